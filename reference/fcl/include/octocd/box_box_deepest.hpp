#pragma once
/// \file box_box_deepest.hpp
/// The deepest contact of two boxes by FCL 0.7's box-box test (fcl::detail::boxBox2, ODE's
/// dBoxBox: the 15 separating axes, a face axis kept unless an edge-edge axis overlaps less
/// than 1/1.05 of it, the incident face clipped against the reference face), as the
/// reference geometry (reference_contact.hpp) reads it: the same bits as FCL's own answer
/// (the same operations in the same order; the test BoxBoxDeepest in
/// tests/reference/test_reference_contact.cpp checks it against FCL on randomised pairs)
/// without FCL's contact vector, its culling to four points and the world positions of
/// the points it does not keep.
///
/// Units: metres; double precision. Frames: each box centred at `position` with its axes the
/// columns of `rotation` (row-major 3x3, body to world), full side lengths `side`.

#include <array>

namespace octocd {

/// One contact of two boxes, as FCL's ContactPoint gives it.
struct BoxBoxContact {
  std::array<double, 3> normal{};  ///< unit, world frame, from A to B (FCL's convention)
  std::array<double, 3> pos{};     ///< m, world frame: the contact point
  double depth = 0;                ///< m, >= 0: its penetration depth
};

/// FCL's box-box test of box A (side_a, rotation_a, position_a) against box B: false when
/// FCL reports no contact (separated, touching, or no clipped point; `out` untouched);
/// otherwise the deepest of the contacts fcl::detail::boxBox2 emits with maxc = 4 (the
/// first of equal depths) in `out`. Throws nothing.
bool box_box_deepest(const std::array<double, 3>& side_a, const std::array<double, 9>& rotation_a,
                     const std::array<double, 3>& position_a, const std::array<double, 3>& side_b,
                     const std::array<double, 9>& rotation_b, const std::array<double, 3>& position_b,
                     BoxBoxContact& out);

}  // namespace octocd
