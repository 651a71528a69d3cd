//
// Helpers shared by the IO tests (PLY, images, json scenes, limits):
// scratch directories and small files.
//

#ifndef YOCTO_TEST_IO_H_
#define YOCTO_TEST_IO_H_

#include <gtest/gtest.h>
#include <unistd.h>
#include <yocto/yocto_fileio.h>
#include <yocto/yocto_scene.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

namespace yocto_test {

// A fresh, empty directory for one test, removed when the test ends.
struct scratch_directory {
  std::string path = "";
  explicit scratch_directory(const std::string& name) {
    path = (std::filesystem::temp_directory_path() /
            ("yocto-sceneio-" + std::to_string(getpid())) / name)
               .string();
    std::filesystem::remove_all(path);
    std::filesystem::create_directories(path);
  }
  ~scratch_directory() {
    auto ec = std::error_code{};
    std::filesystem::remove_all(path, ec);
  }
  std::string file(const std::string& name) const { return path + "/" + name; }
};

inline void write_file(const std::string& filename, const std::string& contents) {
  std::filesystem::create_directories(std::filesystem::path(filename).parent_path());
  auto stream = std::ofstream(filename, std::ios::binary);
  stream.write(contents.data(), (std::streamsize)contents.size());
}

inline std::string read_file(const std::string& filename) {
  auto stream = std::ifstream(filename, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(stream), {});
}

// Every file and directory under a directory, relative and sorted: what a
// failed save must leave unchanged.
inline std::vector<std::string> list_files(const std::string& directory) {
  auto files = std::vector<std::string>{};
  for (auto& entry : std::filesystem::recursive_directory_iterator(directory))
    files.push_back(std::filesystem::relative(entry.path(), directory).string());
  std::sort(files.begin(), files.end());
  return files;
}

inline bool contains(const std::string& text, const std::string& part) {
  return text.find(part) != std::string::npos;
}

// PNG bytes with the header's size replaced and its checksum (ISO 3309
// CRC-32) fixed: a tiny file that claims a huge image.
inline std::string patch_png_size(std::string png, uint32_t width, uint32_t height) {
  if (png.size() < 33 || png.compare(12, 4, "IHDR") != 0) return png;
  auto put = [&](size_t offset, uint32_t value) {
    for (auto k = 0; k < 4; k++) png[offset + k] = (char)(value >> (24 - 8 * k));
  };
  put(16, width);
  put(20, height);
  auto crc = 0xffffffffu;
  for (auto i = 12; i < 29; i++) {
    crc ^= (uint8_t)png[i];
    for (auto k = 0; k < 8; k++) crc = (crc >> 1) ^ (0xedb88320u & (0u - (crc & 1)));
  }
  put(29, ~crc);
  return png;
}

inline void expect_same_shape(const yocto::shape_data& a, const yocto::shape_data& b) {
  EXPECT_EQ(a.positions, b.positions);
  EXPECT_EQ(a.normals, b.normals);
  EXPECT_EQ(a.texcoords, b.texcoords);
  EXPECT_EQ(a.radius, b.radius);
  EXPECT_EQ(a.triangles, b.triangles);
  EXPECT_EQ(a.lines, b.lines);
  EXPECT_EQ(a.curves, b.curves);
}

}  // namespace yocto_test

#endif
