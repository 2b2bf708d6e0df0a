#pragma once
/// \file device_footprint.hpp
/// What the CUDA engine allocates on the device before its first step, in plain C++ (no
/// CUDA toolkit needed): the byte sizes of the device-only structs, the initial capacities
/// of the variable-size buffers, the spatial hash's entry budget and bounds of CUB's
/// temporary storage. One source for the code that allocates (cuda_world.cpp and
/// broadphase_*.cu, which static_assert the sizes against their structs and take the
/// capacities from here) and the host estimate cuda_device_bytes_needed
/// (device_footprint.cpp), so the two cannot drift apart.

#include <cstdint>

#include "loose_blocks.hpp"
#include "octocd/loose_octree.hpp"

namespace octocd {
namespace gpu {
namespace footprint {

/// sizeof(gpu::DeviceShape) (kernels.hpp): one packed shape.
constexpr std::uint64_t kDeviceShapeBytes = 52;
/// sizeof(gpu::MidItem) (kernels.hpp): one midphase work-list item.
constexpr std::uint64_t kMidItemBytes = 16;
/// sizeof(gpu::DeviceContact) (kernels.hpp): one contact record.
constexpr std::uint64_t kDeviceContactBytes = 104;
/// gpu::kIndexShortSegment (kernels.hpp): the contact index lists one body per that many + 1 pairs.
constexpr std::uint64_t kIndexShortSegment = 64;
/// sizeof(gpu::StepStats) (kernels.hpp): what the host reads back after a step.
constexpr std::uint64_t kStepStatsBytes = 160;
/// sizeof(gpu::MetricsResult) (kernels.hpp); the engine holds kMetricsBlocks of them.
constexpr std::uint64_t kMetricsResultBytes = 72;
constexpr std::uint64_t kMetricsPartials = 512;
/// Entries of the loose octree's block table for n bodies: the smallest power of two >= 2 n
/// (at least 2; at most n blocks, so at most half full); each entry 8 bytes, a block key
/// and its first slot (loose_blocks.hpp, broadphase_octree_tree.cu).
constexpr std::uint64_t loose_cell_table_entries(std::uint64_t n) {
  std::uint64_t t = 2;
  while (t < 2 * (n > 0 ? n : 1)) t <<= 1;
  return t;
}
/// Bytes (blocks) of the loose octree's occupancy map for n bodies (loose_blocks.hpp: a
/// byte per block, blocks in key order): 32 per body, at least 2^16 (levels 0 .. 6), at
/// most the blocks of levels 0 .. kLooseMaxDepth, a multiple of 4 (stored as 32-bit
/// words). 32 n covers the levels the bench's boxes use at 10^4 .. 4x10^6 (at 10^6, D_w 9:
/// 19.2 x 10^6 blocks); a scene whose deepest levels need more has them probed without
/// the map.
constexpr std::uint64_t loose_occupancy_blocks(std::uint64_t n) {
  const std::uint64_t all = (gpu::loose_blocks_through(kLooseMaxDepth) + 3) / 4 * 4;
  std::uint64_t b = 32 * n;
  if (b < (1ull << 16)) b = 1ull << 16;
  if (b > all) b = all;
  return (b + 3) / 4 * 4;
}
/// Entries of the loose octree's level table: levels 0 .. kLooseMaxDepth, overflow, escape
/// levels 0 .. kLooseMaxDepth, NaN.
constexpr std::uint32_t kLooseLevelTable = 2 * kLooseMaxDepth + 4;
/// sizeof(LbvhNode) (lbvh.hpp): an internal node of `lbvh`.
constexpr std::uint64_t kLbvhNodeBytes = 12;
/// The spatial hash's entry budget per body (E = kHashEntriesPerBody x n slots).
constexpr std::uint32_t kHashEntriesPerBody = 8;

/// Candidate pairs the engine has room for before its first step, for n bodies; a step that
/// finds more grows the pair buffers and runs again.
constexpr std::uint64_t initial_pair_capacity(std::uint64_t n) { return 2 * n + 64; }
/// gpu::kSmallFrontBodies (cuda_impl.hpp): up to that many bodies the fused small step's
/// lean kernel runs its midphase a block per pair, in segments of the work lists.
constexpr std::uint64_t kSmallBlockPairBodies = 64;
/// gpu::kBlockPairSegments (kernels.hpp): the lean kernel's segments of each work list.
constexpr std::uint64_t kBlockPairSegments = 256;
/// Items per segment before the first step on the lean kernel's scenes (a pair's items of
/// one list).
constexpr std::uint64_t kBlockPairSegmentItems = 256;
/// Items per midphase work list before the first step, for n bodies (grown likewise): on
/// the scenes of a block per pair (n <= kSmallBlockPairBodies) kBlockPairSegmentItems a segment.
constexpr std::uint64_t initial_list_capacity(std::uint64_t n) {
  return n <= kSmallBlockPairBodies && 4 * n + 256 < kBlockPairSegments * kBlockPairSegmentItems
             ? kBlockPairSegments * kBlockPairSegmentItems
             : 4 * n + 256;
}

/// Fixed part of the CUB bounds below: onesweep's bins and counters (at most 16 portions
/// of 2^28 items x 8 passes x 256 digits x 4 bytes = 128 KiB below 2^32 items) and the
/// 256-byte alignment of each of its temporaries.
constexpr std::uint64_t kCubFixedBytes = 256 * 1024;

/// An upper bound of the temporary storage (bytes) of CUB's DeviceRadixSort::SortKeys /
/// SortPairs (not in place, as primitives.cu calls them) on `count` items of `key_bytes`
/// keys and `value_bytes` values (0 for keys only): the alternate key and value buffers
/// (count x (key + value)), onesweep's look-back (256 digits x 4 bytes per tile; tiles hold
/// well over 1024 items on sm_80 and later, so under 1 byte per item) and kCubFixedBytes.
constexpr std::uint64_t cub_sort_temp_bound(std::uint64_t count, std::uint64_t key_bytes, std::uint64_t value_bytes) {
  return count * (key_bytes + value_bytes + 1) + kCubFixedBytes;
}

/// An upper bound of the temporary storage (bytes) of CUB's DeviceScan::ExclusiveSum and
/// DeviceReduce::Sum / Min on `count` items: a tile descriptor per tile or a partial per
/// block (under 1 byte per item) and kCubFixedBytes.
constexpr std::uint64_t cub_scan_temp_bound(std::uint64_t count) { return count + kCubFixedBytes; }

}  // namespace footprint
}  // namespace gpu
}  // namespace octocd
