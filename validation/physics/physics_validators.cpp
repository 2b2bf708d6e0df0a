// The physics tier (SPEC 13): any engine judged on its posed shapes with FCL.
// (Skeleton: rows report n/a until the validators land.)
#include "octocd/physics.hpp"

#include <cmath>

#include <fmt/format.h>

#include "octocd/error.hpp"

namespace octocd {

const char* material_combine_name(MaterialCombine c) {
  switch (c) {
    case MaterialCombine::Product: return "product";
    case MaterialCombine::Min: return "min";
    case MaterialCombine::Max: return "max";
    case MaterialCombine::Average: return "average";
    case MaterialCombine::Geometric: return "geometric";
  }
  return "product";
}

double combine_material(MaterialCombine c, double a, double b) {
  switch (c) {
    case MaterialCombine::Product: return a * b;
    case MaterialCombine::Min: return a < b ? a : b;
    case MaterialCombine::Max: return a > b ? a : b;
    case MaterialCombine::Average: return 0.5 * (a + b);
    case MaterialCombine::Geometric: return std::sqrt(a * b);
  }
  return a * b;
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
  return b;
}

struct PhysicsValidators::Impl {
  const Model* model = nullptr;
  PhysicsBodies bodies;
  Tolerances tol;
  std::string label;
};

PhysicsValidators::PhysicsValidators(const Model& model, const PhysicsBodies& bodies, const Tolerances& tol,
                                     std::string label)
    : impl_(std::make_unique<Impl>()) {
  impl_->model = &model;
  impl_->bodies = bodies;
  impl_->tol = tol;
  impl_->label = std::move(label);
}

PhysicsValidators::~PhysicsValidators() = default;

void PhysicsValidators::observe(const FrameRecord& rec, bool checked) {
  (void)rec;
  (void)checked;
}

std::vector<ValidationResult> PhysicsValidators::results() const { return {}; }

}  // namespace octocd
