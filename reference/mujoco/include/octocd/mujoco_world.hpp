#pragma once
/// \file mujoco_world.hpp
/// The scene in MuJoCo (`octocd run --engine mujoco`): a rotating reference engine whose
/// run the physics tier judges through a version 2 trace, like Bullet's with rotation.
/// docs/engines.md ("mujoco") maps every quantity to its MuJoCo parameter.

#include <cstdint>
#include <memory>
#include <string>

#include "octocd/reference_world.hpp"
#include "octocd/mujoco_settings.hpp"

namespace octocd {

/// The scene of a Model in MuJoCo 2.2 (libmujoco; mjModel built from MJCF text, mjData
/// stepped in double precision). MuJoCo 2.2 has no model-editing API: the constructor
/// writes the scene as MJCF (xml()) and loads it with mj_loadXML from MuJoCo's virtual
/// file system (mjVFS: no file on disk).
///
/// Model (one MuJoCo body per dynamic octocd body, in body order):
/// - a dynamic body is a `<body>` with a `<freejoint>` whose frame origin is octocd's x
///   (the centre of the shape's local AABB) and orientation q; its one geom sits at the
///   body origin: a box shape is `type="box"` with size = the local AABB's half extents,
///   a mesh shape `type="mesh"` of the mesh's vertices (MuJoCo collides a mesh as the
///   convex hull of its vertices, computed by qhull at load; it moves the mesh into its
///   own inertial frame and compensates in geom_pos/geom_quat, so the world placement is
///   the octocd mesh's);
/// - a static body (w = 0, generated walls included) is a geom of the same kind in
///   `<worldbody>` at its pose: MuJoCo never collides two geoms of the world body, so
///   static-static pairs make no contacts;
/// - mass 1/w and an explicit `<inertial pos="0 0 0">` (compiler inertiafromgeom false):
///   the centre of mass is the body origin, so x is MuJoCo's centre of mass, and the
///   inertia is the solid box of the shape's local AABB, m/12 diag(b^2 + c^2, a^2 + c^2,
///   a^2 + b^2) for side lengths a, b, c (a mesh's too, the rule Bullet uses for its
///   hulls): rotation_traits().inertia;
/// - materials: every geom friction = (mu_k, 0, 0) with condim 3 (sliding friction in two
///   directions; MuJoCo takes the larger of two geoms' friction, so mu_k for every pair);
///   restitution through each geom's solref (timeconst, dampratio): the damping ratio of
///   a spring-damper whose rebound is e, dampratio = -ln e / sqrt(pi^2 + ln^2 e) (1 for
///   e = 0: critically damped); timeconst MujocoSettings::timeconst (0: 2 dt / dampratio); solimp
///   MuJoCo's default (0.9, 0.95, 0.001);
/// - options: timestep = scene.dt, gravity = scene.gravity, integrator Euler
///   (semi-implicit: v += dt a, then x += dt v), cone MujocoSettings::cone, iterations
///   MujocoSettings::iterations, multiccd MujocoSettings::multiccd, MuJoCo's Newton
///   solver (its conjugate-gradient solver above 2,000 dynamic bodies, on a stack
///   `<size nstack>` sized from the scene: MuJoCo 2.2 sizes Newton's nv x nv Hessians and
///   its default stack as ints, which wrap; docs/engines.md) and warm start; no damping,
///   no sleeping.
///
/// Stepping: one MuJoCo step of dt per frame, mj_step's own sequence called in parts so
/// its stages are timed: mj_checkPos, mj_checkVel, mj_fwdPosition (kinematics,
/// collision detection, constraints), mj_fwdVelocity, mj_fwdActuation,
/// mj_fwdAcceleration, mj_fwdConstraint (the solver), mj_checkAcc, mj_Euler (the same
/// bits as mj_step: tests/reference/test_mujoco_world.cpp). Detection runs at the state
/// before the step ("pre-step"). MuJoCo's errors (mju_error) are turned into
/// RuntimeError while a call is in MuJoCo; its warnings (contact or constraint buffer
/// full, a bad qpos, qvel or qacc, which MuJoCo answers by dropping contacts or
/// resetting the state) throw RuntimeError naming the warning and frame, and for a bad
/// qpos, qvel or qacc the octocd body whose free joint holds MuJoCo's index.
///
/// state(): x = the free joint's position (the body origin, octocd's x), v its linear velocity,
/// q its orientation, omega the angular velocity in the world frame (MuJoCo keeps it in
/// the body frame: R qvel[3:6]); static bodies as given. Updated by step().
/// collision_geometry(): "mujoco convex hulls (meshes), boxes".
/// rotation_traits(): Inertia (body frame, the local AABB's solid box), per-body friction mu_k and
/// restitution e with combine rule "max" (MuJoCo takes the larger friction of the two
/// geoms; e is one per scene), contact_margin = MujocoSettings::margin, detection
/// "pre-step", contact_geometry "shape", per body collision_shape "convex_hull" (boxes
/// and meshes alike: MuJoCo 2.2 collides every mesh, static ones too, as its hull),
/// jt3 true, contact_model "soft", integrator "semi-implicit", gyroscopic "true", deactivation "off"
/// (MuJoCo's bias force qfrc_bias carries w x I w on every free body).
/// record(): the last step's record (recording on), external trace version 2:
/// - x_pre, v_pre, q_pre, w_pre: the state before the step; x_post ... after it;
///   x_det, q_det = x_pre, q_pre (mj_fwdPosition detects at the state before mj_Euler);
/// - aabbs: the exact world AABBs of the local boxes at the pre-step pose; has_pairs
///   false (MuJoCo's candidate pairs are not exposed);
/// - contacts (manifolds, has_points, has_contact_terms false): one row per
///   mjData::contact entry that is in the solver or in the gap (exclude 0 or 1): pair
///   (a, b), a < b, of the bodies of geom1 and geom2; normal = contact.frame[0..2]
///   (from geom1 to geom2) flipped so it points from B to A; depth = max(0, -dist);
///   point = contact.pos (MuJoCo's midpoint between the surfaces); jn = the normal
///   force of mj_contactForce x dt; jt3 = the tangential force (two frame directions)
///   on A x dt, world frame (MuJoCo's force acts on geom2, its negative on geom1);
///   jt = jt3 along -v_t / |v_t| (docs/trace-format.md, "The sign of jt"), |jt3| when
///   |v_t| <= 1e-6 m/s; rows sorted by pair;
/// - confirmed: the pairs with at least one row.
class MujocoWorld : public SettingsWorld<MujocoSettings> {
 public:
  /// From a model (shared, not copied) and the state to start from (x, v, w per body;
  /// q, omega where given, else the identity and zero). Throws RuntimeError with
  /// MuJoCo's message when it refuses the generated model (e.g. a mesh without volume).
  MujocoWorld(std::shared_ptr<const Model> model, const BodyState& initial,
              const MujocoSettings& settings = MujocoSettings());
  ~MujocoWorld() override;

  /// One MuJoCo step; metrics in octocd's layout:
  /// - stage_ms: midphase = mj_fwdPosition (kinematics, MuJoCo's broadphase and narrow
  ///   phase, constraint set-up: MuJoCo times them together), response =
  ///   mj_fwdVelocity .. mj_fwdConstraint (bias forces and the constraint solver),
  ///   integrate = mj_Euler, metrics = reading state and metrics back; aabbs and
  ///   broadphase are not timed apart (has_stage false);
  /// - cell_candidates = 0 (MuJoCo's broadphase pairs are not exposed);
  ///   dynamic_pairs = pairs with a dynamic body whose exact world AABBs at the pre-step
  ///   pose overlap (counted here); aabb_pairs = dynamic_pairs + static_static_pairs;
  /// - contacts = MuJoCo's contact rows (mjData::ncon, gap rows within the margin
  ///   included); penetration over rows with dist < 0 (depth = -dist);
  /// - kinetic_energy = 0.5 m |v|^2 + 0.5 w_b . I w_b, momentum = sum m v (double).
  /// Throws RuntimeError naming the body and frame when a state becomes non-finite.
  const FrameMetrics& step() override;
  /// "mujoco".
  std::string name() const override { return "mujoco"; }
  /// "mujoco-sap" (mj_collision's sweep and prune over the bodies' bounding boxes).
  std::string broadphase_name() const override { return "mujoco-sap"; }
  /// "mujoco-convex": mjc_BoxBox for box pairs, MPR (libccd) on the hulls otherwise.
  std::string midphase_name() const override { return "mujoco-convex"; }
  /// Integrate, midphase, response and metrics are timed; aabbs and broadphase are not.
  bool has_stage(Stage s) const override;
  /// How MuJoCo's figures differ from octocd's (see step()).
  std::string notes() const override;
  /// The MJCF text this engine loaded (for tests and debugging: mj_loadXML of it gives
  /// the same mjModel).
  const std::string& xml() const;
  /// MuJoCo's version string (mj_versionString).
  static std::string mujoco_version();

 private:
  struct Impl;
  Impl& impl() const;
};

}  // namespace octocd
