//
// yscene convert: a pbrt, hair, USD or json scene to a json scene (shapes as
// ply, textures as exr).
//

#include <spawn.h>
#include <sys/wait.h>

#include <cerrno>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>

#include "yscene_cli.h"

extern char** environ;

using namespace yocto;

// -----------------------------------------------------------------------------
// USD INPUT
// -----------------------------------------------------------------------------

// USD stages are read by Pixar's usd-core in Python: scripts/usd_to_yocto.py
// writes a json scene into a temporary folder, which is then loaded as any
// json scene (so checked) and saved by save_scene like every other input.
bool is_usd_file(const std::string& filename) {
  auto extension = path_extension(filename);
  return extension == ".usd" || extension == ".usda" || extension == ".usdc" ||
         extension == ".usdz";
}

// The environment's value of `name`, else `fallback`.
static std::string environment_or(const char* name, const std::string& fallback) {
  auto value = std::getenv(name);
  return value && *value ? std::string(value) : fallback;
}

temporary_folder::~temporary_folder() {
  auto ignored = std::error_code{};
  if (!path.empty()) std::filesystem::remove_all(path, ignored);
}

// Runs the converter on `input` into `folder`: true if it succeeded. The
// child prints its own warnings and errors ("error: FILE: PRIM: ...") on our
// stderr; `error` is set only for what the child cannot say itself.
static bool run_usd_converter(const std::string& input, const std::string& folder,
    const convert_options& options, std::string& error, bool& child_failed) {
  child_failed = false;
  auto python    = environment_or("YOCTO_USD_PYTHON", YOCTO_USD_PYTHON);
  auto converter = environment_or("YOCTO_USD_CONVERTER", YOCTO_USD_CONVERTER);
  if (!std::filesystem::exists(python)) {
    error = input + ": reading USD needs usd-core in " + python +
            " (run: bash scripts/setup.sh --usd, or set YOCTO_USD_PYTHON)";
    return false;
  }
  auto args = std::vector<std::string>{python, converter, input, folder};
  if (!options.usd_time.empty()) args.insert(args.end(), {"--time", options.usd_time});
  if (!options.hair_material.empty())
    args.insert(args.end(), {"--hair-material", options.hair_material});
  if (!options.usd_width.empty()) args.insert(args.end(), {"--width", options.usd_width});
  if (options.quiet) args.push_back("--quiet");
  auto argv = std::vector<char*>{};
  for (auto& arg : args) argv.push_back(arg.data());
  argv.push_back(nullptr);
  auto pid = (pid_t)0;
  if (auto code = posix_spawn(&pid, python.c_str(), nullptr, nullptr, argv.data(), environ)) {
    error = input + ": cannot run " + python + ": " + std::strerror(code);
    return false;
  }
  auto status = 0;
  while (waitpid(pid, &status, 0) < 0) {
    if (errno != EINTR) {
      error = input + ": lost the converter process: " + std::strerror(errno);
      return false;
    }
  }
  if (WIFEXITED(status) && WEXITSTATUS(status) == 0) return true;
  child_failed = WIFEXITED(status) && WEXITSTATUS(status) == 1;
  error = input + ": the USD converter " + converter +
          (WIFSIGNALED(status) ? " was killed by signal " + std::to_string(WTERMSIG(status))
                               : " failed with exit status " + std::to_string(WEXITSTATUS(status)));
  return false;
}

bool convert_usd_stage(const std::string& input, const convert_options& options,
    temporary_folder& folder, std::string& error, bool& child_failed) {
  child_failed = false;
  if (!options.hair_material.empty()) {
    // Checked here, so that its errors name it and its values are valid.
    auto materials = scene_data{};
    if (!load_scene(options.hair_material, materials, error, nullptr, memory_limit))
      return false;
    auto found = false;
    for (auto& material : materials.materials) found |= material.type == material_type::hair;
    if (!found) {
      error = options.hair_material + ": --hair-material: no hair material in it";
      return false;
    }
  }
  auto base = std::filesystem::temp_directory_path().string() + "/yscene-usd-XXXXXX";
  if (!mkdtemp(base.data())) {
    error = input + ": cannot make a temporary folder: " + std::strerror(errno);
    return false;
  }
  folder.path = base;
  return run_usd_converter(input, folder.path, options, error, child_failed);
}

bool load_cli_scene(const std::string& input, scene_data& scene, const convert_options& usd,
    const pbrt_params& params, std::string& error, bool& child_failed) {
  child_failed = false;
  if (!is_usd_file(input)) return load_any_scene(input, scene, error, params);
  auto folder = temporary_folder{};
  if (!convert_usd_stage(input, usd, folder, error, child_failed)) return false;
  if (!load_scene(path_join(folder.path, "scene.json"), scene, error, nullptr, memory_limit)) {
    error = input + ": the converted scene does not load: " + error;
    return false;
  }
  return true;
}

// -----------------------------------------------------------------------------
// CONVERT
// -----------------------------------------------------------------------------

// Loads INPUT (tessellating curves if asked) and saves it as a json scene.
static int convert_scene(const std::string& input, const std::string& output,
    const pbrt_params& params, const convert_options& options) {
  auto quiet = options.quiet;
  if (path_extension(output) != ".json")
    return print_error(output + ": the output must be a .json scene");
  auto scene = scene_data{};
  auto error = std::string{};
  auto start = std::chrono::steady_clock::now();
  if (!is_usd_file(input) &&
      (!options.usd_time.empty() || !options.hair_material.empty() || !options.usd_width.empty()))
    return print_error(input + ": --time, --hair-material and --width are for USD inputs");
  auto child_failed = false;
  if (!load_cli_scene(input, scene, options, with_memory_limit(params), error, child_failed))
    return child_failed ? 1 : print_error(error);
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
  if (!quiet && is_usd_file(input))
    std::printf("hair material: %s\n",
        options.hair_material.empty()
            ? "default (eumelanin 1.3, beta_m 0.3, beta_n 0.3; or the prims' primvars)"
            : (options.hair_material + " (or the prims' primvars)").c_str());
  return 0;
}

CLI::App* add_convert_command(CLI::App& app, convert_options& options, std::string& max_memory) {
  auto convert = app.add_subcommand("convert",
      "convert a pbrt, hair, USD or json scene to a json scene (shapes as ply, textures as exr)");
  convert->add_option("input", options.input,
      "input scene: pbrt, pbrt.gz, hair, usd, usda, usdc, usdz or json")
      ->required();
  convert->add_option("output", options.output, "output json scene")->required();
  convert->add_option("--curves", options.curves, "native Bezier curves or line segments")
      ->check(CLI::IsMember({"native", "lines"}));
  convert->add_option("--segments", options.params.segments, "line segments per curve")
      ->check(CLI::Range(1, 64));
  convert->add_flag("--lenient", options.params.lenient, "unknown pbrt directives are warnings");
  convert->add_option("--time", options.usd_time, "USD: the time code to read (default: default)")
      ->check(CLI::Number);
  convert->add_option("--hair-material", options.hair_material,
      "USD: a json scene whose first hair material grooms without hair primvars take "
      "(default: eumelanin 1.3)");
  convert->add_option("--width", options.usd_width,
      "USD: the width (diameter) of curves that author no widths, such as Blender's particle "
      "hair (default: 0.01)")
      ->check(CLI::PositiveNumber);
  convert->add_flag("--quiet,-q", options.quiet, "print nothing on success");
  add_max_memory_option(convert, max_memory);
  return convert;
}

int run_convert(const convert_options& options) {
  auto params            = options.params;
  params.curves_as_lines = options.curves == "lines";
  return convert_scene(options.input, options.output, params, options);
}
