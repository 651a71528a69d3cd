//
// Tests of Yocto/PbrtIO: the pbrt tokenizer and parser (each directive,
// parameter type, both syntaxes, includes), bad input, the camera alone and
// the pbrt curves writer. Scenes are written to a temporary directory at
// test time.
//

#include <sys/stat.h>
#include <yocto/yocto_image.h>
#include <yocto/yocto_ply.h>

#include <random>

#include "test_pbrtio.h"

// -----------------------------------------------------------------------------
// LEXICAL DETAILS AND PARAMETERS
// -----------------------------------------------------------------------------

TEST(pbrtio, lexical_details) {
  // Comments, values with and without brackets, tabs and spaces inside the
  // declaration, `.3`, `+1`, `-0` and `1e-1` numbers, v4 bare booleans.
  auto dir   = temp_dir{};
  auto scene = scene_data{};
  auto error = std::string{};
  auto text  = std::string{
      "# a comment\n"
      "Film \"image\" \"integer xresolution\" 300 # trailing comment\n"
      "   \"integer yresolution\" [ 200 ]\n"
      "Camera \"perspective\" \"float fov\" [ 4.5e1 ]\n"
      "WorldBegin\n"
      "Material \"hair\" \"float\teumelanin\" .3 \"float   beta_m\" [+.25] \"float alpha\" -0\n"
      "  \"float beta_n\" 1e-1\n"
      "AreaLightSource \"diffuse\" \"rgb L\" [1 2 3] \"bool twosided\" true\n"
      "Shape \"curve\" \"point3 P\" [0 0 0 0 0 1 0 0 2 0 0 3] \"float width\" .1\n"};
  ASSERT_TRUE(load_text(dir, text, scene, error)) << error;
  EXPECT_EQ(scene.settings.resolution, 300);
  EXPECT_FLOAT_EQ(scene.cameras[0].aspect, 1.5f);
  ASSERT_EQ(scene.materials.size(), 1u);
  auto& hair = scene.materials[0].hair;
  EXPECT_EQ(scene.materials[0].type, material_type::hair);
  EXPECT_FLOAT_EQ(hair.eumelanin, 0.3f);
  EXPECT_FLOAT_EQ(hair.pheomelanin, 0.0f);
  EXPECT_FLOAT_EQ(hair.beta_m, 0.25f);
  EXPECT_FLOAT_EQ(hair.beta_n, 0.1f);
  EXPECT_FLOAT_EQ(hair.alpha, 0.0f);
  expect_near(scene.materials[0].emission, {1, 2, 3});
}

TEST(pbrtio, numbers_parse_exactly) {
  // 30000 numbers (fixed seed) in the formats real files use: %g with 6 and
  // 9 digits, fixed point, exponents, leading dot, huge and tiny. Each must
  // equal strtof's correctly rounded value bit for bit.
  auto dir     = temp_dir{};
  auto rng     = std::mt19937{42};
  auto uniform = std::uniform_real_distribution<double>{-1, 1};
  auto formats = std::vector<const char*>{"%.6g", "%.9g", "%.3f", "%.7e", "%.12f", "%.2e"};
  auto numbers = std::vector<std::string>{};
  for (auto i = 0; i < 30000; i++) {
    auto value = uniform(rng) * std::pow(10.0, (int)(uniform(rng) * 12));
    char buffer[64];
    std::snprintf(buffer, sizeof(buffer), formats[i % formats.size()], value);
    auto text = std::string{buffer};
    if (i % 7 == 0 && text.rfind("0.", 0) == 0) text = text.substr(1);  // ".3" style
    numbers.push_back(text);
  }
  auto text = std::string{"WorldBegin\nShape \"trianglemesh\" \"point P\" [\n"};
  for (auto& number : numbers) text += number + "\n";
  text += "] \"integer indices\" [ 0 1 2 ]\n";
  auto scene = scene_data{};
  auto error = std::string{};
  ASSERT_TRUE(load_text(dir, text, scene, error)) << error;
  auto& positions = scene.shapes[0].positions;
  ASSERT_EQ(positions.size() * 3, numbers.size());
  for (auto i = 0; i < (int)numbers.size(); i++) {
    auto expected = std::strtof(numbers[i].c_str(), nullptr);
    ASSERT_EQ(positions[i / 3][i % 3], expected) << numbers[i];
  }
}

TEST(pbrtio, parameter_types) {
  // Every parameter type we read: float, integer, bool (quoted and bare),
  // string, rgb, color (v3 alias), spectrum, blackbody, point/point3,
  // normal/normal3, point2 and texture.
  auto dir      = temp_dir{};
  auto scene    = scene_data{};
  auto error    = std::string{};
  auto warnings = std::vector<std::string>{};
  auto text     = std::string{
      "Sampler \"halton\" \"integer pixelsamples\" 64\n"
      "Integrator \"path\" \"integer maxdepth\" [ 7 ]\n"
      "WorldBegin\n"
      "Texture \"grey\" \"spectrum\" \"constant\" \"rgb value\" [ .25 .5 .75 ]\n"
      "MakeNamedMaterial \"a\" \"string type\" \"matte\" \"color Kd\" [ .1 .2 .3 ]\n"
      "MakeNamedMaterial \"b\" \"string type\" \"diffuse\" \"spectrum reflectance\" "
      "[ 400 .2 500 .4 600 .6 ]\n"
      "MakeNamedMaterial \"c\" \"string type\" \"diffuse\" \"texture reflectance\" \"grey\"\n"
      "MakeNamedMaterial \"d\" \"string type\" \"coateddiffuse\" \"float roughness\" .0625 "
      "\"bool remaproughness\" \"false\"\n"
      "AttributeBegin\n"
      "AreaLightSource \"diffuse\" \"blackbody L\" [ 6500 ]\n"
      "NamedMaterial \"a\" Shape \"sphere\"\n"
      "AttributeEnd\n"
      "NamedMaterial \"b\" Shape \"trianglemesh\" \"point P\" [0 0 0 1 0 0 0 1 0] "
      "\"normal N\" [0 0 1 0 0 1 0 0 1] \"point2 uv\" [0 0 1 0 0 1] \"integer indices\" [0 1 2]\n"
      "NamedMaterial \"c\" Shape \"trianglemesh\" \"point3 P\" [0 0 0 1 0 0 0 1 0] "
      "\"normal3 N\" [0 0 2 0 0 2 0 0 2] \"float st\" [0 0 1 0 0 1]\n"
      "NamedMaterial \"d\" Shape \"disk\"\n"};
  ASSERT_TRUE(load_text(dir, text, scene, error, &warnings)) << error;
  EXPECT_EQ(scene.settings.samples, 64);
  EXPECT_EQ(scene.settings.bounces, 7);
  ASSERT_EQ(scene.materials.size(), 4u);
  expect_near(scene.materials[0].color, {.1f, .2f, .3f});
  auto emission = scene.materials[0].emission;
  EXPECT_GT(emission.z, 0);  // a 6500K blackbody is close to white
  EXPECT_NEAR(max_component(emission), 1, 1e-5f);
  EXPECT_GT(min_component(emission), 0.7f);
  expect_near(scene.materials[1].color, {.4f, .4f, .4f});  // spectrum mean
  expect_near(scene.materials[2].color, {.25f, .5f, .75f});
  EXPECT_EQ(scene.materials[3].type, material_type::glossy);
  EXPECT_NEAR(scene.materials[3].roughness, 0.25f, 1e-6f);  // alpha = .0625 = .25^2
  ASSERT_EQ(scene.shapes.size(), 4u);
  EXPECT_EQ(scene.shapes[1].triangles.size(), 1u);
  expect_near(scene.shapes[1].normals[2], {0, 0, 1});
  EXPECT_EQ(scene.shapes[1].texcoords[1], vec2f(1, 0));
  expect_near(scene.shapes[2].normals[0], {0, 0, 1});  // normalized
  EXPECT_EQ(scene.shapes[2].texcoords.size(), 3u);
  EXPECT_TRUE(any_contains(warnings, "blackbody"));
  EXPECT_TRUE(any_contains(warnings, "spectra"));
}

TEST(pbrtio, ignored_parameters_are_listed_once) {
  auto dir      = temp_dir{};
  auto scene    = scene_data{};
  auto error    = std::string{};
  auto warnings = std::vector<std::string>{};
  auto text     = std::string{"WorldBegin\n"};
  for (auto i = 0; i < 5; i++)
    text += "Shape \"sphere\" \"float radius\" 1 \"float zmax\" .5 \"integer splitdepth\" 2\n";
  ASSERT_TRUE(load_text(dir, text, scene, error, &warnings)) << error;
  auto count = 0;
  for (auto& warning : warnings) count += contains(warning, "\"float zmax\"") ? 1 : 0;
  EXPECT_EQ(count, 1);
  EXPECT_TRUE(any_contains(warnings, "scene.pbrt:2:"));
  EXPECT_TRUE(any_contains(warnings, "\"integer splitdepth\""));
}

// -----------------------------------------------------------------------------
// TRANSFORMS AND CAMERA
// -----------------------------------------------------------------------------

static frame3f first_instance_frame(const temp_dir& dir, const std::string& transforms) {
  auto scene = scene_data{};
  auto error = std::string{};
  auto text  = "WorldBegin\n" + transforms + "\nShape \"sphere\"\n";
  EXPECT_TRUE(load_text(dir, text, scene, error)) << error;
  return scene.instances.empty() ? frame3f{} : scene.instances[0].frame;
}

TEST(pbrtio, transform_directives) {
  auto dir = temp_dir{};
  // Translate then Scale: points are scaled first, then translated.
  auto frame = first_instance_frame(dir, "Translate 1 2 3 Scale 2 2 2");
  expect_near(transform_point(frame, {1, 1, 1}), {3, 4, 5});
  // Rotate about z by 90 degrees: x goes to y.
  frame = first_instance_frame(dir, "Rotate 90 0 0 1");
  expect_near(transform_point(frame, {1, 0, 0}), {0, 1, 0});
  // Transform is column-major with the translation in values 12..14.
  frame = first_instance_frame(dir, "Transform [ 0 1 0 0  -1 0 0 0  0 0 1 0  5 6 7 1 ]");
  expect_near(transform_point(frame, {1, 0, 0}), {5, 7, 7});
  // ConcatTransform composes with the current transform; bare numbers too.
  frame = first_instance_frame(dir, "Translate 1 0 0 ConcatTransform 2 0 0 0 0 2 0 0 0 0 2 0 0 0 0 1");
  expect_near(transform_point(frame, {1, 1, 1}), {3, 2, 2});
  // Identity resets; CoordinateSystem/CoordSysTransform save and restore.
  frame = first_instance_frame(dir,
      "Translate 1 0 0 CoordinateSystem \"mine\" Identity Scale 3 3 3 CoordSysTransform \"mine\"");
  expect_near(transform_point(frame, {0, 0, 0}), {1, 0, 0});
  expect_near(transform_vector(frame, {1, 1, 1}), {1, 1, 1});
  // LookAt as a world transform: the eye maps to the origin.
  frame = first_instance_frame(dir, "LookAt 0 0 5  0 0 0  0 1 0");
  expect_near(transform_point(frame, {0, 0, 5}), {0, 0, 0});
}

TEST(pbrtio, attribute_and_transform_scoping) {
  auto dir   = temp_dir{};
  auto scene = scene_data{};
  auto error = std::string{};
  auto text  = std::string{
      "WorldBegin\n"
      "Material \"matte\" \"rgb Kd\" [ 1 0 0 ]\n"
      "AttributeBegin\n"
      "  Translate 1 0 0\n"
      "  Material \"matte\" \"rgb Kd\" [ 0 1 0 ]\n"
      "  AreaLightSource \"diffuse\" \"rgb L\" [ 4 4 4 ]\n"
      "  Shape \"sphere\"\n"
      "  TransformBegin\n"
      "    Translate 0 1 0\n"
      "    Material \"matte\" \"rgb Kd\" [ 0 0 1 ]\n"
      "  TransformEnd\n"
      "  Shape \"sphere\"\n"  // translate (1,0,0), blue, emissive
      "AttributeEnd\n"
      "Shape \"sphere\"\n"};  // identity, red, not emissive
  ASSERT_TRUE(load_text(dir, text, scene, error)) << error;
  // No Film: pbrt's default aspect, resolution left to the renderer.
  EXPECT_EQ(scene.settings.resolution, 0);
  EXPECT_FLOAT_EQ(scene.cameras[0].aspect, 640.0f / 480.0f);
  ASSERT_EQ(scene.instances.size(), 3u);
  auto material = [&](int i) { return scene.materials[scene.instances[i].material]; };
  expect_near(scene.instances[0].frame.o, {1, 0, 0});
  expect_near(material(0).color, {0, 1, 0});
  expect_near(material(0).emission, {4, 4, 4});
  expect_near(scene.instances[1].frame.o, {1, 0, 0});  // TransformEnd restored
  expect_near(material(1).color, {0, 0, 1});           // material is not a transform
  expect_near(material(1).emission, {4, 4, 4});
  expect_near(scene.instances[2].frame.o, {0, 0, 0});
  expect_near(material(2).color, {1, 0, 0});
  expect_near(material(2).emission, {0, 0, 0});
}

TEST(pbrtio, lookat_camera_matches_pbrt_image_orientation) {
  // pbrt: camera at the origin looking along +y with z up. pbrt's camera
  // space is left-handed with x = cross(up, dir) = -x_world to the image's
  // right, so a point at world -x appears on the right of pbrt's image.
  auto dir   = temp_dir{};
  auto scene = scene_data{};
  auto error = std::string{};
  auto text  = std::string{
      "LookAt 0 0 0  0 10 0  0 0 1\n"
      "Camera \"perspective\" \"float fov\" 40\n"
      "Film \"rgb\" \"integer xresolution\" 400 \"integer yresolution\" 200\n"
      "WorldBegin\nTranslate 0 10 0\nShape \"sphere\"\n"};
  ASSERT_TRUE(load_text(dir, text, scene, error)) << error;
  ASSERT_EQ(scene.cameras.size(), 1u);
  auto& camera = scene.cameras[0];
  expect_near(camera.frame.o, {0, 0, 0});
  expect_near(-camera.frame.z, {0, 1, 0});  // -z from eye to target
  expect_near(camera.frame.x, {-1, 0, 0});  // image right, as pbrt
  expect_near(camera.frame.y, {0, 0, 1});   // image up
  // A ray through the right edge of the image goes towards world -x, and
  // one through the top edge goes up.
  auto right = eval_camera(camera, {1, 0.5f}, {0.5f, 0.5f});
  EXPECT_LT(right.d.x, -0.1f);
  auto top = eval_camera(camera, {0.5f, 0}, {0.5f, 0.5f});
  EXPECT_GT(top.d.z, 0.1f);
  // fov spans the shorter side (the height here): the top-edge ray is 20
  // degrees above the axis.
  EXPECT_NEAR(degrees(std::atan2(top.d.z, top.d.y)), 20, 1e-3f);
  EXPECT_FLOAT_EQ(camera.aspect, 2);
  EXPECT_FLOAT_EQ(camera.film, 0.036f);
  EXPECT_EQ(scene.settings.resolution, 400);
}

TEST(pbrtio, camera_fov_on_portrait_film_and_coordinate_system) {
  auto dir   = temp_dir{};
  auto scene = scene_data{};
  auto error = std::string{};
  auto text  = std::string{
      "Scale -1 1 1\n"
      "LookAt 0 0 -5  0 0 0  0 1 0\n"
      "Camera \"perspective\" \"float fov\" 30 \"float focaldistance\" 5 \"float lensradius\" .1\n"
      "Film \"image\" \"integer xresolution\" 100 \"integer yresolution\" 200\n"
      "WorldBegin\n"
      "CoordSysTransform \"camera\"\n"
      "Translate 0 0 5\n"
      "Shape \"sphere\"\n"};
  ASSERT_TRUE(load_text(dir, text, scene, error)) << error;
  auto& camera = scene.cameras[0];
  // The shorter side is the width: the right-edge ray is 15 degrees off axis
  // (checked through the pinhole, without the lens).
  auto pinhole     = camera;
  pinhole.aperture = 0;
  auto right       = eval_camera(pinhole, {1, 0.5f}, {0.5f, 0.5f});
  auto axis  = -camera.frame.z;
  EXPECT_NEAR(degrees(std::acos(dot(right.d, axis))), 15, 1e-3f);
  EXPECT_FLOAT_EQ(camera.aspect, 0.5f);
  EXPECT_FLOAT_EQ(camera.focus, 5);
  EXPECT_FLOAT_EQ(camera.aperture, 0.2f);
  // Looking along +z with y up, pbrt's image right is cross(up, dir) = +x;
  // the `Scale -1 1 1` before LookAt (a common exporter idiom) mirrors it.
  expect_near(camera.frame.x, {-1, 0, 0});
  // "camera" coordinates: 5 units ahead of the camera is the world origin.
  expect_near(scene.instances[0].frame.o, {0, 0, 0});
}

// -----------------------------------------------------------------------------
// MATERIALS
// -----------------------------------------------------------------------------

TEST(pbrtio, hair_material_parameters_and_precedence) {
  auto dir      = temp_dir{};
  auto scene    = scene_data{};
  auto error    = std::string{};
  auto warnings = std::vector<std::string>{};
  // Hair needs curves: one short strand after each material.
  auto curve = std::string{
      "Shape \"curve\" \"point3 P\" [0 0 0 0 0 1 0 0 2 0 0 3] \"float width\" .1\n"};
  auto text = "WorldBegin\n"
              "Material \"hair\"\n" +
              curve +  // pbrt default: eumelanin 1.3
              "Material \"hair\" \"float pheomelanin\" 2 \"float eta\" 1.6\n" + curve +
              "Material \"hair\" \"rgb color\" [ .2 .8 .3 ] \"float eumelanin\" 5\n" + curve +
              "Material \"hair\" \"rgb sigma_a\" [ .1 .2 .3 ] \"rgb reflectance\" [ .5 .5 .5 ]\n"
              "  \"float beta_m\" .1 \"float beta_n\" .9 \"float alpha\" 3\n" +
              curve + "Material \"hair\" \"rgb reflectance\" [ .4 .3 .2 ]\n" + curve;
  ASSERT_TRUE(load_text(dir, text, scene, error, &warnings)) << error;
  ASSERT_EQ(scene.materials.size(), 5u);
  auto& h0 = scene.materials[0].hair;
  EXPECT_FALSE(h0.has_sigma_a || h0.has_color);
  EXPECT_FLOAT_EQ(h0.eumelanin, 1.3f);
  EXPECT_FLOAT_EQ(h0.pheomelanin, 0);
  auto& h1 = scene.materials[1].hair;
  EXPECT_FLOAT_EQ(h1.eumelanin, 0);
  EXPECT_FLOAT_EQ(h1.pheomelanin, 2);
  EXPECT_FLOAT_EQ(h1.eta, 1.6f);
  auto& h2 = scene.materials[2].hair;
  EXPECT_TRUE(h2.has_color);
  EXPECT_FALSE(h2.has_sigma_a);
  expect_near(h2.color, {.2f, .8f, .3f});
  auto& h3 = scene.materials[3].hair;
  EXPECT_TRUE(h3.has_sigma_a);
  EXPECT_FALSE(h3.has_color);
  expect_near(h3.sigma_a, {.1f, .2f, .3f});
  EXPECT_FLOAT_EQ(h3.beta_m, .1f);
  EXPECT_FLOAT_EQ(h3.beta_n, .9f);
  EXPECT_FLOAT_EQ(h3.alpha, 3);
  EXPECT_TRUE(scene.materials[4].hair.has_color);  // v4 name of the colour
  expect_near(scene.materials[4].hair.color, {.4f, .3f, .2f});
  // Parameters overridden by precedence are not reported as ignored.
  EXPECT_FALSE(any_contains(warnings, "eumelanin"));
}

TEST(pbrtio, other_materials_map_to_nearest) {
  auto dir      = temp_dir{};
  auto scene    = scene_data{};
  auto error    = std::string{};
  auto warnings = std::vector<std::string>{};
  auto text     = std::string{
      "WorldBegin\n"
      "Shape \"sphere\"\n"  // default material
      "Material \"plastic\" \"rgb Kd\" [ .1 .2 .3 ] \"float roughness\" 0\n"
      "Shape \"sphere\"\n"
      "Material \"coateddiffuse\" \"rgb reflectance\" [ .9 .6 .1 ] \"float roughness\" .01\n"
      "Shape \"sphere\"\n"
      "Material \"conductor\" \"spectrum eta\" \"metal-Cu-eta\"\n"
      "Shape \"sphere\"\n"
      "Material \"translucent\"\n"
      "Shape \"sphere\"\n"};
  ASSERT_TRUE(load_text(dir, text, scene, error, &warnings)) << error;
  ASSERT_EQ(scene.materials.size(), 5u);
  EXPECT_EQ(scene.materials[0].type, material_type::matte);
  expect_near(scene.materials[0].color, {.5f, .5f, .5f});
  EXPECT_EQ(scene.materials[1].type, material_type::glossy);
  expect_near(scene.materials[1].color, {.1f, .2f, .3f});
  EXPECT_EQ(scene.materials[2].type, material_type::glossy);
  // pbrt-v4 remaps roughness .01 to alpha .1; Yocto's alpha is roughness^2.
  EXPECT_NEAR(scene.materials[2].roughness, std::sqrt(0.1f), 1e-6f);
  EXPECT_EQ(scene.materials[3].type, material_type::glossy);
  EXPECT_EQ(scene.materials[4].type, material_type::matte);
  EXPECT_TRUE(any_contains(warnings, "\"conductor\" is not supported"));
  EXPECT_TRUE(any_contains(warnings, "\"translucent\" is not supported"));
}

TEST(pbrtio, texture_parameters_warn_and_use_a_constant) {
  auto dir      = temp_dir{};
  auto scene    = scene_data{};
  auto error    = std::string{};
  auto warnings = std::vector<std::string>{};
  auto text     = std::string{
      "WorldBegin\n"
      "Texture \"checks\" \"spectrum\" \"checkerboard\" \"float uscale\" 4\n"
      "Material \"diffuse\" \"texture reflectance\" \"checks\"\n"
      "Shape \"sphere\"\n"};
  ASSERT_TRUE(load_text(dir, text, scene, error, &warnings)) << error;
  expect_near(scene.materials[0].color, {.5f, .5f, .5f});
  EXPECT_TRUE(any_contains(warnings, "texture \"checks\""));
}

// -----------------------------------------------------------------------------
// LIGHTS
// -----------------------------------------------------------------------------

TEST(pbrtio, distant_and_constant_infinite_lights) {
  auto dir   = temp_dir{};
  auto scene = scene_data{};
  auto error = std::string{};
  auto text  = std::string{
      "WorldBegin\n"
      "LightSource \"distant\" \"point from\" [ 0 0 0 ] \"point to\" [ 0 0 -2 ] "
      "\"rgb L\" [ 2 2 2 ] \"float scale\" 3\n"
      "AttributeBegin\n"
      "Rotate 90 1 0 0\n"
      "LightSource \"distant\" \"point3 from\" [ 0 0 1 ] \"point3 to\" [ 0 0 0 ]\n"
      "AttributeEnd\n"
      "LightSource \"infinite\" \"rgb L\" [ .5 .6 .7 ] \"rgb scale\" [ 2 2 2 ]\n"};
  ASSERT_TRUE(load_text(dir, text, scene, error)) << error;
  ASSERT_EQ(scene.distant_lights.size(), 2u);
  expect_near(scene.distant_lights[0].direction, {0, 0, 1});
  expect_near(scene.distant_lights[0].emission, {6, 6, 6});
  expect_near(scene.distant_lights[1].direction, {0, -1, 0});  // z rotated about x
  expect_near(scene.distant_lights[1].emission, {1, 1, 1});
  ASSERT_EQ(scene.environments.size(), 1u);
  expect_near(scene.environments[0].emission, {1, 1.2f, 1.4f});
  EXPECT_EQ(scene.environments[0].emission_tex, -1);
}

// Radiance encoding a pbrt light-space direction, for the map tests.
static vec3f direction_color(const vec3f& d) { return (d + vec3f{1, 1, 1}) / 2.0f; }

TEST(pbrtio, equirect_map_keeps_pbrt_directions) {
  // A pbrt-v3 equirect map: pixel (s, t) holds the direction pbrt assigns to
  // it (phi = 2 pi s around z, theta = pi t from +z). After import, the
  // environment must return that colour for the world direction pbrt uses.
  auto dir   = temp_dir{};
  auto image = texture_data{256, 128, {}};
  for (auto j = 0; j < image.height; j++) {
    for (auto i = 0; i < image.width; i++) {
      auto phi = 2 * pif * (i + 0.5f) / image.width, theta = pif * (j + 0.5f) / image.height;
      auto d   = vec3f{std::sin(theta) * std::cos(phi), std::sin(theta) * std::sin(phi),
          std::cos(theta)};
      image.pixels.push_back(direction_color(d));
    }
  }
  auto error = std::string{};
  fs::create_directories(dir / "maps");
  ASSERT_TRUE(save_image(dir / "maps/sky.exr", image, error)) << error;
  auto scene = scene_data{};
  auto text  = std::string{
      "WorldBegin\nAttributeBegin\nRotate -55 1 0 0\nRotate 90 0 0 1\n"
      "LightSource \"infinite\" \"string mapname\" \"maps/sky.exr\"\nAttributeEnd\n"};
  ASSERT_TRUE(load_text(dir, text, scene, error)) << error;
  ASSERT_EQ(scene.environments.size(), 1u);
  ASSERT_EQ(scene.environments[0].emission_tex, 0);
  auto light_to_world = rotation_frame({1, 0, 0}, radians(-55)) *
                        rotation_frame({0, 0, 1}, radians(90));
  // Directions away from the poles and the seam; bilinear error < 0.02.
  for (auto world : {vec3f{0.3f, 0.5f, 0.8f}, vec3f{-0.7f, 0.1f, 0.2f}, vec3f{0.1f, -0.9f, -0.3f}}) {
    world      = normalize(world);
    auto local = transform_direction(inverse(light_to_world, false), world);
    expect_near(eval_environment(scene, scene.environments[0], world), direction_color(local),
        0.02f);
  }
}

TEST(pbrtio, equal_area_map_is_converted_to_equirect) {
  // The same check for a pbrt-v4 equal-area octahedral map.
  auto dir   = temp_dir{};
  auto image = texture_data{128, 128, {}};
  for (auto j = 0; j < image.height; j++)
    for (auto i = 0; i < image.width; i++)
      image.pixels.push_back(direction_color(equal_area_square_to_sphere(
          {(i + 0.5f) / image.width, (j + 0.5f) / image.height})));
  auto error = std::string{};
  ASSERT_TRUE(save_image(dir / "sky.exr", image, error)) << error;
  auto scene = scene_data{};
  auto text  = std::string{
      "WorldBegin\nAttributeBegin\nRotate -120 1 0 0\nRotate 120 0 0 1\n"
      "LightSource \"infinite\" \"string filename\" \"sky.exr\" \"float scale\" 2\n"
      "AttributeEnd\n"};
  ASSERT_TRUE(load_text(dir, text, scene, error)) << error;
  ASSERT_EQ(scene.environments[0].emission_tex, 0);
  EXPECT_EQ(scene.textures[0].width, 2 * scene.textures[0].height);
  auto light_to_world = rotation_frame({1, 0, 0}, radians(-120)) *
                        rotation_frame({0, 0, 1}, radians(120));
  for (auto world : {vec3f{0.3f, 0.5f, 0.8f}, vec3f{-0.7f, 0.1f, 0.2f}, vec3f{0.1f, -0.9f, -0.3f}}) {
    world      = normalize(world);
    auto local = transform_direction(inverse(light_to_world, false), world);
    expect_near(eval_environment(scene, scene.environments[0], world),
        2.0f * direction_color(local), 0.05f);
  }
}

TEST(pbrtio, missing_environment_map_falls_back_to_constant) {
  auto dir      = temp_dir{};
  auto scene    = scene_data{};
  auto error    = std::string{};
  auto warnings = std::vector<std::string>{};
  auto text     = std::string{
      "WorldBegin\nLightSource \"infinite\" \"string filename\" \"textures/none.exr\" "
      "\"float scale\" 1.5\n"};
  ASSERT_TRUE(load_text(dir, text, scene, error, &warnings)) << error;
  ASSERT_EQ(scene.environments.size(), 1u);
  EXPECT_EQ(scene.environments[0].emission_tex, -1);
  expect_near(scene.environments[0].emission, {1.5f, 1.5f, 1.5f});
  EXPECT_TRUE(any_contains(warnings, "none.exr"));
}

TEST(pbrtio, equal_area_mapping_round_trip) {
  // Deterministic grid over the square: square -> sphere -> square.
  for (auto j = 0; j < 64; j++) {
    for (auto i = 0; i < 64; i++) {
      auto uv = vec2f{(i + 0.5f) / 64, (j + 0.5f) / 64};
      auto d  = equal_area_square_to_sphere(uv);
      EXPECT_NEAR(length(d), 1, 1e-5f);
      auto back = equal_area_sphere_to_square(d);
      EXPECT_NEAR(back.x, uv.x, 1e-4f);
      EXPECT_NEAR(back.y, uv.y, 1e-4f);
    }
  }
  // The centre is +z, the corners -z.
  expect_near(equal_area_square_to_sphere({0.5f, 0.5f}), {0, 0, 1});
  expect_near(equal_area_square_to_sphere({0, 0}), {0, 0, -1});
}

// -----------------------------------------------------------------------------
// SHAPES
// -----------------------------------------------------------------------------

TEST(pbrtio, curves_are_chained_and_grouped) {
  auto dir   = temp_dir{};
  auto scene = scene_data{};
  auto error = std::string{};
  auto text  = std::string{"WorldBegin\nMaterial \"hair\"\n"};
  // Two strands of three chained curves (v3 syntax), one v4 curve in another
  // material, then one curve under another transform.
  text += strands_text(2, 3, "point");
  text += "AttributeBegin\nMaterial \"hair\" \"float eumelanin\" 8\n";
  text += curve_text({0, 0, 0}, {1, 0, 0}, {2, 0, 0}, {3, 0, 0}, 0.2f, 0.2f);
  text += "AttributeEnd\nAttributeBegin\nTranslate 0 0 1\n";
  text += curve_text({0, 0, 0}, {1, 0, 0}, {2, 0, 0}, {3, 0, 0}, 0.2f, 0.2f);
  text += "AttributeEnd\n";
  text += strands_text(1, 2, "point3", {5, 0, 0});  // back to the first group
  ASSERT_TRUE(load_text(dir, text, scene, error)) << error;
  ASSERT_EQ(scene.shapes.size(), 3u);
  ASSERT_EQ(scene.instances.size(), 3u);
  auto& hair = scene.shapes[0];
  EXPECT_EQ(hair.curves.size(), 8u);
  // Chained: 3 strands, each with 1 + 3 * segments vertices.
  EXPECT_EQ(hair.positions.size(), (size_t)(2 * (1 + 3 * 3) + (1 + 3 * 2)));
  EXPECT_EQ(hair.curves[1].x, hair.curves[0].w);
  EXPECT_EQ(hair.curves[2].x, hair.curves[1].w);
  EXPECT_NE(hair.curves[3].x, hair.curves[2].w);  // a new strand
  EXPECT_EQ(hair.radius.size(), hair.positions.size());
  // Radius = width / 2, linear from width0 to width1 along the control points.
  EXPECT_FLOAT_EQ(hair.radius[hair.curves[0].x], 0.005f);
  EXPECT_FLOAT_EQ(hair.radius[hair.curves[0].y], (2 * 0.005f + 0.004f) / 3);
  EXPECT_FLOAT_EQ(hair.radius[hair.curves[0].w], 0.004f);
  EXPECT_EQ(scene.shapes[1].curves.size(), 1u);
  EXPECT_EQ(scene.shapes[2].curves.size(), 1u);
  EXPECT_NE(scene.instances[0].material, scene.instances[1].material);
  EXPECT_EQ(scene.instances[0].material, scene.instances[2].material);
  expect_near(scene.instances[2].frame.o, {0, 0, 1});
  EXPECT_FLOAT_EQ(scene.shapes[1].radius[0], 0.1f);
}

TEST(pbrtio, curve_variants) {
  auto dir      = temp_dir{};
  auto scene    = scene_data{};
  auto error    = std::string{};
  auto warnings = std::vector<std::string>{};
  auto text     = std::string{
      "WorldBegin\n"
      // Two Bezier segments in one curve, `width` for both ends, ribbon.
      "Shape \"curve\" \"point P\" [ 0 0 0 1 0 0 2 0 0 3 0 0 4 0 0 5 0 0 6 0 0 ] "
      "\"float width\" .5 \"string type\" \"ribbon\" \"normal N\" [ 0 0 1 0 0 1 0 0 1 ] "
      "\"integer splitdepth\" 3\n"
      // A uniform cubic b-spline (pbrt-v4): one segment.
      "Shape \"curve\" \"point3 P\" [ 0 0 0 6 0 0 12 0 0 18 0 0 ] \"string basis\" \"bspline\"\n"};
  ASSERT_TRUE(load_text(dir, text, scene, error, &warnings)) << error;
  ASSERT_EQ(scene.shapes.size(), 1u);
  auto& shape = scene.shapes[0];
  ASSERT_EQ(shape.curves.size(), 3u);
  EXPECT_EQ(shape.curves[1].x, shape.curves[0].w);
  EXPECT_FLOAT_EQ(shape.radius[0], 0.25f);
  auto b = shape.curves[2];
  expect_near(shape.positions[b.x], {6, 0, 0});  // (p0 + 4 p1 + p2) / 6
  expect_near(shape.positions[b.w], {12, 0, 0});
  EXPECT_TRUE(any_contains(warnings, "ribbon"));
  EXPECT_TRUE(any_contains(warnings, "splitdepth"));
}

TEST(pbrtio, sphere_disk_and_plymesh) {
  auto dir   = temp_dir{};
  auto error = std::string{};
  auto ply   = shape_data{};
  ply.positions = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}};
  ply.triangles = {{0, 1, 2}, {0, 2, 3}};
  fs::create_directories(dir / "meshes");
  ASSERT_TRUE(save_shape(dir / "meshes/quad.ply", ply, error)) << error;
  write_text(dir / "sub/part.pbrt", "Shape \"plymesh\" \"string filename\" \"../meshes/quad.ply\"\n");
  auto scene = scene_data{};
  auto text  = std::string{
      "WorldBegin\n"
      "Shape \"sphere\" \"float radius\" 2\n"
      "Shape \"disk\" \"float radius\" 3 \"float height\" 1\n"
      "Shape \"disk\" \"float radius\" 3 \"float innerradius\" 1\n"
      "Include \"sub/part.pbrt\"\n"};
  ASSERT_TRUE(load_text(dir, text, scene, error)) << error;
  ASSERT_EQ(scene.shapes.size(), 4u);
  auto& sphere = scene.shapes[0];
  EXPECT_EQ(sphere.normals.size(), sphere.positions.size());
  for (auto i = 0; i < (int)sphere.positions.size(); i += 97)
    EXPECT_NEAR(length(sphere.positions[i]), 2, 1e-5f);
  // Triangles face outwards.
  for (auto& t : sphere.triangles) {
    auto& p = sphere.positions;
    auto  n = cross(p[t.y] - p[t.x], p[t.z] - p[t.x]);
    ASSERT_GT(length(n), 0);
    EXPECT_GT(dot(n, p[t.x] + p[t.y] + p[t.z]), 0);
  }
  auto& disk = scene.shapes[1];
  for (auto& p : disk.positions) EXPECT_FLOAT_EQ(p.z, 1);
  EXPECT_EQ(disk.triangles.size(), 64u);
  for (auto& p : scene.shapes[2].positions) EXPECT_GE(length(p), 1 - 1e-5f);
  EXPECT_EQ(scene.shapes[3].triangles.size(), 2u);
}

TEST(pbrtio, curves_as_lines) {
  auto dir    = temp_dir{};
  auto scene  = scene_data{};
  auto error  = std::string{};
  auto params = pbrt_params{};
  params.curves_as_lines = true;
  params.segments        = 2;
  auto text = "WorldBegin\n" + strands_text(2, 3, "point3");
  ASSERT_TRUE(load_text(dir, text, scene, error, nullptr, params)) << error;
  ASSERT_EQ(scene.shapes.size(), 1u);
  auto& lines = scene.shapes[0];
  EXPECT_TRUE(lines.curves.empty());
  EXPECT_EQ(lines.lines.size(), (size_t)(2 * 3 * 2));
  // Shared joints: each strand is one polyline of 3 * 2 + 1 vertices.
  EXPECT_EQ(lines.positions.size(), (size_t)(2 * (3 * 2 + 1)));
  for (auto i = 1; i < 6; i++) EXPECT_EQ(lines.lines[i].x, lines.lines[i - 1].y);
  EXPECT_EQ(lines.radius.size(), lines.positions.size());
}

TEST(pbrtio, curves_to_lines_follows_the_bezier) {
  auto curves      = shape_data{};
  curves.positions = {{0, 0, 0}, {1, 1, 0}, {2, 1, 0}, {3, 0, 0}, {4, -1, 0}, {5, -1, 0},
      {6, 0, 0}};
  curves.radius    = {1, 1, 1, 1, 2, 2, 2};
  curves.curves    = {{0, 1, 2, 3}, {3, 4, 5, 6}};
  auto lines       = curves_to_lines(curves, 4);
  EXPECT_EQ(lines.lines.size(), 8u);
  EXPECT_EQ(lines.positions.size(), 9u);
  expect_near(lines.positions[lines.lines[1].y], eval_bezier(curves.positions[0],
                                                     curves.positions[1], curves.positions[2],
                                                     curves.positions[3], 0.5f));
  expect_near(lines.positions[lines.lines[7].y], {6, 0, 0});
  EXPECT_FLOAT_EQ(lines.radius[lines.lines[7].y], 2);
}

// -----------------------------------------------------------------------------
// INCLUDES
// -----------------------------------------------------------------------------

TEST(pbrtio, nested_and_gzip_includes_relative_to_the_including_file) {
  auto dir = temp_dir{};
  write_text(dir / "a/first.pbrt",
      "MakeNamedMaterial \"red\" \"string type\" \"diffuse\" \"rgb reflectance\" [1 0 0]\n"
      "Include \"b/second.pbrt.gz\"\n");
  write_gz(dir / "a/b/second.pbrt.gz",
      "NamedMaterial \"red\"\n" + strands_text(3, 2, "point3") + "Import \"../third.pbrt\"\n");
  write_text(dir / "a/third.pbrt", "Shape \"sphere\"\n");
  auto scene = scene_data{};
  auto error = std::string{};
  ASSERT_TRUE(load_text(dir, "WorldBegin\nInclude \"a/first.pbrt\"\n", scene, error)) << error;
  EXPECT_EQ(count_curves(scene), 6);
  ASSERT_EQ(scene.shapes.size(), 2u);
  ASSERT_EQ(scene.materials.size(), 1u);  // named materials cross includes
  expect_near(scene.materials[0].color, {1, 0, 0});
  EXPECT_EQ(scene.material_names[0], "red");
  // A whole gzip'd scene loads too.
  write_gz(dir / "whole.pbrt.gz", "WorldBegin\nShape \"sphere\"\n");
  ASSERT_TRUE(load_pbrt_scene(dir / "whole.pbrt.gz", scene, error)) << error;
  EXPECT_EQ(scene.shapes.size(), 1u);
}

// -----------------------------------------------------------------------------
// BAD INPUT
// -----------------------------------------------------------------------------

TEST(pbrtio, bad_input_names_file_line_and_directive) {
  auto dir = temp_dir{};
  expect_error(dir, "WorldBegin\nShape \"sphere\n\"float radius\" 1\n",
      {"scene.pbrt:2:", "unterminated string"});
  expect_error(dir, "WorldBegin\nShape \"sphere\" \"float radius\" [ 1\n",
      {"scene.pbrt:3:", "Shape \"sphere\"", "unterminated ["});
  expect_error(dir, "WorldBegin\nShape \"sphere\" \"float radius\" [ 1 \"two\" ]\n",
      {"scene.pbrt:2:", "expected a number"});
  expect_error(dir, "WorldBegin\nShape \"sphere\" \"integer radius\" 1\n",
      {"scene.pbrt:2:", "\"integer radius\" should be a float"});
  expect_error(dir, "Sampler \"halton\" \"integer pixelsamples\" 1.5\n", {"expected an integer"});
  expect_error(dir, "Sampler \"halton\" \"integer pixelsamples\" [ 1e9 ]\n", {"at most 2^24"});
  expect_error(dir, "WorldBegin\nShape \"sphere\" \"float radius\" 1e99\n", {"expected a number"});
  expect_error(dir, "WorldBegin\nShape \"sphere\" \"vec5 radius\" 1\n",
      {"unknown parameter type \"vec5\""});
  expect_error(dir, "WorldBegin\nShape \"sphere\" \"radius\" 1\n", {"bad parameter declaration"});
  expect_error(dir, "WorldBegin\nMaterial \"hair\" \"bool eumelanin\" 3\n", {"true or false"});
  expect_error(dir, "Translate 1 2\nWorldBegin\n", {"scene.pbrt:2:", "Translate", "3 numbers"});
  expect_error(dir, "WorldBegin\n\nBogus 1 2 3\n", {"scene.pbrt:3:", "Bogus", "unknown directive"});
  expect_error(dir, "WorldBegin\n[ 1 ]\n", {"scene.pbrt:2:", "expected a directive"});
  expect_error(dir, "WorldBegin\nAttributeEnd\n", {"no matching AttributeBegin"});
  expect_error(dir, "WorldBegin\nAttributeBegin\nTransformEnd\n", {"mismatched block", "line 2"});
  expect_error(dir, "WorldBegin\nNamedMaterial \"nope\"\n", {"unknown material \"nope\""});
  expect_error(dir, "WorldBegin\nShape \"curve\" \"point P\" [ 0 0 0 1 1 1 ]\n",
      {"Shape \"curve\"", "4 + 3n control points"});
  expect_error(dir, "WorldBegin\nShape \"curve\" \"point P\" [ 0 0 0 1 1 1 2 2 ]\n",
      {"multiple of 3"});
  expect_error(dir, "WorldBegin\nShape \"trianglemesh\" \"point P\" [0 0 0 1 0 0 0 1 0] "
                    "\"integer indices\" [0 1 3]\n",
      {"index 3", "out of range"});
  expect_error(dir, "WorldBegin\nShape \"plymesh\" \"string filename\" \"missing.ply\"\n",
      {"scene.pbrt:2:", "Shape \"plymesh\"", "missing.ply"});
  expect_error(dir, "LookAt 0 0 0 0 0 1 0 0 1\n", {"LookAt", "parallel"});
  expect_error(dir, "Transform [ 1 0 0 1 0 1 0 0 0 0 1 0 0 0 0 1 ]\n", {"projective"});
  expect_error(dir, "Scale 0 1 1\nCamera \"perspective\"\n", {"singular"});
  expect_error(dir, "WorldBegin\nMaterial \"hair\" \"float beta_m\" 2\n", {"beta_m"});
}

// pbrt's hair parameters are the rows of hair_parameters with a pbrt name,
// read under that name (or pbrt-v4's) and held to the row's range: the ends
// of a closed range load, a value past either end is an error naming the
// file, the line, the directive and the parameter. The variation keys are
// not pbrt's: they are ignored with a warning.
TEST(pbrtio, hair_parameters_follow_the_table) {
  auto dir = temp_dir{};
  // A hair material with one parameter (a number, or r g b all equal to
  // it) on line 3, then a strand.
  auto scene_text = [](const hair_parameter& parameter, const char* name, float value) {
    auto text = std::to_string(value);
    auto declaration =
        parameter.kind == hair_parameter_kind::number
            ? "\"float " + std::string(name) + "\" " + text
            : "\"rgb " + std::string(name) + "\" [ " + text + " " + text + " " + text + " ]";
    return "WorldBegin\n\nMaterial \"hair\" " + declaration +
           "\nShape \"curve\" \"point3 P\" [0 0 0 0 0 1 0 0 2 0 0 3] \"float width\" .1\n";
  };
  auto checked = 0;
  for (auto& parameter : hair_parameters) {
    if (parameter.pbrt[0] == 0) continue;
    checked++;
    for (auto name : {parameter.pbrt, parameter.pbrt_alias}) {
      if (name[0] == 0) continue;
      auto scene    = scene_data{};
      auto error    = std::string{};
      auto warnings = std::vector<std::string>{};
      // The ends of the range (flt_max: a large value) are valid.
      for (auto value : {parameter.min, parameter.max == flt_max ? 1e6f : parameter.max}) {
        auto text = scene_text(parameter, name, value);
        ASSERT_TRUE(load_text(dir, text, scene, error, &warnings)) << text << "\n" << error;
        EXPECT_EQ(get_hair_parameter(scene.materials[0].hair, parameter), vec3f{value}) << text;
        EXPECT_FALSE(any_contains(warnings, name)) << text;
      }
      auto outside = std::vector<float>{parameter.min - 1};
      if (parameter.max != flt_max) outside.push_back(parameter.max + 1);
      for (auto value : outside)
        expect_error(dir, scene_text(parameter, name, value),
            {"scene.pbrt:3:", "Material \"hair\"", name,
                "must be " + format_hair_parameter_range(parameter)});
    }
  }
  EXPECT_GE(checked, 8);  // sigma_a, color, eumelanin, pheomelanin, beta_m, beta_n, alpha, eta
  for (auto& parameter : hair_parameters) {
    if (parameter.pbrt[0] != 0) continue;
    auto scene    = scene_data{};
    auto error    = std::string{};
    auto warnings = std::vector<std::string>{};
    auto text     = scene_text(parameter, parameter.name, parameter.min + 0.5f);
    ASSERT_TRUE(load_text(dir, text, scene, error, &warnings)) << error;
    for (auto& other : hair_parameters)
      EXPECT_EQ(get_hair_parameter(scene.materials[0].hair, other),
          get_hair_parameter(hair_material{}, other))
          << other.name;
    EXPECT_TRUE(any_contains(warnings, "ignoring parameter") &&
                any_contains(warnings, parameter.name))
        << text;
  }
}

TEST(pbrtio, hair_material_on_a_surface_is_an_error_at_the_shape) {
  auto dir = temp_dir{};
  write_text(dir / "tri.ply",
      "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
      "property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n"
      "0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n");
  auto shapes = std::vector<std::string>{"\"sphere\"", "\"disk\"",
      "\"trianglemesh\" \"point3 P\" [0 0 0 1 0 0 0 1 0] \"integer indices\" [0 1 2]",
      "\"plymesh\" \"string filename\" \"tri.ply\""};
  for (auto& shape : shapes) {
    auto type = shape.substr(0, shape.find('"', 1) + 1);
    expect_error(dir,
        "WorldBegin\nMaterial \"hair\"\nAttributeBegin\nShape " + shape + "\nAttributeEnd\n",
        {"scene.pbrt:4:", "Shape " + type, "a hair material needs curves"});
    expect_error(dir,
        "WorldBegin\nMakeNamedMaterial \"fur\" \"string type\" \"hair\"\n"
        "NamedMaterial \"fur\"\nShape " + shape + "\n",
        {"scene.pbrt:4:", "Shape " + type, "a hair material needs curves"});
  }
}

TEST(pbrtio, reverse_orientation_turns_area_lights_and_twosided_warns_once) {
  auto dir      = temp_dir{};
  auto scene    = scene_data{};
  auto error    = std::string{};
  auto warnings = std::vector<std::string>{};
  auto mesh     = std::string{
      "Shape \"trianglemesh\" \"point3 P\" [0 0 0 1 0 0 0 1 0] \"integer indices\" [0 1 2]"
      " \"normal N\" [0 0 1 0 0 1 0 0 1]\n"};
  auto text = "WorldBegin\nAttributeBegin\nAreaLightSource \"diffuse\" \"bool twosided\" true\n" +
              mesh +  // front: +z
              "ReverseOrientation\n" + mesh +  // reversed: -z
              "AttributeBegin\nReverseOrientation\n" + mesh +  // twice: +z
              "AttributeEnd\nAttributeEnd\n"
              "AttributeBegin\nAreaLightSource \"diffuse\" \"bool twosided\" true\n" + mesh +
              "AttributeEnd\n";
  ASSERT_TRUE(load_text(dir, text, scene, error, &warnings)) << error;
  ASSERT_EQ(scene.shapes.size(), 4u);
  auto expected = std::vector<std::pair<vec3i, float>>{
      {{0, 1, 2}, 1}, {{0, 2, 1}, -1}, {{0, 1, 2}, 1}, {{0, 1, 2}, 1}};
  for (auto i = 0; i < 4; i++) {
    EXPECT_EQ(scene.shapes[i].triangles[0], expected[i].first) << i;
    EXPECT_EQ(scene.shapes[i].normals[0].z, expected[i].second) << i;
  }
  auto twosided = 0;
  for (auto& warning : warnings) twosided += contains(warning, "twosided") ? 1 : 0;
  EXPECT_EQ(twosided, 1);
  EXPECT_TRUE(any_contains(warnings, "scene.pbrt:3: AreaLightSource \"diffuse\": twosided "
                                     "area lights emit from the front side only"));
  // A one-sided light gives no warning.
  warnings.clear();
  ASSERT_TRUE(load_text(dir, "WorldBegin\nAreaLightSource \"diffuse\" \"bool twosided\" false\n" +
                                 mesh, scene, error, &warnings)) << error;
  EXPECT_FALSE(any_contains(warnings, "twosided"));
}

TEST(pbrtio, unknown_directives_are_warnings_when_lenient) {
  auto dir      = temp_dir{};
  auto scene    = scene_data{};
  auto error    = std::string{};
  auto warnings = std::vector<std::string>{};
  auto params   = pbrt_params{};
  params.lenient = true;
  auto text = std::string{
      "WorldBegin\nObjectBegin \"thing\" \"float x\" [ 1 2 ] \"bool b\" true\n"
      "Shape \"sphere\"\nObjectEnd\n"};
  ASSERT_TRUE(load_text(dir, text, scene, error, &warnings, params)) << error;
  EXPECT_TRUE(any_contains(warnings, "scene.pbrt:2: unknown directive ObjectBegin"));
  EXPECT_EQ(scene.shapes.size(), 1u);
}

TEST(pbrtio, include_errors) {
  auto dir = temp_dir{};
  // Missing include: the including file and line.
  expect_error(dir, "WorldBegin\n\nInclude \"models/none.pbrt\"\n",
      {"scene.pbrt:3:", "Include", "models/none.pbrt"});
  // Cycle through two files.
  write_text(dir / "x.pbrt", "Include \"y.pbrt\"\n");
  write_text(dir / "y.pbrt", "\nInclude \"x.pbrt\"\n");
  expect_error(dir, "Include \"x.pbrt\"\n", {"y.pbrt:2:", "include cycle", "x.pbrt"});
  // A self-include.
  expect_error(dir, "Include \"scene.pbrt\"\n", {"include cycle"});
  // Errors inside an included file name that file.
  write_text(dir / "bad.pbrt", "Shape \"sphere\"\nShape \"sphere\" \"float radius\" x\n");
  expect_error(dir, "WorldBegin\nInclude \"bad.pbrt\"\n", {"bad.pbrt:2:", "expected a"});
  // A truncated gzip include is an error, not a short file.
  auto text = "WorldBegin\n" + strands_text(200, 3, "point3");
  write_gz(dir / "full.pbrt.gz", text);
  auto size = fs::file_size(dir / "full.pbrt.gz");
  fs::resize_file(dir / "full.pbrt.gz", size / 2);
  expect_error(dir, "Include \"full.pbrt.gz\"\n",
      {"scene.pbrt:1:", "Include", "full.pbrt.gz", "truncated"});
  // A gzip whose data is corrupt.
  write_gz(dir / "corrupt.pbrt.gz", text);
  auto stream = std::fstream(dir / "corrupt.pbrt.gz", std::ios::in | std::ios::out | std::ios::binary);
  stream.seekp((std::streamoff)(size / 2));
  stream.write("\xff\xff\xff\xff\xff\xff\xff\xff", 8);
  stream.close();
  expect_error(dir, "Include \"corrupt.pbrt.gz\"\n", {"corrupt.pbrt.gz"});
}

// -----------------------------------------------------------------------------
// BOUNDS AND HOSTILE INPUT
// -----------------------------------------------------------------------------

// Import options with a low memory limit, so that bounds are tested with
// small files.
static pbrt_params memory_limit_params(double limit) {
  auto params       = pbrt_params{};
  params.max_memory = limit;
  return params;
}

const auto mebibyte = 1024.0 * 1024.0;

TEST(pbrtio, gzip_inflation_is_bounded) {
  auto dir = temp_dir{};
  // 17 MiB of blanks deflate to a few KB: past 16 MiB, more than 100 times
  // the compressed size is refused as a bomb, whatever the budget.
  write_gz(dir / "bomb.pbrt.gz", std::string(17 << 20, ' '));
  expect_error(dir, "WorldBegin\nInclude \"bomb.pbrt.gz\"\nShape \"sphere\"\n",
      {"scene.pbrt:2:", "Include", "bomb.pbrt.gz", "more than 100 times its compressed size"});
  // Below 16 MiB, the budget bounds the inflated text.
  auto limit = memory_limit_params(2 * mebibyte);
  write_gz(dir / "big.pbrt.gz", std::string(6 << 20, ' '));
  expect_error(dir, "WorldBegin\nInclude \"big.pbrt.gz\"\nShape \"sphere\"\n",
      {"scene.pbrt:2:", "big.pbrt.gz", "inflating the text needs", "memory limit of 2 MiB"},
      limit);
  // A gzip'd top-level file too.
  write_gz(dir / "top.pbrt.gz", "WorldBegin\nShape \"sphere\"\n" + std::string(6 << 20, ' '));
  auto scene = scene_data{};
  auto error = std::string{};
  EXPECT_FALSE(load_pbrt_scene(dir / "top.pbrt.gz", scene, error, limit));
  EXPECT_TRUE(contains(error, "top.pbrt.gz: inflating the text needs")) << error;
}

TEST(pbrtio, include_work_is_bounded) {
  // 11 files of 8 Includes each would be 8^10 parses: the text read with
  // every Include stops at 4 times the budget, an Include counting 1 MiB.
  auto dir   = temp_dir{};
  auto limit = memory_limit_params(1 * mebibyte);
  for (auto level = 0; level < 11; level++) {
    auto text = std::string{};
    for (auto k = 0; k < 8; k++)
      text += level < 10 ? "Include \"level" + std::to_string(level + 1) + ".pbrt\"\n" : "# leaf\n";
    write_text(dir / ("level" + std::to_string(level) + ".pbrt"), text);
  }
  expect_error(dir, "WorldBegin\nShape \"sphere\"\nInclude \"level0.pbrt\"\n",
      {"level2.pbrt:1: Include", "level3.pbrt: the scene's text with its Includes comes to "
                                  "over 4 MiB, 4 times the memory limit",
          "1 MiB"},
      limit);
}

TEST(pbrtio, generated_geometry_is_bounded) {
  auto dir   = temp_dir{};
  auto limit = memory_limit_params(4 * mebibyte);
  // 64 spheres of about 116 KB each through repeated Includes: the one that
  // crosses 4 MiB is named with its file and line.
  write_text(dir / "spheres.pbrt", [] {
    auto text = std::string{};
    for (auto k = 0; k < 8; k++) text += "Translate 1 0 0\nShape \"sphere\"\n";
    return text;
  }());
  auto includes = std::string{"WorldBegin\n"};
  for (auto k = 0; k < 8; k++) includes += "Include \"spheres.pbrt\"\n";
  expect_error(dir, includes,
      {"spheres.pbrt:", "Shape \"sphere\"", "the scene with this shape needs",
          "memory limit of 4 MiB"},
      limit);
  // A parameter array claiming more than the budget fails as it grows.
  auto points = std::string{};
  for (auto k = 0; k < 1500000; k++) points += "0 ";
  expect_error(dir,
      "WorldBegin\nShape \"trianglemesh\" \"integer indices\" [0 1 2]\n\"point3 P\" [ " + points +
          "]\n",
      {"scene.pbrt:3:", "Shape \"trianglemesh\"", "the scene with parameter \"point3 P\"",
          "memory limit of 4 MiB"},
      limit);
  // Curves add up across directives.
  {
    auto small = memory_limit_params(0.5 * mebibyte);
    expect_error(dir, "WorldBegin\n" + strands_text(70, 100, "point3"),
        {"scene.pbrt:", "Shape \"curve\": the scene needs", "memory limit of 1 MiB"}, small);
  }
  // Curves as lines: the lines are checked before they are made.
  auto params     = limit;
  params.curves_as_lines = true;
  params.segments = 100000;
  expect_error(dir, "WorldBegin\n" + strands_text(10, 10, "point3"),
      {"scene.pbrt: the scene with curves as lines (100000 segments each) needs",
          "memory limit of 4 MiB"},
      params);
  // Under the budget, all of these load.
  auto scene = scene_data{};
  auto error = std::string{};
  params.segments = 8;
  EXPECT_TRUE(load_text(dir, "WorldBegin\nInclude \"spheres.pbrt\"\n" +
                                 strands_text(10, 10, "point3"),
      scene, error, nullptr, params))
      << error;
}

TEST(pbrtio, equal_area_resampling_is_bounded) {
  // A grey 512x512 equal-area map (a 1 MiB PFM, 5 MiB to load, 3 MiB kept)
  // resamples to 1024x512 RGB (6 MiB): with an 8 MiB budget the map loads
  // but its resampling is refused before it is allocated; with 16 MiB both
  // fit.
  auto dir  = temp_dir{};
  auto grey = std::string{"Pf\n512 512\n-1.0\n"};
  for (auto i = 0; i < 512 * 512; i++) {
    auto value = 0.5f;
    grey.append((const char*)&value, sizeof(value));
  }
  write_text(dir / "sky.pfm", grey);
  auto error = std::string{};
  auto text  = std::string{
      "WorldBegin\nLightSource \"infinite\" \"string filename\" \"sky.pfm\"\n"};
  {
    auto limit = memory_limit_params(8 * mebibyte);
    expect_error(dir, text,
        {"scene.pbrt:2:", "LightSource \"infinite\"",
            "the scene with the equal-area map \"sky.pfm\" resampled to equirectangular needs",
            "memory limit of 8 MiB"},
        limit);
  }
  auto limit = memory_limit_params(16 * mebibyte);
  auto scene = scene_data{};
  ASSERT_TRUE(load_text(dir, text, scene, error, nullptr, limit)) << error;
  EXPECT_EQ(scene.textures.at(0).width, 1024);
}

TEST(pbrtio, scene_with_nothing_to_render_is_an_error) {
  auto dir = temp_dir{};
  for (auto text : {"", "# nothing\n", "LookAt 0 0 5 0 0 0 0 1 0\nCamera \"perspective\"\nWorldBegin\n",
           "WorldBegin\nLightSource \"distant\"\n"})
    expect_error(dir, text, {"scene.pbrt: nothing to render: no shapes and no environment light"});
  // A sky alone is something to see; a camera alone is fine when asked for.
  auto scene = scene_data{};
  auto error = std::string{};
  EXPECT_TRUE(load_text(dir, "WorldBegin\nLightSource \"infinite\"\n", scene, error)) << error;
  auto params        = pbrt_params{};
  params.allow_empty = true;
  EXPECT_TRUE(load_text(dir, "Camera \"perspective\"\nWorldBegin\n", scene, error, nullptr, params))
      << error;
  EXPECT_EQ(scene.cameras.size(), 1u);
}

TEST(pbrtio, only_regular_files_are_read) {
  auto dir = temp_dir{};
  fs::create_directories(dir / "folder.pbrt");
  fs::create_symlink("/dev/zero", dir / "zero.pbrt");
  ASSERT_EQ(mkfifo((dir / "fifo.pbrt").c_str(), 0600), 0);
  for (auto name : {"/dev/zero", "zero.pbrt", "fifo.pbrt"}) {
    expect_error(dir, "WorldBegin\nShape \"sphere\"\nInclude \"" + std::string{name} + "\"\n",
        {"scene.pbrt:3:", "Include", name, "not a regular file"});
    expect_error(dir,
        "WorldBegin\nShape \"plymesh\" \"string filename\" \"" + std::string{name} + "\"\n",
        {"scene.pbrt:2:", "Shape \"plymesh\"", name, "not a regular file"});
    expect_error(dir,
        "WorldBegin\nShape \"sphere\"\nLightSource \"infinite\" \"string mapname\" \"" +
            std::string{name} + "\"\n",
        {"scene.pbrt:3:", "LightSource \"infinite\"", name, "not a regular file"});
  }
  expect_error(dir, "WorldBegin\nShape \"sphere\"\nInclude \"folder.pbrt\"\n",
      {"scene.pbrt:3:", "folder.pbrt", "is a directory"});
  // The scene file itself.
  for (auto name : {"folder.pbrt", "zero.pbrt", "fifo.pbrt"}) {
    auto scene = scene_data{};
    auto error = std::string{};
    EXPECT_FALSE(load_pbrt_scene(dir / name, scene, error));
    EXPECT_TRUE(contains(error, name)) << error;
  }
}

// -----------------------------------------------------------------------------
// THE CAMERA ALONE
// -----------------------------------------------------------------------------

TEST(pbrtio, camera_alone_is_read_up_to_world_begin) {
  auto dir    = temp_dir{};
  auto before = std::string{
      "LookAt 0 1 5  0 0 0  0 1 0\nCamera \"perspective\" \"float fov\" [ 30 ]\n"
      "Film \"image\" \"integer xresolution\" [ 400 ] \"integer yresolution\" [ 200 ]\n"};
  write_text(dir / "full.pbrt", before + "WorldBegin\nShape \"sphere\"\n");
  // The world of a scene whose Includes are missing is never read.
  write_text(dir / "cut.pbrt", before + "WorldBegin\nInclude \"missing.pbrt\"\nShape [\n");
  auto scene = scene_data{};
  auto error = std::string{};
  ASSERT_TRUE(load_pbrt_scene(dir / "full.pbrt", scene, error)) << error;
  EXPECT_FALSE(load_pbrt_scene(dir / "cut.pbrt", scene, error));
  ASSERT_TRUE(load_pbrt_scene(dir / "full.pbrt", scene, error)) << error;
  auto camera = camera_data{};
  ASSERT_TRUE(load_pbrt_camera(dir / "cut.pbrt", camera, error)) << error;
  EXPECT_EQ(camera.frame, scene.cameras.at(0).frame);
  EXPECT_EQ(camera.lens, scene.cameras[0].lens);
  EXPECT_EQ(camera.film, scene.cameras[0].film);
  EXPECT_EQ(camera.aspect, scene.cameras[0].aspect);
  EXPECT_EQ(camera.aspect, 2.0f);
  // No WorldBegin, or an error before it: messages name the file.
  write_text(dir / "noworld.pbrt", before);
  EXPECT_FALSE(load_pbrt_camera(dir / "noworld.pbrt", camera, error));
  EXPECT_EQ(error, dir / "noworld.pbrt" + ": no WorldBegin");
  write_text(dir / "bad.pbrt", "Camera \"perspective\" \"float fov\" [ x ]\nWorldBegin\n");
  EXPECT_FALSE(load_pbrt_camera(dir / "bad.pbrt", camera, error));
  EXPECT_TRUE(contains(error, dir / "bad.pbrt:1: Camera")) << error;
}

// -----------------------------------------------------------------------------
// PBRT CURVES
// -----------------------------------------------------------------------------

TEST(pbrtio, saved_curves_load_back) {
  auto dir   = temp_dir{};
  auto shape = shape_data{};
  for (auto s = 0; s < 3; s++) {
    auto points = std::vector<vec3f>{};
    for (auto k = 0; k < 4; k++) points.push_back({0.1f * s, 0.5f * k, 0.01f * k * k});
    auto radii = std::vector<float>{0.02f, 0.015f, 0.01f, 0.005f};
    append_catmull_rom_strand(shape, points, radii);
  }
  auto error = std::string{};
  for (auto name : {"curves.pbrt", "curves.pbrt.gz"}) {
    ASSERT_TRUE(save_pbrt_curves(dir / name, shape, error)) << error;
    auto scene = scene_data{};
    ASSERT_TRUE(load_text(dir, "WorldBegin\nInclude \"" + std::string{name} + "\"\n", scene,
        error))
        << error;
    ASSERT_EQ(scene.shapes.size(), 1u);
    auto& loaded = scene.shapes[0];
    ASSERT_EQ(loaded.curves.size(), shape.curves.size());
    // Widths are diameters; strands keep their shared end points.
    for (size_t i = 0; i < shape.curves.size(); i++) {
      auto& a = shape.curves[i];
      auto& b = loaded.curves[i];
      for (auto k = 0; k < 4; k++)
        expect_near(loaded.positions[b[k]], shape.positions[a[k]], 1e-6f);
      EXPECT_NEAR(loaded.radius[b.x], shape.radius[a.x], 1e-7f);
      EXPECT_NEAR(loaded.radius[b.w], shape.radius[a.w], 1e-7f);
    }
    EXPECT_EQ(loaded.curves[1].x, loaded.curves[0].w);
  }
}
