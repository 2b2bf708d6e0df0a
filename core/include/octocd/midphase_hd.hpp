#pragma once
/// \file midphase_hd.hpp
/// The per-pair midphase (per-mesh octree levels; design.md section 5.2) and vertex-proximity narrow
/// phase (paper Eq. 7-8, Algorithm A2; design.md section 5.3) as `OCTOCD_HD` functions: the one copy
/// both engines run. The CPU's confirm_contact / exhaustive_contact (midphase.cpp) runs the
/// depth-first descent below; the CUDA engine's level work lists (gpu/src/midphase.cu)
/// run the same set-up (setup_pair), the same cell boxes (moved_grown, moved_back_grown,
/// descendants) and the same vertex tests breadth first. Both confirm exactly the same
/// contacts with the same float32 expressions; their test counts differ (the CPU stops at
/// the first confirmed vertex pair).
///
/// Device-friendly: raw pointers instead of containers, no allocation, no exceptions, no
/// recursion (the level-list descent keeps an explicit stack of at most
/// `kMidphaseMaxLevels` frames).
///
/// Exactness: the pruned path (`confirm_contact`) and the oracle (`exhaustive_contact`) run
/// literally the same vertex tests (`vertex_close`, `vertex_box_close`) on the same float
/// world positions (`world_vertex`). Pruning only skips pairs that cannot pass them: cell
/// boxes are tested with the full margin theta (each box grown by theta/2) plus a small
/// tolerance (`midphase_tolerance`, 1e-5 relative to every magnitude involved) that covers
/// the float rounding of the translations and of the distance, so pruning is
/// conservative, never lossy.

#include <cstdint>

#include "octocd/math.hpp"
#include "octocd/mesh_octree.hpp"

namespace octocd {
namespace hd {

/// Levels are strictly ascending in [0, 10], so a level list has at most 11 entries.
constexpr int kMidphaseMaxLevels = 11;

/// A mesh octree seen through raw pointers (host vectors or packed device arrays).
/// Cell indices (first_child) and vertex indices (first_vertex) are relative to
/// `cells` and `vertices`.
struct OctreeView {
  int depth = 0;                                ///< D_m, deepest level
  Aabb bounds;                                  ///< local AABB of the mesh (m)
  const Vec3* vertices = nullptr;               ///< Morton-sorted local vertices (m)
  std::uint32_t vertex_count = 0;               ///< entries of `vertices`
  const MeshOctreeCell* cells = nullptr;        ///< occupied cells, level by level
  const std::uint32_t* level_offset = nullptr;  ///< depth + 2 entries

  /// First cell of `level`.
  OCTOCD_HD std::uint32_t level_begin(int level) const { return level_offset[level]; }
  /// One past the last cell of `level`.
  OCTOCD_HD std::uint32_t level_end(int level) const { return level_offset[level + 1]; }
};

/// A shape placed in the world: a mesh (`is_mesh`, `octree` valid) or a solid box
/// (`box` is its world AABB).
struct PlacedView {
  bool is_mesh = false;  ///< true: mesh with `octree`; false: box
  OctreeView octree;     ///< valid when is_mesh
  Vec3 position;         ///< world position of the local frame origin (m)
  Aabb box;              ///< world AABB (for meshes: translated bounds) (m)
};

/// A midphase configuration without containers: `aabb_only`, or `count` strictly
/// ascending levels.
struct LevelList {
  bool aabb_only = false;
  int count = 0;
  int levels[kMidphaseMaxLevels] = {};
};

/// Box and vertex test counts of one contact test (summed by the caller).
struct MidphaseCounters {
  std::uint64_t box_tests = 0;     ///< cell-box overlap tests at all levels
  std::uint64_t box_pairs = 0;     ///< surviving deepest-level box pairs (or mesh-box boxes)
  std::uint64_t vertex_tests = 0;  ///< vertex-vertex or vertex-box distance tests
};

// ---- the narrow-phase tests, shared by the pruned path and the oracle ------------------

/// Paper Eq. 7: world vertices wa and wb closer than theta (theta2 = theta * theta).
OCTOCD_HD inline bool vertex_close(Vec3 wa, Vec3 wb, float theta2) {
  const float dx = wa.x - wb.x;
  const float dy = wa.y - wb.y;
  const float dz = wa.z - wb.z;
  return dx * dx + dy * dy + dz * dz < theta2;
}

/// design.md section 5.3 mesh-box: world vertex wa within theta of (or inside) the world box.
OCTOCD_HD inline bool vertex_box_close(Vec3 wa, const Aabb& box, float theta2) {
  return distance2_point_aabb(wa, box) < theta2;
}

/// World position of a local vertex (the one expression every path uses).
OCTOCD_HD inline Vec3 world_vertex(Vec3 v, Vec3 position) {
  return {v.x + position.x, v.y + position.y, v.z + position.z};
}

// ---- helpers ---------------------------------------------------------------------------

/// max(a, b) as std::max writes it ((a < b) ? b : a), on host and device alike.
OCTOCD_HD inline float max_of(float a, float b) { return (a < b) ? b : a; }
/// Largest absolute component.
OCTOCD_HD inline float max_abs(Vec3 v) { return max_of(max_of(fabsf(v.x), fabsf(v.y)), fabsf(v.z)); }
/// Largest absolute coordinate of a box.
OCTOCD_HD inline float max_abs(const Aabb& b) { return max_of(max_abs(b.min), max_abs(b.max)); }

/// Inclusive overlap of a and b with a total margin m (each box grown by m/2).
OCTOCD_HD inline bool overlaps_margin(const Aabb& a, const Aabb& b, float m) {
  return a.min.x - m <= b.max.x && a.max.x + m >= b.min.x &&  //
         a.min.y - m <= b.max.y && a.max.y + m >= b.min.y &&  //
         a.min.z - m <= b.max.z && a.max.z + m >= b.min.z;
}

/// Point p inside box b (inclusive).
OCTOCD_HD inline bool inside(Vec3 p, const Aabb& b) {
  return p.x >= b.min.x && p.x <= b.max.x && p.y >= b.min.y && p.y <= b.max.y && p.z >= b.min.z &&
         p.z <= b.max.z;
}

/// A's cell box `c` moved into B's frame by d = pa - pb and grown by `m` on every side
/// (the box every level test and the narrow-phase filter of B's vertices use).
OCTOCD_HD inline Aabb moved_grown(const Aabb& c, Vec3 d, float m) {
  return Aabb{{c.min.x + d.x - m, c.min.y + d.y - m, c.min.z + d.z - m},
              {c.max.x + d.x + m, c.max.y + d.y + m, c.max.z + d.z + m}};
}

/// B's cell box `c` moved into A's frame (by -d, d = pa - pb) and grown by `m` (the
/// narrow-phase filter of A's vertices).
OCTOCD_HD inline Aabb moved_back_grown(const Aabb& c, Vec3 d, float m) {
  return Aabb{{c.min.x - d.x - m, c.min.y - d.y - m, c.min.z - d.z - m},
              {c.max.x - d.x + m, c.max.y - d.y + m, c.max.z - d.z + m}};
}

/// The cells at level `to` descending from cell c of level `from` (<= to): a contiguous
/// range [begin, end) of `cells` (children are stored contiguously in Morton order).
OCTOCD_HD inline void descendants(const OctreeView& t, std::uint32_t c, int from, int to,
                                  std::uint32_t& begin, std::uint32_t& end) {
  std::uint32_t lo = c;
  std::uint32_t hi = c;
  for (int l = from; l < to; ++l) {
    lo = t.cells[lo].first_child;
    const MeshOctreeCell& h = t.cells[hi];
    hi = h.first_child + h.child_count - 1;
  }
  begin = lo;
  end = hi + 1;
}

/// Entry i (< the list's count) of a level list clamped to an octree's depth (a level
/// deeper than the octree is its deepest).
OCTOCD_HD inline int clamped_level(const LevelList& cfg, int i, int depth) {
  return cfg.levels[i] < depth ? cfg.levels[i] : depth;
}

/// Level list clamped to an octree's depth (clamped_level of every entry). Returns the
/// number of levels written to `out`.
OCTOCD_HD inline int clamp_levels(const LevelList& cfg, int depth, int* out) {
  const int k = cfg.count < kMidphaseMaxLevels ? cfg.count : kMidphaseMaxLevels;
  for (int i = 0; i < k; ++i) out[i] = clamped_level(cfg, i, depth);
  return k;
}

/// Rounding tolerance added to the margin theta (see the file comment).
OCTOCD_HD inline float midphase_tolerance(float theta, float magnitudes) {
  return 1e-5f * (theta + magnitudes);
}

// ---- the oracle --------------------------------------------------------------------------

/// exhaustive_contact once the order is fixed: mesh `a` against `b` (a mesh or a box).
OCTOCD_HD inline bool exhaustive_ordered(const PlacedView& a, const PlacedView& b, float theta) {
  const float theta2 = theta * theta;
  const Vec3* va = a.octree.vertices;
  const std::uint32_t na = a.octree.vertex_count;
  if (!b.is_mesh) {
    for (std::uint32_t i = 0; i < na; ++i) {
      if (vertex_box_close(world_vertex(va[i], a.position), b.box, theta2)) return true;
    }
    return false;
  }
  const Vec3* vb = b.octree.vertices;
  const std::uint32_t nb = b.octree.vertex_count;
  for (std::uint32_t i = 0; i < na; ++i) {
    const Vec3 wa = world_vertex(va[i], a.position);
    for (std::uint32_t j = 0; j < nb; ++j) {
      if (vertex_close(wa, world_vertex(vb[j], b.position), theta2)) return true;
    }
  }
  return false;
}

/// Tests every vertex pair (mesh-mesh), every vertex against the box (mesh-box) or the
/// AABBs (box-box), with no pruning. (The mesh goes first through exhaustive_ordered,
/// called with each order rather than with a reference chosen at run time: see
/// setup_ordered.)
OCTOCD_HD inline bool exhaustive_contact(const PlacedView& a_in, const PlacedView& b_in, float theta) {
  if (!a_in.is_mesh && !b_in.is_mesh) return overlaps(a_in.box, b_in.box);
  return a_in.is_mesh ? exhaustive_ordered(a_in, b_in, theta) : exhaustive_ordered(b_in, a_in, theta);
}

// ---- mesh-mesh -----------------------------------------------------------------------------

/// Narrow phase on one surviving deepest box pair: cell ca of A against cell cb of B.
/// `a_in_b` is A's cell box in B's local frame grown by `margin`; `d` = pa - pb.
/// Only B's vertices inside `a_in_b` and A's vertices inside B's cell box in A's frame
/// (grown by `margin`) can be closer than theta (conservative filters). For every such
/// vertex of A, in order, all such vertices of B are tested, in order; `vertex_tests`
/// counts them. `scratch` (may be null) holds at least `scratch_capacity` Vec3: when B's
/// cell fits, B's filtered world vertices are computed once into it; otherwise they are
/// recomputed per vertex of A. Both give the same tests on the same floats.
OCTOCD_HD inline bool mesh_mesh_leaf(const OctreeView& A, const OctreeView& B, Vec3 pa, Vec3 pb, Vec3 d,
                                     float margin, float theta2, const MeshOctreeCell& ca,
                                     const MeshOctreeCell& cb, const Aabb& a_in_b, Vec3* scratch,
                                     std::uint32_t scratch_capacity, MidphaseCounters& n) {
  const Vec3* vb = B.vertices + cb.first_vertex;
  const bool cached = scratch != nullptr && cb.vertex_count <= scratch_capacity;
  std::uint32_t nb = 0;
  for (std::uint32_t j = 0; j < cb.vertex_count; ++j) {
    if (inside(vb[j], a_in_b)) {
      if (cached) scratch[nb] = world_vertex(vb[j], pb);
      ++nb;
    }
  }
  if (nb == 0) return false;
  const Aabb b_in_a = moved_back_grown(cb.box, d, margin);
  const Vec3* va = A.vertices + ca.first_vertex;
  for (std::uint32_t i = 0; i < ca.vertex_count; ++i) {
    if (!inside(va[i], b_in_a)) continue;
    const Vec3 wa = world_vertex(va[i], pa);
    n.vertex_tests += nb;
    if (cached) {
      for (std::uint32_t j = 0; j < nb; ++j) {
        if (vertex_close(wa, scratch[j], theta2)) return true;
      }
    } else {
      for (std::uint32_t j = 0; j < cb.vertex_count; ++j) {
        if (inside(vb[j], a_in_b) && vertex_close(wa, world_vertex(vb[j], pb), theta2)) return true;
      }
    }
  }
  return false;
}

/// Level-list descent for mesh A against mesh B (design.md section 5.2): at level step i, every cell
/// of A's range against every cell of B's range at levels la[i], lb[i] (A's cell box moved
/// into B's frame and grown by the whole margin); an overlapping pair descends to both
/// cells' descendants at step i + 1; at the last step (k - 1) it goes to the narrow phase.
/// Depth-first in (cell of A, cell of B) order, stopping at the first confirmed vertex
/// pair; an explicit stack of k <= kMidphaseMaxLevels frames replaces recursion.
OCTOCD_HD inline bool mesh_mesh_descend(const OctreeView& A, const OctreeView& B, Vec3 pa, Vec3 pb, Vec3 d,
                                        float margin, float theta2, const int* la, const int* lb, int k,
                                        Vec3* scratch, std::uint32_t scratch_capacity, MidphaseCounters& n) {
  struct Frame {
    std::uint32_t a, a_end;    // cells of A at this step; `a` is the current one
    std::uint32_t b, b_begin, b_end;  // cells of B; `b` is the next one to test against `a`
    Aabb e;                    // cell a's box in B's frame, grown by the margin
  };
  Frame st[kMidphaseMaxLevels];
  // Starts cell f.a: its grown box, and the box tests against all of B's range.
  auto begin_cell = [&](Frame& f) {
    const MeshOctreeCell& ca = A.cells[f.a];
    f.e = moved_grown(ca.box, d, margin);
    f.b = f.b_begin;
    n.box_tests += f.b_end - f.b_begin;
  };
  auto enter = [&](Frame& f, std::uint32_t a0, std::uint32_t a1, std::uint32_t b0, std::uint32_t b1) {
    f.a = a0;
    f.a_end = a1;
    f.b_begin = b0;
    f.b_end = b1;
    f.b = b1;
    if (a0 < a1) begin_cell(f);
  };
  int i = 0;
  enter(st[0], A.level_begin(la[0]), A.level_end(la[0]), B.level_begin(lb[0]), B.level_end(lb[0]));
  while (true) {
    Frame& f = st[i];
    if (f.a >= f.a_end) {  // this step's cells are done: back to the parent step
      if (i == 0) return false;
      --i;
      continue;
    }
    if (f.b >= f.b_end) {  // cell a is done against all of B's range: next cell of A
      ++f.a;
      if (f.a < f.a_end) begin_cell(f);
      continue;
    }
    const std::uint32_t b = f.b++;
    const Aabb& bb = B.cells[b].box;
    const Aabb& e = f.e;
    if (!overlaps(e, bb)) continue;
    if (i + 1 == k) {
      ++n.box_pairs;
      if (mesh_mesh_leaf(A, B, pa, pb, d, margin, theta2, A.cells[f.a], B.cells[b], e, scratch,
                         scratch_capacity, n)) {
        return true;
      }
      continue;
    }
    std::uint32_t na0, na1, nb0, nb1;
    descendants(A, f.a, la[i], la[i + 1], na0, na1);
    descendants(B, b, lb[i], lb[i + 1], nb0, nb1);
    ++i;
    enter(st[i], na0, na1, nb0, nb1);
  }
}

// ---- mesh-box ------------------------------------------------------------------------------

/// Level-list descent for mesh A against a static box (design.md sections 5.2-5.3): A's cells of each
/// step are tested against the box in A's frame grown by theta + tol (`box_local`); the
/// surviving deepest cells test their vertices against the world box. Depth-first in
/// cell order with an explicit stack, stopping at the first vertex within theta.
OCTOCD_HD inline bool mesh_box_descend(const OctreeView& A, Vec3 pa, const Aabb& box, const Aabb& box_local,
                                       float theta2, const int* la, int k, MidphaseCounters& n) {
  struct Frame {
    std::uint32_t a, a_end;
  };
  Frame st[kMidphaseMaxLevels];
  int i = 0;
  st[0].a = A.level_begin(la[0]);
  st[0].a_end = A.level_end(la[0]);
  n.box_tests += st[0].a_end - st[0].a;
  while (true) {
    Frame& f = st[i];
    if (f.a >= f.a_end) {
      if (i == 0) return false;
      --i;
      continue;
    }
    const std::uint32_t a = f.a++;
    const MeshOctreeCell& ca = A.cells[a];
    if (!overlaps(ca.box, box_local)) continue;
    if (i + 1 == k) {
      ++n.box_pairs;
      const Vec3* va = A.vertices + ca.first_vertex;
      n.vertex_tests += ca.vertex_count;
      for (std::uint32_t j = 0; j < ca.vertex_count; ++j) {
        if (vertex_box_close(world_vertex(va[j], pa), box, theta2)) return true;
      }
      continue;
    }
    std::uint32_t na0, na1;
    descendants(A, a, la[i], la[i + 1], na0, na1);
    ++i;
    st[i].a = na0;
    st[i].a_end = na1;
    n.box_tests += na1 - na0;
  }
}

// ---- the contact test ------------------------------------------------------------------------

/// What a contact test needs before any descent.
enum class PairKind : int {
  Decided = 0,     ///< `result` is the answer (aabb-only, box-box, early rejection)
  MeshBox = 1,     ///< mesh A (after `swap`) against box B: mesh_box_descend
  MeshMesh = 2,    ///< mesh A against mesh B: mesh_mesh_descend
  Exhaustive = 3,  ///< no levels to prune with: exhaustive_contact
};

/// The set-up of one contact test (design.md section 5.3), shared by confirm_contact and the CUDA
/// engine's level work lists: which test, the order (`swap`: the given pair is (box,
/// mesh), so A = the second shape), and the frame of the descent.
struct PairSetup {
  PairKind kind = PairKind::Decided;
  bool result = false;  ///< the answer when kind == Decided
  bool swap = false;    ///< A = b_in, B = a_in
  float theta2 = 0.0f;  ///< theta^2 (m^2)
  Vec3 d;               ///< mesh-mesh: pa - pb (m)
  float margin = 0.0f;  ///< mesh-mesh: theta + tolerance (m)
  Aabb box_local;       ///< mesh-box: the box in A's frame grown by theta + tolerance (m)
  int k = 0;            ///< number of level steps
  int la[kMidphaseMaxLevels] = {};  ///< A's levels per step (clamped to its depth)
  int lb[kMidphaseMaxLevels] = {};  ///< B's levels per step (mesh-mesh)
};

/// setup_pair's work once the order is fixed: mesh `a` (A) against `b` (B: a mesh or a
/// box); fills every field of `s` but `swap` (its own function, called with the two
/// orders, so no reference to one of two PlacedViews is chosen at run time: on the device
/// such a choice puts both views in local memory).
OCTOCD_HD inline void setup_ordered(PairSetup& s, const PlacedView& a, const PlacedView& b, float theta,
                                    const LevelList& config) {
  s.theta2 = theta * theta;
  const OctreeView& A = a.octree;
  if (!b.is_mesh) {
    const float tol = midphase_tolerance(theta, max_abs(a.position) + max_abs(A.bounds) + max_abs(b.box));
    const Vec3 lo = b.box.min - a.position;
    const Vec3 hi = b.box.max - a.position;
    s.box_local = expanded(Aabb{lo, hi}, theta + tol);
    // Early rejection: the mesh's bounds against the box, with the margin.
    if (!overlaps(A.bounds, s.box_local)) return;
    s.k = clamp_levels(config, A.depth, s.la);
    s.kind = s.k == 0 ? PairKind::Exhaustive : PairKind::MeshBox;  // no levels: nothing to prune
    return;
  }
  const OctreeView& B = b.octree;
  s.d = a.position - b.position;
  const float tol = midphase_tolerance(
      theta, max_abs(a.position) + max_abs(b.position) + max_abs(A.bounds) + max_abs(B.bounds));
  s.margin = theta + tol;
  // Early rejection (design.md section 5.3): the two bounds, each grown by theta/2, must overlap.
  const Aabb e{A.bounds.min + s.d, A.bounds.max + s.d};
  if (!overlaps_margin(e, B.bounds, s.margin)) return;
  s.k = clamp_levels(config, A.depth, s.la);
  clamp_levels(config, B.depth, s.lb);
  s.kind = s.k == 0 ? PairKind::Exhaustive : PairKind::MeshMesh;
}

/// Classifies a contact test and computes its frame (see PairSetup): aabb-only and
/// box-box are decided by the AABB overlap; a mesh pair whose bounds (grown by the
/// margin) miss is rejected early.
OCTOCD_HD inline PairSetup setup_pair(const PlacedView& a_in, const PlacedView& b_in, float theta,
                                      const LevelList& config) {
  PairSetup s;
  if (config.aabb_only || (!a_in.is_mesh && !b_in.is_mesh)) {
    s.result = overlaps(a_in.box, b_in.box);
    return s;
  }
  s.swap = !a_in.is_mesh;  // (box, mesh) -> (mesh, box)
  if (s.swap) setup_ordered(s, b_in, a_in, theta, config);
  else setup_ordered(s, a_in, b_in, theta, config);
  return s;
}

/// Confirms or rejects contact between two placed shapes (design.md section 5.3):
/// - mesh-mesh: some vertex of A and some vertex of B closer than theta (Eq. 7), found
///   through the level list `config` with cell boxes expanded by theta/2;
/// - mesh-box: some vertex of the mesh within theta of (or inside) the box;
/// - box-box: AABB overlap.
/// `config.aabb_only` confirms every AABB-overlapping pair. theta > 0 in metres. The result
/// equals `exhaustive_contact` for every level list. Counts are added to `stats` (nothing
/// is added on early rejection and for the no-level fallback, as on the CPU since the
/// beginning). `scratch` / `scratch_capacity`: see mesh_mesh_leaf (null is fine).
OCTOCD_HD inline bool confirm_contact(const PlacedView& a_in, const PlacedView& b_in, float theta,
                                      const LevelList& config, MidphaseCounters& stats,
                                      Vec3* scratch = nullptr, std::uint32_t scratch_capacity = 0) {
  const PairSetup s = setup_pair(a_in, b_in, theta, config);
  if (s.kind == PairKind::Decided) return s.result;
  const PlacedView& a = s.swap ? b_in : a_in;
  const PlacedView& b = s.swap ? a_in : b_in;
  if (s.kind == PairKind::Exhaustive) return exhaustive_contact(a, b, theta);
  MidphaseCounters n;
  const bool hit = s.kind == PairKind::MeshBox
                       ? mesh_box_descend(a.octree, a.position, b.box, s.box_local, s.theta2, s.la, s.k, n)
                       : mesh_mesh_descend(a.octree, b.octree, a.position, b.position, s.d, s.margin, s.theta2,
                                           s.la, s.lb, s.k, scratch, scratch_capacity, n);
  stats.box_tests += n.box_tests;
  stats.box_pairs += n.box_pairs;
  stats.vertex_tests += n.vertex_tests;
  return hit;
}

}  // namespace hd
}  // namespace octocd
