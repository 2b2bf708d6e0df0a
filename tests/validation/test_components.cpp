// The validators' components and grouping (validation/src/components.hpp) against oracles:
// a breadth-first search of the same graph labels each node with its component's lowest
// node, and a serial stable pass groups the items; the same answer on 1, 2, 3 and 8 threads.
#include <gtest/gtest.h>

#include <algorithm>
#include <queue>
#include <random>
#include <vector>

#include "octocd/broadphase.hpp"
#include "../../validation/src/components.hpp"

namespace octocd {
namespace octocd_test_components {
namespace {

/// Each node's lowest connected node, by breadth-first search from the nodes in order.
std::vector<std::uint32_t> lowest_by_search(std::size_t n, const std::vector<Pair>& edges) {
  std::vector<std::vector<std::uint32_t>> adj(n);
  for (const Pair& e : edges) {
    adj[e.a].push_back(e.b);
    adj[e.b].push_back(e.a);
  }
  const std::uint32_t none = 0xffffffffu;
  std::vector<std::uint32_t> label(n, none);
  for (std::uint32_t s = 0; s < n; ++s) {
    if (label[s] != none) continue;
    std::queue<std::uint32_t> q;
    q.push(s);
    label[s] = s;  // the first node reached in ascending order is the lowest
    while (!q.empty()) {
      const std::uint32_t i = q.front();
      q.pop();
      for (std::uint32_t j : adj[i])
        if (label[j] == none) {
          label[j] = s;
          q.push(j);
        }
    }
  }
  return label;
}

/// Graphs of n nodes: chains in reverse and shuffled order (long paths for the finds), random
/// sparse links, a star on the highest node, self-links and repeated links.
std::vector<std::vector<Pair>> graphs(std::size_t n, std::mt19937& rng) {
  std::vector<std::vector<Pair>> out(4);
  for (std::uint32_t i = std::uint32_t(n) - 1; i > 0; --i) out[0].push_back({i, i - 1});
  out[1] = out[0];
  std::shuffle(out[1].begin(), out[1].end(), rng);
  for (std::size_t k = 0; k < n / 2; ++k) out[2].push_back({std::uint32_t(rng() % n), std::uint32_t(rng() % n)});
  for (std::uint32_t i = 0; i + 1 < n; i += 3) out[3].push_back({std::uint32_t(n - 1), i});
  out[3].push_back({5, 5});
  out[3].push_back({std::uint32_t(n - 1), 0});
  return out;
}

TEST(Components, EveryRootIsItsComponentsLowestNodeOnAnyThreadCount) {
  std::mt19937 rng(11);
  for (std::size_t n : {std::size_t(7), std::size_t(100), std::size_t(40000)}) {
    for (const std::vector<Pair>& edges : graphs(n, rng)) {
      const std::vector<std::uint32_t> want = lowest_by_search(n, edges);
      Components c;
      for (unsigned threads : {1u, 2u, 3u, 8u}) {
        c.reset(n, threads, {});  // the same object: reset must forget the last graph
        c.join_all(edges.size(), threads, {}, [](std::size_t) { return true; }, [&](std::size_t k) { return edges[k]; });
        c.settle(threads, {});
        for (std::uint32_t i = 0; i < n; ++i) {
          ASSERT_EQ(c.root(i), want[i]) << n << " nodes, " << edges.size() << " edges, " << threads << " threads, node " << i;
          ASSERT_EQ(c.find(i), want[i]);
        }
      }
    }
  }
}

TEST(Components, JoinAllSkipsTheEdgesNotKept) {
  const std::vector<Pair> edges{{0, 1}, {1, 2}, {2, 3}, {3, 4}};
  Components c;
  c.reset(5, 1, {});
  c.join_all(edges.size(), 1, {}, [](std::size_t k) { return k != 1; }, [&](std::size_t k) { return edges[k]; });
  c.settle(1, {});
  EXPECT_EQ(c.root(1), 0u);
  EXPECT_EQ(c.root(2), 2u);  // {1, 2} not kept: 2 starts its own component
  EXPECT_EQ(c.root(4), 2u);
}

TEST(GroupItems, AStableCountingSortByGroupOnAnyThreadCount) {
  std::mt19937 rng(3);
  GroupScratch scratch;
  // Few groups (one of 40,000 items: sorted by parallel_sort), many groups, items in none.
  for (std::size_t groups : {std::size_t(1), std::size_t(3), std::size_t(20000)}) {
    const std::size_t n = 40000;
    std::vector<std::size_t> key(n);
    for (std::size_t& k : key) k = rng() % (groups + 1);  // == groups: in no group
    std::vector<std::vector<std::uint32_t>> want(groups);
    for (std::size_t k = 0; k < n; ++k)
      if (key[k] < groups) want[key[k]].push_back(std::uint32_t(k));
    for (unsigned threads : {1u, 2u, 3u, 8u}) {
      GroupedItems got;
      group_items(n, groups, threads, {}, [&](std::size_t k) { return key[k]; }, scratch, got);
      ASSERT_EQ(got.groups(), groups);
      for (std::size_t g = 0; g < groups; ++g) {
        ASSERT_EQ(got.size(g), want[g].size()) << groups << " groups, " << threads << " threads, group " << g;
        ASSERT_TRUE(std::equal(got.begin(g), got.end(g), want[g].begin())) << "group " << g << ", " << threads << " threads";
      }
    }
  }
}

}  // namespace
}  // namespace octocd_test_components
}  // namespace octocd
