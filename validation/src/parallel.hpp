#pragma once
/// \file parallel.hpp
/// The validators' loop over independent items on threads (internal to
/// octocd_validation). Items write only their own slot of a result vector; the rows tally
/// those slots afterwards in item order, so a verdict never depends on the thread count.
///
/// Plain std::threads that take chunks of items from an atomic counter and are joined at
/// the end: no thread spins while it waits (OpenMP's barriers spin, which on a loaded
/// machine (load 10 on 2 cores) made a 0.16 s frame take 3 s).

#include <algorithm>
#include <atomic>
#include <cstddef>
#include <exception>
#include <functional>
#include <mutex>
#include <thread>
#include <vector>

#include "octocd/validation.hpp"

namespace octocd {

/// Threads a loop of `items` items uses: `threads` (> 0) or the hardware's threads
/// (0), one below `serial_below` items; never more than the items.
inline unsigned loop_threads(int threads, std::size_t items, std::size_t serial_below = 64) {
  if (items < serial_below) return 1;
  const unsigned hw = std::max(1u, std::thread::hardware_concurrency());
  const unsigned want = threads > 0 ? static_cast<unsigned>(threads) : hw;
  return static_cast<unsigned>(std::min<std::size_t>(want, items));
}

/// Calls body(i, worker) for every i in [0, n) on `threads` threads (loop_threads; worker
/// in [0, threads) names the thread, for per-thread scratch). The calling thread is worker
/// 0 and polls `stop` (may be empty) between its chunks; a stop skips the items not
/// started and throws ValidationStopped after every thread is joined. The first
/// exception thrown by `body` is rethrown after the join.
template <class F>
void parallel_items_on(std::size_t n, unsigned threads, const std::function<bool()>& stop, F&& body) {
  if (threads <= 1) {
    unsigned polls = 0;
    for (std::size_t i = 0; i < n; ++i) {
      if ((++polls & 15u) == 0 && stop && stop()) throw ValidationStopped();
      body(i, 0u);
    }
    return;
  }
  std::atomic<std::size_t> next{0};
  std::atomic<bool> cancel{false};
  std::exception_ptr error;
  std::mutex error_mutex;
  const std::size_t chunk = std::max<std::size_t>(1, std::min<std::size_t>(64, n / (threads * 8)));
  auto work = [&](unsigned worker) {
    for (;;) {
      if (cancel.load(std::memory_order_relaxed)) return;
      if (worker == 0 && stop && stop()) {
        cancel.store(true);
        return;
      }
      const std::size_t first = next.fetch_add(chunk);
      if (first >= n) return;
      const std::size_t last = std::min(n, first + chunk);
      try {
        for (std::size_t i = first; i < last; ++i) body(i, worker);
      } catch (...) {
        const std::lock_guard<std::mutex> lock(error_mutex);
        if (!error) error = std::current_exception();
        cancel.store(true);
        return;
      }
    }
  };
  std::vector<std::thread> pool;
  pool.reserve(threads - 1);
  for (unsigned w = 1; w < threads; ++w) pool.emplace_back(work, w);
  work(0);
  for (std::thread& t : pool) t.join();
  if (error) std::rethrow_exception(error);
  if (cancel.load()) throw ValidationStopped();
}

/// parallel_items_on with loop_threads(threads, n) threads (`threads` 0: the hardware's).
template <class F>
void parallel_items(std::size_t n, int threads, const std::function<bool()>& stop, F&& body) {
  parallel_items_on(n, loop_threads(threads, n), stop, std::forward<F>(body));
}

}  // namespace octocd
