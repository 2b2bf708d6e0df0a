#pragma once
/// \file parallel.hpp
/// The process's one team of worker threads, which the CPU engine's stages, `run --worlds`
/// and the validators share (design.md section 4; issue 77 item 1: threads that never slow
/// a busy machine).
///
/// - Workers are started on first use and BLOCK on a condition variable while idle: no
///   spinning wait takes a core that other processes need.
/// - A loop's items are claimed in chunks from an atomic counter. The calling thread works
///   through them too, so a worker that the scheduler has not run yet is simply never
///   waited for: the caller then does every item itself and only waits for workers that
///   claimed a chunk and are still in it.
/// - Each item writes its own result (its own slot of an output, or per-worker scratch
///   merged in a fixed order afterwards), so results never depend on the thread count.
/// - A loop started inside another loop's item (e.g. a copy of `run --worlds` stepping on
///   a worker), or while the team runs another caller's loop, runs serially on its caller.
/// - A loop runs in parallel only from `min_items` items on, a threshold each call site
///   sets from its measured cost (fewer items are cheaper on one thread than a wake-up).
/// - Whether a loop that may use the team does is measured while the process runs
///   (core/src/loop_tuner.hpp, design.md section 4): a short probe runs loops on the team
///   and on their caller alone in turn, and the way whose loops get the process more CPU
///   per second holds for the next second (beside one busy process on two cores a woken
///   worker shares its caller's core, and the caller alone is faster).
///
/// The thread count is a setting: the CPU engine's `threads` (docs/settings.md),
/// `validate --threads`, `run --threads` for `--worlds`. 0 everywhere means
/// default_threads(): `OMP_NUM_THREADS` when set to a positive integer (kept for users of
/// the OpenMP build, which honoured it), else the CPUs this process may run on
/// (sched_getaffinity).

#include <algorithm>
#include <cstddef>
#include <functional>
#include <memory>
#include <type_traits>
#include <vector>

namespace octocd {

/// The threads a loop uses when nobody chose a count: OMP_NUM_THREADS when it holds a
/// positive integer, else the CPUs in this process's affinity mask (sched_getaffinity;
/// std::thread::hardware_concurrency where that fails); at least 1. Read once.
int default_threads();

/// The thread count of loops started by the calling thread: the innermost ThreadCount
/// scope's, else default_threads(). Inside a loop's item it is 1 (nested loops are serial).
int current_threads();

/// Sets current_threads() of the calling thread for its lifetime (`n` 0: default_threads()),
/// then restores the previous value. Used by an engine's step (its `threads` setting) and by
/// callers that run an engine at a chosen count (`validate --determinism`, tests).
class ThreadCount {
 public:
  explicit ThreadCount(int n);
  ~ThreadCount();
  ThreadCount(const ThreadCount&) = delete;
  ThreadCount& operator=(const ThreadCount&) = delete;

 private:
  int saved_;
};

/// How a loop is split: `threads` (0: current_threads()), the fewest items that run in
/// parallel (`min_items`; fewer run on the caller), items per claim (`chunk`; 0: about an
/// eighth of an even share, 1..64), and a stop poll (`stop`, may be empty) that the caller
/// calls between its chunks.
struct LoopOptions {
  int threads = 0;
  std::size_t min_items = 2;
  std::size_t chunk = 0;
  std::function<bool()> stop;
};

/// The chunk body of parallel_chunks: items [first, last) on worker `worker`.
using ChunkBody = std::function<void(std::size_t first, std::size_t last, unsigned worker)>;

/// Runs body over [0, n) in chunks; `worker` is in [0, the loop's threads) and names the
/// thread (0: the caller) for per-thread scratch, no two chunks at once on one number.
/// Returns false when `stop` returned true (items not started are skipped; the ones
/// started finish), true when every item ran. The first exception thrown by `body` is
/// rethrown after every worker has left the loop (the remaining items are skipped).
/// The loop's threads: min(options' threads, n), 1 below min_items items, inside
/// another loop's item, while the team runs another caller's loop, or while the tuner
/// (above) runs loops on their callers alone.
bool parallel_chunks(std::size_t n, const LoopOptions& options, const ChunkBody& body);

/// parallel_chunks with body(i, worker) called for each item i.
template <class F>
bool parallel_for(std::size_t n, const LoopOptions& options, F&& body) {
  return parallel_chunks(n, options, [&body](std::size_t first, std::size_t last, unsigned worker) {
    for (std::size_t i = first; i < last; ++i) body(i, worker);
  });
}

/// The most threads parallel_chunks uses for a loop of `n` items with these options (it
/// may use fewer: a busy team, a nested loop); worker numbers stay below it. For sizing
/// per-worker scratch before the loop.
unsigned loop_threads(std::size_t n, const LoopOptions& options);

/// std::sort of `v` by `less` on `threads` threads (at least 4,096 elements; fewer are
/// sorted on the calling thread): `threads` chunks sorted on the team, then merged pairwise
/// in rounds, each round's merges split on the team by merge paths (the two runs cut where
/// `threads` equal shares of the output begin: each share is std::merge of its two cuts, so
/// a round writes what one std::merge per pair of runs would). The order std::sort gives
/// wherever no two elements are equivalent (the broadphases and validators sort distinct
/// pairs and cell entries), whatever the thread count. T trivially copyable: the merges'
/// second buffer is left uninitialised until they write it.
template <class T, class Less>
void parallel_sort(std::vector<T>& v, unsigned threads, Less less) {
  static_assert(std::is_trivially_copyable_v<T> && std::is_trivially_destructible_v<T>,
                "parallel_sort's merge buffer holds T without constructing it");
  const std::size_t n = v.size();
  if (threads <= 1 || n < 4096) {
    std::sort(v.begin(), v.end(), less);
    return;
  }
  std::vector<std::size_t> bound(threads + 1);  // run k is [bound[k], bound[k + 1])
  for (unsigned k = 0; k <= threads; ++k) bound[k] = n * k / threads;
  LoopOptions one_each;
  one_each.threads = static_cast<int>(threads);
  one_each.chunk = 1;
  T* const data = v.data();
  parallel_for(threads, one_each, [&](std::size_t k, unsigned) { std::sort(data + bound[k], data + bound[k + 1], less); });
  std::allocator<T> alloc;
  struct Buffer {
    std::allocator<T>& alloc;
    T* p;
    std::size_t n;
    ~Buffer() { alloc.deallocate(p, n); }
  } buffer{alloc, alloc.allocate(n), n};
  T* src = data;
  T* dst = buffer.p;
  // The count of A's elements among the first d of merge(A, B): std::merge takes B's
  // element only when it is less than A's.
  auto cut = [&](const T* a, std::size_t na, const T* b, std::size_t nb, std::size_t d) {
    std::size_t lo = d > nb ? d - nb : 0, hi = std::min(d, na);
    while (lo < hi) {
      const std::size_t i = lo + (hi - lo) / 2;
      if (!less(b[d - i - 1], a[i]))
        lo = i + 1;
      else
        hi = i;
    }
    return lo;
  };
  while (bound.size() > 2) {
    const std::size_t runs = bound.size() - 1, merges = (runs + 1) / 2;
    const std::size_t shares = std::max<std::size_t>(1, threads / merges);
    parallel_for(merges * shares, one_each, [&](std::size_t t, unsigned) {
      const std::size_t j = t / shares, s = t % shares;
      const std::size_t first = bound[2 * j], mid = bound[std::min(2 * j + 1, runs)],
                        last = bound[std::min(2 * j + 2, runs)];
      const T* a = src + first;
      const T* b = src + mid;
      const std::size_t na = mid - first, nb = last - mid;
      const std::size_t d0 = (na + nb) * s / shares, d1 = (na + nb) * (s + 1) / shares;
      const std::size_t i0 = cut(a, na, b, nb, d0), i1 = cut(a, na, b, nb, d1);
      std::merge(a + i0, a + i1, b + (d0 - i0), b + (d1 - i1), dst + first + d0, less);
    });
    std::swap(src, dst);
    std::vector<std::size_t> next;
    for (std::size_t k = 0; k < bound.size(); k += 2) next.push_back(bound[k]);
    if (next.back() != n) next.push_back(n);
    bound.swap(next);
  }
  if (src != data)
    parallel_for(threads, one_each, [&](std::size_t k, unsigned) {
      std::copy(src + n * k / threads, src + n * (k + 1) / threads, data + n * k / threads);
    });
}

}  // namespace octocd
