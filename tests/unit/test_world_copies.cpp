// Copies of a scene as separate runs (engines/include/octocd/world_copies.hpp): what `run
// --worlds K` does for engines that step one scene per run. Each copy's final state equals the
// copy run alone (worlds_copy_model, one engine, this thread), whatever the threads.
#include <gtest/gtest.h>

#include <cstdlib>
#include <cstring>
#include <string>

#include "octocd/broadphase.hpp"
#include "octocd/error.hpp"
#include "octocd/scene.hpp"
#include "octocd/world.hpp"
#include "octocd/world_copies.hpp"
#include "support/test_scenes.hpp"

// This file's own names (its tests compile in unity batches with the folder's other files).
namespace octocd_test_world_copies {

using namespace octocd;

namespace {

/// Boxes thrown into an open box (tests/support/test_scenes.hpp): they fly, hit the side
/// walls and each other, so their x and z change (a translation then rounds differently
/// from the untranslated run).
std::shared_ptr<const Model> thrown_boxes() { return build_model(test::mixed_boxes()); }

bool same_bits(const std::vector<Vec3>& a, const std::vector<Vec3>& b) {
  return a.size() == b.size() && std::memcmp(a.data(), b.data(), a.size() * sizeof(Vec3)) == 0;
}

}  // namespace

TEST(WorldCopies, EachCopyEqualsItsRunAloneOnAnyThreadCount) {
  const auto single = thrown_boxes();
  WorldsSpec spec;
  spec.count = 5;
  spec.perturb = 1e-3;
  spec.seed = 9;
  const int frames = 200;
  std::vector<BodyState> alone;
  for (std::size_t c = 0; c < 5; ++c) {
    const auto m = worlds_copy_model(*single, spec, c);
    World w(m, make_broadphase(m->scene.broadphase, m->scene.domain));
    for (int f = 0; f < frames; ++f) w.step();
    alone.push_back(w.state());
  }
  EXPECT_FALSE(same_bits(alone[0].x, alone[1].x)) << "perturbed copies end apart";
  for (const int threads : {1, 3}) {
    std::vector<std::int64_t> seen(5, 0);
    const CopiesRun r = run_copies_separately("cpu", single, spec, frames, threads, {},
                                              [&](std::size_t c, const FrameMetrics& m, const Engine&) {
                                                EXPECT_EQ(m.frame, seen[c] + 1) << "copy " << c;
                                                seen[c] = m.frame;
                                              });
    EXPECT_EQ(r.threads, threads);
    ASSERT_EQ(r.states.size(), 5u);
    for (std::size_t c = 0; c < 5; ++c) {
      EXPECT_EQ(r.frames[c], frames) << "copy " << c;
      EXPECT_EQ(seen[c], frames) << "copy " << c;
      EXPECT_TRUE(same_bits(r.states[c].x, alone[c].x)) << "copy " << c << ", " << threads << " threads";
      EXPECT_TRUE(same_bits(r.states[c].v, alone[c].v)) << "copy " << c << ", " << threads << " threads";
    }
  }
}

TEST(WorldCopies, AnEngineThatCannotBeMadeIsRethrown) {
  const auto single = thrown_boxes();
  WorldsSpec spec;
  spec.count = 3;
  EXPECT_THROW(run_copies_separately("no-such-engine", single, spec, 5, 2), InputError);
}

// An engine whose instances share unguarded process-wide state (EngineInfo::not_thread_safe:
// ODE, whose collision data is one per process) steps its copies one after another, whatever
// the threads asked, and each copy still equals its run alone.
TEST(WorldCopies, AnEngineThatIsNotThreadSafeRunsItsCopiesOneAtATime) {
  const EngineInfo& ode = engine_info("ode", "test");
  ASSERT_FALSE(ode.not_thread_safe.empty()) << "ODE's collision data is one per process (docs/engines.md)";
  EXPECT_TRUE(engine_info("cpu", "test").not_thread_safe.empty());
  if (!engine_built(ode)) GTEST_SKIP() << "ode is not built in this octocd";
  const auto single = thrown_boxes();
  WorldsSpec spec;
  spec.count = 4;
  spec.perturb = 1e-3;
  const int frames = 30;
  const CopiesRun r = run_copies_separately("ode", single, spec, frames, 4);
  EXPECT_EQ(r.threads, 1);
  for (std::size_t c = 0; c < 4; ++c) {
    auto e = make_engine("ode", worlds_copy_model(*single, spec, c));
    for (int f = 0; f < frames; ++f) e->step();
    EXPECT_EQ(r.frames[c], frames) << "copy " << c;
    EXPECT_TRUE(same_bits(r.states[c].x, e->state().x)) << "copy " << c;
  }
}

}  // namespace octocd_test_world_copies
