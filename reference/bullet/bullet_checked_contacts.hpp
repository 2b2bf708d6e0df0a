#pragma once
// The contacts BulletWorld (bullet_world.cpp) takes from Bullet's convex-convex algorithm in
// rotation mode, checked on the two posed polytopes and replaced by the exact separating-axis
// contact where GJK/EPA went wrong (bullet_checked_contacts.cpp). Internal to reference/bullet.
#include <unordered_map>
#include <vector>

#include <btBulletDynamicsCommon.h>
#include <BulletCollision/CollisionDispatch/btConvexConvexAlgorithm.h>

#include "octocd/bullet_world.hpp"
#include "octocd/convex_hull.hpp"

namespace octocd::bullet_detail {

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

/// The box of half extents `he` as a polytope.
Polytope box_polytope(const btVector3& he);

/// A convex hull (convex_hull.hpp: its vertices, faces and planes) as a polytope; each
/// edge once, with the outward normals of the two faces that share it.
Polytope hull_polytope(const ConvexHull& h);

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

  /// Bullet's convex-convex algorithm, each contact checked (CheckedResult) on the pair's
  /// polytopes; a pair of shapes without polytopes goes to Bullet unchecked.
  void processCollision(const btCollisionObjectWrapper* w0, const btCollisionObjectWrapper* w1,
                        const btDispatcherInfo& info, btManifoldResult* out) override;

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
  class CheckedResult;  // bullet_checked_contacts.cpp

  const Registry& registry_;
  BulletNarrowphaseCounts& counts_;
  /// A world axis u that separated the pair (A on u's side) when GJK last found no
  /// contact: tried first next time (frame-to-frame coherence), one separation each.
  btVector3 separating_axis_{0, 1, 0};
  bool has_separating_axis_ = false;
};

}  // namespace octocd::bullet_detail
