// libFuzzer target: the trace readers (issue 10). The input is written as a file and
// every reader below opens it; a file that is not a readable octocd trace must end in
// RuntimeError (exit 1); anything else is a finding. To fuzz a new reader (issue 9's
// replay / compare / report), add it to kReaders.
//
// Note: the HDF5 library itself is not instrumented (Debian's libhdf5), so the fuzzer sees
// coverage only in octocd's code; crashes inside libhdf5 on malformed files are upstream
// bugs, reported as such (reports/cpu/fuzz.md).
#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <fstream>
#include <functional>
#include <string>

#include "octocd/error.hpp"
#include "octocd/trace.hpp"

namespace {

struct Reader {
  const char* name;
  std::function<void(const std::string&)> read;
};

const Reader kReaders[] = {
    {"read_trace_summary", [](const std::string& p) { (void)octocd::read_trace_summary(p); }},
    {"write_xdmf_sidecar",
     [](const std::string& p) { std::remove(octocd::write_xdmf_sidecar(p).c_str()); }},
};

std::string scratch_path() {
  const char* dir = access("/dev/shm", W_OK) == 0 ? "/dev/shm" : "/tmp";
  return std::string(dir) + "/octocd-fuzz-trace-" + std::to_string(getpid()) + ".h5";
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string path = scratch_path();
  {
    std::ofstream out(path, std::ios::binary | std::ios::trunc);
    out.write(reinterpret_cast<const char*>(data), static_cast<std::streamsize>(size));
  }
  for (const Reader& r : kReaders) {
    try {
      r.read(path);
    } catch (const octocd::RuntimeError&) {
    }
  }
  std::remove(path.c_str());
  std::remove((path + ".xmf").c_str());
  return 0;
}
