// The physics tier (design.md section 13): any engine judged on its posed shapes with FCL, never on
// octocd's own response model (that is validation/model/). This file: the settings'
// names, the constructor, and the frame driver (observe); the rows live in files per
// family (physics_impl.hpp lists them).
#include "physics_impl.hpp"

#include "../src/parallel.hpp"
#include "../src/row_clock.hpp"

#include <algorithm>
#include <cmath>
#include <optional>
#include <tuple>
#include <utility>

#include "octocd/error.hpp"
#include "octocd/reference_contact.hpp"

namespace octocd {

double pair_friction(const PhysicsBodies& bodies, std::uint32_t a, std::uint32_t b) {
  const double mu = bodies.body_friction.empty() ? bodies.mu
                                                 : combine_material(bodies.combine, bodies.body_friction[a],
                                                                    bodies.body_friction[b]);
  return std::max(mu, physics_detail::kMuFloor);
}

Pose detection_pose(const Model& model, const FrameRecord& rec, std::size_t i) {
  Pose p;
  if (!rec.x_det.empty()) {
    p.position = rec.x_det[i];
    if (!rec.q_det.empty()) p.orientation = rec.q_det[i];
    return p;
  }
  p.position = rec.aabbs[i].min - model.local_box(i).min;
  return p;
}

PhysicsBodies octocd_physics_bodies(const Model& model) {
  PhysicsBodies b;
  const ContactParams& p = model.scene.response;
  b.mu = p.mu_static;
  b.restitution = p.restitution;
  b.theta_margin = true;
  b.broadphase_exact = true;
  b.contact_geometry = ContactGeometry::Aabb;
  b.slop = p.slop;
  b.velocity_clamp = p.max_velocity;
  b.integrator = PhysicsBodies::Integrator::SemiImplicit;  // design.md section 4.1: v += dt g, then x += dt v
  b.jt_along_sliding = true;
  b.impulses_complete = p.iterations <= 1;
  b.jacobi_response = true;
  return b;
}

const char* contact_model_name(PhysicsBodies::ContactModel m) {
  return m == PhysicsBodies::ContactModel::Soft         ? "soft"
         : m == PhysicsBodies::ContactModel::Undeclared ? "undeclared"
                                                        : "rigid";
}

namespace {

/// The name of `v` in `names` (value, name), or `otherwise`.
template <class E, std::size_t N>
const char* name_in(E v, const std::pair<E, const char*> (&names)[N], const char* otherwise) {
  for (const auto& [e, name] : names)
    if (e == v) return name;
  return otherwise;
}

}  // namespace

const char* gyroscopic_name(PhysicsBodies::Gyroscopic g) {
  using G = PhysicsBodies::Gyroscopic;
  static constexpr std::pair<G, const char*> kNames[] = {{G::Integrated, "true"}, {G::Absent, "false"}};
  return name_in(g, kNames, "undeclared");
}

const char* impulses_name(PhysicsBodies::Impulses i) {
  using I = PhysicsBodies::Impulses;
  static constexpr std::pair<I, const char*> kNames[] = {
      {I::Complete, "complete"}, {I::NormalOnly, "normal-only"}, {I::None, "none"}};
  return name_in(i, kNames, "complete");
}

const char* integrator_name(PhysicsBodies::Integrator i) {
  using I = PhysicsBodies::Integrator;
  static constexpr std::pair<I, const char*> kNames[] = {{I::SemiImplicit, "semi-implicit"},
                                                         {I::Explicit, "explicit"},
                                                         {I::Any, "any"},
                                                         {I::Substepped, "substepped"},
                                                         {I::Undeclared, "undeclared"}};
  return name_in(i, kNames, "semi-implicit");
}

namespace physics_detail {

M3 conjugated(const M3& r, const M3& m) {
  M3 rm{}, out{};
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j)
      for (int k = 0; k < 3; ++k) rm[3 * i + j] += r[3 * i + k] * m[3 * k + j];
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j)
      for (int k = 0; k < 3; ++k) out[3 * i + j] += rm[3 * i + k] * r[3 * j + k];
  return out;
}
M3 inverse(const M3& m) {
  const double c00 = m[4] * m[8] - m[5] * m[7], c01 = m[5] * m[6] - m[3] * m[8], c02 = m[3] * m[7] - m[4] * m[6];
  const double det = m[0] * c00 + m[1] * c01 + m[2] * c02;
  if (!(std::fabs(det) > 0)) return M3{};
  const double k = 1.0 / det;
  return {c00 * k, (m[2] * m[7] - m[1] * m[8]) * k, (m[1] * m[5] - m[2] * m[4]) * k,
          c01 * k, (m[0] * m[8] - m[2] * m[6]) * k, (m[2] * m[3] - m[0] * m[5]) * k,
          c02 * k, (m[1] * m[6] - m[0] * m[7]) * k, (m[0] * m[4] - m[1] * m[3]) * k};
}

std::string pair_name(Pair p) { return fmt::format("pair ({}, {})", p.a, p.b); }
std::string body_name(std::size_t i) { return fmt::format("body {}", i); }
std::string group_name(BodyList members) {
  std::string s = "group (";
  for (std::size_t k = 0; k < members.size() && k < 3; ++k) s += (k ? ", " : "") + std::to_string(members[k]);
  return s + (members.size() > 3 ? ", ...)" : ")");
}

ValidationCause Tally::cause(const char* name, const char* unit) const {
  ValidationCause c;
  c.name = name;
  c.unit = unit;
  c.count = failures;
  c.worst = failures ? worst_failure.figure : 0.0;
  c.examples = examples;
  c.items.assign(items.begin(), items.end());
  c.items_complete = items_complete;
  return c;
}
std::string Tally::summary(const char* name, const char* noun, const char* unit) const {
  if (failures == 0) return fmt::format("{} 0 of {} {}", name, checks, noun);
  std::string s = fmt::format("{} {} of {} {} (worst {:.4g} {}", name, failures, checks, noun, worst_failure.figure,
                              unit);
  if (worst_failure.frame >= 0) s += fmt::format(", frame {}", worst_failure.frame);
  if (!worst_failure.item.empty()) s += " " + worst_failure.item;
  s += ": " + worst_failure.text;
  if (!examples.empty() && examples.front().text != worst_failure.text) s += "; first: " + examples.front().text;
  return s + ")";
}

}  // namespace physics_detail

using namespace dmath;
using namespace physics_detail;

PhysicsValidators::PhysicsValidators(const Model& model, const PhysicsBodies& bodies, const Tolerances& tol,
                                     std::string label)
    : impl_(std::make_unique<Impl>()) {
  Impl& s = *impl_;
  s.model = &model;
  s.bodies = bodies;
  s.tol = tol;
  s.label = std::move(label);
  const std::size_t n = model.bodies.size();
  auto bad = [&](const std::string& field, const std::string& what) {
    throw InputError(fmt::format("physics validators ({}): PhysicsBodies.{}: {}", s.label, field, what));
  };
  if (!bodies.inertia.empty() && bodies.inertia.size() != n)
    bad("inertia", fmt::format("{} tensors for {} bodies; allowed: 0 (derived) or {}", bodies.inertia.size(), n, n));
  if (!bodies.body_friction.empty() && bodies.body_friction.size() != n)
    bad("body_friction", fmt::format("{} values for {} bodies; allowed: 0 or {}", bodies.body_friction.size(), n, n));
  if (!bodies.body_restitution.empty() && bodies.body_restitution.size() != n)
    bad("body_restitution",
        fmt::format("{} values for {} bodies; allowed: 0 or {}", bodies.body_restitution.size(), n, n));
  for (std::size_t i = 0; i < bodies.body_friction.size(); ++i)
    if (!(bodies.body_friction[i] >= 0) || !std::isfinite(bodies.body_friction[i]))
      bad("body_friction", fmt::format("body {}: {}; allowed: finite >= 0", i, bodies.body_friction[i]));
  for (std::size_t i = 0; i < bodies.body_restitution.size(); ++i)
    if (!(bodies.body_restitution[i] >= 0) || !std::isfinite(bodies.body_restitution[i]))
      bad("body_restitution", fmt::format("body {}: {}; allowed: finite >= 0", i, bodies.body_restitution[i]));
  if (!(bodies.mu >= 0) || !std::isfinite(bodies.mu)) bad("mu", fmt::format("{}; allowed: finite >= 0", bodies.mu));
  if (!(bodies.restitution >= 0) || !std::isfinite(bodies.restitution))
    bad("restitution", fmt::format("{}; allowed: finite >= 0", bodies.restitution));
  if (!(bodies.contact_margin >= 0) || !std::isfinite(bodies.contact_margin))
    bad("contact_margin", fmt::format("{}; allowed: finite >= 0 m", bodies.contact_margin));
  if (!bodies.locked_dofs.empty() && bodies.locked_dofs.size() != n)
    bad("locked_dofs", fmt::format("{} values for {} bodies; allowed: 0 or {}", bodies.locked_dofs.size(), n, n));
  for (std::size_t i = 0; i < bodies.locked_dofs.size(); ++i)
    if (bodies.locked_dofs[i] > 63)
      bad("locked_dofs", fmt::format("body {}: {}; allowed: 0 .. 63 (6 bits)", i, unsigned(bodies.locked_dofs[i])));
  if (!(bodies.slop >= 0) || !std::isfinite(bodies.slop))
    bad("slop", fmt::format("{}; allowed: finite >= 0 m", bodies.slop));
  if (!bodies.convex_radius.empty() && bodies.convex_radius.size() != n)
    bad("convex_radius", fmt::format("{} values for {} bodies; allowed: 0 or {}", bodies.convex_radius.size(), n, n));
  for (std::size_t i = 0; i < bodies.convex_radius.size(); ++i)
    if (!(bodies.convex_radius[i] >= 0) || !std::isfinite(bodies.convex_radius[i]))
      bad("convex_radius", fmt::format("body {}: {}; allowed: finite >= 0 m", i, bodies.convex_radius[i]));
  if (!bodies.com_offset.empty() && bodies.com_offset.size() != n)
    bad("com_offset", fmt::format("{} offsets for {} bodies; allowed: 0 or {}", bodies.com_offset.size(), n, n));
  for (std::size_t i = 0; i < bodies.com_offset.size(); ++i)
    for (double c : bodies.com_offset[i])
      if (!std::isfinite(c)) bad("com_offset", fmt::format("body {}: {}; allowed: finite (m, body frame)", i, c));
  for (std::size_t k = 0; k < bodies.incomplete_rows.size(); ++k) {
    const PhysicsBodies::IncompleteRows& e = bodies.incomplete_rows[k];
    const bool whole = e.a == PhysicsBodies::kEveryPair && e.b == PhysicsBodies::kEveryPair;
    if (!whole && !(e.a < e.b && e.b < n))
      bad("incomplete_rows", fmt::format("entry {}: pair ({}, {}); allowed: a < b < {} or both kEveryPair", k, e.a,
                                         e.b, n));
    if (k > 0) {
      const PhysicsBodies::IncompleteRows& p = bodies.incomplete_rows[k - 1];
      if (!(std::make_tuple(p.frame, p.a, p.b) < std::make_tuple(e.frame, e.a, e.b)))
        bad("incomplete_rows", fmt::format("entry {}: frame {} after frame {}; allowed: sorted by (frame, a, b), no "
                                           "duplicates",
                                           k, e.frame, p.frame));
    }
  }

  s.mass.assign(n, 0.0);
  s.inertia.assign(n, M3{});
  for (std::size_t i = 0; i < n; ++i) {
    const float w = model.initial.w[i];
    if (!(w > 0.0f)) continue;
    s.mass[i] = 1.0 / w;
    if (!bodies.inertia.empty()) {
      s.inertia[i] = bodies.inertia[i];
      for (double v : s.inertia[i])
        if (!std::isfinite(v)) bad("inertia", fmt::format("body {}: not finite", i));
    } else {
      // A solid box of the local AABB (Bullet's rule for convex shapes).
      const Aabb& b = model.local_box(i);
      const double a = b.max.x - b.min.x, bb = b.max.y - b.min.y, c = b.max.z - b.min.z;
      const double k = s.mass[i] / 12.0;
      s.inertia[i] = M3{k * (bb * bb + c * c), 0, 0, 0, k * (a * a + c * c), 0, 0, 0, k * (a * a + bb * bb)};
    }
  }
  s.principal.assign(n, {0.0, 0.0});
  for (std::size_t i = 0; i < n; ++i) s.principal[i] = dmath::sym_eigen_range(s.inertia[i]);
  if (bodies.body_restitution.empty()) {
    s.restitution_le_1 = bodies.restitution <= 1.0;
  } else {
    // The largest pair value of any rule is at most the largest body value, or its square.
    double r = 0;
    for (float v : bodies.body_restitution) r = std::max(r, double(v));
    s.restitution_le_1 = combine_material(bodies.restitution_combine, r, r) <= 1.0 && r <= 1.0;
  }
  s.max_margin = bodies.contact_margin;
  if (bodies.theta_margin) {
    s.max_margin = 0;
    for (float t : model.theta_shape) s.max_margin = std::max(s.max_margin, double(t));
  }
  if (!bodies.collision_shape.empty()) {
    if (bodies.collision_shape.size() != n)
      bad("collision_shape", fmt::format("{} values for {} bodies; allowed: 0 (every body as its shape) or {}",
                                         bodies.collision_shape.size(), n, n));
    for (std::size_t i = 0; i < n; ++i)
      if (bodies.collision_shape[i] == CollisionShape::Sphere && !model.shapes[model.bodies[i].shape].mesh)
        bad("collision_shape", fmt::format("body {}: \"sphere\" on a box shape (a box cannot be collided as a "
                                           "sphere); allowed for a box: \"mesh\", \"convex_hull\", \"box\" (each the "
                                           "box itself)",
                                           i));
  }
  s.ref = std::make_unique<ReferenceGeometry>(model, bodies.collision_shape);
  for (std::size_t i = 0; i < bodies.collision_shape.size(); ++i) {
    const CollisionShape c = bodies.collision_shape[i];
    if (c == CollisionShape::Mesh) continue;
    auto& [count, gap] = s.declared[collision_shape_name(c)];
    ++count;
    gap = std::max(gap, s.ref->declared_gap(static_cast<std::uint32_t>(i)));
  }
  s.sat_settings.abs_m = tol.geometry_slack_m;
  s.sat_settings.rel = tol.sat_accept_rel;
}

PhysicsValidators::~PhysicsValidators() = default;

void PhysicsValidators::set_stop(std::function<bool()> stop) { impl_->stop = std::move(stop); }

void PhysicsValidators::set_threads(int threads) { impl_->threads = threads; }

void PhysicsValidators::set_episode_frames(std::int64_t first, std::int64_t last) {
  impl_->episode_first = first;
  impl_->episode_last = last;
}

const std::vector<Pair>* PhysicsValidators::flat_pairs() const {
  return impl_->flat_frame == impl_->last_frame ? &impl_->flat_dynamic : nullptr;
}

void PhysicsValidators::observe_episodes(const FrameRecord& rec) { impl_->advance_episodes(rec); }

bool PhysicsValidators::episodes_pending() const { return impl_->owned_open() > 0; }

void PhysicsValidators::observe(const FrameRecord& rec, bool checked) {
  Impl& s = *impl_;
  const std::size_t n = s.model->bodies.size();
  s.last_frame = rec.frame;
  s.flat_frame = -1;
  std::vector<Pose>& det = s.step_poses;
  const bool poses = !rec.x_det.empty() || rec.aabbs.size() == n;
  const bool pre_poses = !poses && rec.x_pre.size() == n;
  // Each body's pose, on the threads (every entry written: the memory of the last frame's
  // poses is not cleared first).
  if (poses || pre_poses)
    det.resize(n);
  else
    det.assign(n, Pose{});
  if (poses || pre_poses)
    parallel_items_on(n, loop_threads(s.threads, n, kParallelBodyBoxesFrom), s.stop, [&](std::size_t i, unsigned) {
      det[i] = poses ? detection_pose(*s.model, rec, i)
                     // No detection pose: the pre-step pose (its body frame) serves the contact-point lever arms.
                     : s.frame_pose(rec.x_pre[i], rec.q_pre.size() == n ? rec.q_pre[i] : Quat{},
                                    static_cast<std::uint32_t>(i));
    });
  PhysicsFrame f{rec, det, checked && poses, std::nullopt, std::nullopt, false, checked};
  s.measure_rows(f);
  if (f.geometry) s.spare_frame = std::move(f.geometry);  // its tables serve the next checked frame
}

}  // namespace octocd
