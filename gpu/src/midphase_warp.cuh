#pragma once
// The midphase kernels' warp set-up (midphase.cuh): a pair's placed shapes and levels, lane and
// warp ids, the warp's counters and its aggregated appends to the work lists. CUDA only.
#include "kernels.hpp"
#include "octocd/vertex_blocks.hpp"

namespace octocd {
namespace gpu {
namespace mid {

constexpr unsigned kFull = 0xffffffffu;

__device__ inline hd::PlacedView place(const ShapesDesc& s, std::uint32_t shape, Vec3 x, const Aabb& box) {
  hd::PlacedView p;
  const DeviceShape& d = s.shapes[shape];
  p.is_mesh = d.is_mesh != 0;
  if (p.is_mesh) {
    p.octree.depth = d.depth;
    p.octree.bounds = d.bounds;
    p.octree.vertices = s.vertices + d.vertex_offset;
    p.octree.vertex_count = d.vertex_count;
    p.octree.cells = s.cells + d.cell_offset;
    p.octree.level_offset = s.level_offsets + d.level_offset_offset;
  }
  p.position = x;
  p.box = box;
  return p;
}

/// The two placed shapes of pair k and the test's set-up, A first (the mesh when one of
/// the two is a box: hd::setup_pair's order, chosen here on body indices so that the set-up
/// sees the ordered pair and no PlacedView is chosen by reference, which would put both in
/// local memory; `s.swap` is then false and the set-up is otherwise the one of the pair in
/// its own order: an aabb-only or box-box answer is symmetric).
struct PairContext {
  hd::PlacedView a, b;
  const Aabb* blocks_a = nullptr;  ///< A's vertex block boxes (mesh only)
  const Aabb* blocks_b = nullptr;  ///< B's vertex block boxes (mesh only)
  hd::PairSetup s;
  float theta = 0.0f;
  bool static_static = false;
};

__device__ inline PairContext context(const MidListDesc& d, std::uint32_t k, const Pair& p) {
  PairContext c;
  c.static_static = d.w[p.a] == 0.0f && d.w[p.b] == 0.0f;
  const std::uint32_t sa = d.shape[p.a];
  const std::uint32_t sb = d.shape[p.b];
  c.theta = pair_theta(d.shapes.theta[sa], d.shapes.theta[sb]);
  const bool swap = d.shapes.shapes[sa].is_mesh == 0;  // as setup_pair: (box, mesh) -> (mesh, box)
  const std::uint32_t ia = swap ? p.b : p.a;
  const std::uint32_t ib = swap ? p.a : p.b;
  const std::uint32_t s_a = swap ? sb : sa;
  const std::uint32_t s_b = swap ? sa : sb;
  c.a = place(d.shapes, s_a, d.x[ia], d.aabb[ia]);
  c.b = place(d.shapes, s_b, d.x[ib], d.aabb[ib]);
  c.s = hd::setup_pair(c.a, c.b, c.theta, d.levels);
  c.blocks_a = d.shapes.blocks + d.shapes.shapes[s_a].block_offset;
  c.blocks_b = d.shapes.blocks + d.shapes.shapes[s_b].block_offset;
  return c;
}

/// Step i's level of A (`of_b` false) or B in pair context c: hd::clamped_level (the entry
/// of c.s.la / c.s.lb, read without indexing those arrays at a run-time step, which would
/// put them in local memory).
__device__ inline int step_level(const MidListDesc& d, const PairContext& c, int i, bool of_b) {
  return hd::clamped_level(d.levels, i, of_b ? c.b.octree.depth : c.a.octree.depth);
}

__device__ inline std::uint32_t lane_id() { return threadIdx.x & 31u; }
__device__ inline std::uint32_t global_warp() { return (blockIdx.x * blockDim.x + threadIdx.x) >> 5; }
__device__ inline std::uint32_t warp_count() { return (gridDim.x * blockDim.x) >> 5; }

/// One warp's sums of the three counters (box tests, leaf box pairs, vertex tests) over
/// the items it runs: every value added is warp-uniform, so every lane holds the same sums;
/// `flush` adds them to d.counters once per warp and launch instead of one same-address
/// atomic per item (integer sums: the totals do not depend on the order).
struct Tally {
  unsigned long long box_tests = 0;
  unsigned long long box_pairs = 0;
  unsigned long long vertex_tests = 0;
  unsigned long long leaf_items = 0;  ///< the last expand step's leaf items (fuse_leaves)
};

/// Adds a warp's tally to d.counters (lane 0; every lane calls it).
__device__ inline void flush(const MidListDesc& d, const Tally& t) {
  if (lane_id() != 0) return;
  if (t.box_tests) atomicAdd(&d.counters[0], t.box_tests);
  if (t.box_pairs) atomicAdd(&d.counters[1], t.box_pairs);
  if (t.vertex_tests) atomicAdd(&d.counters[2], t.vertex_tests);
  if (t.leaf_items && d.leaf_items) atomicAdd(&d.leaf_items[1], t.leaf_items);
}

/// Warp-aggregated append of this lane's item when `keep` (every lane calls it).
__device__ inline void append(const MidListDesc& d, bool keep, const MidItem& item) {
  const unsigned mask = __ballot_sync(kFull, keep);
  if (mask == 0) return;
  std::uint32_t base = 0;
  if (lane_id() == 0) base = atomicAdd(d.out_count, static_cast<std::uint32_t>(__popc(mask)));
  base = __shfl_sync(kFull, base, 0);
  if (keep) {
    const std::uint32_t idx = base + static_cast<std::uint32_t>(__popc(mask & ((1u << lane_id()) - 1u)));
    if (idx < d.out_capacity) d.out[idx] = item;
  }
}

/// Warp-aggregated append of `cnt` copies of this lane's item, with chunk = 0 .. cnt - 1
/// (every lane calls it): lane l's copies at base + (the counts of lanes < l) + chunk. The
/// whole warp writes them, 32 at a time, not each lane its own in turn (a lane with a large
/// cell pair's leaf items would write them alone): a lane of at least 32 copies has them
/// written by the warp a round of 32 each, lane after lane; the copies of the other lanes
/// are spread over the lanes together (copy i: the first such lane whose inclusive count of
/// those copies exceeds i, found by a binary search over the lanes), so neither a few lanes
/// of many copies nor many lanes of a few take a search per 32 copies or a round per lane.
__device__ inline void append_chunks(const MidListDesc& d, std::uint32_t cnt, const MidItem& item) {
  if (__all_sync(kFull, cnt <= 1u)) {  // at most one copy per lane (small cells): as append
    append(d, cnt == 1u, item);         // (item.chunk is 0)
    return;
  }
  const std::uint32_t lane = lane_id();
  const bool big = cnt >= 32u;
  const std::uint32_t few = big ? 0u : cnt;  // the copies spread over the lanes together
  std::uint32_t incl = cnt;                  // inclusive counts over the lanes: all copies, and `few`
  std::uint32_t incl_few = few;
  for (int o = 1; o < 32; o <<= 1) {
    const std::uint32_t y = __shfl_up_sync(kFull, incl, o);
    const std::uint32_t z = __shfl_up_sync(kFull, incl_few, o);
    if (lane >= static_cast<std::uint32_t>(o)) {
      incl += y;
      incl_few += z;
    }
  }
  const std::uint32_t total = __shfl_sync(kFull, incl, 31);
  if (total == 0) return;
  std::uint32_t base = 0;
  if (lane == 0) base = atomicAdd(d.out_count, total);
  base = __shfl_sync(kFull, base, 0);
  const std::uint32_t excl = incl - cnt;  // this lane's first copy, from base
  for (unsigned many = __ballot_sync(kFull, big); many != 0u; many &= many - 1u) {
    const int owner = __ffs(many) - 1;
    MidItem copy;
    copy.k = __shfl_sync(kFull, item.k, owner);
    copy.ca = __shfl_sync(kFull, item.ca, owner);
    copy.cb = __shfl_sync(kFull, item.cb, owner);
    const std::uint32_t n_copies = __shfl_sync(kFull, cnt, owner);
    const std::uint32_t at = base + __shfl_sync(kFull, excl, owner);
    for (std::uint32_t c = lane; c < n_copies; c += 32) {
      copy.chunk = c;
      if (at + c < d.out_capacity) d.out[at + c] = copy;
    }
  }
  const std::uint32_t total_few = __shfl_sync(kFull, incl_few, 31);
  const std::uint32_t excl_few = incl_few - few;
  for (std::uint32_t i0 = 0; i0 < total_few; i0 += 32) {
    const std::uint32_t i = i0 + lane;
    int owner = 0;  // lanes whose inclusive count of `few` is <= i (non-decreasing over lanes)
    for (int step = 16; step > 0; step >>= 1)
      if (__shfl_sync(kFull, incl_few, owner + step - 1) <= i) owner += step;
    MidItem copy;
    copy.k = __shfl_sync(kFull, item.k, owner);
    copy.ca = __shfl_sync(kFull, item.ca, owner);
    copy.cb = __shfl_sync(kFull, item.cb, owner);
    copy.chunk = i - __shfl_sync(kFull, excl_few, owner);
    const std::uint32_t at = base + __shfl_sync(kFull, excl, owner) + copy.chunk;
    if (i < total_few && at < d.out_capacity) d.out[at] = copy;
  }
}

}  // namespace mid
}  // namespace gpu
}  // namespace octocd
