//
// Json scenes: round trips of the 4.2 layout we write and of the 4.0 and
// mixed layouts of earlier Yocto hair scenes, hair keys and their defaults,
// warnings, every kind of bad input, and the real scenes in ../shared.
//

#include <gtest/gtest.h>

#include <charconv>

#include <nlohmann/json.hpp>
#include <yocto/yocto_sceneio.h>

#include "test_io.h"

using namespace yocto;
using namespace yocto_test;

namespace {

texture_data make_texture(int width, int height, float scale) {
  auto texture = texture_data{width, height, {}};
  for (auto i = 0; i < width * height; i++)
    texture.pixels.push_back(scale * vec3f{i * 0.1f, 1.0f / (i + 3), 0.7f});
  return texture;
}

shape_data make_quad() {
  auto shape      = shape_data{};
  shape.positions = {{-1, -1, 0}, {1, -1, 0}, {1, 1, 0}, {-1, 1, 0}};
  shape.normals   = {{0, 0, 1}, {0, 0, 1}, {0, 0, 1}, {0, 0, 1}};
  shape.texcoords = {{0, 0}, {1, 0}, {1, 1}, {0, 1}};
  shape.triangles = {{0, 1, 2}, {0, 2, 3}};
  return shape;
}

// Fibers: `count` strands of `segments` lines, or of `segments` Bezier
// curves (three new control points per curve).
shape_data make_fibers(bool curves, int count, int segments) {
  auto shape = shape_data{};
  for (auto s = 0; s < count; s++) {
    auto base  = (int)shape.positions.size();
    auto steps = curves ? 3 * segments : segments;
    for (auto k = 0; k <= steps; k++) {
      shape.positions.push_back({0.1f * s, 0.37f * k, 0.01f * k * k});
      shape.radius.push_back(0.003f * (1 - 0.5f * k / steps));
    }
    for (auto k = 0; k < segments; k++) {
      if (curves)
        shape.curves.push_back({base + 3 * k, base + 3 * k + 1, base + 3 * k + 2, base + 3 * k + 3});
      else
        shape.lines.push_back({base + k, base + k + 1});
    }
  }
  return shape;
}

// Every kind of element, with values away from the defaults.
scene_data make_test_scene() {
  auto scene      = scene_data{};
  scene.copyright = "made by the sceneio test";
  scene.settings  = {720, 64, 8};

  auto camera     = camera_data{};
  camera.frame    = lookat_frame({0.1f, 1.3f, 5.7f}, {0, 0.2f, 0}, {0, 1, 0});
  camera.lens     = 0.035f;
  camera.film     = 0.024f;
  camera.aspect   = 1.25f;
  camera.focus    = 5.3f;
  camera.aperture = 0.01f;
  auto side         = camera_data{};
  side.orthographic = true;
  scene.cameras       = {camera, side};
  scene.camera_names  = {"main", ""};

  scene.textures      = {make_texture(5, 3, 4), make_texture(2, 2, 0.5f)};
  scene.texture_names = {"sky", "pattern"};
  auto environment         = environment_data{};
  environment.frame        = rotation_frame({0, 1, 0}, 0.3f);
  environment.emission     = {0.5f, 0.6f, 0.7f};
  environment.emission_tex = 0;
  scene.environments       = {environment};
  scene.environment_names  = {"sky"};
  scene.distant_lights     = {{normalize(vec3f{1, 2, 3}), {3, 2.5f, 2}}};

  scene.shapes      = {make_quad(), make_fibers(false, 3, 4), make_fibers(true, 2, 3)};
  scene.shape_names = {"quad", "strands", "curls"};

  auto floor      = material_data{};
  floor.color     = {0.3f, 0.4f, 0.5f};
  floor.color_tex = 1;
  auto coat       = material_data{};
  coat.type       = material_type::glossy;
  coat.color      = {0.1f, 0.2f, 0.3f};
  coat.roughness  = 0.2f;
  coat.ior        = 1.4f;
  auto light      = material_data{};
  light.emission  = {10, 9, 8};
  light.color     = {0, 0, 0};
  auto hair_all   = material_data{};
  hair_all.type   = material_type::hair;
  hair_all.hair   = {{0.1f, 0.2f, 0.3f}, {0.4f, 0.3f, 0.2f}, 0.7f, 0.2f, 0.25f, 0.35f, 3, 1.6f,
      true, true};
  auto hair_melanin           = material_data{};
  hair_melanin.type           = material_type::hair;
  hair_melanin.hair.eumelanin = 2.5f;
  scene.materials      = {floor, coat, light, hair_all, hair_melanin};
  scene.material_names = {"floor", "coat", "light", "hair-all", "hair-melanin"};

  scene.instances = {
      {translation_frame({0, -1, 0}) * rotation_frame({1, 0, 0}, -pif / 2), 0, 0},
      {lookat_frame({-5, 20, 10}, {0, 9.5f, 0}, {0, 1, 0}), 0, 2},
      {translation_frame({0.5f, 0, 0}), 0, 1}, {identity3x4f, 1, 3}, {identity3x4f, 2, 4},
      {scaling_frame({2, 2, 2}), 2, 3}};
  scene.instance_names = {"floor", "light", "box", "strands", "curls", "big-curls"};
  return scene;
}

// Every parameter of the table, and its has_ flag.
void expect_same_hair(const hair_material& a, const hair_material& b) {
  for (auto& parameter : hair_parameters) {
    EXPECT_EQ(get_hair_parameter(a, parameter), get_hair_parameter(b, parameter))
        << parameter.name;
    if (parameter.has) EXPECT_EQ(a.*parameter.has, b.*parameter.has) << parameter.name;
  }
}

// Field by field, so that a failure says which field.
void expect_same_scene(const scene_data& a, const scene_data& b) {
  EXPECT_EQ(a.copyright, b.copyright);
  EXPECT_EQ(a.settings.resolution, b.settings.resolution);
  EXPECT_EQ(a.settings.samples, b.settings.samples);
  EXPECT_EQ(a.settings.bounces, b.settings.bounces);
  EXPECT_EQ(a.camera_names, b.camera_names);
  EXPECT_EQ(a.environment_names, b.environment_names);
  EXPECT_EQ(a.shape_names, b.shape_names);
  EXPECT_EQ(a.texture_names, b.texture_names);
  EXPECT_EQ(a.material_names, b.material_names);
  EXPECT_EQ(a.instance_names, b.instance_names);
  ASSERT_EQ(a.cameras.size(), b.cameras.size());
  for (size_t i = 0; i < a.cameras.size(); i++) {
    auto &ca = a.cameras[i], &cb = b.cameras[i];
    EXPECT_EQ(ca.frame, cb.frame);
    EXPECT_EQ(ca.orthographic, cb.orthographic);
    EXPECT_EQ(ca.lens, cb.lens);
    EXPECT_EQ(ca.film, cb.film);
    EXPECT_EQ(ca.aspect, cb.aspect);
    EXPECT_EQ(ca.focus, cb.focus);
    EXPECT_EQ(ca.aperture, cb.aperture);
  }
  ASSERT_EQ(a.environments.size(), b.environments.size());
  for (size_t i = 0; i < a.environments.size(); i++) {
    EXPECT_EQ(a.environments[i].frame, b.environments[i].frame);
    EXPECT_EQ(a.environments[i].emission, b.environments[i].emission);
    EXPECT_EQ(a.environments[i].emission_tex, b.environments[i].emission_tex);
  }
  ASSERT_EQ(a.distant_lights.size(), b.distant_lights.size());
  for (size_t i = 0; i < a.distant_lights.size(); i++) {
    EXPECT_EQ(a.distant_lights[i].direction, b.distant_lights[i].direction);
    EXPECT_EQ(a.distant_lights[i].emission, b.distant_lights[i].emission);
  }
  ASSERT_EQ(a.textures.size(), b.textures.size());
  for (size_t i = 0; i < a.textures.size(); i++) {
    EXPECT_EQ(a.textures[i].width, b.textures[i].width);
    EXPECT_EQ(a.textures[i].height, b.textures[i].height);
    EXPECT_EQ(a.textures[i].pixels, b.textures[i].pixels);
  }
  ASSERT_EQ(a.shapes.size(), b.shapes.size());
  for (size_t i = 0; i < a.shapes.size(); i++) expect_same_shape(a.shapes[i], b.shapes[i]);
  ASSERT_EQ(a.materials.size(), b.materials.size());
  for (size_t i = 0; i < a.materials.size(); i++) {
    auto &ma = a.materials[i], &mb = b.materials[i];
    EXPECT_EQ(ma.type, mb.type) << a.material_names[i];
    EXPECT_EQ(ma.emission, mb.emission);
    EXPECT_EQ(ma.color, mb.color);
    EXPECT_EQ(ma.roughness, mb.roughness);
    EXPECT_EQ(ma.ior, mb.ior);
    EXPECT_EQ(ma.emission_tex, mb.emission_tex);
    EXPECT_EQ(ma.color_tex, mb.color_tex);
    expect_same_hair(ma.hair, mb.hair);
  }
  ASSERT_EQ(a.instances.size(), b.instances.size());
  for (size_t i = 0; i < a.instances.size(); i++) {
    EXPECT_EQ(a.instances[i].frame, b.instances[i].frame);
    EXPECT_EQ(a.instances[i].shape, b.instances[i].shape);
    EXPECT_EQ(a.instances[i].material, b.instances[i].material);
  }
}

// Saves the scene into a fresh directory and loads it back.
void expect_round_trip(const scene_data& scene, const std::string& dirname, bool ascii) {
  auto dir   = scratch_directory(dirname);
  auto error = std::string{};
  ASSERT_TRUE(save_scene(dir.file("scene.json"), scene, error, ascii)) << error;
  auto loaded   = scene_data{};
  auto warnings = std::vector<std::string>{};
  ASSERT_TRUE(load_scene(dir.file("scene.json"), loaded, error, &warnings)) << error;
  EXPECT_TRUE(warnings.empty()) << warnings.front();  // our own files are clean
  expect_same_scene(scene, loaded);
  for (auto& file : list_files(dir.path)) EXPECT_FALSE(contains(file, ".tmp-")) << file;
}

// Writes the shapes and the sky texture that the fixtures below refer to.
void write_fixture_files(const std::string& directory) {
  std::filesystem::create_directories(directory + "/shapes");
  std::filesystem::create_directories(directory + "/textures");
  auto error = std::string{};
  auto sphere = make_quad();  // any triangle mesh
  ASSERT_TRUE(save_shape(directory + "/shapes/sphere.ply", sphere, error)) << error;
  ASSERT_TRUE(save_shape(directory + "/shapes/arealight.ply", make_quad(), error)) << error;
  ASSERT_TRUE(save_shape(directory + "/shapes/hair-block.ply", make_fibers(true, 4, 2), error, true))
      << error;
  ASSERT_TRUE(save_shape(directory + "/shapes/hair-curl.ply", make_fibers(false, 3, 5), error))
      << error;
  ASSERT_TRUE(save_image(directory + "/textures/sky.hdr", make_texture(8, 4, 1), error)) << error;
}

// The 4.0 layout of the 2020 hair scenes: groups keyed by name, references
// by name, no material types, files found by name; objects before materials.
const auto layout_40_json = R"({
  "asset": {"copyright": "after yocto-hair-2020"},
  "cameras": {
    "default": {"lens": 0.05, "aperture": 0.0, "aspect": 1.777777778,
                "lookat": [-0.5, 1.5, 5, 0.25, 0.5, 0, 0, 1, 0]}
  },
  "environments": {
    "sky": {"emission": [2, 2, 2], "emission_tex": "sky",
            "frame": [1, 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0]}
  },
  "objects": {
    "sphere": {"frame": [1, 0, 0, 0, 1, 0, 0, 0, 1, -0.5, 0, 0],
               "shape": "sphere", "material": "diffuse"},
    "hairblock": {"frame": [1, 0, 0, 0, 0, 1, 0, -1, 0, 0.5, 1, -0.5],
                  "shape": "hair-block", "material": "hair"},
    "red": {"frame": [1, 0, 0, 0, 1, 0, 0, 0, 1, -1.25, 0, 0],
            "shape": "hair-curl", "material": "red"},
    "arealight1": {"lookat": [-8, 10, 5, -6.5, 3.5, 0, 0, 1, 0],
                   "shape": "arealight", "material": "arealight"}
  },
  "materials": {
    "diffuse": {"color": [0.8, 0.4, 0.05]},
    "hair": {"color": [0.8, 0.4, 0.05]},
    "red": {"pheomelanin": 2},
    "arealight": {"emission": [20, 20, 20]},
    "unused": {"color": [0.5, 0.5, 0.5]}
  }
})";

// The mixed layout of the 2023 scenes: cameras keyed by name, the rest as
// arrays with integer references, camelCase hair keys, extra keys.
const auto layout_mixed_json = R"({
  "asset": {"copyright": "after yocto-hair-2023", "version": "4.2"},
  "cameras": {
    "default": {"lens": 0.05, "aperture": 0.0, "aspect": 1.0,
                "lookat": [0, 15, 23, 0, 9.5, 0, 0, 1, 0]}
  },
  "environments": [{"name": "sky", "emission": [2.5, 2.5, 2.5], "emission_tex": 0}],
  "textures": [{"name": "sky", "uri": "textures/sky.hdr"}],
  "shapes": [{"name": "hair1", "uri": "shapes/hair-curl.ply"},
             {"name": "arealight", "uri": "shapes/arealight.ply"}],
  "subdivs": [],
  "materials": [
    {"name": "hairs", "type": "hair", "eumelanin": 0.3, "sigmaA": [0.06, 0.10, 0.20],
     "betaM": 0.2, "betaN": 0.4, "roughness": 0.1},
    {"name": "arealight", "type": "matte", "emission": [20, 20, 20], "color": [0, 0, 0]}
  ],
  "instances": [
    {"name": "hair", "frame": [-1, 0, 0, 0, 1, 0, 0, 0, -1, 0, 0, 0], "shape": 0, "material": 0},
    {"name": "arealight1", "lookat": [-5, 20, 10, 0, 9.5, 0, 0, 1, 0], "shape": 1, "material": 1}
  ]
})";

bool any_warning(const std::vector<std::string>& warnings, const std::vector<std::string>& parts) {
  for (auto& warning : warnings) {
    auto all = true;
    for (auto& part : parts) all &= contains(warning, part);
    if (all) return true;
  }
  return false;
}

}  // namespace

static void round_trips_every_element_with_binary_and_ascii_shapes() {
  auto scene = make_test_scene();
  expect_round_trip(scene, "round-trip-binary", false);
  expect_round_trip(scene, "round-trip-ascii", true);

  auto dir   = scratch_directory("round-trip-files");
  auto error = std::string{};
  ASSERT_TRUE(save_scene(dir.file("scene.json"), scene, error)) << error;
  EXPECT_EQ(list_files(dir.path),
      (std::vector<std::string>{"scene.json", "shapes", "shapes/curls.ply", "shapes/quad.ply",
          "shapes/strands.ply", "textures", "textures/pattern.exr", "textures/sky.exr"}));
  // The 4.2 layout: arrays, integer references, uris, 12-number frames.
  auto js = nlohmann::json::parse(read_file(dir.file("scene.json")));
  EXPECT_TRUE(js["shapes"].is_array());
  EXPECT_EQ(js["shapes"][2]["uri"], "shapes/curls.ply");
  EXPECT_EQ(js["instances"][4]["shape"], 2);
  EXPECT_EQ(js["instances"][4]["frame"].size(), 12u);
  EXPECT_EQ(js["materials"][3]["type"], "hair");
  EXPECT_EQ(js["materials"][3]["beta_m"], 0.25);  // shortest form, not 0.25000000372529
  EXPECT_EQ(js["cameras"][0]["lens"], 0.035);
}

static void saves_names_that_are_missing_or_clash() {
  auto scene           = make_test_scene();
  scene.shape_names    = {"a/b", "a/b", ""};
  scene.texture_names  = {};  // shorter than the textures: unnamed
  auto dir   = scratch_directory("names");
  auto error = std::string{};
  ASSERT_TRUE(save_scene(dir.file("scene.json"), scene, error)) << error;
  EXPECT_EQ(list_files(dir.path),
      (std::vector<std::string>{"scene.json", "shapes", "shapes/a_b-1.ply", "shapes/a_b.ply",
          "shapes/shape2.ply", "textures", "textures/texture0.exr", "textures/texture1.exr"}));
  auto loaded = scene_data{};
  ASSERT_TRUE(load_scene(dir.file("scene.json"), loaded, error)) << error;
  EXPECT_EQ(loaded.shape_names, (std::vector<std::string>{"a/b", "a/b", ""}));
  EXPECT_EQ(loaded.texture_names, (std::vector<std::string>{"", ""}));
}

static void loads_the_40_layout_and_round_trips_it() {
  auto dir = scratch_directory("layout-40");
  write_fixture_files(dir.path);
  write_file(dir.file("scene.json"), layout_40_json);
  auto scene    = scene_data{};
  auto error    = std::string{};
  auto warnings = std::vector<std::string>{};
  ASSERT_TRUE(load_scene(dir.file("scene.json"), scene, error, &warnings)) << error;
  EXPECT_TRUE(warnings.empty()) << warnings.front();
  EXPECT_EQ(scene.copyright, "after yocto-hair-2020");

  ASSERT_EQ(scene.cameras.size(), 1u);
  auto from = vec3f{-0.5f, 1.5f, 5}, to = vec3f{0.25f, 0.5f, 0};
  EXPECT_EQ(scene.cameras[0].frame, lookat_frame(from, to, {0, 1, 0}));
  EXPECT_FLOAT_EQ(scene.cameras[0].focus, length(from - to));
  EXPECT_FLOAT_EQ(scene.cameras[0].aspect, 1.777777778f);

  // Shapes and textures appear in the order they are first named.
  EXPECT_EQ(scene.shape_names,
      (std::vector<std::string>{"sphere", "hair-block", "hair-curl", "arealight"}));
  EXPECT_EQ(scene.shapes[1].curves.size(), 8u);
  EXPECT_EQ(scene.shapes[2].lines.size(), 15u);
  ASSERT_EQ(scene.texture_names, (std::vector<std::string>{"sky"}));
  EXPECT_EQ(scene.textures[0].width, 8);
  EXPECT_EQ(scene.environments[0].emission_tex, 0);
  EXPECT_EQ(scene.environments[0].emission, (vec3f{2, 2, 2}));

  EXPECT_EQ(scene.material_names,
      (std::vector<std::string>{"diffuse", "hair", "red", "arealight", "unused"}));
  auto& diffuse = scene.materials[0];
  EXPECT_EQ(diffuse.type, material_type::matte);  // it dresses a triangle mesh
  EXPECT_EQ(diffuse.color, (vec3f{0.8f, 0.4f, 0.05f}));
  auto& hair = scene.materials[1];  // colour only, on fibers only: hair
  EXPECT_EQ(hair.type, material_type::hair);
  EXPECT_TRUE(hair.hair.has_color);
  EXPECT_FALSE(hair.hair.has_sigma_a);
  EXPECT_EQ(hair.hair.color, (vec3f{0.8f, 0.4f, 0.05f}));
  EXPECT_EQ(hair.color, (vec3f{0, 0, 0}));
  auto& red = scene.materials[2];  // a hair key: hair; one pigment: the other is 0
  EXPECT_EQ(red.type, material_type::hair);
  EXPECT_EQ(red.hair.pheomelanin, 2);
  EXPECT_EQ(red.hair.eumelanin, 0);
  EXPECT_EQ(scene.materials[3].type, material_type::matte);
  EXPECT_EQ(scene.materials[3].emission, (vec3f{20, 20, 20}));
  EXPECT_EQ(scene.materials[4].type, material_type::matte);  // unused

  EXPECT_EQ(scene.instance_names,
      (std::vector<std::string>{"sphere", "hairblock", "red", "arealight1"}));
  EXPECT_EQ(scene.instances[1].frame,
      (frame3f{{1, 0, 0}, {0, 0, 1}, {0, -1, 0}, {0.5f, 1, -0.5f}}));
  EXPECT_EQ(scene.instances[1].shape, 1);
  EXPECT_EQ(scene.instances[1].material, 1);
  // Objects placed by lookat face their target with +z (cameras with -z).
  auto light = lookat_frame({-8, 10, 5}, {-6.5f, 3.5f, 0}, {0, 1, 0});
  EXPECT_EQ(scene.instances[3].frame, (frame3f{-light.x, light.y, -light.z, light.o}));
  EXPECT_GT(dot(scene.instances[3].frame.z, vec3f{-6.5f, 3.5f, 0} - vec3f{-8, 10, 5}), 0);

  expect_round_trip(scene, "layout-40-saved", false);
}

static void loads_the_mixed_layout_with_aliases_and_warns_about_extra_keys() {
  auto dir = scratch_directory("layout-mixed");
  write_fixture_files(dir.path);
  write_file(dir.file("scene.json"), layout_mixed_json);
  auto scene    = scene_data{};
  auto error    = std::string{};
  auto warnings = std::vector<std::string>{};
  ASSERT_TRUE(load_scene(dir.file("scene.json"), scene, error, &warnings)) << error;
  EXPECT_EQ(warnings.size(), 2u);
  EXPECT_TRUE(any_warning(warnings, {dir.file("scene.json"), "\"subdivs\""}));
  EXPECT_TRUE(
      any_warning(warnings, {dir.file("scene.json"), "material \"hairs\"", "\"roughness\""}));

  EXPECT_EQ(scene.camera_names, (std::vector<std::string>{"default"}));
  EXPECT_EQ(scene.cameras[0].aspect, 1);
  EXPECT_EQ(scene.environments[0].emission_tex, 0);
  auto& hairs = scene.materials[0].hair;
  EXPECT_EQ(scene.materials[0].type, material_type::hair);
  EXPECT_TRUE(hairs.has_sigma_a);
  EXPECT_FALSE(hairs.has_color);
  EXPECT_EQ(hairs.sigma_a, (vec3f{0.06f, 0.10f, 0.20f}));
  EXPECT_EQ(hairs.eumelanin, 0.3f);
  EXPECT_EQ(hairs.pheomelanin, 0);
  EXPECT_EQ(hairs.beta_m, 0.2f);
  EXPECT_EQ(hairs.beta_n, 0.4f);
  EXPECT_EQ(scene.materials[0].roughness, 0);  // not a hair key: dropped
  EXPECT_EQ(scene.instances[0].frame, (frame3f{{-1, 0, 0}, {0, 1, 0}, {0, 0, -1}, {0, 0, 0}}));

  expect_round_trip(scene, "layout-mixed-saved", true);
}

namespace {

// Loads a scene of one lines shape (or a triangle one) dressed by the given
// material json.
bool load_one_material(const std::string& directory, const std::string& material,
    material_data& result, std::vector<std::string>& warnings, std::string& error,
    bool triangles = false) {
  auto shape = triangles ? make_quad() : make_fibers(false, 1, 2);
  std::filesystem::create_directories(directory + "/shapes");
  if (!save_shape(directory + "/shapes/shape.ply", shape, error)) return false;
  auto text = R"({"shapes": [{"name": "shape", "uri": "shapes/shape.ply"}],
                  "materials": [)" + material + R"(],
                  "instances": [{"name": "i", "shape": 0, "material": 0}]})";
  write_file(directory + "/scene.json", text);
  auto scene = scene_data{};
  warnings.clear();
  if (!load_scene(directory + "/scene.json", scene, error, &warnings)) return false;
  result = scene.materials.at(0);
  return true;
}

}  // namespace

TEST(json, hair_keys_aliases_flags_and_defaults) {
  auto dir      = scratch_directory("hair-keys");
  auto material = material_data{};
  auto warnings = std::vector<std::string>{};
  auto error    = std::string{};
  auto load     = [&](const std::string& text, bool triangles = false) {
    material = {};
    EXPECT_TRUE(load_one_material(dir.path, text, material, warnings, error, triangles))
        << error << " in " << text;
    return material.hair;
  };

  // No colouring at all: eumelanin 1.3 (pbrt's rule), no flags.
  auto plain = load(R"({"name": "m", "type": "hair"})");
  EXPECT_EQ(material.type, material_type::hair);
  expect_same_hair(plain, hair_material{});
  EXPECT_EQ(plain.eumelanin, 1.3f);
  // One pigment: the other is 0.
  auto pheo = load(R"({"name": "m", "type": "hair", "pheomelanin": 0.5})");
  EXPECT_EQ(pheo.eumelanin, 0);
  EXPECT_EQ(pheo.pheomelanin, 0.5f);
  auto eu = load(R"({"name": "m", "type": "hair", "eumelanin": 0.5})");
  EXPECT_EQ(eu.eumelanin, 0.5f);
  EXPECT_EQ(eu.pheomelanin, 0);
  // Colour goes to the hair, with its flag.
  auto colored = load(R"({"name": "m", "type": "hair", "color": [0.2, 0.3, 0.4]})");
  EXPECT_TRUE(colored.has_color && !colored.has_sigma_a);
  EXPECT_EQ(colored.color, (vec3f{0.2f, 0.3f, 0.4f}));
  EXPECT_EQ(material.color, (vec3f{0, 0, 0}));
  // Everything given: both flags (the hair library applies the precedence).
  auto all = load(R"({"name": "m", "type": "hair", "sigma_a": [0.1, 0.2, 0.3],
      "color": [0.5, 0.5, 0.5], "eumelanin": 2, "pheomelanin": 0.25, "beta_m": 0.125,
      "beta_n": 0.75, "alpha": 5, "eta": 1.7})");
  EXPECT_TRUE(all.has_sigma_a && all.has_color);
  auto expected = hair_material{{0.1f, 0.2f, 0.3f}, {0.5f, 0.5f, 0.5f}, 2, 0.25f, 0.125f,
      0.75f, 5, 1.7f, true, true};
  expect_same_hair(all, expected);
  EXPECT_TRUE(warnings.empty());
  // camelCase aliases read the same values.
  auto camel = load(R"({"name": "m", "type": "hair", "sigmaA": [0.1, 0.2, 0.3],
      "color": [0.5, 0.5, 0.5], "eumelanin": 2, "pheomelanin": 0.25, "betaM": 0.125,
      "betaN": 0.75, "alpha": 5, "eta": 1.7})");
  expect_same_hair(camel, expected);

  // No type: hair keys make hair; colour alone makes hair on fibers only.
  load(R"({"name": "m", "eumelanin": 0.4})");
  EXPECT_EQ(material.type, material_type::hair);
  load(R"({"name": "m", "color": [0.4, 0.4, 0.4]})");
  EXPECT_EQ(material.type, material_type::hair);
  load(R"({"name": "m", "color": [0.4, 0.4, 0.4]})", true);
  EXPECT_EQ(material.type, material_type::matte);
  EXPECT_EQ(material.color, (vec3f{0.4f, 0.4f, 0.4f}));

  // Keys the type does not use, unknown keys and Yocto types we map.
  auto json_name = dir.file("scene.json");
  load(R"({"name": "m", "type": "hair", "roughness": 0.1, "subdivisions": 2})");
  EXPECT_TRUE(any_warning(warnings, {json_name, "material \"m\"", "\"roughness\""}));
  EXPECT_TRUE(any_warning(warnings, {json_name, "material \"m\"", "\"subdivisions\""}));
  load(R"({"name": "m", "type": "matte", "eumelanin": 0.1})", true);
  EXPECT_TRUE(any_warning(warnings, {json_name, "material \"m\"", "\"eumelanin\""}));
  expect_same_hair(material.hair, hair_material{});
  load(R"({"name": "m", "type": "plastic", "roughness": 0.3})", true);
  EXPECT_EQ(material.type, material_type::glossy);
  EXPECT_EQ(material.roughness, 0.3f);
  EXPECT_TRUE(any_warning(warnings, {json_name, "material \"m\"", "\"plastic\"", "glossy"}));
  load(R"({"name": "m", "type": "transparent"})", true);
  EXPECT_EQ(material.type, material_type::matte);
  EXPECT_TRUE(any_warning(warnings, {json_name, "material \"m\"", "\"transparent\""}));
}

namespace {

// Writes a scene json next to a lines shape, a quad and a sky texture, and
// expects load_scene to fail with a message naming the file and the parts.
void expect_scene_error(const scratch_directory& dir, const std::string& text,
    const std::vector<std::string>& parts) {
  auto error = std::string{};
  std::filesystem::create_directories(dir.file("shapes"));
  ASSERT_TRUE(save_shape(dir.file("shapes/line.ply"), make_fibers(false, 1, 2), error));
  ASSERT_TRUE(save_shape(dir.file("shapes/quad.ply"), make_quad(), error));
  auto filename = dir.file("scene.json");
  write_file(filename, text);
  auto scene    = scene_data{};
  auto warnings = std::vector<std::string>{};
  EXPECT_FALSE(load_scene(filename, scene, error, &warnings)) << text;
  EXPECT_TRUE(contains(error, filename)) << error;
  for (auto& part : parts) EXPECT_TRUE(contains(error, part)) << error << "\nlacks: " << part;
  EXPECT_TRUE(scene.shapes.empty() && scene.instances.empty());
}

// A valid scene with one material and one instance, to break one key at a time.
std::string scene_with(const std::string& material, const std::string& instance =
                                                        R"("shape": 0, "material": 0)") {
  return R"({"cameras": [{"name": "cam", "lens": 0.05}],
    "shapes": [{"name": "line", "uri": "shapes/line.ply"}, {"name": "quad", "uri": "shapes/quad.ply"}],
    "materials": [)" + material + R"(],
    "instances": [{"name": "inst", )" + instance + "}]}";
}

}  // namespace

static void rejects_bad_files_naming_file_and_place() {
  auto dir = scratch_directory("json-errors");
  auto error = std::string{};
  auto scene = scene_data{};
  EXPECT_FALSE(load_scene(dir.file("missing.json"), scene, error));
  EXPECT_TRUE(contains(error, dir.file("missing.json")) && contains(error, "cannot open"))
      << error;
  // Malformed json: nlohmann's byte position as line and column.
  expect_scene_error(dir, "{\n  \"cameras\": [\n    {\"lens\": 0.05,, \"film\": 1}\n  ]\n}",
      {"line 3, column 19", "malformed json"});
  expect_scene_error(dir, "{\"cameras\": [", {"line 1", "malformed json"});
  expect_scene_error(dir, "[1, 2]", {"expected a json object"});
  // A number beyond double range: located as well, not nlohmann's bare message.
  expect_scene_error(dir, "{\"cameras\": [\n  {\"lens\": -1e999}]}",
      {"line 2, column 12", "number -1e999 is out of range"});
}

static void rejects_wrong_types_and_references() {
  auto dir = scratch_directory("json-types");
  auto m   = std::string(R"({"name": "m", "type": "hair"})");
  expect_scene_error(dir, R"({"cameras": [{"name": "cam", "lens": "long"}]})",
      {"camera \"cam\"", "\"lens\"", "expected a number", "\"long\""});
  expect_scene_error(dir, R"({"cameras": {"cam": {"orthographic": 1}}})",
      {"camera \"cam\"", "\"orthographic\"", "true or false"});
  expect_scene_error(dir, R"({"cameras": [{"lookat": [0, 0, 1, 0, 0, 1, 0, 1, 0]}]})",
      {"camera 0", "\"lookat\"", "coincide"});
  expect_scene_error(dir, R"({"cameras": [{"lens": 0}]})", {"camera 0", "\"lens\"", "> 0"});
  expect_scene_error(dir, R"({"materials": "none"})", {"group \"materials\""});
  expect_scene_error(dir, R"({"materials": [3]})", {"material 0", "expected an object"});
  expect_scene_error(dir, R"({"materials": [{"name": 7}]})", {"material 0", "\"name\""});
  expect_scene_error(dir, scene_with(m, R"("frame": [1, 0, 0, 0, 1, 0, 0, 0, 1, 0, 0], "shape": 0, "material": 0)"),
      {"instance \"inst\"", "\"frame\"", "12 numbers", "11 values"});
  expect_scene_error(dir, scene_with(m, R"("shape": 1.5, "material": 0)"),
      {"instance \"inst\"", "\"shape\"", "index or name"});
  expect_scene_error(dir, scene_with(m, R"("shape": 2, "material": 0)"),
      {"instance \"inst\"", "\"shape\"", "reference 2 out of range"});
  expect_scene_error(dir, scene_with(m, R"("shape": 0, "material": -1)"),
      {"instance \"inst\"", "\"material\"", "out of range"});
  expect_scene_error(dir, scene_with(m, R"("shape": 0, "material": "nope")"),
      {"instance \"inst\"", "unknown material \"nope\""});
  expect_scene_error(dir, scene_with(m, R"("shape": 0)"), {"instance \"inst\"", "\"material\""});
  expect_scene_error(dir, scene_with(m, R"("frame": [1, 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0], "lookat": [0, 0, 1, 0, 0, 0, 0, 1, 0], "shape": 0, "material": 0)"),
      {"instance \"inst\"", "both"});
  expect_scene_error(dir, R"({"environments": [{"name": "sky", "emission_tex": 3}]})",
      {"environment \"sky\"", "\"emission_tex\"", "out of range"});
  expect_scene_error(dir, scene_with(R"({"name": "m", "color": "red"})"),
      {"material \"m\"", "\"color\"", "3 numbers"});
  expect_scene_error(dir, scene_with(R"({"name": "m", "type": "velvet"})"),
      {"material \"m\"", "\"type\"", "\"velvet\""});
  expect_scene_error(dir, scene_with(R"({"name": "m", "type": 1})"),
      {"material \"m\"", "\"type\"", "expected a string"});
}

static void rejects_bad_hair_values() {
  auto dir   = scratch_directory("json-hair");
  auto cases = std::vector<std::pair<std::string, std::string>>{
      {R"("beta_m": 1.5)", "\"beta_m\""}, {R"("betaN": -0.1)", "\"betaN\""},
      {R"("eumelanin": -1)", "\"eumelanin\""}, {R"("pheomelanin": -0.5)", "\"pheomelanin\""},
      {R"("eta": 0)", "\"eta\""}, {R"("eta": -1.5)", "\"eta\""},
      {R"("eumelanin": 1e39)", "not a finite"}, {R"("sigma_a": [1, 2])", "\"sigma_a\""},
      {R"("sigmaA": [1, -2, 3])", "\"sigmaA\""}, {R"("eumelanin": "dark")", "\"dark\""},
      {R"("color": [0.5, 1.5, 0.5])", "\"color\""}, {R"("alpha": 100)", "\"alpha\""},
      {R"("beta_m": null)", "\"beta_m\""}, {R"("eta": [1.5])", "\"eta\""}};
  for (auto& [key, part] : cases)
    expect_scene_error(dir, scene_with(R"({"name": "m", "type": "hair", )" + key + "}"),
        {"material \"m\"", part});
}

static void rejects_missing_files_and_hair_on_triangles() {
  auto dir = scratch_directory("json-files");
  expect_scene_error(dir,
      R"({"shapes": [{"name": "hair", "uri": "shapes/missing.ply"}],
          "materials": [{"type": "hair"}], "instances": [{"shape": 0, "material": 0}]})",
      {"shape \"hair\"", "shapes/missing.ply", "cannot open"});
  expect_scene_error(dir,
      R"({"materials": {"m": {}}, "objects": {"x": {"shape": "ghost", "material": "m"}}})",
      {"shape \"ghost\"", "used by instance \"x\"", "shapes/ghost.ply"});
  expect_scene_error(dir,
      R"({"textures": [{"name": "sky", "uri": "textures/sky.hdr"}],
          "environments": [{"emission_tex": 0}]})",
      {"texture \"sky\"", "textures/sky.hdr"});
  expect_scene_error(dir, R"({"environments": {"sky": {"emission_tex": "sky"}}})",
      {"texture \"sky\"", "used by environment \"sky\"", "textures/sky.{hdr"});
  expect_scene_error(dir, R"({"shapes": [{"name": "s"}]})", {"shape \"s\"", "\"uri\""});
  write_file(dir.file("shapes/broken.ply"), "ply\nformat ascii 1.0\nelement vertex 2\n");
  expect_scene_error(dir,
      R"({"shapes": [{"name": "b", "uri": "shapes/broken.ply"}],
          "materials": [{}], "instances": [{"shape": 0, "material": 0}]})",
      {"shape \"b\"", "shapes/broken.ply", "end_header"});
  // Hair on a triangle mesh: validation names instance, shape and material.
  expect_scene_error(dir, scene_with(R"({"name": "m", "type": "hair"})", R"("shape": 1, "material": 0)"),
      {"instance \"inst\"", "shape \"quad\"", "material \"m\""});
}

static void failed_saves_leave_nothing_behind() {
  auto dir   = scratch_directory("json-save-errors");
  auto error = std::string{};
  // An invalid scene is refused before anything is written.
  auto bad_reference               = make_test_scene();
  bad_reference.instances[0].shape = 9;
  EXPECT_FALSE(save_scene(dir.file("scene.json"), bad_reference, error));
  EXPECT_TRUE(contains(error, dir.file("scene.json")) && contains(error, "instance \"floor\""))
      << error;
  EXPECT_TRUE(list_files(dir.path).empty());
  // A texture that cannot be saved, after the shapes were: they are removed.
  auto bad_texture        = make_test_scene();
  bad_texture.textures[1] = {};
  EXPECT_FALSE(save_scene(dir.file("scene.json"), bad_texture, error));
  EXPECT_TRUE(contains(error, "pattern.exr")) << error;
  EXPECT_TRUE(list_files(dir.path).empty());
  // Files that were there before a failed save stay.
  write_file(dir.file("shapes/quad.ply"), "precious");
  EXPECT_FALSE(save_scene(dir.file("scene.json"), bad_texture, error));
  EXPECT_EQ(list_files(dir.path), (std::vector<std::string>{"shapes", "shapes/quad.ply"}));
  EXPECT_FALSE(save_scene(dir.file("no/such/dir/scene.json"), make_test_scene(), error));
  EXPECT_TRUE(contains(error, "no/such/dir")) << error;
  EXPECT_EQ(list_files(dir.path), (std::vector<std::string>{"shapes", "shapes/quad.ply"}));
}

// The real Yocto hair scenes in ../shared, with their missing hair geometry
// (and the sky maps the 2023 folders lack) replaced by small stand-ins
// written into a temporary copy of each scene folder.
TEST(json, loads_every_real_yocto_scene_with_standin_hair) {
  auto root = std::filesystem::path(YOCTO_SHARED_DIR) / "data" / "yocto";
  if (!std::filesystem::exists(root)) GTEST_SKIP() << "no " << root;
  auto filenames = std::vector<std::filesystem::path>{};
  for (auto& entry : std::filesystem::recursive_directory_iterator(root))
    if (entry.path().extension() == ".json") filenames.push_back(entry.path());
  std::sort(filenames.begin(), filenames.end());
  EXPECT_GE(filenames.size(), 7u);

  for (auto k = 0; k < (int)filenames.size(); k++) {
    auto& original = filenames[k];
    SCOPED_TRACE(original.string());
    auto dir = scratch_directory("real-" + std::to_string(k));
    std::filesystem::copy(original.parent_path(), dir.path,
        std::filesystem::copy_options::recursive);
    auto filename = dir.file(original.filename().string());

    // The files the scene names: uris (4.2) or names (4.0).
    auto js       = nlohmann::json::parse(read_file(filename));
    auto shapes   = std::vector<std::string>{};
    auto textures = std::vector<std::string>{};
    auto group = [&](const char* name) {
      return js.contains(name) ? js[name] : nlohmann::json::array();
    };
    for (auto& shape : group("shapes")) shapes.push_back(shape["uri"]);
    for (auto& object : group("objects"))
      shapes.push_back("shapes/" + object["shape"].get<std::string>() + ".ply");
    for (auto& texture : group("textures")) textures.push_back(texture["uri"]);
    for (auto& environment : group("environments"))
      if (environment.contains("emission_tex") && environment["emission_tex"].is_string())
        textures.push_back("textures/" + environment["emission_tex"].get<std::string>() + ".hdr");
    auto error = std::string{};
    std::filesystem::create_directories(dir.file("shapes"));
    std::filesystem::create_directories(dir.file("textures"));
    for (auto& shape : shapes) {
      if (std::filesystem::exists(dir.file(shape))) continue;
      // Curves for some scenes, lines for the others.
      ASSERT_TRUE(save_shape(dir.file(shape), make_fibers(k % 2 == 0, 20, 3), error)) << error;
    }
    for (auto& texture : textures) {
      if (std::filesystem::exists(dir.file(texture))) continue;
      ASSERT_TRUE(save_image(dir.file(texture), make_texture(8, 4, 1), error)) << error;
    }

    auto scene    = scene_data{};
    auto warnings = std::vector<std::string>{};
    ASSERT_TRUE(load_scene(filename, scene, error, &warnings)) << error;
    for (auto& warning : warnings) EXPECT_TRUE(contains(warning, filename)) << warning;
    EXPECT_EQ(scene.cameras.size(), 1u);
    EXPECT_EQ(scene.environments.size(), 1u);
    EXPECT_FALSE(scene.instances.empty());
    auto hair_instances = 0;
    for (auto& instance : scene.instances) {
      if (scene.materials[instance.material].type != material_type::hair) continue;
      hair_instances++;
      EXPECT_TRUE(is_fiber(scene.shapes[instance.shape]));
    }
    EXPECT_GT(hair_instances, 0);
  }
}

// Grouped so that ctest starts few processes: each one pays for loading
// OpenImageIO and its libraries (about 0.3 s).
TEST(json, round_trips_the_42_layout) {
  round_trips_every_element_with_binary_and_ascii_shapes();
  saves_names_that_are_missing_or_clash();
}

TEST(json, loads_the_40_and_mixed_layouts) {
  loads_the_40_layout_and_round_trips_it();
  loads_the_mixed_layout_with_aliases_and_warns_about_extra_keys();
}

// A PLY named by 20000 shape elements (some by other paths to the same
// file) is loaded once, as one shape that every instance uses; textures
// likewise. Distinct files are checked in sum against the memory limit.
TEST(json, each_file_loads_once_and_the_sum_fits_the_memory_limit) {
  auto dir   = scratch_directory("json-same-files");
  auto error = std::string{};
  std::filesystem::create_directories(dir.file("shapes"));
  ASSERT_TRUE(save_shape(dir.file("shapes/quad.ply"), make_quad(), error)) << error;
  ASSERT_TRUE(save_image(dir.file("sky.exr"), make_texture(4, 2, 1), error)) << error;
  std::filesystem::create_symlink("shapes/quad.ply", dir.file("link.ply"));
  auto uris = std::vector<std::string>{"shapes/quad.ply", "./shapes/quad.ply",
      "shapes/../shapes/quad.ply", "link.ply", dir.file("shapes/quad.ply")};
  auto shapes = std::string{}, instances = std::string{};
  for (auto i = 0; i < 20000; i++) {
    shapes += std::string(i ? ", " : "") + R"({"uri": ")" + uris[i % uris.size()] + "\"}";
    instances += std::string(i ? ", " : "") + R"({"shape": )" + std::to_string(i) +
                 R"(, "material": )" + std::to_string(i % 2) + "}";
  }
  write_file(dir.file("scene.json"),
      R"({"textures": [{"uri": "sky.exr"}, {"uri": "./sky.exr"}],
          "materials": [{"color_tex": 1}, {"emission": [1, 1, 1], "emission_tex": 0}],
          "environments": [{"emission": [1, 1, 1], "emission_tex": 1}],
          "shapes": [)" + shapes + R"(], "instances": [)" + instances + "]}");
  auto scene = scene_data{};
  ASSERT_TRUE(load_scene(dir.file("scene.json"), scene, error)) << error;
  EXPECT_EQ(scene.shapes.size(), 1u);
  EXPECT_EQ(scene.shape_names.size(), 1u);
  EXPECT_EQ(scene.instances.size(), 20000u);
  auto all_first = true;
  for (auto& instance : scene.instances) all_first = all_first && instance.shape == 0;
  EXPECT_TRUE(all_first);
  expect_same_shape(scene.shapes[0], make_quad());
  EXPECT_EQ(scene.textures.size(), 1u);
  EXPECT_EQ(scene.materials[0].color_tex, 0);
  EXPECT_EQ(scene.materials[1].emission_tex, 0);
  EXPECT_EQ(scene.environments[0].emission_tex, 0);

  // Distinct files, each within the limit, in sum over it.
  auto sphere = make_sphere_shape(32, 1);
  for (auto name : {"a", "b", "c"})
    ASSERT_TRUE(save_shape(dir.file(std::string("shapes/") + name + ".ply"), sphere, error));
  write_file(dir.file("three.json"), R"({"shapes": [{"name": "a", "uri": "shapes/a.ply"},
      {"name": "b", "uri": "shapes/b.ply"}, {"name": "c", "uri": "shapes/c.ply"}]})");
  auto bytes = sphere.positions.size() * (12 + 12 + 8) + sphere.triangles.size() * 12;
  auto loaded = load_scene(dir.file("three.json"), scene, error, nullptr, 2.5 * bytes);
  EXPECT_FALSE(loaded);
  EXPECT_TRUE(contains(error, dir.file("three.json") + ": loading the shapes up to shape \"c\"") &&
              contains(error, "over the memory limit"))
      << error;
}

TEST(json, rejects_bad_input_naming_file_and_place) {
  rejects_bad_files_naming_file_and_place();
  rejects_wrong_types_and_references();
  rejects_bad_hair_values();
  rejects_missing_files_and_hair_on_triangles();
  failed_saves_leave_nothing_behind();
}

// -----------------------------------------------------------------------------
// HAIR PARAMETERS: the table's keys in files, errors and fingerprints
// -----------------------------------------------------------------------------
namespace {

// A hair material that sets every variation parameter of the table.
hair_material make_varying_hair() {
  auto hair                = hair_material{};
  hair.eumelanin           = 0.8f;
  hair.pheomelanin         = 0.4f;
  hair.random_melanin      = 0.3f;
  hair.random_roughness    = 0.25f;
  hair.tip_eumelanin       = 0.2f;
  hair.has_tip_eumelanin   = true;
  hair.tip_pheomelanin     = 1.5f;
  hair.has_tip_pheomelanin = true;
  hair.tip_color           = {0.9f, 0.8f, 0.7f};
  hair.has_tip_color       = true;
  hair.tip_sigma_a         = {0.05f, 0.1f, 0.2f};
  hair.has_tip_sigma_a     = true;
  hair.tip_start           = 0.4f;
  hair.tint                = {1, 0.6f, 0.5f};
  return hair;
}

// A valid value of the parameter other than `current`.
vec3f other_hair_value(const hair_parameter& parameter, const vec3f& current) {
  auto candidates = {parameter.min, parameter.min + 0.25f, parameter.min + 0.5f,
      parameter.min + 1, parameter.min + 2};
  for (auto candidate : candidates)
    if (is_hair_parameter_valid(parameter, vec3f{candidate}) && vec3f{candidate} != current)
      return vec3f{candidate};
  ADD_FAILURE() << "no other valid value of " << parameter.name;
  return current;
}

// The json text of a parameter's value, each number in its shortest form.
std::string json_value(const hair_parameter& parameter, const vec3f& value) {
  auto number = [](float x) {
    char buffer[32];
    return std::string(buffer, std::to_chars(buffer, buffer + sizeof(buffer), x).ptr);
  };
  if (parameter.kind == hair_parameter_kind::number) return number(value.x);
  return "[" + number(value.x) + ", " + number(value.y) + ", " + number(value.z) + "]";
}

}  // namespace

TEST(json, every_hair_parameter_round_trips) {
  // The material below leaves no variation parameter at its default.
  auto varying = make_varying_hair();
  for (auto& parameter : hair_parameters)
    if (parameter.group == hair_parameter_group::variation)
      EXPECT_TRUE(is_hair_parameter_set(varying, parameter)) << parameter.name;

  // Saved and loaded: the same material, every key written.
  auto scene              = make_test_scene();
  scene.materials[4].hair = varying;
  expect_round_trip(scene, "hair-parameters", false);
  auto dir   = scratch_directory("hair-parameters-keys");
  auto error = std::string{};
  ASSERT_TRUE(save_scene(dir.file("scene.json"), scene, error)) << error;
  auto js = nlohmann::json::parse(read_file(dir.file("scene.json")));
  for (auto& parameter : hair_parameters) {
    if (parameter.group != hair_parameter_group::variation) continue;
    ASSERT_TRUE(js["materials"][4].contains(parameter.name)) << parameter.name;
    EXPECT_EQ(js["materials"][4][parameter.name],
        nlohmann::json::parse(json_value(parameter, get_hair_parameter(varying, parameter))))
        << parameter.name;
    // A material without variation writes none of its keys: files stay
    // as they were before these keys existed.
    EXPECT_FALSE(js["materials"][3].contains(parameter.name)) << parameter.name;
  }
  // name, type, emission, sigma_a, color, eumelanin, pheomelanin, beta_m,
  // beta_n, alpha, eta: what files had before the variation keys.
  EXPECT_EQ(js["materials"][3].size(), 11u) << js["materials"][3].dump();

  // Written by hand, loaded, saved, loaded: the same material each time.
  auto text = std::string{R"({"name": "m", "type": "hair")"};
  for (auto& parameter : hair_parameters)
    if (parameter.group == hair_parameter_group::variation)
      text += ", \"" + std::string(parameter.name) +
              "\": " + json_value(parameter, get_hair_parameter(varying, parameter));
  text += R"(, "eumelanin": 0.8, "pheomelanin": 0.4})";
  auto material = material_data{};
  auto warnings = std::vector<std::string>{};
  ASSERT_TRUE(load_one_material(dir.file("hand"), text, material, warnings, error)) << error;
  EXPECT_TRUE(warnings.empty()) << warnings.front();
  expect_same_hair(material.hair, varying);
  // Each key lands in the field of its name.
  auto& hand = material.hair;
  EXPECT_EQ(hand.random_melanin, 0.3f);
  EXPECT_EQ(hand.random_roughness, 0.25f);
  EXPECT_TRUE(hand.has_tip_eumelanin && hand.tip_eumelanin == 0.2f);
  EXPECT_TRUE(hand.has_tip_pheomelanin && hand.tip_pheomelanin == 1.5f);
  EXPECT_TRUE(hand.has_tip_color && hand.tip_color == (vec3f{0.9f, 0.8f, 0.7f}));
  EXPECT_TRUE(hand.has_tip_sigma_a && hand.tip_sigma_a == (vec3f{0.05f, 0.1f, 0.2f}));
  EXPECT_EQ(hand.tip_start, 0.4f);
  EXPECT_EQ(hand.tint, (vec3f{1, 0.6f, 0.5f}));
  auto loaded = scene_data{};
  ASSERT_TRUE(load_scene(dir.file("hand/scene.json"), loaded, error)) << error;
  std::filesystem::create_directories(dir.file("again"));
  ASSERT_TRUE(save_scene(dir.file("again/scene.json"), loaded, error)) << error;
  auto again = scene_data{};
  ASSERT_TRUE(load_scene(dir.file("again/scene.json"), again, error)) << error;
  expect_same_hair(again.materials[0].hair, varying);
}

TEST(json, hair_parameters_out_of_range_or_of_the_wrong_type_are_errors) {
  auto dir      = scratch_directory("hair-parameters-errors");
  auto material = material_data{};
  auto warnings = std::vector<std::string>{};
  auto filename = dir.file("scene.json");
  for (auto& parameter : hair_parameters) {
    auto key  = "\"" + std::string(parameter.name) + "\"";
    auto rgb  = parameter.kind == hair_parameter_kind::rgb;
    auto bads = std::vector<std::pair<std::string, std::string>>{};  // value, error part
    auto outside = std::vector<float>{parameter.min_open ? parameter.min : parameter.min - 1};
    if (parameter.max != flt_max)
      outside.push_back(parameter.max_open ? parameter.max : parameter.max + 1);
    for (auto value : outside) {
      auto text = nlohmann::json(value).dump();
      auto min  = nlohmann::json(parameter.min).dump();
      bads.push_back({rgb ? "[" + min + ", " + text + ", " + min + "]" : text, "got"});
    }
    bads.push_back({rgb ? "0.5" : "[0.5]", "expected"});
    bads.push_back({rgb ? "[0.5, 0.5]" : "\"dark\"", "expected"});
    bads.push_back({rgb ? "[0.5, \"dark\", 0.5]" : "true", "expected"});
    for (auto& [value, part] : bads) {
      auto text  = R"({"name": "m", "type": "hair", )" + key + ": " + value + "}";
      auto error = std::string{};
      EXPECT_FALSE(load_one_material(dir.path, text, material, warnings, error)) << text;
      for (auto expected : {filename, std::string("material \"m\""), key, std::string(part)})
        EXPECT_TRUE(contains(error, expected)) << text << "\n" << error << "\nlacks " << expected;
      EXPECT_EQ(error.find('\n'), std::string::npos) << error;
    }
  }
  // The range each error states is the table's (colour's lower bound is
  // every material's colour's, checked before the type is known).
  auto error = std::string{};
  EXPECT_FALSE(load_one_material(
      dir.path, R"({"type": "hair", "tip_start": 1})", material, warnings, error));
  EXPECT_TRUE(contains(error, "\"tip_start\": expected a number in [0, 1), got 1")) << error;
  EXPECT_FALSE(load_one_material(
      dir.path, R"({"type": "hair", "tint": [1, 1.5, 1]})", material, warnings, error));
  EXPECT_TRUE(contains(error, "\"tint\": expected numbers in [0, 1], got 1.5")) << error;
  EXPECT_FALSE(load_one_material(
      dir.path, R"({"type": "hair", "eta": 10.5})", material, warnings, error));
  EXPECT_TRUE(contains(error, "\"eta\": expected a number in [1, 10], got 10.5")) << error;
  // The ends of closed ranges are valid.
  EXPECT_TRUE(load_one_material(dir.path,
      R"({"type": "hair", "eta": 1, "random_melanin": 1, "tip_start": 0, "tint": [0, 0, 0]})",
      material, warnings, error))
      << error;
  EXPECT_TRUE(load_one_material(dir.path, R"({"type": "hair", "eta": 10, "alpha": -90})",
      material, warnings, error))
      << error;
}

// A material that varies nothing keeps the fingerprint it had before the
// variation parameters existed (the values below are what fingerprint_scene
// gave then); any parameter of the table changed alone changes it.
TEST(json, fingerprint_follows_every_hair_parameter) {
  EXPECT_EQ(fingerprint_scene(make_test_scene()), 1981355987844060304ull);
  auto dir = scratch_directory("hair-fingerprint");
  write_fixture_files(dir.path);
  auto error = std::string{};
  auto scene = scene_data{};
  write_file(dir.file("mixed.json"), layout_mixed_json);
  ASSERT_TRUE(load_scene(dir.file("mixed.json"), scene, error)) << error;
  EXPECT_EQ(fingerprint_scene(scene), 4198811764396233581ull);
  write_file(dir.file("40.json"), layout_40_json);
  ASSERT_TRUE(load_scene(dir.file("40.json"), scene, error)) << error;
  EXPECT_EQ(fingerprint_scene(scene), 4029181044731584112ull);

  for (auto& hair : {hair_material{}, make_varying_hair()}) {
    auto base = make_test_scene();
    base.materials[4].hair = hair;
    auto fingerprint       = fingerprint_scene(base);
    for (auto& parameter : hair_parameters) {
      auto changed = base;
      set_hair_parameter(changed.materials[4].hair, parameter,
          other_hair_value(parameter, get_hair_parameter(hair, parameter)));
      EXPECT_NE(fingerprint_scene(changed), fingerprint) << parameter.name;
      if (!parameter.has) continue;
      auto flagged = base;
      flagged.materials[4].hair.*parameter.has = !(hair.*parameter.has);
      EXPECT_NE(fingerprint_scene(flagged), fingerprint) << parameter.name << " flag";
    }
  }
}
