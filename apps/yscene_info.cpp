//
// yscene info: a scene's statistics, cameras, materials (with the values
// rendered), environments and lights, as text or as json.
//

#include <cmath>
#include <cstdio>
#include <nlohmann/json.hpp>

#include "yscene_cli.h"

using namespace yocto;

// -----------------------------------------------------------------------------
// INFO
// -----------------------------------------------------------------------------

// info --json's document: keys in the order written and numbers as floats, the
// type of every value here, so that each prints as its shortest text (0.05,
// not 0.05000000074505806). NaN and Inf print as null.
using info_json = nlohmann::basic_json<nlohmann::ordered_map, std::vector, std::string, bool,
    std::int64_t, std::uint64_t, float>;

// A name from a names array, or "#index" when the array lacks it.
static std::string element_name(const std::vector<std::string>& names, int index) {
  return index >= 0 && index < (int)names.size() && !names[index].empty()
             ? names[index]
             : "#" + std::to_string(index);
}

// A perspective camera's field of view across and down the image, in degrees.
static vec2f camera_fov(const camera_data& camera) {
  auto film = camera_film_size(camera);
  return {degrees(2 * std::atan(film.x / (2 * camera.lens))),
      degrees(2 * std::atan(film.y / (2 * camera.lens)))};
}

// Where a hair material's absorption comes from (pbrt's precedence).
static std::string hair_sigma_a_source(const hair_material& hair) {
  return hair.has_sigma_a ? "sigma_a" : hair.has_color ? "color" : "melanin";
}

int run_info(const info_options& options) {
  auto& filename = options.scene;
  auto  scene    = scene_data{};
  auto  error    = std::string{};
  // A USD stage is converted on the fly, as convert does (its defaults;
  // warnings on stderr).
  auto usd          = convert_options{};
  usd.quiet         = true;
  auto child_failed = false;
  if (!load_cli_scene(filename, scene, usd, with_memory_limit(), error, child_failed))
    return child_failed ? 1 : print_error(error);
  auto triangles = (size_t)0, lines = (size_t)0, curves = (size_t)0, vertices = (size_t)0;
  auto bytes = (size_t)0;
  for (auto& shape : scene.shapes) {
    triangles += shape.triangles.size();
    lines += shape.lines.size();
    curves += shape.curves.size();
    vertices += shape.positions.size();
    bytes += (size_t)shape_memory(shape);
  }
  for (auto& texture : scene.textures) bytes += texture.pixels.size() * sizeof(vec3f);
  auto bounds = compute_bounds(scene);
  // The resolution a render would use: the scene's, else render's default.
  auto resolution = scene.settings.resolution > 0 ? scene.settings.resolution
                                                  : trace_params{}.resolution;
  auto texture_text = [&](int texture) {
    if (texture < 0) return std::string{"none"};
    auto& data = scene.textures[texture];
    return element_name(scene.texture_names, texture) + " (" + std::to_string(data.width) + "x" +
           std::to_string(data.height) + ")";
  };

  if (options.json) {
    auto vec3 = [](const vec3f& value) { return info_json::array({value.x, value.y, value.z}); };
    auto json = info_json::object();
    json["scene"]  = filename;
    json["counts"] = {{"cameras", scene.cameras.size()},
        {"environments", scene.environments.size()},
        {"distant_lights", scene.distant_lights.size()}, {"shapes", scene.shapes.size()},
        {"instances", scene.instances.size()}, {"materials", scene.materials.size()},
        {"textures", scene.textures.size()}, {"vertices", vertices}, {"triangles", triangles},
        {"lines", lines}, {"curves", curves}};
    json["memory"] = bytes;
    json["bounds"] = empty(bounds) ? info_json(nullptr)
                                   : info_json::array({vec3(bounds.min), vec3(bounds.max)});
    auto cameras = info_json::array();
    for (auto i = 0; i < (int)scene.cameras.size(); i++) {
      auto& camera = scene.cameras[i];
      auto  size   = camera_resolution(camera, resolution);
      auto  fov    = camera_fov(camera);
      cameras.push_back({{"name", element_name(scene.camera_names, i)},
          {"position", vec3(camera.frame.o)}, {"direction", vec3(-camera.frame.z)},
          {"up", vec3(camera.frame.y)}, {"orthographic", camera.orthographic},
          {"lens", camera.lens}, {"film", camera.film},
          {"fov_degrees", info_json::array({fov.x, fov.y})}, {"aspect", camera.aspect},
          {"focus", camera.focus}, {"aperture", camera.aperture},
          {"resolution", info_json::array({size.x, size.y})}});
    }
    json["cameras"] = std::move(cameras);
    auto materials = info_json::array();
    for (auto i = 0; i < (int)scene.materials.size(); i++) {
      auto& material = scene.materials[i];
      auto  item     = info_json{{"name", element_name(scene.material_names, i)},
          {"type", material_type_names[(int)material.type]},
          {"emission", vec3(material.emission)},
          {"emission_tex", texture_text(material.emission_tex)}};
      if (material.type == material_type::hair) {
        // Every parameter of the table, null if optional and not given;
        // sigma_a is the absorption the model uses, sigma_a_from its source.
        auto& hair = material.hair;
        for (auto& parameter : hair_parameters) {
          auto value = get_hair_parameter(hair, parameter);
          if (parameter.has && !(hair.*parameter.has)) item[parameter.name] = nullptr;
          else if (parameter.kind == hair_parameter_kind::number) item[parameter.name] = value.x;
          else item[parameter.name] = vec3(value);
        }
        item["sigma_a"]      = vec3(make_hair_precomputed(hair).sigma_a);
        item["sigma_a_from"] = hair_sigma_a_source(hair);
      } else {
        item["color"]     = vec3(material.color);
        item["color_tex"] = texture_text(material.color_tex);
        if (material.type == material_type::glossy) {
          item["roughness"] = material.roughness;
          item["ior"]       = material.ior;
        }
      }
      materials.push_back(std::move(item));
    }
    json["materials"] = std::move(materials);
    auto environments = info_json::array();
    for (auto i = 0; i < (int)scene.environments.size(); i++) {
      auto& environment = scene.environments[i];
      environments.push_back({{"name", element_name(scene.environment_names, i)},
          {"emission", vec3(environment.emission)},
          {"emission_tex", texture_text(environment.emission_tex)},
          {"up", vec3(environment.frame.y)}});
    }
    json["environments"] = std::move(environments);
    auto lights = info_json::array();
    for (auto& light : scene.distant_lights)
      lights.push_back(
          {{"direction", vec3(light.direction)}, {"emission", vec3(light.emission)}});
    json["distant_lights"] = std::move(lights);
    // Names are bytes: invalid UTF-8 prints as U+FFFD rather than throwing.
    std::puts(json.dump(2, ' ', false, info_json::error_handler_t::replace).c_str());
    return 0;
  }

  std::printf("scene:        %s\n", filename.c_str());
  std::printf("cameras:      %zu\n", scene.cameras.size());
  std::printf("environments: %zu\n", scene.environments.size());
  std::printf("distant lights: %zu\n", scene.distant_lights.size());
  std::printf("shapes:       %zu\n", scene.shapes.size());
  std::printf("instances:    %zu\n", scene.instances.size());
  std::printf("materials:    %zu\n", scene.materials.size());
  std::printf("textures:     %zu\n", scene.textures.size());
  std::printf("vertices:     %zu\n", vertices);
  std::printf("triangles:    %zu\n", triangles);
  std::printf("fiber segments: %zu (%zu lines, %zu curves)\n", lines + curves, lines, curves);
  std::printf("memory:       %s bytes\n", format_count((double)bytes).c_str());
  if (!empty(bounds)) {
    std::printf("bounds:       [%g %g %g] - [%g %g %g]\n", bounds.min.x, bounds.min.y,
        bounds.min.z, bounds.max.x, bounds.max.y, bounds.max.z);
  } else {
    std::printf("bounds:       empty\n");
  }
  for (auto i = 0; i < (int)scene.cameras.size(); i++) {
    auto& camera = scene.cameras[i];
    auto  size   = camera_resolution(camera, resolution);
    auto  fov    = camera_fov(camera);
    // + 0 turns -0 into 0.
    auto  o = camera.frame.o + vec3f{0, 0, 0}, d = -camera.frame.z + vec3f{0, 0, 0};
    std::printf("camera %s: %s at [%g %g %g] looking [%g %g %g], lens %g mm, film %g mm, "
                "fov %.4g x %.4g deg, aspect %g, focus %g, aperture %g, %dx%d pixels\n",
        element_name(scene.camera_names, i).c_str(),
        camera.orthographic ? "orthographic" : "perspective", o.x, o.y, o.z, d.x, d.y, d.z,
        camera.lens * 1000, camera.film * 1000,
        fov.x, fov.y, camera.aspect, camera.focus,
        camera.aperture, size.x, size.y);
  }
  for (auto i = 0; i < (int)scene.materials.size(); i++) {
    auto& material = scene.materials[i];
    auto  name     = element_name(scene.material_names, i);
    auto  e        = material.emission;
    if (material.type == material_type::hair) {
      auto& hair = material.hair;
      auto  used = make_hair_precomputed(hair);
      auto  from = hair_sigma_a_source(hair);
      char source[160];
      if (from == "sigma_a") std::snprintf(source, sizeof(source), "given");
      else if (from == "color")
        std::snprintf(source, sizeof(source), "from color [%g %g %g]", hair.color.x,
            hair.color.y, hair.color.z);
      else
        std::snprintf(source, sizeof(source), "from melanin (eumelanin %g, pheomelanin %g)",
            hair.eumelanin, hair.pheomelanin);
      // The fiber's parameters, then the variation ones the material sets.
      auto values = std::string{};
      for (auto& parameter : hair_parameters) {
        if (parameter.group == hair_parameter_group::pigment) continue;
        if (parameter.group == hair_parameter_group::variation &&
            !is_hair_parameter_set(hair, parameter))
          continue;
        values += std::string(", ") + parameter.name + " " +
                  format_hair_parameter_value(parameter, get_hair_parameter(hair, parameter)) +
                  (parameter.unit[0] != 0 ? std::string(" ") + parameter.unit : "");
      }
      std::printf("material %s: hair, sigma_a [%g %g %g] %s%s\n", name.c_str(), used.sigma_a.x,
          used.sigma_a.y, used.sigma_a.z, source, values.c_str());
    } else {
      auto c = material.color;
      std::printf("material %s: %s, color [%g %g %g]%s%s, emission [%g %g %g]%s\n",
          name.c_str(), material_type_names[(int)material.type].c_str(), c.x, c.y, c.z,
          material.color_tex >= 0 ? (" x " + texture_text(material.color_tex)).c_str() : "",
          material.type == material_type::glossy
              ? (", roughness " + std::to_string(material.roughness) + ", ior " +
                    std::to_string(material.ior))
                    .c_str()
              : "",
          e.x, e.y, e.z,
          material.emission_tex >= 0 ? (" x " + texture_text(material.emission_tex)).c_str()
                                     : "");
    }
  }
  for (auto i = 0; i < (int)scene.environments.size(); i++) {
    auto& environment = scene.environments[i];
    auto  e           = environment.emission;
    std::printf("environment %s: emission [%g %g %g]%s\n",
        element_name(scene.environment_names, i).c_str(), e.x, e.y, e.z,
        environment.emission_tex >= 0
            ? (" x " + texture_text(environment.emission_tex)).c_str()
            : "");
  }
  for (auto& light : scene.distant_lights) {
    std::printf("distant light: from [%g %g %g], irradiance [%g %g %g]\n", light.direction.x,
        light.direction.y, light.direction.z, light.emission.x, light.emission.y,
        light.emission.z);
  }
  return 0;
}

CLI::App* add_info_command(CLI::App& app, info_options& options, std::string& max_memory) {
  auto info = app.add_subcommand("info",
      "print a scene's statistics, cameras, materials (with the values rendered), "
      "environments and lights");
  info->add_option("scene", options.scene,
      "scene (json, pbrt, pbrt.gz, hair, or usd, usda, usdc, usdz converted on the fly)")->required();
  info->add_flag("--json", options.json, "the same as json, for programs");
  add_max_memory_option(info, max_memory);
  return info;
}
