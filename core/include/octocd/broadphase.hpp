#pragma once
/// \file broadphase.hpp
/// The object-level broadphase (paper section 3.2, Algorithms 1-2, section 4.2; SPEC 5.1).
///
/// Every implementation returns the same set: all unordered pairs (a, b), a < b, whose
/// world AABBs overlap under the inclusive rule of Eq. 6, sorted and unique. They differ
/// only in cost. `flat` is the oracle that all others are tested against.

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "octocd/math.hpp"

namespace octocd {

/// An unordered pair of body indices stored with a < b. Ordered by (a, b).
struct Pair {
  std::uint32_t a = 0;
  std::uint32_t b = 0;
};
/// Equality of both indices.
inline bool operator==(Pair p, Pair q) { return p.a == q.a && p.b == q.b; }
/// Lexicographic order on (a, b): the order contacts are processed in (SPEC 6).
inline bool operator<(Pair p, Pair q) { return p.a < q.a || (p.a == q.a && p.b < q.b); }

/// Per-call counts (SPEC 5.1: "report per frame").
struct BroadPhaseStats {
  /// Cell-level candidates: pairs considered before the exact AABB test (for `flat`,
  /// n(n-1)/2; for `octree`, pairs in related nodes; for `spatial-hash`, pairs sharing a
  /// cell, before de-duplication).
  std::uint64_t cell_candidates = 0;
  /// Pairs returned (after the exact test and de-duplication).
  std::uint64_t pairs = 0;
  /// Bytes held by the broadphase's own structures after the call.
  std::uint64_t memory_bytes = 0;
};

/// Configuration of a broadphase, from the scene's "broadphase" object or
/// `--broadphase NAME`.
struct BroadPhaseConfig {
  std::string name = "octree";  ///< flat | octree | spatial-hash (references add more)
  int octree_depth = 2;         ///< D_w for `octree`, in [0, 10]; -1 = `auto`
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

/// Creates a broadphase by `config.name`: "flat", "octree", "spatial-hash".
/// `domain` is the scene's domain box (the octree's root is its bounding cube).
/// Throws InputError naming `broadphase.name` and the accepted names when unknown, or
/// the field when a parameter is out of range.
std::unique_ptr<BroadPhase> make_broadphase(const BroadPhaseConfig& config, const Aabb& domain);

/// Names accepted by make_broadphase, in a stable order.
std::vector<std::string> broadphase_names();

/// Depth that `octree` uses for `auto` (SPEC 5.1): the deepest level whose cells are
/// still at least twice the mean body extent, in [1, 8]. `boxes` may be empty (gives 2).
int auto_octree_depth(const std::vector<Aabb>& boxes, const Aabb& domain);

}  // namespace octocd
