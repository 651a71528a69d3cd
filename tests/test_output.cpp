//
// Outputs are complete or absent, whatever goes wrong while writing them:
// planted links, a full disk (a file-size limit stands in for one), a failed
// rename among many, signals, and outputs that cannot be written at all.
//

#include <gtest/gtest.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>
#include <yocto/yocto_sceneio.h>

#include <csignal>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "run_yscene.h"

using namespace yocto;
namespace fs = std::filesystem;

// A fresh temporary directory per test, removed at its end.
struct test_directory {
  fs::path path;
  explicit test_directory(const std::string& name) {
    path = fs::temp_directory_path() / ("yocto-output-" + name + "-" + std::to_string(getpid()));
    fs::remove_all(path);
    fs::create_directories(path);
  }
  ~test_directory() {
    auto ec = std::error_code{};
    fs::permissions(path, fs::perms::owner_all, fs::perm_options::add, ec);
    fs::remove_all(path, ec);
  }
  std::string file(const std::string& name) const { return (path / name).string(); }
};

static void write_file(const std::string& filename, const std::string& text) {
  auto stream = std::ofstream(filename, std::ios::binary);
  stream << text;
}

static std::string read_file(const std::string& filename) {
  auto stream = std::ifstream(filename, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(stream), {});
}

// Every path under a directory, relative and sorted.
static std::vector<std::string> list_files(const fs::path& directory) {
  auto files = std::vector<std::string>{};
  for (auto& entry : fs::recursive_directory_iterator(directory))
    files.push_back(fs::relative(entry.path(), directory).string());
  std::sort(files.begin(), files.end());
  return files;
}

static bool contains(const std::string& text, const std::string& part) {
  return text.find(part) != std::string::npos;
}

// Runs this test binary again as a child under a file-size limit (writes
// past it fail with EFBIG, as on a full disk; SIGXFSZ is ignored so that
// they fail rather than kill) to save `what` to `filename` (see
// save_in_child below). A fresh process, not a bare fork: no lock held by
// another thread of this one (OpenImageIO's pool) is inherited. Returns the
// exit status (0 saved, 1 failed) and sets `message` to what it printed.
static int run_save_in_child(
    size_t limit, const std::string& what, const std::string& filename, std::string& message) {
  int pipes[2];
  if (pipe(pipes) != 0) return -1;
  auto child = fork();
  if (child == 0) {
    dup2(pipes[1], 2);
    close(pipes[0]);
    setenv("YOCTO_SAVE_IN_CHILD", (what + ":" + std::to_string(limit) + ":" + filename).c_str(), 1);
    execl("/proc/self/exe", "test_output", (char*)nullptr);
    _exit(127);
  }
  close(pipes[1]);
  char buffer[4096];
  message.clear();
  for (auto count = read(pipes[0], buffer, sizeof(buffer)); count > 0;
       count       = read(pipes[0], buffer, sizeof(buffer)))
    message.append(buffer, (size_t)count);
  close(pipes[0]);
  auto status = 0;
  waitpid(child, &status, 0);
  return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
}

// The same for the command line (arguments split at spaces).
static command_result run_yscene_with_file_limit(size_t bytes, const std::string& arguments) {
  auto split  = std::vector<std::string>{};
  auto stream = std::istringstream(arguments);
  for (auto argument = std::string{}; stream >> argument;) split.push_back(argument);
  return run_yscene_in_child(split, [bytes]() {
    std::signal(SIGXFSZ, SIG_IGN);
    auto limit = rlimit{bytes, bytes};
    setrlimit(RLIMIT_FSIZE, &limit);
  });
}

// A noisy image (it does not compress) of the given size.
static texture_data make_noise_image(int width, int height) {
  auto image   = texture_data{};
  image.width  = width;
  image.height = height;
  auto state   = 1u;
  for (auto i = 0; i < width * height; i++) {
    auto next = [&]() { return (state = state * 1664525u + 1013904223u) / 4294967296.0f; };
    image.pixels.push_back({next(), next(), next()});
  }
  return image;
}

// The child side of run_save_in_child: before the tests start, a process
// started with YOCTO_SAVE_IN_CHILD=WHAT:LIMIT:FILENAME saves a noisy 96x96
// image (27 KB as 8-bit, 110 KB as float; WHAT is its extension), a PLY
// sphere, 100 KB of text or a scene of three spheres with a big last one,
// then exits 0 if the save worked, 1 with its message if not.
static bool save_in_child = []() {
  auto variable = getenv("YOCTO_SAVE_IN_CHILD");
  if (!variable) return false;
  auto task     = std::string(variable);
  auto first    = task.find(':'), second = task.find(':', first + 1);
  auto what     = task.substr(0, first);
  auto limit    = (rlim_t)std::stoull(task.substr(first + 1, second - first - 1));
  auto filename = task.substr(second + 1);
  std::signal(SIGXFSZ, SIG_IGN);
  auto bound = rlimit{limit, limit};
  setrlimit(RLIMIT_FSIZE, &bound);
  auto error = std::string{};
  auto ok    = false;
  if (what == ".ply") {
    ok = save_shape(filename, make_sphere_shape(64, 1), error);
  } else if (what == ".txt") {
    ok = save_text(filename, std::string(100000, 'x'), error);
  } else if (what == "scene") {
    auto scene = make_small_scene(3);
    for (auto& shape : scene.shapes) shape = make_sphere_shape(32, 2);
    scene.shapes[2] = make_sphere_shape(256, 2);
    ok = save_scene(filename, scene, error);
  } else {
    ok = save_image(filename, make_noise_image(96, 96), error);
  }
  std::fprintf(stderr, "%s\n", error.c_str());
  std::exit(ok ? 0 : 1);
}();

TEST(output, planted_links_are_never_followed) {
  auto dir    = test_directory("links");
  auto victim = dir.file("victim.txt");
  write_file(victim, "precious");
  // Links under the names a predictable scheme would pick next
  // (NAME.tmp-PID-N.EXT), and one at the output's own name.
  auto pid = std::to_string(getpid());
  for (auto n = 0; n < 64; n++) {
    fs::create_symlink(victim, dir.file("out.tmp-" + pid + "-" + std::to_string(n) + ".txt"));
    fs::create_symlink(victim, dir.file("img.tmp-" + pid + "-" + std::to_string(n) + ".png"));
  }
  fs::create_symlink(victim, dir.file("out.txt"));
  auto error = std::string{};
  ASSERT_TRUE(save_text(dir.file("out.txt"), "new", error)) << error;
  ASSERT_TRUE(save_image(dir.file("img.png"), make_noise_image(8, 8), error)) << error;
  EXPECT_EQ(read_file(victim), "precious");
  // The link at the output's name was replaced by the file, not written through.
  EXPECT_FALSE(fs::is_symlink(dir.file("out.txt")));
  EXPECT_EQ(read_file(dir.file("out.txt")), "new");
}

TEST(output, temporaries_are_exclusive_unpredictable_and_keep_the_extension) {
  auto dir   = test_directory("temporaries");
  auto error = std::string{};
  auto first = output_file{}, second = output_file{};
  ASSERT_TRUE(open_output_file(first, dir.file("out.png"), error)) << error;
  ASSERT_TRUE(open_output_file(second, dir.file("out.png"), error)) << error;
  EXPECT_NE(first.temporary, second.temporary);
  EXPECT_EQ(fs::path(first.temporary).extension(), ".png");
  // Not derived from the process id.
  auto name = fs::path(first.temporary).filename().string();
  EXPECT_FALSE(contains(name, std::to_string(getpid()))) << name;
  discard_output_file(first);
  discard_output_file(second);
  EXPECT_TRUE(list_files(dir.path).empty());
  // A folder that is not there: the message names the output.
  EXPECT_FALSE(open_output_file(first, dir.file("no/such/out.png"), error));
  EXPECT_TRUE(contains(error, dir.file("no/such/out.png"))) << error;
}

TEST(output, a_full_disk_fails_the_save_and_keeps_the_previous_file) {
  // Every format, the text writer and the PLY writer: each save of a file
  // larger than the limit fails with the file named, the previous file at
  // that name stays as it was, and no temporary is left.
  auto dir   = test_directory("full");
  for (auto name : {"a.png", "a.jpg", "a.exr", "a.hdr", "a.pfm", "a.ply", "a.txt"}) {
    auto filename = dir.file(name);
    write_file(filename, "previous");
    auto message = std::string{};
    EXPECT_EQ(run_save_in_child(4096, fs::path(name).extension().string(), filename, message), 1)
        << name << ": " << message;
    EXPECT_TRUE(contains(message, filename)) << message;
    EXPECT_EQ(read_file(filename), "previous") << name;
    EXPECT_EQ(list_files(dir.path).size(), 1u) << name;
    fs::remove(filename);
  }
}

TEST(output, a_failed_save_scene_leaves_an_existing_scene_untouched) {
  auto dir   = test_directory("reconvert");
  auto error = std::string{};
  auto scene = make_small_scene(3);
  ASSERT_TRUE(save_scene(dir.file("scene.json"), scene, error)) << error;
  auto before = list_files(dir.path);
  auto bytes  = std::vector<std::string>{};
  for (auto& file : before)
    if (fs::is_regular_file(dir.path / file)) bytes.push_back(read_file((dir.path / file).string()));
  // A re-save of different geometry that runs out of space part way (see
  // save_in_child): the first shapes would fit, the last does not.
  auto message = std::string{};
  EXPECT_EQ(run_save_in_child(64 * 1024, "scene", dir.file("scene.json"), message), 1) << message;
  EXPECT_TRUE(contains(message, "cannot write")) << message;
  EXPECT_EQ(list_files(dir.path), before);
  auto index = (size_t)0;
  for (auto& file : before)
    if (fs::is_regular_file(dir.path / file))
      EXPECT_EQ(read_file((dir.path / file).string()), bytes[index++]) << file;
}

TEST(output, a_failed_rename_among_many_restores_the_files_already_replaced) {
  auto dir = test_directory("rollback");
  write_file(dir.file("a.txt"), "old a");
  fs::create_directory(dir.file("b.txt"));  // the second rename fails
  auto error = std::string{};
  auto files = std::vector<output_file>(2);
  ASSERT_TRUE(open_output_file(files[0], dir.file("a.txt"), error)) << error;
  ASSERT_TRUE(open_output_file(files[1], dir.file("b.txt"), error)) << error;
  ASSERT_TRUE(write_output_file(files[0], "new a", 5, error)) << error;
  ASSERT_TRUE(write_output_file(files[1], "new b", 5, error)) << error;
  EXPECT_FALSE(commit_output_files(files, error));
  EXPECT_TRUE(contains(error, dir.file("b.txt"))) << error;
  EXPECT_EQ(read_file(dir.file("a.txt")), "old a");
  EXPECT_EQ(list_files(dir.path), (std::vector<std::string>{"a.txt", "b.txt"}));
  // Without replace, an existing file is an error, not overwritten.
  auto file = output_file{};
  ASSERT_TRUE(open_output_file(file, dir.file("a.txt"), error)) << error;
  EXPECT_FALSE(commit_output_file(file, error, false));
  EXPECT_EQ(read_file(dir.file("a.txt")), "old a");
  EXPECT_EQ(list_files(dir.path), (std::vector<std::string>{"a.txt", "b.txt"}));
}

TEST(output, a_signal_leaves_no_temporary_and_no_folder_made) {
  auto dir    = test_directory("signal");
  auto child  = fork();
  if (child == 0) {
    std::signal(SIGTERM, [](int) {
      remove_pending_outputs();
      _exit(3);
    });
    auto error = std::string{};
    auto file  = output_file{};
    if (!make_output_directories(dir.file("a/b"), error)) _exit(1);
    if (!open_output_file(file, dir.file("a/b/out.exr"), error)) _exit(1);
    if (!write_output_file(file, "partial", 7, error)) _exit(1);
    raise(SIGTERM);
    _exit(2);
  }
  auto status = 0;
  waitpid(child, &status, 0);
  ASSERT_TRUE(WIFEXITED(status));
  EXPECT_EQ(WEXITSTATUS(status), 3);
  EXPECT_TRUE(list_files(dir.path).empty());
}

TEST(cli, unwritable_outputs_fail_before_the_render) {
  auto dir   = test_directory("cli-unwritable");
  auto error = std::string{};
  ASSERT_TRUE(save_scene(dir.file("scene.json"), make_small_scene(), error)) << error;
  auto scene = dir.file("scene.json");
  // A folder named like the output.
  fs::create_directory(dir.file("out.png"));
  auto result = run_yscene("render " + scene + " -o " + dir.file("out.png") + " -s 1 -r 16 -q");
  EXPECT_EQ(result.status, 1) << result.output;
  EXPECT_TRUE(contains(result.output, "is a directory")) << result.output;
  EXPECT_FALSE(contains(result.output, "rendered")) << result.output;
  // A JPEG larger than the format allows is refused before the work.
  result = run_yscene("render " + scene + " -o " + dir.file("big.jpg") + " -s 1 -r 65536 --max-memory 1T -q");
  EXPECT_EQ(result.status, 1) << result.output;
  EXPECT_TRUE(contains(result.output, "65500")) << result.output;
  // A failure after the output's folders were made removes them.
  result = run_yscene("render " + scene + " -o " + dir.file("new/folder/out.png") +
                      " --camera nosuch -s 1 -r 16 -q");
  EXPECT_EQ(result.status, 1) << result.output;
  EXPECT_FALSE(fs::exists(dir.file("new"))) << result.output;
}

TEST(cli, a_failed_final_write_keeps_the_render) {
  auto dir   = test_directory("cli-rescue");
  auto error = std::string{};
  ASSERT_TRUE(save_scene(dir.file("scene.json"), make_small_scene(), error)) << error;
  write_file(dir.file("out.pfm"), "previous");
  // A 64x64 PFM is 49 KB; the rescue EXR of the same smooth image
  // compresses to a few KB, under the 24 KB limit.
  auto result = run_yscene_with_file_limit(24 * 1024,
      "render " + dir.file("scene.json") + " -o " + dir.file("out.pfm") + " -s 1 -r 64 -q");
  EXPECT_EQ(result.status, 1) << result.output;
  EXPECT_TRUE(contains(result.output, dir.file("out.pfm"))) << result.output;
  EXPECT_TRUE(contains(result.output, "saved to " + dir.file("out-rescued.exr")))
      << result.output;
  EXPECT_EQ(read_file(dir.file("out.pfm")), "previous");
  auto image = texture_data{};
  ASSERT_TRUE(load_image(dir.file("out-rescued.exr"), image, error)) << error;
  EXPECT_EQ(image.width, 64);
  // A second failure does not overwrite the first rescue.
  result = run_yscene_with_file_limit(24 * 1024,
      "render " + dir.file("scene.json") + " -o " + dir.file("out.pfm") + " -s 1 -r 64 -q");
  EXPECT_TRUE(contains(result.output, "saved to " + dir.file("out-rescued-1.exr")))
      << result.output;
  EXPECT_EQ(list_files(dir.path), (std::vector<std::string>{"out-rescued-1.exr",
                                      "out-rescued.exr", "out.pfm", "scene.json", "shapes",
                                      "shapes/sphere0.ply"}));
}

TEST(cli, convert_killed_at_any_moment_leaves_all_or_nothing) {
  // A 20k-strand scene (a second's work, most of it writing); SIGTERM at
  // delays across the run: each time the output folder holds either the
  // whole scene, as an uninterrupted convert writes it, or nothing.
  auto dir    = test_directory("cli-convert-kill");
  auto result = run_yscene("hair --style straight --strands 20000 -o " + dir.file("in/hair.json"));
  ASSERT_EQ(result.status, 0) << result.output;
  result = run_yscene("convert " + dir.file("in/hair.json") + " " + dir.file("whole/hair.json"));
  ASSERT_EQ(result.status, 0) << result.output;
  auto whole    = list_files(dir.path / "whole");
  auto complete = 0, empty = 0;
  for (auto delay_ms = 50; delay_ms <= 1250; delay_ms += 150) {
    auto output = dir.path / ("out" + std::to_string(delay_ms));
    auto child  = fork();
    if (child == 0) {
      auto devnull = fopen("/dev/null", "w");
      dup2(fileno(devnull), 1);
      execl(YSCENE_EXE, YSCENE_EXE, "convert", dir.file("in/hair.json").c_str(),
          (output / "hair.json").c_str(), (char*)nullptr);
      _exit(127);
    }
    usleep(delay_ms * 1000);
    kill(child, SIGTERM);
    auto status = 0;
    waitpid(child, &status, 0);
    if (!fs::exists(output)) {
      empty++;
    } else {
      EXPECT_EQ(list_files(output), whole) << delay_ms << " ms";
      complete++;
    }
  }
  std::printf("killed converts: %d left nothing, %d the whole scene\n", empty, complete);
  EXPECT_EQ(complete + empty, 9);
}
