//
// Renders split by sample ranges: the exact sums, the scene fingerprint, the
// part files, and `yscene merge` against one render, bit for bit.
//

#include <OpenImageIO/imageio.h>
#include <gtest/gtest.h>
#include <unistd.h>
#include <yocto/yocto_sampling.h>
#include <yocto/yocto_sceneio.h>
#include <yocto/yocto_trace.h>

#include <algorithm>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>

#include "run_yscene.h"

using namespace yocto;
namespace fs = std::filesystem;

// -----------------------------------------------------------------------------
// EXACT SUMS
// -----------------------------------------------------------------------------

// Samples as a render makes them: mostly moderate, some tiny, some huge,
// some negative (round-off), and zeros.
static std::vector<vec3f> make_samples(int count, uint64_t seed) {
  auto rng     = make_rng(seed);
  auto samples = std::vector<vec3f>(count);
  for (auto& sample : samples) {
    for (auto c = 0; c < 3; c++) {
      auto kind  = rand1i(rng, 6);
      auto value = rand1f(rng);
      sample[c]  = kind == 0   ? 0
                   : kind == 1 ? std::ldexp(value, -30 - rand1i(rng, 90))  // below 2^-41 too
                   : kind == 2 ? std::ldexp(value, rand1i(rng, 60))        // fireflies
                   : kind == 3 ? -std::ldexp(value, -rand1i(rng, 40))
                               : value;
    }
  }
  return samples;
}

// 1000 samples summed in order, reversed, shuffled, and as sums of uneven
// groups added in a shuffled order: every bit the same.
TEST(merge, fixed_sums_do_not_depend_on_order_or_grouping) {
  for (auto seed : {1, 2, 3}) {
    auto samples  = make_samples(1000, seed);
    auto in_order = fixed_sum3{};
    for (auto& sample : samples) add_fixed(in_order, sample);
    auto reversed = fixed_sum3{};
    for (auto i = (int)samples.size() - 1; i >= 0; i--) add_fixed(reversed, samples[i]);
    EXPECT_EQ(in_order, reversed);
    auto rng      = make_rng(seed + 100);
    auto shuffled = samples;
    for (auto i = (int)shuffled.size() - 1; i > 0; i--)
      std::swap(shuffled[i], shuffled[rand1i(rng, i + 1)]);
    auto sum_shuffled = fixed_sum3{};
    for (auto& sample : shuffled) add_fixed(sum_shuffled, sample);
    EXPECT_EQ(in_order, sum_shuffled);
    auto groups = std::vector<fixed_sum3>{};
    for (auto i = 0; i < (int)samples.size();) {
      auto size  = 1 + rand1i(rng, 50);
      auto group = fixed_sum3{};
      for (auto k = i; k < std::min(i + size, (int)samples.size()); k++)
        add_fixed(group, samples[k]);
      groups.push_back(group);
      i += size;
    }
    auto grouped = fixed_sum3{};
    for (auto i = (int)groups.size() - 1; i >= 0; i--) add_fixed(grouped, groups[i]);
    EXPECT_EQ(in_order, grouped);
  }
}

// The sum is exact for samples of 2^-41 or more: against a long double sum
// of values that all fit its 64-bit mantissa (moderate values, a few
// powers of two apart), and in the extremes the format promises.
TEST(merge, fixed_sums_are_exact) {
  auto rng      = make_rng(7);
  auto sum      = fixed_sum3{};
  auto expected = (long double)0;
  for (auto i = 0; i < 10000; i++) {
    auto value = std::ldexp(rand1f(rng), rand1i(rng, 20) - 10);
    if (rand1i(rng, 4) == 0) value = -value;
    add_fixed(sum, vec3f{value, value, value});
    expected += value;
  }
  EXPECT_EQ(fixed_to_double(sum).x, (double)expected);
  // The smallest exact value, a value below it (rounded toward zero), the
  // largest accepted one, and back to zero.
  auto extremes = fixed_sum3{};
  add_fixed(extremes, vec3f{0x1p-41f, 0x1.8p-64f, std::nextafter(fixed_sum_max_sample, 0.0f)});
  EXPECT_EQ(fixed_to_double(extremes).x, 0x1p-41);
  EXPECT_EQ(fixed_to_double(extremes).y, 0x1p-64);
  EXPECT_EQ(fixed_to_double(extremes).z, (double)std::nextafter(fixed_sum_max_sample, 0.0f));
  add_fixed(extremes, vec3f{-0x1p-41f, -0x1.8p-64f, -std::nextafter(fixed_sum_max_sample, 0.0f)});
  EXPECT_EQ(extremes, fixed_sum3{});
  // 2^31 - 1 samples of the largest accepted value stay positive.
  auto big = fixed_sum3{};
  add_fixed(big, vec3f{std::nextafter(fixed_sum_max_sample, 0.0f), 0, 0});
  auto doubled = big;
  for (auto i = 0; i < 30; i++) add_fixed(doubled, doubled);  // 2^30 samples
  add_fixed(doubled, doubled);                                // 2^31
  EXPECT_GT(fixed_to_double(doubled).x, 0x1p126);
}

// The fast path of add_fixed (128-bit, below 2^63) adds what the general
// one does, for every exponent and sign, from accumulators near every carry.
TEST(merge, fixed_sum_fast_path_matches_the_general_one) {
  auto rng = make_rng(5);
  for (auto i = 0; i < 200000; i++) {
    auto bits = (uint32_t)advance_rng(rng);
    auto x    = 0.0f;
    std::memcpy(&x, &bits, sizeof(x));
    if (!std::isfinite(x) || std::abs(x) >= fixed_sum_max_sample) continue;
    uint64_t fast[3], general[3], value[3];
    for (auto k = 0; k < 3; k++) {
      // Words near 0 or all ones, so that carries and borrows run through.
      auto kind = rand1i(rng, 3);
      fast[k]   = kind == 0 ? advance_rng(rng) : kind == 1 ? ~(uint64_t)rand1i(rng, 4)
                                                           : (uint64_t)rand1i(rng, 4);
      general[k] = fast[k];
    }
    add_fixed_float(fast, x);
    float_to_fixed_words(x, value);
    add_fixed_words(general, value);
    ASSERT_TRUE(fast[0] == general[0] && fast[1] == general[1] && fast[2] == general[2])
        << "x = " << x;
  }
}

// The tracer accumulates exactly: 5 samples rendered at once equal 2 then
// 3 rendered as separate states and added up.
TEST(merge, trace_states_of_ranges_add_up_to_one_render) {
  auto scene  = make_small_scene();
  auto bvh    = scene_bvh{};
  auto error  = std::string{};
  ASSERT_TRUE(make_scene_bvh(bvh, scene, {}, error)) << error;
  auto params       = trace_params{};
  params.resolution = 24;
  params.samples    = 5;
  auto context      = make_trace_context(scene, params);
  auto whole = trace_state{}, first = trace_state{}, second = trace_state{};
  init_trace_state(whole, scene, params);
  trace_samples(whole, scene, bvh, context, params, 5);
  init_trace_state(first, scene, params, 0);
  trace_samples(first, scene, bvh, context, params, 2);
  init_trace_state(second, scene, params, 2);
  params.threads = 1;
  trace_samples(second, scene, bvh, context, params, 1);
  trace_samples(second, scene, bvh, context, params, 2);
  for (size_t i = 0; i < whole.sums.size(); i++) add_fixed(first.sums[i], second.sums[i]);
  EXPECT_TRUE(first.sums == whole.sums);
  auto image = get_image(whole);
  auto added = get_image(first.width, first.height, first.sums, 5);
  EXPECT_TRUE(image.pixels == added.pixels);
}

// make_small_scene with 40 hair strands (curves, a hair material) in front
// of the sphere: the paths scatter in fibres, and the roulette threshold's
// pilot and first-hit splitting have hair to work on.
static scene_data make_small_hair_scene() {
  auto scene   = make_small_scene();
  auto strands = shape_data{};
  for (auto s = 0; s < 40; s++) {
    auto base = (int)strands.positions.size();
    for (auto k = 0; k < 4; k++) {
      strands.positions.push_back({-1.2f + 0.06f * s + 0.1f * std::sin(k + s), 1.5f - k, 1.1f});
      strands.radius.push_back(0.02f);
    }
    strands.curves.push_back({base, base + 1, base + 2, base + 3});
  }
  scene.shapes.push_back(strands);
  scene.shape_names.push_back("strands");
  auto hair           = material_data{};
  hair.type           = material_type::hair;
  hair.hair.eumelanin = 0.5f;
  scene.materials.push_back(hair);
  scene.material_names.push_back("hair");
  scene.instances.push_back({identity3x4f, 1, 1});
  scene.instance_names.push_back("strands");
  return scene;
}

// The exact sums of the parts of a render, added: each part is the sample
// numbers at which it starts, calls trace_samples again and ends (threads
// alternating 1 and 2); each part finds the whole render's roulette
// threshold and adaptive rates.
static std::vector<fixed_sum3> add_up_parts(const scene_data& scene, const scene_bvh& bvh,
    const trace_context& context, trace_params params,
    const std::vector<std::vector<int>>& parts, const trace_state& whole) {
  auto added = std::vector<fixed_sum3>(whole.sums.size());
  for (auto& part : parts) {
    auto state = trace_state{};
    init_trace_state(state, scene, params, part.front());
    for (size_t k = 0; k + 1 < part.size(); k++) {
      params.threads = 1 + (part.front() + (int)k) % 2;
      trace_samples(state, scene, bvh, context, params, part[k + 1] - part[k]);
    }
    EXPECT_EQ(state.roulette_threshold, whole.roulette_threshold) << part.front();
    EXPECT_TRUE(state.rates == whole.rates) << part.front();
    EXPECT_TRUE(state.allocation.visibility == whole.allocation.visibility) << part.front();
    EXPECT_EQ(state.allocation.pixel_deviation, whole.allocation.pixel_deviation);
    EXPECT_TRUE(state.roulette_cache.tails == whole.roulette_cache.tails) << part.front();
    EXPECT_EQ(state.roulette_cache.pixel_deviation, whole.roulette_cache.pixel_deviation);
    for (size_t i = 0; i < added.size(); i++) add_fixed(added[i], state.sums[i]);
  }
  return added;
}

// With first-hit splitting (3 paths a camera ray) and the automatic roulette
// threshold, 11 samples rendered at once (2 threads) equal, bit for bit, the
// exact sums of three uneven parts 0:3, 3:7 (in two calls) and 7:11 (1 and 2
// threads): every part's pilot picks the render's threshold and split path k
// of sample s draws the numbers of s * 3 + k whatever the range. The split
// render differs from the unsplit one (the check is not vacuous).
TEST(merge, split_renders_of_ranges_add_up_to_one_render) {
  auto scene = make_small_hair_scene();
  auto bvh   = scene_bvh{};
  auto error = std::string{};
  ASSERT_TRUE(make_scene_bvh(bvh, scene, {}, error)) << error;
  auto params       = trace_params{};
  params.resolution = 24;
  params.samples    = 11;
  params.split      = 3;
  params.threads    = 2;
  ASSERT_TRUE(check_trace_params(scene, params, error)) << error;
  auto context = make_trace_context(scene, params);
  auto whole   = trace_state{};
  init_trace_state(whole, scene, params);
  trace_samples(whole, scene, bvh, context, params, params.samples);
  EXPECT_EQ(whole.nonfinite, 0);
  EXPECT_GT(whole.roulette_threshold, 0.0f);
  auto added = add_up_parts(scene, bvh, context, params, {{0, 3}, {3, 4, 7}, {7, 11}}, whole);
  EXPECT_TRUE(added == whole.sums);
  params.split = 1;
  auto unsplit = trace_state{};
  init_trace_state(unsplit, scene, params);
  trace_samples(unsplit, scene, bvh, context, params, params.samples);
  EXPECT_FALSE(unsplit.sums == whole.sums);
  EXPECT_LT(unsplit.rays, whole.rays);
}

// A sun beside the sky: the shadow rays' allocation (learned by the pilot)
// is the same in every part, so that 12 samples at once (2 threads) equal,
// bit for bit, the sums of the parts 0:5, 5:12 and of 0:3, 3:4:8, 8:12 (1
// and 2 threads). The allocation skips shadow rays (fewer than the light
// samples) and renders other bits than the roulette of shadow_threshold.
TEST(merge, renders_with_shadow_allocation_of_ranges_add_up_to_one_render) {
  auto scene = make_small_hair_scene();
  scene.distant_lights.push_back({normalize(vec3f{1, 2, 1}), {3, 3, 3}});
  auto bvh   = scene_bvh{};
  auto error = std::string{};
  ASSERT_TRUE(make_scene_bvh(bvh, scene, {}, error)) << error;
  auto params       = trace_params{};
  params.resolution = 24;
  params.samples    = 12;
  params.threads    = 2;
  ASSERT_TRUE(check_trace_params(scene, params, error)) << error;
  auto context = make_trace_context(scene, params);
  auto whole   = trace_state{};
  init_trace_state(whole, scene, params);
  trace_samples(whole, scene, bvh, context, params, params.samples);
  EXPECT_EQ(whole.nonfinite, 0);
  ASSERT_GT(whole.allocation.cells.x, 0);
  EXPECT_GT(whole.light_samples, 0);
  EXPECT_LT(whole.shadow_rays, whole.light_samples);
  EXPECT_TRUE(add_up_parts(scene, bvh, context, params, {{0, 5}, {5, 12}}, whole) == whole.sums);
  EXPECT_TRUE(
      add_up_parts(scene, bvh, context, params, {{0, 3}, {3, 4, 8}, {8, 12}}, whole) ==
      whole.sums);
  params.allocation = false;
  auto off          = trace_state{};
  init_trace_state(off, scene, params);
  trace_samples(off, scene, bvh, context, params, params.samples);
  EXPECT_FALSE(off.sums == whole.sums);
  EXPECT_EQ(off.allocation.cells.x, 0);
}

// The default plan (adaptive rates, each pixel's split and the roulette
// cache): 16 samples at once equal, bit for bit, the exact sums of the parts
// 0:3, 3:5:9 (two calls) and 9:16 on 1 or 2 threads: every part's pilots
// find the render's rates, splits and roulette cache, and a pixel's paths
// are numbered by sample whatever the range; the merged sums over 16 give
// the image.
TEST(merge, adaptive_renders_of_ranges_add_up_to_one_render) {
  auto scene = make_small_hair_scene();
  auto bvh   = scene_bvh{};
  auto error = std::string{};
  ASSERT_TRUE(make_scene_bvh(bvh, scene, {}, error)) << error;
  auto params       = trace_params{};
  params.resolution = 48;
  params.samples    = 16;
  params.threads    = 2;
  ASSERT_TRUE(check_trace_params(scene, params, error)) << error;
  auto context = make_trace_context(scene, params);
  auto whole   = trace_state{};
  init_trace_state(whole, scene, params);
  trace_samples(whole, scene, bvh, context, params, params.samples);
  ASSERT_FALSE(whole.rates.empty());
  ASSERT_EQ(whole.splits.size(), whole.sums.size());
  EXPECT_GT(*std::max_element(whole.splits.begin(), whole.splits.end()), 1);
  EXPECT_GT(whole.roulette_cache.cells.x, 0);
  EXPECT_GT(whole.roulette_plays, 0);
  auto added = add_up_parts(scene, bvh, context, params, {{0, 3}, {3, 5, 9}, {9, 16}}, whole);
  EXPECT_TRUE(added == whole.sums);
  EXPECT_TRUE(get_image(whole).pixels ==
              get_image(whole.width, whole.height, added, params.samples).pixels);
}

// -----------------------------------------------------------------------------
// FINGERPRINTS AND PART FILES
// -----------------------------------------------------------------------------

TEST(merge, fingerprint_follows_values_not_names) {
  auto scene       = make_small_scene(2);
  auto fingerprint = fingerprint_scene(scene);
  EXPECT_EQ(fingerprint_scene(make_small_scene(2)), fingerprint);
  auto renamed           = scene;
  renamed.shape_names[0] = "elsewhere";
  renamed.cameras[0].lens *= 2;  // the camera is in the part's settings instead
  EXPECT_EQ(fingerprint_scene(renamed), fingerprint);
  auto changed = scene;
  changed.shapes[1].positions[7].x = std::nextafter(changed.shapes[1].positions[7].x, 10.0f);
  EXPECT_NE(fingerprint_scene(changed), fingerprint);
  changed = scene;
  changed.materials[0].hair.beta_m = 0.31f;
  EXPECT_NE(fingerprint_scene(changed), fingerprint);
  changed = scene;
  changed.instances[1].material = -1;
  EXPECT_NE(fingerprint_scene(changed), fingerprint);
  EXPECT_NE(fingerprint_scene(make_small_scene(1)), fingerprint);
}

static fs::path make_merge_dir(const std::string& name) {
  auto dir = fs::temp_directory_path() / ("yocto-merge-" + name + "-" + std::to_string(getpid()));
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir;
}

static std::string read_bytes(const fs::path& path) {
  auto stream = std::ifstream(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(stream), std::istreambuf_iterator<char>()};
}
static void write_bytes(const fs::path& path, const std::string& bytes) {
  auto stream = std::ofstream(path, std::ios::binary);
  stream << bytes;
}

TEST(merge, a_part_saves_and_loads_exactly_and_reads_as_an_image) {
  auto dir  = make_merge_dir("io");
  auto part = render_part{};
  part.settings  = "scene=0123\nseed=7\n";
  part.samples   = 16;
  part.first     = 3;
  part.count     = 5;
  part.width     = 7;
  part.height    = 3;
  part.rays      = 123456789012345;
  part.nonfinite = 2;
  part.sums.resize(21);
  auto samples = make_samples(21 * 5, 11);
  for (auto i = 0; i < (int)samples.size(); i++) add_fixed(part.sums[i / 5], samples[i]);
  auto filename = (dir / "part.exr").string();
  auto error    = std::string{};
  ASSERT_TRUE(save_render_part(filename, part, error)) << error;
  auto loaded = render_part{};
  ASSERT_TRUE(load_render_part(filename, loaded, error)) << error;
  EXPECT_EQ(loaded.settings, part.settings);
  EXPECT_EQ(loaded.samples, 16);
  EXPECT_EQ(loaded.first, 3);
  EXPECT_EQ(loaded.count, 5);
  EXPECT_EQ(loaded.width, 7);
  EXPECT_EQ(loaded.height, 3);
  EXPECT_EQ(loaded.rays, part.rays);
  EXPECT_EQ(loaded.nonfinite, 2);
  EXPECT_TRUE(loaded.sums == part.sums);
  // Any image viewer sees the mean of the part's samples.
  auto image = texture_data{};
  ASSERT_TRUE(load_image(filename, image, error)) << error;
  ASSERT_EQ(image.pixels.size(), 21u);
  for (auto i = 0; i < 21; i++)
    EXPECT_EQ(image.pixels[i], vec3f(fixed_to_double(part.sums[i]) / 5.0));
  // A name that is not .exr, and a plain image, are not parts.
  EXPECT_FALSE(save_render_part((dir / "part.png").string(), part, error));
  EXPECT_NE(error.find("part.png"), std::string::npos) << error;
  ASSERT_TRUE(save_image((dir / "plain.exr").string(), image, error)) << error;
  EXPECT_FALSE(load_render_part((dir / "plain.exr").string(), loaded, error));
  EXPECT_NE(error.find("plain.exr: not a render part"), std::string::npos) << error;
  fs::remove_all(dir);
}

// -----------------------------------------------------------------------------
// YSCENE MERGE
// -----------------------------------------------------------------------------

// A small curly hair scene under a sky, rendered small with few samples.
struct merge_fixture {
  fs::path    dir      = {};
  std::string scene    = "";
  std::string settings = " --resolution 40 --bounces 8 --quiet";
  int         samples  = 14;
};

static merge_fixture make_merge_fixture(const std::string& name) {
  auto fixture  = merge_fixture{};
  fixture.dir   = make_merge_dir(name);
  fixture.scene = (fixture.dir / "scene" / "scene.json").string();
  auto result   = run_yscene("hair --style curly -n 150 -o " + fixture.scene);
  EXPECT_EQ(result.status, 0) << result.output;
  return fixture;
}

// Renders samples first ... end - 1 of the fixture's render as a part.
static std::string render_part_file(const merge_fixture& fixture, int first, int end,
    int threads, const std::string& extra = "") {
  auto suffix = extra;  // " --seed 5" names part-A-B--seed-5.exr
  for (auto& character : suffix)
    if (!std::isalnum((unsigned char)character)) character = '-';
  auto name = (fixture.dir / ("part-" + std::to_string(first) + "-" + std::to_string(end) +
                              suffix + ".exr"))
                  .string();
  // An option in `extra` replaces the fixture's.
  auto settings = fixture.settings;
  for (auto option : {" --resolution ", " --bounces "}) {
    auto found = settings.find(option);
    if (extra.find(option) == std::string::npos || found == std::string::npos) continue;
    auto value_end = settings.find(' ', found + std::strlen(option));
    settings.erase(found, value_end - found);
  }
  auto result = run_yscene("render " + fixture.scene + " -o " + name + " --samples " +
                           std::to_string(fixture.samples) + " --sample-range " +
                           std::to_string(first) + ":" + std::to_string(end) + " --threads " +
                           std::to_string(threads) + settings + extra);
  EXPECT_EQ(result.status, 0) << result.output;
  return name;
}

static std::string render_whole(const merge_fixture& fixture, const std::string& output) {
  auto filename = (fixture.dir / output).string();
  auto result   = run_yscene("render " + fixture.scene + " -o " + filename + " --samples " +
                           std::to_string(fixture.samples) + fixture.settings);
  EXPECT_EQ(result.status, 0) << result.output;
  return read_bytes(filename);
}

static command_result merge_files(const std::vector<std::string>& parts,
    const std::string& output, const std::string& flags = "") {
  auto arguments = std::string("merge");
  for (auto& part : parts) arguments += " " + part;
  return run_yscene(arguments + " -o " + output + flags);
}

// 2, 3 and 7 parts of uneven sizes, made with 1 and 2 threads and given out
// of order, merge into the single render's pixels (PFM: raw floats), and so
// do tree merges through intermediate parts. 14 spp of a 40-pixel image.
TEST(merge, parts_merge_into_the_single_render_bit_for_bit) {
  auto fixture = make_merge_fixture("exact");
  auto whole   = render_whole(fixture, "whole.pfm");
  ASSERT_FALSE(whole.empty());
  auto splits = std::vector<std::vector<int>>{
      {0, 9, 14}, {0, 5, 6, 14}, {0, 1, 4, 6, 7, 11, 12, 14}};
  auto thread = 0;
  for (auto& split : splits) {
    auto parts = std::vector<std::string>{};
    for (size_t k = 0; k + 1 < split.size(); k++)
      parts.push_back(render_part_file(fixture, split[k], split[k + 1], 1 + thread++ % 2));
    std::reverse(parts.begin(), parts.end());
    if (parts.size() > 2) std::swap(parts[0], parts[1]);
    auto output = (fixture.dir / ("merged-" + std::to_string(parts.size()) + ".pfm")).string();
    auto result = merge_files(parts, output);
    ASSERT_EQ(result.status, 0) << result.output;
    EXPECT_TRUE(read_bytes(output) == whole) << parts.size() << " parts differ from one render";
    for (auto& part : parts) fs::remove(part);
  }
  // A tree: (0:1 + 1:6) and (6:14) into parts, then those into the image;
  // a single part of all samples as well.
  auto low  = (fixture.dir / "low.exr").string();
  auto high = (fixture.dir / "high.exr").string();
  auto result = merge_files({render_part_file(fixture, 1, 6, 2),
                                render_part_file(fixture, 0, 1, 1)},
      low, " --part");
  ASSERT_EQ(result.status, 0) << result.output;
  result = merge_files({render_part_file(fixture, 6, 14, 2)}, high, " --part");
  ASSERT_EQ(result.status, 0) << result.output;
  auto tree = (fixture.dir / "tree.pfm").string();
  result    = merge_files({high, low}, tree);
  ASSERT_EQ(result.status, 0) << result.output;
  EXPECT_TRUE(read_bytes(tree) == whole);
  auto all    = render_part_file(fixture, 0, 14, 2);
  auto single = (fixture.dir / "single.pfm").string();
  result      = merge_files({all}, single);
  ASSERT_EQ(result.status, 0) << result.output;
  EXPECT_TRUE(read_bytes(single) == whole);
  // Other formats go through the same image: an EXR merge equals an EXR render.
  auto exr = (fixture.dir / "merged.exr").string();
  result   = merge_files({all}, exr);
  ASSERT_EQ(result.status, 0) << result.output;
  auto merged_image = texture_data{}, whole_image = texture_data{};
  auto error        = std::string{};
  render_whole(fixture, "whole.exr");
  ASSERT_TRUE(load_image(exr, merged_image, error)) << error;
  ASSERT_TRUE(load_image((fixture.dir / "whole.exr").string(), whole_image, error)) << error;
  EXPECT_TRUE(merged_image.pixels == whole_image.pixels);
  fs::remove_all(fixture.dir);
}

// Parts that are not of one render, that overlap or leave a gap, and part
// files that are cut short or damaged: one error line naming the part, exit
// 1, no output.
TEST(merge, parts_that_do_not_make_one_render_are_refused) {
  auto fixture = make_merge_fixture("refused");
  auto low     = render_part_file(fixture, 0, 5, 2);
  auto high    = render_part_file(fixture, 5, 14, 2);
  auto output  = (fixture.dir / "out.png").string();
  auto expect_refused = [&](const std::vector<std::string>& parts, const std::string& names) {
    expect_failure(merge_files(parts, output), names);
    EXPECT_FALSE(fs::exists(output)) << names;
  };
  // Another seed, resolution, bounces, clamp or sampler.
  for (auto extra : {" --seed 5", " --resolution 41", " --bounces 7", " --clamp 10",
           " --sampler naive"}) {
    auto other = render_part_file(fixture, 5, 14, 2, extra);
    expect_refused({low, other}, fs::path(other).filename().string() + ": not a part of the render of");
    fs::remove(other);
  }
  // Another instruction set for Embree's kernels (as on another CPU): the
  // bits differ, so the merge refuses and says how to make them agree.
  if (embree_isa("") != "sse2") {
    auto other = render_part_file(fixture, 5, 14, 2, " --embree-config max_isa=sse2");
    expect_refused({low, other}, "isa=sse2 here");
    expect_refused({low, other}, "--embree-config max_isa=NAME");
    fs::remove(other);
  }
  // A part of another build of yscene (other sources, compiler or Embree):
  // its renderer line differs, and the merge says to use one build.
  {
    auto part  = render_part{};
    auto error = std::string{};
    ASSERT_TRUE(load_render_part(high, part, error)) << error;
    auto line = part.settings.find("renderer=");
    ASSERT_EQ(line, 0u) << part.settings;
    EXPECT_NE(part.settings.find(" embree "), std::string::npos) << part.settings;
    part.settings.insert(line + 9, "0ther");
    auto other = (fixture.dir / "otherbuild.exr").string();
    ASSERT_TRUE(save_render_part(other, part, error)) << error;
    expect_refused({low, other}, "otherbuild.exr: not a part of the render of");
    expect_refused({low, other}, "renderer=0ther");
    expect_refused({low, other}, "one build of yscene");
    fs::remove(other);
  }
  // Another N, and another scene (more strands) under the same settings.
  auto result = run_yscene("render " + fixture.scene + " -o " +
                           (fixture.dir / "n15.exr").string() +
                           " --samples 15 --sample-range 5:15" + fixture.settings);
  ASSERT_EQ(result.status, 0) << result.output;
  expect_refused({low, (fixture.dir / "n15.exr").string()}, "n15.exr: a part of a 15-sample render");
  auto other_scene = (fixture.dir / "other" / "scene.json").string();
  ASSERT_EQ(run_yscene("hair --style curly -n 151 -o " + other_scene).status, 0);
  result = run_yscene("render " + other_scene + " -o " + (fixture.dir / "other.exr").string() +
                      " --samples 14 --sample-range 5:14" + fixture.settings);
  ASSERT_EQ(result.status, 0) << result.output;
  expect_refused({low, (fixture.dir / "other.exr").string()}, "other.exr: not a part of the render of");
  // Overlap, a part given twice, a gap, missing ends.
  auto middle = render_part_file(fixture, 4, 8, 1);
  expect_refused({low, middle, high}, "overlap");
  expect_refused({low, middle, high}, fs::path(middle).filename().string());
  expect_refused({low, low, high}, "overlap");
  auto late = render_part_file(fixture, 6, 14, 1);
  expect_refused({late, low}, "samples 5:6 are in no part");
  auto tree = (fixture.dir / "tree.exr").string();
  expect_failure(merge_files({low, late}, tree, " --part"), "samples 5:6 are in no part");
  EXPECT_FALSE(fs::exists(tree));
  expect_refused({high}, "samples 0:5 of 14 are in no part");
  expect_refused({low}, "samples 5:14 of 14 are in no part");
  // A part cut short, one with a damaged byte in its pixels, one with a
  // damaged header value, and something that is not an image at all.
  auto bytes = read_bytes(high);
  auto cut   = (fixture.dir / "cut.exr").string();
  write_bytes(cut, bytes.substr(0, bytes.size() * 2 / 3));
  expect_refused({low, cut}, "cut.exr");
  auto damaged = (fixture.dir / "damaged.exr").string();
  auto flipped = bytes;
  flipped[flipped.size() - 100] ^= 0x10;
  write_bytes(damaged, flipped);
  expect_refused({low, damaged}, "damaged.exr");
  auto header = bytes;
  auto range  = header.find("5:14");
  ASSERT_NE(range, std::string::npos);
  header[range] = '4';  // the range 4:14 overlaps low, but the checksum tells first
  write_bytes(damaged, header);
  expect_refused({low, damaged}, "damaged.exr: render part is damaged");
  write_bytes(damaged, "not an image");
  expect_refused({low, damaged}, "damaged.exr");
  expect_refused({low, (fixture.dir / "missing.exr").string()}, "missing.exr");
  // With all of that, the good parts still merge.
  result = merge_files({high, low}, output);
  EXPECT_EQ(result.status, 0) << result.output;
  EXPECT_TRUE(fs::exists(output));
  fs::remove_all(fixture.dir);
}

// --sample-range itself: A:B within [0, N) and a part named .exr.
TEST(merge, bad_sample_ranges_are_refused) {
  auto fixture = make_merge_fixture("ranges");
  auto output  = (fixture.dir / "part.exr").string();
  for (auto range : {"3", "3:", ":3", "a:b", "3:3", "5:2", "0:15", "3:4x"}) {
    expect_failure(run_yscene("render " + fixture.scene + " -o " + output +
                              " --samples 14 --sample-range " + range + fixture.settings),
        std::string("--sample-range ") + range);
    EXPECT_FALSE(fs::exists(output)) << range;
  }
  expect_failure(run_yscene("render " + fixture.scene + " -o " +
                            (fixture.dir / "part.png").string() +
                            " --samples 14 --sample-range 0:3" + fixture.settings),
      "part.png: a render part");
  expect_failure(run_yscene("render " + fixture.scene + " -o " + output +
                            " --samples 14 --sample-range 0:3 --checkpoints" + fixture.settings),
      "--sample-range");
  fs::remove_all(fixture.dir);
}

// -----------------------------------------------------------------------------
// AOVS IN PARTS
// -----------------------------------------------------------------------------

// An EXR's channels as written: names, formats and the pixels in their
// native layout (what a part needs to be written back unchanged).
struct exr_channels {
  OIIO::ImageSpec            spec   = {};
  std::vector<unsigned char> pixels = {};
};
static bool read_exr(const std::string& filename, exr_channels& exr) {
  auto input = OIIO::ImageInput::open(filename);
  if (!input) return false;
  exr.spec = input->spec();
  exr.pixels.resize(exr.spec.image_bytes(true));
  auto ok = input->read_image(0, 0, 0, exr.spec.nchannels, OIIO::TypeDesc::UNKNOWN,
      exr.pixels.data());
  input->close();
  return ok;
}
static bool write_exr(const std::string& filename, const exr_channels& exr) {
  auto output = OIIO::ImageOutput::create(filename);
  if (!output || !output->open(filename, exr.spec)) return false;
  auto ok = output->write_image(OIIO::TypeDesc::UNKNOWN, exr.pixels.data());
  return output->close() && ok;
}

// An image's channels by name, each a float per pixel (an EXR of yscene
// render --aovs, or of yscene merge).
static std::map<std::string, std::vector<float>> read_float_channels(const std::string& filename) {
  auto channels = std::map<std::string, std::vector<float>>{};
  auto input    = OIIO::ImageInput::open(filename);
  EXPECT_TRUE(input) << filename << ": " << OIIO::geterror();
  if (!input) return channels;
  auto& spec   = input->spec();
  auto  pixels = (size_t)spec.width * spec.height;
  auto  values = std::vector<float>(pixels * spec.nchannels);
  EXPECT_TRUE(input->read_image(0, 0, 0, spec.nchannels, OIIO::TypeDesc::FLOAT, values.data()))
      << filename;
  for (auto c = 0; c < spec.nchannels; c++) {
    auto& channel = channels[spec.channelnames[c]];
    for (size_t i = 0; i < pixels; i++) channel.push_back(values[i * spec.nchannels + c]);
  }
  input->close();
  return channels;
}

// Every channel of two images has the same name and bits, pixel by pixel.
static void expect_same_channels(const std::string& merged, const std::string& whole) {
  auto a = read_float_channels(merged), b = read_float_channels(whole);
  ASSERT_EQ(a.size(), b.size()) << merged;
  for (auto& [name, values] : b) {
    ASSERT_TRUE(a.count(name)) << merged << " has no channel " << name;
    auto& other = a.at(name);
    ASSERT_EQ(other.size(), values.size()) << name;
    EXPECT_EQ(std::memcmp(other.data(), values.data(), values.size() * sizeof(float)), 0)
        << merged << ": channel " << name << " differs from " << whole;
  }
}

// Three uneven parts 0:2, 2:9 and 9:14 of the fixture's render with --aovs
// (1, 2 and 1 threads), merged in another order, give an EXR with the 26
// channels of one render's --aovs output (R, G, B and the nine layers),
// each bit for bit; so does a tree merge through an intermediate part
// (which keeps the AOV sums). The lobe, depth and coverage layers are not
// all zero (the comparison is not vacuous).
TEST(merge, aov_parts_merge_into_the_single_render_layer_for_layer) {
  auto fixture = make_merge_fixture("aovs");
  fixture.settings += " --aovs";
  render_whole(fixture, "whole.exr");
  auto whole = (fixture.dir / "whole.exr").string();
  auto parts = std::vector<std::string>{render_part_file(fixture, 2, 9, 2),
      render_part_file(fixture, 9, 14, 1), render_part_file(fixture, 0, 2, 1)};
  auto part  = render_part{};
  auto error = std::string{};
  ASSERT_TRUE(load_render_part(parts[0], part, error)) << error;
  EXPECT_EQ(part.extra, trace_aov_sums);
  EXPECT_EQ(part.extra_sums.size(), part.sums.size() * trace_aov_sums);
  auto merged = (fixture.dir / "merged.exr").string();
  auto result = merge_files(parts, merged);
  ASSERT_EQ(result.status, 0) << result.output;
  auto channels = read_float_channels(whole);
  EXPECT_EQ(channels.size(), 26u);
  for (auto name : {"albedo.G", "normal.Z", "tangent.X", "hair_R.R", "hair_TT.G", "hair_TRT.B",
           "hair_TRRT.R", "depth.Z", "coverage.Y"}) {
    ASSERT_TRUE(channels.count(name)) << name;
    auto& values = channels.at(name);
    EXPECT_TRUE(std::any_of(values.begin(), values.end(), [](float v) { return v != 0; }))
        << name << " is all zero";
  }
  expect_same_channels(merged, whole);
  auto low = (fixture.dir / "low.exr").string();
  result   = merge_files({parts[2], parts[0]}, low, " --part");
  ASSERT_EQ(result.status, 0) << result.output;
  auto tree = (fixture.dir / "tree.exr").string();
  result    = merge_files({parts[1], low}, tree);
  ASSERT_EQ(result.status, 0) << result.output;
  expect_same_channels(tree, whole);
  fs::remove_all(fixture.dir);
}

// A part with AOVs and one without are not parts of one render: the merge
// fails with one error line naming the setting (aovs), in either order, as
// a part or an image, and writes nothing.
TEST(merge, aov_and_plain_parts_do_not_mix) {
  auto fixture = make_merge_fixture("aovmix");
  auto plain   = render_part_file(fixture, 0, 5, 2);
  auto aovs    = render_part_file(fixture, 5, 14, 2, " --aovs");
  for (auto output : {"out.exr", "part.exr"}) {
    auto filename = (fixture.dir / output).string();
    auto flags    = std::string(output) == "part.exr" ? " --part" : "";
    for (auto& parts : {std::vector{plain, aovs}, std::vector{aovs, plain}}) {
      auto result = merge_files(parts, filename, flags);
      expect_failure(result, "aovs");
      expect_failure(result, "not a part of the render of");
      EXPECT_FALSE(fs::exists(filename)) << output;
    }
  }
  fs::remove_all(fixture.dir);
}

// A part with AOVs whose extra sums were changed after it was written (one
// bit of one word of one pixel's hair_TRT sum), or whose yocto:extra
// attribute was dropped (its extra channels then look like someone else's),
// fails its checksum: load_render_part says the part is damaged, and the
// merge fails naming it. A part that lost an extra channel is refused as not
// a part, naming the channel. The part rewritten unchanged still merges
// (the rewriting itself damages nothing).
TEST(merge, aov_parts_with_damaged_extra_sums_fail_their_checksum) {
  auto fixture = make_merge_fixture("aovdamaged");
  fixture.settings += " --aovs";
  auto low   = render_part_file(fixture, 0, 5, 2);
  auto high  = render_part_file(fixture, 5, 14, 2);
  auto exr   = exr_channels{};
  ASSERT_TRUE(read_exr(high, exr));
  auto& spec  = exr.spec;
  auto  words = std::vector<size_t>{};  // byte offset of each channel in a pixel
  for (auto c = 0, offset = 0; c < spec.nchannels; c++) {
    words.push_back(offset);
    offset += (int)spec.channelformat(c).size();
  }
  auto channel = [&](const std::string& name) {
    auto found = std::find(spec.channelnames.begin(), spec.channelnames.end(), name);
    EXPECT_NE(found, spec.channelnames.end()) << name;
    return (int)(found - spec.channelnames.begin());
  };
  auto rewrite = [&](const std::string& name, const exr_channels& changed) {
    auto filename = (fixture.dir / name).string();
    EXPECT_TRUE(write_exr(filename, changed)) << name << ": " << OIIO::geterror();
    return filename;
  };
  auto output = (fixture.dir / "out.exr").string();
  // Unchanged: still a good part.
  auto same   = rewrite("same.exr", exr);
  auto result = merge_files({low, same}, output);
  EXPECT_EQ(result.status, 0) << result.output;
  fs::remove(output);
  // One bit of the low word of extra sum 5 (hair_TRT), green, at pixel 777.
  auto flipped = exr;
  auto index   = channel("extra.5.G.0");
  ASSERT_EQ(spec.channelformat(index), OIIO::TypeDesc::UINT32);
  flipped.pixels[777 * spec.pixel_bytes(true) + words[index]] ^= 0x04;
  auto damaged = rewrite("damaged.exr", flipped);
  auto part    = render_part{};
  auto error   = std::string{};
  EXPECT_FALSE(load_render_part(damaged, part, error));
  EXPECT_NE(error.find("damaged.exr: render part is damaged"), std::string::npos) << error;
  expect_failure(merge_files({low, damaged}, output), "damaged.exr: render part is damaged");
  EXPECT_FALSE(fs::exists(output));
  // The attribute that says how many extra sums a pixel has, dropped.
  auto unmarked = exr;
  unmarked.spec.erase_attribute("yocto:extra");
  auto lost = rewrite("unmarked.exr", unmarked);
  EXPECT_FALSE(load_render_part(lost, part, error));
  EXPECT_NE(error.find("unmarked.exr: render part is damaged"), std::string::npos) << error;
  // An extra channel dropped (the last one, extra.7.B.5).
  auto cut      = exr_channels{};
  auto last     = channel("extra.7.B.5");
  cut.spec      = spec;
  cut.spec.nchannels--;
  cut.spec.channelnames.erase(cut.spec.channelnames.begin() + last);
  cut.spec.channelformats.erase(cut.spec.channelformats.begin() + last);
  auto pixel_bytes = spec.pixel_bytes(true), word = spec.channelformat(last).size();
  for (size_t i = 0; i < (size_t)spec.width * spec.height; i++) {
    auto pixel = exr.pixels.data() + i * pixel_bytes;
    cut.pixels.insert(cut.pixels.end(), pixel, pixel + words[last]);
    cut.pixels.insert(cut.pixels.end(), pixel + words[last] + word, pixel + pixel_bytes);
  }
  auto missing = rewrite("missing.exr", cut);
  EXPECT_FALSE(load_render_part(missing, part, error));
  EXPECT_NE(error.find("extra.7.B.5"), std::string::npos) << error;
  expect_failure(merge_files({low, missing}, output), "missing.exr");
  fs::remove_all(fixture.dir);
}
