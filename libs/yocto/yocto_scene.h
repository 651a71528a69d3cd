//
// # Yocto/Scene: the scene model
//
// Only what hair scenes need: perspective or orthographic cameras, one
// environment (constant or image), shapes made of triangles, line segments or
// cubic Bezier curves with a per-vertex radius, materials `matte`, `glossy` and
// `hair`, and instances that place a shape with a material. Elements refer to
// each other by index (-1 is none). Names live in parallel `*_names` arrays, as
// in Yocto/GL.
//

#ifndef YOCTO_SCENE_H_
#define YOCTO_SCENE_H_

#include <yocto_hair/yocto_hair.h>

#include <array>
#include <string>
#include <vector>

#include "yocto_math.h"

// -----------------------------------------------------------------------------
// SCENE DATA
// -----------------------------------------------------------------------------
namespace yocto {

// Camera looking along -z of its frame: perspective (pinhole or thin lens),
// or orthographic with the film scaled by focus / lens. Lens, film and focus
// in meters as Yocto/GL; aspect is width over height.
struct camera_data {
  frame3f frame        = identity3x4f;
  bool    orthographic = false;
  float   lens         = 0.050f;
  float   film         = 0.036f;
  float   aspect       = 1.5f;
  float   focus        = 10000;
  float   aperture     = 0;
};

// Linear RGB float image (row 0 is the top row).
struct texture_data {
  int                width  = 0;
  int                height = 0;
  std::vector<vec3f> pixels = {};
};

// Named float channels of an image, interleaved (pixel by pixel), beside a
// texture_data's RGB: an EXR layer such as "albedo" with channels R, G, B.
struct image_layer {
  std::string              name     = "";
  std::vector<std::string> channels = {};
  std::vector<float>       pixels   = {};  // width * height * channels.size()
};

enum struct material_type { matte, glossy, hair };
inline const auto material_type_names = std::array<std::string, 3>{
    "matte", "glossy", "hair"};

// Material: matte is Lambertian; glossy is a GGX dielectric coat (roughness,
// ior) over a Lambertian base; hair holds the hair model's parameters.
struct material_data {
  material_type type      = material_type::matte;
  vec3f         emission  = {0, 0, 0};
  vec3f         color     = {0, 0, 0};
  float         roughness = 0;
  float         ior       = 1.5f;
  int           emission_tex = -1;
  int           color_tex    = -1;
  hair_material hair         = {};
};

// A shape is one of: triangles, lines (segments between two vertices) or
// curves (cubic Bezier segments with four control points). Radius is
// per vertex (per control point for curves).
struct shape_data {
  std::vector<vec3i> triangles = {};
  std::vector<vec2i> lines     = {};
  std::vector<vec4i> curves    = {};
  std::vector<vec3f> positions = {};
  std::vector<vec3f> normals   = {};
  std::vector<vec2f> texcoords = {};
  std::vector<float> radius    = {};
};

struct instance_data {
  frame3f frame    = identity3x4f;
  int     shape    = -1;
  int     material = -1;
};

// Environment: emission times an optional equirectangular texture, oriented by
// its frame.
struct environment_data {
  frame3f frame        = identity3x4f;
  vec3f   emission     = {0, 0, 0};
  int     emission_tex = -1;
};

// Directional light (pbrt's "distant"): radiance arriving from `direction`
// (pointing towards the light) with the given irradiance.
struct distant_light_data {
  vec3f direction = {0, 0, 1};
  vec3f emission  = {0, 0, 0};
};

// Render settings a scene file may carry (pbrt's Film, Sampler, Integrator).
struct scene_render_settings {
  int resolution = 0;  // largest image side, 0 if not given
  int samples    = 0;  // 0 if not given
  int bounces    = 0;  // 0 if not given
};

struct scene_data {
  std::vector<camera_data>        cameras        = {};
  std::vector<environment_data>   environments   = {};
  std::vector<distant_light_data> distant_lights = {};
  std::vector<shape_data>         shapes         = {};
  std::vector<texture_data>       textures       = {};
  std::vector<material_data>      materials      = {};
  std::vector<instance_data>      instances      = {};

  std::vector<std::string> camera_names      = {};
  std::vector<std::string> environment_names = {};
  std::vector<std::string> shape_names       = {};
  std::vector<std::string> texture_names     = {};
  std::vector<std::string> material_names    = {};
  std::vector<std::string> instance_names    = {};

  scene_render_settings settings  = {};
  std::string           copyright = "";
};

}  // namespace yocto

// -----------------------------------------------------------------------------
// SCENE EVALUATION
// -----------------------------------------------------------------------------
namespace yocto {

// Camera ray through image coordinates uv in [0,1]^2 (v down) with lens
// sample luv for depth of field.
ray3f eval_camera(const camera_data& camera, const vec2f& image_uv, const vec2f& lens_uv);

// Film size: `film` on the image's larger side, the other by the aspect.
vec2f camera_film_size(const camera_data& camera);

// Image coordinates in [0,1]^2 (v down) where a pinhole camera sees a world
// point in front of it: the inverse of eval_camera (any uv for points behind).
vec2f project_camera_point(const camera_data& camera, const vec3f& point);

// Image resolution for a camera whose largest side is `resolution` pixels.
vec2i camera_resolution(const camera_data& camera, int resolution);

// Texture lookup with bilinear filtering and wrapping; uv in [0,1]^2.
vec3f eval_texture(const texture_data& texture, const vec2f& uv);
// The same for an equirectangular map: u wraps around the horizon, v is
// clamped, so that the poles (v = 0 and 1) do not blend into each other.
vec3f eval_environment_texture(const texture_data& texture, const vec2f& uv);

// Environment radiance arriving from direction (pointing away from the scene).
vec3f eval_environment(const scene_data& scene, const environment_data& environment,
    const vec3f& direction);
// Equirectangular coordinates of a local direction and back.
vec2f direction_to_equirect(const vec3f& local_direction);
vec3f equirect_to_direction(const vec2f& uv);

// Bytes a shape's arrays hold (what loading it allocates).
double shape_memory(const shape_data& shape);

// A 64-bit fingerprint of what a render of the scene depends on besides
// the camera: shapes, textures, materials, instances, environments and
// distant lights, value by value (names, files and settings left out). Two
// loads of the same scene give the same fingerprint; any changed value
// almost surely changes it.
uint64_t fingerprint_scene(const scene_data& scene);

// Bounds of a shape and of the whole scene.
bbox3f compute_bounds(const shape_data& shape);
bbox3f compute_bounds(const scene_data& scene);

// Is this a fiber shape (lines or curves)?
inline bool is_fiber(const shape_data& shape) {
  return !shape.lines.empty() || !shape.curves.empty();
}

// Cubic Bezier evaluation and derivative at u in [0, 1].
inline vec3f eval_bezier(
    const vec3f& p0, const vec3f& p1, const vec3f& p2, const vec3f& p3, float u) {
  auto v = 1 - u;
  return v * v * v * p0 + 3 * v * v * u * p1 + 3 * v * u * u * p2 + u * u * u * p3;
}
inline float eval_bezier(float p0, float p1, float p2, float p3, float u) {
  auto v = 1 - u;
  return v * v * v * p0 + 3 * v * v * u * p1 + 3 * v * u * u * p2 + u * u * u * p3;
}
inline vec3f eval_bezier_derivative(
    const vec3f& p0, const vec3f& p1, const vec3f& p2, const vec3f& p3, float u) {
  auto v = 1 - u;
  return 3 * v * v * (p1 - p0) + 6 * v * u * (p2 - p1) + 3 * u * u * (p3 - p2);
}

// Geometry of a triangle hit at Embree's barycentric uv: world position,
// interpolated shading normal (geometric if the shape has none), geometric
// normal and texture coordinates.
struct surface_point {
  vec3f position  = {0, 0, 0};
  vec3f normal    = {0, 0, 1};
  vec3f gnormal   = {0, 0, 1};
  vec2f texcoord  = {0, 0};
};
surface_point eval_surface_point(const scene_data& scene, const instance_data& instance,
    int element, const vec2f& uv);

// Geometry of a fiber hit (line or curve element at parameter u) seen along a
// ray: the point on the axis, the tangent, the radius and the signed offset h
// in [-1, 1] of the ray from the axis over the radius. The frame has x = the
// tangent, z = the normal facing back along the ray (-d with its tangent
// component removed) and y = z x x, so that h = dot(hit - axis, y) / radius.
struct fiber_point {
  vec3f   position = {0, 0, 0};  // hit point on the fiber's surface
  vec3f   axis     = {0, 0, 0};  // point on the axis at u
  vec3f   tangent  = {1, 0, 0};
  float   radius   = 0;
  float   h        = 0;
  frame3f frame    = {};
  vec3f   normal   = {0, 0, 1};  // surface normal of a round fiber at h
};
fiber_point eval_fiber_point(const scene_data& scene, const instance_data& instance,
    int element, float u, const ray3f& ray, float distance);

// A ray leaving a fiber at `axis` (with its tangent and radius there): it
// starts on the circle of 1.01 radius around the axis, on the side that
// `direction` heads to (`side` when it runs along the fiber), so that it
// starts outside the fiber and moves away from it: the hair model accounts
// for the whole passage of light through the fiber it leaves.
ray3f spawn_fiber_ray(const vec3f& axis, const vec3f& tangent, float radius,
    const vec3f& side, const vec3f& direction);

// Procedural shapes: a UV sphere (steps along the equator, steps/2 rings)
// with normals, and a quad of the given size in the xy plane facing +z.
shape_data make_sphere_shape(int steps, float radius);
shape_data make_quad_shape(const vec2f& size);

// Appends a strand through the points to a curves shape: a uniform
// Catmull-Rom spline (one-sided tangents at the ends) as n - 1 chained cubic
// Bezier segments, 3 (n - 1) + 1 vertices, the radius interpolated linearly
// between the points' radii. Fewer than 2 points append nothing.
void append_catmull_rom_strand(shape_data& shape, const std::vector<vec3f>& points,
    const std::vector<float>& radii);

// The largest coordinate a scene may hold, in world space. Embree asserts on
// a ray whose origin or direction has a component beyond 1.844e18 (its
// FLT_LARGE) and drops primitives whose bounds pass it; 1e15 leaves a factor
// of a thousand for the arithmetic of hit points and ray offsets, and is far
// beyond any real scene (floats at 1e15 are 1.3e8 apart).
inline constexpr float max_scene_coordinate = 1e15f;

// Checks references, sizes and frames (finite, invertible), and what reaches
// the ray tracer: camera rays (corner, edge and centre pixels through the
// centre and rim of the lens) must start within max_scene_coordinate along a
// finite unit direction; vertex positions, radii and instanced bounds must lie
// within it; distant light directions must normalize. Returns false with a
// message naming the element.
bool validate_scene(const scene_data& scene, std::string& error);

// Adds a default camera framing the scene bounds if the scene has none.
void add_missing_camera(scene_data& scene);

}  // namespace yocto

#endif
