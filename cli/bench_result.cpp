// The result file of `octocd bench` (bench_sweep.hpp, docs/bench-format.md): its header
// (sweep, settings, machine, build), the checks before --resume keeps a file's finished
// points, the timing hygiene recorded with it, and a sweep's stop or end.
#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>

#include <fmt/format.h>

#include "bench_sweep.hpp"
#include "octocd/atomic_file.hpp"
#include "octocd/error.hpp"
#include "octocd/json_fields.hpp"
#include "octocd/json_strict.hpp"
#include "octocd/stop.hpp"
#include "octocd/timing_limits.hpp"

namespace octocd::cli::bench {

namespace fs = std::filesystem;

json result_settings(const Sweep& s, int shard, int shards) {
  json settings{{"engines", s.engines},
                {"repeat", s.repeat},
                {"frames", s.frames},
                {"warmup", s.warmup},
                {"shard", {{"index", shard}, {"count", shards}}}};
  if (s.kind == "steps" || s.kind == "speed-accuracy") {
    settings["protocol"] = s.protocol;
    settings["min_time_s"] = std::max(s.min_time_s, 0.0);
    settings["max_time_s"] = std::max(s.max_time_s, 0.0);
  }
  if (s.kind == "broadphase") {
    settings["warm_replays"] = s.warm_replays;
    settings["min_time_ms"] = s.min_time_ms;
  }
  if (s.kind == "max-instances") {
    settings["probe_repeat"] = s.probe_repeat;
    settings["target_steps_per_s"] = s.target;
    settings["max_instances"] = s.max_instances;
    settings["resolution"] = s.resolution;
    settings["search_time_s"] = s.search_time_s;
    settings["window"] = {{"name", s.windows[0].name}, {"first", s.windows[0].first}, {"last", s.windows[0].last}};
  }
  return settings;
}

json new_result(const Sweep& s, const std::string& origin, const json& def, const json& settings,
                std::size_t points_total) {
  json result{{"format", "octocd-bench"},
              {"version", 1},
              {"sweep", {{"name", s.name}, {"kind", s.kind}, {"description", s.description}, {"origin", origin},
                         {"definition", def}}},
              {"settings", settings},
              {"machine", machine_description()},
              {"build", build_description()},
              {"started", utc_time_now()},
              {"points_total", points_total},
              {"complete", false},
              {"points", json::array()}};
  return result;
}

namespace {

constexpr std::size_t kMaxName = 4096;      ///< bytes of an id, a host or CPU name in a result
constexpr std::size_t kMaxRepeat = 1000;    ///< repetitions of a spread (a sweep's repeat is at most 1000)

/// Checks a spread {n, median, min, max, values, ...} of a kept point (`at` names it).
void check_spread(const JsonFields& f, const json& v, const std::string& at) {
  f.object(v, at);
  f.count(f.member(v, at, "n", "a spread {n, median, min, max, values} (docs/bench-format.md)"), at + ".n", kMaxRepeat);
  for (const char* k : {"median", "min", "max", "mean", "stdev"})
    if (v.contains(k)) (void)f.number_or_null(v[k], at + "." + k, -1e300, 1e300);
  if (v.contains("values")) {
    const json& vals = f.array(v["values"], at + ".values", kMaxRepeat);
    for (std::size_t i = 0; i < vals.size(); ++i)
      (void)f.number_or_null(vals[i], fmt::format("{}.values[{}]", at, i), -1e300, 1e300);
  }
}

/// A kept point's timing spread (steps_per_s, cpu_steps_per_s, world_steps_per_s,
/// ms_per_frame): as check_spread, and its median, min, max and values each 0 (not
/// measured) or in [limits::kMinTiming, limits::kMaxTiming], the figures a run of bench
/// writes (check_point_timings): a resumed result keeps no figure bench would not write.
void check_timing_spread(const JsonFields& f, const json& v, const std::string& at) {
  check_spread(f, v, at);
  const auto one = [&](const json& x, const std::string& where) {
    const double t = x.is_number() ? x.get<double>() : std::nan("");
    if (t == 0.0 || (std::isfinite(t) && t >= limits::kMinTiming && t <= limits::kMaxTiming)) return;
    f.fail(where, x.is_null() ? "null" : x.dump().substr(0, 60),
           fmt::format("0 (not measured) or a timing from {:g} to {:g}, as bench writes them", limits::kMinTiming,
                       limits::kMaxTiming));
  };
  for (const char* k : {"median", "min", "max"})
    if (v.contains(k)) one(v[k], at + "." + k);
  if (v.contains("values"))
    for (std::size_t i = 0; i < v["values"].size(); ++i) one(v["values"][i], fmt::format("{}.values[{}]", at, i));
}

}  // namespace

std::map<std::string, json> resumable_points(const json& old, const std::string& path, const Sweep& s,
                                             const std::string& origin, const json& def,
                                             const std::vector<Point>& points, json& result) {
  std::map<std::string, json> kept;
  const JsonFields f(path);
  const json& settings = result["settings"];
  if (!old.is_object()) f.fail("(the document)", json_type_text(old) + ", not an object", "a result of octocd bench");
  const std::string allowed = "a result of octocd bench (docs/bench-format.md) to resume";
  const auto key = [&](const char* k) -> const json& { return f.member(old, "", k, allowed); };
  const json& format = key("format");
  const json& version = key("version");
  if (format != "octocd-bench" || version != 1)
    throw InputError(fmt::format("{}: format: {} version {}; allowed: octocd-bench version 1", path,
                                 format.dump().substr(0, 60), version.dump().substr(0, 20)));
  const json& sweep = f.object(key("sweep"), "sweep");
  if (f.member(sweep, "sweep", "definition", allowed) != def)
    throw InputError(fmt::format("{}: sweep.definition: another sweep ('{}'); allowed: a result of the same sweep "
                                 "definition to resume",
                                 path, sweep.contains("name") ? f.text(sweep["name"], "sweep.name", kMaxName) : "?"));
  if (key("settings") != settings)
    throw InputError(fmt::format("{}: settings: {}; allowed: the same engines, repeat and shard as now ({})", path,
                                 old["settings"].dump().substr(0, 400), settings.dump()));
  const json& machine = f.object(key("machine"), "machine");
  for (const char* k : {"hostname", "cpu", "gpu"}) {
    const std::string mine = result["machine"].value(k, "");
    const std::string theirs =
        machine.contains(k) ? f.text(machine[k], std::string("machine.") + k, kMaxName) : std::string();
    if (theirs != mine)
      throw InputError(fmt::format("{}: machine.{}: '{}'; allowed: a result measured on this machine ('{}') to "
                                   "resume",
                                   path, k, theirs, mine));
  }
  if (old.contains("started")) result["started"] = f.text(old["started"], "started", 64);
  const json& pts = f.array(key("points"), "points", kMaxPoints);
  std::map<std::string, const Point*> by_id;
  for (const auto& p : points) by_id[p.id] = &p;
  const std::vector<std::string> windows = [&] {
    std::vector<std::string> w;
    for (const auto& x : s.windows) w.push_back(x.name);
    return w;
  }();
  for (std::size_t i = 0; i < pts.size(); ++i) {
    const json& pt = pts[i];
    const std::string at = fmt::format("points[{}]", i);
    const auto refuse = [&](const std::string& k, const std::string& problem, const std::string& ok) {
      throw InputError(fmt::format("{}: {}{}: {} (sweep {}); allowed: {}", path, at, k, problem, origin, ok));
    };
    f.object(pt, at);
    const std::string id = f.text(f.member(pt, at, "id", "a point id"), at + ".id", kMaxName);
    const std::string status = f.one_of(f.member(pt, at, "status", "ok, skipped, failed"), at + ".status",
                                        {"ok", "skipped", "failed"});
    if (pt.contains("reason")) (void)f.text(pt["reason"], at + ".reason", std::size_t(1) << 20);
    if (s.kind == "max-instances") {
      // "SCENE | instances=N | ENGINE" or "... | confirm", N in [1, max_instances].
      const std::string axes_allowed =
          fmt::format("params.axes.instances = N in [1, {}] (a probe of the sweep)", s.max_instances);
      const json& params = f.object(f.member(pt, at, "params", axes_allowed), at + ".params");
      const json& axes = f.object(f.member(params, at + ".params", "axes", axes_allowed), at + ".params.axes");
      const long n = static_cast<long>(f.integer(f.member(axes, at + ".params.axes", "instances", axes_allowed),
                                                 at + ".params.axes.instances", 1, s.max_instances));
      bool known = false;
      for (const auto& sc : s.scenes)
        for (const auto& e : s.engines)
          for (const char* tail : {"", " | confirm"})
            known = known || id == fmt::format("{} | instances={} | {}{}", stem(sc), n, e, tail);
      if (!known)
        refuse(".id", "'" + id + "' is not a probe of the sweep",
               fmt::format("'SCENE | instances=N | ENGINE[ | confirm]' with params.axes.instances = N in [1, {}]",
                           s.max_instances));
      (void)f.integer(f.member(pt, at, "index", "an integer >= 0"), at + ".index", 0,
                      static_cast<std::int64_t>(kMaxPoints));
      const std::string v = f.one_of(f.member(pt, at, "verdict", "pass, below, limit, skipped, failed"),
                                     at + ".verdict", {"pass", "below", "limit", "skipped", "failed"});
      const bool fits = status == "ok" ? (v == "pass" || v == "below")
                                       : status == "skipped" ? (v == "skipped" || v == "limit") : v == "failed";
      if (!fits)
        refuse(".verdict", "'" + v + "' with status '" + status + "'",
               "pass or below (ok), skipped or limit (skipped), failed (failed)");
      if (pt.contains("cut"))
        (void)f.integer(f.member(f.object(pt["cut"], at + ".cut"), at + ".cut", "repetitions_cut", "an integer >= 0"),
                        at + ".cut.repetitions_cut", 0, static_cast<std::int64_t>(kMaxRepeat));
    } else {
      const auto it = by_id.find(id);
      if (it == by_id.end()) refuse(".id", "'" + id + "' is not a point of the sweep", "the ids the sweep expands to");
      const auto want = static_cast<std::int64_t>(it->second->index);
      const json* index = pt.contains("index") ? &pt["index"] : nullptr;
      const bool same = index && (index->is_number_unsigned()  ? index->get<std::uint64_t>() == std::uint64_t(want)
                                  : index->is_number_integer() ? index->get<std::int64_t>() == want
                                                               : false);
      if (!same)
        refuse(".index", index ? index->dump().substr(0, 60) : "missing",
               fmt::format("{} (the index of '{}' among the sweep's {} points)", want, id, points.size()));
    }
    if (kept.count(id)) refuse(".id", "'" + id + "' twice", "each point once");
    if (status == "ok") {
      bool shaped = true;
      if (s.kind != "broadphase") {
        shaped = pt.contains("windows") && pt["windows"].is_object() && pt["windows"].size() == windows.size();
        for (const auto& w : windows)
          shaped = shaped && pt["windows"].contains(w) && pt["windows"][w].is_object() &&
                   pt["windows"][w].contains("steps_per_s") && pt["windows"][w]["steps_per_s"].is_object();
      } else {
        shaped = pt.contains("ms_per_frame") && pt["ms_per_frame"].is_object();
      }
      if (!shaped) {
        std::string names;
        for (const auto& w : windows) names += (names.empty() ? "" : ", ") + w;
        refuse(s.kind != "broadphase" ? ".windows" : ".ms_per_frame", "a point of another shape",
               s.kind != "broadphase" ? "windows {" + names + "} each with steps_per_s (docs/bench-format.md)"
                                      : std::string("a ms_per_frame spread (docs/bench-format.md)"));
      }
      // The figures the run reads back (a max-instances search: the median and n of steps/s).
      if (s.kind != "broadphase") {
        for (const auto& w : windows)
          for (const char* k : {"steps_per_s", "cpu_steps_per_s", "world_steps_per_s"})
            if (pt["windows"][w].contains(k))
              check_timing_spread(f, pt["windows"][w][k], at + ".windows." + w + "." + k);
      } else {
        check_timing_spread(f, pt["ms_per_frame"], at + ".ms_per_frame");
      }
      kept[id] = pt;
    } else if (status == "skipped") {
      kept[id] = pt;
    }
  }
  return kept;
}

std::map<std::string, json> resumed_points(const BenchOptions& o, const Sweep& s, const std::string& origin,
                                           const json& def, const std::vector<Point>& points, json& result) {
  std::error_code ec;
  if (!fs::exists(o.output, ec)) return {};
  if (!o.resume)
    throw InputError(fmt::format("{}: exists; allowed: a new file, or --resume to continue it (remove it to start "
                                 "over)",
                                 o.output));
  const std::string text = octocd::read_input_file(o.output, "-o", "a bench result of the same sweep to --resume");
  const json old = octocd::parse_json_strict(text, o.output);  // a second "points" key refused, not silently won
  return resumable_points(old, o.output, s, origin, def, points, result);
}

bool finished_result_matches(const json& old, const std::string& path, const json& def, const json& settings) {
  const JsonFields f(path);
  if (!old.is_object()) f.fail("(the document)", json_type_text(old) + ", not an object", "a result of octocd bench");
  const std::string allowed = "a finished result of the same sweep (docs/bench-format.md)";
  if (f.member(old, "", "format", allowed) != "octocd-bench" || f.member(old, "", "version", allowed) != 1)
    f.fail("format", "not octocd-bench version 1", "octocd-bench version 1");
  if (!old.contains("complete") || !f.boolean(old["complete"], "complete")) return false;
  const json& sweep = f.object(f.member(old, "", "sweep", allowed), "sweep");
  return sweep.contains("definition") && sweep["definition"] == def && old.contains("settings") &&
         old["settings"] == settings;
}

void record_hygiene(json& result, const Sweep& s, bool quiet) {
  const json& m = result["machine"];
  const long threads = m.value("threads", 0L);
  const long omp = m.value("omp_threads", 1L);
  const json la = m.value("load_average", json::array());
  const double load = la.empty() ? 0.0 : la[0].get<double>();
  json warnings = json::array();
  if (threads > 0 && omp > threads)
    warnings.push_back(fmt::format("{} CPU engine threads on {} cores oversubscribe them", omp, threads));
  if (threads > 0 && load + static_cast<double>(omp) > static_cast<double>(threads) + 1.0)
    warnings.push_back(fmt::format("load average {:.1f} leaves {:.1f} of {} cores free for {} CPU engine thread(s)", load,
                                   std::max(0.0, static_cast<double>(threads) - load), threads, omp));
  result["hygiene"] = {{"threads", threads}, {"omp_threads", omp}, {"load_average_start", la}, {"warnings", warnings}};
  for (const auto& w : warnings)
    fmt::print(stderr, "bench {}: warning: {}; timings will be noisy (the report marks them){}\n", octocd::printable(s.name),
               w.get<std::string>(), omp > 1 ? "; --cpu threads=1 (or OMP_NUM_THREADS=1) helps on a shared machine" : "");
  if (s.repeat < 2 && !quiet)
    fmt::print(stderr, "bench {}: note: 1 repetition per point: no spread, so no timing verdict\n", octocd::printable(s.name));
}

int record_stopped(json& result, int sig, const std::function<void()>& write, RunSession& session,
                   const std::string& finished) {
  result["stopped"] = octocd::stop_signal_name(sig);
  write();
  std::fputc('\n', stderr);
  return session.stopped(sig, finished.empty() ? std::string() : " after " + finished);
}

void record_complete(json& result, const std::function<void()>& write) {
  result["complete"] = true;
  result["machine"]["load_average_end"] = load_average();
  write();
}

std::optional<int> finish_sweep(json& result, const std::function<void()>& write, RunSession& session) {
  if (const int sig = session.signal()) return record_stopped(result, sig, write, session);
  record_complete(result, write);
  return std::nullopt;
}

std::string BadEngineValues::add(const std::string& id, const std::exception& e) {
  points.push_back(fmt::format("point {}: {}", id, e.what()));
  return e.what();
}

void BadEngineValues::refuse(const std::string& output) const {
  if (points.empty()) return;
  throw InputError(fmt::format("{} point(s) failed on a value an engine gave, stored as failed in the result {} with "
                               "the other points; the first: {}",
                               points.size(), output, points.front()));
}

}  // namespace octocd::cli::bench
