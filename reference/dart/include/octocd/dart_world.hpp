#pragma once
/// \file dart_world.hpp
/// The same scene in DART 6.12 (Dynamic Animation and Robotics Toolkit; Debian's
/// libdart-dev): `octocd run --engine dart`. A rotating reference engine beside Bullet,
/// MuJoCo and ODE, recorded as a version 2 trace that the physics tier judges
/// (docs/engines.md, "dart"). DART's headers (Eigen, Boost, FCL) stay in the .cpp files.

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "octocd/dart_settings.hpp"
#include "octocd/reference_world.hpp"

namespace octocd {

/// The scene of a Model in one dart::simulation::World, stepped once per frame by
/// World::step.
///
/// Bodies (every body rotates: a scene without rotation simply starts with w = 0):
/// - a dynamic body (inverse mass w > 0) is a Skeleton of one BodyNode on a FreeJoint
///   whose frame origin is octocd's x (the centre of the shape's local AABB) and whose
///   centre of mass is that origin; its one ShapeNode (collision and dynamics aspects) sits
///   at the origin: a box shape is a BoxShape of the local AABB's sides; a mesh shape is a
///   MeshShape of the convex hull of its vertices (convex_hull.hpp, faces fanned into
///   triangles), which FCL collides as a BVH of the hull's surface triangles (DART 6.12 has
///   no convex shape that FCL collides as a solid);
/// - mass = 1/w; inertia about x, body frame: a box's m/12 (b^2 + c^2, ...); a hull's
///   tensor at uniform density about the local AABB centre (hull_mass_properties, density
///   = m / volume), as the ode engine does; RotationTraits::inertia gives it per body;
/// - static bodies (w = 0, generated walls included) are BodyNodes on WeldJoints of one
///   immobile Skeleton at their poses: a box is a BoxShape, a mesh a MeshShape of its
///   triangles; one Skeleton without self-collision checking, so static-static pairs are
///   never collided;
/// - initial x, v, q, omega from the state given (FreeJoint::setTransformOf,
///   setLinearVelocity, setAngularVelocity, world frame); no joint damping.
///
/// Materials: every ShapeNode's DynamicsAspect friction coefficient = mu_k / sqrt(2)
/// (DartFriction::Inscribed, the default) or mu_k (Pyramid); DART takes the smaller of the
/// two shapes' values per contact and bounds each of its two friction directions by it
/// times that contact's normal impulse. Restitution coefficient sqrt(e) per shape: DART
/// multiplies the two, so every pair gets e; DART bounces when e times the approach speed
/// exceeds its fixed 0.1 m/s (the scene's restitution_threshold is not expressible).
///
/// Contacts: DartSettings::collision's detector (FCL by default: FCL's dynamic AABB tree
/// and its narrow phase, DART's contact post-processing), at the pose before the step;
/// CollisionOption::maxNumContacts = DartSettings::max_contacts. Every contact is one
/// ContactConstraint (one normal row, two friction rows) in DART's boxed LCP
/// (DartSettings::lcp), with ERP, the correction cap and CFM of DartSettings: DART keeps
/// them in process-wide statics, set here for each step and put back after it.
///
/// Stepping: gravity = scene.gravity, time step dt, one World::step per frame. DART's
/// integrator is semi-implicit Euler: v' = v + dt (M^-1 (f - c(v)) + impulses / m), then
/// x' = x + dt v', R' = R exp(dt w'_body) (FreeJoint::integratePositions). The Coriolis
/// term c(v) of a free body carries w x I w at the pre-step velocity (gyroscopic,
/// explicit).
///
/// state(): x (the body origin = centre of mass), v, q, omega (world frame) after the last step
/// (BodyNode::getWorldTransform, getLinearVelocity, getAngularVelocity); static bodies
/// as given.
/// collision_geometry(): "dart fcl: boxes (BoxShape, fcl::Box), convex hulls (dynamic meshes, MeshShape of the
/// hull), triangle meshes (static meshes, MeshShape)", naming only what the scene has.
/// rotation_traits(): the traits a version 2 trace declares:
/// - inertia: per body as described above (zeros for static bodies);
/// - body_friction = mu_k with combine "min" (DART takes the smaller shape's value;
///   the inscribed pyramid stays inside mu_k's cone); body_restitution = sqrt(e) with
///   combine "product" (DART multiplies), so every pair has e;
/// - contact_margin 1e-4 m (DART reports only overlapping shapes; the margin covers the
///   float32 pose in the trace and FCL's tolerances);
/// - detection "pre-step"; candidate_pairs false (no /pairs: the detector's pairs are
///   not exposed); contact_geometry "shape";
/// - body_collision_shape "box" (box shapes), "convex_hull" (dynamic meshes), "mesh"
///   (static meshes); rotates, jt3;
/// - contact_model "rigid", integrator "semi-implicit", gyroscopic "true".
/// record(): the last step's record (recording on):
/// - x_pre, v_pre, q_pre, w_pre: the state before the step; *_post after it; x_det,
///   q_det = x_pre, q_pre (DART collides inside World::step before positions move);
/// - aabbs: the exact world AABBs of the local boxes at the pre-step pose; has_pairs
///   false;
/// - contacts (manifolds, has_points; has_contact_terms false): one row per
///   collision::Contact of World::getLastCollisionResult() between a dynamic body and
///   another body; pair (a, b), a < b, of the two ShapeNodes' bodies; normal =
///   Contact::normal (from object 2's body to object 1's), flipped so it points from B
///   to A; depth = max(0, Contact::penetrationDepth); point = Contact::point;
///   J_A = Contact::force (the force on object 1's body that ContactConstraint::
///   applyImpulse stores: (n lambda_n + d1 lambda_1 + d2 lambda_2) / dt, the LCP's own
///   impulses) times dt, negated when A is object 2's body; jn = J_A . normal; jt3 =
///   J_A - jn normal; jt = jt3 along -v_t / |v_t| (v_t from v_pre + dt g on dynamic
///   bodies and w_pre), |jt3| when |v_t| <= 1e-6 m/s; rows sorted by pair;
/// - confirmed: the pairs with at least one row.
class DartWorld : public SettingsWorld<DartSettings> {
 public:
  /// The model (shared, not copied) from the state `initial` (x, v, w per body; q and
  /// omega when given, else the identity and zero). Throws InputError when a mesh's hull
  /// spans no volume, or when DartSettings::collision is `dart` and the scene has a mesh
  /// (DART's own detector has no mesh shape).
  DartWorld(std::shared_ptr<const Model> model, const BodyState& initial,
            const DartSettings& settings = DartSettings());
  ~DartWorld() override;

  /// One World::step of dt. Metrics in octocd's layout:
  /// - stage_ms: response = World::step (collision detection, the constraint solve and
  ///   the integration: DART runs them in one call), metrics = reading back; the other
  ///   stages are not timed apart (has_stage false);
  /// - cell_candidates = 0 (the detector's candidate pairs are not exposed);
  ///   dynamic_pairs = pairs with a dynamic body whose exact world AABBs at the pre-step
  ///   pose overlap; aabb_pairs = that + static_static_pairs(model);
  /// - contacts = rows of World::getLastCollisionResult(); penetration mean / max over
  ///   their depths, share above scene.response.slop;
  /// - kinetic_energy = sum 0.5 m |v|^2 + 0.5 w_b . I w_b; momentum = sum m v.
  /// Throws RuntimeError naming the body and frame when its state becomes non-finite, and
  /// when the step's contacts reach DartSettings::max_contacts (DART drops the rest).
  const FrameMetrics& step() override;
  /// "dart".
  std::string name() const override { return "dart"; }
  /// "dart-fcl" (FCL's dynamic AABB tree inside FCLCollisionGroup) or "dart-all-pairs"
  /// (DARTCollisionGroup tests every pair's AABBs), per DartSettings::collision.
  std::string broadphase_name() const override;
  /// "dart-fcl-collide" (FCL's narrow phase and DART's contact post-processing) or
  /// "dart-collide" (DART's own box-box).
  std::string midphase_name() const override;
  /// How DART's figures differ from octocd's (see step()).
  std::string notes() const override;
  /// Response and metrics are timed; aabbs, broadphase, midphase and integrate are not
  /// (they run inside World::step).
  bool has_stage(Stage s) const override;
  /// DART's version string (DART_VERSION of the headers built against).
  static std::string dart_version();

 private:
  struct Impl;
  Impl& impl() const;
};

}  // namespace octocd
