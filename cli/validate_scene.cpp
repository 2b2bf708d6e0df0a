// `octocd validate SCENE.json` (validate_parts.hpp): the run session, the scene and the
// validators' options; the engine's run judged as it steps on the worker thread, or through
// a trace for an engine that does not record every step, or --determinism's runs compared.
#include "validate_parts.hpp"

#include <unistd.h>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>
#include <exception>
#include <filesystem>
#include <fmt/format.h>
#include <nlohmann/json.hpp>
#include "octocd/bullet_world.hpp"
#include "octocd/error.hpp"
#include "octocd/setting_error.hpp"
#include "octocd/expect.hpp"
#include "octocd/junit.hpp"
#include "octocd/results_table.hpp"
#include "octocd/device_judge.hpp"
#include "octocd/external.hpp"
#include "octocd/scene.hpp"
#include "octocd/stop.hpp"
#include "octocd/run_session.hpp"
#include "octocd/text.hpp"
#include "octocd/trace.hpp"
#include "octocd/validation.hpp"
#include "octocd/version.hpp"
#include "octocd/engines.hpp"
#include "octocd/process_engines.hpp"
#include "command_support.hpp"
#include "predict.hpp"
#include "tools.hpp"
#include "view.hpp"
#include "validate_worker.hpp"

namespace octocd::cli {

namespace {

/// `octocd validate SCENE --engine E` for a reference engine (EngineInfo::records_every_step
/// false: Bullet, MuJoCo, ODE): the engine runs `--frames` steps into a version 2 trace
/// (`--trace FILE`, else a temporary file, removed afterwards) with every state and contact,
/// which is then judged as `--trace-in` judges it (validate_trace_in).
int validate_through_trace(octocd::RunSession& session, ValidateOptions& o, const octocd::ValidationOptions& vo,
                           const std::shared_ptr<const octocd::Model>& model, Clock::time_point t0) {
  namespace fs = std::filesystem;
  const bool temporary = o.trace.empty();
  // A temporary trace is made once the engine has stepped: a process engine stopped by a
  // signal ends octocd at once (process_engines.hpp), with nothing of its own left. From
  // its making to its removal it is the session's: any stop or failure removes it.
  std::string path = o.trace;
  const auto make_temporary = [&] {
    path = octocd::cli::temporary_trace("validate-" + o.engine);
    session.add_temporary(path);
  };
  const auto remove_temporary = [&] {
    if (!temporary || path.empty()) return;
    std::error_code ec;
    fs::remove(path, ec);
    session.forget_temporary(path);
  };
  const std::string what = o.engine + (octocd::scene_rotates(model->scene) ? " (rotation)" : " (translation only)");
  std::string geometry;
  std::int64_t stepped = 0;  // frames the engine stepped and the trace took
  try {
    const std::unique_ptr<octocd::Engine> engine =
        make_engine(o.engine, model, o.settings);
    octocd::Engine& world = *engine;
    geometry = world.collision_geometry();
    if (world.writes_own_trace()) {  // a process engine: its own trace is judged, as written
      world.plan_steps(o.frames);
      octocd::cli::show_process_progress(world, o.frames, true);  // its start-up and steps, as they happen
      world.step();  // its process runs every frame; the trace is checked against the request
      if (temporary) make_temporary();
      octocd::copy_own_trace(world, path, temporary ? "validate" : "--trace");
    } else {
      check_engine_inertia(world, *model, o.engine);  // before a trace octocd would refuse is begun
      if (temporary) make_temporary();
      octocd::TraceOptions topt;
      topt.state_every = 1;
      topt.contacts = true;
      topt.v2 = *world.rotation_traits();
      topt.gravity = model->scene.gravity;
      world.set_recording(true);
      octocd::TraceMetadata meta = octocd::trace_metadata(world, 1);
      meta.start_time = octocd::cli::utc_time_now();
      octocd::TraceWriter trace(path, meta, octocd::trace_bodies(world), topt);
      trace.append_state(0, world.state());
      // A step that outlasts the grace after a signal ends the process there (the session
      // removes a temporary trace; a --trace keeps its flushed frames): no frame is judged
      // before the stepping ends.
      // Declared after the trace: the read-back ends before the trace is closed or destroyed,
      // whatever the way out.
      std::optional<octocd::RunSession::KeptTrace> kept;
      if (temporary) session.keep("its temporary trace is removed; no frame judged");
      else kept.emplace(session.keep_trace(trace, path, "; no frame judged"));
      for (int f = 0; f < o.frames && octocd::stop_signal() == 0; ++f) {
        std::optional<octocd::StopWithin> within(
            std::in_place, fmt::format("validate stepped frame {} of {} on engine {} (a step longer than the 0.5 s "
                                       "grace)",
                                       f + 1, o.frames, o.engine));
        const octocd::FrameMetrics& m = world.step();
        within.reset();
        check_engine_state(world.state(), stepped + 1, o.engine);  // the trace stays judgeable
        trace.append_frame_v2(m, world.state(), world.record());
        if (kept) kept->frame_written();
        ++stepped;
      }
      if (kept) kept->end();
      trace.close();
      session.keep("");
    }
  } catch (...) {  // the engine failed: its temporary trace goes (a --trace keeps the frames written)
    remove_temporary();
    throw;
  }
  octocd::ExternalOptions eo;
  eo.against_fcl = vo.against_fcl;
  eo.tol = vo.tol;
  eo.overridden = vo.overridden;
  eo.judge_device = vo.judge_device;
  // The trace's scene names its mesh files as the scene file does: relative to the scene
  // file's folder (its --mesh-dir), not to the (temporary) trace's.
  eo.mesh_dir = fs::absolute(o.scene).parent_path().string();
  octocd::ExternalTraceInfo info;
  std::vector<octocd::ValidationResult> results;
  // A signal that stopped the stepping: the frames the trace took are judged (a second
  // signal cuts the judging short, keeping the frames judged whole), as `validate SCENE`
  // on the cpu engine keeps its verdict; without one, a signal while judging ends at once.
  const int stop_sig = octocd::stop_signal();
  try {
    if (stop_sig != 0) {
      // The stepped frames are judged for kValidateStopGrace (a second signal: at once):
      // the verdict of the frames judged whole by then, within the 1 s of a stop.
      const auto judge_until = Clock::now() + kValidateStopGrace;
      eo.stop = [judge_until] { return octocd::stop_signal_count() > 1 || Clock::now() >= judge_until; };
      eo.keep_on_stop = true;
      try {
        results = octocd::validate_external_trace(path, eo, o.every, 0, &info);
      } catch (const octocd::ValidationStopped&) {
        session.keep("no frame judged, no verdict");
        const int code = session.stopped(stop_sig, fmt::format(" after frame {} of {}, and cut short (a second signal "
                                                               "or its bound) while checking {}'s trace",
                                                               stepped, o.frames, o.engine));
        remove_temporary();
        if (!o.junit.empty())
          octocd::write_junit_error(o.junit, model->scene.name, "stopped",
                                    fmt::format("stopped by {} twice; no frame judged", octocd::stop_signal_name(stop_sig)));
        return code;
      }
    } else {
      const std::string judging_what = fmt::format(
          temporary ? "judging {}'s trace (its temporary file removed)" : "judging {}'s trace, which stays on disk",
          o.engine);
      const octocd::StopAtOnce judging(judging_what.c_str());
      results = octocd::validate_external_trace(path, eo, o.every, 0, &info);
      if (!o.view.empty()) o.views = octocd::cli::write_failure_views(path, results, o.view);
    }
  } catch (const octocd::InputError& e) {
    if (!temporary) throw;
    remove_temporary();
    // The scene was accepted: a trace the engine wrote that the reader refuses is the run's
    // failure, said as such, never a refusal naming a temporary file that no longer exists.
    std::string why = e.what();
    if (why.rfind(path, 0) == 0) why = why.substr(path.size() + (why.compare(path.size(), 2, ": ") == 0 ? 2 : 0));
    throw octocd::RuntimeError(fmt::format("engine {}: its trace of scene '{}' (temporary, removed) is one octocd's "
                                           "reader refuses: {}",
                                           o.engine, octocd::printable(model->scene.name), why));
  } catch (...) {
    remove_temporary();
    throw;
  }
  remove_temporary();
  const octocd::RunName run{model->scene.name, ""};
  const octocd::ExpectationReport report = octocd::match_expectations(o.expectations, run, results);
  // Stopped: the table covers the frames judged whole; what the trace holds is what the
  // judging read back from it (info.frames), never a count kept beside it.
  std::string stopped;
  if (stop_sig != 0)
    stopped = fmt::format(
        "the table covers {} of {} (an incomplete verdict); stopped by {} after frame {}{}",
        info.judged_to >= 1 ? fmt::format("frames 1..{}", info.judged_to) : std::string("no whole frame"), o.frames,
        octocd::stop_signal_name(stop_sig), stepped,
        info.stopped ? fmt::format("; judging was cut short (a second signal or its {} ms after the stop) inside "
                                   "frame {}",
                                   kValidateStopGrace.count(), info.stopped_in)
                     : std::string());
  write_scene_junit(o, model->scene.name, what, info.frames, results, stopped, report, t0);
  fmt::print("validate {} (engine {}, judged as a version 2 external trace{}: {} bodies, {} "
             "frames, checks every {}, against: {})\n\ngeometry: {}\n\n",
             model->scene.name, what, temporary ? "" : " " + path, info.bodies, info.frames, o.every, o.against, geometry);
  fmt::print("{}", octocd::format_results(results, vo.overridden, &report));
  const nlohmann::ordered_json meta = {{"engine", what},   {"geometry", geometry},  {"frames", info.frames},
                                       {"every", o.every}, {"against", o.against}, {"scene_file", o.scene},
                                       {"build_id", octocd::build_id()}};
  if (stop_sig != 0) {
    write_stopped_json(o, run, results, report, meta, stopped);
    fmt::print("\nSTOPPED: {}\n", stopped);
    std::fflush(stdout);
    const std::string kept = info.frames > 0 ? fmt::format("frames 1..{}", info.frames) : std::string("no frame");
    session.keep(temporary ? fmt::format("its temporary trace (it held {}) is removed", kept)
                           : fmt::format("the trace {} holds {} (read back)", path, kept));
    return session.stopped(stop_sig, fmt::format(" after frame {} of {}", stepped, o.frames));
  }
  return conclude_validate(o, run, results, report, meta);
}

/// The end of `validate SCENE`: JUnit (with `stopped`, the incomplete verdict's status,
/// when a signal stopped it), the table, then either the STOPPED line and 130/143 or
/// conclude_validate's outcome and exit code.
int validate_verdict(const ValidateOptions& o, const std::string& name,
                     const std::vector<octocd::ValidationResult>& results, const std::vector<std::string>& overridden,
                     const std::string& stopped, std::int64_t done, Clock::time_point t0) {
  const octocd::RunName run{name, ""};
  const octocd::ExpectationReport report = octocd::match_expectations(o.expectations, run, results);
  write_scene_junit(o, name, o.engine, o.frames, results, stopped, report, t0);
  fmt::print("validate {} (engine {}, {} frames, checks every {}, against: {})\n\n", name, o.engine,
             o.frames, o.every, o.against);
  fmt::print("{}", octocd::format_results(results, overridden, &report));
  if (const int sig = octocd::stop_signal()) {
    // (A signal after the JUnit was written: the whole table, stopped at its end.)
    const std::string line = stopped.empty() ? fmt::format("the table covers frames 1..{} of {}; stopped by {}", done,
                                                           o.frames, octocd::stop_signal_name(sig))
                                             : stopped;
    write_stopped_json(o, run, results, report,
                       {{"engine", o.engine}, {"frames", o.frames}, {"every", o.every}, {"against", o.against},
                        {"scene_file", o.scene}, {"build_id", octocd::build_id()}},
                       line);
    fmt::print("\nSTOPPED: {}\n", line);
    std::fflush(stdout);
    return octocd::RunSession::current()->stopped_after_frame(sig, done, o.frames, o.trace);
  }
  return conclude_validate(o, run, results, report,
                           {{"engine", o.engine}, {"frames", o.frames}, {"every", o.every}, {"against", o.against},
                            {"scene_file", o.scene}, {"build_id", octocd::build_id()}});
}

/// `octocd validate SCENE --determinism`: the rows of determinism_rows (cli/predict.hpp) in
/// validate's table, JUnit, --json and --expect; exit as `validate` (3 when a row differs).
int validate_determinism(const ValidateOptions& o, const std::shared_ptr<const octocd::Model>& model,
                         Clock::time_point t0) {
  octocd::check_engine_settings(o.settings, octocd::cli_argument_names());
  octocd::cli::DeterminismOptions d;
  d.engine = o.engine;
  d.model = model;
  d.settings = o.settings;
  d.frames = o.frames;
  if (o.threads == 1)
    throw octocd::InputError("--threads 1: --determinism compares 1 thread against N; allowed: --threads N >= 2, or 0 "
                             "(max(2, the hardware's))");
  d.threads = o.threads;
  // SIGINT/SIGTERM: the runs stop between frames (and between runs); the rows finished
  // before are written (table, --junit, --json) and said; the runs' temporary traces go
  // (the run session). A process engine's run stopped inside its process ends octocd there
  // (process_engines.hpp), saying how many rows had finished.
  constexpr std::size_t kRows = 3;  // determinism-runs, -threads, -cpu-cuda
  d.stop = [] { return octocd::stop_signal() != 0; };
  const std::vector<octocd::ValidationResult> results = octocd::cli::determinism_rows(d);
  const int sig = octocd::stop_signal();
  std::string stopped;
  if (sig != 0)
    stopped = fmt::format("stopped by {} after {} of {} determinism rows", octocd::stop_signal_name(sig),
                          results.size(), kRows);
  // Its own key in --expect's file (SCENE--determinism): the scene's validator rows are not run here.
  const std::string name = model->scene.name + "--determinism";
  const octocd::RunName run{name, ""};
  const octocd::ExpectationReport report = octocd::match_expectations(o.expectations, run, results);
  if (!o.junit.empty())
    write_junit_guarded(o, [&] {
      octocd::write_junit(o.junit, name, results, std::chrono::duration<double>(Clock::now() - t0).count(),
                          {{"engine", o.engine},
                           {"frames", std::to_string(o.frames)},
                           {"mode", "determinism"},
                           {"scene_file", o.scene},
                           {"build_id", octocd::build_id()}},
                          stopped, &report);
    });
  fmt::print("validate {} --determinism (engine {}, {} frames; each pair of runs compared bit for bit as `octocd "
             "compare` does)\n\n",
             model->scene.name, o.engine, o.frames);
  fmt::print("{}", octocd::format_results(results, {}, &report));
  if (sig != 0) {
    write_stopped_json(o, run, results, report,
                       {{"engine", o.engine}, {"frames", o.frames}, {"mode", "determinism"},
                        {"scene_file", o.scene}, {"build_id", octocd::build_id()}},
                       stopped);
    fmt::print("\nSTOPPED: {}\n", stopped);
    std::fflush(stdout);
    std::string kept = fmt::format("the table above holds the {} finished row(s)", results.size());
    if (!o.junit.empty()) kept += fmt::format(", --junit {} too", o.junit);
    if (!o.json.empty()) kept += fmt::format(", --json {} too", o.json);
    octocd::RunSession& session = *octocd::RunSession::current();
    session.keep(kept);
    return session.stopped(sig, fmt::format(" after {} of {} determinism rows", results.size(), kRows));
  }
  return conclude_validate(o, run, results, report,
                           {{"engine", o.engine}, {"frames", o.frames}, {"mode", "determinism"},
                            {"scene_file", o.scene}, {"build_id", octocd::build_id()}});
}

}  // namespace

int validate_scene_command(ValidateOptions& o, Clock::time_point t0) {
  // SIGINT/SIGTERM: stop between frames, flush, 130/143; the judging worker is waited for
  // kValidateStopGrace (a second signal ends the wait), then the verdict of the frames
  // judged so far is written, whatever that takes: no deadline cuts the writing.
  octocd::RunSession session("validate", {0.0, octocd::SecondSignal::Recorded});
  octocd::Scene scene;
  if (o.trace_in.empty()) {  // --trace-in judges a trace, not a scene
    const octocd::StopAtOnce loading("loading the scene and its meshes");
    scene = load_scene_for(o.scene, o.data_dir);
    // Without --engine, a rotating scene (rotation: true, an orientation or an angular
    // velocity) is validated on the registry's first engine that rotates (bullet).
    if (!o.engine_given && octocd::scene_rotates(scene)) {
      for (const octocd::EngineInfo& e : octocd::engine_infos())
        if (e.rotates) {
          o.engine = e.name;
          break;
        }
      o.rotation = true;
    }
    octocd::EngineOptions eo;
    eo.rotation = o.rotation;
    const octocd::EngineInfo& info = octocd::engine_info(o.engine, "--engine");
    octocd::apply_engine_options(scene, info, eo, octocd::cli_argument_names());
    if (!info.records_every_step) scene.frames = o.frames;  // it is judged through its trace
  }
  octocd::ValidationOptions vo;
  vo.frames = o.frames;
  vo.every = o.every;
  vo.threads = o.threads;
  if (const octocd::JudgeDeviceKind& kind = octocd::judge_device_kind(o.judge_device, "--judge-device"); kind.make) {
    (void)kind.make();  // no device or no CUDA build: exit 1 saying why, before the run
    vo.judge_device = kind.make;
    fmt::print("judge device {}: broadphase-completeness and penetration on the GPU (their details say what went "
               "to the CPU reference); every other row on the CPU, contact-completeness, contact-geometry and "
               "impulse-feasibility on the GPU's candidate pairs\n",
               kind.name);
  }
  // Frames judged while the engine runs the next ones, unless a trace is written (its
  // frames then stay those judged when a signal stops the checks of a frame).
  vo.pipeline = o.trace.empty();
  vo.against_bullet = vo.against_fcl = false;
  std::string rest = o.against;
  while (!rest.empty()) {
    const auto comma = rest.find(',');
    const std::string item = rest.substr(0, comma);
    rest = comma == std::string::npos ? "" : rest.substr(comma + 1);
    const std::map<std::string, bool*> references{{"bullet", &vo.against_bullet}, {"fcl", &vo.against_fcl}};
    if (const auto ref = references.find(item); ref != references.end()) {
      *ref->second = true;
    } else if (item != "none" && !item.empty()) {
      throw octocd::InputError(fmt::format(
          "--against: unknown reference '{}'; allowed: a comma-separated list of bullet, fcl, or none",
          item));
    }
  }
  std::map<std::string, std::string> given;  // --tolerance NAME: the item that set it
  for (const std::string& item : o.tolerances) {
    const auto eq = item.find('=');
    std::string names;
    for (const auto& e : octocd::tolerance_table()) names += (names.empty() ? "" : ", ") + std::string(e.name);
    if (eq == std::string::npos || eq == 0)
      throw octocd::InputError(fmt::format("--tolerance: '{}' is not NAME=VALUE; allowed names: {}", item, names));
    const std::string name = item.substr(0, eq), text = item.substr(eq + 1);
    if (const auto before = given.find(name); before != given.end())
      throw octocd::InputError(fmt::format("--tolerance: {} given twice ('{}' and '{}'); allowed: each tolerance once",
                                           name, before->second, item));
    given[name] = item;
    double value = 0.0;
    std::size_t used = 0;
    // Decimal only: std::stod also reads "0x10" (16), "inf" and "nan".
    const bool decimal = !text.empty() && text.find_first_not_of("0123456789+-.eE") == std::string::npos;
    try {
      if (decimal) value = std::stod(text, &used);
    } catch (const std::exception&) {
      used = 0;
    }
    if (used == 0 || used != text.size())
      throw octocd::InputError(fmt::format(
          "--tolerance: {}: '{}' is not a decimal number; allowed: a finite number >= 0 (decimal, e.g. 0.01 or 1e-3)",
          name, text));
    try {
      octocd::set_tolerance(vo.tol, name, value);
    } catch (const octocd::SettingError& e) {
      throw octocd::InputError("--tolerance: " + e.describe());
    }
    vo.overridden.push_back(name);
  }
  if (!o.trace_in.empty()) {
    if (o.check_only) {  // checking writes nothing: a signal ends it at once
      const octocd::StopAtOnce checking("checking the trace");
      return validate_trace_in(o, vo, t0);
    }
    return validate_trace_in(o, vo, t0);  // polls the signal (an incomplete verdict)
  }
  std::optional<octocd::StopAtOnce> building(std::in_place, "building the model");
  const std::shared_ptr<const octocd::Model> model = octocd::build_model(scene);
  building.reset();
  if (o.determinism) return validate_determinism(o, model, t0);
  if (!octocd::engine_info(o.engine, "--engine").records_every_step) {
    // It is judged through its trace when it records (Bullet: hull mode or rotation).
    if (!make_engine(o.engine, model, o.settings)->can_record())
      throw octocd::InputError(fmt::format(
          "--engine: {} with boxes equal to the AABBs and no rotation cannot be validated (no per-frame record); "
          "allowed: {}, or {} with --bullet shape=hull (the default) or --rotation",
          o.engine, engines_with([](const EngineInfo& e) { return e.records_every_step; }), o.engine));
    return validate_through_trace(session, o, vo, model, t0);
  }
  std::unique_ptr<octocd::TraceWriter> trace;
  std::int64_t done = 0;  // frames of the validated engine
  vo.stop = [] { return octocd::stop_signal() != 0; };
  vo.on_step = [&](const octocd::Engine& w) {
    ++done;
    if (!o.trace.empty()) {
      if (!trace) {
        // --view draws frames from the trace: every state (the initial one first) and contact.
        const bool every = !o.view.empty();
        octocd::TraceMetadata meta = octocd::trace_metadata(w, every ? 1 : 10);
        meta.start_time = octocd::cli::utc_time_now();
        octocd::TraceOptions topt;
        topt.flush_every = 1;  // every checked frame on disk: a stopped or killed run keeps them all
        if (every) {
          topt.state_every = 1;
          topt.contacts = true;
        }
        trace = std::make_unique<octocd::TraceWriter>(o.trace, meta, octocd::trace_bodies(w), topt);
        if (every) trace->append_state(0, model->initial);
      }
      trace->append_frame(w.last_metrics(), w.state(), w.contacts());
    }
  };
  std::vector<octocd::ValidationResult> results;
  std::int64_t stopped_in = 0;  // the frame a signal stopped the checks in (0: none)
  // The engine runs and is judged on a worker thread, so this thread answers a signal
  // within kValidateStopGrace even when a step of a big scene takes seconds: the worker
  // normally stops at its next poll; if not, the verdict of the frames judged so far
  // (on_judged's latest snapshot) is reported and the process ends without it.
  JudgedSoFar so_far;
  JudgingProgress progress;
  const std::int64_t frames_total = o.frames;
  vo.on_judged = [&so_far, &progress, frames_total](const std::vector<octocd::ValidationResult>& rows,
                                                    std::int64_t judged) {
    so_far.keep(rows, judged);
    progress.tick(judged, frames_total);
  };
  Worker worker([&] {
    octocd::check_engine_settings(o.settings, octocd::cli_argument_names());
    results = octocd::validate_engine([&] { return make_engine(o.engine, model, o.settings); }, vo, &stopped_in);
  });
  if (!worker.wait()) {
    // A step or check outlasting the grace, or a second signal: the incomplete verdict of
    // the frames judged so far, then the process ends (the worker is not waited for).
    const int sig = octocd::stop_signal();
    auto [rows, judged] = so_far.get();
    const std::string stopped =
        fmt::format("the table covers frames 1..{} of {} (an incomplete verdict); stopped by {}{}; frame {} "
                    "was cut short",
                    judged, o.frames, octocd::stop_signal_name(sig),
                    octocd::stop_signal_count() > 1 ? " twice" : "", judged + 1);
    end_without_worker(with_junit_outcome(o, validate_verdict(o, scene.name, rows, vo.overridden, stopped, judged, t0)));
  }
  try {
    worker.join();
  } catch (const octocd::RuntimeError&) {
    close_after_failure(trace, o.trace, o.no_xdmf);
    throw;
  }
  const bool signalled = octocd::stop_signal() != 0;
  if (trace) {
    trace->close();
    octocd::write_validation(o.trace, results);
    // A stopped run has a second: the sidecar and the pages re-read the trace, so they are left out.
    if (!signalled) write_sidecar(o.trace, o.no_xdmf);
    if (!o.view.empty() && !signalled) o.views = octocd::cli::write_failure_views(o.trace, results, o.view);
  }
  // Where a signal stopped the checks: the table covers the frames judged so far.
  std::string stopped;
  if (const int sig = octocd::stop_signal()) {
    // Frames whose checks are complete (a pipelined run has stepped one more).
    const std::int64_t judged = so_far.get().second;
    stopped = fmt::format("the table covers frames 1..{} of {} (an incomplete verdict); stopped by {}{}", judged,
                          o.frames, octocd::stop_signal_name(sig),
                          judged == o.frames     ? " in the analytic or Bullet rerun (n/a)"
                          : stopped_in > judged ? fmt::format(" inside the checks of frame {} (partly judged)", stopped_in)
                                                : std::string());
  }
  return validate_verdict(o, scene.name, results, vo.overridden, stopped, done, t0);
}

}  // namespace octocd::cli
