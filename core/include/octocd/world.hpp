#pragma once
/// \file world.hpp
/// The CPU reference pipeline (design.md section 4): bodies in structure-of-arrays hot state,
/// shapes with their per-mesh octrees, and one step of named, timed stages (the stage
/// functions of octocd/stages.hpp, called in order).

#include <array>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "octocd/broadphase.hpp"
#include "octocd/engine.hpp"
#include "octocd/math.hpp"
#include "octocd/mesh.hpp"
#include "octocd/mesh_octree.hpp"
#include "octocd/midphase.hpp"
#include "octocd/scene.hpp"
#include "octocd/stages.hpp"

namespace octocd {

/// The cpu engine's settings (docs/settings.md, "The cpu engine"; `--cpu KEY=VALUE`).
struct CpuSettings {
  /// Threads of its parallel stages (midphase; the octree broadphase from 4096 bodies),
  /// on the process's worker team (octocd/parallel.hpp); 0: the caller's count
  /// (current_threads(): OMP_NUM_THREADS when set, else the CPUs this process may run on).
  /// 1 .. 4096 otherwise. Results do not depend on it.
  int threads = 0;
};

/// The CPU reference engine (`cpu`, design.md section 4): owns its hot state and the chosen
/// broadphase; shares the Model (shapes, bodies) it was built from.
class World : public Engine {
 public:
  /// Builds the model (build_model) and the scene's broadphase. Throws InputError for
  /// unreadable meshes, an unknown broadphase, or a rotating scene (scene_rotates: the
  /// cpu engine translates only, design.md section 3; require_translation_only names the key).
  explicit World(const Scene& scene);

  /// Same, with a broadphase made by the caller (e.g. a Bullet or FCL reference from
  /// make_any_broadphase). Takes ownership; `broadphase` must not be null.
  World(const Scene& scene, std::unique_ptr<BroadPhase> broadphase);

  /// From an already built model (shared, not copied), a broadphase (owned) and its
  /// settings. Throws InputError for a rotating scene (require_translation_only).
  World(std::shared_ptr<const Model> model, std::unique_ptr<BroadPhase> broadphase, CpuSettings settings = {});

  std::string name() const override { return "cpu"; }
  std::string device() const override;
  std::string broadphase_name() const override { return broadphase_->name(); }
  const Model& model() const override { return *model_; }
  /// Runs one step (design.md section 4) and returns its metrics. Throws RuntimeError naming the body
  /// and frame when a position or velocity becomes non-finite.
  const FrameMetrics& step() override;
  const BodyState& state() const override { return state_; }
  const FrameMetrics& last_metrics() const override { return metrics_; }
  std::int64_t frame() const override { return frame_; }
  /// Contacts of the last step's first response pass, in (a, b) order, with their impulses.
  const std::vector<ContactRecord>& contacts() const override { return contacts_; }
  bool octocd_contacts() const override { return true; }
  bool can_record() const override { return true; }
  void set_recording(bool on) override { recording_ = on; }
  const FrameRecord& record() const override { return record_; }
  /// Replaces the hot state (sizes must equal the body count, else InputError).
  void set_state(const BodyState& state) override;

  /// The shared model (e.g. to build another engine from the same bits).
  std::shared_ptr<const Model> shared_model() const { return model_; }
  /// Hot state (mutable: tests and validators set up states with it).
  BodyState& mutable_state() { return state_; }
  /// World AABBs as of the last step's Aabbs stage (before the response).
  const std::vector<Aabb>& world_aabbs() const { return aabbs_; }
  /// Broadphase pairs of the last step.
  const std::vector<Pair>& candidate_pairs() const { return pairs_; }
  /// The broadphase in use.
  const BroadPhase& broadphase() const { return *broadphase_; }

 private:
  std::shared_ptr<const Model> model_;
  BodyState state_;
  std::unique_ptr<BroadPhase> broadphase_;
  CpuSettings settings_;
  std::vector<Aabb> aabbs_;
  std::vector<Pair> pairs_;
  std::vector<std::uint8_t> confirmed_;  // per pair: midphase verdict
  std::vector<ContactRecord> contacts_;
  FrameMetrics metrics_;
  std::int64_t frame_ = 0;
  bool recording_ = false;
  FrameRecord record_;
  ResponseScratch response_;  // the response stage's buffers (design.md section 6 Jacobi reduction)
};

}  // namespace octocd
