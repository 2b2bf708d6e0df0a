/// \file broadphase_registry.cpp
/// broadphase_infos() and its look-ups, from the rows of octocd/broadphase_table.def.

#include "octocd/broadphase_registry.hpp"

#include <cstddef>

namespace octocd {

const std::vector<BroadPhaseInfo>& broadphase_infos() {
  static const std::vector<BroadPhaseInfo> infos = {
#define OCTOCD_BROADPHASE(ID, NAME, HOST, DEVICE, PAIRS, COST, SUMMARY)                              \
  BroadPhaseInfo{BroadPhaseId::ID,       NAME, BroadPhaseHost::HOST, BroadPhaseDevice::DEVICE, \
                 BroadPhasePairs::PAIRS, BroadPhaseCost::COST, SUMMARY},
#include "octocd/broadphase_table.def"
#undef OCTOCD_BROADPHASE
  };
  return infos;
}

const BroadPhaseInfo& broadphase_info(BroadPhaseId id) {
  return broadphase_infos()[static_cast<std::size_t>(id)];
}

const std::string& broadphase_name(BroadPhaseId id) { return broadphase_info(id).name; }

const BroadPhaseInfo* find_broadphase_info(const std::string& name) {
  for (const BroadPhaseInfo& info : broadphase_infos())
    if (info.name == name) return &info;
  return nullptr;
}

std::vector<std::string> every_broadphase_name() {
  return broadphase_names_where([](const BroadPhaseInfo&) { return true; });
}

std::string join_broadphase_names(const std::vector<std::string>& names) {
  std::string list;
  for (const std::string& s : names) list += (list.empty() ? "" : ", ") + s;
  return list;
}

}  // namespace octocd
