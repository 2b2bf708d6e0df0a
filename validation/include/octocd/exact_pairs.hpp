#pragma once
/// \file exact_pairs.hpp
/// The validators' reference pair set in O(n log n + pairs) for the scenes engines run:
/// exactly the set `flat` finds (every pair tested through Eq. 6, `overlaps` in
/// octocd/math.hpp: inclusive float comparisons), without testing every pair.

#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "octocd/broadphase.hpp"
#include "octocd/error.hpp"
#include "octocd/math.hpp"

namespace octocd {

namespace limits {
/// Most reference pairs the validators judge in one frame, per body: a frame of n bodies
/// whose (grown) boxes overlap in more than 64 n pairs is refused, since every pair costs
/// the validators about 0.7 KiB and 3.5 us (SAT, FCL, the rows' truth). Real runs stay far
/// below: the box lattice of bench_validation --lattice has 13 a body, the shipped scenes
/// fewer; only piled-up (coincident) bodies come near, n / 2 a body.
constexpr std::uint64_t kMaxPairsPerBody = 64;
/// Candidate tests (two boxes sharing a grid cell) exact_pairs allows per allowed pair:
/// two boxes of one level share at most 8 cells (2 per axis), so a frame within
/// kMaxPairsPerBody makes about as many tests as pairs times 8 at most (the shipped
/// scenes: 2 to 3 a pair).
constexpr std::uint64_t kCandidateTestsPerPair = 8;
}  // namespace limits

/// Knobs of exact_pairs (defaults are what the validators use).
struct ExactPairsSettings {
  /// Threads for the cell scan and the per-box passes (those from 1,024 boxes on); 0: one
  /// below 4096 boxes, else current_threads() (octocd/parallel.hpp: OMP_NUM_THREADS when
  /// set, else the CPUs this process may run on). The result does not depend on it.
  int threads = 0;
  /// Most pairs per box; 0: no limit. With a limit, L = max_pairs_per_body x the boxes:
  /// exact_pairs counts the candidate tests of its grid (boxes sharing a cell, O(n log n),
  /// before any test or per-pair allocation) and throws PairLimitError when they exceed
  /// limits::kCandidateTestsPerPair x L, or when the tests find more than L pairs (its
  /// memory stays within the tests: 8 bytes each). The validators pass
  /// limits::kMaxPairsPerBody.
  std::uint64_t max_pairs_per_body = 0;
};

/// exact_pairs' refusal of boxes crowded beyond ExactPairsSettings::max_pairs_per_body (an
/// InputError: exit 2). `count` is the candidate tests (`tests` true, counted before any
/// test) or the pairs found (`tests` false); `limit` the number it exceeded.
class PairLimitError : public InputError {
 public:
  /// The message: the count, what it counts, the bodies and the limit.
  PairLimitError(std::uint64_t count, bool tests, std::uint64_t limit, std::size_t bodies);
  /// The same figures under another message (a caller adds the frame, the file).
  PairLimitError(const std::string& message, const PairLimitError& from);
  std::uint64_t count = 0;  ///< candidate tests or pairs, as `tests` says
  bool tests = false;       ///< count is candidate tests (true) or pairs found (false)
  std::uint64_t limit = 0;  ///< the limit `count` exceeded
  std::size_t bodies = 0;   ///< the boxes given
};

/// Every pair (a, b), a < b, of `boxes` (world AABBs, m, one per body) for which
/// overlaps(boxes[a], boxes[b]) holds (Eq. 6: min_A <= max_B and max_A >= min_B on every
/// axis, float comparisons, touching faces included), sorted ascending, unique: the same
/// set as the `flat` broadphase, for every input (NaN, infinite, inverted and
/// coincident boxes included). `out` is cleared first.
///
/// Algorithm: a hierarchical uniform grid on each box's hull [min(lo, hi), max(lo, hi)]
/// per axis (a superset of Eq. 6's pairs; an inverted box is still found). Level L has
/// cells of side c0 2^L (c0: the median of the boxes' largest finite hull side); a box
/// lives on the lowest level whose side is at least its largest side, in 8 cells at most
/// (up to 27 where rounding of the cell index lands a side exactly on a cell border).
/// Pairs of one level meet in a shared cell; a box meets the boxes of coarser levels by
/// looking up its own range of their cells (in O(1) through a dense table of the level's
/// cells where they span at most 4 x its entries + 1,024 cells, else by binary search).
/// Every candidate is tested with `overlaps`
/// itself and reported only from the one cell holding the lowest corner of the two hulls'
/// intersection (cell indices are floor((x - origin) / side), monotone in x, so that
/// cell lies in both boxes' ranges). A box with a NaN coordinate overlaps nothing under
/// Eq. 6 (each coordinate enters one comparison) and is skipped; a box with an infinite
/// side (or one 2^60 cells wide) is tested against every other box.
///
/// Cost: O(n log n) for the grid plus the candidates that share a cell (for bodies of
/// similar size spread through a scene, a few per body) plus n x the unbounded boxes;
/// memory: 8 cell entries per box (32 bytes each), the dense tables (8 bytes a cell, at
/// most 4 x the entries + 1,025 cells a level) plus the pairs (8 bytes each). Many
/// boxes crowded into one cell (all coincident) make it quadratic, as their pairs are;
/// ExactPairsSettings::max_pairs_per_body refuses them before that work (PairLimitError).
void exact_pairs(const std::vector<Aabb>& boxes, std::vector<Pair>& out, const ExactPairsSettings& settings = {});

/// exact_pairs' work space: the boxes' hulls and levels, the grid's cell entries and dense
/// cell tables, the pairs found per thread and their sort's buffers. A caller that keeps
/// one between calls (the validators: one per call site, kept from frame to frame) has
/// each later call rebuild these tables in the memory they already hold instead of
/// allocating and first-touching it anew. It holds no result: any boxes may follow any
/// others. One call at a time. Movable (a moved-from object is usable, empty).
class ExactPairsTables {
 public:
  ExactPairsTables();
  ~ExactPairsTables();
  ExactPairsTables(ExactPairsTables&&) noexcept;
  ExactPairsTables& operator=(ExactPairsTables&&) noexcept;
  ExactPairsTables(const ExactPairsTables&) = delete;
  ExactPairsTables& operator=(const ExactPairsTables&) = delete;
  struct Impl;
  /// The tables (exact_pairs.cpp defines them).
  Impl& impl();

 private:
  std::unique_ptr<Impl> impl_;
};

/// exact_pairs with its tables in `tables` (kept by the caller; the result is the same
/// as with fresh tables). Its per-box passes (hulls, levels, cell entries and their ranks,
/// the cells' runs, the limit's lookups, the pairs' sort) run on the settings' threads
/// from 1,024 boxes (or entries) on; the result never depends on the thread count.
void exact_pairs(const std::vector<Aabb>& boxes, std::vector<Pair>& out, const ExactPairsSettings& settings,
                 ExactPairsTables& tables);

/// exact_pairs as a BroadPhase named "exact-grid" (the validators' reference where
/// `flat`'s n(n-1)/2 tests cost too much). Stateless; stats.pairs and
/// stats.cell_candidates are the pairs found; settings.max_pairs_per_body applies to
/// each call (PairLimitError).
std::unique_ptr<BroadPhase> make_exact_pairs_broadphase(const ExactPairsSettings& settings = {});

}  // namespace octocd
