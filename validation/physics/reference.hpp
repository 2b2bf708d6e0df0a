#pragma once
/// \file reference.hpp
/// The reference contact geometry of one pair, as the physics tier's `contact-geometry`
/// row judges it (octocd/physics.hpp, row 3; design.md section 13b.9): shared by the validators
/// (contact_rows.cpp) and `octocd view` (harness/src/view.cpp), so a page draws
/// exactly the normal a row was judged against. Internal to validation/.
///
/// Two convex polytopes (boxes, convex meshes, declared hulls and boxes) that penetrate:
/// the separating-axis test (sat.hpp) gives the depth and the normal of the minimum
/// translation, and every axis within its epsilon is an accepted normal; the posed answer
/// (ReferenceGeometry::posed: two boxes octocd's box-box, hulls FCL's EPA) is kept beside
/// it (the second opinion). Other shapes: FCL / libccd (ReferenceGeometry::posed). Units: metres; normals unit, from B to A (design.md section 2).

#include <array>
#include <cstdint>
#include <vector>

#include "octocd/math.hpp"
#include "octocd/pose.hpp"
#include "octocd/reference_contact.hpp"
#include "sat.hpp"

namespace octocd {

/// The reference geometry of one pair at its detection poses.
struct PairReference {
  /// The reference: posed()'s answer, with SAT's depth and normal when `sat`.
  ReferenceNormal g;
  /// g's depth and normal are the separating-axis test's (both shapes convex polytopes
  /// and posed() found them penetrating).
  bool sat = false;
  SatResult sat_result;  ///< the separating-axis test (filled when `sat`)
  ReferenceNormal fcl;   ///< posed()'s own answer (the second opinion where `sat`)
};

/// The reference of bodies a, b at poses pa, pb: ref.posed(a, b, pa, pb); when it
/// penetrates (valid) and both shapes are convex (ReferenceGeometry::convex), the
/// separating-axis test with `settings` replaces its depth (no longer an upper bound) and
/// normal. Throws InputError for a body out of range (ReferenceGeometry).
PairReference pair_reference(const ReferenceGeometry& ref, std::uint32_t a, std::uint32_t b, const Pose& pa,
                             const Pose& pb, const SatSettings& settings);

/// Work space of pair_reference_into for one frame's poses: the hulls placed for the
/// separating-axis test (hull a kept while the next pair has the same first body) and the
/// accepted axes of the last pair.
struct PairReferenceScratch {
  PlacedHull a, b;
  std::uint32_t placed_a = 0xffffffffu;  ///< the body whose hull `a` holds (none: 2^32 - 1)
  std::vector<SatAxis> accepted;         ///< the last pair's accepted axes (where `sat`)
  /// A hull last asked whether it is a box (hull_box), by address, with the answer.
  struct BoxSeen {
    const HullFeatures* hull = nullptr;
    bool box = false;
    std::array<double, 3> lo{}, hi{};  ///< its extent where `box`
  };
  BoxSeen box_seen[2];  ///< body a's hull, body b's (a scratch serves one ReferenceGeometry)
};

/// pair_reference for callers that judge many pairs at one set of poses: the same figures
/// bit for bit, with SAT's accepted axes left in scratch.accepted (the result's
/// sat_result.accepted stays empty) until the next call, and body a's placed hull reused
/// while a repeats. `scratch` serves one set of poses only (a new frame: a new scratch).
PairReference pair_reference_into(const ReferenceGeometry& ref, std::uint32_t a, std::uint32_t b, const Pose& pa,
                                  const Pose& pb, const SatSettings& settings, PairReferenceScratch& scratch);

/// The normal one contact row is judged against, and its angle.
struct RowReference {
  Vec3 normal;         ///< unit, B to A: SAT's nearest accepted axis, or `r`'s normal
  double angle = 0;    ///< radians in [0, pi] between the row's normal and `normal`
};

/// For a row with normal `n`: with `by_sat`, the accepted axis of t.sat_result nearest to
/// n (sat_angle_to_accepted); otherwise r.normal (the FCL answer, or box-box on the world
/// AABBs for an engine that resolves on them) and angle_between(n, r.normal).
RowReference row_reference(const PairReference& t, const ReferenceNormal& r, bool by_sat, Vec3 n);
/// The same with SAT's accepted axes given apart (as pair_reference_into leaves them).
RowReference row_reference(const std::vector<SatAxis>& accepted, const ReferenceNormal& r, bool by_sat, Vec3 n);

}  // namespace octocd
