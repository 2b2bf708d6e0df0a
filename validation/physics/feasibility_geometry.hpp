#pragma once
/// \file feasibility_geometry.hpp
/// The geometry the impulse-feasibility row builds its contact points with
/// (feasibility_contacts.cpp): 2D convex hulls of a contact patch projected on its tangent
/// plane, segment crossings and closest points, a hull's edges and supporting planes, the
/// least translation over two hulls' face normals. Double precision throughout; units metres.
#include <cstddef>
#include <cstdint>
#include <utility>
#include <vector>

#include "dmath.hpp"
#include "octocd/reference_contact.hpp"

namespace octocd::feasibility_geometry {

using dmath::D3;
using dmath::M3;

/// R^T v: a world vector in the frame whose rotation is R.
D3 mul_t(const M3& r, const D3& v);
/// Two unit vectors spanning the plane normal to unit n (with n, a right-handed frame).
std::pair<D3, D3> tangent_basis(const D3& n);

/// A point of a tangent plane (its coordinates along tangent_basis' two vectors).
struct P2 {
  double x = 0, y = 0;
  std::size_t k = 0;  ///< index of the 3D point it came from
};
/// The z of (a - o) x (b - o): > 0 when o, a, b turn counter-clockwise.
double cross2(const P2& o, const P2& a, const P2& b);
/// The 2D convex hull (Andrew's monotone chain), counter-clockwise, collinear points dropped;
/// fewer than 3 points come back as given (sorted).
std::vector<P2> hull2(std::vector<P2> p);
/// The distance from p to the segment [a, b].
double dist_segment(const P2& p, const P2& a, const P2& b);
/// Whether p lies within `tol` of the convex polygon h (counter-clockwise; 1 or 2 points:
/// a point or a segment).
bool within(const P2& p, const std::vector<P2>& h, double tol);
/// The crossing of segments ab and cd, if any (written to `out`; false when parallel or apart).
bool crossing(const P2& a, const P2& b, const P2& c, const P2& d, P2& out);

/// The separating-axis test over the face normals of hulls a and b only (their vertices
/// `va`, `vb` in the world; rotations ra, rb): the unit axis (B to A) of the least overlap,
/// with `gap` its minus (the largest gap when apart); zero when neither hull has faces.
D3 face_axes_least(const std::vector<D3>& va, const HullFeatures& ha, const M3& ra, const std::vector<D3>& vb,
                   const HullFeatures& hb, const M3& rb, double& gap);
/// A convex hull's edges (pairs of indices into its vertices, the smaller first): each
/// face's outline, the faces found as the vertices on each face normal's two support planes
/// (3 or more within 1e-9 of the hull's extent), each outline ordered about its centre;
/// each edge once, sorted.
std::vector<std::pair<std::uint32_t, std::uint32_t>> hull_edges(const HullFeatures& h);
/// The closest points of segments [p0, p1] and [q0, q1] (Ericson, Real-Time Collision
/// Detection 5.1.9): s on the first, t on the second.
void closest_on_segments(const D3& p0, const D3& p1, const D3& q0, const D3& q1, D3& s, D3& t);

/// A hull's edges and its supporting planes in its body frame: per face normal direction
/// both outward normals u with the hull's support max(u . v) (the hull is the intersection
/// of their half-spaces u . x <= support).
struct HullEdges {
  std::vector<std::pair<std::uint32_t, std::uint32_t>> edges;  ///< hull_edges
  std::vector<D3> normals;                                     ///< unit, body frame
  std::vector<double> support;                                 ///< m, one per normal
};
/// hull_edges and the supporting planes of h.
HullEdges hull_edges_and_planes(const HullFeatures& h);

}  // namespace octocd::feasibility_geometry
