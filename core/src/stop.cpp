/// \file stop.cpp
/// SIGINT/SIGTERM recorded in a lock-free atomic, polled by the commands' loops.

#include "octocd/stop.hpp"

#include <signal.h>
#include <sys/time.h>
#include <unistd.h>

#include <cstddef>

#include <atomic>
#include <string>
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
std::atomic<bool> g_armed{false};            // the grace timer runs

// Async-signal-safe: setitimer is a plain system call.
void arm_grace() {
  const long us = g_grace_us.load();
  itimerval t{};
  t.it_value.tv_sec = us / 1000000;
  t.it_value.tv_usec = us % 1000000;
  g_armed.store(true);
  ::setitimer(ITIMER_REAL, &t, nullptr);
}

// Async-signal-safe: write(2) and _exit(2) only. `tail` follows `what`.
void exit_now(int sig, const char* what, const char* tail = "; nothing was written\n") {
  const auto put = [](const char* t) {
    std::size_t n = 0;
    while (t[n] != '\0') ++n;
    (void)!::write(2, t, n);
  };
  put("octocd: stopped by ");
  put(sig == SIGINT ? "SIGINT" : sig == SIGTERM ? "SIGTERM" : "a signal");
  put(" while ");
  put(what);
  put(tail);
  ::_exit(128 + sig);
}

// SIGALRM: the grace of a StopWithin ran out while it is still alive.
extern "C" void grace_over(int) {
  const int sig = g_signal.load();
  if (const char* what = g_within.load())
    if (sig != 0) exit_now(sig, what, "\n");
}

extern "C" void record_signal(int sig) {
  if (const char* what = g_at_once.load()) exit_now(sig, what);
  int expected = 0;
  if (!g_signal.compare_exchange_strong(expected, sig)) {
    // A second signal while stopping: the user insists. Default action (ends the process).
    ::signal(sig, SIG_DFL);
    ::raise(sig);
  }
  if (g_within.load() != nullptr) arm_grace();
}

}  // namespace

int stop_signal() { return g_signal.load(std::memory_order_relaxed); }

int stop_exit_code(int sig) { return 128 + sig; }

const char* stop_signal_name(int sig) {
  switch (sig) {
    case SIGINT: return "SIGINT";
    case SIGTERM: return "SIGTERM";
    default: return "a signal";
  }
}

StopOnSignals::StopOnSignals() {
  g_signal.store(0);
  struct sigaction sa {};
  sa.sa_handler = record_signal;
  sigemptyset(&sa.sa_mask);
  sa.sa_flags = SA_RESTART;  // blocking reads and writes resume; the loop polls the flag
  sigaction(SIGINT, &sa, &g_old_int);
  sigaction(SIGTERM, &sa, &g_old_term);
  struct sigaction alrm {};
  alrm.sa_handler = grace_over;
  sigemptyset(&alrm.sa_mask);
  alrm.sa_flags = SA_RESTART;
  sigaction(SIGALRM, &alrm, &g_old_alrm);
}

StopWithin::StopWithin(std::string what, double grace_s) : what_(std::move(what)), grace_s_(grace_s) {
  g_grace_us.store(static_cast<long>(grace_s_ * 1e6) > 0 ? static_cast<long>(grace_s_ * 1e6) : 1);
  g_within.store(what_.c_str());
  if (g_signal.load() != 0) arm_grace();  // recorded between the loop's poll and here
}

StopWithin::~StopWithin() {
  g_within.store(nullptr);
  if (g_armed.exchange(false)) {
    const itimerval off{};
    ::setitimer(ITIMER_REAL, &off, nullptr);
  }
}

StopAtOnce::StopAtOnce(const char* what) {
  g_at_once.store(what);
  if (const int sig = g_signal.load()) exit_now(sig, what);
}

StopAtOnce::~StopAtOnce() { g_at_once.store(nullptr); }

StopOnSignals::~StopOnSignals() {
  sigaction(SIGINT, &g_old_int, nullptr);
  sigaction(SIGTERM, &g_old_term, nullptr);
  sigaction(SIGALRM, &g_old_alrm, nullptr);
}

}  // namespace octocd
