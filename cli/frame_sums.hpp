#pragma once
/// \file frame_sums.hpp
/// Running sums of FrameMetrics over frames: the figures `run`'s summary and `bench`'s
/// windows both add up (internal to the CLI).

#include <array>
#include <cstdint>

#include "octocd/engine.hpp"

namespace octocd::cli {

/// Sums over frames of the step time (ms), the stage times (ms, per Stage), the broadphase
/// pairs (aabb_pairs) and candidates (cell_candidates), the midphase box pairs, the vertex
/// tests and the contacts; `frames` counts the frames added.
struct FrameSums {
  std::int64_t frames = 0;
  double step_ms = 0.0;
  std::array<double, static_cast<int>(Stage::Count)> stage_ms{};
  double pairs = 0.0, candidates = 0.0, box_pairs = 0.0, vertex_tests = 0.0, contacts = 0.0;

  /// Adds one frame's row.
  void add(const FrameMetrics& m) {
    ++frames;
    step_ms += m.step_ms;
    for (std::size_t s = 0; s < stage_ms.size(); ++s) stage_ms[s] += m.stage_ms[s];
    pairs += static_cast<double>(m.aabb_pairs);
    candidates += static_cast<double>(m.cell_candidates);
    box_pairs += static_cast<double>(m.box_pairs);
    vertex_tests += static_cast<double>(m.vertex_tests);
    contacts += static_cast<double>(m.contacts);
  }
};

}  // namespace octocd::cli
