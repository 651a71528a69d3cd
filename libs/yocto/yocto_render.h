//
// # Yocto/Render: a render session
//
// What `yscene render` and `yscene serve` share: a scene loaded within the
// memory budget, its settings resolved (the caller's parameters over the
// scene file's), its BVH built (again with fewer curve pieces, then in the
// compact layout, when over budget), and the progressive accumulation in
// passes that end on powers of two and take about two seconds each. After
// edits of materials, lights or the camera a session restarts its
// accumulation without loading or building again. A pass is the same samples
// whatever came before it: a session renders the bits trace_samples would.
//

#ifndef YOCTO_RENDER_H_
#define YOCTO_RENDER_H_

#include <atomic>
#include <chrono>
#include <string>
#include <vector>

#include "yocto_bvh.h"
#include "yocto_fileio.h"
#include "yocto_scene.h"
#include "yocto_trace.h"

// -----------------------------------------------------------------------------
// RENDER SESSION
// -----------------------------------------------------------------------------
namespace yocto {

// How a session loads and builds, beside the tracer's parameters.
struct render_session_params {
  std::string scene  = "";  // any file load_any_scene reads
  std::string camera = "";  // camera name; "" keeps trace_params::camera
  // The trace_params the caller gave: the scene file's settings hold for
  // the others (samples, bounces, resolution).
  bool samples_given    = false;
  bool bounces_given    = false;
  bool resolution_given = false;
  // Curves tessellated into this many line segments each after loading (0:
  // native curves).
  int line_segments = 0;
  // Fibres in Embree's layout, read in place by the BVH (less memory); a
  // session that saves its scene keeps the plain layout save_scene writes.
  bool pack_fibers = true;
  // The BVH's parameters; max_curve_pieces is planned from the render's
  // rays unless curve_pieces_given.
  bvh_params bvh                = {};
  bool       curve_pieces_given = false;
  // Samples first ... end - 1 of the render (end 0: all of params.samples).
  int    first      = 0;
  int    end        = 0;
  double max_memory = default_memory_limit();
};

struct render_session {
  render_session_params settings = {};
  trace_params          params   = {};  // resolved against the scene's settings
  scene_data            scene    = {};
  scene_bvh             bvh      = {};
  bvh_params            built    = {};  // what the BVH was built with
  trace_context         context  = {};
  trace_state           state    = {};
  int                   first    = 0;   // the samples to render: first ...
  int                   count    = 0;   // ... first + count - 1
  double                load_seconds = 0;
  // The current accumulation's passes: render time and process CPU time in
  // them (what happens between passes, saving say, is not rendering).
  double seconds     = 0;
  double cpu_seconds = 0;
};

// Loads the scene into a new session, resolves the settings and the camera, checks the
// parameters and that the image buffers fit the memory budget. False with
// a message naming the file otherwise.
bool load_render_session(render_session& session, const render_session_params& settings,
    const trace_params& params, std::string& error);

// Builds the BVH within what the budget leaves after the scene and the
// image (each retry with fewer pieces or the compact layout adds a warning),
// the tracer's context and empty sums.
bool build_render_session(
    render_session& session, std::string& error, std::vector<std::string>* warnings = nullptr);

// After the scene's materials, environments, lights or camera (or
// params.camera) changed: the context again and empty sums. The BVH stays.
void restart_render_session(render_session& session);

// The samples the next pass adds: 1 first, then the most, up to the next
// power of two, that take about pass_seconds at the speed so far.
int next_pass_samples(const render_session& session, double pass_seconds = 2);

// Renders the next pass. With `cancel` set during it, the pass stops early,
// returns false and the sums are partial: restart the session.
bool render_session_pass(render_session& session, const std::atomic<bool>* cancel = nullptr);

// Whether every sample is done, or time_budget (> 0) seconds have passed
// and the samples reached a power of two.
bool is_render_session_done(const render_session& session, double time_budget = 0);

// One machine-readable line of figures, "stats key=value ...".
std::string format_render_stats(const render_session& session);

// This process's CPU time (user and system) in seconds, and its peak resident
// memory in bytes.
double  process_cpu_seconds();
int64_t process_peak_memory();

bool is_power_of_two(int n);

}  // namespace yocto

#endif
