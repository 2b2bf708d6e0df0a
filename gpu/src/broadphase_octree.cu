// Broadphase `octree` on the device: the loose octree of SPEC 5.1 (Ulrich 2000, looseness
// 2) with every cell and level decision from octocd/loose_octree.hpp, the header the CPU
// driver (core/src/broadphase_octree.cpp) uses. Steps (orchestrated by cuda_world.cpp):
// 1. keys: D_w (the scene's, or `auto` from the smallest body extent, a CUB minimum),
//    then per body loose_place_unit -> (level, Morton cell) key, the overflow key, or the
//    NaN key; its unit box in fixed point (loose_q_min / loose_q_max);
// 2. a stable radix sort by key: slot order = (key, body), so every occupied cell is a
//    contiguous run of slots and the levels follow each other in key order;
// 3. a query per slot, counting then filling at scanned offsets:
//    - a body in a cell (level l) looks at every level m <= l that holds bodies: the
//      cells whose loose boxes meet its own box (loose_query_axis_q: at most 4 per axis),
//      each found by binary search in the sorted keys; at m = l it keeps only slots after
//      its own, at m < l every body;
//    - an overflow body tests every in-tree body and the overflow bodies after it;
//    then the exact AABB test (octocd::overlaps, Eq. 6). Each overlapping pair is met
//    exactly once (same level: by the smaller slot; across levels: by the finer body;
//    with the overflow list: by the overflow body), because a body's box lies in its
//    cell's loose box and the query ranges are exact;
// 4. the pairs, as keys (a << 32) | b, are radix-sorted: the sorted unique set `flat`
//    gives.
#include "kernels.hpp"

namespace octocd {
namespace gpu {
namespace {

__global__ void loose_extent_kernel(LooseDesc d) {
  const std::uint32_t i = blockIdx.x * blockDim.x + threadIdx.x;
  if (i >= d.n) return;
  const Aabb b = d.aabb[i];
  float ext = loose_unit_extent(loose_unit(d.grid, b.min), loose_unit(d.grid, b.max));
  ext = ext < 0.0f ? 0.0f : ext;
  // As the CPU driver: NaN extents are left out of the minimum.
  d.extent[i] = ext != ext ? __int_as_float(0x7f800000) : ext;
}

__global__ void loose_keys_kernel(LooseDesc d) {
  const std::uint32_t i = blockIdx.x * blockDim.x + threadIdx.x;
  if (i >= d.n) return;
  const int depth = d.depth >= 0 ? d.depth : loose_auto_depth(*d.min_extent);
  const Aabb b = d.aabb[i];
  d.body[i] = i;
  LooseQBox q{};
  if (loose_has_nan(b)) {
    d.key[i] = kLooseNoKey;
    d.q[i] = q;
    return;
  }
  const Vec3 lo = loose_unit(d.grid, b.min);
  const Vec3 hi = loose_unit(d.grid, b.max);
  d.key[i] = loose_place_key(loose_place_unit(lo, hi, depth));
  q.lo[0] = static_cast<std::int16_t>(loose_q_min(lo.x));
  q.lo[1] = static_cast<std::int16_t>(loose_q_min(lo.y));
  q.lo[2] = static_cast<std::int16_t>(loose_q_min(lo.z));
  q.hi[0] = static_cast<std::int16_t>(loose_q_max(hi.x));
  q.hi[1] = static_cast<std::int16_t>(loose_q_max(hi.y));
  q.hi[2] = static_cast<std::int16_t>(loose_q_max(hi.z));
  d.q[i] = q;
}

__global__ void loose_gather_kernel(LooseDesc d) {
  const std::uint32_t s = blockIdx.x * blockDim.x + threadIdx.x;
  if (s >= d.n) return;
  const std::uint32_t body = d.slot_body[s];
  d.slot_box[s] = d.aabb[body];
  d.slot_q[s] = d.q[body];
}

/// First slot in [lo, hi) whose key is >= key.
__device__ std::uint32_t lower_bound(const std::uint32_t* keys, std::uint32_t lo, std::uint32_t hi,
                                     std::uint32_t key) {
  while (lo < hi) {
    const std::uint32_t mid = lo + (hi - lo) / 2;
    if (keys[mid] < key) lo = mid + 1;
    else hi = mid;
  }
  return lo;
}

/// Tests slot s against slot t; counts or writes the pair (by body index, a < b).
struct Emitter {
  const LooseDesc& d;
  bool fill;
  std::uint32_t found = 0;
  unsigned long long tests = 0;
  std::uint32_t body_s;
  Aabb box_s;
  unsigned long long* out = nullptr;

  __device__ void test(std::uint32_t t) {
    ++tests;
    if (!overlaps(box_s, d.slot_box[t])) return;
    if (fill) {
      const std::uint32_t body_t = d.slot_body[t];
      const std::uint32_t a = body_s < body_t ? body_s : body_t;
      const std::uint32_t b = body_s < body_t ? body_t : body_s;
      out[found] = (static_cast<unsigned long long>(a) << 32) | b;
    }
    ++found;
  }
};

__global__ void loose_query_kernel(LooseDesc d, bool fill) {
  const std::uint32_t s = blockIdx.x * blockDim.x + threadIdx.x;
  if (s >= d.n) return;
  const std::uint32_t key = d.sorted_key[s];
  Emitter e{d, fill};
  e.body_s = d.slot_body[s];
  e.box_s = d.slot_box[s];
  if (fill) e.out = d.pair_keys + d.offset[s];
  if (key == kLooseNoKey) {  // a NaN box overlaps nothing
    if (!fill) d.count[s] = 0;
    return;
  }
  const std::uint32_t overflow_begin = lower_bound(d.sorted_key, 0, d.n, kLooseOverflowKey);
  if (key == kLooseOverflowKey) {
    const std::uint32_t used = lower_bound(d.sorted_key, overflow_begin, d.n, kLooseNoKey);
    for (std::uint32_t t = 0; t < overflow_begin; ++t) e.test(t);
    for (std::uint32_t t = s + 1; t < used; ++t) e.test(t);
  } else {
    const int level = loose_key_level(key);
    const LooseQBox q = d.slot_q[s];
    for (int m = 0; m <= level; ++m) {
      // The slots of level m: [first key of m, first key of m + 1).
      const std::uint32_t lv_begin = lower_bound(d.sorted_key, 0, overflow_begin, loose_level_base(m));
      const std::uint32_t lv_end = m < kLooseMaxDepth
                                       ? lower_bound(d.sorted_key, lv_begin, overflow_begin, loose_level_base(m + 1))
                                       : overflow_begin;
      if (lv_begin == lv_end) continue;  // no body at this level
      const LooseRange rx = loose_query_axis_q(q.lo[0], q.hi[0], m);
      const LooseRange ry = loose_query_axis_q(q.lo[1], q.hi[1], m);
      const LooseRange rz = loose_query_axis_q(q.lo[2], q.hi[2], m);
      for (int iz = rz.lo; iz <= rz.hi; ++iz) {
        for (int iy = ry.lo; iy <= ry.hi; ++iy) {
          for (int ix = rx.lo; ix <= rx.hi; ++ix) {
            const std::uint32_t ck = loose_cell_key(m, static_cast<std::uint32_t>(ix), static_cast<std::uint32_t>(iy),
                                                    static_cast<std::uint32_t>(iz));
            std::uint32_t t = lower_bound(d.sorted_key, lv_begin, lv_end, ck);
            if (m == level && t <= s) t = s + 1;  // same level: only the slots after s
            for (; t < lv_end && d.sorted_key[t] == ck; ++t) e.test(t);
          }
        }
      }
    }
  }
  if (!fill) {
    d.count[s] = e.found;
    if (e.tests) atomicAdd(d.candidates, e.tests);
  }
}

__global__ void unpack_pairs_kernel(const unsigned long long* keys, std::uint32_t count, Pair* pairs) {
  const std::uint32_t k = blockIdx.x * blockDim.x + threadIdx.x;
  if (k >= count) return;
  const unsigned long long v = keys[k];
  Pair p;
  p.a = static_cast<std::uint32_t>(v >> 32);
  p.b = static_cast<std::uint32_t>(v & 0xffffffffull);
  pairs[k] = p;
}

}  // namespace

cudaError_t launch_loose_extent(const LooseDesc& d, cudaStream_t stream) {
  if (d.n == 0) return cudaSuccess;
  loose_extent_kernel<<<grid_for(d.n), kBlockSize, 0, stream>>>(d);
  return cudaGetLastError();
}

cudaError_t launch_loose_keys(const LooseDesc& d, cudaStream_t stream) {
  if (d.n == 0) return cudaSuccess;
  loose_keys_kernel<<<grid_for(d.n), kBlockSize, 0, stream>>>(d);
  return cudaGetLastError();
}

cudaError_t launch_loose_gather(const LooseDesc& d, cudaStream_t stream) {
  if (d.n == 0) return cudaSuccess;
  loose_gather_kernel<<<grid_for(d.n), kBlockSize, 0, stream>>>(d);
  return cudaGetLastError();
}

cudaError_t launch_loose_query(const LooseDesc& d, bool fill, cudaStream_t stream) {
  if (d.n == 0) return cudaSuccess;
  loose_query_kernel<<<grid_for(d.n), kBlockSize, 0, stream>>>(d, fill);
  return cudaGetLastError();
}

cudaError_t launch_unpack_pairs(const unsigned long long* keys, std::uint32_t count, Pair* pairs,
                                cudaStream_t stream) {
  if (count == 0) return cudaSuccess;
  unpack_pairs_kernel<<<grid_for(count), kBlockSize, 0, stream>>>(keys, count, pairs);
  return cudaGetLastError();
}

}  // namespace gpu
}  // namespace octocd
