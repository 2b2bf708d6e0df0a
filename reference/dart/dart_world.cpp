// octocd::DartWorld: the scene in DART's World (see dart_world.hpp for every setting and why).
#include "octocd/dart_world.hpp"
#include "octocd/adapter_rows.hpp"

#include <assimp/scene.h>
#include <dart/collision/CollisionObject.hpp>
#include <dart/collision/CollisionResult.hpp>
#include <dart/collision/dart/DARTCollisionDetector.hpp>
#include <dart/collision/fcl/FCLCollisionDetector.hpp>
#include <dart/collision/fcl/FCLCollisionObject.hpp>
#include <dart/collision/fcl/FCLTypes.hpp>
#include <dart/config.hpp>
#include <dart/constraint/BoxedLcpConstraintSolver.hpp>
#include <dart/constraint/ContactConstraint.hpp>
#include <dart/constraint/DantzigBoxedLcpSolver.hpp>
#include <dart/constraint/PgsBoxedLcpSolver.hpp>
#include <dart/dynamics/BodyNode.hpp>
#include <dart/dynamics/BoxShape.hpp>
#include <dart/dynamics/FreeJoint.hpp>
#include <dart/dynamics/MeshShape.hpp>
#include <dart/dynamics/ShapeNode.hpp>
#include <dart/dynamics/Skeleton.hpp>
#include <dart/dynamics/WeldJoint.hpp>
#include <dart/simulation/World.hpp>
#include <fmt/format.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <iostream>
#include <unordered_map>
#include <utility>

#include "octocd/convex_hull.hpp"
#include "octocd/error.hpp"
#include "octocd/pose.hpp"
#include "octocd/version.hpp"

namespace octocd {

namespace {

using dart::constraint::ContactConstraint;

Vec3 to_vec3(const Eigen::Vector3d& v) {
  return {static_cast<float>(v.x()), static_cast<float>(v.y()), static_cast<float>(v.z())};
}

/// A triangle mesh as DART's MeshShape takes it: an aiScene with one aiMesh and a root
/// node naming it, allocated with new as aiReleaseImport (which ~MeshShape calls) deletes
/// a scene that no assimp Importer owns. `vertices` in metres (shape frame), `triangles`
/// indices into them.
const aiScene* make_ai_scene(const std::vector<std::array<double, 3>>& vertices,
                             const std::vector<std::array<std::uint32_t, 3>>& triangles) {
  auto* scene = new aiScene();
  auto* mesh = new aiMesh();
  mesh->mPrimitiveTypes = aiPrimitiveType_TRIANGLE;
  mesh->mNumVertices = static_cast<unsigned>(vertices.size());
  mesh->mVertices = new aiVector3D[vertices.size()];
  for (std::size_t k = 0; k < vertices.size(); ++k)
    mesh->mVertices[k] = aiVector3D(static_cast<ai_real>(vertices[k][0]), static_cast<ai_real>(vertices[k][1]),
                                    static_cast<ai_real>(vertices[k][2]));
  mesh->mNumFaces = static_cast<unsigned>(triangles.size());
  mesh->mFaces = new aiFace[triangles.size()];
  for (std::size_t k = 0; k < triangles.size(); ++k) {
    aiFace& f = mesh->mFaces[k];
    f.mNumIndices = 3;
    f.mIndices = new unsigned[3]{triangles[k][0], triangles[k][1], triangles[k][2]};
  }
  scene->mNumMeshes = 1;
  scene->mMeshes = new aiMesh*[1]{mesh};
  scene->mNumMaterials = 1;
  scene->mMaterials = new aiMaterial*[1]{new aiMaterial()};
  scene->mRootNode = new aiNode();
  scene->mRootNode->mNumMeshes = 1;
  scene->mRootNode->mMeshes = new unsigned[1]{0};
  return scene;
}

/// A pose as DART's Isometry3d (octocd's Quat is (w, x, y, z), normalised here).
Eigen::Isometry3d isometry(Vec3 x, Quat q) {
  const Quat n = normalized(q);
  Eigen::Isometry3d t = Eigen::Isometry3d::Identity();
  t.linear() = Eigen::Quaterniond(n.w, n.x, n.y, n.z).toRotationMatrix();
  t.translation() = Eigen::Vector3d(x.x, x.y, x.z);
  return t;
}

/// DART's FCL collision detector whose collision objects start at their shape frame's world
/// pose (DartFclInsert::Posed). FCLCollisionObject makes its fcl::CollisionObject at the
/// identity and the collision group registers it in FCL's dynamic AABB tree at once, so n
/// boxes go in as n leaves with one AABB at the origin: a chain n deep, O(n^2) to build.
/// Posed here, each leaf goes in with its body's AABB. Before every collide DART poses each
/// object again and refits and rebalances the tree: the steps collide the same poses, but
/// the tree, so the order of the contacts, differs from the origin build's.
class PosedFclDetector : public dart::collision::FCLCollisionDetector {
 public:
  /// A detector owned by the returned pointer (DART's detectors are held by shared_ptr).
  static std::shared_ptr<PosedFclDetector> create() { return std::shared_ptr<PosedFclDetector>(new PosedFclDetector()); }

 protected:
  std::unique_ptr<dart::collision::CollisionObject> createCollisionObject(
      const dart::dynamics::ShapeFrame* frame) override {
    std::unique_ptr<dart::collision::CollisionObject> object = FCLCollisionDetector::createCollisionObject(frame);
    auto* fcl_object = static_cast<dart::collision::FCLCollisionObject*>(object.get())->getFCLCollisionObject();
    fcl_object->setTransform(dart::collision::FCLTypes::convertTransform(frame->getWorldTransform()));
    fcl_object->computeAABB();
    return object;
  }

 private:
  PosedFclDetector() = default;
};

/// DART's process-wide contact constraint parameters (ContactConstraint statics), set to a
/// world's values for the lifetime of the object and put back after.
class ContactParameters {
 public:
  explicit ContactParameters(const DartSettings& s)
      : erp_(ContactConstraint::getErrorReductionParameter()),
        erv_(ContactConstraint::getMaxErrorReductionVelocity()),
        cfm_(ContactConstraint::getConstraintForceMixing()) {
    set(s.erp, s.max_erv, s.cfm);
  }
  ~ContactParameters() { set(erp_, erv_, cfm_); }
  ContactParameters(const ContactParameters&) = delete;
  ContactParameters& operator=(const ContactParameters&) = delete;

 private:
  static void set(double erp, double erv, double cfm) {
    ContactConstraint::setErrorReductionParameter(erp);
    ContactConstraint::setMaxErrorReductionVelocity(erv);
    ContactConstraint::setConstraintForceMixing(cfm);
  }
  double erp_, erv_, cfm_;
};

}  // namespace

struct DartWorld::Impl : SettingsCore<DartSettings> {
  dart::simulation::WorldPtr world;
  std::vector<dart::dynamics::BodyNode*> nodes;  // index = body id; static ones too
  std::unordered_map<const dart::dynamics::ShapeFrame*, std::uint32_t> body_of;

  void read_state() {
    for (std::size_t i = 0; i < nodes.size(); ++i) {
      if (!dynamic(i)) continue;
      const dart::dynamics::BodyNode* b = nodes[i];
      const Eigen::Isometry3d& t = b->getWorldTransform();
      state.x[i] = to_vec3(t.translation());
      const Eigen::Quaterniond q(t.linear());
      state.q[i] = {static_cast<float>(q.w()), static_cast<float>(q.x()), static_cast<float>(q.y()),
                    static_cast<float>(q.z())};
      state.v[i] = to_vec3(b->getLinearVelocity());
      state.omega[i] = to_vec3(b->getAngularVelocity());
    }
  }

  std::uint32_t index_of(const dart::collision::CollisionObject* o) const {
    return body_of.at(o->getShapeFrame());
  }

  void fill_record();
};

void DartWorld::Impl::fill_record() {
  FrameRecord& r = record;
  const dart::collision::CollisionResult& result = world->getLastCollisionResult();
  std::vector<ContactRecord> rows;
  std::vector<Vec3> jt3;
  rows.reserve(result.getNumContacts());
  jt3.reserve(result.getNumContacts());
  for (std::size_t k = 0; k < result.getNumContacts(); ++k) {
    const dart::collision::Contact& ct = result.getContact(k);
    const std::uint32_t i1 = index_of(ct.collisionObject1), i2 = index_of(ct.collisionObject2);
    if (!dynamic(i1) && !dynamic(i2)) continue;  // not a constraint (no static-static pair is collided)
    // Contact::normal points from object 2's body to object 1's; Contact::force acts on
    // object 1's body.
    const double n21[3] = {ct.normal.x(), ct.normal.y(), ct.normal.z()};
    const double j1[3] = {dt * ct.force.x(), dt * ct.force.y(), dt * ct.force.z()};
    rows.push_back(manifold_row(i1, i2, n21, j1, ct.penetrationDepth, to_vec3(ct.point), jt3));
  }
  finish_manifold_record(r, rows, jt3);
}

DartWorld::DartWorld(std::shared_ptr<const Model> model, const BodyState& initial, const DartSettings& settings)
    : SettingsWorld(std::make_unique<Impl>(), std::move(model), initial, "dart", settings) {
  using namespace dart::dynamics;
  Impl& m = impl();
  const Model& src = *m.model;
  const Scene& scene = src.scene;
  const std::size_t n = initial.size();

  const bool fcl = settings.collision == DartCollision::Fcl;
  if (!fcl)
    for (std::size_t i = 0; i < n; ++i)
      if (src.shapes[src.bodies[i].shape].mesh)
        throw InputError(fmt::format(
            "--dart collision=dart: body {} ({}) is a mesh, and DART's own collision detector has no mesh shape; "
            "allowed: collision=fcl for scenes with meshes",
            i, src.shapes[src.bodies[i].shape].name));

  m.world = dart::simulation::World::create("octocd");
  m.world->setGravity(Eigen::Vector3d(scene.gravity.x, scene.gravity.y, scene.gravity.z));
  m.world->setTimeStep(scene.dt);
  {
    using namespace dart::constraint;
    auto pgs = std::make_shared<PgsBoxedLcpSolver>();
    PgsBoxedLcpSolver::Option opt = pgs->getOption();
    opt.mMaxIteration = settings.iterations;
    pgs->setOption(opt);
    std::unique_ptr<BoxedLcpConstraintSolver> solver;
    if (settings.lcp == DartLcp::Dantzig)
      solver = std::make_unique<BoxedLcpConstraintSolver>(std::make_shared<DantzigBoxedLcpSolver>(), pgs);
    else
      solver = std::make_unique<BoxedLcpConstraintSolver>(pgs, nullptr);
    m.world->setConstraintSolver(std::move(solver));
  }
  auto* cs = m.world->getConstraintSolver();
  if (fcl) {
    std::shared_ptr<dart::collision::FCLCollisionDetector> detector;
    if (settings.insert == DartFclInsert::Posed)
      detector = PosedFclDetector::create();
    else
      detector = dart::collision::FCLCollisionDetector::create();
    {
      // DART warns on std::cerr about FCL 0.4's incomplete primitive support whenever
      // PRIMITIVE is set; the warning is kept off the run's output (docs/engines.md, "dart",
      // says what FCL's primitives do here).
      std::streambuf* err = std::cerr.rdbuf(nullptr);
      detector->setPrimitiveShapeType(settings.boxes == DartFclBoxes::Primitive
                                          ? dart::collision::FCLCollisionDetector::PRIMITIVE
                                          : dart::collision::FCLCollisionDetector::MESH);
      std::cerr.rdbuf(err);
    }
    cs->setCollisionDetector(detector);
  } else {
    cs->setCollisionDetector(dart::collision::DARTCollisionDetector::create());
  }
  cs->getCollisionOption().maxNumContacts = static_cast<std::size_t>(settings.max_contacts);

  // One DART shape per octocd shape and use: box, hull (dynamic mesh), triangle mesh (static mesh).
  std::vector<char> static_mesh(src.shapes.size(), 0), dynamic_mesh(src.shapes.size(), 0);
  for (std::size_t i = 0; i < n; ++i) {
    const std::uint32_t s = src.bodies[i].shape;
    if (!src.shapes[s].mesh) continue;
    (initial.w[i] > 0.0f ? dynamic_mesh : static_mesh)[s] = 1;
  }
  std::vector<ShapePtr> box(src.shapes.size()), hull(src.shapes.size()), trimesh(src.shapes.size());
  std::vector<HullMassProperties> hull_mass(src.shapes.size());
  for (std::size_t k = 0; k < src.shapes.size(); ++k) {
    const Shape& s = src.shapes[k];
    const Vec3 centre = 0.5f * (s.local.min + s.local.max);  // the body origin in the shape frame
    const Vec3 side = s.local.max - s.local.min;
    if (!s.mesh) {
      box[k] = std::make_shared<BoxShape>(Eigen::Vector3d(side.x, side.y, side.z));
      continue;
    }
    if (dynamic_mesh[k]) {
      std::vector<Vec3> pts(s.mesh->vertices);
      for (Vec3& p : pts) p -= centre;
      const ConvexHull h = convex_hull(pts, s.name);
      hull_mass[k] = hull_mass_properties(h);
      std::vector<std::array<std::uint32_t, 3>> tris;
      for (const auto& f : h.faces)
        for (std::size_t c = 1; c + 1 < f.size(); ++c) tris.push_back({f[0], f[c], f[c + 1]});
      hull[k] = std::make_shared<MeshShape>(Eigen::Vector3d::Ones(), make_ai_scene(h.vertices, tris));
    }
    if (static_mesh[k]) {
      std::vector<std::array<double, 3>> verts;
      verts.reserve(s.mesh->vertices.size());
      for (const Vec3& p : s.mesh->vertices) {
        const Vec3 q = p - centre;
        verts.push_back({q.x, q.y, q.z});
      }
      std::vector<std::array<std::uint32_t, 3>> tris;
      for (const auto& t : s.mesh->triangles) tris.push_back({t[0], t[1], t[2]});
      trimesh[k] = std::make_shared<MeshShape>(Eigen::Vector3d::Ones(), make_ai_scene(verts, tris));
    }
  }

  const double mu = scene.response.mu_kinetic;
  const double e = scene.response.restitution;
  const double mu_shape = settings.friction == DartFriction::Inscribed ? mu / std::sqrt(2.0) : mu;
  const double e_shape = std::sqrt(std::max(0.0, e));
  auto attach = [&](BodyNode* b, const ShapePtr& shape, std::size_t i) {
    ShapeNode* sn = b->createShapeNodeWith<CollisionAspect, DynamicsAspect>(shape);
    sn->getDynamicsAspect()->setFrictionCoeff(mu_shape);
    sn->getDynamicsAspect()->setRestitutionCoeff(e_shape);
    m.body_of[sn] = static_cast<std::uint32_t>(i);
  };

  bool has_box = false, has_hull = false, has_trimesh = false;
  m.nodes.assign(n, nullptr);
  m.inertia.assign(n, {});
  SkeletonPtr statics = Skeleton::create("static");
  statics->setMobile(false);
  statics->setSelfCollisionCheck(false);
  for (std::size_t i = 0; i < n; ++i) {
    const std::uint32_t s = src.bodies[i].shape;
    const Shape& shape = src.shapes[s];
    const bool is_static = !(initial.w[i] > 0.0f);
    const Eigen::Isometry3d pose = isometry(m.state.x[i], m.state.q[i]);
    ShapePtr geom;
    std::string declared;
    if (!shape.mesh) {
      geom = box[s];
      declared = "box";
      has_box = true;
    } else if (is_static) {
      geom = trimesh[s];
      declared = "mesh";
      has_trimesh = true;
    } else {
      geom = hull[s];
      declared = "convex_hull";
      has_hull = true;
    }
    m.traits.body_collision_shape.push_back(declared);
    m.traits.body_friction.push_back(static_cast<float>(mu));
    m.traits.body_restitution.push_back(static_cast<float>(e_shape));
    const std::string name = fmt::format("b{}", i);
    if (is_static) {
      WeldJoint::Properties jp;
      jp.mName = "j" + name;
      jp.mT_ParentBodyToJoint = pose;
      BodyNode::Properties bp;
      bp.mName = name;
      auto pair = statics->createJointAndBodyNodePair<WeldJoint>(nullptr, jp, bp);
      attach(pair.second, geom, i);
      m.nodes[i] = pair.second;
      m.traits.inertia.push_back({});
      continue;
    }
    const double mass = 1.0 / static_cast<double>(initial.w[i]);
    std::array<double, 9> tensor{};
    if (!shape.mesh) {
      const Vec3 side = shape.local.max - shape.local.min;
      const double a = side.x, b = side.y, c = side.z;
      tensor[0] = mass / 12.0 * (b * b + c * c);
      tensor[4] = mass / 12.0 * (a * a + c * c);
      tensor[8] = mass / 12.0 * (a * a + b * b);
    } else {
      const double density = mass / hull_mass[s].volume;
      for (std::size_t k = 0; k < 9; ++k) tensor[k] = density * hull_mass[s].inertia_origin[k];
    }
    m.inertia[i] = tensor;
    std::array<float, 9> tf{};
    for (std::size_t k = 0; k < 9; ++k) tf[k] = static_cast<float>(tensor[k]);
    m.traits.inertia.push_back(tf);

    SkeletonPtr skel = Skeleton::create(name);
    FreeJoint::Properties jp;
    jp.mName = "j" + name;
    BodyNode::Properties bp;
    bp.mName = name;
    auto pair = skel->createJointAndBodyNodePair<FreeJoint>(nullptr, jp, bp);
    BodyNode* body = pair.second;
    body->setInertia(Inertia(mass, Eigen::Vector3d::Zero(),
                             (Eigen::Matrix3d() << tensor[0], tensor[1], tensor[2], tensor[3], tensor[4], tensor[5],
                              tensor[6], tensor[7], tensor[8])
                                 .finished()));
    attach(body, geom, i);
    FreeJoint::setTransformOf(pair.first, pose);
    const Vec3 v = m.state.v[i], om = m.state.omega[i];
    pair.first->setLinearVelocity(Eigen::Vector3d(v.x, v.y, v.z));
    pair.first->setAngularVelocity(Eigen::Vector3d(om.x, om.y, om.z));
    m.nodes[i] = body;
    m.world->addSkeleton(skel);
  }
  if (statics->getNumBodyNodes() > 0) m.world->addSkeleton(statics);
  m.read_state();  // the state as DART holds it (double pose rounded to float)

  m.geometry = fmt::format("dart {}:", dart_collision_name(settings.collision));
  if (has_box)
    m.geometry += fcl ? fmt::format(" boxes (BoxShape, {}),", settings.boxes == DartFclBoxes::Primitive
                                                                  ? "fcl::Box"
                                                                  : "a 12-triangle mesh")
                      : " boxes (BoxShape),";
  if (has_hull) m.geometry += " convex hulls (dynamic meshes, MeshShape of the hull),";
  if (has_trimesh) m.geometry += " triangle meshes (static meshes, MeshShape),";
  if (m.geometry.back() == ',') m.geometry.pop_back();

  RotationTraits& t = m.traits;
  t.mu = static_cast<float>(mu);
  t.restitution = static_cast<float>(e);
  t.friction_combine = "min";
  t.restitution_combine = "product";
  t.contact_margin = 1e-4f;
  t.candidate_pairs = false;
  t.contact_model = "rigid";
  t.gyroscopic = "true";
  t.normal_reuse_deg = 0.0;  // every step, the constraint solver runs collision detection anew
}

DartWorld::~DartWorld() = default;

DartWorld::Impl& DartWorld::impl() const { return static_cast<Impl&>(core()); }

const FrameMetrics& DartWorld::step() {
  Impl& m = impl();
  const std::size_t n = m.w.size();
  FrameRecord& r = m.record;
  m.save_pre_state();
  const auto t0 = std::chrono::steady_clock::now();
  {
    const ContactParameters params(m.settings);
    m.world->step();
  }
  const double step_ms = ms_since(t0);

  const auto t1 = std::chrono::steady_clock::now();
  FrameMetrics fm = m.next_frame();
  m.read_state();
  m.check_finite("DART's");
  const dart::collision::CollisionResult& result = m.world->getLastCollisionResult();
  if (result.getNumContacts() >= static_cast<std::size_t>(m.settings.max_contacts))
    throw RuntimeError(fmt::format("frame {}: DART's collision detection reached its bound of {} contacts and dropped "
                                   "the rest; raise it with --dart contacts=N",
                                   m.frame, m.settings.max_contacts));
  fm.dynamic_pairs = m.posed_overlapping_pairs();
  fm.aabb_pairs = fm.dynamic_pairs + m.static_static;
  if (m.recording) {
    m.save_post_state();  // DART collides inside World::step before the positions move
    r.has_pairs = false;
    m.fill_record();
  }
  PenetrationSum pen;
  for (std::size_t k = 0; k < result.getNumContacts(); ++k)
    pen.add(std::max(0.0, result.getContact(k).penetrationDepth), m.slop);
  fm.contacts = result.getNumContacts();
  pen.finish(fm);
  EnergySum energy;
  for (std::size_t i = 0; i < n; ++i) {
    if (!m.dynamic(i)) continue;
    const dart::dynamics::BodyNode* b = m.nodes[i];
    const Eigen::Vector3d v = b->getLinearVelocity();
    energy.add_linear(1.0 / static_cast<double>(m.w[i]), v.data(), v.squaredNorm());
    // w_b = R^T w in the body frame.
    const Eigen::Vector3d wb = b->getWorldTransform().linear().transpose() * b->getAngularVelocity();
    energy.add_rotational(wb.data(), m.inertia[i]);
  }
  energy.finish(fm);
  fm.stage_ms[static_cast<int>(Stage::Response)] = step_ms;
  fm.stage_ms[static_cast<int>(Stage::Metrics)] = ms_since(t1);
  return m.finish_step(fm, t0);
}

std::string DartWorld::broadphase_name() const {
  return impl().settings.collision == DartCollision::Fcl ? "dart-fcl" : "dart-all-pairs";
}
std::string DartWorld::midphase_name() const {
  return impl().settings.collision == DartCollision::Fcl ? "dart-fcl-collide" : "dart-collide";
}
std::string DartWorld::dart_version() { return DART_VERSION; }

bool DartWorld::has_stage(Stage s) const { return s == Stage::Response || s == Stage::Metrics; }

std::string DartWorld::notes() const {
  const DartSettings& s = impl().settings;
  return fmt::format(
      "DART {}: {}; {} boxed LCP{} (erp {}, max_erv {} m/s, cfm {}), friction {} (pyramid per contact),\n"
      "semi-implicit Euler, explicit gyroscopic term. broadphase candidates are not exposed (0); AABB and\n"
      "dynamic pairs are the exact boxes at the pre-step pose that overlap. response = World::step (collision\n"
      "detection, the constraint solve and the integration in one call: aabbs, broadphase, midphase and\n"
      "integrate n/a). contacts = DART's contact rows, penetration over their depths; kinetic energy includes\n"
      "rotation.",
      dart_version(), impl().geometry, dart_lcp_name(s.lcp),
      s.lcp == DartLcp::Pgs ? fmt::format(", {} iterations", s.iterations) : std::string(" (PGS fallback)"), s.erp,
      s.max_erv, s.cfm, dart_friction_name(s.friction));
}

}  // namespace octocd
