// The test build of the CPU step (tests/faults/planted_faults.hpp) against the product's
// World: with no fault planted it runs the same stages in the same order, so every step
// gives the same bits (state, pairs, confirmed pairs, contacts); each planted fault
// changes the run; the "other rounding" engine really rounds differently.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <string>
#include <vector>

#include "faults/planted_faults.hpp"
#include "octocd/world.hpp"
#include "support/test_scenes.hpp"

// This file's own names (its tests compile in unity batches with the folder's other files).
namespace octocd_test_planted_faults {

using namespace octocd;
using octocd::test::FaultyWorld;
using octocd::test::PlantedFaults;

namespace {

std::string source_dir() {
  const char* root = std::getenv("OCTOCD_SOURCE_DIR");
  return root ? root : ".";
}

bool same_bits(const std::vector<Vec3>& a, const std::vector<Vec3>& b) {
  return a.size() == b.size() && (a.empty() || std::memcmp(a.data(), b.data(), a.size() * sizeof(Vec3)) == 0);
}

bool same_contacts(const std::vector<ContactRecord>& a, const std::vector<ContactRecord>& b) {
  if (a.size() != b.size()) return false;
  for (std::size_t k = 0; k < a.size(); ++k) {
    const ContactRecord& x = a[k];
    const ContactRecord& y = b[k];
    if (x.pair.a != y.pair.a || x.pair.b != y.pair.b || x.axis != y.axis ||
        std::memcmp(&x.depth, &y.depth, sizeof(float)) != 0 || std::memcmp(&x.jn, &y.jn, sizeof(float)) != 0 ||
        std::memcmp(&x.jt, &y.jt, sizeof(float)) != 0 ||
        !same_bits({x.normal, x.v_a, x.v_b, x.dx_a, x.dx_b, x.dv_a, x.dv_b},
                   {y.normal, y.v_a, y.v_b, y.dx_a, y.dx_b, y.dv_a, y.dv_b}))
      return false;
  }
  return true;
}

/// Steps World and FaultyWorld(faults) side by side; returns the first frame whose
/// state, pairs, confirmed pairs or contacts differ in any bit (0: none in `frames`).
std::int64_t first_difference(const Scene& scene, const PlantedFaults& faults, int frames) {
  const auto model = build_model(scene);
  World world(model, make_broadphase(scene.broadphase, scene.domain));
  FaultyWorld faulty(model, make_broadphase(scene.broadphase, scene.domain), faults);
  world.set_recording(true);
  faulty.set_recording(true);
  for (int f = 1; f <= frames; ++f) {
    world.step();
    faulty.step();
    const FrameRecord& a = world.record();
    const FrameRecord& b = faulty.record();
    if (world.state_hash() != faulty.state_hash() || !same_bits(a.x_post, b.x_post) ||
        !same_bits(a.v_post, b.v_post) || a.pairs != b.pairs || a.confirmed != b.confirmed ||
        !same_contacts(world.contacts(), faulty.contacts()) ||
        world.last_metrics().dynamic_pairs != faulty.last_metrics().dynamic_pairs ||
        world.last_metrics().kinetic_energy != faulty.last_metrics().kinetic_energy)
      return f;
  }
  return 0;
}

Scene shipped(const std::string& name) { return load_scene(source_dir() + "/datasets/scenes/" + name + ".json"); }

}  // namespace

// With no fault planted the test build is the product, bit for bit, on boxes (one pass
// and eight passes) and on meshes (the midphase and narrow phase).
TEST(PlantedFaults, NoFaultIsWorldBitForBit) {
  EXPECT_EQ(first_difference(octocd::test::mixed_boxes(), {}, 300), 0);
  Scene stack = shipped("box-stack");
  ASSERT_EQ(stack.response.iterations, 8);
  EXPECT_EQ(first_difference(stack, {}, 300), 0);
  if (!std::filesystem::exists(source_dir() + "/datasets/cache/bunny.obj"))
    GTEST_SKIP() << "datasets not fetched (bunny.obj): the mesh scene is not compared";
  Scene bunnies = shipped("bunny-stack-50");
  bunnies.response.iterations = 4;
  EXPECT_EQ(first_difference(bunnies, {}, 300), 0);  // bunnies land from frame ~190 on
}

// Every planted fault changes the run (a fault that changes nothing could not be caught).
TEST(PlantedFaults, EveryFaultChangesTheRun) {
  Scene stack = shipped("box-stack");  // 8 passes: the pass faults act
  const Scene boxes = octocd::test::mixed_boxes(0.8f);  // v_max 0.8 m/s: the clamp acts
  struct Case {
    const char* name;
    bool PlantedFaults::*field;
  };
  const Case cases[] = {
      {"eq12_weights", &PlantedFaults::eq12_weights},
      {"friction_sign", &PlantedFaults::friction_sign},
      {"momentum_leak", &PlantedFaults::momentum_leak},
      {"normal_sign", &PlantedFaults::normal_sign},
      {"impulse_wrong_body", &PlantedFaults::impulse_wrong_body},
      {"corrections_summed", &PlantedFaults::corrections_summed},
      {"explicit_euler", &PlantedFaults::explicit_euler},
      {"skip_clamp", &PlantedFaults::skip_clamp},
      {"broadphase_drops_pair", &PlantedFaults::broadphase_drops_pair},
      {"midphase_drops_contact", &PlantedFaults::midphase_drops_contact},
      {"jmin_first_pass_only", &PlantedFaults::jmin_first_pass_only},
      {"one_pass_fewer", &PlantedFaults::one_pass_fewer},
      {"last_pass_no_corrections", &PlantedFaults::last_pass_no_corrections},
  };
  for (const Case& c : cases) {
    PlantedFaults f;
    f.*c.field = true;
    EXPECT_TRUE(f.any()) << c.name;
    const bool on_stack = first_difference(stack, f, 300) != 0;
    const bool on_boxes = first_difference(boxes, f, 300) != 0;
    EXPECT_TRUE(on_stack || on_boxes) << c.name << " changed nothing in 300 frames";
  }
  EXPECT_FALSE(PlantedFaults{}.any());
}

// The other-rounding engine is another engine: with inverse masses that are not powers of
// two (1.3 kg) its impulses differ from contact_impulse's in some bits.
TEST(PlantedFaults, OtherRoundingDiffersInTheLastBits) {
  ContactParams p;
  int differ = 0, cases = 0;
  for (int i = 1; i <= 200; ++i) {
    const float fi = static_cast<float>(i);
    const Vec3 va{0.013f * fi, -0.37f * static_cast<float>(i % 17 + 1), 0.029f * static_cast<float>(i % 5)};
    const float wa = 1.0f / 1.3f, wb = i % 3 == 0 ? 0.0f : 1.0f / 1.3f;
    const ContactImpulse a = contact_impulse(va, Vec3{}, wa, wb, {0, 1, 0}, p);
    const ContactImpulse b = octocd::test::contact_impulse_other_rounding(va, Vec3{}, wa, wb, {0, 1, 0}, p);
    ++cases;
    EXPECT_NEAR(a.jn, b.jn, 1e-5f * std::max(1.0f, a.jn)) << i;
    EXPECT_NEAR(a.jt, b.jt, 1e-5f * std::max(1.0f, std::fabs(a.jt))) << i;
    if (std::memcmp(&a.jn, &b.jn, sizeof(float)) != 0 || !same_bits({a.tangent}, {b.tangent})) ++differ;
  }
  EXPECT_GT(differ, 0) << "of " << cases;
  Scene boxes = octocd::test::mixed_boxes();
  for (GroupSpec& g : boxes.groups) g.mass = 1.3f;
  PlantedFaults f;
  f.other_rounding = true;
  EXPECT_NE(first_difference(boxes, f, 300), 0);
}

}  // namespace octocd_test_planted_faults
