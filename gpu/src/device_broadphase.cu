// make_device_broadphase (device_broadphase.hpp): the device factory of a broadphase by
// its row of octocd/broadphase_table.def. Host code only.
#include <cstddef>
#include <string>

#include <fmt/format.h>

#include "device_broadphase.hpp"
#include "octocd/broadphase_registry.hpp"
#include "octocd/cuda_world.hpp"
#include "octocd/error.hpp"

namespace octocd {
namespace gpu {

namespace {

/// A device factory of a row of octocd/broadphase_table.def.
using DeviceFactory = std::unique_ptr<DeviceBroadPhase> (*)(const BroadPhaseConfig&, const Aabb&, DeviceUse);

/// The device factory of every row, in the table's order (nullptr unless its device is `seam`).
#define OCTOCD_DEVICE_ENTRY_none(ID) nullptr
#define OCTOCD_DEVICE_ENTRY_step(ID) nullptr
#define OCTOCD_DEVICE_ENTRY_seam(ID) &make_device_broadphase_##ID
constexpr DeviceFactory kDeviceFactories[] = {
#define OCTOCD_BROADPHASE(ID, NAME, HOST, DEVICE, PAIRS, COST, SUMMARY) OCTOCD_DEVICE_ENTRY_##DEVICE(ID),
#include "octocd/broadphase_table.def"
#undef OCTOCD_BROADPHASE
};

}  // namespace

std::unique_ptr<DeviceBroadPhase> make_device_broadphase(const BroadPhaseConfig& config, const Aabb& domain,
                                                         DeviceUse use) {
  if (const BroadPhaseInfo* info = find_broadphase_info(config.name)) {
    if (const DeviceFactory make = kDeviceFactories[static_cast<std::size_t>(info->id)]) return make(config, domain, use);
  }
  throw InputError(fmt::format("broadphase.name: '{}' is not available on the cuda engine; allowed there: {}",
                               config.name, join_broadphase_names(cuda_broadphase_names())));
}

}  // namespace gpu
}  // namespace octocd
