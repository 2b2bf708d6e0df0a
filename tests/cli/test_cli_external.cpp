// `octocd validate --trace-in`: another engine's trace judged frame by frame (issue 11).
// Malformed traces exit 2 naming the dataset, the frame and the problem; the Python toy
// engine's planted missed pair exits 3 naming the frame and the pair; octocd's own traces
// (every state, contacts) pass.
#include <gtest/gtest.h>
#include <hdf5.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <functional>
#include <limits>
#include <string>
#include <vector>

#include "support/cli_run.hpp"
#include "support/external_trace.hpp"

// This file's own names (its tests compile in unity batches with the folder's other files).
namespace octocd_test_cli_external {

namespace fs = std::filesystem;

namespace {

using octocd::test::Result;
using octocd::test::bin;
using octocd::test::source_dir;
using octocd::test::run;
using octocd::test::Trace;

class TraceIn : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() /
           ("octocd-trace-in-" + std::to_string(::getpid()) + "-" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }

  /// Writes `t` and runs `octocd validate --trace-in` on it.
  Result validate(const Trace& t, const std::string& extra = "") {
    const std::string path = (dir_ / "t.h5").string();
    t.write(path);
    return run(bin() + " validate --trace-in " + path + " " + extra);
  }

  fs::path dir_;
};

/// Expects exit 2 and every piece of `names` in the message.
void expect_bad(const Result& r, const std::vector<std::string>& names) {
  EXPECT_EQ(r.code, 2) << r.output;
  for (const std::string& n : names) EXPECT_NE(r.output.find(n), std::string::npos) << n << " not in:\n" << r.output;
  EXPECT_EQ(r.output.find("validator "), std::string::npos) << "judged anyway:\n" << r.output;
}

}  // namespace

TEST_F(TraceIn, AValidTracePassesAndChecksClean) {
  const Result r = validate(Trace{});
  EXPECT_EQ(r.code, 0) << r.output;
  EXPECT_NE(r.output.find("engine 'test-engine', 3 bodies, 3 frames"), std::string::npos) << r.output;
  const Result c = validate(Trace{}, "--check-only");
  EXPECT_EQ(c.code, 0) << c.output;
  EXPECT_NE(c.output.find("valid external trace"), std::string::npos) << c.output;
}

TEST_F(TraceIn, AMissedPairFailsNamingFrameAndPair) {
  Trace t;
  t.pairs = {1, 2, 1, 2};  // frame 2 has no pair
  t.pair_offsets = {0, 1, 1, 2};
  const Result r = validate(t);
  EXPECT_EQ(r.code, 3) << r.output;
  EXPECT_NE(r.output.find("frame 2: engine 'test-engine' misses pair (1, 2)"), std::string::npos) << r.output;
}

TEST_F(TraceIn, MissingRequiredDatasets) {
  for (const char* name : {"/bodies/inverse_mass", "/bodies/local_aabb_min", "/contacts/normal", "/pairs/pair"}) {
    Trace t;
    t.skip = {name};
    expect_bad(validate(t), {name, "missing"});
  }
  Trace none;
  none.skip = {"/states/position", "/states/velocity", "/aabbs/min", "/aabbs/max"};
  expect_bad(validate(none), {"/states/position", "missing"});
}

TEST_F(TraceIn, MismatchedShapesAndBodyCounts) {
  Trace rows;
  rows.velocity.resize(rows.velocity.size() - 9);  // one state row short
  expect_bad(validate(rows), {"/states/velocity", "shape 3 x 3 x 3"});
  Trace bodies;
  bodies.aabb_bodies = 2;  // two bodies per frame in /aabbs
  bodies.aabb_min.resize(3 * 2 * 3);
  bodies.aabb_max.resize(3 * 2 * 3);
  expect_bad(validate(bodies), {"/aabbs/min", "shape 3 x 2 x 3", "3 bodies"});
  Trace masses;
  masses.inverse_mass = {1.0f, 1.0f};
  expect_bad(validate(masses), {"/bodies/inverse_mass", "one per body"});
  Trace offsets;
  offsets.contact_offsets = {0, 1, 2};
  expect_bad(validate(offsets), {"/contacts/offsets", "F + 1"});
}

TEST_F(TraceIn, NonFiniteValuesNameDatasetAndFrame) {
  Trace t;
  t.position[3 * (3 * 3 + 1) + 1] = std::numeric_limits<float>::quiet_NaN();  // row 3, body 1
  expect_bad(validate(t), {"/states/position", "frame 3", "body 1", "not finite"});
  Trace n;
  n.normal[3] = std::numeric_limits<float>::infinity();  // frame 2's contact
  expect_bad(validate(n), {"/contacts/normal", "frame 2", "unit vector"});
}

TEST_F(TraceIn, BadPairsNameDatasetFrameAndProblem) {
  Trace out_of_range;
  out_of_range.pairs = {1, 2, 1, 7, 1, 2};
  expect_bad(validate(out_of_range), {"/pairs/pair", "frame 2", "(1, 7)", "out of range"});
  Trace order;
  order.pairs = {1, 2, 2, 1, 1, 2};
  expect_bad(validate(order), {"/pairs/pair", "frame 2", "(2, 1): a >= b"});
  Trace unsorted;
  unsorted.pairs = {1, 2, 1, 2, 0, 2, 1, 2};
  unsorted.pair_offsets = {0, 1, 3, 4};
  expect_bad(validate(unsorted), {"/pairs/pair", "frame 2", "not sorted"});
  Trace duplicated;
  duplicated.contact_pair = {1, 2, 1, 2, 1, 2, 1, 2};
  duplicated.contact_offsets = {0, 1, 1, 4};
  duplicated.normal.insert(duplicated.normal.end(), {-1, 0, 0});
  duplicated.depth.push_back(0.001f);
  duplicated.jn.push_back(0);
  duplicated.jt.push_back(0);
  expect_bad(validate(duplicated), {"/contacts/pair", "frame 3", "duplicated"});
}

TEST_F(TraceIn, AFlippedNormalConventionIsNamed) {
  Trace t;
  t.normal = {1, 0, 0, 1, 0, 0, 1, 0, 0};  // from A to B
  const Result r = validate(t);
  EXPECT_EQ(r.code, 3) << r.output;
  EXPECT_NE(r.output.find("the convention is from B to A"), std::string::npos) << r.output;
}

TEST_F(TraceIn, OctocdsOwnTracePasses) {
  const std::string trace = (dir_ / "own.h5").string();
  const Result w = run(bin() + " run " + source_dir() + "/tests/data/spheres-drop.json --frames 60 --state-every 1 " +
                       "--contacts --quiet --trace " + trace);
  ASSERT_EQ(w.code, 0) << w.output;
  const Result r = run(bin() + " validate --trace-in " + trace + " --every 5");
  EXPECT_EQ(r.code, 0) << r.output;
  EXPECT_NE(r.output.find("engine 'cpu', 32 bodies, 60 frames"), std::string::npos) << r.output;
}

TEST_F(TraceIn, PythonToyEngineFailsOnItsPlantedMissedPair) {
  const std::string python = "/usr/bin/python3";
  if (run(python + " -c 'import h5py, numpy'").code != 0)
    GTEST_SKIP() << python << " lacks h5py or numpy (Debian: python3-h5py): the example cannot run";
  const std::string example = source_dir() + "/examples/python/toy_engine.py";
  const std::string planted = (dir_ / "toy.h5").string(), clean = (dir_ / "clean.h5").string();
  ASSERT_EQ(run(python + " " + example + " " + planted).code, 0);
  const Result r = run(bin() + " validate --trace-in " + planted);
  EXPECT_EQ(r.code, 3) << r.output;
  EXPECT_NE(r.output.find("frame 7: engine 'toy-engine' misses pair (2, 3)"), std::string::npos) << r.output;
  ASSERT_EQ(run(python + " " + example + " --no-plant " + clean).code, 0);
  const Result ok = run(bin() + " validate --trace-in " + clean);
  EXPECT_EQ(ok.code, 0) << ok.output;
}

TEST_F(TraceIn, SceneAndTraceInAreExclusive) {
  const std::string path = (dir_ / "t.h5").string();
  Trace{}.write(path);
  EXPECT_EQ(run(bin() + " validate").code, 2);
  EXPECT_EQ(run(bin() + " validate " + source_dir() + "/tests/data/spheres-drop.json --trace-in " + path).code, 2);
  EXPECT_EQ(run(bin() + " validate --trace-in " + (dir_ / "missing.h5").string()).code, 2);
}

// ---- External traces version 2 (design.md section 13, issue 17): rotation, inertia, manifolds with
// points, materials. Every problem exits 2 with and without --check-only, naming the
// dataset (or attribute), the frame (or body) and the allowed values.

namespace {

/// Expects exit 2 naming every piece of `names`, with and without --check-only.
void expect_bad_both(const std::function<Result(const std::string&)>& validate, const std::vector<std::string>& names) {
  expect_bad(validate("--check-only"), names);
  expect_bad(validate(""), names);
}

/// Grows make_v2's contacts to 7 rows: frame 2 has (0, 1), (1, 2), (0, 1).
Trace split_manifold() {
  Trace t = Trace::make_v2();
  t.contact_offsets = {0, 2, 5, 7};
  t.contact_pair = {1, 2, 1, 2, 0, 1, 1, 2, 0, 1, 1, 2, 1, 2};
  t.normal.clear();
  for (int k = 0; k < 7; ++k) t.normal.insert(t.normal.end(), {-1, 0, 0});
  t.depth.assign(7, 0.001f);
  t.jn.assign(7, 0.01f);
  t.jt.assign(7, 0.0f);
  t.point.assign(21, 0.1f);
  return t;
}

}  // namespace

TEST_F(TraceIn, AVersion2TraceOfARotatingEngineChecksCleanAndIsJudged) {
  const Result c = validate(Trace::make_v2(), "--check-only");
  EXPECT_EQ(c.code, 0) << c.output;
  EXPECT_NE(c.output.find("version 2"), std::string::npos) << c.output;
  EXPECT_NE(c.output.find("rotation"), std::string::npos) << c.output;
  EXPECT_NE(c.output.find("manifolds"), std::string::npos) << c.output;
  const Result r = validate(Trace::make_v2());
  EXPECT_TRUE(r.code == 0 || r.code == 3) << r.output;  // judged, not refused
  EXPECT_NE(r.output.find("engine 'test-engine', 3 bodies, 3 frames"), std::string::npos) << r.output;
  // Conventions octocd's engine follows that physics does not need: no /aabbs, no
  // /pairs, a manifold's rows repeating the pair, materials absent.
  Trace bare = Trace::make_v2();
  bare.skip = {"/aabbs/min", "/aabbs/max", "/pairs/offsets", "/pairs/pair", "/bodies/inertia", "/bodies/friction",
               "/bodies/restitution"};
  bare.string_attrs.clear();
  bare.number_attrs.clear();
  EXPECT_EQ(validate(bare, "--check-only").code, 0);
}

TEST_F(TraceIn, Version2NonUnitQuaternionsAndMissingHalves) {
  Trace q = Trace::make_v2();
  for (int k = 0; k < 4; ++k) q.orientation[(2 * 3 + 1) * 4 + k] *= 1.01f;  // row 2, body 1
  auto v = [&](const Trace& t) { return [&, t](const std::string& extra) { return validate(t, extra); }; };
  expect_bad_both(v(q), {"/states/orientation", "frame 2", "body 1", "allowed: unit quaternions (w, x, y, z)",
                         "| |q| - 1 | <= 1e-3"});
  Trace small = Trace::make_v2();
  small.orientation[0] = 0.99f;  // row 0, body 0: |q| = 0.99
  expect_bad_both(v(small), {"/states/orientation", "frame 1", "body 0 before the step", "|q| = 0.99"});
  Trace no_w = Trace::make_v2();
  no_w.angular_velocity.clear();
  expect_bad_both(v(no_w), {"/states/angular_velocity", "missing (orientation without angular_velocity)",
                            "allowed: /states/orientation and /states/angular_velocity together"});
  Trace no_q = Trace::make_v2();
  no_q.orientation.clear();
  expect_bad_both(v(no_q), {"/states/orientation", "missing (angular_velocity without orientation)"});
}

TEST_F(TraceIn, Version2InertiaMustBeSymmetricPositiveDefinite) {
  auto v = [&](const Trace& t) { return [&, t](const std::string& extra) { return validate(t, extra); }; };
  Trace asym = Trace::make_v2();
  asym.inertia[9 + 1] = 0.002f;  // body 1: I[0][1] = 0.002, I[1][0] = 0
  expect_bad_both(v(asym), {"/bodies/inertia", "body 1", "not symmetric", "allowed: a symmetric positive definite"});
  Trace indefinite = Trace::make_v2();
  indefinite.inertia[18 + 8] = -0.001f;  // body 2: I[2][2] < 0
  expect_bad_both(v(indefinite), {"/bodies/inertia", "body 2", "not positive definite (leading minor 3",
                                  "leading minors > 0"});
  Trace dyn_zero = Trace::make_v2();
  dyn_zero.inertia.assign(27, 0.0f);  // zeros: fine for static body 0, not for 1
  expect_bad_both(v(dyn_zero), {"/bodies/inertia", "body 1", "not positive definite"});
  Trace shape = Trace::make_v2();
  shape.dims["/bodies/inertia"] = {3, 9};
  expect_bad_both(v(shape), {"/bodies/inertia", "2 dimensions", "allowed: 3 dimensions"});
}

TEST_F(TraceIn, Version2ManifoldRowsOfOnePairMustBeConsecutive) {
  auto v = [&](const Trace& t) { return [&, t](const std::string& extra) { return validate(t, extra); }; };
  expect_bad_both(v(split_manifold()), {"/contacts/pair", "frame 2", "row 2 is (0, 1) again after (1, 2)",
                                        "manifold rows of one pair not consecutive",
                                        "the rows of one pair (a manifold) consecutive"});
  // The same rows in (a, b) order: a valid manifold.
  Trace sorted = split_manifold();
  sorted.contact_pair = {1, 2, 1, 2, 0, 1, 0, 1, 1, 2, 1, 2, 1, 2};
  EXPECT_EQ(validate(sorted, "--check-only").code, 0);
}

TEST_F(TraceIn, Version2MaterialsOutsideTheirRange) {
  auto v = [&](const Trace& t) { return [&, t](const std::string& extra) { return validate(t, extra); }; };
  Trace mu = Trace::make_v2();
  mu.number_attrs["mu"] = -0.1;
  expect_bad_both(v(mu), {"/ (root attribute mu)", "-0.1", "allowed: a finite friction coefficient >= 0"});
  Trace e = Trace::make_v2();
  e.number_attrs["restitution"] = 1.5;
  expect_bad_both(v(e), {"/ (root attribute restitution)", "1.5", "allowed: a restitution in [0, 1]"});
  Trace friction = Trace::make_v2();
  friction.friction[1] = -1.0f;
  expect_bad_both(v(friction), {"/bodies/friction", "body 1: -1", "friction coefficient >= 0 per body"});
  Trace restitution = Trace::make_v2();
  restitution.restitution[2] = 2.0f;
  expect_bad_both(v(restitution), {"/bodies/restitution", "body 2: 2", "in [0, 1] per body"});
  Trace margin = Trace::make_v2();
  margin.number_attrs["contact_margin"] = -0.01;
  expect_bad_both(v(margin), {"/ (root attribute contact_margin)", "-0.01", "finite distance >= 0 (m)"});
  Trace exact = Trace::make_v2();
  exact.number_attrs["broadphase_exact"] = 2;
  expect_bad_both(v(exact), {"/ (root attribute broadphase_exact)", "allowed: 0", "or 1"});
  Trace count = Trace::make_v2();
  count.friction.pop_back();
  expect_bad_both(v(count), {"/bodies/friction", "shape 2", "3 values, one per body"});
}

TEST_F(TraceIn, Version2UnknownStrings) {
  auto v = [&](const Trace& t) { return [&, t](const std::string& extra) { return validate(t, extra); }; };
  Trace detection = Trace::make_v2();
  detection.string_attrs["detection"] = "post-step";
  expect_bad_both(v(detection), {"/ (root attribute detection)", "'post-step' unknown",
                                 "allowed: \"pre-step\", \"integrated\""});
  Trace combine = Trace::make_v2();
  combine.string_attrs["friction_combine"] = "median";
  expect_bad_both(v(combine), {"/ (root attribute friction_combine)", "'median' unknown",
                               "\"product\", \"min\", \"max\", \"average\", \"geometric\""});
  Trace rcombine = Trace::make_v2();
  rcombine.string_attrs["restitution_combine"] = "sum";
  expect_bad_both(v(rcombine), {"/ (root attribute restitution_combine)", "'sum' unknown"});
  Trace geometry = Trace::make_v2();
  geometry.string_attrs["contact_geometry"] = "mesh";
  expect_bad_both(v(geometry), {"/ (root attribute contact_geometry)", "'mesh' unknown", "\"shape\", \"aabb\""});
}

TEST_F(TraceIn, Version1And2FieldsMixed) {
  auto v = [&](const Trace& t) { return [&, t](const std::string& extra) { return validate(t, extra); }; };
  const Trace v2 = Trace::make_v2();
  Trace rotation;  // version 1 with orientations
  rotation.orientation = v2.orientation;
  rotation.angular_velocity = v2.angular_velocity;
  expect_bad_both(v(rotation), {"/states/orientation", "present in a version 1 file (v1/v2 fields mixed)",
                                "allowed: root attribute version = 2"});
  Trace inertia;
  inertia.inertia = v2.inertia;
  expect_bad_both(v(inertia), {"/bodies/inertia", "v1/v2 fields mixed"});
  Trace points;
  points.point = {0.1f, 0, 0, 0.1f, 0, 0, 0.1f, 0, 0};
  expect_bad_both(v(points), {"/contacts/point", "v1/v2 fields mixed"});
  Trace friction;
  friction.friction = v2.friction;
  expect_bad_both(v(friction), {"/bodies/friction", "v1/v2 fields mixed"});
  Trace version;
  version.version = 3;
  expect_bad_both(v(version), {"/ (root attribute version)", "3", "allowed: 1 or 2"});
}

TEST_F(TraceIn, Version2WrongShapesAndValues) {
  auto v = [&](const Trace& t) { return [&, t](const std::string& extra) { return validate(t, extra); }; };
  Trace q = Trace::make_v2();
  q.dims["/states/orientation"] = {4, 3, 3};
  expect_bad_both(v(q), {"/states/orientation", "shape 4 x 3 x 3", "allowed: 4 x 3 x 4"});
  Trace w = Trace::make_v2();
  w.dims["/states/angular_velocity"] = {3, 3, 3};
  expect_bad_both(v(w), {"/states/angular_velocity", "shape 3 x 3 x 3", "allowed: 4 x 3 x 3"});
  Trace p = Trace::make_v2();
  p.dims["/contacts/point"] = {5, 2};
  expect_bad_both(v(p), {"/contacts/point", "shape 5 x 2", "allowed: 5 x 3"});
  Trace nan = Trace::make_v2();
  nan.point[3 * 3 + 1] = std::numeric_limits<float>::quiet_NaN();  // frame 3's first row
  expect_bad_both(v(nan), {"/contacts/point", "frame 3", "row 0 (pair (1, 2))", "not finite", "finite world point"});
  Trace spin = Trace::make_v2();
  spin.angular_velocity[(1 * 3 + 2) * 3] = std::numeric_limits<float>::infinity();  // row 1, body 2
  expect_bad_both(v(spin), {"/states/angular_velocity", "frame 1", "body 2", "not finite"});
}

TEST_F(TraceIn, PythonRotatingWriterIsAValidVersion2Trace) {
  const std::string python = "/usr/bin/python3";
  if (run(python + " -c 'import h5py, numpy'").code != 0)
    GTEST_SKIP() << python << " lacks h5py or numpy (Debian: python3-h5py): the example cannot run";
  const std::string example = source_dir() + "/examples/python/rotating_writer.py";
  const std::string path = (dir_ / "rotating.h5").string();
  const Result w = run(python + " " + example + " " + path);
  ASSERT_EQ(w.code, 0) << w.output;
  const Result c = run(bin() + " validate --trace-in " + path + " --check-only");
  EXPECT_EQ(c.code, 0) << c.output;
  EXPECT_NE(c.output.find("version 2"), std::string::npos) << c.output;
  EXPECT_NE(c.output.find("rotation"), std::string::npos) << c.output;
  const Result r = run(bin() + " validate --trace-in " + path);
  EXPECT_TRUE(r.code == 0 || r.code == 3) << r.output;  // judged, never refused as input
}

// /contacts/jt3 (design.md section 13b.11): the tangential impulse vectors; each must lie in its row's
// contact plane (within kJt3MaxAngleDeg = 1 deg), one per contact row.
TEST_F(TraceIn, Version2Jt3InTheContactPlane) {
  auto v = [&](const Trace& t) { return [&, t](const std::string& extra) { return validate(t, extra); }; };
  Trace good = Trace::make_v2();
  // Normals are -x: friction along y and z, |jt3| = |jt|.
  good.jt3 = {0, 0.001f, 0, 0, -0.002f, 0, 0, 0, 0.003f, 0, 0, 0, 0, 0.003f, 0.004f};
  const Result ok = validate(good);
  EXPECT_TRUE(ok.code == 0 || ok.code == 3) << ok.output;
  EXPECT_NE(ok.output.find("rule jt3 on"), std::string::npos) << ok.output;
  Trace tilted = good;
  tilted.jt3[3 * 3 + 0] = 0.004f;  // frame 3's first row: (0.004, 0, 0.004) is 45 deg out of the plane
  tilted.jt3[3 * 3 + 2] = 0.004f;
  expect_bad_both(v(tilted), {"/contacts/jt3", "frame 3", "row 0 (pair (1, 2))", "45 deg out of the contact plane",
                              "orthogonal to the row's normal (within 1 deg)"});
  Trace shape = good;
  shape.dims["/contacts/jt3"] = {4, 3};
  expect_bad_both(v(shape), {"/contacts/jt3", "shape 4 x 3", "allowed: 5 x 3"});
  Trace v1;
  v1.jt3 = {0, 0.001f, 0, 0, 0.001f, 0, 0, 0.001f, 0};
  expect_bad(validate(v1), {"/contacts/jt3", "present in a version 1 file"});
}

// Declared collision shapes (design.md section 13b.10): the root attribute or one string per body;
// an unknown value, a sphere on a box, both forms at once, a wrong count: exit 2 naming
// the file, the dataset or attribute, the body and the allowed values.
TEST_F(TraceIn, Version2CollisionShapes) {
  auto v = [&](const Trace& t) { return [&, t](const std::string& extra) { return validate(t, extra); }; };
  Trace all = Trace::make_v2();
  all.string_attrs["collision_shape"] = "convex_hull";
  const Result ok = validate(all);
  EXPECT_TRUE(ok.code == 0 || ok.code == 3) << ok.output;
  Trace per_body = Trace::make_v2();
  per_body.collision_shape = {"mesh", "box", "convex_hull"};
  EXPECT_EQ(validate(per_body, "--check-only").code, 0);
  Trace unknown = Trace::make_v2();
  unknown.collision_shape = {"mesh", "capsule", "box"};
  expect_bad_both(v(unknown), {"t.h5", "/bodies/collision_shape: body 1", "'capsule' unknown",
                               "\"mesh\", \"convex_hull\", \"box\" or \"sphere\""});
  Trace attr = Trace::make_v2();
  attr.string_attrs["collision_shape"] = "hull";
  expect_bad_both(v(attr), {"root attribute collision_shape", "'hull' unknown", "\"convex_hull\""});
  Trace both = per_body;
  both.string_attrs["collision_shape"] = "mesh";
  expect_bad_both(v(both), {"/bodies/collision_shape", "given with the root attribute"});
  Trace count = Trace::make_v2();
  count.collision_shape = {"mesh", "box"};
  expect_bad_both(v(count), {"/bodies/collision_shape", "2 values", "3 strings, one per body"});
  // Every body here is a box: a box cannot be collided as a sphere.
  Trace sphere = Trace::make_v2();
  sphere.collision_shape = {"mesh", "mesh", "sphere"};
  const Result s = validate(sphere);
  EXPECT_EQ(s.code, 2) << s.output;
  for (const char* f : {"t.h5", "/bodies/collision_shape", "body 2", "\"sphere\" on a box shape", "allowed for a box"})
    EXPECT_NE(s.output.find(f), std::string::npos) << f << " not in:\n" << s.output;
}

}  // namespace octocd_test_cli_external
