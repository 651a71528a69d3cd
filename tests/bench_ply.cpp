//
// Speed of PLY fiber files: a hair model has millions of curves.
// Run: build/tests/bench_ply (files go to the system temporary directory
// and are removed at the end).
//

#include <benchmark/benchmark.h>
#include <unistd.h>
#include <yocto/yocto_ply.h>

#include <filesystem>

using namespace yocto;

namespace {

// Strands of chained Bezier curves: 3 new control points per curve, a radius
// per control point, as converted hair models are.
shape_data make_hair(int num_curves) {
  auto shape             = shape_data{};
  auto curves_per_strand = 16;
  for (auto c = 0; c < num_curves; c++) {
    auto k = c % curves_per_strand;
    if (k == 0) {
      shape.positions.push_back({c * 1e-3f, 0, 0});
      shape.radius.push_back(0.004f);
    }
    auto base = (int)shape.positions.size() - 1;
    for (auto i = 1; i <= 3; i++) {
      shape.positions.push_back({c * 1e-3f, 0.1f * (3 * k + i), 0.01f * i});
      shape.radius.push_back(0.004f);
    }
    shape.curves.push_back({base, base + 1, base + 2, base + 3});
  }
  return shape;
}

std::string bench_file(const std::string& name) {
  return (std::filesystem::temp_directory_path() /
          ("yocto-bench-" + std::to_string(getpid()) + "-" + name))
      .string();
}

void bench_load(benchmark::State& state, bool ascii) {
  auto num_curves = (int)state.range(0);
  auto filename   = bench_file(ascii ? "ascii.ply" : "binary.ply");
  auto error      = std::string{};
  if (!save_shape(filename, make_hair(num_curves), error, ascii)) {
    state.SkipWithError(error.c_str());
    return;
  }
  auto bytes = std::filesystem::file_size(filename);
  for (auto _ : state) {
    auto shape = shape_data{};
    if (!load_shape(filename, shape, error)) state.SkipWithError(error.c_str());
    benchmark::DoNotOptimize(shape.curves.data());
  }
  state.SetItemsProcessed(state.iterations() * num_curves);
  state.SetBytesProcessed(state.iterations() * (int64_t)bytes);
  std::filesystem::remove(filename);
}

void bench_save(benchmark::State& state) {
  auto shape    = make_hair((int)state.range(0));
  auto filename = bench_file("saved.ply");
  auto error    = std::string{};
  for (auto _ : state)
    if (!save_shape(filename, shape, error)) state.SkipWithError(error.c_str());
  state.SetItemsProcessed(state.iterations() * state.range(0));
  std::filesystem::remove(filename);
}

}  // namespace

BENCHMARK_CAPTURE(bench_load, binary, false)->Arg(1 << 20)->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(bench_load, ascii, true)->Arg(1 << 17)->Unit(benchmark::kMillisecond);
BENCHMARK(bench_save)->Arg(1 << 20)->Unit(benchmark::kMillisecond);
BENCHMARK_MAIN();
