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


const char* ode_space_name(OdeSpace s) {
  switch (s) {
    case OdeSpace::Hash: return "hash";
    case OdeSpace::Sap: return "sap";
    case OdeSpace::QuadTree: return "quadtree";
    case OdeSpace::Auto: break;
  }
  return "auto";
}

OdeSpace ode_resolved_space(OdeSpace s, std::size_t bodies) {
  if (s != OdeSpace::Auto) return s;
  return bodies >= kOdeAutoSapBodies ? OdeSpace::Sap : OdeSpace::Hash;
}

int ode_quadtree_depth(std::size_t bodies) {
  int depth = 1;
  for (std::size_t leaves = 4; depth < 8 && leaves * 16 < bodies; leaves *= 4) ++depth;
  return depth;
}

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
      {"space",
       [](OdeSettings& s, const SettingValue& v) {
         for (const OdeSpace e : {OdeSpace::Hash, OdeSpace::Sap, OdeSpace::QuadTree, OdeSpace::Auto})
           if (v.value == ode_space_name(e)) {
             s.space = e;
             return;
           }
         v.not_allowed(
             "hash (dHashSpace), sap (dSweepAndPruneSpace), quadtree (dQuadTreeSpace over the domain), auto (hash "
             "below 10000 bodies, sap from there)");
       }},
  }};
  return table;
}

}  // namespace octocd
