//
// Micro-benchmarks of the hair model: ns per call of eval_hair_brdf,
// eval_hair_scattering, sample_hair_scattering, sample_hair_scattering_pdf,
// eval_hair_scattering_and_pdf and the hair work of one bounce, over a fixed
// set of 1024 random configurations (materials from glassy to rough,
// absorbing and not, random h, frames and directions; fixed seed).
// Run: bench_hair --benchmark_repetitions=5 --benchmark_report_aggregates_only=true
//

#include <benchmark/benchmark.h>
#include <yocto/yocto_sampling.h>
#include <yocto_hair/yocto_hair.h>

#include <vector>

using namespace yocto;

struct hair_config {
  hair_precomputed material = {};
  hair_brdf        brdf     = {};
  float            h        = 0;
  frame3f          frame    = {};
  vec3f            outgoing = {0, 0, 1}, incoming = {0, 0, 1};
  vec2f            rn       = {0, 0};
};

static const std::vector<hair_config>& get_configs() {
  static const auto configs = [] {
    auto configs = std::vector<hair_config>(1024);
    auto rng     = make_rng(2024);
    for (auto& config : configs) {
      auto material        = hair_material{};
      material.beta_m      = 0.01f + 0.99f * rand1f(rng);
      material.beta_n      = 0.01f + 0.99f * rand1f(rng);
      material.alpha       = 4 * rand1f(rng);
      material.eumelanin   = 2 * rand1f(rng);
      material.pheomelanin = rand1f(rng);
      config.material      = make_hair_precomputed(material);
      config.h             = -1 + 2 * rand1f(rng);
      config.frame         = frame_fromz({0, 0, 0}, sample_sphere(rand2f(rng)));
      config.brdf          = eval_hair_brdf(config.material, config.h, config.frame);
      config.outgoing      = sample_sphere(rand2f(rng));
      config.incoming      = sample_sphere(rand2f(rng));
      config.rn            = rand2f(rng);
    }
    return configs;
  }();
  return configs;
}

static void bench_eval_hair_brdf(benchmark::State& state) {
  auto& configs = get_configs();
  auto  i       = 0;
  for (auto _ : state) {
    auto& config = configs[i++ & 1023];
    benchmark::DoNotOptimize(eval_hair_brdf(config.material, config.h, config.frame));
  }
}
BENCHMARK(bench_eval_hair_brdf);

static void bench_eval_hair_scattering(benchmark::State& state) {
  auto& configs = get_configs();
  auto  i       = 0;
  for (auto _ : state) {
    auto& config = configs[i++ & 1023];
    benchmark::DoNotOptimize(
        eval_hair_scattering(config.brdf, config.outgoing, config.incoming));
  }
}
BENCHMARK(bench_eval_hair_scattering);

static void bench_sample_hair_scattering(benchmark::State& state) {
  auto& configs = get_configs();
  auto  i       = 0;
  for (auto _ : state) {
    auto& config = configs[i++ & 1023];
    benchmark::DoNotOptimize(
        sample_hair_scattering(config.brdf, config.outgoing, config.rn));
  }
}
BENCHMARK(bench_sample_hair_scattering);

static void bench_sample_hair_scattering_pdf(benchmark::State& state) {
  auto& configs = get_configs();
  auto  i       = 0;
  for (auto _ : state) {
    auto& config = configs[i++ & 1023];
    benchmark::DoNotOptimize(
        sample_hair_scattering_pdf(config.brdf, config.outgoing, config.incoming));
  }
}
BENCHMARK(bench_sample_hair_scattering_pdf);

static void bench_eval_hair_scattering_and_pdf(benchmark::State& state) {
  auto& configs = get_configs();
  auto  i       = 0;
  for (auto _ : state) {
    auto& config = configs[i++ & 1023];
    benchmark::DoNotOptimize(
        eval_hair_scattering_and_pdf(config.brdf, config.outgoing, config.incoming));
  }
}
BENCHMARK(bench_eval_hair_scattering_and_pdf);

// The hair work of one path-tracer bounce: the per-hit brdf, a light sample's
// eval and pdf, a BSDF sample and its eval and pdf. First with separate calls
// and a brdf that knows nothing of the outgoing direction, then as the
// renderer does it: the brdf made for the outgoing direction and the combined
// eval and pdf.
static void bench_hair_bounce_separate_calls(benchmark::State& state) {
  auto& configs = get_configs();
  auto  i       = 0;
  for (auto _ : state) {
    auto& config = configs[i++ & 1023];
    auto  brdf   = eval_hair_brdf(config.material, config.h, config.frame);
    auto  f      = eval_hair_scattering(brdf, config.outgoing, config.incoming);
    auto  pdf    = sample_hair_scattering_pdf(brdf, config.outgoing, config.incoming);
    auto  wi     = sample_hair_scattering(brdf, config.outgoing, config.rn);
    f += eval_hair_scattering(brdf, config.outgoing, wi);
    pdf += sample_hair_scattering_pdf(brdf, config.outgoing, wi);
    benchmark::DoNotOptimize(f);
    benchmark::DoNotOptimize(pdf);
  }
}
BENCHMARK(bench_hair_bounce_separate_calls);

static void bench_hair_bounce_cached_and_combined(benchmark::State& state) {
  auto& configs = get_configs();
  auto  i       = 0;
  for (auto _ : state) {
    auto& config = configs[i++ & 1023];
    auto brdf = eval_hair_brdf(config.material, config.h, config.frame, config.outgoing);
    auto [f, pdf] = eval_hair_scattering_and_pdf(brdf, config.outgoing, config.incoming);
    auto wi       = sample_hair_scattering(brdf, config.outgoing, config.rn);
    auto [f2, pdf2] = eval_hair_scattering_and_pdf(brdf, config.outgoing, wi);
    benchmark::DoNotOptimize(f + f2);
    benchmark::DoNotOptimize(pdf + pdf2);
  }
}
BENCHMARK(bench_hair_bounce_cached_and_combined);

// The per-material work, which the renderer caches (for reference).
static void bench_make_hair_precomputed(benchmark::State& state) {
  auto material = hair_material{};
  auto i        = 0;
  for (auto _ : state) {
    material.beta_m = 0.01f + (i++ & 1023) / 1100.0f;
    benchmark::DoNotOptimize(make_hair_precomputed(material));
  }
}
BENCHMARK(bench_make_hair_precomputed);

BENCHMARK_MAIN();
