#pragma once
/// \file broadphase_registry.hpp
/// The broadphases octocd knows and what each promises: the one place that knows a
/// broadphase by its name, generated from the rows of octocd/broadphase_table.def (design.md
/// section 5.1). Callers ask a BroadPhaseInfo for a fact (where it runs, what it promises)
/// and name a particular broadphase by its BroadPhaseId, never by a string; a house test
/// (tests/house/broadphase_names.cmake) keeps it so. The factories read the same rows:
/// make_broadphase (core), make_any_broadphase (octocd/reference_broadphase.hpp), the
/// device factory and footprint of the cuda engine (gpu/src/device_broadphase.hpp,
/// cuda_device_bytes_needed).

#include <string>
#include <vector>

namespace octocd {

/// One identifier per row of broadphase_table.def, in its order.
enum class BroadPhaseId {
#define OCTOCD_BROADPHASE(ID, NAME, HOST, DEVICE, PAIRS, COST, SUMMARY) ID,
#include "octocd/broadphase_table.def"
#undef OCTOCD_BROADPHASE
};

/// Which library builds a broadphase on the CPU.
enum class BroadPhaseHost {
  core,    ///< octocd_core (make_broadphase)
  bullet,  ///< Bullet, in octocd_reference (make_reference_broadphase)
  fcl,     ///< FCL, in octocd_reference (make_reference_broadphase)
  none     ///< no CPU implementation: the device only
};

/// What the cuda engine has of a broadphase.
enum class BroadPhaseDevice {
  none,  ///< nothing: `--engine cuda` refuses it
  step,  ///< the engine's own step runs it (no DeviceBroadPhase): the device oracle
  seam   ///< a DeviceBroadPhase behind gpu/src/device_broadphase.hpp
};

/// What a broadphase promises of its pair set (every one returns the overlapping pairs,
/// sorted and unique; they differ in how).
enum class BroadPhasePairs {
  oracle,   ///< tests every pair: the set the others are tested against
  exact,    ///< finds the overlapping set itself (tested against the oracle)
  filtered  ///< a library proposes a superset (extra candidates) that octocd's exact test reduces
};

/// How many AABB tests a broadphase makes for n bodies.
enum class BroadPhaseCost {
  quadratic,    ///< n(n-1)/2 (benches run it once)
  subquadratic  ///< fewer: a tree, grid or sweep
};

/// One broadphase: a row of broadphase_table.def. Every field is fixed at compile time.
struct BroadPhaseInfo {
  BroadPhaseId id;          ///< its identifier
  std::string name;         ///< as in `--broadphase` ("octree")
  BroadPhaseHost host;      ///< which library builds it on the CPU
  BroadPhaseDevice device;  ///< what the cuda engine has of it
  BroadPhasePairs pairs;    ///< what it promises
  BroadPhaseCost cost;      ///< how many AABB tests it makes
  std::string summary;      ///< one line for help texts and the docs' table

  /// Some CPU library builds it (host != none).
  bool on_cpu() const { return host != BroadPhaseHost::none; }
  /// The cuda engine has it (device != none).
  bool on_device() const { return device != BroadPhaseDevice::none; }
  /// Only the cuda engine has it.
  bool device_only() const { return !on_cpu() && on_device(); }
};

/// Every broadphase, in the table's order: flat, octree, octree-strict, spatial-hash, the
/// Bullet and FCL references, lbvh.
const std::vector<BroadPhaseInfo>& broadphase_infos();

/// The row of `id`.
const BroadPhaseInfo& broadphase_info(BroadPhaseId id);

/// The name of `id` as in `--broadphase`.
const std::string& broadphase_name(BroadPhaseId id);

/// The row named `name`, or nullptr for a name no broadphase has.
const BroadPhaseInfo* find_broadphase_info(const std::string& name);

/// The names of the rows for which `keep(info)` holds, in the table's order.
template <class Keep>
std::vector<std::string> broadphase_names_where(Keep keep) {
  std::vector<std::string> names;
  for (const BroadPhaseInfo& info : broadphase_infos())
    if (keep(info)) names.push_back(info.name);
  return names;
}

/// Every broadphase name, in the table's order (all_broadphase_names() then the device-only
/// ones).
std::vector<std::string> every_broadphase_name();

/// `names` joined by ", " (for "allowed: ..." messages).
std::string join_broadphase_names(const std::vector<std::string>& names);

}  // namespace octocd
