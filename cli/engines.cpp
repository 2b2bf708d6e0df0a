// `octocd engines`: every engine of the registry, whether it runs here and why not, and
// what it can do (docs/engines.md).
#include <string>

#include <CLI/CLI.hpp>
#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "command.hpp"
#include "octocd/engine_registry.hpp"
#include "octocd/engines.hpp"
#include "octocd/error.hpp"
#include "octocd/names.hpp"
#include "octocd/process_engines.hpp"
#include "octocd/run_session.hpp"
#include "octocd/text.hpp"

namespace octocd::cli {

namespace {

/// Options of `octocd engines`.
struct EnginesOptions {
  bool available = false;  ///< --available: only the names of the engines that run here
  bool json = false;       ///< --json: the registry as JSON on stdout
  double check_timeout_s = 30.0;  ///< --check-timeout: one bound for every process engine's check, run at once
  bool no_checks = false;  ///< --no-checks: no process engine's check runs; their availability is not said
};

/// What the engine `e` can do, in words, for the table.
std::string capabilities(const EngineInfo& e) {
  std::string s = e.rotates ? "rotates" : "translates only";
  s += e.has_midphase ? ", octree midphase" : "";
  s += e.uses_scene_broadphase ? ", the scene's broadphase" : ", broadphase " + e.own_broadphase;
  s += e.records_every_step ? ", judged in process" : ", judged through its trace";
  s += ", geometry " + join_names(e.geometries);
  const std::vector<std::string> keys = engine_setting_names(e);
  if (!keys.empty()) s += ", settings " + join_names(keys);
  if (!e.not_thread_safe.empty()) s += ", not thread-safe (run --worlds: one copy at a time)";
  if (e.max_bodies > 0) s += fmt::format(", at most {} bodies", e.max_bodies);
  return s;
}

/// What `why` says of a process engine whose check --no-checks left out.
constexpr const char* kNotChecked = "not checked (--no-checks)";

/// The registry as JSON: one object per engine (docs/cli.md, "engines"). With `checked`
/// false a process engine's "available" is null and its "why" kNotChecked.
int engines_json(bool checked) {
  nlohmann::ordered_json list = nlohmann::ordered_json::array();
  for (const EngineInfo& e : engine_infos()) {
    const bool answered = checked || e.command.empty();
    const std::string why = answered ? engine_unavailable(e) : kNotChecked;
    nlohmann::ordered_json j;
    j["name"] = e.name;
    j["kind"] = e.command.empty() ? "builtin" : "process";
    if (answered)
      j["available"] = why.empty();
    else
      j["available"] = nullptr;
    j["why"] = utf8_replaced(why);
    j["rotates"] = e.rotates;
    j["geometries"] = e.geometries;
    j["settings"] = engine_setting_names(e);
    j["thread_safe"] = e.not_thread_safe.empty();
    if (!e.not_thread_safe.empty()) j["not_thread_safe"] = e.not_thread_safe;
    if (e.max_bodies > 0) {
      j["max_bodies"] = e.max_bodies;
      j["max_bodies_reason"] = e.max_bodies_reason;
    }
    j["description"] = e.description;
    if (!e.own_broadphase.empty()) {
      j["own_broadphase"] = e.own_broadphase;
      j["own_broadphase_class"] = e.own_broadphase_class;
    }
    if (!e.command.empty()) {
      j["command"] = e.command;
      if (const ProcessEngineSpec* p = find_process_engine(e.name)) j["engines_file"] = p->file;
    }
    list.push_back(std::move(j));
  }
  nlohmann::ordered_json doc;
  doc["engines"] = std::move(list);
  doc["engines_files"] = engines_files_read();
  fmt::print("{}\n", doc.dump(2));
  return 0;
}

int engines_command(const EnginesOptions& o) {
  if (!(o.check_timeout_s > 0.0 && o.check_timeout_s <= 30.0))
    throw InputError(fmt::format("--check-timeout: {:g} s; allowed: a number of seconds in (0, 30]", o.check_timeout_s));
  if (o.no_checks && !o.json)
    throw InputError("--no-checks: without --json; allowed: with --json only (the table and --available say what runs "
                     "here, which takes the checks)");
  if (o.no_checks) return engines_json(false);
  // SIGINT/SIGTERM while the checks run: they are stopped (their process trees end with
  // them), nothing is listed (a stopped check says nothing of its engine), one line, 130/143.
  RunSession session("engines");
  session.keep("nothing listed");
  // Every process engine's check at once, under one bound; the answers are kept for the process.
  const std::vector<ProcessEngineSpec>& specs = process_engines(builtin_engine_names());
  check_process_engines(specs, o.check_timeout_s);
  if (const int sig = session.signal())
    return session.stopped(sig, fmt::format(" while the checks of {} process engine(s) ran", specs.size()));
  if (o.json) return engines_json(true);
  for (const EngineInfo& e : engine_infos()) {
    const std::string why = engine_unavailable(e);
    if (o.available) {
      if (why.empty()) fmt::print("{}\n", e.name);
      continue;
    }
    fmt::print("{:<8} {}\n", e.name, printable(why.empty() ? "available" : "unavailable: " + why));
    fmt::print("         {}\n         {}\n", printable(e.description), capabilities(e));
    if (!e.command.empty()) {
      const ProcessEngineSpec* p = find_process_engine(e.name);
      fmt::print("         a process engine: {} (from {})\n", printable(join_names(e.command, " ")),
                 p ? printable(p->file) : "");
    }
  }
  return 0;
}

}  // namespace

Command add_engines_command(CLI::App& app) {
  const auto options = std::make_shared<EnginesOptions>();
  CLI::App* cmd = add_table_command(app, CommandId::engines);
  cmd->add_flag("--available", options->available, "Print only the names of the engines that run here, one a line");
  cmd->add_option("--check-timeout", options->check_timeout_s,
                  "One bound (s) for the checks of every process engine, run at once (at most 32 at a time): a "
                  "check still running then is stopped and its engine listed unavailable, timed out; in (0, 30]")
      ->default_val(30.0);
  cmd->add_flag("--json", options->json,
                "Print the registry as JSON: per engine name, kind (builtin or process), available, why, rotates, "
                "geometries, settings, thread_safe (not_thread_safe: why not), max_bodies and its reason where it has "
                "one, description, own_broadphase and its class where it runs its own (a process "
                "engine also: command, engines_file), and the engines files read");
  cmd->add_flag("--no-checks", options->no_checks,
                "With --json: run no process engine's check (each starts its runtime, about 0.6 s of CPU for Node.js): "
                "a process engine's available is null and its why \"not checked (--no-checks)\"; built-in engines "
                "are answered as always");
  return {[cmd] { return cmd->parsed(); }, [options] { return engines_command(*options); }};
}

}  // namespace octocd::cli
