#pragma once
/// \file physics.hpp
/// The physics tier of the validators (SPEC 13, ARCHITECTURE.md seam 3): judges any
/// engine, rotating or not, with any solver and any broadphase, on the true geometry of
/// its posed shapes (FCL), never on octocd's own response model. The model tier
/// (validation.hpp: Eq. 14 contraction, averaged corrections, the applied-state
/// re-derivation, midphase completeness, analytic scenes, Bullet dynamics) is apart.
///
/// Rows (each ValidationResult has tier Physics):
///  1. `broadphase-completeness`: every pair with a dynamic body whose posed shapes are
///     closer than the contact margin is among the engine's candidate pairs; extra pairs
///     are allowed and counted (candidates per true pair). An engine that declares an
///     exact AABB broadphase is also held to set equality with `flat` on its world AABBs.
///  2. `contact-completeness`: every pair penetrating deeper than a tolerance has at
///     least one contact; a contact on a pair farther apart than the margin is a false
///     contact.
///  3. `contact-geometry`: per contact, the angle between the engine's normal and FCL's
///     (EPA on penetrating pairs, nearest points otherwise) and the depth against FCL's.
///  4. `penetration`: the largest true penetration over the run, after a settling window.
///  5. `friction`: |J_t| <= mu J_n per contact row; a friction impulse never raises the
///     relative tangential speed at the contact point (v + w x r).
///  6. `conservation`: on isolated dynamic groups (no static contact in the step), linear
///     momentum changes by m g dt only, angular momentum about the group's centre of mass
///     is kept, kinetic energy (translational + rotational) does not rise beyond gravity's
///     work when restitution <= 1.

#include <array>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "octocd/engine.hpp"
#include "octocd/validation.hpp"

namespace octocd {

/// How a pair's friction coefficient or restitution is made from the two bodies' values.
enum class MaterialCombine {
  Product,    ///< a * b (Bullet's btManifoldResult default)
  Min,        ///< min(a, b)
  Max,        ///< max(a, b)
  Average,    ///< (a + b) / 2 (PhysX's default)
  Geometric,  ///< sqrt(a * b)
};
/// "product", "min", "max", "average", "geometric".
const char* material_combine_name(MaterialCombine c);
/// The pair's value of a and b under rule c.
double combine_material(MaterialCombine c, double a, double b);

/// Which geometry an engine's contacts are computed on (what its normals and depths are
/// judged against).
enum class ContactGeometry {
  /// The posed shapes themselves (meshes, boxes): any engine's default.
  Shape,
  /// The bodies' world AABBs: octocd's SPEC 6 response resolves every contact on the
  /// two world AABBs (Eq. 9-10), so its normal is an AABB axis. The angle to the posed
  /// shapes' normal is then reported as a figure, not judged.
  Aabb,
};

/// What the physics tier knows of the bodies beyond the Model (shapes, local boxes,
/// inverse masses): inertia, materials and what the engine declares of itself.
struct PhysicsBodies {
  /// Body-frame inertia tensor per body (kg m^2, symmetric positive definite; row-major
  /// 3x3). Empty: derived from the local AABB as a solid box of the body's mass
  /// (m/12 (b^2 + c^2), ...), as Bullet's convex shapes do. Unused for static bodies.
  std::vector<std::array<double, 9>> inertia;
  /// Per-body friction coefficient and restitution (>= 0). Empty: `mu` and
  /// `restitution` for every pair.
  std::vector<float> body_friction, body_restitution;
  /// Pair friction coefficient and restitution when no per-body values are given.
  double mu = 0.6;
  double restitution = 0.5;
  /// How per-body values combine into a pair's.
  MaterialCombine combine = MaterialCombine::Product;
  /// Contact margin (m, >= 0): contacts are expected up to this distance (Bullet's
  /// contact breaking threshold, PhysX's contact offset); a contact on a pair farther
  /// apart is a false contact. octocd's engines: the pair's theta (vertex proximity,
  /// SPEC 5.3), given by `theta_margin`.
  double contact_margin = 0.02;
  /// Use the model's pair theta (Model::theta) as the contact margin (octocd's engines).
  bool theta_margin = false;
  /// The engine declares an exact AABB broadphase (its candidate pairs are exactly the
  /// overlapping world AABBs, Eq. 6): also held to set equality with `flat`.
  bool broadphase_exact = false;
  /// What the engine's contact normals and depths are computed on.
  ContactGeometry contact_geometry = ContactGeometry::Shape;
  /// The scene's slop (m, SPEC 6 delta): the penetration bound is a multiple of it.
  double slop = 0.001;
};

/// What octocd's own engines (cpu, cuda) declare of themselves: mu = the scene's
/// response.mu_static, restitution = response.restitution, the pair's theta as the contact
/// margin (vertex proximity, SPEC 5.3), an exact AABB broadphase (SPEC 5.1), contacts
/// resolved on the world AABBs (SPEC 6), slop = response.slop (delta). Inertia empty
/// (derived; unused: the records are translation-only).
PhysicsBodies octocd_physics_bodies(const Model& model);

/// Physics-tier validators, fed one FrameRecord at a time (octocd's engines, another
/// engine through octocd/external.hpp, or an external trace v1/v2).
class PhysicsValidators {
 public:
  /// Validators for records of bodies described by `model` (shapes, local boxes in the
  /// body frame, inverse masses; not owned, must outlive this object) and `bodies`.
  /// `label` names the engine in details ("engine 'bullet'"). Builds FCL geometry of
  /// every distinct shape. Throws InputError naming the field when `bodies` has the wrong
  /// sizes or values.
  PhysicsValidators(const Model& model, const PhysicsBodies& bodies, const Tolerances& tol, std::string label);
  ~PhysicsValidators();
  PhysicsValidators(const PhysicsValidators&) = delete;
  PhysicsValidators& operator=(const PhysicsValidators&) = delete;

  /// Judges one step. The record is trusted (callers with data from outside check it
  /// first: check_frame_record). `checked` runs the costly rows (broadphase and contact
  /// completeness, contact geometry) on this frame; friction and conservation run on
  /// every frame that has states.
  void observe(const FrameRecord& rec, bool checked);

  /// The six rows so far, tier Physics, each saying how many items it judged.
  std::vector<ValidationResult> results() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

/// The detection pose of body i in `rec` (FrameRecord::x_det / q_det, or octocd's rule:
/// world AABB minus local box, identity orientation).
Pose detection_pose(const Model& model, const FrameRecord& rec, std::size_t i);

}  // namespace octocd
