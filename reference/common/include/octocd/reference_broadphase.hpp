#pragma once
/// \file reference_broadphase.hpp
/// Reference broadphases from Bullet and FCL behind octocd's BroadPhase interface
/// (design.md section 5.1, "References"). They exist to compare octocd's own broadphases against
/// well-known libraries, in results (tests) and in cost (benchmarks).
///
/// Every reference returns exactly what `flat` returns: the pairs (a < b) whose world
/// AABBs overlap under the inclusive rule of Eq. 6 (octocd::overlaps), sorted ascending,
/// unique. The wrapped library only proposes candidates; each candidate then goes through
/// octocd::overlaps() as the exact test, and the result is sorted and de-duplicated. This
/// is exact as long as the library reports a superset of the overlapping pairs, which the
/// unit test (tests/reference/test_reference_broadphase.cpp) checks against `flat`.
///
/// Units: metres (AABBs as given; Bullet runs in float, FCL in double).
/// State: every reference but fcl-sap is incremental. The library's proxies / objects are created on
/// the first find_pairs call (one per body, body index as user data) and only updated
/// afterwards, so the body count must not change between calls on one instance (a
/// changed count throws octocd::InputError). Each instance owns its library objects;
/// nothing is shared between instances. Not thread-safe per instance.
///
/// This library (octocd_reference) sits beside octocd_core: core does not depend on it.
/// Front ends that want every name call make_any_broadphase(), which tries core first.

#include <memory>
#include <string>
#include <vector>

#include "octocd/broadphase.hpp"
#include "octocd/math.hpp"

namespace octocd {

/// Creates a reference broadphase by `config.name` (a row of octocd/broadphase_table.def
/// with host `bullet` or `fcl`):
/// - "bullet-dbvt": Bullet's btDbvtBroadphase (two dynamic AABB trees with fattened
///   leaves and a hashed pair cache), updated with setAabb + calculateOverlappingPairs.
/// - "bullet-sap": Bullet's bt32BitAxisSweep3 (incremental sweep and prune on quantised
///   32-bit endpoints) over `domain` grown 64 times about its centre.
/// - "fcl-dynamic-aabb-tree": fcl::DynamicAABBTreeCollisionManager<double>.
/// - "fcl-sap": fcl::SaPCollisionManager<double>.
/// - "fcl-interval-tree": fcl::IntervalTreeCollisionManager<double>.
/// - "fcl-spatial-hash": fcl::SpatialHashingCollisionManager<double>, cell size
///   `config.cell_size` (m), scene limits = `domain` (bodies outside it are kept by FCL
///   in its own out-of-limits list).
/// - "fcl-naive": fcl::NaiveCollisionManager<double> (all pairs, O(n^2)).
/// FCL objects are fcl::Box shapes of the AABB's size grown by 1e-7 m on every side,
/// translated to the AABB's centre: fcl-sap and fcl-interval-tree treat equal endpoints
/// as separated and would otherwise miss exactly touching pairs; the padding's extra
/// candidates are removed by the exact test. fcl-sap is rebuilt every call (FCL 0.7's
/// SaPCollisionManager::update() hangs on moved bodies); the others are updated.
/// Extra candidates that the exact test removes: bullet-dbvt (fattened leaves, from the
/// second call on), bullet-sap (quantisation, clamping), fcl-spatial-hash (cell sharing).
/// `domain` is the scene's domain box (m). Throws InputError naming `broadphase.name`
/// and the accepted names when the name is unknown, or `broadphase.cell_size` when it is
/// not finite and > 0. The caller owns the returned object.
std::unique_ptr<BroadPhase> make_reference_broadphase(const BroadPhaseConfig& config,
                                                      const Aabb& domain);

/// Names accepted by make_reference_broadphase, in the table's order (Bullet first).
std::vector<std::string> reference_broadphase_names();

/// The registry over core and references: make_broadphase() for core names (flat,
/// octree, spatial-hash), make_reference_broadphase() for the reference names. Throws
/// InputError naming `broadphase.name` and every accepted name when unknown. The caller
/// owns the returned object.
std::unique_ptr<BroadPhase> make_any_broadphase(const BroadPhaseConfig& config,
                                                const Aabb& domain);

/// The names of every row with a CPU implementation, in the table's order:
/// broadphase_names() followed by reference_broadphase_names().
std::vector<std::string> all_broadphase_names();

}  // namespace octocd
