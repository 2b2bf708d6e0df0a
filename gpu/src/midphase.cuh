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
//
// The parts, each a header that includes the one before: midphase_warp.cuh (a pair's set-up,
// the warp's counters and appends), midphase_tiles.cuh (vertex tiles and their tests),
// midphase_leaf.cuh (leaf items, cell pairs, the first step), midphase_witness.cuh (the
// witness cache); this file: the work of each kernel (start, decide, expand, leaf, the lean
// block per pair).
#include "midphase_witness.cuh"

namespace octocd {
namespace gpu {
namespace mid {

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

/// mid_start's work on pair k (every lane of the warp; passed: the witness pass ran, which
/// wrote pairs[k] and, for a pair it neither confirmed nor decided, witness[k] = `passed_w`,
/// the failed witness or kNoWitness).
template <bool kWitness, bool kLean = false>
__device__ inline void start_item(const MidListDesc& d, std::uint32_t k, bool witnesses, bool passed,
                                  unsigned long long passed_w, Tally& t) {
  // The pair from its sorted key (the broadphase's output), kept for the later stages.
  const unsigned long long key = d.pair_keys[k];
  const Pair p = unpack_pair(d, key);
  if (!passed && lane_id() == 0) d.pairs[k] = p;
  if (witnesses) {
    unsigned long long w = kNoWitness;  // the last witness, tested and failed (or none)
    if (passed) {
      w = passed_w;
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
        return;
      }
    }
    unsigned long long found = kNoWitness;
    if (w != kNoWitness && witness_block_close(d, p, w, t, found)) {
      if (lane_id() == 0) {
        d.confirmed[k] = 1;
        d.wit.witness[k] = found;
      }
      return;
    }
  }
  start_pair<kLean>(d, k, context(d, k, p), witnesses, t);
}

/// mid_start's work: one warp per live candidate pair (grid-stride over the whole grid:
/// warp g runs pairs g, g + warps, g + 2 warps, ...).
/// With the witness cache on, a pair is first tested at its last witness (witness_close,
/// before its set-up; by mid_witness_items when witness_pass, else here by lane 0), then,
/// when that fails, at the vertex blocks beside it (witness_block_close): a pair still
/// within theta there is confirmed and keeps the vertex pair found, with no set-up and no
/// cell test. After the witness pass the warp reads 32 of its pairs' answers at once (a
/// lane each) and runs only those the pass left open (not confirmed, not kStaticStatic),
/// in the same order: a pass that settled most pairs leaves no chain of loads per pair.
/// !kWitness: compiled without the cache (the fused small step).
template <bool kWitness, bool kLean = false>
__device__ inline void mid_start_items(const MidListDesc& d) {
  const std::uint32_t np = *d.pair_count < d.pair_capacity ? *d.pair_count : d.pair_capacity;
  const bool witnesses = kWitness && d.wit.witness != nullptr;
  const bool passed = witnesses && witness_pass(d, np);  // pairs[k] and confirmed[k] written
  Tally t;
  if (passed) {
    const unsigned long long g = global_warp();
    const unsigned long long warps = warp_count();
    for (unsigned long long r = 0; g + r * warps < np; r += 32) {
      const unsigned long long mine = g + (r + lane_id()) * warps;  // this lane's pair
      unsigned long long w = kNoWitness;
      bool open = false;
      if (mine < np && d.confirmed[mine] == 0) {
        w = d.wit.witness[mine];
        open = w != kStaticStatic;
      }
      for (unsigned m = __ballot_sync(kFull, open); m != 0; m &= m - 1u) {
        const int j = __ffs(m) - 1;
        const unsigned long long wj = __shfl_sync(kFull, w, j);
        start_item<kWitness, kLean>(d, static_cast<std::uint32_t>(g + (r + static_cast<unsigned long long>(j)) * warps),
                                    witnesses, true, wj, t);
      }
    }
  } else {
    for (std::uint32_t k = global_warp(); k < np; k += warp_count())
      start_item<kWitness, kLean>(d, k, witnesses, false, kNoWitness, t);
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
