/// \file bullet_world.cpp
/// octocd::BulletWorld: the scene in btDiscreteDynamicsWorld (see bullet_world.hpp for
/// every setting and why).

#include "octocd/bullet_world.hpp"
#include "octocd/version.hpp"

#include <btBulletDynamicsCommon.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <memory>
#include <vector>

namespace octocd {

namespace {

btVector3 to_bt(const Vec3& v) { return btVector3(v.x, v.y, v.z); }
Vec3 from_bt(const btVector3& v) {
  return {static_cast<float>(v.x()), static_cast<float>(v.y()), static_cast<float>(v.z())};
}

double ms_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0)
      .count();
}

/// btDiscreteDynamicsWorld with its step's phases timed, so the Bullet engine reports
/// the stages octocd has (docs: README "Bullet as an engine"). stepSimulation(dt, 0) runs
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
  void performDiscreteCollisionDetection() override {
    const double before = aabbs_ms + broadphase_ms;
    const auto t0 = std::chrono::steady_clock::now();
    btDiscreteDynamicsWorld::performDiscreteCollisionDetection();
    narrow_ms += std::max(0.0, ms_since(t0) - (aabbs_ms + broadphase_ms - before));
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

}  // namespace

struct BulletWorld::Impl {
  double dt = 0.001;
  float slop = 0.001f;
  std::unique_ptr<btDefaultCollisionConfiguration> config;
  std::unique_ptr<btCollisionDispatcher> dispatcher;
  std::unique_ptr<btDbvtBroadphase> broadphase;
  std::unique_ptr<btSequentialImpulseConstraintSolver> solver;
  std::unique_ptr<TimedDynamicsWorld> world;
  std::vector<float> w;                 // inverse mass per body (0 = static)
  std::uint64_t static_static = 0;      // static_static_pairs(model), constant
  std::vector<std::unique_ptr<btBoxShape>> shapes;  // one per octocd shape
  std::vector<std::unique_ptr<btRigidBody>> bodies;  // index = body id
  BodyState state;
  FrameMetrics metrics;
  std::int64_t frame = 0;

  ~Impl() {
    if (world) {
      for (auto& b : bodies) world->removeRigidBody(b.get());
    }
    world.reset();  // before the solver, broadphase, dispatcher and config it uses
  }

  void read_state() {
    for (std::size_t i = 0; i < bodies.size(); ++i) {
      state.x[i] = from_bt(bodies[i]->getWorldTransform().getOrigin());
      state.v[i] = from_bt(bodies[i]->getLinearVelocity());
    }
  }
};

BulletWorld::BulletWorld(const World& src) : BulletWorld(src.shared_model(), src.state()) {}

BulletWorld::BulletWorld(std::shared_ptr<const Model> model, const BodyState& initial)
    : model_(std::move(model)), impl_(std::make_unique<Impl>()) {
  Impl& m = *impl_;
  const Model& src = *model_;
  const Scene& scene = src.scene;
  m.dt = scene.dt;
  m.slop = scene.response.slop;
  m.config = std::make_unique<btDefaultCollisionConfiguration>();
  m.dispatcher = std::make_unique<btCollisionDispatcher>(m.config.get());
  m.broadphase = std::make_unique<btDbvtBroadphase>();
  m.solver = std::make_unique<btSequentialImpulseConstraintSolver>();
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

  for (const Shape& s : src.shapes) {
    const Vec3 he = 0.5f * (s.local.max - s.local.min);
    m.shapes.push_back(std::make_unique<btBoxShape>(to_bt(he)));  // default margin 0.04
  }

  // Product combination in Bullet: sqrt on every body gives mu_k and e for every pair.
  const btScalar friction = std::sqrt(scene.response.mu_kinetic);
  const btScalar restitution = std::sqrt(scene.response.restitution);

  const BodyState& s0 = initial;
  m.state = s0;
  const std::size_t n = s0.size();
  m.bodies.reserve(n);
  for (std::size_t i = 0; i < n; ++i) {
    btBoxShape* box = m.shapes[src.bodies[i].shape].get();
    const float w = s0.w[i];
    const btScalar mass = w > 0.0f ? btScalar(1.0f / w) : btScalar(0);
    btTransform t;
    t.setIdentity();
    // x is the centre of the world AABB; the box is centred on the local AABB centre.
    t.setOrigin(to_bt(s0.x[i]));
    btRigidBody::btRigidBodyConstructionInfo ci(mass, nullptr, box, btVector3(0, 0, 0));
    ci.m_startWorldTransform = t;
    ci.m_friction = friction;
    ci.m_restitution = restitution;
    ci.m_linearDamping = 0;
    ci.m_angularDamping = 0;
    auto body = std::make_unique<btRigidBody>(ci);
    body->setAngularFactor(btScalar(0));
    if (mass > 0) {
      body->setLinearVelocity(to_bt(s0.v[i]));
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
    if (overlaps(translated(model_->local_box(ia), m.state.x[ia]), translated(model_->local_box(ib), m.state.x[ib])))
      ++exact;
  }
  fm.dynamic_pairs = exact;
  fm.aabb_pairs = exact + m.static_static;
  m.read_state();
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
const FrameMetrics& BulletWorld::last_metrics() const { return impl_->metrics; }
std::int64_t BulletWorld::frame() const { return impl_->frame; }
std::string BulletWorld::device() const { return cpu_description(); }
std::string BulletWorld::notes() const {
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
