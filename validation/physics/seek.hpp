#pragma once
/// \file seek.hpp
/// Look-ups of pairs asked in ascending order in a sorted pair list (the physics tier's
/// candidates, required pairs and contact rows against its truth and the engine's
/// pairs). Internal to validation/physics.

#include <algorithm>
#include <cstddef>
#include <vector>

#include "octocd/broadphase.hpp"

namespace octocd::physics_detail {

/// std::lower_bound of p in the sorted `v`, searched onwards from `cursor` (0 at first;
/// set to the answer) when every pair before it lies below p, else from the start:
/// steps of 1, 2, 4, ... from there until a pair not below p, then a binary search within
/// the last step. Pairs asked in ascending order cost O(log gap) each and read `v` in
/// order; any order is answered correctly.
inline std::size_t seek(const std::vector<Pair>& v, Pair p, std::size_t& cursor) {
  const std::size_t n = v.size();
  std::size_t lo = cursor <= n && (cursor == 0 || v[cursor - 1] < p) ? cursor : 0;
  std::size_t hi = lo, step = 1;
  // Every pair before lo lies below p; v[hi] does not, or hi == n.
  while (hi < n && v[hi] < p) {
    lo = hi + 1;
    hi = std::min(n, lo + step);
    step *= 2;
  }
  cursor = std::size_t(std::lower_bound(v.begin() + std::ptrdiff_t(lo), v.begin() + std::ptrdiff_t(hi), p) -
                       v.begin());
  return cursor;
}

}  // namespace octocd::physics_detail
