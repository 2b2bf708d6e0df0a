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
///     reference ("[reference: SAT]" / "[reference: FCL]"); rows on shapes
///     that do not penetrate give the angle to the nearest-points direction as a figure
///     (two shapes touching at an edge or corner have no defined normal there, and a
///     persistent manifold keeps the normal a point was found with while bodies turn); the pair's deepest row's depth against
///     FCL's within `depth_m` (one-sided against a non-convex upper bound); with points,
///     each point within the pair's depth (or distance, or half the contact margin:
///     the midpoint of a persistent manifold's row) + `depth_m` of the nearer of the two
///     surfaces (a witness point lies on one; any point of the intersection lies within
///     the depth of both). Engines resolving on world AABBs
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
///     (impulses applied at two witness points) (rotating records; n/a for
///     translation-only ones); kinetic energy (translational + rotational) does not rise
///     when every restitution <= 1 (contact_model soft: per pair contact episode instead,
///     PhysicsBodies::contact_model). Groups with locked axes (locked_dofs) do not judge
///     the momentum along them nor, rotation locked, the angular momentum (counted).
///  7. `momentum-balance` (every frame with states; design.md section 13b.7): per dynamic body with
///     contact rows, m (v' - v) - m g dt = sum of its rows' J = jn n + J_t (J_t: jt along
///     -v_t, or +t for octocd's records), and with rotation and points the torques
///     sum (p - x) x J = I_w (w' - w) (no gyroscopic term) or = L' - L, L = R I R^T w
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
#include "octocd/reference_contact.hpp"
#include "octocd/validation.hpp"

namespace octocd {

class DeviceJudge;  // octocd/device_judge.hpp (validation/device/)

/// How a pair's friction coefficient or restitution is made from the two bodies' values.
enum class MaterialCombine {
  Product,    ///< a * b (Bullet's btManifoldResult default)
  Min,        ///< min(a, b)
  Max,        ///< max(a, b)
  Average,    ///< (a + b) / 2 (PhysX's default)
  Geometric,  ///< sqrt(a * b)
};
/// "product", "min", "max", "average", "geometric".
const char* material_combine_name(MaterialCombine c);
/// The pair's value of a and b under rule c.
double combine_material(MaterialCombine c, double a, double b);

/// Which geometry an engine's contacts are computed on (what its normals and depths are
/// judged against).
enum class ContactGeometry {
  /// The posed shapes themselves (meshes, boxes): any engine's default.
  Shape,
  /// The bodies' world AABBs: octocd's design.md section 6 response resolves every contact on the
  /// two world AABBs (Eq. 9-10), so its normal is an AABB axis. The angle to the posed
  /// shapes' normal is then reported as a figure, not judged.
  Aabb,
};

/// What the physics tier knows of the bodies beyond the Model (shapes, local boxes,
/// inverse masses): inertia, materials and what the engine declares of itself.
struct PhysicsBodies {
  /// Body-frame inertia tensor per body (kg m^2, symmetric positive definite; row-major
  /// 3x3). Empty: derived from the local AABB as a solid box of the body's mass
  /// (m/12 (b^2 + c^2), ...), as Bullet's convex shapes do. Unused for static bodies.
  std::vector<std::array<double, 9>> inertia;
  /// Per-body friction coefficient and restitution (>= 0). Empty: `mu` and
  /// `restitution` for every pair.
  std::vector<float> body_friction, body_restitution;
  /// Pair friction coefficient and restitution when no per-body values are given.
  double mu = 0.6;
  double restitution = 0.5;
  /// How per-body values combine into a pair's: friction (external traces v2:
  /// `friction_combine`) and restitution (`restitution_combine`).
  MaterialCombine combine = MaterialCombine::Product;
  MaterialCombine restitution_combine = MaterialCombine::Product;
  /// Contact margin (m, >= 0): contacts are expected up to this distance (Bullet's
  /// contact breaking threshold, PhysX's contact offset); a contact on a pair farther
  /// apart is a false contact. octocd's engines: the pair's theta (vertex proximity,
  /// design.md section 5.3), given by `theta_margin`.
  double contact_margin = 0.02;
  /// Use the model's pair theta (Model::theta) as the contact margin (octocd's engines).
  bool theta_margin = false;
  /// The engine declares an exact AABB broadphase (its candidate pairs are exactly the
  /// overlapping world AABBs, Eq. 6): also held to set equality with `flat`.
  bool broadphase_exact = false;
  /// What the engine's contact normals and depths are computed on.
  ContactGeometry contact_geometry = ContactGeometry::Shape;
  /// What the engine collided each body as (design.md section 13b.10): empty, every body as its shape
  /// (a box, or a mesh's triangles); else one per body. The geometric rows (broadphase
  /// and contact completeness, contact geometry, penetration) judge the declared shape;
  /// its gap to the true shape is a figure. `Sphere` on a box shape is an InputError.
  std::vector<CollisionShape> collision_shape;
  /// The scene's slop (m, design.md section 6 delta): the penetration bound is a multiple of it.
  double slop = 0.001;
  /// A velocity clamp the engine declares (m/s, per component; 0 = none): octocd's Eq. 23
  /// v_max, PhysX's maxLinearVelocity. A clamp removes momentum by design, so an isolated
  /// group with a body at the clamp after the step is not judged on conservation (the
  /// row counts such groups).
  double velocity_clamp = 0.0;

  // ---- Declarations (design.md section 13b.12; external traces v2: root attributes and
  // /bodies/locked_dofs; docs/trace-format.md, "Declarations").
  /// `contact_model`: how the engine's contacts act. Rigid: impulses resolve a contact
  /// within the step, so an isolated group's kinetic energy never rises in a step. Soft
  /// (compliant contacts: springs, soft constraints, XPBD compliance): a contact may store
  /// energy in its penetration and give it back in a later step, so energy is judged over
  /// each pair's contact episode (first step with a row to the first without), not per step.
  /// Undeclared (external traces without the attribute): every admissible value, so an
  /// isolated group fails energy only where it fails both ways: a step raising its kinetic
  /// energy (rigid) inside a contact episode whose mechanical energy rose (soft).
  enum class ContactModel { Rigid, Soft, Undeclared };
  ContactModel contact_model = ContactModel::Rigid;
  /// `gyroscopic`: how the engine treats the gyroscopic term (w x I w) of free rotation
  /// (docs/validation.md, "Free rotation: the invariants").
  enum class Gyroscopic {
    /// Not declared: a torque-free body may keep w (no term) or keep its angular momentum
    /// L = R I R^T w and not gain rotational energy (the term, in any first-order form);
    /// precession is never a failure. Bullet applies its implicit term only to bodies in a
    /// solver batch with contacts, so one trace holds both.
    Undeclared,
    /// Declared "true": every body carries the term. free-flight holds L and the
    /// rotational energy to the integrator's order; momentum-balance judges the change of
    /// L against the contact torques.
    Integrated,
    /// Declared "false": no term. free-flight expects w' = w; momentum-balance
    /// I_w (w' - w) = the contact torques.
    Absent,
  };
  Gyroscopic gyroscopic = Gyroscopic::Undeclared;
  /// `integrator`: how a free body's position advances over a step, x' = x + dt v + a g dt^2
  /// with v the velocity before the step (docs/validation.md, "Free flight: any consistent
  /// integrator"): semi-implicit Euler x' = x + dt v' (a = 1; design.md section 4.1,
  /// octocd's engines), explicit x' = x + dt v (a = 0), `Any` (a in [0, 1] per step),
  /// `Substepped` (n = `substeps` semi-implicit substeps of dt / n: a = (n + 1) / (2n);
  /// Rapier, PhysX TGS, Box2D v3, XPBD), or `Undeclared` (every admissible value: a in
  /// [0, 1] and the orientation of substepping, as `Any` with substepping's allowances).
  enum class Integrator { SemiImplicit, Explicit, Any, Substepped, Undeclared };
  Integrator integrator = Integrator::SemiImplicit;
  /// With Integrator::Substepped: the substep count n (>= 1; root attribute `substeps`).
  int substeps = 1;
  /// The integrator admits substepping (Substepped or Undeclared): the normal and the
  /// impulse points may turn with the bodies within the step (momentum-balance), the spin
  /// may change within it (free-flight's orientation).
  bool may_substep() const { return integrator == Integrator::Substepped || integrator == Integrator::Undeclared; }
  /// Per body (empty: none locked): bits 0-2 translation along world x, y, z, bits 3-5
  /// rotation about world x, y, z locked by a joint (6 bits at most). Rows about a locked
  /// axis are n/a for that body and counted (a joint's impulses are not in the contact
  /// rows): momentum-balance and free-flight skip the locked components, conservation does
  /// not judge the angular momentum (rotation locked) or the momentum along a locked axis
  /// (translation locked) of a group with such a body.
  std::vector<std::uint8_t> locked_dofs;
  /// `deactivation` (with /states/sleeping): whether the engine puts bodies to sleep.
  enum class Deactivation {
    /// Not declared: every body is judged awake (a body an engine froze fails free-flight).
    Undeclared,
    /// Declared "off": the engine never deactivates a body.
    Off,
    /// Declared "on", or /states/sleeping given: FrameRecord::asleep_pre / asleep_post
    /// flag the bodies asleep. A body asleep before and after a step must not move (x, q,
    /// v, w kept: free-flight's `sleeping` cause) and is not judged as free-flying or on
    /// momentum balance; one that fell asleep in the step is not judged on it (its
    /// velocity zeroed by the engine); a group with a sleeping body is not judged on
    /// conservation; a pair whose dynamic bodies were all asleep before the step needs no
    /// candidate pair or contact row (engines do not collide sleeping bodies). Counted.
    Flagged,
  };
  Deactivation deactivation = Deactivation::Undeclared;
  /// `impulse_points` "witness-pair": each body takes a row's impulse at its own witness
  /// point, the two up to the row's depth + contact margin apart in any direction, so
  /// conservation's angular momentum allows that lever times |J| (jn and jt) per row;
  /// otherwise ("one", the default) the lever applies to the friction part only.
  bool witness_pair_impulses = false;
  /// `friction_directions` (external traces v2 without /contacts/jt3): 1 = each row's
  /// friction impulse lies along its sliding (-v_t), so the scalar jt is the whole of it;
  /// 2 = two friction directions (jt is only its component along -v_t); 0 = undeclared.
  /// Read by the row plan (plan_trace_rows): momentum-balance needs jt3 or 1.
  int friction_directions = 0;

  // ---- What octocd's own records mean (set by octocd_physics_bodies).
  /// The rows' `jt` is design.md section 6's J_t along t = v_t / |v_t| (negative when friction opposes
  /// the sliding: octocd's ContactRecord), not the trace convention's impulse along
  /// -v_t / |v_t|.
  bool jt_along_sliding = false;
  /// The rows carry every impulse the step applied. octocd with response.iterations > 1
  /// records the first relaxation pass only (its later passes apply more impulses on the
  /// same pairs): momentum-balance is then n/a with that reason.
  bool impulses_complete = true;
  /// `impulses`: what the contact rows' impulses hold (external traces: the root attribute
  /// `impulses`; docs/validation.md, "What the impulses hold").
  enum class Impulses {
    /// jn and the friction (jt, jt3) are the step's impulses (default).
    Complete,
    /// jn is reported; the friction is not (jt, jt3 hold whatever the writer put there, never
    /// read): `friction` is n/a, `momentum-balance` holds each body's residual
    /// m (v' - v) - m g dt - sum jn n within the sum of its rows' cones (mu jn, a disc in
    /// each row's tangent plane), conservation's witness-point lever takes mu jn for |jt|.
    NormalOnly,
    /// No impulse is reported: `friction` and `momentum-balance` n/a; conservation judges
    /// momentum and energy, not the angular momentum (its witness-point lever needs |J|).
    None,
  };
  Impulses impulses = Impulses::Complete;
  /// `speculative` 1: contact rows may join shapes apart by up to the contact margin plus
  /// their approach within the step; contact-completeness's false-contact bound adds
  /// dt (|v_a - v_b| + |w_a| R_a + |w_b| R_b) (R: the body's reach from its origin,
  /// velocities the larger of before and after the step; not judged without states).
  bool speculative = false;
  /// `contacts_complete` 0: the engine's API may drop contact rows (Havok). free-flight and
  /// conservation judge only the bodies and groups the exact reference shows apart from
  /// every other body through the step (docs/validation.md, "Incomplete contact
  /// reporting"); contact-completeness and momentum-balance are n/a, naming it.
  bool contacts_complete = true;
  /// `manifold_points` "persistent": a row's points ride on each body and may drift off
  /// the shapes. Read, not yet used beyond this: contact-geometry's point check is not
  /// applied (counted); normals and depths are judged.
  bool persistent_points = false;
  /// `depth_per` "manifold": each row carries its manifold's one depth (Jolt's
  /// mPenetrationDepth). contact-geometry judges one depth per pair: its deepest row's
  /// depth against the exact reference's penetration along that row's normal (two convex
  /// polytopes: the overlap of their hulls projected on the normal, >= the minimum
  /// translation; other shapes: the minimum translation, as "point"); a row's point may
  /// lie within that (larger) depth of the surfaces.
  bool depth_per_manifold = false;
  /// `depth_per` "unknown": the rows carry no depth of their own (Havok's witness points).
  /// contact-geometry's depth cause is n/a (counted, named), no row's depth decides
  /// whether its normal is judged, and the point check takes the reference's depth;
  /// penetration is still judged on the posed shapes. The rows' depth is still read as
  /// the witness points' lever (momentum-balance, conservation, friction): write the
  /// witness points' separation along the normal, or 0.
  bool depth_unknown = false;
  /// `depth_per` declared. Undeclared admits "point" and "manifold": a pair's depth fails
  /// only where it misses both SAT's minimum and the hulls' overlap along its deepest row's
  /// normal ("unknown" is never assumed: it gives the depth judgement up).
  bool depth_per_declared = true;
  /// `/bodies/convex_radius` (m, >= 0; empty: every body 0): each body is collided as its
  /// shape inflated by this radius (the Minkowski sum with a sphere: Jolt's convex radius,
  /// Box2D's rounded polygons). Every geometric rule judges the rounded shapes: their
  /// distance is the posed shapes' minus the radii sum, their depth the posed shapes' plus
  /// it (exact for a Minkowski sum with a sphere); candidates grow by the radius.
  std::vector<double> convex_radius;
  /// `/bodies/com_offset` (m, body frame; empty: every body's position is its centre of
  /// mass): where each body's centre of mass lies relative to the point its position gives
  /// (MuJoCo's free joint integrates the body frame's origin). The trace reader turns the
  /// records' states into the centres of mass (x + R c; with `velocity_at` "origin" also
  /// v + w x R c), so the rules on states judge the centre of mass; the detection poses
  /// stay the body frame's, where the shapes are placed. Records fed to PhysicsValidators
  /// directly follow the same split: states (x_pre, x_post, v_pre, v_post) of the centres
  /// of mass, detection poses (x_det, q_det) of the body frames; the rows' levers start at
  /// x_det + R c. One offset per body, finite, or none (else InputError).
  std::vector<std::array<double, 3>> com_offset;
  /// With com_offset: the root attribute `velocity_at` "origin" (the stored velocity was the
  /// origin's, converted by the reader); free-flight's velocity floor takes the stored
  /// magnitude (docs/validation.md, "Floors").
  bool velocity_at_origin = false;
  /// The engine is design.md section 6's Jacobi response (octocd's cpu and cuda): an energy failure of
  /// an isolated group is reported as the model's property (its Jacobi-summed impulses
  /// computed from one pre-response state overshoot on chains), not as an engine fault.
  bool jacobi_response = false;
};

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
