// Broadphase `octree` on the device: the loose octree of SPEC 5.1 (Ulrich 2000, looseness
// 2) with every cell and level decision from octocd/loose_octree.hpp, the header the CPU
// driver (core/src/broadphase_octree.cpp) uses. Steps (orchestrated by cuda_world.cpp):
// 1. keys: D_w (the scene's, or `auto` from the smallest body extent, a CUB minimum),
//    then per body loose_place_unit -> (level, Morton cell) key, the overflow key, or the
//    NaN key; its unit box in fixed point (loose_q_min / loose_q_max);
// 2. a stable radix sort by key: slot order = (key, body), so every occupied cell is a
//    contiguous run of slots and the levels follow each other in key order (with a fixed
//    D_w the overflow and NaN keys follow level D_w's cells, so the sort covers only the
//    bits they need);
// 3. a level table (first slot of every level, of the overflow list and of the NaN
//    bodies) and a hash table of the occupied cells (cell key -> its run of slots, open
//    addressing with linear probing over an array of keys, at most a quarter full, the
//    runs in a parallel array read on a hit only), then a query per slot:
//    - a body in a cell (level l) looks at every level m <= l that holds bodies: the
//      cells whose loose boxes meet its own box (loose_query_axis_q: at most 4 per axis),
//      looked up in the cell table (from kWarpQueryBodies bodies one thread per slot,
//      the lookups one after another: at 10^6 bodies the query is instruction bound and
//      most cells of a window are empty; below, one warp per slot, a lane per cell); at
//      m = l it keeps only slots after its own (a cell whose key precedes its own is not
//      even looked up), at m < l every body;
//    - an overflow body tests the overflow bodies after it;
//    then the exact AABB test (octocd::overlaps, Eq. 6). A second kernel, one thread per
//    in-tree slot, tests it against every overflow body (walls: a handful, each of which
//    would otherwise scan all n slots with one warp). Each overlapping pair is met exactly
//    once (same level: by the smaller slot; across levels: by the finer body; with the
//    overflow list: by the in-tree body, or the smaller overflow slot), because a body's
//    box lies in its cell's loose box and the query ranges are exact;
// 4. the pairs are appended as keys (a << shift) | b (PairOutput::shift) with one atomic
//    per group of threads that append together (their order varies; the set does not),
//    then radix-sorted by the caller: the sorted unique set `flat` gives.
#include <cstdlib>
#include <string>

#include <cub/device/device_radix_sort.cuh>
#include <cub/device/device_reduce.cuh>
#include <cub/device/device_scan.cuh>

#include "broadphase_common.cuh"
#include "device_broadphase.hpp"
#include "device_buffer.hpp"
#include "device_footprint.hpp"
#include "kernels.hpp"
#include "octocd/cuda_world.hpp"

namespace octocd {
namespace gpu {
namespace {


/// Below this many bodies the query runs one warp per slot, from it one thread per slot
/// (bench_gpu_broadphase on the H100: 10^4 boxes 0.15 vs 0.21 ms, 10^5 0.28 vs 0.26 ms,
/// 10^6 1.63 vs 1.16 ms).
constexpr std::uint32_t kWarpQueryBodies = 65536;

/// A body's unit box in the fixed point of loose_q_min / loose_q_max.
struct LooseQBox {
  std::int16_t lo[3];
  std::int16_t hi[3];
};
static_assert(sizeof(LooseQBox) == footprint::kLooseQBoxBytes, "device_footprint.hpp: LooseQBox");

/// The home entry of a cell key (murmur3's 32-bit finaliser: Morton keys of neighbouring
/// cells differ in low bits only).
__device__ inline std::uint32_t cell_hash(std::uint32_t k, std::uint32_t mask) {
  k ^= k >> 16;
  k *= 0x85ebca6bu;
  k ^= k >> 13;
  k *= 0xc2b2ae35u;
  k ^= k >> 16;
  return k & mask;
}

/// What the kernels read and write (device pointers).
struct LooseDesc {
  const Aabb* aabb = nullptr;      ///< world AABBs, per body
  std::uint32_t n = 0;             ///< bodies
  LooseGrid grid;                  ///< root cube of the scene's domain
  int depth = 2;                   ///< D_w in [0, 10]; -1 = auto (from *min_extent)
  float* extent = nullptr;         ///< scratch per body (auto depth): largest unit side
  float* min_extent = nullptr;     ///< one float: the smallest extent (auto depth)
  /// The sort keys of overflow and NaN bodies: kLooseOverflowKey and kLooseNoKey with
  /// depth `auto`; with a fixed D_w the two values after level D_w's last cell key
  /// (loose_level_base(D_w + 1) and + 1), so the key sort covers only the bits they need
  /// (D_w = 2: 7 bits, one radix pass instead of four).
  std::uint32_t overflow_key = kLooseOverflowKey;
  std::uint32_t nan_key = kLooseNoKey;
  std::uint32_t* key = nullptr;    ///< per body: cell key, overflow_key or nan_key
  std::uint32_t* body = nullptr;   ///< per body: its index (the sort's values)
  LooseQBox* q = nullptr;          ///< per body: fixed-point unit box
  const std::uint32_t* sorted_key = nullptr;   ///< per slot: key, ascending
  const std::uint32_t* slot_body = nullptr;    ///< per slot: body (stable: body order per cell)
  Aabb* slot_box = nullptr;        ///< per slot: the body's AABB
  LooseQBox* slot_q = nullptr;     ///< per slot: the body's fixed-point box
  /// Per level m in [0, kLooseMaxDepth + 1]: the first slot whose key is >= level m's base
  /// (entry kLooseMaxDepth + 1: the first overflow slot); then the first NaN slot.
  std::uint32_t* level_begin = nullptr;
  /// The cell table, cell_mask + 1 entries: the keys (kLooseNoKey = empty; never a cell
  /// key) and each key's run of slots [x, y).
  std::uint32_t* cell_keys = nullptr;
  uint2* cell_runs = nullptr;
  std::uint32_t cell_mask = 0;     ///< table size - 1 (a power of two >= 4 n)
  unsigned long long* pair_keys = nullptr;  ///< out: (a << shift) | b, appended in any order
  int shift = 32;                           ///< PairOutput::shift
  std::uint32_t capacity = 0;               ///< entries pair_keys holds
  std::uint32_t* total = nullptr;           ///< out: pairs found (may exceed capacity)
  unsigned long long* candidates = nullptr; ///< out (added): exact AABB tests
};

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
    d.key[i] = d.nan_key;
    d.q[i] = q;
    return;
  }
  const Vec3 lo = loose_unit(d.grid, b.min);
  const Vec3 hi = loose_unit(d.grid, b.max);
  const std::uint32_t key = loose_place_key(loose_place_unit(lo, hi, depth));
  d.key[i] = key == kLooseOverflowKey ? d.overflow_key : key;
  q.lo[0] = static_cast<std::int16_t>(loose_q_min(lo.x));
  q.lo[1] = static_cast<std::int16_t>(loose_q_min(lo.y));
  q.lo[2] = static_cast<std::int16_t>(loose_q_min(lo.z));
  q.hi[0] = static_cast<std::int16_t>(loose_q_max(hi.x));
  q.hi[1] = static_cast<std::int16_t>(loose_q_max(hi.y));
  q.hi[2] = static_cast<std::int16_t>(loose_q_max(hi.z));
  d.q[i] = q;
}

/// First slot in [lo, hi) whose key is >= key.
__device__ std::uint32_t lower_bound(const std::uint32_t* keys, std::uint32_t lo, std::uint32_t hi,
                                     std::uint32_t key);

constexpr int kLevelTable = kLooseMaxDepth + 3;  // levels 0..10, overflow, NaN
static_assert(kLevelTable == static_cast<int>(footprint::kLooseLevelTable), "device_footprint.hpp: level table");

__global__ void loose_gather_kernel(LooseDesc d) {
  const std::uint32_t s = blockIdx.x * blockDim.x + threadIdx.x;
  if (s < kLevelTable) {  // the level table (the sorted keys are complete)
    // Levels deeper than D_w hold no body: their entries are the overflow list's start.
    const std::uint32_t base = s <= static_cast<std::uint32_t>(kLooseMaxDepth)
                                   ? min(loose_level_base(static_cast<int>(s)), d.overflow_key)
                                   : (s == kLooseMaxDepth + 1 ? d.overflow_key : d.nan_key);
    d.level_begin[s] = lower_bound(d.sorted_key, 0, d.n, base);
  }
  if (s >= d.n) return;
  const std::uint32_t body = d.slot_body[s];
  d.slot_box[s] = d.aabb[body];
  d.slot_q[s] = d.q[body];
  // The cell table: the first slot of a run writes its begin, the last its end (both
  // claim or find the key's entry; the table holds at least four times the cell count).
  const std::uint32_t key = d.sorted_key[s];
  if (key >= d.overflow_key) return;
  const bool first = s == 0 || d.sorted_key[s - 1] != key;
  const bool last = s + 1 == d.n || d.sorted_key[s + 1] != key;
  if (!first && !last) return;
  std::uint32_t h = cell_hash(key, d.cell_mask);
  for (;;) {
    const std::uint32_t old = atomicCAS(&d.cell_keys[h], kLooseNoKey, key);
    if (old == kLooseNoKey || old == key) break;
    h = (h + 1) & d.cell_mask;
  }
  if (first) d.cell_runs[h].x = s;
  if (last) d.cell_runs[h].y = s + 1;
}

/// The run of slots [begin, end) of cell `key` (empty when the cell holds no body).
__device__ inline uint2 find_cell(const LooseDesc& d, std::uint32_t key) {
  std::uint32_t h = cell_hash(key, d.cell_mask);
  for (;;) {
    const std::uint32_t k = d.cell_keys[h];
    if (k == key) return d.cell_runs[h];
    if (k == kLooseNoKey) return make_uint2(0, 0);
    h = (h + 1) & d.cell_mask;
  }
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
    if (key == d.overflow_key) {
      e.range(s + 1, d.level_begin[kLooseMaxDepth + 2]);  // the overflow bodies after it
    } else if (key != d.nan_key) {                        // a NaN box overlaps nothing
      const int level = loose_key_level(key);
      const LooseQBox q = d.slot_q[s];
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
            if (m != level || ck >= key) {
              const uint2 run = find_cell(d, ck);
              t0 = run.x;
              t1 = run.y;
              if (m == level && t0 <= s) t0 = s + 1 < t1 ? s + 1 : t1;
            }
          }
          e.runs(t0, t1);
        }
      }
    }
  }
  bp::block_add(d.candidates, lane == 0 ? e.tests : 0ull);
}

/// Tests slots [t0, t1) against the query box (body `body`), emitting overlapping pairs.
__device__ inline void test_run(const LooseDesc& d, const Aabb& box, std::uint32_t body, std::uint32_t t0,
                                std::uint32_t t1, unsigned long long& tests) {
  if (t0 >= t1) return;
  tests += t1 - t0;
  const PairOutput out{d.pair_keys, d.shift, d.capacity, d.total, nullptr};
  for (std::uint32_t t = t0; t < t1; ++t)
    if (overlaps(box, d.slot_box[t])) bp::append_key(out, bp::pair_key(body, d.slot_body[t], d.shift));
}

/// One thread per slot: the loose octree query of the file comment. At each level that
/// holds bodies, the thread walks the (at most 4 x 4 x 4) cells of its window, looks each
/// up in the cell table and tests the run of slots it holds (at its own level only the
/// slots after its own).
__global__ void loose_query_kernel(LooseDesc d) {
  const std::uint32_t s = blockIdx.x * blockDim.x + threadIdx.x;
  unsigned long long tests = 0;
  if (s < d.n) {
    const std::uint32_t key = d.sorted_key[s];
    const std::uint32_t body = d.slot_body[s];
    const Aabb box = d.slot_box[s];
    if (key == d.overflow_key) {
      test_run(d, box, body, s + 1, d.level_begin[kLooseMaxDepth + 2], tests);  // the overflow bodies after it
    } else if (key != d.nan_key) {  // a NaN box overlaps nothing
      const int level = loose_key_level(key);
      const LooseQBox q = d.slot_q[s];
      for (int m = 0; m <= level; ++m) {
        if (d.level_begin[m] == d.level_begin[m + 1]) continue;  // no body at this level
        const LooseRange rx = loose_query_axis_q(q.lo[0], q.hi[0], m);
        const LooseRange ry = loose_query_axis_q(q.lo[1], q.hi[1], m);
        const LooseRange rz = loose_query_axis_q(q.lo[2], q.hi[2], m);
        for (int iz = rz.lo; iz <= rz.hi; ++iz)
          for (int iy = ry.lo; iy <= ry.hi; ++iy)
            for (int ix = rx.lo; ix <= rx.hi; ++ix) {
              const std::uint32_t ck = loose_cell_key(m, static_cast<std::uint32_t>(ix),
                                                      static_cast<std::uint32_t>(iy), static_cast<std::uint32_t>(iz));
              if (m == level && ck < key) continue;  // same level: its slots all come before s
              const uint2 run = find_cell(d, ck);
              std::uint32_t t0 = run.x;
              if (m == level && t0 <= s) t0 = s + 1 < run.y ? s + 1 : run.y;  // same level: the slots after s
              test_run(d, box, body, t0, run.y, tests);
            }
      }
    }
  }
  bp::block_add(d.candidates, tests);
}

/// One thread per in-tree slot t: the overflow bodies (slots [overflow_begin, used)) that
/// overlap it. Every thread of a warp walks the same overflow slots (one ballot per
/// overflow body that hits any of them).
__global__ void loose_overflow_kernel(LooseDesc d) {
  const std::uint32_t t = blockIdx.x * blockDim.x + threadIdx.x;
  const std::uint32_t ov_begin = d.level_begin[kLooseMaxDepth + 1];
  const std::uint32_t ov_end = d.level_begin[kLooseMaxDepth + 2];
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

/// `octree` on the device (see the file comment).
class LooseOctreeDevice final : public DeviceBroadPhase {
 public:
  LooseOctreeDevice(int depth, const Aabb& domain) : depth_(depth), grid_(loose_grid(domain)) {
    // Test hook: OCTOCD_CUDA_OCTREE_QUERY=warp|thread forces one query kernel.
    if (const char* q = std::getenv("OCTOCD_CUDA_OCTREE_QUERY")) {
      const std::string v = q;
      if (v == "warp") query_ = Query::Warp;
      else if (v == "thread") query_ = Query::Thread;
      else if (!v.empty())
        throw InputError(fmt::format("OCTOCD_CUDA_OCTREE_QUERY: '{}'; allowed: warp, thread (or unset)", v));
    }
    if (depth_ >= 0 && depth_ < kLooseMaxDepth) {
      overflow_key_ = loose_level_base(depth_ + 1);
      key_bits_ = 1;
      while ((overflow_key_ + 1) >> key_bits_ != 0) ++key_bits_;  // bits of the NaN key
    }
  }

  std::string name() const override { return "octree"; }

  void reserve(std::uint32_t n, cudaStream_t stream) override {
    (void)stream;
    extent_.ensure(n);
    min_.ensure(1);
    key_.ensure(n);
    body_.ensure(n);
    q_.ensure(n);
    sorted_key_.ensure(n);
    slot_body_.ensure(n);
    slot_box_.ensure(n);
    slot_q_.ensure(n);
    level_begin_.ensure(kLevelTable);
    if (n > (1u << 29)) throw RuntimeError(fmt::format("octree: {} bodies; the device octree takes at most 2^29", n));
    cell_mask_ = static_cast<std::uint32_t>(footprint::loose_cell_table_entries(n) - 1);
    cell_keys_.ensure(static_cast<std::size_t>(cell_mask_) + 1);
    cell_runs_.ensure(static_cast<std::size_t>(cell_mask_) + 1);
    std::size_t a = 0, c = 0;
    check(cub::DeviceRadixSort::SortPairs(nullptr, a, key_.get(), sorted_key_.get(), body_.get(), slot_body_.get(),
                                          static_cast<int>(n), 0, 32),
          "cub::DeviceRadixSort::SortPairs (size)");
    check(cub::DeviceReduce::Min(nullptr, c, extent_.get(), min_.get(), static_cast<int>(n)),
          "cub::DeviceReduce::Min (size)");
    temp_.ensure(std::max({a, c, std::size_t{1}}));
    n_ = n;
  }

  void find(const Aabb* aabb, std::uint32_t n, const PairOutput& out, cudaStream_t stream) override {
    bp::check_reserved(n_ != kNotReserved, n_, n, "octree");
    check(cudaMemsetAsync(out.total, 0, sizeof(std::uint32_t), stream), "cudaMemset pair total");
    if (n == 0) return;
    LooseDesc d;
    d.aabb = aabb;
    d.n = n;
    d.grid = grid_;
    d.depth = depth_;
    d.overflow_key = overflow_key_;
    d.nan_key = overflow_key_ == kLooseOverflowKey ? kLooseNoKey : overflow_key_ + 1;
    d.extent = extent_.get();
    d.min_extent = min_.get();
    d.key = key_.get();
    d.body = body_.get();
    d.q = q_.get();
    d.sorted_key = sorted_key_.get();
    d.slot_body = slot_body_.get();
    d.slot_box = slot_box_.get();
    d.slot_q = slot_q_.get();
    d.level_begin = level_begin_.get();
    d.cell_keys = cell_keys_.get();
    d.cell_runs = cell_runs_.get();
    d.cell_mask = cell_mask_;
    d.pair_keys = out.keys;
    d.shift = out.shift;
    d.capacity = out.capacity;
    d.total = out.total;
    d.candidates = out.candidates;
    const unsigned g = grid_for(n);
    std::size_t bytes = temp_.capacity();
    if (depth_ < 0) {
      loose_extent_kernel<<<g, kBlockSize, 0, stream>>>(d);
      bp::launched(cudaGetLastError(), "loose_extent");
      bp::launched(cub::DeviceReduce::Min(temp_.get(), bytes, extent_.get(), min_.get(), static_cast<int>(n), stream),
               "cub::DeviceReduce::Min");
    }
    loose_keys_kernel<<<g, kBlockSize, 0, stream>>>(d);
    bp::launched(cudaGetLastError(), "loose_keys");
    bytes = temp_.capacity();
    bp::launched(cub::DeviceRadixSort::SortPairs(temp_.get(), bytes, key_.get(), sorted_key_.get(), body_.get(),
                                             slot_body_.get(), static_cast<int>(n), 0, key_bits_, stream),
             "cub::DeviceRadixSort::SortPairs");
    check(cudaMemsetAsync(cell_keys_.get(), 0xff, (static_cast<std::size_t>(cell_mask_) + 1) * sizeof(std::uint32_t),
                          stream),
          "cudaMemset octree cell table");
    loose_gather_kernel<<<grid_for(std::max<std::uint32_t>(n, kLevelTable)), kBlockSize, 0, stream>>>(d);
    bp::launched(cudaGetLastError(), "loose_gather");
    if (query_ == Query::Warp || (query_ == Query::Auto && n < kWarpQueryBodies)) {
      loose_query_warp_kernel<<<bp::warp_grid_for(n), kBlockSize, 0, stream>>>(d);
    } else {
      loose_query_kernel<<<grid_for(n), kBlockSize, 0, stream>>>(d);
    }
    bp::launched(cudaGetLastError(), "loose_query");
    loose_overflow_kernel<<<grid_for(n), kBlockSize, 0, stream>>>(d);
    bp::launched(cudaGetLastError(), "loose_overflow");
  }

  std::uint64_t device_bytes() const override {
    std::uint64_t t = 0;
    for (const BufferBase* b : std::initializer_list<const BufferBase*>{
             &extent_, &min_, &key_, &body_, &q_, &sorted_key_, &slot_body_, &slot_box_, &slot_q_,
             &level_begin_, &cell_keys_, &cell_runs_, &temp_})
      t += b->bytes();
    return t;
  }

 private:
  int depth_;
  LooseGrid grid_;
  enum class Query { Auto, Warp, Thread };
  Query query_ = Query::Auto;
  std::uint32_t overflow_key_ = kLooseOverflowKey;  // see LooseDesc::overflow_key
  int key_bits_ = 32;                               // the key sort's end bit
  static constexpr std::uint32_t kNotReserved = 0xffffffffu;
  std::uint32_t n_ = kNotReserved;
  DeviceBuffer<float> extent_{"octree body extents"};
  DeviceBuffer<float> min_{"octree smallest extent"};
  DeviceBuffer<std::uint32_t> key_{"octree body keys"};
  DeviceBuffer<std::uint32_t> body_{"octree body indices"};
  DeviceBuffer<LooseQBox> q_{"octree body unit boxes"};
  DeviceBuffer<std::uint32_t> sorted_key_{"octree sorted keys"};
  DeviceBuffer<std::uint32_t> slot_body_{"octree slot bodies"};
  DeviceBuffer<Aabb> slot_box_{"octree slot boxes"};
  DeviceBuffer<LooseQBox> slot_q_{"octree slot unit boxes"};
  DeviceBuffer<std::uint32_t> level_begin_{"octree level table"};
  std::uint32_t cell_mask_ = 1;
  DeviceBuffer<std::uint32_t> cell_keys_{"octree cell table keys"};
  DeviceBuffer<uint2> cell_runs_{"octree cell table runs"};
  DeviceBuffer<unsigned char> temp_{"octree CUB temporary storage"};
};

}  // namespace

std::unique_ptr<DeviceBroadPhase> make_device_loose_octree(const BroadPhaseConfig& config, const Aabb& domain) {
  return std::make_unique<LooseOctreeDevice>(config.octree_depth, domain);
}

std::unique_ptr<DeviceBroadPhase> make_device_broadphase(const BroadPhaseConfig& config, const Aabb& domain) {
  if (config.name == "lbvh") return make_device_lbvh(domain);  // device only, no parameter
  // The parameter checks of make_broadphase (throws InputError naming the field).
  (void)make_broadphase(config, domain);
  if (config.name == "octree") return make_device_loose_octree(config, domain);
  if (config.name == "octree-strict") return make_device_strict_octree(config, domain);
  if (config.name == "spatial-hash") return make_device_spatial_hash(config);
  std::string names;
  for (const std::string& nm : cuda_broadphase_names()) names += (names.empty() ? "" : ", ") + nm;
  throw InputError(
      fmt::format("broadphase.name: '{}' is not available on the cuda engine; allowed there: {}", config.name, names));
}

}  // namespace gpu
}  // namespace octocd
