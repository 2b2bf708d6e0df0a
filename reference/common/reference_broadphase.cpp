/// \file reference_broadphase.cpp
/// The factories of the reference broadphases (Bullet, FCL) and of every CPU broadphase,
/// by the rows of octocd/broadphase_table.def (design.md section 5.1).

#include "octocd/reference_broadphase.hpp"

#include <cmath>
#include <sstream>

#include "octocd/error.hpp"
#include "reference_detail.hpp"

namespace octocd {

namespace {

bool is_reference(const BroadPhaseInfo& b) {
  return b.host == BroadPhaseHost::bullet || b.host == BroadPhaseHost::fcl;
}

[[noreturn]] void throw_unknown(const std::string& name, const std::vector<std::string>& names) {
  throw InputError("broadphase.name: unknown broadphase '" + name + "'; allowed: " + join_broadphase_names(names));
}

}  // namespace

std::vector<std::string> reference_broadphase_names() { return broadphase_names_where(is_reference); }

std::unique_ptr<BroadPhase> make_reference_broadphase(const BroadPhaseConfig& config,
                                                      const Aabb& domain) {
  const BroadPhaseInfo* info = find_broadphase_info(config.name);
  if (info && info->host == BroadPhaseHost::bullet) {
    return reference_detail::make_bullet_broadphase(info->id, domain);
  }
  if (info && info->host == BroadPhaseHost::fcl) {
    if (!(std::isfinite(config.cell_size) && config.cell_size > 0.0f)) {
      std::ostringstream msg;
      msg << "broadphase.cell_size: " << config.cell_size
          << " is out of range (expected a finite number > 0, in m)";
      throw InputError(msg.str());
    }
    return reference_detail::make_fcl_broadphase(info->id, config.cell_size, domain);
  }
  throw_unknown(config.name, reference_broadphase_names());
}

std::vector<std::string> all_broadphase_names() {
  return broadphase_names_where([](const BroadPhaseInfo& b) { return b.on_cpu(); });
}

std::unique_ptr<BroadPhase> make_any_broadphase(const BroadPhaseConfig& config,
                                                const Aabb& domain) {
  const BroadPhaseInfo* info = find_broadphase_info(config.name);
  if (info && info->host == BroadPhaseHost::core) return make_broadphase(config, domain);
  if (info && is_reference(*info)) return make_reference_broadphase(config, domain);
  throw_unknown(config.name, all_broadphase_names());
}

}  // namespace octocd
