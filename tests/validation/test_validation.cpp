// Every validator of design.md section 7 passes on the correct pipeline and catches a planted fault
// (issue 3 item 3: "a validator that cannot fail is a defect").
#include <gtest/gtest.h>

#include <array>
#include <atomic>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <mutex>
#include <set>
#include <string>

#include <unistd.h>

#include <fmt/format.h>

#include "octocd/bullet_world.hpp"
#include "octocd/exact_pairs.hpp"
#include "octocd/physics.hpp"
#include "octocd/reference_broadphase.hpp"
#include "octocd/trace.hpp"
#include "faults/planted_faults.hpp"
#include "octocd/validation.hpp"
#include "octocd/validation_rows.hpp"
#include "support/test_scenes.hpp"

// This file's own names (its tests compile in unity batches with the folder's other files).
namespace octocd_test_validation {

using namespace octocd;
using octocd::test::FaultyWorld;
using octocd::test::mixed_boxes;
using octocd::test::PlantedFaults;

namespace {

std::string source_dir() {
  const char* root = std::getenv("OCTOCD_SOURCE_DIR");
  return root ? root : ".";
}

ValidationResult find(const std::vector<ValidationResult>& rs, const std::string& name) {
  for (const auto& r : rs)
    if (r.name == name) return r;
  ValidationResult none;
  ADD_FAILURE() << "no result named " << name;
  return none;
}

/// Runs validators 1-6 on `world` for `frames` steps.
std::vector<ValidationResult> run(Engine& world, int frames,
                                  std::vector<std::unique_ptr<BroadPhase>> extra = {},
                                  FrameValidators::ConfirmFn midphase = nullptr) {
  ValidationOptions opt;
  opt.every = 5;
  world.set_recording(true);
  FrameValidators v(world, opt, std::move(extra));
  if (midphase) v.set_midphase(std::move(midphase));
  for (int f = 1; f <= frames; ++f) {
    world.step();
    v.observe(world, f % opt.every == 0);
  }
  return v.results();
}

/// A broadphase that drops the last pair of another.
class DroppingBroadPhase : public BroadPhase {
 public:
  explicit DroppingBroadPhase(std::unique_ptr<BroadPhase> inner, std::string name = "drops-one-pair")
      : inner_(std::move(inner)), name_(std::move(name)) {}
  std::string name() const override { return name_; }
  void find_pairs(const std::vector<Aabb>& boxes, std::vector<Pair>& out,
                  BroadPhaseStats& stats) override {
    inner_->find_pairs(boxes, out, stats);
    if (!out.empty()) out.pop_back();
  }

 private:
  std::unique_ptr<BroadPhase> inner_;
  std::string name_;
};

/// A broadphase that adds the pair (0, 1) to another's set (kept sorted).
class AddingBroadPhase : public BroadPhase {
 public:
  explicit AddingBroadPhase(std::unique_ptr<BroadPhase> inner) : inner_(std::move(inner)) {}
  std::string name() const override { return "adds-one-pair"; }
  void find_pairs(const std::vector<Aabb>& boxes, std::vector<Pair>& out, BroadPhaseStats& stats) override {
    inner_->find_pairs(boxes, out, stats);
    const Pair added{0, 1};
    const auto at = std::lower_bound(out.begin(), out.end(), added);
    if (at == out.end() || !(*at == added)) out.insert(at, added);
  }

 private:
  std::unique_ptr<BroadPhase> inner_;
};

/// A broadphase that leaves out another's pairs of two static bodies (w = 0).
class StaticDroppingBroadPhase : public BroadPhase {
 public:
  StaticDroppingBroadPhase(std::unique_ptr<BroadPhase> inner, std::vector<float> w)
      : inner_(std::move(inner)), w_(std::move(w)) {}
  std::string name() const override { return "drops-static-pairs"; }
  void find_pairs(const std::vector<Aabb>& boxes, std::vector<Pair>& out, BroadPhaseStats& stats) override {
    inner_->find_pairs(boxes, out, stats);
    out.erase(std::remove_if(out.begin(), out.end(), [&](Pair p) { return w_[p.a] == 0.0f && w_[p.b] == 0.0f; }),
              out.end());
  }

 private:
  std::unique_ptr<BroadPhase> inner_;
  std::vector<float> w_;
};

}  // namespace

TEST(Validators, AllPassOnTheCorrectPipeline) {
  const Scene scene = mixed_boxes();
  World world(scene);
  std::vector<std::unique_ptr<BroadPhase>> all;
  for (const std::string& name : all_broadphase_names()) {
    BroadPhaseConfig cfg = scene.broadphase;
    cfg.name = name;
    all.push_back(make_any_broadphase(cfg, scene.domain));
  }
  const auto rs = run(world, 300, std::move(all));
  for (const auto& r : rs) {
    EXPECT_TRUE(r.applicable) << r.name << ": " << r.detail;
    // The physics tier's energy check is the one row the paper's model itself breaks
    // here: design.md section 6 sums each body's impulses computed from the same pre-response state
    // (Jacobi), which overshoots where a body is squeezed between others (frame 201: an
    // isolated group of 4 boxes goes from 17.9 to 69.3 J). That is a finding about the
    // model (docs/validation.md, "Validate your own engine"), not a validator fault; momentum and
    // every other row still pass.
    if (r.tier == Tier::Physics && r.name == "conservation" && !r.pass) {
      EXPECT_NE(r.detail.find("kinetic energy"), std::string::npos) << r.detail;
      continue;
    }
    EXPECT_TRUE(r.pass) << r.name << ": " << r.detail;
  }
}

TEST(Validators, AScenesRowsAreTheRowTablesInItsOrderAndTiers) {
  ValidationOptions o;
  o.frames = 20;
  const std::vector<ValidationResult> rs = validate_scene(mixed_boxes(), o);
  const std::vector<RowInfo>& rows = validation_rows();
  ASSERT_EQ(rs.size(), rows.size());
  for (std::size_t k = 0; k < rs.size(); ++k) {
    EXPECT_EQ(rs[k].name, rows[k].name);
    EXPECT_EQ(rs[k].tier, rows[k].tier) << rs[k].name;
  }
}

// docs/validation.md's "Causes per row" lists every row that splits its failures, with its
// causes in the row table's order, and no other row.
TEST(Validators, DocumentedCausesAreTheRowTables) {
  std::ifstream doc(source_dir() + "/docs/validation.md");
  ASSERT_TRUE(doc) << source_dir() + "/docs/validation.md";
  std::map<std::string, std::string> documented;  // row -> "a, b, c"
  bool in_section = false;
  for (std::string line; std::getline(doc, line);) {
    if (line.rfind("#", 0) == 0) in_section = line == "### Causes per row";
    if (!in_section || line.rfind("| ", 0) != 0 || line.rfind("| row |", 0) == 0) continue;
    const std::size_t bar = line.find(" | ", 2);
    ASSERT_NE(bar, std::string::npos) << line;
    std::string row = line.substr(2, bar - 2);
    row = row.substr(0, row.find(" ("));  // "bullet-dynamics (stacks and piles)"
    std::string causes = line.substr(bar + 3);
    causes = causes.substr(0, causes.rfind(" |"));
    EXPECT_TRUE(documented.emplace(row, causes).second) << "listed twice: " << row;
  }
  std::size_t with_causes = 0;
  for (const RowInfo& row : validation_rows()) {
    if (row.causes.empty()) continue;
    ++with_causes;
    std::string causes;
    for (const RowCause& c : row.causes) causes += (causes.empty() ? "" : ", ") + std::string(c.name);
    const auto it = documented.find(row.name);
    ASSERT_NE(it, documented.end()) << row.name << " (" << causes << ") missing from docs/validation.md";
    EXPECT_EQ(it->second, causes) << row.name;
  }
  EXPECT_EQ(documented.size(), with_causes);
  EXPECT_GE(with_causes, 8u);
}

TEST(Validators, CandidateSetsCatchADroppedPair) {
  const Scene scene = mixed_boxes();
  World world(scene);
  BroadPhaseConfig cfg = scene.broadphase;
  std::vector<std::unique_ptr<BroadPhase>> extra;
  extra.push_back(std::make_unique<DroppingBroadPhase>(make_broadphase(cfg, scene.domain)));
  const ValidationResult r = find(run(world, 100, std::move(extra)), "candidate-sets");
  EXPECT_FALSE(r.pass) << r.detail;
  EXPECT_NE(r.detail.find("drops-one-pair misses pair"), std::string::npos) << r.detail;
}

// A quadratic-cost broadphase (fcl-naive: n(n-1)/2 tests) above 6,325 bodies is compared once
// in ceil(n(n-1)/2 / 2e7) judged frames, from the first: 10,006 boxes give once in 3, so of two
// judged frames the first. A faulty one is still caught there, and the detail names the stride.
/// The candidate-sets row of `frames` steps of `scene` on the CPU engine with fcl-naive as the
/// one extra broadphase (dropping its last pair where `drop_one`).
ValidationResult fcl_naive_candidate_sets(const Scene& scene, int frames, bool drop_one = false) {
  BroadPhaseConfig cfg = scene.broadphase;
  cfg.name = "fcl-naive";
  World world(scene);
  std::vector<std::unique_ptr<BroadPhase>> extra;
  std::unique_ptr<BroadPhase> naive = make_any_broadphase(cfg, scene.domain);
  if (drop_one) naive = std::make_unique<DroppingBroadPhase>(std::move(naive), "fcl-naive");
  extra.push_back(std::move(naive));
  return find(run(world, frames, std::move(extra)), "candidate-sets");
}

TEST(Validators, QuadraticBroadphaseIsComparedOnAStride) {
  const Scene scene = load_scene(source_dir() + "/datasets/scenes/boxes-uniform-10k.json");
  {
    const ValidationResult r = fcl_naive_candidate_sets(scene, 10);
    EXPECT_TRUE(r.pass) << r.detail;
    EXPECT_NE(r.detail.find("fcl-naive (on 1 of the 2 frames: a quadratic broadphase is compared once in 3 judged "
                            "frames"),
              std::string::npos)
        << r.detail;
  }
  {
    const ValidationResult r = fcl_naive_candidate_sets(scene, 10, true);
    EXPECT_FALSE(r.pass) << r.detail;
    EXPECT_NE(r.detail.find("frame 5: fcl-naive misses pair"), std::string::npos) << r.detail;
  }
}

/// `count` boxes of 0.2 m on a grid 0.5 m apart (no pair), filled from the corner of a cube
/// just large enough, no gravity, no walls, the octree broadphase.
Scene sparse_grid(int count) {
  const int side = int(std::ceil(std::cbrt(double(count))));
  const double half = 0.25 * (side - 1);
  return parse_scene(fmt::format(R"({{
    "name": "sparse-grid-{0}", "dt": 0.001, "frames": 10,
    "domain": {{"min": [{1}, {1}, {1}], "max": [{2}, {2}, {2}]}},
    "gravity": [0, 0, 0], "walls": "none",
    "broadphase": {{"name": "octree", "depth": "auto"}},
    "groups": [{{"name": "box", "shape": {{"box": [0.1, 0.1, 0.1]}}, "count": {0}, "mass": 1.0,
                "layout": {{"type": "grid", "min": [{3}, {3}, {3}], "max": [{4}, {4}, {4}], "spacing": 0.5}}}}]}})",
                                 count, -half - 1, half + 1, -half, half),
                     "sparse-grid");
}

// Above 141,421 boxes one call of a quadratic-cost broadphase is over 10^10 AABB tests (at
// 10^6 boxes 5 x 10^11: hours on the first judged frame, where the stride starts): it is not
// compared at all, and the detail says so. 150,000 boxes 0.5 m apart, no pair.
TEST(Validators, QuadraticBroadphaseAboveItsCallLimitIsNotCompared) {
  const Scene scene = sparse_grid(150000);
  ASSERT_EQ(body_count(scene), 150000u);
  const ValidationResult r = fcl_naive_candidate_sets(scene, 5);
  EXPECT_TRUE(r.pass) << r.detail;
  EXPECT_NE(r.detail.find("fcl-naive (not compared: a quadratic broadphase's one call would be 1.1e+10 AABB tests on "
                          "150000 boxes, above 1e+10)"),
            std::string::npos)
      << r.detail;
}

// Above 200,000 boxes a subquadratic broadphase is compared once in ceil(n / 200,000) judged
// frames, from the first: 250,000 boxes 0.5 m apart give once in 2, so of two judged frames
// the first. The detail names the stride; a broadphase that adds a pair is caught on the
// frame it is compared on, once.
TEST(Validators, LargeScenesCompareBroadphasesOnAStride) {
  const Scene scene = sparse_grid(250000);
  ASSERT_EQ(body_count(scene), 250000u);
  auto candidate_sets = [&](bool add_one) {
    World world(scene);
    std::unique_ptr<BroadPhase> bp = make_broadphase(scene.broadphase, scene.domain);
    if (add_one) bp = std::make_unique<AddingBroadPhase>(std::move(bp));
    std::vector<std::unique_ptr<BroadPhase>> extra;
    extra.push_back(std::move(bp));
    return find(run(world, 10, std::move(extra)), "candidate-sets");
  };
  const ValidationResult clean = candidate_sets(false);
  EXPECT_TRUE(clean.pass) << clean.detail;
  EXPECT_NE(clean.detail.find("octree (on 1 of the 2 frames: above 200000 boxes a broadphase is compared once in 2 "
                              "judged frames)"),
            std::string::npos)
      << clean.detail;
  const ValidationResult planted = candidate_sets(true);
  EXPECT_FALSE(planted.pass) << planted.detail;
  EXPECT_EQ(planted.measured, 1.0) << planted.detail;
  EXPECT_NE(planted.detail.find("frame 5: adds-one-pair adds pair (0, 1)"), std::string::npos) << planted.detail;
}

// candidate-sets' `flat` set is broadphase-completeness' pairs with a dynamic body (computed
// once a frame, PhysicsValidators::flat_pairs) joined with the static bodies' own pairs. In
// mixed-boxes the open box's floor and four walls overlap along eight edges: a broadphase that leaves out
// those static-static pairs is caught, naming the first, on every judged frame.
TEST(Validators, CandidateSetsHoldTheStaticStaticPairs) {
  const Scene scene = mixed_boxes();
  World probe(scene);
  probe.set_recording(true);
  probe.step();
  const std::vector<float>& w = probe.model().initial.w;
  std::vector<Pair> all;
  exact_pairs(probe.record().aabbs, all);
  std::vector<Pair> walls;
  std::copy_if(all.begin(), all.end(), std::back_inserter(walls),
               [&](Pair p) { return w[p.a] == 0.0f && w[p.b] == 0.0f; });
  ASSERT_EQ(walls.size(), 8u);

  World world(scene);
  std::vector<std::unique_ptr<BroadPhase>> extra;
  extra.push_back(std::make_unique<StaticDroppingBroadPhase>(make_broadphase(scene.broadphase, scene.domain), w));
  const ValidationResult r = find(run(world, 20, std::move(extra)), "candidate-sets");
  EXPECT_FALSE(r.pass) << r.detail;
  EXPECT_EQ(r.measured, 4.0) << r.detail;  // frames 5, 10, 15, 20
  EXPECT_NE(r.detail.find(fmt::format("frame 5: drops-static-pairs misses pair ({}, {}) (8 missing, 0 extra)",
                                      walls[0].a, walls[0].b)),
            std::string::npos)
      << r.detail;
}

// The physics tier keeps a checked frame's `flat` set (its pairs with a dynamic body) for the
// model tier, and only that frame's: exact_pairs on the frame's AABBs less the static-static
// pairs; none after a frame that is not checked.
TEST(Validators, PhysicsKeepsTheCheckedFramesFlatPairs) {
  World world(mixed_boxes());
  world.set_recording(true);
  PhysicsValidators v(world.model(), octocd_physics_bodies(world.model()), Tolerances{}, "engine cpu");
  const std::vector<float>& w = world.model().initial.w;
  for (int f = 1; f <= 30; ++f) {
    world.step();
    const bool checked = f % 2 == 0;
    v.observe(world.record(), checked);
    if (!checked) {
      EXPECT_EQ(v.flat_pairs(), nullptr) << "frame " << f;
      continue;
    }
    ASSERT_NE(v.flat_pairs(), nullptr) << "frame " << f;
    std::vector<Pair> want;
    exact_pairs(world.record().aabbs, want);
    want.erase(std::remove_if(want.begin(), want.end(), [&](Pair p) { return w[p.a] == 0.0f && w[p.b] == 0.0f; }),
               want.end());
    EXPECT_EQ(*v.flat_pairs(), want) << "frame " << f;
  }
}

/// Boxes of 1 kg, {half side, position, velocity} each (float32 values written exactly), in
/// boxes-uniform-1m's closed box, no gravity, dt 1 ms, AABB-only midphase: an island of that
/// scene cut out with its wall.
Scene island_of_boxes(const std::string& name, const std::vector<std::array<std::array<double, 3>, 3>>& boxes) {
  std::string groups;
  for (std::size_t k = 0; k < boxes.size(); ++k) {
    const auto& [h, x, v] = boxes[k];
    groups += fmt::format(R"({}{{"name": "b{}", "shape": {{"box": [{}, {}, {}]}}, "count": 1, "mass": 1.0,
      "positions": [[{}, {}, {}]], "velocity": {{"type": "fixed", "value": [{}, {}, {}]}}}})",
                          k ? ", " : "", k, h[0], h[1], h[2], x[0], x[1], x[2], v[0], v[1], v[2]);
  }
  return parse_scene(R"({"name": ")" + name + R"(", "domain": {"min": [-7.891, -7.891, -7.891],
    "max": [7.891, 7.891, 7.891]}, "gravity": [0, 0, 0], "dt": 0.001, "frames": 1, "walls": "closed-box",
    "broadphase": {"name": "octree", "depth": "auto"}, "midphase": {"levels": "aabb-only"},
    "groups": [)" + groups + "]}",
                     name);
}

/// impulse-feasibility's row after one step of `scene` on octocd's cpu engine, its record
/// changed by `edit(rec)` before it is judged (every frame checked).
template <class Edit>
ValidationResult feasibility_after_step(const Scene& scene, Edit&& edit) {
  World world(scene);
  ValidationOptions opt;
  opt.every = 1;
  world.set_recording(true);
  FrameValidators v(world, opt, {});
  world.step();
  FrameRecord rec = world.record();
  edit(rec);
  v.observe(rec, true);
  return find(v.results(), "impulse-feasibility");
}

// impulse-feasibility's programme on two islands of boxes-uniform-1m's frames 46 and 47 (the
// cpu and cuda engines step them bit for bit), cut out with their wall, where a resting box
// (its bound 1e-9 kg m/s) was left 102 and 23 x off by CLP's dual simplex on columns in kg m/s
// (impulses a few 1e-9 below 0 taken as 0; FeasibilityColumnsInUnitsOfTheirBounds): its
// second opinions (its dual simplex with its scaling, its primal simplex) found impulses
// within 0.003 of the bounds, and the columns in units of their bounds do on the first solve.
// The resting box given a sideways velocity that nothing pushes still fails.
TEST(Validators, FeasibilityTakesSecondOpinionsOnAFailure) {
  const double L = 0.06, S = 0.03;
  const std::vector<Scene> islands = {
      island_of_boxes("frame-46", {{{{L, L, L}, {-7.6283426, -6.334025, 1.7753646}, {-0.1872612, 0.18793195, -0.31167692}}},
                                   {{{L, L, L}, {-7.83114, -6.3594327, 1.6667272}, {0.0, 0.0, 0.0}}},
                                   {{{L, L, L}, {-7.650882, -6.2387633, 1.6551882}, {-0.18726122, 0.18793195, -0.6128431}}},
                                   {{{S, S, S}, {-7.741089, -6.3178673, 1.6713655}, {0.041854262, 0.034480896, -0.054673523}}}}),
      island_of_boxes("frame-47", {{{{L, L, L}, {3.4092658, -7.7352757, 0.13076447}, {0.6055453, -0.5222961, -0.2649205}}},
                                   {{{L, L, L}, {3.649894, -7.8310113, 0.18434112}, {0.0, 0.0, 0.0}}},
                                   {{{L, L, L}, {3.5294938, -7.746698, 0.10116594}, {0.3547347, 0.6149511, 0.099035025}}}})};
  for (const Scene& scene : islands) {
    // nudge: m/s added to the resting box's (body 7's) velocity after the step, along z (a
    // tangent of its wall's normal).
    auto feasibility = [&](double nudge) {
      return feasibility_after_step(scene, [&](FrameRecord& rec) { rec.v_post[7].z += static_cast<float>(nudge); });
    };
    const ValidationResult clean = feasibility(0.0);
    EXPECT_TRUE(clean.pass) << scene.name << ": " << clean.detail;
    EXPECT_NE(clean.detail.find("1 island-steps of 1 steps"), std::string::npos) << scene.name << ": " << clean.detail;
    EXPECT_LT(clean.measured, 0.01) << scene.name << ": " << clean.detail;
    // The resting box pushed sideways by 10^-3 kg m/s, 100 x its neighbours' bounds: friction
    // from the wall needs a normal impulse that only a neighbour could balance.
    const ValidationResult planted = feasibility(1e-3);
    EXPECT_FALSE(planted.pass) << scene.name << ": " << planted.detail;
    EXPECT_NE(planted.detail.find("infeasible 1 of 1 island-steps"), std::string::npos)
        << scene.name << ": " << planted.detail;
  }
}

// impulse-feasibility's programme where CLP leaves an impulse a few 1e-9 kg m/s below 0
// (inside its tolerance on a column's bound when the columns are in kg m/s): taken as 0, it
// left a resting box of boxes-uniform-1m's frame 256 (its bound 1e-9 kg m/s) 3.2 x off on
// every solve, while the engine's own impulses explain the step. The island of 9 boxes cut
// out with its wall (the cpu engine's state before the step); the columns are scaled to
// their rows' bounds (feasibility_programme.cpp). The resting box (body 6) pushed sideways
// along its wall by 10^-3 kg m/s still fails.
TEST(Validators, FeasibilityColumnsInUnitsOfTheirBounds) {
  const double L = 0.06, S = 0.03;
  const Scene scene = island_of_boxes(
      "frame-256", {{{{L, L, L}, {-1.50899065, 1.03579557, -7.83187771}, {0, 0, 0}}},
                    {{{S, S, S}, {-1.4380703, 0.956857681, -7.74182034}, {0.0440209061, 0.123933017, 0.0223416183}}},
                    {{{S, S, S}, {-1.53893197, 0.955703497, -7.74199677}, {0.234047472, 0.00365946139, 0.00906473026}}},
                    {{{L, L, L}, {-1.2759161, 1.02733028, -7.82561922}, {-0.108271435, 0.0581813566, -0.288225621}}},
                    {{{L, L, L}, {-1.47998559, 1.04659963, -7.71154451}, {0.0133332498, 0.0933347419, 0.00322915521}}},
                    {{{S, S, S}, {-1.36588466, 1.1064775, -7.79340601}, {-0.116171069, -0.25140205, -0.314820796}}},
                    {{{S, S, S}, {-1.45562768, 0.896854699, -7.77458763}, {0.135627627, 0.0619862527, -0.107658662}}},
                    {{{S, S, S}, {-1.42586422, 1.13648748, -7.73914099}, {-0.115097098, 0.083334744, -0.0371444076}}},
                    {{{S, S, S}, {-1.45027947, 0.896986425, -7.68848801}, {0.156151041, 0.133933023, 0.0946545303}}}});
  auto feasibility = [&](double nudge) {
    return feasibility_after_step(scene, [&](FrameRecord& rec) { rec.v_post[6].x += static_cast<float>(nudge); });
  };
  const ValidationResult clean = feasibility(0.0);
  EXPECT_TRUE(clean.pass) << clean.detail;
  EXPECT_NE(clean.detail.find("of 1 steps"), std::string::npos) << clean.detail;
  const ValidationResult planted = feasibility(1e-3);
  EXPECT_FALSE(planted.pass) << planted.detail;
  EXPECT_NE(planted.detail.find("infeasible 1 of 1 island-steps"), std::string::npos) << planted.detail;
}

// impulse-feasibility's islands passed on witness impulses (Gauss-Seidel sweeps within the
// pyramids) without their programmes: the row's worst figure and failures on a step of 100
// islands are those of each island judged alone (every other body asleep: its programme
// solved, a probe). 100 stacks of one to three boxes on the floor (y up), no gravity; each
// top box given a sideways velocity after the step (none on every 7th), v0 x k^j m/s for
// stack j. v0 6e-10, k 1.001: every island within its bound, the witnesses' figures (a box
// pushed sideways off a floor it does not press: none) 1.6 x their programmes', those of
// the 22 islands beyond the 64 largest above the programmes' largest (solved in a second
// round); v0 1e-11, k 1.1: 39 fail.
TEST(Validators, FeasibilityWitnessesKeepTheProgrammesVerdict) {
  std::string groups;
  for (int j = 0; j < 100; ++j)
    for (int level = 0; level <= j % 3; ++level)
      groups += fmt::format(R"({}{{"name": "s{}-{}", "shape": {{"box": [0.1, 0.1, 0.1]}}, "count": 1, "mass": {},
        "positions": [[{}, {}, {}]], "velocity": {{"type": "fixed", "value": [0, 0, 0]}}}})",
                            groups.empty() ? "" : ", ", j, level, 1.0 + 0.01 * (j % 4), -1.75 + 0.35 * (j % 10),
                            -1.9 + 0.2 * level, -1.75 + 0.35 * (j / 10));
  const Scene scene = parse_scene(R"({"name": "stacks", "domain": {"min": [-2, -2, -2], "max": [2, 2, 2]},
    "gravity": [0, 0, 0], "dt": 0.01, "frames": 1, "walls": "floor",
    "broadphase": {"name": "octree", "depth": "auto"}, "midphase": {"levels": "aabb-only"},
    "groups": [)" + groups + "]}",
                                  "stacks");
  // Body index of each stack's top box: the floor is body 0, the boxes follow in order.
  std::vector<std::uint32_t> top;
  for (std::uint32_t j = 0, next = 1; j < 100; ++j) {
    next += j % 3 + 1;
    top.push_back(next - 1);
  }
  // The row on the step with sideways velocities v0 k^j, with only `alone`'s stack awake
  // (-1: every stack).
  auto feasibility = [&](double v0, double k, int alone) {
    return feasibility_after_step(scene, [&](FrameRecord& rec) {
      for (int j = 0; j < 100; ++j)
        if (j % 7 != 0) (j % 2 ? rec.v_post[top[std::size_t(j)]].x : rec.v_post[top[std::size_t(j)]].z) +=
                            static_cast<float>(v0 * std::pow(k, j));
      if (alone >= 0) {
        rec.asleep_pre.assign(rec.v_post.size(), 1);
        const std::uint32_t t = top[std::size_t(alone)];
        for (int level = 0; level <= alone % 3; ++level) rec.asleep_pre[t - std::uint32_t(level)] = 0;
        rec.asleep_post = rec.asleep_pre;
      }
    });
  };
  // The row's worst figure (its detail's "worst X of its bound", 3 digits; failing: its
  // cause's worst).
  auto figure = [](const ValidationResult& r) {
    if (!r.pass) return r.causes.at(0).worst;
    const std::size_t at = r.detail.find("worst ");
    return at == std::string::npos ? -1.0 : std::stod(r.detail.substr(at + 6));
  };
  for (const auto& [v0, k] : {std::pair<double, double>{6e-10, 1.001}, {1e-11, 1.1}}) {
    const ValidationResult all = feasibility(v0, k, -1);
    ASSERT_TRUE(all.applicable) << all.detail;
    EXPECT_NE(all.detail.find("100 island-steps of 1 steps"), std::string::npos) << all.detail;
    double worst = 0;
    std::set<std::string> failing;
    for (int j = 0; j < 100; ++j) {
      const ValidationResult one = feasibility(v0, k, j);
      ASSERT_NE(one.detail.find("1 island-steps of 1 steps"), std::string::npos) << j << ": " << one.detail;
      EXPECT_EQ(one.detail.find("passed on impulses found by Gauss-Seidel"), std::string::npos) << one.detail;
      worst = std::max(worst, figure(one));
      if (!one.pass) failing.insert(one.causes.at(0).items.begin(), one.causes.at(0).items.end());
    }
    EXPECT_GT(worst, 0.1) << "k " << k;
    EXPECT_EQ(figure(all), worst) << "k " << k << ": " << all.detail;
    EXPECT_EQ(all.pass ? std::vector<std::string>{} : all.causes.at(0).items,
              std::vector<std::string>(failing.begin(), failing.end()))
        << "k " << k << ": " << all.detail;
    EXPECT_EQ(failing.size(), k < 1.05 ? 0u : 39u) << "k " << k << ": " << all.detail;
    // Islands passed on their witnesses where the step's largest figure is within the bound.
    if (failing.empty()) {
      EXPECT_NE(all.detail.find("passed on impulses found by Gauss-Seidel"), std::string::npos) << all.detail;
    }
  }
}

TEST(Validators, MidphaseCompletenessCatchesLossyPruning) {
  if (!std::filesystem::exists(source_dir() + "/datasets/cache/bunny.obj"))
    GTEST_SKIP() << "datasets not fetched";
  Scene scene = load_scene(source_dir() + "/datasets/scenes/bunny-stack-50.json");
  World world(scene);
  // Halving theta loses contacts whose closest vertices are between theta/2 and theta.
  auto lossy = [](const PlacedShape& a, const PlacedShape& b, float theta, const MidphaseConfig& c,
                  MidphaseStats& st) { return confirm_contact(a, b, 0.5f * theta, c, st); };
  for (int f = 0; f < 600; ++f) world.step();  // let them land
  const ValidationResult r = find(run(world, 100, {}, lossy), "midphase-completeness");
  EXPECT_FALSE(r.pass) << r.detail;
}

TEST(Validators, ContactNormalsCatchAFlippedNormal) {
  PlantedFaults f;
  f.normal_sign = true;
  FaultyWorld world(mixed_boxes(), f);
  const ValidationResult r = find(run(world, 60), "contact-geometry");
  EXPECT_TRUE(r.applicable);
  EXPECT_FALSE(r.pass) << r.detail;
  EXPECT_GT(r.measured, 90.0);  // degrees: the flipped normal is 180 deg from FCL's
  EXPECT_NE(r.detail.find("the convention is from B to A"), std::string::npos) << r.detail;
}

TEST(Validators, NonPenetrationCatchesBetaOvershoot) {
  Scene scene = mixed_boxes();
  scene.response.beta = 1.5f;  // outside (0, 1]: the scene loader would refuse it
  World world(scene);
  const ValidationResult r = find(run(world, 300), "non-penetration-eq14");
  EXPECT_FALSE(r.pass) << r.detail;
}

TEST(Validators, FrictionCatchesTheWrongSign) {
  PlantedFaults f;
  f.friction_sign = true;
  FaultyWorld world(mixed_boxes(), f);
  const ValidationResult r = find(run(world, 300), "friction-monotonicity");
  EXPECT_FALSE(r.pass) << r.detail;
}

TEST(Validators, ConservationCatchesEq12WeightsAndMomentumLeak) {
  for (int fault = 0; fault < 2; ++fault) {
    PlantedFaults f;
    f.eq12_weights = fault == 0;
    f.momentum_leak = fault == 1;
    FaultyWorld world(mixed_boxes(), f);
    const ValidationResult r = find(run(world, 300), "impulse-conservation");
    EXPECT_FALSE(r.pass) << "fault " << fault << ": " << r.detail;
    EXPECT_NE(r.detail.find(fault == 0 ? "centre" : "momentum"), std::string::npos) << r.detail;
  }
}

TEST(Validators, AnalyticAndBulletCatchWrongFriction) {
  const Scene scene = load_scene(source_dir() + "/datasets/scenes/slide.json");
  const Tolerances tol;
  {
    World good(scene);
    const ValidationResult a = validate_analytic(good, scene.frames, tol);
    EXPECT_TRUE(a.pass) << a.detail;
    World good2(scene);
    const ValidationResult b = validate_against_bullet(good2, scene.frames, tol);
    EXPECT_TRUE(b.pass) << b.detail;
  }
  PlantedFaults f;
  f.friction_sign = true;
  FaultyWorld bad(scene, f);
  const ValidationResult a = validate_analytic(bad, scene.frames, tol);
  EXPECT_FALSE(a.pass) << a.detail;
  FaultyWorld bad2(scene, f);
  const ValidationResult b = validate_against_bullet(bad2, scene.frames, tol);
  EXPECT_FALSE(b.pass) << b.detail;
}

namespace {

/// A correct engine whose bodies are pushed sideways after every step (v.x = 0.3 m/s, the
/// whole stack alike): a stack that slides along the floor and never comes to rest, at the
/// right heights.
class PushedWorld : public Engine {
 public:
  explicit PushedWorld(const Scene& scene) : inner_(scene) {}
  std::string name() const override { return "pushed"; }
  std::string device() const override { return inner_.device(); }
  std::string broadphase_name() const override { return inner_.broadphase_name(); }
  const Model& model() const override { return inner_.model(); }
  const FrameMetrics& step() override {
    inner_.step();
    BodyState s = inner_.state();
    for (std::size_t i = 0; i < s.size(); ++i)
      if (s.w[i] > 0.0f) s.v[i].x = 0.3f;
    inner_.set_state(s);
    return inner_.last_metrics();
  }
  const BodyState& state() const override { return inner_.state(); }
  const FrameMetrics& last_metrics() const override { return inner_.last_metrics(); }
  std::int64_t frame() const override { return inner_.frame(); }
  const std::vector<ContactRecord>& contacts() const override { return inner_.contacts(); }

 private:
  World inner_;
};

bool has_cause(const ValidationResult& r, const std::string& name) {
  for (const ValidationCause& c : r.causes)
    if (c.name == name) return true;
  return false;
}

}  // namespace

// design.md section 7.8 compares settled heights: a pile still falling has none. 24 boxes let go at rest
// in the air are a pile; after 30 frames they fall in Bullet too: n/a, naming Bullet's
// speed. After 3000 frames both rest and the heights are compared. Before: the heights of
// two falling piles were compared (mixed-pile-1000 passed at 300 frames while falling at
// 2.6 m/s; bunny-pile-10k failed at 300 frames while still moving).
TEST(Validators, BulletDynamicsComparesHeightsOnlyOnceBulletRests) {
  const Scene pile = parse_scene(R"({
    "name": "falling-pile", "domain": {"min": [-0.5, 0, -0.5], "max": [0.5, 1.5, 0.5]},
    "walls": "open-box",
    "groups": [{"name": "b", "shape": {"box": [0.06, 0.05, 0.07]}, "count": 24,
                "layout": {"type": "grid", "min": [-0.35, 0.3, -0.35], "max": [0.35, 1.2, 0.35],
                           "spacing": 0.2}}]})",
                                 "falling-pile (test)");
  World falling(pile);
  const ValidationResult r = validate_against_bullet(falling, 30, Tolerances());
  EXPECT_FALSE(r.applicable) << r.detail;
  EXPECT_NE(r.detail.find("Bullet has not come to rest after 30 frames (pile)"), std::string::npos) << r.detail;
  EXPECT_NE(r.detail.find("validate with more --frames"), std::string::npos) << r.detail;
  World rested(pile);
  const ValidationResult s = validate_against_bullet(rested, 3000, Tolerances());
  EXPECT_TRUE(s.applicable && s.pass) << s.detail;
}

// A resting stack: octocd's engine and Bullet colliding hulls (an engine that is not
// octocd) pass; a run pushed sideways every step keeps its heights (the height figure alone passes
// it) and fails as still moving where Bullet rests.
TEST(Validators, BulletDynamicsCatchesARunThatKeepsMovingWhereBulletRests) {
  const Scene scene = load_scene(source_dir() + "/datasets/scenes/box-stack.json");
  const int frames = 300;
  {
    World good(scene);
    const ValidationResult r = validate_against_bullet(good, frames, Tolerances());
    EXPECT_TRUE(r.applicable && r.pass) << r.detail;
    EXPECT_NE(r.detail.find("moved over the last 30 frames: octocd"), std::string::npos) << r.detail;
  }
  {
    World model_of(scene);
    BulletSettings hulls;
    hulls.shape = BulletShape::Hull;
    BulletWorld other(model_of, hulls);
    const ValidationResult r = validate_against_bullet(other, frames, Tolerances());
    EXPECT_TRUE(r.applicable && r.pass) << r.detail;
  }
  PushedWorld pushed(scene);
  const ValidationResult r = validate_against_bullet(pushed, frames, Tolerances());
  ASSERT_TRUE(r.applicable) << r.detail;
  EXPECT_FALSE(r.pass) << r.detail;
  EXPECT_LE(r.measured, r.bound) << "the heights agree: only the new cause catches it; " << r.detail;
  EXPECT_TRUE(has_cause(r, "still-moving")) << r.detail;
  EXPECT_FALSE(has_cause(r, "height")) << r.detail;
}

TEST(Validators, ResultsGoToTheTrace) {
  const std::string path =
      (std::filesystem::temp_directory_path() / ("octocd-validation-" + std::to_string(::getpid()) + ".h5"))
          .string();
  World world(mixed_boxes());
  {
    TraceWriter w(path, trace_metadata(world, 10), trace_bodies(world), TraceOptions{});
    w.append_frame(world.step(), world.state(), world.contacts());
  }
  const auto rs = run(world, 20);
  write_validation(path, rs);
  write_validation(path, rs);  // rewriting replaces the group
  EXPECT_EQ(read_trace_summary(path).frames, 1);
  std::filesystem::remove(path);
}

// ---- a stop inside a frame's checks (issue 19 item 4) --------------------------------

namespace {

std::atomic<bool> g_slow_started{false};
std::mutex g_slow_mutex;
std::condition_variable g_slow_released;
bool g_slow_release = false;  // guarded by g_slow_mutex

/// A broadphase whose find_pairs does not return until released (up to 2 minutes): one
/// call of an O(n^2) broadphase on 10^5 bodies, which polls nothing.
class EndlessBroadPhase : public BroadPhase {
 public:
  std::string name() const override { return "endless"; }
  void find_pairs(const std::vector<Aabb>&, std::vector<Pair>& out, BroadPhaseStats&) override {
    g_slow_started = true;
    std::unique_lock<std::mutex> lock(g_slow_mutex);
    g_slow_released.wait_for(lock, std::chrono::minutes(2), [] { return g_slow_release; });
    out.clear();
  }
};

}  // namespace

// ValidationOptions::stop is honoured inside the candidate-set check, while a broadphase
// call that polls nothing is still running: observe throws ValidationStopped, and the
// rows so far (with their own times) remain, the candidate-sets row naming the comparisons
// the stop left out. Before: the check ran to the call's end.
TEST(Validators, AStopEndsACheckWhoseBroadphaseCallPollsNothing) {
  const Scene scene = mixed_boxes();
  World world(scene);
  world.set_recording(true);
  ValidationOptions opt;
  opt.stop = [] { return g_slow_started.load(); };  // stop once the endless call runs
  std::vector<std::unique_ptr<BroadPhase>> extra;
  extra.push_back(std::make_unique<EndlessBroadPhase>());
  FrameValidators v(world, opt, std::move(extra));
  world.step();
  v.observe(world, false);  // no candidate-set check: no stop
  world.step();
  // Without the stop inside the check, observe would wait the 2 minutes and return.
  EXPECT_THROW(v.observe(world, true), ValidationStopped);
  {
    const std::lock_guard<std::mutex> lock(g_slow_mutex);
    g_slow_release = true;
  }
  g_slow_released.notify_all();  // the helper thread ends
  const std::vector<ValidationResult> rs = v.results();
  EXPECT_EQ(rs.size(), 15u);
  for (const ValidationResult& r : rs) EXPECT_GE(r.seconds, 0.0) << r.name;
  EXPECT_GT(find(rs, "applied-state").seconds, 0.0);
  // The broadphases the stop left uncompared on the frame are named as such.
  const std::string& detail = find(rs, "candidate-sets").detail;
  EXPECT_NE(detail.find("(on 0 of the 1 frames: the run stopped before its comparison on the last)"),
            std::string::npos)
      << detail;
  EXPECT_EQ(detail.find("quadratic"), std::string::npos) << detail;
}

// validate_engine stopped by ValidationOptions::stop inside the checks: the results of
// the frames judged, the reruns n/a with the reason.
TEST(Validators, ValidateEngineStoppedInsideAFrameKeepsItsRows) {
  const Scene scene = mixed_boxes();
  const std::shared_ptr<const Model> model = build_model(scene);
  ValidationOptions opt;
  opt.frames = 50;
  opt.every = 5;
  opt.against_fcl = false;
  int polls = 0;
  opt.stop = [&] { return ++polls > 40; };  // some poll inside a frame's checks
  std::int64_t stopped_in = 0;
  const std::vector<ValidationResult> rs = validate_engine(
      [&]() -> std::unique_ptr<Engine> {
        return std::make_unique<World>(model, make_any_broadphase(scene.broadphase, scene.domain));
      },
      opt, &stopped_in);
  EXPECT_GT(stopped_in, 0);
  EXPECT_LE(stopped_in, 50);
  EXPECT_FALSE(find(rs, "analytic").applicable);
  EXPECT_NE(find(rs, "analytic").detail.find("not run: stopped after frame"), std::string::npos);
  EXPECT_FALSE(find(rs, "bullet-dynamics").applicable);
}

}  // namespace octocd_test_validation
