#pragma once
// The per-warp row of broadphase `flat` (design.md section 5.1, Eq. 6), shared by broadphase_flat.cu's
// counting and fill kernels and by the fused small-scene step (small_step.cu), which also
// walks the rows "backwards" (the bodies a < i meeting body i) to build its body-major
// contact index without a sort. CUDA only (nvcc).
#include "broadphase_common.cuh"
#include "kernels.hpp"

namespace octocd {
namespace gpu {

/// One warp tests the bodies j in [j0, j1) against `box` 32 at a time, in j order, with
/// the inclusive overlap of Eq. 6 (octocd::overlaps; `box_first`: overlaps(box, aabb[j]),
/// else overlaps(aabb[j], box), so a pair is always tested with its smaller index's box
/// first, as the row of that body tests it). Every hit is numbered in j order (0, 1, ...)
/// and passed to emit(number, j) by its lane; returns the hits (warp-uniform). Every lane
/// of the warp must call it with the same arguments (j0, j1 warp-uniform).
template <bool box_first, class Emit>
__device__ inline std::uint32_t flat_row(const Aabb* aabb, const Aabb& box, std::uint32_t j0, std::uint32_t j1,
                                         Emit&& emit) {
  const std::uint32_t lane = threadIdx.x & 31u;
  const Aabb own = box;  // in registers: `emit` may write memory that `box` could alias
  std::uint32_t found = 0;
  for (std::uint32_t b = j0; b < j1; b += 32) {
    const std::uint32_t j = b + lane;
    const bool hit = j < j1 && (box_first ? overlaps(own, aabb[j]) : overlaps(aabb[j], own));
    const unsigned mask = __ballot_sync(bp::kFullMask, hit);
    if (hit) emit(found + static_cast<std::uint32_t>(__popc(mask & ((1u << lane) - 1u))), j);
    found += static_cast<std::uint32_t>(__popc(mask));
  }
  return found;
}

/// Body i's pairs (i, j), j > i: counted into count[i] (keys == nullptr), or written as
/// keys (i << shift) | j in j order at keys[offset[i] ..] where below `capacity`. One warp.
__device__ inline void flat_pairs_of(const Aabb* aabb, std::uint32_t n, std::uint32_t i, std::uint32_t* count,
                                     const std::uint32_t* offset, unsigned long long* keys, std::uint32_t capacity,
                                     int shift) {
  const Aabb bi = aabb[i];
  const std::uint32_t o = keys ? offset[i] : 0u;
  const std::uint32_t found = flat_row<true>(aabb, bi, i + 1, n, [&](std::uint32_t r, std::uint32_t j) {
    if (keys && o + r < capacity) keys[o + r] = bp::pair_key(i, j, shift);
  });
  if (!keys && (threadIdx.x & 31u) == 0) count[i] = found;
}

}  // namespace gpu
}  // namespace octocd
