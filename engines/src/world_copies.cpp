// Copies of a scene as separate runs, several at once (octocd/world_copies.hpp).
#include "octocd/world_copies.hpp"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <exception>
#include <mutex>
#include <thread>

#include "octocd/stop.hpp"

namespace octocd {

CopiesRun run_copies_separately(const std::string& engine, const std::shared_ptr<const Model>& single,
                                const WorldsSpec& spec, int frames, int threads, const EngineSettingItems& settings,
                                const CopyFrameCallback& on_frame) {
  const std::size_t k = static_cast<std::size_t>(std::max<long>(spec.count, 1));
  (void)worlds_copy_model(*single, spec, k - 1);  // the spec's checks, before any thread starts
  CopiesRun out;
  out.states.resize(k);
  out.step_ms.assign(k, 0.0);
  out.frames.assign(k, 0);
  int t = threads > 0 ? threads : static_cast<int>(std::thread::hardware_concurrency());
  t = std::max(1, std::min<int>(t, static_cast<int>(k)));
  out.threads = t;
  std::atomic<std::size_t> next{0};
  std::atomic<bool> failed{false};
  std::exception_ptr first;
  std::mutex first_mutex;
  // Engines are made and destroyed one at a time (a library's set-up may share state
  // between its worlds); their steps run at once.
  std::mutex make_mutex;
  auto worker = [&] {
    for (std::size_t c = next++; c < k && !failed; c = next++) {
      try {
        std::unique_ptr<Engine> e;
        {
          std::lock_guard<std::mutex> lock(make_mutex);
          e = make_engine(engine, worlds_copy_model(*single, spec, c), settings);
        }
        for (int f = 0; f < frames && !failed && stop_signal() == 0; ++f) {
          const FrameMetrics& m = e->step();
          out.step_ms[c] += m.step_ms;
          ++out.frames[c];
          if (on_frame) on_frame(c, m, *e);
        }
        out.states[c] = e->state();
        std::lock_guard<std::mutex> lock(make_mutex);
        e.reset();
      } catch (...) {
        std::lock_guard<std::mutex> lock(first_mutex);  // (an engine not yet reset is destroyed unlocked)
        if (!first) first = std::current_exception();
        failed = true;
      }
    }
  };
  const auto t0 = std::chrono::steady_clock::now();
  std::vector<std::thread> pool;
  for (int i = 1; i < t; ++i) pool.emplace_back(worker);
  worker();
  for (std::thread& th : pool) th.join();
  out.wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  if (first) std::rethrow_exception(first);
  return out;
}

}  // namespace octocd
