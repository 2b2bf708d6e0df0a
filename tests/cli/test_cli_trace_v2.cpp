// `octocd compare` and `octocd replay` on traces of format version 2 (issue 17, design.md section 13;
// docs/trace-format.md): the rotating Bullet engine's own traces and external traces,
// versions mixed. Oracles: a trace against itself and against an independent run of the
// same deterministic engine (same), one planted difference (a quaternion turned by a known
// angle about a known axis, an angular velocity, one manifold row's impulse or point)
// found at its frame, body and size; q and -q are one orientation; bad input exits 2
// naming file, dataset, frame and the allowed values.
#include <gtest/gtest.h>

#include <hdf5.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "support/cli_run.hpp"

// This file's own names (its tests compile in unity batches with the folder's other files).
namespace octocd_test_cli_trace_v2 {

namespace fs = std::filesystem;
using json = nlohmann::json;
using octocd::test::Result;
using octocd::test::run_octocd;
using octocd::test::source_dir;

namespace {

constexpr double kPi = 3.14159265358979323846;

/// Reads or writes `count` floats of a float dataset at `start` (rank = start.size()).
void hyperslab(const std::string& path, const char* dataset, const std::vector<hsize_t>& start,
               const std::vector<hsize_t>& count, std::vector<float>& values, bool write) {
  const hid_t f = H5Fopen(path.c_str(), write ? H5F_ACC_RDWR : H5F_ACC_RDONLY, H5P_DEFAULT);
  ASSERT_GE(f, 0) << path;
  const hid_t d = H5Dopen2(f, dataset, H5P_DEFAULT);
  ASSERT_GE(d, 0) << dataset;
  const hid_t s = H5Dget_space(d);
  H5Sselect_hyperslab(s, H5S_SELECT_SET, start.data(), nullptr, count.data(), nullptr);
  const hid_t m = H5Screate_simple(static_cast<int>(count.size()), count.data(), nullptr);
  hsize_t n = 1;
  for (hsize_t c : count) n *= c;
  values.resize(n);
  if (write)
    ASSERT_GE(H5Dwrite(d, H5T_NATIVE_FLOAT, m, s, H5P_DEFAULT, values.data()), 0);
  else
    ASSERT_GE(H5Dread(d, H5T_NATIVE_FLOAT, m, s, H5P_DEFAULT, values.data()), 0);
  H5Sclose(m);
  H5Sclose(s);
  H5Dclose(d);
  H5Fclose(f);
}

std::vector<float> get(const std::string& path, const char* dataset, std::vector<hsize_t> start,
                       std::vector<hsize_t> count) {
  std::vector<float> v;
  hyperslab(path, dataset, start, count, v, false);
  return v;
}
void put(const std::string& path, const char* dataset, std::vector<hsize_t> start, std::vector<hsize_t> count,
         std::vector<float> v) {
  hyperslab(path, dataset, start, count, v, true);
}

/// Removes a dataset or group.
void remove_link(const std::string& path, const char* name) {
  const hid_t f = H5Fopen(path.c_str(), H5F_ACC_RDWR, H5P_DEFAULT);
  ASSERT_GE(f, 0);
  ASSERT_GE(H5Ldelete(f, name, H5P_DEFAULT), 0) << name;
  H5Fclose(f);
}

/// Sets the root attribute `version` (an int32).
void set_version(const std::string& path, int version) {
  const hid_t f = H5Fopen(path.c_str(), H5F_ACC_RDWR, H5P_DEFAULT);
  ASSERT_GE(f, 0);
  if (H5Aexists(f, "version") > 0) H5Adelete(f, "version");
  const hid_t s = H5Screate(H5S_SCALAR);
  const hid_t a = H5Acreate2(f, "version", H5T_STD_I32LE, s, H5P_DEFAULT, H5P_DEFAULT);
  ASSERT_GE(H5Awrite(a, H5T_NATIVE_INT, &version), 0);
  H5Aclose(a);
  H5Sclose(s);
  H5Fclose(f);
}

/// Sets a float64 root attribute.
void set_number(const std::string& path, const char* name, double value) {
  const hid_t f = H5Fopen(path.c_str(), H5F_ACC_RDWR, H5P_DEFAULT);
  ASSERT_GE(f, 0);
  if (H5Aexists(f, name) > 0) H5Adelete(f, name);
  const hid_t s = H5Screate(H5S_SCALAR);
  const hid_t a = H5Acreate2(f, name, H5T_IEEE_F64LE, s, H5P_DEFAULT, H5P_DEFAULT);
  ASSERT_GE(H5Awrite(a, H5T_NATIVE_DOUBLE, &value), 0);
  H5Aclose(a);
  H5Sclose(s);
  H5Fclose(f);
}

/// Creates a float32 dataset of the given shape and values.
void create(const std::string& path, const char* name, const std::vector<hsize_t>& shape, const std::vector<float>& v) {
  const hid_t f = H5Fopen(path.c_str(), H5F_ACC_RDWR, H5P_DEFAULT);
  ASSERT_GE(f, 0);
  const hid_t s = H5Screate_simple(static_cast<int>(shape.size()), shape.data(), nullptr);
  const hid_t d = H5Dcreate2(f, name, H5T_IEEE_F32LE, s, H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
  ASSERT_GE(d, 0) << name;
  ASSERT_GE(H5Dwrite(d, H5T_NATIVE_FLOAT, H5S_ALL, H5S_ALL, H5P_DEFAULT, v.data()), 0);
  H5Dclose(d);
  H5Sclose(s);
  H5Fclose(f);
}

/// The dims of a dataset.
std::vector<hsize_t> dims(const std::string& path, const char* name) {
  const hid_t f = H5Fopen(path.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT);
  const hid_t d = H5Dopen2(f, name, H5P_DEFAULT);
  const hid_t s = H5Dget_space(d);
  std::vector<hsize_t> out(static_cast<std::size_t>(H5Sget_simple_extent_ndims(s)));
  H5Sget_simple_extent_dims(s, out.data(), nullptr);
  H5Sclose(s);
  H5Dclose(d);
  H5Fclose(f);
  return out;
}

/// q * r (Hamilton product, (w, x, y, z)), in double.
std::array<double, 4> mul(const std::array<double, 4>& q, const std::array<double, 4>& r) {
  return {q[0] * r[0] - q[1] * r[1] - q[2] * r[2] - q[3] * r[3], q[0] * r[1] + q[1] * r[0] + q[2] * r[3] - q[3] * r[2],
          q[0] * r[2] - q[1] * r[3] + q[2] * r[0] + q[3] * r[1], q[0] * r[3] + q[1] * r[2] - q[2] * r[1] + q[3] * r[0]};
}

json read_json(const fs::path& p) {
  std::ifstream in(p);
  return json::parse(in);
}

class TraceV2 : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("octocd-v2-" + std::to_string(::getpid()) + "-" +
                                        ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  std::string path(const std::string& name) const { return (dir_ / name).string(); }
  /// rot-slope (body 0 a static slope turned 20 degrees, body 1 a box tilted with it,
  /// sliding down) in Bullet with rotation, every state, contacts: a version 2 trace.
  std::string bullet_trace(const std::string& name, int frames = 40) {
    const std::string t = path(name);
    const Result r = run_octocd("run " + source_dir() + "/datasets/scenes/rot-slope.json --engine bullet --rotation "
                                "--frames " + std::to_string(frames) + " --state-every 1 --contacts --quiet --no-xdmf "
                                "--trace " + t);
    EXPECT_EQ(r.code, 0) << r.output;
    return t;
  }
  std::string copy(const std::string& from, const std::string& name) {
    fs::copy_file(from, path(name), fs::copy_options::overwrite_existing);
    return path(name);
  }
  fs::path dir_;
};

}  // namespace

TEST_F(TraceV2, CompareOfAVersion2TraceWithItselfAndAnIndependentRunIsSame) {
  const std::string a = bullet_trace("a.h5"), b = bullet_trace("b.h5");
  const auto shape = dims(a, "/states/orientation");
  ASSERT_EQ(shape.size(), 3u);
  const std::string states = std::to_string(shape[0]) + " common states x " + std::to_string(shape[1]) + " bodies";
  for (const std::string& other : {a, b}) {  // Bullet in one thread is deterministic
    const Result r = run_octocd("compare " + a + " " + other + " --json " + path("c.json"));
    EXPECT_EQ(r.code, 0) << r.output;
    EXPECT_NE(r.output.find("\nsame\n"), std::string::npos) << r.output;
    for (const std::string q : {"positions", "velocities", "orientations", "angular_velocities"})
      EXPECT_NE(r.output.find(q + std::string(18 - q.size() + 1, ' ') + states), std::string::npos)
          << q << "\n" << r.output;
    EXPECT_NE(r.output.find("rows by pair with point, point_b, jt3"), std::string::npos) << r.output;
    const json j = read_json(path("c.json"));
    EXPECT_TRUE(j["same"].get<bool>());
    EXPECT_EQ(j["traces"][0]["version"], 2);
    EXPECT_TRUE(j["traces"][1]["rotation"].get<bool>());
  }
}

TEST_F(TraceV2, CompareFindsAnOrientationTurnedByTenDegreesAtItsFrameAndBody) {
  const std::string a = bullet_trace("a.h5"), b = copy(a, "b.h5");
  // Body 1 (the sliding box) in state row 17 = frame 17, turned by 10 degrees about a
  // skew axis in its body frame.
  const auto q = get(b, "/states/orientation", {17, 1, 0}, {1, 1, 4});
  const double half = 10.0 * kPi / 360.0, s = std::sin(half) / std::sqrt(14.0);
  const auto t = mul({q[0], q[1], q[2], q[3]}, {std::cos(half), s, 2 * s, 3 * s});
  put(b, "/states/orientation", {17, 1, 0}, {1, 1, 4},
      {static_cast<float>(t[0]), static_cast<float>(t[1]), static_cast<float>(t[2]), static_cast<float>(t[3])});
  Result r = run_octocd("compare " + a + " " + b + " --json " + path("c.json"));
  EXPECT_EQ(r.code, 3) << r.output;
  EXPECT_NE(r.output.find("DIFFERENT: first at frame 17, body 1 (orientations)"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("angle 10"), std::string::npos) << r.output;
  const json j = read_json(path("c.json"));
  EXPECT_EQ(j["first"]["frame"], 17);
  EXPECT_EQ(j["first"]["body"], 1);
  bool seen = false;
  for (const auto& k : j["quantities"]) {
    if (k["quantity"] == "orientations") {
      seen = true;
      // float32 quaternions: the angle within 1e-5 rad of 10 degrees.
      EXPECT_NEAR(k["max_abs_difference"].get<double>(), 10.0 * kPi / 180.0, 1e-5) << k.dump();
      EXPECT_EQ(k["beyond_count"], 1);
    } else {
      EXPECT_FALSE(k["differs"].get<bool>()) << k.dump();  // nothing else was touched
    }
  }
  EXPECT_TRUE(seen);
  // The tolerance is the angle in rad: 0.18 > 10 degrees (0.1745) > 0.17.
  EXPECT_EQ(run_octocd("compare " + a + " " + b + " --tolerance orientations=0.18").code, 0);
  EXPECT_EQ(run_octocd("compare " + a + " " + b + " --tolerance orientations=0.17").code, 3);
  EXPECT_EQ(run_octocd("compare " + a + " " + b + " --quantity positions,velocities,contacts").code, 0);
}

TEST_F(TraceV2, MinusQIsTheSameOrientationAndAnAngularVelocityDifferenceIsFound) {
  const std::string a = bullet_trace("a.h5"), b = copy(a, "b.h5");
  const auto shape = dims(a, "/states/orientation");
  auto q = get(b, "/states/orientation", {0, 0, 0}, {shape[0], shape[1], 4});
  for (float& x : q) x = -x;  // every quaternion negated: the same rotations
  put(b, "/states/orientation", {0, 0, 0}, {shape[0], shape[1], 4}, q);
  Result r = run_octocd("compare " + a + " " + b);
  EXPECT_EQ(r.code, 0) << r.output;
  auto w = get(b, "/states/angular_velocity", {30, 1, 0}, {1, 1, 3});
  w[1] += 0.5f;
  put(b, "/states/angular_velocity", {30, 1, 0}, {1, 1, 3}, w);
  r = run_octocd("compare " + a + " " + b);
  EXPECT_EQ(r.code, 3) << r.output;
  EXPECT_NE(r.output.find("DIFFERENT: first at frame 30, body 1 (angular_velocities)"), std::string::npos) << r.output;
  EXPECT_EQ(run_octocd("compare " + a + " " + b + " --tolerance angular_velocities=0.6").code, 0);
}

TEST_F(TraceV2, CompareFindsOneManifoldRowsImpulseOrPointByPair) {
  const std::string a = bullet_trace("a.h5"), b = copy(a, "b.h5");
  // The contact rows of frame 20: /contacts/frame row 19 (frames 1..40).
  std::vector<float> off;
  {
    const hid_t f = H5Fopen(a.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT);
    const hid_t d = H5Dopen2(f, "/contacts/offsets", H5P_DEFAULT);
    const hid_t s = H5Dget_space(d);
    hsize_t n = 0;
    H5Sget_simple_extent_dims(s, &n, nullptr);
    std::vector<std::int64_t> o(n);
    H5Dread(d, H5T_NATIVE_INT64, H5S_ALL, H5S_ALL, H5P_DEFAULT, o.data());
    for (auto x : o) off.push_back(static_cast<float>(x));
    H5Sclose(s);
    H5Dclose(d);
    H5Fclose(f);
  }
  ASSERT_GT(off.size(), 21u);
  const auto k0 = static_cast<hsize_t>(off[19]), k1 = static_cast<hsize_t>(off[20]);
  ASSERT_GE(k1 - k0, 2u) << "frame 20 has a manifold";  // the box on the slope: several points
  const hsize_t k = k0 + 1;                                 // the second row of the frame
  std::vector<std::uint32_t> pair(2);
  {
    const hid_t f = H5Fopen(a.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT);
    const hid_t d = H5Dopen2(f, "/contacts/pair", H5P_DEFAULT);
    const hid_t s = H5Dget_space(d);
    const hsize_t start[2] = {k, 0}, count[2] = {1, 2};
    H5Sselect_hyperslab(s, H5S_SELECT_SET, start, nullptr, count, nullptr);
    const hid_t m = H5Screate_simple(2, count, nullptr);
    H5Dread(d, H5T_NATIVE_UINT32, m, s, H5P_DEFAULT, pair.data());
    H5Sclose(m);
    H5Sclose(s);
    H5Dclose(d);
    H5Fclose(f);
  }
  auto p = get(b, "/contacts/point", {k, 0}, {1, 3});
  p[1] += 0.001f;  // 1 mm
  put(b, "/contacts/point", {k, 0}, {1, 3}, p);
  Result r = run_octocd("compare " + a + " " + b + " --json " + path("c.json"));
  EXPECT_EQ(r.code, 3) << r.output;
  const std::string at = "first at frame 20, body " + std::to_string(pair[0]) + " (contacts)";
  EXPECT_NE(r.output.find("DIFFERENT: " + at), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("pair (" + std::to_string(pair[0]) + ", " + std::to_string(pair[1]) + ") row"),
            std::string::npos)
      << r.output;
  EXPECT_NE(r.output.find("point.y"), std::string::npos) << r.output;
  EXPECT_EQ(run_octocd("compare " + a + " " + b + " --tolerance contacts=0.002").code, 0);
  EXPECT_EQ(run_octocd("compare " + a + " " + b + " --tolerance contacts=0.0005").code, 3);
  // One row's normal impulse.
  const std::string c = copy(a, "c.h5");
  auto jn = get(c, "/contacts/jn", {k}, {1});
  jn[0] = jn[0] * 2.0f + 1.0f;
  put(c, "/contacts/jn", {k}, {1}, jn);
  r = run_octocd("compare " + a + " " + c);
  EXPECT_EQ(r.code, 3) << r.output;
  EXPECT_NE(r.output.find(": jn: A "), std::string::npos) << r.output;
  // One row's point on B (Bullet's second witness point) by 1 mm, and its friction vector.
  const std::string d = copy(a, "d.h5");
  auto pb = get(d, "/contacts/point_b", {k, 0}, {1, 3});
  pb[2] += 0.001f;
  put(d, "/contacts/point_b", {k, 0}, {1, 3}, pb);
  r = run_octocd("compare " + a + " " + d);
  EXPECT_EQ(r.code, 3) << r.output;
  EXPECT_NE(r.output.find("DIFFERENT: " + at), std::string::npos) << r.output;
  EXPECT_NE(r.output.find(": point_b.z: A "), std::string::npos) << r.output;
  EXPECT_EQ(run_octocd("compare " + a + " " + d + " --tolerance contacts=0.002").code, 0);
  const std::string e = copy(a, "e.h5");
  auto jt3 = get(e, "/contacts/jt3", {k, 0}, {1, 3});
  jt3[0] = jt3[0] * 2.0f + 1.0f;
  put(e, "/contacts/jt3", {k, 0}, {1, 3}, jt3);
  r = run_octocd("compare " + a + " " + e);
  EXPECT_EQ(r.code, 3) << r.output;
  EXPECT_NE(r.output.find(": jt3.x: A "), std::string::npos) << r.output;
}

TEST_F(TraceV2, AnExternalVersion2TraceComparesWithTheOctocdTraceItWasMadeFrom) {
  // The octocd trace without /frames is an external trace of version 2 (docs/trace-format.md:
  // `octocd run --engine bullet --rotation --state-every 1 --contacts` gives one).
  const std::string a = bullet_trace("a.h5"), e = copy(a, "e.h5");
  remove_link(e, "/frames");
  ASSERT_EQ(run_octocd("validate --trace-in " + e + " --check-only").code, 0);
  Result r = run_octocd("compare " + a + " " + e);
  EXPECT_EQ(r.code, 0) << r.output;
  EXPECT_NE(r.output.find("external trace version 2"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("same (in what both traces hold)"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("/frames/aabb_pairs missing in B (an external trace: no /frames)"), std::string::npos)
      << r.output;
  const auto q = get(e, "/states/orientation", {9, 1, 0}, {1, 1, 4});
  const double half = 10.0 * kPi / 360.0;
  const auto t = mul({std::cos(half), 0.0, std::sin(half), 0.0}, {q[0], q[1], q[2], q[3]});  // about world y
  put(e, "/states/orientation", {9, 1, 0}, {1, 1, 4},
      {static_cast<float>(t[0]), static_cast<float>(t[1]), static_cast<float>(t[2]), static_cast<float>(t[3])});
  r = run_octocd("compare " + e + " " + a);
  EXPECT_EQ(r.code, 3) << r.output;
  EXPECT_NE(r.output.find("DIFFERENT: first at frame 9, body 1 (orientations)"), std::string::npos) << r.output;
}

TEST_F(TraceV2, VersionsMixedCompareWithTheUnrotatedTraceAsIdentity) {
  // An octocd cpu trace (version 1) and the same run written as an external version 2
  // trace with identity orientations and zero angular velocities: the same.
  const std::string scene = path("stack.json");
  {
    std::ifstream in(source_dir() + "/datasets/scenes/box-stack.json");
    std::ofstream(scene) << in.rdbuf();
  }
  const std::string v1 = path("v1.h5");
  Result r = run_octocd("run " + scene + " --frames 30 --state-every 1 --contacts --quiet --no-xdmf --trace " + v1);
  ASSERT_EQ(r.code, 0) << r.output;
  const std::string e = copy(v1, "e.h5");
  remove_link(e, "/frames");
  set_version(e, 2);
  const auto s = dims(e, "/states/position");
  std::vector<float> q(s[0] * s[1] * 4, 0.0f), w(s[0] * s[1] * 3, 0.0f);
  for (std::size_t i = 0; i < q.size(); i += 4) q[i] = 1.0f;
  create(e, "/states/orientation", {s[0], s[1], 4}, q);
  create(e, "/states/angular_velocity", {s[0], s[1], 3}, w);
  r = run_octocd("validate --trace-in " + e + " --check-only");
  ASSERT_EQ(r.code, 0) << r.output;
  r = run_octocd("compare " + v1 + " " + e);
  EXPECT_EQ(r.code, 0) << r.output;
  EXPECT_NE(r.output.find("note: octocd trace version 1 (A) vs external trace version 2 with rotation (B)"),
            std::string::npos)
      << r.output;
  EXPECT_NE(r.output.find("(A: /states/orientation absent, no rotation: identity)"), std::string::npos) << r.output;
  // One body turned by 10 degrees in the version 2 trace: found against the identity.
  const double half = 10.0 * kPi / 360.0;
  put(e, "/states/orientation", {12, 3, 0}, {1, 1, 4},
      {static_cast<float>(std::cos(half)), static_cast<float>(std::sin(half)), 0.0f, 0.0f});
  r = run_octocd("compare " + v1 + " " + e + " --json " + path("c.json"));
  EXPECT_EQ(r.code, 3) << r.output;
  EXPECT_NE(r.output.find("DIFFERENT: first at frame 12, body 3 (orientations)"), std::string::npos) << r.output;
  const json j = read_json(path("c.json"));
  for (const auto& k : j["quantities"]) {
    if (k["quantity"] == "orientations") {
      EXPECT_NEAR(k["max_abs_difference"].get<double>(), 10.0 * kPi / 180.0, 1e-6);
    }
  }
}

TEST_F(TraceV2, BadVersion2InputExitsTwoNamingFileDatasetFrameAndAllowed) {
  const std::string a = bullet_trace("a.h5");
  // A non-unit quaternion in an octocd trace and in an external one.
  const std::string b = copy(a, "b.h5");
  put(b, "/states/orientation", {12, 1, 0}, {1, 1, 4}, {1.01f, 0.0f, 0.0f, 0.0f});
  Result r = run_octocd("compare " + a + " " + b);
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find(b + ": /states/orientation: frame 12: body 1: (1.01, 0, 0, 0), |q| = 1.01; allowed: unit "
                              "quaternions"),
            std::string::npos)
      << r.output;
  const std::string e = copy(b, "e.h5");
  remove_link(e, "/frames");
  r = run_octocd("compare " + a + " " + e);
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find(e + ": /states/orientation: frame 12: body 1"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("allowed: unit quaternions"), std::string::npos) << r.output;
  // Orientation without angular velocity.
  const std::string c = copy(a, "c.h5");
  remove_link(c, "/states/angular_velocity");
  r = run_octocd("compare " + a + " " + c);
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find(c + ": /states/angular_velocity: missing (/states/orientation present); allowed: "
                              "/states/orientation and /states/angular_velocity together"),
            std::string::npos)
      << r.output;
  // Version 2 datasets in a version 1 file.
  const std::string d = copy(a, "d.h5");
  set_version(d, 1);
  r = run_octocd("compare " + a + " " + d);
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find(d + ": /states/orientation: a version 2 dataset in a version 1 trace (v1/v2 fields mixed)"),
            std::string::npos)
      << r.output;
  // An unknown version.
  set_version(d, 3);
  r = run_octocd("compare " + a + " " + d);
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find(d + ": version: 3; allowed: 1 or 2"), std::string::npos) << r.output;
  // A wrong quaternion dataset shape (n x 3 per state).
  const std::string f = copy(a, "f.h5");
  const auto s = dims(a, "/states/orientation");
  remove_link(f, "/states/orientation");
  create(f, "/states/orientation", {s[0], s[1], 3}, std::vector<float>(s[0] * s[1] * 3, 0.0f));
  r = run_octocd("compare " + a + " " + f);
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find(f + ": /states/orientation: shape " + std::to_string(s[0]) + " x " + std::to_string(s[1]) +
                              " x 3; allowed: states x " + std::to_string(s[1]) + " bodies x 4"),
            std::string::npos)
      << r.output;
}

TEST_F(TraceV2, ReplayRefusesAVersion2TraceNamingWhy) {
  const std::string a = bullet_trace("a.h5");
  const Result r = run_octocd("replay " + a + " --broadphase flat,octree");
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find(a + ": version: 2 (a rotating engine's trace); replay cannot replay it"), std::string::npos)
      << r.output;
  EXPECT_NE(r.output.find("allowed: a version 1 trace"), std::string::npos) << r.output;
  EXPECT_EQ(std::count(r.output.begin(), r.output.end(), '\n'), 1) << r.output;
}

TEST_F(TraceV2, AnExternalVersion1TraceComparesByPairWithItsOctocdTrace) {
  // docs/trace-format.md: a trace of `octocd run --state-every 1 --contacts` without /frames
  // is an external trace of version 1 (contacts by position: step f's rows are
  // offsets[f-1] .. offsets[f]-1). Its contacts compare by pair, frame for frame.
  const std::string v1 = path("v1.h5");
  Result r = run_octocd("run " + source_dir() + "/datasets/scenes/box-stack.json --frames 30 --state-every 1 "
                        "--contacts --quiet --no-xdmf --trace " + v1);
  ASSERT_EQ(r.code, 0) << r.output;
  const std::string e = copy(v1, "e.h5");
  remove_link(e, "/frames");
  r = run_octocd("compare " + v1 + " " + e);
  EXPECT_EQ(r.code, 0) << r.output;
  EXPECT_NE(r.output.find("external trace version 1"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("30 common frames: "), std::string::npos) << r.output;
  EXPECT_EQ(r.output.find("orientations"), std::string::npos) << r.output;  // not by default in version 1
  // One contact row's depth, in the flat row of frame 25's first contact.
  std::vector<float> off;
  {
    const hid_t f = H5Fopen(e.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT);
    const hid_t d = H5Dopen2(f, "/contacts/offsets", H5P_DEFAULT);
    std::vector<std::int64_t> o(31);
    ASSERT_GE(H5Dread(d, H5T_NATIVE_INT64, H5S_ALL, H5S_ALL, H5P_DEFAULT, o.data()), 0);
    for (auto x : o) off.push_back(static_cast<float>(x));
    H5Dclose(d);
    H5Fclose(f);
  }
  const auto k = static_cast<hsize_t>(off[24]);
  ASSERT_GT(static_cast<hsize_t>(off[25]), k) << "frame 25 has contacts";
  auto depth = get(e, "/contacts/depth", {k}, {1});
  depth[0] += 1e-3f;
  put(e, "/contacts/depth", {k}, {1}, depth);
  r = run_octocd("compare " + v1 + " " + e);
  EXPECT_EQ(r.code, 3) << r.output;
  EXPECT_NE(r.output.find("DIFFERENT: first at frame 25"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find(": depth: A "), std::string::npos) << r.output;
  // Asked for, orientations are in neither trace: nothing requested was compared, exit 2
  // naming what each lacks (never "same").
  r = run_octocd("compare " + v1 + " " + e + " --quantity orientations,angular_velocities");
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find("no requested quantity could be compared"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("/states/orientation in neither (no rotation)"), std::string::npos) << r.output;
}

TEST_F(TraceV2, BodiesAndMaterialsOfVersion2TracesAreStructure) {
  // Inertia and materials are not scene parameters of an external trace: compare names
  // them (exit 3) where both traces hold them.
  const std::string a = bullet_trace("a.h5"), e = copy(a, "e.h5");
  remove_link(e, "/frames");
  auto inertia = get(e, "/bodies/inertia", {1, 0, 0}, {1, 3, 3});
  inertia[4] *= 1.5f;  // I_yy of the box
  put(e, "/bodies/inertia", {1, 0, 0}, {1, 3, 3}, inertia);
  set_number(e, "mu", 0.3);
  const Result r = run_octocd("compare " + a + " " + e);
  EXPECT_EQ(r.code, 3) << r.output;
  EXPECT_NE(r.output.find("/bodies/inertia: body 1: ("), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("mu: 0.2"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find(" vs 0.3 (root attribute)"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("DIFFERENT: structure"), std::string::npos) << r.output;
}

}  // namespace octocd_test_cli_trace_v2
