// libFuzzer target: `octocd compare` (issue 22). The input is written as a trace file and
// compared with itself through compare_command (cli/compare.cpp) on every quantity
// (positions, velocities, orientations, angular velocities, contacts, pairs, energy; with an
// external or version 2 input, contacts by pair), so every dataset compare reads is read
// (twice) and every record it walks is walked. A file that is not a readable trace must end
// in InputError (exit 2) or RuntimeError (exit 1); anything else (a crash, a sanitizer
// report, a hang, another exception) is a finding.
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <string>

#include "../cli/tools.hpp"
#include "fuzz_common.hpp"
#include "octocd/error.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string path = octocd_fuzz::scratch_path("compare");
  octocd_fuzz::write_input(path, data, size);
  octocd::cli::CompareOptions o;
  o.a = o.b = path;
  o.quantities = "positions,velocities,orientations,angular_velocities,contacts,pairs,energy";
  try {
    const octocd_fuzz::QuietStdout quiet;
    (void)octocd::cli::compare_command(o);
  } catch (const octocd::InputError&) {
  } catch (const octocd::RuntimeError&) {
  }
  std::remove(path.c_str());
  return 0;
}
