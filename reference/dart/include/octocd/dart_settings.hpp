#pragma once
/// \file dart_settings.hpp
/// The settings of the DART engine (`dart`): which of DART's collision detectors finds the
/// contacts, how FCL takes boxes, which boxed LCP solver DART's constraint solver runs, its
/// contact constraint parameters and how friction is bounded. Set from C++ (DartWorld's
/// constructor) or as KEY=VALUE items (apply_settings); docs/engines.md, "dart", and
/// docs/settings.md list them with the DART parameter each one sets. Plain data: no DART
/// header is needed to use it.

#include <string>
#include <vector>

#include "octocd/adapter_rows.hpp"
#include "octocd/pyramid_friction.hpp"

namespace octocd {

/// Which DART collision detector finds the contacts (ConstraintSolver::setCollisionDetector).
enum class DartCollision {
  /// dart::collision::FCLCollisionDetector: boxes, triangle meshes (MeshShape as an FCL
  /// BVH of its triangles), so every octocd scene is expressible.
  Fcl,
  /// dart::collision::DARTCollisionDetector: DART's own detector (boxes: ODE's dBoxBox
  /// port, up to 4 points); it has no mesh shape, so a scene with a mesh is refused.
  Dart,
};

/// How FCLCollisionDetector takes a BoxShape (FCLCollisionDetector::setPrimitiveShapeType).
enum class DartFclBoxes {
  /// PRIMITIVE: fcl::Box with FCL's analytic box-box test (several points per pair).
  Primitive,
  /// MESH: a 12-triangle BVH of the box (DART's own default), collided as a mesh.
  Mesh,
};

/// Where each collision object enters FCL's dynamic AABB tree when the world is built.
enum class DartFclInsert {
  /// At the origin, as DART does (FCLCollisionObject starts at the identity): n bodies of
  /// one shape go in as n leaves with one AABB, a chain n deep, O(n^2) to build. The first
  /// step poses every object and rebalances the tree.
  Origin,
  /// At the body's pose (the object is posed when DART creates it): the tree is built from
  /// the bodies' AABBs. The first step's rebalanced tree differs from Origin's, so FCL
  /// reports the contacts in another order and the constraint solve differs in the last
  /// bits (a run is not bit for bit Origin's).
  Posed,
};

/// Which boxed LCP solver BoxedLcpConstraintSolver runs.
enum class DartLcp {
  /// DantzigBoxedLcpSolver (ODE's Dantzig pivoting solver) with PgsBoxedLcpSolver as the
  /// fallback when it fails: the constraint solver DART's World creates.
  Dantzig,
  /// PgsBoxedLcpSolver alone (projected Gauss-Seidel, DartSettings::iterations sweeps),
  /// no secondary solver.
  Pgs,
};

/// How a contact's two friction directions are bounded. DART's ContactConstraint gives
/// each direction the box |lambda_t| <= mu_shape lambda_n (a friction pyramid, findex),
/// mu_shape the smaller of the two shapes' DynamicsAspect friction coefficients
/// (mu_shape = mu_dir of PyramidFriction).
using DartFriction = PyramidFriction;

/// "fcl" or "dart".
const char* dart_collision_name(DartCollision c);
/// "primitive" or "mesh".
const char* dart_fcl_boxes_name(DartFclBoxes b);
/// "origin" or "posed".
const char* dart_fcl_insert_name(DartFclInsert i);
/// "dantzig" or "pgs".
const char* dart_lcp_name(DartLcp l);
/// "inscribed" or "pyramid".
inline const char* dart_friction_name(DartFriction f) { return pyramid_friction_name(f); }

/// The dart engine's settings. The defaults are what `octocd run --engine dart` runs:
/// DART's own defaults where DART has one, except `boxes` and `contacts` (below).
struct DartSettings {
  /// The collision detector (DartCollision); key `collision`, values fcl | dart.
  /// Default fcl (DART's World default; the one that takes meshes).
  DartCollision collision = DartCollision::Fcl;
  /// How FCL takes boxes (DartFclBoxes); key `boxes`, values primitive | mesh. Default
  /// primitive (DART's own default is mesh: a box collided as 12 triangles gets contacts
  /// on its triangles' intersections, not on its faces). Read only with collision=fcl.
  DartFclBoxes boxes = DartFclBoxes::Primitive;
  /// Where collision objects enter FCL's tree at set-up (DartFclInsert); key `insert`,
  /// values origin | posed. Default origin (DART's own). posed takes the FCL part of the
  /// set-up from O(n^2) to about O(n log n) (docs/engines.md, "dart", gives the figures);
  /// read only with collision=fcl.
  DartFclInsert insert = DartFclInsert::Origin;
  /// The boxed LCP solver (DartLcp); key `lcp`, values dantzig | pgs. Default dantzig
  /// (DART's World default, with PGS as its fallback).
  DartLcp lcp = DartLcp::Dantzig;
  /// Sweeps of the PGS solver (PgsBoxedLcpSolver::Option::mMaxIteration); key
  /// `iterations`, an integer in [1, 10000]. Default 30, DART's. Read by lcp=pgs and by
  /// the Dantzig solver's PGS fallback.
  int iterations = 30;
  /// Error reduction parameter (ContactConstraint::setErrorReductionParameter): the
  /// share of a contact's depth the next step's target velocity removes, erp depth / dt,
  /// capped at max_erv; key `erp`, a number in [0, 1]. Default 0.01, DART's.
  double erp = 0.01;
  /// The cap of that correction velocity (ContactConstraint::setMaxErrorReductionVelocity,
  /// m/s); key `max_erv`, a number in [0, 100]. Default 1e-3, DART's.
  double max_erv = 1e-3;
  /// Constraint force mixing (ContactConstraint::setConstraintForceMixing: every row's
  /// diagonal times 1 + cfm); key `cfm`, a number in [1e-9, 1]. Default 1e-5, DART's.
  double cfm = 1e-5;
  /// The friction bound (DartFriction); key `friction`, values inscribed | pyramid.
  /// Default inscribed (the friction vector stays in the Coulomb cone).
  DartFriction friction = DartFriction::Inscribed;
  /// Most contacts one step's collision detection may report
  /// (CollisionOption::maxNumContacts); key `contacts`, an integer in [1, 10000000].
  /// Default 200000 (DART's World asks for 1000 and silently drops the rest: a pile of
  /// 1000 bodies has more). A step that reaches the bound throws RuntimeError naming it.
  int max_contacts = 200000;
};

/// ERP, the correction velocity cap and CFM as the linked DART's ContactConstraint holds
/// them before anything sets them, and the PGS sweeps of a fresh PgsBoxedLcpSolver::Option;
/// the other fields as DartSettings: the library's defaults, which DartSettings' defaults
/// claim to be. (DART keeps ERP, the cap and CFM in process-wide statics; DartWorld sets
/// them for the duration of each step and puts the previous values back.)
DartSettings dart_library_defaults();

/// The dart engine's settings table, one row a key in the struct's order:
/// collision (fcl or dart), boxes (primitive or mesh), insert (origin or posed), lcp
/// (dantzig or pgs), iterations (an integer in [1, 10000]), erp (a decimal number in [0, 1]),
/// max_erv (in [0, 100]), cfm (in [1e-9, 1]), friction (inscribed or pyramid), contacts (an
/// integer in [1, 10000000]).
/// apply_settings(settings, items, where) (adapter_rows.hpp) sets a DartSettings from
/// "KEY=VALUE" items (`--dart KEY=VALUE`, repeatable), throwing InputError that names the
/// key, the value and what is allowed; setting_names<DartSettings>() lists the keys.
template <>
const SettingTable<DartSettings>& setting_table<DartSettings>();

}  // namespace octocd
