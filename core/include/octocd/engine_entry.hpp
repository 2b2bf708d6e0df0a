#pragma once
/// \file engine_entry.hpp
/// What an engine adapter gives the registry (engines.cpp) when its package is found: its
/// factory and its settings. An adapter's folder holds one `<engine>_engine.cpp` defining
/// `EngineHooks <engine>_engine_hooks()`; its CMakeLists.txt registers it with
/// `octocd_register_engine` (reference/CMakeLists.txt), which compiles it into
/// octocd_engines and lists it in the generated engine_adapters.hpp. It stands in core/, below
/// both the adapters (reference/) that fill it and the registry (engines/) that reads it, so that
/// neither of those folders includes the other's headers for it (docs/architecture.md, "No circles").

#include <memory>
#include <string>
#include <vector>

#include "octocd/engine.hpp"

namespace octocd {

/// A setting's items, "KEY=VALUE" each, in order.
using EngineItems = std::vector<std::string>;

/// A built engine's factory and settings.
struct EngineHooks {
  /// Builds the engine from a model and its settings items (`where` names them in errors:
  /// "--ode"); throws InputError for a bad item.
  std::unique_ptr<Engine> (*make)(const std::shared_ptr<const Model>& model, const EngineItems& items,
                                  const std::string& where) = nullptr;
  /// The keys of its settings struct.
  std::vector<std::string> (*setting_names)() = nullptr;
  /// Throws InputError as make() would for the items.
  void (*check_settings)(const EngineItems& items, const std::string& where) = nullptr;
  /// A help line after the keys ("" for none).
  const char* settings_help = "";
};

/// The hooks of a reference world `W` built as W(model, model->initial, settings), its
/// settings struct `S` filled by `Apply` (apply_settings<S>) and its keys from `Names`.
template <class W, class S, void (*Apply)(S&, const std::vector<std::string>&, const std::string&),
          std::vector<std::string> (*Names)()>
EngineHooks reference_engine_hooks(const char* help = "") {
  EngineHooks h;
  h.make = [](const std::shared_ptr<const Model>& model, const EngineItems& items,
              const std::string& where) -> std::unique_ptr<Engine> {
    S s;
    Apply(s, items, where);
    return std::make_unique<W>(model, model->initial, s);
  };
  h.setting_names = Names;
  h.check_settings = [](const EngineItems& items, const std::string& where) {
    S s;
    Apply(s, items, where);
  };
  h.settings_help = help;
  return h;
}

}  // namespace octocd
