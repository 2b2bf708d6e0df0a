// libFuzzer target: `octocd replay` (issue 22). The input is written as a trace file and
// replayed through replay_command (cli/replay.cpp): replay_input_from_trace reads /bodies,
// /states, /frames and the parameters, then at most 4 frames go through two broadphases
// on the CPU engine (octree and spatial-hash: the set comparison runs too), one timed
// pass. A file that is not a readable trace must end in InputError (exit 2) or
// RuntimeError (exit 1); anything else (a crash, a sanitizer report, a hang, another
// exception) is a finding.
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <string>

#include "../cli/tools.hpp"
#include "fuzz_common.hpp"
#include "octocd/error.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string path = octocd_fuzz::scratch_path("replay");
  octocd_fuzz::write_input(path, data, size);
  octocd::cli::ReplayOptions o;
  o.trace = path;
  o.broadphases = "octree,spatial-hash";
  o.repeat = 1;
  o.warm_replays = 0;
  o.max_frames = 4;
  try {
    const octocd_fuzz::QuietStdout quiet;
    (void)octocd::cli::replay_command(o);
  } catch (const octocd::InputError&) {
  } catch (const octocd::RuntimeError&) {
  }
  std::remove(path.c_str());
  return 0;
}
