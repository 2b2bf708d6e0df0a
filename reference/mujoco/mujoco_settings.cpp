// MujocoSettings: the KEY=VALUE parser (mujoco_settings.hpp).
#include "octocd/mujoco_settings.hpp"
#include "octocd/adapter_rows.hpp"

#include <fmt/format.h>

#include <cmath>
#include <string>

#include "octocd/error.hpp"

namespace octocd {

namespace {

/// `value` as a decimal number (digits, sign, point, exponent only: no hex, inf or nan),
/// or false.
bool parse_decimal(const std::string& value, double& out) {
  if (value.empty() || value.find_first_not_of("0123456789+-.eE") != std::string::npos) return false;
  std::size_t used = 0;
  try {
    out = std::stod(value, &used);
  } catch (const std::exception&) {
    return false;
  }
  return used == value.size() && std::isfinite(out);
}

}  // namespace

const char* mujoco_cone_name(MujocoCone c) { return c == MujocoCone::Pyramidal ? "pyramidal" : "elliptic"; }

std::vector<std::string> mujoco_setting_names() { return {"iterations", "cone", "timeconst", "margin", "multiccd", "max_contacts"}; }

void set_mujoco_setting(MujocoSettings& s, const std::string& key, const std::string& value,
                        const std::string& where) {
  if (key == "iterations") {
    std::size_t used = 0;
    long n = -1;
    try {
      n = std::stol(value, &used);
    } catch (const std::exception&) {
      used = 0;
    }
    if (used != value.size() || value.empty() || n < 1 || n > 10000)
      throw InputError(fmt::format("{}: iterations='{}' is not allowed; allowed: an integer in [1, 10000] (MuJoCo's "
                                   "main solver iterations per step; its default 100)",
                                   where, value));
    s.iterations = static_cast<int>(n);
    return;
  }
  if (key == "max_contacts") {
    std::size_t used = 0;
    long n = -1;
    try {
      n = std::stol(value, &used);
    } catch (const std::exception&) {
      used = 0;
    }
    if (used != value.size() || value.empty() || n < 0 || n > 1000000)
      throw InputError(fmt::format("{}: max_contacts='{}' is not allowed; allowed: an integer in [0, 1000000] (MuJoCo's "
                                   "contact capacity; 0: 6 per dynamic body, at least 256, at most 1500)",
                                   where, value));
    s.max_contacts = static_cast<int>(n);
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
    double t = -1.0;
    if (!parse_decimal(value, t) || t < 0.0 || t > 1.0)
      throw InputError(fmt::format("{}: timeconst='{}' is not allowed; allowed: a decimal number of seconds in [0, 1] "
                                   "(0: 2 dt, the stiffest contact MuJoCo keeps)",
                                   where, value));
    s.timeconst = t;
    return;
  }
  if (key == "margin") {
    double m = -1.0;
    if (!parse_decimal(value, m) || m < 0.0 || m > 0.1)
      throw InputError(fmt::format("{}: margin='{}' is not allowed; allowed: a decimal number of metres in [0, 0.1] "
                                   "(contact rows reported up to this distance)",
                                   where, value));
    s.margin = m;
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
