//
// yscene: render, inspect and convert hair scenes.
//

#include <sys/resource.h>
#include <unistd.h>

#include <CLI/CLI.hpp>
#include <atomic>
#include <charconv>
#include <chrono>
#include <csignal>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <sstream>
#include <functional>
#include <nlohmann/json.hpp>
#include <yocto/yocto_bvh.h>
#include <yocto/yocto_hairgen.h>
#include <yocto/yocto_pbrtio.h>
#include <yocto/yocto_sceneio.h>
#include <yocto/yocto_trace.h>

#include "yocto_source_hash.h"  // generated from the sources: YOCTO_SOURCE_HASH

using namespace yocto;

// -----------------------------------------------------------------------------
// HELPERS
// -----------------------------------------------------------------------------

static int print_error(const std::string& message) {
  std::fprintf(stderr, "error: %s\n", message.c_str());
  return 1;
}

// Creates the missing directories above an output file before the work that
// fills it, so that a long render or a conversion does not fail at its end.
// The folders made are removed again if the command fails (see main).
static bool make_output_directory(const std::string& output, std::string& error) {
  if (make_output_directories(path_dirname(output), error)) return true;
  error = output + ": " + error;
  return false;
}

// SIGTERM, SIGHUP, SIGQUIT and (outside a render) SIGINT end a command with
// nothing of its outputs left: temporaries and the folders it made go, then
// the signal takes its default course.
static void handle_fatal_signal(int signal) {
  remove_pending_outputs();
  std::signal(signal, SIG_DFL);
  std::raise(signal);
}

static void install_signal_handlers() {
  for (auto signal : {SIGINT, SIGTERM, SIGHUP, SIGQUIT}) std::signal(signal, handle_fatal_signal);
}

static double seconds_since(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

static std::string format_duration(double seconds) {
  auto total = (int64_t)(seconds + 0.5);
  char buffer[64];
  std::snprintf(buffer, sizeof(buffer), "%02d:%02d:%02d", (int)(total / 3600),
      (int)((total / 60) % 60), (int)(total % 60));
  return buffer;
}

static std::string format_count(double count) {
  char buffer[64];
  if (count >= 1e9) std::snprintf(buffer, sizeof(buffer), "%.2fG", count / 1e9);
  else if (count >= 1e6) std::snprintf(buffer, sizeof(buffer), "%.2fM", count / 1e6);
  else if (count >= 1e3) std::snprintf(buffer, sizeof(buffer), "%.2fk", count / 1e3);
  else std::snprintf(buffer, sizeof(buffer), "%.0f", count);
  return buffer;
}

// The enum value of a name from its names table (the command line has
// checked that the name is in it).
template <typename Enum, size_t size>
static Enum enum_from_name(const std::array<std::string, size>& names, const std::string& name) {
  return (Enum)(std::find(names.begin(), names.end(), name) - names.begin());
}

// Bytes from --max-memory: a positive number, plain or with a K, M, G or T
// suffix (powers of 1024), e.g. 4G or 1.5G.
static bool parse_memory_size(const std::string& text, double& bytes) {
  auto end   = (char*)nullptr;
  auto value = std::strtod(text.c_str(), &end);
  if (end == text.c_str()) return false;
  auto suffix = std::string(end);
  auto units  = std::string("KMGT");
  auto unit   = suffix.size() == 1 ? units.find((char)std::toupper((unsigned char)suffix[0]))
                                   : std::string::npos;
  if (!suffix.empty() && unit == std::string::npos) return false;
  bytes = suffix.empty() ? value : std::ldexp(value, 10 * (int)(unit + 1));
  return std::isfinite(bytes) && bytes >= 1;
}

// Peak resident memory of this process in bytes.
static int64_t peak_memory() {
  auto usage = rusage{};
  getrusage(RUSAGE_SELF, &usage);
  return (int64_t)usage.ru_maxrss * 1024;
}

// CPU time of this process (user and system) in seconds.
static double cpu_seconds() {
  auto usage = rusage{};
  getrusage(RUSAGE_SELF, &usage);
  return usage.ru_utime.tv_sec + usage.ru_utime.tv_usec * 1e-6 + usage.ru_stime.tv_sec +
         usage.ru_stime.tv_usec * 1e-6;
}

// Loads a scene by extension: json, pbrt, or a Cem Yuksel .hair model.
static bool load_any_scene(const std::string& filename, scene_data& scene,
    std::string& error, const pbrt_params& params) {
  auto extension = path_extension(filename);
  if (extension == ".pbrt" || extension == ".gz") {
    return load_pbrt_scene(filename, scene, error, params);
  } else if (extension == ".hair") {
    return load_hair_scene(filename, scene, error, params);
  } else {
    return load_scene(filename, scene, error);
  }
}

// -----------------------------------------------------------------------------
// RENDER
// -----------------------------------------------------------------------------

// The first Ctrl-C asks the render to stop after its pass; a second one,
// while that pass or loading still runs, ends the program as usual.
static std::atomic<bool> interrupted = false;
static void handle_sigint(int signal) {
  if (interrupted) return handle_fatal_signal(signal);
  interrupted = true;
}

struct render_options {
  std::string scene    = "";
  std::string output   = "";
  std::string camera   = "";
  float       exposure = 0;
  bool        flat_curves = false;
  bool        quiet       = false;
  // Benchmark variants and measurements.
  std::string curves      = "native";  // native or lines
  int         segments    = 4;         // line segments per curve with lines
  bool        no_flatten  = false;     // Embree instances even for identity frames
  bool        checkpoints = false;     // save at 1, 2, 4, ... spp
  double      time_budget = 0;         // stop at the first power of two after it
  bool        stats       = false;     // one machine-readable line of figures
  bool        embree_only = false;     // replay the render's rays through Embree
  std::string bvh_quality = "high";    // Embree build quality
  std::string embree_config = "";      // Embree device configuration
  bool        bvh_compact   = false;   // Embree's compact BVH
  int         curve_pieces  = 4;       // most exact pieces of a bent Bezier segment
  std::string sample_range  = "";      // A:B: render these samples as a part
};

// OUTPUT with "-NNNNNspp" before the extension.
static std::string checkpoint_filename(const std::string& output, int samples) {
  auto extension = path_extension(output);
  char suffix[32];
  std::snprintf(suffix, sizeof(suffix), "-%05dspp", samples);
  return output.substr(0, output.size() - extension.size()) + suffix + extension;
}

static bool is_power_of_two(int n) { return n > 0 && (n & (n - 1)) == 0; }

// The limit of the renderer's speed: renders the samples (timed), records the
// same rays again (the render is deterministic) and casts them through Embree
// alone (timed, median of three). Prints both rates and their ratio.
static int run_raycast(const render_options& options, const scene_data& scene,
    const scene_bvh& bvh, const trace_context& context, const trace_params& params) {
  auto state = trace_state{};
  init_trace_state(state, scene, params);
  auto start = std::chrono::steady_clock::now();
  auto cpu   = cpu_seconds();
  trace_samples(state, scene, bvh, context, params, params.samples);
  auto render_time = seconds_since(start), render_cpu = cpu_seconds() - cpu;
  auto render_rays = (double)state.rays;
  init_trace_state(state, scene, params);
  auto rays = record_trace_rays(state, scene, bvh, context, params, params.samples);
  if ((double)rays.size() != render_rays)
    return print_error("the recorded rays differ from the rendered ones");
  auto times = std::vector<double>{}, cpus = std::vector<double>{};
  auto hits  = (int64_t)0;
  for (auto run = 0; run < 3; run++) {
    auto run_start = std::chrono::steady_clock::now();
    auto run_cpu   = cpu_seconds();
    hits           = cast_trace_rays(bvh, rays, params.threads);
    times.push_back(seconds_since(run_start));
    cpus.push_back(cpu_seconds() - run_cpu);
  }
  std::sort(times.begin(), times.end());
  std::sort(cpus.begin(), cpus.end());
  std::printf("raycast %s: %zu rays (%.1f%% hit) of %d spp at %dx%d\n", options.scene.c_str(),
      rays.size(), 100.0 * hits / std::max(rays.size(), (size_t)1), params.samples,
      state.width, state.height);
  std::printf("  renderer   %s rays/s (%.3fs, cpu %.3fs)\n",
      format_count(render_rays / render_time).c_str(), render_time, render_cpu);
  std::printf("  embree     %s rays/s (%.3fs, cpu %.3fs, median of 3)\n",
      format_count(rays.size() / times[1]).c_str(), times[1], cpus[1]);
  std::printf("  renderer / embree: %.3f (by cpu time %.3f)\n",
      (render_rays / render_time) / (rays.size() / times[1]),
      (render_rays / render_cpu) / (rays.size() / cpus[1]));
  if (options.stats)
    std::printf("stats rays=%zu render_seconds=%.6f render_cpu=%.6f embree_seconds=%.6f "
                "embree_cpu=%.6f\n",
        rays.size(), render_time, render_cpu, times[1], cpus[1]);
  return 0;
}

// Checks before any work that the output can be written: its folder takes a
// new file, the name is not a folder, the disk holds the image (12 bytes a
// pixel, the float formats' size, bounds every image format) and JPEG's largest
// side is not exceeded.
static bool check_render_output(
    const render_options& options, const trace_params& params, std::string& error) {
  auto side = (double)std::max(params.resolution, 1);
  if ((path_extension(options.output) == ".jpg" || path_extension(options.output) == ".jpeg") &&
      side > 65500) {
    error = options.output + ": JPEG images are at most 65500 pixels a side (resolution " +
            std::to_string(params.resolution) + ")";
    return false;
  }
  auto pixel_bytes = options.sample_range.empty() ? 12 : render_part_pixel_bytes;
  // AOVs: 23 float channels, or their sums in a part.
  if (params.aovs)
    pixel_bytes += options.sample_range.empty() ? 23 * 4
                                                : trace_aov_sums * render_part_extra_bytes;
  return check_output_file(options.output, side * side * pixel_bytes + 65536, error);
}

// After a failed save, writes the render as STEM-rescued.exr next to the
// output, else in the current folder, else in the temporary one (numbered
// if taken: an existing file is never overwritten). `save` writes it to a
// name without replacing anything.
static bool save_rescued_render(const std::string& output,
    const std::function<bool(const std::string&, std::string&)>& save, std::string& rescued) {
  auto name    = std::filesystem::path(output).stem().string() + "-rescued";
  auto folders = std::vector<std::string>{
      path_dirname(output), "", std::filesystem::temp_directory_path().string()};
  for (auto& folder : folders) {
    for (auto attempt = 0; attempt < 100; attempt++) {
      rescued = path_join(
          folder, name + (attempt == 0 ? "" : "-" + std::to_string(attempt)) + ".exr");
      auto ec = std::error_code{};
      if (std::filesystem::exists(rescued, ec)) continue;
      auto error = std::string{};
      if (save(rescued, error)) return true;
      break;  // this folder does not take it: the next one
    }
  }
  return false;
}

// The compiler that built this program, as it names itself.
static std::string compiler_name() {
#if defined(__clang__)
  return "clang " __clang_version__;
#elif defined(__GNUC__)
  return "gcc " __VERSION__;
#else
  return "unknown compiler";
#endif
}

// What every part of one render shares, one "key=value" a line, for a merge
// to compare: the scene's fingerprint, the camera and everything else that
// changes a sample's value (floats with 9 digits, which round-trip). The
// threads are left out: they do not change a bit.
static std::string render_settings(const scene_data& scene, const trace_params& params,
    const render_options& options, const trace_state& state) {
  auto text = std::string{};
  auto line = [&](const std::string& key, const std::string& value) {
    text += key + "=" + value + "\n";
  };
  auto number = [](double value) {
    char buffer[64];
    std::snprintf(buffer, sizeof(buffer), "%.9g", value);
    return std::string(buffer);
  };
  auto numbers = [&](std::initializer_list<float> values) {
    auto result = std::string{};
    for (auto value : values) result += (result.empty() ? "" : " ") + number(value);
    return result;
  };
  auto& camera = scene.cameras[params.camera];
  auto& frame  = camera.frame;
  // The code that renders: the same settings on other sources, another
  // compiler or another Embree may give other bits (fibre semantics change).
  line("renderer", std::string(YOCTO_SOURCE_HASH) + " " + compiler_name() + " embree " +
                       embree_version());
  line("scene", hex_string(fingerprint_scene(scene)));
  line("camera", std::to_string(params.camera));
  line("camera_frame", numbers({frame.x.x, frame.x.y, frame.x.z, frame.y.x, frame.y.y,
                           frame.y.z, frame.z.x, frame.z.y, frame.z.z, frame.o.x, frame.o.y,
                           frame.o.z}));
  line("camera_lens", numbers({camera.lens, camera.film, camera.aspect, camera.focus,
                          camera.aperture, camera.orthographic ? 1.0f : 0.0f}));
  line("resolution", std::to_string(state.width) + "x" + std::to_string(state.height));
  line("seed", std::to_string(params.seed));
  line("sampler", trace_sampler_names[(int)params.sampler]);
  line("lights", trace_lights_names[(int)params.lights]);
  line("sequence", sequence_names[(int)params.sequence]);
  line("sobol_bounces", std::to_string(params.sobol_bounces));
  line("bounces", std::to_string(params.bounces));
  line("roulette_bounce", std::to_string(params.roulette_bounce));
  line("roulette_threshold", number(params.roulette_threshold));
  line("split", std::to_string(params.split));
  line("shadow_threshold", number(params.shadow_threshold));
  line("clamp", number(params.clamp));
  // Only when on, so that the settings of renders without AOVs stay as they were.
  if (params.aovs) line("aovs", "1");
  line("hair", std::string(params.hair_sampling.four_numbers ? "four-numbers" : "demux") +
                   (params.hair_sampling.per_hit ? " per-hit" : "") +
                   (params.hair_sampling.mixture_weight ? " mixture-weight" : "") +
                   (params.hair_sampling.fast_pow ? " fast-pow" : ""));
  line("curves", options.curves + (options.curves == "lines"
                                        ? " " + std::to_string(options.segments) : "") +
                     (options.flat_curves ? " flat" : " round") + " pieces " +
                     std::to_string(options.curve_pieces));
  // Of Embree's configuration, only the instruction set changes a bit.
  line("isa", embree_isa(options.embree_config));
  line("bvh", options.bvh_quality + (options.no_flatten ? " instances" : " flatten") +
                  (options.bvh_compact ? " compact" : ""));
  return text;
}

// A:B from --sample-range: the part's samples A ... B - 1 of `samples`.
static bool parse_sample_range(
    const std::string& text, int samples, int& first, int& end, std::string& error) {
  auto colon = text.find(':');
  auto parse = [](const std::string& digits, int& value) {
    auto result = std::from_chars(digits.data(), digits.data() + digits.size(), value);
    return !digits.empty() && result.ec == std::errc{} &&
           result.ptr == digits.data() + digits.size();
  };
  if (colon == std::string::npos || !parse(text.substr(0, colon), first) ||
      !parse(text.substr(colon + 1), end)) {
    error = "--sample-range " + text + ": expected A:B, two whole numbers";
    return false;
  }
  if (first < 0 || end <= first || end > samples) {
    error = "--sample-range " + text + ": expected 0 <= A < B <= " + std::to_string(samples) +
            " (the render's samples)";
    return false;
  }
  return true;
}

static int run_render(const render_options& options, trace_params params,
    const CLI::App& command) {
  auto is_part = !options.sample_range.empty();
  if (is_part && path_extension(options.output) != ".exr")
    return print_error(options.output + ": a render part (--sample-range) is an OpenEXR "
                                        "image: use a name ending in .exr");
  if (is_part && (options.checkpoints || options.time_budget > 0 || options.embree_only))
    return print_error(
        "--sample-range renders one part: --checkpoints, --time-budget and --embree-only "
        "do not apply");
  if (!is_image_filename(options.output))
    return print_error(options.output + ": unknown image extension (use exr, hdr, pfm, png or jpg)");
  if (params.aovs && path_extension(options.output) != ".exr")
    return print_error(options.output + ": --aovs writes the AOVs as layers of an OpenEXR "
                                        "image: use a name ending in .exr");
  if (params.aovs && options.embree_only)
    return print_error("--embree-only casts rays alone: --aovs does not apply");
  // Ctrl-C from here on ends the render after its current pass (after the
  // first, if it comes while loading) and saves the samples done.
  interrupted   = false;
  auto previous = std::signal(SIGINT, handle_sigint);
  auto start    = std::chrono::steady_clock::now();
  auto scene    = scene_data{};
  auto error = std::string{};
  if (!load_any_scene(options.scene, scene, error, {})) return print_error(error);
  if (!make_output_directory(options.output, error)) return print_error(error);
  add_missing_camera(scene);
  if (options.curves == "lines") {
    for (auto& shape : scene.shapes)
      if (!shape.curves.empty()) shape = curves_to_lines(shape, options.segments);
  }
  // Settings carried by the scene file are defaults the command line overrides.
  if (scene.settings.samples > 0 && command.count("--samples") == 0)
    params.samples = scene.settings.samples;
  if (scene.settings.bounces > 0 && command.count("--bounces") == 0)
    params.bounces = scene.settings.bounces;
  if (scene.settings.resolution > 0 && command.count("--resolution") == 0)
    params.resolution = scene.settings.resolution;
  if (!options.camera.empty()) {
    auto found = std::find(scene.camera_names.begin(), scene.camera_names.end(), options.camera);
    if (found == scene.camera_names.end())
      return print_error(options.scene + ": no camera named " + options.camera);
    params.camera = (int)(found - scene.camera_names.begin());
  }
  if (!check_trace_params(scene, params, error)) return print_error(options.scene + ": " + error);
  // The samples to render: all, or the part's range.
  auto first = 0, end = params.samples;
  if (is_part && !parse_sample_range(options.sample_range, params.samples, first, end, error))
    return print_error(error);
  auto count = end - first;
  // The image buffers, before they are allocated.
  auto size = camera_resolution(scene.cameras[params.camera], params.resolution);
  auto from = command.count("--resolution") ? std::string(" (--resolution)")
                                            : std::string(" (the scene's settings)");
  if (!check_load_memory(options.scene,
          "a render at resolution " + std::to_string(params.resolution) + from + ", " +
              std::to_string(size.x) + "x" + std::to_string(size.y) + " pixels,",
          trace_image_bytes(scene, params), error))
    return print_error(error);
  if (!check_render_output(options, params, error)) return print_error(error);
  auto load_time = seconds_since(start);

  auto bvh        = scene_bvh{};
  auto bvh_params_ = bvh_params{};
  bvh_params_.flat_curves = options.flat_curves;
  bvh_params_.flatten     = !options.no_flatten;
  bvh_params_.quality     = enum_from_name<bvh_quality_type>(bvh_quality_names,
      options.bvh_quality);
  bvh_params_.embree_config = options.embree_config;
  bvh_params_.compact       = options.bvh_compact;
  bvh_params_.max_curve_pieces = options.curve_pieces;
  if (!make_scene_bvh(bvh, scene, bvh_params_, error))
    return print_error(options.scene + ": " + error);
  auto context = make_trace_context(scene, params);
  if (options.embree_only) return run_raycast(options, scene, bvh, context, params);
  auto state  = trace_state{};
  init_trace_state(state, scene, params, first);
  if (!options.quiet)
    std::fprintf(stderr, "loaded %s in %.2fs, bvh in %.2fs (%s bytes); rendering %dx%d\n",
        options.scene.c_str(), load_time, bvh.build_seconds,
        format_count((double)bvh.peak_memory).c_str(), state.width, state.height);

  // Passes of samples: Ctrl-C ends the current pass and saves. A pass ends
  // on a power of two (the checkpoints and the time budget stop there) and
  // takes up to about two seconds at the speed of the passes so far. A
  // pixel's samples in a row find its fibres and BVH nodes still in the
  // cache: 2.5-10% less CPU on the peers' hair balls at 64 spp than one
  // sample per pixel per pass (6% with one thread). Each sample is the same
  // whatever the pass.
  auto render_start   = std::chrono::steady_clock::now();
  auto render_cpu     = cpu_seconds();
  auto last_progress  = -1.0;
  while (state.samples < count && (state.samples == 0 || !interrupted)) {
    auto pass = 1;
    if (state.samples > 0) {
      auto per_sample = seconds_since(render_start) / state.samples;
      auto aligned    = state.samples & -state.samples;  // the next power of two stays a step
      while (pass * 2 <= aligned && pass * 2 * per_sample <= 2.0) pass *= 2;
    }
    trace_samples(state, scene, bvh, context, params, std::min(pass, count - state.samples));
    auto elapsed = seconds_since(render_start);
    if (options.checkpoints && is_power_of_two(state.samples)) {
      // Saving is not rendering: its time is left out of the figures.
      auto save_start = std::chrono::steady_clock::now();
      auto filename   = checkpoint_filename(options.output, state.samples);
      auto saved = params.aovs
                       ? save_image_layers(filename, get_image(state),
                             get_aov_layers(state.width, state.height, state.aov_sums,
                                 state.samples),
                             error)
                       : save_image(filename, get_image(state), error, options.exposure);
      if (!saved) return print_error(error);
      std::printf("checkpoint spp=%d seconds=%.6f cpu_seconds=%.6f rays=%lld file=%s\n",
          state.samples, elapsed, cpu_seconds() - render_cpu, (long long)state.rays.load(),
          filename.c_str());
      std::fflush(stdout);
      render_start += std::chrono::steady_clock::now() - save_start;
    }
    if (options.time_budget > 0 && elapsed >= options.time_budget &&
        is_power_of_two(state.samples))
      break;
    if (!options.quiet && (elapsed - last_progress > 0.25 || state.samples == count)) {
      last_progress = elapsed;
      auto fraction = (double)state.samples / count;
      auto eta      = elapsed / fraction - elapsed;
      auto bar      = std::string(30, ' ');
      for (auto i = 0; i < (int)(fraction * 30); i++) bar[i] = '#';
      std::fprintf(stderr, "\r[%s] %d/%d spp  elapsed %s  eta %s ", bar.c_str(),
          state.samples, count, format_duration(elapsed).c_str(),
          format_duration(eta).c_str());
    }
  }
  std::signal(SIGINT, previous);
  auto render_time = seconds_since(render_start);
  render_cpu       = cpu_seconds() - render_cpu;
  if (!options.quiet) std::fprintf(stderr, "\n");
  if (interrupted)
    std::fprintf(stderr, "interrupted: saving the %d samples per pixel done\n", state.samples);
  if (state.nonfinite > 0)
    std::fprintf(stderr, "warning: %lld NaN or Inf samples were dropped\n",
        (long long)state.nonfinite.load());

  // A part keeps the exact sums of the samples done (all of its range,
  // unless interrupted: a merge then reports the gap).
  auto part = render_part{};
  if (is_part) {
    part.settings  = render_settings(scene, params, options, state);
    part.samples   = params.samples;
    part.first     = first;
    part.count     = state.samples;
    part.width     = state.width;
    part.height    = state.height;
    part.rays      = state.rays;
    part.nonfinite = state.nonfinite;
    part.sums      = std::move(state.sums);
    part.extra     = params.aovs ? trace_aov_sums : 0;
    part.extra_sums = std::move(state.aov_sums);
  }
  auto image  = is_part ? texture_data{} : get_image(state);
  auto layers = is_part || !params.aovs
                    ? std::vector<image_layer>{}
                    : get_aov_layers(state.width, state.height, state.aov_sums, state.samples);
  auto save   = [&](const std::string& filename, std::string& error, bool replace) {
    if (is_part) return save_render_part(filename, part, error, replace);
    if (params.aovs) return save_image_layers(filename, image, layers, error, replace);
    return save_image(filename, image, error, options.exposure, replace);
  };
  if (!save(options.output, error, true)) {
    // The output was checked before the render, yet the write failed (the
    // disk filled up, say): the samples are worth keeping.
    auto rescued     = std::string{};
    auto save_rescue = [&](const std::string& filename, std::string& error) {
      return is_part || params.aovs ? save(filename, error, false)
                                    : save_image(filename, image, error, 0, false);
    };
    if (save_rescued_render(options.output, save_rescue, rescued))
      return print_error(error + "; the render was saved to " + rescued);
    return print_error(error + "; the render could not be saved elsewhere either");
  }
  auto samples = (double)state.width * state.height * state.samples;
  auto what    = is_part ? "part " + options.output + " (samples " + std::to_string(first) + ":" +
                            std::to_string(first + state.samples) + " of " +
                            std::to_string(params.samples) + ")"
                         : options.output;
  if (!options.quiet) {
    std::printf(
        "rendered %s: %dx%d, %d spp in %.2fs (%s samples/s, %s rays/s, peak memory %s bytes)\n",
        what.c_str(), state.width, state.height, state.samples, render_time,
        format_count(samples / render_time).c_str(),
        format_count((double)state.rays / render_time).c_str(),
        format_count((double)peak_memory()).c_str());
    // Clamping biases the image: say by how much.
    if (params.clamp > 0)
      std::printf("clamp %g: %lld of %s samples clamped, removing %.3g%% of their energy "
                  "(--clamp 0 for none)\n",
          params.clamp, (long long)state.clamped.load(), format_count(samples).c_str(),
          100 * clamped_energy_fraction(state));
  }
  if (options.stats) {
    auto segments = (size_t)0;
    for (auto& shape : scene.shapes) segments += shape.lines.size() + shape.curves.size();
    std::printf("stats load_seconds=%.6f bvh_seconds=%.6f bvh_bytes=%lld segments=%zu "
                "width=%d height=%d spp=%d render_seconds=%.6f render_cpu=%.6f rays=%lld "
                "peak_memory=%lld clamped=%lld clamped_energy=%.6g roulette_threshold=%.6g\n",
        load_time, bvh.build_seconds, (long long)bvh.peak_memory, segments, state.width,
        state.height, state.samples, render_time, render_cpu, (long long)state.rays.load(),
        (long long)peak_memory(), (long long)state.clamped.load(),
        clamped_energy_fraction(state), state.roulette_threshold);
  }
  return 0;
}

// -----------------------------------------------------------------------------
// MERGE
// -----------------------------------------------------------------------------

struct merge_options {
  std::vector<std::string> parts    = {};
  std::string              output   = "";
  float                    exposure = 0;
  bool                     part     = false;  // write a part (the union), not an image
  bool                     quiet    = false;
};

// The first setting (a "key=value" line) in which a and b differ: a's line
// and b's line with that key, "(no KEY)" where one lacks it.
static std::pair<std::string, std::string> first_difference(
    const std::string& a, const std::string& b) {
  auto lines = [](const std::string& text) {
    auto result = std::vector<std::pair<std::string, std::string>>{};  // key, line
    auto stream = std::istringstream(text);
    for (auto line = std::string{}; std::getline(stream, line);)
      result.push_back({line.substr(0, line.find('=')), line});
    return result;
  };
  auto lines_a = lines(a), lines_b = lines(b);
  auto find    = [](const auto& lines, const std::string& key) {
    for (auto& [other, line] : lines)
      if (other == key) return line;
    return "(no " + key + ")";
  };
  for (auto& [key, line] : lines_a)
    if (auto other = find(lines_b, key); other != line) return {line, other};
  for (auto& [key, line] : lines_b)
    if (auto other = find(lines_a, key); other != line) return {other, line};
  return {"", ""};
}

// Adds up parts of one render: they must share the scene and settings and
// cover [0, N) once (for an image) or one range without gaps (for a part).
// The sums are exact, so the image has the bits of a render on one machine.
static int run_merge(const merge_options& options) {
  auto& output = options.output;
  if (options.part && path_extension(output) != ".exr")
    return print_error(output + ": a render part is an OpenEXR image: use a name ending in .exr");
  if (!options.part && !is_image_filename(output))
    return print_error(output + ": unknown image extension (use exr, hdr, pfm, png or jpg)");
  struct part_range {
    std::string filename = "";
    int         first = 0, end = 0;
  };
  auto ranges = std::vector<part_range>{};
  auto merged = render_part{};
  auto error  = std::string{};
  auto range_text = [](int first, int end) {
    return std::to_string(first) + ":" + std::to_string(end);
  };
  for (auto& filename : options.parts) {
    auto part = render_part{};
    if (!load_render_part(filename, part, error)) return print_error(error);
    if (ranges.empty()) {
      // Fail before the work if the output cannot be written.
      auto pixel_bytes = options.part ? render_part_pixel_bytes + part.extra * render_part_extra_bytes
                                      : 12 + (part.extra > 0 ? 23 * 4 : 0);
      auto bytes       = (double)part.width * part.height * pixel_bytes + 65536;
      if (!check_output_file(output, bytes, error)) return print_error(error);
      merged.settings = part.settings;
      merged.samples  = part.samples;
      merged.width    = part.width;
      merged.height   = part.height;
      merged.sums.assign(part.sums.size(), fixed_sum3{});
      merged.extra = part.extra;
      merged.extra_sums.assign(part.extra_sums.size(), fixed_sum3{});
    }
    auto& reference = ranges.empty() ? filename : ranges.front().filename;
    if (part.samples != merged.samples)
      return print_error(filename + ": a part of a " + std::to_string(part.samples) +
                         "-sample render, but " + reference + " is of a " +
                         std::to_string(merged.samples) + "-sample one");
    if (part.settings != merged.settings) {
      auto [here, there] = first_difference(part.settings, merged.settings);
      auto hint = here.rfind("isa=", 0) == 0
                      ? "; machines with different CPUs agree when every part gets the same "
                        "--embree-config max_isa=NAME"
                  : here.rfind("renderer=", 0) == 0
                      ? "; render every part with one build of yscene"
                      : "";
      return print_error(filename + ": not a part of the render of " + reference + ": " + here +
                         " here, " + there + " there (parts of one render share the scene "
                         "and every setting" + hint + ")");
    }
    if (part.width != merged.width || part.height != merged.height ||
        part.sums.size() != merged.sums.size())
      return print_error(filename + ": " + std::to_string(part.width) + "x" +
                         std::to_string(part.height) + " pixels, but " + reference + " has " +
                         std::to_string(merged.width) + "x" + std::to_string(merged.height));
    // The settings say whether a render has AOVs; a part that lacks them
    // where its settings say it has them is damaged or not ours.
    if (part.extra != merged.extra || part.extra_sums.size() != merged.extra_sums.size())
      return print_error(filename + ": " + std::to_string(part.extra) +
                         " extra sums a pixel, but " + reference + " has " +
                         std::to_string(merged.extra));
    for (size_t i = 0; i < part.sums.size(); i++) add_fixed(merged.sums[i], part.sums[i]);
    for (size_t i = 0; i < part.extra_sums.size(); i++)
      add_fixed(merged.extra_sums[i], part.extra_sums[i]);
    merged.rays += part.rays;
    merged.nonfinite += part.nonfinite;
    ranges.push_back({filename, part.first, part.first + part.count});
  }
  // Each sample once: sorted by range, neighbours neither overlap nor leave
  // a gap; an image needs all of [0, N).
  std::stable_sort(ranges.begin(), ranges.end(),
      [](const part_range& a, const part_range& b) { return a.first < b.first; });
  for (size_t i = 1; i < ranges.size(); i++) {
    auto &before = ranges[i - 1], &after = ranges[i];
    if (after.first < before.end)
      return print_error(after.filename + ": samples " + range_text(after.first, after.end) +
                         " overlap those of " + before.filename + " (" +
                         range_text(before.first, before.end) + ")");
    if (after.first > before.end)
      return print_error("samples " + range_text(before.end, after.first) +
                         " are in no part: a gap between " + before.filename + " (" +
                         range_text(before.first, before.end) + ") and " + after.filename +
                         " (" + range_text(after.first, after.end) + ")");
  }
  auto first = ranges.front().first, end = ranges.back().end;
  if (!options.part && first > 0)
    return print_error("samples " + range_text(0, first) + " of " +
                       std::to_string(merged.samples) + " are in no part (the first, " +
                       ranges.front().filename + ", starts at " + std::to_string(first) + ")");
  if (!options.part && end < merged.samples)
    return print_error("samples " + range_text(end, merged.samples) + " of " +
                       std::to_string(merged.samples) + " are in no part (the last, " +
                       ranges.back().filename + ", ends at " + std::to_string(end) + ")");
  merged.first = first;
  merged.count = end - first;
  if (!make_output_directory(output, error)) return print_error(error);
  auto aovs = merged.extra == trace_aov_sums;
  if (merged.extra > 0 && !aovs)
    return print_error(ranges.front().filename + ": " + std::to_string(merged.extra) +
                       " extra sums a pixel, not the " + std::to_string(trace_aov_sums) +
                       " of the AOVs of this yscene");
  if (aovs && !options.part && path_extension(output) != ".exr")
    std::fprintf(stderr, "warning: %s keeps the beauty alone: the parts' AOVs are saved as "
                         "layers of an .exr output\n", output.c_str());
  auto image = options.part ? texture_data{}
                            : get_image(merged.width, merged.height, merged.sums,
                                  merged.samples);
  auto saved = options.part ? save_render_part(output, merged, error)
               : aovs && path_extension(output) == ".exr"
                   ? save_image_layers(output, image,
                         get_aov_layers(merged.width, merged.height, merged.extra_sums,
                             merged.samples),
                         error)
                   : save_image(output, image, error, options.exposure);
  if (!saved) return print_error(error);
  if (merged.nonfinite > 0)
    std::fprintf(stderr, "warning: %lld NaN or Inf samples were dropped\n",
        (long long)merged.nonfinite);
  if (!options.quiet)
    std::printf("merged %zu parts into %s: %dx%d, samples %s of %d (%s rays)\n",
        ranges.size(), output.c_str(), merged.width, merged.height,
        range_text(first, end).c_str(), merged.samples, format_count((double)merged.rays).c_str());
  return 0;
}

// -----------------------------------------------------------------------------
// INFO
// -----------------------------------------------------------------------------

// What `info` says about a scene: the counts, and every camera, material
// (with the values the renderer uses), environment and light, as text or
// as json.
struct info_options {
  std::string scene = "";
  bool        json  = false;
};

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

static int run_info(const info_options& options) {
  auto& filename = options.scene;
  auto  scene    = scene_data{};
  auto  error    = std::string{};
  if (!load_any_scene(filename, scene, error, {})) return print_error(error);
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

// -----------------------------------------------------------------------------
// CONVERT
// -----------------------------------------------------------------------------

static int run_convert(const std::string& input, const std::string& output,
    const pbrt_params& params, bool quiet) {
  if (path_extension(output) != ".json")
    return print_error(output + ": the output must be a .json scene");
  auto scene = scene_data{};
  auto error = std::string{};
  auto start = std::chrono::steady_clock::now();
  if (!load_any_scene(input, scene, error, params)) return print_error(error);
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

// -----------------------------------------------------------------------------
// HAIR GENERATOR
// -----------------------------------------------------------------------------

struct hair_options {
  std::string output       = "";
  std::string style        = "straight";
  std::string fit_camera   = "";     // scene whose first camera places the strands
  float       fit_fraction = 0.75f;  // of the image the strands span
  float       fit_distance = 0;      // 0: where the camera sees them now
  bool        quiet        = false;  // nothing printed on success
};

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

// Offset of pbrt's WorldBegin in a scene's text (comments and strings
// skipped), or npos.
static size_t find_world_begin(const std::string& text) {
  for (auto i = (size_t)0; i < text.size(); i++) {
    if (text[i] == '#') {
      while (i < text.size() && text[i] != '\n') i++;
    } else if (text[i] == '"') {
      i++;
      while (i < text.size() && text[i] != '"') i++;
    } else if (text.compare(i, 10, "WorldBegin") == 0 &&
               (i == 0 || std::isspace((unsigned char)text[i - 1]))) {
      return i;
    }
  }
  return std::string::npos;
}

// The first camera of a scene. For a plain .pbrt file only the part before
// WorldBegin is read (through a temporary copy), so the camera of a scene
// whose world includes are missing, the stand-ins' use case, still loads.
static bool load_first_camera(const std::string& filename, camera_data& camera,
    std::string& error) {
  auto scene = scene_data{};
  if (path_extension(filename) == ".pbrt") {
    auto text = std::string{};
    if (!load_text(filename, text, error)) return false;
    auto world = find_world_begin(text);
    if (world == std::string::npos) return error = filename + ": no WorldBegin", false;
    // The copy goes to a private folder (mode 0700, unpredictable name) of
    // the system's temporary folder: no other user can plant a link there.
    auto folder = (std::filesystem::temp_directory_path() / "yscene-XXXXXX").string();
    if (!mkdtemp(folder.data()))
      return error = folder + ": cannot create a temporary folder", false;
    auto temporary = folder + "/camera.pbrt";
    auto ok = save_text(temporary, text.substr(0, world) + "WorldBegin\n", error);
    auto warnings = std::vector<std::string>{};
    auto params        = pbrt_params{};
    params.allow_empty = true;  // the world is cut off: a camera alone
    if (ok) ok = load_pbrt_scene(temporary, scene, error, params, &warnings);
    std::remove(temporary.c_str());
    rmdir(folder.c_str());
    // Messages name the user's file, not the temporary copy; warnings (e.g.
    // an unsupported camera type) go to stderr, as convert's do.
    auto rename = [&](std::string message) {
      auto at = message.find(temporary);
      if (at != std::string::npos) message.replace(at, temporary.size(), filename);
      return message;
    };
    for (auto& warning : warnings)
      std::fprintf(stderr, "warning: %s\n", rename(warning).c_str());
    if (!ok) return error = rename(error), false;
  } else if (!load_any_scene(filename, scene, error, {})) {
    return false;
  }
  if (scene.cameras.empty()) return error = filename + ": no camera", false;
  camera = scene.cameras[0];
  return true;
}

static int run_hair(const hair_options& options, hair_style_params params,
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

// -----------------------------------------------------------------------------
// MAIN
// -----------------------------------------------------------------------------

static int run_main(int argc, const char** argv) {
  auto app = CLI::App{"yscene: render, inspect and convert hair scenes"};
  app.require_subcommand(1);

  auto render_opts = render_options{};
  auto params      = trace_params{};
  auto sampler     = std::string{"path"};
  auto lights      = std::string{"automatic"};
  auto sequence    = std::string{"sobol"};
  auto render      = app.add_subcommand("render", "render a scene to an image");
  render->add_option("scene", render_opts.scene,
      "scene: json (Yocto/GL), pbrt or pbrt.gz (pbrt-v3/v4), or hair (Cem Yuksel's strands "
      "under a default sky and camera)")->required();
  render->add_option("--output,-o", render_opts.output, "output image (exr, hdr, pfm, png, jpg)")
      ->required();
  render->add_option("--samples,-s", params.samples, "samples per pixel");
  render->add_option("--resolution,-r", params.resolution, "largest image side in pixels");
  render->add_option("--sampler", sampler, "path (MIS) or naive (BSDF sampling only)")
      ->check(CLI::IsMember(trace_sampler_names));
  render->add_option("--lights", lights,
          "lights sampled by path: automatic (those BSDF sampling does not find as well) or all")
      ->check(CLI::IsMember(trace_lights_names));
  render->add_option("--sequence", sequence,
          "random numbers of a pixel: sobol (Owen-scrambled) or independent")
      ->check(CLI::IsMember(sequence_names));
  render->add_option("--sobol-bounces", params.sobol_bounces,
          "bounces drawing Sobol numbers (independent numbers after them)")
      ->check(CLI::NonNegativeNumber);
  render->add_option("--roulette-bounce", params.roulette_bounce,
          "first bounce where Russian roulette may end a path that lost energy")
      ->check(CLI::NonNegativeNumber);
  render->add_option("--roulette-threshold", params.roulette_threshold,
          "paths whose throughput falls below this play Russian roulette");
  render->add_option("--split", params.split,
          "paths per camera ray, sharing its first hit");
  render->add_option("--shadow-threshold", params.shadow_threshold,
          "light samples that would add less than this play a roulette for their shadow ray")
      ->check(CLI::NonNegativeNumber);
  render->add_option("--bounces,-b", params.bounces, "maximum scattering events per path (pbrt's maxdepth)");
  render->add_option("--threads,-t", params.threads, "threads (0 = all cores)");
  render->add_option("--seed", params.seed, "random seed");
  render->add_option("--clamp", params.clamp,
      "scale samples down to this largest component (0 = off, the default): fewer "
      "fireflies, a darker (biased) image; the summary says how much it removed");
  render->add_option("--exposure,-e", render_opts.exposure, "exposure for png/jpg (stops)");
  render->add_option("--camera", render_opts.camera, "camera name");
  render->add_flag("--flat-curves", render_opts.flat_curves, "ray-facing flat fibers");
  render->add_flag("--hair-four-numbers", params.hair_sampling.four_numbers,
      "sample hair with four random numbers instead of demuxing two");
  render->add_flag("--quiet,-q", render_opts.quiet,
      "print nothing on success (no progress, no summary; errors and warnings still go to "
      "stderr, --stats and --checkpoints lines to stdout)");
  render->add_option("--curves", render_opts.curves,
          "native Bezier curves, or line segments tessellated after loading")
      ->check(CLI::IsMember({"native", "lines"}));
  render->add_option("--segments", render_opts.segments, "line segments per curve with --curves lines")
      ->check(CLI::Range(1, 64));
  render->add_flag("--hair-per-hit", params.hair_sampling.per_hit,
      "compute the hair material terms at every hit (as the thesis), not once per material");
  render->add_flag("--hair-mixture-weight", params.hair_sampling.mixture_weight,
      "weigh sampled hair directions by eval / pdf of the lobe mixture even where no MIS needs "
      "the pdf (by default the sampled lobe's own weight, which skips the evaluation)");
  render->add_flag("--hair-fast-pow", params.hair_sampling.fast_pow,
      "hair roughness powers by repeated squaring instead of std::pow (matters with --hair-per-hit)");
  render->add_flag("--no-flatten", render_opts.no_flatten,
      "keep every instance an Embree instance (no single-level BVH for identity frames)");
  render->add_flag("--checkpoints", render_opts.checkpoints,
      "also save OUTPUT-NNNNNspp.EXT at 1, 2, 4, ... spp and print a line for each");
  render->add_option("--time-budget", render_opts.time_budget,
          "stop at the first power-of-two spp reached after this many seconds")
      ->check(CLI::NonNegativeNumber);
  render->add_option("--bvh-quality", render_opts.bvh_quality, "Embree build quality")
      ->check(CLI::IsMember({"low", "medium", "high"}));
  render->add_option("--embree-config", render_opts.embree_config,
      "Embree device configuration (e.g. verbose=2 prints the BVH Embree builds)");
  render->add_option("--curve-pieces", render_opts.curve_pieces,
          "give Embree bent Bezier segments as up to this many exact pieces (1: never)")
      ->check(CLI::Range(1, 4));
  render->add_flag("--bvh-compact", render_opts.bvh_compact,
      "Embree's compact BVH layout (less memory, slower)");
  render->add_flag("--stats", render_opts.stats, "print a machine-readable line of figures");
  render->add_flag("--aovs", params.aovs,
      "also write albedo, normal, tangent, depth, coverage and hair lobe layers (exr)");
  render->add_option("--sample-range", render_opts.sample_range,
      "A:B: render only samples A ... B-1 of the --samples render and write them as a part "
      "(.exr) for yscene merge");
  render->add_flag("--embree-only", render_opts.embree_only,
      "render, then cast the same rays through Embree alone and compare rays/s "
      "(no image is written; use few samples: every ray is kept in memory)");

  // Every command that loads a scene takes the memory limit of the load.
  auto max_memory     = std::string{};
  auto add_max_memory = [&](CLI::App* command) {
    command->add_option("--max-memory", max_memory,
        "memory a load may use: bytes or with a K, M or G suffix, e.g. 4G (default: 3/4 of "
        "physical memory, or of ulimit -v if lower)");
  };
  add_max_memory(render);

  auto info_opts = info_options{};
  auto info      = app.add_subcommand("info",
      "print a scene's statistics, cameras, materials (with the values rendered), "
      "environments and lights");
  info->add_option("scene", info_opts.scene, "scene (json, pbrt, pbrt.gz or hair)")->required();
  info->add_flag("--json", info_opts.json, "the same as json, for programs");
  add_max_memory(info);

  auto merge_opts = merge_options{};
  auto merge      = app.add_subcommand("merge",
      "add up the parts of a render made with --sample-range into its image (bit for bit the "
      "image of one render)");
  merge->add_option("parts", merge_opts.parts, "render parts (.exr), in any order")
      ->required();
  merge->add_option("--output,-o", merge_opts.output,
          "output image (exr, hdr, pfm, png, jpg), or a part (exr) with --part")
      ->required();
  merge->add_option("--exposure,-e", merge_opts.exposure, "exposure for png/jpg (stops)");
  merge->add_flag("--part", merge_opts.part,
      "write the merged parts as one part (their ranges must be contiguous), to merge later");
  merge->add_flag("--quiet,-q", merge_opts.quiet, "print nothing on success");
  add_max_memory(merge);

  auto convert_in = std::string{}, convert_out = std::string{}, curves_mode = std::string{"native"};
  auto pbrt       = pbrt_params{};
  auto convert_quiet = false;
  auto convert    = app.add_subcommand("convert",
      "convert a pbrt, hair or json scene to a json scene (shapes as ply, textures as exr)");
  convert->add_option("input", convert_in, "input scene: pbrt, pbrt.gz, hair or json")
      ->required();
  convert->add_option("output", convert_out, "output json scene")->required();
  convert->add_option("--curves", curves_mode, "native Bezier curves or line segments")
      ->check(CLI::IsMember({"native", "lines"}));
  convert->add_option("--segments", pbrt.segments, "line segments per curve")
      ->check(CLI::Range(1, 64));
  convert->add_flag("--lenient", pbrt.lenient, "unknown pbrt directives are warnings");
  convert->add_flag("--quiet,-q", convert_quiet, "print nothing on success");
  add_max_memory(convert);

  auto hair_opts     = hair_options{};
  auto hair_params   = hair_style_params{};
  auto hair = app.add_subcommand("hair", "generate a hair scene or stand-in hair geometry");
  hair->add_option("--style", hair_opts.style, "straight, curly, curls, block or fur")
      ->check(CLI::IsMember(hair_style_names));
  hair->add_option("--strands,-n", hair_params.strands, "number of strands")
      ->check(CLI::Range(1, 50000000));
  hair->add_option("--segments", hair_params.segments, "Bezier segments per strand (0: style default)")
      ->check(CLI::Range(0, 1000));
  hair->add_option("--radius", hair_params.radius, "root radius (0: style default)")
      ->check(CLI::NonNegativeNumber);
  hair->add_option("--seed", hair_params.seed, "random seed");
  hair->add_option("--output,-o", hair_opts.output,
          "json scene (with ply and sky), .pbrt, .pbrt.gz, .hair or .ply strands")
      ->required();
  hair->add_flag("--quiet,-q", hair_opts.quiet, "print nothing on success");
  hair->add_option("--fit-camera", hair_opts.fit_camera,
      "place the strands where this scene's first camera looks (pbrt: read up to WorldBegin)");
  add_max_memory(hair);
  hair->add_option("--fit-fraction", hair_opts.fit_fraction,
          "with --fit-camera: fraction of the image the strands span")
      ->check(CLI::Range(0.01f, 1.0f));
  hair->add_option("--fit-distance", hair_opts.fit_distance,
          "with --fit-camera: distance along the view axis (0: where the camera sees them)")
      ->check(CLI::NonNegativeNumber);
  // The material's parameters: one option per row of hair_parameters.
  auto hair_values = std::vector<std::vector<float>>(std::size(hair_parameters));
  for (auto k = 0; k < (int)std::size(hair_parameters); k++)
    add_hair_parameter_option(hair, hair_parameters[k], hair_values[k]);

  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    // Help exits 0; every command-line error exits 1 as other errors do.
    auto code = app.exit(e);
    return code == 0 ? 0 : 1;
  }
  if (!max_memory.empty() && !parse_memory_size(max_memory, load_memory_limit))
    return print_error("--max-memory " + max_memory +
                       ": expected a number of bytes, optionally with a K, M or G suffix (e.g. 4G)");

  if (render->parsed()) {
    params.sampler  = enum_from_name<trace_sampler_type>(trace_sampler_names, sampler);
    params.lights   = enum_from_name<trace_lights_type>(trace_lights_names, lights);
    params.sequence = enum_from_name<sequence_type>(sequence_names, sequence);
    return run_render(render_opts, params, *render);
  } else if (merge->parsed()) {
    return run_merge(merge_opts);
  } else if (info->parsed()) {
    return run_info(info_opts);
  } else if (hair->parsed()) {
    auto material = hair_material{};
    for (auto k = 0; k < (int)std::size(hair_parameters); k++) {
      auto& values = hair_values[k];
      if (values.empty()) continue;
      set_hair_parameter(material, hair_parameters[k],
          values.size() == 3 ? vec3f{values[0], values[1], values[2]} : vec3f{values[0]});
    }
    return run_hair(hair_opts, hair_params, material);
  } else if (convert->parsed()) {
    pbrt.curves_as_lines = curves_mode == "lines";
    return run_convert(convert_in, convert_out, pbrt, convert_quiet);
  }
  return 1;
}

// Whatever escapes (a huge scene's allocation) is one error line, not an
// abort. A command that fails leaves none of the folders it made.
int main(int argc, const char** argv) {
  install_signal_handlers();
  auto code = 1;
  try {
    code = run_main(argc, argv);
  } catch (const std::bad_alloc&) {
    code = print_error("out of memory");
  } catch (const std::exception& e) {
    code = print_error(e.what());
  }
  if (code == 0) keep_output_directories();
  else remove_output_directories();
  return code;
}
