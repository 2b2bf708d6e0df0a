#pragma once
/// \file folder_entries.hpp
/// The entries of an open folder, read with getdents64(2) alone: no allocation, no lock,
/// async-signal-safe, so usable in a signal handler (stop.cpp's temporaries) and in a
/// forked child of a threaded process (a process engine's keeper, which walks
/// /proc/PID/task).

#include <dirent.h>
#include <unistd.h>

namespace octocd {

/// Calls `f(name)` (a NUL-terminated const char*, valid during the call) for every entry of
/// the folder open as descriptor `dir` (O_DIRECTORY), "." and ".." left out, until the end or
/// a read error. The descriptor's offset moves; it is not closed.
template <class F>
void for_each_folder_entry(int dir, F&& f) {
  alignas(8) char entries[2048];
  for (;;) {
    const ssize_t got = ::getdents64(dir, entries, sizeof entries);
    if (got <= 0) return;
    for (ssize_t off = 0; off < got;) {
      const auto* d = reinterpret_cast<const struct dirent64*>(entries + off);
      off += d->d_reclen;
      const char* name = d->d_name;
      if (name[0] == '.' && (name[1] == '\0' || (name[1] == '.' && name[2] == '\0'))) continue;
      f(name);
    }
  }
}

}  // namespace octocd
