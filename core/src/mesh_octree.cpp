/// \file mesh_octree.cpp
/// Per-mesh octree of the midphase (design.md section 5.2, paper Algorithm A1).

#include "octocd/mesh_octree.hpp"
#include "octocd/vertex_blocks.hpp"

#include <algorithm>
#include <cmath>
#include <numeric>
#include <string>

#include "octocd/error.hpp"

namespace octocd {
namespace {

constexpr int kMaxDepth = 10;       // 10 bits per axis, 30-bit Morton codes
constexpr int kAutoMaxDepth = 8;    // design.md section 5.2: `auto` goes at most 8 deep
constexpr std::uint32_t kAutoLeafLimit = 64;

Aabb tight_bounds(const std::vector<Vec3>& v) {
  Aabb b{v[0], v[0]};
  for (const Vec3& p : v) {
    b.min = {std::min(b.min.x, p.x), std::min(b.min.y, p.y), std::min(b.min.z, p.z)};
    b.max = {std::max(b.max.x, p.x), std::max(b.max.y, p.y), std::max(b.max.z, p.z)};
  }
  return b;
}

/// Cell coordinate of v along one axis at `depth` inside [lo, hi], clamped to the grid.
/// Computed in double; scaling by 2^depth is exact, so the depth-d coordinate equals the
/// depth-D coordinate shifted right by D - d (the Morton prefix property holds exactly).
std::uint32_t cell_coord(float v, float lo, float hi, int depth) {
  const std::uint32_t n = 1u << depth;
  const double extent = static_cast<double>(hi) - static_cast<double>(lo);
  if (!(extent > 0.0)) return 0;
  const double t = (static_cast<double>(v) - static_cast<double>(lo)) / extent;
  const double c = std::floor(t * static_cast<double>(n));
  if (!(c > 0.0)) return 0;
  if (c >= static_cast<double>(n - 1)) return n - 1;
  return static_cast<std::uint32_t>(c);
}

/// Morton code of the depth-`depth` cell holding v.
std::uint32_t vertex_code(const Vec3& v, const Aabb& b, int depth) {
  return morton3(cell_coord(v.x, b.min.x, b.max.x, depth), cell_coord(v.y, b.min.y, b.max.y, depth),
                 cell_coord(v.z, b.min.z, b.max.z, depth));
}

void check_mesh(const Mesh& mesh) {
  if (mesh.vertices.empty()) {
    throw InputError("mesh octree: mesh '" + mesh.name + "' has no vertices");
  }
  if (mesh.vertices.size() > 0xffffffffull) {
    throw InputError("mesh octree: mesh '" + mesh.name + "' has too many vertices");
  }
}

Aabb grow(const Aabb& b, const Aabb& c) {
  return {{std::min(b.min.x, c.min.x), std::min(b.min.y, c.min.y), std::min(b.min.z, c.min.z)},
          {std::max(b.max.x, c.max.x), std::max(b.max.y, c.max.y), std::max(b.max.z, c.max.z)}};
}

bool same_box(const Aabb& a, const Aabb& b) { return a.min == b.min && a.max == b.max; }

}  // namespace

int auto_mesh_octree_depth(const Mesh& mesh) {
  check_mesh(mesh);
  const Aabb b = tight_bounds(mesh.vertices);
  std::vector<std::uint32_t> codes(mesh.vertices.size());
  for (std::size_t i = 0; i < codes.size(); ++i) codes[i] = vertex_code(mesh.vertices[i], b, kAutoMaxDepth);
  std::sort(codes.begin(), codes.end());
  // The largest leaf only shrinks as the depth grows (children partition their parent):
  // pick the first depth whose largest occupied leaf holds <= 64 vertices.
  for (int d = 0; d <= kAutoMaxDepth; ++d) {
    const int shift = 3 * (kAutoMaxDepth - d);
    std::uint32_t largest = 0;
    for (std::size_t i = 0; i < codes.size();) {
      std::size_t j = i + 1;
      while (j < codes.size() && (codes[j] >> shift) == (codes[i] >> shift)) ++j;
      largest = std::max<std::uint32_t>(largest, static_cast<std::uint32_t>(j - i));
      i = j;
    }
    if (largest <= kAutoLeafLimit) return d;
  }
  return kAutoMaxDepth;
}

std::vector<Aabb> vertex_block_boxes(const std::vector<Vec3>& vertices) {
  std::vector<Aabb> boxes;
  boxes.reserve((vertices.size() + kVertexBlock - 1) / kVertexBlock);
  for (std::size_t i = 0; i < vertices.size(); i += kVertexBlock) {
    const std::size_t end = std::min<std::size_t>(i + kVertexBlock, vertices.size());
    Aabb box{vertices[i], vertices[i]};
    for (std::size_t j = i + 1; j < end; ++j) box = grow(box, Aabb{vertices[j], vertices[j]});
    boxes.push_back(box);
  }
  return boxes;
}

MeshOctree build_mesh_octree(const Mesh& mesh, int depth) {
  check_mesh(mesh);
  if (depth == -1) depth = auto_mesh_octree_depth(mesh);
  if (depth < 0 || depth > kMaxDepth) {
    throw InputError("mesh octree depth: " + std::to_string(depth) +
                     " is out of range; accepted: 0..10 or -1 (auto)");
  }
  MeshOctree t;
  t.depth = depth;
  t.bounds = tight_bounds(mesh.vertices);
  const std::size_t n = mesh.vertices.size();

  // Algorithm A1: vertices sorted by the Morton code of their depth-D cell. The sort key is
  // the code of the depth-kMaxDepth cell (whose top 3 D bits are the depth-D code: the
  // prefix property of cell_coord), stable on ties, so the vertices of a leaf cell follow
  // one another in Morton order too: a block of kVertexBlock consecutive vertices
  // (vertex_blocks.hpp) is then a compact patch whose box the leaves' filters can skip
  // (asian-dragon's mean block diagonal is 0.036 of the mesh's, 0.12 with a leaf cell's
  // vertices in the file's order: reports/h100/README.md, "Experiments and A/B results",
  // "Midphase"). A cell's vertex set, and so every answer of the midphase, is the same
  // either way.
  std::vector<std::uint32_t> fine(n);
  std::vector<std::uint32_t> code(n);
  const int shift = 3 * (kMaxDepth - depth);
  for (std::size_t i = 0; i < n; ++i) {
    fine[i] = vertex_code(mesh.vertices[i], t.bounds, kMaxDepth);
    code[i] = fine[i] >> shift;
  }
  t.original_index.resize(n);
  std::iota(t.original_index.begin(), t.original_index.end(), 0u);
  std::stable_sort(t.original_index.begin(), t.original_index.end(),
                   [&](std::uint32_t a, std::uint32_t b) { return fine[a] < fine[b]; });
  t.vertices.resize(n);
  for (std::size_t i = 0; i < n; ++i) t.vertices[i] = mesh.vertices[t.original_index[i]];

  // Level by level, bottom up; per-level arrays are concatenated top down at the end.
  std::vector<std::vector<MeshOctreeCell>> levels(static_cast<std::size_t>(depth) + 1);
  {
    auto& leaves = levels[static_cast<std::size_t>(depth)];
    for (std::size_t i = 0; i < n;) {
      const std::uint32_t c = code[t.original_index[i]];
      std::size_t j = i;
      Aabb box{t.vertices[i], t.vertices[i]};
      while (j < n && code[t.original_index[j]] == c) {
        box = grow(box, Aabb{t.vertices[j], t.vertices[j]});
        ++j;
      }
      leaves.push_back({box, static_cast<std::uint32_t>(i), static_cast<std::uint32_t>(j - i), 0u, 0u, c});
      i = j;
    }
  }
  for (int l = depth - 1; l >= 0; --l) {
    const auto& kids = levels[static_cast<std::size_t>(l) + 1];
    auto& cells = levels[static_cast<std::size_t>(l)];
    for (std::size_t i = 0; i < kids.size();) {
      const std::uint32_t m = kids[i].morton >> 3;
      MeshOctreeCell cell{kids[i].box, kids[i].first_vertex, 0u, static_cast<std::uint32_t>(i), 0u, m};
      std::size_t j = i;
      while (j < kids.size() && (kids[j].morton >> 3) == m) {
        cell.box = grow(cell.box, kids[j].box);
        cell.vertex_count += kids[j].vertex_count;
        ++j;
      }
      cell.child_count = static_cast<std::uint32_t>(j - i);
      cells.push_back(cell);
      i = j;
    }
  }
  t.level_offset.assign(static_cast<std::size_t>(depth) + 2, 0u);
  for (int l = 0; l <= depth; ++l) {
    t.level_offset[static_cast<std::size_t>(l) + 1] =
        t.level_offset[static_cast<std::size_t>(l)] + static_cast<std::uint32_t>(levels[static_cast<std::size_t>(l)].size());
  }
  t.cells.reserve(t.level_offset.back());
  for (int l = 0; l <= depth; ++l) {
    for (MeshOctreeCell c : levels[static_cast<std::size_t>(l)]) {
      if (l < depth) c.first_child += t.level_offset[static_cast<std::size_t>(l) + 1];
      t.cells.push_back(c);
    }
  }
  return t;
}

std::string MeshOctree::validate() const {
  auto fail = [&](const std::string& s) { return "mesh octree: " + s; };
  if (depth < 0 || depth > kMaxDepth) return fail("depth " + std::to_string(depth) + " outside [0, 10]");
  if (vertices.empty()) return fail("no vertices");
  if (original_index.size() != vertices.size()) return fail("original_index size differs from vertices");
  {
    std::vector<char> seen(vertices.size(), 0);
    for (std::uint32_t i : original_index) {
      if (i >= vertices.size() || seen[i]) return fail("original_index is not a permutation");
      seen[i] = 1;
    }
  }
  if (!same_box(bounds, tight_bounds(vertices))) return fail("bounds is not the tight AABB of the vertices");
  if (level_offset.size() != static_cast<std::size_t>(depth) + 2) return fail("level_offset size is not depth + 2");
  if (level_offset[0] != 0) return fail("level_offset[0] != 0");
  for (int l = 0; l <= depth; ++l) {
    if (level_end(l) <= level_begin(l)) return fail("level " + std::to_string(l) + " is empty");
  }
  if (level_end(0) - level_begin(0) != 1) return fail("level 0 does not hold exactly one cell");
  if (level_offset.back() != cells.size()) return fail("level_offset.back() != cells.size()");
  for (int l = 0; l <= depth; ++l) {
    const std::string at = "level " + std::to_string(l) + " cell ";
    std::uint32_t next_vertex = 0;
    std::uint32_t next_child = l < depth ? level_begin(l + 1) : 0;
    for (std::uint32_t c = level_begin(l); c < level_end(l); ++c) {
      const MeshOctreeCell& cell = cells[c];
      const std::string where = at + std::to_string(c);
      if (cell.morton >= (1u << (3 * l))) return fail(where + ": Morton code out of range");
      if (c > level_begin(l) && cells[c - 1].morton >= cell.morton) return fail(where + ": not in strict Morton order");
      if (cell.vertex_count == 0) return fail(where + ": no vertices");
      if (cell.first_vertex != next_vertex) return fail(where + ": vertex range not contiguous");
      if (static_cast<std::uint64_t>(cell.first_vertex) + cell.vertex_count > vertices.size()) {
        return fail(where + ": vertex range past the end");
      }
      next_vertex = cell.first_vertex + cell.vertex_count;
      Aabb box{vertices[cell.first_vertex], vertices[cell.first_vertex]};
      for (std::uint32_t v = cell.first_vertex; v < next_vertex; ++v) {
        box = grow(box, Aabb{vertices[v], vertices[v]});
        if (vertex_code(vertices[v], bounds, l) != cell.morton) return fail(where + ": holds a vertex of another cell");
      }
      if (!same_box(box, cell.box)) return fail(where + ": box is not the tight AABB of its vertices");
      if (l == depth) {
        if (cell.child_count != 0) return fail(where + ": deepest cell with children");
        continue;
      }
      if (cell.child_count < 1 || cell.child_count > 8) return fail(where + ": child_count outside 1..8");
      if (cell.first_child != next_child) return fail(where + ": children not contiguous");
      if (cell.first_child + cell.child_count > level_end(l + 1)) return fail(where + ": children past level end");
      next_child = cell.first_child + cell.child_count;
      std::uint32_t child_vertex = cell.first_vertex;
      for (std::uint32_t k = cell.first_child; k < next_child; ++k) {
        const MeshOctreeCell& kid = cells[k];
        if ((kid.morton >> 3) != cell.morton) return fail(where + ": child " + std::to_string(k) + " of another parent");
        if (kid.first_vertex != child_vertex) return fail(where + ": children do not tile its vertex range");
        child_vertex += kid.vertex_count;
        if (!contains(cell.box, kid.box)) return fail(where + ": child box outside the parent box");
      }
      if (child_vertex != next_vertex) return fail(where + ": children do not tile its vertex range");
    }
    if (next_vertex != vertices.size()) return fail(at + "ranges do not cover every vertex");
    if (l < depth && next_child != level_end(l + 1)) return fail(at + "children do not cover the next level");
  }
  return "";
}

}  // namespace octocd
