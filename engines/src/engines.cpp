// Building octocd's engines by name (engines.hpp): the factories of the registry's
// engines and the checks of what a caller overrides.
#include "octocd/engines.hpp"

#include <algorithm>

#include <fmt/format.h>

#include "octocd/broadphase.hpp"
#include "octocd/bullet_settings.hpp"
#include "octocd/bullet_world.hpp"
#include "octocd/cuda_settings.hpp"
#include "octocd/cuda_world.hpp"
#include "octocd/error.hpp"
#include "octocd/reference_broadphase.hpp"
#include "octocd/world.hpp"
#if OCTOCD_HAVE_MUJOCO
#include "octocd/mujoco_world.hpp"
#endif
#if OCTOCD_HAVE_ODE
#include "octocd/ode_world.hpp"
#endif
#if OCTOCD_HAVE_DART
#include "octocd/dart_world.hpp"
#endif

namespace octocd {

namespace {

using Items = std::vector<std::string>;
/// Builds the engine from a model and its own settings items (`where` names them in errors).
using Factory = std::unique_ptr<Engine> (*)(const std::shared_ptr<const Model>&, const Items&, const std::string&);

/// One engine of engine_infos(): how it is built, whether this build has it, and its
/// settings (the keys of its struct, a help line, and a check of items that throws as the
/// factory would).
struct Registered {
  const char* name;
  Factory make;
  bool built;
  std::vector<std::string> (*setting_names)();
  const char* settings_help;
  void (*check_settings)(const Items&, const std::string&);
};

std::vector<std::string> no_settings() { return {}; }

void check_none(const Items& items, const std::string& where) {
  if (!items.empty())
    throw InputError(fmt::format("{}: '{}': this engine has no settings; allowed: none", where, items.front()));
}

std::unique_ptr<Engine> make_cpu(const std::shared_ptr<const Model>& model, const Items& items,
                                 const std::string& where) {
  check_none(items, where);
  return std::make_unique<World>(model, make_any_broadphase(model->scene.broadphase, model->scene.domain));
}

CudaSettings cuda_settings(const Items& items, const std::string& where) {
  CudaSettings s;
  apply_cuda_settings(s, items, where);
  check_cuda_settings(s, where);
  return s;
}

void check_cuda(const Items& items, const std::string& where) { (void)cuda_settings(items, where); }

std::unique_ptr<Engine> make_cuda(const std::shared_ptr<const Model>& model, const Items& items,
                                  const std::string& where) {
  return make_cuda_engine(model, model->scene.broadphase.name, cuda_settings(items, where));
}

BulletSettings bullet_settings(const Items& items, const std::string& where) {
  BulletSettings s;
  apply_bullet_settings(s, items, where);
  return s;
}

void check_bullet(const Items& items, const std::string& where) { (void)bullet_settings(items, where); }

std::unique_ptr<Engine> make_bullet(const std::shared_ptr<const Model>& model, const Items& items,
                                    const std::string& where) {
  return std::make_unique<BulletWorld>(model, model->initial, BulletOptions(), bullet_settings(items, where));
}

/// A reference engine whose adapter may be absent from this build (its package not found):
/// its settings are parsed when built; when absent, its setting keys are none and building
/// it is a RuntimeError.
#if OCTOCD_HAVE_ODE
OdeSettings ode_settings(const Items& items, const std::string& where) {
  OdeSettings s;
  apply_ode_settings(s, items, where);
  return s;
}
void check_ode(const Items& items, const std::string& where) { (void)ode_settings(items, where); }
std::vector<std::string> ode_keys() { return ode_setting_names(); }
std::unique_ptr<Engine> make_ode(const std::shared_ptr<const Model>& model, const Items& items,
                                 const std::string& where) {
  return std::make_unique<OdeWorld>(model, model->initial, ode_settings(items, where));
}
#else
void check_ode(const Items& items, const std::string& where) { check_none(items, where); }
std::vector<std::string> ode_keys() { return {}; }
std::unique_ptr<Engine> make_ode(const std::shared_ptr<const Model>&, const Items&, const std::string&) {
  throw RuntimeError("engine 'ode' is not built in this octocd (configured without libode-dev)");
}
#endif

#if OCTOCD_HAVE_MUJOCO
MujocoSettings mujoco_settings(const Items& items, const std::string& where) {
  MujocoSettings s;
  apply_mujoco_settings(s, items, where);
  return s;
}
void check_mujoco(const Items& items, const std::string& where) { (void)mujoco_settings(items, where); }
std::vector<std::string> mujoco_keys() { return mujoco_setting_names(); }
std::unique_ptr<Engine> make_mujoco(const std::shared_ptr<const Model>& model, const Items& items,
                                    const std::string& where) {
  return std::make_unique<MujocoWorld>(model, model->initial, mujoco_settings(items, where));
}
#else
void check_mujoco(const Items& items, const std::string& where) { check_none(items, where); }
std::vector<std::string> mujoco_keys() { return {}; }
std::unique_ptr<Engine> make_mujoco(const std::shared_ptr<const Model>&, const Items&, const std::string&) {
  throw RuntimeError("engine 'mujoco' is not built in this octocd (configured without libmujoco-dev)");
}
#endif

#if OCTOCD_HAVE_DART
DartSettings dart_settings(const Items& items, const std::string& where) {
  DartSettings s;
  apply_dart_settings(s, items, where);
  return s;
}
void check_dart(const Items& items, const std::string& where) { (void)dart_settings(items, where); }
std::vector<std::string> dart_keys() { return dart_setting_names(); }
std::unique_ptr<Engine> make_dart(const std::shared_ptr<const Model>& model, const Items& items,
                                  const std::string& where) {
  return std::make_unique<DartWorld>(model, model->initial, dart_settings(items, where));
}
#else
void check_dart(const Items& items, const std::string& where) { check_none(items, where); }
std::vector<std::string> dart_keys() { return {}; }
std::unique_ptr<Engine> make_dart(const std::shared_ptr<const Model>&, const Items&, const std::string&) {
  throw RuntimeError("engine 'dart' is not built in this octocd (configured without libdart-dev)");
}
#endif

/// The engines, one entry each, by the names of engine_infos().
const std::vector<Registered>& registered() {
  static const std::vector<Registered> r{
      {"cpu", &make_cpu, true, &no_settings, "", &check_none},
      {"cuda", &make_cuda, OCTOCD_HAVE_CUDA != 0, &cuda_setting_names, "", &check_cuda},
      {"bullet", &make_bullet, true, &bullet_setting_names,
       "shape=hull: convex hulls of dynamic meshes, triangle meshes of static ones, the default; shape=box: boxes "
       "equal to the AABBs",
       &check_bullet},
      {"mujoco", &make_mujoco, OCTOCD_HAVE_MUJOCO != 0, &mujoco_keys, "", &check_mujoco},
      {"ode", &make_ode, OCTOCD_HAVE_ODE != 0, &ode_keys, "", &check_ode},
      {"dart", &make_dart, OCTOCD_HAVE_DART != 0, &dart_keys, "", &check_dart},
  };
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
  n.settings = "{}";
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
    throw InputError(fmt::format("{}: engine {} translates only (design.md section 3); allowed: {} with {}", names.rotation,
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

std::vector<std::string> engine_setting_names(const EngineInfo& info) { return registered(info).setting_names(); }

std::string engine_settings_help(const EngineInfo& info) {
  const Registered& r = registered(info);
  const std::vector<std::string> keys = r.setting_names();
  if (keys.empty()) return "";
  std::string text = fmt::format("A setting of the {} engine, KEY=VALUE, repeatable (docs/settings.md); keys: {}",
                                 info.name, join(keys, ", "));
  if (*r.settings_help) text += fmt::format(" ({})", r.settings_help);
  return text;
}

void check_engine_settings(const EngineSettingItems& settings, const ArgumentNames& names) {
  for (const auto& [engine, items] : settings) {
    const std::string where = fmt::format(fmt::runtime(names.settings), engine);
    const EngineInfo* info = find_engine_info(engine);
    if (info == nullptr)
      throw InputError(fmt::format("{}: unknown engine '{}'; allowed: {}", where, engine, join(engine_names(), ", ")));
    registered(*info).check_settings(items, where);
  }
}

std::unique_ptr<Engine> make_engine(const std::string& name, const std::shared_ptr<const Model>& model,
                                    const EngineSettingItems& settings) {
  const EngineInfo& info = engine_info(name, "--engine");
  const auto it = settings.find(name);
  static const Items kNone;
  return registered(info).make(model, it == settings.end() ? kNone : it->second,
                               fmt::format(fmt::runtime(cli_argument_names().settings), name));
}

}  // namespace octocd
