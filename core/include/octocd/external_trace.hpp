#pragma once
/// \file external_trace.hpp
/// The hardened reader of external traces (docs/trace-format.md, "External traces",
/// versions 1 and 2) and the checks of a FrameRecord that another engine filled: what a
/// process engine reads back from its program and what `octocd validate --trace-in` judges
/// (octocd/external.hpp). Every value is checked before anything is computed from it;
/// every error is an InputError naming the file or origin, the field, the frame and the
/// allowed range. It reads through core's one HDF5 reader (docs/trace-format.md,
/// "Security rules and limits").
///
/// Conventions a caller must follow (design.md section 2). Units: m, s, kg; float32 state.
/// - Pairs are body indices (a, b) with a < b < bodies, sorted by (a, b), unique.
/// - One contact per pair in (a, b) order, or with manifolds = true several consecutive
///   rows per pair; the normal is unit and points from B to A (+n applied to A separates
///   the pair); depth >= 0 (m); J_n >= 0 (kg m/s) along n; J_t (kg m/s) the friction
///   impulse along -v_t / |v_t|, v_t the tangential velocity of A relative to B at the
///   contact point before the solver (so J_t >= 0 when friction opposes sliding).
/// - AABB overlap is inclusive (Eq. 6): boxes that only touch are a pair.
/// - A body's world AABB is its local box translated by its position (with rotation: the
///   bounds of its posed shape at the detection pose).
/// - States follow design.md section 4's order: x_pre, v_pre before the step; the world AABBs after
///   integration (semi-implicit Euler, design.md section 4.1) unless x_det gives the detection pose;
///   x_post, v_post after the response.
/// Rotating engines (design.md section 13; external traces version 2) fill q_pre/q_post, w_pre/w_post
/// (empty: identity, zero), the detection pose x_det/q_det (the pose their collision
/// detection ran at; Bullet, PhysX: the pre-step pose), and may give manifolds (several
/// consecutive rows per pair, manifolds = true) with world contact points
/// (has_points = true). A body's position is then the origin of its body frame (its
/// centre of mass), and its local box is the shape's box in that frame.
/// A violation that can be seen in the data (a >= b, an index out of range, unsorted or
/// duplicated pairs, a non-unit or non-finite normal, a negative depth, wrong array
/// sizes, a non-finite value) is an InputError naming the field, the frame and the
/// problem, never a verdict. A normal pointing from A to B or a strict overlap test gives
/// a FAIL whose detail names the convention.

#include <array>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "octocd/engine.hpp"
#include "octocd/mesh.hpp"
#include "octocd/physics_bodies.hpp"

namespace octocd {

/// The bodies of another engine, constant over a run.
struct ExternalBodies {
  /// Local AABB per body (m, one per body): the world AABB is this box translated by the
  /// body's position. May be empty when `scene_json` gives the bodies.
  std::vector<Aabb> local_boxes;
  /// Inverse mass per body (1/kg, one per body, >= 0; 0 = static). Empty: taken from
  /// `scene_json`, else every body has 1 kg.
  std::vector<float> inverse_mass;
  /// Optional triangle mesh per body (empty, or one per body; nullptr = the body is its
  /// box), in the frame of its local box (vertices inside it). Bodies sharing a mesh
  /// should share the pointer (FCL geometry is built once per distinct shape). Used by the
  /// FCL reference normals.
  std::vector<std::shared_ptr<const Mesh>> meshes;
  /// Optional scene (JSON text, docs/scenes.md). Its parameters (dt, gravity, response:
  /// alpha, beta, delta, mu_s, ...) are the ones judged against; its bodies (walls first,
  /// then each group's bodies in order) with their meshes become the bodies, and
  /// `local_boxes` / `inverse_mass`, when also given, must match them.
  std::string scene_json;
  /// The file `scene_json` was read from (a trace's root attribute `scene`): an untrusted
  /// scene, parsed with parse_embedded_scene so that its meshes are looked up only inside
  /// ExternalOptions::mesh_dir (default: this file's folder) and the data dir. Empty when
  /// the caller gives the scene itself (its meshes resolve as parse_scene's).
  std::string scene_file;
  /// Without a scene: time step (s, > 0) and gravity (m/s^2) used to integrate x_pre,
  /// v_pre when a frame gives states but no AABBs, and for the derived velocity changes.
  float dt = 0.001f;
  Vec3 gravity{0.0f, -9.81f, 0.0f};
  /// Domain box for octocd's octree and hash broadphases (m). Empty: the scene's domain,
  /// else the bounding box of the first frame's AABBs. Bodies outside are never lost.
  std::optional<Aabb> domain;
  /// What the physics tier needs beyond the bodies (design.md section 13, external traces v2):
  /// inertia, materials, the contact margin, and what the engine declares of itself
  /// (exact AABB broadphase, the geometry its contacts are computed on).
  PhysicsBodies physics;
};

/// Names of a FrameRecord's fields in error messages (the C++ field names by default;
/// external traces give their dataset paths).
struct RecordFieldNames {
  std::string aabbs = "aabbs", pairs = "pairs", contact_pair = "contacts.pair",
              contact_normal = "contacts.normal", contact_depth = "contacts.depth",
              contact_jn = "contacts.jn", contact_jt = "contacts.jt", x_pre = "x_pre", v_pre = "v_pre",
              x_post = "x_post", v_post = "v_post";
  // Rotating engines (design.md section 13).
  std::string q_pre = "q_pre", q_post = "q_post", w_pre = "w_pre", w_post = "w_post", x_det = "x_det",
              q_det = "q_det", contact_point = "contacts.point";
  /// The tangential impulse vectors (design.md section 13b.11; traces: /contacts/jt3).
  std::string contact_jt3 = "contacts.jt3";
  /// Each row's point on B (FrameRecord::point_b; traces: /contacts/point_b).
  std::string contact_point_b = "contacts.point_b";
};

/// Largest angle (degrees) between a contact row's tangential impulse vector
/// (FrameRecord::jt3) and its contact plane (the plane orthogonal to its normal). float32
/// rounding of a vector built from unit friction directions orthogonal to the normal
/// leaves ~1e-5 deg; an engine that keeps a manifold point's friction directions from when
/// it was found (persistent friction anchors) while its normal turns by a fraction of a
/// degree per step stays well within 1 deg; a row whose jt3 carries the normal impulse
/// (the total impulse written by mistake) lies tens of degrees out. Rows with |jt3| <=
/// 1e-9 kg m/s have no direction and are not checked.
inline constexpr double kJt3MaxAngleDeg = 1.0;

/// Checks one record from outside octocd against the conventions above: `aabbs` (empty
/// allowed when the states are given) and the states (all four empty, or one per body)
/// sized `bodies`, finite, min <= max; `pairs` (when rec.has_pairs) with a < b < bodies,
/// sorted, unique; contact pairs likewise, except that with rec.manifolds a pair may have
/// several rows, which must be consecutive (sorted by (a, b) non-decreasingly); normals
/// finite and unit (|n| within 1e-3 of 1); depth finite >= 0; J_n finite >= 0; J_t finite;
/// with rec.has_points every contact point finite (m); rec.jt3 empty or one finite vector
/// per contact within kJt3MaxAngleDeg of its contact plane; rec.point_b empty or, with
/// rec.has_points, one finite point (m) per contact.
/// Rotation (design.md section 13): q_pre, q_post, w_pre, w_post all empty (no rotation) or all one per
/// body, and then the states too; quaternions finite with | |q| - 1 | <= 1e-3; angular
/// velocities finite (rad/s). Detection pose: x_det empty or one finite position per
/// body; q_det empty or one unit quaternion per body, only with x_det. Throws InputError
/// "ORIGIN: FIELD: frame F: PROBLEM; allowed: RANGE".
void check_frame_record(const FrameRecord& rec, std::size_t bodies, const std::string& origin,
                        const RecordFieldNames& names = {});

/// Names of PhysicsBodies' fields in error messages (the C++ names by default; external
/// traces give their datasets and root attributes).
struct PhysicsFieldNames {
  std::string inertia = "physics.inertia", body_friction = "physics.body_friction",
              body_restitution = "physics.body_restitution", mu = "physics.mu",
              restitution = "physics.restitution", contact_margin = "physics.contact_margin",
              slop = "physics.slop", locked_dofs = "physics.locked_dofs";
};

/// Checks what the physics tier is told of the bodies (design.md section 13) for `inverse_mass.size()`
/// bodies: `inertia` empty or one per body, finite, symmetric (|I_rc - I_cr| <= 1e-4
/// max |I|) and positive definite (Sylvester: leading minors > 0) for every dynamic body
/// (static bodies: anything finite, zeros allowed); `body_friction` empty or one finite
/// value >= 0 per body; `body_restitution` empty or one per body in [0, 1]; `mu` finite
/// >= 0; `restitution` in [0, 1]; `contact_margin` finite >= 0; `slop` finite > 0;
/// `locked_dofs` empty or one value in 0 .. 63 per body (design.md section 13b.12).
/// Throws InputError "ORIGIN: FIELD: [body I: ]PROBLEM; allowed: RANGE".
void check_physics_bodies(const PhysicsBodies& physics, const std::vector<float>& inverse_mass,
                          const std::string& origin, const PhysicsFieldNames& names = {});

/// The inertia tensor (kg m^2, body frame, row-major 3x3) of a solid box `local` of mass
/// 1 / inverse_mass: m/12 diag(b^2 + c^2, a^2 + c^2, a^2 + b^2) for side lengths a, b, c
/// (Bullet's rule for convex shapes: btBoxShape::calculateLocalInertia of the bounding
/// box). Zeros for a static body (inverse_mass 0).
std::array<double, 9> box_inertia(const Aabb& local, float inverse_mass);

/// What an external trace holds (check_external_trace).
struct ExternalTraceInfo {
  std::string engine = "external";  ///< root attribute `engine`, or "external"
  std::size_t bodies = 0;           ///< n
  std::int64_t frames = 0;          ///< steps F (frames 1..F)
  bool has_scene = false;           ///< root attribute `scene` (JSON)
  bool has_states = false;          ///< /states/position and /states/velocity
  bool has_aabbs = false;           ///< /aabbs/min and /aabbs/max
  bool has_pairs = false;           ///< /pairs
  bool has_contacts = false;        ///< /contacts
  bool spec6_response = false;      ///< root attribute `response_model` == "spec6"
  int version = 1;                  ///< root attribute `version` (1 or 2)
  bool has_rotation = false;        ///< v2: /states/orientation (and angular_velocity)
  bool has_points = false;          ///< v2: /contacts/point
  bool manifolds = false;           ///< v2: some pair has several contact rows in a frame
  bool has_jt3 = false;             ///< v2: /contacts/jt3 (friction impulse vectors)
  bool has_point_b = false;         ///< v2: /contacts/point_b (each row's point on B)
  bool has_sleeping = false;        ///< v2: /states/sleeping (the bodies the engine deactivated)
  /// A version 1 trace of octocd's TraceWriter (/frames and the root attribute
  /// `parameters`) that declares none of the declarations (written before they existed):
  /// read as declaring octocd's conventions (octocd_physics_bodies), as it was judged then.
  bool octocd_conventions = false;
  /// /states/frame skips frames (`octocd run --state-every K`, K > 1), read by
  /// validate_external_trace as TraceStates::Recorded: rows needing each step's states
  /// before and after it are n/a (naming `--state-every 1`), the geometric rows and the
  /// friction cone are judged on the steps whose pre-step state is recorded.
  bool sparse_states = false;
  /// Filled by validate_external_trace: the last frame whose checks completed (0: none;
  /// the run's or shard's last frame when not stopped), and with
  /// ExternalOptions::keep_on_stop the frame a stop cut short inside its checks (partly in
  /// the verdict; 0: it stopped between frames).
  std::int64_t judged_to = 0, stopped_in = 0;
  /// Filled by validate_external_trace: true when `stop` ended the judging early.
  bool stopped = false;
};

/// Checks an external trace (docs/trace-format.md, "External traces", versions 1 and 2):
/// root attributes, every required dataset, shapes and body counts, the bodies' physics
/// (check_physics_bodies), then every frame's values (check_frame_record). Version 2
/// datasets in a version 1 file are an error ("v1/v2 fields mixed"). Throws InputError
/// "PATH: DATASET: [frame F: ]PROBLEM; allowed: ..." on the first problem; RuntimeError
/// when the file cannot be opened as HDF5.
ExternalTraceInfo check_external_trace(const std::string& path);

/// Which states a trace must carry to be read (ExternalTrace).
enum class TraceStates {
  EveryFrame,  ///< /states/frame = 0, 1, ..., F: what the validators need
  Sparse,      ///< frame 0, then any strictly increasing frames (`octocd run --state-every K`):
               ///< a frame without a state reads the nearest recorded one (what `view` draws)
  /// The same frames, judged on what they carry (validate --trace-in): with sparse states,
  /// step f's record carries no states, only its detection pose from the recorded state
  /// f - 1 (design.md section 4.1's integrated pose for version 1 and "integrated"
  /// detection); a step whose pre-step state is not recorded has no pose (posed(f) false:
  /// the validator skips it).
  Recorded,
};

/// An external trace opened for reading, frame by frame (what `octocd validate
/// --trace-in` reads). Version 1: positions, velocities, world AABBs, pairs, one contact
/// per pair. Version 2 (design.md section 13) also: orientations and angular velocities (q_pre/q_post,
/// w_pre/w_post), the detection pose (x_det/q_det = row f-1 of /states for detection
/// "pre-step"; for "integrated", x_det = design.md section 4.1's integrated position from row f-1 and
/// q_det = row f-1's orientation), manifold contacts (manifolds = true) with their
/// points, and ExternalBodies::physics (inertia given or derived with box_inertia,
/// materials, contact margin, broadphase_exact, contact geometry, the scene's slop or
/// 0.001). Positions are never inferred from /aabbs in version 2.
class ExternalTrace {
 public:
  /// Opens `path` and checks everything but the per-frame values (as
  /// check_external_trace). Throws InputError / RuntimeError as check_external_trace.
  /// With TraceStates::Sparse a trace whose /states/frame skips frames is read: F is its
  /// last state frame and frame(f)'s pre- and post-step states (x, v, q, w, and the
  /// detection pose) are all the recorded state nearest to f (ties: the earlier one).
  explicit ExternalTrace(const std::string& path, TraceStates states = TraceStates::EveryFrame);
  ~ExternalTrace();
  ExternalTrace(const ExternalTrace&) = delete;
  ExternalTrace& operator=(const ExternalTrace&) = delete;

  /// What the trace holds (`manifolds` only once a frame with a manifold was read).
  const ExternalTraceInfo& info() const;
  /// The bodies: local boxes, inverse masses, scene, dt, gravity, physics.
  const ExternalBodies& bodies() const;
  /// Step f in [1, info().frames] as a FrameRecord, checked (check_frame_record). Throws
  /// InputError "PATH: DATASET: frame F: PROBLEM; allowed: ..." on a bad value, and for
  /// f out of range.
  FrameRecord frame(std::int64_t f);
  /// The frame whose recorded state frame(f) carries: f, unless sparse_states().
  std::int64_t state_frame(std::int64_t f) const;
  /// The first frame with a row in /contacts (0: none); for a trace without /contacts,
  /// the first frame octocd's per-frame counts (/frames/frame, /frames/contacts) give
  /// contacts in, when it has them.
  std::int64_t first_contact_frame() const;
  /// True when the trace was read with TraceStates::Sparse and /states/frame skips frames.
  bool sparse_states() const;
  /// With sparse_states(): the frames that have a recorded state (0 first, increasing);
  /// otherwise empty.
  const std::vector<std::int64_t>& state_frames() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace octocd
