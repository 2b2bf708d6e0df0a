#pragma once
/// \file device_judge.hpp
/// The physics tier's device part (design.md section 13; docs/architecture.md, "The judges'
/// device part"): the geometry that the rows `broadphase-completeness` and `penetration`
/// read on a checked frame, computed on a GPU in double precision, independently of the
/// engine it judges. It calls nothing of gpu/ (the CUDA engine's broadphases, midphase or
/// response) and reads only core types, so a bug shared with the engine cannot pass unseen;
/// the CPU tier (validation/physics/) stays the oracle and judges every other row (rows
/// contact-completeness and contact-geometry on the device's candidate pairs,
/// impulse-feasibility and the near-pair search on overlapping_pairs of their grown boxes).
///
/// What the device computes:
///  - candidates: every pair of bodies whose world AABBs overlap (inclusive: touching
///    faces overlap, design.md Eq. 6), at least one of them dynamic, found by a uniform
///    grid over the boxes' lower corners (cell side = the largest extent of the bodies not
///    wider than twice the mean; wider bodies are tested against every body), sorted by
///    (a, b) with a < b;
///  - per candidate whose two bodies are boxes: the separating-axis test of the two posed
///    boxes in double precision (octocd/box_sat.hpp's closed form, the CPU reference's for
///    two boxes: 3 + 3 face normals and the 9 edge-edge crosses longer than 1e-9), its
///    least overlap (m). Pairs with another shape are marked and left to the CPU reference.
/// Poses arrive in float32 and are taken exactly; the quaternion is normalised in double
/// (as dmath::rotation). Units: metres.

#include <array>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "octocd/broadphase.hpp"
#include "octocd/math.hpp"
#include "octocd/pose.hpp"

namespace octocd {

/// One body as the device judge sees it (DeviceJudge::set_bodies).
struct DeviceJudgeBody {
  /// The body's local box in the body frame (m): a box shape fills it.
  std::array<double, 3> lo{}, hi{};
  /// A box: its world AABB is posed on the device and its pairs with boxes get the
  /// separating-axis test there. Otherwise its world AABB is given per frame
  /// (DeviceJudge::judge_frame's `world`) and its pairs go to the CPU reference.
  bool box = false;
  /// Dynamic (inverse mass > 0): a pair of two static bodies is never a candidate.
  bool dynamic = false;
  /// How far its world AABB is grown on every side before the candidates are taken (m, >= 0).
  double grow = 0;
};

/// The device's answer for one candidate pair.
struct DeviceBoxSat {
  /// Both bodies are boxes and `overlap` holds; false: the pair is the CPU reference's.
  bool box = false;
  /// The least overlap over the tested axes (m): > 0 the boxes penetrate by that depth
  /// (the minimum translation), <= 0 they are apart or touch, and -overlap is a lower
  /// bound of their distance.
  double overlap = 0;
};

/// One checked frame's device geometry (DeviceJudge::judge_frame).
struct DeviceFrameAnswer {
  std::vector<Pair> candidates;  ///< grown world AABBs overlap, a body dynamic; sorted, a < b
  std::vector<DeviceBoxSat> sat;  ///< per candidate
  double device_seconds = 0;     ///< wall time of the call (upload, kernels, download)
};

/// A GPU that judges checked frames (see the file comment). Not thread-safe: one caller at
/// a time. Errors (no device, a CUDA error, memory) are std::runtime_error naming the step.
class DeviceJudge {
 public:
  virtual ~DeviceJudge() = default;
  /// The device's name and the judge's kind, e.g. "cuda: NVIDIA H100 80GB HBM3".
  virtual std::string device_name() const = 0;
  /// The bodies of every following frame (their count fixes the poses' size).
  virtual void set_bodies(const std::vector<DeviceJudgeBody>& bodies) = 0;
  /// Frame geometry at `poses` (one per body, body to world): candidates and the box pairs'
  /// separating-axis tests into `out` (its vectors replaced). `world[i]` is the world AABB
  /// of non-box body i (ignored for boxes; may be empty when every body is a box). Throws
  /// std::invalid_argument when a size differs from set_bodies'.
  virtual void judge_frame(const std::vector<Pose>& poses, const std::vector<Aabb>& world,
                           DeviceFrameAnswer& out) = 0;
  /// The separating-axis test of `pairs` at the last judge_frame's poses (pairs a row asks
  /// about beyond the candidates, e.g. an engine's contact pairs): one answer each, in order.
  virtual void box_sat(const std::vector<Pair>& pairs, std::vector<DeviceBoxSat>& out) = 0;
  /// Every pair (a < b, sorted) whose `boxes` overlap (inclusive) with a dynamic body, on
  /// the device (an engine's own world AABBs, compared with `flat`'s set).
  virtual void overlapping_pairs(const std::vector<Aabb>& boxes, std::vector<Pair>& out) = 0;
};

/// A judge on the first CUDA device. Throws std::runtime_error saying why when this build
/// has no CUDA (OCTOCD_CUDA=OFF) or no device is usable.
std::unique_ptr<DeviceJudge> make_cuda_judge();

/// Whether this build has the CUDA judge (it may still find no device at run time).
bool cuda_judge_built();

/// One place the device rows can be judged (`--judge-device NAME`): its name and its maker
/// (null: no device, the CPU tier judges every row).
struct JudgeDeviceKind {
  const char* name;
  std::unique_ptr<DeviceJudge> (*make)();
};
/// Every kind, in the order help texts list them: "cpu" (the default), "cuda" (make_cuda_judge).
const std::vector<JudgeDeviceKind>& judge_device_kinds();
/// The kind named `name`; throws std::invalid_argument naming `option`, the value and the
/// allowed names.
const JudgeDeviceKind& judge_device_kind(const std::string& name, const char* option);

}  // namespace octocd
