// Another engine's frames judged by octocd's validators (issue 11): the conventions check,
// the model of its bodies, and ExternalValidator, which hands FrameRecords to the same
// FrameValidators that judge octocd's engines.
#include "octocd/external.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <map>
#include <tuple>
#include <utility>

#include <fmt/format.h>

#include "octocd/error.hpp"
#include "octocd/mesh_octree.hpp"

namespace octocd {

namespace {

bool finite(Vec3 v) { return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z); }

[[noreturn]] void fail(const std::string& origin, const std::string& field, std::int64_t frame,
                       const std::string& problem, const std::string& allowed) {
  throw InputError(fmt::format("{}: {}: frame {}: {}; allowed: {}", origin, field, frame, problem, allowed));
}

/// Pairs sorted by (a, b), unique, a < b < n.
void check_pairs(const std::vector<Pair>& pairs, std::size_t n, const std::string& origin,
                 const std::string& field, std::int64_t frame) {
  const std::string allowed =
      fmt::format("pairs (a, b) with a < b < {} bodies, sorted by (a, b), each once", n);
  for (std::size_t i = 0; i < pairs.size(); ++i) {
    const Pair q = pairs[i];
    if (q.a >= q.b)
      fail(origin, field, frame, fmt::format("row {} is ({}, {}): a >= b", i, q.a, q.b), allowed);
    if (q.b >= n)
      fail(origin, field, frame, fmt::format("row {} is ({}, {}): body {} out of range", i, q.a, q.b, q.b),
           allowed);
    if (i > 0 && !(pairs[i - 1] < q))
      fail(origin, field, frame,
           fmt::format("row {} is ({}, {}) after ({}, {}): {}", i, q.a, q.b, pairs[i - 1].a, pairs[i - 1].b,
                       pairs[i - 1] == q ? "duplicated" : "not sorted"),
           allowed);
  }
}

void check_vectors(const std::vector<Vec3>& v, std::size_t n, const std::string& origin,
                   const std::string& field, std::int64_t frame) {
  if (v.size() != n)
    fail(origin, field, frame, fmt::format("{} rows for {} bodies", v.size(), n), "one row per body");
  for (std::size_t i = 0; i < n; ++i)
    if (!finite(v[i]))
      fail(origin, field, frame, fmt::format("body {} is ({}, {}, {}): not finite", i, v[i].x, v[i].y, v[i].z),
           "finite numbers");
}

}  // namespace

void check_frame_record(const FrameRecord& rec, std::size_t n, const std::string& origin,
                        const RecordFieldNames& names) {
  const std::int64_t f = rec.frame;
  const bool states = !rec.x_pre.empty() || !rec.v_pre.empty() || !rec.x_post.empty() || !rec.v_post.empty();
  if (rec.aabbs.empty() && !states)
    fail(origin, names.aabbs, f, "no world AABBs and no states", "the AABBs, or x_pre, v_pre, x_post, v_post");
  if (!rec.aabbs.empty()) {
    if (rec.aabbs.size() != n)
      fail(origin, names.aabbs, f, fmt::format("{} boxes for {} bodies", rec.aabbs.size(), n), "one per body");
    for (std::size_t i = 0; i < n; ++i) {
      const Aabb& b = rec.aabbs[i];
      if (!finite(b.min) || !finite(b.max))
        fail(origin, names.aabbs, f, fmt::format("body {}: not finite", i), "finite numbers");
      if (!(b.min.x <= b.max.x && b.min.y <= b.max.y && b.min.z <= b.max.z))
        fail(origin, names.aabbs, f,
             fmt::format("body {}: min ({}, {}, {}) above max ({}, {}, {})", i, b.min.x, b.min.y, b.min.z, b.max.x,
                         b.max.y, b.max.z),
             "min <= max on every axis");
    }
  }
  if (states) {
    check_vectors(rec.x_pre, n, origin, names.x_pre, f);
    check_vectors(rec.v_pre, n, origin, names.v_pre, f);
    check_vectors(rec.x_post, n, origin, names.x_post, f);
    check_vectors(rec.v_post, n, origin, names.v_post, f);
  }
  if (rec.has_pairs) check_pairs(rec.pairs, n, origin, names.pairs, f);
  std::vector<Pair> contact_pairs(rec.contacts.size());
  for (std::size_t i = 0; i < rec.contacts.size(); ++i) contact_pairs[i] = rec.contacts[i].pair;
  check_pairs(contact_pairs, n, origin, names.contact_pair, f);
  for (std::size_t i = 0; i < rec.contacts.size(); ++i) {
    const ContactRecord& c = rec.contacts[i];
    const std::string which = fmt::format("row {} (pair ({}, {}))", i, c.pair.a, c.pair.b);
    const double len = length(c.normal);
    if (!finite(c.normal) || !(std::fabs(len - 1.0) <= 1e-3))
      fail(origin, names.contact_normal, f,
           fmt::format("{} is ({}, {}, {}), length {}", which, c.normal.x, c.normal.y, c.normal.z, len),
           "a finite unit vector (|n| within 1e-3 of 1) from B to A");
    if (!std::isfinite(c.depth) || c.depth < 0.0f)
      fail(origin, names.contact_depth, f, fmt::format("{} is {}", which, c.depth), "a finite depth >= 0 (m)");
    if (!std::isfinite(c.jn) || c.jn < 0.0f)
      fail(origin, names.contact_jn, f, fmt::format("{} is {}", which, c.jn),
           "a finite normal impulse >= 0 (kg m/s)");
    if (!std::isfinite(c.jt))
      fail(origin, names.contact_jt, f, fmt::format("{} is {}", which, c.jt), "a finite impulse (kg m/s)");
  }
}

struct ExternalValidator::Impl {
  ExternalOptions options;
  PhysicsBodies physics;
  std::shared_ptr<Model> model;
  bool domain_given = false;
  std::unique_ptr<FrameValidators> validators;
};

ExternalValidator::ExternalValidator(const ExternalBodies& bodies, const ExternalOptions& options)
    : impl_(std::make_unique<Impl>()) {
  Impl& s = *impl_;
  s.options = options;
  s.physics = bodies.physics;
  const std::string& origin = options.engine;
  auto model = std::make_shared<Model>();
  if (!bodies.scene_json.empty()) {
    *model = *build_model(parse_scene(bodies.scene_json, origin + " scene"));
    s.domain_given = true;
    const std::size_t n = model->bodies.size();
    if (!bodies.local_boxes.empty() && bodies.local_boxes.size() != n)
      throw InputError(fmt::format("{}: local_boxes: {} boxes, the scene has {} bodies; allowed: one per body of "
                                   "the scene (walls first, then each group's bodies)",
                                   origin, bodies.local_boxes.size(), n));
    for (std::size_t i = 0; i < bodies.local_boxes.size(); ++i) {
      const Aabb& a = bodies.local_boxes[i];
      const Aabb& b = model->local_box(i);
      const float d = std::max({std::fabs(a.min.x - b.min.x), std::fabs(a.min.y - b.min.y),
                                std::fabs(a.min.z - b.min.z), std::fabs(a.max.x - b.max.x),
                                std::fabs(a.max.y - b.max.y), std::fabs(a.max.z - b.max.z)});
      if (!(d <= 1e-5f * (1.0f + length(b.max - b.min))))
        throw InputError(fmt::format("{}: local_boxes: body {} is ({}, {}, {})-({}, {}, {}), the scene's is "
                                     "({}, {}, {})-({}, {}, {}); allowed: the scene's local box (within 1e-5)",
                                     origin, i, a.min.x, a.min.y, a.min.z, a.max.x, a.max.y, a.max.z, b.min.x,
                                     b.min.y, b.min.z, b.max.x, b.max.y, b.max.z));
    }
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
  s.model = std::move(model);
}

ExternalValidator::~ExternalValidator() = default;

std::size_t ExternalValidator::body_count() const { return impl_->model->bodies.size(); }

const Model& ExternalValidator::model() const { return *impl_->model; }

void ExternalValidator::observe(FrameRecord rec, bool checked) {
  Impl& s = *impl_;
  const Model& model = *s.model;
  const std::size_t n = model.bodies.size();
  check_frame_record(rec, n, s.options.engine);
  if (rec.aabbs.empty()) {
    // SPEC 4.1 then 4.2, with the same float32 operations as octocd's engines.
    rec.aabbs.resize(n);
    for (std::size_t i = 0; i < n; ++i) {
      Vec3 x = rec.x_pre[i], v = rec.v_pre[i];
      integrate(x, v, model.initial.w[i], model.scene.gravity, Vec3{}, model.scene.dt);
      rec.aabbs[i] = translated(model.local_box(i), x);
    }
  }
  rec.has_contact_terms = false;
  rec.confirmed.clear();
  for (const ContactRecord& c : rec.contacts) rec.confirmed.push_back(c.pair);
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
    s.validators = std::make_unique<FrameValidators>(
        model, vo, compared_broadphases(model.scene, s.options.against_fcl),
        FrameValidators::Source{fmt::format("engine '{}'", s.options.engine), false, s.options.spec6_response,
                                std::make_shared<PhysicsBodies>(s.physics)});
  }
  s.validators->observe(rec, checked);
}

std::vector<ValidationResult> ExternalValidator::results() const {
  std::vector<ValidationResult> out;
  if (impl_->validators) out = impl_->validators->results();
  auto na = [&](const char* name, const char* figure) {
    ValidationResult r;
    r.name = name;
    r.figure = figure;
    r.applicable = false;
    r.detail = "another engine's frames: this validator steps an engine (octocd validate SCENE.json)";
    out.push_back(r);
  };
  na("analytic", "closed form of an analytic scene");
  na("bullet-dynamics", "comparison with btDiscreteDynamicsWorld");
  return out;
}

std::vector<ValidationResult> validate_frame(const ExternalBodies& bodies, const FrameRecord& rec,
                                             const ExternalOptions& options) {
  ExternalValidator v(bodies, options);
  v.observe(rec, true);
  return v.results();
}

}  // namespace octocd
