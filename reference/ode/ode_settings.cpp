// OdeSettings: the KEY=VALUE parser (ode_settings.hpp) and ODE's own defaults.
#include "octocd/ode_settings.hpp"
#include "octocd/adapter_rows.hpp"

#include <fmt/format.h>
#include <ode/ode.h>

#include <cmath>
#include <string>

#include "octocd/error.hpp"

#if !defined(dDOUBLE)
#error "octocd's ODE adapter needs ODE's double-precision build (dDOUBLE)"
#endif

namespace octocd {

namespace {

/// An integer in [lo, hi] from the whole of `value`, else InputError with `allowed`.
int parse_int(const std::string& key, const std::string& value, long lo, long hi, const std::string& where,
              const char* allowed) {
  std::size_t used = 0;
  long n = lo - 1;
  try {
    n = std::stol(value, &used);
  } catch (const std::exception&) {
    used = 0;
  }
  if (value.empty() || used != value.size() || n < lo || n > hi)
    throw InputError(fmt::format("{}: {}='{}' is not allowed; allowed: {}", where, key, value, allowed));
  return static_cast<int>(n);
}

/// A decimal number in [lo, hi] from the whole of `value` (no hex, inf or nan), else
/// InputError with `allowed`.
double parse_number(const std::string& key, const std::string& value, double lo, double hi, const std::string& where,
                    const char* allowed) {
  std::size_t used = 0;
  double x = std::nan("");
  const bool decimal = !value.empty() && value.find_first_not_of("0123456789+-.eE") == std::string::npos;
  try {
    if (decimal) x = std::stod(value, &used);
  } catch (const std::exception&) {
    used = 0;
  }
  if (!decimal || used != value.size() || !(x >= lo && x <= hi))
    throw InputError(fmt::format("{}: {}='{}' is not allowed; allowed: {}", where, key, value, allowed));
  return x;
}

}  // namespace

const char* ode_stepper_name(OdeStepper s) { return s == OdeStepper::QuickStep ? "quickstep" : "step"; }
const char* ode_friction_name(OdeFriction f) { return f == OdeFriction::Pyramid ? "pyramid" : "inscribed"; }

OdeSettings ode_library_defaults() {
  dInitODE2(0);
  OdeSettings s;
  dWorldID w = dWorldCreate();
  s.erp = static_cast<double>(dWorldGetERP(w));
  s.cfm = static_cast<double>(dWorldGetCFM(w));
  s.iterations = dWorldGetQuickStepNumIterations(w);
  dBodyID b = dBodyCreate(w);
  s.gyroscopic = dBodyGetGyroscopicMode(b) != 0;
  dWorldDestroy(w);  // destroys the body too
  return s;
}

std::vector<std::string> ode_setting_names() {
  return {"stepper", "iterations", "erp", "cfm", "contacts", "friction", "gyroscopic"};
}

void set_ode_setting(OdeSettings& s, const std::string& key, const std::string& value, const std::string& where) {
  if (key == "stepper") {
    if (value == "step") s.stepper = OdeStepper::Step;
    else if (value == "quickstep") s.stepper = OdeStepper::QuickStep;
    else
      throw InputError(fmt::format("{}: stepper='{}' is not allowed; allowed: step (dWorldStep, the Dantzig LCP), "
                                   "quickstep (dWorldQuickStep, iterations Gauss-Seidel sweeps)",
                                   where, value));
    return;
  }
  if (key == "iterations") {
    s.iterations = parse_int(key, value, 1, 10000, where,
                             "an integer in [1, 10000] (dWorldQuickStep's sweeps per step; ODE's default 20)");
    return;
  }
  if (key == "erp") {
    s.erp = parse_number(key, value, 0.0, 1.0, where, "a decimal number in [0, 1] (dWorldSetERP; ODE's default 0.2)");
    return;
  }
  if (key == "cfm") {
    s.cfm = parse_number(key, value, 0.0, 1.0, where,
                         "a decimal number in [0, 1] (dWorldSetCFM; ODE's default 1e-10 in double precision)");
    return;
  }
  if (key == "contacts") {
    s.max_contacts = parse_int(key, value, 1, 64, where, "an integer in [1, 64] (dCollide's contacts per pair)");
    return;
  }
  if (key == "friction") {
    if (value == "inscribed") s.friction = OdeFriction::Inscribed;
    else if (value == "pyramid") s.friction = OdeFriction::Pyramid;
    else
      throw InputError(fmt::format("{}: friction='{}' is not allowed; allowed: inscribed (mu / sqrt 2 per friction "
                                   "direction: inside the Coulomb cone), pyramid (mu per direction)",
                                   where, value));
    return;
  }
  if (key == "gyroscopic") {
    if (value == "true") s.gyroscopic = true;
    else if (value == "false") s.gyroscopic = false;
    else
      throw InputError(fmt::format("{}: gyroscopic='{}' is not allowed; allowed: true, false "
                                   "(dBodySetGyroscopicMode)",
                                   where, value));
    return;
  }
  std::string names;
  for (const std::string& n : ode_setting_names()) names += (names.empty() ? "" : ", ") + n;
  throw InputError(fmt::format("{}: unknown ode setting '{}'; allowed: {} (docs/engines.md)", where, key, names));
}

void apply_ode_settings(OdeSettings& s, const std::vector<std::string>& items, const std::string& where) {
  apply_setting_items(items, where, "stepper=quickstep",
                      [&](const std::string& k, const std::string& v) { set_ode_setting(s, k, v, where); });
}

}  // namespace octocd
