// Momentum balance per body and free flight (design.md sections 13b.7, 13b.8) on Bullet with rotation,
// the correct rotating engine (issue 30 item 7): its version 2 traces of the shipped
// rotating scenes pass both rows, and faults planted into a copy of each trace (edited
// in place) are caught with exit 3 and a detail naming the frame and the body: an edited
// velocity of a body in contact, one row of a manifold dropped, a row's impulse applied to
// a lone body instead of its own, a lone body's velocity x1.5, a lone body teleported by
// 1 cm, a lone spinning body's angular velocity x1.5, a lone body's orientation turned
// by 30 deg. The bodies are found in the trace (no contact row in the step), never
// pinned by number. Few frames each, the geometric rows on a few frames only.
// BulletFriction plants the friction faults of design.md section 13b.11 on rot-stack-10, rot-drop-220
// and rot-pile-1000 (rot-slope's are in test_cli_rotation_faults.cpp).
#include <gtest/gtest.h>
#include <hdf5.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <filesystem>
#include <functional>
#include <iostream>
#include <regex>
#include <set>
#include <string>
#include <vector>

#include "support/cli_run.hpp"
#include "support/trace_edit.hpp"

// This file's own names (its tests compile in unity batches with the folder's other files).
namespace octocd_test_cli_bullet_balance {

namespace fs = std::filesystem;
using octocd::test::Result;
using octocd::test::run_octocd;
using octocd::test::source_dir;

namespace {

using octocd::test::Data;
using octocd::test::read;
using octocd::test::replace;
using octocd::test::write;

/// What a trace says about who is in contact when.
struct Layout {
  int bodies = 0, frames = 0;
  Data inv_mass, offsets, pairs, velocity, angular, jn, normal;
  /// Bodies with a contact row in step f (1-based).
  std::set<int> in_contact(int f) const {
    std::set<int> s;
    for (auto r = static_cast<std::size_t>(offsets.v[f - 1]); r < static_cast<std::size_t>(offsets.v[f]); ++r) {
      s.insert(static_cast<int>(pairs.v[2 * r]));
      s.insert(static_cast<int>(pairs.v[2 * r + 1]));
    }
    return s;
  }
  bool dynamic(int i) const { return inv_mass.v[static_cast<std::size_t>(i)] > 0; }
  double speed(const Data& d, int row, int i) const {
    const double* p = &d.v[(static_cast<std::size_t>(row) * bodies + i) * 3];
    return std::sqrt(p[0] * p[0] + p[1] * p[1] + p[2] * p[2]);
  }
  /// The first (frame, body) from frame `from` on with `want(frame, body)`; (-1, -1) if none.
  std::pair<int, int> find(int from, const std::function<bool(int, int)>& want) const {
    for (int f = from; f < frames; ++f)
      for (int i = 0; i < bodies; ++i)
        if (dynamic(i) && want(f, i)) return {f, i};
    return {-1, -1};
  }
};

struct Case {
  const char* scene;
  int frames;
};

class BulletBalance : public ::testing::TestWithParam<Case> {
 protected:
  fs::path dir_, trace_;
  Layout layout_;

  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("octocd-bullet-balance-" + std::to_string(::getpid()) + "-" +
                                        GetParam().scene);
    fs::create_directories(dir_);
    trace_ = dir_ / "base.h5";
    const std::string scene = source_dir() + "/datasets/scenes/" + GetParam().scene + ".json";
    const Result r = run_octocd("run " + scene + " --engine bullet --rotation --frames " +
                                std::to_string(GetParam().frames) + " --trace " + trace_.string() +
                                " --state-every 1 --contacts --no-xdmf --quiet");
    ASSERT_EQ(r.code, 0) << r.output;
    const hid_t f = H5Fopen(trace_.string().c_str(), H5F_ACC_RDONLY, H5P_DEFAULT);
    ASSERT_GE(f, 0);
    layout_.inv_mass = read(f, "/bodies/inverse_mass");
    layout_.offsets = read(f, "/contacts/offsets");
    layout_.pairs = read(f, "/contacts/pair");
    layout_.velocity = read(f, "/states/velocity");
    layout_.angular = read(f, "/states/angular_velocity");
    layout_.jn = read(f, "/contacts/jn");
    layout_.normal = read(f, "/contacts/normal");
    H5Fclose(f);
    layout_.bodies = static_cast<int>(layout_.velocity.dims.at(1));
    layout_.frames = static_cast<int>(layout_.velocity.dims.at(0)) - 1;
  }
  void TearDown() override {
    std::error_code ec;
    fs::remove_all(dir_, ec);
  }

  /// A copy of the trace without contact row `row` of step f (its later offsets shifted).
  Result dropped_row(int f, std::size_t row) {
    const fs::path p = dir_ / "dropped-row.h5";
    fs::copy_file(trace_, p, fs::copy_options::overwrite_existing);
    const hid_t file = H5Fopen(p.string().c_str(), H5F_ACC_RDWR, H5P_DEFAULT);
    EXPECT_GE(file, 0);
    for (const char* name : {"/contacts/pair", "/contacts/normal", "/contacts/depth", "/contacts/jn", "/contacts/jt",
                             "/contacts/point", "/contacts/point_b", "/contacts/jt3"}) {
      if (H5Lexists(file, name, H5P_DEFAULT) <= 0) continue;  // jt3, point_b: where the engine writes them
      Data d = read(file, name);
      std::size_t per = 1;
      for (std::size_t k = 1; k < d.dims.size(); ++k) per *= d.dims[k];
      d.v.erase(d.v.begin() + static_cast<std::ptrdiff_t>(row * per),
                d.v.begin() + static_cast<std::ptrdiff_t>((row + 1) * per));
      d.dims[0] -= 1;
      replace(file, name, d);
    }
    Data o = read(file, "/contacts/offsets");
    for (std::size_t k = static_cast<std::size_t>(f); k < o.v.size(); ++k) o.v[k] -= 1;
    write(file, "/contacts/offsets", o);
    H5Fclose(file);
    return run_octocd("validate --trace-in " + p.string() + " --every " + std::to_string(layout_.frames));
  }

  /// A copy of the trace with state row `row` of `dataset` changed for body i by `edit`
  /// (its components), and for body j by `edit_j` when given, judged with the geometric
  /// rows on one frame.
  Result planted(const std::string& tag, const char* dataset, int row, int i,
                 const std::function<void(double*)>& edit, int j = -1,
                 const std::function<void(double*)>& edit_j = {}) {
    const fs::path p = dir_ / (tag + ".h5");
    fs::copy_file(trace_, p, fs::copy_options::overwrite_existing);
    const hid_t f = H5Fopen(p.string().c_str(), H5F_ACC_RDWR, H5P_DEFAULT);
    EXPECT_GE(f, 0);
    Data d = read(f, dataset);
    const std::size_t per = d.dims.at(2);
    edit(&d.v[(static_cast<std::size_t>(row) * layout_.bodies + i) * per]);
    if (j >= 0) edit_j(&d.v[(static_cast<std::size_t>(row) * layout_.bodies + j) * per]);
    write(f, dataset, d);
    H5Fclose(f);
    return run_octocd("validate --trace-in " + p.string() + " --every " + std::to_string(layout_.frames));
  }
};

/// Exit 3, the row FAILs and the output names "frame F: body I" with `what`.
void expect_caught(const Result& r, const std::string& row, int frame, int body, const std::string& what) {
  EXPECT_EQ(r.code, 3) << r.output;
  EXPECT_TRUE(std::regex_search(r.output, std::regex("(^|\n)physics +" + row + " +[^ ]+ +[^ ]+ +FAIL")))
      << row << "\n" << r.output;
  const std::string named = "frame " + std::to_string(frame) + ": body " + std::to_string(body) + what;
  EXPECT_NE(r.output.find(named), std::string::npos) << named << "\n" << r.output;
}

TEST_P(BulletBalance, CleanRunPassesAndPlantedFaultsAreCaught) {
  const Result clean = run_octocd("validate --trace-in " + trace_.string() + " --every 40");
  EXPECT_EQ(clean.code, 0) << clean.output;
  for (const char* row : {"momentum-balance", "free-flight"})
    EXPECT_TRUE(std::regex_search(clean.output, std::regex(std::string("(^|\n)physics +") + row +
                                                           " +[^ ]+ +[^ ]+ +pass")))
        << row << "\n" << clean.output;
  const Layout& L = layout_;
  int planted_faults = 0;

  // A body in contact: its velocity edited by 0.1 m/s along y.
  const auto [fc, ic] = L.find(5, [&](int f, int i) { return L.in_contact(f).count(i) > 0; });
  if (fc > 0) {
    ++planted_faults;
    expect_caught(planted("contact-velocity", "/states/velocity", fc, ic, [](double* v) { v[1] += 0.1; }),
                  "momentum-balance", fc, ic, ": m (v' - v)");
  }
  // One row of a manifold (a pair with 2+ rows in the step) with a normal impulse
  // dropped: the bodies' momentum change keeps it, their rows no longer do.
  for (int f = 5; f <= L.frames && fc > 0; ++f) {
    const auto b = static_cast<std::size_t>(L.offsets.v[f - 1]), e = static_cast<std::size_t>(L.offsets.v[f]);
    std::size_t pick = e;
    for (std::size_t r = b; r + 1 < e && pick == e; ++r)
      if (L.pairs.v[2 * r] == L.pairs.v[2 * r + 2] && L.pairs.v[2 * r + 1] == L.pairs.v[2 * r + 3] &&
          L.jn.v[r] > 1e-3)
        pick = r;
    if (pick == e) continue;
    const int a = static_cast<int>(L.pairs.v[2 * pick]), bb = static_cast<int>(L.pairs.v[2 * pick + 1]);
    const Result r = dropped_row(f, pick);
    expect_caught(r, "momentum-balance", f, L.dynamic(a) ? a : bb, ": m (v' - v)");
    ++planted_faults;
    break;
  }
  // A lone body (no contact row in the step), moving: velocity x1.5, then teleported by 1 cm.
  const auto [fl, il] = L.find(
      5, [&](int f, int i) { return L.in_contact(f).count(i) == 0 && L.speed(L.velocity, f, i) > 0.01; });
  if (fl > 0) {
    planted_faults += 2;
    expect_caught(planted("lone-velocity", "/states/velocity", fl, il,
                          [](double* v) { v[0] *= 1.5, v[1] *= 1.5, v[2] *= 1.5; }),
                  "free-flight", fl, il, " without contacts: v'");
    expect_caught(planted("teleport", "/states/position", fl, il, [](double* x) { x[2] += 0.01; }), "free-flight",
                  fl, il, " without contacts: x'");
    // Its orientation turned by 30 deg about x.
    ++planted_faults;
    const double c = std::cos(M_PI / 12), s = std::sin(M_PI / 12);
    expect_caught(planted("turned", "/states/orientation", fl, il,
                          [&](double* q) {
                            const std::array<double, 4> o{q[0], q[1], q[2], q[3]};  // (c, s, 0, 0) * o
                            q[0] = c * o[0] - s * o[1];
                            q[1] = c * o[1] + s * o[0];
                            q[2] = c * o[2] - s * o[3];
                            q[3] = c * o[3] + s * o[2];
                          }),
                  "free-flight", fl, il, " without contacts: q' is 30");
  }
  // A row's normal impulse applied to a lone body instead of the row's body B.
  for (int f = 5; f <= L.frames; ++f) {
    const auto b = static_cast<std::size_t>(L.offsets.v[f - 1]), e = static_cast<std::size_t>(L.offsets.v[f]);
    std::size_t pick = e;
    for (std::size_t r = b; r < e && pick == e; ++r)
      if (L.jn.v[r] > 1e-2 && L.dynamic(static_cast<int>(L.pairs.v[2 * r + 1]))) pick = r;
    if (pick == e) continue;
    const std::set<int> busy = L.in_contact(f);
    int lone = -1;
    for (int i = 0; i < L.bodies && lone < 0; ++i)
      if (L.dynamic(i) && busy.count(i) == 0) lone = i;
    if (lone < 0) continue;
    const int body_b = static_cast<int>(L.pairs.v[2 * pick + 1]);
    const double* n = &L.normal.v[3 * pick];
    const double jn = L.jn.v[pick], wb = L.inv_mass.v[static_cast<std::size_t>(body_b)],
                 wl = L.inv_mass.v[static_cast<std::size_t>(lone)];
    const Result r = planted(
        "wrong-body", "/states/velocity", f, body_b,
        [&](double* v) {
          for (int k = 0; k < 3; ++k) v[k] += wb * jn * n[k];  // B no longer gets -jn n
        },
        lone,
        [&](double* v) {
          for (int k = 0; k < 3; ++k) v[k] -= wl * jn * n[k];  // the lone body does
        });
    expect_caught(r, "momentum-balance", f, body_b, ": m (v' - v)");
    expect_caught(r, "free-flight", f, lone, " without contacts: v'");
    ++planted_faults;
    break;
  }
  // A lone spinning body: angular velocity x1.5.
  const auto [fs_, is] = L.find(
      5, [&](int f, int i) { return L.in_contact(f).count(i) == 0 && L.speed(L.angular, f, i) > 0.5; });
  if (fs_ > 0) {
    ++planted_faults;
    expect_caught(planted("spin", "/states/angular_velocity", fs_, is,
                          [](double* w) { w[0] *= 1.5, w[1] *= 1.5, w[2] *= 1.5; }),
                  "free-flight", fs_, is, " without contacts: w'");
  }
  EXPECT_GE(planted_faults, 1);
  std::cout << GetParam().scene << ": " << planted_faults << " faults planted\n";
}

INSTANTIATE_TEST_SUITE_P(Scenes, BulletBalance,
                         ::testing::Values(Case{"rot-slope", 120}, Case{"rot-stack-10", 120},
                                           Case{"rot-drop-220", 120}, Case{"rot-pile-1000", 40}),
                         [](const ::testing::TestParamInfo<Case>& i) {
                           std::string s = i.param.scene;
                           for (char& ch : s)
                             if (ch == '-') ch = '_';
                           return s;
                         });

/// Friction faults (design.md section 13b.11) planted on Bullet's traces of rot-stack-10, rot-drop-220
/// and rot-pile-1000, one scene each: on the manifold pair with the largest normal
/// impulse, its friction set to 1.2x the cone and to an unscaled pyramid (each row mu jn
/// along two tangents: sqrt(2) mu jn); friction reversed on a manifold; a row carrying
/// friction dropped. Each exits 3 naming the frame and the pair (the body for the dropped
/// row, which momentum-balance judges).
class BulletFriction : public BulletBalance {
 protected:
  Data pos, quat, point, jt3;
  double mu = 0.5;
  void SetUp() override {
    BulletBalance::SetUp();
    const hid_t f = H5Fopen(trace_.string().c_str(), H5F_ACC_RDONLY, H5P_DEFAULT);
    ASSERT_GE(f, 0);
    pos = read(f, "/states/position");
    quat = read(f, "/states/orientation");
    point = read(f, "/contacts/point");
    jt3 = read(f, "/contacts/jt3");
    const hid_t a = H5Aopen(f, "mu", H5P_DEFAULT);
    ASSERT_GE(a, 0);
    H5Aread(a, H5T_NATIVE_DOUBLE, &mu);
    H5Aclose(a);
    H5Fclose(f);
    ASSERT_FALSE(jt3.v.empty()) << "Bullet writes /contacts/jt3";
  }

  /// A manifold: pair (a, b) in step f, rows [r0, r1).
  struct Patch {
    int f = -1, a = -1, b = -1;
    std::size_t r0 = 0, r1 = 0;
  };
  std::vector<Patch> patches() const {
    std::vector<Patch> out;
    for (int f = 1; f <= layout_.frames; ++f) {
      const auto e = static_cast<std::size_t>(layout_.offsets.v[f]);
      for (auto r = static_cast<std::size_t>(layout_.offsets.v[f - 1]); r < e;) {
        Patch p{f, static_cast<int>(layout_.pairs.v[2 * r]), static_cast<int>(layout_.pairs.v[2 * r + 1]), r, r};
        while (p.r1 < e && layout_.pairs.v[2 * p.r1] == p.a && layout_.pairs.v[2 * p.r1 + 1] == p.b) ++p.r1;
        out.push_back(p);
        r = p.r1;
      }
    }
    return out;
  }
  std::array<double, 3> vec(const Data& d, std::size_t row) const {
    return {d.v[3 * row], d.v[3 * row + 1], d.v[3 * row + 2]};
  }
  double friction(const Patch& p) const {
    std::array<double, 3> s{};
    for (std::size_t r = p.r0; r < p.r1; ++r)
      for (int k = 0; k < 3; ++k) s[k] += jt3.v[3 * r + k];
    return std::sqrt(s[0] * s[0] + s[1] * s[1] + s[2] * s[2]);
  }
  /// The slowest tangential speed at the patch's points, before the step (after gravity)
  /// and after it (m/s).
  double sliding(const Patch& p) const {
    double slowest = 1e9;
    const double g_dt[3] = {0, -9.81e-3, 0};  // the scenes' gravity x dt
    for (int post = 0; post < 2; ++post)
      for (std::size_t r = p.r0; r < p.r1; ++r) {
        std::array<double, 3> rel{};
        for (int body : {p.a, p.b}) {
          const std::size_t o = (static_cast<std::size_t>(p.f - 1 + post) * layout_.bodies + body) * 3;
          const std::size_t x0 = (static_cast<std::size_t>(p.f - 1) * layout_.bodies + body) * 3;
          const double sign = body == p.a ? 1.0 : -1.0;
          const double* w = &layout_.angular.v[o];
          const double arm[3] = {point.v[3 * r] - pos.v[x0], point.v[3 * r + 1] - pos.v[x0 + 1],
                                 point.v[3 * r + 2] - pos.v[x0 + 2]};
          const double wxr[3] = {w[1] * arm[2] - w[2] * arm[1], w[2] * arm[0] - w[0] * arm[2],
                                 w[0] * arm[1] - w[1] * arm[0]};
          for (int k = 0; k < 3; ++k)
            rel[k] += sign * (layout_.velocity.v[o + k] + wxr[k] + (post == 0 && layout_.dynamic(body) ? g_dt[k] : 0));
        }
        const auto n = vec(layout_.normal, r);
        const double vn = rel[0] * n[0] + rel[1] * n[1] + rel[2] * n[2];
        double t2 = 0;
        for (int k = 0; k < 3; ++k) t2 += (rel[k] - vn * n[k]) * (rel[k] - vn * n[k]);
        slowest = std::min(slowest, std::sqrt(t2));
      }
    return slowest;
  }
  /// A copy of the trace with /contacts/jt3 rows [p.r0, p.r1) set by `set(row, n, jt3)`.
  Result planted_jt3(const std::string& tag, const Patch& p,
                     const std::function<void(std::size_t, const std::array<double, 3>&, double*)>& set) {
    const fs::path path = dir_ / (tag + ".h5");
    fs::copy_file(trace_, path, fs::copy_options::overwrite_existing);
    const hid_t f = H5Fopen(path.string().c_str(), H5F_ACC_RDWR, H5P_DEFAULT);
    EXPECT_GE(f, 0);
    Data j = jt3;
    for (std::size_t r = p.r0; r < p.r1; ++r) set(r, vec(layout_.normal, r), &j.v[3 * r]);
    write(f, "/contacts/jt3", j);
    H5Fclose(f);
    return run_octocd("validate --trace-in " + path.string() + " --every " + std::to_string(layout_.frames));
  }
};

/// Unit tangents t1, t2 of normal n (t1 from a fixed world axis, so one patch's rows,
/// whose normals agree, share them).
std::array<std::array<double, 3>, 2> tangents(const std::array<double, 3>& n) {
  const std::array<double, 3> axis = std::fabs(n[0]) < 0.9 ? std::array<double, 3>{1, 0, 0}
                                                           : std::array<double, 3>{0, 0, 1};
  const double d = axis[0] * n[0] + axis[1] * n[1] + axis[2] * n[2];
  std::array<double, 3> t1{axis[0] - d * n[0], axis[1] - d * n[1], axis[2] - d * n[2]};
  const double l = std::sqrt(t1[0] * t1[0] + t1[1] * t1[1] + t1[2] * t1[2]);
  for (double& x : t1) x /= l;
  const std::array<double, 3> t2{n[1] * t1[2] - n[2] * t1[1], n[2] * t1[0] - n[0] * t1[2], n[0] * t1[1] - n[1] * t1[0]};
  return {t1, t2};
}

/// Exit 3, the friction row FAILs, "frame F: pair (A, B)" and every fragment in the output.
void expect_friction_caught(const Result& r, int frame, int a, int b, const std::vector<std::string>& fragments) {
  EXPECT_EQ(r.code, 3) << r.output;
  EXPECT_TRUE(std::regex_search(r.output, std::regex("(^|\n)physics +friction +[^ ]+ +[^ ]+ +FAIL"))) << r.output;
  const std::string named = "frame " + std::to_string(frame) + ": pair (" + std::to_string(a) + ", " +
                            std::to_string(b) + ")";
  EXPECT_NE(r.output.find(named), std::string::npos) << named << "\n" << r.output;
  for (const std::string& f : fragments) EXPECT_NE(r.output.find(f), std::string::npos) << f << "\n" << r.output;
}

TEST_P(BulletFriction, FrictionFaultsAreCaughtNamingFrameAndPair) {
  const std::vector<Patch> all = patches();
  // The manifold (2+ rows) with the largest summed normal impulse.
  const Patch* big = nullptr;
  double best = 0;
  for (const Patch& p : all) {
    double jn = 0;
    for (std::size_t r = p.r0; r < p.r1; ++r) jn += layout_.jn.v[r];
    if (p.r1 - p.r0 >= 2 && jn > best) {
      best = jn;
      big = &p;
    }
  }
  ASSERT_NE(big, nullptr) << "no manifold in the trace";
  const Patch cone = *big;
  // 1.2x the cone: each row's friction 1.2 mu jn along one tangent.
  expect_friction_caught(planted_jt3("cone12", cone,
                                     [&](std::size_t r, const std::array<double, 3>& n, double* j) {
                                       const auto t = tangents(n);
                                       for (int k = 0; k < 3; ++k) j[k] = 1.2 * mu * layout_.jn.v[r] * t[0][k];
                                     }),
                         cone.f, cone.a, cone.b, {"x the cone) (sums over its", "[rule: jt3]"});
  // An unscaled pyramid: each direction clamped to mu jn, the diagonal sqrt(2) mu jn.
  expect_friction_caught(planted_jt3("pyramid", cone,
                                     [&](std::size_t r, const std::array<double, 3>& n, double* j) {
                                       const auto t = tangents(n);
                                       for (int k = 0; k < 3; ++k) j[k] = mu * layout_.jn.v[r] * (t[0][k] + t[1][k]);
                                     }),
                         cone.f, cone.a, cone.b, {"1.414 x the cone", "[rule: jt3]"});
  // Friction reversed on a manifold: the sliding manifold (2+ rows, above friction_cone_abs,
  // its friction on the cone: kinetic, its bodies' only pair: dissipation judges it) whose
  // points slide fastest, before and after the step.
  const Patch* slide = nullptr;
  double fastest = 0.01;  // m/s
  for (const Patch& p : all) {
    double jn = 0;
    for (std::size_t r = p.r0; r < p.r1; ++r) jn += layout_.jn.v[r];
    if (p.r1 - p.r0 < 2 || friction(p) <= 2e-3 || friction(p) < 0.99 * mu * jn || p.f < 2) continue;
    bool alone = true;
    for (const Patch& q : all)
      if (q.f == p.f && !(q.a == p.a && q.b == p.b))
        for (int i : {p.a, p.b})
          alone = alone && !(layout_.dynamic(i) && (q.a == i || q.b == i));
    const double s = alone ? sliding(p) : 0.0;
    if (s > fastest) {
      fastest = s;
      slide = &p;
    }
  }
  std::string reversed = "on a stack pair (momentum-balance)";
  if (slide) {
    const Patch p = *slide;
    reversed = "on frame " + std::to_string(p.f) + " pair (" + std::to_string(p.a) + ", " + std::to_string(p.b) +
               ") (" + std::to_string(p.r1 - p.r0) + " rows, sliding " + std::to_string(fastest) + " m/s)";
    expect_friction_caught(planted_jt3("reversed", p,
                                       [&](std::size_t, const std::array<double, 3>&, double* j) {
                                         for (int k = 0; k < 3; ++k) j[k] = -j[k];
                                       }),
                           p.f, p.a, p.b,
                           {"(" + std::to_string(p.r1 - p.r0) + " rows): the friction impulse",
                            "pushes the contact points along their sliding"});
  } else {
    // No manifold slides alone (a stack: each pair shares a box): dissipation cannot tell
    // a pair's friction from its neighbours'. The reversed impulses no longer match the
    // bodies' velocity change: momentum-balance names both bodies of the pair with the
    // largest friction.
    const Patch* most = nullptr;
    double f_most = 2e-3;
    for (const Patch& p : all)
      if (p.r1 - p.r0 >= 2 && friction(p) > f_most) {
        f_most = friction(p);
        most = &p;
      }
    ASSERT_NE(most, nullptr) << "no manifold with friction above 2e-3 kg m/s";
    const Patch p = *most;
    const Result r = planted_jt3("reversed", p, [&](std::size_t, const std::array<double, 3>&, double* j) {
      for (int k = 0; k < 3; ++k) j[k] = -j[k];
    });
    for (int i : {p.a, p.b})
      if (layout_.dynamic(i)) expect_caught(r, "momentum-balance", p.f, i, ": m (v' - v)");
  }
  // A row carrying friction dropped from a manifold.
  for (const Patch& p : all) {
    std::size_t pick = p.r1;
    for (std::size_t r = p.r0; r < p.r1 && p.r1 - p.r0 >= 2 && pick == p.r1; ++r) {
      const auto j = vec(jt3, r);
      if (std::sqrt(j[0] * j[0] + j[1] * j[1] + j[2] * j[2]) > 1e-3 && layout_.jn.v[r] > 1e-3) pick = r;
    }
    if (pick == p.r1) continue;
    expect_caught(dropped_row(p.f, pick), "momentum-balance", p.f, layout_.dynamic(p.a) ? p.a : p.b, ": m (v' - v)");
    break;
  }
  std::cout << GetParam().scene << ": cone faults on frame " << cone.f << " pair (" << cone.a << ", " << cone.b
            << ") (" << cone.r1 - cone.r0 << " rows); reversed friction " << reversed << "\n";
}

INSTANTIATE_TEST_SUITE_P(Scenes, BulletFriction,
                         ::testing::Values(Case{"rot-stack-10", 120}, Case{"rot-drop-220", 120},
                                           Case{"rot-pile-1000", 60}),
                         [](const ::testing::TestParamInfo<Case>& i) {
                           std::string s = i.param.scene;
                           for (char& ch : s)
                             if (ch == '-') ch = '_';
                           return s;
                         });

}  // namespace

}  // namespace octocd_test_cli_bullet_balance
