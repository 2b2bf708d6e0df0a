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

#include "cli_run.hpp"

namespace fs = std::filesystem;

namespace {

using octocd::test::Result;
using octocd::test::bin;
using octocd::test::source_dir;
using octocd::test::run;

/// A small external trace, held in arrays that a test may break before writing: 3 boxes
/// of half side 0.1 (body 0 static), two overlapping by the slop (1, 2) and one apart, 3
/// frames at rest without gravity, the pair and its contact in every frame.
struct Trace {
  static constexpr int kBodies = 3, kFrames = 3;
  std::vector<float> local_min, local_max, inverse_mass{0.0f, 1.0f, 1.0f};
  std::vector<float> position, velocity, aabb_min, aabb_max;  // (F+1) n 3, (F+1) n 3, F n 3
  std::vector<std::int64_t> pair_offsets{0, 1, 2, 3}, contact_offsets{0, 1, 2, 3};
  std::vector<std::uint32_t> pairs{1, 2, 1, 2, 1, 2}, contact_pair{1, 2, 1, 2, 1, 2};
  std::vector<float> normal{-1, 0, 0, -1, 0, 0, -1, 0, 0}, depth{0.001f, 0.001f, 0.001f}, jn{0, 0, 0}, jt{0, 0, 0};
  std::vector<std::string> skip;  // datasets to leave out
  hsize_t aabb_bodies = kBodies;  // rows per frame written to /aabbs (a wrong body count)

  Trace() {
    const float x[kBodies][3] = {{0, -1, 0}, {0, 0, 0}, {0.199f, 0, 0}};
    for (int i = 0; i < kBodies; ++i)
      for (int k = 0; k < 3; ++k) {
        local_min.push_back(-0.1f);
        local_max.push_back(0.1f);
      }
    for (int f = 0; f <= kFrames; ++f)
      for (int i = 0; i < kBodies; ++i)
        for (int k = 0; k < 3; ++k) {
          position.push_back(x[i][k]);
          velocity.push_back(0.0f);
          if (f > 0) {
            aabb_min.push_back(x[i][k] - 0.1f);
            aabb_max.push_back(x[i][k] + 0.1f);
          }
        }
  }

  void write(const std::string& path) const {
    const hid_t file = H5Fcreate(path.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT);
    ASSERT_GE(file, 0);
    const hid_t lcpl = H5Pcreate(H5P_LINK_CREATE);
    H5Pset_create_intermediate_group(lcpl, 1);
    auto put = [&](const char* name, hid_t mem, hid_t type, std::vector<hsize_t> dims, const void* data) {
      for (const std::string& s : skip)
        if (s == name) return;
      const hid_t space = H5Screate_simple(static_cast<int>(dims.size()), dims.data(), nullptr);
      const hid_t d = H5Dcreate2(file, name, type, space, lcpl, H5P_DEFAULT, H5P_DEFAULT);
      ASSERT_GE(d, 0) << name;
      ASSERT_GE(H5Dwrite(d, mem, H5S_ALL, H5S_ALL, H5P_DEFAULT, data), 0) << name;
      H5Dclose(d);
      H5Sclose(space);
    };
    auto str_attr = [&](const char* name, const char* value) {
      const hid_t t = H5Tcopy(H5T_C_S1);
      H5Tset_size(t, H5T_VARIABLE);
      const hid_t space = H5Screate(H5S_SCALAR);
      const hid_t a = H5Acreate2(file, name, t, space, H5P_DEFAULT, H5P_DEFAULT);
      H5Awrite(a, t, &value);
      H5Aclose(a);
      H5Sclose(space);
      H5Tclose(t);
    };
    str_attr("format", "octocd-trace");
    str_attr("engine", "test-engine");
    {
      const int version = 1;
      const hid_t space = H5Screate(H5S_SCALAR);
      const hid_t a = H5Acreate2(file, "version", H5T_STD_I32LE, space, H5P_DEFAULT, H5P_DEFAULT);
      H5Awrite(a, H5T_NATIVE_INT, &version);
      H5Aclose(a);
      H5Sclose(space);
      const double gravity[3] = {0, 0, 0};
      const hsize_t three = 3;
      const hid_t gs = H5Screate_simple(1, &three, nullptr);
      const hid_t g = H5Acreate2(file, "gravity", H5T_IEEE_F64LE, gs, H5P_DEFAULT, H5P_DEFAULT);
      H5Awrite(g, H5T_NATIVE_DOUBLE, gravity);
      H5Aclose(g);
      H5Sclose(gs);
    }
    const hsize_t n = kBodies, f = kFrames;
    const hid_t F = H5T_NATIVE_FLOAT, FT = H5T_IEEE_F32LE;
    put("/bodies/local_aabb_min", F, FT, {n, 3}, local_min.data());
    put("/bodies/local_aabb_max", F, FT, {n, 3}, local_max.data());
    put("/bodies/inverse_mass", F, FT, {inverse_mass.size()}, inverse_mass.data());
    put("/states/position", F, FT, {f + 1, n, 3}, position.data());
    put("/states/velocity", F, FT, {velocity.size() / (3 * n), n, 3}, velocity.data());
    put("/aabbs/min", F, FT, {f, aabb_bodies, 3}, aabb_min.data());
    put("/aabbs/max", F, FT, {f, aabb_bodies, 3}, aabb_max.data());
    put("/pairs/offsets", H5T_NATIVE_INT64, H5T_STD_I64LE, {pair_offsets.size()}, pair_offsets.data());
    put("/pairs/pair", H5T_NATIVE_UINT32, H5T_STD_U32LE, {pairs.size() / 2, 2}, pairs.data());
    put("/contacts/offsets", H5T_NATIVE_INT64, H5T_STD_I64LE, {contact_offsets.size()}, contact_offsets.data());
    const hsize_t c = contact_pair.size() / 2;
    put("/contacts/pair", H5T_NATIVE_UINT32, H5T_STD_U32LE, {c, 2}, contact_pair.data());
    put("/contacts/normal", F, FT, {c, 3}, normal.data());
    put("/contacts/depth", F, FT, {c}, depth.data());
    put("/contacts/jn", F, FT, {c}, jn.data());
    put("/contacts/jt", F, FT, {c}, jt.data());
    H5Pclose(lcpl);
    H5Fclose(file);
  }
};

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
