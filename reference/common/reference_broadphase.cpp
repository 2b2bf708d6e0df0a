/// \file reference_broadphase.cpp
/// Registry of the reference broadphases (Bullet, FCL) and the combined registry over
/// core and references (design.md section 5.1).

#include "octocd/reference_broadphase.hpp"

#include <algorithm>
#include <cmath>
#include <sstream>

#include "octocd/error.hpp"
#include "reference_detail.hpp"

namespace octocd {

namespace {

const std::vector<std::string>& bullet_names() {
  static const std::vector<std::string> names = {"bullet-dbvt", "bullet-sap"};
  return names;
}

const std::vector<std::string>& fcl_names() {
  static const std::vector<std::string> names = {"fcl-dynamic-aabb-tree", "fcl-sap",
                                                 "fcl-interval-tree", "fcl-spatial-hash",
                                                 "fcl-naive"};
  return names;
}

bool contains(const std::vector<std::string>& names, const std::string& name) {
  return std::find(names.begin(), names.end(), name) != names.end();
}

[[noreturn]] void throw_unknown(const std::string& name, const std::vector<std::string>& names) {
  std::string list;
  for (const std::string& s : names) list += (list.empty() ? "" : ", ") + s;
  throw InputError("broadphase.name: unknown broadphase '" + name + "'; allowed: " + list);
}

}  // namespace

std::vector<std::string> reference_broadphase_names() {
  std::vector<std::string> names = bullet_names();
  names.insert(names.end(), fcl_names().begin(), fcl_names().end());
  return names;
}

std::unique_ptr<BroadPhase> make_reference_broadphase(const BroadPhaseConfig& config,
                                                      const Aabb& domain) {
  if (contains(bullet_names(), config.name)) {
    return reference_detail::make_bullet_broadphase(config.name, domain);
  }
  if (contains(fcl_names(), config.name)) {
    if (!(std::isfinite(config.cell_size) && config.cell_size > 0.0f)) {
      std::ostringstream msg;
      msg << "broadphase.cell_size: " << config.cell_size
          << " is out of range (expected a finite number > 0, in m)";
      throw InputError(msg.str());
    }
    return reference_detail::make_fcl_broadphase(config.name, config.cell_size, domain);
  }
  throw_unknown(config.name, reference_broadphase_names());
}

std::vector<std::string> all_broadphase_names() {
  std::vector<std::string> names = broadphase_names();
  const std::vector<std::string> refs = reference_broadphase_names();
  names.insert(names.end(), refs.begin(), refs.end());
  return names;
}

std::unique_ptr<BroadPhase> make_any_broadphase(const BroadPhaseConfig& config,
                                                const Aabb& domain) {
  if (contains(broadphase_names(), config.name)) return make_broadphase(config, domain);
  if (contains(reference_broadphase_names(), config.name)) {
    return make_reference_broadphase(config, domain);
  }
  throw_unknown(config.name, all_broadphase_names());
}

}  // namespace octocd
