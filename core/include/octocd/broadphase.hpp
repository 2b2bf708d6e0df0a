#pragma once
/// \file broadphase.hpp
/// The object-level broadphase (paper section 3.2, Algorithms 1-2, section 4.2; design.md section 5.1).
///
/// Every implementation returns the same set: all unordered pairs (a, b), a < b, whose
/// world AABBs overlap under the inclusive rule of Eq. 6, sorted and unique. They differ
/// only in cost. `flat` is the oracle that all others are tested against.
///
/// octocd's own broadphases (make_broadphase; Bullet's and FCL's are in
/// octocd/reference_broadphase.hpp; the names and promises of all of them are the rows of
/// octocd/broadphase_table.def, read through octocd/broadphase_registry.hpp):
/// - `flat`: all n(n-1)/2 pairs through Eq. 6 (broadphase.cpp).
/// - `octree` (default): the loose octree (design.md section 5.1; Ulrich 2000, looseness 2): each body
///   in the cell of its AABB centre at the deepest level whose cell side is >= its
///   largest side, queried against the <= 3x3x3 cells of its own and every coarser level
///   whose loose boxes (cells grown by half a side) meet it; bodies fitting no loose box
///   in an overflow list tested against every body (broadphase_octree_cache.cpp; cell math in
///   octocd/loose_octree.hpp, shared with the CUDA engine). Across calls on one instance
///   it keeps the pairs of the boxes grown by an eighth of the median body size and,
///   while every box stays inside its grown box, only re-tests those pairs; a few bodies
///   leaving theirs are re-queried alone (same answer, far less work for coherent
///   motion).
/// - `octree-strict`: the paper's octree read literally (design.md section 5.1, paper Algorithms 1-2):
///   each body in the deepest node fully containing it, pairs in nodes that are equal or
///   ancestor and descendant (broadphase_octree_strict.cpp).
/// - `spatial-hash`: uniform grid of cell size h (paper section 4.2), with coarser grids
///   (2h, 4h, ...) for bodies touching more than 64 cells (broadphase_spatial_hash.cpp).

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "octocd/broadphase_registry.hpp"
#include "octocd/math.hpp"

namespace octocd {

/// An unordered pair of body indices stored with a < b. Ordered by (a, b).
struct Pair {
  std::uint32_t a = 0;
  std::uint32_t b = 0;
};
/// Equality of both indices.
inline bool operator==(Pair p, Pair q) { return p.a == q.a && p.b == q.b; }
/// Lexicographic order on (a, b): the order contacts are processed in (design.md section 6).
inline bool operator<(Pair p, Pair q) { return p.a < q.a || (p.a == q.a && p.b < q.b); }

/// Per-call counts (design.md section 5.1: "report per frame").
struct BroadPhaseStats {
  /// Cell-level candidates: pairs considered before the exact AABB test (for `flat`,
  /// n(n-1)/2; for `octree`, the pairs of bodies in queried cells that reach the exact
  /// test, overflow pairs included, on the instance's first call; on later calls the
  /// kept pairs re-tested, plus the tests on grown boxes when the tree is rebuilt or
  /// bodies are re-queried (broadphase_octree_cache.cpp); for `octree-strict`, pairs in
  /// related nodes; for `spatial-hash`, pairs sharing a cell, before de-duplication).
  std::uint64_t cell_candidates = 0;
  /// Pairs returned (after the exact test and de-duplication).
  std::uint64_t pairs = 0;
  /// Bytes held by the broadphase's own structures after the call.
  std::uint64_t memory_bytes = 0;
};

/// Configuration of a broadphase, from the scene's "broadphase" object or
/// `--broadphase NAME`.
struct BroadPhaseConfig {
  /// A name of broadphase_infos() (flat | octree | octree-strict | spatial-hash; references
  /// add more); default `octree`.
  std::string name = broadphase_name(BroadPhaseId::octree);
  /// D_w for `octree` and `octree-strict`, in [0, 10]; -1 = `auto` (auto_loose_octree_depth
  /// for `octree`, auto_octree_depth for `octree-strict`, computed on every call).
  int octree_depth = 2;
  float cell_size = 0.25f;      ///< h (m) for `spatial-hash`, > 0 (paper section 4.2)
};

/// One broadphase. Implementations may keep state between calls (incremental ones such
/// as Bullet's dbvt create proxies on the first call and update them afterwards); the
/// body count must not change between calls on one instance.
class BroadPhase {
 public:
  virtual ~BroadPhase() = default;

  /// Name as accepted by `--broadphase` (e.g. "octree").
  virtual std::string name() const = 0;

  /// Finds all overlapping pairs among `boxes` (world AABBs, one per body, indexed by
  /// body). `out` is cleared and filled with pairs (a < b), sorted ascending, unique.
  /// Bodies outside the domain are handled (never lost). Not thread-safe per instance.
  virtual void find_pairs(const std::vector<Aabb>& boxes, std::vector<Pair>& out,
                          BroadPhaseStats& stats) = 0;
};

/// Creates a broadphase by `config.name`: a row of broadphase_infos() whose host is
/// BroadPhaseHost::core (flat, octree, octree-strict, spatial-hash). `domain` is the scene's domain box (m; the octrees' root is its
/// bounding cube: centred on it, side = its longest side). Throws InputError naming
/// `broadphase.name` and the accepted names when unknown, or the field
/// (`broadphase.depth`: -1 or [0, 10]; `broadphase.cell_size`: finite > 0) when a
/// parameter is out of range (checked for every name).
std::unique_ptr<BroadPhase> make_broadphase(const BroadPhaseConfig& config, const Aabb& domain);

/// Throws InputError naming the field when a parameter of `config` is out of range
/// (`broadphase.depth`: -1 or [0, 10]; `broadphase.cell_size`: finite > 0); the checks
/// make_broadphase and the device broadphases run whatever the name.
void check_broadphase_parameters(const BroadPhaseConfig& config);

/// Names accepted by make_broadphase (the rows with host BroadPhaseHost::core), in the
/// table's order: flat, octree, octree-strict, spatial-hash.
std::vector<std::string> broadphase_names();

/// Depth that `octree-strict` uses for `auto` (design.md section 5.1, "from body count and size"):
/// the deepest level whose cells (side = longest domain side / 2^level, m) are still at
/// least twice the mean body extent (mean over bodies of the longest AABB side; bodies
/// with a non-finite or negative side left out), in [1, 8]. `boxes` (world AABBs, m) may
/// be empty (gives 2).
int auto_octree_depth(const std::vector<Aabb>& boxes, const Aabb& domain);

/// Depth that `octree` (the loose octree) uses for `auto` (design.md section 5.1): the level whose
/// cell side is the smallest body extent, i.e. the deepest level l in [0, 10] with
/// S / 2^l >= the smallest largest-AABB-side over `boxes` (S = the longest domain side;
/// computed in the unit coordinates of octocd/loose_octree.hpp), so the smallest body
/// sits at level D_w. Boxes with a NaN coordinate are left out; empty `boxes`, or every
/// body larger than S, gives 0; zero-size bodies give 10.
int auto_loose_octree_depth(const std::vector<Aabb>& boxes, const Aabb& domain);

}  // namespace octocd
