//
// Fuzzes the PLY shape loader: the input is the file.
//

#include <yocto/yocto_ply.h>

#include "fuzz_common.h"

using namespace yocto_fuzz;

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  initialize_fuzzing();
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  auto filename = scratch_folder() + "/shape.ply";
  write_file(filename, data, size);
  auto shape = yocto::shape_data{};
  auto error = std::string{};
  report_load(yocto::load_shape(filename, shape, error, fuzz_memory_limit), error);
  std::remove(filename.c_str());
  return 0;
}
