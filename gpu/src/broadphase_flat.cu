// Broadphase `flat` on the device (SPEC 5.1, the device oracle): every pair (i, j), i < j,
// tested with the inclusive AABB overlap of Eq. 6 (octocd::overlaps). Counting pass, then
// (on the host side) an exclusive scan and a fill pass: body i writes its pairs in j order
// at its scanned offset, so the output is the sorted unique pair set, never truncated.
#include "kernels.hpp"

namespace octocd {
namespace gpu {
namespace {

__global__ void flat_count_kernel(const Aabb* aabb, std::uint32_t n, std::uint32_t* count) {
  const std::uint32_t i = blockIdx.x * blockDim.x + threadIdx.x;
  if (i >= n) return;
  const Aabb bi = aabb[i];
  std::uint32_t c = 0;
  for (std::uint32_t j = i + 1; j < n; ++j) c += overlaps(bi, aabb[j]) ? 1u : 0u;
  count[i] = c;
}

__global__ void flat_fill_kernel(const Aabb* aabb, std::uint32_t n, const std::uint32_t* offset, Pair* pairs) {
  const std::uint32_t i = blockIdx.x * blockDim.x + threadIdx.x;
  if (i >= n) return;
  const Aabb bi = aabb[i];
  std::uint32_t o = offset[i];
  for (std::uint32_t j = i + 1; j < n; ++j) {
    if (overlaps(bi, aabb[j])) {
      Pair p;
      p.a = i;
      p.b = j;
      pairs[o++] = p;
    }
  }
}

}  // namespace

cudaError_t launch_flat_count(const Aabb* aabb, std::uint32_t n, std::uint32_t* count, cudaStream_t stream) {
  if (n == 0) return cudaSuccess;
  flat_count_kernel<<<grid_for(n), kBlockSize, 0, stream>>>(aabb, n, count);
  return cudaGetLastError();
}

cudaError_t launch_flat_fill(const Aabb* aabb, std::uint32_t n, const std::uint32_t* offset, Pair* pairs,
                             cudaStream_t stream) {
  if (n == 0) return cudaSuccess;
  flat_fill_kernel<<<grid_for(n), kBlockSize, 0, stream>>>(aabb, n, offset, pairs);
  return cudaGetLastError();
}

}  // namespace gpu
}  // namespace octocd
