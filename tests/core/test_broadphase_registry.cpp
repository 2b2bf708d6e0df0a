// The broadphase registry (core/include/octocd/broadphase_registry.hpp, the rows of
// core/include/octocd/broadphase_table.def) against the factories that read it and the docs'
// table: every row with a CPU side is built by make_any_broadphase under its name and finds
// `flat`'s pair set; rows without one are refused; the table of docs/architecture.md
// ("Adding a broadphase") states what the registry states, row by row.
#include <gtest/gtest.h>

#include <random>
#include <set>
#include <string>
#include <vector>

#include "octocd/broadphase.hpp"
#include "octocd/broadphase_registry.hpp"
#include "octocd/error.hpp"
#include "octocd/reference_broadphase.hpp"
#include "support/doc_broadphases.hpp"

// This file's own names (its tests compile in unity batches with the folder's other files).
namespace octocd_test_broadphase_registry {

using namespace octocd;

namespace {

const char* host_word(BroadPhaseHost h) {
  switch (h) {
    case BroadPhaseHost::core: return "core";
    case BroadPhaseHost::bullet: return "bullet";
    case BroadPhaseHost::fcl: return "fcl";
    case BroadPhaseHost::none: return "none";
  }
  return "?";
}

const char* device_word(BroadPhaseDevice d) {
  switch (d) {
    case BroadPhaseDevice::none: return "none";
    case BroadPhaseDevice::step: return "step";
    case BroadPhaseDevice::seam: return "seam";
  }
  return "?";
}

const char* pairs_word(BroadPhasePairs p) {
  switch (p) {
    case BroadPhasePairs::oracle: return "oracle";
    case BroadPhasePairs::exact: return "exact";
    case BroadPhasePairs::filtered: return "filtered";
  }
  return "?";
}

/// 200 random boxes in the unit cube, sides up to 0.2 m, some touching exactly.
std::vector<Aabb> random_boxes() {
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> pos(0.0f, 1.0f), side(0.01f, 0.2f);
  std::vector<Aabb> boxes;
  for (int i = 0; i < 200; ++i) {
    const Vec3 lo{pos(rng), pos(rng), pos(rng)};
    const float s = side(rng);
    boxes.push_back({lo, {lo.x + s, lo.y + s, lo.z + s}});
  }
  boxes.push_back({boxes[0].max, {boxes[0].max.x + 0.1f, boxes[0].max.y + 0.1f, boxes[0].max.z + 0.1f}});
  return boxes;
}

}  // namespace

TEST(BroadPhaseRegistry, NamesAndIdsAreOneToOne) {
  std::set<std::string> names;
  for (std::size_t i = 0; i < broadphase_infos().size(); ++i) {
    const BroadPhaseInfo& info = broadphase_infos()[i];
    EXPECT_EQ(static_cast<std::size_t>(info.id), i) << info.name;
    EXPECT_TRUE(names.insert(info.name).second) << "twice: " << info.name;
    EXPECT_EQ(find_broadphase_info(info.name), &info);
    EXPECT_EQ(&broadphase_info(info.id), &info);
    EXPECT_FALSE(info.summary.empty()) << info.name;
    EXPECT_TRUE(info.on_cpu() || info.on_device()) << info.name << " runs nowhere";
  }
  EXPECT_EQ(find_broadphase_info("no-such-broadphase"), nullptr);
  // The CPU rows first, the device-only ones last (lists and help texts rely on it).
  std::vector<std::string> cpu_then_device = all_broadphase_names();
  for (const std::string& n : broadphase_names_where([](const BroadPhaseInfo& b) { return b.device_only(); }))
    cpu_then_device.push_back(n);
  EXPECT_EQ(every_broadphase_name(), cpu_then_device);
}

TEST(BroadPhaseRegistry, OneOracleWhichRunsOnBothSides) {
  int oracles = 0;
  for (const BroadPhaseInfo& info : broadphase_infos()) {
    if (info.pairs != BroadPhasePairs::oracle) continue;
    ++oracles;
    EXPECT_EQ(info.host, BroadPhaseHost::core) << info.name;
    EXPECT_TRUE(info.on_device()) << info.name;
    EXPECT_EQ(info.cost, BroadPhaseCost::quadratic) << info.name;
  }
  EXPECT_EQ(oracles, 1);
  EXPECT_EQ(BroadPhaseConfig{}.name, broadphase_name(BroadPhaseId::octree));  // the default
}

TEST(BroadPhaseRegistry, EveryCpuRowIsBuiltByItsNameAndFindsTheOraclesPairs) {
  const Aabb domain{{0.0f, 0.0f, 0.0f}, {1.3f, 1.3f, 1.3f}};
  const std::vector<Aabb> boxes = random_boxes();
  BroadPhaseConfig oracle_cfg;
  oracle_cfg.name = broadphase_name(BroadPhaseId::flat);
  std::vector<Pair> want;
  BroadPhaseStats stats;
  make_broadphase(oracle_cfg, domain)->find_pairs(boxes, want, stats);
  ASSERT_GT(want.size(), 10u);
  std::size_t built = 0;
  for (const BroadPhaseInfo& info : broadphase_infos()) {
    BroadPhaseConfig cfg;
    cfg.name = info.name;
    if (!info.on_cpu()) {
      EXPECT_THROW(make_any_broadphase(cfg, domain), InputError) << info.name;
      continue;
    }
    if (info.host == BroadPhaseHost::core) EXPECT_NO_THROW(make_broadphase(cfg, domain)) << info.name;
    else EXPECT_THROW(make_broadphase(cfg, domain), InputError) << info.name;
    auto bp = make_any_broadphase(cfg, domain);
    ASSERT_TRUE(bp) << info.name;
    EXPECT_EQ(bp->name(), info.name);
    std::vector<Pair> got;
    bp->find_pairs(boxes, got, stats);
    EXPECT_EQ(got, want) << info.name;
    ++built;
  }
  EXPECT_EQ(built, all_broadphase_names().size());
}

TEST(BroadPhaseRegistry, UnknownNamesAreRefusedNamingTheRows) {
  BroadPhaseConfig cfg;
  cfg.name = "no-such-broadphase";
  try {
    make_any_broadphase(cfg, Aabb{{0, 0, 0}, {1, 1, 1}});
    FAIL() << "accepted";
  } catch (const InputError& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find("broadphase.name"), std::string::npos) << msg;
    for (const std::string& name : all_broadphase_names()) EXPECT_NE(msg.find(name), std::string::npos) << msg;
  }
}

TEST(BroadPhaseRegistry, DocsTableStatesTheRegistry) {
  const std::vector<test::DocBroadPhase> rows = test::doc_broadphases();
  ASSERT_EQ(rows.size(), broadphase_infos().size())
      << "docs/architecture.md, section \"Adding a broadphase\": its table must list the rows of "
      << "core/include/octocd/broadphase_table.def, in order";
  for (std::size_t i = 0; i < rows.size(); ++i) {
    const BroadPhaseInfo& info = broadphase_infos()[i];
    const test::DocBroadPhase& r = rows[i];
    EXPECT_EQ(r.name, info.name) << "row " << i;
    EXPECT_EQ(r.cpu, host_word(info.host)) << info.name;
    EXPECT_EQ(r.device, device_word(info.device)) << info.name;
    EXPECT_EQ(r.promise, pairs_word(info.pairs)) << info.name;
    EXPECT_EQ(r.cost, info.cost == BroadPhaseCost::quadratic ? "quadratic" : "subquadratic") << info.name;
  }
  // The lists the CLI, Python and the engines show, as the docs' table states them.
  EXPECT_EQ(all_broadphase_names(), test::doc_broadphase_names([](const test::DocBroadPhase& r) {
              return r.cpu != "none";
            }));
  EXPECT_EQ(broadphase_names_where([](const BroadPhaseInfo& b) { return b.device_only(); }),
            test::doc_broadphase_names([](const test::DocBroadPhase& r) {
              return r.cpu == "none" && r.device != "none";
            }));
}

}  // namespace octocd_test_broadphase_registry
