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
//
// Groups: `cameras`, `environments`, `textures`, `shapes`, `materials`,
// `instances` (or `objects`, as 4.0 calls them), plus `asset` (copyright),
// `distant_lights` and `settings` (resolution, samples, bounces). Each group
// is an array (4.2: integer references, `uri` files relative to the json)
// or an object keyed by name (4.0: references by name; a shape or texture
// named but not listed is found at shapes/NAME.ply or
// textures/NAME.{hdr,exr,png,jpg,jpeg,pfm}); layouts may mix per group.
// Frames are 12 numbers (x, y, z axes, then origin) or a 9-number `lookat`
// (from, to, up); a camera placed by lookat focuses on `to`.
//
// Material types: matte, glossy, hair; other Yocto types map to the nearest
// with a warning (plastic, metal, reflective, gltfpbr -> glossy; transparent,
// refractive, glass, subsurface, volumetric -> matte); anything else is an
// error. A material without `type` is hair if it has a hair key (a name or
// alias of hair_parameters other than color) or if the instances that use it
// all have fiber (lines or curves) shapes; otherwise matte. Hair keys are the
// rows of hair_parameters (yocto_scene.h: names, aliases such as betaM,
// ranges, defaults), color going into hair.color; a key's has_ flag is set
// when it is given; one pigment given makes the other 0. Keys a type does
// not use are dropped with a warning (e.g. roughness on hair), so a loaded
// material holds defaults in the fields its type ignores. Bad values, wrong types, out-of-range
// references, missing files and hair on a triangle mesh are errors.
// Each file is loaded once: shape (texture) elements that name the same file,
// the path resolved, become one shape (texture) that their users share, named
// after the first of them. The files' sizes and their sum are checked against
// load_memory_limit.
bool load_scene(const std::string& filename, scene_data& scene, std::string& error,
    std::vector<std::string>* warnings = nullptr);

// Saves a json scene (4.2 layout) with shapes as PLY files under shapes/ and
// textures as float EXR under textures/, next to the json, named after the
// elements (made safe and unique). Each material writes the keys its type
// uses (hair: optional keys when given, variation keys when away from their
// defaults, the others always), so load_scene(save_scene(scene)) gives back
// every field that has a meaning. The scene is validated first; on failure the files this call
// created are removed.
bool save_scene(const std::string& filename, const scene_data& scene,
    std::string& error, bool ascii_shapes = false);

}  // namespace yocto

// -----------------------------------------------------------------------------
// SHAPES
// -----------------------------------------------------------------------------
namespace yocto {

// PLY: vertex x y z [nx ny nz] [u v | s t] [radius]; element face
// (polygons become triangle fans), line (polylines become segments) or curve
// (4 indices each), each with a vertex_indices list. Reads ascii and binary
// of either byte order, any property type; skips unknown properties and
// elements. Texcoords are kept as stored (no v flip). Writes binary
// little-endian or ascii.
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

// Saves linear RGB pixels: exr/hdr/pfm stay linear (exr and pfm as 32-bit
// float), png/jpg are scaled by 2^exposure, clamped, converted to sRGB and
// quantised. Unknown extension and non-finite pixels are errors. With
// replace false an existing file is an error, never overwritten.
bool save_image(const std::string& filename, const texture_data& image,
    std::string& error, float exposure = 0, bool replace = true);

// Saves an OpenEXR image (the name must end in .exr) of the RGB pixels as
// channels R, G, B and every layer's channels as LAYER.CHANNEL (float32,
// zip), written as any output (complete or absent). Layers must have the
// image's size and finite values.
bool save_image_layers(const std::string& filename, const texture_data& image,
    const std::vector<image_layer>& layers, std::string& error, bool replace = true);

// Is this an image extension we can save?
bool is_image_filename(const std::string& filename);

}  // namespace yocto

// -----------------------------------------------------------------------------
// RENDER PARTS
// -----------------------------------------------------------------------------
namespace yocto {

// A part of a render split by sample ranges: the exact sums (fixed_sum3) of
// samples first ... first + count - 1 of every pixel of a render of
// `samples` samples a pixel, and what a merge must check. `settings` holds
// "key=value" lines that every part of one render shares: the scene's
// fingerprint, seed, resolution, camera, sampler, bounces, clamp and the
// rest (the caller writes them; a merge compares them line by line).
struct render_part {
  std::string             settings  = "";
  int                     samples   = 0;  // N: the whole render's samples a pixel
  int                     first     = 0;  // the part's samples: first ... first + count - 1
  int                     count     = 0;
  int                     width     = 0;
  int                     height    = 0;
  int64_t                 rays      = 0;  // rays cast for these samples
  int64_t                 nonfinite = 0;  // samples dropped as NaN or Inf
  std::vector<fixed_sum3> sums      = {};
  // Further exact sums, the same number a pixel (the AOVs of yocto_trace),
  // or none.
  int                     extra     = 0;  // sums a pixel
  std::vector<fixed_sum3> extra_sums = {};
};

// A part's bytes a pixel before compression: R, G, B as floats, then the
// sums as 18 32-bit words (and 18 more for each extra sum).
inline constexpr int render_part_pixel_bytes = 84;
inline constexpr int render_part_extra_bytes = 72;

// Saves a part as an OpenEXR image (the name must end in .exr), written as
// any output (complete or absent). Channels R, G, B hold the mean of the
// part's samples, to look at; the 18 32-bit unsigned channels sum.R.0 ...
// sum.B.5 hold the sums' words in 32-bit halves, least significant first;
// extra sums k in channels extra.K.R.0 ... extra.K.B.5 the same way, with
// the attribute yocto:extra (their number a pixel; absent for none).
// String attributes: yocto:part (the format, "yocto-hair render part 1"),
// yocto:settings, yocto:samples, yocto:range ("first:end", end excluded),
// yocto:rays, yocto:nonfinite and yocto:checksum (16 hex digits: a
// hash_stream of the attributes and the sums, so that a damaged file is
// found out).
bool save_render_part(const std::string& filename, const render_part& part,
    std::string& error, bool replace = true);

// Loads a part: a file that is not a part, truncated, damaged (checksum),
// or inconsistent (a range outside [0, samples)) is an error naming it.
bool load_render_part(const std::string& filename, render_part& part, std::string& error);

// A 64-bit value as 16 lower-case hex digits (part checksums, scene fingerprints).
std::string hex_string(uint64_t value);

}  // namespace yocto

// -----------------------------------------------------------------------------
// FILE HELPERS
// -----------------------------------------------------------------------------
namespace yocto {

// Checks that filename names a regular file and gives its size: a
// directory, a device (/dev/zero reads forever) or a fifo (blocks) is refused
// with a message naming it. Every loader checks its inputs with this first.
bool check_input_file(const std::string& filename, size_t& size, std::string& error);

// Writes a file through a temporary in the same directory, then renames.
// The text is written byte for byte, so binary data works too.
bool save_text(const std::string& filename, const std::string& text, std::string& error);
bool load_text(const std::string& filename, std::string& text, std::string& error);

// Path helpers: directory of a path (with trailing separator or empty),
// extension (with dot, lower case), and join.
std::string path_dirname(const std::string& filename);
std::string path_extension(const std::string& filename);
std::string path_join(const std::string& directory, const std::string& filename);

// An output being written: a temporary next to its final name, created
// exclusively under an unpredictable name (never an existing file or a
// link planted there), filled, checked and renamed into place. Until then
// it is listed for remove_pending_outputs, so no exit path leaves it.
struct output_file {
  std::string filename  = "";  // the final name
  std::string temporary = "";  // where the bytes go until the rename
  int         descriptor = -1;
  size_t      written    = 0;
};

// Creates the temporary of `filename` (same folder and extension).
bool open_output_file(output_file& file, const std::string& filename, std::string& error);
// Writes all of `data` (short writes are continued, failures reported).
bool write_output_file(output_file& file, const void* data, size_t size, std::string& error);
// Flushes to disk and checks the size on disk against the bytes written:
// a full disk or a file-size limit fails here, not after the rename.
bool finish_output_file(output_file& file, std::string& error);
// Finishes the files and renames them into place as one step: signals wait
// until all are renamed, and if a rename fails the files already replaced
// are restored from backups. With replace false, an existing file is never
// overwritten (the commit fails instead). On failure nothing is left.
bool commit_output_files(std::vector<output_file>& files, std::string& error,
    bool replace = true);
bool commit_output_file(output_file& file, std::string& error, bool replace = true);
// Removes the temporaries of unfinished or failed outputs.
void discard_output_files(std::vector<output_file>& files);
void discard_output_file(output_file& file);

// Checks up front that `filename` can be written: its folder exists and
// takes a new file, the name is not a folder, and the disk has `bytes` free.
bool check_output_file(const std::string& filename, double bytes, std::string& error);

// A folder made for outputs: listed for remove_pending_outputs until
// keep_output_directories, so a failed or interrupted command removes the
// folders it created (only if empty; never one that existed).
bool make_output_directories(const std::string& directory, std::string& error);
void keep_output_directories();
void remove_output_directories();

// Removes every pending temporary and every folder listed above. Uses only
// unlink and rmdir, so signal handlers may call it.
void remove_pending_outputs();

// The memory one load may ask for, in bytes. Sizes read from a file (image
// pixels, element counts, inflated text, generated geometry) are checked
// against it before anything is allocated, so a tiny file claiming a huge
// size fails with a message naming the file instead of exhausting memory.
// yscene sets it from --max-memory; the default is 3/4 of physical memory,
// or of the address-space limit (ulimit -v) when that is lower.
extern double load_memory_limit;

// Checks that `what` in `filename` needing `bytes` fits load_memory_limit;
// otherwise sets error to "FILENAME: WHAT needs N MiB, over the memory limit
// of M MiB (--max-memory)" and returns false. Bytes are a double so that
// products of untrusted counts cannot overflow.
bool check_load_memory(const std::string& filename, const std::string& what,
    double bytes, std::string& error);

}  // namespace yocto

#endif
