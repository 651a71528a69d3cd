//
// # Yocto/PLY: shapes as PLY files
//
// Triangle meshes, line segments and cubic Bezier curves with a radius per
// vertex, in Yocto/GL's PLY layout, binary and ascii. Loads return false with
// a one-line message naming the file and the element or line on bad input;
// saves write through a temporary name (yocto_fileio.h), so a failed save
// leaves nothing behind.
//

#ifndef YOCTO_PLY_H_
#define YOCTO_PLY_H_

#include <string>

#include "yocto_fileio.h"
#include "yocto_scene.h"

// -----------------------------------------------------------------------------
// PLY SHAPES
// -----------------------------------------------------------------------------
namespace yocto {

// PLY: vertex x y z [nx ny nz] [u v | s t] [radius]; element face
// (polygons become triangle fans), line (polylines become segments) or curve
// (4 indices each), each with a vertex_indices list. Reads ascii and binary
// of either byte order, any property type; skips unknown properties and
// elements. Texcoords are kept as stored (no v flip). Writes binary
// little-endian or ascii. The file must fit max_memory.
bool load_shape(const std::string& filename, shape_data& shape, std::string& error,
    double max_memory = default_memory_limit());
bool save_shape(const std::string& filename, const shape_data& shape,
    std::string& error, bool ascii = false);

// Encodes a shape as PLY bytes in memory (filename names it in messages):
// what save_shape writes, for savers that write several files as one.
bool encode_shape(const std::string& filename, const shape_data& shape,
    std::string& data, std::string& error, bool ascii = false);

}  // namespace yocto

#endif
