// The mujoco engine's registration (engine_entry.hpp): compiled into octocd_engines when
// reference/mujoco is built (octocd_register_engine in this folder's CMakeLists.txt).
#include "octocd/engine_entry.hpp"
#include "octocd/mujoco_world.hpp"

namespace octocd {

EngineHooks mujoco_engine_hooks() {
  return reference_engine_hooks<MujocoWorld, MujocoSettings, &apply_settings<MujocoSettings>, &setting_names<MujocoSettings>>();
}

}  // namespace octocd
