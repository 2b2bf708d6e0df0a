/// \file atomic_file.cpp
/// write_file_atomically: a temporary file, fsync, rename (atomic_file.hpp).

#include "octocd/atomic_file.hpp"

#include <fcntl.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstring>

#include <fmt/format.h>

#include "octocd/error.hpp"
#include "octocd/stop.hpp"

namespace octocd {

void write_file_atomically(const std::string& path, const std::string& text, const std::string& label) {
  // POSIX calls, so a failure names errno (ENOSPC, EFBIG, ...) and the temporary file is
  // removed whatever fails (before: `bench -o` left o.json.tmp.PID on a full disk).
  const std::string tmp = path + ".tmp." + std::to_string(::getpid());
  const std::string who = label.empty() ? path : label + ": " + path;
  const auto reason = [](int e) {
    const char* name = ::strerrorname_np(e);
    return fmt::format("{} ({})", std::strerror(e), name ? name : ("errno " + std::to_string(e)).c_str());
  };
  set_stop_remove(tmp);  // a process ended at once by a signal removes it too
  struct Forget {
    ~Forget() { set_stop_remove(""); }
  } forget;
  const int fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd < 0)
    throw RuntimeError(fmt::format("{}: cannot create the temporary file {}: {}; {} is unchanged", who, tmp,
                                   reason(errno), path));
  int err = 0;
  for (std::size_t done = 0; done < text.size() && err == 0;) {
    const ssize_t n = ::write(fd, text.data() + done, text.size() - done);
    if (n < 0 && errno == EINTR) continue;
    if (n < 0) err = errno;
    else done += static_cast<std::size_t>(n);
  }
  if (err == 0 && ::fsync(fd) != 0 && errno != EINVAL) err = errno;
  if (::close(fd) != 0 && err == 0) err = errno;
  if (err == 0 && ::rename(tmp.c_str(), path.c_str()) != 0) err = errno;
  if (err != 0) {
    ::unlink(tmp.c_str());
    throw RuntimeError(fmt::format("{}: writing failed: {}; {} is unchanged (its last complete version, if any) and "
                                   "no temporary file is left",
                                   who, reason(err), path));
  }
}

}  // namespace octocd
