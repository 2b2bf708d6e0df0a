#pragma once
/// \file validation.hpp
/// The validators of SPEC section 7 and `octocd validate`.
///
/// Each validator returns a named result: the measured figure, the bound it is held to,
/// pass/fail and a detail line (the first offending frame/pair when it fails). Every
/// tolerance is defined once, in `Tolerances`, with the reason for its value.

#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "octocd/broadphase.hpp"
#include "octocd/midphase.hpp"
#include "octocd/scene.hpp"
#include "octocd/world.hpp"

namespace octocd {

/// One validator's verdict.
struct ValidationResult {
  std::string name;      ///< e.g. "candidate-sets"
  std::string figure;    ///< what `measured` is, with its unit
  double measured = 0;   ///< the measured figure
  double bound = 0;      ///< the bound it is compared with
  bool pass = true;      ///< measured within bound
  bool applicable = true;  ///< false: this scene has nothing to check (counts as a pass)
  std::string detail;    ///< first offending frame/pair, or a short note
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
  /// Analytic free fall (Eq. 2-3): |x - closed form| <= this x n x (1 + |x|) (float32
  /// accumulation over n steps).
  double freefall_rel_per_step = 2e-6;
  /// Bounce: |v_out - e v_in| <= this x |v_in| (one float32 impulse).
  double bounce_rel = 1e-4;
  /// Slide: stopping distance within this share of v0^2/(2 mu_k g) (issue 2: 2%).
  double slide_rel = 0.02;
  /// Resting stack: once settled (frame 200), no box moves more than this many slops.
  double stack_slops = 1.0;
  /// Bullet comparison: settled centre-of-mass heights differ by at most this share of the
  /// mean body height. Bullet uses box shapes equal to the AABBs and its own solver
  /// (sequential impulses, split impulse), octocd a Jacobi AABB response: same physics,
  /// different numerics.
  double bullet_height_rel = 0.10;
  /// Bullet comparison: centre-of-mass trajectories of `bounce` and `slide` differ by at
  /// most this many metres at any frame (restitution and friction are combined by Bullet
  /// per contact point; the contact timing differs by a step).
  double bullet_trajectory_m = 0.03;
};

/// What `octocd validate` runs.
struct ValidationOptions {
  int frames = 300;   ///< steps to run (>= 1)
  int every = 10;     ///< check candidate sets, midphase and normals every k-th frame (>= 1)
  bool against_bullet = true;  ///< run the Bullet dynamics comparison (scenes it applies to)
  bool against_fcl = true;     ///< include Bullet/FCL broadphases; FCL reference normals
  Tolerances tol;
  /// Called after every step of the validated world (e.g. to write a trace); may be empty.
  std::function<void(const World&)> on_step;
};

/// Per-frame validators, fed frame by frame from a World (after World::step()).
/// Hooks let tests plant faults: extra broadphases (e.g. one that drops a pair) and the
/// midphase function under test.
class FrameValidators {
 public:
  /// `broadphases` are compared with `flat` (the caller owns them via the vector).
  /// `against_fcl` enables the FCL reference normals (needs meshes' FCL models).
  FrameValidators(const World& world, const ValidationOptions& options,
                  std::vector<std::unique_ptr<BroadPhase>> broadphases);
  ~FrameValidators();

  /// The midphase function checked against exhaustive_contact (default confirm_contact).
  using ConfirmFn = std::function<bool(const PlacedShape&, const PlacedShape&, float,
                                       const MidphaseConfig&, MidphaseStats&)>;
  /// Replaces the midphase under test (planted-fault tests).
  void set_midphase(ConfirmFn fn);

  /// Checks the frame the world just stepped. `checked` selects the costly validators
  /// (candidate sets, midphase completeness, normals) for this frame.
  void observe(const World& world, bool checked);

  /// Results of validators 1-6 so far.
  std::vector<ValidationResult> results() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

/// Validator 7 (SPEC 7.7): the analytic scene `scene.name` (free-fall, bounce, slide,
/// box-stack) run in `world` against its closed form; not applicable to other scenes.
/// Steps `world` itself (at most scene.frames steps).
ValidationResult validate_analytic(World& world, const Tolerances& tol);

/// Validator 8 (SPEC 7.8): `world` (octocd) against Bullet's btDiscreteDynamicsWorld on
/// the same scene: settled centre-of-mass height (box-stack, bunny-stack-50) or the
/// centre-of-mass trajectory (bounce, slide) over `frames` steps. Not applicable to other
/// scenes. Steps `world` itself.
ValidationResult validate_against_bullet(World& world, int frames, const Tolerances& tol);

/// Runs every validator on a scene: validators 1-6 over `options.frames` steps, then 7 and
/// 8 on fresh worlds. Uses octocd's and (against_fcl) the reference broadphases.
std::vector<ValidationResult> validate_scene(const Scene& scene, const ValidationOptions& options);

/// Prints results as a table (name, figure, measured, bound, verdict, detail).
std::string format_results(const std::vector<ValidationResult>& results);

/// Appends `/validation` to an existing trace (SPEC 8): one row per result with name,
/// figure, measured, bound, pass, applicable, detail. Throws RuntimeError naming the path.
void write_validation(const std::string& trace_path, const std::vector<ValidationResult>& results);

}  // namespace octocd
