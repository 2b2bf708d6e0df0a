#pragma once
/// \file parallel.hpp
/// The validators' loop over independent items on OpenMP threads (internal to
/// octocd_validation). Items write only their own slot of a result vector; the rows tally
/// those slots afterwards in item order, so a verdict never depends on the thread count.

#include <omp.h>

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <exception>
#include <functional>
#include <mutex>

#include "octocd/validation.hpp"

namespace octocd {

/// Calls body(i) for every i in [0, n) on OpenMP's threads (dynamic schedule; one thread
/// below 64 items). The calling thread polls `stop` (may be empty) every 16 of its items;
/// a stop skips the items not started and throws ValidationStopped after the loop. The
/// first exception thrown by `body` (in time) is rethrown after the loop.
template <class F>
void parallel_items(std::size_t n, const std::function<bool()>& stop, F&& body) {
  std::atomic<bool> cancel{false};
  std::exception_ptr error;
  std::mutex error_mutex;
  const std::int64_t count = static_cast<std::int64_t>(n);
  const int threads = n < 64 ? 1 : omp_get_max_threads();
  unsigned polls = 0;
#pragma omp parallel for schedule(dynamic, 4) num_threads(threads)
  for (std::int64_t i = 0; i < count; ++i) {
    if (cancel.load(std::memory_order_relaxed)) continue;
    if (omp_get_thread_num() == 0 && (++polls & 15u) == 0 && stop && stop()) {
      cancel.store(true);
      continue;
    }
    try {
      body(static_cast<std::size_t>(i));
    } catch (...) {
      const std::lock_guard<std::mutex> lock(error_mutex);
      if (!error) error = std::current_exception();
      cancel.store(true);
    }
  }
  if (error) std::rethrow_exception(error);
  if (cancel.load()) throw ValidationStopped();
}

}  // namespace octocd
