// The history of nightly results (design.md section 21; docs/regression.md): `octocd
// history-append DIR` and `octocd bench --history DIR` add one file per run to a history
// folder (bench results, the verdicts of `validate --json`, the machine, the build, the
// date). A file is written under a temporary name and linked to its final name, which must
// not exist: nothing in the folder is ever rewritten. `octocd report --history DIR` reads it
// (report/report_history.py).
#include <fcntl.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <map>
#include <set>

#include <fmt/format.h>

#include "octocd/error.hpp"
#include "octocd/json_fields.hpp"
#include "octocd/json_strict.hpp"
#include "octocd/stop.hpp"
#include "octocd/text.hpp"
#include "octocd/version.hpp"
#include "tools.hpp"

namespace octocd::cli {

namespace {

namespace fs = std::filesystem;
using json = nlohmann::json;

constexpr std::size_t kMaxName = 4096;     ///< bytes of a scene, engine, row or cause name kept
constexpr std::size_t kMaxReason = 2000;   ///< bytes of an expectation's reason or an outcome's text kept
constexpr std::size_t kMaxRows = 10000;    ///< rows of one validation (octocd writes about 20)
constexpr std::size_t kMaxOutcomes = 10000;

/// `text` cut to `max_bytes` bytes at a UTF-8 character boundary.
std::string bounded(std::string text, std::size_t max_bytes) {
  if (text.size() <= max_bytes) return text;
  std::size_t n = max_bytes;
  while (n > 0 && (static_cast<unsigned char>(text[n]) & 0xC0) == 0x80) --n;
  text.resize(n);
  return text;
}

/// [A-Za-z0-9._-] of `text` (others as '_'), at most 40 characters, "unknown" when empty:
/// the commit in a file name.
std::string file_safe(const std::string& text) {
  std::string out;
  for (char c : text) {
    if (out.size() >= 40) break;
    const bool ok = (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') || c == '.' ||
                    c == '-' || c == '_';
    out += ok ? c : '_';
  }
  return out.empty() ? std::string("unknown") : out;
}

/// ENGINE and SCENE of a matrix trace named ENGINE--SCENE[--quick].h5 (scripts/nightly.sh).
std::pair<std::string, std::string> engine_scene_of_trace(const std::string& trace, const std::string& engine) {
  std::string stem = fs::path(trace).filename().string();
  if (stem.size() > 3 && stem.compare(stem.size() - 3, 3, ".h5") == 0) stem.resize(stem.size() - 3);
  const auto sep = stem.find("--");
  if (sep == std::string::npos) return {engine, stem};
  return {stem.substr(0, sep), stem.substr(sep + 2)};
}

/// Whether `t` is a UTC time as octocd writes one (YYYY-MM-DDTHH:MM:SSZ) with fields in range.
bool is_utc_time(const std::string& t) {
  if (t.size() != 20 || t[4] != '-' || t[7] != '-' || t[10] != 'T' || t[13] != ':' || t[16] != ':' || t[19] != 'Z')
    return false;
  for (int i : {0, 1, 2, 3, 5, 6, 8, 9, 11, 12, 14, 15, 17, 18})
    if (t[static_cast<std::size_t>(i)] < '0' || t[static_cast<std::size_t>(i)] > '9') return false;
  const auto at = [&](int i, int n) { return std::stoi(t.substr(static_cast<std::size_t>(i), static_cast<std::size_t>(n))); };
  return at(5, 2) >= 1 && at(5, 2) <= 12 && at(8, 2) >= 1 && at(8, 2) <= 31 && at(11, 2) <= 23 && at(14, 2) <= 59 &&
         at(17, 2) <= 60;
}

/// The build of a result's "build" object as a history file records it ({"build_id",
/// "git_revision", "version", "commit"}), or null when it names none.
json build_of_result(const JsonFields& f, const json& r, const std::string& where) {
  if (!r.contains("build")) return nullptr;
  const json& b = f.object(r["build"], where + "build");
  json out = json::object();
  for (const char* k : {"build_id", "git_revision"})
    if (b.contains(k)) out[k] = f.text(b[k], where + "build." + k, kMaxName);
  const std::string id = out.value("build_id", std::string());
  if (id.empty() && out.value("git_revision", std::string()).empty()) return nullptr;
  const auto plus = id.find('+');
  out["version"] = plus == std::string::npos ? id : id.substr(0, plus);
  out["commit"] = plus == std::string::npos ? out.value("git_revision", std::string()) : id.substr(plus + 1);
  return out;
}

/// The date and build a history entry carries, from the run's own results.
struct HistoryStamp {
  std::string date;        ///< the earliest "started" of the results (UTC), "" when there is none
  json build;              ///< the results' build ({build_id, git_revision, version, commit}) or null
  std::string build_from;  ///< the result that gave `build`
};

/// The run's start and build from bench results `bench` (named `names`, else bench[i]):
/// the earliest "started" and their one build. InputError naming the file and field for a
/// "started" that is missing or no UTC time YYYY-MM-DDTHH:MM:SSZ, or results of two builds.
HistoryStamp history_stamp(const json& bench, const std::vector<std::string>& names) {
  HistoryStamp s;
  for (std::size_t i = 0; i < bench.size(); ++i) {
    const std::string name = i < names.size() ? names[i] : fmt::format("bench[{}]", i);
    const JsonFields f(name);
    const json& r = bench[i];
    const std::string allowed = "a result of `octocd bench` (docs/bench-format.md)";
    const std::string started = f.text(f.member(r, "", "started", allowed), "started", 64);
    if (!is_utc_time(started))
      throw InputError(fmt::format("{}: started: '{}'; allowed: a UTC time YYYY-MM-DDTHH:MM:SSZ (the run's start, "
                                   "as octocd bench writes it)", printable(name), printable(started)));
    if (s.date.empty() || started < s.date) s.date = started;  // the run began with its first result
    const json build = build_of_result(f, r, "");
    if (build.is_null()) continue;
    if (s.build.is_null()) {
      s.build = build;
      s.build_from = name;
    } else if (build.value("build_id", std::string()) != s.build.value("build_id", std::string()) ||
               build.value("git_revision", std::string()) != s.build.value("git_revision", std::string())) {
      throw InputError(fmt::format("{}: build: {} ({}); {} has {} ({}); allowed: results of one build in one run",
                                   printable(name), printable(build.value("build_id", std::string())),
                                   printable(build.value("git_revision", std::string())), printable(s.build_from),
                                   printable(s.build.value("build_id", std::string())),
                                   printable(s.build.value("git_revision", std::string()))));
    }
  }
  return s;
}

}  // namespace

json history_build() {
  json b = build_description();
  const std::string id = build_id();
  const auto plus = id.find('+');
  b["version"] = plus == std::string::npos ? id : id.substr(0, plus);
  b["commit"] = plus == std::string::npos ? b.value("git_revision", std::string()) : id.substr(plus + 1);
  return b;
}

json history_verdicts(const std::string& path) {
  const JsonFields f(path);
  const json doc = parse_json_strict(
      read_input_file(path, "--validation", "a verdict of `octocd validate --json` (docs/validation-output.md)"), path);
  const std::string allowed = "a verdict of `octocd validate --json` (docs/validation-output.md)";
  f.object(doc, "(the document)");
  const std::string engine = f.text(f.member(doc, "", "engine", allowed), "engine", kMaxName);
  std::string scene, eng = engine;
  if (doc.contains("scene")) {
    scene = f.text(doc["scene"], "scene", kMaxName);
  } else {
    const std::string trace = f.text(f.member(doc, "", "trace", allowed + " (a \"scene\" or a \"trace\")"), "trace", kMaxName);
    std::tie(eng, scene) = engine_scene_of_trace(trace, engine);
  }
  // Outcomes of the expectations by row: new and grown failures, expected ones, fixed ones.
  std::map<std::string, std::vector<json>> by_row;
  if (doc.contains("expectations")) {
    const json& ex = f.object(doc["expectations"], "expectations");
    if (ex.contains("outcomes")) {
      const json& outs = f.array(ex["outcomes"], "expectations.outcomes", kMaxOutcomes);
      for (std::size_t i = 0; i < outs.size(); ++i) {
        const std::string at = fmt::format("expectations.outcomes[{}]", i);
        const json& o = f.object(outs[i], at);
        const std::string kind = f.one_of(f.member(o, at, "outcome", allowed), at + ".outcome",
                                          {"new", "grown", "expected", "fixed"});
        json rec = {{"outcome", kind},
                    {"cause", o.contains("cause") ? f.text(o["cause"], at + ".cause", kMaxName) : std::string()}};
        for (const char* k : {"worst", "allowed"})
          if (o.contains(k) && o[k].is_number()) rec[k] = o[k];
        if (o.contains("reason") && o["reason"].is_string()) rec["reason"] = bounded(o["reason"].get<std::string>(), kMaxReason);
        by_row[f.text(f.member(o, at, "row", allowed), at + ".row", kMaxName)].push_back(std::move(rec));
      }
    }
  }
  json out = json::array();
  const json& rows = f.array(f.member(doc, "", "rows", allowed), "rows", kMaxRows);
  std::set<std::string> seen;
  for (std::size_t i = 0; i < rows.size(); ++i) {
    const std::string at = fmt::format("rows[{}]", i);
    const json& r = f.object(rows[i], at);
    const std::string name = f.text(f.member(r, at, "name", allowed), at + ".name", kMaxName);
    const std::string verdict = f.one_of(f.member(r, at, "verdict", allowed), at + ".verdict",
                                         {"pass", "fail", "n/a", "expected"});
    seen.insert(name);
    const std::vector<json>& outs = by_row[name];
    const auto has = [&](const char* k) {
      for (const json& o : outs)
        if (o["outcome"] == k) return true;
      return false;
    };
    // The row's status over nights: a failure no expectation covers (or beyond its figure)
    // is new; a failure within its expectations expected; a pass whose expectation no
    // longer fails fixed.
    std::string status = verdict;
    if (verdict == "fail") status = "new";
    if (has("new") || has("grown")) status = "new";
    else if (verdict == "expected") status = "expected";
    else if (verdict == "pass" && has("fixed")) status = "fixed";
    json row = {{"engine", eng}, {"scene", scene}, {"row", name}, {"verdict", verdict}, {"status", status}};
    if (r.contains("tier") && r["tier"].is_string()) row["tier"] = bounded(r["tier"].get<std::string>(), kMaxName);
    if (!outs.empty()) row["expectations"] = outs;
    out.push_back(std::move(row));
  }
  // An outcome of a row the run did not list (an expectation of a row no longer judged).
  for (const auto& [name, outs] : by_row)
    if (!seen.count(name) && !outs.empty())
      out.push_back({{"engine", eng}, {"scene", scene}, {"row", name}, {"verdict", "n/a"},
                     {"status", outs.front()["outcome"] == "fixed" ? "fixed" : "n/a"}, {"expectations", outs}});
  return out;
}

// The entry's "date" and "build" are the run's own (history_stamp of `bench`: a backfill of
// archived results keeps each run's start and commit); without a result (verdicts alone) the
// appending binary's history_build and now. "dated_by" says which ("result" or "append"),
// "appended" {"date", "build"} when and by what the file was added.
std::string append_history(const std::string& dir, const std::string& kind, json bench, json verdicts,
                           const std::string& label) {
  std::error_code ec;
  check_output_folder(dir, label.c_str(), true);
  // The run's own start and build from its results (a backfill keeps its date and commit);
  // the appending binary's build and now only for a run without a result (verdicts alone).
  const HistoryStamp run = history_stamp(bench, {});
  fs::create_directories(dir, ec);
  if (ec) throw RuntimeError(fmt::format("{}: {}: cannot create the folder: {}", label, dir, ec.message()));
  const json appender = history_build();
  const std::string now = utc_time_now();
  const json build = run.build.is_null() ? appender : run.build;
  const std::string date = run.date.empty() ? now : run.date;
  json entry = {{"format", "octocd-history"}, {"version", 1}, {"kind", kind}, {"date", date},
                {"build", build}, {"machine", machine_description()},
                {"dated_by", run.date.empty() ? "append" : "result"},
                {"appended", {{"date", now}, {"build", appender}}},
                {"bench", std::move(bench)}, {"verdicts", std::move(verdicts)}};
  const std::string text = entry.dump(1, ' ', false, json::error_handler_t::replace) + "\n";
  // YYYYMMDDTHHMMSSZ-COMMIT-KIND.json: sorted by name is sorted by date.
  std::string stamp;
  for (char c : date)
    if (c != '-' && c != ':') stamp += c;
  const std::string base = fmt::format("{}-{}-{}", stamp, file_safe(build.value("commit", std::string())), kind);
  const std::string first = (fs::path(dir) / (base + ".json")).string();
  const TemporaryFile tmp = create_temporary_beside(first, label);
  const TrackedTemporary tracked(tmp.path);  // until it is linked, a stop removes it too
  std::size_t done = 0;
  while (done < text.size()) {
    const ssize_t n = ::write(tmp.fd, text.data() + done, text.size() - done);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) {
      const int err = errno;
      ::close(tmp.fd);
      ::unlink(tmp.path.c_str());
      throw RuntimeError(fmt::format("{}: {}: writing failed: {}; the history is left as it was", label, tmp.path,
                                     std::strerror(err)));
    }
    done += static_cast<std::size_t>(n);
  }
  const bool synced = ::fsync(tmp.fd) == 0;
  ::close(tmp.fd);
  if (!synced) {
    ::unlink(tmp.path.c_str());
    throw RuntimeError(fmt::format("{}: {}: fsync failed; the history is left as it was", label, tmp.path));
  }
  // link(2) never replaces a file: a name taken (two runs in one second) gets -2, -3, ...
  for (int k = 1; k < 1000; ++k) {
    const std::string target =
        k == 1 ? first : (fs::path(dir) / fmt::format("{}-{}.json", base, k)).string();
    if (::link(tmp.path.c_str(), target.c_str()) == 0) {
      ::unlink(tmp.path.c_str());
      return target;
    }
    if (errno != EEXIST) {
      const int err = errno;
      ::unlink(tmp.path.c_str());
      throw RuntimeError(fmt::format("{}: {}: cannot add the file: {}; the history is left as it was", label, target,
                                     std::strerror(err)));
    }
  }
  ::unlink(tmp.path.c_str());
  throw RuntimeError(fmt::format("{}: {}: 999 files of this second and commit already; the history is left as it was",
                                 label, first));
}

CLI::App* add_history_append_command(CLI::App& app, HistoryAppendOptions& o) {
  CLI::App* c = add_table_command(app, CommandId::history_append);
  c->add_option("dir", o.dir, "The history folder (created)")->required();
  c->add_option("--bench", o.bench, "Result files of `octocd bench` (.json) to add (repeatable)");
  c->add_option("--validation", o.validation,
                "Verdicts of `octocd validate --json` (.json) to add (repeatable; a matrix trace ENGINE--SCENE.h5 "
                "gives its engine and scene)");
  c->add_option("--errored", o.errored,
                "Cases that gave no verdict (a run that crashed, timed out or was bad input), named as scripts/nightly.sh "
                "names them: SCENE (engine cpu) or ENGINE--SCENE[--quick]; each is one row `run` of status error "
                "(repeatable)");
  c->add_option("--kind", o.kind, "What made the run: nightly (default) or bench")
      ->check(CLI::IsMember({"nightly", "bench"}));
  return c;
}

int history_append_command(const HistoryAppendOptions& o) {
  check_output_folder(o.dir, "history-append", true);  // before any input is read
  json bench = json::array(), verdicts = json::array();
  for (const auto& p : o.bench) {
    json r = parse_json_strict(read_input_file(p, "--bench", "a result of `octocd bench` (.json)"), p);
    if (!r.is_object() || r.value("format", std::string()) != "octocd-bench")
      throw InputError(fmt::format("--bench: {}: format: not octocd-bench; allowed: a result of `octocd bench` (.json)",
                                   printable(p)));
    bench.push_back(std::move(r));
  }
  for (const auto& p : o.validation)
    for (auto& row : history_verdicts(p)) verdicts.push_back(std::move(row));
  for (const auto& name : o.errored) {
    const auto [engine, scene] = engine_scene_of_trace(name + ".h5", "cpu");
    verdicts.push_back({{"engine", bounded(engine, kMaxName)}, {"scene", bounded(scene, kMaxName)}, {"row", "run"},
                        {"verdict", "error"}, {"status", "error"}});
  }
  const std::size_t rows = verdicts.size();
  (void)history_stamp(bench, o.bench);  // a bad start or two builds: exit 2 naming the file, nothing written
  const std::string path = append_history(o.dir, o.kind, std::move(bench), std::move(verdicts), "history-append");
  fmt::print("octocd history-append: wrote {} ({} bench result(s), {} verdict row(s))\n", printable(path),
             o.bench.size(), rows);
  return 0;
}

}  // namespace octocd::cli
