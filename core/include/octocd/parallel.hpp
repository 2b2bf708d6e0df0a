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
/// (std::merge, each round's merges on the team). The order std::sort gives wherever no two
/// elements are equivalent (the broadphases and validators sort distinct pairs and cell
/// entries), whatever the thread count. T copyable and default-constructible.
template <class T, class Less>
void parallel_sort(std::vector<T>& v, unsigned threads, Less less) {
  const std::size_t n = v.size();
  if (threads <= 1 || n < 4096) {
    std::sort(v.begin(), v.end(), less);
    return;
  }
  auto at = [](std::vector<T>& x, std::size_t k) { return x.begin() + std::ptrdiff_t(k); };
  std::vector<std::size_t> bound(threads + 1);  // run k is [bound[k], bound[k + 1])
  for (unsigned k = 0; k <= threads; ++k) bound[k] = n * k / threads;
  LoopOptions one_each;
  one_each.threads = static_cast<int>(threads);
  one_each.chunk = 1;
  parallel_for(threads, one_each, [&](std::size_t k, unsigned) { std::sort(at(v, bound[k]), at(v, bound[k + 1]), less); });
  std::vector<T> merged(n);
  while (bound.size() > 2) {
    const std::size_t runs = bound.size() - 1, merges = (runs + 1) / 2;
    parallel_for(merges, one_each, [&](std::size_t j, unsigned) {
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
