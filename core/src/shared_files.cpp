/// \file shared_files.cpp
/// shared_dir(): the shipped files of a source tree or of an installed prefix
/// (octocd/shared_files.hpp).

#include "octocd/shared_files.hpp"

#include <dlfcn.h>

#include <cstdlib>
#include <filesystem>
#include <vector>

#ifndef OCTOCD_SOURCE_DIR
#define OCTOCD_SOURCE_DIR "."
#endif

namespace octocd {

namespace fs = std::filesystem;

std::string shared_dir() {
  if (const char* env = std::getenv("OCTOCD_SOURCE_DIR"); env != nullptr && *env != '\0') return env;
  std::vector<fs::path> binaries;
  std::error_code ec;
  const fs::path exe = fs::read_symlink("/proc/self/exe", ec);
  if (!ec) binaries.push_back(exe);
  Dl_info info{};
  if (dladdr(reinterpret_cast<void*>(&shared_dir), &info) != 0 && info.dli_fname != nullptr &&
      fs::path(info.dli_fname).is_absolute())
    binaries.push_back(fs::weakly_canonical(info.dli_fname, ec));
  for (const fs::path& b : binaries) {
    const fs::path share = (b.parent_path() / ".." / "share" / "octocd").lexically_normal();
    if (fs::is_directory(share / "datasets" / "scenes", ec)) return share.string();
  }
  return OCTOCD_SOURCE_DIR;
}

}  // namespace octocd
