#pragma once
/// \file reference_world.hpp
/// The adapter base of the reference engines (reference/mujoco, reference/ode,
/// reference/dart): what every one of them keeps and does alike, written once. An
/// engine's folder holds its model mapping (scene -> the engine's bodies, shapes and
/// materials), its step and its contact extraction; the state, the settings
/// (SettingsWorld), the metrics, the version 2 FrameRecord and the Engine accessors live
/// here (docs/architecture.md, "Adding an engine").

#include <algorithm>
#include <array>
#include <chrono>
#include <cstdint>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "octocd/engine.hpp"

namespace octocd {

/// Milliseconds (steady clock) since `t0`.
inline double ms_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}

/// What a reference world keeps besides its engine's own objects. An adapter's private
/// state (`struct XWorld::Impl`) derives from it, so the adapter reads and writes these
/// fields directly; ReferenceWorld owns it and answers the Engine accessors from it.
struct ReferenceCore {
  virtual ~ReferenceCore() = default;

  std::shared_ptr<const Model> model;  ///< the model the world was built from (shared)
  double dt = 0.001;                   ///< scene.dt (s)
  Vec3 gravity;                        ///< scene.gravity (m/s^2)
  float slop = 0.001f;                 ///< scene.response.slop (m)
  std::vector<float> w;                ///< inverse mass per body (1/kg; 0: static)
  std::vector<std::array<double, 9>> inertia;  ///< body frame, about x, row-major (kg m^2; 0: static)
  std::uint64_t static_static = 0;     ///< static_static_pairs(*model)
  BodyState state;                     ///< after the last step (the initial one before any)
  FrameMetrics metrics;                ///< the last step's
  std::int64_t frame = 0;              ///< steps taken
  bool recording = false;              ///< whether step() fills `record`
  RotationTraits traits;               ///< what a version 2 trace declares
  FrameRecord record;                  ///< the last step's (see each adapter's record())
  std::vector<ContactRecord> no_contacts;  ///< contacts() while not recording (empty)
  std::string geometry;                ///< collision_geometry()

  /// Takes what every adapter reads from the model and the initial state: dt, gravity,
  /// slop, w, static_static, state (q resized to the identity and omega to zero where the
  /// state has none). Throws InputError "<engine>: the initial state has N bodies, the
  /// model M" when the counts differ. The traits start as every reference engine declares
  /// them: rotates, jt3, detection "pre-step", broadphase_exact false, contact_geometry
  /// "shape", integrator "semi-implicit"; the adapter sets the rest.
  void start(std::shared_ptr<const Model> m, const BodyState& initial, const std::string& engine);

  /// Body i has an inverse mass > 0.
  bool dynamic(std::size_t i) const { return w[i] > 0.0f; }

  /// The metrics of the next frame: frame incremented, fm.frame = frame, fm.time = frame dt.
  FrameMetrics next_frame();
  /// fm.step_ms = ms_since(t0); metrics = fm; returns metrics.
  const FrameMetrics& finish_step(FrameMetrics& fm, std::chrono::steady_clock::time_point t0);

  /// record.frame = frame + 1 and x_pre, v_pre, q_pre, w_pre = the state (before a step).
  void save_pre_state();
  /// record's x_post ... w_post = the state; x_det, q_det = x_pre, q_pre (the engine
  /// detects at the pose before its step).
  void save_post_state();

  /// Throws RuntimeError "frame F: body i has a non-finite state after <who> step (x (..),
  /// v (..))" for the first dynamic body whose x, v or omega is not finite.
  void check_finite(const std::string& who) const;

  /// record.aabbs = the exact world AABBs of the bodies' local boxes at the pre-step pose
  /// (record.x_pre, q_pre); returns the number of pairs with a dynamic body whose boxes
  /// overlap (octocd::overlaps, inclusive: sort by min x, sweep).
  std::uint64_t posed_overlapping_pairs();

  /// One manifold row from an engine contact between bodies i1 and i2 (i1 != i2):
  /// `normal21` the normal from body 2 into body 1 (unit to the engine's rounding; used
  /// normalized), `impulse1` the impulse on body 1 (N s, world), `depth` (m; negative taken
  /// as 0), `point` (world). The row's pair is (min, max) with the normal and impulse seen
  /// from A (flipped when i1 > i2); with n unit: jn = max(0, J_A . n), jt3 = J_A - (J_A . n) n
  /// (appended to `jt3`: in the contact plane to double rounding, whatever the sign of
  /// J_A . n), jt = row_scalar_jt.
  ContactRecord manifold_row(std::uint32_t i1, std::uint32_t i2, const double normal21[3], const double impulse1[3],
                             double depth, Vec3 point, std::vector<Vec3>& jt3) const;
};

/// Sums a step's penetration figures: add() every depth that counts (m), then finish()
/// writes penetration_mean (over the depths added), _max and _share_above_slop into
/// FrameMetrics (left as they are when nothing was added).
struct PenetrationSum {
  std::uint64_t count = 0, above = 0;
  double sum = 0.0, max = 0.0;
  /// Adds one depth; `slop` (m) decides whether it counts as above.
  void add(double depth, float slop) {
    ++count;
    sum += depth;
    max = std::max(max, depth);
    if (depth > static_cast<double>(slop)) ++above;
  }
  /// Writes the mean, maximum and share above slop into `fm` when count > 0.
  void finish(FrameMetrics& fm) const {
    if (count == 0) return;
    fm.penetration_mean = sum / static_cast<double>(count);
    fm.penetration_max = max;
    fm.penetration_share_above_slop = static_cast<double>(above) / static_cast<double>(count);
  }
};

/// Sums kinetic energy (J) and linear momentum (kg m/s) over dynamic bodies, in double.
struct EnergySum {
  double ke = 0.0, px = 0.0, py = 0.0, pz = 0.0;
  /// Adds 0.5 m |v|^2 (`v_sq` = |v|^2 as the engine computes it) and m v.
  void add_linear(double mass, const double v[3], double v_sq) {
    ke += 0.5 * mass * v_sq;
    px += mass * v[0];
    py += mass * v[1];
    pz += mass * v[2];
  }
  /// Adds 0.5 w_b . (I w_b): `w_b` the angular velocity in the body frame (rad/s), `I`
  /// the body-frame tensor, row-major (kg m^2).
  void add_rotational(const double w_b[3], const std::array<double, 9>& I) {
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c) ke += 0.5 * w_b[r] * I[static_cast<std::size_t>(3 * r + c)] * w_b[c];
  }
  /// Writes kinetic_energy and momentum into `fm`.
  void finish(FrameMetrics& fm) const {
    fm.kinetic_energy = ke;
    fm.momentum = {px, py, pz};
  }
};

/// The Engine part every reference world shares: it owns the adapter's state (a
/// ReferenceCore, usually the adapter's Impl) and answers the accessors from it. An
/// adapter derives from it and implements name(), broadphase_name(), step(), notes(),
/// has_stage() and whatever else is its own.
class ReferenceWorld : public Engine {
 public:
  ~ReferenceWorld() override;
  ReferenceWorld(const ReferenceWorld&) = delete;
  ReferenceWorld& operator=(const ReferenceWorld&) = delete;

  /// x, v, w, q, omega after the last step (the initial state before any).
  const BodyState& state() const override;
  /// Metrics of the last step.
  const FrameMetrics& last_metrics() const override;
  /// Steps taken so far.
  std::int64_t frame() const override;
  /// The CPU model (cpu_description()).
  std::string device() const override;
  /// The model it was built from.
  const Model& model() const override;
  /// While recording: record().contacts; otherwise empty.
  const std::vector<ContactRecord>& contacts() const override;
  /// What the engine collides, naming only what the scene has.
  std::string collision_geometry() const override;
  /// The traits its version 2 trace declares.
  const RotationTraits* rotation_traits() const override;
  /// Always true.
  bool can_record() const override { return true; }
  /// Turns the per-step FrameRecord on or off.
  void set_recording(bool on) override;
  /// The last step's record (recording on).
  const FrameRecord& record() const override;

 protected:
  /// Takes ownership of the adapter's state; the adapter's constructor fills it.
  explicit ReferenceWorld(std::unique_ptr<ReferenceCore> core);
  /// The adapter's state.
  ReferenceCore& core() const { return *core_; }

 private:
  std::unique_ptr<ReferenceCore> core_;
};

/// A ReferenceCore with the adapter's settings struct `S` (MujocoSettings, OdeSettings,
/// DartSettings): the state of an adapter that has settings derives from it.
template <class S>
struct SettingsCore : ReferenceCore {
  S settings;  ///< what the world was built with
};

/// A ReferenceWorld whose adapter has a settings struct `S`: it starts the adapter's state
/// and keeps the settings, so the adapter's constructor goes on from a started core.
template <class S>
class SettingsWorld : public ReferenceWorld {
 public:
  /// The settings it was built with.
  const S& settings() const { return static_cast<const SettingsCore<S>&>(core()).settings; }

 protected:
  /// Takes ownership of the adapter's state `core`, runs core->start(model, initial,
  /// engine) (ReferenceCore::start: throws InputError when the body counts differ) and
  /// stores `settings` in it; the adapter's constructor builds the rest.
  SettingsWorld(std::unique_ptr<SettingsCore<S>> core, std::shared_ptr<const Model> model,
                const BodyState& initial, const std::string& engine, const S& settings)
      : ReferenceWorld(std::move(core)) {
    auto& c = static_cast<SettingsCore<S>&>(this->core());
    c.start(std::move(model), initial, engine);
    c.settings = settings;
  }
};

}  // namespace octocd
