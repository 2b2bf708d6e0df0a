// exact_pairs (octocd/exact_pairs.hpp) against the `flat` oracle: the same pair set,
// compared as sorted vectors, on random and adversarial boxes.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <vector>

#include "octocd/broadphase.hpp"
#include "octocd/exact_pairs.hpp"
#include "../../validation/src/parallel.hpp"

namespace octocd {
namespace octocd_test_exact_pairs {
namespace {

std::vector<Pair> flat_pairs(const std::vector<Aabb>& boxes) {
  BroadPhaseConfig cfg;
  cfg.name = "flat";
  auto flat = make_broadphase(cfg, Aabb{{-1, -1, -1}, {1, 1, 1}});
  std::vector<Pair> out;
  BroadPhaseStats st;
  flat->find_pairs(boxes, out, st);
  return out;
}

void expect_same(const std::vector<Aabb>& boxes, const char* what) {
  const std::vector<Pair> want = flat_pairs(boxes);
  for (int threads : {1, 2, 3}) {
    ExactPairsSettings s;
    s.threads = threads;
    std::vector<Pair> got{{7, 9}};  // cleared by the call
    exact_pairs(boxes, got, s);
    ASSERT_EQ(got.size(), want.size()) << what << ", " << threads << " threads";
    for (std::size_t k = 0; k < got.size(); ++k)
      ASSERT_TRUE(got[k] == want[k]) << what << ": pair " << k << " (" << got[k].a << ", " << got[k].b << ") vs ("
                                     << want[k].a << ", " << want[k].b << ")";
  }
}

Aabb box(float x, float y, float z, float hx, float hy, float hz) { return {{x - hx, y - hy, z - hz}, {x + hx, y + hy, z + hz}}; }

TEST(ExactPairs, RandomBoxesOfMixedSizes) {
  std::mt19937 rng(1234);
  std::uniform_real_distribution<float> pos(-10, 10), size(0.01f, 0.6f), u(0, 1);
  for (int round = 0; round < 6; ++round) {
    std::vector<Aabb> boxes;
    const int n = 300 + 250 * round;
    for (int i = 0; i < n; ++i) {
      float h = size(rng);
      if (u(rng) < 0.05f) h *= 30;    // a few large boxes (coarser levels)
      if (u(rng) < 0.05f) h *= 1e-4f;  // and tiny ones
      boxes.push_back(box(pos(rng), pos(rng), pos(rng), h, h * u(rng) + 1e-6f, h));
    }
    ASSERT_GT(flat_pairs(boxes).size(), std::size_t(n) / 4) << "the boxes meet: the test compares real pairs";
    expect_same(boxes, "random");
  }
}

TEST(ExactPairs, TouchingFacesAndSharedCoordinates) {
  // A lattice of unit boxes whose faces, edges and corners touch exactly (inclusive
  // overlap: every neighbour, diagonal ones included, is a pair), coordinates on a few
  // values only, plus coincident copies and zero-size boxes on the faces.
  std::vector<Aabb> boxes;
  for (int x = 0; x < 7; ++x)
    for (int y = 0; y < 5; ++y)
      for (int z = 0; z < 6; ++z) boxes.push_back({{float(x), float(y), float(z)}, {float(x + 1), float(y + 1), float(z + 1)}});
  const std::size_t lattice = boxes.size();
  for (std::size_t i = 0; i < lattice; i += 3) boxes.push_back(boxes[i]);  // coincident
  for (int x = 0; x <= 7; ++x) boxes.push_back({{float(x), 2, 3}, {float(x), 2, 3}});  // points on corners
  boxes.push_back({{3, 0, 0}, {3, 5, 6}});  // a flat plate on a face plane
  const std::vector<Pair> want = flat_pairs(boxes);
  // Box (0,0,0) meets its 7 neighbours of the 2x2x2 block by faces, edges and a corner.
  std::size_t of_first = 0;
  for (const Pair& p : want) of_first += p.a == 0 && p.b < lattice;
  EXPECT_EQ(of_first, 7u);
  expect_same(boxes, "lattice");
  // The same lattice shifted off the origin by a non-representable step, and scaled
  // small (cells of the grid then fall between the floats).
  for (Aabb& b : boxes)
    for (int k = 0; k < 3; ++k) {
      b.min[k] = b.min[k] * 1e-3f + 0.1f;
      b.max[k] = b.max[k] * 1e-3f + 0.1f;
    }
  expect_same(boxes, "scaled lattice");
}

TEST(ExactPairs, HugeTinyCoincidentAndDegenerateBoxes) {
  std::mt19937 rng(99);
  std::uniform_real_distribution<float> pos(-5, 5);
  std::vector<Aabb> boxes;
  // 1,000 tiny boxes: with the rest over 1,024 boxes, so the passes over the unbounded and
  // huge boxes run on threads (exact_pairs.cpp's kParallelBoxesFrom) at 2 and 3 threads.
  for (int i = 0; i < 1000; ++i) boxes.push_back(box(pos(rng), pos(rng), pos(rng), 1e-7f, 1e-7f, 1e-7f));  // tiny
  for (int i = 0; i < 40; ++i) boxes.push_back(box(0, 0, 0, 0.3f, 0.3f, 0.3f));  // coincident
  boxes.push_back(box(0, 0, 0, 1e6f, 1e6f, 1e6f));  // huge: meets all
  boxes.push_back(box(3, 0, 0, 1e30f, 1e-3f, 1e30f));  // huge slab
  const float inf = std::numeric_limits<float>::infinity(), nan = std::numeric_limits<float>::quiet_NaN();
  boxes.push_back({{-inf, -inf, -inf}, {inf, inf, inf}});  // unbounded
  boxes.push_back({{-inf, 1, 1}, {inf, 1.5f, 1.5f}});      // an infinite rod
  boxes.push_back({{-inf, 1, 1}, {inf, 1.5f, 1.5f}});      // and its copy
  boxes.push_back({{inf, inf, inf}, {inf, inf, inf}});     // a point at infinity
  boxes.push_back({{nan, 0, 0}, {1, 1, 1}});               // NaN: overlaps nothing in flat
  boxes.push_back({{0, 0, 0}, {1, 1, nan}});
  boxes.push_back({{1, 1, 1}, {-1, -1, -1}});  // inverted (min > max)
  boxes.push_back({{0.5f, -1, -1}, {0.2f, 1, 1}});  // inverted on x only
  boxes.push_back({{0.2f, 0.2f, 0.2f}, {0.2f, 0.2f, 0.2f}});  // a point
  boxes.push_back({{-0.0f, 0, 0}, {0.0f, 0, 0}});  // signed zeros
  boxes.push_back(box(1e30f, 1e30f, 1e30f, 1e25f, 1e25f, 1e25f));  // far away
  boxes.push_back(box(1e30f, 1e30f, 1e30f, 1.0f, 1.0f, 1.0f));
  expect_same(boxes, "adversarial");
}

TEST(ExactPairs, AllPointsAndAllCoincident) {
  std::vector<Aabb> points;
  for (int i = 0; i < 500; ++i) {
    const float x = float(i % 10), y = float((i / 10) % 10), z = float(i / 100);
    points.push_back({{x, y, z}, {x, y, z}});
  }
  expect_same(points, "points (zero median extent)");
  std::vector<Aabb> same(300, box(1, 2, 3, 0.5f, 0.5f, 0.5f));
  expect_same(same, "all coincident");
  expect_same({}, "none");
  expect_same({box(0, 0, 0, 1, 1, 1)}, "one");
}

// Enough boxes and pairs (over 4,096 cell entries and pairs) that their sorts run on
// threads (parallel_sort): the same set as flat on 1, 2 and 3 threads.
TEST(ExactPairs, ManyPairsSortedOnThreads) {
  std::mt19937 rng(99);
  std::uniform_real_distribution<float> pos(-4, 4), size(0.1f, 0.3f);
  std::vector<Aabb> boxes;
  for (int i = 0; i < 5000; ++i) {
    const float h = size(rng);
    boxes.push_back(box(pos(rng), pos(rng), pos(rng), h, h, h));
  }
  ASSERT_GT(flat_pairs(boxes).size(), 8192u);
  expect_same(boxes, "many pairs");
}

// parallel_sort orders as std::sort on any thread count, below and above the size it
// sorts on threads from, with and without repeated values.
TEST(ParallelSort, SameOrderAsStdSort) {
  std::mt19937 rng(5);
  for (std::size_t n : {std::size_t(0), std::size_t(1), std::size_t(4095), std::size_t(4096), std::size_t(10007),
                        std::size_t(50000)}) {
    for (std::uint32_t spread : {7u, 1000000u}) {
      std::vector<Pair> v(n);
      for (Pair& p : v) p = {std::uint32_t(rng() % spread), std::uint32_t(rng() % spread)};
      std::vector<Pair> want = v;
      std::sort(want.begin(), want.end());
      for (unsigned threads : {1u, 2u, 3u, 5u, 8u}) {
        std::vector<Pair> got = v;
        parallel_sort(got, threads, [](Pair p, Pair q) { return p < q; });
        ASSERT_EQ(got.size(), n);
        EXPECT_TRUE(std::equal(got.begin(), got.end(), want.begin(), [](Pair p, Pair q) { return p == q; }))
            << n << " pairs, values below " << spread << ", " << threads << " threads";
      }
    }
  }
}

// ---- the validators' limit (ExactPairsSettings::max_pairs_per_body) ---------------------

/// n unit boxes at the origin: every pair overlaps, each in the same 8 cells of the grid.
std::vector<Aabb> coincident(std::size_t n) { return std::vector<Aabb>(n, Aabb{{-0.5f, -0.5f, -0.5f}, {0.5f, 0.5f, 0.5f}}); }

ExactPairsSettings limited() {
  ExactPairsSettings s;
  s.max_pairs_per_body = limits::kMaxPairsPerBody;
  return s;
}

// Coincident boxes are refused from their cells' occupancy, before any pair is tested or
// kept: 129 boxes make 8,256 pairs (64 a body, the limit) and 8 x 8,256 tests; 130 make
// 8,385 pairs, 67,080 tests, above 8 x 64 x 130 = 66,560.
TEST(ExactPairs, TheLimitRefusesCrowdedBoxesFromTheirCellCounts) {
  std::vector<Pair> out;
  exact_pairs(coincident(129), out, limited());
  EXPECT_EQ(out.size(), 129u * 128u / 2u);
  try {
    exact_pairs(coincident(130), out, limited());
    FAIL() << "130 coincident boxes accepted";
  } catch (const PairLimitError& e) {
    EXPECT_TRUE(e.tests);
    EXPECT_EQ(e.count, 8u * 130u * 129u / 2u);
    EXPECT_EQ(e.limit, 8u * 64u * 130u);
    EXPECT_EQ(e.bodies, 130u);
    EXPECT_STREQ(e.what(), "130 bodies' boxes crowd together: 67080 candidate pair tests (boxes sharing a grid "
                           "cell), more than the limit 66560 (8 tests for each of 64 pairs a body); allowed: at "
                           "most 64 overlapping pairs a body (coincident or piled-up bodies are refused)");
  }
  // 300,000 coincident boxes: 3.6e11 tests counted, none made (the grid's 2.4 million
  // cell entries are all that is allocated).
  EXPECT_THROW(exact_pairs(coincident(300000), out, limited()), PairLimitError);
  // Without a limit (the default), every pair.
  exact_pairs(coincident(200), out);
  EXPECT_EQ(out.size(), 200u * 199u / 2u);
}

// Boxes of another level count too: many small boxes inside one large box each meet the
// large ones through their lookups (step 2), so 300 large boxes over 3,000 small ones
// (900,000 pairs, 273 a body) are refused as well.
TEST(ExactPairs, TheLimitCountsPairsAcrossLevels) {
  std::vector<Aabb> boxes;
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> u(-4.0f, 4.0f);
  for (int i = 0; i < 3000; ++i) {
    const Vec3 c{u(rng), u(rng), u(rng)};
    boxes.push_back({c - Vec3{0.05f, 0.05f, 0.05f}, c + Vec3{0.05f, 0.05f, 0.05f}});
  }
  for (int i = 0; i < 300; ++i) boxes.push_back({{-5, -5, -5}, {5, 5, 5}});
  std::vector<Pair> out;
  EXPECT_THROW(exact_pairs(boxes, out, limited()), PairLimitError);
  // 10 large boxes (30,045 pairs, 9 a body) are within it, and the set is flat's.
  boxes.resize(3010);
  exact_pairs(boxes, out, limited());
  EXPECT_EQ(out, flat_pairs(boxes));
}

// A frame as dense as real runs get (bench_validation --lattice: every box overlaps its 26
// neighbours, 13 pairs a body) is far within the limit, and the set is flat's.
TEST(ExactPairs, ALatticeOfTouchingBoxesIsWithinTheLimit) {
  std::vector<Aabb> boxes;
  for (int x = 0; x < 12; ++x)
    for (int y = 0; y < 12; ++y)
      for (int z = 0; z < 12; ++z) {
        const Vec3 c{0.19f * float(x), 0.19f * float(y), 0.19f * float(z)};
        boxes.push_back({c - Vec3{0.1f, 0.1f, 0.1f}, c + Vec3{0.1f, 0.1f, 0.1f}});
      }
  std::vector<Pair> out;
  exact_pairs(boxes, out, limited());
  EXPECT_EQ(out, flat_pairs(boxes));
  EXPECT_GT(out.size(), 10u * boxes.size());  // 26 neighbours inside, fewer on the faces
}

// One ExactPairsTables kept across calls (as the validators keep it from frame to frame):
// each call gives flat's set whatever the call before left in the tables (more or fewer
// boxes, levels, unbounded boxes and pairs, a refusal by the limit), on 1, 2 and 3 threads.
TEST(ExactPairs, KeptTablesGiveFlatsSetAfterAnyEarlierCall) {
  std::mt19937 rng(11);
  std::uniform_real_distribution<float> pos(-6, 6), size(0.05f, 0.4f), u(0, 1);
  auto scene = [&](int n, float huge_share) {  // at one density: the domain grows with n
    const float k = std::cbrt(float(n) / 3000.0f);
    std::vector<Aabb> boxes;
    for (int i = 0; i < n; ++i) {
      float h = size(rng);
      if (u(rng) < huge_share) h *= 20;  // coarser levels
      boxes.push_back(box(k * pos(rng), k * pos(rng), k * pos(rng), h, h, h * u(rng) + 1e-4f));
    }
    return boxes;
  };
  const float inf = std::numeric_limits<float>::infinity(), nan = std::numeric_limits<float>::quiet_NaN();
  std::vector<std::vector<Aabb>> calls = {scene(3000, 0.02f), scene(400, 0.0f), scene(2500, 0.1f)};
  calls[1].push_back({{-inf, -1, -1}, {inf, 1, 1}});  // an unbounded rod
  calls[1].push_back({{nan, 0, 0}, {1, 1, 1}});
  calls.push_back(coincident(200));  // refused with the limit
  calls.push_back(scene(1500, 0.05f));
  for (int threads : {1, 2, 3}) {
    ExactPairsTables tables;
    ExactPairsSettings s = limited();
    s.threads = threads;
    for (std::size_t c = 0; c < calls.size(); ++c) {
      std::vector<Pair> got{{7, 9}};  // cleared by the call
      if (c == 3) {
        EXPECT_THROW(exact_pairs(calls[c], got, s, tables), PairLimitError);
        continue;
      }
      exact_pairs(calls[c], got, s, tables);
      const std::vector<Pair> want = flat_pairs(calls[c]);
      ASSERT_GT(want.size(), calls[c].size() / 4) << "call " << c << ": the boxes meet";
      EXPECT_EQ(got, want) << "call " << c << ", " << threads << " threads";
    }
  }
}

TEST(ExactPairs, BroadPhaseAdapterMatchesFlat) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> pos(-3, 3);
  std::vector<Aabb> boxes;
  for (int i = 0; i < 400; ++i) boxes.push_back(box(pos(rng), pos(rng), pos(rng), 0.2f, 0.2f, 0.2f));
  auto bp = make_exact_pairs_broadphase();
  EXPECT_EQ(bp->name(), "exact-grid");
  std::vector<Pair> got;
  BroadPhaseStats st;
  bp->find_pairs(boxes, got, st);
  const std::vector<Pair> want = flat_pairs(boxes);
  ASSERT_EQ(got.size(), want.size());
  EXPECT_TRUE(std::equal(got.begin(), got.end(), want.begin(), [](Pair p, Pair q) { return p == q; }));
  EXPECT_EQ(st.pairs, want.size());
}

}  // namespace
}  // namespace octocd_test_exact_pairs
}  // namespace octocd
