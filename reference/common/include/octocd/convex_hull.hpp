#pragma once
/// \file convex_hull.hpp
/// The convex hull of a mesh as the engines' convex shapes take it (ODE's dGeomConvex,
/// and any adapter that needs faces, planes or the hull's mass properties): vertices,
/// polygonal faces wound counter-clockwise seen from outside, and one outward plane per
/// face. Computed with qhull (libqhull_r, Debian's libqhull-dev) on the mesh's vertices in
/// double precision: every hull vertex is one of the mesh's vertices, and every vertex lies
/// on or below every face's plane up to double rounding. Every adapter (Bullet, ODE, DART)
/// and the physics tier's reference geometry collide this one hull.

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
  /// outside (right-hand rule: the outward normal). At least 3 per face: qhull's facets,
  /// coplanar ones merged where qhull's roundoff bound cannot tell them apart (its default
  /// options), otherwise triangles.
  std::vector<std::vector<std::uint32_t>> faces;
  /// Per face, its plane (nx, ny, nz, d): unit outward normal n (qhull's facet normal) and
  /// offset d = max over the face's corners of n . v, so every vertex of
  /// the hull satisfies n . v <= d (up to rounding) and the face lies on n . v = d.
  std::vector<std::array<double, 4>> planes;
};

/// The convex hull of `points` (m). Throws InputError "<what>: the convex hull of its N
/// vertices has F faces (they span no volume...)" when the points span no volume (fewer
/// than 4 points, or all in one plane: qhull refuses them and its message's first line is
/// added).
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
