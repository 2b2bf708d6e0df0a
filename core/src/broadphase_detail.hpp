#pragma once
// Private to the broadphase implementations (core/src/broadphase*.cpp).
#include <cstddef>
#include <cstdint>
#include <memory>
#include <vector>

#include "octocd/broadphase.hpp"

namespace octocd::detail {

/// `octree`, the loose octree broadphase (broadphase_octree_cache.cpp); depth -1 = auto.
std::unique_ptr<BroadPhase> make_octree_broadphase(int depth, const Aabb& domain);
/// `octree-strict`, the paper's octree read literally (broadphase_octree_strict.cpp);
/// depth -1 = auto.
std::unique_ptr<BroadPhase> make_strict_octree_broadphase(int depth, const Aabb& domain);
/// The uniform-grid spatial hash (broadphase_spatial_hash.cpp); cell size in m.
std::unique_ptr<BroadPhase> make_spatial_hash_broadphase(float cell_size);

/// Sorts `pairs` (each with a < b < n, no duplicates required) ascending by (a, b) with a
/// two-pass stable counting sort (O(n + pairs)); `tmp` and `count` are scratch buffers
/// kept by the caller so that nothing is allocated once they have grown.
void sort_pairs(std::vector<Pair>& pairs, std::size_t n, std::vector<Pair>& tmp,
                std::vector<std::uint32_t>& count);

}  // namespace octocd::detail
