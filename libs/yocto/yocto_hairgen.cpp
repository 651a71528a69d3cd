//
// Implementation of Yocto/HairGen.
//

#include "yocto_hairgen.h"

#include <cmath>

#include "yocto_sampling.h"

// -----------------------------------------------------------------------------
// STRANDS
// -----------------------------------------------------------------------------
namespace yocto {

// Keeps a point at least `offset` times the radius away from the head center.
static vec3f push_out_of_head(const vec3f& p, float offset) {
  auto d = p - hair_head_center;
  auto l = length(d);
  if (l >= hair_head_radius * offset) return p;
  if (l == 0) return hair_head_center + vec3f{0, hair_head_radius * offset, 0};
  return hair_head_center + d / l * (hair_head_radius * offset);
}

// A root on the scalp: the head's upper part, none on the face side (+z below
// the hairline, as in Cem Yuksel's models, which scenes view from -z).
static vec3f sample_scalp(rng_state& rng) {
  while (true) {
    auto n = sample_sphere(rand2f(rng));
    if (n.y < -0.2f) continue;
    if (n.z > 0.55f && n.y < 0.45f) continue;  // face
    return n;
  }
}

// A strand that grows from the scalp, lies down along the head under its
// weight and falls from it; curly strands add a helix around that path.
static std::vector<vec3f> make_head_strand(rng_state& rng, int npoints, bool curly) {
  auto normal  = sample_scalp(rng);
  auto strand_length = (curly ? 9.0f : 11.0f) * (0.85f + 0.3f * rand1f(rng));
  auto step    = strand_length / (npoints - 1);
  auto gravity = vec3f{0, -1, 0};
  // Start along the scalp, downhill; on the crown, away from the parting.
  auto downhill = gravity - dot(gravity, normal) * normal;
  if (length(downhill) < 0.2f) downhill = vec3f{normal.x >= 0 ? 1.0f : -1.0f, 0, -0.4f};
  auto d    = normalize(safe_normalize(downhill) + normal * 0.3f);
  auto p    = hair_head_center + normal * (hair_head_radius * 1.01f);
  auto path = std::vector<vec3f>{p};
  for (auto k = 1; k < npoints; k++) {
    auto jitter = (rand3f(rng) - 0.5f) * 0.1f;
    d           = normalize(d * 0.7f + gravity * 0.3f + jitter);
    p           = push_out_of_head(p + d * step, 1.02f + 0.06f * (float)k / npoints);
    path.push_back(p);
  }
  if (!curly) return path;
  // Curls: a helix around the path, radius and period varying per strand,
  // growing from nothing at the root.
  auto curl_radius = 0.3f + 0.3f * rand1f(rng);
  auto period      = 1.4f + 0.8f * rand1f(rng);
  auto phase       = 2 * pif * rand1f(rng);
  auto curled      = std::vector<vec3f>{path[0]};
  for (auto k = 1; k < npoints; k++) {
    auto along  = safe_normalize(path[k] - path[k - 1]);
    auto basis  = basis_fromz(along);
    auto angle  = phase + 2 * pif * (k * step) / period;
    auto ramp   = std::min(1.0f, k * step / 1.5f);
    auto offset = (basis[0] * std::cos(angle) + basis[1] * std::sin(angle)) * curl_radius * ramp;
    curled.push_back(push_out_of_head(path[k] + offset, 1.01f));
  }
  return curled;
}

// A strand of a lock of curls: a helix hanging from the lock's root, each
// strand offset within the lock's cross-section.
static std::vector<vec3f> make_lock_strand(rng_state& rng, int npoints) {
  auto top      = vec3f{-4, 11.5f, 0};
  auto length   = 10.0f * (0.92f + 0.08f * rand1f(rng));
  auto radius   = 0.8f;
  auto period   = 2.4f;
  auto r        = 0.38f * std::sqrt(rand1f(rng));
  auto a        = 2 * pif * rand1f(rng);
  auto points   = std::vector<vec3f>{};
  for (auto k = 0; k < npoints; k++) {
    auto t     = length * k / (npoints - 1);
    auto angle = 2 * pif * t / period;
    // The helix widens a little towards the tip, as a lock under its weight.
    auto helix = radius * std::min(1.0f, t / 1.2f) * (1 + 0.15f * t / length);
    auto side  = vec3f{std::cos(angle), 0, std::sin(angle)};
    auto out   = vec3f{-std::sin(angle), 0, std::cos(angle)};
    auto noise = (rand3f(rng) - 0.5f) * 0.04f;
    points.push_back(top + vec3f{0, -t, 0} + side * (helix + r * std::cos(a)) +
                     out * (r * std::sin(a)) + vec3f{0, 0.25f * r * std::sin(a + angle), 0} +
                     noise);
  }
  return points;
}

// A fiber of the block: straight along z through the unit cube.
static std::vector<vec3f> make_block_fiber(rng_state& rng, int index, int count, int npoints) {
  auto side = std::max(1, (int)std::ceil(std::sqrt((float)count)));
  auto cell = 1.0f / side;
  auto x    = (index % side + 0.2f + 0.6f * rand1f(rng)) * cell;
  auto y    = (index / side + 0.2f + 0.6f * rand1f(rng)) * cell;
  auto points = std::vector<vec3f>{};
  for (auto k = 0; k < npoints; k++) points.push_back({x, y, (float)k / (npoints - 1)});
  return points;
}

// A strand of the fur ball: straight from a root on the unit sphere, tilted
// up to 30 degrees away from the normal, 0.35 long give or take 15%.
static std::vector<vec3f> make_fur_strand(rng_state& rng, int npoints) {
  auto normal        = sample_sphere(rand2f(rng));
  auto strand_length = 0.35f * (0.85f + 0.3f * rand1f(rng));
  auto tilt          = radians(30.0f) * rand1f(rng);
  auto azimuth       = 2 * pif * rand1f(rng);
  auto basis         = basis_fromz(normal);
  auto direction     = (basis[0] * std::cos(azimuth) + basis[1] * std::sin(azimuth)) *
                       std::sin(tilt) + normal * std::cos(tilt);
  auto points = std::vector<vec3f>{};
  for (auto k = 0; k < npoints; k++)
    points.push_back(normal + direction * (strand_length * k / (npoints - 1)));
  return points;
}

int hair_strand_segments(const hair_style_params& params) {
  auto defaults = std::array<int, 5>{8, 24, 40, 1, 3};
  return params.segments > 0 ? params.segments : defaults[(int)params.style];
}

shape_data make_hair_strands(const hair_style_params& params) {
  auto shape    = shape_data{};
  auto radii    = std::array<float, 5>{0.012f, 0.01f, 0.008f, 0.003f, 0.01f};
  auto style    = (int)params.style;
  auto segments = hair_strand_segments(params);
  auto radius   = params.radius > 0 ? params.radius : radii[style];
  auto npoints  = segments + 1;
  shape.positions.reserve((size_t)params.strands * (3 * segments + 1));
  shape.radius.reserve(shape.positions.capacity());
  shape.curves.reserve((size_t)params.strands * segments);
  for (auto s = 0; s < params.strands; s++) {
    // One stream per strand: the same strand whatever the strand count.
    auto rng    = make_rng(params.seed, 2 * (uint64_t)s + 1);
    auto points = std::vector<vec3f>{};
    switch (params.style) {
      case hair_style::straight: points = make_head_strand(rng, npoints, false); break;
      case hair_style::curly: points = make_head_strand(rng, npoints, true); break;
      case hair_style::curls: points = make_lock_strand(rng, npoints); break;
      case hair_style::block:
        points = make_block_fiber(rng, s, params.strands, npoints);
        break;
      case hair_style::fur: points = make_fur_strand(rng, npoints); break;
    }
    // Radius tapering linearly from the root to a fifth at the tip (blocks
    // of fibers keep theirs).
    auto tip   = params.style == hair_style::block ? radius : radius * 0.2f;
    auto radii = std::vector<float>(points.size());
    for (size_t i = 0; i < radii.size(); i++) {
      radii[i] = radius + (tip - radius) * (float)i / std::max((int)radii.size() - 1, 1);
    }
    append_catmull_rom_strand(shape, points, radii);
  }
  return shape;
}

}  // namespace yocto

// -----------------------------------------------------------------------------
// SKY AND SCENES
// -----------------------------------------------------------------------------
namespace yocto {

texture_data make_sky_texture(int width, int height, const vec3f& sun_direction) {
  auto sky     = texture_data{width, height, {}};
  auto sun     = normalize(sun_direction);
  auto zenith  = vec3f{0.25f, 0.45f, 0.95f};
  auto horizon = vec3f{1.0f, 0.95f, 0.85f};
  auto ground  = vec3f{0.22f, 0.2f, 0.18f};
  sky.pixels.reserve((size_t)width * height);
  for (auto j = 0; j < height; j++) {
    for (auto i = 0; i < width; i++) {
      auto w = equirect_to_direction({(i + 0.5f) / width, (j + 0.5f) / height});
      auto c = w.y >= 0 ? horizon + (zenith - horizon) * std::pow(w.y, 0.4f)
                        : ground + (horizon - ground) * std::exp(8 * w.y);
      auto cos_sun = std::max(dot(w, sun), 0.0f);
      c += vec3f{1.0f, 0.9f, 0.75f} * (40 * std::pow(cos_sun, 600.0f) + 0.6f * std::pow(cos_sun, 8.0f));
      sky.pixels.push_back(c);
    }
  }
  return sky;
}

scene_data make_hair_scene(const hair_style_params& params, const hair_material& hair) {
  auto scene  = scene_data{};
  auto camera = camera_data{};
  auto sky_frame = identity3x4f;
  switch (params.style) {
    case hair_style::straight:
    case hair_style::curly:
      // The thesis's camera; the hair is turned to show its back (below).
      camera.frame  = lookat_frame({0, 15, 23}, {0, 9.5f, 0}, {0, 1, 0});
      camera.aspect = 1;
      camera.focus  = 24;
      break;
    case hair_style::curls:
      camera.frame  = lookat_frame({-4, 5.9f, 20}, {-4, 5.9f, 0}, {0, 1, 0});
      camera.aspect = 16.0f / 9.0f;
      camera.focus  = 20;
      break;
    case hair_style::block:
      // z up, as pbrt's hair block scene.
      camera.frame  = lookat_frame({2, -3, 1.2f}, {1.25f, 0.3f, 0.5f}, {0, 0, 1});
      camera.aspect = 2;
      camera.lens   = 0.036f / 2 / std::tan(radians(23.0f) / 2) / 2;  // 23 deg vertical
      camera.focus  = 3.6f;
      sky_frame     = {{1, 0, 0}, {0, 0, 1}, {0, -1, 0}, {0, 0, 0}};
      break;
    case hair_style::fur:
      // 36 deg: the fur's reach (1.4025 at most, 16.3 deg off the axis at 5
      // units) spans 90% of the frame.
      camera.frame  = lookat_frame({0, 0, 5}, {0, 0, 0}, {0, 1, 0});
      camera.aspect = 1;
      camera.lens   = 0.036f / 2 / std::tan(radians(36.0f) / 2);
      camera.focus  = 5;
      break;
  }
  scene.cameras.push_back(camera);
  scene.camera_names.push_back("default");

  if (params.style == hair_style::fur) {
    // A plain white environment: the benchmark's lighting, no texture lookups.
    scene.environments.push_back({identity3x4f, {1, 1, 1}, -1});
    scene.environment_names.push_back("white");
  } else {
    scene.textures.push_back(make_sky_texture(512, 256, {-0.4f, 0.6f, 0.7f}));
    scene.texture_names.push_back("sky");
    scene.environments.push_back({sky_frame, {1, 1, 1}, 0});
    scene.environment_names.push_back("sky");
  }

  scene.shapes.push_back(make_hair_strands(params));
  scene.shape_names.push_back("hair");

  auto add_material = [&](const std::string& name, const material_data& material) {
    scene.materials.push_back(material);
    scene.material_names.push_back(name);
    return (int)scene.materials.size() - 1;
  };
  auto add_instance = [&](const std::string& name, const frame3f& frame, int shape, int material) {
    scene.instances.push_back({frame, shape, material});
    scene.instance_names.push_back(name);
  };
  auto hair_material_data = material_data{};
  hair_material_data.type = material_type::hair;
  hair_material_data.hair = hair;

  if (params.style == hair_style::curls) {
    // The thesis's four locks: black, red, brown and blonde.
    struct lock {
      const char* name;
      float       eumelanin, pheomelanin, x;
    };
    for (auto [name, eumelanin, pheomelanin, x] :
        {lock{"black", 8, 0, -3.75f}, lock{"red", 0, 2, -1.25f}, lock{"brown", 1.3f, 0, 1.25f},
            lock{"blonde", 0.3f, 0, 3.75f}}) {
      auto material              = hair_material_data;
      material.hair.has_sigma_a  = false;
      material.hair.has_color    = false;
      material.hair.eumelanin    = eumelanin;
      material.hair.pheomelanin  = pheomelanin;
      add_instance(name, translation_frame({x, 0, 0}), 0, add_material(name, material));
    }
    return scene;
  }
  // Head styles face +z; the camera looks from +z at the back of the head.
  auto head = params.style == hair_style::straight || params.style == hair_style::curly;
  auto turn = head ? rotation_frame({0, 1, 0}, pif) : identity3x4f;
  add_instance("hair", turn, 0, add_material("hair", hair_material_data));
  auto solid = material_data{};
  if (params.style == hair_style::fur) {
    solid.color = {0.5f, 0.5f, 0.5f};
    scene.shapes.push_back(make_sphere_shape(128, 1));
    scene.shape_names.push_back("ball");
    add_instance("ball", identity3x4f, 1, add_material("ball", solid));
  } else if (params.style == hair_style::block) {
    solid.color = {0.2f, 0.8f, 0.3f};
    scene.shapes.push_back(make_sphere_shape(96, 0.5f));
    scene.shape_names.push_back("sphere");
    add_instance("sphere", translation_frame({2, 0.5f, 0.5f}), 1, add_material("sphere", solid));
  } else {
    solid.color = {0.35f, 0.25f, 0.2f};
    scene.shapes.push_back(make_sphere_shape(128, hair_head_radius));
    scene.shape_names.push_back("head");
    add_instance("head", turn * translation_frame(hair_head_center), 1,
        add_material("head", solid));
  }
  return scene;
}

}  // namespace yocto

// -----------------------------------------------------------------------------
// PLACEMENT FOR A CAMERA
// -----------------------------------------------------------------------------
namespace yocto {

frame3f fit_hair_to_camera(const camera_data& camera, const shape_data& strands,
    float fraction, float distance) {
  if (strands.positions.empty() || !(fraction > 0) || !std::isfinite(fraction))
    return identity3x4f;
  auto centre    = center(compute_bounds(strands));
  auto to_camera = inverse(camera.frame);
  if (!(distance > 0)) {
    // Camera space looks down -z.
    auto depth = -transform_point(to_camera, centre).z;
    distance   = depth > 0 ? depth : camera.focus;
  }
  // Half the image plane at unit depth, as eval_camera spans it.
  auto half = camera_film_size(camera) / (2 * camera.lens);
  if (!(distance > 0) || !std::isfinite(distance) || !(half.x > 0) || !(half.y > 0) ||
      !std::isfinite(half.x) || !std::isfinite(half.y))
    return identity3x4f;
  auto target = transform_point(camera.frame, {0, 0, -distance});

  // Control points relative to the centre, in camera axes; a scale s puts a
  // point at (s q.x, s q.y, s q.z - distance), in front while s q.z < distance.
  auto offsets = std::vector<vec3f>{};
  offsets.reserve(strands.positions.size());
  auto nearest = 0.0f;
  for (auto& p : strands.positions) {
    offsets.push_back(transform_vector(to_camera, p - centre));
    nearest = std::max(nearest, offsets.back().z);
  }
  // The fraction of the image (the larger of the two axes) the silhouette spans.
  auto coverage = [&](float s) {
    auto lo = vec2f{0, 0}, hi = vec2f{0, 0};
    for (auto& q : offsets) {
      auto depth = distance - s * q.z;
      auto uv    = vec2f{s * q.x, s * q.y} / depth;
      lo         = min(lo, uv);
      hi         = max(hi, uv);
    }
    auto span = (hi - lo) / (2.0f * half);
    return std::max(span.x, span.y);
  };
  // The silhouette grows with the scale: bracket, then bisect. Points may
  // come at most to a tenth of the distance from the camera.
  auto limit = nearest > 0 ? 0.9f * distance / nearest : 0.0f;
  auto lo = 0.0f, hi = limit > 0 ? limit : 1.0f;
  if (limit <= 0) {
    for (auto k = 0; k < 64 && coverage(hi) < fraction; k++) hi *= 2;
  }
  if (coverage(hi) <= 0) {
    lo = 1;  // a point or a line along the view axis: nothing to fill with
  } else if (coverage(hi) <= fraction) {
    lo = hi;  // the closest the strands may come
  } else {
    for (auto k = 0; k < 48; k++) {
      auto mid = (lo + hi) / 2;
      if (coverage(mid) < fraction) lo = mid;
      else hi = mid;
    }
  }
  auto scale = lo > 0 && std::isfinite(lo) ? lo : 1.0f;
  return {{scale, 0, 0}, {0, scale, 0}, {0, 0, scale}, target - scale * centre};
}

void transform_hair_strands(shape_data& strands, const frame3f& frame) {
  for (auto& p : strands.positions) p = transform_point(frame, p);
  auto scale = frame_scale(frame);
  for (auto& r : strands.radius) r *= scale;
}

}  // namespace yocto
