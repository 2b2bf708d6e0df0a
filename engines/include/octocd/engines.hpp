#pragma once
/// \file engines.hpp
/// Building any of octocd's engines by name (the registry of engine_registry.hpp, made
/// concrete): the one factory the CLI, Python and bench call. The library octocd_engines
/// links the three engines' libraries (core's World, reference's BulletWorld, gpu's cuda
/// engine or its stub), so nothing above it names an engine's class or branches on a name.

#include <map>
#include <memory>
#include <string>
#include <vector>

#include "octocd/engine.hpp"
#include "octocd/engine_registry.hpp"
#include "octocd/scene.hpp"

namespace octocd {

/// How a caller names its arguments in messages: the CLI's flags or Python's keywords.
struct ArgumentNames {
  std::string broadphase = "--broadphase";
  std::string midphase = "--midphase";
  std::string rotation = "--rotation";
  /// How choosing an engine reads, "{}" for its name: "--engine {}" or "engine='{}'".
  std::string choose = "--engine {}";
  /// How leaving an option out reads, "{}" for the option: "no {}" or "None".
  std::string omit = "no {}";
  /// How an engine's settings are named, "{}" for the engine: "--{}" (`--bullet
  /// shape=box`) or "{}" (Python's `bullet={'shape': 'box'}`).
  std::string settings = "--{}";
};

/// Settings of engines as "KEY=VALUE" items, by engine name, each engine's items in the
/// order given (the CLI's repeated `--ENGINE KEY=VALUE`, Python's `ENGINE={KEY: VALUE}`).
/// An engine reads only its own items; each engine's registry entry parses them onto its
/// documented settings struct (docs/settings.md: CudaSettings, BulletSettings, ...).
using EngineSettingItems = std::map<std::string, std::vector<std::string>>;

/// The keys of the settings of the engine `info` (the field names of its settings struct,
/// in the struct's order); empty for an engine without settings (cpu).
std::vector<std::string> engine_setting_names(const EngineInfo& info);

/// One line on the settings of the engine `info` for help texts: what the items are, their
/// keys and, where it helps, what the values mean; "" for an engine without settings.
std::string engine_settings_help(const EngineInfo& info);

/// Checks every engine's items in `settings` as its registry entry parses them, whatever
/// the engine a caller runs (a bad item is an input error before anything runs). Throws
/// InputError "<names.settings for the engine>: ..." naming the key, the value and what is
/// allowed, or naming an engine that has no settings or no such name.
void check_engine_settings(const EngineSettingItems& settings, const ArgumentNames& names);

/// The CLI's spelling (the defaults) and Python's (broadphase=, engine='bullet', None).
ArgumentNames cli_argument_names();
ArgumentNames python_argument_names();

/// What a caller overrides on top of a scene when it builds an engine.
struct EngineOptions {
  std::string broadphase;  ///< replaces the scene's broadphase.name; "": the scene's
  std::string midphase;    ///< replaces the scene's midphase.levels ("1,2", "aabb-only"); "": the scene's
  bool rotation = false;   ///< the bodies rotate (as the scene key rotation: true)
  /// Settings items by engine (docs/settings.md); an engine reads only its own.
  EngineSettingItems settings;
};

/// Applies `options` to `scene` for the engine `info` and checks them as strictly as the
/// scene file is checked: a broadphase or midphase for an engine that runs its own or
/// none, an unknown broadphase name (from the option or the file), a device-only
/// broadphase off the device, a midphase level deeper than the scene's midphase.depth,
/// rotation with an engine that translates only (and a rotating scene there:
/// require_translation_only). Throws InputError "<where>: <problem>; allowed: <what>", the
/// options named as `names` spells them.
void apply_engine_options(Scene& scene, const EngineInfo& info, const EngineOptions& options,
                          const ArgumentNames& names);

/// Whether the engine `info` is in this build (cuda: a build with CUDA).
bool engine_built(const EngineInfo& info);

/// "" when the engine `info` can run on this machine, else why not (e.g. "no CUDA device:
/// <the CUDA runtime's reason>"). Never throws.
std::string engine_unavailable(const EngineInfo& info);

/// The names of the engines in this build, in engine_infos() order.
std::vector<std::string> built_engine_names();

/// Builds the engine `name` from `model` (shared, not copied) with the model's broadphase
/// (checked by apply_engine_options when it came from a caller) and its own items of
/// `settings` parsed onto its settings struct by its registry entry (items of other engines
/// are ignored). Throws InputError for an unknown name ("--engine: unknown engine ..."), a
/// bad setting item ("--ENGINE: ...") or a broadphase the engine does not have,
/// RuntimeError when the engine cannot start (no CUDA device, a build without CUDA or
/// without the engine's library, too little device memory, more bodies than its
/// EngineInfo::max_bodies: refused before any set-up, with the measured reason).
std::unique_ptr<Engine> make_engine(const std::string& name, const std::shared_ptr<const Model>& model,
                                    const EngineSettingItems& settings = {});

/// Every broadphase name of some engine, in the order of the broadphase table
/// (every_broadphase_name(), octocd/broadphase_registry.hpp): all_broadphase_names() (cpu;
/// cuda has those too) then cuda_only_broadphase_names() (lbvh).
std::vector<std::string> any_engine_broadphase_names();

}  // namespace octocd
