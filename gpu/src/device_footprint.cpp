// The host estimate of the CUDA engine's device memory before its first step
// (cuda_device_bytes_needed, cuda_world.hpp): buffer by buffer, what the CudaWorld
// constructor, CudaWorld::Impl::prepare() (cuda_world.cpp) and the device broadphases'
// reserve() (broadphase_*.cu) allocate, with the struct sizes and capacities of
// device_footprint.hpp. Plain C++: compiled in builds with and without CUDA, and needs no
// device.
#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include <fmt/format.h>

#include "device_footprint.hpp"
#include "octocd/broadphase_registry.hpp"
#include "octocd/cuda_world.hpp"
#include "octocd/error.hpp"
#include "octocd/vertex_blocks.hpp"

namespace octocd {

namespace {

using namespace gpu::footprint;

/// Bytes of a device buffer of `count` elements of `elem` bytes (a DeviceBuffer holds at
/// least one element).
std::uint64_t buf(std::uint64_t count, std::uint64_t elem) { return std::max<std::uint64_t>(count, 1) * elem; }

/// Elements of the packed shape arrays (CudaWorld constructor: "Shapes: every octree
/// packed once").
struct ShapeCounts {
  std::uint64_t shapes = 0;
  std::uint64_t vertices = 0;
  std::uint64_t cells = 0;
  std::uint64_t level_offsets = 0;
  std::uint64_t blocks = 0;  ///< vertex block boxes: ceil(vertices / kVertexBlock) per mesh
  std::uint64_t theta = 0;
};

/// The device broadphase's reserve(n) buffers of each row of octocd/broadphase_table.def
/// whose device is `step` or `seam`: device_bytes_ID(n, cfg).

/// `flat` runs in the engine's step: no buffers of its own.
std::uint64_t device_bytes_flat(std::uint64_t, const BroadPhaseConfig&) { return 0; }

/// LooseOctreeDevice::reserve (broadphase_octree_tree.cu) and its pair cache.
std::uint64_t device_bytes_octree(std::uint64_t n, const BroadPhaseConfig&) {
  const std::uint64_t n1 = n + 1;
  const std::uint64_t temp = std::max({cub_sort_temp_bound(n, 4, 4), cub_scan_temp_bound(n1), std::uint64_t{1}});
  const std::uint64_t table = loose_cell_table_entries(n);
  // The pair cache (CoherentOctreeDevice::reserve, broadphase_octree_cache.cu): its status,
  // the fattened boxes, the cache, its scratch, the filter's selection and flags (first
  // capacity: initial_pair_capacity), the filter's CUB storage (a scan's bound).
  const std::uint64_t cap = initial_pair_capacity(n);
  const std::uint64_t cache = buf(1, 16) + buf(n, sizeof(Aabb)) + 3 * buf(cap, sizeof(std::uint64_t)) +
                              buf(cap, 1) + buf(cub_scan_temp_bound(cap), 1);
  // + the sorted mode's pair counts and segments (n + 1 each), long-segment list and its
  // two counts.
  return cache + buf(1, sizeof(float)) + 4 * buf(n, sizeof(std::uint32_t)) + 2 * buf(n1, sizeof(std::uint32_t)) +
         buf(n, sizeof(std::uint32_t)) + buf(2, sizeof(std::uint32_t)) +
         buf(n, sizeof(Aabb)) + buf(kLooseLevelTable, sizeof(std::uint32_t)) +
         buf(table, sizeof(std::uint64_t)) + buf(loose_occupancy_blocks(n) / 4, sizeof(std::uint32_t)) +
         buf(temp, 1);
}

/// StrictOctreeDevice::reserve (broadphase_octree_strict.cu).
std::uint64_t device_bytes_octree_strict(std::uint64_t n, const BroadPhaseConfig& cfg) {
  const std::uint64_t n1 = n + 1;
  const bool auto_depth = cfg.octree_depth < 0;
  std::uint64_t temp = std::max(cub_sort_temp_bound(n, 8, 4), cub_scan_temp_bound(n1));
  if (auto_depth) temp = std::max(temp, cub_scan_temp_bound(n));
  std::uint64_t b = 2 * buf(n, sizeof(std::uint64_t)) + 2 * buf(n, sizeof(std::uint32_t)) + buf(n, sizeof(Aabb)) +
                    2 * buf(n1, sizeof(std::uint32_t)) + buf(1, sizeof(double)) + buf(1, sizeof(std::uint32_t)) +
                    buf(1, sizeof(int)) + buf(temp, 1);
  if (auto_depth) b += buf(n, sizeof(double)) + buf(n, sizeof(std::uint32_t));
  return b;
}

/// SpatialHashDevice::reserve (broadphase_spatial_hash.cu).
std::uint64_t device_bytes_spatial_hash(std::uint64_t n, const BroadPhaseConfig&) {
  const std::uint64_t n1 = n + 1;
  const std::uint64_t entries = std::uint64_t{kHashEntriesPerBody} * n;
  const std::uint64_t counts = entries + n + 1;
  const std::uint64_t temp =
      std::max({cub_sort_temp_bound(entries, 8, 4), cub_scan_temp_bound(counts), cub_scan_temp_bound(n1)});
  return buf(n, sizeof(std::uint8_t)) + buf(3 * n, sizeof(std::int32_t)) + 4 * buf(n1, sizeof(std::uint32_t)) +
         2 * buf(entries, sizeof(std::uint64_t)) + 2 * buf(entries, sizeof(std::uint32_t)) +
         2 * buf(counts, sizeof(std::uint32_t)) + buf(temp, 1);
}

/// LbvhDevice::reserve (broadphase_lbvh.cu).
std::uint64_t device_bytes_lbvh(std::uint64_t n, const BroadPhaseConfig&) {
  const std::uint64_t inner = n;  // n - 1 internal nodes, sized n
  // Per body: code, index, sorted code, slot body, leaf parent; the slot boxes. Per
  // internal node: the node, its box, its parent and refit flag.
  return 5 * buf(n, sizeof(std::uint32_t)) + buf(n, sizeof(Aabb)) + buf(inner, kLbvhNodeBytes) + buf(inner, sizeof(Aabb)) +
         2 * buf(inner, sizeof(std::uint32_t)) + buf(std::max(cub_sort_temp_bound(n, 4, 4), std::uint64_t{1}), 1);
}

/// A footprint of a row of octocd/broadphase_table.def.
using Footprint = std::uint64_t (*)(std::uint64_t, const BroadPhaseConfig&);

/// The footprint of every row, in the table's order (nullptr where the device has none).
#define OCTOCD_FOOTPRINT_none(ID) nullptr
#define OCTOCD_FOOTPRINT_step(ID) &device_bytes_##ID
#define OCTOCD_FOOTPRINT_seam(ID) &device_bytes_##ID
constexpr Footprint kFootprints[] = {
#define OCTOCD_BROADPHASE(ID, NAME, HOST, DEVICE, PAIRS, COST, SUMMARY) OCTOCD_FOOTPRINT_##DEVICE(ID),
#include "octocd/broadphase_table.def"
#undef OCTOCD_BROADPHASE
};

/// The device broadphase's reserve(n) buffers; throws InputError for a broadphase the
/// device does not have.
std::uint64_t broadphase_bytes(std::uint64_t n, const BroadPhaseConfig& cfg) {
  if (const BroadPhaseInfo* info = find_broadphase_info(cfg.name)) {
    if (const Footprint bytes = kFootprints[static_cast<std::size_t>(info->id)]) return bytes(n, cfg);
  }
  throw InputError(fmt::format("broadphase.name: '{}' is not available on the cuda engine; allowed there: {}",
                               cfg.name, join_broadphase_names(cuda_broadphase_names())));
}

std::uint64_t engine_bytes(std::uint64_t n, const BroadPhaseConfig& cfg, const ShapeCounts& sc) {
  if (n > kCudaMaxBodies)
    throw InputError(fmt::format("the cuda engine takes at most {} (2^31 - 1) bodies (it indexes bodies with "
                                 "32-bit integers); this model has {}",
                                 kCudaMaxBodies, n));
  const std::uint64_t bp = broadphase_bytes(n, cfg);  // checks the name first
  const std::uint64_t n1 = n + 1;
  // Constructor: per body x, v, x_saved, v_saved, w, local, shape, aabb.
  const std::uint64_t bodies = 4 * buf(n, sizeof(Vec3)) + buf(n, sizeof(float)) + 2 * buf(n, sizeof(Aabb)) +
                               buf(n, sizeof(std::uint32_t));
  // Constructor: the packed shapes, per-shape theta, the step statistics.
  const std::uint64_t shapes = buf(sc.shapes, kDeviceShapeBytes) + buf(sc.vertices, sizeof(Vec3)) +
                               buf(sc.cells, sizeof(MeshOctreeCell)) + buf(sc.level_offsets, sizeof(std::uint32_t)) +
                               buf(sc.blocks, sizeof(Aabb)) + buf(sc.theta, sizeof(float)) + buf(1, kStepStatsBytes) +
                               buf(kMetricsPartials, kMetricsResultBytes);
  // prepare() at the first capacities: bp_counts (two), in_counts.offset (n + 1 each), the
  // contact index's offsets (n + 1, 8 bytes); per candidate pair: pair keys (2), pairs,
  // confirmed, hit, dx_a, dx_b, dv_a, dv_b, depth0, records, the contact index's ranks
  // and entries (the small path holds its in-lists instead), its long-segment list (pcap /
  // (kIndexShortSegment + 1) + 1 entries of 4 bytes, counted as a byte per pair plus 4:
  // linear in pcap); the midphase's witness cache on a model with meshes (3 x 8 bytes per
  // pair, prev_begin n + 1, its count); the midphase's two leaf item words; the two work
  // lists; CUB's temporary storage (the largest of its uses).
  static_assert(kIndexShortSegment + 1 >= sizeof(std::uint32_t), "a byte per pair covers the long-segment list");
  const std::uint64_t pcap = initial_pair_capacity(n);
  const std::uint64_t lcap = initial_list_capacity(n);
  const std::uint64_t temp = std::max({cub_sort_temp_bound(pcap, 8, 0), cub_scan_temp_bound(n1), std::uint64_t{1}});
  const std::uint64_t witness_cache = sc.vertices > 0 ? 3 * buf(pcap, sizeof(unsigned long long)) +
                                                            buf(n1, sizeof(std::uint32_t)) + buf(1, sizeof(std::uint32_t))
                                                      : 0;
  const std::uint64_t step = 3 * buf(n1, sizeof(std::uint32_t)) + buf(n1, sizeof(unsigned long long)) +
                             2 * buf(pcap, sizeof(unsigned long long)) + buf(pcap, sizeof(Pair)) +
                             2 * buf(pcap, sizeof(std::uint8_t)) + 4 * buf(pcap, sizeof(Vec3)) +
                             buf(pcap, sizeof(float)) + buf(pcap, kDeviceContactBytes) +
                             2 * buf(pcap, sizeof(std::uint32_t)) +
                             buf(pcap, 1) + sizeof(std::uint32_t) + witness_cache + buf(2, sizeof(unsigned long long)) +
                             2 * buf(lcap, kMidItemBytes) + buf(temp, 1);
  // The fused small step's column counts (n + 1), allocated when it runs (counted up to 32768
  // bodies, kMetricsOneBlockBodies: above the small path's kCudaSmallStepMaxBodies).
  const std::uint64_t small = n >= 1 && n <= 32768 ? buf(n1, sizeof(std::uint32_t)) : 0;
  return bodies + shapes + step + bp + small;
}

}  // namespace

std::vector<std::string> cuda_broadphase_names() {
  return broadphase_names_where([](const BroadPhaseInfo& b) { return b.on_device(); });
}

std::vector<std::string> cuda_only_broadphase_names() {
  return broadphase_names_where([](const BroadPhaseInfo& b) { return b.device_only(); });
}

std::uint64_t cuda_device_bytes_needed(std::uint64_t bodies, const BroadPhaseConfig& broadphase) {
  return engine_bytes(bodies, broadphase, ShapeCounts{});
}

std::uint64_t cuda_device_bytes_needed(const Model& model, const std::string& broadphase) {
  ShapeCounts sc;
  sc.shapes = model.shapes.size();
  sc.theta = model.theta_shape.size();
  for (const Shape& s : model.shapes) {
    if (!s.octree) continue;
    sc.vertices += s.octree->vertices.size();
    sc.cells += s.octree->cells.size();
    sc.level_offsets += s.octree->level_offset.size();
    sc.blocks += (s.octree->vertices.size() + kVertexBlock - 1) / kVertexBlock;
  }
  BroadPhaseConfig cfg = model.scene.broadphase;
  cfg.name = broadphase;
  return engine_bytes(model.initial.size(), cfg, sc);
}

}  // namespace octocd
