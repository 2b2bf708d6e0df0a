#pragma once
/// \file mesh_octree.hpp
/// The per-mesh octree of the midphase (paper Fig. 1, 4, A1, Algorithms A1-A2; design.md section 5.2).
///
/// Built once per shape in the mesh's local frame. Level 0 is the mesh's local AABB;
/// level l splits it into 2^l cells per axis, down to depth D_m. Vertices are sorted by
/// the Morton code of their depth-D_m cell (Algorithm A1), so every occupied cell at every
/// level owns a contiguous vertex range. Only occupied cells are stored, level by level;
/// each stores the tight AABB of its own vertices (not the cell bounds), its vertex range
/// and its children.

#include <cstdint>
#include <string>
#include <vector>

#include "octocd/math.hpp"
#include "octocd/mesh.hpp"

namespace octocd {

/// One occupied cell of a mesh octree.
struct MeshOctreeCell {
  Aabb box;                   ///< tight AABB of the cell's vertices (local frame, m)
  std::uint32_t first_vertex; ///< first index into MeshOctree::vertices
  std::uint32_t vertex_count; ///< number of vertices (> 0)
  std::uint32_t first_child;  ///< index into cells of the first occupied child (level+1)
  std::uint32_t child_count;  ///< occupied children, 0..8 (0 at the deepest level)
  std::uint32_t morton;       ///< Morton code of the cell at its own level
};

/// The per-mesh octree. Cells of level l are cells[level_offset[l] .. level_offset[l+1]).
/// Level 0 holds exactly one cell (the whole mesh).
struct MeshOctree {
  int depth = 0;                          ///< D_m, deepest level, in [0, 10]
  Aabb bounds;                            ///< local AABB of the mesh (level-0 cell bounds)
  /// The mesh's vertices sorted by the Morton code of their depth-10 cell, ties in input
  /// order: sorted by their depth-`depth` cell (Algorithm A1: a cell's vertices are a
  /// contiguous range) and, inside a leaf cell, in Morton order too (compact blocks of
  /// kVertexBlock vertices, vertex_blocks.hpp). The order is the same at every depth.
  std::vector<Vec3> vertices;
  std::vector<std::uint32_t> original_index;  ///< vertices[i] == mesh.vertices[original_index[i]]
  std::vector<MeshOctreeCell> cells;      ///< occupied cells, level by level, Morton order
  std::vector<std::uint32_t> level_offset;  ///< size depth + 2

  /// Cells of `level` as a [begin, end) index range into `cells`.
  std::uint32_t level_begin(int level) const { return level_offset[level]; }
  /// End of the cells of `level` in `cells`.
  std::uint32_t level_end(int level) const { return level_offset[level + 1]; }

  /// Checks every invariant (Morton order, contiguous ranges, children inside parents,
  /// tight boxes containing exactly their vertices, level offsets). Returns an empty
  /// string when valid, otherwise a description of the first violation.
  std::string validate() const;
};

/// Builds the octree of `mesh` down to `depth` in [0, 10]; `depth` = -1 picks `auto`
/// (design.md section 5.2, see `auto_mesh_octree_depth`).
/// Throws InputError when the mesh has no vertices or depth is out of range.
MeshOctree build_mesh_octree(const Mesh& mesh, int depth);

/// The depth `auto` picks for `mesh` (design.md section 5.2: "the deepest level whose occupied leaves
/// hold <= 64 vertices, at most 8"), read as: subdivide until every occupied leaf holds
/// <= 64 vertices, i.e. the smallest depth D in [0, 8] whose largest occupied depth-D cell
/// holds <= 64 vertices; 8 when even depth 8 has a larger cell (many coincident vertices).
/// Throws InputError when the mesh has no vertices.
int auto_mesh_octree_depth(const Mesh& mesh);

}  // namespace octocd
