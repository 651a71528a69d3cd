//
// Implementation of Yocto/Render.
//

#include "yocto_render.h"

#include <sys/resource.h>

#include <algorithm>

#include "yocto_sceneio.h"

// -----------------------------------------------------------------------------
// PROCESS FIGURES
// -----------------------------------------------------------------------------
namespace yocto {

double process_cpu_seconds() {
  auto usage = rusage{};
  getrusage(RUSAGE_SELF, &usage);
  return usage.ru_utime.tv_sec + usage.ru_utime.tv_usec * 1e-6 + usage.ru_stime.tv_sec +
         usage.ru_stime.tv_usec * 1e-6;
}

int64_t process_peak_memory() {
  auto usage = rusage{};
  getrusage(RUSAGE_SELF, &usage);
  return (int64_t)usage.ru_maxrss * 1024;
}

bool is_power_of_two(int n) { return n > 0 && (n & (n - 1)) == 0; }

}  // namespace yocto

// -----------------------------------------------------------------------------
// RENDER SESSION
// -----------------------------------------------------------------------------
namespace yocto {

bool load_render_session(render_session& session, const render_session_params& settings,
    const trace_params& params, std::string& error) {
  auto start       = std::chrono::steady_clock::now();
  session.settings = settings;
  session.params   = params;
  auto& scene      = session.scene;
  auto  pbrt       = pbrt_params{};
  pbrt.max_memory  = settings.max_memory;
  if (!load_any_scene(settings.scene, scene, error, pbrt)) return false;
  add_missing_camera(scene);
  if (settings.line_segments > 0) {
    for (auto& shape : scene.shapes)
      if (!shape.curves.empty()) shape = curves_to_lines(shape, settings.line_segments);
  }
  // Settings carried by the scene file are defaults the caller overrides.
  auto& resolved = session.params;
  if (scene.settings.samples > 0 && !settings.samples_given)
    resolved.samples = scene.settings.samples;
  if (scene.settings.bounces > 0 && !settings.bounces_given)
    resolved.bounces = scene.settings.bounces;
  if (scene.settings.resolution > 0 && !settings.resolution_given)
    resolved.resolution = scene.settings.resolution;
  if (!settings.camera.empty()) {
    auto found = std::find(scene.camera_names.begin(), scene.camera_names.end(), settings.camera);
    if (found == scene.camera_names.end()) {
      error = settings.scene + ": no camera named " + settings.camera;
      return false;
    }
    resolved.camera = (int)(found - scene.camera_names.begin());
  }
  if (!check_trace_params(scene, resolved, error)) {
    error = settings.scene + ": " + error;
    return false;
  }
  session.first = settings.first;
  session.count = (settings.end > 0 ? settings.end : resolved.samples) - settings.first;
  // The image buffers, before they are allocated.
  auto size = camera_resolution(scene.cameras[resolved.camera], resolved.resolution);
  auto from = settings.resolution_given ? std::string(" (--resolution)")
                                        : std::string(" (the scene's settings)");
  if (!check_load_memory(settings.scene,
          "a render at resolution " + std::to_string(resolved.resolution) + from + ", " +
              std::to_string(size.x) + "x" + std::to_string(size.y) + " pixels,",
          trace_image_bytes(scene, resolved), settings.max_memory, error))
    return false;
  session.load_seconds = std::chrono::duration<double>(
      std::chrono::steady_clock::now() - start).count();
  return true;
}

bool build_render_session(
    render_session& session, std::string& error, std::vector<std::string>* warnings) {
  auto& scene    = session.scene;
  auto& params   = session.params;
  auto& settings = session.settings;
  if (settings.pack_fibers) pack_fiber_vertices(scene);
  // The BVH takes what the memory budget leaves after the scene and the
  // image. Over it, the build is tried again with half the curve pieces (the
  // same curves, looser bounds: slower rays), then in the compact layout, and
  // fails with a message only then. `built` says what was used: the parts'
  // settings record it.
  auto built       = settings.bvh;
  auto scene_bytes = 0.0;
  for (auto& shape : scene.shapes) scene_bytes += shape_memory(shape);
  for (auto& texture : scene.textures) scene_bytes += texture.pixels.size() * sizeof(vec3f);
  built.max_bytes = settings.max_memory - scene_bytes - trace_image_bytes(scene, params);
  if (!(built.max_bytes > 0)) {
    error = settings.scene + ": the scene and the image leave no memory for the BVH within "
                             "the memory budget (raise --max-memory)";
    return false;
  }
  // The curve pieces, planned: none when the render's rays (about two a
  // sample, over all of its samples, whatever part this is, so that the
  // parts of one render agree) do not repay their build; the most bent
  // segments first within the budget. Pieces given are kept even when they
  // do not repay, within the budget still.
  auto size         = camera_resolution(scene.cameras[params.camera], params.resolution);
  auto planned_rays = settings.curve_pieces_given ? 1e30
                                                  : 2.0 * size.x * size.y * params.samples;
  auto plan                   = plan_curve_pieces(scene, built, planned_rays, built.max_bytes);
  built.max_curve_pieces      = plan.max_pieces;
  built.curve_piece_threshold = plan.threshold;
  while (!make_scene_bvh(session.bvh, scene, built, error)) {
    if (!session.bvh.over_budget) {
      error = settings.scene + ": " + error;
      return false;
    }
    if (built.max_curve_pieces > 1) {
      built.max_curve_pieces /= 2;
    } else if (!built.compact) {
      built.compact = true;
    } else {
      error = settings.scene + ": " + error +
              ", with one piece a curve and the compact layout (raise --max-memory)";
      return false;
    }
    if (warnings)
      warnings->push_back(settings.scene + ": " + error + "; building it again with " +
                          std::to_string(built.max_curve_pieces) + " curve pieces" +
                          (built.compact ? ", compact" : ""));
  }
  session.built = built;
  restart_render_session(session);
  return true;
}

void restart_render_session(render_session& session) {
  session.context = make_trace_context(session.scene, session.params);
  init_trace_state(session.state, session.scene, session.params, session.first);
  session.seconds     = 0;
  session.cpu_seconds = 0;
}

int next_pass_samples(const render_session& session, double pass_seconds) {
  auto& state = session.state;
  auto  pass  = 1;
  // A pass ends on a power of two (checkpoints and time budgets stop there).
  // A pixel's samples in a row find its fibres and BVH nodes still in the
  // cache: 2.5-10% less CPU on the peers' hair balls at 64 spp than one
  // sample per pixel per pass (6% with one thread).
  if (state.samples > 0) {
    auto per_sample = session.seconds / state.samples;
    auto aligned    = state.samples & -state.samples;  // the next power of two stays a step
    while (pass * 2 <= aligned && pass * 2 * per_sample <= pass_seconds) pass *= 2;
  }
  return std::max(std::min(pass, session.count - state.samples), 0);
}

bool render_session_pass(render_session& session, const std::atomic<bool>* cancel) {
  auto count = next_pass_samples(session);
  if (count <= 0) return true;
  auto start = std::chrono::steady_clock::now();
  auto cpu   = process_cpu_seconds();
  auto done  = trace_samples(session.state, session.scene, session.bvh, session.context,
      session.params, count, cancel);
  session.seconds += std::chrono::duration<double>(std::chrono::steady_clock::now() - start)
                         .count();
  session.cpu_seconds += process_cpu_seconds() - cpu;
  return done;
}

bool is_render_session_done(const render_session& session, double time_budget) {
  auto samples = session.state.samples;
  if (samples >= session.count) return true;
  return time_budget > 0 && session.seconds >= time_budget && is_power_of_two(samples);
}

std::string format_render_stats(const render_session& session) {
  auto& scene    = session.scene;
  auto& state    = session.state;
  auto& bvh      = session.bvh;
  auto  segments = (size_t)0;
  auto  pieces   = (size_t)0;  // the Bezier curves Embree got for them
  auto  cones    = (size_t)0;  // and the cones of the straight ones
  for (auto i = 0; i < (int)scene.shapes.size(); i++) {
    auto& shape = scene.shapes[i];
    auto& given = bvh.pieces[i];
    segments += shape.lines.size() + num_curves(shape);
    pieces += given.pieces.empty() && given.cones.empty() ? num_curves(shape)
                                                          : given.pieces.size();
    cones += given.cones.size();
  }
  char buffer[2048];
  std::snprintf(buffer, sizeof(buffer),
      "stats load_seconds=%.6f bvh_seconds=%.6f bvh_bytes=%lld segments=%zu "
      "bvh_build_peak_bytes=%lld curve_pieces=%zu cones=%zu width=%d height=%d spp=%d "
      "render_seconds=%.6f render_cpu=%.6f rays=%lld peak_memory=%lld clamped=%lld "
      "clamped_energy=%.6g roulette_threshold=%.6g adaptive=%d adaptive_gain=%.4g split=%.4g "
      "allocation_cells=%d vertices=%lld light_samples=%lld shadow_rays=%lld "
      "roulette_cells=%d roulette_plays=%lld roulette_ends=%lld",
      session.load_seconds, bvh.build_seconds, (long long)bvh.peak_memory, segments,
      (long long)bvh.build_peak_memory, pieces, cones, state.width, state.height, state.samples,
      session.seconds, session.cpu_seconds, (long long)state.rays.load(),
      (long long)process_peak_memory(), (long long)state.clamped.load(),
      clamped_energy_fraction(state), state.roulette_threshold, state.rates.empty() ? 0 : 1,
      state.adaptive_gain,
      state.paths > 0 ? (double)state.continuations / (double)state.paths : (double)state.split,
      state.allocation.cells.x * state.allocation.cells.y * state.allocation.cells.z,
      (long long)state.vertices.load(), (long long)state.light_samples.load(),
      (long long)state.shadow_rays.load(),
      state.roulette_cache.cells.x * state.roulette_cache.cells.y * state.roulette_cache.cells.z,
      (long long)state.roulette_plays.load(), (long long)state.roulette_ends.load());
  return buffer;
}

}  // namespace yocto
