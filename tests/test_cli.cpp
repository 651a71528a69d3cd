//
// End-to-end tests of the yscene command line: bad input gives a one-line
// error naming the file, exit status 1 and no output; renders are complete,
// deterministic across thread counts, and survive Ctrl-C; info, --quiet,
// the help and --clamp tell the user the whole truth.
//

#include <gtest/gtest.h>
#include <sys/wait.h>
#include <yocto/yocto_sceneio.h>
#include <yocto_hair/yocto_hair.h>

#include <nlohmann/json.hpp>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "run_yscene.h"

using namespace yocto;
namespace fs = std::filesystem;

// A fresh temporary directory per test.
static fs::path make_test_dir(const std::string& name) {
  auto dir = fs::temp_directory_path() / ("yscene-cli-" + name + "-" + std::to_string(getpid()));
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir;
}

static void write_file(const fs::path& path, const std::string& text) {
  auto stream = std::ofstream(path, std::ios::binary);
  stream << text;
}

// Files left in a directory (to catch temporaries left behind).
static std::vector<std::string> list_files(const fs::path& dir) {
  auto files = std::vector<std::string>{};
  for (auto& entry : fs::recursive_directory_iterator(dir))
    if (entry.is_regular_file()) files.push_back(entry.path().filename().string());
  std::sort(files.begin(), files.end());
  return files;
}

// A tiny valid scene (make_small_scene) saved as DIR/scene.json.
static void write_small_scene(const fs::path& dir) {
  auto error = std::string{};
  ASSERT_TRUE(save_scene((dir / "scene.json").string(), make_small_scene(), error)) << error;
}

TEST(cli, missing_scene_file) {
  auto dir    = make_test_dir("missing");
  auto result = run_yscene((dir / "nothere.json").string() + " --output x.png");  // no command
  EXPECT_EQ(result.status, 1);
  result = run_yscene("render " + (dir / "nothere.json").string() + " --output " +
               (dir / "out.png").string());
  expect_failure(result, "nothere.json");
  EXPECT_TRUE(list_files(dir).empty());
}

TEST(cli, malformed_json_names_file_and_line) {
  auto dir = make_test_dir("json");
  write_file(dir / "bad.json", "{\n  \"cameras\": [\n    {\"lens\": 0.05,}\n  ]\n}\n");
  auto result = run_yscene("render " + (dir / "bad.json").string() + " --output " +
                    (dir / "out.png").string());
  expect_failure(result, "bad.json");
  EXPECT_NE(result.output.find("line 3"), std::string::npos) << result.output;
  EXPECT_FALSE(fs::exists(dir / "out.png"));
}

TEST(cli, wrong_types_and_references_are_errors) {
  auto dir = make_test_dir("types");
  write_file(dir / "types.json", R"({"cameras": [{"lens": "long"}]})");
  expect_failure(run_yscene("render " + (dir / "types.json").string() + " -o " +
                     (dir / "out.png").string()), "lens");
  write_file(dir / "refs.json",
      R"({"materials": [{"type": "matte"}], "instances": [{"shape": 3, "material": 0}]})");
  expect_failure(run_yscene("render " + (dir / "refs.json").string() + " -o " +
                     (dir / "out.png").string()), "shape");
  EXPECT_FALSE(fs::exists(dir / "out.png"));
}

TEST(cli, missing_and_truncated_ply) {
  auto dir = make_test_dir("ply");
  write_small_scene(dir);
  // Truncate the sphere's PLY in the middle of its vertex data.
  auto ply  = dir / "shapes" / "sphere0.ply";
  auto size = fs::file_size(ply);
  fs::resize_file(ply, size / 2);
  expect_failure(run_yscene("render " + (dir / "scene.json").string() + " -o " +
                     (dir / "out.exr").string()), "sphere0.ply");
  fs::remove(ply);
  expect_failure(run_yscene("render " + (dir / "scene.json").string() + " -o " +
                     (dir / "out.exr").string()), "sphere0.ply");
  EXPECT_FALSE(fs::exists(dir / "out.exr"));
}

TEST(cli, unreadable_texture) {
  auto dir = make_test_dir("texture");
  write_file(dir / "sky.hdr", "this is not an image");
  write_file(dir / "scene.json", R"({"cameras": [{"lookat": [0, 0, 4, 0, 0, 0, 0, 1, 0]}],
    "textures": [{"name": "sky", "uri": "sky.hdr"}],
    "environments": [{"emission": [1, 1, 1], "emission_tex": 0}]})");
  expect_failure(run_yscene("render " + (dir / "scene.json").string() + " -o " +
                     (dir / "out.png").string()), "sky.hdr");
  EXPECT_FALSE(fs::exists(dir / "out.png"));
}

TEST(cli, singular_frames_are_errors_not_embree_asserts) {
  auto dir = make_test_dir("frames");
  write_small_scene(dir);  // for shapes/sphere0.ply
  auto zero    = std::string("[0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 4]");
  auto objects = std::string(R"("shapes": [{"name": "sphere0", "uri": "shapes/sphere0.ply"}],
    "materials": [{"name": "grey", "color": [0.5, 0.5, 0.5]}],)");
  write_file(dir / "camera.json", R"({"cameras": [{"name": "cam", "frame": )" + zero + "}]," +
                                      objects + R"("instances": [{"shape": 0, "material": 0}]})");
  write_file(dir / "instance.json",
      "{" + objects + R"("instances": [{"name": "hair", "shape": 0, "material": 0, "frame": )" +
          zero + "}]}");
  write_file(dir / "scale.pbrt", "LookAt 0 0 5 0 0 0 0 1 0\nCamera \"perspective\"\nWorldBegin\n"
                                 "AttributeBegin\nScale 0 0 0\nShape \"sphere\"\nAttributeEnd\n");
  auto out = (dir / "out.png").string();
  auto camera =
      run_yscene("render " + (dir / "camera.json").string() + " -o " + out + " -s 1 -r 8");
  expect_failure(camera, "camera.json");
  EXPECT_NE(camera.output.find("camera \"cam\": frame is singular"), std::string::npos)
      << camera.output;
  auto instance = run_yscene("info " + (dir / "instance.json").string());
  expect_failure(instance, "instance.json");
  EXPECT_NE(instance.output.find("instance \"hair\": frame is singular"), std::string::npos)
      << instance.output;
  for (auto command : {"render " + (dir / "scale.pbrt").string() + " -o " + out + " -s 1 -r 8",
           "convert " + (dir / "scale.pbrt").string() + " " + (dir / "out.json").string(),
           "info " + (dir / "scale.pbrt").string()}) {
    auto result = run_yscene(command);
    expect_failure(result, "scale.pbrt");
    EXPECT_NE(result.output.find("frame is singular"), std::string::npos) << result.output;
  }
  EXPECT_FALSE(fs::exists(out));
  EXPECT_FALSE(fs::exists(dir / "out.json"));
}

TEST(cli, extreme_cameras_are_errors_not_embree_asserts) {
  // Finite values whose rays Embree would abort on (SIGABRT in Debian's
  // build), from json and from pbrt, are refused at load naming file and
  // element (the other cases are unit tests of validate_scene).
  auto dir = make_test_dir("extreme");
  write_small_scene(dir);  // for shapes/sphere0.ply
  auto objects = std::string(R"("shapes": [{"name": "sphere0", "uri": "shapes/sphere0.ply"}],
    "materials": [{"name": "grey", "color": [0.5, 0.5, 0.5]}],
    "instances": [{"name": "ball", "shape": 0, "material": 0}])");
  auto out     = (dir / "out.png").string();
  write_file(dir / "far.json", R"({"cameras": [{"name": "cam", "frame": )"
                               R"([1, 0, 0, 0, 1, 0, 0, 0, 1, 1e19, 0, 4]}], )" + objects + "}");
  auto far = run_yscene("render " + (dir / "far.json").string() + " -o " + out + " -s 1 -r 8");
  expect_failure(far, "far.json");
  EXPECT_NE(far.output.find("camera \"cam\": position 1e+19 is outside the range"),
      std::string::npos) << far.output;
  write_file(dir / "lens.json", R"({"cameras": [{"name": "cam", "aperture": 3e38}], )" +
                                    objects + "}");
  auto lens = run_yscene("render " + (dir / "lens.json").string() + " -o " + out + " -s 1 -r 8");
  expect_failure(lens, "lens.json");
  EXPECT_NE(lens.output.find("aperture 3e+38 give rays the ray tracer cannot trace"),
      std::string::npos) << lens.output;
  write_file(dir / "far.pbrt", "LookAt 1e19 0 5 0 0 0 0 1 0\nCamera \"perspective\"\n"
                               "WorldBegin\nShape \"sphere\"\n");
  auto pbrt = run_yscene("render " + (dir / "far.pbrt").string() + " -o " + out + " -s 1 -r 8");
  expect_failure(pbrt, "far.pbrt");
  EXPECT_NE(pbrt.output.find("position 1e+19 is outside the range"), std::string::npos)
      << pbrt.output;
  EXPECT_FALSE(fs::exists(out));
}

TEST(cli, unknown_output_extension) {
  auto dir = make_test_dir("extension");
  write_small_scene(dir);
  expect_failure(run_yscene("render " + (dir / "scene.json").string() + " -o " +
                     (dir / "out.xyz").string()), "out.xyz");
  EXPECT_FALSE(fs::exists(dir / "out.xyz"));
}

TEST(cli, render_writes_a_complete_image_and_nothing_else) {
  auto dir = make_test_dir("render");
  write_small_scene(dir);
  auto before = list_files(dir);
  for (auto name : {"out.png", "out.exr", "out.hdr", "out.pfm", "out.jpg"}) {
    auto result = run_yscene("render " + (dir / "scene.json").string() + " -o " +
                      (dir / name).string() + " -s 2 -r 32");
    EXPECT_EQ(result.status, 0) << result.output;
    EXPECT_NE(result.output.find("rays/s"), std::string::npos) << result.output;
    auto image = texture_data{};
    auto error = std::string{};
    EXPECT_TRUE(load_image((dir / name).string(), image, error)) << error;
    EXPECT_EQ(image.width, 32);
  }
  auto after = list_files(dir);
  EXPECT_EQ(after.size(), before.size() + 5);  // no temporaries left
}

TEST(cli, outputs_go_into_new_directories_or_fail_before_the_work) {
  auto dir = make_test_dir("directories");
  write_small_scene(dir);
  auto scene = (dir / "scene.json").string();
  auto result = run_yscene("render " + scene + " -o " + (dir / "a/b/out.png").string() +
                    " -s 1 -r 16 --quiet");
  EXPECT_EQ(result.status, 0) << result.output;
  EXPECT_TRUE(fs::is_regular_file(dir / "a/b/out.png"));
  result = run_yscene("hair --style straight --strands 10 -o " + (dir / "c/d/hair.pbrt").string());
  EXPECT_EQ(result.status, 0) << result.output;
  result = run_yscene("convert " + (dir / "c/d/hair.pbrt").string() + " " +
               (dir / "e/f/hair.json").string());
  EXPECT_EQ(result.status, 0) << result.output;
  EXPECT_TRUE(fs::is_regular_file(dir / "e/f/hair.json"));
  // A directory that cannot be made (a file is in the way): the error comes
  // before rendering (no summary line) and names the output.
  write_file(dir / "file", "not a directory");
  auto blocked = (dir / "file/out.png").string();
  result = run_yscene("render " + scene + " -o " + blocked + " -s 1 -r 16 --quiet");
  expect_failure(result, blocked);
  EXPECT_EQ(result.output.find("rays/s"), std::string::npos) << result.output;
}

TEST(cli, hair_counts_beyond_int_indices_are_errors_before_allocating) {
  auto dir = make_test_dir("hair-count");
  // 50M strands of 1000 segments: 1.5e11 control points, which once threw
  // bad_alloc. (Counts just past 2^31 are not tried: should the check
  // regress, they would allocate tens of gigabytes.)
  auto output = (dir / "h.ply").string();
  auto result = run_yscene("hair --strands 50000000 --segments 1000 -o " + output);
  expect_failure(result, "h.ply");
  EXPECT_NE(result.output.find("150050000000 control points"), std::string::npos)
      << result.output;
  EXPECT_TRUE(list_files(dir).empty());
}

TEST(cli, hair_fur_style_writes_a_scene) {
  auto dir    = make_test_dir("fur");
  auto result = run_yscene("hair --style fur --strands 200 --output " + (dir / "fur.json").string());
  EXPECT_EQ(result.status, 0) << result.output;
  EXPECT_NE(result.output.find("600 Bezier segments"), std::string::npos) << result.output;
  EXPECT_TRUE(fs::is_regular_file(dir / "fur.json"));
  EXPECT_TRUE(fs::is_regular_file(dir / "shapes/hair.ply"));
  EXPECT_TRUE(fs::is_regular_file(dir / "shapes/ball.ply"));
  fs::remove_all(dir);
}

TEST(cli, threads_one_and_two_give_the_same_image) {
  auto dir = make_test_dir("threads");
  ASSERT_EQ(run_yscene("hair --style curly --strands 200 -o " + (dir / "hair.json").string()).status, 0);
  for (auto threads : {1, 2}) {
    auto result = run_yscene("render " + (dir / "hair.json").string() + " -o " +
                      (dir / ("t" + std::to_string(threads) + ".exr")).string() +
                      " -s 2 -r 40 --quiet --threads " + std::to_string(threads));
    ASSERT_EQ(result.status, 0) << result.output;
  }
  auto one = texture_data{}, two = texture_data{};
  auto error = std::string{};
  ASSERT_TRUE(load_image((dir / "t1.exr").string(), one, error)) << error;
  ASSERT_TRUE(load_image((dir / "t2.exr").string(), two, error)) << error;
  EXPECT_EQ(one.pixels, two.pixels);
}

TEST(cli, sigint_saves_the_samples_done) {
  auto dir = make_test_dir("sigint");
  ASSERT_EQ(run_yscene("hair --style straight --strands 500 -o " + (dir / "hair.json").string()).status, 0);
  // Far more samples than 2 seconds allow; SIGINT after 2 seconds.
  // -k: should the signal be lost, the render is killed (and the test fails)
  // instead of running for minutes. --foreground: one SIGINT, to yscene
  // alone; otherwise timeout also signals its process group, and a second
  // SIGINT that comes after the first was handled ends yscene at once, by
  // design (a second Ctrl-C), which made this test fail now and then.
  auto command = "timeout --foreground -k 20 --preserve-status -s INT 2 " +
                 std::string(YSCENE_EXE) + " render " +
                 (dir / "hair.json").string() + " -o " + (dir / "out.exr").string() +
                 " -s 100000 -r 32 2>&1";
  auto pipe   = popen(command.c_str(), "r");
  auto output = std::string{};
  char buffer[4096];
  while (auto read = fread(buffer, 1, sizeof(buffer), pipe)) output.append(buffer, read);
  auto status = pclose(pipe);
  ASSERT_TRUE(WIFEXITED(status));
  EXPECT_EQ(WEXITSTATUS(status), 0) << output;
  EXPECT_NE(output.find("interrupted"), std::string::npos) << output;
  auto image = texture_data{};
  auto error = std::string{};
  EXPECT_TRUE(load_image((dir / "out.exr").string(), image, error)) << error;
}

TEST(cli, info_prints_counts) {
  auto dir = make_test_dir("info");
  ASSERT_EQ(run_yscene("hair --style block --strands 100 --segments 2 -o " + (dir / "block.json").string()).status, 0);
  auto result = run_yscene("info " + (dir / "block.json").string());
  EXPECT_EQ(result.status, 0) << result.output;
  EXPECT_NE(result.output.find("fiber segments: 200"), std::string::npos) << result.output;
  EXPECT_NE(result.output.find("bounds:"), std::string::npos) << result.output;
}

TEST(cli, convert_bad_input_leaves_nothing) {
  auto dir = make_test_dir("convert");
  // A pbrt scene whose include is missing, one with an unterminated string,
  // and a truncated .hair file.
  write_file(dir / "missing.pbrt", "WorldBegin\nInclude \"models/nothere.pbrt\"\nWorldEnd\n");
  write_file(dir / "string.pbrt", "WorldBegin\nMaterial \"hair\n");
  write_file(dir / "short.hair", std::string("HAIR\x02\x00\x00\x00", 8));
  auto out = (dir / "out" / "scene.json").string();
  expect_failure(run_yscene("convert " + (dir / "missing.pbrt").string() + " " + out), "nothere.pbrt");
  expect_failure(run_yscene("convert " + (dir / "string.pbrt").string() + " " + out), "string.pbrt");
  expect_failure(run_yscene("convert " + (dir / "short.hair").string() + " " + out), "short.hair");
  EXPECT_FALSE(fs::exists(dir / "out"));
}

TEST(cli, convert_refuses_hostile_pbrt_and_writes_nothing) {
  auto dir = make_test_dir("hostile-pbrt");
  // A non-UTF-8 material name on a mesh (which once failed in the json
  // writer after the PLY was saved), an empty file, and an Include of a
  // device.
  write_file(dir / "latin1.pbrt",
      "WorldBegin\nMakeNamedMaterial \"caf\xe9\" \"string type\" \"diffuse\"\n"
      "NamedMaterial \"caf\xe9\"\n"
      "Shape \"trianglemesh\" \"point3 P\" [0 0 0 1 0 0 0 1 0] \"integer indices\" [0 1 2]\n");
  write_file(dir / "empty.pbrt", "");
  write_file(dir / "device.pbrt", "WorldBegin\nShape \"sphere\"\nInclude \"/dev/zero\"\n");
  auto out = (dir / "out" / "scene.json").string();
  expect_failure(run_yscene("convert " + (dir / "latin1.pbrt").string() + " " + out),
      "latin1.pbrt:2: string \"caf\\xE9\" is not valid UTF-8");
  expect_failure(run_yscene("convert " + (dir / "empty.pbrt").string() + " " + out),
      "empty.pbrt: nothing to render");
  expect_failure(run_yscene("convert " + (dir / "device.pbrt").string() + " " + out),
      "device.pbrt:3: Include: \"/dev/zero\" (/dev/zero) is not a regular file");
  EXPECT_FALSE(fs::exists(dir / "out"));
}

TEST(cli, convert_generated_hair_round_trips) {
  auto dir = make_test_dir("roundtrip");
  for (auto extension : {".pbrt", ".pbrt.gz", ".hair"}) {
    auto strands = (dir / (std::string("strands") + extension)).string();
    ASSERT_EQ(run_yscene("hair --style curly --strands 30 --segments 6 -o " + strands).status, 0);
    auto json   = (dir / (std::string("converted") + extension + ".json")).string();
    auto result = run_yscene("convert " + strands + " " + json);
    ASSERT_EQ(result.status, 0) << result.output;
    auto scene = scene_data{};
    auto error = std::string{};
    ASSERT_TRUE(load_scene(json, scene, error)) << error;
    auto curves = (size_t)0;
    for (auto& shape : scene.shapes) curves += shape.curves.size();
    // pbrt keeps the Bezier segments; .hair keeps the strand points (one
    // segment per generated segment after the Catmull-Rom fit).
    EXPECT_EQ(curves, (size_t)30 * 6) << extension;
  }
}

// A strand scene with three hair materials, one per source of sigma_a
// (melanin, colour, sigma_a given), under a sky, seen by a named camera.
static void write_hair_materials_scene(const fs::path& filename) {
  auto scene = make_small_scene();
  scene.camera_names[0] = "front";
  scene.cameras[0].lens = 0.035f;
  auto strands = shape_data{};
  append_catmull_rom_strand(strands, {{-1, -1, 0}, {0, 0, 0}, {1, 1, 0}}, {0.02f, 0.01f, 0.01f});
  scene.shapes.push_back(strands);
  scene.shape_names.push_back("strands");
  auto add_hair = [&](const std::string& name, const hair_material& hair) {
    auto material = material_data{};
    material.type = material_type::hair;
    material.hair = hair;
    scene.materials.push_back(material);
    scene.material_names.push_back(name);
    scene.instances.push_back({identity3x4f, 1, (int)scene.materials.size() - 1});
    scene.instance_names.push_back(name);
  };
  auto melanin = hair_material{};
  melanin.eumelanin = 0.3f;
  melanin.pheomelanin = 0;
  add_hair("blonde", melanin);
  auto color      = hair_material{};
  color.color     = {0.8f, 0.4f, 0.2f};
  color.has_color = true;
  color.beta_n    = 0.5f;
  add_hair("coloured", color);
  auto given        = hair_material{};
  given.sigma_a     = {0.1f, 0.2f, 0.3f};
  given.has_sigma_a = true;
  given.alpha       = 3;
  given.eta         = 1.6f;
  add_hair("given", given);
  auto error = std::string{};
  ASSERT_TRUE(save_scene(filename.string(), scene, error)) << error;
}

// info names every camera and material with the values a render uses: the
// sigma_a the hair model gets and where it came from; --json says the same.
TEST(cli, info_prints_cameras_materials_and_lights) {
  auto dir   = make_test_dir("info-materials");
  auto scene = dir / "scene.json";
  write_hair_materials_scene(scene);
  auto result = run_yscene("info " + scene.string());
  ASSERT_EQ(result.status, 0) << result.output;
  auto& text = result.output;
  EXPECT_NE(text.find("camera front: perspective at [0 0 4] looking [0 0 -1], lens 35 mm"),
      std::string::npos) << text;
  EXPECT_NE(text.find("720x480 pixels"), std::string::npos) << text;
  EXPECT_NE(text.find("material grey: matte, color [0.5 0.5 0.5]"), std::string::npos) << text;
  EXPECT_NE(text.find("material blonde: hair, sigma_a"), std::string::npos) << text;
  EXPECT_NE(text.find("from melanin (eumelanin 0.3, pheomelanin 0)"), std::string::npos) << text;
  EXPECT_NE(text.find("from color [0.8 0.4 0.2]"), std::string::npos) << text;
  EXPECT_NE(text.find("material given: hair, sigma_a [0.1 0.2 0.3] given, beta_m 0.3, "
                      "beta_n 0.3, alpha 3 deg, eta 1.6\n"),
      std::string::npos) << text;
  EXPECT_NE(text.find("environment sky: emission [1 1 1]"), std::string::npos) << text;

  result = run_yscene("info --json " + scene.string());
  ASSERT_EQ(result.status, 0) << result.output;
  auto json = nlohmann::json::parse(result.output, nullptr, false);
  ASSERT_FALSE(json.is_discarded()) << result.output;
  EXPECT_EQ(json["counts"]["materials"], 4);
  EXPECT_EQ(json["cameras"][0]["name"], "front");
  EXPECT_EQ(json["cameras"][0]["resolution"], nlohmann::json::array({720, 480}));
  EXPECT_NEAR(json["cameras"][0]["lens"].get<double>(), 0.035, 1e-7);
  auto& materials = json["materials"];
  ASSERT_EQ(materials.size(), 4u);
  EXPECT_EQ(materials[1]["sigma_a_from"], "melanin");
  EXPECT_EQ(materials[2]["sigma_a_from"], "color");
  EXPECT_EQ(materials[3]["sigma_a_from"], "sigma_a");
  // The absorption the model uses, from each source.
  auto melanin  = hair_sigma_a_from_melanin(0.3f, 0);
  auto coloured = hair_sigma_a_from_color({0.8f, 0.4f, 0.2f}, 0.5f);
  for (auto c = 0; c < 3; c++) {
    EXPECT_NEAR(materials[1]["sigma_a"][c].get<double>(), melanin[c], 1e-5);
    EXPECT_NEAR(materials[2]["sigma_a"][c].get<double>(), coloured[c], 1e-5);
  }
  EXPECT_NEAR(materials[3]["sigma_a"][2].get<double>(), 0.3, 1e-7);
  EXPECT_NEAR(materials[3]["eta"].get<double>(), 1.6, 1e-6);
  EXPECT_EQ(json["environments"][0]["emission"], nlohmann::json::array({1, 1, 1}));
  fs::remove_all(dir);
}

// The value info --json gives a parameter: a number, r g b, or null.
static nlohmann::json info_value(const hair_parameter& parameter, const hair_material& hair) {
  if (parameter.has && !(hair.*parameter.has)) return nullptr;
  auto value = get_hair_parameter(hair, parameter);
  if (parameter.kind == hair_parameter_kind::number) return value.x;
  return nlohmann::json::array({value.x, value.y, value.z});
}

// info prints the variation parameters a material sets (in the text, after
// the others; a material without variation prints as before) and --json
// prints every parameter of the table. The scenes come from yscene hair.
TEST(cli, info_prints_every_hair_parameter) {
  auto dir     = make_test_dir("info-hair-parameters");
  auto plain   = (dir / "plain" / "hair.json").string();
  auto varying = (dir / "varying" / "hair.json").string();
  ASSERT_EQ(run_yscene("hair -n 10 -o " + plain).status, 0);
  auto result = run_yscene(
      "hair -n 10 --eta 1.6 --random-melanin 0.3 --random-roughness 0.25 --tip-eumelanin 0.2 "
      "--tip-pheomelanin 1.5 --tip-color 0.9 0.8 0.7 --tip-sigma-a 0.05 0.1 0.2 --tip-start 0.4 "
      "--tint 1 0.6 0.5 -o " + varying);
  ASSERT_EQ(result.status, 0) << result.output;

  result = run_yscene("info " + plain);
  ASSERT_EQ(result.status, 0) << result.output;
  EXPECT_NE(result.output.find("material hair: hair, sigma_a [0.5447 0.9061 1.781] from "
                               "melanin (eumelanin 1.3, pheomelanin 0), beta_m 0.3, beta_n "
                               "0.3, alpha 2 deg, eta 1.55\n"),
      std::string::npos)
      << result.output;
  result = run_yscene("info " + varying);
  ASSERT_EQ(result.status, 0) << result.output;
  EXPECT_NE(result.output.find("beta_m 0.3, beta_n 0.3, alpha 2 deg, eta 1.6, random_melanin "
                               "0.3, random_roughness 0.25, tip_eumelanin 0.2, tip_pheomelanin "
                               "1.5, tip_color [0.9 0.8 0.7], tip_sigma_a [0.05 0.1 0.2], "
                               "tip_start 0.4, tint [1 0.6 0.5]\n"),
      std::string::npos)
      << result.output;

  for (auto& filename : {plain, varying}) {
    auto scene = scene_data{};
    auto error = std::string{};
    ASSERT_TRUE(load_scene(filename, scene, error)) << error;
    auto& hair = scene.materials[0].hair;
    result     = run_yscene("info --json " + filename);
    ASSERT_EQ(result.status, 0) << result.output;
    auto json = nlohmann::json::parse(result.output, nullptr, false);
    ASSERT_FALSE(json.is_discarded()) << result.output;
    auto& item = json["materials"][0];
    EXPECT_EQ(item["type"], "hair");
    for (auto& parameter : hair_parameters) {
      ASSERT_TRUE(item.contains(parameter.name)) << parameter.name;
      // sigma_a is the absorption the model uses (here from melanin).
      if (std::string(parameter.name) == "sigma_a") continue;
      auto  expected = info_value(parameter, hair);
      auto& value    = item[parameter.name];
      ASSERT_EQ(value.type(), expected.type()) << parameter.name << ": " << value;
      auto count = expected.is_array() ? 3 : expected.is_null() ? 0 : 1;
      for (auto c = 0; c < count; c++)
        EXPECT_EQ((count == 3 ? value[c] : value).get<float>(),
            (count == 3 ? expected[c] : expected).get<float>())
            << parameter.name;
    }
    EXPECT_EQ(item["sigma_a_from"], "melanin");
  }
  fs::remove_all(dir);
}

// yscene hair has an option for every parameter of the table, and the
// scene it writes carries the values given.
TEST(cli, hair_options_write_every_hair_parameter) {
  auto dir  = make_test_dir("hair-parameters");
  auto help = run_yscene("hair --help").output;
  for (auto& parameter : hair_parameters) {
    auto option = "--" + std::string(parameter.name);
    std::replace(option.begin(), option.end(), '_', '-');
    EXPECT_NE(help.find(option + " "), std::string::npos) << option << "\n" << help;
  }

  // The issue's example, then every option with a value other than its default.
  auto json   = (dir / "example" / "hair.json").string();
  auto result = run_yscene("hair --style straight -n 10 --random-melanin 0.3 "
                           "--tip-eumelanin 0.2 --tip-color 0.9 0.8 0.7 --tint 1 0.6 0.5 -o " +
                           json);
  ASSERT_EQ(result.status, 0) << result.output;
  auto scene = scene_data{};
  auto error = std::string{};
  ASSERT_TRUE(load_scene(json, scene, error)) << error;
  auto& example = scene.materials[0].hair;
  EXPECT_EQ(example.random_melanin, 0.3f);
  EXPECT_TRUE(example.has_tip_eumelanin);
  EXPECT_EQ(example.tip_eumelanin, 0.2f);
  EXPECT_TRUE(example.has_tip_color);
  EXPECT_EQ(example.tip_color, (vec3f{0.9f, 0.8f, 0.7f}));
  EXPECT_EQ(example.tint, (vec3f{1, 0.6f, 0.5f}));
  EXPECT_FALSE(example.has_tip_pheomelanin || example.has_tip_sigma_a);
  EXPECT_EQ(example.random_roughness, 0);
  auto text = nlohmann::json::parse(std::ifstream(json));
  for (auto key : {"random_melanin", "tip_eumelanin", "tip_color", "tint"})
    EXPECT_TRUE(text["materials"][0].contains(key)) << key;
  for (auto key : {"random_roughness", "tip_pheomelanin", "tip_sigma_a", "tip_start"})
    EXPECT_FALSE(text["materials"][0].contains(key)) << key;

  auto arguments = std::string{"hair --style straight -n 10"};
  auto expected  = hair_material{};
  for (auto& parameter : hair_parameters) {
    auto option = "--" + std::string(parameter.name);
    std::replace(option.begin(), option.end(), '_', '-');
    auto value = parameter.min + 0.25f;  // valid and not a default
    EXPECT_NE(vec3f{value}, parameter.default_value) << parameter.name;
    auto number = std::to_string(value);
    arguments += " " + option + " " + number;
    if (parameter.kind == hair_parameter_kind::rgb) arguments += " " + number + " " + number;
    set_hair_parameter(expected, parameter, vec3f{value});
  }
  json   = (dir / "every" / "hair.json").string();
  result = run_yscene(arguments + " -o " + json);
  ASSERT_EQ(result.status, 0) << arguments << "\n" << result.output;
  ASSERT_TRUE(load_scene(json, scene, error)) << error;
  for (auto& parameter : hair_parameters) {
    EXPECT_EQ(get_hair_parameter(scene.materials[0].hair, parameter),
        get_hair_parameter(expected, parameter))
        << parameter.name;
    if (parameter.has) EXPECT_TRUE(scene.materials[0].hair.*parameter.has) << parameter.name;
  }

  // Without variation options, the material has no variation key.
  json   = (dir / "plain" / "hair.json").string();
  result = run_yscene("hair --style straight -n 10 --eumelanin 2 -o " + json);
  ASSERT_EQ(result.status, 0) << result.output;
  text = nlohmann::json::parse(std::ifstream(json));
  for (auto& parameter : hair_parameters)
    if (parameter.group == hair_parameter_group::variation)
      EXPECT_FALSE(text["materials"][0].contains(parameter.name)) << parameter.name;
  fs::remove_all(dir);
}

// Each option holds its value to the table's range (either end) and rgb
// options take three numbers; an error names the option and the range.
TEST(cli, hair_options_check_the_table_ranges) {
  auto dir    = make_test_dir("hair-ranges");
  auto output = dir / "hair.json";
  auto expect_refused = [&](const std::string& arguments, const std::string& part) {
    auto result = run_yscene("hair -n 10 " + arguments + " -o " + output.string());
    EXPECT_EQ(result.status, 1) << arguments << "\n" << result.output;
    EXPECT_EQ(result.output.rfind(arguments.substr(0, arguments.find(' ')) + ": ", 0), 0u)
        << arguments << "\n" << result.output;
    EXPECT_NE(result.output.find(part), std::string::npos) << arguments << "\n" << result.output;
    EXPECT_FALSE(fs::exists(output)) << arguments;
  };
  for (auto& parameter : hair_parameters) {
    auto option = "--" + std::string(parameter.name);
    std::replace(option.begin(), option.end(), '_', '-');
    auto rgb  = parameter.kind == hair_parameter_kind::rgb;
    auto bads = std::vector<float>{parameter.min_open ? parameter.min : parameter.min - 1};
    if (parameter.max != flt_max)
      bads.push_back(parameter.max_open ? parameter.max : parameter.max + 1);
    for (auto bad : bads) {
      auto text = std::to_string(bad), min = std::to_string(parameter.min);
      expect_refused(option + " " + (rgb ? min + " " + text + " " + min : text),
          format_hair_parameter_range(parameter));
    }
    if (rgb) expect_refused(option + " 0.5 0.5", "3 required");
  }
  expect_refused("--eta dark", "expected a number");
  fs::remove_all(dir);
}

// --quiet: nothing at all on success, for every command; errors still come.
TEST(cli, quiet_prints_nothing_on_success) {
  auto dir   = make_test_dir("quiet");
  auto scene = (dir / "hair" / "scene.json").string();
  auto runs  = std::vector<std::string>{
      "hair --style curly -n 20 -q -o " + scene,
      "render " + scene + " -o " + (dir / "image.png").string() + " -s 2 -r 16 -q",
      "render " + scene + " -o " + (dir / "part.exr").string() +
          " -s 2 -r 16 -q --sample-range 0:2",
      "merge " + (dir / "part.exr").string() + " -o " + (dir / "merged.png").string() + " -q",
      "convert " + scene + " " + (dir / "copy" / "scene.json").string() + " -q",
  };
  for (auto& arguments : runs) {
    auto result = run_yscene(arguments);
    EXPECT_EQ(result.status, 0) << arguments << "\n" << result.output;
    EXPECT_EQ(result.output, "") << arguments;
  }
  EXPECT_TRUE(fs::exists(dir / "copy" / "scene.json"));
  expect_failure(run_yscene("render " + (dir / "none.json").string() + " -o " +
                            (dir / "x.png").string() + " -q"),
      "none.json");
  fs::remove_all(dir);
}

// The help of each command names every format it takes and writes.
TEST(cli, help_lists_every_format) {
  auto expect_all = [](const std::string& command, const std::vector<std::string>& words) {
    auto result = run_yscene(command + " --help");
    EXPECT_EQ(result.status, 0) << result.output;
    for (auto& word : words)
      EXPECT_NE(result.output.find(word), std::string::npos) << command << ": " << word;
  };
  expect_all("render", {"json", "pbrt", "pbrt.gz", "hair", "exr", "hdr", "pfm", "png", "jpg",
                           "--sample-range", "--clamp"});
  expect_all("convert", {"pbrt", "pbrt.gz", "hair", "json", "ply"});
  expect_all("info", {"json", "pbrt", "pbrt.gz", "hair", "--json"});
  expect_all("merge", {"exr", "hdr", "pfm", "png", "jpg", "--part"});
  expect_all("hair", {"json", ".pbrt", ".pbrt.gz", ".hair", ".ply"});
  expect_all("", {"render", "merge", "info", "convert", "hair"});
}

// --clamp is off by default; when on, the summary says how many samples it
// clamped and what share of their energy it removed. A small light of
// radiance 200 beside a grey sphere, found by BSDF sampling alone, makes
// fireflies.
TEST(cli, clamp_is_off_by_default_and_reports_what_it_removes) {
  auto dir   = make_test_dir("clamp");
  auto scene = make_small_scene();
  scene.environments[0].emission = {0.1f, 0.1f, 0.1f};
  auto light     = material_data{};
  light.emission = {200, 200, 200};
  scene.materials.push_back(light);
  scene.material_names.push_back("light");
  scene.shapes.push_back(make_sphere_shape(8, 0.3f));
  scene.shape_names.push_back("bulb");
  scene.instances.push_back({translation_frame({1.5f, 1.5f, 1.5f}), 1, 1});
  scene.instance_names.push_back("bulb");
  auto error = std::string{};
  ASSERT_TRUE(save_scene((dir / "scene.json").string(), scene, error)) << error;
  auto render = [&](const std::string& name, const std::string& flags) {
    auto result = run_yscene("render " + (dir / "scene.json").string() + " -o " +
                             (dir / name).string() + " -s 8 -r 32 --sampler naive" + flags);
    EXPECT_EQ(result.status, 0) << result.output;
    auto image = texture_data{};
    auto error = std::string{};
    EXPECT_TRUE(load_image((dir / name).string(), image, error)) << error;
    auto sum = 0.0;
    for (auto& pixel : image.pixels) sum += pixel.x + pixel.y + pixel.z;
    return std::pair{result.output, sum};
  };
  auto [plain, plain_sum]     = render("plain.exr", "");
  auto [clamped, clamped_sum] = render("clamped.exr", " --clamp 10");
  EXPECT_EQ(plain.find("samples clamped"), std::string::npos) << plain;
  auto line = clamped.substr(clamped.find("clamp 10: "));
  EXPECT_EQ(line.rfind("clamp 10: ", 0), 0u) << clamped;
  auto count = std::stoll(line.substr(10));
  EXPECT_GT(count, 0) << line;
  auto removed = std::stod(line.substr(line.find("removing ") + 9));
  EXPECT_GT(removed, 0) << line;
  EXPECT_LT(removed, 100) << line;
  EXPECT_LT(clamped_sum, plain_sum);
  fs::remove_all(dir);
}

TEST(cli, max_memory_bounds_the_bvh_too) {
  // A curly groom of 2,000 strands: its BVH with 4 curve pieces takes about
  // three times the bytes of 1. With --max-memory at the scene, the image and
  // 0.6 of the 4-piece BVH, the render plans fewer pieces (the most bent
  // segments) up front and succeeds, and its part records the split it used;
  // with the scene and image alone it fails with one line naming the budget,
  // exit 1, and writes nothing (never an abort).
  auto dir = make_test_dir("bvh-budget");
  auto scene = (dir / "curly.json").string();
  ASSERT_EQ(run_yscene("hair --style curly --strands 2000 --quiet --output " + scene).status, 0);
  auto info = run_yscene("info --json " + scene);
  ASSERT_EQ(info.status, 0) << info.output;
  auto scene_bytes = nlohmann::json::parse(info.output)["memory"].get<double>();
  auto stat = [](const std::string& output, const std::string& key) {
    auto at = output.find(" " + key + "=");
    return at == std::string::npos ? -1.0 : std::stod(output.substr(at + key.size() + 2));
  };
  auto render_stats = [&](const std::string& args) {
    auto result = run_yscene("render " + scene + " --resolution 32 --quiet --stats " + args +
                             " --output " + (dir / "free.exr").string());
    EXPECT_EQ(result.status, 0) << result.output;
    return result.output;
  };
  auto whole  = render_stats("--samples 1 --curve-pieces 1");
  auto pieced = render_stats("--samples 1 --curve-pieces 4");
  auto bvh_bytes = stat(pieced, "bvh_bytes"), segments = stat(pieced, "segments");
  ASSERT_GT(bvh_bytes, 2 * stat(whole, "bvh_bytes")) << pieced << whole;
  ASSERT_GT(stat(pieced, "curve_pieces"), 1.5 * segments) << pieced;
  // Without --curve-pieces the plan splits only when the render's rays
  // repay the build: not 1 spp at 32x32 for 48,000 segments, yes at 256 spp.
  EXPECT_EQ(stat(render_stats("--samples 1"), "curve_pieces"), segments);
  EXPECT_GT(stat(render_stats("--samples 256 --time-budget 0"), "curve_pieces"), 1.5 * segments);
  auto image_bytes = 32.0 * 32 * (72 + 12 + 3);  // trace_image_bytes of a 32x32 exr
  auto budget = [&](double bvh) {
    return std::to_string((long long)(scene_bytes + image_bytes + bvh));
  };
  auto part  = (dir / "part.exr").string();
  auto fewer = run_yscene("render " + scene + " --samples 2 --sample-range 0:1 --resolution 32 "
                          "--curve-pieces 4 --quiet --stats --max-memory " +
                          budget(0.6 * bvh_bytes) + " --output " + part);
  ASSERT_EQ(fewer.status, 0) << fewer.output;
  EXPECT_EQ(fewer.output.find("building it again"), std::string::npos) << fewer.output;
  EXPECT_LT(stat(fewer.output, "bvh_bytes"), 0.6 * bvh_bytes) << fewer.output;
  EXPECT_GT(stat(fewer.output, "curve_pieces"), segments) << fewer.output;
  EXPECT_LT(stat(fewer.output, "curve_pieces"), stat(pieced, "curve_pieces")) << fewer.output;
  auto loaded = render_part{};
  auto error  = std::string{};
  ASSERT_TRUE(load_render_part(part, loaded, error)) << error;
  EXPECT_NE(loaded.settings.find("pieces 4 over "), std::string::npos) << loaded.settings;
  auto output = dir / "none.exr";
  auto none   = run_yscene("render " + scene + " --samples 1 --resolution 32 --quiet "
                           "--max-memory " + budget(4096) + " --output " + output.string());
  EXPECT_EQ(none.status, 1) << none.output;
  EXPECT_NE(none.output.find("error: "), std::string::npos) << none.output;
  EXPECT_NE(none.output.find("memory"), std::string::npos) << none.output;
  EXPECT_FALSE(fs::exists(output));
  fs::remove_all(dir);
}
