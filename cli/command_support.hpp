#pragma once
/// \file command_support.hpp
/// What the subcommands `run` and `validate` share (their files: run.cpp, validate.cpp):
/// help texts from the registry, option validators, loading a scene, the stop line and
/// closing a trace.

#include <chrono>
#include <cstdint>
#include <memory>
#include <string>

#include <CLI/CLI.hpp>

#include "octocd/engine_registry.hpp"
#include "octocd/scene.hpp"
#include "octocd/trace.hpp"

namespace octocd::cli {

/// The clock of `run`'s and `validate`'s wall times (setup, stepping, the stop's grace).
using Clock = std::chrono::steady_clock;
/// How many pipeline stages a FrameMetrics times (octocd::Stage::Count).
constexpr int kStages = static_cast<int>(octocd::Stage::Count);

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
