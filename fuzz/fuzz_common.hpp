#pragma once
/// \file fuzz_common.hpp
/// What the trace-reading fuzz targets share: writing the input to a scratch file, and
/// silencing stdout while a command (compare, replay) prints its report.
#include <fcntl.h>
#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <fstream>
#include <string>

namespace octocd_fuzz {

/// A scratch file "octocd-fuzz-TAG-PID.h5" in /dev/shm (or /tmp), reused for every input
/// of this process.
inline std::string scratch_path(const char* tag) {
  const char* dir = access("/dev/shm", W_OK) == 0 ? "/dev/shm" : "/tmp";
  return std::string(dir) + "/octocd-fuzz-" + tag + "-" + std::to_string(getpid()) + ".h5";
}

/// Writes the `size` bytes at `data` to `path` (truncating it).
inline void write_input(const std::string& path, const std::uint8_t* data, std::size_t size) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(reinterpret_cast<const char*>(data), static_cast<std::streamsize>(size));
}

/// While alive, stdout (fd 1) goes to /dev/null; restored (flushed) on destruction. The
/// commands print a report per input, which would drown libFuzzer's own output.
class QuietStdout {
 public:
  QuietStdout() {
    std::fflush(stdout);
    saved_ = dup(1);
    const int null = open("/dev/null", O_WRONLY);
    if (null >= 0) {
      dup2(null, 1);
      close(null);
    }
  }
  ~QuietStdout() {
    std::fflush(stdout);
    if (saved_ >= 0) {
      dup2(saved_, 1);
      close(saved_);
    }
  }
  QuietStdout(const QuietStdout&) = delete;
  QuietStdout& operator=(const QuietStdout&) = delete;

 private:
  int saved_ = -1;
};

}  // namespace octocd_fuzz
