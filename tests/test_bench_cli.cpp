//
// End-to-end tests of the yscene render flags the benchmark drives:
// checkpoints at powers of two, the time budget, tessellation into lines,
// the machine-readable stats line and the Embree-only ray replay.
//

#include <gtest/gtest.h>
#include <sys/wait.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

#include "run_yscene.h"

namespace fs = std::filesystem;

static std::string read_bytes(const fs::path& path) {
  auto stream = std::ifstream(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(stream), {});
}

// The value of key=VALUE in the output's line starting with `prefix`.
static std::string field(const std::string& output, const std::string& prefix,
    const std::string& key) {
  auto stream = std::istringstream(output);
  for (auto line = std::string{}; std::getline(stream, line);) {
    if (line.rfind(prefix, 0) != 0) continue;
    auto at = line.find(" " + key + "=");
    if (at == std::string::npos) continue;
    auto begin = at + key.size() + 2;
    return line.substr(begin, line.find(' ', begin) - begin);
  }
  return "";
}

// A generated lock of curls (20 strands of 4 Bezier segments) in a fresh
// temporary directory.
struct bench_cli : ::testing::Test {
  fs::path dir, scene;
  void     SetUp() override {
    dir = fs::temp_directory_path() /
          ("yscene-bench-" + std::string(::testing::UnitTest::GetInstance()
                                             ->current_test_info()
                                             ->name()) +
              "-" + std::to_string(getpid()));
    fs::remove_all(dir);
    fs::create_directories(dir);
    scene       = dir / "lock.json";
    auto result = run_yscene("hair --style curls --strands 20 --segments 4 --output " +
                             scene.string());
    ASSERT_EQ(result.status, 0) << result.output;
  }
  void TearDown() override { fs::remove_all(dir); }
};

TEST_F(bench_cli, checkpoints_are_saved_at_powers_of_two_and_match_the_final_image) {
  auto output = dir / "out.pfm";
  // Uniform sampling: adaptive rates are planned for the whole sample count,
  // so an adaptive checkpoint is not the render of its sample count.
  auto result = run_yscene("render " + scene.string() + " -o " + output.string() +
                           " -r 24 -s 6 -q --checkpoints --no-adaptive");
  ASSERT_EQ(result.status, 0) << result.output;
  for (auto spp : {"00001", "00002", "00004"})
    EXPECT_TRUE(fs::exists(dir / ("out-" + std::string(spp) + "spp.pfm"))) << spp;
  EXPECT_FALSE(fs::exists(dir / "out-00006spp.pfm"));
  EXPECT_EQ(field(result.output, "checkpoint spp=4", "file"),
      (dir / "out-00004spp.pfm").string());
  // 6 spp is no power of two: the final image is not the 4-spp checkpoint;
  // at 4 spp it is, byte for byte.
  auto four = dir / "four.pfm";
  ASSERT_EQ(run_yscene("render " + scene.string() + " -o " + four.string() +
                       " -r 24 -s 4 -q --no-adaptive")
                .status,
      0);
  EXPECT_EQ(read_bytes(four), read_bytes(dir / "out-00004spp.pfm"));
  EXPECT_NE(read_bytes(output), read_bytes(dir / "out-00004spp.pfm"));
}

TEST_F(bench_cli, a_spent_time_budget_stops_at_the_next_power_of_two) {
  auto result = run_yscene("render " + scene.string() + " -o " + (dir / "out.pfm").string() +
                           " -r 24 -s 64 -q --stats --time-budget 0.000001");
  ASSERT_EQ(result.status, 0) << result.output;
  EXPECT_EQ(field(result.output, "stats", "spp"), "1");
}

TEST_F(bench_cli, lines_tessellate_every_curve_into_the_given_segments) {
  auto native = run_yscene("render " + scene.string() + " -o " + (dir / "a.pfm").string() +
                           " -r 16 -s 1 -q --stats");
  auto lines  = run_yscene("render " + scene.string() + " -o " + (dir / "b.pfm").string() +
                          " -r 16 -s 1 -q --stats --curves lines --segments 3");
  ASSERT_EQ(native.status, 0) << native.output;
  ASSERT_EQ(lines.status, 0) << lines.output;
  auto curves = std::stoll(field(native.output, "stats", "segments"));
  EXPECT_EQ(curves, 20 * 4);
  EXPECT_EQ(std::stoll(field(lines.output, "stats", "segments")), 3 * curves);
  EXPECT_GT(std::stoll(field(lines.output, "stats", "bvh_bytes")), 0);
}

TEST_F(bench_cli, embree_only_replays_the_render_rays_and_writes_no_image) {
  auto output = dir / "unused.pfm";
  auto result = run_yscene("render " + scene.string() + " -o " + output.string() +
                           " -r 24 -s 2 -q --stats --embree-only");
  ASSERT_EQ(result.status, 0) << result.output;
  EXPECT_NE(result.output.find("renderer / embree:"), std::string::npos) << result.output;
  EXPECT_GT(std::stoll(field(result.output, "stats", "rays")), 24 * 24 * 2 / 2);
  EXPECT_FALSE(fs::exists(output));
}
