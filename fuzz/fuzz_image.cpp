//
// Fuzzes image loading through OpenImageIO: the first byte picks the
// extension (OpenImageIO chooses its reader from it, and falls back to the
// others when the data does not match), the rest is the file.
//

#include <yocto/yocto_image.h>

#include "fuzz_common.h"

using namespace yocto_fuzz;

// The formats Debian's OpenImageIO reads that scenes use or could use.
static const char* const image_extensions[] = {
    ".png", ".jpg", ".exr", ".hdr", ".pfm", ".ppm", ".tga"};
static const size_t num_image_extensions = std::size(image_extensions);

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  initialize_fuzzing();
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size < 1) return 0;
  auto extension = image_extensions[data[0] % num_image_extensions];
  auto filename  = scratch_folder() + "/image" + extension;
  write_file(filename, data + 1, size - 1);
  auto image = yocto::texture_data{};
  auto error = std::string{};
  report_load(yocto::load_image(filename, image, error, fuzz_memory_limit), error);
  std::remove(filename.c_str());
  return 0;
}
