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
    s.iterations = setting_integer(key, value, 1, 10000, where,
                             "an integer in [1, 10000] (dWorldQuickStep's sweeps per step; ODE's default 20)");
    return;
  }
  if (key == "erp") {
    s.erp = setting_number(key, value, 0.0, 1.0, where, "a decimal number in [0, 1] (dWorldSetERP; ODE's default 0.2)");
    return;
  }
  if (key == "cfm") {
    s.cfm = setting_number(key, value, 0.0, 1.0, where,
                         "a decimal number in [0, 1] (dWorldSetCFM; ODE's default 1e-10 in double precision)");
    return;
  }
  if (key == "contacts") {
    s.max_contacts = setting_integer(key, value, 1, 64, where, "an integer in [1, 64] (dCollide's contacts per pair)");
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
