// Broadphase `octree-strict` on the device (design.md section 5.1: the paper's world octree read
// literally, paper section 3.2, Algorithms 1-2), the same structure as the CPU's
// core/src/broadphase_octree_strict.cpp, with every node decision from
// octocd/strict_octree.hpp (the header the CPU uses). Enqueued on one stream, with no host
// synchronisation and no allocation (DeviceBroadPhase contract, device_broadphase.hpp):
// 1. depth: the configured D_w, or `auto` as auto_octree_depth computes it: per body
//    strict_auto_extent / strict_auto_counts, two CUB sums (extents, counted bodies), and a
//    one-thread kernel that writes strict_auto_depth into a device int the later kernels
//    read. (The CPU sums in body order, CUB in its own fixed tree: the mean can differ in
//    the last bits, so the depth could differ where the mean sits exactly on a level
//    boundary; the pair set does not depend on the depth.)
// 2. keys: per body the node key strict_node_key (a body in the deepest node holding it; a
//    body not inside the root at the root); NaN boxes get a key at or after every
//    subtree end and are left out, as on the CPU;
// 3. a stable radix sort of (key, body): nodes in pre-order, a node's bodies in body
//    order, so a node's subtree is the contiguous run [slot of key, slot of
//    strict_subtree_key_end(key));
// 4. a query per slot, one warp per slot: the slots after it up to its subtree's end,
//    i.e. the later bodies of its own node and every body of the nodes below it, through
//    the exact test (octocd::overlaps, Eq. 6). A pair in related nodes (equal, or ancestor
//    and descendant) is met exactly once: by the earlier slot of a node, or by the
//    ancestor's body. Counted (per slot), exclusively scanned over n + 1 entries (the
//    total is offset[n], copied device-to-device to *out.total), then filled at the
//    scanned offsets where the index is below out.capacity.
// The exact tests made are exactly the pairs in related nodes, which is the CPU's
// BroadPhaseStats::cell_candidates for `octree-strict` (before its subtree-bounds culling
// and sweep): *out.candidates gets the same number as the CPU reports.
// Cost: like the CPU's (design.md section 5.1) a body that straddles a split plane near the root is
// tested against its whole subtree; the warp per slot spreads that work over 32 lanes.
#include "broadphase_common.cuh"
#include "broadphase_key_sort.cuh"
#include "scanned_counts.hpp"
#include "octocd/broadphase.hpp"
#include "octocd/loose_octree.hpp"
#include "octocd/strict_octree.hpp"

namespace octocd {
namespace gpu {
namespace {

/// What the strict-octree kernels read and write (device pointers; n bodies): FindDesc's
/// boxes, bodies and pair output (keys, capacity, candidates), and:
struct StrictDesc : bp::FindDesc {
  Aabb domain;                        ///< the scene's domain (m): the root cube's box
  int depth = 2;                      ///< D_w in [0, 10]; -1 = auto (read *depth_auto)
  int* depth_auto = nullptr;          ///< one int: D_w for auto (written by the depth kernel)
  unsigned long long no_key = 0;      ///< key of a NaN body: >= every node key and subtree end
  double* extent = nullptr;           ///< per body (auto): strict_auto_extent, 0 if not counted
  std::uint32_t* counted = nullptr;   ///< per body (auto): 1 if its extent counts
  double* extent_sum = nullptr;       ///< one double (auto): sum of extent
  std::uint32_t* counted_sum = nullptr;  ///< one uint32 (auto): sum of counted
  unsigned long long* key = nullptr;  ///< per body: node key (sort input)
  std::uint32_t* body = nullptr;      ///< per body: its index (sort input)
  const unsigned long long* sorted_key = nullptr;  ///< per slot: node key, ascending
  const std::uint32_t* slot_body = nullptr;        ///< per slot: body (body order per node)
  Aabb* slot_box = nullptr;           ///< per slot: the body's AABB
  std::uint32_t* count = nullptr;     ///< per slot: pairs found (count pass); count[n] = 0
  const std::uint32_t* offset = nullptr;  ///< per slot: exclusive scan of count (fill pass)
};

__device__ int depth_of(const StrictDesc& d) { return d.depth >= 0 ? d.depth : *d.depth_auto; }

__global__ void strict_extent_kernel(StrictDesc d) {
  const std::uint32_t i = blockIdx.x * blockDim.x + threadIdx.x;
  if (i >= d.n) return;
  const double e = strict_auto_extent(d.aabb[i]);
  const bool c = strict_auto_counts(e);
  d.extent[i] = c ? e : 0.0;
  d.counted[i] = c ? 1u : 0u;
}

__global__ void strict_depth_kernel(StrictDesc d) {
  if (blockIdx.x == 0 && threadIdx.x == 0) *d.depth_auto = strict_auto_depth(*d.extent_sum, *d.counted_sum, d.domain);
}

__global__ void strict_keys_kernel(StrictDesc d) {
  const std::uint32_t i = blockIdx.x * blockDim.x + threadIdx.x;
  if (i >= d.n) return;
  const Aabb b = d.aabb[i];
  d.body[i] = i;
  if (loose_has_nan(b)) {  // overlaps nothing (Eq. 6): left out, as on the CPU
    d.key[i] = d.no_key;
    return;
  }
  d.key[i] = strict_node_key(strict_grid(d.domain, depth_of(d)), b);
}

__global__ void strict_gather_kernel(StrictDesc d) {
  const std::uint32_t s = blockIdx.x * blockDim.x + threadIdx.x;
  if (s >= d.n) return;
  d.slot_box[s] = d.aabb[d.slot_body[s]];
}

/// One warp per slot s: the slots (s, end of s's subtree) through Eq. 6.
template <bool kFill>
__global__ void strict_query_kernel(StrictDesc d) {
  bp::warp_query<kFill>(d.n, 0, d.out, d.offset, d.count,
                        [&](std::uint32_t s, unsigned lane, bp::WarpWriter& w, unsigned long long& tests) {
    const unsigned long long key = d.sorted_key[s];
    if (key != d.no_key) {
      const std::uint32_t end = bp::lower_bound_u64(d.sorted_key, s + 1, d.n, strict_subtree_key_end(key, depth_of(d)));
      const Aabb box = d.slot_box[s];
      const std::uint32_t body_s = d.slot_body[s];
      for (std::uint32_t t0 = s + 1; t0 < end; t0 += bp::kWarpSize) {
        const std::uint32_t t = t0 + lane;
        bool hit = false;
        unsigned long long pk = 0;
        if (t < end) {
          hit = overlaps(box, d.slot_box[t]);
          if (kFill && hit) pk = bp::pair_key(body_s, d.slot_body[t], d.out.shift);
        }
        w.round(hit, pk);
      }
      if (lane == 0) tests = end - s - 1;
    }
  });
}

class StrictOctreeDevice final : public DeviceBroadPhase {
 public:
  StrictOctreeDevice(int depth, const Aabb& domain) : depth_(depth), domain_(domain) {
    // Node keys have at most 3 D_w + 4 bits (D_w = 10 for auto) and every subtree end is
    // at most 2^(3 D_w + 4) (the root's): that is the NaN key, so a subtree's slot range
    // never reaches the NaN bodies. The sort looks at one bit more.
    const int bits = 3 * (depth_ >= 0 ? depth_ : kStrictMaxDepth) + 4;
    no_key_ = 1ull << bits;
    end_bit_ = bits + 1;
  }

  std::string name() const override { return broadphase_name(BroadPhaseId::octree_strict); }

  void reserve(std::uint32_t n, cudaStream_t stream) override {
    const std::size_t n1 = static_cast<std::size_t>(n) + 1;
    sort_.ensure(n, true);
    pairs_.ensure(n1);
    scalars_d_.ensure(1);
    scalars_u_.ensure(1);
    depth_auto_.ensure(1);
    if (depth_ < 0) {
      extent_.ensure(n);
      counted_.ensure(n);
    }
    // CUB temporary storage for every primitive find() runs on these sizes.
    std::size_t bytes = 0;
    sort_.need_temp(bytes, n, end_bit_, stream);
    pairs_.need_temp(bytes, static_cast<std::uint32_t>(n1), stream);
    if (depth_ < 0) {
      bp::need_temp(bytes, "cub::DeviceReduce::Sum (size)",
                    [&](std::size_t& b) { return sum_f64(nullptr, b, nullptr, nullptr, n, stream); });
      bp::need_temp(bytes, "cub::DeviceReduce::Sum (size)",
                    [&](std::size_t& b) { return sum_u32(nullptr, b, nullptr, nullptr, n, stream); });
    }
    temp_.ensure(bytes);
    reserved_ = true;
    reserved_n_ = n;
  }

  void find(const Aabb* aabb, std::uint32_t n, const PairOutput& out, cudaStream_t stream) override {
    if (!bp::start_find(reserved_, reserved_n_, n, broadphase_name(BroadPhaseId::octree_strict), out, stream)) return;
    StrictDesc d;
    d.set_find(aabb, n, out);
    d.domain = domain_;
    d.depth = depth_;
    d.depth_auto = depth_auto_.get();
    d.no_key = no_key_;
    d.extent = extent_.get();
    d.counted = counted_.get();
    d.extent_sum = scalars_d_.get();
    d.counted_sum = scalars_u_.get();
    sort_.set_with_boxes(d);
    d.count = pairs_.count.get();
    d.offset = pairs_.offset.get();
    std::size_t bytes = temp_.capacity();

    if (depth_ < 0) {  // auto_octree_depth on the device
      strict_extent_kernel<<<grid_for(n), kBlockSize, 0, stream>>>(d);
      bp::launched(cudaGetLastError(), "strict_extent");
      bp::launched(sum_f64(temp_.get(), bytes, extent_.get(), scalars_d_.get(), n, stream), "cub::DeviceReduce::Sum");
      bytes = temp_.capacity();
      bp::launched(sum_u32(temp_.get(), bytes, counted_.get(), scalars_u_.get(), n, stream), "cub::DeviceReduce::Sum");
      strict_depth_kernel<<<1, 1, 0, stream>>>(d);
      bp::launched(cudaGetLastError(), "strict_depth");
    }
    strict_keys_kernel<<<grid_for(n), kBlockSize, 0, stream>>>(d);
    bp::launched(cudaGetLastError(), "strict_keys");
    bytes = temp_.capacity();
    bp::launched(sort_.sort(temp_.get(), bytes, n, end_bit_, stream), "cub::DeviceRadixSort::SortPairs");
    strict_gather_kernel<<<grid_for(n), kBlockSize, 0, stream>>>(d);
    bp::launched(cudaGetLastError(), "strict_gather");
    check(cudaMemsetAsync(pairs_.count.get() + n, 0, sizeof(std::uint32_t), stream), "cudaMemset strict counts");
    strict_query_kernel<false><<<bp::warp_grid_for(n), kBlockSize, 0, stream>>>(d);
    bp::launched(cudaGetLastError(), "strict_query (count)");
    bytes = temp_.capacity();
    bp::launched(pairs_.scan(temp_.get(), bytes, n + 1, stream), "cub::DeviceScan::ExclusiveSum");
    check(pairs_.copy_total(out.total, n, stream), "cudaMemcpy pair total");
    strict_query_kernel<true><<<bp::warp_grid_for(n), kBlockSize, 0, stream>>>(d);
    bp::launched(cudaGetLastError(), "strict_query (fill)");
  }

  std::uint64_t device_bytes() const override {
    return sort_.bytes() + pairs_.bytes() +
           total_bytes({&extent_, &counted_, &scalars_d_, &scalars_u_, &depth_auto_, &temp_});
  }

 private:
  int depth_;
  Aabb domain_;
  int end_bit_ = 34;
  unsigned long long no_key_ = 0;
  bool reserved_ = false;
  std::uint32_t reserved_n_ = 0;
  bp::KeySortBuffers<unsigned long long> sort_{"octree-strict body keys", "octree-strict body indices",
                                               "octree-strict sorted keys", "octree-strict slot bodies",
                                               "octree-strict slot boxes"};
  ScannedCounts pairs_{"octree-strict pair counts", "octree-strict pair offsets"};
  DeviceBuffer<double> extent_{"octree-strict body extents"};
  DeviceBuffer<std::uint32_t> counted_{"octree-strict counted extents"};
  DeviceBuffer<double> scalars_d_{"octree-strict extent sum"};
  DeviceBuffer<std::uint32_t> scalars_u_{"octree-strict counted sum"};
  DeviceBuffer<int> depth_auto_{"octree-strict auto depth"};
  DeviceBuffer<unsigned char> temp_{"octree-strict CUB temporary storage"};
};

}  // namespace

std::unique_ptr<DeviceBroadPhase> make_device_strict_octree(const BroadPhaseConfig& config, const Aabb& domain) {
  check_broadphase_parameters(config);  // the checks of make_broadphase (same errors)
  return std::make_unique<StrictOctreeDevice>(config.octree_depth, domain);
}

std::unique_ptr<DeviceBroadPhase> make_device_broadphase_octree_strict(const BroadPhaseConfig& config,
                                                                       const Aabb& domain, DeviceUse) {
  return make_device_strict_octree(config, domain);
}

}  // namespace gpu
}  // namespace octocd
