// octocd::OdeWorld: the scene in ODE's dWorld (see ode_world.hpp for every setting and why).
#include "octocd/ode_world.hpp"
#include "octocd/adapter_rows.hpp"

#include <fmt/format.h>
#include <ode/ode.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdarg>
#include <cstdint>
#include <cstdio>
#include <limits>
#include <mutex>
#include <utility>

#include "octocd/convex_hull.hpp"
#include "octocd/error.hpp"
#include "octocd/text.hpp"
#include "octocd/version.hpp"

#if !defined(dDOUBLE)
#error "octocd's ODE adapter needs ODE's double-precision build (dDOUBLE)"
#endif

namespace octocd {

namespace {

Vec3 to_vec3(const dReal* v) { return {static_cast<float>(v[0]), static_cast<float>(v[1]), static_cast<float>(v[2])}; }

/// A double bound rounded to the float at or beyond it (down for a minimum, up for a maximum).
float float_below(double d) {
  float f = static_cast<float>(d);
  if (static_cast<double>(f) > d) f = std::nextafter(f, -std::numeric_limits<float>::infinity());
  return f;
}
float float_above(double d) {
  float f = static_cast<float>(d);
  if (static_cast<double>(f) < d) f = std::nextafter(f, std::numeric_limits<float>::infinity());
  return f;
}

/// ODE's warnings (dMessage: "Polygon 3 is not defined counterclockwise", ...) on stderr as
/// octocd shows text (control characters escaped, docs/robustness.md "Sinks"), the first 5
/// of a process, then one line saying the rest are not shown: never ODE's raw printf.
void ode_message(int num, const char* msg, va_list ap) {
  static std::atomic<int> shown{0};
  char text[512];
  std::vsnprintf(text, sizeof text, msg, ap);
  const int k = shown++;
  if (k < 5) std::fprintf(stderr, "octocd: ode: warning %d: %s\n", num, printable(text).c_str());
  if (k == 5) std::fprintf(stderr, "octocd: ode: more warnings, not shown\n");
}

/// ODE's library-wide set-up, once per process (dInitODE2; never closed: other worlds
/// may live until exit), and its per-thread collision data for the calling thread.
void init_ode_for_this_thread() {
  static std::once_flag once;
  std::call_once(once, [] {
    dInitODE2(0);
    dSetMessageHandler(ode_message);
  });
  dAllocateODEDataForThread(dAllocateMaskAll);
}

/// Category bits: static geoms collide only with dynamic ones (no static-static pairs).
constexpr unsigned long kDynamicCategory = 1, kStaticCategory = 2;

}  // namespace

struct OdeWorld::Impl : SettingsCore<OdeSettings> {
  /// One octocd shape as ODE takes it: a box's sides, or a hull's planes, points and
  /// polygons (dCreateConvex keeps pointers to them), or a triangle mesh's data.
  struct ShapeData {
    bool box = true;
    dReal sides[3] = {0, 0, 0};                     ///< box: full side lengths (m)
    ConvexHull hull;                                 ///< mesh: its convex hull (shape frame)
    std::vector<dReal> planes, points;               ///< dCreateConvex's arrays
    std::vector<unsigned int> polygons;              ///< count, then indices, per face
    HullMassProperties mass;                         ///< mesh: the hull's, density 1
    std::vector<float> tri_vertices;                 ///< static mesh: vertices (shape frame)
    std::vector<dTriIndex> tri_indices;              ///< static mesh: triangles
    dTriMeshDataID tri = nullptr;                    ///< static mesh: ODE's data (built once)
  };

  /// One contact of the near callback, before its joint exists.
  struct Row {
    std::uint32_t i1 = 0, i2 = 0;  ///< bodies of geom 1 and geom 2
    dContactGeom geom{};
  };

  float mu = 0.0f, restitution = 0.0f, restitution_threshold = 0.0f;
  dWorldID world = nullptr;
  dSpaceID space = nullptr;
  OdeSpace space_used = OdeSpace::Hash;  ///< settings.space resolved for the scene's body count
  dJointGroupID joints = nullptr;
  std::vector<ShapeData> shapes;
  std::vector<dBodyID> bodies;  // index = body id; nullptr for a static body
  std::vector<dGeomID> geoms;   // index = body id

  // Per step: the callback's pairs and contact rows, the joints' feedback.
  std::vector<Pair> pairs;
  std::vector<Row> rows;
  std::vector<dContactGeom> buffer;
  std::vector<dJointFeedback> feedback;
  double narrow_ms = 0.0;

  ~Impl() override {
    if (joints) dJointGroupDestroy(joints);
    for (dGeomID g : geoms)
      if (g) dGeomDestroy(g);
    if (space) dSpaceDestroy(space);
    if (world) dWorldDestroy(world);  // its bodies with it
    for (ShapeData& s : shapes)
      if (s.tri) dGeomTriMeshDataDestroy(s.tri);
  }

  static std::uint32_t index_of(dGeomID g) {
    return static_cast<std::uint32_t>(reinterpret_cast<std::uintptr_t>(dGeomGetData(g)));
  }

  static void near_callback(void* data, dGeomID o1, dGeomID o2) {
    Impl& m = *static_cast<Impl*>(data);
    const std::uint32_t i1 = index_of(o1), i2 = index_of(o2);
    m.pairs.push_back(i1 < i2 ? Pair{i1, i2} : Pair{i2, i1});
    const auto t0 = std::chrono::steady_clock::now();
    const int n = dCollide(o1, o2, m.settings.max_contacts, m.buffer.data(), static_cast<int>(sizeof(dContactGeom)));
    m.narrow_ms += ms_since(t0);
    for (int k = 0; k < n; ++k) m.rows.push_back({i1, i2, m.buffer[static_cast<std::size_t>(k)]});
  }

  void read_state() {
    for (std::size_t i = 0; i < bodies.size(); ++i) {
      const dBodyID b = bodies[i];
      if (!b) continue;
      state.x[i] = to_vec3(dBodyGetPosition(b));
      state.v[i] = to_vec3(dBodyGetLinearVel(b));
      const dReal* q = dBodyGetQuaternion(b);  // (w, x, y, z), as octocd's Quat
      state.q[i] = {static_cast<float>(q[0]), static_cast<float>(q[1]), static_cast<float>(q[2]), static_cast<float>(q[3])};
      state.omega[i] = to_vec3(dBodyGetAngularVel(b));
    }
  }

  void fill_record();
};

void OdeWorld::Impl::fill_record() {
  FrameRecord& r = record;
  fill_engine_aabbs(r, geoms.size(), [&](std::size_t i) {
    dReal b[6];
    dGeomGetAABB(geoms[i], b);  // (minx, maxx, miny, maxy, minz, maxz) at the detection pose
    return Aabb{{float_below(b[0]), float_below(b[2]), float_below(b[4])},
                {float_above(b[1]), float_above(b[3]), float_above(b[5])}};
  });
  r.pairs = pairs;
  sort_unique_pairs(r.pairs);
  r.has_pairs = true;

  std::vector<ContactRecord> unsorted;
  std::vector<Vec3> jt3;
  for (std::size_t k = 0; k < rows.size(); ++k) {
    const Row& row = rows[k];
    const dJointFeedback& fb = feedback[k];
    // The joint's node 0 is geom 1's body, or geom 2's when geom 1 is static (ODE then
    // reverses the attachment); fb.f1 is the force on node 0. Impulse on geom 1's body:
    const double s1 = bodies[row.i1] != nullptr ? 1.0 : -1.0;
    const double j1[3] = {s1 * fb.f1[0] * dt, s1 * fb.f1[1] * dt, s1 * fb.f1[2] * dt};
    // dContactGeom's normal points from geom 2 into geom 1.
    const double n21[3] = {row.geom.normal[0], row.geom.normal[1], row.geom.normal[2]};
    unsorted.push_back(manifold_row(row.i1, row.i2, n21, j1, row.geom.depth, to_vec3(row.geom.pos), jt3));
  }
  finish_manifold_record(r, unsorted, jt3);
}

OdeWorld::OdeWorld(std::shared_ptr<const Model> model, const BodyState& initial, const OdeSettings& settings)
    : SettingsWorld(std::make_unique<Impl>(), std::move(model), initial, "ode", settings) {
  init_ode_for_this_thread();
  Impl& m = impl();
  const Model& src = *m.model;
  const Scene& scene = src.scene;
  m.mu = scene.response.mu_kinetic;
  m.restitution = scene.response.restitution;
  m.restitution_threshold = scene.response.restitution_threshold;
  m.buffer.resize(static_cast<std::size_t>(settings.max_contacts));

  m.world = dWorldCreate();
  dWorldSetGravity(m.world, scene.gravity.x, scene.gravity.y, scene.gravity.z);
  dWorldSetERP(m.world, settings.erp);
  dWorldSetCFM(m.world, settings.cfm);
  dWorldSetQuickStepNumIterations(m.world, settings.iterations);
  dWorldSetAutoDisableFlag(m.world, 0);
  m.joints = dJointGroupCreate(0);

  const std::size_t n = initial.size();
  m.space_used = ode_resolved_space(settings.space, n);
  if (m.space_used == OdeSpace::Sap) {
    m.space = dSweepAndPruneSpaceCreate(nullptr, dSAP_AXES_XYZ);
  } else if (m.space_used == OdeSpace::QuadTree) {
    const Vec3 c = 0.5f * (scene.domain.min + scene.domain.max), e = 0.5f * (scene.domain.max - scene.domain.min);
    const dVector3 centre = {c.x, c.y, c.z, 0}, extents = {e.x, e.y, e.z, 0};
    m.space = dQuadTreeSpaceCreate(nullptr, centre, extents, ode_quadtree_depth(n));
  } else {
    m.space = dHashSpaceCreate(nullptr);
  }

  // Which shapes a static body uses as a triangle mesh, and which as a hull or box.
  std::vector<char> static_mesh(src.shapes.size(), 0), dynamic_use(src.shapes.size(), 0);
  for (std::size_t i = 0; i < n; ++i) {
    const std::uint32_t s = src.bodies[i].shape;
    const bool is_static = !(initial.w[i] > 0.0f);
    if (is_static && src.shapes[s].mesh) static_mesh[s] = 1;
    if (!is_static) dynamic_use[s] = 1;
  }
  m.shapes.resize(src.shapes.size());
  for (std::size_t k = 0; k < src.shapes.size(); ++k) {
    const Shape& s = src.shapes[k];
    Impl::ShapeData& d = m.shapes[k];
    const Vec3 centre = 0.5f * (s.local.min + s.local.max);  // the body origin in the shape frame
    const Vec3 side = s.local.max - s.local.min;
    for (int a = 0; a < 3; ++a) d.sides[a] = side[a];
    if (!s.mesh) continue;
    d.box = false;
    if (dynamic_use[k]) {
      std::vector<Vec3> pts(s.mesh->vertices);
      for (Vec3& p : pts) p -= centre;
      d.hull = convex_hull(pts, s.name);
      // ODE's dGeomConvex takes the body origin (the local AABB's centre) as inside the hull:
      // one outside (a corner tetrahedron) made ODE abort ("ODE INTERNAL ERROR 1: assertion
      // !bSafeNormalize4Fault"). Refused instead, naming the shape.
      for (std::size_t f = 0; f < d.hull.planes.size(); ++f)
        if (!(d.hull.planes[f][3] > 1e-9))
          throw InputError(fmt::format(
              "{}: engine ode needs the centre of the mesh's bounding box inside its convex hull (ODE's convex "
              "geometry takes it as the body's origin), but the hull's face {} passes {:g} m from it on its outer "
              "side; allowed: a mesh whose bounding-box centre lies inside its hull (not, e.g., a corner "
              "tetrahedron), or another engine",
              s.name, f, -d.hull.planes[f][3]));
      d.mass = hull_mass_properties(d.hull);
      for (const auto& v : d.hull.vertices) d.points.insert(d.points.end(), v.begin(), v.end());
      for (std::size_t f = 0; f < d.hull.faces.size(); ++f) {
        d.planes.insert(d.planes.end(), d.hull.planes[f].begin(), d.hull.planes[f].end());
        d.polygons.push_back(static_cast<unsigned int>(d.hull.faces[f].size()));
        d.polygons.insert(d.polygons.end(), d.hull.faces[f].begin(), d.hull.faces[f].end());
      }
    }
    if (static_mesh[k]) {
      for (const Vec3& p : s.mesh->vertices) {
        const Vec3 q = p - centre;
        d.tri_vertices.insert(d.tri_vertices.end(), {q.x, q.y, q.z});
      }
      for (const auto& t : s.mesh->triangles) d.tri_indices.insert(d.tri_indices.end(), {t[0], t[1], t[2]});
      d.tri = dGeomTriMeshDataCreate();
      dGeomTriMeshDataBuildSingle(d.tri, d.tri_vertices.data(), static_cast<int>(3 * sizeof(float)),
                                  static_cast<int>(s.mesh->vertices.size()), d.tri_indices.data(),
                                  static_cast<int>(d.tri_indices.size()), static_cast<int>(3 * sizeof(dTriIndex)));
      // ODE's convex-trimesh collider needs the face angles: without them a hull (a
      // dynamic mesh) touching a static mesh aborts the process (ODE INTERNAL ERROR 2).
      if (!dGeomTriMeshDataPreprocess2(d.tri, (1U << dTRIDATAPREPROCESS_BUILD_CONCAVE_EDGES) |
                                                  (1U << dTRIDATAPREPROCESS_BUILD_FACE_ANGLES),
                                       nullptr))
        throw RuntimeError(fmt::format("ode: preprocessing static mesh {} for its colliders failed", s.name));
    }
  }

  bool has_box = false, has_hull = false, has_trimesh = false;
  m.bodies.assign(n, nullptr);
  m.geoms.assign(n, nullptr);
  m.inertia.assign(n, {});
  for (std::size_t i = 0; i < n; ++i) {
    const Impl::ShapeData& d = m.shapes[src.bodies[i].shape];
    const bool is_static = !(initial.w[i] > 0.0f);
    dGeomID g = nullptr;
    std::string declared;
    if (d.box) {
      g = dCreateBox(m.space, d.sides[0], d.sides[1], d.sides[2]);
      declared = "box";
      has_box = true;
    } else if (is_static) {
      g = dCreateTriMesh(m.space, d.tri, nullptr, nullptr, nullptr);
      declared = "mesh";
      has_trimesh = true;
    } else {
      g = dCreateConvex(m.space, d.planes.data(), static_cast<unsigned int>(d.hull.planes.size()), d.points.data(),
                        static_cast<unsigned int>(d.hull.vertices.size()), d.polygons.data());
      declared = "convex_hull";
      has_hull = true;
    }
    m.geoms[i] = g;
    dGeomSetData(g, reinterpret_cast<void*>(static_cast<std::uintptr_t>(i)));
    const Quat q = normalized(m.state.q[i]);
    const dQuaternion dq = {q.w, q.x, q.y, q.z};
    const Vec3 x = m.state.x[i];
    m.traits.body_collision_shape.push_back(declared);
    m.traits.body_friction.push_back(m.mu);
    m.traits.body_restitution.push_back(m.restitution);
    if (is_static) {
      dGeomSetCategoryBits(g, kStaticCategory);
      dGeomSetCollideBits(g, kDynamicCategory);
      dGeomSetPosition(g, x.x, x.y, x.z);
      dGeomSetQuaternion(g, dq);
      m.traits.inertia.push_back({});
      continue;
    }
    dGeomSetCategoryBits(g, kDynamicCategory);
    dGeomSetCollideBits(g, kDynamicCategory | kStaticCategory);
    const double mass = 1.0 / static_cast<double>(initial.w[i]);
    dMass dm;
    std::array<double, 9> tensor{};
    if (d.box) {
      dMassSetBoxTotal(&dm, mass, d.sides[0], d.sides[1], d.sides[2]);
    } else {
      const double density = mass / d.mass.volume;
      const auto& I = d.mass.inertia_origin;
      dMassSetParameters(&dm, mass, 0, 0, 0, density * I[0], density * I[4], density * I[8], density * I[1],
                         density * I[2], density * I[5]);
    }
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c) tensor[static_cast<std::size_t>(3 * r + c)] = dm.I[4 * r + c];
    if (!dMassCheck(&dm))
      throw RuntimeError(fmt::format("body {} ({}): ODE refuses its mass properties (dMassCheck): mass {} kg, inertia "
                                     "diagonal ({}, {}, {}) kg m^2",
                                     i, src.shapes[src.bodies[i].shape].name, mass, tensor[0], tensor[4], tensor[8]));
    m.inertia[i] = tensor;
    std::array<float, 9> tf{};
    for (std::size_t k = 0; k < 9; ++k) tf[k] = static_cast<float>(tensor[k]);
    m.traits.inertia.push_back(tf);
    dBodyID b = dBodyCreate(m.world);
    dBodySetMass(b, &dm);
    dBodySetPosition(b, x.x, x.y, x.z);
    dBodySetQuaternion(b, dq);
    dBodySetLinearVel(b, m.state.v[i].x, m.state.v[i].y, m.state.v[i].z);
    dBodySetAngularVel(b, m.state.omega[i].x, m.state.omega[i].y, m.state.omega[i].z);
    dBodySetAutoDisableFlag(b, 0);
    dBodySetGyroscopicMode(b, settings.gyroscopic ? 1 : 0);
    dGeomSetBody(g, b);
    m.bodies[i] = b;
  }
  m.read_state();  // the state as ODE holds it (normalised quaternions)

  m.geometry = "ode";
  if (has_box) m.geometry += " boxes (dBox),";
  if (has_hull) m.geometry += " convex hulls (dynamic meshes, dConvex),";
  if (has_trimesh) m.geometry += " triangle meshes (static meshes, dTriMesh),";
  if (m.geometry.back() == ',') m.geometry.pop_back();

  RotationTraits& t = m.traits;
  t.mu = m.mu;
  t.restitution = m.restitution;
  t.friction_combine = "min";
  t.restitution_combine = "min";
  t.contact_margin = 1e-4f;
  t.contact_model = "rigid";
  t.gyroscopic = settings.gyroscopic ? "true" : "false";
  t.deactivation = "off";  // dWorldSetAutoDisableFlag(world, 0) and per body: no body is ever disabled
  t.normal_reuse_deg = 0.0;  // every step collides anew (dSpaceCollide, its joint group emptied)
}

OdeWorld::~OdeWorld() = default;

OdeWorld::Impl& OdeWorld::impl() const { return static_cast<Impl&>(core()); }

const FrameMetrics& OdeWorld::step() {
  init_ode_for_this_thread();
  Impl& m = impl();
  if (m.recording) m.save_pre_state();
  const auto t0 = std::chrono::steady_clock::now();
  m.pairs.clear();
  m.rows.clear();
  m.narrow_ms = 0.0;
  dSpaceCollide(m.space, &m, &Impl::near_callback);
  const double collide_ms = ms_since(t0);

  const auto t1 = std::chrono::steady_clock::now();
  m.feedback.assign(m.rows.size(), dJointFeedback{});
  const dReal mu_dir = m.settings.friction == OdeFriction::Inscribed ? m.mu / std::sqrt(2.0) : m.mu;
  for (std::size_t k = 0; k < m.rows.size(); ++k) {
    const Impl::Row& row = m.rows[k];
    dContact c{};
    c.geom = row.geom;
    c.surface.mode = dContactApprox1;
    c.surface.mu = mu_dir;
    if (m.restitution > 0.0f) {
      c.surface.mode |= dContactBounce;
      c.surface.bounce = m.restitution;
      c.surface.bounce_vel = m.restitution_threshold;
    }
    dJointID j = dJointCreateContact(m.world, m.joints, &c);
    dJointAttach(j, m.bodies[row.i1], m.bodies[row.i2]);
    dJointSetFeedback(j, &m.feedback[k]);
  }
  const int ok = m.settings.stepper == OdeStepper::QuickStep ? dWorldQuickStep(m.world, m.dt) : dWorldStep(m.world, m.dt);
  const double response_ms = ms_since(t1);
  if (!ok) throw RuntimeError(fmt::format("frame {}: ODE's step failed (out of memory in its work area)", m.frame + 1));

  const auto t2 = std::chrono::steady_clock::now();
  FrameMetrics fm = m.next_frame();
  m.read_state();
  m.check_finite("ODE's");
  if (m.recording) {
    m.save_post_state();  // ODE collides before it steps
    m.fill_record();
  }
  std::vector<Pair> unique_pairs = m.pairs;
  fm.cell_candidates = unique_pairs.size();
  fm.dynamic_pairs = unique_pairs.size();
  fm.aabb_pairs = unique_pairs.size() + m.static_static;
  fm.contacts = m.rows.size();
  PenetrationSum pen;
  for (const Impl::Row& row : m.rows) pen.add(std::max<dReal>(0, row.geom.depth), m.slop);
  pen.finish(fm);
  EnergySum energy;
  for (std::size_t i = 0; i < m.bodies.size(); ++i) {
    const dBodyID b = m.bodies[i];
    if (!b) continue;
    const dReal* v = dBodyGetLinearVel(b);
    energy.add_linear(1.0 / static_cast<double>(m.w[i]), v, v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
    // w_l = R^T w in the body frame (dBodyGetRotation: 3x4, row-major).
    const dReal* R = dBodyGetRotation(b);
    const dReal* wv = dBodyGetAngularVel(b);
    double wl[3];
    for (int k = 0; k < 3; ++k) wl[k] = R[0 * 4 + k] * wv[0] + R[1 * 4 + k] * wv[1] + R[2 * 4 + k] * wv[2];
    energy.add_rotational(wl, m.inertia[i]);
  }
  energy.finish(fm);
  dJointGroupEmpty(m.joints);
  fm.stage_ms[static_cast<int>(Stage::Broadphase)] = std::max(0.0, collide_ms - m.narrow_ms);
  fm.stage_ms[static_cast<int>(Stage::Midphase)] = m.narrow_ms;
  fm.stage_ms[static_cast<int>(Stage::Response)] = response_ms;
  fm.stage_ms[static_cast<int>(Stage::Metrics)] = ms_since(t2);
  return m.finish_step(fm, t0);
}

std::string OdeWorld::broadphase_name() const {
  switch (impl().space_used) {
    case OdeSpace::Sap: return "ode-sap";
    case OdeSpace::QuadTree: return "ode-quadtree";
    default: return "ode-hash";
  }
}

bool OdeWorld::has_stage(Stage s) const { return s != Stage::Aabbs && s != Stage::Integrate; }

std::string OdeWorld::notes() const {
  const OdeSettings& s = impl().settings;
  return fmt::format(
      "{}; {} (erp {}, cfm {}{}), friction {} (dContactApprox1), up to {} contacts per pair,\n"
      "gyroscopic term {}. broadphase candidates = AABB pairs = dynamic pairs = the pairs {} hands the\n"
      "near callback (ODE's own AABBs at the pre-step pose: a hull's are tighter than its posed local box;\n"
      "no static-static pairs); midphase = ODE's dCollide (dBoxBox, libccd MPR for hulls: one point per\n"
      "pair, trimesh colliders); response = contact joints + the ODE step, which also integrates (aabbs and\n"
      "integrate n/a). contacts = contact rows, penetration over their depths; kinetic energy includes rotation.",
      impl().geometry, s.stepper == OdeStepper::QuickStep ? "dWorldQuickStep" : "dWorldStep", s.erp, s.cfm,
      s.stepper == OdeStepper::QuickStep ? fmt::format(", {} iterations", s.iterations) : std::string(),
      ode_friction_name(s.friction), s.max_contacts, s.gyroscopic ? "on" : "off",
      impl().space_used == OdeSpace::Sap        ? "dSweepAndPruneSpace"
      : impl().space_used == OdeSpace::QuadTree ? "dQuadTreeSpace"
                                                : "dHashSpace");
}

}  // namespace octocd
