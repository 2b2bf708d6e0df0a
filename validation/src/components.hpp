#pragma once
/// \file components.hpp
/// The validators' connected components of a contact graph, and their items grouped per
/// component, on threads (internal to octocd_validation; docs/validation.md, "Validation
/// at scale", Groups and islands). Conservation's isolated groups and applied-state's and
/// impulse-feasibility's islands are components of this kind: bodies joined by contact
/// pairs.
///
/// - Components: a union-find whose unions run on any number of threads at once. A union
///   links the larger of the two roots under the smaller by compare-and-swap (linking by
///   index: a parent is never above its child, so no cycle can form and a failed swap only
///   retries with the new roots), and finds halve the path they walk. Every root is
///   therefore the lowest node of its component, whatever order the threads joined in: the
///   components, their roots and every order derived from them do not depend on the thread
///   count.
/// - group_items: items (bodies, contacts) gathered per group, the groups in ascending key
///   order and each group's items in ascending item order (what one pass of a stable
///   counting sort by group gives), counted and placed on threads.

#include <algorithm>
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <vector>

#include "parallel.hpp"

namespace octocd {

/// The fewest items that a union, root or grouping pass runs on threads (a few memory
/// accesses an item: below this, waking a thread costs more than the pass).
constexpr std::size_t kParallelComponentsFrom = 16384;

/// Connected components of an undirected graph on the nodes [0, n), each named by its
/// lowest node (its root). Holds its n parents, marks and, once settled, roots; reset()
/// reuses their memory for the next frame's graph. Node indices are uint32 (the
/// validators' body indices).
class Components {
 public:
  /// Starts n singleton components (each node its own root), on `threads` threads.
  /// Throws ValidationStopped when `stop` returns true (the components then mean nothing).
  /// No node is marked.
  void reset(std::size_t n, unsigned threads, const std::function<bool()>& stop) {
    if (n > capacity_) {
      parent_.reset(new std::atomic<std::uint32_t>[n]);
      marked_.reset(new std::atomic<std::uint8_t>[n]);
      capacity_ = n;
    }
    n_ = n;
    parallel_ranges(n, n >= kParallelComponentsFrom ? threads : 1u, stop, [&](std::size_t first, std::size_t last) {
      for (std::size_t i = first; i < last; ++i) {
        parent_[i].store(std::uint32_t(i), std::memory_order_relaxed);
        marked_[i].store(0, std::memory_order_relaxed);
      }
    });
  }

  /// Marks node i (a body of a contact pair, joined or not); safe from many threads at once.
  void mark(std::uint32_t i) { marked_[i].store(1, std::memory_order_relaxed); }

  /// Whether node i was marked since reset() (read once the marking loop is done).
  bool marked(std::uint32_t i) const { return marked_[i].load(std::memory_order_relaxed) != 0; }

  /// The root of node i (i < size()): its component's lowest node once every join is done.
  /// Safe beside other finds and joins on other threads (it shortens the path it walks).
  std::uint32_t find(std::uint32_t i) const {
    for (;;) {
      const std::uint32_t p = parent_[i].load(std::memory_order_relaxed);
      if (p == i) return i;
      const std::uint32_t gp = parent_[p].load(std::memory_order_relaxed);
      // Path halving: i's parent becomes its grandparent (an ancestor: i is no root, so
      // no union writes its parent again; a concurrent halving writes another ancestor).
      if (gp != p) parent_[i].store(gp, std::memory_order_relaxed);
      i = gp;
    }
  }

  /// Joins the components of nodes a and b (both < size()); safe from many threads at once.
  void join(std::uint32_t a, std::uint32_t b) {
    for (;;) {
      a = find(a);
      b = find(b);
      if (a == b) return;
      if (a < b) std::swap(a, b);  // a, the larger root, goes under b
      std::uint32_t expected = a;
      if (parent_[a].compare_exchange_strong(expected, b, std::memory_order_relaxed)) return;
      // a stopped being a root meanwhile: retry from the roots as they are now.
    }
  }

  /// Calls join(edge(k)) for every k in [0, edges) with keep(k) on `threads` threads
  /// (keep called once for every k, from any thread; `edge` returns a Pair-like value with
  /// members a and b, called for the edges kept). ValidationStopped on a stop.
  template <class Keep, class Edge>
  void join_all(std::size_t edges, unsigned threads, const std::function<bool()>& stop, Keep&& keep, Edge&& edge) {
    const unsigned edge_threads = edges >= kParallelComponentsFrom ? threads : 1u;
    parallel_ranges(edges, edge_threads, stop, [&](std::size_t first, std::size_t last) {
      for (std::size_t k = first; k < last; ++k) {
        if (!keep(k)) continue;
        const auto e = edge(k);
        join(e.a, e.b);
      }
    });
  }

  /// Once every join is done: each node's root found on `threads` threads and kept, so
  /// that root() reads it in one step. The roots go to an array of their own: a find's
  /// halving on one thread may write an ancestor that is not the root into a parent that
  /// another thread has just settled. ValidationStopped on a stop.
  void settle(unsigned threads, const std::function<bool()>& stop) {
    root_.resize(n_);
    parallel_ranges(n_, n_ >= kParallelComponentsFrom ? threads : 1u, stop, [&](std::size_t first, std::size_t last) {
      for (std::size_t i = first; i < last; ++i) root_[i] = find(std::uint32_t(i));
    });
  }

  /// Node i's root after settle() (its component's lowest node).
  std::uint32_t root(std::uint32_t i) const { return root_[i]; }

  /// Every node's root after settle(), indexed by node.
  const std::vector<std::uint32_t>& roots() const { return root_; }

 private:
  std::unique_ptr<std::atomic<std::uint32_t>[]> parent_;
  std::unique_ptr<std::atomic<std::uint8_t>[]> marked_;
  std::vector<std::uint32_t> root_;
  std::size_t n_ = 0, capacity_ = 0;
};

/// Items grouped: group g's items are items[first[g] .. first[g + 1]), ascending.
struct GroupedItems {
  std::vector<std::size_t> first;      ///< groups + 1 offsets into items
  std::vector<std::uint32_t> items;    ///< item indices, group by group
  /// The group count.
  std::size_t groups() const { return first.empty() ? 0 : first.size() - 1; }
  /// Group g's item count.
  std::size_t size(std::size_t g) const { return first[g + 1] - first[g]; }
  /// Group g's first item (a pointer into items) and one past its last.
  const std::uint32_t* begin(std::size_t g) const { return items.data() + first[g]; }
  const std::uint32_t* end(std::size_t g) const { return items.data() + first[g + 1]; }
  /// Group g's items, for a range-based for.
  struct Range {
    const std::uint32_t *first, *last;
    const std::uint32_t* begin() const { return first; }
    const std::uint32_t* end() const { return last; }
  };
  Range group(std::size_t g) const { return {begin(g), end(g)}; }
};

/// Scratch that group_items reuses from call to call (one per caller; not shared between
/// threads).
struct GroupScratch {
  std::unique_ptr<std::atomic<std::uint32_t>[]> count;
  std::size_t capacity = 0;
};

/// Groups the items [0, n) by group(k) (a group number below `groups`, or `groups` and
/// above for an item in no group): `out` holds each group's items ascending, the groups in
/// ascending order (a stable counting sort by group), counted and placed on `threads`
/// threads with atomic counters, then each group put in item order (groups of fewer than
/// 4,096 items sorted on the threads, block by block of groups; larger ones each by
/// parallel_sort). Items are uint32. ValidationStopped on a stop.
template <class Group>
void group_items(std::size_t n, std::size_t groups, unsigned threads, const std::function<bool()>& stop,
                 Group&& group, GroupScratch& scratch, GroupedItems& out) {
  if (groups > scratch.capacity) {
    scratch.count.reset(new std::atomic<std::uint32_t>[groups]);
    scratch.capacity = groups;
  }
  std::atomic<std::uint32_t>* const count = scratch.count.get();
  const unsigned item_threads = n >= kParallelComponentsFrom ? threads : 1u;
  const unsigned group_threads = groups >= kParallelComponentsFrom ? threads : 1u;
  parallel_ranges(groups, group_threads, stop, [&](std::size_t first, std::size_t last) {
    for (std::size_t g = first; g < last; ++g) count[g].store(0, std::memory_order_relaxed);
  });
  parallel_ranges(n, item_threads, stop, [&](std::size_t first, std::size_t last) {
    for (std::size_t k = first; k < last; ++k) {
      const std::size_t g = group(k);
      if (g < groups) count[g].fetch_add(1, std::memory_order_relaxed);
    }
  });
  // Each group's first item: the counts summed per block of groups, the blocks' offsets in
  // order, then each block's groups from its offset; each count becomes its group's cursor.
  out.first.resize(groups + 1);
  const std::size_t blocks = group_threads > 1 ? std::min<std::size_t>(groups, std::size_t(group_threads) * 8) : 1;
  std::vector<std::size_t> block_first(blocks + 1, 0);
  auto block_begin = [&](std::size_t b) { return groups * b / blocks; };
  parallel_items_on(blocks, group_threads, stop, [&](std::size_t b, unsigned) {
    std::size_t sum = 0;
    for (std::size_t g = block_begin(b); g < block_begin(b + 1); ++g) sum += count[g].load(std::memory_order_relaxed);
    block_first[b + 1] = sum;
  });
  for (std::size_t b = 0; b < blocks; ++b) block_first[b + 1] += block_first[b];
  parallel_items_on(blocks, group_threads, stop, [&](std::size_t b, unsigned) {
    std::size_t at = block_first[b];
    for (std::size_t g = block_begin(b); g < block_begin(b + 1); ++g) {
      out.first[g] = at;
      at += count[g].load(std::memory_order_relaxed);
      count[g].store(std::uint32_t(out.first[g]), std::memory_order_relaxed);  // now its cursor
    }
  });
  out.first[groups] = block_first[blocks];
  out.items.resize(out.first[groups]);
  parallel_ranges(n, item_threads, stop, [&](std::size_t first, std::size_t last) {
    for (std::size_t k = first; k < last; ++k) {
      const std::size_t g = group(k);
      if (g < groups) out.items[count[g].fetch_add(1, std::memory_order_relaxed)] = std::uint32_t(k);
    }
  });
  // Each group in item order (the atomic cursors placed them in the threads' order): the
  // groups of fewer than 4,096 items in each block of groups on the threads, the larger
  // ones, listed per block, then each by parallel_sort.
  constexpr std::size_t kSortedOnTheTeamFrom = 4096;
  std::uint32_t* const items = out.items.data();
  std::vector<std::vector<std::size_t>> big(blocks);
  parallel_items_on(blocks, group_threads, stop, [&](std::size_t b, unsigned) {
    for (std::size_t g = block_begin(b); g < block_begin(b + 1); ++g) {
      if (std::is_sorted(items + out.first[g], items + out.first[g + 1])) continue;
      if (out.size(g) < kSortedOnTheTeamFrom)
        std::sort(items + out.first[g], items + out.first[g + 1]);
      else
        big[b].push_back(g);
    }
  });
  std::vector<std::uint32_t> sorted;
  for (const std::vector<std::size_t>& list : big)
    for (const std::size_t g : list) {
      sorted.assign(out.begin(g), out.end(g));
      parallel_sort(sorted, threads, std::less<std::uint32_t>());
      std::copy(sorted.begin(), sorted.end(), items + out.first[g]);
    }
}

}  // namespace octocd
