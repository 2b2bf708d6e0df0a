#pragma once
/// \file cli_run.hpp
/// Running the `octocd` command from a test: the binary under test, the source tree, and
/// a shell command's exit code with its merged stdout and stderr. Shared by the
/// test_cli*.cpp files (tests/cli, tests/scene) (each needs OCTOCD_TEST_BIN defined by CMake).
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string>

#include "support/wait_event.hpp"

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

/// A run killed mid-way: whether the kill ended it (false: it had ended before) and the
/// flushed frames its trace held when it was killed.
struct KilledRun {
  bool killed = false;
  std::int64_t frames = 0;
};

/// `octocd run SCENE --trace TRACE --quiet`, killed with SIGKILL (no warning) once TRACE
/// holds at least `frames` flushed frames, or after 60 s.
inline KilledRun run_killed_after(const std::string& scene, const std::string& trace, std::int64_t frames) {
  KilledRun k;
  const pid_t pid = ::fork();
  if (pid < 0) return k;
  if (pid == 0) {
    const std::string b = bin();
    ::execl(b.c_str(), b.c_str(), "run", scene.c_str(), "--trace", trace.c_str(), "--quiet",
            static_cast<char*>(nullptr));
    ::_exit(127);
  }
  k.frames = wait_for_trace_frames(trace, frames, std::chrono::seconds(60));
  ::kill(pid, SIGKILL);
  int status = 0;
  ::waitpid(pid, &status, 0);
  k.killed = WIFSIGNALED(status) && WTERMSIG(status) == SIGKILL;
  return k;
}

}  // namespace octocd::test
