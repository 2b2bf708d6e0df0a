// BulletSettings: the KEY=VALUE parser the CLI and Python share (bullet_settings.hpp).
#include "octocd/bullet_settings.hpp"
#include "octocd/adapter_rows.hpp"

#include <fmt/format.h>

#include <string>

#include "octocd/error.hpp"

namespace octocd {

const char* bullet_shape_name(BulletShape s) { return s == BulletShape::Box ? "box" : "hull"; }

std::vector<std::string> bullet_setting_names() { return {"shape", "iterations"}; }

void set_bullet_setting(BulletSettings& s, const std::string& key, const std::string& value,
                        const std::string& where) {
  if (key == "shape") {
    if (value == "hull") s.shape = BulletShape::Hull;
    else if (value == "box") s.shape = BulletShape::Box;
    else
      throw InputError(fmt::format("{}: shape='{}' is not allowed; allowed: hull (convex hulls of dynamic meshes, "
                                   "triangle meshes of static ones), box (boxes equal to the AABBs)",
                                   where, value));
    return;
  }
  if (key == "iterations") {
    s.solver_iterations = setting_integer(key, value, 1, 10000, where,
                                          "an integer in [1, 10000] (the sequential-impulse solver's iterations per "
                                          "step; Bullet's default 10)");
    return;
  }
  std::string names;
  for (const std::string& n : bullet_setting_names()) names += (names.empty() ? "" : ", ") + n;
  throw InputError(fmt::format("{}: unknown bullet setting '{}'; allowed: {} (docs/settings.md)", where, key, names));
}

void apply_bullet_settings(BulletSettings& s, const std::vector<std::string>& items, const std::string& where) {
  apply_setting_items(items, where, "shape=box",
                      [&](const std::string& k, const std::string& v) { set_bullet_setting(s, k, v, where); });
}

}  // namespace octocd
