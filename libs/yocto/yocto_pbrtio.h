//
// # Yocto/PbrtIO: pbrt scenes and Cem Yuksel's .hair models
//
// Imports the subset of pbrt-v3 and pbrt-v4 scene syntax that real hair scenes
// use into the scene model: `Include`/`Import` of plain and gzip'd files, the
// transform directives and blocks, perspective cameras, film, sampler and
// integrator defaults, infinite, distant and diffuse area lights, `hair`,
// diffuse and coated materials, and the shapes `curve`, `sphere`, `disk`,
// `trianglemesh` and `plymesh`. Also reads and writes Cem Yuksel's binary
// `.hair` format.
//
// Conventions of the import:
// - World coordinates are kept as pbrt's numbers. pbrt's camera space is
//   left-handed (x right, y up, z forward); the Yocto camera frame keeps x as
//   the image's right and y as its up and points z backwards, so images match
//   pbrt's, not their mirror.
// - pbrt curve widths are diameters: radius = width / 2, per control point,
//   interpolated linearly from width0 to width1 along the control points.
//   Consecutive curves sharing an end point become one strand with shared
//   vertices; all curves of one material and transform form one shape.
// - Environment maps are equirectangular (pbrt-v3) or equal-area octahedral
//   (pbrt-v4, converted to equirectangular at load time). A missing map gives
//   a constant environment of the same scale and a warning.
// - Glossy roughness follows Yocto: the GGX alpha is roughness squared.
//
// Errors name the file, the line (the byte offset in binary files) and the
// directive. Parameters we ignore are reported once each as warnings.
//

#ifndef YOCTO_PBRTIO_H_
#define YOCTO_PBRTIO_H_

#include <string>
#include <vector>

#include "yocto_scene.h"

// -----------------------------------------------------------------------------
// PBRT SCENES
// -----------------------------------------------------------------------------
namespace yocto {

// Import options.
struct pbrt_params {
  bool lenient         = false;  // unknown directives become warnings
  bool curves_as_lines = false;  // tessellate Bezier curves into line segments
  int  segments        = 4;      // segments per Bezier curve when curves_as_lines
  bool allow_empty     = false;  // accept a scene with nothing to render (camera only)
};

// Loads a pbrt-v3 or pbrt-v4 scene (plain or .gz) into the scene model.
// Warnings are appended to `warnings` if given, printed to stderr otherwise.
// A scene without shapes or an environment light is an error unless
// params.allow_empty. Strings must be UTF-8; the files the scene names must
// be regular files. The load keeps within load_memory_limit (yocto_sceneio.h):
// the scene so far, the text of open files, parameter lists and the
// resampling of environment maps are checked before they grow past it; a
// .gz file may inflate to at most 100 times its size (past 16 MiB); and the
// text read with all Includes, each counted as at least 1 MiB, to at most
// 4 times the limit.
bool load_pbrt_scene(const std::string& filename, scene_data& scene,
    std::string& error, const pbrt_params& params = {},
    std::vector<std::string>* warnings = nullptr);

// Tessellates cubic Bezier curves into `segments` line segments each; curves
// that share an end vertex share the line vertex too (one polyline a strand).
shape_data curves_to_lines(const shape_data& curves, int segments);

}  // namespace yocto

// -----------------------------------------------------------------------------
// CEM YUKSEL'S .HAIR MODELS
// -----------------------------------------------------------------------------
namespace yocto {

// Loads a .hair model as a curves shape: a Catmull-Rom spline through each
// strand's points, converted to cubic Bezier segments; radius is half the
// file's thickness. If `color` is given it receives the mean of the colour
// array, or the header's default colour if the file has no colour array.
bool load_hair_model(const std::string& filename, shape_data& shape,
    std::string& error, vec3f* color = nullptr);

// Saves the strands of a curves or lines shape as a .hair model: the points
// are the curve end points (line vertices), thickness is twice the radius.
bool save_hair_model(
    const std::string& filename, const shape_data& shape, std::string& error);

// Builds a scene around a .hair model: the curves shape (or lines if
// params.curves_as_lines), a hair material (pbrt's default, eumelanin 1.3,
// or the file's colour if it has a colour array), a camera framing it and a
// constant white environment.
bool load_hair_scene(const std::string& filename, scene_data& scene,
    std::string& error, const pbrt_params& params = {});

}  // namespace yocto

// -----------------------------------------------------------------------------
// MAPPINGS
// -----------------------------------------------------------------------------
namespace yocto {

// Equal-area octahedral mapping of the unit sphere to [0,1]^2 and back
// (Clarberg, Fast Equal-Area Mapping of the (Hemi)Sphere using SIMD, JGT
// 2008), the layout of pbrt-v4's environment maps.
vec2f equal_area_sphere_to_square(const vec3f& direction);
vec3f equal_area_square_to_sphere(const vec2f& uv);

}  // namespace yocto

#endif
