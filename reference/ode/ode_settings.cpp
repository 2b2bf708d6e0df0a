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

/// The ode engine's settings, one row a key.
template <>
const SettingTable<OdeSettings>& setting_table<OdeSettings>() {
  using T = SettingTable<OdeSettings>;
  static const T table{"ode", "docs/engines.md", "stepper=quickstep", {
      {"stepper",
       T::choice(
           &OdeSettings::stepper, "step", OdeStepper::Step, "quickstep", OdeStepper::QuickStep,
           "step (dWorldStep, the Dantzig LCP), quickstep (dWorldQuickStep, iterations Gauss-Seidel sweeps)")},
      {"iterations", T::integer(&OdeSettings::iterations, 1, 10000,
                                "an integer in [1, 10000] (dWorldQuickStep's sweeps per step; ODE's default 20)")},
      {"erp",
       T::number(&OdeSettings::erp, 0.0, 1.0, "a decimal number in [0, 1] (dWorldSetERP; ODE's default 0.2)")},
      {"cfm", T::number(&OdeSettings::cfm, 0.0, 1.0,
                        "a decimal number in [0, 1] (dWorldSetCFM; ODE's default 1e-10 in double precision)")},
      {"contacts",
       T::integer(&OdeSettings::max_contacts, 1, 64, "an integer in [1, 64] (dCollide's contacts per pair)")},
      {"friction", T::pyramid_friction(&OdeSettings::friction)},
      {"gyroscopic",
       T::choice(&OdeSettings::gyroscopic, "true", true, "false", false, "true, false (dBodySetGyroscopicMode)")},
  }};
  return table;
}

}  // namespace octocd
