// Reference broadphases (design.md section 5.1, reference/): every Bullet and FCL reference returns
// exactly the pairs of `flat`, on the first call and incrementally after every body moved.
// Parameterised over (name, body count) in the style of FCL's test_fcl_broadphase_collision,
// but comparing whole sorted pair vectors (not just counts) against octocd's oracle, with
// bodies outside the domain and exact face contacts.

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <string>
#include <tuple>
#include <vector>

#include "octocd/broadphase.hpp"
#include "octocd/error.hpp"
#include "octocd/reference_broadphase.hpp"
#include "support/doc_broadphases.hpp"

namespace octocd {
namespace octocd_test_reference_broadphase {
namespace {

const Aabb kDomain{{-2.0f, 0.0f, -1.0f}, {2.0f, 1.0f, 1.0f}};

/// A body of side `w` whose min corner on `axis` is exactly `b`'s max there: the two
/// touch face to face (inclusive rule: they overlap).
Aabb touching(const Aabb& b, int axis, float w) {
  Aabb t = b;
  if (axis == 0) { t.min.x = b.max.x; t.max.x = b.max.x + w; }
  if (axis == 1) { t.min.y = b.max.y; t.max.y = b.max.y + w; }
  if (axis == 2) { t.min.z = b.max.z; t.max.z = b.max.z + w; }
  return t;
}

Aabb box_at(Vec3 c, Vec3 h) { return {{c.x - h.x, c.y - h.y, c.z - h.z}, {c.x + h.x, c.y + h.y, c.z + h.z}}; }

/// n random boxes (fixed seed): sizes spread over two orders of magnitude plus a few
/// large ones, ~10% centred outside the domain (some far outside), ~10% exactly
/// touching the previous box on a face, a few zero-size ones.
std::vector<Aabb> random_boxes(std::size_t n, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> ux(-2.0f, 2.0f), uy(0.0f, 1.0f), uz(-1.0f, 1.0f);
  std::uniform_real_distribution<float> u01(0.0f, 1.0f);
  const float base = 0.9f * std::cbrt(1.0f / static_cast<float>(n));
  std::vector<Aabb> boxes;
  boxes.reserve(n);
  while (boxes.size() < n) {
    const float r = u01(rng);
    if (r < 0.1f && !boxes.empty()) {
      boxes.push_back(touching(boxes.back(), static_cast<int>(rng() % 3), base * (0.2f + u01(rng))));
      continue;
    }
    Vec3 c{ux(rng), uy(rng), uz(rng)};
    if (r < 0.2f) c = {c.x * 3.0f, c.y * 5.0f - 2.0f, c.z * 4.0f};      // outside (mostly)
    if (r < 0.22f) c = {c.x * 40.0f, c.y + 30.0f, c.z - 25.0f};        // far outside
    float s = base * (0.1f + 1.5f * u01(rng) * u01(rng));
    if (r > 0.99f) s = base * 6.0f;                                    // large
    if (r > 0.985f && r <= 0.99f) s = 0.0f;                            // zero size
    boxes.push_back(box_at(c, {s * (0.5f + u01(rng)), s * (0.5f + u01(rng)), s * (0.5f + u01(rng))}));
  }
  return boxes;
}

/// Moves every body: most by a small step, some teleported; touching pairs are rebuilt
/// so that exact face contacts exist in the moved frame too.
std::vector<Aabb> moved(const std::vector<Aabb>& in, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> step(-0.05f, 0.05f), u01(0.0f, 1.0f);
  std::vector<Aabb> out = in;
  for (std::size_t i = 0; i < out.size(); ++i) {
    Vec3 d{step(rng), step(rng), step(rng)};
    if (u01(rng) < 0.05f) d = {40.0f * step(rng), 20.0f * step(rng), 40.0f * step(rng)};
    out[i] = {out[i].min + d, out[i].max + d};
    if (i > 0 && u01(rng) < 0.1f) {
      out[i] = touching(out[i - 1], static_cast<int>(rng() % 3), out[i].max.x - out[i].min.x);
    }
  }
  return out;
}

std::vector<Pair> oracle(const std::vector<Aabb>& boxes) {
  BroadPhaseConfig config;
  config.name = "flat";
  auto flat = make_broadphase(config, kDomain);
  std::vector<Pair> pairs;
  BroadPhaseStats stats;
  flat->find_pairs(boxes, pairs, stats);
  return pairs;
}

/// Well-formed (a < b < n, strictly ascending hence unique) and equal to the oracle; on
/// failure reports the first missing and the first extra pair.
void expect_same(const std::vector<Pair>& got, const std::vector<Pair>& want, std::size_t n,
                 const std::string& what) {
  for (std::size_t k = 0; k < got.size(); ++k) {
    ASSERT_LT(got[k].a, got[k].b) << what << ": pair " << k;
    ASSERT_LT(got[k].b, n) << what << ": pair " << k;
    if (k > 0) {
      ASSERT_TRUE(got[k - 1] < got[k]) << what << ": not sorted/unique at " << k;
    }
  }
  if (got == want) return;
  std::vector<Pair> missing, extra;
  std::set_difference(want.begin(), want.end(), got.begin(), got.end(), std::back_inserter(missing));
  std::set_difference(got.begin(), got.end(), want.begin(), want.end(), std::back_inserter(extra));
  ADD_FAILURE() << what << ": " << got.size() << " pairs, flat has " << want.size() << "; "
                << missing.size() << " missing"
                << (missing.empty() ? std::string() : " e.g. (" + std::to_string(missing[0].a) + ", " + std::to_string(missing[0].b) + ")")
                << ", " << extra.size() << " extra"
                << (extra.empty() ? std::string() : " e.g. (" + std::to_string(extra[0].a) + ", " + std::to_string(extra[0].b) + ")");
}

using Param = std::tuple<std::string, std::size_t>;

class ReferenceBroadPhase : public ::testing::TestWithParam<Param> {};

TEST_P(ReferenceBroadPhase, EqualsFlatFirstCallAndIncrementally) {
  const auto& [name, n] = GetParam();
  BroadPhaseConfig config;
  config.name = name;
  config.cell_size = 0.9f * std::cbrt(1.0f / static_cast<float>(n)) * 2.0f;  // ~2 mean sizes
  auto bp = make_reference_broadphase(config, kDomain);
  ASSERT_EQ(bp->name(), name);

  std::vector<Aabb> boxes = random_boxes(n, 1234u + static_cast<unsigned>(n));
  std::vector<Pair> got;
  BroadPhaseStats stats;
  for (int frame = 0; frame < 3; ++frame) {
    if (frame > 0) boxes = moved(boxes, 99u * static_cast<unsigned>(frame) + static_cast<unsigned>(n));
    const std::vector<Pair> want = oracle(boxes);
    ASSERT_GT(want.size(), n / 10) << "data set too sparse to test anything";
    got.assign(3, Pair{0, 0});  // stale content must be cleared
    bp->find_pairs(boxes, got, stats);
    expect_same(got, want, n, name + " n=" + std::to_string(n) + " frame " + std::to_string(frame));
    EXPECT_EQ(stats.pairs, got.size());
    EXPECT_GE(stats.cell_candidates, stats.pairs);
  }
}

std::vector<Param> params() {
  std::vector<Param> out;
  for (const std::string& name : reference_broadphase_names()) {
    for (std::size_t n : {100u, 1000u, 10000u}) {
      // fcl-naive is O(n^2) in FCL's double Eigen AABB test: capped at 1000 bodies.
      if (name == "fcl-naive" && n > 1000) continue;
      out.emplace_back(name, n);
    }
  }
  return out;
}

INSTANTIATE_TEST_SUITE_P(All, ReferenceBroadPhase, ::testing::ValuesIn(params()),
                         [](const ::testing::TestParamInfo<Param>& p) {
                           std::string s = std::get<0>(p.param) + "_" +
                                           std::to_string(std::get<1>(p.param));
                           std::replace(s.begin(), s.end(), '-', '_');
                           return s;
                         });

TEST(ReferenceBroadPhaseRegistry, NamesAndErrors) {
  // The rows docs/architecture.md's broadphase table gives the CPU library bullet or fcl.
  const std::vector<std::string> expected = octocd::test::doc_broadphase_names(
      [](const octocd::test::DocBroadPhase& r) { return r.cpu == "bullet" || r.cpu == "fcl"; });
  ASSERT_FALSE(expected.empty()) << "docs/architecture.md: the broadphase table";
  EXPECT_EQ(reference_broadphase_names(), expected);
  std::vector<std::string> all = broadphase_names();
  all.insert(all.end(), expected.begin(), expected.end());
  EXPECT_EQ(all_broadphase_names(), all);

  BroadPhaseConfig config;
  for (const std::string& name : all) {
    config.name = name;
    EXPECT_EQ(make_any_broadphase(config, kDomain)->name(), name);
  }
  config.name = "octree";
  EXPECT_THROW(make_reference_broadphase(config, kDomain), InputError);
  config.name = "bullet-nope";
  try {
    make_any_broadphase(config, kDomain);
    ADD_FAILURE() << "no throw";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("broadphase.name"), std::string::npos);
    EXPECT_NE(std::string(e.what()).find("fcl-naive"), std::string::npos);
  }
  config.name = "fcl-spatial-hash";
  config.cell_size = 0.0f;
  EXPECT_THROW(make_reference_broadphase(config, kDomain), InputError);
}

TEST(ReferenceBroadPhaseRegistry, BodyCountChangeThrowsAndEmptyWorks) {
  for (const std::string& name : reference_broadphase_names()) {
    BroadPhaseConfig config;
    config.name = name;
    auto bp = make_reference_broadphase(config, kDomain);
    std::vector<Pair> out;
    BroadPhaseStats stats;
    bp->find_pairs({}, out, stats);
    EXPECT_TRUE(out.empty()) << name;
    auto bp2 = make_reference_broadphase(config, kDomain);
    const std::vector<Aabb> two = {box_at({0, 0.5f, 0}, {0.1f, 0.1f, 0.1f}),
                                   touching(box_at({0, 0.5f, 0}, {0.1f, 0.1f, 0.1f}), 1, 0.2f)};
    bp2->find_pairs(two, out, stats);
    EXPECT_EQ(out, (std::vector<Pair>{{0, 1}})) << name << ": touching faces overlap";
    EXPECT_THROW(bp2->find_pairs({two[0]}, out, stats), InputError) << name;
  }
}

}  // namespace
}  // namespace octocd_test_reference_broadphase
}  // namespace octocd
