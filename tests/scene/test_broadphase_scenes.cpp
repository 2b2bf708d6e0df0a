// Every broadphase returns exactly the `flat` pair set on frames of the dataset scenes
// (issue 2 item 7, design.md section 7.1): the world AABBs of recorded frames are replayed through each.
// Both octrees (`octree`, the loose one, and `octree-strict`) at several depths and
// `auto`; also on the 10,000-box benchmark scene (issue 6 item 5).
#include <gtest/gtest.h>

#include <cstdlib>
#include <filesystem>
#include <string>
#include <vector>

#include "octocd/broadphase.hpp"
#include "octocd/scene.hpp"
#include "octocd/world.hpp"

// This file's own names (its tests compile in unity batches with the folder's other files).
namespace octocd_test_broadphase_scenes {

using namespace octocd;

namespace {

std::string source_dir() {
  const char* root = std::getenv("OCTOCD_SOURCE_DIR");
  return root ? root : ".";
}

class BroadphaseOnScenes : public ::testing::TestWithParam<const char*> {};

}  // namespace

TEST_P(BroadphaseOnScenes, EveryBroadphaseEqualsFlatOnRecordedFrames) {
  const std::string name = GetParam();
  if (!std::filesystem::exists(source_dir() + "/datasets/cache/bunny.obj"))
    GTEST_SKIP() << "datasets not fetched (run datasets/fetch.sh)";
  Scene scene = load_scene(source_dir() + "/datasets/scenes/" + name + ".json");
  scene.midphase = MidphaseConfig::parse("aabb-only");  // fast frames; detection only
  World world(scene);
  std::vector<std::unique_ptr<BroadPhase>> phases;
  std::vector<std::string> labels;
  for (const std::string& bp : broadphase_names()) {
    BroadPhaseConfig cfg = scene.broadphase;
    cfg.name = bp;
    if (bp == "octree" || bp == "octree-strict") {
      for (int depth : {0, 2, 4, 7, 10, -1}) {
        cfg.octree_depth = depth;
        phases.push_back(make_broadphase(cfg, scene.domain));
        labels.push_back(bp + " depth " + std::to_string(depth));
      }
    } else {
      phases.push_back(make_broadphase(cfg, scene.domain));
      labels.push_back(bp);
    }
  }
  auto flat_cfg = scene.broadphase;
  flat_cfg.name = "flat";
  auto flat = make_broadphase(flat_cfg, scene.domain);
  std::vector<Pair> expected, got;
  std::size_t checked = 0, nonempty = 0;
  for (int frame = 1; frame <= 600; ++frame) {
    world.step();
    if (frame % 50 != 0) continue;
    BroadPhaseStats st;
    flat->find_pairs(world.world_aabbs(), expected, st);
    nonempty += expected.empty() ? 0 : 1;
    for (std::size_t i = 0; i < phases.size(); ++i) {
      phases[i]->find_pairs(world.world_aabbs(), got, st);
      ASSERT_EQ(got, expected) << labels[i] << " differs from flat at frame " << frame;
      ++checked;
    }
  }
  EXPECT_GT(nonempty, 0u) << "no frame had any pair: the comparison proved nothing";
  RecordProperty("comparisons", std::to_string(checked));
}

INSTANTIATE_TEST_SUITE_P(Datasets, BroadphaseOnScenes,
                         ::testing::Values("bunny-stack-50", "bunny-random-400",
                                           "armadillo-random-250", "dragon-random-250",
                                           "asian-dragon-random-60"),
                         [](const ::testing::TestParamInfo<const char*>& p) {
                           std::string s = p.param;
                           for (char& c : s)
                             if (c == '-') c = '_';
                           return s;
                         });

// The broadphase benchmark scene (no dataset needed): 10,006 bodies, walls included.
// One instance of each broadphase sees consecutive frames (its incremental path), and
// fresh instances see one frame (the from-scratch path).
TEST(BroadphaseOnBoxScene, EveryBroadphaseEqualsFlatOnBoxesRandom10000) {
  Scene scene = load_scene(source_dir() + "/datasets/scenes/boxes-random-10000.json");
  World world(scene);
  std::vector<std::unique_ptr<BroadPhase>> phases;
  std::vector<std::string> labels;
  for (const std::string& bp : broadphase_names()) {
    if (bp == "flat") continue;
    BroadPhaseConfig cfg = scene.broadphase;
    cfg.name = bp;
    for (int depth : {3, 5, -1}) {
      cfg.octree_depth = depth;
      phases.push_back(make_broadphase(cfg, scene.domain));
      labels.push_back(bp + " depth " + std::to_string(depth));
      if (bp != "octree" && bp != "octree-strict") break;
    }
  }
  auto flat_cfg = scene.broadphase;
  flat_cfg.name = "flat";
  auto flat = make_broadphase(flat_cfg, scene.domain);
  std::vector<Pair> expected, got;
  for (int frame = 1; frame <= 60; ++frame) {
    world.step();
    BroadPhaseStats st;
    for (std::size_t i = 0; i < phases.size(); ++i) phases[i]->find_pairs(world.world_aabbs(), got, st);
    if (frame % 20 != 0) continue;
    flat->find_pairs(world.world_aabbs(), expected, st);
    ASSERT_GT(expected.size(), 100u);
    for (std::size_t i = 0; i < phases.size(); ++i) {
      phases[i]->find_pairs(world.world_aabbs(), got, st);
      ASSERT_EQ(got, expected) << labels[i] << " differs from flat at frame " << frame;
      auto fresh_cfg = scene.broadphase;
      fresh_cfg.name = phases[i]->name();
      auto fresh = make_broadphase(fresh_cfg, scene.domain);
      fresh->find_pairs(world.world_aabbs(), got, st);
      ASSERT_EQ(got, expected) << "fresh " << labels[i] << " differs from flat at frame " << frame;
    }
  }
}

}  // namespace octocd_test_broadphase_scenes
