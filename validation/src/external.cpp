// Another engine's frames judged by octocd's validators (issue 11): the model of its
// bodies, and ExternalValidator, which hands FrameRecords to the same
// FrameValidators that judge octocd's engines. The checks of each record against the
// conventions are core's (check_frame_record, octocd/external_trace.hpp).
#include "octocd/external.hpp"

#include "octocd/device_judge.hpp"
#include "octocd/physics.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <limits>
#include <map>
#include <tuple>
#include <utility>

#include <fmt/format.h>

#include "octocd/error.hpp"
#include "octocd/mesh_octree.hpp"
#include "octocd/validation_rows.hpp"

namespace octocd {

namespace {

bool finite(Vec3 v) { return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z); }

/// The exact world AABB of a mesh at `pose`: the bounds of its posed vertices (design.md section 13).
Aabb posed_mesh_aabb(const Mesh& mesh, const Pose& pose) {
  Aabb out{to_world(pose, mesh.vertices.front()), to_world(pose, mesh.vertices.front())};
  for (const Vec3& v : mesh.vertices) {
    const Vec3 w = to_world(pose, v);
    out.min = {std::min(out.min.x, w.x), std::min(out.min.y, w.y), std::min(out.min.z, w.z)};
    out.max = {std::max(out.max.x, w.x), std::max(out.max.y, w.y), std::max(out.max.z, w.z)};
  }
  return out;
}

/// With a scene: each body's local box must be the scene's, or (design.md section 13: the body frame's
/// origin is the centre of mass) the scene's translated, same size within 1e-5 relative.
/// A translated box gets a shape of its own (one per scene shape and offset) whose mesh
/// is moved by the offset, so the shape's bounds are the given local box.
void place_scene_shapes(Model& model, const std::vector<Aabb>& local_boxes, const std::string& origin) {
  std::map<std::tuple<std::uint32_t, float, float, float>, std::uint32_t> moved;
  for (std::size_t i = 0; i < local_boxes.size(); ++i) {
    const Aabb a = local_boxes[i];
    const Aabb b = model.local_box(i);
    const float tol = 1e-5f * (1.0f + length(b.max - b.min));
    const Vec3 sa = a.max - a.min, sb = b.max - b.min;
    const float dsize = std::max({std::fabs(sa.x - sb.x), std::fabs(sa.y - sb.y), std::fabs(sa.z - sb.z)});
    if (!finite(a.min) || !finite(a.max) || !(dsize <= tol))
      throw InputError(fmt::format("{}: local_boxes: body {} is ({}, {}, {})-({}, {}, {}), the scene's is "
                                   "({}, {}, {})-({}, {}, {}); allowed: the scene's local box (within 1e-5), or "
                                   "it translated (the body frame's origin at the centre of mass; sizes within "
                                   "1e-5)",
                                   origin, i, a.min.x, a.min.y, a.min.z, a.max.x, a.max.y, a.max.z, b.min.x, b.min.y,
                                   b.min.z, b.max.x, b.max.y, b.max.z));
    const Vec3 offset = center(a) - center(b);
    if (std::max({std::fabs(offset.x), std::fabs(offset.y), std::fabs(offset.z)}) <= tol) continue;
    const std::uint32_t id = model.bodies[i].shape;
    const auto key = std::make_tuple(id, offset.x, offset.y, offset.z);
    auto it = moved.find(key);
    if (it == moved.end()) {
      Shape shape = model.shapes[id];
      shape.name = fmt::format("{}@({}, {}, {})", shape.name, offset.x, offset.y, offset.z);
      shape.local = translated(shape.local, offset);
      if (shape.mesh) {
        auto mesh = std::make_shared<Mesh>(*shape.mesh);
        for (Vec3& v : mesh->vertices) v = v + offset;
        const int depth = shape.octree ? shape.octree->depth : model.scene.mesh_octree_depth;
        shape.octree = std::make_shared<const MeshOctree>(build_mesh_octree(*mesh, depth));
        shape.mesh = std::move(mesh);
      }
      model.shapes.push_back(std::move(shape));
      model.theta_shape.push_back(model.theta_shape[id]);
      it = moved.emplace(key, static_cast<std::uint32_t>(model.shapes.size() - 1)).first;
    }
    model.bodies[i].shape = it->second;
  }
}

}  // namespace

struct ExternalValidator::Impl {
  ExternalOptions options;
  PhysicsBodies physics;
  std::shared_ptr<Model> model;
  bool domain_given = false;
  std::unique_ptr<FrameValidators> validators;
  std::int64_t episode_first = std::numeric_limits<std::int64_t>::min();
  std::int64_t episode_last = std::numeric_limits<std::int64_t>::max();
  /// Checks `rec`, completes its AABBs and confirmed pairs, and builds the validators on
  /// the first frame (the domain around its AABBs unless given).
  void prepare(FrameRecord& rec);
};

ExternalValidator::ExternalValidator(const ExternalBodies& bodies, const ExternalOptions& options)
    : impl_(std::make_unique<Impl>()) {
  Impl& s = *impl_;
  s.options = options;
  s.physics = bodies.physics;
  const std::string& origin = options.engine;
  auto model = std::make_shared<Model>();
  if (!bodies.scene_json.empty()) {
    // A trace's scene: its meshes only from --mesh-dir (default: the trace's folder) or the data dir.
    const std::string mesh_dir = !options.mesh_dir.empty() ? options.mesh_dir
                                 : bodies.scene_file.empty()
                                     ? std::string()
                                     : std::filesystem::absolute(bodies.scene_file).parent_path().string();
    *model = *build_model(bodies.scene_file.empty()
                              ? parse_scene(bodies.scene_json, origin + " scene")
                              : parse_embedded_scene(bodies.scene_json,
                                                     bodies.scene_file + ": / (root attribute scene)", mesh_dir));
    s.domain_given = true;
    const std::size_t n = model->bodies.size();
    if (!bodies.local_boxes.empty() && bodies.local_boxes.size() != n)
      throw InputError(fmt::format("{}: local_boxes: {} boxes, the scene has {} bodies; allowed: one per body of "
                                   "the scene (walls first, then each group's bodies)",
                                   origin, bodies.local_boxes.size(), n));
    place_scene_shapes(*model, bodies.local_boxes, origin);
    if (!bodies.inverse_mass.empty() && bodies.inverse_mass.size() != n)
      throw InputError(fmt::format("{}: inverse_mass: {} values, the scene has {} bodies; allowed: one per body",
                                   origin, bodies.inverse_mass.size(), n));
    for (std::size_t i = 0; i < bodies.inverse_mass.size(); ++i) {
      const float a = bodies.inverse_mass[i], b = model->initial.w[i];
      if (!(std::fabs(a - b) <= 1e-5f * std::max(1.0f, b)))
        throw InputError(fmt::format("{}: inverse_mass: body {} is {} 1/kg, the scene's is {}; allowed: the "
                                     "scene's value",
                                     origin, i, a, b));
    }
  } else {
    const std::size_t n = bodies.local_boxes.size();
    if (n == 0)
      throw InputError(fmt::format("{}: local_boxes: empty; allowed: one local box per body (or a scene)", origin));
    if (!bodies.inverse_mass.empty() && bodies.inverse_mass.size() != n)
      throw InputError(fmt::format("{}: inverse_mass: {} values for {} bodies; allowed: one per body, or none",
                                   origin, bodies.inverse_mass.size(), n));
    if (!bodies.meshes.empty() && bodies.meshes.size() != n)
      throw InputError(fmt::format("{}: meshes: {} entries for {} bodies; allowed: one per body (nullptr for a "
                                   "box), or none",
                                   origin, bodies.meshes.size(), n));
    if (!(bodies.dt > 0.0f) || !std::isfinite(bodies.dt))
      throw InputError(fmt::format("{}: dt: {}; allowed: a finite time step > 0 (s)", origin, bodies.dt));
    if (!finite(bodies.gravity))
      throw InputError(fmt::format("{}: gravity: not finite; allowed: finite m/s^2", origin));
    Scene& sc = model->scene;
    sc.name = options.engine;
    sc.dt = bodies.dt;
    sc.gravity = bodies.gravity;
    sc.walls = Walls::None;
    // One shape per distinct (local box, mesh).
    std::map<std::tuple<const Mesh*, float, float, float, float, float, float>, std::uint32_t> ids;
    for (std::size_t i = 0; i < n; ++i) {
      const Aabb& box = bodies.local_boxes[i];
      if (!finite(box.min) || !finite(box.max) ||
          !(box.min.x <= box.max.x && box.min.y <= box.max.y && box.min.z <= box.max.z))
        throw InputError(fmt::format("{}: local_boxes: body {}: not finite or min above max; allowed: finite "
                                     "boxes with min <= max (m)",
                                     origin, i));
      const float w = bodies.inverse_mass.empty() ? 1.0f : bodies.inverse_mass[i];
      if (!std::isfinite(w) || w < 0.0f)
        throw InputError(fmt::format("{}: inverse_mass: body {} is {}; allowed: finite >= 0 (1/kg, 0 = static)",
                                     origin, i, w));
      const std::shared_ptr<const Mesh> mesh = bodies.meshes.empty() ? nullptr : bodies.meshes[i];
      const auto key = std::make_tuple(mesh.get(), box.min.x, box.min.y, box.min.z, box.max.x, box.max.y,
                                       box.max.z);
      auto it = ids.find(key);
      if (it == ids.end()) {
        Shape shape{fmt::format("body{}", i), box, nullptr, nullptr, 0.0f};
        if (mesh) {
          if (mesh->vertices.empty())
            throw InputError(fmt::format("{}: meshes: body {}: no vertices; allowed: a triangle mesh", origin, i));
          if (mesh->triangles.empty())  // FCL's traversal reads past a mesh without triangles
            throw InputError(fmt::format("{}: meshes: body {}: no triangles; allowed: a triangle mesh", origin, i));
          const Aabb mb = mesh_bounds(*mesh);
          const float slack = 1e-5f * (1.0f + length(box.max - box.min));
          if (mb.min.x < box.min.x - slack || mb.min.y < box.min.y - slack || mb.min.z < box.min.z - slack ||
              mb.max.x > box.max.x + slack || mb.max.y > box.max.y + slack || mb.max.z > box.max.z + slack)
            throw InputError(fmt::format("{}: meshes: body {}: vertices outside its local box; allowed: a mesh in "
                                         "the frame of its local box",
                                         origin, i));
          shape.octree = std::make_shared<const MeshOctree>(build_mesh_octree(*mesh, sc.mesh_octree_depth));
          shape.mesh = mesh;
          shape.mean_edge = mean_edge_length(*mesh);
        }
        model->shapes.push_back(std::move(shape));
        it = ids.emplace(key, static_cast<std::uint32_t>(model->shapes.size() - 1)).first;
      }
      model->bodies.push_back({it->second, "external"});
      model->initial.x.push_back({});
      model->initial.v.push_back({});
      model->initial.w.push_back(w);
    }
    model->theta_shape.clear();
    for (const Shape& sh : model->shapes) model->theta_shape.push_back(sh.mean_edge);
    if (bodies.domain) {
      sc.domain = *bodies.domain;
      s.domain_given = true;
    }
  }
  check_physics_bodies(bodies.physics, model->initial.w, origin);
  s.model = std::move(model);
}

ExternalValidator::~ExternalValidator() = default;

std::size_t ExternalValidator::body_count() const { return impl_->model->bodies.size(); }

const Model& ExternalValidator::model() const { return *impl_->model; }

void ExternalValidator::observe(FrameRecord rec, bool checked) {
  impl_->prepare(rec);
  impl_->validators->observe(rec, checked);
}

void ExternalValidator::set_episode_frames(std::int64_t first, std::int64_t last) {
  impl_->episode_first = first;
  impl_->episode_last = last;
  if (impl_->validators) impl_->validators->physics().set_episode_frames(first, last);
}

void ExternalValidator::observe_episodes(FrameRecord rec) {
  impl_->prepare(rec);
  impl_->validators->physics().observe_episodes(rec);
}

bool ExternalValidator::episodes_pending() const {
  return impl_->validators && impl_->validators->physics().episodes_pending();
}

bool ExternalValidator::judges_episodes() const {
  return !impl_->options.octocd_engine && impl_->physics.contact_model != PhysicsBodies::ContactModel::Rigid;
}

void ExternalValidator::Impl::prepare(FrameRecord& rec) {
  Impl& s = *this;
  const Model& m = *s.model;
  const std::size_t n = m.bodies.size();
  check_frame_record(rec, n, s.options.engine);
  if (rec.aabbs.empty() && !rec.x_det.empty()) {
    // A rotating engine's record (design.md section 13): the exact world AABBs at its detection pose.
    rec.aabbs.resize(n);
    for (std::size_t i = 0; i < n; ++i) {
      const Pose pose{rec.x_det[i], rec.q_det.empty() ? Quat{} : rec.q_det[i]};
      const Shape& shape = m.shapes[m.bodies[i].shape];
      rec.aabbs[i] = shape.mesh ? posed_mesh_aabb(*shape.mesh, pose) : posed_box_aabb(shape.local, pose);
    }
  } else if (rec.aabbs.empty()) {
    // design.md sections 4.1 then 4.2, with the same float32 operations as octocd's engines.
    rec.aabbs.resize(n);
    for (std::size_t i = 0; i < n; ++i) {
      Vec3 x = rec.x_pre[i], v = rec.v_pre[i];
      integrate(x, v, m.initial.w[i], m.scene.gravity, Vec3{}, m.scene.dt);
      rec.aabbs[i] = translated(m.local_box(i), x);
    }
  }
  rec.has_contact_terms = false;
  rec.confirmed.clear();
  for (const ContactRecord& c : rec.contacts)  // a manifold's rows are consecutive: one pair each
    if (rec.confirmed.empty() || !(rec.confirmed.back() == c.pair)) rec.confirmed.push_back(c.pair);
  if (!s.validators) {
    if (!s.domain_given) {
      // The first frame's bounding box (the octrees' root cube is built around it).
      Aabb d = rec.aabbs.front();
      for (const Aabb& b : rec.aabbs) {
        d.min = {std::min(d.min.x, b.min.x), std::min(d.min.y, b.min.y), std::min(d.min.z, b.min.z)};
        d.max = {std::max(d.max.x, b.max.x), std::max(d.max.y, b.max.y), std::max(d.max.z, b.max.z)};
      }
      const Vec3 pad = 0.01f * (d.max - d.min) + Vec3{1e-3f, 1e-3f, 1e-3f};
      s.model->scene.domain = {d.min - pad, d.max + pad};
    }
    ValidationOptions vo;
    vo.against_fcl = s.options.against_fcl;
    vo.against_bullet = false;
    vo.tol = s.options.tol;
    vo.overridden = s.options.overridden;
    vo.threads = s.options.threads;
    vo.judge_device = s.options.judge_device;
    vo.stop = s.options.stop;
    s.validators = std::make_unique<FrameValidators>(
        // Another engine's pairs are judged by the physics tier (broadphase completeness),
        // not against octocd's broadphases: none are compared here.
        m, vo, std::vector<std::unique_ptr<BroadPhase>>{},
        FrameValidators::Source{fmt::format("engine '{}'", s.options.engine), false, s.options.spec6_response,
                                std::make_shared<PhysicsBodies>(s.options.octocd_engine
                                                                    ? octocd_physics_bodies(m)
                                                                    : s.physics)});
    s.validators->physics().set_episode_frames(s.episode_first, s.episode_last);
  }
}

std::vector<ValidationResult> ExternalValidator::results() const {
  std::vector<ValidationResult> out;
  if (impl_->validators) out = impl_->validators->results();
  auto na = [&](RowId id, const char* figure) {
    ValidationResult r;
    r.tier = row_info(id).tier;
    r.name = row_info(id).name;
    r.figure = figure;
    r.applicable = false;
    r.detail = "another engine's frames: this validator steps an engine (octocd validate SCENE.json)";
    out.push_back(r);
  };
  na(RowId::Analytic, "closed form of an analytic scene");
  na(RowId::BulletDynamics, "comparison with btDiscreteDynamicsWorld");
  return out;
}

std::vector<ValidationResult> validate_frame(const ExternalBodies& bodies, const FrameRecord& rec,
                                             const ExternalOptions& options) {
  ExternalValidator v(bodies, options);
  v.observe(rec, true);
  return v.results();
}

}  // namespace octocd
