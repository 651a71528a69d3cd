//
// Implementation of Yocto/HairIO: see yocto_hairio.h.
//

#include "yocto_hairio.h"

#include <cstdio>
#include <cstring>
#include <filesystem>
#include <limits>
#include <new>

// -----------------------------------------------------------------------------
// HAIR FILES
// -----------------------------------------------------------------------------
namespace yocto {

// Cem Yuksel's .hair layout: a 128-byte header, then the optional arrays
// segments (uint16 per strand), points (3 floats), thickness, transparency
// (1 float) and colour (3 floats) per point, in that order, little-endian.
struct hair_header {
  char     signature[4]         = {'H', 'A', 'I', 'R'};
  uint32_t num_strands          = 0;
  uint32_t num_points           = 0;
  uint32_t flags                = 0;
  uint32_t default_segments     = 0;
  float    default_thickness    = 1;
  float    default_transparency = 0;
  float    default_color[3]     = {0, 0, 0};
  char     info[88]             = {};
};
static_assert(sizeof(hair_header) == 128, "the .hair header is 128 bytes");

enum hair_flags : uint32_t {
  hair_has_segments     = 1,
  hair_has_points       = 2,
  hair_has_thickness    = 4,
  hair_has_transparency = 8,
  hair_has_color        = 16,
};

static bool load_hair_model(const std::string& filename, shape_data& shape,
    std::string& error, vec3f* color, bool* has_color_array, double max_memory) {
  shape          = {};
  auto file_size = (size_t)0;
  if (!check_input_file(filename, file_size, error)) return false;
  auto data = std::string{};
  if (!load_text(filename, data, error, max_memory)) return false;
  auto header = hair_header{};
  if (data.size() < sizeof(header)) {
    error = filename + ": truncated header at byte " + std::to_string(data.size()) +
            " (a .hair header has 128 bytes)";
    return false;
  }
  std::memcpy(&header, data.data(), sizeof(header));
  if (std::memcmp(header.signature, "HAIR", 4) != 0) {
    error = filename + ": not a .hair file (bad signature at byte 0)";
    return false;
  }
  auto flags = header.flags;
  if (!(flags & hair_has_points)) {
    error = filename + ": the header (byte 12) declares no points array";
    return false;
  }
  // Check every count against the file size before allocating anything.
  auto strands = (uint64_t)header.num_strands, points = (uint64_t)header.num_points;
  auto offset_segments  = (uint64_t)sizeof(header);
  auto offset_points    = offset_segments + ((flags & hair_has_segments) ? 2 * strands : 0);
  auto offset_thickness = offset_points + 12 * points;
  auto offset_transp    = offset_thickness + ((flags & hair_has_thickness) ? 4 * points : 0);
  auto offset_color     = offset_transp + ((flags & hair_has_transparency) ? 4 * points : 0);
  auto expected_size    = offset_color + ((flags & hair_has_color) ? 12 * points : 0);
  if (expected_size > data.size()) {
    error = filename + ": truncated at byte " + std::to_string(data.size()) + ": the header (" +
            std::to_string(strands) + " strands, " + std::to_string(points) +
            " points) needs " + std::to_string(expected_size) + " bytes";
    return false;
  }
  if (points > (uint64_t)std::numeric_limits<int>::max() / 4) {
    error = filename + ": too many points (" + std::to_string(points) + ") at byte 8";
    return false;
  }
  // Every strand has a point, so the points (bounded by the file's size
  // above) bound the strands before any loop over them.
  if (strands > points) {
    error = filename + ": the header claims " + std::to_string(strands) +
            " strands (byte 4) for " + std::to_string(points) +
            " points (byte 8); every strand has at least one point";
    return false;
  }
  // The points read, then the spline through them: up to three control
  // points with a radius (and a colour) and a curve per point.
  auto needed = (double)points * (sizeof(vec3f) + sizeof(float)) +
                3.0 * (double)points * (sizeof(vec3f) + sizeof(float)) +
                (double)points * sizeof(vec4i) +
                ((flags & hair_has_color) ? 4.0 * (double)points * sizeof(vec3f) : 0.0);
  if (!check_load_memory(filename, "the spline through " + std::to_string(points) + " points",
          needed, max_memory, error))
    return false;
  auto bytes = (const unsigned char*)data.data();
  auto read_float = [&](uint64_t offset) {
    auto value = 0.0f;
    std::memcpy(&value, bytes + offset, 4);
    return value;
  };
  auto strand_segments = [&](uint64_t strand) -> uint64_t {
    if (!(flags & hair_has_segments)) return header.default_segments;
    auto value = (uint16_t)0;
    std::memcpy(&value, bytes + offset_segments + 2 * strand, 2);
    return value;
  };
  auto total = (uint64_t)0;
  for (auto s = (uint64_t)0; s < strands; s++) total += strand_segments(s) + 1;
  if (total != points) {
    error = filename + ": the strands' segments " +
            std::string{(flags & hair_has_segments) ? "(array at byte 128)"
                                                    : "(default at byte 16)"} +
            " add up to " + std::to_string(total) + " points, the header (byte 8) says " +
            std::to_string(points);
    return false;
  }
  // Points and radii, checked for garbage.
  auto positions = std::vector<vec3f>(points);
  auto radii     = std::vector<float>(points, header.default_thickness / 2);
  for (auto i = (uint64_t)0; i < points; i++) {
    auto offset  = offset_points + 12 * i;
    positions[i] = {read_float(offset), read_float(offset + 4), read_float(offset + 8)};
    if (!isfinite(positions[i])) {
      error = filename + ": point " + std::to_string(i) + " at byte " + std::to_string(offset) +
              " is not finite";
      return false;
    }
    if (flags & hair_has_thickness) radii[i] = read_float(offset_thickness + 4 * i) / 2;
    if (!(radii[i] >= 0 && radii[i] < flt_max)) {
      error = filename + ": thickness of point " + std::to_string(i) + " at byte " +
              std::to_string((flags & hair_has_thickness) ? offset_thickness + 4 * i : 20) +
              " is not a non-negative number";
      return false;
    }
  }
  // Per-point colours, when the file has them: the shape's colours (clamped
  // into (0, 1), where Chiang's inversion to an absorption holds; a
  // non-finite one as the file's average), and their average the model's.
  auto colors  = std::vector<vec3f>{};
  auto average = vec3f{header.default_color[0], header.default_color[1], header.default_color[2]};
  if (flags & hair_has_color) {
    auto sum = vec3f{0, 0, 0};
    colors.resize(points);
    for (auto i = (uint64_t)0; i < points; i++) {
      auto offset = offset_color + 12 * i;
      colors[i]   = vec3f{read_float(offset), read_float(offset + 4), read_float(offset + 8)};
      if (isfinite(colors[i])) sum += colors[i];
    }
    average = points ? sum / (float)points : vec3f{0, 0, 0};
    for (auto& c : colors) c = glm::clamp(isfinite(c) ? c : average, vec3f{0.01f}, vec3f{0.99f});
  }
  if (color) *color = average;
  if (has_color_array) *has_color_array = (flags & hair_has_color) != 0;
  // A Catmull-Rom spline through each strand's points.
  shape.positions.reserve(points * 3);
  shape.radius.reserve(points * 3);
  auto first = (uint64_t)0;
  for (auto s = (uint64_t)0; s < strands; s++) {
    auto count = strand_segments(s) + 1;
    append_catmull_rom_strand(shape,
        std::vector<vec3f>(positions.begin() + first, positions.begin() + first + count),
        std::vector<float>(radii.begin() + first, radii.begin() + first + count),
        colors.empty() ? std::vector<vec3f>{}
                       : std::vector<vec3f>(colors.begin() + first, colors.begin() + first + count));
    first += count;
  }
  return true;
}

bool load_hair_model(const std::string& filename, shape_data& shape, std::string& error,
    vec3f* color, double max_memory) try {
  return load_hair_model(filename, shape, error, color, nullptr, max_memory);
} catch (const std::bad_alloc&) {
  // Past the budget's checks, the system (or ulimit -v) gave less.
  error = allocation_error(filename, "its strands");
  return false;
}

bool save_hair_model(const std::string& filename, const shape_data& shape, std::string& error) {
  // Strands: chains of curves (lines) where each starts at the previous end.
  auto segments = std::vector<uint16_t>{};
  auto vertices = std::vector<int>{};
  auto add_element = [&](int start, int end, bool continues) {
    if (!continues) {
      segments.push_back(0);
      vertices.push_back(start);
    }
    if (segments.back() == 65535) return false;
    segments.back()++;
    vertices.push_back(end);
    return true;
  };
  auto num_vertices = (int)shape.positions.size();
  auto in_range = [&](int v) { return v >= 0 && v < num_vertices; };
  for (auto i = 0; i < (int)shape.curves.size(); i++) {
    auto& c = shape.curves[i];
    if (!in_range(c.x) || !in_range(c.w)) {
      error = filename + ": curve " + std::to_string(i) + " references a missing vertex";
      return false;
    }
    if (!add_element(c.x, c.w, i > 0 && shape.curves[i - 1].w == c.x)) {
      error = filename + ": a strand has more than 65535 segments";
      return false;
    }
  }
  for (auto i = 0; i < (int)shape.lines.size(); i++) {
    auto& l = shape.lines[i];
    if (!in_range(l.x) || !in_range(l.y)) {
      error = filename + ": line " + std::to_string(i) + " references a missing vertex";
      return false;
    }
    if (!add_element(l.x, l.y, i > 0 && shape.lines[i - 1].y == l.x)) {
      error = filename + ": a strand has more than 65535 segments";
      return false;
    }
  }
  if (segments.empty()) {
    error = filename + ": the shape has no curves or lines to save";
    return false;
  }
  auto has_radius = shape.radius.size() == shape.positions.size();
  auto has_colors = shape.colors.size() == shape.positions.size();
  auto header     = hair_header{};
  header.num_strands = (uint32_t)segments.size();
  header.num_points  = (uint32_t)vertices.size();
  header.flags       = hair_has_segments | hair_has_points |
                 (has_radius ? (uint32_t)hair_has_thickness : 0u) |
                 (has_colors ? (uint32_t)hair_has_color : 0u);
  std::snprintf(header.info, sizeof(header.info), "yocto-hair");
  auto data = std::string((const char*)&header, sizeof(header));
  data.append((const char*)segments.data(), segments.size() * sizeof(uint16_t));
  for (auto v : vertices) data.append((const char*)&shape.positions[v], 12);
  if (has_radius) {
    for (auto v : vertices) {
      auto thickness = 2 * shape.radius[v];
      data.append((const char*)&thickness, 4);
    }
  }
  // The file's arrays in order: transparency (never written), then colours.
  if (has_colors) {
    for (auto v : vertices) data.append((const char*)&shape.colors[v], 12);
  }
  // save_text writes bytes as they are, through a temporary name.
  return save_text(filename, data, error);
}

bool load_hair_scene(const std::string& filename, scene_data& scene, std::string& error,
    const hair_params& params) {
  scene            = {};
  auto shape       = shape_data{};
  auto color       = vec3f{0, 0, 0};
  auto color_array = false;
  if (!load_hair_model(filename, shape, error, &color, &color_array, params.max_memory))
    return false;
  if (shape.curves.empty()) {
    error = filename + ": the model has no strand with a segment";
    return false;
  }
  if (params.curves_as_lines) shape = curves_to_lines(shape, params.segments);
  auto material = material_data{};
  material.type = material_type::hair;
  if (color_array) {
    // Chiang's inversion needs a reflectance strictly inside (0, 1).
    material.hair.has_color = true;
    material.hair.color     = glm::clamp(color, vec3f{0.01f}, vec3f{0.99f});
  }
  auto name = std::filesystem::path(filename).stem().string();
  scene.shapes.push_back(std::move(shape));
  scene.shape_names.push_back(name);
  scene.materials.push_back(material);
  scene.material_names.push_back("hair");
  scene.instances.push_back({identity3x4f, 0, 0});
  scene.instance_names.push_back(name);
  scene.environments.push_back({identity3x4f, {1, 1, 1}, -1});
  scene.environment_names.push_back("sky");
  add_missing_camera(scene);
  return validate_loaded_scene(scene, filename, error);
}

}  // namespace yocto
