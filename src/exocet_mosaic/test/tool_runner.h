/**
 * @file tool_runner.h
 * @brief Tests of the command-line tools: running a built tool of this package as a process and reading its output.
 */
#pragma once

#include <sys/wait.h>

#include <cstdlib>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "exocet_common/testing/paths.h"
#include "exocet_common/testing/temp_dir.h"

namespace exocet_mosaic {
namespace testing {

/// A tool's exit code and what it printed.
struct RunResult {
  int exit_code = -1;
  std::string out, err;
};

/// The whole content of a text file ("" if it cannot be read).
inline std::string readText(const std::string& path) {
  std::ifstream in(path);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

/// Runs the built `tool` of this package with `args`, capturing its exit code, stdout and stderr in `scratch`.
inline RunResult runTool(const std::string& tool, const std::vector<std::string>& args,
                         const exocet_common::testing::TempDir& scratch) {
  std::string command = "'" + exocet_common::testing::executableDir() + "/" + tool + "'";
  for (const auto& a : args) command += " '" + a + "'";
  command += " >'" + scratch.file("stdout") + "' 2>'" + scratch.file("stderr") + "'";
  const int status = std::system(command.c_str());
  RunResult r;
  r.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  r.out = readText(scratch.file("stdout"));
  r.err = readText(scratch.file("stderr"));
  return r;
}

}  // namespace testing
}  // namespace exocet_mosaic
