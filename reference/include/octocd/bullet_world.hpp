#pragma once
/// \file bullet_world.hpp
/// The same scene in Bullet's btDiscreteDynamicsWorld (SPEC 7 item 8): a dynamics
/// reference for `octocd run --engine bullet`, so validators can compare settled heights
/// and centre-of-mass trajectories with octocd's own pipeline.

#include <cstdint>
#include <memory>

#include "octocd/world.hpp"

namespace octocd {

/// The scene of `world` (its bodies, shapes, inverse masses and initial state) in Bullet's
/// btDiscreteDynamicsWorld (btDefaultCollisionConfiguration, btCollisionDispatcher,
/// btDbvtBroadphase, btSequentialImpulseConstraintSolver). Bullet is the float build
/// (btScalar = float, as pkg-config `bullet` gives).
///
/// Bodies:
/// - every body is a btRigidBody with a btBoxShape of its shape's local AABB half extents
///   (mesh bodies too: SPEC 7.8 compares against "box shapes equal to the AABBs"), centred
///   on the AABB centre, so Bullet's centre of mass is octocd's x. Box-box pairs use
///   Bullet's dedicated btBoxBoxCollisionAlgorithm (btBoxBoxDetector).
/// - collision margin: Bullet's default 0.04 m, which btBoxShape keeps INSIDE the given
///   half extents (the box's outer surface is the AABB). The box-box detector works on
///   the full extents (getHalfExtentsWithMargin), so the margin does not change the
///   contact geometry of box pairs; it is left at the default for GJK's sake.
/// - translation only: setAngularFactor(0) and zero inertia, as the paper.
/// - mass = 1/w; w = 0 gives a static body (mass 0, Bullet's static object).
/// - every dynamic body has setActivationState(DISABLE_DEACTIVATION): resting bodies keep
///   being simulated (no sleeping), as in octocd; no linear or angular damping.
///
/// Materials. Bullet combines the two bodies' friction and restitution as PRODUCTS
/// (btManifoldResult::calculateCombinedFriction/Restitution). octocd uses one mu_k and
/// one e for every pair, so every body (static and dynamic alike) gets
/// friction = sqrt(scene.response.mu_kinetic) and restitution =
/// sqrt(scene.response.restitution): the product is mu_k and e for every pair
/// (dynamic-static and dynamic-dynamic), up to float rounding. The global combine
/// callbacks (gCalculateCombined*Callback) are left alone: they are process-wide.
/// Bullet has one friction coefficient (no static/kinetic split): mu_k is used, mu_s has
/// no Bullet counterpart.
///
/// Solver (btContactSolverInfo): Bullet's defaults (10 iterations, SOR 1, erp2 0.2, warm
/// starting 0.85, SOLVER_SIMD, linear slop 0), except
/// - m_restitutionVelocityThreshold = scene.response.restitution_threshold (v_th: Bullet
///   zeroes restitution below it, like Eq. 17; Bullet's default is 0.2 m/s);
/// - split impulse on (the default) with m_splitImpulsePenetrationThreshold = 0 (default
///   -0.04 m): EVERY penetrating contact's Baumgarte recovery goes to Bullet's separate
///   "push" velocity, not into the body's velocity. With the default, penetrations under
///   4 cm (all of them here) are fixed through the velocity and add erp2 * depth / dt to
///   rebounds (bounce.json measured 0.543 instead of 0.498 for e = 0.5). octocd also
///   corrects positions apart from velocities (SPEC 6), so this is the comparable setting.
/// octocd's delta, beta, alpha, J_min, mu_s and v_max have no Bullet counterpart and are
/// not used (no velocity clamp).
///
/// Stepping: gravity = scene.gravity; step() calls stepSimulation(dt, 0): exactly one
/// internal step of dt per frame, no sub-stepping and no interpolation. Bullet's
/// integrator is semi-implicit Euler like SPEC 4.1 (v += dt g, then x += dt v), so free
/// fall follows the same closed form as octocd.
class BulletWorld : public Engine {
 public:
  /// The scene, shapes and bodies of `world` (its model, shared) and its current state.
  explicit BulletWorld(const World& world);
  /// From a model (shared, not copied) and the state to start from (x, v, w per body).
  BulletWorld(std::shared_ptr<const Model> model, const BodyState& initial);
  ~BulletWorld();
  BulletWorld(const BulletWorld&) = delete;
  BulletWorld& operator=(const BulletWorld&) = delete;

  /// One fixed step; metrics in octocd's layout, so a summary compares with `cpu`'s:
  /// - stage_ms, timed inside stepSimulation (a btDiscreteDynamicsWorld subclass times
  ///   the base calls): aabbs = updateAabbs (world AABBs and the dbvt leaf updates),
  ///   broadphase = computeOverlappingPairs, midphase = dispatchAllCollisionPairs (Bullet's
  ///   narrow phase: box-box manifolds; it has no midphase of its own), response =
  ///   calculateSimulationIslands + solveConstraints (10 sequential-impulse iterations),
  ///   integrate = the rest of stepSimulation (prediction, integration, bookkeeping),
  ///   metrics = reading state and metrics back. step_ms = all of it.
  /// - cell_candidates = pairs in Bullet's overlapping pair cache: its broadphase output,
  ///   from AABBs fattened by the contact threshold (0.02 m), the motion over the step and
  ///   the dbvt margin, kept until they separate, static-static pairs excluded.
  /// - dynamic_pairs = the cached pairs whose exact AABBs (x +- half extents at the
  ///   positions the broadphase saw, the pre-step state) overlap (Eq. 6): the count
  ///   octocd's engines give. aabb_pairs = dynamic_pairs + static_static_pairs(model).
  /// - box_tests, box_pairs, vertex_tests = 0 (no octree midphase).
  /// - contacts = persistent manifolds with >= 1 point.
  /// - penetration_mean / max over manifold POINTS with negative distance (depth =
  ///   -distance; 0 when none); penetration_share_above_slop = share of those points
  ///   whose depth exceeds scene.response.slop.
  /// - kinetic_energy and momentum (double) over dynamic bodies; memory_bytes = 0.
  const FrameMetrics& step() override;
  /// x = centre of each body's AABB (Bullet's centre of mass), v = linear velocity, w as
  /// given. Updated by step().
  const BodyState& state() const override;
  /// Metrics of the last step.
  const FrameMetrics& last_metrics() const override;
  /// Steps taken so far.
  std::int64_t frame() const override;
  /// "bullet".
  std::string name() const override { return "bullet"; }
  /// The CPU model.
  std::string device() const override;
  /// "bullet-dbvt" (btDbvtBroadphase).
  std::string broadphase_name() const override { return "bullet-dbvt"; }
  /// The model it was built from.
  const Model& model() const override { return *model_; }
  /// Bullet exposes no octocd contact records: always empty.
  const std::vector<ContactRecord>& contacts() const override { return no_contacts_; }
  /// Every stage is timed (see step(); `midphase` holds Bullet's narrow phase).
  bool has_stage(Stage s) const override;
  /// How Bullet's figures differ from octocd's (see step()).
  std::string notes() const override;
  /// "bullet-box-box": Bullet's btBoxBoxDetector on the AABB boxes, not a level list.
  std::string midphase_name() const override { return "bullet-box-box"; }

 private:
  std::shared_ptr<const Model> model_;
  std::vector<ContactRecord> no_contacts_;
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace octocd
