// BulletSettings: the KEY=VALUE parser the CLI and Python share (bullet_settings.hpp).
#include "octocd/bullet_settings.hpp"
#include "octocd/adapter_rows.hpp"

#include <fmt/format.h>

#include <string>

#include "octocd/error.hpp"

namespace octocd {

const char* bullet_shape_name(BulletShape s) { return s == BulletShape::Box ? "box" : "hull"; }

/// The bullet engine's settings, one row a key.
template <>
const SettingTable<BulletSettings>& setting_table<BulletSettings>() {
  using T = SettingTable<BulletSettings>;
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

}  // namespace octocd
