#pragma once
/// \file sat.hpp
/// Exact reference geometry of two convex polytopes by the separating-axis test (design.md section
/// 13b.9): the physics tier's `contact-geometry` row judges box-box and convex-polytope
/// pairs against it; FCL stays the reference for other shapes, and the posed answer
/// (ReferenceGeometry::posed: two boxes octocd's box-box, hulls FCL's EPA) the second opinion.
///
/// Shapes: each body's convex hull (octocd/reference_contact.hpp HullFeatures: a box's 8
/// corners, or a convex mesh's hull) in its body frame, placed at a Pose (body to world).
/// Units: metres. Arithmetic: double precision throughout (the poses' float32 values are
/// taken exactly).
///
/// Axes tested (Gottschalk's theorem for convex polytopes): the face normals of A, the
/// face normals of B, and the cross product of every edge direction of A with every edge
/// direction of B (nearly parallel edge pairs, |e_a x e_b| < 1e-9, give no axis). Along a
/// unit axis u the shapes' projections [a0, a1] and [b0, b1] overlap by
/// min(b1 - a0, a1 - b0): the translation of A along +u (b1 - a0) or -u (a1 - b0) that
/// separates them along u. The minimum translation (penetration depth) is the least
/// overlap over the axes, and its direction (from B to A, design.md section 2) is the contact normal.
/// An overlap <= 0 on any axis: the shapes are separated (or touch).
///
/// Accepted normals: every axis whose overlap is within epsilon of the minimum,
/// epsilon = abs_m + rel x minimum (SatSettings). Two engines' choices between nearly
/// equal axes are both correct contacts: ODE's dBoxBox (FCL's box-box, Bullet's
/// btBoxBoxDetector) keeps a face axis unless an edge-edge axis overlaps less than 1/1.05
/// of it (a stable face contact), while an exact detector takes the least overlap.
///
/// Cost: (faces_a + faces_b + edges_a x edges_b) x (vertices_a + vertices_b) products;
/// two boxes: 15 axes x 16 vertices. An axis whose direction repeats an earlier one's bit
/// for bit (two boxes turned alike: B's faces are A's, and each edge cross one of them)
/// copies that axis's figures instead of projecting again (the same figures: the same
/// arithmetic). Pairs beyond SatSettings::max_work are not tested
/// (sat_min_translation returns tested = false) and the caller falls back to FCL.
/// Two boxes (hull_box) take the closed form instead (sat_boxes, octocd/box_sat.hpp: 15
/// axes, radii from R = A^T B, no vertex projected; the device judge's formula too), whose
/// oracle is this hull test (tests/validation/test_box_sat.cpp).

#include <array>
#include <cstddef>
#include <vector>

#include "octocd/pose.hpp"
#include "octocd/reference_contact.hpp"

namespace octocd {

/// Settings of the separating-axis test.
struct SatSettings {
  /// Absolute part of the acceptance epsilon (m). The poses arrive in float32: a vertex at
  /// up to ~10 m from the origin projects with a rounding error near 10 x 2^-23 (~1.2e-6
  /// m) per coordinate and orientation entry; 1e-5 m (Tolerances::geometry_slack_m, the
  /// slack of every geometric comparison) covers it with margin.
  double abs_m = 1e-5;
  /// Relative part of the acceptance epsilon (fraction of the minimum overlap). 0.05: ODE's
  /// box-box test (FCL's, Bullet's btBoxBoxDetector) prefers a face axis to an edge-edge
  /// axis unless the edge-edge overlap is below the face overlap / 1.05 (its
  /// fudge_factor), so a face normal within 5% of the minimum is a choice two widely used
  /// detectors make on purpose.
  double rel = 0.05;
  /// Largest work (axes x vertices projected) of one test; beyond it the pair is not
  /// tested (two icospheres of 162 vertices and 480 edges need ~7.5e7). 2e6: a box
  /// against a 162-vertex icosphere (~3e5) is tested.
  double max_work = 2e6;
  /// Also fill SatResult::accepted when the shapes are apart or touch (every axis whose
  /// overlap is within epsilon of the least, the largest gap's first): impulse-feasibility
  /// takes every plane an engine may take within its margin.
  bool accept_separated = false;
};

/// One axis of the separating-axis test.
struct SatAxis {
  std::array<double, 3> normal{};  ///< unit, world frame, from B to A (the direction A is translated)
  double overlap = 0;              ///< m: the translation of A along `normal` that separates the shapes along it
  /// Where it came from: 0 a face normal of A, 1 a face normal of B, 2 an edge-edge cross product.
  int kind = 0;
};

/// The result of one separating-axis test.
struct SatResult {
  bool tested = false;     ///< false: beyond SatSettings::max_work, nothing else is filled
  bool separated = false;  ///< an axis with overlap <= 0 (the shapes are apart or touch)
  double depth = 0;        ///< m: the minimum overlap (the penetration depth); <= 0 when separated
  std::array<double, 3> normal{};  ///< unit, world frame, B to A: the axis of the minimum
  double epsilon = 0;      ///< m: SatSettings::abs_m + rel x max(depth, 0)
  /// every axis with overlap <= depth + epsilon (penetrating pairs; apart ones too with
  /// SatSettings::accept_separated)
  std::vector<SatAxis> accepted;
  std::size_t axes = 0;    ///< axes tested
};

/// The separating-axis test of hull `a` at pose `pa` against hull `b` at `pb` (see the
/// file comment). Hulls without vertices give tested = false. Throws nothing.
SatResult sat_min_translation(const HullFeatures& a, const Pose& pa, const HullFeatures& b, const Pose& pb,
                              const SatSettings& settings = SatSettings{});

/// A hull placed in the world frame (place_hull): its vertices (m), unit face normals and
/// unit edge directions, as sat_min_translation places them. The vertices are kept one
/// coordinate a vector (vertex k is (x[k], y[k], z[k])), padded to an even count by
/// repeating the last vertex (a repeated vertex moves no projection's extremes), so that a
/// projection takes two vertices an instruction.
struct PlacedHull {
  std::vector<double> x, y, z;  ///< vertex coordinates (m, world), padded (see above)
  std::size_t vertex_count = 0;  ///< the hull's vertices, before padding
  std::vector<std::array<double, 3>> faces, edges;
};

/// Hull `h` at pose `p` (body to world), written into `out` (its vectors cleared, their
/// capacity kept). Throws nothing beyond std::bad_alloc.
void place_hull(const HullFeatures& h, const Pose& p, PlacedHull& out);

/// sat_min_translation on hulls already placed (place_hull), with the accepted axes written
/// into `accepted` (cleared first, its capacity kept) instead of the result's vector (left
/// empty): a caller that places a body once for its many pairs and reads the axes before
/// its next test allocates nothing per pair. The same figures as sat_min_translation, bit
/// for bit. Throws nothing beyond std::bad_alloc.
SatResult sat_min_translation_placed(const PlacedHull& a, const PlacedHull& b, const SatSettings& settings,
                                     std::vector<SatAxis>& accepted);

/// Whether hull `h` is a box as the separating-axis test sees one, and if so its extent
/// [lo, hi] in the body frame (m): 8 vertices, the 8 corners of their bounding box (each
/// coordinate its least or greatest value), and face normals and edge directions exactly
/// (1, 0, 0), (0, 1, 0), (0, 0, 1) in that order, as octocd/reference_contact.hpp builds a
/// box shape's hull (and a body declared as its box). lo and hi are untouched otherwise.
bool hull_box(const HullFeatures& h, std::array<double, 3>& lo, std::array<double, 3>& hi);

/// sat_min_translation_placed for two boxes in closed form (octocd/box_sat.hpp, Gottschalk's
/// OBB test: no vertex is projected): box [lo_a, hi_a] of A's body frame at pose `pa`
/// against [lo_b, hi_b] at `pb`, for hulls that hull_box accepts. The same axes in the same
/// order and kinds, bit for bit the same unit normals (up to the sign of a zero component),
/// the overlaps equal to the hull test's up to rounding (about 1e-16 of the boxes' and
/// centres' scale; on an edge-edge axis box_sat.hpp's kBoxSatEps x the half extents / the
/// cross's length more, at most ~1e-7 m on the shortest crosses tested). The accepted axes
/// go into `accepted` (cleared first). Non-finite poses: tested = false (the caller takes
/// the hull test). SatSettings::max_work applies as to the hull test (15 axes x 16
/// vertices). Allocates nothing once `accepted` holds 15 axes; throws nothing beyond
/// std::bad_alloc.
SatResult sat_boxes(const std::array<double, 3>& lo_a, const std::array<double, 3>& hi_a, const Pose& pa,
                    const std::array<double, 3>& lo_b, const std::array<double, 3>& hi_b, const Pose& pb,
                    const SatSettings& settings, std::vector<SatAxis>& accepted);

/// The penetration of two posed convex hulls along one direction.
struct SatAlong {
  bool tested = false;  ///< false: beyond SatSettings::max_work, a hull without vertices, or no axis across n
  double depth = 0;     ///< m, >= 0: the translation of A along n after which the shapes no longer overlap
  std::array<double, 3> axis{};  ///< unit, world frame: the axis whose face of B - A the translation leaves through
};

/// How far hull `a` at pose `pa` must be translated along the unit world direction `n`
/// (from B to A) to leave hull `b` at `pb`, each shape rounded by its convex radius,
/// `radius` the two summed (m, >= 0): the deepest point of the shapes' overlap along n.
/// A + t n meets B exactly where t n lies in the Minkowski difference B - A, whose faces
/// are among the separating-axis test's axes (the face normals of both hulls and the
/// cross products of their edges), each taken with both orientations u: for shapes that
/// overlap (the origin inside B - A) the depth is the ray's exit, min over the axes with
/// u . n > 0 of (overlap along u + radius) / (u . n), at least 0. It equals
/// the minimum translation where n is the minimum's axis, grows as 1 / cos of the angle
/// while n leaves it across the same face, and never reads the far side of a large face
/// (as the hulls' overlap projected on n does). Exact for hulls; with a radius the faces'
/// planes pushed out by it (exact where the ray leaves through a face, above the rounded
/// edge's exit by at most the radius otherwise). Cost: the separating-axis test's, under
/// `settings`.max_work. Throws nothing beyond std::bad_alloc.
SatAlong sat_depth_along(const HullFeatures& a, const Pose& pa, const HullFeatures& b, const Pose& pb,
                         const std::array<double, 3>& n, double radius, const SatSettings& settings = SatSettings{});

/// The smallest angle (radians, [0, pi]) between the unit vector `n` and an accepted axis
/// of `r` (each taken with its orientation, B to A); pi when none is accepted.
double sat_angle_to_accepted(const SatResult& r, const std::array<double, 3>& n, std::size_t* nearest = nullptr);
/// The same over the axes `accepted` (as sat_min_translation_placed leaves them).
double sat_angle_to_accepted(const std::vector<SatAxis>& accepted, const std::array<double, 3>& n,
                             std::size_t* nearest = nullptr);

}  // namespace octocd
