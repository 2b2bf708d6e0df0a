#pragma once
// The judging of `octocd validate` on a thread of its own (validate_parts.hpp), so that the main
// thread answers a signal within kValidateStopGrace while a step of a big scene takes seconds:
// the worker, the verdict it has judged so far, and its progress lines.
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <functional>
#include <mutex>
#include <optional>
#include <thread>
#include <utility>
#include <vector>

#include "octocd/stop.hpp"
#include "octocd/validation.hpp"
#include "command_support.hpp"

namespace octocd::cli {

/// How long the main thread of `validate` waits for the judging worker to stop after a
/// signal before it reports the verdict of the frames judged so far without it. The bound
/// cuts the judging, never the writing of what was judged: the verdict is then written
/// whatever time that takes (no process deadline).
inline constexpr std::chrono::milliseconds kValidateStopGrace{450};
/// The verdict of the frames judged so far (ValidationOptions::on_judged's latest rows),
/// kept by the judging worker, read by the main thread when a step outlasts the grace.
class JudgedSoFar {
 public:
  void keep(const std::vector<octocd::ValidationResult>& rows, std::int64_t judged) {
    const std::lock_guard<std::mutex> lock(m_);
    rows_ = rows;
    judged_ = judged;
  }
  std::pair<std::vector<octocd::ValidationResult>, std::int64_t> get() const {
    const std::lock_guard<std::mutex> lock(m_);
    return {rows_, judged_};
  }

 private:
  mutable std::mutex m_;
  std::vector<octocd::ValidationResult> rows_;
  std::int64_t judged_ = 0;
};

/// Progress of a long judging on stderr: "validate: judged frame N of M (R frames/s)",
/// the first after 2 s of judging and then every 2 s (a judging that ends sooner prints
/// none). R: the frames judged since the first call over the seconds since it.
class JudgingProgress {
 public:
  void tick(std::int64_t judged_to, std::int64_t frames) {
    const auto now = Clock::now();
    if (!start_) {
      start_ = now;
      first_ = judged_to;
      last_ = now;
      return;
    }
    if (now - last_ < std::chrono::seconds(2)) return;
    last_ = now;
    const double s = std::chrono::duration<double>(now - *start_).count();
    std::fprintf(stderr, "validate: judged frame %lld of %lld (%.2f frames/s)\n", static_cast<long long>(judged_to),
                 static_cast<long long>(frames), s > 0 ? double(judged_to - first_) / s : 0.0);
  }

 private:
  std::optional<Clock::time_point> start_;
  Clock::time_point last_;
  std::int64_t first_ = 0;
};

/// Waits until `done` (set under `m`, `cv` notified) and returns true, or returns false
/// once a signal has waited kValidateStopGrace for it, or at once on a second signal.
inline bool wait_for_worker(std::mutex& m, std::condition_variable& cv, const bool& done) {
  std::unique_lock<std::mutex> lock(m);
  std::optional<Clock::time_point> first;
  for (;;) {
    if (cv.wait_for(lock, std::chrono::milliseconds(10), [&] { return done; })) return true;
    if (octocd::stop_signal() == 0) continue;
    const auto now = Clock::now();
    if (!first) first = now;
    if (octocd::stop_signal_count() > 1 || now - *first >= kValidateStopGrace) return false;
  }
}

/// Ends the process with `code` at once (stdout and stderr flushed), without waiting for a
/// worker thread that a stop left running.
[[noreturn]] inline void end_without_worker(int code) {
  std::fflush(stdout);
  std::fflush(stderr);
  std::_Exit(code);
}

/// A job on its own thread, so that the main thread answers a signal within
/// kValidateStopGrace while the job runs (a step of a big scene may take seconds): wait()
/// as wait_for_worker, join() rethrows what the job threw.
class Worker {
 public:
  explicit Worker(std::function<void()> job)
      : thread_([this, job = std::move(job)] {
          try {
            job();
          } catch (...) {
            error_ = std::current_exception();
          }
          const std::lock_guard<std::mutex> lock(m_);
          done_ = true;
          cv_.notify_all();
        }) {}
  /// True once the job finished; false once a stop outlasted the grace (the job may still run).
  bool wait() { return wait_for_worker(m_, cv_, done_); }
  /// Joins the finished job and rethrows what it threw, if anything.
  void join() {
    thread_.join();
    if (error_) std::rethrow_exception(error_);
  }

 private:
  std::mutex m_;
  std::condition_variable cv_;
  bool done_ = false;
  std::exception_ptr error_;
  std::thread thread_;  // last: the job starts once the members above exist
};

}  // namespace octocd::cli
