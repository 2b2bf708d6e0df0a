// Batched worlds (core/include/octocd/worlds.hpp): K copies of a scene as one world.
// The oracle: every copy of a batched run equals, bit for bit, the single-world run of the
// same scene translated by the copy's offset (and copy 0, at offset zero, the plain run).
#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

#include "octocd/broadphase.hpp"
#include "octocd/error.hpp"
#include "octocd/scene.hpp"
#include "octocd/world.hpp"
#include "octocd/worlds.hpp"
#include "support/test_scenes.hpp"

// This file's own names (its tests compile in unity batches with the folder's other files).
namespace octocd_test_worlds {

using namespace octocd;

namespace {

std::string scene_path(const std::string& name) {
  const char* src = std::getenv("OCTOCD_SOURCE_DIR");
  return std::string(src ? src : ".") + "/datasets/scenes/" + name + ".json";
}

std::shared_ptr<const Model> box_stack() { return build_model(load_scene(scene_path("box-stack"))); }

/// Boxes thrown into an open box (tests/support/test_scenes.hpp): they fly, hit the side
/// walls and each other, so their x and z change (a translation then rounds differently
/// from the untranslated run).
std::shared_ptr<const Model> thrown_boxes() { return build_model(test::mixed_boxes()); }

/// Steps a cpu engine on `model` for `frames` frames; returns its state and the largest
/// contact count of a frame.
BodyState run(std::shared_ptr<const Model> model, int frames, std::uint64_t* max_contacts = nullptr) {
  World w(model, make_broadphase(model->scene.broadphase, model->scene.domain));
  std::uint64_t most = 0;
  for (int f = 0; f < frames; ++f) most = std::max(most, w.step().contacts);
  if (max_contacts) *max_contacts = most;
  return w.state();
}

bool same_bits(const std::vector<Vec3>& a, const std::vector<Vec3>& b) {
  return a.size() == b.size() && std::memcmp(a.data(), b.data(), a.size() * sizeof(Vec3)) == 0;
}

}  // namespace

TEST(Worlds, CopiesOfThrownBoxesEqualTheSingleWorldRunTranslatedBitForBit) {
  const auto single = thrown_boxes();
  const std::size_t n = single->initial.size();
  WorldsSpec spec;
  spec.count = 6;  // a 3 x 2 grid: copies along x and z
  const WorldsLayout layout = worlds_layout(*single, spec);
  ASSERT_EQ(layout.nx, 3);
  ASSERT_EQ(layout.nz, 2);
  const auto batched = make_worlds_model(single, spec);
  ASSERT_EQ(batched->initial.size(), 6 * n);
  const int frames = 300;
  std::uint64_t contacts_single = 0, contacts_batched = 0;
  const BodyState plain = run(single, frames, &contacts_single);
  const BodyState all = run(batched, frames, &contacts_batched);
  ASSERT_GT(contacts_single, 0u) << "the stack rests on contacts: a run without any tests nothing";
  EXPECT_GE(contacts_batched, contacts_single);
  // Copy 0 sits at offset zero: the plain run, bit for bit.
  const BodyState c0 = world_state(all, n, 0);
  EXPECT_TRUE(same_bits(c0.x, plain.x));
  EXPECT_TRUE(same_bits(c0.v, plain.v));
  int differs = 0;
  for (std::size_t c = 1; c < 6; ++c) {
    // The oracle of copy c: the scene alone, translated by the same offset.
    const auto alone = make_worlds_model(*single, {layout.offsets[c]}, spec);
    const BodyState want = run(alone, frames);
    const BodyState got = world_state(all, n, c);
    EXPECT_TRUE(same_bits(got.x, want.x)) << "copy " << c;
    EXPECT_TRUE(same_bits(got.v, want.v)) << "copy " << c;
    // The offset's rounding makes a difference: the plain run's bits do not carry over.
    const BodyState back = world_state(all, n, c);
    bool all_same = true;
    for (std::size_t i = 0; i < n; ++i) {
      const Vec3 d = back.x[i] - layout.offsets[c] - plain.x[i];
      all_same = all_same && d.x == 0.0f && d.z == 0.0f;
    }
    differs += all_same ? 0 : 1;
  }
  EXPECT_GT(differs, 0) << "some offset rounds differently (else the oracle above is the plain run)";
  EXPECT_TRUE(worlds_escaped(*batched, layout, spec.margin, all).empty());
}

TEST(Worlds, NoPairJoinsTwoCopies) {
  const auto single = box_stack();
  const std::size_t n = single->initial.size();
  WorldsSpec spec;
  spec.count = 9;
  const auto batched = make_worlds_model(single, spec);
  std::vector<Aabb> boxes;
  for (std::size_t i = 0; i < batched->initial.size(); ++i)
    boxes.push_back(translated(batched->local_box(i), batched->initial.x[i]));
  BroadPhaseConfig flat;
  flat.name = "flat";
  std::vector<Pair> pairs;
  BroadPhaseStats stats;
  make_broadphase(flat, batched->scene.domain)->find_pairs(boxes, pairs, stats);
  ASSERT_FALSE(pairs.empty());  // the stacked boxes touch each other and the floor
  for (const Pair& p : pairs) EXPECT_EQ(p.a / n, p.b / n) << "pair " << p.a << ", " << p.b;
  // Every copy's bodies lie in its cell; one moved into its neighbour's cell is reported.
  const WorldsLayout layout = worlds_layout(*single, spec);
  EXPECT_TRUE(worlds_escaped(*batched, layout, spec.margin, batched->initial).empty());
  BodyState moved = batched->initial;
  moved.x[4 * n + n - 1].x += layout.spacing.x;
  EXPECT_EQ(worlds_escaped(*batched, layout, spec.margin, moved), std::vector<long>{4});
}

TEST(Worlds, PerturbationMovesDynamicBodiesOfCopiesAfterTheFirstWithinEps) {
  const auto single = box_stack();
  const std::size_t n = single->initial.size();
  WorldsSpec spec;
  spec.count = 5;
  spec.perturb = 1e-3;
  spec.seed = 7;
  const auto a = make_worlds_model(single, spec);
  const auto b = make_worlds_model(single, spec);
  EXPECT_TRUE(same_bits(a->initial.x, b->initial.x)) << "the same seed gives the same copies";
  spec.seed = 8;
  const auto other = make_worlds_model(single, spec);
  EXPECT_FALSE(same_bits(a->initial.x, other->initial.x)) << "another seed gives other copies";
  const WorldsLayout layout = worlds_layout(*single, spec);
  std::size_t moved = 0;
  for (std::size_t c = 0; c < 5; ++c)
    for (std::size_t i = 0; i < n; ++i) {
      const Vec3 x = a->initial.x[c * n + i];
      const Vec3 want = single->initial.x[i] + layout.offsets[c];
      if (c == 0 || single->initial.w[i] == 0.0f) {
        EXPECT_TRUE(x.x == want.x && x.y == want.y && x.z == want.z) << "copy " << c << " body " << i;
        continue;
      }
      const Vec3 d = x - want;
      // eps plus the rounding of the offset (ulp of a few m).
      EXPECT_LE(std::max({std::fabs(d.x), std::fabs(d.y), std::fabs(d.z)}), 1e-3f + 1e-5f);
      if (d.x != 0.0f || d.y != 0.0f || d.z != 0.0f) ++moved;
    }
  EXPECT_EQ(moved, 4 * 4u) << "four dynamic boxes in each of copies 1..4";
}

TEST(Worlds, TheBatchedSceneHoldsEveryCopyAndKeepsTheOctreeCellSize) {
  const auto single = box_stack();
  WorldsSpec spec;
  spec.count = 1024;
  const auto batched = make_worlds_model(single, spec);
  EXPECT_EQ(batched->scene.walls, Walls::None);
  EXPECT_EQ(batched->scene.name, "box-stack x1024 worlds");
  for (std::size_t i = 0; i < batched->initial.size(); ++i)
    ASSERT_TRUE(contains(batched->scene.domain, translated(batched->local_box(i), batched->initial.x[i])));
  // box-stack's octree: depth 2 over a 2 m domain; the grid of 32 x 32 cells of
  // 2.7 m is 86 m a side: 2^6 times wider, six levels deeper.
  ASSERT_EQ(single->scene.broadphase.name, "octree");
  EXPECT_EQ(batched->scene.broadphase.octree_depth, single->scene.broadphase.octree_depth + 6);
}

TEST(Worlds, OutOfRangeRequestsNameTheOption) {
  const auto single = box_stack();
  auto message = [&](WorldsSpec spec) -> std::string {
    try {
      (void)worlds_layout(*single, spec);
    } catch (const InputError& e) {
      return e.what();
    }
    return "";
  };
  WorldsSpec s;
  s.count = 0;
  EXPECT_NE(message(s).find("--worlds: 0; allowed: [1, "), std::string::npos);
  s.count = 2;
  s.perturb = -1.0;
  EXPECT_NE(message(s).find("--world-perturb"), std::string::npos);
  s.perturb = 0.0;
  s.margin = 0.0;
  EXPECT_NE(message(s).find("--world-margin"), std::string::npos);
  s.margin = 0.5;
  s.count = kMaxWorlds;  // 1024 x 1024 cells of 2.7 m: far past 1000 m
  const std::string far = message(s);
  EXPECT_NE(far.find("--worlds"), std::string::npos) << far;
  EXPECT_NE(far.find("|coordinate| <= 1000 m"), std::string::npos) << far;
  EXPECT_NE(far.find("at most 136900 copies"), std::string::npos) << far;
}

TEST(Worlds, ACopyAloneStartsWhereItsBatchedCopyStartsBeforeTheTranslation) {
  const auto single = thrown_boxes();
  const std::size_t n = single->initial.size();
  WorldsSpec spec;
  spec.count = 4;
  spec.perturb = 1e-3;
  spec.seed = 11;
  const WorldsLayout layout = worlds_layout(*single, spec);
  const auto batched = make_worlds_model(*single, layout.offsets, spec);
  for (std::size_t c = 0; c < 4; ++c) {
    const auto alone = worlds_copy_model(*single, spec, c);
    ASSERT_EQ(alone->initial.size(), n);
    EXPECT_TRUE(same_bits(alone->initial.v, single->initial.v));
    std::vector<Vec3> moved;
    for (const Vec3& x : alone->initial.x) moved.push_back(x + layout.offsets[c]);
    EXPECT_TRUE(same_bits(moved, world_state(batched->initial, n, c).x)) << "copy " << c;
    EXPECT_EQ(same_bits(alone->initial.x, single->initial.x), c == 0) << "copy " << c;
  }
}

}  // namespace octocd_test_worlds
