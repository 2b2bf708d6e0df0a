#pragma once
/// \file planted_faults.hpp
/// A test build of the CPU reference step with deliberate faults, for the validators'
/// self-tests ("a validator that cannot fail is a defect"; ARCHITECTURE "The reference
/// step stays plain"). FaultyWorld runs World's stages (octocd/stages.hpp) in World's
/// order and changes, between or instead of them, only what a planted fault names; with
/// no fault planted it reproduces World bit for bit (tests/core/test_planted_faults.cpp).
/// The product (octocd_core, `octocd`, Python) holds no fault.

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "octocd/broadphase.hpp"
#include "octocd/engine.hpp"
#include "octocd/stages.hpp"

namespace octocd {
namespace test {

/// Deliberate faults, all off by default. Each one is caught by a validator in
/// tests/validation/test_validation.cpp, test_applied_state.cpp, test_applied_state_iterations.cpp
/// or test_external.cpp.
struct PlantedFaults {
  bool eq12_weights = false;     ///< split corrections with the paper's Eq. 12 (swapped) weights
  bool friction_sign = false;    ///< apply friction with the wrong sign (speeds sliding up)
  bool momentum_leak = false;    ///< apply only 90% of each impulse to body B
  bool normal_sign = false;      ///< use the contact normal pointing from A to B
  bool impulse_wrong_body = false;   ///< add B's velocity change to A (dv_sum[a] += dv_b)
  bool corrections_summed = false;   ///< sum position corrections instead of averaging them
  bool explicit_euler = false;   ///< x += dt v_old, then v += dt g (explicit, not Eq. 2-3)
  bool skip_clamp = false;       ///< leave out the Eq. 23 velocity clamp
  bool broadphase_drops_pair = false;  ///< the engine's own broadphase call loses its first
                                       ///< pair that has a dynamic body (fresh instances don't)
  bool midphase_drops_contact = false; ///< the engine's midphase rejects its first confirmed
                                       ///< contact of every frame
  bool jmin_first_pass_only = false;   ///< the J_min floor (Eq. 18) only in the first pass
  bool one_pass_fewer = false;         ///< response.iterations - 1 passes (at least 1)
  bool last_pass_no_corrections = false;  ///< the last pass's position corrections dropped
  /// Not a fault: a design.md section 6 engine that rounds differently (contact_impulse_other_rounding),
  /// so near-ties of the relaxation passes go other ways than in octocd's engines; the
  /// validators must pass it.
  bool other_rounding = false;

  /// Whether any field is set.
  bool any() const;
};

/// Paper Eq. 16-22 as octocd::contact_impulse (octocd/math.hpp), with two operations in
/// another, equally valid float order: J_n = -(1 + e)(v_n / (w_A + w_B)) and
/// t = v_t / |v_t| per component. Same units and conventions as contact_impulse.
ContactImpulse contact_impulse_other_rounding(Vec3 v_a, Vec3 v_b, float w_a, float w_b, Vec3 n,
                                              const ContactParams& p);

/// The `cpu` engine's step with `faults` planted (name() is "cpu": the validators judge
/// it as octocd's CPU engine, both tiers). Not thread-safe.
class FaultyWorld : public Engine {
 public:
  /// From a scene (build_model and the scene's broadphase, as World(scene)).
  FaultyWorld(const Scene& scene, const PlantedFaults& faults);
  /// From a built model (shared) and a broadphase (owned, not null), as World(model, bp).
  FaultyWorld(std::shared_ptr<const Model> model, std::unique_ptr<BroadPhase> broadphase,
              const PlantedFaults& faults);

  std::string name() const override { return "cpu"; }
  std::string device() const override { return "test build of the cpu engine with planted faults"; }
  std::string broadphase_name() const override { return broadphase_->name(); }
  const Model& model() const override { return *model_; }
  /// World::step's stages in order, with the planted faults.
  const FrameMetrics& step() override;
  const BodyState& state() const override { return state_; }
  const FrameMetrics& last_metrics() const override { return metrics_; }
  std::int64_t frame() const override { return frame_; }
  const std::vector<ContactRecord>& contacts() const override { return contacts_; }
  bool octocd_contacts() const override { return true; }
  bool can_record() const override { return true; }
  void set_recording(bool on) override { recording_ = on; }
  const FrameRecord& record() const override { return record_; }
  /// Replaces the hot state (sizes must equal the body count, else InputError).
  void set_state(const BodyState& state) override;

 private:
  /// The response stage (octocd::respond's passes) with the response faults.
  void respond_with_faults();

  std::shared_ptr<const Model> model_;
  PlantedFaults faults_;
  BodyState state_;
  std::unique_ptr<BroadPhase> broadphase_;
  std::vector<Aabb> aabbs_;
  std::vector<Pair> pairs_;
  std::vector<std::uint8_t> confirmed_;
  std::vector<ContactRecord> contacts_;
  ResponseScratch response_;
  FrameMetrics metrics_;
  std::int64_t frame_ = 0;
  bool recording_ = false;
  FrameRecord record_;
};

/// The product's World when no fault is planted (faults.any() false), else a FaultyWorld
/// with `faults`; from a built model (shared) and a broadphase (owned, not null).
std::unique_ptr<Engine> cpu_engine(std::shared_ptr<const Model> model, std::unique_ptr<BroadPhase> broadphase,
                                   const PlantedFaults& faults);
/// The same from a scene (build_model and the scene's broadphase).
std::unique_ptr<Engine> cpu_engine(const Scene& scene, const PlantedFaults& faults);

}  // namespace test
}  // namespace octocd
