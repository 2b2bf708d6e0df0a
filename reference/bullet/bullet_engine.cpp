// The bullet engine's registration (engine_entry.hpp): compiled into octocd_engines
// (octocd_register_engine in reference/CMakeLists.txt).
#include "octocd/engine_entry.hpp"
#include "octocd/bullet_world.hpp"

namespace octocd {

EngineHooks bullet_engine_hooks() {
  EngineHooks h;
  h.make = [](const std::shared_ptr<const Model>& model, const EngineItems& items,
              const std::string& where) -> std::unique_ptr<Engine> {
    BulletSettings s;
    apply_settings(s, items, where);
    return std::make_unique<BulletWorld>(model, model->initial, BulletOptions(), s);
  };
  h.setting_names = &setting_names<BulletSettings>;
  h.check_settings = [](const EngineItems& items, const std::string& where) {
    BulletSettings s;
    apply_settings(s, items, where);
  };
  h.settings_help =
      "shape=hull: convex hulls of dynamic meshes, triangle meshes of static ones, the default; shape=box: boxes "
      "equal to the AABBs";
  return h;
}

}  // namespace octocd
