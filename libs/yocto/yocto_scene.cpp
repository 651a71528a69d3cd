//
// Implementation of Yocto/Scene.
//

#include "yocto_scene.h"

#include <array>
#include <cstring>
#include <unordered_map>

#include <cmath>
#include <cstdio>

// -----------------------------------------------------------------------------
// CAMERAS
// -----------------------------------------------------------------------------
namespace yocto {

vec2i camera_resolution(const camera_data& camera, int resolution) {
  auto aspect = camera.aspect > 0 ? camera.aspect : 1.0f;
  if (aspect >= 1) {
    return {resolution, std::max(1, (int)std::lround(resolution / aspect))};
  } else {
    return {std::max(1, (int)std::lround(resolution * aspect)), resolution};
  }
}

vec2f camera_film_size(const camera_data& camera) {
  return camera.aspect >= 1 ? vec2f{camera.film, camera.film / camera.aspect}
                            : vec2f{camera.film * camera.aspect, camera.film};
}

ray3f eval_camera(const camera_data& camera, const vec2f& image_uv, const vec2f& lens_uv) {
  // The image plane is at `lens` behind the pinhole, so a film point q maps
  // to the direction -q.
  auto film = camera_film_size(camera);
  auto q = vec3f{film.x * (0.5f - image_uv.x), film.y * (image_uv.y - 0.5f),
      camera.lens};
  if (camera.orthographic) {
    auto scale = camera.focus / camera.lens;
    auto o     = vec3f{-q.x * scale, -q.y * scale, 0};
    return {transform_point(camera.frame, o),
        transform_direction(camera.frame, {0, 0, -1})};
  }
  auto direction = normalize(-q);
  if (camera.aperture <= 0) {
    return {camera.frame.o, transform_direction(camera.frame, direction)};
  }
  // Thin lens: aim every lens point at the point in focus along this pixel.
  auto focus_point = direction * (camera.focus / std::abs(direction.z));
  auto r           = std::sqrt(lens_uv.x) * camera.aperture / 2;
  auto phi         = 2 * pif * lens_uv.y;
  auto lens_point  = vec3f{r * std::cos(phi), r * std::sin(phi), 0};
  return {transform_point(camera.frame, lens_point),
      transform_direction(camera.frame, focus_point - lens_point)};
}

vec2f project_camera_point(const camera_data& camera, const vec3f& point) {
  // Camera space looks down -z; the film point at depth `lens` scales by
  // lens / depth.
  auto local = transform_point(inverse(camera.frame), point);
  auto film  = camera_film_size(camera);
  auto scale = camera.lens / -local.z;
  return {0.5f + local.x * scale / film.x, 0.5f - local.y * scale / film.y};
}

}  // namespace yocto

// -----------------------------------------------------------------------------
// TEXTURES AND ENVIRONMENTS
// -----------------------------------------------------------------------------
namespace yocto {

// Bilinear lookup, pixel centers at half-integers; u always wraps, v wraps
// or is clamped to the first and last rows.
static vec3f eval_texture(const texture_data& texture, const vec2f& uv, bool clamp_v) {
  if (texture.width <= 0 || texture.height <= 0) return {1, 1, 1};
  auto s  = (uv.x - std::floor(uv.x)) * texture.width - 0.5f;
  auto t  = (clamp_v ? std::clamp(uv.y, 0.0f, 1.0f) : uv.y - std::floor(uv.y)) *
               texture.height - 0.5f;
  auto i  = (int)std::floor(s), j = (int)std::floor(t);
  auto fu = s - i, fv = t - j;
  auto wrap_i = [&](int x) { return ((x % texture.width) + texture.width) % texture.width; };
  auto wrap_j = [&](int y) {
    if (clamp_v) return std::clamp(y, 0, texture.height - 1);
    return ((y % texture.height) + texture.height) % texture.height;
  };
  auto at = [&](int x, int y) {
    return texture.pixels[(size_t)wrap_j(y) * texture.width + wrap_i(x)];
  };
  return at(i, j) * (1 - fu) * (1 - fv) + at(i + 1, j) * fu * (1 - fv) +
         at(i, j + 1) * (1 - fu) * fv + at(i + 1, j + 1) * fu * fv;
}

vec3f eval_texture(const texture_data& texture, const vec2f& uv) {
  return eval_texture(texture, uv, false);
}

vec3f eval_environment_texture(const texture_data& texture, const vec2f& uv) {
  return eval_texture(texture, uv, true);
}

// Yocto/GL's equirectangular convention: u = atan2(z, x) / 2pi, v = acos(y)/pi.
vec2f direction_to_equirect(const vec3f& w) {
  auto u = std::atan2(w.z, w.x) / (2 * pif);
  if (u < 0) u += 1;
  return {u, safe_acos(w.y) / pif};
}
vec3f equirect_to_direction(const vec2f& uv) {
  auto phi = uv.x * 2 * pif, theta = uv.y * pif;
  return {std::cos(phi) * std::sin(theta), std::cos(theta), std::sin(phi) * std::sin(theta)};
}

vec3f eval_environment(const scene_data& scene, const environment_data& environment,
    const vec3f& direction) {
  if (environment.emission_tex < 0) return environment.emission;
  auto local = transform_direction(inverse(environment.frame, false), direction);
  return environment.emission *
         eval_environment_texture(
             scene.textures[environment.emission_tex], direction_to_equirect(local));
}

}  // namespace yocto

// -----------------------------------------------------------------------------
// HAIR PARAMETERS
// -----------------------------------------------------------------------------
namespace yocto {

// Each row reads its value through the pointer of its kind, a field no
// other row reads, and its default is hair_material{}'s (a number's in every
// component).
static constexpr bool hair_parameters_agree_with_hair_material() {
  constexpr auto defaults = hair_material{};
  for (auto& parameter : hair_parameters) {
    auto number = parameter.kind == hair_parameter_kind::number;
    if (number != (parameter.number != nullptr) || number == (parameter.rgb != nullptr))
      return false;
    auto value = number ? vec3f{defaults.*parameter.number} : defaults.*parameter.rgb;
    if (value != parameter.default_value) return false;
    for (auto& other : hair_parameters) {
      if (&other == &parameter) continue;
      if ((number && other.number == parameter.number) ||
          (!number && other.rgb == parameter.rgb) || (parameter.has && other.has == parameter.has))
        return false;
    }
  }
  return true;
}
static_assert(hair_parameters_agree_with_hair_material(),
    "a row of hair_parameters disagrees with hair_material (kind, default) or reads "
    "another row's field");

const hair_parameter* find_hair_parameter(const std::string& key) {
  for (auto& parameter : hair_parameters)
    if (key == parameter.name || (parameter.alias[0] != 0 && key == parameter.alias))
      return &parameter;
  return nullptr;
}

vec3f get_hair_parameter(const hair_material& material, const hair_parameter& parameter) {
  return parameter.kind == hair_parameter_kind::number ? vec3f{material.*parameter.number}
                                                       : material.*parameter.rgb;
}

void set_hair_parameter(
    hair_material& material, const hair_parameter& parameter, const vec3f& value) {
  if (parameter.kind == hair_parameter_kind::number) material.*parameter.number = value.x;
  else material.*parameter.rgb = value;
  if (parameter.has) material.*parameter.has = true;
}

bool is_hair_parameter_set(const hair_material& material, const hair_parameter& parameter) {
  if (parameter.has) return material.*parameter.has;
  return get_hair_parameter(material, parameter) != parameter.default_value;
}

bool is_hair_parameter_valid(const hair_parameter& parameter, const vec3f& value) {
  for (auto c : {value.x, value.y, value.z}) {
    auto above = parameter.min_open ? c > parameter.min : c >= parameter.min;
    auto below = parameter.max_open ? c < parameter.max : c <= parameter.max;
    if (!(above && below)) return false;  // NaN fails both
  }
  return true;
}

std::string format_hair_parameter_range(const hair_parameter& parameter) {
  char buffer[96];
  if (parameter.max == flt_max) {
    std::snprintf(buffer, sizeof(buffer), "%s %g", parameter.min_open ? ">" : ">=",
        parameter.min);
  } else {
    std::snprintf(buffer, sizeof(buffer), "in %c%g, %g%c", parameter.min_open ? '(' : '[',
        parameter.min, parameter.max, parameter.max_open ? ')' : ']');
  }
  return buffer;
}

std::string format_hair_parameter_value(const hair_parameter& parameter, const vec3f& value) {
  char text[96];
  if (parameter.kind == hair_parameter_kind::number)
    std::snprintf(text, sizeof(text), "%g", value.x);
  else std::snprintf(text, sizeof(text), "[%g %g %g]", value.x, value.y, value.z);
  return text;
}

bool check_hair_material(const hair_material& material, std::string& error) {
  for (auto& parameter : hair_parameters) {
    if (parameter.has && !(material.*parameter.has)) continue;
    auto value = get_hair_parameter(material, parameter);
    if (is_hair_parameter_valid(parameter, value)) continue;
    error = std::string(parameter.name) + " " + format_hair_parameter_value(parameter, value) +
            " is not " + format_hair_parameter_range(parameter);
    return false;
  }
  return true;
}

}  // namespace yocto

// -----------------------------------------------------------------------------
// BOUNDS AND VALIDATION
// -----------------------------------------------------------------------------
namespace yocto {

double shape_memory(const shape_data& shape) {
  return (double)shape.triangles.size() * sizeof(vec3i) +
         (double)shape.lines.size() * sizeof(vec2i) +
         (double)shape.curves.size() * sizeof(vec4i) +
         (double)shape.positions.size() * sizeof(vec3f) +
         (double)shape.normals.size() * sizeof(vec3f) +
         (double)shape.texcoords.size() * sizeof(vec2f) +
         (double)shape.radius.size() * sizeof(float) +
         (double)shape.colors.size() * sizeof(vec3f) +
         (double)shape.fiber_vertices.size() * sizeof(vec4f) +
         (double)shape.fiber_curves.size() * sizeof(int);
}

// Scene values into a hash_stream.
struct scene_hasher {
  hash_stream stream = {};
  void add_bytes(const void* data, size_t size) { hash_bytes(stream, data, size); }
  template <typename T>
  void add(const std::vector<T>& values) {
    add_bytes(values.data(), values.size() * sizeof(T));
  }
  template <typename... Ts>
  void add_values(const Ts&... values) {
    // Field by field: a struct's padding bytes are not part of its value.
    (add_bytes(&values, sizeof(values)), ...);
  }
  void add(const frame3f& frame) { add_values(frame.x, frame.y, frame.z, frame.o); }
  // The array of `count` values of T that value(i) gives, hashed as
  // hash_bytes hashes it (its words, then its size), made a block at a time
  // (4096 values: whole words): a packed shape's arrays as they were.
  template <typename T, typename Value>
  void add_unpacked(size_t count, const Value& value) {
    auto block = std::vector<T>{};
    for (size_t first = 0; first < count; first += 4096) {
      block.clear();
      for (auto i = first; i < std::min(first + 4096, count); i++) block.push_back(value(i));
      hash_words(stream, block.data(), block.size() * sizeof(T));
    }
    hash_word(stream, count * sizeof(T));
  }
  // Every hair parameter: the values in the table's order, then the has_
  // flags; first of the parameters that are not variation, then of those that
  // are, if some value or flag of them is away from its default, so that
  // materials without variation keep the fingerprint they had before it.
  void add(const hair_material& hair) {
    auto add_rows = [&](bool variation) {
      auto in_rows = [&](const hair_parameter& parameter) {
        return (parameter.group == hair_parameter_group::variation) == variation;
      };
      for (auto& parameter : hair_parameters) {
        if (!in_rows(parameter)) continue;
        if (parameter.kind == hair_parameter_kind::number) add_values(hair.*parameter.number);
        else add_values(hair.*parameter.rgb);
      }
      for (auto& parameter : hair_parameters)
        if (in_rows(parameter) && parameter.has) add_values(hair.*parameter.has);
    };
    auto varies = false;
    for (auto& parameter : hair_parameters) {
      if (parameter.group != hair_parameter_group::variation) continue;
      varies |= get_hair_parameter(hair, parameter) != parameter.default_value ||
                (parameter.has && hair.*parameter.has);
    }
    add_rows(false);
    if (varies) add_rows(true);
  }
};

uint64_t fingerprint_scene(const scene_data& scene) {
  auto hasher = scene_hasher{};
  for (auto& shape : scene.shapes) {
    hasher.add(shape.triangles);
    hasher.add(shape.lines);
    if (shape.fiber_curves.empty()) {
      hasher.add(shape.curves);
    } else {
      hasher.add_unpacked<vec4i>(shape.fiber_curves.size(),
          [&](size_t i) { return curve_vertices(shape, (int)i); });
    }
    if (shape.fiber_vertices.empty()) {
      hasher.add(shape.positions);
      hasher.add(shape.normals);
      hasher.add(shape.texcoords);
      hasher.add(shape.radius);
    } else {
      // A packed shape hashes as it did unpacked: its positions, normals,
      // texcoords and radii in that order.
      auto& vertices = shape.fiber_vertices;
      hasher.add_unpacked<vec3f>(
          vertices.size(), [&](size_t i) { return vertex_position(shape, (int)i); });
      hasher.add(shape.normals);
      hasher.add(shape.texcoords);
      hasher.add_unpacked<float>(
          vertices.size(), [&](size_t i) { return vertex_radius(shape, (int)i); });
    }
    // Only when present: the fingerprints of shapes without colours stay.
    if (!shape.colors.empty()) hasher.add(shape.colors);
  }
  for (auto& texture : scene.textures) {
    hasher.add_values(texture.width, texture.height);
    hasher.add(texture.pixels);
  }
  for (auto& material : scene.materials) {
    hasher.add_values(material.type, material.emission, material.color, material.roughness,
        material.ior, material.emission_tex, material.color_tex);
    hasher.add(material.hair);
  }
  for (auto& instance : scene.instances) {
    hasher.add(instance.frame);
    hasher.add_values(instance.shape, instance.material);
  }
  for (auto& environment : scene.environments) {
    hasher.add(environment.frame);
    hasher.add_values(environment.emission, environment.emission_tex);
  }
  for (auto& light : scene.distant_lights) hasher.add_values(light.direction, light.emission);
  // The element counts, so that moving data between groups changes it too.
  hasher.add_values(scene.shapes.size(), scene.textures.size(), scene.materials.size(),
      scene.instances.size(), scene.environments.size(), scene.distant_lights.size());
  return hasher.stream.hash;
}

bbox3f compute_bounds(const shape_data& shape) {
  auto bounds = bbox3f{};
  for (auto i = 0; i < num_vertices(shape); i++) {
    auto p = vertex_position(shape, i);
    auto r = vertex_radius(shape, i);
    bounds = merge(bounds, p - r);
    bounds = merge(bounds, p + r);
  }
  return bounds;
}

void pack_fiber_vertices(shape_data& shape) {
  if (!is_fiber(shape) || !shape.fiber_vertices.empty() ||
      shape.radius.size() != shape.positions.size())
    return;
  shape.fiber_vertices.resize(shape.positions.size());
  for (size_t i = 0; i < shape.positions.size(); i++)
    shape.fiber_vertices[i] = {shape.positions[i], shape.radius[i]};
  // Swapped with empty vectors: assigning {} would keep their memory.
  std::vector<vec3f>{}.swap(shape.positions);
  std::vector<float>{}.swap(shape.radius);
  if (shape.curves.empty() || !elements_are_consecutive(shape.curves)) return;
  shape.fiber_curves.resize(shape.curves.size());
  for (size_t i = 0; i < shape.curves.size(); i++) shape.fiber_curves[i] = shape.curves[i].x;
  std::vector<vec4i>{}.swap(shape.curves);
  // Strands of one length, one after the other: the first strand's
  // segments (curves whose first vertices step by 3), then every curve checked.
  auto count = (int)shape.fiber_curves.size(), n = 1;
  while (n < count && shape.fiber_curves[n] == shape.fiber_curves[n - 1] + 3) n++;
  auto regular = count < (1 << 29);
  for (auto e = 0; e < count && regular; e++)
    regular = shape.fiber_curves[e] == 3 * e + e / n;
  shape.fiber_strand_segments = regular ? n : 0;
}
void pack_fiber_vertices(scene_data& scene) {
  for (auto& shape : scene.shapes) pack_fiber_vertices(shape);
}

void unpack_fiber_vertices(shape_data& shape) {
  if (shape.fiber_vertices.empty()) return;
  // Read through the accessors of the packed layout, then freed.
  auto count = num_vertices(shape);
  shape.positions.resize(count);
  shape.radius.resize(count);
  for (auto i = 0; i < count; i++) {
    shape.positions[i] = vertex_position(shape, i);
    shape.radius[i]    = vertex_radius(shape, i);
  }
  if (!shape.fiber_curves.empty()) {
    shape.curves.resize(shape.fiber_curves.size());
    for (auto i = 0; i < num_curves(shape); i++) shape.curves[i] = curve_vertices(shape, i);
  }
  std::vector<vec4f>{}.swap(shape.fiber_vertices);
  std::vector<int>{}.swap(shape.fiber_curves);
  shape.fiber_strand_segments = 0;
}

bbox3f compute_bounds(const scene_data& scene) {
  auto shape_bounds = std::vector<bbox3f>{};
  for (auto& shape : scene.shapes) shape_bounds.push_back(compute_bounds(shape));
  auto bounds = bbox3f{};
  for (auto& instance : scene.instances) {
    if (instance.shape < 0 || instance.shape >= (int)shape_bounds.size()) continue;
    auto& sb = shape_bounds[instance.shape];
    if (empty(sb)) continue;
    for (auto c = 0; c < 8; c++) {
      auto corner = vec3f{(c & 1) ? sb.max.x : sb.min.x,
          (c & 2) ? sb.max.y : sb.min.y, (c & 4) ? sb.max.z : sb.min.z};
      bounds = merge(bounds, transform_point(instance.frame, corner));
    }
  }
  return bounds;
}

template <typename T>
static bool check_elements(const std::vector<T>& elements, int num_vertices,
    const std::string& shape_name, const char* kind, std::string& error) {
  for (auto i = 0; i < (int)elements.size(); i++) {
    for (auto k = 0; k < (int)elements[i].length(); k++) {
      if (elements[i][k] < 0 || elements[i][k] >= num_vertices) {
        error = "shape " + shape_name + ": " + kind + " " + std::to_string(i) +
                " references vertex " + std::to_string(elements[i][k]) + " of " +
                std::to_string(num_vertices);
        return false;
      }
    }
  }
  return true;
}

static std::string element_name(const std::vector<std::string>& names, int index,
    const char* kind) {
  if (index >= 0 && index < (int)names.size() && !names[index].empty())
    return std::string(kind) + " \"" + names[index] + "\"";
  return std::string(kind) + " " + std::to_string(index);
}

// A frame must be finite and invertible: Embree asserts on a singular
// instance, and a camera or environment with one maps every direction to
// zero. Singular is relative to the axes' lengths, so tiny scales pass.
static bool check_frame(const frame3f& frame, const std::string& name, std::string& error) {
  if (!isfinite(frame.x) || !isfinite(frame.y) || !isfinite(frame.z) || !isfinite(frame.o)) {
    error = name + ": frame is not finite";
    return false;
  }
  auto x = glm::dvec3(frame.x), y = glm::dvec3(frame.y), z = glm::dvec3(frame.z);
  auto det = std::abs(glm::dot(x, glm::cross(y, z)));
  if (!(det > 1e-12 * glm::length(x) * glm::length(y) * glm::length(z))) {
    error = name + ": frame is singular";
    return false;
  }
  return true;
}

static std::string format_number(double value) {
  char buffer[32];
  std::snprintf(buffer, sizeof(buffer), "%g", value);
  return buffer;
}

// The component of largest magnitude (NaN if any is NaN), for messages.
static float largest_component(const vec3f& v) {
  auto largest = v.x;
  for (auto c : {v.y, v.z})
    if (std::isnan(c) || std::abs(c) > std::abs(largest)) largest = c;
  return largest;
}

static bool in_scene_range(const vec3f& p) {
  return std::abs(p.x) <= max_scene_coordinate && std::abs(p.y) <= max_scene_coordinate &&
         std::abs(p.z) <= max_scene_coordinate;  // false for NaN
}

static std::string outside_range() {
  return "outside the range the ray tracer accepts (|coordinate| <= " +
         format_number(max_scene_coordinate) + ")";
}

// Cameras: parameters each finite can still overflow together (a huge film
// over a tiny lens, a huge focus or aperture), so the rays themselves are
// checked where eval_camera's origins and directions are extreme: the corner,
// edge and centre pixels, through the centre and the rim of the lens.
static bool check_camera(const camera_data& camera, const std::string& name, std::string& error) {
  auto parameters = {std::pair{"lens", camera.lens}, std::pair{"film", camera.film},
      std::pair{"aspect", camera.aspect}, std::pair{"focus", camera.focus}};
  for (auto [what, value] : parameters) {
    if (!(std::isfinite(value) && value > 0)) {
      error = name + ": " + what + " " + format_number(value) + " is not positive and finite";
      return false;
    }
  }
  if (!(std::isfinite(camera.aperture) && camera.aperture >= 0)) {
    error = name + ": aperture " + format_number(camera.aperture) +
            " is not zero or positive and finite";
    return false;
  }
  if (!in_scene_range(camera.frame.o)) {
    error = name + ": position " + format_number(largest_component(camera.frame.o)) +
            " is " + outside_range();
    return false;
  }
  auto rays_error = [&](const std::string& problem) {
    error = name + ": lens " + format_number(camera.lens) + ", film " +
            format_number(camera.film) + ", aspect " + format_number(camera.aspect) +
            ", focus " + format_number(camera.focus) + " and aperture " +
            format_number(camera.aperture) + " give rays the ray tracer cannot trace: " +
            problem;
    return false;
  };
  for (auto u : {0.0f, 0.5f, 1.0f}) {
    for (auto v : {0.0f, 0.5f, 1.0f}) {
      for (auto lens_uv : {vec2f{0, 0}, vec2f{1, 0}, vec2f{1, 0.25f}, vec2f{1, 0.5f},
               vec2f{1, 0.75f}}) {
        auto ray = eval_camera(camera, {u, v}, lens_uv);
        if (!in_scene_range(ray.o))
          return rays_error("an origin at " + format_number(largest_component(ray.o)) +
                            ", " + outside_range());
        if (!isfinite(ray.d) || std::abs(length(ray.d) - 1) > 1e-3f)
          return rays_error("a direction that is not a finite unit vector");
      }
    }
  }
  return true;
}

// Vertex positions and radii: Embree takes them as they are.
// Packed or not (pack_fiber_vertices).
static bool check_shape_range(const shape_data& shape, const std::string& name,
    std::string& error) {
  for (auto i = 0; i < num_vertices(shape); i++) {
    auto position = vertex_position(shape, i);
    if (!in_scene_range(position)) {
      error = name + ": vertex " + std::to_string(i) + ": position " +
              format_number(largest_component(position)) + " is " + outside_range();
      return false;
    }
  }
  auto has_radius = !shape.radius.empty() || !shape.fiber_vertices.empty();
  for (auto i = 0; has_radius && i < num_vertices(shape); i++) {
    auto radius = vertex_radius(shape, i);
    if (!(radius >= 0 && radius <= max_scene_coordinate)) {
      error = name + ": vertex " + std::to_string(i) + ": radius " +
              format_number(radius) + " is negative or outside the range the " +
              "ray tracer accepts (<= " + format_number(max_scene_coordinate) + ")";
      return false;
    }
  }
  return true;
}

bool validate_scene(const scene_data& scene, std::string& error) {
  auto num_textures = (int)scene.textures.size();
  for (auto i = 0; i < (int)scene.cameras.size(); i++) {
    auto name = element_name(scene.camera_names, i, "camera");
    if (!check_frame(scene.cameras[i].frame, name, error)) return false;
    if (!check_camera(scene.cameras[i], name, error)) return false;
  }
  for (auto i = 0; i < (int)scene.distant_lights.size(); i++) {
    auto direction = scene.distant_lights[i].direction;
    if (!(std::abs(length(normalize(direction)) - 1) <= 1e-3f)) {  // false for NaN
      error = "distant light " + std::to_string(i) + ": direction [" +
              format_number(direction.x) + " " + format_number(direction.y) + " " +
              format_number(direction.z) + "] does not normalize to a unit vector";
      return false;
    }
  }
  for (auto i = 0; i < (int)scene.shapes.size(); i++) {
    auto& shape = scene.shapes[i];
    auto  name  = element_name(scene.shape_names, i, "shape");
    auto  kinds = (int)!shape.triangles.empty() + (int)!shape.lines.empty() +
                 (int)!shape.curves.empty();
    if (kinds > 1) {
      error = name + ": a shape holds only one of triangles, lines or curves";
      return false;
    }
    auto nverts = num_vertices(shape);
    auto check_size = [&](size_t size, const char* what) {
      if (size != 0 && size != (size_t)nverts) {
        error = name + ": " + what + " has " + std::to_string(size) +
                " values for " + std::to_string(nverts) + " vertices";
        return false;
      }
      return true;
    };
    if (!check_size(shape.normals.size(), "normals")) return false;
    if (!check_size(shape.texcoords.size(), "texcoords")) return false;
    if (!check_size(shape.radius.size(), "radius")) return false;
    if (!check_size(shape.colors.size(), "colors")) return false;
    for (auto v = 0; v < (int)shape.colors.size(); v++) {
      auto& c = shape.colors[v];
      if (!(isfinite(c) && min_component(c) >= 0 && max_component(c) <= 1)) {
        error = name + ": vertex " + std::to_string(v) + ": color is not in [0, 1]";
        return false;
      }
    }
    if (!check_elements(shape.triangles, nverts, name, "triangle", error)) return false;
    if (!check_elements(shape.lines, nverts, name, "line", error)) return false;
    if (!check_elements(shape.curves, nverts, name, "curve", error)) return false;
    for (auto c = 0; c < (int)shape.fiber_curves.size(); c++) {
      auto first = shape.fiber_curves[c];
      if (first < 0 || first > nverts - 4) {
        error = name + ": curve " + std::to_string(c) + " references vertex " +
                std::to_string(first < 0 ? first : first + 3) + " of " + std::to_string(nverts);
        return false;
      }
      // The computed first vertex (fiber_strand_segments) must be the stored one.
      auto n = shape.fiber_strand_segments;
      if (n > 0 && first != 3 * c + c / n) {
        error = name + ": curve " + std::to_string(c) + " starts at vertex " +
                std::to_string(first) + ", not where strands of " + std::to_string(n) +
                " segments put it";
        return false;
      }
    }
    if (!check_shape_range(shape, name, error)) return false;
  }
  for (auto i = 0; i < (int)scene.materials.size(); i++) {
    auto& material = scene.materials[i];
    for (auto tex : {material.emission_tex, material.color_tex}) {
      if (tex < -1 || tex >= num_textures) {
        error = element_name(scene.material_names, i, "material") +
                ": texture reference " + std::to_string(tex) + " out of range";
        return false;
      }
    }
    auto hair_error = std::string{};
    if (material.type == material_type::hair && !check_hair_material(material.hair, hair_error)) {
      error = element_name(scene.material_names, i, "material") + ": " + hair_error;
      return false;
    }
  }
  for (auto i = 0; i < (int)scene.environments.size(); i++) {
    if (!check_frame(scene.environments[i].frame,
            element_name(scene.environment_names, i, "environment"), error))
      return false;
    auto tex = scene.environments[i].emission_tex;
    if (tex < -1 || tex >= num_textures) {
      error = element_name(scene.environment_names, i, "environment") +
              ": texture reference " + std::to_string(tex) + " out of range";
      return false;
    }
  }
  // Shape bounds once, for instances that share shapes.
  auto shape_bounds = std::vector<bbox3f>{};
  if (!scene.instances.empty())
    for (auto& shape : scene.shapes) shape_bounds.push_back(compute_bounds(shape));
  for (auto i = 0; i < (int)scene.instances.size(); i++) {
    auto& instance = scene.instances[i];
    auto  name     = element_name(scene.instance_names, i, "instance");
    if (!check_frame(instance.frame, name, error)) return false;
    if (instance.shape < 0 || instance.shape >= (int)scene.shapes.size()) {
      error = name + ": shape reference " + std::to_string(instance.shape) + " out of range";
      return false;
    }
    // The placed shape must stay in range too (a large scale or offset).
    auto& bounds = shape_bounds[instance.shape];
    for (auto c = 0; c < 8 && !empty(bounds); c++) {
      auto corner = transform_point(instance.frame,
          {(c & 1) ? bounds.max.x : bounds.min.x, (c & 2) ? bounds.max.y : bounds.min.y,
              (c & 4) ? bounds.max.z : bounds.min.z});
      if (!in_scene_range(corner)) {
        error = name + ": its frame places " +
                element_name(scene.shape_names, instance.shape, "shape") + " at " +
                format_number(largest_component(corner)) + ", " + outside_range();
        return false;
      }
    }
    if (instance.material < 0 || instance.material >= (int)scene.materials.size()) {
      error = name + ": material reference " + std::to_string(instance.material) +
              " out of range";
      return false;
    }
    auto& shape    = scene.shapes[instance.shape];
    auto& material = scene.materials[instance.material];
    if (material.type == material_type::hair && !shape.triangles.empty()) {
      error = name + ": hair " +
              element_name(scene.material_names, instance.material, "material") +
              " on triangle " + element_name(scene.shape_names, instance.shape, "shape") +
              " (hair needs lines or curves)";
      return false;
    }
    if (is_fiber(shape) && shape.radius.empty() && shape.fiber_vertices.empty()) {
      error = name + ": fiber " + element_name(scene.shape_names, instance.shape, "shape") +
              " has no radius";
      return false;
    }
  }
  return true;
}

// A converted scene is validated like a json one (what the directives cannot
// see alone, e.g. a Scale 0 0 0 instance); on error it is left empty.
bool validate_loaded_scene(
    scene_data& scene, const std::string& filename, std::string& error) {
  if (validate_scene(scene, error)) return true;
  error = filename + ": " + error;
  scene = {};
  return false;
}

void add_missing_camera(scene_data& scene) {
  if (!scene.cameras.empty()) return;
  auto bounds = compute_bounds(scene);
  if (empty(bounds)) bounds = {{-1, -1, -1}, {1, 1, 1}};
  auto camera   = camera_data{};
  camera.aspect = 1;
  // Frame the bounding sphere with the camera's field of view.
  auto radius   = length(size(bounds)) / 2;
  auto fov      = 2 * std::atan(camera.film / (2 * camera.lens));
  auto distance = radius / std::sin(fov / 2);
  auto target   = center(bounds);
  camera.frame  = lookat_frame(target + vec3f{0, 0, distance}, target, {0, 1, 0});
  camera.focus  = distance;
  scene.cameras.push_back(camera);
  scene.camera_names.push_back("default");
}

}  // namespace yocto

// -----------------------------------------------------------------------------
// HIT GEOMETRY
// -----------------------------------------------------------------------------
namespace yocto {

surface_point eval_surface_point(const scene_data& scene, const instance_data& instance,
    int element, const vec2f& uv) {
  auto& shape    = scene.shapes[instance.shape];
  auto  triangle = shape.triangles[element];
  // Embree's barycentrics: p = (1 - u - v) p0 + u p1 + v p2.
  auto w0 = 1 - uv.x - uv.y, w1 = uv.x, w2 = uv.y;
  auto& p = shape.positions;
  auto point     = surface_point{};
  point.position = transform_point(instance.frame,
      w0 * p[triangle.x] + w1 * p[triangle.y] + w2 * p[triangle.z]);
  point.gnormal = transform_normal(instance.frame,
      cross(p[triangle.y] - p[triangle.x], p[triangle.z] - p[triangle.x]));
  point.normal = point.gnormal;
  if (!shape.normals.empty()) {
    auto& n = shape.normals;
    auto  interpolated = w0 * n[triangle.x] + w1 * n[triangle.y] + w2 * n[triangle.z];
    if (length(interpolated) > 0)
      point.normal = transform_normal(instance.frame, interpolated);
  }
  if (!shape.texcoords.empty()) {
    auto& t        = shape.texcoords;
    point.texcoord = w0 * t[triangle.x] + w1 * t[triangle.y] + w2 * t[triangle.z];
  }
  if (!isfinite(point.gnormal)) point.gnormal = {0, 0, 1};
  if (!isfinite(point.normal)) point.normal = point.gnormal;
  return point;
}

fiber_point eval_fiber_point(const scene_data& scene, const instance_data& instance,
    int element, float u, const ray3f& ray, float distance) {
  auto& shape = scene.shapes[instance.shape];
  auto  p     = [&](int i) { return vertex_position(shape, i); };
  auto  r     = [&](int i) { return vertex_radius(shape, i); };
  auto  axis = vec3f{0, 0, 0}, tangent = vec3f{1, 0, 0};
  auto  radius = 0.0f;
  if (!shape.lines.empty()) {
    auto line = shape.lines[element];
    axis      = p(line.x) * (1 - u) + p(line.y) * u;
    tangent   = p(line.y) - p(line.x);
    radius    = r(line.x) * (1 - u) + r(line.y) * u;
  } else {
    auto curve = curve_vertices(shape, element);
    auto p0 = p(curve.x), p1 = p(curve.y), p2 = p(curve.z), p3 = p(curve.w);
    axis    = eval_bezier(p0, p1, p2, p3, u);
    tangent = eval_bezier_derivative(p0, p1, p2, p3, u);
    radius  = eval_bezier(r(curve.x), r(curve.y), r(curve.z), r(curve.w), u);
    // A Bezier whose end control points coincide has no derivative at the end.
    if (length(tangent) == 0) tangent = p3 - p0;
  }
  auto point     = fiber_point{};
  point.position = ray.o + ray.d * distance;
  point.axis     = transform_point(instance.frame, axis);
  point.tangent  = safe_normalize(transform_vector(instance.frame, tangent));
  // The scale's cube root is skipped for the common identity frame.
  point.radius   = instance.frame == identity3x4f ? radius
                                                  : radius * frame_scale(instance.frame);
  if (point.tangent == vec3f{0, 0, 0}) point.tangent = {1, 0, 0};

  // z: the direction back to the ray origin, made orthogonal to the tangent.
  auto x = point.tangent;
  auto z = -ray.d - dot(-ray.d, x) * x;
  if (length(z) < 1e-6f) {
    // The ray runs along the fiber: any normal will do, and h is 0.
    auto basis  = basis_fromz(x);  // columns: two normals, then x
    point.frame = {basis[2], basis[0], basis[1], point.position};
    point.h     = 0;
  } else {
    z           = normalize(z);
    auto y      = cross(z, x);
    point.frame = {x, y, z, point.position};
    // The ray moves only within the x-z plane, so every point on it has the
    // same y offset from the axis: the signed ray-axis distance.
    auto offset = dot(ray.o - point.axis, y);
    point.h     = point.radius > 0 ? std::clamp(offset / point.radius, -1.0f, 1.0f) : 0.0f;
  }
  point.normal = point.frame.z * safe_sqrt(1 - point.h * point.h) + point.frame.y * point.h;
  return point;
}

vec2f strand_random(const vec3f& root) {
  // SplitMix64's finaliser over the bits, one coordinate at a time.
  auto mix = [](uint64_t x) {
    x += 0x9e3779b97f4a7c15ULL;
    x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ULL;
    x = (x ^ (x >> 27)) * 0x94d049bb133111ebULL;
    return x ^ (x >> 31);
  };
  auto hash = (uint64_t)0x73747261ULL;  // "stra"
  for (auto c = 0; c < 3; c++) {
    auto value = root[c] == 0 ? 0.0f : root[c];  // -0 and 0 alike
    auto bits  = (uint32_t)0;
    std::memcpy(&bits, &value, sizeof(bits));
    hash = mix(hash ^ bits);
  }
  // 24 bits each: floats in [0, 1) that never round to 1.
  return {(float)(hash >> 40) * 0x1p-24f, (float)((hash >> 8) & 0xffffff) * 0x1p-24f};
}

fiber_strands make_fiber_strands(const shape_data& shape) {
  auto strands  = fiber_strands{};
  auto count    = shape.lines.empty() ? num_curves(shape) : (int)shape.lines.size();
  auto start_of = [&](int i) { return segment_ends(shape, i).x; };
  auto end_of   = [&](int i) { return segment_ends(shape, i).y; };
  // Segments by the position they start at (bits: exact matches only).
  auto key = [&](int vertex) {
    auto  p = vertex_position(shape, vertex);
    auto  x = vec3f{p.x == 0 ? 0.0f : p.x, p.y == 0 ? 0.0f : p.y, p.z == 0 ? 0.0f : p.z};
    auto  bits = std::array<uint32_t, 3>{};
    std::memcpy(bits.data(), &x[0], sizeof(bits));
    return bits;
  };
  struct key_hash {
    size_t operator()(const std::array<uint32_t, 3>& k) const {
      return ((size_t)k[0] * 0x9e3779b1u) ^ ((size_t)k[1] * 0x85ebca6bu) ^ k[2];
    }
  };
  auto starting = std::unordered_map<std::array<uint32_t, 3>, std::vector<int>, key_hash>{};
  starting.reserve(count);
  for (auto i = 0; i < count; i++) starting[key(start_of(i))].push_back(i);
  // Each segment continues the first segment (in file order) that ends where
  // it starts and is not continued yet: the same chains whatever the order
  // of the strands in the file, unless strands touch.
  auto next = std::vector<int>(count, -1), previous = std::vector<int>(count, -1);
  for (auto i = 0; i < count; i++) {
    auto found = starting.find(key(end_of(i)));
    if (found == starting.end()) continue;
    for (auto j : found->second) {
      if (j == i || previous[j] >= 0) continue;
      next[i] = j, previous[j] = i;
      break;
    }
  }
  strands.strand.assign(count, -1);
  strands.u.assign(count, {0, 0});
  auto walk = [&](int root) {
    auto id    = (int)strands.starts.size();
    auto first = (int)strands.segments.size();
    strands.starts.push_back(first);
    for (auto i = root; i >= 0 && strands.strand[i] < 0; i = next[i]) {
      strands.strand[i] = id;
      strands.segments.push_back(i);
    }
    // Place along the strand by the chords of its segments.
    auto total = 0.0f;
    for (auto k = first; k < (int)strands.segments.size(); k++) {
      auto i = strands.segments[k];
      total += length(vertex_position(shape, end_of(i)) - vertex_position(shape, start_of(i)));
    }
    auto run = 0.0f, n = (float)(strands.segments.size() - first);
    for (auto k = first; k < (int)strands.segments.size(); k++) {
      auto i      = strands.segments[k];
      auto length_i = length(
          vertex_position(shape, end_of(i)) - vertex_position(shape, start_of(i)));
      strands.u[i] = total > 0 ? vec2f{run / total, (run + length_i) / total}
                               : vec2f{(k - first) / n, (k - first + 1) / n};
      run += length_i;
    }
    strands.random.push_back(strand_random(vertex_position(shape, start_of(root))));
  };
  for (auto i = 0; i < count; i++)
    if (previous[i] < 0) walk(i);
  for (auto i = 0; i < count; i++)
    if (strands.strand[i] < 0) walk(i);  // closed loops
  strands.starts.push_back((int)strands.segments.size());
  return strands;
}

ray3f spawn_fiber_ray(const vec3f& axis, const vec3f& tangent, float radius,
    const vec3f& side, const vec3f& direction) {
  auto away = direction - dot(direction, tangent) * tangent;
  away      = length(away) > 1e-6f ? normalize(away) : side;
  return {axis + away * (radius * 1.01f), direction, radius * 0.01f + ray_eps * 0.1f, flt_max};
}

}  // namespace yocto

// -----------------------------------------------------------------------------
// PROCEDURAL SHAPES
// -----------------------------------------------------------------------------
namespace yocto {

shape_data make_sphere_shape(int steps, float radius) {
  auto shape  = shape_data{};
  auto nu     = std::max(steps, 3), nv = std::max(steps / 2, 2);
  for (auto j = 0; j <= nv; j++) {
    for (auto i = 0; i <= nu; i++) {
      auto uv = vec2f{(float)i / nu, (float)j / nv};
      auto n  = equirect_to_direction(uv);
      shape.positions.push_back(n * radius);
      shape.normals.push_back(n);
      shape.texcoords.push_back(uv);
    }
  }
  for (auto j = 0; j < nv; j++) {
    for (auto i = 0; i < nu; i++) {
      auto v00 = j * (nu + 1) + i, v10 = v00 + 1, v01 = v00 + nu + 1, v11 = v01 + 1;
      // Counter-clockwise seen from outside, so geometric normals point out.
      if (j > 0) shape.triangles.push_back({v00, v10, v01});
      if (j < nv - 1) shape.triangles.push_back({v10, v11, v01});
    }
  }
  return shape;
}

void append_catmull_rom_strand(shape_data& shape, const std::vector<vec3f>& points,
    const std::vector<float>& radii, const std::vector<vec3f>& colors) {
  auto n = (int)std::min(points.size(), radii.size());
  if (n < 2) return;
  if ((int)colors.size() >= n) {
    // Control points' colours as their radii: thirds between the points'.
    shape.colors.push_back(colors[0]);
    for (auto i = 0; i < n - 1; i++) {
      shape.colors.push_back((2.0f * colors[i] + colors[i + 1]) / 3.0f);
      shape.colors.push_back((colors[i] + 2.0f * colors[i + 1]) / 3.0f);
      shape.colors.push_back(colors[i + 1]);
    }
  }
  // Tangents m_i = (p_{i+1} - p_{i-1}) / 2; the chord at the ends.
  auto tangent = [&](int i) {
    if (i == 0) return points[1] - points[0];
    if (i == n - 1) return points[n - 1] - points[n - 2];
    return (points[i + 1] - points[i - 1]) / 2.0f;
  };
  auto first = (int)shape.positions.size();
  shape.positions.push_back(points[0]);
  shape.radius.push_back(radii[0]);
  for (auto i = 0; i < n - 1; i++) {
    // Hermite to Bezier: inner control points at a third of the tangents.
    shape.positions.push_back(points[i] + tangent(i) / 3.0f);
    shape.positions.push_back(points[i + 1] - tangent(i + 1) / 3.0f);
    shape.positions.push_back(points[i + 1]);
    shape.radius.push_back((2 * radii[i] + radii[i + 1]) / 3);
    shape.radius.push_back((radii[i] + 2 * radii[i + 1]) / 3);
    shape.radius.push_back(radii[i + 1]);
    shape.curves.push_back({first, first + 1, first + 2, first + 3});
    first += 3;
  }
}

shape_data make_quad_shape(const vec2f& size) {
  auto shape      = shape_data{};
  auto h          = size / 2.0f;
  shape.positions = {{-h.x, -h.y, 0}, {h.x, -h.y, 0}, {h.x, h.y, 0}, {-h.x, h.y, 0}};
  shape.normals   = {{0, 0, 1}, {0, 0, 1}, {0, 0, 1}, {0, 0, 1}};
  shape.texcoords = {{0, 0}, {1, 0}, {1, 1}, {0, 1}};
  shape.triangles = {{0, 1, 2}, {0, 2, 3}};
  return shape;
}

}  // namespace yocto

// -----------------------------------------------------------------------------
// CURVES TO LINES
// -----------------------------------------------------------------------------
namespace yocto {

shape_data curves_to_lines(const shape_data& curves, int segments) {
  segments        = std::max(segments, 1);
  auto lines      = shape_data{};
  auto has_radius = curves.radius.size() == curves.positions.size();
  auto has_colors = curves.colors.size() == curves.positions.size();
  auto num_vertices = (int)curves.positions.size();
  // Line vertex of each curve end point, so strands share their joints.
  auto end_vertex = std::vector<int>(curves.positions.size(), -1);
  auto emit       = [&](const vec4i& c, float u) {
    auto& p = curves.positions;
    lines.positions.push_back(eval_bezier(p[c.x], p[c.y], p[c.z], p[c.w], u));
    if (has_radius) {
      auto& r = curves.radius;
      lines.radius.push_back(eval_bezier(r[c.x], r[c.y], r[c.z], r[c.w], u));
    }
    if (has_colors) {
      auto& k = curves.colors;
      lines.colors.push_back(eval_bezier(k[c.x], k[c.y], k[c.z], k[c.w], u));
    }
    return (int)lines.positions.size() - 1;
  };
  lines.positions.reserve(curves.curves.size() * segments + 1);
  lines.lines.reserve(curves.curves.size() * segments);
  for (auto& c : curves.curves) {
    if (glm::any(glm::lessThan(c, vec4i{0})) ||
        glm::any(glm::greaterThanEqual(c, vec4i{num_vertices})))
      continue;
    if (end_vertex[c.x] < 0) end_vertex[c.x] = emit(c, 0);
    auto previous = end_vertex[c.x];
    for (auto s = 1; s <= segments; s++) {
      auto next = -1;
      if (s < segments) {
        next = emit(c, (float)s / segments);
      } else {
        if (end_vertex[c.w] < 0) end_vertex[c.w] = emit(c, 1);
        next = end_vertex[c.w];
      }
      lines.lines.push_back({previous, next});
      previous = next;
    }
  }
  return lines;
}

}  // namespace yocto
