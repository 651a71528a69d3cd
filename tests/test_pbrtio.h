//
// Helpers shared by the pbrt and .hair IO tests: a scratch directory per
// test, files written as text or gzip'd, pbrt text of curves, and loads that
// expect an error.
//

#ifndef YOCTO_TEST_PBRTIO_H_
#define YOCTO_TEST_PBRTIO_H_

#include <gtest/gtest.h>
#include <unistd.h>
#include <yocto/yocto_pbrtio.h>
#include <zlib.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <initializer_list>
#include <string>
#include <vector>

using namespace yocto;
namespace fs = std::filesystem;

// A fresh directory per test, removed at the end.
struct temp_dir {
  fs::path path;
  temp_dir() {
    auto info = ::testing::UnitTest::GetInstance()->current_test_info();
    path      = fs::temp_directory_path() / ("yocto_pbrtio_" + std::to_string(getpid()) +
                                        "_" + info->name());
    fs::remove_all(path);
    fs::create_directories(path);
  }
  ~temp_dir() { fs::remove_all(path); }
  std::string operator/(const std::string& name) const { return (path / name).string(); }
};

inline void write_text(const std::string& filename, const std::string& text) {
  fs::create_directories(fs::path(filename).parent_path());
  auto stream = std::ofstream(filename, std::ios::binary);
  stream << text;
}

inline void write_gz(const std::string& filename, const std::string& text) {
  fs::create_directories(fs::path(filename).parent_path());
  auto file = gzopen(filename.c_str(), "wb");
  ASSERT_NE(file, nullptr);
  ASSERT_EQ(gzwrite(file, text.data(), (unsigned)text.size()), (int)text.size());
  ASSERT_EQ(gzclose(file), Z_OK);
}

// Writes `text` as dir/scene.pbrt and loads it.
inline bool load_text(const temp_dir& dir, const std::string& text, scene_data& scene,
    std::string& error, std::vector<std::string>* warnings = nullptr,
    const pbrt_params& params = {}) {
  write_text(dir / "scene.pbrt", text);
  auto local_warnings = std::vector<std::string>{};
  return load_pbrt_scene(
      dir / "scene.pbrt", scene, error, params, warnings ? warnings : &local_warnings);
}

inline bool contains(const std::string& text, const std::string& part) {
  return text.find(part) != std::string::npos;
}

inline bool any_contains(const std::vector<std::string>& texts, const std::string& part) {
  for (auto& text : texts)
    if (contains(text, part)) return true;
  return false;
}

inline void expect_near(const vec3f& a, const vec3f& b, float tolerance = 1e-5f) {
  EXPECT_NEAR(a.x, b.x, tolerance);
  EXPECT_NEAR(a.y, b.y, tolerance);
  EXPECT_NEAR(a.z, b.z, tolerance);
}

// A cubic Bezier curve in pbrt syntax.
inline std::string curve_text(const vec3f& p0, const vec3f& p1, const vec3f& p2,
    const vec3f& p3, float w0, float w1, const char* point_type = "point3") {
  char buffer[512];
  std::snprintf(buffer, sizeof(buffer),
      "Shape \"curve\" \"%s P\" [ %g %g %g %g %g %g %g %g %g %g %g %g ] "
      "\"float width0\" [ %g ] \"float width1\" [ %g ] \"string type\" \"cylinder\"\n",
      point_type, p0.x, p0.y, p0.z, p1.x, p1.y, p1.z, p2.x, p2.y, p2.z, p3.x, p3.y, p3.z, w0,
      w1);
  return buffer;
}

// A few strands of `segments` chained curves each: stand-in geometry.
inline std::string strands_text(int strands, int segments, const char* point_type,
    const vec3f& origin = {0, 0, 0}) {
  auto text = std::string{};
  for (auto s = 0; s < strands; s++) {
    for (auto k = 0; k < segments; k++) {
      auto base = origin + vec3f{0.1f * s, 0.3f * k, 0};
      text += curve_text(base, base + vec3f{0.02f, 0.1f, 0}, base + vec3f{-0.02f, 0.2f, 0},
          base + vec3f{0, 0.3f, 0}, 0.01f, 0.008f, point_type);
    }
  }
  return text;
}

inline int count_curves(const scene_data& scene) {
  auto count = 0;
  for (auto& shape : scene.shapes) count += (int)shape.curves.size();
  return count;
}

// Loads `text` and expects an error containing every part.
inline void expect_error(const temp_dir& dir, const std::string& text,
    std::initializer_list<std::string> parts, const pbrt_params& params = {}) {
  auto scene = scene_data{};
  auto error = std::string{};
  EXPECT_FALSE(load_text(dir, text, scene, error, nullptr, params)) << text;
  for (auto& part : parts) EXPECT_TRUE(contains(error, part)) << error << "\nmissing: " << part;
  EXPECT_TRUE(scene.shapes.empty() && scene.cameras.empty());
  EXPECT_EQ(error.find('\n'), std::string::npos) << error;
}

#endif
