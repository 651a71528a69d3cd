//
// Tests of Yocto/PbrtIO on the real pbrt-v3 and pbrt-v4 hair scenes in
// ../shared/data/pbrt. Their hair geometry is not available, so each test
// copies the scene folder to a temporary directory and writes small stand-in
// include files there (a few curves in the scene's syntax, gzip'd where the
// scene includes a .gz), then loads the real scene file.
//

#include <gtest/gtest.h>
#include <unistd.h>
#include <yocto/yocto_pbrtio.h>
#include <zlib.h>

#include <cstdio>
#include <filesystem>
#include <fstream>

using namespace yocto;
namespace fs = std::filesystem;

// -----------------------------------------------------------------------------
// HELPERS
// -----------------------------------------------------------------------------

static const auto pbrt_data = fs::path(YOCTO_SHARED_DIR) / "data" / "pbrt";

// The real scene files live beside the repository, not in it.
#define SKIP_WITHOUT_REAL_SCENES()      \
  if (!fs::exists(pbrt_data))           \
  GTEST_SKIP() << "no real scene files at " << pbrt_data

// A temporary copy of a scene folder, removed at the end.
struct scene_copy {
  fs::path path;
  explicit scene_copy(const fs::path& source) {
    auto info = ::testing::UnitTest::GetInstance()->current_test_info();
    path      = fs::temp_directory_path() /
           ("yocto_pbrtio_scenes_" + std::to_string(getpid()) + "_" + info->name());
    fs::remove_all(path);
    fs::create_directories(path);
    fs::copy(source, path, fs::copy_options::recursive);
  }
  ~scene_copy() { fs::remove_all(path); }
  std::string operator/(const std::string& name) const { return (path / name).string(); }
};

// `strands` strands of `segments` chained curves (pbrt widths 0.01 to 0.005).
static std::string stand_in_curves(int strands, int segments, const char* point_type) {
  auto text = std::string{};
  char buffer[512];
  for (auto s = 0; s < strands; s++) {
    for (auto k = 0; k < segments; k++) {
      auto x = 0.5f * s, y = 1.0f * k;
      std::snprintf(buffer, sizeof(buffer),
          "Shape \"curve\" \"%s P\" [ %g %g 0 %g %g 0.1 %g %g -0.1 %g %g 0 ] "
          "\"float width0\" [ 0.01 ] \"float width1\" [ 0.005 ] \"string type\" [ \"cylinder\" ]\n",
          point_type, x, y, x, y + 0.33f, x, y + 0.66f, x, y + 1);
      text += buffer;
    }
  }
  return text;
}

static void write_text(const std::string& filename, const std::string& text) {
  fs::create_directories(fs::path(filename).parent_path());
  std::ofstream(filename, std::ios::binary) << text;
}

static void write_gz(const std::string& filename, const std::string& text) {
  fs::create_directories(fs::path(filename).parent_path());
  auto file = gzopen(filename.c_str(), "wb");
  ASSERT_NE(file, nullptr);
  gzwrite(file, text.data(), (unsigned)text.size());
  ASSERT_EQ(gzclose(file), Z_OK);
}

static bool any_contains(const std::vector<std::string>& texts, const std::string& part) {
  for (auto& text : texts)
    if (text.find(part) != std::string::npos) return true;
  return false;
}

static void expect_near(const vec3f& a, const vec3f& b, float tolerance = 1e-4f) {
  EXPECT_NEAR(a.x, b.x, tolerance);
  EXPECT_NEAR(a.y, b.y, tolerance);
  EXPECT_NEAR(a.z, b.z, tolerance);
}

// The instance of the shape with the given curve count, or -1.
static int curves_instance(const scene_data& scene) {
  for (auto i = 0; i < (int)scene.instances.size(); i++)
    if (!scene.shapes[scene.instances[i].shape].curves.empty()) return i;
  return -1;
}

// The camera of the three v3 scenes and of the v4 ones: pbrt's world-to-camera
// matrix (column-major); its inverse places the camera.
static frame3f hair_scenes_world_to_camera() {
  return {{-0.999887f, 0.00390257f, 0.0145262f}, {-0.0f, 0.965755f, -0.259457f},
      {0.0150413f, 0.259428f, 0.965645f}, {0.146624f, -9.36998f, 28.765f}};
}

// -----------------------------------------------------------------------------
// PBRT-V3
// -----------------------------------------------------------------------------

TEST(pbrtio_scenes, v3_curly_hair) {
  SKIP_WITHOUT_REAL_SCENES();
  auto dir = scene_copy{pbrt_data / "pbrt-v3" / "hair"};
  write_text(dir / "models/curly-hair.pbrt", stand_in_curves(4, 3, "point"));
  auto scene    = scene_data{};
  auto error    = std::string{};
  auto warnings = std::vector<std::string>{};
  ASSERT_TRUE(load_pbrt_scene(dir / "curly-hair.pbrt", scene, error, {}, &warnings)) << error;
  EXPECT_EQ(scene.settings.resolution, 1024);
  EXPECT_EQ(scene.settings.samples, 1024);
  EXPECT_EQ(scene.settings.bounces, 32);
  ASSERT_EQ(scene.cameras.size(), 1u);
  auto& camera = scene.cameras[0];
  EXPECT_FLOAT_EQ(camera.aspect, 1);
  EXPECT_NEAR(2 * std::atan(camera.film / 2 / camera.lens), radians(32), 1e-5f);
  auto camera_to_world = inverse(hair_scenes_world_to_camera());
  expect_near(camera.frame.o, camera_to_world.o);
  expect_near(-camera.frame.z, normalize(camera_to_world.z));
  // Hair: one curves shape, one instance, pbrt's hair with eumelanin .3.
  ASSERT_EQ(scene.shapes.size(), 1u);
  EXPECT_EQ(scene.shapes[0].curves.size(), 12u);
  EXPECT_EQ(scene.shapes[0].positions.size(), 4u * 10);  // chained strands
  EXPECT_FLOAT_EQ(scene.shapes[0].radius[0], 0.005f);
  ASSERT_EQ(scene.materials.size(), 1u);
  EXPECT_EQ(scene.materials[0].type, material_type::hair);
  EXPECT_FLOAT_EQ(scene.materials[0].hair.eumelanin, 0.3f);
  EXPECT_FLOAT_EQ(scene.materials[0].hair.pheomelanin, 0);
  // The sky: the real 512x256 equirect Skydome.pfm, rotated as in the file.
  ASSERT_EQ(scene.environments.size(), 1u);
  auto& env = scene.environments[0];
  ASSERT_EQ(env.emission_tex, 0);
  EXPECT_EQ(scene.textures[0].width, 512);
  EXPECT_EQ(scene.textures[0].height, 256);
  auto light_to_world = rotation_frame({1, 0, 0}, radians(-55)) *
                        rotation_frame({0, 0, 1}, radians(90));
  expect_near(env.frame.y, light_to_world.z);  // pbrt's map pole is its z
  EXPECT_TRUE(any_contains(warnings, "PixelFilter"));
  EXPECT_TRUE(any_contains(warnings, "\"float scale\""));  // Film scale
}

TEST(pbrtio_scenes, v3_straight_hair) {
  SKIP_WITHOUT_REAL_SCENES();
  auto dir = scene_copy{pbrt_data / "pbrt-v3" / "hair"};
  write_text(dir / "models/straight-hair.pbrt", stand_in_curves(3, 2, "point"));
  auto scene    = scene_data{};
  auto error    = std::string{};
  auto warnings = std::vector<std::string>{};
  ASSERT_TRUE(load_pbrt_scene(dir / "straight-hair.pbrt", scene, error, {}, &warnings))
      << error;
  EXPECT_EQ(scene.settings.samples, 512);
  EXPECT_NEAR(2 * std::atan(scene.cameras[0].film / 2 / scene.cameras[0].lens), radians(35),
      1e-5f);
  // Only the named material in use becomes a scene material.
  ASSERT_EQ(scene.materials.size(), 1u);
  EXPECT_EQ(scene.material_names[0], "brown_hair");
  auto& hair = scene.materials[0].hair;
  EXPECT_FLOAT_EQ(hair.eumelanin, 1.3f);
  EXPECT_FLOAT_EQ(hair.beta_m, 0.25f);
  EXPECT_FLOAT_EQ(hair.alpha, 2);
  EXPECT_EQ(scene.shapes[0].curves.size(), 6u);
  // The sun: pointing from the scene towards "from".
  ASSERT_EQ(scene.distant_lights.size(), 1u);
  expect_near(scene.distant_lights[0].direction, normalize(vec3f{0.190330f, 0.758426f, -0.623349f}));
  expect_near(scene.distant_lights[0].emission, vec3f{19.091171f}, 1e-4f);
  EXPECT_EQ(scene.environments.size(), 1u);
}

TEST(pbrtio_scenes, v3_sphere_hairblock_matches_pbrt_image_layout) {
  SKIP_WITHOUT_REAL_SCENES();
  auto dir = scene_copy{pbrt_data / "pbrt-v3" / "hair"};
  write_text(dir / "models/block.pbrt", stand_in_curves(5, 1, "point"));
  auto scene = scene_data{};
  auto error = std::string{};
  auto warnings = std::vector<std::string>{};
  ASSERT_TRUE(load_pbrt_scene(dir / "sphere-hairblock.pbrt", scene, error, {}, &warnings))
      << error;
  EXPECT_EQ(scene.settings.resolution, 1000);
  auto& camera = scene.cameras[0];
  EXPECT_FLOAT_EQ(camera.aspect, 2);
  // Hair block, sphere, disk.
  ASSERT_EQ(scene.shapes.size(), 3u);
  ASSERT_EQ(scene.instances.size(), 3u);
  auto hair = curves_instance(scene);
  ASSERT_EQ(hair, 0);
  auto& hair_material = scene.materials[scene.instances[0].material];
  EXPECT_TRUE(hair_material.hair.has_color);
  expect_near(hair_material.hair.color, {.2f, .8f, .3f});
  EXPECT_FLOAT_EQ(hair_material.hair.beta_m, .3f);
  EXPECT_FLOAT_EQ(hair_material.hair.beta_n, .8f);
  auto& sphere = scene.instances[1];
  expect_near(sphere.frame.o, {2, .5f, .5f});
  EXPECT_EQ(scene.materials[sphere.material].type, material_type::matte);
  expect_near(scene.materials[sphere.material].color, {.2f, .8f, .3f});
  expect_near(scene.materials[scene.instances[2].material].color, {.1f, .1f, .1f});
  // The disk stands upright at y = 5 behind the objects, facing them.
  expect_near(transform_point(scene.instances[2].frame, {0, 0, 0}), {0, 5, 0});
  expect_near(transform_normal(scene.instances[2].frame, {0, 0, 1}), {0, -1, 0});
  // pbrt's render shows the sphere centred at about (220, 247) of 1000x500.
  auto uv = project_camera_point(camera, sphere.frame.o);
  EXPECT_NEAR(uv.x, 0.22f, 0.02f);
  EXPECT_NEAR(uv.y, 0.494f, 0.03f);
  // The constant sky of pbrt's default infinite light.
  ASSERT_EQ(scene.environments.size(), 1u);
  expect_near(scene.environments[0].emission, {1, 1, 1});
  EXPECT_EQ(scene.environments[0].emission_tex, -1);
}

// -----------------------------------------------------------------------------
// PBRT-V4
// -----------------------------------------------------------------------------

struct v4_expectation {
  const char*   file;
  const char*   geometry;
  material_type type;
  float         eumelanin;
  float         beta_m;
};

TEST(pbrtio_scenes, v4_hair_scenes) {
  SKIP_WITHOUT_REAL_SCENES();
  auto expectations = std::vector<v4_expectation>{
      {"hair-betam-0.25.pbrt", "geometry/straight-hair.pbrt.gz", material_type::hair, 1.3f, .25f},
      {"hair-eumel-0.3.pbrt", "geometry/straight-hair.pbrt.gz", material_type::hair, .3f, .25f},
      {"hair-eumel-2.pbrt", "geometry/straight-hair.pbrt.gz", material_type::hair, 2, .25f},
      {"hair-coated-diffuse.pbrt", "geometry/curly-hair.pbrt.gz", material_type::glossy, 0, 0},
  };
  auto dir = scene_copy{pbrt_data / "pbrt-v4" / "hair"};
  write_gz(dir / "geometry/straight-hair.pbrt.gz", stand_in_curves(3, 4, "point3"));
  write_gz(dir / "geometry/curly-hair.pbrt.gz", stand_in_curves(2, 5, "point3"));
  for (auto& expected : expectations) {
    SCOPED_TRACE(expected.file);
    auto scene    = scene_data{};
    auto error    = std::string{};
    auto warnings = std::vector<std::string>{};
    ASSERT_TRUE(load_pbrt_scene(dir / expected.file, scene, error, {}, &warnings)) << error;
    EXPECT_EQ(scene.settings.resolution, 1024);
    EXPECT_EQ(scene.settings.bounces, 32);
    auto& camera = scene.cameras[0];
    EXPECT_FLOAT_EQ(camera.focus, 21);
    expect_near(camera.frame.o, inverse(hair_scenes_world_to_camera()).o);
    // The environment map is not available: a constant sky and a warning.
    ASSERT_EQ(scene.environments.size(), 1u);
    EXPECT_EQ(scene.environments[0].emission_tex, -1);
    expect_near(scene.environments[0].emission, {1, 1, 1});
    EXPECT_TRUE(any_contains(warnings, "sunflowers_equiarea_blurred.exr"));
    EXPECT_TRUE(any_contains(warnings, "\"float iso\""));
    // Hair (or coated diffuse) curves and the dark sphere placed in camera
    // space, 25 units ahead of the camera and 2 up.
    ASSERT_EQ(scene.instances.size(), 2u);
    auto  hair     = curves_instance(scene);
    ASSERT_GE(hair, 0);
    auto& material = scene.materials[scene.instances[hair].material];
    EXPECT_EQ(material.type, expected.type);
    if (expected.type == material_type::hair) {
      EXPECT_FLOAT_EQ(material.hair.eumelanin, expected.eumelanin);
      EXPECT_FLOAT_EQ(material.hair.beta_m, expected.beta_m);
      EXPECT_EQ(scene.shapes[scene.instances[hair].shape].curves.size(), 12u);
    } else {
      expect_near(material.color, {.9f, .6f, .1f});
      EXPECT_NEAR(material.roughness, std::sqrt(0.1f), 1e-6f);
      EXPECT_EQ(scene.shapes[scene.instances[hair].shape].curves.size(), 10u);
    }
    auto& sphere = scene.instances[1 - hair];
    auto  offset = sphere.frame.o - camera.frame.o;
    EXPECT_NEAR(dot(offset, -camera.frame.z), 25, 1e-3f);
    EXPECT_NEAR(dot(offset, camera.frame.y), 2, 1e-3f);
    EXPECT_NEAR(dot(offset, camera.frame.x), 0, 1e-3f);
    expect_near(scene.materials[sphere.material].color, {.1f, .1f, .1f});
  }
}

TEST(pbrtio_scenes, v4_scene_as_lines) {
  SKIP_WITHOUT_REAL_SCENES();
  auto dir = scene_copy{pbrt_data / "pbrt-v4" / "hair"};
  write_gz(dir / "geometry/straight-hair.pbrt.gz", stand_in_curves(3, 4, "point3"));
  auto scene  = scene_data{};
  auto error  = std::string{};
  auto params = pbrt_params{};
  params.curves_as_lines = true;
  params.segments        = 2;
  auto warnings          = std::vector<std::string>{};
  ASSERT_TRUE(load_pbrt_scene(dir / "hair-eumel-2.pbrt", scene, error, params, &warnings))
      << error;
  auto& shape = scene.shapes[scene.instances[0].shape];
  EXPECT_TRUE(shape.curves.empty());
  EXPECT_EQ(shape.lines.size(), 3u * 4 * 2);
  EXPECT_EQ(shape.positions.size(), 3u * (4 * 2 + 1));
}
