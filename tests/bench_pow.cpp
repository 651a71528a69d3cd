//
// The fast integer power against std::pow, as the thesis measured it. The hair
// model raises the roughness to the 20th and 22nd powers (Chiang et al. 2016,
// eqs. 7 and 8); the hair library does it once per material, in
// make_hair_precomputed, so the choice can only matter where those terms are
// computed at every hit (the thesis's layout, `yscene render --hair-per-hit`).
// This measures each level: the power alone, the per-material terms, and one
// hit's terms with and without them (1024 roughness values from 0.01 to 1,
// fixed seed).
// Run: bench_pow --benchmark_repetitions=5 --benchmark_report_aggregates_only=true
//

#include <benchmark/benchmark.h>
#include <yocto/yocto_sampling.h>
#include <yocto_hair/yocto_hair.h>

#include <cmath>
#include <vector>

using namespace yocto;

static const std::vector<float>& get_betas() {
  static const auto betas = [] {
    auto rng   = make_rng(2024);
    auto betas = std::vector<float>(1024);
    for (auto& beta : betas) beta = 0.01f + 0.99f * rand1f(rng);
    return betas;
  }();
  return betas;
}

// The pair of powers of one material: beta_m^20 and beta_n^22.
static void bench_std_pow(benchmark::State& state) {
  auto& betas = get_betas();
  auto  i     = 0;
  for (auto _ : state) {
    auto beta = betas[i++ & 1023];
    benchmark::DoNotOptimize(std::pow(beta, 20.0f) + std::pow(beta, 22.0f));
  }
}
BENCHMARK(bench_std_pow);

static void bench_fast_pow(benchmark::State& state) {
  auto& betas = get_betas();
  auto  i     = 0;
  for (auto _ : state) {
    auto beta = betas[i++ & 1023];
    benchmark::DoNotOptimize(pow_int<20>(beta) + pow_int<22>(beta));
  }
}
BENCHMARK(bench_fast_pow);

// Everything the hair library computes per material (std::pow included).
static void bench_make_hair_precomputed(benchmark::State& state) {
  auto& betas = get_betas();
  auto  i     = 0;
  for (auto _ : state) {
    auto material   = hair_material{};
    material.beta_m = betas[i++ & 1023];
    material.beta_n = betas[(i * 7) & 1023];
    benchmark::DoNotOptimize(make_hair_precomputed(material));
  }
}
BENCHMARK(bench_make_hair_precomputed);

static void bench_make_hair_precomputed_fast_pow(benchmark::State& state) {
  auto& betas = get_betas();
  auto  i     = 0;
  for (auto _ : state) {
    auto material   = hair_material{};
    material.beta_m = betas[i++ & 1023];
    material.beta_n = betas[(i * 7) & 1023];
    benchmark::DoNotOptimize(make_hair_precomputed(material, true));
  }
}
BENCHMARK(bench_make_hair_precomputed_fast_pow);

// One hit's terms, with the material terms cached (the renderer's default)
// and computed at the hit (--hair-per-hit, the thesis's layout).
static void bench_eval_hair_brdf_cached(benchmark::State& state) {
  auto& betas    = get_betas();
  auto  material = hair_material{};
  auto  cached   = make_hair_precomputed(material);
  auto  frame    = frame_fromz({0, 0, 0}, normalize(vec3f{0.3f, 0.2f, 1}));
  auto  i        = 0;
  for (auto _ : state) {
    auto h = 2 * betas[i++ & 1023] - 1;
    benchmark::DoNotOptimize(eval_hair_brdf(cached, h, frame));
  }
}
BENCHMARK(bench_eval_hair_brdf_cached);

static void bench_eval_hair_brdf_per_hit(benchmark::State& state) {
  auto& betas    = get_betas();
  auto  material = hair_material{};
  auto  frame    = frame_fromz({0, 0, 0}, normalize(vec3f{0.3f, 0.2f, 1}));
  auto  i        = 0;
  for (auto _ : state) {
    auto h = 2 * betas[i++ & 1023] - 1;
    benchmark::DoNotOptimize(eval_hair_brdf(material, h, frame));
  }
}
BENCHMARK(bench_eval_hair_brdf_per_hit);

static void bench_eval_hair_brdf_per_hit_fast_pow(benchmark::State& state) {
  auto& betas    = get_betas();
  auto  material = hair_material{};
  auto  frame    = frame_fromz({0, 0, 0}, normalize(vec3f{0.3f, 0.2f, 1}));
  auto  i        = 0;
  for (auto _ : state) {
    auto h = 2 * betas[i++ & 1023] - 1;
    benchmark::DoNotOptimize(eval_hair_brdf(make_hair_precomputed(material, true), h, frame));
  }
}
BENCHMARK(bench_eval_hair_brdf_per_hit_fast_pow);

// The fast power gives the same values (relative difference of a few ulps):
// checked once here so that the timing compares equal work.
static void bench_pow_agreement(benchmark::State& state) {
  auto worst = 0.0f;
  for (auto beta : get_betas()) {
    auto exact = std::pow(beta, 20.0f), fast = pow_int<20>(beta);
    if (exact > 0) worst = std::max(worst, std::abs(fast - exact) / exact);
  }
  for (auto _ : state) benchmark::DoNotOptimize(worst);
  state.counters["max_relative_difference"] = worst;
  if (!(worst < 1e-5f)) state.SkipWithError("pow_int<20> disagrees with std::pow");
}
BENCHMARK(bench_pow_agreement)->Iterations(1);
BENCHMARK_MAIN();
