#pragma once
// Device code of the midphase + narrow phase (SPEC 5.2-5.3) as per-level work lists of box
// pairs, so a pair whose meshes overlap deeply spreads over many warps instead of one
// thread:
// - start (one warp per candidate pair): hd::setup_pair, the set-up the CPU's
//   confirm_contact runs, decides aabb-only, box-box and early rejections (static-static
//   pairs are skipped as in World::step); for a mesh pair the warp tests every cell pair
//   of step 0 (levels la[0] x lb[0], or A's cells against the box) and appends the
//   overlapping ones (pair, cell of A, cell of B) to the first list;
// - expand (one warp per item of step i): the descendants at step i + 1 of both cells
//   (hd::descendants), tested with the same boxes (hd::moved_grown), appended to the next
//   list;
// - leaf (one warp per item of the last step): the narrow phase of hd::mesh_mesh_leaf /
//   mesh_box_descend on that cell pair, lanes over B's vertices, A's vertices in order.
//   The vertex filters scan whole blocks of 32 vertices (vertex_blocks.hpp) and skip a
//   block whose box misses the filter box: mesh-mesh, the other's grown cell box (no vertex
//   of the block is inside it, so the filtered vertices, their order and the counts are
//   unchanged); mesh-box, box_local (a vertex outside it cannot be within theta of the box:
//   the argument that lets the cell test skip a cell).
// A pair is confirmed when any of its leaves has a vertex pair within theta: the same
// vertex tests on the same floats as the CPU's depth-first descent, so the same answer;
// only the order of the work differs. Lists are appended with warp-aggregated integer
// atomics (item order varies run to run; results and counts do not). A list that would
// pass its capacity still counts every item (the host then regrows and reruns the step).
// A large leaf cell pair is split into items of kLeafChunk of B's vertices each, so its
// vertex tests spread over several warps.
// Counts: box tests = every cell pair tested, box pairs = surviving leaf cell pairs,
// vertex tests = per leaf (A's filtered vertices) x (B's filtered vertices) or the cell's
// vertices against a box: the work done here, with no early exit, so each is >= the
// CPU's count.
// This header holds the per-item device code; midphase.cu wraps it in its kernels
// (mid_start, mid_expand, mid_leaf) and the fused small-scene step (small_step.cu) calls the
// same functions between grid-wide barriers. Every loop over items is a grid-stride loop
// over whole warps (the item index and its bounds are warp-uniform), so the warp
// collectives (__ballot_sync / __shfl_sync with the full mask) see all 32 lanes. CUDA only.
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

/// The two placed shapes of pair k and the test's set-up, A first (after the swap).
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
  const hd::PlacedView va = place(d.shapes, sa, d.x[p.a], d.aabb[p.a]);
  const hd::PlacedView vb = place(d.shapes, sb, d.x[p.b], d.aabb[p.b]);
  c.theta = pair_theta(d.shapes.theta[sa], d.shapes.theta[sb]);
  c.s = hd::setup_pair(va, vb, c.theta, d.levels);
  c.a = c.s.swap ? vb : va;
  c.b = c.s.swap ? va : vb;
  const Aabb* blocks_sa = d.shapes.blocks + d.shapes.shapes[sa].block_offset;
  const Aabb* blocks_sb = d.shapes.blocks + d.shapes.shapes[sb].block_offset;
  c.blocks_a = c.s.swap ? blocks_sb : blocks_sa;
  c.blocks_b = c.s.swap ? blocks_sa : blocks_sb;
  return c;
}

__device__ inline std::uint32_t lane_id() { return threadIdx.x & 31u; }
__device__ inline std::uint32_t global_warp() { return (blockIdx.x * blockDim.x + threadIdx.x) >> 5; }
__device__ inline std::uint32_t warp_count() { return (gridDim.x * blockDim.x) >> 5; }

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
/// (every lane calls it).
__device__ inline void append_chunks(const MidListDesc& d, std::uint32_t cnt, MidItem item) {
  const std::uint32_t lane = lane_id();
  std::uint32_t incl = cnt;
  for (int o = 1; o < 32; o <<= 1) {
    const std::uint32_t y = __shfl_up_sync(kFull, incl, o);
    if (lane >= static_cast<std::uint32_t>(o)) incl += y;
  }
  const std::uint32_t total = __shfl_sync(kFull, incl, 31);
  if (total == 0) return;
  std::uint32_t base = 0;
  if (lane == 0) base = atomicAdd(d.out_count, total);
  base = __shfl_sync(kFull, base, 0);
  const std::uint32_t start = base + incl - cnt;
  for (std::uint32_t c = 0; c < cnt; ++c) {
    if (start + c < d.out_capacity) {
      item.chunk = c;
      d.out[start + c] = item;
    }
  }
}

/// Tests the cell pairs [a0, a1) x [b0, b1) of pair k (mesh-box: [a0, a1) against the
/// box; b is unused) with the lanes of the warp and appends the overlapping ones; at the
/// last step (`last`) a mesh-mesh cell pair is appended once per kLeafChunk of B's
/// vertices, and the surviving leaf box pairs are counted.
__device__ inline void test_cells(const MidListDesc& d, const PairContext& c, std::uint32_t k, std::uint32_t a0,
                           std::uint32_t a1, std::uint32_t b0, std::uint32_t b1, bool last) {
  const bool mesh_box = c.s.kind == hd::PairKind::MeshBox;
  const std::uint32_t nb = mesh_box ? 1u : b1 - b0;
  const std::uint32_t total = (a1 - a0) * nb;
  const hd::OctreeView& A = c.a.octree;
  const hd::OctreeView& B = c.b.octree;
  for (std::uint32_t c0 = 0; c0 < total; c0 += 32) {
    const std::uint32_t t = c0 + lane_id();
    bool keep = false;
    MidItem item{k, 0, 0};
    if (t < total) {
      item.ca = a0 + t / nb;
      item.cb = mesh_box ? 0u : b0 + t % nb;
      keep = mesh_box ? overlaps(A.cells[item.ca].box, c.s.box_local)
                      : overlaps(hd::moved_grown(A.cells[item.ca].box, c.s.d, c.s.margin), B.cells[item.cb].box);
    }
    if (last) {
      const unsigned mask = __ballot_sync(kFull, keep);
      if (lane_id() == 0 && mask) atomicAdd(&d.counters[1], static_cast<unsigned long long>(__popc(mask)));
    }
    if (last && !mesh_box) {
      const std::uint32_t nv = keep ? B.cells[item.cb].vertex_count : 0u;
      append_chunks(d, keep ? (nv + kLeafChunk - 1) / kLeafChunk : 0u, item);
    } else {
      append(d, keep, item);
    }
  }
  if (lane_id() == 0 && total > 0) atomicAdd(&d.counters[0], static_cast<unsigned long long>(total));
}

/// mid_start's work: one warp per live candidate pair (grid-stride over the whole grid).
__device__ inline void mid_start_items(const MidListDesc& d) {
  const std::uint32_t np = *d.pair_count < d.pair_capacity ? *d.pair_count : d.pair_capacity;
  for (std::uint32_t k = global_warp(); k < np; k += warp_count()) {
    // The pair from its sorted key (the broadphase's output), kept for the later stages.
    const unsigned long long key = d.pair_keys[k];
    Pair p;
    p.a = static_cast<std::uint32_t>(key >> d.pair_shift);
    p.b = static_cast<std::uint32_t>(key & ((1ull << d.pair_shift) - 1ull));
    if (lane_id() == 0) d.pairs[k] = p;
    const PairContext c = context(d, k, p);
    if (c.static_static || c.s.kind == hd::PairKind::Decided || c.s.kind == hd::PairKind::Exhaustive) {
      if (lane_id() == 0) {
        bool hit = false;
        if (!c.static_static)
          hit = c.s.kind == hd::PairKind::Decided ? c.s.result : hd::exhaustive_contact(c.a, c.b, c.theta);
        d.confirmed[k] = hit ? 1 : 0;
      }
      continue;
    }
    if (lane_id() == 0) d.confirmed[k] = 0;
    const hd::OctreeView& A = c.a.octree;
    const hd::OctreeView& B = c.b.octree;
    const bool mesh_box = c.s.kind == hd::PairKind::MeshBox;
    test_cells(d, c, k, A.level_begin(c.s.la[0]), A.level_end(c.s.la[0]), mesh_box ? 0u : B.level_begin(c.s.lb[0]),
               mesh_box ? 1u : B.level_end(c.s.lb[0]), d.steps == 1);
  }
}

/// mid_expand's work: one warp per item of step `step` (grid-stride over the whole grid).
__device__ inline void mid_expand_items(const MidListDesc& d, int step) {
  const std::uint32_t count = *d.in_count < d.in_capacity ? *d.in_count : d.in_capacity;
  for (std::uint32_t it = global_warp(); it < count; it += warp_count()) {
    const MidItem item = d.in[it];
    const PairContext c = context(d, item.k, d.pairs[item.k]);
    const bool mesh_box = c.s.kind == hd::PairKind::MeshBox;
    std::uint32_t a0, a1, b0 = 0, b1 = 1;
    hd::descendants(c.a.octree, item.ca, c.s.la[step], c.s.la[step + 1], a0, a1);
    if (!mesh_box) hd::descendants(c.b.octree, item.cb, c.s.lb[step], c.s.lb[step + 1], b0, b1);
    test_cells(d, c, item.k, a0, a1, b0, b1, step + 2 == d.steps);
  }
}

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
/// `box`, in order, from vertex block `pos` on (blocks whose box misses `box` skipped, the
/// lanes test a block's 32 vertices at once) until the blocks end or a further 32 might
/// not fit; advances pos (a block index) and fill (warp-uniform).
__device__ inline void stage_tile(const Vec3* v, const Aabb* blocks, std::uint32_t begin, std::uint32_t end,
                                  const Aabb& box, Vec3 position, Vec3* tile, std::uint32_t& pos, std::uint32_t& fill) {
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
      if ((mask >> lane) & 1u)
        tile[fill + static_cast<std::uint32_t>(__popc(mask & ((1u << lane) - 1u)))] = hd::world_vertex(v[j], position);
      fill += static_cast<std::uint32_t>(__popc(mask));
    }
    pos = next;
  }
  __syncwarp();
}

__device__ inline bool pair_confirmed(const MidListDesc& d, std::uint32_t k) {
  return *(volatile const std::uint8_t*)(d.confirmed + k) != 0;
}

/// Shared memory of mid_leaf_items: per warp of the block, a tile of B's and one of A's
/// filtered world vertices.
using LeafTiles = Vec3[kWarpsPerBlock][2][kLeafTile];

/// mid_leaf's work: one warp per item of the last step (grid-stride over the whole grid);
/// `tiles` is the block's shared memory (blockDim.x == kBlockSize).
__device__ inline void mid_leaf_items(const MidListDesc& d, LeafTiles& tiles) {
  Vec3* tile_b = tiles[threadIdx.x >> 5][0];
  Vec3* tile_a = tiles[threadIdx.x >> 5][1];
  const std::uint32_t count = *d.in_count < d.in_capacity ? *d.in_count : d.in_capacity;
  const std::uint32_t lane = lane_id();
  for (std::uint32_t it = global_warp(); it < count; it += warp_count()) {
    const MidItem item = d.in[it];
    const PairContext c = context(d, item.k, d.pairs[item.k]);
    const hd::OctreeView& A = c.a.octree;
    const MeshOctreeCell ca = A.cells[item.ca];
    const std::uint32_t a_begin = ca.first_vertex;
    const std::uint32_t a_end = ca.first_vertex + ca.vertex_count;
    const Vec3 pa = c.a.position;
    if (c.s.kind == hd::PairKind::MeshBox) {  // as mesh_box_descend's last step
      // Only the blocks whose box overlaps box_local (the box in A's frame grown by
      // theta + tolerance, as the cell test) can hold a vertex within theta of the box.
      bool hit = false;
      const std::uint32_t g1 = block_end(a_end);
      for (std::uint32_t g0 = a_begin / kVertexBlock; g0 < g1; g0 += 32) {
        unsigned m = blocks_overlapping(c.blocks_a, g0, g1, c.s.box_local);
        while (m) {
          const std::uint32_t j = (g0 + static_cast<std::uint32_t>(__ffs(m) - 1)) * kVertexBlock + lane;
          m &= m - 1u;
          hit = hit || (j >= a_begin && j < a_end &&
                        hd::vertex_box_close(hd::world_vertex(A.vertices[j], pa), c.b.box, c.s.theta2));
        }
      }
      if (lane == 0 && ca.vertex_count > 0)
        atomicAdd(&d.counters[2], static_cast<unsigned long long>(ca.vertex_count));
      if (__any_sync(kFull, hit) && lane == 0) d.confirmed[item.k] = 1;
      continue;
    }
    // As mesh_mesh_leaf: B's vertices inside A's grown cell box (in B's frame) against
    // A's vertices inside B's grown cell box (in A's frame), vertex_close(wa, wb).
    const hd::OctreeView& B = c.b.octree;
    const MeshOctreeCell cb = B.cells[item.cb];
    // This item's share of B's vertices: chunk `item.chunk` of the cell's.
    const std::uint32_t chunk_begin = item.chunk * kLeafChunk;
    const std::uint32_t rest = cb.vertex_count > chunk_begin ? cb.vertex_count - chunk_begin : 0u;
    const std::uint32_t nbv = rest < kLeafChunk ? rest : kLeafChunk;
    const std::uint32_t b_begin = cb.first_vertex + chunk_begin;
    const std::uint32_t b_end = b_begin + nbv;
    const Vec3 pb = c.b.position;
    const Aabb a_in_b = hd::moved_grown(ca.box, c.s.d, c.s.margin);
    const Aabb b_in_a = hd::moved_back_grown(cb.box, c.s.d, c.s.margin);
    // The filtered counts, whole blocks of 32 vertices skipped when their box misses the
    // filter box (no vertex of theirs is inside it): the same counts.
    const std::uint32_t nbf = count_inside(B.vertices, c.blocks_b, b_begin, b_end, a_in_b);
    if (nbf == 0) continue;  // as mesh_mesh_leaf: no vertex test
    const std::uint32_t naf = count_inside(A.vertices, c.blocks_a, a_begin, a_end, b_in_a);
    if (lane == 0 && naf > 0)
      atomicAdd(&d.counters[2], static_cast<unsigned long long>(naf) * static_cast<unsigned long long>(nbf));
    if (naf == 0) continue;
    // Tiles of B's filtered world vertices against tiles of A's; another leaf of this
    // pair may confirm it first (checked between tiles): the answer is the same.
    bool found = false;
    // jb, ia: the next vertex block of B's and A's ranges to stage.
    std::uint32_t jb = b_begin / kVertexBlock;
    const std::uint32_t jb_end = block_end(b_end);
    const std::uint32_t ia_end = block_end(a_end);
    while (!found && jb < jb_end) {
      if (__shfl_sync(kFull, lane == 0 ? static_cast<int>(pair_confirmed(d, item.k)) : 0, 0)) break;
      std::uint32_t nb = 0;
      stage_tile(B.vertices, c.blocks_b, b_begin, b_end, a_in_b, pb, tile_b, jb, nb);
      std::uint32_t ia = a_begin / kVertexBlock;
      while (!found && nb > 0 && ia < ia_end) {
        std::uint32_t na = 0;
        stage_tile(A.vertices, c.blocks_a, a_begin, a_end, b_in_a, pa, tile_a, ia, na);
        // Lane l takes B vertices l, l + 32, ... of the tile; the warp stops as soon as
        // one lane has a close pair (checked every 16 A vertices: same answer, less work
        // when the meshes are in contact).
        for (std::uint32_t jj0 = 0; jj0 < nb && !found; jj0 += 32) {
          const bool valid = jj0 + lane < nb;
          const Vec3 wb = tile_b[valid ? jj0 + lane : 0u];
          bool hit = false;
          for (std::uint32_t i0 = 0; i0 < na && !found; i0 += 16) {
            const std::uint32_t i1 = i0 + 16 < na ? i0 + 16 : na;
            for (std::uint32_t ii = i0; ii < i1; ++ii) hit = hit || (valid && hd::vertex_close(tile_a[ii], wb, c.s.theta2));
            found = __any_sync(kFull, hit);
          }
        }
        __syncwarp();
      }
    }
    if (found && lane == 0) d.confirmed[item.k] = 1;
  }
}

}  // namespace mid
}  // namespace gpu
}  // namespace octocd
