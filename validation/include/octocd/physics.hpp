#pragma once
/// \file physics.hpp
/// The physics tier of the validators (design.md section 13, ARCHITECTURE.md seam 3): judges any
/// engine, rotating or not, with any solver and any broadphase, on the true geometry of
/// its posed shapes (FCL), never on octocd's own response model. The model tier
/// (validation.hpp: Eq. 14 contraction, averaged corrections, the applied-state
/// re-derivation, midphase completeness, analytic scenes, Bullet dynamics) is apart.
///
/// Rows (each ValidationResult has tier Physics; each detail names the frame and the
/// pair or body of the first or worst offence, and how many items it judged):
///  1. `broadphase-completeness` (checked frames): every pair with a dynamic body whose
///     posed shapes (detection pose) are closer than `broadphase_margin_m` - slack is
///     among the engine's candidate pairs; extra pairs are allowed and counted
///     (candidates per true pair). Pairs are found through the exact posed world AABBs
///     grown by the largest margin any row asks about, in octocd's loose octree, then
///     FCL. An engine that declares an exact AABB broadphase is also held to set equality
///     with `flat` on its world AABBs (static-static pairs dropped on both sides). n/a
///     when the record has no candidate pairs.
///  2. `contact-completeness` (checked frames): every pair penetrating deeper than
///     `contact_depth_m` (FCL; non-convex meshes must really intersect, and their depth,
///     an upper bound, is proven by a vertex that deep inside the other shape:
///     ReferenceGeometry::penetration_witness; a bound alone is n/a) has at least one
///     contact row; a row on a pair farther apart than the contact margin (or the pair's
///     theta) + slack is a false contact.
///  3. `contact-geometry` (checked frames): per row on penetrating shapes, the angle
///     between the engine's normal and the reference's within `normal_angle_deg`. Two
///     convex polytopes (boxes, convex meshes, declared hulls and boxes): the
///     separating-axis test (sat.hpp), the angle to the nearest axis whose overlap is
///     within geometry_slack_m + `sat_accept_rel` of the minimum, the depth against the
///     SAT minimum, the posed reference's answer a second opinion (figure: FCL's EPA on
///     hulls; two boxes: octocd's box-box, the same minimum). Other shapes: FCL (convex
///     hulls: libccd EPA). Details name the
///     reference ("[reference: SAT]" / "[reference: FCL]"). Resting rows (depth 0 or
///     none, beside a deeper row, or on shapes within `contact_depth_m`) are judged the
///     same way whatever their depth where SAT judges the pair (shapes within
///     `contact_depth_m` also along any axis they overlap by at most that much); rows on
///     shapes that do not penetrate, and a non-convex pair's resting rows, give the angle
///     to the nearest-points direction as a figure, the sign judged where the shapes are
///     apart (two shapes touching at an edge or corner have no defined normal there, and a
///     persistent manifold keeps the normal a point was found with while bodies turn); the pair's deepest row's depth against
///     FCL's within `depth_m` (one-sided against a non-convex upper bound); with points,
///     each point within the pair's depth (or distance, or half the contact margin:
///     the midpoint of a persistent manifold's row) + `depth_m` of the nearer of the two
///     surfaces (a witness point lies on one; any point of the intersection lies within
///     the depth of both); FrameRecord::point_b (the row's point on B) is judged the same
///     way. Engines resolving on world AABBs
///     (ContactGeometry::Aabb) are judged against box-box on rec.aabbs (the least overlap
///     of the two boxes' axes, ReferenceGeometry::aabb_pair); their angle
///     to the posed shapes is a figure. The sign share is a figure.
///  4. `penetration` (checked frames): the largest true penetration (FCL) from frame
///     `penetration_settle_frames` on, at most `penetration_slops` x slop.
///  5. `friction` (every frame), per pair (a manifold's rows together), two rules; the
///     detail says which judged ("[rule: jt3]" or "[rule: scalar]"):
///     - jt3 (FrameRecord::jt3, the tangential impulse vectors): the cone |sum jt3| <=
///       mu sum jn + rounding (16 x 2^-23 of sum |jt3| + mu sum jn; no relative slack),
///       mu the pair's (per-body values combined, else `mu`); dissipation on every pair
///       that is its dynamic bodies' only contact pair, manifolds included: the summed
///       friction impulse must not push the rows' points along their relative sliding
///       (v + w x r at each row's point), sum_k jt3_k . v_t,k / sum_k |jt3_k| <=
///       `friction_speed` + the witness-point allowance, with the sliding taken before
///       the step, with the pair's normal impulses alone, and after the step (a solver
///       may fix its friction direction at any of them; it fails when it pushes along the
///       sliding at all three). Pairs whose friction impulse is at most
///       `friction_cone_abs` are not judged on direction (counted).
///     - scalar jt (no jt3): the cone sum |jt| <= mu sum jn + rounding +
///       `friction_cone_abs`; dissipation where the pair is a single row and the only
///       contact of each of its dynamic bodies, as follows.
///     Translation-only records (or no points): the relative tangential speed at the
///     centres after the step is at most the speed before it (v_pre + dt g on dynamic
///     bodies) + `friction_speed`. Rotating records with points: the row's friction
///     impulse on A, the tangential part of A's momentum change (B's, negated, when A
///     is static), does no positive work on the final sliding at the row's point:
///     J_t/|J_t| . v_t' <= `friction_speed` + the witness-point allowance (|w_a| + |w_b|)
///     s after the step, s the larger of the row's depth and the gap across the point
///     (its FCL distances to the two surfaces summed): an engine may take each body's
///     velocity at its own witness point. This is the maximal-dissipation condition;
///     |v_t'| itself may rise under a sequential-impulse solver's one-direction friction
///     row on spinning bodies (Bullet: 0.14-5% on 4 rows of rot-drop-220), so it is not
///     judged there. Other rows: the cone only (counted).
///  6. `conservation` (every frame with states): isolated dynamic groups (components of
///     the contact graph, 2+ dynamic bodies, no static body in their contacts): linear
///     momentum changes by m g dt only; angular momentum about the group's centre of
///     mass, sum m (x_pre - c_pre) x v + R I R^T w (v, q, w before: v_pre + dt g, q_pre,
///     w_pre; after: v_post, q_post, w_post), kept within angular_momentum_rel x the
///     exchange + dt |w x I w| per body (free rotation) + (depth + margin) |jt| per row
///     (impulses applied at two witness points; with FrameRecord::point_b the change is
///     expected to be exactly sum (p_a - p_b) x J over the group's rows, leaving
///     |p_a - p_b| |jt| open without jt3) (rotating records; n/a for
///     translation-only ones); kinetic energy (translational + rotational) does not rise
///     when every restitution <= 1 (contact_model soft: per pair contact episode instead,
///     PhysicsBodies::contact_model). Groups with locked axes (locked_dofs) do not judge
///     the momentum along them nor, rotation locked, the angular momentum (counted).
///  7. `momentum-balance` (every frame with states; design.md section 13b.7): per dynamic body with
///     contact rows, m (v' - v) - m g dt = sum of its rows' J = jn n + J_t (J_t: jt along
///     -v_t, or +t for octocd's records), and with rotation and points the torques
///     sum (p - x) x J = I_w (w' - w) (p on B: FrameRecord::point_b where the record
///     carries it, with no witness-point allowance) (no gyroscopic term) or = L' - L, L = R I R^T w
///     before and after the step, within its first-order bound (the term; undeclared:
///     either, PhysicsBodies::gyroscopic); bound: balance_ulps x 2^-23 x
///     (rows + 2) x the magnitudes, plus what a scalar jt leaves open (discs in each row's
///     tangent plane; docs/validate-your-engine.md derives it). n/a when the rows are not
///     the step's impulses (impulses_complete false).
///  8. `free-flight` (every frame with states; design.md section 13b.8): per dynamic body without a
///     contact row (or confirmed pair): v' = v + g dt, x' by the declared integrator,
///     the spin by the invariants (L = R I R^T w kept to second order in |w| dt and the
///     rotational energy not rising, or w' = w for an engine without the gyroscopic term;
///     docs/validation.md, "Free rotation: the invariants"), q' = q advanced by w dt within
///     free_flight_angle_rad + (|w| dt)^2. Locked axes are not judged (counted).
///  9. `impulse-feasibility` (checked frames, the --every cadence, with states; docs/validation.md,
///     "Motion explained by feasible contact impulses"): reads no contact row. Per step,
///     octocd finds the contacts itself: every pair whose posed shapes (detection pose) lie
///     within the pair's margin + geometry_slack_m + both bodies' motion through the step,
///     its normals (the separating-axis test's least translation and accepted axes on the
///     hulls, else FCL's; an engine on AABBs: the world boxes' least overlap), its points
///     (the corners of the overlap of the two shapes' near outlines) and, per vertex near a
///     face of the other shape, that face's normal within 45 degrees. Per island (dynamic
///     bodies joined by such contacts, 16 bodies at most: larger ones counted and named,
///     not judged) a linear programme (COIN-OR CLP) over compressive impulses in each
///     point's friction cone (widened to every normal within 1.5 deg of octocd's, then an
///     8-sided pyramid circumscribed about it, 1.082 x that along its edges) minimises the largest residual of the bodies' momentum changes m (v' - v -
///     g dt) and, with rotation, L' - L (or I_w (w' - w) without the gyroscopic term), each
///     in units of its bound: balance_ulps x 2^-23 x (points + 2) x the magnitudes, the
///     torque of that at the farthest point, and with rotation the lever the engine's point
///     may take beside octocd's times the impulses found. Above 1 fails naming the island,
///     the body, its residual, the nearest feasible impulses per pair, and the bodies whose
///     motion left free makes the island feasible. Islands with a sleeping, locked or
///     clamped body are counted, not judged.
/// Reporting (design.md section 13b.13): every row fills ValidationResult::judged and ::causes (per
/// cause its count, worst figure, first examples with frame and item "pair (A, B)",
/// "body I" or "group (I, J, K)", and the failing items) and lists every cause in its
/// detail; a row that judged nothing is n/a with its reason.
/// Cost: a checked frame is O(n) for the posed AABBs plus FCL on the candidate pairs
/// (non-convex mesh pairs that intersect cost the most: their depth is bisected with
/// BVH collide along up to 8 directions).

#include <array>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "octocd/engine.hpp"
#include "octocd/physics_bodies.hpp"
#include "octocd/reference_contact.hpp"
#include "octocd/validation.hpp"

namespace octocd {

class DeviceJudge;  // octocd/device_judge.hpp (validation/device/)


/// "rigid", "soft" or "undeclared".
const char* contact_model_name(PhysicsBodies::ContactModel m);
/// "undeclared", "true" or "false".
const char* gyroscopic_name(PhysicsBodies::Gyroscopic g);
/// "complete", "normal-only" or "none".
const char* impulses_name(PhysicsBodies::Impulses i);
/// The friction coefficient of pair (a, b) as the friction row judges it: the bodies'
/// body_friction combined by `combine` (else `mu`), at least 1e-5 (an engine's friction
/// floor, docs/validation.md "Floors"). a and b index the bodies (caller-checked).
double pair_friction(const PhysicsBodies& bodies, std::uint32_t a, std::uint32_t b);
/// "semi-implicit", "explicit", "any", "substepped" or "undeclared".
const char* integrator_name(PhysicsBodies::Integrator i);

/// What octocd's own cpu and cuda engines declare: mu = the scene's mu_static (the
/// cone of Eq. 21), restitution = the scene's e, the pair's theta as contact margin
/// (vertex proximity, design.md section 5.3), an exact AABB broadphase, contacts on the world AABBs
/// (design.md section 6), slop = delta, semi-implicit Euler (design.md section 4.1), jt along the sliding (design.md section 6's
/// J_t), impulses complete only with response.iterations = 1 (the record holds the first
/// pass), the Jacobi response. Bodies translate only: inertia is not needed.
PhysicsBodies octocd_physics_bodies(const Model& model);

/// Physics-tier validators, fed one FrameRecord at a time (octocd's engines, another
/// engine through octocd/external.hpp, or an external trace v1/v2).
class PhysicsValidators {
 public:
  /// Validators for records of bodies described by `model` (shapes, local boxes in the
  /// body frame, inverse masses; not owned, must outlive this object) and `bodies`.
  /// `label` names the engine in details ("engine 'bullet'"). Builds FCL geometry of
  /// every distinct shape. Throws InputError naming the field when `bodies` has the wrong
  /// sizes or values.
  PhysicsValidators(const Model& model, const PhysicsBodies& bodies, const Tolerances& tol, std::string label);
  ~PhysicsValidators();
  PhysicsValidators(const PhysicsValidators&) = delete;
  PhysicsValidators& operator=(const PhysicsValidators&) = delete;

  /// Judges one step. The record is trusted (callers with data from outside check it
  /// first: check_frame_record). `checked` runs the costly rows (broadphase and contact
  /// completeness, contact geometry) on this frame; friction and conservation run on
  /// every frame that has states.
  void observe(const FrameRecord& rec, bool checked);

  /// `flat`'s pairs on the world AABBs of the last observed frame that have a dynamic body
  /// (sorted by (a, b); static-static pairs left out), when that frame's
  /// broadphase-completeness computed them (a checked frame of an engine that declares an
  /// exact AABB broadphase: octocd's); null otherwise. Valid until the next observe().
  const std::vector<Pair>* flat_pairs() const;

  /// The eight rows so far (1-8 above), tier Physics, each with how many items it judged,
  /// its causes and its own time (ValidationResult::seconds).
  std::vector<ValidationResult> results() const;

  /// Polled inside observe's long loops (every 16 candidate pairs, contacts or groups);
  /// observe throws ValidationStopped when it returns true. Empty (default): never.
  void set_stop(std::function<bool()> stop);

  /// Threads for the per-pair reference geometry of a checked frame (FCL, SAT):
  /// ValidationOptions::threads (0: the hardware's). Verdicts do not depend on it.
  void set_threads(int threads);

  /// Judges rows 1 (broadphase-completeness) and 4 (penetration) of the checked frames on
  /// `device` (octocd/device_judge.hpp: the candidates and the box pairs' separating-axis
  /// test there, every other pair by the CPU reference), and says so in their details;
  /// null: on the CPU (default). Set before the first observe(). Verdicts, causes and
  /// failing items are the CPU's (tests/gpu/test_device_judge.cpp).
  void set_judge_device(std::unique_ptr<DeviceJudge> device);

  /// Shards (`validate --trace-in T --shard i/N`): with contact_model soft, the energy of
  /// an isolated group is judged over its contact episode, which may begin in one shard's
  /// frames and end in the next's. This validator then judges only the episodes whose
  /// first contact step lies in [first, last] (frame numbers; default: every episode).
  /// For the verdict of the whole run, feed it every frame before `first` with
  /// observe_episodes (so it knows which episodes are open when its frames begin: judged
  /// by an earlier shard), its frames with observe, then frames after `last` with
  /// observe_episodes while episodes_pending().
  void set_episode_frames(std::int64_t first, std::int64_t last);

  /// A frame outside the judged ones: only the soft-contact episodes advance (opened,
  /// grown, spoiled, closed; closed ones begun in the episode frames are judged); no row
  /// counts it. Nothing when the energy is not judged per episode (contact_model rigid, a
  /// restitution above 1).
  void observe_episodes(const FrameRecord& rec);

  /// True while an episode begun in the episode frames is still open (its bodies still in
  /// contact): a shard reads on past its last frame until this is false or the trace ends.
  bool episodes_pending() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

/// The detection pose of body i in `rec` (FrameRecord::x_det / q_det, or octocd's rule:
/// world AABB minus local box, identity orientation).
Pose detection_pose(const Model& model, const FrameRecord& rec, std::size_t i);

}  // namespace octocd
