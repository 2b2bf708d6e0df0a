// MujocoSettings: the KEY=VALUE parser (mujoco_settings.hpp).
#include "octocd/mujoco_settings.hpp"
#include "octocd/adapter_rows.hpp"

#include <fmt/format.h>

#include <cmath>
#include <string>

#include "octocd/error.hpp"

namespace octocd {


const char* mujoco_cone_name(MujocoCone c) { return c == MujocoCone::Pyramidal ? "pyramidal" : "elliptic"; }

/// The mujoco engine's settings, one row a key.
template <>
const SettingTable<MujocoSettings>& setting_table<MujocoSettings>() {
  using T = SettingTable<MujocoSettings>;
  static const T table{"mujoco", "docs/engines.md", "cone=pyramidal", {
      {"iterations",
       T::integer(&MujocoSettings::iterations, 1, 10000,
                  "an integer in [1, 10000] (MuJoCo's main solver iterations per step; its default 100)")},
      {"cone", T::choice(&MujocoSettings::cone, "elliptic", MujocoCone::Elliptic, "pyramidal",
                         MujocoCone::Pyramidal, "elliptic (the Coulomb cone), pyramidal (MuJoCo's default)")},
      {"timeconst",
       T::number(&MujocoSettings::timeconst, 0.0, 1.0,
                 "a decimal number of seconds in [0, 1] (0: 2 dt, the stiffest contact MuJoCo keeps)")},
      {"margin", T::number(&MujocoSettings::margin, 0.0, 0.1,
                           "a decimal number of metres in [0, 0.1] (contact rows reported up to this distance)")},
      {"multiccd", T::choice(&MujocoSettings::multiccd, "on", true, "off", false,
                             "on (several contact points per convex pair), off (MPR's one point)")},
      {"max_contacts",
       T::integer(&MujocoSettings::max_contacts, 0, 1000000,
                  "an integer in [0, 1000000] (MuJoCo's contact capacity; 0: 6 per dynamic body, at "
                  "least 256, at most 1500)")},
  }};
  return table;
}

}  // namespace octocd
