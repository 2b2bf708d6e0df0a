// Running an engine's command as a bounded child process (child_process.hpp).
#include "child_process.hpp"

#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <spawn.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cstdlib>
#include <cstring>

#include <fmt/format.h>

#include "octocd/stop.hpp"
#include "octocd/text.hpp"

extern char** environ;

namespace octocd::process_detail {

namespace {

using Clock = std::chrono::steady_clock;

/// Bytes of each stream kept (the tail).
constexpr std::size_t kTailBytes = 64 * 1024;

/// Appends `data` to `tail`, keeping its last kTailBytes.
void keep_tail(std::string& tail, const char* data, std::size_t n) {
  tail.append(data, n);
  if (tail.size() > 2 * kTailBytes) tail.erase(0, tail.size() - kTailBytes);
}

/// Reads what `fd` holds now (non-blocking) into `tail`, at most `reads` reads of 16 KiB;
/// false at EOF or error.
bool drain(int fd, std::string& tail, std::uint64_t& total, int reads = 64) {
  char buf[16384];
  for (int k = 0; k < reads; ++k) {
    const ssize_t n = ::read(fd, buf, sizeof buf);
    if (n > 0) {
      keep_tail(tail, buf, static_cast<std::size_t>(n));
      total += static_cast<std::uint64_t>(n);
      continue;
    }
    if (n < 0 && errno == EINTR) continue;
    if (n < 0 && (errno == EAGAIN || errno == EWOULDBLOCK)) return true;
    return false;  // EOF or error
  }
  return true;
}

double since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

/// The size of `path` (0 when absent).
std::uint64_t file_size(const std::string& path) {
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0) return 0;
  return static_cast<std::uint64_t>(st.st_size);
}

/// printable(text) with the C1 controls (U+0080..U+009F, UTF-8 C2 80..C2 9F: U+009B is
/// an 8-bit CSI to some terminals) also written as \\u00NN.
std::string terminal_safe(const std::string& text) {
  const std::string p = printable(text);
  std::string out;
  out.reserve(p.size());
  for (std::size_t i = 0; i < p.size(); ++i) {
    const auto c = static_cast<unsigned char>(p[i]);
    const auto d = i + 1 < p.size() ? static_cast<unsigned char>(p[i + 1]) : 0;
    if (c == 0xC2 && d >= 0x80 && d <= 0x9F) {
      out += fmt::format("\\u{:04x}", d);
      ++i;
    } else {
      out += p[i];
    }
  }
  return out;
}

const char* signal_text(int sig) {
  const char* name = sigabbrev_np(sig);
  return name ? name : "?";
}

}  // namespace

std::string find_on_path(const std::string& program) {
  if (program.empty()) return "";
  if (program.find('/') != std::string::npos) return ::access(program.c_str(), X_OK) == 0 ? program : "";
  const char* path = std::getenv("PATH");
  std::string rest = path && *path ? path : "/usr/local/bin:/usr/bin:/bin";
  while (true) {
    const auto colon = rest.find(':');
    std::string dir = rest.substr(0, colon);
    if (dir.empty()) dir = ".";
    const std::string full = dir + "/" + program;
    struct stat st {};
    if (::stat(full.c_str(), &st) == 0 && S_ISREG(st.st_mode) && ::access(full.c_str(), X_OK) == 0) return full;
    if (colon == std::string::npos) break;
    rest = rest.substr(colon + 1);
  }
  return "";
}

ChildOutcome run_child(const ChildRun& run) {
  ChildOutcome o;
  int out[2] = {-1, -1}, err[2] = {-1, -1};
  if (::pipe2(out, O_CLOEXEC | O_NONBLOCK) != 0 || ::pipe2(err, O_CLOEXEC | O_NONBLOCK) != 0) {
    o.end = ChildOutcome::End::SpawnFailed;
    o.spawn_error = fmt::format("pipe: {}", std::strerror(errno));
    for (int fd : {out[0], out[1], err[0], err[1]})
      if (fd >= 0) ::close(fd);
    return o;
  }
  // The child's ends block (a writer waits for octocd to read, never loses bytes).
  ::fcntl(out[1], F_SETFL, 0);
  ::fcntl(err[1], F_SETFL, 0);
  posix_spawn_file_actions_t fa;
  posix_spawnattr_t attr;
  posix_spawn_file_actions_init(&fa);
  posix_spawnattr_init(&attr);
  posix_spawn_file_actions_addopen(&fa, 0, "/dev/null", O_RDONLY, 0);
  posix_spawn_file_actions_adddup2(&fa, out[1], 1);
  posix_spawn_file_actions_adddup2(&fa, err[1], 2);
  posix_spawn_file_actions_addclosefrom_np(&fa, 3);  // no descriptor of octocd's (a trace open for writing) leaks
  if (!run.cwd.empty()) posix_spawn_file_actions_addchdir_np(&fa, run.cwd.c_str());
  // Its own process group (a terminal's Ctrl-C reaches octocd, which stops the group), no
  // blocked signal, and the default action for those octocd catches or ignores.
  sigset_t none, defaults;
  sigemptyset(&none);
  sigemptyset(&defaults);
  for (int s : {SIGINT, SIGTERM, SIGHUP, SIGQUIT, SIGPIPE, SIGXFSZ, SIGALRM, SIGCHLD, SIGUSR1, SIGUSR2})
    sigaddset(&defaults, s);
  posix_spawnattr_setflags(&attr, POSIX_SPAWN_SETPGROUP | POSIX_SPAWN_SETSIGMASK | POSIX_SPAWN_SETSIGDEF);
  posix_spawnattr_setpgroup(&attr, 0);
  posix_spawnattr_setsigmask(&attr, &none);
  posix_spawnattr_setsigdefault(&attr, &defaults);
  std::vector<char*> argv;
  for (const std::string& a : run.argv) argv.push_back(const_cast<char*>(a.c_str()));
  argv.push_back(nullptr);
  pid_t pid = -1;
  const auto t0 = Clock::now();
  const int rc = ::posix_spawn(&pid, argv[0], &fa, &attr, argv.data(), environ);
  posix_spawn_file_actions_destroy(&fa);
  posix_spawnattr_destroy(&attr);
  ::close(out[1]);
  ::close(err[1]);
  if (rc != 0) {
    ::close(out[0]);
    ::close(err[0]);
    o.end = ChildOutcome::End::SpawnFailed;
    o.spawn_error = fmt::format("{}: {}", run.argv.empty() ? "" : run.argv[0], std::strerror(rc));
    return o;
  }
  // A process that ends at once while stopping (stop.hpp) kills the group too.
  (void)octocd::stop_track_child(pid, true);
  struct Forget {
    pid_t group;
    ~Forget() { (void)octocd::stop_track_child(group, false); }
  } forget{pid};
  bool out_open = true, err_open = true;
  int status = 0;
  bool reaped = false;
  // Stops the group: SIGTERM, up to `grace` for it to end, then SIGKILL; reaps the child.
  auto stop_group = [&](double grace) {
    ::kill(-pid, SIGTERM);
    const auto t = Clock::now();
    while (since(t) < grace) {
      if (::waitpid(pid, &status, WNOHANG) == pid) {
        reaped = true;
        break;
      }
      if (out_open) out_open = drain(out[0], o.out_tail, o.out_bytes);
      if (err_open) err_open = drain(err[0], o.err_tail, o.err_bytes);
      ::usleep(5000);
    }
    ::kill(-pid, SIGKILL);  // the group: helpers the child started too
    if (!reaped) {
      while (::waitpid(pid, &status, 0) < 0 && errno == EINTR) {
      }
      reaped = true;
    }
  };
  while (!reaped) {
    pollfd fds[2] = {{out[0], POLLIN, 0}, {err[0], POLLIN, 0}};
    if (out_open || err_open) {
      if (!out_open) fds[0].fd = -1;
      if (!err_open) fds[1].fd = -1;
      ::poll(fds, 2, 10);
    } else {
      ::usleep(10000);
    }
    if (out_open) out_open = drain(out[0], o.out_tail, o.out_bytes);
    if (err_open) err_open = drain(err[0], o.err_tail, o.err_bytes);
    const pid_t w = ::waitpid(pid, &status, WNOHANG);
    if (w == pid) {
      reaped = true;
      break;
    }
    if (const int sig = octocd::stop_signal()) {
      o.end = ChildOutcome::End::Stopped;
      o.stop_signal = sig;
      stop_group(0.2);  // within the 0.5 s grace of a stopping command (stop.hpp: StopWithin)
      break;
    }
    if (since(t0) > run.timeout_s) {
      o.end = ChildOutcome::End::TimedOut;
      stop_group(run.grace_s);
      break;
    }
    if (!run.watched.empty() && file_size(run.watched) > run.watched_max) {
      o.end = ChildOutcome::End::Oversize;
      stop_group(run.grace_s);
      break;
    }
  }
  o.seconds = since(t0);
  // What the pipes still hold (a helper still holding them open is not waited for).
  if (out_open) drain(out[0], o.out_tail, o.out_bytes);
  if (err_open) drain(err[0], o.err_tail, o.err_bytes);
  ::close(out[0]);
  ::close(err[0]);
  if (o.end == ChildOutcome::End::Exited) {
    if (WIFSIGNALED(status)) {
      o.end = ChildOutcome::End::Signalled;
      o.code = WTERMSIG(status);
    } else {
      o.code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
    }
  }
  return o;
}

std::string describe(const ChildOutcome& o) {
  using End = ChildOutcome::End;
  switch (o.end) {
    case End::Exited:
      return fmt::format("exited with code {} after {:.2f} s", o.code, o.seconds);
    case End::Signalled:
      return fmt::format("was killed by signal {} (SIG{}) after {:.2f} s", o.code, signal_text(o.code), o.seconds);
    case End::TimedOut:
      return fmt::format("ran past its bound of {:.2f} s (timeout_s) and was stopped (SIGTERM, then SIGKILL)",
                         o.seconds);
    case End::Oversize:
      return fmt::format("wrote a trace beyond its max_trace_bytes and was stopped after {:.2f} s", o.seconds);
    case End::Stopped:
      return fmt::format("was stopped by octocd's {} after {:.2f} s", stop_signal_name(o.stop_signal), o.seconds);
    case End::SpawnFailed:
      return fmt::format("could not be started ({})", o.spawn_error);
  }
  return "";
}

std::string output_tail(const ChildOutcome& o) {
  const bool err = !o.err_tail.empty();
  const std::string& tail = err ? o.err_tail : o.out_tail;
  const std::uint64_t total = err ? o.err_bytes : o.out_bytes;
  if (tail.empty()) return "";
  // The last 8 lines, at most 1000 bytes, each printable.
  std::string t = tail;
  while (!t.empty() && (t.back() == '\n' || t.back() == '\r')) t.pop_back();
  std::vector<std::string> lines;
  std::size_t end = t.size(), used = 0;
  bool whole = total == tail.size();  // every byte it wrote is shown
  while (end > 0) {
    if (lines.size() == 8 || used >= 1000) {
      whole = false;
      break;
    }
    const std::size_t nl = t.rfind('\n', end - 1);
    const std::size_t begin = nl == std::string::npos ? 0 : nl + 1;
    std::string line = t.substr(begin, end - begin);
    if (!line.empty() && line.back() == '\r') line.pop_back();
    if (used + line.size() > 1000) {
      line = "..." + line.substr(line.size() - (1000 - used));
      whole = false;
    }
    used += line.size();
    lines.push_back(terminal_safe(line));
    if (nl == std::string::npos) break;
    end = nl;
  }
  std::reverse(lines.begin(), lines.end());
  std::string shown;
  for (const std::string& l : lines) shown += (shown.empty() ? "" : " | ") + l;
  return fmt::format("; its {} ended{}: {}", err ? "stderr" : "stdout",
                     whole ? std::string() : fmt::format(" (the last {} of {} bytes)", used, total), shown);
}

}  // namespace octocd::process_detail
