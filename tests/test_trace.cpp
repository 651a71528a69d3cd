//
// Tests of the path tracer on scenes built in code: furnace, agreement of
// the MIS and BSDF-only estimators, determinism across thread counts.
//

#include <gtest/gtest.h>
#include <yocto/yocto_trace.h>

#include <cmath>
#include <limits>
#include <map>
#include <stdexcept>

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
  std::vector<float>      rates     = {};           // adaptive rates (empty: uniform)
  int                     split     = 0;            // paths per camera ray
  std::vector<uint8_t>    splits    = {};           // per pixel (empty: split)
};

// Renders samples first ... first + count - 1 (count < 0: params.samples).
static test_render render_scene(const scene_data& scene, const trace_params& params,
    int first = 0, int count = -1) {
  auto bvh   = scene_bvh{};
  auto error = std::string{};
  EXPECT_TRUE(make_scene_bvh(bvh, scene, {}, error)) << error;
  EXPECT_TRUE(check_trace_params(scene, params, error)) << error;
  auto context = make_trace_context(scene, params);
  auto state   = trace_state{};
  init_trace_state(state, scene, params, first);
  trace_samples(state, scene, bvh, context, params, count < 0 ? params.samples : count);
  return {get_image(state), state.rays.load(), state.nonfinite.load(), state.sums,
      state.roulette_threshold, state.rates, state.split, state.splits};
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
  // Every pixel takes its 256 camera samples (no per-pixel plan): a camera
  // ray grazing the tessellated sphere, whose shading normal faces away,
  // brings 0, and the plan, whose pilot rarely meets one, gives some edge
  // pixels 64 camera samples (8 paths each), where one such ray is 1/64
  // (the mean stays 1: adaptive_images_are_unbiased_at_any_sample_count).
  for (auto sampler : {trace_sampler_type::naive, trace_sampler_type::path}) {
    auto naive        = sampler == trace_sampler_type::naive;
    auto params       = trace_params{};
    params.adaptive   = trace_adaptive_type::off;
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

// A render packs its fibres before the BVH (what yscene does): the same
// image bit for bit, and the same rays, as the scene as loaded; also with
// strands that vary along their length and per strand (their strands are
// found from the packed positions) and in curve pieces.
TEST(trace, packed_fibres_render_the_same_image) {
  auto params       = trace_params{};
  params.resolution = 32;
  params.samples    = 8;
  for (auto varies : {false, true}) {
    auto scene = make_hair_test_scene();
    if (varies) {
      scene.materials[0].hair.tip_eumelanin     = 0.1f;
      scene.materials[0].hair.has_tip_eumelanin = true;
      scene.materials[0].hair.random_melanin    = 0.3f;
    }
    auto packed = scene;
    pack_fiber_vertices(packed);
    ASSERT_FALSE(packed.shapes[0].fiber_vertices.empty());
    auto a = render_scene(scene, params), b = render_scene(packed, params);
    EXPECT_TRUE(a.sums == b.sums) << varies;
    EXPECT_EQ(a.rays, b.rays) << varies;
    EXPECT_EQ(fingerprint_scene(scene), fingerprint_scene(packed)) << varies;
  }
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
  // The hair scene at 24x24: the global Sobol point (the default), Sobol
  // pairs and independent numbers render the same image in expectation
  // (means within 1.5% at 256 spp), and the error at 16 spp against a
  // 512-spp reference is lower with either Sobol sequence (a low-discrepancy
  // sampler stratifies the pixel, lens and first bounces).
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
  auto means = std::array<double, 3>{}, errors = std::array<double, 3>{};
  auto types = std::array<sequence_type, 3>{
      sequence_type::global_sobol, sequence_type::sobol, sequence_type::independent};
  for (auto t = 0; t < 3; t++) {
    params.sequence = types[t];
    params.seed     = 22;
    params.samples  = 256;
    means[t]        = image_mean(render_scene(scene, params).image);
    params.samples  = 16;
    errors[t]       = mse(render_scene(scene, params).image);
  }
  EXPECT_NEAR(means[0] / means[2], 1, 0.015) << means[0] << " " << means[2];
  EXPECT_NEAR(means[1] / means[2], 1, 0.015) << means[1] << " " << means[2];
  EXPECT_LT(errors[0], errors[2]) << errors[0] << " " << errors[2];
  EXPECT_LT(errors[1], errors[2]) << errors[1] << " " << errors[2];
  std::printf("mse at 16 spp: global sobol %g, sobol pairs %g, independent %g\n", errors[0],
      errors[1], errors[2]);
}

TEST(trace, global_sobol_slots_go_to_the_pairs_a_path_draws) {
  // The hair test scene: a pinhole, a constant sky (left to BSDF sampling,
  // so no light pairs), no glossy material, roulette from bounce 0 (the
  // default). Pairs: 0 pixel, 1 lens, then 6 a bounce (light, light point,
  // lobe/roulette, direction, four numbers' second pair, shadow). The 16
  // slots of the global point go, in path order, to the pixel, then the
  // roulette, direction and second pair of bounces 0 to 4; every other pair
  // is padded (-1). With roulette from bounce 1, bounce 0's roulette pair
  // is padded and bounce 5's roulette takes the last slot.
  auto scene   = make_hair_test_scene();
  auto params  = trace_params{};
  auto context = make_trace_context(scene, params);
  auto& slots  = context.sequence_slots;
  auto expected_slots = [&](int roulette_bounce) {
    auto expected = std::vector<int8_t>((size_t)(2 + 6 * params.sobol_bounces), -1);
    expected[0] = 0;
    auto next   = 1;
    for (auto bounce = 0; next < 16; bounce++) {
      for (auto pair : {2, 3, 4})
        if (next < 16 && (pair != 2 || bounce >= roulette_bounce))
          expected[2 + 6 * bounce + pair] = (int8_t)next++;
    }
    // The list ends at the last pair with a slot.
    while (!expected.empty() && expected.back() < 0) expected.pop_back();
    return expected;
  };
  EXPECT_TRUE(slots == expected_slots(0));
  {
    auto later            = params;
    later.roulette_bounce = 1;
    EXPECT_TRUE(make_trace_context(scene, later).sequence_slots == expected_slots(1));
  }
  // Hair sampled from two numbers: no second pair, so deeper bounces get
  // slots (bounce 7's roulette takes the last).
  params.hair_sampling.four_numbers = false;
  auto demux = make_trace_context(scene, params).sequence_slots;
  EXPECT_EQ(demux[2 + 4], -1);
  EXPECT_EQ(demux[2 + 2], 1);
  EXPECT_EQ(demux[2 + 3], 2);
  EXPECT_EQ(demux[2 + 6 * 7 + 2], 15);
  EXPECT_EQ(std::count_if(demux.begin(), demux.end(), [](int8_t s) { return s >= 0; }), 16);
  // A huge --sobol-bounces allocates nothing more (the list stops at the
  // 16th slot) and renders (no int overflow in the pair count).
  params.hair_sampling.four_numbers = true;
  params.sobol_bounces              = 2000000000;
  EXPECT_TRUE(make_trace_context(scene, params).sequence_slots == slots);
  params.resolution = 8;
  params.samples    = 4;
  auto image        = render_scene(scene, params).image;
  for (auto& pixel : image.pixels) ASSERT_TRUE(isfinite(pixel));
  // Other sequences take no slots.
  params.sequence = sequence_type::sobol;
  EXPECT_TRUE(make_trace_context(scene, params).sequence_slots.empty());
}

TEST(trace, russian_roulette_from_any_bounce_keeps_the_mean) {
  // Roulette is unbiased wherever it starts: the hair scene at 24x24, 256
  // spp, starting at bounce 0 (the default: the first vertex's direction
  // already plays) and at bounce 8: means within 1.5%; the early roulette
  // casts fewer rays.
  auto params         = trace_params{};
  params.resolution   = 24;
  params.samples      = 256;
  params.clamp        = 0;
  params.roulette_bounce = 0;
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
  params.allocation       = false;  // the roulette of shadow_threshold
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

// Renders of seeds 1 ... n: the pixels' variance between them (averaged over
// pixels and channels) and the rays all of them cast.
static std::pair<double, int64_t> variance_between_seeds(
    const scene_data& scene, trace_params params, int n) {
  auto renders = std::vector<test_render>{};
  auto rays    = int64_t{0};
  for (auto seed = 1; seed <= n; seed++) {
    params.seed = seed;
    renders.push_back(render_scene(scene, params));
    rays += renders.back().rays;
  }
  auto variance = 0.0;
  auto pixels   = renders[0].image.pixels.size();
  for (size_t i = 0; i < pixels; i++) {
    for (auto c = 0; c < 3; c++) {
      auto sum = 0.0, sum2 = 0.0;
      for (auto& render : renders) {
        sum += render.image.pixels[i][c], sum2 += sqr((double)render.image.pixels[i][c]);
      }
      variance += (sum2 - sum * sum / renders.size()) / (renders.size() - 1);
    }
  }
  return {variance / (3 * pixels), rays};
}

// variance_between_seeds of 8 seeds, times their rays, of `params` over
// that of `other` (printed as a figure named `what`).
static double variance_times_rays_ratio(const scene_data& scene, const trace_params& params,
    const trace_params& other, const std::string& what) {
  auto [variance, rays]             = variance_between_seeds(scene, params, 8);
  auto [other_variance, other_rays] = variance_between_seeds(scene, other, 8);
  auto ratio = variance * rays / (other_variance * other_rays);
  std::printf("[ figure ] %s: variance %.3e against %.3e, rays %lld against %lld, variance x "
              "rays %.3f\n",
      what.c_str(), variance, other_variance, (long long)rays, (long long)other_rays, ratio);
  return ratio;
}

// The hair test scene's curtain before a black wall (in place of its
// sphere): a tail that leaves the curtain towards the camera's side reaches
// the sky, one that leaves towards the wall ends there.
static scene_data make_walled_hair_scene() {
  auto scene = make_hair_test_scene();
  scene.shapes[1]    = make_quad_shape({20, 20});
  scene.materials[1] = material_data{};
  scene.materials[1].color = {0, 0, 0};
  scene.instances[1] = {translation_frame({0, 0, -0.3f}), 1, 1};
  return scene;
}

TEST(trace, roulette_cache_learns_where_tails_lead) {
  // The pilot on the walled curtain (32x32 pixels, 16 spp): a grid of cells,
  // the same bits with 1 and 2 threads; at the curtain's centre the fitted
  // second moment of a tail towards the open sky (+z) is more than twice
  // (measured 0.18 against 0.00) that of one towards the black wall (-z), and a path of
  // low throughput survives more often leaving towards the sky. Survival is
  // in [w, min(16 w, 1)] and without a grid it is the throughput's.
  auto scene = make_walled_hair_scene();
  auto bvh   = scene_bvh{};
  auto error = std::string{};
  ASSERT_TRUE(make_scene_bvh(bvh, scene, {}, error)) << error;
  auto params       = trace_params{};
  params.resolution = 32;
  params.samples    = 16;
  params.threads    = 1;
  params.roulette_control = true;
  auto context      = make_trace_context(scene, params);
  auto cache        = run_trace_pilot(scene, bvh, context, params).roulette_cache;
  ASSERT_GT(cache.cells.x * cache.cells.y * cache.cells.z, 0);
  ASSERT_EQ(cache.tails.size(), (size_t)cache.cells.x * cache.cells.y * cache.cells.z);
  EXPECT_GT(cache.pixel_deviation, 0.0f);
  params.threads = 2;
  auto again     = run_trace_pilot(scene, bvh, context, params).roulette_cache;
  EXPECT_EQ(again.cells, cache.cells);
  EXPECT_EQ(again.tails, cache.tails);
  EXPECT_EQ(again.pixel_deviation, cache.pixel_deviation);
  EXPECT_EQ(again.controls, cache.controls);
  auto centre = vec3f{0, 0, 0};
  auto cell   = find_roulette_cell(cache, centre);
  ASSERT_GE(cell, 0);
  auto& tail       = cache.tails[cell];
  auto  to_sky     = tail[0] + tail[3], to_wall = tail[0] - tail[3];
  std::printf("[ figure ] tail moment towards the sky %g, towards the wall %g\n", to_sky, to_wall);
  EXPECT_GT(to_sky, 2 * std::max(to_wall, 0.0f));
  // The control variate: a mean tail per channel and direction, larger
  // towards the sky, and the second moment about it below the moment.
  ASSERT_EQ(cache.controls.size(), cache.tails.size());
  auto& control = cache.controls[cell];
  for (auto c = 0; c < 3; c++) {
    auto mean_to_sky = control[4 * c] + control[4 * c + 3],
         mean_to_wall = control[4 * c] - control[4 * c + 3];
    std::printf("[ figure ] channel %d: mean tail towards the sky %g, towards the wall %g\n", c,
        mean_to_sky, mean_to_wall);
    EXPECT_GT(mean_to_sky, 2 * std::max(mean_to_wall, 0.0f)) << c;
  }
  auto residual_to_sky = control[12] + control[15];
  std::printf("[ figure ] tail moment about the mean towards the sky %g\n", residual_to_sky);
  EXPECT_LT(residual_to_sky, to_sky);
  auto low = 0.01f;
  EXPECT_GT(roulette_survival(cache, centre, {0, 0, 1}, low),
      roulette_survival(cache, centre, {0, 0, -1}, low));
  for (auto weight : {0.0f, 0.001f, 0.05f, 0.3f, 1.0f, 3.0f}) {
    for (auto direction : {vec3f{0, 0, 1}, vec3f{0, 0, -1}, vec3f{1, 0, 0}, vec3f{0, -1, 0}}) {
      auto survive = roulette_survival(cache, centre, direction, weight);
      EXPECT_GE(survive, std::min(weight, 1.0f)) << weight;
      EXPECT_LE(survive, std::min(16 * weight, 1.0f)) << weight;
    }
  }
  EXPECT_EQ(roulette_survival(trace_roulette_cache{}, centre, {0, 0, 1}, 0.25f), 0.25f);
  EXPECT_EQ(roulette_survival(trace_roulette_cache{}, centre, {0, 0, 1}, 4.0f), 1.0f);
  EXPECT_EQ(find_roulette_cell(trace_roulette_cache{}, centre), -1);
  params.roulette_control = false;
  EXPECT_TRUE(run_trace_pilot(scene, bvh, context, params).roulette_cache.controls.empty());
  params.roulette_cache = false;
  EXPECT_EQ(run_trace_pilot(scene, bvh, context, params).roulette_cache.cells.x, 0);
}

TEST(trace, roulette_cache_is_fitted_again_from_the_plans_paths) {
  // The walled curtain at 32x32, 16 spp, adaptive sampling on: the render's
  // cache is the pilot's fitted again with the tails of the plan's split
  // paths as well (each path's own: see record_path_tails), the same bits
  // with 1 and 2 threads, with as many cells or more, and it still sees
  // that a tail towards the sky is worth more than twice one towards the
  // wall (measured 0.32 against 0). Without the plan, or with the control
  // variate, the render's cache is the pilot's.
  auto scene = make_walled_hair_scene();
  auto bvh   = scene_bvh{};
  auto error = std::string{};
  ASSERT_TRUE(make_scene_bvh(bvh, scene, {}, error)) << error;
  auto params       = trace_params{};
  params.resolution = 32;
  params.samples    = 16;
  params.adaptive   = trace_adaptive_type::on;
  params.threads    = 1;
  auto context      = make_trace_context(scene, params);
  auto first        = run_trace_pilot(scene, bvh, context, params).roulette_cache;
  auto cache_of_render = [&](const trace_params& params) {
    auto state = trace_state{};
    init_trace_state(state, scene, params);
    trace_samples(state, scene, bvh, context, params, 1);
    return state.roulette_cache;
  };
  auto cells = [](const trace_roulette_cache& cache) {
    return cache.cells.x * cache.cells.y * cache.cells.z;
  };
  auto refit = cache_of_render(params);
  params.threads = 2;
  auto again     = cache_of_render(params);
  EXPECT_EQ(again.cells, refit.cells);
  EXPECT_EQ(again.tails, refit.tails);
  ASSERT_GT(cells(first), 0);
  EXPECT_GE(cells(refit), cells(first));
  EXPECT_NE(refit.tails, first.tails);
  EXPECT_EQ(refit.pixel_deviation, first.pixel_deviation);
  auto centre = vec3f{0, 0, 0};
  auto& tail  = refit.tails[find_roulette_cell(refit, centre)];
  auto  to_sky = tail[0] + tail[3], to_wall = tail[0] - tail[3];
  std::printf("[ figure ] refitted tail moment towards the sky %g, towards the wall %g\n",
      to_sky, to_wall);
  EXPECT_GT(to_sky, 2 * std::max(to_wall, 0.0f));
  params.adaptive = trace_adaptive_type::off;
  auto unplanned  = cache_of_render(params);
  EXPECT_EQ(unplanned.cells, first.cells);
  EXPECT_EQ(unplanned.tails, first.tails);
  params.adaptive         = trace_adaptive_type::on;
  params.roulette_control = true;
  auto controlled         = cache_of_render(params);
  auto controlled_pilot   = run_trace_pilot(scene, bvh, context, params).roulette_cache;
  EXPECT_EQ(controlled.tails, controlled_pilot.tails);
  EXPECT_EQ(controlled.controls, controlled_pilot.controls);
}

TEST(trace, roulette_control_keeps_the_mean_and_lowers_the_noise) {
  // The hair test scene with light brown hair (eumelanin 0.5: its tails
  // bring back much of what they carry, which the roulette loses when it
  // ends them), 24x24, adaptive sampling off, lobe guide off: the roulette
  // with the cache's mean tail as a control variate against without.
  // - The same mean at 1024 spp (expect_same_mean).
  // - 16 spp, 8 seeds: the pixels' variance across seeds times the rays
  //   below 0.97 times the one without (measured 0.936; 0.97 at eumelanin
  //   0.2 and 0.3, 1.00 at 0.1, where the roulette rarely plays).
  auto scene                        = make_hair_test_scene();
  scene.materials[0].hair.eumelanin = 0.5f;
  auto params                       = trace_params{};
  params.resolution                 = 24;
  params.adaptive                   = trace_adaptive_type::off;
  params.lobe_guide                 = 0;
  params.samples                    = 1024;
  params.seed                       = 53;
  params.roulette_control           = true;
  auto controlled                   = render_scene(scene, params);
  params.roulette_control           = false;
  auto plain                        = render_scene(scene, params);
  EXPECT_NE(controlled.image.pixels, plain.image.pixels);
  expect_same_mean(controlled, plain, "roulette with and without its control variate");
  params.samples          = 16;
  params.roulette_control = true;
  auto without            = params;
  without.roulette_control = false;
  EXPECT_LT(variance_times_rays_ratio(scene, params, without, "roulette control variate"), 0.97);
}

TEST(trace, roulette_cache_keeps_the_mean_and_saves_rays) {
  // The walled curtain at 24x24, 512 spp, one seed, adaptive sampling off:
  // the roulette by region and direction against the pilot's one threshold
  // (params.roulette_cache off): the same mean (expect_same_mean: within 4
  // standard errors, each below 1% of the mean), and fewer rays (the tails
  // into the wall end sooner). A threshold the user sets holds everywhere:
  // no cache.
  auto scene        = make_walled_hair_scene();
  auto params       = trace_params{};
  params.resolution = 24;
  params.samples    = 512;
  params.seed       = 43;
  params.adaptive   = trace_adaptive_type::off;
  params.lobe_guide = 0;  // the roulette alone (the guide has its own test)
  auto cached       = render_scene(scene, params);
  params.roulette_cache = false;
  auto global       = render_scene(scene, params);
  EXPECT_EQ(cached.roulette_threshold, global.roulette_threshold);
  EXPECT_NE(cached.image.pixels, global.image.pixels);
  EXPECT_LT(cached.rays, global.rays);
  expect_same_mean(cached, global, "roulette cache against one threshold");
  auto bvh   = scene_bvh{};
  auto error = std::string{};
  ASSERT_TRUE(make_scene_bvh(bvh, scene, {}, error)) << error;
  params.roulette_cache     = true;
  params.roulette_threshold = 0.5f;
  auto context = make_trace_context(scene, params);
  auto state   = trace_state{};
  init_trace_state(state, scene, params);
  trace_samples(state, scene, bvh, context, params, 1);
  EXPECT_EQ(state.roulette_cache.cells.x, 0);
  params.roulette_threshold = 0;
  init_trace_state(state, scene, params);
  trace_samples(state, scene, bvh, context, params, 1);
  EXPECT_GT(state.roulette_cache.cells.x, 0);
  // The tally of what the roulette did (--stats).
  EXPECT_GT(state.roulette_ends, 0);
  EXPECT_LT(state.roulette_ends, state.roulette_plays);
  EXPECT_LT(state.roulette_plays, state.vertices);
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
  for (auto split : {0, 1, 2, 1024}) {
    params.split = split;
    EXPECT_TRUE(check_trace_params(scene, params, error)) << split << ": " << error;
  }
  for (auto split : {-1, 1025, 2000}) {
    params.split = split;
    error        = "";
    EXPECT_FALSE(check_trace_params(scene, params, error)) << split;
    EXPECT_NE(error.find("split"), std::string::npos) << error;
  }
  // Split paths number their samples sample * split + k in 32 bits (and
  // adaptive pixels up to 16 paths a sample: see below).
  params.adaptive = trace_adaptive_type::off;
  params.split   = 1024;
  params.samples = 1 << 22;  // 2^32 paths: the last is 2^32 - 1
  EXPECT_TRUE(check_trace_params(scene, params, error)) << error;
  params.samples = (1 << 22) + 1;
  EXPECT_FALSE(check_trace_params(scene, params, error));
}

// A sun over the hair scene's sky: its light is sampled, and hair strands
// and the sphere shadow one another.
static scene_data make_sun_hair_scene() {
  auto scene = make_hair_test_scene();
  scene.distant_lights.push_back({normalize(vec3f{1, 2, 1}), {3, 3, 3}});
  return scene;
}

TEST(trace, shadow_allocation_follows_the_visibility_of_each_region) {
  // The allocation's grid covers the pilot's shadow rays; a point outside
  // its bounds takes the nearest cell, a render without a grid none; every
  // cell's sqrt(P) is in [0, 1] and, in a scene where the strands shadow
  // one another, differs between cells.
  auto scene = make_sun_hair_scene();
  auto bvh   = scene_bvh{};
  auto error = std::string{};
  ASSERT_TRUE(make_scene_bvh(bvh, scene, {}, error)) << error;
  auto params       = trace_params{};
  params.resolution = 32;
  params.samples    = 16;
  auto context      = make_trace_context(scene, params);
  auto allocation   = run_trace_pilot(scene, bvh, context, params).allocation;
  ASSERT_GT(allocation.cells.x * allocation.cells.y * allocation.cells.z, 1);
  EXPECT_GT(allocation.pixel_deviation, 0.0f);
  auto lowest = 1.0f, highest = 0.0f;
  for (auto value : allocation.visibility) {
    EXPECT_GE(value, 0.0f);
    EXPECT_LE(value, 1.0f);
    lowest = std::min(lowest, value), highest = std::max(highest, value);
  }
  EXPECT_LT(lowest, highest);
  auto far    = allocation.bounds.max + vec3f{10, 10, 10};
  auto corner = allocation.bounds.max - vec3f{1e-4f, 1e-4f, 1e-4f};
  EXPECT_EQ(find_allocation_cell(allocation, far), find_allocation_cell(allocation, corner));
  EXPECT_EQ(find_allocation_cell(allocation, allocation.bounds.min - vec3f{5, 5, 5}), 0);
  EXPECT_EQ(find_allocation_cell(trace_allocation{}, {0, 0, 0}), -1);
  EXPECT_EQ(find_allocation_cell(allocation, {flt_max, 0, std::nanf("")}), -1);
  params.allocation = false;
  EXPECT_EQ(run_trace_pilot(scene, bvh, context, params).allocation.cells.x, 0);
}

TEST(trace, shadow_allocation_keeps_the_mean_and_saves_shadow_rays) {
  // The sun hair scene at 32x32, 256 spp, with a fixed roulette threshold:
  // the allocation of shadow rays against a shadow ray for every light
  // sample (params.allocation off, shadow_threshold 0): the same mean (expect_same_mean: 4 standard errors, below 1% of the mean),
  // fewer shadow rays; the sun takes no MIS weight, so the hair takes its
  // lobe weights (no pdf) and renders the same mean as with the mixture's.
  auto scene              = make_sun_hair_scene();
  auto params             = trace_params{};
  params.resolution       = 32;
  params.samples          = 256;
  params.clamp            = 0;
  params.roulette_threshold = 0.5f;
  params.adaptive         = trace_adaptive_type::off;
  auto allocated          = render_scene(scene, params);
  params.allocation       = false;
  params.shadow_threshold = 0;
  auto every              = render_scene(scene, params);
  expect_same_mean(allocated, every, "allocation against every shadow ray");
  EXPECT_LT(allocated.rays, every.rays);
  params.hair_sampling.mixture_weight = true;
  auto mixture = render_scene(scene, params);
  EXPECT_FALSE(mixture.sums == every.sums);
  expect_same_mean(every, mixture, "lobe weights against mixture weights under a sun");
}

TEST(trace, shadow_allocation_renders_do_not_depend_on_threads) {
  // Default parameters on the sun hair scene (24x24, 8 spp): the same sums,
  // rays and allocation with 1 and 2 threads.
  auto params       = trace_params{};
  params.resolution = 24;
  params.samples    = 8;
  params.threads    = 1;
  auto scene        = make_sun_hair_scene();
  auto one          = render_scene(scene, params);
  params.threads    = 2;
  auto two          = render_scene(scene, params);
  EXPECT_TRUE(two.sums == one.sums);
  EXPECT_EQ(two.rays, one.rays);
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

// -----------------------------------------------------------------------------
// ADAPTIVE SAMPLING
// -----------------------------------------------------------------------------

static double image_mse(const texture_data& image, const texture_data& reference) {
  auto sum = 0.0;
  for (size_t i = 0; i < image.pixels.size(); i++) {
    auto d = image.pixels[i] - reference.pixels[i];
    sum += ((double)d.x * d.x + (double)d.y * d.y + (double)d.z * d.z) / 3;
  }
  return sum / image.pixels.size();
}

TEST(trace, adaptive_sampling_keeps_the_mean_and_spends_where_the_noise_is) {
  // The hair scene at 32x32, 128 spp, a fixed roulette threshold (0.5), one
  // seed: the adaptive render has the uniform one's mean (expect_same_mean:
  // within 4 standard errors; one measured 0.02% of the mean). The sky
  // around the strands has no variance: its pixels take one path every 8
  // samples (the most 128 allows), the strands' up to 16 a sample, and the
  // render casts no more than 5% more rays than the uniform one (the pilot's
  // budget is the uniform render's rays, estimated from 2 paths a pixel).
  auto scene        = make_hair_test_scene();
  auto params       = trace_params{};
  params.resolution = 32;
  params.samples    = 128;
  params.seed       = 23;
  params.roulette_threshold = 0.5f;
  params.split      = 1;  // adaptive sampling alone
  params.adaptive   = trace_adaptive_type::off;
  auto uniform_state = render_scene(scene, params);
  params.adaptive    = trace_adaptive_type::on;
  auto adaptive_state = render_scene(scene, params);
  EXPECT_TRUE(uniform_state.rates.empty());
  ASSERT_EQ(adaptive_state.rates.size(), uniform_state.sums.size());
  auto fewer = 0, more = 0;
  for (auto rate : adaptive_state.rates) {
    EXPECT_TRUE(rate == 0.125f || rate == 0.25f || rate == 0.5f ||
                (rate >= 1 && rate <= 16 && rate == std::round(rate)))
        << rate;
    fewer += rate < 1, more += rate > 1;
  }
  std::printf("[ figure ] adaptive rates: %d pixels below 1, %d above, of %zu\n", fewer, more,
      adaptive_state.rates.size());
  EXPECT_GT(fewer, 0);
  EXPECT_GT(more, 0);
  expect_same_mean(adaptive_state, uniform_state, "adaptive against uniform");
  EXPECT_LT((double)adaptive_state.rays, 1.05 * (double)uniform_state.rays);
}

TEST(trace, adaptive_sampling_lowers_the_error_for_its_rays) {
  // The hair scene at 32x32 against a uniform reference of 2048 spp (another
  // seed): at 64 spp, 3 seeds, the MSE times the rays of adaptive renders
  // with one path per camera ray (measured 0.974x) and of the default plan,
  // each pixel its own split (measured 0.973x), are below the uniform
  // renders'. The plan spends the uniform render's rays, whatever splits it
  // picks (its budget, from the pilot's 2 paths a pixel): within 5% of them.
  auto scene        = make_hair_test_scene();
  auto params       = trace_params{};
  params.resolution = 32;
  params.samples    = 2048;
  params.seed       = 1000;
  params.roulette_threshold = 0.5f;
  params.split      = 1;
  params.adaptive   = trace_adaptive_type::off;
  auto reference    = render_scene(scene, params).image;
  params.samples    = 64;
  auto uniform = 0.0, adaptive = 0.0, planned = 0.0;
  auto uniform_rays = 0.0, planned_rays = 0.0;
  for (auto seed : {1, 2, 3}) {
    params.seed     = (uint64_t)seed;
    params.split    = 1;
    params.adaptive = trace_adaptive_type::off;
    auto one        = render_scene(scene, params);
    uniform += image_mse(one.image, reference) * (double)one.rays;
    uniform_rays += (double)one.rays;
    params.adaptive = trace_adaptive_type::on;
    auto other      = render_scene(scene, params);
    adaptive += image_mse(other.image, reference) * (double)other.rays;
    params.split    = 0;
    auto plan       = render_scene(scene, params);
    planned += image_mse(plan.image, reference) * (double)plan.rays;
    planned_rays += (double)plan.rays;
  }
  std::printf("[ figure ] MSE x rays: uniform %g adaptive %g (%.2fx) planned %g (%.2fx), "
              "planned rays %.3fx uniform's\n",
      uniform, adaptive, adaptive / uniform, planned, planned / uniform,
      planned_rays / uniform_rays);
  EXPECT_LT(adaptive, uniform);
  EXPECT_LT(planned, uniform);
  EXPECT_NEAR(planned_rays / uniform_rays, 1, 0.05);
}

// A glossy wall under a constant sky, filling the frame (every pixel sees
// the same kind of point, and the noise of the coat's lobe choice is even)
// or a sixth of it (the sky's pixels around it have no variance).
static scene_data make_glossy_wall_scene(float size) {
  auto scene = scene_data{};
  scene.cameras.push_back(make_test_camera(2));
  scene.environments.push_back({identity3x4f, {1, 1, 1}, -1});
  scene.shapes.push_back(make_quad_shape({size, size}));
  auto wall      = material_data{};
  wall.type      = material_type::glossy;
  wall.color     = {0.2f, 0.3f, 0.5f};
  wall.roughness = 0.3f;
  scene.materials.push_back(wall);
  scene.instances.push_back({identity3x4f, 0, 0});
  return scene;
}

TEST(trace, pixel_plan_predicts_its_gain_and_splits_where_the_tail_is_noisy) {
  // The plan on a glossy wall under a constant sky (64x64, 16 spp, so that
  // the sky's corners are beyond the plan's windows): filling
  // a sixth of the frame, its rates promise a gain above the wall's that
  // fills the frame (the sky's pixels have no variance), and the sky far
  // from the wall takes one path per camera ray (nothing after its hit to
  // split); filling the frame, the camera's hit varies little against the
  // coat's lobe choice after it, so every pixel splits. The same plan, bit
  // for bit, with 1 and 2 threads, and what a default render uses.
  auto params       = trace_params{};
  params.resolution = 64;
  params.samples    = 16;
  params.threads    = 1;
  auto gains = std::vector<float>{};
  for (auto uneven : {true, false}) {
    auto scene = make_glossy_wall_scene(uneven ? 0.6f : 8.0f);
    auto bvh   = scene_bvh{};
    auto error = std::string{};
    ASSERT_TRUE(make_scene_bvh(bvh, scene, {}, error)) << error;
    auto context   = make_trace_context(scene, params);
    auto threshold = estimate_roulette_threshold(scene, bvh, context, params);
    auto plan      = estimate_pixel_plan(scene, bvh, context, params, threshold);
    auto two       = params;
    two.threads    = 2;
    auto again     = estimate_pixel_plan(scene, bvh, context, two, threshold);
    EXPECT_EQ(again.gain, plan.gain);
    EXPECT_TRUE(again.rates == plan.rates);
    EXPECT_TRUE(again.splits == plan.splits);
    ASSERT_EQ(plan.splits.size(), (size_t)64 * 64);
    auto splits = 0.0;
    for (auto split : plan.splits) {
      EXPECT_GE(split, 1);
      EXPECT_LE(split, 8);
      splits += split;
    }
    std::printf("[ figure ] plan, %s: gain %.4g, mean split %.3g\n",
        uneven ? "a sixth of the frame" : "the whole frame", plan.gain, splits / 4096);
    EXPECT_GE(plan.gain, 1.0f);
    gains.push_back(plan.gain);
    if (uneven) {
      EXPECT_EQ(plan.splits[0], 1);  // a corner: sky, 7 x 7 pixels around
      EXPECT_LT(plan.rates[0], 1.0f);
    } else {
      for (auto split : plan.splits) EXPECT_GT(split, 1);
      // Even noise, planned as near even: the pilot's 2 samples a pixel
      // vary from pixel to pixel, and unshrunk (see estimate_pixel_plan)
      // they gave 59% of the pixels one rate, the others 1/4 to 5 times it
      // (and a predicted gain of 1.45); shrunk, 73% at one rate, the others
      // half or twice it. That rate is below 1 (1/4): the splits (about 7
      // paths a camera ray) are paid from uniform sampling's rays, and
      // rates below 1 are powers of 1/2, coarser steps than above.
      auto counts = std::map<float, int>{};
      for (auto rate : plan.rates) counts[rate]++;
      auto [common, even] = *std::max_element(counts.begin(), counts.end(),
          [](auto& a, auto& b) { return a.second < b.second; });
      std::printf("[ figure ] plan, the whole frame: %d of %d pixels at rate %g\n", (int)even,
          (int)plan.rates.size(), common);
      EXPECT_LT(common, 1.0f);
      EXPECT_GE(even, (int)plan.rates.size() * 2 / 3);
      for (auto rate : plan.rates) {
        EXPECT_GE(rate, common / 2);
        EXPECT_LE(rate, common * 2);
      }
    }
    auto state = trace_state{};
    init_trace_state(state, scene, params);
    trace_samples(state, scene, bvh, context, params, 1);
    EXPECT_EQ(state.adaptive_gain, plan.gain);
    EXPECT_TRUE(state.rates == plan.rates);
    EXPECT_TRUE(state.splits == plan.splits);
  }
  EXPECT_GT(gains[0], gains[1]);
}

TEST(trace, adaptive_images_are_unbiased_at_any_sample_count) {
  // The white sky alone (every path brings exactly 1): no pixel has
  // variance, so every pixel takes one path every q samples, q the largest
  // power of two up to 8 dividing the sample count (8 for 64, 4 for 12, 1
  // for 7); the image is 1 everywhere after any number of samples (a
  // pixel's paths so far, not the samples, divide its sums), here 1, 3 and
  // all.
  auto sky = make_furnace_scene();
  sky.instances.clear();
  for (auto [samples, every] : {std::pair{64, 8}, {12, 4}, {7, 1}}) {
    auto params       = trace_params{};
    params.resolution = 16;
    params.samples    = samples;
    params.adaptive   = trace_adaptive_type::on;
    for (auto count : {1, 3, samples}) {
      auto state = render_scene(sky, params, 0, count);
      ASSERT_EQ(state.rates.size(), (size_t)256);
      for (auto rate : state.rates) EXPECT_EQ(rate, 1.0f / every) << samples;
      for (auto& pixel : state.image.pixels) {
        EXPECT_NEAR(pixel.x, 1, 1e-5f) << samples << " " << count;
        EXPECT_NEAR(pixel.z, 1, 1e-5f) << samples << " " << count;
      }
    }
  }
}

TEST(trace, adaptive_renders_do_not_depend_on_threads) {
  // The hair scene at 32x32, 16 spp, default roulette: the same rates and
  // sums, bit for bit, with 1 and 2 threads.
  auto params       = trace_params{};
  params.resolution = 32;
  params.samples    = 16;
  params.adaptive   = trace_adaptive_type::on;
  params.threads    = 1;
  auto one          = render_scene(make_hair_test_scene(), params);
  params.threads    = 2;
  auto two          = render_scene(make_hair_test_scene(), params);
  EXPECT_FALSE(one.rates.empty());
  EXPECT_TRUE(one.rates == two.rates);
  EXPECT_TRUE(one.splits == two.splits);
  EXPECT_TRUE(one.sums == two.sums);
  EXPECT_EQ(one.rays, two.rays);
}

TEST(trace, adaptive_sample_numbers_are_checked) {
  // Up to 16 paths a sample, numbered in 32 bits: samples x split x 16 must
  // stay within 2^32 (the automatic split counts as its largest, 8).
  auto scene      = make_hair_test_scene();
  auto params     = trace_params{};
  auto error      = std::string{};
  params.adaptive = trace_adaptive_type::on;
  params.split    = 1;
  params.samples  = 1 << 28;
  EXPECT_TRUE(check_trace_params(scene, params, error)) << error;
  params.samples = (1 << 28) + 1;
  EXPECT_FALSE(check_trace_params(scene, params, error));
  EXPECT_NE(error.find("adaptive"), std::string::npos) << error;
  params.split   = 0;
  params.samples = 1 << 25;
  EXPECT_TRUE(check_trace_params(scene, params, error)) << error;
  params.samples = (1 << 25) + 1;
  EXPECT_FALSE(check_trace_params(scene, params, error));
  params.adaptive = trace_adaptive_type::off;
  EXPECT_TRUE(check_trace_params(scene, params, error)) << error;
}

TEST(trace, automatic_split_is_each_pixels_own) {
  // The hair scene (32x32, 16 spp), also under a sun and under a textured
  // sky (a light with area, sampled with MIS): with adaptive sampling and
  // an automatic split every pixel has its own split in 1 ... 8, some hair
  // pixels more than 1, a corner of sky 1; a split that is set is the
  // render's, no pixel's own, with adaptive sampling or without (split 1
  // when none is set).
  auto lit    = make_lit_scene();
  auto sky    = make_hair_test_scene();
  sky.textures     = lit.textures;
  sky.environments = lit.environments;
  for (auto& scene : {make_hair_test_scene(), make_sun_hair_scene(), sky}) {
    auto params       = trace_params{};
    params.resolution = 32;
    params.samples    = 16;
    auto automatic    = render_scene(scene, params);
    ASSERT_EQ(automatic.splits.size(), automatic.sums.size());
    auto most = 0;
    for (auto split : automatic.splits) {
      EXPECT_GE(split, 1);
      EXPECT_LE(split, 8);
      most = std::max(most, (int)split);
    }
    EXPECT_GT(most, 1);
    EXPECT_EQ(automatic.splits[0], 1);
    params.split = 3;
    auto set     = render_scene(scene, params);
    EXPECT_TRUE(set.splits.empty());
    EXPECT_EQ(set.split, 3);
    params.adaptive = trace_adaptive_type::off;
    auto uniform    = render_scene(scene, params);
    EXPECT_TRUE(uniform.splits.empty());
    EXPECT_EQ(uniform.split, 3);
    params.split = 0;
    EXPECT_EQ(render_scene(scene, params).split, 1);
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
  params.hair_sampling.mixture_weight = true;
  auto mixture      = render_scene(scene, params);
  EXPECT_NE(lobe.image.pixels, mixture.image.pixels);
  expect_same_mean(lobe, mixture, "lobe weights against mixture weights");
}

// -----------------------------------------------------------------------------
// AOVS
// -----------------------------------------------------------------------------

// A render with params.aovs (or without): the beauty, its sums and the AOV
// layers.
struct aov_render {
  texture_data             image     = {};
  std::vector<fixed_sum3>  sums      = {};
  std::vector<fixed_sum3>  aov_sums  = {};
  std::vector<image_layer> layers    = {};
  int64_t                  rays      = 0;
  int64_t                  nonfinite = 0;
};

// Renders samples first ... first + params.samples - 1.
static aov_render render_aovs(const scene_data& scene, const trace_params& params, int first = 0) {
  auto bvh   = scene_bvh{};
  auto error = std::string{};
  EXPECT_TRUE(make_scene_bvh(bvh, scene, {}, error)) << error;
  EXPECT_TRUE(check_trace_params(scene, params, error)) << error;
  auto context = make_trace_context(scene, params);
  auto state   = trace_state{};
  init_trace_state(state, scene, params, first);
  trace_samples(state, scene, bvh, context, params, params.samples);
  return {get_image(state), state.sums, state.aov_sums,
      get_aov_layers(state.width, state.height, state.aov_sums, state.samples),
      state.rays.load(), state.nonfinite.load()};
}

// The layer of that name (an exception fails the test if there is none).
static const image_layer& find_layer(const aov_render& render, const std::string& name) {
  for (auto& layer : render.layers)
    if (layer.name == name) return layer;
  throw std::runtime_error("no AOV layer " + name);
}
// Pixel i of a layer of three channels, and of one.
static vec3f layer3(const aov_render& render, const std::string& name, int i) {
  auto& pixels = find_layer(render, name).pixels;
  return {pixels.at(3 * i), pixels.at(3 * i + 1), pixels.at(3 * i + 2)};
}
static float layer1(const aov_render& render, const std::string& name, int i) {
  return find_layer(render, name).pixels.at(i);
}

static const auto hair_lobe_layers = std::array<std::string, 4>{
    "hair_R", "hair_TT", "hair_TRT", "hair_TRRT"};

// The sum of the four lobe layers at pixel i, and of their absolute values.
static vec3f lobe_sum(const aov_render& render, int i, bool absolute = false) {
  auto sum = vec3f{0, 0, 0};
  for (auto& name : hair_lobe_layers)
    sum += absolute ? abs(layer3(render, name, i)) : layer3(render, name, i);
  return sum;
}

// An orthographic camera at z = 5 looking down -z at a 2.4 x 2.4 square
// around the z axis (rays along exactly (0, 0, -1)), four straight fibres of
// radius 0.15 across it (lines, about one per quarter of the image, with
// known tangents: horizontal, tilted towards the camera by atan(1/2), tilted
// and running right to left, and tilted by atan(3/2)), or `only` one of them,
// and, if asked, a matte sphere behind them; a constant white sky.
static const auto aov_fibre_radius = 0.15f;
static const auto aov_fibre_ends   = std::array<std::pair<vec3f, vec3f>, 4>{
    std::pair{vec3f{-2, 0.72f, 0}, vec3f{2, 0.72f, 0}},
    std::pair{vec3f{-2, 0.27f, -1}, vec3f{2, 0.27f, 1}},
    std::pair{vec3f{2, -0.22f, 0.5f}, vec3f{-2, -0.22f, -0.5f}},
    std::pair{vec3f{-2, -0.77f, -3}, vec3f{2, -0.77f, 3}}};
static scene_data make_aov_fibre_scene(
    const hair_material& hair, bool sphere, int only = -1) {
  auto scene  = scene_data{};
  auto camera = camera_data{};
  camera.frame        = translation_frame({0, 0, 5});
  camera.orthographic = true;
  camera.lens         = 0.036f;
  camera.film         = 0.036f;
  camera.focus        = 2.4f;
  camera.aspect       = 1;
  scene.cameras.push_back(camera);
  scene.environments.push_back({identity3x4f, {1, 1, 1}, -1});
  auto fibres = shape_data{};
  for (auto k = 0; k < (int)aov_fibre_ends.size(); k++) {
    if (only >= 0 && k != only) continue;
    auto [root, tip] = aov_fibre_ends[k];
    fibres.lines.push_back({(int)fibres.positions.size(), (int)fibres.positions.size() + 1});
    fibres.positions.insert(fibres.positions.end(), {root, tip});
    fibres.radius.insert(fibres.radius.end(), {aov_fibre_radius, aov_fibre_radius});
  }
  scene.shapes.push_back(fibres);
  auto material = material_data{};
  material.type = material_type::hair;
  material.hair = hair;
  scene.materials.push_back(material);
  scene.instances.push_back({identity3x4f, 0, 0});
  if (sphere) {
    scene.shapes.push_back(make_sphere_shape(64, 1));
    auto matte  = material_data{};
    matte.color = {0.3f, 0.6f, 0.9f};
    scene.materials.push_back(matte);
    scene.instances.push_back({translation_frame({0, 0, -3}), 1, 1});
  }
  return scene;
}

// The hair test scene without its sphere: hair and sky only.
static scene_data make_hair_only_scene() {
  auto scene = make_hair_test_scene();
  scene.instances.pop_back();
  return scene;
}

TEST(trace, aov_layers_are_named_and_sized) {
  // The nine layers in the order of get_aov_layers (albedo, normal, tangent,
  // the four lobes, depth, coverage) with their channels, one value a
  // channel and pixel; none from sums of the wrong size.
  auto params       = trace_params{};
  params.resolution = 8;
  params.samples    = 1;
  params.aovs       = true;
  auto render       = render_aovs(make_hair_test_scene(), params);
  auto expected     = std::vector<std::pair<std::string, std::string>>{{"albedo", "RGB"},
          {"normal", "XYZ"}, {"tangent", "XYZ"}, {"hair_R", "RGB"}, {"hair_TT", "RGB"},
          {"hair_TRT", "RGB"}, {"hair_TRRT", "RGB"}, {"depth", "Z"}, {"coverage", "Y"}};
  ASSERT_EQ(render.layers.size(), expected.size());
  for (size_t k = 0; k < expected.size(); k++) {
    auto& layer    = render.layers[k];
    auto  channels = std::string{};
    for (auto& channel : layer.channels) channels += channel;
    EXPECT_EQ(layer.name, expected[k].first);
    EXPECT_EQ(channels, expected[k].second) << layer.name;
    EXPECT_EQ(layer.pixels.size(), 64 * channels.size()) << layer.name;
  }
  EXPECT_EQ(render.aov_sums.size(), 64u * trace_aov_sums);
  EXPECT_TRUE(get_aov_layers(8, 8, std::vector<fixed_sum3>(64 * trace_aov_sums - 1), 1).empty());
}

TEST(trace, aovs_white_furnace) {
  // White hair (sigma_a = 0, default roughness and tilt) alone under a
  // constant white sky, the hair test scene's curves at 24x24, 4 spp, the
  // lobe-weight path (no lights) and fixed seed. Each hair hit's albedo is 1
  // (sum of A_p = 1 within 1e-6), so the albedo layer equals the coverage
  // within 1e-5: 1 wherever coverage is 1 (and the test needs such pixels).
  // Every path carries all its energy to the sky (the lobe weight of a white
  // fibre is 1), so the beauty is 1 within 1e-4 at every pixel, and the lobe
  // layers sum to the coverage within 1e-4.
  auto scene = make_hair_only_scene();
  scene.environments[0].emission = {1, 1, 1};
  scene.materials[0].hair.has_sigma_a = true;
  scene.materials[0].hair.sigma_a     = {0, 0, 0};
  auto params       = trace_params{};
  params.resolution = 24;
  params.samples    = 4;
  params.seed       = 12;
  params.aovs       = true;
  auto render       = render_aovs(scene, params);
  EXPECT_EQ(render.nonfinite, 0);
  auto covered = 0, partial = 0;
  auto worst_albedo = 0.0f, worst_beauty = 0.0f, worst_lobes = 0.0f;
  for (auto i = 0; i < (int)render.image.pixels.size(); i++) {
    auto coverage = layer1(render, "coverage", i);
    auto albedo   = layer3(render, "albedo", i);
    if (coverage == 1) covered++;
    if (coverage > 0 && coverage < 1) partial++;
    worst_albedo = std::max(worst_albedo, max_component(abs(albedo - coverage)));
    worst_beauty = std::max(worst_beauty, max_component(abs(render.image.pixels[i] - 1.0f)));
    worst_lobes  = std::max(worst_lobes, max_component(abs(lobe_sum(render, i) - coverage)));
    if (coverage == 1) EXPECT_NEAR(min_component(albedo), 1, 1e-5f) << "pixel " << i;
  }
  std::printf("[ figure ] AOV furnace: %d pixels covered, %d partly; worst |albedo - coverage| "
              "%.2g, |beauty - 1| %.2g, |lobes - coverage| %.2g\n",
      covered, partial, worst_albedo, worst_beauty, worst_lobes);
  EXPECT_GT(covered, 10);
  EXPECT_GT(partial, 10);
  EXPECT_LE(worst_albedo, 1e-5f);
  EXPECT_LE(worst_beauty, 1e-4f);
  EXPECT_LE(worst_lobes, 1e-4f);
}

// The brdf of a hit seen along -z, with the lobes of the direction (0, 0, 1)
// to the camera: the fibre frame the tracer builds (x the tangent, z the
// direction to the camera without its tangent part, y = z x x), and the
// offset h read back from the normal (normal = z sqrt(1 - h^2) + y h).
static hair_brdf aov_hit_brdf(const hair_material& material, const vec3f& tangent,
    const vec3f& normal) {
  auto x = tangent;
  auto z = normalize(vec3f{0, 0, 1} - dot(vec3f{0, 0, 1}, x) * x);
  auto y = cross(z, x);
  return eval_hair_brdf(make_hair_precomputed(material), dot(normal, y), frame3f{x, y, z, {}},
      {0, 0, 1});
}

TEST(trace, aov_albedo_is_the_hair_albedo_of_the_hit) {
  // The orthographic fibre scene at 1 spp (each pixel one sample; 32x32, two
  // renders of samples 0 and 1, fixed seed): wherever the sample hit hair
  // (coverage 1), the albedo layer is eval_hair_albedo of the fibre frame and
  // offset h of the hit, rebuilt from the tangent and normal layers, for the
  // camera direction (0, 0, 1); within 1e-4 (h read back from the normal is
  // good to 1e-7, and the albedo's slope in h is below 100 for h within 1 -
  // 1e-4 of the edge). Two materials: melanin 0.8 with default roughness and
  // tilt (2 degrees), and a sigma_a with beta_m 0.1, beta_n 0.7 and alpha 0.
  // The four fibres see theta_o = 0, 0.46, -0.24 and 0.98.
  auto brown      = hair_material{};
  brown.eumelanin = 0.8f;
  auto coloured   = hair_material{};
  coloured.has_sigma_a = true;
  coloured.sigma_a     = {0.2f, 0.6f, 1.5f};
  coloured.beta_m      = 0.1f;
  coloured.beta_n      = 0.7f;
  coloured.alpha       = 0;
  for (auto& material : {brown, coloured}) {
    auto scene        = make_aov_fibre_scene(material, false);
    auto params       = trace_params{};
    params.resolution = 32;
    params.samples    = 1;
    params.seed       = 31;
    params.aovs       = true;
    auto compared = 0;
    auto worst    = 0.0f;
    auto spread   = std::array<float, 2>{1, 0};  // the albedos seen, so that h matters
    for (auto first : {0, 1}) {
      auto render = render_aovs(scene, params, first);
      for (auto i = 0; i < (int)render.image.pixels.size(); i++) {
        if (layer1(render, "coverage", i) != 1) continue;
        auto tangent  = layer3(render, "tangent", i);
        auto normal   = layer3(render, "normal", i);
        auto brdf     = aov_hit_brdf(material, tangent, normal);
        auto expected = clamp(eval_hair_albedo(brdf, {0, 0, 1}), 0.0f, 1.0f);
        auto albedo   = layer3(render, "albedo", i);
        auto error    = max_component(abs(albedo - expected));
        worst         = std::max(worst, error);
        spread        = {std::min(spread[0], albedo.y), std::max(spread[1], albedo.y)};
        compared++;
        EXPECT_LE(error, 1e-4f) << "pixel " << i << " h " << brdf.h << ": albedo ("
                                << albedo.x << ", " << albedo.y << ", " << albedo.z
                                << "), expected (" << expected.x << ", " << expected.y << ", "
                                << expected.z << ")";
      }
    }
    std::printf("[ figure ] AOV albedo of %d hair hits: worst error %.2g, green from %.3f "
                "to %.3f\n", compared, worst, spread[0], spread[1]);
    EXPECT_GT(compared, 100);
    EXPECT_GT(spread[1] - spread[0], 0.05f);
  }
}

TEST(trace, aov_normals_tangents_and_depth_of_first_hits) {
  // The orthographic fibre scene with the sphere behind, 32x32 at 1 spp
  // (two renders, samples 0 and 1; fixed seed). Where the sample hit
  // something (depth > 0): the normal has unit length (1e-5) and faces the
  // camera (dot with (0, 0, 1), the direction to the camera, > 0); the
  // tangent has unit length. Fibres (coverage 1): the tangent is one of the
  // four lines' directions, root to tip (1e-5), and orthogonal to the normal
  // (1e-5); on the horizontal fibre (axis at z = 0) the depth is 5 - r
  // normal.z within 1e-3 (the hit lies on the cylinder where the normal
  // says). The sphere (coverage 0): the tangent is the normal, the depth in
  // [7, 8]. Where the sample escaped everything is 0. Each kind is seen.
  auto scene        = make_aov_fibre_scene(hair_material{}, true);
  auto params       = trace_params{};
  params.resolution = 32;
  params.samples    = 1;
  params.seed       = 7;
  params.aovs       = true;
  auto directions   = std::vector<vec3f>{};
  for (auto& [root, tip] : aov_fibre_ends) directions.push_back(normalize(tip - root));
  auto fibres  = std::array<int, 4>{};
  auto spheres = 0, escaped = 0;
  auto least_facing = 1.0f;
  for (auto first : {0, 1}) {
    auto render = render_aovs(scene, params, first);
    for (auto i = 0; i < (int)render.image.pixels.size(); i++) {
      auto depth    = layer1(render, "depth", i);
      auto coverage = layer1(render, "coverage", i);
      auto normal   = layer3(render, "normal", i);
      auto tangent  = layer3(render, "tangent", i);
      if (depth == 0) {
        escaped++;
        EXPECT_EQ(coverage, 0) << i;
        EXPECT_EQ(normal, (vec3f{0, 0, 0})) << i;
        EXPECT_EQ(tangent, (vec3f{0, 0, 0})) << i;
        EXPECT_EQ(layer3(render, "albedo", i), (vec3f{0, 0, 0})) << i;
        continue;
      }
      EXPECT_NEAR(length(normal), 1, 1e-5f) << i;
      EXPECT_NEAR(length(tangent), 1, 1e-5f) << i;
      EXPECT_GT(normal.z, 0) << "pixel " << i << " coverage " << coverage;
      least_facing = std::min(least_facing, normal.z);
      if (coverage == 1) {
        auto fibre = -1;
        for (auto k = 0; k < 4; k++)
          if (max_component(abs(tangent - directions[k])) <= 1e-5f) fibre = k;
        ASSERT_GE(fibre, 0) << "pixel " << i << ": tangent (" << tangent.x << ", " << tangent.y
                            << ", " << tangent.z << ") is no fibre's, root to tip";
        fibres[fibre]++;
        EXPECT_NEAR(dot(tangent, normal), 0, 1e-5f) << i;
        if (fibre == 0) EXPECT_NEAR(depth, 5 - aov_fibre_radius * normal.z, 1e-3f) << i;
      } else {
        EXPECT_EQ(coverage, 0) << i;
        spheres++;
        EXPECT_EQ(tangent, normal) << i;
        EXPECT_GE(depth, 7 - 1e-3f) << i;
        EXPECT_LE(depth, 8 + 1e-3f) << i;
      }
    }
  }
  std::printf("[ figure ] AOV first hits: fibres %d %d %d %d, sphere %d, sky %d; least "
              "normal.z %.3g\n", fibres[0], fibres[1], fibres[2], fibres[3], spheres, escaped,
      least_facing);
  for (auto k = 0; k < 4; k++) EXPECT_GT(fibres[k], 20) << "fibre " << k;
  EXPECT_GT(spheres, 100);
  EXPECT_GT(escaped, 100);
}

// A ray that runs along a fibre (here every ray of an orthographic camera
// looking down a fibre's axis, lines and curves) meets no side of it: the
// AOV normal is then the tangent towards the camera (the end cap's), not
// eval_fiber_point's arbitrary frame (perpendicular to the view, which the
// AOV of 60c9418 gave). 16x16 at 1 spp: at every pixel whose sample hit the
// fibre's end, the normal must face the camera (normal.z > 0).
TEST(trace, aov_normal_of_a_fibre_seen_end_on_faces_the_camera) {
  for (auto curves : {false, true}) {
    auto scene   = make_aov_fibre_scene(hair_material{}, false);
    auto fibre   = shape_data{};
    for (auto k = 0; k < 4; k++) {
      fibre.positions.push_back({0.3f, 0, 1 - 2 * k / 3.0f});
      fibre.radius.push_back(0.5f);
    }
    if (curves) fibre.curves.push_back({0, 1, 2, 3});
    if (!curves) fibre.lines = {{0, 1}, {1, 2}, {2, 3}};
    scene.shapes[0]   = fibre;
    auto params       = trace_params{};
    params.resolution = 16;
    params.samples    = 1;
    params.aovs       = true;
    auto render       = render_aovs(scene, params);
    auto hits = 0, facing = 0;
    for (auto i = 0; i < (int)render.image.pixels.size(); i++) {
      if (layer1(render, "coverage", i) != 1) continue;
      hits++;
      facing += layer3(render, "normal", i).z > 0;
    }
    EXPECT_GT(hits, 10);
    EXPECT_EQ(facing, hits) << (curves ? "curves" : "lines");
  }
}

TEST(trace, aov_depth_averages_the_hits_and_coverage_counts_hair) {
  // The orthographic fibre scene with the sphere, 32x32 at 16 spp (fixed
  // seed): coverage is a multiple of 1/16 in [0, 1]; pixels where only the
  // horizontal fibre is hit (tangent layer = coverage x (1, 0, 0), no
  // sphere behind: the top quarter) have a depth in [5 - r, 5] (the mean over
  // the samples that hit, not over all samples) even where the coverage is
  // below 1; and pixels with sky and sphere only have coverage 0 and a depth
  // in [7, 8].
  auto scene        = make_aov_fibre_scene(hair_material{}, true);
  auto params       = trace_params{};
  params.resolution = 32;
  params.samples    = 16;
  params.seed       = 3;
  params.aovs       = true;
  params.adaptive   = trace_adaptive_type::off;  // every pixel 16 paths
  auto render       = render_aovs(scene, params);
  auto partial = 0, sphere_only = 0;
  for (auto i = 0; i < (int)render.image.pixels.size(); i++) {
    auto coverage = layer1(render, "coverage", i);
    auto depth    = layer1(render, "depth", i);
    auto tangent  = layer3(render, "tangent", i);
    EXPECT_GE(coverage, 0);
    EXPECT_LE(coverage, 1);
    EXPECT_EQ(coverage * 16, std::round(coverage * 16)) << i;
    auto row = i / 32;
    if (row < 8 && coverage > 0 &&
        max_component(abs(tangent - vec3f{coverage, 0, 0})) <= 1e-5f) {
      if (coverage < 1) partial++;
      EXPECT_GE(depth, 5 - aov_fibre_radius - 1e-3f) << i << " coverage " << coverage;
      EXPECT_LE(depth, 5 + 1e-3f) << i << " coverage " << coverage;
    }
    if (coverage == 0 && depth > 0) {
      sphere_only++;
      EXPECT_GE(depth, 7 - 1e-3f) << i;
      EXPECT_LE(depth, 8 + 1e-3f) << i;
    }
  }
  EXPECT_GT(partial, 10);
  EXPECT_GT(sphere_only, 100);
}

TEST(trace, aov_layers_are_finite_and_in_range) {
  // The hair test scene (hair, a matte sphere) under the lit scene's
  // textured sky, 24x24 at 8 spp, with split 2 and clamp 5 (fixed seed):
  // every value of every layer is finite; coverage in [0, 1]; depth > 0
  // wherever coverage > 0, and 0 only where albedo and normal are 0 too;
  // albedo in [0, 1]; lobes non-negative.
  auto scene = make_hair_test_scene();
  auto lit   = make_lit_scene();
  scene.textures     = lit.textures;
  scene.environments = lit.environments;
  auto params       = trace_params{};
  params.resolution = 24;
  params.samples    = 8;
  params.seed       = 19;
  params.split      = 2;
  params.clamp      = 5;
  params.aovs       = true;
  auto render       = render_aovs(scene, params);
  EXPECT_EQ(render.nonfinite, 0);
  for (auto& layer : render.layers) {
    for (auto value : layer.pixels) ASSERT_TRUE(std::isfinite(value)) << layer.name;
  }
  auto hair = 0, empty = 0;
  for (auto i = 0; i < (int)render.image.pixels.size(); i++) {
    auto coverage = layer1(render, "coverage", i);
    auto depth    = layer1(render, "depth", i);
    auto albedo   = layer3(render, "albedo", i);
    EXPECT_GE(coverage, 0) << i;
    EXPECT_LE(coverage, 1) << i;
    if (coverage > 0) {
      hair++;
      EXPECT_GT(depth, 0) << i;
    }
    if (depth == 0) {
      empty++;
      EXPECT_EQ(albedo, (vec3f{0, 0, 0})) << i;
      EXPECT_EQ(layer3(render, "normal", i), (vec3f{0, 0, 0})) << i;
    }
    EXPECT_GE(min_component(albedo), 0) << i;
    EXPECT_LE(max_component(albedo), 1) << i;
    for (auto& name : hair_lobe_layers) EXPECT_GE(min_component(layer3(render, name, i)), 0);
  }
  EXPECT_GT(hair, 50);
  EXPECT_GT(empty, 20);
}

// Checks, per pixel, that the beauty is the sum of the lobe layers plus what
// the camera sees of the sky directly: under a constant sky E, E (1 -
// coverage); at 1 spp (sky = null) the beauty itself where the sample did
// not hit hair (where the lobes must be 0). Tolerance: 2e-5 times the
// largest of 1, the beauty and the sum of the lobes' absolute values (float
// rounding of the path's sums in two orders). Returns the worst relative
// error and counts the pixels that saw hair.
static double expect_lobes_sum_to_beauty(const aov_render& render, const vec3f* sky,
    const std::string& what, int& hair_pixels) {
  auto worst  = 0.0;
  hair_pixels = 0;
  for (auto i = 0; i < (int)render.image.pixels.size(); i++) {
    auto coverage = layer1(render, "coverage", i);
    auto beauty   = render.image.pixels[i];
    auto lobes    = lobe_sum(render, i);
    if (coverage > 0) hair_pixels++;
    auto direct = vec3f{0, 0, 0};
    if (sky) {
      direct = *sky * (1 - coverage);
    } else if (coverage == 0) {
      EXPECT_EQ(lobe_sum(render, i, true), (vec3f{0, 0, 0})) << what << " pixel " << i;
      continue;
    } else {
      EXPECT_EQ(coverage, 1) << what << ": the check needs 1 spp";
    }
    auto scale = std::max({1.0f, max_component(abs(beauty)),
        max_component(lobe_sum(render, i, true))});
    auto error = max_component(abs(beauty - lobes - direct)) / scale;
    worst      = std::max(worst, (double)error);
    EXPECT_LE(error, 2e-5f) << what << " pixel " << i << ": beauty (" << beauty.x << ", "
                            << beauty.y << ", " << beauty.z << "), lobes (" << lobes.x << ", "
                            << lobes.y << ", " << lobes.z << "), coverage " << coverage;
  }
  std::printf("[ figure ] lobes %s: %d hair pixels, worst relative error %.2g\n", what.c_str(),
      hair_pixels, worst);
  return worst;
}

TEST(trace, aov_lobes_sum_to_the_beauty_of_the_hair) {
  // Hair and sky only (the hair test scene without its sphere), 24x24, fixed
  // seeds: per pixel the lobe layers sum to the beauty minus the sky seen
  // directly (expect_lobes_sum_to_beauty, 2e-5 relative), along every way
  // the tracer splits a path by lobe:
  // - a constant sky at 4 spp: the lobe-weight path (the sampled lobe takes
  //   the rest of the path), the mixture weight (lobes' shares of eval),
  //   --lights all (the sky light-sampled: NEE split by lobe terms) and a
  //   distant light (NEE of a delta light) with BSDF samples finding the sky;
  // - at 1 spp, where a pixel's sample hit hair or not: a textured sky with a
  //   bright spot (NEE, MIS), the same with split 3 and clamp 0.05 (lobes
  //   scaled like the beauty; more than 20 hair pixels are clamped), the
  //   naive sampler (lobe weights, no NEE) and four numbers a hair sample
  //   (the mixture).
  // Each case is rendered twice, from sample 0 and from sample 1.
  struct lobe_case {
    std::string name;
    bool        textured = false;
    bool        distant  = false;
    int         samples  = 4;
    std::function<void(trace_params&)> set = [](trace_params&) {};
  };
  auto cases = std::vector<lobe_case>{
      {"constant sky, lobe weights", false, false, 4},
      {"constant sky, mixture weights", false, false, 4,
          [](trace_params& params) { params.hair_sampling.mixture_weight = true; }},
      {"constant sky, sampled as a light", false, false, 4,
          [](trace_params& params) { params.lights = trace_lights_type::all; }},
      {"constant sky and a distant light", false, true, 4},
      {"textured sky", true, false, 1},
      {"textured sky, split 3, clamp 0.05", true, false, 1,
          [](trace_params& params) { params.split = 3, params.clamp = 0.05f; }},
      {"textured sky, naive", true, false, 1,
          [](trace_params& params) { params.sampler = trace_sampler_type::naive; }},
      {"textured sky, four numbers", true, false, 1,
          [](trace_params& params) { params.hair_sampling.four_numbers = true; }},
  };
  auto lit = make_lit_scene();
  for (auto& test : cases) {
    auto scene = make_hair_only_scene();
    auto sky   = scene.environments[0].emission;
    if (test.textured) {
      scene.textures     = lit.textures;
      scene.environments = lit.environments;
    }
    if (test.distant) scene.distant_lights.push_back({{0.3f, 1, 0.5f}, {3, 2.5f, 2}});
    auto params       = trace_params{};
    params.resolution = 24;
    params.samples    = test.samples;
    params.seed       = 23;
    params.aovs       = true;
    test.set(params);
    auto hair_pixels = 0, clamped = 0;
    auto brightest   = 0.0f;
    for (auto first : {0, 1}) {
      auto render = render_aovs(scene, params, first);
      EXPECT_EQ(render.nonfinite, 0) << test.name;
      expect_lobes_sum_to_beauty(render, test.textured ? nullptr : &sky, test.name, hair_pixels);
      EXPECT_GT(hair_pixels, 100) << test.name;
      // Hair pixels whose sample was clamped (to 1e-6 relative).
      for (auto i = 0; i < (int)render.image.pixels.size(); i++) {
        auto value = max_component(render.image.pixels[i]);
        if (params.clamp == 0 || layer1(render, "coverage", i) != 1) continue;
        brightest = std::max(brightest, value);
        clamped += std::abs(value - params.clamp) <= 1e-6f * params.clamp;
      }
    }
    if (params.clamp == 0) continue;
    std::printf("[ figure ] lobes %s: %d hair pixels clamped, brightest %g\n",
        test.name.c_str(), clamped, brightest);
    EXPECT_GT(clamped, 20) << test.name << ": too few hair pixels clamped";
  }
}

TEST(trace, aov_lobes_of_lobe_and_mixture_weights_agree) {
  // Under a constant sky the lobe-weight path gives all of a path's light
  // after its first hair hit to the lobe it sampled there, the mixture
  // weight splits it by the lobes' shares of eval at the sampled direction:
  // both estimate each lobe's share. Hair and sky only, 24x24 at 512 spp,
  // threshold 0.5, one seed (the two share their directions): per lobe, the
  // mean over pixels of the difference of the two layers is within 4
  // standard errors (mean_difference: pixels are independent samples) of 0,
  // and 4 standard errors stay below 5% of the lobe's image mean (the check
  // has power; TRRT, 0.1% of the light, is checked for the first alone). The
  // lobe layers differ pixel by pixel (the estimators do differ).
  auto scene        = make_hair_only_scene();
  auto params       = trace_params{};
  params.resolution = 24;
  params.samples    = 512;
  params.seed       = 29;
  params.roulette_threshold = 0.5f;
  params.aovs       = true;
  auto lobe         = render_aovs(scene, params);
  params.hair_sampling.mixture_weight = true;
  auto mixture      = render_aovs(scene, params);
  auto layer_image  = [](const aov_render& render, const std::string& name) {
    auto image = texture_data{render.image.width, render.image.height, {}};
    for (auto i = 0; i < (int)render.image.pixels.size(); i++)
      image.pixels.push_back(layer3(render, name, i));
    return image;
  };
  auto total = 0.0;
  for (auto& name : hair_lobe_layers) total += image_mean(layer_image(lobe, name));
  for (auto& name : hair_lobe_layers) {
    auto a = layer_image(lobe, name), b = layer_image(mixture, name);
    auto [difference, error] = mean_difference(a, b);
    auto reference           = image_mean(b);
    std::printf("[ figure ] AOV %s: lobe weights %.5f, mixture %.5f (%.1f%% of the hair's "
                "light), difference %.2e +- %.2e\n",
        name.c_str(), image_mean(a), reference, 100 * reference / total, difference, error);
    EXPECT_LE(std::abs(difference), 4 * error) << name;
    if (name != "hair_TRRT") EXPECT_LT(4 * error, 0.05 * reference) << name;
    EXPECT_NE(a.pixels, b.pixels) << name;
  }
}

TEST(trace, aov_lobes_of_a_lone_fibre_are_the_sky_times_a_p) {
  // One straight fibre (the orthographic scene's second, theta_o = 0.46;
  // melanin 0.8, default roughness and tilt) alone under a constant white
  // sky: it cannot see itself, so the light of a path that hits it is, in
  // expectation, the sky times sum_p A_p at the hit's h, lobe p bringing
  // A_p. 64 renders of one sample (samples 0 ... 63 of 64x64 pixels, fixed
  // seed; 32k hits) give every sample's lobe layers and, from the normal
  // and tangent layers, its A_p (aov_hit_brdf): per lobe and channel the mean of lobe
  // layer - A_p over the samples that hit hair is 0 within 4 standard errors
  // (+ 1e-5), for the lobe-weight path, the mixture weight and the sky
  // sampled as a light (the NEE split); and 4 standard errors stay below 10%
  // of the mean A_p for R and TT, 30% for TRT (the check has power; TRRT,
  // 0.2% of the light, is checked for the first alone).
  auto material      = hair_material{};
  material.eumelanin = 0.8f;
  auto scene         = make_aov_fibre_scene(material, false, 1);
  for (auto mode : {0, 1, 2}) {
    auto params       = trace_params{};
    params.resolution = 64;
    params.samples    = 1;
    params.seed       = 43;
    params.aovs       = true;
    params.hair_sampling.mixture_weight = mode == 1;
    if (mode == 2) params.lights = trace_lights_type::all;
    auto name = std::string(mode == 0   ? "lobe weights"
                            : mode == 1 ? "mixture weights"
                                        : "sky sampled as a light");
    auto sums = std::array<glm::dvec3, 4>{}, sums2 = std::array<glm::dvec3, 4>{};
    auto a_sums = std::array<glm::dvec3, 4>{};
    auto hits   = 0;
    for (auto first = 0; first < 64; first++) {
      auto render = render_aovs(scene, params, first);
      for (auto i = 0; i < (int)render.image.pixels.size(); i++) {
        if (layer1(render, "coverage", i) != 1) continue;
        auto brdf = aov_hit_brdf(
            material, layer3(render, "tangent", i), layer3(render, "normal", i));
        hits++;
        for (auto p = 0; p < 4; p++) {
          auto d = glm::dvec3(layer3(render, hair_lobe_layers[p], i) - brdf.lobes.a[p]);
          sums[p] += d, sums2[p] += d * d;
          a_sums[p] += glm::dvec3(brdf.lobes.a[p]);
        }
      }
    }
    for (auto p = 0; p < 4; p++) {
      auto mean  = sums[p] / (double)hits;
      auto error = sqrt(max(sums2[p] / (double)hits - mean * mean, glm::dvec3(0)) /
                        (double)(hits - 1));
      auto a     = a_sums[p] / (double)hits;
      std::printf("[ figure ] lone fibre, %s, %s: %d hits, mean A_p (%.4f, %.4f, %.4f), "
                  "layer - A_p (%.1e, %.1e, %.1e) +- (%.1e, %.1e, %.1e)\n",
          name.c_str(), hair_lobe_layers[p].c_str(), hits, a.x, a.y, a.z, mean.x, mean.y,
          mean.z, error.x, error.y, error.z);
      for (auto c = 0; c < 3; c++) {
        EXPECT_LE(std::abs(mean[c]), 4 * error[c] + 1e-5) << name << " lobe " << p << " " << c;
        if (p < 3) EXPECT_LT(4 * error[c], (p < 2 ? 0.1 : 0.3) * a[c]) << name << " lobe " << p;
      }
    }
    EXPECT_GT(hits, 10000) << name;
  }
}

TEST(trace, aovs_leave_the_beauty_bit_for_bit) {
  // With params.aovs off the AOV sums stay empty (and give no layers); on,
  // the beauty's sums and the rays are the same, bit for bit: the hair test
  // scene at 16x16, 4 spp, under a constant sky (lobe weights), with mixture
  // weights, under the textured sky (NEE), with split 2 and clamp 1, and
  // with the naive sampler.
  auto lit      = make_lit_scene();
  auto constant = make_hair_test_scene();
  auto textured = constant;
  textured.textures     = lit.textures;
  textured.environments = lit.environments;
  auto base       = trace_params{};
  base.resolution = 16;
  base.samples    = 4;
  base.seed       = 37;
  auto cases = std::vector<std::pair<bool, trace_params>>{};
  for (auto k = 0; k < 5; k++) {
    auto params = base;
    if (k == 1) params.hair_sampling.mixture_weight = true;
    if (k == 3) params.split = 2, params.clamp = 1;
    if (k == 4) params.sampler = trace_sampler_type::naive;
    cases.push_back({k >= 2, params});
  }
  for (auto& [sky, params] : cases) {
    auto& scene = sky ? textured : constant;
    auto  off   = render_aovs(scene, params);
    auto  with  = params;
    with.aovs   = true;
    auto on     = render_aovs(scene, with);
    EXPECT_TRUE(off.aov_sums.empty());
    EXPECT_TRUE(off.layers.empty());
    EXPECT_EQ(on.aov_sums.size(), on.sums.size() * trace_aov_sums);
    EXPECT_TRUE(on.sums == off.sums) << "split " << params.split << " sampler "
                                     << (int)params.sampler << " textured " << sky;
    EXPECT_EQ(on.rays, off.rays);
  }
}

TEST(trace, lobe_guide_keeps_the_mean_and_lowers_the_noise) {
  // The walled curtain (its hair lit by the sky through the camera's side,
  // a black wall behind), 24x24, adaptive sampling off: hair lobes chosen
  // half by the roulette cache's worth of their directions (lobe_guide 0.5)
  // against the luminance choice alone (0).
  // - The same mean at 1024 spp: within 4 standard errors of the pixels'
  //   differences, which are below 2% of the mean (the image is dark: most
  //   of it is the wall).
  // - 16 spp, 8 seeds: the pixels' variance across seeds times the rays cast
  //   (the cost) below 0.8 times the unguided one (measured 0.5: tails into
  //   the wall are chosen less often).
  // - The guide needs the cache: with it off, the guide does nothing (the
  //   same bits as guide 0).
  auto scene        = make_walled_hair_scene();
  auto params       = trace_params{};
  params.resolution = 24;
  params.adaptive   = trace_adaptive_type::off;
  params.samples    = 1024;
  params.seed       = 47;
  params.lobe_guide = 0.5f;
  auto guided       = render_scene(scene, params);
  params.lobe_guide = 0;
  auto plain        = render_scene(scene, params);
  EXPECT_NE(guided.image.pixels, plain.image.pixels);
  auto [difference, error] = mean_difference(guided.image, plain.image);
  auto reference           = image_mean(plain.image);
  std::printf("[ figure ] lobe guide 0.5 against none: means %g and %g, difference %.2e +- %.2e\n",
      image_mean(guided.image), reference, difference, error);
  EXPECT_EQ(guided.nonfinite, 0);
  EXPECT_LE(std::abs(difference), 4 * error);
  EXPECT_LT(4 * error, 0.02 * reference);
  params.samples    = 16;
  params.lobe_guide = 0.5f;
  auto unguided       = params;
  unguided.lobe_guide = 0;
  EXPECT_LT(variance_times_rays_ratio(scene, params, unguided, "lobe guide"), 0.8);
  // The share is checked: in [0, 0.95], so that every lobe keeps a chance.
  auto message = std::string{};
  for (auto share : {0.0f, 0.5f, 0.95f}) {
    params.lobe_guide = share;
    EXPECT_TRUE(check_trace_params(scene, params, message)) << share << ": " << message;
  }
  for (auto share : {-0.1f, 0.96f, 1.0f, std::numeric_limits<float>::quiet_NaN()}) {
    params.lobe_guide = share;
    message           = "";
    EXPECT_FALSE(check_trace_params(scene, params, message)) << share;
    EXPECT_NE(message.find("lobe guide"), std::string::npos) << message;
  }
  params.samples        = 4;
  params.seed           = 5;
  params.lobe_guide     = 0.5f;
  params.roulette_cache = false;
  auto without_cache    = render_scene(scene, params);
  params.lobe_guide     = 0;
  EXPECT_EQ(render_scene(scene, params).image.pixels, without_cache.image.pixels);
}
