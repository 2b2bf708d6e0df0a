// octocd::DartWorld (`--engine dart`, reference/dart/): its settings against DART's own
// defaults, free fall against DART's semi-implicit Euler, a free spin against angular
// momentum, a resting box against m g dt read from DART's own contact forces, the sign of
// its contact normals, a recorded trace read back row for row, and recorded runs judged by
// the physics tier. Skipped when this octocd is built without DART.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <unistd.h>
#include <vector>

#include "octocd/error.hpp"
#include "octocd/external.hpp"
#include "octocd/scene.hpp"
#include "octocd/trace.hpp"
#if OCTOCD_HAVE_DART
#include <dart/collision/CollisionObject.hpp>
#include <dart/collision/CollisionResult.hpp>
#include <dart/collision/fcl/FCLCollisionDetector.hpp>
#include <dart/constraint/ConstraintSolver.hpp>
#include <dart/dynamics/BodyNode.hpp>
#include <dart/dynamics/BoxShape.hpp>
#include <dart/dynamics/FreeJoint.hpp>
#include <dart/dynamics/MeshShape.hpp>
#include <dart/dynamics/ShapeNode.hpp>
#include <dart/dynamics/Skeleton.hpp>
#include <dart/dynamics/WeldJoint.hpp>
#include <dart/simulation/World.hpp>

#include <fstream>
#include <map>
#include <set>

#include "octocd/dart_world.hpp"
#endif

// This file's own names (its tests compile in unity batches with the folder's other files).
namespace octocd_test_dart_world {

using namespace octocd;

#if OCTOCD_HAVE_DART

namespace {

std::string scene_path(const std::string& name) {
  const char* root = std::getenv("OCTOCD_SOURCE_DIR");
  return std::string(root ? root : ".") + "/datasets/scenes/" + name + ".json";
}

/// World angular momentum R I_b R^T w (I_b row-major, body frame).
std::array<double, 3> angular_momentum(const Quat& q, const Vec3& w, const std::array<float, 9>& ib) {
  const double qw = q.w, x = q.x, y = q.y, z = q.z;
  const double r[3][3] = {{1 - 2 * (y * y + z * z), 2 * (x * y - qw * z), 2 * (x * z + qw * y)},
                          {2 * (x * y + qw * z), 1 - 2 * (x * x + z * z), 2 * (y * z - qw * x)},
                          {2 * (x * z - qw * y), 2 * (y * z + qw * x), 1 - 2 * (x * x + y * y)}};
  const double wv[3] = {w.x, w.y, w.z};
  double wl[3], lb[3];
  for (int i = 0; i < 3; ++i) wl[i] = r[0][i] * wv[0] + r[1][i] * wv[1] + r[2][i] * wv[2];  // R^T w
  for (int i = 0; i < 3; ++i) lb[i] = ib[3 * i] * wl[0] + ib[3 * i + 1] * wl[1] + ib[3 * i + 2] * wl[2];
  std::array<double, 3> l{};
  for (int i = 0; i < 3; ++i) l[i] = r[i][0] * lb[0] + r[i][1] * lb[1] + r[i][2] * lb[2];
  return l;
}

double norm3(const std::array<double, 3>& a) { return std::sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2]); }

/// A box (half extents 0.1 m, 1 kg) at height `y` above a static floor (4 x 0.2 x 4 m,
/// top at y = 0). `box_first`: the box is body 0 and the floor body 1; otherwise the
/// scene's generated floor wall is body 0 and the box body 1.
Scene box_on_floor(bool box_first, float y, float vx = 0.0f) {
  const std::string box = R"({"name": "box", "shape": {"box": [0.1, 0.1, 0.1]}, "count": 1, "mass": 1.0,
      "positions": [[0.0, )" + std::to_string(y) + R"(, 0.0]], "velocity": {"type": "fixed", "value": [)" +
                          std::to_string(vx) + R"(, 0.0, 0.0]}})";
  const std::string floor = R"({"name": "ground", "shape": {"box": [2.0, 0.1, 2.0]}, "count": 1, "mass": 0,
      "positions": [[0.0, -0.1, 0.0]]})";
  const std::string text = R"({"name": "box-on-floor", "domain": {"min": [-2, 0, -2], "max": [2, 2, 2]},
    "rotation": true, "walls": )" + std::string(box_first ? "\"none\"" : "\"floor\"") + R"(,
    "wall_thickness": 0.2, "response": {"mu_kinetic": 0.3, "restitution": 0.0},
    "groups": [)" + box + (box_first ? ", " + floor : std::string()) + "]}";
  return parse_scene(text, "box-on-floor (test)");
}

/// Runs `frames` steps of `engine` into a version 2 trace at `path`, as `octocd run
/// --trace PATH --state-every 1 --contacts` does; keeps every record in `records` when
/// given; returns the contact rows written.
std::uint64_t write_trace(Engine& engine, const std::string& path, int frames,
                          std::vector<FrameRecord>* records = nullptr) {
  std::uint64_t rows = 0;
  TraceOptions topt;
  topt.state_every = 1;
  topt.contacts = true;
  engine.set_recording(true);
  topt.v2 = *engine.rotation_traits();
  topt.gravity = engine.scene().gravity;
  TraceWriter trace(path, trace_metadata(engine, 1), trace_bodies(engine), topt);
  trace.append_state(0, engine.state());
  for (int f = 0; f < frames; ++f) {
    const FrameMetrics& m = engine.step();
    trace.append_frame_v2(m, engine.state(), engine.record());
    rows += engine.record().contacts.size();
    if (records) records->push_back(engine.record());
  }
  trace.close();
  return rows;
}

/// The physics tier's verdict on a trace: the names of its failing physics rows ("" all
/// pass), each with its detail.
std::string physics_failures(const std::string& path) {
  ExternalOptions eo;
  eo.threads = 1;
  std::string failed;
  for (const ValidationResult& r : validate_external_trace(path, eo))
    if (r.tier == Tier::Physics && !r.pass) failed += r.name + ": " + r.detail + "\n";
  return failed;
}

/// `x` with 3 significant digits, for RecordProperty.
std::string sci(double x) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.3g", x);
  return buf;
}

std::string temp_trace(const std::string& stem) {
  return (std::filesystem::temp_directory_path() / (stem + "-" + std::to_string(::getpid()) + ".h5")).string();
}

}  // namespace

// DartSettings' defaults are the linked DART's own (ContactConstraint's statics, a fresh
// PgsBoxedLcpSolver::Option); the parser names the key, the value and the allowed range.
TEST(DartSettings, DefaultsAreDartsAndBadValuesAreNamed) {
  const DartSettings ours, darts = dart_library_defaults();
  EXPECT_EQ(ours.erp, darts.erp);
  EXPECT_EQ(ours.max_erv, darts.max_erv);
  EXPECT_EQ(ours.cfm, darts.cfm);
  EXPECT_EQ(ours.iterations, darts.iterations);
  DartSettings s;
  apply_settings(s, {"collision=dart", "boxes=mesh", "lcp=pgs", "iterations=50", "erp=0.2", "max_erv=0.5",
                          "cfm=1e-6", "friction=pyramid", "contacts=5000", "insert=posed"},
                      "--dart");
  EXPECT_EQ(s.collision, DartCollision::Dart);
  EXPECT_EQ(s.boxes, DartFclBoxes::Mesh);
  EXPECT_EQ(s.lcp, DartLcp::Pgs);
  EXPECT_EQ(s.iterations, 50);
  EXPECT_EQ(s.erp, 0.2);
  EXPECT_EQ(s.max_erv, 0.5);
  EXPECT_EQ(s.cfm, 1e-6);
  EXPECT_EQ(s.friction, DartFriction::Pyramid);
  EXPECT_EQ(s.max_contacts, 5000);
  EXPECT_EQ(s.insert, DartFclInsert::Posed);
  EXPECT_EQ(DartSettings().insert, DartFclInsert::Origin);
  auto error = [](const std::string& item) {
    DartSettings t;
    try {
      apply_settings(t, {item}, "--dart");
    } catch (const InputError& e) {
      return std::string(e.what());
    }
    return std::string();
  };
  EXPECT_EQ(error("erp=1.5"), "--dart: erp='1.5' is not allowed; allowed: a decimal number in [0, 1] "
                              "(ContactConstraint::setErrorReductionParameter; DART's default 0.01)");
  EXPECT_NE(error("cfm=0").find("cfm='0' is not allowed; allowed: a decimal number in [1e-9, 1]"), std::string::npos);
  EXPECT_NE(error("iterations=0").find("allowed: an integer in [1, 10000]"), std::string::npos);
  EXPECT_NE(error("collision=bullet").find("collision='bullet' is not allowed; allowed: fcl"), std::string::npos);
  EXPECT_NE(error("lcp=lemke").find("allowed: dantzig"), std::string::npos);
  EXPECT_EQ(error("solver=pgs"), "--dart: unknown dart setting 'solver'; allowed: collision, boxes, insert, lcp, iterations, "
                                 "erp, max_erv, cfm, friction, contacts (docs/engines.md)");
  EXPECT_NE(error("erp").find("'erp' is not KEY=VALUE"), std::string::npos);
  // A world sets DART's process-wide contact parameters only while it steps.
  const auto model = build_model(box_on_floor(true, 0.1005f));
  DartSettings stiff;
  stiff.erp = 0.5;
  DartWorld dart(model, model->initial, stiff);
  dart.step();
  EXPECT_EQ(dart_library_defaults().erp, darts.erp);
}

// DART's own collision detector has no mesh shape: a mesh scene with collision=dart is
// refused naming the body and the setting that takes it.
TEST(DartSettings, DartDetectorRefusesMeshes) {
  const Scene scene = parse_scene(R"({"name": "ball", "domain": {"min": [-1, -1, -1], "max": [1, 1, 1]},
    "walls": "none", "rotation": true,
    "groups": [{"name": "ball", "shape": {"icosphere": {"radius": 0.3, "subdivisions": 1}}, "count": 1,
                "mass": 1, "positions": [[0, 0, 0]]}]})",
                                  "ball (test)");
  const auto model = build_model(scene);
  DartSettings s;
  s.collision = DartCollision::Dart;
  try {
    DartWorld dart(model, model->initial, s);
    ADD_FAILURE() << "a mesh scene was accepted by DART's own detector";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("body 0 (icosphere-r0.3-s1) is a mesh"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("allowed: collision=fcl"), std::string::npos) << e.what();
  }
}

// A lone box falling with an initial velocity follows DART's semi-implicit Euler exactly:
// v_n = v_0 + n g dt, x_n = x_0 + n dt v_0 + g dt^2 n (n + 1) / 2 (x += dt v after v +=
// dt g), to float32 rounding of the stored state (positions up to 5 m: 1e-6 m); the
// explicit form (n (n - 1) / 2) is 4.9 mm away after 1000 steps.
TEST(DartWorld, FreeFallFollowsSemiImplicitEuler) {
  const Scene scene = parse_scene(R"({"name": "fall", "domain": {"min": [-10, -10, -10], "max": [10, 10, 10]},
    "walls": "none", "rotation": true,
    "groups": [{"name": "b", "shape": {"box": [0.1, 0.2, 0.3]}, "count": 1, "mass": 2.0,
                "positions": [[0.5, 1.0, -0.5]], "velocity": {"type": "fixed", "value": [0.3, 2.0, -0.1]}}]})",
                                  "fall (test)");
  const auto model = build_model(scene);
  DartWorld dart(model, model->initial);
  const double dt = scene.dt, g = scene.gravity.y;
  const int steps = 1000;
  double worst = 0.0;
  for (int n = 1; n <= steps; ++n) {
    dart.step();
    const Vec3 x = dart.state().x[0], v = dart.state().v[0];
    const double xn[3] = {0.5 + n * dt * 0.3, 1.0 + n * dt * 2.0 + g * dt * dt * n * (n + 1) / 2.0, -0.5 - n * dt * 0.1};
    const double vn[3] = {0.3, 2.0 + n * g * dt, -0.1};
    for (int k = 0; k < 3; ++k) {
      worst = std::max(worst, std::fabs(x[k] - xn[k]));
      ASSERT_NEAR(v[k], vn[k], 2e-6) << "step " << n << " axis " << k;
    }
    ASSERT_EQ(dart.last_metrics().contacts, 0u);
  }
  EXPECT_LT(worst, 1e-6) << "worst position error " << worst << " m";
  const double explicit_gap = std::fabs(g) * dt * dt * steps;  // n(n+1)/2 - n(n-1)/2 = n
  EXPECT_GT(explicit_gap, 1000 * worst);
  RecordProperty("worst_position_error_m", sci(worst));
}

// Torque-free spin of a box with three different moments of inertia (no gravity, no
// contact), spun mostly about y with small x, z parts so it tumbles: DART's free body
// carries the Coriolis term w x I w of its velocity before the step, so the world angular
// momentum R I R^T w stays within 1% over 2 s, while a body keeping its initial w (no
// gyroscopic term) would be off by more than twice that. The body's inertia is the solid
// box's m/12 (b^2 + c^2), ... as DART holds it (BodyNode::getInertia).
TEST(DartWorld, FreeSpinKeepsAngularMomentum) {
  const Scene scene = parse_scene(R"({"name": "spin", "domain": {"min": [-1, -1, -1], "max": [1, 1, 1]},
    "gravity": [0, 0, 0], "walls": "none", "rotation": true,
    "groups": [{"name": "brick", "shape": {"box": [0.3, 0.1, 0.05]}, "count": 1, "mass": 2.0,
                "positions": [[0, 0, 0]], "angular_velocity": [0.2, 6.0, 0.1]}]})",
                                  "spin (test)");
  const auto model = build_model(scene);
  DartWorld dart(model, model->initial);
  const std::array<float, 9> inertia = dart.rotation_traits()->inertia[0];
  EXPECT_NEAR(inertia[0], 2.0 / 12 * (0.2 * 0.2 + 0.1 * 0.1), 1e-7);
  EXPECT_NEAR(inertia[4], 2.0 / 12 * (0.6 * 0.6 + 0.1 * 0.1), 1e-7);
  EXPECT_NEAR(inertia[8], 2.0 / 12 * (0.6 * 0.6 + 0.2 * 0.2), 1e-7);
  const Quat q0 = dart.state().q[0];
  const Vec3 w0 = dart.state().omega[0];
  const std::array<double, 3> l0 = angular_momentum(q0, w0, inertia);
  double worst = 0.0, w_change = 0.0, worst_no_gyro = 0.0;
  const double dt = scene.dt;
  for (int f = 1; f <= 2000; ++f) {
    dart.step();
    const std::array<double, 3> l = angular_momentum(dart.state().q[0], dart.state().omega[0], inertia);
    worst = std::max(worst, norm3({l[0] - l0[0], l[1] - l0[1], l[2] - l0[2]}) / norm3(l0));
    w_change = std::max(w_change, static_cast<double>(length(dart.state().omega[0] - w0)));
    // The same body turning at its initial w for f steps.
    const Quat turned = axis_angle((1.0f / length(w0)) * w0, length(w0) * static_cast<float>(f * dt)) * q0;
    const std::array<double, 3> ln = angular_momentum(turned, w0, inertia);
    worst_no_gyro = std::max(worst_no_gyro, norm3({ln[0] - l0[0], ln[1] - l0[1], ln[2] - l0[2]}) / norm3(l0));
  }
  EXPECT_GT(w_change, 1.0) << "the body must tumble for the test to mean something";
  EXPECT_LT(worst, 0.01);
  EXPECT_GT(worst_no_gyro, 0.02);
  RecordProperty("angular_momentum_drift", sci(worst));
  RecordProperty("angular_momentum_drift_without_gyroscopic", sci(worst_no_gyro));
}

// A box set down on a static floor (its bottom 0.5 mm above) settles: after 0.5 s its
// speed is below 1e-4 m/s, it sinks at most 1 mm into the floor, it stays upright, and
// every step's contact rows carry sum jn = m |g| dt within 1e-4 of it, so over the last
// 0.5 s sum jn = m g T: jn is DART's own Contact::force (the LCP impulse
// ContactConstraint::applyImpulse stores) times dt. Every row's normal points from the
// floor (B) to the box (A) when the box is body 0, from the box to the floor when the
// floor is.
TEST(DartWorld, RestingBoxSettlesAndItsRowsCarryItsWeight) {
  for (bool box_first : {true, false}) {
    SCOPED_TRACE(box_first ? "box is body 0" : "floor is body 0");
    const auto model = build_model(box_on_floor(box_first, 0.1005f));
    DartWorld dart(model, model->initial);
    dart.set_recording(true);
    const std::size_t box = box_first ? 0 : 1, floor = 1 - box;
    const double m = 1.0, g = 9.81, dt = model->scene.dt;
    double worst_balance = 0.0, jn_total = 0.0;
    int counted = 0;
    for (int f = 1; f <= 1000; ++f) {
      dart.step();
      const FrameRecord& r = dart.record();
      double jn = 0.0;
      for (const ContactRecord& c : r.contacts) {
        ASSERT_EQ(c.pair, (Pair{0, 1}));
        const float up = c.pair.a == box ? 1.0f : -1.0f;
        ASSERT_NEAR(c.normal.y, up, 1e-6f) << "frame " << f;
        ASSERT_GE(c.jn, 0.0f);
        jn += c.jn;
      }
      if (f > 500) {
        ASSERT_FALSE(r.contacts.empty()) << "frame " << f;
        worst_balance = std::max(worst_balance, std::fabs(jn - m * g * dt) / (m * g * dt));
        jn_total += jn;
        ++counted;
      }
    }
    const Vec3 x = dart.state().x[box], v = dart.state().v[box];
    const Quat q = dart.state().q[box];
    EXPECT_LT(length(v), 1e-4f);
    EXPECT_GT(x.y - 0.1f, -1e-3f) << "sank " << 0.1f - x.y << " m";
    EXPECT_NEAR(std::fabs(q.w), 1.0f, 1e-6f);
    EXPECT_LT(worst_balance, 1e-4);
    EXPECT_NEAR(jn_total, m * g * dt * counted, 1e-4 * m * g * dt * counted);
    EXPECT_EQ(dart.state().x[floor].y, -0.1f);
    RecordProperty(box_first ? "balance_box_first" : "balance_floor_first", sci(worst_balance));
  }
}

// A box sliding on the floor: its rows' friction opposes the sliding (jt > 0, jt3 against
// the velocity) and stays inside the Coulomb cone of the scene's mu (the inscribed pyramid:
// at most mu jn along each friction direction / sqrt 2).
TEST(DartWorld, SlidingBoxFrictionOpposesTheSlidingInsideTheCone) {
  const auto model = build_model(box_on_floor(true, 0.1f, 1.0f));
  DartWorld dart(model, model->initial);
  dart.set_recording(true);
  int sliding = 0;
  for (int f = 1; f <= 100; ++f) {
    dart.step();
    const FrameRecord& r = dart.record();
    float jn = 0.0f;
    Vec3 jt{};
    for (std::size_t k = 0; k < r.contacts.size(); ++k) {
      jn += r.contacts[k].jn;
      jt += r.jt3[k];
    }
    if (r.contacts.empty() || r.v_post[0].x < 0.05f) continue;
    ++sliding;
    EXPECT_LT(jt.x, 0.0f) << "frame " << f;
    EXPECT_LE(length(jt), 0.3f * jn * 1.0001f) << "frame " << f;
  }
  EXPECT_GT(sliding, 20);
}

// A recorded run read back from its trace (ExternalTrace, as `validate --trace-in`
// reads it) gives every frame's states and contact rows as recorded: the same pairs,
// normals, depths, points, jn and jt3 to float.
// insert=posed builds FCL's tree from the bodies' AABBs instead of n leaves at the origin.
// Until the first contact both runs integrate free bodies alike; that frame collides the
// same poses, so it finds the same contacts (pair, normal, point, depth), in FCL's order
// for the other tree: the rows are compared as sorted sets.
TEST(DartWorld, PosedInsertFindsTheSameFirstContacts) {
  const auto model = build_model(load_scene(scene_path("rot-stack-10")));
  auto records_of = [&](DartFclInsert insert) {
    DartSettings s;
    s.insert = insert;
    DartWorld dart(model, model->initial, s);
    std::vector<FrameRecord> records;
    const std::string path = temp_trace(std::string("dart-insert-") + dart_fcl_insert_name(insert));
    write_trace(dart, path, 40, &records);
    std::filesystem::remove(path);
    return records;
  };
  auto sorted_rows = [](const FrameRecord& r) {
    std::vector<std::array<float, 9>> rows;
    for (const ContactRecord& c : r.contacts)
      rows.push_back({static_cast<float>(c.pair.a), static_cast<float>(c.pair.b), c.normal.x, c.normal.y, c.normal.z,
                      c.point.x, c.point.y, c.point.z, c.depth});
    std::sort(rows.begin(), rows.end());
    return rows;
  };
  const auto origin = records_of(DartFclInsert::Origin), posed = records_of(DartFclInsert::Posed);
  std::size_t f = 0;
  while (f < origin.size() && origin[f].contacts.empty()) {
    ASSERT_TRUE(posed[f].contacts.empty()) << "frame " << f + 1;
    ++f;
  }
  ASSERT_LT(f, origin.size()) << "no contact in 40 frames";
  EXPECT_GE(origin[f].contacts.size(), 4u);
  EXPECT_EQ(sorted_rows(origin[f]), sorted_rows(posed[f])) << "frame " << f + 1;
}

TEST(DartWorld, TraceRoundTrips) {
  const Scene scene = load_scene(scene_path("rot-stack-10"));
  const auto model = build_model(scene);
  DartWorld dart(model, model->initial);
  const std::string path = temp_trace("dart-roundtrip");
  std::vector<FrameRecord> records;
  EXPECT_GT(write_trace(dart, path, 120, &records), 1000u);
  ExternalTrace trace(path);
  ASSERT_EQ(trace.info().frames, 120);
  EXPECT_EQ(trace.info().version, 2);
  EXPECT_TRUE(trace.info().has_rotation);
  EXPECT_TRUE(trace.info().has_points);
  for (std::int64_t f = 1; f <= 120; ++f) {
    const FrameRecord got = trace.frame(f);
    const FrameRecord& want = records[static_cast<std::size_t>(f - 1)];
    ASSERT_EQ(got.contacts.size(), want.contacts.size()) << "frame " << f;
    for (std::size_t i = 0; i < want.x_post.size(); ++i) {
      ASSERT_EQ(got.x_post[i], want.x_post[i]) << "frame " << f << " body " << i;
      ASSERT_EQ(got.w_post[i], want.w_post[i]) << "frame " << f << " body " << i;
    }
    for (std::size_t k = 0; k < want.contacts.size(); ++k) {
      const ContactRecord &a = got.contacts[k], &b = want.contacts[k];
      ASSERT_EQ(a.pair, b.pair);
      ASSERT_EQ(a.normal, b.normal);
      ASSERT_EQ(a.point, b.point);
      ASSERT_EQ(a.depth, b.depth);
      ASSERT_EQ(a.jn, b.jn);
      ASSERT_EQ(got.jt3[k], want.jt3[k]);
    }
  }
  std::filesystem::remove(path);
}

// A recorded stack of ten boxes (rot-stack-10, 300 frames: the stack settles under FCL's
// box-box manifolds) passes every row of the physics tier that judges something; a tilted
// box dropped onto a static icosphere collided as its triangle mesh (MeshShape, declared
// "mesh") passes every row but two, both on FCL's box-against-mesh normals
// (DartEngineFault.FclPrimitiveBoxAgainstAMeshGetsNormalsPointingTheWrongWay):
// contact-geometry, and impulse-feasibility on exactly the steps where DART's own rows
// (CollisionResult's contacts, Contact::force dt) pull the box into the ball: their sum on
// the box points inwards along the ball's radius at the contact (37 of 400 steps).
TEST(DartWorld, RecordedRunsPassThePhysicsTier) {
  {
    const Scene scene = load_scene(scene_path("rot-stack-10"));
    const auto model = build_model(scene);
    DartWorld dart(model, model->initial);
    EXPECT_EQ(dart.rotation_traits()->body_collision_shape[1], "box");
    const std::string path = temp_trace("dart-stack");
    EXPECT_GT(write_trace(dart, path, 300), 3000u);
    EXPECT_EQ(physics_failures(path), "");
    std::filesystem::remove(path);
  }
  {
    const Scene scene = parse_scene(R"({"name": "box-on-ball", "domain": {"min": [-1, -1, -1], "max": [1, 2, 1]},
      "walls": "none", "rotation": true, "response": {"mu_kinetic": 0.5, "restitution": 0.2},
      "groups": [{"name": "ball", "shape": {"icosphere": {"radius": 0.3, "subdivisions": 2}}, "count": 1,
                  "mass": 0, "positions": [[0, 0, 0]]},
                 {"name": "box", "shape": {"box": [0.05, 0.05, 0.05]}, "count": 1, "mass": 1.0,
                  "positions": [[0.05, 0.4, 0.02]], "orientation": {"axis": [1, 0, 1], "angle_deg": 30}}]})",
                                    "box-on-ball (test)");
    const auto model = build_model(scene);
    DartWorld dart(model, model->initial);
    EXPECT_EQ(dart.rotation_traits()->body_collision_shape[0], "mesh");
    const std::string path = temp_trace("dart-mesh");
    std::vector<FrameRecord> records;
    EXPECT_GT(write_trace(dart, path, 400, &records), 100u);
    EXPECT_NE(dart.collision_geometry().find("triangle meshes"), std::string::npos) << dart.collision_geometry();
    // The steps on which DART's own rows pull the box (body 1) towards the ball's centre.
    std::set<std::int64_t> pulled;
    for (const FrameRecord& r : records) {
      if (r.contacts.empty()) continue;
      double inward = 0.0;  // the rows' impulse on the box along the ball's outward radius
      for (std::size_t k = 0; k < r.contacts.size(); ++k) {
        const ContactRecord& c = r.contacts[k];
        ASSERT_EQ(c.pair, (Pair{0, 1}));
        const Vec3 on_a = c.jn * c.normal + r.jt3[k];  // on the ball (A); the box gets minus it
        inward += dot(on_a, c.point) / length(c.point);
      }
      if (inward > 1e-6) pulled.insert(r.frame);
    }
    EXPECT_GT(pulled.size(), 10u);
    // Only contact-geometry and impulse-feasibility fail: FCL's box-against-mesh normals.
    ExternalOptions eo;
    eo.threads = 1;
    std::string failed;
    for (const ValidationResult& r : validate_external_trace(path, eo)) {
      if (r.tier != Tier::Physics || r.pass) continue;
      failed += r.name + " ";
      if (r.name != "impulse-feasibility") continue;
      ASSERT_EQ(r.causes.size(), 1u);
      // Every infeasible step is one where DART pulls, named by its first examples.
      EXPECT_EQ(r.causes[0].count, pulled.size()) << r.detail;
      for (const ValidationExample& e : r.causes[0].examples) {
        EXPECT_EQ(e.item, "body 1");
        EXPECT_EQ(pulled.count(e.frame), 1u) << e.text;
      }
      RecordProperty("pulled_steps", static_cast<int>(pulled.size()));
    }
    EXPECT_EQ(failed, "contact-geometry impulse-feasibility ");
    std::filesystem::remove(path);
  }
}

// ---- Faults of DART itself, shown with plain DART calls (no octocd code) ------------------

namespace {

namespace dd = dart::dynamics;

/// A plain DART world for the witnesses: gravity -9.81 y, dt 1 ms, FCL with boxes as
/// `boxes` (fcl::Box or a 12-triangle mesh), DART's default constraint solver.
dart::simulation::WorldPtr plain_world(dart::collision::FCLCollisionDetector::PrimitiveShape boxes) {
  auto world = dart::simulation::World::create("witness");
  world->setGravity(Eigen::Vector3d(0, -9.81, 0));
  world->setTimeStep(0.001);
  auto fcl = dart::collision::FCLCollisionDetector::create();
  fcl->setPrimitiveShapeType(boxes);
  world->getConstraintSolver()->setCollisionDetector(fcl);
  return world;
}

/// A static body of `shape` at `pose` (a WeldJoint to the world) in `world`.
dd::BodyNode* add_static(const dart::simulation::WorldPtr& world, const dd::ShapePtr& shape,
                         const Eigen::Isometry3d& pose, double mu) {
  auto skel = dd::Skeleton::create("floor");
  dd::WeldJoint::Properties jp;
  jp.mT_ParentBodyToJoint = pose;
  auto pair = skel->createJointAndBodyNodePair<dd::WeldJoint>(nullptr, jp);
  pair.second->createShapeNodeWith<dd::CollisionAspect, dd::DynamicsAspect>(shape)->getDynamicsAspect()
      ->setFrictionCoeff(mu);
  world->addSkeleton(skel);
  return pair.second;
}

/// A free 1 kg cube of side 0.1 m (BoxShape) at `pose` moving at `v` in `world`.
dd::BodyNode* add_cube(const dart::simulation::WorldPtr& world, const Eigen::Isometry3d& pose,
                       const Eigen::Vector3d& v, double mu) {
  auto skel = dd::Skeleton::create("cube");
  auto pair = skel->createJointAndBodyNodePair<dd::FreeJoint>();
  auto box = std::make_shared<dd::BoxShape>(Eigen::Vector3d(0.1, 0.1, 0.1));
  pair.second->createShapeNodeWith<dd::CollisionAspect, dd::DynamicsAspect>(box)->getDynamicsAspect()
      ->setFrictionCoeff(mu);
  pair.second->setInertia(dd::Inertia(1.0, Eigen::Vector3d::Zero(), box->computeInertia(1.0)));
  dd::FreeJoint::setTransformOf(pair.first, pose);
  pair.first->setLinearVelocity(v);
  world->addSkeleton(skel);
  return pair.second;
}

}  // namespace

// DART documents collision::Contact::normal as pointing from object 2's body to object
// 1's, and so it does for two fcl::Box (rot-stack-10 passes contact-geometry). A box
// against a MeshShape (an FCL BVH of triangles) breaks it in both of FCLCollisionDetector's
// box modes: a cube set down sliding on a static floor given as a MeshShape (a 4 x 0.2 x
// 4 m box of 12 triangles, MeshShape::loadMesh of an OBJ) gets rows whose normal points
// from object 1's body to object 2's. With PRIMITIVE boxes the normal is always the
// cube-into-floor direction whichever object FCL names first (measured: 32% of 580 rows
// reversed); with MESH boxes (DART's own default; a triangle pair's normal) 57% of 2277
// rows. DART's LCP applies its normal impulse along them, pulling the bodies together on
// those rows. Plain DART calls, no octocd code: the physics tier's contact-geometry row
// fails `dart` runs with a box against a mesh (the box walls against the icosphere hulls
// of rot-drop-220 and rot-pile-1000; docs/engines.md, "dart").
TEST(DartEngineFault, FclPrimitiveBoxAgainstAMeshGetsNormalsPointingTheWrongWay) {
  const std::string obj = (std::filesystem::temp_directory_path() /
                           ("dart-floor-" + std::to_string(::getpid()) + ".obj")).string();
  {
    std::ofstream out(obj);
    for (int i = 0; i < 8; ++i)
      out << "v " << ((i & 1) ? 2.0 : -2.0) << " " << ((i & 2) ? 0.1 : -0.1) << " " << ((i & 4) ? 2.0 : -2.0) << "\n";
    // 12 triangles, counter-clockwise seen from outside (1-based indices).
    out << "f 1 2 4\nf 1 4 3\nf 5 7 8\nf 5 8 6\nf 1 5 6\nf 1 6 2\nf 3 4 8\nf 3 8 7\nf 1 3 7\nf 1 7 5\n"
           "f 2 6 8\nf 2 8 4\n";
  }
  auto wrong_share = [&](dart::collision::FCLCollisionDetector::PrimitiveShape boxes, int* rows_seen) {
    auto world = plain_world(boxes);
    const aiScene* floor_mesh = dd::MeshShape::loadMesh(obj);
    EXPECT_NE(floor_mesh, nullptr);
    Eigen::Isometry3d floor_pose = Eigen::Isometry3d::Identity();
    floor_pose.translation() = Eigen::Vector3d(0, -0.1, 0);
    dd::BodyNode* floor =
        add_static(world, std::make_shared<dd::MeshShape>(Eigen::Vector3d::Ones(), floor_mesh), floor_pose, 0.5);
    Eigen::Isometry3d cube_pose = Eigen::Isometry3d::Identity();
    cube_pose.translation() = Eigen::Vector3d(0, 0.0505, 0);
    dd::BodyNode* cube = add_cube(world, cube_pose, Eigen::Vector3d(0.2, 0, 0), 0.5);
    int rows = 0, wrong = 0;
    for (int step = 1; step <= 300; ++step) {
      world->step();
      const dart::collision::CollisionResult& r = world->getLastCollisionResult();
      for (std::size_t k = 0; k < r.getNumContacts(); ++k) {
        const dart::collision::Contact& c = r.getContact(k);
        const dd::BodyNode* b1 = c.collisionObject1->getShapeFrame()->asShapeNode()->getBodyNodePtr().get();
        // From object 2's body to object 1's: up when object 1 is the cube, down when the floor.
        const double expected_y = b1 == cube ? 1.0 : -1.0;
        EXPECT_TRUE(b1 == cube || b1 == floor);
        ++rows;
        if (c.normal.y() * expected_y < -0.5) ++wrong;
      }
    }
    *rows_seen = rows;
    return rows > 0 ? static_cast<double>(wrong) / rows : 0.0;
  };
  int rows_primitive = 0, rows_mesh = 0;
  const double primitive = wrong_share(dart::collision::FCLCollisionDetector::PRIMITIVE, &rows_primitive);
  const double mesh = wrong_share(dart::collision::FCLCollisionDetector::MESH, &rows_mesh);
  std::filesystem::remove(obj);
  EXPECT_GT(rows_primitive, 100);
  EXPECT_GT(primitive, 0.2) << "share of rows whose normal points from object 1's body to object 2's";
  EXPECT_GT(rows_mesh, 100);
  EXPECT_GT(mesh, 0.2) << "share of rows whose normal points from object 1's body to object 2's";
  RecordProperty("wrong_normal_share_primitive", sci(primitive));
  RecordProperty("wrong_normal_share_mesh", sci(mesh));
}

// DART's default constraint solver runs ODE's Dantzig LCP (DantzigBoxedLcpSolver) with
// ContactConstraint's friction rows bounded through findex by the normal row's value
// (|lambda_t| <= mu lambda_n per direction): like ODE's dWorldStep it fixes those bounds
// from the normal impulses solved before it reaches the first friction row and does not
// revisit them when solving friction changes the normal impulses. So DART's own contact
// forces (collision::Contact::force, what ContactConstraint::applyImpulse stores) break the
// Coulomb bound of the final normal force: a cube tilted 30 degrees about (0, 1, 1) set
// down on a box floor while sliding at 1.2 m/s gets rows whose friction exceeds mu times
// their own normal force (mu_shape = mu / sqrt 2 per direction: the friction vector of a
// row may reach mu f_n at the pyramid's corner, no more). Plain DART calls, no octocd
// code: the physics tier's friction row (cone) fails `dart` runs with the Dantzig solver;
// `--dart lcp=pgs` (each friction row clamped by the current normal value) passes it.
TEST(DartEngineFault, DantzigFrictionExceedsTheFinalNormalForce) {
  const double mu = 0.5, mu_shape = mu / std::sqrt(2.0);
  auto world = plain_world(dart::collision::FCLCollisionDetector::PRIMITIVE);
  Eigen::Isometry3d floor_pose = Eigen::Isometry3d::Identity();
  floor_pose.translation() = Eigen::Vector3d(0, -0.1, 0);
  add_static(world, std::make_shared<dd::BoxShape>(Eigen::Vector3d(4, 0.2, 4)), floor_pose, mu_shape);
  Eigen::Isometry3d cube_pose = Eigen::Isometry3d::Identity();
  cube_pose.linear() = Eigen::AngleAxisd(30 * M_PI / 180, Eigen::Vector3d(0, 1, 1).normalized()).toRotationMatrix();
  // The lowest corner 0.5 mm below the floor's top.
  double lowest = 0.0;
  for (int i = 0; i < 8; ++i) {
    const Eigen::Vector3d corner((i & 1) ? 0.05 : -0.05, (i & 2) ? 0.05 : -0.05, (i & 4) ? 0.05 : -0.05);
    lowest = std::min(lowest, (cube_pose.linear() * corner).y());
  }
  cube_pose.translation() = Eigen::Vector3d(0, -lowest - 0.0005, 0);
  add_cube(world, cube_pose, Eigen::Vector3d(1.0, -0.5, 0.7), mu_shape);
  double worst_row = 0.0;
  int steps_over = 0;
  for (int step = 1; step <= 300; ++step) {
    world->step();
    const dart::collision::CollisionResult& r = world->getLastCollisionResult();
    bool over = false;
    for (std::size_t k = 0; k < r.getNumContacts(); ++k) {
      const dart::collision::Contact& c = r.getContact(k);
      const double fn = c.force.dot(c.normal);
      EXPECT_GE(fn, -1e-9);
      const double ft = (c.force - fn * c.normal).norm();
      if (fn > 1e-9) {
        const double ratio = ft / (mu * fn);  // mu = sqrt 2 mu_shape: the pyramid's corner
        worst_row = std::max(worst_row, ratio);
        over = over || ratio > 1.01;
      }
    }
    steps_over += over ? 1 : 0;
  }
  EXPECT_GT(worst_row, 1.1) << "a row's friction over mu times its own final normal force";
  EXPECT_GT(steps_over, 5);
  RecordProperty("worst_row_cone_ratio", sci(worst_row));
  RecordProperty("steps_over", sci(steps_over));
}


namespace {

/// An icosphere of `radius` (an icosahedron subdivided `subdivisions` times, every vertex
/// pushed onto the sphere), written as an OBJ at `path`; returns its vertices.
std::vector<Eigen::Vector3d> write_icosphere_obj(const std::string& path, double radius, int subdivisions) {
  const double t = (1.0 + std::sqrt(5.0)) / 2.0;
  std::vector<Eigen::Vector3d> v = {{-1, t, 0}, {1, t, 0}, {-1, -t, 0}, {1, -t, 0}, {0, -1, t}, {0, 1, t},
                                    {0, -1, -t}, {0, 1, -t}, {t, 0, -1}, {t, 0, 1}, {-t, 0, -1}, {-t, 0, 1}};
  for (Eigen::Vector3d& p : v) p = radius * p.normalized();
  std::vector<std::array<int, 3>> f = {{0, 11, 5}, {0, 5, 1},  {0, 1, 7},   {0, 7, 10}, {0, 10, 11},
                                       {1, 5, 9},  {5, 11, 4}, {11, 10, 2}, {10, 7, 6}, {7, 1, 8},
                                       {3, 9, 4},  {3, 4, 2},  {3, 2, 6},   {3, 6, 8},  {3, 8, 9},
                                       {4, 9, 5},  {2, 4, 11}, {6, 2, 10},  {8, 6, 7},  {9, 8, 1}};
  for (int s = 0; s < subdivisions; ++s) {
    std::map<std::pair<int, int>, int> mid;
    auto midpoint = [&](int a, int b) {
      const auto key = std::minmax(a, b);
      auto it = mid.find(key);
      if (it != mid.end()) return it->second;
      v.push_back(radius * (v[a] + v[b]).normalized());
      return mid[key] = static_cast<int>(v.size()) - 1;
    };
    std::vector<std::array<int, 3>> g;
    for (const auto& tri : f) {
      const int ab = midpoint(tri[0], tri[1]), bc = midpoint(tri[1], tri[2]), ca = midpoint(tri[2], tri[0]);
      g.push_back({tri[0], ab, ca});
      g.push_back({tri[1], bc, ab});
      g.push_back({tri[2], ca, bc});
      g.push_back({ab, bc, ca});
    }
    f = g;
  }
  std::ofstream out(path);
  for (const Eigen::Vector3d& p : v) out << "v " << p.x() << " " << p.y() << " " << p.z() << "\n";
  for (const auto& tri : f) out << "f " << tri[0] + 1 << " " << tri[1] + 1 << " " << tri[2] + 1 << "\n";
  return v;
}

/// A free 1 kg body of `mesh` (a MeshShape: FCL collides it as a BVH of its triangles) at
/// `pose` moving at `v` in `world`, with a solid sphere's inertia of `radius`.
dd::BodyNode* add_mesh_body(const dart::simulation::WorldPtr& world, const aiScene* mesh, double radius,
                            const Eigen::Isometry3d& pose, const Eigen::Vector3d& v, double mu) {
  auto skel = dd::Skeleton::create("hull");
  auto pair = skel->createJointAndBodyNodePair<dd::FreeJoint>();
  pair.second->createShapeNodeWith<dd::CollisionAspect, dd::DynamicsAspect>(
      std::make_shared<dd::MeshShape>(Eigen::Vector3d::Ones(), mesh))->getDynamicsAspect()->setFrictionCoeff(mu);
  pair.second->setInertia(dd::Inertia(1.0, Eigen::Vector3d::Zero(), 0.4 * radius * radius * Eigen::Matrix3d::Identity()));
  dd::FreeJoint::setTransformOf(pair.first, pose);
  pair.first->setLinearVelocity(v);
  world->addSkeleton(skel);
  return pair.second;
}

/// rot-drop-220's floor (a BoxShape of 2.2 x 0.1 x 2.2 m, top at y = 0, fcl::Box) and one of
/// its icospheres (radius 0.07 m, 2 subdivisions, 1 kg) as a MeshShape, the way `--engine
/// dart` builds them, in a plain DART world; `cubes` 1 kg cubes rest on the floor away
/// from the icosphere. `hull_vertices` are the icosphere's vertices in its body frame.
struct HullOnFloor {
  dart::simulation::WorldPtr world;
  dd::BodyNode* floor = nullptr;
  dd::BodyNode* hull = nullptr;
  std::vector<Eigen::Vector3d> hull_vertices;

  HullOnFloor(const std::string& obj, const Eigen::Isometry3d& hull_pose, const Eigen::Vector3d& hull_v, int cubes) {
    world = plain_world(dart::collision::FCLCollisionDetector::PRIMITIVE);
    Eigen::Isometry3d floor_pose = Eigen::Isometry3d::Identity();
    floor_pose.translation() = Eigen::Vector3d(0, -0.05, 0);
    const double mu_shape = 0.5 / std::sqrt(2.0);
    floor = add_static(world, std::make_shared<dd::BoxShape>(Eigen::Vector3d(2.2, 0.1, 2.2)), floor_pose, mu_shape);
    for (int c = 0; c < cubes; ++c) {
      Eigen::Isometry3d cube_pose = Eigen::Isometry3d::Identity();
      cube_pose.translation() = Eigen::Vector3d(-0.8 + 0.4 * (c % 5), 0.05, 0.6 - 0.4 * (c / 5));
      add_cube(world, cube_pose, Eigen::Vector3d::Zero(), mu_shape);
    }
    hull_vertices = write_icosphere_obj(obj, 0.07, 2);
    const aiScene* mesh = dd::MeshShape::loadMesh(obj);
    EXPECT_NE(mesh, nullptr);
    hull = add_mesh_body(world, mesh, 0.07, hull_pose, hull_v, mu_shape);
  }

  /// How far the icosphere's lowest vertex is below the floor's top (m; negative above it).
  /// Lifting the icosphere by it separates the two, so no contact between them can be
  /// deeper (the icosphere lies inside the floor's 2.2 x 2.2 m top here).
  double sunk() const {
    double lowest = 1e9;
    for (const Eigen::Vector3d& p : hull_vertices) lowest = std::min(lowest, (hull->getWorldTransform() * p).y());
    return -lowest;
  }

  /// Whether contact `c` is between the floor and the icosphere; `hull_first` tells whether
  /// the icosphere is its object 1.
  bool floor_hull(const dart::collision::Contact& c, bool* hull_first) const {
    const dd::BodyNode* b1 = c.collisionObject1->getShapeFrame()->asShapeNode()->getBodyNodePtr().get();
    const dd::BodyNode* b2 = c.collisionObject2->getShapeFrame()->asShapeNode()->getBodyNodePtr().get();
    *hull_first = b1 == hull;
    return (b1 == hull && b2 == floor) || (b1 == floor && b2 == hull);
  }
};

/// `q` (w, x, y, z) and `x` as a pose.
Eigen::Isometry3d pose_of(const Eigen::Quaterniond& q, const Eigen::Vector3d& x) {
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  pose.linear() = q.normalized().toRotationMatrix();
  pose.translation() = x;
  return pose;
}

}  // namespace

// FCL 0.7 collides a primitive box with a MeshShape triangle by triangle, and each
// box-triangle test is libccd's MPR (GJKCollide -> ccdMPRPenetration), which returns the
// penetration along the ray between the two shapes' centres, not the minimum translation.
// For an icosphere hull sunk into rot-drop-220's floor (a wide flat box whose centre is far
// from the hull) that ray leaves through a side face of the floor, and DART reports
// Contact::penetrationDepth = the distance to that side, along a sideways normal. The
// icosphere lifted by its own depth below the floor's top is clear of the floor, so no
// correct contact between them is deeper than that. Poses of the trace
// dart--rot-drop-220.h5 (--engine dart, 400 frames): body 214 at frame 380, 6.06 cm deep,
// rows up to 0.986 m; body 215 at frame 392, 8.02 cm deep, rows up to 0.596 m (the physics
// tier's contact-geometry/depth row: SAT's minimum against the deepest row). One collision
// (the contacts World::step finds at the pose before it steps), plain DART calls.
TEST(DartEngineFault, FclBoxAgainstAMeshReportsDepthsBeyondTheOverlap) {
  const std::string obj = (std::filesystem::temp_directory_path() /
                           ("dart-icosphere-" + std::to_string(::getpid()) + ".obj")).string();
  struct Case {
    const char* name;
    Eigen::Quaterniond q;
    Eigen::Vector3d x;
  };
  const Case cases[] = {
      {"body 214 frame 380", Eigen::Quaterniond(0.977628, 0.210332, -0.000475, -0.002113),
       Eigen::Vector3d(-0.060706, 0.00941, -0.15673)},
      {"body 215 frame 392", Eigen::Quaterniond(0.976323, 0.216319, 0, 0.000004),
       Eigen::Vector3d(0.571036, -0.010219, -0.456181)}};
  for (const Case& k : cases) {
    SCOPED_TRACE(k.name);
    HullOnFloor w(obj, pose_of(k.q, k.x), Eigen::Vector3d::Zero(), 0);
    const double sunk = w.sunk();
    ASSERT_GT(sunk, 0.05);
    w.world->step();
    const dart::collision::CollisionResult& r = w.world->getLastCollisionResult();
    double deepest = 0.0, sideways = 0.0;
    int rows = 0, beyond = 0;
    for (std::size_t i = 0; i < r.getNumContacts(); ++i) {
      const dart::collision::Contact& c = r.getContact(i);
      bool hull_first = false;
      if (!w.floor_hull(c, &hull_first)) continue;
      ++rows;
      if (c.penetrationDepth > sunk + 1e-6) ++beyond;
      if (c.penetrationDepth > deepest) {
        deepest = c.penetrationDepth;
        sideways = std::fabs(c.normal.y());
      }
    }
    EXPECT_GT(rows, 100);
    EXPECT_GT(deepest, 5 * sunk) << "deepest row " << deepest << " m, the icosphere " << sunk << " m below the top";
    EXPECT_LT(sideways, 0.1) << "the deepest row's normal is not sideways";
    EXPECT_GT(beyond, 10);
    RecordProperty(std::string(k.name == cases[0].name ? "b214" : "b215") + "_sunk_m", sci(sunk));
    RecordProperty(std::string(k.name == cases[0].name ? "b214" : "b215") + "_deepest_row_m", sci(deepest));
    RecordProperty(std::string(k.name == cases[0].name ? "b214" : "b215") + "_rows_beyond",
                   std::to_string(beyond) + " of " + std::to_string(rows));
  }
  std::filesystem::remove(obj);
}

// The icosphere falls through the floor: rot-drop-220's body 215 (state of frame 369 of
// dart--rot-drop-220.h5: 3.65 m/s down, tilted 25 degrees about x) lands on the floor. Every
// floor-icosphere row of its first steps has the normal of
// DartEngineFault.FclPrimitiveBoxAgainstAMeshGetsNormalsPointingTheWrongWay, from object 1's
// body to object 2's, so DART's LCP sees the icosphere's approach as separation along them;
// once it is 3 cm in, the rest are sideways rows (the MPR depths of
// DartEngineFault.FclBoxAgainstAMeshReportsDepthsBeyondTheOverlap) it also moves along
// without approaching. DART's own Contact::force on the icosphere is zero on every row while
// it falls 8 cm into the floor at 3.7 m/s, and it comes to rest there. Which object FCL
// names first is decided by its dynamic AABB tree: seven cubes resting elsewhere on the floor
// give the tree of the scene (with the floor and the icosphere alone the order alternates
// every step and the icosphere stops 1 mm in). The trace shows the same steps: 5, 18, 32,
// 43, ... rows from frame 370, 8.02 cm deep at frame 391 (the physics tier's penetration
// row, bound 2 cm). Plain DART calls.
TEST(DartEngineFault, FclBoxAgainstAMeshLetsAHullSinkIntoTheFloor) {
  const std::string obj = (std::filesystem::temp_directory_path() /
                           ("dart-icosphere-" + std::to_string(::getpid()) + ".obj")).string();
  HullOnFloor w(obj,
                pose_of(Eigen::Quaterniond(0.976296, 0.21644, 0, 0), Eigen::Vector3d(0.576339, 0.068651, -0.45071)),
                Eigen::Vector3d(-0.252449, -3.65428, -0.260476), 7);
  std::filesystem::remove(obj);
  int steps_unresisted = 0, steps_all_reversed = 0, rows_reversed = 0, rows_in_contact = 0;
  double push_while_sinking = 0.0;
  for (int step = 1; step <= 40; ++step) {
    w.world->step();
    const double vy = w.hull->getLinearVelocity().y();
    const dart::collision::CollisionResult& r = w.world->getLastCollisionResult();
    int rows = 0, reversed = 0;
    double push = 0.0;  // DART's force on the icosphere along +y, summed over the rows
    for (std::size_t i = 0; i < r.getNumContacts(); ++i) {
      const dart::collision::Contact& c = r.getContact(i);
      bool hull_first = false;
      if (!w.floor_hull(c, &hull_first)) continue;
      ++rows;
      // Contact::normal points from object 2's body to object 1's: +y when object 1 is the icosphere.
      const double expected_y = hull_first ? 1.0 : -1.0;
      if (c.normal.y() * expected_y < -0.5) ++reversed;
      push += (hull_first ? 1.0 : -1.0) * c.force.y();
    }
    rows_in_contact += rows;
    rows_reversed += reversed;
    if (rows > 0 && vy < -1.0) {  // in the floor and still falling fast after the step
      ++steps_unresisted;
      steps_all_reversed += reversed == rows ? 1 : 0;
      push_while_sinking = std::max(push_while_sinking, std::fabs(push));
    }
  }
  const double sunk = w.sunk();
  EXPECT_GT(sunk, 0.05) << "the icosphere's lowest point is " << sunk << " m below the floor's top";
  EXPECT_LT(std::fabs(w.hull->getLinearVelocity().y()), 0.01) << "it rests there";
  EXPECT_GE(steps_unresisted, 15);
  EXPECT_LT(push_while_sinking, 1e-6) << "DART's LCP pushed the falling icosphere up";
  EXPECT_GE(steps_all_reversed, 5) << "steps whose every floor-icosphere row points from object 1's body to object 2's";
  EXPECT_GT(rows_reversed, 300);
  RecordProperty("sunk_m", sci(sunk));
  RecordProperty("steps_falling_in_contact_without_force", std::to_string(steps_unresisted));
  RecordProperty("steps_every_row_reversed", std::to_string(steps_all_reversed));
  RecordProperty("rows_reversed", std::to_string(rows_reversed) + " of " + std::to_string(rows_in_contact));
}


#else

TEST(DartWorld, NotBuilt) {
  GTEST_SKIP() << "this octocd is built without DART (find_package(DART CONFIG) found no DART: libdart-dev)";
}

#endif

}  // namespace octocd_test_dart_world
