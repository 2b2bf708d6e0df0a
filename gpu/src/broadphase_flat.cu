// Broadphase `flat` on the device (design.md section 5.1, the device oracle): every pair (i, j), i < j,
// tested with the inclusive AABB overlap of Eq. 6 (octocd::overlaps). Counting pass, then
// an exclusive scan and a fill pass: body i writes its pair keys in j order at its scanned
// offset (those that fit the capacity; the total tells the host to regrow and rerun).
#include "broadphase_common.cuh"
#include "broadphase_flat.cuh"
#include "kernels.hpp"

namespace octocd {
namespace gpu {
namespace {


/// One warp per body i (grid-stride): flat_pairs_of (broadphase_flat.cuh), counting
/// (keys == nullptr) or writing the keys in j order from offset[i].
__global__ void flat_kernel(const Aabb* aabb, std::uint32_t n, std::uint32_t* count, const std::uint32_t* offset,
                            unsigned long long* keys, std::uint32_t capacity, int shift) {
  const std::uint32_t warps = (gridDim.x * blockDim.x) >> 5;
  for (std::uint32_t i = (blockIdx.x * blockDim.x + threadIdx.x) >> 5; i < n; i += warps)
    flat_pairs_of(aabb, n, i, count, offset, keys, capacity, shift);
}

}  // namespace

cudaError_t launch_flat_count(const Aabb* aabb, std::uint32_t n, std::uint32_t* count, cudaStream_t stream) {
  if (n == 0) return cudaSuccess;
  flat_kernel<<<bp::warp_grid_for(n), kBlockSize, 0, stream>>>(aabb, n, count, nullptr, nullptr, 0, 32);
  return cudaGetLastError();
}

cudaError_t launch_flat_fill(const Aabb* aabb, std::uint32_t n, const std::uint32_t* offset,
                             unsigned long long* keys, std::uint32_t capacity, int shift, cudaStream_t stream) {
  if (n == 0) return cudaSuccess;
  flat_kernel<<<bp::warp_grid_for(n), kBlockSize, 0, stream>>>(aabb, n, nullptr, offset, keys, capacity, shift);
  return cudaGetLastError();
}

}  // namespace gpu
}  // namespace octocd
