/// \file broadphase_octree_strict.cpp
/// `octree-strict`: the paper's world-space octree read literally (paper section 3.2,
/// Algorithms 1-2; design.md section 5.1). The default `octree` is
/// the loose octree of broadphase_octree_cache.cpp.
///
/// Node math (grid, node keys, subtree ranges) lives in octocd/strict_octree.hpp, shared
/// with the CUDA engine's gpu/src/broadphase_octree_strict.cu.
///
/// Structure. The root is the bounding cube of the domain (centred on the domain centre,
/// side = longest domain side), split D_w times. Coordinates are mapped monotonically to
/// the integer grid of the depth-D_w leaves; a body goes into the deepest node whose cell
/// holds both its min and max corner cell. Node cells are half-open [lo, hi) in grid
/// space (closed only on the root's upper faces), so two bodies in unrelated nodes are
/// strictly separated on some axis and cannot overlap, not even by touching faces. Bodies
/// not inside the root (or with a non-finite coordinate) stay at the root. Because the
/// grid mapping is monotone in each coordinate, the argument holds under float rounding.
///
/// Keys. A node at level l with Morton code m (of its level-l cell) covers the contiguous
/// range [m * 8^(D-l), (m+1) * 8^(D-l)) of depth-D leaf Morton codes; its key is
/// (range lo, level), so sorting by key lists nodes in pre-order and a node's subtree is
/// a contiguous run of the sorted bodies.
///
/// Query. Bodies are sorted by (node key, min.x), so each non-empty node is a run of
/// slots. Pass 1 lists the non-empty nodes in pre-order with their nearest non-empty
/// ancestor and the union AABB of their subtree's bodies. Pass 2 descends: a node's
/// candidate list is the set of its ancestors' bodies that overlap its subtree bounds
/// (filtered from the parent's list plus the parent's own bodies; an ancestor body that
/// misses the bounds cannot overlap any body below, so this is exact, with no rounding
/// involved); it is kept sorted by min.x (a merge). Pairs inside a node: sweep and prune
/// on x (in a node of kSplitOwnFrom bodies or more, those spanning its centre plane across
/// x swept on y among themselves); pairs with ancestors: a two-list sweep on x of the own
/// bodies against the candidate list. Every related pair is met once, then goes through
/// Eq. 6. `cell_candidates` counts all pairs in related nodes (design.md section 5.1), i.e.
/// before this culling.
///
/// Incremental use: the sorted order of the previous call is kept and re-sorted by
/// insertion sort (near O(n) for coherent motion; bodies that changed node are sorted
/// apart and merged in), with a fall-back to a full sort when the order changed a lot.
/// Buffers are kept between calls.
///
/// Threads: the keys and their kept/moved split (in blocks), the re-sort of the kept order
/// (in runs cut at node boundaries) or the full sort, the copies and pass 2 (subtrees, and
/// the nodes above them in runs) run on the worker team (octocd/parallel.hpp,
/// current_threads()); the pairs and counts do not depend on the thread count.

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstring>
#include <limits>

#include "octocd/broadphase.hpp"
#include "octocd/parallel.hpp"
#include "octocd/strict_octree.hpp"

#include "broadphase_detail.hpp"

namespace octocd {

namespace {

/// The fewest bodies whose keys, sort, copies and descent run on the worker team
/// (octocd/parallel.hpp): below, one thread costs less than waking others.
constexpr std::size_t kParallelItemsFrom = 4096;

/// An item's node key where its box has a NaN coordinate (no node key reaches it: a key is
/// a leaf range's start < 8^10, shifted by 4, and a level).
constexpr std::uint64_t kNoNode = ~std::uint64_t(0);

/// Float to an unsigned key with the same order (-0 sorts just before +0).
inline std::uint32_t float_key(float f) {
  std::uint32_t u;
  std::memcpy(&u, &f, sizeof u);
  return (u & 0x80000000u) ? ~u : (u | 0x80000000u);
}

/// Whether box `b` of the node with key `key` spans that node's centre plane across x, read
/// off its leaf indices (strict_leaf_span, as strict_node_key finds them; 0 for a leaf node, a
/// box outside the root or an unusable grid). A node's own bodies each span one of its three centre planes,
/// and those that span the one across x overlap one another in x: judge_node sweeps them on
/// y. A hint only: whatever it answers, the same pairs are found.
inline std::uint8_t spans_centre_x(const StrictGrid& g, std::uint64_t key, const Aabb& b) {
  const int s = g.depth - strict_key_level(key);
  std::uint32_t t0 = 0, t1 = 0;
  if (!g.usable || s <= 0 || !strict_leaf_span(g, b.min.x, b.max.x, 0, t0, t1)) return 0;
  return ((t0 ^ t1) >> (s - 1)) != 0u ? 1 : 0;
}

/// The fewest own bodies of a node for which judge_node sweeps those spanning its centre
/// plane across x on y (apart from the others); below it, one sweep on x.
constexpr std::uint32_t kSplitOwnFrom = 64;

/// One body in the sort: node key (range lo << 4 | level), then min.x.
struct Item {
  std::uint64_t node;
  std::uint32_t minx;  // float_key(min.x)
  std::uint32_t body;
};

inline bool item_less(const Item& p, const Item& q) {
  if (p.node != q.node) return p.node < q.node;
  if (p.minx != q.minx) return p.minx < q.minx;
  return p.body < q.body;
}

/// A non-empty node: its own bodies are the sorted slots [begin, end).
struct Node {
  std::uint64_t hi;          // end of its leaf range
  std::uint32_t begin;
  std::uint32_t end;
  std::int32_t parent;       // nearest non-empty proper ancestor, -1 at the top
  std::uint32_t last;        // one past the last node of its subtree (pre-order)
  std::uint64_t anc_pop;     // bodies in all proper ancestors (for the candidate count)
  Aabb bounds;               // union of the AABBs of the bodies of its subtree
};

/// An ancestor body kept for the current node (it overlaps the node's subtree bounds).
struct Cand {
  Aabb box;
  std::uint32_t body;
};

/// A node on a descent's stack; its ancestor candidates are the stack's cands[cbegin, cend).
struct Frame {
  std::int32_t node;
  std::uint32_t cbegin;
  std::uint32_t cend;
};

class StrictOctreeBroadPhase final : public BroadPhase {
 public:
  StrictOctreeBroadPhase(int depth, const Aabb& domain) : depth_cfg_(depth), domain_(domain) {}

  std::string name() const override { return broadphase_name(BroadPhaseId::octree_strict); }

  void find_pairs(const std::vector<Aabb>& boxes, std::vector<Pair>& out,
                  BroadPhaseStats& stats) override {
    out.clear();
    const std::size_t n = boxes.size();
    const int depth = depth_cfg_ < 0 ? auto_octree_depth(boxes, domain_) : depth_cfg_;
    build_keys(boxes, depth);
    sort_items();

    // Bodies in sorted order (SoA of what the sweep reads).
    sorted_.resize(items_.size());
    sminx_.resize(items_.size());
    LoopOptions by_items;
    by_items.min_items = kParallelItemsFrom;
    parallel_for(items_.size(), by_items, [&](std::size_t k, unsigned) {
      sorted_[k] = boxes[items_[k].body];
      sminx_[k] = sorted_[k].min.x;
    });

    // Pass 1: the non-empty nodes in pre-order, their parents and subtree bounds.
    nodes_.clear();
    parents_.clear();
    const std::uint32_t m = static_cast<std::uint32_t>(items_.size());
    for (std::uint32_t g = 0; g < m;) {
      const std::uint64_t key = items_[g].node;
      std::uint32_t e = g + 1;
      Aabb own = sorted_[g];
      while (e < m && items_[e].node == key) {
        own = merged(own, sorted_[e]);
        ++e;
      }
      const std::uint64_t lo = key >> 4;
      const std::uint64_t hi = strict_subtree_leaf_end(key, depth);
      while (!parents_.empty() && nodes_[parents_.back()].hi <= lo) close_top();
      Node node;
      node.hi = hi;
      node.begin = g;
      node.end = e;
      node.parent = parents_.empty() ? -1 : parents_.back();
      node.anc_pop = 0;
      if (node.parent >= 0) {
        const Node& p = nodes_[node.parent];
        node.anc_pop = p.anc_pop + (p.end - p.begin);
      }
      node.bounds = own;
      parents_.push_back(static_cast<std::int32_t>(nodes_.size()));
      nodes_.push_back(node);
      g = e;
    }
    while (!parents_.empty()) close_top();

    // Pass 2: descent. A node's candidates are the bodies of its ancestors that overlap
    // its subtree bounds (the only ones that can overlap a body of its subtree), filtered
    // from the parent's candidates and the parent's own bodies. In tasks on the worker team,
    // each first rebuilding its first node's ancestors' candidates: subtrees of at most
    // `target` nodes, and the nodes above them in runs of about equal own bodies (they hold
    // the bodies that span coarse cells' centre planes, an eighth of all at 10^6 bodies);
    // their pairs joined in task order.
    const std::size_t nn = nodes_.size();
    const unsigned threads = loop_threads(items_.size(), by_items);
    const std::size_t target = threads <= 1 ? nn : std::max<std::size_t>(64, nn / (std::size_t(threads) * 16));
    task_roots_.clear();
    above_.clear();
    std::uint64_t above_pop = 0;
    for (std::size_t k = 0; k < nn;) {
      if (nodes_[k].last - k <= target) {
        task_roots_.push_back(static_cast<std::uint32_t>(k));
        k = nodes_[k].last;
      } else {
        above_.push_back(static_cast<std::uint32_t>(k));
        above_pop += nodes_[k].end - nodes_[k].begin + 1;
        ++k;
      }
    }
    // The runs of above_: [above_run_[r], above_run_[r + 1]), cut where equal shares of
    // their own bodies (plus one a node) begin.
    const std::size_t runs = std::min<std::size_t>(above_.size(), threads <= 1 ? 1 : std::size_t(threads) * 4);
    above_run_.assign(1, 0);
    std::uint64_t sum = 0;
    for (std::size_t j = 0, r = 1; j < above_.size(); ++j) {
      if (r < runs && sum >= above_pop * r / runs) {
        above_run_.push_back(static_cast<std::uint32_t>(j));
        ++r;
      }
      sum += nodes_[above_[j]].end - nodes_[above_[j]].begin + 1;
    }
    above_run_.push_back(static_cast<std::uint32_t>(above_.size()));
    const std::size_t above_tasks = above_.empty() ? 0 : above_run_.size() - 1;
    const std::size_t tasks = above_tasks + task_roots_.size();
    task_out_.resize(tasks);
    std::vector<std::uint64_t> task_candidates(tasks, 0);
    scratch_.resize(std::max(1u, threads));
    LoopOptions by_task;
    by_task.threads = static_cast<int>(threads);
    by_task.chunk = 1;
    parallel_for(tasks, by_task, [&](std::size_t t, unsigned worker) {
      Scratch& sc = scratch_[worker];
      sc.frames.clear();
      sc.cands.clear();
      std::vector<Pair>& pairs = task_out_[t];
      pairs.clear();
      std::uint64_t& candidates = task_candidates[t];
      const bool above = t < above_tasks;
      const std::uint32_t first = above ? above_[above_run_[t]] : task_roots_[t - above_tasks];
      sc.chain.clear();
      for (std::int32_t a = nodes_[first].parent; a >= 0; a = nodes_[a].parent) sc.chain.push_back(a);
      for (auto a = sc.chain.rbegin(); a != sc.chain.rend(); ++a) enter(std::size_t(*a), sc);
      if (above) {
        for (std::uint32_t j = above_run_[t]; j < above_run_[t + 1]; ++j) {
          enter(above_[j], sc);
          candidates += judge_node(above_[j], sc, pairs);
        }
        return;
      }
      for (std::size_t k = first; k < nodes_[first].last; ++k) {
        enter(k, sc);
        candidates += judge_node(k, sc, pairs);
      }
    });
    std::uint64_t candidates = 0;
    std::size_t total = 0;
    for (std::size_t t = 0; t < tasks; ++t) {
      candidates += task_candidates[t];
      total += task_out_[t].size();
    }
    out.reserve(total);
    for (const std::vector<Pair>& pairs : task_out_) out.insert(out.end(), pairs.begin(), pairs.end());

    detail::sort_pairs(out, n, tmp_pairs_, count_);
    stats.cell_candidates = candidates;
    stats.pairs = out.size();
    stats.memory_bytes = (items_.capacity() + moved_.capacity() + merge_buf_.capacity() + fresh_.capacity()) *
                             sizeof(Item) + sorted_.capacity() * sizeof(Aabb) +
                         sminx_.capacity() * sizeof(float) + nodes_.capacity() * sizeof(Node) +
                         parents_.capacity() * sizeof(std::int32_t) +
                         scratch_bytes() +
                         (task_roots_.capacity() + above_.capacity() + above_run_.capacity()) * sizeof(std::uint32_t) +
                         tmp_pairs_.capacity() * sizeof(Pair) +
                         count_.capacity() * sizeof(std::uint32_t);
  }

 private:
  static Aabb merged(const Aabb& a, const Aabb& b) {
    return {{std::min(a.min.x, b.min.x), std::min(a.min.y, b.min.y), std::min(a.min.z, b.min.z)},
            {std::max(a.max.x, b.max.x), std::max(a.max.y, b.max.y), std::max(a.max.z, b.max.z)}};
  }

  /// Pops the top of the pass-1 stack; its subtree bounds are final: merge into parent.
  void close_top() {
    const std::int32_t t = parents_.back();
    parents_.pop_back();
    nodes_[t].last = static_cast<std::uint32_t>(nodes_.size());
    if (!parents_.empty()) {
      Node& p = nodes_[parents_.back()];
      p.bounds = merged(p.bounds, nodes_[t].bounds);
    }
  }

  /// A descent's stack: the frames of the nodes entered, their candidates, scratch.
  struct Scratch {
    std::vector<Frame> frames;
    std::vector<Cand> cands;
    std::vector<Cand> filt;
    std::vector<std::int32_t> chain;
    std::vector<std::uint32_t> across, rest;  // a large node's own slots (judge_node)
  };

  /// Enters node k on `sc`'s stack: pops the frames down to its parent's, then pushes its
  /// own with its candidates (the parent's candidates and the parent's own bodies that
  /// overlap its subtree bounds; both sorted by min.x, so the merged list is too).
  void enter(std::size_t k, Scratch& sc) const {
    const Node& node = nodes_[k];
    while (!sc.frames.empty() && sc.frames.back().node != node.parent) {
      sc.cands.resize(sc.frames.back().cbegin);
      sc.frames.pop_back();
    }
    const std::uint32_t cbegin = static_cast<std::uint32_t>(sc.cands.size());
    if (node.parent >= 0) {
      const Frame& pf = sc.frames.back();
      const Node& p = nodes_[node.parent];
      sc.filt.clear();
      for (std::uint32_t c = pf.cbegin; c < pf.cend; ++c) {
        if (overlaps(sc.cands[c].box, node.bounds)) sc.filt.push_back(sc.cands[c]);
      }
      std::size_t a = 0;
      for (std::uint32_t j = p.begin; j < p.end; ++j) {
        if (!overlaps(sorted_[j], node.bounds)) continue;
        while (a < sc.filt.size() && sc.filt[a].box.min.x <= sorted_[j].min.x) sc.cands.push_back(sc.filt[a++]);
        sc.cands.push_back({sorted_[j], items_[j].body});
      }
      while (a < sc.filt.size()) sc.cands.push_back(sc.filt[a++]);
    }
    sc.frames.push_back({static_cast<std::int32_t>(k), cbegin, static_cast<std::uint32_t>(sc.cands.size())});
  }

  /// The pairs of node k (entered on `sc`, its frame on top) into `out`: its own bodies by
  /// sweep and prune on x, and against its ancestor candidates by a two-list sweep on x (a
  /// pair met from whichever has the smaller min.x, own first on ties). Returns the node's
  /// cell candidates (all pairs in related nodes).
  std::uint64_t judge_node(std::size_t k, Scratch& sc, std::vector<Pair>& out) const {
    const Node& node = nodes_[k];
    const std::uint32_t cbegin = sc.frames.back().cbegin, cend = sc.frames.back().cend;
    const std::uint64_t pop = node.end - node.begin;
    if (pop >= kSplitOwnFrom) {
      own_pairs_split(node, sc, out);
    } else {
      for (std::uint32_t i = node.begin; i < node.end; ++i) {
        const Aabb bi = sorted_[i];
        const std::uint32_t body_i = items_[i].body;
        for (std::uint32_t j = i + 1; j < node.end && sminx_[j] <= bi.max.x; ++j) {
          if (overlaps_all_axes(bi, sorted_[j])) emit(body_i, items_[j].body, out);
        }
      }
    }
    std::uint32_t i = node.begin, c = cbegin;
    while (i < node.end && c < cend) {
      if (sminx_[i] <= sc.cands[c].box.min.x) {
        const Aabb bi = sorted_[i];
        for (std::uint32_t q = c; q < cend && sc.cands[q].box.min.x <= bi.max.x; ++q) {
          if (overlaps_all_axes(bi, sc.cands[q].box)) emit(items_[i].body, sc.cands[q].body, out);
        }
        ++i;
      } else {
        const Aabb bc = sc.cands[c].box;
        for (std::uint32_t q = i; q < node.end && sminx_[q] <= bc.max.x; ++q) {
          if (overlaps_all_axes(sorted_[q], bc)) emit(items_[q].body, sc.cands[c].body, out);
        }
        ++c;
      }
    }
    return pop * (pop - 1) / 2 + pop * node.anc_pop;
  }

  /// The pairs among a large node's own bodies. Those spanning its centre plane across x
  /// (spans_centre_x) overlap one another in x, so a sweep on x would test each against all
  /// the others (10^6 uniform boxes put thousands in each of the top nodes): they are swept
  /// on y among themselves, the others on x, and the two sets against each other by a
  /// two-list sweep on x. Each pair once.
  void own_pairs_split(const Node& node, Scratch& sc, std::vector<Pair>& out) const {
    std::vector<std::uint32_t>& across = sc.across;
    std::vector<std::uint32_t>& rest = sc.rest;
    across.clear();
    rest.clear();
    const std::uint64_t key = items_[node.begin].node;
    for (std::uint32_t i = node.begin; i < node.end; ++i)
      (spans_centre_x(grid_, key, sorted_[i]) ? across : rest).push_back(i);
    for (std::size_t a = 0; a < rest.size(); ++a) {  // rest x rest, on x (slots in min.x order)
      const Aabb bi = sorted_[rest[a]];
      for (std::size_t b = a + 1; b < rest.size() && sminx_[rest[b]] <= bi.max.x; ++b) {
        if (overlaps_all_axes(bi, sorted_[rest[b]])) emit(items_[rest[a]].body, items_[rest[b]].body, out);
      }
    }
    std::size_t a = 0, r = 0;  // across x rest, on x
    while (a < across.size() && r < rest.size()) {
      if (sminx_[across[a]] <= sminx_[rest[r]]) {
        const Aabb bi = sorted_[across[a]];
        for (std::size_t q = r; q < rest.size() && sminx_[rest[q]] <= bi.max.x; ++q) {
          if (overlaps_all_axes(bi, sorted_[rest[q]])) emit(items_[across[a]].body, items_[rest[q]].body, out);
        }
        ++a;
      } else {
        const Aabb bi = sorted_[rest[r]];
        for (std::size_t q = a; q < across.size() && sminx_[across[q]] <= bi.max.x; ++q) {
          if (overlaps_all_axes(sorted_[across[q]], bi)) emit(items_[across[q]].body, items_[rest[r]].body, out);
        }
        ++r;
      }
    }
    std::sort(across.begin(), across.end(), [&](std::uint32_t p, std::uint32_t q) {  // across x across, on y
      return sorted_[p].min.y < sorted_[q].min.y || (sorted_[p].min.y == sorted_[q].min.y && p < q);
    });
    for (std::size_t i = 0; i < across.size(); ++i) {
      const Aabb bi = sorted_[across[i]];
      for (std::size_t j = i + 1; j < across.size() && sorted_[across[j]].min.y <= bi.max.y; ++j) {
        if (overlaps_all_axes(bi, sorted_[across[j]])) emit(items_[across[i]].body, items_[across[j]].body, out);
      }
    }
  }

  /// The descents' scratch and pairs (bytes).
  std::size_t scratch_bytes() const {
    std::size_t bytes = 0;
    for (const Scratch& sc : scratch_)
      bytes += sc.frames.capacity() * sizeof(Frame) + (sc.cands.capacity() + sc.filt.capacity()) * sizeof(Cand) +
               (sc.chain.capacity() + sc.across.capacity() + sc.rest.capacity()) * sizeof(std::int32_t);
    for (const std::vector<Pair>& pairs : task_out_) bytes += pairs.capacity() * sizeof(Pair);
    return bytes;
  }

  static void emit(std::uint32_t p, std::uint32_t q, std::vector<Pair>& out) {
    out.push_back(p < q ? Pair{p, q} : Pair{q, p});
  }

  /// Node key of every body with no NaN coordinate (bodies with a NaN never overlap
  /// anything under Eq. 6 and are left out). Keeps the previous order of items_ when the
  /// body set is the same, so that sort_items() can insertion-sort.
  void build_keys(const std::vector<Aabb>& boxes, int depth) {
    const std::size_t n = boxes.size();
    if (items_.size() != n || !all_finite_prev_) {
      items_.resize(n);
      for (std::size_t i = 0; i < n; ++i) items_[i].body = static_cast<std::uint32_t>(i);
      coherent_ = false;
    } else {
      coherent_ = true;
    }
    all_finite_prev_ = true;
    moved_.clear();

    grid_ = strict_grid(domain_, depth);  // shared with the CUDA engine

    // Each item's key on the worker team (reading the boxes in the kept order), then the
    // items kept in order and the moved ones set apart on this thread.
    fresh_.resize(n);
    LoopOptions by_items;
    by_items.min_items = kParallelItemsFrom;
    parallel_for(n, by_items, [&](std::size_t k, unsigned) {
      const std::uint32_t body = items_[k].body;
      const Aabb& b = boxes[body];
      Item& it = fresh_[k];
      it.body = body;
      if (std::isnan(b.min.x) || std::isnan(b.min.y) || std::isnan(b.min.z) ||
          std::isnan(b.max.x) || std::isnan(b.max.y) || std::isnan(b.max.z)) {
        it.node = kNoNode;
        return;
      }
      it.node = strict_node_key(grid_, b);
      it.minx = float_key(b.min.x);
    });
    // Per block of items on the team: its kept and moved counts, then each written to its
    // place (the kept ones in order into items_, the moved ones into moved_): what one pass
    // in order gives. A body that changed node may move far in the order: it is sorted
    // apart and merged (sort_items); a NaN box leaves the item set (rebuilt next time).
    const unsigned threads = loop_threads(n, by_items);
    const std::size_t blocks = threads <= 1 ? 1 : std::size_t(threads) * 8;
    block_kept_.assign(blocks + 1, 0);
    block_moved_.assign(blocks + 1, 0);
    std::atomic<bool> any_nan{false};
    LoopOptions one_each;
    one_each.threads = static_cast<int>(threads);
    one_each.chunk = 1;
    const auto kind = [&](std::size_t k) {  // 0 kept, 1 moved, 2 left out
      const Item& it = fresh_[k];
      if (it.node == kNoNode) return 2;
      return coherent_ && items_[k].node != it.node ? 1 : 0;
    };
    parallel_for(blocks, one_each, [&](std::size_t b, unsigned) {
      std::size_t kept = 0, moved = 0;
      bool nan = false;
      for (std::size_t k = n * b / blocks; k < n * (b + 1) / blocks; ++k) {
        const int what = kind(k);
        kept += what == 0;
        moved += what == 1;
        nan = nan || what == 2;
      }
      block_kept_[b + 1] = kept;
      block_moved_[b + 1] = moved;
      if (nan) any_nan.store(true, std::memory_order_relaxed);
    });
    for (std::size_t b = 0; b < blocks; ++b) {
      block_kept_[b + 1] += block_kept_[b];
      block_moved_[b + 1] += block_moved_[b];
    }
    if (any_nan.load()) all_finite_prev_ = false;
    moved_.resize(block_moved_[blocks]);
    // The kept items go to merge_buf_, then swapped in: items_ holds the old nodes that
    // every block reads meanwhile.
    merge_buf_.resize(block_kept_[blocks]);
    parallel_for(blocks, one_each, [&](std::size_t b, unsigned) {
      std::size_t kept = block_kept_[b], moved = block_moved_[b];
      for (std::size_t k = n * b / blocks; k < n * (b + 1) / blocks; ++k) {
        const int what = kind(k);
        if (what == 0) merge_buf_[kept++] = fresh_[k];
        else if (what == 1) moved_[moved++] = fresh_[k];
      }
    });
    items_.swap(merge_buf_);
  }

  /// Sorts items_ by (node, min.x, body): when the previous order is available (coherent
  /// motion), insertion sort in runs cut at node boundaries on the team, falling back to
  /// parallel_sort past a run's budget of moves; the moved items sorted and merged in.
  void sort_items() {
    const std::size_t m = items_.size();
    LoopOptions by_items;
    by_items.min_items = kParallelItemsFrom;
    const unsigned threads = loop_threads(m, by_items);
    bool ok = coherent_;
    if (ok) {
      // The kept items' nodes are still in order (a body that changed node was set apart):
      // only min.x can be out of order, within a node. So runs cut at node boundaries are
      // sorted on their own, on the team, each by insertion within a budget of moves.
      const std::size_t runs = threads <= 1 ? 1 : std::size_t(threads) * 8;
      run_start_.assign(runs + 1, m);
      run_start_[0] = 0;
      for (std::size_t r = 1; r < runs; ++r) {
        std::size_t g = std::max(run_start_[r - 1], m * r / runs);
        while (g > 0 && g < m && items_[g].node == items_[g - 1].node) ++g;
        run_start_[r] = g;
      }
      std::atomic<bool> within{true};
      LoopOptions one_each;
      one_each.threads = static_cast<int>(threads);
      one_each.chunk = 1;
      parallel_for(runs, one_each, [&](std::size_t r, unsigned) {
        const std::size_t lo = run_start_[r], hi = run_start_[r + 1];
        std::size_t budget = 8 * (hi - lo) + 64;
        for (std::size_t i = lo + 1; i < hi; ++i) {
          const Item x = items_[i];
          std::size_t j = i;
          while (j > lo && item_less(x, items_[j - 1])) {
            items_[j] = items_[j - 1];
            --j;
            if (--budget == 0) {
              items_[j] = x;
              within.store(false, std::memory_order_relaxed);
              return;
            }
          }
          items_[j] = x;
        }
      });
      ok = within.load();
    }
    if (!ok) parallel_sort(items_, threads, item_less);
    if (!moved_.empty()) {
      std::sort(moved_.begin(), moved_.end(), item_less);
      merge_buf_.resize(m + moved_.size());
      std::merge(items_.begin(), items_.end(), moved_.begin(), moved_.end(), merge_buf_.begin(),
                 item_less);
      items_.swap(merge_buf_);
    }
  }

  int depth_cfg_;
  Aabb domain_;
  bool coherent_ = false;
  bool all_finite_prev_ = true;
  std::vector<Item> items_;
  std::vector<Item> moved_;
  std::vector<Item> fresh_;  // each item's key this call, in the kept order
  std::vector<Item> merge_buf_;
  std::vector<std::size_t> block_kept_;   // build_keys' blocks: kept items before each
  std::vector<std::size_t> block_moved_;  // and moved items before each
  std::vector<std::size_t> run_start_;  // sort_items' runs: [run_start_[r], run_start_[r + 1])
  std::vector<Aabb> sorted_;
  std::vector<float> sminx_;
  StrictGrid grid_;  // this call's leaf grid (build_keys)
  std::vector<Node> nodes_;
  std::vector<std::int32_t> parents_;
  std::vector<std::uint32_t> task_roots_;
  std::vector<std::uint32_t> above_;      // the nodes above the subtrees' roots, in pre-order
  std::vector<std::uint32_t> above_run_;  // the runs of above_ judged as one task each
  std::vector<std::vector<Pair>> task_out_;
  std::vector<Scratch> scratch_;
  std::vector<Pair> tmp_pairs_;
  std::vector<std::uint32_t> count_;
};

}  // namespace

namespace detail {

std::unique_ptr<BroadPhase> make_host_octree_strict(const BroadPhaseConfig& config, const Aabb& domain) {
  return std::make_unique<StrictOctreeBroadPhase>(config.octree_depth, domain);
}

}  // namespace detail

}  // namespace octocd
