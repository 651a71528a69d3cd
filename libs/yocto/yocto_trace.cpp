//
// Implementation of Yocto/Trace.
//

#include "yocto_trace.h"

#include <limits>
#include <tuple>
#include <pmmintrin.h>
#include <tbb/blocked_range.h>
#include <xmmintrin.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>


// -----------------------------------------------------------------------------
// LIGHTS
// -----------------------------------------------------------------------------
namespace yocto {

// The dimensions of a pixel sample, in pairs: the pixel position and the
// lens, then six pairs per bounce (light choice and light element, point on
// the light, glossy lobe and roulette, BSDF direction, two more numbers for
// hair sampled with four, and the shadow-ray roulette). Fixed positions keep
// every bounce's numbers stratified across the samples of a pixel, whatever
// the path did before.
enum trace_pair {
  trace_pair_pixel = 0, trace_pair_lens = 1,
  trace_pair_light = 0, trace_pair_light_point = 1, trace_pair_lobe_roulette = 2,
  trace_pair_direction = 3, trace_pair_direction_more = 4, trace_pair_shadow = 5,
};
// (Capped so that no --sobol-bounces overflows an int; no path goes deeper.)
static int trace_bounce_pairs(int bounce) { return 2 + 6 * std::min(bounce, 1 << 24); }

// The pairs that take the slots of the global Sobol point (global_sobol),
// in the order a path draws them, leaving out those this render never
// draws (the lens of a pinhole, lights where none are sampled, the roulette
// before its first bounce, the glossy lobe where no material is glossy), so
// that the dimensions a path uses are the lowest, best stratified ones. The
// list ends at the last pair with a slot (later pairs are padded).
static std::vector<int8_t> make_sequence_slots(
    const scene_data& scene, const trace_params& params, bool samples_lights) {
  auto slots = std::vector<int8_t>{};
  auto next  = 0;
  auto take  = [&](int pair) {
    if (next >= sobol_global_dimensions / 2) return;
    slots.resize(std::max(slots.size(), (size_t)pair + 1), -1);
    slots[pair] = (int8_t)next++;
  };
  auto& camera = scene.cameras[std::clamp(params.camera, 0, (int)scene.cameras.size() - 1)];
  auto glossy  = false, four_numbers = params.hair_sampling.four_numbers;
  for (auto& material : scene.materials) glossy |= material.type == material_type::glossy;
  take(trace_pair_pixel);
  if (!camera.orthographic && camera.aperture > 0) take(trace_pair_lens);
  for (auto bounce = 0; bounce < params.sobol_bounces && next < sobol_global_dimensions / 2;
       bounce++) {
    auto pairs = trace_bounce_pairs(bounce);
    if (samples_lights) take(pairs + trace_pair_light), take(pairs + trace_pair_light_point);
    if (glossy || bounce >= params.roulette_bounce) take(pairs + trace_pair_lobe_roulette);
    take(pairs + trace_pair_direction);
    if (four_numbers) take(pairs + trace_pair_direction_more);
    if (samples_lights && (params.shadow_threshold > 0 || params.allocation))
      take(pairs + trace_pair_shadow);
  }
  return slots;
}

// Whether paths sample lights: next-event estimation with MIS (the path
// sampler) where the context has lights to sample.
static bool paths_sample_lights(const trace_params& params, const trace_context& context) {
  return params.sampler == trace_sampler_type::path && !context.lights.empty();
}

trace_context make_trace_context(const scene_data& scene, const trace_params& params) {
  auto context    = trace_context{};
  context.shading = make_shading_context(scene, params.hair_sampling);
  context.instance_light.assign(scene.instances.size(), -1);
  context.environment_light.assign(scene.environments.size(), -1);
  for (auto& environment : scene.environments)
    context.environment_inverses.push_back(inverse(environment.frame, false));
  for (auto i = 0; i < (int)scene.instances.size(); i++) {
    auto& instance = scene.instances[i];
    auto& material = scene.materials[instance.material];
    auto& shape    = scene.shapes[instance.shape];
    if (material.emission == vec3f{0, 0, 0} || shape.triangles.empty()) continue;
    auto light     = trace_light{};
    light.instance = i;
    auto total     = 0.0f;
    for (auto& t : shape.triangles) {
      auto p0 = transform_point(instance.frame, shape.positions[t.x]);
      auto p1 = transform_point(instance.frame, shape.positions[t.y]);
      auto p2 = transform_point(instance.frame, shape.positions[t.z]);
      total += length(cross(p1 - p0, p2 - p0)) / 2;
      light.cdf.push_back(total);
    }
    if (total <= 0) continue;
    context.instance_light[i] = (int)context.lights.size();
    context.lights.push_back(light);
  }
  for (auto i = 0; i < (int)scene.environments.size(); i++) {
    auto& environment = scene.environments[i];
    if (environment.emission == vec3f{0, 0, 0}) continue;
    // A constant sky is found as well by the BSDF's own samples as by
    // uniform light samples, which cost a shadow ray each.
    if (environment.emission_tex < 0 && params.lights == trace_lights_type::automatic) continue;
    auto light        = trace_light{};
    light.environment = i;
    light.radiance    = max_component(environment.emission);
    if (environment.emission_tex >= 0) {
      // MIS compensation (Karlik et al., MIS Compensation: Optimizing
      // Sampling Techniques in Multiple Importance Sampling, 2019): light
      // samples go where the sky is above its average, proportionally to the
      // excess; BSDF samples, which MIS weighs fully where the light pdf is
      // 0, find the rest. A sky of one value is left to BSDF sampling.
      auto& texture = scene.textures[environment.emission_tex];
      auto  average = 0.0, weights = 0.0;
      for (auto j = 0; j < texture.height; j++) {
        auto sin_theta = std::sin((j + 0.5f) * pif / texture.height);
        for (auto k = 0; k < texture.width; k++) {
          average += std::max(max_component(texture.pixels[(size_t)j * texture.width + k]),
                         0.0f) * sin_theta;
          weights += sin_theta;
        }
      }
      average /= std::max(weights, 1e-30);
      light.radiance = (float)average * max_component(environment.emission);
      auto offset = params.lights == trace_lights_type::automatic ? (float)average : 0.0f;
      auto total  = 0.0f;
      for (auto j = 0; j < texture.height; j++) {
        auto sin_theta = std::sin((j + 0.5f) * pif / texture.height);
        for (auto k = 0; k < texture.width; k++) {
          auto value = max_component(texture.pixels[(size_t)j * texture.width + k]);
          total += std::max(value - offset, 0.0f) * sin_theta;
          light.cdf.push_back(total);
        }
      }
      // Nothing above the average (well above rounding): a constant sky.
      if (!(total > 1e-6f * std::max((float)average, 1e-30f) * texture.width * texture.height))
        continue;
    }
    context.environment_light[i] = (int)context.lights.size();
    context.lights.push_back(light);
  }
  for (auto i = 0; i < (int)scene.distant_lights.size(); i++) {
    if (scene.distant_lights[i].emission == vec3f{0, 0, 0}) continue;
    auto light    = trace_light{};
    light.distant = i;
    context.lights.push_back(light);
  }
  for (auto& light : context.lights) context.mis_lights |= light.distant < 0;
  if (params.sequence == sequence_type::global_sobol && !scene.cameras.empty())
    context.sequence_slots =
        make_sequence_slots(scene, params, paths_sample_lights(params, context));
  return context;
}

// Direction pdf (solid angle) of sampling the environment texture, at the
// texture coordinates of the direction (computed once for the emission and
// the pdf: the inverse mapping costs an atan2 and an acos).
static float environment_texture_pdf(
    const scene_data& scene, const trace_light& light, const vec2f& uv) {
  auto& environment = scene.environments[light.environment];
  auto& texture     = scene.textures[environment.emission_tex];
  auto  i     = std::clamp((int)(uv.x * texture.width), 0, texture.width - 1);
  auto  j     = std::clamp((int)(uv.y * texture.height), 0, texture.height - 1);
  auto  prob  = sample_discrete_pdf(light.cdf, j * texture.width + i);
  auto  sin_theta = std::sin((j + 0.5f) * pif / texture.height);
  if (sin_theta <= 0) return 0;
  return prob * texture.width * texture.height / (2 * pif * pif * sin_theta);
}

// A direction sampled towards a light. Area lights: the sampled point (its
// distance, geometric normal and texture coordinates); textured environments:
// the sampled texture coordinates.
struct light_sample {
  vec3f incoming = {0, 0, 0};  // zero if the light has no area
  vec3f position = {0, 0, 0};  // area lights: the sampled point
  float distance = flt_max;    // area lights: to the sampled point
  vec3f gnormal  = {0, 0, 1};  // area lights: at the sampled point
  vec2f uv       = {0, 0};     // area lights: texcoord; environments: equirect uv
};

static light_sample sample_light(const scene_data& scene, const trace_light& light,
    const vec3f& position, float rel, const vec2f& ruv) {
  auto sample = light_sample{};
  if (light.instance >= 0) {
    auto& instance = scene.instances[light.instance];
    auto  element  = sample_discrete(light.cdf, rel);
    auto  point    = eval_surface_point(scene, instance, element, sample_triangle(ruv));
    sample.position = point.position;
    sample.distance = length(point.position - position);
    sample.incoming = safe_normalize(point.position - position);
    sample.gnormal  = safe_normalize(point.gnormal);
    sample.uv       = point.texcoord;
  } else if (light.environment >= 0) {
    auto& environment = scene.environments[light.environment];
    if (environment.emission_tex < 0) {
      sample.incoming = sample_sphere(ruv);
      return sample;
    }
    auto& texture = scene.textures[environment.emission_tex];
    auto  index   = sample_discrete(light.cdf, rel);
    sample.uv     = vec2f{((index % texture.width) + ruv.x) / texture.width,
        ((index / texture.width) + ruv.y) / texture.height};
    sample.incoming = transform_direction(environment.frame, equirect_to_direction(sample.uv));
  } else {
    sample.incoming = normalize(scene.distant_lights[light.distant].direction);
  }
  return sample;
}

}  // namespace yocto

// -----------------------------------------------------------------------------
// PATH TRACING
// -----------------------------------------------------------------------------
namespace yocto {

static float power_heuristic(float pdf_a, float pdf_b) {
  auto a = pdf_a * pdf_a, b = pdf_b * pdf_b;
  return a + b > 0 ? a / (a + b) : 0;
}

// Radiance of the environments along an escaping ray's direction, each
// weighted for MIS against its own light-sampling pdf when bsdf_pdf > 0 (each
// environment is a light of its own, so each has its own pair of weights). As
// eval_environment, but with the world-to-local frames inverted once per
// scene and the texture coordinates computed once for emission and pdf.
static vec3f eval_environments(const scene_data& scene, const trace_context& context,
    const vec3f& direction, float bsdf_pdf) {
  auto radiance = vec3f{0, 0, 0};
  auto nlights  = (float)std::max((int)context.lights.size(), 1);
  for (auto i = 0; i < (int)scene.environments.size(); i++) {
    auto& environment = scene.environments[i];
    auto  light       = context.environment_light[i];
    auto  mis_needed  = light >= 0 && bsdf_pdf > 0;
    auto  emission    = environment.emission;
    auto  light_pdf   = 1 / (4 * pif);
    if (environment.emission_tex >= 0) {
      auto local = transform_direction(context.environment_inverses[i], direction);
      auto uv    = direction_to_equirect(local);
      emission *= eval_environment_texture(scene.textures[environment.emission_tex], uv);
      if (mis_needed) light_pdf = environment_texture_pdf(scene, context.lights[light], uv);
    }
    radiance += emission * (mis_needed ? power_heuristic(bsdf_pdf, light_pdf / nlights) : 1.0f);
  }
  return radiance;
}

// Solid-angle pdf that light sampling would have produced for a BSDF ray that
// hit an area light (at distance, with cosine at the light) or escaped.
static float area_light_pdf(const scene_data& scene, const trace_context& context,
    int instance, float distance, float cos_light) {
  auto index = context.instance_light[instance];
  if (index < 0 || cos_light <= 0) return 0;
  auto area = context.lights[index].cdf.back();
  return distance * distance / (cos_light * area) / context.lights.size();
}

// What a light sample brings if nothing occludes it: its emission, the
// solid-angle pdf of choosing the light and the sample, and whether the light
// is a delta (distant) light, which takes no MIS weight.
struct trace_light_value {
  vec3f emission = {0, 0, 0};
  float pdf      = 0;
  bool  delta    = false;
};
static trace_light_value eval_light_sample(const scene_data& scene,
    const trace_context& context, const trace_light& light, const light_sample& sample,
    const vec3f& incoming) {
  auto nlights = (float)context.lights.size();
  if (light.instance >= 0) {
    if (dot(sample.gnormal, incoming) >= 0) return {};  // the light's back
    auto& material = scene.materials[scene.instances[light.instance].material];
    auto  emission = material.emission;
    if (material.emission_tex >= 0)
      emission *= eval_texture(scene.textures[material.emission_tex], sample.uv);
    return {emission, area_light_pdf(scene, context, light.instance, sample.distance,
                          -dot(sample.gnormal, incoming)), false};
  } else if (light.environment >= 0) {
    // The sampled texture coordinates give emission and pdf directly.
    auto& environment = scene.environments[light.environment];
    if (environment.emission_tex < 0) return {environment.emission, 1 / (4 * pif) / nlights};
    return {environment.emission * eval_environment_texture(
                                       scene.textures[environment.emission_tex], sample.uv),
        environment_texture_pdf(scene, light, sample.uv) / nlights, false};
  } else {
    return {scene.distant_lights[light.distant].emission, 1 / nlights, true};
  }
}

// A pixel sample's sequence: the render's sequence type, its Sobol pairs and,
// for global_sobol, the pairs' slots.
static sequence_state make_pixel_sequence(const trace_context& context,
    const trace_params& params, uint64_t seed, int64_t pixel, uint32_t sample) {
  return make_sequence(params.sequence, seed, pixel, sample,
      trace_bounce_pairs(params.sobol_bounces), context.sequence_slots.data(),
      (int)context.sequence_slots.size());
}

// A point where a pilot path played the roulette: the throughput's largest
// component, the probability of surviving, the radiance gathered and rays
// cast before it (the path's tail is what comes after), and the vertex and
// the direction the tail leaves it in.
struct trace_roulette_point {
  float   weight    = 0;
  vec3f   throughput = {0, 0, 0};
  float   survive   = 1;
  vec3f   radiance  = {0, 0, 0};
  int64_t rays      = 0;
  vec3f   position  = {0, 0, 0};
  vec3f   direction = {0, 0, 0};
};

// A pilot's tail for the roulette cache: where it left from, in which
// direction, and its squared radiance per unit throughput and its rays, each
// already weighted by the pilot's own roulette; its radiance per unit
// throughput (so weighted too) and the throughput's colour (the throughput
// over its largest component), for the control variate.
struct trace_tail_record {
  vec3f position  = {0, 0, 0};
  vec3f direction = {0, 0, 0};
  float moment    = 0;
  float cost      = 0;
  vec3f tail      = {0, 0, 0};
  vec3f colour    = {0, 0, 0};
};

// A shadow ray a pilot path cast: the point it left and whether it reached
// its light.
struct trace_shadow_record {
  vec3f position = {0, 0, 0};
  bool  visible  = false;
};

// What paths did on a row of the image (see trace_state).
struct trace_tally {
  int64_t vertices = 0, light_samples = 0, shadow_rays = 0, paths = 0, continuations = 0;
  int64_t roulette_plays = 0, roulette_ends = 0;
};

// The camera ray of a sample of pixel (i, j) of a width x height image; the
// lens pair is drawn only for cameras with a lens (a pinhole ignores it).
static ray3f sample_camera_ray(const camera_data& camera, int i, int j, int width,
    int height, sequence_state& sequence) {
  auto puv  = sample_sequence2f(sequence, trace_pair_pixel);
  auto lens = !camera.orthographic && camera.aperture > 0;
  auto luv  = lens ? sample_sequence2f(sequence, trace_pair_lens) : vec2f{0, 0};
  return eval_camera(camera, {(i + puv.x) / width, (j + puv.y) / height}, luv);
}

// What every vertex of a path needs: the scene, its BVH and lights, the
// parameters, the roulette threshold, the ray counter and, when not null,
// the list of rays cast, (pilot paths) the roulette points met and shadow
// rays cast, the shadow rays' allocation, the tally of what paths did and
// the roulette cache (which, when set, decides the roulette instead of the
// threshold).
struct trace_walk {
  const scene_data&                  scene;
  const scene_bvh&                   bvh;
  const trace_context&               context;
  const trace_params&                params;
  float                              roulette_threshold;
  int64_t&                           rays;
  std::vector<trace_ray>*            record          = nullptr;
  std::vector<trace_roulette_point>* roulette_points = nullptr;
  std::vector<trace_shadow_record>*  shadows         = nullptr;
  const trace_allocation*            allocation      = nullptr;
  trace_tally*                       tally           = nullptr;
  const trace_roulette_cache*        roulette        = nullptr;
  // With roulette_points: split paths (trace_path) turn their points into
  // tails here, each path's as soon as it ends (see record_path_tails).
  std::vector<trace_tail_record>*    tails           = nullptr;
};

// The cell of a grid (bounds, cells per axis, cells per unit length) that
// holds a point, the nearest for points outside; -1 without a grid.
static int find_grid_cell(
    const bbox3f& bounds, const vec3i& cells, const vec3f& cell_scale, const vec3f& position) {
  if (cells.x <= 0) return -1;
  auto local = (position - bounds.min) * cell_scale;
  if (!isfinite(local)) return -1;
  auto i = std::clamp((int)local.x, 0, cells.x - 1), j = std::clamp((int)local.y, 0, cells.y - 1),
       k = std::clamp((int)local.z, 0, cells.z - 1);
  return (k * cells.y + j) * cells.x + i;
}

int find_allocation_cell(const trace_allocation& allocation, const vec3f& position) {
  return find_grid_cell(allocation.bounds, allocation.cells, allocation.cell_scale, position);
}

int find_roulette_cell(const trace_roulette_cache& cache, const vec3f& position) {
  return find_grid_cell(cache.bounds, cache.cells, cache.cell_scale, position);
}

// sqrt(M2 / c) of a cell's fit in a direction.
static float eval_tail_worth(const std::array<float, 8>& tail, const vec3f& direction) {
  auto moment = tail[0] + tail[1] * direction.x + tail[2] * direction.y + tail[3] * direction.z;
  auto cost   = tail[4] + tail[5] * direction.x + tail[6] * direction.y + tail[7] * direction.z;
  // A linear fit may fall below zero towards directions its cell's tails
  // rarely took: no worth there; and a tail costs at least its next ray.
  return std::sqrt(std::max(moment, 0.0f) / std::max(cost, 1.0f));
}

// A cell's control variate in a direction: the mean tail per unit
// throughput, at least zero (any mu keeps the estimate unbiased; a negative
// one could only be a fit's error).
static vec3f eval_tail_mean(const std::array<float, 16>& control, const vec3f& direction) {
  auto mean = vec3f{0, 0, 0};
  for (auto c = 0; c < 3; c++)
    mean[c] = std::max(control[4 * c] + control[4 * c + 1] * direction.x +
                           control[4 * c + 2] * direction.y + control[4 * c + 3] * direction.z,
        0.0f);
  return mean;
}

// roulette_survival in a cell already found: sqrt(R / c) with a control
// variate, sqrt(M2 / c) without.
static float roulette_survival(
    const trace_roulette_cache& cache, int cell, const vec3f& direction, float weight) {
  if (cell < 0 || !(weight > 0)) return std::min(std::max(weight, 0.0f), 1.0f);
  auto tail = cache.tails[cell];
  if (!cache.controls.empty())
    for (auto i = 0; i < 4; i++) tail[i] = cache.controls[cell][12 + i];
  auto survive = weight * eval_tail_worth(tail, direction) / cache.pixel_deviation;
  // As the global threshold's clamp: never below the throughput itself,
  // nor above 16 times it.
  survive = std::clamp(survive, weight, 16 * weight);
  return std::isfinite(survive) ? std::min(survive, 1.0f) : std::min(weight, 1.0f);
}

float roulette_survival(const trace_roulette_cache& cache, const vec3f& position,
    const vec3f& direction, float weight) {
  return roulette_survival(cache, find_roulette_cell(cache, position), direction, weight);
}

// A pilot path's tail at one of its roulette points, now that the path
// has ended with `radiance` gathered and `rays` cast: as if no roulette had
// been played at the point, its squared radiance per unit of throughput and
// its rays, weighted by the inverse probability of having survived it (zero
// if it did not); with `record`, the cache's record of it where finite.
// False for a point that gives no tail.
static bool measure_path_tail(const trace_roulette_point& point, const vec3f& radiance,
    int64_t rays, double& moment, double& cost, std::vector<trace_tail_record>* record) {
  if (!(point.weight > 0) || !(point.survive > 0)) return false;
  auto tail = glm::dvec3(radiance - point.radiance) / (double)point.weight;
  moment    = point.survive * glm::dot(tail, tail) / 3;
  cost      = (double)(rays - point.rays) / point.survive;
  if (record && std::isfinite(moment) && std::isfinite(cost) && isfinite(vec3f(tail)))
    record->push_back({point.position, point.direction, (float)moment, (float)cost,
        vec3f(tail), point.throughput / point.weight});
  return true;
}

// The tails of the roulette points a split path met (from `first` on), for
// the roulette cache; the points are then dropped.
static void record_path_tails(std::vector<trace_roulette_point>& points, size_t first,
    const vec3f& radiance, int64_t rays, std::vector<trace_tail_record>& tails) {
  auto moment = 0.0, cost = 0.0;
  for (auto i = first; i < points.size(); i++)
    measure_path_tail(points[i], radiance, rays, moment, cost, &tails);
  points.resize(first);
}

static scene_intersection cast_closest(const trace_walk& walk, const ray3f& ray) {
  walk.rays++;
  if (walk.record) walk.record->push_back({ray, false});
  return intersect_scene_bvh(walk.bvh, ray);
}

// Adds to `radiance` what a path gathers from its scattering vertex `point`,
// reached by `ray` at `bounce` with throughput `weight`, on: next-event
// estimation there and at every later vertex, BSDF sampling, Russian
// roulette, and the emission that the sampled rays find. A path scatters at
// most params.bounces times (pbrt's maxdepth): the ray leaving the last
// scattering vertex is still traced for the emission it finds, so that its
// MIS weight and the light sample's add up to one.
//
// With `lobes` (four values, R to TRRT), the radiance of the path from its
// first hair scattering on is also added to the lobe it took there (the
// light sampled there by each lobe's term, the rest by the sampled lobe or
// by the lobes' shares of the sampled direction's value): see AOVS.
static void scatter_path(const trace_walk& walk, material_point point, ray3f ray, int bounce,
    vec3f weight, sequence_state& sequence, vec3f& radiance, vec3f* lobes = nullptr) {
  auto& [scene, bvh, context, params, threshold, rays, record, points, shadows, allocation,
      tally, roulette, tails] = walk;
  auto use_mis = params.sampler == trace_sampler_type::path;
  // Next-event estimation, when there are lights to sample; MIS weighs the
  // BSDF samples that find lights with area, so only then is a BSDF pdf
  // needed (no BSDF sample finds a distant light).
  auto samples_lights = paths_sample_lights(params, context);
  auto needs_pdf      = samples_lights && context.mis_lights;
  // The lobe split: at the first hair vertex, each lobe's share of what the
  // rest of the path brings (radiance beyond `lobe_mark`).
  auto split_lobes  = false;
  auto lobe_shares  = std::array<vec3f, 4>{};
  auto lobe_mark    = vec3f{0, 0, 0};
  for (;; bounce++) {
    auto outgoing = -ray.d;
    auto first_hair = lobes && !split_lobes && point.type == material_type::hair;
    if (tally) tally->vertices++;
    // Next-event estimation: one light, one shadow ray.
    auto pairs = trace_bounce_pairs(bounce);
    if (samples_lights) {
      auto  nlights = (int)context.lights.size();
      auto  choice  = sample_sequence2f(sequence, pairs + trace_pair_light);
      auto& light   = context.lights[std::min((int)(choice.x * nlights), nlights - 1)];
      auto  rel     = choice.y;
      auto  ruv     = sample_sequence2f(sequence, pairs + trace_pair_light_point);
      auto  sample  = sample_light(scene, light, point.position, rel, ruv);
      auto  incoming = sample.incoming;
      // The shadow ray is cast only for a sample that would add light if
      // visible, with the allocation's probability for its region (see
      // trace_allocation) or, without one, a sky sample that would add
      // little (below params.shadow_threshold times the sky's average
      // radiance, the value of a white surface under it) with probability
      // proportional to what it adds; it is weighted up when it is cast, so
      // that the estimate is unbiased.
      if (incoming != vec3f{0, 0, 0} && may_scatter(point, outgoing, incoming)) {
        auto [emission, pdf, delta] = eval_light_sample(scene, context, light, sample, incoming);
        if (pdf > 0 && emission != vec3f{0, 0, 0}) {
          // A delta light takes no MIS weight: no pdf.
          auto bsdfcos     = vec3f{0, 0, 0};
          auto scatter_pdf = 0.0f;
          if (delta) bsdfcos = eval_bsdfcos(point, outgoing, incoming);
          else std::tie(bsdfcos, scatter_pdf) = eval_bsdfcos_and_pdf(point, outgoing, incoming);
          auto mis      = delta ? 1.0f : power_heuristic(pdf, scatter_pdf);
          auto contribution = weight * bsdfcos * emission * (mis / pdf);
          auto value    = max_component(contribution);
          auto survive  = 1.0f;
          auto cell     = allocation ? find_allocation_cell(*allocation, point.position) : -1;
          if (cell >= 0) {
            survive = std::min(
                value * allocation->visibility[cell] / allocation->pixel_deviation, 1.0f);
          } else {
            auto threshold = params.shadow_threshold * light.radiance;
            survive = value > 0 && value < threshold ? value / threshold : 1.0f;
          }
          if (tally && value > 0) tally->light_samples++;
          if (value > 0 && survive > 0 &&
              (survive == 1 || sample_sequence2f(sequence, pairs + trace_pair_shadow).x < survive)) {
            auto shadow = spawn_ray(point, incoming);
            // Area lights: visibility of the sampled point itself (stopping
            // just short of it), as a light may hide part of itself.
            if (light.instance >= 0)
              shadow.tmax = length(sample.position - shadow.o) * (1 - 1e-3f);
            if (record) record->push_back({shadow, true});
            rays++;
            if (tally) tally->shadow_rays++;
            auto visible = !intersect_scene_bvh_any(bvh, shadow);
            if (shadows) shadows->push_back({point.position, visible});
            if (visible) {
              radiance += contribution / survive;
              if (first_hair) {
                auto terms = eval_bsdfcos_lobes(point, outgoing, incoming);
                for (auto p = 0; p < 4; p++)
                  lobes[p] += weight * terms[p] * emission * (mis / pdf / survive);
              }
            }
          }
        }
      }
    }

    // BSDF sampling.
    auto lobe_roulette = sample_sequence2f(sequence, pairs + trace_pair_lobe_roulette);
    auto rn   = vec2f{0, 0}, more = vec2f{0, 0};
    if (bsdf_takes_more_numbers(point)) {
      auto numbers = sample_sequence4f(sequence, pairs + trace_pair_direction);
      rn = {numbers.x, numbers.y}, more = {numbers.z, numbers.w};
    } else {
      rn = sample_sequence2f(sequence, pairs + trace_pair_direction);
    }
    // The pdf only where an MIS weight will need it (0 otherwise). Hair
    // without it may choose its lobe by what the cache expects each lobe's
    // direction to be worth. A fibre that absorbs nothing keeps the
    // luminance choice: its every lobe weight is then exactly 1, the
    // zero-variance estimate of a uniform sky (the white furnace), which a
    // guide learned from noisy tails could only perturb.
    auto cell  = roulette ? find_roulette_cell(*roulette, point.position) : -1;
    auto guide = cell >= 0 && params.lobe_guide > 0 && !needs_pdf &&
                 point.type == material_type::hair &&
                 point.hair.material.sigma_a != vec3f{0, 0, 0};
    auto lobe_worth = std::array<float, 4>{};
    if (guide) {
      auto directions = hair_lobe_directions(point.hair, outgoing);
      for (auto p = 0; p < 4; p++)
        lobe_worth[p] = eval_tail_worth(roulette->tails[cell], directions[p]);
    }
    auto sample = sample_bsdf(point, outgoing, lobe_roulette.x, rn, more, needs_pdf,
        guide ? &lobe_worth : nullptr, params.lobe_guide);
    if (sample.weight == vec3f{0, 0, 0}) break;
    auto incoming = sample.incoming;
    auto bsdf_pdf = sample.pdf;
    weight *= sample.weight;
    if (first_hair) {
      if (sample.lobe >= 0) {
        lobe_shares[sample.lobe] = {1, 1, 1};
      } else {
        auto terms = eval_bsdfcos_lobes(point, outgoing, incoming);
        for (auto p = 0; p < 4; p++)
          for (auto c = 0; c < 3; c++)
            lobe_shares[p][c] = sample.bsdfcos[c] > 0 ? terms[p][c] / sample.bsdfcos[c] : 0.0f;
      }
    }
    if (!isfinite(weight)) break;
    if (first_hair) {
      split_lobes = true;
      lobe_mark   = radiance;
    }

    // Russian roulette from params.roulette_bounce on: a path survives with
    // the roulette cache's probability for where it is and where it goes
    // or, without one, throughput / threshold (the parameter's or the
    // pilot's), and is weighted up when it does (unbiased). Either is at
    // least the throughput: a path that carries all of its energy (a white
    // fiber) would gain variance and nothing else.
    auto survive = roulette ? roulette_survival(*roulette, cell, incoming, max_component(weight))
                            : max_component(weight) / threshold;
    if (bounce >= params.roulette_bounce) {
      if (points)
        points->push_back({max_component(weight), weight, std::min(survive, 1.0f), radiance,
            rays, point.position, incoming});
      if (survive < 1) {
        if (tally) tally->roulette_plays++;
        // The control variate: what the tail is expected to bring now, and
        // the difference from it if the path goes on.
        auto controlled = cell >= 0 && roulette && !roulette->controls.empty();
        auto control    = controlled ? weight * eval_tail_mean(roulette->controls[cell], incoming)
                                     : vec3f{0, 0, 0};
        if (lobe_roulette.y >= survive) {
          if (tally) tally->roulette_ends++;
          if (controlled) radiance += control;
          break;
        }
        if (controlled) radiance += control * (1 - 1 / survive);
        weight /= survive;
      }
    }
    ray               = spawn_ray(point, incoming);
    auto intersection = cast_closest(walk, ray);
    if (!intersection.hit) {
      radiance += weight * eval_environments(scene, context, ray.d, use_mis ? bsdf_pdf : 0);
      break;
    }
    point = eval_material_point(scene, context.shading, intersection.instance, intersection.element,
        intersection.uv, intersection.distance, ray);
    if (point.emission != vec3f{0, 0, 0}) {
      auto mis = 1.0f;
      if (use_mis && bsdf_pdf > 0) {
        auto light_pdf = area_light_pdf(scene, context, intersection.instance,
            intersection.distance, std::abs(dot(point.gnormal, -ray.d)));
        mis = power_heuristic(bsdf_pdf, light_pdf);
      }
      radiance += weight * point.emission * mis;
    }
    if (bounce + 1 >= params.bounces || scatters_nothing(point)) break;
  }
  if (split_lobes) {
    for (auto p = 0; p < 4; p++) lobes[p] += lobe_shares[p] * (radiance - lobe_mark);
  }
}

// The path tracer from a camera ray. With split > 1 the camera ray and its
// hit are shared by that many paths from the first scattering vertex on,
// each weighing 1 / split (with `continuations`, split values: what each
// path brought, for the plan's pilot); path k of sample s draws its numbers
// as sample s * split + k would, so the split paths of samples first ... end - 1 take
// exactly the points first * split ... end * split - 1 of every pair of
// dimensions past the camera's (stratified together, and any sample range
// still renders alone).
//
// With `aov`, what the sample adds to the AOVs (see AOVS in the header).
struct trace_aov_sample {
  vec3f                albedo   = {0, 0, 0};
  vec3f                normal   = {0, 0, 0};
  vec3f                tangent  = {0, 0, 0};
  std::array<vec3f, 4> lobes    = {};
  float                depth    = 0;
  bool                 hit      = false;
  bool                 hair     = false;
};
static vec3f trace_path(const trace_walk& walk, const ray3f& camera_ray,
    sequence_state& sequence, int split, trace_aov_sample* aov = nullptr,
    vec3f* continuations = nullptr) {
  auto& scene   = walk.scene;
  auto& context = walk.context;
  auto& params  = walk.params;
  auto intersection = cast_closest(walk, camera_ray);
  if (!intersection.hit) return eval_environments(scene, context, camera_ray.d, 0);
  auto point    = eval_material_point(scene, context.shading, intersection.instance,
      intersection.element, intersection.uv, intersection.distance, camera_ray);
  auto radiance = point.emission;  // camera rays take no MIS weight
  auto lobes    = aov ? aov->lobes.data() : nullptr;
  if (aov) {
    aov->hit     = true;
    aov->depth   = intersection.distance;
    aov->hair    = point.type == material_type::hair;
    aov->albedo  = eval_albedo(point, -camera_ray.d);  // in [0, 1]
    aov->normal  = point.normal;
    // A fibre seen end on has no side facing the camera: its end cap does.
    if (point.fiber && !(dot(point.normal, -camera_ray.d) > 1e-6f))
      aov->normal = dot(point.tangent, -camera_ray.d) >= 0 ? point.tangent : -point.tangent;
    aov->tangent = point.fiber ? point.tangent : point.normal;
  }
  if (params.bounces < 1 || scatters_nothing(point)) return radiance;
  split = std::max(split, 1);
  if (split == 1 && !continuations) {
    scatter_path(walk, point, camera_ray, 0, {1, 1, 1}, sequence, radiance, lobes);
    return radiance;
  }
  auto sample = sequence.index;
  auto sum    = vec3f{0, 0, 0};
  for (auto k = 0; k < split; k++) {
    sequence.index = sample * (uint32_t)split + (uint32_t)k;
    auto before    = sum;
    auto first     = walk.roulette_points ? walk.roulette_points->size() : 0;
    scatter_path(walk, point, camera_ray, 0, {1, 1, 1}, sequence, sum, lobes);
    if (continuations) continuations[k] = sum - before;
    if (walk.tails) record_path_tails(*walk.roulette_points, first, sum, walk.rays, *walk.tails);
  }
  sequence.index = sample;
  if (aov) {
    for (auto& lobe : aov->lobes) lobe /= (float)split;
  }
  return radiance + sum / (float)split;
}

vec3f trace_radiance(const scene_data& scene, const scene_bvh& bvh,
    const trace_context& context, const ray3f& ray, sequence_state& sequence,
    const trace_params& params, int64_t& rays) {
  auto threshold = params.roulette_threshold > 0 ? params.roulette_threshold : 1.0f;
  return trace_path({scene, bvh, context, params, threshold, rays}, ray, sequence, params.split);
}

}  // namespace yocto

// -----------------------------------------------------------------------------
// IMAGE RENDERING
// -----------------------------------------------------------------------------
namespace yocto {

// Most paths a sample of an adaptive pixel.
static const int adaptive_max_paths = 16;
// Most paths a camera ray of the per-pixel plan.
static const int trace_max_split = 8;

bool check_trace_params(const scene_data& scene, const trace_params& params,
    std::string& error) {
  if (scene.cameras.empty()) return error = "the scene has no camera", false;
  if (params.camera < 0 || params.camera >= (int)scene.cameras.size())
    return error = "camera " + std::to_string(params.camera) + " out of range", false;
  if (params.resolution < 1 || params.resolution > 65536)
    return error = "resolution must be in [1, 65536]", false;
  if (params.samples < 1) return error = "samples must be at least 1", false;
  if (params.bounces < 1) return error = "bounces must be at least 1", false;
  if (params.split < 0 || params.split > 1024)
    return error = "split must be 0 (automatic) or in [1, 1024]", false;
  // Split paths number their samples sample * split + k in 32 bits (for
  // the per-pixel plan, its largest split), adaptive pixels up to 16 paths a
  // sample too.
  auto adaptive = params.adaptive != trace_adaptive_type::off;
  auto split    = params.split > 0 ? params.split : adaptive ? trace_max_split : 1;
  if ((int64_t)params.samples * split > ((int64_t)1 << 32))
    return error = "samples times split must stay below 2^32", false;
  if (adaptive && (int64_t)params.samples * split * adaptive_max_paths > ((int64_t)1 << 32))
    return error = "samples times split (8 if automatic) times 16 must stay below 2^32 "
                   "with adaptive sampling",
           false;
  if (!(params.roulette_threshold >= 0) || !std::isfinite(params.roulette_threshold))
    return error = "roulette threshold must be 0 (automatic) or positive", false;
  if (!(params.clamp >= 0)) return error = "clamp must be 0 (none) or positive", false;
  if (!(params.lobe_guide >= 0 && params.lobe_guide <= 0.95f))
    return error = "lobe guide must be in [0, 0.95]", false;
  if (params.threads < 0) return error = "threads must be 0 (all) or positive", false;
  return true;
}

double trace_image_bytes(const scene_data& scene, const trace_params& params) {
  auto size = camera_resolution(scene.cameras[params.camera], params.resolution);
  // Adaptive sampling: the rates and splits, and the pilot's three buffers
  // and, while one is shrunk, six more (its two halves, its coarse field, a
  // window's sums and weights, a row).
  auto adaptive = params.adaptive != trace_adaptive_type::off
                      ? sizeof(float) + sizeof(uint8_t) + 9 * sizeof(double)
                      : 0;
  return (double)size.x * (double)size.y *
             (sizeof(fixed_sum3) + sizeof(vec3f) + 3 * sizeof(uint8_t) + adaptive) +
         trace_aov_bytes(scene, params);
}

// The AOV layers' channels, in the order of the sums: three per sum, the
// last sum holding depth, coverage and the count of samples that hit.
static const auto trace_aov_names = std::array<std::string, 7>{
    "albedo", "normal", "tangent", "hair_R", "hair_TT", "hair_TRT", "hair_TRRT"};

double trace_aov_bytes(const scene_data& scene, const trace_params& params) {
  if (!params.aovs) return 0;
  auto size = camera_resolution(scene.cameras[params.camera], params.resolution);
  // The sums, and the layers' floats when they are saved (23 channels).
  return (double)size.x * (double)size.y *
         (trace_aov_sums * sizeof(fixed_sum3) + 23 * sizeof(float));
}

// The AOV layers with pixel i's sums scaled by scale(i).
template <typename Scale>
static std::vector<image_layer> get_aov_layers_scaled(int width, int height,
    const std::vector<fixed_sum3>& aov_sums, const Scale& pixel_scale) {
  auto pixels = (size_t)width * (size_t)height;
  auto layers = std::vector<image_layer>{};
  if (aov_sums.size() != pixels * trace_aov_sums) return layers;
  for (auto k = 0; k < 7; k++) {
    auto directions = k == 1 || k == 2;
    layers.push_back({trace_aov_names[k],
        directions ? std::vector<std::string>{"X", "Y", "Z"}
                   : std::vector<std::string>{"R", "G", "B"},
        std::vector<float>(pixels * 3)});
  }
  layers.push_back({"depth", {"Z"}, std::vector<float>(pixels)});
  layers.push_back({"coverage", {"Y"}, std::vector<float>(pixels)});
  for (size_t i = 0; i < pixels; i++) {
    auto scale = pixel_scale(i);
    auto sums  = &aov_sums[i * trace_aov_sums];
    for (auto k = 0; k < 7; k++) {
      auto value = fixed_to_double(sums[k]) * scale;
      for (auto c = 0; c < 3; c++) layers[k].pixels[i * 3 + c] = (float)value[c];
    }
    auto extra = fixed_to_double(sums[7]);  // depth, hair hits, hits
    layers[7].pixels[i] = extra[2] > 0 ? (float)(extra[0] / extra[2]) : 0.0f;
    layers[8].pixels[i] = (float)(extra[1] * scale);
  }
  return layers;
}

std::vector<image_layer> get_aov_layers(int width, int height,
    const std::vector<fixed_sum3>& aov_sums, int samples) {
  auto scale = samples > 0 ? 1.0 / samples : 0.0;
  return get_aov_layers_scaled(width, height, aov_sums, [scale](size_t) { return scale; });
}

void init_trace_state(trace_state& state, const scene_data& scene, const trace_params& params,
    int first) {
  auto size     = camera_resolution(scene.cameras[params.camera], params.resolution);
  state.width   = size.x;
  state.height  = size.y;
  state.first   = first;
  state.samples = 0;
  state.sums.assign((size_t)size.x * size.y, fixed_sum3{});
  state.aov_sums.assign(params.aovs ? (size_t)size.x * size.y * trace_aov_sums : 0, fixed_sum3{});
  state.clamped = 0;
  state.row_energy.assign(size.y, 0.0);
  state.row_clamped.assign(size.y, 0.0);
  state.rays      = 0;
  state.nonfinite = 0;
  state.roulette_threshold = 0;
  state.adaptive_gain      = 0;
  state.rates.clear();
  state.splits.clear();
  state.split      = 0;
  state.allocation = {};
  state.roulette_cache = {};
  state.vertices = 0, state.light_samples = 0, state.shadow_rays = 0;
  state.paths = 0, state.continuations = 0;
  state.roulette_plays = 0, state.roulette_ends = 0;
}

// Runs f(begin, end) over [0, size) in chunks on `threads` threads (0 for
// all), with the floating-point modes Embree asks for set in every thread.
template <typename Func>
static void parallel_chunks(int64_t size, int64_t grain, int threads, Func&& func) {
  auto arena = tbb::task_arena(threads > 0 ? threads : tbb::task_arena::automatic);
  arena.execute([&] {
    tbb::parallel_for(tbb::blocked_range<int64_t>(0, size, grain),
        [&](const tbb::blocked_range<int64_t>& range) {
          // Flush-to-zero and denormals-are-zero: denormals slow Embree's
          // curve intersection down.
          _MM_SET_FLUSH_ZERO_MODE(_MM_FLUSH_ZERO_ON);
          _MM_SET_DENORMALS_ZERO_MODE(_MM_DENORMALS_ZERO_ON);
          func(range.begin(), range.end());
        });
  });
}

// The allocation from the pilot's shadow rays (see trace_allocation): a
// grid over the points they left, of cells of about 256 rays each on
// average (at most 64 a side), each cell's fraction of visible rays shrunk
// towards the whole scene's by a prior of 16 rays.
// A grid over the finite positions of a pilot's records (rows of structs
// with a `position`), of about `per_cell` records a cell on average and at
// most `max_side` cells a side: its bounds, cells per axis and cells per unit
// length. False, and no grid, without a finite position.
template <typename Record>
static bool make_record_grid(const std::vector<std::vector<Record>>& rows, double per_cell,
    int max_side, bbox3f& bounds, vec3i& cells, vec3f& cell_scale) {
  bounds     = bbox3f{};
  auto count = (size_t)0;
  for (auto& row : rows) {
    for (auto& record : row) {
      if (!isfinite(record.position)) continue;
      bounds = merge(bounds, record.position);
      count++;
    }
  }
  if (count == 0) return false;
  // A flat or tiny cloud of points still gets cells of some size.
  auto extent = max(bounds.max - bounds.min, vec3f{1e-6f, 1e-6f, 1e-6f});
  extent      = max(extent, vec3f{1, 1, 1} * (max_component(extent) * 1e-3f));
  auto target = std::max((double)count / per_cell, 1.0);
  auto side   = std::cbrt((double)extent.x * extent.y * extent.z / target);
  for (auto a = 0; a < 3; a++)
    cells[a] = std::clamp((int)std::ceil(extent[a] / side), 1, max_side);
  cell_scale = vec3f(cells) / extent;
  return true;
}

static trace_allocation make_trace_allocation(
    const std::vector<std::vector<trace_shadow_record>>& rows, double pixel_deviation) {
  auto allocation = trace_allocation{};
  if (!(pixel_deviation > 0) || !std::isfinite(pixel_deviation)) return allocation;
  if (!make_record_grid(
          rows, 256, 64, allocation.bounds, allocation.cells, allocation.cell_scale))
    return {};
  allocation.pixel_deviation = (float)pixel_deviation;
  auto cells   = allocation.cells;
  auto ncells  = (size_t)cells.x * cells.y * cells.z;
  auto rays    = std::vector<double>(ncells), visible = std::vector<double>(ncells);
  auto total   = 0.0, total_visible = 0.0;
  for (auto& row : rows) {
    for (auto& shadow : row) {
      auto cell = find_allocation_cell(allocation, shadow.position);
      if (cell < 0) continue;
      rays[cell] += 1, visible[cell] += shadow.visible ? 1 : 0;
      total += 1, total_visible += shadow.visible ? 1 : 0;
    }
  }
  auto prior = 16.0, scene_visible = total_visible / std::max(total, 1.0);
  allocation.visibility.resize(ncells);
  for (size_t cell = 0; cell < ncells; cell++) {
    auto fraction = (visible[cell] + prior * scene_visible) / (rays[cell] + prior);
    allocation.visibility[cell] = (float)std::sqrt(std::clamp(fraction, 0.0, 1.0));
  }
  return allocation;
}

// Solves the 4 x 4 system a x = b (symmetric positive definite: a ridge
// fit's) by Cholesky; false if it is not.
static bool solve_ridge_system(std::array<double, 16> a, std::array<double, 4>& b) {
  for (auto k = 0; k < 4; k++) {
    for (auto m = 0; m < k; m++) a[k * 4 + k] -= a[k * 4 + m] * a[k * 4 + m];
    if (!(a[k * 4 + k] > 0)) return false;
    a[k * 4 + k] = std::sqrt(a[k * 4 + k]);
    for (auto i = k + 1; i < 4; i++) {
      for (auto m = 0; m < k; m++) a[i * 4 + k] -= a[i * 4 + m] * a[k * 4 + m];
      a[i * 4 + k] /= a[k * 4 + k];
    }
  }
  for (auto i = 0; i < 4; i++) {  // L y = b
    for (auto m = 0; m < i; m++) b[i] -= a[i * 4 + m] * b[m];
    b[i] /= a[i * 4 + i];
  }
  for (auto i = 3; i >= 0; i--) {  // L^T x = y
    for (auto m = i + 1; m < 4; m++) b[i] -= a[m * 4 + i] * b[m];
    b[i] /= a[i * 4 + i];
  }
  return true;
}

// a + b . d by least squares over points (1, d) with a ridge worth `ridge`
// of them towards a = prior, b = 0, given X^T X and X^T y; the prior where
// the system cannot be solved or its solution is not finite in float.
static std::array<float, 4> fit_ridge_line(const std::array<double, 16>& normal,
    const std::array<double, 4>& targets, double ridge, double prior) {
  auto a = normal;
  for (auto i = 0; i < 4; i++) a[i * 4 + i] += ridge;
  auto line = targets;
  line[0] += ridge * prior;
  auto fit = std::array<float, 4>{(float)prior, 0, 0, 0};
  if (!solve_ridge_system(a, line)) return fit;
  for (auto i = 0; i < 4; i++)
    if (!std::isfinite((float)line[i])) return fit;
  return {(float)line[0], (float)line[1], (float)line[2], (float)line[3]};
}

// Adds a point x = (1, d) to X^T X, and its value y to X^T y.
static void add_line_point(std::array<double, 16>& normal, const vec3f& direction) {
  auto x = std::array<double, 4>{1, direction.x, direction.y, direction.z};
  for (auto i = 0; i < 4; i++)
    for (auto k = 0; k < 4; k++) normal[i * 4 + k] += x[i] * x[k];
}
static void add_line_value(std::array<double, 4>& targets, const vec3f& direction, double value) {
  auto x = std::array<double, 4>{1, direction.x, direction.y, direction.z};
  for (auto i = 0; i < 4; i++) targets[i] += x[i] * value;
}

// The roulette cache from the pilot's tails (see trace_roulette_cache): a
// grid of cells of about 1,024 tails each on average (at most 16 a side);
// in each cell, M2 and c fitted as a + b . d by least squares with a ridge
// of 16 tails' weight towards the whole scene's means (a = mean, b = 0), so
// that a cell of few tails keeps near them. With `control`, the control
// variate the same way (see trace_roulette_cache): per cell the mean tail
// per unit throughput of each channel, then the tails' second moment about
// it, each tail's E[(T - w mu)^2] estimated without bias as
// M2 - 2 T . (w mu) / 3 + |w mu|^2 / 3 from its roulette-weighted T and M2.
static trace_roulette_cache make_roulette_cache(
    const std::vector<std::vector<trace_tail_record>>& rows, double pixel_deviation,
    double scene_moment, double scene_cost, bool control) {
  auto cache = trace_roulette_cache{};
  if (!(pixel_deviation > 0) || !std::isfinite(pixel_deviation) || !(scene_moment > 0) ||
      !(scene_cost > 0))
    return cache;
  if (!make_record_grid(rows, 1024, 16, cache.bounds, cache.cells, cache.cell_scale)) return {};
  cache.pixel_deviation = (float)pixel_deviation;
  auto cells  = cache.cells;
  auto ncells = (size_t)cells.x * cells.y * cells.z;
  auto ridge  = 16.0;
  // Per cell: X^T X and X^T y of the fits, X = (1, d); all tails share X.
  auto normal  = std::vector<std::array<double, 16>>(ncells);
  auto moments = std::vector<std::array<double, 4>>(ncells);
  auto costs   = std::vector<std::array<double, 4>>(ncells);
  for (auto& row : rows) {
    for (auto& tail : row) {
      auto cell = find_roulette_cell(cache, tail.position);
      if (cell < 0) continue;
      add_line_point(normal[cell], tail.direction);
      add_line_value(moments[cell], tail.direction, tail.moment);
      add_line_value(costs[cell], tail.direction, tail.cost);
    }
  }
  cache.tails.resize(ncells);
  for (size_t cell = 0; cell < ncells; cell++) {
    auto moment = fit_ridge_line(normal[cell], moments[cell], ridge, scene_moment);
    auto cost   = fit_ridge_line(normal[cell], costs[cell], ridge, scene_cost);
    for (auto i = 0; i < 4; i++) cache.tails[cell][i] = moment[i], cache.tails[cell][4 + i] = cost[i];
  }
  if (!control) return cache;

  // The means: per channel, the tail over the channel's throughput, fitted
  // where that throughput is not zero.
  auto mean_normal  = std::vector<std::array<std::array<double, 16>, 3>>(ncells);
  auto mean_targets = std::vector<std::array<std::array<double, 4>, 3>>(ncells);
  auto scene_mean = glm::dvec3{0, 0, 0}, scene_count = glm::dvec3{0, 0, 0};
  for (auto& row : rows) {
    for (auto& tail : row) {
      auto cell = find_roulette_cell(cache, tail.position);
      if (cell < 0) continue;
      for (auto c = 0; c < 3; c++) {
        if (!(tail.colour[c] > 0)) continue;
        auto value = (double)tail.tail[c] / tail.colour[c];
        add_line_point(mean_normal[cell][c], tail.direction);
        add_line_value(mean_targets[cell][c], tail.direction, value);
        scene_mean[c] += value, scene_count[c] += 1;
      }
    }
  }
  scene_mean /= glm::max(scene_count, glm::dvec3{1, 1, 1});
  cache.controls.resize(ncells);
  for (size_t cell = 0; cell < ncells; cell++) {
    for (auto c = 0; c < 3; c++) {
      auto mean = fit_ridge_line(mean_normal[cell][c], mean_targets[cell][c], ridge, scene_mean[c]);
      for (auto i = 0; i < 4; i++) cache.controls[cell][4 * c + i] = mean[i];
    }
  }
  // The second moments about the means, fitted as M2 was.
  auto residuals      = std::vector<std::array<double, 4>>(ncells);
  auto scene_residual = 0.0, residual_count = 0.0;
  for (auto& row : rows) {
    for (auto& tail : row) {
      auto cell = find_roulette_cell(cache, tail.position);
      if (cell < 0) continue;
      auto expected = glm::dvec3(tail.colour * eval_tail_mean(cache.controls[cell], tail.direction));
      auto residual = tail.moment - 2 * glm::dot(glm::dvec3(tail.tail), expected) / 3 +
                      glm::dot(expected, expected) / 3;
      add_line_value(residuals[cell], tail.direction, residual);
      scene_residual += residual, residual_count += 1;
    }
  }
  scene_residual = std::max(scene_residual / std::max(residual_count, 1.0), 0.0);
  for (size_t cell = 0; cell < ncells; cell++) {
    auto residual = fit_ridge_line(normal[cell], residuals[cell], ridge, scene_residual);
    for (auto i = 0; i < 4; i++) cache.controls[cell][12 + i] = residual[i];
  }
  return cache;
}

// The roulette threshold of a render, from a pilot: Rath et al. 2022
// (Efficiency-Aware Russian Roulette and Splitting, EARS) give a path of
// throughput w the survival probability q = w sqrt(E[L^2] / c) /
// sqrt(V / C) that maximises the efficiency of the image (1 / (MSE x cost)),
// where L is the radiance the path's tail brings per unit of throughput and c
// its cost, V and C the variance and cost of a pixel sample. With one global
// estimate of each, q = w / threshold for threshold = sqrt(V / C) /
// sqrt(E[L^2] / c), costs in rays. The pilot renders two sets of 8 samples
// of up to 4,096 pixels on a grid (a pure function of the scene, the
// parameters and the seed, so that every part of a render finds the same
// threshold), with a threshold of 0.5 (between the extremes of the benchmark
// scenes); the spread of the two sets' means gives V as the render's
// stratified numbers make it. The tails are those of the pilot's own
// roulette, each weighted by the inverse of its survival probability. With
// params.roulette_cache, the same tails, with where they left from and in
// which direction, give the roulette cache (see make_roulette_cache); with
// params.allocation, its shadow rays give the allocation's visibility (see
// make_trace_allocation).
// A pilot's tails kept for a second fit of the roulette cache (see
// init_roulette_threshold): per grid row, and the scalars of the first fit.
struct trace_pilot_tails {
  std::vector<std::vector<trace_tail_record>> rows = {};
  double pixel_deviation = 0, moment = 0, cost = 0;
};
static trace_pilot run_trace_pilot(const scene_data& scene, const scene_bvh& bvh,
    const trace_context& context, const trace_params& params, trace_pilot_tails* kept) {
  auto size   = camera_resolution(scene.cameras[params.camera], params.resolution);
  // 1% of the render's samples (2 x 8 on up to 1/1600 of its pixel samples),
  // but no fewer than 64 pixels (more than 1% of a tiny render) and no more
  // than 4,096.
  auto pilot_samples = 8, pilot_pixels = (int)std::clamp(
      (double)size.x * size.y * params.samples / 1600, 64.0, 4096.0);
  auto pilot_threshold = 0.5f;
  auto stride = std::max(1, (int)std::ceil(std::sqrt((double)size.x * size.y / pilot_pixels)));
  auto nx = std::max(size.x / stride, 1), ny = std::max(size.y / stride, 1);
  auto pilot  = params;
  pilot.split = 1;
  auto& camera = scene.cameras[params.camera];
  // Per grid row: squared difference of the two sets' pixel means, pixels,
  // rays, samples, tail second moment, tail rays and roulette points; added
  // in row order.
  auto rows = std::vector<std::array<double, 7>>(ny);
  // Per grid row, with params.allocation: the shadow rays cast; with
  // params.roulette_cache: the tails.
  auto row_shadows = std::vector<std::vector<trace_shadow_record>>(params.allocation ? ny : 0);
  auto row_tails   = std::vector<std::vector<trace_tail_record>>(params.roulette_cache ? ny : 0);
  parallel_chunks(ny, 1, params.threads, [&](int64_t begin, int64_t end) {
    auto points = std::vector<trace_roulette_point>{};
    auto rays   = (int64_t)0;
    auto walk   = trace_walk{scene, bvh, context, pilot, pilot_threshold, rays, nullptr, &points};
    auto shadows = std::vector<trace_shadow_record>{};
    if (params.allocation) walk.shadows = &shadows;
    for (auto row = begin; row < end; row++) {
      auto& sums = rows[row];
      sums       = {};
      shadows.clear();
      auto tails = std::vector<trace_tail_record>{};
      auto j     = std::min((int)row * stride + stride / 2, size.y - 1);
      for (auto column = 0; column < nx; column++) {
        auto i     = std::min(column * stride + stride / 2, size.x - 1);
        auto pixel = (int64_t)j * size.x + i;
        // Two sets of samples with independent scrambles: the spread of
        // their means is the variance of a pixel as the render's numbers
        // stratify it, not as independent ones would.
        glm::dvec3 means[2];
        for (auto set = 0; set < 2; set++) {
          auto seed = hash_uint64(params.seed ^ (0x70696c6f74ULL + (uint64_t)set));  // "pilot"
          auto set_sum = glm::dvec3{0, 0, 0};
          for (auto s = 0; s < pilot_samples; s++) {
            rays          = 0;
            auto sequence = make_pixel_sequence(context, pilot, seed, pixel, (uint32_t)s);
            auto ray = sample_camera_ray(camera, i, j, size.x, size.y, sequence);
            if (!is_traceable_ray(ray)) continue;
            points.clear();
            auto radiance = trace_path(walk, ray, sequence, 1);
            if (!isfinite(radiance)) continue;
            set_sum += glm::dvec3(radiance);
            sums[2] += (double)rays;
            sums[3] += 1;
            for (auto& point : points) {
              auto moment = 0.0, cost = 0.0;
              if (!measure_path_tail(point, radiance, rays, moment, cost,
                      params.roulette_cache ? &tails : nullptr))
                continue;
              sums[4] += moment;
              sums[5] += cost;
              sums[6] += 1;
            }
          }
          means[set] = set_sum / (double)pilot_samples;
        }
        auto difference = means[0] - means[1];
        sums[0] += glm::dot(difference, difference) / 3;
        sums[1] += 1;
      }
      if (params.allocation) row_shadows[row] = shadows;
      if (params.roulette_cache) row_tails[row] = std::move(tails);
    }
  });
  auto totals = std::array<double, 7>{};
  for (auto& sums : rows)
    for (auto k = 0; k < 7; k++) totals[k] += sums[k];
  auto pilot_result = trace_pilot{};
  if (!(totals[1] > 0 && totals[3] > 0 && totals[6] > 0)) return pilot_result;
  // Var(mean A - mean B) = 2 V / n for V the variance of one sample.
  auto pixel_variance = pilot_samples * totals[0] / totals[1] / 2;
  auto pixel_cost     = totals[2] / totals[3];
  auto tail_moment = totals[4] / totals[6], tail_cost = totals[5] / totals[6];
  if (!(tail_moment > 0) || !(tail_cost > 0)) return pilot_result;
  auto threshold = std::sqrt(pixel_variance / pixel_cost) / std::sqrt(tail_moment / tail_cost);
  if (!std::isfinite(threshold)) return pilot_result;
  pilot_result.roulette_threshold = (float)std::clamp(threshold, 1.0 / 16, 1.0);
  if (params.allocation)
    pilot_result.allocation =
        make_trace_allocation(row_shadows, std::sqrt(pixel_variance / pixel_cost));
  if (params.roulette_cache)
    pilot_result.roulette_cache = make_roulette_cache(
        row_tails, std::sqrt(pixel_variance / pixel_cost), tail_moment, tail_cost,
        params.roulette_control);
  if (kept && pilot_result.roulette_cache.cells.x > 0)
    *kept = {std::move(row_tails), std::sqrt(pixel_variance / pixel_cost), tail_moment, tail_cost};
  return pilot_result;
}
trace_pilot run_trace_pilot(const scene_data& scene, const scene_bvh& bvh,
    const trace_context& context, const trace_params& params) {
  return run_trace_pilot(scene, bvh, context, params, nullptr);
}

float estimate_roulette_threshold(const scene_data& scene, const scene_bvh& bvh,
    const trace_context& context, const trace_params& params) {
  return run_trace_pilot(scene, bvh, context, params).roulette_threshold;
}

// Box averages over (2 radius + 1)^2 pixels, rows then columns (the same
// sums whatever the threads).
static void box_average(std::vector<double>& values, vec2i size, int radius) {
  auto row = std::vector<double>(values.size());
  for (auto j = 0; j < size.y; j++) {
    for (auto i = 0; i < size.x; i++) {
      auto sum = 0.0;
      auto lo = std::max(i - radius, 0), hi = std::min(i + radius, size.x - 1);
      for (auto k = lo; k <= hi; k++) sum += values[(size_t)j * size.x + k];
      row[(size_t)j * size.x + i] = sum / (hi - lo + 1);
    }
  }
  for (auto j = 0; j < size.y; j++) {
    auto lo = std::max(j - radius, 0), hi = std::min(j + radius, size.y - 1);
    for (auto i = 0; i < size.x; i++) {
      auto sum = 0.0;
      for (auto k = lo; k <= hi; k++) sum += row[(size_t)k * size.x + i];
      values[(size_t)j * size.x + i] = sum / (hi - lo + 1);
    }
  }
}

// The plan's pilot measures one pixel in two, those of a checkerboard's
// black squares; their even and odd columns are two independent halves.
static bool pilot_measures(int i, int j) { return (i + j) % 2 == 0; }

// Per pixel, the average of `values` over the pixels of its (2 radius + 1)^2
// window that `counts(i, j)` includes (`none` if it includes none).
template <typename Counts>
static std::vector<double> window_average(const std::vector<double>& values, vec2i size,
    int radius, Counts&& counts, double none = 0) {
  auto sums = std::vector<double>(values.size()), weights = std::vector<double>(values.size());
  for (auto j = 0; j < size.y; j++) {
    for (auto i = 0; i < size.x; i++) {
      auto pixel = (size_t)j * size.x + i;
      if (!counts(i, j)) continue;
      sums[pixel] = values[pixel], weights[pixel] = 1;
    }
  }
  box_average(sums, size, radius);
  box_average(weights, size, radius);
  for (size_t pixel = 0; pixel < sums.size(); pixel++)
    sums[pixel] = weights[pixel] > 0 ? sums[pixel] / weights[pixel] : none;
  return sums;
}

// A pilot's per-pixel estimates averaged over each pixel's window, shrunk
// towards the field four times coarser by as much as their noise calls for.
// The pilot's even and odd columns give two independent averages A and B of
// the same smooth field; across the image, the covariance of their
// departures from the coarse field C is the fine field's own variance s^2,
// and (A - B)^2 / 4 the noise n^2 of their mean. Each pixel takes C +
// s^2 / (s^2 + n^2) ((A + B) / 2 - C), the linear estimate of least squared
// error (James and Stein 1961): the fine averages where they stand out of
// their noise, the coarse field where the pilot saw only noise (an even
// noise would otherwise be planned as uneven, and the rates lose to a
// uniform render). Sums in pixel order: the same whatever the threads.
static void shrink_window_average(std::vector<double>& values, vec2i size, int radius) {
  auto none   = std::numeric_limits<double>::quiet_NaN();
  auto even   = window_average(values, size, radius,
      [](int i, int j) { return pilot_measures(i, j) && i % 2 == 0; }, none);
  auto odd    = window_average(values, size, radius,
      [](int i, int j) { return pilot_measures(i, j) && i % 2 == 1; }, none);
  auto coarse = window_average(values, size, 4 * radius, pilot_measures);
  auto signal = 0.0, noise = 0.0;
  for (size_t i = 0; i < values.size(); i++) {
    // A window with one half only (an image one pixel wide or high): that
    // half stands for both there (no noise is seen in it).
    if (std::isnan(even[i])) even[i] = odd[i];
    if (std::isnan(odd[i])) odd[i] = even[i];
    signal += (even[i] - coarse[i]) * (odd[i] - coarse[i]);
    noise += (even[i] - odd[i]) * (even[i] - odd[i]) / 4;
  }
  auto weight = signal > 0 ? signal / (signal + noise) : 0.0;
  if (!std::isfinite(weight)) weight = 0;
  for (size_t i = 0; i < values.size(); i++)
    values[i] = coarse[i] + weight * ((even[i] + odd[i]) / 2 - coarse[i]);
}

// The fewest paths a pixel may take: one every q samples, q a power of two
// that divides the sample count (up to 8), so that the render takes whole
// paths in every pixel.
static int max_sample_stride(int samples) {
  auto every = 1;
  while (every < 8 && samples % (every * 2) == 0) every *= 2;
  return every;
}

// Paths a sample per pixel (see estimate_pixel_plan). A pixel's camera hit
// is a 2D integrand with edges (fibres against the sky), whose variance
// under Owen-scrambled nets falls as n^-1.5 (Owen 1997), the paths after
// it as n^-1: its MSE after n camera samples is a n^-1.5 + b n^-1, a =
// V_hit, b = V_tail / k (variance - hit), for n c rays. Minimising the
// image's sum for a budget gives 1.5 a n^-2.5 + b n^-2 = lambda c in every
// pixel (solved for n by Newton's method, below), lambda the smallest whose
// rounded rates cost no more than `budget` rays a sample slot, summed over
// the pixels (bisection on log lambda). With a = 0 it is the allocation in
// proportion to sqrt(b / c). Variances that are not finite give every pixel
// a path a sample.
static std::vector<float> allocate_stratified_rates(const std::vector<double>& hit,
    const std::vector<double>& variance, const std::vector<double>& cost, double budget,
    int samples, int threads) {
  auto pixels = variance.size();
  auto max_every = max_sample_stride(samples);
  auto quantize = [&](double rate) -> float {
    if (rate >= 1) return (float)std::min((double)adaptive_max_paths, std::round(rate));
    auto every = 1;
    while (every < max_every && rate * every * std::sqrt(2.0) < 1) every *= 2;
    return 1.0f / (float)every;
  };
  auto rates = std::vector<float>(pixels, 1.0f);
  for (size_t i = 0; i < pixels; i++) {
    if (!std::isfinite(hit[i]) || !std::isfinite(variance[i])) return rates;
  }
  // With u = n^-1/2 the condition is 1.5 a u^5 + b u^4 = lambda c, convex
  // and increasing in u: Newton's method from the smaller of the roots of
  // either term alone (where the sum is between lambda c and twice it)
  // converges from above. Per pixel, those roots are (c / 1.5 a)^(1/5)
  // lambda^(1/5) and (c / b)^(1/4) lambda^(1/4).
  // Per pixel: 1.5 a, b and the two roots' factors.
  auto terms = std::vector<std::array<double, 4>>(pixels);
  for (size_t i = 0; i < pixels; i++) {
    auto a = 1.5 * hit[i], b = std::max(variance[i] - hit[i], 0.0);
    terms[i] = {a, b, a > 0 ? std::pow(cost[i] / a, 0.2) : flt_max,
        b > 0 ? std::sqrt(std::sqrt(cost[i] / b)) : flt_max};
  }
  auto camera_samples = [&](size_t i, double lambda, double lambda5, double lambda4) {
    auto [a, b, root_a, root_b] = terms[i];
    if (!(a > 0 || b > 0)) return 0.0;
    auto target = lambda * cost[i];
    auto u      = std::min(root_a * lambda5, root_b * lambda4);
    for (auto iteration = 0; iteration < 5; iteration++) {
      auto u3 = u * u * u;
      u -= (u3 * u * (a * u + b) - target) / (u3 * (5 * a * u + 4 * b));
    }
    return u > 0 ? 1 / (u * u) : 0.0;
  };
  auto rows = (int64_t)std::min(pixels, (size_t)1024);
  auto row_sums = std::vector<double>(rows);
  auto rates_at = [&](double lambda, bool store, std::vector<float>& rates) {
    auto lambda5 = std::pow(lambda, 0.2), lambda4 = std::sqrt(std::sqrt(lambda));
    parallel_chunks(rows, 1, threads, [&](int64_t begin, int64_t end) {
      for (auto row = begin; row < end; row++) {
        auto sum = 0.0;
        auto first = pixels * (size_t)row / (size_t)rows;
        auto last  = pixels * (size_t)(row + 1) / (size_t)rows;
        for (auto i = first; i < last; i++) {
          auto rate = quantize(camera_samples(i, lambda, lambda5, lambda4) / samples);
          if (store) rates[i] = rate;
          sum += rate * cost[i];
        }
        row_sums[row] = sum;
      }
    });
    auto spent = 0.0;
    for (auto sum : row_sums) spent += sum;  // in row order: the same whatever the threads
    return spent;
  };
  // The smallest lambda whose rounded rates cost no more than the budget.
  auto low = 1e-30, high = 1e30;
  if (!(rates_at(high, false, rates) <= budget)) return rates;
  for (auto iteration = 0; iteration < 60; iteration++) {
    auto middle = std::sqrt(low * high);
    if (rates_at(middle, false, rates) <= budget) high = middle;
    else low = middle;
  }
  rates_at(high, true, rates);
  return rates;
}

// The per-pixel plan (see the header): on one pixel in two, 2 camera
// samples, each hit continued by 2 paths, with numbers of their own; per
// pixel, the variance between the two paths of a hit (the tail's, V_tail),
// the variance of a hit's mean, V_hit + V_tail / 2, and the tail's rays,
// averaged over 7 x 7 pixels, the variances shrunk by their noise. Then per
// pixel the split and the rates.
// With `tails` (a list per image row), the tails of the pilot's paths too.
static trace_pixel_plan estimate_pixel_plan(const scene_data& scene, const scene_bvh& bvh,
    const trace_context& context, const trace_params& params, float roulette_threshold,
    const trace_allocation* allocation, const trace_roulette_cache* roulette_cache,
    std::vector<std::vector<trace_tail_record>>* tails) {
  auto  size   = camera_resolution(scene.cameras[params.camera], params.resolution);
  auto& camera = scene.cameras[params.camera];
  auto  pixels = (size_t)size.x * size.y;
  auto  tail_variance = std::vector<double>(pixels), hit_variance = std::vector<double>(pixels);
  auto  tail_cost     = std::vector<double>(pixels);
  auto  seed = hash_uint64(params.seed ^ 0x7261746573ULL);  // "rates"
  // Tails are kept on no more than 32,768 of the measured pixels (all of
  // them at 256 x 256; 1 in 32, picked by a hash, at 1920 x 1080), so that
  // their records stay small (on the peers' blond curly ball at 1920², 17 MB
  // more peak memory than without them).
  auto tail_stride = (uint64_t)std::max(1.0, std::ceil((double)pixels / 2 / 32768));
  parallel_chunks(size.y, 1, params.threads, [&](int64_t begin, int64_t end) {
    auto rays = (int64_t)0;
    auto points = std::vector<trace_roulette_point>{};
    auto walk = trace_walk{scene, bvh, context, params, roulette_threshold, rays, nullptr,
        nullptr, nullptr, allocation, nullptr, roulette_cache};
    for (auto j = (int)begin; j < (int)end; j++) {
      for (auto i = 0; i < size.x; i++) {
        if (!pilot_measures(i, j)) continue;
        auto pixel  = (int64_t)j * size.x + i;
        auto record = tails && hash_uint64(seed ^ (uint64_t)pixel) % tail_stride == 0;
        walk.roulette_points = record ? &points : nullptr;
        walk.tails           = record ? &(*tails)[j] : nullptr;
        auto means  = std::array<vec3f, 2>{};
        auto within = 0.0, camera_rays = 0.0;
        rays = 0;
        for (auto s = 0; s < 2; s++) {
          auto sequence = make_pixel_sequence(context, params, seed, pixel, (uint32_t)s);
          auto ray = sample_camera_ray(camera, i, j, size.x, size.y, sequence);
          if (!is_traceable_ray(ray)) continue;
          auto tails    = std::array<vec3f, 2>{};
          auto radiance = trace_path(walk, ray, sequence, 2, nullptr, tails.data());
          camera_rays += 1;
          if (!isfinite(radiance)) continue;
          means[s]        = radiance;
          auto difference = glm::dvec3(tails[0] - tails[1]);
          within += glm::dot(difference, difference) / 6;  // (a - b)^2 / 2, 3 channels
        }
        auto difference      = glm::dvec3(means[0] - means[1]);
        tail_variance[pixel] = within / 2;
        hit_variance[pixel]  = glm::dot(difference, difference) / 6;
        tail_cost[pixel]     = std::max(((double)rays - camera_rays) / 4, 0.0);
      }
    }
  });
  shrink_window_average(tail_variance, size, 3);
  shrink_window_average(hit_variance, size, 3);
  // The rays are not shrunk: a sky pixel's are exact (none after the
  // camera's), and shrunk towards the hair's they would budget rays that
  // are never cast.
  tail_cost = window_average(tail_cost, size, 3, pilot_measures);
  // Per pixel, a sample is a camera ray and its hit (one ray) continued by
  // k paths of c_tail rays each: its variance is V_hit + V_tail / k and
  // its cost 1 + k c_tail. The k that minimises their product is the
  // classic optimum of splitting (EARS's factor at the first vertex, from
  // the pixel's own statistics), searched over the integers 1 ... 8, and
  // no more than the fewest paths' stride q: a pixel at k paths a camera
  // ray and one camera ray every q samples then costs no more than a
  // uniform sample, so the budget below can always be met (no splits at an
  // odd sample count). The buffers then hold each pixel's V_hit, variance
  // and cost at that split (hit_variance held the variance of a hit's mean
  // until then).
  auto plan = trace_pixel_plan{};
  if (params.split == 0) plan.splits.assign(pixels, 1);
  // The budget is the rays of params.samples samples a pixel without the
  // plan (no rates, a pixel's split params.split or 1): `--samples N` costs
  // what N uniform samples cost, whatever rates and splits the plan picks,
  // so that a render at N is compared with others at N for the same work.
  auto budget = 0.0;
  for (size_t i = 0; i < pixels; i++) budget += 1 + std::max(params.split, 1) * tail_cost[i];
  auto  max_split = std::min(trace_max_split, max_sample_stride(params.samples));
  auto& variance  = tail_variance;
  auto& cost      = tail_cost;
  for (size_t i = 0; i < pixels; i++) {
    // Where no hit was continued (sky), there is no tail to split, and
    // none of the variance shrinking gave it is the tail's.
    auto tail = tail_cost[i] > 0 ? tail_variance[i] : 0.0;
    auto hit  = std::max(hit_variance[i] - tail / 2, 0.0);
    auto best = std::max(params.split, 1);
    if (params.split == 0 && tail_cost[i] > 0) {
      auto best_product = std::numeric_limits<double>::max();
      for (auto split = 1; split <= max_split; split++) {
        auto product = (hit + tail / split) * (1 + split * tail_cost[i]);
        if (product < best_product * (1 - 1e-9)) best = split, best_product = product;
      }
    }
    if (params.split == 0) plan.splits[i] = (uint8_t)best;
    variance[i]    = hit + tail / best;
    cost[i]        = 1 + best * tail_cost[i];
    hit_variance[i] = hit;
  }
  // The gain in efficiency the rates promise if variances fell as 1 /
  // samples: mean(v) mean(c) / mean(sqrt(v c))^2.
  auto variances = 0.0, costs = 0.0, deviations = 0.0;
  for (size_t i = 0; i < pixels; i++) {
    variances += variance[i];
    costs += cost[i];
    deviations += std::sqrt(variance[i] * cost[i]);
  }
  auto gain = deviations > 0 ? variances * costs / (deviations * deviations) : 1.0;
  plan.gain = std::isfinite(gain) ? (float)gain : 1.0f;
  plan.rates = allocate_stratified_rates(
      hit_variance, variance, cost, budget, params.samples, params.threads);
  return plan;
}
trace_pixel_plan estimate_pixel_plan(const scene_data& scene, const scene_bvh& bvh,
    const trace_context& context, const trace_params& params, float roulette_threshold,
    const trace_allocation* allocation, const trace_roulette_cache* roulette_cache) {
  return estimate_pixel_plan(
      scene, bvh, context, params, roulette_threshold, allocation, roulette_cache, nullptr);
}

// A pixel's adaptive rate (trace_state::rates) as m paths every sample or
// one path every q samples; {1, 1} without rates.
struct trace_pixel_paths {
  int paths = 1;
  int every = 1;
};
static trace_pixel_paths get_pixel_paths(const trace_state& state, size_t pixel) {
  auto rate = state.rates.empty() ? 1.0f : state.rates[pixel];
  if (rate >= 1) return {(int)rate, 1};
  return {1, (int)std::lround(1 / rate)};
}

// Adds `count` samples to every pixel of the image rows; with `records`, the
// rays of row j go to (*records)[j].
static bool trace_rows(trace_state& state, const scene_data& scene, const scene_bvh& bvh,
    const trace_context& context, const trace_params& params, int count,
    std::vector<std::vector<trace_ray>>* records, const std::atomic<bool>* cancel = nullptr) {
  auto& camera     = scene.cameras[params.camera];
  auto  render_row = [&](int j) {
    auto rays = (int64_t)0, nonfinite = (int64_t)0, clamped = (int64_t)0;
    auto energy = 0.0, clamped_energy = 0.0;
    auto record = records ? &(*records)[j] : nullptr;
    auto tally  = trace_tally{};
    auto walk   = trace_walk{scene, bvh, context, params, state.roulette_threshold, rays,
        record, nullptr, nullptr, state.allocation.cells.x > 0 ? &state.allocation : nullptr,
        &tally, state.roulette_cache.cells.x > 0 ? &state.roulette_cache : nullptr};
    for (auto i = 0; i < state.width; i++) {
      auto pixel = j * state.width + i;
      auto& sum  = state.sums[pixel];
      auto  next = state.first + state.samples;
      // Adaptive rates: m paths a sample (numbers s m ... s m + m - 1), each
      // weighing 1 / m, or one path every q samples (numbers s / q) weighing
      // q; the paths of any range of samples are a pure function of it.
      auto [paths, every] = get_pixel_paths(state, pixel);
      auto split = state.splits.empty() ? state.split : (int)state.splits[pixel];
      auto path_weight    = (float)every / (float)paths;
      for (auto n = (int64_t)next * paths; n < (int64_t)(next + count) * paths; n++) {
        if (n % every != 0) continue;
        auto s        = (uint32_t)(n / every);
        auto sequence = make_pixel_sequence(context, params, params.seed, pixel, s);
        auto ray = sample_camera_ray(camera, i, j, state.width, state.height, sequence);
        // validate_scene checked the camera; a ray that round-off still
        // made untraceable counts as a dropped sample.
        if (!is_traceable_ray(ray)) {
          nonfinite++;
          continue;
        }
        auto aov      = trace_aov_sample{};
        auto radiance = trace_path(walk, ray, sequence, split, params.aovs ? &aov : nullptr);
        tally.paths++;
        tally.continuations += split;
        // The AOVs of the camera's hit count even if the path's radiance is
        // dropped (its lobes do not).
        auto add_aovs = [&](float lobe_scale) {
          if (!params.aovs) return;
          auto sums = &state.aov_sums[(size_t)pixel * trace_aov_sums];
          add_fixed(sums[0], aov.albedo * path_weight);
          add_fixed(sums[1], aov.normal * path_weight);
          add_fixed(sums[2], aov.tangent * path_weight);
          for (auto p = 0; p < 4; p++) {
            auto lobe = aov.lobes[p] * (lobe_scale * path_weight);
            if (isfinite(lobe) && max_component(abs(lobe)) < fixed_sum_max_sample)
              add_fixed(sums[3 + p], lobe);
          }
          if (aov.hit)
            add_fixed(sums[7], vec3f{aov.depth, aov.hair ? 1.0f : 0.0f, 1.0f} * path_weight);
        };
        if (!isfinite(radiance)) {
          nonfinite++;
          add_aovs(0);
          continue;
        }
        auto lobe_scale = 1.0f;
        // The energies only serve the clamped share: summed when clamping.
        if (params.clamp > 0) {
          auto sample_energy = (double)radiance.x + radiance.y + radiance.z;
          energy += sample_energy * path_weight;
          if (max_component(radiance) > params.clamp) {
            lobe_scale = params.clamp / max_component(radiance);
            radiance *= lobe_scale;
            clamped++;
            clamped_energy += (sample_energy - ((double)radiance.x + radiance.y + radiance.z)) *
                              path_weight;
          }
        }
        radiance *= path_weight;
        // Beyond what the exact sum holds (1e29): as good as infinite.
        if (max_component(abs(radiance)) >= fixed_sum_max_sample) {
          nonfinite++;
          add_aovs(0);
          continue;
        }
        add_fixed(sum, radiance);
        add_aovs(lobe_scale);
      }
    }
    state.rays += rays;
    state.vertices += tally.vertices;
    state.light_samples += tally.light_samples;
    state.shadow_rays += tally.shadow_rays;
    state.paths += tally.paths;
    state.continuations += tally.continuations;
    state.roulette_plays += tally.roulette_plays;
    state.roulette_ends += tally.roulette_ends;
    state.nonfinite += nonfinite;
    state.clamped += clamped;
    state.row_energy[j] += energy;
    state.row_clamped[j] += clamped_energy;
  };
  auto cancelled = std::atomic<bool>{false};
  parallel_chunks(state.height, 1, params.threads, [&](int64_t begin, int64_t end) {
    for (auto j = begin; j < end; j++) {
      if (cancel && cancel->load(std::memory_order_relaxed)) {
        cancelled = true;
        return;
      }
      render_row((int)j);
    }
  });
  if (cancelled) return false;
  state.samples += count;
  return true;
}

// The render's roulette threshold: the parameter's, or the pilot's (once),
// which also gives the shadow rays' allocation. Then the per-pixel plan
// (once, with the threshold and allocation the render uses), unless
// adaptive sampling is off.
static void init_roulette_threshold(trace_state& state, const scene_data& scene,
    const scene_bvh& bvh, const trace_context& context, const trace_params& params) {
  if (state.roulette_threshold > 0) return;
  auto pilot  = trace_pilot{};
  auto kept   = trace_pilot_tails{};
  auto lights = paths_sample_lights(params, context);
  if (params.roulette_threshold <= 0 || (params.allocation && lights))
    pilot = run_trace_pilot(scene, bvh, context, params, &kept);
  state.roulette_threshold = params.roulette_threshold > 0 ? params.roulette_threshold
                                                           : pilot.roulette_threshold;
  state.allocation = pilot.allocation;
  auto allocation  = state.allocation.cells.x > 0 ? &state.allocation : nullptr;
  // A threshold the user set holds everywhere.
  if (params.roulette_threshold <= 0) state.roulette_cache = pilot.roulette_cache;
  auto roulette = state.roulette_cache.cells.x > 0 ? &state.roulette_cache : nullptr;
  state.split   = std::max(params.split, 1);
  if (params.adaptive == trace_adaptive_type::off) return;
  // The plan's paths are the cache's second training set: its fit is made
  // again from both pilots' tails (about three times the first's at 256²,
  // spread over the image), which the render then uses. Not with the
  // control variate: its credits and debits are not the tails the fit
  // reads (a tail is zero where the roulette ended it).
  auto refit = roulette && !kept.rows.empty() && !params.roulette_control;
  auto plan_tails = std::vector<std::vector<trace_tail_record>>(
      refit ? camera_resolution(scene.cameras[params.camera], params.resolution).y : 0);
  auto plan = estimate_pixel_plan(scene, bvh, context, params, state.roulette_threshold,
      allocation, roulette, refit ? &plan_tails : nullptr);
  state.rates         = std::move(plan.rates);
  state.splits        = std::move(plan.splits);
  state.adaptive_gain = plan.gain;
  if (refit) {
    for (auto& row : plan_tails) kept.rows.push_back(std::move(row));
    auto cache = make_roulette_cache(
        kept.rows, kept.pixel_deviation, kept.moment, kept.cost, params.roulette_control);
    if (cache.cells.x > 0) state.roulette_cache = std::move(cache);
  }
}

bool trace_samples(trace_state& state, const scene_data& scene, const scene_bvh& bvh,
    const trace_context& context, const trace_params& params, int count,
    const std::atomic<bool>* cancel) {
  init_roulette_threshold(state, scene, bvh, context, params);
  return trace_rows(state, scene, bvh, context, params, count, nullptr, cancel);
}

double clamped_energy_fraction(const trace_state& state) {
  auto energy = 0.0, clamped = 0.0;
  for (auto j = 0; j < (int)state.row_energy.size(); j++) {
    energy += state.row_energy[j];
    clamped += state.row_clamped[j];
  }
  return energy > 0 ? clamped / energy : 0;
}

texture_data get_image(int width, int height, const std::vector<fixed_sum3>& sums,
    int samples) {
  auto image = texture_data{width, height, {}};
  auto scale = samples > 0 ? 1.0 / samples : 0.0;
  image.pixels.resize(sums.size());
  for (size_t i = 0; i < sums.size(); i++)
    image.pixels[i] = vec3f(fixed_to_double(sums[i]) * scale);
  return image;
}
// What a pixel's sums are multiplied by for the mean of its paths: 1 / n for
// n samples, unless the pixel takes one path every q samples (weighing q),
// and n is not a multiple of q: then 1 / (q t) for the t paths taken among
// samples first ... first + n - 1.
static double pixel_scale(const trace_state& state, size_t pixel) {
  if (state.samples <= 0) return 0;
  auto q = (int64_t)get_pixel_paths(state, pixel).every;
  if (q == 1) return 1.0 / state.samples;
  auto first = (int64_t)state.first, end = first + state.samples;
  auto paths = (end + q - 1) / q - (first + q - 1) / q;
  return paths > 0 ? 1.0 / (double)(q * paths) : 0.0;
}

texture_data get_image(const trace_state& state) {
  if (state.rates.empty()) return get_image(state.width, state.height, state.sums, state.samples);
  auto image = texture_data{state.width, state.height, {}};
  image.pixels.resize(state.sums.size());
  for (size_t i = 0; i < state.sums.size(); i++)
    image.pixels[i] = vec3f(fixed_to_double(state.sums[i]) * pixel_scale(state, i));
  return image;
}

std::vector<image_layer> get_aov_layers(const trace_state& state) {
  return get_aov_layers_scaled(state.width, state.height, state.aov_sums,
      [&state](size_t i) { return pixel_scale(state, i); });
}

}  // namespace yocto

// -----------------------------------------------------------------------------
// RAY CASTING ALONE
// -----------------------------------------------------------------------------
namespace yocto {

std::vector<trace_ray> record_trace_rays(trace_state& state, const scene_data& scene,
    const scene_bvh& bvh, const trace_context& context, const trace_params& params,
    int count) {
  auto records = std::vector<std::vector<trace_ray>>(state.height);
  init_roulette_threshold(state, scene, bvh, context, params);
  trace_rows(state, scene, bvh, context, params, count, &records);
  auto size = (size_t)0;
  for (auto& record : records) size += record.size();
  auto rays = std::vector<trace_ray>{};
  rays.reserve(size);
  for (auto& record : records) rays.insert(rays.end(), record.begin(), record.end());
  return rays;
}

int64_t cast_trace_rays(const scene_bvh& bvh, const std::vector<trace_ray>& rays, int threads) {
  auto hits = std::atomic<int64_t>{0};
  // Chunks of a few hundred consecutive rays: about one image row of a
  // render, so that the replay keeps the render's ray coherence.
  parallel_chunks((int64_t)rays.size(), 256, threads, [&](int64_t begin, int64_t end) {
    auto count = (int64_t)0;
    for (auto i = begin; i < end; i++) {
      auto& ray = rays[i];
      count += ray.any_hit ? intersect_scene_bvh_any(bvh, ray.ray)
                           : intersect_scene_bvh(bvh, ray.ray).hit;
    }
    hits += count;
  });
  return hits;
}

}  // namespace yocto
