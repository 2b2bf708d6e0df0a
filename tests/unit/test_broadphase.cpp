// Broadphase (SPEC 5.1): every implementation returns exactly the pairs of `flat`.

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <ostream>
#include <limits>
#include <map>
#include <random>
#include <string>
#include <vector>

#include "octocd/broadphase.hpp"
#include "octocd/error.hpp"

namespace octocd {
namespace {

// ---- data sets ----------------------------------------------------------------

// A non-cubic domain: bounding cube is [-2, 2] x [-1.5, 2.5] x [-2, 2] (side 4, centred
// on (0, 0.5, 0)); octree cell borders at depth d are multiples of 4/2^d from -2.
const Aabb kDomain{{-2.0f, 0.0f, -1.0f}, {2.0f, 1.0f, 1.0f}};

float snap(float v, float q) { return std::round(v / q) * q; }

/// Random boxes of varied sizes, some partly or wholly outside the domain, with exact
/// face contacts (some on octree cell borders), zero-size and identical boxes.
std::vector<Aabb> random_boxes(std::size_t n, unsigned seed, float scale = 1.0f) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> ux(-2.4f, 2.4f), uy(-0.3f, 1.3f), uz(-1.3f, 1.3f);
  std::uniform_real_distribution<float> u01(0.0f, 1.0f);
  // Mean size tuned so that n bodies give a few overlaps each.
  const float base = scale * 0.9f * std::cbrt(1.0f / static_cast<float>(std::max<std::size_t>(n, 1)));
  std::vector<Aabb> boxes;
  boxes.reserve(n);
  while (boxes.size() < n) {
    const float r = u01(rng);
    Vec3 c{ux(rng), uy(rng), uz(rng)};
    Vec3 h{base * (0.05f + u01(rng)), base * (0.05f + u01(rng)), base * (0.05f + u01(rng))};
    if (r < 0.02f && !boxes.empty()) {  // identical to an earlier box
      boxes.push_back(boxes[rng() % boxes.size()]);
      continue;
    }
    if (r < 0.06f) h = {0.0f, 0.0f, 0.0f};            // zero-size box (a point)
    else if (r < 0.08f) h = {0.0f, h.y, h.z};          // flat box
    else if (r < 0.085f) h = {1.5f, 0.02f, 0.02f};     // long rod across cells
    if (r >= 0.10f && r < 0.30f) {
      // Snap to a 1/32 grid: exact contacts, many on octree cell borders (4/2^d).
      const float q = 1.0f / 32.0f;
      c = {snap(c.x, q), snap(c.y, q), snap(c.z, q)};
      h = {snap(h.x, q / 2), snap(h.y, q / 2), snap(h.z, q / 2)};
    }
    Aabb b{{c.x - h.x, c.y - h.y, c.z - h.z}, {c.x + h.x, c.y + h.y, c.z + h.z}};
    boxes.push_back(b);
    if (r >= 0.30f && r < 0.36f && boxes.size() < n) {
      // A neighbour sharing exactly one face coordinate with b (touching: must pair).
      const int axis = static_cast<int>(rng() % 3);
      Aabb t = b;
      const float len = b.max[axis] - b.min[axis] + 0.01f;
      t.min[axis] = b.max[axis];
      t.max[axis] = b.max[axis] + len;
      boxes.push_back(t);
    }
  }
  return boxes;
}

const std::vector<Pair>& flat_pairs_cached(const std::vector<Aabb>& boxes, const std::string& key) {
  static std::map<std::string, std::vector<Pair>> cache;
  auto it = cache.find(key);
  if (it != cache.end()) return it->second;
  auto flat = make_broadphase({"flat", 2, 0.25f}, kDomain);
  std::vector<Pair> out;
  BroadPhaseStats st;
  flat->find_pairs(boxes, out, st);
  return cache.emplace(key, std::move(out)).first->second;
}

std::vector<Pair> flat_pairs(const std::vector<Aabb>& boxes) {
  auto flat = make_broadphase({"flat", 2, 0.25f}, kDomain);
  std::vector<Pair> out;
  BroadPhaseStats st;
  flat->find_pairs(boxes, out, st);
  return out;
}

/// Brute force written independently of the library (not through `flat`).
std::vector<Pair> brute(const std::vector<Aabb>& b) {
  std::vector<Pair> out;
  for (std::uint32_t i = 0; i < b.size(); ++i) {
    for (std::uint32_t j = i + 1; j < b.size(); ++j) {
      bool ok = true;
      for (int a = 0; a < 3; ++a) {
        ok = ok && b[i].min[a] <= b[j].max[a] && b[j].min[a] <= b[i].max[a];
      }
      if (ok) out.push_back({i, j});
    }
  }
  return out;
}

void expect_well_formed(const std::vector<Pair>& out, std::size_t n) {
  for (std::size_t k = 0; k < out.size(); ++k) {
    ASSERT_LT(out[k].a, out[k].b) << "pair " << k;
    ASSERT_LT(out[k].b, n) << "pair " << k;
    if (k > 0) {
      ASSERT_TRUE(out[k - 1] < out[k]) << "not sorted/unique at " << k;
    }
  }
}

std::string describe_diff(const std::vector<Pair>& got, const std::vector<Pair>& want) {
  std::vector<Pair> missing, extra;
  std::set_difference(want.begin(), want.end(), got.begin(), got.end(),
                      std::back_inserter(missing));
  std::set_difference(got.begin(), got.end(), want.begin(), want.end(),
                      std::back_inserter(extra));
  std::string s = "missing " + std::to_string(missing.size()) + ", extra " +
                  std::to_string(extra.size());
  if (!missing.empty())
    s += " (first missing " + std::to_string(missing[0].a) + "," + std::to_string(missing[0].b) + ")";
  if (!extra.empty())
    s += " (first extra " + std::to_string(extra[0].a) + "," + std::to_string(extra[0].b) + ")";
  return s;
}

// ---- parameterised over every implementation and configuration -----------------

struct Variant {
  std::string name;
  int depth;
  float cell;
};

void PrintTo(const Variant& v, std::ostream* os) {
  *os << v.name << " depth " << v.depth << " cell " << v.cell;
}

std::string variant_name(const testing::TestParamInfo<Variant>& info) {
  std::string s = info.param.name;
  if (s == "octree") s += info.param.depth < 0 ? "_auto" : "_d" + std::to_string(info.param.depth);
  if (s == "spatial-hash") s += "_h" + std::to_string(static_cast<int>(info.param.cell * 1000)) + "mm";
  std::replace(s.begin(), s.end(), '-', '_');
  return s;
}

std::vector<Variant> all_variants() {
  std::vector<Variant> v;
  for (const std::string& name : broadphase_names()) {
    if (name == "octree") {
      for (int d : {0, 1, 2, 4, 7, 10, -1}) v.push_back({name, d, 0.25f});
    } else if (name == "spatial-hash") {
      for (float h : {0.25f, 0.05f, 0.01f, 1.0f}) v.push_back({name, 2, h});
    } else {
      v.push_back({name, 2, 0.25f});
    }
  }
  return v;
}

class BroadPhaseEquivalence : public testing::TestWithParam<Variant> {
 protected:
  std::unique_ptr<BroadPhase> make() const {
    BroadPhaseConfig cfg;
    cfg.name = GetParam().name;
    cfg.octree_depth = GetParam().depth;
    cfg.cell_size = GetParam().cell;
    return make_broadphase(cfg, kDomain);
  }
};

TEST_P(BroadPhaseEquivalence, NameRoundTrips) { EXPECT_EQ(make()->name(), GetParam().name); }

TEST_P(BroadPhaseEquivalence, MatchesFlatOnRandomSets) {
  for (std::size_t n : {std::size_t{10}, std::size_t{1000}, std::size_t{5000}}) {
    for (unsigned seed : {1u, 2u}) {
      if (n == 5000 && seed == 2u) continue;  // keep the file fast
      const std::vector<Aabb> boxes = random_boxes(n, seed, n < 100 ? 3.0f : 2.0f);
      const std::vector<Pair>& want =
          flat_pairs_cached(boxes, std::to_string(n) + "/" + std::to_string(seed));
      ASSERT_GT(want.size(), n / 2) << "data set should have overlaps";
      auto bp = make();
      std::vector<Pair> got;
      BroadPhaseStats st;
      bp->find_pairs(boxes, got, st);
      SCOPED_TRACE("n=" + std::to_string(n) + " seed=" + std::to_string(seed));
      expect_well_formed(got, n);
      EXPECT_TRUE(got == want) << describe_diff(got, want);
      EXPECT_EQ(st.pairs, got.size());
      EXPECT_GE(st.cell_candidates, st.pairs);
    }
  }
}

TEST_P(BroadPhaseEquivalence, MatchesFlatOnSnappedDenseSet) {
  // Everything on a coarse 1/8 grid: many exact face, edge and corner contacts.
  std::mt19937 rng(7);
  std::vector<Aabb> boxes;
  for (int i = 0; i < 600; ++i) {
    const float x = static_cast<float>(static_cast<int>(rng() % 33) - 16) / 8.0f;
    const float y = static_cast<float>(static_cast<int>(rng() % 9)) / 8.0f;
    const float z = static_cast<float>(static_cast<int>(rng() % 17) - 8) / 8.0f;
    const float sx = static_cast<float>(rng() % 3) / 8.0f, sy = static_cast<float>(rng() % 3) / 8.0f,
                sz = static_cast<float>(rng() % 3) / 8.0f;
    boxes.push_back({{x, y, z}, {x + sx, y + sy, z + sz}});
  }
  const std::vector<Pair> want = brute(boxes);
  auto bp = make();
  std::vector<Pair> got;
  BroadPhaseStats st;
  bp->find_pairs(boxes, got, st);
  expect_well_formed(got, boxes.size());
  EXPECT_TRUE(got == want) << describe_diff(got, want);
}

TEST_P(BroadPhaseEquivalence, TouchingFacesOnCellBordersPair) {
  // x = 0 is the root's middle plane; y = 0.5 its middle in y; x = -1 a depth-2 border.
  std::vector<Aabb> boxes = {
      {{-0.3f, 0.1f, 0.1f}, {0.0f, 0.3f, 0.3f}},   // 0
      {{0.0f, 0.1f, 0.1f}, {0.2f, 0.3f, 0.3f}},    // 1: shares face x = 0 with 0
      {{0.0f, 0.3f, 0.3f}, {0.1f, 0.5f, 0.4f}},    // 2: edge/corner with 1, corner with 0
      {{0.0f, 0.5f, 0.4f}, {0.0f, 0.5f, 0.4f}},    // 3: zero-size, on 2's corner
      {{-1.2f, 0.6f, -0.5f}, {-1.0f, 0.7f, -0.4f}},  // 4
      {{-1.0f, 0.7f, -0.4f}, {-0.8f, 0.9f, -0.2f}},  // 5: corner contact with 4 at x = -1
      {{-2.5f, -1.0f, -1.5f}, {-2.0f, 0.0f, -1.0f}},  // 6: outside, touches domain corner
      {{-2.0f, 0.0f, -1.0f}, {-1.9f, 0.1f, -0.9f}},   // 7: corner contact with 6
      {{0.0f, 0.1f, 0.1f}, {0.2f, 0.3f, 0.3f}},    // 8: identical to 1
      {{2.0f, 2.5f, 2.0f}, {2.2f, 2.6f, 2.1f}},    // 9: on the root cube's upper corner
      {{1.9f, 2.4f, 1.9f}, {2.0f, 2.5f, 2.0f}},    // 10: touches 9 at the root corner
  };
  const std::vector<Pair> want = {{0, 1}, {0, 2}, {0, 8}, {1, 2}, {1, 8}, {2, 3},
                                  {2, 8}, {4, 5}, {6, 7}, {9, 10}};
  ASSERT_TRUE(brute(boxes) == want) << "test data";
  auto bp = make();
  std::vector<Pair> got;
  BroadPhaseStats st;
  bp->find_pairs(boxes, got, st);
  EXPECT_TRUE(got == want) << describe_diff(got, want);
}

TEST_P(BroadPhaseEquivalence, DegenerateBoxesMatchFlat) {
  std::vector<Aabb> boxes = random_boxes(300, 11);
  const float inf = std::numeric_limits<float>::infinity();
  const float nan = std::numeric_limits<float>::quiet_NaN();
  boxes[5] = {{-inf, -inf, -inf}, {inf, inf, inf}};    // covers everything
  boxes[17] = {{nan, 0.0f, 0.0f}, {1.0f, 1.0f, 1.0f}};  // never overlaps (Eq. 6)
  boxes[30] = {{0.5f, 0.5f, 0.5f}, {0.4f, 0.6f, 0.6f}};  // inverted in x
  boxes[44] = {{-100.0f, -100.0f, -100.0f}, {100.0f, 100.0f, 100.0f}};  // huge
  boxes[61] = {{1e30f, 1e30f, 1e30f}, {1e30f, 1e30f, 1e30f}};  // far away point
  boxes[62] = boxes[61];
  boxes[80] = {{-0.5f, -inf, -0.5f}, {0.5f, inf, 0.5f}};  // infinite column
  const std::vector<Pair> want = brute(boxes);
  ASSERT_TRUE(flat_pairs(boxes) == want);
  auto bp = make();
  std::vector<Pair> got;
  BroadPhaseStats st;
  bp->find_pairs(boxes, got, st);
  expect_well_formed(got, boxes.size());
  EXPECT_TRUE(got == want) << describe_diff(got, want);
}

TEST_P(BroadPhaseEquivalence, RepeatedCallsAfterMovingBodiesMatchFlat) {
  std::vector<Aabb> boxes = random_boxes(1000, 3);
  std::mt19937 rng(99);
  std::uniform_real_distribution<float> step(-0.02f, 0.02f);
  std::uniform_real_distribution<float> jump(-2.0f, 2.0f);
  auto bp = make();  // one instance across all calls
  std::vector<Pair> got;
  for (int frame = 0; frame < 6; ++frame) {
    const bool teleport = frame == 3;
    for (Aabb& b : boxes) {
      const Vec3 d = teleport ? Vec3{jump(rng), jump(rng) * 0.3f, jump(rng) * 0.5f}
                              : Vec3{step(rng), step(rng), step(rng)};
      b = translated(b, d);
    }
    BroadPhaseStats st;
    bp->find_pairs(boxes, got, st);
    const std::vector<Pair> want = flat_pairs(boxes);
    SCOPED_TRACE("frame " + std::to_string(frame));
    expect_well_formed(got, boxes.size());
    EXPECT_TRUE(got == want) << describe_diff(got, want);
    EXPECT_EQ(st.pairs, want.size());
  }
}

TEST_P(BroadPhaseEquivalence, EmptyAndSingleBody) {
  auto bp = make();
  std::vector<Pair> got = {{0, 1}};  // must be cleared
  BroadPhaseStats st;
  bp->find_pairs({}, got, st);
  EXPECT_TRUE(got.empty());
  EXPECT_EQ(st.pairs, 0u);
  auto bp1 = make();
  got = {{0, 1}};
  bp1->find_pairs({Aabb{{0, 0, 0}, {1, 1, 1}}}, got, st);
  EXPECT_TRUE(got.empty());
  EXPECT_EQ(st.cell_candidates, 0u);
}

INSTANTIATE_TEST_SUITE_P(AllBroadPhases, BroadPhaseEquivalence, testing::ValuesIn(all_variants()),
                         variant_name);

// ---- per-implementation properties ------------------------------------------------

TEST(BroadPhase, NamesAreTheDocumentedOnes) {
  EXPECT_EQ(broadphase_names(), (std::vector<std::string>{"flat", "octree", "spatial-hash"}));
  for (const std::string& name : broadphase_names()) {
    BroadPhaseConfig cfg;
    cfg.name = name;
    EXPECT_EQ(make_broadphase(cfg, kDomain)->name(), name);
  }
}

TEST(BroadPhase, UnknownNameThrowsInputError) {
  BroadPhaseConfig cfg;
  cfg.name = "kd-tree";
  try {
    make_broadphase(cfg, kDomain);
    FAIL() << "no exception";
  } catch (const InputError& e) {
    EXPECT_STREQ(e.what(),
                 "broadphase.name: unknown broadphase 'kd-tree' (expected one of: flat, octree, "
                 "spatial-hash)");
  }
}

TEST(BroadPhase, OutOfRangeParametersThrowInputError) {
  for (int d : {-2, 11, 100}) {
    BroadPhaseConfig cfg;
    cfg.octree_depth = d;
    try {
      make_broadphase(cfg, kDomain);
      FAIL() << "depth " << d;
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find("broadphase.depth"), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find("[0, 10]"), std::string::npos) << e.what();
    }
  }
  for (float h : {0.0f, -0.25f, std::numeric_limits<float>::quiet_NaN(),
                  std::numeric_limits<float>::infinity()}) {
    BroadPhaseConfig cfg;
    cfg.name = "spatial-hash";
    cfg.cell_size = h;
    try {
      make_broadphase(cfg, kDomain);
      FAIL() << "cell size " << h;
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find("broadphase.cell_size"), std::string::npos) << e.what();
    }
  }
  for (int d : {-1, 0, 10}) {
    BroadPhaseConfig cfg;
    cfg.octree_depth = d;
    EXPECT_NO_THROW(make_broadphase(cfg, kDomain)) << d;
  }
}

TEST(BroadPhase, FlatCountsAllPairs) {
  const std::vector<Aabb> boxes = random_boxes(100, 5);
  auto bp = make_broadphase({"flat", 2, 0.25f}, kDomain);
  std::vector<Pair> got;
  BroadPhaseStats st;
  bp->find_pairs(boxes, got, st);
  EXPECT_EQ(st.cell_candidates, 100u * 99u / 2u);
  EXPECT_TRUE(got == brute(boxes));
}

TEST(BroadPhase, OctreeCullsCandidates) {
  // Small boxes, all inside the domain.
  std::mt19937 rng(6);
  std::uniform_real_distribution<float> ux(-1.95f, 1.9f), uy(0.05f, 0.9f), uz(-0.95f, 0.9f);
  std::uniform_real_distribution<float> us(0.0f, 0.05f);
  std::vector<Aabb> boxes;
  for (int i = 0; i < 2000; ++i) {
    const Vec3 lo{ux(rng), uy(rng), uz(rng)};
    boxes.push_back({lo, {lo.x + us(rng), lo.y + us(rng), lo.z + us(rng)}});
  }
  const std::uint64_t all = 2000ull * 1999ull / 2ull;
  std::vector<Pair> got;
  BroadPhaseStats d0, d2, d4;
  make_broadphase({"octree", 0, 0.25f}, kDomain)->find_pairs(boxes, got, d0);
  EXPECT_EQ(d0.cell_candidates, all);  // depth 0: everything at the root
  make_broadphase({"octree", 2, 0.25f}, kDomain)->find_pairs(boxes, got, d2);
  make_broadphase({"octree", 4, 0.25f}, kDomain)->find_pairs(boxes, got, d4);
  EXPECT_LT(d2.cell_candidates, all / 4);
  EXPECT_LT(d4.cell_candidates, d2.cell_candidates);
  EXPECT_GT(d2.memory_bytes, 0u);
}

TEST(BroadPhase, SpatialHashCountsSharedCells) {
  // Two unit-ish boxes sharing 2 cells of size 1 and one far away: 2 shared-cell
  // candidates, one pair.
  const std::vector<Aabb> boxes = {{{0.1f, 0.1f, 0.1f}, {1.5f, 0.9f, 0.9f}},
                                   {{0.2f, 0.2f, 0.2f}, {1.2f, 0.8f, 0.8f}},
                                   {{5.1f, 5.1f, 5.1f}, {5.2f, 5.2f, 5.2f}}};
  std::vector<Pair> got;
  BroadPhaseStats st;
  make_broadphase({"spatial-hash", 2, 1.0f}, kDomain)->find_pairs(boxes, got, st);
  EXPECT_EQ(st.cell_candidates, 2u);
  ASSERT_EQ(got.size(), 1u);
  EXPECT_TRUE(got[0] == (Pair{0, 1}));
}

TEST(BroadPhase, AutoOctreeDepth) {
  EXPECT_EQ(auto_octree_depth({}, kDomain), 2);
  // Root side 4: level l has cells of 4/2^l; mean extent 0.1 -> deepest with >= 0.2 is 4.
  std::vector<Aabb> small(10, Aabb{{0, 0, 0}, {0.1f, 0.05f, 0.02f}});
  EXPECT_EQ(auto_octree_depth(small, kDomain), 4);
  // Mean of longest sides (0.1 and 0.3) = 0.2 -> cells >= 0.4 -> level 3 (0.5).
  std::vector<Aabb> mixed = {{{0, 0, 0}, {0.1f, 0.1f, 0.1f}}, {{0, 0, 0}, {0.05f, 0.3f, 0.1f}}};
  EXPECT_EQ(auto_octree_depth(mixed, kDomain), 3);
  std::vector<Aabb> points(5, Aabb{{1, 1, 1}, {1, 1, 1}});
  EXPECT_EQ(auto_octree_depth(points, kDomain), 8);
  std::vector<Aabb> huge(3, Aabb{{-5, -5, -5}, {5, 5, 5}});
  EXPECT_EQ(auto_octree_depth(huge, kDomain), 1);
}

}  // namespace
}  // namespace octocd
