#pragma once
/// \file reference_detail.hpp
/// Internal helpers shared by the Bullet and FCL reference broadphases (not installed).

#include <algorithm>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "octocd/broadphase.hpp"
#include "octocd/error.hpp"
#include "octocd/math.hpp"

namespace octocd::reference_detail {

/// Turns library candidates into the exact answer: keeps each candidate (any order of
/// a, b; a == b dropped) that passes octocd::overlaps() on `boxes`, stores it as (a < b),
/// sorts ascending and removes duplicates. `candidates` is consumed (becomes `out`).
inline void finish_pairs(const std::vector<Aabb>& boxes, std::vector<Pair>& candidates,
                         std::vector<Pair>& out) {
  out.clear();
  for (Pair p : candidates) {
    if (p.a == p.b) continue;
    if (p.a > p.b) std::swap(p.a, p.b);
    if (overlaps(boxes[p.a], boxes[p.b])) out.push_back(p);
  }
  std::sort(out.begin(), out.end());
  out.erase(std::unique(out.begin(), out.end()), out.end());
}

/// Throws InputError when an incremental reference is called with a body count other than
/// the one its proxies were created for.
inline void check_count(const std::string& name, std::size_t expected, std::size_t got) {
  if (expected != got) {
    throw InputError("broadphase '" + name + "': body count changed from " +
                     std::to_string(expected) + " to " + std::to_string(got) +
                     " between calls on one instance (not supported)");
  }
}

// Defined in bullet_broadphase.cpp and fcl_broadphase.cpp: the CPU factories of the rows
// of octocd/broadphase_table.def with host `bullet` and `fcl`. `id` is one of their rows.
std::unique_ptr<BroadPhase> make_bullet_broadphase(BroadPhaseId id, const Aabb& domain);
std::unique_ptr<BroadPhase> make_fcl_broadphase(BroadPhaseId id, float cell_size, const Aabb& domain);

}  // namespace octocd::reference_detail
