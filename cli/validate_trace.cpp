// `octocd validate --trace-in FILE.h5` (validate_parts.hpp): another engine's trace
// checked (--check-only) or judged frame by frame on the worker thread, and its verdict.
#include "validate_parts.hpp"

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <string>
#include <vector>
#include <mutex>
#include <filesystem>
#include <fmt/format.h>
#include <nlohmann/json.hpp>
#include "octocd/expect.hpp"
#include "octocd/junit.hpp"
#include "octocd/results_table.hpp"
#include "octocd/shards.hpp"
#include "octocd/device_judge.hpp"
#include "octocd/external.hpp"
#include "octocd/stop.hpp"
#include "octocd/text.hpp"
#include "octocd/validation.hpp"
#include "octocd/version.hpp"
#include "command_support.hpp"
#include "view.hpp"
#include "validate_worker.hpp"

namespace octocd::cli {

namespace {

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
    return octocd::RunSession::current()->stopped_after_frame(sig, info.judged_to, info.frames, "", "",
                                                              fmt::format(" of the trace {}", o.trace_in));
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

}  // namespace

/// `octocd validate --trace-in FILE.h5`: another engine's trace judged frame by frame
/// (octocd/external.hpp); exit 0 all pass, 3 any fails, 2 a malformed trace.
int validate_trace_in(ValidateOptions& o, const octocd::ValidationOptions& vo, Clock::time_point t0) {
  if (o.check_only) {
    const octocd::ExternalTraceInfo info = octocd::check_external_trace(o.trace_in);
    // Opened as the judging opens it (states every K-th frame read as recorded): a trace
    // this line calls valid is one `validate --trace-in` judges, and the exit says so.
    const octocd::ExternalTrace trace(o.trace_in, octocd::TraceStates::Recorded);
    fmt::print("{}: valid external trace: engine '{}', {} bodies, {} frames, version {}; {}{}{}{}{}{}{}{}{}\n",
               octocd::printable(o.trace_in), octocd::printable(info.engine), info.bodies, info.frames, info.version,
               !info.has_states        ? ""
               : trace.sparse_states() ? fmt::format("states ({} of the {} frames) ", trace.state_frames().size() - 1,
                                                     info.frames)
                                       : std::string("states "),
               info.has_rotation ? "rotation " : "", info.has_aabbs ? "aabbs " : "", info.has_pairs ? "pairs " : "",
               info.has_contacts ? "contacts " : "", info.has_points ? "points " : "",
               info.has_point_b ? "point_b " : "", info.manifolds ? "manifolds " : "", info.has_scene ? "scene" : "");
    // Per row, without judging: judged (the trace carries what it needs) or n/a with what
    // to add (docs/validate-your-engine.md, "What a trace must carry").
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
    octocd::RunSession& session = *octocd::RunSession::current();
    session.keep("no frame judged, no verdict");
    const int code = session.stopped(sig, fmt::format(" while checking the trace {}", o.trace_in));
    if (!o.junit.empty())
      octocd::write_junit_error(o.junit, std::filesystem::path(o.trace_in).stem().string(), "stopped",
                                fmt::format("stopped by {} while checking the trace; no frame judged",
                                            octocd::stop_signal_name(sig)));
    return code;
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

}  // namespace octocd::cli
