// The judges' device part (validation/device/, octocd/device_judge.hpp) against the CPU
// tier, the oracle: on shipped scenes (boxes; boxes with meshes, whose pairs the device
// leaves to the CPU reference) the physics tier judges the same recorded frames once on
// the CPU and once with rows broadphase-completeness and penetration on the device (and
// rows contact-completeness and contact-geometry on the CPU geometry of the device's
// candidate pairs; impulse-feasibility and the near-pair search on the device's pairs within
// a step's reach), and every row must give the same verdict, applicability, judged
// count, causes, failure counts and failing items, with figures equal to 1e-9 m (the
// device's separating-axis arithmetic rounds apart from the CPU's). Planted faults must fail on both alike: a
// required pair dropped from the engine's candidates, a frame whose boxes are turned (the
// engine's pairs then miss pairs and the boxes penetrate; the rotated separating axes),
// a penetrating pair's contact rows dropped, a penetration bound below every depth, and a
// free box's velocity edited under contacts_complete 0.
//
// Without a usable CUDA device every test is SKIPPED with the reason (CI builds with nvcc
// and has no GPU). Environment: OCTOCD_SOURCE_DIR (scenes and datasets; default: the
// source tree this was built from).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include <fmt/format.h>

#include "octocd/device_judge.hpp"
#include "octocd/physics.hpp"
#include "octocd/scene.hpp"
#include "octocd/validation.hpp"
#include "octocd/world.hpp"

namespace {

using namespace octocd;

std::string source_dir() {
  const char* root = std::getenv("OCTOCD_SOURCE_DIR");
  return root ? root : OCTOCD_TEST_SOURCE_DIR;
}

/// A judge on this machine's device, or the reason there is none.
std::unique_ptr<DeviceJudge> device_or(std::string& why) {
  try {
    return make_cuda_judge();
  } catch (const std::exception& e) {
    why = e.what();
    return nullptr;
  }
}

#define REQUIRE_DEVICE()                                  \
  do {                                                    \
    std::string why;                                      \
    if (!device_or(why)) GTEST_SKIP() << "no device judge: " << why; \
  } while (0)

/// Frames 1..frames of scene `name` on the CPU engine, recorded.
std::vector<FrameRecord> recorded(const std::string& name, int frames, std::shared_ptr<const Model>& model) {
  const Scene scene = load_scene(source_dir() + "/datasets/scenes/" + name + ".json");
  model = build_model(scene);
  World world(model, make_broadphase(scene.broadphase, scene.domain));
  world.set_recording(true);
  std::vector<FrameRecord> out;
  for (int f = 1; f <= frames; ++f) {
    world.step();
    out.push_back(world.record());
  }
  return out;
}

std::vector<ValidationResult> judged(const Model& model, const PhysicsBodies& bodies,
                                     const std::vector<FrameRecord>& recs, int every, bool on_device,
                                     const Tolerances& tol = Tolerances{}) {
  PhysicsValidators v(model, bodies, tol, "engine 'cpu'");
  if (on_device) v.set_judge_device(make_cuda_judge());
  for (const FrameRecord& r : recs) v.observe(r, r.frame % every == 0);
  return v.results();
}

/// Every row alike (see the file comment); returns the names of the rows that failed.
std::vector<std::string> expect_same(const std::vector<ValidationResult>& cpu, const std::vector<ValidationResult>& dev) {
  std::vector<std::string> failed;
  EXPECT_EQ(cpu.size(), dev.size());
  for (std::size_t k = 0; k < std::min(cpu.size(), dev.size()); ++k) {
    const ValidationResult& a = cpu[k];
    const ValidationResult& b = dev[k];
    SCOPED_TRACE(a.name + ": cpu: " + a.detail + "\n  device: " + b.detail);
    EXPECT_EQ(a.name, b.name);
    EXPECT_EQ(a.pass, b.pass);
    EXPECT_EQ(a.applicable, b.applicable);
    EXPECT_EQ(a.judged, b.judged);
    EXPECT_NEAR(a.measured, b.measured, 1e-9 + 1e-9 * std::fabs(a.measured));
    EXPECT_EQ(a.causes.size(), b.causes.size());
    for (std::size_t c = 0; c < std::min(a.causes.size(), b.causes.size()); ++c) {
      EXPECT_EQ(a.causes[c].name, b.causes[c].name);
      EXPECT_EQ(a.causes[c].count, b.causes[c].count);
      EXPECT_EQ(a.causes[c].items, b.causes[c].items);
      EXPECT_NEAR(a.causes[c].worst, b.causes[c].worst, 1e-9 + 1e-9 * std::fabs(a.causes[c].worst));
    }
    if (!a.pass) failed.push_back(a.name);
  }
  return failed;
}

const ValidationResult& row(const std::vector<ValidationResult>& rs, const std::string& name) {
  for (const ValidationResult& r : rs)
    if (r.name == name) return r;
  static const ValidationResult none;
  ADD_FAILURE() << "no row " << name;
  return none;
}

bool has(const std::vector<std::string>& v, const std::string& s) { return std::find(v.begin(), v.end(), s) != v.end(); }

// box-stack recorded over 20 frames (`recs`, `model`) and the pair of its last frame's
// deepest contact row (`gone`, depth `depth`), which penetrates beyond the geometry slack.
void deepest_contact_of_box_stack(std::shared_ptr<const Model>& model, std::vector<FrameRecord>& recs, Pair& gone,
                                  float& depth) {
  recs = recorded("box-stack", 20, model);
  const FrameRecord& last = recs.back();
  ASSERT_FALSE(last.contacts.empty()) << "box-stack has no contact at frame 20";
  const ContactRecord* deepest = &last.contacts.front();
  for (const ContactRecord& c : last.contacts)
    if (c.depth > deepest->depth) deepest = &c;
  ASSERT_GT(deepest->depth, 1e-4f) << "no contact deeper than the geometry slack";
  gone = deepest->pair;
  depth = deepest->depth;
}

struct SceneCase {
  const char* name;
  int frames, every;
};

class DeviceJudgeScenes : public ::testing::TestWithParam<SceneCase> {};

// Shipped scenes: the same verdicts; the device rows say where they ran.
TEST_P(DeviceJudgeScenes, SameVerdictsAsTheCpuTier) {
  REQUIRE_DEVICE();
  const SceneCase c = GetParam();
  std::shared_ptr<const Model> model;
  const std::vector<FrameRecord> recs = recorded(c.name, c.frames, model);
  const PhysicsBodies bodies = octocd_physics_bodies(*model);
  const auto cpu = judged(*model, bodies, recs, c.every, false);
  const auto dev = judged(*model, bodies, recs, c.every, true);
  expect_same(cpu, dev);
  EXPECT_NE(row(dev, "broadphase-completeness").detail.find("judged on the device (cuda: "), std::string::npos);
  EXPECT_NE(row(dev, "penetration").detail.find("judged on the device (cuda: "), std::string::npos);
  EXPECT_NE(row(dev, "contact-completeness").detail.find("from the device (cuda: "), std::string::npos);
  EXPECT_GT(row(dev, "broadphase-completeness").judged, 0u) << "nothing judged: the comparison would be vacuous";
  // impulse-feasibility took its pairs within a step's reach from the device.
  EXPECT_EQ(row(dev, "broadphase-completeness").detail.find("; 0 searches of pairs within a step's reach"),
            std::string::npos);
  EXPECT_GT(row(dev, "impulse-feasibility").judged + row(dev, "free-flight").judged, 0u);
}

INSTANTIATE_TEST_SUITE_P(Shipped, DeviceJudgeScenes,
                         ::testing::Values(SceneCase{"box-stack", 60, 5}, SceneCase{"boxes-uniform-10k", 30, 10},
                                           SceneCase{"boxes-random-10000", 30, 10},
                                           SceneCase{"mixed-pile-1000", 40, 10}, SceneCase{"sizes-50x-214", 60, 10}),
                         [](const auto& param_info) {
                           std::string n = param_info.param.name;
                           for (char& ch : n)
                             if (ch == '-') ch = '_';
                           return n;
                         });

// A required pair dropped from the engine's candidates: missing-pair on both, the same item.
TEST(DeviceJudgeFaults, DroppedPairFailsOnBoth) {
  REQUIRE_DEVICE();
  std::shared_ptr<const Model> model;
  std::vector<FrameRecord> recs;
  Pair gone;
  float depth = 0;
  // The pair of the deepest contact row penetrates: drop it from the candidates (its
  // contact rows stay).
  ASSERT_NO_FATAL_FAILURE(deepest_contact_of_box_stack(model, recs, gone, depth));
  FrameRecord& last = recs.back();
  last.pairs.erase(std::remove(last.pairs.begin(), last.pairs.end(), gone), last.pairs.end());
  PhysicsBodies bodies = octocd_physics_bodies(*model);
  bodies.broadphase_exact = false;  // the missing-pair cause alone
  const auto cpu = judged(*model, bodies, recs, 20, false);
  const auto dev = judged(*model, bodies, recs, 20, true);
  const auto failed = expect_same(cpu, dev);
  EXPECT_TRUE(has(failed, "broadphase-completeness"));
  ASSERT_FALSE(row(dev, "broadphase-completeness").causes.empty());
  EXPECT_EQ(row(dev, "broadphase-completeness").causes[0].items,
            std::vector<std::string>{fmt::format("pair ({}, {})", gone.a, gone.b)});
}

// A penetrating pair's contact rows dropped: missing-contact on both (the CPU geometry of
// the device's candidates against the CPU's own), the same item.
TEST(DeviceJudgeFaults, DroppedContactFailsOnBoth) {
  REQUIRE_DEVICE();
  std::shared_ptr<const Model> model;
  std::vector<FrameRecord> recs;
  Pair gone;
  float depth = 0;
  ASSERT_NO_FATAL_FAILURE(deepest_contact_of_box_stack(model, recs, gone, depth));
  FrameRecord& last = recs.back();
  Tolerances tol;
  tol.contact_depth_m = 0.25 * depth;  // the dropped pair penetrates deeper
  last.contacts.erase(std::remove_if(last.contacts.begin(), last.contacts.end(),
                                     [&](const ContactRecord& c) { return c.pair == gone; }),
                      last.contacts.end());
  const PhysicsBodies bodies = octocd_physics_bodies(*model);
  const auto cpu = judged(*model, bodies, recs, 20, false, tol);
  const auto dev = judged(*model, bodies, recs, 20, true, tol);
  const auto failed = expect_same(cpu, dev);
  EXPECT_TRUE(has(failed, "contact-completeness"));
  const ValidationResult& r = row(dev, "contact-completeness");
  ASSERT_FALSE(r.causes.empty());
  EXPECT_EQ(r.causes[0].items, std::vector<std::string>{fmt::format("pair ({}, {})", gone.a, gone.b)});
  EXPECT_NE(r.detail.find("from the device (cuda: "), std::string::npos) << r.detail;
}

// Turned boxes (random orientations at the detection pose) on a dense frame: the engine's
// axis-aligned pairs miss pairs that now penetrate; the rotated boxes' axes are the test.
TEST(DeviceJudgeFaults, TurnedBoxesFailAlike) {
  REQUIRE_DEVICE();
  std::shared_ptr<const Model> model;
  std::vector<FrameRecord> recs = recorded("boxes-uniform-10k", 10, model);
  FrameRecord& f = recs.back();
  const std::size_t n = model->bodies.size();
  std::mt19937 rng(7);
  std::normal_distribution<float> g(0.0f, 1.0f);
  f.x_det.resize(n);
  f.q_det.resize(n);
  for (std::size_t i = 0; i < n; ++i) {
    f.x_det[i] = f.aabbs[i].min - model->local_box(i).min;
    Quat q{g(rng), g(rng), g(rng), g(rng)};
    const float len = std::sqrt(q.w * q.w + q.x * q.x + q.y * q.y + q.z * q.z);
    f.q_det[i] = model->initial.w[i] > 0 ? Quat{q.w / len, q.x / len, q.y / len, q.z / len} : Quat{};
  }
  PhysicsBodies bodies = octocd_physics_bodies(*model);
  bodies.broadphase_exact = false;
  bodies.contact_geometry = ContactGeometry::Shape;
  Tolerances tol;
  tol.penetration_slops = 1.0;
  const std::vector<FrameRecord> one{f};
  const auto cpu = judged(*model, bodies, one, 1, false, tol);
  const auto dev = judged(*model, bodies, one, 1, true, tol);
  const auto failed = expect_same(cpu, dev);
  EXPECT_TRUE(has(failed, "broadphase-completeness"));
  EXPECT_GT(row(dev, "penetration").judged, 0u);
}

// A penetration bound below every depth: every penetrating pair-frame fails, alike.
TEST(DeviceJudgeFaults, TightPenetrationBoundFailsOnBoth) {
  REQUIRE_DEVICE();
  std::shared_ptr<const Model> model;
  const std::vector<FrameRecord> recs = recorded("box-stack", 40, model);
  Tolerances tol;
  tol.penetration_slops = 1e-9;
  const PhysicsBodies bodies = octocd_physics_bodies(*model);
  const auto cpu = judged(*model, bodies, recs, 5, false, tol);
  const auto dev = judged(*model, bodies, recs, 5, true, tol);
  const auto failed = expect_same(cpu, dev);
  EXPECT_TRUE(has(failed, "penetration"));
}

// contacts_complete 0 (an engine that may drop contact rows): free-flight judges a body without
// rows only where the near-pair search, on the device here, shows it apart from every other
// body. A free box's velocity edited in the last frame fails on both alike, the same item.
TEST(DeviceJudgeFaults, IncompleteContactsEditedFreeVelocityFailsAlike) {
  REQUIRE_DEVICE();
  std::shared_ptr<const Model> model;
  std::vector<FrameRecord> recs = recorded("boxes-uniform-10k", 20, model);
  FrameRecord& last = recs.back();
  ASSERT_EQ(last.v_post.size(), model->bodies.size());
  std::vector<char> paired(model->bodies.size(), 0);
  for (const Pair& p : last.pairs) paired[p.a] = paired[p.b] = 1;
  for (const ContactRecord& c : last.contacts) paired[c.pair.a] = paired[c.pair.b] = 1;
  std::size_t edited = model->bodies.size();
  for (std::size_t i = 0; i < model->bodies.size() && edited == model->bodies.size(); ++i)
    if (!paired[i] && std::fabs(last.v_pre[i].x) + std::fabs(last.v_pre[i].y) + std::fabs(last.v_pre[i].z) > 0.1f)
      edited = i;
  ASSERT_LT(edited, model->bodies.size()) << "no moving box without pairs at frame 20";
  last.v_post[edited].x += 0.5f;
  PhysicsBodies bodies = octocd_physics_bodies(*model);
  bodies.contacts_complete = false;
  const auto cpu = judged(*model, bodies, recs, 10, false);
  const auto dev = judged(*model, bodies, recs, 10, true);
  const auto failed = expect_same(cpu, dev);
  EXPECT_TRUE(has(failed, "free-flight"));
  EXPECT_EQ(row(dev, "broadphase-completeness").detail.find("; 0 searches of pairs within a step's reach"),
            std::string::npos);
}

}  // namespace
