#pragma once
/// \file parallel.hpp
/// The validators' loop over independent items on threads (internal to
/// octocd_validation). Items write only their own slot of a result vector; the rows tally
/// those slots afterwards in item order, so a verdict never depends on the thread count.
///
/// The loops run on the process's worker team (octocd/parallel.hpp): workers that sleep
/// while idle (no spinning wait; OpenMP's barriers spin, which on a loaded machine (load
/// 10 on 2 cores) made a 0.16 s frame take 3 s), items claimed in chunks from an atomic
/// counter, the calling thread working too.

#include <algorithm>
#include <cstddef>
#include <functional>
#include <vector>

#include "octocd/parallel.hpp"
#include "octocd/validation.hpp"

namespace octocd {

/// Threads a loop of `items` items uses: `threads` (> 0) or current_threads() (0: the
/// CPU engine's default, OMP_NUM_THREADS or the CPUs this process may run on), one below
/// `serial_below` items or inside another loop's item; never more than the items.
inline unsigned loop_threads(int threads, std::size_t items, std::size_t serial_below = 64) {
  LoopOptions o;
  o.threads = threads;
  o.min_items = serial_below;
  return loop_threads(items, o);
}

/// Calls body(i, worker) for every i in [0, n) on at most `threads` threads (loop_threads;
/// worker in [0, threads) names the thread, for per-thread scratch). The calling thread is
/// worker 0 and polls `stop` (may be empty) between its chunks; a stop skips the items not
/// started and throws ValidationStopped once every worker has left the loop. The first
/// exception thrown by `body` is rethrown likewise. Items are claimed in chunks of about an
/// eighth of a thread's share, at most 64 items up to 4,096 items a thread and a 64th of the
/// share above.
template <class F>
void parallel_items_on(std::size_t n, unsigned threads, const std::function<bool()>& stop, F&& body) {
  LoopOptions o;
  o.threads = static_cast<int>(std::max(1u, threads));
  // Items per claim: about an eighth of a thread's even share, at most 64 up to 64 x 64 items
  // a thread, then a 64th of the share (a claim is one atomic add on a counter the threads
  // share: at 10^6 cheap items and 16 threads, 64 a claim made 15,600 of them a pass).
  const std::size_t share = n / std::max(1u, threads);
  o.chunk = threads <= 1 ? 16 : std::max<std::size_t>(1, std::min(std::max<std::size_t>(64, share / 64), share / 8));
  o.stop = stop;
  if (!parallel_for(n, o, std::forward<F>(body))) throw ValidationStopped();
}

/// parallel_items_on with loop_threads(threads, n) threads (`threads` 0: the hardware's).
template <class F>
void parallel_items(std::size_t n, int threads, const std::function<bool()>& stop, F&& body) {
  parallel_items_on(n, loop_threads(threads, n), stop, std::forward<F>(body));
}

/// Calls body(first, last) for contiguous ranges that cover [0, n), about 8 a thread, on
/// `threads` threads: for loops of cheap items (a few memory accesses each), where a call
/// of the body per item and the claims cost more than the items (claims of 64 items made
/// 15,600 atomic adds on one counter a pass at 10^6 items and 16 threads). One thread:
/// body(0, n). `stop` as parallel_items_on, polled between ranges.
template <class F>
void parallel_ranges(std::size_t n, unsigned threads, const std::function<bool()>& stop, F&& body) {
  if (threads <= 1 || n < 2) {
    if (stop && stop()) throw ValidationStopped();
    body(std::size_t(0), n);
    return;
  }
  const std::size_t ranges = std::min<std::size_t>(n, std::size_t(threads) * 8);
  parallel_items_on(ranges, threads, stop,
                    [&](std::size_t r, unsigned) { body(n * r / ranges, n * (r + 1) / ranges); });
}

/// The fewest items parallel_select runs on threads (two passes of a few instructions an
/// item: below this one thread costs less than waking another).
constexpr std::size_t kParallelSelectFrom = 8192;

/// `out` = value(i) for every i in [0, n) with keep(i), in i order, on `threads` threads
/// (keep and value called once per item, from any thread): the items counted per block,
/// then each block written at its offset (`out` resized, not cleared first: only entries
/// past its old size are value-initialised before they are written). One thread, or fewer
/// than kParallelSelectFrom items: the plain loop. `stop` as parallel_items_on
/// (ValidationStopped; `out` then holds no meaning). T default-constructible.
template <class T, class Keep, class Value>
void parallel_select(std::size_t n, std::vector<T>& out, unsigned threads, const std::function<bool()>& stop,
                     Keep&& keep, Value&& value) {
  if (threads <= 1 || n < kParallelSelectFrom) {
    out.clear();
    for (std::size_t i = 0; i < n; ++i)
      if (keep(i)) out.push_back(value(i));
    return;
  }
  const std::size_t blocks = std::size_t(threads) * 8;
  std::vector<std::size_t> offset(blocks + 1, 0);
  std::vector<char> kept(n);
  auto first = [&](std::size_t b) { return n * b / blocks; };
  parallel_items_on(blocks, threads, stop, [&](std::size_t b, unsigned) {
    std::size_t c = 0;
    for (std::size_t i = first(b); i < first(b + 1); ++i) c += (kept[i] = keep(i) ? 1 : 0);
    offset[b + 1] = c;
  });
  for (std::size_t b = 0; b < blocks; ++b) offset[b + 1] += offset[b];
  out.resize(offset[blocks]);
  parallel_items_on(blocks, threads, stop, [&](std::size_t b, unsigned) {
    std::size_t k = offset[b];
    for (std::size_t i = first(b); i < first(b + 1); ++i)
      if (kept[i]) out[k++] = value(i);
  });
}

}  // namespace octocd
