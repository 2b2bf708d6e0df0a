#pragma once
/// \file applied_state.hpp
/// design.md section 7 item 9 (private to validation/): the applied-state judge. An independent
/// re-derivation of design.md section 4.1 and design.md section 6 in double precision predicts every body's
/// post-step x and v from a FrameRecord's pre-step state and confirmed contacts; the
/// engine's state must match within a float32 tolerance. Momentum and the mass-weighted
/// centre are measured on the applied state of isolated dynamic groups.
///
/// Relaxation passes (response.iterations > 1) make design.md section 6 discontinuous at decisions
/// that float32 rounding can tip either way (v_n near 0, |v_n| near v_th, stick or slip,
/// an overlap near 0, two overlaps or a centre offset near a tie, the fixed-axis
/// distance): the outcome feeds the next pass of every neighbour. Each such near-tie is a
/// branch (J_n = max(.., J_min), max(d_p - delta, 0) and the v_max clamp are continuous in
/// their inputs: no branch). Within an island (dynamic bodies connected by confirmed contacts) the judge
/// explores the outcomes, bounded (kMaxRuns, kMaxWork, kMaxQueueBytes), and accepts the
/// engine's state when some consistent choice (an outcome the double value allows within
/// the rounding margin) reproduces every body of the island within the tolerance. A
/// float32 evaluation of the same formulas, run alongside, proposes the outcome of each
/// near-tie (the first branch tried); the verdict is the double re-derivation's. When the
/// bound is exceeded without a match, only the bodies that no near-tie can reach within
/// the remaining passes are judged; the others are counted as not judged.

#include <algorithm>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "octocd/validation.hpp"

namespace octocd {

/// A running count of the model tier's checks and failures: the worst figure (a ratio or an
/// excess over its bound, judged <= 1 or <= 0 by the caller) and the first failure's
/// description.
struct CheckTally {
  std::uint64_t checks = 0;
  std::uint64_t failures = 0;
  double worst = 0.0;
  std::string first;
  void check(bool ok, double figure, const std::string& what) {
    ++checks;
    worst = std::max(worst, figure);
    if (ok) return;
    if (failures == 0) first = what;
    ++failures;
  }
  /// check() with the description made by `what()` only where it is kept (the first failure).
  template <class F, class = decltype(std::declval<F>()())>
  void check(bool ok, double figure, F&& what) {
    ++checks;
    worst = std::max(worst, figure);
    if (ok) return;
    if (failures == 0) first = what();
    ++failures;
  }
};

/// Judges the applied state frame by frame (FrameValidators owns one).
class AppliedStateJudge {
 public:
  /// Branch runs (complete re-derivations of one island's passes) per island and frame.
  static constexpr int kMaxRuns = 256;
  /// Contact evaluations (contacts x passes, summed over the branch runs) per island and
  /// frame, beyond the first run.
  static constexpr std::uint64_t kMaxWork = std::uint64_t{1} << 22;
  /// Memory of the queue of branches still to explore, per island and frame (bytes).
  static constexpr std::uint64_t kMaxQueueBytes = std::uint64_t{8} << 20;

  /// `model` (scene parameters, local boxes, inverse masses) must outlive the judge.
  AppliedStateJudge(const Model& model, const Tolerances& tol);
  ~AppliedStateJudge();
  AppliedStateJudge(const AppliedStateJudge&) = delete;
  AppliedStateJudge& operator=(const AppliedStateJudge&) = delete;

  /// Judges one step. `rec` holds x_pre, v_pre, x_post, v_post (one entry per body; the
  /// call does nothing when they are empty), aabbs and the sorted confirmed pairs.
  /// `judge_response`: compare every dynamic body with the design.md section 6 re-derivation (octocd's
  /// engines, or another engine that claims design.md section 6); false: only the isolated groups,
  /// with the position after integration taken from the engine's world AABBs.
  void observe(const FrameRecord& rec, bool judge_response);

  /// The applied-state row (Tier::Model): failures = dynamic body-frames off the
  /// re-derivation; the detail names the first, or the share of body-frames judged.
  ValidationResult result() const;

  /// The isolated-group checks on the applied state, for the conservation row.
  struct Groups {
    std::uint64_t groups = 0;    ///< isolated dynamic groups judged (momentum)
    std::uint64_t pairs = 0;     ///< isolated pairs judged (mass-weighted centre)
    std::uint64_t failures = 0;  ///< groups or pairs off their bound
    double worst = 0.0;          ///< largest residual / bound over the judged ones
    std::string first;           ///< the first failure ("" none)
  };
  /// Figures so far.
  Groups groups() const;

  /// Polled per island and per relaxation pass of the re-derivation; observe throws
  /// ValidationStopped when it returns true. Empty (default): never.
  void set_stop(std::function<bool()> stop);
  /// Threads the frame's islands are searched on (0: the hardware's; 1: serial); the
  /// verdicts do not depend on it.
  void set_threads(int threads);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace octocd
