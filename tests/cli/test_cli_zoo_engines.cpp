// A zoo of engines unlike octocd's (issue 30 item 7, design.md section 13b.12): small plain programs
// that step their own bodies and write a version 2 external trace, judged by `octocd
// validate --trace-in` at default tolerances. Each clean run passes every physics row
// (exit 0) once it declares what it is; the same run undeclared fails the row the
// declaration is about; each planted fault (a lone body's velocity x1.5 / x2, a body
// teleported by 1 cm, an angular velocity x1.5 on a lone spinning body, an orientation
// turned by 30 deg, a dropped manifold row, an edited velocity of a body in contact, an
// impulse on the wrong body) exits 3 with a detail naming the frame and the body.
//  (a) soft contacts: a damped penalty spring lets two boxes penetrate by ~4 mm and
//      pushes them apart over ~10 steps (contact_model "soft");
//  (c) a gyroscopic term: a flat box spinning about a non-principal axis bounces off the
//      floor, another spins alone (gyroscopic "true"; judged by the invariants of free
//      rotation, it passes undeclared too and fails declared "false");
//  (d) joints locking rotation: a box sliding on the floor on a 4-row manifold and two
//      boxes colliding off-centre in the air keep w = 0 (/bodies/locked_dofs = 0x38);
//  (f) convex hulls of concave meshes: an L-shaped bar lands turning on the hull of a
//      U-shaped channel, across its hollow (collision_shape "convex_hull"); declared as
//      the meshes, its rows are false contacts.
//  (g) substeps: n semi-implicit substeps per step (integrator "substepped", `substeps` n):
//      a free body advances by x + dt v + (n + 1) / (2n) g dt^2; a flat box bounces on the
//      floor turning (its rows' normal and points turn within the step).
//  (k) an integrator of the body origin: a bunny whose centre of mass lies 2.4 cm from its
//      body frame's origin lands spinning, another spins alone; the engine advances the
//      origin (MuJoCo's free joint: integrated_point "origin").
//  (l) two witness points per row: two boxes meet face to face in the air, each row's
//      impulse applied at a point on each body 3 cm apart across the normal
//      (/contacts/point_b).
//  (j) a pile of 30 boxes in 15 columns whose top boxes bounce on the bottom ones: with
//      the rows of each ended contact's last impulse dropped (contacts_complete 0, judged
//      on the geometry), and with every impulse reported 0.2% or 2% low (the systematic
//      ratio momentum-balance fits).
#include <gtest/gtest.h>
#include <hdf5.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iostream>
#include <map>
#include <random>
#include <regex>
#include <set>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "support/cli_run.hpp"
#include "octocd/engine.hpp"
#include "octocd/reference_contact.hpp"
#include "octocd/scene.hpp"

// This file's own names (its tests compile in unity batches with the folder's other files).
namespace octocd_test_cli_zoo_engines {

namespace fs = std::filesystem;
using octocd::build_model;
using octocd::CollisionShape;
using octocd::parse_scene;
using octocd::ReferenceGeometry;
using octocd::test::Result;
using octocd::test::run_octocd;

namespace {

using V = std::array<double, 3>;
using Q = std::array<double, 4>;  // (w, x, y, z)
using M = std::array<double, 9>;  // row-major

V operator+(V a, V b) { return {a[0] + b[0], a[1] + b[1], a[2] + b[2]}; }
V operator-(V a, V b) { return {a[0] - b[0], a[1] - b[1], a[2] - b[2]}; }
V operator*(double s, V a) { return {s * a[0], s * a[1], s * a[2]}; }
double dot(V a, V b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
V cross(V a, V b) { return {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]}; }
double norm(V a) { return std::sqrt(dot(a, a)); }
V mul(const M& m, V v) {
  return {m[0] * v[0] + m[1] * v[1] + m[2] * v[2], m[3] * v[0] + m[4] * v[1] + m[5] * v[2],
          m[6] * v[0] + m[7] * v[1] + m[8] * v[2]};
}
Q qmul(Q a, Q b) {
  return {a[0] * b[0] - a[1] * b[1] - a[2] * b[2] - a[3] * b[3], a[0] * b[1] + a[1] * b[0] + a[2] * b[3] - a[3] * b[2],
          a[0] * b[2] - a[1] * b[3] + a[2] * b[0] + a[3] * b[1], a[0] * b[3] + a[1] * b[2] - a[2] * b[1] + a[3] * b[0]};
}
Q qnorm(Q q) {
  const double n = std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
  return {q[0] / n, q[1] / n, q[2] / n, q[3] / n};
}
/// The rotation of `angle` rad about `axis` (any length > 0).
Q axis_angle(V axis, double angle) {
  const V u = (1.0 / norm(axis)) * axis;
  const double s = std::sin(0.5 * angle);
  return {std::cos(0.5 * angle), s * u[0], s * u[1], s * u[2]};
}
M rotation(Q q) {
  const double w = q[0], x = q[1], y = q[2], z = q[3];
  return {1 - 2 * (y * y + z * z), 2 * (x * y - w * z),     2 * (x * z + w * y),
          2 * (x * y + w * z),     1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
          2 * (x * z - w * y),     2 * (y * z + w * x),     1 - 2 * (x * x + y * y)};
}
/// R M R^T.
M conj(const M& r, const M& m) {
  M rm{}, out{};
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j)
      for (int k = 0; k < 3; ++k) rm[3 * i + j] += r[3 * i + k] * m[3 * k + j];
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j)
      for (int k = 0; k < 3; ++k) out[3 * i + j] += rm[3 * i + k] * r[3 * j + k];
  return out;
}
M diag(V d) { return {d[0], 0, 0, 0, d[1], 0, 0, 0, d[2]}; }
/// Rounds to float32, as the engine stores its state.
double f32(double x) { return static_cast<double>(static_cast<float>(x)); }
V f32(V a) { return {f32(a[0]), f32(a[1]), f32(a[2])}; }
Q f32(Q q) { return {f32(q[0]), f32(q[1]), f32(q[2]), f32(q[3])}; }

/// One body of a zoo engine: a box of half extents `h`, mass m (0: static), its locked
/// degrees of freedom (design.md section 13b.12 bits).
struct Body {
  V h{0.1, 0.1, 0.1};
  double m = 1.0;
  unsigned locked = 0;
  M inertia() const {
    const double a = 2 * h[0], b = 2 * h[1], c = 2 * h[2], k = m / 12.0;
    return diag({k * (b * b + c * c), k * (a * a + c * c), k * (a * a + b * b)});
  }
};
/// The static floor of the zoo's engines: a 4 x 0.2 x 4 m box, its top at y = 0 when
/// placed at (0, -0.1, 0).
Body floor_body() {
  Body floor;
  floor.h = {2, 0.1, 2};
  floor.m = 0;
  return floor;
}
struct State {
  std::vector<V> x, v, w;
  std::vector<Q> q;
};
/// One contact row: impulse jn along n (from B to A) on A, friction jt along -v_t.
struct Row {
  int a = 0, b = 0;
  V n{}, p{};
  V pb{};  ///< the point on B where B's impulse acts (written as /contacts/point_b with Zoo::point_b)
  double depth = 0, jn = 0, jt = 0;
};

/// A zoo engine's run: bodies, states (row 0 the initial one), contact rows per step,
/// and what the engine declares (root attributes).
struct Zoo {
  std::string engine;
  std::vector<Body> bodies;
  double dt = 0.001;
  V g{0, -9.81, 0};
  std::vector<State> states;
  std::vector<std::vector<Row>> rows;
  std::map<std::string, std::string> text;
  // Each zoo engine's friction is one impulse along -v_t per row (jt, no jt3): declared.
  std::map<std::string, double> numbers{
      {"mu", 0.5}, {"restitution", 0.5}, {"contact_margin", 0.005}, {"friction_directions", 1}};
  bool write_locked = true;
  /// Writes each row's Row::pb as /contacts/point_b (two witness points per row).
  bool point_b = false;
  std::size_t hull_vertices = 0;  // (f): the L's hull vertex count
  /// States written every `state_every`-th frame (with /states/frame), as `octocd run
  /// --state-every K` writes them; contacts every frame.
  int state_every = 1;
  /// Extra /bodies datasets (float): n values, or n x 3 when 3n.
  std::map<std::string, std::vector<double>> body_floats;
  /// Per body its centre of mass in the body frame (m; empty: the box centre). The run
  /// simulates the centres of mass (x, v); write() gives the body frame's origin x - R c
  /// (and, with text velocity_at "origin", its velocity v - w x R c) and, with
  /// `write_com`, /bodies/com_offset.
  std::vector<V> com_offset;
  bool write_com = true;
  /// The states are the body frame's origin already (its position and velocity, as an
  /// engine integrating the origin keeps them: origin_engine): written as they are.
  bool states_at_origin = false;

  int n() const { return static_cast<int>(bodies.size()); }
  M inertia_world(int i, const State& s) const { return conj(rotation(s.q[i]), bodies[i].inertia()); }

  /// Free motion of body i over one step from `s`: v + g dt, w less the gyroscopic term
  /// when `gyroscopic`, then (after the caller's impulses) x + dt v', q advanced by w' dt.
  void integrate_velocity(int i, const State& s, State& t, bool gyroscopic) const {
    if (bodies[i].m == 0) return;
    t.v[i] = s.v[i] + dt * g;
    t.w[i] = s.w[i];
    if (gyroscopic) {
      const M iw = inertia_world(i, s);
      const M inv = conj(rotation(s.q[i]), diag({1 / bodies[i].inertia()[0], 1 / bodies[i].inertia()[4],
                                                 1 / bodies[i].inertia()[8]}));
      t.w[i] = s.w[i] - dt * mul(inv, cross(s.w[i], mul(iw, s.w[i])));
    }
  }
  void integrate_position(int i, const State& s, State& t) const {
    t.v[i] = f32(t.v[i]);
    t.w[i] = f32(t.w[i]);
    if (bodies[i].m == 0) return;
    t.x[i] = f32(s.x[i] + dt * t.v[i]);
    const double angle = norm(t.w[i]) * dt;
    t.q[i] = f32(angle > 0 ? qnorm(qmul(axis_angle(t.w[i], angle), s.q[i])) : s.q[i]);
  }

  /// Substeps per step (0: one update per step, as above). With n > 0 the step is the
  /// contacts' impulses at its start (found at the pre-step pose), then n semi-implicit
  /// substeps of dt / n: v += g h, w less the gyroscopic term h I_w^-1 (w x I_w w) when
  /// `gyroscopic`, x += h v, q advanced by w h (Rapier's, PhysX TGS's scheme).
  int substeps = 0;
  void substep(int i, const State& s, State& t, bool gyroscopic) const {
    if (bodies[i].m == 0) return;
    const double h = dt / substeps;
    V v = t.v[i] - dt * g, w = t.w[i], x = s.x[i];  // t: after gravity (dt) and the contacts
    Q q = s.q[i];
    const M body = bodies[i].inertia();
    for (int k = 0; k < substeps; ++k) {
      v = v + h * g;
      if (gyroscopic) {
        const M r = rotation(q), iw = conj(r, body), inv = conj(r, diag({1 / body[0], 1 / body[4], 1 / body[8]}));
        w = w - h * mul(inv, cross(w, mul(iw, w)));
      }
      x = x + h * v;
      const double angle = norm(w) * h;
      if (angle > 0) q = qnorm(qmul(axis_angle(w, angle), q));
    }
    t.v[i] = f32(v);
    t.w[i] = f32(w);
    t.x[i] = f32(x);
    t.q[i] = f32(q);
  }

  /// Steps the run `frames` times from its last state: gravity (and the gyroscopic term
  /// when `gyroscopic`) on every body, then `contacts(s, t, rows)` (s the state before the
  /// step, t the state being stepped, the step's rows), then the positions (or `substeps`).
  void run(int frames, bool gyroscopic,
           const std::function<void(const State&, State&, std::vector<Row>&)>& contacts) {
    for (int f = 1; f <= frames; ++f) {
      const State s = states.back();
      State t = s;
      std::vector<Row> step;
      for (int i = 0; i < n(); ++i) integrate_velocity(i, s, t, gyroscopic && substeps == 0);
      contacts(s, t, step);
      for (int i = 0; i < n(); ++i) substeps > 0 ? substep(i, s, t, gyroscopic) : integrate_position(i, s, t);
      states.push_back(t);
      rows.push_back(step);
    }
  }

  /// Writes the run as an external trace, version 2 (docs/trace-format.md).
  void write(const std::string& path) const {
    const hid_t file = H5Fcreate(path.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT);
    ASSERT_GE(file, 0) << path;
    const hid_t lcpl = H5Pcreate(H5P_LINK_CREATE);
    H5Pset_create_intermediate_group(lcpl, 1);
    auto put = [&](const char* name, hid_t mem, hid_t type, std::vector<hsize_t> shape, const void* data) {
      const hid_t space = H5Screate_simple(static_cast<int>(shape.size()), shape.data(), nullptr);
      const hid_t d = H5Dcreate2(file, name, type, space, lcpl, H5P_DEFAULT, H5P_DEFAULT);
      ASSERT_GE(d, 0) << name;
      if (shape[0] > 0) {
        ASSERT_GE(H5Dwrite(d, mem, H5S_ALL, H5S_ALL, H5P_DEFAULT, data), 0) << name;
      }
      H5Dclose(d);
      H5Sclose(space);
    };
    auto floats = [&](const char* name, std::vector<hsize_t> shape, const std::vector<double>& v) {
      put(name, H5T_NATIVE_DOUBLE, H5T_IEEE_F32LE, shape, v.data());
    };
    auto str_attr = [&](const char* name, const std::string& value) {
      const hid_t t = H5Tcopy(H5T_C_S1);
      H5Tset_size(t, H5T_VARIABLE);
      const hid_t space = H5Screate(H5S_SCALAR);
      const hid_t a = H5Acreate2(file, name, t, space, H5P_DEFAULT, H5P_DEFAULT);
      const char* c = value.c_str();
      H5Awrite(a, t, &c);
      H5Aclose(a);
      H5Sclose(space);
      H5Tclose(t);
    };
    auto num_attr = [&](const char* name, const std::vector<double>& v) {
      const hsize_t count = v.size();
      const hid_t space = count == 1 ? H5Screate(H5S_SCALAR) : H5Screate_simple(1, &count, nullptr);
      const hid_t a = H5Acreate2(file, name, H5T_IEEE_F64LE, space, H5P_DEFAULT, H5P_DEFAULT);
      H5Awrite(a, H5T_NATIVE_DOUBLE, v.data());
      H5Aclose(a);
      H5Sclose(space);
    };
    str_attr("format", "octocd-trace");
    str_attr("engine", engine);
    {  // an integer, as docs/trace-format.md says (a float version is refused)
      const hid_t space = H5Screate(H5S_SCALAR);
      const hid_t a = H5Acreate2(file, "version", H5T_STD_I32LE, space, H5P_DEFAULT, H5P_DEFAULT);
      const int two = 2;
      H5Awrite(a, H5T_NATIVE_INT, &two);
      H5Aclose(a);
      H5Sclose(space);
    }
    num_attr("dt", {dt});
    num_attr("gravity", {g[0], g[1], g[2]});
    for (const auto& [k, v] : text) str_attr(k.c_str(), v);
    for (const auto& [k, v] : numbers) num_attr(k.c_str(), {v});
    const hsize_t nb = static_cast<hsize_t>(n()), frames = rows.size();
    std::vector<double> lo, hi, im, inertia;
    std::vector<std::uint8_t> locked;
    for (const Body& b : bodies) {
      for (int k = 0; k < 3; ++k) {
        lo.push_back(-b.h[k]);
        hi.push_back(b.h[k]);
      }
      im.push_back(b.m > 0 ? 1.0 / b.m : 0.0);
      const M I = b.m > 0 ? b.inertia() : M{};
      inertia.insert(inertia.end(), I.begin(), I.end());
      locked.push_back(static_cast<std::uint8_t>(b.locked));
    }
    floats("/bodies/local_aabb_min", {nb, 3}, lo);
    floats("/bodies/local_aabb_max", {nb, 3}, hi);
    floats("/bodies/inverse_mass", {nb}, im);
    floats("/bodies/inertia", {nb, 3, 3}, inertia);
    if (write_locked) put("/bodies/locked_dofs", H5T_NATIVE_UINT8, H5T_STD_U8LE, {nb}, locked.data());
    if (!com_offset.empty() && write_com) {
      std::vector<double> c;
      for (const V& o : com_offset) c.insert(c.end(), o.begin(), o.end());
      floats("/bodies/com_offset", {nb, 3}, c);
    }
    for (const auto& [name, values] : body_floats)
      floats(name.c_str(), values.size() == nb ? std::vector<hsize_t>{nb} : std::vector<hsize_t>{nb, 3}, values);
    std::vector<double> x, v, w, q;
    std::vector<std::int64_t> state_frame;
    for (std::size_t f = 0; f < states.size(); f += static_cast<std::size_t>(state_every)) {
      const State& s = states[f];
      state_frame.push_back(static_cast<std::int64_t>(f));
      for (int i = 0; i < n(); ++i) {
        V xi = s.x[i], vi = s.v[i];
        if (!com_offset.empty() && !states_at_origin) {  // the body frame's origin, c behind the centre of mass
          const V rc = mul(rotation(s.q[i]), com_offset[i]);
          xi = xi - rc;
          const auto at = text.find("velocity_at");
          if (at != text.end() && at->second == "origin") vi = vi - cross(s.w[i], rc);
        }
        x.insert(x.end(), xi.begin(), xi.end());
        v.insert(v.end(), vi.begin(), vi.end());
        w.insert(w.end(), s.w[i].begin(), s.w[i].end());
        q.insert(q.end(), s.q[i].begin(), s.q[i].end());
      }
    }
    const hsize_t rows_n = state_frame.size();
    if (state_every > 1)
      put("/states/frame", H5T_NATIVE_INT64, H5T_STD_I64LE, {rows_n}, state_frame.data());
    floats("/states/position", {rows_n, nb, 3}, x);
    floats("/states/velocity", {rows_n, nb, 3}, v);
    floats("/states/orientation", {rows_n, nb, 4}, q);
    floats("/states/angular_velocity", {rows_n, nb, 3}, w);
    // Candidate pairs: every pair with a dynamic body, every step (a conservative broadphase).
    std::vector<std::int64_t> pair_offsets{0}, pairs;
    for (hsize_t f = 0; f < frames; ++f) {
      for (int a = 0; a < n(); ++a)
        for (int b = a + 1; b < n(); ++b)
          if (bodies[a].m > 0 || bodies[b].m > 0) {
            pairs.push_back(a);
            pairs.push_back(b);
          }
      pair_offsets.push_back(static_cast<std::int64_t>(pairs.size() / 2));
    }
    put("/pairs/offsets", H5T_NATIVE_INT64, H5T_STD_I64LE, {pair_offsets.size()}, pair_offsets.data());
    put("/pairs/pair", H5T_NATIVE_INT64, H5T_STD_I64LE, {pairs.size() / 2, 2}, pairs.data());
    std::vector<std::int64_t> offsets{0}, cpair;
    std::vector<double> normal, point, point_on_b, depth, jn, jt;
    for (const auto& step : rows) {
      for (const Row& r : step) {
        cpair.push_back(r.a);
        cpair.push_back(r.b);
        normal.insert(normal.end(), r.n.begin(), r.n.end());
        point.insert(point.end(), r.p.begin(), r.p.end());
        point_on_b.insert(point_on_b.end(), r.pb.begin(), r.pb.end());
        depth.push_back(r.depth);
        jn.push_back(r.jn);
        jt.push_back(r.jt);
      }
      offsets.push_back(static_cast<std::int64_t>(cpair.size() / 2));
    }
    const hsize_t c = cpair.size() / 2;
    put("/contacts/offsets", H5T_NATIVE_INT64, H5T_STD_I64LE, {offsets.size()}, offsets.data());
    put("/contacts/pair", H5T_NATIVE_INT64, H5T_STD_I64LE, {c, 2}, cpair.data());
    floats("/contacts/normal", {c, 3}, normal);
    floats("/contacts/point", {c, 3}, point);
    if (point_b) floats("/contacts/point_b", {c, 3}, point_on_b);
    floats("/contacts/depth", {c}, depth);
    floats("/contacts/jn", {c}, jn);
    floats("/contacts/jt", {c}, jt);
    H5Pclose(lcpl);
    H5Fclose(file);
  }
};

State initial(const Zoo& z, const std::vector<V>& x, const std::vector<V>& v, const std::vector<V>& w,
              const std::vector<Q>& q) {
  State s;
  s.x = x;
  s.v = v;
  s.w = w;
  s.q = q;
  for (int i = 0; i < z.n(); ++i) {
    s.x[i] = f32(s.x[i]);
    s.v[i] = f32(s.v[i]);
    s.w[i] = f32(s.w[i]);
    s.q[i] = f32(s.q[i]);
  }
  return s;
}

/// A damped penalty spring along x between boxes a and b (half extent 0.1 along x, b on
/// a's +x side, equal y and z), found at the pre-step pose `s`: depth d = 0.2 - (x_b - x_a),
/// impulse jn = max(0, (k d + c v_close) dt) with v_close from `free` (the velocities after
/// gravity); the row's normal -x, its point midway between the faces. Applies jn to `t` (1 kg
/// each; a static a is not moved) and appends the row; nothing when the boxes are apart.
void x_spring(const Zoo& z, const State& s, const State& free, State& t, int a, int b, double k, double c,
              std::vector<Row>& rows) {
  const double d = 0.2 - (s.x[b][0] - s.x[a][0]);
  if (!(d > 0)) return;
  Row r;
  r.a = a;
  r.b = b;
  r.n = {-1, 0, 0};
  r.depth = f32(d);
  r.p = f32(V{0.5 * (s.x[a][0] + 0.1 + s.x[b][0] - 0.1), s.x[b][1], s.x[b][2]});
  const double closing = free.v[a][0] - free.v[b][0];
  r.jn = f32(std::max(0.0, (k * d + c * closing) * z.dt));
  if (z.bodies[a].m > 0) t.v[a] = t.v[a] + r.jn * r.n;
  t.v[b] = t.v[b] - r.jn * r.n;
  rows.push_back(r);
}

/// (a) Soft contacts: boxes 0 and 1 (1 kg) meet head-on in the air at 2 m/s and a
/// damped penalty spring (k = 125 kN/m, c = 50 N s/m) pushes them apart: ~4 mm deep, over
/// ~12 steps, its kinetic energy rising in the steps that release the penetration; body 2
/// spins alone. Boxes 3, 4 and 5 in a row (4 and 5 1 mm apart) make one 3-body episode: 3
/// hits 4 at 1 m/s, 4 meets 5 while 3 still presses it, and the three separate; its
/// springs' damping is `chain_c` (a negative value feeds energy in: a planted fault).
/// Contacts found at the pre-step pose, impulses jn = (k d + c v_close) dt, every spring's
/// from the velocities after gravity.
Zoo soft_engine(int frames = 60, double chain_c = 50) {
  Zoo z;
  z.engine = "zoo-soft";
  z.bodies = {Body{}, Body{}, Body{}, Body{}, Body{}, Body{}};
  z.text["contact_model"] = "soft";
  const double k = 125000, c = 50;
  z.states.push_back(initial(
      z, {{-0.13, 1.0, 0}, {0.13, 1.0, 0}, {0, 2.0, 1.0}, {-0.21, 1.0, -1.0}, {0, 1.0, -1.0}, {0.201, 1.0, -1.0}},
      {{1, 0, 0}, {-1, 0, 0}, {0.2, 0.5, 0}, {1, 0, 0}, {0, 0, 0}, {0, 0, 0}},
      {{0, 0, 0}, {0, 0, 0}, {1, 2, 0}, {0, 0, 0}, {0, 0, 0}, {0, 0, 0}},
      {{1, 0, 0, 0}, {1, 0, 0, 0}, axis_angle({0, 0, 1}, 0.3), {1, 0, 0, 0}, {1, 0, 0, 0}, {1, 0, 0, 0}}));
  const std::vector<std::array<int, 2>> springs{{0, 1}, {3, 4}, {4, 5}};
  z.run(frames, false, [&](const State& s, State& t, std::vector<Row>& rows) {
    const State after_gravity = t;
    for (const auto& [a, b] : springs) x_spring(z, s, after_gravity, t, a, b, k, a == 0 ? c : chain_c, rows);
  });
  return z;
}

/// (a) Soft contacts whose isolated episode may begin in contact: no gravity; a static wall
/// (body 0, x = 0) and boxes 1 and 2 (1 kg) moving away from it at 1 m/s along x, box 2 2 mm
/// into box 1. `from_wall`: box 1 starts 0.5 mm into the wall, so the first step's group
/// touches a static body and the pair's spring is loaded before box 1 leaves the wall; the
/// pair's isolated episode begins at frame 2 with the spring still compressed, and its
/// release raises the pair's mechanical energy although the damped spring (c = 50 N s/m)
/// loses energy. Otherwise box 1 starts 1 mm off the wall and box 2 1 mm behind box 1,
/// closing at 1 m/s: the pair's episode begins with its first contact. The pair's spring
/// has damping `c` (negative: a planted fault); k = 125 kN/m as soft_engine's.
Zoo soft_released_engine(bool from_wall, double c, int frames = 40) {
  Zoo z;
  z.engine = "zoo-soft-released";
  Body wall;
  wall.m = 0;
  z.bodies = {wall, Body{}, Body{}};
  z.g = {0, 0, 0};
  z.text["contact_model"] = "soft";
  const double k = 125000;
  const std::vector<V> x = from_wall ? std::vector<V>{{0, 1, 0}, {0.1995, 1, 0}, {0.3975, 1, 0}}
                                     : std::vector<V>{{0, 1, 0}, {0.201, 1, 0}, {0.402, 1, 0}};
  const std::vector<V> v = from_wall ? std::vector<V>{{0, 0, 0}, {1, 0, 0}, {1, 0, 0}}
                                     : std::vector<V>{{0, 0, 0}, {1, 0, 0}, {0, 0, 0}};
  z.states.push_back(initial(z, x, v, {{0, 0, 0}, {0, 0, 0}, {0, 0, 0}}, {{1, 0, 0, 0}, {1, 0, 0, 0}, {1, 0, 0, 0}}));
  z.run(frames, false, [&](const State& s, State& t, std::vector<Row>& rows) {
    const State free = t;
    for (const auto& [a, b] : std::vector<std::array<int, 2>>{{0, 1}, {1, 2}})
      x_spring(z, s, free, t, a, b, k, a == 0 ? 50 : c, rows);
  });
  return z;
}

/// The 8 corners of a box of half extents h, body frame.
std::vector<V> box_corners(V h) {
  std::vector<V> out;
  for (int c = 0; c < 8; ++c) out.push_back({(c & 1 ? 1 : -1) * h[0], (c & 2 ? 1 : -1) * h[1], (c & 4 ? 1 : -1) * h[2]});
  return out;
}

/// Rows of body i's `vertices` (body frame; default: its box's corners) against the floor
/// (body 0, top at y = 0) at state s, resolved one after the other on t's velocities
/// (restitution e, no friction): each row's impulse is applied at its vertex to v and w
/// (rotation locked: v only).
void floor_corners(const Zoo& z, int i, const State& s, State& t, std::vector<Row>& rows, double e,
                   const std::vector<V>& vertices = {}) {
  const Body& b = z.bodies[i];
  const M r = rotation(s.q[i]);
  const M iw_inv = conj(r, diag({1 / b.inertia()[0], 1 / b.inertia()[4], 1 / b.inertia()[8]}));
  const bool spin = (b.locked >> 3) == 0;
  for (const V& local : vertices.empty() ? box_corners(b.h) : vertices) {
    const V arm = mul(r, local);
    const V corner = s.x[i] + arm;
    if (!(corner[1] < 0)) continue;
    Row row;
    row.a = 0;
    row.b = i;
    row.n = {0, -1, 0};
    row.depth = f32(-corner[1]);
    row.p = f32(V{corner[0], 0.5 * corner[1], corner[2]});
    const V lever = row.p - s.x[i];
    const V vp = t.v[i] + cross(t.w[i], lever);
    const double vn = vp[1];  // (v_A - v_B) . n with A the static floor, n = -y
    if (vn < 0) {
      const V rn = cross(lever, V{0, 1, 0});
      const double kk = 1 / b.m + (spin ? dot(rn, mul(iw_inv, rn)) : 0.0);
      row.jn = f32(-(1 + e) * vn / kk);
      t.v[i] = t.v[i] + (row.jn / b.m) * V{0, 1, 0};
      if (spin) t.w[i] = t.w[i] + mul(iw_inv, cross(lever, row.jn * V{0, 1, 0}));
    }
    rows.push_back(row);
  }
}

/// (c) A gyroscopic term: body 1, a flat box (0.4 x 0.2 x 0.1 m, 1 kg) spinning about a
/// non-principal axis, falls onto the floor and bounces off its corners; body 2, the same
/// box, spins alone. Free rotation: w' = w - dt I_w^-1 (w x I_w w) (explicit, I_w at the
/// pre-step orientation), then q advanced by w' dt.
Zoo gyroscopic_engine(int frames = 200) {
  Zoo z;
  z.engine = "zoo-gyroscopic";
  Body floor;
  floor.h = {2, 0.1, 2};
  floor.m = 0;
  Body flat;
  flat.h = {0.2, 0.1, 0.05};
  z.bodies = {floor, flat, flat};
  z.text["gyroscopic"] = "true";
  z.states.push_back(initial(z, {{0, -0.1, 0}, {0, 0.22, 0}, {1.2, 1.5, 0.5}}, {{0, 0, 0}, {0, 0, 0}, {0, 1, 0}},
                             {{0, 0, 0}, {2, 5, 1}, {3, 6, 2}},
                             {{1, 0, 0, 0}, axis_angle({1, 1, 0}, 0.5), axis_angle({0, 1, 1}, 0.2)}));
  z.run(frames, true, [&](const State& s, State& t, std::vector<Row>& rows) {
    floor_corners(z, 1, s, t, rows, 0.5);
    floor_corners(z, 2, s, t, rows, 0.5);
  });
  return z;
}

/// (h) Off-centre bodies: gyroscopic_engine's flat boxes with their centres of mass
/// (3, -2, 1) cm off the box centre (a weight inside; the inertia about the centre of mass
/// is the uniform box's): body 1 falls turning onto the floor and bounces on its corners
/// (their levers from the centre of mass), body 2 spins alone. The run simulates the centres
/// of mass; the trace gives the body frame's origin (MuJoCo's free joint), declared by
/// /bodies/com_offset and velocity_at "com".
Zoo com_engine(int frames = 200) {
  Zoo z;
  z.engine = "zoo-off-centre";
  Body floor;
  floor.h = {2, 0.1, 2};
  floor.m = 0;
  Body flat;
  flat.h = {0.2, 0.1, 0.05};
  z.bodies = {floor, flat, flat};
  const V c{0.03, -0.02, 0.01};
  z.com_offset = {{0, 0, 0}, c, c};
  z.text["gyroscopic"] = "true";
  z.text["velocity_at"] = "com";
  std::vector<V> corners;  // the box's corners from the centre of mass
  for (const V& k : box_corners(flat.h)) corners.push_back(k - c);
  z.states.push_back(initial(z, {{0, -0.1, 0}, {0, 0.25, 0}, {1.2, 1.5, 0.5}}, {{0, 0, 0}, {0, 0, 0}, {0, 1, 0}},
                             {{0, 0, 0}, {2, 5, 1}, {3, 6, 2}},
                             {{1, 0, 0, 0}, axis_angle({1, 1, 0}, 0.5), axis_angle({0, 1, 1}, 0.2)}));
  z.run(frames, true, [&](const State& s, State& t, std::vector<Row>& rows) {
    floor_corners(z, 1, s, t, rows, 0.5, corners);
    floor_corners(z, 2, s, t, rows, 0.5, corners);
  });
  return z;
}

/// (k) An engine that integrates the body frame's origin (MuJoCo's free joint): two
/// bunnies (scale 0.2, 1 kg, their inertia about the centre of mass the uniform local
/// box's) whose centre of mass lies c = (2, -1, 1) cm from the body origin (a weight
/// inside), collided as their convex hulls on a static floor box (top at y = 0). Body 1
/// falls turning and bounces on its hull vertices (e = 0.3, frictionless, resolved one
/// after the other, levers from the centre of mass); body 2 spins alone. Per step at dt =
/// 1/240 s, from the state at the step's start (r = origin - centre of mass = -R c): the
/// explicit gyroscopic term a = -I_w^-1 (w x I_w w), w' = w + dt a, the origin's velocity
/// v_o' = v_o + dt (g + a x r + w x (w x r)) (its exact acceleration at the start), each
/// row's impulse J at arm p - x_c moving v_o by J / m + (I_w^-1 (arm x J)) x r, then x_o' =
/// x_o + dt v_o' and q advanced by w' dt: a consistent first-order integrator of the
/// origin, whose centre of mass drifts by O(dt^2). The states are the origin's
/// (velocity_at "origin"). The trace's scene gives the meshes (collision_shape
/// "convex_hull").
Zoo origin_engine(const fs::path& dir, int frames = 150) {
  Zoo z;
  z.engine = "zoo-origin";
  z.dt = 1.0 / 240.0;
  z.text["scene"] = R"({"name": "zoo-origin", "rotation": true, "dt": 0.004166666666666667, "frames": )" +
                    std::to_string(frames) +
                    R"(, "walls": "none", "gravity": [0, -9.81, 0], "domain": {"min": [-3, -1, -3], "max": [3, 6, 3]},
    "groups": [
      {"name": "floor", "shape": {"box": [2, 0.1, 2]}, "count": 1, "mass": 0, "positions": [[0, -0.1, 0]]},
      {"name": "bunnies", "shape": {"mesh": "bunny", "scale": 0.2}, "count": 2, "mass": 1,
       "positions": [[0, 0.3, 0], [1.2, 2.0, 0.5]]}]})";
  const auto model = build_model(parse_scene(z.text["scene"], (dir / "zoo-origin.json").string()));
  const octocd::Aabb box = model->local_box(1);
  Body bunny;
  bunny.h = {0.5 * (double(box.max.x) - box.min.x), 0.5 * (double(box.max.y) - box.min.y),
             0.5 * (double(box.max.z) - box.min.z)};
  z.bodies = {floor_body(), bunny, bunny};
  const ReferenceGeometry hulls(*model, {CollisionShape::Mesh, CollisionShape::ConvexHull, CollisionShape::ConvexHull});
  std::vector<V> hull;
  for (const auto& p : hulls.hull_features(1).vertices) hull.push_back({p[0], p[1], p[2]});
  const V c{0.02, -0.01, 0.01};
  z.com_offset = {{0, 0, 0}, c, c};
  z.states_at_origin = true;
  z.text["velocity_at"] = "origin";
  z.text["integrated_point"] = "origin";
  z.text["gyroscopic"] = "true";
  z.text["integrator"] = "semi-implicit";
  z.text["collision_shape"] = "convex_hull";
  z.states.push_back(initial(z, {{0, -0.1, 0}, {0, 0.3, 0}, {1.2, 2.0, 0.5}}, {{0, 0, 0}, {0.2, -0.5, 0}, {0, 1, 0}},
                             {{0, 0, 0}, {4, 9, 3}, {10, 6, 4}},
                             {{1, 0, 0, 0}, axis_angle({1, 0.5, 0.2}, 0.7), axis_angle({0, 1, 1}, 0.2)}));
  const double e = 0.3;
  for (int f = 1; f <= frames; ++f) {
    const State s = z.states.back();
    State t = s;
    std::vector<Row> step;
    for (int i = 1; i < z.n(); ++i) {
      const Body& b = z.bodies[i];
      const M rot = rotation(s.q[i]);
      const M iw = conj(rot, b.inertia());
      const M iw_inv = conj(rot, diag({1 / b.inertia()[0], 1 / b.inertia()[4], 1 / b.inertia()[8]}));
      const V r = -1.0 * mul(rot, c);  // origin - centre of mass
      const V w = s.w[i];
      const V a = -1.0 * mul(iw_inv, cross(w, mul(iw, w)));
      V w1 = w + z.dt * a;
      V v1 = s.v[i] + z.dt * (z.g + cross(a, r) + cross(w, cross(w, r)));
      const V xc = s.x[i] - r;
      for (const V& local : i == 1 ? hull : std::vector<V>{}) {
        const V p = s.x[i] + mul(rot, local);
        if (!(p[1] < 0)) continue;
        Row row;
        row.a = 0;
        row.b = i;
        row.n = {0, -1, 0};
        row.depth = f32(-p[1]);
        row.p = f32(V{p[0], 0.5 * p[1], p[2]});
        const V arm = row.p - xc;
        const V vp = (v1 - cross(w1, r)) + cross(w1, arm);  // the point's velocity from the centre of mass
        if (vp[1] < 0) {
          const V rn = cross(arm, V{0, 1, 0});
          row.jn = f32(-(1 + e) * vp[1] / (1 / b.m + dot(rn, mul(iw_inv, rn))));
          const V dw = mul(iw_inv, cross(arm, row.jn * V{0, 1, 0}));
          w1 = w1 + dw;
          v1 = v1 + (row.jn / b.m) * V{0, 1, 0} + cross(dw, r);
        }
        step.push_back(row);
      }
      t.v[i] = f32(v1);
      t.w[i] = f32(w1);
      t.x[i] = f32(s.x[i] + z.dt * t.v[i]);
      const double angle = norm(t.w[i]) * z.dt;
      t.q[i] = f32(angle > 0 ? qnorm(qmul(axis_angle(t.w[i], angle), s.q[i])) : s.q[i]);
    }
    z.states.push_back(t);
    z.rows.push_back(step);
  }
  return z;
}

/// The largest drift of body i's centre of mass off free flight over z's steps without
/// rows on it: |v_c' - v_c - g dt| with v_c = v_o + w x R c (m/s; z integrates the origin).
double com_drift(const Zoo& z, int i) {
  double worst = 0;
  for (std::size_t f = 1; f < z.states.size(); ++f) {
    bool free = true;
    for (const Row& r : z.rows[f - 1]) free = free && r.a != i && r.b != i;
    if (!free) continue;
    auto vc = [&](const State& s) { return s.v[i] + cross(s.w[i], mul(rotation(s.q[i]), z.com_offset[i])); };
    worst = std::max(worst, norm(vc(z.states[f]) - vc(z.states[f - 1]) - z.dt * z.g));
  }
  return worst;
}

/// (g) Substeps: `n` semi-implicit substeps per step of `dt` (Zoo::substep), declared
/// integrator "substepped" with `substeps` n and the gyroscopic term. `floor`: a flat box
/// (body 1) falls turning onto the floor (body 0) and bounces on its corner rows (a small
/// pile), else body 1 falls free too; bodies 2 (spinning about a non-principal axis) and 3
/// (not spinning) fall free. A free body advances by x + dt v + (n + 1) / (2n) g dt^2.
Zoo substepped_engine(int n, double dt, int frames, bool floor) {
  Zoo z;
  z.engine = "zoo-substepped";
  z.dt = dt;
  z.substeps = n;
  Body ground;
  ground.h = {2, 0.1, 2};
  ground.m = 0;
  Body flat;
  flat.h = {0.2, 0.1, 0.05};
  z.bodies = {ground, flat, flat, Body{}};
  z.text["gyroscopic"] = "true";
  z.text["integrator"] = "substepped";
  z.numbers["substeps"] = n;
  const double up = floor ? 0.0 : 3.0;  // a free fall of 1 s stays above the floor
  z.states.push_back(initial(z, {{0, -0.1, 0}, {0, floor ? 0.22 : 6.0, 0}, {1.2, 3.5 + up, 0.5}, {-1.2, 3.0 + up, 0.5}},
                             {{0, 0, 0}, {0, 0, 0}, {0, 1, 0}, {0.3, 0.5, 0}}, {{0, 0, 0}, {2, 5, 1}, {3, 6, 2}, {0, 0, 0}},
                             {{1, 0, 0, 0}, axis_angle({1, 1, 0}, 0.5), axis_angle({0, 1, 1}, 0.2), {1, 0, 0, 0}}));
  z.run(frames, true, [&](const State& s, State& t, std::vector<Row>& rows) {
    if (floor) floor_corners(z, 1, s, t, rows, 0.5);
  });
  return z;
}

/// (d) Joints locking rotation (locked_dofs 0x38 on bodies 1-3): box 1 slides on the floor
/// on 4 corner rows (0.5 mm deep, Coulomb friction mu 0.5 along -v_t), boxes 2 (1 kg) and
/// 3 (2 kg) collide in the air 5 cm off their line of centres (e = 0.5, one impulse at the
/// face centre of their overlap); none turns. Body 4, a cube, spins alone.
Zoo locked_engine(int frames = 80) {
  Zoo z;
  z.engine = "zoo-joints";
  Body locked;
  locked.locked = 0x38;
  Body heavy = locked;
  heavy.m = 2;
  z.bodies = {floor_body(), locked, locked, heavy, Body{}};
  const double mu = 0.5, e = 0.5;
  z.states.push_back(initial(z, {{0, -0.1, 0}, {-1.0, 0.0995, 0}, {0, 1.0, 0}, {0.23, 1.05, 0}, {1.2, 1.5, 0.8}},
                             {{0, 0, 0}, {1.5, 0, 0}, {1, 0, 0}, {-1, 0, 0}, {0, 0.3, 0}},
                             {{0, 0, 0}, {0, 0, 0}, {0, 0, 0}, {0, 0, 0}, {1, 2, 3}},
                             {{1, 0, 0, 0}, {1, 0, 0, 0}, {1, 0, 0, 0}, {1, 0, 0, 0}, axis_angle({1, 0, 0}, 0.4)}));
  z.run(frames, false, [&](const State& s, State& t, std::vector<Row>& rows) {
    // Box 1 on the floor: the 4 bottom corners carry m g dt and Coulomb friction.
    {
      const double jn = f32(z.bodies[1].m * 9.81 * z.dt / 4);
      const double vx = t.v[1][0];
      const double total = std::min(mu * 4 * jn, z.bodies[1].m * std::fabs(vx));
      const double jt = f32(total / 4);
      for (int c = 0; c < 4; ++c) {
        Row r;
        r.a = 0;
        r.b = 1;
        r.n = {0, -1, 0};
        r.depth = f32(0.1 - s.x[1][1]);
        r.p = f32(V{s.x[1][0] + (c & 1 ? 0.1 : -0.1), -0.5 * r.depth, (c & 2 ? 0.1 : -0.1)});
        r.jn = jn;
        r.jt = vx != 0 ? jt : 0.0;
        // On B (the box): -J = jn y + jt along v_t (A's -v_t: A is the static floor).
        t.v[1] = t.v[1] + (r.jn / z.bodies[1].m) * V{0, 1, 0} - (r.jt / z.bodies[1].m) * V{vx > 0 ? 1.0 : -1.0, 0, 0};
        rows.push_back(r);
      }
    }
    // Boxes 2 and 3: face contact along x.
    const double d = 0.2 - (s.x[3][0] - s.x[2][0]);
    if (d > 0) {
      Row r;
      r.a = 2;
      r.b = 3;
      r.n = {-1, 0, 0};
      r.depth = f32(d);
      r.p = f32(V{0.5 * (s.x[2][0] + 0.1 + s.x[3][0] - 0.1), 0.5 * (s.x[2][1] + s.x[3][1]), 0.0});
      const double vn = dot(t.v[2] - t.v[3], r.n);
      if (vn < 0) {
        r.jn = f32(-(1 + e) * vn / (1 / z.bodies[2].m + 1 / z.bodies[3].m));
        t.v[2] = t.v[2] + (r.jn / z.bodies[2].m) * r.n;
        t.v[3] = t.v[3] - (r.jn / z.bodies[3].m) * r.n;
      }
      rows.push_back(r);
    }
  });
  return z;
}

/// A prism as a triangle mesh (OBJ): the polygon `profile` (x, y; counter-clockwise)
/// extruded along z over [0, depth]; `caps`: convex quads of profile indices tiling it.
void write_prism_obj(const fs::path& path, const std::vector<std::array<double, 2>>& profile,
                     const std::vector<std::array<int, 4>>& caps, double depth) {
  std::ofstream out(path);
  const int k = static_cast<int>(profile.size());
  for (double zc : {0.0, depth})
    for (const auto& p : profile) out << "v " << p[0] << ' ' << p[1] << ' ' << zc << '\n';
  for (const auto& c : caps) {  // OBJ indices from 1: front (z = 0, facing -z), back (+z)
    out << "f " << c[0] + 1 << ' ' << c[3] + 1 << ' ' << c[2] + 1 << '\n' << "f " << c[0] + 1 << ' ' << c[2] + 1
        << ' ' << c[1] + 1 << '\n';
    out << "f " << c[0] + k + 1 << ' ' << c[1] + k + 1 << ' ' << c[2] + k + 1 << '\n'
        << "f " << c[0] + k + 1 << ' ' << c[2] + k + 1 << ' ' << c[3] + k + 1 << '\n';
  }
  for (int i = 0; i < k; ++i) {  // sides, facing out of the counter-clockwise profile
    const int j = (i + 1) % k;
    out << "f " << i + 1 << ' ' << j + 1 << ' ' << j + k + 1 << '\n' << "f " << i + 1 << ' ' << j + k + 1 << ' '
        << i + k + 1 << '\n';
  }
}

/// (f) Convex hulls of concave meshes: a static U-shaped channel (body 0: 0.8 x 0.3 x
/// 0.6 m, its hollow 0.6 m wide and 0.2 m deep, top at y = 0) and an L-shaped bar (body 1:
/// 0.2 x 0.15 x 0.06 m, 1 kg) dropped turning onto it; body 2, another L, spins alone.
/// The engine collides convex hulls, computed by btConvexHullComputer (octocd's
/// ReferenceGeometry::hull_features): the U's hull is its bounding box, so the L lands on
/// the lid across the hollow, where the U itself has nothing. Its rows are the L's hull
/// vertices below the lid (frictionless, e = 0.2, resolved one after the other at each
/// vertex, as floor_corners). Declares collision_shape "convex_hull"; the trace's scene
/// gives the meshes (OBJ files in `dir`).
Zoo hull_engine(const fs::path& dir, int frames = 200) {
  const fs::path u = dir / "u-channel.obj", l = dir / "l-bar.obj";
  write_prism_obj(u, {{0, 0}, {0.8, 0}, {0.8, 0.3}, {0.7, 0.3}, {0.7, 0.1}, {0.1, 0.1}, {0.1, 0.3}, {0, 0.3}},
                  {{0, 1, 4, 5}, {1, 2, 3, 4}, {0, 5, 6, 7}}, 0.6);
  write_prism_obj(l, {{0, 0}, {0.2, 0}, {0.2, 0.05}, {0.05, 0.05}, {0.05, 0.15}, {0, 0.15}},
                  {{0, 1, 2, 3}, {0, 3, 4, 5}}, 0.06);
  Zoo z;
  z.engine = "zoo-hulls";
  const Body bar{{0.1, 0.075, 0.03}};  // 1 kg
  z.bodies = {Body{{0.4, 0.15, 0.3}, 0.0}, bar, bar};
  const std::vector<V> x0{{0, -0.15, 0}, {0.05, 0.14, 0.02}, {1.5, 1.0, 0}};
  z.text["collision_shape"] = "convex_hull";
  z.text["scene"] = R"({"name": "zoo-hulls", "rotation": true, "dt": 0.001, "frames": )" + std::to_string(frames) +
                    R"(, "walls": "none", "gravity": [0, -9.81, 0], "domain": {"min": [-2, -1, -2], "max": [3, 3, 2]},
    "groups": [
      {"name": "channel", "shape": {"mesh": ")" + u.string() + R"(", "scale": 0.8}, "count": 1, "mass": 0,
       "positions": [[0, -0.15, 0]]},
      {"name": "bars", "shape": {"mesh": ")" + l.string() + R"(", "scale": 0.2}, "count": 2, "mass": 1,
       "positions": [[0.05, 0.14, 0.02], [1.5, 1.0, 0]]}]})";
  const auto model = build_model(parse_scene(z.text["scene"], (dir / "zoo-hulls.json").string()));
  const ReferenceGeometry hulls(*model, std::vector<CollisionShape>(3, CollisionShape::ConvexHull));
  std::vector<V> bar_hull;
  for (const auto& p : hulls.hull_features(1).vertices) bar_hull.push_back({p[0], p[1], p[2]});
  z.states.push_back(initial(z, x0, {{0, 0, 0}, {0.1, -0.5, 0}, {0, 0.5, 0}}, {{0, 0, 0}, {3, 2, 5}, {1, 2, 3}},
                             {{1, 0, 0, 0}, axis_angle({1, 0.5, 0.2}, 0.7), axis_angle({0, 0, 1}, 0.3)}));
  z.run(frames, false, [&](const State& s, State& t, std::vector<Row>& rows) {
    floor_corners(z, 1, s, t, rows, 0.2, bar_hull);
  });
  z.hull_vertices = bar_hull.size();
  return z;
}

/// The first step (1-based) with a row on pair (a, b) and a normal impulse.
int first_impulse(const Zoo& z, int a, int b) {
  for (std::size_t f = 0; f < z.rows.size(); ++f)
    for (const Row& r : z.rows[f])
      if (r.a == a && r.b == b && r.jn > 0) return static_cast<int>(f) + 1;
  return -1;
}

class ZooEngines : public ::testing::Test {
 protected:
  fs::path dir_;
  void SetUp() override {
    dir_ = fs::temp_directory_path() /
           ("octocd-zoo-" + std::to_string(::getpid()) + "-" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::create_directories(dir_);
  }
  void TearDown() override {
    std::error_code ec;
    fs::remove_all(dir_, ec);
  }
  Result judge(const Zoo& z, const std::string& tag) {
    const fs::path p = dir_ / (tag + ".h5");
    z.write(p.string());
    return run_octocd("validate --trace-in " + p.string());
  }
};

/// Every physics row passes or is n/a; lists the table on failure.
void expect_clean(const Result& r) {
  EXPECT_EQ(r.code, 0) << r.output;
  EXPECT_EQ(r.output.find("FAIL"), std::string::npos) << r.output;
}

/// Exit 3 and every fragment in the output.
void expect_caught(const Result& r, const std::vector<std::string>& fragments) {
  EXPECT_EQ(r.code, 3) << r.output;
  for (const std::string& f : fragments) EXPECT_NE(r.output.find(f), std::string::npos) << f << "\n" << r.output;
}

TEST_F(ZooEngines, SoftContactsPassDeclaredOrUndeclaredAndFailDeclaredRigid) {
  const Zoo z = soft_engine();
  ASSERT_GT(first_impulse(z, 0, 1), 0);
  double deepest = 0;
  for (const auto& step : z.rows)
    for (const Row& r : step) deepest = std::max(deepest, r.depth);
  EXPECT_GT(deepest, 0.002);  // a few mm
  EXPECT_LT(deepest, 0.006);
  const Result ok = judge(z, "soft");
  expect_clean(ok);
  EXPECT_NE(ok.output.find("2 episodes judged, 1 of them of 3 or more bodies"), std::string::npos) << ok.output;
  Zoo rigid = z;
  rigid.text["contact_model"] = "rigid";
  expect_caught(judge(rigid, "rigid"), {"kinetic energy", "group (0, 1)", "group (3, 4, 5)"});
  // Undeclared: every admissible value; the steps that fail as rigid lie in episodes that
  // pass as soft, so nothing fails, and the detail names the declaration.
  Zoo undeclared = z;
  undeclared.text.erase("contact_model");
  const Result u = judge(undeclared, "undeclared");
  expect_clean(u);
  EXPECT_NE(u.output.find("contact_model undeclared: energy judged as rigid (per step) and as soft"),
            std::string::npos)
      << u.output;
  EXPECT_NE(u.output.find("declare contact_model to sharpen the verdict"), std::string::npos) << u.output;
  // The chain's springs feeding energy in fail both ways: caught undeclared, naming both.
  Zoo gain = soft_engine(60, -50);
  gain.text.erase("contact_model");
  expect_caught(judge(gain, "gain-undeclared"),
                {"conservation", "group (3, 4, 5) of 3 bodies (contact_model undeclared: judged soft)",
                 "it fails both ways"});
}

/// "NEW FAILURE row/cause" of every failing cause in `output`.
std::set<std::string> failing_causes(const std::string& output) {
  std::set<std::string> out;
  const std::regex re("(^|\n)NEW FAILURE ([a-z-]+/[a-z-]+):");
  for (auto it = std::sregex_iterator(output.begin(), output.end(), re); it != std::sregex_iterator(); ++it)
    out.insert((*it)[2]);
  return out;
}

// design.md section 13d: an undeclared fact admits every value, so the undeclared verdict
// is never stricter than a declared one: for each declaration, each zoo engine (clean and
// with a planted fault) fails undeclared only causes it fails under every declared value.
TEST_F(ZooEngines, UndeclaredIsNeverStricterThanAnyDeclaredValue) {
  std::vector<std::pair<std::string, Zoo>> engines{{"soft", soft_engine()},
                                                   {"soft-gain", soft_engine(60, -50)},
                                                   {"gyroscopic", gyroscopic_engine()},
                                                   {"joints", locked_engine()},
                                                   {"substepped", substepped_engine(4, 0.001, 200, true)}};
  {  // planted: a lone body's velocity x1.5, a dropped row
    Zoo fast = locked_engine();
    fast.states[40].v[4] = f32(1.5 * fast.states[40].v[4]);
    engines.emplace_back("joints-fast", fast);
    Zoo dropped = locked_engine();
    dropped.rows[49].erase(dropped.rows[49].begin() + 2);
    engines.emplace_back("joints-dropped", dropped);
    Zoo deep = locked_engine();  // body 1's rows 1 cm deeper than the shapes at frame 30
    for (Row& row : deep.rows[29])
      if (row.b == 1) row.depth = f32(row.depth + 0.01);
    engines.emplace_back("joints-deep", deep);
  }
  const std::map<std::string, std::vector<std::string>> values{
      {"gyroscopic", {"true", "false"}},
      {"integrator", {"semi-implicit", "explicit", "any", "substepped"}},
      {"contact_model", {"rigid", "soft"}},
      {"depth_per", {"point", "manifold"}}};
  std::size_t judged = 0, undeclared_failures = 0;
  for (const auto& [name, base] : engines)
    for (const auto& [attribute, choices] : values) {
      Zoo undeclared = base;
      undeclared.text.erase(attribute);
      if (attribute == "integrator") undeclared.numbers.erase("substeps");
      const std::set<std::string> loose = failing_causes(judge(undeclared, name + "-undeclared").output);
      undeclared_failures += loose.size();
      for (const std::string& value : choices) {
        Zoo declared = undeclared;
        declared.text[attribute] = value;
        if (value == "substepped") declared.numbers["substeps"] = name == "substepped" ? 4 : 1;
        const Result r = judge(declared, name + "-" + attribute + "-" + value);
        const std::set<std::string> strict = failing_causes(r.output);
        ++judged;
        for (const std::string& cause : loose)
          EXPECT_TRUE(strict.count(cause)) << name << ": undeclared " << attribute << " fails " << cause
                                           << " but declared \"" << value << "\" does not\n" << r.output;
      }
    }
  EXPECT_EQ(judged, 8u * 10u);
  EXPECT_GT(undeclared_failures, 0u);  // the planted faults fail undeclared too
}

// design.md section 13b.12 for episodes of 3 or more bodies: the row's energy is judged over the
// isolated group's whole episode. The chain 3-4-5 passes with damped springs; springs
// with negative damping (c = -50 N s/m: each step's impulses still balance momentum)
// gain energy over the episode and fail it, naming the group.
TEST_F(ZooEngines, SoftContactsThreeBodyEpisodeIsJudged) {
  const Zoo z = soft_engine();
  int together = -1;  // a step where 4 touches 3 and 5 at once
  for (std::size_t f = 0; f < z.rows.size() && together < 0; ++f) {
    int hits = 0;
    for (const Row& r : z.rows[f]) hits += (r.a == 3 && r.b == 4) || (r.a == 4 && r.b == 5);
    if (hits == 2) together = static_cast<int>(f) + 1;
  }
  ASSERT_GT(together, 0) << "the chain never forms one group";
  const Zoo gain = soft_engine(60, -50);
  const Result r = judge(gain, "gain");
  expect_caught(r, {"conservation", "group (3, 4, 5) of 3 bodies (soft contacts) over its contact episode"});
  EXPECT_TRUE(std::regex_search(r.output, std::regex("(^|\n)physics +conservation +[^ ]+ +[^ ]+ +FAIL"))) << r.output;
  for (const char* row : {"momentum-balance", "free-flight"})
    EXPECT_TRUE(std::regex_search(r.output, std::regex(std::string("(^|\n)physics +") + row + " +[^ ]+ +[^ ]+ +pass")))
        << row << "\n" << r.output;
  std::cout << "3-body episode: one group at frame " << together << "\n" << r.output.substr(0, r.output.find("\nmodel")) << "\n";
}

// Shards of a soft-contact run (`validate --trace-in T --shard i/N`, then `--merge`): the
// energy is judged over each isolated group's contact episode, and here a shard border
// falls inside both episodes (boxes 0-1 and the chain 3-4-5). The shard holding an
// episode's first contact step judges it (following the episodes through the frames
// before its own and reading on past its last frame): the merged rows equal the whole
// run's, clean (every row passes, both episodes judged) and with the chain's springs
// feeding energy in (conservation fails on group (3, 4, 5), once).
TEST_F(ZooEngines, SoftEpisodesAcrossShardBordersMergeToTheWholeVerdict) {
  auto load = [](const fs::path& p) {
    std::ifstream in(p);
    return nlohmann::json::parse(in);
  };
  for (const double chain_c : {50.0, -50.0}) {
    const Zoo z = soft_engine(60, chain_c);
    const int frames = static_cast<int>(z.rows.size());
    // Each episode's first and last step with a row.
    auto span = [&](std::vector<int> bodies) {
      int first = -1, last = -1;
      for (int f = 0; f < frames; ++f)
        for (const Row& r : z.rows[std::size_t(f)])
          if (std::count(bodies.begin(), bodies.end(), r.a) && std::count(bodies.begin(), bodies.end(), r.b)) {
            if (first < 0) first = f + 1;
            last = f + 1;
          }
      return std::make_pair(first, last);
    };
    const auto pair = span({0, 1}), chain = span({3, 4, 5});
    ASSERT_GT(pair.first, 0);
    ASSERT_GT(chain.first, 0);
    // The fewest shards with a border (after frame floor(k F / N)) inside both episodes.
    int count = 0;
    for (int n = 2; n <= frames && count == 0; ++n) {
      bool in_pair = false, in_chain = false;
      for (int k = 1; k < n; ++k) {
        const int border = k * frames / n;
        in_pair = in_pair || (border >= pair.first && border < pair.second);
        in_chain = in_chain || (border >= chain.first && border < chain.second);
      }
      if (in_pair && in_chain) count = n;
    }
    ASSERT_GT(count, 1) << "episodes at frames " << pair.first << ".." << pair.second << " and " << chain.first
                        << ".." << chain.second;
    const std::string tag = chain_c > 0 ? "clean" : "gain";
    const fs::path trace = dir_ / (tag + ".h5");
    z.write(trace.string());
    const Result whole = run_octocd("validate --trace-in " + trace.string() + " --json " +
                                    (dir_ / (tag + ".whole.json")).string());
    ASSERT_EQ(whole.code, chain_c > 0 ? 0 : 3) << whole.output;
    std::string files;
    for (int i = 0; i < count; ++i) {
      const fs::path out = dir_ / (tag + ".s" + std::to_string(i) + ".json");
      const Result r = run_octocd("validate --trace-in " + trace.string() + " --shard " + std::to_string(i) + "/" +
                                  std::to_string(count) + " --json " + out.string());
      ASSERT_TRUE(r.code == 0 || r.code == 3) << r.output;
      files += " " + out.string();
    }
    const Result merged =
        run_octocd("validate --merge" + files + " --json " + (dir_ / (tag + ".merged.json")).string());
    EXPECT_EQ(merged.code, whole.code) << merged.output;
    const nlohmann::json a = load(dir_ / (tag + ".whole.json")), b = load(dir_ / (tag + ".merged.json"));
    ASSERT_EQ(a["rows"].size(), b["rows"].size());
    const char* keys[] = {"tier", "name", "figure", "measured", "bound", "verdict", "judged", "tolerances", "causes"};
    for (std::size_t r = 0; r < a["rows"].size(); ++r)
      for (const char* key : keys)
        EXPECT_EQ(a["rows"][r][key], b["rows"][r][key]) << tag << ": row " << a["rows"][r]["name"] << ", " << key;
    EXPECT_NE(whole.output.find("2 episodes judged"), std::string::npos) << whole.output;
    // Every episode judged once, by one shard: the shards' episode counts (judged, of 3
    // or more bodies, not judged) sum to the whole run's.
    auto episodes = [&](const fs::path& json) {
      std::array<int, 3> n{};
      const nlohmann::json doc = load(json);
      for (const auto& row : doc["rows"]) {
        std::smatch m;
        const std::string detail = row["detail"];
        if (row["name"] == "conservation" &&
            std::regex_search(detail, m, std::regex("\\((\\d+) episodes judged, (\\d+) of them of 3 or more "
                                                    "bodies; (\\d+) not judged")))
          n = {std::stoi(m[1]), std::stoi(m[2]), std::stoi(m[3])};
      }
      return n;
    };
    std::array<int, 3> sum{};
    for (int i = 0; i < count; ++i) {
      const std::array<int, 3> n = episodes(dir_ / (tag + ".s" + std::to_string(i) + ".json"));
      for (int k = 0; k < 3; ++k) sum[static_cast<std::size_t>(k)] += n[static_cast<std::size_t>(k)];
    }
    EXPECT_EQ(sum, episodes(dir_ / (tag + ".whole.json"))) << tag;
    EXPECT_EQ(sum[0], 2) << tag;
    if (chain_c < 0) {
      EXPECT_NE(merged.output.find("group (3, 4, 5) of 3 bodies (soft contacts) over its contact episode"),
                std::string::npos)
          << merged.output;
    }
    std::cout << tag << ": " << count << " shards; episodes at frames " << pair.first << ".." << pair.second << " and "
              << chain.first << ".." << chain.second << "\n";
  }
}

// A soft pair's isolated episode that begins in contact is not judged: the pair's spring
// was loaded while box 1 still touched the static wall, so its stored energy is not in the
// bodies' mechanical energy at the episode's first step, and its release (+14% of the
// kinetic energy, a damped spring) would read as a gain (as MuJoCo's rot-drop-220 pair
// (15, 42) and bunny-stack-50 pair (6, 15) are released from the floor: docs/engines.md,
// "mujoco"). The same pair meeting in free flight
// is judged from its first contact: it passes with a damped spring and fails with negative
// damping (c = -50 N s/m), naming the pair.
TEST_F(ZooEngines, SoftEpisodeBegunInContactIsNotJudged) {
  const Zoo loaded = soft_released_engine(true, 50);
  ASSERT_FALSE(loaded.rows[0].empty());
  bool wall_left = false;  // frame 2: the pair still compressed, box 1 off the wall
  for (const Row& r : loaded.rows[1]) wall_left = wall_left || (r.a == 1 && r.b == 2);
  for (const Row& r : loaded.rows[1]) wall_left = wall_left && r.a != 0;
  ASSERT_TRUE(wall_left);
  // The pair's mechanical energy rises over its isolated contact steps.
  auto pair_energy = [](const Zoo& z, std::size_t s) {
    double e = 0;
    for (int i : {1, 2}) e += 0.5 * dot(z.states[s].v[i], z.states[s].v[i]);
    return e;
  };
  std::size_t last = 1;
  while (last < loaded.rows.size() && !loaded.rows[last].empty()) ++last;
  const double rise = (pair_energy(loaded, last) - pair_energy(loaded, 1)) / pair_energy(loaded, 1);
  EXPECT_GT(rise, 0.05);
  const Result r = judge(loaded, "loaded");
  expect_clean(r);
  EXPECT_NE(r.output.find("0 episodes judged, 0 of them of 3 or more bodies; 1 not judged: a body touched a static "
                          "one, it began in contact (1: "),
            std::string::npos)
      << r.output;
  const Result fresh = judge(soft_released_engine(false, 50), "fresh");
  expect_clean(fresh);
  EXPECT_NE(fresh.output.find("1 episodes judged"), std::string::npos) << fresh.output;
  expect_caught(judge(soft_released_engine(false, -50), "gain"),
                {"conservation", "pair (1, 2) (soft contacts) over its contact episode"});
  RecordProperty("released_rise", std::to_string(rise));
}

TEST_F(ZooEngines, SoftContactsEditedVelocityAndWrongBodyAreCaught) {
  const Zoo base = soft_engine();
  const int f = first_impulse(base, 0, 1) + 2;
  {  // the velocity of body 0, in contact, edited in step f
    Zoo z = base;
    z.states[f].v[0][1] += 0.05;
    expect_caught(judge(z, "edited"), {"momentum-balance", "frame " + std::to_string(f) + ": body 0"});
  }
  {  // step f's impulse on body 1 given to body 2 (which flies alone)
    Zoo z = base;
    const double jn = z.rows[f - 1].at(0).jn;
    z.states[f].v[1][0] -= jn;
    z.states[f].v[2][0] += jn;
    const Result r = judge(z, "wrong-body");
    expect_caught(r, {"frame " + std::to_string(f) + ": body 1: m (v' - v)",
                      "frame " + std::to_string(f) + ": body 2 without contacts: v'"});
  }
}

// The term is judged by the invariants of free rotation (L = R I R^T w kept to second
// order, the rotational energy not rising), so the run passes declared "true" and
// undeclared alike; declared "false" (w' = w), the lone body's precession fails.
TEST_F(ZooEngines, GyroscopicTermPassesDeclaredOrUndeclaredAndFailsDeclaredAbsent) {
  const Zoo z = gyroscopic_engine();
  ASSERT_GT(first_impulse(z, 0, 1), 0);
  const Result ok = judge(z, "gyro");
  expect_clean(ok);
  EXPECT_NE(ok.output.find("gyroscopic term declared"), std::string::npos) << ok.output;
  Zoo plain = z;
  plain.text.erase("gyroscopic");
  const Result undeclared = judge(plain, "undeclared");
  expect_clean(undeclared);
  EXPECT_NE(undeclared.output.find("gyroscopic term undeclared"), std::string::npos) << undeclared.output;
  Zoo absent = z;
  absent.text["gyroscopic"] = "false";
  expect_caught(judge(absent, "absent"),
                {"free-flight", "frame 1: body 1 without contacts: w'", "angular-velocity", "gyroscopic term false"});
}

TEST_F(ZooEngines, GyroscopicLoneSpinEditsAreCaught) {
  const Zoo base = gyroscopic_engine(60);
  {  // angular velocity x1.5 on the lone spinning body 2 in step 30
    Zoo z = base;
    z.states[30].w[2] = f32(1.5 * z.states[30].w[2]);
    expect_caught(judge(z, "spin"), {"frame 30: body 2 without contacts: w'", "angular-velocity 2 of"});
  }
  {  // its orientation turned by 30 deg in step 31
    Zoo z = base;
    z.states[31].q[2] = f32(qnorm(qmul(axis_angle({0, 0, 1}, M_PI / 6), z.states[31].q[2])));
    expect_caught(judge(z, "turned"), {"frame 31: body 2 without contacts: q' is 30", "orientation"});
  }
}

TEST_F(ZooEngines, LockedRotationPassesDeclaredAndFailsUndeclared) {
  const Zoo z = locked_engine();
  ASSERT_GT(first_impulse(z, 2, 3), 0);
  const Result ok = judge(z, "joints");
  expect_clean(ok);
  EXPECT_NE(ok.output.find("locked axes"), std::string::npos) << ok.output;
  Zoo plain = z;
  plain.write_locked = false;  // identity orientations, w = 0, nothing declared
  const Result r = judge(plain, "undeclared");
  expect_caught(r, {"momentum-balance", "I_w (w' - w)", "angular momentum"});
}

TEST_F(ZooEngines, LockedEngineDroppedRowAndLoneBodyEditsAreCaught) {
  const Zoo base = locked_engine();
  {  // one row of box 1's 4-row floor manifold dropped in step 50
    Zoo z = base;
    z.rows[49].erase(z.rows[49].begin() + 2);
    expect_caught(judge(z, "dropped"), {"momentum-balance", "frame 50: body 1"});
  }
  for (double k : {1.5, 2.0}) {  // the lone body 4's velocity x1.5 / x2 in step 40
    Zoo z = base;
    z.states[40].v[4] = f32(k * z.states[40].v[4]);
    expect_caught(judge(z, "fast"), {"free-flight", "frame 40: body 4 without contacts: v'"});
  }
  {  // body 4 teleported by 1 cm in step 60
    Zoo z = base;
    z.states[60].x[4][2] = f32(z.states[60].x[4][2] + 0.01);
    expect_caught(judge(z, "teleport"), {"frame 60: body 4 without contacts: x'", "position"});
  }
}

TEST_F(ZooEngines, ConvexHullsOfConcaveMeshesPassDeclaredAndFailAsMeshes) {
  const Zoo z = hull_engine(dir_);
  EXPECT_EQ(z.hull_vertices, 10u);  // the L's 6 profile corners less its reflex one, twice
  const int first = first_impulse(z, 0, 1);
  ASSERT_GT(first, 0);
  std::size_t rows = 0;
  for (const auto& step : z.rows) rows += step.size();
  std::size_t multi = 0, pair_frames = 0;
  for (const auto& step : z.rows) {
    multi += step.size() >= 2;
    pair_frames += !step.empty();
  }

  std::cout << "zoo-hulls: " << rows << " rows, first impulse at frame " << first << ", " << multi
            << " steps with 2+ rows\n";
  const Result ok = judge(z, "hulls");
  expect_clean(ok);
  EXPECT_NE(ok.output.find("collided as declared \"convex_hull\""), std::string::npos) << ok.output;
  // Declared as the concave meshes: the L lands on the lid of the U's hull, 0.15-0.2 m
  // from the hollow's floor and walls: every row is a false contact, its point off body 0.
  Zoo mesh = z;
  mesh.text["collision_shape"] = "mesh";
  const Result r = judge(mesh, "meshes");
  expect_caught(r, {"contact-completeness", "frame " + std::to_string(first) + ": pair (0, 1)"});
  for (const char* row : {"contact-completeness", "contact-geometry"})
    EXPECT_TRUE(std::regex_search(r.output, std::regex(std::string("(^|\n)physics +") + row + " +[^ ]+ +[^ ]+ +FAIL")))
        << row << "\n" << r.output;
  const std::string every = "false-contact " + std::to_string(pair_frames) + " of " + std::to_string(pair_frames);
  EXPECT_NE(r.output.find(every), std::string::npos) << every << "\n" << r.output;
  EXPECT_NE(r.output.find("cause point-off-shape"), std::string::npos) << r.output;
}

TEST_F(ZooEngines, ConvexHullEngineFaultsAreCaught) {
  const Zoo base = hull_engine(dir_);
  // A step of the L's manifold with 2+ rows, one carrying a normal impulse: dropped.
  int fd = -1;
  std::size_t drop = 0;
  for (std::size_t f = 0; f < base.rows.size() && fd < 0; ++f)
    for (std::size_t k = 0; k < base.rows[f].size() && base.rows[f].size() >= 2; ++k)
      if (base.rows[f][k].jn > 1e-3) {
        fd = static_cast<int>(f) + 1;
        drop = k;
        break;
      }
  ASSERT_GT(fd, 0);
  {
    Zoo z = base;
    z.rows[fd - 1].erase(z.rows[fd - 1].begin() + static_cast<std::ptrdiff_t>(drop));
    expect_caught(judge(z, "dropped"), {"momentum-balance", "frame " + std::to_string(fd) + ": body 1"});
  }
  {  // that row's impulse given to the lone L (body 2) instead of the falling one
    Zoo z = base;
    const Row& row = z.rows[fd - 1][drop];
    z.states[fd].v[1] = f32(z.states[fd].v[1] + row.jn * row.n);  // body 1 no longer gets -jn n
    z.states[fd].v[2] = f32(z.states[fd].v[2] - row.jn * row.n);
    expect_caught(judge(z, "wrong-body"), {"frame " + std::to_string(fd) + ": body 1: m (v' - v)",
                                           "frame " + std::to_string(fd) + ": body 2 without contacts: v'"});
  }
  {  // the lone L's orientation turned by 30 deg in step 40
    Zoo z = base;
    z.states[40].q[2] = f32(qnorm(qmul(axis_angle({1, 0, 0}, M_PI / 6), z.states[40].q[2])));
    expect_caught(judge(z, "turned"), {"frame 40: body 2 without contacts: q' is 30", "orientation"});
  }
  {  // its angular velocity x1.5 in step 50
    Zoo z = base;
    z.states[50].w[2] = f32(1.5 * z.states[50].w[2]);
    expect_caught(judge(z, "spin"), {"frame 50: body 2 without contacts: w'", "angular-velocity"});
  }
  {  // its velocity x1.5 in step 60, then teleported by 1 cm in step 70
    Zoo z = base;
    z.states[60].v[2] = f32(1.5 * z.states[60].v[2]);
    expect_caught(judge(z, "fast"), {"free-flight", "frame 60: body 2 without contacts: v'"});
    z = base;
    z.states[70].x[2][0] = f32(z.states[70].x[2][0] + 0.01);
    expect_caught(judge(z, "teleport"), {"frame 70: body 2 without contacts: x'", "position"});
  }
}

TEST_F(ZooEngines, SubsteppedFreeFallAndPilePassAtEveryN) {
  for (int n : {1, 2, 4, 8}) {
    const Zoo z = substepped_engine(n, 0.001, 200, true);
    ASSERT_GT(first_impulse(z, 0, 1), 0) << n;
    const Result ok = judge(z, "substepped-" + std::to_string(n));
    expect_clean(ok);
    for (const char* row : {"momentum-balance", "free-flight"})  // judged, not n/a
      EXPECT_TRUE(std::regex_search(ok.output, std::regex(std::string("(^|\n)physics +") + row + " +[^ ]+ +[^ ]+ +pass")))
          << row << "\n" << ok.output;
    Zoo undeclared = z;  // every admissible integrator: a in [0, 1]
    undeclared.text.erase("integrator");
    undeclared.numbers.erase("substeps");
    expect_clean(judge(undeclared, "undeclared-" + std::to_string(n)));
    const Zoo fall = substepped_engine(n, 1.0 / 60, 60, false);  // a free fall at dt 1/60
    expect_clean(judge(fall, "fall-" + std::to_string(n)));
    if (n == 1) continue;
    // Declared one update per step, the free bodies are (1 - a) g dt^2 off (1.02 mm at n = 4).
    Zoo semi = fall;
    semi.text["integrator"] = "semi-implicit";
    semi.numbers.erase("substeps");
    expect_caught(judge(semi, "semi-" + std::to_string(n)), {"free-flight", "without contacts: x'", "x + dt v'"});
  }
}

TEST_F(ZooEngines, SubsteppedFaultsAreCaughtDeclaredAndUndeclared) {
  for (double dt : {1.0 / 60, 0.001}) {
    const Zoo base = substepped_engine(4, dt, 60, false);
    for (bool declared : {true, false}) {
      auto planted = [&](const std::function<void(Zoo&)>& edit, const std::vector<std::string>& fragments) {
        Zoo z = base;
        if (!declared) {
          z.text.erase("integrator");
          z.numbers.erase("substeps");
        }
        edit(z);
        expect_caught(judge(z, "planted"), fragments);
      };
      SCOPED_TRACE(std::to_string(dt) + (declared ? " declared" : " undeclared"));
      planted([](Zoo& z) { z.states[30].x[3][0] = f32(z.states[30].x[3][0] + 0.01); },
              {"frame 30: body 3 without contacts: x'", "position"});
      planted([](Zoo& z) { z.states[30].x[3][1] = f32(z.states[30].x[3][1] - 0.01); },  // along g
              {"frame 30: body 3 without contacts: x'", "position"});
      planted([](Zoo& z) { z.states[40].v[3] = f32(1.5 * z.states[40].v[3]); },
              {"free-flight", "frame 40: body 3 without contacts: v'"});
      planted([](Zoo& z) { z.states[50].w[2] = f32(1.5 * z.states[50].w[2]); },
              {"frame 50: body 2 without contacts: w'", "angular-velocity"});
    }
  }
}

/// (h) An engine whose API reports the normal impulses only (Rapier): zoo engine (d) with
/// the friction the writer cannot see written as zeros, declared impulses "normal-only".
Zoo normal_only_engine() {
  Zoo z = locked_engine();
  z.engine = "zoo-normal-only";
  for (auto& step : z.rows)
    for (Row& r : step) r.jt = 0;
  z.text["impulses"] = "normal-only";
  return z;
}

/// The row of `output`'s table for `row` (physics tier) has this verdict ("pass", "FAIL", "n/a").
bool row_verdict(const std::string& output, const std::string& row, const std::string& verdict) {
  return std::regex_search(output, std::regex("(^|\n)physics +" + row + " +[^ ]+ +[^ ]+ +" + verdict));
}

TEST_F(ZooEngines, NormalOnlyImpulsesAreJudgedWithinTheirCones) {
  const Zoo z = normal_only_engine();
  const Result ok = judge(z, "normal-only");
  expect_clean(ok);
  EXPECT_TRUE(row_verdict(ok.output, "momentum-balance", "pass")) << ok.output;
  EXPECT_TRUE(row_verdict(ok.output, "friction", "n/a")) << ok.output;
  EXPECT_NE(ok.output.find("impulses = \"normal-only\": its rows carry no friction impulse"), std::string::npos)
      << ok.output;
  // The same zeros read as complete impulses: the sliding box decelerates without friction.
  Zoo complete = z;
  complete.text.erase("impulses");
  expect_caught(judge(complete, "complete"), {"momentum-balance", "body 1"});
  {  // one row of box 1's 4-row floor manifold dropped in step 50
    Zoo f = z;
    f.rows[49].erase(f.rows[49].begin() + 2);
    expect_caught(judge(f, "dropped"), {"momentum-balance", "frame 50: body 1"});
  }
  {  // the sliding box's velocity x1.5 in step 40 (in contact)
    Zoo f = z;
    f.states[40].v[1] = f32(1.5 * f.states[40].v[1]);
    expect_caught(judge(f, "fast"), {"momentum-balance", "frame 40: body 1"});
  }
  {  // the lone body 4 teleported by 1 cm in step 60
    Zoo f = z;
    f.states[60].x[4][2] = f32(f.states[60].x[4][2] + 0.01);
    expect_caught(judge(f, "teleport"), {"frame 60: body 4 without contacts: x'", "position"});
  }
}

TEST_F(ZooEngines, NoImpulsesLeaveConservationToJudge) {
  Zoo z = locked_engine();  // (i) an engine whose API reports no impulse (Jolt): zeros written
  const int fc = first_impulse(z, 2, 3);
  ASSERT_GT(fc, 0);
  z.engine = "zoo-no-impulses";
  for (auto& step : z.rows)
    for (Row& r : step) r.jn = r.jt = 0;
  z.text["impulses"] = "none";
  const Result ok = judge(z, "none");
  expect_clean(ok);
  EXPECT_TRUE(row_verdict(ok.output, "momentum-balance", "n/a")) << ok.output;
  EXPECT_TRUE(row_verdict(ok.output, "friction", "n/a")) << ok.output;
  EXPECT_TRUE(row_verdict(ok.output, "conservation", "pass")) << ok.output;
  EXPECT_NE(ok.output.find("impulses = \"none\" (the engine reports no impulse)"), std::string::npos) << ok.output;
  {  // box 2's velocity x1.5 in the step it collides with box 3: the pair's momentum changes
    Zoo f = z;
    f.states[fc].v[2] = f32(1.5 * f.states[fc].v[2]);
    expect_caught(judge(f, "fast"), {"conservation", "frame " + std::to_string(fc)});
  }
  {  // the collision's row dropped: boxes 2 and 3 change velocity in free flight
    Zoo f = z;
    auto& step = f.rows[fc - 1];
    step.erase(std::remove_if(step.begin(), step.end(), [](const Row& r) { return r.a == 2; }), step.end());
    expect_caught(judge(f, "dropped"), {"frame " + std::to_string(fc) + ": body 2 without contacts: v'"});
  }
  {  // the lone body 4 teleported by 1 cm in step 60
    Zoo f = z;
    f.states[60].x[4][2] = f32(f.states[60].x[4][2] + 0.01);
    expect_caught(judge(f, "teleport"), {"frame 60: body 4 without contacts: x'", "position"});
  }
  z.text["impulses"] = "some";
  const Result bad = judge(z, "bad");
  EXPECT_EQ(bad.code, 2) << bad.output;
  EXPECT_NE(bad.output.find("\"complete\", \"normal-only\", \"none\""), std::string::npos) << bad.output;
}

TEST_F(ZooEngines, SparseStatesAreJudgedOnWhatTheyCarry) {
  Zoo z = locked_engine(80);
  z.state_every = 10;  // states of frames 0, 10, ..., 80; contacts every frame
  const Result ok = judge(z, "sparse");
  expect_clean(ok);
  for (const char* row : {"conservation", "momentum-balance", "free-flight"}) {
    EXPECT_TRUE(row_verdict(ok.output, row, "n/a")) << row << "\n" << ok.output;
  }
  EXPECT_NE(ok.output.find("add every state (/states/frame 0, 1, 2, ...: octocd run --state-every 1)"),
            std::string::npos)
      << ok.output;
  for (const char* row : {"contact-completeness", "contact-geometry", "penetration", "friction"})
    EXPECT_TRUE(row_verdict(ok.output, row, "pass")) << row << "\n" << ok.output;
  // Step 41 is detected at the recorded state 40: its rows are judged there.
  Zoo flipped = z;
  for (Row& r : flipped.rows[40]) r.n = -1.0 * r.n;
  expect_caught(judge(flipped, "flipped"), {"contact-geometry", "frame 41"});
  // Step 45's pre-step state is not recorded: not judged (docs/validation.md, "Sparse states").
  flipped = z;
  for (Row& r : flipped.rows[44]) r.n = -1.0 * r.n;
  expect_clean(judge(flipped, "flipped-unposed"));
  // A recorded state with body 1 sunk 5 cm into the floor: the next step's pose penetrates.
  Zoo sunk = z;
  sunk.states[30].x[1][1] = f32(sunk.states[30].x[1][1] - 0.05);
  expect_caught(judge(sunk, "sunk"), {"penetration", "frame 31"});
}

// README's main job writes a state every 10th frame: judged on the frames it carries.
TEST_F(ZooEngines, TheMainJobsTraceGetsATable) {
  const fs::path trace = dir_ / "bunny.h5";
  const Result run = run_octocd("run " + octocd::test::source_dir() + "/datasets/scenes/bunny-stack-50.json --frames 300 "
                                "--trace " + trace.string() + " --quiet --no-xdmf");
  ASSERT_EQ(run.code, 0) << run.output;
  const Result r = run_octocd("validate --trace-in " + trace.string());
  EXPECT_TRUE(r.code == 0 || r.code == 3) << r.output;
  EXPECT_NE(r.output.find("physics  penetration"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("octocd run --state-every 1"), std::string::npos) << r.output;
}

// The fourth round's declarations that octocd reads but does not judge by yet (design.md
// section 13d items 4, 5b, 5d): each is read with its conservative meaning, or refused.
TEST_F(ZooEngines, FourthRoundDeclarationsAreReadOrRefused) {
  const Zoo base = locked_engine();
  // speculative: a row on boxes 2 and 3 while they are 6 mm apart (margin 5 mm), closing
  // at 2 m/s (2 mm a step): a false contact, unless declared speculative.
  Zoo spec = base;
  int fs = -1;
  for (std::size_t f = 1; f < spec.states.size() && fs < 0; ++f) {
    const double gap = spec.states[f - 1].x[3][0] - spec.states[f - 1].x[2][0] - 0.2;
    if (gap > 0.0052 && gap < 0.0066) fs = static_cast<int>(f);
  }
  ASSERT_GT(fs, 0);
  {
    Row r;
    r.a = 2;
    r.b = 3;
    r.n = {-1, 0, 0};
    const State& s = spec.states[fs - 1];
    r.p = f32(V{0.5 * (s.x[2][0] + s.x[3][0]), 0.5 * (s.x[2][1] + s.x[3][1]), 0.0});
    spec.rows[fs - 1].push_back(r);
  }
  expect_caught(judge(spec, "not-speculative"), {"contact-completeness", "frame " + std::to_string(fs)});
  Zoo declared = spec;
  declared.numbers["speculative"] = 1;
  const Result ok = judge(declared, "speculative");
  EXPECT_FALSE(row_verdict(ok.output, "contact-completeness", "FAIL")) << ok.output;
  EXPECT_NE(ok.output.find("speculative contacts declared"), std::string::npos) << ok.output;
  // contacts_complete 0: a dropped row is not judged (contact-completeness and
  // momentum-balance n/a); free-flight and conservation judge what the geometry shows apart.
  Zoo dropped = base;
  dropped.rows[49].erase(dropped.rows[49].begin() + 2);
  dropped.numbers["contacts_complete"] = 0;
  const Result partial = judge(dropped, "incomplete");
  expect_clean(partial);
  for (const char* row : {"contact-completeness", "momentum-balance"})
    EXPECT_TRUE(row_verdict(partial.output, row, "n/a")) << row << "\n" << partial.output;
  for (const char* row : {"conservation", "free-flight"})
    EXPECT_TRUE(row_verdict(partial.output, row, "pass")) << row << "\n" << partial.output;
  // The advice never contradicts the declaration: the steps or pairs, not contacts_complete 1.
  EXPECT_NE(partial.output.find("add /contacts/incomplete in place of the root attribute contacts_complete = 0"),
            std::string::npos)
      << partial.output;
  EXPECT_EQ(partial.output.find("contacts_complete = 1"), std::string::npos) << partial.output;
  {  // boxes 2 and 3 collide in the air, apart from everything else: box 2's velocity x1.5
    const int fc = first_impulse(dropped, 2, 3);
    ASSERT_GT(fc, 0);
    Zoo f = dropped;
    f.states[fc].v[2] = f32(1.5 * f.states[fc].v[2]);
    expect_caught(judge(f, "incomplete-fast"), {"conservation", "frame " + std::to_string(fc)});
  }
  // manifold_points persistent: a point 2 cm off the shapes passes; fixed, it fails.
  Zoo drift = base;
  drift.rows[29][0].p[2] += 0.3;  // 0.1 m off the box's side, beyond depth_m
  expect_caught(judge(drift, "drift"), {"contact-geometry", "frame 30: pair (0, 1) row 0: point"});
  drift.text["manifold_points"] = "persistent";
  const Result persistent = judge(drift, "persistent");
  expect_clean(persistent);
  EXPECT_NE(persistent.output.find("manifold_points \"persistent\""), std::string::npos) << persistent.output;
  // /bodies/convex_radius and /bodies/com_offset of zeros: judged as without them.
  Zoo shapes = base;
  shapes.body_floats["/bodies/convex_radius"] = std::vector<double>(5, 0.0);
  shapes.body_floats["/bodies/com_offset"] = std::vector<double>(15, 0.0);
  expect_clean(judge(shapes, "zeros"));
  shapes.body_floats["/bodies/convex_radius"][1] = -0.01;
  Result r = judge(shapes, "negative-radius");
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find("/bodies/convex_radius: body 1: -0.0099"), std::string::npos) << r.output;
  shapes.body_floats["/bodies/convex_radius"][1] = 0.0;
  shapes.body_floats["/bodies/com_offset"][7] = 0.01;  // an offset needs velocity_at
  r = judge(shapes, "no-velocity-at");
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find("root attribute velocity_at"), std::string::npos) << r.output;
}

// design.md section 13d items 4 and 5b: depth_per "unknown" makes the depth cause n/a (named)
// while penetration is judged on the posed shapes; "manifold" judges one depth per pair
// along its normal; undeclared admits both "point" and "manifold". A depth 1 cm off fails
// under "point", "manifold" and undeclared.
TEST_F(ZooEngines, DepthPerIsJudgedAsDeclared) {
  const Zoo base = locked_engine();
  for (const char* value : {"point", "manifold"}) {
    Zoo z = base;
    z.text["depth_per"] = value;
    expect_clean(judge(z, std::string("depth-") + value));
  }
  Zoo deep = base;  // body 1's rows (on the floor) 1 cm deeper than the shapes at frame 30
  for (Row& row : deep.rows[29])
    if (row.b == 1) row.depth = f32(row.depth + 0.01);
  for (const char* value : {"point", "manifold", ""}) {
    Zoo z = deep;
    if (*value) z.text["depth_per"] = value;
    expect_caught(judge(z, std::string("deep-") + value), {"contact-geometry", "frame 30: pair (0, 1)"});
  }
  Zoo unknown = deep;
  unknown.text["depth_per"] = "unknown";
  const Result u = judge(unknown, "deep-unknown");
  expect_clean(u);
  EXPECT_NE(u.output.find("depth n/a on"), std::string::npos) << u.output;
  EXPECT_NE(u.output.find("depth_per \"unknown\""), std::string::npos) << u.output;
  // Penetration is still judged on the posed shapes: box 1 sunk 2 cm into the floor from
  // frame 40 on (its rows as before) fails penetration with depth_per "unknown".
  Zoo sunk = base;
  for (std::size_t f = 40; f < sunk.states.size(); ++f) sunk.states[f].x[1][1] = f32(sunk.states[f].x[1][1] - 0.02);
  sunk.text["depth_per"] = "unknown";
  const Result pen = judge(sunk, "sunk-unknown");
  EXPECT_EQ(pen.code, 3) << pen.output;
  EXPECT_TRUE(row_verdict(pen.output, "penetration", "FAIL")) << pen.output;
}

// depth_per "manifold" along a normal a little off the floor's (docs/validation.md, "Depth
// per manifold"): box 1's 4 rows carry the manifold's one depth (0.5 mm) along a normal
// turned 1.4 deg about z from frame 20 on. The deepest point of the overlap along that
// normal is 0.5 mm / cos 1.4 deg, so the run is clean declared "manifold", "point" or
// undeclared (the hulls' overlap projected on the normal reads the far edge of the 4 m
// floor instead: 2.8 cm or 7.6 cm by the side); a depth 1 cm off still fails. The engine
// reports no impulses (impulses "none", as Jolt): its rows' impulses were applied along
// the floor's normal.
TEST_F(ZooEngines, ManifoldDepthIsTheOverlapsDeepestPointAlongItsNormal) {
  Zoo base = locked_engine();
  base.text["impulses"] = "none";
  const double t = 1.4 * 3.14159265358979323846 / 180.0;
  for (const double side : {1.0, -1.0}) {
    Zoo tilted = base;
    for (std::size_t f = 19; f < tilted.rows.size(); ++f)
      for (Row& row : tilted.rows[f])
        if (row.b == 1) row.n = f32(V{side * std::sin(t), -std::cos(t), 0});
    for (const char* value : {"manifold", "point", ""}) {
      Zoo z = tilted;
      if (*value) z.text["depth_per"] = value;
      expect_clean(judge(z, std::string("tilted-") + value));
    }
    Zoo deep = tilted;
    deep.text["depth_per"] = "manifold";
    for (Row& row : deep.rows[29])
      if (row.b == 1) row.depth = f32(row.depth + 0.01);
    expect_caught(judge(deep, "tilted-deep"), {"contact-geometry", "frame 30: pair (0, 1) manifold depth"});
  }
}

// Resting normals without a depth (docs/validation.md, contact-geometry): box 1 rests 0.5 mm
// deep on the floor on 4 loaded rows that carry depth 0 (an engine that reports no depth,
// or declares depth_per "unknown"). Clean, the rows are judged on SAT's axes; at frame 30
// the 4 rows with their normal flipped (pointing from the floor into the box), or turned by
// 45 deg, fail contact-geometry naming the frame and the pair, whatever depth_per says. A
// normal turned by 30 deg lies within normal_angle_deg (40) as on any row: its impulses
// then miss box 1's momentum change, and momentum-balance names the frame and the body.
TEST_F(ZooEngines, RestingNormalsAreJudgedWhateverTheDepth) {
  Zoo base = locked_engine();
  for (auto& step : base.rows)
    for (Row& row : step)
      if (row.b == 1) row.depth = 0;
  auto planted = [&](V n) {
    Zoo z = base;
    for (Row& row : z.rows[29])
      if (row.b == 1) row.n = f32(n);
    return z;
  };
  const double c45 = std::sqrt(0.5);
  for (const char* value : {"", "point", "unknown"}) {
    Zoo z = base;
    if (*value) z.text["depth_per"] = value;
    const Result ok = judge(z, std::string("resting-") + value);
    expect_clean(ok);
    EXPECT_NE(ok.output.find("resting rows"), std::string::npos) << ok.output;
    for (const V& n : {V{0, 1, 0}, V{c45, -c45, 0}}) {
      Zoo f = planted(n);
      if (*value) f.text["depth_per"] = value;
      const Result r = judge(f, std::string("resting-fault-") + value);
      EXPECT_TRUE(row_verdict(r.output, "contact-geometry", "FAIL")) << r.output;
      expect_caught(r, {"frame 30: pair (0, 1) row 0: normal", "a resting row: depth 0 m"});
    }
  }
  const Result turned = judge(planted({0.5, -std::sqrt(0.75), 0}), "resting-30");
  EXPECT_TRUE(row_verdict(turned.output, "contact-geometry", "pass")) << turned.output;
  EXPECT_TRUE(row_verdict(turned.output, "momentum-balance", "FAIL")) << turned.output;
  expect_caught(turned, {"frame 30", "body 1"});
}

// design.md section 13d item 4: /bodies/convex_radius rounds a body's shape. Box 1 rests
// 2 cm higher on the floor (its rows 0.5 mm deep into the floor): judged on the box rounded
// by 2 cm it is clean; without the radius its rows join shapes 1.95 cm apart (a false
// contact, margin 5 mm); a row depth 1 cm off on the rounded box still fails.
TEST_F(ZooEngines, RoundedShapesAreJudgedOnTheInflatedShape) {
  Zoo z = locked_engine();
  for (State& s : z.states) s.x[1][1] = f32(s.x[1][1] + 0.02);
  z.body_floats["/bodies/convex_radius"] = {0, 0.02, 0, 0, 0};
  const Result ok = judge(z, "rounded");
  expect_clean(ok);
  EXPECT_NE(ok.output.find("rounded by /bodies/convex_radius"), std::string::npos) << ok.output;
  Zoo bare = z;
  bare.body_floats.erase("/bodies/convex_radius");
  expect_caught(judge(bare, "not-rounded"), {"contact-completeness", "false contact on pair (0, 1)"});
  Zoo deep = z;
  for (Row& row : deep.rows[29])
    if (row.b == 1) row.depth = f32(row.depth + 0.01);
  expect_caught(judge(deep, "rounded-deep"), {"contact-geometry", "frame 30: pair (0, 1)"});
  // contacts_complete 0 (rows may be missing): box 1's rows dropped at frame 30 leave it
  // touching the floor through its radius, so it is not judged as free (its friction and
  // support changed its velocity); free-flight is not fooled by the posed shapes' gap.
  Zoo gap = z;
  gap.numbers["contacts_complete"] = 0;
  gap.rows[29].erase(std::remove_if(gap.rows[29].begin(), gap.rows[29].end(), [](const Row& row) { return row.b == 1; }),
                     gap.rows[29].end());
  expect_clean(judge(gap, "rounded-incomplete"));
  Zoo sunk = z;  // 2 cm into the floor from frame 40 on: penetration of the rounded shapes
  for (std::size_t f = 40; f < sunk.states.size(); ++f) sunk.states[f].x[1][1] = f32(sunk.states[f].x[1][1] - 0.02);
  const Result pen = judge(sunk, "rounded-sunk");
  EXPECT_EQ(pen.code, 3) << pen.output;
  EXPECT_TRUE(row_verdict(pen.output, "penetration", "FAIL")) << pen.output;
}

// design.md section 13d item 5d: positions at the body frame's origin, 3.7 cm from the
// centre of mass. Declared (/bodies/com_offset, velocity_at "com" or "origin"): clean;
// left out, the spinning body's origin fails free-flight; a 1 cm teleport and a 1.5x
// velocity still fail when declared.
TEST_F(ZooEngines, OffCentreBodiesAreJudgedAtTheirCentreOfMass) {
  const Zoo z = com_engine();
  ASSERT_GT(first_impulse(z, 0, 1), 0);
  expect_clean(judge(z, "com"));
  // velocity_at "origin": the stored origin velocity (|w x R c| ~ 0.2 m/s here) is rounded
  // at its own magnitude; free-flight's floor takes it (docs/validation.md, "Floors").
  Zoo origin = z;
  origin.text["velocity_at"] = "origin";
  expect_clean(judge(origin, "origin"));
  Zoo left_out = z;
  left_out.write_com = false;
  left_out.text.erase("velocity_at");
  expect_caught(judge(left_out, "left-out"), {"free-flight", "body 2"});
  Zoo teleport = z;
  teleport.states[120].x[2][0] = f32(teleport.states[120].x[2][0] + 0.01);
  expect_caught(judge(teleport, "teleport"), {"free-flight", "frame 120", "body 2"});
  Zoo fast = origin;
  fast.states[120].v[2] = f32(1.5 * fast.states[120].v[2]);
  expect_caught(judge(fast, "fast"), {"free-flight", "body 2"});
  // contacts_complete 0 places the shapes in the body frame (x - R c): body 1's rows dropped
  // on a bounce step leave it touching the floor, not judged free; body 2 alone is, and its
  // teleport still fails.
  const int bounce = first_impulse(z, 0, 1);
  Zoo incomplete = z;
  incomplete.numbers["contacts_complete"] = 0;
  incomplete.rows[bounce - 1].clear();
  expect_clean(judge(incomplete, "com-incomplete"));
  incomplete.states[120].x[2][0] = f32(incomplete.states[120].x[2][0] + 0.01);
  expect_caught(judge(incomplete, "com-incomplete-teleport"), {"free-flight", "frame 120", "body 2"});
  Zoo bad = z;
  bad.text["velocity_at"] = "middle";
  const Result r = judge(bad, "bad-velocity-at");
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find("root attribute velocity_at"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("\"com\", \"origin\""), std::string::npos) << r.output;
}

// Issue 78 item 6: an engine integrating the body origin (zoo engine (k)). Declared
// (integrated_point "origin"): clean; undeclared, the centre of mass's first-order drift
// fails free-flight on the lone spinner and momentum-balance on the landing bunny; a 1.5x
// velocity (free and in contact) and a 1 cm teleport still fail declared; a bad value
// exits 2 naming the attribute and the allowed values.
TEST_F(ZooEngines, OriginIntegratorIsJudgedWithinItsFirstOrderDrift) {
  const Zoo z = origin_engine(dir_);
  const int first = first_impulse(z, 0, 1);
  ASSERT_GT(first, 0);
  int contact_steps = 0;
  for (const auto& step : z.rows) contact_steps += !step.empty();
  std::cout << "zoo-origin: first impulse at frame " << first << ", " << contact_steps
            << " steps with rows; the lone bunny's centre of mass drifts up to " << com_drift(z, 2)
            << " m/s a step off free flight\n";
  const Result ok = judge(z, "origin");
  expect_clean(ok);
  EXPECT_NE(ok.output.find("integrated_point \"origin\""), std::string::npos) << ok.output;
  Zoo undeclared = z;
  undeclared.text.erase("integrated_point");
  const Result r = judge(undeclared, "origin-undeclared");
  expect_caught(r, {"body 2 without contacts"});
  EXPECT_TRUE(row_verdict(r.output, "free-flight", "FAIL")) << r.output;
  EXPECT_TRUE(row_verdict(r.output, "momentum-balance", "FAIL")) << r.output;
  Zoo fast = z;
  fast.states[100].v[2] = f32(1.5 * fast.states[100].v[2]);
  expect_caught(judge(fast, "origin-fast"), {"free-flight", "frame 100: body 2"});
  Zoo teleport = z;
  teleport.states[100].x[2][0] = f32(teleport.states[100].x[2][0] + 0.01);
  expect_caught(judge(teleport, "origin-teleport"), {"free-flight", "frame 100: body 2"});
  Zoo landing = z;  // body 1's velocity x1.5 right after its first impulse
  landing.states[first].v[1] = f32(1.5 * landing.states[first].v[1]);
  expect_caught(judge(landing, "origin-landing"),
                {"momentum-balance", "frame " + std::to_string(first) + ": body 1"});
  Zoo bad = z;
  bad.text["integrated_point"] = "centre";
  const Result b = judge(bad, "bad-integrated-point");
  EXPECT_EQ(b.code, 2) << b.output;
  EXPECT_NE(b.output.find("root attribute integrated_point"), std::string::npos) << b.output;
  EXPECT_NE(b.output.find("\"com\", \"origin\""), std::string::npos) << b.output;
}

/// (j) A 30-box pile: 15 columns of two boxes (0.2 m, 1 kg, rotation locked) on a 5 x 3
/// grid 0.3 m apart. Each bottom box rests on the floor (0.5 mm deep); each top box falls
/// onto it from its own height (5 to 33 cm) and bounces (e = 0.5 above 5 cm/s of
/// approach) until it rests. Contacts are found at the pre-step pose, four corner rows per
/// contact, and resolved together (30 projected Gauss-Seidel sweeps per column); each
/// row carries a quarter of its contact's impulse, and the velocities are the ones those
/// rounded rows give.
Zoo pile_engine(int frames = 400) {
  Zoo z;
  z.engine = "zoo-pile";
  Body box;
  box.locked = 0x38;
  z.bodies = {floor_body()};
  std::vector<V> x{{0, -0.1, 0}}, zero{{0, 0, 0}};
  std::vector<Q> q{{1, 0, 0, 0}};
  for (int k = 0; k < 15; ++k) {
    const double cx = -0.6 + 0.3 * (k % 5), cz = -0.3 + 0.3 * (k / 5);
    for (double y : {0.0995, 0.2995 + 0.05 + 0.02 * k}) {
      z.bodies.push_back(box);
      x.push_back({cx, y, cz});
      zero.push_back({0, 0, 0});
      q.push_back({1, 0, 0, 0});
    }
  }
  z.states.push_back(initial(z, x, zero, zero, q));
  const double e = 0.5;
  z.run(frames, false, [&](const State& s, State& t, std::vector<Row>& rows) {
    for (int k = 0; k < 15; ++k) {
      const int b = 1 + 2 * k, top = 2 + 2 * k;
      const double df = 0.1 - s.x[b][1], dbt = 0.2 - (s.x[top][1] - s.x[b][1]);
      const V vb0 = t.v[b], vt0 = t.v[top];
      // (v_A - v_B) . n with n = -y: the floor's row (A the floor) v_b,y; the boxes' (A the
      // bottom one) v_top,y - v_b,y. Negative: approaching.
      const double approach = vt0[1] - vb0[1], target = approach < -0.05 ? -e * approach : 0.0;
      double jf = 0, jbt = 0, vb = vb0[1], vt = vt0[1];
      for (int it = 0; it < 30; ++it) {
        if (df > 0) {
          const double nj = std::max(0.0, jf - vb);
          vb += nj - jf;
          jf = nj;
        }
        if (dbt > 0) {
          const double nj = std::max(0.0, jbt + (target - (vt - vb)) / 2.0);
          vt += nj - jbt;
          vb -= nj - jbt;
          jbt = nj;
        }
      }
      auto corners = [&](int a, int bb, double depth, double y, double j) {
        double sum = 0;
        for (int c = 0; c < 4; ++c) {
          Row r;
          r.a = a;
          r.b = bb;
          r.n = {0, -1, 0};
          r.depth = f32(depth);
          r.p = f32(V{s.x[b][0] + (c & 1 ? 0.1 : -0.1), y, s.x[b][2] + (c & 2 ? 0.1 : -0.1)});
          r.jn = f32(j / 4);
          sum += r.jn;
          rows.push_back(r);
        }
        return sum;
      };
      const double sf = df > 0 ? corners(0, b, df, -0.5 * df, jf) : 0.0;
      const double sbt = dbt > 0 ? corners(b, top, dbt, s.x[b][1] + 0.1 - 0.5 * dbt, jbt) : 0.0;
      t.v[b] = vb0 + (sf - sbt) * V{0, 1, 0};  // the rows' impulses (1 kg each): on A along n, on B -n
      t.v[top] = vt0 + sbt * V{0, 1, 0};
    }
    std::stable_sort(rows.begin(), rows.end(),
                     [](const Row& l, const Row& r) { return std::make_pair(l.a, l.b) < std::make_pair(r.a, r.b); });
  });
  return z;
}

/// Zoo engine (j) whose API reports no row in the step of a contact's last impulse, as
/// Havok's "collision finished" events carry no data: in every contact that ends before
/// the run does, the rows of its last step with a normal impulse are dropped.
Zoo drop_ended_contacts(Zoo z) {
  std::map<std::pair<int, int>, int> last_impulse;  // pair -> step index of its episode's last impulse
  std::vector<std::set<std::pair<int, int>>> dropped(z.rows.size());
  for (std::size_t f = 0; f < z.rows.size(); ++f) {
    std::set<std::pair<int, int>> here;
    for (const Row& r : z.rows[f]) {
      here.insert({r.a, r.b});
      if (r.jn > 0) last_impulse[{r.a, r.b}] = static_cast<int>(f);
    }
    for (auto it = last_impulse.begin(); it != last_impulse.end();) {
      if (here.count(it->first)) {
        ++it;
        continue;
      }
      dropped[static_cast<std::size_t>(it->second)].insert(it->first);  // the episode ended before step f
      it = last_impulse.erase(it);
    }
  }
  for (std::size_t f = 0; f < z.rows.size(); ++f) {
    auto& step = z.rows[f];
    step.erase(std::remove_if(step.begin(), step.end(), [&](const Row& r) { return dropped[f].count({r.a, r.b}) > 0; }),
               step.end());
  }
  return z;
}

TEST_F(ZooEngines, DroppedContactRowsAreJudgedOnTheGeometry) {
  const Zoo pile = pile_engine();
  ASSERT_GT(first_impulse(pile, 1, 2), 0);
  expect_clean(judge(pile, "pile"));  // every row reported: a clean run
  const Zoo havok = drop_ended_contacts(pile);
  std::size_t rows = 0, kept = 0;
  for (std::size_t f = 0; f < pile.rows.size(); ++f) {
    rows += pile.rows[f].size();
    kept += havok.rows[f].size();
  }
  ASSERT_GT(rows - kept, 40u);  // the bounces' last impulses
  // Declared complete, the top boxes read as free while a dropped impulse moves them.
  expect_caught(judge(havok, "declared-complete"), {"free-flight", "without contacts: v'"});
  Zoo incomplete = havok;
  incomplete.numbers["contacts_complete"] = 0;
  const Result ok = judge(incomplete, "incomplete");
  expect_clean(ok);
  EXPECT_TRUE(row_verdict(ok.output, "free-flight", "pass")) << ok.output;  // judged, not n/a
  EXPECT_TRUE(row_verdict(ok.output, "momentum-balance", "n/a")) << ok.output;
  EXPECT_TRUE(row_verdict(ok.output, "contact-completeness", "n/a")) << ok.output;
  EXPECT_NE(ok.output.find("body-steps without rows but near a body not judged"), std::string::npos) << ok.output;
  // A top box edited in free flight (body 30 falls 33 cm: 10 cm above its column at step 100).
  {
    Zoo f = incomplete;
    ASSERT_GT(f.states[100].x[30][1] - f.states[100].x[29][1], 0.25);
    f.states[100].v[30] = f32(1.5 * f.states[100].v[30]);
    expect_caught(judge(f, "fast"), {"free-flight", "frame 100: body 30 without contacts: v'"});
  }
  {
    Zoo f = incomplete;
    f.states[100].x[30][0] = f32(f.states[100].x[30][0] + 0.01);
    expect_caught(judge(f, "teleport"), {"frame 100: body 30 without contacts: x'", "position"});
  }
}

/// Zoo engine (j) reporting every impulse `ratio` of what it applied (Havok: 0.17% low).
Zoo biased(Zoo z, double ratio) {
  for (auto& step : z.rows)
    for (Row& r : step) r.jn = f32(ratio * r.jn);
  return z;
}

TEST_F(ZooEngines, ASystematicImpulseRatioIsOneFinding) {
  const Zoo pile = pile_engine();
  const int fi = first_impulse(pile, 29, 30);  // body 30 lands on body 29
  ASSERT_GT(fi, 0);
  const Zoo low = biased(pile, 0.998);
  const Result ok = judge(low, "low");
  expect_clean(ok);
  EXPECT_TRUE(row_verdict(ok.output, "momentum-balance", "pass")) << ok.output;
  EXPECT_NE(ok.output.find("impulse ratio 0.99800"), std::string::npos) << ok.output;
  EXPECT_NE(ok.output.find("within the 1% a systematic ratio may take"), std::string::npos) << ok.output;
  {  // the unbiased run fits 1
    const Result exact = judge(pile, "exact");
    EXPECT_NE(exact.output.find("impulse ratio 1.00000"), std::string::npos) << exact.output;
  }
  {  // body 30's velocity x1.5 in the step it lands: caught beside the bias
    Zoo f = low;
    f.states[fi].v[30] = f32(1.5 * f.states[fi].v[30]);
    const Result r = judge(f, "fast");
    expect_caught(r, {"momentum-balance", "frame " + std::to_string(fi) + ": body 30"});
    EXPECT_EQ(failing_causes(r.output).count("momentum-balance/ratio"), 0u) << r.output;
  }
  {  // one of body 1's four floor rows dropped in step 200
    Zoo f = low;
    auto& step = f.rows[199];
    const auto it = std::find_if(step.begin(), step.end(), [](const Row& r) { return r.a == 0 && r.b == 1; });
    ASSERT_NE(it, step.end());
    step.erase(it);
    expect_caught(judge(f, "dropped"), {"momentum-balance", "frame 200: body 1"});
  }
  {  // 2% low: the bias itself is the one finding, no body-step fails
    const Result r = judge(biased(pile, 0.98), "bias");
    EXPECT_EQ(r.code, 3) << r.output;
    const std::set<std::string> causes = failing_causes(r.output);
    EXPECT_EQ(causes, (std::set<std::string>{"momentum-balance/ratio"})) << r.output;
    EXPECT_NE(r.output.find("the reported impulses are 0.98000 of the momentum change"), std::string::npos)
        << r.output;
  }
}

/// Zoo engine (j) reporting each row's jn off by its own uniform random factor in
/// [1 - scatter, 1 + scatter] (Havok: about +-0.2% around the momentum change).
Zoo scattered(Zoo z, double scatter) {
  std::mt19937 random(78);
  std::uniform_real_distribution<double> factor(1.0 - scatter, 1.0 + scatter);
  for (auto& step : z.rows)
    for (Row& r : step) r.jn = f32(factor(random) * r.jn);
  return z;
}

TEST_F(ZooEngines, ASpreadOfImpulsesIsOneFinding) {
  const Zoo pile = pile_engine();
  const int fi = first_impulse(pile, 29, 30);  // body 30 lands on body 29
  ASSERT_GT(fi, 0);
  const Zoo spread = scattered(pile, 0.002);
  const Result ok = judge(spread, "spread");
  expect_clean(ok);
  EXPECT_TRUE(row_verdict(ok.output, "momentum-balance", "pass")) << ok.output;
  const std::regex finding(
      "one finding, a spread of the reported impulses about the momentum change: quartiles "
      "([0-9.]+) \\.\\. ([0-9.]+) over ([0-9]+) body-steps whose rows push one way, about the centre ([0-9.]+); "
      "([0-9]+) body-steps failing at it pass");
  std::smatch m;
  ASSERT_TRUE(std::regex_search(ok.output, m, finding)) << ok.output;
  const double q1 = std::stod(m[1]), q3 = std::stod(m[2]), centre = std::stod(m[4]);
  EXPECT_LT(q1, 1.0 - 2e-4) << m[0];  // a scatter, not one factor: the quartiles apart
  EXPECT_GT(q3, 1.0 + 2e-4) << m[0];
  EXPECT_GT(q1, 1.0 - 2e-3) << m[0];  // inside the planted +-0.2%
  EXPECT_LT(q3, 1.0 + 2e-3) << m[0];
  EXPECT_NEAR(centre, 1.0, 5e-4) << m[0];
  EXPECT_GT(std::stoull(m[5]), 100u) << m[0];  // body-steps failing at the centre alone
  {  // body 30's velocity x1.5 in the step it lands: still caught, naming frame and body
    Zoo f = spread;
    f.states[fi].v[30] = f32(1.5 * f.states[fi].v[30]);
    const Result r = judge(f, "fast");
    expect_caught(r, {"momentum-balance", "frame " + std::to_string(fi) + ": body 30"});
    EXPECT_EQ(failing_causes(r.output).count("momentum-balance/ratio"), 0u) << r.output;
  }
  {  // one of body 1's four floor rows dropped in step 200
    Zoo f = spread;
    auto& step = f.rows[199];
    const auto it = std::find_if(step.begin(), step.end(), [](const Row& r) { return r.a == 0 && r.b == 1; });
    ASSERT_NE(it, step.end());
    step.erase(it);
    expect_caught(judge(f, "dropped"), {"momentum-balance", "frame 200: body 1"});
  }
  {  // a 2% systematic factor on the scatter: the factor is the one finding
    const Result r = judge(biased(spread, 0.98), "bias");
    EXPECT_EQ(r.code, 3) << r.output;
    EXPECT_EQ(failing_causes(r.output), (std::set<std::string>{"momentum-balance/ratio"})) << r.output;
    EXPECT_NE(r.output.find("the reported impulses are 0.98"), std::string::npos) << r.output;
  }
  {  // a 2% scatter: the spread itself is the one finding (fences beyond 1 +- 1%)
    const Result r = judge(scattered(pile, 0.02), "wide");
    EXPECT_EQ(r.code, 3) << r.output;
    EXPECT_EQ(failing_causes(r.output), (std::set<std::string>{"momentum-balance/ratio"})) << r.output;
    EXPECT_NE(r.output.find("the reported impulses scatter from"), std::string::npos) << r.output;
  }
}

/// (l) Two witness points per row (cannon-es, Bullet): two 1 kg boxes meet face to face
/// along x in the air; the engine applies the row's impulse at a point on each body, on
/// A's +x face 2 cm above A's centre and on B's -x face 1 cm below it (3 cm apart across
/// the normal), with the impulse those two levers give (restitution 0.5 at the points):
/// the pair leaves turning, its angular momentum changed by (p_a - p_b) x J. Declared by
/// /contacts/point_b.
Zoo witness_pair_engine(int frames = 40) {
  Zoo z;
  z.engine = "zoo-witness-pair";
  z.bodies = {Body{}, Body{}};
  z.point_b = true;
  z.numbers["contact_margin"] = 0.002;
  const double e = 0.5;
  z.states.push_back(initial(z, {{-0.2105, 1.0, 0}, {0, 1.0, 0}}, {{1, 0, 0}, {0, 0, 0}}, {{0, 0, 0}, {0, 0, 0}},
                             {{1, 0, 0, 0}, {1, 0, 0, 0}}));
  z.run(frames, false, [&](const State& s, State& t, std::vector<Row>& rows) {
    const double d = 0.2 - (s.x[1][0] - s.x[0][0]);
    if (!(d > 0)) return;
    Row r;
    r.a = 0;
    r.b = 1;
    r.n = {-1, 0, 0};
    r.depth = f32(d);
    r.p = f32(s.x[0] + V{0.1, 0.02, 0});
    r.pb = f32(s.x[1] + V{-0.1, -0.01, 0});
    const V ra = r.p - s.x[0], rb = r.pb - s.x[1];
    const M ia = conj(rotation(s.q[0]), diag({1 / z.bodies[0].inertia()[0], 1 / z.bodies[0].inertia()[4],
                                              1 / z.bodies[0].inertia()[8]}));
    const M ib = conj(rotation(s.q[1]), diag({1 / z.bodies[1].inertia()[0], 1 / z.bodies[1].inertia()[4],
                                              1 / z.bodies[1].inertia()[8]}));
    const double vn = dot((t.v[0] + cross(t.w[0], ra)) - (t.v[1] + cross(t.w[1], rb)), r.n);
    if (vn < 0) {
      const V ca = cross(ra, r.n), cb = cross(rb, r.n);
      const double k = 1 / z.bodies[0].m + 1 / z.bodies[1].m + dot(ca, mul(ia, ca)) + dot(cb, mul(ib, cb));
      r.jn = f32(-(1 + e) * vn / k);
      const V j = r.jn * r.n;  // on A at p, -j on B at pb
      t.v[0] = t.v[0] + (1 / z.bodies[0].m) * j;
      t.w[0] = t.w[0] + mul(ia, cross(ra, j));
      t.v[1] = t.v[1] - (1 / z.bodies[1].m) * j;
      t.w[1] = t.w[1] - mul(ib, cross(rb, j));
    }
    rows.push_back(r);
  });
  return z;
}

TEST_F(ZooEngines, TwoWitnessPointsPerRowAreJudgedOnBoth) {
  const Zoo z = witness_pair_engine();
  const int first = first_impulse(z, 0, 1);
  ASSERT_GT(first, 0);
  // The pair leaves turning: each body's spin is its own lever's.
  ASSERT_GT(norm(z.states[first].w[0]), 1.0);
  ASSERT_GT(norm(z.states[first].w[1]), 0.5);
  const std::string at = "frame " + std::to_string(first);
  {  // every row passes; impulse-feasibility takes each row's impulse at its two witness points
     // too (docs/validation.md, impulse-feasibility)
    const Result r = judge(z, "witness-pair");
    for (const char* row :
         {"contact-geometry", "friction", "conservation", "momentum-balance", "free-flight", "impulse-feasibility"})
      EXPECT_TRUE(row_verdict(r.output, row, "pass")) << row << "\n" << r.output;
  }
  {  // B leaves the step 1.5x as fast: no compressive impulse at either pair of points explains it
    Zoo fast = z;
    fast.states[std::size_t(first)].v[1] = 1.5 * fast.states[std::size_t(first)].v[1];
    const Result r = judge(fast, "witness-pair-fast");
    EXPECT_TRUE(row_verdict(r.output, "impulse-feasibility", "FAIL")) << r.output;
    EXPECT_NE(r.output.find(at + " body 1: " + at + ": island group (0, 1)"), std::string::npos) << r.output;
  }
  {  // one point per row (A's): B's lever is 3 cm off across the normal
    Zoo one = z;
    one.point_b = false;
    const Result r = judge(one, "one-point");
    expect_caught(r, {at + ": body 1", at + ": isolated group of 2 bodies"});
    EXPECT_TRUE(row_verdict(r.output, "momentum-balance", "FAIL")) << r.output;
    EXPECT_TRUE(row_verdict(r.output, "conservation", "FAIL")) << r.output;
  }
  {  // B's point moved 1 cm off B's face (into A, along the normal: the levers' torques stay)
    Zoo off = z;
    off.rows[first - 1][0].pb = f32(off.rows[first - 1][0].pb + V{-0.01, 0, 0});
    const Result r = judge(off, "point-b-off");
    expect_caught(r, {"contact-geometry", at + ": pair (0, 1) row 0: point_b"});
    EXPECT_TRUE(row_verdict(r.output, "momentum-balance", "pass")) << r.output;
  }
  {  // a point on B that is not a number: refused before anything is judged (exit 2)
    Zoo bad = z;
    bad.rows[first - 1][0].pb = {std::nan(""), 0, 0};
    const Result r = judge(bad, "point-b-nan");
    EXPECT_EQ(r.code, 2) << r.output;
    for (const std::string& f :
         {std::string("/contacts/point_b: ") + at + ": row 0 (pair (0, 1))", std::string("not finite")})
      EXPECT_NE(r.output.find(f), std::string::npos) << f << "\n" << r.output;
  }
}

TEST_F(ZooEngines, BadDeclarationsExitTwoNamingTheAttribute) {
  Zoo z = soft_engine(5);
  z.text["contact_model"] = "squishy";
  Result r = judge(z, "bad-model");
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find("contact_model"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("\"rigid\", \"soft\""), std::string::npos) << r.output;
  z.text["contact_model"] = "soft";
  z.text["integrator"] = "verlet";
  r = judge(z, "bad-integrator");
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find("\"semi-implicit\", \"explicit\", \"any\", \"substepped\""), std::string::npos)
      << r.output;
  z.text["integrator"] = "substepped";  // without `substeps`
  r = judge(z, "bad-substeps");
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find("root attribute substeps"), std::string::npos) << r.output;
  z.numbers["substeps"] = 2.5;
  r = judge(z, "bad-substeps-value");
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find("an integer n in [1, 1000000]"), std::string::npos) << r.output;
  z.text.erase("integrator");  // `substeps` alone
  r = judge(z, "substeps-alone");
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find("given without integrator"), std::string::npos) << r.output;
  z.numbers.erase("substeps");
  z.text["gyroscopic"] = "yes";
  r = judge(z, "bad-gyro");
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find("gyroscopic"), std::string::npos) << r.output;
  z.text.erase("gyroscopic");
  z.bodies[1].locked = 64;
  r = judge(z, "bad-locked");
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find("/bodies/locked_dofs: body 1: 64"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("0 .. 63"), std::string::npos) << r.output;
}

}  // namespace

namespace {

// The h5py writer example of the declarations (docs/trace-format.md, "Declarations"):
// explicit Euler, a gyroscopic term, soft contacts and a rotation-locked cube pass.
TEST_F(ZooEngines, PythonDeclarationsWriterPasses) {
  const std::string python = "/usr/bin/python3";
  if (octocd::test::run(python + " -c 'import h5py, numpy'").code != 0)
    GTEST_SKIP() << python << " lacks h5py or numpy: the example cannot run";
  const std::string out = (dir_ / "declared.h5").string();
  const Result w = octocd::test::run(python + " " + octocd::test::source_dir() +
                                     "/examples/python/declarations_writer.py " + out);
  ASSERT_EQ(w.code, 0) << w.output;
  const Result r = run_octocd("validate --trace-in " + out);
  expect_clean(r);
  for (const char* f : {"integrator explicit", "gyroscopic term declared", "contact_model soft", "rotation locked"})
    EXPECT_NE(r.output.find(f), std::string::npos) << f << "\n" << r.output;
}

}  // namespace

}  // namespace octocd_test_cli_zoo_engines
