//
// Tests of what the benchmark relies on: recording a render's rays does not
// change the render and records exactly the rays it counts; replaying them
// through Embree alone is deterministic; the single-level BVH of identity
// instances finds the same hits as Embree instancing; per-hit hair material
// terms give the image of per-material ones.
//

#include <gtest/gtest.h>
#include <yocto/yocto_hairgen.h>
#include <yocto/yocto_trace.h>

using namespace yocto;

// A small generated hair scene (curls, 60 strands) with a sphere instanced
// away from the origin, so that the BVH holds flat and instanced shapes.
static scene_data make_bench_scene() {
  auto style     = hair_style_params{};
  style.style    = hair_style::curls;
  style.strands  = 60;
  style.segments = 8;
  auto scene     = make_hair_scene(style, hair_material{});
  auto sphere    = (int)scene.shapes.size();
  scene.shapes.push_back(make_sphere_shape(32, 0.5f));
  auto moved = identity3x4f;
  moved.o    = {-4, 9, 0};
  scene.instances.push_back({moved, sphere, 0});
  return scene;
}

static trace_params make_bench_params() {
  auto params       = trace_params{};
  params.resolution = 48;
  params.samples    = 2;
  params.threads    = 2;
  return params;
}

struct bench_setup {
  scene_data    scene   = {};
  scene_bvh     bvh     = {};
  trace_context context = {};
  trace_params  params  = {};
};

static bench_setup make_setup(const bvh_params& bparams = {}) {
  auto setup   = bench_setup{};
  setup.scene  = make_bench_scene();
  setup.params = make_bench_params();
  auto error   = std::string{};
  EXPECT_TRUE(make_scene_bvh(setup.bvh, setup.scene, bparams, error)) << error;
  setup.context = make_trace_context(setup.scene);
  return setup;
}

TEST(bench, recording_rays_keeps_the_image_and_counts_every_ray) {
  auto  setup = make_setup();
  auto& [scene, bvh, context, params] = setup;
  auto  rendered = trace_state{};
  init_trace_state(rendered, scene, params);
  trace_samples(rendered, scene, bvh, context, params, params.samples);
  auto recorded = trace_state{};
  init_trace_state(recorded, scene, params);
  auto rays = record_trace_rays(recorded, scene, bvh, context, params, params.samples);
  EXPECT_EQ((int64_t)rays.size(), rendered.rays.load());
  EXPECT_EQ(recorded.rays.load(), rendered.rays.load());
  EXPECT_EQ(get_image(recorded).pixels, get_image(rendered).pixels);
  // Camera rays come first in each path; a hair scene also has shadow rays.
  auto shadows = (int64_t)0;
  for (auto& ray : rays) shadows += ray.any_hit;
  EXPECT_GT(shadows, 0);
  EXPECT_LT(shadows, (int64_t)rays.size());
}

TEST(bench, recorded_rays_are_the_same_at_one_and_two_threads) {
  // The lambdas use setup's members: a structured binding cannot be
  // captured before C++20 (clang refuses).
  auto setup  = make_setup();
  auto record = [&](int threads) {
    auto state      = trace_state{};
    auto tparams    = setup.params;
    tparams.threads = threads;
    init_trace_state(state, setup.scene, tparams);
    return record_trace_rays(
        state, setup.scene, setup.bvh, setup.context, tparams, tparams.samples);
  };
  auto one = record(1), two = record(2);
  ASSERT_EQ(one.size(), two.size());
  for (auto i = 0; i < (int)one.size(); i++) {
    ASSERT_EQ(one[i].any_hit, two[i].any_hit) << i;
    ASSERT_EQ(one[i].ray.o, two[i].ray.o) << i;
    ASSERT_EQ(one[i].ray.d, two[i].ray.d) << i;
  }
}

TEST(bench, casting_rays_alone_counts_the_hits_of_single_queries) {
  auto  setup = make_setup();
  auto& [scene, bvh, context, params] = setup;
  auto  state = trace_state{};
  init_trace_state(state, scene, params);
  auto rays     = record_trace_rays(state, scene, bvh, context, params, params.samples);
  auto expected = (int64_t)0;
  for (auto& ray : rays)
    expected += ray.any_hit ? intersect_scene_bvh_any(bvh, ray.ray)
                            : intersect_scene_bvh(bvh, ray.ray).hit;
  EXPECT_GT(expected, 0);
  EXPECT_EQ(cast_trace_rays(bvh, rays, 1), expected);
  EXPECT_EQ(cast_trace_rays(bvh, rays, 2), expected);
}

TEST(bench, flat_and_instanced_bvh_find_the_same_hits) {
  auto flat      = make_setup();
  auto instanced = make_setup(bvh_params{false, false, false});
  auto& [scene, bvh, context, params] = flat;
  auto state = trace_state{};
  init_trace_state(state, scene, params);
  auto rays = record_trace_rays(state, scene, bvh, context, params, params.samples);
  // Both instances must be hit for the check to mean anything.
  auto hit_instances = std::vector<int>(scene.instances.size(), 0);
  for (auto& ray : rays) {
    auto a = intersect_scene_bvh(flat.bvh, ray.ray);
    auto b = intersect_scene_bvh(instanced.bvh, ray.ray);
    ASSERT_EQ(a.hit, b.hit);
    if (!a.hit) continue;
    ASSERT_EQ(a.instance, b.instance);
    ASSERT_EQ(a.element, b.element);
    // Instancing transforms the ray: the distance agrees to float precision.
    ASSERT_NEAR(a.distance, b.distance, 1e-4f * std::max(1.0f, a.distance));
    hit_instances[a.instance]++;
    ASSERT_EQ(intersect_scene_bvh_any(flat.bvh, ray.ray),
        intersect_scene_bvh_any(instanced.bvh, ray.ray));
  }
  for (auto i = 0; i < (int)hit_instances.size(); i++)
    if (!scene.shapes[scene.instances[i].shape].curves.empty() ||
        i + 1 == (int)scene.instances.size())
      EXPECT_GT(hit_instances[i], 0) << "instance " << i;
}

TEST(bench, per_hit_hair_terms_give_the_per_material_image) {
  auto setup  = make_setup();
  auto render = [&](bool per_hit) {
    auto tparams         = setup.params;
    tparams.hair_sampling.per_hit = per_hit;
    auto state           = trace_state{};
    init_trace_state(state, setup.scene, tparams);
    trace_samples(state, setup.scene, setup.bvh, setup.context, tparams, tparams.samples);
    return get_image(state);
  };
  EXPECT_EQ(render(true).pixels, render(false).pixels);
}
