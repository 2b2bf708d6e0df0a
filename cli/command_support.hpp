#pragma once
/// \file command_support.hpp
/// What the subcommands `run` and `validate` share (their files: run.cpp, validate.cpp):
/// help texts from the registry, option validators, loading a scene, the stop line,
/// closing a trace and a process engine's progress.

#include <chrono>
#include <cstdint>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include <CLI/CLI.hpp>

#include "octocd/engine.hpp"
#include "octocd/engine_registry.hpp"
#include "octocd/process_engines.hpp"
#include "octocd/run_session.hpp"
#include "octocd/scene.hpp"
#include "octocd/trace.hpp"

namespace octocd::cli {

/// The clock of `run`'s and `validate`'s wall times (setup, stepping, the stop's grace).
using Clock = std::chrono::steady_clock;
/// How many pipeline stages a FrameMetrics times (octocd::Stage::Count).
constexpr int kStages = static_cast<int>(octocd::Stage::Count);

/// The help of `--engine` (run, validate): the engines' names are the option's choices;
/// their descriptions are `octocd engines`' (docs/engines.md).
std::string engines_help();

/// "--engine A, --engine B" for the engines of the registry whose EngineInfo has `has`
/// (e.g. those that rotate), for help texts.
std::string engines_with(bool (*has)(const EngineInfo&));

/// The help of `--data-dir` (run, validate): where dataset meshes are looked up.
std::string data_dir_help();

/// An integer option in [1, 2147483647], with the message in the project's form
/// ("--frames: 0 is out of range; allowed: an integer in [1, 2147483647]").
CLI::Validator at_least_one();

/// Before a reference engine steps (run, validate SCENE --engine E): the inertia the engine
/// gives each dynamic body lies where a trace may hold it (docs/trace-format.md, "Security
/// rules and limits": finite, diagonal moments in [1e-12, 1e15] kg m^2), else InputError
/// "scene 'S': body B (group G, shape M): engine E gives it inertia I[k][k] = X kg m^2: the
/// shape cannot give a positive inertia a trace may hold; allowed: ..." (a needle, a
/// collinear or a 1e29-wide mesh), so the run fails first instead of writing a trace octocd
/// refuses. Engines without rotation traits are not checked.
void check_engine_inertia(const Engine& world, const Model& model, const std::string& engine);

/// After each step of a reference engine (before its frame is written to a trace): every
/// position, velocity and angular velocity finite and within the trace limits (|x| <= 1e6 m,
/// |v| <= 1e6 m/s, |omega| <= 1e6 rad/s), else RuntimeError "engine E: frame F: body B: its
/// angular velocity (...) rad/s is out of range; allowed: ... ; the run stops before writing
/// frame F".
void check_engine_state(const BodyState& state, std::int64_t frame, const std::string& engine);

/// Loads the scene for `run` and `validate`: `--data-dir` (checked to be a folder; else
/// InputError naming it) or the default lookup of docs/scenes.md.
Scene load_scene_for(const std::string& path, const std::string& data_dir);

/// Writes the XDMF sidecar of a finished (or stopped) trace unless `no_xdmf`; returns its
/// path ("" when not written).
std::string write_sidecar(const std::string& trace, bool no_xdmf);

/// After a runtime failure: closes `trace` and writes its sidecar as far as the disk allows
/// (a failure here is dropped: the original error is the one the user must see).
void close_after_failure(std::unique_ptr<TraceWriter>& trace, const std::string& path, bool no_xdmf);

/// What to say of a process engine's run as its progress comes (set_process_progress):
/// "engine NAME: its process started in S s; stepping" at its first progress line, "frame
/// N/F  R frames/s  (its process as it runs, ...)" at each tenth of its frames (when
/// `tenths`), and a line at least every 10 s meanwhile ("engine NAME: its process is still
/// starting after T s" before its first progress line, else the frame line). One per run.
class ProcessProgressLines {
 public:
  /// `name`: the engine's name as shown (printable).
  ProcessProgressLines(std::string name, bool tenths) : name_(std::move(name)), tenths_(tenths) {}
  /// The lines to say for `p` now (none, one or two), without newlines.
  std::vector<std::string> next(const ProcessProgress& p);

 private:
  std::string name_;
  bool tenths_;
  double said_s_ = 0.0;     // when the last line was said (s since the process started)
  std::int64_t tenth_ = 0;  // the tenths of the frames said
  bool started_ = false;    // its start-up was said
};

/// A process engine's run said on stderr as it happens (stdout flushed first, each line
/// flushed): now "engine NAME: starting PROCESS for F frames; ..."; then, from inside its
/// first step(), "engine NAME: its process started in S s; stepping" at its first progress
/// line (docs/bring-your-engine.md, "Progress"), a line "frame N/F  R frames/s  (its
/// process as it runs, ...)" at each tenth of the frames it says it stepped, and a line at
/// least every 10 s meanwhile ("... still starting after T s" before its first progress
/// line). Nothing when `world` is not a process engine or `shown` is false.
void show_process_progress(Engine& world, std::int64_t frames, bool shown);

}  // namespace octocd::cli
