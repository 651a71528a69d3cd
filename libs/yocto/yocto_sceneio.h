//
// # Yocto/SceneIO: loading and saving scenes, shapes and images
//
// Json scenes in Yocto/GL's 4.2 layout (arrays and integer references) and the
// older 4.0 layout (objects keyed by name), PLY shapes (binary and ascii;
// faces, lines and curves) and images through OpenImageIO. Every function
// returns false with a one-line message naming the file and the element or
// line on bad input. Outputs are written to a temporary name and renamed when
// complete, so a failed save leaves nothing behind.
//

#ifndef YOCTO_SCENEIO_H_
#define YOCTO_SCENEIO_H_

#include <string>
#include <vector>

#include "yocto_scene.h"

// -----------------------------------------------------------------------------
// SCENES
// -----------------------------------------------------------------------------
namespace yocto {

// Loads a json scene with its shapes and textures. Warnings (unknown keys)
// are appended to `warnings` if given, printed to stderr otherwise.
bool load_scene(const std::string& filename, scene_data& scene, std::string& error,
    std::vector<std::string>* warnings = nullptr);

// Saves a json scene (4.2 layout) with shapes as PLY files under shapes/ and
// textures under textures/, next to the json.
bool save_scene(const std::string& filename, const scene_data& scene,
    std::string& error, bool ascii_shapes = false);

}  // namespace yocto

// -----------------------------------------------------------------------------
// SHAPES
// -----------------------------------------------------------------------------
namespace yocto {

// PLY: vertex x y z [nx ny nz] [u v] [radius]; element face (triangles),
// line (2 indices each) or curve (4 indices each) with vertex_indices.
bool load_shape(const std::string& filename, shape_data& shape, std::string& error);
bool save_shape(const std::string& filename, const shape_data& shape,
    std::string& error, bool ascii = false);

}  // namespace yocto

// -----------------------------------------------------------------------------
// IMAGES
// -----------------------------------------------------------------------------
namespace yocto {

// Loads any image OpenImageIO reads as linear RGB (8-bit formats are
// converted from sRGB).
bool load_image(const std::string& filename, texture_data& image, std::string& error);

// Saves linear RGB pixels: exr/hdr/pfm stay linear, png/jpg are scaled by
// 2^exposure, converted to sRGB and quantised. Unknown extension is an error.
bool save_image(const std::string& filename, const texture_data& image,
    std::string& error, float exposure = 0);

// Is this an image extension we can save?
bool is_image_filename(const std::string& filename);

}  // namespace yocto

// -----------------------------------------------------------------------------
// FILE HELPERS
// -----------------------------------------------------------------------------
namespace yocto {

// Writes a file through a temporary name in the same directory, then renames.
bool save_text(const std::string& filename, const std::string& text, std::string& error);
bool load_text(const std::string& filename, std::string& text, std::string& error);

// Path helpers: directory of a path (with trailing separator or empty),
// extension (with dot, lower case), and join.
std::string path_dirname(const std::string& filename);
std::string path_extension(const std::string& filename);
std::string path_join(const std::string& directory, const std::string& filename);

// A temporary filename next to `filename`, unique to this process.
std::string make_temporary_filename(const std::string& filename);

}  // namespace yocto

#endif
