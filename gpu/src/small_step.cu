// The fused small-scene step (issue 20, item 2): below kCudaSmallStepMaxBodies bodies the
// whole step is one cooperative kernel launch instead of a graph of about 25-30 dependent
// nodes, whose fixed cost (launch and dependency latency per node, about 80 us per step on
// an H100 whatever the scene) bounds small scenes. The grid is co-resident (sized from the
// occupancy, launched with cudaLaunchCooperativeKernel) and its phases are separated by
// grid-wide barriers (cooperative_groups grid.sync). Every phase calls the per-element device
// code of the per-stage kernels (integrate.cuh, broadphase_flat.cuh, midphase.cuh,
// response.cuh, metrics.cuh); the formulas are those of core's OCTOCD_HD headers. Phases:
//  1. integrate (Eq. 1-3, keeping x_saved / v_saved for a rerun; a recorded step first copies
//     the state at its start into x_pre / v_pre) and world AABBs, per body;
//     zero the step's counters and counts;
//  2. broadphase `flat`, one warp per body i: count its pairs (i, j), j > i (the row of
//     broadphase_flat.cu) and the pairs (a, i), a < i (the same tests, overlaps(aabb[a],
//     aabb[i]), read by column);
//  3. one block: exclusive scans of both counts, one cub::BlockScan of the packed counts
//     (out << 32) | in, tile by tile (integers, so the offsets are those of cub::DeviceScan);
//     the pair total into counts[0];
//  4. fill, one warp per body: the keys (i << shift) | j at out_offset[i] in j order: the
//     keys come out sorted by (a, b), so no key sort is needed (the graph path sorts the
//     same unique set into the same order); the in-list of body i (a ascending) at
//     in_offset[i];
//  5. mid_start (one warp per pair: pairs[k], confirmed[k], step 0 items); the in-lists'
//     entries a resolved to their pair index k (binary search in a's key segment);
//  6. mid_expand per level step, mid_leaf (the midphase's work lists, warp per item); the
//     lean kernel runs 5 and 6 a block per pair instead (midphase.cuh, mid_block_pairs:
//     its steps apart by __syncthreads, one grid-wide barrier after them all);
//  7. per response pass: contact_terms per pair, then per dynamic body the sums of its kept
//     contacts in the order the graph path's stable sort by body gives and World::step
//     adds them: the pairs (a, i), a < i, in increasing a (its in-list), then the pairs
//     (i, b) in increasing b (its key segment); apply_contact_sums; after the last pass the
//     clamp (Eq. 23) of the same body;
//  8. block 0: the metrics (the one-block pass of metrics.cu over the same 512 slots, so
//     the same bits), and a copy of the step statistics into mapped pinned host memory
//     (no separate device-to-host copy).
// Fused front (n <= SmallStepDesc::front_bodies): phases 1-4 without a grid-wide barrier:
// every block integrates every body from x_saved / v_saved (equal to x / v at a step's
// start) into its shared memory (FrontState: positions, boxes), builds a 64-bit overlap mask
// per body (the same overlap tests as the warp rows), takes both counts from the masks,
// scans them and fills its share of the rows and the resolved in-lists from there; block 0
// stores the integrated state and the boxes. The lean kernel's block midphase then follows
// with no barrier (the resident kernel zeroes the counts before the hand-over). The last
// response pass copies the new state into x_saved / v_saved (not when a list overflowed: the host
// then restores the state from them and reruns).
// Shared boxes (front_bodies < n <= SmallStepDesc::shared_boxes_bodies): every block
// integrates every body into its shared memory as the fused front does, the grid's warps
// count a row and a column each from those boxes (phase 2's code), one grid-wide barrier,
// then every block scans both counts and fills its rows from its boxes: no barrier after
// the integration, and the broadphase reads no body box from global memory.
// Resident kernel (small_resident_kernel): the same step in a loop, one batch of steps per
// request the host writes into mapped memory (ResidentDesc in kernels.hpp).
// Overflow: a pair list or midphase list that passes its capacity is counted in full and
// the host regrows and reruns the step, as on the graph path. Every thread reaches every
// grid.sync (no early return); loops over warps have warp-uniform bounds.
#include <initializer_list>

#include <cooperative_groups.h>
#include <cub/block/block_scan.cuh>
#include <cuda/atomic>

#include "broadphase_common.cuh"
#include "broadphase_flat.cuh"
#include "integrate.cuh"
#include "kernels.hpp"
#include "metrics.cuh"
#include "midphase.cuh"
#include "response.cuh"

namespace octocd {
namespace gpu {
namespace {

namespace cg = cooperative_groups;

/// Both counts' scans as one: cub::BlockScan of the packed values (out << 32) | in.
using BlockScan = cub::BlockScan<unsigned long long, kBlockSize>;
/// Counts per thread and tile of block_exclusive_scans (a tile of kBlockSize * kScanItems).
constexpr std::uint32_t kScanItems = 4;

constexpr std::size_t max3(std::size_t a, std::size_t b, std::size_t c) {
  return a > b ? (a > c ? a : c) : (b > c ? b : c);
}

/// Bodies up to which every block scans both counts itself into shared memory and fills
/// right after (no grid-wide barrier between the scan and the fill).
constexpr std::uint32_t kSharedScanBodies = 2048;

/// The scan phase's shared memory: CUB's storage and both offset arrays (n + 1 entries).
struct ScanShared {
  typename BlockScan::TempStorage storage;
  std::uint32_t out_offset[kSharedScanBodies + 1];
  std::uint32_t in_offset[kSharedScanBodies + 1];
};

/// The shared memory of the shared boxes (n <= kSmallSharedBoxesMaxBodies) and of the
/// fused front (n <= kSmallFrontMaxBodies): the integrated boxes and both offsets (n + 1
/// entries each) of the shared boxes (the front keeps its own in FrontState), CUB's
/// storage; the fused front's counts (the shared boxes count into global memory).
struct FrontShared {
  typename BlockScan::TempStorage storage;
  Aabb aabb[kSmallSharedBoxesMaxBodies];
  std::uint32_t out_offset[kSmallSharedBoxesMaxBodies + 1];
  std::uint32_t in_offset[kSmallSharedBoxesMaxBodies + 1];
  std::uint32_t out_count[kSmallFrontMaxBodies + 1];
  std::uint32_t in_count[kSmallFrontMaxBodies + 1];
};

constexpr std::size_t max2(std::size_t a, std::size_t b) { return a > b ? a : b; }

/// Shared memory of the fused kernel, used by one phase at a time (grid.sync between):
/// the scan's storage (and offsets) or the fused front's, the leaf tiles, the metrics slots.
constexpr std::size_t kSharedBytes = max2(
    max3(sizeof(ScanShared), sizeof(mid::LeafTiles), sizeof(metrics::Acc) * kMetricsBlockSize), sizeof(FrontShared));
static_assert(kSharedBytes <= 48 * 1024, "static shared memory of the fused step");

/// Exclusive prefix sums of a[0 .. count) into a_out and of b[0 .. count) into b_out (and
/// into a_out2 / b_out2 when not null) by one block (every thread calls it): one scan of the
/// packed values (a << 32) | b, kItems consecutive counts a thread (b's total, the pair
/// total, is below 2^32, so no carry reaches a's half; integers, so the offsets are those of
/// two cub::DeviceScan runs); returns a's total.
template <std::uint32_t kItems = kScanItems>
__device__ std::uint32_t block_exclusive_scans(const std::uint32_t* a, const std::uint32_t* b, std::uint32_t* a_out,
                                               std::uint32_t* b_out, std::uint32_t count,
                                               typename BlockScan::TempStorage& storage,
                                               std::uint32_t* a_out2 = nullptr, std::uint32_t* b_out2 = nullptr) {
  unsigned long long carry = 0;
  for (std::uint32_t base = 0; base < count; base += kBlockSize * kItems) {
    const std::uint32_t first = base + threadIdx.x * kItems;
    unsigned long long v[kItems];
#pragma unroll
    for (std::uint32_t q = 0; q < kItems; ++q) {
      const std::uint32_t idx = first + q;
      v[q] = idx < count ? (static_cast<unsigned long long>(a[idx]) << 32) | b[idx] : 0ull;
    }
    unsigned long long tile_total = 0;
    BlockScan(storage).ExclusiveSum(v, v, tile_total);
#pragma unroll
    for (std::uint32_t q = 0; q < kItems; ++q) {
      const std::uint32_t idx = first + q;
      if (idx < count) {
        const unsigned long long e = carry + v[q];
        const std::uint32_t ea = static_cast<std::uint32_t>(e >> 32);
        const std::uint32_t eb = static_cast<std::uint32_t>(e);
        a_out[idx] = ea;
        b_out[idx] = eb;
        if (a_out2) {
          a_out2[idx] = ea;
          b_out2[idx] = eb;
        }
      }
    }
    carry += tile_total;
    __syncthreads();  // the storage is reused by the next tile
  }
  return static_cast<std::uint32_t>(carry >> 32);
}

/// %globaltimer (ns).
__device__ inline unsigned long long global_ns() {
  unsigned long long t;
  asm volatile("mov.u64 %0, %%globaltimer;" : "=l"(t));
  return t;
}

/// Thread 0 of block 0 stamps %globaltimer (ns) into profile[slot] (a timed step, or profiling).
__device__ inline void stamp(unsigned long long* profile, int slot) {
  if (profile && blockIdx.x == 0 && threadIdx.x == 0) profile[slot] = global_ns();
}

__device__ inline std::uint32_t min_u32(std::uint32_t a, std::uint32_t b) { return a < b ? a : b; }

/// The `flat` broadphase's counts from `boxes` (n of them), a body per warp of the grid:
/// body i's row (j > i) into s.out_count[i], its column (a < i) into s.in_count[i].
__device__ __forceinline__ void count_rows(const SmallStepDesc& s, const Aabb* boxes, std::uint32_t n,
                                           std::uint32_t warp, std::uint32_t warps) {
  for (std::uint32_t i = warp; i < n; i += warps) {
    flat_pairs_of(boxes, n, i, s.out_count, nullptr, nullptr, 0, s.shift);
    const std::uint32_t in = flat_row<false>(boxes, boxes[i], 0u, i, [](std::uint32_t, std::uint32_t) {});
    if ((threadIdx.x & 31u) == 0) s.in_count[i] = in;
  }
}

/// The `flat` broadphase's fill from `boxes`, a body per warp of the grid: body i's keys
/// (i << shift) | j in j order at out_offset[i], its in-list (a ascending) at in_offset[i],
/// each below the pair capacity.
__device__ __forceinline__ void fill_rows(const SmallStepDesc& s, const Aabb* boxes, std::uint32_t n,
                                          const std::uint32_t* out_offset, const std::uint32_t* in_offset,
                                          std::uint32_t warp, std::uint32_t warps) {
  const std::uint32_t cap = s.mid.pair_capacity;
  for (std::uint32_t i = warp; i < n; i += warps) {
    flat_pairs_of(boxes, n, i, nullptr, out_offset, s.pair_keys, cap, s.shift);
    const std::uint32_t o = in_offset[i];
    (void)flat_row<false>(boxes, boxes[i], 0u, i, [&](std::uint32_t r, std::uint32_t a) {
      if (o + r < cap) s.in_list[o + r] = a;
    });
  }
}

/// The fused front's state (n <= kSmallFrontMaxBodies <= 64), kept in shared memory apart
/// from the phases' union for the whole step: every body's integrated position and world
/// AABB (the block's own copy of what block 0 stores: the block midphase sets its pairs up
/// from these, as no grid-wide barrier orders block 0's stores before it); bit j of
/// mask[i] (j != i): the pair of i and j overlaps, tested as the row of min(i, j) tests it
/// (overlaps(box_min, box_max)); the pairs' offsets of the rows (out_offset, n + 1 entries)
/// and of the columns (in_offset).
struct FrontState {
  Vec3 x[kSmallFrontMaxBodies];
  Aabb aabb[kSmallFrontMaxBodies];
  unsigned long long mask[kSmallFrontMaxBodies];
  std::uint32_t out_offset[kSmallFrontMaxBodies + 1];
  std::uint32_t in_offset[kSmallFrontMaxBodies + 1];
};
static_assert(kSmallFrontMaxBodies <= 64, "one 64-bit overlap mask a body");

/// The bits of positions below `i` (0 <= i <= 64).
__device__ inline unsigned long long bits_below(std::uint32_t i) { return i >= 64 ? ~0ull : (1ull << i) - 1ull; }

/// The rank of pair (a, j), a < j, in row a: its index k is out_offset[a] + that.
__device__ inline std::uint32_t row_rank(const FrontState& fs, std::uint32_t a, std::uint32_t j) {
  return static_cast<std::uint32_t>(__popcll(fs.mask[a] & bits_below(j) & ~bits_below(a + 1)));
}

/// Pair k of the fused front (k below its pair count): row a (the last whose offset is <=
/// k), and the (k - out_offset[a])-th set bit above a in a's mask.
__device__ inline Pair front_pair(const FrontState& fs, std::uint32_t n, std::uint32_t k) {
  std::uint32_t lo = 0, hi = n;  // out_offset[lo] <= k < out_offset[hi]
  while (hi - lo > 1) {
    const std::uint32_t mid = (lo + hi) / 2;
    if (fs.out_offset[mid] <= k) lo = mid;
    else hi = mid;
  }
  const unsigned long long row = fs.mask[lo] & ~bits_below(lo + 1);
  const int r = static_cast<int>(k - fs.out_offset[lo]);  // 0-based: the (r + 1)-th set bit
  const unsigned low = static_cast<unsigned>(row);
  const int in_low = __popc(low);
  const unsigned high = static_cast<unsigned>(row >> 32);
  const std::uint32_t j = r < in_low ? __fns(low, 0, r + 1) : 32u + __fns(high, 0, r - in_low + 1);
  return Pair{lo, j};
}

/// The fused front's fill from the masks, a body per warp of the grid: body i's keys (i <<
/// shift) | j, j > i in j order, at out_offset[i], and its in-list (a < i in increasing a)
/// at in_offset[i] as the pairs' indices k = out_offset[a] + row_rank(a, i) (kNoPair from
/// the pair capacity on), each below the capacity: the keys and the resolved in-lists of
/// fill_rows and resolve_in_lists, with no key read back.
__device__ __forceinline__ void fill_front(const SmallStepDesc& s, const FrontState& fs, std::uint32_t n,
                                           std::uint32_t warp, std::uint32_t warps) {
  const std::uint32_t cap = s.mid.pair_capacity;
  const std::uint32_t lane = threadIdx.x & 31u;
  for (std::uint32_t i = warp; i < n; i += warps) {
    const unsigned long long m = fs.mask[i];
    for (std::uint32_t j = lane; j < n; j += 32) {
      if (((m >> j) & 1ull) == 0) continue;
      if (j > i) {
        const std::uint32_t k = fs.out_offset[i] + row_rank(fs, i, j);
        if (k < cap) s.pair_keys[k] = bp::pair_key(i, j, s.shift);
      } else {
        const std::uint32_t e = fs.in_offset[i] + static_cast<std::uint32_t>(__popcll(m & bits_below(j)));
        const std::uint32_t k = fs.out_offset[j] + row_rank(fs, j, i);
        if (e < cap) s.in_list[e] = k < cap ? k : kNoPair;
      }
    }
  }
}

/// Zeroes the step's counters and list counts (one thread); counts[0], the pair total, is
/// assigned by every step's scan (and the last step's metrics may still read it).
__device__ inline void zero_step_counts(StepStats& st) {
  for (int c = 0; c < 4; ++c) st.counters[c] = 0;
  for (int c = 1; c < hd::kMidphaseMaxLevels + 1; ++c) st.counts[c] = 0;
}

/// The in-lists' entries a resolved to their pair's index k (kNoPair when the pair did not
/// fit the capacity), a body per thread from the grid's last thread down (the first warps
/// take the midphase's pairs): a binary search in a's key segment.
__device__ __forceinline__ void resolve_in_lists(const SmallStepDesc& s, std::uint32_t tid, std::uint32_t threads) {
  const std::uint32_t cap = s.mid.pair_capacity;
  const std::uint32_t n = s.bodies.n;
  const std::uint32_t live = live_count(s.stats->counts, cap);
  for (std::uint32_t i = threads - 1u - tid; i < n; i += threads) {
    const std::uint32_t e1 = min_u32(s.in_offset[i + 1], cap);
    for (std::uint32_t e = s.in_offset[i]; e < e1; ++e) {
      const std::uint32_t a = s.in_list[e];
      const std::uint32_t lo = s.out_offset[a];
      const std::uint32_t hi = min_u32(s.out_offset[a + 1], live);
      const unsigned long long key = bp::pair_key(a, i, s.shift);
      const std::uint32_t k = lo < hi ? bp::lower_bound_u64(s.pair_keys, lo, hi, key) : hi;
      s.in_list[e] = k < hi && s.pair_keys[k] == key ? k : kNoPair;
    }
  }
}

/// What small_step_body calls to hand the next step over early: nothing (the launch per step).
struct NoHandOver {
  __device__ void operator()(bool) const {}
};

/// One whole step (every thread of the grid calls it): `sequence` is written to *s.done at
/// the end, `records` (may be null) gets the first pass's contacts, `profile` (may be
/// null) the phase stamps. kResident (the resident kernel): the caller zeroes the step's
/// counters before it hands the step to the grid (zero_step_counts) and writes *done (behind
/// __threadfence_system), so no grid-wide barrier need order the zeroing before the
/// blocks' atomics (the block midphase follows the front's fill without one); with the
/// response in block 0 alone and the bodies' boxes shared (only block 0 stores the state),
/// block 0's thread 0 calls hand_over(goes_on) right after the response, before the
/// metrics (the next step's other blocks write nothing the metrics read), having copied
/// the counts to host memory; the metrics follow into the same slot. smem:
/// kSharedBytes. kLean (s.lean: scenes of small leaf cells, small_lean_kernel): the midphase's early exit, tile culling and
/// tile filter read as off, constants the compiler folds away.
/// Returns, to thread 0 of block 0 (false elsewhere), whether the next step may follow
/// without the host: every list within its capacity (the host's regrow test,
/// CudaWorld::Impl::grow_if_needed), every body finite, and (with `ring`) the step's
/// record in the ring (RecordRing: block 0 copies it after the response, before the
/// hand-over, into slot `ring_slot` and its pairs from `ring_at`; thread 0 of block 0 sets
/// *ring_used to the pairs copied).
template <bool kLean, bool kResident = false, class HandOver = NoHandOver>
__device__ __forceinline__ bool small_step_body(const SmallStepDesc& s, unsigned long long sequence,
                                                DeviceContact* records, unsigned long long* profile,
                                                unsigned char* smem, HandOver&& hand_over = HandOver{},
                                                const RecordRing* ring = nullptr, std::uint32_t ring_slot = 0,
                                                std::uint32_t ring_at = 0, std::uint32_t* ring_used = nullptr) {
  cg::grid_group grid = cg::this_grid();
  const BodiesDesc& b = s.bodies;
  const std::uint32_t n = b.n;
  const std::uint32_t tid = blockIdx.x * blockDim.x + threadIdx.x;
  const std::uint32_t threads = gridDim.x * blockDim.x;
  const std::uint32_t warp = tid >> 5;  // blockDim.x == kBlockSize, a multiple of 32
  const std::uint32_t warps = threads >> 5;
  const std::uint32_t lane = threadIdx.x & 31u;
  const std::uint32_t cap = s.mid.pair_capacity;
  StepStats* st = s.stats;
  stamp(profile, 0);

  // 1. Integrate and world AABBs; the step's counts from zero (kResident: zeroed already).
  if (tid == 0) {
    if (!kResident) zero_step_counts(*st);
    s.out_count[n] = 0;
    s.in_count[n] = 0;
  }
  const bool front = n <= s.front_bodies;                          // uniform
  const bool shared_boxes = front || n <= s.shared_boxes_bodies;  // uniform
  // The lean kernel's midphase a block per pair (mid_block_pairs), with the front's masks.
  const bool block_pairs = kLean && front && gridDim.x <= kBlockPairSegments;  // uniform
  __shared__ alignas(16) unsigned char fs_bytes[sizeof(FrontState)];  // Vec3 and Aabb initialise their members
  FrontState& fs = *reinterpret_cast<FrontState*>(fs_bytes);
  std::uint32_t front_pairs = 0;  // the fused front's pair count (every block's own scan)
  if (shared_boxes) {
    // Every block integrates every body from the saved state (== the state at the step's
    // start) into its shared memory; block 0 stores the result.
    FrontShared& f = *reinterpret_cast<FrontShared*>(smem);
    Aabb* const boxes = front ? fs.aabb : f.aabb;
    const bool keep_pre = records != nullptr && s.x_pre != nullptr && blockIdx.x == 0;  // uniform per block
    for (std::uint32_t i = threadIdx.x; i < n; i += blockDim.x) {
      Vec3 x, v;
      if (keep_pre) {
        s.x_pre[i] = b.x_saved[i];
        s.v_pre[i] = b.v_saved[i];
      }
      integrated(b, i, b.x_saved[i], b.v_saved[i], s.gravity, s.dt, x, v);
      const Aabb box = translated(b.local[i], x);
      boxes[i] = box;
      if (front) fs.x[i] = x;
      if (blockIdx.x == 0) {
        b.x[i] = x;
        b.v[i] = v;
        b.aabb[i] = box;
      }
    }
    __syncthreads();
    stamp(profile, 1);
    std::uint32_t* g_out = blockIdx.x == 0 ? s.out_offset : nullptr;
    std::uint32_t* g_in = blockIdx.x == 0 ? s.in_offset : nullptr;
    std::uint32_t total = 0;
    if (front) {
      // Body i's overlap mask from the shared boxes, a row a warp of the block (rows i,
      // i + 8, ..), lanes over j (two ballots): the tests of flat_row (the smaller index's
      // box first); then its row's count (the bits above i) and its column's (below i).
      for (std::uint32_t i = threadIdx.x >> 5; i < n; i += blockDim.x >> 5) {
        const Aabb bi = fs.aabb[i];
        unsigned long long m = 0;
        for (std::uint32_t half = 0; half < 2; ++half) {
          const std::uint32_t j = half * 32 + lane;
          const bool hit = j < n && j != i && (j > i ? overlaps(bi, fs.aabb[j]) : overlaps(fs.aabb[j], bi));
          m |= static_cast<unsigned long long>(__ballot_sync(0xffffffffu, hit)) << (32 * half);
        }
        if (lane == 0) fs.mask[i] = m;
      }
      __syncthreads();
      for (std::uint32_t i = threadIdx.x; i <= n; i += blockDim.x) {
        const unsigned long long m = i < n ? fs.mask[i] : 0ull;
        f.out_count[i] = static_cast<std::uint32_t>(__popcll(m & ~bits_below(i + 1)));
        f.in_count[i] = static_cast<std::uint32_t>(__popcll(m & bits_below(i)));
      }
      __syncthreads();
      stamp(profile, 2);
      // At most kSmallFrontMaxBodies + 1 counts: one a thread, one tile (faster than four a
      // thread on the H100: reports/h100/README.md, "Experiments and A/B results").
      static_assert(kSmallFrontMaxBodies + 1 <= kBlockSize, "the fused front's counts in one tile");
      total = block_exclusive_scans<1>(f.out_count, f.in_count, fs.out_offset, fs.in_offset, n + 1, f.storage, g_out,
                                       g_in);
    } else {
      // The grid's warps count the rows and columns (a body each, as phase 2 below) from
      // the block's shared boxes, then one grid-wide barrier.
      count_rows(s, f.aabb, n, warp, warps);
      grid.sync();
      stamp(profile, 2);
      total = block_exclusive_scans(s.out_count, s.in_count, f.out_offset, f.in_offset, n + 1, f.storage, g_out, g_in);
    }
    if (blockIdx.x == 0 && threadIdx.x == 0) st->counts[0] = total;
    front_pairs = total;
    stamp(profile, 3);
    if (front) {
      // The keys and resolved in-lists, read again only after the midphase's barrier when
      // it runs a block per pair (each block finds its pairs in the masks). The launch per
      // step keeps the barrier: it orders block 0's zeroing of the counts before the
      // midphase's atomics (the resident kernel zeroes them before the step is handed over).
      fill_front(s, fs, n, warp, warps);
      if (!(block_pairs && kResident)) grid.sync();
    } else {
      fill_rows(s, f.aabb, n, f.out_offset, f.in_offset, warp, warps);
      grid.sync();
    }
    stamp(profile, 4);
  } else {
    const bool keep_pre = records != nullptr && s.x_pre != nullptr;  // uniform
    for (std::uint32_t i = tid; i < n; i += threads) {
      if (keep_pre) {
        s.x_pre[i] = b.x[i];
        s.v_pre[i] = b.v[i];
      }
      integrate_body(b, i, s.gravity, s.dt);
      aabb_body(b, i);
    }
    grid.sync();
    stamp(profile, 1);

    // 2. Broadphase `flat`, counting: body i's row (j > i) and column (a < i).
    count_rows(s, b.aabb, n, warp, warps);
    grid.sync();
    stamp(profile, 2);

    // 3. Both exclusive scans over n + 1 counts; the pair total. Up to kSharedScanBodies
    // every block scans into its shared memory (block 0 also into the global offsets) and
    // fills from there at once; above, block 0 scans and a grid-wide barrier precedes the fill.
    const bool shared_scan = n <= kSharedScanBodies;
    const std::uint32_t* out_offset = s.out_offset;
    const std::uint32_t* in_offset = s.in_offset;
    if (shared_scan) {
      ScanShared& sh = *reinterpret_cast<ScanShared*>(smem);
      std::uint32_t* g_out = blockIdx.x == 0 ? s.out_offset : nullptr;
      std::uint32_t* g_in = blockIdx.x == 0 ? s.in_offset : nullptr;
      const std::uint32_t total =
          block_exclusive_scans(s.out_count, s.in_count, sh.out_offset, sh.in_offset, n + 1, sh.storage, g_out, g_in);
      if (blockIdx.x == 0 && threadIdx.x == 0) st->counts[0] = total;
      out_offset = sh.out_offset;
      in_offset = sh.in_offset;
      stamp(profile, 3);
    } else {
      if (blockIdx.x == 0) {
        auto& storage = *reinterpret_cast<typename BlockScan::TempStorage*>(smem);
        const std::uint32_t total =
            block_exclusive_scans(s.out_count, s.in_count, s.out_offset, s.in_offset, n + 1, storage);
        if (threadIdx.x == 0) st->counts[0] = total;
      }
      grid.sync();
      stamp(profile, 3);
    }

    // 4. Fill: the pair keys in (a, b) order and the in-lists in a order (below the capacity).
    fill_rows(s, b.aabb, n, out_offset, in_offset, warp, warps);
    grid.sync();
    stamp(profile, 4);
  }  // not from shared boxes

  // 5. Midphase start (one warp per pair); the in-lists' a resolved to k, by the grid's
  // last threads (the first warps take the pairs).
  // The midphase's descriptor: one copy per block in shared memory, written by thread 0
  // after a barrier that every thread of the block has passed, read by all after
  // __syncthreads (a copy per thread is 304 bytes of local memory a thread and step).
  // No witness cache (midphase.cuh, "Witnesses"): its lookups and its copy of the keys cost
  // the fused step more than the descents they spare on 5 of 6 shipped small scenes (H100:
  // reports/h100/README.md, "Experiments and A/B results").
  __shared__ MidListDesc block_md;
  const MidListDesc& md = block_md;
  if (threadIdx.x == 0) {
    block_md = s.mid;
    block_md.wit = WitnessDesc{};
    if (kLean) {
      block_md.early_exit = 0;
      block_md.tile_cull = 0;
      block_md.tile_filter = 0;
    }
    block_md.out = s.lists[0];
    block_md.out_count = st->counts + 1;
    block_md.out_capacity = s.list_capacity;
    if (block_pairs) {  // the block's own integrated state (see FrontState)
      block_md.x = fs.x;
      block_md.aabb = fs.aabb;
    }
  }
  __syncthreads();
  const int steps = s.mid.steps;
  if (block_pairs) {
    // 5-6. The midphase a block per pair (pairs from the front's masks): start, expand
    // steps and leaves in the block's segments of the lists, one grid-wide barrier after
    // them (the front's fill had none).
    __shared__ std::uint32_t block_counts[hd::kMidphaseMaxLevels];
    mid::mid_block_pairs<kLean>(
        block_md, min_u32(front_pairs, cap), [&](std::uint32_t k) { return front_pair(fs, n, k); }, s.lists,
        s.list_capacity / kBlockPairSegments, block_counts, st->counts, *reinterpret_cast<mid::LeafTiles*>(smem));
    grid.sync();
    stamp(profile, 5);
    stamp(profile, 6);
  } else {
    mid::mid_start_items<false, kLean>(md);
    if (!front) resolve_in_lists(s, tid, threads);  // the front's fill resolved them
    grid.sync();
    stamp(profile, 5);

    // 6. Midphase expand steps and leaves (as step_stages.cpp enqueues them; the leaves stay
    // in the leaf list: no expand step runs them itself here).
    for (int i = 0; i + 1 < steps; ++i) {
      if (threadIdx.x == 0) {
        block_md.in = s.lists[i % 2];
        block_md.in_count = st->counts + 1 + i;
        block_md.in_capacity = s.list_capacity;
        block_md.out = s.lists[(i + 1) % 2];
        block_md.out_count = st->counts + 2 + i;
      }
      __syncthreads();
      mid::mid_expand_items<kLean>(md, i);
      grid.sync();
    }
    stamp(profile, 6);
    if (steps > 0) {
      if (threadIdx.x == 0) {
        block_md.in = s.lists[(steps - 1) % 2];
        block_md.in_count = st->counts + steps;
        block_md.in_capacity = s.list_capacity;
        block_md.out = nullptr;
        block_md.out_count = nullptr;
        block_md.out_capacity = 0;
      }
      __syncthreads();
      mid::mid_leaf_items<false, kLean>(md, *reinterpret_cast<mid::LeafTiles*>(smem));
      grid.sync();
    }
  }
  stamp(profile, 7);

  // 7. Response passes; the clamp after the last one. With few pairs block 0 runs them
  // alone (its own barriers), then the metrics; the other blocks are done.
  TermsDesc td = s.terms;
  td.records = records;
  const std::uint32_t live = live_count(st->counts, cap);
  // The fused front's saved state becomes the new state unless the step is to be rerun.
  // Every list within its capacity (the host's regrow test, grow_if_needed): else the host
  // reruns the step from x_saved / v_saved.
  bool fits = st->counts[0] <= cap;
  for (int i = 0; i < steps; ++i) fits = fits && st->counts[1 + i] <= s.list_capacity;
  const bool save = shared_boxes && fits;
  const bool one_block = live <= s.one_block_pairs;
  if (one_block && blockIdx.x != 0) return false;  // uniform per block; no grid.sync follows then
  // The early hand-over (kResident): the smallest dynamic body left non-finite by the last
  // pass, as the metrics find it (metrics_block's first_bad), from the state in registers.
  const bool early = kResident && one_block && shared_boxes;  // uniform
  __shared__ std::uint32_t first_bad;
  if (early && threadIdx.x == 0) first_bad = n;
  const std::uint32_t r_tid = one_block ? threadIdx.x : tid;
  const std::uint32_t r_threads = one_block ? blockDim.x : threads;
  for (int pass = 0; pass < s.iterations; ++pass) {
    if (pass > 0) {
      td.depth0 = nullptr;
      td.records = nullptr;
    }
    for (std::uint32_t k = r_tid; k < live; k += r_threads) contact_terms_at(td, k);
    if (one_block) __syncthreads();
    else grid.sync();
    const bool last = pass + 1 == s.iterations;
    // Body i: its sums, then ContactSums::apply and (last pass) clamp_body on the state
    // loaded before the lists are walked and kept in registers (the same operations in the
    // same order; what changed is stored, and the saved state from the registers).
    for (std::uint32_t i = r_tid; i < n; i += r_threads) {
      const float w = b.w[i];
      Vec3 x = b.x[i];
      Vec3 v = b.v[i];
      if (w != 0.0f) {
        ContactSums sums;
        const std::uint32_t e1 = min_u32(s.in_offset[i + 1], cap);
        for (std::uint32_t e = s.in_offset[i]; e < e1; ++e) {
          const std::uint32_t k = s.in_list[e];
          if (k != kNoPair) sums.add(s.apply, k, true);
        }
        const std::uint32_t k1 = min_u32(s.out_offset[i + 1], live);
        for (std::uint32_t k = s.out_offset[i]; k < k1; ++k) sums.add(s.apply, k, false);
        const Vec3 v0 = v;
        if (sums.count != 0) {
          apply_contact_sums(x, v, sums.dx, sums.dv, sums.count);
          b.x[i] = x;
        }
        if (last) v = clamp_velocity(v, s.max_velocity);
        if (sums.count != 0 || !same_bits(v, v0)) b.v[i] = v;
        if (early && last && (!is_finite(x) || !is_finite(v))) atomicMin(&first_bad, i);
      }
      if (last && save) {
        b.x_saved[i] = x;
        b.v_saved[i] = v;
      }
    }
    if (one_block) __syncthreads();
    else grid.sync();
  }
  stamp(profile, 8);

  // 7b. A recorded step of a resident batch with a ring (RecordRing): block 0 copies the
  // step's record into its slot, before the next step is handed over (its midphase rewrites
  // the pairs and flags, its integration x_pre). A step whose pairs do not fit the slot
  // copies nothing and ends the batch (the host reads it from the live buffers).
  bool ring_fits = true;
  if (ring != nullptr && records != nullptr && blockIdx.x == 0) {  // uniform per block
    const std::uint32_t np = st->counts[0];
    ring_fits = ring_at <= ring->pair_capacity && np <= ring->pair_capacity - ring_at;
    if (fits && ring_fits) {
      if (threadIdx.x == 0 && ring_used) *ring_used = np;
      const std::size_t at = static_cast<std::size_t>(ring_slot) * n;
      for (std::uint32_t i = threadIdx.x; i < n; i += blockDim.x) {
        ring->x_pre[at + i] = s.x_pre[i];
        ring->v_pre[at + i] = s.v_pre[i];
        ring->aabb[at + i] = b.aabb[i];
        ring->x_post[at + i] = b.x[i];
        ring->v_post[at + i] = b.v[i];
      }
      const std::size_t pat = ring_at;
      for (std::uint32_t k = threadIdx.x; k < np; k += blockDim.x) {
        ring->pairs[pat + k] = s.terms.pairs[k];
        ring->confirmed[pat + k] = s.terms.confirmed[k];
        ring->records[pat + k] = records[k];
      }
    }
    __syncthreads();  // every copy read before thread 0 hands the next step over
  }

  // 8. Block 0: the metrics, then everything the host reads, then the step's number.
  bool goes_on = false;
  if (blockIdx.x == 0) {
    StepStats* host = s.host_stats ? s.host_stats + sequence % s.host_slots : nullptr;
    if (early && threadIdx.x == 0) {
      // The counts are final: to host memory, then the next step handed over (its counts
      // zeroed), then the metrics of this step's state (block 0 stores the next one later).
      if (host) {
        for (int c = 0; c < 4; ++c) host->counters[c] = st->counters[c];
        for (int c = 0; c < hd::kMidphaseMaxLevels + 1; ++c) host->counts[c] = st->counts[c];
        host->index_long = st->index_long;
      }
      goes_on = fits && ring_fits && first_bad >= n;
      hand_over(goes_on);
    }
    metrics::metrics_block(s.metrics, reinterpret_cast<metrics::Acc*>(smem), 0, 1, &st->metrics);
    if (threadIdx.x == 0) {
      stamp(profile, 9);
      if (host) {
        if (early) host->metrics = st->metrics;
        else *host = *st;
      }
      if (s.done && !kResident) {
        __threadfence_system();  // the statistics (and stamps) before the step's number
        *s.done = sequence;
      }
      if (!early) goes_on = fits && ring_fits && st->metrics.first_non_finite >= n;
    }
  }
  return goes_on;
}

template <bool kLean>
__global__ void __launch_bounds__(kBlockSize) small_step_kernel(const __grid_constant__ SmallStepDesc s) {
  __shared__ alignas(16) unsigned char smem[kSharedBytes];
  (void)small_step_body<kLean>(s, s.sequence, s.terms.records, s.profile, smem);
}

/// The command that ends the resident kernel (never a request: those have a sequence
/// below 2^62).
constexpr unsigned long long kExitCommand = ~0ull;

/// Block 0, thread 0: waits for a request other than `handled` (system-scope loads of the
/// mapped word, tight at first, then __nanosleep backoff up to 1 us); returns it, or
/// kExitCommand for an exit request or after r.idle_ns without one.
__device__ unsigned long long wait_request(const ResidentDesc& r, unsigned long long handled) {
  cuda::atomic_ref<unsigned long long, cuda::thread_scope_system> request(*r.request);
  const unsigned long long t0 = global_ns();
  unsigned sleep_ns = 0;
  for (unsigned spins = 0;; ++spins) {
    const unsigned long long req = request.load(cuda::std::memory_order_acquire);
    if (req != handled) {
      if (req & kResidentExit) return kExitCommand;
      if (!r.stall) return req;
    }
    if ((spins & 7u) == 0 && r.idle_ns != 0 && global_ns() - t0 > r.idle_ns) return kExitCommand;
    if (spins >= 256) {
      __nanosleep(sleep_ns);
      sleep_ns = sleep_ns < 1024 ? sleep_ns * 2 + 32 : 1024;
    }
  }
}

/// Steps on request (ResidentDesc). Block 0 takes each request and publishes each step's
/// command, (sequence << kResidentShift) | flags (control[1], then control[0] = the next
/// ticket, release); the other blocks wait for the ticket (acquire). Every block reads the
/// first ticket before a grid-wide barrier, so none can miss the first command. Block 0
/// publishes the batch's next step (its counts zeroed first) when the request asked for it
/// and the step went on: right after a one-block response when the bodies' boxes are
/// shared (small_step_body's hand_over: the metrics and statistics then overlap the next
/// step's start in the other blocks), else after the step's last phase; then it writes the
/// step's *done (behind __threadfence_system: the other blocks need not wait for the
/// system-scope fence); at a batch's end it writes *done and waits for the next request. A
/// block done earlier (the one-block response) waits for the next ticket. Launch bounds of
/// one block per multiprocessor (its grid: kSmallStepBlocksPerSm): ptxas then gives the
/// lean kernel about 118 registers, where it chose 80 and spilled.
template <bool kLean>
__global__ void __launch_bounds__(kBlockSize, 1)
    small_resident_kernel(const __grid_constant__ SmallStepDesc s, const __grid_constant__ ResidentDesc r) {
  __shared__ alignas(16) unsigned char smem[kSharedBytes];
  __shared__ unsigned long long command;
  cuda::atomic_ref<unsigned long long, cuda::thread_scope_device> ticket(r.control[0]);
  cuda::atomic_ref<unsigned long long, cuda::thread_scope_device> published(r.control[1]);
  unsigned long long my_ticket = 0;
  if (threadIdx.x == 0) my_ticket = ticket.load(cuda::std::memory_order_relaxed);
  cg::this_grid().sync();
  // Block 0, thread 0: the last request taken, and its batch: the next step's sequence
  // (0: none left), its last step's, whether that one is stamped.
  unsigned long long taken = r.handled;
  unsigned long long next = 0, last = 0;
  unsigned long long ran = 0;  // the last step run, whose *done is still to be written (0: none)
  unsigned long long handed = 0;  // the command published by the early hand-over (0: none)
  bool stamp_last = false;
  // Block 0, thread 0: the batch records every step (kResidentRecord), its first step, and
  // whether the step `ran` ended its batch early (written to r.stopped with its done).
  bool record_batch = false;
  unsigned long long first = 0;
  bool ran_stopped = false;
  std::uint32_t ring_at = 0;  // the batch's pairs copied into the ring so far
  __shared__ std::uint32_t block_ring_at;  // block 0: ring_at for the step under way
  // Block 0, thread 0: the batch's next step's command (a recorded batch's carries the
  // record flag and the step's ring slot, next - first, in the ahead bits); publishing a command (a step's
  // counts zeroed first, released with the ticket: small_step_body's kResident); the next
  // step published when the request asked for it and the step went on (0: none).
  const auto next_command = [&]() -> unsigned long long {
    return (next << kResidentShift) | (next == last && stamp_last ? kResidentStamp : 0ull) |
           (record_batch ? kResidentRecord | (((next - first) & kResidentAheadMax) << kResidentAheadShift) : 0ull);
  };
  const auto publish = [&](unsigned long long cmd) {
    if (cmd != kExitCommand) zero_step_counts(*s.stats);
    published.store(cmd, cuda::std::memory_order_relaxed);
    ticket.store(my_ticket + 1, cuda::std::memory_order_release);
  };
  const auto publish_next = [&](bool goes_on) -> unsigned long long {
    next = goes_on ? next + 1 : 0;
    if (next == 0 || next > last) return 0;
    const unsigned long long cmd = next_command();
    publish(cmd);
    return cmd;
  };
  for (;;) {
    if (threadIdx.x == 0) {
      unsigned long long cmd;
      if (blockIdx.x == 0) {
        const bool more = handed != 0 || (next != 0 && next <= last);
        if (handed != 0) {
          cmd = handed;  // published during the last step
        } else if (more) {
          cmd = next_command();
          publish(cmd);
        }
        handed = 0;
        if (ran != 0 && s.done) {
          if (ran_stopped && r.stopped) *r.stopped = ran;  // before the step's number
          __threadfence_system();  // the statistics (and stamps) before the step's number
          *s.done = ran;
        }
        ran = 0;
        if (!more) {
          cmd = wait_request(r, taken);
          if (cmd != kExitCommand) {
            taken = cmd;
            next = cmd >> kResidentShift;
            last = next + ((cmd >> kResidentAheadShift) & kResidentAheadMax);
            stamp_last = (cmd & kResidentStamp) != 0;
            record_batch = (cmd & kResidentRecord) != 0;
            first = next;
            ring_at = 0;
            cmd = next_command();
          }
          publish(cmd);
        }
      } else {
        unsigned sleep_ns = 0;
        for (unsigned spins = 0; ticket.load(cuda::std::memory_order_acquire) == my_ticket; ++spins) {
          if (spins >= 64) {
            __nanosleep(sleep_ns);
            sleep_ns = sleep_ns < 256 ? sleep_ns * 2 + 32 : 256;
          }
        }
        cmd = published.load(cuda::std::memory_order_relaxed);
      }
      ++my_ticket;
      command = cmd;
      block_ring_at = ring_at;
    }
    __syncthreads();
    const unsigned long long cmd = command;
    const std::uint32_t at = block_ring_at;
    __syncthreads();  // every thread has read them before thread 0 writes the next ones
    if (cmd == kExitCommand) break;
    bool early = false;  // block 0, thread 0: the step handed the next one over itself
    std::uint32_t ring_used = 0;  // block 0, thread 0: the step's pairs copied into the ring
    const bool recorded = (cmd & kResidentRecord) != 0;
    const bool goes_on = small_step_body<kLean, true>(
        s, cmd >> kResidentShift, recorded ? r.records : nullptr, (cmd & kResidentStamp) != 0 ? s.profile : nullptr,
        smem,
        [&](bool on) {
          early = true;
          handed = publish_next(on);
        },
        recorded && r.ring.slots != 0 ? &r.ring : nullptr,
        static_cast<std::uint32_t>((cmd >> kResidentAheadShift) & kResidentAheadMax), at, &ring_used);
    if (blockIdx.x == 0 && threadIdx.x == 0) {
      if (!early) next = goes_on ? next + 1 : 0;
      ran = cmd >> kResidentShift;
      ran_stopped = !goes_on;
      ring_at += ring_used;
    }
  }
  if (blockIdx.x == 0 && threadIdx.x == 0) {
    __threadfence_system();  // the last step's writes before the exit's mark
    cuda::atomic_ref<unsigned long long, cuda::thread_scope_system>(*r.exited)
        .store(r.epoch, cuda::std::memory_order_release);
  }
}

/// The blocks per SM of every instantiation of a kernel (the fewest: the grid fits each).
cudaError_t all_blocks_per_sm(int& blocks, std::initializer_list<const void*> kernels) {
  blocks = 0;
  int fewest = -1;
  for (const void* k : kernels) {
    int b = 0;
    const cudaError_t e = cudaOccupancyMaxActiveBlocksPerMultiprocessor(&b, k, kBlockSize, 0);
    if (e != cudaSuccess) return e;
    fewest = fewest < 0 || b < fewest ? b : fewest;
  }
  blocks = fewest < 0 ? 0 : fewest;
  return cudaSuccess;
}

/// The instantiation for `s`: lean (s.lean) or plain.
template <typename K>
const void* pick(const SmallStepDesc& s, K* plain, K* lean) {
  return reinterpret_cast<const void*>(s.lean != 0 ? lean : plain);
}

}  // namespace

cudaError_t small_step_blocks_per_sm(int& blocks) {
  return all_blocks_per_sm(blocks, {reinterpret_cast<const void*>(&small_step_kernel<false>),
                                    reinterpret_cast<const void*>(&small_step_kernel<true>)});
}

cudaError_t launch_small_step(const SmallStepDesc& s, unsigned grid, cudaStream_t stream) {
  SmallStepDesc arg = s;
  void* args[] = {&arg};
  const void* kernel = pick(s, &small_step_kernel<false>, &small_step_kernel<true>);
  const cudaError_t e = cudaLaunchCooperativeKernel(kernel, dim3(grid), dim3(kBlockSize), args, 0, stream);
  if (e != cudaSuccess) return e;
  return cudaGetLastError();
}

cudaError_t small_resident_blocks_per_sm(int& blocks) {
  return all_blocks_per_sm(blocks, {reinterpret_cast<const void*>(&small_resident_kernel<false>),
                                    reinterpret_cast<const void*>(&small_resident_kernel<true>)});
}

cudaError_t launch_small_resident(const SmallStepDesc& s, const ResidentDesc& r, unsigned grid, cudaStream_t stream) {
  SmallStepDesc arg = s;
  ResidentDesc res = r;
  void* args[] = {&arg, &res};
  const void* kernel = pick(s, &small_resident_kernel<false>, &small_resident_kernel<true>);
  const cudaError_t e = cudaLaunchCooperativeKernel(kernel, dim3(grid), dim3(kBlockSize), args, 0, stream);
  if (e != cudaSuccess) return e;
  return cudaGetLastError();
}

}  // namespace gpu
}  // namespace octocd
