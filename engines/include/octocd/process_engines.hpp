#pragma once
/// \file process_engines.hpp
/// Engines as processes (docs/bring-your-engine.md): an engine registered in an engines
/// file as a command (an argument vector, never a shell string) that reads a run request
/// (JSON) and writes a version 2 trace (docs/trace-format.md). octocd starts it, bounds it
/// (wall time, trace size, the tail of its output kept), reads its trace through the
/// hardened reader (octocd/external_trace.hpp) and replays the frames through the Engine
/// interface, so `run`, `validate`, `bench` and the engine matrix take it by name like a
/// built-in engine (engine_registry.hpp: EngineInfo::command is non-empty for it).
///
/// Engines files are read once, on the registry's first use, in this order (a later entry
/// of the same name replaces an earlier one):
///   1. the shipped file: shared_dir()/engines.json (an install: PREFIX/share/octocd/),
///      else the build tree's share/octocd/engines.json (compiled in);
///   2. $XDG_CONFIG_HOME/octocd/engines.json (else $HOME/.config/octocd/engines.json);
///   3. the file of set_engines_file (`--engines-file FILE`).

#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "octocd/engine.hpp"
#include "octocd/engine_registry.hpp"
#include "octocd/error.hpp"

namespace octocd {

/// A value a process engine gave that is outside its allowed range (its trace's
/// `wall_step_seconds` of 0, a subnormal, 1e-300, a negative number, inf or NaN): bad input
/// from the engine, so `octocd` exits 2 (an InputError). The message names the engine, its
/// engines file, the field, the value and the allowed range. `bench` stores the point as
/// failed with this message, goes on, and then exits 2.
class EngineValueError : public InputError {
 public:
  using InputError::InputError;
};

/// One engine of an engines file (docs/bring-your-engine.md, "The engines file").
struct ProcessEngineSpec {
  /// What it can do: name, description, rotates, geometries (records_every_step false: it is
  /// judged through its trace); `command` holds the resolved argument vector.
  EngineInfo info;
  /// The argument vector run for a request (the request's path is appended): argv[0] is
  /// looked up on PATH (or is a path); later items naming an existing file relative to the
  /// engines file's folder are made absolute.
  std::vector<std::string> command;
  /// Optional availability check (resolved as `command`): exits 0 when the engine's runtime
  /// and packages are present. Empty: none.
  std::vector<std::string> check;
  /// The keys of the KEY=VALUE settings items it accepts (passed through as strings).
  std::vector<std::string> settings;
  /// Wall-time bound of one run (s, > 0; default 600).
  double timeout_s = 600.0;
  /// Largest trace it may write (bytes; default 4 GiB): beyond it the process is stopped.
  std::uint64_t max_trace_bytes = 4ull << 30;
  /// The engines file it came from.
  std::string file;
};

/// The engines file given by the user (`--engines-file FILE`, Python's octocd.load_engines_file), read
/// after the shipped and the user's; "" for none. Call before the registry is first read
/// (main does, before registering the commands); a later call with another path throws
/// RuntimeError (the registry is read once per process).
void set_engines_file(const std::string& path);

/// The engines files read, in look-up order (those that exist), for messages.
std::vector<std::string> engines_files_read();

/// Reads one engines file strictly. Throws InputError "FILE: FIELD: PROBLEM; allowed: ..."
/// for unreadable or malformed JSON, an unknown field, a missing one, a value of the wrong
/// type or range, a name not of [a-z0-9_-]{1,32} or among `builtin` (the built-in engines'
/// names), a name twice in the file, or a command given as a string or whose first item
/// reads as a shell command line.
std::vector<ProcessEngineSpec> read_engines_file(const std::string& path, const std::vector<std::string>& builtin);

/// The process engines of every engines file (look-up order above; later same names
/// replace earlier), read on the first call with the built-in names `builtin`. Throws the
/// InputError of read_engines_file. Thread-safe.
const std::vector<ProcessEngineSpec>& process_engines(const std::vector<std::string>& builtin);

/// The process engine `name` of process_engines (already read), or nullptr.
const ProcessEngineSpec* find_process_engine(const std::string& name);

/// "" when the process engine `spec` can run here, else why not: argv[0] not found on PATH,
/// a file its command names missing, or its check command failing (exit code or signal,
/// the sanitised tail of its output) or running past 30 s. Runs the check at most once
/// per engine and process (cached). Never throws.
std::string process_engine_unavailable(const ProcessEngineSpec& spec);

/// Answers process_engine_unavailable for every engine of `specs` not yet answered, their
/// check commands at once (at most 32 at a time) under one overall bound of `bound_s`
/// seconds, each check stopped at the bound (then SIGTERM, SIGKILL 2 s later): all answered
/// within about bound_s + 2 s, whatever the count of hanging checks; a check that could not
/// start within the bound (more than 32 slow ones) is answered "was not run". Throws
/// InputError for a bound outside (0, 30] s.
void check_process_engines(const std::vector<ProcessEngineSpec>& specs, double bound_s = 30.0);

/// Checks settings items "KEY=VALUE" for `spec`: each has '=' and a KEY of spec.settings.
/// Throws InputError "<where>: 'ITEM' ...; allowed: <keys>".
void check_process_settings(const ProcessEngineSpec& spec, const std::vector<std::string>& items,
                            const std::string& where);

/// The run request for `model` (docs/bring-your-engine.md, "The request"): bodies in
/// octocd's order, meshes in the body frame, materials, the initial state, `frames` steps,
/// the trace path `trace`, the settings items as {KEY: VALUE}. Pure.
nlohmann::ordered_json process_request(const ProcessEngineSpec& spec, const Model& model, std::int64_t frames,
                                       const std::string& trace, const std::vector<std::string>& items);

/// Stops the process a step() of the process engine `engine` runs now, from any thread
/// (Python's Ctrl-C inside Engine.step()): its tree is stopped (SIGTERM, SIGKILL 0.2 s
/// later) and that step() throws RuntimeError "engine 'NAME' ... was stopped ..." instead
/// of ending octocd; a step() that starts before the stop is taken is stopped at once.
/// False (nothing done) when `engine` is not a process engine.
bool cancel_process_engine_step(Engine& engine);

/// What a process engine's process has said of its run so far, while it runs.
struct ProcessProgress {
  std::int64_t frames = 0;     ///< the frames its request asks for
  /// The frames it has said it stepped: N of its last stdout line `octocd-progress N`
  /// (docs/bring-your-engine.md, "Progress"), 0 <= N <= frames; -1 before its first such
  /// line (still starting, or an engine that says none).
  std::int64_t stepped = -1;
  double seconds = 0.0;        ///< wall time since its process was started (s)
  double started_s = -1.0;     ///< `seconds` at its first progress line (its start-up); -1 before
};

/// Has `report` called on the thread of the process engine `engine`'s first step() while
/// its process runs: at each progress line the process writes, and at least once a second
/// otherwise; `report` must not throw. An empty `report` calls nothing. False (nothing
/// done) when `engine` is not a process engine.
bool set_process_progress(Engine& engine, std::function<void(const ProcessProgress&)> report);


/// The engine `spec` on `model` (shared) with its settings `items` (checked: InputError
/// naming `where`). Cheap: the process runs at the first step(), for the frames of
/// plan_steps when called before it, else the scene's frames; it then writes its own
/// trace (Engine::own_trace), which is checked and replayed frame by frame. Every failure
/// of the process is a RuntimeError "engine 'NAME': ..." naming what it did and the
/// sanitised tail of its stderr (its stdout's lines other than progress lines when its
/// stderr is empty); a bad value in its trace (a wall_step_seconds giving no finite steps/s)
/// is an EngineValueError; a SIGINT/SIGTERM (stop_signal) while it runs stops its
/// process tree (SIGTERM, then SIGKILL) and ends octocd through the command's run session
/// (RunSession::end_now, run_session.hpp), its temporary folder (the session's while the
/// process runs) removed; without a session the step fails (RuntimeError). Whatever ends a run, the process and every process it started
/// (one that calls setsid() included) have ended when step() returns or octocd exits
/// (docs/bring-your-engine.md, "The invocation").
std::unique_ptr<Engine> make_process_engine(const ProcessEngineSpec& spec, const std::shared_ptr<const Model>& model,
                                            const std::vector<std::string>& items, const std::string& where);

/// Copies the trace `engine` wrote itself (Engine::own_trace, after its first step) to
/// `path` atomically (a temporary file beside it, then a rename: `path` is never left half
/// written). Throws InputError / RuntimeError naming `label` and `path` as
/// write_file_atomically (octocd/atomic_file.hpp), RuntimeError when the engine has no trace.
void copy_own_trace(const Engine& engine, const std::string& path, const std::string& label);

}  // namespace octocd
