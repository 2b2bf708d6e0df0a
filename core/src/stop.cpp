/// \file stop.cpp
/// SIGINT/SIGTERM recorded in a lock-free atomic, polled by the commands' loops.

#include "octocd/stop.hpp"

#include <signal.h>
#include <unistd.h>

#include <cstddef>

#include <atomic>

namespace octocd {
namespace {

std::atomic<int> g_signal{0};
static_assert(std::atomic<int>::is_always_lock_free, "the handler needs a lock-free flag");

struct sigaction g_old_int, g_old_term;
std::atomic<const char*> g_at_once{nullptr};  // StopAtOnce's phrase while one is alive
static_assert(std::atomic<const char*>::is_always_lock_free, "the handler needs a lock-free pointer");

// Async-signal-safe: write(2) and _exit(2) only.
void exit_now(int sig, const char* what) {
  const auto put = [](const char* t) {
    std::size_t n = 0;
    while (t[n] != '\0') ++n;
    (void)!::write(2, t, n);
  };
  put("octocd: stopped by ");
  put(sig == SIGINT ? "SIGINT" : sig == SIGTERM ? "SIGTERM" : "a signal");
  put(" while ");
  put(what);
  put("; nothing was written\n");
  ::_exit(128 + sig);
}

extern "C" void record_signal(int sig) {
  if (const char* what = g_at_once.load()) exit_now(sig, what);
  int expected = 0;
  if (!g_signal.compare_exchange_strong(expected, sig)) {
    // A second signal while stopping: the user insists. Default action (ends the process).
    ::signal(sig, SIG_DFL);
    ::raise(sig);
  }
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
}

StopAtOnce::StopAtOnce(const char* what) {
  g_at_once.store(what);
  if (const int sig = g_signal.load()) exit_now(sig, what);
}

StopAtOnce::~StopAtOnce() { g_at_once.store(nullptr); }

StopOnSignals::~StopOnSignals() {
  sigaction(SIGINT, &g_old_int, nullptr);
  sigaction(SIGTERM, &g_old_term, nullptr);
}

}  // namespace octocd
