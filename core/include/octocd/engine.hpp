#pragma once
/// \file engine.hpp
/// The two seams every engine shares (ARCHITECTURE.md): one `Engine` interface that the
/// CLI, the trace writer and the validators hold for `cpu`, `cuda` and `bullet` alike, and
/// one `FrameRecord` per step: what an engine did, in engine-neutral arrays, so the
/// validators judge the state an engine actually applied.
///
/// `Model` is what every engine is built from: the scene, its shapes (meshes with their
/// per-mesh octrees) and its bodies with their initial state. It is built once on the
/// host (`build_model`) and shared, so every engine starts from the same bits.

#include <array>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "octocd/broadphase.hpp"
#include "octocd/math.hpp"
#include "octocd/mesh.hpp"
#include "octocd/mesh_octree.hpp"
#include "octocd/pose.hpp"
#include "octocd/scene.hpp"

namespace octocd {

/// The named stages of one step, in execution order (like Box2D's profile).
enum class Stage : int {
  Integrate = 0,   ///< Eq. 1-3
  Aabbs,           ///< world AABBs from positions
  Broadphase,      ///< design.md section 5.1
  Midphase,        ///< design.md sections 5.2-5.3: per-mesh octree levels + vertex proximity
  Response,        ///< design.md section 6: corrections, impulses, friction, clamp
  Metrics,         ///< energy, momentum, penetration statistics
  Count
};

/// Stage name as used in traces and summaries ("integrate", "aabbs", "broadphase",
/// "midphase", "response", "metrics").
const char* stage_name(Stage s);

/// Everything measured in one step (one row of the trace's /frames).
struct FrameMetrics {
  std::int64_t frame = 0;          ///< 1-based index of the step just taken
  double time = 0.0;               ///< simulated time after the step (s)
  double step_ms = 0.0;            ///< wall time of the whole step (ms)
  std::array<double, static_cast<int>(Stage::Count)> stage_ms{};  ///< wall ms per stage
  /// Broadphase pairs before the exact AABB test: the pairs its cells (octree, hash) or
  /// tree leaves (Bullet's fattened AABBs) paired up; n(n-1)/2 for `flat`. A cost figure.
  std::uint64_t cell_candidates = 0;
  /// Broadphase pairs: every pair with overlapping world AABBs (Eq. 6), static-static
  /// ones (walls touching walls) included, as `flat` gives them.
  std::uint64_t aabb_pairs = 0;
  /// The aabb_pairs with at least one dynamic body (w > 0): the pairs that can produce a
  /// contact (static-static pairs are skipped by the midphase).
  std::uint64_t dynamic_pairs = 0;
  std::uint64_t box_tests = 0;        ///< midphase cell-box tests
  std::uint64_t box_pairs = 0;        ///< midphase surviving deepest-level box pairs
  std::uint64_t vertex_tests = 0;     ///< narrow-phase vertex tests
  /// Contacts resolved by the response's first pass: confirmed by the midphase and kept
  /// by Eq. 9 (all three overlaps > 0); equals the rows of /contacts for the frame.
  std::uint64_t contacts = 0;
  double penetration_mean = 0.0;   ///< mean AABB d_p over those contacts (m), Eq. 10
  double penetration_max = 0.0;    ///< max d_p (m)
  double penetration_share_above_slop = 0.0;  ///< share of contacts with d_p > delta, [0, 1]
  double kinetic_energy = 0.0;     ///< sum 0.5 m |v|^2 over dynamic bodies (J)
  std::array<double, 3> momentum{};  ///< sum m v over dynamic bodies (kg m/s)
  std::uint64_t memory_bytes = 0;  ///< bytes held by the pipeline's buffers
};

/// One contact as resolved by the response's first pass (design.md section 6): optional /contacts in
/// traces; the per-contact validators (contraction, friction) read these terms.
struct ContactRecord {
  Pair pair;            ///< (a, b), a < b
  Vec3 normal;          ///< from b to a (unit)
  float depth = 0.0f;   ///< AABB d_p (m) before correction (Eq. 10)
  float jn = 0.0f;      ///< normal impulse (kg m/s)
  float jt = 0.0f;      ///< friction impulse along t (kg m/s)
  int axis = 1;         ///< axis of the normal (0 = x, 1 = y, 2 = z)
  Vec3 v_a, v_b;        ///< pre-response velocities (m/s)
  Vec3 dx_a, dx_b;      ///< this contact's position corrections, before per-body averaging (m)
  Vec3 dv_a, dv_b;      ///< this contact's velocity changes (m/s)
  /// World contact point (m) of a manifold row (external traces v2, `bullet` with
  /// rotation); meaningful only when FrameRecord::has_points. octocd's engines leave it 0.
  Vec3 point;
};

/// A shape shared by bodies: a box or a mesh with its octree. Local frame centred on the
/// local AABB centre, so a body's position is its AABB centre.
struct Shape {
  std::string name;                          ///< e.g. "bunny@0.2" or "box"
  Aabb local;                                ///< local AABB (m)
  std::shared_ptr<const MeshOctree> octree;  ///< nullptr for boxes
  std::shared_ptr<const Mesh> mesh;          ///< welded, normalised, scaled; nullptr for boxes
  float mean_edge = 0.0f;                    ///< mean edge length (m), 0 for boxes
};

/// Hot body state in structure-of-arrays form (design.md section 3), float32. Index = body id.
struct BodyState {
  std::vector<Vec3> x;   ///< positions: centre of the world AABB (m)
  std::vector<Vec3> v;   ///< velocities (m/s)
  std::vector<float> w;  ///< inverse masses (1/kg); 0 = static
  /// Rotating engines only (design.md section 13: `bullet` with rotation): orientations (unit
  /// quaternions, body to world) and angular velocities (rad/s, world frame), one per
  /// body; x is then the origin of the body frame (the centre of the shape's local AABB,
  /// Bullet's centre of mass). Empty for octocd's engines, which translate only
  /// (identity, zero).
  std::vector<Quat> q;
  std::vector<Vec3> omega;
  /// Number of bodies.
  std::size_t size() const { return x.size(); }
};

/// Cold per-body data, kept apart from the hot state.
struct BodyInfo {
  std::uint32_t shape = 0;  ///< index into Model::shapes
  std::string group;        ///< scene group name ("walls" for generated walls)
};

/// What every engine is built from (design.md section 3): the scene, its shapes and its bodies with
/// their initial state. Walls come first, then the groups' bodies in order.
struct Model {
  Scene scene;                  ///< the validated scene
  std::vector<Shape> shapes;    ///< indexed by BodyInfo::shape
  std::vector<BodyInfo> bodies; ///< per body
  BodyState initial;            ///< state at frame 0 (q, omega filled when scene_rotates)
  /// Per shape (m): the scene's theta, or with `auto` the shape's mean edge; a pair's theta
  /// is the larger of its two shapes' values (pair_theta). O(shapes), not O(shapes^2).
  std::vector<float> theta_shape;

  /// theta (m) for a pair of shapes: the scene's value or `auto` (design.md section 6).
  float theta(std::uint32_t shape_a, std::uint32_t shape_b) const {
    return pair_theta(theta_shape[shape_a], theta_shape[shape_b]);
  }
  /// Local AABB of body i (m).
  const Aabb& local_box(std::size_t i) const { return shapes[bodies[i].shape].local; }
};

/// Builds shapes (loading, welding, normalising and scaling meshes; building their
/// octrees to max(D_m, deepest midphase level)), walls and bodies from a validated scene.
/// Throws InputError naming the scene key for unreadable meshes.
std::shared_ptr<const Model> build_model(const Scene& scene);

/// Pairs of static bodies (w = 0) whose world AABBs overlap (Eq. 6, inclusive) at the
/// initial state. Constant over a run (static bodies never move), so engines whose
/// broadphase has no per-pair loop on the host report dynamic_pairs = aabb_pairs - this.
std::uint64_t static_static_pairs(const Model& model);

/// The largest mean number of vertices per occupied cell of the midphase's deepest level
/// (MidphaseConfig::levels' last) over the model's mesh shapes: a shape's vertex count over
/// its occupied cells at that level (MeshOctree::level_begin .. level_end). 0 when the
/// model has no mesh or its midphase is AABB-only. A measure of the work of one leaf cell
/// pair in the vertex narrow phase; the cuda engine picks its small-scene kernel by it
/// (docs/gpu.md, "Small scenes: the kernel's shape").
double largest_mean_leaf_vertices(const Model& model);

/// What an engine did in one step, engine-neutral (ARCHITECTURE.md seam 2). Filled only
/// while recording is on (Engine::set_recording); the validators read only this.
struct FrameRecord {
  std::int64_t frame = 0;           ///< the step this describes (1-based)
  std::vector<Vec3> x_pre, v_pre;   ///< state before the step (before integration)
  std::vector<Aabb> aabbs;          ///< world AABBs the broadphase saw (after integration)
  std::vector<Pair> pairs;          ///< candidate pairs the engine itself used, sorted
  std::vector<Pair> confirmed;      ///< pairs confirmed by midphase + narrow phase, sorted
  std::vector<ContactRecord> contacts;  ///< first-pass response terms (Eq. 9 survivors)
  std::vector<Vec3> x_post, v_post; ///< state after the step (what the engine applied)
  /// What the record holds. octocd's engines fill everything (both true). A record of
  /// another engine (octocd/external.hpp, `octocd validate --trace-in`) may have no
  /// candidate pairs (`pairs` then means nothing) and carries only pair, normal, depth,
  /// jn, jt per contact; the validators then derive the rest from the states.
  bool has_pairs = true;          ///< `pairs` is the engine's candidate set for this step
  bool has_contact_terms = true;  ///< contacts carry axis, v_a/v_b, dx_a/dx_b, dv_a/dv_b

  // ---- Rotating engines (design.md section 13, external traces v2). All empty for octocd's engines,
  // which translate only: orientation = identity, angular velocity = 0.
  /// Orientations before / after the step (unit quaternions, body to world); empty: the
  /// identity for every body.
  std::vector<Quat> q_pre, q_post;
  /// Angular velocities before / after the step (rad/s, world frame); empty: zero.
  std::vector<Vec3> w_pre, w_post;
  /// The pose at which the step's collision detection ran (the AABBs, pairs and contacts
  /// refer to it): positions (m) and orientations. Empty: octocd's rule, the position
  /// after integration (world AABB minus local box, design.md sections 4.1-4.2) with the identity
  /// orientation. Engines that detect before integrating (Bullet, PhysX) give x_pre/q_pre.
  std::vector<Vec3> x_det;
  std::vector<Quat> q_det;
  /// `contacts` may hold several rows per pair (a manifold), consecutive, in (a, b)
  /// order; false: one row per pair (octocd's engines).
  bool manifolds = false;
  /// Every contact carries its world `point`.
  bool has_points = false;
  /// The tangential (friction) impulse vector of each contact row on A (kg m/s, world
  /// frame, orthogonal to the row's normal), one per entry of `contacts`, in the same
  /// order (external traces v2: `/contacts/jt3`; `bullet` with rotation: the impulses of
  /// its friction directions summed as a vector). Empty when the engine gives none: the
  /// physics tier then judges the scalar ContactRecord::jt.
  std::vector<Vec3> jt3;
  /// Where the engine applied each row's impulse on B (m, world frame), one per entry of
  /// `contacts`, in the same order, when it applies a row at two witness points: the
  /// row's ContactRecord::point is then the point on A, this the point on B (external
  /// traces v2: `/contacts/point_b`; `bullet` with rotation: getPositionWorldOnB of body1,
  /// btSequentialImpulseConstraintSolver's rel_pos2). Empty: one point per row (octocd's
  /// engines), used for both bodies. Only with has_points.
  std::vector<Vec3> point_b;
  /// Bodies the engine had deactivated (put to sleep) in the state before / after the
  /// step: one flag per body, 1 = asleep (external traces v2: `/states/sleeping`). Empty:
  /// every body awake. A body asleep in both is judged not to move; one that fell asleep
  /// in the step (its velocity zeroed by the engine) is not judged on that step.
  std::vector<std::uint8_t> asleep_pre, asleep_post;
};

/// What a rotating engine states about its bodies and contacts beyond the Model (design.md section 13):
/// the root attributes and /bodies tables of a version-2 trace (docs/trace-format.md,
/// "Version 2"), so octocd's physics-tier validators judge it with the engine's own
/// inertia, materials and contact margin. Engines that translate only have none.
struct RotationTraits {
  /// Body-frame inertia tensor per body (kg m^2, row-major 3x3; zeros for static bodies).
  std::vector<std::array<float, 9>> inertia;
  /// Per-body friction coefficient and restitution (>= 0), combined per pair by
  /// `friction_combine` / `restitution_combine`.
  std::vector<float> body_friction, body_restitution;
  /// The pair values the per-body ones combine to (the scene's mu and e).
  float mu = 0.6f, restitution = 0.5f;
  /// "product" (Bullet's rule), "min", "max", "average" or "geometric".
  std::string friction_combine = "product", restitution_combine = "product";
  /// Contacts are reported up to this distance between the shapes (m).
  float contact_margin = 0.02f;
  /// "pre-step" (detection at the state before the step) or "integrated".
  std::string detection = "pre-step";
  /// The candidate pairs are exactly the overlapping world AABBs (false: conservative).
  bool broadphase_exact = false;
  /// "shape" (contacts computed on the posed shapes) or "aabb".
  std::string contact_geometry = "shape";
  /// What every body is collided as, written as the root attribute `collision_shape`
  /// ("mesh", "convex_hull", "box", "sphere"; design.md section 13b.10); empty: not written (each body
  /// as its shape).
  std::string collision_shape;
  /// The same per body, written as /bodies/collision_shape instead of the root attribute
  /// (one of the four names each; empty: not written). Bullet's hull mode: "convex_hull"
  /// (a dynamic mesh is its hull, a box itself), "mesh" (a static triangle mesh).
  std::vector<std::string> body_collision_shape;
  /// The bodies rotate. false (a translation-only engine that records, e.g. Bullet's hull
  /// mode without rotation): the version 2 trace has no /states/orientation,
  /// /states/angular_velocity or /bodies/inertia (readers take the bodies as never
  /// turning), `inertia` may be empty and records carry no q or w.
  bool rotates = true;
  /// Every record carries the engine's candidate pairs (FrameRecord::has_pairs): the
  /// trace writes /pairs. false (an engine that does not expose its broadphase, e.g.
  /// MuJoCo): no /pairs, and readers judge no candidate set.
  bool candidate_pairs = true;
  /// Every record carries FrameRecord::jt3 (the tangential impulse vectors): the trace
  /// writes /contacts/jt3.
  bool jt3 = false;
  /// Every record carries FrameRecord::point_b (each row's point on B): the trace writes
  /// /contacts/point_b.
  bool point_b = false;
  // ---- Declarations (docs/validate-your-engine.md, "Declarations"): engine facts the
  // physics tier's rules read; "" = not declared (the root attribute is not written and a
  // reader takes its documented default).
  /// Root attribute `contact_model`: "rigid" or "soft" (contacts as springs, e.g. MuJoCo).
  std::string contact_model;
  /// Root attribute `integrator`: "semi-implicit" (x += dt v'), "explicit" (x += dt v) or
  /// "any".
  std::string integrator;
  /// Root attribute `gyroscopic`: "true" when the engine integrates the gyroscopic term
  /// dt w x I_w w (Bullet's implicit step), "false" when it does not.
  std::string gyroscopic;
  /// Root attribute `deactivation`: "off" when the engine never deactivates (puts to
  /// sleep) a body, so every body is judged awake; "" = undeclared.
  std::string deactivation;
  /// Root attribute `impulse_points`: "witness-pair" when each body takes a row's impulse
  /// at its own witness point and the two may lie apart across the normal (a persistent
  /// manifold's points drift: Bullet keeps a point while the drift is within its breaking
  /// threshold), so a row turns its pair by up to (depth + contact margin) x |J|; "" =
  /// undeclared ("one": one point, or two apart along the normal only).
  std::string impulse_points;
  /// Root attribute `normal_reuse_deg`: the most (degrees) a pair's two bodies turn relative
  /// to each other while the engine still applies a contact normal found on an earlier step:
  /// 0 when every step finds its normals anew (MuJoCo, ODE, DART), Jolt's body-pair cache
  /// angle; < 0 = undeclared (a persistent manifold keeps its normal while its point holds:
  /// Bullet). Read as PhysicsBodies::normal_reuse_deg.
  double normal_reuse_deg = -1.0;
};

/// One simulation engine: `cpu` (World), `cuda` (CudaWorld), `bullet` (BulletWorld).
/// Holders never branch on the name. Not thread-safe.
class Engine {
 public:
  virtual ~Engine() = default;

  /// "cpu", "cuda" or "bullet".
  virtual std::string name() const = 0;
  /// The device it runs on (CPU model or GPU name).
  virtual std::string device() const = 0;
  /// The broadphase in use, as in `--broadphase` (e.g. "octree", "bullet-dbvt").
  virtual std::string broadphase_name() const = 0;
  /// The model the engine was built from (scene, shapes, bodies).
  virtual const Model& model() const = 0;
  /// The midphase in use, as in `--midphase` ("aabb-only", "1,2", ...): the scene's
  /// midphase.levels by default; an engine with its own narrow phase names it instead
  /// (`bullet`: "bullet-box-box"). Traces and summaries record this, never a midphase
  /// the engine did not run.
  virtual std::string midphase_name() const { return model().scene.midphase.to_string(); }

  /// Runs one step (design.md section 4) and returns its metrics. Throws RuntimeError naming the body
  /// and frame when a position or velocity becomes non-finite.
  virtual const FrameMetrics& step() = 0;
  /// A promise: the caller's next `steps` calls are step(), with nothing but step()'s
  /// metrics, last_metrics() and frame() read in between (no state(), contacts(),
  /// record(), set_state() or set_recording()); while recording (set_recording(true)
  /// before the promise) state(), contacts() and record() of the step just taken may be
  /// read too. An engine may then run ahead of the calls (`cuda`'s resident small step runs
  /// up to 64 steps per host round trip, recorded ones up to CudaSettings::record_batch,
  /// their records copied back a batch at once); each step()
  /// still returns its own step's metrics, and the results are the same bits. A call the
  /// promise rules out may throw RuntimeError until the steps run ahead are taken. A later
  /// call replaces the count (0: no more ahead). Engines that cannot run ahead ignore it.
  virtual void plan_steps(std::int64_t steps) { (void)steps; }
  /// Steps run ahead of frame() under plan_steps: the next steps_ahead() calls of step()
  /// return them (they wait for no new work), and until they are taken the calls the
  /// promise rules out may throw. A caller that stops early (an interrupt) calls
  /// plan_steps(0), then step() that many times. 0 for engines that never run ahead.
  virtual std::int64_t steps_ahead() const { return 0; }
  /// Hot state after the last step (host copy; for `cuda`, downloaded on demand).
  virtual const BodyState& state() const = 0;
  /// Metrics of the last step.
  virtual const FrameMetrics& last_metrics() const = 0;
  /// Steps taken so far.
  virtual std::int64_t frame() const = 0;
  /// Contacts resolved in the last step, in (a, b) order (empty for engines without
  /// per-contact records, and for `cuda` unless recording).
  virtual const std::vector<ContactRecord>& contacts() const = 0;

  /// What geometry the engine collides, in words, for summaries, bench results and
  /// traces (design.md section 15): octocd's engines collide the scene's meshes and boxes themselves;
  /// `bullet` says hulls, triangle mesh or boxes (BulletSettings::shape).
  virtual std::string collision_geometry() const {
    return "octocd meshes (octree midphase on the mesh vertices, contacts on the world AABBs), boxes";
  }

  /// What a reader must know to compare this engine's metrics with the `cpu` engine's
  /// (printed under the run summary); "" when they mean exactly what FrameMetrics says.
  virtual std::string notes() const { return ""; }

  /// For an engine whose bodies rotate (`bullet` in rotation mode): its inertia,
  /// materials and contact conventions (a trace is then written as version 2). nullptr
  /// (the default) for engines that translate only.
  virtual const RotationTraits* rotation_traits() const { return nullptr; }

  /// Whether this engine follows octocd's contact conventions (contacts on the world
  /// AABBs, the pair's theta as contact margin, an exact AABB broadphase:
  /// octocd_physics_bodies): trace_metadata then writes octocd_trace_declarations
  /// (trace.hpp) into its traces as root attributes, and readers read those declarations,
  /// never the engine's name. true for octocd's own engines (`cpu`, `cuda`).
  virtual bool octocd_contacts() const { return false; }

  /// Whether the engine's run is a version 2 trace it writes itself (a process engine,
  /// engines/include/octocd/process_engines.hpp): a caller that keeps or judges a trace takes
  /// own_trace() instead of writing one from state() and record(). false for octocd's engines
  /// and the linked reference engines.
  virtual bool writes_own_trace() const { return false; }
  /// The trace the engine wrote itself (writes_own_trace): its path once the first step()
  /// has run, valid while the engine lives (a temporary file it removes); "" before that and
  /// for engines that write none.
  virtual std::string own_trace() const { return ""; }

  /// Whether this engine can fill FrameRecord (false for `bullet` without rotation).
  virtual bool can_record() const { return false; }
  /// Turns the per-step FrameRecord on or off (off by default: it costs copies).
  virtual void set_recording(bool on) { (void)on; }
  /// The last step's record (empty unless recording).
  virtual const FrameRecord& record() const {
    static const FrameRecord kEmpty;
    return kEmpty;
  }
  /// Whether the engine times stage `s`; summaries print "n/a", not 0, for a stage it
  /// lacks. (`bullet` times every stage; its `midphase` is Bullet's narrow phase.)
  virtual bool has_stage(Stage s) const { (void)s; return true; }
  /// Replaces the hot state (positions, velocities, inverse masses; each of size
  /// state().size()) before the next step: `octocd replay` and the broadphase sweeps feed
  /// every engine the same recorded positions this way. Throws InputError when the sizes
  /// differ, or when the engine cannot take a state from outside (the default, e.g.
  /// `bullet`).
  virtual void set_state(const BodyState& state);

  /// The scene.
  const Scene& scene() const { return model().scene; }
  /// Shapes, indexed by BodyInfo::shape.
  const std::vector<Shape>& shapes() const { return model().shapes; }
  /// Cold per-body data.
  const std::vector<BodyInfo>& bodies() const { return model().bodies; }
  /// theta (m) for a pair of shapes (design.md section 6).
  float theta(std::uint32_t shape_a, std::uint32_t shape_b) const {
    return model().theta(shape_a, shape_b);
  }
  /// FNV-1a 64-bit hash of the bits of every x then every v of state(): bit-identical
  /// states hash equal (determinism and CPU/GPU equality checks).
  std::uint64_t state_hash() const;
};

/// FNV-1a 64-bit hash of the bits of every x then every v.
std::uint64_t state_hash(const BodyState& state);

}  // namespace octocd
