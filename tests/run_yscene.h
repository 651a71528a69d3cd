//
// Runs the yscene command line from a test: exit status and everything it
// printed (stdout and stderr together). YSCENE_EXE comes from CMake.
//

#ifndef TESTS_RUN_YSCENE_H_
#define TESTS_RUN_YSCENE_H_

#include <sys/wait.h>

#include <cstdio>
#include <string>

struct command_result {
  int         status = -1;
  std::string output = "";  // stdout and stderr together
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

#endif
