//
// Implementation of Yocto/Image: see yocto_image.h.
//

#include "yocto_image.h"

#include <OpenImageIO/filesystem.h>
#include <OpenImageIO/imageio.h>

#include <algorithm>
#include <array>
#include <cctype>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <limits>
#include <new>

// -----------------------------------------------------------------------------
// IMAGES
// -----------------------------------------------------------------------------
namespace yocto {

// sRGB transfer function (IEC 61966-2-1).
static float srgb_to_linear(float c) {
  return c <= 0.04045f ? c / 12.92f : std::pow((c + 0.055f) / 1.055f, 2.4f);
}
static float linear_to_srgb(float c) {
  return c <= 0.0031308f ? 12.92f * c : 1.055f * std::pow(c, 1 / 2.4f) - 0.055f;
}

static bool is_linear_extension(const std::string& extension) {
  return extension == ".exr" || extension == ".hdr" || extension == ".pfm";
}
static bool is_8bit_extension(const std::string& extension) {
  return extension == ".png" || extension == ".jpg" || extension == ".jpeg";
}

// OpenImageIO 2.4 reads PFM but cannot write it: the format is a short
// header and raw little-endian floats, rows from the bottom up.
static void encode_pfm(const texture_data& image, std::string& data) {
  data = "PF\n" + std::to_string(image.width) + " " + std::to_string(image.height) +
         "\n-1.0\n";  // a negative scale means little-endian
  data.reserve(data.size() + image.pixels.size() * 12);
  for (auto j = image.height - 1; j >= 0; j--) {
    for (auto i = 0; i < image.width; i++) {
      auto& pixel = image.pixels[(size_t)j * image.width + i];
      for (auto c = 0; c < 3; c++) append_raw(data, pixel[c]);
    }
  }
}

bool is_image_filename(const std::string& filename) {
  auto extension = path_extension(filename);
  return is_linear_extension(extension) || is_8bit_extension(extension);
}

// Refuses an image whose header claims more pixels than the file can hold or
// than the memory limit allows, before a pixel is allocated. Uncompressed
// formats (PFM, PNM) store every value; PNG's deflate stream inflates at
// most 1032 times (a 258-byte match coded in two bits) into rows of at
// least one filter byte and one bit a pixel. Other formats (EXR, JPEG,
// HDR's run lengths) compress too well to bound: the memory limit alone.
static bool check_image_size(const std::string& filename, const OIIO::ImageSpec& spec,
    const std::string& format, size_t file_size, double max_memory, std::string& error) {
  auto width = (double)spec.width, height = (double)spec.height;
  auto channels = (double)spec.nchannels;
  auto size     = std::to_string(spec.width) + "x" + std::to_string(spec.height);
  auto min_bytes = 0.0;
  if (format == "pnm") {
    // PFM is floats; PNM is binary at its bit depth, or ascii with at least
    // one character a value.
    auto bits = (double)spec.get_int_attribute("oiio:BitsPerSample", 8 * (int)spec.format.size());
    if (spec.get_int_attribute("pnm:binary", 1) != 0)
      min_bytes = height * std::ceil(width * channels * bits / 8);
    else min_bytes = height * width * channels;
  } else if (format == "png") {
    min_bytes = height * (1 + std::ceil(width / 8)) / 1032;
  }
  if (min_bytes > (double)file_size) {
    error = filename + ": the header claims " + size + " pixels, more than the file's " +
            std::to_string(file_size) + " bytes can hold";
    return false;
  }
  // What load_image allocates: the decoder's buffer, the float values read
  // and the RGB pixels kept.
  auto pixels = width * height;
  auto bytes  = pixels * channels * (spec.format.size() + sizeof(float)) +
               pixels * sizeof(vec3f);
  auto what = "a " + size + " image with " + std::to_string(spec.nchannels) +
              (spec.nchannels == 1 ? " channel" : " channels");
  return check_load_memory(filename, what, bytes, max_memory, error);
}

// Four bytes of a chunk type, printable whatever they hold.
static std::string printable_name(const unsigned char* bytes, int count) {
  auto name = std::string{};
  for (auto i = 0; i < count; i++)
    name += std::isalnum(bytes[i]) ? (char)bytes[i] : '?';
  return name;
}

// libpng allocates an ancillary chunk (iCCP, zTXt, ...) at the length its
// header claims before reading it, inside OpenImageIO's open: a few hundred
// bytes claiming 2 GB allocate 2 GB. Walks the chunk headers of a PNG (by
// its signature, whatever the extension) and refuses a length past the end
// of the file (PNG spec, section 5.3), before OpenImageIO sees the file.
static bool check_png_chunks(const std::string& filename, std::string& error) {
  auto file = std::fopen(filename.c_str(), "rb");
  if (!file) return true;  // OpenImageIO reports it
  unsigned char header[8];
  auto is_png = std::fread(header, 1, 8, file) == 8 &&
                std::memcmp(header, "\x89PNG\r\n\x1a\n", 8) == 0;
  auto offset = (uint64_t)8, size = (uint64_t)0;
  if (is_png && std::fseek(file, 0, SEEK_END) == 0) size = (uint64_t)std::ftell(file);
  auto ok = true;
  while (is_png && ok && offset + 8 <= size) {
    unsigned char chunk[8];
    if (std::fseek(file, (long)offset, SEEK_SET) != 0 || std::fread(chunk, 1, 8, file) != 8)
      break;
    auto length = (uint64_t)chunk[0] << 24 | (uint64_t)chunk[1] << 16 |
                  (uint64_t)chunk[2] << 8 | (uint64_t)chunk[3];
    // Length, type, data and CRC.
    if (offset + 12 + length > size) {
      error = filename + ": PNG chunk \"" + printable_name(chunk + 4, 4) + "\" at byte " +
              std::to_string(offset) + " claims " + std::to_string(length) +
              " bytes, more than the file holds";
      ok = false;
    }
    if (std::memcmp(chunk + 4, "IEND", 4) == 0) break;
    offset += 12 + length;
  }
  std::fclose(file);
  return ok;
}

bool load_image(
    const std::string& filename, texture_data& image, std::string& error, double max_memory) try {
  image = {};
  // OpenImageIO opens the file itself: a device or fifo would never end.
  auto file_size = (size_t)0;
  if (!check_input_file(filename, file_size, error)) return false;
  if (!check_png_chunks(filename, error)) return false;
  // Colours as stored: OpenImageIO would otherwise premultiply them by an
  // alpha that we drop.
  auto config = OIIO::ImageSpec{};
  config.attribute("oiio:UnassociatedAlpha", 1);
  auto input = OIIO::ImageInput::open(filename, &config);
  if (!input) {
    auto message = OIIO::geterror();
    error = filename + ": cannot open image" + (message.empty() ? "" : " (" + message + ")");
    return false;
  }
  auto& spec     = input->spec();
  auto  channels = spec.nchannels;
  if (spec.width <= 0 || spec.height <= 0 || channels <= 0) {
    error = filename + ": image has no pixels";
    return false;
  }
  if (spec.depth > 1) {
    error = filename + ": a volume image (depth " + std::to_string(spec.depth) +
            "), not a picture";
    return false;
  }
  if (!check_image_size(filename, spec, input->format_name(), file_size, max_memory, error))
    return false;
  // Environment sampling indexes pixels with int: guard the count.
  auto num_pixels = (size_t)spec.width * (size_t)spec.height;
  if (num_pixels > ((size_t)1 << 31) / (size_t)channels) {
    error = filename + ": image too large (" + std::to_string(spec.width) + "x" +
            std::to_string(spec.height) + ")";
    return false;
  }
  auto buffer = std::vector<float>(num_pixels * channels);
  if (!input->read_image(0, 0, 0, channels, OIIO::TypeDesc::FLOAT, buffer.data())) {
    error = filename + ": cannot read image (" + input->geterror() + ")";
    return false;
  }
  input->close();

  // Float formats are linear; integer formats are sRGB unless they say
  // otherwise.
  auto colorspace = spec.get_string_attribute("oiio:ColorSpace");
  auto linear     = spec.format.is_floating_point() || colorspace == "Linear" ||
                colorspace == "linear";
  image.width  = spec.width;
  image.height = spec.height;
  image.pixels.resize(num_pixels);
  for (size_t i = 0; i < num_pixels; i++) {
    auto* pixel = buffer.data() + i * channels;
    // Grey (with or without alpha) becomes RGB; alpha is dropped.
    auto rgb = channels < 3 ? vec3f{pixel[0], pixel[0], pixel[0]}
                            : vec3f{pixel[0], pixel[1], pixel[2]};
    if (!linear)
      rgb = {srgb_to_linear(rgb.x), srgb_to_linear(rgb.y), srgb_to_linear(rgb.z)};
    if (!isfinite(rgb)) {
      error = filename + ": pixel (" + std::to_string(i % spec.width) + ", " +
              std::to_string(i / spec.width) + ") is not finite";
      image = {};
      return false;
    }
    image.pixels[i] = rgb;
  }
  return true;
} catch (const std::bad_alloc&) {
  // Past the budget's checks, the system (or ulimit -v) gave less.
  error = allocation_error(filename, "its pixels");
  return false;
}

// Encodes `pixels`, laid out in the spec's channel formats, into `data` with
// OpenImageIO, in memory; `what` names the file in the errors.
static bool encode_with_oiio(const std::string& filename, const std::string& what,
    OIIO::ImageSpec spec, const void* pixels, std::string& data, std::string& error) {
  auto output = OIIO::ImageOutput::create(filename);
  if (!output) {
    error = filename + ": cannot save " + what + " (" + OIIO::geterror() + ")";
    return false;
  }
  auto bytes  = std::vector<unsigned char>{};
  auto memory = OIIO::Filesystem::IOVecOutput(bytes);
  auto proxy  = (OIIO::Filesystem::IOProxy*)&memory;
  spec.attribute("oiio:ioproxy", OIIO::TypeDesc::PTR, &proxy);
  auto failed = [&](const std::string& step) {
    error = filename + ": cannot " + step + " " + what + " (" + output->geterror() + ")";
    return false;
  };
  if (!output->open(filename, spec)) return failed("create");
  if (!output->write_image(OIIO::TypeDesc::UNKNOWN, pixels)) return failed("write");
  if (!output->close()) return failed("finish");
  data.assign(bytes.begin(), bytes.end());
  return true;
}

// Checks that an image can be saved: a known extension, pixels for its size,
// all finite.
static bool check_image_to_save(
    const std::string& filename, const texture_data& image, std::string& error) {
  if (!is_image_filename(filename)) {
    error = filename + ": unknown image extension \"" + path_extension(filename) +
            "\" (use exr, hdr, pfm, png or jpg)";
    return false;
  }
  if (image.width <= 0 || image.height <= 0 ||
      image.pixels.size() != (size_t)image.width * (size_t)image.height) {
    error = filename + ": cannot save image: " + std::to_string(image.pixels.size()) +
            " pixels for size " + std::to_string(image.width) + "x" +
            std::to_string(image.height);
    return false;
  }
  for (size_t i = 0; i < image.pixels.size(); i++) {
    if (!isfinite(image.pixels[i])) {
      error = filename + ": cannot save image: pixel (" +
              std::to_string(i % image.width) + ", " + std::to_string(i / image.width) +
              ") is not finite";
      return false;
    }
  }
  return true;
}

// The bytes go to disk through save_text, which checks the write
// (OpenImageIO does not report a failed write of some formats, and libjpeg
// ends the program on one).
bool encode_image(const std::string& filename, const texture_data& image,
    std::string& data, std::string& error, float exposure) {
  if (!check_image_to_save(filename, image, error)) return false;
  auto extension = path_extension(filename);
  if (extension == ".pfm") return encode_pfm(image, data), true;
  if (is_linear_extension(extension)) {
    auto spec = OIIO::ImageSpec(image.width, image.height, 3, OIIO::TypeDesc::FLOAT);
    return encode_with_oiio(filename, "image", spec, image.pixels.data(), data, error);
  }
  auto spec = OIIO::ImageSpec(image.width, image.height, 3, OIIO::TypeDesc::UINT8);
  spec.attribute("oiio:ColorSpace", "sRGB");
  auto scale  = std::exp2(exposure);
  auto pixels = std::vector<uint8_t>(image.pixels.size() * 3);
  for (size_t i = 0; i < image.pixels.size(); i++) {
    for (auto c = 0; c < 3; c++) {
      auto value = std::clamp(image.pixels[i][c] * scale, 0.0f, 1.0f);
      pixels[i * 3 + c] = (uint8_t)std::lround(linear_to_srgb(value) * 255);
    }
  }
  return encode_with_oiio(filename, "image", spec, pixels.data(), data, error);
}

bool save_image(const std::string& filename, const texture_data& image,
    std::string& error, float exposure, bool replace) {
  auto data = std::string{};
  if (!encode_image(filename, image, data, error, exposure)) return false;
  return save_text(filename, data, error, replace);
}

bool save_image_layers(const std::string& filename, const texture_data& image,
    const std::vector<image_layer>& layers, std::string& error, bool replace) {
  if (path_extension(filename) != ".exr") {
    error = filename + ": image layers are saved in OpenEXR only: use a name ending in .exr";
    return false;
  }
  if (!check_image_to_save(filename, image, error)) return false;
  auto data     = std::string{};
  auto pixels   = image.pixels.size();
  auto channels = 3;
  auto spec     = OIIO::ImageSpec(image.width, image.height, 3, OIIO::TypeDesc::FLOAT);
  for (auto& layer : layers) {
    if (layer.channels.empty() || layer.pixels.size() != pixels * layer.channels.size()) {
      error = filename + ": cannot save layer " + layer.name + ": " +
              std::to_string(layer.pixels.size()) + " values for " +
              std::to_string(pixels) + " pixels of " +
              std::to_string(layer.channels.size()) + " channels";
      return false;
    }
    for (size_t i = 0; i < layer.pixels.size(); i++) {
      if (!std::isfinite(layer.pixels[i])) {
        auto pixel = i / layer.channels.size();
        error = filename + ": cannot save layer " + layer.name + ": pixel (" +
                std::to_string(pixel % image.width) + ", " +
                std::to_string(pixel / image.width) + ") is not finite";
        return false;
      }
    }
    for (auto& channel : layer.channels) spec.channelnames.push_back(layer.name + "." + channel);
    channels += (int)layer.channels.size();
  }
  spec.nchannels = channels;
  spec.attribute("compression", "zip");
  auto values = std::vector<float>(pixels * channels);
  for (size_t i = 0; i < pixels; i++) {
    auto out = &values[i * channels];
    for (auto c = 0; c < 3; c++) *out++ = image.pixels[i][c];
    for (auto& layer : layers) {
      auto count = layer.channels.size();
      for (size_t c = 0; c < count; c++) *out++ = layer.pixels[i * count + c];
    }
  }
  if (!encode_with_oiio(filename, "image", spec, values.data(), data, error)) return false;
  return save_text(filename, data, error, replace);
}

}  // namespace yocto

// -----------------------------------------------------------------------------
// RENDER PARTS
// -----------------------------------------------------------------------------
namespace yocto {

static const auto render_part_format = std::string{"yocto-hair render part 1"};
static const auto render_part_channels = std::array<std::string, 3>{"R", "G", "B"};

// The name of the channel with bits 32 half ... 32 half + 31 of channel c.
// Extra sum k: "extra.K." before the same names.
static std::string render_part_channel(int c, int half, int extra = -1) {
  auto prefix = extra < 0 ? std::string{"sum."} : "extra." + std::to_string(extra) + ".";
  return prefix + render_part_channels[c] + "." + std::to_string(half);
}

static std::string render_part_range(const render_part& part) {
  return std::to_string(part.first) + ":" + std::to_string(part.first + part.count);
}

static uint64_t render_part_checksum(const render_part& part) {
  auto stream = hash_stream{};
  hash_bytes(stream, render_part_format.data(), render_part_format.size());
  hash_bytes(stream, part.settings.data(), part.settings.size());
  for (auto value : {(int64_t)part.samples, (int64_t)part.first, (int64_t)part.count,
           (int64_t)part.width, (int64_t)part.height, part.rays, part.nonfinite})
    hash_word(stream, (uint64_t)value);
  hash_bytes(stream, part.sums.data(), part.sums.size() * sizeof(fixed_sum3));
  // Parts without extra sums keep the checksums they always had.
  if (part.extra > 0) {
    hash_word(stream, (uint64_t)part.extra);
    hash_bytes(stream, part.extra_sums.data(), part.extra_sums.size() * sizeof(fixed_sum3));
  }
  return stream.hash;
}

bool save_render_part(const std::string& filename, const render_part& part,
    std::string& error, bool replace) {
  if (path_extension(filename) != ".exr") {
    error = filename + ": a render part is an OpenEXR image: use a name ending in .exr";
    return false;
  }
  if (part.width <= 0 || part.height <= 0 || part.count <= 0 ||
      part.sums.size() != (size_t)part.width * (size_t)part.height) {
    error = filename + ": cannot save a render part without samples or pixels";
    return false;
  }
  if (part.extra < 0 || part.extra_sums.size() != part.sums.size() * part.extra) {
    error = filename + ": cannot save a render part whose extra sums do not fit its pixels";
    return false;
  }
  // R, G, B as floats, then the words as 32-bit halves: the sums', then each
  // extra sum's.
  auto sums     = 1 + part.extra;
  auto channels = 3 + 18 * sums;
  auto spec     = OIIO::ImageSpec(part.width, part.height, channels, OIIO::TypeDesc::FLOAT);
  spec.channelnames.assign(render_part_channels.begin(), render_part_channels.end());
  spec.channelformats.assign(3, OIIO::TypeDesc::FLOAT);
  for (auto k = -1; k < part.extra; k++) {
    for (auto c = 0; c < 3; c++) {
      for (auto half = 0; half < 6; half++) {
        spec.channelnames.push_back(render_part_channel(c, half, k));
        spec.channelformats.push_back(OIIO::TypeDesc::UINT32);
      }
    }
  }
  spec.attribute("compression", "zip");
  spec.attribute("yocto:part", render_part_format);
  spec.attribute("yocto:settings", part.settings);
  spec.attribute("yocto:samples", std::to_string(part.samples));
  spec.attribute("yocto:range", render_part_range(part));
  spec.attribute("yocto:rays", std::to_string(part.rays));
  spec.attribute("yocto:nonfinite", std::to_string(part.nonfinite));
  if (part.extra > 0) spec.attribute("yocto:extra", std::to_string(part.extra));
  spec.attribute("yocto:checksum", hex_string(render_part_checksum(part)));
  // Pixels in the native layout: 3 floats, then 18 unsigned ints a sum.
  auto pixel_words = (size_t)channels;
  static_assert(render_part_pixel_bytes == 4 * (3 + 18) && render_part_extra_bytes == 4 * 18);
  auto pixels = std::vector<uint32_t>(part.sums.size() * pixel_words);
  for (size_t i = 0; i < part.sums.size(); i++) {
    auto out  = &pixels[i * pixel_words];
    auto mean = glm::vec3(fixed_to_double(part.sums[i]) / (double)part.count);
    std::memcpy(out, &mean[0], 3 * sizeof(float));
    out += 3;
    for (auto k = -1; k < part.extra; k++) {
      auto& sum = k < 0 ? part.sums[i] : part.extra_sums[i * part.extra + k];
      for (auto word = 0; word < 9; word++) {
        *out++ = (uint32_t)sum.words[word];
        *out++ = (uint32_t)(sum.words[word] >> 32);
      }
    }
  }
  auto data = std::string{};
  if (!encode_with_oiio(filename, "render part", spec, pixels.data(), data, error)) return false;
  return save_text(filename, data, error, replace);
}

// A whole decimal number from an attribute, or false.
static bool parse_part_number(const std::string& text, int64_t& value) {
  auto end    = text.data() + text.size();
  auto result = std::from_chars(text.data(), end, value);
  return !text.empty() && result.ec == std::errc{} && result.ptr == end;
}

bool load_render_part(
    const std::string& filename, render_part& part, std::string& error, double max_memory) try {
  part           = {};
  auto file_size = (size_t)0;
  if (!check_input_file(filename, file_size, error)) return false;
  auto input = OIIO::ImageInput::open(filename);
  if (!input) {
    auto message = OIIO::geterror();
    error = filename + ": cannot open render part" + (message.empty() ? "" : " (" + message + ")");
    return false;
  }
  auto& spec     = input->spec();
  auto  not_part = [&](const std::string& what) {
    error = filename + ": not a render part of yocto-hair (" + what + ")";
    return false;
  };
  if (spec.get_string_attribute("yocto:part") != render_part_format)
    return not_part("no yocto:part attribute \"" + render_part_format + "\"");
  auto samples = (int64_t)0, first = (int64_t)0, end = (int64_t)0;
  auto range   = std::string(spec.get_string_attribute("yocto:range"));
  auto colon   = range.find(':');
  if (!parse_part_number(spec.get_string_attribute("yocto:samples"), samples) ||
      colon == std::string::npos || !parse_part_number(range.substr(0, colon), first) ||
      !parse_part_number(range.substr(colon + 1), end) ||
      !parse_part_number(spec.get_string_attribute("yocto:rays"), part.rays) ||
      !parse_part_number(spec.get_string_attribute("yocto:nonfinite"), part.nonfinite))
    return not_part("bad yocto:samples, yocto:range, yocto:rays or yocto:nonfinite");
  if (samples <= 0 || samples > std::numeric_limits<int>::max() || first < 0 ||
      end <= first || end > samples) {
    error = filename + ": sample range " + range + " is not within the render's " +
            std::to_string(samples) + " samples";
    return false;
  }
  part.samples  = (int)samples;
  part.first    = (int)first;
  part.count    = (int)(end - first);
  part.settings = std::string(spec.get_string_attribute("yocto:settings"));
  part.width    = spec.width;
  part.height   = spec.height;
  // Where each channel is in a native pixel.
  auto offsets = std::vector<size_t>(spec.nchannels);
  for (auto c = 1; c < spec.nchannels; c++)
    offsets[c] = offsets[c - 1] + spec.channelformat(c - 1).size();
  auto extra = (int64_t)0;
  if (spec.find_attribute("yocto:extra") &&
      (!parse_part_number(spec.get_string_attribute("yocto:extra"), extra) || extra < 1 ||
          extra > 64))
    return not_part("bad yocto:extra");
  part.extra       = (int)extra;
  auto sum_offsets = std::vector<size_t>(18 * (1 + part.extra));
  for (auto k = -1; k < part.extra; k++) {
    for (auto c = 0; c < 3; c++) {
      for (auto half = 0; half < 6; half++) {
        auto name  = render_part_channel(c, half, k);
        auto found = std::find(spec.channelnames.begin(), spec.channelnames.end(), name);
        if (found == spec.channelnames.end()) return not_part("no channel " + name);
        auto index = (int)(found - spec.channelnames.begin());
        if (spec.channelformat(index) != OIIO::TypeDesc::UINT32)
          return not_part("channel " + name + " is not 32-bit unsigned");
        sum_offsets[18 * (k + 1) + 6 * c + half] = offsets[index];
      }
    }
  }
  if (spec.width <= 0 || spec.height <= 0 || spec.depth > 1) return not_part("no pixels");
  auto pixels      = (double)spec.width * (double)spec.height;
  auto pixel_bytes = spec.pixel_bytes(true);
  if (!check_load_memory(filename,
          "a " + std::to_string(spec.width) + "x" + std::to_string(spec.height) + " render part",
          pixels * ((double)pixel_bytes + (1 + part.extra) * sizeof(fixed_sum3)), max_memory,
          error))
    return false;
  auto buffer = std::vector<unsigned char>((size_t)pixels * pixel_bytes);
  if (!input->read_image(0, 0, 0, spec.nchannels, OIIO::TypeDesc::UNKNOWN, buffer.data())) {
    error = filename + ": cannot read render part (" + input->geterror() + ")";
    return false;
  }
  input->close();
  part.sums.resize((size_t)pixels);
  part.extra_sums.resize((size_t)pixels * part.extra);
  for (size_t i = 0; i < part.sums.size(); i++) {
    auto pixel = buffer.data() + i * pixel_bytes;
    for (auto k = -1; k < part.extra; k++) {
      auto& sum     = k < 0 ? part.sums[i] : part.extra_sums[i * part.extra + k];
      auto  offsets = &sum_offsets[18 * (k + 1)];
      for (auto word = 0; word < 9; word++) {
        uint32_t low, high;
        std::memcpy(&low, pixel + offsets[2 * word], 4);
        std::memcpy(&high, pixel + offsets[2 * word + 1], 4);
        sum.words[word] = (uint64_t)high << 32 | low;
      }
    }
  }
  if (spec.get_string_attribute("yocto:checksum") != hex_string(render_part_checksum(part))) {
    error = filename + ": render part is damaged (its checksum does not match its contents)";
    part  = {};
    return false;
  }
  return true;
} catch (const std::bad_alloc&) {
  // Past the budget's checks, the system (or ulimit -v) gave less.
  error = allocation_error(filename, "the part");
  return false;
}

}  // namespace yocto
