// Per-body stages of the CUDA step (SPEC 4.1, 4.2, Eq. 23): integrate, world AABBs, clamp.
// Each thread calls the same OCTOCD_HD function World::step calls for its body.
#include "kernels.hpp"

namespace octocd {
namespace gpu {
namespace {

__global__ void integrate_kernel(BodiesDesc b, Vec3 gravity, float dt) {
  const std::uint32_t i = blockIdx.x * blockDim.x + threadIdx.x;
  if (i >= b.n) return;
  Vec3 x = b.x[i];
  Vec3 v = b.v[i];
  if (b.x_saved) {  // the state before the step, for a rerun after a buffer overflow
    b.x_saved[i] = x;
    b.v_saved[i] = v;
  }
  integrate(x, v, b.w[i], gravity, Vec3{}, dt);
  b.x[i] = x;
  b.v[i] = v;
}

__global__ void aabbs_kernel(BodiesDesc b) {
  const std::uint32_t i = blockIdx.x * blockDim.x + threadIdx.x;
  if (i >= b.n) return;
  b.aabb[i] = translated(b.local[i], b.x[i]);
}

__global__ void clamp_kernel(BodiesDesc b, float v_max) {
  const std::uint32_t i = blockIdx.x * blockDim.x + threadIdx.x;
  if (i >= b.n) return;
  if (b.w[i] != 0.0f) b.v[i] = clamp_velocity(b.v[i], v_max);
}

}  // namespace

cudaError_t launch_integrate(const BodiesDesc& b, Vec3 gravity, float dt, cudaStream_t stream) {
  if (b.n == 0) return cudaSuccess;
  integrate_kernel<<<grid_for(b.n), kBlockSize, 0, stream>>>(b, gravity, dt);
  return cudaGetLastError();
}

cudaError_t launch_aabbs(const BodiesDesc& b, cudaStream_t stream) {
  if (b.n == 0) return cudaSuccess;
  aabbs_kernel<<<grid_for(b.n), kBlockSize, 0, stream>>>(b);
  return cudaGetLastError();
}

cudaError_t launch_clamp(const BodiesDesc& b, float v_max, cudaStream_t stream) {
  if (b.n == 0) return cudaSuccess;
  clamp_kernel<<<grid_for(b.n), kBlockSize, 0, stream>>>(b, v_max);
  return cudaGetLastError();
}

}  // namespace gpu
}  // namespace octocd
