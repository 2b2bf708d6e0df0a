// The dart engine's registration (engine_entry.hpp): compiled into octocd_engines when
// reference/dart is built (octocd_register_engine in this folder's CMakeLists.txt).
#include "octocd/engine_entry.hpp"
#include "octocd/dart_world.hpp"

namespace octocd {

EngineHooks dart_engine_hooks() {
  return reference_engine_hooks<DartWorld, DartSettings, &apply_settings<DartSettings>, &setting_names<DartSettings>>();
}

}  // namespace octocd
