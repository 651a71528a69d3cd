//
// Hair in the full renderer: the white furnace with multiple scattering, the
// frame and offset h wiring through real Embree hits, and every generated
// style rendering without NaN or Inf.
//

#include <gtest/gtest.h>
#include <unistd.h>
#include <yocto/yocto_hairgen.h>
#include <yocto/yocto_pbrtio.h>
#include <yocto/yocto_trace.h>

#include <cmath>
#include <filesystem>
#include <fstream>

using namespace yocto;

static texture_data render_image(const scene_data& scene, const trace_params& params,
    int64_t* nonfinite = nullptr) {
  auto bvh   = scene_bvh{};
  auto error = std::string{};
  EXPECT_TRUE(make_scene_bvh(bvh, scene, {}, error)) << error;
  auto context = make_trace_context(scene);
  auto state   = trace_state{};
  init_trace_state(state, scene, params);
  trace_samples(state, scene, bvh, context, params, params.samples);
  if (nonfinite) *nonfinite = state.nonfinite;
  return get_image(state);
}

// Non-absorbing hair alone in a constant white environment: light is only
// redistributed, so every pixel converges to 1. This checks the cosine
// convention, the frame and h at fiber hits, the ray offsets that let paths
// leave a fiber, MIS weights, and multiple scattering between fibers.
TEST(render, hair_white_furnace_every_pixel_is_one) {
  for (auto [beta_m, beta_n] : {std::pair{0.3f, 0.3f}, std::pair{0.1f, 0.6f}}) {
    auto style     = hair_style_params{};
    style.style    = hair_style::block;
    style.strands  = 400;
    style.radius   = 0.005f;
    auto hair      = hair_material{};
    hair.has_sigma_a = true;
    hair.sigma_a   = {0, 0, 0};
    hair.beta_m    = beta_m;
    hair.beta_n    = beta_n;
    auto scene     = make_hair_scene(style, hair);
    scene.instances.resize(1);  // the fibers only
    scene.environments[0].emission_tex = -1;
    // Look at the block's face from the front, the view filled by fibers.
    scene.cameras[0].frame  = lookat_frame({0.5f, -3, 0.5f}, {0.5f, 0.5f, 0.5f}, {0, 0, 1});
    scene.cameras[0].lens   = 0.15f;
    scene.cameras[0].aspect = 2;
    // 400 fibers of radius 0.005 in the unit cube: paths scatter several
    // times and escape. 6x3 pixels, 16384 spp: every pixel within 1%, the
    // mean within 0.3%.
    auto params       = trace_params{};
    params.resolution = 6;
    params.samples    = 16384;
    params.bounces    = 4096;  // paths end by Russian roulette, not truncation
    params.clamp      = 0;
    auto nonfinite    = (int64_t)0;
    auto image        = render_image(scene, params, &nonfinite);
    EXPECT_EQ(nonfinite, 0);
    auto sum = 0.0, worst = 0.0;
    for (auto& p : image.pixels) {
      sum += mean(p);
      worst = std::max(worst, (double)max_component(abs(p - vec3f{1, 1, 1})));
    }
    std::printf("hair furnace beta_m %.1f beta_n %.1f: mean %.5f, worst pixel deviation %.4f\n",
        beta_m, beta_n, sum / image.pixels.size(), worst);
    EXPECT_NEAR(sum / image.pixels.size(), 1, 0.003) << beta_m << " " << beta_n;
    EXPECT_LT(worst, 0.01) << beta_m << " " << beta_n;
  }
}

// A straight fiber hit through Embree at several offsets: with low roughness
// and no tilt, sampled R-lobe directions follow the mirror reflection off the
// cylinder's surface at that offset.
TEST(render, hair_r_lobe_follows_the_mirror_reflection_at_h) {
  auto scene = scene_data{};
  auto shape = shape_data{};
  shape.positions = {{-2, 0, 0}, {-0.6f, 0, 0}, {0.6f, 0, 0}, {2, 0, 0}};
  shape.radius    = {0.1f, 0.1f, 0.1f, 0.1f};
  shape.curves    = {{0, 1, 2, 3}};
  scene.shapes.push_back(shape);
  scene.materials.push_back({});
  auto frame = rotation_frame({0.3f, 0.5f, 1}, 0.8f);  // not axis-aligned
  scene.instances.push_back({frame, 0, 0});
  auto bvh   = scene_bvh{};
  auto error = std::string{};
  ASSERT_TRUE(make_scene_bvh(bvh, scene, {}, error)) << error;

  auto material  = hair_material{};
  material.beta_m = 0.02f;
  material.beta_n = 0.02f;
  material.alpha  = 0;
  auto rng = make_rng(3);
  for (auto offset : {-0.8f, -0.4f, 0.0f, 0.3f, 0.7f}) {
    // A ray perpendicular to the fiber, offset along the fiber's local y.
    auto origin = transform_point(frame, {0.2f, offset * 0.1f, 3});
    auto ray    = ray3f{origin, transform_direction(frame, {0, 0, -1})};
    auto hit    = intersect_scene_bvh(bvh, ray);
    ASSERT_TRUE(hit.hit);
    auto fiber = eval_fiber_point(scene, scene.instances[0], hit.element, hit.uv.x, ray, hit.distance);
    EXPECT_NEAR(fiber.h, offset, 2e-3f);
    auto brdf     = eval_hair_brdf(material, fiber.h, fiber.frame);
    auto outgoing = -ray.d;
    // The mirror direction off the true surface normal at the hit.
    auto surface = fiber.position - fiber.axis;
    surface      = normalize(surface - dot(surface, fiber.tangent) * fiber.tangent);
    auto mirror  = reflect(outgoing, surface);
    // First random number 0 picks the R lobe; average 200 samples.
    auto average = vec3f{0, 0, 0};
    for (auto i = 0; i < 200; i++) {
      auto more = rand3f(rng);
      average += sample_hair_scattering(brdf, outgoing, vec4f{0, more.x, more.y, more.z});
    }
    average = normalize(average);
    EXPECT_GT(dot(average, mirror), std::cos(radians(3))) << "h = " << offset;
    // and not the mirror off the opposite offset (the sign matters)
    if (std::abs(offset) > 0.2f) {
      auto flipped = fiber.frame.z * safe_sqrt(1 - sqr(offset)) - fiber.frame.y * offset;
      EXPECT_LT(dot(average, reflect(outgoing, flipped)), std::cos(radians(10)));
    }
  }
}

TEST(render, every_style_renders_without_nan_or_inf) {
  for (auto style : {hair_style::straight, hair_style::curly, hair_style::curls,
           hair_style::block, hair_style::fur}) {
    auto params       = hair_style_params{};
    params.style      = style;
    params.strands    = 300;
    auto scene        = make_hair_scene(params, hair_material{});
    auto trace        = trace_params{};
    trace.resolution  = 48;
    trace.samples     = 4;
    auto nonfinite    = (int64_t)0;
    auto image        = render_image(scene, trace, &nonfinite);
    EXPECT_EQ(nonfinite, 0) << hair_style_names[(int)style];
    auto sum = 0.0;
    for (auto& p : image.pixels) {
      ASSERT_TRUE(isfinite(p)) << hair_style_names[(int)style];
      ASSERT_GE(min_component(p), 0) << hair_style_names[(int)style];
      sum += mean(p);
    }
    EXPECT_GT(sum, 0) << hair_style_names[(int)style];
  }
}

TEST(render, generator_is_deterministic_and_strands_are_chained) {
  auto params    = hair_style_params{};
  params.style   = hair_style::curly;
  params.strands = 50;
  auto a = make_hair_strands(params), b = make_hair_strands(params);
  EXPECT_EQ(a.positions, b.positions);
  EXPECT_EQ(a.radius, b.radius);
  // The first strands do not depend on how many strands there are.
  params.strands = 20;
  auto c         = make_hair_strands(params);
  EXPECT_TRUE(std::equal(c.positions.begin(), c.positions.end(), a.positions.begin()));
  // Segments of a strand share end points; radius tapers to 20% at the tip.
  auto per_strand = (int)a.curves.size() / 50;
  for (auto s = 0; s < 50; s++) {
    for (auto k = 1; k < per_strand; k++)
      EXPECT_EQ(a.curves[s * per_strand + k].x, a.curves[s * per_strand + k - 1].w);
    auto root = a.radius[a.curves[s * per_strand].x];
    auto tip  = a.radius[a.curves[s * per_strand + per_strand - 1].w];
    EXPECT_NEAR(tip / root, 0.2f, 1e-5f);
  }
}

// The benchmark fur ball: straight strands on the unit sphere, tilted at
// most 30 degrees off the normal, 0.35 long within 15%, 0.01 to 0.002 thick.
TEST(render, fur_style_is_a_ball_of_straight_strands) {
  auto params    = hair_style_params{};
  params.style   = hair_style::fur;
  params.strands = 2000;
  auto shape     = make_hair_strands(params);
  ASSERT_EQ(hair_strand_segments(params), 3);
  ASSERT_EQ(shape.curves.size(), 2000 * 3);
  auto mean_root = vec3f{0, 0, 0};
  for (auto s = 0; s < params.strands; s++) {
    auto root      = shape.positions[shape.curves[s * 3].x];
    auto tip       = shape.positions[shape.curves[s * 3 + 2].w];
    auto direction = normalize(tip - root);
    EXPECT_NEAR(length(root), 1, 1e-4f) << s;
    EXPECT_GE(length(tip - root), 0.35f * 0.85f - 1e-4f) << s;
    EXPECT_LE(length(tip - root), 0.35f * 1.15f + 1e-4f) << s;
    EXPECT_LE(degrees(std::acos(std::min(dot(direction, normalize(root)), 1.0f))), 30.01f) << s;
    // Straight: every control point on the root-tip line.
    for (auto k = 0; k < 3; k++) {
      auto curve = shape.curves[s * 3 + k];
      for (auto i : {curve.x, curve.y, curve.z, curve.w}) {
        auto q = shape.positions[i] - root;
        EXPECT_LT(length(q - dot(q, direction) * direction), 1e-5f) << s;
      }
    }
    EXPECT_FLOAT_EQ(shape.radius[shape.curves[s * 3].x], 0.01f) << s;
    EXPECT_FLOAT_EQ(shape.radius[shape.curves[s * 3 + 2].w], 0.002f) << s;
    mean_root += root;
  }
  // Uniform roots: each coordinate's mean has a standard deviation of
  // 1 / sqrt(3 * 2000) = 0.013, so the mean is within 0.05 unless the roots
  // cluster.
  EXPECT_LT(length(mean_root / (float)params.strands), 0.05f);

  auto scene = make_hair_scene(params, hair_material{});
  ASSERT_EQ(scene.instances.size(), 2);
  EXPECT_EQ(scene.instances[0].frame, identity3x4f);
  EXPECT_EQ(scene.materials[scene.instances[0].material].type, material_type::hair);
  auto& ball = scene.materials[scene.instances[1].material];
  EXPECT_EQ(ball.type, material_type::matte);
  EXPECT_EQ(ball.color, (vec3f{0.5f, 0.5f, 0.5f}));
  EXPECT_NEAR(max_component(compute_bounds(scene.shapes[scene.instances[1].shape]).max), 1, 1e-4f);
  ASSERT_EQ(scene.environments.size(), 1);
  EXPECT_EQ(scene.environments[0].emission, (vec3f{1, 1, 1}));
  EXPECT_EQ(scene.environments[0].emission_tex, -1);
  EXPECT_TRUE(scene.textures.empty());
  // The camera looks at the ball, and the farthest tip still lands inside the
  // frame.
  ASSERT_EQ(scene.cameras.size(), 1);
  auto& camera = scene.cameras[0];
  auto  centre = project_camera_point(camera, {0, 0, 0});
  EXPECT_NEAR(centre.x, 0.5f, 1e-5f);
  EXPECT_NEAR(centre.y, 0.5f, 1e-5f);
  for (auto& p : shape.positions) {
    auto uv = project_camera_point(camera, p);
    EXPECT_GT(std::min(uv.x, uv.y), 0.02f);
    EXPECT_LT(std::max(uv.x, uv.y), 0.98f);
  }
}

TEST(render, pbrt_curves_are_written_through_a_unique_temporary) {
  // Another writer's temporary under the old fixed name (filename + ".tmp")
  // must be neither used nor removed.
  auto dir = std::filesystem::temp_directory_path() /
             ("yocto-render-tmp-" + std::to_string(getpid()));
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  auto params    = hair_style_params{};
  params.strands = 3;
  auto shape     = make_hair_strands(params);
  for (auto name : {"h.pbrt", "h.pbrt.gz"}) {
    auto filename = (dir / name).string();
    std::ofstream(filename + ".tmp") << "another writer";
    auto error = std::string{};
    EXPECT_TRUE(save_pbrt_curves(filename, shape, error)) << error;
    EXPECT_TRUE(std::filesystem::is_regular_file(filename)) << filename;
    auto other = std::ifstream(filename + ".tmp");
    auto text  = std::string(std::istreambuf_iterator<char>(other), {});
    EXPECT_EQ(text, "another writer") << filename;
  }
  // Only the outputs and the other writer's files: no temporary left.
  auto count = 0;
  for (auto& entry : std::filesystem::directory_iterator(dir)) count += entry.exists();
  EXPECT_EQ(count, 4);
  std::filesystem::remove_all(dir);
}
