//
// Runs the yscene command line from a test: exit status and everything it
// printed (stdout and stderr together). YSCENE_EXE comes from CMake.
//

#ifndef TESTS_RUN_YSCENE_H_
#define TESTS_RUN_YSCENE_H_

#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstdio>
#include <functional>
#include <sstream>
#include <string>
#include <vector>
#include <yocto/yocto_scene.h>

struct command_result {
  int         status = -1;  // exit status, -1 if ended by a signal
  std::string output = "";  // stdout and stderr together
  int         signal = 0;   // the signal that ended it, if any
};

inline command_result run_yscene(const std::string& arguments) {
  auto command = std::string(YSCENE_EXE) + " " + arguments + " 2>&1";
  auto pipe    = popen(command.c_str(), "r");
  auto result  = command_result{};
  if (!pipe) return result;
  char buffer[4096];
  while (auto read = fread(buffer, 1, sizeof(buffer), pipe)) result.output.append(buffer, read);
  auto status   = pclose(pipe);
  result.status = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return result;
}

// Runs yscene with the arguments (no shell) in a child process that first
// calls `setup`: resource limits and signal dispositions set there are kept
// across exec.
inline command_result run_yscene_in_child(
    const std::vector<std::string>& arguments, const std::function<void()>& setup) {
  auto result = command_result{};
  int  pipes[2];
  if (pipe(pipes) != 0) return result;
  auto child = fork();
  if (child == 0) {
    setup();
    dup2(pipes[1], 1);
    dup2(pipes[1], 2);
    close(pipes[0]);
    close(pipes[1]);
    auto argv = std::vector<char*>{(char*)YSCENE_EXE};
    for (auto& argument : arguments) argv.push_back((char*)argument.c_str());
    argv.push_back(nullptr);
    execv(YSCENE_EXE, argv.data());
    _exit(127);
  }
  close(pipes[1]);
  char buffer[4096];
  for (auto count = read(pipes[0], buffer, sizeof(buffer)); count > 0;
       count       = read(pipes[0], buffer, sizeof(buffer)))
    result.output.append(buffer, (size_t)count);
  close(pipes[0]);
  auto status = 0;
  waitpid(child, &status, 0);
  if (WIFEXITED(status)) result.status = WEXITSTATUS(status);
  if (WIFSIGNALED(status)) result.signal = WTERMSIG(status);
  return result;
}

// Exit status 1 and exactly one error line, which names `names`.
inline void expect_failure(const command_result& result, const std::string& names) {
  EXPECT_EQ(result.status, 1) << result.output;
  auto error_lines = 0;
  auto stream      = std::istringstream(result.output);
  for (auto line = std::string{}; std::getline(stream, line);) {
    if (line.find("error") != std::string::npos) {
      error_lines++;
      EXPECT_EQ(line.rfind("error: ", 0), 0u) << line;
      EXPECT_NE(line.find(names), std::string::npos) << line;
    }
  }
  EXPECT_EQ(error_lines, 1) << result.output;
}

// A tiny valid scene: `shapes` matte spheres (sphere0, sphere1, ...) under
// a constant sky, seen by one camera.
inline yocto::scene_data make_small_scene(int shapes = 1) {
  using namespace yocto;
  auto scene   = scene_data{};
  auto camera  = camera_data{};
  camera.frame = lookat_frame({0, 0, 4}, {0, 0, 0}, {0, 1, 0});
  scene.cameras.push_back(camera);
  scene.camera_names.push_back("camera");
  scene.environments.push_back({identity3x4f, {1, 1, 1}, -1});
  scene.environment_names.push_back("sky");
  auto material  = material_data{};
  material.type  = material_type::matte;
  material.color = {0.5f, 0.5f, 0.5f};
  scene.materials.push_back(material);
  scene.material_names.push_back("grey");
  for (auto i = 0; i < shapes; i++) {
    scene.shapes.push_back(make_sphere_shape(16 + 8 * i, 1));
    scene.shape_names.push_back("sphere" + std::to_string(i));
    scene.instances.push_back({identity3x4f, i, 0});
    scene.instance_names.push_back("sphere" + std::to_string(i));
  }
  return scene;
}

#endif
