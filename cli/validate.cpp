// `octocd validate`: the validators judge an engine's run of a scene or another engine's
// trace (docs/validation.md, docs/cli.md "validate").
#include <signal.h>
#include <unistd.h>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <ctime>
#include <fstream>
#include <map>
#include <memory>
#include <new>
#include <optional>
#include <string>
#include <string_view>
#include <vector>
#include <climits>
#include <condition_variable>
#include <exception>
#include <functional>
#include <mutex>
#include <thread>
#include <filesystem>
#include <CLI/CLI.hpp>
#include <fmt/format.h>
#include <nlohmann/json.hpp>
#include "octocd/broadphase.hpp"
#include "octocd/bullet_world.hpp"
#include "octocd/error.hpp"
#include "octocd/setting_error.hpp"
#include "octocd/expect.hpp"
#include "octocd/junit.hpp"
#include "octocd/results_table.hpp"
#include "octocd/shards.hpp"
#include "octocd/device_judge.hpp"
#include "octocd/external.hpp"
#include "octocd/midphase.hpp"
#include "octocd/reference_broadphase.hpp"
#include "octocd/scene.hpp"
#include "octocd/atomic_file.hpp"
#include "octocd/run_session.hpp"
#include "octocd/text.hpp"
#include "octocd/trace.hpp"
#include "octocd/validation.hpp"
#include "octocd/version.hpp"
#include "octocd/world.hpp"
#include "octocd/cuda_world.hpp"
#include "octocd/engines.hpp"
#include "octocd/process_engines.hpp"
#include "command.hpp"
#include "command_support.hpp"
#include "predict.hpp"
#include "tools.hpp"
#include "view.hpp"

namespace octocd::cli {

namespace {



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
/// file (its message begins "--junit: ": a size limit, a full disk, a folder put in its
/// way) is said at once on stderr (it says what the file holds) and kept in
/// o.junit_failed instead of thrown, and the verdict goes on to the table and --json.
void write_junit_guarded(const ValidateOptions& o, const std::function<void()>& write) {
  try {
    write();
  } catch (const std::runtime_error& e) {
    if (std::string_view(e.what()).rfind("--junit: ", 0) != 0) throw;
    o.junit_failed = e.what();
    std::fprintf(stderr, "octocd: runtime failure: %s\n", octocd::printable_line(o.junit_failed).c_str());
  }
}

/// The exit of a `validate` whose --junit could not be written (o.junit_failed): a last
/// line on stderr saying what --json holds, then 1; otherwise `code`. Called once the
/// verdict and --json are written.
int with_junit_outcome(const ValidateOptions& o, int code) {
  if (o.junit_failed.empty()) return code;
  std::fflush(stdout);
  const std::string json = o.json.empty() ? std::string("no --json was asked (the verdict is the table above)")
                                          : fmt::format("--json {} holds the whole verdict (written)", o.json);
  std::fprintf(stderr, "octocd: --junit %s was not written (above); %s\n", octocd::printable_line(o.junit).c_str(),
               octocd::printable_line(json).c_str());
  return 1;
}

/// Whether --view's pages could not be written (FailureViews::write_error): then says so
/// on stderr, after the verdict (which stands), and `validate` exits 1.
bool views_failed(const ValidateOptions& o) {
  if (o.views.write_error.empty()) return false;
  std::fflush(stdout);
  std::fprintf(stderr, "octocd: %s\n", o.views.write_error.c_str());
  return true;
}

/// --junit of a scene's verdict (the scene run here, or `engine`'s trace of it): `results`
/// with --view's pages in their details, the time since `t0`, the run's properties (engine,
/// frames, every, against, scene_file, build_id) and `stopped` (the line of an incomplete
/// verdict, "" for a whole one). Nothing without --junit; a failure to write it is kept
/// (write_junit_guarded).
void write_scene_junit(const ValidateOptions& o, const std::string& suite, const std::string& engine,
                       std::int64_t frames, const std::vector<octocd::ValidationResult>& results,
                       const std::string& stopped, const octocd::ExpectationReport& report, Clock::time_point t0) {
  if (o.junit.empty()) return;
  write_junit_guarded(o, [&] {
    octocd::write_junit(o.junit, suite, octocd::cli::with_views_in_details(results, o.views, o.junit),
                        std::chrono::duration<double>(Clock::now() - t0).count(),
                        {{"engine", engine},
                         {"frames", std::to_string(frames)},
                         {"every", std::to_string(o.every)},
                         {"against", o.against},
                         {"scene_file", o.scene},
                         {"build_id", octocd::build_id()}},
                        stopped, &report);
  });
}

/// The end of every `validate` path: matches `results` of `run` against --expect, writes
/// --json and --write-expect, prints the outcome lines (plain text) and the verdict line;
/// returns the exit code: 0 when every failure is expected (or none), 3 when one is new or
/// grown (or, with --strict, an expectation is fixed); 0 after --write-expect; 1 when
/// --view's pages could not be written (views_failed).
/// `print_table` prints the table (it needs the report for its verdicts) before them.
int conclude_validate(const ValidateOptions& o, const octocd::RunName& run,
                      const std::vector<octocd::ValidationResult>& results,
                      const octocd::ExpectationReport& report, const nlohmann::ordered_json& meta) {
  using Kind = octocd::ExpectationOutcome::Kind;
  if (!o.views.summary.empty()) fmt::print("\n{}", octocd::cli::format_views(o.views));
  if (!o.json.empty()) {
    nlohmann::ordered_json doc = octocd::results_json(results, run, &report, meta);
    octocd::cli::add_views_to_json(doc, o.views, o.json);
    octocd::write_json_file(o.json, doc, "--json");
  }
  if (!report.outcomes.empty()) fmt::print("\n");
  for (const octocd::ExpectationOutcome& x : report.outcomes) fmt::print("{}\n", octocd::printable_line(x.text));
  if (!o.write_expect.empty()) {
    const std::vector<octocd::Expectation> entries = octocd::expectations_from(run, results);
    octocd::write_expectations(o.write_expect, run, entries);
    fmt::print("\nwrote {} expectation(s) of {} {} to {} (edit each reason)\n", entries.size(),
               run.scene.empty() ? "trace" : "scene", run.scene.empty() ? run.trace : run.scene, o.write_expect);
    return views_failed(o) ? 1 : 0;
  }
  int code = report.exit_code(o.strict);
  const std::size_t expected = report.count(Kind::Expected), fixed = report.count(Kind::Fixed);
  const std::size_t failing = report.count(Kind::New) + report.count(Kind::Grown);
  if (failing == 0 && expected == 0) {
    fmt::print("\n{}\n", fixed > 0 && o.strict ? "VALIDATION FAILED: an expected failure no longer fails (--strict)"
                                                 : "all validators pass");
  } else if (failing == 0) {
    fmt::print("\nall validators pass or fail as expected ({} expected failure(s), {} fixed; {}){}\n", expected,
               fixed, report.file, fixed > 0 && o.strict ? "; VALIDATION FAILED: --strict and a fixed expectation" : "");
  } else {
    fmt::print("\nVALIDATION FAILED: {} new or grown failure(s){}\n", failing,
               expected > 0 ? fmt::format(", {} expected", expected) : std::string());
  }
  return views_failed(o) ? 1 : code;
}

/// How long the main thread of `validate` waits for the judging worker to stop after a
/// signal before it reports the verdict of the frames judged so far without it. The bound
/// cuts the judging, never the writing of what was judged: the verdict is then written
/// whatever time that takes (no process deadline).
constexpr std::chrono::milliseconds kValidateStopGrace{450};
/// The verdict of the frames judged so far (ValidationOptions::on_judged's latest rows),
/// kept by the judging worker, read by the main thread when a step outlasts the grace.
class JudgedSoFar {
 public:
  void keep(const std::vector<octocd::ValidationResult>& rows, std::int64_t judged) {
    const std::lock_guard<std::mutex> lock(m_);
    rows_ = rows;
    judged_ = judged;
  }
  std::pair<std::vector<octocd::ValidationResult>, std::int64_t> get() const {
    const std::lock_guard<std::mutex> lock(m_);
    return {rows_, judged_};
  }

 private:
  mutable std::mutex m_;
  std::vector<octocd::ValidationResult> rows_;
  std::int64_t judged_ = 0;
};

/// --json of a stopped `validate`: the rows of the frames judged, with `stopped` (the
/// STOPPED line's text) in the document, so that a stop never loses what was judged.
void write_stopped_json(const ValidateOptions& o, const octocd::RunName& run,
                        const std::vector<octocd::ValidationResult>& results, const octocd::ExpectationReport& report,
                        nlohmann::ordered_json meta, const std::string& stopped) {
  if (o.json.empty()) return;
  meta["stopped"] = stopped;
  nlohmann::ordered_json doc = octocd::results_json(results, run, &report, meta);
  octocd::write_json_file(o.json, doc, "--json");
}

/// Progress of a long judging on stderr: "validate: judged frame N of M (R frames/s)",
/// the first after 2 s of judging and then every 2 s (a judging that ends sooner prints
/// none). R: the frames judged since the first call over the seconds since it.
class JudgingProgress {
 public:
  void tick(std::int64_t judged_to, std::int64_t frames) {
    const auto now = Clock::now();
    if (!start_) {
      start_ = now;
      first_ = judged_to;
      last_ = now;
      return;
    }
    if (now - last_ < std::chrono::seconds(2)) return;
    last_ = now;
    const double s = std::chrono::duration<double>(now - *start_).count();
    std::fprintf(stderr, "validate: judged frame %lld of %lld (%.2f frames/s)\n", static_cast<long long>(judged_to),
                 static_cast<long long>(frames), s > 0 ? double(judged_to - first_) / s : 0.0);
  }

 private:
  std::optional<Clock::time_point> start_;
  Clock::time_point last_;
  std::int64_t first_ = 0;
};

/// Waits until `done` (set under `m`, `cv` notified) and returns true, or returns false
/// once a signal has waited kValidateStopGrace for it, or at once on a second signal.
bool wait_for_worker(std::mutex& m, std::condition_variable& cv, const bool& done) {
  std::unique_lock<std::mutex> lock(m);
  std::optional<Clock::time_point> first;
  for (;;) {
    if (cv.wait_for(lock, std::chrono::milliseconds(10), [&] { return done; })) return true;
    if (octocd::stop_signal() == 0) continue;
    const auto now = Clock::now();
    if (!first) first = now;
    if (octocd::stop_signal_count() > 1 || now - *first >= kValidateStopGrace) return false;
  }
}

/// Ends the process with `code` at once (stdout and stderr flushed), without waiting for a
/// worker thread that a stop left running.
[[noreturn]] void end_without_worker(int code) {
  std::fflush(stdout);
  std::fflush(stderr);
  std::_Exit(code);
}

/// A job on its own thread, so that the main thread answers a signal within
/// kValidateStopGrace while the job runs (a step of a big scene may take seconds): wait()
/// as wait_for_worker, join() rethrows what the job threw.
class Worker {
 public:
  explicit Worker(std::function<void()> job)
      : thread_([this, job = std::move(job)] {
          try {
            job();
          } catch (...) {
            error_ = std::current_exception();
          }
          const std::lock_guard<std::mutex> lock(m_);
          done_ = true;
          cv_.notify_all();
        }) {}
  /// True once the job finished; false once a stop outlasted the grace (the job may still run).
  bool wait() { return wait_for_worker(m_, cv_, done_); }
  /// Joins the finished job and rethrows what it threw, if anything.
  void join() {
    thread_.join();
    if (error_) std::rethrow_exception(error_);
  }

 private:
  std::mutex m_;
  std::condition_variable cv_;
  bool done_ = false;
  std::exception_ptr error_;
  std::thread thread_;  // last: the job starts once the members above exist
};

int trace_in_verdict(ValidateOptions& o, const octocd::ValidationOptions& vo, const octocd::ExternalOptions& eo,
                     const octocd::ExternalTraceInfo& info, const std::vector<octocd::ValidationResult>& results,
                     int every, Clock::time_point t0, const std::string& cut);

/// `octocd validate --trace-in FILE.h5`: another engine's trace judged frame by frame
/// (octocd/external.hpp); exit 0 all pass, 3 any fails, 2 a malformed trace.
int validate_trace_in(ValidateOptions& o, const octocd::ValidationOptions& vo, Clock::time_point t0) {
  if (o.check_only) {
    const octocd::ExternalTraceInfo info = octocd::check_external_trace(o.trace_in);
    fmt::print("{}: valid external trace: engine '{}', {} bodies, {} frames, version {}; {}{}{}{}{}{}{}{}\n",
               o.trace_in, info.engine, info.bodies, info.frames, info.version, info.has_states ? "states " : "",
               info.has_rotation ? "rotation " : "", info.has_aabbs ? "aabbs " : "", info.has_pairs ? "pairs " : "",
               info.has_contacts ? "contacts " : "", info.has_points ? "points " : "",
               info.manifolds ? "manifolds " : "", info.has_scene ? "scene" : "");
    // Per row, without judging: judged (the trace carries what it needs) or n/a with what
    // to add (docs/validate-your-engine.md, "What a trace must carry").
    const octocd::ExternalTrace trace(o.trace_in);
    fmt::print("\nrows (judged: the trace carries what the row needs; n/a: what to add to judge it):\n");
    for (const octocd::TraceRowPlan& r : octocd::plan_trace_rows(info, trace.bodies())) {
      const char* tier = octocd::tier_name(r.tier);
      if (r.judged)
        fmt::print("{:<8} {:<24} judged{}\n", tier, r.name,
                   r.partial.empty() ? std::string() : "; partly: add " + r.partial);
      else
        fmt::print("{:<8} {:<24} n/a    {}{}\n", tier, r.name, r.add.rfind("nothing", 0) == 0 ? "" : "add ", r.add);
    }
    return 0;
  }
  octocd::ExternalOptions eo;
  eo.against_fcl = vo.against_fcl;
  eo.tol = vo.tol;
  eo.overridden = vo.overridden;
  eo.threads = o.threads;
  eo.judge_device = vo.judge_device;
  eo.mesh_dir = o.mesh_dir;
  if (!o.shard.empty()) eo.shard = octocd::parse_shard(o.shard);
  octocd::ExternalTraceInfo info;
  const int every = o.every_given ? o.every : 1;
  // SIGINT/SIGTERM: the checks poll it; the verdict of the frames judged so far is reported
  // as incomplete (a signal while the trace is checked ends with no verdict). The judging
  // runs on a worker thread so that a check which polls late cannot delay the verdict past
  // kValidateStopGrace: the main thread then reports the worker's latest snapshot.
  eo.stop = [] { return octocd::stop_signal() != 0; };
  eo.keep_on_stop = true;
  JudgedSoFar so_far;
  octocd::ExternalTraceInfo so_far_info;  // under so_far's snapshot (its own mutex below)
  std::mutex info_m;
  JudgingProgress progress;
  eo.on_judged = [&](const std::vector<octocd::ValidationResult>& rows, const octocd::ExternalTraceInfo& i) {
    {
      const std::lock_guard<std::mutex> lock(info_m);
      so_far_info = i;
    }
    so_far.keep(rows, i.judged_to);
    progress.tick(i.judged_to, o.frames_given ? std::min<std::int64_t>(o.frames, i.frames) : i.frames);
  };
  std::vector<octocd::ValidationResult> results;
  Worker worker([&] {
    results = octocd::validate_external_trace(o.trace_in, eo, every, o.frames_given ? o.frames : 0, &info);
  });
  const auto stopped_checking = [&](int sig) {
    std::fprintf(stderr, "octocd validate: stopped by %s while checking the trace %s; no frame judged, no verdict\n",
                 octocd::stop_signal_name(sig), o.trace_in.c_str());
    if (!o.junit.empty())
      octocd::write_junit_error(o.junit, std::filesystem::path(o.trace_in).stem().string(), "stopped",
                                fmt::format("stopped by {} while checking the trace; no frame judged",
                                            octocd::stop_signal_name(sig)));
    return octocd::stop_exit_code(sig);
  };
  if (!worker.wait()) {
    // A check outlasting the grace, or a second signal: the verdict of the frames judged so
    // far (the worker's latest snapshot) is written, then the process ends without the worker.
    const int sig = octocd::stop_signal();
    auto [rows, judged] = so_far.get();
    int code = 0;
    if (rows.empty()) {
      code = stopped_checking(sig);
    } else {
      octocd::ExternalTraceInfo i;
      {
        const std::lock_guard<std::mutex> lock(info_m);
        i = so_far_info;
      }
      i.stopped = true;
      i.judged_to = judged;
      i.stopped_in = judged + 1;
      code = trace_in_verdict(o, vo, eo, i, rows, every, t0, " (a check outlasted the stop's grace)");
    }
    end_without_worker(with_junit_outcome(o, code));
  }
  try {
    worker.join();
  } catch (const octocd::ValidationStopped&) {
    return stopped_checking(octocd::stop_signal());
  }
  return trace_in_verdict(o, vo, eo, info, results, every, t0, "");
}

/// The verdict of `validate --trace-in`: views, JUnit, the table, and the STOPPED line with
/// 128 + the signal when `info.stopped`, else conclude_validate's outcome. `cut`: appended to
/// the STOPPED line (why the frame in progress is missing).
int trace_in_verdict(ValidateOptions& o, const octocd::ValidationOptions& vo, const octocd::ExternalOptions& eo,
                     const octocd::ExternalTraceInfo& info, const std::vector<octocd::ValidationResult>& results,
                     int every, Clock::time_point t0, const std::string& cut) {
  std::string stopped;
  if (info.stopped) {
    const std::int64_t first = octocd::shard_frames(eo.shard, info.frames).first;
    stopped = fmt::format(
        "the table covers {} of {} (an incomplete verdict); stopped by {}{}",
        info.judged_to >= first ? fmt::format("frames {}..{}", first, info.judged_to) : std::string("no whole frame"),
        info.frames, octocd::stop_signal_name(octocd::stop_signal()),
        !cut.empty()          ? fmt::format("; frame {} was cut short{}", info.stopped_in, cut)
        : info.stopped_in > 0 ? fmt::format(" inside the checks of frame {} (partly judged)", info.stopped_in)
                              : std::string());
  }
  if (!o.view.empty() && !info.stopped) o.views = octocd::cli::write_failure_views(o.trace_in, results, o.view, o.mesh_dir);
  const octocd::RunName run = octocd::trace_run(o.trace_in);
  const octocd::ExpectationReport report = octocd::match_expectations(o.expectations, run, results);
  std::string share;
  if (!o.shard.empty()) {
    const auto [first, last] = octocd::shard_frames(eo.shard, info.frames);
    share = fmt::format(", shard {}/{}: frames {}..{}", eo.shard.index, eo.shard.count, first, last);
  }
  if (!o.junit.empty())
    write_junit_guarded(o, [&] {
      octocd::write_junit(o.junit, std::filesystem::path(o.trace_in).stem().string(),
                          octocd::cli::with_views_in_details(results, o.views, o.junit),
                          std::chrono::duration<double>(Clock::now() - t0).count(),
                          {{"engine", info.engine},
                           {"frames", std::to_string(info.frames)},
                           {"every", std::to_string(every)},
                           {"against", o.against},
                           {"trace_file", o.trace_in},
                           {"build_id", octocd::build_id()}},
                          stopped, &report);
    });
  fmt::print("validate external trace {} (engine '{}', {} bodies, {} frames, checks every {}, against: {}{})\n\n",
             octocd::printable(o.trace_in), octocd::printable(info.engine), info.bodies, info.frames, every, o.against,
             share);
  fmt::print("{}", octocd::format_results(results, vo.overridden, &report));
  if (info.stopped) {
    const int sig = octocd::stop_signal();
    write_stopped_json(o, run, results, report,
                       {{"engine", info.engine}, {"frames", info.frames}, {"every", every}, {"against", o.against},
                        {"build_id", octocd::build_id()}},
                       stopped);
    fmt::print("\nSTOPPED: {}\n", stopped);
    std::fflush(stdout);
    report_stop(sig, "validate", info.judged_to, info.frames, "", fmt::format(" of the trace {}", o.trace_in));
    return octocd::stop_exit_code(sig);
  }
  nlohmann::ordered_json meta = {{"engine", info.engine}, {"frames", info.frames}, {"every", every},
                                 {"against", o.against}, {"build_id", octocd::build_id()}};
  if (!o.shard.empty()) {
    octocd::ShardIdentity id;
    id.trace = run.trace;
    std::error_code ec;
    id.trace_bytes = std::filesystem::file_size(o.trace_in, ec);
    id.engine = info.engine;
    id.bodies = info.bodies;
    id.frames = info.frames;
    id.every = every;
    id.against = vo.against_fcl ? "fcl" : "none";  // what --against changes for a trace
    id.tol = vo.tol;
    meta["shard"] = octocd::shard_json(eo.shard, id);
  }
  return conclude_validate(o, run, results, report, meta);
}

/// `octocd validate --merge A.json B.json ...`: the shards' verdicts joined into the
/// unsharded run's (octocd/shards.hpp); exit as `validate`, 2 for bad shards.
int validate_merge(const ValidateOptions& o) {
  const octocd::MergedValidation m = octocd::merge_validations(o.merge);
  const octocd::ExpectationReport report = octocd::match_expectations(o.expectations, m.run, m.results);
  std::vector<std::string> overridden;
  const octocd::Tolerances defaults;
  for (const octocd::ToleranceEntry& e : octocd::tolerance_table())
    if (m.identity.tol.*(e.member) != defaults.*(e.member)) overridden.push_back(e.name);
  fmt::print("validate external trace {} merged from {} shards (engine '{}', {} bodies, {} frames, checks every {}, "
             "against: {})\n\n",
             octocd::printable(m.identity.trace), m.files.size(), octocd::printable(m.identity.engine),
             m.identity.bodies, m.identity.frames, m.identity.every, m.identity.against);
  fmt::print("{}", octocd::format_results(m.results, overridden, &report));
  if (!o.junit.empty()) {
    double seconds = 0;
    for (const octocd::ValidationResult& r : m.results) seconds += r.seconds;
    write_junit_guarded(o, [&] {
      octocd::write_junit(o.junit, std::filesystem::path(m.identity.trace).stem().string(), m.results, seconds,
                          {{"engine", m.identity.engine},
                           {"frames", std::to_string(m.identity.frames)},
                           {"shards", std::to_string(m.files.size())}},
                          "", &report);
    });
  }
  nlohmann::ordered_json files = nlohmann::ordered_json::array();
  for (const std::string& f : m.files) files.push_back(f);
  return conclude_validate(o, m.run, m.results, report,
                           {{"engine", m.identity.engine}, {"frames", m.identity.frames}, {"every", m.identity.every},
                            {"against", m.identity.against}, {"build_id", octocd::build_id()},
                            {"merged_from", files}});
}


int validate_scene_command(ValidateOptions& o, Clock::time_point t0);


/// `octocd validate SCENE --engine E` for a reference engine (EngineInfo::records_every_step
/// false: Bullet, MuJoCo, ODE): the engine runs `--frames` steps into a version 2 trace
/// (`--trace FILE`, else a temporary file, removed afterwards) with every state and contact,
/// which is then judged as `--trace-in` judges it (validate_trace_in).
int validate_through_trace(ValidateOptions& o, const octocd::ValidationOptions& vo,
                           const std::shared_ptr<const octocd::Model>& model, Clock::time_point t0) {
  namespace fs = std::filesystem;
  const bool temporary = o.trace.empty();
  // A temporary trace is made once the engine has stepped: a process engine stopped by a
  // signal ends octocd at once (process_engines.hpp), with nothing of its own left.
  std::string path = o.trace;
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
      if (temporary) path = octocd::cli::temporary_trace("validate-" + o.engine);
      octocd::copy_own_trace(world, path, temporary ? "validate" : "--trace");
    } else {
      check_engine_inertia(world, *model, o.engine);  // before a trace octocd would refuse is begun
      if (temporary) path = octocd::cli::temporary_trace("validate-" + o.engine);
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
      octocd::RunSession* session = octocd::RunSession::current();
      if (session && temporary) {
        session->add_temporary(path);
        session->keep("its temporary trace is removed; no frame judged");
      } else if (session) {
        session->keep(fmt::format("the trace {} holds the frames of its last flush; no frame judged", path));
        session->keep_read_back([&trace, path] {
          const std::string held = octocd::cli::trace_read_back(trace, path);
          return held.empty() ? held : held + "; no frame judged";
        });
      }
      // Cleared before the trace is closed or destroyed, whatever the way out.
      const struct ForgetReadBack {
        octocd::RunSession* session;
        ~ForgetReadBack() {
          if (session) session->forget_read_back();
        }
      } forget_read_back{session};
      for (int f = 0; f < o.frames && octocd::stop_signal() == 0; ++f) {
        std::optional<octocd::StopWithin> within(
            std::in_place, fmt::format("validate stepped frame {} of {} on engine {} (a step longer than the 0.5 s "
                                       "grace)",
                                       f + 1, o.frames, o.engine));
        const octocd::FrameMetrics& m = world.step();
        within.reset();
        check_engine_state(world.state(), stepped + 1, o.engine);  // the trace stays judgeable
        trace.append_frame_v2(m, world.state(), world.record());
        ++stepped;
      }
      if (session) session->forget_read_back();
      trace.close();
      if (session) session->keep("");
      if (session && temporary) session->forget_temporary(path);  // removed below, once judged
    }
  } catch (...) {  // the engine failed: its temporary trace goes (a --trace keeps the frames written)
    std::error_code ec;
    if (temporary && !path.empty()) fs::remove(path, ec);
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
    if (temporary) octocd::set_stop_remove(path);
    if (stop_sig != 0) {
      // The stepped frames are judged for kValidateStopGrace (a second signal: at once):
      // the verdict of the frames judged whole by then, within the 1 s of a stop.
      const auto judge_until = Clock::now() + kValidateStopGrace;
      eo.stop = [judge_until] { return octocd::stop_signal_count() > 1 || Clock::now() >= judge_until; };
      eo.keep_on_stop = true;
      try {
        results = octocd::validate_external_trace(path, eo, o.every, 0, &info);
      } catch (const octocd::ValidationStopped&) {
        std::fprintf(stderr, "octocd validate: stopped by %s after frame %lld of %d, and cut short (a second signal "
                             "or its bound) while checking %s's trace; no frame judged, no verdict\n",
                     octocd::stop_signal_name(stop_sig), static_cast<long long>(stepped), o.frames, o.engine.c_str());
        if (!o.junit.empty())
          octocd::write_junit_error(o.junit, model->scene.name, "stopped",
                                    fmt::format("stopped by {} twice; no frame judged", octocd::stop_signal_name(stop_sig)));
        octocd::set_stop_remove("");
        std::error_code ec;
        if (temporary) fs::remove(path, ec);
        return octocd::stop_exit_code(stop_sig);
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
    octocd::set_stop_remove("");
    std::error_code ec;
    if (!temporary) throw;
    fs::remove(path, ec);
    // The scene was accepted: a trace the engine wrote that the reader refuses is the run's
    // failure, said as such, never a refusal naming a temporary file that no longer exists.
    std::string why = e.what();
    if (why.rfind(path, 0) == 0) why = why.substr(path.size() + (why.compare(path.size(), 2, ": ") == 0 ? 2 : 0));
    throw octocd::RuntimeError(fmt::format("engine {}: its trace of scene '{}' (temporary, removed) is one octocd's "
                                           "reader refuses: {}",
                                           o.engine, octocd::printable(model->scene.name), why));
  } catch (...) {
    octocd::set_stop_remove("");
    std::error_code ec;
    if (temporary) fs::remove(path, ec);
    throw;
  }
  octocd::set_stop_remove("");
  std::error_code ec;
  if (temporary) fs::remove(path, ec);
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
    std::fprintf(stderr, "octocd validate: stopped by %s after frame %lld of %d; %s\n", octocd::stop_signal_name(stop_sig),
                 static_cast<long long>(stepped), o.frames,
                 (temporary ? fmt::format("its temporary trace (it held {}) is removed", kept)
                            : fmt::format("the trace {} holds {} (read back)", path, kept))
                     .c_str());
    return octocd::stop_exit_code(stop_sig);
  }
  return conclude_validate(o, run, results, report, meta);
}

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
    report_stop(sig, "validate", done, o.frames, o.trace);
    return octocd::stop_exit_code(sig);
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
  octocd::RunSession* session = octocd::RunSession::current();
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
    if (session) {
      session->keep(kept);
      return session->stopped(sig, fmt::format(" after {} of {} determinism rows", results.size(), kRows));
    }
    std::fprintf(stderr, "octocd validate: %s; %s\n", stopped.c_str(), kept.c_str());
    return octocd::stop_exit_code(sig);
  }
  return conclude_validate(o, run, results, report,
                           {{"engine", o.engine}, {"frames", o.frames}, {"mode", "determinism"},
                            {"scene_file", o.scene}, {"build_id", octocd::build_id()}});
}

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
               "to the CPU reference); every other row on the CPU\n",
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
    return validate_through_trace(o, vo, model, t0);
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
