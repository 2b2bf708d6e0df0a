#pragma once
/// \file atomic_file.hpp
/// Writing a result file so that no reader, killed process or full disk ever leaves half
/// of it (docs/robustness.md, "Full disk"): `bench -o`, `replay --json`, `compare --json`,
/// `run --summary-json`, `validate --junit`.

#include <string>

namespace octocd {

/// Writes `text` to `path` atomically: a temporary file `path.tmp.PID` in the same folder
/// (POSIX write, fsync), then rename over `path`. On any failure (ENOSPC, EFBIG under a
/// file size limit with SIGXFSZ ignored, EACCES, ...) the temporary file is removed, `path`
/// is left as it was (its last complete version, or absent), and RuntimeError says so:
/// "<label>: <path>: writing failed: <strerror> (<ERRNAME>); ..." (`label` and its ": "
/// left out when empty, e.g. "--junit").
void write_file_atomically(const std::string& path, const std::string& text, const std::string& label = "");

}  // namespace octocd
