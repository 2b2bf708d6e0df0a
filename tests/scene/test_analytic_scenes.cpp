// Analytic scenes against closed forms (issue 2 item 7, design.md section 7.7), and determinism.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <memory>
#include <string>
#include <vector>

#include "octocd/error.hpp"
#include "octocd/scene.hpp"
#include "octocd/world.hpp"

// This file's own names (its tests compile in unity batches with the folder's other files).
namespace octocd_test_analytic_scenes {

using namespace octocd;

namespace {

std::string scene_path(const std::string& name) {
  const char* root = std::getenv("OCTOCD_SOURCE_DIR");
  return std::string(root ? root : ".") + "/datasets/scenes/" + name + ".json";
}

/// Index of the first body of `group`.
std::size_t first_of(const World& w, const std::string& group) {
  for (std::size_t i = 0; i < w.bodies().size(); ++i)
    if (w.bodies()[i].group == group) return i;
  ADD_FAILURE() << "no body in group " << group;
  return 0;
}

}  // namespace

// Eq. 2-3 in closed form: v_n = v_0 + n g dt, x_n = x_0 + n dt v_0 + g dt^2 n (n + 1) / 2.
TEST(AnalyticScenes, FreeFallMatchesClosedForm) {
  const Scene scene = load_scene(scene_path("free-fall"));
  World world(scene);
  const std::size_t i = first_of(world, world.bodies().back().group);
  const Vec3 x0 = world.state().x[i], v0 = world.state().v[i];
  const double g = scene.gravity.y, dt = scene.dt;
  for (int n = 1; n <= scene.frames; ++n) {
    world.step();
    const double v = v0.y + n * g * dt;
    const double x = x0.y + n * dt * v0.y + g * dt * dt * n * (n + 1) / 2.0;
    // float32 state: the error grows like n * ulp(|x|).
    ASSERT_NEAR(world.state().v[i].y, v, 1e-5 * (1 + std::fabs(v))) << "frame " << n;
    ASSERT_NEAR(world.state().x[i].y, x, 2e-6 * n * (1 + std::fabs(x))) << "frame " << n;
    ASSERT_EQ(world.state().x[i].x, x0.x);
  }
  EXPECT_EQ(world.last_metrics().contacts, 0u);
}

// A bounce above v_th returns at e * v (Eq. 17, 19).
TEST(AnalyticScenes, BounceReturnsAtRestitutionTimesImpactSpeed) {
  const Scene scene = load_scene(scene_path("bounce"));
  World world(scene);
  const std::size_t i = first_of(world, world.bodies().back().group);
  bool bounced = false;
  for (int n = 0; n < scene.frames && !bounced; ++n) {
    const float v_prev = world.state().v[i].y;
    world.step();
    const float v_impact = v_prev + scene.gravity.y * scene.dt;  // after the integrate stage
    if (world.state().v[i].y > 0.0f) {
      bounced = true;
      ASSERT_GT(-v_impact, scene.response.restitution_threshold);
      EXPECT_NEAR(world.state().v[i].y, -scene.response.restitution * v_impact,
                  1e-5f * std::fabs(v_impact))
          << "impact at " << v_impact << " m/s";
    }
  }
  EXPECT_TRUE(bounced) << "the body never bounced";
}

// A block sliding on the floor stops after v0^2 / (2 mu_k g) (Eq. 20-22), within 2%.
TEST(AnalyticScenes, SlideStopsAtCoulombDistance) {
  const Scene scene = load_scene(scene_path("slide"));
  World world(scene);
  const std::size_t i = first_of(world, world.bodies().back().group);
  const Vec3 x0 = world.state().x[i];
  const double v0 = world.state().v[i].x;
  ASSERT_GT(v0, 0.0);
  int n = 0;
  while (n < scene.frames && world.state().v[i].x > 0.0f) {
    world.step();
    ++n;
  }
  ASSERT_LE(world.state().v[i].x, 0.0f) << "still sliding after " << n << " frames";
  const double expected = v0 * v0 / (2.0 * scene.response.mu_kinetic * -scene.gravity.y);
  const double travelled = world.state().x[i].x - x0.x;
  EXPECT_NEAR(travelled, expected, 0.02 * expected);
  // It stays stopped.
  for (int k = 0; k < 200; ++k) world.step();
  EXPECT_NEAR(world.state().x[i].x - x0.x, travelled, 1e-4);
}

// A resting column of boxes stays within the slop delta of rest for 2000 frames.
// Started exactly touching, the column first settles: design.md section 6's Jacobi reduction averages
// the opposing corrections of a box between two contacts, so each contact keeps a
// penetration of a few delta (checked below: at most 3 delta per contact, design.md section 7.4's
// per-frame statistics). Once settled (frame 200) no box moves by more than delta.
TEST(AnalyticScenes, BoxStackStaysWithinSlopOfRest) {
  const Scene scene = load_scene(scene_path("box-stack"));
  ASSERT_GE(scene.frames, 2000);
  World world(scene);
  const float slop = scene.response.slop;
  constexpr int kSettle = 200;
  BodyState rest;
  double worst = 0.0;
  for (int n = 1; n <= 2000; ++n) {
    world.step();
    if (n > kSettle) {
      ASSERT_EQ(world.contacts().size(), 4u) << "frame " << n << ": the column came apart";
    }
    for (const ContactRecord& c : world.contacts())
      ASSERT_LE(c.depth, 3.0f * slop) << "contact " << c.pair.a << "-" << c.pair.b << " frame " << n;
    if (n == kSettle) rest = world.state();
    if (n <= kSettle) continue;
    for (std::size_t i = 0; i < rest.size(); ++i) {
      if (rest.w[i] == 0.0f) continue;
      const Vec3 d = world.state().x[i] - rest.x[i];
      worst = std::max(worst, static_cast<double>(length(d)));
      ASSERT_LE(length(d), slop) << "body " << i << " frame " << n;
    }
  }
  RecordProperty("max_displacement_m", std::to_string(worst));
}

// Bit-identical reruns, independent of the thread count, with a pinned hash.
TEST(Determinism, RerunsAreBitIdenticalAndPinned) {
  const char* root = std::getenv("OCTOCD_SOURCE_DIR");
  const Scene scene = load_scene(std::string(root ? root : ".") + "/tests/data/spheres-drop.json");
  auto run = [&](int threads) {
    CpuSettings settings;
    settings.threads = threads;
    World world(build_model(scene), make_broadphase(scene.broadphase, scene.domain), settings);
    for (int n = 0; n < 400; ++n) world.step();
    return world.state_hash();
  };
  const std::uint64_t h1 = run(2);
  const std::uint64_t h2 = run(2);
  const std::uint64_t h3 = run(1);
  EXPECT_EQ(h1, h2);
  EXPECT_EQ(h1, h3);
  // Pinned: a change here means the step's arithmetic changed. Update it only on purpose.
  EXPECT_EQ(h1, 14935660299574476031ull) << "hash " << h1;
}

// The stages' threads leave a step's bits alone where they run in parallel: on
// bunny-random-400 the midphase runs on the worker team from 64 pairs a step, and the
// state hash of every step at 2 and 3 threads equals that at 1 thread.
TEST(Determinism, ThreadCountDoesNotChangeTheBitsOfAMeshScene) {
  const Scene scene = load_scene(scene_path("bunny-random-400"));
  const std::shared_ptr<const Model> model = build_model(scene);
  std::uint64_t most_pairs = 0;
  auto run = [&](int threads) {
    CpuSettings settings;
    settings.threads = threads;
    World world(model, make_broadphase(scene.broadphase, scene.domain), settings);
    std::vector<std::uint64_t> hashes;
    for (int n = 0; n < 240; ++n) {
      most_pairs = std::max(most_pairs, world.step().dynamic_pairs);
      hashes.push_back(world.state_hash());
    }
    return hashes;
  };
  const std::vector<std::uint64_t> one = run(1);
  EXPECT_GE(most_pairs, 64u) << "no step reached the midphase's parallel threshold";
  EXPECT_EQ(run(2), one);
  EXPECT_EQ(run(3), one);
}

// A NaN in the state stops the run with an error naming the body and the frame.
TEST(Failures, NonFiniteStateNamesBodyAndFrame) {
  const Scene scene = load_scene(scene_path("free-fall"));
  World world(scene);
  world.step();
  const std::size_t i = world.state().size() - 1;
  world.mutable_state().v[i].x = std::nanf("");
  try {
    world.step();
    FAIL() << "no error";
  } catch (const RuntimeError& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find("frame 2"), std::string::npos) << msg;
    EXPECT_NE(msg.find("body " + std::to_string(i)), std::string::npos) << msg;
  }
}

// A body leaving the domain is never lost: it stays a broadphase candidate.
TEST(Failures, BodyOutsideDomainStillCollides) {
  const Scene scene = load_scene(scene_path("bounce"));
  World world(scene);
  const std::size_t i = first_of(world, world.bodies().back().group);
  ASSERT_EQ(world.bodies()[0].group, "walls");  // the floor comes first
  // Just outside the domain in x, resting on the floor's part that sticks out of it.
  const Aabb floor = world.world_aabbs()[0];
  const Aabb local = world.shapes()[world.bodies()[i].shape].local;
  world.mutable_state().x[i] = {scene.domain.max.x + 0.5f * (floor.max.x - scene.domain.max.x),
                                floor.max.y + local.max.y - 0.002f, center(scene.domain).z};
  world.mutable_state().v[i] = {};
  world.step();
  bool found = false;
  for (const Pair& p : world.candidate_pairs()) found = found || (p.a == 0 && p.b == i);
  EXPECT_TRUE(found) << "body outside the domain lost by the broadphase";
  EXPECT_GE(world.last_metrics().contacts, 1u);
}

}  // namespace octocd_test_analytic_scenes
