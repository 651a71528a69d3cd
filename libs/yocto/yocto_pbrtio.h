//
// # Yocto/PbrtIO: pbrt scenes
//
// Imports the subset of pbrt-v3 and pbrt-v4 scene syntax that real hair scenes
// use into the scene model: `Include`/`Import` of plain and gzip'd files, the
// transform directives and blocks, perspective cameras, film, sampler and
// integrator defaults, infinite, distant and diffuse area lights, `hair`,
// diffuse and coated materials, and the shapes `curve`, `sphere`, `disk`,
// `trianglemesh` and `plymesh` (through yocto_ply) with environment maps
// (through yocto_image). Also gives a scene's camera alone, and writes curves
// in pbrt's syntax (stand-in geometry for scenes that include it).
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

#include "yocto_fileio.h"
#include "yocto_scene.h"

// -----------------------------------------------------------------------------
// PBRT SCENES
// -----------------------------------------------------------------------------
namespace yocto {

// Import options.
struct pbrt_params {
  bool   lenient         = false;  // unknown directives become warnings
  bool   curves_as_lines = false;  // tessellate Bezier curves into line segments
  int    segments        = 4;      // segments per Bezier curve when curves_as_lines
  bool   allow_empty     = false;  // accept a scene with nothing to render (camera only)
  double max_memory      = default_memory_limit();  // bytes the load may use
};

// Loads a pbrt-v3 or pbrt-v4 scene (plain or .gz) into the scene model.
// Warnings are appended to `warnings` if given, printed to stderr otherwise.
// A scene without shapes or an environment light is an error unless
// params.allow_empty. Strings must be UTF-8; the files the scene names must
// be regular files. The load keeps within params.max_memory: the scene so
// far, the text of open files, parameter lists and the resampling of
// environment maps are checked before they grow past it; a .gz file may
// inflate to at most 100 times its size (past 16 MiB); and the text read
// with all Includes, each counted as at least 1 MiB, to at most 4 times the
// limit.
bool load_pbrt_scene(const std::string& filename, scene_data& scene,
    std::string& error, const pbrt_params& params = {},
    std::vector<std::string>* warnings = nullptr);

// The first camera of a pbrt scene (plain or .gz), parsing only up to the
// first WorldBegin: the world and what it Includes are never read, so the
// camera of a scene whose geometry is missing (what stand-ins are for) still
// loads. The camera is load_pbrt_scene's for the same text; no WorldBegin is
// an error. Errors and warnings name the file, as load_pbrt_scene's do.
bool load_pbrt_camera(const std::string& filename, camera_data& camera,
    std::string& error, const pbrt_params& params = {},
    std::vector<std::string>* warnings = nullptr);

}  // namespace yocto

// -----------------------------------------------------------------------------
// PBRT CURVES
// -----------------------------------------------------------------------------
namespace yocto {

// Writes curves in pbrt's syntax (`Shape "curve"`, one per Bezier segment,
// `point3 P` and widths as diameters) to .pbrt or gzip'd .pbrt.gz.
bool save_pbrt_curves(const std::string& filename, const shape_data& shape,
    std::string& error);

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
