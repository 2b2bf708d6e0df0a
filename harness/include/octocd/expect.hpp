#pragma once
/// \file expect.hpp
/// Verdicts that gate a CI (design.md sections 14b, 13b.13): a row's failures by cause, expectations
/// (known failures, `octocd validate --expect FILE.json`) matched against a run's results,
/// and the machine-readable output of `octocd validate --json`.
///
/// An expectations file (JSON, docs/validation-output.md):
///
///     {"expectations": [
///       {"scene": "bunny-stack-50", "row": "conservation", "cause": "energy",
///        "worst": 0.01, "reason": "Jacobi-averaged passes raise KE (design.md section 13b.13)"},
///       {"trace": "run.h5", "row": "penetration", "cause": "penetration",
///        "items": ["pair (3, 7)"], "worst": 0.03, "reason": "..."}]}
///
/// Each entry names its run by `scene` (the scene's name) or `trace` (the trace file's
/// name, without folders), a row, one of its causes, optionally the only items allowed to
/// fail, the worst figure allowed (in the cause's unit, >= 0) and a one-line reason. A
/// root key "comment" (a string) may say what the file is.

#include <cstdint>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "octocd/validation.hpp"

namespace octocd {

/// The causes of `r`'s failures, normalised: `r.causes` when the validator split them;
/// for a failing row without causes (the model tier today) one cause named like the row,
/// unit = the row's figure, worst = `measured`, count = `measured` when the row counts its
/// failures (bound 0 and `measured` a whole number >= 1), else 1. Empty for a row that
/// passed or is n/a. Causes with count 0 are left out.
std::vector<ValidationCause> failure_causes(const ValidationResult& r);

/// Every row name the validators produce (physics tier, then model tier): the names of
/// validation_rows() (octocd/validation_rows.hpp).
const std::vector<std::string>& validation_row_names();

/// The documented causes of `row` (design.md section 13b.13; its RowInfo::causes in
/// octocd/validation_rows.hpp), without the row-named fallback; empty for a row that does
/// not split its failures, or a name no row has.
std::vector<std::string> documented_causes(const std::string& row);

/// The share of a written expectation's figure left above the worst figure measured
/// (expectations_from): 0.1, so a recorded non-integer figure is at most 90% of its allowance.
inline constexpr double kExpectHeadroom = 0.1;

/// One known failure (an entry of an expectations file).
struct Expectation {
  std::string scene;   ///< the scene's name; "" when `trace` names the run
  std::string trace;   ///< the trace file's name (no folders); "" when `scene` names the run
  std::string row;     ///< a row of validation_row_names()
  std::string cause;   ///< a documented cause of the row, or the row's own name
  bool has_items = false;          ///< `items` given: only these items may fail
  std::vector<std::string> items;  ///< e.g. "pair (3, 7)", "body 4", "group (1, 2, 3)"
  double worst = 0;    ///< the worst figure allowed (the cause's unit), >= 0
  std::string reason;  ///< one line: why this failure is known and accepted
  /// "scene S" or "trace T", then "row/cause" (how messages name the entry).
  std::string label() const;
};

/// An expectations file, parsed.
struct Expectations {
  std::string path;                 ///< where it was read from ("" when built in memory)
  std::vector<Expectation> entries; ///< in file order
};

/// Parses expectations from JSON text; `origin` names the source in messages. Throws
/// InputError "ORIGIN: expectations[I] (FIELD): PROBLEM; allowed: ..." for text that is
/// not JSON, an entry without scene or trace (or with both), an unknown row or cause, a
/// negative or non-finite worst figure, a missing reason, items that are not strings, or
/// two entries for the same run, row and cause.
Expectations parse_expectations(const nlohmann::json& doc, const std::string& origin);
/// parse_expectations of `text` (JSON); text that is not JSON is an InputError.
Expectations parse_expectations_text(const std::string& text, const std::string& origin);
/// Reads `path` (InputError naming it when it cannot be read or is malformed).
Expectations load_expectations(const std::string& path);

/// The run an expectations entry names: a scene name or a trace file name.
struct RunName {
  std::string scene;  ///< the scene's name, or ""
  std::string trace;  ///< the trace's file name (folders stripped), or ""
  bool matches(const Expectation& e) const;
};
/// RunName of a trace path (its file name).
RunName trace_run(const std::string& trace_path);

/// What became of one failing cause or one expectation.
struct ExpectationOutcome {
  enum class Kind {
    Expected,  ///< a failure within its expectation (figure and items)
    New,       ///< a failure no expectation names
    Grown,     ///< an expected failure beyond its figure, or failing on items not listed
    Fixed,     ///< an expectation whose failure no longer occurs
  };
  Kind kind = Kind::New;
  std::string row, cause, unit;
  std::uint64_t count = 0;   ///< failing items of the cause (0 for Fixed)
  double worst = 0;          ///< the measured worst figure (0 for Fixed)
  double allowed = 0;        ///< the expectation's figure (New: the row's bound)
  std::vector<std::string> outside;  ///< failing items not listed by the expectation (Grown)
  std::string reason;        ///< the expectation's reason ("" for New)
  std::string first;         ///< the first example's text, or the row's detail
  /// One plain-text line: "expected row/cause: ...", "NEW FAILURE row/cause: measured X >
  /// bound Y ...", "GROWN row/cause: ...", "fixed row/cause: ... remove it from FILE".
  std::string text;
};
/// "expected", "new", "grown" or "fixed".
const char* outcome_name(ExpectationOutcome::Kind kind);

/// A run's results matched against expectations.
struct ExpectationReport {
  std::string file;  ///< the expectations file ("" when none was given)
  std::vector<ExpectationOutcome> outcomes;  ///< failing causes in row order, then Fixed ones
  std::size_t count(ExpectationOutcome::Kind kind) const;
  /// Row `name` failed and every failing cause of it is Expected.
  bool row_expected(const std::string& name) const;
  /// 0 when no cause is New or Grown (and, with `strict`, none is Fixed), else 3.
  int exit_code(bool strict) const;
};

/// Matches `results` of run `run` against the entries of `expect` naming that run: each
/// failing cause (failure_causes) is Expected (an entry for its row and cause, worst <=
/// its figure and, when the entry lists items, every failing item listed and the list
/// complete), Grown (an entry, but beyond it) or New (none); each entry of the run whose
/// cause does not fail is Fixed. Without expectations (`expect` empty) every failure is New.
ExpectationReport match_expectations(const Expectations& expect, const RunName& run,
                                     const std::vector<ValidationResult>& results);

/// The expectations that accept `results`' current failures of `run` (one per failing
/// cause; its figure: a whole-number worst exactly, any other worst divided by
/// 1 - kExpectHeadroom and rounded up to 3 significant digits; its items when complete; a
/// placeholder reason naming the worst and the allowance, to edit): what `--write-expect`
/// records.
std::vector<Expectation> expectations_from(const RunName& run, const std::vector<ValidationResult>& results);

/// JSON of expectations ({"expectations": [...]}, the file format above).
nlohmann::ordered_json expectations_json(const std::vector<Expectation>& entries);

/// `--write-expect PATH`: replaces the entries of `run` in PATH (kept when PATH exists and
/// parses; other runs' entries stay, so one file collects a whole scene set) by `entries`
/// and writes it (its `comment` kept). Throws InputError when an existing PATH is malformed, RuntimeError when
/// it cannot be written.
void write_expectations(const std::string& path, const RunName& run, const std::vector<Expectation>& entries);

/// The table's and JSON's verdict of a row: "pass", "fail", "n/a" or "expected" (every
/// failing cause Expected in `report`; `report` may be null).
std::string row_verdict(const ValidationResult& r, const ExpectationReport* report);

/// `octocd validate --json`: every row (tier, name, figure, measured, bound, verdict,
/// detail, judged, seconds, tolerances) with its causes (name, unit, count, worst,
/// examples (frame, item, figure, text), items, items_complete), and, when given, the
/// expectation outcomes. `run` names the run ("scene" or "trace"); `meta` adds keys
/// (engine, frames, ...). Non-finite figures are written as null.
nlohmann::ordered_json results_json(const std::vector<ValidationResult>& results, const RunName& run,
                            const ExpectationReport* report = nullptr,
                            const nlohmann::ordered_json& meta = nlohmann::ordered_json::object());

/// Writes `doc` (indented) to `path`; RuntimeError naming `what` and the path on failure.
void write_json_file(const std::string& path, const nlohmann::ordered_json& doc, const std::string& what);

}  // namespace octocd
