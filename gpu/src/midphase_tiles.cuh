#pragma once
// The midphase's vertex tiles (midphase.cuh): vertex blocks staged in shared memory, the
// early exit and tile switches, confirming a pair, and the tests of two tiles (close, witness,
// apart). CUDA only.
#include "midphase_warp.cuh"

namespace octocd {
namespace gpu {
namespace mid {

/// Filtered vertices one warp stages in shared memory per tile (each of A and B).
constexpr std::uint32_t kLeafTile = 128;
constexpr int kWarpsPerBlock = kBlockSize / 32;

static_assert(kVertexBlock == 32, "one lane per vertex of a block (mesh_octree.hpp)");

/// The vertex blocks of v[begin, end): blocks [begin / 32, block_end(end)) of the shape's
/// vertex_block_boxes (the first and last may hold vertices outside the range).
__device__ inline std::uint32_t block_end(std::uint32_t end) { return (end + kVertexBlock - 1) / kVertexBlock; }

/// Bit l: block g0 + l (< g1) has a box overlapping `box` (lane l tests it): the blocks
/// that may hold a vertex inside `box` (vertex_block_boxes), the others are skipped.
__device__ inline unsigned blocks_overlapping(const Aabb* blocks, std::uint32_t g0, std::uint32_t g1, const Aabb& box) {
  const std::uint32_t g = g0 + lane_id();
  return __ballot_sync(kFull, g < g1 && overlaps(blocks[g], box));
}

/// Ballot of the lanes whose vertex of block g (vertex g * 32 + lane) is in [begin, end)
/// and inside `box`; j is the lane's vertex.
__device__ inline unsigned block_inside(const Vec3* v, std::uint32_t g, std::uint32_t begin, std::uint32_t end,
                                        const Aabb& box, std::uint32_t& j) {
  j = g * kVertexBlock + lane_id();
  return __ballot_sync(kFull, j >= begin && j < end && hd::inside(v[j], box));
}

/// The number of vertices of v[begin, end) inside `box` (warp-uniform), whole blocks of
/// 32 vertices skipped when their box misses `box`.
__device__ inline std::uint32_t count_inside(const Vec3* v, const Aabb* blocks, std::uint32_t begin,
                                             std::uint32_t end, const Aabb& box) {
  std::uint32_t n = 0;
  const std::uint32_t g1 = block_end(end);
  for (std::uint32_t g0 = begin / kVertexBlock; g0 < g1; g0 += 32) {
    unsigned m = blocks_overlapping(blocks, g0, g1, box);
    while (m) {
      const std::uint32_t g = g0 + static_cast<std::uint32_t>(__ffs(m) - 1);
      m &= m - 1u;
      std::uint32_t j;
      n += static_cast<std::uint32_t>(__popc(block_inside(v, g, begin, end, box, j)));
    }
  }
  return n;
}

/// Appends to tile[fill ..] the world positions of the vertices of v[begin, end) inside
/// `box`, in order, and to ids[fill ..] their indices (ids may be null), from vertex block `pos` on (blocks
/// whose box misses `box` skipped, the lanes test a block's 32 vertices at once) until the
/// blocks end or a further 32 might not fit; advances pos (a block index) and fill
/// (warp-uniform).
__device__ inline void stage_tile(const Vec3* v, const Aabb* blocks, std::uint32_t begin, std::uint32_t end,
                                  const Aabb& box, Vec3 position, Vec3* tile, std::uint32_t* ids, std::uint32_t& pos,
                                  std::uint32_t& fill) {
  const std::uint32_t lane = lane_id();
  const std::uint32_t g1 = block_end(end);
  while (pos < g1 && fill + 32 <= kLeafTile) {
    unsigned m = blocks_overlapping(blocks, pos, g1, box);
    std::uint32_t next = pos + 32;  // past the blocks tested
    while (m) {
      const std::uint32_t g = pos + static_cast<std::uint32_t>(__ffs(m) - 1);
      if (fill + 32 > kLeafTile) {  // resume at block g
        next = g;
        break;
      }
      m &= m - 1u;
      std::uint32_t j;
      const unsigned mask = block_inside(v, g, begin, end, box, j);
      if ((mask >> lane) & 1u) {
        const std::uint32_t at = fill + static_cast<std::uint32_t>(__popc(mask & ((1u << lane) - 1u)));
        tile[at] = hd::world_vertex(v[j], position);
        if (ids != nullptr) ids[at] = j;
      }
      fill += static_cast<std::uint32_t>(__popc(mask));
    }
    pos = next;
  }
  __syncwarp();
}

/// d's early exit, tile culling and tile filter (MidListDesc), all off with kLean: the fused
/// step's lean kernel, where they are constants and their code is dropped.
template <bool kLean>
__device__ inline bool exit_on(const MidListDesc& d) {
  return !kLean && d.early_exit != 0;
}
/// d's tile culling (exit_on).
template <bool kLean>
__device__ inline bool cull_on(const MidListDesc& d) {
  return !kLean && d.tile_cull != 0;
}
/// d's tile filter (exit_on).
template <bool kLean>
__device__ inline bool filter_on(const MidListDesc& d) {
  return !kLean && d.tile_filter != 0;
}

__device__ inline bool pair_confirmed(const MidListDesc& d, std::uint32_t k) {
  return *(volatile const std::uint8_t*)(d.confirmed + k) != 0;
}

/// pair_confirmed as one warp-uniform value (lane 0 reads, every lane gets it).
__device__ inline bool confirmed_now(const MidListDesc& d, std::uint32_t k) {
  return __shfl_sync(kFull, lane_id() == 0 ? static_cast<int>(pair_confirmed(d, k)) : 0, 0) != 0;
}

/// With the early exit on (d.early_exit), whether pair k is already confirmed, so that the
/// rest of its work can be skipped (warp-uniform: one load by lane 0); false with it off.
template <bool kLean = false>
__device__ inline bool skip_confirmed(const MidListDesc& d, std::uint32_t k) {
  return exit_on<kLean>(d) && confirmed_now(d, k);
}

/// Confirms pair k (one thread), found by the vertex pair `witness` (WitnessDesc::witness),
/// kept when the witness cache is on.
__device__ inline void confirm(const MidListDesc& d, std::uint32_t k, unsigned long long witness) {
  d.confirmed[k] = 1;
  if (d.wit.witness != nullptr) d.wit.witness[k] = witness;
}

/// Whether some vertex of tile_a[0, na) and some vertex of tile_b[0, nb) are closer than
/// theta (hd::vertex_close; the whole warp, warp-uniform result): every one of the na x nb
/// pairs is tested unless a close pair ends the scan early (checked every 16 rounds: the
/// same answer, less work when the meshes are in contact). Lanes: with nb <= 16, lane l
/// takes B vertex l % P (P: nb rounded up to a power of two) and A vertices l / P,
/// l / P + 32 / P, ... (so a small B tile keeps all 32 lanes busy); otherwise lane l takes
/// B vertices l, l + 32, ... against every A vertex.
__device__ inline bool tiles_close(const Vec3* tile_a, std::uint32_t na, const Vec3* tile_b, std::uint32_t nb,
                                   float theta2) {
  const std::uint32_t lane = lane_id();
  bool found = false;
  if (nb <= 16) {
    const std::uint32_t p = nb <= 1 ? 1u : 1u << (32 - __clz(static_cast<int>(nb - 1)));  // 1, 2, 4, 8 or 16
    const std::uint32_t groups = 32u / p;
    const std::uint32_t j = lane % p;
    const bool valid = j < nb;
    const Vec3 wb = tile_b[valid ? j : 0u];
    bool hit = false;
    for (std::uint32_t i0 = 0; i0 < na && !found; i0 += 16u * groups) {
      const std::uint32_t i1 = i0 + 16u * groups < na ? i0 + 16u * groups : na;
      for (std::uint32_t ii = i0 + lane / p; ii < i1; ii += groups)
        hit = hit || (valid && hd::vertex_close(tile_a[ii], wb, theta2));
      found = __any_sync(kFull, hit);
    }
    return found;
  }
  for (std::uint32_t jj0 = 0; jj0 < nb && !found; jj0 += 32) {
    const bool valid = jj0 + lane < nb;
    const Vec3 wb = tile_b[valid ? jj0 + lane : 0u];
    bool hit = false;
    for (std::uint32_t i0 = 0; i0 < na && !found; i0 += 16) {
      const std::uint32_t i1 = i0 + 16 < na ? i0 + 16 : na;
      for (std::uint32_t ii = i0; ii < i1; ++ii) hit = hit || (valid && hd::vertex_close(tile_a[ii], wb, theta2));
      found = __any_sync(kFull, hit);
    }
  }
  return found;
}

/// The witness of two tiles that tiles_close found close (the whole warp; warp-uniform):
/// the vertex ids (ids_a, ids_b: the staged vertices' indices) of the first close pair in
/// B's tile order, then A's. Run once per confirming tile pair, so the scan of tiles_close
/// keeps no positions.
__device__ inline unsigned long long tiles_witness(const Vec3* tile_a, const std::uint32_t* ids_a, std::uint32_t na,
                                                   const Vec3* tile_b, const std::uint32_t* ids_b, std::uint32_t nb,
                                                   float theta2) {
  for (std::uint32_t j0 = 0; j0 < nb; j0 += 32) {
    const std::uint32_t j = j0 + lane_id();
    std::uint32_t at = na;  // the first A vertex close to B vertex j
    if (j < nb) {
      const Vec3 wb = tile_b[j];
      for (std::uint32_t i = 0; i < na && at == na; ++i)
        if (hd::vertex_close(tile_a[i], wb, theta2)) at = i;
    }
    const unsigned close = __ballot_sync(kFull, at < na);
    if (close != 0) {
      const int l = __ffs(close) - 1;
      const std::uint32_t ia = __shfl_sync(kFull, at, l);
      return (static_cast<unsigned long long>(ids_a[ia]) << 32) | ids_b[j0 + static_cast<std::uint32_t>(l)];
    }
  }
  return kNoWitness;  // (not reached after tiles_close)
}

/// The bounding box of the world vertices tile[0, n) (the whole warp; warp-uniform result;
/// n >= 1): exact minima and maxima, no rounding.
__device__ inline Aabb tile_box(const Vec3* tile, std::uint32_t n) {
  Vec3 lo = tile[0], hi = tile[0];
  for (std::uint32_t i = lane_id(); i < n; i += 32) {
    const Vec3 v = tile[i];
    lo = {fminf(lo.x, v.x), fminf(lo.y, v.y), fminf(lo.z, v.z)};
    hi = {fmaxf(hi.x, v.x), fmaxf(hi.y, v.y), fmaxf(hi.z, v.z)};
  }
  for (int o = 16; o > 0; o >>= 1) {
    lo.x = fminf(lo.x, __shfl_xor_sync(kFull, lo.x, o));
    lo.y = fminf(lo.y, __shfl_xor_sync(kFull, lo.y, o));
    lo.z = fminf(lo.z, __shfl_xor_sync(kFull, lo.z, o));
    hi.x = fmaxf(hi.x, __shfl_xor_sync(kFull, hi.x, o));
    hi.y = fmaxf(hi.y, __shfl_xor_sync(kFull, hi.y, o));
    hi.z = fmaxf(hi.z, __shfl_xor_sync(kFull, hi.z, o));
  }
  return {lo, hi};
}

/// Whether the coordinates on one axis of every vertex of one set are >= `lo` and of every
/// vertex of the other set <= `hi` with a gap g = lo - hi (in float) > 0 and g * g >= theta2:
/// then no pair of the two is within theta as hd::vertex_close computes it. Exact: rounding
/// is monotone, so each pair's |dx| = |fl(wa.x - wb.x)| >= g, fl(dx * dx) >= fl(g * g), and
/// adding the other (non-negative) squares never lowers the sum below that (no FMA:
/// --fmad=false), so the sum is >= theta2 and vertex_close(wa, wb) is false.
__device__ inline bool axis_apart(float lo, float hi, float theta2) {
  const float g = lo - hi;
  return g > 0.0f && g * g >= theta2;
}

/// Whether two tiles' boxes (tile_box) are apart by theta on some axis (axis_apart): then
/// tiles_close on them is false, and the tile pair is skipped (the same answer).
__device__ inline bool tiles_apart(const Aabb& a, const Aabb& b, float theta2) {
  return axis_apart(b.min.x, a.max.x, theta2) || axis_apart(a.min.x, b.max.x, theta2) ||
         axis_apart(b.min.y, a.max.y, theta2) || axis_apart(a.min.y, b.max.y, theta2) ||
         axis_apart(b.min.z, a.max.z, theta2) || axis_apart(a.min.z, b.max.z, theta2);
}

/// The part of `box` (A's filter box b_in_a, in A's frame) that can hold a vertex of A
/// within theta of a vertex of the world box `tile` (a staged tile of B, tile_box): `tile`
/// moved into A's frame (minus pa) and grown by `margin` (theta + midphase_tolerance),
/// intersected with `box`. Conservative as moved_back_grown: if vertex_close(wa, wb) with
/// wa = world_vertex(va, pa) and wb in `tile`, then on each axis |wa - wb| < theta up to a
/// few roundings of the magnitudes |pa|, |pb|, |A.bounds|, |B.bounds| (those of
/// wa, wb and pa), far below the tolerance (1e-5 of them: about 170 float ulps), so va is
/// inside the result. A leaf stages for a tile of B only A's vertices inside it (whole vertex
/// blocks skipped by their boxes), not every vertex inside b_in_a: the same answer, since a
/// vertex outside it is close to no vertex of the tile. May be empty (box_empty).
__device__ inline Aabb near_tile(const Aabb& box, const Aabb& tile, Vec3 pa, float margin) {
  return {{fmaxf(box.min.x, tile.min.x - pa.x - margin), fmaxf(box.min.y, tile.min.y - pa.y - margin),
           fmaxf(box.min.z, tile.min.z - pa.z - margin)},
          {fminf(box.max.x, tile.max.x - pa.x + margin), fminf(box.max.y, tile.max.y - pa.y + margin),
           fminf(box.max.z, tile.max.z - pa.z + margin)}};
}

/// Whether `b` holds no point (min > max on some axis; hd::inside is false for every point).
__device__ inline bool box_empty(const Aabb& b) {
  return b.min.x > b.max.x || b.min.y > b.max.y || b.min.z > b.max.z;
}

/// Shared memory of mid_leaf_items and of the last mid_expand step when it runs the
/// leaves itself: per warp of the block, a tile of B's and one of A's filtered world
/// vertices ([w][0]: B, [w][1]: A) and each one's vertex index (the witness).
struct LeafTiles {
  Vec3 v[kWarpsPerBlock][2][kLeafTile];
  std::uint32_t id[kWarpsPerBlock][2][kLeafTile];
};

/// One warp's two tiles in LeafTiles.
struct WarpTiles {
  Vec3* a;
  Vec3* b;
  std::uint32_t* id_a;
  std::uint32_t* id_b;
};

/// This warp's tiles of the block's LeafTiles; the vertex ids only when d keeps witnesses
/// (else null: stage_tile then writes none).
__device__ inline WarpTiles warp_tiles(const MidListDesc& d, LeafTiles& t) {
  const std::uint32_t w = threadIdx.x >> 5;
  const bool ids = d.wit.witness != nullptr;
  return {t.v[w][1], t.v[w][0], ids ? t.id[w][1] : nullptr, ids ? t.id[w][0] : nullptr};
}

}  // namespace mid
}  // namespace gpu
}  // namespace octocd
