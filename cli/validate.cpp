// `octocd validate`: the validators judge an engine's run of a scene or another engine's
// trace (docs/validation.md, docs/cli.md "validate").
#include "validate_parts.hpp"

#include <chrono>
#include <cstdio>
#include <cstring>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <vector>
#include <exception>
#include <filesystem>
#include <CLI/CLI.hpp>
#include "octocd/bullet_world.hpp"
#include "octocd/error.hpp"
#include "octocd/expect.hpp"
#include "octocd/junit.hpp"
#include "octocd/device_judge.hpp"
#include "octocd/external.hpp"
#include "octocd/midphase.hpp"
#include "octocd/scene.hpp"
#include "octocd/atomic_file.hpp"
#include "octocd/validation.hpp"
#include "octocd/version.hpp"
#include "octocd/cuda_world.hpp"
#include "octocd/engines.hpp"
#include "command.hpp"
#include "command_support.hpp"
#include "predict.hpp"
#include "tools.hpp"

namespace octocd::cli {

namespace {

/// `octocd validate`: exit 0 when every validator passes, 3 when any fails. With
/// `--junit`, the report is written in every case that gets past the command line:
/// results (failures included), or one errored case when the scene is bad input or the
/// run fails.
int validate_command(ValidateOptions& o) {
  // Output paths before any work: files absent or regular, folders not a file, FIFO,
  // device or link (atomic_file.hpp); --view DIR/SCENE-trace.h5 is checked as a trace.
  for (const auto& [path, option] : {std::pair<const std::string&, const char*>{o.junit, "--junit"},
                                     {o.json, "--json"},
                                     {o.write_expect, "--write-expect"},
                                     {o.trace, "--trace"}})
    if (!path.empty()) check_output_file(path, option);
  if (!o.view.empty()) check_output_folder(o.view, "--view", false);
  if (!o.expect.empty()) o.expectations = octocd::load_expectations(o.expect);  // bad input before the run
  if (!o.merge.empty()) {
    if (!o.scene.empty() || !o.trace_in.empty() || !o.shard.empty() || o.check_only)
      throw octocd::InputError("--merge: joins shards' JSON verdicts; allowed without SCENE, --trace-in, --shard and "
                               "--check-only");
    return with_junit_outcome(o, validate_merge(o));
  }
  if (o.determinism && (!o.trace_in.empty() || !o.trace.empty() || !o.view.empty()))
    throw octocd::InputError("--determinism: runs the engine on SCENE.json and compares its runs; allowed without "
                             "--trace-in, --trace and --view (the runs' traces are temporary)");
  if (!o.shard.empty() && (o.trace_in.empty() || o.check_only))
    throw octocd::InputError("--shard: splits the frames of a judged trace; allowed with --trace-in FILE.h5 (not "
                             "--check-only); a scene's run is judged whole");
  if (!o.write_expect.empty() && o.check_only)
    throw octocd::InputError("--write-expect: records a judged run's failures; allowed without --check-only");
  if (o.scene.empty() == o.trace_in.empty())
    throw octocd::InputError("validate: give either SCENE.json or --trace-in FILE.h5 (not both)");
  if (o.check_only && o.trace_in.empty())
    throw octocd::InputError("--check-only: needs --trace-in FILE.h5");
  if (!o.trace_in.empty() && (!o.trace.empty() || o.engine_given))
    throw octocd::InputError("--trace-in: judges a trace another engine wrote; allowed without --trace and --engine");
  if (!o.mesh_dir.empty() && o.trace_in.empty())
    throw octocd::InputError("--mesh-dir: where a judged trace's scene finds its meshes; allowed with --trace-in "
                             "FILE.h5 (a scene file names its own)");
  if (!o.view.empty() && o.check_only)
    throw octocd::InputError("--view: draws a judged run's failures; allowed without --check-only");
  if (!o.view.empty() && o.trace_in.empty() && o.trace.empty()) {
    // The pages are drawn from a trace: without --trace, DIR/SCENE-trace.h5 (kept beside them).
    std::error_code ec;
    std::filesystem::create_directories(o.view, ec);
    o.trace = (std::filesystem::path(o.view) / (std::filesystem::path(o.scene).stem().string() + "-trace.h5")).string();
  }
  const auto t0 = Clock::now();
  // The report of a scene that could not be validated; the original error is what the
  // caller sees (and its exit code), even when the report cannot be written.
  auto junit_error = [&](const char* kind, const char* message) {
    // A failure to write --junit itself leaves that file as its message says (unchanged):
    // no error case is written into it afterwards.
    if (o.junit.empty() || !o.junit_failed.empty() || std::string_view(message).rfind("--junit: ", 0) == 0) return;
    try {
      octocd::write_junit_error(o.junit, std::filesystem::path(o.trace_in.empty() ? o.scene : o.trace_in).stem().string(),
                                kind, message);
    } catch (const std::exception& w) {
      std::fprintf(stderr, "octocd: warning: %s\n", w.what());
    }
  };
  try {
    return with_junit_outcome(o, validate_scene_command(o, t0));
  } catch (const octocd::InputError& e) {
    junit_error("bad-input", e.what());
    throw;
  } catch (const octocd::RuntimeError& e) {
    junit_error("runtime-failure", e.what());
    throw;
  }
}
}  // namespace

Command add_validate_command(CLI::App& app) {
  const auto options = std::make_shared<ValidateOptions>();
  ValidateOptions& val = *options;
  CLI::App* val_cmd = add_table_command(app, CommandId::validate);
  // Each option's help fits one or two lines; the details are in docs/validation.md and
  // the pages it names (docs/cli.md keeps this help).
  val_cmd->add_option("scene", val.scene, "Scene file (JSON, see docs/scenes.md); or give --trace-in");
  val_cmd->add_option("--against", val.against, "References: comma-separated bullet, fcl, or none (docs/validation.md)")
      ->default_val("bullet,fcl");
  val_cmd->add_option("--frames", val.frames, "Steps to run (>= 1), for every validator")
      ->check(at_least_one())
      ->default_val(300);
  val_cmd->add_option("--every", val.every,
                      "Check candidate sets, midphase and normals every K-th frame (>= 1)")
      ->check(at_least_one())
      ->default_val(10);
  val_cmd->add_option("--engine", val.engine,
                      "The engine that steps the scene (`octocd engines`); default cpu, or the first engine that "
                      "rotates for a rotating scene")
      ->check(CLI::IsMember(octocd::engine_names()))
      ->default_val("cpu");
  val_cmd->add_flag("--rotation", val.rotation,
                    "The bodies rotate (as rotation: true); needs an engine that rotates");
  add_engine_settings_options(val_cmd, val.settings, true);
  val_cmd->add_option("--tolerance", val.tolerances,
                      "Override a validator bound, NAME=VALUE, repeatable; marked '*' in the table (names, units: "
                      "docs/validation.md)");
  val_cmd->add_option("--trace", val.trace, "Write the validated run as a trace with the results under /validation");
  val_cmd->add_flag("--no-xdmf", val.no_xdmf, "With --trace: do not write the XDMF sidecar");
  val_cmd->add_option("--data-dir", val.data_dir, "Folder of the dataset meshes (default: docs/scenes.md)");
  val_cmd->add_option("--junit", val.junit, "Also write a JUnit XML report, one test case per row");
  val_cmd->add_option("--trace-in", val.trace_in, "Judge another engine's trace (docs/trace-format.md) instead of a scene");
  val_cmd->add_option("--expect", val.expect,
                      "Known failures (JSON, docs/validation-output.md): exit 0 when every failure is expected, 3 "
                      "naming each new or grown one");
  val_cmd->add_option("--write-expect", val.write_expect, "Record this run's failures in FILE.json; exits 0");
  val_cmd->add_flag("--strict", val.strict, "With --expect: an expected failure that no longer fails is exit 3");
  val_cmd->add_option("--json", val.json, "Also write every row as JSON (docs/validation-output.md)");
  val_cmd->add_option("--view", val.view, "Also write a page per failing example into DIR (docs/debugging.md)");
  val_cmd->add_option("--mesh-dir", val.mesh_dir, "With --trace-in: the only folder besides the data dir for its meshes");
  val_cmd->add_option("--shard", val.shard, "With --trace-in: judge only shard i of N (i/N) of its frames");
  val_cmd->add_option("--merge", val.merge, "Join the --json files of one --trace-in run's shards into its verdict")
      ->expected(1, -1);
  val_cmd->add_option("--judge-device", val.judge_device,
                      "Where broadphase-completeness and penetration are judged (docs/gpu.md)")
      ->check(CLI::IsMember([] {
        std::vector<std::string> names;
        for (const octocd::JudgeDeviceKind& k : octocd::judge_device_kinds()) names.push_back(k.name);
        return names;
      }()))
      ->capture_default_str();
  val_cmd->add_option("--threads", val.threads, "Threads judging one frame; 0: OMP_NUM_THREADS, else every CPU")
      ->check(CLI::Range(0, 4096))
      ->default_val(0);
  val_cmd->add_flag("--determinism", val.determinism,
                    "Compare runs bit for bit instead of judging (docs/predictability.md)");
  val_cmd->add_flag("--check-only", val.check_only,
                    "With --trace-in: only check the file and list the rows it can judge");

  return {[val_cmd] { return val_cmd->parsed(); },
          [options, val_cmd] {
            options->frames_given = val_cmd->get_option("--frames")->count() > 0;
            options->every_given = val_cmd->get_option("--every")->count() > 0;
            options->engine_given = val_cmd->get_option("--engine")->count() > 0;
            return validate_command(*options);
          }};
}

}  // namespace octocd::cli
