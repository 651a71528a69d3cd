//
// Tests of the path tracer on scenes built in code: furnace, agreement of
// the MIS and BSDF-only estimators, determinism across thread counts.
//

#include <gtest/gtest.h>
#include <yocto/yocto_trace.h>

#include <cmath>
#include <limits>

using namespace yocto;

// A camera at distance looking at the origin.
static camera_data make_test_camera(float distance, float aspect = 1) {
  auto camera   = camera_data{};
  camera.frame  = lookat_frame({0, 0, distance}, {0, 0, 0}, {0, 1, 0});
  camera.aspect = aspect;
  camera.focus  = distance;
  return camera;
}

struct test_render {
  texture_data            image     = {};
  int64_t                 rays      = 0;
  int64_t                 nonfinite = 0;
  std::vector<fixed_sum3> sums      = {};
  float                   roulette_threshold = 0;  // the one the render used
};

static test_render render_scene(const scene_data& scene, const trace_params& params) {
  auto bvh   = scene_bvh{};
  auto error = std::string{};
  EXPECT_TRUE(make_scene_bvh(bvh, scene, {}, error)) << error;
  EXPECT_TRUE(check_trace_params(scene, params, error)) << error;
  auto context = make_trace_context(scene, params);
  auto state   = trace_state{};
  init_trace_state(state, scene, params);
  trace_samples(state, scene, bvh, context, params, params.samples);
  return {get_image(state), state.rays.load(), state.nonfinite.load(), state.sums,
      state.roulette_threshold};
}

static double image_mean(const texture_data& image) {
  auto sum = 0.0;
  for (auto& p : image.pixels) sum += mean(p);
  return sum / image.pixels.size();
}

// A white Lambertian sphere inside a constant white environment: every pixel
// converges to 1, whatever it sees (a convex object sees only the sky).
static scene_data make_furnace_scene() {
  auto scene = scene_data{};
  scene.cameras.push_back(make_test_camera(4));
  scene.environments.push_back({identity3x4f, {1, 1, 1}, -1});
  scene.shapes.push_back(make_sphere_shape(128, 1));
  auto white  = material_data{};
  white.color = {1, 1, 1};
  scene.materials.push_back(white);
  scene.instances.push_back({identity3x4f, 0, 0});
  return scene;
}

TEST(trace, white_furnace_matte_sphere_renders_the_environment) {
  // Every pixel within 1% of 1 and the image mean within 0.2%, for both
  // samplers. BSDF sampling alone returns exactly 1 per path (up to the
  // tessellation of the sphere): 24x24 pixels at 256 spp. MIS with uniform
  // sphere light samples (--lights all; automatic leaves the constant sky to
  // BSDF sampling) is noisier per path (standard deviation about 0.25): 12x12
  // pixels at 16384 spp, so 3.3 sigma is 0.65% with independent numbers.
  for (auto sampler : {trace_sampler_type::naive, trace_sampler_type::path}) {
    auto naive        = sampler == trace_sampler_type::naive;
    auto params       = trace_params{};
    params.resolution = naive ? 24 : 12;
    params.samples    = naive ? 256 : 16384;
    params.sampler    = sampler;
    params.lights     = trace_lights_type::all;
    params.seed       = 5;
    auto render       = render_scene(make_furnace_scene(), params);
    EXPECT_EQ(render.nonfinite, 0);
    EXPECT_NEAR(image_mean(render.image), 1, 0.002);
    auto worst = 0.0f;
    for (auto& p : render.image.pixels)
      worst = std::max(worst, max_component(abs(p - vec3f{1, 1, 1})));
    EXPECT_LT(worst, 0.01f) << trace_sampler_names[(int)sampler];
  }
}

// A grey floor, a glossy sphere and an area light under a textured sky:
// light sampling matters, so MIS and BSDF-only estimates must agree.
static scene_data make_lit_scene() {
  auto scene = scene_data{};
  scene.cameras.push_back(make_test_camera(5, 1.5f));
  // A sky texture with a bright spot: importance sampling of texels matters.
  auto sky = texture_data{32, 16, {}};
  for (auto j = 0; j < sky.height; j++)
    for (auto i = 0; i < sky.width; i++)
      sky.pixels.push_back(
          (i == 5 && j == 4) ? vec3f{40, 30, 20} : vec3f{0.2f, 0.3f, 0.5f} * (1.0f - j / 16.0f));
  scene.textures.push_back(sky);
  scene.environments.push_back({identity3x4f, {1, 1, 1}, 0});
  scene.shapes.push_back(make_quad_shape({8, 8}));
  scene.shapes.push_back(make_sphere_shape(48, 0.8f));
  scene.shapes.push_back(make_quad_shape({1, 1}));
  auto floor = material_data{}, ball = material_data{}, light = material_data{};
  floor.color    = {0.5f, 0.5f, 0.5f};
  ball.type      = material_type::glossy;
  ball.color     = {0.7f, 0.2f, 0.1f};
  ball.roughness = 0.4f;
  light.emission = {10, 10, 10};
  scene.materials = {floor, ball, light};
  scene.instances.push_back({rotation_frame({1, 0, 0}, -pif / 2) * translation_frame({0, 0, -0.8f}), 0, 0});
  scene.instances.push_back({identity3x4f, 1, 1});
  scene.instances.push_back({lookat_frame({1.5f, 2.5f, 1}, {0, 0, 0}, {0, 1, 0}) *
                                 rotation_frame({0, 1, 0}, pif), 2, 2});
  return scene;
}

TEST(trace, path_and_naive_agree_with_area_light_and_sky) {
  // 24x16 pixels; path at 64 spp, naive at 1024 spp. Image means agree within
  // 2% (MIS adds no bias; naive is only noisier).
  auto params       = trace_params{};
  params.resolution = 24;
  params.bounces    = 8;
  params.clamp      = 0;
  params.seed       = 3;
  params.samples    = 64;
  auto path         = render_scene(make_lit_scene(), params);
  params.sampler    = trace_sampler_type::naive;
  params.samples    = 1024;
  auto naive        = render_scene(make_lit_scene(), params);
  EXPECT_EQ(path.nonfinite, 0);
  EXPECT_EQ(naive.nonfinite, 0);
  auto path_mean = image_mean(path.image), naive_mean = image_mean(naive.image);
  EXPECT_GT(path_mean, 0.05);
  EXPECT_NEAR(path_mean / naive_mean, 1, 0.02) << path_mean << " " << naive_mean;
}

// Hair strands (curves) with a hair material over a sphere.
static scene_data make_hair_test_scene() {
  auto scene = scene_data{};
  scene.cameras.push_back(make_test_camera(4));
  scene.environments.push_back({identity3x4f, {0.8f, 0.9f, 1}, -1});
  auto strands = shape_data{};
  auto rng     = make_rng(11);
  for (auto s = 0; s < 200; s++) {
    auto base  = (int)strands.positions.size();
    auto start = vec3f{rand1f(rng) * 2 - 1, 1, rand1f(rng) * 0.4f - 0.2f};
    for (auto k = 0; k < 7; k++) {
      auto t = k / 6.0f;
      strands.positions.push_back(start + vec3f{0.2f * std::sin(6 * t + s), -2 * t, 0});
      strands.radius.push_back(0.01f * (1 - 0.7f * t));
    }
    strands.curves.push_back({base, base + 1, base + 2, base + 3});
    strands.curves.push_back({base + 3, base + 4, base + 5, base + 6});
  }
  scene.shapes.push_back(strands);
  scene.shapes.push_back(make_sphere_shape(32, 0.5f));
  auto hair = material_data{};
  hair.type = material_type::hair;
  hair.hair.eumelanin = 0.8f;
  auto skin = material_data{};
  skin.color = {0.6f, 0.5f, 0.4f};
  scene.materials = {hair, skin};
  scene.instances.push_back({identity3x4f, 0, 0});
  scene.instances.push_back({translation_frame({0, 0, -0.8f}), 1, 1});
  return scene;
}

// A camera that validation would refuse, rendered anyway: its rays never
// reach Embree (which would abort); the samples are dropped and counted.
TEST(trace, untraceable_camera_rays_are_dropped_not_aborted) {
  auto scene = make_furnace_scene();
  scene.cameras[0].frame.o = {1e19f, 0, 4};
  auto params       = trace_params{};
  params.resolution = 8;
  params.samples    = 1;
  auto render       = render_scene(scene, params);
  EXPECT_EQ(render.nonfinite, (int64_t)render.image.pixels.size());
  EXPECT_EQ(render.rays, 0);
}

TEST(trace, same_image_bit_for_bit_with_one_and_two_threads) {
  auto params       = trace_params{};
  params.resolution = 32;
  params.samples    = 8;
  params.threads    = 1;
  auto one          = render_scene(make_hair_test_scene(), params);
  params.threads    = 2;
  auto two          = render_scene(make_hair_test_scene(), params);
  ASSERT_EQ(one.image.pixels.size(), two.image.pixels.size());
  auto identical = true;
  for (auto i = 0; i < (int)one.image.pixels.size(); i++)
    identical = identical && one.image.pixels[i] == two.image.pixels[i];
  EXPECT_TRUE(identical);
  EXPECT_EQ(one.rays, two.rays);
  // and a different seed gives a different image
  params.seed = 77;
  auto other  = render_scene(make_hair_test_scene(), params);
  EXPECT_NE(other.image.pixels, one.image.pixels);
}

TEST(trace, hair_scene_has_no_nan_and_the_hair_is_visible) {
  auto params       = trace_params{};
  params.resolution = 32;
  params.samples    = 16;
  auto render       = render_scene(make_hair_test_scene(), params);
  EXPECT_EQ(render.nonfinite, 0);
  for (auto& p : render.image.pixels) {
    ASSERT_TRUE(isfinite(p));
    ASSERT_GE(min_component(p), 0);
  }
  // The hair darkens the middle of the image compared to the sky.
  auto center = render.image.pixels[16 * 32 + 16];
  EXPECT_LT(mean(center), 0.85f);
}

// Fibres pointing at the camera, one exactly along its central ray, lines
// and Beziers. Black ones show their caps black, never the sky through a
// hole. Hair ones are shaded with the hair model at its hard case (light
// along the fibre, cos theta = 0) and nothing non-finite comes out.
TEST(trace, fibres_seen_end_on_show_their_caps) {
  for (auto curves : {false, true}) {
    for (auto black : {true, false}) {
      auto scene = scene_data{};
      scene.cameras.push_back(make_test_camera(4));
      scene.environments.push_back({identity3x4f, {0.8f, 0.9f, 1}, -1});
      auto strands = shape_data{};
      for (auto center : {vec2f{0, 0}, vec2f{0.5f, 0.3f}, vec2f{-0.4f, -0.6f}}) {
        auto base = (int)strands.positions.size();
        for (auto k = 0; k < 4; k++) {
          strands.positions.push_back({center.x, center.y, 1 - 2 * k / 3.0f});
          strands.radius.push_back(0.15f);
        }
        if (curves) {
          strands.curves.push_back({base, base + 1, base + 2, base + 3});
        } else {
          for (auto k = 0; k < 3; k++) strands.lines.push_back({base + k, base + k + 1});
        }
      }
      scene.shapes.push_back(strands);
      auto material = material_data{};
      if (black) {
        material.color = {0, 0, 0};
      } else {
        material.type           = material_type::hair;
        material.hair.eumelanin = 1.5f;
      }
      scene.materials.push_back(material);
      scene.instances.push_back({identity3x4f, 0, 0});
      auto params       = trace_params{};
      params.resolution = 64;
      params.samples    = 16;
      auto render       = render_scene(scene, params);
      auto what         = std::string(curves ? "curves" : "lines") + (black ? " black" : " hair");
      EXPECT_EQ(render.nonfinite, 0) << what;
      for (auto& p : render.image.pixels) ASSERT_TRUE(isfinite(p)) << what;
      if (!black) continue;
      // The central fibre's cap, 0.15 in radius at distance 3, covers the
      // 4 x 4 pixels around the centre of the 64 x 64 image (2.2 across).
      for (auto j = 30; j < 34; j++) {
        for (auto i = 30; i < 34; i++) {
          EXPECT_EQ(render.image.pixels[j * 64 + i], (vec3f{0, 0, 0}))
              << what << " pixel " << i << ", " << j;
        }
      }
    }
  }
}

// An emissive sphere over a grey floor, nothing else: light sampling picks
// points on the whole sphere, half of them hidden by its near side.
static scene_data make_sphere_light_scene() {
  auto scene = scene_data{};
  scene.cameras.push_back(make_test_camera(4));
  scene.shapes.push_back(make_quad_shape({6, 6}));
  scene.shapes.push_back(make_sphere_shape(48, 0.4f));
  auto floor     = material_data{};
  floor.color    = {0.8f, 0.8f, 0.8f};
  auto light     = material_data{};
  light.emission = {5, 5, 5};
  scene.materials = {floor, light};
  scene.instances.push_back({translation_frame({0, 0, -1}), 0, 0});
  scene.instances.push_back({translation_frame({0.3f, 0.2f, 0}), 1, 1});
  return scene;
}

// Image means of path (MIS) and naive (BSDF sampling only) renders of one
// scene, unclamped, at their own sample counts.
static std::pair<double, double> path_and_naive_means(
    const scene_data& scene, trace_params params, int path_samples, int naive_samples) {
  params.clamp   = 0;
  params.sampler = trace_sampler_type::path;
  params.samples = path_samples;
  auto path      = image_mean(render_scene(scene, params).image);
  params.sampler = trace_sampler_type::naive;
  params.samples = naive_samples;
  return {path, image_mean(render_scene(scene, params).image)};
}

TEST(trace, sphere_light_is_not_counted_through_itself) {
  // 16x16 pixels, bounces 2 (direct light on the floor and the sphere's
  // emission); path at 64 spp, naive at 2048 spp: means within 3%. Counting
  // light samples on the sphere's far side made path 1.8x too bright.
  auto params       = trace_params{};
  params.resolution = 16;
  params.bounces    = 2;
  params.seed       = 5;
  auto [path_mean, naive_mean] = path_and_naive_means(make_sphere_light_scene(), params, 64, 2048);
  EXPECT_GT(naive_mean, 0.1);
  EXPECT_NEAR(path_mean / naive_mean, 1, 0.03) << path_mean << " " << naive_mean;
}

TEST(trace, two_environments_weigh_like_one) {
  // A grey sphere (albedo 0.6) under two constant environments of 0.5 renders
  // like one under a single environment of 1 (MIS weights per environment).
  // 12x12 pixels, 256 spp, path: means within 1%.
  auto params       = trace_params{};
  params.resolution = 12;
  params.samples    = 256;
  params.clamp      = 0;
  params.lights     = trace_lights_type::all;  // constant skies are sampled too
  auto one          = make_furnace_scene();
  one.materials[0].color = {0.6f, 0.6f, 0.6f};
  auto two          = one;
  two.environments  = {{identity3x4f, {0.5f, 0.5f, 0.5f}, -1},
      {identity3x4f, {0.5f, 0.5f, 0.5f}, -1}};
  auto one_mean = image_mean(render_scene(one, params).image);
  auto two_mean = image_mean(render_scene(two, params).image);
  EXPECT_NEAR(two_mean / one_mean, 1, 0.01) << two_mean << " " << one_mean;
}

TEST(trace, one_bounce_is_direct_light_for_both_samplers) {
  // bounces = 1: one scattering vertex, lit by the sky and the area light,
  // the same for path (64 spp) and naive (1024 spp) within 3%.
  auto params       = trace_params{};
  params.resolution = 24;
  params.bounces    = 1;
  params.seed       = 9;
  auto [path_mean, naive_mean] = path_and_naive_means(make_lit_scene(), params, 64, 1024);
  EXPECT_GT(naive_mean, 0.05);
  EXPECT_NEAR(path_mean / naive_mean, 1, 0.03) << path_mean << " " << naive_mean;
}

TEST(trace, sky_seen_at_the_pole_is_the_top_row) {
  // An empty scene under a 4x2 sky, top row 1 and bottom row 0, seen by a
  // camera looking straight up with a narrow field (v < 0.02 everywhere):
  // every pixel is 1. Wrapping v at the pole blended in the bottom row
  // (about 0.5 here). 8x8 pixels, 4 spp, both samplers.
  auto scene  = scene_data{};
  auto camera = camera_data{};
  camera.frame  = lookat_frame({0, 0, 0}, {0, 1, 0}, {0, 0, 1});
  camera.aspect = 1;
  camera.film   = 0.002f;
  scene.cameras.push_back(camera);
  scene.textures.push_back({4, 2, {{1, 1, 1}, {1, 1, 1}, {1, 1, 1}, {1, 1, 1},
                                      {0, 0, 0}, {0, 0, 0}, {0, 0, 0}, {0, 0, 0}}});
  scene.environments.push_back({identity3x4f, {1, 1, 1}, 0});
  auto params       = trace_params{};
  params.resolution = 8;
  params.samples    = 4;
  for (auto sampler : {trace_sampler_type::path, trace_sampler_type::naive}) {
    params.sampler = sampler;
    auto image     = render_scene(scene, params).image;
    for (auto& pixel : image.pixels) EXPECT_NEAR(mean(pixel), 1, 1e-5f);
  }
}

TEST(trace, constant_sky_is_left_to_bsdf_sampling) {
  // --lights automatic does not light-sample a constant sky: `path` then casts
  // no shadow ray and renders exactly what `naive` renders, bit for bit; and
  // its image agrees with --lights all (MIS with uniform sky samples). A grey
  // sphere (albedo 0.6) in a white sky, 16x16 pixels, 256 spp: means within 1%.
  auto scene = make_furnace_scene();
  scene.materials[0].color = {0.6f, 0.6f, 0.6f};
  auto params       = trace_params{};
  params.resolution = 16;
  params.samples    = 256;
  params.clamp      = 0;
  auto automatic    = render_scene(scene, params);
  params.lights     = trace_lights_type::all;
  auto all          = render_scene(scene, params);
  params.sampler    = trace_sampler_type::naive;
  auto naive        = render_scene(scene, params);
  EXPECT_EQ(automatic.rays, naive.rays);
  EXPECT_GT(all.rays, automatic.rays);
  EXPECT_EQ(automatic.image.pixels, naive.image.pixels);
  auto automatic_mean = image_mean(automatic.image), all_mean = image_mean(all.image);
  EXPECT_NEAR(automatic_mean / all_mean, 1, 0.01) << automatic_mean << " " << all_mean;
  // So is a textured sky of one value (MIS compensation leaves nothing to
  // light-sample), bit for bit.
  auto textured = scene;
  textured.textures.push_back({4, 2, std::vector<vec3f>(8, vec3f{0.7f, 0.7f, 0.7f})});
  textured.environments[0].emission_tex = 0;
  params.sampler = trace_sampler_type::path;
  params.lights  = trace_lights_type::automatic;
  auto textured_path = render_scene(textured, params);
  params.sampler = trace_sampler_type::naive;
  auto textured_naive = render_scene(textured, params);
  EXPECT_EQ(textured_path.rays, textured_naive.rays);
  EXPECT_EQ(textured_path.image.pixels, textured_naive.image.pixels);
  // A textured sky with a bright spot is still light-sampled.
  params            = trace_params{};
  params.resolution = 16;
  params.samples    = 4;
  auto lit          = render_scene(make_lit_scene(), params);
  params.sampler    = trace_sampler_type::naive;
  auto lit_naive = render_scene(make_lit_scene(), params);
  EXPECT_NE(lit.rays, lit_naive.rays);
}

TEST(trace, sobol_and_independent_numbers_agree_and_sobol_has_less_noise) {
  // The hair scene at 24x24: Sobol and independent numbers render the same
  // image in expectation (means within 1.5% at 256 spp), and the error at 16
  // spp against a 512-spp Sobol reference is lower with Sobol numbers (a
  // low-discrepancy sampler stratifies the pixel, lens and first bounces).
  auto scene        = make_hair_test_scene();
  auto params       = trace_params{};
  params.resolution = 24;
  params.clamp      = 0;
  params.samples    = 512;
  params.seed       = 21;
  auto reference    = render_scene(scene, params).image;
  auto mse = [&](const texture_data& image) {
    auto sum = 0.0;
    for (size_t i = 0; i < image.pixels.size(); i++) {
      auto d = image.pixels[i] - reference.pixels[i];
      sum += dot(d, d) / 3;
    }
    return sum / image.pixels.size();
  };
  params.samples     = 256;
  params.seed        = 22;
  auto sobol_mean    = image_mean(render_scene(scene, params).image);
  params.sequence    = sequence_type::independent;
  auto independent_mean = image_mean(render_scene(scene, params).image);
  EXPECT_NEAR(sobol_mean / independent_mean, 1, 0.015) << sobol_mean << " " << independent_mean;
  params.samples     = 16;
  auto independent_mse = mse(render_scene(scene, params).image);
  params.sequence    = sequence_type::sobol;
  auto sobol_mse     = mse(render_scene(scene, params).image);
  EXPECT_LT(sobol_mse, independent_mse) << sobol_mse << " " << independent_mse;
  std::printf("mse at 16 spp: sobol %g independent %g\n", sobol_mse, independent_mse);
}

TEST(trace, russian_roulette_from_any_bounce_keeps_the_mean) {
  // Roulette is unbiased wherever it starts: the hair scene at 24x24, 256
  // spp, starting at bounce 1 and at bounce 8: means within 1.5%; the early
  // roulette casts fewer rays.
  auto params         = trace_params{};
  params.resolution   = 24;
  params.samples      = 256;
  params.clamp        = 0;
  params.roulette_bounce = 1;
  auto early          = render_scene(make_hair_test_scene(), params);
  params.roulette_bounce = 8;
  auto late           = render_scene(make_hair_test_scene(), params);
  EXPECT_LT(early.rays, late.rays);
  auto early_mean = image_mean(early.image), late_mean = image_mean(late.image);
  EXPECT_NEAR(early_mean / late_mean, 1, 0.015) << early_mean << " " << late_mean;
}

TEST(trace, shadow_ray_roulette_keeps_the_mean_and_saves_rays) {
  // Sky samples adding less than a threshold times the sky's average play a
  // roulette for their shadow ray: the hair scene under the lit scene's
  // textured sky, 24x24 pixels at 256 spp, threshold 0 against 1 (a harsh
  // one): means within 1.5%, fewer rays with the roulette.
  auto scene = make_hair_test_scene();
  auto lit   = make_lit_scene();
  scene.textures     = lit.textures;
  scene.environments = lit.environments;
  auto params             = trace_params{};
  params.resolution       = 24;
  params.samples          = 256;
  params.clamp            = 0;
  params.shadow_threshold = 0;
  auto every              = render_scene(scene, params);
  params.shadow_threshold = 1;
  auto roulette           = render_scene(scene, params);
  EXPECT_LT(roulette.rays, every.rays);
  auto every_mean = image_mean(every.image), roulette_mean = image_mean(roulette.image);
  EXPECT_NEAR(roulette_mean / every_mean, 1, 0.015) << roulette_mean << " " << every_mean;
  std::printf("rays %lld -> %lld, means %g %g\n", (long long)every.rays,
      (long long)roulette.rays, every_mean, roulette_mean);
}

// -----------------------------------------------------------------------------
// ROULETTE THRESHOLD AND SPLITTING
// -----------------------------------------------------------------------------

// The mean over pixels of mean(a - b) and its standard error: pixels take
// independent numbers (their scrambles and generators are hashed from the
// pixel), so the pixel differences are independent samples of the difference
// of the two estimators, even when the two renders share their seed.
static std::pair<double, double> mean_difference(const texture_data& a, const texture_data& b) {
  auto sum = 0.0, sum2 = 0.0;
  auto n   = (double)a.pixels.size();
  for (size_t i = 0; i < a.pixels.size(); i++) {
    auto d = (double)mean(a.pixels[i]) - (double)mean(b.pixels[i]);
    sum += d, sum2 += d * d;
  }
  auto variance = std::max(0.0, (sum2 - sum * sum / n) / (n - 1));
  return {sum / n, std::sqrt(variance / n)};
}

// Two renders of one image by unbiased estimators: the mean pixel difference
// is within 4 standard errors of 0 (mean_difference), and 4 standard errors
// stay below 1% of the image mean (the check has power).
static void expect_same_mean(const test_render& a, const test_render& b, const std::string& what) {
  auto [difference, error] = mean_difference(a.image, b.image);
  auto reference           = image_mean(b.image);
  std::printf("[ figure ] %s: means %g and %g, difference %.2e +- %.2e; rays %lld and %lld\n",
      what.c_str(), image_mean(a.image), reference, difference, error, (long long)a.rays,
      (long long)b.rays);
  EXPECT_EQ(a.nonfinite, 0) << what;
  EXPECT_EQ(b.nonfinite, 0) << what;
  EXPECT_LE(std::abs(difference), 4 * error) << what;
  EXPECT_LT(4 * error, 0.01 * reference) << what;
}

TEST(trace, roulette_threshold_estimate_is_in_range_and_deterministic) {
  // The pilot on the hair scene (32x32 pixels, 16 spp): a threshold in
  // [1/16, 1]; the same bits with 1 and 2 threads and on a second call;
  // and the one a render of samples 5 ... 15 records (trace_samples runs the
  // pilot once, whatever the sample range).
  auto scene = make_hair_test_scene();
  auto bvh   = scene_bvh{};
  auto error = std::string{};
  ASSERT_TRUE(make_scene_bvh(bvh, scene, {}, error)) << error;
  auto params       = trace_params{};
  params.resolution = 32;
  params.samples    = 16;
  params.threads    = 1;
  auto context      = make_trace_context(scene, params);
  auto threshold    = estimate_roulette_threshold(scene, bvh, context, params);
  std::printf("[ figure ] estimated roulette threshold %.9g\n", threshold);
  EXPECT_GE(threshold, 1.0f / 16);
  EXPECT_LE(threshold, 1.0f);
  EXPECT_EQ(estimate_roulette_threshold(scene, bvh, context, params), threshold);
  params.threads = 2;
  EXPECT_EQ(estimate_roulette_threshold(scene, bvh, context, params), threshold);
  // For a render of 1024 spp the pilot takes every pixel (32 grid rows for
  // the threads to share): again in range and the same with 1 and 2 threads.
  {
    auto many    = params;
    many.samples = 1024;
    many.threads = 1;
    auto value   = estimate_roulette_threshold(scene, bvh, context, many);
    std::printf("[ figure ] estimated roulette threshold for 1024 spp %.9g\n", value);
    EXPECT_GE(value, 1.0f / 16);
    EXPECT_LE(value, 1.0f);
    many.threads = 2;
    EXPECT_EQ(estimate_roulette_threshold(scene, bvh, context, many), value);
  }
  auto state = trace_state{};
  init_trace_state(state, scene, params, 5);
  EXPECT_EQ(state.roulette_threshold, 0.0f);
  trace_samples(state, scene, bvh, context, params, 11);
  EXPECT_EQ(state.roulette_threshold, threshold);
  // A fixed threshold is used as given.
  params.roulette_threshold = 0.3f;
  init_trace_state(state, scene, params);
  trace_samples(state, scene, bvh, context, params, 1);
  EXPECT_EQ(state.roulette_threshold, 0.3f);
}

TEST(trace, roulette_threshold_keeps_the_mean) {
  // Roulette below any threshold is unbiased: the hair scene at 24x24, 256
  // spp, one seed, with the automatic threshold (the pilot's), 0.25 and 1
  // (every path that lost energy plays). Each image has the mean of the one
  // at 1 (expect_same_mean: within 4 standard errors of the pixel
  // differences; one measured 0.03% of the mean). A lower threshold casts
  // more rays (fewer paths end); the automatic render records its threshold.
  auto scene        = make_hair_test_scene();
  auto params       = trace_params{};
  params.resolution = 24;
  params.samples    = 256;
  params.seed       = 41;
  params.roulette_threshold = 1;
  auto one          = render_scene(scene, params);
  params.roulette_threshold = 0.25f;
  auto quarter      = render_scene(scene, params);
  params.roulette_threshold = 0;
  auto automatic    = render_scene(scene, params);
  EXPECT_EQ(one.roulette_threshold, 1.0f);
  EXPECT_EQ(quarter.roulette_threshold, 0.25f);
  EXPECT_GT(automatic.roulette_threshold, 0.0f);
  EXPECT_LE(automatic.roulette_threshold, 1.0f);
  EXPECT_GT(quarter.rays, one.rays);
  expect_same_mean(quarter, one, "threshold 0.25 against 1");
  expect_same_mean(automatic, one,
      "threshold " + std::to_string(automatic.roulette_threshold) + " (automatic) against 1");
}

TEST(trace, roulette_threshold_is_checked) {
  auto scene  = make_hair_test_scene();
  auto params = trace_params{};
  auto error  = std::string{};
  for (auto threshold : {0.0f, 0.5f, 1.0f, 4.0f}) {
    params.roulette_threshold = threshold;
    EXPECT_TRUE(check_trace_params(scene, params, error)) << threshold << ": " << error;
  }
  for (auto threshold : {-0.5f, -std::numeric_limits<float>::min(),
           std::numeric_limits<float>::quiet_NaN(), std::numeric_limits<float>::infinity()}) {
    params.roulette_threshold = threshold;
    error                     = "";
    EXPECT_FALSE(check_trace_params(scene, params, error)) << threshold;
    EXPECT_NE(error.find("roulette threshold"), std::string::npos) << error;
  }
}

TEST(trace, split_keeps_the_mean_and_saves_camera_rays) {
  // The hair scene at 24x24, 128 spp, a fixed threshold (0.5), one seed,
  // split 1 and 4 (the same pixel positions, other bounce numbers): the same
  // mean (expect_same_mean; one standard error measured 0.05% of the mean,
  // so a bias of 0.2% of the mean fails). Split 4 casts one camera ray for four paths: with C = 128 x
  // 576 camera rays and T the rays after them at split 1, it casts C + 4 T'
  // with T' of T's expectation, so its rays are 4 x rays(split 1) - 3 C
  // within 2% (measured 0.07%): fewer than 4 times as many. The split image
  // is not the unsplit one (each split path takes its own numbers).
  auto scene        = make_hair_test_scene();
  auto params       = trace_params{};
  params.resolution = 24;
  params.seed       = 17;
  params.samples    = 128;
  params.roulette_threshold = 0.5f;
  auto single       = render_scene(scene, params);
  params.split      = 4;
  auto split        = render_scene(scene, params);
  EXPECT_NE(split.image.pixels, single.image.pixels);
  expect_same_mean(split, single, "split 4 against 1");
  auto camera_rays = (double)single.image.pixels.size() * params.samples;
  auto expected    = 4.0 * single.rays - 3 * camera_rays;
  EXPECT_NEAR((double)split.rays, expected, 0.02 * expected);
  EXPECT_GT(split.rays, single.rays);
  EXPECT_LT(split.rays, 4 * single.rays);
}

TEST(trace, split_is_checked) {
  auto scene  = make_hair_test_scene();
  auto params = trace_params{};
  auto error  = std::string{};
  for (auto split : {1, 2, 1024}) {
    params.split = split;
    EXPECT_TRUE(check_trace_params(scene, params, error)) << split << ": " << error;
  }
  for (auto split : {0, -1, 1025, 2000}) {
    params.split = split;
    error        = "";
    EXPECT_FALSE(check_trace_params(scene, params, error)) << split;
    EXPECT_NE(error.find("split"), std::string::npos) << error;
  }
  // Split paths number their samples sample * split + k in 32 bits.
  params.split   = 1024;
  params.samples = 1 << 22;  // 2^32 paths: the last is 2^32 - 1
  EXPECT_TRUE(check_trace_params(scene, params, error)) << error;
  params.samples = (1 << 22) + 1;
  EXPECT_FALSE(check_trace_params(scene, params, error));
}

TEST(trace, automatic_roulette_and_split_renders_do_not_depend_on_threads) {
  // Default parameters (the pilot picks the roulette threshold) with split 1
  // and 3: the hair scene at 32x32, 8 spp, gives the same sums, bit for bit,
  // the same threshold and the same ray count with 1 and 2 threads.
  for (auto split : {1, 3}) {
    auto params       = trace_params{};
    params.resolution = 32;
    params.samples    = 8;
    params.split      = split;
    params.threads    = 1;
    auto one          = render_scene(make_hair_test_scene(), params);
    EXPECT_GT(one.roulette_threshold, 0.0f);
    params.threads = 2;
    auto two       = render_scene(make_hair_test_scene(), params);
    EXPECT_TRUE(two.sums == one.sums) << "split " << split;
    EXPECT_EQ(two.roulette_threshold, one.roulette_threshold);
    EXPECT_EQ(two.rays, one.rays);
  }
}

TEST(trace, hair_lobe_weights_render_like_mixture_weights) {
  // Under a constant sky no MIS needs the hair pdf, and sampled hair
  // directions take their lobe's weight A_p / P(p) (sample_hair_scattering_
  // weight) instead of eval / pdf of the lobe mixture: the same expectation.
  // The hair scene at 24x24, 256 spp, one seed and threshold: the same mean
  // (expect_same_mean; one standard error measured 0.003% of the mean, the
  // two sharing their directions), and the images differ (the option does
  // switch the estimator).
  auto scene        = make_hair_test_scene();
  auto params       = trace_params{};
  params.resolution = 24;
  params.samples    = 256;
  params.seed       = 8;
  params.roulette_threshold = 0.5f;
  auto lobe         = render_scene(scene, params);
  params.hair_mixture_weight = true;
  auto mixture      = render_scene(scene, params);
  EXPECT_NE(lobe.image.pixels, mixture.image.pixels);
  expect_same_mean(lobe, mixture, "lobe weights against mixture weights");
}
