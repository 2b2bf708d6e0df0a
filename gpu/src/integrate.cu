// Per-body stages of the CUDA step (design.md sections 4.1, 4.2, Eq. 23): integrate, world AABBs, clamp.
// Each thread calls the same OCTOCD_HD function World::step calls for its body, through
// the per-body functions of integrate.cuh (which the fused small step calls too).
#include "integrate.cuh"
#include "kernels.hpp"

namespace octocd {
namespace gpu {
namespace {

__global__ void integrate_kernel(BodiesDesc b, Vec3 gravity, float dt) {
  const std::uint32_t i = blockIdx.x * blockDim.x + threadIdx.x;
  if (i >= b.n) return;
  integrate_body(b, i, gravity, dt);
}

__global__ void aabbs_kernel(BodiesDesc b) {
  const std::uint32_t i = blockIdx.x * blockDim.x + threadIdx.x;
  if (i >= b.n) return;
  aabb_body(b, i);
}

__global__ void clamp_kernel(BodiesDesc b, float v_max) {
  const std::uint32_t i = blockIdx.x * blockDim.x + threadIdx.x;
  if (i >= b.n) return;
  clamp_body(b, i, v_max);
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
