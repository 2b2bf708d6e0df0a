/// \file expect.cpp
/// Causes, expectations and `validate --json` (octocd/expect.hpp; design.md sections 13b.13, 14b).

#include "octocd/expect.hpp"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <set>
#include <sstream>

#include <fmt/format.h>

#include "octocd/atomic_file.hpp"
#include "octocd/error.hpp"
#include "octocd/json_strict.hpp"
#include "octocd/names.hpp"
#include "octocd/text.hpp"
#include "octocd/validation_rows.hpp"

namespace octocd {
namespace {

/// "%.6g" of a figure for messages (plain text).
std::string num(double v) { return fmt::format("{:.6g}", v); }

/// `v` (>= 0) rounded up to 3 significant digits: a written expectation's figure, readable
/// and never below the measured one.
double round_up(double v) {
  if (v <= 0) return 0;
  const double scale = std::pow(10.0, std::floor(std::log10(v)) - 2);
  const double r = std::ceil(v / scale) * scale;
  return r >= v ? r : std::nextafter(r, HUGE_VAL);
}

/// The figure a written expectation allows for a measured worst `v` (>= 0): a whole number
/// (a count of failing items or contacts, or an angle at its 180-degree maximum) exactly, any
/// other figure with kExpectHeadroom over it (v / (1 - kExpectHeadroom)), rounded up to 3
/// significant digits, so the figure measured is at most 90% of the allowance and a run on
/// another machine or compiler (float32 physics, design.md section 14b) does not flip the
/// expectation by a last-digit difference.
double allowance(double v) {
  if (v == std::floor(v)) return v;
  return round_up(v / (1.0 - kExpectHeadroom));
}

/// A figure for JSON: null when not finite (JSON has no NaN or inf).
nlohmann::ordered_json onumber(double v) {
  return std::isfinite(v) ? nlohmann::ordered_json(v) : nlohmann::ordered_json(nullptr);
}

}  // namespace

std::vector<ValidationCause> failure_causes(const ValidationResult& r) {
  std::vector<ValidationCause> out;
  if (!r.applicable || r.pass) return out;
  for (const ValidationCause& c : r.causes)
    if (c.count > 0) out.push_back(c);
  if (!out.empty()) return out;
  ValidationCause c;
  c.name = r.name;
  c.unit = r.figure;
  c.worst = r.measured;
  const bool counts = r.bound == 0 && std::isfinite(r.measured) && r.measured >= 1 &&
                      r.measured == std::floor(r.measured) && r.measured < 1e18;
  c.count = counts ? static_cast<std::uint64_t>(r.measured) : 1;
  c.examples.push_back(ValidationExample{-1, "", r.measured, r.detail});
  out.push_back(std::move(c));
  return out;
}

const std::vector<std::string>& validation_row_names() {
  static const std::vector<std::string> names = names_of(validation_rows());
  return names;
}

std::vector<std::string> documented_causes(const std::string& row) {
  const RowInfo* info = find_row_info(row);
  return info ? names_of(info->causes) : std::vector<std::string>{};
}

std::string Expectation::label() const {
  return fmt::format("{} {} {}/{}", scene.empty() ? "trace" : "scene", scene.empty() ? trace : scene, row, cause);
}

Expectations parse_expectations(const nlohmann::json& doc, const std::string& origin) {
  Expectations out;
  out.path = origin;
  if (!doc.is_object() || !doc.contains("expectations") || !doc["expectations"].is_array())
    throw InputError(fmt::format("{}: expected an object {{\"expectations\": [...]}}; allowed: the format of "
                                 "docs/validation-output.md",
                                 origin));
  for (const auto& [key, value] : doc.items())
    if (key != "expectations" && key != "comment")
      throw InputError(fmt::format("{}: unknown key '{}'; allowed: expectations, comment", origin, key));
  const nlohmann::json& list = doc["expectations"];
  std::set<std::string> seen;
  for (std::size_t i = 0; i < list.size(); ++i) {
    const nlohmann::json& e = list[i];
    auto bad = [&](const std::string& field, const std::string& problem) {
      return InputError(fmt::format("{}: expectations[{}] ({}): {}", origin, i, field, problem));
    };
    if (!e.is_object()) throw bad("entry", "not an object; allowed: {\"scene\"|\"trace\", \"row\", \"cause\", "
                                           "\"items\"?, \"worst\", \"reason\"}");
    for (const auto& [key, value] : e.items())
      if (key != "scene" && key != "trace" && key != "row" && key != "cause" && key != "items" && key != "worst" &&
          key != "reason")
        throw bad(key, "unknown key; allowed: scene, trace, row, cause, items, worst, reason");
    auto text = [&](const char* field, bool required) -> std::string {
      if (!e.contains(field)) {
        if (required) throw bad(field, "missing; allowed: a non-empty string");
        return "";
      }
      if (!e[field].is_string() || e[field].get<std::string>().empty())
        throw bad(field, "not a non-empty string");
      return e[field].get<std::string>();
    };
    Expectation x;
    x.scene = text("scene", false);
    x.trace = text("trace", false);
    if (x.scene.empty() == x.trace.empty())
      throw bad("scene/trace", "give exactly one of scene (a scene's name) or trace (a trace's file name)");
    x.row = text("row", true);
    const std::vector<std::string>& rows = validation_row_names();
    if (std::find(rows.begin(), rows.end(), x.row) == rows.end())
      throw bad("row", fmt::format("unknown row '{}'; allowed: {}", x.row, join_names(rows)));
    x.cause = text("cause", true);
    std::vector<std::string> causes = documented_causes(x.row);
    if (std::find(causes.begin(), causes.end(), x.row) == causes.end()) causes.push_back(x.row);
    if (std::find(causes.begin(), causes.end(), x.cause) == causes.end())
      throw bad("cause", fmt::format("unknown cause '{}' of row {}; allowed: {}", x.cause, x.row, join_names(causes)));
    if (e.contains("items")) {
      if (!e["items"].is_array()) throw bad("items", "not a list; allowed: a list of item strings");
      x.has_items = true;
      for (const auto& it : e["items"]) {
        if (!it.is_string()) throw bad("items", "an item that is not a string; allowed: e.g. \"pair (3, 7)\"");
        x.items.push_back(it.get<std::string>());
      }
      std::sort(x.items.begin(), x.items.end());
    }
    if (!e.contains("worst") || !e["worst"].is_number())
      throw bad("worst", "missing or not a number; allowed: the worst figure allowed, a finite number >= 0");
    x.worst = e["worst"].get<double>();
    if (!std::isfinite(x.worst) || x.worst < 0)
      throw bad("worst", fmt::format("{} is out of range; allowed: a finite number >= 0", x.worst));
    x.reason = text("reason", true);
    if (x.reason.find('\n') != std::string::npos) throw bad("reason", "not one line");
    if (!seen.insert(x.label()).second) throw bad("entry", fmt::format("a second entry for {}", x.label()));
    out.entries.push_back(std::move(x));
  }
  return out;
}

Expectations parse_expectations_text(const std::string& text, const std::string& origin) {
  // Strict: a key twice in one object (a second "tolerance" or "items") is refused, not
  // silently won by the last one; a NUL byte ends nothing.
  return parse_expectations(parse_json_strict(text, origin), origin);
}

Expectations load_expectations(const std::string& path) {
  // A regular file of at most 64 MiB, checked before it is read (a FIFO never blocks).
  return parse_expectations_text(read_input_file(path, "--expect", "an expectations file (JSON)"), path);
}

bool RunName::matches(const Expectation& e) const {
  return e.scene.empty() ? (!trace.empty() && e.trace == trace) : (!scene.empty() && e.scene == scene);
}

RunName trace_run(const std::string& trace_path) {
  return RunName{"", std::filesystem::path(trace_path).filename().string()};
}

const char* outcome_name(ExpectationOutcome::Kind kind) {
  switch (kind) {
    case ExpectationOutcome::Kind::Expected: return "expected";
    case ExpectationOutcome::Kind::New: return "new";
    case ExpectationOutcome::Kind::Grown: return "grown";
    case ExpectationOutcome::Kind::Fixed: return "fixed";
  }
  return "";
}

std::size_t ExpectationReport::count(ExpectationOutcome::Kind kind) const {
  return static_cast<std::size_t>(
      std::count_if(outcomes.begin(), outcomes.end(), [&](const ExpectationOutcome& o) { return o.kind == kind; }));
}

bool ExpectationReport::row_expected(const std::string& name) const {
  bool any = false;
  for (const ExpectationOutcome& o : outcomes) {
    if (o.row != name || o.kind == ExpectationOutcome::Kind::Fixed) continue;
    if (o.kind != ExpectationOutcome::Kind::Expected) return false;
    any = true;
  }
  return any;
}

int ExpectationReport::exit_code(bool strict) const {
  if (count(ExpectationOutcome::Kind::New) > 0 || count(ExpectationOutcome::Kind::Grown) > 0) return 3;
  if (strict && count(ExpectationOutcome::Kind::Fixed) > 0) return 3;
  return 0;
}

ExpectationReport match_expectations(const Expectations& expect, const RunName& run,
                                     const std::vector<ValidationResult>& results) {
  ExpectationReport report;
  report.file = expect.path;
  std::vector<const Expectation*> mine;
  for (const Expectation& e : expect.entries)
    if (run.matches(e)) mine.push_back(&e);
  std::set<const Expectation*> used;
  for (const ValidationResult& r : results) {
    for (const ValidationCause& c : failure_causes(r)) {
      ExpectationOutcome o;
      o.row = r.name;
      o.cause = c.name;
      o.unit = c.unit;
      o.count = c.count;
      o.worst = c.worst;
      o.first = c.examples.empty() ? r.detail : c.examples.front().text;
      const auto it = std::find_if(mine.begin(), mine.end(), [&](const Expectation* e) {
        return e->row == r.name && e->cause == c.name;
      });
      if (it == mine.end()) {
        o.kind = ExpectationOutcome::Kind::New;
        o.allowed = r.bound;
        // A cause of its own (one of a row's several) gives its figure: the row's may be within
        // its bound when another cause failed the row.
        o.text = c.name == r.name
                     ? fmt::format("NEW FAILURE {}/{}: measured {} > bound {} ({}; {} item(s)): {}", o.row, o.cause,
                                   num(r.measured), num(r.bound), r.figure, c.count, o.first)
                     : fmt::format("NEW FAILURE {}/{}: worst {}{}{} ({} item(s); the row's {}: {} of bound {}): {}",
                                   o.row, o.cause, num(c.worst), c.unit.empty() ? "" : " ", c.unit, c.count,
                                   r.figure, num(r.measured), num(r.bound), o.first);
      } else {
        const Expectation& e = **it;
        used.insert(&e);
        o.allowed = e.worst;
        o.reason = bounded(e.reason);
        if (e.has_items) {
          for (const std::string& item : c.items)
            if (!std::binary_search(e.items.begin(), e.items.end(), item)) o.outside.push_back(item);
          if (!c.items_complete) o.outside.push_back("(more items than recorded)");
        }
        const bool grown = !(c.worst <= e.worst) || !o.outside.empty();  // NaN grows
        o.kind = grown ? ExpectationOutcome::Kind::Grown : ExpectationOutcome::Kind::Expected;
        if (grown) {
          o.text = fmt::format("GROWN {}/{}: worst {} {} allowed {} {}({} item(s)){}: {}", o.row, o.cause, num(c.worst),
                               c.worst <= e.worst ? "<=" : ">", num(e.worst), c.unit.empty() ? "" : c.unit + " ",
                               c.count, o.outside.empty() ? "" : "; items not listed: " + join_names(o.outside),
                               o.first);
        } else {
          o.text = fmt::format("expected {}/{}: worst {} <= allowed {} {}({} item(s)); reason: {}", o.row, o.cause,
                               num(c.worst), num(e.worst), c.unit.empty() ? "" : c.unit + " ", c.count, bounded(e.reason));
        }
      }
      report.outcomes.push_back(std::move(o));
    }
  }
  for (const Expectation* e : mine) {
    if (used.count(e)) continue;
    ExpectationOutcome o;
    o.kind = ExpectationOutcome::Kind::Fixed;
    o.row = e->row;
    o.cause = e->cause;
    o.allowed = e->worst;
    o.reason = bounded(e->reason);
    const auto row = std::find_if(results.begin(), results.end(),
                                  [&](const ValidationResult& r) { return r.name == e->row; });
    const std::string state = row == results.end() ? "the row was not produced"
                              : !row->applicable   ? "the row judged nothing (n/a)"
                                                   : "no longer fails";
    o.text = fmt::format("fixed {}/{}: {}: remove it from {}", o.row, o.cause, state,
                         expect.path.empty() ? "the expectations" : expect.path);
    report.outcomes.push_back(std::move(o));
  }
  return report;
}

std::vector<Expectation> expectations_from(const RunName& run, const std::vector<ValidationResult>& results) {
  std::vector<Expectation> out;
  for (const ValidationResult& r : results) {
    for (const ValidationCause& c : failure_causes(r)) {
      Expectation e;
      e.scene = run.scene;
      e.trace = run.scene.empty() ? run.trace : "";
      e.row = r.name;
      e.cause = c.name;
      e.worst = std::isfinite(c.worst) ? allowance(std::max(c.worst, 0.0)) : 0.0;
      if (c.items_complete && !c.items.empty()) {
        e.has_items = true;
        e.items = c.items;
      }
      e.reason = fmt::format("TODO: say why this is accepted ({} item(s), worst {}, allowed {}; first: {})", c.count,
                             num(c.worst), num(e.worst), c.examples.empty() ? r.detail : c.examples.front().text);
      std::replace(e.reason.begin(), e.reason.end(), '\n', ' ');
      out.push_back(std::move(e));
    }
  }
  return out;
}

nlohmann::ordered_json expectations_json(const std::vector<Expectation>& entries) {
  nlohmann::ordered_json list = nlohmann::ordered_json::array();
  for (const Expectation& e : entries) {
    nlohmann::ordered_json j = nlohmann::ordered_json::object();
    if (!e.scene.empty()) j["scene"] = e.scene;
    else j["trace"] = e.trace;
    j["row"] = e.row;
    j["cause"] = e.cause;
    if (e.has_items) j["items"] = e.items;
    j["worst"] = e.worst;
    j["reason"] = e.reason;
    list.push_back(std::move(j));
  }
  return nlohmann::ordered_json{{"expectations", list}};
}

void write_expectations(const std::string& path, const RunName& run, const std::vector<Expectation>& entries) {
  std::vector<Expectation> all;
  std::string comment;
  std::error_code ec;
  if (std::filesystem::exists(std::filesystem::symlink_status(path, ec))) {
    check_output_file(path, "--write-expect");  // a regular file: a FIFO is never opened
    const std::string text = read_input_file(path, "--write-expect", "an expectations file (JSON) to add to");
    for (Expectation& e : parse_expectations_text(text, path).entries)
      if (!run.matches(e)) all.push_back(std::move(e));
    const nlohmann::json old = nlohmann::json::parse(text, nullptr, false);
    if (old.is_object() && old.contains("comment") && old["comment"].is_string()) comment = old["comment"];
  }
  all.insert(all.end(), entries.begin(), entries.end());
  nlohmann::ordered_json doc = nlohmann::ordered_json::object();
  if (!comment.empty()) doc["comment"] = comment;  // the file's own note stays
  doc["expectations"] = expectations_json(all)["expectations"];
  write_json_file(path, doc, "--write-expect");
}

std::string row_verdict(const ValidationResult& r, const ExpectationReport* report) {
  if (!r.applicable) return "n/a";
  if (r.pass) return "pass";
  return report && report->row_expected(r.name) ? "expected" : "fail";
}

nlohmann::ordered_json results_json(const std::vector<ValidationResult>& results, const RunName& run,
                            const ExpectationReport* report, const nlohmann::ordered_json& meta) {
  nlohmann::ordered_json doc = nlohmann::ordered_json::object();
  if (!run.scene.empty()) doc["scene"] = run.scene;
  if (!run.trace.empty()) doc["trace"] = run.trace;
  for (const auto& [k, v] : meta.items()) doc[k] = v;
  nlohmann::ordered_json rows = nlohmann::ordered_json::array();
  for (const ValidationResult& r : results) {
    nlohmann::ordered_json j = {{"tier", tier_name(r.tier)},
                        {"name", r.name},
                        {"figure", r.figure},
                        {"measured", onumber(r.measured)},
                        {"bound", onumber(r.bound)},
                        {"verdict", row_verdict(r, report)},
                        {"detail", r.detail},
                        {"judged", r.judged},
                        {"seconds", onumber(r.seconds)},
                        {"tolerances", r.tolerances}};
    nlohmann::ordered_json causes = nlohmann::ordered_json::array();
    for (const ValidationCause& c : failure_causes(r)) {
      nlohmann::ordered_json examples = nlohmann::ordered_json::array();
      for (const ValidationExample& x : c.examples)
        examples.push_back({{"frame", x.frame}, {"item", x.item}, {"figure", onumber(x.figure)}, {"text", x.text}});
      causes.push_back({{"name", c.name},
                        {"unit", c.unit},
                        {"count", c.count},
                        {"worst", onumber(c.worst)},
                        {"examples", examples},
                        {"items", c.items},
                        {"items_complete", c.items_complete}});
    }
    j["causes"] = causes;
    rows.push_back(std::move(j));
  }
  doc["rows"] = rows;
  if (report) {
    nlohmann::ordered_json e = {{"file", report->file}};
    nlohmann::ordered_json list = nlohmann::ordered_json::array();
    for (const ExpectationOutcome& o : report->outcomes)
      list.push_back({{"outcome", outcome_name(o.kind)},
                      {"row", o.row},
                      {"cause", o.cause},
                      {"unit", o.unit},
                      {"count", o.count},
                      {"worst", onumber(o.worst)},
                      {"allowed", onumber(o.allowed)},
                      {"outside", o.outside},
                      {"reason", o.reason},
                      {"text", o.text}});
    e["outcomes"] = list;
    doc["expectations"] = e;
  }
  return doc;
}

void write_json_file(const std::string& path, const nlohmann::ordered_json& doc, const std::string& what) {
  // Text from a trace (an engine's name, a file name) may hold bytes that are not UTF-8.
  write_file_atomically(path, doc.dump(2, ' ', false, nlohmann::ordered_json::error_handler_t::replace) + "\n", what);  // no half or 0-byte file on a full disk
}

}  // namespace octocd
