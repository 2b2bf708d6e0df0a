// BulletSettings: the KEY=VALUE parser the CLI and Python share (bullet_settings.hpp).
#include "octocd/bullet_settings.hpp"
#include "octocd/adapter_rows.hpp"

#include <fmt/format.h>

#include <string>

#include "octocd/error.hpp"

namespace octocd {

const char* bullet_shape_name(BulletShape s) { return s == BulletShape::Box ? "box" : "hull"; }

namespace {

using T = SettingTable<BulletSettings>;

/// The bullet engine's settings, one row a key.
const T& bullet_table() {
  static const T table{"bullet", "docs/settings.md", "shape=box", {
      {"shape", T::choice(&BulletSettings::shape, "hull", BulletShape::Hull, "box", BulletShape::Box,
                          "hull (convex hulls of dynamic meshes, triangle meshes of static ones), box (boxes equal "
                          "to the AABBs)")},
      {"iterations",
       T::integer(
           &BulletSettings::solver_iterations, 1, 10000,
           "an integer in [1, 10000] (the sequential-impulse solver's iterations per step; Bullet's default 10)")},
  }};
  return table;
}

}  // namespace

std::vector<std::string> bullet_setting_names() { return bullet_table().names(); }

void set_bullet_setting(BulletSettings& s, const std::string& key, const std::string& value,
                        const std::string& where) {
  bullet_table().set(s, key, value, where);
}

void apply_bullet_settings(BulletSettings& s, const std::vector<std::string>& items, const std::string& where) {
  bullet_table().apply(s, items, where);
}

}  // namespace octocd
