// Running an engine's command as a bounded child process (child_process.hpp).
#include "child_process.hpp"

#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <dirent.h>
#include <pthread.h>
#include <sys/prctl.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>

#include <fmt/format.h>

#include "octocd/folder_entries.hpp"
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

/// Longest stdout line given whole to ChildRun::on_poll (bytes); a longer one is cut there.
constexpr std::size_t kLineBytes = 4096;

/// The complete lines of a stream, split as its bytes come (ChildRun::on_poll).
struct LineSplitter {
  std::string partial;               ///< the line begun, not yet ended
  bool cut = false;                  ///< the line begun passed kLineBytes: its rest is dropped
  std::vector<std::string> lines;    ///< complete lines not yet handed on

  void add(const char* data, std::size_t n) {
    for (std::size_t i = 0; i < n; ++i) {
      if (data[i] == '\n') {
        lines.push_back(std::move(partial));
        partial.clear();
        cut = false;
      } else if (partial.size() < kLineBytes) {
        partial.push_back(data[i]);
      } else {
        cut = true;
      }
    }
  }
};

/// Reads what `fd` holds now (non-blocking) into `tail` (and `lines` when given), at most
/// `reads` reads of 16 KiB; false at EOF or error.
bool drain(int fd, std::string& tail, std::uint64_t& total, LineSplitter* lines = nullptr, int reads = 64) {
  char buf[16384];
  for (int k = 0; k < reads; ++k) {
    const ssize_t n = ::read(fd, buf, sizeof buf);
    if (n > 0) {
      keep_tail(tail, buf, static_cast<std::size_t>(n));
      if (lines) lines->add(buf, static_cast<std::size_t>(n));
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

/// "ENOENT", "EACCES", ... ("errno N" when unnamed).
std::string errno_name(int e) {
  const char* name = strerrorname_np(e);
  return name ? std::string(name) : fmt::format("errno {}", e);
}

const char* signal_text(int sig) {
  const char* name = sigabbrev_np(sig);
  return name ? name : "?";
}

}  // namespace

namespace {

/// Whether `path` is a regular file this process may execute.
bool executable_file(const std::string& path) {
  struct stat st {};
  return ::stat(path.c_str(), &st) == 0 && S_ISREG(st.st_mode) && ::access(path.c_str(), X_OK) == 0;
}

}  // namespace

std::string find_on_path(const std::string& program) {
  if (program.empty()) return "";
  if (program.find('/') != std::string::npos) return executable_file(program) ? program : "";
  const char* path = std::getenv("PATH");
  std::string rest = path && *path ? path : "/usr/local/bin:/usr/bin:/bin";
  while (true) {
    const auto colon = rest.find(':');
    std::string dir = rest.substr(0, colon);
    if (dir.empty()) dir = ".";
    const std::string full = dir + "/" + program;
    if (executable_file(full)) return full;
    if (colon == std::string::npos) break;
    rest = rest.substr(colon + 1);
  }
  return "";
}

std::string why_not_runnable(const std::string& program) {
  if (program.find('/') == std::string::npos)
    return find_on_path(program).empty() ? "not found on PATH" : "";
  struct stat st {};
  if (::stat(program.c_str(), &st) != 0) {
    const int e = errno;
    return fmt::format("cannot be run: {} ({})", std::strerror(e), errno_name(e));
  }
  if (S_ISDIR(st.st_mode)) return "cannot be run: a folder (EISDIR)";
  if (!S_ISREG(st.st_mode)) return "cannot be run: not a regular file (EACCES)";
  if (::access(program.c_str(), X_OK) != 0) {
    const int e = errno;
    return fmt::format("cannot be run: {} ({})", std::strerror(e), errno_name(e));
  }
  return "";
}

namespace {

// ---- the keeper ------------------------------------------------------------------------
// A forked copy of the calling process between octocd and the engine's process (docs/
// engines.md, "Process engines and their process tree"): a child subreaper
// (prctl(PR_SET_CHILD_SUBREAPER)), so every descendant of the engine, one that calls
// setsid() or makes a process group of its own included, stays in its tree or is
// re-parented to it; when the engine ends, is stopped or octocd goes (PR_SET_PDEATHSIG),
// it kills every descendant it finds through /proc/PID/task/TID/children until none is
// left, reaps them, reports the engine's wait status on a pipe and exits. The caller may
// hold threads, so it is made with _Fork() (no atfork handler runs) and until _exit() it
// only makes system calls: no allocation, no lock, no stdio.

/// What the keeper writes on its report pipe (fd 3) before it exits.
struct KeeperReport {
  int exec_errno = 0;  ///< the engine's execve() or chdir() failed with this errno (0: it ran)
  int status = 0;      ///< the engine's wait status (waitpid)
  int ended = 0;       ///< 1: the engine ended (status holds); 0: it was killed by the keeper
};

/// The keeper's orders (signals from octocd, blocked and taken with sigtimedwait).
constexpr int kStopGraceful = SIGTERM;  ///< a bound passed: SIGTERM to the tree, the run's grace, SIGKILL
constexpr int kStopFast = SIGUSR1;      ///< octocd stops: the same with kFastGraceS
constexpr int kOwnerGone = SIGHUP;      ///< octocd is gone (PR_SET_PDEATHSIG): SIGKILL to the tree at once
constexpr double kFastGraceS = 0.2;     ///< within a stopping command's 0.5 s grace (stop.hpp: StopWithin)

/// The largest number of descendants one walk signals (a fork bomb is met by repeated walks).
constexpr int kMaxWalk = 4096;

double now_s() {
  timespec t{};
  ::clock_gettime(CLOCK_MONOTONIC, &t);
  return static_cast<double>(t.tv_sec) + 1e-9 * static_cast<double>(t.tv_nsec);
}

/// Writes `v` in decimal at `out` (no terminator); returns the end.
char* put_int(char* out, long v) {
  char digits[24];
  int n = 0;
  do {
    digits[n++] = static_cast<char>('0' + v % 10);
    v /= 10;
  } while (v > 0 && n < 24);
  while (n > 0) *out++ = digits[--n];
  return out;
}

/// Appends the children of every thread of `pid` (/proc/PID/task/TID/children) to
/// list[n..kMaxWalk); returns the new count. System calls only.
int add_children(pid_t pid, pid_t* list, int n) {
  char path[48] = "/proc/";
  char* e = put_int(path + 6, pid);
  const char task[] = "/task";
  for (const char* c = task; *c; ++c) *e++ = *c;
  *e = '\0';
  const int dir = ::open(path, O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (dir < 0) return n;
  for_each_folder_entry(dir, [&](const char* tid) {
    if (tid[0] < '0' || tid[0] > '9') return;
    char rel[300];
    char* r = rel;
    for (const char* c = tid; *c && r < rel + 280; ++c) *r++ = *c;
    const char tail[] = "/children";
    for (const char* c = tail; *c; ++c) *r++ = *c;
    *r = '\0';
    const int fd = ::openat(dir, rel, O_RDONLY | O_CLOEXEC);
    if (fd < 0) return;
    char buf[1024];
    long value = -1;
    for (;;) {
      const ssize_t k = ::read(fd, buf, sizeof buf);
      if (k <= 0) break;
      for (ssize_t i = 0; i < k; ++i) {
        if (buf[i] >= '0' && buf[i] <= '9') {
          value = (value < 0 ? 0 : value * 10) + (buf[i] - '0');
        } else if (value >= 0) {
          if (n < kMaxWalk) list[n++] = static_cast<pid_t>(value);
          value = -1;
        }
      }
    }
    if (value >= 0 && n < kMaxWalk) list[n++] = static_cast<pid_t>(value);
    ::close(fd);
  });
  ::close(dir);
  return n;
}

/// Sends `sig` to every descendant of the calling process (a walk from it down); returns
/// how many it found.
int signal_descendants(int sig) {
  pid_t list[kMaxWalk];
  int n = add_children(::getpid(), list, 0);
  for (int i = 0; i < n; ++i) {
    ::kill(list[i], sig);
    n = add_children(list[i], list, n);
  }
  return n;
}

/// The keeper's state of the engine.
struct EngineState {
  pid_t pid = -1;
  bool ended = false;
  int status = 0;
};

/// Reaps every child that ended; false once the keeper has no child left.
bool reap(EngineState& engine) {
  for (;;) {
    int status = 0;
    const pid_t w = ::waitpid(-1, &status, WNOHANG);
    if (w > 0) {
      if (w == engine.pid && !engine.ended) {
        engine.ended = true;
        engine.status = status;
      }
      continue;
    }
    return !(w < 0 && errno == ECHILD);
  }
}

/// SIGKILL to every descendant, again until none is left (each killed one's children come
/// to the keeper, the subreaper), all reaped; at most about 10 s (a fork bomb).
void kill_tree(EngineState& engine) {
  const timespec pause{0, 1000000};
  const double until = now_s() + 10.0;
  while (reap(engine) && now_s() < until) {
    signal_descendants(SIGKILL);
    ::nanosleep(&pause, nullptr);
  }
}

[[noreturn]] void keeper_main(pid_t owner, char* const* argv, const char* cwd, double grace_s) {
  // fds here: 0 /dev/null, 1 and 2 the output pipes, 3 the report pipe; nothing else.
  sigset_t orders;
  ::sigemptyset(&orders);
  for (int s : {kStopGraceful, kStopFast, kOwnerGone, SIGINT, SIGCHLD}) ::sigaddset(&orders, s);
  struct sigaction dfl {};
  dfl.sa_handler = SIG_DFL;
  ::sigemptyset(&dfl.sa_mask);
  for (int s = 1; s < NSIG; ++s)
    if (s != SIGKILL && s != SIGSTOP) ::sigaction(s, &dfl, nullptr);
  ::prctl(PR_SET_PDEATHSIG, kOwnerGone);
  KeeperReport report;
  auto finish = [&](EngineState& engine) {
    kill_tree(engine);
    report.ended = engine.ended ? 1 : 0;
    report.status = engine.status;
    (void)!::write(3, &report, sizeof report);
    ::_exit(0);
  };
  EngineState engine;
  if (::getppid() != owner) finish(engine);  // octocd went before PR_SET_PDEATHSIG held
  ::prctl(PR_SET_CHILD_SUBREAPER, 1);
  ::setpgid(0, 0);  // out of octocd's group: a terminal's Ctrl-C reaches octocd, which orders the stop
  int failed[2];
  if (::pipe2(failed, O_CLOEXEC) != 0) {
    report.exec_errno = errno;
    finish(engine);
  }
  engine.pid = ::_Fork();
  if (engine.pid == 0) {
    // The engine: a process group of its own, no blocked signal, every signal at its default,
    // not the report pipe.
    ::close(3);
    ::setpgid(0, 0);
    sigset_t none;
    ::sigemptyset(&none);
    ::sigprocmask(SIG_SETMASK, &none, nullptr);
    int err = 0;
    if (cwd != nullptr && ::chdir(cwd) != 0) err = errno;
    if (err == 0) {
      ::execve(argv[0], argv, environ);
      err = errno;
    }
    (void)!::write(failed[1], &err, sizeof err);
    ::_exit(127);
  }
  if (engine.pid < 0) {
    report.exec_errno = errno;
    finish(engine);
  }
  ::close(failed[1]);
  // The output pipes are the engine's and its descendants' alone: they end with them.
  ::dup2(0, 1);
  ::dup2(0, 2);
  int err = 0;
  while (::read(failed[0], &err, sizeof err) < 0 && errno == EINTR) {
  }
  ::close(failed[0]);
  report.exec_errno = err;
  double deadline = -1.0;
  const timespec tick{0, 10 * 1000000};
  for (;;) {
    siginfo_t info;
    const int sig = ::sigtimedwait(&orders, &info, &tick);
    if (sig == kOwnerGone) break;
    if ((sig == kStopGraceful || sig == kStopFast || sig == SIGINT) && deadline < 0.0) {
      signal_descendants(SIGTERM);
      deadline = now_s() + (sig == kStopGraceful ? grace_s : kFastGraceS);
    }
    reap(engine);
    if (engine.ended) break;
    if (deadline >= 0.0 && now_s() >= deadline) break;
  }
  finish(engine);
  ::_exit(0);
}

}  // namespace

ChildOutcome run_child(const ChildRun& run) {
  ChildOutcome o;
  o.timeout_s = run.timeout_s;
  o.timeout_setting = run.timeout_setting;
  o.grace_s = run.grace_s;
  int out[2] = {-1, -1}, err[2] = {-1, -1}, rep[2] = {-1, -1};
  if (::pipe2(out, O_CLOEXEC | O_NONBLOCK) != 0 || ::pipe2(err, O_CLOEXEC | O_NONBLOCK) != 0 ||
      ::pipe2(rep, O_CLOEXEC | O_NONBLOCK) != 0) {
    o.end = ChildOutcome::End::SpawnFailed;
    o.spawn_error = fmt::format("pipe: {}", std::strerror(errno));
    for (int fd : {out[0], out[1], err[0], err[1], rep[0], rep[1]})
      if (fd >= 0) ::close(fd);
    return o;
  }
  // The child's ends block (a writer waits for octocd to read, never loses bytes).
  ::fcntl(out[1], F_SETFL, 0);
  ::fcntl(err[1], F_SETFL, 0);
  ::fcntl(rep[1], F_SETFL, 0);
  // Everything the keeper uses is made before fork() (it may not allocate).
  std::vector<char*> argv;
  for (const std::string& a : run.argv) argv.push_back(const_cast<char*>(a.c_str()));
  argv.push_back(nullptr);
  const char* cwd = run.cwd.empty() ? nullptr : run.cwd.c_str();
  const pid_t owner = ::getpid();
  // The keeper's orders are blocked from its first instruction (it takes them with
  // sigtimedwait); this thread's mask is restored at once.
  sigset_t orders, old;
  ::sigemptyset(&orders);
  for (int s : {kStopGraceful, kStopFast, kOwnerGone, SIGINT, SIGCHLD}) ::sigaddset(&orders, s);
  ::pthread_sigmask(SIG_BLOCK, &orders, &old);
  const auto t0 = Clock::now();
  const pid_t keeper = ::_Fork();  // no atfork handler runs (they may lock what another thread holds)
  if (keeper == 0) {
    // No descriptor of octocd's (a trace open for writing) leaks: 0 /dev/null, 1 and 2 the
    // output pipes, 3 the report pipe.
    const int o1 = ::fcntl(out[1], F_DUPFD, 10), e1 = ::fcntl(err[1], F_DUPFD, 10), r1 = ::fcntl(rep[1], F_DUPFD, 10);
    const int null = ::open("/dev/null", O_RDONLY);
    if (o1 < 0 || e1 < 0 || r1 < 0 || null < 0) ::_exit(127);
    ::dup2(null, 0);
    ::dup2(o1, 1);
    ::dup2(e1, 2);
    ::dup2(r1, 3);
    ::close_range(4, ~0U, 0);
    keeper_main(owner, argv.data(), cwd, run.grace_s);
  }
  const int fork_errno = errno;
  ::pthread_sigmask(SIG_SETMASK, &old, nullptr);
  ::close(out[1]);
  ::close(err[1]);
  ::close(rep[1]);
  if (keeper < 0) {
    for (int fd : {out[0], err[0], rep[0]}) ::close(fd);
    o.end = ChildOutcome::End::SpawnFailed;
    o.spawn_error = fmt::format("fork: {} ({})", std::strerror(fork_errno), errno_name(fork_errno));
    return o;
  }
  bool out_open = true, err_open = true;
  LineSplitter out_lines;
  LineSplitter* const split = run.on_poll ? &out_lines : nullptr;
  int status = 0;
  bool reaped = false;
  double ordered_at = -1.0, ordered_grace = 0.0;  // when the keeper was told to stop, and its grace
  // Tells the keeper to stop the engine's tree (SIGTERM, `grace`, SIGKILL); once.
  auto order_stop = [&](int order, double grace) {
    if (ordered_at >= 0.0) return;
    ::kill(keeper, order);
    ordered_at = since(t0);
    ordered_grace = grace;
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
    if (out_open) out_open = drain(out[0], o.out_tail, o.out_bytes, split);
    if (err_open) err_open = drain(err[0], o.err_tail, o.err_bytes);
    if (split) {
      run.on_poll(split->lines);
      split->lines.clear();
    }
    const pid_t w = ::waitpid(keeper, &status, WNOHANG);
    if (w == keeper) {
      reaped = true;
      break;
    }
    if (o.end == ChildOutcome::End::Exited) {
      if (const int sig = octocd::stop_signal()) {
        o.end = ChildOutcome::End::Stopped;
        o.stop_signal = sig;
        order_stop(kStopFast, kFastGraceS);
      } else if (run.cancel != nullptr && run.cancel->load()) {
        o.end = ChildOutcome::End::Stopped;
        order_stop(kStopFast, kFastGraceS);
      } else if (since(t0) > run.timeout_s) {
        o.end = ChildOutcome::End::TimedOut;
        order_stop(kStopGraceful, run.grace_s);
      } else if (!run.watched.empty() && file_size(run.watched) > run.watched_max) {
        o.end = ChildOutcome::End::Oversize;
        order_stop(kStopGraceful, run.grace_s);
      }
    }
    // A keeper that does not end well after its grace (stopped by a debugger): killed.
    if (ordered_at >= 0.0 && since(t0) > ordered_at + ordered_grace + 5.0) {
      ::kill(keeper, SIGKILL);
      while (::waitpid(keeper, &status, 0) < 0 && errno == EINTR) {
      }
      reaped = true;
    }
  }
  o.seconds = since(t0);
  // What the pipes still hold (the keeper killed every writer before it ended).
  if (out_open) drain(out[0], o.out_tail, o.out_bytes, split);
  if (err_open) drain(err[0], o.err_tail, o.err_bytes);
  if (split && !split->lines.empty()) run.on_poll(split->lines);
  KeeperReport report;
  const bool reported = ::read(rep[0], &report, sizeof report) == static_cast<ssize_t>(sizeof report);
  ::close(out[0]);
  ::close(err[0]);
  ::close(rep[0]);
  if (reported && report.exec_errno != 0) {
    o.end = ChildOutcome::End::SpawnFailed;
    o.spawn_error = fmt::format("{}: {} ({})", run.argv.empty() ? "" : run.argv[0], std::strerror(report.exec_errno), errno_name(report.exec_errno));
    return o;
  }
  if (o.end == ChildOutcome::End::Exited) {
    const int st = reported && report.ended ? report.status : status;
    if (!reported || !report.ended) {
      o.end = ChildOutcome::End::Signalled;  // the keeper was killed, or killed the engine unordered
      o.code = !reported && WIFSIGNALED(status) ? WTERMSIG(status) : SIGKILL;
    } else if (WIFSIGNALED(st)) {
      o.end = ChildOutcome::End::Signalled;
      o.code = WTERMSIG(st);
    } else {
      o.code = WIFEXITED(st) ? WEXITSTATUS(st) : -1;
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
      return fmt::format("ran past its {} of {:g} s and was stopped after {:.2f} s (SIGTERM to its process tree, "
                         "SIGKILL to what is left after a grace of {:g} s)",
                         o.timeout_setting, o.timeout_s, o.seconds, o.grace_s);
    case End::Oversize:
      return fmt::format("wrote a trace beyond its max_trace_bytes and was stopped after {:.2f} s", o.seconds);
    case End::Stopped:
      if (o.stop_signal == 0) return fmt::format("was stopped (its caller interrupted the step) after {:.2f} s", o.seconds);
      return fmt::format("was stopped by octocd's {} after {:.2f} s", stop_signal_name(o.stop_signal), o.seconds);
    case End::SpawnFailed:
      return fmt::format("could not be started: {}", o.spawn_error);
  }
  return "";
}

bool progress_line(const std::string& line, std::int64_t* frames) {
  long long n = -1;
  char rest = 0;
  if (std::sscanf(line.c_str(), "octocd-progress %lld%c", &n, &rest) != 1 || n < 0) return false;
  if (frames) *frames = n;
  return true;
}

std::string output_tail(const ChildOutcome& o) {
  const bool err = !o.err_tail.empty();
  const std::string& tail = err ? o.err_tail : o.out_tail;
  const std::uint64_t total = err ? o.err_bytes : o.out_bytes;
  // The last 8 lines, at most 1000 bytes, each printable; of stdout, its progress lines
  // left out (they say how far it ran, not what went wrong).
  std::string t = tail;
  while (!t.empty() && (t.back() == '\n' || t.back() == '\r')) t.pop_back();
  std::vector<std::string> lines;
  std::size_t end = t.size(), used = 0, progress = 0;
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
    if (!err && progress_line(line, nullptr)) {
      ++progress;
    } else {
      if (used + line.size() > 1000) {
        line = "..." + line.substr(line.size() - (1000 - used));
        whole = false;
      }
      used += line.size();
      lines.push_back(terminal_safe(line));
    }
    if (nl == std::string::npos) break;
    end = nl;
  }
  if (lines.empty())
    return progress > 0 ? "; no error output (its stderr is empty, its stdout holds only octocd-progress lines)"
                        : "; no error output (its stderr and stdout are empty)";
  std::reverse(lines.begin(), lines.end());
  std::string shown;
  for (const std::string& l : lines) shown += (shown.empty() ? "" : " | ") + l;
  return fmt::format("; its {} ended{}{}: {}", err ? "stderr" : "stdout",
                     progress > 0 ? " (its octocd-progress lines left out)" : "",
                     whole || progress > 0 ? std::string() : fmt::format(" (the last {} of {} bytes)", used, total),
                     shown);
}

}  // namespace octocd::process_detail
