#pragma once
/// \file convex_hull.hpp
/// The convex hull of a mesh as the engines' convex shapes take it (ODE's dGeomConvex,
/// and any adapter that needs faces, planes or the hull's mass properties): vertices,
/// polygonal faces wound counter-clockwise seen from outside, and one outward plane per
/// face. Computed with Bullet's btConvexHullComputer on the mesh's vertices (exact
/// integer arithmetic: every hull vertex is one of the mesh's vertices).

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "octocd/math.hpp"
#include "octocd/mesh.hpp"

namespace octocd {

/// A convex polytope in its shape frame (double precision, metres).
struct ConvexHull {
  /// The hull's vertices (each one of the input points, converted to double).
  std::vector<std::array<double, 3>> vertices;
  /// Per face, the indices into `vertices` of its corners, counter-clockwise seen from
  /// outside (right-hand rule: the outward normal). At least 3 per face. Faces thinner than 1e-6 of the hull's bounding-box diagonal (slivers of collinear
  /// corners, whose normal is rounding noise) are left out. The hull is Bullet's, found on
  /// a grid of 1/10216 of the points' range: a thin face's plane may tilt so that hull
  /// vertices lie beyond it by up to about 2% of the diagonal (asian-dragon: 1.7%).
  std::vector<std::vector<std::uint32_t>> faces;
  /// Per face, its plane (nx, ny, nz, d): unit outward normal n (Newell's normal of the
  /// polygon) and offset d = max over the face's corners of n . v, so every vertex of
  /// the hull satisfies n . v <= d (up to rounding) and the face lies on n . v = d.
  std::vector<std::array<double, 4>> planes;
};

/// The convex hull of `points` (m). Throws InputError "<what>: ..." when the points span
/// no volume (fewer than 4 points not in one plane: btConvexHullComputer then returns a
/// polygon or less), naming the number of points and the hull's face count.
ConvexHull convex_hull(const std::vector<Vec3>& points, const std::string& what);

/// The convex hull of a mesh's vertices (Mesh::vertices; the triangles are not read).
/// Throws InputError as convex_hull(points, mesh.name).
ConvexHull convex_hull(const Mesh& mesh);

/// Mass properties of a convex hull of uniform density 1 kg/m^3 (scale by the density,
/// i.e. mass / volume), from the signed tetrahedra of each face's fan with the mean of
/// the hull's vertices (an interior point): volume (m^3), centroid (m, shape frame) and
/// the inertia tensor about the shape frame's ORIGIN (kg m^2 at density 1, row-major
/// 3x3: I = tr(C) E - C with C the second moment integral of x x^T, for a tetrahedron
/// p0..p3 of volume V: V/20 (sum_i p_i p_i^T + s s^T), s = sum_i p_i).
struct HullMassProperties {
  double volume = 0.0;                      ///< m^3
  std::array<double, 3> centroid{};         ///< m, shape frame
  std::array<double, 9> inertia_origin{};   ///< kg m^2 per kg/m^3, about the origin
};

/// The mass properties of `hull` (HullMassProperties). A hull with faces from
/// convex_hull() has a positive volume.
HullMassProperties hull_mass_properties(const ConvexHull& hull);

}  // namespace octocd
