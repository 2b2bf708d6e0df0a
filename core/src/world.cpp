// The CPU reference engine: World::step runs the stages of octocd/stages.hpp in order
// (design.md section 4), times each and records the frame.
#include "octocd/world.hpp"

#include <chrono>
#include <utility>

#include <fmt/format.h>

#include "octocd/error.hpp"
#include "octocd/parallel.hpp"
#include "octocd/stages.hpp"
#include "octocd/version.hpp"

namespace octocd {

namespace {

using Clock = std::chrono::steady_clock;

double ms_since(Clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
}

template <class T>
std::uint64_t capacity_bytes(const std::vector<T>& v) {
  return static_cast<std::uint64_t>(v.capacity() * sizeof(T));
}

std::uint64_t octree_bytes(const MeshOctree& o) {
  return capacity_bytes(o.vertices) + capacity_bytes(o.original_index) + capacity_bytes(o.cells) +
         capacity_bytes(o.level_offset);
}

}  // namespace

World::World(const Scene& scene) : World(scene, make_broadphase(scene.broadphase, scene.domain)) {}

World::World(const Scene& scene, std::unique_ptr<BroadPhase> broadphase)
    : World(build_model(scene), std::move(broadphase)) {}

World::World(std::shared_ptr<const Model> model, std::unique_ptr<BroadPhase> broadphase, CpuSettings settings)
    : model_(std::move(model)), state_(model_->initial), broadphase_(std::move(broadphase)), settings_(settings) {
  if (!broadphase_) throw InputError("World: no broadphase given");
  require_translation_only(model_->scene, "cpu");  // design.md section 3: octocd's engines translate only
  aabbs_.resize(state_.size());
  update_world_aabbs(*model_, state_.x, aabbs_);
}

std::string World::device() const { return cpu_description(); }

const FrameMetrics& World::step() {
  const auto t_step = Clock::now();
  // The stages' loops run on settings_.threads threads (0: the caller's count).
  const ThreadCount threads(settings_.threads > 0 ? settings_.threads : current_threads());
  const Scene& scene = model_->scene;
  const Model& model = *model_;
  FrameMetrics m;
  m.frame = frame_ + 1;
  m.time = static_cast<double>(m.frame) * static_cast<double>(scene.dt);
  auto stage_ms = [&m](Stage s) -> double& { return m.stage_ms[static_cast<int>(s)]; };
  if (recording_) {
    record_.frame = m.frame;
    record_.x_pre = state_.x;
    record_.v_pre = state_.v;
  }

  // 1. Integrate (Eq. 1-3; integrate.cpp).
  auto t0 = Clock::now();
  integrate_bodies(state_, scene.gravity, scene.dt);
  stage_ms(Stage::Integrate) = ms_since(t0);

  // 2. World AABBs (design.md section 4.2; integrate.cpp).
  t0 = Clock::now();
  update_world_aabbs(model, state_.x, aabbs_);
  stage_ms(Stage::Aabbs) = ms_since(t0);

  // 3. Broadphase (design.md section 5.1; broadphase_*.cpp).
  t0 = Clock::now();
  BroadPhaseStats bp;
  broadphase_->find_pairs(aabbs_, pairs_, bp);
  m.cell_candidates = bp.cell_candidates;
  m.aabb_pairs = pairs_.size();
  stage_ms(Stage::Broadphase) = ms_since(t0);

  // 4. Midphase + narrow phase (design.md sections 5.2-5.3; midphase.cpp).
  t0 = Clock::now();
  confirm_pairs(model, state_, aabbs_, pairs_, confirmed_, m);
  stage_ms(Stage::Midphase) = ms_since(t0);

  // 5. Response (design.md section 6; response.cpp), then the clamp (Eq. 23; integrate.cpp).
  t0 = Clock::now();
  respond(model, state_, aabbs_, pairs_, confirmed_, scene.response, response_, contacts_);
  clamp_velocities(state_, scene.response.max_velocity);
  m.contacts = contacts_.size();
  stage_ms(Stage::Response) = ms_since(t0);

  // 6. Metrics and the NaN guard (metrics.cpp).
  t0 = Clock::now();
  frame_state_metrics(model, state_, contacts_, scene.response.slop, m);
  std::uint64_t bytes = capacity_bytes(state_.x) + capacity_bytes(state_.v) + capacity_bytes(state_.w) +
                        capacity_bytes(aabbs_) + capacity_bytes(pairs_) + capacity_bytes(confirmed_) +
                        capacity_bytes(contacts_) + response_.memory_bytes() + bp.memory_bytes;
  for (const Shape& s : model_->shapes)
    if (s.octree) bytes += octree_bytes(*s.octree);
  m.memory_bytes = bytes;
  stage_ms(Stage::Metrics) = ms_since(t0);

  if (recording_) {
    record_.aabbs = aabbs_;
    record_.pairs = pairs_;
    record_.confirmed.clear();
    for (std::size_t k = 0; k < pairs_.size(); ++k)
      if (confirmed_[k]) record_.confirmed.push_back(pairs_[k]);
    record_.contacts = contacts_;
    record_.x_post = state_.x;
    record_.v_post = state_.v;
  }

  m.step_ms = ms_since(t_step);
  frame_ = m.frame;
  metrics_ = m;
  return metrics_;
}

void World::set_state(const BodyState& s) {
  const std::size_t n = state_.size();
  if (s.x.size() != n || s.v.size() != n || s.w.size() != n)
    throw InputError(fmt::format("World::set_state: expected {} bodies, got x {}, v {}, w {}", n, s.x.size(),
                                 s.v.size(), s.w.size()));
  state_ = s;
}

}  // namespace octocd
