/// \file parallel.cpp
/// The worker team of octocd/parallel.hpp: threads started on first use that sleep on a
/// condition variable between loops; a loop is published under the team's mutex, workers
/// join it (at most the loop's threads - 1) and claim chunks from its atomic counter; the
/// caller closes the loop once its own claims run dry, so no worker joins afterwards, and
/// waits only for the workers that joined: first for at most kCallerSpin on a
/// lock-free count (a worker in its last chunk on another core is done within
/// microseconds, sooner than a sleeping caller is woken), then asleep. Whether a loop
/// runs on the team at all is the LoopTuner's measured choice (loop_tuner.hpp).

#include "octocd/parallel.hpp"

#include <time.h>

#include <sched.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdint>
#include <condition_variable>
#include <cstdlib>
#include <exception>
#include <mutex>
#include <thread>
#include <vector>

#include "loop_tuner.hpp"

namespace octocd {

namespace {

/// How long a caller whose chunks ran dry waits on a lock-free count for the workers
/// still in a chunk before it sleeps. bunny-random-400, 2 threads, this VM (AMD EPYC,
/// 2 cores): the loops' ends 1 us (median) and 52 us (99th percentile) after the caller's;
/// a sleeping caller is woken 10-60 us after the last worker leaves.
constexpr auto kCallerSpin = std::chrono::microseconds(30);

/// A spin-wait hint to the core (x86 `pause`; nothing elsewhere).
inline void cpu_relax() {
#if defined(__x86_64__) || defined(__i386__)
  __builtin_ia32_pause();
#endif
}

/// Seconds on the steady clock, and CPU seconds of the whole process (all threads).
double seconds_now() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}
double process_cpu_seconds() {
  timespec ts{};
  if (clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts) != 0) return 0.0;
  return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
}

/// 0: no ThreadCount scope on this thread. -1: inside a loop's item (loops are serial).
thread_local int tls_threads = 0;
constexpr int kInsideLoop = -1;

/// One published loop.
struct Loop {
  const ChunkBody* body = nullptr;
  std::size_t n = 0;
  std::size_t chunk = 1;
  unsigned max_joined = 0;  ///< workers that may join (the loop's threads - 1)
  unsigned joined = 0;      ///< under the team's mutex
  unsigned active = 0;      ///< joined and not yet left; under the team's mutex
  std::atomic<unsigned> in_chunks{0};  ///< joined and not yet left, read without the mutex
  std::atomic<std::size_t> next{0};
  std::atomic<bool> cancel{false};
  std::mutex error_mutex;
  std::exception_ptr error;

  /// Claims and runs chunks until none is left or the loop is cancelled. An exception of
  /// the body (or of the stop poll) is kept for the caller and cancels the loop.
  void work(unsigned worker, const std::function<bool()>* stop, bool& stopped) {
    try {
      for (;;) {
        if (cancel.load(std::memory_order_relaxed)) return;
        if (stop && *stop && (*stop)()) {
          stopped = true;
          cancel.store(true, std::memory_order_relaxed);
          return;
        }
        const std::size_t first = next.fetch_add(chunk, std::memory_order_relaxed);
        if (first >= n) return;
        (*body)(first, std::min(n, first + chunk), worker);
      }
    } catch (...) {
      const std::lock_guard<std::mutex> lock(error_mutex);
      if (!error) error = std::current_exception();
      cancel.store(true, std::memory_order_relaxed);
    }
  }
};

/// The team. Never destroyed (its sleeping workers end with the process), so no exit
/// path waits on a worker.
class Team {
 public:

  /// Runs `loop` on the caller and up to loop.max_joined workers; false when the team is
  /// already running another caller's loop (the caller then runs it alone). `spun`: the
  /// seconds the caller spent waiting on the lock-free count (CPU that did no item).
  bool run(Loop& loop, const std::function<bool()>* stop, bool& stopped, double& spun) {
    {
      const std::lock_guard<std::mutex> lock(mutex_);
      if (loop_ != nullptr) return false;
      const std::uint64_t before = generation_;  // a new worker joins this loop too
      while (threads_.size() < loop.max_joined) threads_.emplace_back([this, before] { serve(before); });
      loop_ = &loop;
      ++generation_;
    }
    if (loop.max_joined + 1 >= threads_.size()) {
      wake_.notify_all();
    } else {
      for (unsigned k = 0; k < loop.max_joined; ++k) wake_.notify_one();
    }
    tls_threads = kInsideLoop;
    loop.work(0, stop, stopped);
    std::unique_lock<std::mutex> lock(mutex_);
    loop_ = nullptr;  // no worker joins from here on
    if (loop.active != 0) {
      lock.unlock();
      const auto start = std::chrono::steady_clock::now();
      auto at = start;
      while (loop.in_chunks.load(std::memory_order_acquire) != 0 && at - start < kCallerSpin) {
        cpu_relax();
        at = std::chrono::steady_clock::now();
      }
      spun = std::chrono::duration<double>(at - start).count();
      lock.lock();
    }
    done_.wait(lock, [&] { return loop.active == 0; });
    return true;
  }

  /// Whether a loop starting now runs on the team (the tuner's choice, loop_tuner.hpp),
  /// and whether the tuner is probing (then the loop's wall time goes to loop_ended()).
  struct Choice {
    bool team = true;
    bool probing = false;
  };
  Choice tune(double now) {
    const std::lock_guard<std::mutex> lock(tuner_mutex_);
    const bool on_team = tuner_.begin(now, [this] { return process_cpu_seconds() - spun_; });
    return {on_team, tuner_.probing()};
  }

  /// A loop begun while probing took `wall` seconds.
  void loop_ended(double wall) {
    const std::lock_guard<std::mutex> lock(tuner_mutex_);
    tuner_.ended(wall);
  }

  /// The caller's spin seconds so far (CPU that did no item), for the tuner.
  void add_spin(double s) {
    const std::lock_guard<std::mutex> lock(tuner_mutex_);
    spun_ += s;
  }

 private:
  /// A worker: sleeps until a loop newer than `seen` is published, joins it when it
  /// still takes workers, works, leaves; until the process ends.
  void serve(std::uint64_t seen) {
    tls_threads = kInsideLoop;
    std::unique_lock<std::mutex> lock(mutex_);
    for (;;) {
      wake_.wait(lock, [&] { return generation_ != seen; });
      seen = generation_;
      Loop* loop = loop_;
      if (loop == nullptr || loop->joined >= loop->max_joined) continue;
      const unsigned worker = ++loop->joined;
      ++loop->active;
      loop->in_chunks.fetch_add(1, std::memory_order_relaxed);
      lock.unlock();
      bool ignored = false;
      loop->work(worker, nullptr, ignored);
      loop->in_chunks.fetch_sub(1, std::memory_order_release);
      lock.lock();
      if (--loop->active == 0) done_.notify_all();
    }
  }

  std::mutex mutex_;
  std::condition_variable wake_;
  std::condition_variable done_;
  std::vector<std::thread> threads_;
  Loop* loop_ = nullptr;
  std::uint64_t generation_ = 0;
  std::mutex tuner_mutex_;
  detail::LoopTuner tuner_;
  double spun_ = 0.0;
};

Team& team() {
  static Team* const t = new Team;
  return *t;
}

int read_default_threads() {
  if (const char* env = std::getenv("OMP_NUM_THREADS")) {
    char* end = nullptr;
    const long v = std::strtol(env, &end, 10);
    if (end != env && (*end == '\0' || *end == ',') && v > 0) return static_cast<int>(std::min(v, 4096L));
  }
  cpu_set_t set;
  CPU_ZERO(&set);
  if (sched_getaffinity(0, sizeof(set), &set) == 0) {
    const int n = CPU_COUNT(&set);
    if (n > 0) return n;
  }
  return static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
}

}  // namespace

int default_threads() {
  static const int n = read_default_threads();
  return n;
}

int current_threads() {
  if (tls_threads == kInsideLoop) return 1;
  return tls_threads > 0 ? tls_threads : default_threads();
}

ThreadCount::ThreadCount(int n) : saved_(tls_threads) {
  if (tls_threads != kInsideLoop) tls_threads = n > 0 ? n : 0;
}

ThreadCount::~ThreadCount() { tls_threads = saved_; }

unsigned loop_threads(std::size_t n, const LoopOptions& options) {
  if (n < std::max<std::size_t>(options.min_items, 2) || tls_threads == kInsideLoop) return 1;
  const int want = options.threads > 0 ? options.threads : current_threads();
  return static_cast<unsigned>(std::max<std::size_t>(1, std::min<std::size_t>(static_cast<std::size_t>(want), n)));
}

namespace {

/// A loop on its caller alone: the same chunks, the stop polled between them.
bool run_alone(std::size_t n, const LoopOptions& options, const ChunkBody& body) {
  const std::function<bool()>* stop = options.stop ? &options.stop : nullptr;
  const std::size_t chunk = options.chunk > 0 ? options.chunk : 64;
  const int saved = tls_threads;
  tls_threads = kInsideLoop;
  try {
    for (std::size_t first = 0; first < n; first += chunk) {
      if (stop && (*stop)()) {
        tls_threads = saved;
        return false;
      }
      body(first, std::min(n, first + chunk), 0u);
    }
  } catch (...) {
    tls_threads = saved;
    throw;
  }
  tls_threads = saved;
  return true;
}

/// A loop on the team (the caller one of its threads), or on the caller alone where the
/// team is running another caller's loop.
bool run_on_team(std::size_t n, unsigned threads, const LoopOptions& options, const ChunkBody& body) {
  const std::function<bool()>* stop = options.stop ? &options.stop : nullptr;
  Loop loop;
  loop.body = &body;
  loop.n = n;
  loop.chunk = options.chunk > 0 ? options.chunk
                                  : std::max<std::size_t>(1, std::min<std::size_t>(64, n / (threads * 8u)));
  loop.max_joined = threads - 1;
  bool stopped = false;
  double spun = 0.0;
  const int saved = tls_threads;
  const bool ran = team().run(loop, stop, stopped, spun);
  tls_threads = saved;
  if (spun > 0.0) team().add_spin(spun);
  if (!ran) return run_alone(n, options, body);  // the team runs another caller's loop
  if (loop.error) std::rethrow_exception(loop.error);
  return !stopped;
}

}  // namespace

bool parallel_chunks(std::size_t n, const LoopOptions& options, const ChunkBody& body) {
  const unsigned threads = loop_threads(n, options);
  if (threads <= 1) return run_alone(n, options, body);
  // On the team or on the caller alone, as the tuner chose; while it probes, it is told
  // the loop's wall time.
  struct Told {
    double start;
    bool probing;
    ~Told() {
      if (probing) team().loop_ended(seconds_now() - start);
    }
  };
  const double start = seconds_now();
  const Team::Choice choice = team().tune(start);
  const Told told{start, choice.probing};
  return choice.team ? run_on_team(n, threads, options, body) : run_alone(n, options, body);
}

}  // namespace octocd
