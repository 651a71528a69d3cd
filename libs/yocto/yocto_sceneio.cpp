//
// Implementation of Yocto/SceneIO: see yocto_sceneio.h.
//

#include "yocto_sceneio.h"

#include <sys/stat.h>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <iostream>
#include <new>
#include <nlohmann/json.hpp>
#include <string_view>
#include <unordered_map>
#include <unordered_set>

// -----------------------------------------------------------------------------
// JSON SCENES: LOADING
// -----------------------------------------------------------------------------
namespace yocto {

// Ordered so that elements keyed by name (4.0 layout) keep the file's order.
using json = nlohmann::ordered_json;

// What a material element said, kept until instances tell which materials
// dress fibers: that decides the type of a material without one.
struct json_material_info {
  bool                     has_type      = false;
  bool                     has_hair_keys = false;
  bool                     has_color     = false;
  std::vector<std::string> keys          = {};
  std::vector<std::string> hair_given    = {};  // hair parameters given, by name
};

// Everything load_scene needs besides the scene: where files are, what the
// elements referred to, and the messages.
struct json_loader {
  std::string                     filename       = "";
  std::string                     dirname        = "";
  double                          max_memory     = 0;  // the budget of the whole load
  std::string                     error          = "";
  std::vector<std::string>        warnings       = {};
  std::vector<std::string>        shape_uris     = {};
  std::vector<std::string>        shape_users    = {};  // who named it first
  std::vector<std::string>        texture_uris   = {};  // "" is textures/NAME.*
  std::vector<std::string>        texture_users  = {};
  std::vector<json_material_info> material_infos = {};
};

static bool json_fail(json_loader& loader, const std::string& message) {
  loader.error = loader.filename + ": " + message;
  return false;
}

static void json_warn(json_loader& loader, const std::string& message) {
  loader.warnings.push_back(loader.filename + ": " + message);
}

static std::string json_key(const std::string& element, const std::string& key) {
  return element + ": key \"" + key + "\"";
}

static std::string json_describe(const json& value) {
  if (value.is_array()) return "an array of " + std::to_string(value.size()) + " values";
  if (value.is_string()) return "the string \"" + value.get<std::string>() + "\"";
  if (value.is_boolean()) return value.get<bool>() ? "true" : "false";
  if (value.is_number()) return value.dump();
  return std::string("a ") + value.type_name();
}

static bool read_number(json_loader& loader, const json& value, const std::string& where,
    float& number, float min = flt_min, float max = flt_max, bool open_min = false) {
  if (!value.is_number())
    return json_fail(loader, where + ": expected a number, got " + json_describe(value));
  number = (float)value.get<double>();
  if (!std::isfinite(number))
    return json_fail(loader, where + ": " + value.dump() + " is not a finite float");
  if (number < min || number > max || (open_min && number == min)) {
    auto range = std::string{};
    if (max == flt_max) range = (open_min ? "> " : ">= ") + format_float(min);
    else range = "in [" + format_float(min) + ", " + format_float(max) + "]";
    return json_fail(loader, where + ": expected a number " + range + ", got " +
                                 format_float(number));
  }
  return true;
}

static bool read_numbers(json_loader& loader, const json& value, const std::string& where,
    float* numbers, int count, float min = flt_min, float max = flt_max) {
  if (!value.is_array() || value.size() != (size_t)count)
    return json_fail(loader, where + ": expected an array of " + std::to_string(count) +
                                 " numbers, got " + json_describe(value));
  for (auto i = 0; i < count; i++)
    if (!read_number(loader, value[i], where, numbers[i], min, max)) return false;
  return true;
}

static bool read_vec3(json_loader& loader, const json& value, const std::string& where,
    vec3f& v, float min = flt_min, float max = flt_max) {
  return read_numbers(loader, value, where, &v.x, 3, min, max);
}

// A frame is 12 numbers: the x, y and z axes, then the origin.
static bool read_frame(
    json_loader& loader, const json& value, const std::string& where, frame3f& frame) {
  float numbers[12];
  if (!read_numbers(loader, value, where, numbers, 12)) return false;
  frame = {{numbers[0], numbers[1], numbers[2]}, {numbers[3], numbers[4], numbers[5]},
      {numbers[6], numbers[7], numbers[8]}, {numbers[9], numbers[10], numbers[11]}};
  return true;
}

// A lookat is 9 numbers: from, to, up. Degenerate ones would make NaN axes.
static bool read_lookat(json_loader& loader, const json& value, const std::string& where,
    frame3f& frame, float& distance) {
  float numbers[9];
  if (!read_numbers(loader, value, where, numbers, 9)) return false;
  auto from = vec3f{numbers[0], numbers[1], numbers[2]};
  auto to   = vec3f{numbers[3], numbers[4], numbers[5]};
  auto up   = vec3f{numbers[6], numbers[7], numbers[8]};
  distance  = length(from - to);
  if (!(distance > 0)) return json_fail(loader, where + ": from and to coincide");
  if (!(length(cross(up, normalize(from - to))) > 1e-6f * length(up)))
    return json_fail(loader, where + ": up is zero or parallel to the view direction");
  frame = lookat_frame(from, to, up);
  return true;
}

static bool read_bool(
    json_loader& loader, const json& value, const std::string& where, bool& flag) {
  if (!value.is_boolean())
    return json_fail(loader, where + ": expected true or false, got " + json_describe(value));
  flag = value.get<bool>();
  return true;
}

static bool read_string(
    json_loader& loader, const json& value, const std::string& where, std::string& text) {
  if (!value.is_string())
    return json_fail(loader, where + ": expected a string, got " + json_describe(value));
  text = value.get<std::string>();
  return true;
}

static bool read_count(
    json_loader& loader, const json& value, const std::string& where, int& count) {
  if (!value.is_number_integer() || value.get<int64_t>() < 0 ||
      value.get<int64_t>() > std::numeric_limits<int>::max())
    return json_fail(loader, where + ": expected a non-negative integer, got " +
                                 json_describe(value));
  count = (int)value.get<int64_t>();
  return true;
}

enum struct json_reference { shape, texture, material };

// A reference is an index (4.2 layout) or a name (4.0 layout). A name with
// no element makes one for shapes and textures, whose files are then found
// by name (shapes/NAME.ply, textures/NAME.*), as Yocto 4.0 did.
static bool read_reference(json_loader& loader, scene_data& scene, const json& value,
    const std::string& where, const std::string& user, json_reference kind, int& index) {
  auto& names = kind == json_reference::shape     ? scene.shape_names
                : kind == json_reference::texture ? scene.texture_names
                                                  : scene.material_names;
  auto  what  = kind == json_reference::shape     ? std::string("shape")
                : kind == json_reference::texture ? std::string("texture")
                                                  : std::string("material");
  if (value.is_number_integer()) {
    auto number = value.get<int64_t>();
    if (number == -1 && kind == json_reference::texture) {
      index = -1;
      return true;
    }
    if (number < 0 || number >= (int64_t)names.size())
      return json_fail(loader, where + ": " + what + " reference " + value.dump() +
                                   " out of range (" + std::to_string(names.size()) +
                                   " " + what + "s)");
    index = (int)number;
    return true;
  }
  if (!value.is_string())
    return json_fail(loader, where + ": expected a " + what +
                                 " index or name, got " + json_describe(value));
  auto name  = value.get<std::string>();
  auto found = std::find(names.begin(), names.end(), name);
  if (found != names.end()) {
    index = (int)(found - names.begin());
    return true;
  }
  if (kind == json_reference::material)
    return json_fail(loader, where + ": unknown material \"" + name + "\"");
  index = (int)names.size();
  names.push_back(name);
  if (kind == json_reference::shape) {
    scene.shapes.emplace_back();
    loader.shape_uris.push_back("shapes/" + name + ".ply");
    loader.shape_users.push_back(user);
  } else {
    scene.textures.emplace_back();
    loader.texture_uris.push_back("");
    loader.texture_users.push_back(user);
  }
  return true;
}

// Calls parse(element, name, label) for each element of a group: an array of
// objects (4.2 layout) or an object keyed by name (4.0 layout).
template <typename Parse>
static bool parse_group(json_loader& loader, const json& group,
    const std::string& group_name, const std::string& kind, Parse&& parse) {
  if (group.is_array()) {
    for (size_t i = 0; i < group.size(); i++) {
      auto& element = group[i];
      auto  label   = kind + " " + std::to_string(i);
      if (!element.is_object())
        return json_fail(loader, label + ": expected an object, got " + json_describe(element));
      auto name = std::string{};
      if (element.contains("name") &&
          !read_string(loader, element["name"], json_key(label, "name"), name))
        return false;
      if (!name.empty()) label = kind + " \"" + name + "\"";
      if (!parse(element, name, label)) return false;
    }
    return true;
  }
  if (group.is_object()) {
    for (auto& [name, element] : group.items()) {
      auto label = kind + " \"" + name + "\"";
      if (!element.is_object())
        return json_fail(loader, label + ": expected an object, got " + json_describe(element));
      if (!parse(element, name, label)) return false;
    }
    return true;
  }
  return json_fail(loader, "group \"" + group_name +
                               "\": expected an array or an object, got " +
                               json_describe(group));
}

static void warn_unknown_key(
    json_loader& loader, const std::string& label, const std::string& key) {
  json_warn(loader, label + ": unknown key \"" + key + "\" ignored");
}

static bool parse_camera(json_loader& loader, const json& element,
    const std::string& label, camera_data& camera) {
  auto has_focus = false, has_frame = false, has_lookat = false;
  auto distance  = 0.0f;
  for (auto& [key, value] : element.items()) {
    auto where = json_key(label, key);
    auto ok    = true;
    if (key == "name") continue;
    else if (key == "lens") ok = read_number(loader, value, where, camera.lens, 0, flt_max, true);
    else if (key == "film") ok = read_number(loader, value, where, camera.film, 0, flt_max, true);
    else if (key == "aspect")
      ok = read_number(loader, value, where, camera.aspect, 0, flt_max, true);
    else if (key == "focus")
      ok = has_focus = read_number(loader, value, where, camera.focus, 0, flt_max, true);
    else if (key == "aperture") ok = read_number(loader, value, where, camera.aperture, 0);
    else if (key == "orthographic") ok = read_bool(loader, value, where, camera.orthographic);
    else if (key == "frame") ok = has_frame = read_frame(loader, value, where, camera.frame);
    else if (key == "lookat")
      ok = has_lookat = read_lookat(loader, value, where, camera.frame, distance);
    else warn_unknown_key(loader, label, key);
    if (!ok) return false;
  }
  if (has_frame && has_lookat)
    return json_fail(loader, label + ": has both \"frame\" and \"lookat\"");
  // As Yocto/GL: a camera placed by lookat focuses on its target.
  if (has_lookat && !has_focus) camera.focus = distance;
  return true;
}

static bool parse_environment(json_loader& loader, scene_data& scene,
    const json& element, const std::string& label, environment_data& environment) {
  for (auto& [key, value] : element.items()) {
    auto where = json_key(label, key);
    auto ok    = true;
    if (key == "name") continue;
    else if (key == "emission") ok = read_vec3(loader, value, where, environment.emission, 0);
    else if (key == "emission_tex")
      ok = read_reference(loader, scene, value, where, label, json_reference::texture,
          environment.emission_tex);
    else if (key == "frame") ok = read_frame(loader, value, where, environment.frame);
    else warn_unknown_key(loader, label, key);
    if (!ok) return false;
  }
  return true;
}

static bool parse_instance(json_loader& loader, scene_data& scene, const json& element,
    const std::string& label, instance_data& instance) {
  auto has_frame = false, has_lookat = false;
  auto distance  = 0.0f;
  for (auto& [key, value] : element.items()) {
    auto where = json_key(label, key);
    auto ok    = true;
    if (key == "name") continue;
    else if (key == "frame") ok = has_frame = read_frame(loader, value, where, instance.frame);
    else if (key == "lookat") {
      ok = has_lookat = read_lookat(loader, value, where, instance.frame, distance);
      // As Yocto/GL: an object placed by lookat points its +z at the target
      // (a camera points -z), so an area light's front faces what it lights.
      instance.frame.x = -instance.frame.x;
      instance.frame.z = -instance.frame.z;
    } else if (key == "shape")
      ok = read_reference(
          loader, scene, value, where, label, json_reference::shape, instance.shape);
    else if (key == "material")
      ok = read_reference(
          loader, scene, value, where, label, json_reference::material, instance.material);
    else warn_unknown_key(loader, label, key);
    if (!ok) return false;
  }
  if (has_frame && has_lookat)
    return json_fail(loader, label + ": has both \"frame\" and \"lookat\"");
  if (!element.contains("shape")) return json_fail(loader, label + ": no \"shape\" given");
  if (!element.contains("material"))
    return json_fail(loader, label + ": no \"material\" given");
  return true;
}

// Yocto/GL material types we do not model, mapped to the nearest we do.
static bool parse_material_type(json_loader& loader, const json& value,
    const std::string& where, material_type& type) {
  auto name = std::string{};
  if (!read_string(loader, value, where, name)) return false;
  for (auto t = 0; t < (int)material_type_names.size(); t++) {
    if (name == material_type_names[t]) {
      type = (material_type)t;
      return true;
    }
  }
  static const auto glossy_like = std::unordered_set<std::string>{
      "plastic", "metal", "metallic", "reflective", "gltfpbr", "coated"};
  static const auto matte_like = std::unordered_set<std::string>{"transparent",
      "refractive", "subsurface", "volumetric", "thinglass", "glass", "passthrough"};
  if (glossy_like.count(name) || matte_like.count(name)) {
    type = glossy_like.count(name) ? material_type::glossy : material_type::matte;
    json_warn(loader, where + ": material type \"" + name + "\" is not supported, using " +
                          material_type_names[(int)type]);
    return true;
  }
  return json_fail(loader, where + ": unknown material type \"" + name +
                               "\" (expected matte, glossy or hair)");
}

// A hair parameter's value, checked against its range in hair_parameters.
static bool read_hair_parameter(json_loader& loader, const json& value,
    const std::string& where, const hair_parameter& parameter, vec3f& result) {
  auto count = parameter.kind == hair_parameter_kind::number ? 1 : 3;
  if (count == 1 && !value.is_number())
    return json_fail(loader, where + ": expected a number, got " + json_describe(value));
  if (count == 3 && (!value.is_array() || value.size() != 3))
    return json_fail(loader, where + ": expected an array of 3 numbers, got " +
                                 json_describe(value));
  for (auto c = 0; c < count; c++) {
    auto& number = count == 1 ? value : value[c];
    if (!number.is_number())
      return json_fail(loader, where + ": expected a number, got " + json_describe(number));
    result[c] = (float)number.get<double>();
    if (!std::isfinite(result[c]))
      return json_fail(loader, where + ": " + number.dump() + " is not a finite float");
    if (!is_hair_parameter_valid(parameter, vec3f{result[c]}))
      return json_fail(loader, where + ": expected " + (count == 1 ? "a number " : "numbers ") +
                                   format_hair_parameter_range(parameter) + ", got " +
                                   format_float(result[c]));
  }
  if (count == 1) result = vec3f{result.x};
  return true;
}

static bool parse_material(json_loader& loader, scene_data& scene, const json& element,
    const std::string& label, material_data& material, json_material_info& info) {
  auto& hair = material.hair;
  for (auto& [key, value] : element.items()) {
    auto where = json_key(label, key);
    auto ok    = true;
    if (key == "name") continue;
    info.keys.push_back(key);
    // "color" is every type's: it goes to the hair in finish_material.
    auto parameter = key != "color" ? find_hair_parameter(key) : nullptr;
    info.has_hair_keys |= parameter != nullptr;
    if (parameter) {
      auto number = vec3f{0, 0, 0};
      ok = read_hair_parameter(loader, value, where, *parameter, number);
      if (ok) set_hair_parameter(hair, *parameter, number);
      info.hair_given.push_back(parameter->name);
    } else if (key == "type") {
      ok = info.has_type = parse_material_type(loader, value, where, material.type);
    } else if (key == "emission") {
      ok = read_vec3(loader, value, where, material.emission, 0);
    } else if (key == "color") {
      ok = info.has_color = read_vec3(loader, value, where, material.color, 0);
    } else if (key == "roughness") {
      ok = read_number(loader, value, where, material.roughness, 0, 1);
    } else if (key == "ior") {
      ok = read_number(loader, value, where, material.ior, 0, flt_max, true);
    } else if (key == "emission_tex") {
      ok = read_reference(
          loader, scene, value, where, label, json_reference::texture, material.emission_tex);
    } else if (key == "color_tex") {
      ok = read_reference(
          loader, scene, value, where, label, json_reference::texture, material.color_tex);
    } else {
      info.keys.pop_back();
      warn_unknown_key(loader, label, key);
    }
    if (!ok) return false;
  }
  return true;
}

// Once the type is known: hair takes the colour as its own, each type drops
// (with a warning) the keys it does not use, and the pigment defaults apply.
static bool finish_material(json_loader& loader, const std::string& label,
    material_data& material, const json_material_info& info) {
  auto used = [&](const std::string& key) {
    if (key == "type" || key == "emission" || key == "emission_tex" || key == "color")
      return true;
    switch (material.type) {
      case material_type::matte: return key == "color_tex";
      case material_type::glossy:
        return key == "color_tex" || key == "roughness" || key == "ior";
      case material_type::hair: return find_hair_parameter(key) != nullptr;
    }
    return false;
  };
  for (auto& key : info.keys) {
    if (!used(key))
      json_warn(loader, label + ": key \"" + key + "\" is not used by " +
                            material_type_names[(int)material.type] +
                            " materials, ignored");
  }
  auto defaults = material_data{};
  if (material.type == material_type::hair) {
    if (info.has_color) {
      auto& color = *find_hair_parameter("color");
      for (auto c = 0; c < 3; c++)
        if (!is_hair_parameter_valid(color, vec3f{material.color[c]}))
          return json_fail(loader, json_key(label, "color") + ": a hair colour must be " +
                                       format_hair_parameter_range(color) + ", got " +
                                       format_float(material.color[c]));
      set_hair_parameter(material.hair, color, material.color);
    }
    // pbrt's rule: one pigment given means the other is 0.
    auto given = [&](const std::string& name) {
      return std::find(info.hair_given.begin(), info.hair_given.end(), name) !=
             info.hair_given.end();
    };
    if (given("pheomelanin") && !given("eumelanin")) material.hair.eumelanin = 0;
    if (given("eumelanin") && !given("pheomelanin")) material.hair.pheomelanin = 0;
    material.color     = defaults.color;
    material.color_tex = defaults.color_tex;
    material.roughness = defaults.roughness;
    material.ior       = defaults.ior;
  } else {
    material.hair = defaults.hair;
    if (material.type == material_type::matte) {
      material.roughness = defaults.roughness;
      material.ior       = defaults.ior;
    }
  }
  return true;
}

static bool parse_asset(json_loader& loader, scene_data& scene, const json& asset) {
  if (!asset.is_object())
    return json_fail(loader, "group \"asset\": expected an object, got " + json_describe(asset));
  for (auto& [key, value] : asset.items()) {
    if (key == "copyright") {
      if (!read_string(loader, value, json_key("asset", key), scene.copyright)) return false;
    } else if (key != "version" && key != "generator") {
      warn_unknown_key(loader, "asset", key);
    }
  }
  return true;
}

static bool parse_settings(json_loader& loader, scene_data& scene, const json& settings) {
  if (!settings.is_object())
    return json_fail(loader, "group \"settings\": expected an object, got " +
                                 json_describe(settings));
  for (auto& [key, value] : settings.items()) {
    auto where = json_key("settings", key);
    auto ok    = true;
    if (key == "resolution") ok = read_count(loader, value, where, scene.settings.resolution);
    else if (key == "samples") ok = read_count(loader, value, where, scene.settings.samples);
    else if (key == "bounces") ok = read_count(loader, value, where, scene.settings.bounces);
    else warn_unknown_key(loader, "settings", key);
    if (!ok) return false;
  }
  return true;
}

// A file reference of a texture or shape element; 4.0 groups keyed by name
// may leave it out and use the default place.
static bool parse_file_element(json_loader& loader, const json& element,
    const std::string& label, bool uri_required, std::string& uri) {
  for (auto& [key, value] : element.items()) {
    if (key == "name") continue;
    if (key == "uri") {
      if (!read_string(loader, value, json_key(label, key), uri)) return false;
    } else {
      warn_unknown_key(loader, label, key);
    }
  }
  if (uri_required && uri.empty()) return json_fail(loader, label + ": no \"uri\" given");
  return true;
}

// Finds textures/NAME.EXT for a texture that a 4.0 scene names without a file.
static bool find_texture_file(json_loader& loader, const std::string& name,
    const std::string& label, std::string& uri) {
  static const char* extensions[] = {".hdr", ".exr", ".png", ".jpg", ".jpeg", ".pfm"};
  for (auto extension : extensions) {
    auto candidate = "textures/" + name + extension;
    auto ec        = std::error_code{};
    if (std::filesystem::is_regular_file(path_join(loader.dirname, candidate), ec)) {
      uri = candidate;
      return true;
    }
  }
  return json_fail(loader, label + ": no image file textures/" + name +
                               ".{hdr,exr,png,jpg,jpeg,pfm} in " +
                               (loader.dirname.empty() ? "." : loader.dirname));
}

// The type of a material that names none: hair keys make it hair, and so
// does dressing fibers alone; anything else is matte.
static material_type infer_material_type(const scene_data& scene, int material,
    const json_material_info& info) {
  if (info.has_hair_keys) return material_type::hair;
  auto used = false, fibers_only = true;
  for (auto& instance : scene.instances) {
    if (instance.material != material) continue;
    used = true;
    fibers_only &= is_fiber(scene.shapes[instance.shape]);
  }
  return used && fibers_only ? material_type::hair : material_type::matte;
}

// Elements that name the same file (the path resolved) merge into the first
// of them: returns each element's new index, and keeps one entry per file in
// `elements` and in the parallel arrays, the first of which holds the paths.
template <typename T>
static std::vector<int> merge_same_files(
    std::vector<T>& elements, const std::vector<std::vector<std::string>*>& arrays) {
  auto& paths = *arrays.front();
  auto  first = std::unordered_map<std::string, int>{};
  auto  index = std::vector<int>(elements.size());
  auto  kept  = 0;
  for (auto i = 0; i < (int)elements.size(); i++) {
    auto ec  = std::error_code{};
    auto key = std::filesystem::weakly_canonical(paths[i], ec).string();
    if (ec) key = paths[i];
    auto [found, added] = first.try_emplace(key, kept);
    index[i]            = found->second;
    if (!added) continue;
    if (kept != i) {
      elements[kept] = std::move(elements[i]);
      for (auto array : arrays) (*array)[kept] = std::move((*array)[i]);
    }
    kept++;
  }
  elements.resize(kept);
  for (auto array : arrays) array->resize(kept);
  return index;
}

// Line and column of a byte offset, for json syntax errors.
static std::string text_position(const std::string& text, size_t byte) {
  auto line = 1, column = 1;
  for (size_t i = 0; i < byte && i < text.size(); i++) {
    if (text[i] == '\n') line++, column = 1;
    else column++;
  }
  return "line " + std::to_string(line) + ", column " + std::to_string(column);
}

// nlohmann's SAX events, ignored but for the error: its position is what
// the DOM parser's exception lacks for a number out of double range.
struct json_error_locator {
  size_t      position = 0;
  std::string token    = "";
  bool null() { return true; }
  bool boolean(bool) { return true; }
  bool number_integer(json::number_integer_t) { return true; }
  bool number_unsigned(json::number_unsigned_t) { return true; }
  bool number_float(json::number_float_t, const std::string&) { return true; }
  bool string(std::string&) { return true; }
  bool binary(json::binary_t&) { return true; }
  bool start_object(size_t) { return true; }
  bool key(std::string&) { return true; }
  bool end_object() { return true; }
  bool start_array(size_t) { return true; }
  bool end_array() { return true; }
  bool parse_error(size_t byte, const std::string& last_token, const json::exception&) {
    position = byte;
    token    = last_token;
    return false;
  }
};

static bool load_scene_json(json_loader& loader, scene_data& scene) {
  auto text = std::string{};
  if (!load_text(loader.filename, text, loader.error, loader.max_memory)) return false;
  auto js = json{};
  // nlohmann reports the byte just past the error.
  auto place = [&](size_t byte) { return text_position(text, byte > 0 ? byte - 1 : 0); };
  try {
    js = json::parse(text);
  } catch (const json::parse_error& exception) {
    // Its message without its own prefix and position.
    auto message = std::string(exception.what());
    auto column  = message.find(", column ");
    auto colon   = message.find(": ", column == std::string::npos ? 0 : column);
    if (colon != std::string::npos) message = message.substr(colon + 2);
    return json_fail(loader, place(exception.byte) + ": malformed json: " + message);
  } catch (const json::exception& exception) {
    // A number beyond double range (1e999), located by parsing again: the
    // place is where the number starts.
    auto locator = json_error_locator{};
    json::sax_parse(text, &locator);
    if (exception.id != 406)
      return json_fail(loader, place(locator.position) + ": " + exception.what());
    auto start = locator.position - std::min(locator.position, locator.token.size());
    return json_fail(loader, text_position(text, start) + ": number " + locator.token +
                                 " is out of range");
  }
  if (!js.is_object())
    return json_fail(loader, "expected a json object at the top, got " + json_describe(js));

  // Groups go in dependency order, whatever their order in the file.
  static const auto known_groups = std::unordered_set<std::string>{"asset", "settings",
      "textures", "shapes", "materials", "cameras", "environments", "distant_lights",
      "instances", "objects"};
  for (auto& [key, value] : js.items())
    if (!known_groups.count(key)) json_warn(loader, "unknown group \"" + key + "\" ignored");
  auto group = [&](const char* name) -> const json* {
    auto found = js.find(name);
    return found == js.end() ? nullptr : &*found;
  };

  if (auto asset = group("asset"); asset && !parse_asset(loader, scene, *asset)) return false;
  if (auto settings = group("settings");
      settings && !parse_settings(loader, scene, *settings))
    return false;
  if (auto textures = group("textures")) {
    auto keyed = textures->is_object();
    auto ok    = parse_group(loader, *textures, "textures", "texture",
           [&](const json& element, const std::string& name, const std::string& label) {
          auto uri = std::string{};
          if (!parse_file_element(loader, element, label, !keyed, uri)) return false;
          scene.textures.emplace_back();
          scene.texture_names.push_back(name);
          loader.texture_uris.push_back(uri);
          loader.texture_users.push_back("");
          return true;
        });
    if (!ok) return false;
  }
  if (auto shapes = group("shapes")) {
    auto keyed = shapes->is_object();
    auto ok    = parse_group(loader, *shapes, "shapes", "shape",
           [&](const json& element, const std::string& name, const std::string& label) {
          auto uri = std::string{};
          if (!parse_file_element(loader, element, label, !keyed, uri)) return false;
          if (uri.empty()) uri = "shapes/" + name + ".ply";
          scene.shapes.emplace_back();
          scene.shape_names.push_back(name);
          loader.shape_uris.push_back(uri);
          loader.shape_users.push_back("");
          return true;
        });
    if (!ok) return false;
  }
  if (auto materials = group("materials")) {
    auto ok = parse_group(loader, *materials, "materials", "material",
        [&](const json& element, const std::string& name, const std::string& label) {
          auto material = material_data{};
          auto info     = json_material_info{};
          if (!parse_material(loader, scene, element, label, material, info)) return false;
          scene.materials.push_back(material);
          scene.material_names.push_back(name);
          loader.material_infos.push_back(info);
          return true;
        });
    if (!ok) return false;
  }
  if (auto cameras = group("cameras")) {
    auto ok = parse_group(loader, *cameras, "cameras", "camera",
        [&](const json& element, const std::string& name, const std::string& label) {
          auto camera = camera_data{};
          if (!parse_camera(loader, element, label, camera)) return false;
          scene.cameras.push_back(camera);
          scene.camera_names.push_back(name);
          return true;
        });
    if (!ok) return false;
  }
  if (auto environments = group("environments")) {
    auto ok = parse_group(loader, *environments, "environments", "environment",
        [&](const json& element, const std::string& name, const std::string& label) {
          auto environment = environment_data{};
          if (!parse_environment(loader, scene, element, label, environment)) return false;
          scene.environments.push_back(environment);
          scene.environment_names.push_back(name);
          return true;
        });
    if (!ok) return false;
  }
  if (auto lights = group("distant_lights")) {
    auto ok = parse_group(loader, *lights, "distant_lights", "distant light",
        [&](const json& element, const std::string&, const std::string& label) {
          auto light = distant_light_data{};
          for (auto& [key, value] : element.items()) {
            auto where = json_key(label, key);
            auto ok    = true;
            if (key == "name") continue;
            else if (key == "direction") ok = read_vec3(loader, value, where, light.direction);
            else if (key == "emission") ok = read_vec3(loader, value, where, light.emission, 0);
            else warn_unknown_key(loader, label, key);
            if (!ok) return false;
          }
          if (!(length(light.direction) > 0))
            return json_fail(loader, json_key(label, "direction") + ": is zero");
          scene.distant_lights.push_back(light);
          return true;
        });
    if (!ok) return false;
  }
  for (auto group_name : {"instances", "objects"}) {
    auto instances = group(group_name);
    if (!instances) continue;
    auto ok = parse_group(loader, *instances, group_name, "instance",
        [&](const json& element, const std::string& name, const std::string& label) {
          auto instance = instance_data{};
          if (!parse_instance(loader, scene, element, label, instance)) return false;
          scene.instances.push_back(instance);
          scene.instance_names.push_back(name);
          return true;
        });
    if (!ok) return false;
  }

  // Files, relative to the json's directory.
  auto element_label = [](const char* kind, const std::string& name,
                           const std::string& user, int index) {
    auto label = name.empty() ? std::string(kind) + " " + std::to_string(index)
                              : std::string(kind) + " \"" + name + "\"";
    return user.empty() ? label : label + " (used by " + user + ")";
  };
  auto shape_paths = std::vector<std::string>{}, shape_labels = std::vector<std::string>{};
  for (auto i = 0; i < (int)scene.shapes.size(); i++) {
    shape_paths.push_back(path_join(loader.dirname, loader.shape_uris[i]));
    shape_labels.push_back(element_label("shape", scene.shape_names[i], loader.shape_users[i], i));
  }
  auto texture_paths = std::vector<std::string>{}, texture_labels = std::vector<std::string>{};
  for (auto i = 0; i < (int)scene.textures.size(); i++) {
    auto label = element_label("texture", scene.texture_names[i], loader.texture_users[i], i);
    auto& uri  = loader.texture_uris[i];
    if (uri.empty() && !find_texture_file(loader, scene.texture_names[i], label, uri))
      return false;
    texture_paths.push_back(path_join(loader.dirname, uri));
    texture_labels.push_back(label);
  }
  // Each file is loaded once: elements naming the same file share one shape
  // or texture (a PLY named by 20000 shapes is one shape, and one BVH that
  // Embree instances), so memory is that of the distinct files.
  auto shape_index = merge_same_files(
      scene.shapes, {&shape_paths, &scene.shape_names, &shape_labels});
  for (auto& instance : scene.instances) instance.shape = shape_index[instance.shape];
  auto texture_index = merge_same_files(
      scene.textures, {&texture_paths, &scene.texture_names, &texture_labels});
  auto remap_texture = [&](int& texture) {
    if (texture >= 0) texture = texture_index[texture];
  };
  for (auto& material : scene.materials) {
    remap_texture(material.color_tex);
    remap_texture(material.emission_tex);
  }
  for (auto& environment : scene.environments) remap_texture(environment.emission_tex);

  // Files are checked one by one as they load; their sum is checked too.
  auto total = 0.0;
  for (auto i = 0; i < (int)scene.shapes.size(); i++) {
    auto error = std::string{};
    if (!load_shape(shape_paths[i], scene.shapes[i], error, loader.max_memory))
      return json_fail(loader, shape_labels[i] + ": " + error);
    total += shape_memory(scene.shapes[i]);
    if (!check_load_memory(loader.filename,
            "loading the shapes up to " + shape_labels[i], total, loader.max_memory,
            loader.error))
      return false;
  }
  for (auto i = 0; i < (int)scene.textures.size(); i++) {
    auto error = std::string{};
    if (!load_image(texture_paths[i], scene.textures[i], error, loader.max_memory))
      return json_fail(loader, texture_labels[i] + ": " + error);
    total += scene.textures[i].pixels.size() * sizeof(vec3f);
    if (!check_load_memory(loader.filename,
            "loading the shapes and textures up to " + texture_labels[i], total,
            loader.max_memory, loader.error))
      return false;
  }

  for (auto i = 0; i < (int)scene.materials.size(); i++) {
    auto& material = scene.materials[i];
    auto& info     = loader.material_infos[i];
    if (!info.has_type) material.type = infer_material_type(scene, i, info);
    auto label = element_label("material", scene.material_names[i], "", i);
    if (!finish_material(loader, label, material, info)) return false;
  }

  auto error = std::string{};
  if (!validate_scene(scene, error)) return json_fail(loader, error);
  return true;
}

bool load_scene(const std::string& filename, scene_data& scene, std::string& error,
    std::vector<std::string>* warnings, double max_memory) try {
  scene       = {};
  auto loader = json_loader{filename, path_dirname(filename), max_memory};
  auto ok     = load_scene_json(loader, scene);
  if (warnings) {
    warnings->insert(warnings->end(), loader.warnings.begin(), loader.warnings.end());
  } else {
    for (auto& warning : loader.warnings) std::cerr << "warning: " << warning << "\n";
  }
  if (!ok) {
    error = loader.error;
    scene = {};
  }
  return ok;
} catch (const std::bad_alloc&) {
  // Past the budget's checks, the system (or ulimit -v) gave less.
  error = allocation_error(filename, "the scene");
  return false;
}

}  // namespace yocto

// -----------------------------------------------------------------------------
// JSON SCENES: SAVING
// -----------------------------------------------------------------------------
namespace yocto {

// The double whose shortest decimal form is the float's shortest form, so
// that files read "0.1", not "0.10000000149011612", and still load back to
// the same float.
static double json_number(float value) {
  auto text   = format_float(value);
  auto number = 0.0;
  std::from_chars(text.data(), text.data() + text.size(), number);
  return (float)number == value ? number : (double)value;
}

static json json_array(const float* values, int count) {
  auto array = json::array();
  for (auto i = 0; i < count; i++) array.push_back(json_number(values[i]));
  return array;
}
static json json_vec3(const vec3f& v) { return json_array(&v.x, 3); }
static json json_frame(const frame3f& frame) {
  float values[12] = {frame.x.x, frame.x.y, frame.x.z, frame.y.x, frame.y.y, frame.y.z,
      frame.z.x, frame.z.y, frame.z.z, frame.o.x, frame.o.y, frame.o.z};
  return json_array(values, 12);
}

static std::string element_name(const std::vector<std::string>& names, size_t index) {
  return index < names.size() ? names[index] : std::string{};
}

// Unique file names under a directory, from element names made safe.
static std::vector<std::string> make_file_names(const std::vector<std::string>& names,
    size_t count, const std::string& kind, const std::string& extension) {
  auto files = std::vector<std::string>{};
  auto used  = std::unordered_set<std::string>{};
  for (size_t i = 0; i < count; i++) {
    auto stem = element_name(names, i);
    for (auto& c : stem)
      if (!std::isalnum((unsigned char)c) && c != '-' && c != '_' && c != '.') c = '_';
    if (stem.empty() || stem[0] == '.') stem = kind + std::to_string(i);
    auto unique = stem;
    for (auto k = 1; used.count(unique); k++) unique = stem + "-" + std::to_string(k);
    used.insert(unique);
    files.push_back(unique + extension);
  }
  return files;
}

static json make_scene_json(const scene_data& scene,
    const std::vector<std::string>& shape_files,
    const std::vector<std::string>& texture_files) {
  auto js           = json::object();
  auto named        = [](const std::vector<std::string>& names, size_t index) {
    auto element = json::object();
    auto name    = element_name(names, index);
    if (!name.empty()) element["name"] = name;
    return element;
  };
  js["asset"] = {{"version", "4.2"}, {"generator", "yocto-hair"}};
  if (!scene.copyright.empty()) js["asset"]["copyright"] = scene.copyright;
  auto& settings = scene.settings;
  if (settings.resolution != 0 || settings.samples != 0 || settings.bounces != 0)
    js["settings"] = {{"resolution", settings.resolution}, {"samples", settings.samples},
        {"bounces", settings.bounces}};

  auto cameras = json::array();
  for (size_t i = 0; i < scene.cameras.size(); i++) {
    auto& camera            = scene.cameras[i];
    auto  element           = named(scene.camera_names, i);
    element["frame"]        = json_frame(camera.frame);
    element["orthographic"] = camera.orthographic;
    element["lens"]         = json_number(camera.lens);
    element["film"]         = json_number(camera.film);
    element["aspect"]       = json_number(camera.aspect);
    element["focus"]        = json_number(camera.focus);
    element["aperture"]     = json_number(camera.aperture);
    cameras.push_back(element);
  }
  if (!cameras.empty()) js["cameras"] = cameras;

  auto environments = json::array();
  for (size_t i = 0; i < scene.environments.size(); i++) {
    auto& environment   = scene.environments[i];
    auto  element       = named(scene.environment_names, i);
    element["frame"]    = json_frame(environment.frame);
    element["emission"] = json_vec3(environment.emission);
    if (environment.emission_tex >= 0) element["emission_tex"] = environment.emission_tex;
    environments.push_back(element);
  }
  if (!environments.empty()) js["environments"] = environments;

  auto lights = json::array();
  for (auto& light : scene.distant_lights) {
    auto element         = json::object();
    element["direction"] = json_vec3(light.direction);
    element["emission"]  = json_vec3(light.emission);
    lights.push_back(element);
  }
  if (!lights.empty()) js["distant_lights"] = lights;

  auto textures = json::array();
  for (size_t i = 0; i < scene.textures.size(); i++) {
    auto element   = named(scene.texture_names, i);
    element["uri"] = "textures/" + texture_files[i];
    textures.push_back(element);
  }
  if (!textures.empty()) js["textures"] = textures;

  auto shapes = json::array();
  for (size_t i = 0; i < scene.shapes.size(); i++) {
    auto element   = named(scene.shape_names, i);
    element["uri"] = "shapes/" + shape_files[i];
    shapes.push_back(element);
  }
  if (!shapes.empty()) js["shapes"] = shapes;

  // Each type writes the keys it uses (the loader ignores the others).
  auto materials = json::array();
  for (size_t i = 0; i < scene.materials.size(); i++) {
    auto& material      = scene.materials[i];
    auto  element       = named(scene.material_names, i);
    element["type"]     = material_type_names[(int)material.type];
    element["emission"] = json_vec3(material.emission);
    if (material.emission_tex >= 0) element["emission_tex"] = material.emission_tex;
    if (material.type == material_type::hair) {
      // Optional keys when given, variation keys away from their defaults
      // (files without variation stay as they were), the others always.
      for (auto& parameter : hair_parameters) {
        auto write = parameter.has || parameter.group == hair_parameter_group::variation
                         ? is_hair_parameter_set(material.hair, parameter)
                         : true;
        if (!write) continue;
        auto value = get_hair_parameter(material.hair, parameter);
        element[parameter.name] = parameter.kind == hair_parameter_kind::number
                                      ? json(json_number(value.x))
                                      : json_vec3(value);
      }
    } else {
      element["color"] = json_vec3(material.color);
      if (material.color_tex >= 0) element["color_tex"] = material.color_tex;
      if (material.type == material_type::glossy) {
        element["roughness"] = json_number(material.roughness);
        element["ior"]       = json_number(material.ior);
      }
    }
    materials.push_back(element);
  }
  if (!materials.empty()) js["materials"] = materials;

  auto instances = json::array();
  for (size_t i = 0; i < scene.instances.size(); i++) {
    auto& instance      = scene.instances[i];
    auto  element       = named(scene.instance_names, i);
    element["frame"]    = json_frame(instance.frame);
    element["shape"]    = instance.shape;
    element["material"] = instance.material;
    instances.push_back(element);
  }
  if (!instances.empty()) js["instances"] = instances;
  return js;
}

bool save_scene(const std::string& filename, const scene_data& scene,
    std::string& error, bool ascii_shapes) {
  if (!validate_scene(scene, error)) {
    error = filename + ": cannot save scene: " + error;
    return false;
  }
  auto directory     = path_dirname(filename);
  auto shape_files   = make_file_names(scene.shape_names, scene.shapes.size(), "shape", ".ply");
  auto texture_files = make_file_names(
      scene.texture_names, scene.textures.size(), "texture", ".exr");

  // All or nothing: every file is written to its temporary first, and only
  // when all are complete are they renamed into place, the json last. A
  // failure (or a signal) before then leaves an existing scene untouched.
  auto files = std::vector<output_file>{};
  auto undo  = [&]() {
    discard_output_files(files);
    remove_output_directories();
    return false;
  };
  auto stage = [&](const std::string& path, const std::string& data) {
    files.emplace_back();
    return open_output_file(files.back(), path, error) &&
           write_output_file(files.back(), data.data(), data.size(), error) &&
           finish_output_file(files.back(), error);
  };
  auto data   = std::string{};
  auto status = (struct stat){};
  if (!directory.empty() && (stat(directory.c_str(), &status) != 0 || !S_ISDIR(status.st_mode))) {
    error = filename + ": no such directory " + directory;
    return false;
  }
  if (!scene.shapes.empty() && !make_output_directories(path_join(directory, "shapes"), error))
    return undo();
  for (size_t i = 0; i < scene.shapes.size(); i++) {
    auto path = path_join(directory, "shapes/" + shape_files[i]);
    if (!encode_shape(path, scene.shapes[i], data, error, ascii_shapes) || !stage(path, data))
      return undo();
  }
  if (!scene.textures.empty() &&
      !make_output_directories(path_join(directory, "textures"), error))
    return undo();
  for (size_t i = 0; i < scene.textures.size(); i++) {
    auto path = path_join(directory, "textures/" + texture_files[i]);
    if (!encode_image(path, scene.textures[i], data, error, 0) || !stage(path, data))
      return undo();
  }
  if (!stage(filename, make_scene_json(scene, shape_files, texture_files).dump(2) + "\n"))
    return undo();
  if (!commit_output_files(files, error)) return undo();
  keep_output_directories();
  return true;
}

}  // namespace yocto

// -----------------------------------------------------------------------------
// ANY SCENE
// -----------------------------------------------------------------------------
namespace yocto {

bool load_any_scene(const std::string& filename, scene_data& scene, std::string& error,
    const pbrt_params& params) {
  auto extension = path_extension(filename);
  if (extension == ".pbrt" || extension == ".gz") {
    return load_pbrt_scene(filename, scene, error, params);
  } else if (extension == ".hair") {
    auto hair = hair_params{params.curves_as_lines, params.segments, params.max_memory};
    return load_hair_scene(filename, scene, error, hair);
  } else {
    return load_scene(filename, scene, error, nullptr, params.max_memory);
  }
}

}  // namespace yocto
