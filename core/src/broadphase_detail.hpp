#pragma once
// Private to the broadphase implementations (core/src/broadphase*.cpp).
#include <cstddef>
#include <cstdint>
#include <memory>
#include <vector>

#include "octocd/broadphase.hpp"

namespace octocd::detail {

/// The CPU factory of every row of octocd/broadphase_table.def with host `core`:
/// make_host_ID(config, domain), defined beside its broadphase (make_host_flat in
/// broadphase.cpp, make_host_octree in broadphase_octree_cache.cpp, make_host_octree_strict
/// in broadphase_octree_strict.cpp, make_host_spatial_hash in broadphase_spatial_hash.cpp).
/// `config`'s parameters are checked (make_broadphase) before it is called.
#define OCTOCD_HOST_FACTORY_core(ID) \
  std::unique_ptr<BroadPhase> make_host_##ID(const BroadPhaseConfig& config, const Aabb& domain);
#define OCTOCD_HOST_FACTORY_bullet(ID)
#define OCTOCD_HOST_FACTORY_fcl(ID)
#define OCTOCD_HOST_FACTORY_none(ID)
#define OCTOCD_BROADPHASE(ID, NAME, HOST, DEVICE, PAIRS, COST, SUMMARY) OCTOCD_HOST_FACTORY_##HOST(ID)
#include "octocd/broadphase_table.def"
#undef OCTOCD_BROADPHASE
#undef OCTOCD_HOST_FACTORY_core
#undef OCTOCD_HOST_FACTORY_bullet
#undef OCTOCD_HOST_FACTORY_fcl
#undef OCTOCD_HOST_FACTORY_none

/// Sorts `pairs` (each with a < b < n, no duplicates required) ascending by (a, b), O(n +
/// pairs). On one thread a two-pass counting sort (by b, then stably by a); on more, a
/// bucket pass by ranges of a on the worker team (octocd/parallel.hpp), then a counting
/// sort by a in each bucket with each a's run sorted by b. The same order either way.
/// `threads`: 0 picks loop_threads() of the pairs from 32,768 on (fewer: one thread); a
/// count > 1 takes the bucket path with that many threads' buckets. `tmp` and `count` are
/// scratch buffers kept by the caller so that nothing is allocated once they have grown.
void sort_pairs(std::vector<Pair>& pairs, std::size_t n, std::vector<Pair>& tmp,
                std::vector<std::uint32_t>& count, unsigned threads = 0);

}  // namespace octocd::detail
