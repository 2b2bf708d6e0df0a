#pragma once
/// \file physics_bodies.hpp
/// What a trace or an engine declares of its bodies beyond their shapes, boxes and inverse
/// masses (design.md section 13): inertia, materials, the contact margin, the geometry its
/// contacts are computed on and the declarations of design.md section 13b.12. Filled by the
/// external-trace reader (octocd/external_trace.hpp) and by octocd's own engines
/// (octocd_physics_bodies, octocd/physics.hpp); read by the physics tier (octocd/physics.hpp).
/// Plain data: no function here reads a file.

#include <array>
#include <cstdint>
#include <limits>
#include <vector>

namespace octocd {

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

/// What an engine collided a body as (design.md section 13b.10; external traces v2:
/// `/bodies/collision_shape` or the root attribute `collision_shape`). The physics tier's
/// geometric rows judge this shape; its gap to the true shape is a figure.
enum class CollisionShape {
  Mesh,        ///< "mesh": the shape itself (a box shape: the box; a mesh: its triangles)
  ConvexHull,  ///< "convex_hull": the convex hull of the shape's vertices (a box: itself)
  Box,         ///< "box": the shape's local box (its AABB in the body frame)
  /// "sphere": centred on the local box, through the mesh's farthest vertex. Mesh shapes
  /// only (a box shape cannot be a sphere: refused).
  Sphere,
};
/// "mesh", "convex_hull", "box", "sphere".
const char* collision_shape_name(CollisionShape c);

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
  /// One entry of `/contacts/incomplete`: step `frame` (1 .. F) may lack rows, of the pair
  /// (a, b) (a < b, body indices) or, where a == b == kEveryPair, of any pair.
  struct IncompleteRows {
    std::int64_t frame = 0;
    std::uint32_t a = 0, b = 0;
  };
  /// IncompleteRows::a and b of an entry naming a whole step.
  static constexpr std::uint32_t kEveryPair = 0xffffffffu;
  /// `/contacts/incomplete` (with contacts_complete 1): the steps, or pairs of a step, whose
  /// rows the engine may have dropped (Havok: the step that ends a contact), sorted by
  /// (frame, a, b), no duplicates; empty: none. On those only, as contacts_complete 0 does
  /// for every step: contact-completeness does not require the pair's rows, momentum-balance
  /// does not judge its bodies, and free-flight and conservation judge a body or group there
  /// only where the exact reference shows it apart from the declared pairs' other bodies
  /// (docs/validation.md, "Incomplete contact reporting"). The rest is judged as complete.
  std::vector<IncompleteRows> incomplete_rows;
  /// `manifold_points` "persistent": a row's points ride on each body and may drift off
  /// the shapes. Read, not yet used beyond this: contact-geometry's point check is not
  /// applied (counted); normals and depths are judged.
  bool persistent_points = false;
  /// `normal_reuse_deg` (degrees, [0, 180]): the most a pair's two bodies turn relative to
  /// each other while the engine still applies a contact normal it found on an earlier step.
  /// impulse-feasibility gives each contact point the normals it carried on earlier steps
  /// (a persistent manifold's, docs/validation.md, "Motion explained by feasible contact
  /// impulses") only from the steps whose relative rotation of the pair lies within this
  /// angle of the current one, walking back while it lies within twice it (a cached manifold
  /// found at step m is reused while each later step stays within the angle of m's).
  /// 0: every normal is the step's own (MuJoCo, ODE, DART); 2: Jolt's body-pair cache
  /// (PhysicsSettings::mBodyPairCacheCosMaxDeltaRotationDiv2 = cos(1 deg)); undeclared
  /// (infinity): no bound, a point keeps its normal while its material points hold (Bullet).
  double normal_reuse_deg = std::numeric_limits<double>::infinity();
  /// `friction_per` "manifold": the engine applies a pair's friction as one tangential
  /// impulse of at most mu times the pair's summed normal impulse at one point of its
  /// contact patch (the mean of its manifold's points, loaded or speculative), and a
  /// torsion about the normal of at most mu sum_k d_k N_k (d_k: point k's distance from
  /// that point in the contact plane): Jolt 5.6's friction model. impulse-feasibility
  /// pools each pair's friction that way instead of a Coulomb cone at each contact point
  /// ("point", the default); rows' reported friction is judged as before.
  bool friction_per_manifold = false;
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
  /// The root attribute `integrated_point` "origin" (default "com"): the engine's
  /// integrator advances the body frame's origin (x' = x + dt v_o, v_o' = v_o + dt times the
  /// origin's acceleration: MuJoCo's free joint), not the centre of mass. Such a consistent
  /// first-order integrator moves the centre of mass off its own rule by up to
  /// |c| dt w (3 |w' - w| + 2 dt w^2) in velocity and |c| dt (|w' - w| + 2 dt w^2) in
  /// position per step (w the larger of |w|, |w'|; docs/validation.md, "An engine that
  /// integrates the body origin"): free-flight and momentum-balance allow that drift, and
  /// judge the centre of mass otherwise as before. Needs com_offset to change anything.
  bool integrated_origin = false;
  /// The engine is design.md section 6's Jacobi response (octocd's cpu and cuda): an energy failure of
  /// an isolated group is reported as the model's property (its Jacobi-summed impulses
  /// computed from one pre-response state overshoot on chains), not as an engine fault.
  bool jacobi_response = false;
};

}  // namespace octocd
