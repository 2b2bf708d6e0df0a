// DartSettings: the KEY=VALUE parser (dart_settings.hpp) and DART's own defaults.
#include "octocd/dart_settings.hpp"
#include "octocd/adapter_rows.hpp"

#include <dart/constraint/ContactConstraint.hpp>
#include <dart/constraint/PgsBoxedLcpSolver.hpp>
#include <fmt/format.h>

#include <string>

#include "octocd/error.hpp"

namespace octocd {

const char* dart_collision_name(DartCollision c) { return c == DartCollision::Dart ? "dart" : "fcl"; }
const char* dart_fcl_boxes_name(DartFclBoxes b) { return b == DartFclBoxes::Mesh ? "mesh" : "primitive"; }
const char* dart_fcl_insert_name(DartFclInsert i) { return i == DartFclInsert::Origin ? "origin" : "posed"; }
const char* dart_lcp_name(DartLcp l) { return l == DartLcp::Pgs ? "pgs" : "dantzig"; }

DartSettings dart_library_defaults() {
  using dart::constraint::ContactConstraint;
  DartSettings s;
  s.erp = ContactConstraint::getErrorReductionParameter();
  s.max_erv = ContactConstraint::getMaxErrorReductionVelocity();
  s.cfm = ContactConstraint::getConstraintForceMixing();
  s.iterations = dart::constraint::PgsBoxedLcpSolver::Option().mMaxIteration;
  return s;
}

/// The dart engine's settings, one row a key.
template <>
const SettingTable<DartSettings>& setting_table<DartSettings>() {
  using T = SettingTable<DartSettings>;
  static const T table{"dart", "docs/engines.md", "lcp=pgs", {
      {"collision",
       T::choice(&DartSettings::collision, "fcl", DartCollision::Fcl, "dart", DartCollision::Dart,
                 "fcl (FCLCollisionDetector: boxes and meshes), dart (DARTCollisionDetector: boxes only)")},
      {"boxes", T::choice(&DartSettings::boxes, "primitive", DartFclBoxes::Primitive, "mesh", DartFclBoxes::Mesh,
                          "primitive (fcl::Box, FCL's box-box test), mesh (a 12-triangle BVH, DART's default)")},
      {"insert", T::choice(&DartSettings::insert, "origin", DartFclInsert::Origin, "posed", DartFclInsert::Posed,
                           "origin (each collision object enters FCL's tree at the origin, DART's own), posed (at "
                           "its body's pose: a faster set-up, contacts in another order)")},
      {"lcp",
       T::choice(&DartSettings::lcp, "dantzig", DartLcp::Dantzig, "pgs", DartLcp::Pgs,
                 "dantzig (DantzigBoxedLcpSolver, PGS fallback), pgs (PgsBoxedLcpSolver, iterations sweeps)")},
      {"iterations", T::integer(&DartSettings::iterations, 1, 10000,
                                "an integer in [1, 10000] (PgsBoxedLcpSolver's sweeps; DART's default 30)")},
      {"erp",
       T::number(
           &DartSettings::erp, 0.0, 1.0,
           "a decimal number in [0, 1] (ContactConstraint::setErrorReductionParameter; DART's default 0.01)")},
      {"max_erv", T::number(&DartSettings::max_erv, 0.0, 100.0,
                            "a decimal number in [0, 100] m/s (ContactConstraint::setMaxErrorReductionVelocity; "
                            "DART's default 1e-3)")},
      {"cfm",
       T::number(
           &DartSettings::cfm, 1e-9, 1.0,
           "a decimal number in [1e-9, 1] (ContactConstraint::setConstraintForceMixing; DART's default 1e-5)")},
      {"friction", T::pyramid_friction(&DartSettings::friction)},
      {"contacts", T::integer(&DartSettings::max_contacts, 1, 10000000,
                              "an integer in [1, 10000000] (CollisionOption::maxNumContacts per step)")},
  }};
  return table;
}

}  // namespace octocd
