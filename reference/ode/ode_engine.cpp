// The ode engine's registration (engine_entry.hpp): compiled into octocd_engines when
// reference/ode is built (octocd_register_engine in this folder's CMakeLists.txt).
#include "octocd/engine_entry.hpp"
#include "octocd/ode_world.hpp"

namespace octocd {

EngineHooks ode_engine_hooks() {
  return reference_engine_hooks<OdeWorld, OdeSettings, &apply_settings<OdeSettings>, &setting_names<OdeSettings>>();
}

}  // namespace octocd
