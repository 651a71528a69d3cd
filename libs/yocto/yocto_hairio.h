//
// # Yocto/HairIO: Cem Yuksel's .hair models
//
// Reads and writes the binary `.hair` format of the public hair models used
// by Bitterli's scenes (a 128-byte header, then optional arrays of segments
// per strand, points, thickness, transparency and colour), as curves shapes,
// and builds a scene around a model. Errors name the file and the byte
// offset; counts are checked against the file's size and the load's memory
// limit before anything is allocated.
//

#ifndef YOCTO_HAIRIO_H_
#define YOCTO_HAIRIO_H_

#include <string>

#include "yocto_fileio.h"
#include "yocto_scene.h"

// -----------------------------------------------------------------------------
// HAIR FILES
// -----------------------------------------------------------------------------
namespace yocto {

// Options of a scene made from a model.
struct hair_params {
  bool   curves_as_lines = false;  // tessellate Bezier curves into line segments
  int    segments        = 4;      // segments per Bezier curve when curves_as_lines
  double max_memory      = default_memory_limit();  // bytes the load may use
};

// Loads a .hair model as a curves shape: a Catmull-Rom spline through each
// strand's points, converted to cubic Bezier segments; radius is half the
// file's thickness. If `color` is given it receives the mean of the colour
// array, or the header's default colour if the file has no colour array.
// The file and the spline must fit max_memory.
bool load_hair_model(const std::string& filename, shape_data& shape,
    std::string& error, vec3f* color = nullptr,
    double max_memory = default_memory_limit());

// Saves the strands of a curves or lines shape as a .hair model: the points
// are the curve end points (line vertices), thickness is twice the radius.
bool save_hair_model(
    const std::string& filename, const shape_data& shape, std::string& error);

// Builds a scene around a .hair model: the curves shape (or lines if
// params.curves_as_lines), a hair material (pbrt's default, eumelanin 1.3,
// or the file's colour if it has a colour array), a camera framing it and a
// constant white environment.
bool load_hair_scene(const std::string& filename, scene_data& scene,
    std::string& error, const hair_params& params = {});

}  // namespace yocto

#endif
