/// \file bullet_world.cpp
/// octocd::BulletWorld: the scene in btDiscreteDynamicsWorld (see bullet_world.hpp for
/// every setting and why).

#include "octocd/bullet_world.hpp"
#include "octocd/adapter_rows.hpp"
#include "octocd/convex_hull.hpp"
#include "octocd/reference_world.hpp"
#include "octocd/version.hpp"
#include "bullet_checked_contacts.hpp"

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

}  // namespace

using namespace bullet_detail;

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
  fill_engine_aabbs(r, bodies.size(), [&](std::size_t i) {
    const btBroadphaseProxy* proxy = bodies[i]->getBroadphaseHandle();
    return Aabb{from_bt(proxy->m_aabbMin), from_bt(proxy->m_aabbMax)};
  });
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
  sort_unique_pairs(r.pairs);
  r.has_pairs = true;

  // Contacts: every manifold point within the breaking threshold, one row each, with its
  // friction impulse vector (the friction directions' impulses summed, on A).
  r.contacts.clear();
  std::vector<Vec3> jt3, point_b;
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
      // The solver applies the impulse at each body's own witness point (rel_pos1 from
      // getPositionWorldOnA on body0, rel_pos2 from getPositionWorldOnB on body1): the
      // row's point is A's, point_b B's.
      c.point = swap ? p1 : p0;
      c.jn = cp.m_appliedImpulse;
      const Vec3 j_a = swap ? -friction : friction;  // friction impulse on A
      c.jt = row_scalar_jt(r, c, j_a, w, dt, gravity);
      r.contacts.push_back(c);
      jt3.push_back(j_a);
      point_b.push_back(swap ? p0 : p1);
    }
  }
  std::vector<ContactRecord> rows;
  rows.swap(r.contacts);
  finish_manifold_record(r, rows, jt3, &point_b);
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
    m.traits.point_b = true;  // and its point on B (the row's point is A's witness point)
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
