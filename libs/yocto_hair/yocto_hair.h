//
// # Yocto/Hair: a physically based hair scattering model
//
// The model of Pharr, The Implementation of a Hair Scattering Model (2016),
// built on d'Eon et al., An Energy-Conserving Hair Reflectance Model (EGSR
// 2011) and Chiang et al., A Practical and Controllable Hair and Fur Model for
// Production Path Tracing (EGSR 2016). Depends on the math header alone.
//
// Use: once per material, `make_hair_precomputed` (or let `eval_hair_brdf`
// do it); once per hit, `eval_hair_brdf` with the fiber frame and the signed
// offset h; then `eval_hair_scattering`, `sample_hair_scattering` and
// `sample_hair_scattering_pdf` with world-space directions, both pointing away
// from the fiber. `eval_hair_scattering` returns the BSDF times the cosine
// (Yocto/GL's bsdfcos convention), so the path weight of a sampled direction
// is eval / pdf.
//
// Frame convention: x = fiber tangent, z = shading normal facing the outgoing
// direction, y = z × x. A ray arriving along -outgoing that passes the axis at
// signed distance h·radius, measured along y, has offset h: for a hit point p
// on a round fiber, h = dot(p - axis, y) / radius.
//

#ifndef YOCTO_HAIR_H_
#define YOCTO_HAIR_H_

#include <yocto/yocto_math.h>

#include <array>
#include <utility>

// -----------------------------------------------------------------------------
// HAIR MATERIAL AND BSDF
// -----------------------------------------------------------------------------
namespace yocto {

// What the json and pbrt loaders fill. Precedence as pbrt: sigma_a if given,
// else color if given, else melanin.
struct hair_material {
  vec3f sigma_a     = {0, 0, 0};  // used if has_sigma_a
  vec3f color       = {0, 0, 0};  // used if has_color
  float eumelanin   = 1.3f;
  float pheomelanin = 0.0f;
  float beta_m      = 0.3f;  // longitudinal roughness in [0, 1]
  float beta_n      = 0.3f;  // azimuthal roughness in [0, 1]
  float alpha       = 2.0f;  // scale tilt in degrees
  float eta         = 1.55f;
  bool  has_sigma_a = false;
  bool  has_color   = false;
  // Variation across a groom (eval_hair_material_point). The defaults vary
  // nothing: such a material is the same for every strand and point.
  float random_melanin   = 0;          // [0, 1]: per strand pigment factor spread
  float random_roughness = 0;          // [0, 1]: per strand beta_m, beta_n factor spread
  float tip_eumelanin    = 0;          // used if has_tip_eumelanin
  float tip_pheomelanin  = 0;          // used if has_tip_pheomelanin
  vec3f tip_color        = {0, 0, 0};  // used if has_tip_color
  vec3f tip_sigma_a      = {0, 0, 0};  // used if has_tip_sigma_a
  float tip_start        = 0;          // [0, 1): where the blend to the tip starts
  vec3f tint             = {1, 1, 1};  // dye colour; white adds no absorption
  bool  has_tip_eumelanin   = false;
  bool  has_tip_pheomelanin = false;
  bool  has_tip_color       = false;
  bool  has_tip_sigma_a     = false;
};

// Whether a material varies between strands or along them (any variation
// key away from its default): only then does a renderer need strands and
// eval_hair_material_point; otherwise one make_hair_precomputed serves all.
bool hair_material_varies(const hair_material& material);

// The material at one point of a groom, with nothing left to vary: r and r'
// are the strand's two random values in [0, 1) (random.x, random.y), u the
// point's place along the strand (0 at the root, 1 at the tip). The pigment parameter the material uses
// (precedence as above) is blended from the root's value to the tip's from
// u = tip_start to u = 1 (linearly, a tip value left out is the root's);
// then sigma_a = that pigment's absorption (the colour's mapped with the
// material's beta_n) times 1 + (2 r - 1) random_melanin (Cycles' Random
// Color: for melanin it is each concentration scaled by the factor, as
// sigma_a is linear in them), plus the tint's absorption (Chiang et al. 2016
// section 4.2, the colour mapping). beta_m and beta_n are scaled by 1 + (2 r'
// - 1) random_roughness (so that pigment and roughness vary independently)
// and clamped to [0.01, 1]. The result has has_sigma_a set.
hair_material eval_hair_material_point(
    const hair_material& material, const vec2f& random, float u);

// Everything that depends on the material alone; compute it once per material
// (the renderer may cache it) and pass it to eval_hair_brdf for each hit.
// Index p: 0 = R, 1 = TT, 2 = TRT, 3 = all higher orders (p_max).
struct hair_precomputed {
  vec3f sigma_a        = {0, 0, 0};  // absorption per unit radius
  float eta            = 1.55f;      // clamped to [1, 1000]
  float beta_m         = 0.3f;       // clamped to [0.01, 1]
  float beta_n         = 0.3f;       // clamped to [0.01, 1]
  float v[4]           = {0, 0, 0, 0};  // longitudinal variances
  float m_scale[4]     = {0, 0, 0, 0};  // 1 / (v (1 - e^(-2/v))), M_p's factor
  float m_tail[4]      = {0, 0, 0, 0};  // 1 - e^(-2/v), for sampling M_p
  float s              = 0;             // azimuthal logistic scale
  float n_scale        = 1;  // 1 / (F(pi) - F(-pi)), trimmed logistic norm
  float n_cdf_min      = 0;  // logistic F(-pi), for sampling N_p
  float sin_2k_alpha[3] = {0, 0, 0};  // sin of alpha, 2 alpha, 4 alpha
  float cos_2k_alpha[3] = {1, 1, 1};  // cos of alpha, 2 alpha, 4 alpha
};

// Terms that depend on the outgoing direction and h: attenuations A_p, lobe
// choice probabilities, azimuthal offsets Phi(p, h) and the tilted sines and
// cosines of theta_o of each longitudinal lobe.
struct hair_lobes {
  vec3f a[4]         = {};
  float a_pdf[4]     = {0, 0, 0, 0};
  float phi_shift[3] = {0, 0, 0};
  float sin_gamma_t  = 0, cos_gamma_t = 1;  // refracted offset angle
  float sin_theta[4] = {0, 0, 0, 0};
  float cos_theta[4] = {1, 1, 1, 1};
};

// Everything precomputed for one hit: the material terms, the offset h and
// the orthonormal fiber frame (x tangent, y = z × x, z normal); and, if the
// outgoing direction was given, the lobes for it, which the three scattering
// functions then reuse whenever they are called with that same direction (a
// path tracer makes three or four calls per hit, all with one outgoing).
struct hair_brdf {
  hair_precomputed material     = {};
  float            h            = 0;  // signed offset in [-1, 1]
  float            gamma_o      = 0;  // asin(h)
  float            cos_gamma_o  = 1;
  vec3f            x            = {1, 0, 0};
  vec3f            y            = {0, 1, 0};
  vec3f            z            = {0, 0, 1};
  bool             has_outgoing = false;  // lobes hold the terms of outgoing
  vec3f            outgoing     = {0, 0, 0};
  hair_lobes       lobes        = {};
};

// Material terms: clamped roughness, variances, logistic scale, tilt sines
// and cosines, and sigma_a chosen by the precedence above. fast_pow: beta^20
// and beta^22 by repeated squaring instead of std::pow (the thesis's
// variant; the same values within float rounding).
hair_precomputed make_hair_precomputed(
    const hair_material& material, bool fast_pow = false);

// The absorption make_hair_precomputed takes from a material (by the
// precedence above, negative components as 0, infinite ones as 1e30): the
// one term a renderer recomputes where only a groom's pigments vary.
vec3f make_hair_absorption(const hair_material& material);

// Per-hit terms. frame: x = fiber tangent, z = shading normal facing the
// outgoing direction, o unused; z is orthogonalised against x and y is
// rebuilt as z × x. h in [-1, 1] is the signed offset (clamped).
hair_brdf eval_hair_brdf(const hair_material& material, float h, const frame3f& frame);
hair_brdf eval_hair_brdf(
    const hair_precomputed& material, float h, const frame3f& frame);
// The same, with the terms of one outgoing direction computed once for all
// later calls with it (any other direction still works, at full cost).
hair_brdf eval_hair_brdf(const hair_precomputed& material, float h,
    const frame3f& frame, const vec3f& outgoing);

// BSDF times cosine (Yocto's bsdfcos convention): sum over p of M_p A_p N_p.
// World directions, both pointing away from the fiber.
vec3f eval_hair_scattering(
    const hair_brdf& brdf, const vec3f& outgoing, const vec3f& incoming);

// Samples an incoming direction from two uniform numbers in [0, 1), each
// split in two by demux_hair_sample; as a float carries 24 bits, 12 per
// output, the bits below are filled from a hash of the input, so the four
// numbers keep the Morton stratification without being quantised. Returns
// {0, 0, 0} if the fiber neither reflects nor transmits anything (then the
// pdf is 0 too).
vec3f sample_hair_scattering(
    const hair_brdf& brdf, const vec3f& outgoing, const vec2f& rn);
// The same from four independent uniform numbers: lobe choice, azimuth,
// longitudinal angle, rotation around the longitudinal cone.
vec3f sample_hair_scattering(
    const hair_brdf& brdf, const vec3f& outgoing, const vec4f& rn);

// A sampled direction with the weight of the lobe that drew it.
struct hair_sample {
  vec3f incoming = {0, 0, 0};  // zero if the fiber returns nothing
  int   lobe     = -1;         // p: 0 R, 1 TT, 2 TRT, 3 the higher orders; -1 none
  vec3f weight   = {0, 0, 0};
};

// The direction sample_hair_scattering draws from the same two numbers,
// with the weight A_p / P(p) of the lobe p it came from: each lobe's
// directions are drawn with density exactly M_p N_p, so this weight has the
// expectation of eval / pdf (the one-sample estimator of the lobe mixture)
// and costs no evaluation of M_p or N_p. Its luminance is the same constant
// (sum of the lobes' luminances) as that of eval / pdf, since the lobe is
// chosen by luminance. For a path tracer that needs no pdf of the direction
// (no multiple importance sampling against a light).
hair_sample sample_hair_scattering_weight(
    const hair_brdf& brdf, const vec3f& outgoing, const vec2f& rn);
// The same from four independent uniform numbers (as sample_hair_scattering).
hair_sample sample_hair_scattering_weight(
    const hair_brdf& brdf, const vec3f& outgoing, const vec4f& rn);

// Lobe guiding: the same with the lobe p chosen with probability
// (1 - guided) P(p) + guided P(p) worth_p / sum_q P(q) worth_q, P the
// luminance choice above and worth_p >= 0 what a renderer expects a
// direction of lobe p to be worth (say, what the light arriving from
// hair_lobe_directions' p-th direction adds per unit of cost); the weight is
// A_p over that probability, still unbiased. guided in [0, 0.95] (larger is
// taken as 0.95: a lobe rated 0 keeps a chance); with 0, or every worth 0,
// it is the unguided choice. No lobe's weight exceeds 1 / (1 - guided) times
// its unguided weight.
hair_sample sample_hair_scattering_weight(const hair_brdf& brdf, const vec3f& outgoing,
    const vec4f& rn, const std::array<float, 4>& worth, float guided);
hair_sample sample_hair_scattering_weight(const hair_brdf& brdf, const vec3f& outgoing,
    const vec2f& rn, const std::array<float, 4>& worth, float guided);

// A direction that stands for each lobe's incoming directions (p = 0 R to 3
// the higher orders): R, TT and TRT their centre, theta_i = -theta_o (tilted)
// at the azimuth Phi(p, h); the higher orders, of uniform azimuth, the mean
// of their directions, which lies along the fiber (not a unit vector).
std::array<vec3f, 4> hair_lobe_directions(const hair_brdf& brdf, const vec3f& outgoing);

// Solid-angle pdf of sample_hair_scattering.
float sample_hair_scattering_pdf(
    const hair_brdf& brdf, const vec3f& outgoing, const vec3f& incoming);

// eval_hair_scattering and sample_hair_scattering_pdf in one pass, with the
// same results: multiple importance sampling needs both for one pair of
// directions, and they share every M_p N_p product.
std::pair<vec3f, float> eval_hair_scattering_and_pdf(
    const hair_brdf& brdf, const vec3f& outgoing, const vec3f& incoming);

// The terms of eval_hair_scattering one lobe at a time, M_p A_p N_p for p =
// 0 (R), 1 (TT), 2 (TRT), 3 (TRRT and higher); they sum to it (up to
// rounding). A renderer splits a path's light by the lobe it took with them.
std::array<vec3f, 4> eval_hair_scattering_lobes(
    const hair_brdf& brdf, const vec3f& outgoing, const vec3f& incoming);

// Directional albedo rho(outgoing) = integral of eval_hair_scattering over
// all incoming directions: the fraction of light from `outgoing`'s direction
// that the fiber scatters, at the brdf's offset h. Each lobe's M_p N_p has
// unit integral (d'Eon's M_p is normalised for every theta_o, tilted or not;
// N_p is a normalised trimmed logistic, 1 / 2 pi for p_max), so it is exactly
// sum_p A_p(theta_o, h), with no quadrature (tested against one).
vec3f eval_hair_albedo(const hair_brdf& brdf, const vec3f& outgoing);

// Absorption coefficient from eumelanin and pheomelanin concentrations
// (d'Eon et al. 2011); negative concentrations count as 0.
vec3f hair_sigma_a_from_melanin(float eumelanin, float pheomelanin);
// Absorption coefficient giving roughly the color c after multiple
// scattering (Chiang et al. 2016, section 4.2). c is clamped to [FLT_MIN, 1]
// (the smallest normal float). Per channel it is invertible,
// c = exp(-sqrt(sigma_a) d(beta_n)) with d the polynomial of eq. 9, for every
// sigma_a up to (ln FLT_MIN / d)^2 (over 200 at any beta_n).
vec3f hair_sigma_a_from_color(const vec3f& color, float beta_n);

}  // namespace yocto

// -----------------------------------------------------------------------------
// BUILDING BLOCKS (exposed for tests and tools)
// -----------------------------------------------------------------------------
namespace yocto {

// Splits one uniform number into two by a Morton-curve demux: the number's 32
// leading bits, even bits to the first value and odd bits to the second (16
// bits each; F. Giesen, Decoding Morton Codes, 2009). Keeps stratification.
vec2f demux_hair_sample(float u);

// Exponentially scaled modified Bessel function I_0(x) e^(-x), x >= 0,
// accurate to float precision for every x (series, then asymptotic
// expansion). Bounded in (0, 1], so it never overflows.
float hair_bessel_i0e(float x);

// d'Eon's longitudinal lobe M_p for variance v (d'Eon et al. 2011, eq. 6),
// with theta_o already tilted and cos_theta_o >= 0. Normalised so that its
// integral times cos(theta_i) over theta_i in [-pi/2, pi/2] is 1.
float eval_hair_longitudinal(float v, float sin_theta_i, float cos_theta_i,
    float sin_theta_o, float cos_theta_o);

}  // namespace yocto

#endif
