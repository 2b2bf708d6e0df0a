// Broadphase `octree` on the device: the loose octree of design.md section 5.1 (Ulrich 2000, looseness
// 2) with every cell and level decision from octocd/loose_octree.hpp, the header the CPU
// tree (core/src/broadphase_octree_tree.cpp) uses. Steps (orchestrated by cuda_world.cpp):
// 1. keys: D_w (the scene's, or `auto` from the smallest body extent: a block minimum,
//    then one atomicMin per block on the float's bits),
//    then per body loose_place_unit -> (level, Morton cell) key, the overflow key, a stray
//    key (a body outside the root cube: see "Stray bodies" at loose_keys_kernel), or the
//    NaN key (the query recomputes its unit box in fixed point, loose_q_min / loose_q_max,
//    from the slot's AABB);
// 2. a stable radix sort by key: slot order = (key, body), so every occupied cell is a
//    contiguous run of slots and the levels follow each other in key order (with a fixed
//    D_w the overflow, stray and NaN keys follow level D_w's cells, so the sort covers only
//    the bits they need);
// 3. a level table (first slot of every level, of the overflow list, of the stray bodies
//    of each level by size and of the NaN bodies) and a hash table of the occupied blocks
//    (aligned 2 x 2 x 2 groups of cells, whose slots are one run: loose_blocks.hpp; one 64-bit entry per block, its key and
//    its first slot, open addressing with linear probing, at most half full) and the
//    occupancy map (a byte per block in key order, a bit per occupied cell, for the levels
//    that fit footprint::loose_occupancy_blocks: loose_blocks.hpp), then a query per slot:
//    - a body in a cell (level l) looks at every level m <= l that holds bodies: the
//      cells whose loose boxes meet its own box (loose_query_axis_q: at most 4 per axis);
//      from kWarpQueryBodies bodies one thread per slot probes the blocks that hold
//      them (at most 3 per axis, 2 for a window of 3 cells: 8 probes where a probe per
//      cell took 27), but only a block whose byte in the occupancy map has an occupied
//      cell in the window (at 10^6 bodies most blocks of a window are empty), and walks
//      each block's run, skipping the slots of cells outside the window (the block's
//      octant mask), so it tests exactly the slots of the window's cells; below, one warp per
//      slot, a lane per cell (its run found through its block); at m = l it keeps only
//      slots after its own (a block or cell whose keys all precede its own is not even
//      looked up), at m < l every body;
//      a body in a cell also tests the stray bodies of the levels above its own;
//    - an overflow body tests the overflow and stray bodies after it; a stray body tests
//      the stray bodies after it (with the thread query: loose_lists_kernel, a warp per
//      slot) and, as a body of its level by size would, the cells of the levels up to it
//      that its box meets (none when it is far outside);
//    then the exact AABB test (octocd::overlaps, Eq. 6). A second kernel, one thread per
//    in-tree slot, tests it against every overflow body (walls: a handful, each of which
//    would otherwise scan all n slots with one warp). Each overlapping pair is met exactly
//    once (same level: by the smaller slot; across levels: by the finer body; with the
//    overflow list: by the in-tree body, or the smaller overflow slot; with a stray body:
//    by the finer one, or the smaller slot), because a body's
//    box lies in its cell's loose box and the query ranges are exact;
// 4. the pairs are appended as keys (a << shift) | b (PairOutput::shift) with one atomic
//    per group of threads that append together (their order varies; the set does not;
//    the thread query keeps a thread's first pairs until the end and appends the warp's
//    with one atomic: one atomic on the total per pair bounded it at 10^6 bodies),
//    then radix-sorted by the caller: the sorted unique set `flat` gives. Given
//    PairOutput::scratch (sorts_pairs()), the octree sorts them itself, without a radix
//    sort of the pairs (5 or 6 passes of 8 bits over 2 bits(n) bits): the queries append
//    into the scratch and count the pairs of each smaller body a (one atomicAdd each); an
//    exclusive scan of the n counts gives each a's segment of the output; each pair goes
//    to its segment (one atomicSub: any order within it); then each segment is sorted on
//    its own: one thread per body for at most kLocalSortMax keys (insertion sort in
//    place), one block for at most kBlockSortMax (a CUB block radix sort of the keys'
//    low words over the bits of b: a segment shares its a), else (a huge
//    segment: a body that overlaps thousands of bodies of larger index, as the floor of a
//    pile) its chunks of kBlockSortMax keys spread over the blocks: a block radix sort each,
//    then each key's rank from binary searches in the other chunks, then the copy back (one
//    block per segment took 0.5 ms a step on bunny-pile-1m's floor). Pairs that do not fit
//    the output are copied from the scratch as they are (keys [0, capacity), any order; the caller grows
//    the output and runs find() again).
#include <cstdlib>
#include <string>

#include <cub/block/block_radix_sort.cuh>
#include <cub/block/block_reduce.cuh>
#include <cuda/functional>
#include <cub/device/device_scan.cuh>

#include "broadphase_common.cuh"
#include "broadphase_key_sort.cuh"
#include "device_broadphase.hpp"
#include "device_buffer.hpp"
#include "device_footprint.hpp"
#include "kernels.hpp"
#include "loose_blocks.hpp"
#include "scanned_counts.hpp"
#include "octocd/cuda_world.hpp"

namespace octocd {
namespace gpu {
namespace {


/// Below this many bodies the query runs one warp per slot, from it one thread per slot
/// (where the thread query overtakes the warp's in bench_gpu_broadphase on the H100:
/// reports/h100/README.md, "Experiments and A/B results", "Broadphases").
constexpr std::uint32_t kWarpQueryBodies = 32768;

/// A body's unit box in the fixed point of loose_q_min / loose_q_max.
struct LooseQBox {
  std::int32_t lo[3];
  std::int32_t hi[3];
};

/// The fixed-point unit box of a body's AABB, computed where the query needs it (from
/// the slot's AABB, bit for bit what loose_keys_kernel placed the body with: the same
/// functions of the same floats; a stored copy per body and per slot cost 48 bytes of
/// traffic a body).
__device__ inline LooseQBox loose_qbox(const LooseGrid& g, const Aabb& b) {
  const Vec3 lo = loose_unit(g, b.min);
  const Vec3 hi = loose_unit(g, b.max);
  return {{loose_q_min(lo.x), loose_q_min(lo.y), loose_q_min(lo.z)},
          {loose_q_max(hi.x), loose_q_max(hi.y), loose_q_max(hi.z)}};
}

/// The root cube and D_w of one find() with the snapped root (loose_snapped_grid).
struct LooseRoot {
  LooseGrid grid;
  int depth = 0;
};

/// What the kernels read and write (device pointers).
struct LooseDesc {
  const Aabb* aabb = nullptr;      ///< world AABBs, per body
  std::uint32_t n = 0;             ///< bodies
  LooseGrid grid;                  ///< root cube of the scene's domain
  int depth = 2;                   ///< D_w in [0, 10]; -1 = auto (root->depth)
  /// One float (auto depth): the smallest extent (largest unit side of a body's box),
  /// as its bits (non-negative floats order as their bits); kMinExtentInit before the
  /// minimum.
  float* min_extent = nullptr;
  /// Depth `auto`: one LooseRoot that loose_root_kernel writes from *min_extent
  /// (loose_snapped_grid: exact tests 0.21-0.93 x those of the domain's cube on the bench
  /// boxes at 10^4 .. 4x10^6); the keys and the queries then use its grid and depth instead
  /// of `grid` and `depth`. nullptr: a fixed depth.
  LooseRoot* root = nullptr;
  /// The sort keys after the cells': overflow_key (the overflow list), then the stray
  /// bodies' stray_key(d, l) = overflow_key + 1 + l (l in [0, 10]: the level by size), then
  /// nan_key = overflow_key + kLooseMaxDepth + 2; overflow_key is the first key after level
  /// D_w's cells (loose_level_base(D_w + 1); kLooseKeysEnd for D_w = 10 and depth `auto`),
  /// so the key sort covers only the bits they need (D_w = 2: 7 bits, one radix pass instead
  /// of four).
  std::uint32_t overflow_key = 0;
  std::uint32_t nan_key = 0;
  std::uint32_t* key = nullptr;    ///< per body: cell key, overflow_key, a stray key or nan_key
  std::uint32_t* body = nullptr;   ///< per body: its index (the sort's values)
  const std::uint32_t* sorted_key = nullptr;   ///< per slot: key, ascending
  const std::uint32_t* slot_body = nullptr;    ///< per slot: body (stable: body order per cell)
  Aabb* slot_box = nullptr;        ///< per slot: the body's AABB
  /// The level table (kLevelTable entries): per level m in [0, kLooseMaxDepth] the first
  /// slot whose key is >= level m's base; then (kOverflowEntry) the first overflow slot; per
  /// stray level l (kStrayEntry + l) the first stray slot of level l or above; then
  /// (kNanEntry) the first NaN slot.
  std::uint32_t* level_begin = nullptr;
  /// The block table, cell_mask + 1 entries (loose_blocks.hpp): loose_block_entry(block
  /// key, first slot), kLooseBlockEmpty where empty.
  unsigned long long* cell_table = nullptr;
  std::uint32_t cell_mask = 0;     ///< table size - 1 (a power of two >= 2 n)
  /// The occupancy map (loose_blocks.hpp): occupancy_blocks bytes as 32-bit words; the
  /// words levels 0 .. D_w use are cleared by loose_keys_kernel and set by
  /// loose_gather_kernel.
  std::uint32_t* occupancy = nullptr;
  std::uint32_t occupancy_blocks = 0;
  unsigned long long* pair_keys = nullptr;  ///< out: (a << shift) | b, appended in any order
  /// Sorted mode (PairOutput::scratch given; pair_keys is then the scratch): per body a,
  /// n + 1 entries zeroed before the query, the pairs (a, b) appended; else nullptr.
  std::uint32_t* pair_count = nullptr;
  int shift = 32;                           ///< PairOutput::shift
  std::uint32_t capacity = 0;               ///< entries pair_keys holds
  std::uint32_t* total = nullptr;           ///< out: pairs found (may exceed capacity)
  unsigned long long* candidates = nullptr; ///< out (added): exact AABB tests
};

/// The byte cudaMemset fills min_extent with: 0x7f7f7f7f = 3.4e38, above every extent that
/// gives a depth other than 0 (loose_auto_depth of it and of +inf, all NaN bodies, is 0).
constexpr int kMinExtentInit = 0x7f;

__global__ void loose_extent_kernel(LooseDesc d) {
  using Reduce = cub::BlockReduce<std::uint32_t, kBlockSize>;
  __shared__ typename Reduce::TempStorage storage;
  const std::uint32_t i = blockIdx.x * blockDim.x + threadIdx.x;
  std::uint32_t bits = 0x7f800000u;  // +inf: no body, or a NaN extent
  if (i < d.n) {
    const Aabb b = d.aabb[i];
    const float ext = loose_unit_extent(loose_unit(d.grid, b.min), loose_unit(d.grid, b.max));
    // As the CPU driver: NaN extents are left out of the minimum; negative (and -0) are 0
    // (+0: the bits of non-negative floats order as the floats).
    if (ext == ext) bits = ext > 0.0f ? __float_as_uint(ext) : 0u;
  }
  const std::uint32_t m = Reduce(storage).Reduce(bits, cuda::minimum<>{});
  if (threadIdx.x == 0) atomicMin(reinterpret_cast<unsigned int*>(d.min_extent), m);
}

/// One thread: the snapped root from the smallest extent (LooseDesc::root).
__global__ void loose_root_kernel(LooseDesc d) {
  LooseRoot r;
  r.grid = loose_snapped_grid(d.grid, *d.min_extent, &r.depth);
  *d.root = r;
}

/// The root cube of this find(): the snapped one when LooseDesc::root is given.
__device__ inline LooseGrid loose_call_grid(const LooseDesc& d) { return d.root ? d.root->grid : d.grid; }

/// The sort key of a stray body whose level by size is l (LooseDesc::overflow_key).
__device__ inline std::uint32_t stray_key(const LooseDesc& d, int l) {
  return d.overflow_key + 1u + static_cast<std::uint32_t>(l);
}

/// Stray bodies (the keys between overflow_key and nan_key): a body whose box fits a
/// level by size (loose_level_for_extent) but not the loose box of its cell there (its
/// centre lies outside the root cube: a body that left the domain) climbs in the CPU's
/// octree to a coarser level, or to the overflow list, where every query of its level's
/// cells (at the coarse levels: every body) tests it. On the device it is kept out of the
/// cells and sorted by its level by size l; the pairs with it are met once each:
/// - a body of a cell of level m <= l: by the stray body, which queries the cells of
///   levels 0 .. l whose loose boxes meet its box (loose_query_axis_q: clamped to the
///   grid, at most 4 per axis as for a body of level l; none when the box is beyond the
///   loose boxes of the grid's edge), every slot of those cells;
/// - a body of a cell of level m > l: by that body, which tests the stray bodies of
///   levels < m (a run of the stray keys);
/// - an overflow body: by the overflow body (it tests every slot after its own);
///   another stray body: by the smaller slot.
/// Exact as the cells are: a body's box lies in its cell's loose box, so a stray box
/// that overlaps it meets that loose box. (Climbing, the 2,800 bunnies bunny-pile-100k
/// throws over its walls by frame 2700 would make the queries test 1.5 x 10^8 slots a step;
/// kept apart, 5.4 x 10^6.)
__global__ void loose_keys_kernel(LooseDesc d) {
  const std::uint32_t i = blockIdx.x * blockDim.x + threadIdx.x;
  const int depth = d.root ? d.root->depth : d.depth;
  // The occupancy words of levels 0 .. D_w, cleared by the whole grid (the previous
  // find's queries are done: stream order; loose_gather_kernel sets them after the sort).
  const std::uint32_t words = loose_occupancy_words(d.occupancy_blocks, depth);
  for (std::uint32_t w = i; w < words; w += gridDim.x * blockDim.x) d.occupancy[w] = 0u;
  if (i >= d.n) return;
  const LooseGrid grid = loose_call_grid(d);
  const Aabb b = d.aabb[i];
  d.body[i] = i;
  if (loose_has_nan(b)) {
    d.key[i] = d.nan_key;
    return;
  }
  const Vec3 lo = loose_unit(grid, b.min);
  const Vec3 hi = loose_unit(grid, b.max);
  const LoosePlace p = loose_place_unit(lo, hi, depth);
  const int by_size = loose_level_for_extent(loose_unit_extent(lo, hi), depth);
  if (by_size >= 0 && p.level < by_size) d.key[i] = stray_key(d, by_size);  // climbed (or overflow)
  else d.key[i] = p.level == kLooseOverflowLevel ? d.overflow_key : loose_place_key(p);
}

/// First slot in [lo, hi) whose key is >= key.
__device__ std::uint32_t lower_bound(const std::uint32_t* keys, std::uint32_t lo, std::uint32_t hi,
                                     std::uint32_t key);

/// Level table entries (LooseDesc::level_begin): levels 0..10, overflow, stray levels
/// 0..10, NaN.
constexpr int kOverflowEntry = kLooseMaxDepth + 1;
constexpr int kStrayEntry = kLooseMaxDepth + 2;
constexpr int kNanEntry = 2 * kLooseMaxDepth + 3;
constexpr int kLevelTable = kNanEntry + 1;
static_assert(kLevelTable == static_cast<int>(footprint::kLooseLevelTable), "device_footprint.hpp: level table");

__global__ void loose_gather_kernel(LooseDesc d) {
  const std::uint32_t s = blockIdx.x * blockDim.x + threadIdx.x;
  if (s < kLevelTable) {  // the level table (the sorted keys are complete)
    // Levels deeper than D_w hold no body: their entries are the overflow list's start.
    const std::uint32_t base = s <= static_cast<std::uint32_t>(kLooseMaxDepth)
                                   ? min(loose_level_base(static_cast<int>(s)), d.overflow_key)
                                   : d.overflow_key + (s - static_cast<std::uint32_t>(kOverflowEntry));
    d.level_begin[s] = lower_bound(d.sorted_key, 0, d.n, base);
  }
  if (s >= d.n) return;
  const std::uint32_t body = d.slot_body[s];
  d.slot_box[s] = d.aabb[body];
  // The block table: the first slot of a block's run claims an empty entry (one per
  // block, so a claimed entry is another block's: probe on; at most half full).
  const std::uint32_t key = d.sorted_key[s];
  if (key >= d.overflow_key) return;
  const int level = loose_cell_key_level(key);
  // The occupancy map: the first slot of a cell sets the cell's bit.
  if (s == 0 || d.sorted_key[s - 1] != key) {
    std::uint32_t w = 0;
    const std::uint32_t bit = loose_occupancy_bit(key, level, d.occupancy_blocks, &w);
    if (bit != 0) atomicOr(&d.occupancy[w], bit);
  }
  if (!loose_block_first(d.sorted_key, s, level)) return;
  const unsigned long long entry = loose_block_entry(loose_block_key(key, level), s);
  std::uint32_t h = loose_block_hash(loose_block_key(key, level), d.cell_mask);
  while (atomicCAS(&d.cell_table[h], kLooseBlockEmpty, entry) != kLooseBlockEmpty) h = (h + 1) & d.cell_mask;
}

/// The first slot of block `block_key` (kLooseNoSlot when it holds no body).
__device__ inline std::uint32_t find_block(const LooseDesc& d, std::uint32_t block_key) {
  return loose_block_find(d.cell_table, d.cell_mask, block_key);
}

/// The occupancy byte of block `block_key` (0xff outside the map).
__device__ inline std::uint32_t block_octants(const LooseDesc& d, std::uint32_t block_key) {
  return loose_block_octants(d.occupancy, d.occupancy_blocks, block_key);
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


/// Appends `key` for every lane with `hit` (every lane of the warp calls it): one atomic
/// per warp, the keys in lane order after base (those below the capacity).
__device__ inline void warp_emit(const LooseDesc& d, bool hit, unsigned long long key) {
  const std::uint32_t lane = threadIdx.x & 31u;
  const unsigned mask = __ballot_sync(bp::kFullMask, hit);
  if (mask == 0) return;
  std::uint32_t base = 0;
  if (lane == 0) base = atomicAdd(d.total, static_cast<std::uint32_t>(__popc(mask)));
  base = __shfl_sync(bp::kFullMask, base, 0);
  if (hit) {
    const std::uint32_t idx = base + static_cast<std::uint32_t>(__popc(mask & ((1u << lane) - 1u)));
    if (idx < d.capacity) d.pair_keys[idx] = key;
    if (d.pair_count) atomicAdd(&d.pair_count[key >> d.shift], 1u);
  }
}

/// One warp's query for slot s: the lanes test candidate slots 32 at a time and append
/// the overlapping pairs (by body index, a < b) with one atomic per round that hits.
struct WarpEmitter {
  const LooseDesc& d;
  std::uint32_t lane;
  unsigned long long tests = 0;  // warp-uniform
  std::uint32_t body_s;
  Aabb box_s;

  /// One round: the lanes with `valid` test slot t (every lane calls it).
  __device__ void test(bool valid, std::uint32_t t) {
    const bool hit = valid && overlaps(box_s, d.slot_box[t]);
    warp_emit(d, hit, hit ? bp::pair_key(body_s, d.slot_body[t], d.shift) : 0ull);
  }

  /// Tests slots [t0, t1) (warp-uniform bounds).
  __device__ void range(std::uint32_t t0, std::uint32_t t1) {
    if (t0 >= t1) return;
    tests += t1 - t0;
    for (std::uint32_t b = t0; b < t1; b += 32) test(b + lane < t1, b + lane);
  }

  /// Tests the concatenation of every lane's run [t0, t1) (each lane its own bounds):
  /// an inclusive warp scan of the run lengths, then candidate j of a round belongs to
  /// the lane whose run holds it (a 5-step binary search over the lanes' offsets).
  __device__ void runs(std::uint32_t t0, std::uint32_t t1) {
    const std::uint32_t len = t1 > t0 ? t1 - t0 : 0u;
    std::uint32_t incl = len;
    for (unsigned o = 1; o < 32; o <<= 1) {
      const std::uint32_t v = __shfl_up_sync(bp::kFullMask, incl, o);
      if (lane >= o) incl += v;
    }
    const std::uint32_t total = __shfl_sync(bp::kFullMask, incl, 31);
    if (total == 0) return;
    tests += total;
    for (std::uint32_t k = 0; k < total; k += 32) {
      const std::uint32_t j = k + lane;
      // owner = the first lane whose inclusive offset exceeds j.
      std::uint32_t lo = 0;
      for (std::uint32_t step = 16; step > 0; step >>= 1) {
        const std::uint32_t probe = __shfl_sync(bp::kFullMask, incl, lo + step - 1);
        if (probe <= j) lo += step;
      }
      const std::uint32_t owner_t0 = __shfl_sync(bp::kFullMask, t0, lo);
      const std::uint32_t owner_incl = __shfl_sync(bp::kFullMask, incl, lo);
      const std::uint32_t owner_len = __shfl_sync(bp::kFullMask, len, lo);
      const bool valid = j < total;
      test(valid, owner_t0 + (j - (owner_incl - owner_len)));
    }
  }
};

/// One warp per slot (below kWarpQueryBodies bodies, where one thread per slot would
/// leave the device idle behind each thread's chain of lookups): the lanes look up the
/// (at most 4 x 4 x 4) cells of a level in the cell table at once, then the warp tests
/// the concatenated runs.
__global__ void loose_query_warp_kernel(LooseDesc d) {
  const std::uint32_t lane = threadIdx.x & 31u;
  const std::uint32_t s = (blockIdx.x * blockDim.x + threadIdx.x) >> 5;
  WarpEmitter e{d, lane};
  if (s < d.n) {
    const std::uint32_t key = d.sorted_key[s];
    e.body_s = d.slot_body[s];
    e.box_s = d.slot_box[s];
    if (key >= d.overflow_key && key < d.nan_key) {
      e.range(s + 1, d.level_begin[kNanEntry]);  // the overflow and stray bodies after it
    }
    if (key != d.overflow_key && key != d.nan_key) {  // a cell's body or a stray one (a NaN box overlaps nothing)
      const bool stray = key > d.overflow_key;
      // Stray: its level by size, no own cell (every slot of the cells it meets).
      const int level = stray ? static_cast<int>(key - d.overflow_key - 1u) : loose_cell_key_level(key);
      const int own = stray ? -1 : level;
      const LooseQBox q = loose_qbox(loose_call_grid(d), e.box_s);
      // A cell's body: the stray bodies of the levels above its own.
      if (!stray) e.range(d.level_begin[kStrayEntry], d.level_begin[kStrayEntry + level]);
      for (int m = 0; m <= level; ++m) {
        if (d.level_begin[m] == d.level_begin[m + 1]) continue;  // no body at this level
        const LooseRange rx = loose_query_axis_q(q.lo[0], q.hi[0], m);
        const LooseRange ry = loose_query_axis_q(q.lo[1], q.hi[1], m);
        const LooseRange rz = loose_query_axis_q(q.lo[2], q.hi[2], m);
        const int nx = rx.hi - rx.lo + 1, ny = ry.hi - ry.lo + 1, nz = rz.hi - rz.lo + 1;
        const int cells = nx * ny * nz;
        for (int c0 = 0; c0 < cells; c0 += 32) {
          // Lane c finds cell c0 + c's slot run [t0, t1) (empty: t0 == t1).
          std::uint32_t t0 = 0, t1 = 0;
          const int c = c0 + static_cast<int>(lane);
          if (c < cells) {
            const int ix = rx.lo + c % nx, iy = ry.lo + (c / nx) % ny, iz = rz.lo + c / (nx * ny);
            const std::uint32_t ck = loose_cell_key(m, static_cast<std::uint32_t>(ix), static_cast<std::uint32_t>(iy),
                                                    static_cast<std::uint32_t>(iz));
            // Same level: only the slots after s, so no cell before s's own (its slots all
            // come before s in key order) is looked up.
            if (m != own || ck >= key) {
              loose_cell_run(
                  d.sorted_key, d.n, ck, m, [&](std::uint32_t bk) { return find_block(d, bk); },
                  [&](std::uint32_t bk) { return block_octants(d, bk); }, &t0, &t1);
              if (m == own && t0 <= s) t0 = s + 1 < t1 ? s + 1 : t1;
            }
          }
          e.runs(t0, t1);
        }
      }
    }
  }
  bp::block_add(d.candidates, lane == 0 ? e.tests : 0ull);
}

/// One thread per slot: the loose octree query of the file comment. At each level that
/// holds bodies, the thread probes the blocks that hold the (at most 4 x 4 x 4) cells of
/// its window (at most 3 x 3 x 3) in the block table and tests the slots of the window's
/// cells in each block's run (loose_block_query; at its own level only the slots after
/// its own). Its pairs go through bp::PairBuffer (the warp appends them at the end).
__global__ void __launch_bounds__(kBlockSize, 5) loose_query_kernel(LooseDesc d) {
  const std::uint32_t s = blockIdx.x * blockDim.x + threadIdx.x;
  unsigned long long tests = 0;
  const PairOutput out{d.pair_keys, d.shift, d.capacity, d.total, nullptr};
  bp::PairBuffer pairs;
  auto counted = [&](unsigned long long k) {
    if (d.pair_count) atomicAdd(&d.pair_count[k >> d.shift], 1u);
  };
  if (s < d.n) {
    const std::uint32_t key = d.sorted_key[s];
    const std::uint32_t body = d.slot_body[s];
    const Aabb box = d.slot_box[s];
    // The overflow and stray bodies after an overflow or stray slot: loose_lists_kernel.
    if (key != d.overflow_key && key != d.nan_key) {  // a cell's body or a stray one (a NaN box overlaps nothing)
      const bool stray = key > d.overflow_key;
      // Stray: its level by size, no own cell (every slot of the cells it meets).
      const int level = stray ? static_cast<int>(key - d.overflow_key - 1u) : loose_cell_key_level(key);
      const int own = stray ? -1 : level;
      const LooseQBox q = loose_qbox(loose_call_grid(d), box);
      // A cell's body: the stray bodies of the levels above its own.
      if (!stray) {
        const std::uint32_t e0 = d.level_begin[kStrayEntry], e1 = d.level_begin[kStrayEntry + level];
        tests += e1 > e0 ? e1 - e0 : 0u;
        for (std::uint32_t t = e0; t < e1; ++t)
          if (overlaps(box, d.slot_box[t])) pairs.add(out, bp::pair_key(body, d.slot_body[t], d.shift), counted);
      }
      for (int m = 0; m <= level; ++m) {
        if (d.level_begin[m] == d.level_begin[m + 1]) continue;  // no body at this level
        const LooseRange rx = loose_query_axis_q(q.lo[0], q.hi[0], m);
        const LooseRange ry = loose_query_axis_q(q.lo[1], q.hi[1], m);
        const LooseRange rz = loose_query_axis_q(q.lo[2], q.hi[2], m);
        loose_block_query(
            d.sorted_key, d.n, s, key, own, m, rx, ry, rz, [&](std::uint32_t bk) { return find_block(d, bk); },
            [&](std::uint32_t bk) { return block_octants(d, bk); },
            [&](std::uint32_t t) {
              ++tests;
              if (overlaps(box, d.slot_box[t])) pairs.add(out, bp::pair_key(body, d.slot_body[t], d.shift), counted);
            });
      }
    }
  }
  pairs.flush(out, counted);
  bp::block_add(d.candidates, tests);
}

/// Blocks of loose_lists_kernel (at most; grid-stride over the overflow and stray slots).
constexpr unsigned kListsBlocks = 1024;

/// With the thread query: one warp per overflow or stray slot s (grid-stride over those
/// slots), its lanes testing the overflow and stray slots after s 32 at a time (a thread
/// running such a range alone would set the query's length: bunny-pile-100k throws 2,800
/// bunnies out of its box).
__global__ void loose_lists_kernel(LooseDesc d) {
  const std::uint32_t lane = threadIdx.x & 31u;
  const std::uint32_t first = d.level_begin[kOverflowEntry], end = d.level_begin[kNanEntry];
  const std::uint32_t warps = (gridDim.x * blockDim.x) >> 5;
  WarpEmitter e{d, lane};
  for (std::uint32_t s = first + ((blockIdx.x * blockDim.x + threadIdx.x) >> 5); s < end; s += warps) {
    e.body_s = d.slot_body[s];
    e.box_s = d.slot_box[s];
    e.range(s + 1, end);
  }
  bp::block_add(d.candidates, lane == 0 ? e.tests : 0ull);
}

/// One thread per in-tree slot t: the overflow bodies (slots [overflow_begin, used)) that
/// overlap it. Every thread of a warp walks the same overflow slots (one ballot per
/// overflow body that hits any of them).
__global__ void loose_overflow_kernel(LooseDesc d) {
  const std::uint32_t t = blockIdx.x * blockDim.x + threadIdx.x;
  const std::uint32_t ov_begin = d.level_begin[kOverflowEntry];
  const std::uint32_t ov_end = d.level_begin[kStrayEntry];
  const bool mine = t < ov_begin;
  unsigned long long tests = 0;
  if (ov_begin < ov_end && (blockIdx.x * blockDim.x) < ov_begin) {  // block-uniform
    const Aabb box = mine ? d.slot_box[t] : Aabb{};
    const std::uint32_t body = mine ? d.slot_body[t] : 0u;
    for (std::uint32_t o = ov_begin; o < ov_end; ++o) {
      const bool hit = mine && overlaps(box, d.slot_box[o]);
      warp_emit(d, hit, hit ? bp::pair_key(body, d.slot_body[o], d.shift) : 0ull);
    }
    if (mine) tests = ov_end - ov_begin;
  }
  bp::block_add(d.candidates, tests);
}

/// Segments of at most this many keys are sorted by one thread (insertion sort in place:
/// at most 64 x 63 / 2 moves; a body of a dense pile has a few dozen partners at most).
constexpr std::uint32_t kLocalSortMax = 64;
/// Keys per thread of the block radix sort of longer segments (the keys' low words: a
/// segment shares its body a; 32 KB of shared memory for the block's exchange).
constexpr int kBlockSortItems = 32;
/// Segments of at most this many keys are sorted by one block's radix sort in shared memory.
constexpr std::uint32_t kBlockSortMax = static_cast<std::uint32_t>(kBlockSize * kBlockSortItems);
/// Blocks of loose_long_sort_kernel (each takes long segments one after another) and of the
/// huge segments' kernels (each takes chunks one after another).
constexpr unsigned kLongSortBlocks = 264;

/// What the sorting kernels of the sorted mode read and write (device pointers).
struct LooseSortDesc {
  const unsigned long long* scratch = nullptr;  ///< the appended keys (in any order)
  unsigned long long* scratch_rw = nullptr;     ///< the same, reused by the long sort
  unsigned long long* keys = nullptr;           ///< out: PairOutput::keys
  std::uint32_t* count = nullptr;               ///< per body a: its pairs (consumed by the scatter)
  const std::uint32_t* offset = nullptr;        ///< n + 1: exclusive scan of the counts
  /// n entries: from the front the bodies whose segment is longer than kLocalSortMax (at
  /// most kBlockSortMax: long), from the back those with a longer one (huge).
  std::uint32_t* long_list = nullptr;
  std::uint32_t* long_count = nullptr;          ///< two words, zeroed before: long, huge
  const std::uint32_t* total = nullptr;         ///< the pairs found
  std::uint32_t capacity = 0;
  std::uint32_t n = 0;
  int shift = 32;
};

/// Sorted mode, 1: pair i of the scratch to its body a's segment (in any order within it).
/// When the pairs did not fit (total > capacity) the scratch's keys are copied as they are:
/// the segments then pass the capacity, and the caller, which grows the output and runs
/// find() again, still decodes keys [0, capacity) as pairs (none may be the padding).
__global__ void loose_scatter_kernel(LooseSortDesc d) {
  const std::uint32_t i = blockIdx.x * blockDim.x + threadIdx.x;
  const std::uint32_t total = *d.total;
  if (i >= total || i >= d.capacity) return;
  const unsigned long long k = d.scratch[i];
  if (total > d.capacity) {
    d.keys[i] = k;
    return;
  }
  const auto a = static_cast<std::uint32_t>(k >> d.shift);
  const std::uint32_t pos = d.offset[a] + atomicSub(&d.count[a], 1u) - 1u;
  if (pos < d.capacity) d.keys[pos] = k;
}

/// Sorted mode, 2: one thread per body sorts its segment (at most kLocalSortMax keys) or
/// lists it for loose_long_sort_kernel. Nothing when the pairs did not fit (the caller
/// grows the output and runs find() again).
__global__ void loose_segment_sort_kernel(LooseSortDesc d) {
  const std::uint32_t a = blockIdx.x * blockDim.x + threadIdx.x;
  if (a >= d.n || *d.total > d.capacity) return;
  const std::uint32_t b0 = d.offset[a];
  const std::uint32_t len = d.offset[a + 1] - b0;
  if (len < 2) return;
  if (len > kBlockSortMax) {
    d.long_list[d.n - 1u - atomicAdd(&d.long_count[1], 1u)] = a;
    return;
  }
  if (len > kLocalSortMax) {
    d.long_list[atomicAdd(&d.long_count[0], 1u)] = a;
    return;
  }
  unsigned long long* seg = d.keys + b0;  // this thread's alone
  for (std::uint32_t i = 1; i < len; ++i) {
    const unsigned long long k = seg[i];
    std::uint32_t j = i;
    for (; j > 0 && seg[j - 1] > k; --j) seg[j] = seg[j - 1];
    seg[j] = k;
  }
}

/// Sorts keys [c0, c0 + clen) of `seg` (clen <= kBlockSortMax; every key of a segment has
/// its body a above bit `shift`) with one block's radix sort of their low words over bits
/// [0, shift), the body b (the whole block calls it).
template <class Sort>
__device__ inline void block_sort_chunk(typename Sort::TempStorage& storage, unsigned long long* seg,
                                        std::uint32_t c0, std::uint32_t clen, int shift) {
  const unsigned long long high = (seg[c0] >> shift) << shift;
  const unsigned long long low_mask = (1ull << shift) - 1ull;
  std::uint32_t v[kBlockSortItems];
  for (int k = 0; k < kBlockSortItems; ++k) {
    const std::uint32_t i = threadIdx.x * kBlockSortItems + static_cast<std::uint32_t>(k);
    // Padding: all ones, after every body index (ties keep it after: the sort is stable).
    v[k] = i < clen ? static_cast<std::uint32_t>(seg[c0 + i] & low_mask) : 0xffffffffu;
  }
  Sort(storage).Sort(v, 0, shift);
  for (int k = 0; k < kBlockSortItems; ++k) {
    const std::uint32_t i = threadIdx.x * kBlockSortItems + static_cast<std::uint32_t>(k);
    if (i < clen) seg[c0 + i] = high | v[k];
  }
  __syncthreads();  // the shared storage is reused by the next chunk
}

using LongSort = cub::BlockRadixSort<std::uint32_t, kBlockSize, kBlockSortItems>;


/// Chunk g of the huge segments (length > kBlockSortMax; the chunks of kBlockSortMax keys of
/// each, in list order): its body a, its segment's first key b0 and length len, its first
/// key c0 within the segment; false past the last chunk. Walks the huge list (at most
/// total / kBlockSortMax entries).
__device__ inline bool huge_chunk(const LooseSortDesc& d, std::uint32_t g, std::uint32_t& b0, std::uint32_t& len,
                                  std::uint32_t& c0) {
  const std::uint32_t huge = d.long_count[1];
  for (std::uint32_t j = 0; j < huge; ++j) {
    const std::uint32_t a = d.long_list[d.n - 1u - j];
    b0 = d.offset[a];
    len = d.offset[a + 1] - b0;
    const std::uint32_t chunks = (len + kBlockSortMax - 1) / kBlockSortMax;
    if (g < chunks) {
      c0 = g * kBlockSortMax;
      return true;
    }
    g -= chunks;
  }
  return false;
}

/// Sorted mode, 3: a block radix sort of each long segment (kLocalSortMax < length <=
/// kBlockSortMax) and of each chunk of the huge ones (the kLongSortBlocks blocks take them in
/// turn, so a huge segment's chunks spread over blocks).
__global__ void __launch_bounds__(kBlockSize) loose_long_sort_kernel(LooseSortDesc d) {
  __shared__ typename LongSort::TempStorage storage;
  if (*d.total > d.capacity) return;
  const std::uint32_t lists = d.long_count[0];
  for (std::uint32_t j = blockIdx.x; j < lists; j += gridDim.x) {
    const std::uint32_t a = d.long_list[j];
    const std::uint32_t b0 = d.offset[a];
    block_sort_chunk<LongSort>(storage, d.keys + b0, 0, d.offset[a + 1] - b0, d.shift);
  }
  std::uint32_t b0 = 0, len = 0, c0 = 0;
  for (std::uint32_t g = blockIdx.x; huge_chunk(d, g, b0, len, c0); g += gridDim.x)
    block_sort_chunk<LongSort>(storage, d.keys + b0, c0, len - c0 < kBlockSortMax ? len - c0 : kBlockSortMax, d.shift);
}

/// Sorted mode, 4 (huge segments, after 3): 4a, each key of a huge segment to its rank in
/// the scratch: its index in its sorted chunk plus, per other chunk, a binary search (the
/// keys are distinct).
__global__ void __launch_bounds__(kBlockSize) loose_huge_rank_kernel(LooseSortDesc d) {
  if (*d.total > d.capacity) return;
  std::uint32_t b0 = 0, len = 0, own = 0;
  for (std::uint32_t g = blockIdx.x; huge_chunk(d, g, b0, len, own); g += gridDim.x) {
    const unsigned long long* seg = d.keys + b0;
    const std::uint32_t end = len - own < kBlockSortMax ? len : own + kBlockSortMax;
    for (std::uint32_t i = own + threadIdx.x; i < end; i += blockDim.x) {
      const unsigned long long k = seg[i];
      std::uint32_t rank = i - own;
      for (std::uint32_t c0 = 0; c0 < len; c0 += kBlockSortMax) {
        if (c0 == own) continue;
        const std::uint32_t c1 = len - c0 < kBlockSortMax ? len : c0 + kBlockSortMax;
        rank += bp::lower_bound_u64(seg, c0, c1, k) - c0;
      }
      d.scratch_rw[b0 + rank] = k;
    }
  }
}

/// 4b: the huge segments back from the scratch, in order.
__global__ void __launch_bounds__(kBlockSize) loose_huge_copy_kernel(LooseSortDesc d) {
  if (*d.total > d.capacity) return;
  std::uint32_t b0 = 0, len = 0, c0 = 0;
  for (std::uint32_t g = blockIdx.x; huge_chunk(d, g, b0, len, c0); g += gridDim.x) {
    const std::uint32_t end = len - c0 < kBlockSortMax ? len : c0 + kBlockSortMax;
    for (std::uint32_t i = c0 + threadIdx.x; i < end; i += blockDim.x) d.keys[b0 + i] = d.scratch_rw[b0 + i];
  }
}

/// `octree` on the device (see the file comment).
class LooseOctreeDevice final : public DeviceBroadPhase {
 public:
  LooseOctreeDevice(int depth, const Aabb& domain, LooseOctreeQuery query)
      : depth_(depth), grid_(loose_grid(domain)), query_(query) {
    overflow_key_ = depth_ >= 0 && depth_ < kLooseMaxDepth ? loose_level_base(depth_ + 1) : kLooseKeysEnd;
    key_bits_ = 1;
    while (nan_key() >> key_bits_ != 0) ++key_bits_;  // bits of the NaN key
  }

  std::string name() const override { return broadphase_name(BroadPhaseId::octree); }
  bool sorts_pairs() const override { return true; }

  void reserve(std::uint32_t n, cudaStream_t stream) override {
    min_.ensure(1);
    root_.ensure(1);
    sort_.ensure(n, true);
    level_begin_.ensure(kLevelTable);
    if (n > (1u << 29)) throw RuntimeError(fmt::format("octree: {} bodies; the device octree takes at most 2^29", n));
    cell_mask_ = static_cast<std::uint32_t>(footprint::loose_cell_table_entries(n) - 1);
    cell_table_.ensure(static_cast<std::size_t>(cell_mask_) + 1);
    occupancy_blocks_ = static_cast<std::uint32_t>(footprint::loose_occupancy_blocks(n));
    occupancy_.ensure(occupancy_blocks_ / 4);
    const std::size_t n1 = static_cast<std::size_t>(n) + 1;
    pairs_.ensure(n1);
    long_list_.ensure(std::max<std::size_t>(n, 1));
    long_count_.ensure(2);
    std::size_t bytes = 1;
    sort_.need_temp(bytes, n, 32, stream);
    pairs_.need_temp(bytes, n + 1, stream);
    temp_.ensure(bytes);
    n_ = n;
  }

  void find(const Aabb* aabb, std::uint32_t n, const PairOutput& out, cudaStream_t stream) override {
    bp::check_reserved(n_ != kNotReserved, n_, n, broadphase_name(BroadPhaseId::octree));
    check(cudaMemsetAsync(out.total, 0, sizeof(std::uint32_t), stream), "cudaMemset pair total");
    if (n == 0) return;
    if (out.scratch) {
      check(cudaMemsetAsync(pairs_.count.get(), 0, (static_cast<std::size_t>(n) + 1) * sizeof(std::uint32_t), stream),
            "cudaMemset octree pair counts");
      check(cudaMemsetAsync(long_count_.get(), 0, 2 * sizeof(std::uint32_t), stream),
            "cudaMemset octree long segments");
    }
    LooseDesc d;
    d.aabb = aabb;
    d.n = n;
    d.grid = grid_;
    d.depth = depth_;
    d.overflow_key = overflow_key_;
    d.nan_key = nan_key();
    d.min_extent = min_.get();
    d.root = depth_ < 0 ? root_.get() : nullptr;
    sort_.set_with_boxes(d);
    d.level_begin = level_begin_.get();
    d.cell_table = cell_table_.get();
    d.cell_mask = cell_mask_;
    d.occupancy = occupancy_.get();
    d.occupancy_blocks = occupancy_blocks_;
    const bool sorted = out.scratch != nullptr;
    d.pair_keys = sorted ? out.scratch : out.keys;
    d.pair_count = sorted ? pairs_.count.get() : nullptr;
    d.shift = out.shift;
    d.capacity = out.capacity;
    d.total = out.total;
    d.candidates = out.candidates;
    const unsigned g = grid_for(n);
    if (depth_ < 0) {
      check(cudaMemsetAsync(min_.get(), kMinExtentInit, sizeof(float), stream), "cudaMemset octree smallest extent");
      loose_extent_kernel<<<g, kBlockSize, 0, stream>>>(d);
      bp::launched(cudaGetLastError(), "loose_extent");
      if (d.root) {
        loose_root_kernel<<<1, 1, 0, stream>>>(d);
        bp::launched(cudaGetLastError(), "loose_root");
      }
    }
    loose_keys_kernel<<<g, kBlockSize, 0, stream>>>(d);
    bp::launched(cudaGetLastError(), "loose_keys");
    std::size_t bytes = temp_.capacity();
    bp::launched(sort_.sort(temp_.get(), bytes, n, key_bits_, stream), "cub::DeviceRadixSort::SortPairs");
    check(cudaMemsetAsync(cell_table_.get(), 0xff,
                          (static_cast<std::size_t>(cell_mask_) + 1) * sizeof(unsigned long long), stream),
          "cudaMemset octree block table");
    loose_gather_kernel<<<grid_for(std::max<std::uint32_t>(n, kLevelTable)), kBlockSize, 0, stream>>>(d);
    bp::launched(cudaGetLastError(), "loose_gather");
    if (query_ == Query::Warp || (query_ == Query::Auto && n < kWarpQueryBodies)) {
      loose_query_warp_kernel<<<bp::warp_grid_for(n), kBlockSize, 0, stream>>>(d);
    } else {
      loose_query_kernel<<<grid_for(n), kBlockSize, 0, stream>>>(d);
      bp::launched(cudaGetLastError(), "loose_query");
      loose_lists_kernel<<<std::min(bp::warp_grid_for(n), kListsBlocks), kBlockSize, 0, stream>>>(d);
    }
    bp::launched(cudaGetLastError(), "loose_query");
    loose_overflow_kernel<<<grid_for(n), kBlockSize, 0, stream>>>(d);
    bp::launched(cudaGetLastError(), "loose_overflow");
    if (sorted) sort_pairs(out, n, stream);
  }

  /// The sorted mode's last steps (see the file comment): the segments, the scatter, the
  /// segment sorts.
  void sort_pairs(const PairOutput& out, std::uint32_t n, cudaStream_t stream) {
    std::size_t bytes = temp_.capacity();
    bp::launched(pairs_.scan(temp_.get(), bytes, n + 1, stream),
                 "cub::DeviceScan::ExclusiveSum (octree pair segments)");
    LooseSortDesc s;
    s.scratch = out.scratch;
    s.scratch_rw = out.scratch;
    s.keys = out.keys;
    s.count = pairs_.count.get();
    s.offset = pairs_.offset.get();
    s.long_list = long_list_.get();
    s.long_count = long_count_.get();
    s.total = out.total;
    s.capacity = out.capacity;
    s.n = n;
    s.shift = out.shift;
    bp::launch(loose_scatter_kernel, grid_for(std::max<std::uint32_t>(out.capacity, 1)), stream, s, "loose_scatter");
    bp::launch(loose_segment_sort_kernel, grid_for(n), stream, s, "loose_segment_sort");
    bp::launch(loose_long_sort_kernel, kLongSortBlocks, stream, s, "loose_long_sort");
    bp::launch(loose_huge_rank_kernel, kLongSortBlocks, stream, s, "loose_huge_rank");
    bp::launch(loose_huge_copy_kernel, kLongSortBlocks, stream, s, "loose_huge_copy");
  }

  std::uint64_t device_bytes() const override {
    return sort_.bytes() + pairs_.bytes() +
           total_bytes({&min_, &level_begin_, &cell_table_, &occupancy_, &long_list_, &long_count_, &temp_});
  }

 private:
  int depth_;
  LooseGrid grid_;
  using Query = LooseOctreeQuery;
  Query query_ = Query::Auto;
  std::uint32_t overflow_key_ = 0;  // see LooseDesc::overflow_key
  int key_bits_ = 32;               // the key sort's end bit
  std::uint32_t nan_key() const { return overflow_key_ + kLooseMaxDepth + 2; }
  static constexpr std::uint32_t kNotReserved = 0xffffffffu;
  std::uint32_t n_ = kNotReserved;
  DeviceBuffer<float> min_{"octree smallest extent"};
  DeviceBuffer<LooseRoot> root_{"octree snapped root"};
  bp::KeySortBuffers<std::uint32_t> sort_{"octree body keys", "octree body indices", "octree sorted keys",
                                          "octree slot bodies", "octree slot boxes"};
  DeviceBuffer<std::uint32_t> level_begin_{"octree level table"};
  std::uint32_t cell_mask_ = 1;
  DeviceBuffer<unsigned long long> cell_table_{"octree block table"};
  std::uint32_t occupancy_blocks_ = 0;
  DeviceBuffer<std::uint32_t> occupancy_{"octree occupancy map"};
  ScannedCounts pairs_{"octree pairs per body", "octree pair segments"};
  DeviceBuffer<std::uint32_t> long_list_{"octree long pair segments"};
  DeviceBuffer<std::uint32_t> long_count_{"octree long pair segment count"};
  DeviceBuffer<unsigned char> temp_{"octree CUB temporary storage"};
};

}  // namespace

std::unique_ptr<DeviceBroadPhase> make_device_loose_octree(const BroadPhaseConfig& config, const Aabb& domain,
                                                           LooseOctreeQuery query) {
  return std::make_unique<LooseOctreeDevice>(config.octree_depth, domain, query);
}

}  // namespace gpu
}  // namespace octocd
