//
// Implementation of Yocto/Hair. Equations follow Pharr, The Implementation of
// a Hair Scattering Model (2016), "hair.pdf" below; the longitudinal lobe is
// d'Eon et al. 2011 (EGSR), its sampling d'Eon et al. 2013 (Importance
// Sampling for Physically-Based Hair Fiber Models), the roughness maps and
// colour inversion Chiang et al. 2016 (EGSR).
//

#include "yocto_hair.h"

#include <array>
#include <cstdint>
#include <limits>

// -----------------------------------------------------------------------------
// BUILDING BLOCKS
// -----------------------------------------------------------------------------
namespace yocto {

// Giesen's "Compact1By1": keeps the even bits of x, packed into 16 bits.
static uint32_t compact_1by1(uint32_t x) {
  x &= 0x55555555u;
  x = (x ^ (x >> 1)) & 0x33333333u;
  x = (x ^ (x >> 2)) & 0x0f0f0f0fu;
  x = (x ^ (x >> 4)) & 0x00ff00ffu;
  x = (x ^ (x >> 8)) & 0x0000ffffu;
  return x;
}

vec2f demux_hair_sample(float u) {
  // u in [0, 1) scaled to 32 bits; clamped so that u = 1 or garbage cannot
  // overflow the conversion.
  auto scaled = (double)std::clamp(u, 0.0f, 1.0f) * 4294967296.0;
  auto bits   = (uint32_t)std::min(scaled, 4294967295.0);
  return {compact_1by1(bits) / 65536.0f, compact_1by1(bits >> 1) / 65536.0f};
}

// Coefficients of the two expansions of I_0 used below, built at compile
// time: 1 / (k!)^2 for the power series in x^2/4 (A&S 9.6.12), and
// ((2k-1)!!)^2 / (k! 8^k) for the asymptotic series in 1/x (A&S 9.7.1).
template <int n>
static constexpr std::array<double, n> make_i0_series() {
  auto coefficients = std::array<double, n>{};
  auto c            = 1.0;
  for (auto k = 0; k < n; k++) {
    if (k > 0) c /= (double)k * k;
    coefficients[k] = c;
  }
  return coefficients;
}
template <int n>
static constexpr std::array<double, n> make_i0_asymptotic() {
  auto coefficients = std::array<double, n>{};
  auto c            = 1.0;
  for (auto k = 0; k < n; k++) {
    if (k > 0) c *= (2.0 * k - 1) * (2.0 * k - 1) / (8.0 * k);
    coefficients[k] = c;
  }
  return coefficients;
}
// Below x = 12 the series' 24 terms leave a relative error under 1e-12
// (below x = 3, 12 terms leave under 1e-10); from 12 on the asymptotic terms
// keep shrinking until k ~ 2x, and 15 of them leave under 1e-10.
static constexpr auto i0_series     = make_i0_series<24>();
static constexpr auto i0_asymptotic = make_i0_asymptotic<15>();

// MurmurHash3's 32-bit finaliser (Appleby): mixes every input bit into every
// output bit.
static uint32_t hash_bits(uint32_t x) {
  x ^= x >> 16;
  x *= 0x85ebca6bu;
  x ^= x >> 13;
  x *= 0xc2b2ae35u;
  x ^= x >> 16;
  return x;
}

// demux_hair_sample for the sampler. A float in [0, 1) resolves 24 bits near
// 1 and random number generators give 24 (multiples of 2^-24), so the 32-bit
// code has 8 bits the input does not carry: 12 bits per output, a 2^-12
// quantisation that a chi-square test detects in the tails of low-roughness
// lobes. Keep the Morton demux of the top 24 bits (and so the
// stratification), and fill the low 8 bits and a fraction below 2^-16 from a
// hash of the whole input.
static vec2f demux_hair_sample_filled(float u) {
  auto scaled   = (double)std::clamp(u, 0.0f, 1.0f) * 4294967296.0;
  auto bits     = (uint32_t)std::min(scaled, 4294967295.0);
  auto hash     = hash_bits(bits ^ 0x9e3779b9u);
  bits          = (bits & 0xffffff00u) | (hash & 0xffu);
  auto fraction = hash_bits(hash);
  auto x        = compact_1by1(bits) + (fraction & 0xffffu) / 65536.0f;
  auto y        = compact_1by1(bits >> 1) + (fraction >> 16) / 65536.0f;
  // x / 2^16 may round up to 1 in float.
  return {std::min(x / 65536.0f, 1 - flt_eps / 2),
      std::min(y / 65536.0f, 1 - flt_eps / 2)};
}

float hair_bessel_i0e(float x_) {
  // In double with positive terms only, so that the float result is within
  // rounding of the exact value.
  auto x = std::abs((double)x_);
  if (!(x < 1e30)) return 0;  // huge (I_0 e^-x -> 0) or NaN
  if (x < 12) {
    // Horner's rule in q^2 on the even and odd terms: two independent
    // chains of half the length, as the loop is latency bound.
    auto q = x * x / 4, q2 = q * q, even = 0.0, odd = 0.0;
    auto n = x < 3 ? 12 : (int)i0_series.size();
    for (auto k = n - 2; k >= 0; k -= 2) {
      even = even * q2 + i0_series[k];
      odd  = odd * q2 + i0_series[k + 1];
    }
    return (float)((even + q * odd) * std::exp(-x));
  } else {
    // I_0(x) e^-x sqrt(2 pi x) = sum_k c_k / x^k.
    auto y = 1 / x, sum = 0.0;
    for (auto k = (int)i0_asymptotic.size() - 1; k >= 0; k--) {
      sum = sum * y + i0_asymptotic[k];
    }
    return (float)(sum / std::sqrt(2 * 3.14159265358979323846 * x));
  }
}

// M_p with its material factor m_scale = 1 / (v (1 - e^{-2/v})) given.
// d'Eon 2011 eq. 6: M = csch(1/v) / (2v) e^{-b} I_0(a), a = cos_i cos_o / v,
// b = sin_i sin_o / v. With csch(1/v) = 2 e^{-1/v} / (1 - e^{-2/v}):
// M = m_scale e^{a - b - 1/v} [I_0(a) e^{-a}], and a - b - 1/v cancels
// analytically to -(1 - cos(theta_i + theta_o)) / v, which float keeps
// accurate even at v = 5e-5 where a, b and 1/v are all ~2e4.
static float eval_longitudinal(float v, float m_scale, float sin_i,
    float cos_i, float sin_o, float cos_o) {
  auto cos_sum = cos_i * cos_o - sin_i * sin_o;
  auto sin_sum = sin_i * cos_o + cos_i * sin_o;
  // 1 - cos(x) as sin^2(x) / (1 + cos(x)) near the peak, where the direct
  // difference would cancel.
  auto one_minus_cos = cos_sum > 0 ? sin_sum * sin_sum / (1 + cos_sum)
                                   : 1 - cos_sum;
  auto a = cos_i * cos_o / v;
  return m_scale * std::exp(-one_minus_cos / v) * hair_bessel_i0e(a);
}

static float longitudinal_scale(float v) { return 1 / (v * -std::expm1(-2 / v)); }

float eval_hair_longitudinal(float v, float sin_theta_i, float cos_theta_i,
    float sin_theta_o, float cos_theta_o) {
  if (!(v > 0)) return 0;
  return eval_longitudinal(v, longitudinal_scale(v), sin_theta_i,
      cos_theta_i, sin_theta_o, cos_theta_o);
}

}  // namespace yocto

// -----------------------------------------------------------------------------
// PIGMENTS AND MATERIAL TERMS
// -----------------------------------------------------------------------------
namespace yocto {

vec3f hair_sigma_a_from_melanin(float eumelanin, float pheomelanin) {
  // d'Eon et al. 2011, section 4: absorption per unit concentration.
  auto eumelanin_sigma_a   = vec3f{0.419f, 0.697f, 1.37f};
  auto pheomelanin_sigma_a = vec3f{0.187f, 0.4f, 1.05f};
  return std::max(eumelanin, 0.0f) * eumelanin_sigma_a +
         std::max(pheomelanin, 0.0f) * pheomelanin_sigma_a;
}

vec3f hair_sigma_a_from_color(const vec3f& color, float beta_n) {
  // Chiang et al. 2016, eq. 9. Colour 0 would need infinite absorption: the
  // smallest normal float stands for it, so that every sigma_a up to
  // (ln FLT_MIN / denom)^2 (over 200 at any beta_n) has a colour that gives
  // it exactly (USD import carries per-point melanin as such colours).
  auto b     = beta_n;
  auto denom = 5.969f - 0.215f * b + 2.532f * sqr(b) - 10.73f * b * sqr(b) +
               5.574f * sqr(sqr(b)) + 0.245f * b * sqr(sqr(b));
  auto sigma_a = vec3f{0, 0, 0};
  for (auto c = 0; c < 3; c++) {
    sigma_a[c] = sqr(std::log(std::clamp(color[c], std::numeric_limits<float>::min(), 1.0f)) / denom);
  }
  return sigma_a;
}

// A roughness the model can use: beta = 0 makes the variance 0 and every
// term NaN (pbrt-v3 issue #219); NaN is taken as pbrt's default.
static float usable_roughness(float beta) {
  return beta == beta ? std::clamp(beta, 0.01f, 1.0f) : 0.3f;
}

vec3f make_hair_absorption(const hair_material& material) {
  auto beta_n = usable_roughness(material.beta_n);
  // Precedence as pbrt: sigma_a, else colour, else melanin.
  auto sigma_a = vec3f{0, 0, 0};
  if (material.has_sigma_a) {
    sigma_a = glm::max(material.sigma_a, vec3f{0, 0, 0});
  } else if (material.has_color) {
    sigma_a = hair_sigma_a_from_color(material.color, beta_n);
  } else {
    sigma_a = hair_sigma_a_from_melanin(material.eumelanin, material.pheomelanin);
  }
  if (!isfinite(sigma_a)) sigma_a = glm::min(sigma_a, 1e30f);
  if (!isfinite(sigma_a)) sigma_a = {0, 0, 0};  // NaN input
  return sigma_a;
}

hair_precomputed make_hair_precomputed(const hair_material& material, bool fast_pow) {
  auto pre = hair_precomputed{};
  auto beta_m = usable_roughness(material.beta_m);
  auto beta_n = usable_roughness(material.beta_n);
  pre.beta_m = beta_m;
  pre.beta_n = beta_n;
  // eta < 1 has no meaning for a fiber in air; inf would make Fresnel NaN.
  pre.eta = material.eta == material.eta ? std::clamp(material.eta, 1.0f, 1e3f)
                                         : 1.55f;

  pre.sigma_a = make_hair_absorption(material);

  // hair.pdf eq. 4 (Chiang 2016 eq. 7): variance of the R lobe; TT is
  // narrower, TRT and beyond wider.
  auto v0 = sqr(0.726f * beta_m + 0.812f * sqr(beta_m) +
                3.7f * (fast_pow ? pow_int<20>(beta_m) : std::pow(beta_m, 20.0f)));
  pre.v[0] = v0;
  pre.v[1] = v0 / 4;
  pre.v[2] = 4 * v0;
  pre.v[3] = 4 * v0;
  for (auto p = 0; p < 4; p++) {
    pre.m_tail[p]  = -std::expm1(-2 / pre.v[p]);
    pre.m_scale[p] = 1 / (pre.v[p] * pre.m_tail[p]);
  }

  // hair.pdf eq. 8 (Chiang 2016 eq. 8): logistic scale; 0.265 is the
  // published constant.
  pre.s = std::sqrt(pif / 8) * (0.265f * beta_n + 1.194f * sqr(beta_n) +
                                   5.372f * (fast_pow ? pow_int<22>(beta_n)
                                                      : std::pow(beta_n, 22.0f)));
  // Logistic CDF F(x) = 1 / (1 + e^{-x/s}); F(pi) - F(-pi) = tanh(pi / 2s).
  pre.n_scale   = 1 / std::tanh(pif / (2 * pre.s));
  pre.n_cdf_min = 1 / (1 + std::exp(pif / pre.s));

  // Scale tilt: sines and cosines of alpha, 2 alpha and 4 alpha by the double
  // angle formulas.
  auto alpha = std::isfinite(material.alpha) ? radians(material.alpha) : 0.0f;
  pre.sin_2k_alpha[0] = std::sin(alpha);
  pre.cos_2k_alpha[0] = std::cos(alpha);
  for (auto k = 1; k < 3; k++) {
    pre.sin_2k_alpha[k] = 2 * pre.cos_2k_alpha[k - 1] * pre.sin_2k_alpha[k - 1];
    pre.cos_2k_alpha[k] = sqr(pre.cos_2k_alpha[k - 1]) -
                          sqr(pre.sin_2k_alpha[k - 1]);
  }
  return pre;
}

bool hair_material_varies(const hair_material& material) {
  return material.random_melanin != 0 || material.random_roughness != 0 ||
         material.has_tip_eumelanin || material.has_tip_pheomelanin ||
         material.has_tip_color || material.has_tip_sigma_a || material.tint != vec3f{1, 1, 1};
}

hair_material eval_hair_material_point(
    const hair_material& material, const vec2f& random, float u) {
  auto blend = material.tip_start < 1
                   ? std::clamp((u - material.tip_start) / (1 - material.tip_start), 0.0f, 1.0f)
                   : 0.0f;
  if (!(blend == blend)) blend = 0;
  // The pigment parameters at u (a tip value left out is the root's); their
  // absorption by make_hair_absorption's precedence.
  auto at_u = material;
  if (material.has_tip_sigma_a)
    at_u.sigma_a = material.sigma_a + (material.tip_sigma_a - material.sigma_a) * blend;
  if (material.has_tip_color)
    at_u.color = material.color + (material.tip_color - material.color) * blend;
  if (material.has_tip_eumelanin)
    at_u.eumelanin = material.eumelanin + (material.tip_eumelanin - material.eumelanin) * blend;
  if (material.has_tip_pheomelanin)
    at_u.pheomelanin = material.pheomelanin +
                       (material.tip_pheomelanin - material.pheomelanin) * blend;
  auto sigma_a = make_hair_absorption(at_u);
  sigma_a *= std::max(1 + (2 * random.x - 1) * material.random_melanin, 0.0f);
  if (material.tint != vec3f{1, 1, 1})
    sigma_a += hair_sigma_a_from_color(material.tint, usable_roughness(material.beta_n));
  auto point        = material;
  point.sigma_a     = sigma_a;
  point.has_sigma_a = true;
  if (material.random_roughness != 0) {
    auto scale = std::max(1 + (2 * random.y - 1) * material.random_roughness, 0.0f);
    point.beta_m = std::clamp(material.beta_m * scale, 0.01f, 1.0f);
    point.beta_n = std::clamp(material.beta_n * scale, 0.01f, 1.0f);
  }
  return point;
}

hair_brdf eval_hair_brdf(const hair_material& material, float h, const frame3f& frame) {
  return eval_hair_brdf(make_hair_precomputed(material), h, frame);
}

hair_brdf eval_hair_brdf(
    const hair_precomputed& material, float h, const frame3f& frame) {
  auto brdf     = hair_brdf{};
  brdf.material = material;
  brdf.h        = h == h ? std::clamp(h, -1.0f, 1.0f) : 0.0f;
  brdf.gamma_o  = safe_asin(brdf.h);
  brdf.cos_gamma_o = safe_sqrt(1 - sqr(brdf.h));
  // Orthonormal frame: x the tangent, z the normal made orthogonal to x,
  // y = z × x so that the sign of h matches the documented convention.
  auto x = safe_normalize(frame.x);
  auto z = safe_normalize(frame.z - dot(frame.z, x) * x);
  if (x == vec3f{0, 0, 0} || z == vec3f{0, 0, 0}) {
    auto basis = basis_fromz(x == vec3f{0, 0, 0} ? vec3f{1, 0, 0} : x);
    x          = basis[2];
    z          = basis[0];
  }
  brdf.x = x;
  brdf.y = cross(z, x);
  brdf.z = z;
  return brdf;
}

}  // namespace yocto

// -----------------------------------------------------------------------------
// SCATTERING TERMS
// -----------------------------------------------------------------------------
namespace yocto {

// A direction in the fiber frame: longitudinal angle (sin, cos >= 0) and the
// components (y, z) in the normal plane, whose angle is the azimuth phi.
struct hair_angles {
  float sin_theta = 0, cos_theta = 1, y = 1, z = 0;
};

static hair_angles make_angles(const hair_brdf& brdf, const vec3f& w) {
  auto angles = hair_angles{};
  angles.y    = dot(w, brdf.y);
  angles.z    = dot(w, brdf.z);
  // cos(theta) from the normal-plane components stays accurate at grazing
  // angles, where sqrt(1 - sin^2) would not.
  angles.sin_theta = std::clamp(dot(w, brdf.x), -1.0f, 1.0f);
  angles.cos_theta = std::min(std::sqrt(sqr(angles.y) + sqr(angles.z)), 1.0f);
  return angles;
}

// phi_i - phi_o with a single arc tangent: the angle between the normal-plane
// projections.
static float relative_phi(const hair_angles& wo, const hair_angles& wi) {
  return std::atan2(wo.y * wi.z - wo.z * wi.y, wo.y * wi.y + wo.z * wi.z);
}

// Fresnel reflectance of a dielectric of relative index eta >= 1 seen from
// outside, unpolarised.
static float fresnel_dielectric(float eta, float cos_i) {
  cos_i      = std::clamp(cos_i, 0.0f, 1.0f);
  auto sin_t2 = (1 - sqr(cos_i)) / sqr(eta);
  auto cos_t  = safe_sqrt(1 - sin_t2);
  // Both denominators vanish only for eta = 1 at grazing incidence.
  auto d_parallel      = eta * cos_i + cos_t;
  auto d_perpendicular = cos_i + eta * cos_t;
  if (!(d_parallel > 0) || !(d_perpendicular > 0)) return 1;
  auto r_parallel      = (eta * cos_i - cos_t) / d_parallel;
  auto r_perpendicular = (cos_i - eta * cos_t) / d_perpendicular;
  return (sqr(r_parallel) + sqr(r_perpendicular)) / 2;
}

static hair_lobes make_lobes(const hair_brdf& brdf, const hair_angles& wo) {
  auto& mat   = brdf.material;
  auto  lobes = hair_lobes{};
  auto  sin_o = wo.sin_theta, cos_o = wo.cos_theta;

  // hair.pdf section "Absorption in the fiber": refracted angles. eta' is the
  // modified index of the projected problem (Bravais); cos(theta_o) = 0 would
  // divide by zero (MDL-SDK issue 6), and gives eta' -> inf, sin(gamma_t) = 0.
  auto sin_theta_t = sin_o / mat.eta;
  auto cos_theta_t = safe_sqrt(1 - sqr(sin_theta_t));
  auto eta_p       = safe_sqrt(sqr(mat.eta) - sqr(sin_o)) / std::max(cos_o, 1e-30f);
  auto sin_gamma_t = std::clamp(brdf.h / std::max(eta_p, 1.0f), -1.0f, 1.0f);
  auto cos_gamma_t = safe_sqrt(1 - sqr(sin_gamma_t));
  auto gamma_t     = std::asin(sin_gamma_t);

  // Transmittance of one pass through the fiber: path length 2 cos(gamma_t)
  // / cos(theta_t) in units of the radius. cos(theta_t) >= sqrt(1 - 1/eta^2)
  // is 0 only for eta = 1; an unabsorbed path stays 1 there.
  auto path = 2 * cos_gamma_t / std::max(cos_theta_t, 1e-6f);
  auto t    = vec3f{std::exp(-mat.sigma_a.x * path),
      std::exp(-mat.sigma_a.y * path), std::exp(-mat.sigma_a.z * path)};

  // hair.pdf eq. 12-13: A_0 = f, A_1 = (1 - f)^2 T, A_p = A_{p-1} T f, and
  // the geometric tail A_pmax = A_2 f T / (1 - f T).
  auto f    = fresnel_dielectric(mat.eta, cos_o * brdf.cos_gamma_o);
  lobes.a[0] = vec3f{f, f, f};
  lobes.a[1] = sqr(1 - f) * t;
  lobes.a[2] = lobes.a[1] * t * f;
  // 1 - f T vanishes only for f = 1 and T = 1, where A_2 = 0 as well.
  auto denom = glm::max(vec3f{1, 1, 1} - t * f, vec3f{1e-6f});
  lobes.a[3] = lobes.a[2] * t * f / denom;

  // hair.pdf eq. 10: Phi(p, h) = 2 p gamma_t - 2 gamma_o + p pi.
  for (auto p = 0; p < 3; p++) {
    lobes.phi_shift[p] = 2 * p * gamma_t - 2 * brdf.gamma_o + p * pif;
  }
  lobes.sin_gamma_t = sin_gamma_t, lobes.cos_gamma_t = cos_gamma_t;

  // Scale tilt on theta_o (pbrt-v3 after PR #256, pbrt-v4): R sees
  // theta_o - 2 alpha, TT theta_o + alpha, TRT theta_o + 4 alpha; the p_max
  // term is untilted. The rotated cosine is taken in absolute value.
  auto& sin_a = mat.sin_2k_alpha;
  auto& cos_a = mat.cos_2k_alpha;
  lobes.sin_theta[0] = sin_o * cos_a[1] - cos_o * sin_a[1];
  lobes.cos_theta[0] = cos_o * cos_a[1] + sin_o * sin_a[1];
  lobes.sin_theta[1] = sin_o * cos_a[0] + cos_o * sin_a[0];
  lobes.cos_theta[1] = cos_o * cos_a[0] - sin_o * sin_a[0];
  lobes.sin_theta[2] = sin_o * cos_a[2] + cos_o * sin_a[2];
  lobes.cos_theta[2] = cos_o * cos_a[2] - sin_o * sin_a[2];
  lobes.sin_theta[3] = sin_o;
  lobes.cos_theta[3] = cos_o;
  for (auto p = 0; p < 4; p++) lobes.cos_theta[p] = std::abs(lobes.cos_theta[p]);

  // Lobe choice proportional to the luminance of A_p (hair.pdf "Sampling");
  // all zero if the fiber returns nothing.
  auto total = 0.0f;
  for (auto p = 0; p < 4; p++) total += lobes.a_pdf[p] = luminance(lobes.a[p]);
  if (total > 0) {
    for (auto p = 0; p < 4; p++) lobes.a_pdf[p] /= total;
  }
  return lobes;
}

// The lobes of outgoing: those cached in the brdf if it was made for this
// direction, else computed into storage.
static const hair_lobes& find_lobes(const hair_brdf& brdf,
    const vec3f& outgoing, const hair_angles& wo, hair_lobes& storage) {
  if (brdf.has_outgoing && outgoing == brdf.outgoing) return brdf.lobes;
  storage = make_lobes(brdf, wo);
  return storage;
}

// Angle wrapped into [-pi, pi] without loops (a NaN stays a NaN, never hangs).
static float wrap_angle(float x) {
  auto wrapped = x - 2 * pif * std::round(x / (2 * pif));
  return std::clamp(wrapped, -pif, pif);
}

// hair.pdf eq. 11: logistic distribution of scale s trimmed to [-pi, pi].
// Written with |x| so that e^{-|x|/s} underflows to 0 instead of overflowing.
static float eval_azimuthal(const hair_precomputed& mat, float x) {
  auto e = std::exp(-std::abs(x) / mat.s);
  return mat.n_scale * e / (mat.s * sqr(1 + e));
}

// Inverse CDF of the trimmed logistic: u in [0, 1) to x in [-pi, pi].
static float sample_azimuthal(const hair_precomputed& mat, float u) {
  auto y = u / mat.n_scale + mat.n_cdf_min;  // F(x) = y
  if (!(y > 0)) return -pif;
  if (!(y < 1)) return pif;
  return std::clamp(-mat.s * std::log((1 - y) / y), -pif, pif);
}

}  // namespace yocto

// -----------------------------------------------------------------------------
// EVAL, SAMPLE AND PDF
// -----------------------------------------------------------------------------
namespace yocto {

hair_brdf eval_hair_brdf(const hair_precomputed& material, float h,
    const frame3f& frame, const vec3f& outgoing) {
  auto brdf         = eval_hair_brdf(material, h, frame);
  brdf.lobes        = make_lobes(brdf, make_angles(brdf, outgoing));
  brdf.outgoing     = outgoing;
  brdf.has_outgoing = true;
  return brdf;
}

// M_p N_p of each lobe for a pair of directions (N = 1 / 2 pi for p_max), the
// part that eval and pdf share; they weight it by A_p and by the lobe choice.
// Returns the lobes of outgoing (cached in the brdf or computed in storage).
static const hair_lobes& eval_lobe_products(const hair_brdf& brdf,
    const vec3f& outgoing, const vec3f& incoming, hair_lobes& storage,
    float products[4]) {
  auto& mat   = brdf.material;
  auto  wo    = make_angles(brdf, outgoing);
  auto  wi    = make_angles(brdf, incoming);
  auto  phi   = relative_phi(wo, wi);
  auto& lobes = find_lobes(brdf, outgoing, wo, storage);
  for (auto p = 0; p < 4; p++) {
    auto m = eval_longitudinal(mat.v[p], mat.m_scale[p], wi.sin_theta,
        wi.cos_theta, lobes.sin_theta[p], lobes.cos_theta[p]);
    auto n = p < 3 ? eval_azimuthal(mat, wrap_angle(phi - lobes.phi_shift[p]))
                   : 1 / (2 * pif);
    products[p] = m * n;
  }
  return lobes;
}

std::pair<vec3f, float> eval_hair_scattering_and_pdf(
    const hair_brdf& brdf, const vec3f& outgoing, const vec3f& incoming) {
  // hair.pdf eq. 3 is f = sum_p M_p A_p N_p / |cos theta_i|; the tracer
  // needs f times the cosine, so the sum itself is returned. The pdf weights
  // the same products by the lobe choice instead of A_p.
  auto  storage = hair_lobes{};
  float products[4];
  auto& lobes = eval_lobe_products(brdf, outgoing, incoming, storage, products);
  auto  sum   = vec3f{0, 0, 0};
  auto  pdf   = 0.0f;
  for (auto p = 0; p < 4; p++) {
    sum += products[p] * lobes.a[p];
    pdf += products[p] * lobes.a_pdf[p];
  }
  return {sum, pdf};
}

vec3f eval_hair_scattering(
    const hair_brdf& brdf, const vec3f& outgoing, const vec3f& incoming) {
  return eval_hair_scattering_and_pdf(brdf, outgoing, incoming).first;
}

float sample_hair_scattering_pdf(
    const hair_brdf& brdf, const vec3f& outgoing, const vec3f& incoming) {
  return eval_hair_scattering_and_pdf(brdf, outgoing, incoming).second;
}

std::array<vec3f, 4> eval_hair_scattering_lobes(
    const hair_brdf& brdf, const vec3f& outgoing, const vec3f& incoming) {
  auto  storage = hair_lobes{};
  float products[4];
  auto& lobes = eval_lobe_products(brdf, outgoing, incoming, storage, products);
  auto  terms = std::array<vec3f, 4>{};
  for (auto p = 0; p < 4; p++) terms[p] = products[p] * lobes.a[p];
  return terms;
}

vec3f eval_hair_albedo(const hair_brdf& brdf, const vec3f& outgoing) {
  auto  storage = hair_lobes{};
  auto& lobes   = find_lobes(brdf, outgoing, make_angles(brdf, outgoing), storage);
  return lobes.a[0] + lobes.a[1] + lobes.a[2] + lobes.a[3];
}

// The lobe chosen by u: p with probability choice[p]; -1 if the fiber
// returns nothing.
static int sample_hair_lobe(const float choice[4], float u) {
  auto last = -1;
  for (auto q = 0; q < 4; q++) {
    if (choice[q] > 0) last = q;
  }
  if (last < 0) return -1;
  auto p = 0;
  for (; p < last; p++) {
    if (u < choice[p]) break;
    u -= choice[p];
  }
  return p;
}

// A direction of lobe p, drawn with density M_p N_p (exactly, so that
// A_p / P(p) is an unbiased weight for it): rn.y the azimuth, rn.z the
// longitudinal angle, rn.w the rotation around the longitudinal cone.
static vec3f sample_hair_lobe_direction(const hair_brdf& brdf, const hair_lobes& lobes,
    const hair_angles& wo, int p, const vec4f& rn) {
  auto& mat = brdf.material;
  // d'Eon 2013: cos(theta) = 1 + v log(u + (1 - u) e^{-2/v}) around the
  // (tilted) outgoing cone; written as t = 1 - cos(theta) with log1p so that
  // sin(theta) = sqrt(t (2 - t)) keeps its digits at low roughness.
  auto t = -mat.v[p] * std::log1p(-(1 - rn.z) * mat.m_tail[p]);
  t      = std::clamp(t, 0.0f, 2.0f);  // u = 0 may round to log(0)
  auto cos_theta   = 1 - t;
  auto sin_theta   = safe_sqrt(t * (2 - t));
  auto cos_phi     = std::cos(2 * pif * rn.w);
  auto sin_theta_i = -cos_theta * lobes.sin_theta[p] +
                     sin_theta * cos_phi * lobes.cos_theta[p];
  sin_theta_i      = std::clamp(sin_theta_i, -1.0f, 1.0f);
  auto cos_theta_i = safe_sqrt(1 - sqr(sin_theta_i));

  // Azimuth: Phi(p, h) plus a trimmed logistic sample; uniform for p_max.
  auto dphi = p < 3 ? lobes.phi_shift[p] + sample_azimuthal(mat, rn.y)
                    : 2 * pif * rn.y;
  // phi_i = phi_o + dphi as a rotation of the outgoing normal-plane direction
  // (any direction if the outgoing one runs along the fiber).
  auto cos_phi_o = 1.0f, sin_phi_o = 0.0f;
  if (wo.cos_theta > 0) {
    cos_phi_o = wo.y / wo.cos_theta;
    sin_phi_o = wo.z / wo.cos_theta;
  }
  auto cos_dphi = std::cos(dphi), sin_dphi = std::sin(dphi);
  auto cos_phi_i = cos_phi_o * cos_dphi - sin_phi_o * sin_dphi;
  auto sin_phi_i = sin_phi_o * cos_dphi + cos_phi_o * sin_dphi;
  return brdf.x * sin_theta_i + brdf.y * (cos_theta_i * cos_phi_i) +
         brdf.z * (cos_theta_i * sin_phi_i);
}

// A lobe chosen by rn.x, a direction of it from the other three numbers, and
// the lobe's weight A_p / P(p); zero direction and weight if the fiber
// returns nothing. With `worth`, P(p) is the guided choice of
// sample_hair_scattering_weight.
static hair_sample sample_hair_lobes(const hair_brdf& brdf, const vec3f& outgoing,
    const vec4f& rn, const std::array<float, 4>* worth = nullptr, float guided = 0) {
  auto  wo      = make_angles(brdf, outgoing);
  auto  storage = hair_lobes{};
  auto& lobes   = find_lobes(brdf, outgoing, wo, storage);
  if (!worth || !(guided > 0)) {
    auto p = sample_hair_lobe(lobes.a_pdf, rn.x);
    if (p < 0) return {};
    return {sample_hair_lobe_direction(brdf, lobes, wo, p, rn), p, lobes.a[p] / lobes.a_pdf[p]};
  }
  // (1 - guided) P(p) + guided P(p) worth_p / sum_q P(q) worth_q: the
  // luminance choice keeps a share (at least 5 %: a lobe the worth rates 0
  // must keep a chance, or the estimate is biased where the worth is wrong),
  // so no lobe's weight grows by more than 1 / (1 - guided).
  auto total = 0.0f;
  for (auto p = 0; p < 4; p++) total += lobes.a_pdf[p] * std::max((*worth)[p], 0.0f);
  float choice[4] = {lobes.a_pdf[0], lobes.a_pdf[1], lobes.a_pdf[2], lobes.a_pdf[3]};
  guided          = std::min(guided, 0.95f);
  if (total > 0 && std::isfinite(total)) {
    for (auto p = 0; p < 4; p++)
      choice[p] *= 1 - guided + guided * std::max((*worth)[p], 0.0f) / total;
  }
  auto p = sample_hair_lobe(choice, rn.x);
  if (p < 0 || !(choice[p] > 0)) return {};
  return {sample_hair_lobe_direction(brdf, lobes, wo, p, rn), p, lobes.a[p] / choice[p]};
}

// Two numbers demuxed into the four a direction takes.
static vec4f demux_hair_numbers(const vec2f& rn) {
  auto u0 = demux_hair_sample_filled(rn.x), u1 = demux_hair_sample_filled(rn.y);
  return {u0.x, u0.y, u1.x, u1.y};
}

vec3f sample_hair_scattering(
    const hair_brdf& brdf, const vec3f& outgoing, const vec2f& rn) {
  return sample_hair_lobes(brdf, outgoing, demux_hair_numbers(rn)).incoming;
}

vec3f sample_hair_scattering(
    const hair_brdf& brdf, const vec3f& outgoing, const vec4f& rn) {
  return sample_hair_lobes(brdf, outgoing, rn).incoming;
}

hair_sample sample_hair_scattering_weight(
    const hair_brdf& brdf, const vec3f& outgoing, const vec2f& rn) {
  return sample_hair_lobes(brdf, outgoing, demux_hair_numbers(rn));
}

hair_sample sample_hair_scattering_weight(
    const hair_brdf& brdf, const vec3f& outgoing, const vec4f& rn) {
  return sample_hair_lobes(brdf, outgoing, rn);
}

hair_sample sample_hair_scattering_weight(const hair_brdf& brdf, const vec3f& outgoing,
    const vec4f& rn, const std::array<float, 4>& worth, float guided) {
  return sample_hair_lobes(brdf, outgoing, rn, &worth, guided);
}

hair_sample sample_hair_scattering_weight(const hair_brdf& brdf, const vec3f& outgoing,
    const vec2f& rn, const std::array<float, 4>& worth, float guided) {
  return sample_hair_lobes(brdf, outgoing, demux_hair_numbers(rn), &worth, guided);
}

std::array<vec3f, 4> hair_lobe_directions(const hair_brdf& brdf, const vec3f& outgoing) {
  auto  wo        = make_angles(brdf, outgoing);
  auto  storage   = hair_lobes{};
  auto& lobes     = find_lobes(brdf, outgoing, wo, storage);
  auto  cos_phi_o = 1.0f, sin_phi_o = 0.0f;
  if (wo.cos_theta > 0) cos_phi_o = wo.y / wo.cos_theta, sin_phi_o = wo.z / wo.cos_theta;
  // Phi(p, h) as rotations (no trigonometric call): by -2 gamma_o (cos
  // 1 - 2 h^2, sin -2 h cos gamma_o), then p times by 2 gamma_t + pi.
  auto h = brdf.h, cos_shift = 1 - 2 * h * h, sin_shift = -2 * h * brdf.cos_gamma_o;
  auto cos_step = -(1 - 2 * sqr(lobes.sin_gamma_t));
  auto sin_step = -2 * lobes.sin_gamma_t * lobes.cos_gamma_t;
  auto directions = std::array<vec3f, 4>{};
  for (auto p = 0; p < 3; p++) {
    // The centre of the longitudinal cone: theta_i = -(tilted theta_o).
    auto sin_theta_i = -lobes.sin_theta[p], cos_theta_i = lobes.cos_theta[p];
    auto cos_phi_i   = cos_phi_o * cos_shift - sin_phi_o * sin_shift;
    auto sin_phi_i   = sin_phi_o * cos_shift + cos_phi_o * sin_shift;
    directions[p]    = brdf.x * sin_theta_i + brdf.y * (cos_theta_i * cos_phi_i) +
                    brdf.z * (cos_theta_i * sin_phi_i);
    auto next = cos_shift * cos_step - sin_shift * sin_step;
    sin_shift = sin_shift * cos_step + cos_shift * sin_step, cos_shift = next;
  }
  // The higher orders, of uniform azimuth: the mean of their directions lies
  // on the fiber.
  directions[3] = brdf.x * -lobes.sin_theta[3];
  return directions;
}

}  // namespace yocto
