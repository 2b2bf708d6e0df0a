#pragma once
/// \file midphase.hpp
/// Midphase (per-mesh octree levels; design.md section 5.2) and vertex-proximity narrow phase
/// (paper Eq. 7-8, Algorithm A2; design.md section 5.3).

#include <cstdint>
#include <string>
#include <vector>

#include "octocd/math.hpp"
#include "octocd/mesh_octree.hpp"

namespace octocd {

/// A midphase configuration: `aabb-only` (the paper's "Level 0 (AABB only)": AABB overlap
/// is the contact), or an ascending list of levels [l1, ..., lk], e.g. the paper's
/// A = [2], B = [1, 2], C = [0, 1, 2].
struct MidphaseConfig {
  bool aabb_only = false;
  std::vector<int> levels{1, 2};  ///< strictly ascending, each in [0, 10]

  /// Parses "aabb-only", "2", "1,2", "0,1,2", "[1, 2]", ... Throws InputError naming
  /// `field` and the accepted forms when malformed, unsorted, duplicated or out of range.
  static MidphaseConfig parse(const std::string& text, const std::string& field = "midphase");
  /// Canonical text: "aabb-only" or "1,2".
  std::string to_string() const;
  /// Deepest level used (0 for aabb-only).
  int max_level() const;
};

/// Counts from the midphase and narrow phase, summed over calls.
struct MidphaseStats {
  std::uint64_t box_tests = 0;     ///< cell-box overlap tests at all levels
  std::uint64_t box_pairs = 0;     ///< surviving deepest-level box pairs (or mesh-box boxes)
  std::uint64_t vertex_tests = 0;  ///< vertex-vertex or vertex-box distance tests
};

/// A shape placed in the world for the contact test: either a mesh (octree != nullptr)
/// or a solid box (octree == nullptr, `box` is its world AABB).
struct PlacedShape {
  const MeshOctree* octree = nullptr;  ///< not owned; nullptr for a box
  Vec3 position;                       ///< world position of the local frame origin (m)
  Aabb box;                            ///< world AABB (for meshes: translated bounds)
};

/// Confirms or rejects contact between two placed shapes (design.md section 5.3):
/// - mesh-mesh: some vertex of A and some vertex of B closer than theta (Eq. 7), found
///   through the level list of `config` with cell boxes expanded by theta/2;
/// - mesh-box: some vertex of the mesh within theta of (or inside) the box;
/// - box-box: AABB overlap.
/// `aabb_only` confirms every AABB-overlapping pair. theta > 0 in metres. For every level
/// list the result equals `exhaustive_contact` (no false negatives from pruning).
/// Precondition: config.max_level() <= the depth of each mesh octree (World builds the
/// octrees that deep); a level deeper than an octree is treated as its deepest level.
bool confirm_contact(const PlacedShape& a, const PlacedShape& b, float theta,
                     const MidphaseConfig& config, MidphaseStats& stats);

/// The oracle: tests every vertex pair (mesh-mesh), every vertex against the box
/// (mesh-box) or the AABBs (box-box), with no pruning.
bool exhaustive_contact(const PlacedShape& a, const PlacedShape& b, float theta);

}  // namespace octocd
