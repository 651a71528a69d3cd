//
// Tests of the hair scattering model's building blocks: the Bessel function,
// the longitudinal lobe's normalisation, pigments, the Morton demux, the
// wiring of h and the frame, and the hard numerical cases; then the
// statistical tests of the full BSDF (furnaces, sampling weights and
// consistency, chi-square goodness of fit).
//

#include <gtest/gtest.h>
#include <yocto/yocto_sampling.h>
#include <yocto_hair/yocto_hair.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <functional>
#include <limits>
#include <vector>

using namespace yocto;

// -----------------------------------------------------------------------------
// DETERMINISTIC QUADRATURE
// -----------------------------------------------------------------------------

// Gauss-Legendre nodes and weights on [-1, 1] by Newton's method on P_n.
struct gauss_rule {
  std::vector<double> nodes, weights;
};
static gauss_rule make_gauss_rule(int n) {
  auto rule = gauss_rule{std::vector<double>(n), std::vector<double>(n)};
  for (auto i = 0; i < n; i++) {
    auto x = std::cos(3.14159265358979323846 * (i + 0.75) / (n + 0.5));
    auto derivative = 0.0;
    for (auto iteration = 0; iteration < 100; iteration++) {
      auto p0 = 1.0, p1 = x;  // P_0, P_1, then the three-term recurrence
      for (auto k = 2; k <= n; k++) {
        auto p2 = ((2 * k - 1) * x * p1 - (k - 1) * p0) / k;
        p0 = p1, p1 = p2;
      }
      auto pn    = n == 1 ? x : p1;
      auto pn_1  = n == 1 ? 1.0 : p0;
      derivative = n * (x * pn - pn_1) / (x * x - 1);
      auto step  = pn / derivative;
      x -= step;
      if (std::abs(step) < 1e-15) break;
    }
    rule.nodes[i]   = x;
    rule.weights[i] = 2 / ((1 - x * x) * derivative * derivative);
  }
  return rule;
}

// Composite Gauss-Legendre (n nodes) over the panels between sorted breaks.
static double integrate_panels(std::vector<double> breaks,
    const std::function<double(double)>& f, int n = 8) {
  static const auto rules = std::vector<gauss_rule>{make_gauss_rule(1),
      make_gauss_rule(2), make_gauss_rule(3), make_gauss_rule(4),
      make_gauss_rule(5), make_gauss_rule(6), make_gauss_rule(7),
      make_gauss_rule(8)};
  auto& rule = rules.at(n - 1);
  std::sort(breaks.begin(), breaks.end());
  auto sum = 0.0;
  for (auto i = 0; i + 1 < (int)breaks.size(); i++) {
    auto a = breaks[i], b = breaks[i + 1];
    if (b - a < 1e-12) continue;
    for (auto k = 0; k < (int)rule.nodes.size(); k++) {
      sum += rule.weights[k] * (b - a) / 2 * f((a + b) / 2 + rule.nodes[k] * (b - a) / 2);
    }
  }
  return sum;
}

// Breaks around a peak at center of width w: center +- w {1/2, 1, 2, 4, ...}
// inside [lo, hi]; periodic (wrapped into [lo, hi]) if asked.
static void add_lobe_breaks(std::vector<double>& breaks, double center,
    double width, double lo, double hi, bool periodic = false) {
  auto period = hi - lo;
  auto place  = [&](double x) {
    if (periodic) x = lo + std::fmod(std::fmod(x - lo, period) + period, period);
    if (x > lo && x < hi) breaks.push_back(x);
  };
  place(center);
  for (auto k = 0.5; k * width < period; k *= 2) {
    place(center - k * width);
    place(center + k * width);
  }
}

// -----------------------------------------------------------------------------
// BESSEL FUNCTION AND LONGITUDINAL LOBE
// -----------------------------------------------------------------------------

// Reference I_0(x) e^-x from the integral (1/pi) int_0^pi e^{x (cos t - 1)} dt
// by the trapezoidal rule in long double: for a periodic analytic integrand
// the error falls like I_{2n}(x) / I_0(x) ~ exp(-(2n)^2 / 2x), far below
// 1e-18 with n = 3000 for every x up to 1e5 (exp(-180) there).
static long double reference_i0e(long double x) {
  const int n   = 3000;
  auto      sum = (1.0L + std::exp(-2 * x)) / 2;
  for (auto k = 1; k < n; k++) {
    sum += std::exp(x * (std::cos(k * 3.14159265358979323846264L / n) - 1));
  }
  return sum / n;
}

TEST(hair, bessel_i0e_float_precision) {
  // 0, then 300 log-spaced points in [1e-4, 1e5] (M_p needs up to ~7e4 at
  // beta_m = 0.01), and both sides of the series/asymptotic switch at 12.
  auto xs = std::vector<float>{0, 11.999f, 12, 12.001f};
  for (auto i = 0; i <= 300; i++) xs.push_back(1e-4f * std::pow(1e9f, i / 300.0f));
  auto worst = 0.0, worst_x = 0.0;
  for (auto x : xs) {
    auto value     = (long double)hair_bessel_i0e(x);
    auto reference = reference_i0e((long double)x);
    auto error     = (double)std::abs(value / reference - 1);
    if (error > worst) worst = error, worst_x = x;
  }
  // Float rounding alone is 6e-8 relative; allow one float epsilon.
  std::printf("[ figure ] I0e worst relative error %.3g at x = %g\n", worst, worst_x);
  RecordProperty("i0e_worst_relative_error", std::to_string(worst));
  EXPECT_LE(worst, 1.2e-7);
  EXPECT_EQ(hair_bessel_i0e(0), 1.0f);
  EXPECT_TRUE(std::isfinite(hair_bessel_i0e(1e30f)));
}

// Integral of M_p cos(theta_i) over theta_i for one variance and theta_o,
// with panels refined around the peak at theta_i = -theta_o.
static double integrate_longitudinal(float v, double theta_o) {
  auto breaks = std::vector<double>{-pif / 2.0, pif / 2.0};
  add_lobe_breaks(breaks, -theta_o, std::sqrt(v), -pif / 2.0, pif / 2.0);
  auto sin_o = (float)std::sin(theta_o), cos_o = (float)std::cos(theta_o);
  return integrate_panels(breaks, [&](double theta_i) {
    auto m = eval_hair_longitudinal(v, (float)std::sin(theta_i),
        (float)std::cos(theta_i), sin_o, cos_o);
    return m * std::cos(theta_i);
  });
}

TEST(hair, longitudinal_normalised) {
  // beta_m from 0.01 to 1, all four variances, theta_o across the range:
  // the integral of M_p cos(theta_i) must be 1. (pbrt's I_0 leaves it as low
  // as 0.987.) Deterministic quadrature; tolerance 1e-4.
  auto betas = std::vector<float>{0.01f, 0.02f, 0.05f, 0.1f, 0.2f, 0.3f, 0.4f,
      0.5f, 0.6f, 0.7f, 0.8f, 0.9f, 1.0f};
  auto thetas = std::vector<double>{-1.5, -0.9, -0.3, 0.0, 0.2, 0.8, 1.2, 1.55};
  auto worst  = 0.0;
  for (auto beta_m : betas) {
    auto material   = hair_material{};
    material.beta_m = beta_m;
    auto pre        = make_hair_precomputed(material);
    for (auto p = 0; p < 4; p++) {
      for (auto theta_o : thetas) {
        auto integral = integrate_longitudinal(pre.v[p], theta_o);
        worst         = std::max(worst, std::abs(integral - 1));
        EXPECT_NEAR(integral, 1, 1e-4)
            << "beta_m " << beta_m << " p " << p << " theta_o " << theta_o;
      }
    }
  }
  std::printf("[ figure ] M_p normalisation worst |integral - 1| = %.3g\n", worst);
  RecordProperty("mp_worst_deviation", std::to_string(worst));
}

TEST(hair, longitudinal_peak_accurate_at_low_roughness) {
  // At v = 1.35e-5 (TT lobe, beta_m = 0.01) the exponent's terms are ~7e4
  // each; with the analytic cancellation the float value at points around
  // the peak must match a long double evaluation of the textbook formula
  // to 1e-4 relative.
  auto material   = hair_material{};
  material.beta_m = 0.01f;
  auto v          = make_hair_precomputed(material).v[1];
  auto theta_o    = 0.4f;
  auto worst      = 0.0;
  for (auto k = -6; k <= 6; k++) {
    auto theta_i = -theta_o + k * 0.5f * std::sqrt(v);
    auto sin_i = std::sin(theta_i), cos_i = std::cos(theta_i);
    auto sin_o = std::sin(theta_o), cos_o = std::cos(theta_o);
    auto value = eval_hair_longitudinal(v, sin_i, cos_i, sin_o, cos_o);
    // The reference sees exactly the same float inputs.
    auto lv = (long double)v;
    auto ti = std::atan2((long double)sin_i, (long double)cos_i);
    auto to = std::atan2((long double)sin_o, (long double)cos_o);
    // log M = log(1 / (v (1 - e^{-2/v}))) - (1 - cos(ti + to)) / v + log I0e(a)
    auto a         = (long double)cos_i * cos_o / lv;
    auto log_m     = -std::log(lv * -std::expm1(-2 / lv)) -
                 (1 - std::cos(ti + to)) / lv + std::log(reference_i0e(a));
    auto reference = std::exp(log_m);
    worst = std::max(worst, (double)std::abs(value / reference - 1));
  }
  std::printf("[ figure ] M_p at beta_m = 0.01 worst relative error %.3g\n", worst);
  EXPECT_LE(worst, 1e-4);
}

// -----------------------------------------------------------------------------
// PIGMENTS AND DEMUX
// -----------------------------------------------------------------------------

TEST(hair, sigma_a_from_melanin) {
  // By hand: 1.3 (0.419, 0.697, 1.37); 0.5 (0.419, 0.697, 1.37) + 2 (0.187,
  // 0.4, 1.05).
  auto a = hair_sigma_a_from_melanin(1.3f, 0);
  EXPECT_NEAR(a.x, 0.5447f, 1e-6f);
  EXPECT_NEAR(a.y, 0.9061f, 1e-6f);
  EXPECT_NEAR(a.z, 1.781f, 1e-6f);
  auto b = hair_sigma_a_from_melanin(0.5f, 2);
  EXPECT_NEAR(b.x, 0.5835f, 1e-6f);
  EXPECT_NEAR(b.y, 1.1485f, 1e-6f);
  EXPECT_NEAR(b.z, 2.785f, 1e-6f);
  auto c = hair_sigma_a_from_melanin(-1, -1);
  EXPECT_EQ(c, vec3f(0, 0, 0));
}

TEST(hair, sigma_a_from_color) {
  // By hand: at beta_n = 0.3 the denominator is 5.969 - 0.0645 + 0.22788 -
  // 0.28971 + 0.04514894 + 0.00059535 = 5.88841475; sigma_a = (ln c / it)^2.
  auto a = hair_sigma_a_from_color({0.5f, 0.25f, 0.9f}, 0.3f);
  EXPECT_NEAR(a.x, 0.0138565189f, 1e-7f);
  EXPECT_NEAR(a.y, 0.0554260756f, 1e-7f);
  EXPECT_NEAR(a.z, 0.000320154f, 1e-8f);
  // At beta_n = 1 the denominator is 3.375: (ln 0.5 / 3.375)^2; colour 0 is
  // clamped to the smallest normal float: (ln 2^-126 / 3.375)^2 = 669.6447;
  // white absorbs nothing.
  auto b = hair_sigma_a_from_color({0.5f, 0, 1}, 1);
  EXPECT_NEAR(b.x, 0.0421796885f, 1e-7f);
  EXPECT_NEAR(b.y, 669.6447f, 1e-3f);
  EXPECT_EQ(b.z, 0.0f);
}

TEST(hair, sigma_a_from_color_inverts) {
  // c = exp(-sqrt(sigma_a) d(beta_n)) gives back sigma_a (1e-5 relative) for
  // sigma_a from a faint tint to black hair (eumelanin 8: 10.96 in blue) and
  // past it, up to the limit (ln FLT_MIN / d)^2 (over 200): USD import carries
  // per-point melanin as such colours.
  for (auto beta_n : {0.01f, 0.3f, 0.7f, 1.0f}) {
    auto d = 5.969f - 0.215f * beta_n + 2.532f * sqr(beta_n) -
             10.73f * beta_n * sqr(beta_n) + 5.574f * sqr(sqr(beta_n)) +
             0.245f * beta_n * sqr(sqr(beta_n));
    for (auto sigma_a : {0.01f, 0.2f, 1.0f, 4.11f, 10.96f, 50.0f, 200.0f}) {
      auto c = std::exp(-std::sqrt(sigma_a) * d);
      auto s = hair_sigma_a_from_color({c, c, c}, beta_n);
      EXPECT_NEAR(s.x / sigma_a, 1, 1e-5f) << "beta_n " << beta_n << " sigma_a " << sigma_a;
    }
  }
}

TEST(hair, material_precedence) {
  auto material    = hair_material{};  // no colouring: eumelanin 1.3
  auto pre         = make_hair_precomputed(material);
  EXPECT_NEAR(pre.sigma_a.x, 0.5447f, 1e-6f);
  material.has_color = true;
  material.color     = {0.5f, 0.5f, 0.5f};
  material.beta_n    = 1;
  EXPECT_NEAR(make_hair_precomputed(material).sigma_a.y, 0.0421796885f, 1e-7f);
  material.has_sigma_a = true;
  material.sigma_a     = {0.1f, 0.2f, 0.3f};
  EXPECT_EQ(make_hair_precomputed(material).sigma_a, vec3f(0.1f, 0.2f, 0.3f));
  // Roughness is clamped to [0.01, 1].
  material.beta_m = 0;
  material.beta_n = 7;
  pre             = make_hair_precomputed(material);
  EXPECT_EQ(pre.beta_m, 0.01f);
  EXPECT_EQ(pre.beta_n, 1.0f);
  EXPECT_GT(pre.v[0], 0.0f);
}

TEST(hair, fast_pow_matches_std_pow) {
  // Powers of two are exact in float; the material terms with the fast power
  // agree with std::pow's within 4e-6 relative (a few float roundings of the
  // five multiplies, doubled by the square in v) over 1000 roughness values.
  EXPECT_EQ(pow_int<20>(2.0f), 1048576.0f);
  EXPECT_EQ(pow_int<22>(0.5f), 1.0f / 4194304.0f);
  EXPECT_EQ(pow_int<0>(3.0f), 1.0f);
  auto worst = 0.0f;
  for (auto i = 0; i < 1000; i++) {
    auto material   = hair_material{};
    material.beta_m = 0.01f + 0.99f * i / 999;
    material.beta_n = 1.0f - 0.99f * i / 999;
    auto exact = make_hair_precomputed(material);
    auto fast  = make_hair_precomputed(material, true);
    worst = std::max(worst, std::abs(fast.v[0] - exact.v[0]) / exact.v[0]);
    worst = std::max(worst, std::abs(fast.s - exact.s) / exact.s);
  }
  std::printf("[ figure ] fast pow: worst relative difference of v and s %.2g\n", worst);
  EXPECT_LT(worst, 4e-6f);
}

TEST(hair, demux_hand_worked_bits) {
  // u = 0.75: bits 1100 0..., bit 31 (odd) -> second bit 15, bit 30 (even) ->
  // first bit 15: (0.5, 0.5).
  EXPECT_EQ(demux_hair_sample(0.75f), vec2f(0.5f, 0.5f));
  EXPECT_EQ(demux_hair_sample(0.5f), vec2f(0.0f, 0.5f));   // bit 31 only
  EXPECT_EQ(demux_hair_sample(0.25f), vec2f(0.5f, 0.0f));  // bit 30 only
  EXPECT_EQ(demux_hair_sample(0.0f), vec2f(0.0f, 0.0f));
  // u = 0x9C / 256 = 0.609375: bits 31..24 = 1 0 0 1 1 1 0 0. Odd bits
  // 31, 29, 27, 25 = 1 0 1 0 -> second = 0xA000 / 65536 = 0.625; even bits
  // 30, 28, 26, 24 = 0 1 1 0 -> first = 0x6000 / 65536 = 0.375.
  EXPECT_EQ(demux_hair_sample(0.609375f), vec2f(0.375f, 0.625f));
  // u = 0xAAAAAA00 / 2^32: odd bits 9..31 set -> second bits 4..15 = 0xFFF0.
  EXPECT_EQ(demux_hair_sample(0xAAAAAA00u / 4294967296.0f),
      vec2f(0.0f, 0xFFF0 / 65536.0f));
  // u = 0x55555500 / 2^32: even bits 8..30 set -> first bits 4..15 = 0xFFF0.
  EXPECT_EQ(demux_hair_sample(0x55555500u / 4294967296.0f),
      vec2f(0xFFF0 / 65536.0f, 0.0f));
  // u = 0xFFFF0000 / 2^32: bits 16..31 -> both get bits 8..15 = 0xFF00.
  EXPECT_EQ(demux_hair_sample(0xFFFF0000u / 4294967296.0f),
      vec2f(0xFF00 / 65536.0f, 0xFF00 / 65536.0f));
  // Out of range inputs stay in [0, 1).
  auto one = demux_hair_sample(1.0f);
  EXPECT_LT(one.x, 1.0f);
  EXPECT_LT(one.y, 1.0f);
}

// -----------------------------------------------------------------------------
// FRAME AND H WIRING
// -----------------------------------------------------------------------------

TEST(hair, low_roughness_r_lobe_is_mirror_of_cylinder) {
  // A straight fiber along x of radius 0.5 through the origin, a ray along d
  // passing the axis at offset h along y (the frame the tracer builds: x the
  // tangent, z = -d without its tangent part, y = z × x). With beta = 0.01,
  // alpha = 0 and sigma_a = 1e4 only R survives; its samples (2000, fixed
  // seed) must lie within 0.05 rad of the mirror reflection off the
  // cylinder's surface normal at the hit, on average within 0.02 rad.
  auto material        = hair_material{};
  material.beta_m      = 0.01f;
  material.beta_n      = 0.01f;
  material.alpha       = 0;
  material.has_sigma_a = true;
  material.sigma_a     = {1e4f, 1e4f, 1e4f};
  auto radius          = 0.5f;
  auto rng             = make_rng(7);
  for (auto h : {-0.9f, -0.4f, 0.0f, 0.3f, 0.8f}) {
    for (auto d : {vec3f{0.3f, 0.2f, -1}, vec3f{-0.5f, -1, 0.4f}}) {
      d         = normalize(d);
      auto x    = vec3f{1, 0, 0};
      auto z    = normalize(-d - dot(-d, x) * x);
      auto y    = cross(z, x);
      auto axis = vec3f{0.7f, 0, 0};
      // First hit of the ray with the cylinder: offset h r along y, on the
      // side facing the ray; the surface normal points from the axis to it.
      auto hit    = axis + radius * (h * y + std::sqrt(1 - h * h) * z);
      auto normal = normalize(hit - axis);
      auto mirror = reflect(-d, normal);
      // h as the tracer computes it from the geometry.
      auto h_geometry = dot(hit - axis, y) / radius;
      auto brdf       = eval_hair_brdf(material, h_geometry, frame3f{x, y, z, {}});
      auto mean_angle = 0.0;
      for (auto i = 0; i < 2000; i++) {
        auto wi    = sample_hair_scattering(brdf, -d, rand2f(rng));
        auto angle = std::acos(std::clamp(dot(wi, mirror), -1.0f, 1.0f));
        EXPECT_LT(angle, 0.05f) << "h " << h;
        mean_angle += angle / 2000;
      }
      EXPECT_LT(mean_angle, 0.02) << "h " << h;
      // And the lobe really is there: eval at the mirror beats eval at the
      // mirror of the opposite offset.
      auto other = reflect(-d, normalize(-h * y + std::sqrt(1 - h * h) * z));
      if (h != 0) {
        EXPECT_GT(eval_hair_scattering(brdf, -d, mirror).x,
            100 * eval_hair_scattering(brdf, -d, other).x);
      }
    }
  }
}

// -----------------------------------------------------------------------------
// HARD CASES
// -----------------------------------------------------------------------------

// Directions including grazing ones along the fiber (|w.x| -> 1).
static vec3f hard_direction(rng_state& rng) {
  auto kind = rand1i(rng, 4);
  auto w    = sample_sphere(rand2f(rng));
  if (kind == 0) return w;
  auto sign = rand1f(rng) < 0.5f ? -1.0f : 1.0f;
  if (kind == 1) return {sign, 0, 0};  // exactly along the fiber
  auto tiny = std::pow(10.0f, -1 - 7 * rand1f(rng));
  auto phi  = 2 * pif * rand1f(rng);
  auto side = vec3f{0, std::cos(phi), std::sin(phi)};
  return normalize(vec3f{sign, 0, 0} + tiny * side);
}

TEST(hair, hard_cases_finite_and_consistent) {
  // 10^6 random evaluations (eval and pdf of a random pair, plus a sample and
  // its eval and pdf) over beta in {0.01, 0 (clamped), 0.3, 1}, h in {-1, 0,
  // 1, random}, sigma_a in {0, 0.5, 1e4}, alpha in {0, 10} degrees, eta in
  // {1.0001, 1.55, 2}, and grazing directions. No NaN, Inf or negative value;
  // pdf > 0 wherever eval > 0. Fixed seed.
  auto rng      = make_rng(1234);
  auto betas    = std::vector<float>{0.01f, 0.0f, 0.3f, 1.0f};
  auto hs       = std::vector<float>{-1, 0, 1, 0.5f};
  auto sigmas   = std::vector<float>{0, 0.5f, 1e4f};
  auto alphas   = std::vector<float>{0, 10};
  auto etas     = std::vector<float>{1.0001f, 1.55f, 2};
  auto failures = 0, evaluations = 1000000;
  auto nonzero  = 0;
  for (auto i = 0; i < evaluations / 2 && failures < 10; i++) {
    auto material        = hair_material{};
    material.beta_m      = betas[rand1i(rng, 4)];
    material.beta_n      = betas[rand1i(rng, 4)];
    material.alpha       = alphas[rand1i(rng, 2)];
    material.eta         = etas[rand1i(rng, 3)];
    material.has_sigma_a = true;
    material.sigma_a     = vec3f{1, 1, 1} * sigmas[rand1i(rng, 3)];
    auto h = hs[rand1i(rng, 4)];
    if (h == 0.5f) h = 2 * rand1f(rng) - 1;
    auto frame = frame_fromz({0, 0, 0}, sample_sphere(rand2f(rng)));
    auto brdf  = eval_hair_brdf(material, h, frame);
    auto wo    = transform_direction(frame, hard_direction(rng));
    auto wi    = transform_direction(frame, hard_direction(rng));
    auto check = [&](const vec3f& wi, const char* what) {
      auto f   = eval_hair_scattering(brdf, wo, wi);
      auto pdf = sample_hair_scattering_pdf(brdf, wo, wi);
      auto ok  = isfinite(f) && std::isfinite(pdf) && min_component(f) >= 0 &&
                pdf >= 0 && (max_component(f) == 0 || pdf > 0);
      if (max_component(f) > 0) nonzero++;
      if (!ok && failures++ < 10) {
        ADD_FAILURE() << what << ": f " << f.x << " " << f.y << " " << f.z
                      << " pdf " << pdf << " beta " << material.beta_m << " "
                      << material.beta_n << " h " << h << " sigma_a "
                      << material.sigma_a.x << " eta " << material.eta
                      << " alpha " << material.alpha << " wo.x "
                      << dot(wo, frame.x) << " wi.x " << dot(wi, frame.x);
      }
    };
    check(wi, "random pair");
    auto ws = sample_hair_scattering(brdf, wo, rand2f(rng));
    if (!isfinite(ws) || std::abs(length(ws) - 1) > 1e-3f) {
      if (failures++ < 10) ADD_FAILURE() << "bad sampled direction";
      continue;
    }
    check(ws, "sampled");
  }
  std::printf("[ figure ] hard cases: %d evaluations, %d non-zero, %d failures\n",
      evaluations, nonzero, failures);
  EXPECT_EQ(failures, 0);
  EXPECT_GT(nonzero, evaluations / 4);  // the check is not vacuous
}

TEST(hair, cached_lobes_and_combined_eval_match_separate_calls) {
  // 100k random hard-case configurations (fixed seed): a brdf made for the
  // outgoing direction gives the same eval, pdf and sample as one made
  // without it, for that direction and (falling back) for another;
  // eval_hair_scattering_and_pdf gives what eval and pdf give separately.
  // Tolerance: 1e-6 relative (the operations are the same, in the same order).
  auto rng      = make_rng(4321);
  auto failures = 0, compared = 0;
  auto close    = [](float a, float b) {
    return std::abs(a - b) <= 1e-6f * std::max(std::abs(a), std::abs(b)) ||
           std::abs(a - b) < 1e-30f;
  };
  auto close3 = [&](const vec3f& a, const vec3f& b) {
    return close(a.x, b.x) && close(a.y, b.y) && close(a.z, b.z);
  };
  for (auto i = 0; i < 100000 && failures < 10; i++) {
    auto material        = hair_material{};
    material.beta_m      = 0.01f + rand1f(rng);
    material.beta_n      = 0.01f + rand1f(rng);
    material.alpha       = 10 * rand1f(rng);
    material.eta         = 1 + rand1f(rng);
    material.has_sigma_a = true;
    material.sigma_a     = vec3f{rand1f(rng), rand1f(rng), 4 * rand1f(rng)};
    auto pre    = make_hair_precomputed(material);
    auto h      = i % 7 == 0 ? (i % 2 ? 1.0f : -1.0f) : 2 * rand1f(rng) - 1;
    auto frame  = frame_fromz({0, 0, 0}, sample_sphere(rand2f(rng)));
    auto wo     = transform_direction(frame, hard_direction(rng));
    auto other  = transform_direction(frame, hard_direction(rng));
    auto plain  = eval_hair_brdf(pre, h, frame);
    auto cached = eval_hair_brdf(pre, h, frame, wo);
    auto rn     = rand2f(rng);
    for (auto outgoing : {wo, other}) {
      auto wi       = sample_hair_scattering(plain, outgoing, rn);
      auto wi_cache = sample_hair_scattering(cached, outgoing, rn);
      auto ok       = close3(wi, wi_cache);
      for (auto incoming : {wi, transform_direction(frame, hard_direction(rng))}) {
        auto f        = eval_hair_scattering(plain, outgoing, incoming);
        auto pdf      = sample_hair_scattering_pdf(plain, outgoing, incoming);
        auto [cf, cp] = eval_hair_scattering_and_pdf(cached, outgoing, incoming);
        auto [pf, pp] = eval_hair_scattering_and_pdf(plain, outgoing, incoming);
        ok = ok && close3(f, cf) && close(pdf, cp) && close3(f, pf) &&
             close(pdf, pp) &&
             close3(f, eval_hair_scattering(cached, outgoing, incoming)) &&
             close(pdf, sample_hair_scattering_pdf(cached, outgoing, incoming));
        compared++;
      }
      if (!ok && failures++ < 10) {
        ADD_FAILURE() << "mismatch at configuration " << i << " h " << h;
      }
    }
  }
  std::printf("[ figure ] cached and combined calls: %d pairs compared, %d mismatches\n",
      compared, failures);
  EXPECT_EQ(failures, 0);
}

// -----------------------------------------------------------------------------
// FURNACES AND SAMPLING
// -----------------------------------------------------------------------------

// A white fiber (sigma_a = 0) of the given roughness, default alpha and eta.
static hair_material white_material(float beta_m, float beta_n, float alpha = 2) {
  auto material        = hair_material{};
  material.beta_m      = beta_m;
  material.beta_n      = beta_n;
  material.alpha       = alpha;
  material.has_sigma_a = true;
  material.sigma_a     = {0, 0, 0};
  return material;
}

// Local direction from theta and phi (x = sin theta, phi = atan2(z, y)).
static vec3f local_direction(double theta, double phi) {
  return {(float)std::sin(theta), (float)(std::cos(theta) * std::cos(phi)),
      (float)(std::cos(theta) * std::sin(phi))};
}

// Panel breaks for integrating eval_hair_scattering over the sphere in the
// identity fiber frame, for theta_o and h: in theta_i around minus the tilted
// theta_o of each lobe, in the relative azimuth phi_i - phi_o around Phi(p,
// h) and the wrap-around kinks opposite.
static std::pair<std::vector<double>, std::vector<double>> scattering_breaks(
    const hair_precomputed& pre, float alpha_degrees, double theta_o, float h) {
  auto alpha        = (double)radians(alpha_degrees);
  auto tilts        = std::vector<double>{-2 * alpha, alpha, 4 * alpha, 0};
  auto breaks_theta = std::vector<double>{-pif / 2.0, pif / 2.0};
  for (auto p = 0; p < 4; p++) {
    auto t = theta_o + tilts[p];
    auto c = std::atan2(std::sin(t), std::abs(std::cos(t)));
    add_lobe_breaks(breaks_theta, -c, std::sqrt(pre.v[p]), -pif / 2.0, pif / 2.0);
  }
  auto eta_p = std::sqrt(sqr((double)pre.eta) - sqr(std::sin(theta_o))) / std::cos(theta_o);
  auto gamma_t    = std::asin(h / eta_p);
  auto gamma_o    = std::asin((double)h);
  auto breaks_phi = std::vector<double>{-pif, pif};
  for (auto p = 0; p < 3; p++) {
    auto center = 2 * p * gamma_t - 2 * gamma_o + p * pif;
    add_lobe_breaks(breaks_phi, center, pre.s, -pif, pif, true);
    // The wrapped logistic has a kink opposite its centre.
    add_lobe_breaks(breaks_phi, center + pif, 2 * pif, -pif, pif, true);
  }
  return {breaks_theta, breaks_phi};
}

TEST(hair, white_furnace_uniform_sampling) {
  // sigma_a = 0, beta_m, beta_n in {.1, .3, .5, .7, .9}: the cosine-weighted
  // BSDF integrates to 1. Monte Carlo with uniform directions and a random h
  // per sample, 300k samples per pair, fixed seed; tolerance 0.05 (pbrt-v3's).
  auto worst = 0.0;
  auto rng   = make_rng(42);
  for (auto beta_m : {.1f, .3f, .5f, .7f, .9f}) {
    for (auto beta_n : {.1f, .3f, .5f, .7f, .9f}) {
      auto pre = make_hair_precomputed(white_material(beta_m, beta_n));
      auto sum = 0.0;
      const auto samples = 300000;
      for (auto i = 0; i < samples; i++) {
        auto brdf = eval_hair_brdf(pre, -1 + 2 * rand1f(rng), frame3f{});
        auto wo   = sample_sphere(rand2f(rng));
        auto wi   = sample_sphere(rand2f(rng));
        sum += eval_hair_scattering(brdf, wo, wi).y / sample_sphere_pdf(wi);
      }
      auto average = sum / samples;
      worst        = std::max(worst, std::abs(average - 1));
      EXPECT_NEAR(average, 1, 0.05) << "beta_m " << beta_m << " beta_n " << beta_n;
    }
  }
  std::printf("[ figure ] uniform white furnace worst |E - 1| = %.4f\n", worst);
  RecordProperty("uniform_furnace_worst", std::to_string(worst));
}

TEST(hair, white_furnace_quadrature) {
  // Deterministic: integral of eval over theta_i and phi with composite
  // Gauss-Legendre panels refined around every lobe (5 nodes per panel),
  // for beta_m, beta_n in {0.02, 0.05, 0.1, 0.2, 0.3, ..., 1}, theta_o in
  // {-1.2, 0.1, 0.9}, h cycling through {-0.95, -0.3, 0.5, 0.99} and the
  // scale tilt alpha through {0, 2, 10} degrees (432 configurations).
  // Tolerance 0.002.
  auto betas  = std::vector<float>{0.02f, 0.05f, 0.1f, 0.2f, 0.3f, 0.4f, 0.5f, 0.6f, 0.7f,
       0.8f, 0.9f, 1};
  auto thetas = std::vector<double>{-1.2, 0.1, 0.9};
  auto hs     = std::vector<float>{-0.95f, -0.3f, 0.5f, 0.99f};
  auto alphas = std::vector<float>{0, 2, 10};
  auto worst  = 0.0;
  auto count  = 0;
  for (auto beta_m : betas) {
    for (auto beta_n : betas) {
      for (auto theta_o : thetas) {
        auto h        = hs[count % hs.size()];
        auto material = white_material(beta_m, beta_n, alphas[count % alphas.size()]);
        count++;
        auto pre      = make_hair_precomputed(material);
        auto brdf     = eval_hair_brdf(pre, h, frame3f{});
        auto wo       = local_direction(theta_o, pif / 2);
        // Named, not a structured binding: C++17 lambdas cannot capture those (clang).
        auto breaks       = scattering_breaks(pre, material.alpha, theta_o, h);
        auto& breaks_theta = breaks.first;
        auto& breaks_phi   = breaks.second;
        auto integral = integrate_panels(breaks_theta, [&](double theta_i) {
          return std::cos(theta_i) * integrate_panels(breaks_phi, [&](double phi) {
            auto wi = local_direction(theta_i, pif / 2 + phi);
            return (double)eval_hair_scattering(brdf, wo, wi).y;
          }, 5);
        }, 5);
        worst = std::max(worst, std::abs(integral - 1));
        EXPECT_NEAR(integral, 1, 0.002) << "beta_m " << beta_m << " beta_n "
                                        << beta_n << " theta_o " << theta_o
                                        << " alpha " << material.alpha;
      }
    }
  }
  std::printf("[ figure ] quadrature white furnace worst |E - 1| = %.2g\n", worst);
  RecordProperty("quadrature_furnace_worst", std::to_string(worst));
}

// Outgoing directions for the sampling tests: uniform, plus grazing ones
// (|w.x| within 1e-2 .. 1e-6 of 1) a quarter of the time.
static vec3f test_outgoing(rng_state& rng) {
  if (rand1f(rng) < 0.75f) return sample_sphere(rand2f(rng));
  auto sign = rand1f(rng) < 0.5f ? -1.0f : 1.0f;
  auto tiny = std::pow(10.0f, -1 - 2 * rand1f(rng));  // 1e-1 .. 1e-3
  auto phi  = 2 * pif * rand1f(rng);
  return normalize(vec3f{sign, tiny * std::cos(phi), tiny * std::sin(phi)});
}

TEST(hair, sampling_weights_and_sampled_furnace) {
  // sigma_a = 0: eval / pdf must be 1 for every sample (eval and pdf share
  // the A_p-proportional lobe choice), within 0.001. 49 (beta_m, beta_n)
  // pairs in {0.01, 0.1, 0.3, 0.5, 0.7, 0.9, 1}, 6000 samples each (294k in
  // all), h from {-1, -0.999, 0, 0.999, 1} or uniform, a quarter of the
  // outgoing directions grazing, random frames; fixed seed. The mean weight
  // per pair is the sampled furnace: 1 +- 0.01.
  auto betas        = std::vector<float>{0.01f, 0.1f, 0.3f, 0.5f, 0.7f, 0.9f, 1};
  auto hs           = std::vector<float>{-1, -0.999f, 0, 0.999f, 1, 2};
  auto rng          = make_rng(99);
  auto worst_weight = 0.0, worst_furnace = 0.0;
  auto bad          = 0;
  for (auto beta_m : betas) {
    for (auto beta_n : betas) {
      auto pre = make_hair_precomputed(white_material(beta_m, beta_n, 10 * rand1f(rng)));
      auto sum = 0.0;
      const auto samples = 6000;
      for (auto i = 0; i < samples; i++) {
        auto h = hs[rand1i(rng, (int)hs.size())];
        if (h == 2) h = -1 + 2 * rand1f(rng);
        auto frame  = frame_fromz({0, 0, 0}, sample_sphere(rand2f(rng)));
        auto brdf   = eval_hair_brdf(pre, h, frame);
        auto wo     = transform_direction(frame, test_outgoing(rng));
        auto wi     = sample_hair_scattering(brdf, wo, rand2f(rng));
        auto f      = eval_hair_scattering(brdf, wo, wi);
        auto pdf    = sample_hair_scattering_pdf(brdf, wo, wi);
        auto weight = pdf > 0 ? f.y / pdf : 0.0f;
        sum += weight;
        auto deviation = std::abs(weight - 1.0);
        worst_weight   = std::max(worst_weight, deviation);
        if (deviation > 1e-3 && bad++ < 5) {
          ADD_FAILURE() << "weight " << weight << " f " << f.y << " pdf " << pdf
                        << " beta " << beta_m << " " << beta_n << " h " << h
                        << " wo.x " << dot(wo, frame.x);
        }
      }
      auto average  = sum / samples;
      worst_furnace = std::max(worst_furnace, std::abs(average - 1));
      EXPECT_NEAR(average, 1, 0.01) << "beta_m " << beta_m << " beta_n " << beta_n;
    }
  }
  std::printf("[ figure ] sampling weights worst |w - 1| = %.2g; sampled furnace "
              "worst |E - 1| = %.2g\n", worst_weight, worst_furnace);
  RecordProperty("weights_worst", std::to_string(worst_weight));
  RecordProperty("sampled_furnace_worst", std::to_string(worst_furnace));
  EXPECT_EQ(bad, 0);
}

TEST(hair, sampling_consistency) {
  // sigma_a = 0.25, incoming radiance L = z^2 (z the shading normal): the
  // importance-sampled and the uniform estimate of int f L must agree within
  // 1%. beta_m, beta_n in {0.2, 0.4, 0.6, 0.8, 1}; per pair 2 random
  // (outgoing, h) configurations, each integrated by importance sampling
  // (numbers jittered on a 160 x 160 grid, stratification kept by the Morton
  // demux) and by uniform sampling (jittered 320 x 320 grid): 51200 and
  // 204800 samples per pair. Fixed seed. Measured spread over 5 seeds: worst
  // pair 0.3% - 0.5%; both estimators agree to 1e-5 at 10^6 samples.
  auto rng   = make_rng(5);
  auto worst = 0.0;
  for (auto beta_m : {.2f, .4f, .6f, .8f, 1.f}) {
    for (auto beta_n : {.2f, .4f, .6f, .8f, 1.f}) {
      auto material    = white_material(beta_m, beta_n);
      material.sigma_a = {0.25f, 0.25f, 0.25f};
      auto pre         = make_hair_precomputed(material);
      auto importance = 0.0, uniform = 0.0;
      for (auto config = 0; config < 2; config++) {
        auto brdf = eval_hair_brdf(pre, -1 + 2 * rand1f(rng), frame3f{});
        auto wo   = sample_sphere(rand2f(rng));
        auto sum  = 0.0;
        const auto grid_is = 160;
        for (auto i = 0; i < grid_is * grid_is; i++) {
          auto cell = vec2f{(float)(i % grid_is), (float)(i / grid_is)};
          auto wi   = sample_hair_scattering(
              brdf, wo, (cell + rand2f(rng)) / (float)grid_is);
          auto pdf = sample_hair_scattering_pdf(brdf, wo, wi);
          if (pdf > 0) sum += eval_hair_scattering(brdf, wo, wi).y * sqr(wi.z) / pdf;
        }
        importance += sum / sqr(grid_is);
        sum = 0;
        const auto grid_u = 320;
        for (auto i = 0; i < grid_u * grid_u; i++) {
          auto cell = vec2f{(float)(i % grid_u), (float)(i / grid_u)};
          auto wi   = sample_sphere((cell + rand2f(rng)) / (float)grid_u);
          sum += eval_hair_scattering(brdf, wo, wi).y * sqr(wi.z) /
                 sample_sphere_pdf(wi);
        }
        uniform += sum / sqr(grid_u);
      }
      auto difference = std::abs(importance - uniform) / importance;
      worst           = std::max(worst, difference);
      EXPECT_LT(difference, 0.01) << "beta_m " << beta_m << " beta_n " << beta_n;
    }
  }
  std::printf("[ figure ] sampling consistency worst relative difference %.2g\n", worst);
  RecordProperty("consistency_worst", std::to_string(worst));
}

// -----------------------------------------------------------------------------
// SAMPLED LOBE WEIGHTS
// -----------------------------------------------------------------------------

// A random hit for the lobe weight tests: material by melanin (most often),
// sigma_a or colour; beta_m, beta_n in [0.01, 1], alpha in [0, 10] degrees,
// eta in [1.0001, 2]; h uniform or at the edges +-1; a random frame and a hard
// outgoing direction (grazing ones included). The brdf caches the lobes of
// outgoing when `cached`.
struct weight_case {
  hair_material material = {};
  hair_brdf     brdf     = {};
  vec3f         outgoing = {0, 0, 0};
};
static weight_case random_weight_case(rng_state& rng, bool cached) {
  auto  test           = weight_case{};
  auto& material       = test.material;
  material.eumelanin   = 3 * rand1f(rng);
  material.pheomelanin = rand1f(rng) < 0.3f ? 2 * rand1f(rng) : 0;
  material.beta_m      = 0.01f + 0.99f * rand1f(rng);
  material.beta_n      = 0.01f + 0.99f * rand1f(rng);
  material.alpha       = 10 * rand1f(rng);
  material.eta         = rand1f(rng) < 0.1f ? 1.0001f : 1 + rand1f(rng);
  auto kind            = rand1i(rng, 5);
  if (kind == 0) {
    material.has_sigma_a = true;
    material.sigma_a     = {2 * rand1f(rng), 2 * rand1f(rng), 4 * rand1f(rng)};
  } else if (kind == 1) {
    material.has_color = true;
    material.color     = {rand1f(rng), rand1f(rng), rand1f(rng)};
  }
  auto h        = rand1i(rng, 8) == 0 ? (rand1f(rng) < 0.5f ? -1.0f : 1.0f) : 2 * rand1f(rng) - 1;
  auto frame    = frame_fromz({0, 0, 0}, sample_sphere(rand2f(rng)));
  test.outgoing = transform_direction(frame, hard_direction(rng));
  auto pre      = make_hair_precomputed(material);
  test.brdf     = cached ? eval_hair_brdf(pre, h, frame, test.outgoing)
                         : eval_hair_brdf(pre, h, frame);
  return test;
}

TEST(hair, lobe_weight_sample_draws_the_same_direction) {
  // 200k random hits (random_weight_case, half with cached lobes; fixed seed)
  // and random numbers, an eighth of them at 0 or just below 1:
  // sample_hair_scattering_weight returns exactly (bit for bit) the direction
  // sample_hair_scattering returns for the same two numbers, a zero weight
  // with a zero direction, and a finite non-negative weight otherwise. A
  // fiber that returns nothing (eta 1: no reflection; sigma_a 1e4: no
  // transmission) gives a zero direction and weight.
  auto rng      = make_rng(2024);
  auto failures = 0, zero = 0;
  const auto count = 200000;
  for (auto i = 0; i < count && failures < 10; i++) {
    auto test = random_weight_case(rng, i % 2 == 0);
    auto rn   = rand2f(rng);
    if (rand1i(rng, 8) == 0) {
      rn = {rand1f(rng) < 0.5f ? 0.0f : std::nextafter(1.0f, 0.0f), rn.y};
      if (rand1f(rng) < 0.5f) std::swap(rn.x, rn.y);
    }
    auto sample    = sample_hair_scattering_weight(test.brdf, test.outgoing, rn);
    auto incoming  = sample_hair_scattering(test.brdf, test.outgoing, rn);
    auto no_sample = incoming == vec3f{0, 0, 0};
    if (no_sample) zero++;
    auto ok = sample.incoming == incoming && isfinite(sample.weight) &&
              min_component(sample.weight) >= 0 &&
              (!no_sample || sample.weight == vec3f{0, 0, 0});
    if (!ok && failures++ < 10) {
      ADD_FAILURE() << "sample " << i << ": weight sample (" << sample.incoming.x << ", "
                    << sample.incoming.y << ", " << sample.incoming.z << ") plain ("
                    << incoming.x << ", " << incoming.y << ", " << incoming.z
                    << ") weight (" << sample.weight.x << ", " << sample.weight.y << ", "
                    << sample.weight.z << ")";
    }
  }
  std::printf("[ figure ] lobe weight sampler: %d directions compared, %d zero, %d "
              "differences\n", count, zero, failures);
  EXPECT_EQ(failures, 0);
  EXPECT_LT(zero, count / 100);  // the comparison is not vacuous
  auto black    = white_material(0.3f, 0.3f);
  black.eta     = 1;
  black.sigma_a = {1e4f, 1e4f, 1e4f};
  auto brdf     = eval_hair_brdf(black, 0.2f, frame3f{});
  auto outgoing = normalize(vec3f{0.3f, 0.2f, 1});
  auto sample   = sample_hair_scattering_weight(brdf, outgoing, {0.3f, 0.6f});
  EXPECT_EQ(sample.incoming, (vec3f{0, 0, 0}));
  EXPECT_EQ(sample.weight, (vec3f{0, 0, 0}));
  EXPECT_EQ(sample_hair_scattering(brdf, outgoing, vec2f{0.3f, 0.6f}), (vec3f{0, 0, 0}));
}

TEST(hair, lobe_weight_sample_of_four_numbers_draws_the_same_direction) {
  // 100k random hits (random_weight_case, half with cached lobes; fixed
  // seed) and four random numbers: the four-number sample_hair_scattering_
  // weight returns exactly (bit for bit) the direction of the four-number
  // sample_hair_scattering, a finite non-negative weight, and zero with a
  // zero direction; and a direction other than the two-number sampler's for
  // the first two numbers (the numbers are not demuxed).
  auto rng      = make_rng(2025);
  auto failures = 0, differing = 0;
  const auto count = 100000;
  for (auto i = 0; i < count && failures < 10; i++) {
    auto test     = random_weight_case(rng, i % 2 == 0);
    auto rn       = vec4f{rand1f(rng), rand1f(rng), rand1f(rng), rand1f(rng)};
    auto sample   = sample_hair_scattering_weight(test.brdf, test.outgoing, rn);
    auto incoming = sample_hair_scattering(test.brdf, test.outgoing, rn);
    auto ok = sample.incoming == incoming && isfinite(sample.weight) &&
              min_component(sample.weight) >= 0 &&
              (incoming != vec3f{0, 0, 0} || sample.weight == vec3f{0, 0, 0});
    if (!ok && failures++ < 10) ADD_FAILURE() << "sample " << i;
    differing += incoming != sample_hair_scattering(test.brdf, test.outgoing, vec2f{rn.x, rn.y});
  }
  EXPECT_EQ(failures, 0);
  EXPECT_GT(differing, count / 2);
}

TEST(hair, lobe_weight_luminance_equals_eval_over_pdf_luminance) {
  // Lobes are chosen by the luminance of A_p, so per sample
  // luminance(A_p / P(p)) = sum_q luminance(A_q) = luminance(eval / pdf) at
  // the sampled direction (eval = sum M N A, pdf = sum M N P). 200k random
  // hits (random_weight_case, fixed seed); relative tolerance 1e-3; samples
  // with pdf 0 are skipped (and counted, to show the check is not vacuous).
  // Also: the per-channel weight is not always eval / pdf's (the weights
  // differ by lobe, eval / pdf mixes them), else this test would be trivial.
  auto rng      = make_rng(77);
  auto failures = 0, compared = 0, differing = 0;
  auto worst    = 0.0;
  const auto count = 200000;
  for (auto i = 0; i < count && failures < 10; i++) {
    auto test   = random_weight_case(rng, i % 2 == 1);
    auto sample = sample_hair_scattering_weight(test.brdf, test.outgoing, rand2f(rng));
    if (sample.incoming == vec3f{0, 0, 0}) continue;
    auto [f, pdf] = eval_hair_scattering_and_pdf(test.brdf, test.outgoing, sample.incoming);
    if (!(pdf > 0)) continue;
    compared++;
    auto mixture  = f / pdf;
    auto expected = (double)luminance(mixture), value = (double)luminance(sample.weight);
    auto error    = std::abs(value - expected) / std::max(expected, 1e-30);
    worst         = std::max(worst, error);
    if (max_component(abs(sample.weight - mixture)) > 1e-3f * max_component(mixture))
      differing++;
    if (!(error <= 1e-3) && failures++ < 10) {
      ADD_FAILURE() << "sample " << i << ": luminance of weight " << value
                    << ", of eval / pdf " << expected << " (pdf " << pdf << ") beta "
                    << test.material.beta_m << " " << test.material.beta_n << " h "
                    << test.brdf.h << " eta " << test.material.eta;
    }
  }
  std::printf("[ figure ] lobe weight luminance: %d samples compared, worst relative "
              "difference %.2g, %d with other colours than eval / pdf\n",
      compared, worst, differing);
  RecordProperty("lobe_weight_luminance_worst", std::to_string(worst));
  EXPECT_EQ(failures, 0);
  EXPECT_GT(compared, count * 9 / 10);
  EXPECT_GT(differing, count / 10);
}

// Sums of samples and of their squares, per channel: the mean and its
// standard error (from the samples' own variance).
struct channel_stats {
  glm::dvec3 sum = {0, 0, 0}, sum2 = {0, 0, 0};
  int        n   = 0;
};
static void add_sample(channel_stats& stats, const vec3f& x) {
  auto d = glm::dvec3(x);
  stats.sum += d, stats.sum2 += d * d, stats.n++;
}
static double sample_mean(const channel_stats& stats, int c) { return stats.sum[c] / stats.n; }
static double standard_error(const channel_stats& stats, int c) {
  auto n        = (double)stats.n;
  auto variance = std::max(0.0, (stats.sum2[c] - stats.sum[c] * stats.sum[c] / n) / (n - 1));
  return std::sqrt(variance / n);
}

TEST(hair, lobe_weight_and_eval_over_pdf_estimate_the_same_albedo) {
  // Each lobe's directions are drawn with density M_p N_p, so both A_p / P(p)
  // and eval / pdf at the drawn direction estimate the directional albedo
  // sum_p A_p (M_p and N_p integrate to one): five fixed hits (absorbing
  // brown, blond, red, low roughness and a white fiber), 200k independent
  // samples each, fixed seed. Per RGB channel, with SE the standard error of
  // the mean estimated from the samples:
  // - the paired difference of the two means (same directions) is within 4 SE
  //   of the per-sample difference, plus 2e-4 relative (M_p's normalisation is
  //   checked to 1e-4 by longitudinal_normalised, and N_p is float);
  // - each mean is within 4 SE (+ 2e-4 relative) of sum_p A_p of the lobes;
  // - the white fiber: every weight is 1 within 1e-4 (sum_p A_p = 1 and the
  //   lobe is chosen by A_p itself), so the mean weight is 1 within 1e-4.
  // The standard errors are printed: measured 1e-4 to 3e-3 relative for eval
  // / pdf and at most 6e-4 relative for the paired difference, whose 4 SE is
  // checked to stay below 1% relative (the check has power).
  struct albedo_case {
    const char* name;
    vec3f       sigma_a;
    float       beta_m, beta_n, alpha, h, theta_o;
  };
  auto cases = std::vector<albedo_case>{
      {"brown", hair_sigma_a_from_melanin(1.3f, 0), 0.3f, 0.3f, 2, 0.3f, 0.4f},
      {"blond", hair_sigma_a_from_melanin(0.3f, 0), 0.1f, 0.6f, 3, -0.8f, -1.0f},
      {"red", hair_sigma_a_from_melanin(0.2f, 2), 0.6f, 0.9f, 8, 0.95f, 1.3f},
      {"glossy", {0.4f, 1.0f, 2.5f}, 0.05f, 0.1f, 10, 0.0f, 0.9f},
      {"white", {0, 0, 0}, 0.3f, 0.3f, 2, 0.5f, 0.2f},
  };
  auto rng = make_rng(31337);
  for (auto& test : cases) {
    auto white       = test.sigma_a == vec3f{0, 0, 0};
    auto material    = white_material(test.beta_m, test.beta_n, test.alpha);
    material.sigma_a = test.sigma_a;
    auto frame       = frame_fromz({0, 0, 0}, normalize(vec3f{0.3f, -0.5f, 0.8f}));
    auto wo          = transform_direction(frame, local_direction(test.theta_o, 0.7));
    auto brdf        = eval_hair_brdf(make_hair_precomputed(material), test.h, frame, wo);
    auto albedo      = vec3f{0, 0, 0};
    for (auto p = 0; p < 4; p++) albedo += brdf.lobes.a[p];
    auto weights = channel_stats{}, mixtures = channel_stats{}, differences = channel_stats{};
    auto worst_white   = 0.0f;
    const auto samples = 200000;
    for (auto i = 0; i < samples; i++) {
      auto sample   = sample_hair_scattering_weight(brdf, wo, rand2f(rng));
      auto [f, pdf] = sample.incoming == vec3f{0, 0, 0}
                          ? std::pair{vec3f{0, 0, 0}, 0.0f}
                          : eval_hair_scattering_and_pdf(brdf, wo, sample.incoming);
      auto mixture   = pdf > 0 ? f / pdf : vec3f{0, 0, 0};
      add_sample(weights, sample.weight);
      add_sample(mixtures, mixture);
      add_sample(differences, sample.weight - mixture);
      auto deviation = max_component(abs(sample.weight - vec3f{1, 1, 1}));
      if (white) worst_white = std::max(worst_white, deviation);
    }
    for (auto c = 0; c < 3; c++) {
      auto expected = (double)albedo[c], floor = 2e-4 * expected;
      auto weight   = sample_mean(weights, c), weight_error = standard_error(weights, c);
      auto mixture  = sample_mean(mixtures, c), mixture_error = standard_error(mixtures, c);
      auto difference       = sample_mean(differences, c);
      auto difference_error = standard_error(differences, c);
      std::printf("[ figure ] albedo %s [%d]: sum A_p %.5f, weight %.5f +- %.1e, "
                  "eval / pdf %.5f +- %.1e, difference %.1e +- %.1e\n",
          test.name, c, expected, weight, weight_error, mixture, mixture_error, difference,
          difference_error);
      EXPECT_LE(std::abs(difference), 4 * difference_error + floor) << test.name << " " << c;
      EXPECT_LE(4 * difference_error, 0.01 * expected) << test.name << " " << c;
      EXPECT_NEAR(weight, expected, 4 * weight_error + floor) << test.name << " " << c;
      EXPECT_NEAR(mixture, expected, 4 * mixture_error + floor) << test.name << " " << c;
      if (white) EXPECT_NEAR(weight, 1, 1e-4) << "white furnace, channel " << c;
    }
    if (white) EXPECT_LE(worst_white, 1e-4f);
    if (!white) EXPECT_LT(max_component(albedo), 0.95f) << test.name << " absorbs";
  }
}

// -----------------------------------------------------------------------------
// CHI-SQUARE GOODNESS OF FIT OF THE SAMPLER AGAINST THE PDF
// -----------------------------------------------------------------------------

// Regularised upper incomplete gamma function Q(a, x) = Gamma(a, x) / Gamma(a):
// the series of P = 1 - Q for x < a + 1, else the continued fraction of Q
// (Legendre's), evaluated by the modified Lentz method.
static double gamma_q(double a, double x) {
  if (!(x > 0)) return 1;
  auto log_prefix = a * std::log(x) - x - std::lgamma(a);
  if (x < a + 1) {
    // P(a, x) = x^a e^-x / Gamma(a) sum_n x^n / (a (a + 1) ... (a + n)).
    auto term = 1 / a, sum = term;
    for (auto n = 1; n < 10000 && term > sum * 1e-16; n++) {
      term *= x / (a + n);
      sum += term;
    }
    return 1 - sum * std::exp(log_prefix);
  }
  // Gamma(a, x) = x^a e^-x / (x + 1 - a - 1 (1 - a) / (x + 3 - a - ...)).
  const auto tiny = 1e-300;
  auto       b = x + 1 - a, c = 1 / tiny, d = 1 / b, fraction = d;
  for (auto i = 1; i < 10000; i++) {
    auto an = -i * (i - a);
    b += 2;
    d = an * d + b;
    if (std::abs(d) < tiny) d = tiny;
    c = b + an / c;
    if (std::abs(c) < tiny) c = tiny;
    d = 1 / d;
    auto delta = d * c;
    fraction *= delta;
    if (std::abs(delta - 1) < 1e-16) break;
  }
  return std::exp(log_prefix) * fraction;
}

TEST(hair, gamma_q_closed_forms) {
  // Q(1, x) = e^-x; Q(3, x) = e^-x (1 + x + x^2 / 2); Q(1/2, x) = erfc(sqrt x).
  for (auto x : {0.1, 1.0, 2.5, 4.0, 10.0, 40.0}) {
    EXPECT_NEAR(gamma_q(1, x), std::exp(-x), 1e-12 * std::max(1.0, std::exp(-x)));
    EXPECT_NEAR(gamma_q(3, x) / (std::exp(-x) * (1 + x + x * x / 2)), 1, 1e-10);
    EXPECT_NEAR(gamma_q(0.5, x) / std::erfc(std::sqrt(x)), 1, 1e-10);
  }
}

struct chi2_case {
  float beta_m, beta_n, alpha;
  vec3f sigma_a;
  float h, theta_o;
};

// p-value of the chi-square test of `samples` draws of sample_hair_scattering
// (the two- or the four-number overload) against sample_hair_scattering_pdf on a 10 x 20 grid in (sin theta_i, phi_i)
// of the fiber frame. Expected counts integrate the pdf over each cell (6 x 8
// sub-panels of 4 x 4 Gauss-Legendre nodes; d omega = d sin(theta) d phi);
// cells expecting fewer than 5 are pooled, smallest first, until the pool
// expects 5. Also returns the pdf's integral over the sphere.
static double chi2_pvalue(const chi2_case& test, bool four_numbers,
    int samples, uint64_t seed, double& pdf_integral, int& zero_pdf_hits) {
  auto material        = white_material(test.beta_m, test.beta_n, test.alpha);
  material.sigma_a     = test.sigma_a;
  auto frame           = frame_fromz({0, 0, 0}, normalize(vec3f{0.3f, -0.5f, 0.8f}));
  auto brdf            = eval_hair_brdf(material, test.h, frame);
  auto phi_o           = 0.7f;
  auto wo              = brdf.x * std::sin(test.theta_o) +
              brdf.y * (std::cos(test.theta_o) * std::cos(phi_o)) +
              brdf.z * (std::cos(test.theta_o) * std::sin(phi_o));
  const int  rows = 10, cols = 20;
  auto       direction = [&](double u, double phi) {
    auto r = std::sqrt(std::max(0.0, 1 - u * u));
    return normalize(brdf.x * (float)u + brdf.y * (float)(r * std::cos(phi)) +
                     brdf.z * (float)(r * std::sin(phi)));
  };
  static const auto rule     = make_gauss_rule(4);
  auto              expected = std::vector<double>(rows * cols, 0.0);
  for (auto row = 0; row < rows; row++) {
    for (auto col = 0; col < cols; col++) {
      auto u0 = -1 + 2.0 * row / rows, du = 2.0 / rows / 6;
      auto p0 = -pif + 2.0 * pif * col / cols, dp = 2.0 * pif / cols / 8;
      auto sum = 0.0;
      for (auto su = 0; su < 6; su++) {
        for (auto sp = 0; sp < 8; sp++) {
          for (auto i = 0; i < 4; i++) {
            for (auto j = 0; j < 4; j++) {
              auto u   = u0 + du * (su + (rule.nodes[i] + 1) / 2);
              auto phi = p0 + dp * (sp + (rule.nodes[j] + 1) / 2);
              auto w   = rule.weights[i] * rule.weights[j] * du * dp / 4;
              sum += w * sample_hair_scattering_pdf(brdf, wo, direction(u, phi));
            }
          }
        }
      }
      expected[row * cols + col] = sum * samples;
    }
  }
  pdf_integral = 0;
  for (auto e : expected) pdf_integral += e / samples;

  auto observed = std::vector<double>(rows * cols, 0.0);
  auto rng      = make_rng(seed);
  for (auto i = 0; i < samples; i++) {
    auto wi  = four_numbers
                   ? sample_hair_scattering(brdf, wo, vec4f{rand2f(rng), rand2f(rng)})
                   : sample_hair_scattering(brdf, wo, rand2f(rng));
    auto u   = std::clamp(dot(wi, brdf.x), -1.0f, 1.0f);
    auto phi = std::atan2(dot(wi, brdf.z), dot(wi, brdf.y));
    auto row = std::clamp((int)((u + 1) / 2 * rows), 0, rows - 1);
    auto col = std::clamp((int)((phi + pif) / (2 * pif) * cols), 0, cols - 1);
    observed[row * cols + col] += 1;
  }

  // Samples in cells where the pdf integrates to (nearly) nothing.
  zero_pdf_hits = 0;
  for (auto cell = 0; cell < rows * cols; cell++) {
    if (expected[cell] < 1e-9 && observed[cell] > 0) zero_pdf_hits++;
  }

  auto order = std::vector<int>(rows * cols);
  for (auto cell = 0; cell < rows * cols; cell++) order[cell] = cell;
  std::sort(order.begin(), order.end(),
      [&](int a, int b) { return expected[a] < expected[b]; });
  auto statistic = 0.0, pool_expected = 0.0, pool_observed = 0.0;
  auto bins = 0;
  for (auto cell : order) {
    if (pool_expected < 5) {
      pool_expected += expected[cell];
      pool_observed += observed[cell];
      if (pool_expected >= 5) {
        statistic += sqr(pool_observed - pool_expected) / pool_expected;
        bins++;
      }
    } else {
      statistic += sqr(observed[cell] - expected[cell]) / expected[cell];
      bins++;
    }
  }
  return gamma_q((bins - 1) / 2.0, statistic / 2);
}

// Low, middle and high roughness; alpha 0 and 10 degrees; white and
// absorbing; h and theta_o varied, with a grazing and an edge case.
static std::vector<chi2_case> chi2_cases() {
  auto cases     = std::vector<chi2_case>{};
  auto roughness = std::vector<vec2f>{{0.15f, 0.2f}, {0.35f, 0.5f}, {0.8f, 0.9f}};
  auto hs        = std::vector<float>{-0.7f, 0.2f, 0.95f, -0.3f, 0.6f, 0.0f};
  auto thetas    = std::vector<float>{0.3f, -0.9f, 1.2f, -0.1f, 0.7f, -1.3f, 0.5f};
  auto index     = 0;
  for (auto beta : roughness) {
    for (auto alpha : {0.0f, 10.0f}) {
      for (auto sigma_a : {vec3f{0, 0, 0}, vec3f{0.4f, 1.0f, 2.5f}}) {
        cases.push_back({beta.x, beta.y, alpha, sigma_a, hs[index % hs.size()],
            thetas[index % thetas.size()]});
        index++;
      }
    }
  }
  cases.push_back({0.15f, 0.2f, 2, {0.2f, 0.2f, 0.2f}, 1.0f, 1.45f});
  cases.push_back({0.3f, 0.3f, 2, {0.5f, 0.8f, 1.2f}, -1.0f, -0.05f});
  return cases;
}

// Runs the chi-square test over all the cases with one sampler overload.
static void test_chi2_cases(bool four_numbers, uint64_t seed) {
  auto worst_p = 1.0, worst_integral = 0.0;
  for (auto& test : chi2_cases()) {
    auto integral  = 0.0;
    auto zero_hits = 0;
    auto p = chi2_pvalue(test, four_numbers, 100000, seed++, integral, zero_hits);
    std::printf("[ figure ] chi2 (%s) beta %.2f %.2f alpha %2.0f sigma_a %.1f "
                "h %+.2f theta_o %+.2f: p = %.3f, pdf integral %.6f\n",
        four_numbers ? "4 numbers" : "2 numbers", test.beta_m, test.beta_n,
        test.alpha, test.sigma_a.x, test.h, test.theta_o, p, integral);
    worst_p        = std::min(worst_p, p);
    worst_integral = std::max(worst_integral, std::abs(integral - 1));
    EXPECT_GT(p, 0.01) << "beta " << test.beta_m << " " << test.beta_n
                       << " alpha " << test.alpha << " h " << test.h;
    EXPECT_NEAR(integral, 1, 2e-3) << "beta " << test.beta_m << " " << test.beta_n;
    EXPECT_EQ(zero_hits, 0);
  }
  std::printf("[ figure ] chi2 (%s) smallest p-value %.3f; worst |pdf integral "
              "- 1| %.2g\n", four_numbers ? "4 numbers" : "2 numbers", worst_p,
      worst_integral);
  testing::Test::RecordProperty(
      four_numbers ? "chi2_smallest_p_4" : "chi2_smallest_p_2", std::to_string(worst_p));
  testing::Test::RecordProperty("pdf_integral_worst", std::to_string(worst_integral));
}

// 14 parameter sets (chi2_cases), 100000 samples each with fixed seeds:
// p-value > 0.01 each, the pdf integrates to 1 within 2e-3 over the sphere,
// and no sample lands where the pdf is 0. Under a correct sampler p is
// uniform, so 14 sets at 0.01 fail by chance with probability 13% for a
// random seed; the seeds are fixed, and the sampler was also checked at 10^6
// and 4 10^6 samples over many seeds (docs/RESULTS.md, "Hair model"). Deliberate
// mismatches in the sampler fail it: the logistic scale 5% too wide gives
// p < 0.001 for all 14 sets; the variance 5% too wide, for 12 of 14.
TEST(hair, chi_square_two_number_sampler) { test_chi2_cases(false, 1000); }
TEST(hair, chi_square_four_number_sampler) { test_chi2_cases(true, 2000); }

TEST(hair, non_finite_material_values_stay_finite) {
  // Garbage in a material (NaN, inf) must not reach the renderer as NaN.
  auto nan = std::numeric_limits<float>::quiet_NaN();
  auto inf = std::numeric_limits<float>::infinity();
  auto materials = std::vector<hair_material>(4);
  materials[0].beta_m = nan, materials[0].beta_n = nan, materials[0].alpha = nan;
  materials[1].eta = inf, materials[1].alpha = inf;
  materials[2].has_sigma_a = true, materials[2].sigma_a = {inf, nan, 1};
  materials[3].eta = nan, materials[3].has_color = true, materials[3].color = {nan, 0, 2};
  auto rng = make_rng(3);
  for (auto& material : materials) {
    for (auto i = 0; i < 1000; i++) {
      auto brdf = eval_hair_brdf(material, 2 * rand1f(rng) - 1, frame3f{});
      auto wo   = sample_sphere(rand2f(rng));
      auto wi   = sample_hair_scattering(brdf, wo, rand2f(rng));
      auto f    = eval_hair_scattering(brdf, wo, wi);
      auto pdf  = sample_hair_scattering_pdf(brdf, wo, wi);
      ASSERT_TRUE(isfinite(wi) && isfinite(f) && std::isfinite(pdf));
      ASSERT_TRUE(min_component(f) >= 0 && pdf >= 0);
    }
  }
}

// -----------------------------------------------------------------------------
// ALBEDO, LOBE TERMS AND SAMPLED LOBES
// -----------------------------------------------------------------------------

// Nodes and weights of composite Gauss-Legendre (5 nodes a panel) over the
// panels between the breaks.
static std::vector<std::pair<double, double>> panel_nodes(std::vector<double> breaks) {
  static const auto rule = make_gauss_rule(5);
  std::sort(breaks.begin(), breaks.end());
  auto nodes = std::vector<std::pair<double, double>>{};
  for (auto i = 0; i + 1 < (int)breaks.size(); i++) {
    auto a = breaks[i], b = breaks[i + 1];
    if (b - a < 1e-12) continue;
    for (auto k = 0; k < (int)rule.nodes.size(); k++)
      nodes.push_back({(a + b) / 2 + rule.nodes[k] * (b - a) / 2, rule.weights[k] * (b - a) / 2});
  }
  return nodes;
}

// A fixed hit in the identity fiber frame: material, offset h and the
// outgoing direction's theta_o (its azimuth is 0.3).
struct albedo_hit {
  const char* name;
  vec3f       sigma_a;
  float       beta_m, beta_n, alpha, h, theta_o;
};

// The brdf of a hit, with the lobes of its outgoing direction cached.
static hair_brdf make_albedo_brdf(const albedo_hit& hit, vec3f& outgoing) {
  auto material    = white_material(hit.beta_m, hit.beta_n, hit.alpha);
  material.sigma_a = hit.sigma_a;
  outgoing         = local_direction(hit.theta_o, 0.3);
  return eval_hair_brdf(make_hair_precomputed(material), hit.h, frame3f{}, outgoing);
}

TEST(hair, albedo_is_the_integral_of_scattering) {
  // eval_hair_albedo (sum_p A_p, no quadrature) against the integral of
  // eval_hair_scattering over the sphere of incoming directions, per RGB
  // channel, and each lobe's term of eval_hair_scattering_lobes against its
  // A_p (channels summed), by the white furnace's panels (scattering_breaks,
  // 5 x 5 Gauss-Legendre nodes a panel; deterministic). Five materials: white
  // (sigma_a = 0), brown and blond by melanin, red (eu- and pheomelanin) and
  // a sigma_a; beta_m, beta_n from 0.05 to 0.9; each at alpha 0 and 2
  // degrees; theta_o in {-1.2, 0, 0.7, 1.4}, two values of h each out of
  // {-0.95, -0.4, 0.1, 0.6, 0.99} (80 configurations). Tolerance: 2e-5 +
  // 1e-4 relative (the white furnace's quadrature is good to 3e-6). At every
  // node the lobes sum to eval within 1e-6 relative. The white fiber's
  // albedo is 1 within 1e-6; the brdf made without the outgoing direction
  // gives the same albedo, bit for bit.
  auto hits = std::vector<albedo_hit>{
      {"white", {0, 0, 0}, 0.3f, 0.3f, 0, 0, 0},
      {"brown", hair_sigma_a_from_melanin(1.3f, 0), 0.3f, 0.3f, 0, 0, 0},
      {"smooth blond", hair_sigma_a_from_melanin(0.3f, 0), 0.05f, 0.08f, 0, 0, 0},
      {"rough red", hair_sigma_a_from_melanin(0.2f, 2), 0.9f, 0.9f, 0, 0, 0},
      {"sigma_a", {0.4f, 1.0f, 2.5f}, 0.15f, 0.6f, 0, 0, 0},
  };
  auto thetas     = std::vector<double>{-1.2, 0.0, 0.7, 1.4};
  auto hs         = std::vector<float>{-0.95f, -0.4f, 0.1f, 0.6f, 0.99f};
  auto worst      = 0.0, worst_sum = 0.0;
  auto count      = 0;
  for (auto hit : hits) {
    for (auto alpha : {0.0f, 2.0f}) {
      for (auto theta_o : thetas) {
        for (auto k = 0; k < 2; k++) {
          hit.alpha   = alpha;
          hit.theta_o = (float)theta_o;
          hit.h       = hs[count++ % hs.size()];
          auto wo     = vec3f{};
          auto brdf   = make_albedo_brdf(hit, wo);
          auto albedo = eval_hair_albedo(brdf, wo);
          EXPECT_EQ(eval_hair_albedo(eval_hair_brdf(brdf.material, hit.h, frame3f{}), wo), albedo);
          auto breaks       = scattering_breaks(brdf.material, alpha, theta_o, hit.h);
          auto& breaks_theta = breaks.first;
          auto& breaks_phi   = breaks.second;
          auto phis     = panel_nodes(breaks_phi);
          auto integral = std::array<double, 7>{};  // R, G, B, then lobes R ... TRRT+
          for (auto [theta_i, weight_theta] : panel_nodes(breaks_theta)) {
            for (auto [phi, weight_phi] : phis) {
              auto wi     = local_direction(theta_i, 0.3 + phi);
              auto f      = eval_hair_scattering(brdf, wo, wi);
              auto terms  = eval_hair_scattering_lobes(brdf, wo, wi);
              auto weight = weight_theta * weight_phi * std::cos(theta_i);
              auto sum    = vec3f{0, 0, 0};
              for (auto p = 0; p < 4; p++) {
                sum += terms[p];
                integral[3 + p] += weight * ((double)terms[p].x + terms[p].y + terms[p].z);
              }
              for (auto c = 0; c < 3; c++) integral[c] += weight * f[c];
              worst_sum = std::max(worst_sum,
                  (double)max_component(abs(sum - f)) / std::max(max_component(f), 1e-30f));
            }
          }
          auto expect = [&](double value, double expected, const std::string& what) {
            auto error = std::abs(value - expected);
            worst      = std::max(worst, error / std::max(expected, 0.2));
            EXPECT_LE(error, 2e-5 + 1e-4 * expected)
                << hit.name << " alpha " << alpha << " theta_o " << theta_o << " h " << hit.h
                << ": " << what << " integral " << value << ", expected " << expected;
          };
          for (auto c = 0; c < 3; c++)
            expect(integral[c], albedo[c], "albedo channel " + std::to_string(c));
          for (auto p = 0; p < 4; p++) {
            auto a = brdf.lobes.a[p];
            expect(integral[3 + p], (double)a.x + a.y + a.z, "lobe " + std::to_string(p));
          }
          if (hit.sigma_a == vec3f{0, 0, 0}) {
            EXPECT_LE(max_component(abs(albedo - vec3f{1, 1, 1})), 1e-6f) << hit.h;
          } else {
            EXPECT_LT(max_component(albedo), 0.95f) << hit.name << " absorbs";
          }
        }
      }
    }
  }
  std::printf("[ figure ] albedo against quadrature: %d configurations, worst error %.2g "
              "(relative above 0.2); lobes sum to eval within %.2g relative\n",
      count, worst, worst_sum);
  RecordProperty("albedo_quadrature_worst", std::to_string(worst));
  EXPECT_LE(worst_sum, 1e-6);
}

TEST(hair, scattering_lobes_sum_to_scattering) {
  // 200k random hits (random_weight_case: melanin, sigma_a and colour
  // materials, beta in [0.01, 1], alpha in [0, 10], h at the edges, grazing
  // directions; half with cached lobes; fixed seed), with a random hard
  // incoming direction or a sampled one: the four terms are finite and
  // non-negative and sum to eval_hair_scattering within 1e-6 relative; where
  // the lobes are cached each term p is its A_p times one number (M_p N_p),
  // the same for the three channels, within 1e-5 relative (+ 1e-30).
  auto rng      = make_rng(2121);
  auto failures = 0, nonzero = 0;
  auto worst    = 0.0;
  const auto count = 200000;
  for (auto i = 0; i < count && failures < 10; i++) {
    auto cached = i % 2 == 0;
    auto test   = random_weight_case(rng, cached);
    auto frame  = frame3f{test.brdf.x, test.brdf.y, test.brdf.z, {0, 0, 0}};
    auto wi     = rand1i(rng, 2) == 0
                      ? transform_direction(frame, hard_direction(rng))
                      : sample_hair_scattering(test.brdf, test.outgoing, rand2f(rng));
    auto f      = eval_hair_scattering(test.brdf, test.outgoing, wi);
    auto terms  = eval_hair_scattering_lobes(test.brdf, test.outgoing, wi);
    auto sum    = vec3f{0, 0, 0};
    auto ok     = true;
    for (auto p = 0; p < 4; p++) {
      ok = ok && isfinite(terms[p]) && min_component(terms[p]) >= 0;
      sum += terms[p];
      if (!cached) continue;
      // terms[p] = A_p m: m from the largest channel of A_p.
      auto a = test.brdf.lobes.a[p];
      auto c = a.x >= a.y && a.x >= a.z ? 0 : a.y >= a.z ? 1 : 2;
      if (!(a[c] > 0)) continue;
      auto m = terms[p][c] / a[c];
      // (Denormal terms, below 1e-30, keep few digits.)
      ok = ok && max_component(abs(terms[p] - a * m)) <= 1e-5f * max_component(terms[p]) + 1e-30f;
    }
    auto error = (double)max_component(abs(sum - f));
    if (max_component(f) > 0) nonzero++;
    worst = std::max(worst, error / std::max(max_component(f), 1e-30f));
    ok    = ok && error <= 1e-6 * max_component(f);
    if (!ok && failures++ < 10) {
      ADD_FAILURE() << "case " << i << ": eval (" << f.x << ", " << f.y << ", " << f.z
                    << ") lobes sum (" << sum.x << ", " << sum.y << ", " << sum.z << ") h "
                    << test.brdf.h << " cached " << cached;
    }
  }
  std::printf("[ figure ] lobe terms: %d cases, %d non-zero, worst relative |sum - eval| "
              "%.2g\n", count, nonzero, worst);
  EXPECT_EQ(failures, 0);
  EXPECT_GT(nonzero, count / 4);  // not vacuous
}

// Four fixed hits for the lobe-choice tests: white, brown, smooth blond and
// rough red.
static std::vector<albedo_hit> make_lobe_choice_hits() {
  return {
      {"white", {0, 0, 0}, 0.3f, 0.3f, 2, 0.5f, 0.2f},
      {"brown", hair_sigma_a_from_melanin(1.3f, 0), 0.3f, 0.3f, 2, 0.3f, 0.4f},
      {"smooth blond", hair_sigma_a_from_melanin(0.3f, 0), 0.05f, 0.08f, 2, -0.6f, -0.7f},
      {"rough red", hair_sigma_a_from_melanin(0.2f, 2), 0.9f, 0.9f, 0, 0.9f, 1.2f},
  };
}

TEST(hair, lobe_weight_sampler_reports_the_lobe_it_drew) {
  // sample_hair_scattering_weight's lobe p for four fixed hits (white, brown,
  // smooth blond, rough red; 100k samples each, fixed seed):
  // - p is in 0 ... 3 and the weight is A_p / P(p) with P(p) = luminance(A_p)
  //   / sum_q luminance(A_q), within 1e-5 relative;
  // - the lobes' frequencies match P: chi-square with 3 degrees of freedom,
  //   p-value > 0.001;
  // - the lobe belongs to the direction: given the direction wi, lobe q drew
  //   it with probability P(q) M_q N_q / pdf = luminance(term_q) /
  //   luminance(eval) at wi, so the mean of 1{p = q} minus that is 0 within
  //   4 standard errors (+ 2e-4, M_p's normalisation) for every q.
  auto hits = make_lobe_choice_hits();
  auto rng = make_rng(4242);
  for (auto& hit : hits) {
    auto wo    = vec3f{};
    auto brdf  = make_albedo_brdf(hit, wo);
    auto total = 0.0;
    for (auto p = 0; p < 4; p++) total += luminance(brdf.lobes.a[p]);
    auto choice = std::array<double, 4>{};
    for (auto p = 0; p < 4; p++) choice[p] = luminance(brdf.lobes.a[p]) / total;
    auto counts = std::array<double, 4>{};
    auto sums = std::array<double, 4>{}, sums2 = std::array<double, 4>{};
    auto failures = 0;
    const auto samples = 100000;
    for (auto i = 0; i < samples; i++) {
      auto sample = sample_hair_scattering_weight(brdf, wo, rand2f(rng));
      auto p      = sample.lobe;
      if (p < 0 || p > 3 || sample.incoming == vec3f{0, 0, 0}) {
        if (failures++ < 5) ADD_FAILURE() << hit.name << ": lobe " << p;
        continue;
      }
      counts[p] += 1;
      auto expected = brdf.lobes.a[p] / (float)choice[p];
      if (max_component(abs(sample.weight - expected)) > 1e-5f * max_component(expected) &&
          failures++ < 5) {
        ADD_FAILURE() << hit.name << ": lobe " << p << " weight (" << sample.weight.x << ", "
                      << sample.weight.y << ", " << sample.weight.z << "), A_p / P(p) ("
                      << expected.x << ", " << expected.y << ", " << expected.z << ")";
      }
      auto terms = eval_hair_scattering_lobes(brdf, wo, sample.incoming);
      auto all   = 0.0;
      for (auto q = 0; q < 4; q++) all += luminance(terms[q]);
      for (auto q = 0; q < 4; q++) {
        auto d = (p == q ? 1.0 : 0.0) - (all > 0 ? luminance(terms[q]) / all : 0.0);
        sums[q] += d, sums2[q] += d * d;
      }
    }
    EXPECT_EQ(failures, 0) << hit.name;
    auto statistic = 0.0;
    auto lobes     = 0;
    for (auto q = 0; q < 4; q++) {
      if (choice[q] == 0) continue;
      statistic += sqr(counts[q] - samples * choice[q]) / (samples * choice[q]);
      lobes++;
    }
    auto pvalue = gamma_q((lobes - 1) / 2.0, statistic / 2);
    std::printf("[ figure ] sampled lobes %s: P = %.4f %.4f %.4f %.4f, frequencies %.4f %.4f "
                "%.4f %.4f, chi-square p = %.3f\n",
        hit.name, choice[0], choice[1], choice[2], choice[3], counts[0] / samples,
        counts[1] / samples, counts[2] / samples, counts[3] / samples, pvalue);
    EXPECT_GT(pvalue, 0.001) << hit.name;
    for (auto q = 0; q < 4; q++) {
      auto mean  = sums[q] / samples;
      auto error = std::sqrt(std::max(0.0, sums2[q] / samples - mean * mean) / (samples - 1));
      EXPECT_LE(std::abs(mean), 4 * error + 2e-4) << hit.name << " lobe " << q;
    }
  }
}

TEST(hair, guided_lobe_choice_keeps_the_albedo_and_bounds_the_weights) {
  // sample_hair_scattering_weight with a lobe guide, for four fixed hits
  // (white, brown, smooth blond, rough red), five worths (one lobe only, the
  // transmission lobes, uneven, one negative, all zero) and guided shares
  // 0.5 and 0.9; 100k samples each (fixed seed):
  // - the mean weight is the albedo sum_p A_p within 4 standard errors (+
  //   2e-4 relative) per channel: the guide changes the noise, not the mean;
  // - every weight is A_p / P'(p) with P' the guided choice, at most
  //   1 / (1 - guided) times the unguided A_p / P(p) (1e-5 relative);
  // - all worths zero, or guided 0, draw exactly the unguided sample.
  auto hits = make_lobe_choice_hits();
  auto worths = std::vector<std::array<float, 4>>{
      {1, 0, 0, 0}, {0, 1, 1, 1}, {0.2f, 3, 0.05f, 1}, {-1, 2, 1, 0.5f}, {0, 0, 0, 0}};
  auto rng = make_rng(5151);
  for (auto& hit : hits) {
    auto wo     = vec3f{};
    auto brdf   = make_albedo_brdf(hit, wo);
    auto albedo = vec3f{0, 0, 0};
    auto total  = 0.0f;
    for (auto p = 0; p < 4; p++) albedo += brdf.lobes.a[p], total += luminance(brdf.lobes.a[p]);
    for (auto& worth : worths) {
      for (auto guided : {0.5f, 0.9f}) {
        auto weights  = channel_stats{};
        auto failures = 0;
        for (auto i = 0; i < 100000; i++) {
          auto rn     = vec4f{rand1f(rng), rand1f(rng), rand1f(rng), rand1f(rng)};
          auto sample = sample_hair_scattering_weight(brdf, wo, rn, worth, guided);
          add_sample(weights, sample.weight);
          auto plain = sample_hair_scattering_weight(brdf, wo, rn);
          if (worth == std::array<float, 4>{}) {
            if (sample.weight != plain.weight || sample.incoming != plain.incoming)
              if (failures++ < 5) ADD_FAILURE() << hit.name << ": all worths 0 changed the sample";
            continue;
          }
          auto p = sample.lobe;
          if (p < 0 || p > 3) {
            if (failures++ < 5) ADD_FAILURE() << hit.name << ": lobe " << p;
            continue;
          }
          auto unguided = luminance(brdf.lobes.a[p]) > 0
                              ? max_component(brdf.lobes.a[p]) * total / luminance(brdf.lobes.a[p])
                              : 0.0f;
          if (max_component(sample.weight) > unguided / (1 - guided) * (1 + 1e-5f) &&
              failures++ < 5)
            ADD_FAILURE() << hit.name << ": lobe " << p << " weight "
                          << max_component(sample.weight) << " above " << unguided / (1 - guided);
        }
        EXPECT_EQ(failures, 0) << hit.name;
        for (auto c = 0; c < 3; c++) {
          auto mean = sample_mean(weights, c), error = standard_error(weights, c);
          EXPECT_NEAR(mean, albedo[c], 4 * error + 2e-4 * albedo[c])
              << hit.name << " guided " << guided << " worth " << worth[0] << " " << worth[1]
              << " " << worth[2] << " " << worth[3] << " channel " << c;
        }
      }
    }
    auto rn = vec4f{0.3f, 0.6f, 0.2f, 0.9f};
    auto a = sample_hair_scattering_weight(brdf, wo, rn, worths[2], 0.0f);
    auto b = sample_hair_scattering_weight(brdf, wo, rn);
    EXPECT_EQ(a.incoming, b.incoming) << hit.name;
    EXPECT_EQ(a.weight, b.weight) << hit.name;
  }
}

TEST(hair, lobe_directions_are_where_each_lobe_peaks) {
  // hair_lobe_directions of smooth fibres (beta_m = beta_n = 0.1, no tilt
  // and 3 degrees; blond and brown; three offsets and outgoing angles):
  // R, TT and TRT's directions are unit vectors at which the lobe's own term
  // (eval_hair_scattering_lobes) is at least that at 256 random directions
  // (fixed seed), and not below 1/4 of its largest value over them; the
  // higher orders' direction lies along the fibre (the mean of a uniform
  // azimuth), its length cos of the tilted theta at most 1.
  auto rng = make_rng(777);
  for (auto alpha : {0.0f, 3.0f}) {
    for (auto eumelanin : {0.3f, 1.3f}) {
      for (auto h : {-0.7f, 0.0f, 0.4f}) {
        for (auto theta_o : {-0.8f, 0.1f, 0.6f}) {
          auto hit  = albedo_hit{"smooth", hair_sigma_a_from_melanin(eumelanin, 0), 0.1f, 0.1f,
              alpha, h, theta_o};
          auto wo   = vec3f{};
          auto brdf = make_albedo_brdf(hit, wo);
          auto directions = hair_lobe_directions(brdf, wo);
          for (auto p = 0; p < 3; p++) {
            EXPECT_NEAR(length(directions[p]), 1, 1e-5f) << p;
            auto at_centre = luminance(eval_hair_scattering_lobes(brdf, wo, directions[p])[p]);
            auto largest   = 0.0f;
            for (auto i = 0; i < 256; i++) {
              auto wi = sample_sphere(rand2f(rng));
              largest = std::max(largest, luminance(eval_hair_scattering_lobes(brdf, wo, wi)[p]));
            }
            EXPECT_GE(at_centre, largest) << "lobe " << p << " h " << h << " theta " << theta_o;
            EXPECT_GT(at_centre, 0.0f) << "lobe " << p;
          }
          EXPECT_NEAR(std::abs(dot(directions[3], brdf.x)), length(directions[3]), 1e-6f);
          EXPECT_LE(length(directions[3]), 1 + 1e-6f);
        }
      }
    }
  }
}
