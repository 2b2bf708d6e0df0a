// Copies of a scene as separate runs, several at once (octocd/world_copies.hpp).
#include "octocd/world_copies.hpp"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <mutex>

#include "octocd/parallel.hpp"
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
  // An engine whose instances share unguarded process-wide state steps its copies one
  // after another (EngineInfo::not_thread_safe).
  const bool serial = !engine_info(engine, "--engine").not_thread_safe.empty();
  const int t = serial ? 1 : static_cast<int>(loop_threads(k, LoopOptions{threads, 2, 1, {}}));
  out.threads = t;
  std::atomic<bool> failed{false};
  // Engines are made and destroyed one at a time (a library's set-up may share state
  // between its worlds); their steps run at once, on the worker team (octocd/parallel.hpp):
  // an engine's own loops inside a copy run serially there.
  std::mutex make_mutex;
  LoopOptions loop;
  loop.threads = t;
  loop.chunk = 1;
  const auto t0 = std::chrono::steady_clock::now();
  parallel_for(k, loop, [&](std::size_t c, unsigned) {
    try {
      if (failed || stop_signal() != 0) return;  // a copy not begun by a stop is not made
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
      failed = true;  // the other copies stop at their next frame; the first error is rethrown
      throw;
    }
  });
  out.wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return out;
}

}  // namespace octocd
