#pragma once
/// \file timing_limits.hpp
/// The range of a timing figure octocd measures or reads: a bench result's steps/s and
/// ms/frame, a process engine's frames over its trace's wall_step_seconds.

namespace octocd::limits {

/// A timing figure lies in [kMinTiming, kMaxTiming] (or is 0: not measured): the range
/// `report` takes for a bench result's timings (docs/bench-format.md; report_data.py
/// TIMING_RANGE). Beyond it, a figure is one no clock of this machine can have measured.
constexpr double kMinTiming = 1e-12;
constexpr double kMaxTiming = 1e15;

}  // namespace octocd::limits
