// The engine registry (engine_registry.hpp, engines.hpp): one entry per engine, its
// EngineInfo (what it can do) beside its factory and its settings parser, and the checks of
// what a caller overrides.
#include "octocd/engines.hpp"

#include <algorithm>
#include <cstdlib>
#include <functional>
#include <string>
#include <utility>

#include <fmt/format.h>

#include "engine_adapters.hpp"
#include "octocd/engine_entry.hpp"
#include "octocd/broadphase.hpp"
#include "octocd/cuda_settings.hpp"
#include "octocd/cuda_world.hpp"
#include "octocd/error.hpp"
#include "octocd/names.hpp"
#include "octocd/process_engines.hpp"
#include "octocd/reference_broadphase.hpp"
#include "octocd/world.hpp"

namespace octocd {

namespace {

using Items = EngineItems;
/// Builds the engine from a model and its own settings items (`where` names them in errors).
using Factory =
    std::function<std::unique_ptr<Engine>(const std::shared_ptr<const Model>&, const Items&, const std::string&)>;

/// One engine: what it can do, how it is built, whether this build has it, and its
/// settings (the keys of its struct, a help line, and a check of items that throws as the
/// factory would).
struct Registered {
  EngineInfo info;
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

/// An EngineInfo of octocd's own pipeline: the scene's broadphase and midphase, a
/// FrameRecord every step (judged in process), batched worlds.
EngineInfo octocd_info(const char* name, const char* description) {
  EngineInfo e;
  e.name = name;
  e.description = description;
  e.has_midphase = e.uses_scene_broadphase = e.records_every_step = e.batched_worlds = true;
  return e;
}

EngineInfo cpu_info() {
  EngineInfo cpu = octocd_info("cpu", "octocd's CPU reference pipeline");
  cpu.threads_setting = "threads";
  cpu.device_twin = "cuda";
  return cpu;
}

/// The most threads `--cpu threads=N` takes.
constexpr long kMostCpuThreads = 4096;

std::vector<std::string> cpu_setting_names() { return {"threads"}; }

/// CpuSettings from `threads=N` items (the last one wins); InputError naming the key and
/// the range otherwise.
CpuSettings cpu_settings(const Items& items, const std::string& where) {
  CpuSettings s;
  for (const std::string& item : items) {
    const std::size_t eq = item.find('=');
    const std::string key = item.substr(0, eq);
    if (eq == std::string::npos)
      throw InputError(fmt::format("{}: '{}' is not KEY=VALUE; allowed: threads=N (docs/settings.md)", where, item));
    if (key != "threads")
      throw InputError(fmt::format("{}: unknown cpu setting '{}'; allowed: threads (docs/settings.md)", where, key));
    const std::string value = item.substr(eq + 1);
    char* end = nullptr;
    const long v = std::strtol(value.c_str(), &end, 10);
    if (value.empty() || value[0] < '0' || value[0] > '9' || *end != '\0' || v > kMostCpuThreads)
      throw InputError(fmt::format("{}: threads='{}' is not allowed; allowed: an integer 0 .. {} (0: OMP_NUM_THREADS "
                                   "when set, else the CPUs this process may run on)",
                                   where, value, kMostCpuThreads));
    s.threads = static_cast<int>(v);
  }
  return s;
}

void check_cpu(const Items& items, const std::string& where) { (void)cpu_settings(items, where); }

std::unique_ptr<Engine> make_cpu(const std::shared_ptr<const Model>& model, const Items& items,
                                 const std::string& where) {
  return std::make_unique<World>(model, make_any_broadphase(model->scene.broadphase, model->scene.domain),
                                 cpu_settings(items, where));
}

EngineInfo cuda_info() {
  EngineInfo cuda = octocd_info("cuda", "the GPU engine (needs a CUDA build and device)");
  cuda.device_broadphases = true;
  cuda.device = true;
  cuda.memory_kind = "device memory";
  cuda.device_twin = "cpu";
  return cuda;
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

/// A reference engine's EngineInfo: it rotates, collides convex hulls of the meshes and runs
/// its own broadphase (`own_broadphase`, the class `own_class`) and narrow phase (no
/// midphase: `no_midphase_reason`).
EngineInfo reference_info(const char* name, const char* description, std::string own_broadphase,
                          const char* own_class, const char* no_midphase_reason) {
  EngineInfo e;
  e.name = name;
  e.description = description;
  e.rotates = true;
  e.own_broadphase = std::move(own_broadphase);
  e.own_broadphase_class = own_class;
  e.geometries = {"hull"};
  e.no_midphase_reason = no_midphase_reason;
  return e;
}

EngineInfo bullet_info() {
  EngineInfo bullet = reference_info("bullet",
      "the same scene in Bullet's btDiscreteDynamicsWorld", broadphase_name(BroadPhaseId::bullet_dbvt),
      "btDbvtBroadphase",
      "Bullet runs its own narrow phase: GJK/EPA on convex hulls and triangle meshes, or btBoxBoxDetector on the "
      "AABB boxes (--bullet shape=box)");
  bullet.geometries = {"hull", "box"};
  bullet.geometry_setting = "shape";
  bullet.iterations_setting = "iterations";
  return bullet;
}

EngineInfo ode_info() {
  EngineInfo ode = reference_info("ode",
      "the same scene in the Open Dynamics Engine (dWorld, rotating boxes and hulls)", "ode-hash", "dHashSpace",
      "ODE runs its own narrow phase: dCollide (dBoxBox, libccd MPR on convex hulls, trimesh colliders)");
  ode.not_thread_safe =
      "ODE 0.16's default threading implementation is one per process and Debian builds it without "
      "ODE_EXT_mt_collisions (dGetConfiguration): worlds stepped at once on threads end in SIGSEGV or an ODE "
      "assertion (m_dependencies_count, threading_impl_templates.h; docs/engines.md)";
  return ode;
}

EngineInfo mujoco_info() {
  EngineInfo mujoco = reference_info("mujoco",
      "the same scene in MuJoCo (soft contacts, convex hulls, rotating bodies)", "mujoco-sap",
      "MuJoCo's mj_collision (sweep and prune)",
      "MuJoCo runs its own narrow phase: mjc_BoxBox on box pairs, MPR (libccd) on the convex hulls of meshes");
  mujoco.max_bodies = 12000;
  mujoco.max_bodies_reason =
      "MuJoCo 2.2 builds its model from XML only and its compiler (mj_setConst) is quadratic in the bodies "
      "(2.8 CPU s at 5,000, 11-45 CPU s at 10^4, about 1,100 CPU s at 10^5; docs/engines.md, \"Set-up of large "
      "scenes (MuJoCo 2.2)\")";
  mujoco.not_thread_safe =
      "MuJoCo 2.2's error and warning handlers (mju_user_error, mju_user_warning) are process-wide pointers the "
      "adapter sets around each step (docs/engines.md)";
  return mujoco;
}

EngineInfo dart_info() {
  EngineInfo dart = reference_info("dart",
      "the same scene in DART (World, FCL collision, boxed LCP; rotating boxes and hulls)", "dart-fcl",
      "FCL's dynamic AABB tree in DART's FCLCollisionGroup",
      "DART runs its own narrow phase: FCL's (box-box, BVH triangle meshes for hulls and static meshes) with DART's "
      "contact post-processing");
  dart.max_bodies = 20000;
  dart.max_bodies_reason =
      "DART 6.12 adds bodies in O(n) each (World::addSkeleton, FCL's dynamic tree, CollisionGroup::"
      "addShapeFrameImpl): 5-6 s at 10^4, 334 s at 5 x 10^4 (22-29 s with --dart insert=posed), 124-144 s at 10^5 "
      "even posed (docs/engines.md, dart, \"Set-up of large scenes\")";
  dart.not_thread_safe =
      "DART 6.12's contact parameters (ContactConstraint's error reduction and constraint force mixing) are "
      "process-wide statics the adapter sets around each step (docs/engines.md)";
  return dart;
}


/// A reference engine (an adapter folder that registers itself, engine_entry.hpp): its
/// hooks when this build registered its adapter; otherwise it is listed as not built (no
/// setting keys; building it is a RuntimeError naming the package it was configured
/// without). Its EngineInfo is the same either way.
Registered adapter_entry(EngineInfo info, const char* package) {
  for (const auto& [name, hooks_of] : engine_adapters())
    if (name == info.name) {
      const EngineHooks h = hooks_of();
      return {std::move(info), h.make, true, h.setting_names, h.settings_help, h.check_settings};
    }
  const std::string why = fmt::format("engine '{}' is not built in this octocd (configured without {})", info.name,
                                      package);
  const Factory missing = [why](const std::shared_ptr<const Model>&, const Items&,
                                const std::string&) -> std::unique_ptr<Engine> { throw RuntimeError(why); };
  return {std::move(info), missing, false, &no_settings, "", &check_none};
}

/// The engines, one entry each, in engine_infos()' order.
const std::vector<Registered>& registered() {
  static const std::vector<Registered> r{
      {cpu_info(), &make_cpu, true, &cpu_setting_names,
       "threads=N: its stages' threads; 0: OMP_NUM_THREADS when set, else the CPUs this process may run on",
       &check_cpu},
      {cuda_info(), &make_cuda, OCTOCD_HAVE_CUDA != 0, &cuda_setting_names, "", &check_cuda},
      adapter_entry(bullet_info(), "libbullet-dev"),
      adapter_entry(mujoco_info(), "libmujoco-dev"),
      adapter_entry(ode_info(), "libode-dev"),
      adapter_entry(dart_info(), "libdart-dev"),
  };
  return r;
}

/// The entry of `info` (an EngineInfo of engine_infos(), a copy of the entry's).
const Registered& registered(const EngineInfo& info) {
  for (const Registered& r : registered())
    if (info.name == r.info.name) return r;
  throw RuntimeError(fmt::format("engine '{}' is not in the registry (engines.cpp)", info.name));
}

/// `names.choose` for the first engine with `has`, e.g. "--engine cuda".
template <class Has>
std::string choose_engine(const ArgumentNames& names, Has has) {
  for (const EngineInfo& e : engine_infos())
    if (has(e)) return fmt::format(fmt::runtime(names.choose), e.name);
  return "";
}

}  // namespace

std::vector<std::string> builtin_engine_names() {
  std::vector<std::string> names;
  for (const Registered& r : registered()) names.push_back(r.info.name);
  return names;
}

const std::vector<EngineInfo>& engine_infos() {
  static const std::vector<EngineInfo> infos = [] {
    std::vector<EngineInfo> v;
    for (const Registered& r : registered()) v.push_back(r.info);
    for (const ProcessEngineSpec& p : process_engines(builtin_engine_names())) v.push_back(p.info);
    return v;
  }();
  return infos;
}

const std::vector<std::string>& engine_names() {
  static const std::vector<std::string> names = names_of(engine_infos());
  return names;
}

const EngineInfo* find_engine_info(const std::string& name) {
  for (const EngineInfo& e : engine_infos())
    if (e.name == name) return &e;
  return nullptr;
}

const EngineInfo& engine_info(const std::string& name, const std::string& where) {
  if (const EngineInfo* e = find_engine_info(name)) return *e;
  throw InputError(fmt::format("{}: unknown engine '{}'; allowed: {}", where, name, join_names(engine_names())));
}

ArgumentNames cli_argument_names() { return ArgumentNames{}; }

ArgumentNames python_argument_names() {
  // Keyword arguments broadphase, midphase and rotation; engine='NAME'; None; NAME={...}.
  return ArgumentNames{"broadphase", "midphase", "rotation", "engine='{}'", "None", "{}"};
}

std::vector<std::string> any_engine_broadphase_names() { return every_broadphase_name(); }

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
      std::string list = join_names(known);
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

bool engine_built(const EngineInfo& info) { return !info.command.empty() || registered(info).built; }

std::string engine_unavailable(const EngineInfo& info) {
  try {
    if (!info.command.empty()) return process_engine_unavailable(*find_process_engine(info.name));
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

std::vector<std::string> engine_setting_names(const EngineInfo& info) {
  if (!info.command.empty()) return find_process_engine(info.name)->settings;
  return registered(info).setting_names();
}

std::string engine_settings_help(const EngineInfo& info) {
  if (!info.command.empty()) {
    const std::vector<std::string> keys = engine_setting_names(info);
    return keys.empty() ? "" : fmt::format("A setting of the process engine {}, KEY=VALUE, repeatable, passed to its "
                                           "process as a string; keys: {}",
                                           info.name, join_names(keys));
  }
  const Registered& r = registered(info);
  const std::vector<std::string> keys = r.setting_names();
  if (keys.empty()) return "";
  std::string text = fmt::format("A setting of the {} engine, KEY=VALUE, repeatable (docs/settings.md); keys: {}",
                                 info.name, join_names(keys));
  if (*r.settings_help) text += fmt::format(" ({})", r.settings_help);
  return text;
}

void check_engine_settings(const EngineSettingItems& settings, const ArgumentNames& names) {
  for (const auto& [engine, items] : settings) {
    const std::string where = fmt::format(fmt::runtime(names.settings), engine);
    const EngineInfo* info = find_engine_info(engine);
    if (info == nullptr)
      throw InputError(fmt::format("{}: unknown engine '{}'; allowed: {}", where, engine, join_names(engine_names())));
    if (!info->command.empty()) check_process_settings(*find_process_engine(engine), items, where);
    else registered(*info).check_settings(items, where);
  }
}

std::unique_ptr<Engine> make_engine(const std::string& name, const std::shared_ptr<const Model>& model,
                                    const EngineSettingItems& settings) {
  const EngineInfo& info = engine_info(name, "--engine");
  const auto it = settings.find(name);
  static const Items kNone;
  const std::string where = fmt::format(fmt::runtime(cli_argument_names().settings), name);
  if (info.max_bodies > 0 && model->bodies.size() > info.max_bodies)
    throw RuntimeError(fmt::format("engine {} does not start {} bodies: above its measured limit of {} bodies ({}); "
                                   "allowed: at most {} bodies on {}, or another engine (octocd engines)",
                                   name, model->bodies.size(), info.max_bodies, info.max_bodies_reason,
                                   info.max_bodies, name));
  if (!info.command.empty())
    return make_process_engine(*find_process_engine(name), model, it == settings.end() ? kNone : it->second, where);
  return registered(info).make(model, it == settings.end() ? kNone : it->second, where);
}

}  // namespace octocd
