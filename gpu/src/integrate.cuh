#pragma once
// Per-body device code of integrate.cu (design.md sections 4.1, 4.2, Eq. 23): one call per body, shared
// by the per-stage kernels (integrate.cu) and the fused small-scene step (small_step.cu).
// Each calls the same OCTOCD_HD function World::step calls for its body. CUDA only (nvcc).
#include "kernels.hpp"

namespace octocd {
namespace gpu {

/// Eq. 1-3 for body i (octocd::integrate, no external force), keeping the state before
/// the step in x_saved / v_saved when they are set (for a rerun after a buffer overflow).
__device__ inline void integrate_body(const BodiesDesc& b, std::uint32_t i, Vec3 gravity, float dt) {
  Vec3 x = b.x[i];
  Vec3 v = b.v[i];
  if (b.x_saved) {
    b.x_saved[i] = x;
    b.v_saved[i] = v;
  }
  integrate(x, v, b.w[i], gravity, Vec3{}, dt);
  b.x[i] = x;
  b.v[i] = v;
}

/// Eq. 1-3 for body i from the state (x0, v0) into (x, v), stored nowhere: the fused
/// small step's front (small_step.cu), whose every block integrates every body from the
/// saved state into its shared memory. The same call as integrate_body, so the same bits.
__device__ inline void integrated(const BodiesDesc& b, std::uint32_t i, Vec3 x0, Vec3 v0, Vec3 gravity, float dt,
                                  Vec3& x, Vec3& v) {
  x = x0;
  v = v0;
  integrate(x, v, b.w[i], gravity, Vec3{}, dt);
}

/// Body i's world AABB: translated(local, x).
__device__ inline void aabb_body(const BodiesDesc& b, std::uint32_t i) { b.aabb[i] = translated(b.local[i], b.x[i]); }

/// Eq. 23 for body i when it is dynamic.
__device__ inline void clamp_body(const BodiesDesc& b, std::uint32_t i, float v_max) {
  if (b.w[i] != 0.0f) b.v[i] = clamp_velocity(b.v[i], v_max);
}

}  // namespace gpu
}  // namespace octocd
