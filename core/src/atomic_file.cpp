/// \file atomic_file.cpp
/// Output files made beside their target under an unpredictable name and renamed over it;
/// input files checked to be regular files before they are opened (atomic_file.hpp).

#include "octocd/atomic_file.hpp"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>

#include <fmt/format.h>

#include "octocd/error.hpp"
#include "octocd/stop.hpp"

namespace octocd {

namespace {

std::string reason(int e) {
  const char* name = ::strerrorname_np(e);
  return fmt::format("{} ({})", std::strerror(e), name ? name : ("errno " + std::to_string(e)).c_str());
}

std::string who(const std::string& label, const std::string& path) {
  return label.empty() ? path : label + ": " + path;
}

/// The process's umask, read without changing it (/proc/self/status "Umask:"; 022 when
/// that cannot be read): umask(2) would set it, racing with other threads' creates.
mode_t current_umask() {
  std::ifstream in("/proc/self/status");
  std::string line;
  while (std::getline(in, line))
    if (line.rfind("Umask:", 0) == 0) return static_cast<mode_t>(std::strtoul(line.c_str() + 6, nullptr, 8) & 0777);
  return 022;
}

}  // namespace

const char* file_type_word(unsigned mode) {
  return S_ISDIR(mode)                     ? "a folder"
         : S_ISFIFO(mode)                  ? "a FIFO"
         : S_ISCHR(mode) || S_ISBLK(mode)  ? "a device"
         : S_ISSOCK(mode)                  ? "a socket"
         : S_ISLNK(mode)                   ? "a symbolic link"
                                           : "not a plain file";
}

std::string output_path_kind(const std::string& path) {
  struct stat st {};
  if (::lstat(path.c_str(), &st) != 0 || S_ISREG(st.st_mode)) return "";
  if (S_ISLNK(st.st_mode)) {
    std::error_code ec;
    const std::filesystem::path to = std::filesystem::read_symlink(path, ec);
    return fmt::format("a symbolic link (to {})", ec ? std::string("?") : to.string());
  }
  return file_type_word(st.st_mode);
}

void check_output_file(const std::string& path, const std::string& label, bool folder_made_later) {
  constexpr const char* kAllowed = "a new file or a regular file (replaced by rename), in an existing folder";
  if (path.empty()) throw InputError(fmt::format("{}: an empty path; allowed: {}", label.empty() ? "output" : label, kAllowed));
  const std::string kind = output_path_kind(path);
  if (!kind.empty())
    throw InputError(fmt::format("{}: {}, not a regular file; allowed: {}", who(label, path), kind, kAllowed));
  struct stat st {};
  if (::lstat(path.c_str(), &st) == 0 || folder_made_later) return;  // a regular file, or a folder made later
  const std::filesystem::path parent = std::filesystem::path(path).parent_path();
  struct stat pst {};
  if (::stat(parent.empty() ? "." : parent.c_str(), &pst) != 0 || !S_ISDIR(pst.st_mode))
    throw InputError(fmt::format("{}: its folder {} does not exist; allowed: {}", who(label, path),
                                 parent.empty() ? "." : parent.string(), kAllowed));
}

TemporaryFile create_temporary_beside(const std::string& path, const std::string& label) {
  check_output_file(path, label);
  TemporaryFile t;
  t.path = path + ".tmp.XXXXXX";
  t.fd = ::mkostemp(t.path.data(), O_CLOEXEC);
  if (t.fd < 0)
    throw RuntimeError(fmt::format("{}: cannot create a temporary file in its folder: {}; {} is unchanged",
                                   who(label, path), reason(errno), path));
  ::fchmod(t.fd, 0666 & ~current_umask());  // mkstemp makes 0600; a plain create would not
  return t;
}

void rename_over(const std::string& temporary, const std::string& path, const std::string& label) {
  // Checked again: the target may have become a FIFO, a folder or a link since the start.
  const std::string kind = output_path_kind(path);
  if (!kind.empty()) {
    ::unlink(temporary.c_str());
    throw InputError(fmt::format("{}: {}, not a regular file; allowed: a new file or a regular file (replaced by "
                                 "rename), in an existing folder",
                                 who(label, path), kind));
  }
  if (::rename(temporary.c_str(), path.c_str()) != 0) {
    const int e = errno;
    ::unlink(temporary.c_str());
    throw RuntimeError(fmt::format("{}: renaming {} onto it failed: {}; {} is unchanged and no temporary file is left",
                                   who(label, path), temporary, reason(e), path));
  }
}

void write_file_atomically(const std::string& path, const std::string& text, const std::string& label) {
  // POSIX calls, so a failure names errno (ENOSPC, EFBIG, ...) and the temporary file is
  // removed whatever fails.
  const TemporaryFile tmp = create_temporary_beside(path, label);
  const TrackedTemporary tracked(tmp.path);  // until it is renamed, a stop removes it too
  int err = 0;
  for (std::size_t done = 0; done < text.size() && err == 0;) {
    const ssize_t n = ::write(tmp.fd, text.data() + done, text.size() - done);
    if (n < 0 && errno == EINTR) continue;
    if (n < 0) err = errno;
    else done += static_cast<std::size_t>(n);
  }
  if (err == 0 && ::fsync(tmp.fd) != 0 && errno != EINVAL) err = errno;
  if (::close(tmp.fd) != 0 && err == 0) err = errno;
  if (err != 0) {
    ::unlink(tmp.path.c_str());
    throw RuntimeError(fmt::format("{}: writing failed: {}; {} is unchanged (its last complete version, if any) and "
                                   "no temporary file is left",
                                   who(label, path), reason(err), path));
  }
  rename_over(tmp.path, path, label);
}

void check_input_file(const std::string& path, const std::string& label, const std::string& allowed) {
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0) {
    const int e = errno;
    throw InputError(fmt::format("{}: {}; allowed: {}", who(label, path),
                                 e == ENOENT ? std::string("no such file")
                                             : fmt::format("cannot be examined ({})", reason(e)),
                                 allowed));
  }
  if (!S_ISREG(st.st_mode))
    throw InputError(fmt::format("{}: not a regular file ({}); allowed: {}", who(label, path), file_type_word(st.st_mode),
                                 allowed));
}

std::string read_input_file(const std::string& path, const std::string& label, const std::string& allowed,
                            std::uint64_t max_bytes) {
  const int fd = ::open(path.c_str(), O_RDONLY | O_NONBLOCK | O_CLOEXEC | O_NOCTTY);
  if (fd < 0) {
    const int e = errno;
    throw InputError(fmt::format("{}: {}; allowed: {}", who(label, path),
                                 e == ENOENT ? std::string("no such file") : fmt::format("cannot be opened ({})", reason(e)),
                                 allowed));
  }
  struct Close {
    int fd;
    ~Close() { ::close(fd); }
  } close_it{fd};
  struct stat st {};
  if (::fstat(fd, &st) != 0)
    throw InputError(fmt::format("{}: cannot be examined ({}); allowed: {}", who(label, path), reason(errno), allowed));
  if (!S_ISREG(st.st_mode))
    throw InputError(fmt::format("{}: not a regular file ({}); allowed: {}", who(label, path), file_type_word(st.st_mode),
                                 allowed));
  if (static_cast<std::uint64_t>(st.st_size) > max_bytes)
    throw InputError(fmt::format("{}: {} bytes; allowed: {} of at most {} bytes", who(label, path), st.st_size,
                                 allowed, max_bytes));
  std::string text;
  text.reserve(static_cast<std::size_t>(st.st_size));
  char buf[1 << 16];
  for (;;) {
    const ssize_t n = ::read(fd, buf, sizeof buf);
    if (n < 0 && errno == EINTR) continue;
    if (n < 0)
      throw InputError(fmt::format("{}: cannot be read ({}); allowed: {}", who(label, path), reason(errno), allowed));
    if (n == 0) break;
    if (text.size() + static_cast<std::size_t>(n) > max_bytes)  // grew while read
      throw InputError(fmt::format("{}: more than {} bytes; allowed: {} of at most {} bytes", who(label, path),
                                   max_bytes, allowed, max_bytes));
    text.append(buf, static_cast<std::size_t>(n));
  }
  return text;
}

}  // namespace octocd
