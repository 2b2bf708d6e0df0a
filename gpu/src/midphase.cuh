#pragma once
// Device code of the midphase + narrow phase (design.md sections 5.2-5.3) as per-level work lists of box
// pairs, so a pair whose meshes overlap deeply spreads over many warps instead of one
// thread:
// - start (one warp per candidate pair): hd::setup_pair, the set-up the CPU's
//   confirm_contact runs, decides aabb-only, box-box and early rejections (static-static
//   pairs are skipped as in World::step); for a mesh pair the warp tests every cell pair
//   of step 0 (levels la[0] x lb[0], or A's cells against the box) and appends the
//   overlapping ones (pair, cell of A, cell of B) to the first list. When no pair can
//   need a level step (no mesh shape, or no level), the per-stage path runs decide
//   instead: the same answers, a thread per pair (boxes spend a thread per pair, not a warp);
// - expand (one warp per item of step i): the descendants at step i + 1 of both cells
//   (hd::descendants), tested with the same boxes (hd::moved_grown), appended to the next
//   list; the last expand step of the graph path (mid_expand_last_kernel) runs the
//   surviving leaf cell pairs of its item itself, in lane order, as the leaf items the list
//   would have held (leaf_item, the same code mid_leaf runs), when the step has at least
//   kFuseItemsPerWarp items per warp (fuse_leaves): no leaf item is written, read or set up
//   again, and the leaf list stays empty (mid_expand_append_kernel, launched beside it, does
//   the step otherwise);
// - leaf (one warp per item of the last step): the narrow phase of hd::mesh_mesh_leaf /
//   mesh_box_descend on that cell pair, lanes over B's vertices, A's vertices in order.
//   The vertex filters scan whole blocks of 32 vertices (vertex_blocks.hpp) and skip a
//   block whose box misses the filter box: mesh-mesh, the other's grown cell box (no vertex
//   of the block is inside it, so the filtered vertices, their order and the counts are
//   unchanged); mesh-box, box_local (a vertex outside it cannot be within theta of the box:
//   the argument that lets the cell test skip a cell). The first tile of each of B's and
//   A's ranges is staged while counting (the rest of a range only counted), so a small
//   leaf scans its vertices once.
// A pair is confirmed when any of its leaves has a vertex pair within theta: the same
// vertex tests on the same floats as the CPU's depth-first descent, so the same answer;
// only the order of the work differs. Lists are appended with warp-aggregated integer
// atomics (item order varies run to run; results and counts do not). A list that would
// pass its capacity still counts every item (the host then regrows and reruns the step).
// A large leaf cell pair (over kLeafWholePairs vertex pairs) is split into items
// (leaf_items): each chunk of B's vertices (leaf_b_chunk) against each kLeafAPart of A's,
// so its vertex tests spread over several warps (the filtered counts of an item's parts add
// up to the cell pair's).
// Early exit (MidListDesc::early_exit, CudaSettings::midphase_early_exit, on by default): the
// answer per pair is a boolean, so once confirmed[k] is set the rest of pair k's work
// cannot change it (nor any result: the response reads only confirmed[k]). With it on, an
// expand item or leaf item of a confirmed pair is skipped before its set-up, a cell test
// stops before its next 32 cell pairs, the fused leaves stop before the next chunk, and a
// leaf checks the pair before each tile of B and of A (each check one volatile load by lane
// 0, shuffled: warp-uniform, so no lane leaves a warp collective). A leaf then runs no count
// over its whole vertex ranges (only the tiles it stages), and the fused leaves of an expand
// item run deepest overlap first (overlap_depth: the likelier hits first).
// Tile culling (MidListDesc::tile_cull: on, except in the small path's lean kernel; with the
// exit on or off): a leaf skips a pair of staged vertex tiles whose bounding boxes are apart
// by theta on some axis (tiles_apart; exact for hd::vertex_close's float sum), so a large
// leaf tests only the tile pairs that are near each other.
// Tile filter (MidListDesc::tile_filter: on, except in the lean kernel): for
// each staged tile of B a leaf stages only A's vertices near it (near_tile: the tile's box
// in A's frame grown by the margin, within b_in_a; whole vertex blocks skipped by their
// boxes), so a large leaf does not rescan and stage A's whole filtered cell per tile of
// B; with the exit on A's first tile is then not staged ahead of B's tiles.
// Counts, early exit off: box tests = every cell pair tested, box pairs = surviving leaf
// cell pairs, vertex tests = per leaf (A's filtered vertices) x (B's filtered vertices) or
// the cell's vertices against a box: the work of the lists with no early exit (a leaf of a
// pair already confirmed still computes its filtered counts and only skips its vertex
// tests), so each is >= the CPU's count and none depends on timing or on where the leaves
// run. Early exit on: the work done (box tests: per 32 cell pairs tested; box pairs: the
// surviving leaf cell pairs of the tests run; vertex tests: na x nb per pair of tiles
// tested and not culled, a mesh-box leaf's cell vertices), each <= the figure with the exit
// off on the same state (box tests and box pairs > 0 exactly when they are), and dependent
// on timing (run to run, grid, path).
// Witnesses (MidListDesc::wit; the per-stage path with the early exit, for meshes with
// levels; the fused small step keeps none): a leaf that
// confirms pair k stores the vertex pair it found (A's vertex, B's vertex: indices into the
// shapes' octree vertices; the tiles keep each staged vertex's index) as witness[k]; at the
// end of the step keep_witness copies the sorted keys and witnesses; the next step looks
// pair k's key up among them (prev_begin[a]: the run of a's pairs) and tests that vertex
// pair first, before the pair's set-up (mid_witness, a thread per pair, before mid_start:
// witness_close), with the vertex test of the leaves (hd::vertex_close or
// vertex_box_close on hd::world_vertex). A pair within theta
// there is confirmed with no set-up and no descent: the answer of the descent, which
// confirms exactly when some vertex pair passes that test (its pruning, the set-up's early
// rejection included, is conservative, midphase_hd.hpp). Which witness a pair keeps
// (several leaves may confirm it) depends on timing; the answers do not. A witness that
// fails is followed by the pairs of the two 32-vertex blocks that hold its vertices
// (witness_block_close, mid_start's warp): a contact that slid keeps a close vertex pair
// there. Counts: each
// vertex pair a witness test compares counts as a vertex test (at most kWitnessVertexTests
// a pair).
// Each warp sums its counts in registers (Tally) and adds them once per launch.
// Set-up: context() orders the pair (mesh first) on body indices and reads a step's levels
// with hd::clamped_level, so no PlacedView is chosen by reference and no level array is
// indexed at a run-time step: the per-item set-up stays in registers (no local memory).
// This header holds the per-item device code; midphase.cu wraps it in its kernels
// (mid_decide, mid_start, mid_expand, mid_leaf) and the fused small-scene step (small_step.cu) calls the
// same functions between grid-wide barriers (its lean kernel: a block per pair,
// mid_block_pairs, the steps apart by __syncthreads). Every loop over pairs is a grid-stride loop
// over whole warps, every loop over expand items a contiguous share per warp (warp_range),
// over leaf items a stride of the grid's warps; the item index and its bounds are
// warp-uniform, so the warp collectives (__ballot_sync / __shfl_sync with the full mask) see
// all 32 lanes. CUDA only.
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

/// The narrow phase of one leaf item of pair k (the whole warp): mesh-box, A's cell `ca`
/// against the box (as mesh_box_descend's last step); mesh-mesh, leaf item `chunk` of A's
/// cell `ca` and B's cell `cb` (MidItem::chunk, leaf_ranges: a chunk of B's vertices against
/// a part of A's, as mesh_mesh_leaf on those). Sets confirmed[k] on a vertex pair within theta;
/// adds the vertex tests to `t`. Early exit off: the item's whole count (the vertex count of
/// A's cell, or filtered A x filtered B of its part and chunk),
/// whether or not the tests are cut short because the pair is confirmed (here or by another
/// warp), so the counts do not depend on timing. Early exit on (the caller skips the item
/// when the pair is already confirmed): mesh-box, the cell's vertex count; mesh-mesh,
/// na x nb for every pair of tiles tested (a tile pair cut short by a hit counts in full),
/// no count over the whole ranges is run, and the pair is checked before every tile of B
/// and of A. `tiles`: the warp's kLeafTile-vertex tiles (warp_tiles). The leaf that
/// confirms the pair stores the vertex pair it found (confirm: the witness) when kWitness
/// and d keeps witnesses; !kWitness compiles the leaf without them (the fused small step);
/// kLean: as exit_on.
template <bool kWitness, bool kLean = false>
__device__ inline void leaf_item(const MidListDesc& d, const PairContext& c, std::uint32_t k, std::uint32_t ca_index,
                                 std::uint32_t cb_index, std::uint32_t chunk, const WarpTiles& tiles, Tally& t) {
  Vec3* const tile_a = tiles.a;
  Vec3* const tile_b = tiles.b;
  std::uint32_t* const id_a = kWitness ? tiles.id_a : nullptr;
  std::uint32_t* const id_b = kWitness ? tiles.id_b : nullptr;
  const std::uint32_t lane = lane_id();
  const hd::OctreeView& A = c.a.octree;
  const MeshOctreeCell ca = A.cells[ca_index];
  std::uint32_t a_begin = ca.first_vertex;  // mesh-mesh: this item's part of A's cell (below)
  std::uint32_t a_end = ca.first_vertex + ca.vertex_count;
  const Vec3 pa = c.a.position;
  const bool exit_early = exit_on<kLean>(d);
  if (c.s.kind == hd::PairKind::MeshBox) {  // as mesh_box_descend's last step
    t.vertex_tests += ca.vertex_count;
    // The answer is known: the tests would not change it (early exit on: checked already).
    if (!exit_early && confirmed_now(d, k)) return;
    // Only the blocks whose box overlaps box_local (the box in A's frame grown by
    // theta + tolerance, as the cell test) can hold a vertex within theta of the box.
    bool hit = false;
    std::uint32_t hj = 0;  // this lane's vertex within theta, once `hit` (kWitness)
    const std::uint32_t g1 = block_end(a_end);
    for (std::uint32_t g0 = a_begin / kVertexBlock; g0 < g1; g0 += 32) {
      unsigned m = blocks_overlapping(c.blocks_a, g0, g1, c.s.box_local);
      while (m) {
        const std::uint32_t j = (g0 + static_cast<std::uint32_t>(__ffs(m) - 1)) * kVertexBlock + lane;
        m &= m - 1u;
        if constexpr (kWitness) {
          if (!hit && j >= a_begin && j < a_end &&
              hd::vertex_box_close(hd::world_vertex(A.vertices[j], pa), c.b.box, c.s.theta2)) {
            hit = true;
            hj = j;
          }
        } else {
          hit = hit || (j >= a_begin && j < a_end &&
                        hd::vertex_box_close(hd::world_vertex(A.vertices[j], pa), c.b.box, c.s.theta2));
        }
      }
    }
    if constexpr (kWitness) {
      const unsigned hits = __ballot_sync(kFull, hit);
      if (hits != 0) {
        const std::uint32_t w = __shfl_sync(kFull, hj, __ffs(hits) - 1);
        if (lane == 0) confirm(d, k, static_cast<unsigned long long>(w) << 32);
      }
    } else {
      if (__any_sync(kFull, hit) && lane == 0) d.confirmed[k] = 1;
    }
    return;
  }
  // As mesh_mesh_leaf: B's vertices inside A's grown cell box (in B's frame) against
  // A's vertices inside B's grown cell box (in A's frame), vertex_close(wa, wb).
  const hd::OctreeView& B = c.b.octree;
  const MeshOctreeCell cb = B.cells[cb_index];
  // This item's share (MidItem::chunk): a chunk of B's cell's vertices against a part of
  // A's cell's vertices.
  std::uint32_t a0, a1, b0, b1;
  leaf_ranges(chunk, ca.vertex_count, cb.vertex_count, a0, a1, b0, b1);
  a_begin = ca.first_vertex + a0;
  a_end = ca.first_vertex + a1;
  const std::uint32_t b_begin = cb.first_vertex + b0;
  const std::uint32_t b_end = cb.first_vertex + b1;
  const Vec3 pb = c.b.position;
  const Aabb a_in_b = hd::moved_grown(ca.box, c.s.d, c.s.margin);
  const Aabb b_in_a = hd::moved_back_grown(cb.box, c.s.d, c.s.margin);
  // Early exit off: the filtered counts, whole blocks of 32 vertices skipped when their box
  // misses the filter box (no vertex of theirs is inside it): the first tile of each range
  // is staged while counting (stage_tile counts what it stages), the rest of the range only
  // counted; the counts are those of the whole ranges. Early exit on: only the first tiles
  // are staged (a tile short of full ends its range, so an empty first tile means no
  // filtered vertex: no vertex test, as mesh_mesh_leaf); with the tile filter as well
  // (d.tile_filter) A's first tile is not staged here: A's tiles are staged per tile of B,
  // only the vertices near it (near_tile).
  const bool filter = filter_on<kLean>(d);
  const bool a_first = !(exit_early && filter);  // A's first tile staged before the tiles of B
  std::uint32_t jb = b_begin / kVertexBlock;  // the next vertex block of B's range to stage
  const std::uint32_t jb_end = block_end(b_end);
  std::uint32_t nb = 0;
  stage_tile(B.vertices, c.blocks_b, b_begin, b_end, a_in_b, pb, tile_b, id_b, jb, nb);
  const std::uint32_t nbf =
      exit_early ? nb
                 : nb + (jb < jb_end ? count_inside(B.vertices, c.blocks_b, jb * kVertexBlock, b_end, a_in_b) : 0u);
  if (nbf == 0) return;  // as mesh_mesh_leaf: no vertex test
  const std::uint32_t ia_end = block_end(a_end);
  std::uint32_t ia_first = a_begin / kVertexBlock;  // A's next block after its first tile
  std::uint32_t na_first = 0;
  if (a_first) {
    stage_tile(A.vertices, c.blocks_a, a_begin, a_end, b_in_a, pa, tile_a, id_a, ia_first, na_first);
    const std::uint32_t naf =
        exit_early ? na_first
                   : na_first + (ia_first < ia_end
                                     ? count_inside(A.vertices, c.blocks_a, ia_first * kVertexBlock, a_end, b_in_a)
                                     : 0u);
    if (!exit_early) t.vertex_tests += static_cast<unsigned long long>(naf) * static_cast<unsigned long long>(nbf);
    if (naf == 0) return;
  }
  // Tiles of B's filtered world vertices against tiles of A's (B's first tile and, for it,
  // A's first tile are already staged); another leaf of this pair may confirm it first
  // (checked between B's tiles, and with the early exit on between A's too): the answer is
  // the same.
  bool found = false;
  bool b_staged = true;  // tile_b holds B's next tile (nb vertices)
  while (!found) {
    if (!b_staged || !exit_early) {  // early exit on: the caller has just checked
      if (confirmed_now(d, k)) break;
    }
    if (!b_staged) {
      if (jb >= jb_end) break;
      nb = 0;
      stage_tile(B.vertices, c.blocks_b, b_begin, b_end, a_in_b, pb, tile_b, id_b, jb, nb);
    }
    if (nb == 0) break;  // (only at the range's end)
    const bool cull = cull_on<kLean>(d);
    Aabb box_b{};
    if (cull || filter) {
      box_b = tile_box(tile_b, nb);
      __syncwarp();  // tile_b is read; it is staged again only after the loop below
    }
    // A's vertices staged for this tile of B: with the tile filter only those near the
    // tile (near_tile), else every one inside b_in_a. An empty filter box holds none of A's
    // vertices: no vertex of this tile can be close to A's (the next tile of B is taken).
    const Aabb a_filter = filter ? near_tile(b_in_a, box_b, pa, c.s.margin) : b_in_a;
    if (filter && box_empty(a_filter)) {
      b_staged = false;
      continue;
    }
    // tile_a still holds A's first tile (if staged: a_first) only while B's first tile is
    // tested.
    bool a_staged = b_staged && a_first;
    b_staged = false;
    std::uint32_t ia = a_staged ? ia_first : a_begin / kVertexBlock;
    std::uint32_t na = a_staged ? na_first : 0u;
    while (!found && nb > 0) {
      if (!a_staged) {
        if (ia >= ia_end) break;
        if (exit_early && confirmed_now(d, k)) break;
        na = 0;
        stage_tile(A.vertices, c.blocks_a, a_begin, a_end, a_filter, pa, tile_a, id_a, ia, na);
      }
      a_staged = false;
      // A pair of tiles whose boxes are apart by theta on some axis has no close vertex
      // pair (tiles_apart: exact), so its tests are skipped (not counted with the exit on).
      if (na > 0 && !(cull && tiles_apart(tile_box(tile_a, na), box_b, c.s.theta2))) {
        if (exit_early) t.vertex_tests += static_cast<unsigned long long>(na) * static_cast<unsigned long long>(nb);
        found = tiles_close(tile_a, na, tile_b, nb, c.s.theta2);
        if constexpr (kWitness) {
          if (found) {
            const unsigned long long w = d.wit.witness != nullptr
                                             ? tiles_witness(tile_a, id_a, na, tile_b, id_b, nb, c.s.theta2)
                                             : kNoWitness;
            if (lane == 0) confirm(d, k, w);
          }
        }
      }
      __syncwarp();
    }
  }
  if constexpr (!kWitness) {
    if (found && lane == 0) d.confirmed[k] = 1;
  }
}

/// The last step's cell pairs of `mask` (bit l: lane l's `item` survived), run as leaves by
/// this warp in lane order instead of being appended to the leaf list: each mesh-mesh cell
/// pair as its leaf_items items, each mesh-box cell once, exactly the items the list would
/// have held (so the same tests and counts); with the early exit on, none after the pair is
/// confirmed, and the cell pairs in the order of `depth` (lane's overlap_depth), deepest
/// first (the likelier hits first; ties in lane order), else in lane order.
__device__ inline void run_leaves(const MidListDesc& d, const PairContext& c, std::uint32_t k, unsigned mask,
                                  const MidItem& item, float depth, LeafTiles& tiles, Tally& t) {
  const WarpTiles warp = warp_tiles(d, tiles);
  const bool mesh_box = c.s.kind == hd::PairKind::MeshBox;
  const bool deepest_first = d.early_exit != 0;
  const unsigned key = __float_as_uint(depth);  // depth >= +0: ordered as the floats
  while (mask) {
    int l;
    if (deepest_first) {
      const bool in = ((mask >> lane_id()) & 1u) != 0;
      const unsigned best = __reduce_max_sync(kFull, in ? key : 0u);
      l = __ffs(__ballot_sync(kFull, in && key == best)) - 1;
    } else {
      l = __ffs(mask) - 1;
    }
    mask &= ~(1u << l);
    const std::uint32_t ca = __shfl_sync(kFull, item.ca, l);
    const std::uint32_t cb = __shfl_sync(kFull, item.cb, l);
    const std::uint32_t chunks =
        mesh_box ? 1u : leaf_items(c.a.octree.cells[ca].vertex_count, c.b.octree.cells[cb].vertex_count);
    for (std::uint32_t ch = 0; ch < chunks; ++ch) {
      if (skip_confirmed(d, k)) return;
      leaf_item<true>(d, c, k, ca, cb, ch, warp, t);
    }
  }
}

/// The smallest extent of the overlap of two boxes (+0 when they touch or miss): how deep a
/// leaf cell pair overlaps, the fused leaves' order with the early exit (run_leaves).
__device__ inline float overlap_depth(const Aabb& a, const Aabb& b) {
  const float x = fminf(a.max.x, b.max.x) - fmaxf(a.min.x, b.min.x);
  const float y = fminf(a.max.y, b.max.y) - fmaxf(a.min.y, b.min.y);
  const float z = fminf(a.max.z, b.max.z) - fmaxf(a.min.z, b.min.z);
  const float m = fminf(x, fminf(y, z));
  return m > 0.0f ? m : 0.0f;
}

/// Tests the cell pairs [a0, a1) x [b0, b1) of pair k (mesh-box: [a0, a1) against the
/// box; b is unused) with the lanes of the warp and appends the overlapping ones; at the
/// last step (`last`) a mesh-mesh cell pair is appended once per leaf item (leaf_items),
/// and the surviving leaf box pairs are counted; with `leaves` (last step only)
/// the surviving cell pairs are run here as leaves (run_leaves) instead of appended. Box
/// tests are counted per 32 cell pairs tested; with the early exit on, the test stops before
/// the next 32 once the pair is confirmed (the caller checked it before the first).
template <bool kLean = false>
__device__ inline void test_cells(const MidListDesc& d, const PairContext& c, std::uint32_t k, std::uint32_t a0,
                                  std::uint32_t a1, std::uint32_t b0, std::uint32_t b1, bool last, Tally& t,
                                  LeafTiles* leaves = nullptr) {
  const bool mesh_box = c.s.kind == hd::PairKind::MeshBox;
  const std::uint32_t nb = mesh_box ? 1u : b1 - b0;
  const std::uint32_t total = (a1 - a0) * nb;
  const hd::OctreeView& A = c.a.octree;
  const hd::OctreeView& B = c.b.octree;
  for (std::uint32_t c0 = 0; c0 < total; c0 += 32) {
    if (c0 > 0 && skip_confirmed<kLean>(d, k)) break;
    t.box_tests += total - c0 < 32u ? total - c0 : 32u;
    const std::uint32_t i = c0 + lane_id();
    bool keep = false;
    MidItem item{k, 0, 0};
    if (i < total) {
      item.ca = a0 + i / nb;
      item.cb = mesh_box ? 0u : b0 + i % nb;
      keep = mesh_box ? overlaps(A.cells[item.ca].box, c.s.box_local)
                      : overlaps(hd::moved_grown(A.cells[item.ca].box, c.s.d, c.s.margin), B.cells[item.cb].box);
    }
    // The leaf items of a surviving cell pair at the last step (one for mesh-box), for the
    // leaf list or the fuse decision's count.
    const bool counted = last && keep && (leaves == nullptr || d.leaf_items != nullptr);
    const std::uint32_t chunks =
        counted ? (mesh_box ? 1u : leaf_items(A.cells[item.ca].vertex_count, B.cells[item.cb].vertex_count)) : 0u;
    if (last) {
      const unsigned mask = __ballot_sync(kFull, keep);
      t.box_pairs += static_cast<unsigned long long>(__popc(mask));
      if (d.leaf_items != nullptr) t.leaf_items += __reduce_add_sync(kFull, chunks);
      if (leaves != nullptr) {
        float depth = 0.0f;  // the order of the leaves with the early exit
        if (keep && exit_on<kLean>(d))
          depth = mesh_box ? overlap_depth(A.cells[item.ca].box, c.s.box_local)
                           : overlap_depth(hd::moved_grown(A.cells[item.ca].box, c.s.d, c.s.margin),
                                           B.cells[item.cb].box);
        run_leaves(d, c, k, mask, item, depth, *leaves, t);
        continue;
      }
    }
    if (last && !mesh_box) {
      append_chunks(d, chunks, item);
    } else {
      append(d, keep, item);
    }
  }
}

/// The pair of sorted key `key` (PairOutput: (a << pair_shift) | b).
__device__ inline Pair unpack_pair(const MidListDesc& d, unsigned long long key) {
  Pair p;
  p.a = static_cast<std::uint32_t>(key >> d.pair_shift);
  p.b = static_cast<std::uint32_t>(key & ((1ull << d.pair_shift) - 1ull));
  return p;
}

/// Whether pair context c is decided without a level step: static-static, hd::setup_pair's
/// PairKind::Decided, or PairKind::Exhaustive.
__device__ inline bool decided_alone(const PairContext& c) {
  return c.static_static || c.s.kind == hd::PairKind::Decided || c.s.kind == hd::PairKind::Exhaustive;
}

/// The answer of a pair decided_alone (one thread): false for static-static, the set-up's
/// result, or hd::exhaustive_contact (also the answer of any other pair, by every level list).
__device__ inline bool alone_answer(const PairContext& c) {
  if (c.static_static) return false;
  return c.s.kind == hd::PairKind::Decided ? c.s.result : hd::exhaustive_contact(c.a, c.b, c.theta);
}

/// Step 0 of a pair not decided_alone, by the warp: the cell pairs of levels la[0] x
/// lb[0] (or A's cells against the box), the overlapping ones appended (every lane calls it).
template <bool kLean = false>
__device__ inline void first_step(const MidListDesc& d, const PairContext& c, std::uint32_t k, Tally& t) {
  const hd::OctreeView& A = c.a.octree;
  const hd::OctreeView& B = c.b.octree;
  const bool mesh_box = c.s.kind == hd::PairKind::MeshBox;
  const int la0 = step_level(d, c, 0, false);
  const int lb0 = mesh_box ? 0 : step_level(d, c, 0, true);
  test_cells<kLean>(d, c, k, A.level_begin(la0), A.level_end(la0), mesh_box ? 0u : B.level_begin(lb0),
             mesh_box ? 1u : B.level_end(lb0), d.steps == 1, t);
}

/// The last step's witness of the pair with sorted key `key` whose first body is `a` (one
/// thread): the first kept key >= `key` from prev_begin[a] (a galloping search: a body's
/// run is short but a wall's holds thousands), kNoWitness unless it is `key` (the pair was
/// not a candidate then, or had no witness). A stale prev_begin[a] (a had no pairs then)
/// cannot find `key`.
__device__ inline unsigned long long last_witness(const MidListDesc& d, std::uint32_t a, unsigned long long key) {
  const WitnessDesc& w = d.wit;
  const std::uint32_t count = *w.prev_count;
  std::uint32_t lo = w.prev_begin[a];
  std::uint32_t hi = count;
  // Every kept key in [prev_begin[a], lo) is below `key`; probes at lo, lo + 1, lo + 3, ...
  for (std::uint32_t span = 1; lo < count; span *= 2) {
    const std::uint32_t probe = count - lo > span - 1 ? lo + span - 1 : count - 1;
    if (w.prev_keys[probe] >= key) {
      hi = probe;
      break;
    }
    lo = probe + 1;
  }
  while (lo < hi) {  // the first key >= `key` in [lo, hi], hi's (when < count) is
    const std::uint32_t mid = lo + (hi - lo) / 2;
    if (w.prev_keys[mid] < key) lo = mid + 1;
    else hi = mid;
  }
  return lo < count && w.prev_keys[lo] == key ? w.prev_witness[lo] : kNoWitness;
}

/// Pair p in context()'s order (A the mesh when one of the two is a box) as its witness
/// tests need it: the bodies, the shapes, theta^2 as hd::setup_pair computes it, and
/// witness w's vertex indices (A's, B's: indices into each shape's octree vertices).
struct WitnessSides {
  std::uint32_t ia, ib;      ///< bodies A and B
  const DeviceShape* A;
  const DeviceShape* B;
  float theta2;              ///< m^2
  std::uint32_t va, vb;      ///< w's vertices of A and B
};

/// Pair p's WitnessSides for witness w (w's vertices are not range-checked here).
__device__ inline WitnessSides witness_sides(const MidListDesc& d, const Pair& p, unsigned long long w) {
  const std::uint32_t sa = d.shape[p.a];
  const std::uint32_t sb = d.shape[p.b];
  const bool swap = d.shapes.shapes[sa].is_mesh == 0;  // as context()
  const float theta = pair_theta(d.shapes.theta[sa], d.shapes.theta[sb]);
  return {swap ? p.b : p.a,
          swap ? p.a : p.b,
          &d.shapes.shapes[swap ? sb : sa],
          &d.shapes.shapes[swap ? sa : sb],
          theta * theta,
          static_cast<std::uint32_t>(w >> 32),
          static_cast<std::uint32_t>(w)};
}

/// Whether pair p (sorted key `key`) is confirmed at its last witness (last_witness; one
/// thread), before and without its set-up: the leaves' vertex test (hd::vertex_close, or
/// hd::vertex_box_close against the box's world AABB) on the same world vertices, A the
/// mesh when one of the two is a box (context()'s order), theta^2 as hd::setup_pair
/// computes it. True only when the descent would confirm the pair: it confirms exactly
/// when some vertex pair passes that test, and such a pair is not decided by the set-up
/// (its early rejection's margin covers theta; aabb-only and level-less models keep no
/// witnesses). False for a static-static pair (never confirmed), no witness, a box-box
/// pair or an index out of range. A tested witness counts as one vertex test (`tests`);
/// *w is the witness.
__device__ inline bool witness_close(const MidListDesc& d, const Pair& p, unsigned long long key,
                                     std::uint32_t& tests, unsigned long long& w) {
  w = last_witness(d, p.a, key);
  if (w == kNoWitness) return false;
  tests += 1;
  if (d.w[p.a] == 0.0f && d.w[p.b] == 0.0f) return false;
  const WitnessSides ws = witness_sides(d, p, w);
  const std::uint32_t ia = ws.ia, ib = ws.ib, va = ws.va, vb = ws.vb;
  const DeviceShape& A = *ws.A;
  const DeviceShape& B = *ws.B;
  const float theta2 = ws.theta2;
  if (A.is_mesh == 0 || va >= A.vertex_count) return false;
  const Vec3 wa = hd::world_vertex(d.shapes.vertices[A.vertex_offset + va], d.x[ia]);
  if (B.is_mesh == 0) return hd::vertex_box_close(wa, d.aabb[ib], theta2);
  return vb < B.vertex_count &&
         hd::vertex_close(wa, hd::world_vertex(d.shapes.vertices[B.vertex_offset + vb], d.x[ib]), theta2);
}

/// Whether some vertex pair beside pair p's last witness w (which failed witness_close) is
/// within theta (the whole warp; warp-uniform): the 32 x 32 pairs of the 32-vertex blocks
/// of A's and B's vertices that hold the witness's two vertices, a lane per B vertex, A's
/// block broadcast by shuffles (mesh-box: A's block against the box). The vertices are in
/// Morton order, so a block is a compact patch: a contact that slid keeps a close pair
/// there. Confirms only as the descent would (any vertex pair that passes the leaves' test
/// confirms the pair); *found is the pair found. The vertex tests run are counted in t.
__device__ inline bool witness_block_close(const MidListDesc& d, const Pair& p, unsigned long long w, Tally& t,
                                           unsigned long long& found) {
  if (d.w[p.a] == 0.0f && d.w[p.b] == 0.0f) return false;  // static-static: never confirmed
  const WitnessSides ws = witness_sides(d, p, w);
  const std::uint32_t ia = ws.ia, ib = ws.ib, va = ws.va, vb = ws.vb;
  const DeviceShape& A = *ws.A;
  const DeviceShape& B = *ws.B;
  const float theta2 = ws.theta2;
  if (A.is_mesh == 0 || va >= A.vertex_count || (B.is_mesh != 0 && vb >= B.vertex_count)) return false;
  const std::uint32_t ja = (va & ~31u) + lane_id();
  const bool a_in = ja < A.vertex_count;
  bool close = false;
  unsigned long long mine = 0;
  if (B.is_mesh == 0) {
    t.vertex_tests += static_cast<unsigned long long>(__popc(__ballot_sync(kFull, a_in)));
    if (a_in) {
      close = hd::vertex_box_close(hd::world_vertex(d.shapes.vertices[A.vertex_offset + ja], d.x[ia]), d.aabb[ib], theta2);
      mine = static_cast<unsigned long long>(ja) << 32;
    }
  } else {
    const std::uint32_t jb = (vb & ~31u) + lane_id();
    const bool b_in = jb < B.vertex_count;
    const unsigned a_mask = __ballot_sync(kFull, a_in);
    t.vertex_tests += static_cast<unsigned long long>(__popc(a_mask)) *
                      static_cast<unsigned long long>(__popc(__ballot_sync(kFull, b_in)));
    const Vec3 wa = a_in ? hd::world_vertex(d.shapes.vertices[A.vertex_offset + ja], d.x[ia]) : Vec3{};
    const Vec3 wb = b_in ? hd::world_vertex(d.shapes.vertices[B.vertex_offset + jb], d.x[ib]) : Vec3{};
    int first = -1;  // the first of A's block within theta of this lane's B vertex
    for (int i = 0; i < 32; ++i) {
      Vec3 ai;
      ai.x = __shfl_sync(kFull, wa.x, i);
      ai.y = __shfl_sync(kFull, wa.y, i);
      ai.z = __shfl_sync(kFull, wa.z, i);
      if (first < 0 && b_in && ((a_mask >> i) & 1u) != 0 && hd::vertex_close(ai, wb, theta2)) first = i;
    }
    if (first >= 0) {
      close = true;
      mine = (static_cast<unsigned long long>((va & ~31u) + static_cast<std::uint32_t>(first)) << 32) | jb;
    }
  }
  const unsigned m = __ballot_sync(kFull, close);
  if (m == 0) return false;
  found = __shfl_sync(kFull, mine, __ffs(m) - 1);
  return true;
}

/// Whether the witness pass tests this step's witnesses (np live pairs; grid-uniform):
/// from d.witness_pass_pairs on (kWitnessPassPairsPerWarp per warp of mid_start's grid);
/// below, mid_start does.
__device__ inline bool witness_pass(const MidListDesc& d, std::uint32_t np) { return np >= d.witness_pass_pairs; }

/// mid_witness's work (before mid_start, with the witness cache on; nothing unless
/// witness_pass): one thread per live candidate pair k (grid-stride), pairs[k] from its
/// sorted key, and confirmed[k] = 1 with witness[k] its last witness when the pair is still
/// within theta there (witness_close), else confirmed[k] = 0 and witness[k] the failed
/// witness or kNoWitness (mid_start then tests the blocks beside it, or sets the pair up). A thread per pair keeps every pair's chain of
/// dependent loads (the lookup, the shapes, the two vertices) in flight at once.
__device__ inline void mid_witness_items(const MidListDesc& d) {
  const std::uint32_t np = *d.pair_count < d.pair_capacity ? *d.pair_count : d.pair_capacity;
  if (!witness_pass(d, np)) return;
  std::uint32_t tests = 0;
  for (std::uint32_t k = blockIdx.x * blockDim.x + threadIdx.x; k < np; k += gridDim.x * blockDim.x) {
    const unsigned long long key = d.pair_keys[k];
    const Pair p = unpack_pair(d, key);
    d.pairs[k] = p;
    unsigned long long w;
    const bool close = witness_close(d, p, key, tests, w);
    d.confirmed[k] = close ? 1 : 0;
    d.wit.witness[k] = w;  // a failed one for mid_start's block test (witness_block_close)
  }
  Tally t;
  t.vertex_tests = __reduce_add_sync(kFull, tests);
  flush(d, t);
}

/// Pair k's start (set up as c), by the warp: a pair decided_alone gets its answer
/// (lane 0), any other confirmed[k] = 0 and its first step's cell pairs appended
/// (first_step); with `witnesses`, witness[k] = kNoWitness either way.
template <bool kLean = false>
__device__ inline void start_pair(const MidListDesc& d, std::uint32_t k, const PairContext& c, bool witnesses,
                                  Tally& t) {
  if (decided_alone(c)) {
    if (lane_id() == 0) {
      d.confirmed[k] = alone_answer(c) ? 1 : 0;
      if (witnesses) d.wit.witness[k] = kNoWitness;
    }
    return;
  }
  if (lane_id() == 0) {
    d.confirmed[k] = 0;
    if (witnesses) d.wit.witness[k] = kNoWitness;
  }
  first_step<kLean>(d, c, k, t);
}

/// mid_start's work: one warp per live candidate pair (grid-stride over the whole grid).
/// With the witness cache on, a pair is first tested at its last witness (witness_close,
/// before its set-up; by mid_witness_items when witness_pass, else here by lane 0), then,
/// when that fails, at the vertex blocks beside it (witness_block_close): a pair still
/// within theta there is confirmed and keeps the vertex pair found, with no set-up and no
/// cell test.
/// !kWitness: compiled without the cache (the fused small step).
template <bool kWitness, bool kLean = false>
__device__ inline void mid_start_items(const MidListDesc& d) {
  const std::uint32_t np = *d.pair_count < d.pair_capacity ? *d.pair_count : d.pair_capacity;
  const bool witnesses = kWitness && d.wit.witness != nullptr;
  const bool passed = witnesses && witness_pass(d, np);  // pairs[k] and confirmed[k] written
  Tally t;
  for (std::uint32_t k = global_warp(); k < np; k += warp_count()) {
    if (passed && d.confirmed[k] != 0) continue;  // confirmed at its witness (mid_witness)
    // The pair from its sorted key (the broadphase's output), kept for the later stages.
    const unsigned long long key = d.pair_keys[k];
    const Pair p = unpack_pair(d, key);
    if (!passed && lane_id() == 0) d.pairs[k] = p;
    if (witnesses) {
      unsigned long long w = kNoWitness;  // the last witness, tested and failed (or none)
      if (passed) {
        w = d.wit.witness[k];
      } else {
        std::uint32_t tests = 0;
        const bool close = lane_id() == 0 && witness_close(d, p, key, tests, w);
        t.vertex_tests += tests;  // lane 0's tally is the warp's
        w = __shfl_sync(kFull, w, 0);
        if (__shfl_sync(kFull, close ? 1 : 0, 0) != 0) {
          if (lane_id() == 0) {
            d.confirmed[k] = 1;
            d.wit.witness[k] = w;
          }
          continue;
        }
      }
      unsigned long long found = kNoWitness;
      if (w != kNoWitness && witness_block_close(d, p, w, t, found)) {
        if (lane_id() == 0) {
          d.confirmed[k] = 1;
          d.wit.witness[k] = found;
        }
        continue;
      }
    }
    start_pair<kLean>(d, k, context(d, k, p), witnesses, t);
  }
  flush(d, t);
}

/// Keeps pair k of this step's np for the next step's witness lookups (WitnessDesc): its
/// key, its witness (kNoWitness unless confirmed by a vertex test) and, at the start of a
/// body's run of keys, prev_begin of that body (one thread per pair; prev_count is written
/// by keep_witness_count).
__device__ inline void keep_witness(const MidListDesc& d, std::uint32_t k) {
  const WitnessDesc& w = d.wit;
  const unsigned long long key = d.pair_keys[k];
  w.prev_keys[k] = key;
  w.prev_witness[k] = d.confirmed[k] != 0 ? w.witness[k] : kNoWitness;
  const std::uint32_t a = static_cast<std::uint32_t>(key >> d.pair_shift);
  if (k == 0 || static_cast<std::uint32_t>(d.pair_keys[k - 1] >> d.pair_shift) != a) w.prev_begin[a] = k;
}

/// The number of pairs keep_witness keeps (one thread): this step's live pairs.
__device__ inline void keep_witness_count(const MidListDesc& d) {
  *d.wit.prev_count = *d.pair_count < d.pair_capacity ? *d.pair_count : d.pair_capacity;
}

/// mid_decide's work (the per-stage path's midphase when no pair can need a level step: no
/// mesh shape, or no level): one thread per live candidate pair k (whole warps; `k0` the
/// warp's first pair, a multiple of 32): pairs[k] from its sorted key and confirmed[k], the
/// answer mid_start_items' lane 0 writes for a pair decided_alone (alone_answer, which any
/// other pair gets too). A box pair thus takes one
/// thread, not a warp.
__device__ inline void mid_decide_warp(const MidListDesc& d, std::uint32_t k0) {
  const std::uint32_t np = *d.pair_count < d.pair_capacity ? *d.pair_count : d.pair_capacity;
  const std::uint32_t k = k0 + lane_id();
  if (k >= np) return;
  const Pair p = unpack_pair(d, d.pair_keys[k]);
  d.pairs[k] = p;
  const PairContext c = context(d, k, p);
  d.confirmed[k] = alone_answer(c) ? 1 : 0;
}

/// Whether the last expand step runs its leaves itself (test_cells' `leaves`;
/// mid_expand_last_kernel, else mid_expand_append_kernel appends them for mid_leaf_kernel): when
/// the step has at least kFuseItemsPerWarp items per warp of the grid. The leaf list spreads a
/// pair's leaves over more warps, and the appending expand and the leaf kernel run at 64 registers
/// (4 blocks per SM) where the fused kernel needs 128 (2): with fewer items the list wins (fused,
/// the Table 5 scenes run slower); with very many it is written and read from memory beyond the L2.
/// No count per warp suits every scene (the leaf list's size, which decides, depends on the meshes
/// too), so fusing also needs the last step's leaf items (MidListDesc::leaf_items[0], counted
/// whether the leaves were fused or appended) at kFuseLeafItems or more: bunny-pile-1m (about 3
/// million leaf box pairs of one item each) runs faster appending, 5,242,880 dragons (about as many
/// leaf box pairs of about ten items) fused. Both thresholds are the H100's best over the piles and
/// the max-instances scenes (reports/h100/README.md, "Experiments and A/B results", "Midphase").
/// Grid-uniform. Where the leaves run changes neither a result nor a count (the same leaf items
/// either way). d.fuse_min_items (tests) replaces the threshold by an item count.
constexpr std::uint32_t kFuseItemsPerWarp = 256;
constexpr unsigned long long kFuseLeafItems = 1ull << 24;
__device__ inline bool fuse_leaves(const MidListDesc& d, std::uint32_t count) {
  if (d.fuse_min_items > 0) return count >= d.fuse_min_items;
  return count >= kFuseItemsPerWarp * warp_count() && (d.leaf_items == nullptr || d.leaf_items[0] >= kFuseLeafItems);
}

/// This warp's share of `count` list items: the contiguous range [begin, end), an equal
/// share per warp of the grid. A warp (start or expand) appends the items of one pair
/// together, so consecutive items often belong to the same pair: mid_expand_items sets a
/// pair up once per run of its items (context() again only when k changes).
__device__ inline void warp_range(std::uint32_t count, std::uint32_t& begin, std::uint32_t& end) {
  const unsigned long long per = (static_cast<unsigned long long>(count) + warp_count() - 1) / warp_count();
  const unsigned long long b = global_warp() * per;
  const unsigned long long e = b + per;
  begin = b < count ? static_cast<std::uint32_t>(b) : count;
  end = e < count ? static_cast<std::uint32_t>(e) : count;
}

/// Expand step `step` of `item` (pair item.k, set up as c), by the warp: the descendants of
/// its cells at the next step, tested and appended (test_cells; `last`: the step before the
/// leaves, whose leaves run here when `leaves` is not null).
template <bool kLean = false>
__device__ inline void expand_item(const MidListDesc& d, const PairContext& c, const MidItem& item, int step,
                                   bool last, Tally& t, LeafTiles* leaves) {
  const bool mesh_box = c.s.kind == hd::PairKind::MeshBox;
  std::uint32_t a0, a1, b0 = 0, b1 = 1;
  hd::descendants(c.a.octree, item.ca, step_level(d, c, step, false), step_level(d, c, step + 1, false), a0, a1);
  if (!mesh_box)
    hd::descendants(c.b.octree, item.cb, step_level(d, c, step, true), step_level(d, c, step + 1, true), b0, b1);
  test_cells<kLean>(d, c, item.k, a0, a1, b0, b1, last, t, leaves);
}

/// mid_expand's work: one warp per item of step `step` (warp_range of the list).
/// `tiles`: the block's LeafTiles (blockDim.x == kBlockSize) when the last step may run its
/// leaves itself (fuse_leaves), or null (never).
template <bool kLean = false>
__device__ inline void mid_expand_items(const MidListDesc& d, int step, LeafTiles* tiles = nullptr) {
  const std::uint32_t count = *d.in_count < d.in_capacity ? *d.in_count : d.in_capacity;
  const bool last = step + 2 == d.steps;
  LeafTiles* leaves = last && tiles != nullptr && fuse_leaves(d, count) ? tiles : nullptr;
  Tally t;
  std::uint32_t begin, end;
  warp_range(count, begin, end);
  PairContext c;
  bool have = false;  // c is the set-up of pair ck
  std::uint32_t ck = 0;
  for (std::uint32_t it = begin; it < end; ++it) {
    const MidItem item = d.in[it];
    if (skip_confirmed<kLean>(d, item.k)) continue;  // early exit: neither set up nor counted
    if (!have || item.k != ck) {
      c = context(d, item.k, d.pairs[item.k]);
      ck = item.k;
      have = true;
    }
    expand_item<kLean>(d, c, item, step, last, t, leaves);
  }
  flush(d, t);
}

/// mid_leaf's work: one warp per item of the last step, every warp_count()-th item from
/// the warp's own index on (a large cell pair's items are appended together, and those near
/// its contact cost the most: striding spreads them over the warps where a contiguous share
/// per warp put them on a few); `tiles` is the block's shared memory (blockDim.x ==
/// kBlockSize). kWitness: as leaf_item.
template <bool kWitness, bool kLean = false>
__device__ inline void mid_leaf_items(const MidListDesc& d, LeafTiles& tiles) {
  const WarpTiles warp = warp_tiles(d, tiles);
  const std::uint32_t count = *d.in_count < d.in_capacity ? *d.in_count : d.in_capacity;
  Tally t;
  for (std::uint32_t it = global_warp(); it < count; it += warp_count()) {
    const MidItem item = d.in[it];
    if (skip_confirmed<kLean>(d, item.k)) continue;  // early exit: neither set up nor counted
    // Set up per item: keeping the set-up across a run of the same pair's items (as
    // mid_expand_items does) takes 89 registers here, or spills 352 bytes at 64.
    const PairContext c = context(d, item.k, d.pairs[item.k]);
    leaf_item<kWitness, kLean>(d, c, item.k, item.ca, item.cb, item.chunk, warp, t);
  }
  flush(d, t);
}

/// The midphase of the fused small step's lean kernel, a block per pair: pairs k =
/// blockIdx.x, blockIdx.x + gridDim.x, ... of the np live pairs (pair k: pair_of(k), a
/// block-local look-up, so the sorted keys need not be visible yet); for each, warp 0 sets the
/// pair up and runs its start, then each step's items are shared by the block's warps
/// (items w, w + warps, ... to warp w), the steps and the leaves apart by __syncthreads: no
/// grid-wide barrier between the start, the expand steps and the leaves. The block's lists
/// are its own segments of the two lists (`capacity` items each from blockIdx.x *
/// capacity on, blockIdx.x < kBlockPairSegments; their counts `counts`, steps entries of
/// the block's shared memory), which hold one pair's items at a time: the same items, the
/// same tests and counts as the grid's lists. st_counts[1 + i] gets, by atomicMax, each
/// pair's count of list i times kBlockPairSegments: a segment that overflowed then reads
/// above the lists' capacity, the host's regrow test (grow_if_needed), and the regrown
/// segments hold it. `md` is the block's descriptor in shared memory, whose lists thread 0
/// sets; `tiles` the block's leaf tiles. Every thread of the block calls it (block-uniform
/// loops).
template <bool kLean, class PairOf>
__device__ inline void mid_block_pairs(MidListDesc& md, std::uint32_t np, PairOf&& pair_of, MidItem* const* lists,
                                       std::uint32_t capacity, std::uint32_t* counts, std::uint32_t* st_counts,
                                       LeafTiles& tiles) {
  const MidListDesc& d = md;
  const std::uint32_t warp = threadIdx.x >> 5;
  const std::uint32_t warps = blockDim.x >> 5;
  const int steps = d.steps;
  const std::size_t base = static_cast<std::size_t>(blockIdx.x) * capacity;
  const WarpTiles leaf_tiles = warp_tiles(d, tiles);
  Tally t;
  for (std::uint32_t k = blockIdx.x; k < np; k += gridDim.x) {
    if (threadIdx.x == 0) {
      for (int i = 0; i < steps; ++i) counts[i] = 0;
      md.out = lists[0] + base;
      md.out_count = counts;
      md.out_capacity = capacity;
    }
    __syncthreads();
    const Pair p = pair_of(k);
    const PairContext c = context(d, k, p);  // every warp's, set up while warp 0 starts
    if (warp == 0) {
      if (lane_id() == 0) d.pairs[k] = p;
      start_pair<kLean>(d, k, c, false, t);
    }
    __syncthreads();
    if (counts[0] == 0) continue;  // decided alone, or no cell pair: done
    for (int i = 0; i < steps; ++i) {
      const bool leaves = i + 1 == steps;
      if (threadIdx.x == 0) {
        md.in = lists[i % 2] + base;
        md.in_count = counts + i;
        md.in_capacity = capacity;
        md.out = leaves ? nullptr : lists[(i + 1) % 2] + base;
        md.out_count = leaves ? nullptr : counts + i + 1;
      }
      __syncthreads();
      const std::uint32_t count = counts[i] < capacity ? counts[i] : capacity;
      for (std::uint32_t it = warp; it < count; it += warps) {
        const MidItem item = d.in[it];
        if (leaves) leaf_item<false, kLean>(d, c, k, item.ca, item.cb, item.chunk, leaf_tiles, t);
        else expand_item<kLean>(d, c, item, i, i + 2 == steps, t, nullptr);
      }
      __syncthreads();
    }
    if (threadIdx.x == 0) {
      for (int i = 0; i < steps; ++i) {
        const unsigned long long scaled = static_cast<unsigned long long>(counts[i]) * kBlockPairSegments;
        atomicMax(st_counts + 1 + i, scaled < 0xffffffffull ? static_cast<std::uint32_t>(scaled) : 0xffffffffu);
      }
    }
  }
  flush(d, t);
}

}  // namespace mid
}  // namespace gpu
}  // namespace octocd
