//
// Helpers shared by the fuzz targets: a private scratch folder per process,
// the small shapes and images that fuzzed scenes may name, and the memory
// budget of a load.
//

#ifndef YOCTO_FUZZ_COMMON_H_
#define YOCTO_FUZZ_COMMON_H_

#include <OpenImageIO/imageio.h>
#include <signal.h>
#include <unistd.h>
#include <yocto/yocto_image.h>
#include <yocto/yocto_ply.h>

#include <cerrno>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <iterator>
#include <string>

namespace yocto_fuzz {

// The budget of one load, passed to every loader: checked allocations stay
// well under libFuzzer's -rss_limit_mb=2048, with room for the sanitizers'
// own memory.
inline constexpr double fuzz_memory_limit = 512.0 * (1 << 20);

// Stops the run on a problem of the harness itself (not of the input).
[[noreturn]] inline void fuzz_fail(const std::string& message) {
  std::fprintf(stderr, "fuzz harness: %s\n", message.c_str());
  std::abort();
}

// Removes the scratch folder on a normal exit. A crash exits without
// cleaning up: the next run removes the folders of processes that are gone
// (scripts/fuzz.sh also gives each run its own TMPDIR).
inline std::string scratch_path = "";
inline void remove_scratch_folder() {
  auto ec = std::error_code{};
  if (!scratch_path.empty()) std::filesystem::remove_all(scratch_path, ec);
}

// Folders named yocto-fuzz-PID-* whose process no longer runs.
inline void remove_stale_folders(const std::string& base) {
  auto ec = std::error_code{};
  for (auto& entry : std::filesystem::directory_iterator(base, ec)) {
    auto name = entry.path().filename().string();
    auto pid  = 0;
    if (std::sscanf(name.c_str(), "yocto-fuzz-%d-", &pid) != 1 || pid <= 0) continue;
    if (kill(pid, 0) == 0 || errno != ESRCH) continue;
    std::filesystem::remove_all(entry.path(), ec);
  }
}

// This process's folder for inputs: under $TMPDIR if set, else in /dev/shm
// (memory, fast), else /tmp; unique to the process.
inline const std::string& scratch_folder() {
  if (!scratch_path.empty()) return scratch_path;
  auto base = std::string{};
  if (auto tmpdir = std::getenv("TMPDIR"); tmpdir && *tmpdir) base = tmpdir;
  else if (std::filesystem::is_directory("/dev/shm")) base = "/dev/shm";
  else base = "/tmp";
  remove_stale_folders(base);
  auto pattern = base + "/yocto-fuzz-" + std::to_string(getpid()) + "-XXXXXX";
  if (!mkdtemp(pattern.data())) fuzz_fail("cannot create a folder in " + base);
  scratch_path = pattern;
  std::atexit(remove_scratch_folder);
  return scratch_path;
}

inline void write_file(const std::string& filename, const void* data, size_t size) {
  auto file = std::fopen(filename.c_str(), "wb");
  if (!file) fuzz_fail("cannot create " + filename);
  auto written = size ? std::fwrite(data, 1, size, file) : 0;
  if (std::fclose(file) != 0 || written != size) fuzz_fail("cannot write " + filename);
}

// Small valid files under FOLDER that fuzzed scenes name: the names the
// generated scenes use (shapes/hair.ply, shapes/head.ply, sphere.ply and
// ball.ply, textures/sky.exr), a lines shape, and a square sky (pbrt-v4
// wants square maps) in every image format we read.
inline void make_scene_files(const std::string& folder) {
  std::filesystem::create_directories(folder + "/shapes");
  std::filesystem::create_directories(folder + "/textures");
  auto error = std::string{};
  auto hair  = yocto::shape_data{};
  hair.positions = {{0, 0, 0}, {0, 1, 0}, {0, 2, 0}, {0, 3, 0}, {1, 0, 0}, {1, 1, 1},
      {1, 2, 0}, {1, 3, 1}};
  hair.radius    = {0.01f, 0.01f, 0.008f, 0.005f, 0.01f, 0.01f, 0.008f, 0.005f};
  hair.curves    = {{0, 1, 2, 3}, {4, 5, 6, 7}};
  auto head      = yocto::shape_data{};
  head.positions = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  head.normals   = {{-1, -1, -1}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  head.texcoords = {{0, 0}, {1, 0}, {0, 1}, {1, 1}};
  head.triangles = {{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}};
  auto lines      = yocto::shape_data{};
  lines.positions = {{0, 0, 0}, {0, 1, 0}, {0, 2, 1}};
  lines.radius    = {0.01f, 0.01f, 0.005f};
  lines.lines     = {{0, 1}, {1, 2}};
  auto sky   = yocto::texture_data{};
  sky.width  = 4;
  sky.height = 4;
  for (auto i = 0; i < 16; i++)
    sky.pixels.push_back({(i % 4) / 2.0f, (i / 4) / 3.0f, i == 5 ? 8.0f : 0.5f});
  auto ok = yocto::save_shape(folder + "/shapes/hair.ply", hair, error) &&
            yocto::save_shape(folder + "/shapes/head.ply", head, error, true) &&
            yocto::save_shape(folder + "/shapes/sphere.ply", head, error) &&
            yocto::save_shape(folder + "/shapes/ball.ply", head, error) &&
            yocto::save_shape(folder + "/shapes/lines.ply", lines, error);
  for (auto extension : {".exr", ".hdr", ".pfm", ".png", ".jpg"})
    ok = ok && yocto::save_image(folder + "/textures/sky" + extension, sky, error);
  if (!ok) fuzz_fail("cannot make the scene files: " + error);
}

// With YOCTO_FUZZ_VERBOSE set (replaying one input by hand), prints what
// the loader said about the input.
inline void report_load(bool ok, const std::string& error) {
  static const auto verbose = std::getenv("YOCTO_FUZZ_VERBOSE") != nullptr;
  if (verbose) std::fprintf(stderr, "%s\n", ok ? "loaded" : error.c_str());
}

// Settings every target starts with: images read on the fuzzing thread
// alone (no thread pool to keep between inputs).
inline void initialize_fuzzing() {
  OIIO::attribute("threads", 1);
  OIIO::attribute("exr_threads", 1);
}

}  // namespace yocto_fuzz

#endif
