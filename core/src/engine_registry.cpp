// The engines octocd has and their capabilities (engine_registry.hpp).
#include "octocd/engine_registry.hpp"

#include <fmt/format.h>

#include "octocd/error.hpp"

namespace octocd {

const std::vector<EngineInfo>& engine_infos() {
  static const std::vector<EngineInfo> infos = [] {
    EngineInfo cpu;
    cpu.name = "cpu";
    cpu.description = "octocd's CPU reference pipeline";
    cpu.has_midphase = true;
    cpu.uses_scene_broadphase = true;
    cpu.records_every_step = true;
    cpu.octocd_contacts = true;

    EngineInfo cuda;
    cuda.name = "cuda";
    cuda.description = "the GPU engine (needs a CUDA build and device)";
    cuda.has_midphase = true;
    cuda.uses_scene_broadphase = true;
    cuda.device_broadphases = true;
    cuda.device = true;
    cuda.memory_kind = "device memory";
    cuda.records_every_step = true;
    cuda.octocd_contacts = true;

    EngineInfo bullet;
    bullet.name = "bullet";
    bullet.description = "the same scene in Bullet's btDiscreteDynamicsWorld";
    bullet.rotates = true;
    bullet.own_broadphase = "bullet-dbvt";
    bullet.own_broadphase_class = "btDbvtBroadphase";
    bullet.geometries = {"hull", "box"};
    bullet.geometry_setting = "shape";
    bullet.iterations_setting = "iterations";
    bullet.no_midphase_reason =
        "Bullet runs its own narrow phase: GJK/EPA on convex hulls and triangle meshes, or btBoxBoxDetector on the "
        "AABB boxes (--bullet shape=box)";
    EngineInfo ode;
    ode.name = "ode";
    ode.description = "the same scene in the Open Dynamics Engine (dWorld, rotating boxes and hulls)";
    ode.rotates = true;
    ode.own_broadphase = "ode-hash";
    ode.own_broadphase_class = "dHashSpace";
    ode.geometries = {"hull"};
    ode.no_midphase_reason =
        "ODE runs its own narrow phase: dCollide (dBoxBox, libccd MPR on convex hulls, trimesh colliders)";

    EngineInfo mujoco;
    mujoco.name = "mujoco";
    mujoco.description = "the same scene in MuJoCo (soft contacts, convex hulls, rotating bodies)";
    mujoco.rotates = true;
    mujoco.own_broadphase = "mujoco-sap";
    mujoco.own_broadphase_class = "MuJoCo's mj_collision (sweep and prune)";
    mujoco.geometries = {"hull"};
    mujoco.no_midphase_reason =
        "MuJoCo runs its own narrow phase: mjc_BoxBox on box pairs, MPR (libccd) on the convex hulls of meshes";

    EngineInfo dart;
    dart.name = "dart";
    dart.description = "the same scene in DART (World, FCL collision, boxed LCP; rotating boxes and hulls)";
    dart.rotates = true;
    dart.own_broadphase = "dart-fcl";
    dart.own_broadphase_class = "FCL's dynamic AABB tree in DART's FCLCollisionGroup";
    dart.geometries = {"hull"};
    dart.no_midphase_reason =
        "DART runs its own narrow phase: FCL's (box-box, BVH triangle meshes for hulls and static meshes) with DART's "
        "contact post-processing";
    return std::vector<EngineInfo>{cpu, cuda, bullet, mujoco, ode, dart};
  }();
  return infos;
}

const std::vector<std::string>& engine_names() {
  static const std::vector<std::string> names = [] {
    std::vector<std::string> v;
    for (const EngineInfo& e : engine_infos()) v.push_back(e.name);
    return v;
  }();
  return names;
}

const EngineInfo* find_engine_info(const std::string& name) {
  for (const EngineInfo& e : engine_infos())
    if (e.name == name) return &e;
  return nullptr;
}

const EngineInfo& engine_info(const std::string& name, const std::string& where) {
  if (const EngineInfo* e = find_engine_info(name)) return *e;
  std::string names;
  for (const EngineInfo& e : engine_infos()) names += (names.empty() ? "" : ", ") + e.name;
  throw InputError(fmt::format("{}: unknown engine '{}'; allowed: {}", where, name, names));
}

bool writes_octocd_contacts(const std::string& engine) {
  const EngineInfo* e = find_engine_info(engine);
  return e != nullptr && e->octocd_contacts;
}

}  // namespace octocd
