// libFuzzer target: the external-trace reader of `octocd validate --trace-in` (issue 22).
// The input is written as a trace file; check_external_trace (what --check-only does)
// checks it, then validate_external_trace judges its first 3 frames with every validator
// (FCL and Bullet beside, as the CLI does). A file that is not a valid external trace must
// end in InputError (exit 2) or RuntimeError (exit 1); anything else (a crash, a sanitizer
// report, a hang, another exception) is a finding.
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <string>

#include "fuzz_common.hpp"
#include "octocd/error.hpp"
#include "octocd/external.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string path = octocd_fuzz::scratch_path("external");
  octocd_fuzz::write_input(path, data, size);
  try {
    (void)octocd::check_external_trace(path);
    (void)octocd::validate_external_trace(path, octocd::ExternalOptions{}, 1, 3);
  } catch (const octocd::InputError&) {
  } catch (const octocd::RuntimeError&) {
  }
  std::remove(path.c_str());
  return 0;
}
