#pragma once
/// \file wait_event.hpp
/// Waiting on events, never on a timer: a child process's end (a pidfd from pidfd_open,
/// woken by the exit itself) and a condition on files, checked again after every inotify
/// event in the folders watched (a file created, written, closed or renamed into place).
/// Each wait takes a limit: a functional bound, so that a test that would hang fails
/// instead; no assertion depends on how long a wait took. Linux only (inotify, pidfd).
#include <poll.h>
#include <sys/inotify.h>
#include <sys/syscall.h>
#include <sys/types.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cstdint>
#include <exception>
#include <filesystem>
#include <functional>
#include <string>
#include <vector>

#include "octocd/trace.hpp"

namespace octocd::test {

/// Milliseconds from now until `deadline` (0 when it passed), as poll(2)'s timeout.
inline int ms_until(std::chrono::steady_clock::time_point deadline) {
  const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(deadline - std::chrono::steady_clock::now());
  return left.count() > 0 ? static_cast<int>(left.count()) : 0;
}

/// poll(2) on one descriptor for POLLIN until `deadline`, restarted after EINTR: true when
/// it became readable, false when the deadline passed first.
inline bool readable_before(int fd, std::chrono::steady_clock::time_point deadline) {
  for (;;) {
    pollfd p{fd, POLLIN, 0};
    const int n = ::poll(&p, 1, ms_until(deadline));
    if (n > 0) return true;
    if (n == 0) return false;
    if (errno != EINTR) return false;
  }
}

/// Waits for the child `pid` to end, for at most `limit`. True once it ended, with its
/// wait status in `status` (the child is reaped); false when the limit passed first (the
/// child runs on: the caller kills it). Without pidfd_open (Linux before 5.3) it waits
/// without a bound.
inline bool wait_child(pid_t pid, int& status, std::chrono::milliseconds limit) {
  const int fd = static_cast<int>(::syscall(SYS_pidfd_open, pid, 0));
  if (fd >= 0) {
    const bool ended = readable_before(fd, std::chrono::steady_clock::now() + limit);
    ::close(fd);
    if (!ended) return false;
  }
  pid_t got = 0;
  while ((got = ::waitpid(pid, &status, 0)) < 0 && errno == EINTR) {
  }
  return got == pid;
}

/// The inotify events wait_until wakes on: a file created, written, closed after writing
/// or renamed into the folder (an atomic write), and a folder created.
constexpr std::uint32_t kFileChanges = IN_CREATE | IN_MODIFY | IN_CLOSE_WRITE | IN_MOVED_TO;

/// Waits until `ready()` holds, for at most `limit`: `ready` is checked at once, then again
/// after each batch of inotify events `mask` on the paths `watch` (folders or files; a path
/// that does not exist yet is watched from the first event after it appears, so list its
/// parent folder too). True once `ready()` held, false when the limit passed first.
inline bool wait_until(const std::function<bool()>& ready, const std::vector<std::filesystem::path>& watch,
                       std::chrono::milliseconds limit, std::uint32_t mask = kFileChanges) {
  const auto deadline = std::chrono::steady_clock::now() + limit;
  const int fd = ::inotify_init1(IN_CLOEXEC | IN_NONBLOCK);
  if (fd < 0) return ready();
  auto add_watches = [&] {
    for (const auto& p : watch) (void)::inotify_add_watch(fd, p.c_str(), mask);  // again: the same watch
  };
  add_watches();  // before the first check: no event between the check and the wait is lost
  bool held = ready();
  alignas(inotify_event) char buf[64 * 1024];
  while (!held && readable_before(fd, deadline)) {
    while (::read(fd, buf, sizeof buf) > 0) {
    }
    add_watches();
    held = ready();
  }
  ::close(fd);
  return held;
}

/// Waits until the trace `trace` holds at least `frames` flushed frames (read_trace_summary,
/// checked after each change in its folder), for at most `limit`. Returns the frames it held
/// at the last check (0 while it is missing or unreadable): >= `frames` unless the limit passed.
inline std::int64_t wait_for_trace_frames(const std::string& trace, std::int64_t frames,
                                          std::chrono::milliseconds limit) {
  std::int64_t seen = 0;
  wait_until(
      [&] {
        try {
          seen = read_trace_summary(trace).frames;
        } catch (const std::exception&) {
        }
        return seen >= frames;
      },
      {std::filesystem::path(trace).parent_path()}, limit);
  return seen;
}

}  // namespace octocd::test
