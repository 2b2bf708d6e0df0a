// Building octocd's engines by name (engines.hpp): the factories of the registry's
// engines and the checks of what a caller overrides.
#include "octocd/engines.hpp"

#include <algorithm>

#include <fmt/format.h>

#include "octocd/broadphase.hpp"
#include "octocd/bullet_world.hpp"
#include "octocd/cuda_world.hpp"
#include "octocd/error.hpp"
#include "octocd/reference_broadphase.hpp"
#include "octocd/world.hpp"
#if OCTOCD_HAVE_MUJOCO
#include "octocd/mujoco_world.hpp"
#endif

namespace octocd {

namespace {

using Factory = std::unique_ptr<Engine> (*)(const std::shared_ptr<const Model>&, const CudaSettings&,
                                             const BulletSettings&);

/// One engine of engine_infos(): how it is built and whether this build has it.
struct Registered {
  const char* name;
  Factory make;
  bool built;
};

std::unique_ptr<Engine> make_cpu(const std::shared_ptr<const Model>& model, const CudaSettings&,
                                 const BulletSettings&) {
  return std::make_unique<World>(model, make_any_broadphase(model->scene.broadphase, model->scene.domain));
}

std::unique_ptr<Engine> make_cuda(const std::shared_ptr<const Model>& model, const CudaSettings& cuda,
                                  const BulletSettings&) {
  return make_cuda_engine(model, model->scene.broadphase.name, cuda);
}

std::unique_ptr<Engine> make_bullet(const std::shared_ptr<const Model>& model, const CudaSettings&,
                                    const BulletSettings& bullet) {
  return std::make_unique<BulletWorld>(model, model->initial, BulletOptions(), bullet);
}

std::unique_ptr<Engine> make_mujoco(const std::shared_ptr<const Model>& model, const CudaSettings&,
                                    const BulletSettings&) {
#if OCTOCD_HAVE_MUJOCO
  return std::make_unique<MujocoWorld>(model, model->initial);
#else
  (void)model;
  throw RuntimeError("engine 'mujoco' is not built in this octocd");
#endif
}

/// The factories, by the names of engine_infos().
const std::vector<Registered>& registered() {
  static const std::vector<Registered> r{
      {"cpu", &make_cpu, true}, {"cuda", &make_cuda, OCTOCD_HAVE_CUDA != 0}, {"bullet", &make_bullet, true},
      {"mujoco", &make_mujoco, OCTOCD_HAVE_MUJOCO != 0}};
  return r;
}

const Registered& registered(const EngineInfo& info) {
  for (const Registered& r : registered())
    if (info.name == r.name) return r;
  throw RuntimeError(fmt::format("engine '{}' is in engine_infos() but has no factory (engines.cpp)", info.name));
}

std::string join(const std::vector<std::string>& v, const char* sep) {
  std::string s;
  for (const std::string& x : v) s += (s.empty() ? "" : sep) + x;
  return s;
}

/// `names.choose` for the first engine with `has`, e.g. "--engine cuda".
template <class Has>
std::string choose_engine(const ArgumentNames& names, Has has) {
  for (const EngineInfo& e : engine_infos())
    if (has(e)) return fmt::format(fmt::runtime(names.choose), e.name);
  return "";
}

}  // namespace

ArgumentNames cli_argument_names() { return ArgumentNames{}; }

ArgumentNames python_argument_names() {
  ArgumentNames n;
  n.broadphase = "broadphase";
  n.midphase = "midphase";
  n.rotation = "rotation";
  n.choose = "engine='{}'";
  n.omit = "None";
  return n;
}

std::vector<std::string> any_engine_broadphase_names() {
  std::vector<std::string> names = all_broadphase_names();
  for (const std::string& n : cuda_only_broadphase_names()) names.push_back(n);
  return names;
}

void apply_engine_options(Scene& scene, const EngineInfo& info, const EngineOptions& o, const ArgumentNames& names) {
  const std::string choose_this = fmt::format(fmt::runtime(names.choose), info.name);
  const std::string file = scene.path.empty() ? std::string("<scene>") : scene.path;
  if (!o.broadphase.empty()) scene.broadphase.name = o.broadphase;
  if (!info.has_midphase && !o.midphase.empty())
    throw InputError(fmt::format("{}: engine {} has no octree midphase ({}); allowed: {} with {}", names.midphase,
                                 info.name, info.no_midphase_reason, fmt::format(fmt::runtime(names.omit), names.midphase),
                                 choose_this));
  if (!o.midphase.empty()) scene.midphase = MidphaseConfig::parse(o.midphase, names.midphase);
  if (!info.uses_scene_broadphase) {
    if (!o.broadphase.empty() && o.broadphase != info.own_broadphase)
      throw InputError(fmt::format("{}: engine {} runs {}, not '{}'; allowed: {}, or {} with {}", names.broadphase,
                                   info.name, info.own_broadphase_class, o.broadphase, info.own_broadphase,
                                   fmt::format(fmt::runtime(names.omit), names.broadphase), choose_this));
  } else {
    const std::vector<std::string> known = all_broadphase_names();
    const std::vector<std::string> device_only = cuda_only_broadphase_names();
    const std::string& bp = scene.broadphase.name;
    const std::string where = o.broadphase.empty() ? file + ": broadphase.name" : names.broadphase;
    const bool on_device_only = std::find(device_only.begin(), device_only.end(), bp) != device_only.end();
    if (on_device_only && !info.device_broadphases)
      throw InputError(fmt::format("{}: broadphase '{}' exists on the device only; allowed: {} with it, or another "
                                   "broadphase",
                                   where, bp, choose_engine(names, [](const EngineInfo& e) {
                                     return e.device_broadphases;
                                   })));
    if (!on_device_only && std::find(known.begin(), known.end(), bp) == known.end()) {
      std::string list = join(known, ", ");
      const std::string device_engine = choose_engine(names, [](const EngineInfo& e) { return e.device_broadphases; });
      for (const std::string& nm : device_only) list += ", " + nm + " (" + device_engine + ")";
      throw InputError(fmt::format("{}: unknown broadphase '{}'; allowed: {}", where, bp, list));
    }
    const int depth = scene.mesh_octree_depth;
    if (!o.midphase.empty() && depth >= 0 && !scene.midphase.aabb_only && scene.midphase.max_level() > depth)
      throw InputError(fmt::format(
          "{}: level {} is deeper than the scene's midphase.depth {} ({}); allowed: aabb-only or ascending levels in "
          "[0, {}], or raise midphase.depth in the scene",
          names.midphase, scene.midphase.max_level(), depth, file, depth));
  }
  if (o.rotation && !info.rotates)
    throw InputError(fmt::format("{}: engine {} translates only (SPEC 3); allowed: {} with {}", names.rotation,
                                 info.name, names.rotation,
                                 choose_engine(names, [](const EngineInfo& e) { return e.rotates; })));
  if (o.rotation) scene.rotation = true;
  if (!info.rotates) require_translation_only(scene, info.name);
}

bool engine_built(const EngineInfo& info) { return registered(info).built; }

std::string engine_unavailable(const EngineInfo& info) {
  try {
    if (!engine_built(info)) return fmt::format("engine '{}' is not built in this octocd", info.name);
    if (info.device && !cuda_device_available()) return cuda_device_status();
  } catch (const std::exception& e) {
    return e.what();
  }
  return "";
}

std::vector<std::string> built_engine_names() {
  std::vector<std::string> names;
  for (const EngineInfo& e : engine_infos())
    if (engine_built(e)) names.push_back(e.name);
  return names;
}

std::unique_ptr<Engine> make_engine(const std::string& name, const std::shared_ptr<const Model>& model,
                                    const CudaSettings& cuda, const BulletSettings& bullet) {
  const EngineInfo& info = engine_info(name, "--engine");
  return registered(info).make(model, cuda, bullet);
}

}  // namespace octocd
