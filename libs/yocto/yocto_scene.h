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
  // Per vertex, optional: fibres' own colours (Cem Yuksel's .hair files),
  // which a hair material given by colour takes at each point.
  std::vector<vec3f> colors    = {};
  // A fibre shape packed for rendering (pack_fiber_vertices): each vertex's
  // position and radius as one float4, the layout Embree reads, in place of
  // positions and radius (then empty); and, for curves whose four vertices
  // are consecutive (strands), each one's first vertex in place of curves.
  std::vector<vec4f> fiber_vertices = {};
  std::vector<int>   fiber_curves   = {};
  // When every packed strand has this many segments, one strand after the
  // other (3 n + 1 vertices each), curve e's first vertex is 3 e + e / n:
  // computed, not read (a dependent cache miss per hit). 0 otherwise.
  int fiber_strand_segments = 0;
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
// HAIR PARAMETERS
// -----------------------------------------------------------------------------
namespace yocto {

// A hair parameter's value: one number, or three (a colour or an absorption).
enum struct hair_parameter_kind { number, rgb };

// What a parameter is about: the pigment (sigma_a, else color, else melanin),
// the fiber's roughness, tilt and index, or variation across a groom. A
// material that leaves every variation parameter at its default saves,
// prints (`info` text) and fingerprints as if the group did not exist.
enum struct hair_parameter_group { pigment, fiber, variation };

// One row of hair_parameters. A value is read and written through the
// member pointer of its kind; numbers travel as vec3f with the value in every
// component, so that ranges and defaults apply to both kinds alike.
struct hair_parameter {
  const char*            name          = "";  // json key; `yscene hair --name-with-dashes`
  hair_parameter_kind    kind          = hair_parameter_kind::number;
  hair_parameter_group   group         = hair_parameter_group::fiber;
  float                  min           = 0;        // valid range, of each component
  float                  max           = flt_max;  // flt_max: no upper bound
  bool                   min_open      = false;    // min itself is not valid
  bool                   max_open      = false;    // max itself is not valid
  vec3f                  default_value = {0, 0, 0};  // hair_material{}'s value
  float hair_material::* number        = nullptr;  // the value, kind number
  vec3f hair_material::* rgb           = nullptr;  // the value, kind rgb
  bool hair_material::*  has           = nullptr;  // optional keys: set when given
  const char*            alias         = "";  // json spelling also read (camelCase)
  const char*            pbrt          = "";  // pbrt's parameter, "" if pbrt has none
  const char*            pbrt_alias    = "";  // pbrt-v4's other name for it
  const char*            unit          = "";  // printed after the value by `info`
  const char*            doc           = "";  // one line, for `yscene hair --help`
};

// Every hair material parameter, in the order json files list them. Json
// load and save, pbrt import, `yscene hair` options, `yscene info` (text and
// --json), validate_scene and fingerprint_scene all read this table: a new
// parameter is a new field of hair_material and one row here (a compile-time
// check in yocto_scene.cpp holds each default_value to hair_material{}'s).
// Rules between keys stay with their users: pbrt's precedence (sigma_a, then
// color, then melanin; one pigment given makes the other 0) in the loaders.
// clang-format off
inline constexpr hair_parameter hair_parameters[] = {
    // name, kind, group, min, max, min_open, max_open, default_value, number, rgb, has,
    // alias, pbrt, pbrt_alias, unit, doc
    {"sigma_a", hair_parameter_kind::rgb, hair_parameter_group::pigment, 0, flt_max, false,
        false, vec3f{0}, nullptr, &hair_material::sigma_a, &hair_material::has_sigma_a,
        "sigmaA", "sigma_a", "", "",
        "absorption per unit radius r g b (if given, overrides color and melanin)"},
    {"color", hair_parameter_kind::rgb, hair_parameter_group::pigment, 0, 1, false, false,
        vec3f{0}, nullptr, &hair_material::color, &hair_material::has_color, "", "color",
        "reflectance", "",
        "colour r g b after multiple scattering (if given, overrides melanin)"},
    {"eumelanin", hair_parameter_kind::number, hair_parameter_group::pigment, 0, flt_max,
        false, false, vec3f{1.3f}, &hair_material::eumelanin, nullptr, nullptr, "",
        "eumelanin", "", "", "eumelanin concentration (brown-black pigment)"},
    {"pheomelanin", hair_parameter_kind::number, hair_parameter_group::pigment, 0, flt_max,
        false, false, vec3f{0}, &hair_material::pheomelanin, nullptr, nullptr, "",
        "pheomelanin", "", "", "pheomelanin concentration (red-yellow pigment)"},
    {"beta_m", hair_parameter_kind::number, hair_parameter_group::fiber, 0, 1, false, false,
        vec3f{0.3f}, &hair_material::beta_m, nullptr, nullptr, "betaM", "beta_m", "", "",
        "longitudinal roughness"},
    {"beta_n", hair_parameter_kind::number, hair_parameter_group::fiber, 0, 1, false, false,
        vec3f{0.3f}, &hair_material::beta_n, nullptr, nullptr, "betaN", "beta_n", "", "",
        "azimuthal roughness"},
    {"alpha", hair_parameter_kind::number, hair_parameter_group::fiber, -90, 90, false,
        false, vec3f{2}, &hair_material::alpha, nullptr, nullptr, "", "alpha", "", "deg",
        "scale tilt in degrees"},
    {"eta", hair_parameter_kind::number, hair_parameter_group::fiber, 1, 10, false, false,
        vec3f{1.55f}, &hair_material::eta, nullptr, nullptr, "", "eta", "", "",
        "index of refraction of the fiber"},
    {"random_melanin", hair_parameter_kind::number, hair_parameter_group::variation, 0, 1,
        false, false, vec3f{0}, &hair_material::random_melanin, nullptr, nullptr, "", "", "",
        "", "per strand spread of the pigment: times 1 + (2 r - 1) random_melanin"},
    {"random_roughness", hair_parameter_kind::number, hair_parameter_group::variation, 0, 1,
        false, false, vec3f{0}, &hair_material::random_roughness, nullptr, nullptr, "", "",
        "", "", "per strand spread of beta_m and beta_n: times 1 + (2 r - 1) random_roughness"},
    {"tip_eumelanin", hair_parameter_kind::number, hair_parameter_group::variation, 0,
        flt_max, false, false, vec3f{0}, &hair_material::tip_eumelanin, nullptr,
        &hair_material::has_tip_eumelanin, "", "", "", "",
        "eumelanin at the tip (absent: the root's)"},
    {"tip_pheomelanin", hair_parameter_kind::number, hair_parameter_group::variation, 0,
        flt_max, false, false, vec3f{0}, &hair_material::tip_pheomelanin, nullptr,
        &hair_material::has_tip_pheomelanin, "", "", "", "",
        "pheomelanin at the tip (absent: the root's)"},
    {"tip_color", hair_parameter_kind::rgb, hair_parameter_group::variation, 0, 1, false,
        false, vec3f{0}, nullptr, &hair_material::tip_color, &hair_material::has_tip_color,
        "", "", "", "", "colour r g b at the tip (absent: the root's)"},
    {"tip_sigma_a", hair_parameter_kind::rgb, hair_parameter_group::variation, 0, flt_max,
        false, false, vec3f{0}, nullptr, &hair_material::tip_sigma_a,
        &hair_material::has_tip_sigma_a, "", "", "", "",
        "absorption r g b at the tip (absent: the root's)"},
    {"tip_start", hair_parameter_kind::number, hair_parameter_group::variation, 0, 1, false,
        true, vec3f{0}, &hair_material::tip_start, nullptr, nullptr, "", "", "", "",
        "where along the strand (0 root, 1 tip) the blend to the tip values starts"},
    {"tint", hair_parameter_kind::rgb, hair_parameter_group::variation, 0, 1, false, false,
        vec3f{1}, nullptr, &hair_material::tint, nullptr, "", "", "", "",
        "dye colour r g b, its absorption added to the pigment's (white: none)"},
};
// clang-format on

// The row whose name or alias is `key`, nullptr if none.
const hair_parameter* find_hair_parameter(const std::string& key);

// A parameter's value in a material (a number in every component).
vec3f get_hair_parameter(const hair_material& material, const hair_parameter& parameter);
// Sets a parameter's value (a number from the x component) and its has_ flag.
void set_hair_parameter(
    hair_material& material, const hair_parameter& parameter, const vec3f& value);

// Whether a material gives the parameter: its has_ flag if it has one, else
// a value other than the default.
bool is_hair_parameter_set(const hair_material& material, const hair_parameter& parameter);

// Whether every component lies in the parameter's range (false for NaN).
bool is_hair_parameter_valid(const hair_parameter& parameter, const vec3f& value);
// The range as text: "in [0, 1]", "in [0, 1)", ">= 0", "> 0".
std::string format_hair_parameter_range(const hair_parameter& parameter);
// A value as text, as printf's %g: "0.3", or "[1 0.6 0.5]" for rgb.
std::string format_hair_parameter_value(const hair_parameter& parameter, const vec3f& value);

// Checks every parameter a hair material uses (optional ones only if given)
// against its range; false with "NAME VALUE is not RANGE" otherwise.
bool check_hair_material(const hair_material& material, std::string& error);

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
  return !shape.lines.empty() || !shape.curves.empty() || !shape.fiber_curves.empty();
}

// Packs a fibre shape's positions and radii into fiber_vertices, freeing
// them: a render packs its fibres before building the BVH, which then hands
// Embree the scene's own memory instead of a float4 copy of every vertex
// (208 MB less at 13M vertices, at the peak of the build). Curves whose
// vertices are consecutive keep their first index only (fiber_curves: 4
// bytes a segment, not 16), which is what Embree reads. Shapes without a
// radius for every vertex, and triangles, stay as they are. What a render
// reads reads packed and unpacked shapes alike, through the functions
// below: hit geometry, strands, bounds, the fingerprint (the same either
// way), the BVH, validation and saving (which unpacks a copy of each
// shape); curves_to_lines, loading and the generators take unpacked ones.
void pack_fiber_vertices(shape_data& shape);
void pack_fiber_vertices(scene_data& scene);
// The inverse: positions, radius and curves back from the packed layout.
void unpack_fiber_vertices(shape_data& shape);

// A vertex's position and radius (0 without radii), and the vertex count,
// packed or not.
inline int num_vertices(const shape_data& shape) {
  return (int)(shape.fiber_vertices.empty() ? shape.positions.size()
                                            : shape.fiber_vertices.size());
}
inline vec3f vertex_position(const shape_data& shape, int index) {
  if (shape.fiber_vertices.empty()) return shape.positions[index];
  auto& v = shape.fiber_vertices[index];
  return {v.x, v.y, v.z};
}
inline float vertex_radius(const shape_data& shape, int index) {
  if (!shape.fiber_vertices.empty()) return shape.fiber_vertices[index].w;
  return index < (int)shape.radius.size() ? shape.radius[index] : 0.0f;
}
// Do the vertex indices of each element run consecutively from its first
// (strands: what Embree's index buffers and fiber_curves keep)?
template <typename Element>
inline bool elements_are_consecutive(const std::vector<Element>& elements) {
  for (auto& element : elements)
    for (auto k = 1; k < (int)element.length(); k++)
      if (element[k] != element[0] + k) return false;
  return true;
}

// The number of Bezier curves and a curve's four vertices, packed or not.
inline int num_curves(const shape_data& shape) {
  return (int)(shape.fiber_curves.empty() ? shape.curves.size() : shape.fiber_curves.size());
}
inline vec4i curve_vertices(const shape_data& shape, int element) {
  if (shape.fiber_curves.empty()) return shape.curves[element];
  auto n     = shape.fiber_strand_segments;
  auto first = n > 0 ? 3 * element + element / n : shape.fiber_curves[element];
  return {first, first + 1, first + 2, first + 3};
}
// A fibre segment's first and last vertex (a line's two, a curve's ends).
inline vec2i segment_ends(const shape_data& shape, int element) {
  if (!shape.lines.empty()) return shape.lines[element];
  auto curve = curve_vertices(shape, element);
  return {curve.x, curve.w};
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

// The strands of a fibre shape (lines or curves): which segments form each
// strand, root first, from connectivity (a segment continues the one whose
// end is its start: the same vertex, or a vertex at the same position), so
// that files that do not list strands (PLY, pbrt, generated grooms) have
// them, and those that do (Cem Yuksel's .hair, whose strands the loader
// writes as chains of segments) keep theirs. A segment no other one ends at
// starts a strand; a closed loop starts at its lowest segment.
struct fiber_strands {
  std::vector<int>   strand   = {};  // per segment: its strand
  std::vector<vec2f> u        = {};  // per segment: place along the strand at its start
                                     // and end, by chord length (0 root, 1 tip)
  std::vector<vec2f> random   = {};  // per strand: two values in [0, 1) of its root
  std::vector<int>   starts   = {};  // strand k: segments[starts[k] ... starts[k + 1] - 1]
  std::vector<int>   segments = {};  // segment indices strand by strand, root first
};
fiber_strands make_fiber_strands(const shape_data& shape);

// Two uniform values in [0, 1) that depend on a strand's root position
// alone (its three floats' bits, -0 as 0), so that reordering the strands of
// a file, or splitting a groom into files, changes no strand's values.
vec2f strand_random(const vec3f& root);

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
// between the points' radii (and colours, if given: one per point, appended
// to shape.colors). Fewer than 2 points append nothing.
void append_catmull_rom_strand(shape_data& shape, const std::vector<vec3f>& points,
    const std::vector<float>& radii, const std::vector<vec3f>& colors = {});

// Tessellates cubic Bezier curves into `segments` line segments each; curves
// that share an end vertex share the line vertex too (one polyline a strand).
shape_data curves_to_lines(const shape_data& curves, int segments);

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
// within it; distant light directions must normalize; hair materials'
// parameters must lie in their ranges (check_hair_material). Shapes may be
// packed (pack_fiber_vertices). Returns false with a message naming the
// element.
bool validate_scene(const scene_data& scene, std::string& error);

// validate_scene for a scene a loader has just converted from `filename`: on
// error the message names the file and the scene is left empty.
bool validate_loaded_scene(scene_data& scene, const std::string& filename, std::string& error);

// Adds a default camera framing the scene bounds if the scene has none.
void add_missing_camera(scene_data& scene);

}  // namespace yocto

#endif
