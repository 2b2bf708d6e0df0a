#pragma once
/// \file world_copies.hpp
/// Copies of a scene as separate runs (docs/gpu.md, "Batched worlds"): what the
/// engines that step one scene per run (the reference engines, process engines) do for
/// `octocd run --worlds K`: K engines, one per copy, each copy at offset zero and perturbed
/// as the batched copy is (worlds_copy_model), several copies at once on threads.

#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "octocd/engine.hpp"
#include "octocd/engines.hpp"
#include "octocd/worlds.hpp"

namespace octocd {

/// What run_copies_separately did.
struct CopiesRun {
  std::vector<BodyState> states;  ///< per copy, its engine's state after the last step it ran
  std::vector<double> step_ms;    ///< per copy, the sum of its steps' FrameMetrics::step_ms
  std::vector<std::int64_t> frames;  ///< per copy, the steps it ran (fewer than asked after a stop signal)
  double wall_s = 0.0;            ///< wall time of all copies, from the first engine's making to the last step (s)
  int threads = 1;                ///< copies run at once
};

/// Called after every step of copy `copy` with its metrics and engine, from the thread
/// running that copy: calls for different copies may come at once (the callee keeps them
/// apart), those of one copy come in frame order.
using CopyFrameCallback = std::function<void(std::size_t copy, const FrameMetrics& metrics, const Engine& engine)>;

/// Runs copies 0 .. spec.count-1 of `single` for `frames` steps each on engine `engine`
/// (make_engine with `settings`), copy c from worlds_copy_model(*single, spec, c), `threads`
/// copies at once on the worker team (octocd/parallel.hpp; 0: current_threads(), at least
/// 1; never more than the copies; 1 for an engine with EngineInfo::not_thread_safe, whatever
/// `threads`); an engine's own parallel loops run serially inside a
/// copy (no nested teams). A copy's engine is made on the thread that steps it and
/// destroyed there, one engine at a time (steps run at once). Stops
/// between steps on octocd::stop_signal(); a copy not begun by then is not made (0 frames).
/// The first error of any copy (InputError,
/// RuntimeError: a non-finite state, an engine that cannot start) is rethrown after every
/// thread has ended; the copies still running stop at their next step.
CopiesRun run_copies_separately(const std::string& engine, const std::shared_ptr<const Model>& single,
                                const WorldsSpec& spec, int frames, int threads,
                                const EngineSettingItems& settings = {}, const CopyFrameCallback& on_frame = {});

}  // namespace octocd
