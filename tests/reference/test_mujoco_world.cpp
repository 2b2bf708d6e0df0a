// octocd::MujocoWorld (`--engine mujoco`, reference/mujoco/): its step is mj_step, the
// closed forms of its integrator (free fall, torque-free spin with MuJoCo's explicit
// gyroscopic term), a box resting on a floor, the sign conventions of its contact rows,
// a trace the physics tier passes, its settings, and the faults of MuJoCo 2.2 that the
// physics tier reports or that stop a run, each shown with a witness computed from
// MuJoCo's own data.
// Skipped (GTEST_SKIP) when octocd is built without MuJoCo.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "octocd/error.hpp"
#include "octocd/external.hpp"
#include "octocd/scene.hpp"
#include "octocd/trace.hpp"

#if OCTOCD_HAVE_MUJOCO
#include <mujoco/mujoco.h>

#include "octocd/mujoco_world.hpp"
#endif

// This file's own names (its tests compile in unity batches with the folder's other files).
namespace octocd_test_mujoco_world {

using namespace octocd;

#if !OCTOCD_HAVE_MUJOCO
TEST(MujocoWorld, NotBuilt) { GTEST_SKIP() << "octocd is built without MuJoCo (libmujoco-dev not found)"; }
#else

namespace {

std::string scene_path(const std::string& name) {
  const char* root = std::getenv("OCTOCD_SOURCE_DIR");
  return std::string(root ? root : ".") + "/datasets/scenes/" + name + ".json";
}

/// True when datasets/fetch.sh has put `file` into datasets/cache.
bool have_dataset_mesh(const std::string& file) {
  const char* root = std::getenv("OCTOCD_SOURCE_DIR");
  return std::filesystem::exists(std::string(root ? root : ".") + "/datasets/cache/" + file);
}

/// The same MJCF loaded into a MuJoCo model of the test's own, with the engine's initial
/// state (the adapter's recipe: x, the normalised q, v, and R^T w in the body frame),
/// stepped with mj_step: the oracle for what MuJoCo itself does.
struct RawMujoco {
  mjModel* m = nullptr;
  mjData* d = nullptr;
  std::vector<int> qadr, dadr, geom;  // per octocd body (-1: static)

  RawMujoco(const MujocoWorld& w, const BodyState& s0) {
    const std::string& xml = w.xml();
    auto vfs = std::make_unique<mjVFS>();
    mj_defaultVFS(vfs.get());
    mj_makeEmptyFileVFS(vfs.get(), "t.xml", static_cast<int>(xml.size()));
    std::memcpy(vfs->filedata[mj_findFileVFS(vfs.get(), "t.xml")], xml.data(), xml.size());
    char err[1000] = "";
    m = mj_loadXML("t.xml", vfs.get(), err, sizeof err);
    mj_deleteVFS(vfs.get());
    EXPECT_NE(m, nullptr) << err;
    d = mj_makeData(m);
    for (std::size_t i = 0; i < s0.size(); ++i) {
      geom.push_back(mj_name2id(m, mjOBJ_GEOM, ("g" + std::to_string(i)).c_str()));
      const int j = mj_name2id(m, mjOBJ_JOINT, ("j" + std::to_string(i)).c_str());
      qadr.push_back(j < 0 ? -1 : m->jnt_qposadr[j]);
      dadr.push_back(j < 0 ? -1 : m->jnt_dofadr[j]);
      if (j < 0) continue;
      mjtNum* qp = d->qpos + qadr.back();
      mjtNum* qv = d->qvel + dadr.back();
      const Quat q = s0.q.empty() ? Quat{} : normalized(s0.q[i]);
      const Vec3 om = s0.omega.empty() ? Vec3{} : s0.omega[i];
      qp[0] = s0.x[i].x, qp[1] = s0.x[i].y, qp[2] = s0.x[i].z;
      mjtNum qd[4] = {q.w, q.x, q.y, q.z};
      mju_normalize4(qd);
      std::copy(qd, qd + 4, qp + 3);
      qv[0] = s0.v[i].x, qv[1] = s0.v[i].y, qv[2] = s0.v[i].z;
      mjtNum neg[4], wv[3] = {om.x, om.y, om.z};
      mju_negQuat(neg, qd);
      mju_rotVecQuat(qv + 3, wv, neg);
    }
  }
  ~RawMujoco() {
    mj_deleteData(d);
    mj_deleteModel(m);
  }
  RawMujoco(const RawMujoco&) = delete;
  RawMujoco& operator=(const RawMujoco&) = delete;

  /// Velocity (world) of body i's material point at world point p: v + w x (p - x).
  std::array<double, 3> point_velocity(std::size_t i, const mjtNum* p) const {
    if (qadr[i] < 0) return {0, 0, 0};
    const mjtNum* qp = d->qpos + qadr[i];
    const mjtNum* qv = d->qvel + dadr[i];
    mjtNum w[3];
    mju_rotVecQuat(w, qv + 3, qp + 3);
    const double r[3] = {p[0] - qp[0], p[1] - qp[1], p[2] - qp[2]};
    return {qv[0] + w[1] * r[2] - w[2] * r[1], qv[1] + w[2] * r[0] - w[0] * r[2], qv[2] + w[0] * r[1] - w[1] * r[0]};
  }
  /// The contacts between the geoms of bodies a and b (indices into d->contact).
  std::vector<int> contacts(std::size_t a, std::size_t b) const {
    std::vector<int> out;
    for (int c = 0; c < d->ncon; ++c) {
      const int g1 = d->contact[c].geom1, g2 = d->contact[c].geom2;
      if ((g1 == geom[a] && g2 == geom[b]) || (g1 == geom[b] && g2 == geom[a])) out.push_back(c);
    }
    return out;
  }
  /// How far world point p lies outside box geom g (m; negative: inside, by the least
  /// depth to a face), from MuJoCo's geom_xpos, geom_xmat and geom_size.
  double outside_box(int g, const mjtNum* p) const {
    mjtNum r[3], l[3];
    for (int k = 0; k < 3; ++k) r[k] = p[k] - d->geom_xpos[3 * g + k];
    mju_mulMatTVec(l, d->geom_xmat + 9 * g, r, 3, 3);
    double out2 = 0.0, in = -1e300;
    for (int k = 0; k < 3; ++k) {
      const double e = std::fabs(l[k]) - m->geom_size[3 * g + k];
      if (e > 0) out2 += e * e;
      in = std::max(in, e);
    }
    return out2 > 0 ? std::sqrt(out2) : in;
  }
};

/// A scene with one group per entry of `groups` (JSON objects), no walls unless `walls`.
Scene scene_of(const std::string& groups, const std::string& extra = "", const std::string& walls = "none") {
  return parse_scene(R"({"name": "mj", "domain": {"min": [-3, 0, -3], "max": [3, 4, 3]}, "rotation": true,
    "walls": ")" + walls + R"(", "wall_thickness": 0.2)" + extra + R"(, "groups": [)" + groups + "]}",
                     "mujoco (test)");
}

/// Steps `engine` `frames` times into a version 2 trace at `path`, as `octocd run --trace
/// PATH --state-every 1 --contacts` does.
void write_trace(Engine& engine, const std::string& path, int frames) {
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
  }
  trace.close();
}

}  // namespace

// The engine calls mj_step's parts itself (to time them): after 500 steps of three boxes
// tumbling onto a floor (contacts, spin, friction) its state is mj_step's, bit for bit.
TEST(MujocoWorld, StepIsMjStep) {
  const auto model = build_model(scene_of(
      R"({"name": "b", "shape": {"box": [0.1, 0.05, 0.08]}, "count": 3, "mass": 1.5,
          "positions": [[0, 0.15, 0], [0.05, 0.4, 0.02], [-0.04, 0.65, 0]],
          "orientation": {"axis": [1, 0.3, 0.2], "angle_deg": 25}, "angular_velocity": [1, 3, -2]})",
      R"(, "response": {"mu_kinetic": 0.4, "restitution": 0.3})", "floor"));
  MujocoWorld w(model, model->initial);
  RawMujoco raw(w, model->initial);
  std::size_t contacts = 0;
  for (int f = 0; f < 500; ++f) {
    w.step();
    mj_step(raw.m, raw.d);
    contacts += static_cast<std::size_t>(raw.d->ncon);
    for (std::size_t i = 0; i < raw.qadr.size(); ++i) {
      if (raw.qadr[i] < 0) continue;
      const mjtNum* qp = raw.d->qpos + raw.qadr[i];
      ASSERT_EQ(w.state().x[i].y, static_cast<float>(qp[1])) << "frame " << f + 1 << " body " << i;
      ASSERT_EQ(w.state().q[i].x, static_cast<float>(qp[4])) << "frame " << f + 1 << " body " << i;
      ASSERT_EQ(w.state().v[i].x, static_cast<float>(raw.d->qvel[raw.dadr[i]])) << "frame " << f + 1 << " body " << i;
    }
  }
  EXPECT_GT(contacts, 100u) << "the boxes must land for the comparison to cover contacts";
}

// Free fall under MuJoCo's Euler integrator, semi-implicit: v_n = v0 + n g dt,
// x_n = x0 + n dt v0 + g dt^2 n (n + 1) / 2. The float32 state stays within 2e-6 m of it
// over 400 steps (MuJoCo works in double); explicit Euler (x += dt v before v += dt g)
// would be n dt^2 |g| = 3.9e-3 m off.
TEST(MujocoWorld, FreeFallFollowsSemiImplicitEuler) {
  const auto model = build_model(scene_of(
      R"({"name": "b", "shape": {"box": [0.1, 0.1, 0.1]}, "count": 1, "mass": 2,
          "positions": [[0.1, 2.0, -0.2]], "velocity": {"type": "fixed", "value": [1.0, 2.0, 0.5]}})"));
  MujocoWorld w(model, model->initial);
  const double dt = model->scene.dt;
  const Vec3 g = model->scene.gravity, x0 = model->initial.x[0], v0 = model->initial.v[0];
  double worst = 0.0;
  for (int n = 1; n <= 400; ++n) {
    w.step();
    for (int k = 0; k < 3; ++k) {
      const double x = x0[k] + n * dt * v0[k] + g[k] * dt * dt * n * (n + 1) / 2.0;
      const double v = v0[k] + static_cast<double>(n) * g[k] * dt;
      worst = std::max(worst, std::fabs(w.state().x[0][k] - x));
      ASSERT_NEAR(w.state().v[0][k], v, 2e-6) << "step " << n;
    }
    ASSERT_EQ(w.last_metrics().contacts, 0u);
  }
  EXPECT_LT(worst, 2e-6);
  EXPECT_LT(worst, 0.01 * 400 * dt * dt * 9.81) << "indistinguishable from explicit Euler";
}

// Torque-free spin of a box with three different moments of inertia: MuJoCo's free joint
// integrates I dw_b/dt = -w_b x I w_b explicitly (qfrc_bias), so every step satisfies
// I_w (w' - w) + dt w x I_w w = 0 (the declared gyroscopic term) to rounding, and the
// world angular momentum R I R^T w drifts only at the integrator's first order: measured
// below 1 % over 2 s while a body without the gyroscopic term (w held constant) would be
// off by more than twice that.
TEST(MujocoWorld, FreeSpinHasTheGyroscopicTerm) {
  const auto model = build_model(scene_of(
      R"({"name": "brick", "shape": {"box": [0.3, 0.1, 0.05]}, "count": 1, "mass": 2.0,
          "positions": [[0, 0, 0]], "angular_velocity": [0.2, 6.0, 0.1]})",
      R"(, "gravity": [0, 0, 0])"));
  MujocoWorld w(model, model->initial);
  const std::array<float, 9> I = w.rotation_traits()->inertia[0];
  EXPECT_NEAR(I[0], 2.0 / 12 * (0.2 * 0.2 + 0.1 * 0.1), 1e-7);
  auto world_L = [&](const Quat& q, const Vec3& om) {  // R I R^T w
    const Vec3 wl = rotate(conjugate(q), om);
    return rotate(q, Vec3{I[0] * wl.x, I[4] * wl.y, I[8] * wl.z});
  };
  const Vec3 w0 = w.state().omega[0];
  const Quat q0 = w.state().q[0];
  const Vec3 L0 = world_L(q0, w0);
  double worst_step = 0.0, worst_L = 0.0, worst_no_gyro = 0.0, w_change = 0.0;
  const double dt = model->scene.dt;
  for (int f = 1; f <= 2000; ++f) {
    const Quat q = w.state().q[0];
    const Vec3 om = w.state().omega[0];
    w.step();
    const Vec3 om1 = w.state().omega[0];
    // I_w (w' - w) + dt w x I_w w, relative to |I_w w|.
    const Vec3 Iw = world_L(q, om);
    const Vec3 r = world_L(q, om1 - om) + static_cast<float>(dt) * cross(om, Iw);
    worst_step = std::max(worst_step, static_cast<double>(length(r) / length(Iw)));
    worst_L = std::max(worst_L, static_cast<double>(length(world_L(w.state().q[0], om1) - L0) / length(L0)));
    const Quat turned = axis_angle((1.0f / length(w0)) * w0, length(w0) * static_cast<float>(f * dt)) * q0;
    worst_no_gyro = std::max(worst_no_gyro, static_cast<double>(length(world_L(turned, w0) - L0) / length(L0)));
    w_change = std::max(w_change, static_cast<double>(length(om1 - w0)));
  }
  EXPECT_GT(w_change, 0.1) << "the body must tumble for the test to mean something";
  EXPECT_LT(worst_step, 1e-5) << "the step is not w' = w - dt I^-1 (w x I w)";
  EXPECT_GT(worst_no_gyro, 0.02);
  EXPECT_LT(worst_L, 0.01);
  RecordProperty("angular_momentum_relative_change", std::to_string(worst_L));
}

// A box (2 kg) resting on a static floor settles: after 0.5 s its speed is below 1e-3 m/s,
// it has sunk less than 0.1 mm (soft contact: the spring's static deflection at
// timeconst 2 dt is a few micrometres), and the normal impulses of its rows sum to
// m |g| dt within 0.1 %, the rows' jn being MuJoCo's own mj_contactForce x dt (checked
// against the test's own MuJoCo data).
TEST(MujocoWorld, RestingBoxSettlesAndCarriesItsWeight) {
  const auto model = build_model(scene_of(
      R"({"name": "b", "shape": {"box": [0.1, 0.1, 0.1]}, "count": 1, "mass": 2, "positions": [[0, 0.1, 0]]})",
      R"(, "response": {"restitution": 0.0})", "floor"));
  MujocoWorld w(model, model->initial);
  RawMujoco raw(w, model->initial);
  w.set_recording(true);
  const std::size_t box = 1;  // the generated floor is body 0
  const double m = 2.0, g = 9.81, dt = model->scene.dt;
  for (int f = 1; f <= 600; ++f) {
    w.step();
    mj_step(raw.m, raw.d);
    if (f < 500) continue;
    double jn = 0.0, jn_raw = 0.0;
    for (const ContactRecord& c : w.record().contacts) {
      EXPECT_EQ(c.pair.a, 0u);
      EXPECT_EQ(c.pair.b, box);
      jn += c.jn;
    }
    for (int c : raw.contacts(0, box)) {
      mjtNum f6[6];
      mj_contactForce(raw.m, raw.d, c, f6);
      jn_raw += f6[0] * dt;
    }
    EXPECT_EQ(w.record().contacts.size(), raw.contacts(0, box).size());
    EXPECT_NEAR(jn, jn_raw, 1e-6 * jn_raw);
    EXPECT_NEAR(jn, m * g * dt, 1e-3 * m * g * dt) << "frame " << f;
    EXPECT_LT(length(w.state().v[box]), 1e-3f) << "frame " << f;
    EXPECT_GT(w.state().x[box].y, 0.1f - 1e-4f) << "frame " << f;
  }
}

// The conventions of the rows (docs/trace-format.md, "Version 2"): a box sliding at
// +0.3 m/s along x on a static floor (it hops a little: docs/engines.md, "mujoco"). Box as body 0 (A): normal (0, 1, 0), from the floor
// (B) to A; floor as body 0 (A): normal (0, -1, 0). Either way jt > 0 (friction opposes
// A's sliding relative to B), jt3 is the friction impulse on A (along -x when A is the
// box), orthogonal to the normal, and the box's momentum change along x is its rows'
// friction impulses.
TEST(MujocoWorld, NormalPointsFromBToAAndJtOpposesSliding) {
  for (const bool box_first : {true, false}) {
    SCOPED_TRACE(box_first ? "box is body 0" : "floor is body 0");
    const std::string box = R"({"name": "box", "shape": {"box": [0.1, 0.1, 0.1]}, "count": 1, "mass": 1.0,
        "positions": [[0.0, 0.1, 0.0]], "velocity": {"type": "fixed", "value": [0.3, 0.0, 0.0]}})";
    const std::string floor = R"({"name": "ground", "shape": {"box": [2.0, 0.1, 2.0]}, "count": 1, "mass": 0,
        "positions": [[0.0, -0.1, 0.0]]})";
    const auto model = build_model(scene_of(box_first ? box + ", " + floor : floor + ", " + box,
                                            R"(, "response": {"mu_kinetic": 0.3, "restitution": 0.0})"));
    MujocoWorld w(model, model->initial);
    w.set_recording(true);
    const std::size_t b = box_first ? 0 : 1;
    int rows = 0;
    for (int f = 0; f < 200; ++f) {
      const float vx = w.state().v[b].x;
      w.step();
      const FrameRecord& r = w.record();
      ASSERT_EQ(r.contacts.size(), r.jt3.size());
      double fx = 0.0;
      for (std::size_t k = 0; k < r.contacts.size(); ++k) {
        const ContactRecord& c = r.contacts[k];
        EXPECT_EQ(c.pair.a, 0u);
        EXPECT_EQ(c.pair.b, 1u);
        EXPECT_NEAR(c.normal.y, box_first ? 1.0f : -1.0f, 1e-6f);
        EXPECT_NEAR(dot(r.jt3[k], c.normal), 0.0f, 1e-6f);
        if (c.jn > 0.0f && std::fabs(vx) > 0.01f) {  // sliding (at rest MuJoCo's soft friction creeps either way)
          EXPECT_GT(c.jt, 0.0f) << "frame " << f + 1;
          EXPECT_LT(r.jt3[k].x * (box_first ? 1.0f : -1.0f), 0.0f);
        }
        fx += box_first ? r.jt3[k].x : -r.jt3[k].x;  // the impulse on the box
        ++rows;
      }
      EXPECT_NEAR(w.state().v[b].x - vx, fx, 1e-5) << "frame " << f + 1;
    }
    EXPECT_GT(rows, 50);
  }
}

// rot-stack-10 (ten boxes stacked on a floor, each 0.5 mm above the next), 1000 frames,
// written as `octocd run --trace --contacts --state-every 1` writes it: every
// physics-tier row of `octocd validate --trace-in` passes or is n/a (the broadphase rows:
// no candidate pairs in the trace), and momentum-balance and free-flight judge something.
// (Three such boxes are thrown apart at frame 183 by a wrong box-box contact:
// MujocoFaults.AlignedBoxesGetAContactTenCentimetresDeep; a stack sliding as it lands
// fails friction's dissipation rule: MujocoFaults.SoftFrictionPushesAlongTheSliding.)
TEST(MujocoWorld, StackOfTenTracePassesThePhysicsTier) {
  const auto model = build_model(load_scene(scene_path("rot-stack-10")));
  MujocoWorld w(model, model->initial);
  const std::string path = (std::filesystem::temp_directory_path() / "octocd-test-mujoco-stack.h5").string();
  write_trace(w, path, 1000);
  ExternalOptions eo;
  const std::vector<ValidationResult> results = validate_external_trace(path, eo);
  std::filesystem::remove(path);
  bool balance = false, flight = false;
  for (const ValidationResult& r : results) {
    if (r.tier != Tier::Physics) continue;
    SCOPED_TRACE(r.name);
    EXPECT_TRUE(r.pass) << r.detail;
    if (r.name == "momentum-balance") balance = r.applicable && r.judged > 0;
    if (r.name == "free-flight") flight = r.applicable && r.judged > 0;
    if (r.name == "broadphase-completeness") {
      EXPECT_FALSE(r.applicable) << "the trace holds no candidate pairs";
    }
  }
  EXPECT_TRUE(balance);
  EXPECT_TRUE(flight);
}

// A brick spun at 1000 rad/s about its middle axis, alone (|w| dt = 1 rad a step):
// MuJoCo's explicit gyroscopic term diverges (the fate of mixed-pile-1000's dragon 584,
// docs/engines.md "mujoco") and mj_checkAcc resets the state at frame 102. The error names
// the frame, MuJoCo's DOF and the octocd body that holds it: DOF 9 is the second free
// joint's (DOFs 6-11), body 1 of the scene.
TEST(MujocoWorld, BadAccelerationNamesTheBody) {
  const auto model = build_model(scene_of(
      R"({"name": "calm", "shape": {"box": [0.1, 0.1, 0.1]}, "count": 1, "mass": 1, "positions": [[-1, 2, 0]]},
         {"name": "spinner", "shape": {"box": [0.2, 0.1, 0.05]}, "count": 1, "mass": 1, "positions": [[1, 2, 0]],
          "angular_velocity": [10, 1000, 10]})",
      R"(, "gravity": [0, 0, 0])"));
  MujocoWorld w(model, model->initial);
  std::string what;
  int frames = 0;
  try {
    for (; frames < 1000; ++frames) w.step();
  } catch (const RuntimeError& e) {
    what = e.what();
  }
  EXPECT_EQ(frames, 101) << "steps before the failing one";
  EXPECT_NE(what.find("mujoco: frame 102: MuJoCo warning: bad number in qacc"), std::string::npos) << what;
  EXPECT_NE(what.find("): DOF 9 is body 1 (group spinner)"), std::string::npos) << what;
}

// A column of four boxes on the floor finds more contacts than `max_contacts=2` holds: the
// first step throws before MuJoCo's solver runs on the truncated arrays (with 10^4 boxes and
// max_contacts=100 it ended in SIGSEGV inside mj_fwdConstraint), naming the setting and its
// value; the engine's state is still the initial one.
TEST(MujocoWorld, AFullContactBufferIsAnErrorNamingMaxContacts) {
  const auto model = build_model(scene_of(
      R"({"name": "stack", "shape": {"box": [0.1, 0.1, 0.1]}, "count": 4, "mass": 2,
          "positions": [[0, 0.1, 0], [0, 0.3, 0], [0, 0.5, 0], [0, 0.7, 0]]})",
      "", "floor"));
  MujocoSettings settings;
  settings.max_contacts = 2;
  MujocoWorld w(model, model->initial, settings);
  std::string what;
  try {
    w.step();
  } catch (const RuntimeError& e) {
    what = e.what();
  }
  EXPECT_NE(what.find("mujoco: frame 1: the contact buffer is full (nconmax 2)"), std::string::npos) << what;
  EXPECT_NE(what.find("--mujoco max_contacts=2 (as set)"), std::string::npos) << what;
  EXPECT_EQ(w.frame(), 0) << "no frame was counted";
}

// 4,000 free boxes, four resting on the floor so the solver runs at the first step: MuJoCo
// 2.2's own stack size (nstack, about 5 nv^2 + 12 njmax nv mjtNums as an int) wraps past
// about 3,400 free bodies (here mj_loadXML stopped with "Stack overflow"), and its Newton
// solver takes 3 nv^2 of it, nv x nv as an int that wraps past 7,723 bodies (the SIGSEGV
// in mj_fwdConstraint at 10^4). Above 2,000 dynamic bodies the adapter runs MuJoCo's CG
// solver on a stack it sizes from the scene (docs/engines.md, "Set-up of large scenes").
TEST(MujocoWorld, LargeScenesRunOnTheConjugateGradientSolverWithAStackSizedFromTheScene) {
  const auto model = build_model(scene_of(
      R"({"name": "resting", "shape": {"box": [0.1, 0.1, 0.1]}, "count": 4, "mass": 1,
          "positions": [[0, 0.099, 0], [0.5, 0.099, 0], [1, 0.099, 0], [1.5, 0.099, 0]]},
         {"name": "high", "shape": {"box": [0.04, 0.04, 0.04]}, "count": 3996, "mass": 1,
          "layout": {"type": "grid", "min": [-2.8, 1.0, -2.8], "max": [2.8, 3.8, 2.8], "spacing": 0.25}})",
      "", "floor"));
  std::size_t dynamic = 0;
  for (float w : model->initial.w) dynamic += w > 0.0f ? 1 : 0;
  ASSERT_EQ(dynamic, 4000u);
  MujocoWorld w(model, model->initial);
  const std::string& xml = w.xml();
  EXPECT_NE(xml.find("solver=\"CG\""), std::string::npos);
  const std::size_t at = xml.find("nstack=\"");
  ASSERT_NE(at, std::string::npos);
  const long long nstack = std::stoll(xml.substr(at + 8));
  EXPECT_GT(nstack, 4001LL * 4001);  // MuJoCo's broadphase takes about nbody^2 / 2 of it
  EXPECT_LT(nstack, 2147483647LL);
  for (int f = 0; f < 2; ++f) {
    const FrameMetrics& m = w.step();
    EXPECT_GE(m.contacts, 4u) << "frame " << f + 1 << ": the four resting boxes touch the floor";
  }
  std::size_t resting = 0;
  for (std::size_t i = 0; i < model->initial.size(); ++i) {
    if (!(model->initial.w[i] > 0.0f) || model->initial.x[i].y > 0.5f) continue;
    ++resting;
    EXPECT_NEAR(w.state().x[i].y, 0.1f, 0.01f) << "body " << i << " rests on the floor";
  }
  EXPECT_EQ(resting, 4u);
  EXPECT_NE(w.notes().find("CG solver"), std::string::npos) << w.notes();
}

TEST(MujocoSettings, KeysValuesAndErrors) {
  MujocoSettings s;
  apply_settings(s, {"iterations=20", "cone=pyramidal", "timeconst=0.01", "margin=0.002", "multiccd=off",
                            "max_contacts=500"},
                        "--mujoco");
  EXPECT_EQ(s.iterations, 20);
  EXPECT_EQ(s.cone, MujocoCone::Pyramidal);
  EXPECT_DOUBLE_EQ(s.timeconst, 0.01);
  EXPECT_DOUBLE_EQ(s.margin, 0.002);
  EXPECT_FALSE(s.multiccd);
  EXPECT_EQ(s.max_contacts, 500);
  auto error = [](const std::string& item) {
    MujocoSettings t;
    try {
      apply_settings(t, {item}, "--mujoco");
    } catch (const InputError& e) {
      return std::string(e.what());
    }
    return std::string();
  };
  EXPECT_EQ(error("iterations=0"),
            "--mujoco: iterations='0' is not allowed; allowed: an integer in [1, 10000] (MuJoCo's main solver "
            "iterations per step; its default 100)");
  EXPECT_NE(error("cone=round").find("cone='round' is not allowed; allowed: elliptic"), std::string::npos);
  EXPECT_NE(error("timeconst=inf").find("timeconst='inf' is not allowed"), std::string::npos);
  EXPECT_NE(error("margin=0.5").find("margin='0.5' is not allowed; allowed: a decimal number of metres in [0, 0.1]"),
            std::string::npos);
  EXPECT_NE(error("multiccd=yes").find("multiccd='yes'"), std::string::npos);
  EXPECT_NE(error("max_contacts=-1").find("max_contacts='-1'"), std::string::npos);
  EXPECT_NE(error("solver=pgs").find("unknown mujoco setting 'solver'; allowed: iterations, cone, timeconst, margin, "
                                     "multiccd, max_contacts"),
            std::string::npos);
  EXPECT_NE(error("cone").find("'cone' is not KEY=VALUE"), std::string::npos);
  // The settings reach the model: the loaded option and sizes.
  const auto model = build_model(scene_of(R"({"name": "b", "shape": {"box": [0.1, 0.1, 0.1]}, "count": 1,
      "mass": 1, "positions": [[0, 1, 0]]})"));
  MujocoWorld w(model, model->initial, s);
  RawMujoco raw(w, model->initial);
  EXPECT_EQ(raw.m->opt.iterations, 20);
  EXPECT_EQ(raw.m->opt.cone, mjCONE_PYRAMIDAL);
  EXPECT_EQ(raw.m->opt.enableflags & mjENBL_MULTICCD, 0);
  EXPECT_EQ(raw.m->nconmax, 500);
  EXPECT_DOUBLE_EQ(raw.m->geom_solref[2 * raw.geom[0]], 0.01);
  EXPECT_DOUBLE_EQ(raw.m->geom_margin[raw.geom[0]], 0.002);
  EXPECT_FLOAT_EQ(w.rotation_traits()->contact_margin, 0.002f);
}

// ---- MuJoCo 2.2 faults the physics tier reports (docs/engines.md, "mujoco"), each shown
// on MuJoCo's own data: its contacts (mjData::contact), forces (mj_contactForce), geom
// poses (geom_xpos, geom_xmat, geom_size) and velocities (qvel).

// rot-drop-220, frame 1: a bar (half extents 0.1 x 0.05 x 0.05, turned 60 deg about
// (1, 0, 1)) placed 14.9 mm into the +x wall. mjc_BoxBox reports one contact with
// dist = -7.44 mm: half the depth of the bar's deepest corner below the wall's face,
// computed from MuJoCo's own geom poses and sizes (contact-geometry fails `depth`: SAT
// 14.88 mm).
TEST(MujocoFaults, BoxBoxReportsHalfTheDepthOfAVertexInAFace) {
  const auto model = build_model(scene_of(
      R"({"name": "wall", "shape": {"box": [0.05, 1.5, 1.1]}, "count": 1, "mass": 0, "positions": [[1.05, 1.5, 0]]},
         {"name": "bar", "shape": {"box": [0.1, 0.05, 0.05]}, "count": 1, "mass": 1,
          "positions": [[0.896762848, 2.77780581, -0.744058728]],
          "orientation": {"axis": [1, 0, 1], "angle_deg": 60}})"));
  MujocoWorld w(model, model->initial);
  RawMujoco raw(w, model->initial);
  mj_forward(raw.m, raw.d);
  const std::vector<int> cs = raw.contacts(0, 1);
  ASSERT_EQ(cs.size(), 1u);
  const mjContact& c = raw.d->contact[cs[0]];
  // The deepest corner of the bar beyond the wall's inner face (x = 1.0), along the
  // contact normal, from MuJoCo's geom data.
  const int gb = raw.geom[1];
  double deepest = -1e300;
  for (int k = 0; k < 8; ++k) {
    mjtNum local[3], world[3];
    for (int a = 0; a < 3; ++a) local[a] = ((k >> a) & 1 ? 1 : -1) * raw.m->geom_size[3 * gb + a];
    mju_mulMatVec(world, raw.d->geom_xmat + 9 * gb, local, 3, 3);
    for (int a = 0; a < 3; ++a) world[a] += raw.d->geom_xpos[3 * gb + a];
    deepest = std::max(deepest, -raw.outside_box(raw.geom[0], world));
  }
  EXPECT_NEAR(deepest, 0.01488, 1e-4) << "the bar's corner inside the wall";
  EXPECT_NEAR(-c.dist, 0.5 * deepest, 1e-6) << "MuJoCo's dist is half the corner's depth";
  RecordProperty("corner_depth_m", std::to_string(deepest));
  RecordProperty("mujoco_dist_m", std::to_string(c.dist));
}

// rot-drop-220, frame 29: two cubes (half extents 0.05, the same orientation, 30 deg
// about (1, 1, 0)) meeting face to face 0.33 mm deep. mjc_BoxBox's face clipping returns
// five points, one of them 0.1126 m outside the first cube (0 from the second), with a
// normal force of 1 N: a point on neither contact face (contact-geometry fails
// `point-off-shape`).
TEST(MujocoFaults, BoxBoxFaceContactHasAPointOffTheFirstBox) {
  const auto model = build_model(scene_of(
      R"({"name": "c", "shape": {"box": [0.05, 0.05, 0.05]}, "count": 2, "mass": 1,
          "positions": [[-0.317502577, 0.437426082, 0.238953312], [-0.188754643, 0.477100788, 0.30524964]],
          "orientation": {"axis": [1, 1, 0], "angle_deg": 30}})",
      R"(, "gravity": [0, 0, 0])"));
  MujocoWorld w(model, model->initial);
  RawMujoco raw(w, model->initial);
  mj_forward(raw.m, raw.d);
  const std::vector<int> cs = raw.contacts(0, 1);
  ASSERT_GE(cs.size(), 2u);
  double worst = 0.0, force = 0.0;
  for (int k : cs) {
    const mjContact& c = raw.d->contact[k];
    const double off = std::max(raw.outside_box(c.geom1, c.pos), raw.outside_box(c.geom2, c.pos));
    if (off > worst) {
      worst = off;
      mjtNum f6[6];
      mj_contactForce(raw.m, raw.d, k, f6);
      force = f6[0];
    }
  }
  EXPECT_GT(worst, 0.1) << "a contact point 10 cm off a box of half extent 5 cm";
  EXPECT_GT(force, 0.0) << "and MuJoCo pushes there";
  RecordProperty("point_off_box_m", std::to_string(worst));
}

// Three boxes (half extents 0.1 m, 1 kg) stacked on a floor, each 0.5 mm above the
// next, settle; at frame 183 the two lower ones, face to face and turned against each
// other by 1e-7 rad, get five contacts from mjc_BoxBox: four at the face's corners
// 7.8 micrometres deep and one at an inner point with dist = -0.107 m. MuJoCo's own geom
// poses put the point 3.9 micrometres inside both boxes and the boxes' overlap along the
// normal at 7.8 micrometres; the solver answers the 10.7 cm with 34.8 kN over the step
// and the upper boxes leave at 17 m/s (contact-geometry fails `depth`: SAT 7.81e-6 m).
TEST(MujocoFaults, AlignedBoxesGetAContactTenCentimetresDeep) {
  const auto model = build_model(scene_of(
      R"({"name": "b", "shape": {"box": [0.1, 0.1, 0.1]}, "count": 3, "mass": 1,
          "positions": [[0, 0.1005, 0], [0, 0.301, 0], [0, 0.5015, 0]]})",
      R"(, "response": {"mu_kinetic": 0.5, "restitution": 0.0})", "floor"));
  MujocoWorld w(model, model->initial);
  RawMujoco raw(w, model->initial);
  for (int f = 1; f < 183; ++f) mj_step(raw.m, raw.d);
  mj_forward(raw.m, raw.d);
  const std::vector<int> cs = raw.contacts(1, 2);
  ASSERT_FALSE(cs.empty());
  const int g1 = raw.geom[1], g2 = raw.geom[2];
  // The overlap of the two boxes along y (their faces are within 1e-7 rad of y).
  const double overlap = (raw.d->geom_xpos[3 * g1 + 1] + raw.m->geom_size[3 * g1 + 1]) -
                         (raw.d->geom_xpos[3 * g2 + 1] - raw.m->geom_size[3 * g2 + 1]);
  EXPECT_LT(overlap, 1e-5);
  double deepest = 0.0, inside = 0.0;
  for (int k : cs) {
    const mjContact& c = raw.d->contact[k];
    if (-c.dist > deepest) {
      deepest = -c.dist;
      inside = std::max(raw.outside_box(g1, c.pos), raw.outside_box(g2, c.pos));
    }
  }
  EXPECT_GT(deepest, 0.1) << "MuJoCo's deepest contact";
  EXPECT_LT(std::fabs(inside), 1e-5) << "its point lies on both surfaces";
  mj_Euler(raw.m, raw.d);
  EXPECT_GT(raw.d->qvel[raw.dadr[2] + 1], 10.0) << "the middle box is thrown up";
  RecordProperty("mujoco_depth_m", std::to_string(deepest));
  RecordProperty("overlap_m", std::to_string(overlap));
}

// rot-drop-220, frame 130: cube 70 lands on a corner on the floor while sliding. MuJoCo's
// soft friction is a damper toward its reference acceleration aref = -b v_t (b =
// 2 / (dmax timeconst)), not Coulomb's maximal dissipation: after the corner's normal
// impulse has slowed the point's sliding below the reference, the friction force pushes
// the point along its sliding. Witness from MuJoCo's own data: the friction force of
// mj_contactForce (world) has positive power on the point's tangential velocity both
// before the step and after it (qvel) (friction fails `dissipation`, 3 rows).
TEST(MujocoFaults, SoftFrictionPushesAlongTheSliding) {
  const Scene scene = load_scene(scene_path("rot-drop-220"));
  const auto model = build_model(scene);
  MujocoWorld w(model, model->initial);
  RawMujoco raw(w, model->initial);
  for (int f = 1; f < 130; ++f) mj_step(raw.m, raw.d);
  mj_forward(raw.m, raw.d);  // frame 130's contacts at its pre-step state (mj_step repeats it)
  const std::vector<int> cs = raw.contacts(0, 70);
  ASSERT_EQ(cs.size(), 1u);
  const mjContact c = raw.d->contact[cs[0]];
  mjtNum f6[6];
  mj_contactForce(raw.m, raw.d, cs[0], f6);
  double ft[3];  // the friction force on geom2 (world)
  for (int k = 0; k < 3; ++k) ft[k] = f6[1] * c.frame[3 + k] + f6[2] * c.frame[6 + k];
  // geom2's point velocity relative to geom1's, tangential part.
  auto sliding = [&](double out[3]) {
    const std::size_t b1 = c.geom1 == raw.geom[0] ? 0 : 70, b2 = b1 == 0 ? 70 : 0;
    const std::array<double, 3> v2 = raw.point_velocity(b2, c.pos), v1 = raw.point_velocity(b1, c.pos);
    double vn = 0.0;
    for (int k = 0; k < 3; ++k) vn += (v2[k] - v1[k]) * c.frame[k];
    for (int k = 0; k < 3; ++k) out[k] = v2[k] - v1[k] - vn * c.frame[k];
  };
  double before[3], after[3];
  sliding(before);
  mj_Euler(raw.m, raw.d);  // the rest of mj_step
  sliding(after);
  const double p_before = ft[0] * before[0] + ft[1] * before[1] + ft[2] * before[2];
  const double p_after = ft[0] * after[0] + ft[1] * after[1] + ft[2] * after[2];
  const double speed_after = std::sqrt(after[0] * after[0] + after[1] * after[1] + after[2] * after[2]);
  EXPECT_GT(f6[0], 0.0);
  EXPECT_GT(p_before, 0.0) << "friction power on the sliding before the step (W)";
  EXPECT_GT(p_after, 0.0) << "friction power on the sliding after the step (W)";
  EXPECT_GT(speed_after, 0.1) << "the point still slides at 0.15 m/s";
  RecordProperty("friction_power_after_W", std::to_string(p_after));
}

// bunny-stack-50 with rotation, frame 570: bunny 8 comes down on the floor (a box, top at
// y = 0, 1.4 x 1.4 m) spinning at 10 rad/s. Its whole hull lies over the floor's top face,
// its lowest vertex 1.075 mm below it (MuJoCo's own mesh_vert, geom_xpos, geom_xmat), so
// lifting it by 1.075 mm along the face's normal separates the two. MuJoCo 2.2's convex
// collider (libccd's MPR, which searches along the line between the geoms' centres; the
// floor's centre is 0.36 m away sideways) reports one contact whose normal is 46.1 deg off
// the face's normal, tilted toward the bunny's side, with dist = -1.550 mm: the depth
// along that tilted normal (1.075 mm / cos 46.1 deg), not the minimum translation. The
// solver pushes along it: 767 N, 553 N of it sideways on a bunny that only needs lifting
// (contact-geometry fails `normal-angle`: 46.1 deg from SAT's axis, the floor's normal).
TEST(MujocoFaults, ConvexColliderTiltsAFloorNormalTowardTheFloorsCentreLine) {
  Scene scene = load_scene(scene_path("bunny-stack-50"));
  scene.rotation = true;
  const auto model = build_model(scene);
  MujocoWorld w(model, model->initial);
  RawMujoco raw(w, model->initial);
  for (int f = 1; f < 570; ++f) mj_step(raw.m, raw.d);
  mj_forward(raw.m, raw.d);  // frame 570's contacts at its pre-step state
  const std::vector<int> cs = raw.contacts(0, 8);
  ASSERT_EQ(cs.size(), 1u);
  const mjContact& c = raw.d->contact[cs[0]];
  const int gf = raw.geom[0], gb = raw.geom[8];
  ASSERT_EQ(c.geom1, gf);
  // The floor's top face: its normal (geom_xmat's y column) and height.
  const double up[3] = {raw.d->geom_xmat[9 * gf + 1], raw.d->geom_xmat[9 * gf + 4], raw.d->geom_xmat[9 * gf + 7]};
  double top = 0.0;
  for (int k = 0; k < 3; ++k) top += up[k] * raw.d->geom_xpos[3 * gf + k];
  top += raw.m->geom_size[3 * gf + 1];
  // The bunny's vertices (MuJoCo's mesh, in the geom's frame) in the world: the deepest
  // below the top face, and whether all lie over it.
  const int mesh = raw.m->geom_dataid[gb];
  double sunk = -1e300;
  bool over_the_face = true;
  for (int v = 0; v < raw.m->mesh_vertnum[mesh]; ++v) {
    const float* p = raw.m->mesh_vert + 3 * (raw.m->mesh_vertadr[mesh] + v);
    const mjtNum local[3] = {p[0], p[1], p[2]};
    mjtNum world[3];
    mju_mulMatVec(world, raw.d->geom_xmat + 9 * gb, local, 3, 3);
    for (int k = 0; k < 3; ++k) world[k] += raw.d->geom_xpos[3 * gb + k];
    double height = 0.0;
    for (int k = 0; k < 3; ++k) height += up[k] * world[k];
    sunk = std::max(sunk, top - height);
    over_the_face = over_the_face && std::fabs(world[0] - raw.d->geom_xpos[3 * gf]) < raw.m->geom_size[3 * gf] &&
                    std::fabs(world[2] - raw.d->geom_xpos[3 * gf + 2]) < raw.m->geom_size[3 * gf + 2];
  }
  const double cos_tilt = c.frame[0] * up[0] + c.frame[1] * up[1] + c.frame[2] * up[2];
  const double tilt_deg = std::acos(std::min(1.0, cos_tilt)) * 180.0 / M_PI;
  // The tilt's direction against the line from the floor's centre to the bunny's, both
  // projected on the face.
  double tilt_dir[3], centres[3], dot = 0.0, nt = 0.0, nc = 0.0;
  for (int k = 0; k < 3; ++k) {
    tilt_dir[k] = c.frame[k] - cos_tilt * up[k];
    centres[k] = raw.d->geom_xpos[3 * gb + k] - raw.d->geom_xpos[3 * gf + k];
  }
  const double along = centres[0] * up[0] + centres[1] * up[1] + centres[2] * up[2];
  for (int k = 0; k < 3; ++k) {
    centres[k] -= along * up[k];
    dot += tilt_dir[k] * centres[k];
    nt += tilt_dir[k] * tilt_dir[k];
    nc += centres[k] * centres[k];
  }
  const double toward_centre_line = dot / std::sqrt(nt * nc);
  mjtNum f6[6];
  mj_contactForce(raw.m, raw.d, cs[0], f6);
  const double sideways = f6[0] * std::sqrt(std::max(0.0, 1.0 - cos_tilt * cos_tilt));
  EXPECT_TRUE(over_the_face) << "the bunny lies over the floor's top face";
  EXPECT_GT(sunk, 0.0005);
  EXPECT_LT(sunk, 0.002) << "a 1 mm overlap: lifting the bunny by it separates the two";
  EXPECT_GT(tilt_deg, 40.0) << "MuJoCo's normal against the floor's face normal";
  EXPECT_GT(toward_centre_line, 0.9) << "tilted along the floor's centre-to-bunny line";
  EXPECT_NEAR(-c.dist, sunk / cos_tilt, 0.01 * sunk / cos_tilt) << "the depth along the tilted normal";
  EXPECT_GT(-c.dist, 1.3 * sunk) << "deeper than the minimum translation";
  EXPECT_GT(sideways, 0.5 * f6[0]) << "the normal force pushes the bunny sideways";
  RecordProperty("tilt_deg", std::to_string(tilt_deg));
  RecordProperty("tilt_cos_to_centre_line", std::to_string(toward_centre_line));
  RecordProperty("lowest_vertex_depth_m", std::to_string(sunk));
  RecordProperty("mujoco_dist_m", std::to_string(c.dist));
  RecordProperty("normal_force_N", std::to_string(f6[0]));
  RecordProperty("sideways_force_N", std::to_string(sideways));
}

// mixed-pile-1000 under MuJoCo (`octocd run` stops at frame 631: "bad number in qacc"),
// its first step, frame 476 of MuJoCo's own run: bunny 94 lies at the foot of the +z wall,
// its hull 2.2 mm past the wall's inner face and 1.0 mm above the floor. MuJoCo 2.2
// collides a hull with a box by MPR (libccd), whose search starts on the line between the
// two geoms' centres; the wall's centre is 2 m above the bunny, and the one contact it
// reports points down along the wall, 85.5 deg from the face's normal (4.4 deg from that
// line), with dist = -28.7 mm: the solver pushes the bunny into the floor with 2.36 kN.
// Witness, the bunny alone at that pose in the same open box, from MuJoCo's own data: the
// hull's vertices (mesh_vert placed by geom_xpos and geom_xmat) against the wall's box
// (geom_xpos, geom_xmat, geom_size). Moving the hull by its overlap with the box along one
// of the box's axes separates them, so the least such overlap (2.24 mm) bounds the
// penetration depth; MuJoCo's depth is more than ten times it. (In the pile the floor's
// contact, MPR again, is then 0.106 m deep along the floor's length with the hull 14.7 mm
// below its top, and the bunny leaves at 96 m/s spinning at 1618 rad/s; docs/engines.md,
// "mujoco".)
TEST(MujocoFaults, HullAtTheFootOfAWallGetsAContactAlongTheWall) {
  if (!have_dataset_mesh("bunny.obj")) GTEST_SKIP() << "datasets not fetched (run datasets/fetch.sh)";
  const Scene scene = parse_scene(
      R"({"name": "corner", "domain": {"min": [-1, 0, -1], "max": [1, 4, 1]}, "dt": 0.001, "walls": "open-box",
          "groups": [{"name": "bunny", "shape": {"mesh": "bunny", "scale": 0.12}, "count": 1, "mass": 1.1,
                      "positions": [[0.131268734, 0.0336819256, 0.952305129]],
                      "orientation": [0.358527071, -0.672032727, 0.584547757, 0.279525084]}]})",
      scene_path("corner"));
  const auto model = build_model(scene);
  ASSERT_EQ(model->bodies.size(), 6u);  // floor, -x, +x, -z, +z walls, the bunny
  MujocoWorld w(model, model->initial);
  RawMujoco raw(w, model->initial);
  mj_forward(raw.m, raw.d);
  const int gw = raw.geom[4], gb = raw.geom[5];
  const int mesh = raw.m->geom_dataid[gb];
  ASSERT_GE(mesh, 0);
  // Hull vertex v in the world: mesh_vert (float, the mesh's inertial frame) placed by the geom.
  auto hull_vertex = [&](int v, mjtNum world[3]) {
    mjtNum local[3];
    for (int k = 0; k < 3; ++k) local[k] = raw.m->mesh_vert[3 * (raw.m->mesh_vertadr[mesh] + v) + k];
    mju_mulMatVec(world, raw.d->geom_xmat + 9 * gb, local, 3, 3);
    for (int k = 0; k < 3; ++k) world[k] += raw.d->geom_xpos[3 * gb + k];
  };
  // The hull lies where octocd puts the mesh: the world AABB of MuJoCo's vertices (moved
  // into the mesh's inertial frame, placed by geom_xpos/geom_xmat) is the posed mesh's.
  {
    const Shape& shape = model->shapes[model->bodies[5].shape];
    ASSERT_TRUE(shape.mesh);
    const Pose pose{model->initial.x[5], normalized(model->initial.q[5])};
    for (int a = 0; a < 3; ++a) {
      double lo = 1e300, hi = -1e300, mlo = 1e300, mhi = -1e300;
      for (const Vec3& v : shape.mesh->vertices) {
        const double p = static_cast<double>(to_world(pose, v)[a]);
        lo = std::min(lo, p), hi = std::max(hi, p);
      }
      for (int v = 0; v < raw.m->mesh_vertnum[mesh]; ++v) {
        mjtNum world[3];
        hull_vertex(v, world);
        mlo = std::min(mlo, world[a]), mhi = std::max(mhi, world[a]);
      }
      EXPECT_NEAR(mlo, lo, 2e-6) << "axis " << a;
      EXPECT_NEAR(mhi, hi, 2e-6) << "axis " << a;
    }
  }
  // The hull's overlap with the wall's box along each of the box's axes; the least bounds
  // the penetration depth.
  double bound = 1e300, lowest = 1e300;
  int bound_axis = -1;
  for (int a = 0; a < 3; ++a) {
    const mjtNum* r = raw.d->geom_xmat + 9 * gw;  // row-major: the box's axis a is column a
    const mjtNum axis[3] = {r[a], r[3 + a], r[6 + a]};
    double lo = 1e300, hi = -1e300;
    for (int v = 0; v < raw.m->mesh_vertnum[mesh]; ++v) {
      mjtNum world[3];
      hull_vertex(v, world);
      const double p = mju_dot3(world, axis);
      lo = std::min(lo, p), hi = std::max(hi, p);
      lowest = std::min(lowest, static_cast<double>(world[1]));
    }
    const double c = mju_dot3(raw.d->geom_xpos + 3 * gw, axis), h = raw.m->geom_size[3 * gw + a];
    const double overlap = std::min(hi - (c - h), (c + h) - lo);
    if (overlap < bound) bound = overlap, bound_axis = a;
  }
  EXPECT_EQ(bound_axis, 2) << "the least overlap is across the wall (its z axis)";
  EXPECT_GT(bound, 0.0) << "the hull reaches into the wall";
  EXPECT_LT(bound, 0.003) << "by 2.2 mm";
  EXPECT_GT(lowest, 0.0) << "the hull is above the floor";
  EXPECT_TRUE(raw.contacts(0, 5).empty()) << "and has no contact with it";
  const std::vector<int> cs = raw.contacts(4, 5);
  ASSERT_EQ(cs.size(), 1u);
  const mjContact& c = raw.d->contact[cs[0]];
  ASSERT_EQ(c.geom1, gw) << "the normal points from the wall to the bunny";
  const mjtNum face[3] = {raw.d->geom_xmat[9 * gw + 2], raw.d->geom_xmat[9 * gw + 5], raw.d->geom_xmat[9 * gw + 8]};
  const double angle_deg = std::acos(std::min(1.0, std::fabs(mju_dot3(c.frame, face)))) * 180.0 / 3.14159265358979;
  mjtNum centres[3];
  mju_sub3(centres, raw.d->geom_xpos + 3 * gb, raw.d->geom_xpos + 3 * gw);
  mju_normalize3(centres);
  const double to_centres_deg = std::acos(std::min(1.0, mju_dot3(c.frame, centres))) * 180.0 / 3.14159265358979;
  mjtNum f6[6];
  mj_contactForce(raw.m, raw.d, cs[0], f6);
  EXPECT_GT(-c.dist, 10.0 * bound) << "MuJoCo's depth against the bound";
  EXPECT_GT(angle_deg, 80.0) << "the normal against the wall's face normal (deg)";
  EXPECT_LT(to_centres_deg, 10.0) << "the normal against the line between the geoms' centres (deg)";
  EXPECT_LT(c.frame[1], -0.99) << "the normal points down along the wall";
  EXPECT_GT(f6[0], 0.0) << "and MuJoCo pushes the bunny along it, into the floor";
  RecordProperty("depth_bound_m", std::to_string(bound));
  RecordProperty("mujoco_dist_m", std::to_string(c.dist));
  RecordProperty("normal_to_face_deg", std::to_string(angle_deg));
  RecordProperty("normal_to_centres_deg", std::to_string(to_centres_deg));
  RecordProperty("normal_force_N", std::to_string(f6[0]));
}

#endif  // OCTOCD_HAVE_MUJOCO

}  // namespace octocd_test_mujoco_world
