#pragma once
/// \file device_broadphase.hpp
/// The seam between the CUDA engine's step (cuda_world.cpp) and its device broadphases
/// (design.md section 5.1 on the GPU): the rows of octocd/broadphase_table.def with device
/// `seam`: `octree` (loose), `octree-strict`, `spatial-hash`, and `lbvh` (a Karras 2012
/// linear BVH: the field's standard GPU baseline, on the device only); `flat` (device
/// `step`) stays inside cuda_world.cpp as the device oracle.
///
/// Contract of DeviceBroadPhase::find:
/// - input: n world AABBs on the device (m), the same array the CPU broadphase gets;
/// - output: every pair (a, b), a < b, whose AABBs overlap (octocd::overlaps, Eq. 6,
///   inclusive; a box with a NaN coordinate overlaps nothing), each exactly once, as the
///   key (a << 32) | b, in any order, into out.keys[0 .. min(total, out.capacity));
///   *out.total (device) receives the total found, which may exceed out.capacity: the
///   caller then grows the buffer and runs the step again (no pair is ever dropped);
/// - *out.candidates (device) is incremented by the exact AABB tests made (FrameMetrics::
///   cell_candidates), with integer atomics (order-free);
/// - everything is enqueued on `stream`; find() makes no host synchronisation and no
///   allocation (so the step can be captured in a CUDA graph): scratch is sized by
///   reserve(), which the caller calls before find() whenever n changes, outside capture.
///
/// Plain C++ (compiled by the host compiler and nvcc).

#include <cstdint>
#include <memory>
#include <string>

#include <cuda_runtime_api.h>

#include "octocd/broadphase.hpp"
#include "octocd/math.hpp"

namespace octocd {
namespace gpu {

/// Bits needed to hold every value in [0, n], at least 1 and at most 32: the engine's
/// PairOutput::shift for n bodies (body indices < n < 2^key_bits(n)) and the end bit of
/// its sorts by body index.
inline int key_bits(std::uint32_t n) {
  int bits = 1;
  while (bits < 32 && (n >> bits) != 0) ++bits;
  return bits;
}

/// Where a device broadphase writes its pairs (all device pointers).
struct PairOutput {
  unsigned long long* keys = nullptr;        ///< capacity entries: (a << shift) | b, a < b
  /// Bits of b in a key, in [1, 32]; every body index must be < 2^shift. The engine uses
  /// key_bits(n), so its key sort covers 2 x shift bits, not 32 + shift.
  int shift = 32;
  std::uint32_t capacity = 0;                ///< entries keys can hold
  std::uint32_t* total = nullptr;            ///< out: pairs found (may exceed capacity)
  unsigned long long* candidates = nullptr;  ///< added: exact AABB tests
  /// Optional (nullptr: unused), capacity entries the broadphase may overwrite. Given to a
  /// broadphase whose sorts_pairs() is true, find() leaves keys[0 .. total) in ascending
  /// order whenever total <= capacity (the sorted unique set `flat` gives), so the caller
  /// needs no sort of its own; the entries from total on are left as they were. When the
  /// pairs do not fit (total > capacity), keys[0 .. capacity) hold pairs of the set in any
  /// order, as without a scratch.
  unsigned long long* scratch = nullptr;
};

/// What the caller does after a find() once its stream has synchronised (settle()).
enum class Settled {
  Valid,  ///< the pairs find() wrote are the contract's
  Rerun,  ///< they are not (a pair cache that missed): run find() again on the same boxes
  /// They are not and the broadphase needs larger buffers: call reserve(n) (outside any
  /// capture; buffer addresses change, so a captured graph must be dropped), then find().
  Regrow
};

/// Plans a broadphase may enqueue (plan() is in [0, kBroadPhasePlans)).
constexpr int kBroadPhasePlans = 3;

/// A broadphase on the device; owns its scratch buffers (released by the destructor).
class DeviceBroadPhase {
 public:
  virtual ~DeviceBroadPhase() = default;
  /// The `--broadphase` name.
  virtual std::string name() const = 0;
  /// Sizes the scratch for n bodies (may allocate; throws RuntimeError naming the buffer
  /// and bytes when device memory runs out). Called before find() when n changes.
  virtual void reserve(std::uint32_t n, cudaStream_t stream) = 0;
  /// Enqueues the broadphase on `stream` (see the file comment for the contract).
  virtual void find(const Aabb* aabb, std::uint32_t n, const PairOutput& out, cudaStream_t stream) = 0;
  /// Whether find() sorts its keys when given PairOutput::scratch (`octree`); without it
  /// (or when false) the keys come in any order and the caller sorts them.
  virtual bool sorts_pairs() const { return false; }
  /// Device bytes held by the scratch.
  virtual std::uint64_t device_bytes() const = 0;
  /// Which work the next find() enqueues, in [0, kBroadPhasePlans), decided on the host
  /// from earlier find()s (a broadphase with state across calls: a pair cache); a caller
  /// that captures find() into CUDA graphs keeps one graph per plan. Default 0 (always
  /// the same work).
  virtual int plan() const { return 0; }
  /// Called once after every find() (or replay of a captured find()), when its stream has
  /// synchronised: whether its pairs hold (Settled); may change plan(). Stateless
  /// broadphases: always Valid.
  virtual Settled settle() { return Settled::Valid; }
};

/// What a device broadphase is made for.
enum class DeviceUse {
  OneShot,  ///< each find() on boxes of their own (benchmarks, tests)
  Steps     ///< the engine's steps, one find() a step: it may keep state across them (`octree`'s pair cache)
};

/// The device factory of every row of octocd/broadphase_table.def with device `seam`:
/// make_device_broadphase_ID(config, domain, use), defined beside its broadphase
/// (broadphase_octree_cache.cu, broadphase_octree_strict.cu, broadphase_spatial_hash.cu,
/// broadphase_lbvh.cu). Each checks the parameters it reads as make_broadphase checks
/// them (InputError naming the field).
#define OCTOCD_DEVICE_FACTORY_none(ID)
#define OCTOCD_DEVICE_FACTORY_step(ID)
#define OCTOCD_DEVICE_FACTORY_seam(ID)                                                                 \
  std::unique_ptr<DeviceBroadPhase> make_device_broadphase_##ID(const BroadPhaseConfig& config, const Aabb& domain, \
                                                                DeviceUse use);
#define OCTOCD_BROADPHASE(ID, NAME, HOST, DEVICE, PAIRS, COST, SUMMARY) OCTOCD_DEVICE_FACTORY_##DEVICE(ID)
#include "octocd/broadphase_table.def"
#undef OCTOCD_BROADPHASE
#undef OCTOCD_DEVICE_FACTORY_none
#undef OCTOCD_DEVICE_FACTORY_step
#undef OCTOCD_DEVICE_FACTORY_seam

/// The device broadphase named config.name over the scene's `domain` (m), made for `use`:
/// the factory of its row (device `seam`): `octree`, `octree-strict` or `spatial-hash`,
/// with the parameters of BroadPhaseConfig (checked as make_broadphase checks them), or
/// `lbvh` (no parameter). Throws InputError for any other name, naming
/// `broadphase.name` and the names the device has (cuda_broadphase_names).
/// device_broadphase.cu.
std::unique_ptr<DeviceBroadPhase> make_device_broadphase(const BroadPhaseConfig& config, const Aabb& domain,
                                                         DeviceUse use = DeviceUse::OneShot);

/// Which query kernel the device `octree` runs: Auto (a warp per body below 32768 bodies,
/// a thread per body from there), or one of them forced (its tests run both on small box
/// sets). The pair set is the same.
enum class LooseOctreeQuery { Auto, Warp, Thread };

/// `octree` (design.md section 5.1, Ulrich's loose octree, cell math of loose_octree.hpp), depth
/// config.octree_depth (-1 = auto), query kernel `query`. broadphase_octree_tree.cu.
std::unique_ptr<DeviceBroadPhase> make_device_loose_octree(const BroadPhaseConfig& config, const Aabb& domain,
                                                           LooseOctreeQuery query = LooseOctreeQuery::Auto);
/// `octree` with a pair cache across calls (temporal coherence; broadphase_octree_cache.cu):
/// the pairs of the bodies' fattened boxes (each AABB grown on every side by
/// `margin_fraction` x the median body size) are found by the one-shot `octree` and kept;
/// while every AABB stays inside its fattened box, a find() tests only the kept pairs on
/// the AABBs (sorted, so its keys come in ascending order whether or not a scratch is
/// given). A find() on a cache that a body left writes an incomplete set and its settle()
/// says Rerun; plan() then rebuilds. The first call, and 2, 4, .. 64 calls after a cache
/// that served no call, run the one-shot `octree` on the AABBs. Exact: the pair set is
/// always `flat`'s once settle() says Valid. Name "octree".
std::unique_ptr<DeviceBroadPhase> make_device_coherent_octree(const BroadPhaseConfig& config, const Aabb& domain,
                                                              float margin_fraction = 0.125f);
/// `octree-strict` (design.md section 5.1, the paper's octree read literally, as
/// core/src/broadphase_octree_strict.cpp), depth config.octree_depth (-1 = auto).
/// broadphase_octree_strict.cu.
std::unique_ptr<DeviceBroadPhase> make_device_strict_octree(const BroadPhaseConfig& config, const Aabb& domain);
/// `spatial-hash` (paper section 4.2; design.md section 5.1, as core/src/broadphase_spatial_hash.cpp),
/// cell size config.cell_size. broadphase_spatial_hash.cu.
std::unique_ptr<DeviceBroadPhase> make_device_spatial_hash(const BroadPhaseConfig& config);
/// `lbvh`: a linear BVH (Karras 2012) rebuilt on every find() from a CUB radix sort of the
/// bodies' Morton codes (the centres' level-10 cells in the loose octree's root cube of
/// `domain`, m; they shape the tree only), boxes refitted bottom-up, one stack traversal
/// per body (lbvh.hpp). Device only: the CPU has no `lbvh`. broadphase_lbvh.cu.
std::unique_ptr<DeviceBroadPhase> make_device_lbvh(const Aabb& domain);

}  // namespace gpu
}  // namespace octocd
