// What a verdict of `octocd validate` becomes (validate_parts.hpp): JUnit, --json (also
// of a stopped run), --expect's outcome lines, --write-expect and the exit code; --merge
// of shards' verdicts.
#include "validate_parts.hpp"

#include <chrono>
#include <cstdio>
#include <cstring>
#include <string>
#include <string_view>
#include <vector>
#include <functional>
#include <filesystem>
#include <fmt/format.h>
#include <nlohmann/json.hpp>
#include "octocd/expect.hpp"
#include "octocd/junit.hpp"
#include "octocd/results_table.hpp"
#include "octocd/shards.hpp"
#include "octocd/atomic_file.hpp"
#include "octocd/text.hpp"
#include "octocd/validation.hpp"
#include "octocd/version.hpp"
#include "command_support.hpp"
#include "view.hpp"

namespace octocd::cli {

namespace {

/// Whether --view's pages could not be written (FailureViews::write_error): then says so
/// on stderr, after the verdict (which stands), and `validate` exits 1.
bool views_failed(const ValidateOptions& o) {
  if (o.views.write_error.empty()) return false;
  std::fflush(stdout);
  std::fprintf(stderr, "octocd: %s\n", o.views.write_error.c_str());
  return true;
}

}  // namespace

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

}  // namespace octocd::cli
