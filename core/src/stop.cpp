/// \file stop.cpp
/// SIGINT/SIGTERM recorded in a lock-free atomic, polled by the commands' loops.

#include "octocd/stop.hpp"

#include <signal.h>

#include <atomic>

namespace octocd {
namespace {

std::atomic<int> g_signal{0};
static_assert(std::atomic<int>::is_always_lock_free, "the handler needs a lock-free flag");

struct sigaction g_old_int, g_old_term;

extern "C" void record_signal(int sig) {
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

StopOnSignals::~StopOnSignals() {
  sigaction(SIGINT, &g_old_int, nullptr);
  sigaction(SIGTERM, &g_old_term, nullptr);
}

}  // namespace octocd
