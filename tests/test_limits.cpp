//
// Memory bombs and hangs: tiny inputs that claim gigabytes or never end (an
// image header, a PNG header, a json scene naming one PLY 20000 times, a
// render resolution, a .hair header, devices as files), each run through
// yscene under an address-space limit of 1 GiB and without one, with an
// alarm. Each ends with exit status 1 and one error line naming the file,
// never an abort, a signal, "out of memory" or a hang; a normal tiny scene
// still renders under the same limits.
//

#include <gtest/gtest.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>
#include <yocto/yocto_image.h>

#include <cstdint>
#include <filesystem>
#include <sstream>
#include <vector>

#include "run_yscene.h"
#include "test_io.h"

using namespace yocto;
using namespace yocto_test;
namespace fs = std::filesystem;

// -----------------------------------------------------------------------------
// HELPERS
// -----------------------------------------------------------------------------
namespace {

// Runs yscene with the arguments under RLIMIT_AS of 1 GiB (ulimit -v
// 1048576), or with no address-space limit, and an alarm of 30 seconds (a
// hang ends in SIGALRM, not in the test's timeout).
command_result run_limited(const std::vector<std::string>& arguments, bool limited = true) {
  return run_yscene_in_child(arguments, [limited]() {
#ifndef YOCTO_SANITIZED
    // AddressSanitizer reserves terabytes of address space for its shadow
    // memory, so under it no address-space limit can apply: the sanitized
    // suite still checks every message, exit status and the alarm.
    auto limit = rlimit{(rlim_t)1 << 30, (rlim_t)1 << 30};
    if (limited) setrlimit(RLIMIT_AS, &limit);
#endif
    alarm(30);  // kept across exec
  });
}

// Exit status 1 and exactly one line, "error: ...", naming every part.
void expect_refused(const command_result& result, const std::vector<std::string>& parts) {
  EXPECT_EQ(result.signal, 0) << result.output;
  EXPECT_EQ(result.status, 1) << result.output;
  auto lines  = std::vector<std::string>{};
  auto stream = std::istringstream(result.output);
  for (auto line = std::string{}; std::getline(stream, line);) lines.push_back(line);
  ASSERT_EQ(lines.size(), 1u) << result.output;
  EXPECT_EQ(lines[0].rfind("error: ", 0), 0u) << lines[0];
  EXPECT_EQ(lines[0].find("out of memory"), std::string::npos) << lines[0];
  for (auto& part : parts)
    EXPECT_NE(lines[0].find(part), std::string::npos) << lines[0] << "\nlacks: " << part;
}

// The same refusal under the address-space limit and without one.
void expect_refused_either_way(
    const std::vector<std::string>& arguments, const std::vector<std::string>& parts) {
  for (auto limited : {true, false}) {
    SCOPED_TRACE(limited ? "under ulimit -v 1048576" : "without an address-space limit");
    expect_refused(run_limited(arguments, limited), parts);
  }
}

// A json scene: a camera, a grey material, and the given groups.
std::string make_json(const std::string& groups) {
  return R"({"cameras": [{"lookat": [0, 0, 4, 0, 0, 0, 0, 1, 0]}],
    "materials": [{"color": [0.5, 0.5, 0.5]}])" +
         (groups.empty() ? std::string{} : ", " + groups) + "}";
}

// A sky whose texture is the given file.
std::string make_sky_json(const std::string& texture) {
  return make_json(R"("textures": [{"uri": ")" + texture + R"("}],
    "environments": [{"emission": [1, 1, 1], "emission_tex": 0}])");
}

// A binary PLY of `count` vertices stored as bytes (12 bytes each once
// loaded) and one triangle.
std::string make_byte_ply(int count) {
  auto data = "ply\nformat binary_little_endian 1.0\nelement vertex " + std::to_string(count) +
              "\nproperty uchar x\nproperty uchar y\nproperty uchar z\n"
              "element face 1\nproperty list uchar int vertex_indices\nend_header\n";
  for (auto i = 0; i < count; i++) data += std::string{(char)(i % 3 == 1), (char)(i % 3 == 2), 0};
  data += '\3';
  for (int32_t index : {0, 1, 2}) data.append((const char*)&index, 4);
  return data;
}

}  // namespace

// -----------------------------------------------------------------------------
// TESTS
// -----------------------------------------------------------------------------

TEST(limits, a_tiny_scene_renders_under_the_limits) {
  auto dir = scratch_directory("limits-tiny");
  write_file(dir.file("quad.ply"), make_byte_ply(3));
  write_file(dir.file("scene.json"),
      make_json(R"("environments": [{"emission": [1, 1, 1]}],
        "shapes": [{"uri": "quad.ply"}], "instances": [{"shape": 0, "material": 0}])"));
  auto result = run_limited(
      {"render", dir.file("scene.json"), "-o", dir.file("out.png"), "-s", "2", "-r", "16", "-t", "1"});
  EXPECT_EQ(result.status, 0) << result.output;
  EXPECT_TRUE(fs::exists(dir.file("out.png")));
}

TEST(limits, image_headers_claiming_gigapixels_are_refused) {
  // A 19-byte PGM claiming 46000x46000 pixels as a sky; then a PNG (a
  // valid 2x2 one written by yscene, its header patched to 19000x19000).
  auto dir = scratch_directory("limits-images");
  write_file(dir.file("big.pgm"), "P5\n46000 46000\n255\n");
  write_file(dir.file("scene.json"), make_sky_json("big.pgm"));
  expect_refused_either_way({"render", dir.file("scene.json"), "-o", dir.file("out.png")},
      {"scene.json", "big.pgm", "46000x46000"});
  auto small = texture_data{2, 2, std::vector<vec3f>(4, vec3f{0.5f, 0.5f, 0.5f})};
  auto error = std::string{};
  ASSERT_TRUE(save_image(dir.file("small.png"), small, error)) << error;
  write_file(dir.file("big.png"), patch_png_size(read_file(dir.file("small.png")), 19000, 19000));
  write_file(dir.file("scene.json"), make_sky_json("big.png"));
  expect_refused_either_way({"render", dir.file("scene.json"), "-o", dir.file("out.png")},
      {"scene.json", "big.png", "19000x19000"});
  EXPECT_FALSE(fs::exists(dir.file("out.png")));
}

TEST(limits, one_ply_named_by_20000_shapes_loads_once) {
  // 30 KB of PLY is 120 KB of shape: loaded 20000 times it would need 2.4 GB.
  auto dir = scratch_directory("limits-same-ply");
  write_file(dir.file("mesh.ply"), make_byte_ply(10000));
  auto shapes = std::string{}, instances = std::string{};
  for (auto i = 0; i < 20000; i++) {
    shapes += std::string(i ? ", " : "") + R"({"uri": "mesh.ply"})";
    instances += std::string(i ? ", " : "") + R"({"shape": )" + std::to_string(i) +
                 R"(, "material": 0})";
  }
  write_file(dir.file("scene.json"),
      make_json(R"("shapes": [)" + shapes + R"(], "instances": [)" + instances + "]"));
  auto result = run_limited({"info", dir.file("scene.json")});
  EXPECT_EQ(result.status, 0) << result.output;
  EXPECT_NE(result.output.find("shapes:       1\n"), std::string::npos) << result.output;
  EXPECT_NE(result.output.find("instances:    20000\n"), std::string::npos) << result.output;
}

TEST(limits, render_buffers_are_checked_before_allocating) {
  // 65536 pixels wide is a 100 GB render, from the scene or the command line.
  auto dir = scratch_directory("limits-buffers");
  write_file(dir.file("scene.json"),
      R"({"settings": {"resolution": 65536},)" + make_json("").substr(1));
  expect_refused_either_way({"render", dir.file("scene.json"), "-o", dir.file("out.exr")},
      {"scene.json", "resolution 65536 (the scene's settings)", "65536x43691"});
  expect_refused_either_way({"render", dir.file("scene.json"), "-o", dir.file("out.exr"), "-r",
                     "40000", "--max-memory", "1G"},
      {"scene.json", "resolution 40000 (--resolution)", "over the memory limit of 1024 MiB"});
  EXPECT_FALSE(fs::exists(dir.file("out.exr")));
}

TEST(limits, hair_headers_and_devices_are_refused_at_once) {
  // A .hair header claiming four billion strands of no points; then a shape
  // and a texture naming /dev/zero, which would read forever.
  auto dir    = scratch_directory("limits-hair-devices");
  auto header = std::string("HAIR", 4);
  for (uint32_t value : {4000000000u, 0u, 2u, 0u}) header.append((const char*)&value, 4);
  header.resize(128, '\0');
  write_file(dir.file("bomb.hair"), header);
  expect_refused_either_way({"info", dir.file("bomb.hair")}, {"bomb.hair", "4000000000 strands"});
  write_file(dir.file("shape.json"),
      make_json(R"("shapes": [{"uri": "/dev/zero"}], "instances": [{"shape": 0, "material": 0}])"));
  expect_refused_either_way({"info", dir.file("shape.json")},
      {"shape.json", "/dev/zero", "not a regular file"});
  write_file(dir.file("sky.json"), make_sky_json("/dev/zero"));
  expect_refused_either_way({"convert", dir.file("sky.json"), dir.file("out.json")},
      {"sky.json", "/dev/zero", "not a regular file"});
  EXPECT_FALSE(fs::exists(dir.file("out.json")));
}

TEST(limits, max_memory_option_sets_the_limit_of_every_load) {
  auto dir = scratch_directory("limits-max-memory");
  write_file(dir.file("mesh.ply"), make_byte_ply(100000));
  write_file(dir.file("scene.json"), make_json(R"("shapes": [{"uri": "mesh.ply"}],
      "instances": [{"shape": 0, "material": 0}])"));
  expect_refused_either_way({"info", dir.file("scene.json"), "--max-memory", "1M"},
      {"scene.json", "over the memory limit of 1 MiB (--max-memory)"});
  auto result = run_limited({"info", dir.file("scene.json"), "--max-memory", "64M"});
  EXPECT_EQ(result.status, 0) << result.output;
  expect_refused_either_way({"info", dir.file("scene.json"), "--max-memory", "lots"},
      {"--max-memory lots"});
}

TEST(limits, a_pbrt_sphere_bomb_names_its_file) {
  // 100 Includes of a file of 200 spheres: 79M triangles, 2.3 GB of scene
  // from 8 KB of text. Under 1 GiB of address space the load ends with one
  // line naming the included file and its line (the budget's message, or an
  // allocation that failed before the budget was reached); without a limit,
  // --max-memory 256M refuses it the same way. (Under the sanitizers, where
  // no address-space limit applies, only the second: the whole load would
  // take a minute.)
  auto dir     = scratch_directory("limits-spheres");
  auto spheres = std::string{};
  for (auto i = 0; i < 200; i++) spheres += "Shape \"sphere\" \"float radius\" 1\n";
  write_file(dir.file("spheres.pbrt"), spheres);
  auto scene = std::string{"LookAt 0 0 5 0 0 0 0 1 0\nCamera \"perspective\"\nWorldBegin\n"};
  for (auto i = 0; i < 100; i++) scene += "Include \"spheres.pbrt\"\n";
  write_file(dir.file("scene.pbrt"), scene);
  for (auto command : {"info", "render"}) {
    auto arguments = std::vector<std::string>{command, dir.file("scene.pbrt")};
    if (std::string{command} == "render")
      arguments.insert(arguments.end(), {"-o", dir.file("out.exr"), "-r", "16"});
#ifndef YOCTO_SANITIZED
    expect_refused(run_limited(arguments), {"spheres.pbrt:", "Shape \"sphere\""});
#endif
    arguments.insert(arguments.end(), {"--max-memory", "256M"});
    expect_refused(run_limited(arguments, false),
        {"spheres.pbrt:", "Shape \"sphere\"", "memory limit of 256 MiB"});
  }
  EXPECT_FALSE(fs::exists(dir.file("out.exr")));
}
