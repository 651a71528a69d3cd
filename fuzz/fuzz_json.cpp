//
// Fuzzes the json scene loader: the input is the json, written next to a
// shapes/ and textures/ folder of small valid files it may name (as the
// generated scenes do), so that fuzzing reaches past the references.
//

#include <yocto/yocto_sceneio.h>

#include "fuzz_common.h"

using namespace yocto_fuzz;

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  initialize_fuzzing();
  make_scene_files(scratch_folder());
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  auto filename = scratch_folder() + "/scene.json";
  write_file(filename, data, size);
  auto scene    = yocto::scene_data{};
  auto error    = std::string{};
  auto warnings = std::vector<std::string>{};
  report_load(yocto::load_scene(filename, scene, error, &warnings, fuzz_memory_limit), error);
  std::remove(filename.c_str());
  return 0;
}
