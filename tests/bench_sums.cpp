//
// What the exact sums cost a render: adding one RGB sample to a pixel's
// 192-bit fixed-point sums (fixed_sum3, what the tracer does since renders
// can be split by sample ranges) against the double sums it replaced. The
// samples are a render's kind of values (1024 of them, fixed seed: mostly
// below 1, some tiny, a few fireflies); pixels cycle through 4096 sums, as a
// pass over an image row would.
// Run: bench_sums --benchmark_repetitions=5 --benchmark_report_aggregates_only=true
//

#include <benchmark/benchmark.h>
#include <yocto/yocto_sampling.h>

#include <vector>

using namespace yocto;

static const std::vector<vec3f>& get_samples() {
  static const auto samples = [] {
    auto rng     = make_rng(2026);
    auto samples = std::vector<vec3f>(1024);
    for (auto& sample : samples) {
      auto scale = rand1i(rng, 16) == 0 ? 1000.0f : rand1i(rng, 16) == 0 ? 1e-6f : 1.0f;
      sample     = scale * rand3f(rng);
    }
    return samples;
  }();
  return samples;
}

static void bench_fixed_sum(benchmark::State& state) {
  auto& samples = get_samples();
  auto  sums    = std::vector<fixed_sum3>(4096);
  auto  i       = 0;
  for (auto _ : state) {
    add_fixed(sums[i & 4095], samples[i & 1023]);
    i++;
  }
  benchmark::DoNotOptimize(sums.data());
}
BENCHMARK(bench_fixed_sum);

static void bench_double_sum(benchmark::State& state) {
  auto& samples = get_samples();
  auto  sums    = std::vector<glm::dvec3>(4096);
  auto  i       = 0;
  for (auto _ : state) {
    sums[i & 4095] += glm::dvec3(samples[i & 1023]);
    i++;
  }
  benchmark::DoNotOptimize(sums.data());
}
BENCHMARK(bench_double_sum);

BENCHMARK_MAIN();
