#pragma once
/// \file commands.hpp
/// The subcommands of `octocd`, each registered the same way by its own file and
/// dispatched by main.cpp: `run` (run.cpp), `validate` (validate.cpp), `bench`, `replay`,
/// `compare`, `report`, `trace-summary` (their files, through tools.hpp's
/// add_X_command / X_command pairs) and `view` (view.cpp); and what `run` and `validate`
/// share.

#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

#include "octocd/engine_registry.hpp"
#include "octocd/scene.hpp"
#include "octocd/trace.hpp"

namespace octocd::cli {

/// One subcommand after registration: whether CLI11 chose it, and running it (throws
/// InputError or RuntimeError like every command; returns the exit code). Owns its options.
struct Command {
  std::function<bool()> selected;
  std::function<int()> run;
};

/// Registers `run` on `app` (run.cpp).
Command add_run_command(CLI::App& app);

/// Registers `validate` on `app` (validate.cpp).
Command add_validate_command(CLI::App& app);

/// Registers `engines` on `app` (engines.cpp).
Command add_engines_command(CLI::App& app);

/// Registers every subcommand on `app` in help order: run, validate, bench, replay,
/// compare, report, trace-summary, view, engines.
std::vector<Command> add_commands(CLI::App& app);

/// The help of `--engine` (run, validate), from the registry: each engine's name and
/// description, "(docs/engines.md)".
std::string engines_help();

/// "--engine A, --engine B" for the engines of the registry whose EngineInfo has `has`
/// (e.g. those that rotate), for help texts.
std::string engines_with(bool (*has)(const EngineInfo&));

/// The help of `--data-dir` (run, validate): where dataset meshes are looked up.
std::string data_dir_help();

/// An integer option in [1, 2147483647], with the message in the project's form
/// ("--frames: 0 is out of range; allowed: an integer in [1, 2147483647]").
CLI::Validator at_least_one();

/// Prints on stderr the line of a command stopped by SIGINT/SIGTERM: the signal, the
/// frame it stopped after of `total`, what `trace` holds, and `note`.
void report_stop(int sig, const char* command, std::int64_t done, std::int64_t total, const std::string& trace,
                 const std::string& note = "");

/// Loads the scene for `run` and `validate`: `--data-dir` (checked to be a folder; else
/// InputError naming it) or the default lookup of docs/scenes.md.
Scene load_scene_for(const std::string& path, const std::string& data_dir);

/// Writes the XDMF sidecar of a finished (or stopped) trace unless `no_xdmf`; returns its
/// path ("" when not written).
std::string write_sidecar(const std::string& trace, bool no_xdmf);

/// After a runtime failure: closes `trace` and writes its sidecar as far as the disk allows
/// (a failure here is dropped: the original error is the one the user must see).
void close_after_failure(std::unique_ptr<TraceWriter>& trace, const std::string& path, bool no_xdmf);

}  // namespace octocd::cli
