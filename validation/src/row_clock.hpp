#pragma once
/// \file row_clock.hpp
/// Per-row timing and stop polling inside the validators (internal to octocd_validation):
/// RowClock adds its scope's steady_clock time to a row's seconds (JUnit's per-testcase
/// time); StopPoll polls ValidationOptions::stop every 16th item of a long loop.

#include <chrono>
#include <functional>

#include "octocd/validation.hpp"

namespace octocd {

/// Adds the std::chrono::steady_clock time from construction to destruction to `seconds`.
class RowClock {
 public:
  explicit RowClock(double& seconds) : seconds_(seconds), t0_(std::chrono::steady_clock::now()) {}
  ~RowClock() { seconds_ += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0_).count(); }
  RowClock(const RowClock&) = delete;
  RowClock& operator=(const RowClock&) = delete;

 private:
  double& seconds_;
  std::chrono::steady_clock::time_point t0_;
};

/// Polls `stop` (may be empty: never stops) on every 16th call and throws
/// ValidationStopped when it returns true. A poll costs one atomic load (stop_signal), so
/// 16 items of the costliest loop (FCL on a mesh pair, the exhaustive vertex test) keep
/// the answer well within a second.
class StopPoll {
 public:
  explicit StopPoll(const std::function<bool()>& stop) : stop_(stop) {}
  void operator()() {
    if ((++count_ & 15u) == 0 && stop_ && stop_()) throw ValidationStopped();
  }
  /// Polls now, whatever the count.
  void now() const {
    if (stop_ && stop_()) throw ValidationStopped();
  }

 private:
  const std::function<bool()>& stop_;
  unsigned count_ = 0;
};

}  // namespace octocd
