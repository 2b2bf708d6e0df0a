#pragma once
/// \file external.hpp
/// Validate your own engine (issue 11): octocd's validators (design.md section 7) judge the frames that
/// another engine computed, given through this C++ API or in an external trace
/// (docs/trace-format.md, "External traces"; `octocd validate --trace-in FILE.h5`).
///
/// The same FrameValidators that judge octocd's engines judge these frames: each frame is
/// a FrameRecord (octocd/engine.hpp) that another program filled. What is judged (design.md section 13,
/// docs/validation.md, "Which rows judge what"): the physics tier (octocd/physics.hpp: broadphase and
/// contact completeness, contact geometry against FCL on the posed shapes, penetration,
/// friction, conservation) for any engine, with ExternalBodies::physics; the model tier
/// (the paper's response: Eq. 14, friction monotonicity, impulse conservation, the
/// applied state) only for an engine that claims design.md section 6 (ExternalOptions::spec6_response),
/// n/a with the reason otherwise. Midphase completeness, the analytic scenes and the
/// Bullet dynamics comparison need octocd's own pipeline or an engine to step: n/a.
///
/// The conventions a caller follows, the checks of a record and the external-trace reader
/// are octocd/external_trace.hpp (core); this header holds the judging of such frames.

#include <array>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "octocd/engine.hpp"
#include "octocd/external_trace.hpp"
#include "octocd/physics.hpp"
#include "octocd/shard_spec.hpp"
#include "octocd/validation.hpp"

namespace octocd {

/// How an ExternalValidator judges.
struct ExternalOptions {
  /// Names the engine in verdicts ("engine 'NAME' misses pair ...") and errors.
  std::string engine = "external";
  /// `--mesh-dir`: the only folder (besides the data dir) where the meshes named by a
  /// trace's scene (ExternalBodies::scene_file) are looked up; "" = the trace's folder.
  std::string mesh_dir;
  /// Compare Bullet's and FCL's broadphases with `flat` beside the engine's pairs, and
  /// judge normals against FCL/libccd.
  bool against_fcl = true;
  /// Also judge the applied state against the design.md section 6 re-derivation (design.md section 7.9,
  /// validation/model/applied_state.hpp): for an engine that implements octocd's response.
  bool spec6_response = false;
  /// The frames follow octocd's own conventions without declaring them (a version 1 trace
  /// of octocd's TraceWriter written before the declarations: ExternalTraceInfo::
  /// octocd_conventions): the physics tier takes octocd_physics_bodies (contacts on the
  /// world AABBs, the pair's theta as contact margin, an exact AABB broadphase, J_t along
  /// the sliding) instead of ExternalBodies::physics. Never set from an engine's name.
  bool octocd_engine = false;
  /// Bounds (validation.hpp); names in `overridden` are marked in format_results.
  Tolerances tol;
  std::vector<std::string> overridden;
  /// validate_external_trace judges only this shard's frames (octocd/shards.hpp:
  /// shard_frames of the frames the whole run judges); default: every frame.
  ShardSpec shard;
  /// Threads per frame (ValidationOptions::threads; 0: the hardware's).
  int threads = 0;
  /// The judge device of rows 1 and 4 (ValidationOptions::judge_device; empty: the CPU).
  std::function<std::unique_ptr<DeviceJudge>()> judge_device;
  /// Polled inside the long loops of a frame's checks (as ValidationOptions::stop) and by
  /// validate_external_trace between frames; when it returns true they throw
  /// ValidationStopped (the frame in progress is then partly judged). May be empty (never
  /// stops). The Python module polls Ctrl-C with it.
  std::function<bool()> stop;
  /// With `stop`: once the judging of frames has begun, validate_external_trace returns the
  /// verdict of the frames judged so far instead of throwing (ExternalTraceInfo::judged_to
  /// and stopped_in say how far it got); a stop while the trace is checked still throws
  /// ValidationStopped. `octocd validate --trace-in` sets it (an incomplete verdict on a signal).
  bool keep_on_stop = false;
  /// Called by validate_external_trace on its thread when the judging begins (judged_to
  /// 0) and after a frame whose checks are complete, at most every 20 ms (and after the
  /// first), with the verdict a stop right then
  /// would return and what the trace holds (ExternalTraceInfo::judged_to the last frame
  /// judged whole). May be empty. `octocd validate --trace-in` keeps the latest as the
  /// incomplete verdict it reports when a check outlasts its stop grace.
  std::function<void(const std::vector<ValidationResult>& results, const ExternalTraceInfo& info)> on_judged;
};

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
  /// engine's collision detection used; leave empty to derive them: the exact bounds of
  /// each shape at x_det/q_det when given, else from x_pre, v_pre by design.md section 4.1), `pairs` (or
  /// set has_pairs = false), `contacts` (pair, normal, depth, jn, jt, and `point` with
  /// has_points; the other ContactRecord fields are ignored) and optionally the four
  /// states, with rotation q_pre/q_post/w_pre/w_post and the detection pose.
  /// `confirmed` is ignored (set to the contacts' pairs). `checked` runs the costly
  /// validators (candidate sets, normals) on this frame. Throws InputError
  /// (check_frame_record, origin = options.engine) before judging anything of the frame.
  void observe(FrameRecord rec, bool checked = true);

  /// Shards: the soft-contact episodes judged are those begun in frames [first, last]
  /// (PhysicsValidators::set_episode_frames; default: all).
  void set_episode_frames(std::int64_t first, std::int64_t last);
  /// A frame outside the judged ones, checked as observe checks it: only the soft-contact
  /// episodes advance (PhysicsValidators::observe_episodes).
  void observe_episodes(FrameRecord rec);
  /// An episode begun in the episode frames is still open (PhysicsValidators::episodes_pending).
  bool episodes_pending() const;
  /// The energy of these bodies is judged per contact episode (PhysicsBodies::contact_model
  /// soft declared): a shard needs the frames around its own (set_episode_frames).
  bool judges_episodes() const;

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

/// What one row of `validate --trace-in` needs of a trace, from what the trace holds and
/// declares (docs/validate-your-engine.md, "What a trace must carry"): the check-only
/// listing, and the n/a a row gets when the trace lacks what it needs.
struct TraceRowPlan {
  Tier tier = Tier::Physics;
  std::string name;     ///< a row of validation_rows() (octocd/validation_rows.hpp), in its order
  bool judged = true;   ///< the trace carries what the row needs (it may still find nothing to judge)
  /// Not judged: what to add (datasets or root attributes), or "nothing ..." with the
  /// reason when no trace can give it (rows that step an engine).
  std::string add;
  /// Judged, but a part of the row needs more: what to add for it ("" when nothing).
  std::string partial;
};

/// The plan of every row (validation_rows()) for a trace holding `info` with the
/// bodies and declarations `bodies` (ExternalTrace::bodies()). Reads nothing.
std::vector<TraceRowPlan> plan_trace_rows(const ExternalTraceInfo& info, const ExternalBodies& bodies);

/// Rows of `results` that `plan` says the trace cannot judge become n/a, their detail
/// naming what to add ("n/a: the trace lacks what this row needs; to judge it, add
/// /contacts ..."): a trace is never failed for an omission. Rows nothing can be added to
/// keep their reason, with the plan's appended.
void apply_trace_plan(std::vector<ValidationResult>& results, const std::vector<TraceRowPlan>& plan);

/// Checks the trace (check_external_trace), then judges it frame by frame with an
/// ExternalValidator: the costly validators on every `every`-th frame (>= 1), at most
/// `max_frames` frames (0 = all). options.engine and spec6_response come from the trace.
/// Rows the trace cannot judge are n/a naming what to add (apply_trace_plan).
/// `info`, when not null, receives what the trace holds.
std::vector<ValidationResult> validate_external_trace(const std::string& path, ExternalOptions options,
                                                      int every = 1, std::int64_t max_frames = 0,
                                                      ExternalTraceInfo* info = nullptr);

}  // namespace octocd
