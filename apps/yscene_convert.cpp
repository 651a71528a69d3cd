//
// yscene convert: a pbrt, hair or json scene to a json scene (shapes as ply,
// textures as exr).
//

#include <chrono>
#include <cstdio>

#include "yscene_cli.h"

using namespace yocto;

// -----------------------------------------------------------------------------
// CONVERT
// -----------------------------------------------------------------------------

// Loads INPUT (tessellating curves if asked) and saves it as a json scene.
static int convert_scene(const std::string& input, const std::string& output,
    const pbrt_params& params, bool quiet) {
  if (path_extension(output) != ".json")
    return print_error(output + ": the output must be a .json scene");
  auto scene = scene_data{};
  auto error = std::string{};
  auto start = std::chrono::steady_clock::now();
  if (!load_any_scene(input, scene, error, with_memory_limit(params))) return print_error(error);
  if (params.curves_as_lines) {
    for (auto& shape : scene.shapes)
      if (!shape.curves.empty()) shape = curves_to_lines(shape, params.segments);
  }
  if (!make_output_directory(output, error)) return print_error(error);
  if (!save_scene(output, scene, error)) return print_error(error);
  auto curves = (size_t)0, lines = (size_t)0;
  for (auto& shape : scene.shapes) {
    curves += shape.curves.size();
    lines += shape.lines.size();
  }
  if (!quiet)
    std::printf("converted %s to %s in %.2fs: %zu shapes, %zu curves, %zu lines\n",
        input.c_str(), output.c_str(), seconds_since(start), scene.shapes.size(), curves, lines);
  return 0;
}

CLI::App* add_convert_command(CLI::App& app, convert_options& options, std::string& max_memory) {
  auto convert = app.add_subcommand("convert",
      "convert a pbrt, hair or json scene to a json scene (shapes as ply, textures as exr)");
  convert->add_option("input", options.input, "input scene: pbrt, pbrt.gz, hair or json")
      ->required();
  convert->add_option("output", options.output, "output json scene")->required();
  convert->add_option("--curves", options.curves, "native Bezier curves or line segments")
      ->check(CLI::IsMember({"native", "lines"}));
  convert->add_option("--segments", options.params.segments, "line segments per curve")
      ->check(CLI::Range(1, 64));
  convert->add_flag("--lenient", options.params.lenient, "unknown pbrt directives are warnings");
  convert->add_flag("--quiet,-q", options.quiet, "print nothing on success");
  add_max_memory_option(convert, max_memory);
  return convert;
}

int run_convert(const convert_options& options) {
  auto params            = options.params;
  params.curves_as_lines = options.curves == "lines";
  return convert_scene(options.input, options.output, params, options.quiet);
}
