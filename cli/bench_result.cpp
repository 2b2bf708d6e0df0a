// The result file of `octocd bench` (bench_sweep.hpp, docs/bench-format.md): its header
// (sweep, settings, machine, build), the checks before --resume keeps a file's finished
// points, and the timing hygiene recorded with it.
#include <algorithm>
#include <filesystem>
#include <fstream>
#include <sstream>

#include <fmt/format.h>

#include "bench_sweep.hpp"
#include "octocd/atomic_file.hpp"
#include "octocd/error.hpp"
#include "octocd/json_strict.hpp"

namespace octocd::cli::bench {

namespace fs = std::filesystem;

json result_settings(const Sweep& s, int shard, int shards) {
  json settings{{"engines", s.engines},
                {"repeat", s.repeat},
                {"frames", s.frames},
                {"warmup", s.warmup},
                {"shard", {{"index", shard}, {"count", shards}}}};
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

std::map<std::string, json> resumed_points(const BenchOptions& o, const Sweep& s, const std::string& origin,
                                           const json& def, const std::vector<Point>& points, json& result) {
  std::map<std::string, json> kept;
  std::error_code ec;
  if (!fs::exists(o.output, ec)) return kept;
  const json settings = result["settings"];
  if (!o.resume)
    throw InputError(fmt::format("{}: exists; allowed: a new file, or --resume to continue it (remove it to start "
                                 "over)",
                                 o.output));
  json old;
  {
    const std::string text = octocd::read_input_file(o.output, "-o", "a bench result of the same sweep to --resume");
    old = octocd::parse_json_strict(text, o.output);  // a second "points" key refused, not silently won
  }
  if (old.value("format", "") != "octocd-bench" || old.value("version", 0) != 1)
    throw InputError(fmt::format("{}: format: {} version {}; allowed: octocd-bench version 1", o.output,
                                 old.value("format", "?"), old.value("version", 0)));
  if (old["sweep"]["definition"] != def)
    throw InputError(fmt::format("{}: sweep.definition: another sweep ('{}'); allowed: a result of the same sweep "
                                 "definition to resume",
                                 o.output, old["sweep"].value("name", "?")));
  if (old["settings"] != settings)
    throw InputError(fmt::format("{}: settings: {}; allowed: the same engines, repeat and shard as now ({})",
                                 o.output, old["settings"].dump(), settings.dump()));
  for (const char* k : {"hostname", "cpu", "gpu"})
    if (old["machine"].value(k, "") != result["machine"].value(k, ""))
      throw InputError(fmt::format("{}: machine.{}: '{}'; allowed: a result measured on this machine ('{}') to "
                                   "resume",
                                   o.output, k, old["machine"].value(k, ""), result["machine"].value(k, "")));
  result["started"] = old.value("started", result["started"].get<std::string>());
  if (!old.contains("points") || !old["points"].is_array())
    throw InputError(fmt::format("{}: points: not an array; allowed: a result file of octocd bench to resume",
                                 o.output));
  std::map<std::string, const Point*> by_id;
  for (const auto& p : points) by_id[p.id] = &p;
  for (std::size_t i = 0; i < old["points"].size(); ++i) {
    const json& pt = old["points"][i];
    const std::string key = fmt::format("points[{}]", i);
    const auto refuse = [&](const std::string& k, const std::string& problem, const std::string& allowed) {
      throw InputError(fmt::format("{}: {}{}: {} (sweep {}); allowed: {}", o.output, key, k, problem, origin, allowed));
    };
    if (!pt.is_object()) refuse("", "not an object", "a point of the sweep");
    if (!pt.contains("id") || !pt["id"].is_string()) refuse(".id", "missing or not a string", "a point id");
    const std::string id = pt["id"];
    if (s.kind == "max-instances") {
      // "SCENE | instances=N | ENGINE" or "... | confirm", N in [1, max_instances].
      const json* n_json = nullptr;
      if (pt.contains("params") && pt["params"].is_object() && pt["params"].contains("axes") &&
          pt["params"]["axes"].is_object() && pt["params"]["axes"].contains("instances"))
        n_json = &pt["params"]["axes"]["instances"];
      const long n = n_json && n_json->is_number_integer() ? n_json->get<long>() : 0;
      bool known = false;
      for (const auto& sc : s.scenes)
        for (const auto& e : s.engines)
          for (const char* tail : {"", " | confirm"})
            known = known || (n >= 1 && n <= s.max_instances &&
                              id == fmt::format("{} | instances={} | {}{}", stem(sc), n, e, tail));
      if (!known)
        refuse(".id", "'" + id + "' is not a probe of the sweep",
               fmt::format("'SCENE | instances=N | ENGINE[ | confirm]' with params.axes.instances = N in [1, {}]",
                           s.max_instances));
      if (!pt.contains("index") || !pt["index"].is_number_integer() || pt["index"].get<long long>() < 0)
        refuse(".index", pt.contains("index") ? pt["index"].dump() : "missing", "an integer >= 0");
      const std::string v = pt.value("verdict", "");
      if (v != "pass" && v != "below" && v != "limit" && v != "skipped" && v != "failed")
        refuse(".verdict", "'" + v + "'", "pass, below, limit, skipped, failed");
    } else {
      const auto it = by_id.find(id);
      if (it == by_id.end()) refuse(".id", "'" + id + "' is not a point of the sweep", "the ids the sweep expands to");
      if (!pt.contains("index") || !pt["index"].is_number_integer() || pt["index"].get<long long>() != it->second->index)
        refuse(".index", pt.contains("index") ? pt["index"].dump() : "missing",
               fmt::format("{} (the index of '{}' among the sweep's {} points)", it->second->index, id,
                           points.size()));
    }
    if (kept.count(id)) refuse(".id", "'" + id + "' twice", "each point once");
    const std::string status = pt.value("status", "");
    if (status == "ok") {
      bool shaped = true;
      if (s.kind != "broadphase") {
        shaped = pt.contains("windows") && pt["windows"].is_object() && pt["windows"].size() == s.windows.size();
        for (const auto& w : s.windows)
          shaped = shaped && pt["windows"].contains(w.name) && pt["windows"][w.name].is_object() &&
                   pt["windows"][w.name].contains("steps_per_s") && pt["windows"][w.name]["steps_per_s"].is_object();
      } else {
        shaped = pt.contains("ms_per_frame") && pt["ms_per_frame"].is_object();
      }
      if (!shaped)
        refuse(s.kind != "broadphase" ? ".windows" : ".ms_per_frame", "a point of another shape",
               s.kind != "broadphase" ? "windows {" + [&] {
                 std::string names;
                 for (const auto& w : s.windows) names += (names.empty() ? "" : ", ") + w.name;
                 return names;
               }() + "} each with steps_per_s (docs/bench-format.md)"
                                 : std::string("a ms_per_frame spread (docs/bench-format.md)"));
      kept[id] = pt;
    } else if (status == "skipped") {
      kept[id] = pt;
    } else if (status != "failed") {
      refuse(".status", "'" + status + "'", "ok, skipped, failed");
    }
  }
  return kept;
}

void record_hygiene(json& result, const Sweep& s, bool quiet) {
  const json& m = result["machine"];
  const long threads = m.value("threads", 0L);
  const long omp = m.value("omp_threads", 1L);
  const json la = m.value("load_average", json::array());
  const double load = la.empty() ? 0.0 : la[0].get<double>();
  json warnings = json::array();
  if (threads > 0 && omp > threads)
    warnings.push_back(fmt::format("{} OpenMP threads on {} cores oversubscribe them", omp, threads));
  if (threads > 0 && load + static_cast<double>(omp) > static_cast<double>(threads) + 1.0)
    warnings.push_back(fmt::format("load average {:.1f} leaves {:.1f} of {} cores free for {} OpenMP thread(s)", load,
                                   std::max(0.0, static_cast<double>(threads) - load), threads, omp));
  result["hygiene"] = {{"threads", threads}, {"omp_threads", omp}, {"load_average_start", la}, {"warnings", warnings}};
  for (const auto& w : warnings)
    fmt::print(stderr, "bench {}: warning: {}; timings will be noisy (the report marks them){}\n", s.name,
               w.get<std::string>(), omp > 1 ? "; OMP_NUM_THREADS=1 helps on a shared machine" : "");
  if (s.repeat < 2 && !quiet)
    fmt::print(stderr, "bench {}: note: 1 repetition per point: no spread, so no timing verdict\n", s.name);
}

}  // namespace octocd::cli::bench
