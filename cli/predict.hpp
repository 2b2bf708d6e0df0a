// Predictability (design.md section 20, docs/predictability.md): determinism of an engine's
// run (`octocd validate --determinism`) and the recorded runs the divergence sweep
// (`octocd bench divergence`, cli/bench_divergence.cpp) is made of.
#pragma once

#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "octocd/engine.hpp"
#include "octocd/engines.hpp"
#include "octocd/validation.hpp"

namespace octocd::cli {

/// Runs engine `engine` (an engine_names() name) on `model` with `settings` for `frames`
/// steps (>= 1) and writes its trace to `path` (an existing or absent regular file, which is
/// replaced): every state (the initial one first) and, where the engine records, every
/// contact row; version 2 for a rotating engine; a process engine's own trace as written
/// (copy_own_trace). `stop` (may be empty) is asked between frames: once it returns true
/// the run ends there and record_trace returns false (the trace holds the frames stepped).
/// Throws what make_engine, the engine and TraceWriter throw.
bool record_trace(const std::string& engine, const std::shared_ptr<const Model>& model,
                  const EngineSettingItems& settings, int frames, const std::string& path,
                  const std::function<bool()>& stop = {});

/// The positions (m, one Vec3 per body in model order) of every body at frames 0..frames
/// (row 0: the initial state) of engine `engine`'s run of `model`: read from the state
/// after each step, or for a process engine from its own trace. Throws as record_trace,
/// and RuntimeError when a process engine's trace holds fewer states.
std::vector<std::vector<Vec3>> run_positions(const std::string& engine, const std::shared_ptr<const Model>& model,
                                             const EngineSettingItems& settings, int frames);

/// What `validate --determinism` compares (docs/predictability.md).
struct DeterminismOptions {
  std::string engine;                   ///< the engine judged
  std::shared_ptr<const Model> model;   ///< its scene, as validate built it
  EngineSettingItems settings;          ///< --ENGINE KEY=VALUE items
  int frames = 300;                     ///< steps of every run (>= 1)
  /// Threads of the threaded runs of an engine with an EngineInfo::threads_setting (>= 2;
  /// 0: max(2, the hardware's)), passed as that setting; the single-threaded run uses 1.
  int threads = 0;
  /// Asked between runs and between the frames of a run (may be empty): once it returns
  /// true, determinism_rows returns the rows finished before (fewer than 3).
  std::function<bool()> stop;
};

/// The determinism rows of `o.engine` on `o.model` (tier Physics, bound 0 = bit for bit):
/// `determinism-runs` (two runs with the same input), `determinism-threads` (1 against N
/// threads, an engine with an EngineInfo::threads_setting; else n/a with the reason)
/// and `determinism-cpu-cuda` (the engine against its EngineInfo::device_twin: octocd's cpu
/// against cuda; n/a for an engine without one, n/a naming why when the twin cannot run here). Every
/// comparison is `octocd compare`'s (compare_traces, bit for bit) of two traces written by
/// record_trace into temporary files (removed afterwards); a row that differs fails with
/// the first difference (frame, body, quantity, |A - B|, both values); stopped (o.stop),
/// the rows finished before. Throws what record_trace and compare_traces throw.
std::vector<ValidationResult> determinism_rows(const DeterminismOptions& o);

}  // namespace octocd::cli
