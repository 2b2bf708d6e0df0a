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

/// std::sort of `v` by `less` on `threads` threads (at least 4,096 elements; fewer are
/// sorted on the calling thread): `threads` chunks sorted on threads, then merged pairwise
/// (std::merge, each round's merges on threads). The order std::sort gives wherever no
/// two elements are equivalent (the validators sort distinct pairs and cell entries).
template <class T, class Less>
void parallel_sort(std::vector<T>& v, unsigned threads, Less less) {
  const std::size_t n = v.size();
  if (threads <= 1 || n < 4096) {
    std::sort(v.begin(), v.end(), less);
    return;
  }
  const std::function<bool()> never;
  auto at = [&](std::vector<T>& x, std::size_t k) { return x.begin() + std::ptrdiff_t(k); };
  std::vector<std::size_t> bound(threads + 1);  // run k is [bound[k], bound[k + 1])
  for (unsigned k = 0; k <= threads; ++k) bound[k] = n * k / threads;
  parallel_items_on(threads, threads, never,
                    [&](std::size_t k, unsigned) { std::sort(at(v, bound[k]), at(v, bound[k + 1]), less); });
  std::vector<T> merged(n);
  while (bound.size() > 2) {
    const std::size_t runs = bound.size() - 1, merges = (runs + 1) / 2;
    parallel_items_on(merges, static_cast<unsigned>(std::min<std::size_t>(threads, merges)), never,
                      [&](std::size_t j, unsigned) {
      const std::size_t first = bound[2 * j], mid = bound[std::min(2 * j + 1, runs)],
                        last = bound[std::min(2 * j + 2, runs)];
      std::merge(at(v, first), at(v, mid), at(v, mid), at(v, last), at(merged, first), less);
    });
    v.swap(merged);
    std::vector<std::size_t> next;
    for (std::size_t k = 0; k < bound.size(); k += 2) next.push_back(bound[k]);
    if (next.back() != n) next.push_back(n);
    bound.swap(next);
  }
}

}  // namespace octocd
