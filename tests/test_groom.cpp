//
// Tests of grooms that vary (issue 20): strands from connectivity, the
// per-strand random value (a function of the root alone, uniform), hair
// materials from root to tip and from strand to strand, the tint, per-point
// colours of .hair files, and renders: the white furnace of a varying white
// groom, bit-identical renders of materials that do not vary, and a varying
// groom's render.
//

#include <gtest/gtest.h>
#include <unistd.h>
#include <yocto/yocto_hairio.h>
#include <yocto/yocto_sampling.h>
#include <yocto/yocto_shading.h>
#include <yocto/yocto_trace.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <string>
#include <vector>

using namespace yocto;

// -----------------------------------------------------------------------------
// HELPERS
// -----------------------------------------------------------------------------

// The bits of a position, -0 as 0: a key that tells exactly equal positions.
static std::array<uint32_t, 3> position_key(const vec3f& p) {
  auto key = std::array<uint32_t, 3>{};
  for (auto c = 0; c < 3; c++) {
    auto value = p[c] == 0 ? 0.0f : p[c];
    std::memcpy(&key[c], &value, 4);
  }
  return key;
}

// The number of segments (lines or curves) of a fibre shape and their ends.
static int count_segments(const shape_data& shape) {
  return (int)(shape.curves.empty() ? shape.lines.size() : shape.curves.size());
}
static vec3f segment_start(const shape_data& shape, int i) {
  return shape.positions[shape.curves.empty() ? shape.lines[i].x : shape.curves[i].x];
}
static vec3f segment_end(const shape_data& shape, int i) {
  return shape.positions[shape.curves.empty() ? shape.lines[i].y : shape.curves[i].w];
}

// A groom of `count` strands of 1 to 5 segments (lines or Catmull-Rom
// curves), roots in [-1, 1]^3, each strand its own vertices, shared between
// its segments.
static shape_data make_random_groom(int count, bool curves, uint64_t seed) {
  auto shape = shape_data{};
  auto rng   = make_rng(seed);
  for (auto s = 0; s < count; s++) {
    auto points = std::vector<vec3f>{rand3f(rng) * 2.0f - 1.0f};
    auto length = 2 + rand1i(rng, 5);
    while ((int)points.size() < length)
      points.push_back(points.back() + vec3f{0, -0.1f, 0} + (rand3f(rng) - 0.5f) * 0.05f);
    if (curves) {
      append_catmull_rom_strand(shape, points, std::vector<float>(points.size(), 0.01f));
    } else {
      auto base = (int)shape.positions.size();
      for (auto k = 0; k < (int)points.size(); k++) {
        shape.positions.push_back(points[k]);
        shape.radius.push_back(0.01f);
        if (k > 0) shape.lines.push_back({base + k - 1, base + k});
      }
    }
  }
  return shape;
}

// The same groom written differently: its segments in another order, its
// vertices in another order (indices rebuilt) and, if `split`, each
// segment with vertices of its own (joints by equal positions only).
static shape_data shuffle_groom(const shape_data& shape, bool split, uint64_t seed) {
  auto rng   = make_rng(seed);
  auto count = count_segments(shape);
  auto order = std::vector<int>(count);
  for (auto i = 0; i < count; i++) order[i] = i;
  for (auto i = count - 1; i > 0; i--) std::swap(order[i], order[rand1i(rng, i + 1)]);
  // Segments in the new order, as lists of old vertices (split: copies).
  auto elements = std::vector<std::vector<int>>{};
  auto vertices = std::vector<int>{};  // new vertex -> old vertex
  auto shared   = std::vector<int>(shape.positions.size(), -1);
  for (auto i : order) {
    auto old = shape.curves.empty()
                   ? std::vector<int>{shape.lines[i].x, shape.lines[i].y}
                   : std::vector<int>{shape.curves[i].x, shape.curves[i].y, shape.curves[i].z,
                         shape.curves[i].w};
    auto element = std::vector<int>{};
    for (auto v : old) {
      if (split || shared[v] < 0) {
        shared[v] = (int)vertices.size();
        vertices.push_back(v);
      }
      element.push_back(shared[v]);
    }
    elements.push_back(element);
  }
  // Vertices shuffled too.
  auto places = std::vector<int>(vertices.size());
  for (auto i = 0; i < (int)places.size(); i++) places[i] = i;
  for (auto i = (int)places.size() - 1; i > 0; i--)
    std::swap(places[i], places[rand1i(rng, i + 1)]);
  auto shuffled = shape_data{};
  shuffled.positions.resize(vertices.size());
  shuffled.radius.resize(vertices.size());
  for (auto v = 0; v < (int)vertices.size(); v++) {
    shuffled.positions[places[v]] = shape.positions[vertices[v]];
    shuffled.radius[places[v]]    = shape.radius[vertices[v]];
  }
  for (auto& element : elements) {
    if (shape.curves.empty()) {
      shuffled.lines.push_back({places[element[0]], places[element[1]]});
    } else {
      shuffled.curves.push_back(
          {places[element[0]], places[element[1]], places[element[2]], places[element[3]]});
    }
  }
  return shuffled;
}

// The segments of strands [first, last) of a shape, in file order, each with
// vertices of its own: a part of the groom as another file would hold it.
static shape_data take_strands(
    const shape_data& shape, const fiber_strands& strands, int first, int last) {
  auto part = shape_data{};
  for (auto i = 0; i < count_segments(shape); i++) {
    if (strands.strand[i] < first || strands.strand[i] >= last) continue;
    auto base     = (int)part.positions.size();
    auto vertices = shape.curves.empty()
                        ? std::vector<int>{shape.lines[i].x, shape.lines[i].y}
                        : std::vector<int>{shape.curves[i].x, shape.curves[i].y,
                              shape.curves[i].z, shape.curves[i].w};
    for (auto v : vertices) {
      part.positions.push_back(shape.positions[v]);
      part.radius.push_back(shape.radius[v]);
    }
    if (shape.curves.empty()) part.lines.push_back({base, base + 1});
    else part.curves.push_back({base, base + 1, base + 2, base + 3});
  }
  return part;
}

// What the strands say of one segment, found by its end positions.
struct segment_strand {
  vec2f random = {0, 0};
  vec2f u      = {0, 0};
  vec3f root   = {0, 0, 0};
};
using segment_key = std::pair<std::array<uint32_t, 3>, std::array<uint32_t, 3>>;
static std::map<segment_key, segment_strand> strands_by_segment(
    const shape_data& shape, const fiber_strands& strands) {
  auto table = std::map<segment_key, segment_strand>{};
  for (auto i = 0; i < count_segments(shape); i++) {
    auto strand = strands.strand[i];
    auto root   = segment_start(shape, strands.segments[strands.starts[strand]]);
    table[{position_key(segment_start(shape, i)), position_key(segment_end(shape, i))}] = {
        strands.random[strand], strands.u[i], root};
  }
  return table;
}

// Checks the invariants of a shape's strands: every segment in exactly one
// strand, root first, each continuing the previous one's end; u from 0 at
// the root to 1 at the tip (1e-6), continuous and non-decreasing, each
// segment's share its chord over the strand's (1e-6); the random value the
// root's. Returns the strands as lists of segments.
static std::vector<std::vector<int>> check_strands(
    const shape_data& shape, const fiber_strands& strands, const std::string& what) {
  auto count = count_segments(shape);
  EXPECT_EQ((int)strands.strand.size(), count) << what;
  EXPECT_EQ((int)strands.u.size(), count) << what;
  EXPECT_EQ((int)strands.segments.size(), count) << what;
  EXPECT_EQ(strands.starts.size(), strands.random.size() + 1) << what;
  if (strands.starts.empty() || (int)strands.segments.size() != count) return {};
  EXPECT_EQ(strands.starts.front(), 0) << what;
  EXPECT_EQ(strands.starts.back(), count) << what;
  auto seen   = std::vector<int>(count, 0);
  auto result = std::vector<std::vector<int>>{};
  for (auto k = 0; k + 1 < (int)strands.starts.size(); k++) {
    auto first = strands.starts[k], last = strands.starts[k + 1];
    EXPECT_LT(first, last) << what << " strand " << k << " is empty";
    if (!(first < last)) continue;
    auto total = 0.0;
    for (auto j = first; j < last; j++)
      total += length(segment_end(shape, strands.segments[j]) -
                      segment_start(shape, strands.segments[j]));
    auto list = std::vector<int>{};
    for (auto j = first; j < last; j++) {
      auto i = strands.segments[j];
      list.push_back(i);
      seen[i]++;
      EXPECT_EQ(strands.strand[i], k) << what << " segment " << i;
      auto u = strands.u[i];
      EXPECT_LE(u.x, u.y) << what << " segment " << i;
      if (total > 0) {
        auto chord = length(segment_end(shape, i) - segment_start(shape, i));
        EXPECT_NEAR(u.y - u.x, chord / total, 1e-6) << what << " segment " << i;
      }
      if (j == first) EXPECT_NEAR(u.x, 0, 1e-6) << what << " root of strand " << k;
      if (j == last - 1) EXPECT_NEAR(u.y, 1, 1e-6) << what << " tip of strand " << k;
      if (j + 1 < last) {
        auto next = strands.segments[j + 1];
        EXPECT_TRUE(segment_end(shape, i) == segment_start(shape, next))
            << what << " segment " << next << " does not start where " << i << " ends";
        EXPECT_NEAR(strands.u[next].x, u.y, 1e-6) << what << " segment " << next;
      }
    }
    EXPECT_EQ(strands.random[k], strand_random(segment_start(shape, list.front())))
        << what << " strand " << k;
    result.push_back(list);
  }
  for (auto i = 0; i < count; i++) EXPECT_EQ(seen[i], 1) << what << " segment " << i;
  return result;
}

// A camera at distance looking at the origin.
static camera_data make_groom_camera(float distance) {
  auto camera  = camera_data{};
  camera.frame = lookat_frame({0, 0, distance}, {0, 0, 0}, {0, 1, 0});
  camera.focus = distance;
  return camera;
}

// A lock of 120 Catmull-Rom strands hanging from y = 1 to y = -1 under a
// sky, with a skin sphere behind it if `skin`.
static scene_data make_groom_scene(
    const hair_material& hair, bool skin, const vec3f& sky = {0.8f, 0.9f, 1}) {
  auto scene = scene_data{};
  scene.cameras.push_back(make_groom_camera(4));
  scene.environments.push_back({identity3x4f, sky, -1});
  auto groom = shape_data{};
  auto rng   = make_rng(11);
  for (auto s = 0; s < 120; s++) {
    auto root   = vec3f{rand1f(rng) * 2 - 1, 1, rand1f(rng) * 0.4f - 0.2f};
    auto points = std::vector<vec3f>{};
    auto radii  = std::vector<float>{};
    for (auto k = 0; k < 5; k++) {
      auto t = k / 4.0f;
      points.push_back(root + vec3f{0.15f * std::sin(5 * t + s), -2 * t, 0});
      radii.push_back(0.012f * (1 - 0.6f * t));
    }
    append_catmull_rom_strand(groom, points, radii);
  }
  scene.shapes.push_back(groom);
  auto material = material_data{};
  material.type = material_type::hair;
  material.hair = hair;
  scene.materials.push_back(material);
  scene.instances.push_back({identity3x4f, 0, 0});
  if (skin) {
    scene.shapes.push_back(make_sphere_shape(32, 0.5f));
    auto matte  = material_data{};
    matte.color = {0.6f, 0.5f, 0.4f};
    scene.materials.push_back(matte);
    scene.instances.push_back({translation_frame({0, 0, -0.8f}), 1, 1});
  }
  return scene;
}

struct groom_render {
  texture_data            image     = {};
  int64_t                 nonfinite = 0;
  std::vector<fixed_sum3> sums      = {};
};

static groom_render render_groom(const scene_data& scene, const trace_params& params) {
  auto bvh   = scene_bvh{};
  auto error = std::string{};
  EXPECT_TRUE(validate_scene(scene, error)) << error;
  EXPECT_TRUE(make_scene_bvh(bvh, scene, {}, error)) << error;
  auto context = make_trace_context(scene, params);
  auto state   = trace_state{};
  init_trace_state(state, scene, params);
  trace_samples(state, scene, bvh, context, params, params.samples);
  return {get_image(state), state.nonfinite.load(), state.sums};
}

// Each component of a within a relative tolerance of b's.
static void expect_relative(const vec3f& a, const vec3f& b, float tolerance,
    const std::string& what) {
  for (auto c = 0; c < 3; c++)
    EXPECT_NEAR(a[c], b[c], tolerance * std::max(std::abs(b[c]), 1e-12f))
        << what << " channel " << c << ": " << a[c] << " for " << b[c];
}

// -----------------------------------------------------------------------------
// THE PER-STRAND RANDOM VALUE
// -----------------------------------------------------------------------------

TEST(groom, random_value_is_a_function_of_the_root_alone) {
  // A groom of 60 strands (lines, then curves) and the same groom written
  // in other orders: segments and vertices shuffled, joints shared or by
  // equal positions only; and split in two files. Every segment, found by
  // its end positions, keeps its strand's root, random value and place u
  // exactly (bit for bit), while strand indices change.
  for (auto curves : {false, true}) {
    auto groom     = make_random_groom(60, curves, 7);
    auto reference = make_fiber_strands(groom);
    auto before    = strands_by_segment(groom, reference);
    ASSERT_EQ((int)before.size(), count_segments(groom));
    EXPECT_EQ(reference.random.size(), 60u);
    for (auto split : {false, true}) {
      auto what     = std::string(curves ? "curves" : "lines") + (split ? " split" : " shared");
      auto shuffled = shuffle_groom(groom, split, 13);
      auto strands  = make_fiber_strands(shuffled);
      check_strands(shuffled, strands, what);
      EXPECT_EQ(strands.random.size(), 60u) << what;
      auto after         = strands_by_segment(shuffled, strands);
      auto moved_strands = 0;
      for (auto i = 0; i < count_segments(shuffled); i++) {
        auto key = segment_key{position_key(segment_start(shuffled, i)),
            position_key(segment_end(shuffled, i))};
        ASSERT_TRUE(before.count(key)) << what;
        auto& old = before.at(key);
        auto& now = after.at(key);
        EXPECT_TRUE(now.root == old.root) << what << " segment " << i;
        EXPECT_EQ(now.random, old.random) << what << " segment " << i;
        EXPECT_EQ(now.u, old.u) << what << " segment " << i;
      }
      for (auto k = 0; k < (int)strands.random.size(); k++) {
        auto root = segment_start(shuffled, strands.segments[strands.starts[k]]);
        for (auto l = 0; l < (int)reference.random.size(); l++) {
          auto other = segment_start(groom, reference.segments[reference.starts[l]]);
          if (other == root && l != k) moved_strands++;
        }
      }
      EXPECT_GT(moved_strands, 30) << what << ": the shuffle should renumber the strands";
    }
    // The groom split in two files (strands 0-24 and 25-59): the same too.
    for (auto [first, last] : {std::pair{0, 25}, std::pair{25, 60}}) {
      auto part    = take_strands(groom, reference, first, last);
      auto strands = make_fiber_strands(part);
      EXPECT_EQ((int)strands.random.size(), last - first);
      for (auto& [key, now] : strands_by_segment(part, strands)) {
        EXPECT_EQ(now.random, before.at(key).random) << "part from strand " << first;
        EXPECT_EQ(now.u, before.at(key).u) << "part from strand " << first;
      }
    }
  }

  // Two strands with the same root position (different vertices, different
  // paths, in different shapes and at different indices) get the same value.
  auto root  = vec3f{0.25f, 1.0f, -0.125f};
  auto one   = shape_data{};
  one.positions = {root, root + vec3f{0, -1, 0}};
  one.lines     = {{0, 1}};
  auto many     = make_random_groom(40, false, 21);
  auto base     = (int)many.positions.size();
  many.positions.insert(
      many.positions.end(), {root, root + vec3f{0.1f, -0.5f, 0}, root + vec3f{0.2f, -1, 0}});
  many.lines.push_back({base + 1, base + 2});  // the tip segment first in the file
  many.lines.push_back({base, base + 1});
  auto alone  = make_fiber_strands(one);
  auto within = make_fiber_strands(many);
  ASSERT_EQ(alone.random.size(), 1u);
  auto strand = within.strand[(int)many.lines.size() - 1];
  EXPECT_NE(strand, 0);
  EXPECT_EQ(within.strand[(int)many.lines.size() - 2], strand);
  EXPECT_EQ(within.random[strand], alone.random[0]);
  EXPECT_EQ(alone.random[0], strand_random(root));
  // -0 and 0 agree, coordinate by coordinate and through a shape.
  EXPECT_EQ(strand_random({-0.0f, 0.0f, 0.0f}), strand_random({0.0f, 0.0f, 0.0f}));
  EXPECT_EQ(strand_random({0.5f, -0.0f, 2.0f}), strand_random({0.5f, 0.0f, 2.0f}));
  EXPECT_EQ(strand_random({1.0f, 2.0f, -0.0f}), strand_random({1.0f, 2.0f, 0.0f}));
  auto negative      = shape_data{};
  negative.positions = {{-0.0f, 1, -0.0f}, {0, 0, 0}};
  negative.lines     = {{0, 1}};
  auto positive      = negative;
  positive.positions[0] = {0.0f, 1, 0.0f};
  EXPECT_EQ(make_fiber_strands(negative).random[0], make_fiber_strands(positive).random[0]);
  // Values in [0, 1), and the next float over gives another value.
  auto next = vec3f{std::nextafter(root.x, 1.0f), root.y, root.z};
  EXPECT_NE(strand_random(next), strand_random(root));
  for (auto value : {alone.random[0].x, alone.random[0].y}) {
    EXPECT_GE(value, 0);
    EXPECT_LT(value, 1);
  }
}

TEST(groom, random_value_is_uniform) {
  // 20,000 strands (single segments) with roots uniform in [-1, 1]^3, and
  // 20,000 on a regular 0.01 grid of a plane (as a scalp's roots: floats
  // that share most of their bits). For each set: random.x and random.y in
  // [0, 1), each in 20 bins (chi-square below 43.82, the 0.999 quantile for
  // 19 degrees of freedom), the pair in 10 x 10 bins (below 148.23, the
  // 0.999 quantile for 99), and the correlation of x and y below 0.03 in
  // magnitude (its standard deviation is 1 / sqrt(20000) = 0.007).
  auto n = 20000;
  for (auto grid : {false, true}) {
    auto what  = std::string(grid ? "grid roots" : "random roots");
    auto shape = shape_data{};
    auto rng   = make_rng(3);
    for (auto i = 0; i < n; i++) {
      auto root = grid ? vec3f{(i % 142) * 0.01f, 1.5f, (i / 142) * 0.01f - 0.7f}
                       : rand3f(rng) * 2.0f - 1.0f;
      shape.positions.push_back(root);
      shape.positions.push_back(root + vec3f{0, -0.3f, 0});
      shape.lines.push_back({2 * i, 2 * i + 1});
    }
    auto strands = make_fiber_strands(shape);
    ASSERT_EQ((int)strands.random.size(), n) << what;
    auto bins_x = std::vector<double>(20), bins_y = std::vector<double>(20);
    auto bins_xy = std::vector<double>(100);
    auto sx = 0.0, sy = 0.0, sxx = 0.0, syy = 0.0, sxy = 0.0;
    for (auto& r : strands.random) {
      ASSERT_TRUE(r.x >= 0 && r.x < 1 && r.y >= 0 && r.y < 1) << what;
      bins_x[(int)(r.x * 20)]++;
      bins_y[(int)(r.y * 20)]++;
      bins_xy[(int)(r.x * 10) * 10 + (int)(r.y * 10)]++;
      sx += r.x, sy += r.y, sxx += r.x * r.x, syy += r.y * r.y, sxy += r.x * r.y;
    }
    auto chi_square = [&](const std::vector<double>& bins) {
      auto expected = (double)n / bins.size(), sum = 0.0;
      for (auto count : bins) sum += (count - expected) * (count - expected) / expected;
      return sum;
    };
    EXPECT_LT(chi_square(bins_x), 43.82) << what;
    EXPECT_LT(chi_square(bins_y), 43.82) << what;
    EXPECT_LT(chi_square(bins_xy), 148.23) << what;
    auto covariance  = sxy / n - (sx / n) * (sy / n);
    auto correlation = covariance / std::sqrt((sxx / n - sx * sx / n / n) *
                                              (syy / n - sy * sy / n / n));
    EXPECT_LT(std::abs(correlation), 0.03) << what;
    std::printf("[ figure ] %s: chi-square x %.1f, y %.1f, xy %.1f, correlation %.4f\n",
        what.c_str(), chi_square(bins_x), chi_square(bins_y), chi_square(bins_xy),
        correlation);
  }
}

// -----------------------------------------------------------------------------
// STRANDS FROM CONNECTIVITY
// -----------------------------------------------------------------------------

TEST(groom, strands_from_connectivity) {
  // Lines chained by shared vertices, with chords 1, 2 and 1: one strand,
  // u = 0, 1/4, 3/4, 1.
  auto chain      = shape_data{};
  chain.positions = {{0, 0, 0}, {1, 0, 0}, {1, 2, 0}, {1, 2, 1}};
  chain.lines     = {{0, 1}, {1, 2}, {2, 3}};
  auto strands    = make_fiber_strands(chain);
  EXPECT_EQ(check_strands(chain, strands, "chain"), (std::vector<std::vector<int>>{{0, 1, 2}}));
  EXPECT_NEAR(strands.u[0].y, 0.25f, 1e-6f);
  EXPECT_NEAR(strands.u[2].x, 0.75f, 1e-6f);

  // The same by equal positions only, listed tip first, the root at -0.
  auto reversed      = shape_data{};
  reversed.positions = {{1, 2, 0}, {1, 2, 1}, {1, 0, 0}, {1, 2, 0}, {0, 0, 0}, {1, 0, 0}};
  reversed.lines     = {{0, 1}, {2, 3}, {4, 5}};
  reversed.positions[4] = {-0.0f, 0, -0.0f};
  strands = make_fiber_strands(reversed);
  EXPECT_EQ(check_strands(reversed, strands, "reversed"),
      (std::vector<std::vector<int>>{{2, 1, 0}}));
  EXPECT_EQ(strands.random[0], strand_random({0, 0, 0}));
  auto signs      = shape_data{};
  signs.positions = {{0, 1, 0}, {-0.0f, 0, 0}, {0, 0, 0}, {0, -1, 0}};
  signs.lines     = {{0, 1}, {2, 3}};
  EXPECT_EQ(check_strands(signs, make_fiber_strands(signs), "-0 joint"),
      (std::vector<std::vector<int>>{{0, 1}}));

  // Curves: two Catmull-Rom strands (3 and 1 segments, shared joints), and
  // a third by equal positions only, its segments interleaved with the
  // others' in the file.
  auto curves = shape_data{};
  append_catmull_rom_strand(curves, {{0, 0, 0}, {0, -1, 0}, {0.5f, -2, 0}, {0.5f, -3, 0.5f}},
      {0.01f, 0.01f, 0.01f, 0.01f});
  append_catmull_rom_strand(curves, {{2, 0, 0}, {2, -1, 0}}, {0.01f, 0.01f});
  auto third = shape_data{};
  append_catmull_rom_strand(third, {{4, 0, 0}, {4, -1, 0}, {4, -2, 1}}, {0.01f, 0.01f, 0.01f});
  auto base = (int)curves.positions.size();
  for (auto k = 0; k < 2; k++) {
    for (auto v = 0; v < 4; v++) {
      curves.positions.push_back(third.positions[third.curves[k][v]]);
      curves.radius.push_back(0.01f);
    }
  }
  curves.curves.insert(curves.curves.begin() + 1, vec4i{base + 4, base + 5, base + 6, base + 7});
  curves.curves.insert(curves.curves.begin(), vec4i{base, base + 1, base + 2, base + 3});
  // Now: 0 third's root, 1 first's root, 2 third's tip, 3 and 4 first's, 5 second.
  EXPECT_EQ(check_strands(curves, make_fiber_strands(curves), "curves"),
      (std::vector<std::vector<int>>{{0, 2}, {1, 3, 4}, {5}}));

  // A closed loop (a square listed from its third side) starts at its
  // lowest segment; beside it three single-segment strands.
  auto loop      = shape_data{};
  loop.positions = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}};
  loop.lines     = {{2, 3}, {3, 0}, {0, 1}, {1, 2}};
  for (auto k = 0; k < 3; k++) {
    auto first = (int)loop.positions.size();
    loop.positions.push_back({5.0f + k, 0, 0});
    loop.positions.push_back({5.0f + k, 0.5f * (k + 1), 0});
    loop.lines.push_back({first, first + 1});
  }
  strands = make_fiber_strands(loop);
  EXPECT_EQ(check_strands(loop, strands, "loop and singles"),
      (std::vector<std::vector<int>>{{4}, {5}, {6}, {0, 1, 2, 3}}));
  for (auto i = 4; i < 7; i++) EXPECT_EQ(strands.u[i], (vec2f{0, 1}));
  EXPECT_EQ(strands.random[3], strand_random({1, 1, 0}));

  // No segment, no strand.
  auto empty = make_fiber_strands(shape_data{});
  EXPECT_TRUE(empty.random.empty());
  EXPECT_EQ(empty.starts, std::vector<int>{0});
}

// -----------------------------------------------------------------------------
// ROOT TO TIP, STRAND TO STRAND, TINT
// -----------------------------------------------------------------------------

// Hair materials by each pigment parameter, with a tip value.
static std::vector<std::pair<std::string, hair_material>> make_tipped_materials() {
  auto melanin                = hair_material{};
  melanin.eumelanin           = 1.3f;
  melanin.pheomelanin         = 0.2f;
  melanin.tip_eumelanin       = 0.2f;
  melanin.tip_pheomelanin     = 0.6f;
  melanin.has_tip_eumelanin   = true;
  melanin.has_tip_pheomelanin = true;
  auto color                  = hair_material{};
  color.has_color             = true;
  color.color                 = {0.3f, 0.2f, 0.1f};
  color.tip_color             = {0.9f, 0.8f, 0.6f};
  color.has_tip_color         = true;
  color.beta_n                = 0.4f;
  auto sigma_a                = hair_material{};
  sigma_a.has_sigma_a         = true;
  sigma_a.sigma_a             = {1, 2, 3};
  sigma_a.tip_sigma_a         = {0.1f, 0.2f, 0.3f};
  sigma_a.has_tip_sigma_a     = true;
  return {{"melanin", melanin}, {"color", color}, {"sigma_a", sigma_a}};
}

// The material without its tip values, and with its tip values as its root
// values (a tip value left out is the root's).
static hair_material root_of(const hair_material& material) {
  auto root                = material;
  root.has_tip_eumelanin   = false;
  root.has_tip_pheomelanin = false;
  root.has_tip_color       = false;
  root.has_tip_sigma_a     = false;
  return root;
}
static hair_material tip_of(const hair_material& material) {
  auto tip        = root_of(material);
  tip.eumelanin   = material.has_tip_eumelanin ? material.tip_eumelanin : material.eumelanin;
  tip.pheomelanin = material.has_tip_pheomelanin ? material.tip_pheomelanin
                                                 : material.pheomelanin;
  tip.color       = material.has_tip_color ? material.tip_color : material.color;
  tip.sigma_a     = material.has_tip_sigma_a ? material.tip_sigma_a : material.sigma_a;
  return tip;
}

TEST(groom, root_to_tip) {
  // For melanin, colour and sigma_a materials (any random pair; nothing
  // random here): sigma_a at u = 0 is make_hair_absorption of the material
  // without variation (relative 1e-6), at u = 1 that of the tip's values
  // (relative 1e-5: the blend a + (b - a) 1 may miss b by an ulp, which the
  // colour mapping amplifies); in between every channel lies between the two.
  // With tip_start = 0.5: u = 0.25 is the root's, u = 0.75 the pigment
  // halfway (the average absorption for melanin and sigma_a, which are
  // linear; the halfway colour's for colour).
  for (auto& [name, material] : make_tipped_materials()) {
    auto random = vec2f{0.37f, 0.81f};
    EXPECT_TRUE(hair_material_varies(material)) << name;
    auto root = make_hair_absorption(root_of(material));
    auto tip  = make_hair_absorption(tip_of(material));
    auto at0  = eval_hair_material_point(material, random, 0);
    auto at1  = eval_hair_material_point(material, random, 1);
    EXPECT_TRUE(at0.has_sigma_a) << name;
    expect_relative(at0.sigma_a, root, 1e-6f, name + " root");
    expect_relative(at1.sigma_a, tip, 1e-5f, name + " tip");
    expect_relative(make_hair_absorption(at1), tip, 1e-5f, name + " tip absorption");
    for (auto c = 0; c < 3; c++) EXPECT_GT(std::abs(root[c] - tip[c]), 0.01f) << name;
    for (auto u = 0.1f; u < 0.95f; u += 0.1f) {
      auto sigma_a = eval_hair_material_point(material, random, u).sigma_a;
      for (auto c = 0; c < 3; c++) {
        EXPECT_GE(sigma_a[c], std::min(root[c], tip[c]) * (1 - 1e-6f)) << name << " u " << u;
        EXPECT_LE(sigma_a[c], std::max(root[c], tip[c]) * (1 + 1e-6f)) << name << " u " << u;
      }
    }
    auto late      = material;
    late.tip_start = 0.5f;
    expect_relative(eval_hair_material_point(late, random, 0.25f).sigma_a, root, 1e-6f,
        name + " before tip_start");
    auto halfway = (root + tip) / 2.0f;
    if (name == "color")
      halfway = hair_sigma_a_from_color((material.color + material.tip_color) / 2.0f, 0.4f);
    expect_relative(eval_hair_material_point(late, random, 0.75f).sigma_a, halfway, 1e-5f,
        name + " halfway from tip_start");
    expect_relative(eval_hair_material_point(late, random, 1).sigma_a, tip, 1e-5f,
        name + " tip with tip_start");
  }

  // A tip value left out is the root's: only tip_eumelanin given keeps the
  // root's pheomelanin; a tip value of a pigment the material does not use
  // (tip_eumelanin on a colour material) changes nothing.
  auto melanin              = hair_material{};
  melanin.eumelanin         = 1.0f;
  melanin.pheomelanin       = 0.5f;
  melanin.tip_eumelanin     = 0.1f;
  melanin.has_tip_eumelanin = true;
  melanin.tip_pheomelanin   = 3.0f;  // not given: ignored
  expect_relative(eval_hair_material_point(melanin, {0.5f, 0.5f}, 1).sigma_a,
      hair_sigma_a_from_melanin(0.1f, 0.5f), 1e-5f, "tip eumelanin only");
  auto color              = hair_material{};
  color.has_color         = true;
  color.color             = {0.4f, 0.3f, 0.2f};
  color.has_tip_eumelanin = true;
  color.tip_eumelanin     = 5;
  color.tip_color         = {0.9f, 0.9f, 0.9f};  // not given: ignored
  for (auto u : {0.0f, 0.5f, 1.0f})
    expect_relative(eval_hair_material_point(color, {0.5f, 0.5f}, u).sigma_a,
        make_hair_absorption(color), 1e-6f, "colour with a melanin tip");
}

TEST(groom, random_melanin_and_roughness_keep_the_mean) {
  // Over the 20,000 strands of random roots, a melanin material's sigma_a
  // (random_melanin 0.5) and beta_m, beta_n (random_roughness 0.5) average
  // to the material's within 1%: the factor 1 + (2 r - 1) 0.5 has mean 1 and
  // standard deviation 0.29, so the mean's is 0.002 and 1% is 5 of them.
  // With random_melanin 1 (factor 2 r, deviation 0.58): within 2%. The two
  // factors are independent: their correlation below 0.03 in magnitude.
  // A sigma_a = 0 material stays at 0 for every strand.
  auto shape = shape_data{};
  auto rng   = make_rng(5);
  for (auto i = 0; i < 20000; i++) {
    auto root = rand3f(rng) * 2.0f - 1.0f;
    shape.positions.insert(shape.positions.end(), {root, root + vec3f{0, -1, 0}});
    shape.lines.push_back({2 * i, 2 * i + 1});
  }
  auto strands = make_fiber_strands(shape);
  for (auto spread : {0.5f, 1.0f}) {
    auto material             = hair_material{};
    material.eumelanin        = 1.3f;
    material.pheomelanin      = 0.3f;
    material.beta_m           = 0.3f;
    material.beta_n           = 0.4f;
    material.random_melanin   = spread;
    material.random_roughness = 0.5f;
    auto expected             = make_hair_absorption(material);
    auto sum                  = glm::dvec3{0, 0, 0};
    auto beta_m = 0.0, beta_n = 0.0, sf = 0.0, sr = 0.0, sff = 0.0, srr = 0.0, sfr = 0.0;
    for (auto& random : strands.random) {
      auto point = eval_hair_material_point(material, random, 0.5f);
      sum += glm::dvec3(point.sigma_a);
      beta_m += point.beta_m;
      beta_n += point.beta_n;
      auto f = (double)point.sigma_a.x / expected.x, r = (double)point.beta_m / 0.3;
      sf += f, sr += r, sff += f * f, srr += r * r, sfr += f * r;
    }
    auto n    = (double)strands.random.size();
    auto mean = vec3f(sum / n);
    expect_relative(mean, expected, spread == 1 ? 0.02f : 0.01f, "mean sigma_a");
    EXPECT_NEAR(beta_m / n, 0.3, 0.003);
    EXPECT_NEAR(beta_n / n, 0.4, 0.004);
    auto correlation = (sfr / n - sf / n * sr / n) /
                       std::sqrt((sff / n - sf * sf / n / n) * (srr / n - sr * sr / n / n));
    EXPECT_LT(std::abs(correlation), 0.03);
  }
  auto white             = hair_material{};
  white.has_sigma_a      = true;
  white.sigma_a          = {0, 0, 0};
  white.random_melanin   = 0.5f;
  white.random_roughness = 0.5f;
  for (auto k = 0; k < 1000; k++)
    EXPECT_EQ(eval_hair_material_point(white, strands.random[k], 0.3f).sigma_a,
        (vec3f{0, 0, 0}));
}

TEST(groom, tint_adds_the_absorption_of_its_colour) {
  // A white tint adds nothing: the material does not vary, and a varying
  // one's sigma_a is bit-identical with and without it. A coloured tint
  // adds hair_sigma_a_from_color(tint, beta_n) with the material's beta_n
  // (relative 1e-5), the same on every strand and at every u (the dye is not
  // scaled by random_melanin).
  auto plain = hair_material{};
  plain.tint = {1, 1, 1};
  EXPECT_FALSE(hair_material_varies(plain));
  auto material             = hair_material{};
  material.eumelanin        = 0.8f;
  material.beta_m           = 0.2f;
  material.beta_n           = 0.5f;
  material.random_melanin   = 0.4f;
  material.random_roughness = 0.3f;
  material.tip_eumelanin    = 0.3f;
  material.has_tip_eumelanin = true;
  auto white                = material;
  white.tint                = {1, 1, 1};
  auto dyed                 = material;
  dyed.tint                 = {0.9f, 0.5f, 0.6f};
  auto tinted               = hair_material{};
  tinted.tint               = dyed.tint;
  EXPECT_TRUE(hair_material_varies(tinted));
  auto dye = hair_sigma_a_from_color(dyed.tint, 0.5f);
  for (auto& random : {vec2f{0.1f, 0.9f}, vec2f{0.5f, 0.5f}, vec2f{0.95f, 0.2f}}) {
    for (auto u : {0.0f, 0.4f, 1.0f}) {
      auto base = eval_hair_material_point(material, random, u).sigma_a;
      EXPECT_EQ(eval_hair_material_point(white, random, u).sigma_a, base);
      expect_relative(eval_hair_material_point(dyed, random, u).sigma_a - base, dye, 1e-5f,
          "tint");
    }
  }
  // On a material without variation but the tint: its pigment plus the dye.
  expect_relative(eval_hair_material_point(tinted, {0.3f, 0.3f}, 0.5f).sigma_a,
      make_hair_absorption(hair_material{}) + hair_sigma_a_from_color(tinted.tint, 0.3f), 1e-5f,
      "tint alone");
}

// -----------------------------------------------------------------------------
// RENDERS
// -----------------------------------------------------------------------------

TEST(groom, white_furnace_with_random_melanin_and_roughness) {
  // The lock alone, sigma_a = 0 with random_melanin 0.5 and random_roughness
  // 0.5 (each hit's beta_m and beta_n from its strand), under a constant
  // white sky; 32x32 pixels. The fibre pixels are those a black matte lock
  // darkens. With the lobe weights (default, lights automatic: the constant
  // sky left to BSDF sampling) and with the mixture weights, each fibre
  // pixel is 1 within 1e-4 (4 spp, every path carries its energy to the sky).
  // With MIS against uniform sky samples (lights all, 256 spp), which needs
  // eval and pdf of each strand's own roughness to agree, the fibre pixels
  // average 1 within 0.5% (over seeds their average deviates by about 0.1%).
  auto white             = hair_material{};
  white.has_sigma_a      = true;
  white.sigma_a          = {0, 0, 0};
  white.random_melanin   = 0.5f;
  white.random_roughness = 0.5f;
  auto scene             = make_groom_scene(white, false, {1, 1, 1});
  auto params            = trace_params{};
  params.resolution      = 32;
  params.samples         = 1;
  params.seed            = 19;
  auto black             = scene;
  black.materials[0]     = material_data{};
  auto coverage          = render_groom(black, params);
  auto fibre             = std::vector<int>{};
  for (auto i = 0; i < (int)coverage.image.pixels.size(); i++)
    if (max_component(coverage.image.pixels[i]) < 0.999f) fibre.push_back(i);
  ASSERT_GT(fibre.size(), 40u);
  auto context = make_shading_context(scene);
  EXPECT_FALSE(context.strands[0].strand.empty());
  for (auto mixture : {false, true}) {
    params.samples                      = 4;
    params.hair_sampling.mixture_weight = mixture;
    auto render                         = render_groom(scene, params);
    EXPECT_EQ(render.nonfinite, 0);
    auto worst = 0.0f;
    for (auto i : fibre)
      worst = std::max(worst, max_component(abs(render.image.pixels[i] - 1.0f)));
    EXPECT_LT(worst, 1e-4f) << (mixture ? "mixture weights" : "lobe weights");
  }
  params.hair_sampling.mixture_weight = false;
  params.lights                       = trace_lights_type::all;
  params.samples                      = 256;
  auto render                         = render_groom(scene, params);
  EXPECT_EQ(render.nonfinite, 0);
  auto sum = 0.0;
  for (auto i : fibre) sum += mean(render.image.pixels[i]);
  EXPECT_NEAR(sum / fibre.size(), 1, 0.005);
  std::printf("[ figure ] varying white furnace, MIS: %zu fibre pixels average %.4f\n",
      fibre.size(), sum / fibre.size());
}

TEST(groom, materials_that_do_not_vary_render_bit_for_bit) {
  // The lock over a skin sphere, 24x24 at 8 spp. A hair material without
  // variation renders the same sums, bit for bit, as: the same material with
  // the variation keys at their defaults written out and unused tip values
  // (no has_ flag) and a tip_start; and the same material through the
  // varying path with variation that changes nothing (a tip value equal to
  // the root's), for melanin, colour and sigma_a. Shading builds no strands
  // for the first two and builds them for the third.
  auto materials = make_tipped_materials();
  for (auto& [name, tipped] : materials) {
    auto material             = root_of(tipped);
    auto explicit_zero        = material;
    explicit_zero.random_melanin   = 0;
    explicit_zero.random_roughness = 0;
    explicit_zero.tint             = {1, 1, 1};
    explicit_zero.tip_start        = 0.5f;
    explicit_zero.tip_eumelanin    = 0.1f;
    explicit_zero.tip_color        = {0.9f, 0.9f, 0.9f};
    explicit_zero.tip_sigma_a      = {5, 5, 5};
    auto trivial                   = material;
    trivial.has_tip_eumelanin      = name == "melanin";
    trivial.tip_eumelanin          = material.eumelanin;
    trivial.has_tip_color          = name == "color";
    trivial.tip_color              = material.color;
    trivial.has_tip_sigma_a        = name == "sigma_a";
    trivial.tip_sigma_a            = material.sigma_a;
    EXPECT_FALSE(hair_material_varies(material)) << name;
    EXPECT_FALSE(hair_material_varies(explicit_zero)) << name;
    EXPECT_TRUE(hair_material_varies(trivial)) << name;
    auto params       = trace_params{};
    params.resolution = 24;
    params.samples    = 8;
    params.seed       = 23;
    auto scene        = make_groom_scene(material, true);
    auto reference    = render_groom(scene, params);
    for (auto& [what, other] :
        {std::pair{"explicit zeros", explicit_zero}, std::pair{"trivial variation", trivial}}) {
      auto other_scene = make_groom_scene(other, true);
      auto context     = make_shading_context(other_scene);
      auto varies      = std::string(what) == "trivial variation";
      EXPECT_EQ(context.strands[0].strand.empty(), !varies) << name << " " << what;
      EXPECT_TRUE(context.strands[1].strand.empty()) << name << " " << what;
      EXPECT_EQ((bool)context.hair_varies[0], varies) << name << " " << what;
      auto render = render_groom(other_scene, params);
      EXPECT_TRUE(render.sums == reference.sums) << name << " " << what;
    }
    auto context = make_shading_context(scene);
    EXPECT_TRUE(context.strands[0].strand.empty()) << name;
    EXPECT_FALSE(context.hair_varies[0]) << name;
  }
}

TEST(groom, varying_groom_renders_finite_and_different) {
  // The lock over a skin sphere, 32x32 at 16 spp, eumelanin 1.3 with
  // random_melanin 0.5 and tip_eumelanin 0.2: no NaN or Inf, no negative
  // pixel; it differs from the lock without variation, and its lower half
  // (the tips hang down) is brighter by more than 5% of the sky-lit mean
  // there, since the tips hold less pigment.
  auto plain          = hair_material{};
  auto varying        = plain;
  varying.random_melanin    = 0.5f;
  varying.tip_eumelanin     = 0.2f;
  varying.has_tip_eumelanin = true;
  auto params         = trace_params{};
  params.resolution   = 32;
  params.samples      = 16;
  params.seed         = 29;
  auto base           = render_groom(make_groom_scene(plain, true), params);
  auto render         = render_groom(make_groom_scene(varying, true), params);
  EXPECT_EQ(render.nonfinite, 0);
  for (auto& p : render.image.pixels) {
    ASSERT_TRUE(isfinite(p));
    ASSERT_GE(min_component(p), 0);
  }
  EXPECT_FALSE(render.sums == base.sums);
  auto lower = [](const texture_data& image) {
    auto sum = 0.0;
    for (auto j = image.height * 5 / 8; j < image.height; j++)
      for (auto i = 0; i < image.width; i++) sum += mean(image.pixels[j * image.width + i]);
    return sum;
  };
  std::printf("[ figure ] varying groom: lower part %.3f against %.3f without variation\n",
      lower(render.image), lower(base.image));
  EXPECT_GT(lower(render.image), 1.05 * lower(base.image));
}

// -----------------------------------------------------------------------------
// PER-POINT COLOURS OF .HAIR FILES
// -----------------------------------------------------------------------------

// A file in the temporary folder, removed at the end of the test.
struct temp_file {
  std::string path = {};
  explicit temp_file(const std::string& name)
      : path((std::filesystem::temp_directory_path() /
                 ("test_groom_" + std::to_string(getpid()) + "_" + name))
                 .string()) {}
  ~temp_file() { std::filesystem::remove(path); }
};

// Writes a Cem Yuksel .hair file: a 128-byte header ("HAIR", strands,
// points, flags, default segments, thickness, transparency and colour, then
// 88 bytes of text), the segments per strand (uint16), the points and, if
// any, a colour per point; little-endian, as this machine.
static void write_hair_file(const std::string& filename,
    const std::vector<std::vector<vec3f>>& strands,
    const std::vector<std::vector<vec3f>>& colors) {
  auto bytes = std::string{};
  auto put   = [&](const void* data, size_t size) { bytes.append((const char*)data, size); };
  auto num_points = (uint32_t)0;
  for (auto& strand : strands) num_points += (uint32_t)strand.size();
  auto num_strands = (uint32_t)strands.size();
  auto flags       = (uint32_t)(1 | 2 | (colors.empty() ? 0 : 16));
  auto segments    = (uint32_t)0;
  float thickness = 0.02f, transparency = 0, color[3] = {0.5f, 0.5f, 0.5f};
  bytes = "HAIR";
  put(&num_strands, 4);
  put(&num_points, 4);
  put(&flags, 4);
  put(&segments, 4);
  put(&thickness, 4);
  put(&transparency, 4);
  put(color, 12);
  bytes.resize(128, '\0');
  for (auto& strand : strands) {
    auto count = (uint16_t)(strand.size() - 1);
    put(&count, 2);
  }
  for (auto& strand : strands) put(strand.data(), strand.size() * 12);
  for (auto& strand : colors) put(strand.data(), strand.size() * 12);
  auto stream = std::ofstream(filename, std::ios::binary);
  stream.write(bytes.data(), (std::streamsize)bytes.size());
}

TEST(groom, per_point_colours_of_hair_files) {
  // Two strands of 3 and 2 points with a colour each (one out of range,
  // clamped to [0.01, 0.99]): shape.colors has 3 per segment + 1 a strand,
  // one per control point: the points' colours at the curve ends (1e-6),
  // thirds between them inside. The scene's material is given by colour,
  // and its fingerprint changes with a colour.
  auto file    = temp_file{"colours.hair"};
  auto strands = std::vector<std::vector<vec3f>>{
      {{0, 1, 0}, {0, 0, 0}, {0.2f, -1, 0}}, {{1, 1, 0}, {1, 0, 0}}};
  auto colors = std::vector<std::vector<vec3f>>{
      {{0.2f, 0.1f, 0.05f}, {0.6f, 0.5f, 0.3f}, {0.9f, 0.8f, 0.7f}},
      {{1.5f, 0.5f, -0.2f}, {0.3f, 0.3f, 0.3f}}};
  write_hair_file(file.path, strands, colors);
  auto shape = shape_data{};
  auto error = std::string{};
  ASSERT_TRUE(load_hair_model(file.path, shape, error)) << error;
  ASSERT_EQ(shape.curves.size(), 3u);
  ASSERT_EQ(shape.colors.size(), shape.positions.size());
  EXPECT_EQ(shape.colors.size(), 3u * 2 + 1 + 3u * 1 + 1);
  auto expected = std::vector<vec3f>{colors[0][0], colors[0][1], colors[0][2],
      glm::clamp(colors[1][0], vec3f{0.01f}, vec3f{0.99f}), colors[1][1]};
  auto ends     = std::vector<vec2i>{{0, 1}, {1, 2}, {3, 4}};
  for (auto k = 0; k < 3; k++) {
    auto& curve = shape.curves[k];
    auto  c0 = expected[ends[k].x], c1 = expected[ends[k].y];
    expect_relative(shape.colors[curve.x], c0, 1e-6f, "start colour");
    expect_relative(shape.colors[curve.w], c1, 1e-6f, "end colour");
    expect_relative(shape.colors[curve.y], (2.0f * c0 + c1) / 3.0f, 1e-6f, "first third");
    expect_relative(shape.colors[curve.z], (c0 + 2.0f * c1) / 3.0f, 1e-6f, "second third");
  }
  auto scene = scene_data{};
  ASSERT_TRUE(load_hair_scene(file.path, scene, error)) << error;
  auto& hair = scene.materials[0].hair;
  EXPECT_TRUE(hair.has_color);
  EXPECT_FALSE(hair.has_sigma_a);
  EXPECT_EQ(scene.shapes[0].colors.size(), scene.shapes[0].positions.size());
  // The colours are part of what a render depends on: the fingerprint.
  auto recoloured = scene;
  recoloured.shapes[0].colors[1].y += 0.1f;
  EXPECT_NE(fingerprint_scene(recoloured), fingerprint_scene(scene));

  // A hit on the first curve (colours c0 at its start, c1 at its end) seen
  // along -z: its hair's sigma_a is the colour's at the hit, interpolated
  // along the segment (relative 1e-5), each channel between the ends'; at
  // t = 0.001 and 0.999 within 1% of the nearer end's. Colours alone need no
  // strands.
  auto context = make_shading_context(scene);
  EXPECT_TRUE(context.hair_varies[0]);
  EXPECT_TRUE(context.strands[0].strand.empty());
  auto& p      = scene.shapes[0].positions;
  auto& curve  = scene.shapes[0].curves[0];
  auto  beta_n = hair.beta_n;
  auto  s0     = hair_sigma_a_from_color(expected[0], beta_n);
  auto  s1     = hair_sigma_a_from_color(expected[1], beta_n);
  for (auto t : {0.001f, 0.3f, 0.5f, 0.999f}) {
    auto axis  = eval_bezier(p[curve.x], p[curve.y], p[curve.z], p[curve.w], t);
    auto ray   = ray3f{axis + vec3f{0, 0, 5}, {0, 0, -1}, 0, flt_max};
    auto point = eval_material_point(scene, context, 0, 0, {t, 0}, 5 - 0.01f, ray);
    ASSERT_EQ(point.type, material_type::hair);
    auto sigma_a = point.hair.material.sigma_a;
    expect_relative(sigma_a,
        hair_sigma_a_from_color(expected[0] + (expected[1] - expected[0]) * t, beta_n), 1e-5f,
        "hit colour at t " + std::to_string(t));
    for (auto c = 0; c < 3; c++) {
      EXPECT_GE(sigma_a[c], std::min(s0[c], s1[c]) * (1 - 1e-5f)) << "t " << t;
      EXPECT_LE(sigma_a[c], std::max(s0[c], s1[c]) * (1 + 1e-5f)) << "t " << t;
    }
    if (t < 0.01f) expect_relative(sigma_a, s0, 0.01f, "near the start");
    if (t > 0.99f) expect_relative(sigma_a, s1, 0.01f, "near the end");
  }
  // A sigma_a material over the same shape ignores the colours.
  auto absorbing                    = scene;
  absorbing.materials[0].hair       = hair_material{};
  absorbing.materials[0].hair.has_sigma_a = true;
  absorbing.materials[0].hair.sigma_a     = {0.5f, 1, 2};
  EXPECT_FALSE(make_shading_context(absorbing).hair_varies[0]);

  // Without a colour array: no shape.colors, a melanin material.
  auto plain = temp_file{"plain.hair"};
  write_hair_file(plain.path, strands, {});
  ASSERT_TRUE(load_hair_model(plain.path, shape, error)) << error;
  EXPECT_TRUE(shape.colors.empty());
  ASSERT_TRUE(load_hair_scene(plain.path, scene, error)) << error;
  EXPECT_TRUE(scene.shapes[0].colors.empty());
  EXPECT_FALSE(scene.materials[0].hair.has_color);
  EXPECT_FALSE(make_shading_context(scene).hair_varies[0]);
}

// -----------------------------------------------------------------------------
// BUGS THIS FILE FOUND (fixed)
// -----------------------------------------------------------------------------

TEST(groom, per_point_colours_survive_curves_as_lines) {
  // load_hair_scene with curves_as_lines (yscene convert --curves lines)
  // tessellates the curves with curves_to_lines, which dropped shape.colors
  // (the groom fell back to the file's average colour): the lines keep a
  // colour per vertex, the points' colours at the strands' points.
  auto file    = temp_file{"lines.hair"};
  auto strands = std::vector<std::vector<vec3f>>{{{0, 1, 0}, {0, 0, 0}, {0.2f, -1, 0}}};
  auto colors  = std::vector<std::vector<vec3f>>{
      {{0.2f, 0.1f, 0.05f}, {0.6f, 0.5f, 0.3f}, {0.9f, 0.8f, 0.7f}}};
  write_hair_file(file.path, strands, colors);
  auto params            = hair_params{};
  params.curves_as_lines = true;
  auto scene             = scene_data{};
  auto error             = std::string{};
  ASSERT_TRUE(load_hair_scene(file.path, scene, error, params)) << error;
  auto& shape = scene.shapes[0];
  ASSERT_FALSE(shape.lines.empty());
  ASSERT_EQ(shape.colors.size(), shape.positions.size());
  expect_relative(shape.colors[shape.lines.front().x], colors[0][0], 1e-5f, "root colour");
  expect_relative(shape.colors[shape.lines.back().y], colors[0][2], 1e-5f, "tip colour");
}

TEST(groom, validation_checks_the_colours) {
  // validate_scene checked normals, texcoords and radius against the
  // vertices, not colors: a shape with fewer colours than vertices under a
  // hair material by colour passed, and eval_material_point then read past
  // the end of shape.colors.
  auto scene     = make_groom_scene(hair_material{}, false);
  auto& hair     = scene.materials[0].hair;
  hair.has_color = true;
  hair.color     = {0.5f, 0.4f, 0.3f};
  scene.shapes[0].colors.assign(2, vec3f{0.5f, 0.5f, 0.5f});
  auto error = std::string{};
  EXPECT_FALSE(validate_scene(scene, error));
  EXPECT_NE(error.find("colors"), std::string::npos) << error;
}

TEST(groom, per_point_colours_survive_a_hair_round_trip) {
  // save_hair_model wrote no colour array: a .hair -> .hair conversion lost
  // the points' colours. Saved and loaded again, every control point keeps
  // its colour (the spline's inner points are rebuilt from the points').
  auto file    = temp_file{"in.hair"};
  auto copy    = temp_file{"out.hair"};
  auto strands = std::vector<std::vector<vec3f>>{
      {{0, 1, 0}, {0, 0, 0}, {0.2f, -1, 0}}, {{1, 1, 0}, {1, 0, 0.5f}}};
  auto colors  = std::vector<std::vector<vec3f>>{
      {{0.2f, 0.1f, 0.05f}, {0.6f, 0.5f, 0.3f}, {0.9f, 0.8f, 0.7f}},
      {{0.3f, 0.3f, 0.3f}, {0.7f, 0.2f, 0.1f}}};
  write_hair_file(file.path, strands, colors);
  auto shape = shape_data{}, again = shape_data{};
  auto error = std::string{};
  ASSERT_TRUE(load_hair_model(file.path, shape, error)) << error;
  ASSERT_TRUE(save_hair_model(copy.path, shape, error)) << error;
  ASSERT_TRUE(load_hair_model(copy.path, again, error)) << error;
  ASSERT_EQ(again.colors.size(), shape.colors.size());
  for (size_t i = 0; i < shape.colors.size(); i++)
    expect_relative(again.colors[i], shape.colors[i], 1e-6f, "colour " + std::to_string(i));
}
