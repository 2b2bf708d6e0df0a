#pragma once
/// \file kernels.hpp
/// The CUDA engine's kernels as seen from the host (cuda_world.cpp): descriptor structs
/// (what each kernel reads and writes, as raw device pointers), the launch wrappers
/// (defined in the stage files integrate.cu, broadphase_flat.cu, midphase.cu, response.cu,
/// metrics.cu, primitives.cu) and the block sizes, kept here in one place.
///
/// Plain C++ (compiled by both the host compiler and nvcc): only the CUDA runtime API's
/// types, no kernel code. Every wrapper launches on `stream` and returns the launch's
/// cudaError_t (cudaGetLastError); the caller checks it (and synchronises when
/// CudaSettings::sync_each_launch).
///
/// Every formula a kernel evaluates comes from core/include/octocd/math.hpp or
/// midphase_hd.hpp (OCTOCD_HD); kernels only index, loop and store.

#include <cstddef>
#include <cstdint>

#include <cuda_runtime_api.h>

#include "octocd/broadphase.hpp"
#include "octocd/loose_octree.hpp"
#include "octocd/math.hpp"
#include "octocd/mesh_octree.hpp"
#include "octocd/midphase_hd.hpp"

namespace octocd {
namespace gpu {

/// Threads per block of every per-element kernel (one thread per body, pair or entry).
constexpr int kBlockSize = 256;
/// Threads of the single block that reduces the frame's metrics (a power of two).
constexpr int kMetricsBlockSize = 512;
/// Blocks of the metrics reduction's first pass when the scene has more than
/// kMetricsOneBlockBodies bodies (a fixed number: the sums' order depends on n only).
constexpr unsigned kMetricsBlocks = 512;
constexpr std::uint32_t kMetricsOneBlockBodies = 32768;

/// Blocks of kBlockSize threads covering `count` elements (at least 1).
inline unsigned grid_for(std::size_t count) {
  const std::size_t g = (count + kBlockSize - 1) / kBlockSize;
  return static_cast<unsigned>(g == 0 ? 1 : g);
}

#ifdef __CUDACC__
/// Entries actually present in a buffer of `capacity` entries whose producer counted
/// `*total` (more than the capacity when it overflowed: the step is then rerun).
__device__ inline std::uint32_t live_count(const std::uint32_t* total, std::uint32_t capacity) {
  const std::uint32_t t = *total;
  return t < capacity ? t : capacity;
}

/// Launches the one-argument `kernel` on `grid` blocks of kBlockSize threads on `stream`
/// when `run`; returns the launch's error (cudaGetLastError), cudaSuccess when not run.
template <class Desc>
inline cudaError_t launch_when(bool run, void (*kernel)(Desc), const Desc& d, unsigned grid, cudaStream_t stream) {
  if (!run) return cudaSuccess;
  kernel<<<grid, kBlockSize, 0, stream>>>(d);
  return cudaGetLastError();
}
#endif

/// Hot body state and per-body constants on the device (structure of arrays, n bodies).
struct BodiesDesc {
  Vec3* x = nullptr;                     ///< positions (m)
  Vec3* v = nullptr;                     ///< velocities (m/s)
  const float* w = nullptr;              ///< inverse masses (1/kg), 0 = static
  const Aabb* local = nullptr;           ///< local AABB per body (m)
  const std::uint32_t* shape = nullptr;  ///< shape index per body
  Aabb* aabb = nullptr;                  ///< world AABBs (m), written by the Aabbs stage
  Vec3* x_saved = nullptr;               ///< integrate: copy of x before the step (may be null)
  Vec3* v_saved = nullptr;               ///< integrate: copy of v before the step (may be null)
  std::uint32_t n = 0;                   ///< number of bodies
};

/// One shape in the packed device arrays: a box, or a mesh whose octree occupies
/// vertices[vertex_offset ..], cells[cell_offset ..], level_offsets[level_offset_offset ..]
/// and blocks[block_offset ..] (indices inside cells, level offsets and blocks stay relative
/// to the shape's own arrays).
struct DeviceShape {
  int is_mesh = 0;
  int depth = 0;
  Aabb bounds;
  std::uint32_t vertex_offset = 0;
  std::uint32_t vertex_count = 0;
  std::uint32_t cell_offset = 0;
  std::uint32_t level_offset_offset = 0;
  std::uint32_t block_offset = 0;  ///< its vertex_block_boxes (mesh_octree.hpp)
};

/// All shapes' octrees, packed once at construction, and the per-shape theta.
struct ShapesDesc {
  const DeviceShape* shapes = nullptr;
  const Vec3* vertices = nullptr;
  const MeshOctreeCell* cells = nullptr;
  const std::uint32_t* level_offsets = nullptr;
  const Aabb* blocks = nullptr;  ///< per mesh: vertex_block_boxes of its octree's vertices
  const float* theta = nullptr;  ///< per shape (Model::theta_shape, m); pair: pair_theta
  std::uint32_t count = 0;       ///< number of shapes
};

/// One item of a midphase work list: candidate pair k's cell `ca` of A and cell `cb` of
/// B (cell indices relative to each shape's own cells; cb unused for mesh-box), A and B
/// in hd::setup_pair's order.
struct MidItem {
  std::uint32_t k = 0;
  std::uint32_t ca = 0;
  std::uint32_t cb = 0;
  /// Last step, mesh-mesh: the leaf item of the cell pair (leaf_items, leaf_ranges): a
  /// chunk of B's cell's vertices (leaf_b_chunk of them) against a part of A's (kLeafAPart).
  std::uint32_t chunk = 0;
};

/// A's vertices per leaf work item of a mesh-mesh cell pair, and B's (kLeafChunk for every
/// two parts of A's cell: leaf_b_chunk): a large cell pair becomes several items, so its
/// vertex tests spread over several warps instead of making one warp's items the critical
/// path of a step, while B's chunk grows with A's cell, so a cell pair's items grow about
/// as B's cell, not as the product. With the vertices in depth-10 Morton order (compact
/// vertex blocks, build_mesh_octree) an item's filters skip the blocks of A's cell far from
/// B's tile, so A's part can be large. The sizes are the fastest measured on the H100's
/// Table 5 scenes (reports/h100/README.md, "Experiments and A/B results", "Midphase").
constexpr std::uint32_t kLeafAPart = 8192;
constexpr std::uint32_t kLeafChunk = 64;
/// A cell pair of at most this many vertex pairs stays one leaf item (small cells, a bunny's:
/// splitting them costs more than it spreads; reports/h100/README.md, "Experiments and A/B
/// results", "The small path (fused step)").
constexpr std::uint64_t kLeafWholePairs = 32768;

/// Whether a cell pair whose cells hold `a_vertices` and `b_vertices` is one leaf item.
OCTOCD_HD inline bool leaf_whole(std::uint32_t a_vertices, std::uint32_t b_vertices) {
  return static_cast<std::uint64_t>(a_vertices) * b_vertices <= kLeafWholePairs;
}

/// The parts of kLeafAPart vertices of A's cell of `a_vertices` vertices (at least 1).
OCTOCD_HD inline std::uint32_t leaf_a_parts(std::uint32_t a_vertices) {
  return a_vertices > kLeafAPart ? (a_vertices + kLeafAPart - 1) / kLeafAPart : 1u;
}

/// B's vertices per leaf item of a cell pair whose A cell holds `a_vertices` vertices:
/// kLeafChunk for every two of its parts (64 up to 2 parts, 128 up to 4, ...).
OCTOCD_HD inline std::uint32_t leaf_b_chunk(std::uint32_t a_vertices) {
  return kLeafChunk * ((leaf_a_parts(a_vertices) + 1) / 2);
}

/// The leaf items of a mesh-mesh cell pair whose cells hold `a_vertices` and `b_vertices`:
/// B's chunks x A's parts (MidItem::chunk).
OCTOCD_HD inline std::uint32_t leaf_items(std::uint32_t a_vertices, std::uint32_t b_vertices) {
  if (leaf_whole(a_vertices, b_vertices)) return 1;
  const std::uint32_t chunk = leaf_b_chunk(a_vertices);
  return (b_vertices + chunk - 1) / chunk * leaf_a_parts(a_vertices);
}

/// Leaf item `item` (< leaf_items(a_vertices, b_vertices)) of a mesh-mesh cell pair: A's
/// vertices [a0, a1) and B's [b0, b1), relative to each cell's first vertex (both non-empty
/// when the cells are; over the items they cover every pair of the cells' vertices once).
OCTOCD_HD inline void leaf_ranges(std::uint32_t item, std::uint32_t a_vertices, std::uint32_t b_vertices,
                                  std::uint32_t& a0, std::uint32_t& a1, std::uint32_t& b0, std::uint32_t& b1) {
  if (leaf_whole(a_vertices, b_vertices)) {
    a0 = b0 = 0;
    a1 = a_vertices;
    b1 = b_vertices;
    return;
  }
  const std::uint32_t parts = leaf_a_parts(a_vertices);
  const std::uint32_t chunk = leaf_b_chunk(a_vertices);
  b0 = item / parts * chunk;
  b1 = b_vertices - b0 < chunk ? b_vertices : b0 + chunk;
  a0 = item % parts * kLeafAPart;
  a1 = a_vertices - a0 < kLeafAPart ? a_vertices : a0 + kLeafAPart;
}

/// The midphase's witness cache (midphase.cuh, "Witnesses"): per candidate pair the vertex
/// pair that confirmed it, kept from one step to the next. Null `witness`: off.
struct WitnessDesc {
  /// Out, per pair k of this step: the confirming vertex pair as (A's vertex << 32) | B's
  /// vertex (indices into each shape's octree vertices, A and B in hd::setup_pair's order;
  /// B's is 0 for mesh-box), or kNoWitness (not confirmed by a vertex test, or the pair is
  /// decided alone).
  unsigned long long* witness = nullptr;
  /// The last step's sorted pair keys and witnesses (prev_count entries; keep_witness copies
  /// them at the end of a step) and, per body a, the first of those keys with a as its first
  /// body (stale for a body with none: such an entry points at keys of other bodies).
  unsigned long long* prev_keys = nullptr;
  unsigned long long* prev_witness = nullptr;
  std::uint32_t* prev_begin = nullptr;
  std::uint32_t* prev_count = nullptr;  ///< device word
};

/// WitnessDesc::witness of a pair with none.
constexpr unsigned long long kNoWitness = ~0ull;

/// Most vertex tests a candidate pair's witness costs in a step beyond its descent: its
/// last witness (one test) and, when that fails, the 32 x 32 pairs of the two 32-vertex
/// blocks that hold its vertices (midphase_witness.cuh, witness_block_close).
constexpr std::uint32_t kWitnessVertexTests = 1 + 32 * 32;

/// Live pairs per warp of mid_start's grid from which the witness pass (a thread per pair,
/// launch_mid_witness) tests the witnesses instead of mid_start's warps (MidListDesc::
/// witness_pass_pairs): with many pairs per warp the start's warps run their pairs' lookups
/// one after another, with few the pass's launch and its own chain of loads cost more.
constexpr std::uint32_t kWitnessPassPairsPerWarp = 4;

/// One launch of the midphase work lists (midphase.cu): start (pairs -> step 0 items),
/// expand (step i items -> step i + 1 items) or leaf (last step items -> confirmed).
struct MidListDesc {
  const Vec3* x = nullptr;
  const float* w = nullptr;
  const Aabb* aabb = nullptr;
  const std::uint32_t* shape = nullptr;
  ShapesDesc shapes;
  hd::LevelList levels;
  Pair* pairs = nullptr;  ///< start writes pairs[k] from pair_keys; the others read them
  const unsigned long long* pair_keys = nullptr;  ///< start: the sorted pair keys
  int pair_shift = 32;  ///< start: keys are (a << pair_shift) | b (PairOutput::shift)
  const std::uint32_t* pair_count = nullptr;  ///< device: pairs found (live = min with capacity)
  std::uint32_t pair_capacity = 0;
  std::uint8_t* confirmed = nullptr;        ///< out: 1 = contact confirmed (start or decide writes every pair)
  unsigned long long* counters = nullptr;   ///< out (added): box tests, leaf box pairs, vertex tests
  int steps = 0;                            ///< level steps of the list (the last one: leaves)
  const MidItem* in = nullptr;              ///< expand / leaf: this step's items
  const std::uint32_t* in_count = nullptr;  ///< device: items appended to `in`
  std::uint32_t in_capacity = 0;
  MidItem* out = nullptr;                   ///< start / expand: the next step's items
  std::uint32_t* out_count = nullptr;       ///< device: items appended (may exceed out_capacity)
  std::uint32_t out_capacity = 0;
  /// Per-pair early exit (midphase.cuh, "Early exit"; CudaSettings::midphase_early_exit): 1, an
  /// expand item, a leaf item and a leaf's vertex tiles of a pair already confirmed are
  /// skipped (counts: the work done, timing-dependent); 0, every item of the lists runs and
  /// every leaf counts its whole filtered work (deterministic counts). Same results either way.
  int early_exit = 1;
  /// > 0: the last expand step runs its leaves itself from this many items on (midphase.cuh
  /// fuse_leaves; CudaTestHooks::fuse_min_items); 0: from kFuseItemsPerWarp per warp.
  std::uint32_t fuse_min_items = 0;
  /// The least live pairs from which the witness pass (launch_mid_witness, a thread per
  /// pair) tests the pairs' witnesses; below, mid_start tests them (a warp per pair). Set
  /// by the host: kWitnessPassPairsPerWarp per warp of mid_start's grid, or
  /// CudaTestHooks::witness_pass_min_pairs.
  std::uint32_t witness_pass_pairs = 0;
  /// Two device words (or null: the small path): [0] the last step's leaf items, which
  /// the fuse decision reads (midphase.cuh, fuse_leaves), [1] this step's, summed by the
  /// last expand step's kernels and moved to [0] by mid_keep.
  unsigned long long* leaf_items = nullptr;
  /// A leaf skips a pair of vertex tiles whose boxes are more than theta apart on an axis
  /// (midphase_tiles.cuh, tiles_apart): the same results. 1 on every path; the small path's lean
  /// kernel compiles it as 0.
  int tile_cull = 1;
  /// A leaf stages, for each tile of B's vertices, only A's vertices near that tile (within
  /// theta of its box, midphase_tiles.cuh near_tile; whole vertex blocks skipped by their boxes)
  /// instead of every vertex of A's cell inside B's grown cell box: the same results; with
  /// the early exit off the same counts too (they count the whole filtered ranges either
  /// way). 1 on every path; the small path's lean kernel compiles it as 0.
  int tile_filter = 1;
  /// The witness cache (WitnessDesc; on with the early exit, on meshes with levels): a pair
  /// that needs a level step is first tested at the vertex pair that confirmed it in the
  /// last step; when that pair is still within theta the pair is confirmed without a descent.
  WitnessDesc wit;
};

/// One contact of the first response pass, as the host's ContactRecord wants it.
struct DeviceContact {
  std::uint32_t hit = 0;  ///< 1 when kept by Eq. 9; the other fields are valid only then
  int axis = 1;
  float depth = 0.0f;
  float jn = 0.0f;
  float jt = 0.0f;
  Vec3 normal;
  Vec3 v_a, v_b;
  Vec3 dx_a, dx_b;
  Vec3 dv_a, dv_b;
};

/// Per-contact response terms of one pass (one thread per candidate pair; pairs that are
/// not confirmed get hit = 0).
struct TermsDesc {
  const Pair* pairs = nullptr;
  const std::uint8_t* confirmed = nullptr;
  const std::uint32_t* pair_count = nullptr;  ///< device: pairs found
  std::uint32_t pair_capacity = 0;
  const Vec3* x = nullptr;
  const Vec3* v = nullptr;
  const float* w = nullptr;
  const Aabb* local = nullptr;
  ContactParams params;
  std::uint8_t* hit = nullptr;  ///< out: 1 when confirmed and kept by Eq. 9
  Vec3* dx_a = nullptr;         ///< out: terms (valid where hit)
  Vec3* dx_b = nullptr;
  Vec3* dv_a = nullptr;
  Vec3* dv_b = nullptr;
  float* depth0 = nullptr;          ///< out, first pass only (else null): d_p where hit, else -1
  DeviceContact* records = nullptr; ///< out, first pass while recording only (else null)
};

/// Per-body reduction and application of one pass (one thread per body).
struct ApplyDesc {
  Vec3* x = nullptr;
  Vec3* v = nullptr;
  const float* w = nullptr;
  std::uint32_t n = 0;
  /// The per-stage path's contact index (response.cu), n + 1 entries: the exclusive sums of
  /// the bodies' counts, b-side entries in the low 32 bits, candidate pairs as a in the
  /// high 32 bits. Body i's pairs (a, i), a < i, confirmed: entries[lo(offsets[i]) ..
  /// lo(offsets[i + 1])); its pairs (i, b): the candidate pairs k in [hi(offsets[i]),
  /// hi(offsets[i + 1])).
  const unsigned long long* offsets = nullptr;
  /// The b-side entries (pair k each), in k order within each body's segment once
  /// sort_entries has run (the first pass sorts the segments of at most
  /// kIndexShortSegment entries; the longer ones come sorted).
  std::uint32_t* entries = nullptr;
  int sort_entries = 0;
  /// 1: Eq. 23 (clamp_velocity to max_velocity) on each dynamic body after the pass's
  /// apply_contact_sums: the clamp stage fused into the last pass (same bits).
  int clamp = 0;
  float max_velocity = 0.0f;
  const std::uint8_t* hit = nullptr;
  const Vec3* dx_a = nullptr;
  const Vec3* dx_b = nullptr;
  const Vec3* dv_a = nullptr;
  const Vec3* dv_b = nullptr;
};

/// The frame's metrics, reduced on the device by one block in a fixed order.
struct MetricsResult {
  double kinetic_energy = 0.0;
  double momentum[3] = {0.0, 0.0, 0.0};
  double pen_sum = 0.0;
  double pen_max = 0.0;
  unsigned long long contacts = 0;
  unsigned long long pen_above = 0;
  std::uint32_t first_non_finite = 0;  ///< smallest dynamic body with a non-finite x or v; n if none
};

/// Everything the host reads back after a step, in one device struct (one copy).
struct StepStats {
  MetricsResult metrics;
  unsigned long long counters[4];  ///< box tests, leaf box pairs, vertex tests, broadphase exact tests
  /// [0] pairs found, [1 + i] items of step i (the lean kernel: the most items of step i a
  /// pair had, times kBlockPairSegments): above the list capacity, the lists are grown.
  std::uint32_t counts[hd::kMidphaseMaxLevels + 1];
  std::uint32_t index_long;  ///< bodies of the contact index's long segments (the per-stage path)
};

struct MetricsDesc {
  const Vec3* x = nullptr;
  const Vec3* v = nullptr;
  const float* w = nullptr;
  std::uint32_t n = 0;
  const float* depth0 = nullptr;  ///< first-pass depths, -1 where not a contact
  const std::uint32_t* pair_count = nullptr;  ///< device: pairs found
  std::uint32_t pair_capacity = 0;
  float slop = 0.0f;
  MetricsResult* out = nullptr;
  /// Scratch of kMetricsBlocks partial results (device), used when n > kMetricsOneBlockBodies.
  MetricsResult* partials = nullptr;
};

/// The whole step for the fused small-scene path (small_step.cu): every stage's
/// descriptor as the per-stage launches get it, plus the small path's own index buffers.
/// One cooperative launch runs integrate + AABBs, the `flat` broadphase (count, one-block
/// scans, fill), the midphase lists, `iterations` response passes with the clamp, and the
/// metrics, separated by grid-wide barriers.
struct SmallStepDesc {
  BodiesDesc bodies;  ///< with x_saved / v_saved (the rerun after an overflow)
  Vec3 gravity;
  float dt = 0.0f;
  float max_velocity = 0.0f;  ///< Eq. 23
  int iterations = 1;         ///< response passes (>= 1)
  // Broadphase `flat`, n + 1 entries each (the last count is 0, so the last offset is the
  // total): out_* counts / offsets of the pairs (i, j), j > i (the pair keys' segments);
  // in_* those of the pairs (a, i), a < i (the in-lists' segments).
  std::uint32_t* out_count = nullptr;
  std::uint32_t* out_offset = nullptr;
  std::uint32_t* in_count = nullptr;
  std::uint32_t* in_offset = nullptr;
  /// pair_capacity entries: body i's in-list at in_offset[i]: the pairs (a, i), a < i, in
  /// increasing a, first as a, then resolved to the pair's index k (kNoPair when it did not
  /// fit the capacity: the step is then rerun).
  std::uint32_t* in_list = nullptr;
  unsigned long long* pair_keys = nullptr;  ///< pair_capacity: (a << shift) | b, sorted by (a, b)
  int shift = 32;
  /// The midphase's lists as cuda_world.cpp sets them per step (pairs, pair_keys,
  /// pair_count = &stats->counts[0], confirmed, counters, steps, levels...); in / out are
  /// set per step from `lists`.
  MidListDesc mid;
  MidItem* lists[2] = {nullptr, nullptr};
  std::uint32_t list_capacity = 0;
  TermsDesc terms;      ///< depth0 and records: the first pass's (records may be null)
  ApplyDesc apply;      ///< offsets / entries unused (the small path's index is above); clamp 0
  MetricsDesc metrics;  ///< one block (n <= kMetricsOneBlockBodies)
  StepStats* stats = nullptr;       ///< device: counters and counts (zeroed by the step), metrics
  /// Mapped pinned host memory (may be null): host_slots StepStats; a step copies *stats
  /// into slot sequence % host_slots at its end (the resident kernel's steps run ahead of the
  /// host by up to kResidentAheadMax, each into its own slot).
  StepStats* host_stats = nullptr;
  std::uint32_t host_slots = 1;
  /// The response passes, the clamp and the metrics run in block 0 alone (__syncthreads
  /// instead of grid-wide barriers; the other blocks are done after the midphase) when the
  /// step's pair count is at most this (0: never). Same per-element code, same bits.
  std::uint32_t one_block_pairs = 0;
  /// Mapped pinned host memory (may be null): the step's sequence number, written last
  /// (after host_stats, behind __threadfence_system) so that the host can poll for the end.
  volatile unsigned long long* done = nullptr;
  unsigned long long sequence = 0;  ///< the value written to *done
  /// Mapped pinned host memory of kSmallProfileSlots %globaltimer stamps (ns) by thread 0 of
  /// block 0 at the end of every phase (a timed step: CudaSettings::stage_time_every, or
  /// CudaSettings::small_profile), or null (no stamps). The resident kernel stamps into it
  /// on the requests that carry kResidentStamp.
  unsigned long long* profile = nullptr;
  /// The fused front: when n <= front_bodies (at most kSmallFrontMaxBodies), every block
  /// integrates every body from x_saved / v_saved into its shared memory, counts, scans and
  /// fills the pairs from there, and block 0 stores the integrated state: no grid-wide
  /// barrier before the midphase (else three). It needs x_saved == x and v_saved == v at
  /// the step's start: the host uploads both, and the step's clamp copies the new state into
  /// them unless a list overflowed (the host then restores x from x_saved and reruns).
  std::uint32_t front_bodies = 0;
  /// Shared boxes: when front_bodies < n <= shared_boxes_bodies (at most
  /// kSmallSharedBoxesMaxBodies), every block integrates every body into its shared memory as the
  /// fused front does (block 0 stores the state; the same x_saved / v_saved contract), the
  /// grid's warps count a row and a column each from those boxes, then one grid-wide
  /// barrier, and every block scans the counts and fills its rows from its boxes: two
  /// grid-wide barriers before the midphase (else three), and no body box read from global
  /// memory by the broadphase.
  std::uint32_t shared_boxes_bodies = 0;
  /// A recorded step (its records given) first copies the state at its start here, n of
  /// each, the thread that integrates body i (block 0 with the shared boxes, from x_saved /
  /// v_saved, equal to x / v then): CudaWorld::record's x_pre and v_pre with no copy and
  /// wait on the host before the step. Null: not written.
  Vec3* x_pre = nullptr;
  Vec3* v_pre = nullptr;
  /// Run the kernel compiled without the midphase's early exit, tile culling and tile
  /// filter (their switches read as off: small_step.cu's kLean instantiation); the host sets it
  /// from the scene's meshes (small_lean_kernel). With the fused front the lean kernel runs
  /// the midphase a block per pair. States, pairs and contacts are the same either way; the
  /// midphase counts are then those of midphase_early_exit off (deterministic).
  int lean = 0;
};

/// The fused small step runs its lean kernel (SmallStepDesc::lean) when no shape of the
/// scene holds more than this many vertices per occupied cell of the midphase's deepest
/// level on average (small_lean_kernel). With leaves that small a pair's leaf work is short:
/// the early exit's and the tile culling's code cost more than they save, and a block per pair (the
/// fused front) finishes with the grid's other blocks. With larger leaves the pair with the most
/// leaf work holds a block-per-pair midphase back, and culling saves more than it costs. The
/// threshold lies between the bunny's 41 and the armadillo's 565 (both kernels forced on every
/// small scene: reports/h100/README.md, "Experiments and A/B results", "Small scenes: the kernel's
/// shape").
constexpr double kSmallLeanLeafVertices = 128.0;

/// Whether the fused small step runs its lean kernel for a scene whose largest mean number
/// of vertices per occupied leaf cell (over its mesh shapes, at the midphase's deepest
/// level) is `leaf_vertices` (0: no mesh, or an AABB-only midphase).
constexpr bool small_lean_kernel(double leaf_vertices) { return leaf_vertices <= kSmallLeanLeafVertices; }

/// The segments of each midphase list in the lean kernel, whose midphase runs a block per
/// pair (midphase.cuh, mid_block_pairs): block b uses segment b (list_capacity /
/// kBlockPairSegments items), so a grid of more blocks runs the grid's lists instead.
/// StepStats::counts[1 + i] is then the most items of list i any pair had times this.
constexpr std::uint32_t kBlockPairSegments = 256;

/// The most bodies of the fused front (SmallStepDesc::front_bodies): the block's shared
/// memory holds their counts (and, as for the shared boxes, their boxes and offsets).
constexpr std::uint32_t kSmallFrontMaxBodies = 64;

/// The most bodies of the shared boxes (SmallStepDesc::shared_boxes_bodies): the block's
/// shared memory holds their boxes and offsets.
constexpr std::uint32_t kSmallSharedBoxesMaxBodies = 1024;

/// The resident (persistent) small step (small_step.cu, launch_small_resident): one
/// cooperative launch that runs step after step. Block 0's thread 0 polls `request` in
/// mapped pinned host memory (system-scope acquire loads, __nanosleep backoff) and forwards
/// each step's command to the other blocks through `control` in device memory. A request is
/// (sequence << kResidentShift) | (ahead << kResidentAheadShift) | flags: run the steps
/// sequence .. sequence + ahead (ahead <= kResidentAheadMax) back to back, with no request
/// between them, while each step leaves every list within its capacity and every body
/// finite (a step that does not is the batch's last: the host reruns it or throws); flags:
/// kResidentRecord (every step of the batch is recorded: its first pass writes `records`;
/// with `ring` given each step then copies its record into the ring's slot
/// step - sequence, RecordRing), kResidentStamp (stamp the phases of the batch's last step into
/// SmallStepDesc::profile), kResidentExit (end the kernel, after the batch under way).
/// Each step runs the per-step kernel's code with its sequence, so it ends by writing its
/// statistics to its slot and its sequence to SmallStepDesc::done. The kernel also ends
/// by itself after idle_ns without a new request (so that nothing else on the device waits
/// on an idle resident kernel for long); on every exit it writes `epoch` to `exited`
/// (mapped), after its last step's `done`. The host tells the two apart: a request is
/// either run (done >= its sequence) or left (exited == epoch and done older).
/// The recorded steps of a resident batch (ResidentDesc::ring; CudaSettings::record_batch):
/// device arrays of `slots` slots. After a recorded step's response, block 0 copies into
/// slot k (the step's place in its batch, 0 for the request's first step) what
/// CudaWorld::record reads: the state at the step's start (x_pre, v_pre), the world AABBs,
/// the state after it (x_post, v_post: n each, at k * n), and the step's pairs, confirmed
/// flags and first-pass contact records, as many as the step found, right after the pairs
/// of the batch's earlier steps (a pool of pair_capacity pairs: the host finds a step's
/// place from the earlier steps' pair counts). A step whose pairs do not fit the pool's rest
/// copies none and ends its batch (the host reads that step's record from the live buffers). The host copies a batch's slots back in
/// one go (cuda_world.cpp, CudaWorld::Impl::fetch_records).
struct RecordRing {
  Vec3* x_pre = nullptr;
  Vec3* v_pre = nullptr;
  Vec3* x_post = nullptr;
  Vec3* v_post = nullptr;
  Aabb* aabb = nullptr;
  Pair* pairs = nullptr;
  std::uint8_t* confirmed = nullptr;
  DeviceContact* records = nullptr;
  std::uint32_t pair_capacity = 0;  ///< pairs the pool holds (all slots together)
  std::uint32_t slots = 0;          ///< 0: no ring (a recorded step is read from the live buffers)
};

struct ResidentDesc {
  unsigned long long* request = nullptr;  ///< mapped pinned host memory, written by the host
  unsigned long long* exited = nullptr;   ///< mapped pinned host memory, written at exit
  unsigned long long* control = nullptr;  ///< device, 2 words: [0] ticket, [1] command
  unsigned long long handled = 0;         ///< the request value taken as already run at launch
  unsigned long long epoch = 0;           ///< this launch's number, written to *exited
  unsigned long long idle_ns = 0;         ///< exit after this long without a request (0: never)
  DeviceContact* records = nullptr;       ///< the first pass's records of a recorded step
  RecordRing ring;                        ///< recorded batches' slots (slots 0: none)
  /// Mapped pinned host memory (may be null): the sequence of the last step that ended its
  /// batch early (a list over its capacity, a non-finite body, a ring slot too small),
  /// written before that step's SmallStepDesc::done.
  unsigned long long* stopped = nullptr;
  int stall = 0;  ///< test hook (CudaWorld::TestHooks::resident_ignores_requests): ignore step requests, honour exit
};
constexpr int kResidentShift = 9;
constexpr int kResidentAheadShift = 3;
/// The most steps a request asks for after its first (the stats slots hold one more).
constexpr unsigned long long kResidentAheadMax = 63;
constexpr std::uint32_t kResidentStatsSlots = kResidentAheadMax + 1;
constexpr unsigned long long kResidentRecord = 1;
constexpr unsigned long long kResidentExit = 2;
constexpr unsigned long long kResidentStamp = 4;

/// The fused small step's phases as stamped into SmallStepDesc::profile: slot 0 the kernel's
/// start, slot p the end of phase p (a phase the step skips: the previous stamp again).
constexpr int kSmallProfileSlots = 10;
/// The phase names of slots 1 .. kSmallProfileSlots - 1.
constexpr const char* kSmallProfilePhases[kSmallProfileSlots] = {
    "start",          "integrate+aabb", "count",     "scan",           "fill",
    "mid_start+in-k", "mid_expand",     "mid_leaf",  "response+clamp", "metrics+stats"};

/// The in_list value of a pair that did not fit the pair capacity.
constexpr std::uint32_t kNoPair = 0xffffffffu;

// ---- integrate.cu --------------------------------------------------------------------
/// Eq. 1-3 per body (octocd::integrate, no external force).
cudaError_t launch_integrate(const BodiesDesc& b, Vec3 gravity, float dt, cudaStream_t stream);
/// World AABBs: translated(local, x) per body.
cudaError_t launch_aabbs(const BodiesDesc& b, cudaStream_t stream);
/// Eq. 23 per dynamic body.
cudaError_t launch_clamp(const BodiesDesc& b, float v_max, cudaStream_t stream);

// ---- broadphase_flat.cu --------------------------------------------------------------
/// count[i] = number of j > i whose AABB overlaps body i's (Eq. 6); count[n] untouched.
cudaError_t launch_flat_count(const Aabb* aabb, std::uint32_t n, std::uint32_t* count, cudaStream_t stream);
/// Writes body i's pairs (i, j), j ascending, as keys (i << shift) | j at keys[offset[i]
/// ..] (only below `capacity`; n <= 2^shift): with offset the exclusive scan of count,
/// sorted by (a, b).
cudaError_t launch_flat_fill(const Aabb* aabb, std::uint32_t n, const std::uint32_t* offset,
                             unsigned long long* keys, std::uint32_t capacity, int shift, cudaStream_t stream);

// ---- broadphase_octree_tree.cu -------------------------------------------------------
// ---- midphase.cu -----------------------------------------------------------------------
/// Decide (the per-stage path when no pair can need a level step: no mesh shape or no
/// level): per live pair, one thread each, pairs[k] and confirmed[k], the answers start
/// gives. `grid` blocks of kBlockSize threads, grid-stride over the pairs.
cudaError_t launch_mid_decide(const MidListDesc& d, unsigned grid, cudaStream_t stream);
/// Witnesses (before start; nothing when the witness cache is off, d.wit.witness null): per
/// live pair (one thread each) pairs[k], and confirmed[k] = 1 when the pair is still within
/// theta at its last witness, else 0 (a static-static pair: 0, decided, witness[k] =
/// kStaticStatic). `grid` blocks of kBlockSize threads (grid-stride).
cudaError_t launch_mid_witness(const MidListDesc& d, unsigned grid, cudaStream_t stream);
/// Start: per live pair (one warp each; those launch_mid_witness confirmed or decided skipped)
/// confirmed[k] for decided pairs, the step 0 items of mesh pairs into d.out. `grid` blocks
/// of kBlockSize threads (grid-stride).
cudaError_t launch_mid_start(const MidListDesc& d, unsigned grid, cudaStream_t stream);
/// Expand: the items of step `step` (d.in) to those of step + 1 (d.out).
cudaError_t launch_mid_expand(const MidListDesc& d, int step, unsigned grid, cudaStream_t stream);
/// Leaf: the narrow phase of the last step's items (d.in); sets confirmed[k] = 1 on a hit.
cudaError_t launch_mid_leaf(const MidListDesc& d, unsigned grid, cudaStream_t stream);
/// Keep: this step's sorted keys and witnesses for the next step's start (d.wit; none
/// when the witness cache is off) and its leaf items for the next fuse decision
/// (d.leaf_items), after the leaves. `grid` blocks, grid-stride over the pairs.
cudaError_t launch_mid_keep(const MidListDesc& d, unsigned grid, cudaStream_t stream);

// ---- response.cu -----------------------------------------------------------------------
/// Entries of a body's b-side segment up to which apply_sums' first pass sorts it (insertion
/// sort by its thread); a longer segment is listed and sorted by index_long_kernel.
constexpr std::uint32_t kIndexShortSegment = 64;

/// What the contact index needs (response.cu): the candidate pairs (sorted by (a, b)) and
/// their flags, the bodies' inverse masses, and its buffers.
struct IndexDesc {
  const Pair* pairs = nullptr;
  const std::uint8_t* confirmed = nullptr;
  const std::uint32_t* pair_count = nullptr;  ///< device: pairs found
  std::uint32_t capacity = 0;                 ///< pairs the index covers (live = min with the count)
  std::uint32_t n = 0;
  const float* w = nullptr;
  unsigned long long* offsets = nullptr;  ///< n + 1: zeroed, then counts, then (scanned) offsets
  std::uint32_t* rank = nullptr;          ///< capacity: an entry's place in its segment (fill order)
  std::uint32_t* entries = nullptr;       ///< capacity: the b-side entries (ApplyDesc::entries)
  std::uint32_t* long_list = nullptr;     ///< capacity / (kIndexShortSegment + 1) + 1 bodies
  std::uint32_t* long_count = nullptr;    ///< device: bodies listed (zeroed by the step)
};

/// Counts: per live pair k, 1 << 32 to offsets[a]; per confirmed pair with a dynamic b,
/// 1 to offsets[b] (rank[k] = the count before); a body whose count passes
/// kIndexShortSegment is listed in long_list.
cudaError_t launch_index_count(const IndexDesc& d, unsigned grid, cudaStream_t stream);
/// Fill (after the exclusive scan of offsets): entries[lo(offsets[b]) + rank[k]] = k.
cudaError_t launch_index_fill(const IndexDesc& d, unsigned grid, cudaStream_t stream);
/// The listed long segments rewritten in k order (a block per body scans the live pairs).
cudaError_t launch_index_long(const IndexDesc& d, unsigned grid, cudaStream_t stream);
/// contact_terms per confirmed pair.
/// `grid` blocks of kBlockSize threads, grid-stride over the pairs.
cudaError_t launch_contact_terms(const TermsDesc& d, unsigned grid, cudaStream_t stream);
/// Per dynamic body: sums of its kept contacts' terms in (a, b) order from zero (its two
/// runs of d.offsets), then apply_contact_sums (and Eq. 23 when d.clamp).
cudaError_t launch_apply_sums(const ApplyDesc& d, cudaStream_t stream);

// ---- metrics.cu -------------------------------------------------------------------------
/// Kinetic energy, momentum, the first non-finite body, and the first pass's contact
/// statistics into *d.out: one block for n <= kMetricsOneBlockBodies, else
/// kMetricsBlocks blocks into d.partials and one block combining them; a fixed order for
/// a given n, so deterministic run to run.
cudaError_t launch_metrics(const MetricsDesc& d, cudaStream_t stream);

// ---- small_step.cu -------------------------------------------------------------------
/// Blocks of kBlockSize threads of the fused step kernel that fit on one multiprocessor at
/// once (cudaOccupancyMaxActiveBlocksPerMultiprocessor); 0 when it cannot run.
cudaError_t small_step_blocks_per_sm(int& blocks);
/// The whole step as one cooperative launch (cudaLaunchCooperativeKernel) of `grid` blocks
/// of kBlockSize threads; `grid` must not exceed small_step_blocks_per_sm x the SMs.
/// Requires s.bodies.n in [1, kMetricsOneBlockBodies].
cudaError_t launch_small_step(const SmallStepDesc& s, unsigned grid, cudaStream_t stream);
/// Blocks of the resident small step kernel that fit on one multiprocessor at once.
cudaError_t small_resident_blocks_per_sm(int& blocks);
/// The resident small step (ResidentDesc) as one cooperative launch of `grid` blocks; s's
/// sequence and terms.records are ignored (each request brings its own). It returns when
/// asked to (kResidentExit), or after r.idle_ns without a request.
cudaError_t launch_small_resident(const SmallStepDesc& s, const ResidentDesc& r, unsigned grid, cudaStream_t stream);

// ---- primitives.cu (CUB) ------------------------------------------------------------
/// Exclusive prefix sum of `count` uint32. With temp == nullptr only sets temp_bytes.
cudaError_t exclusive_scan_u32(void* temp, std::size_t& temp_bytes, const std::uint32_t* in, std::uint32_t* out,
                               std::uint32_t count, cudaStream_t stream);
/// Exclusive prefix sum of `count` uint64 (in == out: in place). With temp == nullptr only
/// sets temp_bytes.
cudaError_t exclusive_scan_u64(void* temp, std::size_t& temp_bytes, const unsigned long long* in,
                               unsigned long long* out, std::uint32_t count, cudaStream_t stream);
/// Radix sort of uint64 keys by bits [0, end_bit). With temp == nullptr only sets
/// temp_bytes.
cudaError_t sort_keys_u64(void* temp, std::size_t& temp_bytes, const unsigned long long* keys_in,
                          unsigned long long* keys_out, std::uint32_t count, int end_bit, cudaStream_t stream);
/// Minimum of `count` floats into *out. With temp == nullptr only sets temp_bytes.
cudaError_t min_f32(void* temp, std::size_t& temp_bytes, const float* in, float* out, std::uint32_t count,
                    cudaStream_t stream);

// ---- primitives.cu (CUB), for broadphase_octree_strict.cu ----------------------------
/// Sum of `count` doubles into *out (CUB's fixed reduction tree: the same bits run to run
/// on one device). With temp == nullptr only sets temp_bytes.
cudaError_t sum_f64(void* temp, std::size_t& temp_bytes, const double* in, double* out, std::uint32_t count,
                    cudaStream_t stream);
/// Sum of `count` uint32 into *out. With temp == nullptr only sets temp_bytes.
cudaError_t sum_u32(void* temp, std::size_t& temp_bytes, const std::uint32_t* in, std::uint32_t* out,
                    std::uint32_t count, cudaStream_t stream);

}  // namespace gpu
}  // namespace octocd
