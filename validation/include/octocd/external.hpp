#pragma once
/// \file external.hpp
/// Validate your own engine (issue 11): octocd's validators (SPEC 7) judge the frames that
/// another engine computed, given through this C++ API or in an external trace
/// (docs/trace-format.md, "External traces"; `octocd validate --trace-in FILE.h5`).
///
/// The same FrameValidators that judge octocd's engines judge these frames: each frame is
/// a FrameRecord (octocd/engine.hpp) that another program filled. What is judged:
/// - candidate sets: the engine's pairs against `flat` (the oracle), with Bullet's and
///   FCL's broadphases run on the same AABBs beside it (missing and extra pairs);
/// - contact normals: sign agreement and angles against FCL/libccd (boxes, or meshes);
/// - non-penetration (Eq. 14 contraction with the scene's alpha, beta, delta), friction
///   (|v_t| never rises, |J_t| <= mu_s J_n) and conservation (momentum, mass-weighted
///   centre) on the given before/after states;
/// - optionally the applied state against the SPEC 6 re-derivation (an engine that
///   implements octocd's response).
/// Midphase completeness, the analytic scenes and the Bullet dynamics comparison need
/// octocd's own pipeline or an engine to step; they are reported n/a with the reason.
///
/// Conventions a caller must follow (SPEC 2). Units: m, s, kg; float32 state.
/// - Pairs are body indices (a, b) with a < b < bodies, sorted by (a, b), unique.
/// - One contact per pair (an engine with contact manifolds gives one representative
///   point with the pair's summed impulses), in (a, b) order; the normal is unit and
///   points from B to A (+n applied to A separates the pair); depth >= 0 (m); J_n >= 0
///   and J_t (kg m/s) are impulses along n and along the tangent of the relative velocity.
/// - AABB overlap is inclusive (Eq. 6): boxes that only touch are a pair.
/// - A body's world AABB is its local box translated by its position.
/// - States follow SPEC 4's order: x_pre, v_pre before the step; the world AABBs after
///   integration (semi-implicit Euler, SPEC 4.1); x_post, v_post after the response.
/// A violation that can be seen in the data (a >= b, an index out of range, unsorted or
/// duplicated pairs, a non-unit or non-finite normal, a negative depth, wrong array
/// sizes, a non-finite value) is an InputError naming the field, the frame and the
/// problem, never a verdict. A normal pointing from A to B or a strict overlap test gives
/// a FAIL whose detail names the convention.

#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "octocd/engine.hpp"
#include "octocd/mesh.hpp"
#include "octocd/physics.hpp"
#include "octocd/validation.hpp"

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
  /// Without a scene: time step (s, > 0) and gravity (m/s^2) used to integrate x_pre,
  /// v_pre when a frame gives states but no AABBs, and for the derived velocity changes.
  float dt = 0.001f;
  Vec3 gravity{0.0f, -9.81f, 0.0f};
  /// Domain box for octocd's octree and hash broadphases (m). Empty: the scene's domain,
  /// else the bounding box of the first frame's AABBs. Bodies outside are never lost.
  std::optional<Aabb> domain;
  /// What the physics tier needs beyond the bodies (SPEC 13, external traces v2):
  /// inertia, materials, the contact margin, and what the engine declares of itself
  /// (exact AABB broadphase, the geometry its contacts are computed on).
  PhysicsBodies physics;
};

/// How an ExternalValidator judges.
struct ExternalOptions {
  /// Names the engine in verdicts ("engine 'NAME' misses pair ...") and errors.
  std::string engine = "external";
  /// Compare Bullet's and FCL's broadphases with `flat` beside the engine's pairs, and
  /// judge normals against FCL/libccd.
  bool against_fcl = true;
  /// Also judge the applied state against the SPEC 6 re-derivation (SPEC 7.9,
  /// validation/model/applied_state.hpp): for an engine that implements octocd's response.
  bool spec6_response = false;
  /// Bounds (validation.hpp); names in `overridden` are marked in format_results.
  Tolerances tol;
  std::vector<std::string> overridden;
};

/// Names of a FrameRecord's fields in error messages (the C++ field names by default;
/// external traces give their dataset paths).
struct RecordFieldNames {
  std::string aabbs = "aabbs", pairs = "pairs", contact_pair = "contacts.pair",
              contact_normal = "contacts.normal", contact_depth = "contacts.depth",
              contact_jn = "contacts.jn", contact_jt = "contacts.jt", x_pre = "x_pre", v_pre = "v_pre",
              x_post = "x_post", v_post = "v_post";
};

/// Checks one record from outside octocd against the conventions above: `aabbs` (empty
/// allowed when the states are given) and the states (all four empty, or one per body)
/// sized `bodies`, finite, min <= max; `pairs` (when rec.has_pairs) and contact pairs with
/// a < b < bodies, sorted, unique; normals finite and unit (|n| within 1e-3 of 1); depth
/// finite >= 0; J_n finite >= 0; J_t finite. Throws InputError
/// "ORIGIN: FIELD: frame F: PROBLEM; allowed: RANGE".
void check_frame_record(const FrameRecord& rec, std::size_t bodies, const std::string& origin,
                        const RecordFieldNames& names = {});

/// Feeds another engine's frames to octocd's validators, one step at a time.
class ExternalValidator {
 public:
  /// Builds the bodies (FCL geometry of every distinct shape when options.against_fcl).
  /// Throws InputError naming the field when `bodies` is inconsistent (sizes, a scene
  /// that does not parse or whose bodies differ, a non-finite box, negative mass).
  ExternalValidator(const ExternalBodies& bodies, const ExternalOptions& options);
  ~ExternalValidator();
  ExternalValidator(const ExternalValidator&) = delete;
  ExternalValidator& operator=(const ExternalValidator&) = delete;

  /// Number of bodies.
  std::size_t body_count() const;
  /// The model the validators read (scene parameters, shapes, inverse masses).
  const Model& model() const;

  /// Judges one step. Fill `rec.frame` (named in verdicts), `aabbs` (the world AABBs the
  /// engine's collision detection used; leave empty to derive them from x_pre, v_pre by
  /// SPEC 4.1), `pairs` (or set has_pairs = false), `contacts` (pair, normal, depth, jn,
  /// jt; the other ContactRecord fields are ignored) and optionally the four states.
  /// `confirmed` is ignored (set to the contacts' pairs). `checked` runs the costly
  /// validators (candidate sets, normals) on this frame. Throws InputError
  /// (check_frame_record, origin = options.engine) before judging anything of the frame.
  void observe(FrameRecord rec, bool checked = true);

  /// Every row of the `octocd validate` table so far: validators 1-6 and 9, then
  /// `analytic` and `bullet-dynamics` (n/a: they step an engine).
  std::vector<ValidationResult> results() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

/// One frame in one call: ExternalValidator(bodies, options), observe(rec), results().
std::vector<ValidationResult> validate_frame(const ExternalBodies& bodies, const FrameRecord& rec,
                                             const ExternalOptions& options = {});

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
};

/// Checks an external trace (docs/trace-format.md, "External traces"): root attributes,
/// every required dataset, shapes and body counts, then every frame's values
/// (check_frame_record). Throws InputError "PATH: DATASET: [frame F: ]PROBLEM; allowed:
/// ..." on the first problem; RuntimeError when the file cannot be opened as HDF5.
ExternalTraceInfo check_external_trace(const std::string& path);

/// Checks the trace (check_external_trace), then judges it frame by frame with an
/// ExternalValidator: the costly validators on every `every`-th frame (>= 1), at most
/// `max_frames` frames (0 = all). options.engine and spec6_response come from the trace.
/// `info`, when not null, receives what the trace holds.
std::vector<ValidationResult> validate_external_trace(const std::string& path, ExternalOptions options,
                                                      int every = 1, std::int64_t max_frames = 0,
                                                      ExternalTraceInfo* info = nullptr);

}  // namespace octocd
