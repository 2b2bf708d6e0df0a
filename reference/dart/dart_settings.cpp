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
const char* dart_lcp_name(DartLcp l) { return l == DartLcp::Pgs ? "pgs" : "dantzig"; }
const char* dart_friction_name(DartFriction f) { return f == DartFriction::Pyramid ? "pyramid" : "inscribed"; }

DartSettings dart_library_defaults() {
  using dart::constraint::ContactConstraint;
  DartSettings s;
  s.erp = ContactConstraint::getErrorReductionParameter();
  s.max_erv = ContactConstraint::getMaxErrorReductionVelocity();
  s.cfm = ContactConstraint::getConstraintForceMixing();
  s.iterations = dart::constraint::PgsBoxedLcpSolver::Option().mMaxIteration;
  return s;
}

std::vector<std::string> dart_setting_names() {
  return {"collision", "boxes", "lcp", "iterations", "erp", "max_erv", "cfm", "friction", "contacts"};
}

namespace {

/// One of two names: the first sets `a`, the second `b`; otherwise InputError listing both.
template <class E>
E choose(const std::string& key, const std::string& value, const char* name_a, E a, const char* name_b, E b,
         const std::string& where, const std::string& allowed) {
  if (value == name_a) return a;
  if (value == name_b) return b;
  throw InputError(fmt::format("{}: {}='{}' is not allowed; allowed: {}", where, key, value, allowed));
}

}  // namespace

void set_dart_setting(DartSettings& s, const std::string& key, const std::string& value, const std::string& where) {
  if (key == "collision") {
    s.collision = choose(key, value, "fcl", DartCollision::Fcl, "dart", DartCollision::Dart, where,
                         "fcl (FCLCollisionDetector: boxes and meshes), dart (DARTCollisionDetector: boxes only)");
    return;
  }
  if (key == "boxes") {
    s.boxes = choose(key, value, "primitive", DartFclBoxes::Primitive, "mesh", DartFclBoxes::Mesh, where,
                     "primitive (fcl::Box, FCL's box-box test), mesh (a 12-triangle BVH, DART's default)");
    return;
  }
  if (key == "lcp") {
    s.lcp = choose(key, value, "dantzig", DartLcp::Dantzig, "pgs", DartLcp::Pgs, where,
                   "dantzig (DantzigBoxedLcpSolver, PGS fallback), pgs (PgsBoxedLcpSolver, iterations sweeps)");
    return;
  }
  if (key == "iterations") {
    s.iterations = setting_integer(key, value, 1, 10000, where,
                                   "an integer in [1, 10000] (PgsBoxedLcpSolver's sweeps; DART's default 30)");
    return;
  }
  if (key == "erp") {
    s.erp = setting_number(key, value, 0.0, 1.0, where,
                           "a decimal number in [0, 1] (ContactConstraint::setErrorReductionParameter; DART's "
                           "default 0.01)");
    return;
  }
  if (key == "max_erv") {
    s.max_erv = setting_number(key, value, 0.0, 100.0, where,
                               "a decimal number in [0, 100] m/s (ContactConstraint::setMaxErrorReductionVelocity; "
                               "DART's default 1e-3)");
    return;
  }
  if (key == "cfm") {
    s.cfm = setting_number(key, value, 1e-9, 1.0, where,
                           "a decimal number in [1e-9, 1] (ContactConstraint::setConstraintForceMixing; DART's "
                           "default 1e-5)");
    return;
  }
  if (key == "friction") {
    s.friction = choose(key, value, "inscribed", DartFriction::Inscribed, "pyramid", DartFriction::Pyramid, where,
                        "inscribed (mu / sqrt 2 per friction direction: inside the Coulomb cone), pyramid (mu per "
                        "direction)");
    return;
  }
  if (key == "contacts") {
    s.max_contacts = setting_integer(key, value, 1, 10000000, where,
                                     "an integer in [1, 10000000] (CollisionOption::maxNumContacts per step)");
    return;
  }
  std::string names;
  for (const std::string& n : dart_setting_names()) names += (names.empty() ? "" : ", ") + n;
  throw InputError(fmt::format("{}: unknown dart setting '{}'; allowed: {} (docs/engines.md)", where, key, names));
}

void apply_dart_settings(DartSettings& s, const std::vector<std::string>& items, const std::string& where) {
  apply_setting_items(items, where, "lcp=pgs",
                      [&](const std::string& k, const std::string& v) { set_dart_setting(s, k, v, where); });
}

}  // namespace octocd
