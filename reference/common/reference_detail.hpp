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

/// A library broadphase (Bullet's, FCL's) built on its first find_pairs and moved on the
/// later ones. find_pairs builds it (create) or checks the body count (check_count) and
/// moves every box (move), gathers the library's candidates (collect) and keeps the exact
/// pairs (finish_pairs); stats: the candidates, the pairs and library_bytes() plus the
/// candidate buffer.
class LibraryBroadPhase : public BroadPhase {
 public:
  explicit LibraryBroadPhase(BroadPhaseId id) : name_(broadphase_name(id)) {}

  std::string name() const override { return name_; }

  void find_pairs(const std::vector<Aabb>& boxes, std::vector<Pair>& out, BroadPhaseStats& stats) final {
    if (!built()) {
      create(boxes);
    } else {
      check_count(name_, bodies(), boxes.size());
      move(boxes);
    }
    candidates_.clear();
    collect(candidates_);
    stats.cell_candidates = candidates_.size();
    finish_pairs(boxes, candidates_, out);
    stats.pairs = out.size();
    stats.memory_bytes = library_bytes() + candidates_.capacity() * sizeof(Pair);
  }

 protected:
  /// Whether create() has run.
  virtual bool built() const = 0;
  /// The body count create() was given.
  virtual std::size_t bodies() const = 0;
  /// Builds the library's structure for `boxes` (body i is boxes[i]).
  virtual void create(const std::vector<Aabb>& boxes) = 0;
  /// Moves every body to its box in `boxes` (as many as create() was given).
  virtual void move(const std::vector<Aabb>& boxes) = 0;
  /// Appends the library's candidate pairs (any order, duplicates allowed) to `candidates`.
  virtual void collect(std::vector<Pair>& candidates) = 0;
  /// Approximate bytes of the library's structures and the adapter's own per-body data.
  virtual std::uint64_t library_bytes() const = 0;

 private:
  std::string name_;
  std::vector<Pair> candidates_;
};

// Defined in bullet_broadphase.cpp and fcl_broadphase.cpp: the CPU factories of the rows
// of octocd/broadphase_table.def with host `bullet` and `fcl`. `id` is one of their rows.
std::unique_ptr<BroadPhase> make_bullet_broadphase(BroadPhaseId id, const Aabb& domain);
std::unique_ptr<BroadPhase> make_fcl_broadphase(BroadPhaseId id, float cell_size, const Aabb& domain);

}  // namespace octocd::reference_detail
