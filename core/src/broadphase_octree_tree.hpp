#pragma once
/// \file broadphase_octree_tree.hpp
/// The tree of the `octree` broadphase (private to core/src): the loose octree of
/// design.md section 5.1 built over one call's boxes and queried for their overlapping pairs, steps 1-5
/// of broadphase_octree_cache.cpp's description (keys, order, tables, queries, sorted pairs),
/// implemented in broadphase_octree_tree.cpp. The pair cache across calls (steps 6-7) is
/// the BroadPhase of broadphase_octree_cache.cpp, which holds one tree (as Jolt's
/// BroadPhaseQuadTree holds its QuadTree). The cell and level math is
/// octocd/loose_octree.hpp's, shared with the CUDA engine.

#include <cstdint>
#include <memory>
#include <vector>

#include "octocd/broadphase.hpp"
#include "octocd/loose_octree.hpp"

namespace octocd::detail {

/// A box in the fixed-point unit coordinates of loose_q_min / loose_q_max (which lie in
/// [-2^11, 2^12], so 16 bits hold them).
struct QBox {
  std::int16_t lo[3];
  std::int16_t hi[3];
};

/// The fixed-point box of the unit-coordinate box [lo, hi] (loose_q_min / loose_q_max).
inline QBox qbox_of(const Vec3& lo, const Vec3& hi) {
  return {{static_cast<std::int16_t>(loose_q_min(lo.x)), static_cast<std::int16_t>(loose_q_min(lo.y)),
           static_cast<std::int16_t>(loose_q_min(lo.z))},
          {static_cast<std::int16_t>(loose_q_max(hi.x)), static_cast<std::int16_t>(loose_q_max(hi.y)),
           static_cast<std::int16_t>(loose_q_max(hi.z))}};
}

/// One slot of the sorted order: the body's world AABB, its index, and the end of its
/// cell's run of slots (32 bytes: one load gives all a test needs).
struct Slot {
  Aabb box;
  std::uint32_t body;
  std::uint32_t run_end;
};

/// Eq. 6 without short-circuit: one branch for the caller instead of up to six
/// unpredictable ones.
inline bool overlaps_nb(const Aabb& a, const Aabb& b) {
  return static_cast<bool>(static_cast<unsigned>(a.min.x <= b.max.x) &
                           static_cast<unsigned>(a.max.x >= b.min.x) &
                           static_cast<unsigned>(a.min.y <= b.max.y) &
                           static_cast<unsigned>(a.max.y >= b.min.y) &
                           static_cast<unsigned>(a.min.z <= b.max.z) &
                           static_cast<unsigned>(a.max.z >= b.min.z));
}

/// The loose octree over one call's boxes (steps 1-5). Keeps its buffers and the previous
/// call's order across calls; runs on the worker team (octocd/parallel.hpp) from 4096
/// bodies on; not thread-safe.
class LooseOctreeTree {
 public:
  /// depth: D_w, or -1 for `auto` (loose_auto_depth of the smallest body extent); domain:
  /// the world box the grid covers (m).
  LooseOctreeTree(int depth, const Aabb& domain);
  ~LooseOctreeTree();
  LooseOctreeTree(const LooseOctreeTree&) = delete;
  LooseOctreeTree& operator=(const LooseOctreeTree&) = delete;

  /// Steps 1-5 on `boxes`: out = the overlapping pairs (Eq. 6) sorted by (a, b), each
  /// once; returns the candidates (pairs that reached an exact AABB test). The tree stays
  /// built on `boxes` until the next call (cells_met, gather_all_levels and slots read it).
  std::uint64_t find_pairs(const std::vector<Aabb>& boxes, std::vector<Pair>& out);
  /// The fixed-point query box of the world box `box` (m) in this tree's grid.
  QBox query_box(const Aabb& box) const;
  /// How many cells of the occupied levels a query with q visits.
  std::uint64_t cells_met(const QBox& q) const;
  /// The slots of every occupied cell, at every occupied level, whose loose box meets
  /// the fixed-point box q (in scratch; returns their count).
  std::uint32_t gather_all_levels(const QBox& q, std::vector<std::uint32_t>& scratch) const;
  /// The sorted slots of the last find_pairs call (gather_all_levels indexes them).
  const Slot* slots() const;
  /// The overflow run (bodies too large for any level): slots [overflow_begin, overflow_end).
  std::uint32_t overflow_begin() const;
  std::uint32_t overflow_end() const;
  /// A scratch slot list for gather_all_levels (valid after the first find_pairs call).
  std::vector<std::uint32_t>& scratch();
  /// Bytes held by the tree's buffers (capacities).
  std::uint64_t memory_bytes() const;

 private:
  class Impl;  // broadphase_octree_tree.cpp
  std::unique_ptr<Impl> impl_;
};

}  // namespace octocd::detail
