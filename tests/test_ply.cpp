//
// PLY shapes: round trips, property types and byte orders, fans and
// polylines, the real Yocto/GL lines file, and every kind of bad input.
//

#include <gtest/gtest.h>
#include <yocto/yocto_ply.h>

#include <cstring>
#include <random>

#include "test_io.h"

using namespace yocto;
using namespace yocto_test;

namespace {

// A shape with arbitrary (not round) values, from a fixed seed.
shape_data make_random_shape(int kind, int num_vertices, int num_elements) {
  auto rng   = std::mt19937{7};
  auto value = std::uniform_real_distribution<float>{-10, 10};
  auto index = std::uniform_int_distribution<int>{0, num_vertices - 1};
  auto shape = shape_data{};
  for (auto i = 0; i < num_vertices; i++) {
    shape.positions.push_back({value(rng), value(rng), value(rng)});
    if (kind == 0) {
      shape.normals.push_back(normalize(vec3f{value(rng), value(rng), value(rng)}));
      shape.texcoords.push_back({value(rng) / 10, value(rng) / 10});
    } else {
      shape.radius.push_back(std::abs(value(rng)) / 1000);
    }
  }
  for (auto e = 0; e < num_elements; e++) {
    if (kind == 0) shape.triangles.push_back({index(rng), index(rng), index(rng)});
    if (kind == 1) shape.lines.push_back({index(rng), index(rng)});
    if (kind == 2) shape.curves.push_back({index(rng), index(rng), index(rng), index(rng)});
  }
  return shape;
}

// Appends one value of a PLY type, in ascii or in either byte order.
void encode(std::string& data, const std::string& type, double value, const std::string& format) {
  if (format == "ascii") {
    auto text = std::to_string(value);
    if (value == std::floor(value)) text = std::to_string((long long)value);
    data += text + " ";
    return;
  }
  char bytes[8];
  auto size = 0;
  auto put  = [&](auto typed) {
    size = sizeof(typed);
    std::memcpy(bytes, &typed, size);
  };
  if (type == "char" || type == "int8") put((int8_t)value);
  else if (type == "uchar" || type == "uint8") put((uint8_t)value);
  else if (type == "short" || type == "int16") put((int16_t)value);
  else if (type == "ushort" || type == "uint16") put((uint16_t)value);
  else if (type == "int" || type == "int32") put((int32_t)value);
  else if (type == "uint" || type == "uint32") put((uint32_t)value);
  else if (type == "float" || type == "float32") put((float)value);
  else put((double)value);
  if (format == "binary_big_endian") std::reverse(bytes, bytes + size);
  data.append(bytes, size);
}

}  // namespace

static void round_trips_triangles_lines_and_curves_in_binary_and_ascii() {
  auto dir = scratch_directory("ply-round-trip");
  for (auto kind = 0; kind < 3; kind++) {
    for (auto ascii : {false, true}) {
      auto shape    = make_random_shape(kind, 50, 40);
      auto filename = dir.file("shape" + std::to_string(kind) + (ascii ? "a" : "b") + ".ply");
      auto error    = std::string{};
      ASSERT_TRUE(save_shape(filename, shape, error, ascii)) << error;
      auto loaded = shape_data{};
      ASSERT_TRUE(load_shape(filename, loaded, error)) << error;
      expect_same_shape(shape, loaded);
    }
  }
  // Only the four outputs: no temporary file is left.
  EXPECT_EQ(list_files(dir.path).size(), 6u);
}

static void reads_every_property_type_in_every_format_and_skips_unknown_data() {
  auto dir = scratch_directory("ply-types");
  // Vertex properties (classic and sized type names) with three rows of
  // values each; "flags", "c" and "w" are unknown and skipped, as are the
  // list "extra", the element "material" and the line's "tag".
  struct column {
    std::string name, classic, sized;
    double      values[3];
  };
  auto columns = std::vector<column>{{"x", "short", "int16", {-3, 300, 0}},
      {"y", "uchar", "uint8", {200, 0, 255}}, {"flags", "ushort", "uint16", {7, 65535, 0}},
      {"z", "double", "float64", {0.125, -0.001, 2.5}},
      {"c", "char", "int8", {-1, 127, -128}},
      {"radius", "float", "float32", {0.5, 0.25, 1}},
      {"w", "uint", "uint32", {4000000000.0, 1, 0}}, {"i", "int", "int32", {-5, 6, 7}}};
  auto extra = std::vector<std::vector<double>>{{1, 2}, {}, {5}};
  for (auto sized : {false, true}) {
    for (auto format : {"ascii", "binary_little_endian", "binary_big_endian"}) {
      auto type = [&](const column& c) { return sized ? c.sized : c.classic; };
      auto data = std::string{"ply\nformat "} + format + " 1.0\ncomment types\n";
      data += "element vertex 3\n";
      for (auto i = 0; i < (int)columns.size(); i++) {
        data += "property " + type(columns[i]) + " " + columns[i].name + "\n";
        if (i == 2)
          data += sized ? "property list uint8 int32 extra\n" : "property list uchar int extra\n";
      }
      data += "element material 2\nproperty list ushort float values\nproperty int id\n";
      data += "element line 1\nproperty char tag\n";
      data += sized ? "property list uint16 uint32 vertex_indices\n"
                    : "property list ushort uint vertex_indices\n";
      data += "end_header\n";
      for (auto row = 0; row < 3; row++) {
        for (auto i = 0; i < (int)columns.size(); i++) {
          encode(data, type(columns[i]), columns[i].values[row], format);
          if (i == 2) {
            encode(data, "uchar", (double)extra[row].size(), format);
            for (auto value : extra[row]) encode(data, "int", value, format);
          }
        }
        if (std::string(format) == "ascii") data += "\n";
      }
      for (auto row = 0; row < 2; row++) {
        encode(data, "ushort", 3 - 3 * row, format);
        for (auto k = 0; k < 3 - 3 * row; k++) encode(data, "float", 0.5 * k, format);
        encode(data, "int", row, format);
      }
      encode(data, "char", -7, format);
      encode(data, "ushort", 3, format);
      for (auto index : {0, 1, 2}) encode(data, "uint", index, format);

      auto filename = dir.file(std::string(format) + (sized ? "-sized" : "") + ".ply");
      write_file(filename, data);
      auto shape = shape_data{};
      auto error = std::string{};
      ASSERT_TRUE(load_shape(filename, shape, error)) << error;
      EXPECT_EQ(shape.positions, (std::vector<vec3f>{
                                     {-3, 200, 0.125f}, {300, 0, -0.001f}, {0, 255, 2.5f}}))
          << filename;
      EXPECT_EQ(shape.radius, (std::vector<float>{0.5f, 0.25f, 1}));
      // The polyline of three vertices becomes two segments.
      EXPECT_EQ(shape.lines, (std::vector<vec2i>{{0, 1}, {1, 2}}));
      EXPECT_TRUE(shape.normals.empty() && shape.texcoords.empty() && shape.triangles.empty());
    }
  }
}

static void triangulates_polygons_as_fans_and_reads_st_texcoords() {
  auto dir = scratch_directory("ply-fans");
  write_file(dir.file("fan.ply"),
      "ply\r\nformat ascii 1.0\r\nelement vertex 5\r\nproperty float x\r\n"
      "property float y\r\nproperty float z\r\nproperty float s\r\nproperty float t\r\n"
      "element face 3\r\nproperty list uchar int vertex_indices\r\nend_header\r\n"
      "0 0 0 0 0\r\n1 0 0 1 0\r\n1 1 0 1 1\r\n0 1 0 0 1\r\n0.5 2 0 +0.5 2e0\r\n"
      "3 0 1 2\r\n4 0 1 2 3\r\n5 0 1 2 4 3\r\n");
  auto shape = shape_data{};
  auto error = std::string{};
  ASSERT_TRUE(load_shape(dir.file("fan.ply"), shape, error)) << error;
  EXPECT_EQ(shape.triangles, (std::vector<vec3i>{{0, 1, 2}, {0, 1, 2}, {0, 2, 3}, {0, 1, 2},
                                 {0, 2, 4}, {0, 4, 3}}));
  EXPECT_EQ(shape.texcoords.back(), (vec2f{0.5f, 2}));
}

// No vertices but every kind of vertex property: an empty shape. (The
// columns' storage is then null; the clang-sanitized build caught null plus
// an offset here.)
static void reads_an_empty_vertex_element_with_properties() {
  auto dir = scratch_directory("ply-empty");
  for (auto format : {"ascii", "binary_little_endian", "binary_big_endian"}) {
    auto filename = dir.file(std::string(format) + ".ply");
    write_file(filename, std::string("ply\nformat ") + format +
                             " 1.0\nelement vertex 0\nproperty float x\n"
                             "property float y\nproperty float z\nproperty float nx\n"
                             "property float ny\nproperty float nz\nproperty float u\n"
                             "property float v\nproperty float radius\nelement face 0\n"
                             "property list uchar int vertex_indices\nend_header\n");
    auto shape = shape_data{};
    auto error = std::string{};
    ASSERT_TRUE(load_shape(filename, shape, error)) << error;
    EXPECT_TRUE(shape.positions.empty() && shape.normals.empty() && shape.texcoords.empty() &&
                shape.radius.empty() && shape.triangles.empty());
  }
}

TEST(ply, loads_the_real_yocto_lines_file) {
  auto filename =
      std::string(YOCTO_SHARED_DIR) + "/data/yocto/yocto-gl-lines/thicklines-grid.ply";
  if (!std::filesystem::exists(filename)) GTEST_SKIP() << "no " << filename;
  auto shape = shape_data{};
  auto error = std::string{};
  ASSERT_TRUE(load_shape(filename, shape, error)) << error;
  // The header says 272 vertices (x y z nx ny nz u v radius) and 256 lines.
  EXPECT_EQ(shape.positions.size(), 272u);
  EXPECT_EQ(shape.normals.size(), 272u);
  EXPECT_EQ(shape.texcoords.size(), 272u);
  EXPECT_EQ(shape.radius.size(), 272u);
  EXPECT_EQ(shape.lines.size(), 256u);
  EXPECT_TRUE(shape.triangles.empty() && shape.curves.empty());
  for (auto radius : shape.radius) EXPECT_GT(radius, 0);
  for (auto& line : shape.lines) EXPECT_NE(line.x, line.y);
  // And it survives our own writer.
  auto dir = scratch_directory("ply-real");
  ASSERT_TRUE(save_shape(dir.file("copy.ply"), shape, error)) << error;
  auto copy = shape_data{};
  ASSERT_TRUE(load_shape(dir.file("copy.ply"), copy, error)) << error;
  expect_same_shape(shape, copy);
}

// A bad file must give false and a message naming the file and the place.
void expect_load_error(const std::string& filename, const std::vector<std::string>& parts) {
  auto shape = shape_data{};
  auto error = std::string{};
  EXPECT_FALSE(load_shape(filename, shape, error)) << filename;
  EXPECT_TRUE(contains(error, filename)) << error;
  for (auto& part : parts) EXPECT_TRUE(contains(error, part)) << error << " lacks " << part;
  EXPECT_TRUE(shape.positions.empty());
}

const auto ascii_header =
    std::string("ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\n"
                "property float y\nproperty float z\n");

static void reports_missing_files_and_malformed_headers_by_line() {
  auto dir = scratch_directory("ply-headers");
  expect_load_error(dir.file("missing.ply"), {"cannot open"});
  auto cases = std::vector<std::pair<std::string, std::vector<std::string>>>{
      {"solid cube\n", {"line 1", "not a PLY"}},
      {"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\n",
          {"line 5", "end_header"}},
      {"ply\nformat ascii 1.0\nelement vertex 1\nproperty half x\nend_header\n",
          {"line 4", "half"}},
      {"ply\nformat ascii 1.0\nproperty float x\nend_header\n",
          {"line 3", "before any element"}},
      {"ply\nformat ascii 1.0\nelement vertex many\nend_header\n", {"line 3", "many"}},
      {"ply\nformat utf8 1.0\nend_header\n", {"line 2", "utf8"}},
      {"ply\nformat ascii 1.0\ncomment ok\nvertex 3\nend_header\n", {"line 4", "vertex"}},
      {"ply\nformat ascii 1.0\nelement vertex 1\nproperty list uchar x\nend_header\n",
          {"line 4"}},
      {ascii_header.substr(0, ascii_header.size() - 17) + "end_header\n0 0\n",
          {"vertex", "no property z"}},
  };
  for (auto i = 0; i < (int)cases.size(); i++) {
    auto filename = dir.file("header" + std::to_string(i) + ".ply");
    write_file(filename, cases[i].first);
    expect_load_error(filename, cases[i].second);
  }
}

static void reports_truncated_data_with_element_and_index() {
  auto dir   = scratch_directory("ply-truncated");
  auto shape = make_random_shape(2, 30, 20);
  auto error = std::string{};
  ASSERT_TRUE(save_shape(dir.file("curves.ply"), shape, error)) << error;
  auto data = read_file(dir.file("curves.ply"));
  // Binary rows: 16 bytes per vertex (x y z radius), 17 per curve.
  auto cut_curves = data.substr(0, data.size() - 17 * 3 - 5);
  write_file(dir.file("cut-curves.ply"), cut_curves);
  expect_load_error(dir.file("cut-curves.ply"), {"element curve", "index 16", "ran out"});
  auto header_end = data.find("end_header\n") + 11;
  write_file(dir.file("cut-vertices.ply"), data.substr(0, header_end + 16 * 10 + 3));
  expect_load_error(dir.file("cut-vertices.ply"), {"element vertex", "index 10", "ran out"});
  // An absurd list length is caught before any allocation for it.
  auto bad_count = data;
  bad_count[header_end + 16 * 30] = (char)255;
  write_file(dir.file("bad-count.ply"), bad_count);
  expect_load_error(dir.file("bad-count.ply"), {"element curve", "index 0"});

  write_file(dir.file("cut-ascii.ply"), ascii_header + "end_header\n0 0 0\n1 1 1\n2 2\n");
  expect_load_error(dir.file("cut-ascii.ply"), {"element vertex", "index 2", "ran out"});
  write_file(dir.file("word.ply"), ascii_header + "end_header\n0 0 0\n1 one 1\n2 2 2\n");
  expect_load_error(dir.file("word.ply"), {"line 9", "element vertex", "index 1", "\"one\""});
}

static void reports_wrong_counts_bad_indices_and_bad_values() {
  auto dir   = scratch_directory("ply-indices");
  auto cases = std::vector<std::pair<std::string, std::vector<std::string>>>{
      {"element curve 2\nproperty list uchar int vertex_indices\nend_header\n"
       "0 0 0\n1 1 1\n2 2 2\n4 0 1 2 0\n3 0 1 2\n",
          {"element curve", "index 1", "expected 4"}},
      {"element face 1\nproperty list uchar int vertex_indices\nend_header\n"
       "0 0 0\n1 1 1\n2 2 2\n2 0 1\n",
          {"element face", "index 0", "at least 3"}},
      {"element line 1\nproperty list uchar int vertex_indices\nend_header\n"
       "0 0 0\n1 1 1\n2 2 2\n1 0\n",
          {"element line", "index 0", "at least 2"}},
      {"element line 2\nproperty list uchar int vertex_indices\nend_header\n"
       "0 0 0\n1 1 1\n2 2 2\n2 0 1\n2 1 3\n",
          {"element line", "index 1", "vertex index 3", "out of range"}},
      {"element face 1\nproperty list uchar int vertex_indices\nend_header\n"
       "0 0 0\n1 1 1\n2 2 2\n3 0 -1 2\n",
          {"element face", "index 0", "vertex index -1"}},
      {"element line 1\nproperty list uchar int other\nend_header\n"
       "0 0 0\n1 1 1\n2 2 2\n2 0 1\n",
          {"element line", "no vertex_indices"}},
      {"element line 1\nproperty list uchar int vertex_indices\nelement face 1\n"
       "property list uchar int vertex_indices\nend_header\n"
       "0 0 0\n1 1 1\n2 2 2\n2 0 1\n3 0 1 2\n",
          {"more than one"}},
      {"end_header\n0 0 0\n1 nan 1\n2 2 2\n", {"vertex", "index 1", "not finite"}},
      {"property float radius\nend_header\n0 0 0 1\n1 1 1 -1\n2 2 2 1\n",
          {"vertex", "index 1", "radius"}},
      // Half a normal or texcoord group once wrote out of bounds.
      {"property float nx\nproperty float u\nproperty float v\nend_header\n"
       "0 0 0 7 0.1 0.2\n1 1 1 7 0.1 0.2\n2 2 2 7 0.1 0.2\n",
          {"vertex", "property nx", "normal"}},
      {"property float ny\nproperty float nz\nend_header\n0 0 0 0 1\n1 1 1 0 1\n2 2 2 0 1\n",
          {"vertex", "property ny", "normal"}},
      {"property float nx\nproperty float ny\nproperty float nz\nproperty float t\n"
       "end_header\n0 0 0 0 0 1 5\n1 1 1 0 0 1 5\n2 2 2 0 0 1 5\n",
          {"vertex", "property t", "texcoord"}},
  };
  // An element of empty rows takes no data: a huge count must not hang.
  write_file(dir.file("empty-rows.ply"),
      ascii_header + "element nothing 18446744073709551615\nend_header\n0 0 0\n1 1 1\n2 2 2\n");
  auto shape = shape_data{};
  auto error = std::string{};
  EXPECT_TRUE(load_shape(dir.file("empty-rows.ply"), shape, error)) << error;
  EXPECT_EQ(shape.positions.size(), 3u);
  for (auto i = 0; i < (int)cases.size(); i++) {
    auto filename = dir.file("case" + std::to_string(i) + ".ply");
    write_file(filename, ascii_header + cases[i].first);
    expect_load_error(filename, cases[i].second);
  }
}

static void failed_saves_leave_no_file() {
  auto dir   = scratch_directory("ply-save-errors");
  auto error = std::string{};
  auto shape = make_random_shape(1, 10, 5);
  shape.radius.pop_back();
  EXPECT_FALSE(save_shape(dir.file("bad.ply"), shape, error));
  EXPECT_TRUE(contains(error, dir.file("bad.ply")) && contains(error, "radius")) << error;
  auto mixed = make_random_shape(1, 10, 5);
  mixed.curves.push_back({0, 1, 2, 3});
  EXPECT_FALSE(save_shape(dir.file("mixed.ply"), mixed, error));
  EXPECT_FALSE(save_shape(dir.file("no/such/dir/out.ply"), make_random_shape(2, 8, 2), error));
  EXPECT_TRUE(contains(error, "no/such/dir/out.ply")) << error;
  EXPECT_TRUE(list_files(dir.path).empty());
}

// Grouped so that ctest starts few processes: each one pays for loading
// OpenImageIO and its libraries (about 0.3 s).
TEST(ply, writes_and_reads_every_layout_type_and_format) {
  round_trips_triangles_lines_and_curves_in_binary_and_ascii();
  reads_every_property_type_in_every_format_and_skips_unknown_data();
  triangulates_polygons_as_fans_and_reads_st_texcoords();
  reads_an_empty_vertex_element_with_properties();
}

TEST(ply, rejects_bad_input_naming_file_and_place) {
  reports_missing_files_and_malformed_headers_by_line();
  reports_truncated_data_with_element_and_index();
  reports_wrong_counts_bad_indices_and_bad_values();
  failed_saves_leave_no_file();
}
