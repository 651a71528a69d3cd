//
// # Yocto/Shading: from a hit to a material point, and every material's BSDF
//
// The one place that turns a ray's hit into what shading needs (a
// `material_point`: position, frame, emission, and the material's terms at
// that point, hair included, with a groom's variation per strand and along
// it) and that evaluates, samples and gives the pdf and albedo of every
// material kind: matte (Lambertian), glossy (a GGX dielectric coat over a
// Lambertian base) and hair (Yocto/Hair). An integrator asks it and knows no
// material. The hair sampling variants are options of the hair BSDF here.
//

#ifndef YOCTO_SHADING_H_
#define YOCTO_SHADING_H_

#include <array>
#include <utility>
#include <vector>

#include "yocto_scene.h"

// -----------------------------------------------------------------------------
// SHADING CONTEXT
// -----------------------------------------------------------------------------
namespace yocto {

// How the hair BSDF samples and prepares its terms (each a variant of the
// same estimator; the defaults are the fastest).
struct hair_sampling_params {
  // 4 numbers (two pairs of the pixel's sequence), not 2 demuxed into 4 as
  // in the thesis: under the global Sobol sequence the four are jointly
  // stratified, which the demux only approximates.
  bool four_numbers   = true;
  bool per_hit        = false;  // material terms at every hit (as the thesis)
  bool fast_pow       = false;  // beta^20, beta^22 by squaring, not std::pow
  // Weigh sampled hair directions by eval / pdf of the lobe mixture even
  // where no MIS needs the pdf (otherwise the lobe's own A_p / P(p)).
  bool mixture_weight = false;
};

// What shading precomputes once per scene: the hair terms that depend on the
// material alone (one per material); which instances' hair varies from point
// to point (a material that varies across a groom, hair_material_varies, or
// a shape with colours dressed by a hair material given by colour); and the
// strands of the shapes whose material varies (only those: the others need
// none).
struct shading_context {
  std::vector<hair_precomputed> hair          = {};  // per material
  std::vector<bool>             hair_varies   = {};  // per instance
  std::vector<fiber_strands>    strands       = {};  // per shape, empty if not needed
  hair_sampling_params          hair_sampling = {};
};

shading_context make_shading_context(
    const scene_data& scene, const hair_sampling_params& hair_sampling = {});

}  // namespace yocto

// -----------------------------------------------------------------------------
// MATERIAL POINTS
// -----------------------------------------------------------------------------
namespace yocto {

// What shading needs at a hit.
struct material_point {
  vec3f          position  = {0, 0, 0};
  vec3f          normal    = {0, 0, 1};  // shading normal, facing the outgoing side
  vec3f          gnormal   = {0, 0, 1};  // triangles: geometric normal (area-light pdfs)
  vec3f          emission  = {0, 0, 0};
  vec3f          color     = {0, 0, 0};
  float          roughness = 0;
  float          ior       = 1.5f;
  material_type  type      = material_type::matte;
  bool           fiber     = false;
  vec3f          axis      = {0, 0, 0};  // fibers: point on the axis
  float          radius    = 0;          // fibers: radius at the hit
  vec3f          tangent   = {1, 0, 0};  // fibers
  hair_brdf      hair      = {};         // hair, with the outgoing direction's terms
  hair_sampling_params hair_sampling = {};
};

// The point that a ray hit on element `element` of instance `instance` at
// Embree's uv and distance. A varying groom's hair there is the strand's
// material at that place (eval_hair_material_point), and of its terms only
// those that vary are computed again.
material_point eval_material_point(const scene_data& scene, const shading_context& context,
    int instance, int element, const vec2f& uv, float distance, const ray3f& ray);

// A black matte surface absorbs everything: a path ends there.
bool scatters_nothing(const material_point& point);

// A ray leaving a point: fibers by spawn_fiber_ray (yocto_scene), surfaces
// offset along the normal to the side of the direction.
ray3f spawn_ray(const material_point& point, const vec3f& direction);

}  // namespace yocto

// -----------------------------------------------------------------------------
// BSDFS
// -----------------------------------------------------------------------------
namespace yocto {

// BSDF times the cosine at the incoming direction (Yocto's bsdfcos); both
// directions point away from the point.
vec3f eval_bsdfcos(const material_point& point, const vec3f& outgoing, const vec3f& incoming);

// Solid-angle pdf of sample_bsdf.
float sample_bsdfcos_pdf(
    const material_point& point, const vec3f& outgoing, const vec3f& incoming);

// eval_bsdfcos and sample_bsdfcos_pdf together, for MIS; hair computes the
// lobe products they share once.
std::pair<vec3f, float> eval_bsdfcos_and_pdf(
    const material_point& point, const vec3f& outgoing, const vec3f& incoming);

// Whether eval_bsdfcos can be non-zero for this pair: surfaces scatter only
// into the hemisphere of the outgoing direction; fibers everywhere.
bool may_scatter(const material_point& point, const vec3f& outgoing, const vec3f& incoming);

// Whether sample_bsdf takes the two numbers `more` (hair sampled with four
// independent numbers).
bool bsdf_takes_more_numbers(const material_point& point);

// A sampled direction and its path weight (bsdfcos / pdf), zero if the
// point scatters nothing that way. With needs_pdf false (no MIS weight will
// need it), hair takes the weight A_p / P(p) of the lobe it drew and
// evaluates no lobe (unless hair_sampling.mixture_weight or four_numbers);
// pdf is then 0. rnl: glossy lobe choice; rn, more: the direction. With
// lobe_worth, that lobe weight comes from the guided lobe choice (hair only,
// without a pdf; see sample_hair_scattering_weight).
struct bsdf_sample {
  vec3f incoming = {0, 0, 0};
  vec3f weight   = {0, 0, 0};
  vec3f bsdfcos  = {0, 0, 0};  // when evaluated (pdf > 0)
  float pdf      = 0;
  int   lobe     = -1;  // hair drawn by its lobe weight: the lobe p
};
bsdf_sample sample_bsdf(const material_point& point, const vec3f& outgoing, float rnl,
    const vec2f& rn, const vec2f& more, bool needs_pdf,
    const std::array<float, 4>* lobe_worth = nullptr, float guided = 0);

// Hair: eval_bsdfcos lobe by lobe (R, TT, TRT, TRRT and higher), which sum
// to it; other materials have no lobes (zeros).
std::array<vec3f, 4> eval_bsdfcos_lobes(
    const material_point& point, const vec3f& outgoing, const vec3f& incoming);

// Directional albedo for the outgoing direction: hair the model's own (sum
// of A_p), matte its colour, glossy the Lambertian base under the coat plus
// the coat's Fresnel reflectance at the outgoing angle (GGX's own losses
// left out); in [0, 1].
vec3f eval_albedo(const material_point& point, const vec3f& outgoing);

}  // namespace yocto

#endif
