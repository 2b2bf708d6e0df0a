// octocd::BulletWorld in rotation mode (design.md section 13: octocd's own rotating reference):
// closed forms (a block sliding down a slope, a free spinning body), a stack of ten, the
// sign conventions of its manifold rows (normal from B to A, jt along -v_t), the version 2
// trace it writes, the scene keys that ask for rotation, and the translation-only mode
// left as it was.
#include <gtest/gtest.h>
#include <hdf5.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <vector>

#include "octocd/bullet_world.hpp"
#include "octocd/error.hpp"
#include "octocd/mesh.hpp"
#include "octocd/scene.hpp"
#include "octocd/trace.hpp"
#include "octocd/world.hpp"

// This file's own names (its tests compile in unity batches with the folder's other files).
namespace octocd_test_bullet_rotation {

using namespace octocd;

namespace {

std::string scene_path(const std::string& name) {
  const char* root = std::getenv("OCTOCD_SOURCE_DIR");
  return std::string(root ? root : ".") + "/datasets/scenes/" + name + ".json";
}

/// The body-frame vector v (double) in the world frame: R(q) v.
std::array<double, 3> rotate_d(const Quat& q, const std::array<double, 3>& v) {
  const double w = q.w, x = q.x, y = q.y, z = q.z;
  const double r[3][3] = {{1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)},
                          {2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)},
                          {2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)}};
  std::array<double, 3> out{};
  for (int i = 0; i < 3; ++i) out[i] = r[i][0] * v[0] + r[i][1] * v[1] + r[i][2] * v[2];
  return out;
}

/// World angular momentum R I R^T w of a body with diagonal body-frame inertia `inertia`.
std::array<double, 3> angular_momentum(const Quat& q, const Vec3& w, const std::array<float, 9>& inertia) {
  const Quat qc{q.w, -q.x, -q.y, -q.z};
  std::array<double, 3> wl = rotate_d(qc, {w.x, w.y, w.z});
  for (int k = 0; k < 3; ++k) wl[k] *= inertia[static_cast<std::size_t>(4 * k)];
  return rotate_d(q, wl);
}

double norm3(const std::array<double, 3>& a) { return std::sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2]); }

/// The InputError message of parsing `text`, or "" when it parses.
std::string parse_error(const std::string& text) {
  try {
    parse_scene(text, "rot (test)");
  } catch (const InputError& e) {
    return e.what();
  }
  return "";
}

/// A box (half extents 0.1 m, 1 kg) at height `y` (0.1 = touching a floor whose top is
/// y = 0) moving at +1 m/s along x, and a static floor 4 x 0.2 x 4 m. `box_first`: the box
/// is body 0 (A) and the floor body 1 (B); otherwise the scene's generated floor is body 0.
Scene sliding_box(bool box_first, float y) {
  const std::string box = R"({"name": "box", "shape": {"box": [0.1, 0.1, 0.1]}, "count": 1, "mass": 1.0,
      "positions": [[0.0, )" + std::to_string(y) + R"(, 0.0]], "velocity": {"type": "fixed", "value": [1.0, 0.0, 0.0]}})";
  const std::string floor = R"({"name": "ground", "shape": {"box": [2.0, 0.1, 2.0]}, "count": 1, "mass": 0,
      "positions": [[0.0, -0.1, 0.0]]})";
  const std::string text = R"({"name": "sliding-box", "domain": {"min": [-2, 0, -2], "max": [2, 2, 2]},
    "rotation": true, "walls": )" + std::string(box_first ? "\"none\"" : "\"floor\"") + R"(,
    "wall_thickness": 0.2, "response": {"mu_kinetic": 0.3, "restitution": 0.0},
    "groups": [)" + box + (box_first ? ", " + floor : std::string()) + "]}";
  return parse_scene(text, "sliding-box (test)");
}

/// Dimensions of dataset `name` ({} when absent).
std::vector<hsize_t> dims_of(hid_t file, const char* name) {
  if (H5Lexists(file, name, H5P_DEFAULT) <= 0) return {};
  const hid_t d = H5Dopen2(file, name, H5P_DEFAULT);
  const hid_t sp = H5Dget_space(d);
  std::vector<hsize_t> dims(static_cast<std::size_t>(H5Sget_simple_extent_ndims(sp)));
  H5Sget_simple_extent_dims(sp, dims.data(), nullptr);
  H5Sclose(sp);
  H5Dclose(d);
  return dims;
}

/// A numeric root attribute read as double (NaN when absent).
double attr_number(hid_t file, const char* name) {
  if (H5Aexists(file, name) <= 0) return std::nan("");
  double v = 0.0;
  const hid_t a = H5Aopen(file, name, H5P_DEFAULT);
  H5Aread(a, H5T_NATIVE_DOUBLE, &v);
  H5Aclose(a);
  return v;
}

/// A string root attribute ("" when absent).
std::string attr_string(hid_t file, const char* name) {
  if (H5Aexists(file, name) <= 0) return "";
  const hid_t a = H5Aopen(file, name, H5P_DEFAULT);
  const hid_t t = H5Tcopy(H5T_C_S1);
  H5Tset_size(t, H5T_VARIABLE);
  H5Tset_cset(t, H5T_CSET_UTF8);  // as the writer stores them
  char* p = nullptr;
  H5Aread(a, t, &p);
  std::string s = p ? p : "";
  if (p) H5free_memory(p);
  H5Tclose(t);
  H5Aclose(a);
  return s;
}

/// Runs `frames` steps of `engine` into a trace at `path` as `octocd run --trace PATH
/// --state-every 1 --contacts` does.
void write_trace(Engine& engine, const std::string& path, int frames) {
  TraceOptions topt;
  topt.state_every = 1;
  topt.contacts = engine.can_record();
  if (topt.contacts) engine.set_recording(true);
  if (const RotationTraits* t = engine.rotation_traits()) {
    topt.v2 = *t;
    topt.gravity = engine.scene().gravity;
  }
  TraceWriter trace(path, trace_metadata(engine, 1), trace_bodies(engine), topt);
  trace.append_state(0, engine.state());
  for (int f = 0; f < frames; ++f) {
    const FrameMetrics& m = engine.step();
    if (topt.v2)
      trace.append_frame_v2(m, engine.state(), engine.record());
    else
      trace.append_frame(m, engine.state(), engine.contacts());
  }
  trace.close();
}

}  // namespace

// A block on a slope of angle t with friction mu < tan t slides with a = g (sin t - mu
// cos t) along it (Coulomb, kinetic friction = the product of the bodies' sqrt(mu)).
// Fitted from the speed along the slope between 0.2 s and 0.7 s (after the 0.5 mm drop
// onto the slope); tolerance 1 % of a (measured: 2e-6 relative). The block must not tip:
// its orientation stays within 1e-3 of the slope's.
TEST(BulletRotation, SlopeSlideFollowsCoulomb) {
  const Scene scene = load_scene(scene_path("rot-slope"));
  const auto model = build_model(scene);
  BulletWorld bw(model, model->initial);
  ASSERT_TRUE(bw.rotating());
  const double t = 20.0 * M_PI / 180.0, mu = scene.response.mu_kinetic, g = 9.81;
  const double a_expected = g * (std::sin(t) - mu * std::cos(t));
  const std::size_t block = 1;
  const Quat q0 = bw.state().q[block];
  auto speed_down = [&] {
    const Vec3 v = bw.state().v[block];
    return -(v.x * std::cos(t) + v.y * std::sin(t));
  };
  double s1 = 0.0, s2 = 0.0;
  for (int f = 1; f <= 700; ++f) {
    bw.step();
    if (f == 200) s1 = speed_down();
    const Quat q = bw.state().q[block];
    ASSERT_NEAR(std::fabs(q.w * q0.w + q.x * q0.x + q.y * q0.y + q.z * q0.z), 1.0, 1e-3) << "frame " << f;
  }
  s2 = speed_down();
  const double a = (s2 - s1) / (500 * scene.dt);
  EXPECT_NEAR(a, a_expected, 0.01 * a_expected) << "fitted " << a << " m/s^2";
  RecordProperty("acceleration_relative_error", std::to_string(std::fabs(a - a_expected) / a_expected));
}

// Torque-free spin (no gravity, no contact) of a box with three different moments of
// inertia, spun mostly about y with small x, z components, so its angular velocity
// changes (by more than 1 rad/s: it tumbles): the world angular momentum R I R^T w stays
// within 1 % of its start over 2 s (measured 0.48 %: Bullet's implicit gyroscopic term,
// BT_ENABLE_GYROSCOPIC_FORCE_IMPLICIT_BODY, is a first-order step). The bound is sharp
// enough to catch an engine without the gyroscopic term (w held constant while R turns):
// that body's momentum, computed here in closed form, changes by more than twice the
// bound. Kinetic (rotational) energy must not rise by more than 0.5 %.
TEST(BulletRotation, FreeSpinKeepsAngularMomentum) {
  const Scene scene = parse_scene(R"({"name": "spin", "domain": {"min": [-1, -1, -1], "max": [1, 1, 1]},
    "gravity": [0, 0, 0], "walls": "none", "rotation": true,
    "groups": [{"name": "brick", "shape": {"box": [0.3, 0.1, 0.05]}, "count": 1, "mass": 2.0,
                "positions": [[0, 0, 0]], "angular_velocity": [0.2, 6.0, 0.1]}]})",
                                  "spin (test)");
  const Vec3 w0{0.2f, 6.0f, 0.1f};
  const auto model = build_model(scene);
  BulletWorld bw(model, model->initial);
  const std::array<float, 9> inertia = bw.rotation_traits()->inertia[0];
  EXPECT_NEAR(inertia[0], 2.0 / 12 * (0.2 * 0.2 + 0.1 * 0.1), 1e-6);  // solid box, Bullet's rule
  const Quat q0 = bw.state().q[0];
  const std::array<double, 3> l0 = angular_momentum(q0, bw.state().omega[0], inertia);
  const double bound = 0.01;
  double worst = 0.0, worst_no_gyro = 0.0, w_change = 0.0, e_first = -1.0, e_max = 0.0;
  auto relative = [&](const std::array<double, 3>& l) {
    return norm3({l[0] - l0[0], l[1] - l0[1], l[2] - l0[2]}) / norm3(l0);
  };
  for (int f = 1; f <= 2000; ++f) {
    const FrameMetrics& m = bw.step();
    worst = std::max(worst, relative(angular_momentum(bw.state().q[0], bw.state().omega[0], inertia)));
    // The faulty engine: w0 constant, so R(t) = exp(t [w0]x) R0.
    const Quat turned = axis_angle((1.0f / length(w0)) * w0, length(w0) * static_cast<float>(f) * scene.dt) * q0;
    worst_no_gyro = std::max(worst_no_gyro, relative(angular_momentum(turned, w0, inertia)));
    w_change = std::max(w_change, static_cast<double>(length(bw.state().omega[0] - w0)));
    if (e_first < 0) e_first = m.kinetic_energy;
    e_max = std::max(e_max, m.kinetic_energy);
  }
  EXPECT_GT(w_change, 0.1) << "the body must tumble for the test to mean something";
  EXPECT_GT(worst_no_gyro, 2 * bound) << "the bound would not catch a missing gyroscopic term";
  EXPECT_LT(worst, bound) << "relative change of the world angular momentum";
  EXPECT_LT(e_max, e_first * 1.005) << "rotational energy rose";
  RecordProperty("angular_momentum_relative_change", std::to_string(worst));
  RecordProperty("without_gyroscopic_term", std::to_string(worst_no_gyro));
}

// Ten boxes stacked on the floor stay up over 1 s: every centre within 2 mm of its rest
// height (0.1 + 0.2 k m), within 2 cm of the column's axis, tilted by less than 0.02 rad.
TEST(BulletRotation, StackOfTenStaysUp) {
  const Scene scene = load_scene(scene_path("rot-stack-10"));
  const auto model = build_model(scene);
  BulletWorld bw(model, model->initial);
  for (int f = 0; f < scene.frames; ++f) bw.step();
  double worst_h = 0.0;
  for (std::size_t k = 0; k < 10; ++k) {
    const std::size_t i = k + 1;  // body 0 is the floor
    const Vec3 x = bw.state().x[i];
    const Quat q = bw.state().q[i];
    worst_h = std::max(worst_h, std::fabs(x.y - (0.1 + 0.2 * static_cast<double>(k))));
    EXPECT_NEAR(x.y, 0.1 + 0.2 * static_cast<double>(k), 2e-3) << "box " << k;
    EXPECT_LT(std::hypot(x.x, x.z), 0.02) << "box " << k;
    EXPECT_LT(2.0 * std::sqrt(q.x * q.x + q.y * q.y + q.z * q.z), 0.02) << "box " << k << " tilted";
  }
  RecordProperty("worst_height_error_m", std::to_string(worst_h));
}

// The conventions of the manifold rows (V2-LAYOUT, docs/trace-format.md "Version 2"):
// a box A sliding along +x on a static floor B. With the box as body 0: pair (0, 1),
// normal (0, 1, 0) from B to A, jt > 0 (friction opposes sliding). With the floor first
// (the scene's generated floor is body 0): pair (0, 1) again, A = the floor, so the
// normal is (0, -1, 0) (Bullet's body0/body1 swapped and the normal flipped where
// needed) and jt is still > 0 (A's velocity relative to B is -x, the floor's friction
// impulse on A +x, on the box -x). In both, the box's momentum change along x is -sum jt
// (the friction impulse on A is +jt along -v_t/|v_t|, on B its opposite), every row is
// at the cone (jt = mu jn, kinetic friction while sliding), and the points lie on the
// box's bottom face (y = 0 within 1 mm).
TEST(BulletRotation, NormalAndJtSignOnASlidingBox) {
  for (const bool box_first : {true, false}) {
    SCOPED_TRACE(box_first ? "box is body 0" : "floor is body 0");
    const auto model = build_model(sliding_box(box_first, 0.0995f));  // 0.5 mm into the floor
    BulletWorld bw(model, model->initial);
    ASSERT_TRUE(bw.can_record());
    bw.set_recording(true);
    const std::size_t box = box_first ? 0 : 1;
    const double mu = 0.3;
    double impulse_x = 0.0;
    int rows = 0;
    for (int f = 0; f < 20; ++f) {
      const double v_before = bw.state().v[box].x;
      bw.step();
      const FrameRecord& r = bw.record();
      ASSERT_TRUE(r.manifolds && r.has_points && !r.has_contact_terms);
      double jt_sum = 0.0;
      for (const ContactRecord& c : r.contacts) {
        ASSERT_EQ(c.pair, (Pair{0, 1}));
        const float ny = box_first ? 1.0f : -1.0f;
        EXPECT_NEAR(c.normal.x, 0.0, 1e-5);
        EXPECT_NEAR(c.normal.y, ny, 1e-5);
        EXPECT_GT(c.jn, 0.0f);
        EXPECT_GT(c.jt, 0.0f) << "friction must oppose the sliding";
        EXPECT_NEAR(c.jt, mu * c.jn, 1e-3 * c.jn + 1e-7) << "kinetic friction at the cone";
        EXPECT_NEAR(c.point.y, 0.0, 1e-3);
        jt_sum += c.jt;
        ++rows;
      }
      const double dp = (bw.state().v[box].x - v_before) * 1.0;  // 1 kg
      EXPECT_NEAR(dp, -jt_sum, 1e-5) << "frame " << f + 1;
      impulse_x += dp;
    }
    EXPECT_GT(rows, 20);
    EXPECT_LT(impulse_x, -0.01);  // friction slowed the box down
  }
}

// `octocd run --engine bullet --rotation --trace F --state-every 1 --contacts` (the same
// calls): a version 2 trace with every dataset and attribute of V2-LAYOUT in its shape.
// A translation-only Bullet trace of the same bodies stays version 1 without them.
TEST(BulletRotation, TraceVersion2HasEveryDataset) {
  namespace fs = std::filesystem;
  H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr);  // absent datasets are probed on purpose
  const std::string path = (fs::temp_directory_path() / "octocd-test-rot-drop.h5").string();
  Scene scene = load_scene(scene_path("rot-drop-220"));
  const int frames = 30;
  const auto model = build_model(scene);
  const std::size_t n = model->initial.size();
  std::size_t rows = 0;
  {
    BulletWorld bw(model, model->initial);
    write_trace(bw, path, frames);
  }
  {
    const hid_t f = H5Fopen(path.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT);
    ASSERT_GE(f, 0);
    const hsize_t F = static_cast<hsize_t>(frames), N = n;
    EXPECT_EQ(attr_number(f, "version"), 2.0);
    EXPECT_EQ(attr_string(f, "format"), "octocd-trace");
    EXPECT_EQ(attr_string(f, "engine"), "bullet");
    EXPECT_EQ(attr_string(f, "detection"), "pre-step");
    EXPECT_EQ(attr_string(f, "friction_combine"), "product");
    EXPECT_EQ(attr_string(f, "restitution_combine"), "product");
    EXPECT_EQ(attr_string(f, "contact_geometry"), "shape");
    EXPECT_NEAR(attr_number(f, "mu"), 0.5, 1e-6);
    EXPECT_NEAR(attr_number(f, "restitution"), 0.2, 1e-6);
    EXPECT_NEAR(attr_number(f, "contact_margin"), std::sqrt(2.0) * 0.02 + 0.001, 1e-6);  // sqrt(2) x 0.02 threshold + 1 mm float32
    EXPECT_EQ(attr_number(f, "broadphase_exact"), 0.0);
    EXPECT_EQ(dims_of(f, "/states/position"), (std::vector<hsize_t>{F + 1, N, 3}));
    EXPECT_EQ(dims_of(f, "/states/velocity"), (std::vector<hsize_t>{F + 1, N, 3}));
    EXPECT_EQ(dims_of(f, "/states/orientation"), (std::vector<hsize_t>{F + 1, N, 4}));
    EXPECT_EQ(dims_of(f, "/states/angular_velocity"), (std::vector<hsize_t>{F + 1, N, 3}));
    EXPECT_EQ(dims_of(f, "/states/frame"), (std::vector<hsize_t>{F + 1}));
    EXPECT_EQ(dims_of(f, "/bodies/inertia"), (std::vector<hsize_t>{N, 3, 3}));
    EXPECT_EQ(dims_of(f, "/bodies/friction"), (std::vector<hsize_t>{N}));
    EXPECT_EQ(dims_of(f, "/bodies/restitution"), (std::vector<hsize_t>{N}));
    EXPECT_EQ(dims_of(f, "/bodies/local_aabb_min"), (std::vector<hsize_t>{N, 3}));
    EXPECT_EQ(dims_of(f, "/aabbs/min"), (std::vector<hsize_t>{F, N, 3}));
    EXPECT_EQ(dims_of(f, "/aabbs/max"), (std::vector<hsize_t>{F, N, 3}));
    EXPECT_EQ(dims_of(f, "/pairs/offsets"), (std::vector<hsize_t>{F + 1}));
    EXPECT_EQ(dims_of(f, "/contacts/offsets"), (std::vector<hsize_t>{F + 1}));
    const std::vector<hsize_t> pair = dims_of(f, "/contacts/pair");
    ASSERT_EQ(pair.size(), 2u);
    rows = pair[0];
    for (const char* d : {"/contacts/normal", "/contacts/point"})
      EXPECT_EQ(dims_of(f, d), (std::vector<hsize_t>{rows, 3})) << d;
    for (const char* d : {"/contacts/depth", "/contacts/jn", "/contacts/jt"})
      EXPECT_EQ(dims_of(f, d), (std::vector<hsize_t>{rows})) << d;
    EXPECT_EQ(dims_of(f, "/pairs/pair").size(), 2u);
    H5Fclose(f);
  }
  EXPECT_GT(rows, 0u) << "bodies placed near the floor must touch it within 30 frames";
  // Translation-only in box mode (shape=box; hull mode records and writes version 2):
  // version 1, none of the version 2 datasets.
  {
    scene.rotation = false;
    for (GroupSpec& g : scene.groups) g.orientation = Quat{};
    const auto flat_model = build_model(scene);
    BulletSettings boxes;
    boxes.shape = BulletShape::Box;
    BulletWorld bw(flat_model, flat_model->initial, BulletOptions(), boxes);
    EXPECT_FALSE(bw.rotating());
    write_trace(bw, path, 3);
    const hid_t f = H5Fopen(path.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT);
    ASSERT_GE(f, 0);
    EXPECT_EQ(attr_number(f, "version"), 1.0);
    for (const char* d : {"/states/orientation", "/states/angular_velocity", "/bodies/inertia", "/aabbs/min",
                          "/pairs/pair", "/contacts/point"})
      EXPECT_TRUE(dims_of(f, d).empty()) << d;
    EXPECT_TRUE(std::isnan(attr_number(f, "contact_margin")));
    H5Fclose(f);
  }
  std::error_code ec;
  fs::remove(path, ec);
}

// The records: pre/post states, the pre-step detection pose, pairs sorted a < b with no
// static-static pair, every contact pair among the candidates, rows of a pair
// consecutive, unit normals, depth >= 0, jn >= 0, and every confirmed pair has rows.
TEST(BulletRotation, RecordsFollowTheConventions) {
  const Scene scene = load_scene(scene_path("rot-drop-220"));
  const auto model = build_model(scene);
  BulletWorld bw(model, model->initial);
  bw.set_recording(true);
  std::size_t contact_rows = 0;
  for (int f = 1; f <= 150; ++f) {
    const std::vector<Vec3> x_before = bw.state().x;
    const std::vector<Quat> q_before = bw.state().q;
    bw.step();
    const FrameRecord& r = bw.record();
    ASSERT_EQ(r.frame, f);
    ASSERT_EQ(r.x_pre.size(), x_before.size());
    for (std::size_t i = 0; i < x_before.size(); ++i) {
      ASSERT_EQ(r.x_pre[i], x_before[i]);
      ASSERT_EQ(r.x_det[i], x_before[i]);
      ASSERT_EQ(r.q_det[i].w, q_before[i].w);
      ASSERT_EQ(r.x_post[i], bw.state().x[i]);
    }
    for (std::size_t k = 0; k < r.pairs.size(); ++k) {
      ASSERT_LT(r.pairs[k].a, r.pairs[k].b);
      if (k > 0) {
        ASSERT_TRUE(r.pairs[k - 1] < r.pairs[k]);
      }
      ASSERT_FALSE(model->initial.w[r.pairs[k].a] == 0.0f && model->initial.w[r.pairs[k].b] == 0.0f);
    }
    for (std::size_t k = 0; k < r.contacts.size(); ++k) {
      const ContactRecord& c = r.contacts[k];
      ASSERT_TRUE(std::binary_search(r.pairs.begin(), r.pairs.end(), c.pair)) << "contact pair not a candidate";
      if (k > 0) {
        ASSERT_FALSE(c.pair < r.contacts[k - 1].pair) << "rows not sorted by pair";
      }
      ASSERT_NEAR(length(c.normal), 1.0f, 1e-3f);
      ASSERT_GE(c.depth, 0.0f);
      ASSERT_GE(c.jn, 0.0f);
      ++contact_rows;
    }
    for (const Pair& p : r.confirmed) {
      ASSERT_TRUE(std::any_of(r.contacts.begin(), r.contacts.end(), [&](const ContactRecord& c) { return c.pair == p; }));
    }
  }
  EXPECT_GT(contact_rows, 100u);
}

// Scene keys: orientation as a quaternion or axis + angle, angular_velocity; bad values
// name the key and the range; cpu refuses a rotating scene and names the key.
TEST(BulletRotation, SceneKeysAndRefusals) {
  const std::string head = R"({"name": "k", "domain": {"min": [-1, 0, -1], "max": [1, 2, 1]}, )";
  const std::string group = R"("groups": [{"shape": {"box": [0.1, 0.1, 0.1]}, "count": 1, )";
  const Scene ok = parse_scene(head + group + R"("orientation": {"axis": [0, 0, 2], "angle_deg": 90}}]})", "k");
  EXPECT_NEAR(ok.groups[0].orientation.w, std::sqrt(0.5), 1e-6);
  EXPECT_NEAR(ok.groups[0].orientation.z, std::sqrt(0.5), 1e-6);
  EXPECT_TRUE(scene_rotates(ok));
  EXPECT_FALSE(ok.rotation);
  const Scene q = parse_scene(head + group + R"("orientation": [0, 1, 0, 0], "angular_velocity": [1, 2, 3]}]})", "k");
  EXPECT_EQ(q.groups[0].orientation.x, 1.0f);
  EXPECT_EQ(q.groups[0].angular_velocity, (Vec3{1, 2, 3}));
  EXPECT_FALSE(scene_rotates(parse_scene(head + group + R"("orientation": [1, 0, 0, 0]}]})", "k")));

  std::string e = parse_error(head + group + R"("orientation": [1, 1, 0, 0]}]})");
  EXPECT_NE(e.find("groups[0].orientation"), std::string::npos) << e;
  EXPECT_NE(e.find("unit quaternion"), std::string::npos) << e;
  e = parse_error(head + group + R"("orientation": {"axis": [0, 1, 0], "angle_deg": 400}}]})");
  EXPECT_NE(e.find("groups[0].orientation.angle_deg"), std::string::npos) << e;
  EXPECT_NE(e.find("[-360, 360]"), std::string::npos) << e;
  e = parse_error(head + group + R"("orientation": {"axis": [0, 0, 0], "angle_deg": 10}}]})");
  EXPECT_NE(e.find("groups[0].orientation.axis"), std::string::npos) << e;
  e = parse_error(head + group + R"("angular_velocity": [0, 2000, 0]}]})");
  EXPECT_NE(e.find("groups[0].angular_velocity[1]"), std::string::npos) << e;
  EXPECT_NE(e.find("rad/s"), std::string::npos) << e;
  e = parse_error(head + R"("rotation": 1, )" + group + R"("mass": 1}]})");
  EXPECT_NE(e.find("rotation: expected true or false"), std::string::npos) << e;

  // cpu (World) refuses, naming the key and pointing to --engine bullet.
  const Scene spin = parse_scene(head + group + R"("angular_velocity": [0, 1, 0]}]})", "spin.json");
  try {
    World world(build_model(spin), make_broadphase(spin.broadphase, spin.domain));
    ADD_FAILURE() << "World took a rotating scene";
  } catch (const InputError& err) {
    const std::string m = err.what();
    EXPECT_NE(m.find("groups[0].angular_velocity"), std::string::npos) << m;
    EXPECT_NE(m.find("--engine bullet"), std::string::npos) << m;
  }
  EXPECT_THROW(World(load_scene(scene_path("rot-slope"))), InputError);
}

// Translation-only Bullet in box mode (shape=box, asked for explicitly: the default hull
// mode records) is as before: no rotation traits, no records, no orientations, its
// midphase name, and a scene without rotation keys builds no orientations. In hull mode
// it records, with traits that say the bodies do not rotate, and still no orientations.
TEST(BulletRotation, TranslationOnlyModeUnchanged) {
  const Scene scene = load_scene(scene_path("box-stack"));
  EXPECT_FALSE(scene_rotates(scene));
  const auto model = build_model(scene);
  EXPECT_TRUE(model->initial.q.empty());
  EXPECT_TRUE(model->initial.omega.empty());
  {
    BulletWorld hull(model, model->initial);
    EXPECT_FALSE(hull.rotating());
    EXPECT_TRUE(hull.can_record());
    ASSERT_NE(hull.rotation_traits(), nullptr);
    EXPECT_FALSE(hull.rotation_traits()->rotates);
    EXPECT_EQ(hull.midphase_name(), "bullet-convex");
    hull.set_recording(true);
    for (int f = 0; f < 50; ++f) hull.step();
    EXPECT_TRUE(hull.state().q.empty());
    EXPECT_TRUE(hull.record().q_pre.empty());
  }
  BulletSettings boxes;
  boxes.shape = BulletShape::Box;
  BulletWorld bw(model, model->initial, BulletOptions(), boxes);
  EXPECT_FALSE(bw.rotating());
  EXPECT_FALSE(bw.can_record());
  EXPECT_EQ(bw.rotation_traits(), nullptr);
  EXPECT_EQ(bw.midphase_name(), "bullet-box-box");
  bw.set_recording(true);
  for (int f = 0; f < 50; ++f) bw.step();
  EXPECT_TRUE(bw.contacts().empty());
  EXPECT_TRUE(bw.state().q.empty());
  EXPECT_TRUE(bw.record().contacts.empty());
}

// Stock Bullet leaves friction on rows whose normal impulse fell to 0 (it solves a friction
// row only while its contact's normal impulse is positive): outside the Coulomb cone.
// BulletOptions::coulomb_friction (the default) brings those rows back to 0. Oracle: the
// cone itself, per contact (a pair's rows summed, as the physics tier judges it).
TEST(BulletRotation, FrictionStaysInTheConeOnlyWithTheProjection) {
  const Scene scene = load_scene(scene_path("rot-drop-220"));
  const auto model = build_model(scene);
  const double mu = scene.response.mu_kinetic;
  auto outside_cone = [&](bool project, std::int64_t* projections) {
    BulletOptions options;
    options.coulomb_friction = project;
    BulletWorld bw(model, model->initial, options);
    bw.set_recording(true);
    int outside = 0;
    for (int f = 1; f <= 200; ++f) {
      bw.step();
      const std::vector<ContactRecord>& c = bw.record().contacts;
      for (std::size_t k0 = 0, k1 = 0; k0 < c.size(); k0 = k1) {
        double jt = 0.0, jn = 0.0;
        for (k1 = k0; k1 < c.size() && c[k1].pair == c[k0].pair; ++k1) {
          jt += std::fabs(double(c[k1].jt));
          jn += double(c[k1].jn);
        }
        if (jt > mu * jn * (1.0 + 1e-4) + 1e-7) ++outside;
      }
    }
    *projections = bw.friction_projections();
    return outside;
  };
  std::int64_t stock_projections = -1, projections = -1;
  const int stock = outside_cone(false, &stock_projections);
  const int projected = outside_cone(true, &projections);
  EXPECT_GT(stock, 0) << "stock Bullet kept no stale friction in 200 frames (the fault this guards against)";
  EXPECT_EQ(stock_projections, 0);
  EXPECT_EQ(projected, 0);
  EXPECT_GT(projections, 0);
}

namespace {

/// Separation (m) of body 0 (a box of half extents `he`) from body 1 (an icosphere of
/// radius 0.07 m, 2 subdivisions) along the unit normal n (from 1 to 0), by brute force
/// over the box's corners and the icosphere's vertices: min n.a - max n.b.
double separation_along(const Vec3& n, const BodyState& s, const std::array<double, 3>& he) {
  const Mesh sphere = make_icosphere(0.07f, 2);
  double min_a = 1e30, max_b = -1e30;
  for (int k = 0; k < 8; ++k) {
    const std::array<double, 3> c = rotate_d(s.q[0], {(k & 1) ? he[0] : -he[0], (k & 2) ? he[1] : -he[1],
                                                       (k & 4) ? he[2] : -he[2]});
    min_a = std::min(min_a, n.x * (c[0] + s.x[0].x) + n.y * (c[1] + s.x[0].y) + n.z * (c[2] + s.x[0].z));
  }
  for (const Vec3& v : sphere.vertices) {
    const std::array<double, 3> c = rotate_d(s.q[1], {v.x, v.y, v.z});
    max_b = std::max(max_b, n.x * (c[0] + s.x[1].x) + n.y * (c[1] + s.x[1].y) + n.z * (c[2] + s.x[1].z));
  }
  return min_a - max_b;
}

}  // namespace

// Bullet 3.24's GJK on a box against a convex hull can report the shapes apart along a
// normal on which they overlap: a slab and an icosphere of rot-drop-220 (bodies 89 and
// 208 at frame 64, the poses copied bit for bit) come out 6.3 mm apart along a normal on
// which they overlap by 0.5 mm (the polytopes are 0.77 mm apart). Stock GJK/EPA writes
// that row; the checked narrow phase (BulletOptions::checked_narrowphase, on by default)
// replaces it by the separating-axis contact, consistent with the brute-force separation.
TEST(BulletRotation, CheckedNarrowphaseReplacesAWrongGjkContact) {
  const Scene scene = parse_scene(R"({"name": "slab-sphere", "domain": {"min": [-2, -2, -2], "max": [2, 3, 2]},
    "rotation": true, "walls": "none", "gravity": [0, 0, 0],
    "groups": [{"name": "slab", "shape": {"box": [0.08, 0.04, 0.06]}, "count": 1, "mass": 1.0, "positions": [[0, 0, 0]]},
               {"name": "sphere", "shape": {"icosphere": {"radius": 0.07, "subdivisions": 2}}, "count": 1,
                "mass": 1.0, "positions": [[0, 1, 0]]}]})",
                                  "slab-sphere (test)");
  const auto model = build_model(scene);
  BodyState s = model->initial;
  ASSERT_EQ(s.size(), 2u);
  s.q.resize(2);
  s.omega.resize(2);
  s.x[0] = {0x1.652172p-3f, 0x1.4bb1a2p+0f, 0x1.b1f9fep-3f};
  s.q[0] = {0x1.d906bep-1f, 0.0f, 0x1.1517a6p-2f, 0x1.1517a6p-2f};
  s.x[1] = {0x1.cf583ep-9f, 0x1.4ee1aep+0f, 0x1.abbffap-3f};
  s.q[1] = {0x1.f3dd14p-1f, 0x1.bb4498p-3f, 0.0f, 0.0f};
  const std::array<double, 3> he{0.08, 0.04, 0.06};
  const double tol = 2e-4;
  for (const bool checked : {false, true}) {
    SCOPED_TRACE(checked ? "checked narrow phase" : "stock GJK/EPA");
    BulletOptions opt;
    opt.checked_narrowphase = checked;
    BulletWorld bw(model, s, opt);
    bw.set_recording(true);
    bw.step();
    const FrameRecord& r = bw.record();
    ASSERT_FALSE(r.contacts.empty());
    double worst = 0.0;  // the largest overlap along a row's normal beyond its depth
    for (const ContactRecord& c : r.contacts) {
      const double sep = separation_along(c.normal, s, he);
      worst = std::max(worst, -sep - c.depth);
      if (checked) {
        EXPECT_GE(sep, -c.depth - tol) << "row normal overlaps beyond its depth";
        if (c.depth > 0.0f) {
          EXPECT_NEAR(sep, -c.depth, tol);
        }
      }
    }
    const BulletNarrowphaseCounts n = bw.narrowphase_counts();
    if (checked) {
      EXPECT_GE(n.replaced, 1);
      EXPECT_GE(n.checked, n.replaced);
    } else {
      EXPECT_GT(worst, 3e-4) << "stock GJK must show its wrong row here (else the test proves nothing)";
      EXPECT_EQ(n.checked, 0);
    }
  }
}

}  // namespace octocd_test_bullet_rotation
