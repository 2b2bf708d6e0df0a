// `octocd engines`: every engine of the registry, whether it runs here and why not, and
// what it can do (docs/engines.md).
#include <string>

#include <CLI/CLI.hpp>
#include <fmt/format.h>

#include "command.hpp"
#include "octocd/engine_registry.hpp"
#include "octocd/engines.hpp"

namespace octocd::cli {

namespace {

/// Options of `octocd engines`.
struct EnginesOptions {
  bool available = false;  ///< --available: only the names of the engines that run here
};

/// What the engine `e` can do, in words, for the table.
std::string capabilities(const EngineInfo& e) {
  std::string s = e.rotates ? "rotates" : "translates only";
  s += e.has_midphase ? ", octree midphase" : "";
  s += e.uses_scene_broadphase ? ", the scene's broadphase" : ", broadphase " + e.own_broadphase;
  s += e.records_every_step ? ", judged in process" : ", judged through its trace";
  return s;
}

int engines_command(const EnginesOptions& o) {
  for (const EngineInfo& e : engine_infos()) {
    const std::string why = engine_unavailable(e);
    if (o.available) {
      if (why.empty()) fmt::print("{}\n", e.name);
      continue;
    }
    fmt::print("{:<8} {}\n", e.name, why.empty() ? "available" : "unavailable: " + why);
    fmt::print("         {}\n         {}\n", e.description, capabilities(e));
  }
  return 0;
}

}  // namespace

Command add_engines_command(CLI::App& app) {
  const auto options = std::make_shared<EnginesOptions>();
  CLI::App* cmd = app.add_subcommand(
      "engines", "List the engines of this octocd: available here, or unavailable with the reason (not built, no "
                 "device), and what each can do (docs/engines.md)");
  cmd->add_flag("--available", options->available, "Print only the names of the engines that run here, one a line");
  return {[cmd] { return cmd->parsed(); }, [options] { return engines_command(*options); }};
}

}  // namespace octocd::cli
