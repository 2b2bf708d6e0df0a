/// \file broadphase_octree_cache.cpp
/// `octree` (the default): the loose octree broadphase (design.md section 5.1; Ulrich, "Loose
/// Octrees", Game Programming Gems 2000, looseness k = 2), the form of the paper's world
/// octree (section 3.2, Algorithms 1-2) whose cost scales. The literal reading is
/// `octree-strict` (broadphase_octree_strict.cpp).
///
/// All cell and level math (unit coordinates, level by size, cell of the centre,
/// loose-box containment, query ranges, keys) is in octocd/loose_octree.hpp, shared with
/// the CUDA engine. Two files: the tree (steps 1-5, broadphase_octree_tree.hpp/.cpp) and,
/// here, the BroadPhase with its pair cache across calls (steps 6-7):
///
/// 1. Keys. D_w `auto` is loose_auto_depth of the smallest body extent (in unit
///    coordinates); loose_place_unit gives each body its (level, cell) key, or the
///    overflow list, or none (a box with a NaN coordinate overlaps nothing and is left
///    out); each body's unit box is also kept in the fixed point of loose_q_min/max.
/// 2. Order. Bodies are sorted by (key, body index): a stable order by key. The order of
///    the previous call is reused: bodies whose key did not change keep their relative
///    order (still sorted), the others are sorted apart and merged in (O(n) for coherent
///    motion); a fresh or very different frame takes a stable LSD radix sort on the key.
///    Each occupied cell is then a contiguous run of slots; the cells of one level are
///    contiguous and in Morton order. Boxes are scattered to their slots in body order.
/// 3. Tables. Levels 0..kDenseLevels (at most 2^18 cells) have a dense table indexed by
///    x + 2^l y + 4^l z holding the cell's first slot + 1 and its body count, and an
///    occupancy bit map with one 64-bit word per row of cells (both reset cell by cell,
///    never cleared in full); deeper levels an open-addressing hash table on the key.
/// 4. Query, per occupied cell C of level l; its bodies share one query, made with the
///    union U of their boxes (a superset of each body's own query), with ranges from
///    loose_query_axis_q (equal to loose_query_axis):
///    - own level: the <= 3 x 3 x 3 cells whose loose boxes meet U, keeping only bodies
///      with a larger index, where a body's index at its level orders by its cell's
///      position x + 2^l y + 4^l z first, then by body index (so: later bodies of C
///      itself, and every body of a cell after C in that order; within a cell, slots are
///      in body order). On a dense level the cells after C are the block's bits above
///      C's bit, so they are selected before any table entry is read;
///    - every coarser occupied level m < l: the cells whose loose boxes meet U, keeping
///      every body;
///    then the exact AABB test (Eq. 6, as octocd::overlaps). Each pair is met exactly
///    once: if X in C and Y in C' (same level) overlap, C' is in C's query and C in C''s
///    (both lie in their cell's loose box and the query is exact), and only the one
///    first in that order keeps the pair; across levels only the finer body queries. On a dense level
///    the 27 occupancy bits of the block come from 9 row words, and only occupied cells'
///    table entries are read; the slots found are listed first, then tested with one
///    rarely taken branch each (no short-circuit in the AABB test: its six comparisons
///    are unpredictable, the overall result is not; with SSE2 the six comparisons are
///    two 4-lane ones on the slot's 32 bytes).
///    - overflow bodies are tested against every body (in-tree bodies as structure of
///      arrays, vectorised; overflow bodies with a larger slot).
/// 5. The pairs are sorted by (a, b) with detail::sort_pairs.
/// 6. Pair cache across calls (the "fat AABB" idea of Bullet's dbvt, whose leaves are
///    grown by a margin; a Verlet list in molecular dynamics). Steps 1-5 run on the
///    fattened boxes F_i (every box grown on every side by one margin d, kFatMargin = 1/8
///    of the median body size: the median largest AABB side of at most 1023 bodies
///    spaced evenly in body order; a NaN box stays NaN); their sorted pairs are kept with
///    F and the tree. A later call whose every box B_i lies inside its F_i (or has a NaN
///    coordinate: it overlaps nothing) is a hit: its pairs are the kept pairs whose boxes
///    overlap (Eq. 6), in the kept (sorted) order. Exact: if B_i and B_j overlap, so do
///    F_i and F_j (they contain them), and that pair is kept.
/// 7. Escaped bodies. When a few bodies left their F_i (at most n / 64 in this call and
///    64 + n / 256 since the tree was built), only they are updated: new F_e = B_e grown
///    by d; their kept pairs are dropped; their new pairs are found against the bodies
///    still in the tree under their build-time F (a query of the kept tree at every
///    occupied level, the cells whose loose boxes meet F_e, and the overflow run) and
///    directly against the bodies whose F was replaced since the build; both sorted lists
///    are merged. Otherwise, or when an escaped box would visit more than 4096 cells, the
///    tree is rebuilt (steps 1-6 on the new fattened boxes). The first call on an
///    instance runs steps 1-5 on the boxes themselves and keeps nothing; the next call
///    builds. After a cache that served no call (incoherent input) the next 2 calls run
///    steps 1-5 on the boxes, then one builds; each further useless cache doubles that
///    count, up to 64; a cache that serves a call resets it.
///    The answer never depends on this history; `cell_candidates` does (below).
///
/// Threads (broadphase_octree_tree.cpp): from kParallelMinBodies bodies on, step 1, the
/// slots of step 3 and the queries of step 4 run on the worker team (octocd/parallel.hpp,
/// current_threads(); cells in chunks; the overflow tests in chunks of in-tree slots), each
/// appending to its own pair list; the lists are joined before the sort of step 5, so pairs
/// and candidates do not depend on the thread count. Here, the fattened boxes and the
/// escape check (blocks of bodies, their lists joined in order) from 4,096 bodies and the
/// kept pairs' filter (blocks of pairs, placed in order) from 16,384 pairs run there too.
///
/// `cell_candidates` counts the pairs that reach an exact AABB test: on a call that runs
/// steps 1-5 on the boxes, the tree's tests; on a hit, the kept pairs (all tested on the
/// boxes); on a rebuild, the tree's tests on the fattened boxes plus the kept pairs; on
/// an update, the escaped bodies' tests on fattened boxes plus the kept pairs.

#include <algorithm>

#include "octocd/broadphase.hpp"
#include "octocd/parallel.hpp"

#include "broadphase_detail.hpp"
#include "broadphase_octree_tree.hpp"

namespace octocd {

namespace {

using detail::LooseOctreeTree;
using detail::overlaps_nb;
using detail::QBox;
using detail::Slot;

class LooseOctreeBroadPhase final : public BroadPhase {
 public:
  LooseOctreeBroadPhase(int depth, const Aabb& domain) : tree_(depth, domain) {}

  std::string name() const override { return broadphase_name(BroadPhaseId::octree); }

  void find_pairs(const std::vector<Aabb>& boxes, std::vector<Pair>& out,
                  BroadPhaseStats& stats) override {
    const std::size_t n = boxes.size();
    const bool usable = cache_ready_ && fat_.size() == n;
    if (usable) collect_escaped(boxes);
    if (usable && escaped_.empty()) {
      // Hit: every body still lies in its fattened box, so every overlapping pair is
      // among the kept ones (step 6).
      ++cache_hits_;
      filter_cached(boxes, out);
      stats.cell_candidates = cached_.size();
    } else if (usable && escaped_.size() <= n / kEscapedShare &&
               moved_count_ + escaped_.size() <= kMovedMax + n / kMovedShare &&
               update_escaped(boxes)) {
      // Update: the escaped bodies' pairs are replaced (step 7).
      ++cache_hits_;
      filter_cached(boxes, out);
      stats.cell_candidates = update_candidates_ + cached_.size();
    } else {
      if (cache_ready_ && cache_hits_ == 0) {
        // The last cache served no call (incoherent input): back off, run the tree on the
        // boxes themselves for 2, 4, ... kBackoffMax calls before building again.
        backoff_ = std::min(2 * backoff_, kBackoffMax);
        plain_left_ = backoff_;
        cache_ready_ = false;
      }
      if (cache_ready_ || plain_left_ == 0) {
        // (Re)build: the tree over the fattened boxes gives the kept pairs.
        if (cache_ready_) backoff_ = 1;  // the cache served calls
        fatten(boxes);
        const std::uint64_t tree_candidates = tree_.find_pairs(fat_, cached_);
        cache_ready_ = true;
        cache_hits_ = 0;
        in_moved_.assign(n, 0u);
        moved_count_ = 0;
        moved_list_.clear();
        filter_cached(boxes, out);
        stats.cell_candidates = tree_candidates + cached_.size();
      } else {
        // The tree on the boxes themselves (the first call, or backing off).
        --plain_left_;
        stats.cell_candidates = tree_.find_pairs(boxes, out);
      }
    }
    stats.pairs = out.size();
    stats.memory_bytes = memory_bytes();
  }

 private:
  /// Margin of the fattened boxes (step 6) as a fraction of the median body size.
  static constexpr float kFatMargin = 0.125f;
  /// An update (step 7) replaces at most n / kEscapedShare escaped bodies per call, and
  /// at most kMovedMax + n / kMovedShare since the build; more rebuild.
  static constexpr std::size_t kEscapedShare = 64;
  static constexpr std::size_t kMovedMax = 64;
  static constexpr std::size_t kMovedShare = 256;
  /// An escaped body whose query would visit more cells than this makes a rebuild.
  static constexpr std::uint64_t kQueryCellsMax = 4096;
  /// Most calls run without a cache after caches that served no call.
  static constexpr std::uint32_t kBackoffMax = 64;
  /// Bodies sampled (evenly spaced in body order) for the median size.
  static constexpr std::size_t kFatSample = 1023;
  /// The fewest bodies whose fattening and escape check run on the worker team
  /// (octocd/parallel.hpp), and the fewest kept pairs whose filter does.
  static constexpr std::size_t kParallelBodiesFrom = 4096;
  static constexpr std::size_t kParallelPairsFrom = 16384;

  static LoopOptions by_bodies() {
    LoopOptions loop;
    loop.min_items = kParallelBodiesFrom;
    return loop;
  }

  /// Largest side of a box; 0 unless finite and > 0.
  static float largest_side(const Aabb& b) {
    float ext = b.max.x - b.min.x;
    ext = ext > b.max.y - b.min.y ? ext : b.max.y - b.min.y;
    ext = ext > b.max.z - b.min.z ? ext : b.max.z - b.min.z;
    return (ext > 0.0f && ext <= 3.4e38f) ? ext : 0.0f;
  }

  /// fat_ = every box grown on every side by the margin d = kFatMargin x the median of
  /// the largest sides (finite and > 0) of at most kFatSample bodies spaced evenly in
  /// body order (0 when there are none; a NaN box stays NaN).
  void fatten(const std::vector<Aabb>& boxes) {
    const std::size_t n = boxes.size();
    sizes_.clear();
    const std::size_t stride = n / kFatSample + 1;
    for (std::size_t i = 0; i < n; i += stride) {
      const float e = largest_side(boxes[i]);
      if (e > 0.0f) sizes_.push_back(e);
    }
    float d = 0.0f;
    if (!sizes_.empty()) {
      const auto mid = sizes_.begin() + static_cast<std::ptrdiff_t>(sizes_.size() / 2);
      std::nth_element(sizes_.begin(), mid, sizes_.end());
      d = kFatMargin * *mid;
    }
    fat_d_ = d;
    fat_.resize(n);
    parallel_for(n, by_bodies(), [&](std::size_t i, unsigned) { fat_[i] = expanded(boxes[i], d); });
  }

  /// escaped_ = the bodies whose box is not inside its fattened box (inclusive) and has
  /// no NaN coordinate (a NaN box overlaps nothing), in body order.
  void collect_escaped(const std::vector<Aabb>& boxes) {
    escaped_.clear();
    const std::size_t n = boxes.size();
    const Aabb* b = boxes.data();
    const Aabb* f = fat_.data();
    // Blocks of bodies on the team, each listing its own; the lists joined in block order.
    const unsigned threads = loop_threads(n, by_bodies());
    const std::size_t blocks = threads <= 1 ? 1 : std::size_t(threads) * 8;
    if (escaped_by_.size() < blocks) escaped_by_.resize(blocks);
    LoopOptions one_each;
    one_each.threads = static_cast<int>(threads);
    one_each.chunk = 1;
    parallel_for(blocks, one_each, [&](std::size_t k, unsigned) {
      std::vector<std::uint32_t>& list = escaped_by_[k];
      list.clear();
      const std::size_t end = n * (k + 1) / blocks;
      for (std::size_t i0 = n * k / blocks; i0 < end; i0 += 256) {
        const std::size_t i1 = std::min(end, i0 + 256);
        unsigned bad = 0;
        for (std::size_t i = i0; i < i1; ++i) bad |= escaped(b[i], f[i]);
        if (bad == 0u) continue;
        for (std::size_t i = i0; i < i1; ++i) {
          if (escaped(b[i], f[i]) != 0u) list.push_back(static_cast<std::uint32_t>(i));
        }
      }
    });
    for (std::size_t k = 0; k < blocks; ++k) escaped_.insert(escaped_.end(), escaped_by_[k].begin(), escaped_by_[k].end());
  }

  /// 1 when box b is not inside f (inclusive) and has no NaN coordinate, else 0.
  static unsigned escaped(const Aabb& b, const Aabb& f) {
    const unsigned inside = static_cast<unsigned>(b.min.x >= f.min.x) & static_cast<unsigned>(b.min.y >= f.min.y) &
                            static_cast<unsigned>(b.min.z >= f.min.z) & static_cast<unsigned>(b.max.x <= f.max.x) &
                            static_cast<unsigned>(b.max.y <= f.max.y) & static_cast<unsigned>(b.max.z <= f.max.z);
    const unsigned nan = static_cast<unsigned>(b.min.x != b.min.x) | static_cast<unsigned>(b.min.y != b.min.y) |
                         static_cast<unsigned>(b.min.z != b.min.z) | static_cast<unsigned>(b.max.x != b.max.x) |
                         static_cast<unsigned>(b.max.y != b.max.y) | static_cast<unsigned>(b.max.z != b.max.z);
    return (inside | nan) ^ 1u;
  }

  /// Step 7: the bodies of escaped_ get new fattened boxes (same margin) and their kept
  /// pairs are replaced by the pairs of their new fattened boxes: with the bodies still
  /// in the tree under their build-time fattened box (a query of the tree at every
  /// occupied level, and the overflow run), and with the bodies whose fattened box was
  /// replaced since the build (moved, tested directly). Returns false, changing nothing,
  /// when an escaped box's query would visit more than kQueryCellsMax cells (a huge box:
  /// the caller rebuilds). update_candidates_ = the tests made on fattened boxes.
  bool update_escaped(const std::vector<Aabb>& boxes) {
    // Query ranges first: a box too large for a query leaves everything unchanged.
    equery_.clear();
    for (const std::uint32_t e : escaped_) {
      const QBox q = tree_.query_box(expanded(boxes[e], fat_d_));
      if (tree_.cells_met(q) > kQueryCellsMax) return false;
      equery_.push_back(q);
    }
    // New fattened boxes; the escaped bodies join the moved ones.
    for (const std::uint32_t e : escaped_) {
      fat_[e] = expanded(boxes[e], fat_d_);
      if (in_moved_[e] == 0u) {
        in_moved_[e] = 1u;
        moved_list_.push_back(e);
        ++moved_count_;
      }
      in_moved_[e] |= 2u;  // escaped in this call
    }
    // Drop their kept pairs.
    std::size_t w = 0;
    for (const Pair p : cached_) {
      cached_[w] = p;
      w += ((in_moved_[p.a] | in_moved_[p.b]) & 2u) == 0u ? 1u : 0u;
    }
    cached_.resize(w);
    // Their new pairs.
    fresh_.clear();
    std::uint64_t tests = 0;
    std::vector<std::uint32_t>& scratch = tree_.scratch();
    const Slot* slots = tree_.slots();
    const std::uint32_t overflow_begin = tree_.overflow_begin(), overflow_end = tree_.overflow_end();
    for (std::size_t k = 0; k < escaped_.size(); ++k) {
      const std::uint32_t e = escaped_[k];
      const Aabb fe = fat_[e];
      const std::uint32_t nflat = tree_.gather_all_levels(equery_[k], scratch);
      tests += nflat + (overflow_end - overflow_begin);
      for (std::uint32_t t = 0; t < nflat; ++t) {
        const Slot& sj = slots[scratch[t]];
        if (in_moved_[sj.body] != 0u) continue;  // tested below with its current box
        if (overlaps_nb(fe, sj.box)) fresh_.push_back(e < sj.body ? Pair{e, sj.body} : Pair{sj.body, e});
      }
      for (std::uint32_t o = overflow_begin; o < overflow_end; ++o) {
        const Slot& sj = slots[o];
        if (in_moved_[sj.body] != 0u) continue;
        if (overlaps_nb(fe, sj.box)) fresh_.push_back(e < sj.body ? Pair{e, sj.body} : Pair{sj.body, e});
      }
      for (const std::uint32_t j : moved_list_) {
        // Each pair of two escaped bodies once (from the smaller index).
        if (j == e || ((in_moved_[j] & 2u) != 0u && j < e)) continue;
        ++tests;
        if (overlaps_nb(fe, fat_[j])) fresh_.push_back(e < j ? Pair{e, j} : Pair{j, e});
      }
    }
    for (const std::uint32_t e : escaped_) in_moved_[e] = 1u;
    // Merge (both sorted; disjoint: every new pair has an escaped body, no kept one has).
    std::sort(fresh_.begin(), fresh_.end());
    const std::size_t kept = cached_.size();
    cached_.resize(kept + fresh_.size());
    std::copy(fresh_.begin(), fresh_.end(), cached_.begin() + static_cast<std::ptrdiff_t>(kept));
    std::inplace_merge(cached_.begin(), cached_.begin() + static_cast<std::ptrdiff_t>(kept), cached_.end());
    update_candidates_ = tests;
    return true;
  }


  /// out = the cached pairs whose boxes overlap (Eq. 6), in the cache's sorted order.
  void filter_cached(const std::vector<Aabb>& boxes, std::vector<Pair>& out) {
    const std::size_t m = cached_.size();
    const Aabb* b = boxes.data();
    LoopOptions by_pairs;
    by_pairs.min_items = kParallelPairsFrom;
    const unsigned threads = loop_threads(m, by_pairs);
    if (threads <= 1) {
      out.resize(m);
      std::size_t w = 0;
      for (const Pair p : cached_) {
        out[w] = p;
        w += overlaps_nb(b[p.a], b[p.b]) ? 1u : 0u;
      }
      out.resize(w);
      return;
    }
    // Blocks of kept pairs on the team: each block's overlapping pairs to its own range of
    // filtered_, then every block's to its place in `out` (the kept order).
    const std::size_t blocks = std::size_t(threads) * 8;
    filtered_.resize(m);
    block_at_.assign(blocks + 1, 0);
    LoopOptions one_each;
    one_each.threads = static_cast<int>(threads);
    one_each.chunk = 1;
    parallel_for(blocks, one_each, [&](std::size_t k, unsigned) {
      const std::size_t lo = m * k / blocks, hi = m * (k + 1) / blocks;
      std::size_t w = lo;
      for (std::size_t i = lo; i < hi; ++i) {
        const Pair p = cached_[i];
        filtered_[w] = p;
        w += overlaps_nb(b[p.a], b[p.b]) ? 1u : 0u;
      }
      block_at_[k + 1] = w - lo;
    });
    for (std::size_t k = 0; k < blocks; ++k) block_at_[k + 1] += block_at_[k];
    out.resize(block_at_[blocks]);
    parallel_for(blocks, one_each, [&](std::size_t k, unsigned) {
      const std::size_t lo = m * k / blocks;
      std::copy(filtered_.begin() + static_cast<std::ptrdiff_t>(lo),
                filtered_.begin() + static_cast<std::ptrdiff_t>(lo + block_at_[k + 1] - block_at_[k]),
                out.begin() + static_cast<std::ptrdiff_t>(block_at_[k]));
    });
  }

  std::uint64_t memory_bytes() const {
    const std::uint64_t bytes = fat_.capacity() * sizeof(Aabb) +
                                (cached_.capacity() + fresh_.capacity()) * sizeof(Pair) +
                                (escaped_.capacity() + moved_list_.capacity()) * sizeof(std::uint32_t) +
                                in_moved_.capacity() + equery_.capacity() * sizeof(QBox) +
                                sizes_.capacity() * sizeof(float) + filtered_.capacity() * sizeof(Pair) +
                                block_at_.capacity() * sizeof(std::size_t);
    std::uint64_t lists = 0;
    for (const auto& list : escaped_by_) lists += list.capacity() * sizeof(std::uint32_t);
    return bytes + lists + tree_.memory_bytes();
  }













  LooseOctreeTree tree_;  // steps 1-5
  // Step 6: the pair cache.
  std::vector<Aabb> fat_;        // per body: its fattened box when the cache was built
  std::vector<float> sizes_;     // sampled body sizes (scratch of fatten)
  std::vector<Pair> cached_;     // sorted pairs whose fattened boxes overlap
  float fat_d_ = 0.0f;           // the margin of fat_ (m)
  std::vector<std::uint32_t> escaped_;    // bodies outside their fattened box (this call)
  std::vector<QBox> equery_;              // their new fattened boxes, fixed point
  std::vector<std::uint8_t> in_moved_;    // per body: 1 = fattened box replaced since the build
                                          // (2 added while it escapes in this call)
  std::vector<std::uint32_t> moved_list_; // those bodies
  std::size_t moved_count_ = 0;
  std::vector<Pair> fresh_;               // pairs found by an update
  std::vector<std::vector<std::uint32_t>> escaped_by_;  // per block of bodies: its escaped ones
  std::vector<Pair> filtered_;            // per block of kept pairs: its overlapping ones
  std::vector<std::size_t> block_at_;     // per block: where its filtered pairs go in `out`
  std::uint64_t update_candidates_ = 0;
  bool cache_ready_ = false;     // cached_ and fat_ are valid
  std::uint32_t plain_left_ = 1; // calls that run the tree on the boxes before a build
  std::uint32_t backoff_ = 1;    // the last back-off (calls)
  std::uint64_t cache_hits_ = 0; // calls served by the current cache
};

}  // namespace

namespace detail {

std::unique_ptr<BroadPhase> make_host_octree(const BroadPhaseConfig& config, const Aabb& domain) {
  return std::make_unique<LooseOctreeBroadPhase>(config.octree_depth, domain);
}

}  // namespace detail

}  // namespace octocd
