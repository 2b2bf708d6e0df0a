/// \file bullet_world.cpp
/// octocd::BulletWorld: the scene in btDiscreteDynamicsWorld (see bullet_world.hpp for
/// every setting and why).

#include "octocd/bullet_world.hpp"
#include "octocd/adapter_rows.hpp"
#include "octocd/convex_hull.hpp"
#include "octocd/reference_world.hpp"
#include "octocd/version.hpp"

#include <fmt/format.h>

#include <btBulletDynamicsCommon.h>
#include <BulletCollision/CollisionDispatch/btConvexConvexAlgorithm.h>
#include <BulletCollision/NarrowPhaseCollision/btGjkEpaPenetrationDepthSolver.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <limits>
#include <map>
#include <memory>
#include <unordered_map>
#include <utility>
#include <vector>

namespace octocd {

namespace {

btVector3 to_bt(const Vec3& v) { return btVector3(v.x, v.y, v.z); }
Vec3 from_bt(const btVector3& v) {
  return {static_cast<float>(v.x()), static_cast<float>(v.y()), static_cast<float>(v.z())};
}
// btQuaternion is (x, y, z, w); octocd's Quat is (w, x, y, z).
btQuaternion to_bt(const Quat& q) { return btQuaternion(q.x, q.y, q.z, q.w); }
Quat from_bt(const btQuaternion& q) {
  return {static_cast<float>(q.w()), static_cast<float>(q.x()), static_cast<float>(q.y()),
          static_cast<float>(q.z())};
}

/// btDiscreteDynamicsWorld with its step's phases timed, so the Bullet engine reports
/// the stages octocd has (docs/architecture.md, "Engine"). stepSimulation(dt, 0) runs
/// internalSingleStepSimulation once: predictUnconstraintMotion,
/// performDiscreteCollisionDetection (updateAabbs, computeOverlappingPairs,
/// dispatchAllCollisionPairs), calculateSimulationIslands, solveConstraints,
/// integrateTransforms, then bookkeeping. The overrides only time the base calls.
class TimedDynamicsWorld : public btDiscreteDynamicsWorld {
 public:
  using btDiscreteDynamicsWorld::btDiscreteDynamicsWorld;

  double aabbs_ms = 0.0;       ///< updateAabbs: world AABBs and the dbvt leaf updates
  double broadphase_ms = 0.0;  ///< computeOverlappingPairs: dbvt pair search and cache
  double narrow_ms = 0.0;      ///< dispatchAllCollisionPairs: box-box contact manifolds
  double solve_ms = 0.0;       ///< calculateSimulationIslands + solveConstraints

  void reset_times() { aabbs_ms = broadphase_ms = narrow_ms = solve_ms = 0.0; }

  void updateAabbs() override {
    const auto t0 = std::chrono::steady_clock::now();
    btDiscreteDynamicsWorld::updateAabbs();
    aabbs_ms += ms_since(t0);
  }
  void computeOverlappingPairs() override {
    const auto t0 = std::chrono::steady_clock::now();
    btDiscreteDynamicsWorld::computeOverlappingPairs();
    broadphase_ms += ms_since(t0);
  }
  /// Rotation mode: drop manifold points whose normal is more than kStaleNormalDeg off
  /// the normal of a point found in this step (see prune_stale_normals).
  bool prune_stale = false;
  std::int64_t pruned = 0;  ///< manifold points dropped so far

  void performDiscreteCollisionDetection() override {
    const double before = aabbs_ms + broadphase_ms;
    const auto t0 = std::chrono::steady_clock::now();
    btDiscreteDynamicsWorld::performDiscreteCollisionDetection();
    if (prune_stale) prune_stale_normals();
    narrow_ms += std::max(0.0, ms_since(t0) - (aabbs_ms + broadphase_ms - before));
  }

  /// Largest angle (degrees) between a kept manifold point's normal and the newest one's.
  static constexpr double kStaleNormalDeg = 20.0;

  /// A persistent manifold keeps each point with the normal it was found with while the
  /// bodies turn, and the solver still pushes along it: on rot-pile-1000 a cube pair kept
  /// a point 50 degrees off the minimum translation, with a normal impulse, beside a point
  /// found in the same step on the minimum translation. Points of one manifold lie on one
  /// contact plane between two convex shapes, so where the narrow phase found a point in
  /// this step (lifetime 0), the points whose normal is more than kStaleNormalDeg off its
  /// normal are dropped before the solver runs (their warm-start impulse with them).
  void prune_stale_normals() {
    const btScalar cos_max = static_cast<btScalar>(std::cos(kStaleNormalDeg * 3.14159265358979323846 / 180.0));
    btDispatcher* d = getDispatcher();
    for (int k = 0; k < d->getNumManifolds(); ++k) {
      btPersistentManifold* pm = d->getManifoldByIndexInternal(k);
      int fresh = -1;  // the newest point (smallest lifetime), the deepest of those
      for (int j = 0; j < pm->getNumContacts(); ++j) {
        const btManifoldPoint& p = pm->getContactPoint(j);
        if (fresh < 0 || p.getLifeTime() < pm->getContactPoint(fresh).getLifeTime() ||
            (p.getLifeTime() == pm->getContactPoint(fresh).getLifeTime() &&
             p.getDistance() < pm->getContactPoint(fresh).getDistance()))
          fresh = j;
      }
      if (fresh < 0) continue;
      const btVector3 n = pm->getContactPoint(fresh).m_normalWorldOnB;
      for (int j = pm->getNumContacts() - 1; j >= 0; --j) {
        if (pm->getContactPoint(j).m_normalWorldOnB.dot(n) >= cos_max) continue;
        pm->removeContactPoint(j);
        ++pruned;
      }
    }
  }
  void calculateSimulationIslands() override {
    const auto t0 = std::chrono::steady_clock::now();
    btDiscreteDynamicsWorld::calculateSimulationIslands();
    solve_ms += ms_since(t0);
  }
  void solveConstraints(btContactSolverInfo& info) override {
    const auto t0 = std::chrono::steady_clock::now();
    btDiscreteDynamicsWorld::solveConstraints(info);
    solve_ms += ms_since(t0);
  }
};

/// btSequentialImpulseConstraintSolver plus one pass after its last iteration (rotation
/// mode, BulletOptions::coulomb_friction): every friction row whose contact row ends with
/// a normal impulse of 0 is brought back to 0 through resolveSingleConstraintRowGeneric
/// with both limits 0 (the bodies get the opposite impulse). Bullet solves a friction row
/// only while its contact's normal impulse is positive (solveSingleIteration: `if
/// (totalImpulse > 0)`), so a contact whose normal impulse drops to 0 keeps the friction
/// of an earlier iteration or of the warm start: a tangential impulse with no normal
/// impulse, outside the Coulomb cone (rot-drop-220: 16 of 4914 contacts). Rows with a
/// positive normal impulse are left as Bullet solved them (within mu J_n of their row).
class CoulombSolver : public btSequentialImpulseConstraintSolver {
 public:
  bool project = true;           ///< the pass above on (false: stock Bullet)
  std::int64_t projected = 0;    ///< friction rows brought back to the cone so far

 protected:
  btScalar solveGroupCacheFriendlyIterations(btCollisionObject** bodies, int num_bodies,
                                             btPersistentManifold** manifolds, int num_manifolds,
                                             btTypedConstraint** constraints, int num_constraints,
                                             const btContactSolverInfo& info, btIDebugDraw* draw) override {
    const btScalar r = btSequentialImpulseConstraintSolver::solveGroupCacheFriendlyIterations(
        bodies, num_bodies, manifolds, num_manifolds, constraints, num_constraints, info, draw);
    if (!project) return r;
    for (int j = 0; j < m_tmpSolverContactFrictionConstraintPool.size(); ++j) {
      btSolverConstraint& f = m_tmpSolverContactFrictionConstraintPool[j];
      if (f.m_appliedImpulse == btScalar(0)) continue;
      if (m_tmpSolverContactConstraintPool[f.m_frictionIndex].m_appliedImpulse > btScalar(0)) continue;
      f.m_lowerLimit = 0;
      f.m_upperLimit = 0;
      resolveSingleConstraintRowGeneric(m_tmpSolverBodyPool[f.m_solverBodyIdA], m_tmpSolverBodyPool[f.m_solverBodyIdB], f);
      ++projected;
    }
    return r;
  }
};

/// A convex polytope in its body frame: what the exact separating-axis test needs.
struct Polytope {
  std::vector<btVector3> vertices;      ///< m, body frame
  std::vector<btVector3> face_normals;  ///< unit, one per face (the sign does not matter)
  std::vector<std::pair<int, int>> edges;  ///< vertex indices of each edge, once
  /// Per edge, the outward unit normals of its two faces (body frame): the edge's arc on
  /// the Gauss map, for the Minkowski-face test of the edge-edge axes (PosedPair::exact).
  std::vector<std::pair<btVector3, btVector3>> edge_faces;
  std::vector<btVector3> outward;        ///< outward unit normal of every face (body frame)
  std::vector<btScalar> outward_offset;  ///< per face: max n.v over the vertices (its plane, m)
  btVector3 centroid{0, 0, 0};           ///< mean of the vertices: inside the polytope
  std::vector<btScalar> plus, minus;    ///< per face normal n: max n.v and max -n.v (m)
  btScalar radius = 0;                  ///< largest |v| (m): the bounding sphere about the origin

  /// The neighbours of vertex k along the edges: adjacent[adjacent_start[k] ..
  /// adjacent_start[k + 1]), for support() (CSR layout).
  std::vector<int> adjacent_start, adjacent;

  /// max over the vertices of d.v (body frame) by hill climbing on the edge graph from
  /// vertex `start` (in: where to begin, e.g. the last answer; out: the vertex found).
  /// On a convex polytope a vertex none of whose neighbours is higher along d is a highest
  /// one, so this is exact, in O(path length x degree) instead of O(vertices).
  btScalar support(const btVector3& d, int& start) const {
    int at = start >= 0 && static_cast<std::size_t>(start) < vertices.size() ? start : 0;
    btScalar best = d.dot(vertices[static_cast<std::size_t>(at)]);
    for (bool moved = true; moved;) {
      moved = false;
      for (int k = adjacent_start[static_cast<std::size_t>(at)]; k < adjacent_start[static_cast<std::size_t>(at) + 1]; ++k) {
        const int nb = adjacent[static_cast<std::size_t>(k)];
        const btScalar h = d.dot(vertices[static_cast<std::size_t>(nb)]);
        if (h > best) {
          best = h;
          at = nb;
          moved = true;
        }
      }
    }
    start = at;
    return best;
  }

  /// Fills plus, minus, radius and the adjacency from vertices, edges and face_normals.
  void finish() {
    std::vector<std::vector<int>> nb(vertices.size());
    for (const auto& [i, j] : edges) {
      nb[static_cast<std::size_t>(i)].push_back(j);
      nb[static_cast<std::size_t>(j)].push_back(i);
    }
    adjacent_start.assign(1, 0);
    for (const auto& list : nb) {
      adjacent.insert(adjacent.end(), list.begin(), list.end());
      adjacent_start.push_back(static_cast<int>(adjacent.size()));
    }
    for (const btVector3& v : vertices) {
      radius = std::max(radius, v.length());
      centroid += v;
    }
    if (!vertices.empty()) centroid /= btScalar(vertices.size());
    for (const btVector3& n : outward) {
      btScalar h = -std::numeric_limits<btScalar>::infinity();
      for (const btVector3& v : vertices) h = std::max(h, n.dot(v));
      outward_offset.push_back(h);
    }
    for (const btVector3& n : face_normals) {
      btScalar hp = -std::numeric_limits<btScalar>::infinity(), hm = hp;
      for (const btVector3& v : vertices) {
        hp = std::max(hp, n.dot(v));
        hm = std::max(hm, -n.dot(v));
      }
      plus.push_back(hp);
      minus.push_back(hm);
    }
  }
};

/// Adds `d` (normalised) to `dirs` unless a parallel direction is there already.
void add_direction(std::vector<btVector3>& dirs, btVector3 d) {
  const btScalar len = d.length();
  if (!(len > btScalar(1e-12))) return;
  d /= len;
  for (const btVector3& e : dirs)
    if (e.cross(d).length2() < btScalar(1e-12)) return;
  dirs.push_back(d);
}

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


/// Bullet's convex-convex algorithm (GJK/EPA) on box-hull and hull-hull pairs, with each
/// contact it writes checked on the two polytopes (rotation mode).
///
/// Bullet's GJK/EPA fails now and then on a box against a convex hull: EPA returns no
/// result, or GJK stops on a degenerate simplex, and btGjkPairDetector then writes a
/// contact along a stale axis ((0, 1, 0), its initial guess, or (1, 0, 0)) with a
/// positive distance while the shapes penetrate (rot-pile-1000: a cube corner 4.4 mm
/// inside an icosphere reported 0.5 mm apart along an axis on which they overlap by
/// 94 mm; 39 of 28,574 penetrating rows 41-89 degrees off FCL's minimum translation).
/// Every contact is checked. A penetrating one (distance <= 0): the separation of the two
/// polytopes along its normal must equal its distance and its two witness points must lie
/// on their shapes' surfaces (each within PosedPair::kTolerance + 0.1%), which holds for a
/// correct minimum-translation answer (GJK also returned witness points 57 mm off the
/// icosphere along a correct normal). One that reports the shapes apart: they must not
/// overlap along its normal (the stale-axis failure above overlaps by centimetres). A contact that fails is replaced by the
/// separating-axis test's exact one (PosedPair::exact). A pair GJK found farther apart
/// than the breaking threshold while its bounding spheres overlap gets the separating-axis
/// contact when the polytopes penetrate (a wrong "apart" answer adds no contact at all). Shapes without a polytope (none in
/// rotation mode) go to Bullet unchecked.
class CheckedConvexAlgorithm : public btConvexConvexAlgorithm {
 public:
  using Registry = std::unordered_map<const btCollisionShape*, Polytope>;

  CheckedConvexAlgorithm(btPersistentManifold* mf, const btCollisionAlgorithmConstructionInfo& ci,
                         const btCollisionObjectWrapper* w0, const btCollisionObjectWrapper* w1,
                         btConvexPenetrationDepthSolver* pd, const Registry& registry, BulletNarrowphaseCounts& counts)
      : btConvexConvexAlgorithm(mf, ci, w0, w1, pd, 0, 0), registry_(registry), counts_(counts) {}

  void processCollision(const btCollisionObjectWrapper* w0, const btCollisionObjectWrapper* w1,
                        const btDispatcherInfo& info, btManifoldResult* out) override {
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

  /// Creates CheckedConvexAlgorithm for the registered shape pairs.
  struct CreateFunc : public btCollisionAlgorithmCreateFunc {
    btConvexPenetrationDepthSolver* pd = nullptr;
    const Registry* registry = nullptr;
    BulletNarrowphaseCounts* counts = nullptr;
    btCollisionAlgorithm* CreateCollisionAlgorithm(btCollisionAlgorithmConstructionInfo& ci,
                                                   const btCollisionObjectWrapper* w0,
                                                   const btCollisionObjectWrapper* w1) override {
      void* mem = ci.m_dispatcher1->allocateCollisionAlgorithm(sizeof(CheckedConvexAlgorithm));
      return new (mem) CheckedConvexAlgorithm(ci.m_manifold, ci, w0, w1, pd, *registry, *counts);
    }
  };

 private:
  /// btManifoldResult that checks each contact on the polytopes before it reaches the
  /// manifold.
  class CheckedResult : public btManifoldResult {
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

  const Registry& registry_;
  BulletNarrowphaseCounts& counts_;
  /// A world axis u that separated the pair (A on u's side) when GJK last found no
  /// contact: tried first next time (frame-to-frame coherence), one separation each.
  btVector3 separating_axis_{0, 1, 0};
  bool has_separating_axis_ = false;
};

}  // namespace

struct BulletWorld::Impl {
  double dt = 0.001;
  float slop = 0.001f;
  std::unique_ptr<btDefaultCollisionConfiguration> config;
  // Rotation mode: box-hull and hull-hull pairs through CheckedConvexAlgorithm.
  CheckedConvexAlgorithm::Registry polytopes;  // by shape
  BulletNarrowphaseCounts checked;
  btGjkEpaPenetrationDepthSolver epa;
  CheckedConvexAlgorithm::CreateFunc convex_convex;
  std::unique_ptr<btCollisionDispatcher> dispatcher;
  std::unique_ptr<btDbvtBroadphase> broadphase;
  std::unique_ptr<CoulombSolver> solver;
  std::unique_ptr<TimedDynamicsWorld> world;
  std::vector<float> w;                 // inverse mass per body (0 = static)
  std::uint64_t static_static = 0;      // static_static_pairs(model), constant
  std::vector<std::unique_ptr<btCollisionShape>> shapes;  // one per octocd shape (dynamic bodies)
  // Hull mode: a static body of a mesh shape collides as its triangles (one per shape).
  std::vector<std::unique_ptr<btTriangleMesh>> triangle_meshes;
  std::vector<std::unique_ptr<btCollisionShape>> static_shapes;  // per octocd shape; null: shapes[k]
  std::vector<std::unique_ptr<btRigidBody>> bodies;  // index = body id
  BodyState state;
  FrameMetrics metrics;
  std::int64_t frame = 0;
  // Rotation mode (bullet_world.hpp).
  bool rotation = false;
  // The shapes are the declared geometry (hull mode, or rotation): margins 0, checked
  // narrow phase, absolute breaking threshold, FrameRecord and version 2 traces.
  bool exact = false;
  BulletSettings settings;
  std::string geometry;  // collision_geometry()
  bool recording = false;
  Vec3 gravity;
  RotationTraits traits;
  FrameRecord record;
  std::vector<ContactRecord> no_contacts;

  ~Impl() {
    if (world) {
      // Every overlapping pair leaves through the pair cache's hash (O(1) a pair, its
      // collision algorithm freed) while both proxies live; then ~btCollisionWorld
      // destroys each body's proxy on an empty cache. removeRigidBody per body would
      // scan every pair (cleanProxyFromPairs, removeOverlappingPairsContainingProxy)
      // and the world's list of dynamic bodies for each body: O(bodies x pairs), over
      // 80 s for 10^5 separated boxes.
      btOverlappingPairCache* cache = broadphase->getOverlappingPairCache();
      std::vector<std::pair<btBroadphaseProxy*, btBroadphaseProxy*>> pairs;
      const btBroadphasePairArray& all = cache->getOverlappingPairArray();
      pairs.reserve(static_cast<std::size_t>(all.size()));
      for (int k = 0; k < all.size(); ++k) pairs.emplace_back(all[k].m_pProxy0, all[k].m_pProxy1);
      for (const auto& [p0, p1] : pairs) cache->removeOverlappingPair(p0, p1, dispatcher.get());
    }
    world.reset();  // before the bodies, solver, broadphase, dispatcher and config it uses
  }

  void read_state() {
    for (std::size_t i = 0; i < bodies.size(); ++i) {
      state.x[i] = from_bt(bodies[i]->getWorldTransform().getOrigin());
      state.v[i] = from_bt(bodies[i]->getLinearVelocity());
      if (rotation) {
        state.q[i] = from_bt(bodies[i]->getWorldTransform().getRotation());
        state.omega[i] = from_bt(bodies[i]->getAngularVelocity());
      }
    }
  }

  // Rotation mode: record's aabbs, pairs, contacts and confirmed from Bullet's broadphase
  // and manifolds after stepSimulation (record.x_pre ... already set).
  void fill_record();
};

void BulletWorld::Impl::fill_record() {
  FrameRecord& r = record;
  const std::size_t n = bodies.size();
  r.aabbs.resize(n);
  for (std::size_t i = 0; i < n; ++i) {
    const btBroadphaseProxy* proxy = bodies[i]->getBroadphaseHandle();
    r.aabbs[i] = {from_bt(proxy->m_aabbMin), from_bt(proxy->m_aabbMax)};
  }
  // Candidate pairs: the overlapping pair cache.
  r.pairs.clear();
  btOverlappingPairCache* cache = broadphase->getOverlappingPairCache();
  const int cached = cache->getNumOverlappingPairs();
  const btBroadphasePair* bp = cached > 0 ? cache->getOverlappingPairArrayPtr() : nullptr;
  for (int k = 0; k < cached; ++k) {
    const auto* a = static_cast<const btCollisionObject*>(bp[k].m_pProxy0->m_clientObject);
    const auto* b = static_cast<const btCollisionObject*>(bp[k].m_pProxy1->m_clientObject);
    auto ia = static_cast<std::uint32_t>(a->getUserIndex());
    auto ib = static_cast<std::uint32_t>(b->getUserIndex());
    if (ia == ib) continue;
    if (ia > ib) std::swap(ia, ib);
    r.pairs.push_back({ia, ib});
  }
  std::sort(r.pairs.begin(), r.pairs.end());
  r.pairs.erase(std::unique(r.pairs.begin(), r.pairs.end()), r.pairs.end());
  r.has_pairs = true;

  // Contacts: every manifold point within the breaking threshold, one row each, with its
  // friction impulse vector (the friction directions' impulses summed, on A).
  r.contacts.clear();
  std::vector<Vec3> jt3;
  const bool two_dirs = (world->getSolverInfo().m_solverMode & SOLVER_USE_2_FRICTION_DIRECTIONS) != 0;
  const int nm = dispatcher->getNumManifolds();
  for (int k = 0; k < nm; ++k) {
    const btPersistentManifold* pm = dispatcher->getManifoldByIndexInternal(k);
    const int np = pm->getNumContacts();
    if (np == 0) continue;
    const auto i0 = static_cast<std::uint32_t>(pm->getBody0()->getUserIndex());
    const auto i1 = static_cast<std::uint32_t>(pm->getBody1()->getUserIndex());
    const bool swap = i0 > i1;  // the row's A is body1
    const std::uint32_t ia = swap ? i1 : i0, ib = swap ? i0 : i1;
    for (int j = 0; j < np; ++j) {
      const btManifoldPoint& cp = pm->getContactPoint(j);
      if (cp.getDistance() > pm->getContactBreakingThreshold()) continue;
      // Bullet: normalWorldOnB points from body1 to body0; the witness points lie on the
      // shapes (collision margins 0 in rotation mode).
      const Vec3 n01 = from_bt(cp.m_normalWorldOnB);
      const Vec3 p0 = from_bt(cp.getPositionWorldOnA());
      const Vec3 p1 = from_bt(cp.getPositionWorldOnB());
      const float distance = cp.getDistance();
      Vec3 friction = cp.m_appliedImpulseLateral1 * from_bt(cp.m_lateralFrictionDir1);  // on body0
      if (two_dirs) friction += cp.m_appliedImpulseLateral2 * from_bt(cp.m_lateralFrictionDir2);
      ContactRecord c;
      c.pair = {ia, ib};
      c.normal = swap ? -n01 : n01;  // from B to A
      c.depth = std::max(0.0f, -distance);
      c.point = 0.5f * (p0 + p1);
      c.jn = cp.m_appliedImpulse;
      const Vec3 j_a = swap ? -friction : friction;  // friction impulse on A
      c.jt = row_scalar_jt(r, c, j_a, w, dt, gravity);
      r.contacts.push_back(c);
      jt3.push_back(j_a);
    }
  }
  std::vector<ContactRecord> rows;
  rows.swap(r.contacts);
  finish_manifold_record(r, rows, jt3);
}

BulletWorld::BulletWorld(const World& src, const BulletSettings& settings)
    : BulletWorld(src.shared_model(), src.state(), BulletOptions(), settings) {}

BulletWorld::BulletWorld(std::shared_ptr<const Model> model, const BodyState& initial, const BulletOptions& options,
                         const BulletSettings& settings)
    : model_(std::move(model)), impl_(std::make_unique<Impl>()) {
  Impl& m = *impl_;
  const Model& src = *model_;
  const Scene& scene = src.scene;
  m.dt = scene.dt;
  m.slop = scene.response.slop;
  m.config = std::make_unique<btDefaultCollisionConfiguration>();
  m.dispatcher = std::make_unique<btCollisionDispatcher>(m.config.get());
  m.broadphase = std::make_unique<btDbvtBroadphase>();
  m.solver = std::make_unique<CoulombSolver>();
  m.world = std::make_unique<TimedDynamicsWorld>(m.dispatcher.get(), m.broadphase.get(),
                                                 m.solver.get(), m.config.get());
  m.static_static = static_static_pairs(src);
  m.world->setGravity(to_bt(scene.gravity));
  btContactSolverInfo& info = m.world->getSolverInfo();
  info.m_restitutionVelocityThreshold = scene.response.restitution_threshold;
  // Split impulse for every penetrating contact (default threshold -0.04 m would feed
  // the Baumgarte recovery of shallow penetrations into the velocity): see the header.
  info.m_splitImpulse = 1;
  info.m_splitImpulsePenetrationThreshold = 0;
  info.m_numIterations = settings.solver_iterations;

  m.rotation = scene_rotates(scene);
  m.settings = settings;
  m.exact = m.rotation || settings.shape == BulletShape::Hull;
  m.solver->project = m.exact && options.coulomb_friction;
  m.world->prune_stale = m.exact && options.prune_stale_normals;
  m.gravity = scene.gravity;
  const std::size_t n_bodies = initial.size();
  // Shapes a static body uses (hull mode: a static mesh is Bullet's triangle-mesh shape).
  std::vector<char> used_static(src.shapes.size(), 0);
  for (std::size_t i = 0; i < n_bodies; ++i)
    if (!(initial.w[i] > 0.0f)) used_static[src.bodies[i].shape] = 1;
  for (std::size_t k = 0; k < src.shapes.size(); ++k) {
    const Shape& s = src.shapes[k];
    const bool mesh = s.mesh && s.mesh->vertices.size() >= 4 && !s.mesh->triangles.empty();
    if (settings.shape == BulletShape::Hull && mesh && used_static[k]) {
      // Its triangles (btTriangleMesh copies them), a BVH over them; margin 0 (btConcaveShape's).
      auto tm = std::make_unique<btTriangleMesh>();
      const std::vector<Vec3>& v = s.mesh->vertices;
      for (const auto& t : s.mesh->triangles) tm->addTriangle(to_bt(v[t[0]]), to_bt(v[t[1]]), to_bt(v[t[2]]));
      auto shape = std::make_unique<btBvhTriangleMeshShape>(tm.get(), true);
      shape->setMargin(0);
      m.triangle_meshes.push_back(std::move(tm));
      m.static_shapes.push_back(std::move(shape));
    } else {
      m.static_shapes.push_back(nullptr);
    }
    const Vec3 he = 0.5f * (s.local.max - s.local.min);
    if (m.exact && mesh) {
      // A mesh rotates as the convex hull of its vertices, margin 0 (see bullet_world.hpp).
      const ConvexHull hull = convex_hull(s.mesh->vertices, s.name);
      auto shape = std::make_unique<btConvexHullShape>();
      for (const auto& v : hull.vertices)
        shape->addPoint(btVector3(btScalar(v[0]), btScalar(v[1]), btScalar(v[2])), false);
      shape->setMargin(0);
      shape->recalcLocalAabb();
      m.polytopes.emplace(shape.get(), hull_polytope(hull));
      m.shapes.push_back(std::move(shape));
      continue;
    }
    auto box = std::make_unique<btBoxShape>(to_bt(he));  // default margin 0.04, inside the box
    if (m.exact) {
      box->setMargin(0);  // GJK would round the box's edges and corners by it
      m.polytopes.emplace(box.get(), box_polytope(to_bt(he)));
    }
    m.shapes.push_back(std::move(box));
  }

  // Product combination in Bullet: sqrt on every body gives mu_k and e for every pair.
  const btScalar friction = std::sqrt(scene.response.mu_kinetic);
  const btScalar restitution = std::sqrt(scene.response.restitution);

  // What each body collides as (trace attribute /bodies/collision_shape, summaries).
  bool dynamic_mesh = false, static_mesh = false;
  for (std::size_t i = 0; i < n_bodies; ++i) {
    const bool is_static = !(initial.w[i] > 0.0f);
    const Shape& s = src.shapes[src.bodies[i].shape];
    const bool mesh = s.mesh != nullptr;
    (is_static ? static_mesh : dynamic_mesh) |= mesh;
    if (m.exact) m.traits.body_collision_shape.push_back(m.static_shapes[src.bodies[i].shape] && is_static ? "mesh"
                                                                                                             : "convex_hull");
  }
  if (!m.exact) {
    m.geometry = "bullet boxes equal to the AABBs (shape=box)";
  } else {
    m.geometry = "bullet";
    if (dynamic_mesh) m.geometry += " convex hulls (dynamic meshes),";
    if (static_mesh)
      m.geometry += settings.shape == BulletShape::Hull ? " triangle mesh (static meshes)," : " convex hulls (static meshes),";
    m.geometry += m.rotation ? " boxes (box shapes)" : " boxes (box shapes); translation only (angular factor 0)";
  }

  if (m.exact) {
    // One absolute breaking threshold for every pair (see bullet_world.hpp).
    m.dispatcher->setDispatcherFlags(m.dispatcher->getDispatcherFlags() &
                                     ~btCollisionDispatcher::CD_USE_RELATIVE_CONTACT_BREAKING_THRESHOLD);
    m.traits.mu = scene.response.mu_kinetic;
    m.traits.restitution = scene.response.restitution;
    // Bullet keeps a manifold point while its distance along its normal and its drift
    // across the normal are each within the threshold (btPersistentManifold::
    // refreshContactPoints), so its two witness points, and the shapes, are at most
    // sqrt(2) x the threshold apart; + 1 mm for the float32 distances.
    m.traits.contact_margin = static_cast<float>(std::sqrt(2.0) * gContactBreakingThreshold) + 0.001f;
    m.traits.jt3 = true;  // fill_record gives every row its friction impulse vector
    // Every dynamic body has setActivationState(DISABLE_DEACTIVATION): Bullet never puts
    // one to sleep (its velocities zeroed, its pose frozen), so every body is judged awake.
    m.traits.deactivation = "off";
    // Bullet's solver applies a manifold point's impulse at getPositionWorldOnA on body0 and
    // getPositionWorldOnB on body1 (btSequentialImpulseConstraintSolver::
    // setupContactConstraint), which refreshContactPoints lets drift apart across the normal.
    m.traits.impulse_points = "witness-pair";
    m.traits.rotates = m.rotation;  // translation-only: no orientations, angular velocities, inertia
    // A dynamic mesh is its hull, a box itself, a static mesh (hull mode) its triangles:
    // per body in /bodies/collision_shape (body_collision_shape, set above).
    // Box-hull and hull-hull pairs: Bullet's convex-convex algorithm with the checked
    // contacts (CheckedConvexAlgorithm). Box-box pairs keep btBoxBoxDetector.
    m.convex_convex.pd = &m.epa;
    m.convex_convex.registry = &m.polytopes;
    m.convex_convex.counts = &m.checked;
    if (options.checked_narrowphase)
      for (const auto& [t0, t1] : {std::pair<int, int>{CONVEX_HULL_SHAPE_PROXYTYPE, CONVEX_HULL_SHAPE_PROXYTYPE},
                                 {CONVEX_HULL_SHAPE_PROXYTYPE, BOX_SHAPE_PROXYTYPE},
                                 {BOX_SHAPE_PROXYTYPE, CONVEX_HULL_SHAPE_PROXYTYPE}})
        m.dispatcher->registerCollisionCreateFunc(t0, t1, &m.convex_convex);
  }

  const BodyState& s0 = initial;
  m.state = s0;
  const std::size_t n = s0.size();
  if (m.rotation) {  // identity / zero where the model has none
    m.state.q.resize(n);
    m.state.omega.resize(n);
  }
  m.bodies.reserve(n);
  for (std::size_t i = 0; i < n; ++i) {
    const float w = s0.w[i];
    btCollisionShape* shape = !(w > 0.0f) && m.static_shapes[src.bodies[i].shape]
                                  ? m.static_shapes[src.bodies[i].shape].get()
                                  : m.shapes[src.bodies[i].shape].get();
    const btScalar mass = w > 0.0f ? btScalar(1.0f / w) : btScalar(0);
    btTransform t;
    t.setIdentity();
    // x is the centre of the world AABB; the box is centred on the local AABB centre.
    // Rotation mode: x is the body frame's origin (the local AABB centre), q its turn.
    t.setOrigin(to_bt(s0.x[i]));
    btVector3 inertia(0, 0, 0);
    if (m.exact) {
      // Translation-only: identity, zero inertia (with angular factor 0: never turns).
      if (m.rotation) t.setRotation(to_bt(m.state.q[i]));
      if (mass > 0 && m.rotation) shape->calculateLocalInertia(mass, inertia);
      std::array<float, 9> tensor{};
      for (int k = 0; k < 3; ++k) tensor[static_cast<std::size_t>(4 * k)] = static_cast<float>(inertia[k]);
      if (m.rotation) m.traits.inertia.push_back(tensor);  // translation-only: none (traits.rotates false)
      m.traits.body_friction.push_back(static_cast<float>(friction));
      m.traits.body_restitution.push_back(static_cast<float>(restitution));
    }
    btRigidBody::btRigidBodyConstructionInfo ci(mass, nullptr, shape, inertia);
    ci.m_startWorldTransform = t;
    ci.m_friction = friction;
    ci.m_restitution = restitution;
    ci.m_linearDamping = 0;
    ci.m_angularDamping = 0;
    auto body = std::make_unique<btRigidBody>(ci);
    if (!m.rotation) body->setAngularFactor(btScalar(0));
    if (mass > 0) {
      body->setLinearVelocity(to_bt(s0.v[i]));
      if (m.rotation) body->setAngularVelocity(to_bt(m.state.omega[i]));
      body->setActivationState(DISABLE_DEACTIVATION);
    }
    body->setUserIndex(static_cast<int>(i));  // body id, for the pair counts
    m.world->addRigidBody(body.get());
    m.w.push_back(w);
    m.bodies.push_back(std::move(body));
  }
}

BulletWorld::~BulletWorld() = default;

const FrameMetrics& BulletWorld::step() {
  Impl& m = *impl_;
  m.world->reset_times();
  if (m.exact && m.recording) {
    m.record.frame = m.frame + 1;
    m.record.x_pre = m.state.x;
    m.record.v_pre = m.state.v;
    m.record.q_pre = m.state.q;
    m.record.w_pre = m.state.omega;
  }
  const auto t0 = std::chrono::steady_clock::now();
  m.world->stepSimulation(static_cast<btScalar>(m.dt), 0);
  const double bullet_ms = ms_since(t0);

  const auto t1 = std::chrono::steady_clock::now();
  FrameMetrics fm;
  fm.frame = ++m.frame;
  fm.time = static_cast<double>(m.frame) * m.dt;
  // Pairs, counted as octocd counts them. Bullet's pair cache holds the pairs of its
  // fattened AABBs (contact threshold, motion prediction, dbvt margin), kept until they
  // separate, and never a static-static pair: it is Bullet's candidate list. The pairs of
  // it whose exact AABBs overlap at the positions its broadphase saw (the state before
  // this step, still in m.state) are octocd's dynamic_pairs; the static-static overlaps
  // are constant.
  btOverlappingPairCache* cache = m.broadphase->getOverlappingPairCache();
  const int cached = cache->getNumOverlappingPairs();
  fm.cell_candidates = static_cast<std::uint64_t>(cached);
  const btBroadphasePair* bp = cached > 0 ? cache->getOverlappingPairArrayPtr() : nullptr;
  std::uint64_t exact = 0;
  for (int k = 0; k < cached; ++k) {
    const auto* a = static_cast<const btCollisionObject*>(bp[k].m_pProxy0->m_clientObject);
    const auto* b = static_cast<const btCollisionObject*>(bp[k].m_pProxy1->m_clientObject);
    const auto ia = static_cast<std::size_t>(a->getUserIndex());
    const auto ib = static_cast<std::size_t>(b->getUserIndex());
    if (m.w[ia] == 0.0f && m.w[ib] == 0.0f) continue;
    if (m.rotation) {  // the exact boxes of the rotated local boxes at the pre-step pose
      if (overlaps(posed_box_aabb(model_->local_box(ia), {m.state.x[ia], m.state.q[ia]}),
                   posed_box_aabb(model_->local_box(ib), {m.state.x[ib], m.state.q[ib]})))
        ++exact;
    } else if (overlaps(translated(model_->local_box(ia), m.state.x[ia]),
                        translated(model_->local_box(ib), m.state.x[ib]))) {
      ++exact;
    }
  }
  fm.dynamic_pairs = exact;
  fm.aabb_pairs = exact + m.static_static;
  m.read_state();
  if (m.exact && m.recording) {
    FrameRecord& r = m.record;
    r.x_post = m.state.x;
    r.v_post = m.state.v;
    r.q_post = m.state.q;
    r.w_post = m.state.omega;
    r.x_det = r.x_pre;  // Bullet detects before it integrates
    r.q_det = r.q_pre;
    m.fill_record();
  }
  std::uint64_t contacts = 0, pen_points = 0, above = 0;
  double pen_sum = 0.0, pen_max = 0.0;
  const int nm = m.dispatcher->getNumManifolds();
  for (int k = 0; k < nm; ++k) {
    const btPersistentManifold* pm = m.dispatcher->getManifoldByIndexInternal(k);
    const int np = pm->getNumContacts();
    if (np > 0) ++contacts;
    for (int j = 0; j < np; ++j) {
      const double d = pm->getContactPoint(j).getDistance();
      if (d < 0.0) {
        ++pen_points;
        pen_sum += -d;
        pen_max = std::max(pen_max, -d);
        if (-d > static_cast<double>(m.slop)) ++above;
      }
    }
  }
  fm.contacts = contacts;
  if (pen_points > 0) {
    fm.penetration_mean = pen_sum / static_cast<double>(pen_points);
    fm.penetration_max = pen_max;
    fm.penetration_share_above_slop =
        static_cast<double>(above) / static_cast<double>(pen_points);
  }
  double ke = 0.0, px = 0.0, py = 0.0, pz = 0.0;
  for (std::size_t i = 0; i < m.state.size(); ++i) {
    const float w = m.state.w[i];
    if (!(w > 0.0f)) continue;
    const double mass = 1.0 / static_cast<double>(w);
    const Vec3 v = m.state.v[i];
    const double vx = v.x, vy = v.y, vz = v.z;
    ke += 0.5 * mass * (vx * vx + vy * vy + vz * vz);
    if (m.rotation) {  // + 0.5 w . (I w), in the body frame
      const btRigidBody& body = *m.bodies[i];
      const btVector3 wl = body.getAngularVelocity() * body.getWorldTransform().getBasis();  // R^T w
      const btVector3 inv = body.getInvInertiaDiagLocal();
      for (int k = 0; k < 3; ++k)
        if (inv[k] > 0) ke += 0.5 * static_cast<double>(wl[k]) * static_cast<double>(wl[k]) / static_cast<double>(inv[k]);
    }
    px += mass * vx;
    py += mass * vy;
    pz += mass * vz;
  }
  fm.kinetic_energy = ke;
  fm.momentum = {px, py, pz};
  const TimedDynamicsWorld& tw = *m.world;
  fm.stage_ms[static_cast<int>(Stage::Aabbs)] = tw.aabbs_ms;
  fm.stage_ms[static_cast<int>(Stage::Broadphase)] = tw.broadphase_ms;
  fm.stage_ms[static_cast<int>(Stage::Midphase)] = tw.narrow_ms;
  fm.stage_ms[static_cast<int>(Stage::Response)] = tw.solve_ms;
  // The rest of stepSimulation: prediction, integration and Bullet's bookkeeping.
  fm.stage_ms[static_cast<int>(Stage::Integrate)] =
      std::max(0.0, bullet_ms - (tw.aabbs_ms + tw.broadphase_ms + tw.narrow_ms + tw.solve_ms));
  fm.stage_ms[static_cast<int>(Stage::Metrics)] = ms_since(t1);
  fm.step_ms = ms_since(t0);
  m.metrics = fm;
  return m.metrics;
}

const BodyState& BulletWorld::state() const { return impl_->state; }
bool BulletWorld::rotating() const { return impl_->rotation; }

std::int64_t BulletWorld::friction_projections() const { return impl_->solver->projected; }

BulletNarrowphaseCounts BulletWorld::narrowphase_counts() const {
  BulletNarrowphaseCounts c;
  c = impl_->checked;
  c.pruned = impl_->world->pruned;
  return c;
}
const RotationTraits* BulletWorld::rotation_traits() const { return impl_->exact ? &impl_->traits : nullptr; }
bool BulletWorld::can_record() const { return impl_->exact; }
void BulletWorld::set_recording(bool on) { impl_->recording = impl_->exact && on; }
const BulletSettings& BulletWorld::settings() const { return impl_->settings; }
std::string BulletWorld::collision_geometry() const { return impl_->geometry; }
const FrameRecord& BulletWorld::record() const { return impl_->record; }
const std::vector<ContactRecord>& BulletWorld::contacts() const {
  return impl_->exact && impl_->recording ? impl_->record.contacts : impl_->no_contacts;
}
std::string BulletWorld::midphase_name() const { return impl_->exact ? "bullet-convex" : "bullet-box-box"; }
const FrameMetrics& BulletWorld::last_metrics() const { return impl_->metrics; }
std::int64_t BulletWorld::frame() const { return impl_->frame; }
std::string BulletWorld::device() const { return cpu_description(); }
std::string BulletWorld::notes() const {
  if (impl_->exact) {
    const BulletNarrowphaseCounts c = narrowphase_counts();
    return fmt::format(
        "{}: {}; broadphase\n"
        "candidates are Bullet's pair cache (AABBs fattened by the 0.02 m contact threshold and the\n"
        "step's motion; no static-static pairs); AABB and dynamic pairs are those of the cache whose\n"
        "exact boxes at the pre-step pose overlap. midphase = Bullet's narrow phase (box-box detector,\n"
        "GJK/EPA checked on the polytopes: {} box/hull contacts checked, {} replaced by the\n"
        "separating-axis contact, {} added where GJK found the shapes apart; {} manifold points with a\n"
        "stale normal dropped; {} apart contacts not added: off the surfaces); contacts = manifolds with points, penetration over manifold points;\n"
        "kinetic energy includes rotation.",
        impl_->rotation ? "rotation mode" : "translation only (angular factor 0)", impl_->geometry, c.checked, c.replaced, c.added, c.pruned, c.dropped);
  }
  return "broadphase candidates are Bullet's pair cache (AABBs fattened by the 0.02 m contact\n"
         "threshold, the step's motion and the dbvt margin, kept until they separate; no static-static\n"
         "pairs); AABB and dynamic pairs are those of the cache whose exact AABBs overlap, counted as\n"
         "octocd counts them. midphase = Bullet's narrow phase (box-box manifolds); response = its\n"
         "sequential-impulse solver; integrate = the rest of stepSimulation. contacts = manifolds with\n"
         "points, penetration over manifold points.";
}

bool BulletWorld::has_stage(Stage s) const {
  // Every stage is timed (TimedDynamicsWorld); "midphase" holds Bullet's narrow phase.
  (void)s;
  return true;
}

}  // namespace octocd
