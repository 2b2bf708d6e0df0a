// Broadphase (design.md section 5.1): every implementation returns exactly the pairs of `flat`.

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
#include "octocd/loose_octree.hpp"
#include "octocd/parallel.hpp"
#include "support/doc_broadphases.hpp"

#include "../../core/src/broadphase_detail.hpp"

namespace octocd {
namespace octocd_test_broadphase {
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

bool is_octree(const std::string& name) { return name == "octree" || name == "octree-strict"; }

std::string variant_name(const testing::TestParamInfo<Variant>& info) {
  std::string s = info.param.name;
  if (is_octree(s)) s += info.param.depth < 0 ? "_auto" : "_d" + std::to_string(info.param.depth);
  if (s == "spatial-hash") s += "_h" + std::to_string(static_cast<int>(info.param.cell * 1000)) + "mm";
  std::replace(s.begin(), s.end(), '-', '_');
  return s;
}

std::vector<Variant> all_variants() {
  std::vector<Variant> v;
  for (const std::string& name : broadphase_names()) {
    if (is_octree(name)) {
      for (int d = -1; d <= 10; ++d) v.push_back({name, d, 0.25f});
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

TEST_P(BroadPhaseEquivalence, HugeBodiesBiggerThanTheDomainMatchFlat) {
  // Bodies larger than the root cube (side 4): slabs, walls and boxes around everything,
  // some centred far away, among ordinary bodies.
  std::vector<Aabb> boxes = random_boxes(400, 21);
  boxes[3] = {{-10.0f, -10.0f, -10.0f}, {10.0f, 10.0f, 10.0f}};   // contains the domain
  boxes[50] = {{-3.0f, -0.1f, -3.0f}, {3.0f, 0.0f, 3.0f}};        // floor slab, 6 m wide
  boxes[51] = {{-3.0f, 1.0f, -3.0f}, {3.0f, 1.1f, 3.0f}};         // ceiling slab
  boxes[52] = {{-2.1f, -3.0f, -3.0f}, {-2.0f, 3.0f, 3.0f}};       // side wall on x = -2
  boxes[90] = {{-4.5f, 0.2f, -0.1f}, {4.5f, 0.3f, 0.1f}};         // rod longer than S
  boxes[91] = {{40.0f, 40.0f, 40.0f}, {50.0f, 50.0f, 50.0f}};     // huge and far away
  boxes[92] = {{-0.01f, -0.01f, -0.01f}, {4.01f, 4.01f, 4.01f}};  // just above S
  boxes[93] = {{-2.0f, -1.5f, -2.0f}, {2.0f, 2.5f, 2.0f}};        // exactly the root cube
  boxes[94] = {{-3.9f, -3.4f, -3.9f}, {0.1f, 0.6f, 0.1f}};        // side S, corner outside
  const std::vector<Pair> want = brute(boxes);
  auto bp = make();
  std::vector<Pair> got;
  BroadPhaseStats st;
  bp->find_pairs(boxes, got, st);
  expect_well_formed(got, boxes.size());
  EXPECT_TRUE(got == want) << describe_diff(got, want);
  EXPECT_EQ(st.pairs, want.size());
}

TEST_P(BroadPhaseEquivalence, OutOfDomainBodiesMatchFlat) {
  // Many bodies partly or wholly outside the domain and the root cube, in clusters (so
  // they overlap each other) on every side, some just across the root's loose box.
  std::mt19937 rng(31);
  std::uniform_real_distribution<float> u(-1.0f, 1.0f), s(0.05f, 0.6f);
  std::vector<Aabb> boxes;
  const Vec3 centres[] = {{-3.1f, 0.5f, 0.0f}, {4.05f, 0.5f, 0.0f}, {0.0f, -2.6f, 0.0f},
                          {0.0f, 3.6f, 0.0f},  {0.0f, 0.5f, -4.01f}, {0.0f, 0.5f, 3.0f},
                          {9.0f, 9.0f, 9.0f},  {-2.0f, -1.5f, -2.0f}, {2.0f, 2.5f, 2.0f},
                          {0.0f, 0.5f, 0.0f}};
  for (const Vec3& c : centres) {
    for (int k = 0; k < 60; ++k) {
      const Vec3 lo{c.x + 0.8f * u(rng), c.y + 0.8f * u(rng), c.z + 0.8f * u(rng)};
      boxes.push_back({lo, {lo.x + s(rng), lo.y + s(rng), lo.z + s(rng)}});
    }
  }
  const std::vector<Pair> want = brute(boxes);
  ASSERT_GT(want.size(), boxes.size());
  auto bp = make();
  std::vector<Pair> got;
  BroadPhaseStats st;
  bp->find_pairs(boxes, got, st);
  expect_well_formed(got, boxes.size());
  EXPECT_TRUE(got == want) << describe_diff(got, want);
}

TEST_P(BroadPhaseEquivalence, AllBodiesInOneCellMatchFlat) {
  // Everything inside one deepest-level cell (side 4 / 1024 at depth 10) with a common
  // corner point, plus a dense pile of identical boxes.
  std::vector<Aabb> boxes;
  const float q = 4.0f / 1024.0f;
  const Vec3 o{0.25f + q * 0.25f, 0.75f + q * 0.25f, 0.5f + q * 0.25f};
  std::mt19937 rng(41);
  std::uniform_real_distribution<float> u(0.0f, 0.24f * q);
  for (int i = 0; i < 150; ++i) {
    boxes.push_back({{o.x - u(rng), o.y - u(rng), o.z - u(rng)},
                     {o.x + u(rng), o.y + u(rng), o.z + u(rng)}});
  }
  // A pile of 100 identical boxes (more than a table entry's body count holds), with
  // neighbours touching it from the next cell at the same level and from a finer level.
  for (int i = 0; i < 100; ++i) boxes.push_back({{-1.0f, 0.1f, 0.1f}, {-0.9f, 0.2f, 0.2f}});
  boxes.push_back({{-0.9f, 0.1f, 0.1f}, {-0.8f, 0.2f, 0.2f}});
  boxes.push_back({{-0.9f, 0.15f, 0.15f}, {-0.89f, 0.16f, 0.16f}});
  boxes.push_back({{-1.1f, 0.05f, 0.05f}, {-1.0f, 0.1f, 0.1f}});
  const std::vector<Pair> want = brute(boxes);
  ASSERT_EQ(want.size(), 150u * 149u / 2u + 100u * 99u / 2u + 3u * 100u + 1u);
  auto bp = make();
  std::vector<Pair> got;
  BroadPhaseStats st;
  bp->find_pairs(boxes, got, st);
  expect_well_formed(got, boxes.size());
  EXPECT_TRUE(got == want) << describe_diff(got, want);
}

TEST_P(BroadPhaseEquivalence, MixedSizesAcrossLevelsMatchFlat) {
  // Sizes spread over every level (4 m down to points), many touching exactly on the
  // 1/256 grid (cell borders of every level up to 8 and loose-box borders).
  std::mt19937 rng(51);
  std::uniform_real_distribution<float> c(-2.2f, 2.2f), e(-11.0f, 1.0f);
  std::vector<Aabb> boxes;
  for (int i = 0; i < 1500; ++i) {
    Vec3 ctr{c(rng), 0.5f + 0.6f * c(rng), 0.6f * c(rng)};
    const float h = 0.5f * std::exp2(e(rng));
    if (i % 3 == 0) {
      const float g = 1.0f / 256.0f;
      ctr = {snap(ctr.x, g), snap(ctr.y, g), snap(ctr.z, g)};
      const float hs = std::max(g, snap(h, g));
      boxes.push_back({{ctr.x - hs, ctr.y - hs, ctr.z - hs}, {ctr.x + hs, ctr.y + hs, ctr.z + hs}});
    } else {
      boxes.push_back({{ctr.x - h, ctr.y - 0.5f * h, ctr.z - h}, {ctr.x + h, ctr.y + h, ctr.z + 0.3f * h}});
    }
  }
  const std::vector<Pair> want = brute(boxes);
  ASSERT_GT(want.size(), boxes.size() / 2);
  auto bp = make();
  std::vector<Pair> got;
  BroadPhaseStats st;
  bp->find_pairs(boxes, got, st);
  expect_well_formed(got, boxes.size());
  EXPECT_TRUE(got == want) << describe_diff(got, want);
}

INSTANTIATE_TEST_SUITE_P(AllBroadPhases, BroadPhaseEquivalence, testing::ValuesIn(all_variants()),
                         variant_name);

// ---- per-implementation properties ------------------------------------------------

/// The names docs/architecture.md's broadphase table gives the CPU library `core`.
std::vector<std::string> documented_core_names() {
  return octocd::test::doc_broadphase_names([](const octocd::test::DocBroadPhase& r) { return r.cpu == "core"; });
}

TEST(BroadPhase, NamesAreTheDocumentedOnes) {
  ASSERT_FALSE(documented_core_names().empty()) << "docs/architecture.md: the broadphase table";
  EXPECT_EQ(broadphase_names(), documented_core_names());
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
    std::string allowed;
    for (const std::string& name : documented_core_names()) allowed += (allowed.empty() ? "" : ", ") + name;
    EXPECT_EQ(std::string(e.what()), "broadphase.name: unknown broadphase 'kd-tree'; allowed: " + allowed);
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
  for (const char* name : {"octree", "octree-strict"}) {
    SCOPED_TRACE(name);
    std::vector<Pair> got;
    BroadPhaseStats d0, d2, d4, d6;
    make_broadphase({name, 0, 0.25f}, kDomain)->find_pairs(boxes, got, d0);
    EXPECT_EQ(d0.cell_candidates, all);  // depth 0: everything in the root cell
    make_broadphase({name, 2, 0.25f}, kDomain)->find_pairs(boxes, got, d2);
    make_broadphase({name, 4, 0.25f}, kDomain)->find_pairs(boxes, got, d4);
    make_broadphase({name, 6, 0.25f}, kDomain)->find_pairs(boxes, got, d6);
    if (std::string(name) == "octree") {
      // Loose: every body meets the 3 x 3 x 3 cells around its own, so coarse levels
      // (cells of 1 m at depth 2) cull little; at depth 6 bodies of size <= 0.05 sit in
      // cells of 0.0625 and meet a few neighbours each.
      EXPECT_LT(d2.cell_candidates, all);
      EXPECT_LT(d4.cell_candidates, d2.cell_candidates / 4);
      EXPECT_LT(d6.cell_candidates, 20u * 2000u);
      EXPECT_GE(d6.cell_candidates, d6.pairs);
    } else {
      EXPECT_LT(d2.cell_candidates, all / 4);
      EXPECT_LT(d4.cell_candidates, d2.cell_candidates);
    }
    EXPECT_GT(d2.memory_bytes, 0u);
  }
}

TEST(BroadPhase, LooseOctreeCountsOverflowAgainstEveryBody) {
  // Two bodies bigger than the root cube (side 4) go to the overflow list and are tested
  // against every body; the 100 small ones meet only their neighbours.
  std::vector<Aabb> boxes;
  for (int i = 0; i < 100; ++i) {
    const float x = -1.9f + 0.035f * static_cast<float>(i);
    boxes.push_back({{x, 0.4f, 0.0f}, {x + 0.01f, 0.41f, 0.01f}});
  }
  boxes.push_back({{-3.0f, -0.1f, -3.0f}, {3.0f, 0.0f, 3.0f}});
  boxes.push_back({{-3.0f, 1.0f, -3.0f}, {3.0f, 1.1f, 3.0f}});
  std::vector<Pair> got;
  BroadPhaseStats st;
  make_broadphase({"octree", -1, 0.25f}, kDomain)->find_pairs(boxes, got, st);
  EXPECT_TRUE(got.empty());
  // 2 x 100 + 1 overflow candidates, plus at most a few per small body.
  EXPECT_GE(st.cell_candidates, 201u);
  EXPECT_LT(st.cell_candidates, 201u + 3u * 100u);
}

// ---- the loose octree's cell math (loose_octree.hpp) --------------------------------

TEST(LooseOctree, Morton3PutsXInTheLowBit) {
  EXPECT_EQ(morton3(1, 0, 0), 1u);
  EXPECT_EQ(morton3(0, 1, 0), 2u);
  EXPECT_EQ(morton3(0, 0, 1), 4u);
  EXPECT_EQ(morton3(2, 0, 0), 8u);
  EXPECT_EQ(morton3(1023, 1023, 1023), (1u << 30) - 1u);
  EXPECT_EQ(morton3(5, 3, 6), morton3(10, 6, 12) >> 3);  // prefix property
}

TEST(LooseOctree, GridIsTheDomainsBoundingCube) {
  const LooseGrid g = loose_grid(kDomain);
  EXPECT_EQ(g.side, 4.0f);
  EXPECT_TRUE((g.origin == Vec3{-2.0f, -1.5f, -2.0f}));
  EXPECT_EQ(g.inv_side, 0.25f);
  const Vec3 u = loose_unit(g, {2.0f, 2.5f, 0.0f});
  EXPECT_TRUE((u == Vec3{1.0f, 1.0f, 0.5f}));
  EXPECT_EQ(loose_grid(Aabb{{0, 0, 0}, {0, 0, 0}}).inv_side, 0.0f);  // unusable
}

TEST(LooseOctree, LevelByExtentAndKeys) {
  EXPECT_EQ(loose_level_for_extent(1.0f, 10), 0);
  EXPECT_EQ(loose_level_for_extent(1.0001f, 10), -1);  // bigger than S: overflow
  EXPECT_EQ(loose_level_for_extent(0.5f, 10), 1);
  EXPECT_EQ(loose_level_for_extent(0.2f, 10), 2);      // 1/4 >= 0.2 > 1/8
  EXPECT_EQ(loose_level_for_extent(0.0f, 10), 10);
  EXPECT_EQ(loose_level_for_extent(0.0f, 3), 3);
  EXPECT_EQ(loose_level_for_extent(std::numeric_limits<float>::quiet_NaN(), 10), -1);
  EXPECT_EQ(loose_level_base(0), 0u);
  EXPECT_EQ(loose_level_base(1), 1u);
  EXPECT_EQ(loose_level_base(2), 9u);
  EXPECT_EQ(loose_cell_key(10, 1023, 1023, 1023), 1227133512u);
  for (int l = 0; l <= 10; ++l) {
    EXPECT_EQ(loose_key_level(loose_cell_key(l, 0, 0, 0)), l);
    const std::uint32_t last = (1u << l) - 1u;
    EXPECT_EQ(loose_key_level(loose_cell_key(l, last, last, last)), l);
    if (l < 10) {
      EXPECT_EQ(loose_cell_key(l, last, last, last) + 1u, loose_cell_key(l + 1, 0, 0, 0));
    }
  }
  EXPECT_EQ(loose_key_level(kLooseOverflowKey), -1);
  EXPECT_EQ(loose_cell_index(0.5f, 1), 1u);
  EXPECT_EQ(loose_cell_index(0.4999f, 1), 0u);
  EXPECT_EQ(loose_cell_index(1.0f, 3), 7u);   // upper face: clamped
  EXPECT_EQ(loose_cell_index(-0.1f, 3), 0u);  // outside: clamped
  EXPECT_EQ(loose_cell_index(0.3f, 7) >> 2, loose_cell_index(0.3f, 5));
}

TEST(LooseOctree, PlacementKeepsTheBodyInsideItsLooseBox) {
  const LooseGrid g = loose_grid(kDomain);
  const std::vector<Aabb> boxes = random_boxes(3000, 61);
  int placed = 0, overflow = 0;
  for (int depth = 0; depth <= 10; ++depth) {
    for (const Aabb& b : boxes) {
      const LoosePlace p = loose_place(g, b, depth);
      ASSERT_NE(p.level, kLooseNoLevel);
      if (p.level == kLooseOverflowLevel) {
        ++overflow;
        continue;
      }
      ++placed;
      ASSERT_LE(p.level, depth);
      const std::uint32_t n = 1u << p.level;
      ASSERT_LT(p.ix, n);
      ASSERT_LT(p.iy, n);
      ASSERT_LT(p.iz, n);
      // Level by size: a cell side >= the body, and one level deeper would not do
      // (unless the centre rule made it climb).
      const float side = g.side / static_cast<float>(n);
      const float ext = std::max({b.max.x - b.min.x, b.max.y - b.min.y, b.max.z - b.min.z});
      ASSERT_GE(side * 1.0001f, ext);
      // Inside the loose box (world coordinates, up to rounding).
      const Aabb lb = expanded(loose_cell_box(g, p.level, p.ix, p.iy, p.iz), 1e-5f);
      ASSERT_TRUE(contains(lb, b)) << "level " << p.level;
      // And exactly in unit coordinates.
      const Vec3 lo = loose_unit(g, b.min), hi = loose_unit(g, b.max);
      ASSERT_TRUE(loose_fits_axis(lo.x, hi.x, p.ix, p.level));
      ASSERT_TRUE(loose_fits_axis(lo.y, hi.y, p.iy, p.level));
      ASSERT_TRUE(loose_fits_axis(lo.z, hi.z, p.iz, p.level));
    }
  }
  EXPECT_GT(placed, 0);
  EXPECT_EQ(overflow, 0);  // random_boxes stay inside the root's loose box
  const float nan = std::numeric_limits<float>::quiet_NaN();
  EXPECT_EQ(loose_place(g, Aabb{{nan, 0, 0}, {1, 1, 1}}, 4).level, kLooseNoLevel);
  const float inf = std::numeric_limits<float>::infinity();
  EXPECT_EQ(loose_place(g, Aabb{{-inf, 0, 0}, {1, 1, 1}}, 4).level, kLooseOverflowLevel);
  EXPECT_EQ(loose_place(g, Aabb{{-3, -3, -3}, {3, 3, 3}}, 4).level, kLooseOverflowLevel);
  EXPECT_EQ(loose_place(g, Aabb{{50, 50, 50}, {50, 50, 50}}, 4).level, kLooseOverflowLevel);
  // A small body just outside the root cube but inside the root's loose box climbs.
  const LoosePlace out = loose_place(g, Aabb{{2.5f, 0, 0}, {2.6f, 0.1f, 0.1f}}, 6);
  EXPECT_GE(out.level, 0);
  EXPECT_LT(out.level, 2);
  // An unusable grid puts every finite body in the root cell.
  const LooseGrid bad = loose_grid(Aabb{{0, 0, 0}, {0, 0, 0}});
  EXPECT_EQ(loose_place(bad, Aabb{{5, 5, 5}, {6, 6, 6}}, 4).level, 4);
  EXPECT_EQ(loose_place(bad, Aabb{{-inf, 5, 5}, {6, 6, 6}}, 4).level, kLooseOverflowLevel);
}

TEST(LooseOctree, QueryRangeIsExactlyTheCellsWhoseLooseBoxesMeet) {
  std::mt19937 rng(71);
  std::uniform_real_distribution<float> u(-1.3f, 2.3f), w(0.0f, 0.6f);
  for (int trial = 0; trial < 40000; ++trial) {
    const int level = static_cast<int>(rng() % 11);
    float lo = u(rng), hi = lo + w(rng) / static_cast<float>(1 << (level / 2));
    if (trial % 4 == 0) {  // exactly on cell or loose borders
      const float g = 0.5f / static_cast<float>(1 << level);
      lo = std::round(lo / g) * g;
      hi = std::round(hi / g) * g;
    }
    const LooseRange r = loose_query_axis(lo, hi, level);
    const float n = static_cast<float>(1 << level);
    int want_lo = 1 << 20, want_hi = -1;
    for (int i = 0; i < (1 << level); ++i) {
      const bool meets = static_cast<float>(i) - 0.5f <= hi * n && static_cast<float>(i) + 1.5f >= lo * n;
      if (meets) {
        want_lo = std::min(want_lo, i);
        want_hi = std::max(want_hi, i);
      }
    }
    if (want_hi < 0) {
      ASSERT_GT(r.lo, r.hi) << lo << " " << hi << " level " << level;
    } else {
      ASSERT_EQ(r.lo, want_lo) << lo << " " << hi << " level " << level;
      ASSERT_EQ(r.hi, want_hi) << lo << " " << hi << " level " << level;
    }
    if (hi - lo <= 1.0f / n && want_hi >= 0) {
      ASSERT_LE(r.hi - r.lo + 1, 4);
    }
    // The fixed-point form gives the same range (both empty, or equal).
    const LooseRange q = loose_query_axis_q(loose_q_min(lo), loose_q_max(hi), level);
    if (r.lo > r.hi) {
      ASSERT_GT(q.lo, q.hi) << lo << " " << hi << " level " << level;
    } else {
      ASSERT_EQ(q.lo, r.lo) << lo << " " << hi << " level " << level;
      ASSERT_EQ(q.hi, r.hi) << lo << " " << hi << " level " << level;
    }
  }
  const float inf = std::numeric_limits<float>::infinity();
  EXPECT_EQ(loose_query_axis(-inf, inf, 3).lo, 0);
  EXPECT_EQ(loose_query_axis(-inf, inf, 3).hi, 7);
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const LooseRange none = loose_query_axis(nan, 0.5f, 3);
  EXPECT_GT(none.lo, none.hi);
  for (int level = 0; level <= 10; ++level) {
    const LooseRange all = loose_query_axis_q(loose_q_min(-inf), loose_q_max(inf), level);
    EXPECT_EQ(all.lo, 0);
    EXPECT_EQ(all.hi, (1 << level) - 1);
    const LooseRange q1 = loose_query_axis_q(loose_q_min(nan), loose_q_max(0.5f), level);
    EXPECT_GT(q1.lo, q1.hi);
    const LooseRange q2 = loose_query_axis_q(loose_q_min(0.5f), loose_q_max(nan), level);
    EXPECT_GT(q2.lo, q2.hi);
    const LooseRange far = loose_query_axis_q(loose_q_min(1e30f), loose_q_max(1e30f), level);
    EXPECT_GT(far.lo, far.hi);
  }
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

TEST(BroadPhase, AutoLooseOctreeDepth) {
  // Root side 4: level l has cells of 4/2^l. The smallest body decides: the deepest
  // level whose cell side is >= its largest side.
  EXPECT_EQ(auto_loose_octree_depth({}, kDomain), 0);
  std::vector<Aabb> small(10, Aabb{{0, 0, 0}, {0.1f, 0.05f, 0.02f}});
  EXPECT_EQ(auto_loose_octree_depth(small, kDomain), 5);  // 0.125 >= 0.1 > 0.0625
  small.push_back({{0, 0, 0}, {0.5f, 0.5f, 0.5f}});         // bigger ones change nothing
  EXPECT_EQ(auto_loose_octree_depth(small, kDomain), 5);
  small.push_back({{1, 0, 0}, {1.0625f, 0.01f, 0.01f}});    // exactly a level-6 cell
  EXPECT_EQ(auto_loose_octree_depth(small, kDomain), 6);
  std::vector<Aabb> points(5, Aabb{{1, 1, 1}, {1, 1, 1}});
  EXPECT_EQ(auto_loose_octree_depth(points, kDomain), 10);
  std::vector<Aabb> huge(3, Aabb{{-5, -5, -5}, {5, 5, 5}});
  EXPECT_EQ(auto_loose_octree_depth(huge, kDomain), 0);
  const float nan = std::numeric_limits<float>::quiet_NaN();
  std::vector<Aabb> with_nan = {{{nan, 0, 0}, {0, 0, 0}}, {{0, 0, 0}, {1.0f, 1.0f, 1.0f}}};
  EXPECT_EQ(auto_loose_octree_depth(with_nan, kDomain), 2);
}

/// One loose octree instance per thread count (1, 2, 3) over `frames`, every answer equal
/// to brute force; each thread count's cell candidates, call by call.
std::vector<std::vector<std::uint64_t>> loose_octree_on_1_2_3_threads(const std::vector<std::vector<Aabb>>& frames) {
  std::vector<std::vector<Pair>> wants;
  for (const auto& frame : frames) wants.push_back(brute(frame));
  std::vector<std::vector<std::uint64_t>> candidates;
  for (int threads : {1, 2, 3}) {
    const ThreadCount at(threads);
    auto bp = make_broadphase({"octree", -1, 0.25f}, kDomain);
    std::vector<Pair> got;
    BroadPhaseStats st;
    candidates.emplace_back();
    for (std::size_t call = 0; call < frames.size(); ++call) {
      bp->find_pairs(frames[call], got, st);
      EXPECT_TRUE(got == wants[call]) << threads << " threads, call " << call << ": " << describe_diff(got, wants[call]);
      candidates.back().push_back(st.cell_candidates);
    }
  }
  return candidates;
}

// The loose octree runs its keys and queries on the worker team from 4096 bodies on: the
// pairs (and the candidate count) must not depend on the thread count, including the
// overflow tests split in chunks of in-tree bodies (walls and huge bodies here), on every
// kind of call of one instance: the first (tree on the boxes), the build of the pair
// cache, a hit, an update of a few escaped bodies, a rebuild after a teleport.
TEST(BroadPhase, LooseOctreeThreadCountDoesNotChangeTheAnswer) {
  std::vector<Aabb> boxes = random_boxes(12000, 77);
  boxes[10] = {{-3.0f, -0.1f, -3.0f}, {3.0f, 0.0f, 3.0f}};        // floor slab (overflow)
  boxes[11] = {{-2.1f, -3.0f, -3.0f}, {-2.0f, 3.0f, 3.0f}};       // wall (overflow)
  boxes[12] = {{-10.0f, -10.0f, -10.0f}, {10.0f, 10.0f, 10.0f}};  // contains everything
  std::vector<std::vector<Aabb>> frames = {boxes, boxes, boxes};
  for (std::uint32_t i : {100u, 2000u, 7000u}) boxes[i] = translated(boxes[i], {0.3f, 0.1f, -0.2f});
  frames.push_back(boxes);
  for (Aabb& b : boxes) b = translated(b, {0.25f, 0.0f, 0.0f});
  frames.push_back(boxes);
  const std::vector<std::vector<std::uint64_t>> candidates = loose_octree_on_1_2_3_threads(frames);
  for (const auto& c : candidates) EXPECT_EQ(c, candidates.front());
}

// The loose octree's pair cache on the worker team: its fattened boxes, the escape check
// (blocks of bodies, their lists joined in order) and the filter of the kept pairs (blocks
// of pairs, from 16,384 on) give the same pairs and counts on 1, 2 and 3 threads over a
// build, hits, an update of a few escaped bodies and a rebuild, each equal to brute force.
TEST(BroadPhase, LooseOctreePairCacheThreadCountDoesNotChangeTheAnswer) {
  std::vector<Aabb> boxes = random_boxes(8000, 93, 3.5f);
  std::vector<std::vector<Aabb>> frames = {boxes, boxes, boxes};
  for (Aabb& b : boxes) b = translated(b, {1e-4f, 0.0f, -1e-4f});  // inside the fattened boxes
  frames.push_back(boxes);
  for (std::uint32_t i : {5u, 4000u, 7000u}) boxes[i] = translated(boxes[i], {0.3f, 0.1f, -0.2f});
  frames.push_back(boxes);
  for (Aabb& b : boxes) b = translated(b, {0.25f, 0.0f, 0.0f});
  frames.push_back(boxes);
  const std::vector<std::vector<std::uint64_t>> candidates = loose_octree_on_1_2_3_threads(frames);
  // Call 2 is a hit: its count is the kept pairs, enough for the filter's blocks.
  EXPECT_GE(candidates.front()[2], 16384u);
  EXPECT_LT(brute(frames[2]).size(), candidates.front()[2]);
  for (const auto& c : candidates) EXPECT_EQ(c, candidates.front());
}

// The spatial hash and the strict octree run on the worker team from 4096 bodies on: the
// pairs and the candidate count must not depend on the thread count, with bodies on coarser
// levels of the hash (pairs across levels), a body out of every level's range (oversize),
// one with a NaN coordinate, and bodies at the strict octree's root and deep below it; on
// one instance, calls with a fresh order, the kept order, bodies moved (the strict
// octree's moved items sorted apart and merged) and every body nudged (its kept order
// re-sorted within nodes).
TEST(BroadPhase, SpatialHashAndStrictOctreeThreadCountDoesNotChangeTheAnswer) {
  std::vector<Aabb> boxes = random_boxes(12000, 91);
  boxes[10] = {{-3.0f, -0.1f, -3.0f}, {3.0f, 0.0f, 3.0f}};   // floor slab: a coarse level, the root
  boxes[11] = {{-2.1f, -3.0f, -3.0f}, {-2.0f, 3.0f, 3.0f}};  // wall
  boxes[12] = {{0.5f, 0.5f, 0.5f}, {1.5f, 1.5f, 1.5f}};      // four levels up
  boxes[13] = {{-std::numeric_limits<float>::infinity(), 0, 0}, {0, 0.1f, 0.1f}};  // oversize
  boxes[14] = {{std::numeric_limits<float>::quiet_NaN(), 0, 0}, {0, 0, 0}};        // never overlaps
  // The calls: the boxes with the NaN one (a fresh order), the same without it (fresh: the
  // item set grew), again (the kept order), every 7th body moved a quarter of the domain on.
  std::vector<Aabb> finite = boxes;
  finite[14] = {{0.1f, 0.2f, 0.3f}, {0.15f, 0.25f, 0.35f}};
  std::vector<Aabb> moved = finite;
  for (std::size_t i = 20; i < moved.size(); i += 7) moved[i] = translated(moved[i], {0.9f, -0.4f, 0.3f});
  // Then every body nudged along x by up to 1 cm: most stay in their node, their order by
  // min.x changes (the strict octree's kept order re-sorted by insertion within nodes).
  std::vector<Aabb> nudged = moved;
  for (std::size_t i = 0; i < nudged.size(); ++i)
    nudged[i] = translated(nudged[i], {static_cast<float>((i * 7919) % 101) * 2e-4f - 0.01f, 0.0f, 0.0f});
  const std::vector<std::vector<Aabb>> frames = {boxes, finite, finite, moved, nudged};
  std::vector<std::vector<Pair>> wants;
  for (const auto& frame : frames) wants.push_back(brute(frame));
  for (const char* name : {"spatial-hash", "octree-strict"}) {
    std::vector<std::uint64_t> candidates;
    for (int threads : {1, 2, 3}) {
      const ThreadCount at(threads);
      auto bp = make_broadphase({name, -1, 0.25f}, kDomain);
      std::vector<Pair> got;
      BroadPhaseStats st;
      for (std::size_t call = 0; call < frames.size(); ++call) {
        bp->find_pairs(frames[call], got, st);
        EXPECT_TRUE(got == wants[call]) << name << ", " << threads << " threads, call " << call << ": "
                                        << describe_diff(got, wants[call]);
        candidates.push_back(st.cell_candidates);
      }
    }
    for (std::size_t k = frames.size(); k < candidates.size(); ++k)
      EXPECT_EQ(candidates[k], candidates[k % frames.size()]) << name << " " << k;
  }
}

// The pair sort every broadphase ends with (core/src/broadphase_detail.hpp) against
// std::sort, on one thread and on the bucket path with thread counts that leave buckets
// of unequal width: random pairs in input order, a body in pairs with most others (a run
// of one `a` far longer than insertion's, as a floor in a pile gives), pairs only near the
// ends of the body range (empty buckets), duplicates, and fewer bodies than buckets.
TEST(BroadPhase, PairSortGivesStdSortsOrderOnOneThreadAndInBuckets) {
  std::mt19937 rng(2026);
  const auto random_pairs = [&](std::size_t n, std::size_t m, std::uint32_t lo, std::uint32_t hi) {
    std::uniform_int_distribution<std::uint32_t> body(lo, hi - 1);
    std::vector<Pair> pairs;
    while (pairs.size() < m) {
      std::uint32_t a = body(rng), b = body(rng);
      if (a == b || a >= n || b >= n) continue;
      pairs.push_back({std::min(a, b), std::max(a, b)});
    }
    return pairs;
  };
  std::vector<std::pair<std::string, std::pair<std::size_t, std::vector<Pair>>>> cases;
  cases.push_back({"random", {50000, random_pairs(50000, 200000, 0, 50000)}});
  std::vector<Pair> floor = random_pairs(40000, 60000, 0, 40000);
  for (std::uint32_t b = 2; b < 40000; b += 2) floor.push_back({1, b});
  std::shuffle(floor.begin(), floor.end(), rng);
  cases.push_back({"a floor's run", {40000, floor}});
  std::vector<Pair> ends = random_pairs(100000, 40000, 0, 300);
  for (const Pair& p : random_pairs(100000, 40000, 99700, 100000)) ends.push_back(p);
  cases.push_back({"the ends only", {100000, ends}});
  std::vector<Pair> twice = random_pairs(30000, 50000, 0, 30000);
  twice.insert(twice.end(), twice.begin(), twice.begin() + 20000);
  cases.push_back({"duplicates", {30000, twice}});
  cases.push_back({"three bodies", {3, random_pairs(3, 70000, 0, 3)}});
  for (const auto& [name, c] : cases) {
    const auto& [n, pairs] = c;
    std::vector<Pair> want = pairs;
    std::sort(want.begin(), want.end());
    for (const unsigned threads : {1u, 2u, 3u, 7u, 16u, 64u}) {
      std::vector<Pair> got = pairs, tmp;
      std::vector<std::uint32_t> count;
      detail::sort_pairs(got, n, tmp, count, threads);
      EXPECT_TRUE(got == want) << name << ", " << threads << " threads: " << describe_diff(got, want);
    }
  }
}

// ---- the loose octree's pair cache (broadphase_octree_cache.cpp, steps 6-7) -----

/// Host model of the cache's fattened boxes: every box grown by 1/8 of the median largest
/// side (finite, > 0) of at most 1023 bodies spaced evenly in body order.
std::vector<Aabb> fattened(const std::vector<Aabb>& boxes) {
  std::vector<float> sizes;
  const std::size_t stride = boxes.size() / 1023 + 1;
  for (std::size_t i = 0; i < boxes.size(); i += stride) {
    const Aabb& b = boxes[i];
    const float e = std::max({b.max.x - b.min.x, b.max.y - b.min.y, b.max.z - b.min.z});
    if (e > 0.0f && e <= 3.4e38f) sizes.push_back(e);
  }
  std::nth_element(sizes.begin(), sizes.begin() + static_cast<std::ptrdiff_t>(sizes.size() / 2), sizes.end());
  const float d = sizes.empty() ? 0.0f : 0.125f * sizes[sizes.size() / 2];
  std::vector<Aabb> out;
  for (const Aabb& b : boxes) out.push_back(expanded(b, d));
  return out;
}

/// The kept pairs filtered by the boxes (what a hit returns).
std::vector<Pair> filtered(const std::vector<Pair>& kept, const std::vector<Aabb>& boxes) {
  std::vector<Pair> out;
  for (const Pair p : kept) {
    if (overlaps(boxes[p.a], boxes[p.b])) out.push_back(p);
  }
  return out;
}

// One instance over a motion sequence: every answer equals brute force, through every
// path (first call, build, hits, updates of escaped bodies, a NaN body, rebuilds). The
// kept set is checked against the host model (the fattened boxes' pairs), and the faults
// the cache must not have are planted in the model and shown to give a wrong answer on
// this sequence: no containment check (a stale cache), and an update that re-queries an
// escaped body against the tree's build-time boxes only (missing a body that escaped
// before it).
TEST(BroadPhase, LooseOctreePairCacheMatchesBruteForceOverAMotionSequence) {
  std::vector<Aabb> boxes = random_boxes(3000, 5);
  boxes[400] = {{-3.0f, -0.4f, -3.0f}, {3.0f, -0.3f, 3.0f}};  // floor slab (overflow list)
  const std::size_t n = boxes.size();
  auto bp = make_broadphase({"octree", -1, 0.25f}, kDomain);
  std::vector<Pair> got;
  BroadPhaseStats st;
  const auto call = [&](const std::string& what) {
    SCOPED_TRACE(what);
    bp->find_pairs(boxes, got, st);
    const std::vector<Pair> want = brute(boxes);
    expect_well_formed(got, n);
    EXPECT_TRUE(got == want) << describe_diff(got, want);
    EXPECT_EQ(st.pairs, want.size());
  };
  const auto plain_candidates = [&] {
    std::vector<Pair> p;
    BroadPhaseStats s;
    make_broadphase({"octree", -1, 0.25f}, kDomain)->find_pairs(boxes, p, s);
    return s.cell_candidates;
  };
  call("first call");
  call("build");
  // Hits: the kept pairs are those of the fattened boxes of the build.
  const std::vector<Aabb> before_moves = boxes;
  const std::vector<Aabb> fat0 = fattened(boxes);
  const std::vector<Pair> kept0 = brute(fat0);
  ASSERT_GT(kept0.size(), brute(boxes).size()) << "the margin must add pairs";
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> drift(-0.0005f, 0.0005f);
  for (int f = 0; f < 6; ++f) {
    for (Aabb& b : boxes) b = translated(b, {drift(rng), drift(rng), drift(rng)});
    call("drift " + std::to_string(f));
    EXPECT_EQ(st.cell_candidates, kept0.size()) << "a hit re-tests the kept pairs only";
  }
  // Body a leaves its fattened box: an update (far fewer tests than a tree).
  const std::uint32_t a = 100, b = 200, c = 300;
  const Vec3 p{0.5f, 0.5f, 0.3f};
  boxes[a] = {{p.x - 0.05f, p.y - 0.05f, p.z - 0.05f}, {p.x + 0.05f, p.y + 0.05f, p.z + 0.05f}};
  call("a escapes");
  EXPECT_LT(st.cell_candidates, plain_candidates() / 2) << "an update, not a rebuild";
  // Body b lands on a: the pair is found although a's box in the tree is the build's.
  boxes[b] = {{p.x - 0.02f, p.y, p.z}, {p.x + 0.02f, p.y + 0.08f, p.z + 0.01f}};
  call("b lands on a");
  EXPECT_LT(st.cell_candidates, plain_candidates() / 2) << "an update, not a rebuild";
  EXPECT_TRUE(std::binary_search(got.begin(), got.end(), Pair{a, b}));
  {
    // Planted fault: b re-queried against the build-time fattened boxes only.
    std::vector<Aabb> stale = fat0;
    stale[b] = fattened(boxes)[b];
    std::vector<Pair> faulty = filtered(brute(stale), boxes);
    EXPECT_FALSE(std::binary_search(faulty.begin(), faulty.end(), Pair{a, b}))
        << "the planted fault must lose the pair (a, b)";
    EXPECT_FALSE(faulty == got);
  }
  // Body e lands on the slab (found through the overflow run); body g, which has pairs,
  // moves just past the margin: its new pairs replace its kept ones (none twice).
  const std::uint32_t e = 500;
  boxes[e] = {{1.0f, -0.31f, 0.2f}, {1.05f, -0.26f, 0.25f}};
  call("e lands on the slab");
  EXPECT_TRUE(std::binary_search(got.begin(), got.end(), Pair{400, e}));
  std::uint32_t g = 0;
  for (const Pair q : got) {
    if (q.a > 600 && q.a != e && q.b != 400) {
      g = q.a;
      break;
    }
  }
  ASSERT_GT(g, 0u);
  const std::vector<Aabb> fat_now = fattened(before_moves);
  boxes[g] = translated(boxes[g], {fat_now[g].max.x - before_moves[g].max.x + 0.004f, 0.0f, 0.0f});
  call("g nudged out");
  EXPECT_LT(st.cell_candidates, plain_candidates() / 2) << "an update, not a rebuild";
  // A NaN box overlaps nothing and keeps the cache; back in place it is a hit again.
  const Aabb saved_c = boxes[c];
  boxes[c].min.y = std::numeric_limits<float>::quiet_NaN();
  call("c is NaN");
  boxes[c] = saved_c;
  call("c back");
  // Every body jumps by up to 8 cm: a rebuild; a cache kept without the
  // containment check (planted fault) gives a wrong answer here.
  const std::vector<Aabb> before = boxes;
  std::uniform_real_distribution<float> jump(-0.08f, 0.08f);
  for (Aabb& x : boxes) x = translated(x, {jump(rng), jump(rng), jump(rng)});
  {
    const std::vector<Pair> stale = filtered(brute(fattened(before)), boxes);
    EXPECT_FALSE(stale == brute(boxes)) << "the planted fault (no containment check) must be caught";
  }
  call("teleport");
  call("hit after the rebuild");
  // A body grows over the whole domain (too many cells to re-query: a rebuild), then
  // becomes infinite (overflow list).
  boxes[c] = {{-3.0f, -3.0f, -3.0f}, {3.0f, 3.0f, 3.0f}};
  call("c covers the domain");
  const float inf = std::numeric_limits<float>::infinity();
  boxes[c] = {{-inf, -inf, -inf}, {inf, inf, inf}};
  call("c infinite");
  call("same boxes again");
}

// Incoherent input (a new random set on every call): every answer equals brute force, and
// the cache is built less and less often (calls 2, 5, 10, then after 8 and 16 calls of
// the tree on the boxes): a build is the call whose candidates differ from those of a
// fresh instance's first call on the same boxes. Planted fault: without the back-off
// (a build after every useless cache and one plain call) builds would come at 2, 4, 6, ...
TEST(BroadPhase, LooseOctreeBacksOffOnIncoherentInput) {
  auto bp = make_broadphase({"octree", -1, 0.25f}, kDomain);
  std::vector<int> builds;
  for (int call = 1; call <= 20; ++call) {
    const std::vector<Aabb> boxes = random_boxes(1500, 1000u + static_cast<unsigned>(call));
    std::vector<Pair> got, fresh;
    BroadPhaseStats st, fs;
    bp->find_pairs(boxes, got, st);
    const std::vector<Pair> want = brute(boxes);
    EXPECT_TRUE(got == want) << "call " << call << ": " << describe_diff(got, want);
    make_broadphase({"octree", -1, 0.25f}, kDomain)->find_pairs(boxes, fresh, fs);
    if (st.cell_candidates != fs.cell_candidates) builds.push_back(call);
  }
  EXPECT_EQ(builds, (std::vector<int>{2, 5, 10, 19}));
}

}  // namespace
}  // namespace octocd_test_broadphase
}  // namespace octocd
