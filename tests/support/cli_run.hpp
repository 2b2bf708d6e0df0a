#pragma once
/// \file cli_run.hpp
/// Running the `octocd` command from a test: the binary under test, the source tree, and
/// a shell command's exit code with its merged stdout and stderr. Shared by the
/// test_cli*.cpp files (tests/cli, tests/scene) (each needs OCTOCD_TEST_BIN defined by CMake).
#include <sys/wait.h>

#include <cstdio>
#include <cstdlib>
#include <string>

namespace octocd::test {

/// A finished command: its exit status (-1 when it did not exit normally or could not
/// start) and everything it wrote to stdout and stderr, interleaved.
struct Result {
  int code = -1;
  std::string output;
};

/// The octocd binary under test: $OCTOCD_BIN, else the build's (OCTOCD_TEST_BIN).
inline std::string bin() {
  const char* b = std::getenv("OCTOCD_BIN");
  return b ? b : OCTOCD_TEST_BIN;
}

/// The source tree (datasets/, tests/data/): $OCTOCD_SOURCE_DIR, else the current folder.
inline std::string source_dir() {
  const char* root = std::getenv("OCTOCD_SOURCE_DIR");
  return root ? root : ".";
}

/// Runs `command` with /bin/sh (stderr merged into stdout) and waits for it.
inline Result run(const std::string& command) {
  Result r;
  FILE* p = popen((command + " 2>&1").c_str(), "r");
  if (!p) return r;
  char buf[4096];
  while (std::fgets(buf, sizeof buf, p)) r.output += buf;
  const int status = pclose(p);
  r.code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return r;
}

/// Runs `octocd ARGS` (ARGS as a shell would split them).
inline Result run_octocd(const std::string& args) { return run(bin() + " " + args); }

}  // namespace octocd::test
