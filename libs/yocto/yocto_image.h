//
// # Yocto/Image: images and render parts
//
// Images through OpenImageIO: linear RGB in memory, read from any format it
// reads and written as exr, hdr, pfm (linear) or png, jpg (sRGB), with AOV
// layers in OpenEXR. Render parts: the exact per-pixel sums of a range of a
// render's samples, in OpenEXR, that a merge adds up bit for bit. Loads
// check the size a header claims against the load's memory limit before
// allocating; saves write through a temporary name (yocto_fileio.h).
//

#ifndef YOCTO_IMAGE_H_
#define YOCTO_IMAGE_H_

#include <cstdint>
#include <string>
#include <vector>

#include "yocto_fileio.h"
#include "yocto_scene.h"

// -----------------------------------------------------------------------------
// IMAGES
// -----------------------------------------------------------------------------
namespace yocto {

// Loads any image OpenImageIO reads as linear RGB (8-bit formats are
// converted from sRGB). Its pixels, as the header claims them, must fit
// max_memory.
bool load_image(const std::string& filename, texture_data& image, std::string& error,
    double max_memory = default_memory_limit());

// Saves linear RGB pixels: exr/hdr/pfm stay linear (exr and pfm as 32-bit
// float), png/jpg are scaled by 2^exposure, clamped, converted to sRGB and
// quantised. Unknown extension and non-finite pixels are errors. With
// replace false an existing file is an error, never overwritten.
bool save_image(const std::string& filename, const texture_data& image,
    std::string& error, float exposure = 0, bool replace = true);

// Encodes an image in memory as save_image writes it (filename names it in
// messages and gives the format), for savers that write several files as one.
bool encode_image(const std::string& filename, const texture_data& image,
    std::string& data, std::string& error, float exposure = 0);

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
// or inconsistent (a range outside [0, samples)) is an error naming it. Its
// pixels must fit max_memory.
bool load_render_part(const std::string& filename, render_part& part, std::string& error,
    double max_memory = default_memory_limit());

}  // namespace yocto

#endif
