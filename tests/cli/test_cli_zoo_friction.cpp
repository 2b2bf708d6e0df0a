// Issue 30 item 7, engines unlike octocd's, written here as small plain C++ engines that
// write version 2 traces (octocd's TraceWriter, the same file an outside engine writes
// from docs/trace-format.md) and are judged by `octocd validate --trace-in`:
//  (b) two friction directions with a pyramid: a box sliding down a 30 deg slope on a
//      4-row manifold, its friction directions 45 deg from the slope's fall line;
//  (e) a conservative broadphase: every pair a candidate (a bounding-sphere or fattened
//      box pair cache gives extras).
// The engine is exact by construction: each step the normal impulses cancel gravity's
// normal part, friction acts at the box's 4 bottom corners, the normal impulses are shared
// between the front and back rows so that friction turns nothing (w stays 0), and the
// velocity and position follow the impulses (semi-implicit Euler). Each clean engine
// passes every physics row (exit 0); each planted fault exits 3 naming frame and pair:
// the unscaled pyramid (sqrt(2) mu jn), a friction impulse 1.2x the cone, friction
// reversed on the sliding box.
#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <string>
#include <vector>

#include "support/cli_run.hpp"
#include "octocd/engine.hpp"
#include "octocd/pose.hpp"
#include "octocd/scene.hpp"
#include "octocd/trace.hpp"
#include "octocd/world.hpp"

// This file's own names (its tests compile in unity batches with the folder's other files).
namespace octocd_test_cli_zoo_friction {

namespace fs = std::filesystem;
using namespace octocd;
using octocd::test::Result;
using octocd::test::run_octocd;

namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kTheta = 30.0 * kPi / 180.0;  // slope angle
constexpr double kMu = 0.3;                     // < tan 30 deg: the box slides
constexpr double kHalf = 0.1;                   // the box's half side (m)
constexpr double kDepth = 5e-4;                 // the box sinks this far into the slope (m)
constexpr int kFrames = 20;

/// The scene: a static slope (a box of half extents 1 x 0.1 x 1 turned 30 deg about z), a
/// 1 kg cube of half side 0.1 on it, a static box far away (a pair only a conservative
/// broadphase lists).
std::string scene_text() {
  return R"({"name": "zoo-slope", "rotation": true, "dt": 0.001, "frames": 20, "walls": "none",
    "gravity": [0, -9.81, 0], "domain": {"min": [-3, -3, -3], "max": [3, 3, 3]},
    "response": {"mu_static": 0.3, "mu_kinetic": 0.3, "restitution": 0.0},
    "groups": [
      {"name": "slope", "shape": {"box": [1.0, 0.1, 1.0]}, "count": 1, "mass": 0, "positions": [[0, 0, 0]],
       "orientation": {"axis": [0, 0, 1], "angle_deg": 30}},
      {"name": "box", "shape": {"box": [0.1, 0.1, 0.1]}, "count": 1, "mass": 1.0, "positions": [[0, 0.3, 0]],
       "orientation": {"axis": [0, 0, 1], "angle_deg": 30}},
      {"name": "far", "shape": {"box": [0.1, 0.1, 0.1]}, "count": 1, "mass": 0, "positions": [[2, 2, 2]]}
    ]})";
}

/// What the engine does with friction (the planted faults are engines too).
enum class Friction {
  PyramidScaled,  ///< two directions, each clamped to mu jn / sqrt(2): inside the cone
  Pyramid,        ///< two directions, each clamped to mu jn: sqrt(2) mu jn on the diagonal
  Cone12,         ///< the Coulomb impulse x 1.2
  Reversed,       ///< the Coulomb impulse along the sliding
};

struct Options {
  Friction friction = Friction::PyramidScaled;
  bool all_pairs = false;  // (e) every pair a candidate
};

/// Runs the slope engine and writes its version 2 trace to `path`.
void run_slope_engine(const std::string& path, const Options& o) {
  const std::string text = scene_text();
  const auto model = build_model(parse_scene(text, "zoo slope"));
  const std::size_t n = model->bodies.size();
  const double dt = 0.001, g = 9.81, m = 1.0;
  const Quat q = axis_angle({0, 0, 1}, float(kTheta));
  // Slope frame: normal n (its local +y), fall line u (down the slope), z across it.
  const double nx = -std::sin(kTheta), ny = std::cos(kTheta);
  const double ux = -std::cos(kTheta), uy = -std::sin(kTheta);
  // The engine's two friction directions: 45 deg from the fall line, in the slope plane.
  const double s2 = std::sqrt(0.5);
  const double t1[3] = {s2 * ux, s2 * uy, s2}, t2[3] = {s2 * ux, s2 * uy, -s2};
  // The box's centre: on the slope's top face (0.1 along n), sunk by kDepth, 0.3 m up the fall line.
  double x[3] = {(0.1 + kHalf - kDepth) * nx - 0.3 * ux, (0.1 + kHalf - kDepth) * ny - 0.3 * uy, 0.0};
  double v[3] = {0.5 * ux, 0.5 * uy, 0.0};  // sliding down at 0.5 m/s

  TraceMetadata meta;
  meta.scene_name = "zoo-slope";
  meta.scene_json = text;
  meta.engine = "zoo-pyramid";
  meta.broadphase = o.all_pairs ? "all-pairs" : "exact";
  meta.midphase = "none";
  meta.dt = dt;
  meta.state_every = 1;
  TraceBodies tb;
  for (std::size_t i = 0; i < n; ++i) {
    tb.shape_id.push_back(model->bodies[i].shape);
    tb.inverse_mass.push_back(model->initial.w[i]);
    tb.local_aabb.push_back(model->local_box(i));
    tb.group.push_back(model->bodies[i].group);
  }
  for (const Shape& s : model->shapes) tb.shape_names.push_back(s.name);
  TraceOptions topt;
  topt.state_every = 1;
  topt.contacts = true;
  RotationTraits tr;
  const float inertia = float(m * (2 * kHalf) * (2 * kHalf) / 6.0);
  tr.inertia.assign(n, {});
  tr.inertia[1] = {inertia, 0, 0, 0, inertia, 0, 0, 0, inertia};
  tr.mu = float(kMu);
  tr.restitution = 0.0f;
  tr.contact_margin = 0.001f;
  tr.jt3 = true;
  topt.v2 = tr;
  topt.gravity = Vec3{0.0f, -9.81f, 0.0f};
  TraceWriter writer(path, meta, tb, topt);

  BodyState st;
  const Vec3 far{2, 2, 2};
  auto fill = [&](BodyState& s) {
    s.x = {Vec3{0, 0, 0}, Vec3{float(x[0]), float(x[1]), float(x[2])}, far};
    s.v = {Vec3{}, Vec3{float(v[0]), float(v[1]), float(v[2])}, Vec3{}};
    s.w = {0.0f, 1.0f, 0.0f};
    s.q = {q, q, Quat{}};
    s.omega = {Vec3{}, Vec3{}, Vec3{}};
  };
  fill(st);
  writer.append_state(0, st);
  for (int f = 1; f <= kFrames; ++f) {
    FrameRecord rec;
    rec.frame = f;
    rec.manifolds = true;
    rec.has_points = true;
    rec.has_contact_terms = false;
    const BodyState pre = st;
    for (std::size_t i = 0; i < n; ++i)
      rec.aabbs.push_back(posed_box_aabb(model->local_box(i), Pose{pre.x[i], pre.q[i]}));
    rec.pairs = {{0, 1}};
    if (o.all_pairs) rec.pairs = {{0, 1}, {0, 2}, {1, 2}};
    rec.has_pairs = true;
    // Impulses of the step: the normal part of gravity cancelled, friction on the sliding.
    const double vg[3] = {v[0], v[1] - g * dt, v[2]};
    const double jn = m * g * std::cos(kTheta) * dt;  // total normal impulse
    const double vt[3] = {vg[0] - (vg[0] * nx + vg[1] * ny) * nx, vg[1] - (vg[0] * nx + vg[1] * ny) * ny, vg[2]};
    const double speed = std::sqrt(vt[0] * vt[0] + vt[1] * vt[1] + vt[2] * vt[2]);
    double jt[3] = {0, 0, 0};  // total friction impulse on the box
    if (o.friction == Friction::Pyramid || o.friction == Friction::PyramidScaled) {
      const double cap = (o.friction == Friction::Pyramid ? 1.0 : s2) * kMu * jn;
      for (const double* t : {t1, t2}) {
        const double along = vt[0] * t[0] + vt[1] * t[1] + vt[2] * t[2];
        const double lambda = -std::copysign(std::min(cap, m * std::fabs(along)), along);
        for (int k = 0; k < 3; ++k) jt[k] += lambda * t[k];
      }
    } else {
      const double scale = (o.friction == Friction::Cone12 ? 1.2 : o.friction == Friction::Reversed ? -1.0 : 1.0);
      for (int k = 0; k < 3; ++k) jt[k] = -scale * kMu * jn * vt[k] / speed;
    }
    // Rows: the box's 4 bottom corners. Friction acts kHalf below the centre; the front
    // rows (down the fall line, kHalf ahead of it) carry f/4 more normal impulse and the
    // back rows f/4 less, f the friction against the fall line, so the torques cancel.
    const double f_along = -(jt[0] * ux + jt[1] * uy);  // friction's magnitude against the fall line
    for (int cx : {-1, 1})
      for (int cz : {-1, 1}) {
        const Vec3 corner = to_world(Pose{pre.x[1], q}, Vec3{float(cx * kHalf), float(-kHalf), float(cz * kHalf)});
        // Local +x is -u: a corner with cx = -1 lies down the fall line (the front).
        const double front = cx < 0 ? 1.0 : -1.0;
        ContactRecord c;
        c.pair = {0, 1};
        c.normal = Vec3{float(-nx), float(-ny), 0.0f};  // from B (the box) to A (the slope)
        c.depth = float(kDepth);
        c.point = corner;
        c.jn = float(jn / 4 + front * f_along / 4);
        c.jt = 0.0f;
        rec.contacts.push_back(c);
        // On A (the slope): minus the box's.
        rec.jt3.push_back(Vec3{float(-jt[0] / 4), float(-jt[1] / 4), float(-jt[2] / 4)});
      }
    // The box's step.
    for (int k = 0; k < 3; ++k) v[k] = vg[k] + (jn * (k == 0 ? nx : k == 1 ? ny : 0.0) + jt[k]) / m;
    for (int k = 0; k < 3; ++k) x[k] += v[k] * dt;
    fill(st);
    rec.x_pre = pre.x;
    rec.v_pre = pre.v;
    rec.x_post = st.x;
    rec.v_post = st.v;
    rec.q_pre = pre.q;
    rec.q_post = st.q;
    rec.w_pre = pre.omega;
    rec.w_post = st.omega;
    FrameMetrics fm;
    fm.frame = f;
    writer.append_frame_v2(fm, st, rec);
  }
  writer.close();
}

class ZooFriction : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("octocd-zoo-" + std::to_string(::getpid()) + "-" +
                                        ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  Result judge(const Options& o, const std::string& name) {
    const std::string path = (dir_ / (name + ".h5")).string();
    run_slope_engine(path, o);
    return run_octocd("validate --trace-in " + path);
  }
  fs::path dir_;
};

/// The physics row's verdict in the printed table.
std::string verdict(const Result& r, const std::string& name) {
  const std::size_t at = r.output.find("\nphysics  " + name + " ");
  if (at == std::string::npos) return "missing";
  const std::string line = r.output.substr(at + 1, r.output.find('\n', at + 1) - at - 1);
  for (const char* v : {"pass", "FAIL", "n/a"})
    if (line.find(std::string(" ") + v + " ") != std::string::npos) return v;
  return "?";
}

void expect_clean(const Result& r) {
  EXPECT_EQ(r.code, 0) << r.output;
  for (const char* row : {"broadphase-completeness", "contact-completeness", "contact-geometry", "penetration",
                          "friction"})
    EXPECT_EQ(verdict(r, row), "pass") << row << "\n" << r.output;
}

void expect_friction_caught(const Result& r, const std::vector<std::string>& fragments) {
  EXPECT_EQ(r.code, 3) << r.output;
  EXPECT_EQ(verdict(r, "friction"), "FAIL") << r.output;
  for (const std::string& f : fragments) EXPECT_NE(r.output.find(f), std::string::npos) << f << "\n" << r.output;
}

}  // namespace

// (b) A pyramid of two friction directions scaled to mu jn / sqrt(2) each stays inside
// the cone: every physics row passes, the friction judged on jt3 per pair (4 rows).
TEST_F(ZooFriction, ScaledPyramidPassesEveryPhysicsRow) {
  const Result r = judge({}, "pyramid-scaled");
  expect_clean(r);
  EXPECT_NE(r.output.find("rule jt3 on 20 pairs"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("reference: SAT on"), std::string::npos) << r.output;
}

// (e) A conservative broadphase (every pair a candidate) passes; extras are a figure.
TEST_F(ZooFriction, ConservativeBroadphasePasses) {
  Options o;
  o.all_pairs = true;
  const Result r = judge(o, "all-pairs");
  expect_clean(r);
  EXPECT_NE(r.output.find("candidates per true pair"), std::string::npos) << r.output;
}

// The unscaled pyramid: each direction clamped to mu jn gives sqrt(2) mu jn on the
// diagonal (here the fall line); the per-pair cone on jt3 catches it.
TEST_F(ZooFriction, UnscaledPyramidIsSqrt2TimesTheCone) {
  Options o;
  o.friction = Friction::Pyramid;
  expect_friction_caught(judge(o, "pyramid"), {"frame 1: pair (0, 1)", "1.414 x the cone", "[rule: jt3]"});
}

TEST_F(ZooFriction, FrictionOnePointTwoTimesTheConeIsCaught) {
  Options o;
  o.friction = Friction::Cone12;
  expect_friction_caught(judge(o, "cone12"), {"frame 1: pair (0, 1)", "1.2 x the cone", "(sums over its 4 rows)"});
}

// Friction reversed on the sliding box (a 4-row manifold): it pushes the contact points
// along their sliding before, with the normal impulses and after the step.
TEST_F(ZooFriction, ReversedFrictionOnAFourRowManifoldIsCaught) {
  Options o;
  o.friction = Friction::Reversed;
  expect_friction_caught(judge(o, "reversed"), {"frame 1: pair (0, 1) (4 rows)", "pushes the contact points along "
                                                                                   "their sliding",
                                                "[rule: jt3]"});
}

}  // namespace octocd_test_cli_zoo_friction
