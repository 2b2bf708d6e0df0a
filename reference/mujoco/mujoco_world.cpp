/// \file mujoco_world.cpp
/// octocd::MujocoWorld: the scene in MuJoCo 2.2 (see mujoco_world.hpp for every setting
/// and why).

#include "octocd/mujoco_world.hpp"
#include "octocd/adapter_rows.hpp"

#include <fmt/format.h>
#include <mujoco/mujoco.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "octocd/convex_hull.hpp"
#include "octocd/error.hpp"
#include "octocd/pose.hpp"
#include "octocd/text.hpp"
#include "octocd/version.hpp"

namespace octocd {

namespace {

/// While alive, what the process writes to stdout and stderr (file descriptors 1 and 2) goes
/// to a temporary file instead of the terminal: MuJoCo's qhull prints its errors there
/// (57 lines for a flat mesh). text() returns it; the descriptors are restored on destruction.
class CapturedOutput {
 public:
  CapturedOutput() : file_(std::tmpfile()) {
    if (!file_) return;
    std::fflush(stdout);
    std::fflush(stderr);
    for (int k = 0; k < 2; ++k) {
      saved_[k] = ::dup(k + 1);
      if (saved_[k] >= 0) ::dup2(::fileno(file_), k + 1);
    }
  }
  ~CapturedOutput() {
    restore();
    if (file_) std::fclose(file_);
  }
  CapturedOutput(const CapturedOutput&) = delete;
  CapturedOutput& operator=(const CapturedOutput&) = delete;
  /// Restores stdout and stderr, then returns at most 64 KiB of what was written.
  std::string text() const {
    const_cast<CapturedOutput*>(this)->restore();
    if (!file_) return "";
    std::string out(64u << 10, '\0');
    std::rewind(file_);
    out.resize(std::fread(out.data(), 1, out.size(), file_));
    return out;
  }

 private:
  void restore() {
    std::fflush(stdout);
    std::fflush(stderr);
    for (int k = 0; k < 2; ++k)
      if (saved_[k] >= 0) {
        ::dup2(saved_[k], k + 1);
        ::close(saved_[k]);
        saved_[k] = -1;
      }
  }
  std::FILE* file_;
  int saved_[2] = {-1, -1};
};

/// The first non-empty line of `text` (cut to 300 bytes), for a one-line message.
std::string first_line(const std::string& text) {
  std::size_t a = text.find_first_not_of(" \t\r\n");
  if (a == std::string::npos) return "";
  const std::size_t b = text.find_first_of("\r\n", a);
  return bounded(text.substr(a, b == std::string::npos ? std::string::npos : b - a), 300);
}

/// MuJoCo's error handler while a MuJoCo call runs (MujocoCall): MuJoCo's default prints,
/// appends to MUJOCO_LOG.TXT in the working directory and exits the process.
[[noreturn]] void throw_mujoco_error(const char* msg) { throw RuntimeError(std::string("MuJoCo error: ") + msg); }

/// The last warning MuJoCo issued during a MujocoCall (the counts are in mjData::warning).
thread_local std::string g_last_warning;
void keep_mujoco_warning(const char* msg) { g_last_warning = msg; }

/// Installs octocd's MuJoCo error and warning handlers for the lifetime of the object
/// and puts the previous ones back: MuJoCo's handlers are process-wide function pointers
/// (mju_user_error, mju_user_warning), so they are set only while octocd calls MuJoCo.
class MujocoCall {
 public:
  MujocoCall() : error_(mju_user_error), warning_(mju_user_warning) {
    mju_user_error = &throw_mujoco_error;
    mju_user_warning = &keep_mujoco_warning;
  }
  ~MujocoCall() {
    mju_user_error = error_;
    mju_user_warning = warning_;
  }
  MujocoCall(const MujocoCall&) = delete;
  MujocoCall& operator=(const MujocoCall&) = delete;

 private:
  void (*error_)(const char*);
  void (*warning_)(const char*);
};

/// A float as decimal text that reads back to the same float ("%.9g").
std::string num(double v) { return fmt::format("{:.9g}", v); }
std::string vec(Vec3 v) { return fmt::format("{:.9g} {:.9g} {:.9g}", v.x, v.y, v.z); }
/// MJCF quaternions are (w, x, y, z), as octocd's Quat.
std::string quat(Quat q) { return fmt::format("{:.9g} {:.9g} {:.9g} {:.9g}", q.w, q.x, q.y, q.z); }

/// The damping ratio of a linear spring-damper contact whose rebound velocity is e times
/// the approach velocity: e = exp(-pi z / sqrt(1 - z^2)) solved for z; 1 (critical
/// damping, no rebound) for e = 0; at least 1e-3 (e -> 1 would need z = 0, an infinitely
/// stiff spring in MuJoCo's parametrisation).
double damping_ratio(double e) {
  constexpr double kPi = 3.14159265358979323846;
  if (!(e > 0.0)) return 1.0;
  const double l = std::log(std::min(e, 1.0));
  return std::max(1e-3, -l / std::sqrt(kPi * kPi + l * l));
}

/// The solid box of half extents h at mass m: its diagonal inertia (kg m^2).
std::array<double, 3> solid_box_inertia(Vec3 h, double m) {
  const double a = 2.0 * h.x, b = 2.0 * h.y, c = 2.0 * h.z;
  return {m / 12.0 * (b * b + c * c), m / 12.0 * (a * a + c * c), m / 12.0 * (a * a + b * b)};
}

}  // namespace

struct MujocoWorld::Impl : SettingsCore<MujocoSettings> {
  std::string xml;
  mjModel* m = nullptr;
  mjData* d = nullptr;
  double timeconst = 0.002;  // solref[0] of every geom (s)
  std::vector<int> qpos_adr, dof_adr;  // per octocd body: free joint addresses (-1: static)
  std::vector<std::uint32_t> geom_body;  // per MuJoCo geom: the octocd body
  std::vector<std::array<double, 3>> diag_inertia;  // per body, diagonal, body frame (0: static)
  std::array<int, mjNWARNING> warnings{};  // mjData::warning counts seen so far
  int nconmax = 0, njmax = 0;  // the contact and constraint capacity (<size>), from max_contacts
  const char* solver = "Newton";  // mjOption::solver: "Newton", or "CG" above kMostNewtonBodies

  ~Impl() override {
    if (d) mj_deleteData(d);
    if (m) mj_deleteModel(m);
  }

  void read_state();
  void check_step();
  void check_capacity() const;
  std::string body_of_index(int k, int index) const;
  void fill_record();
};

void MujocoWorld::Impl::read_state() {
  for (std::size_t i = 0; i < w.size(); ++i) {
    if (qpos_adr[i] < 0) continue;  // static: as given
    const mjtNum* qp = d->qpos + qpos_adr[i];
    const mjtNum* qv = d->qvel + dof_adr[i];
    state.x[i] = {static_cast<float>(qp[0]), static_cast<float>(qp[1]), static_cast<float>(qp[2])};
    state.q[i] = {static_cast<float>(qp[3]), static_cast<float>(qp[4]), static_cast<float>(qp[5]),
                  static_cast<float>(qp[6])};
    state.v[i] = {static_cast<float>(qv[0]), static_cast<float>(qv[1]), static_cast<float>(qv[2])};
    mjtNum wb[3] = {qv[3], qv[4], qv[5]}, ww[3];
    mju_rotVecQuat(ww, wb, qp + 3);  // the free joint's angular velocity is in the body frame
    state.omega[i] = {static_cast<float>(ww[0]), static_cast<float>(ww[1]), static_cast<float>(ww[2])};
  }
}

/// The octocd body whose free joint holds index `index` of qpos (warning k =
/// mjWARN_BADQPOS) or of qvel/qacc (the others: a DOF), as ": DOF 9 is body 6 (group
/// g)"; empty when no body holds it.
std::string MujocoWorld::Impl::body_of_index(int k, int index) const {
  const bool qpos = k == mjWARN_BADQPOS;
  const std::vector<int>& adr = qpos ? qpos_adr : dof_adr;
  const int width = qpos ? 7 : 6;
  for (std::size_t i = 0; i < adr.size(); ++i)
    if (adr[i] >= 0 && adr[i] <= index && index < adr[i] + width)
      return fmt::format(": {} {} is body {} (group {})", qpos ? "qpos index" : "DOF", index, i, model->bodies[i].group);
  return "";
}

/// After a step: a non-finite state names its body; a MuJoCo warning (buffers full:
/// contacts or constraints dropped; a bad qpos, qvel or qacc: the state reset, named
/// with the octocd body of MuJoCo's index) throws.
void MujocoWorld::Impl::check_step() {
  for (std::size_t i = 0; i < w.size(); ++i) {
    if (qpos_adr[i] < 0) continue;
    bool finite = true;
    for (int k = 0; k < 7; ++k) finite = finite && std::isfinite(d->qpos[qpos_adr[i] + k]);
    for (int k = 0; k < 6; ++k) finite = finite && std::isfinite(d->qvel[dof_adr[i] + k]);
    if (!finite)
      throw RuntimeError(fmt::format("mujoco: body {} has a non-finite position, orientation or velocity after frame {}",
                                     i, frame));
  }
  static const char* const kWhat[mjNWARNING] = {
      "(near) singular inertia matrix",
      "contact buffer full: contacts were dropped (raise MujocoSettings::max_contacts, key max_contacts)",
      "constraint buffer full: contacts were left out of the solver",
      "visual geom buffer full",
      "bad number in qpos: MuJoCo reset the state",
      "bad number in qvel: MuJoCo reset the state",
      "bad number in qacc: MuJoCo reset the state",
      "bad number in ctrl"};
  for (int k = 0; k < mjNWARNING; ++k) {
    if (d->warning[k].number == warnings[static_cast<std::size_t>(k)]) continue;
    warnings[static_cast<std::size_t>(k)] = d->warning[k].number;
    if (k == mjWARN_VGEOMFULL || k == mjWARN_BADCTRL) continue;  // nothing octocd uses
    const bool bad_state = k == mjWARN_BADQPOS || k == mjWARN_BADQVEL || k == mjWARN_BADQACC;
    throw RuntimeError(fmt::format("mujoco: frame {}: MuJoCo warning: {} ({}){}", frame, k < 8 ? kWhat[k] : "unknown",
                                   g_last_warning, bad_state ? body_of_index(k, d->warning[k].lastinfo) : ""));
  }
}

/// After mj_fwdPosition (collision and constraint set-up): a full contact or constraint
/// buffer throws, naming max_contacts and its value, before mj_fwdConstraint runs on the
/// truncated arrays (MuJoCo 2.2 ends there in SIGSEGV: docs/engines.md).
void MujocoWorld::Impl::check_capacity() const {
  const bool contacts = d->warning[mjWARN_CONTACTFULL].number != warnings[mjWARN_CONTACTFULL];
  const bool rows = d->warning[mjWARN_CNSTRFULL].number != warnings[mjWARN_CNSTRFULL];
  if (!contacts && !rows) return;
  throw RuntimeError(fmt::format(
      "mujoco: frame {}: the {} is full ({} {}): MuJoCo would drop {} and its solver may then crash; "
      "--mujoco max_contacts={} ({}); allowed: a larger max_contacts (an integer in [1, 1000000]; MuJoCo 2.2 "
      "allocates several arrays of njmax x nv x 8 bytes and refuses 2^31 in all, docs/engines.md)",
      frame + 1, contacts ? "contact buffer" : "constraint buffer", contacts ? "nconmax" : "njmax",
      contacts ? nconmax : njmax, contacts ? "contacts" : "constraint rows", nconmax,
      settings.max_contacts > 0 ? "as set"
                                : "the default: 6 per dynamic body, at least 256, at most 1500 and what keeps njmax x nv "
                                  "x 8 bytes within 2^29"));
}

void MujocoWorld::Impl::fill_record() {
  FrameRecord& r = record;
  r.has_pairs = false;
  r.pairs.clear();
  r.contacts.clear();
  r.jt3.clear();
  std::vector<ContactRecord> rows;
  std::vector<Vec3> jt3;
  for (int k = 0; k < d->ncon; ++k) {
    const mjContact& con = d->contact[k];
    if (con.exclude != 0 && con.exclude != 1) continue;  // fused, equality, no dofs: not a contact of the scene
    const std::uint32_t g1 = geom_body[static_cast<std::size_t>(con.geom1)];
    const std::uint32_t g2 = geom_body[static_cast<std::size_t>(con.geom2)];
    if (g1 == g2) continue;
    mjtNum f[6] = {0, 0, 0, 0, 0, 0};
    if (con.efc_address >= 0) mj_contactForce(m, d, k, f);  // contact frame, the force on geom2
    const mjtNum* fr = con.frame;
    // World force on geom2's body: normal along frame row 0, friction along rows 1 and 2.
    mjtNum ft[3];
    for (int c = 0; c < 3; ++c) ft[c] = f[1] * fr[3 + c] + f[2] * fr[6 + c];
    const bool a_is_geom1 = g1 < g2;  // then the normal (geom1 -> geom2) points from A to B
    ContactRecord row;
    row.pair = {std::min(g1, g2), std::max(g1, g2)};
    const float s = a_is_geom1 ? -1.0f : 1.0f;  // geom1 -> geom2 as seen from B to A
    row.normal = {s * static_cast<float>(fr[0]), s * static_cast<float>(fr[1]), s * static_cast<float>(fr[2])};
    row.depth = static_cast<float>(std::max(0.0, -con.dist));
    row.point = {static_cast<float>(con.pos[0]), static_cast<float>(con.pos[1]), static_cast<float>(con.pos[2])};
    row.jn = static_cast<float>(f[0] * dt);
    // The tangential impulse on A: geom2 gets +ft, geom1 -ft.
    const double sa = a_is_geom1 ? -dt : dt;
    const Vec3 j_a{static_cast<float>(sa * ft[0]), static_cast<float>(sa * ft[1]), static_cast<float>(sa * ft[2])};
    row.jt = row_scalar_jt(r, row, j_a, w, dt, gravity);
    rows.push_back(row);
    jt3.push_back(j_a);
  }
  finish_manifold_record(r, rows, jt3);
}

MujocoWorld::MujocoWorld(std::shared_ptr<const Model> model, const BodyState& initial, const MujocoSettings& settings)
    : SettingsWorld(std::make_unique<Impl>(), std::move(model), initial, "mujoco", settings) {
  Impl& im = impl();
  const Model& src = *im.model;
  const Scene& scene = src.scene;
  const std::size_t n = initial.size();
  for (std::size_t i = 0; i < n; ++i) im.state.q[i] = normalized(im.state.q[i]);

  // ---- The MJCF text.
  const double mu = scene.response.mu_kinetic;
  const double e = scene.response.restitution;
  const double zeta = damping_ratio(e);
  const double timeconst = settings.timeconst > 0.0 ? settings.timeconst : 2.0 * im.dt / zeta;
  im.timeconst = timeconst;
  std::size_t dynamic = 0;
  for (std::size_t i = 0; i < n; ++i) dynamic += initial.w[i] > 0.0f ? 1 : 0;
  // Contact capacity: MujocoSettings::max_contacts, or 6 per dynamic body (a box resting
  // on a face has 4), at least 256 and at most kMostDefaultContacts; constraint rows 3 per
  // elliptic contact (condim 3), 4 per pyramidal one. MuJoCo 2.2 allocates its constraint
  // arrays at these sizes, some (J M^-1 J' + R) quadratic in the rows: 12 bytes x rows^2
  // (1500 contacts: about 1 GB; rot-pile-1000's 6000 could not be allocated).
  // MuJoCo 2.2 also allocates mjData's constraint arrays, several of njmax x nv mjtNums
  // (efc_J among them), in one buffer sized as an int, and refuses the scene ("could not
  // create mjData") past 2^31 bytes: njmax 4,500 failed at nv 24,000 (one array 8.6e8
  // bytes) with a stack of 1.5e8 bytes. The default keeps one array, njmax x nv x 8 bytes,
  // within 2^29 (at least 16 contacts).
  constexpr std::size_t kMostDefaultContacts = 1500;
  const std::size_t rows_per_contact = settings.cone == MujocoCone::Elliptic ? 3 : 4;
  const std::size_t jacobian_contacts =
      std::max<std::size_t>(16, (std::size_t{1} << 29) / (8 * rows_per_contact * std::max<std::size_t>(1, 6 * dynamic)));
  const int nconmax =
      settings.max_contacts > 0
          ? settings.max_contacts
          : static_cast<int>(std::min({kMostDefaultContacts, jacobian_contacts, std::max<std::size_t>(256, 6 * dynamic)}));
  const int njmax = nconmax * static_cast<int>(rows_per_contact);
  im.nconmax = nconmax;
  im.njmax = njmax;
  // The solver and the stack, from the scene (docs/engines.md, "Set-up of large scenes"):
  // MuJoCo 2.2's Newton solver takes 3 nv^2 mjtNums of mjData's stack (its dense Hessians;
  // mjData::maxuse_stack 432,228,360 at nv = 12,000) and sizes them as an int nv * nv,
  // which wraps past nv = 46,340 (7,723 free bodies: a negative request that
  // mj_stackAlloc does not refuse, the SIGSEGV in mj_fwdConstraint), and its default
  // nstack (about 5 nv^2 + 12 njmax nv, an int) wraps past about 3,400 free bodies. Up to
  // kMostNewtonBodies dynamic bodies: Newton on MuJoCo's default stack; above: the
  // conjugate-gradient solver (no nv x nv array) on a stack sized here.
  constexpr std::size_t kMostNewtonBodies = 2000;
  const bool newton = dynamic <= kMostNewtonBodies;
  const double nv = 6.0 * static_cast<double>(dynamic), nbody = static_cast<double>(n) + 1.0;
  const long long nstack =
      newton ? -1
             : static_cast<long long>(std::min(2147483647.0, nbody * nbody + 64.0 * (nv + njmax) + 1e6));
  im.solver = newton ? "Newton" : "CG";
  std::string x;
  x.reserve(4096);
  x += "<mujoco model=\"octocd\">\n";
  x += "  <compiler inertiafromgeom=\"false\" angle=\"radian\"/>\n";
  x += fmt::format(
      "  <option timestep=\"{}\" gravity=\"{}\" integrator=\"Euler\" cone=\"{}\" iterations=\"{}\" solver=\"{}\" "
      "impratio=\"1\" density=\"0\" viscosity=\"0\">\n    <flag multiccd=\"{}\"/>\n  </option>\n",
      num(im.dt), vec(scene.gravity), mujoco_cone_name(settings.cone), settings.iterations, im.solver,
      settings.multiccd ? "enable" : "disable");
  x += fmt::format("  <size nconmax=\"{}\" njmax=\"{}\"{}/>\n", nconmax, njmax,
                   nstack > 0 ? fmt::format(" nstack=\"{}\"", nstack) : std::string());
  x += fmt::format(
      "  <default>\n    <geom condim=\"3\" friction=\"{} 0 0\" solref=\"{} {}\" margin=\"{}\" gap=\"{}\"/>\n  "
      "</default>\n",
      num(mu), num(timeconst), num(zeta), num(settings.margin), num(settings.margin));
  // Meshes: one asset per shape with a mesh, its vertices (MuJoCo takes their hull).
  std::vector<char> shape_used(src.shapes.size(), 0);
  for (std::size_t i = 0; i < n; ++i) shape_used[src.bodies[i].shape] = 1;
  bool any_mesh = false;
  for (std::size_t k = 0; k < src.shapes.size(); ++k) {
    const Shape& s = src.shapes[k];
    if (!shape_used[k] || !s.mesh) continue;
    // The hull check every reference engine makes (reference/common/convex_hull.hpp): a mesh
    // that spans no volume (collinear, flat) is the same InputError (exit 2) as on Bullet,
    // ODE and DART, before MuJoCo's own qhull sees it.
    (void)convex_hull(s.mesh->vertices, s.name);
    if (!any_mesh) x += "  <asset>\n";
    any_mesh = true;
    x += fmt::format("    <mesh name=\"s{}\" vertex=\"", k);
    for (const Vec3& v : s.mesh->vertices) {
      x += vec(v);
      x += ' ';
    }
    x += "\"/>\n";
  }
  if (any_mesh) x += "  </asset>\n";
  auto geom = [&](std::size_t i, const std::string& pose) {
    const Shape& s = src.shapes[src.bodies[i].shape];
    if (s.mesh) return fmt::format("<geom name=\"g{}\" type=\"mesh\" mesh=\"s{}\"{}/>", i, src.bodies[i].shape, pose);
    const Vec3 h = 0.5f * (s.local.max - s.local.min);
    return fmt::format("<geom name=\"g{}\" type=\"box\" size=\"{}\"{}/>", i, vec(h), pose);
  };
  x += "  <worldbody>\n";
  for (std::size_t i = 0; i < n; ++i) {
    if (initial.w[i] > 0.0f) continue;
    // A static body: its geom in the world body at its pose (box centred on the local box).
    const Shape& s = src.shapes[src.bodies[i].shape];
    const Pose pose{im.state.x[i], im.state.q[i]};
    const Vec3 at = s.mesh ? pose.position : to_world(pose, center(s.local));
    x += "    " + geom(i, fmt::format(" pos=\"{}\" quat=\"{}\"", vec(at), quat(pose.orientation))) + "\n";
  }
  im.diag_inertia.assign(n, {0.0, 0.0, 0.0});
  for (std::size_t i = 0; i < n; ++i) {
    if (!(initial.w[i] > 0.0f)) continue;
    const Shape& s = src.shapes[src.bodies[i].shape];
    const double mass = 1.0 / static_cast<double>(initial.w[i]);
    im.diag_inertia[i] = solid_box_inertia(0.5f * (s.local.max - s.local.min), mass);
    const std::string at = s.mesh ? "" : fmt::format(" pos=\"{}\"", vec(center(s.local)));
    x += fmt::format(
        "    <body name=\"b{}\" pos=\"{}\" quat=\"{}\">\n      <freejoint name=\"j{}\"/>\n"
        "      <inertial pos=\"0 0 0\" mass=\"{}\" diaginertia=\"{} {} {}\"/>\n      {}\n    </body>\n",
        i, vec(im.state.x[i]), quat(im.state.q[i]), i, num(mass), num(im.diag_inertia[i][0]), num(im.diag_inertia[i][1]),
        num(im.diag_inertia[i][2]), geom(i, at));
  }
  x += "  </worldbody>\n</mujoco>\n";
  im.xml = std::move(x);

  // ---- Load it from MuJoCo's virtual file system.
  {
    const MujocoCall call;
    auto vfs = std::make_unique<mjVFS>();
    mj_defaultVFS(vfs.get());
    const char* file = "octocd-scene.xml";
    if (mj_makeEmptyFileVFS(vfs.get(), file, static_cast<int>(im.xml.size())) != 0)
      throw RuntimeError("mujoco: cannot add the scene to MuJoCo's virtual file system");
    const int at = mj_findFileVFS(vfs.get(), file);
    std::memcpy(vfs->filedata[at], im.xml.data(), im.xml.size());
    char error[1024] = "";
    std::string said;  // what MuJoCo (its qhull) printed while loading: never on the terminal raw
    {
      const CapturedOutput captured;
      im.m = mj_loadXML(file, vfs.get(), error, static_cast<int>(sizeof(error)));
      said = captured.text();
    }
    mj_deleteVFS(vfs.get());
    if (!im.m) {
      // MuJoCo 2.2 sizes mjData's constraint arrays njmax x nv each and refuses them past
      // 2^31 bytes in all (the default capacity keeps one within 2^29).
      const bool data = std::strstr(error, "could not create mjData") != nullptr;
      throw RuntimeError(fmt::format(
          "mujoco: MuJoCo refused the scene '{}': {}{}{}", scene.name, error,
          data ? fmt::format("; MuJoCo 2.2 sizes its constraint arrays njmax x nv mjtNums each (here {} x {}: {:.3g} "
                             "bytes; it refuses 2^31 in all): lower --mujoco max_contacts (now {}{}; docs/engines.md, "
                             "\"Set-up of large scenes\")",
                             njmax, 6 * dynamic, 8.0 * njmax * 6.0 * static_cast<double>(dynamic), nconmax,
                             settings.max_contacts > 0 ? "" : ", the default")
               : std::string(),
          said.empty() ? std::string() : "; it printed: " + first_line(said)));
    }
    if (!said.empty()) std::fprintf(stderr, "octocd: mujoco: %s\n", printable(first_line(said)).c_str());
    im.d = mj_makeData(im.m);
    if (!im.d) throw RuntimeError("mujoco: mj_makeData failed (out of memory?)");
  }

  // ---- Ids, addresses, the initial state in double precision.
  im.qpos_adr.assign(n, -1);
  im.dof_adr.assign(n, -1);
  im.geom_body.assign(static_cast<std::size_t>(im.m->ngeom), 0);
  for (std::size_t i = 0; i < n; ++i) {
    const int g = mj_name2id(im.m, mjOBJ_GEOM, fmt::format("g{}", i).c_str());
    if (g < 0) throw RuntimeError(fmt::format("mujoco: geom g{} missing from the loaded model", i));
    im.geom_body[static_cast<std::size_t>(g)] = static_cast<std::uint32_t>(i);
    if (!(initial.w[i] > 0.0f)) continue;
    const int j = mj_name2id(im.m, mjOBJ_JOINT, fmt::format("j{}", i).c_str());
    if (j < 0) throw RuntimeError(fmt::format("mujoco: joint j{} missing from the loaded model", i));
    im.qpos_adr[i] = im.m->jnt_qposadr[j];
    im.dof_adr[i] = im.m->jnt_dofadr[j];
    mjtNum* qp = im.d->qpos + im.qpos_adr[i];
    mjtNum* qv = im.d->qvel + im.dof_adr[i];
    const Vec3 p = initial.x[i], v = initial.v[i];
    const Quat q = im.state.q[i];
    const Vec3 wv = im.state.omega[i];
    qp[0] = p.x, qp[1] = p.y, qp[2] = p.z;
    mjtNum qd[4] = {q.w, q.x, q.y, q.z};
    mju_normalize4(qd);
    for (int k = 0; k < 4; ++k) qp[3 + k] = qd[k];
    qv[0] = v.x, qv[1] = v.y, qv[2] = v.z;
    // MuJoCo keeps a free joint's angular velocity in the body frame: R^T w.
    mjtNum neg[4], ww[3] = {wv.x, wv.y, wv.z};
    mju_negQuat(neg, qd);
    mju_rotVecQuat(qv + 3, ww, neg);
  }
  im.state.x = initial.x;
  im.state.v = initial.v;
  im.read_state();

  // ---- What the physics tier is told (version 2 root attributes and /bodies).
  RotationTraits& t = im.traits;
  t.mu = static_cast<float>(mu);
  t.restitution = static_cast<float>(e);
  t.friction_combine = "max";      // MuJoCo: the larger friction of the two geoms
  t.restitution_combine = "max";   // one solref for every geom: every pair has e
  t.contact_margin = static_cast<float>(settings.margin);
  t.candidate_pairs = false;  // MuJoCo's broadphase pairs are not exposed: no /pairs
  t.contact_model = "soft";
  t.gyroscopic = "true";
  t.deactivation = "off";  // MuJoCo 2.x has no sleeping: mj_step integrates every body
  t.normal_reuse_deg = 0.0;  // mj_step finds every contact anew (mj_collision): no cached normal
  for (std::size_t i = 0; i < n; ++i) {
    std::array<float, 9> tensor{};
    for (int k = 0; k < 3; ++k) tensor[static_cast<std::size_t>(4 * k)] = static_cast<float>(im.diag_inertia[i][static_cast<std::size_t>(k)]);
    t.inertia.push_back(tensor);
    t.body_friction.push_back(static_cast<float>(mu));
    t.body_restitution.push_back(static_cast<float>(e));
    t.body_collision_shape.push_back("convex_hull");
  }
  bool meshes = false;
  for (std::size_t i = 0; i < n; ++i) meshes = meshes || src.shapes[src.bodies[i].shape].mesh != nullptr;
  im.geometry = meshes ? "mujoco convex hulls (meshes, static ones too), boxes" : "mujoco boxes";
}

MujocoWorld::~MujocoWorld() = default;

MujocoWorld::Impl& MujocoWorld::impl() const { return static_cast<Impl&>(core()); }

const FrameMetrics& MujocoWorld::step() {
  Impl& im = impl();
  const std::size_t n = im.w.size();
  im.save_pre_state();
  const auto t0 = std::chrono::steady_clock::now();
  double detect_ms = 0.0, solve_ms = 0.0, integrate_ms = 0.0;
  {
    // mj_step's sequence (Euler integrator, no sensors, no control callback), in parts.
    const MujocoCall call;
    mjModel* m = im.m;
    mjData* d = im.d;
    mj_checkPos(m, d);
    mj_checkVel(m, d);
    auto t = std::chrono::steady_clock::now();
    mj_fwdPosition(m, d);
    im.check_capacity();
    detect_ms = ms_since(t);
    t = std::chrono::steady_clock::now();
    mj_fwdVelocity(m, d);
    mj_fwdActuation(m, d);
    mj_fwdAcceleration(m, d);
    mj_fwdConstraint(m, d);
    mj_checkAcc(m, d);
    solve_ms = ms_since(t);
    t = std::chrono::steady_clock::now();
    mj_Euler(m, d);
    integrate_ms = ms_since(t);
  }
  const auto t1 = std::chrono::steady_clock::now();
  FrameMetrics fm = im.next_frame();
  im.check_step();
  im.read_state();
  // The world AABBs at the detection pose (the pre-step state): the record's and the pair count's.
  fm.dynamic_pairs = im.posed_overlapping_pairs();
  fm.aabb_pairs = fm.dynamic_pairs + im.static_static;
  if (im.recording) {
    im.save_post_state();  // mj_fwdPosition detects at the state before mj_Euler
    im.fill_record();
  }
  std::uint64_t rows = 0;
  PenetrationSum pen;
  for (int k = 0; k < im.d->ncon; ++k) {
    const mjContact& con = im.d->contact[k];
    if (con.exclude != 0 && con.exclude != 1) continue;
    ++rows;
    if (con.dist < 0.0) pen.add(-con.dist, im.slop);
  }
  fm.contacts = rows;
  pen.finish(fm);
  EnergySum energy;
  for (std::size_t i = 0; i < n; ++i) {
    if (im.qpos_adr[i] < 0) continue;
    const mjtNum* qv = im.d->qvel + im.dof_adr[i];
    // MuJoCo's free joint keeps the angular velocity in the body frame (qv[3..5]).
    energy.add_linear(1.0 / static_cast<double>(im.w[i]), qv, qv[0] * qv[0] + qv[1] * qv[1] + qv[2] * qv[2]);
    for (int k = 0; k < 3; ++k)
      energy.ke += 0.5 * im.diag_inertia[i][static_cast<std::size_t>(k)] * qv[3 + k] * qv[3 + k];
  }
  energy.finish(fm);
  fm.stage_ms[static_cast<int>(Stage::Midphase)] = detect_ms;
  fm.stage_ms[static_cast<int>(Stage::Response)] = solve_ms;
  fm.stage_ms[static_cast<int>(Stage::Integrate)] = integrate_ms;
  fm.stage_ms[static_cast<int>(Stage::Metrics)] = ms_since(t1);
  return im.finish_step(fm, t0);
}

const std::string& MujocoWorld::xml() const { return impl().xml; }
std::string MujocoWorld::mujoco_version() { return mj_versionString(); }

bool MujocoWorld::has_stage(Stage s) const {
  return s == Stage::Integrate || s == Stage::Midphase || s == Stage::Response || s == Stage::Metrics;
}

std::string MujocoWorld::notes() const {
  return fmt::format(
      "MuJoCo {}: {}; soft contacts (solref timeconst {} s, dampratio from e), {} cone, {} solver, semi-implicit\n"
      "Euler. broadphase candidates are not exposed (0); AABB and dynamic pairs are the exact boxes\n"
      "at the pre-step pose that overlap. midphase = mj_fwdPosition (kinematics, MuJoCo's broadphase\n"
      "and narrow phase, constraint set-up), response = bias forces and the constraint solver,\n"
      "integrate = mj_Euler; aabbs and broadphase are not timed apart. contacts = MuJoCo's contact\n"
      "rows; kinetic energy includes rotation.",
      mujoco_version(), impl().geometry,
      num(impl().timeconst),
      mujoco_cone_name(impl().settings.cone), impl().solver);
}

}  // namespace octocd
