#pragma once
/// \file validation.hpp
/// The validators of design.md section 7 and `octocd validate`.
///
/// Each validator returns a named result: the measured figure, the bound it is held to,
/// pass/fail and a detail line (the first offending frame/pair when it fails). Every
/// tolerance is defined once, in `Tolerances`, with the reason for its value.

#include <array>
#include <cstddef>
#include <cstdint>
#include <exception>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "octocd/broadphase.hpp"
#include "octocd/midphase.hpp"
#include "octocd/scene.hpp"
#include "octocd/engine.hpp"
#include "octocd/world.hpp"

namespace octocd {

class PhysicsValidators;
class DeviceJudge;  // octocd/device_judge.hpp (validation/device/)

struct PhysicsBodies;  // octocd/physics.hpp

/// Which judge a row belongs to (design.md section 13, ARCHITECTURE.md seam 3).
enum class Tier {
  /// Physics: any engine (rotation, any solver, any broadphase), judged on the posed
  /// shapes with FCL (validation/physics/).
  Physics,
  /// Model: the paper's design.md section 6 response (Eq. 14, averaged corrections, the applied-state
  /// re-derivation, midphase completeness, analytic scenes, Bullet dynamics); n/a with
  /// the reason for an engine that does not claim design.md section 6 (validation/model/).
  Model,
};
/// "physics" or "model" (the table's tier column, JUnit, the trace's /validation/tier): the
/// one spelling of the tiers' names.
const char* tier_name(Tier tier);
/// The tier whose tier_name is `name`; empty for a name no tier has.
std::optional<Tier> find_tier(const std::string& name);
/// Every tier's name, in Tier order (what a reader of `validate --json` allows).
const std::vector<std::string>& tier_names();

/// One judged item of a row: where, and its figure (design.md section 13b.13).
struct ValidationExample {
  std::int64_t frame = -1;  ///< the frame (step number) it was judged on; -1: not a frame's item
  /// What was judged, in the form expectations name it: "pair (A, B)", "body I",
  /// "group (I, ...)" (an isolated group by its first bodies), "" for the whole run.
  std::string item;
  double figure = 0;        ///< the item's measured figure, in its cause's unit
  std::string text;         ///< one line: what was measured against what, with the bound
};

/// One cause of a row's failures (design.md section 13b.13): e.g. row `contact-completeness` has the
/// causes `missing-contact` and `false-contact`. A second fault never hides behind the
/// first: every cause is counted, and each keeps its first examples.
struct ValidationCause {
  std::string name;         ///< kebab-case, unique within its row (e.g. "normal-angle")
  std::string unit;         ///< unit of the figures (e.g. "deg", "m", "kg m/s", "rel")
  std::uint64_t count = 0;  ///< items that failed for this cause
  double worst = 0;         ///< the largest figure among them (0 when count is 0)
  /// The first failing items in the order judged, at most kMaxExamples.
  std::vector<ValidationExample> examples;
  /// Every distinct failing item (ValidationExample::item) up to kMaxItems, sorted;
  /// `items_complete` false when more failed (expectations listing items then fail).
  std::vector<std::string> items;
  bool items_complete = true;
  static constexpr std::size_t kMaxExamples = 5;
  static constexpr std::size_t kMaxItems = 1000;
};

/// One validator's verdict.
struct ValidationResult {
  Tier tier = Tier::Model;  ///< which judge this row belongs to
  std::string name;      ///< e.g. "candidate-sets"
  std::string figure;    ///< what `measured` is, with its unit
  double measured = 0;   ///< the measured figure
  double bound = 0;      ///< the bound it is compared with
  bool pass = true;      ///< measured within bound
  bool applicable = true;  ///< false: this scene has nothing to check (counts as a pass)
  std::string detail;    ///< first offending frame/pair, or a short note
  /// Names of the Tolerances fields this verdict depends on (comma-separated, "" none);
  /// format_results marks the row when one of them was overridden.
  std::string tolerances;
  /// Time spent in this validator's own work (s, std::chrono::steady_clock), summed over
  /// the frames it judged (for analytic and bullet-dynamics: their whole rerun). Work
  /// that several rows share (the physics tier's FCL truth per candidate pair) is charged
  /// to the first row that needs it. JUnit's per-testcase time.
  double seconds = 0;
  /// Items this row judged (contacts, pairs, groups, bodies, frames: the row says which
  /// in its detail). A row that judged nothing is n/a (`applicable` false), never a pass.
  std::uint64_t judged = 0;
  /// Its failures by cause (empty when it passed). A validator that does not split its
  /// failures gives one cause named like the row, with count = the failing items.
  std::vector<ValidationCause> causes;
};

/// Thrown from inside a check when ValidationOptions::stop returns true (the long loops
/// poll it every few dozen pairs, contacts or steps, so a stop is honoured within a
/// fraction of a second even on a frame whose checks take minutes). validate_engine
/// catches it and returns the results so far; FrameValidators::observe lets it through
/// (the frame it stopped in is then partly judged).
struct ValidationStopped : std::exception {
  const char* what() const noexcept override { return "validation stopped"; }
};

/// Every tolerance of the validators, with the reason for its value: one member per entry of
/// octocd/tolerances.def (its name, default, unit and reason), in that order.
struct Tolerances {
#define OCTOCD_TOLERANCE(name, value, unit, doc) double name = value;
#include "octocd/tolerances.def"
#undef OCTOCD_TOLERANCE
};

/// What `octocd validate` runs.
struct ValidationOptions {
  int frames = 300;   ///< steps to run (>= 1)
  int every = 10;     ///< check candidate sets, midphase and normals every k-th frame (>= 1)
  bool against_bullet = true;  ///< run the Bullet dynamics comparison (scenes it applies to)
  bool against_fcl = true;     ///< include Bullet/FCL broadphases; FCL reference normals
  Tolerances tol;
  /// Names of tolerances the user overrode (marked in the table).
  std::vector<std::string> overridden;
  /// Called after every step of the validated engine (e.g. to write a trace); may be empty.
  std::function<void(const Engine&)> on_step;
  /// Polled before every step of the validated engine; when it returns true validation
  /// stops there: the results cover the frames run so far, and the validators that rerun
  /// the scene (analytic, bullet-dynamics) are `n/a` ("not run: stopped after frame N").
  /// May be empty (never stops). `octocd validate` stops on SIGINT/SIGTERM (stop.hpp).
  /// Also polled inside the long loops of a frame's checks (FrameValidators, the physics
  /// tier, the analytic and Bullet reruns), which then throw ValidationStopped.
  std::function<bool()> stop;
  /// Called by validate_engine after every frame whose checks are complete, with the
  /// results a stop right then would return (the per-frame rows over frames 1..`judged`;
  /// analytic and bullet-dynamics `n/a`, "not run: stopped after frame N of M"), on the
  /// thread that runs validate_engine. May be empty. `octocd validate` keeps the latest as
  /// the incomplete verdict it reports when a step outlasts its stop bound.
  std::function<void(const std::vector<ValidationResult>& results, std::int64_t judged)> on_judged;
  /// Threads that judge one frame's heavy loops (the physics tier's reference geometry
  /// per candidate pair, the reference pair set), on the worker team (octocd/parallel.hpp):
  /// 0 = current_threads() (OMP_NUM_THREADS when set, else the CPUs this process may run
  /// on), 1 = serial. Results do not depend on it (items
  /// are judged into their own slots and tallied in serial order).
  int threads = 0;
  /// The judge device (`--judge-device cuda`): when set, called once per run; the device
  /// it returns computes the physics tier's rows broadphase-completeness and penetration
  /// (their candidates and box-box geometry; octocd/device_judge.hpp: make_cuda_judge),
  /// every other row runs on the CPU. Empty (default): every row on the CPU. Verdicts are
  /// the CPU's (tests/gpu/test_device_judge.cpp); errors of the factory propagate.
  std::function<std::unique_ptr<DeviceJudge>()> judge_device;
  /// validate_engine judges frame f (on a copy of its record, on a second thread) while
  /// the engine runs frame f + 1; ignored when threads is 1. Verdicts are the serial
  /// run's; what changes: on_step(f) runs before frame f is judged, so a stop inside
  /// frame f's checks finds frame f already passed to on_step (a trace holds it).
  bool pipeline = false;
};

/// One entry of the tolerance table (octocd/tolerances.def): its name (as in `--tolerance
/// NAME=VALUE`), the Tolerances member, the unit or meaning of the value, the reason for its
/// value and its default.
struct ToleranceEntry {
  const char* name;
  double Tolerances::*member;
  const char* unit;
  const char* doc;
  double default_value;
};
/// Every tolerance, in the order of octocd/tolerances.def (Tolerances' member order).
const std::vector<ToleranceEntry>& tolerance_table();
/// Sets tolerance `name` to `value` (finite, >= 0). Throws SettingError (octocd/setting_error.hpp;
/// kind "tolerance") with the name, the value and the allowed names or range, for the CLI
/// and Python to word.
void set_tolerance(Tolerances& tol, const std::string& name, double value);

/// Per-frame validators (design.md section 7 items 1-6 and 9), fed one FrameRecord at a time. They
/// read only the record and the model, so the same code judges octocd's engines (the
/// Engine overloads), another engine's frames given through the C++ API
/// (octocd/external.hpp) and external traces (`octocd validate --trace-in`). Hooks let
/// tests plant faults: extra broadphases (e.g. one that drops a pair) and the midphase
/// function under test.
class FrameValidators {
 public:
  /// Who produced the records being judged.
  struct Source {
    /// How messages name it, e.g. "engine cpu (octree)" or "engine 'toy'".
    std::string label;
    /// True for octocd's own pipeline: both tiers are judged, the model tier in full
    /// (candidate sets of octocd's and the reference broadphases against `flat`, midphase
    /// completeness, Eq. 14, friction monotonicity, impulse conservation, the applied
    /// state). False for another engine: the physics tier only, and the model tier's
    /// response rows when `spec6_response`; the others are n/a with the reason.
    bool octocd_pipeline = true;
    /// For another engine: it claims octocd's response (design.md section 6, trace attribute
    /// `response_model = "spec6"`): the model tier's response rows are judged too.
    bool spec6_response = false;
    /// What the physics tier knows of the bodies (inertia, materials, contact margin,
    /// declared exact broadphase, contact geometry). nullptr: octocd's engines'
    /// (octocd_physics_bodies).
    std::shared_ptr<const PhysicsBodies> physics;
  };

  /// Validators for records of bodies described by `model` (scene parameters, shapes,
  /// local boxes, inverse masses; not owned, must outlive this object). `broadphases` are
  /// compared with `flat` on every checked frame (owned from here on). `options.against_fcl`
  /// enables the FCL reference normals (builds FCL geometry for every shape).
  FrameValidators(const Model& model, const ValidationOptions& options,
                  std::vector<std::unique_ptr<BroadPhase>> broadphases, Source source);
  /// The same for `engine`'s model, with source "engine NAME (BROADPHASE)".
  FrameValidators(const Engine& engine, const ValidationOptions& options,
                  std::vector<std::unique_ptr<BroadPhase>> broadphases);
  ~FrameValidators();

  /// The midphase function checked against exhaustive_contact (default confirm_contact),
  /// called from the validators' threads at once (it must hold no state of its own).
  using ConfirmFn = std::function<bool(const PlacedShape&, const PlacedShape&, float,
                                       const MidphaseConfig&, MidphaseStats&)>;
  /// Replaces the midphase under test (planted-fault tests).
  void set_midphase(ConfirmFn fn);

  /// Judges one step. `rec.aabbs` must hold one box per body of the model; `rec.pairs`
  /// and `rec.confirmed` sorted and unique with a < b < bodies; `rec.contacts` in (a, b)
  /// order; the four state vectors either all empty (the state validators then skip
  /// this frame) or one entry per body. `checked` selects the costly validators
  /// (candidate sets, midphase completeness, normals) for this frame; the per-contact
  /// and applied-state checks run on every frame. The record is trusted: callers with
  /// data from outside octocd check it first (check_frame_record, octocd/external.hpp).
  /// A checked frame whose boxes overlap in more than limits::kMaxPairsPerBody pairs a
  /// body (octocd/exact_pairs.hpp; counted before the per-pair work) throws
  /// PairLimitError, "frame F: ...".
  void observe(const FrameRecord& rec, bool checked);

  /// Checks the frame the engine just stepped (its record()). Throws RuntimeError when
  /// the engine does not record (Engine::can_record false or recording off).
  void observe(const Engine& engine, bool checked);

  /// Results of validators 1-6 and 9 so far.
  std::vector<ValidationResult> results() const;

  /// The physics tier these validators run (owned by them): for its shard settings
  /// (PhysicsValidators::set_episode_frames, observe_episodes).
  PhysicsValidators& physics();

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

/// The broadphases `octocd validate` compares with `flat`: octocd's own and, when
/// `with_references`, Bullet's and FCL's (every name of all_broadphase_names but flat),
/// configured like `scene.broadphase` on `scene.domain`.
std::vector<std::unique_ptr<BroadPhase>> compared_broadphases(const Scene& scene, bool with_references);

/// What a scene is, recognised by its content (design.md section 7.7), never by its name.
enum class SceneKind {
  FreeFall,      ///< one dynamic body, gravity, nothing under it: Eq. 2-3 closed form
  Bounce,        ///< one dynamic body at rest above a static support, impact above v_th
  Slide,         ///< one dynamic body resting on a static support, launched sideways
  RestingStack,  ///< several dynamic bodies at rest, each touching what is under it
  Pile,          ///< several dynamic bodies at rest above a floor, falling (settling)
  Other,         ///< nothing analytic
};
/// Recognises the scene kind from the model and its initial state (gravity along -y).
SceneKind classify_scene(const Model& model);
/// "free fall", "bounce", "slide", "resting stack", "pile", "other".
const char* scene_kind_name(SceneKind kind);

/// Validator 7 (design.md section 7.7): the analytic scene kinds (classify_scene) run in `engine`
/// against their closed forms: free fall, bounce, slide, resting stack. Not applicable
/// (n/a) only to the other kinds. Steps `engine` itself, exactly `frames` steps at most
/// (never more): an event the run does not reach fails, saying so (a bounce after the
/// last frame, a slide still moving, a stack judged before its 200 settling frames end
/// is judged on its last frame).
/// `stop` (may be empty) is polled before every step; throws ValidationStopped when it
/// returns true.
ValidationResult validate_analytic(Engine& engine, int frames, const Tolerances& tol,
                                   const std::function<bool()>& stop = {});

/// Validator 8 (design.md section 7.8): `engine` against Bullet's btDiscreteDynamicsWorld built from
/// the same model: settled centre-of-mass height (resting stacks and piles) or the
/// centre-of-mass trajectory (bounce, slide) over `frames` steps. Not applicable to other
/// kinds, nor to a stack or pile that Bullet has not brought to rest by the last frame
/// (Tolerances::bullet_rest_speed_rel); where Bullet rests, `engine` fails as still moving
/// or with a height off by more than bullet_height_rel (causes `still-moving`, `height`).
/// Steps `engine` itself, exactly `frames` steps.
/// `stop` as for validate_analytic.
ValidationResult validate_against_bullet(Engine& engine, int frames, const Tolerances& tol,
                                         const std::function<bool()>& stop = {});

/// Makes a fresh engine of the kind being validated (each call a new one, from the start).
using EngineFactory = std::function<std::unique_ptr<Engine>()>;

/// Runs every validator on the engines `make` builds: validators 1-6 and 9 over
/// `options.frames` steps (with options.pipeline, frame f judged on a copy of its record
/// on a second thread while the engine runs frame f + 1, in order: the serial run's
/// verdicts), then 7 and 8 on fresh engines. Uses octocd's and (against_fcl)
/// the reference broadphases. The engines must be able to record (FrameRecord). When
/// `options.stop` stops it (between frames or inside a check), the results cover the
/// frames judged so far and the validators not run are n/a ("not run: stopped ...");
/// `stopped_in` (may be null) receives the frame whose checks it stopped inside (that
/// frame is partly judged), 0 when it stopped between frames or in a rerun, or did not stop.
std::vector<ValidationResult> validate_engine(const EngineFactory& make, const ValidationOptions& options,
                                              std::int64_t* stopped_in = nullptr);

/// validate_engine with the CPU engine (World) on `scene`.
std::vector<ValidationResult> validate_scene(const Scene& scene, const ValidationOptions& options);

/// Appends `/validation` to an existing trace (design.md section 8): one row per result with name,
/// figure, measured, bound, pass, applicable, detail. Throws RuntimeError naming the path.
void write_validation(const std::string& trace_path, const std::vector<ValidationResult>& results);

}  // namespace octocd
