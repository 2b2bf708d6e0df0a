// Broadphase `octree` on the device: the loose octree of SPEC 5.1 (Ulrich 2000, looseness
// 2) with every cell and level decision from octocd/loose_octree.hpp, the header the CPU
// driver (core/src/broadphase_octree.cpp) uses. Steps (orchestrated by cuda_world.cpp):
// 1. keys: D_w (the scene's, or `auto` from the smallest body extent, a CUB minimum),
//    then per body loose_place_unit -> (level, Morton cell) key, the overflow key, or the
//    NaN key; its unit box in fixed point (loose_q_min / loose_q_max);
// 2. a stable radix sort by key: slot order = (key, body), so every occupied cell is a
//    contiguous run of slots and the levels follow each other in key order;
// 3. a level table (first slot of every level, of the overflow list and of the NaN
//    bodies), then a query per slot, one warp each:
//    - a body in a cell (level l) looks at every level m <= l that holds bodies: the
//      cells whose loose boxes meet its own box (loose_query_axis_q: at most 4 per axis),
//      found by binary search in the sorted keys, one cell per lane; at m = l it keeps
//      only slots after its own, at m < l every body;
//    - an overflow body tests every in-tree body and the overflow bodies after it;
//    then the exact AABB test (octocd::overlaps, Eq. 6), 32 candidates at a time. Each
//    overlapping pair is met exactly once (same level: by the smaller slot; across levels:
//    by the finer body; with the overflow list: by the overflow body), because a body's
//    box lies in its cell's loose box and the query ranges are exact;
// 4. the pairs are appended as keys (a << 32) | b with warp-aggregated atomics (their
//    order varies; the set does not), then radix-sorted by the caller: the sorted unique
//    set `flat` gives.
#include <cub/device/device_radix_sort.cuh>
#include <cub/device/device_reduce.cuh>
#include <cub/device/device_scan.cuh>

#include "broadphase_common.cuh"
#include "device_broadphase.hpp"
#include "device_buffer.hpp"
#include "device_footprint.hpp"
#include "kernels.hpp"

namespace octocd {
namespace gpu {
namespace {

/// A body's unit box in the fixed point of loose_q_min / loose_q_max.
struct LooseQBox {
  std::int16_t lo[3];
  std::int16_t hi[3];
};
static_assert(sizeof(LooseQBox) == footprint::kLooseQBoxBytes, "device_footprint.hpp: LooseQBox");

/// What the kernels read and write (device pointers).
struct LooseDesc {
  const Aabb* aabb = nullptr;      ///< world AABBs, per body
  std::uint32_t n = 0;             ///< bodies
  LooseGrid grid;                  ///< root cube of the scene's domain
  int depth = 2;                   ///< D_w in [0, 10]; -1 = auto (from *min_extent)
  float* extent = nullptr;         ///< scratch per body (auto depth): largest unit side
  float* min_extent = nullptr;     ///< one float: the smallest extent (auto depth)
  std::uint32_t* key = nullptr;    ///< per body: cell key (kLooseOverflowKey / kLooseNoKey)
  std::uint32_t* body = nullptr;   ///< per body: its index (the sort's values)
  LooseQBox* q = nullptr;          ///< per body: fixed-point unit box
  const std::uint32_t* sorted_key = nullptr;   ///< per slot: key, ascending
  const std::uint32_t* slot_body = nullptr;    ///< per slot: body (stable: body order per cell)
  Aabb* slot_box = nullptr;        ///< per slot: the body's AABB
  LooseQBox* slot_q = nullptr;     ///< per slot: the body's fixed-point box
  /// Per level m in [0, kLooseMaxDepth + 1]: the first slot whose key is >= level m's base
  /// (entry kLooseMaxDepth + 1: the first overflow slot); then the first NaN slot.
  std::uint32_t* level_begin = nullptr;
  unsigned long long* pair_keys = nullptr;  ///< out: (a << 32) | b, appended in any order
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

/// First slot in [lo, hi) whose key is >= key.
__device__ std::uint32_t lower_bound(const std::uint32_t* keys, std::uint32_t lo, std::uint32_t hi,
                                     std::uint32_t key);

constexpr int kLevelTable = kLooseMaxDepth + 3;  // levels 0..10, overflow, NaN
static_assert(kLevelTable == static_cast<int>(footprint::kLooseLevelTable), "device_footprint.hpp: level table");

__global__ void loose_gather_kernel(LooseDesc d) {
  const std::uint32_t s = blockIdx.x * blockDim.x + threadIdx.x;
  if (s < kLevelTable) {  // the level table (the sorted keys are complete)
    const std::uint32_t base = s <= static_cast<std::uint32_t>(kLooseMaxDepth)
                                   ? loose_level_base(static_cast<int>(s))
                                   : (s == kLooseMaxDepth + 1 ? kLooseOverflowKey : kLooseNoKey);
    d.level_begin[s] = lower_bound(d.sorted_key, 0, d.n, base);
  }
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


/// One warp's query for slot s: the lanes test the candidate slots of a range 32 at a
/// time and append the overlapping pairs (by body index, a < b) with one atomic per 32.
struct WarpEmitter {
  const LooseDesc& d;
  std::uint32_t lane;
  unsigned long long tests = 0;  // warp-uniform
  std::uint32_t body_s;
  Aabb box_s;

  /// Tests slots [t0, t1) (warp-uniform bounds).
  __device__ void range(std::uint32_t t0, std::uint32_t t1) {
    if (t0 >= t1) return;
    tests += t1 - t0;
    for (std::uint32_t b = t0; b < t1; b += 32) {
      const std::uint32_t t = b + lane;
      const bool hit = t < t1 && overlaps(box_s, d.slot_box[t]);
      const unsigned mask = __ballot_sync(bp::kFullMask, hit);
      if (mask == 0) continue;
      std::uint32_t base = 0;
      if (lane == 0) base = atomicAdd(d.total, static_cast<std::uint32_t>(__popc(mask)));
      base = __shfl_sync(bp::kFullMask, base, 0);
      if (hit) {
        const std::uint32_t idx = base + static_cast<std::uint32_t>(__popc(mask & ((1u << lane) - 1u)));
        if (idx < d.capacity) {
          d.pair_keys[idx] = bp::pair_key(body_s, d.slot_body[t]);
        }
      }
    }
  }
};

/// One warp per slot (grid-stride): the loose octree query of the file comment. At each
/// level the lanes look up the (at most 4 x 4 x 4) cells in parallel, then the warp tests
/// each non-empty cell's slots.
__global__ void loose_query_kernel(LooseDesc d) {
  const std::uint32_t lane = threadIdx.x & 31u;
  const std::uint32_t warps = (gridDim.x * blockDim.x) >> 5;
  for (std::uint32_t s = (blockIdx.x * blockDim.x + threadIdx.x) >> 5; s < d.n; s += warps) {
    const std::uint32_t key = d.sorted_key[s];
    WarpEmitter e{d, lane};
    e.body_s = d.slot_body[s];
    e.box_s = d.slot_box[s];
    if (key != kLooseNoKey) {  // a NaN box overlaps nothing
      const std::uint32_t overflow_begin = d.level_begin[kLooseMaxDepth + 1];
      if (key == kLooseOverflowKey) {
        const std::uint32_t used = d.level_begin[kLooseMaxDepth + 2];
        e.range(0, overflow_begin);
        e.range(s + 1, used);
      } else {
        const int level = loose_key_level(key);
        const LooseQBox q = d.slot_q[s];
        for (int m = 0; m <= level; ++m) {
          const std::uint32_t lv_begin = d.level_begin[m];
          const std::uint32_t lv_end = d.level_begin[m + 1];
          if (lv_begin == lv_end) continue;  // no body at this level
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
              t0 = lower_bound(d.sorted_key, lv_begin, lv_end, ck);
              t1 = (t0 < lv_end && d.sorted_key[t0] == ck) ? lower_bound(d.sorted_key, t0, lv_end, ck + 1) : t0;
              if (m == level && t0 <= s) t0 = s + 1 < t1 ? s + 1 : t1;  // same level: only the slots after s
            }
            unsigned busy = __ballot_sync(bp::kFullMask, t0 < t1);
            while (busy) {
              const int src = __ffs(busy) - 1;
              busy &= busy - 1;
              e.range(__shfl_sync(bp::kFullMask, t0, src), __shfl_sync(bp::kFullMask, t1, src));
            }
          }
        }
      }
    }
    if (lane == 0 && e.tests) atomicAdd(d.candidates, e.tests);
  }
}

/// `octree` on the device (see the file comment).
class LooseOctreeDevice final : public DeviceBroadPhase {
 public:
  LooseOctreeDevice(int depth, const Aabb& domain) : depth_(depth), grid_(loose_grid(domain)) {}

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
    d.pair_keys = out.keys;
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
                                             slot_body_.get(), static_cast<int>(n), 0, 32, stream),
             "cub::DeviceRadixSort::SortPairs");
    loose_gather_kernel<<<grid_for(std::max<std::uint32_t>(n, kLevelTable)), kBlockSize, 0, stream>>>(d);
    bp::launched(cudaGetLastError(), "loose_gather");
    loose_query_kernel<<<bp::warp_grid_for(n), kBlockSize, 0, stream>>>(d);
    bp::launched(cudaGetLastError(), "loose_query");
  }

  std::uint64_t device_bytes() const override {
    std::uint64_t t = 0;
    for (const BufferBase* b : std::initializer_list<const BufferBase*>{
             &extent_, &min_, &key_, &body_, &q_, &sorted_key_, &slot_body_, &slot_box_, &slot_q_,
             &level_begin_, &temp_})
      t += b->bytes();
    return t;
  }

 private:
  int depth_;
  LooseGrid grid_;
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
  DeviceBuffer<unsigned char> temp_{"octree CUB temporary storage"};
};

}  // namespace

std::unique_ptr<DeviceBroadPhase> make_device_loose_octree(const BroadPhaseConfig& config, const Aabb& domain) {
  return std::make_unique<LooseOctreeDevice>(config.octree_depth, domain);
}

std::unique_ptr<DeviceBroadPhase> make_device_broadphase(const BroadPhaseConfig& config, const Aabb& domain) {
  // The parameter checks of make_broadphase (throws InputError naming the field).
  (void)make_broadphase(config, domain);
  if (config.name == "octree") return make_device_loose_octree(config, domain);
  if (config.name == "octree-strict") return make_device_strict_octree(config, domain);
  if (config.name == "spatial-hash") return make_device_spatial_hash(config);
  throw InputError(fmt::format("broadphase.name: '{}' is not available on the cuda engine; allowed there: "
                               "flat, octree, octree-strict, spatial-hash",
                               config.name));
}

}  // namespace gpu
}  // namespace octocd
