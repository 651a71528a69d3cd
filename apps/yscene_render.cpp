//
// yscene render: a scene to an image, or to a part of one (--sample-range)
// for yscene merge.
//

#include <atomic>
#include <charconv>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <new>
#include <yocto/yocto_bvh.h>
#include <yocto/yocto_render.h>

#include "yocto_source_hash.h"  // generated from the sources: YOCTO_SOURCE_HASH
#include "yscene_cli.h"

using namespace yocto;

// -----------------------------------------------------------------------------
// RENDER
// -----------------------------------------------------------------------------

// HH:MM:SS, for the progress line.
static std::string format_duration(double seconds) {
  auto total = (int64_t)(seconds + 0.5);
  char buffer[64];
  std::snprintf(buffer, sizeof(buffer), "%02d:%02d:%02d", (int)(total / 3600),
      (int)((total / 60) % 60), (int)(total % 60));
  return buffer;
}

// The first Ctrl-C asks the render to stop after its pass; a second one,
// while that pass or loading still runs, ends the program as usual.
static std::atomic<bool> interrupted = false;
static void handle_sigint(int signal) {
  if (interrupted) return handle_fatal_signal(signal);
  interrupted = true;
}

// OUTPUT with "-NNNNNspp" before the extension.
static std::string checkpoint_filename(const std::string& output, int samples) {
  auto extension = path_extension(output);
  char suffix[32];
  std::snprintf(suffix, sizeof(suffix), "-%05dspp", samples);
  return output.substr(0, output.size() - extension.size()) + suffix + extension;
}

// The limit of the renderer's speed: renders the samples (timed), records the
// same rays again (the render is deterministic) and casts them through Embree
// alone (timed, median of three). Prints both rates and their ratio.
static int run_raycast(const render_options& options, const scene_data& scene,
    const scene_bvh& bvh, const trace_context& context, const trace_params& params) {
  auto state = trace_state{};
  init_trace_state(state, scene, params);
  auto start = std::chrono::steady_clock::now();
  auto cpu   = process_cpu_seconds();
  trace_samples(state, scene, bvh, context, params, params.samples);
  auto render_time = seconds_since(start), render_cpu = process_cpu_seconds() - cpu;
  auto render_rays = (double)state.rays;
  init_trace_state(state, scene, params);
  auto rays = record_trace_rays(state, scene, bvh, context, params, params.samples);
  if ((double)rays.size() != render_rays)
    return print_error("the recorded rays differ from the rendered ones");
  auto times = std::vector<double>{}, cpus = std::vector<double>{};
  auto hits  = (int64_t)0;
  for (auto run = 0; run < 3; run++) {
    auto run_start = std::chrono::steady_clock::now();
    auto run_cpu   = process_cpu_seconds();
    hits           = cast_trace_rays(bvh, rays, params.threads);
    times.push_back(seconds_since(run_start));
    cpus.push_back(process_cpu_seconds() - run_cpu);
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
  line("adaptive", trace_adaptive_names[(int)params.adaptive]);
  line("allocation", params.allocation ? "learned" : "off");
  // Only when off, so that the settings of default renders stay as they were.
  if (!params.roulette_cache) line("roulette_cache", "off");
  line("lobe_guide", number(params.lobe_guide));
  // Only when on, so that the settings of default renders stay as they were.
  if (params.roulette_control) line("roulette_control", "on");
  line("hair", std::string(params.hair_sampling.four_numbers ? "four-numbers" : "demux") +
                   (params.hair_sampling.per_hit ? " per-hit" : "") +
                   (params.hair_sampling.mixture_weight ? " mixture-weight" : "") +
                   (params.hair_sampling.fast_pow ? " fast-pow" : ""));
  line("curves", options.curves + (options.curves == "lines"
                                        ? " " + std::to_string(options.segments) : "") +
                     (options.flat_curves ? " flat" : " round") + " pieces " +
                     std::to_string(options.curve_pieces) +
                     (options.curve_pieces > 1 && options.curve_piece_threshold != 1
                             ? " over " + number(options.curve_piece_threshold)
                             : "") +
                     (options.straight_cones ? "" : " no-cones"));
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

// Loads, checks, builds the BVH, renders in passes (a render session) and saves.
static int render_scene(const render_options& options, trace_params params,
    const CLI::App& command) try {
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
  auto settings = render_session_params{};
  settings.scene            = options.scene;
  settings.camera           = options.camera;
  settings.samples_given    = command.count("--samples") > 0;
  settings.bounces_given    = command.count("--bounces") > 0;
  settings.resolution_given = command.count("--resolution") > 0;
  settings.line_segments    = options.curves == "lines" ? options.segments : 0;
  settings.bvh.flat_curves  = options.flat_curves;
  settings.bvh.flatten      = !options.no_flatten;
  settings.bvh.quality = enum_from_name<bvh_quality_type>(bvh_quality_names, options.bvh_quality);
  settings.bvh.embree_config    = options.embree_config;
  settings.bvh.compact          = options.bvh_compact;
  settings.bvh.max_curve_pieces = options.curve_pieces;
  settings.bvh.straight_cones   = options.straight_cones;
  settings.curve_pieces_given   = command.count("--curve-pieces") > 0;
  settings.max_memory           = memory_limit;
  auto session = render_session{};
  auto error   = std::string{};
  {
    // A USD stage is converted into a temporary folder as convert does (its
    // defaults), loaded from there, and the folder removed; messages name
    // the stage.
    auto usd = temporary_folder{};
    if (is_usd_file(options.scene)) {
      auto usd_options  = convert_options{};
      usd_options.quiet = options.quiet;
      auto child_failed = false;
      if (!convert_usd_stage(options.scene, usd_options, usd, error, child_failed))
        return child_failed ? 1 : print_error(error);
      settings.scene = path_join(usd.path, "scene.json");
    }
    auto loaded = load_render_session(session, settings, params, error);
    if (!usd.path.empty()) {
      for (auto at = error.find(settings.scene); at != std::string::npos;
           at     = error.find(settings.scene, at + options.scene.size()))
        error.replace(at, settings.scene.size(), options.scene);
      session.settings.scene = options.scene;
    }
    if (!loaded) return print_error(error);
  }
  // The samples to render: all, or the part's range (of the samples the
  // scene's settings may give).
  if (is_part) {
    if (!parse_sample_range(options.sample_range, session.params.samples, session.first,
            settings.end, error))
      return print_error(error);
    session.settings.first = session.first;
    session.settings.end   = settings.end;
    session.count          = settings.end - session.first;
  }
  if (!make_output_directory(options.output, error)) return print_error(error);
  if (!check_render_output(options, session.params, error)) return print_error(error);
  auto warnings = std::vector<std::string>{};
  auto built_ok = build_render_session(session, error, &warnings);
  for (auto& warning : warnings) std::fprintf(stderr, "warning: %s\n", warning.c_str());
  if (!built_ok) return print_error(error);
  auto& scene = session.scene;
  auto& state = session.state;
  params      = session.params;
  // What the BVH was built with, for the parts' settings.
  auto built                  = options;
  built.curve_pieces          = session.built.max_curve_pieces;
  built.curve_piece_threshold = session.built.curve_piece_threshold;
  built.bvh_compact           = session.built.compact;
  if (options.embree_only)
    return run_raycast(options, scene, session.bvh, session.context, params);
  if (!options.quiet)
    std::fprintf(stderr, "loaded %s in %.2fs, bvh in %.2fs (%s bytes); rendering %dx%d\n",
        options.scene.c_str(), session.load_seconds, session.bvh.build_seconds,
        format_count((double)session.bvh.peak_memory).c_str(), state.width, state.height);

  // Passes of samples: Ctrl-C ends the current pass and saves.
  auto last_progress = -1.0;
  auto count         = session.count;
  while (state.samples < count && (state.samples == 0 || !interrupted)) {
    render_session_pass(session);
    auto elapsed = session.seconds;
    if (options.checkpoints && is_power_of_two(state.samples)) {
      auto filename = checkpoint_filename(options.output, state.samples);
      auto layers   = get_aov_layers(state);
      if (!save_render_image(filename, get_image(state), layers, error, options.exposure))
        return print_error(error);
      std::printf("checkpoint spp=%d seconds=%.6f cpu_seconds=%.6f rays=%lld file=%s\n",
          state.samples, elapsed, session.cpu_seconds, (long long)state.rays.load(),
          filename.c_str());
      std::fflush(stdout);
    }
    if (is_render_session_done(session, options.time_budget)) break;
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
  auto render_time = session.seconds;
  if (!options.quiet) std::fprintf(stderr, "\n");
  if (interrupted)
    std::fprintf(stderr, "interrupted: saving the %d samples per pixel done\n", state.samples);
  if (state.nonfinite > 0)
    std::fprintf(stderr, "warning: %lld NaN or Inf samples were dropped\n",
        (long long)state.nonfinite.load());

  // A part keeps the exact sums of the samples done (all of its range,
  // unless interrupted: a merge then reports the gap).
  auto first = session.first;
  auto part  = render_part{};
  if (is_part) {
    part.settings  = render_settings(scene, params, built, state);
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
  auto layers = is_part ? std::vector<image_layer>{}
                        : get_aov_layers(state);  // none without --aovs
  auto save   = [&](const std::string& filename, std::string& error, bool replace) {
    if (is_part) return save_render_part(filename, part, error, replace);
    return save_render_image(filename, image, layers, error, options.exposure, replace);
  };
  if (!save(options.output, error, true)) {
    // The output was checked before the render, yet the write failed (the
    // disk filled up, say): the samples are worth keeping.
    auto rescued     = std::string{};
    auto save_rescue = [&](const std::string& filename, std::string& error) {
      return is_part ? save(filename, error, false)
                     : save_render_image(filename, image, layers, error, 0, false);
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
        format_count((double)process_peak_memory()).c_str());
    // Clamping biases the image: say by how much.
    if (params.clamp > 0)
      std::printf("clamp %g: %lld of %s samples clamped, removing %.3g%% of their energy "
                  "(--clamp 0 for none)\n",
          params.clamp, (long long)state.clamped.load(), format_count(samples).c_str(),
          100 * clamped_energy_fraction(state));
  }
  if (options.stats) std::printf("%s\n", format_render_stats(session).c_str());
  return 0;
} catch (const std::bad_alloc&) {
  // Past the budget's checks (the BVH's included), the system or ulimit -v
  // gave less: the scene is named, what a part wrote is a temporary.
  return print_error(allocation_error(options.scene, "its render (BVH, image buffers, threads)"));
}

CLI::App* add_render_command(CLI::App& app, render_command& command, std::string& max_memory) {
  auto& options  = command.options;
  auto& params   = command.params;
  auto& sampler  = command.sampler;
  auto& lights   = command.lights;
  auto& sequence = command.sequence;
  auto  render   = app.add_subcommand("render", "render a scene to an image");
  render->add_option("scene", options.scene,
      "scene: json (Yocto/GL), pbrt or pbrt.gz (pbrt-v3/v4), hair (Cem Yuksel's strands "
      "under a default sky and camera), or usd, usda, usdc, usdz (converted on the fly, as "
      "convert does)")->required();
  render->add_option("--output,-o", options.output, "output image (exr, hdr, pfm, png, jpg)")
      ->required();
  render->add_option("--samples,-s", params.samples, "samples per pixel");
  render->add_option("--resolution,-r", params.resolution, "largest image side in pixels");
  render->add_option("--sampler", sampler, "path (MIS) or naive (BSDF sampling only)")
      ->check(CLI::IsMember(trace_sampler_names));
  render->add_option("--lights", lights,
          "lights sampled by path: automatic (those BSDF sampling does not find as well) or all")
      ->check(CLI::IsMember(trace_lights_names));
  render->add_option("--sequence", sequence,
          "random numbers of a pixel: global-sobol (one Owen-scrambled Sobol point across "
          "32 dimensions, the default), sobol (Owen-scrambled Sobol pairs, each shuffled) or "
          "independent")
      ->check(CLI::IsMember(sequence_names));
  render->add_option("--sobol-bounces", params.sobol_bounces,
          "bounces drawing Sobol numbers (independent numbers after them)")
      ->check(CLI::NonNegativeNumber);
  render->add_option("--roulette-bounce", params.roulette_bounce,
          "first bounce where Russian roulette may end a path that lost energy")
      ->check(CLI::NonNegativeNumber);
  render->add_option("--roulette-threshold", params.roulette_threshold,
          "paths whose throughput falls below this play Russian roulette");
  render->add_flag_callback("--adaptive", [&params] { params.adaptive = trace_adaptive_type::on; },
      "adaptive sampling (the default): a pilot plans each pixel's paths per camera ray and "
      "paths per sample from its own variances and cost, at the cost of --samples samples "
      "a pixel (unbiased)");
  render->add_flag_callback("--no-adaptive",
      [&params] { params.adaptive = trace_adaptive_type::off; },
      "no adaptive sampling: every pixel one path a sample");
  render->add_option("--split", params.split,
          "paths per camera ray, sharing its first hit (0 = each pixel's own, from the "
          "adaptive pilot; 1 without adaptive sampling)")
      ->check(CLI::Range(0, 1024));
  render->add_flag("--allocation,!--no-allocation", params.allocation,
      "shadow rays per region of the scene from the visibility the pilot measured there "
      "(EARS/MARS: each light sample cast with the probability that maximises efficiency, "
      "the default), or the roulette of --shadow-threshold");
  render->add_flag("--roulette-cache,!--no-roulette-cache", params.roulette_cache,
      "Russian roulette by region and direction from the tails the pilot measured there "
      "(EARS: each path survives with the probability that maximises efficiency, the "
      "default), or the pilot's one threshold everywhere");
  render->add_flag("--roulette-control,!--no-roulette-control", params.roulette_control,
      "an ended path adds the mean its tail was expected to bring, as the roulette cache "
      "learned it, and a surviving one the difference (a control variate: unbiased, less "
      "noise for the rays, but a dark pixel may be slightly negative at low sample counts), "
      "or ended paths add nothing (the default)");
  render->add_option("--lobe-guide", params.lobe_guide,
          "share of a hair lobe's choice made by what the roulette cache expects its "
          "direction to be worth per unit cost (0 = by the lobes' luminance alone; at most "
          "0.95, so that every lobe keeps a chance)")
      ->check(CLI::Range(0.0f, 0.95f));
  render->add_option("--shadow-threshold", params.shadow_threshold,
          "light samples that would add less than this play a roulette for their shadow ray")
      ->check(CLI::NonNegativeNumber);
  render->add_option("--bounces,-b", params.bounces, "maximum scattering events per path (pbrt's maxdepth)");
  render->add_option("--threads,-t", params.threads, "threads (0 = all cores)");
  render->add_option("--seed", params.seed, "random seed");
  render->add_option("--clamp", params.clamp,
      "scale samples down to this largest component (0 = off, the default): fewer "
      "fireflies, a darker (biased) image; the summary says how much it removed");
  render->add_option("--exposure,-e", options.exposure, "exposure for png/jpg (stops)");
  render->add_option("--camera", options.camera, "camera name");
  render->add_flag("--flat-curves", options.flat_curves, "ray-facing flat fibers");
  render->add_flag("--hair-four-numbers,!--hair-demux", params.hair_sampling.four_numbers,
      "sample hair with four random numbers (the default), or with two demuxed into four");
  render->add_flag("--quiet,-q", options.quiet,
      "print nothing on success (no progress, no summary; errors and warnings still go to "
      "stderr, --stats and --checkpoints lines to stdout)");
  render->add_option("--curves", options.curves,
          "native Bezier curves, or line segments tessellated after loading")
      ->check(CLI::IsMember({"native", "lines"}));
  render->add_option("--segments", options.segments, "line segments per curve with --curves lines")
      ->check(CLI::Range(1, 64));
  render->add_flag("--hair-per-hit", params.hair_sampling.per_hit,
      "compute the hair material terms at every hit (as the thesis), not once per material");
  render->add_flag("--hair-mixture-weight", params.hair_sampling.mixture_weight,
      "weigh sampled hair directions by eval / pdf of the lobe mixture even where no MIS needs "
      "the pdf (by default the sampled lobe's own weight, which skips the evaluation)");
  render->add_flag("--hair-fast-pow", params.hair_sampling.fast_pow,
      "hair roughness powers by repeated squaring instead of std::pow (matters with --hair-per-hit)");
  render->add_flag("--no-flatten", options.no_flatten,
      "keep every instance an Embree instance (no single-level BVH for identity frames)");
  render->add_flag("--checkpoints", options.checkpoints,
      "also save OUTPUT-NNNNNspp.EXT at 1, 2, 4, ... spp and print a line for each");
  render->add_option("--time-budget", options.time_budget,
          "stop at the first power-of-two spp reached after this many seconds")
      ->check(CLI::NonNegativeNumber);
  render->add_option("--bvh-quality", options.bvh_quality, "Embree build quality")
      ->check(CLI::IsMember({"low", "medium", "high"}));
  render->add_option("--embree-config", options.embree_config,
      "Embree device configuration (e.g. verbose=2 prints the BVH Embree builds)");
  render->add_option("--curve-pieces", options.curve_pieces,
          "give Embree bent Bezier segments as up to this many exact pieces (1: never)")
      ->check(CLI::Range(1, 4));
  render->add_flag("--straight-cones,!--no-straight-cones", options.straight_cones,
      "give Embree straight Bezier segments (along a line, radius affine along it) as the "
      "truncated cones they are, intersected in closed form (the default), or as curves");
  render->add_flag("--bvh-compact", options.bvh_compact,
      "Embree's compact BVH layout (less memory, slower)");
  render->add_flag("--stats", options.stats, "print a machine-readable line of figures");
  render->add_flag("--aovs", params.aovs,
      "also write albedo, normal, tangent, depth, coverage and hair lobe layers (exr)");
  render->add_option("--sample-range", options.sample_range,
      "A:B: render only samples A ... B-1 of the --samples render and write them as a part "
      "(.exr) for yscene merge");
  render->add_flag("--embree-only", options.embree_only,
      "render, then cast the same rays through Embree alone and compare rays/s "
      "(no image is written; use few samples: every ray is kept in memory)");
  add_max_memory_option(render, max_memory);
  return render;
}

int run_render(const render_command& command, const CLI::App& cli) {
  auto params     = command.params;
  params.sampler  = enum_from_name<trace_sampler_type>(trace_sampler_names, command.sampler);
  params.lights   = enum_from_name<trace_lights_type>(trace_lights_names, command.lights);
  params.sequence = enum_from_name<sequence_type>(sequence_names, command.sequence);
  return render_scene(command.options, params, cli);
}
