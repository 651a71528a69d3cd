//
// # Yocto/Trace: a path tracer for hair scenes
//
// `path` samples the BSDF and, at every bounce, one light (textured
// environment, area light or distant light; a constant environment is left to
// BSDF sampling, which finds it as well without a shadow ray) with a shadow
// ray, combining the two with multiple importance sampling (power heuristic);
// `naive` samples the BSDF only. Every material (hair at line and curve hits
// included) is Yocto/Shading's: the tracer is an integrator only. Each pixel
// sample's random numbers are Owen-scrambled Sobol pairs at fixed dimensions
// per bounce (or independent numbers) and depend only on (seed, pixel,
// sample index): images do not depend on the number of threads, and any
// range of samples renders alone.
//
// Paths end by Russian roulette with the survival probability that
// maximises the image's efficiency (Rath et al. 2022, EARS): a pilot
// measures the pixel samples' variance and cost for the image, and the
// tails' worth and cost per region of the scene and direction (see
// trace_roulette_cache); the pilot is a pure function of the scene, the
// parameters and the seed, so every part of a split render learns the same.
// The same pilot learns, per region of the scene, how often a
// shadow ray reaches its light, and light samples cast their shadow ray with
// the probability that maximises efficiency (see trace_allocation). Where no
// MIS weight needs a BSDF pdf (no light with area to sample: a constant sky,
// distant lights), a sampled hair direction takes its lobe's own weight
// A_p / P(p), and the lobes are not evaluated. A second pilot plans each
// pixel's samples from its own statistics (see estimate_pixel_plan): how many
// paths share a camera ray's hit, and how many paths a sample the pixel
// takes; a pure function of the same inputs.
//

#ifndef YOCTO_TRACE_H_
#define YOCTO_TRACE_H_

#include <array>
#include <atomic>
#include <string>
#include <vector>

#include "yocto_bvh.h"
#include "yocto_sampling.h"
#include "yocto_scene.h"
#include "yocto_shading.h"

// -----------------------------------------------------------------------------
// PARAMETERS
// -----------------------------------------------------------------------------
namespace yocto {

enum struct trace_sampler_type { path, naive };
inline const auto trace_sampler_names = std::array<std::string, 2>{"path", "naive"};

// The lights that `path` samples: `automatic` leaves out those that BSDF
// sampling finds as well (a constant environment), `all` samples every one.
enum struct trace_lights_type { automatic, all };
inline const auto trace_lights_names = std::array<std::string, 2>{"automatic", "all"};

// Adaptive sampling: `automatic` and `on` plan every pixel's samples (see
// estimate_pixel_plan), `off` gives every pixel one path a sample.
enum struct trace_adaptive_type { automatic, on, off };
inline const auto trace_adaptive_names = std::array<std::string, 3>{"auto", "on", "off"};

struct trace_params {
  int                camera     = 0;
  int                resolution = 720;  // largest image side
  trace_sampler_type sampler    = trace_sampler_type::path;
  trace_lights_type  lights     = trace_lights_type::automatic;
  sequence_type      sequence   = sequence_type::global_sobol;  // random numbers of a pixel
  int                sobol_bounces = 32;  // bounces with Sobol numbers, then independent
  int                samples    = 64;
  int                bounces    = 32;    // scattering events per path (pbrt maxdepth)
  int                roulette_bounce = 0;  // first bounce with Russian roulette
  // Paths whose throughput falls below this play the roulette; 0 for the
  // render's own, estimated by a pilot (estimate_roulette_threshold).
  float              roulette_threshold = 0;
  // Paths per camera ray, sharing its hit (splitting at the first vertex);
  // 0 for each pixel's own (see estimate_pixel_plan; 1 without adaptive
  // sampling).
  int                split      = 0;
  // Adaptive sampling: a pilot measures each pixel's variances and cost, and
  // the pixel takes that many more or fewer paths per sample (see
  // estimate_pixel_plan); off: every pixel one path per sample.
  trace_adaptive_type adaptive  = trace_adaptive_type::automatic;
  // Sky samples that would add less than this times the sky's average
  // radiance play a roulette for their shadow ray (0 for none).
  float              shadow_threshold = 0.1f;
  // Largest component a sample may have (scaled down to it), 0 for none.
  // Off by default: clamping removes energy (the image is biased).
  float              clamp      = 0;
  uint64_t           seed       = 961748941;
  int                threads    = 0;     // 0 for all cores
  hair_sampling_params hair_sampling = {};  // options of the hair BSDF (yocto_shading)
  // Also sum the AOVs of every sample (see AOVS below).
  bool               aovs       = false;
  // Shadow rays allocated per region of the scene by what the pilot learned
  // (see trace_allocation); off: params.shadow_threshold's roulette.
  bool               allocation = true;
  // Russian roulette by region and direction from the pilot's tails (see
  // trace_roulette_cache) when the threshold is the pilot's; off: the
  // pilot's one threshold everywhere.
  bool               roulette_cache = true;
  // Hair lobes chosen in part (this share, in [0, 0.95]) by what the roulette
  // cache expects each lobe's direction to be worth per unit cost, where no
  // MIS needs the BSDF's pdf (see sample_hair_scattering_weight); 0 for the
  // luminance choice alone. Needs the roulette cache.
  float              lobe_guide = 0.5f;
  // The roulette takes the roulette cache's mean tail as a control variate
  // (see trace_roulette_cache): an ended path adds what its tail was
  // expected to bring, a surviving one the difference; off (the default, as
  // a sample, and at low sample counts a pixel, may then be negative):
  // ended paths add nothing. Needs the roulette cache.
  bool               roulette_control = false;
};

}  // namespace yocto

// -----------------------------------------------------------------------------
// LIGHTS
// -----------------------------------------------------------------------------
namespace yocto {

// A light to sample: an emissive triangle instance (with a cdf over its
// triangles' world areas), the environment (with a cdf over its texels,
// weighted by sin(theta) and the texel's largest component) or a distant light.
struct trace_light {
  int                instance    = -1;
  int                environment = -1;
  int                distant     = -1;
  std::vector<float> cdf         = {};
  float              radiance    = 0;  // environments: average radiance (else 0)
};

// What the tracer precomputes once per scene: the lights to sample and what
// shading precomputes (make_shading_context).
struct trace_context {
  std::vector<trace_light>      lights         = {};
  shading_context               shading        = {};
  std::vector<int>              instance_light       = {};  // light of an instance, -1 none
  std::vector<int>              environment_light    = {};  // light of an environment, -1 none
  std::vector<frame3f>          environment_inverses = {};  // world to local
  // Slot of each pair in the global Sobol point, -1 for padded pairs
  // (sequence_type::global_sobol only).
  std::vector<int8_t>           sequence_slots       = {};
  // Whether a light to sample has area (an MIS weight then needs the BSDF's
  // pdf); distant lights alone are deltas, which BSDF samples never find.
  bool                          mis_lights           = false;
};

trace_context make_trace_context(const scene_data& scene, const trace_params& params = {});

}  // namespace yocto

// -----------------------------------------------------------------------------
// RENDERING
// -----------------------------------------------------------------------------
namespace yocto {

// Where a render casts shadow rays, per region of the scene: Rath et al.
// 2022 (EARS) give a sample of cost c whose contribution has second moment
// M2 the probability q = sqrt(M2 / c) / sqrt(V / C) of being taken that
// maximises the image's efficiency, 1 / (MSE x cost), V and C the variance
// and cost of a pixel sample; Meyer et al. 2024 (MARS) apply it to each
// sampling technique of a vertex on its own. For a light sample that would
// add c if visible, in a region where a fraction P of shadow rays reach
// their light, M2 = c^2 P and the cost is one ray: its shadow ray is cast
// with probability min(1, c sqrt(P) / sqrt(V / C)) and weighted up by its
// inverse. P is averaged over the cells of a grid over the shadow rays the
// pilot cast, each cell's count shrunk towards the whole scene's by a prior.
struct trace_allocation {
  bbox3f             bounds          = {};
  vec3i              cells           = {0, 0, 0};  // per axis; 0 for no grid
  vec3f              cell_scale      = {0, 0, 0};  // cells per unit length
  float              pixel_deviation = 0;          // sqrt(V / C)
  std::vector<float> visibility      = {};         // per cell: sqrt(P)
};

// The cell of a point in the allocation's grid (points outside the pilot's
// bounds take the nearest cell); -1 without a grid.
int find_allocation_cell(const trace_allocation& allocation, const vec3f& position);

// Russian roulette per region and direction (Rath et al. 2022, EARS): a path
// of throughput w leaving a vertex at x in direction d survives with
// probability q = w sqrt(M2(x, d) / c(x, d)) / sqrt(V / C) (at most 1), M2 and
// c the second moment (per unit throughput) and the cost in rays of the
// radiance its tail brings, V and C a pixel sample's variance and cost. A
// tail that leads out of the hair towards the light is worth more than one
// that leads into it, wherever the hair is: M2 and c are linear functions of
// d in each cell of a grid over the pilot's vertices (least squares over the
// pilot's tails, each cell's fit drawn towards the whole scene's mean).
struct trace_roulette_cache {
  bbox3f             bounds          = {};
  vec3i              cells           = {0, 0, 0};  // per axis; 0 for no grid
  vec3f              cell_scale      = {0, 0, 0};  // cells per unit length
  float              pixel_deviation = 0;          // sqrt(V / C)
  // Per cell: M2 = a + b . d (a, b.x, b.y, b.z), then c the same way.
  std::vector<std::array<float, 8>> tails = {};
  // With params.roulette_control, per cell: the tail's mean radiance per unit
  // of throughput, mu = a + b . d per channel (red's a, b.x, b.y, b.z, then
  // green's, blue's), and its second moment about w mu, R = a + b . d. A path
  // of throughput w that the roulette ends adds w mu (x, d); one that
  // survives with probability q adds w mu (1 - 1 / q) and goes on weighted
  // by 1 / q: unbiased for any mu, and the roulette's variance is
  // w^2 (1 / q - 1) R instead of w^2 (1 / q - 1) M2, so q follows R.
  std::vector<std::array<float, 16>> controls = {};
};

// The cell of a point in the cache's grid, as find_allocation_cell.
int find_roulette_cell(const trace_roulette_cache& cache, const vec3f& position);

// The survival probability of a path of throughput `weight` leaving
// `position` in `direction` (see trace_roulette_cache), in (0, 1].
float roulette_survival(const trace_roulette_cache& cache, const vec3f& position,
    const vec3f& direction, float weight);

// The image being rendered: sums of samples per pixel and counters.
// The render so far: samples first ... first + samples - 1 of every pixel,
// summed exactly (fixed_sum3), so that the sums of disjoint sample ranges,
// added in any order, equal the sums of one render of their union: the
// image of a render split across machines has the same bits.
struct trace_state {
  int                        width   = 0;
  int                        height  = 0;
  int                        first   = 0;  // index of the first sample
  int                        samples = 0;  // samples per pixel done so far
  std::vector<fixed_sum3>    sums    = {};
  std::vector<fixed_sum3>    aov_sums = {};  // with params.aovs: trace_aov_sums a pixel
  std::atomic<int64_t>       rays    = 0;  // rays cast (camera, bounce, shadow)
  std::atomic<int64_t>       nonfinite = 0;  // samples dropped as NaN or Inf
  // What params.clamp did: samples clamped, and per image row the energy
  // (sum of r, g, b) of the samples before clamping and the part removed
  // (rows, so that the figures do not depend on the threads); with clamp off
  // the energies are left at zero.
  std::atomic<int64_t>       clamped        = 0;
  std::vector<double>        row_energy     = {};
  std::vector<double>        row_clamped    = {};
  float                      roulette_threshold = 0;  // the render's, 0 until set
  // The plan's predicted gain of its rates (0 if no plan).
  float                      adaptive_gain = 0;
  // Paths per camera ray without per-pixel splits: max(params.split, 1) (0
  // until set).
  int                        split = 0;
  // The shadow rays' allocation (params.allocation; no cells until set).
  trace_allocation           allocation = {};
  // The roulette by region and direction (params.roulette_cache; no cells
  // until set).
  trace_roulette_cache       roulette_cache = {};
  // What paths did: scattering vertices, light samples there that would
  // add light if visible, and the shadow rays cast for them.
  std::atomic<int64_t>       vertices      = 0;
  std::atomic<int64_t>       light_samples = 0;
  std::atomic<int64_t>       shadow_rays   = 0;
  // Camera paths traced, and the paths that continued them (with the split).
  std::atomic<int64_t>       paths         = 0;
  std::atomic<int64_t>       continuations = 0;
  // Vertices where the roulette could end a path (survival below 1), and
  // the paths it ended.
  std::atomic<int64_t>       roulette_plays = 0;
  std::atomic<int64_t>       roulette_ends  = 0;
  // Paths per sample of each pixel with adaptive sampling (empty until set,
  // and without it): an integer m >= 1 (m paths, each weighing 1 / m), or 1 / q
  // for q a power of two (one path every q samples, weighing q).
  std::vector<float>         rates   = {};
  // Paths per camera ray of each pixel with adaptive sampling and an
  // automatic split (empty otherwise: every pixel takes `split`).
  std::vector<uint8_t>       splits  = {};
};

// The fraction of the samples' energy that clamping removed so far.
double clamped_energy_fraction(const trace_state& state);

// Checks the parameters against the scene; false with a message if wrong.
bool check_trace_params(const scene_data& scene, const trace_params& params,
    std::string& error);

// Bytes of the image buffers a render allocates: the sums of trace_state, the
// image get_image returns and the 8-bit copy a png or jpg save makes (and
// the rates of adaptive sampling and their pilot's buffers). Callers
// check it against their memory budget before init_trace_state.
double trace_image_bytes(const scene_data& scene, const trace_params& params);

// The roulette threshold that maximises the render's efficiency, from a
// pilot of a few samples on a grid of pixels (see the .cpp); trace_samples
// calls it once per render when params.roulette_threshold is 0. The same for
// the same scene, parameters and seed, whatever the threads and sample range.
// Its CPU time is the render's; its rays are not counted in trace_state::rays.
float estimate_roulette_threshold(const scene_data& scene, const scene_bvh& bvh,
    const trace_context& context, const trace_params& params);

// What the roulette's pilot measures: the threshold above and, with
// params.allocation, the shadow rays' allocation.
struct trace_pilot {
  float                roulette_threshold = 1;
  trace_allocation     allocation         = {};  // with params.allocation
  trace_roulette_cache roulette_cache     = {};  // with params.roulette_cache
};
trace_pilot run_trace_pilot(const scene_data& scene, const scene_bvh& bvh,
    const trace_context& context, const trace_params& params);

// The per-pixel plan of adaptive sampling. A pilot traces, on one pixel in
// two (a checkerboard), 2 camera samples, each hit continued by 2 paths,
// with numbers of their own (the image stays unbiased: no path of the pilot
// is in it), and measures per pixel, averaged over 7 x 7 pixels: the
// variance between the paths of one hit (the tail's, V_tail), the variance
// of the camera's hit (V_hit, from the spread of the two hits' means) and
// the tail's rays c. Each variance is shrunk towards its average over
// 25 x 25 pixels by as much as the pilot's noise calls for (measured between
// its even and odd columns), so that a noise that is even across the image
// is planned as even. A sample of the pixel then costs 1 + k c rays for k
// paths per camera ray and has variance V_hit + V_tail / k; the split k
// (1 ... 8, at most the largest power of two dividing params.samples, or
// params.split) minimises their product, the optimum of splitting at the
// first vertex (as EARS, Rath et al. 2022, from the pixel's own
// statistics). The rates minimise the image's mean squared
// error for the rays of params.samples uniform samples a pixel (no rates,
// params.split or 1 path a camera ray: a render costs what one without the
// plan costs, whatever it picks), with the camera hit's part of a pixel's
// error falling as n^-1.5 (Owen-scrambled nets on a 2D integrand with
// edges) and the rest as n^-1 (so that fibre edges against the sky, which
// the pilot's unstratified pairs see as noisy, are not oversampled at high
// counts), and are rounded
// to integers from 1 to 16 or to 1 / q for q = 2, 4, 8 dividing
// params.samples (so that every pixel takes whole paths).
// splits: each pixel's k, empty when params.split sets every pixel's (it
// may pass what a byte holds). gain: the rates' predicted gain in
// efficiency, mean(v) mean(c) / mean(sqrt(v c))^2. A pure function of the
// scene, the parameters, the threshold and the seed, as the roulette's
// pilot.
struct trace_pixel_plan {
  std::vector<float>   rates  = {};
  std::vector<uint8_t> splits = {};
  float                gain   = 1;
};
trace_pixel_plan estimate_pixel_plan(const scene_data& scene, const scene_bvh& bvh,
    const trace_context& context, const trace_params& params, float roulette_threshold,
    const trace_allocation* allocation = nullptr,
    const trace_roulette_cache* roulette_cache = nullptr);

// Empty sums for the camera's image; the samples will start at `first`.
void init_trace_state(trace_state& state, const scene_data& scene, const trace_params& params,
    int first = 0);

// Adds `count` samples to every pixel (samples first + samples ... + count
// - 1), using params.threads threads. A sample with a NaN or Inf component,
// or one of fixed_sum_max_sample or more, is dropped and counted. Once
// `cancel` is set, rows not yet started are skipped: the call returns false
// and the sums are partial (init_trace_state again before more samples).
bool trace_samples(trace_state& state, const scene_data& scene, const scene_bvh& bvh,
    const trace_context& context, const trace_params& params, int count,
    const std::atomic<bool>* cancel = nullptr);

// The current estimate: sums over samples (with adaptive rates, over the
// paths each pixel has taken so far, so that any number of samples gives an
// unbiased image).
texture_data get_image(const trace_state& state);
// The same for sums of `samples` samples a pixel (what a merge of parts has).
texture_data get_image(int width, int height, const std::vector<fixed_sum3>& sums,
    int samples);

// -----------------------------------------------------------------------------
// AOVS
// -----------------------------------------------------------------------------
// With params.aovs every sample adds, besides its radiance, exact sums
// (fixed_sum3, so that the parts of a split render merge to the same bits)
// of what its camera ray found and of its radiance split by hair lobe:
// - albedo: the first hit's directional albedo for the camera ray's
//   direction; hair: the model's own, eval_hair_albedo (sum of A_p at the
//   hit's h); matte: its colour; glossy: colour (1 - F) + F at the outgoing
//   angle; 0 where the ray escapes (OIDN's aux image for the denoiser);
// - normal: the first hit's shading normal, facing the camera (fibres: the
//   round fibre's normal at h; a fibre seen end on, its tangent towards the
//   camera, the end cap's); 0 where the ray escapes;
// - tangent: fibres: the curve's tangent, root to tip (the direction its
//   control points run); surfaces: the normal; 0 where the ray escapes;
// - hair_R, hair_TT, hair_TRT, hair_TRRT: the radiance of the paths by the
//   lobe p of their first hair scattering: the light sampled there split by
//   the lobes' terms (eval_hair_scattering_lobes), the rest of the path by
//   the lobe sampled there (or by the lobes' shares of the sampled
//   direction's value, where MIS needs the mixture). Per sample they sum to
//   the radiance of the paths that scatter at hair (all but what the camera
//   sees directly and what paths gather before reaching hair), and each is
//   its lobe's share in expectation. Dropped (NaN) samples add no lobes;
//   clamped ones add them clamped by the same factor;
// - depth: the distance to the first hit, averaged over the samples that hit
//   (0 where none does); coverage: the fraction of samples whose first hit
//   is hair.
inline constexpr int trace_aov_sums = 8;  // fixed_sum3 a pixel

// Bytes of the AOV sums and layers of a render with params.aovs (0 without).
double trace_aov_bytes(const scene_data& scene, const trace_params& params);

// The AOV layers from sums of `samples` samples a pixel (trace_aov_sums a
// pixel): albedo (R, G, B), normal (X, Y, Z), tangent (X, Y, Z), hair_R,
// hair_TT, hair_TRT, hair_TRRT (R, G, B), depth (Z), coverage (Y).
std::vector<image_layer> get_aov_layers(int width, int height,
    const std::vector<fixed_sum3>& aov_sums, int samples);
// The same for a render's state (normalised as get_image(state)).
std::vector<image_layer> get_aov_layers(const trace_state& state);

// Radiance of one path from a camera ray (exposed for tests); an automatic
// roulette threshold (0) is taken as 1 here, as no pilot runs.
vec3f trace_radiance(const scene_data& scene, const scene_bvh& bvh,
    const trace_context& context, const ray3f& ray, sequence_state& sequence,
    const trace_params& params, int64_t& rays);

}  // namespace yocto

// -----------------------------------------------------------------------------
// RAY CASTING ALONE (the limit of the renderer's speed)
// -----------------------------------------------------------------------------
namespace yocto {

// A ray the tracer cast: a closest-hit query (camera, bounce and area-light
// shadow rays) or an any-hit query (other shadow rays).
struct trace_ray {
  ray3f ray    = {};
  bool  any_hit = false;
};

// Renders the next `count` samples as trace_samples does and
// returns every ray cast, in pixel order (the same list at any thread count).
std::vector<trace_ray> record_trace_rays(trace_state& state, const scene_data& scene,
    const scene_bvh& bvh, const trace_context& context, const trace_params& params,
    int count);

// Casts the rays through the BVH alone, no shading, on `threads` threads (0
// for all) in chunks of consecutive rays; returns the number of hits.
int64_t cast_trace_rays(const scene_bvh& bvh, const std::vector<trace_ray>& rays,
    int threads);

}  // namespace yocto

#endif
