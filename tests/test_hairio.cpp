//
// Tests of Yocto/HairIO: Cem Yuksel's .hair models (the spline through the
// points, round trips, the scene around a model) and every kind of bad
// input. Files are written to a temporary directory at test time.
//

#include <sys/stat.h>
#include <yocto/yocto_hairio.h>

#include "test_pbrtio.h"

// Writes a .hair file with the given header fields and arrays.
static void write_hair(const std::string& filename, uint32_t strands, uint32_t points,
    uint32_t flags, uint32_t default_segments, const std::vector<uint16_t>& segments,
    const std::vector<float>& positions, const std::vector<float>& thickness = {},
    const std::vector<float>& colors = {}) {
  auto data = std::string("HAIR", 4);
  auto put  = [&](const void* value, size_t size) { data.append((const char*)value, size); };
  auto default_thickness = 0.1f, default_transparency = 0.0f;
  float default_color[3] = {0.5f, 0.4f, 0.3f};
  put(&strands, 4);
  put(&points, 4);
  put(&flags, 4);
  put(&default_segments, 4);
  put(&default_thickness, 4);
  put(&default_transparency, 4);
  put(default_color, 12);
  data.resize(128, '\0');
  put(segments.data(), segments.size() * 2);
  put(positions.data(), positions.size() * 4);
  put(thickness.data(), thickness.size() * 4);
  put(colors.data(), colors.size() * 4);
  write_text(filename, data);
}

TEST(hairio, hair_model_catmull_rom_through_points) {
  auto dir = temp_dir{};
  // Two strands: 3 segments and 1 segment, with thickness and colour arrays.
  auto positions = std::vector<float>{0, 0, 0, 1, 0, 0, 2, 1, 0, 3, 1, 0, 0, 5, 0, 0, 6, 0};
  auto thickness = std::vector<float>{.4f, .3f, .2f, .1f, .2f, .2f};
  auto colors    = std::vector<float>(18, 0.25f);
  write_hair(dir / "model.hair", 2, 6, 1 | 2 | 4 | 16, 0, {3, 1}, positions, thickness, colors);
  auto shape = shape_data{};
  auto error = std::string{};
  auto color = vec3f{0, 0, 0};
  ASSERT_TRUE(load_hair_model(dir / "model.hair", shape, error, &color)) << error;
  ASSERT_EQ(shape.curves.size(), 4u);
  expect_near(color, {.25f, .25f, .25f});
  // The curve passes through the points, with radius = thickness / 2.
  expect_near(shape.positions[shape.curves[1].x], {1, 0, 0});
  expect_near(shape.positions[shape.curves[1].w], {2, 1, 0});
  EXPECT_FLOAT_EQ(shape.radius[shape.curves[1].x], 0.15f);
  EXPECT_EQ(shape.curves[1].x, shape.curves[0].w);
  // Catmull-Rom: the tangent at point 1 is (p2 - p0) / 2, so the first
  // inner control point of curve 1 is p1 + (p2 - p0) / 6.
  expect_near(shape.positions[shape.curves[1].y], vec3f{1, 0, 0} + vec3f{2, 1, 0} / 6.0f);
  // C1 continuity at the joint.
  auto d_out = shape.positions[shape.curves[1].y] - shape.positions[shape.curves[1].x];
  auto d_in  = shape.positions[shape.curves[0].w] - shape.positions[shape.curves[0].z];
  expect_near(d_out, d_in);
  expect_near(shape.positions[shape.curves[3].w], {0, 6, 0});
}

TEST(hairio, hair_model_round_trip_and_scene) {
  auto dir = temp_dir{};
  // Default segments (no segments array), default thickness, no colour.
  auto positions = std::vector<float>{};
  for (auto s = 0; s < 3; s++)
    for (auto k = 0; k < 5; k++) positions.insert(positions.end(), {(float)s, (float)k, 0.1f * k});
  write_hair(dir / "a.hair", 3, 15, 2, 4, {}, positions);
  auto shape = shape_data{};
  auto error = std::string{};
  auto color = vec3f{};
  ASSERT_TRUE(load_hair_model(dir / "a.hair", shape, error, &color)) << error;
  EXPECT_EQ(shape.curves.size(), 12u);
  EXPECT_FLOAT_EQ(shape.radius[0], 0.05f);
  expect_near(color, {.5f, .4f, .3f});  // header default
  ASSERT_TRUE(save_hair_model(dir / "b.hair", shape, error)) << error;
  auto again = shape_data{};
  ASSERT_TRUE(load_hair_model(dir / "b.hair", again, error)) << error;
  EXPECT_EQ(again.positions, shape.positions);
  EXPECT_EQ(again.radius, shape.radius);
  EXPECT_EQ(again.curves, shape.curves);
  // Lines save too: the strand's vertices become its points.
  auto lines = curves_to_lines(shape, 2);
  ASSERT_TRUE(save_hair_model(dir / "c.hair", lines, error)) << error;
  ASSERT_TRUE(load_hair_model(dir / "c.hair", again, error)) << error;
  EXPECT_EQ(again.curves.size(), 24u);
  // The scene: shape, hair material, instance, camera, environment.
  auto scene  = scene_data{};
  auto params = hair_params{};
  ASSERT_TRUE(load_hair_scene(dir / "a.hair", scene, error, params)) << error;
  EXPECT_EQ(scene.shapes.size(), 1u);
  EXPECT_EQ(scene.materials[0].type, material_type::hair);
  EXPECT_FALSE(scene.materials[0].hair.has_color);
  EXPECT_EQ(scene.cameras.size(), 1u);
  EXPECT_EQ(scene.environments.size(), 1u);
  EXPECT_TRUE(validate_scene(scene, error)) << error;
  params.curves_as_lines = true;
  ASSERT_TRUE(load_hair_scene(dir / "a.hair", scene, error, params)) << error;
  EXPECT_EQ(scene.shapes[0].lines.size(), 48u);
}

TEST(hairio, bad_hair_files) {
  auto dir   = temp_dir{};
  auto shape = shape_data{};
  auto error = std::string{};
  auto positions = std::vector<float>{0, 0, 0, 1, 0, 0, 2, 0, 0};
  // Truncated header.
  write_text(dir / "short.hair", std::string("HAIR\1\0\0\0", 8));
  EXPECT_FALSE(load_hair_model(dir / "short.hair", shape, error));
  EXPECT_TRUE(contains(error, "short.hair") && contains(error, "byte 8")) << error;
  // Bad signature.
  write_hair(dir / "sig.hair", 1, 3, 2, 2, {}, positions);
  {
    auto stream = std::fstream(dir / "sig.hair", std::ios::in | std::ios::out | std::ios::binary);
    stream.write("HAIX", 4);
  }
  EXPECT_FALSE(load_hair_model(dir / "sig.hair", shape, error));
  EXPECT_TRUE(contains(error, "signature")) << error;
  // Absurd counts: four billion points in a 164-byte file, no allocation.
  write_hair(dir / "absurd.hair", 1, 4000000000u, 2, 2, {}, positions);
  EXPECT_FALSE(load_hair_model(dir / "absurd.hair", shape, error));
  EXPECT_TRUE(contains(error, "truncated at byte 164") && contains(error, "4000000000")) << error;
  // Truncated arrays.
  write_hair(dir / "cut.hair", 1, 3, 2 | 4, 2, {}, positions, {1, 1});
  EXPECT_FALSE(load_hair_model(dir / "cut.hair", shape, error));
  EXPECT_TRUE(contains(error, "cut.hair: truncated at byte 172")) << error;
  // Segments that do not add up to the point count.
  write_hair(dir / "sum.hair", 1, 3, 1 | 2, 0, {5}, positions);
  EXPECT_FALSE(load_hair_model(dir / "sum.hair", shape, error));
  EXPECT_TRUE(contains(error, "add up to 6 points")) << error;
  // Not finite.
  write_hair(dir / "nan.hair", 1, 3, 2, 2, {}, {0, 0, 0, NAN, 0, 0, 2, 0, 0});
  EXPECT_FALSE(load_hair_model(dir / "nan.hair", shape, error));
  EXPECT_TRUE(contains(error, "point 1 at byte 140")) << error;
  // No points array.
  write_hair(dir / "nopoints.hair", 1, 3, 0, 2, {}, {});
  EXPECT_FALSE(load_hair_model(dir / "nopoints.hair", shape, error));
  // Saving an empty shape fails and leaves no file.
  EXPECT_FALSE(save_hair_model(dir / "empty.hair", shape_data{}, error));
  EXPECT_FALSE(fs::exists(dir / "empty.hair"));
  EXPECT_EQ(std::distance(fs::directory_iterator(dir.path), fs::directory_iterator{}), 7);
}

TEST(hairio, hair_header_counts_devices_and_memory_are_checked_first) {
  auto dir   = temp_dir{};
  auto shape = shape_data{};
  auto error = std::string{};
  auto positions = std::vector<float>{0, 0, 0, 1, 0, 0, 2, 0, 0};
  // Four billion strands of no points and no segments array: refused by the
  // header's counts before any loop over the strands.
  write_hair(dir / "strands.hair", 4000000000u, 0, 2, 0, {}, {});
  EXPECT_FALSE(load_hair_model(dir / "strands.hair", shape, error));
  EXPECT_TRUE(contains(error, "strands.hair") && contains(error, "4000000000 strands") &&
              contains(error, "0 points"))
      << error;
  // A device or a fifo named as a model is refused, not read forever.
  fs::create_symlink("/dev/zero", dir / "zero.hair");
  EXPECT_FALSE(load_hair_model(dir / "zero.hair", shape, error));
  EXPECT_TRUE(contains(error, "zero.hair") && contains(error, "not a regular file")) << error;
  ASSERT_EQ(mkfifo((dir / "fifo.hair").c_str(), 0600), 0);
  EXPECT_FALSE(load_hair_model(dir / "fifo.hair", shape, error));
  EXPECT_TRUE(contains(error, "fifo.hair") && contains(error, "not a regular file")) << error;
  // The points against the memory limit.
  write_hair(dir / "model.hair", 1, 3, 2, 2, {}, positions);
  auto loaded = load_hair_model(dir / "model.hair", shape, error, nullptr, 100);
  EXPECT_FALSE(loaded);
  EXPECT_TRUE(contains(error, "model.hair: ") && contains(error, "over the memory limit"))
      << error;
  EXPECT_TRUE(load_hair_model(dir / "model.hair", shape, error)) << error;
}
