// Issue 17 item 4: planted faults in a rotating engine's trace, judged by the physics tier
// through `octocd validate --trace-in`. The engine is Bullet with rotation (octocd's own
// rotating reference, design.md section 13): a small drop of boxes and meshes into an open box,
// written as an external trace version 2. The untouched trace passes (its broadphase is
// Bullet's conservative fattened-AABB pair cache: extras allowed); each fault is planted
// in a copy of the file and must exit 3 with a detail naming the frame and the pair or
// body. The faults are found in the trace itself (the deepest dynamic pair, an isolated
// group, a rotated body), never pinned by number.
#include <gtest/gtest.h>
#include <hdf5.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <functional>
#include <map>
#include <numeric>
#include <regex>
#include <string>
#include <vector>

#include "support/cli_run.hpp"
#include "support/trace_edit.hpp"

// This file's own names (its tests compile in unity batches with the folder's other files).
namespace octocd_test_cli_rotation_faults {

namespace fs = std::filesystem;

namespace {

using octocd::test::Result;
using octocd::test::run_octocd;
using octocd::test::source_dir;

using octocd::test::Data;
using octocd::test::read;
using octocd::test::replace;

double root_double(hid_t file, const char* name, double fallback) {
  if (H5Aexists(file, name) <= 0) return fallback;
  const hid_t a = H5Aopen(file, name, H5P_DEFAULT);
  double x = fallback;
  H5Aread(a, H5T_NATIVE_DOUBLE, &x);
  H5Aclose(a);
  return x;
}

struct V3 {
  double x = 0, y = 0, z = 0;
};
V3 operator-(V3 a, V3 b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
V3 operator+(V3 a, V3 b) { return {a.x + b.x, a.y + b.y, a.z + b.z}; }
V3 operator*(double s, V3 a) { return {s * a.x, s * a.y, s * a.z}; }
double dotp(V3 a, V3 b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
V3 crossp(V3 a, V3 b) { return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x}; }
double len(V3 a) { return std::sqrt(dotp(a, a)); }

/// Rotates v by the unit quaternion (w, x, y, z), or by its inverse.
V3 rotate(const double* q, V3 v, bool inverse = false) {
  const V3 u{inverse ? -q[1] : q[1], inverse ? -q[2] : q[2], inverse ? -q[3] : q[3]};
  const V3 t = 2.0 * crossp(u, v);
  return v + q[0] * t + crossp(u, t);
}

/// The base trace, in memory, with the frame layout decoded.
struct Trace {
  std::string path;
  int bodies = 0, frames = 0;
  Data pos, vel, quat, inv_mass, contact_offsets, contact_pair, normal, depth, jn, jt, jt3, point, point_b, pair_offsets,
      pairs;
  double mu = 0.5;

  void load(const std::string& p) {
    path = p;
    const hid_t f = H5Fopen(p.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT);
    ASSERT_GE(f, 0) << p;
    pos = read(f, "/states/position");
    vel = read(f, "/states/velocity");
    quat = read(f, "/states/orientation");
    inv_mass = read(f, "/bodies/inverse_mass");
    contact_offsets = read(f, "/contacts/offsets");
    contact_pair = read(f, "/contacts/pair");
    normal = read(f, "/contacts/normal");
    depth = read(f, "/contacts/depth");
    jn = read(f, "/contacts/jn");
    jt = read(f, "/contacts/jt");
    jt3 = read(f, "/contacts/jt3");
    point = read(f, "/contacts/point");
    point_b = read(f, "/contacts/point_b");  // Bullet: each row's witness point on B
    pair_offsets = read(f, "/pairs/offsets");
    pairs = read(f, "/pairs/pair");
    mu = root_double(f, "mu", 0.5);
    H5Fclose(f);
    ASSERT_EQ(pos.dims.size(), 3u);
    frames = static_cast<int>(pos.dims[0]) - 1;
    bodies = static_cast<int>(pos.dims[1]);
  }
  /// Contact rows of step f (1-based): [begin, end).
  std::pair<std::size_t, std::size_t> rows(int f) const {
    return {static_cast<std::size_t>(contact_offsets.v[static_cast<std::size_t>(f - 1)]),
            static_cast<std::size_t>(contact_offsets.v[static_cast<std::size_t>(f)])};
  }
  int a(std::size_t r) const { return static_cast<int>(contact_pair.v[2 * r]); }
  int b(std::size_t r) const { return static_cast<int>(contact_pair.v[2 * r + 1]); }
  bool dynamic(int i) const { return inv_mass.v[static_cast<std::size_t>(i)] > 0; }
  V3 x(int row, int i) const {
    const std::size_t o = (static_cast<std::size_t>(row) * bodies + i) * 3;
    return {pos.v[o], pos.v[o + 1], pos.v[o + 2]};
  }
  const double* q(int row, int i) const { return &quat.v[(static_cast<std::size_t>(row) * bodies + i) * 4]; }
};

class RotationFaults : public ::testing::Test {
 protected:
  static fs::path dir_;
  static Trace base_;
  static Result base_result_;
  static bool base_judged_;

  static void SetUpTestSuite() {
    dir_ = fs::temp_directory_path() / ("octocd-rotfaults-" + std::to_string(::getpid()));
    fs::create_directories(dir_);
    // 24 boxes of three sizes, rotated, dropped into an open box. (Meshes: Bullet collides
    // a mesh as its convex hull, which the physics tier, judging the true mesh, sees as
    // false contacts on a bunny; see the closing note of issue 17.)
    const fs::path scene = dir_ / "drop.json";
    std::ofstream(scene) << R"({
      "name": "rot-faults", "rotation": true, "dt": 0.002, "frames": 300,
      "domain": {"min": [-0.6, 0, -0.6], "max": [0.6, 1.6, 0.6]}, "walls": "open-box",
      "groups": [
        {"name": "big", "shape": {"box": [0.06, 0.04, 0.05]}, "count": 8, "mass": 1,
         "orientation": {"axis": [0.6, 0, 0.8], "angle_deg": 30},
         "layout": {"type": "random", "min": [-0.4, 0.2, -0.4], "max": [0.4, 0.6, 0.4], "seed": 3}},
        {"name": "mid", "shape": {"box": [0.04, 0.04, 0.04]}, "count": 8, "mass": 0.5,
         "orientation": {"axis": [0, 1, 0], "angle_deg": 40},
         "layout": {"type": "random", "min": [-0.4, 0.65, -0.4], "max": [0.4, 1.0, 0.4], "seed": 4}},
        {"name": "small", "shape": {"box": [0.025, 0.025, 0.03]}, "count": 8, "mass": 0.2,
         "layout": {"type": "random", "min": [-0.4, 1.05, -0.4], "max": [0.4, 1.3, 0.4], "seed": 5}}
      ]})";
    const fs::path trace = dir_ / "base.h5";
    const Result r = run_octocd("run " + scene.string() + " --engine bullet --rotation --frames 300 --trace " +
                                trace.string() + " --state-every 1 --contacts --no-xdmf --quiet");
    ASSERT_EQ(r.code, 0) << r.output;
    base_.load(trace.string());
  }
  static void TearDownTestSuite() {
    std::error_code ec;
    fs::remove_all(dir_, ec);
  }

  /// The untouched trace judged (once a test program: only the tests that read it pay).
  static const Result& base_result() {
    if (!base_judged_) {
      base_result_ = run_octocd("validate --trace-in " + base_.path);
      base_judged_ = true;
    }
    return base_result_;
  }

  /// A copy of the base trace, changed by `edit` (given the open file), judged: the
  /// frame-sampled rows (the geometric rows and impulse-feasibility) on every `every`-th
  /// step, the planted fault's frame among them (`every` = that frame); the other rows on
  /// every step.
  Result planted(const std::string& name, const std::function<void(hid_t)>& edit, int every) {
    const fs::path p = dir_ / (name + ".h5");
    fs::copy_file(base_.path, p, fs::copy_options::overwrite_existing);
    const hid_t f = H5Fopen(p.string().c_str(), H5F_ACC_RDWR, H5P_DEFAULT);
    EXPECT_GE(f, 0);
    edit(f);
    H5Fclose(f);
    return run_octocd("validate --trace-in " + p.string() + " --every " + std::to_string(every));
  }

  /// The deepest contact row between two dynamic bodies (frame, row), deeper than 2 mm.
  std::pair<int, std::size_t> deepest_dynamic_row() const {
    int best_f = -1;
    std::size_t best_r = 0;
    double best = 2e-3;
    for (int f = 1; f <= base_.frames; ++f) {
      const auto [b, e] = base_.rows(f);
      for (std::size_t r = b; r < e; ++r)
        if (base_.dynamic(base_.a(r)) && base_.dynamic(base_.b(r)) && base_.depth.v[r] > best) {
          best = base_.depth.v[r];
          best_f = f;
          best_r = r;
        }
    }
    return {best_f, best_r};
  }
};

fs::path RotationFaults::dir_;
Trace RotationFaults::base_;
Result RotationFaults::base_result_;
bool RotationFaults::base_judged_ = false;

/// "frame F" and "(A, B)" both in the output.
::testing::AssertionResult names(const Result& r, int frame, int a, int b) {
  const std::string f = "frame " + std::to_string(frame);
  const std::string p = "(" + std::to_string(a) + ", " + std::to_string(b) + ")";
  if (r.output.find(f) == std::string::npos || r.output.find(p) == std::string::npos)
    return ::testing::AssertionFailure() << "no '" << f << "' and '" << p << "' in:\n" << r.output;
  return ::testing::AssertionSuccess();
}

/// The verdict of the physics row `name` in a printed table: "pass", "FAIL" or "n/a".
std::string verdict(const Result& r, const std::string& name) {
  const std::regex line("(^|\n)physics +" + name + " +[^ ]+ +[^ ]+ +(pass|FAIL|n/a)");
  std::smatch m;
  return std::regex_search(r.output, m, line) ? m[2].str() : std::string("missing");
}

/// "(N of M contacts outside the cone)" of the friction row, N (0 when the cone holds).
int cone_failures(const Result& r) {
  std::smatch m;
  return std::regex_search(r.output, m, std::regex("\\((\\d+) of \\d+ contacts outside the cone\\)")) ? std::stoi(m[1].str()) : 0;
}

// Bullet itself breaks one physics rule here, and the friction row says so: its
// btSequentialImpulseConstraintSolver solves a row's friction only while that row's
// normal impulse is > 0, so a row whose normal impulse falls to 0 in the last iteration
// keeps an earlier iteration's friction (|jt| > 0 with jn = 0: 5 rows of this drop).
// Every other physics row passes; the planted faults below are judged on their own rows.
TEST_F(RotationFaults, TheCorrectRotatingEnginePassesEveryPhysicsRow) {
  // Friction too: octocd's Bullet adapter brings the stale friction of rows whose normal
  // impulse fell to 0 back to the cone (BulletOptions::coulomb_friction).
  for (const char* row : {"broadphase-completeness", "contact-completeness", "contact-geometry", "penetration",
                          "friction", "conservation", "momentum-balance", "free-flight"})
    EXPECT_EQ(verdict(base_result(), row), "pass") << row << "\n" << base_result().output;
  // Bullet's pair cache is conservative (fattened AABBs): extras are counted, not failed.
  EXPECT_NE(base_result().output.find("candidates per true pair"), std::string::npos) << base_result().output;
  // The model tier is n/a for an engine that does not claim design.md section 6.
  EXPECT_NE(base_result().output.find("does not claim design.md section 6"), std::string::npos) << base_result().output;
}

/// Removes pair (a, b) from step f's candidate pairs; with `static_pairs`, every frame
/// also lists every static-static pair (pairs no engine is required to report).
void drop_candidate(hid_t file, const Trace& t, int frame, int a, int b, bool static_pairs) {
  Data off = t.pair_offsets, pr = t.pairs;
  std::vector<std::array<int, 2>> statics;
  if (static_pairs)
    for (int i = 0; i < t.bodies; ++i)
      for (int j = i + 1; j < t.bodies; ++j)
        if (!t.dynamic(i) && !t.dynamic(j)) statics.push_back({i, j});
  Data new_off, new_pairs;
  new_off.dims = off.dims;
  new_off.v.push_back(0);
  for (int f = 1; f <= t.frames; ++f) {
    std::vector<std::array<int, 2>> rows = statics;
    for (auto r = static_cast<std::size_t>(off.v[f - 1]); r < static_cast<std::size_t>(off.v[f]); ++r) {
      const int pa = static_cast<int>(pr.v[2 * r]), pb = static_cast<int>(pr.v[2 * r + 1]);
      if (f == frame && pa == a && pb == b) continue;
      rows.push_back({pa, pb});
    }
    std::sort(rows.begin(), rows.end());
    rows.erase(std::unique(rows.begin(), rows.end()), rows.end());
    for (auto& q : rows) {
      new_pairs.v.push_back(q[0]);
      new_pairs.v.push_back(q[1]);
    }
    new_off.v.push_back(static_cast<double>(new_pairs.v.size() / 2));
  }
  new_pairs.dims = {new_pairs.v.size() / 2, 2};
  replace(file, "/pairs/offsets", new_off);
  replace(file, "/pairs/pair", new_pairs);
}

TEST_F(RotationFaults, ADroppedCandidatePairOfATouchingPairFails) {
  const auto [f, r] = deepest_dynamic_row();
  ASSERT_GT(f, 0) << "no dynamic pair deeper than 2 mm in the base trace";
  const int a = base_.a(r), b = base_.b(r);
  for (bool with_static : {false, true}) {
    const Result res = planted(with_static ? "drop-pair-static" : "drop-pair",
                               [&](hid_t h) { drop_candidate(h, base_, f, a, b, with_static); }, f);
    EXPECT_EQ(res.code, 3) << res.output;
    EXPECT_EQ(verdict(res, "broadphase-completeness"), "FAIL") << res.output;
    EXPECT_TRUE(names(res, f, a, b));
  }
}

TEST_F(RotationFaults, AFlippedNormalFails) {
  const auto [f, r] = deepest_dynamic_row();
  ASSERT_GT(f, 0);
  const Result res = planted("flip", [&, r = r](hid_t h) {
    Data n = base_.normal;
    for (int k = 0; k < 3; ++k) n.v[3 * r + k] = -n.v[3 * r + k];
    replace(h, "/contacts/normal", n);
  }, f);
  EXPECT_EQ(res.code, 3) << res.output;
  EXPECT_EQ(verdict(res, "contact-geometry"), "FAIL") << res.output;
  EXPECT_TRUE(names(res, f, base_.a(r), base_.b(r)));
}

TEST_F(RotationFaults, ANormalTurned45DegreesFails) {
  const auto [f, r] = deepest_dynamic_row();
  ASSERT_GT(f, 0);
  const Result res = planted("turn45", [&, r = r](hid_t h) {
    Data n = base_.normal;
    const V3 v{n.v[3 * r], n.v[3 * r + 1], n.v[3 * r + 2]};
    // Any unit vector perpendicular to v, then cos 45 v + sin 45 u.
    V3 u = std::fabs(v.x) < 0.9 ? crossp(v, V3{1, 0, 0}) : crossp(v, V3{0, 1, 0});
    u = (1.0 / len(u)) * u;
    const V3 t = std::sqrt(0.5) * v + std::sqrt(0.5) * u;
    n.v[3 * r] = t.x;
    n.v[3 * r + 1] = t.y;
    n.v[3 * r + 2] = t.z;
    replace(h, "/contacts/normal", n);
    // The row's friction impulse kept in its (turned) contact plane.
    Data j = base_.jt3;
    const V3 jr{j.v[3 * r], j.v[3 * r + 1], j.v[3 * r + 2]};
    const V3 jp = jr - dotp(jr, t) * t;
    j.v[3 * r] = jp.x;
    j.v[3 * r + 1] = jp.y;
    j.v[3 * r + 2] = jp.z;
    replace(h, "/contacts/jt3", j);
  }, f);
  EXPECT_EQ(res.code, 3) << res.output;
  EXPECT_EQ(verdict(res, "contact-geometry"), "FAIL") << res.output;
  EXPECT_TRUE(names(res, f, base_.a(r), base_.b(r)));
}

/// Removes every contact row of pair (a, b) in step f.
void drop_contact(hid_t file, const Trace& t, int frame, int a, int b) {
  std::vector<std::size_t> keep;
  Data off = t.contact_offsets;
  std::size_t removed = 0;
  for (int f = 1; f <= t.frames; ++f) {
    const auto [b0, e0] = t.rows(f);
    for (std::size_t r = b0; r < e0; ++r) {
      if (f == frame && t.a(r) == a && t.b(r) == b) {
        ++removed;
        continue;
      }
      keep.push_back(r);
    }
    off.v[static_cast<std::size_t>(f)] -= static_cast<double>(removed);
  }
  auto subset = [&](const Data& d) {
    Data out;
    out.dims = d.dims;
    out.dims[0] = keep.size();
    const hsize_t w = d.row_size();
    for (std::size_t r : keep)
      for (hsize_t k = 0; k < w; ++k) out.v.push_back(d.v[r * w + k]);
    return out;
  };
  replace(file, "/contacts/offsets", off);
  replace(file, "/contacts/pair", subset(t.contact_pair));
  replace(file, "/contacts/normal", subset(t.normal));
  replace(file, "/contacts/depth", subset(t.depth));
  replace(file, "/contacts/jn", subset(t.jn));
  replace(file, "/contacts/jt", subset(t.jt));
  if (!t.jt3.v.empty()) replace(file, "/contacts/jt3", subset(t.jt3));
  if (!t.point.v.empty()) replace(file, "/contacts/point", subset(t.point));
  if (!t.point_b.v.empty()) replace(file, "/contacts/point_b", subset(t.point_b));
}

TEST_F(RotationFaults, AContactRemovedFromAPenetratingPairFails) {
  const auto [f, r] = deepest_dynamic_row();
  ASSERT_GT(f, 0);
  const int a = base_.a(r), b = base_.b(r);
  const Result res = planted("drop-contact", [&](hid_t h) { drop_contact(h, base_, f, a, b); }, f);
  EXPECT_EQ(res.code, 3) << res.output;
  EXPECT_EQ(verdict(res, "contact-completeness"), "FAIL") << res.output;
  EXPECT_TRUE(names(res, f, a, b));
}

TEST_F(RotationFaults, AFrictionImpulseOutsideTheConeFails) {
  // The row with the largest normal impulse.
  std::size_t best = 0;
  for (std::size_t r = 0; r < base_.jn.v.size(); ++r)
    if (base_.jn.v[r] > base_.jn.v[best]) best = r;
  ASSERT_GT(base_.jn.v[best], 0.0);
  int f = 1;
  while (base_.rows(f).second <= best) ++f;
  // The cone is judged per contact (a pair's rows together): the row's friction set to
  // twice what the pair's whole normal impulse allows.
  double jn_pair = 0.0;
  for (std::size_t r = base_.rows(f).first; r < base_.rows(f).second; ++r)
    if (base_.a(r) == base_.a(best) && base_.b(r) == base_.b(best)) jn_pair += base_.jn.v[r];
  // Bullet writes /contacts/jt3, which the cone judges (the scalar jt is then not used):
  // the row's friction vector set along a tangent of its normal.
  ASSERT_FALSE(base_.jt3.v.empty());
  const V3 nb{base_.normal.v[3 * best], base_.normal.v[3 * best + 1], base_.normal.v[3 * best + 2]};
  V3 tangent = std::fabs(nb.x) < 0.9 ? crossp(nb, V3{1, 0, 0}) : crossp(nb, V3{0, 1, 0});
  tangent = (1.0 / len(tangent)) * tangent;
  const Result res = planted("cone", [&](hid_t h) {
    Data jt = base_.jt;
    jt.v[best] = 2.0 * base_.mu * jn_pair + 0.01;
    replace(h, "/contacts/jt", jt);
    Data j = base_.jt3;
    for (int k = 0; k < 3; ++k)
      j.v[3 * best + k] = (2.0 * base_.mu * jn_pair + 0.01) * (k == 0 ? tangent.x : k == 1 ? tangent.y : tangent.z);
    replace(h, "/contacts/jt3", j);
  }, f);
  EXPECT_EQ(res.code, 3) << res.output;
  EXPECT_EQ(verdict(res, "friction"), "FAIL") << res.output;
  // Exactly the planted contact outside the cone (Bullet's own trace has none: the first test).
  EXPECT_EQ(cone_failures(res), cone_failures(base_result()) + 1) << res.output;
  EXPECT_NE(res.output.find("[rule: jt3]"), std::string::npos) << res.output;
  EXPECT_TRUE(names(res, f, base_.a(best), base_.b(best)));
}

// design.md section 13b.11: friction 1.2x the cone on a pair (its rows' friction vectors all along one
// tangent, each 1.2 mu jn of its row) is caught: the per-pair cone has no relative slack.
TEST_F(RotationFaults, AFrictionImpulseOfOnePointTwoTimesTheConeFails) {
  // The pair with the largest summed normal impulse.
  std::size_t best = 0;
  for (std::size_t r = 0; r < base_.jn.v.size(); ++r)
    if (base_.jn.v[r] > base_.jn.v[best]) best = r;
  int f = 1;
  while (base_.rows(f).second <= best) ++f;
  const int a = base_.a(best), b = base_.b(best);
  const V3 nb{base_.normal.v[3 * best], base_.normal.v[3 * best + 1], base_.normal.v[3 * best + 2]};
  V3 tangent = std::fabs(nb.x) < 0.9 ? crossp(nb, V3{1, 0, 0}) : crossp(nb, V3{0, 1, 0});
  tangent = (1.0 / len(tangent)) * tangent;
  const Result res = planted("cone12", [&](hid_t h) {
    Data j = base_.jt3;
    for (std::size_t r = base_.rows(f).first; r < base_.rows(f).second; ++r) {
      if (base_.a(r) != a || base_.b(r) != b) continue;
      const V3 n{base_.normal.v[3 * r], base_.normal.v[3 * r + 1], base_.normal.v[3 * r + 2]};
      V3 t = tangent - dotp(tangent, n) * n;  // in this row's contact plane
      t = (1.0 / len(t)) * t;
      for (int k = 0; k < 3; ++k)
        j.v[3 * r + k] = 1.2 * base_.mu * base_.jn.v[r] * (k == 0 ? t.x : k == 1 ? t.y : t.z);
    }
    replace(h, "/contacts/jt3", j);
  }, f);
  EXPECT_EQ(res.code, 3) << res.output;
  EXPECT_EQ(verdict(res, "friction"), "FAIL") << res.output;
  EXPECT_NE(res.output.find("1.2 x the cone"), std::string::npos) << res.output;
  EXPECT_TRUE(names(res, f, a, b));
}

TEST_F(RotationFaults, EnergyAddedToAnIsolatedGroupFails) {
  // A step whose contacts form a group of dynamic bodies touching no static body.
  int frame = -1, body = -1;
  for (int f = 1; f <= base_.frames && frame < 0; ++f) {
    const auto [b0, e0] = base_.rows(f);
    std::vector<int> parent(static_cast<std::size_t>(base_.bodies));
    std::iota(parent.begin(), parent.end(), 0);
    std::function<int(int)> find = [&](int i) { return parent[i] == i ? i : parent[i] = find(parent[i]); };
    for (std::size_t r = b0; r < e0; ++r) parent[find(base_.a(r))] = find(base_.b(r));
    std::map<int, bool> touches_static;
    for (std::size_t r = b0; r < e0; ++r)
      touches_static[find(base_.a(r))] |= !base_.dynamic(base_.a(r)) || !base_.dynamic(base_.b(r));
    for (const auto& [root, st] : touches_static)
      if (!st) {
        frame = f;
        for (std::size_t r = b0; r < e0; ++r)
          if (find(base_.a(r)) == root) body = base_.a(r);
        break;
      }
  }
  ASSERT_GT(frame, 0) << "no isolated dynamic group in the base trace";
  const Result res = planted("energy", [&](hid_t h) {
    Data v = base_.vel;
    // Row `frame` is the state after step `frame`: its velocity doubled (and 0.5 m/s up).
    const std::size_t o = (static_cast<std::size_t>(frame) * base_.bodies + body) * 3;
    for (int k = 0; k < 3; ++k) v.v[o + k] *= 2.0;
    v.v[o + 1] += 0.5;
    replace(h, "/states/velocity", v);
  }, frame);
  EXPECT_EQ(res.code, 3) << res.output;
  EXPECT_EQ(verdict(res, "conservation"), "FAIL") << res.output;
  EXPECT_NE(res.output.find("frame " + std::to_string(frame)), std::string::npos) << res.output;
}

TEST_F(RotationFaults, ABroadphaseOnTheUnrotatedLocalBoxMissesAPair) {
  // Every step's pairs recomputed from the local boxes translated (not rotated) to the
  // pre-step positions: what an engine that forgets the orientation in its AABBs finds.
  const hid_t probe = H5Fopen(base_.path.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT);
  const Data lmin = read(probe, "/bodies/local_aabb_min"), lmax = read(probe, "/bodies/local_aabb_max");
  H5Fclose(probe);
  const Result res = planted("unrotated", [&](hid_t h) {
    Data off, pr;
    off.v.push_back(0);
    for (int f = 1; f <= base_.frames; ++f) {
      for (int i = 0; i < base_.bodies; ++i)
        for (int j = i + 1; j < base_.bodies; ++j) {
          if (!base_.dynamic(i) && !base_.dynamic(j)) continue;
          const V3 xi = base_.x(f - 1, i), xj = base_.x(f - 1, j);
          bool overlap = true;
          for (int k = 0; k < 3; ++k) {
            const double ci = k == 0 ? xi.x : k == 1 ? xi.y : xi.z, cj = k == 0 ? xj.x : k == 1 ? xj.y : xj.z;
            overlap = overlap && ci + lmin.v[3 * i + k] <= cj + lmax.v[3 * j + k] &&
                      cj + lmin.v[3 * j + k] <= ci + lmax.v[3 * i + k];
          }
          if (overlap) {
            pr.v.push_back(i);
            pr.v.push_back(j);
          }
        }
      off.v.push_back(static_cast<double>(pr.v.size() / 2));
    }
    off.dims = {off.v.size()};
    pr.dims = {pr.v.size() / 2, 2};
    replace(h, "/pairs/offsets", off);
    replace(h, "/pairs/pair", pr);
  }, 1);
  EXPECT_EQ(res.code, 3) << res.output;
  EXPECT_EQ(verdict(res, "broadphase-completeness"), "FAIL") << res.output;
}

TEST_F(RotationFaults, AnOrientationNotAppliedToContactPointsFails) {
  ASSERT_FALSE(base_.point.v.empty()) << "the Bullet trace has no /contacts/point";
  // The contact row whose point moves most when a body's orientation is ignored (its
  // body-frame offset taken as a world offset): that body's rows of that frame are moved.
  int frame = -1, body = -1;
  double worst = 0.05;  // m: beyond the contact margin (0.022 m) and the depth bound
  for (int f = 1; f <= base_.frames; ++f) {
    const auto [b0, e0] = base_.rows(f);
    for (std::size_t r = b0; r < e0; ++r)
      for (int i : {base_.a(r), base_.b(r)}) {
        if (!base_.dynamic(i)) continue;
        const V3 x = base_.x(f - 1, i), w{base_.point.v[3 * r], base_.point.v[3 * r + 1], base_.point.v[3 * r + 2]};
        const double moved = len(rotate(base_.q(f - 1, i), w - x, true) - (w - x));
        if (moved > worst) {
          worst = moved;
          frame = f;
          body = i;
        }
      }
  }
  ASSERT_GT(frame, 0) << "no contact point of a rotated body";
  const Result res = planted("points", [&](hid_t h) {
    Data p = base_.point;
    const auto [b0, e0] = base_.rows(frame);
    const double* q = base_.q(frame - 1, body);
    const V3 x = base_.x(frame - 1, body);
    for (std::size_t r = b0; r < e0; ++r) {
      if (base_.a(r) != body && base_.b(r) != body) continue;
      const V3 w{p.v[3 * r], p.v[3 * r + 1], p.v[3 * r + 2]};
      const V3 local = rotate(q, w - x, true);  // the point in the body frame
      const V3 wrong = x + local;               // ... taken as a world offset
      p.v[3 * r] = wrong.x;
      p.v[3 * r + 1] = wrong.y;
      p.v[3 * r + 2] = wrong.z;
    }
    replace(h, "/contacts/point", p);
  }, frame);
  EXPECT_EQ(res.code, 3) << res.output;
  EXPECT_EQ(verdict(res, "contact-geometry"), "FAIL") << res.output;
  EXPECT_NE(res.output.find("frame " + std::to_string(frame)), std::string::npos) << res.output;
}

}  // namespace

// design.md section 13b.10: Bullet with rotation collides a mesh as its convex hull and declares it
// (root attribute collision_shape = "convex_hull"): four bunnies dropped in a column pass
// every physics row. The same trace without the declaration is judged on the concave
// bunny, where the hulls' contacts are 7 mm deeper than the meshes' overlap (a false
// verdict the declaration removes).
TEST(DeclaredCollisionShapes, BulletsBunnyHullsPassDeclaredAndFailAsMeshes) {
  const fs::path dir = fs::temp_directory_path() / ("octocd-hulls-" + std::to_string(::getpid()));
  fs::create_directories(dir);
  const fs::path scene = dir / "column.json";
  std::ofstream(scene) << R"({"name": "bunny-rot-column", "rotation": true, "dt": 0.001, "frames": 30,
    "domain": {"min": [-0.6, 0.0, -0.6], "max": [0.6, 1.5, 0.6]}, "walls": "open-box",
    "groups": [{"name": "bunnies", "shape": {"mesh": "bunny", "scale": 0.2}, "count": 4, "mass": 1.0,
      "positions": [[0, 0.1, 0], [0.03, 0.28, 0.01], [-0.02, 0.46, 0.02], [0.01, 0.64, -0.02]],
      "velocity": {"type": "fixed", "value": [0.0, -1.0, 0.0]}}]})";
  const fs::path trace = dir / "column.h5";
  const Result r = run_octocd("validate " + scene.string() + " --engine bullet --frames 30 --trace " + trace.string());
  EXPECT_EQ(r.code, 0) << r.output;
  for (const char* row : {"broadphase-completeness", "contact-completeness", "contact-geometry", "penetration",
                          "friction"})
    EXPECT_EQ(verdict(r, row), "pass") << row << "\n" << r.output;
  EXPECT_NE(r.output.find("collided as declared \"convex_hull\""), std::string::npos) << r.output;
  // Without the declaration: judged on the true (concave) mesh.
  const fs::path bare = dir / "bare.h5";
  fs::copy_file(trace, bare, fs::copy_options::overwrite_existing);
  const hid_t f = H5Fopen(bare.string().c_str(), H5F_ACC_RDWR, H5P_DEFAULT);
  ASSERT_GE(f, 0);
  // Bullet declares its shapes per body (/bodies/collision_shape); drop the declaration.
  if (H5Aexists(f, "collision_shape") > 0) ASSERT_GE(H5Adelete(f, "collision_shape"), 0);
  else ASSERT_GE(H5Ldelete(f, "/bodies/collision_shape", H5P_DEFAULT), 0);
  H5Fclose(f);
  const Result m = run_octocd("validate --trace-in " + bare.string());
  EXPECT_EQ(m.code, 3) << m.output;
  EXPECT_EQ(verdict(m, "contact-geometry"), "FAIL") << m.output;
  EXPECT_NE(m.output.find("(upper bound) [reference: FCL]"), std::string::npos) << m.output;
  std::error_code ec;
  fs::remove_all(dir, ec);
}

// design.md section 13b.11 on Bullet's rot-slope (a box sliding down a slope on a 4-row manifold):
// the clean trace passes the friction row on jt3; friction reversed (every row's jt3
// negated) is caught, naming the frame and the pair.
TEST(FrictionOnManifolds, BulletsSlopeReversedFrictionIsCaught) {
  const fs::path dir = fs::temp_directory_path() / ("octocd-slope-" + std::to_string(::getpid()));
  fs::create_directories(dir);
  const fs::path trace = dir / "slope.h5";
  const Result r = run_octocd("run " + (fs::path(source_dir()) / "datasets/scenes/rot-slope.json").string() +
                              " --engine bullet --rotation --frames 100 --trace " + trace.string() +
                              " --state-every 1 --contacts --no-xdmf --quiet");
  ASSERT_EQ(r.code, 0) << r.output;
  const Result clean = run_octocd("validate --trace-in " + trace.string());
  EXPECT_EQ(clean.code, 0) << clean.output;
  EXPECT_EQ(verdict(clean, "friction"), "pass") << clean.output;
  EXPECT_NE(clean.output.find("rule jt3 on"), std::string::npos) << clean.output;
  const fs::path reversed = dir / "reversed.h5";
  fs::copy_file(trace, reversed, fs::copy_options::overwrite_existing);
  const hid_t f = H5Fopen(reversed.string().c_str(), H5F_ACC_RDWR, H5P_DEFAULT);
  ASSERT_GE(f, 0);
  Data j = read(f, "/contacts/jt3");
  ASSERT_FALSE(j.v.empty());
  for (double& x : j.v) x = -x;
  replace(f, "/contacts/jt3", j);
  H5Fclose(f);
  const Result bad = run_octocd("validate --trace-in " + reversed.string());
  EXPECT_EQ(bad.code, 3) << bad.output;
  EXPECT_EQ(verdict(bad, "friction"), "FAIL") << bad.output;
  EXPECT_TRUE(std::regex_search(bad.output, std::regex("frame \\d+: pair \\(0, 1\\) \\(4 rows\\): the friction "
                                                       "impulse .* pushes the contact points along their sliding")))
      << bad.output;
  std::error_code ec;
  fs::remove_all(dir, ec);
}

}  // namespace octocd_test_cli_rotation_faults
