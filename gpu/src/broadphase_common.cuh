#pragma once
// Device helpers shared by the device broadphases (broadphase_flat.cu, and behind
// DeviceBroadPhase broadphase_octree_tree.cu, broadphase_octree_strict.cu, broadphase_spatial_hash.cu,
// broadphase_lbvh.cu): the pair key, a binary search on sorted 64-bit keys, the
// per-block sum of the exact-test counter, a warp's ordered writer into PairOutput::keys
// (count pass: counts only; fill pass: writes where the index is below the capacity) and
// the frame of a two-pass one-warp-per-item query around it, and an unordered appender
// (one atomic per group of threads). CUDA only (nvcc).
#include <algorithm>
#include <cstdint>
#include <cstdlib>
#include <initializer_list>
#include <string>
#include <vector>

#include <cooperative_groups.h>
#include <cub/block/block_reduce.cuh>

#include "device_broadphase.hpp"
#include "device_buffer.hpp"
#include "kernels.hpp"

namespace octocd {
namespace gpu {
namespace bp {

/// The base of a device broadphase's kernel descriptor: what its find() was given (the
/// kernels read the boxes and write the pairs through `out`).
struct FindDesc {
  const Aabb* aabb = nullptr;  ///< world AABBs (m), per body (device)
  std::uint32_t n = 0;         ///< bodies
  PairOutput out;              ///< pair keys, total, capacity, shift, exact tests

  /// Sets the three from find()'s arguments (host).
  void set_find(const Aabb* boxes, std::uint32_t bodies, const PairOutput& output) {
    aabb = boxes;
    n = bodies;
    out = output;
  }
};

/// Lanes of a warp; the warp-per-item kernels launch 32 threads per item.
constexpr unsigned kWarpSize = 32;

/// This thread's place in a one-warp-per-item kernel: the warp's item (global thread index /
/// kWarpSize) and the thread's lane in its warp.
struct WarpItem {
  std::size_t item;
  unsigned lane;
};
__device__ inline WarpItem warp_item() {
  const std::size_t thread = static_cast<std::size_t>(blockIdx.x) * blockDim.x + threadIdx.x;
  return {thread / kWarpSize, threadIdx.x & (kWarpSize - 1)};
}
constexpr unsigned kFullMask = 0xffffffffu;

/// The output key of the pair {p, q} (p != q): (min << shift) | max, shift in [1, 32]
/// with p, q < 2^shift (PairOutput::shift, device_broadphase.hpp).
__device__ inline unsigned long long pair_key(std::uint32_t p, std::uint32_t q, int shift) {
  const std::uint32_t a = p < q ? p : q;
  const std::uint32_t b = p < q ? q : p;
  return (static_cast<unsigned long long>(a) << shift) | b;
}

/// First index in [lo, hi) of the ascending `keys` whose key is >= key (hi if none).
__device__ inline std::uint32_t lower_bound_u64(const unsigned long long* keys, std::uint32_t lo, std::uint32_t hi,
                                                unsigned long long key) {
  while (lo < hi) {
    const std::uint32_t mid = lo + (hi - lo) / 2;
    if (keys[mid] < key) lo = mid + 1;
    else hi = mid;
  }
  return lo;
}

/// Adds the sum of every thread's `v` to *counter: a block reduction, then one integer
/// atomicAdd per block (order-free). Every thread of the block (kBlockSize threads) must
/// call it, once.
__device__ inline void block_add(unsigned long long* counter, unsigned long long v) {
  using Reduce = cub::BlockReduce<unsigned long long, kBlockSize>;
  __shared__ typename Reduce::TempStorage storage;
  const unsigned long long sum = Reduce(storage).Sum(v);
  if (threadIdx.x == 0 && sum != 0) atomicAdd(counter, sum);
}

/// One warp's pairs for one item (a slot or a body), round by round: in each round every
/// lane offers at most one hit; hits are numbered in lane order after those of earlier
/// rounds, so the output order is fixed. With keys != nullptr (fill pass) hit k goes to
/// keys[base + k] when base + k < capacity (PairOutput's contract); `written` counts all.
/// Every lane of the warp must call round() the same number of times.
struct WarpWriter {
  unsigned long long* keys = nullptr;
  std::uint32_t base = 0;
  std::uint32_t capacity = 0;
  std::uint32_t written = 0;

  __device__ void round(bool hit, unsigned long long key) {
    const unsigned lane = threadIdx.x & (kWarpSize - 1);
    const unsigned ballot = __ballot_sync(kFullMask, hit);
    if (hit && keys) {
      const unsigned long long pos =
          static_cast<unsigned long long>(base) + written + __popc(ballot & ((1u << lane) - 1u));
      if (pos < capacity) keys[pos] = key;
    }
    written += static_cast<std::uint32_t>(__popc(ballot));
  }
};

/// Appends `key` to out.keys at the next free index of *out.total, written only when that
/// index is below out.capacity (PairOutput's contract: the total still counts it): one
/// atomicAdd per group of threads that reach the call together (their order varies from
/// run to run; the set does not).
__device__ inline void append_key(const PairOutput& out, unsigned long long key) {
  const cooperative_groups::coalesced_group g = cooperative_groups::coalesced_threads();
  std::uint32_t base = 0;
  if (g.thread_rank() == 0) base = atomicAdd(out.total, static_cast<std::uint32_t>(g.size()));
  const std::uint32_t idx = g.shfl(base, 0) + static_cast<std::uint32_t>(g.thread_rank());
  if (idx < out.capacity) out.keys[idx] = key;
}

/// Pairs a thread keeps in PairBuffer before it appends the rest one by one.
constexpr int kPairBufferKeys = 8;

/// A thread's pair keys, appended by its whole warp at once (one-thread-per-item queries: `octree`,
/// `lbvh`). append_key from inside a thread's own traversal aggregates only the few lanes that meet
/// a pair at the same moment, so at 10^6 bodies it is about one atomic on the one *out.total per
/// pair, which bounds both queries. A thread keeps its first kPairBufferKeys keys here (the bench's
/// boxes have 0.86 pairs per body) and appends those after with append_key; flush() then gives the
/// warp's kept keys consecutive indices with one atomicAdd (reports/h100/README.md, "Experiments
/// and A/B results", "Broadphases"). The set of keys in out.keys[0 .. min(total, capacity)) is that
/// of appending each key at once; their order varies.
struct PairBuffer {
  unsigned long long key[kPairBufferKeys];
  int count = 0;

  /// Keeps `k`, or appends it (append_key) when the buffer is full; then counted(k) (the
  /// octree's per-body pair count) when appended here.
  template <class Counted>
  __device__ void add(const PairOutput& out, unsigned long long k, Counted&& counted) {
    if (count < kPairBufferKeys) {
      key[count++] = k;
      return;
    }
    append_key(out, k);
    counted(k);
  }

  /// Appends the kept keys of the warp: every lane of the warp calls it, converged; one
  /// atomicAdd on *out.total for the warp (by its last lane), keys written below the
  /// capacity; counted(k) for each.
  template <class Counted>
  __device__ void flush(const PairOutput& out, Counted&& counted) {
    const std::uint32_t lane = threadIdx.x & 31u;
    std::uint32_t incl = static_cast<std::uint32_t>(count);
    for (unsigned o = 1; o < 32; o <<= 1) {
      const std::uint32_t v = __shfl_up_sync(kFullMask, incl, o);
      if (lane >= o) incl += v;
    }
    const std::uint32_t warp_total = __shfl_sync(kFullMask, incl, 31);
    if (warp_total == 0) return;
    std::uint32_t base = 0;
    if (lane == 31) base = atomicAdd(out.total, warp_total);
    base = __shfl_sync(kFullMask, base, 31) + incl - static_cast<std::uint32_t>(count);
    for (int i = 0; i < count; ++i) {
      const std::uint32_t idx = base + static_cast<std::uint32_t>(i);
      if (idx < out.capacity) out.keys[idx] = key[i];
      counted(key[i]);
    }
  }
};

/// The frame of a one-warp-per-item query in two passes (count, then fill; PairOutput's
/// contract) over `items` items whose counts and offsets start at index `first`: for an item
/// i < items (uniform over the warp) it calls query(i, lane, w, tests) with the item's
/// WarpWriter w (fill pass, kFill: writing into out.keys from offset[first + i] below
/// out.capacity; count pass: counting only, no offset read) and this thread's exact-test
/// counter; then in the count pass lane 0 stores w.written in count[first + i], and the
/// block's tests are added to *out.candidates (block_add). Every thread of the block
/// (kBlockSize threads) must call it, once.
template <bool kFill, class Query>
__device__ inline void warp_query(std::uint32_t items, std::uint32_t first, const PairOutput& out,
                                  const std::uint32_t* offset, std::uint32_t* count, Query&& query) {
  const auto [item, lane] = warp_item();
  unsigned long long tests = 0;
  if (item < items) {  // uniform over the warp
    const std::uint32_t i = static_cast<std::uint32_t>(item);
    WarpWriter w;
    if (kFill) {
      w.keys = out.keys;
      w.base = offset[first + i];
      w.capacity = out.capacity;
    }
    query(i, lane, w, tests);
    if (!kFill && lane == 0) count[first + i] = w.written;
  }
  if (!kFill) block_add(out.candidates, tests);
}

/// Blocks of kBlockSize threads for one warp per item (at least 1).
inline unsigned warp_grid_for(std::size_t items) { return grid_for(items * kWarpSize); }

/// Throws RuntimeError naming the kernel when its launch failed.
inline void launched(cudaError_t e, const char* kernel) {
  if (e != cudaSuccess) {
    (void)cudaGetLastError();
    throw RuntimeError(fmt::format("CUDA kernel '{}' failed to launch: {}", kernel, cuda_text(e)));
  }
}

/// Grows `bytes` to the CUB temporary storage a size query asks for: `query(b)` runs the
/// primitive with a null temporary buffer, which sets b; its error is check()ed as `what`.
template <class Query>
inline void need_temp(std::size_t& bytes, const char* what, Query query) {
  std::size_t b = 0;
  check(query(b), what);
  bytes = std::max(bytes, b);
}

/// Throws RuntimeError (a programming error of the caller) when find() gets a body count
/// that reserve() did not size the scratch for.
inline void check_reserved(bool reserved, std::uint32_t reserved_n, std::uint32_t n, const std::string& name) {
  if (!reserved || reserved_n != n)
    throw RuntimeError(fmt::format("device broadphase '{}': find() with {} bodies but reserve() sized it for {}; "
                                   "call reserve(n) first (outside graph capture)",
                                   name, n, reserved ? std::to_string(reserved_n) : std::string("none")));
}

/// Launches `kernel(d)` on `grid` blocks of kBlockSize threads in `stream` and checks the
/// launch (launched: RuntimeError naming `name`).
template <class Desc>
inline void launch(void (*kernel)(Desc), unsigned grid, cudaStream_t stream, const Desc& d, const char* name) {
  kernel<<<grid, kBlockSize, 0, stream>>>(d);
  launched(cudaGetLastError(), name);
}

/// The start of a device broadphase's find(): checks that reserve() sized it for `n`
/// (check_reserved, `name`); with no body, zeroes the pair total and returns false (nothing
/// to find), else true.
inline bool start_find(bool reserved, std::uint32_t reserved_n, std::uint32_t n, const std::string& name,
                       const PairOutput& out, cudaStream_t stream) {
  check_reserved(reserved, reserved_n, n, name);
  if (n > 0) return true;
  check(cudaMemsetAsync(out.total, 0, sizeof(std::uint32_t), stream), "cudaMemset pair total");
  return false;
}

}  // namespace bp
}  // namespace gpu
}  // namespace octocd
