//
// Images through OpenImageIO: exact float round trips, 8-bit sRGB within
// quantisation, grey and alpha inputs, and failures that leave no file.
// Also the file and path helpers.
//

#include <gtest/gtest.h>

#include <OpenImageIO/imageio.h>
#include <sys/stat.h>
#include <yocto/yocto_image.h>

#include "test_io.h"

using namespace yocto;
using namespace yocto_test;

namespace {

// A small image with values across the range, above 1 and tiny ones too.
texture_data make_image(int width, int height, float scale) {
  auto image = texture_data{width, height, {}};
  for (auto j = 0; j < height; j++) {
    for (auto i = 0; i < width; i++) {
      auto u = (i + 0.3f) / width, v = (j + 0.7f) / height;
      image.pixels.push_back(scale * vec3f{u, v * v, 0.001f + u * v / 3});
    }
  }
  return image;
}

// sRGB encoding (IEC 61966-2-1), to compare 8-bit files in their own space.
float encode_srgb(float c) {
  return c <= 0.0031308f ? 12.92f * c : 1.055f * std::pow(c, 1 / 2.4f) - 0.055f;
}

// Writes an 8-bit image with the given channels straight through OpenImageIO,
// colours not premultiplied.
void write_8bit(const std::string& filename, int width, int height, int channels,
    const std::vector<uint8_t>& bytes) {
  auto output = OIIO::ImageOutput::create(filename);
  ASSERT_TRUE(output);
  auto spec = OIIO::ImageSpec(width, height, channels, OIIO::TypeDesc::UINT8);
  spec.attribute("oiio:UnassociatedAlpha", 1);  // store the bytes as given
  ASSERT_TRUE(output->open(filename, spec));
  ASSERT_TRUE(output->write_image(OIIO::TypeDesc::UINT8, bytes.data()));
  ASSERT_TRUE(output->close());
}

}  // namespace

static void exr_and_pfm_round_trips_are_exact() {
  auto dir = scratch_directory("image-float");
  for (auto name : {"image.exr", "image.pfm"}) {
    auto image = make_image(7, 5, 40);
    auto error = std::string{};
    ASSERT_TRUE(save_image(dir.file(name), image, error)) << error;
    auto loaded = texture_data{};
    ASSERT_TRUE(load_image(dir.file(name), loaded, error)) << error;
    EXPECT_EQ(loaded.width, 7);
    EXPECT_EQ(loaded.height, 5);
    EXPECT_EQ(loaded.pixels, image.pixels) << name;  // row 0 stays the top row
  }
  EXPECT_EQ(list_files(dir.path), (std::vector<std::string>{"image.exr", "image.pfm"}));
}

static void hdr_round_trip_is_within_rgbe_precision() {
  auto dir   = scratch_directory("image-hdr");
  auto image = make_image(6, 4, 25);
  auto error = std::string{};
  ASSERT_TRUE(save_image(dir.file("image.hdr"), image, error)) << error;
  auto loaded = texture_data{};
  ASSERT_TRUE(load_image(dir.file("image.hdr"), loaded, error)) << error;
  ASSERT_EQ(loaded.pixels.size(), image.pixels.size());
  // RGBE keeps an 8-bit mantissa under the largest channel's exponent: the
  // error is at most 1/128 of that channel.
  for (size_t i = 0; i < image.pixels.size(); i++)
    for (auto c = 0; c < 3; c++)
      EXPECT_NEAR(loaded.pixels[i][c], image.pixels[i][c], max_component(image.pixels[i]) / 128);
}

static void png_round_trip_is_within_quantisation_with_exposure() {
  auto dir = scratch_directory("image-png");
  for (auto exposure : {0.0f, 1.0f}) {
    auto image = make_image(9, 6, 0.9f);
    auto error = std::string{};
    ASSERT_TRUE(save_image(dir.file("image.png"), image, error, exposure)) << error;
    auto loaded = texture_data{};
    ASSERT_TRUE(load_image(dir.file("image.png"), loaded, error)) << error;
    ASSERT_EQ(loaded.pixels.size(), image.pixels.size());
    // Saved: sRGB of min(2^exposure x, 1) rounded to 1/255; loaded back to
    // linear. In sRGB space the error is half a step (plus float slack).
    auto scale = std::exp2(exposure);
    for (size_t i = 0; i < image.pixels.size(); i++) {
      for (auto c = 0; c < 3; c++) {
        auto expected = encode_srgb(std::min(image.pixels[i][c] * scale, 1.0f));
        EXPECT_NEAR(encode_srgb(loaded.pixels[i][c]), expected, 0.5f / 255 + 1e-5f);
      }
    }
  }
  // jpg is lossy: a smooth image stays close.
  auto image = make_image(16, 16, 0.8f);
  auto error = std::string{};
  ASSERT_TRUE(save_image(dir.file("image.jpg"), image, error)) << error;
  auto loaded = texture_data{};
  ASSERT_TRUE(load_image(dir.file("image.jpg"), loaded, error)) << error;
  ASSERT_EQ(loaded.pixels.size(), image.pixels.size());
  for (size_t i = 0; i < image.pixels.size(); i++)
    EXPECT_NEAR(encode_srgb(loaded.pixels[i].y), encode_srgb(image.pixels[i].y), 0.05f);
}

static void grey_becomes_rgb_and_alpha_is_dropped() {
  auto dir = scratch_directory("image-channels");
  write_8bit(dir.file("grey.png"), 2, 1, 1, {0, 255});
  write_8bit(dir.file("rgba.png"), 1, 1, 4, {255, 188, 0, 10});
  auto image = texture_data{};
  auto error = std::string{};
  ASSERT_TRUE(load_image(dir.file("grey.png"), image, error)) << error;
  EXPECT_EQ(image.pixels, (std::vector<vec3f>{{0, 0, 0}, {1, 1, 1}}));
  ASSERT_TRUE(load_image(dir.file("rgba.png"), image, error)) << error;
  ASSERT_EQ(image.pixels.size(), 1u);
  // sRGB 188/255 is linear 0.5029 (IEC 61966-2-1).
  EXPECT_NEAR(image.pixels[0].x, 1, 1e-6f);
  EXPECT_NEAR(image.pixels[0].y, 0.5029f, 1e-3f);
  EXPECT_EQ(image.pixels[0].z, 0);
}

static void bad_inputs_fail_naming_the_file_and_leave_nothing() {
  auto dir   = scratch_directory("image-errors");
  auto image = make_image(4, 3, 1);
  auto error = std::string{};
  // A PNG whose text chunk claims 1.8 GB (libpng allocated it inside
  // OpenImageIO's open; found by fuzz_image): refused from its header.
  ASSERT_TRUE(save_image(dir.file("chunk.png"), image, error)) << error;
  auto png = read_file(dir.file("chunk.png"));
  auto chunk = std::string{"\x70\x00\x00\x14", 4} + "tEXtComment" + std::string(1, '\0') + "hello";
  png.insert(33, chunk);
  write_file(dir.file("chunk.png"), png);
  auto chunk_bomb = texture_data{};
  EXPECT_FALSE(load_image(dir.file("chunk.png"), chunk_bomb, error));
  EXPECT_TRUE(contains(error, dir.file("chunk.png")) && contains(error, "tEXt") &&
              contains(error, "more than the file holds"))
      << error;
  std::filesystem::remove(dir.file("chunk.png"));
  EXPECT_FALSE(save_image(dir.file("image.xyz"), image, error));
  EXPECT_TRUE(contains(error, dir.file("image.xyz")) && contains(error, ".xyz")) << error;
  EXPECT_FALSE(save_image(dir.file("noextension"), image, error));
  EXPECT_FALSE(save_image(dir.file("no/such/dir/image.png"), image, error));
  EXPECT_TRUE(contains(error, "no/such/dir/image.png")) << error;
  auto short_image = image;
  short_image.pixels.pop_back();
  EXPECT_FALSE(save_image(dir.file("short.exr"), short_image, error));
  EXPECT_TRUE(contains(error, "short.exr")) << error;
  auto nan_image         = image;
  nan_image.pixels[5].y = std::nanf("");
  EXPECT_FALSE(save_image(dir.file("nan.exr"), nan_image, error));
  EXPECT_TRUE(contains(error, "(1, 1)")) << error;
  EXPECT_TRUE(list_files(dir.path).empty());

  auto loaded = texture_data{};
  EXPECT_FALSE(load_image(dir.file("missing.png"), loaded, error));
  EXPECT_TRUE(contains(error, dir.file("missing.png"))) << error;
  write_file(dir.file("garbage.png"), "not an image at all");
  EXPECT_FALSE(load_image(dir.file("garbage.png"), loaded, error));
  EXPECT_TRUE(contains(error, dir.file("garbage.png"))) << error;
  EXPECT_TRUE(loaded.pixels.empty());
  // A PNG cut inside its chunks: OpenImageIO 2.4 leaks on this path, which
  // the sanitized build suppresses (scripts/lsan.supp), not our code.
  ASSERT_TRUE(save_image(dir.file("whole.png"), image, error)) << error;
  write_file(dir.file("cut.png"), read_file(dir.file("whole.png")).substr(0, 40));
  EXPECT_FALSE(load_image(dir.file("cut.png"), loaded, error));
  EXPECT_TRUE(contains(error, dir.file("cut.png"))) << error;

  EXPECT_TRUE(is_image_filename("a/b.EXR"));
  EXPECT_TRUE(is_image_filename("b.jpeg"));
  EXPECT_FALSE(is_image_filename("b.tiff.gz"));
  EXPECT_FALSE(is_image_filename("png"));
}

static void paths_and_temporary_names() {
  EXPECT_EQ(path_dirname("a/b/c.json"), "a/b/");
  EXPECT_EQ(path_dirname("c.json"), "");
  EXPECT_EQ(path_extension("a.b/c.PLY"), ".ply");
  EXPECT_EQ(path_extension("a.b/c"), "");
  EXPECT_EQ(path_join("a/", "b.ply"), "a/b.ply");
  EXPECT_EQ(path_join("a", "b.ply"), "a/b.ply");
  EXPECT_EQ(path_join("", "b.ply"), "b.ply");
  EXPECT_EQ(path_join("a", "/abs/b.ply"), "/abs/b.ply");
  auto dir   = scratch_directory("files-text");
  auto error = std::string{};
  ASSERT_TRUE(save_text(dir.file("a.txt"), "hello\n", error)) << error;
  auto text = std::string{};
  ASSERT_TRUE(load_text(dir.file("a.txt"), text, error)) << error;
  EXPECT_EQ(text, "hello\n");
  EXPECT_FALSE(load_text(dir.file("b.txt"), text, error));
  EXPECT_TRUE(contains(error, dir.file("b.txt"))) << error;
  EXPECT_FALSE(load_text(dir.path, text, error));
  EXPECT_FALSE(save_text(dir.file("no/dir/a.txt"), "x", error));
  EXPECT_EQ(list_files(dir.path), (std::vector<std::string>{"a.txt"}));
}

// Tiny files whose headers claim huge images are refused before a pixel is
// allocated: by what the file can hold (PNM, PFM, PNG) or by the memory
// limit (anything). Devices and fifos are refused before the image library
// opens them (it would read /dev/zero forever, wait on a fifo).
TEST(image, header_bombs_devices_and_fifos_are_refused_before_reading) {
  auto dir   = scratch_directory("image-bombs");
  auto error = std::string{};
  auto image = texture_data{};
  write_file(dir.file("big.pgm"), "P5\n46000 46000\n255\n");
  write_file(dir.file("big.pfm"), "PF\n46000 46000\n-1.0\n");
  for (auto name : {"big.pgm", "big.pfm"}) {
    EXPECT_FALSE(load_image(dir.file(name), image, error));
    EXPECT_TRUE(contains(error, dir.file(name)) && contains(error, "46000x46000") &&
                contains(error, "can hold"))
        << error;
  }
  // A valid 2x2 PNG whose header is patched to claim 19000x19000 pixels.
  write_8bit(dir.file("small.png"), 2, 2, 3, std::vector<uint8_t>(12, 100));
  write_file(dir.file("big.png"), patch_png_size(read_file(dir.file("small.png")), 19000, 19000));
  EXPECT_FALSE(load_image(dir.file("big.png"), image, error));
  EXPECT_TRUE(contains(error, dir.file("big.png")) && contains(error, "19000x19000") &&
              contains(error, "can hold"))
      << error;
  // Compressed formats are bounded by the memory limit.
  ASSERT_TRUE(save_image(dir.file("small.exr"), make_image(64, 32, 1), error)) << error;
  auto loaded = load_image(dir.file("small.exr"), image, error, 10000);
  EXPECT_FALSE(loaded);
  EXPECT_TRUE(contains(error, dir.file("small.exr")) && contains(error, "64x32") &&
              contains(error, "over the memory limit"))
      << error;
  EXPECT_TRUE(load_image(dir.file("small.exr"), image, error)) << error;
  // Not regular files.
  std::filesystem::create_symlink("/dev/zero", dir.file("zero.hdr"));
  ASSERT_EQ(mkfifo(dir.file("fifo.png").c_str(), 0600), 0);
  for (auto name : {"zero.hdr", "fifo.png"}) {
    EXPECT_FALSE(load_image(dir.file(name), image, error));
    EXPECT_TRUE(contains(error, dir.file(name)) && contains(error, "not a regular file"))
        << error;
    auto text = std::string{};
    EXPECT_FALSE(load_text(dir.file(name), text, error));
    EXPECT_TRUE(contains(error, dir.file(name)) && contains(error, "not a regular file"))
        << error;
  }
  EXPECT_FALSE(load_image(dir.path, image, error));
  EXPECT_TRUE(contains(error, "is a directory")) << error;
}

TEST(image, loads_the_real_pbrt_sky_pfm) {
  auto filename = std::string(YOCTO_SHARED_DIR) + "/data/pbrt/pbrt-v3/hair/textures/Skydome.pfm";
  if (!std::filesystem::exists(filename)) GTEST_SKIP() << "no " << filename;
  auto image = texture_data{};
  auto error = std::string{};
  ASSERT_TRUE(load_image(filename, image, error)) << error;
  EXPECT_EQ(image.width, 512);
  EXPECT_EQ(image.height, 256);
  // A sky: the top row is brighter than the bottom row.
  auto top = vec3f{0, 0, 0}, bottom = vec3f{0, 0, 0};
  for (auto i = 0; i < image.width; i++) {
    top += image.pixels[i];
    bottom += image.pixels[(size_t)(image.height - 1) * image.width + i];
  }
  EXPECT_GT(luminance(top), luminance(bottom));
}

// Grouped so that ctest starts few processes: each one pays for loading
// OpenImageIO and its libraries (about 0.3 s).
TEST(image, round_trips_in_every_format_and_reads_grey_and_alpha) {
  exr_and_pfm_round_trips_are_exact();
  hdr_round_trip_is_within_rgbe_precision();
  png_round_trip_is_within_quantisation_with_exposure();
  grey_becomes_rgb_and_alpha_is_dropped();
}

TEST(image, rejects_bad_input_and_file_helpers_work) {
  bad_inputs_fail_naming_the_file_and_leave_nothing();
  paths_and_temporary_names();
}
