//
// Tests of the math and sampling helpers, cameras, and fiber hits through the
// real Embree intersection path.
//

#include <gtest/gtest.h>
#include <yocto/yocto_bvh.h>
#include <yocto/yocto_hairgen.h>
#include <yocto/yocto_ply.h>
#include <yocto/yocto_sampling.h>
#include <yocto/yocto_scene.h>

#include <cmath>
#include <functional>

using namespace yocto;

// -----------------------------------------------------------------------------
// MATH AND SAMPLING
// -----------------------------------------------------------------------------

TEST(math, frame_inverse_and_composition) {
  auto frame = rotation_frame({1, 2, 3}, 0.7f) * translation_frame({1, -2, 5}) *
               scaling_frame({2, 2, 2});
  auto p     = vec3f{0.3f, -1.2f, 4.0f};
  auto q     = transform_point(inverse(frame), transform_point(frame, p));
  EXPECT_NEAR(distance(p, q), 0, 1e-5f);
  EXPECT_NEAR(frame_scale(frame), 2, 1e-5f);
  auto rigid = rotation_frame({0, 1, 0}, 1.1f) * translation_frame({3, 0, 0});
  auto r     = transform_point(inverse(rigid, false), transform_point(rigid, p));
  EXPECT_NEAR(distance(p, r), 0, 1e-5f);
}

TEST(math, lookat_frame_points_minus_z_at_target) {
  auto frame = lookat_frame({1, 2, 3}, {4, 2, 3}, {0, 1, 0});
  EXPECT_NEAR(dot(-frame.z, vec3f{1, 0, 0}), 1, 1e-6f);
  EXPECT_NEAR(dot(frame.y, vec3f{0, 1, 0}), 1, 1e-6f);
  EXPECT_NEAR(dot(cross(frame.x, frame.y), frame.z), 1, 1e-6f);
}

TEST(math, basis_fromz_is_orthonormal) {
  auto rng = make_rng(7);
  for (auto i = 0; i < 1000; i++) {
    auto z = sample_sphere(rand2f(rng));
    auto b = basis_fromz(z);
    EXPECT_NEAR(dot(b[0], b[1]), 0, 1e-5f);
    EXPECT_NEAR(dot(b[0], b[2]), 0, 1e-5f);
    EXPECT_NEAR(length(b[0]), 1, 1e-5f);
    EXPECT_NEAR(length(b[1]), 1, 1e-5f);
    EXPECT_NEAR(dot(cross(b[0], b[1]), b[2]), 1, 1e-5f);
  }
}

TEST(sampling, rand1f_is_in_unit_interval_and_uniform) {
  // 1e6 numbers in 10 bins: each bin within 1% of 1e5 (about 3 sigma).
  auto rng  = make_rng(1234);
  auto bins = std::vector<int>(10, 0);
  for (auto i = 0; i < 1000000; i++) {
    auto r = rand1f(rng);
    ASSERT_GE(r, 0.0f);
    ASSERT_LT(r, 1.0f);
    bins[(int)(r * 10)]++;
  }
  for (auto count : bins) EXPECT_NEAR(count, 100000, 1000);
}

TEST(sampling, generators_are_repeatable_and_streams_differ) {
  auto a = make_rng(42, 1), b = make_rng(42, 1), c = make_rng(42, 2);
  auto same = true, different = false;
  for (auto i = 0; i < 100; i++) {
    auto x = advance_rng(a), y = advance_rng(b), z = advance_rng(c);
    same      = same && x == y;
    different = different || x != z;
  }
  EXPECT_TRUE(same);
  EXPECT_TRUE(different);
}

TEST(sampling, cosine_hemisphere_matches_its_pdf) {
  // Monte Carlo estimate of the integral of cos^2 over the hemisphere (2pi/3)
  // with cosine sampling: 200k samples, tolerance 0.5%.
  auto rng = make_rng(99);
  auto n   = vec3f{0.3f, -0.5f, 0.8f};
  n        = normalize(n);
  auto sum = 0.0;
  auto count = 200000;
  for (auto i = 0; i < count; i++) {
    auto w   = sample_hemisphere_cos(n, rand2f(rng));
    auto pdf = sample_hemisphere_cos_pdf(n, w);
    ASSERT_GT(pdf, 0);
    sum += sqr(dot(n, w)) / pdf;
  }
  EXPECT_NEAR(sum / count, 2 * pif / 3, 0.005 * 2 * pif / 3);
}

TEST(sampling, discrete_distribution) {
  auto cdf = std::vector<float>{1, 1, 4, 10};  // weights 1, 0, 3, 6
  EXPECT_EQ(sample_discrete(cdf, 0.05f), 0);
  EXPECT_EQ(sample_discrete(cdf, 0.2f), 2);
  EXPECT_EQ(sample_discrete(cdf, 0.99f), 3);
  EXPECT_FLOAT_EQ(sample_discrete_pdf(cdf, 1), 0);
  EXPECT_FLOAT_EQ(sample_discrete_pdf(cdf, 2), 0.3f);
}

TEST(camera, center_ray_looks_down_minus_z_and_corners_match_the_field_of_view) {
  auto camera   = camera_data{};
  camera.frame  = lookat_frame({0, 0, 5}, {0, 0, 0}, {0, 1, 0});
  camera.aspect = 2;
  auto center   = eval_camera(camera, {0.5f, 0.5f}, {0, 0});
  EXPECT_NEAR(dot(center.d, vec3f{0, 0, -1}), 1, 1e-6f);
  // Right edge of the image: half the film width over the lens.
  auto right = eval_camera(camera, {1.0f, 0.5f}, {0, 0});
  EXPECT_NEAR(right.d.x / -right.d.z, camera.film / 2 / camera.lens, 1e-5f);
  // Top edge (v = 0) looks up.
  auto top = eval_camera(camera, {0.5f, 0.0f}, {0, 0});
  EXPECT_NEAR(top.d.y / -top.d.z, camera.film / camera.aspect / 2 / camera.lens, 1e-5f);
  EXPECT_EQ(camera_resolution(camera, 640), (vec2i{640, 320}));
}

TEST(texture, environment_lookups_clamp_v_and_wrap_u) {
  // Top row 1, bottom row 0; left column brighter in the top row so that
  // wrapping in u shows.
  auto texture   = texture_data{2, 2, {{1, 1, 1}, {1, 1, 1}, {0, 0, 0}, {0, 0, 0}}};
  // At the poles the environment sees one row, not a blend of both.
  EXPECT_EQ(eval_environment_texture(texture, {0.3f, 0}), (vec3f{1, 1, 1}));
  EXPECT_EQ(eval_environment_texture(texture, {0.3f, 1}), (vec3f{0, 0, 0}));
  EXPECT_EQ(eval_environment_texture(texture, {0.3f, -0.2f}), (vec3f{1, 1, 1}));
  // Surface textures still wrap in v: half of each row at the seam.
  EXPECT_EQ(eval_texture(texture, {0.3f, 0}), (vec3f{0.5f, 0.5f, 0.5f}));
  // u wraps for both: at u = 0 the first and last columns are blended.
  auto columns = texture_data{2, 1, {{1, 1, 1}, {0, 0, 0}}};
  EXPECT_EQ(eval_environment_texture(columns, {0, 0.5f}), (vec3f{0.5f, 0.5f, 0.5f}));
  // Through the scene: straight up is v = 0, the top row.
  auto scene = scene_data{};
  scene.textures.push_back(texture);
  scene.environments.push_back({identity3x4f, {1, 1, 1}, 0});
  EXPECT_EQ(eval_environment(scene, scene.environments[0], {0, 1, 0}), (vec3f{1, 1, 1}));
}

TEST(camera, project_camera_point_inverts_eval_camera) {
  // A rotated portrait and a landscape camera; points along camera rays at
  // several depths project back to the rays' image coordinates (1e-5).
  for (auto aspect : {0.5f, 1.7f}) {
    auto camera   = camera_data{};
    camera.frame  = lookat_frame({1, 2, 5}, {-1, 0, 0}, {0.3f, 1, 0});
    camera.aspect = aspect;
    for (auto uv : {vec2f{0.5f, 0.5f}, vec2f{0.1f, 0.9f}, vec2f{1, 0}, vec2f{0.7f, 0.2f}}) {
      auto ray = eval_camera(camera, uv, {0, 0});
      for (auto depth : {0.5f, 3.0f, 40.0f}) {
        auto projected = project_camera_point(camera, ray.o + ray.d * depth);
        EXPECT_NEAR(projected.x, uv.x, 1e-5f) << aspect << " " << depth;
        EXPECT_NEAR(projected.y, uv.y, 1e-5f) << aspect << " " << depth;
      }
    }
  }
}

// -----------------------------------------------------------------------------
// FIBER HITS THROUGH EMBREE
// -----------------------------------------------------------------------------

// A straight fiber along x through the origin, radius r, as one shape of the
// given kind, placed by an instance frame.
static scene_data make_straight_fiber_scene(bool curves, float radius, const frame3f& frame) {
  auto scene = scene_data{};
  auto shape = shape_data{};
  if (curves) {
    shape.positions = {{-2, 0, 0}, {-2.0f / 3, 0, 0}, {2.0f / 3, 0, 0}, {2, 0, 0}};
    shape.curves    = {{0, 1, 2, 3}};
  } else {
    shape.positions = {{-2, 0, 0}, {0, 0, 0}, {2, 0, 0}};
    shape.lines     = {{0, 1}, {1, 2}};
  }
  shape.radius.assign(shape.positions.size(), radius);
  scene.shapes.push_back(shape);
  scene.materials.push_back({});
  scene.instances.push_back({frame, 0, 0});
  return scene;
}

// Shoots rays at known offsets across the fiber and checks h (sign included),
// tangent, radius, and that the frame is right-handed with z facing the ray.
static void check_fiber_offsets(bool curves, bool flat) {
  auto radius = 0.1f;
  // Instance frame: rotated and translated so that nothing is axis-aligned.
  auto frame = translation_frame({0.5f, 1, -2}) * rotation_frame({0.2f, 1, 0.3f}, 0.9f);
  auto scene = make_straight_fiber_scene(curves, radius, frame);
  auto bvh   = scene_bvh{};
  auto error = std::string{};
  ASSERT_TRUE(make_scene_bvh(bvh, scene, {flat, false}, error)) << error;
  auto axis_x = transform_direction(frame, {1, 0, 0});
  // View along world-space -z of the fiber's local frame, tilted a bit along
  // the fiber so that the ray is not perpendicular to it.
  auto local_dir = normalize(vec3f{0.3f, 0, -1});
  for (auto h : {-0.9f, -0.5f, -0.1f, 0.0f, 0.3f, 0.7f, 0.95f}) {
    // In the fiber's local frame, y = z x x for z = +z (facing the ray
    // origin) is +y: offset the ray along +y by h * radius.
    auto local_origin = vec3f{0.1f, h * radius, 5} - local_dir * 0.0f;
    auto ray = ray3f{transform_point(frame, local_origin - local_dir * 0.0f),
        transform_direction(frame, local_dir)};
    auto hit = intersect_scene_bvh(bvh, ray);
    ASSERT_TRUE(hit.hit) << "h = " << h;
    auto fiber = eval_fiber_point(
        scene, scene.instances[hit.instance], hit.element, hit.uv.x, ray, hit.distance);
    EXPECT_NEAR(fiber.h, h, 2e-3f) << "h = " << h << (curves ? " curves" : " lines")
                                   << (flat ? " flat" : " round");
    EXPECT_NEAR(std::abs(dot(fiber.tangent, axis_x)), 1, 1e-4f);
    EXPECT_NEAR(fiber.radius, radius, 1e-5f);
    EXPECT_NEAR(dot(cross(fiber.frame.z, fiber.frame.x), fiber.frame.y), 1, 1e-4f);
    EXPECT_GT(dot(fiber.frame.z, -ray.d), 0);
    EXPECT_NEAR(dot(fiber.frame.z, fiber.frame.x), 0, 1e-5f);
    // The hit point lies on the tube for round fibers.
    if (!flat) {
      auto to_hit = fiber.position - fiber.axis;
      to_hit -= dot(to_hit, fiber.tangent) * fiber.tangent;
      EXPECT_NEAR(length(to_hit), radius, 2e-3f);
      // and the normal at h is the surface normal there.
      EXPECT_NEAR(dot(normalize(to_hit), fiber.normal), 1, 1e-2f);
    }
  }
}

TEST(fiber, offset_h_of_round_lines) { check_fiber_offsets(false, false); }
TEST(fiber, offset_h_of_round_curves) { check_fiber_offsets(true, false); }
TEST(fiber, offset_h_of_flat_lines) { check_fiber_offsets(false, true); }
TEST(fiber, offset_h_of_flat_curves) { check_fiber_offsets(true, true); }

TEST(fiber, h_sign_follows_the_frame_y_axis) {
  // Rays from +z hitting a fiber along +x: a hit above the axis (y > 0) has
  // y axis = z x x = +y, so h > 0; below, h < 0. Viewed from -z, the frame's
  // y axis flips to -y, and a hit at y > 0 gets h < 0.
  auto scene = make_straight_fiber_scene(true, 0.2f, identity3x4f);
  auto bvh   = scene_bvh{};
  auto error = std::string{};
  ASSERT_TRUE(make_scene_bvh(bvh, scene, {}, error)) << error;
  auto shoot = [&](vec3f o, vec3f d) {
    auto ray = ray3f{o, d};
    auto hit = intersect_scene_bvh(bvh, ray);
    EXPECT_TRUE(hit.hit);
    return eval_fiber_point(scene, scene.instances[0], hit.element, hit.uv.x, ray, hit.distance);
  };
  auto above = shoot({0, 0.1f, 3}, {0, 0, -1});
  EXPECT_NEAR(above.h, 0.5f, 1e-3f);
  EXPECT_NEAR(dot(above.frame.y, vec3f{0, 1, 0}), 1, 1e-5f);
  auto below = shoot({0, -0.1f, 3}, {0, 0, -1});
  EXPECT_NEAR(below.h, -0.5f, 1e-3f);
  auto behind = shoot({0, 0.1f, -3}, {0, 0, 1});
  EXPECT_NEAR(behind.h, -0.5f, 1e-3f);
  EXPECT_NEAR(dot(behind.frame.y, vec3f{0, -1, 0}), 1, 1e-5f);
}

TEST(fiber, curved_bezier_tangent_and_radius_taper) {
  // A quarter-circle-like Bezier from (0,0,0) to (1,1,0) with radius 0.05
  // tapering to 0.01: hit it from +z at the middle and check the tangent
  // against the analytic derivative and the radius against the Bezier blend.
  auto scene = scene_data{};
  auto shape = shape_data{};
  shape.positions = {{0, 0, 0}, {0.55f, 0, 0}, {1, 0.45f, 0}, {1, 1, 0}};
  shape.radius    = {0.05f, 0.04f, 0.02f, 0.01f};
  shape.curves    = {{0, 1, 2, 3}};
  scene.shapes.push_back(shape);
  scene.materials.push_back({});
  scene.instances.push_back({identity3x4f, 0, 0});
  auto bvh   = scene_bvh{};
  auto error = std::string{};
  ASSERT_TRUE(make_scene_bvh(bvh, scene, {}, error)) << error;
  auto& p   = shape.positions;
  auto  mid = eval_bezier(p[0], p[1], p[2], p[3], 0.5f);
  auto  ray = ray3f{mid + vec3f{0, 0, 3}, {0, 0, -1}};
  auto  hit = intersect_scene_bvh(bvh, ray);
  ASSERT_TRUE(hit.hit);
  auto fiber = eval_fiber_point(scene, scene.instances[0], hit.element, hit.uv.x, ray, hit.distance);
  auto expected_tangent = normalize(eval_bezier_derivative(p[0], p[1], p[2], p[3], hit.uv.x));
  EXPECT_NEAR(dot(fiber.tangent, expected_tangent), 1, 1e-5f);
  EXPECT_NEAR(hit.uv.x, 0.5f, 0.05f);
  EXPECT_NEAR(fiber.radius, eval_bezier(0.05f, 0.04f, 0.02f, 0.01f, hit.uv.x), 1e-6f);
  EXPECT_NEAR(fiber.h, 0, 0.05f);
}

TEST(bvh, occlusion_and_misses) {
  auto scene = make_straight_fiber_scene(false, 0.1f, identity3x4f);
  auto bvh   = scene_bvh{};
  auto error = std::string{};
  ASSERT_TRUE(make_scene_bvh(bvh, scene, {}, error)) << error;
  EXPECT_TRUE(intersect_scene_bvh_any(bvh, {{0, 0, 3}, {0, 0, -1}}));
  EXPECT_FALSE(intersect_scene_bvh_any(bvh, {{0, 0.5f, 3}, {0, 0, -1}}));
  EXPECT_FALSE(intersect_scene_bvh_any(bvh, {{0, 0, 3}, {0, 0, -1}, 0, 2.5f}));
  EXPECT_FALSE(intersect_scene_bvh(bvh, {{0, 0, 3}, {0, 0, 1}}).hit);
  EXPECT_GT(bvh.peak_memory, 0);
}

// Two round fibres crossing with overlapping walls (axes 0.12 apart, radii
// 0.1): a ray that starts inside one passes its wall, for closest hits and
// shadow rays, and still sees the other from outside. Lines and Bezier
// curves, directly and through rotated instances (two instances share each
// shape, so they are not flattened).
TEST(bvh, rays_starting_inside_a_fibre_pass_its_wall) {
  for (auto curves : {false, true}) {
    for (auto instanced : {false, true}) {
      auto frame = instanced ? translation_frame({0.5f, 1, -2}) *
                                   rotation_frame({0.2f, 1, 0.3f}, 0.9f)
                             : identity3x4f;
      // Fibre a along x through the origin; fibre b along y with its axis
      // at z = 0.12 (fibre a turned about z, then lifted).
      auto scene = make_straight_fiber_scene(curves, 0.1f, frame);
      scene.instances.push_back(
          {frame * translation_frame({0, 0, 0.12f}) * rotation_frame({0, 0, 1}, pif / 2), 0, 0});
      if (instanced) {
        // Far away copies, so that each shape has several users.
        scene.instances.push_back({translation_frame({50, 0, 0}), 0, 0});
      }
      auto bvh   = scene_bvh{};
      auto error = std::string{};
      ASSERT_TRUE(make_scene_bvh(bvh, scene, {}, error)) << error;
      auto what  = std::string(curves ? "curves" : "lines") + (instanced ? " instanced" : "");
      auto world = [&](const vec3f& point) { return transform_point(frame, point); };
      auto along = [&](const vec3f& direction) { return transform_direction(frame, direction); };
      // From a's axis down, out through a's wall: nothing else is there.
      auto down = ray3f{world({0.3f, 0, 0}), along({0, 0, -1})};
      EXPECT_FALSE(intersect_scene_bvh(bvh, down).hit) << what;
      EXPECT_FALSE(intersect_scene_bvh_any(bvh, down)) << what;
      // From a's axis up: a's wall is passed, b (axis 0.12 up, radius 0.1)
      // is met from outside, 0.02 away.
      auto up  = ray3f{world({0, 0, 0}), along({0, 0, 1})};
      auto hit = intersect_scene_bvh(bvh, up);
      ASSERT_TRUE(hit.hit) << what;
      EXPECT_EQ(hit.instance, 1) << what;
      EXPECT_NEAR(hit.distance, 0.02f, 1e-3f) << what;
      EXPECT_TRUE(intersect_scene_bvh_any(bvh, up)) << what;
      // From inside both, sideways: out of both without a hit.
      for (auto direction : {vec3f{1, 1, 0}, vec3f{1, -1, 0.2f}, vec3f{0, 0, -1}}) {
        auto out = ray3f{world({0.01f, 0.02f, 0.06f}), along(normalize(direction))};
        EXPECT_FALSE(intersect_scene_bvh(bvh, out).hit) << what;
        EXPECT_FALSE(intersect_scene_bvh_any(bvh, out)) << what;
      }
      // From outside, a and b are hit as before.
      auto from_below = ray3f{world({0.3f, 0, -1}), along({0, 0, 1})};
      hit             = intersect_scene_bvh(bvh, from_below);
      ASSERT_TRUE(hit.hit) << what;
      EXPECT_EQ(hit.instance, 0) << what;
      EXPECT_NEAR(hit.distance, 0.9f, 1e-3f) << what;
    }
  }
}

// A fibre of radius 0.08 as lines (two straight segments), one straight
// Bezier, or one bent Bezier (an arch, split into pieces for Embree).
enum struct fiber_kind { lines, straight_bezier, bent_bezier };
static const char* fiber_kind_names[] = {"lines", "straight Bezier", "bent Bezier"};
static scene_data make_fiber_kind_scene(fiber_kind kind, bool instanced) {
  // Instanced: turned, scaled by a half, and shared with a far copy.
  auto frame = instanced ? translation_frame({0.5f, 1, -2}) *
                               rotation_frame({0.2f, 1, 0.3f}, 0.9f) *
                               scaling_frame({0.5f, 0.5f, 0.5f})
                         : identity3x4f;
  auto scene = make_straight_fiber_scene(kind != fiber_kind::lines, 0.08f, frame);
  if (kind == fiber_kind::bent_bezier) {  // the arch: inner control points lifted
    scene.shapes[0].positions[1].y = 1;
    scene.shapes[0].positions[2].y = 1;
  }
  if (instanced) scene.instances.push_back({translation_frame({50, 0, 0}), 0, 0});
  return scene;
}

// Each fibre of the tests below: every kind, round and flat, direct and
// instanced, with its BVH and a name for messages.
struct fiber_case {
  fiber_kind  kind  = fiber_kind::lines;
  bool        flat  = false;
  scene_data  scene = {};
  scene_bvh   bvh   = {};
  std::string what  = "";
};
static void for_each_fiber_case(const std::function<void(const fiber_case&)>& test) {
  for (auto kind : {fiber_kind::lines, fiber_kind::straight_bezier, fiber_kind::bent_bezier}) {
    for (auto flat : {false, true}) {
      for (auto instanced : {false, true}) {
        auto fiber = fiber_case{kind, flat, make_fiber_kind_scene(kind, instanced)};
        auto error = std::string{};
        fiber.what = std::string(fiber_kind_names[(int)kind]) + (flat ? " flat" : " round") +
                     (instanced ? " instanced" : "");
        ASSERT_TRUE(make_scene_bvh(fiber.bvh, fiber.scene, {flat}, error)) << error;
        test(fiber);
      }
    }
  }
}

// The fibre's axis at u along the whole strand (0 to 1), in world space.
static vec3f eval_strand_axis(const scene_data& scene, float u) {
  auto& shape = scene.shapes[0];
  auto& p     = shape.positions;
  auto  local = shape.lines.empty()
                    ? eval_bezier(p[0], p[1], p[2], p[3], u)
                    : (u < 0.5f ? p[0] + (p[1] - p[0]) * (2 * u) : p[1] + (p[2] - p[1]) * (2 * u - 1));
  return transform_point(scene.instances[0].frame, local);
}

// Distance from a point to the fibre's axis, by dense search along it.
static float distance_to_axis(const scene_data& scene, const vec3f& point) {
  auto best = flt_max, best_u = 0.0f;
  for (auto i = 0; i <= 4000; i++) {
    auto d = distance(point, eval_strand_axis(scene, i / 4000.0f));
    if (d < best) best = d, best_u = i / 4000.0f;
  }
  // Ternary refinement within one step on each side (the distance is
  // unimodal there).
  auto a = std::max(best_u - 1 / 4000.0f, 0.0f), b = std::min(best_u + 1 / 4000.0f, 1.0f);
  for (auto k = 0; k < 60; k++) {
    auto m1 = a + (b - a) / 3, m2 = b - (b - a) / 3;
    if (distance(point, eval_strand_axis(scene, m1)) < distance(point, eval_strand_axis(scene, m2)))
      b = m2;
    else
      a = m1;
  }
  return std::min(best, distance(point, eval_strand_axis(scene, (a + b) / 2)));
}

// A strand's ends are closed by discs across its tangent: a fibre seen
// along its axis from either end, round or flat, lines or Beziers, instanced
// or not, shows its whole cap (lines: maybe the half sphere Embree adds).
// Without the caps, Embree's round curves miss every ray parallel to the
// axis (the hole of issue 14), and its flat Beziers most of them.
TEST(bvh, fibre_ends_are_closed_by_caps) {
  for_each_fiber_case([](const fiber_case& test_case) {
    auto& [kind, flat, scene, bvh, what] = test_case;
    auto& shape  = scene.shapes[0];
    auto& frame  = scene.instances[0].frame;
    auto  radius = 0.08f * frame_scale(frame);
    for (auto end = 0; end < 2; end++) {
      // The end point and the outward tangent there, in world space.
      auto& p       = shape.positions;
      auto  last    = (int)p.size() - 1;
      auto  center  = transform_point(frame, end ? p[last] : p[0]);
      auto  outward = normalize(transform_direction(
          frame, end ? p[last] - p[last - 1] : p[0] - p[1]));
      // A pinhole 3 away on the axis; rays through a grid of points of
      // the end plane, those within the cap's disc must hit it there.
      auto basis = basis_fromz(outward);
      auto eye = center + outward * 3.0f, side = basis[0], up = basis[1];
      auto inside = 0, hits = 0;
      for (auto i = 0; i < 41; i++) {
        for (auto j = 0; j < 41; j++) {
          auto x = (i / 20.0f - 1) * radius, y = (j / 20.0f - 1) * radius;
          if (x * x + y * y > radius * radius * 0.995f) continue;
          auto target = center + side * x + up * y;
          auto ray    = ray3f{eye, normalize(target - eye)};
          auto hit    = intersect_scene_bvh(bvh, ray);
          inside++;
          if (!hit.hit) continue;
          hits++;
          // On the disc; for lines, maybe on the half sphere Embree puts
          // around a line's end, up to a radius before it.
          auto disc = distance(eye, target);
          EXPECT_LE(hit.distance, disc + 1e-4f) << what;
          EXPECT_GE(hit.distance, kind == fiber_kind::lines ? disc - radius * 1.001f
                                                            : disc - 1e-4f)
              << what;
          EXPECT_EQ(hit.instance, 0) << what;
          EXPECT_EQ(hit.element, end ? (int)(shape.lines.size() + shape.curves.size()) - 1 : 0)
              << what;
          EXPECT_EQ(hit.uv.x, (float)end) << what;
          EXPECT_TRUE(intersect_scene_bvh_any(bvh, ray)) << what;
          auto fiber = eval_fiber_point(
              scene, scene.instances[0], hit.element, hit.uv.x, ray, hit.distance);
          EXPECT_NEAR(distance(fiber.axis, center), 0, 1e-3f * radius) << what;
          EXPECT_LE(std::abs(fiber.h), 1) << what;
          EXPECT_NEAR(std::abs(dot(fiber.tangent, outward)), 1, 1e-5f) << what;
        }
      }
      EXPECT_EQ(hits, inside) << what << (end ? " end" : " start");
    }
  });
}

// Strand ends meet by position: a strand written with a vertex copy per
// segment is capped at its two ends, not at its joints, where a disc would
// stop a ray that runs inside the fibre (as rays starting inside an
// overlapping neighbour do). Lines and Beziers, round and flat.
TEST(bvh, strands_with_a_vertex_copy_per_segment_are_capped_at_their_ends_only) {
  for (auto curves : {false, true}) {
    for (auto flat : {false, true}) {
      auto shape = shape_data{};
      for (auto segment = 0; segment < 3; segment++) {
        auto start = (int)shape.positions.size();
        auto x0 = -1.5f + segment, x1 = x0 + 1;
        if (curves) {
          for (auto k = 0; k < 4; k++) shape.positions.push_back({x0 + (x1 - x0) * k / 3, 0, 0});
          shape.curves.push_back({start, start + 1, start + 2, start + 3});
        } else {
          shape.positions.push_back({x0, 0, 0});
          shape.positions.push_back({x1, 0, 0});
          shape.lines.push_back({start, start + 1});
        }
      }
      shape.radius.assign(shape.positions.size(), 0.1f);
      auto scene = scene_data{};
      scene.shapes.push_back(shape);
      scene.materials.push_back({});
      scene.instances.push_back({identity3x4f, 0, 0});
      auto bvh   = scene_bvh{};
      auto error = std::string{};
      ASSERT_TRUE(make_scene_bvh(bvh, scene, {flat}, error)) << error;
      auto what = std::string(curves ? "curves" : "lines") + (flat ? " flat" : " round");
      // Along the axis from inside: through both joints, out of the end
      // (round fibres: a flat one has no inside, its ribbon faces the ray).
      for (auto direction : {vec3f{1, 0, 0}, vec3f{-1, 0, 0}}) {
        if (flat) continue;
        auto inside = ray3f{{0, 0.02f, 0.03f}, direction};
        EXPECT_FALSE(intersect_scene_bvh(bvh, inside).hit) << what;
        EXPECT_FALSE(intersect_scene_bvh_any(bvh, inside)) << what;
      }
      // Along the axis from outside: the end's cap, on the end segment.
      for (auto end = 0; end < 2; end++) {
        auto ray = ray3f{{end ? 4.0f : -4.0f, 0.02f, 0.03f}, {end ? -1.0f : 1.0f, 0, 0}};
        auto hit = intersect_scene_bvh(bvh, ray);
        ASSERT_TRUE(hit.hit) << what;
        EXPECT_NEAR(hit.distance, 2.5f, 0.1f) << what;
        EXPECT_EQ(hit.element, end ? 2 : 0) << what;
        EXPECT_EQ(hit.uv.x, (float)end) << what;
      }
    }
  }
}

// A ray leaving a fibre (spawn_fiber_ray, as the path tracer spawns it)
// never hits the fibre's own surface: from hits on its side and on its caps,
// in random directions, at grazing directions along the fibre and across
// its surface, and through it (transmitted), for round and flat fibres,
// lines and Beziers, instanced or not. A straight fibre is convex, so any
// hit is a self-hit; a bent one may be met again elsewhere, and every such
// hit must be a true one: on the surface, with the ray outside the fibre
// before it.
TEST(bvh, rays_leaving_a_fibre_miss_its_own_surface) {
  auto rng = make_rng(91);
  for_each_fiber_case([&rng](const fiber_case& test_case) {
    auto& [kind, flat, scene, bvh, what] = test_case;
    auto radius = 0.08f * frame_scale(scene.instances[0].frame);
    // Rays at the fibre: at points along it from random sides, and at
    // its ends along its tangent (cap hits).
    auto rays = std::vector<ray3f>{};
    for (auto u : {0.0f, 0.01f, 0.3f, 0.5f, 0.77f, 0.99f, 1.0f}) {
      auto axis    = eval_strand_axis(scene, u);
      auto tangent = normalize(eval_strand_axis(scene, std::min(u + 1e-3f, 1.0f)) -
                               eval_strand_axis(scene, std::max(u - 1e-3f, 0.0f)));
      if (u == 0 || u == 1) {
        auto outward = u == 0 ? -tangent : tangent;
        for (auto k = 0; k < 4; k++) {
          auto offset = (rand1f(rng) - 0.5f) * radius * sample_sphere(rand2f(rng));
          rays.push_back({axis + outward * 2.0f + offset, -outward});
        }
        continue;
      }
      for (auto k = 0; k < 6; k++) {
        auto from = sample_sphere(rand2f(rng));
        rays.push_back({axis + from * 2.0f, -from});
      }
    }
    auto tested = 0;
    for (auto& ray : rays) {
      auto hit = intersect_scene_bvh(bvh, ray);
      if (!hit.hit || hit.instance != 0) continue;
      auto fiber = eval_fiber_point(
          scene, scene.instances[0], hit.element, hit.uv.x, ray, hit.distance);
      auto t = fiber.tangent, n = fiber.normal, b = normalize(cross(t, n));
      auto directions = std::vector<vec3f>{};
      for (auto k = 0; k < 16; k++) directions.push_back(sample_sphere(rand2f(rng)));
      for (auto sign : {-1.0f, 1.0f}) {
        // Along the fibre, exactly and almost.
        for (auto tilt : {0.0f, 1e-5f, 1e-3f, 3e-2f})
          for (auto across : {n, -n, b})
            directions.push_back(normalize(sign * t + tilt * across));
        // Across the surface, in its tangent plane and just off it.
        for (auto phi : {0.0f, 0.5f, 1.2f, pif / 2})
          for (auto off : {0.0f, 1e-3f, -1e-3f})
            directions.push_back(
                normalize(std::cos(phi) * sign * t + std::sin(phi) * b + off * n));
        // Through the fibre, as transmitted light leaves it.
        for (auto theta : {0.0f, 0.3f, 1.0f, 1.5f})
          directions.push_back(normalize(-n * std::cos(theta) + sign * t * std::sin(theta)));
      }
      for (auto& direction : directions) {
        auto spawned = spawn_fiber_ray(fiber.axis, fiber.tangent, fiber.radius, n, direction);
        auto again   = intersect_scene_bvh(bvh, spawned);
        tested++;
        if (kind != fiber_kind::bent_bezier) {
          EXPECT_FALSE(again.hit) << what << ": a spawned ray hit its fibre at "
                                  << again.distance;
          EXPECT_FALSE(intersect_scene_bvh_any(bvh, spawned)) << what;
          continue;
        }
        if (!again.hit) continue;
        // A true hit on the bent fibre: on its surface (round) or
        // within its radius (flat), and outside before it.
        auto point = spawned.o + spawned.d * again.distance;
        auto gap   = distance_to_axis(scene, point) - radius;
        if (flat) {
          // Embree draws flat curves as ray-facing quads, a little off
          // the curve (0.5% of the radius is seen here).
          EXPECT_LE(gap, 1e-2f * radius) << what << " at " << again.distance;
        } else {
          EXPECT_NEAR(gap, 0, 2e-3f * radius) << what << " at " << again.distance;
          auto halfway = spawned.o + spawned.d * (again.distance / 2);
          EXPECT_GE(distance_to_axis(scene, halfway), radius) << what;
        }
      }
    }
    EXPECT_GE(tested, 1500) << what;
  });
}

// Rays Embree would abort on (origin or direction beyond its range, NaN or
// zero directions) are misses for closest hits and occluded for shadow rays.
TEST(bvh, untraceable_rays_are_refused_not_aborted) {
  auto scene = make_straight_fiber_scene(false, 0.1f, identity3x4f);
  auto bvh   = scene_bvh{};
  auto error = std::string{};
  ASSERT_TRUE(make_scene_bvh(bvh, scene, {}, error)) << error;
  auto nan = std::nanf("");
  for (auto ray : {ray3f{{1e19f, 0, 3}, {0, 0, -1}}, ray3f{{0, 0, 3}, {0, 0, -3e38f}},
           ray3f{{0, 0, 3}, {nan, 0, -1}}, ray3f{{0, 0, 3}, {0, 0, 0}},
           ray3f{{0, 0, 3}, {0, 0, -1}, nan}}) {
    EXPECT_FALSE(is_traceable_ray(ray));
    EXPECT_FALSE(intersect_scene_bvh(bvh, ray).hit);
    EXPECT_TRUE(intersect_scene_bvh_any(bvh, ray));
  }
  EXPECT_TRUE(is_traceable_ray({{1e18f, 0, 3}, {0, 0, -1}}));
}

// Scenes whose rays or geometry leave the range the ray tracer accepts are
// refused by validation, naming the element and the value.
TEST(scene, validation_refuses_what_the_ray_tracer_cannot_trace) {
  auto scene = make_straight_fiber_scene(false, 0.1f, identity3x4f);
  auto error = std::string{};
  scene.cameras.push_back({});
  scene.camera_names.push_back("cam");
  ASSERT_TRUE(validate_scene(scene, error)) << error;
  auto expect_refused = [&](const scene_data& bad, const std::vector<std::string>& parts) {
    auto message = std::string{};
    EXPECT_FALSE(validate_scene(bad, message));
    for (auto& part : parts)
      EXPECT_NE(message.find(part), std::string::npos) << message << "\nlacks: " << part;
  };
  auto far = scene;
  far.cameras[0].frame.o = {1e19f, 0, 0};
  expect_refused(far, {"camera \"cam\"", "position 1e+19", "outside the range"});
  auto cameras = std::vector<std::pair<camera_data, std::string>>{};
  auto camera = camera_data{};
  camera.lens = 1e-45f;
  cameras.push_back({camera, "lens 1.4013e-45"});
  camera = {};
  camera.aperture = 3e38f;
  cameras.push_back({camera, "aperture 3e+38"});
  camera = {};
  camera.film = 3e38f;
  cameras.push_back({camera, "film 3e+38"});
  camera = {};
  camera.focus = 3e38f, camera.aperture = 0.1f;
  cameras.push_back({camera, "focus 3e+38"});
  camera = {};
  camera.orthographic = true, camera.focus = 1e30f;
  cameras.push_back({camera, "focus 1e+30"});
  for (auto& [bad_camera, part] : cameras) {
    auto bad = scene;
    bad.cameras[0] = bad_camera;
    expect_refused(bad, {"camera \"cam\"", part, "cannot trace"});
  }
  auto vertex = scene;
  vertex.shapes[0].positions[1].y = -1e19f;
  expect_refused(vertex, {"vertex 1", "position -1e+19"});
  auto radius = scene;
  radius.shapes[0].radius[0] = 1e19f;
  expect_refused(radius, {"vertex 0", "radius 1e+19"});
  auto placed = scene;
  placed.instances[0].frame = translation_frame({0, 2e16f, 0});
  expect_refused(placed, {"instance 0", "2e+16"});
  auto light = scene;
  light.distant_lights.push_back({{3e38f, 3e38f, 0}, {1, 1, 1}});
  expect_refused(light, {"distant light 0", "direction"});
  light.distant_lights[0].direction = {0, 0, 0};
  expect_refused(light, {"distant light 0", "direction [0 0 0]"});
}

// A ray at a random point of the box from `corner` spanning `size`, from a
// random direction 3 units away.
static ray3f random_ray_into_box(rng_state& rng, const vec3f& corner, const vec3f& size) {
  auto target = corner + rand3f(rng) * size;
  auto origin = target + sample_sphere(rand2f(rng)) * 3.0f;
  return {origin, normalize(target - origin)};
}
// Do two BVHs' answers agree: both miss, or both hit the same instance and
// element at the same parameter (within 1e-3) and distance (within 1e-4)?
static bool same_hit(const scene_intersection& a, const scene_intersection& b) {
  if (a.hit != b.hit) return false;
  return !a.hit || (a.instance == b.instance && a.element == b.element &&
                       std::abs(a.uv.x - b.uv.x) <= 1e-3f &&
                       std::abs(a.distance - b.distance) <= 1e-4f);
}

TEST(bvh, bent_curves_split_into_exact_pieces_hit_like_whole_ones) {
  // Helical strands of Bezier segments (quarter turns, radius 0.02 against a
  // helix of radius 0.3) are given to Embree in pieces (max_curve_pieces 4)
  // and straight ones are not; 20,000 random rays from a box around them hit
  // the same segment at the same parameter and distance as with whole
  // segments, directly and through an instance (two instances share the
  // shape). Rays grazing an edge may differ by float rounding: at most 0.2%
  // of them may disagree.
  auto scene = scene_data{};
  auto helix = std::vector<vec3f>{};
  for (auto k = 0; k < 12; k++) {
    auto a = k * pif / 2;
    helix.push_back({0.3f * std::cos(a), 0.1f * k, 0.3f * std::sin(a)});
  }
  auto curly = shape_data{};
  append_catmull_rom_strand(curly, helix, std::vector<float>(helix.size(), 0.02f));
  auto straight = shape_data{};
  append_catmull_rom_strand(straight, {{1, 0, 0}, {1, 0.5f, 0}, {1, 1, 0}, {1, 1.5f, 0}},
      {0.02f, 0.02f, 0.02f, 0.02f});
  scene.shapes = {curly, straight};
  scene.materials.push_back({});
  scene.instances.push_back({identity3x4f, 0, 0});
  scene.instances.push_back({identity3x4f, 1, 0});
  for (auto instanced : {false, true}) {
    if (instanced) scene.instances.push_back({translation_frame({0, 0, 2}), 0, 0});
    auto whole_params = bvh_params{}, split_params = bvh_params{};
    whole_params.max_curve_pieces = 1;
    split_params.max_curve_pieces = 4;
    auto whole = scene_bvh{}, split = scene_bvh{};
    auto error = std::string{};
    ASSERT_TRUE(make_scene_bvh(whole, scene, whole_params, error)) << error;
    ASSERT_TRUE(make_scene_bvh(split, scene, split_params, error)) << error;
    EXPECT_TRUE(whole.pieces[0].pieces.empty());
    EXPECT_GT(split.pieces[0].pieces.size(), curly.curves.size());
    EXPECT_TRUE(split.pieces[1].pieces.empty());  // straight: not split
    auto rng = make_rng(17);
    auto hits = 0, disagree = 0;
    for (auto i = 0; i < 20000; i++) {
      auto ray = random_ray_into_box(
          rng, {-0.4f, -0.1f, -0.4f}, {1.6f, 1.5f, 0.8f + 2 * instanced});
      auto a = intersect_scene_bvh(whole, ray), b = intersect_scene_bvh(split, ray);
      hits += a.hit;
      if (!same_hit(a, b)) disagree++;
    }
    EXPECT_GT(hits, 500);
    EXPECT_LE(disagree, 40) << "of " << hits << " hits";
  }
}

// Packed strands of one length have their curves' first vertices computed
// (fiber_strand_segments); strands of different lengths keep them stored.
// Either way every curve's four vertices are the unpacked shape's.
TEST(geometry, packed_strands_compute_or_store_their_first_vertices) {
  for (auto lengths : {std::vector<int>{4, 4, 4}, std::vector<int>{4, 6, 3}}) {
    auto shape = shape_data{};
    for (auto s = 0; s < (int)lengths.size(); s++) {
      auto points = std::vector<vec3f>{};
      for (auto k = 0; k < lengths[s]; k++) points.push_back({(float)s, 0.1f * k * k, 0.2f * k});
      append_catmull_rom_strand(shape, points, std::vector<float>(points.size(), 0.01f));
    }
    auto packed = shape;
    pack_fiber_vertices(packed);
    auto same = lengths[0] == lengths[1] && lengths[1] == lengths[2];
    EXPECT_EQ(packed.fiber_strand_segments, same ? lengths[0] - 1 : 0);
    ASSERT_EQ(num_curves(packed), (int)shape.curves.size());
    for (auto i = 0; i < num_curves(packed); i++)
      EXPECT_EQ(curve_vertices(packed, i), shape.curves[i]);
    unpack_fiber_vertices(packed);
    EXPECT_EQ(packed.fiber_strand_segments, 0);
    EXPECT_EQ(packed.curves, shape.curves);
  }
}

// Straight Bezier segments (strands along lines, tapered or with uneven
// steps between their Catmull-Rom points, so that the parameter's speed
// varies along a segment) are given to
// Embree as cones (bvh_params::straight_cones); a strand that is straight,
// then bent, gets cones for its straight part and Bezier pieces for the rest.
// 20,000 random rays from a box around them, directly and through a rigid
// instance, hit the same segment at the same parameter, distance and offset
// h as with Bezier curves; rays grazing an edge may differ by float rounding:
// at most 0.2% of them may disagree. A scaled instance keeps its shape's
// curves (Embree's cones need directions of unit length), and a ray's
// direction may have any length.
TEST(bvh, straight_segments_as_cones_hit_like_bezier_curves) {
  auto scene    = scene_data{};
  auto straight = shape_data{}, mixed = shape_data{};
  auto rng      = make_rng(29);
  for (auto strand = 0; strand < 12; strand++) {
    auto root = rand3f(rng) * 0.6f, along = sample_sphere(rand2f(rng));
    auto points = std::vector<vec3f>{};
    auto radii  = std::vector<float>{};
    // Even steps with a taper, or uneven steps (a parameter of uneven speed
    // in every segment) of one radius: either way a radius affine along
    // the line.
    auto even = strand % 2 == 0;
    for (auto k = 0, step = 0; k < 5; k++, step += even ? 3 : 1 + k % 3) {
      points.push_back(root + along * (0.05f * step));
      radii.push_back(even ? 0.03f - 0.005f * k : 0.02f);
    }
    append_catmull_rom_strand(straight, points, radii);
  }
  // Straight along x for four points, then a quarter circle.
  auto bent = std::vector<vec3f>{{0, 0.8f, 0}, {0.2f, 0.8f, 0}, {0.4f, 0.8f, 0},
      {0.6f, 0.8f, 0}, {0.8f, 0.8f, 0}};
  for (auto k = 1; k <= 4; k++)
    bent.push_back({0.8f + 0.3f * std::sin(k * pif / 8), 1.1f - 0.3f * std::cos(k * pif / 8), 0});
  append_catmull_rom_strand(mixed, bent, std::vector<float>(bent.size(), 0.025f));
  scene.shapes = {straight, mixed};
  scene.materials.push_back({});
  scene.instances.push_back({identity3x4f, 0, 0});
  scene.instances.push_back({identity3x4f, 1, 0});
  auto turned = translation_frame({0, 0, 1.5f}) * rotation_frame({0.3f, 1, 0.2f}, 0.7f);
  for (auto instanced : {false, true}) {
    if (instanced) scene.instances.push_back({turned, 0, 0});
    auto curves_params = bvh_params{}, cones_params = bvh_params{};
    curves_params.straight_cones = false;
    auto curves = scene_bvh{}, cones = scene_bvh{};
    auto error  = std::string{};
    ASSERT_TRUE(make_scene_bvh(curves, scene, curves_params, error)) << error;
    ASSERT_TRUE(make_scene_bvh(cones, scene, cones_params, error)) << error;
    EXPECT_TRUE(curves.pieces[0].cones.empty());
    // Where uneven steps put an inner control point past the segment's end
    // (the curve overshoots and turns back), the segment stays a curve.
    EXPECT_GE(cones.pieces[0].cones.size(), straight.curves.size() * 3 / 4);
    EXPECT_EQ(cones.pieces[0].cones.size() + cones.pieces[0].pieces.size(),
        straight.curves.size());
    EXPECT_EQ(cones.pieces[1].cones.size(), 3u);  // the straight run, not its joint to the bend
    EXPECT_FALSE(cones.pieces[1].pieces.empty());
    auto hits = 0, disagree = 0;
    for (auto i = 0; i < 20000; i++) {
      auto ray = random_ray_into_box(
          rng, {-0.5f, -0.5f, -0.5f}, {1.8f, 1.8f, 1.6f + 1.5f * instanced});
      auto a = intersect_scene_bvh(curves, ray), b = intersect_scene_bvh(cones, ray);
      hits += a.hit;
      auto same = same_hit(a, b);
      if (same && a.hit) {
        auto& instance = scene.instances[a.instance];
        auto  fa = eval_fiber_point(scene, instance, a.element, a.uv.x, ray, a.distance);
        auto  fb = eval_fiber_point(scene, instance, b.element, b.uv.x, ray, b.distance);
        same = same && std::abs(fa.h - fb.h) <= 2e-3f &&
               std::abs(fa.radius - fb.radius) <= 1e-4f * fa.radius + 1e-7f;
      }
      if (!same) disagree++;
      // The same ray with a direction three times as long.
      auto longer = intersect_scene_bvh(cones, ray3f{ray.o, ray.d * 3.0f});
      EXPECT_EQ(longer.hit, b.hit);
      if (longer.hit && b.hit) EXPECT_NEAR(longer.distance * 3, b.distance, 1e-4f);
    }
    EXPECT_GT(hits, 1500);
    EXPECT_LE(disagree, 40) << "of " << hits << " hits";
    std::printf("[ figure ] cones against Bezier curves%s: %d of %d hits disagree\n",
        instanced ? " (instanced)" : "", disagree, hits);
  }
  // A scaled instance of the straight shape: no cones for it.
  scene.instances.push_back({scaling_frame({0.5f, 0.5f, 0.5f}), 0, 0});
  auto scaled = scene_bvh{};
  auto error  = std::string{};
  ASSERT_TRUE(make_scene_bvh(scaled, scene, bvh_params{}, error)) << error;
  EXPECT_TRUE(scaled.pieces[0].cones.empty());
  EXPECT_FALSE(scaled.pieces[1].cones.empty());
}

// The cone's fraction along its chord maps back to the Bezier parameter: for
// 10,000 random inner fractions 0 <= a <= b <= 1 and parameters t, the
// cubic's value at the returned parameter is within 2e-6 of the fraction.
TEST(bvh, cone_fraction_maps_back_to_the_bezier_parameter) {
  auto rng   = make_rng(5);
  auto worst = 0.0f;
  for (auto i = 0; i < 10000; i++) {
    auto a = rand1f(rng), b = rand1f(rng);
    if (a > b) std::swap(a, b);
    if (i % 10 == 0) a = 0;  // a control point on an end: zero speed there
    auto cone     = bvh_cone{0, a, b};
    auto fraction = [&](float t) {
      auto w = 1 - t;
      return 3 * w * w * t * a + 3 * w * t * t * b + t * t * t;
    };
    auto t = rand1f(rng), u = fraction(t);
    auto back = cone_bezier_parameter(cone, u);
    ASSERT_TRUE(back >= 0 && back <= 1) << a << " " << b << " " << u;
    worst = std::max(worst, std::abs(fraction(back) - u));
  }
  EXPECT_LE(worst, 2e-6f);
  EXPECT_EQ(cone_bezier_parameter({}, 0.25f), 0.25f);  // a uniform parameter
  EXPECT_EQ(cone_bezier_parameter({}, -1.0f), 0.0f);
  EXPECT_EQ(cone_bezier_parameter({}, std::nanf("")), 0.0f);
  std::printf("[ figure ] cone fraction to Bezier parameter: worst error %.2g\n", worst);
}

// The memory budget of a BVH (bvh_params::max_bytes; --max-memory in
// yscene): Embree's allocations beyond it are refused before they are made,
// and the build fails with over_budget and a message, never a crash (also
// under the sanitizers in CI). A curly groom: 4 curve pieces need about three
// times the bytes of 1, so a budget of twice the 1-piece BVH refuses 4
// pieces and takes 1; 1 KiB refuses everything, compact layout included.
TEST(geometry, bvh_memory_budget_refuses_and_fails_cleanly) {
  auto style    = hair_style_params{};
  style.style   = hair_style::curly;
  style.strands = 2000;
  auto scene    = make_hair_scene(style, hair_material{});
  auto error    = std::string{};
  auto bytes    = [&](int pieces) {
    auto bvh    = scene_bvh{};
    auto params = bvh_params{};
    params.max_curve_pieces = pieces;
    EXPECT_TRUE(make_scene_bvh(bvh, scene, params, error)) << error;
    return (double)bvh.peak_memory;
  };
  auto one = bytes(1), four = bytes(4);
  std::printf("[ figure ] BVH bytes: 1 piece %.0f, 4 pieces %.0f\n", one, four);
  ASSERT_GT(four, 2.5 * one);
  auto build = [&](int pieces, bool compact, double budget) {
    auto bvh    = scene_bvh{};
    auto params = bvh_params{};
    params.max_curve_pieces = pieces;
    params.compact          = compact;
    params.max_bytes        = budget;
    auto built = make_scene_bvh(bvh, scene, params, error);
    EXPECT_EQ(bvh.over_budget, !built);
    return built;
  };
  EXPECT_FALSE(build(4, false, 2 * one));
  EXPECT_NE(error.find("memory budget"), std::string::npos) << error;
  EXPECT_TRUE(build(1, false, 2 * one)) << error;
  for (auto compact : {false, true}) {
    EXPECT_FALSE(build(1, compact, 1024));
    EXPECT_NE(error.find("memory budget of 1024 bytes"), std::string::npos) << error;
  }
}

// The curve pieces are planned before the build (plan_curve_pieces): none
// for a straight strand, none when the rays of the render do not repay the
// pieces' build (fewer than 9 a segment), all for a long render; within a
// budget, the most bent segments only, and the build then keeps within it
// (its peak, the build's temporaries included) and gives Embree the
// planned number of curves. A curly groom of 2,000 strands (48,000 bent
// segments).
TEST(geometry, curve_pieces_are_planned_from_rays_and_budget) {
  auto style    = hair_style_params{};
  style.strands = 2000;
  style.style   = hair_style::curly;
  auto curly    = make_hair_scene(style, hair_material{});
  auto straight = scene_data{};
  straight.shapes.emplace_back();
  append_catmull_rom_strand(straight.shapes[0], {{1, 0, 0}, {1, 0.5f, 0}, {1, 1, 0}, {1, 1.5f, 0}},
      {0.02f, 0.02f, 0.02f, 0.02f});
  straight.instances.push_back({identity3x4f, 0, 0});
  auto params   = bvh_params{};
  auto plan     = plan_curve_pieces(straight, params, 1e12, 0);
  EXPECT_EQ(plan.max_pieces, 1);
  auto segments = (double)curly.shapes[0].curves.size();
  plan          = plan_curve_pieces(curly, params, 8 * segments, 0);
  EXPECT_EQ(plan.segments, (int64_t)segments);
  EXPECT_FALSE(plan.pays);
  EXPECT_EQ(plan.max_pieces, 1);
  EXPECT_EQ(plan.pieces, plan.segments);
  auto full = plan_curve_pieces(curly, params, 10 * segments, 0);
  EXPECT_TRUE(full.pays);
  EXPECT_EQ(full.max_pieces, 4);
  EXPECT_EQ(full.threshold, 1.0f);
  EXPECT_GT(full.pieces, (int64_t)(1.5 * segments));
  // Built as planned: Embree gets the planned curves.
  auto build = [&](const scene_data& scene, const bvh_piece_plan& plan, double budget) {
    auto bvh       = scene_bvh{};
    auto error     = std::string{};
    params.max_curve_pieces      = plan.max_pieces;
    params.curve_piece_threshold = plan.threshold;
    params.max_bytes             = budget;
    EXPECT_TRUE(make_scene_bvh(bvh, scene, params, error)) << error;
    auto pieces = bvh.pieces[0].pieces.empty() ? segments : (double)bvh.pieces[0].pieces.size();
    EXPECT_EQ(pieces, (double)plan.pieces);
    return bvh;
  };
  auto whole_bvh = build(curly, plan, 0), full_bvh = build(curly, full, 0);
  // Half way between the two: fewer pieces, the most bent first, and the
  // build fits (the estimate errs on the side of the budget).
  params.max_curve_pieces      = 4;
  params.curve_piece_threshold = 1;
  auto budget = 0.5 * (whole_bvh.build_peak_memory + full_bvh.build_peak_memory);
  auto half   = plan_curve_pieces(curly, params, 1e12, budget);
  EXPECT_LE(half.bytes, budget);
  EXPECT_GT(half.threshold, 1.0f);
  EXPECT_GT(half.pieces, plan.pieces);
  EXPECT_LT(half.pieces, full.pieces);
  auto half_bvh = build(curly, half, budget);
  EXPECT_LE(half_bvh.build_peak_memory, budget);
  std::printf("[ figure ] planned pieces: %lld of %lld within %.0f bytes (built peak %lld)\n",
      (long long)half.pieces, (long long)full.pieces, budget,
      (long long)half_bvh.build_peak_memory);
  // Packed, the same budget: unsplit strands' vertices are read in place,
  // but split, every segment is pieces with vertices of their own, as
  // unpacked: the same plan (the plan once left the pieces' vertices out
  // for packed shapes, and planned more than fit).
  auto packed = curly;
  pack_fiber_vertices(packed);
  params.max_curve_pieces      = 4;
  params.curve_piece_threshold = 1;
  auto packed_half = plan_curve_pieces(packed, params, 1e12, budget);
  EXPECT_EQ(packed_half.pieces, half.pieces);
  EXPECT_EQ(packed_half.threshold, half.threshold);
  EXPECT_LE(packed_half.bytes, budget);
  auto packed_bvh = build(packed, packed_half, budget);
  EXPECT_LE(packed_bvh.build_peak_memory, budget);
  // A budget the unsplit BVH alone exceeds: no pieces.
  params.max_curve_pieces = 4;
  EXPECT_EQ(plan_curve_pieces(curly, params, 1e12, 1024).max_pieces, 1);
}

// A render packs its fibres (pack_fiber_vertices) so that Embree reads the
// scene's vertices and strands' first indices in place. Packed or not, a
// groom is the same scene: the same fingerprint, bounds and strands, and its
// BVH gives the same hits bit for bit (unsplit and in pieces; strands
// sharing their vertices, lines, and segments with a vertex copy each whose
// indices run backwards, which Embree still copies), for 3,000 rays;
// unsplit strands' BVH holds no copy of their vertices.
TEST(bvh, packed_fibres_hit_and_shade_like_unpacked_ones) {
  auto style    = hair_style_params{};
  style.strands = 300;
  style.style   = hair_style::curly;
  auto groom    = make_hair_scene(style, hair_material{});
  auto hair     = -1;
  for (auto i = 0; i < (int)groom.shapes.size(); i++)
    if (!groom.shapes[i].curves.empty()) hair = i;
  ASSERT_GE(hair, 0);
  auto kinds = std::vector<std::pair<std::string, scene_data>>{{"strands", groom}};
  kinds.push_back({"lines", groom});
  kinds.back().second.shapes[hair] = curves_to_lines(groom.shapes[hair], 3);
  // A vertex copy per segment, indexed backwards (the same curve): the
  // indices are not consecutive, and stay as they are.
  kinds.push_back({"copied", groom});
  auto& copied = kinds.back().second.shapes[hair];
  copied       = {};
  for (auto& c : groom.shapes[hair].curves) {
    auto base = (int)copied.positions.size();
    for (auto k = 0; k < 4; k++) {
      copied.positions.push_back(groom.shapes[hair].positions[c[k]]);
      copied.radius.push_back(groom.shapes[hair].radius[c[k]]);
    }
    copied.curves.push_back({base + 3, base + 2, base + 1, base});
  }
  auto bounds = compute_bounds(groom);
  for (auto& [kind, scene] : kinds) {
    auto packed = scene;
    pack_fiber_vertices(packed);
    auto& shape = scene.shapes[hair];
    auto& fibre = packed.shapes[hair];
    EXPECT_TRUE(fibre.positions.empty() && fibre.radius.empty()) << kind;
    ASSERT_EQ(fibre.fiber_vertices.size(), shape.positions.size()) << kind;
    for (auto i = 0; i < num_vertices(shape); i++) {
      EXPECT_EQ(vertex_position(fibre, i), shape.positions[i]) << kind;
      EXPECT_EQ(vertex_radius(fibre, i), shape.radius[i]) << kind;
    }
    // Strands keep one index a segment; reversed curves and lines all four.
    EXPECT_EQ(fibre.curves.empty(), kind != "copied") << kind;
    EXPECT_EQ(fibre.fiber_curves.size(), kind == "strands" ? shape.curves.size() : 0) << kind;
    EXPECT_TRUE(is_fiber(fibre)) << kind;
    ASSERT_EQ(num_curves(fibre), (int)shape.curves.size()) << kind;
    for (auto i = 0; i < num_curves(shape); i++)
      EXPECT_EQ(curve_vertices(fibre, i), shape.curves[i]) << kind;
    EXPECT_EQ(fingerprint_scene(packed), fingerprint_scene(scene)) << kind;
    EXPECT_EQ(shape_memory(fibre) + (kind == "strands" ? 12.0 * shape.curves.size() : 0.0),
        shape_memory(shape))
        << kind;
    auto a = compute_bounds(scene), b = compute_bounds(packed);
    EXPECT_TRUE(a.min == b.min && a.max == b.max) << kind;
    auto strands = make_fiber_strands(shape), packed_strands = make_fiber_strands(fibre);
    EXPECT_EQ(strands.strand, packed_strands.strand) << kind;
    EXPECT_EQ(strands.u, packed_strands.u) << kind;
    EXPECT_EQ(strands.random, packed_strands.random) << kind;
    // Packing twice, or a triangle shape, changes nothing.
    auto again = packed;
    pack_fiber_vertices(again);
    EXPECT_EQ(again.shapes[hair].fiber_vertices, fibre.fiber_vertices) << kind;
    for (auto i = 0; i < (int)packed.shapes.size(); i++)
      if (i != hair) EXPECT_TRUE(packed.shapes[i].fiber_vertices.empty()) << kind;
    // Unpacked, the shape as it was; saved packed, the same PLY bytes.
    auto plain = fibre;
    unpack_fiber_vertices(plain);
    EXPECT_TRUE(plain.fiber_vertices.empty() && plain.fiber_curves.empty()) << kind;
    EXPECT_EQ(plain.positions, shape.positions) << kind;
    EXPECT_EQ(plain.radius, shape.radius) << kind;
    EXPECT_EQ(plain.curves, shape.curves) << kind;
    EXPECT_EQ(plain.lines, shape.lines) << kind;
    auto bytes = std::string{}, packed_bytes = std::string{}, save_error = std::string{};
    ASSERT_TRUE(encode_shape("plain.ply", shape, bytes, save_error)) << save_error;
    ASSERT_TRUE(encode_shape("packed.ply", fibre, packed_bytes, save_error)) << save_error;
    EXPECT_TRUE(packed_bytes == bytes) << kind;
    // Validated packed as unpacked; a strand past the last vertex fails.
    auto valid_error = std::string{};
    EXPECT_TRUE(validate_scene(packed, valid_error)) << kind << ": " << valid_error;
    if (kind == "strands") {
      auto broken = packed;
      broken.shapes[hair].fiber_curves.back() = num_vertices(fibre) - 3;
      EXPECT_FALSE(validate_scene(broken, valid_error));
      EXPECT_NE(valid_error.find("references vertex"), std::string::npos) << valid_error;
      // Strands of one length: first vertices computed, and checked against
      // the stored ones.
      EXPECT_GT(fibre.fiber_strand_segments, 0);
      auto shifted = packed;
      shifted.shapes[hair].fiber_strand_segments += 1;
      EXPECT_FALSE(validate_scene(shifted, valid_error));
      EXPECT_NE(valid_error.find("segments put it"), std::string::npos) << valid_error;
    }

    for (auto pieces : {1, 4}) {
      auto params             = bvh_params{};
      params.max_curve_pieces = pieces;
      // One build thread: Embree's per-thread blocks make its bytes vary.
      params.embree_config = "threads=1";
      auto bvh = scene_bvh{}, packed_bvh = scene_bvh{};
      auto error = std::string{};
      ASSERT_TRUE(make_scene_bvh(bvh, scene, params, error)) << error;
      ASSERT_TRUE(make_scene_bvh(packed_bvh, packed, params, error)) << error;
      auto what = kind + " pieces " + std::to_string(pieces);
      if (kind != "copied" && bvh.pieces[hair].pieces.empty()) {
        // Embree reads the packed strands in place: no float4 copy.
        auto copy = (double)sizeof(vec4f) * num_vertices(shape);
        EXPECT_GE((double)(bvh.peak_memory - packed_bvh.peak_memory), 0.99 * copy) << what;
      }
      // Rays from a sphere around the groom to points within its bounds.
      auto rng  = make_rng(17);
      auto hits = 0;
      for (auto r = 0; r < 3000; r++) {
        auto target = bounds.min + (bounds.max - bounds.min) * rand3f(rng);
        auto from   = sample_sphere(rand2f(rng)) * 2.0f * length(bounds.max - bounds.min) +
                      center(bounds);
        auto ray    = ray3f{from, normalize(target - from)};
        auto x = intersect_scene_bvh(bvh, ray), y = intersect_scene_bvh(packed_bvh, ray);
        ASSERT_EQ(x.hit, y.hit) << what;
        EXPECT_EQ(intersect_scene_bvh_any(bvh, ray), intersect_scene_bvh_any(packed_bvh, ray))
            << what;
        if (!x.hit) continue;
        EXPECT_EQ(x.instance, y.instance) << what;
        EXPECT_EQ(x.element, y.element) << what;
        EXPECT_EQ(x.uv, y.uv) << what;
        EXPECT_EQ(x.distance, y.distance) << what;
        auto& instance = scene.instances[x.instance];
        if (instance.shape != hair) continue;
        hits++;
        auto p = eval_fiber_point(scene, instance, x.element, x.uv.x, ray, x.distance);
        auto q = eval_fiber_point(packed, instance, y.element, y.uv.x, ray, y.distance);
        EXPECT_EQ(p.axis, q.axis) << what;
        EXPECT_EQ(p.tangent, q.tangent) << what;
        EXPECT_EQ(p.radius, q.radius) << what;
        EXPECT_EQ(p.h, q.h) << what;
      }
      EXPECT_GT(hits, 100) << what;
    }
  }
}
