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
/// "physics" or "model" (the table's tier column, JUnit, the trace's /validation/tier).
const char* tier_name(Tier tier);

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

/// Every tolerance of the validators, with the reason for its value (issue 3: "stated in
/// one place with the reason for each").
struct Tolerances {
  /// Contraction (Eq. 14) slack in m: float32 positions of O(1) m round at ~1e-7 m per
  /// operation; a correction is a handful of operations.
  double contraction_m = 2e-6;
  /// Friction: slack on |v_t'| <= |v_t| in m/s (float32 velocity rounding, |v| <= v_max).
  double friction_speed = 1e-5;
  /// Friction: relative slack on |J_t| <= mu_s J_n (float32 products).
  double friction_cone_rel = 1e-5;
  /// Physics-tier friction cone, scalar rule (traces without /contacts/jt3): absolute
  /// slack (kg m/s) on a pair's sum |jt| <= mu sum jn; and the friction impulse up to
  /// which the jt3 dissipation rule does not judge a pair's friction direction. A
  /// sequential-impulse solver's leftovers (warm start, rows clamped while the normal
  /// impulse fell to 0) are of this size: Bullet with rotation without its Coulomb
  /// projection left up to 2.5e-4 kg m/s on pairs whose final jn is 0 (boxes of 0.2-1 kg
  /// at dt 2 ms), and 4 landing pairs of rot-drop-220 / rot-pile-1000 carry 0.96e-3 -
  /// 0.99e-3 kg m/s across their sliding. The jt3 cone has no such slack (rounding only:
  /// 16 x 2^-23 of sum |jt3| + mu sum jn). A planted friction impulse 1.2x the cone is
  /// caught by both rules. There is no relative slack: the 25% the cone once allowed
  /// covered Bullet's rows that kept friction after their normal impulse fell to 0
  /// (13% above mu times the final normal impulses on 4-row box-floor manifolds); Bullet's
  /// adapter now projects those rows back (CoulombSolver, reference/bullet/bullet_world.cpp),
  /// and the per-pair sum passes on rot-slope, rot-stack-10, rot-drop-220 and
  /// rot-pile-1000 with rounding alone, on both rules.
  double friction_cone_abs = 1e-3;
  /// Momentum per impulse: |m_a dv_a + m_b dv_b| <= this x (|m_a dv_a| + |m_b dv_b|) + 1e-9.
  /// float32 impulses carry ~6e-8 relative error; x 20 for the products and sums.
  double momentum_rel = 1e-5;
  /// Mass-weighted centre per correction, same reasoning as momentum.
  double centre_rel = 1e-5;
  /// Contact normals: minimum share of contacts whose AABB-axis normal has the same sign
  /// as FCL's (dot > 0). The response normal is the AABB axis of least overlap (Eq. 10),
  /// FCL's the geometric one; for meshes they can differ by up to 90 degrees on oblique
  /// contacts, but a sign flip means the response pushes bodies into each other.
  double normal_sign_agreement = 0.90;
  /// Analytic free fall (Eq. 2-3): |x - closed form| <= this x n x (1 + |x|). Measured
  /// float32 error: 2.5e-8; explicit Euler differs by |g| dt^2 per step (9.8e-6 m at
  /// dt = 1 ms), i.e. >= 4.7e-7 for |x| < 20 m, so it fails this bound.
  double freefall_rel_per_step = 1e-7;
  /// Bounce: |v_out - e v_in| <= this x |v_in| (one float32 impulse).
  double bounce_rel = 1e-4;
  /// Slide: stopping distance within this share of v0^2/(2 mu_k g) (issue 2: 2%).
  double slide_rel = 0.02;
  /// Resting stack: from frame 200 on (or on the last frame of a shorter run), every body
  /// stays within this many slops of its rest height (its initial height lowered by one
  /// slop per contact below it: design.md section 6 leaves each contact's first delta of penetration
  /// uncorrected).
  double stack_slops = 1.0;
  /// Applied state (design.md section 7.9): engine vs the double re-derivation, per component,
  /// |diff| <= this x 2^-23 x (iterations + 2) x (the magnitudes that entered the value:
  /// |x| + the corrections + the largest AABB coordinate of its contacts; |v| + |g dt| +
  /// the velocity changes + the largest velocity of its contacts' bodies). A few float32
  /// roundings per operation chain; explicit Euler (|g| dt^2 = 9.8e-6 m per step) and
  /// summed instead of averaged corrections exceed it.
  double applied_state_ulps = 4.0;
  /// Applied-state momentum of an isolated dynamic group: |sum m v' - sum m v| <= this x
  /// (sum m |dv|) + 1e-9 kg m/s; mass-weighted centre of an isolated pair likewise with
  /// the position tolerance added.
  double applied_conservation_rel = 1e-5;
  /// Bullet comparison: settled centre-of-mass heights differ by at most this share of the
  /// mean body height. Bullet uses box shapes equal to the AABBs and its own solver
  /// (sequential impulses, split impulse), octocd a Jacobi AABB response: same physics,
  /// different numerics.
  double bullet_height_rel = 0.10;
  /// Bullet comparison: a run is at rest when its dynamic bodies moved less than this share
  /// of sqrt(g h) per second on average over the last tenth of the frames (1 to 100; h the
  /// mean body height; sqrt(g h) is about the speed of a fall by one body height): 0.05 is
  /// 0.05 m/s for 0.1 m bodies under 9.81 m/s^2. Displacement, not the state's velocity:
  /// octocd's resting bodies keep a downward velocity that the position correction cancels
  /// every step (bunny-stack-50 at rest: mean |v| 0.2 m/s, displacement 0.001 m/s). Heights
  /// are compared only once Bullet's run is at rest (else the row is n/a: mixed-pile-1000
  /// after 300 frames still falls at 2.6 m/s, and its heights say nothing of where it
  /// settles); octocd's run then has to be at rest too.
  double bullet_rest_speed_rel = 0.05;
  /// Bullet comparison: centre-of-mass trajectories of `bounce` and `slide` differ by at
  /// most this many metres at any frame (restitution and friction are combined by Bullet
  /// per contact point; the contact timing differs by a step).
  double bullet_trajectory_m = 0.03;

  // ---- Physics tier (design.md section 13, octocd/physics.hpp). Measured on octocd's CPU engine
  // (octocd_physics_bodies; tests/validation/test_physics.cpp, every 10th frame checked) over
  // 1500 frames of box-stack, bunny-stack-50, bunny-random-400 and dragon-random-250, and
  // on the hand-made rotated records of that test. Bullet with rotation is measured by
  // its own tests; its figures belong here too once they land.
  /// Geometric slack (m) of every FCL comparison: float32 poses of O(1-10) m round at
  /// ~1e-6 m, FCL's GJK/EPA/bisection tolerances are 1e-6 m or finer. octocd: the closest
  /// of its contact pairs to the false-contact bound is 1.1e-5 m inside it (box-stack).
  double geometry_slack_m = 1e-5;
  /// Broadphase completeness: pairs whose posed shapes are closer than this (m) must be
  /// candidates (0: penetrating pairs, deeper than the slack). octocd: every required pair
  /// found (3390 on bunny-stack-50, 3995 on bunny-random-400); its candidates per true
  /// pair: 2.2 (bunny-stack-50), 7.6 (bunny-random-400).
  double broadphase_margin_m = 0.0;
  /// Contact completeness: a pair penetrating deeper than this (m) needs a contact: one
  /// slop of design.md section 6 (below it a resting engine may leave a pair untouched). octocd: every
  /// such pair has a contact (2769 on bunny-stack-50, 589 on bunny-random-400).
  double contact_depth_m = 1e-3;
  /// Contact geometry: largest angle between the engine's normal and FCL's minimum
  /// translation, on rows of penetrating shapes (degrees). An engine resolving a contact
  /// on the true geometry finds FCL's direction up to rounding (0.0 deg on the
  /// rotated-box records); they part where two directions give nearly the same depth
  /// (a box corner near a face's edge), where either separates: Bullet with rotation
  /// (a trial merge with main: tests/scene/test_cli_rotation_faults.cpp's 24 boxes and
  /// 4 bunnies, 300 frames) worst 31.6 deg, 3 of 643 judged rows above 30. 40 lets those
  /// through and catches a normal turned by 45 deg (planted). octocd (contacts on world AABBs, judged against FCL box-box on them):
  /// 0.0 deg on every row; against the posed shapes (a figure only) its AABB-axis
  /// normals deviate by p95 28-30 deg, max 57 deg (bunny-stack-50) and 115 deg
  /// (bunny-random-400).
  double normal_angle_deg = 40.0;
  /// Contact geometry of two convex polytopes (boxes, convex meshes; design.md section 13b.9): the
  /// separating-axis test accepts as a normal every axis whose overlap is within
  /// geometry_slack_m + this fraction of the minimum translation (validation/physics/
  /// sat.hpp). 0.05: ODE's box-box test (FCL's, Bullet's btBoxBoxDetector) keeps a face
  /// axis unless an edge-edge axis overlaps less than 1/1.05 of it (its fudge_factor), so
  /// a face normal up to 5% deeper than the minimum is a deliberate choice of widely used
  /// detectors; a normal 45 deg from every accepted axis is still caught.
  double sat_accept_rel = 0.05;
  /// Contact geometry: largest |engine depth - FCL depth| (m) of a pair's deepest row,
  /// and how far beyond the pair's depth (or distance) a row's point may lie from either
  /// surface. A solver's depth is measured at its own point of the manifold, FCL's is the
  /// minimum translation: several slops. octocd: 0 m (AABB depths are Eq. 10 exactly).
  /// The planted unrotated contact points lie 0.04 m off.
  double depth_m = 5e-3;
  /// Penetration: the largest true penetration is at most this many slops (2 cm at the
  /// default slop of 1 mm). octocd: box-stack 1.02 mm; bunny-stack-50 5.3 mm; over 300
  /// frames bunny-random-400 7.1 mm; over 1500 frames octocd's own model FAILS it on the
  /// random mesh scenes: bunny-random-400 26 mm (frame 880), dragon-random-250 24 mm
  /// (frame 1030); these are upper bounds (non-convex meshes: the least separating
  /// translation over 8 directions), the AABB response (design.md section 6) does not push along the
  /// surfaces' normal, so thin parts pass into each other.
  double penetration_slops = 20.0;
  /// Penetration: frames before this one are not judged (settling), 0 = all.
  double penetration_settle_frames = 0.0;
  /// Angular momentum of an isolated group: |dL| <= this x the exchanged angular
  /// momentum (sum of the bodies' |dL_i|) + dt |w x I w| per body (an explicit
  /// orientation update of a non-isotropic body misses the gyroscopic term) + (depth +
  /// margin) |jt| per row (Bullet applies a row's impulse at a witness point on each
  /// body, apart along the normal) + float32 slack. Exact to rounding on the off-centre collision record (impulses at the
  /// detection pose); octocd's records are translation-only (n/a).
  double angular_momentum_rel = 1e-3;
  /// Energy of an isolated group: KE' <= KE (after gravity) x (1 + this) + slack, when
  /// every restitution <= 1. octocd: worst rise 1.2e-7 of KE on bunny-stack-50, 6.1e-4
  /// on bunny-random-400 (Eq. 18's impulse floor J_min on grazing contacts); octocd's
  /// own model FAILS it on dragon-random-250 over 1500 frames: +25.8% (0.165 -> 0.207 J,
  /// frame 584, a group of 3 bodies): design.md section 6 sums the impulses of a body's contacts
  /// computed from the same pre-response state (Jacobi), which overshoots on chains.
  double energy_rel = 1e-3;
  /// Momentum balance per body (design.md section 13b.7) and free flight (13b.8): rounding allowance
  /// in units of 2^-23 of the magnitudes that entered the compared values (docs/
  /// validate-your-engine.md, "momentum-balance", derives it). A float32 velocity update
  /// v' = v + sum of k terms rounds at most k + 1 times by 2^-24 of the running sum; an
  /// iterative solver (Bullet: 10 iterations) adds every row's increment each iteration.
  /// 16 x (rows + 2) covers 10 iterations of sums whose partial sums stay within the
  /// magnitudes; a dropped row, an edited velocity or an impulse on the wrong body is
  /// larger by orders of magnitude.
  double balance_ulps = 16.0;
  /// Free flight: angle (rad) between the engine's q' and q advanced by w dt, beyond
  /// (|w| dt)^2 (the second-order difference between integrators: exponential map,
  /// normalised first-order update) and float32 rounding of the quaternion (~1e-7 rad).
  /// A body turned by 30 deg (0.52 rad) in one step is caught.
  double free_flight_angle_rad = 1e-4;
  /// Momentum balance with a scalar `jt`: below this relative sliding speed at a row
  /// before the step (m/s), the friction impulse's direction is the engine's choice
  /// (Bullet: below sqrt(FLT_EPSILON) = 3.45e-4 m/s it takes btPlaneSpace1's axis), so the
  /// row's J_t is known only to lie in its cone; above it, J_t is jt along -v_t / |v_t|.
  /// /contacts/jt3 (the vector) removes the question.
  double friction_direction_speed = 1e-3;
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
  /// per candidate pair, the reference pair set): 0 = the hardware's
  /// (std::thread::hardware_concurrency), 1 = serial. Results do not depend on it (items
  /// are judged into their own slots and tallied in serial order).
  int threads = 0;
  /// validate_engine judges frame f (on a copy of its record, on a second thread) while
  /// the engine runs frame f + 1; ignored when threads is 1. Verdicts are the serial
  /// run's; what changes: on_step(f) runs before frame f is judged, so a stop inside
  /// frame f's checks finds frame f already passed to on_step (a trace holds it).
  bool pipeline = false;
};

/// One entry of the tolerance table: its name (as in `--tolerance NAME=VALUE`), the
/// Tolerances member, and the unit or meaning of the value.
struct ToleranceEntry {
  const char* name;
  double Tolerances::*member;
  const char* unit;
};
/// Every tolerance, in declaration order.
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

  /// The midphase function checked against exhaustive_contact (default confirm_contact).
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
