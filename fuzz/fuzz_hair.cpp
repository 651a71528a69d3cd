//
// Fuzzes the loader of Cem Yuksel's .hair models: the input is the file.
//

#include <yocto/yocto_hairio.h>

#include "fuzz_common.h"

using namespace yocto_fuzz;

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  initialize_fuzzing();
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  auto filename = scratch_folder() + "/model.hair";
  write_file(filename, data, size);
  auto shape = yocto::shape_data{};
  auto error = std::string{};
  auto color = yocto::vec3f{0, 0, 0};
  report_load(yocto::load_hair_model(filename, shape, error, &color, fuzz_memory_limit), error);
  std::remove(filename.c_str());
  return 0;
}
