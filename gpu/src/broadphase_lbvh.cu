// Broadphase `lbvh` on the device: the field's standard GPU baseline, a linear BVH
// (Karras, "Maximizing parallelism in the construction of BVHs, octrees, and k-d trees",
// HPG 2012), built from scratch on every find() with the tree math of lbvh.hpp:
// 1. codes: per body the 30-bit Morton code of its AABB centre in the loose octree's root
//    cube of the scene domain (lbvh_code);
// 2. a CUB radix sort of (code, body) over 30 bits: slot order (stable: equal codes in
//    body order);
// 3. per slot its AABB gathered, and per internal node i < n - 1 its children and range
//    (lbvh_internal, Karras's Algorithm 1 with the slot as tie-break for equal codes),
//    the parent of each child, and the node's refit flag cleared;
// 4. the boxes bottom-up: one thread per leaf climbs to the root; at each node the first
//    thread to arrive (atomicAdd on the node's flag) stops, the second (which sees both
//    children's boxes, written before a __threadfence and read through L2) writes the
//    union of the two and goes on;
// 5. one thread per slot s walks the tree with a stack (lbvh_query: subtrees whose boxes
//    miss its box, or whose slots all come before s, are skipped), makes the exact test
//    (octocd::overlaps, Eq. 6) against every leaf t > s it reaches and appends the
//    overlapping pairs (bp::PairBuffer: its first pairs appended by the whole warp at the
//    end, as the octree's query), so each pair is met once, from its smaller slot.
// The pairs are appended in an order that varies run to run; the caller sorts them: the
// sorted unique set `flat` gives. FrameMetrics::cell_candidates: the leaf tests.
#include <algorithm>
#include <initializer_list>
#include <string>

#include "broadphase_common.cuh"
#include "broadphase_key_sort.cuh"
#include "device_broadphase.hpp"
#include "device_buffer.hpp"
#include "device_footprint.hpp"
#include "kernels.hpp"
#include "lbvh.hpp"

namespace octocd {
namespace gpu {
namespace {

static_assert(sizeof(LbvhNode) == footprint::kLbvhNodeBytes, "device_footprint.hpp: LbvhNode");

/// What the kernels read and write (device pointers): FindDesc's boxes, bodies and pair
/// output (keys, total, exact tests), and:
struct LbvhDesc : bp::FindDesc {
  LooseGrid grid;                          ///< root cube of the scene's domain
  std::uint32_t* key = nullptr;            ///< per body: its code (the sort's keys)
  std::uint32_t* body = nullptr;           ///< per body: its index (the sort's values)
  const std::uint32_t* sorted_key = nullptr;   ///< per slot: code, ascending
  const std::uint32_t* slot_body = nullptr;    ///< per slot: body
  Aabb* slot_box = nullptr;                ///< per slot: the body's AABB (the leaves' boxes)
  LbvhNode* nodes = nullptr;               ///< n - 1 internal nodes (0 = root)
  Aabb* node_box = nullptr;                ///< n - 1 internal boxes
  std::uint32_t* node_parent = nullptr;    ///< n - 1: parent of internal node (kLbvhNone for the root)
  std::uint32_t* leaf_parent = nullptr;    ///< n: parent of each slot's leaf
  std::uint32_t* flag = nullptr;           ///< n - 1 refit counters
};

__global__ void lbvh_code_kernel(LbvhDesc d) {
  const std::uint32_t i = blockIdx.x * blockDim.x + threadIdx.x;
  if (i >= d.n) return;
  d.key[i] = lbvh_code(d.grid, d.aabb[i]);
  d.body[i] = i;
}

/// Per slot s: its box; for s < n - 1 also internal node s, its children's parents and
/// its refit flag (n >= 2).
__global__ void lbvh_build_kernel(LbvhDesc d) {
  const std::uint32_t s = blockIdx.x * blockDim.x + threadIdx.x;
  if (s >= d.n) return;
  d.slot_box[s] = d.aabb[d.slot_body[s]];
  if (s + 1 >= d.n) return;
  const LbvhNode node = lbvh_internal(d.sorted_key, d.n, s);
  d.nodes[s] = node;
  d.flag[s] = 0u;
  if (s == 0) d.node_parent[0] = kLbvhNone;
  for (const std::uint32_t ref : {node.left, node.right}) {
    if (ref & kLbvhLeaf) d.leaf_parent[ref & ~kLbvhLeaf] = s;
    else d.node_parent[ref] = s;
  }
}

/// A box written by another thread of the running kernel: loaded through L2 (not a
/// possibly stale L1 line).
__device__ inline Aabb load_l2(const Aabb* p) {
  const float* f = reinterpret_cast<const float*>(p);
  return {{__ldcg(f), __ldcg(f + 1), __ldcg(f + 2)}, {__ldcg(f + 3), __ldcg(f + 4), __ldcg(f + 5)}};
}

/// The box of a child reference (internal node or leaf).
__device__ inline Aabb child_box(const LbvhDesc& d, std::uint32_t ref) {
  return (ref & kLbvhLeaf) ? d.slot_box[ref & ~kLbvhLeaf] : load_l2(d.node_box + ref);
}

/// One thread per leaf climbs towards the root; the second thread at a node writes its box.
__global__ void lbvh_refit_kernel(LbvhDesc d) {
  const std::uint32_t s = blockIdx.x * blockDim.x + threadIdx.x;
  if (s >= d.n) return;
  std::uint32_t p = d.leaf_parent[s];
  while (p != kLbvhNone) {
    __threadfence();  // this thread's box writes before its arrival is counted
    if (atomicAdd(d.flag + p, 1u) == 0u) return;  // the sibling's subtree is not done yet
    __threadfence();  // the sibling's box (written before its own fence and arrival) is read after
    const LbvhNode node = d.nodes[p];
    d.node_box[p] = lbvh_union(child_box(d, node.left), child_box(d, node.right));
    p = d.node_parent[p];
  }
}

/// One thread per slot: the query of the file comment.
__global__ void lbvh_query_kernel(LbvhDesc d) {
  const std::uint32_t s = blockIdx.x * blockDim.x + threadIdx.x;
  unsigned long long tests = 0;
  bp::PairBuffer pairs;
  auto counted = [](unsigned long long) {};
  if (s < d.n) {
    const Aabb box = d.slot_box[s];
    const std::uint32_t body = d.slot_body[s];
    lbvh_query(d.nodes, d.node_box, s, box, [&](std::uint32_t t) {
      ++tests;
      if (overlaps(box, d.slot_box[t])) pairs.add(d.out, bp::pair_key(body, d.slot_body[t], d.out.shift), counted);
    });
  }
  pairs.flush(d.out, counted);
  bp::block_add(d.out.candidates, tests);
}

/// `lbvh` on the device (see the file comment).
class LbvhDevice final : public DeviceBroadPhase {
 public:
  explicit LbvhDevice(const Aabb& domain) : grid_(loose_grid(domain)) {}

  std::string name() const override { return broadphase_name(BroadPhaseId::lbvh); }

  void reserve(std::uint32_t n, cudaStream_t stream) override {
    if (n > 0x7fffffffu)
      throw RuntimeError(fmt::format("device broadphase '{}': {} bodies; it takes at most 2^31 - 1", name(), n));
    // n - 1 internal nodes; n entries keep every buffer (and the host estimate,
    // device_footprint.cpp) linear in n.
    const std::size_t inner = n;
    sort_.ensure(n, true);
    leaf_parent_.ensure(n);
    nodes_.ensure(inner);
    node_box_.ensure(inner);
    node_parent_.ensure(inner);
    flag_.ensure(inner);
    std::size_t bytes = 1;
    sort_.need_temp(bytes, n, kLbvhCodeBits, stream);
    temp_.ensure(bytes);
    n_ = n;
    reserved_ = true;
  }

  void find(const Aabb* aabb, std::uint32_t n, const PairOutput& out, cudaStream_t stream) override {
    bp::check_reserved(reserved_, n_, n, broadphase_name(BroadPhaseId::lbvh));
    check(cudaMemsetAsync(out.total, 0, sizeof(std::uint32_t), stream), "cudaMemset pair total");
    if (n < 2) return;  // no pair, no exact test
    LbvhDesc d;
    d.set_find(aabb, n, out);
    d.grid = grid_;
    sort_.set_with_boxes(d);
    d.nodes = nodes_.get();
    d.node_box = node_box_.get();
    d.node_parent = node_parent_.get();
    d.leaf_parent = leaf_parent_.get();
    d.flag = flag_.get();
    const unsigned g = grid_for(n);
    bp::launch(lbvh_code_kernel, g, stream, d, "lbvh_code");
    std::size_t bytes = temp_.capacity();
    bp::launched(sort_.sort(temp_.get(), bytes, n, kLbvhCodeBits, stream), "cub::DeviceRadixSort::SortPairs");
    bp::launch(lbvh_build_kernel, g, stream, d, "lbvh_build");
    bp::launch(lbvh_refit_kernel, g, stream, d, "lbvh_refit");
    bp::launch(lbvh_query_kernel, g, stream, d, "lbvh_query");
  }

  std::uint64_t device_bytes() const override {
    return sort_.bytes() + total_bytes({&leaf_parent_, &nodes_, &node_box_, &node_parent_, &flag_, &temp_});
  }

 private:
  LooseGrid grid_;
  bool reserved_ = false;
  std::uint32_t n_ = 0;
  bp::KeySortBuffers<std::uint32_t> sort_{"lbvh body codes", "lbvh body indices", "lbvh sorted codes",
                                          "lbvh slot bodies", "lbvh slot boxes"};
  DeviceBuffer<std::uint32_t> leaf_parent_{"lbvh leaf parents"};
  DeviceBuffer<LbvhNode> nodes_{"lbvh internal nodes"};
  DeviceBuffer<Aabb> node_box_{"lbvh internal boxes"};
  DeviceBuffer<std::uint32_t> node_parent_{"lbvh internal parents"};
  DeviceBuffer<std::uint32_t> flag_{"lbvh refit flags"};
  DeviceBuffer<unsigned char> temp_{"lbvh CUB temporary storage"};
};

}  // namespace

std::unique_ptr<DeviceBroadPhase> make_device_lbvh(const Aabb& domain) { return std::make_unique<LbvhDevice>(domain); }

std::unique_ptr<DeviceBroadPhase> make_device_broadphase_lbvh(const BroadPhaseConfig&, const Aabb& domain, DeviceUse) {
  return make_device_lbvh(domain);  // no parameter
}

}  // namespace gpu
}  // namespace octocd
