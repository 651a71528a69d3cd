//
// Benchmarks of Yocto/PbrtIO: parsing speed of curve-heavy pbrt files, plain
// and gzip'd, in the syntax of the real hair scenes (one Shape "curve" per
// segment, chained into strands). Reports curves per second.
//

#include <benchmark/benchmark.h>
#include <unistd.h>
#include <yocto/yocto_pbrtio.h>
#include <zlib.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <random>

using namespace yocto;
namespace fs = std::filesystem;

// Writes `num_curves` curves as strands of 16 segments, with the number
// formatting of the real files (6 significant digits).
static std::string make_curves_text(int num_curves) {
  auto text = std::string{"Material \"hair\" \"float eumelanin\" 1.3\n"};
  auto rng  = std::mt19937{7};
  auto uni  = std::uniform_real_distribution<float>{-1, 1};
  auto p    = vec3f{0, 0, 0};
  char buffer[512];
  for (auto i = 0; i < num_curves; i++) {
    if (i % 16 == 0) p = {uni(rng) * 10, uni(rng) * 10, uni(rng) * 10};
    auto q = std::array<vec3f, 4>{};
    q[0]   = p;
    for (auto k = 1; k < 4; k++) q[k] = q[k - 1] + vec3f{uni(rng), uni(rng), 1} * 0.05f;
    std::snprintf(buffer, sizeof(buffer),
        "Shape \"curve\" \"point P\" [ %g %g %g %g %g %g %g %g %g %g %g %g ] "
        "\"float width0\" [ %g ] \"float width1\" [ %g ] \"string type\" [ \"cylinder\" ]\n",
        q[0].x, q[0].y, q[0].z, q[1].x, q[1].y, q[1].z, q[2].x, q[2].y, q[2].z, q[3].x,
        q[3].y, q[3].z, 0.008f, 0.007f);
    text += buffer;
    p = q[3];
  }
  return text;
}

// The scene files are written once per process and removed at exit.
struct bench_files {
  std::string dir, text;
  bench_files(int num_curves) {
    dir  = (fs::temp_directory_path() / ("yocto_pbrtio_bench_" + std::to_string(getpid()))).string();
    text = make_curves_text(num_curves);
    fs::create_directories(dir);
    std::ofstream(dir + "/curves.pbrt", std::ios::binary) << text;
    auto file = gzopen((dir + "/curves.pbrt.gz").c_str(), "wb6");
    gzwrite(file, text.data(), (unsigned)text.size());
    gzclose(file);
    std::ofstream(dir + "/plain.pbrt") << "WorldBegin\nInclude \"curves.pbrt\"\n";
    std::ofstream(dir + "/gzip.pbrt") << "WorldBegin\nInclude \"curves.pbrt.gz\"\n";
  }
  ~bench_files() { fs::remove_all(dir); }
};

static void bench_load(benchmark::State& state, bool gzip) {
  auto        num_curves = (int)state.range(0);
  static auto files      = bench_files{num_curves};
  auto        filename   = files.dir + (gzip ? "/gzip.pbrt" : "/plain.pbrt");
  for (auto _ : state) {
    auto scene    = scene_data{};
    auto error    = std::string{};
    auto warnings = std::vector<std::string>{};
    if (!load_pbrt_scene(filename, scene, error, {}, &warnings))
      state.SkipWithError(error.c_str());
    benchmark::DoNotOptimize(scene.shapes.data());
  }
  state.counters["curves/s"] = benchmark::Counter(
      (double)num_curves * state.iterations(), benchmark::Counter::kIsRate);
  state.counters["MB/s"] = benchmark::Counter(
      (double)files.text.size() * state.iterations() / 1e6, benchmark::Counter::kIsRate);
}

static void bench_load_plain(benchmark::State& state) { bench_load(state, false); }
static void bench_load_gzip(benchmark::State& state) { bench_load(state, true); }
BENCHMARK(bench_load_plain)->Arg(1 << 18)->Unit(benchmark::kMillisecond);
BENCHMARK(bench_load_gzip)->Arg(1 << 18)->Unit(benchmark::kMillisecond);

BENCHMARK_MAIN();
