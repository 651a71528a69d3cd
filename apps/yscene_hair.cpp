//
// yscene hair: a hair scene, or stand-in strands for scenes that include
// them, optionally placed where a scene's camera looks.
//

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>

#include "yscene_cli.h"

using namespace yocto;

// -----------------------------------------------------------------------------
// HAIR GENERATOR
// -----------------------------------------------------------------------------

// `yscene hair --name-with-dashes`: one number, or r g b, that must lie in
// the parameter's range; the values go to `values` (empty if not given).
static void add_hair_parameter_option(
    CLI::App* command, const hair_parameter& parameter, std::vector<float>& values) {
  auto name = "--" + std::string(parameter.name);
  std::replace(name.begin(), name.end(), '_', '-');
  auto range = format_hair_parameter_range(parameter);
  auto help  = std::string(parameter.doc) + " (" + range;
  if (!parameter.has)
    help += ", default " + format_hair_parameter_value(parameter, parameter.default_value);
  auto in_range = [&parameter, range](std::string& text) {
    auto end   = (char*)nullptr;
    auto value = std::strtof(text.c_str(), &end);
    if (text.empty() || *end != 0) return "expected a number, got " + text;
    if (!is_hair_parameter_valid(parameter, vec3f{value}))
      return "expected a number " + range + ", got " + text;
    return std::string{};
  };
  command->add_option(name, values, help + ")")
      ->expected(parameter.kind == hair_parameter_kind::number ? 1 : 3)
      ->check(CLI::Validator(in_range, ""));
}

// The first camera of a scene. A .pbrt file is read only up to WorldBegin,
// so the camera of a scene whose world includes are missing, the stand-ins'
// use case, still loads; warnings (e.g. an unsupported camera type) go to
// stderr, as convert's do.
static bool load_first_camera(const std::string& filename, camera_data& camera,
    std::string& error) {
  if (path_extension(filename) == ".pbrt")
    return load_pbrt_camera(filename, camera, error, with_memory_limit());
  auto scene = scene_data{};
  if (!load_any_scene(filename, scene, error, with_memory_limit())) return false;
  if (scene.cameras.empty()) return error = filename + ": no camera", false;
  camera = scene.cameras[0];
  return true;
}

// Generates the strands of a style and saves them as OUTPUT's extension says.
static int generate_hair(const hair_options& options, hair_style_params params,
    const hair_material& material) {
  params.style = enum_from_name<hair_style>(hair_style_names, options.style);
  auto start     = std::chrono::steady_clock::now();
  auto error     = std::string{};
  auto extension = path_extension(options.output);
  auto output    = options.output;
  auto is_pbrt   = extension == ".pbrt" ||
                 (output.size() > 8 && output.substr(output.size() - 8) == ".pbrt.gz");
  auto strands   = (size_t)0, segments = (size_t)0;
  // Shapes index their vertices with int: refuse before allocating.
  auto points = (int64_t)params.strands * (3 * (int64_t)hair_strand_segments(params) + 1);
  if (points >= (int64_t)INT32_MAX)
    return print_error(output + ": " + std::to_string(params.strands) + " strands of " +
                       std::to_string(hair_strand_segments(params)) + " segments need " +
                       std::to_string(points) + " control points, more than the " +
                       std::to_string(INT32_MAX - 1) + " a shape can index");
  if (!options.fit_camera.empty() && extension == ".json")
    return print_error("--fit-camera places stand-in strands: use a .pbrt, .pbrt.gz, .hair or .ply output");
  if (extension == ".json") {
    auto scene = make_hair_scene(params, material);
    strands    = (size_t)params.strands;
    segments   = scene.shapes[0].curves.size();
    if (!make_output_directory(output, error)) return print_error(error);
    if (!save_scene(output, scene, error)) return print_error(error);
  } else if (is_pbrt || extension == ".hair" || extension == ".ply") {
    // Strands only: stand-in geometry for scenes that include or load it.
    auto shape = make_hair_strands(params);
    strands    = (size_t)params.strands;
    segments   = shape.curves.size();
    if (!options.fit_camera.empty()) {
      auto camera = camera_data{};
      if (!load_first_camera(options.fit_camera, camera, error)) return print_error(error);
      auto frame = fit_hair_to_camera(camera, shape, options.fit_fraction, options.fit_distance);
      transform_hair_strands(shape, frame);
      std::printf("fitted to %s's camera: scale %g, centre [%g %g %g]\n",
          options.fit_camera.c_str(), frame_scale(frame), center(compute_bounds(shape)).x,
          center(compute_bounds(shape)).y, center(compute_bounds(shape)).z);
    }
    if (!make_output_directory(output, error)) return print_error(error);
    auto ok = is_pbrt ? save_pbrt_curves(output, shape, error)
              : extension == ".hair" ? save_hair_model(output, shape, error)
                                     : save_shape(output, shape, error);
    if (!ok) return print_error(error);
  } else {
    return print_error(
        output + ": unknown output extension (use .json, .pbrt, .pbrt.gz, .hair or .ply)");
  }
  if (!options.quiet)
    std::printf("generated %s: %s hair, %zu strands, %zu Bezier segments in %.2fs\n",
      output.c_str(), options.style.c_str(), strands, segments, seconds_since(start));
  return 0;
}

CLI::App* add_hair_command(CLI::App& app, hair_command& command, std::string& max_memory) {
  auto& options = command.options;
  auto& params  = command.params;
  auto hair = app.add_subcommand("hair", "generate a hair scene or stand-in hair geometry");
  hair->add_option("--style", options.style, "straight, curly, curls, block or fur")
      ->check(CLI::IsMember(hair_style_names));
  hair->add_option("--strands,-n", params.strands, "number of strands")
      ->check(CLI::Range(1, 50000000));
  hair->add_option("--segments", params.segments, "Bezier segments per strand (0: style default)")
      ->check(CLI::Range(0, 1000));
  hair->add_option("--radius", params.radius, "root radius (0: style default)")
      ->check(CLI::NonNegativeNumber);
  hair->add_option("--seed", params.seed, "random seed");
  hair->add_option("--output,-o", options.output,
          "json scene (with ply and sky), .pbrt, .pbrt.gz, .hair or .ply strands")
      ->required();
  hair->add_flag("--quiet,-q", options.quiet, "print nothing on success");
  hair->add_option("--fit-camera", options.fit_camera,
      "place the strands where this scene's first camera looks (pbrt: read up to WorldBegin)");
  add_max_memory_option(hair, max_memory);
  hair->add_option("--fit-fraction", options.fit_fraction,
          "with --fit-camera: fraction of the image the strands span")
      ->check(CLI::Range(0.01f, 1.0f));
  hair->add_option("--fit-distance", options.fit_distance,
          "with --fit-camera: distance along the view axis (0: where the camera sees them)")
      ->check(CLI::NonNegativeNumber);
  // The material's parameters: one option per row of hair_parameters.
  command.values = std::vector<std::vector<float>>(std::size(hair_parameters));
  for (auto k = 0; k < (int)std::size(hair_parameters); k++)
    add_hair_parameter_option(hair, hair_parameters[k], command.values[k]);
  return hair;
}

int run_hair(const hair_command& command) {
  auto material = hair_material{};
  for (auto k = 0; k < (int)std::size(hair_parameters); k++) {
    auto& values = command.values[k];
    if (values.empty()) continue;
    set_hair_parameter(material, hair_parameters[k],
        values.size() == 3 ? vec3f{values[0], values[1], values[2]} : vec3f{values[0]});
  }
  return generate_hair(command.options, command.params, material);
}
