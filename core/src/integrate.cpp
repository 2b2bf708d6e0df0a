// Per-body stages of the CPU step (design.md sections 4.1, 4.2, Eq. 23): integrate, world AABBs, clamp.
// The CUDA engine's gpu/src/integrate.cu runs the same OCTOCD_HD functions per thread.
#include "octocd/stages.hpp"

namespace octocd {

void integrate_bodies(BodyState& state, Vec3 gravity, float dt) {
  const std::size_t n = state.size();
  for (std::size_t i = 0; i < n; ++i) integrate(state.x[i], state.v[i], state.w[i], gravity, Vec3{}, dt);
}

void update_world_aabbs(const Model& model, const std::vector<Vec3>& x, std::vector<Aabb>& boxes) {
  const std::size_t n = x.size();
  for (std::size_t i = 0; i < n; ++i) boxes[i] = translated(model.local_box(i), x[i]);
}

void clamp_velocities(BodyState& state, float v_max) {
  const std::size_t n = state.size();
  for (std::size_t i = 0; i < n; ++i)
    if (state.w[i] != 0.0f) state.v[i] = clamp_velocity(state.v[i], v_max);
}

}  // namespace octocd
