// MujocoSettings: the KEY=VALUE parser (mujoco_settings.hpp).
#include "octocd/mujoco_settings.hpp"
#include "octocd/adapter_rows.hpp"

#include <fmt/format.h>

#include <cmath>
#include <string>

#include "octocd/error.hpp"

namespace octocd {


const char* mujoco_cone_name(MujocoCone c) { return c == MujocoCone::Pyramidal ? "pyramidal" : "elliptic"; }

std::vector<std::string> mujoco_setting_names() { return {"iterations", "cone", "timeconst", "margin", "multiccd", "max_contacts"}; }

void set_mujoco_setting(MujocoSettings& s, const std::string& key, const std::string& value,
                        const std::string& where) {
  if (key == "iterations") {
    s.iterations = setting_integer(key, value, 1, 10000, where,
                                   "an integer in [1, 10000] (MuJoCo's main solver iterations per step; its default "
                                   "100)");
    return;
  }
  if (key == "max_contacts") {
    s.max_contacts = setting_integer(key, value, 0, 1000000, where,
                                     "an integer in [0, 1000000] (MuJoCo's contact capacity; 0: 6 per dynamic body, "
                                     "at least 256, at most 1500)");
    return;
  }
  if (key == "cone") {
    if (value == "elliptic") s.cone = MujocoCone::Elliptic;
    else if (value == "pyramidal") s.cone = MujocoCone::Pyramidal;
    else
      throw InputError(fmt::format("{}: cone='{}' is not allowed; allowed: elliptic (the Coulomb cone), pyramidal "
                                   "(MuJoCo's default)",
                                   where, value));
    return;
  }
  if (key == "timeconst") {
    s.timeconst = setting_number(key, value, 0.0, 1.0, where,
                                 "a decimal number of seconds in [0, 1] (0: 2 dt, the stiffest contact MuJoCo keeps)");
    return;
  }
  if (key == "margin") {
    s.margin = setting_number(key, value, 0.0, 0.1, where,
                              "a decimal number of metres in [0, 0.1] (contact rows reported up to this distance)");
    return;
  }
  if (key == "multiccd") {
    if (value == "on") s.multiccd = true;
    else if (value == "off") s.multiccd = false;
    else
      throw InputError(fmt::format("{}: multiccd='{}' is not allowed; allowed: on (several contact points per convex "
                                   "pair), off (MPR's one point)",
                                   where, value));
    return;
  }
  std::string names;
  for (const std::string& n : mujoco_setting_names()) names += (names.empty() ? "" : ", ") + n;
  throw InputError(fmt::format("{}: unknown mujoco setting '{}'; allowed: {} (docs/engines.md)", where, key, names));
}

void apply_mujoco_settings(MujocoSettings& s, const std::vector<std::string>& items, const std::string& where) {
  apply_setting_items(items, where, "cone=pyramidal",
                      [&](const std::string& k, const std::string& v) { set_mujoco_setting(s, k, v, where); });
}

}  // namespace octocd
