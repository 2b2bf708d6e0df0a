#pragma once
// `octocd validate` (docs/validation.md, docs/cli.md "validate"), split by what its parts do;
// what they share is declared here:
// - validate.cpp: the command line (add_validate_command) and validate_command, which checks
//   the options' combinations and takes the path: --merge, --trace-in or a scene;
// - validate_scene.cpp: a scene's run judged (validate_scene_command), through a trace for an
//   engine that does not record every step, or --determinism's runs compared;
// - validate_trace.cpp: --trace-in, another engine's trace judged (validate_trace_in), or
//   checked only;
// - validate_outcome.cpp: what a verdict becomes: JUnit, --json (also of a stopped run),
//   --expect's outcome lines and the exit code (conclude_validate); --merge of shards;
// - validate_worker.hpp: the judging on its own thread, so that a signal is answered within
//   kValidateStopGrace.
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "octocd/engines.hpp"
#include "octocd/expect.hpp"
#include "octocd/external.hpp"
#include "octocd/scene.hpp"
#include "octocd/validation.hpp"
#include "command_support.hpp"
#include "view.hpp"

namespace octocd::cli {

/// What `octocd validate`'s command line asks (add_validate_command).
struct ValidateOptions {
  std::string scene;
  std::string engine = "cpu";
  std::vector<std::string> tolerances;
  std::string against = "bullet,fcl";
  int frames = 300;
  int every = 10;
  std::string trace;
  std::string trace_in;       ///< --trace-in: judge another engine's trace instead of a scene
  bool check_only = false;    ///< --check-only: only check the --trace-in file's structure
  bool frames_given = false;  ///< --frames on the command line (--trace-in: else every frame)
  bool every_given = false;   ///< --every on the command line (--trace-in: else 1)
  std::string data_dir;
  std::string junit;
  bool no_xdmf = false;
  bool rotation = false;      ///< --rotation: the scene's bodies rotate (engine bullet only)
  octocd::EngineSettingItems settings;  ///< --ENGINE KEY=VALUE items by engine
  bool engine_given = false;  ///< --engine was on the command line
  std::string expect;         ///< --expect FILE.json: known failures (design.md section 14b)
  std::string write_expect;   ///< --write-expect FILE.json: record the current failures
  bool strict = false;        ///< --strict: an expected failure that no longer fails is exit 3
  std::string json;           ///< --json FILE: every row, cause and item as JSON
  std::string view;           ///< --view DIR: a page per failing example (cli/view.hpp)
  std::string mesh_dir;       ///< --mesh-dir DIR: where a judged trace's scene may name meshes
  octocd::cli::FailureViews views;  ///< the pages --view wrote (linked from the table, JSON, JUnit)
  std::string shard;          ///< --shard i/N: judge only this share of the trace's frames
  std::vector<std::string> merge;  ///< --merge A.json B.json ...: join shards' verdicts
  int threads = 0;            ///< --threads: threads per frame (0: the hardware's)
  std::string judge_device = "cpu";  ///< --judge-device: cpu, or cuda (rows 1 and 4 on the GPU)
  octocd::Expectations expectations;  ///< --expect's file, read before the run
  bool determinism = false;   ///< --determinism: runs compared bit for bit instead of the validators
  /// Why --junit could not be written (write_junit_guarded): raised by validate_command
  /// once --json is written, so a failed --junit never costs the --json file.
  mutable std::string junit_failed;
};

/// Runs `write` (a write_junit or write_junit_error to o.junit); a failure to write that
/// file (its message begins "--junit: ") is said at once on stderr and kept in
/// o.junit_failed instead of thrown, and the verdict goes on to the table and --json.
void write_junit_guarded(const ValidateOptions& o, const std::function<void()>& write);
/// The exit of a `validate` whose --junit could not be written (o.junit_failed): 1 after a
/// last line on stderr saying what --json holds; otherwise `code`.
int with_junit_outcome(const ValidateOptions& o, int code);
/// --junit of a scene's verdict (the scene run here, or `engine`'s trace of it); nothing
/// without --junit; a failure to write it is kept (write_junit_guarded).
void write_scene_junit(const ValidateOptions& o, const std::string& suite, const std::string& engine,
                       std::int64_t frames, const std::vector<octocd::ValidationResult>& results,
                       const std::string& stopped, const octocd::ExpectationReport& report, Clock::time_point t0);
/// The end of every `validate` path: --expect's outcome, --json, --write-expect, the verdict
/// line; returns the exit code (0, 3, or 1 when --view's pages could not be written).
int conclude_validate(const ValidateOptions& o, const octocd::RunName& run,
                      const std::vector<octocd::ValidationResult>& results,
                      const octocd::ExpectationReport& report, const nlohmann::ordered_json& meta);
/// --json of a stopped `validate`: the rows of the frames judged, with `stopped` in the document.
void write_stopped_json(const ValidateOptions& o, const octocd::RunName& run,
                        const std::vector<octocd::ValidationResult>& results, const octocd::ExpectationReport& report,
                        nlohmann::ordered_json meta, const std::string& stopped);
/// `octocd validate --merge A.json B.json ...`: the shards' verdicts joined (octocd/shards.hpp).
int validate_merge(const ValidateOptions& o);
/// `octocd validate --trace-in FILE.h5`: another engine's trace judged frame by frame, or
/// checked only (--check-only); exit 0 all pass, 3 any fails, 2 a malformed trace.
int validate_trace_in(ValidateOptions& o, const octocd::ValidationOptions& vo, Clock::time_point t0);
/// `octocd validate SCENE.json` or `--trace-in FILE.h5` once the options are checked: the run
/// session, the scene, the validators' options, then the scene's run, its determinism or the
/// trace judged; returns the exit code.
int validate_scene_command(ValidateOptions& o, Clock::time_point t0);

}  // namespace octocd::cli
