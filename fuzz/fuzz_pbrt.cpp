//
// Fuzzes the pbrt importer with Includes and gzip. The input is a flag byte,
// the main file, and optionally a NUL byte followed by a second file that the
// main one may `Include "include.pbrt"` or `Include "include.pbrt.gz"`:
// - flag bit 0: the main file is gzip'd, as main.pbrt.gz;
// - flag bit 1: the second file's bytes are include.pbrt.gz as they are (to
//   fuzz the inflater on broken streams); otherwise it is written both plain
//   and gzip'd.
// Shapes and environment maps can be named from the folder of small files
// (shapes/hair.ply, textures/sky.exr, ...).
//

#include <yocto/yocto_pbrtio.h>
#include <zlib.h>

#include <cstring>

#include "fuzz_common.h"

using namespace yocto_fuzz;

static void write_gzip_file(const std::string& filename, const void* data, size_t size) {
  auto file = gzopen(filename.c_str(), "wb");
  if (!file) fuzz_fail("cannot create " + filename);
  auto written = size ? gzwrite(file, data, (unsigned)size) : 0;
  if (gzclose(file) != Z_OK || (size_t)written != size)
    fuzz_fail("cannot write " + filename);
}

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  initialize_fuzzing();
  make_scene_files(scratch_folder());
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size < 1) return 0;
  auto flags = data[0];
  auto text = data + 1, end = data + size;
  auto separator = (const uint8_t*)std::memchr(text, 0, end - text);
  auto main_end  = separator ? separator : end;
  auto included  = separator ? separator + 1 : end;

  auto& folder   = scratch_folder();
  auto  plain    = folder + "/include.pbrt", gzipped = folder + "/include.pbrt.gz";
  auto  filename = folder + ((flags & 1) ? "/main.pbrt.gz" : "/main.pbrt");
  if (flags & 1) write_gzip_file(filename, text, main_end - text);
  else write_file(filename, text, main_end - text);
  if (flags & 2) {
    write_file(gzipped, included, end - included);
  } else {
    write_file(plain, included, end - included);
    write_gzip_file(gzipped, included, end - included);
  }

  auto scene        = yocto::scene_data{};
  auto error        = std::string{};
  auto warnings     = std::vector<std::string>{};
  auto params       = yocto::pbrt_params{};
  params.max_memory = fuzz_memory_limit;
  report_load(yocto::load_pbrt_scene(filename, scene, error, params, &warnings), error);
  for (auto& name : {filename, plain, gzipped}) std::remove(name.c_str());
  return 0;
}
