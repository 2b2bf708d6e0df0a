#pragma once
/// \file vertex_blocks.hpp
/// Boxes of blocks of consecutive mesh-octree vertices, so a scan for the vertices inside
/// a box can skip whole blocks (the CUDA midphase's leaf filter, issue 20).

#include <cstdint>
#include <vector>

#include "octocd/math.hpp"

namespace octocd {

/// Consecutive vertices per block of `vertex_block_boxes` (one warp's lanes).
constexpr std::uint32_t kVertexBlock = 32;

/// The tight AABB (local frame, m) of every block of kVertexBlock consecutive entries of
/// `vertices` (a MeshOctree's Morton-sorted vertices): box b holds vertices
/// [b * kVertexBlock, min((b + 1) * kVertexBlock, size)), ceil(size / kVertexBlock) boxes,
/// each the exact float min / max of its vertices (as the octree cells' boxes). A vertex
/// that is `hd::inside` a box X lies in a block whose box `overlaps` X, so a scan that skips
/// the blocks whose box misses X keeps exactly the vertices inside X, in their order.
/// Empty input gives no boxes. Defined in mesh_octree.cpp.
std::vector<Aabb> vertex_block_boxes(const std::vector<Vec3>& vertices);

}  // namespace octocd
