/// \file stop.cpp
/// SIGINT/SIGTERM recorded in a lock-free atomic, polled by the commands' loops; after the
/// first signal a 20 ms SIGALRM tick enforces StopWithin's grace and StopOnSignals'
/// deadline.

#include "octocd/stop.hpp"

#include "octocd/folder_entries.hpp"

#include <dirent.h>
#include <fcntl.h>
#include <pthread.h>
#include <signal.h>
#include <sys/time.h>
#include <time.h>
#include <unistd.h>

#include <algorithm>
#include <cstddef>
#include <cstring>

#include <atomic>
#include <cerrno>
#include <functional>
#include <mutex>
#include <string>
#include <thread>
#include <utility>

namespace octocd {
namespace {

std::atomic<int> g_signal{0};
static_assert(std::atomic<int>::is_always_lock_free, "the handler needs a lock-free flag");

struct sigaction g_old_int, g_old_term, g_old_alrm;
std::atomic<const char*> g_at_once{nullptr};  // StopAtOnce's phrase while one is alive
static_assert(std::atomic<const char*>::is_always_lock_free, "the handler needs a lock-free pointer");
std::atomic<const char*> g_within{nullptr};  // StopWithin's phrase while one is alive
std::atomic<long> g_grace_us{500000};        // its grace (microseconds)
std::atomic<long> g_deadline_us{0};          // StopOnSignals' deadline (0: none)
std::atomic<long long> g_signal_ns{0};       // CLOCK_MONOTONIC at the first signal
std::atomic<bool> g_ticking{false};          // the 20 ms SIGALRM tick runs
std::atomic<bool> g_second_ends{true};       // a second signal ends the process at once
std::atomic<int> g_count{0};                 // signals received since StopOnSignals

// stop_track_temporary's paths and stop_track_child's process groups: removed and killed
// by exit_now (a slot is free while its flag is false; written only while it is).
constexpr std::size_t kTrackSlots = 64;  // a process engine's folder per copy of `run --worlds`
char g_temp_text[kTrackSlots][4096];
std::atomic<bool> g_temp_on[kTrackSlots];
std::atomic<int> g_children[kTrackSlots];  // process group ids, 0: free

// set_stop_kept's text: a ring of buffers, so the handler never reads one being rewritten
// (the text changes at most once a frame; a handler reads it within microseconds).
constexpr std::size_t kKeptSlots = 4, kKeptBytes = 1024;
char g_kept_text[kKeptSlots][kKeptBytes];
std::atomic<const char*> g_kept{nullptr};
std::atomic<unsigned> g_kept_slot{0};

// set_stop_kept_reader: a thread waits on a pipe; the handler that would end the process
// writes one byte to it and leaves the ending to that thread (bounded by the tick).
int g_wake[2] = {-1, -1};
std::atomic<bool> g_reader_on{false};            // a reader is set
std::atomic<bool> g_reader_asked{false};         // an ending was handed to it
std::atomic<long long> g_reader_bound_ns{200000000};
std::atomic<long long> g_reader_until_ns{0};     // past this the tick ends the process itself
std::atomic<int> g_pending_sig{0};               // the ending handed over: exit_now's arguments
std::atomic<const char*> g_pending_middle{""};
std::atomic<const char*> g_pending_tail{"\n"};
char g_pending_what[1024];                       // copied: a StopWithin's text may go away
std::atomic<bool> g_exiting{false};              // exit_now has begun (one line, one _exit)
std::mutex g_reader_mu;                          // guards g_reader while it is set or called
std::function<std::string()> g_reader;

// Async-signal-safe (clock_gettime is).
long long now_ns() {
  timespec t{};
  ::clock_gettime(CLOCK_MONOTONIC, &t);
  return static_cast<long long>(t.tv_sec) * 1000000000LL + t.tv_nsec;
}

// Async-signal-safe: setitimer is a plain system call.
void start_tick() {
  if (g_ticking.exchange(true)) return;
  itimerval t{};
  t.it_value.tv_usec = 20000;
  t.it_interval.tv_usec = 20000;
  ::setitimer(ITIMER_REAL, &t, nullptr);
}

void stop_tick() {
  if (!g_ticking.exchange(false)) return;
  const itimerval off{};
  ::setitimer(ITIMER_REAL, &off, nullptr);
}

// Async-signal-safe: unlinks the entries of the folder `path` (files; empty subfolders),
// one level deep, with open(2), getdents64(2) (for_each_folder_entry) and unlinkat(2) only.
void empty_folder(const char* path) {
  const int dir = ::open(path, O_RDONLY | O_DIRECTORY | O_CLOEXEC | O_NOFOLLOW);
  if (dir < 0) return;
  for_each_folder_entry(dir, [dir](const char* name) {
    if (::unlinkat(dir, name, 0) != 0) ::unlinkat(dir, name, AT_REMOVEDIR);
  });
  ::close(dir);
}

// Async-signal-safe: unlink(2), rmdir(2) and empty_folder only. The files first, then the
// folders (their unlink failed), each emptied of the files it still holds (a process
// engine's request, its trace, what it wrote in its working folder).
void remove_temporaries(bool forget) {
  for (std::size_t k = 0; k < kTrackSlots; ++k)
    if (g_temp_on[k].load()) ::unlink(g_temp_text[k]);
  for (std::size_t k = 0; k < kTrackSlots; ++k)
    if (forget ? g_temp_on[k].exchange(false) : g_temp_on[k].load()) {
      empty_folder(g_temp_text[k]);
      ::rmdir(g_temp_text[k]);
    }
}

// The stop line's descriptor: a copy of stderr taken by StopOnSignals, so a line written
// while a library has pointed descriptor 2 elsewhere (MuJoCo's model compile captures it
// into a temporary file) still reaches the command's stderr; 2 when none was taken.
std::atomic<int> g_err_fd{2};

// Async-signal-safe: write(2) only.
void put(const char* t) {
  std::size_t n = 0;
  while (t[n] != '\0') ++n;
  (void)!::write(g_err_fd.load(), t, n);
}

// Async-signal-safe: write(2) and _exit(2) only. Prints "octocd: stopped by SIG...",
// then `middle` and `what`, then "; <kept>" when set_stop_kept gave a text (else `tail`).
[[noreturn]] void exit_now(int sig, const char* middle, const char* what, const char* tail) {
  if (g_exiting.exchange(true))  // another thread is ending the process: its line, its _exit
    for (;;) ::pause();
  for (auto& c : g_children)
    if (const int group = c.load(); group > 0) ::kill(-group, SIGKILL);  // kill(2) is async-signal-safe
  remove_temporaries(false);
  put("octocd: stopped by ");
  put(sig == SIGINT ? "SIGINT" : sig == SIGTERM ? "SIGTERM" : "a signal");
  put(middle);
  put(what);
  if (const char* kept = g_kept.load()) {
    put("; ");
    put(kept);
    put("\n");
  } else {
    put(tail);
  }
  ::_exit(128 + sig);
}

// Async-signal-safe: ends the process (exit_now), or, with a kept reader set and not yet
// asked, hands the ending to its thread once and returns; after that returns until the
// reader's bound has passed, then ends the process with set_stop_kept's text.
void end_process(int sig, const char* middle, const char* what, const char* tail) {
  if (g_reader_on.load() && !g_reader_asked.exchange(true)) {
    std::size_t n = 0;
    while (what[n] != '\0' && n + 1 < sizeof g_pending_what) {
      g_pending_what[n] = what[n];
      ++n;
    }
    g_pending_what[n] = '\0';
    g_pending_sig.store(sig);
    g_pending_middle.store(middle);
    g_pending_tail.store(tail);
    g_reader_until_ns.store(now_ns() + g_reader_bound_ns.load());
    start_tick();
    const char b = 1;
    if (::write(g_wake[1], &b, 1) == 1) return;
  }
  if (g_reader_asked.load()) {
    if (now_ns() < g_reader_until_ns.load()) return;  // the reader still has time
    exit_now(g_pending_sig.load(), g_pending_middle.load(), g_pending_what, g_pending_tail.load());
  }
  exit_now(sig, middle, what, tail);
}

// SIGALRM, every 20 ms after the first signal: StopWithin's grace or the deadline ran out.
extern "C" void tick(int) {
  const int sig = g_signal.load();
  if (sig == 0) return;
  if (g_reader_asked.load()) return end_process(sig, "", "", "\n");  // the reader's bound
  const long long elapsed_us = (now_ns() - g_signal_ns.load()) / 1000;
  if (const char* what = g_within.load())
    if (elapsed_us >= g_grace_us.load()) return end_process(sig, " while ", what, "\n");
  const long deadline = g_deadline_us.load();
  if (deadline > 0 && elapsed_us >= deadline) end_process(sig, "", ": stopping took longer than its bound", "\n");
}

// The kept reader's thread (set_stop_kept_reader): waits for an ending handed over, asks
// the reader for the text and ends the process with it. Signals go to the other threads.
void reader_loop() {
  sigset_t block;
  sigemptyset(&block);
  sigaddset(&block, SIGINT);
  sigaddset(&block, SIGTERM);
  sigaddset(&block, SIGALRM);
  pthread_sigmask(SIG_BLOCK, &block, nullptr);
  char b = 0;
  for (;;) {
    const ssize_t n = ::read(g_wake[0], &b, 1);
    if (n == 1) break;
    if (n < 0 && errno == EINTR) continue;
    return;  // the pipe failed: the tick ends the process with set_stop_kept's text
  }
  std::string text;
  {
    const std::lock_guard<std::mutex> lock(g_reader_mu);
    try {
      if (g_reader) text = g_reader();
    } catch (...) {
      text.clear();
    }
  }
  if (!text.empty()) set_stop_kept(text);
  exit_now(g_pending_sig.load(), g_pending_middle.load(), g_pending_what, g_pending_tail.load());
}

extern "C" void record_signal(int sig) {
  if (const char* what = g_at_once.load()) exit_now(sig, " while ", what, "; nothing was written\n");
  g_count.fetch_add(1);
  int expected = 0;
  if (!g_signal.compare_exchange_strong(expected, sig)) {
    // A second signal while stopping: the user insists; the process ends now, saying
    // what it keeps (everything flushed before: a trace is readable at any instant),
    // unless the command answers it itself (SecondSignal::Recorded; the deadline holds).
    if (g_second_ends.load()) end_process(sig, " again", " while stopping", "\n");
    return;
  }
  g_signal_ns.store(now_ns());
  if (g_within.load() != nullptr || g_deadline_us.load() > 0) start_tick();
}

}  // namespace

int stop_signal() { return g_signal.load(std::memory_order_relaxed); }

int stop_signal_count() { return g_count.load(std::memory_order_relaxed); }

int stop_exit_code(int sig) { return 128 + sig; }

bool stop_track_temporary(const std::string& path, bool tracked) {
  if (path.empty() || path.size() >= sizeof g_temp_text[0]) return false;
  for (std::size_t k = 0; k < kTrackSlots; ++k) {
    if (tracked) {
      if (g_temp_on[k].load()) continue;
      std::memcpy(g_temp_text[k], path.c_str(), path.size() + 1);
      g_temp_on[k].store(true);
      return true;
    }
    if (g_temp_on[k].load() && path == g_temp_text[k]) {
      g_temp_on[k].store(false);
      return true;
    }
  }
  return false;
}

TrackedTemporary::TrackedTemporary(std::string path)
    : path_(std::move(path)), tracked_(stop_track_temporary(path_, true)) {}

TrackedTemporary::~TrackedTemporary() {
  if (tracked_) (void)stop_track_temporary(path_, false);
}

bool stop_track_child(int group, bool tracked) {
  if (group <= 0) return false;
  for (auto& c : g_children) {
    int expected = tracked ? 0 : group;
    if (c.compare_exchange_strong(expected, tracked ? group : 0)) return true;
  }
  return false;
}

void stop_clean_up() {
  for (auto& c : g_children)
    if (const int group = c.exchange(0); group > 0) ::kill(-group, SIGKILL);
  remove_temporaries(true);
}

const char* stop_signal_name(int sig) {
  switch (sig) {
    case SIGINT: return "SIGINT";
    case SIGTERM: return "SIGTERM";
    default: return "a signal";
  }
}

void set_stop_kept(const std::string& text) {
  if (text.empty()) {
    g_kept.store(nullptr);
    return;
  }
  const unsigned slot = (g_kept_slot.fetch_add(1) + 1) % kKeptSlots;
  const std::size_t n = std::min(text.size(), kKeptBytes - 1);
  std::memcpy(g_kept_text[slot], text.data(), n);
  g_kept_text[slot][n] = '\0';
  g_kept.store(g_kept_text[slot]);
}

void set_stop_kept_reader(std::function<std::string()> reader, double bound_s) {
  const std::lock_guard<std::mutex> lock(g_reader_mu);
  g_reader = std::move(reader);
  g_reader_bound_ns.store(std::max(1000000LL, static_cast<long long>(bound_s * 1e9)));
  if (g_reader && g_wake[0] < 0) {
    if (::pipe2(g_wake, O_CLOEXEC) != 0) {
      g_wake[0] = g_wake[1] = -1;
    } else {
      std::thread(reader_loop).detach();
    }
  }
  g_reader_on.store(static_cast<bool>(g_reader) && g_wake[0] >= 0);
}

StopOnSignals::StopOnSignals(double deadline_s, SecondSignal second) {
  if (const int fd = ::fcntl(2, F_DUPFD_CLOEXEC, 3); fd >= 0) g_err_fd.store(fd);
  g_reader_asked.store(false);
  g_signal.store(0);
  g_count.store(0);
  g_second_ends.store(second == SecondSignal::EndsAtOnce);
  g_kept.store(nullptr);
  g_deadline_us.store(deadline_s > 0.0 ? std::max(1L, static_cast<long>(deadline_s * 1e6)) : 0L);
  struct sigaction sa {};
  sa.sa_handler = record_signal;
  sigemptyset(&sa.sa_mask);
  sa.sa_flags = SA_RESTART;  // blocking reads and writes resume; the loop polls the flag
  sigaction(SIGINT, &sa, &g_old_int);
  sigaction(SIGTERM, &sa, &g_old_term);
  struct sigaction alrm {};
  alrm.sa_handler = tick;
  sigemptyset(&alrm.sa_mask);
  alrm.sa_flags = SA_RESTART;
  sigaction(SIGALRM, &alrm, &g_old_alrm);
}

StopWithin::StopWithin(std::string what, double grace_s) : what_(std::move(what)), grace_s_(grace_s) {
  g_grace_us.store(static_cast<long>(grace_s_ * 1e6) > 0 ? static_cast<long>(grace_s_ * 1e6) : 1);
  g_within.store(what_.c_str());
  if (g_signal.load() != 0) {  // recorded between the loop's poll and here: the grace starts now
    g_signal_ns.store(now_ns());
    start_tick();
  }
}

StopWithin::~StopWithin() {
  g_within.store(nullptr);
  if (g_deadline_us.load() == 0) stop_tick();  // a deadline keeps the tick running
}

StopAtOnce::StopAtOnce(const char* what) {
  g_at_once.store(what);
  if (const int sig = g_signal.load()) exit_now(sig, " while ", what, "; nothing was written\n");
}

StopAtOnce::~StopAtOnce() { g_at_once.store(nullptr); }

StopOnSignals::~StopOnSignals() {
  set_stop_kept_reader({});
  stop_tick();
  g_deadline_us.store(0);
  g_kept.store(nullptr);
  g_second_ends.store(true);
  sigaction(SIGINT, &g_old_int, nullptr);
  sigaction(SIGTERM, &g_old_term, nullptr);
  sigaction(SIGALRM, &g_old_alrm, nullptr);
  if (const int fd = g_err_fd.exchange(2); fd != 2) ::close(fd);
}

}  // namespace octocd
