/// \file bullet_checked_contacts.cpp
/// The checked convex-convex contacts of BulletWorld in rotation mode (bullet_checked_contacts.hpp):
/// polytopes, their exact separating-axis contact, and the check of each contact Bullet writes.

#include "bullet_checked_contacts.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <utility>

namespace octocd::bullet_detail {

namespace {

/// Adds `d` (normalised) to `dirs` unless a parallel direction is there already.
void add_direction(std::vector<btVector3>& dirs, btVector3 d) {
  const btScalar len = d.length();
  if (!(len > btScalar(1e-12))) return;
  d /= len;
  for (const btVector3& e : dirs)
    if (e.cross(d).length2() < btScalar(1e-12)) return;
  dirs.push_back(d);
}

/// The closest points ca on segment [p0, p1] and cb on segment [q0, q1] (the standard
/// clamped solution of the two-parameter least squares).
void closest_on_segments(const btVector3& p0, const btVector3& p1, const btVector3& q0, const btVector3& q1,
                         btVector3& ca, btVector3& cb) {
  const btVector3 d1 = p1 - p0, d2 = q1 - q0, r = p0 - q0;
  const btScalar a = d1.dot(d1), e = d2.dot(d2), f = d2.dot(r);
  btScalar s = 0, t = 0;
  if (a <= SIMD_EPSILON && e <= SIMD_EPSILON) {
  } else if (a <= SIMD_EPSILON) {
    t = btClamped(f / e, btScalar(0), btScalar(1));
  } else {
    const btScalar c = d1.dot(r);
    if (e <= SIMD_EPSILON) {
      s = btClamped(-c / a, btScalar(0), btScalar(1));
    } else {
      const btScalar b = d1.dot(d2), denom = a * e - b * b;
      s = denom > SIMD_EPSILON ? btClamped((b * f - c * e) / denom, btScalar(0), btScalar(1)) : btScalar(0);
      t = (b * s + f) / e;
      if (t < 0) {
        t = 0;
        s = btClamped(-c / a, btScalar(0), btScalar(1));
      } else if (t > 1) {
        t = 1;
        s = btClamped((b - c) / a, btScalar(0), btScalar(1));
      }
    }
  }
  ca = p0 + s * d1;
  cb = q0 + t * d2;
}

/// A convex set in a plane (2D): its hull's vertices counter-clockwise (1 point, 2 for a
/// segment, >= 3 for a polygon).
using Plane2 = std::vector<btVector3>;  // (x, y, 0)

/// The convex hull (counter-clockwise, Andrew's monotone chain) of planar points; a point
/// or a segment when they are (nearly) one.
Plane2 hull2(std::vector<btVector3> pts) {
  std::sort(pts.begin(), pts.end(), [](const btVector3& a, const btVector3& b) {
    return a.x() < b.x() || (a.x() == b.x() && a.y() < b.y());
  });
  auto turn = [](const btVector3& o, const btVector3& a, const btVector3& b) {
    return (a.x() - o.x()) * (b.y() - o.y()) - (a.y() - o.y()) * (b.x() - o.x());
  };
  Plane2 h(2 * pts.size() + 1);
  std::size_t k = 0;
  for (std::size_t i = 0; i < pts.size(); ++i) {
    while (k >= 2 && turn(h[k - 2], h[k - 1], pts[i]) <= 0) --k;
    h[k++] = pts[i];
  }
  for (std::size_t i = pts.size() - 1, t = k + 1; i-- > 0;) {
    while (k >= t && turn(h[k - 2], h[k - 1], pts[i]) <= 0) --k;
    h[k++] = pts[i];
  }
  h.resize(pts.size() <= 1 ? pts.size() : k - 1);
  if (h.size() == 2 && (h[0] - h[1]).length2() == 0) h.resize(1);
  return h;
}

/// `subject` (a point, a segment or a polygon) clipped to the convex polygon `clip`
/// (counter-clockwise, >= 3 vertices): Sutherland-Hodgman over clip's edges.
Plane2 clip2(Plane2 subject, const Plane2& clip) {
  for (std::size_t e = 0; e < clip.size() && !subject.empty(); ++e) {
    const btVector3 a = clip[e], b = clip[(e + 1) % clip.size()];
    auto inside = [&](const btVector3& p) { return (b.x() - a.x()) * (p.y() - a.y()) - (b.y() - a.y()) * (p.x() - a.x()) >= 0; };
    auto cut = [&](const btVector3& p, const btVector3& q) {
      const btScalar dp = (b.x() - a.x()) * (p.y() - a.y()) - (b.y() - a.y()) * (p.x() - a.x());
      const btScalar dq = (b.x() - a.x()) * (q.y() - a.y()) - (b.y() - a.y()) * (q.x() - a.x());
      return p + (q - p) * (dp / (dp - dq));
    };
    Plane2 out;
    const std::size_t n = subject.size();
    const std::size_t edges = n == 1 ? 0 : n == 2 ? 1 : n;
    if (n == 1) {
      if (inside(subject[0])) out.push_back(subject[0]);
    }
    for (std::size_t i = 0; i < edges; ++i) {
      const btVector3 p = subject[i], q = subject[(i + 1) % n];
      const bool ip = inside(p), iq = inside(q);
      if (ip) out.push_back(p);
      if (ip != iq) out.push_back(cut(p, q));
      if (n == 2 && iq) out.push_back(q);
    }
    subject = std::move(out);
  }
  return subject;
}

/// The point of the convex set `h` (hull2's form) nearest to p (both planar).
btVector3 nearest2(const Plane2& h, const btVector3& p) {
  if (h.size() == 1) return h[0];
  if (h.size() >= 3 && clip2({p}, h).size() == 1) return p;
  btVector3 best = h[0];
  const std::size_t edges = h.size() == 2 ? 1 : h.size();
  for (std::size_t i = 0; i < edges; ++i) {
    btVector3 ca, cb;
    closest_on_segments(p, p, h[i], h[(i + 1) % h.size()], ca, cb);
    if ((cb - p).length2() < (best - p).length2()) best = cb;
  }
  return best;
}

/// Two posed polytopes: separations along axes and the exact separating-axis contact.
class PosedPair {
 public:
  /// Absolute tolerance (m) of the checks on Bullet's contacts (EPA's accuracy is 1e-4 m).
  static constexpr btScalar kTolerance = btScalar(2e-4);
  /// Growth (m) of a bounding sphere when picking edges near the other shape: above the
  /// contact margin (sqrt(2) x 0.02 m).
  static constexpr btScalar kReach = btScalar(0.03);

  /// The world vertices are computed on first use: most pairs Bullet visits are far apart
  /// (far_apart needs none) or get no contact to check.
  PosedPair(const Polytope& a, const btTransform& ta, const Polytope& b, const btTransform& tb)
      : a_(a), b_(b), ta_(ta), tb_(tb) {}

  /// Separation (m) of A from B along the unit axis u (A on u's side): min_A u.a -
  /// max_B u.b; negative = the overlap A must move along u to leave B.
  /// Both extremes by Polytope::support in the body frames, each climb starting where
  /// the last one ended (nearby axes have nearby extreme vertices).
  btScalar separation(const btVector3& u) const {
    const btScalar max_b = b_.support(u * tb_.getBasis(), start_[0]) + u.dot(tb_.getOrigin());
    const btScalar min_a = -a_.support(-(u * ta_.getBasis()), start_[1]) + u.dot(ta_.getOrigin());
    return min_a - max_b;
  }

  /// separation(u) and separation(-u) together; the climbs toward -u start where the
  /// last ones toward -u ended (an axis and its opposite have extreme vertices far apart).
  std::pair<btScalar, btScalar> separations(const btVector3& u) const {
    const btVector3 ua = u * ta_.getBasis(), ub = u * tb_.getBasis();
    const btScalar oa = u.dot(ta_.getOrigin()), ob = u.dot(tb_.getOrigin());
    const btScalar max_b = b_.support(ub, start_[0]) + ob, min_a = -a_.support(-ua, start_[1]) + oa;
    const btScalar min_b = -b_.support(-ub, start_[2]) + ob, max_a = a_.support(ua, start_[3]) + oa;
    return {min_a - max_b, min_b - max_a};
  }

  /// Signed distance estimate (m) of world point p to A (`on_a`) or B: the largest
  /// distance of p above the supporting planes of the polytope along both signs of its
  /// face normals (0 on the surface; negative inside; for a point outside, a lower bound
  /// of its distance that is 0 only on the surface).
  btScalar surface_distance(bool on_a, const btVector3& p) const {
    const Polytope& poly = on_a ? a_ : b_;
    const btVector3 local = (on_a ? ta_ : tb_).invXform(p);
    btScalar best = -std::numeric_limits<btScalar>::infinity();
    for (std::size_t k = 0; k < poly.face_normals.size(); ++k) {
      const btScalar d = poly.face_normals[k].dot(local);
      best = std::max({best, d - poly.plus[k], -d - poly.minus[k]});
    }
    return best;
  }

  /// True when a face normal of either polytope separates them (a cheap proof that they do
  /// not penetrate).
  /// `axis` (optional) receives the separating axis u found (A on u's side: separation(u) > 0).
  bool face_axis_separates(btVector3* axis = nullptr) const {
    for (const Polytope* p : {&a_, &b_}) {
      const btMatrix3x3& basis = (p == &a_ ? ta_ : tb_).getBasis();
      for (const btVector3& n : p->face_normals) {
        const btVector3 u = basis * n;
        const auto [plus, minus] = separations(u);
        if (!(plus > 0) && !(minus > 0)) continue;
        if (axis) *axis = plus > 0 ? u : -u;
        return true;
      }
    }
    return false;
  }

  /// True when the bounding spheres about the two body origins are apart by more than
  /// `gap` (m): then no contact within `gap` exists.
  bool far_apart(btScalar gap) const {
    return (ta_.getOrigin() - tb_.getOrigin()).length() > a_.radius + b_.radius + gap;
  }

  /// The separating-axis test over the face normals of both and the cross products of
  /// their edge directions: the axis of largest separation (for penetrating convex
  /// polytopes, the minimum translation, with -separation its depth). Writes Bullet's
  /// contact: normal on B (from B to A), B's witness point, the distance (separation).
  void exact(btVector3& normal_on_b, btVector3& point_on_b, btScalar& distance) const {
    btScalar best = -std::numeric_limits<btScalar>::infinity();
    btVector3 best_u(0, 1, 0);
    // Face axes: the outward normal n of a face of A separates by min_B n.b - A's plane
    // (u = -n); one of B, min_A m.a - B's plane (u = m). One support climb each.
    const btVector3 oa = ta_.getOrigin(), ob = tb_.getOrigin();
    for (std::size_t k = 0; k < a_.outward.size(); ++k) {
      const btVector3 n = ta_.getBasis() * a_.outward[k];
      const btScalar d = -b_.support(-(n * tb_.getBasis()), start_[0]) + n.dot(ob) - (a_.outward_offset[k] + n.dot(oa));
      if (d > best) {
        best = d;
        best_u = -n;
      }
    }
    for (std::size_t k = 0; k < b_.outward.size(); ++k) {
      const btVector3 m = tb_.getBasis() * b_.outward[k];
      const btScalar d = -a_.support(-(m * ta_.getBasis()), start_[1]) + m.dot(oa) - (b_.outward_offset[k] + m.dot(ob));
      if (d > best) {
        best = d;
        best_u = m;
      }
    }
    // Edge-edge axes (Gregorius, "The Separating Axis Test between Convex Polyhedra",
    // GDC 2013): only edge pairs that build a face of the Minkowski difference A - B give
    // a candidate axis: their arcs on the Gauss map (between the two faces' outward
    // normals; B's negated) cross. The edges that support a minimum translation, or a
    // contact within the margin, lie where the shapes meet: only edges within |best| +
    // kReach of the other shape's box are crossed (a hull-hull pair of bunnies has 948 x
    // 948 edges). (|best| alone is not enough: shapes that only an edge-edge axis
    // separates have best < 0 from the faces.)
    const btScalar grow = std::max(-best, btScalar(0)) + kReach;
    const btVector3 centre_a = ta_ * a_.centroid;
    std::vector<EdgeArc> arcs_a, arcs_b;
    edge_arcs(a_, world_a(), ta_, box_of(world_b()), grow, false, arcs_a);
    edge_arcs(b_, world_b(), tb_, box_of(world_a()), grow, true, arcs_b);
    constexpr btScalar kArcTolerance = btScalar(1e-6);  // a superset of the crossing arcs is harmless
    for (const EdgeArc& ea : arcs_a) {
      for (const EdgeArc& eb : arcs_b) {
        const btScalar cba = eb.n0.dot(ea.axis), dba = eb.n1.dot(ea.axis);
        if (cba * dba > kArcTolerance) continue;
        const btScalar adc = ea.n0.dot(eb.axis), bdc = ea.n1.dot(eb.axis);
        if (adc * bdc > kArcTolerance || cba * bdc < -kArcTolerance) continue;
        btVector3 u = ea.dir.cross(eb.dir);
        const btScalar len = u.length();
        if (!(len > btScalar(1e-6))) continue;
        // Oriented out of A at its edge (Gregorius): N from A toward B, u = -N; the other
        // sign is no Minkowski-face axis (and any axis gives a lower bound only).
        u /= len;
        if (u.dot(ea.point - centre_a) < 0) u = -u;
        const btScalar d = -b_.support(-(u * tb_.getBasis()), start_[2]) + u.dot(ob) -
                           (a_.support(u * ta_.getBasis(), start_[3]) + u.dot(oa));
        if (d > best) {
          best = d;
          best_u = -u;
        }
      }
    }
    // Witnesses: the extreme vertices of A along -u and of B along +u (within the
    // tolerance); the set of smaller extent (a corner, an edge, the smaller face) gives
    // the contact's middle, the other witness lies the separation away along u.
    auto extreme = [&](const std::vector<btVector3>& w, const btVector3& dir, btVector3& mean,
                       std::vector<btVector3>& set) {
      btScalar top = -std::numeric_limits<btScalar>::infinity();
      for (const btVector3& x : w) top = std::max(top, dir.dot(x));
      btVector3 lo(0, 0, 0), hi(0, 0, 0), sum(0, 0, 0);
      set.clear();
      for (const btVector3& x : w) {
        if (dir.dot(x) < top - kTolerance) continue;
        if (set.empty()) lo = hi = x;
        lo.setMin(x);
        hi.setMax(x);
        sum += x;
        set.push_back(x);
      }
      mean = sum / btScalar(set.size());
      return (hi - lo).length();
    };
    btVector3 mean_a, mean_b;
    std::vector<btVector3> set_a, set_b;
    const btScalar extent_a = extreme(world_a(), -best_u, mean_a, set_a);
    const btScalar extent_b = extreme(world_b(), best_u, mean_b, set_b);
    if (set_a.size() == 2 && set_b.size() == 2) {
      // Edge against edge: the closest points of the two segments.
      btVector3 ca, cb;
      closest_on_segments(set_a[0], set_a[1], set_b[0], set_b[1], ca, cb);
      normal_on_b = best_u;
      distance = best;
      point_on_b = ca - best * best_u;
      return;
    }
    // The contact's middle: where the two extreme features overlap seen along u (the
    // centroid of their overlap, clipped in the plane normal to u), or, where they do not
    // overlap, the point of B's feature nearest to A's; on B's support plane. A feature
    // seen beside the other (a vertex of A past B's face) would otherwise give a point off
    // B's surface.
    btVector3 e1, e2;
    btPlaneSpace1(best_u, e1, e2);
    auto flat = [&](const std::vector<btVector3>& set) {
      std::vector<btVector3> q;
      for (const btVector3& x : set) q.emplace_back(e1.dot(x), e2.dot(x), btScalar(0));
      return hull2(std::move(q));
    };
    const Plane2 fa = flat(set_a), fb = flat(set_b);
    Plane2 overlap = fb.size() >= 3 ? clip2(fa, fb) : fa.size() >= 3 ? clip2(fb, fa) : Plane2{};
    btVector3 c(0, 0, 0);
    if (!overlap.empty()) {
      for (const btVector3& x : overlap) c += x;
      c /= btScalar(overlap.size());
    } else {
      btVector3 ma(0, 0, 0);
      for (const btVector3& x : fa) ma += x;
      c = nearest2(fb, ma / btScalar(fa.size()));
    }
    btScalar top_b = -std::numeric_limits<btScalar>::infinity();
    for (const btVector3& x : set_b) top_b = std::max(top_b, best_u.dot(x));
    normal_on_b = best_u;
    distance = best;
    point_on_b = c.x() * e1 + c.y() * e2 + top_b * best_u;
    (void)extent_a;
    (void)extent_b;
  }

 private:
  /// An edge in world space with its Gauss-map arc: unit direction, the outward normals of
  /// its two faces (n0, n1; negated for B, the Minkowski difference A - B) and n1 x n0.
  struct EdgeArc {
    btVector3 dir, n0, n1, axis;
    btVector3 point;  ///< a world point of the edge (its first vertex)
  };

  /// The world AABB of the points `w`.
  static std::pair<btVector3, btVector3> box_of(const std::vector<btVector3>& w) {
    btVector3 lo(std::numeric_limits<btScalar>::infinity(), std::numeric_limits<btScalar>::infinity(),
                 std::numeric_limits<btScalar>::infinity());
    btVector3 hi = -lo;
    for (const btVector3& x : w) {
      lo.setMin(x);
      hi.setMax(x);
    }
    return {lo, hi};
  }

  /// The edges of `p` (world vertices `w`, pose `t`) whose segment's box comes within
  /// `grow` of box `other`, as EdgeArc (faces' normals negated when `negate`).
  static void edge_arcs(const Polytope& p, const std::vector<btVector3>& w, const btTransform& t,
                        const std::pair<btVector3, btVector3>& other, btScalar grow, bool negate,
                        std::vector<EdgeArc>& arcs) {
    const btVector3 lo = other.first - btVector3(grow, grow, grow), hi = other.second + btVector3(grow, grow, grow);
    const btScalar sign = negate ? btScalar(-1) : btScalar(1);
    for (std::size_t k = 0; k < p.edges.size(); ++k) {
      const btVector3& x0 = w[static_cast<std::size_t>(p.edges[k].first)];
      const btVector3& x1 = w[static_cast<std::size_t>(p.edges[k].second)];
      btVector3 elo = x0, ehi = x0;
      elo.setMin(x1);
      ehi.setMax(x1);
      if (elo.x() > hi.x() || elo.y() > hi.y() || elo.z() > hi.z() || ehi.x() < lo.x() || ehi.y() < lo.y() ||
          ehi.z() < lo.z())
        continue;
      btVector3 d = x1 - x0;
      const btScalar len = d.length();
      if (!(len > btScalar(1e-12))) continue;
      EdgeArc a;
      a.dir = d / len;
      a.n0 = sign * (t.getBasis() * p.edge_faces[k].first);
      a.n1 = sign * (t.getBasis() * p.edge_faces[k].second);
      a.axis = a.n1.cross(a.n0);
      a.point = x0;
      arcs.push_back(a);
    }
  }

  const Polytope& a_;
  const Polytope& b_;
  btTransform ta_, tb_;
  /// The vertices of `p` posed by `t`, into `w` once.
  static const std::vector<btVector3>& posed(const Polytope& p, const btTransform& t, std::vector<btVector3>& w) {
    if (w.empty()) {
      w.reserve(p.vertices.size());
      for (const btVector3& x : p.vertices) w.push_back(t * x);
    }
    return w;
  }
  const std::vector<btVector3>& world_a() const { return posed(a_, ta_, wa_); }
  const std::vector<btVector3>& world_b() const { return posed(b_, tb_, wb_); }

  mutable std::vector<btVector3> wa_, wb_;  ///< world vertices, filled on first use
  /// Where the next support climbs start: B along +u, A along -u (separation), B along
  /// -u, A along +u (the opposite axis in separations()).
  mutable std::array<int, 4> start_{};
};

}  // namespace

/// The box of half extents `he` as a polytope.
Polytope box_polytope(const btVector3& he) {
  Polytope p;
  for (int k = 0; k < 8; ++k)
    p.vertices.emplace_back((k & 1) ? he.x() : -he.x(), (k & 2) ? he.y() : -he.y(), (k & 4) ? he.z() : -he.z());
  for (int k = 0; k < 3; ++k) {
    btVector3 axis(0, 0, 0);
    axis[k] = 1;
    p.face_normals.push_back(axis);
    p.outward.push_back(axis);
    p.outward.push_back(-axis);
    for (int v = 0; v < 8; ++v) {
      if (v & (1 << k)) continue;
      p.edges.emplace_back(v, v | (1 << k));
      // The edge along axis k at corner v: its faces are those of the two other axes, on
      // the sides of v's coordinates.
      btVector3 n[2];
      int m = 0;
      for (int j = 0; j < 3; ++j) {
        if (j == k) continue;
        n[m] = btVector3(0, 0, 0);
        n[m][j] = (v & (1 << j)) ? 1 : -1;
        ++m;
      }
      p.edge_faces.emplace_back(n[0], n[1]);
    }
  }
  p.finish();
  return p;
}

/// A convex hull (convex_hull.hpp: its vertices, faces and planes) as a polytope; each
/// edge once, with the outward normals of the two faces that share it.
Polytope hull_polytope(const ConvexHull& h) {
  Polytope p;
  for (const auto& v : h.vertices) p.vertices.emplace_back(btScalar(v[0]), btScalar(v[1]), btScalar(v[2]));
  std::map<std::pair<int, int>, std::pair<int, int>> faces_of_edge;  // (lower, higher vertex) -> its two faces
  for (std::size_t f = 0; f < h.faces.size(); ++f) {
    const btVector3 n(btScalar(h.planes[f][0]), btScalar(h.planes[f][1]), btScalar(h.planes[f][2]));
    add_direction(p.face_normals, n);
    p.outward.push_back(n);
    const std::vector<std::uint32_t>& idx = h.faces[f];
    for (std::size_t k = 0; k < idx.size(); ++k) {
      const int a = static_cast<int>(idx[k]), b = static_cast<int>(idx[(k + 1) % idx.size()]);
      const auto at = faces_of_edge.emplace(std::make_pair(std::min(a, b), std::max(a, b)),
                                            std::make_pair(static_cast<int>(f), -1));
      if (!at.second) at.first->second.second = static_cast<int>(f);
    }
  }
  for (const auto& e : faces_of_edge) {
    p.edges.push_back(e.first);
    const int f0 = e.second.first, f1 = e.second.second;
    p.edge_faces.emplace_back(p.outward[static_cast<std::size_t>(f0)],
                              f1 >= 0 ? p.outward[static_cast<std::size_t>(f1)] : btVector3(0, 0, 0));
  }
  p.finish();
  return p;
}

/// btManifoldResult that checks each contact on the polytopes before it reaches the
/// manifold.
class CheckedConvexAlgorithm::CheckedResult : public btManifoldResult {
 public:
  CheckedResult(const btCollisionObjectWrapper* w0, const btCollisionObjectWrapper* w1, const PosedPair& pair,
                BulletNarrowphaseCounts& counts)
      : btManifoldResult(w0, w1), pair_(pair), counts_(counts) {}
  bool added = false;

  void addContactPoint(const btVector3& normal, const btVector3& point, btScalar distance) override {
    ++counts_.checked;
    const btScalar tol = PosedPair::kTolerance + btScalar(1e-3) * std::abs(distance);
    const btScalar along = pair_.separation(normal);
    // Apart: no overlap along the normal; penetrating: the separation along it is the
    // distance. Either way the witness points lie on their shapes' surfaces (apart:
    // within the distance they report, GJK's witnesses being that far from exact).
    const btScalar on = tol + std::max(distance, btScalar(0));
    const bool good = (distance > 0 ? along > -tol : std::abs(along - distance) <= tol) &&
                      std::abs(pair_.surface_distance(false, point)) <= on &&
                      std::abs(pair_.surface_distance(true, point + distance * normal)) <= on;
    if (good) {
      add_unchecked(normal, point, distance);
      return;
    }
    btVector3 n, p;
    btScalar d = 0;
    pair_.exact(n, p, d);
    // Apart, the separating axis's separation is a lower bound of the distance, and its
    // witness points are the closest points only where they lie on both surfaces (a
    // vertex or edge over a face, edge against edge); otherwise no contact is added (an
    // apart contact is optional: the manifold keeps its earlier points).
    if (d > 0 && !(std::abs(pair_.surface_distance(false, p)) <= tol + d &&
                   std::abs(pair_.surface_distance(true, p + d * n)) <= tol + d)) {
      ++counts_.dropped;
      return;
    }
    ++counts_.replaced;
    add_unchecked(n, p, d);
  }

  void add_unchecked(const btVector3& normal, const btVector3& point, btScalar distance) {
    added = true;
    btManifoldResult::addContactPoint(normal, point, distance);
  }

 private:
  const PosedPair& pair_;
  BulletNarrowphaseCounts& counts_;
};

void CheckedConvexAlgorithm::processCollision(const btCollisionObjectWrapper* w0, const btCollisionObjectWrapper* w1,
                                              const btDispatcherInfo& info, btManifoldResult* out) {
  const auto ia = registry_.find(w0->getCollisionShape());
  const auto ib = registry_.find(w1->getCollisionShape());
  if (ia == registry_.end() || ib == registry_.end()) {
    btConvexConvexAlgorithm::processCollision(w0, w1, info, out);
    return;
  }
  const PosedPair pair(ia->second, w0->getWorldTransform(), ib->second, w1->getWorldTransform());
  CheckedResult checked(w0, w1, pair, counts_);
  checked.m_closestPointDistanceThreshold = out->m_closestPointDistanceThreshold;
  btConvexConvexAlgorithm::processCollision(w0, w1, info, &checked);
  btPersistentManifold* manifold = checked.getPersistentManifold();
  out->setPersistentManifold(manifold);
  if (checked.added || manifold == nullptr) return;
  const btScalar threshold = manifold->getContactBreakingThreshold();
  if (pair.far_apart(threshold)) return;
  // The axis that separated the pair last time first (the bodies moved little since).
  if (has_separating_axis_ && pair.separation(separating_axis_) > 0) return;
  if (pair.face_axis_separates(&separating_axis_)) {
    has_separating_axis_ = true;
    return;
  }
  btVector3 normal, point;
  btScalar distance = 0;
  pair.exact(normal, point, distance);
  has_separating_axis_ = distance > 0;
  if (distance > 0) {  // apart (the separation is a lower bound of the distance)
    separating_axis_ = normal;
    return;
  }
  ++counts_.added;
  checked.add_unchecked(normal, point, distance);
}

}  // namespace octocd::bullet_detail
