// The impulse-feasibility row's contact geometry (feasibility_geometry.hpp): tangent-plane
// hulls, segment crossings and closest points, hull edges and supporting planes.
#include "feasibility_geometry.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace octocd::feasibility_geometry {

using namespace dmath;

/// R^T v: a world vector in the frame whose rotation is R.
D3 mul_t(const M3& r, const D3& v) {
  return {r[0] * v[0] + r[3] * v[1] + r[6] * v[2], r[1] * v[0] + r[4] * v[1] + r[7] * v[2],
          r[2] * v[0] + r[5] * v[1] + r[8] * v[2]};
}

/// Two unit vectors spanning the plane normal to unit n.
std::pair<D3, D3> tangent_basis(const D3& n) {
  const D3 a = std::fabs(n[0]) < 0.6 ? D3{1, 0, 0} : std::fabs(n[1]) < 0.6 ? D3{0, 1, 0} : D3{0, 0, 1};
  const D3 e1 = unit(cross3(n, a));
  return {e1, cross3(n, e1)};
}

double cross2(const P2& o, const P2& a, const P2& b) { return (a.x - o.x) * (b.y - o.y) - (a.y - o.y) * (b.x - o.x); }

/// The 2D convex hull (Andrew's monotone chain), counter-clockwise, collinear points dropped.
std::vector<P2> hull2(std::vector<P2> p) {
  std::sort(p.begin(), p.end(), [](const P2& a, const P2& b) { return a.x < b.x || (a.x == b.x && a.y < b.y); });
  if (p.size() < 3) return p;
  std::vector<P2> h(2 * p.size());
  std::size_t k = 0;
  for (std::size_t i = 0; i < p.size(); ++i) {
    while (k >= 2 && cross2(h[k - 2], h[k - 1], p[i]) <= 0) --k;
    h[k++] = p[i];
  }
  for (std::size_t i = p.size() - 1, t = k + 1; i > 0; --i) {
    while (k >= t && cross2(h[k - 2], h[k - 1], p[i - 1]) <= 0) --k;
    h[k++] = p[i - 1];
  }
  h.resize(k - 1);
  return h;
}

double dist_segment(const P2& p, const P2& a, const P2& b) {
  const double dx = b.x - a.x, dy = b.y - a.y, l2 = dx * dx + dy * dy;
  double t = l2 > 0 ? ((p.x - a.x) * dx + (p.y - a.y) * dy) / l2 : 0.0;
  t = std::min(1.0, std::max(0.0, t));
  return std::hypot(p.x - a.x - t * dx, p.y - a.y - t * dy);
}

/// Whether p lies within `tol` of the convex polygon h (counter-clockwise; 1 or 2 points:
/// a point or a segment).
bool within(const P2& p, const std::vector<P2>& h, double tol) {
  if (h.empty()) return false;
  if (h.size() == 1) return std::hypot(p.x - h[0].x, p.y - h[0].y) <= tol;
  if (h.size() == 2) return dist_segment(p, h[0], h[1]) <= tol;
  for (std::size_t i = 0; i < h.size(); ++i) {
    const P2& a = h[i];
    const P2& b = h[(i + 1) % h.size()];
    const double l = std::hypot(b.x - a.x, b.y - a.y);
    if (l > 0 && cross2(a, b, p) / l < -tol) return false;
  }
  return true;
}

/// The crossing of segments ab and cd, if any.
bool crossing(const P2& a, const P2& b, const P2& c, const P2& d, P2& out) {
  const double rx = b.x - a.x, ry = b.y - a.y, sx = d.x - c.x, sy = d.y - c.y;
  const double den = rx * sy - ry * sx;
  if (std::fabs(den) < 1e-300) return false;
  const double t = ((c.x - a.x) * sy - (c.y - a.y) * sx) / den;
  const double u = ((c.x - a.x) * ry - (c.y - a.y) * rx) / den;
  if (t < 0 || t > 1 || u < 0 || u > 1) return false;
  out.x = a.x + t * rx;
  out.y = a.y + t * ry;
  return true;
}

/// The separating-axis test over the face normals of hulls a and b only (their vertices
/// `va`, `vb` in the world; rotations ra, rb): the unit axis (B to A) of the least overlap,
/// with `gap` its minus (the largest gap when apart); zero when neither hull has faces.
D3 face_axes_least(const std::vector<D3>& va, const HullFeatures& ha, const M3& ra, const std::vector<D3>& vb,
                   const HullFeatures& hb, const M3& rb, double& gap) {
  D3 best{};
  double least = std::numeric_limits<double>::infinity();
  auto range = [](const std::vector<D3>& v, const D3& u) {
    double lo = std::numeric_limits<double>::infinity(), hi = -lo;
    for (const D3& x : v) {
      const double t = dot3(u, x);
      lo = std::min(lo, t);
      hi = std::max(hi, t);
    }
    return std::pair<double, double>{lo, hi};
  };
  for (const auto& [h, r] : {std::pair<const HullFeatures*, const M3*>{&ha, &ra}, {&hb, &rb}})
    for (const auto& fl : h->face_normals) {
      const D3 u = unit(mul(*r, D3{fl[0], fl[1], fl[2]}));
      const auto [a0, a1] = range(va, u);
      const auto [b0, b1] = range(vb, u);
      // A moved along +u by b1 - a0, or along -u by a1 - b0, separates them along u.
      if (b1 - a0 < least) {
        least = b1 - a0;
        best = u;
      }
      if (a1 - b0 < least) {
        least = a1 - b0;
        best = -1.0 * u;
      }
    }
  gap = -least;
  return best;
}

/// A convex hull's edges (pairs of indices into its vertices): each face's outline, the
/// faces found as the vertices on each face normal's two support planes (3 or more within
/// `tol` of it), each outline ordered about its centre; each edge once.
std::vector<std::pair<std::uint32_t, std::uint32_t>> hull_edges(const HullFeatures& h) {
  std::vector<std::pair<std::uint32_t, std::uint32_t>> edges;
  std::vector<D3> v(h.vertices.size());
  double extent = 0;
  for (std::size_t k = 0; k < v.size(); ++k) {
    v[k] = D3{h.vertices[k][0], h.vertices[k][1], h.vertices[k][2]};
    extent = std::max(extent, len3(v[k]));
  }
  const double tol = 1e-9 * std::max(1.0, extent);
  for (const auto& fl : h.face_normals)
    for (const double sign : {1.0, -1.0}) {
      const D3 n = sign * unit(D3{fl[0], fl[1], fl[2]});
      double top = -std::numeric_limits<double>::infinity();
      for (const D3& p : v) top = std::max(top, dot3(n, p));
      std::vector<std::uint32_t> face;
      D3 c{};
      for (std::size_t k = 0; k < v.size(); ++k)
        if (dot3(n, v[k]) >= top - tol) {
          face.push_back(std::uint32_t(k));
          c = c + v[k];
        }
      if (face.size() < 3) continue;
      c = (1.0 / double(face.size())) * c;
      const auto [e1, e2] = tangent_basis(n);
      std::sort(face.begin(), face.end(), [&](std::uint32_t a, std::uint32_t b) {
        return std::atan2(dot3(e2, v[a] - c), dot3(e1, v[a] - c)) < std::atan2(dot3(e2, v[b] - c), dot3(e1, v[b] - c));
      });
      for (std::size_t k = 0; k < face.size(); ++k) {
        const std::uint32_t a = face[k], b = face[(k + 1) % face.size()];
        edges.emplace_back(std::min(a, b), std::max(a, b));
      }
    }
  std::sort(edges.begin(), edges.end());
  edges.erase(std::unique(edges.begin(), edges.end()), edges.end());
  return edges;
}

/// The closest points of segments [p0, p1] and [q0, q1] (Ericson, Real-Time Collision
/// Detection 5.1.9): s on the first, t on the second.
void closest_on_segments(const D3& p0, const D3& p1, const D3& q0, const D3& q1, D3& s, D3& t) {
  const D3 d1 = p1 - p0, d2 = q1 - q0, r = p0 - q0;
  const double a = dot3(d1, d1), e = dot3(d2, d2), f = dot3(d2, r);
  double u = 0, w = 0;
  if (a <= 1e-300 && e <= 1e-300) {
    s = p0;
    t = q0;
    return;
  }
  if (a <= 1e-300) {
    w = std::clamp(f / e, 0.0, 1.0);
  } else {
    const double c = dot3(d1, r);
    if (e <= 1e-300) {
      u = std::clamp(-c / a, 0.0, 1.0);
    } else {
      const double b = dot3(d1, d2), den = a * e - b * b;
      u = den > 0 ? std::clamp((b * f - c * e) / den, 0.0, 1.0) : 0.0;
      w = (b * u + f) / e;
      if (w < 0) {
        w = 0;
        u = std::clamp(-c / a, 0.0, 1.0);
      } else if (w > 1) {
        w = 1;
        u = std::clamp((b - c) / a, 0.0, 1.0);
      }
    }
  }
  s = p0 + u * d1;
  t = q0 + w * d2;
}

HullEdges hull_edges_and_planes(const HullFeatures& h) {
  HullEdges out;
  out.edges = hull_edges(h);
  for (const auto& fl : h.face_normals)
    for (const double sign : {1.0, -1.0}) {
      const D3 u = sign * unit(D3{fl[0], fl[1], fl[2]});
      double top = -std::numeric_limits<double>::infinity();
      for (const auto& v : h.vertices) top = std::max(top, dot3(u, D3{v[0], v[1], v[2]}));
      out.normals.push_back(u);
      out.support.push_back(top);
    }
  return out;
}

}  // namespace octocd::feasibility_geometry
