// A sweep of `octocd bench` (bench_sweep.hpp): the named sweeps (bench/sweeps/*.json, read
// like any sweep file), parsing and checking a definition, expanding it to points, and the
// scene text of a point (a steps point, a max-instances count, a broadphase lattice).
#include <algorithm>
#include <array>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <set>
#include <sstream>

#include <fmt/format.h>

#include "bench_sweep.hpp"
#include "octocd/worlds.hpp"
#include "octocd/engine_registry.hpp"
#include "octocd/atomic_file.hpp"
#include "octocd/scene.hpp"
#include "octocd/error.hpp"
#include "octocd/json_fields.hpp"
#include "octocd/json_strict.hpp"
#include "octocd/reference_broadphase.hpp"
#include "octocd/shared_files.hpp"

namespace octocd::cli::bench {

namespace fs = std::filesystem;

[[noreturn]] void bad(const std::string& origin, const std::string& key, const std::string& problem,
                      const std::string& allowed) {
  throw InputError(fmt::format("{}: {}: {}; allowed: {}", origin, key, problem, allowed));
}

std::string named_sweeps_dir() { return (fs::path(shared_dir()) / "bench" / "sweeps").string(); }

std::vector<std::string> named_sweeps() {
  std::vector<std::string> names;
  std::error_code ec;
  for (fs::directory_iterator it(named_sweeps_dir(), ec), end; !ec && it != end; it.increment(ec))
    if (it->path().extension() == ".json" && it->is_regular_file(ec)) names.push_back(it->path().stem().string());
  std::sort(names.begin(), names.end());
  return names;
}

std::string named_list() {
  std::string s;
  for (const auto& n : named_sweeps()) s += (s.empty() ? "" : ", ") + n;
  return s;
}

json read_sweep_file(const std::string& path) {
  // A regular file of at most 64 MiB, checked before it is read (a FIFO never blocks).
  const std::string text = octocd::read_input_file(path, "", "a sweep file (JSON, docs/bench-format.md)");
  return octocd::parse_json_strict(text, path);  // duplicate keys and NUL bytes refused
}

namespace {

/// An integer of the sweep in [lo, hi] through JsonFields (checked before it is converted:
/// a huge unsigned value never wraps into range), `def` when absent.
int get_int(const json& j, const std::string& key, const std::string& origin, int lo, int hi, int def) {
  if (!j.contains(key)) return def;
  return static_cast<int>(JsonFields(origin).integer(j.at(key), key, lo, hi));
}

std::vector<std::string> string_list(const json& j, const std::string& key, const std::string& origin) {
  std::vector<std::string> out;
  if (!j.at(key).is_array() || j.at(key).empty()) bad(origin, key, "not a non-empty array", "an array of strings");
  for (std::size_t i = 0; i < j.at(key).size(); ++i) {
    const json& v = j.at(key)[i];
    if (!v.is_string()) bad(origin, fmt::format("{}[{}]", key, i), v.dump() + " is not a string", "a string");
    out.push_back(v.get<std::string>());
  }
  return out;
}

/// The object at `key` of names to integers in [lo, hi] (`max_worlds`, `max_bodies`), empty
/// when absent; anything else is bad input naming the key (`shape`: the allowed object).
std::map<std::string, long> integer_map(const json& j, const std::string& key, const std::string& origin, long lo,
                                        long hi, const std::string& shape) {
  std::map<std::string, long> out;
  if (!j.contains(key)) return out;
  if (!j.at(key).is_object()) bad(origin, key, "not an object", shape);
  for (auto it = j.at(key).begin(); it != j.at(key).end(); ++it)
    out[it.key()] = static_cast<long>(JsonFields(origin).integer(it.value(), key + "." + it.key(), lo, hi));
  return out;
}

/// The string at `key`, or `fallback` when absent; anything else is bad input naming the
/// key (not a raw json type_error).
std::string optional_string(const json& j, const std::string& key, const std::string& origin,
                            const std::string& fallback) {
  if (!j.contains(key)) return fallback;
  if (!j.at(key).is_string()) bad(origin, key, j.at(key).dump() + " is not a string", "a string");
  return j.at(key).get<std::string>();
}

}  // namespace

const std::vector<std::string>& trace_modes() {
  static const std::vector<std::string> modes{"off", "states", "contacts"};
  return modes;
}

std::vector<std::string> checked_trace_modes(const std::vector<std::string>& modes, const std::string& what) {
  const std::string allowed = "a non-empty list of off, states, contacts, each once";
  if (modes.empty()) throw InputError(fmt::format("{}: empty; allowed: {}", what, allowed));
  for (std::size_t i = 0; i < modes.size(); ++i) {
    if (std::find(trace_modes().begin(), trace_modes().end(), modes[i]) == trace_modes().end())
      throw InputError(fmt::format("{}: '{}' is not a trace mode; allowed: {}", what, modes[i], allowed));
    if (std::find(modes.begin(), modes.begin() + static_cast<long>(i), modes[i]) != modes.begin() + static_cast<long>(i))
      throw InputError(fmt::format("{}: '{}' is listed twice; allowed: {}", what, modes[i], allowed));
  }
  return modes;
}

namespace {

/// The scene key a known axis name sets.
std::string axis_key(const std::string& name) {
  static const std::map<std::string, std::string> keys{
      {"midphase", "/midphase/levels"}, {"broadphase", "/broadphase/name"}, {"cell_size", "/broadphase/cell_size"},
      {"beta", "/response/beta"},       {"delta", "/response/slop"},      {"slop", "/response/slop"},
      {"alpha", "/response/alpha"},     {"count", "/groups/0/count"},     {"mesh", "/groups/0/shape/mesh"},
      {"iterations", "/response/iterations"}};
  const auto it = keys.find(name);
  return it == keys.end() ? "" : it->second;
}

std::string resolve_scene(const std::string& entry, const std::string& scene_dir, const std::string& sweep_dir) {
  const bool bare = entry.find('/') == std::string::npos && fs::path(entry).extension() != ".json";
  if (bare) return (fs::path(scene_dir) / (entry + ".json")).string();
  const fs::path p(entry);
  return p.is_absolute() || sweep_dir.empty() ? entry : (fs::path(sweep_dir) / p).string();
}

/// The keys of a speed-accuracy sweep: dts (> 0, each dividing the largest), sim_seconds
/// (a multiple of the largest dt), iterations, geometries, rotation.
void parse_speed_accuracy(const json& j, const std::string& origin, Sweep& s) {
  if (!j.contains("dts") || !j.at("dts").is_array() || j.at("dts").empty())
    bad(origin, "dts", "missing or not a non-empty array", "an array of time steps in seconds, each > 0");
  for (std::size_t i = 0; i < j.at("dts").size(); ++i) {
    const json& v = j.at("dts")[i];
    if (!v.is_number() || !std::isfinite(v.get<double>()) || !(v.get<double>() > 0.0) || v.get<double>() > 0.1)
      bad(origin, fmt::format("dts[{}]", i), v.dump() + " is not a time step", "a number in (0, 0.1] (seconds, as a scene's dt)");
    const double dt = v.get<double>();
    if (std::find(s.dts.begin(), s.dts.end(), dt) != s.dts.end())
      bad(origin, fmt::format("dts[{}]", i), v.dump() + " is listed twice", "each time step once");
    s.dts.push_back(dt);
  }
  const double largest = *std::max_element(s.dts.begin(), s.dts.end());
  for (std::size_t i = 0; i < s.dts.size(); ++i) {
    const double r = largest / s.dts[i];
    if (std::abs(r - std::round(r)) > 1e-6 * r)
      bad(origin, fmt::format("dts[{}]", i),
          fmt::format("{} does not divide the largest time step {} (ratio {})", s.dts[i], largest, r),
          "time steps that divide the largest one (e.g. 1/60 s x 1, 1/2, 1/4, 1/8, 1/16): positions are compared at "
          "its multiples");
  }
  if (j.contains("sim_seconds")) {
    const json& v = j.at("sim_seconds");
    if (!v.is_number() || !std::isfinite(v.get<double>()) || !(v.get<double>() > 0.0) || v.get<double>() > 1e6)
      bad(origin, "sim_seconds", v.dump() + " is out of range", "a number of seconds in (0, 1e6]");
    s.sim_seconds = v.get<double>();
  }
  const double k = s.sim_seconds / largest;
  if (k < 1.0 - 1e-9 || std::abs(k - std::round(k)) > 1e-6 * k)
    bad(origin, "sim_seconds", fmt::format("{} s is not a multiple of the largest time step {} s", s.sim_seconds, largest),
        "a multiple of the largest dt (every point ends at the same time)");
  if (j.contains("diverge_beyond_m")) {
    const json& v = j.at("diverge_beyond_m");
    if (!v.is_number() || !(v.get<double>() >= 0.0) || !std::isfinite(v.get<double>()))
      bad(origin, "diverge_beyond_m", v.dump() + " is out of range", "a finite number of metres >= 0");
    s.diverge_beyond_m = v.get<double>();
  }
  if (j.contains("iterations")) {
    const json& a = j.at("iterations");
    if (!a.is_array() || a.empty()) bad(origin, "iterations", "not a non-empty array", "an array of integers in [1, 10000]");
    for (std::size_t i = 0; i < a.size(); ++i)
      s.iterations.push_back(static_cast<int>(JsonFields(origin).integer(a[i], fmt::format("iterations[{}]", i), 1, 10000)));
  } else {
    s.iterations = {10};
  }
  if (j.contains("geometries")) {
    for (const auto& g : string_list(j, "geometries", origin)) {
      if (g != "box" && g != "hull") bad(origin, "geometries", "'" + g + "'", "\"box\", \"hull\" (Bullet's shape setting)");
      s.geometries.push_back(g);
    }
  } else {
    s.geometries = {"hull", "box"};
  }
  if (j.contains("rotation")) {
    const json& a = j.at("rotation");
    if (!a.is_array() || a.empty()) bad(origin, "rotation", "not a non-empty array", "an array of false, true");
    for (std::size_t i = 0; i < a.size(); ++i) {
      if (!a[i].is_boolean()) bad(origin, fmt::format("rotation[{}]", i), a[i].dump() + " is not a boolean", "false, true");
      s.rotations.push_back(a[i].get<bool>());
    }
  } else {
    s.rotations = {false, true};
  }
}

}  // namespace

Sweep parse_sweep(const json& j, const std::string& origin, const std::string& scene_dir, const std::string& sweep_dir) {
  Sweep s;
  s.origin = origin;
  s.definition = j;
  if (!j.is_object()) bad(origin, "(top level)", "not a JSON object", "an object with name, kind, ...");
  static const std::set<std::string> common{"name",  "kind",   "description", "engines", "frames",
                                            "warmup", "repeat", "format",      "version"};
  static const std::set<std::string> steps{"scenes", "axes", "set", "windows", "series_every", "traced", "worlds",
                                           "max_worlds", "max_bodies", "min_time_s", "max_time_s"};
  static const std::set<std::string> bp{"bodies",       "scenes", "broadphases", "max_bodies",
                                        "warm_replays", "set",    "min_time_ms"};
  if (!j.contains("name") || !j.at("name").is_string() || j.at("name").get<std::string>().empty())
    bad(origin, "name", "missing or not a non-empty string", "a non-empty string");
  s.name = j.at("name");
  s.kind = optional_string(j, "kind", origin, "steps");
  static const std::set<std::string> mi{"scenes", "set",          "target_steps_per_s", "max_instances",
                                        "resolution", "paper", "probe_repeat", "search_time_s"};
  static const std::set<std::string> sa{"scenes",     "set",        "dts",      "sim_seconds",      "iterations",
                                        "geometries", "rotation", "diverge_beyond_m", "min_time_s", "max_time_s"};
  static const std::set<std::string> dv{"scenes", "set", "eps", "copies", "seed", "rotation"};
  if (s.kind != "steps" && s.kind != "broadphase" && s.kind != "max-instances" && s.kind != "speed-accuracy" &&
      s.kind != "divergence")
    bad(origin, "kind", "'" + s.kind + "'",
        "\"steps\", \"broadphase\", \"max-instances\", \"speed-accuracy\", \"divergence\"");
  const auto& extra = s.kind == "steps"           ? steps
                      : s.kind == "broadphase"    ? bp
                      : s.kind == "max-instances" ? mi
                      : s.kind == "divergence"    ? dv
                                                  : sa;
  if (s.kind == "speed-accuracy")
    for (const char* k : {"frames", "warmup"})
      if (j.contains(k))
        bad(origin, k, "not a key of kind 'speed-accuracy' (every point runs sim_seconds)",
            "name, kind, description, engines, repeat, scenes, set, dts, sim_seconds, iterations, geometries, rotation, "
            "diverge_beyond_m");
  for (auto it = j.begin(); it != j.end(); ++it) {
    if (!common.count(it.key()) && !extra.count(it.key())) {
      std::string keys;
      for (const auto& k : common) keys += (keys.empty() ? "" : ", ") + k;
      for (const auto& k : extra) keys += ", " + k;
      bad(origin, it.key(), "unknown key for kind '" + s.kind + "'", keys);
    }
  }
  if (j.contains("format") && j.at("format") != "octocd-sweep")
    bad(origin, "format", j.at("format").dump(), "\"octocd-sweep\"");
  if (j.contains("version") && j.at("version") != 1) bad(origin, "version", j.at("version").dump(), "1");
  s.description = optional_string(j, "description", origin, "");
  s.engines = j.contains("engines") ? string_list(j, "engines", origin) : engine_names();
  for (std::size_t i = 0; i < s.engines.size(); ++i)
    if (std::find(engine_names().begin(), engine_names().end(), s.engines[i]) == engine_names().end())
      bad(origin, fmt::format("engines[{}]", i), "'" + s.engines[i] + "'", fmt::format("{}", fmt::join(engine_names(), ", ")));
  s.repeat = get_int(j, "repeat", origin, 1, 1000, 5);
  // The time budget of a point (steps and speed-accuracy sweeps; the key sets above refuse it elsewhere).
  for (const char* k : {"min_time_s", "max_time_s"}) {
    if (!j.contains(k)) continue;
    const json& v = j.at(k);
    if (!v.is_number() || !std::isfinite(v.get<double>()) || v.get<double>() < 0.0 || v.get<double>() > 86400.0)
      bad(origin, k, v.dump().substr(0, 60) + " is out of range", "a number of seconds in [0, 86400] (0: no limit)");
    (std::string(k) == "min_time_s" ? s.min_time_s : s.max_time_s) = v.get<double>();
  }
  if (j.contains("set")) {
    if (!j.at("set").is_object()) bad(origin, "set", "not an object", "an object of JSON pointer -> value");
    s.set = j.at("set");
    for (auto it = s.set.begin(); it != s.set.end(); ++it)
      if (it.key().empty() || it.key()[0] != '/')
        bad(origin, "set." + it.key(), "not a JSON pointer", "keys like \"/response/beta\"");
  }
  if (s.kind == "max-instances") {
    s.frames = get_int(j, "frames", origin, 1, 100000000, 300);
    s.warmup = get_int(j, "warmup", origin, 0, 100000000, 300);
    s.probe_repeat = get_int(j, "probe_repeat", origin, 1, 1000, 1);
    s.search_time_s = get_int(j, "search_time_s", origin, 0, 100000000, 0);
    if (s.probe_repeat > s.repeat)
      bad(origin, "probe_repeat", fmt::format("{} is above repeat ({})", s.probe_repeat, s.repeat),
          "an integer in [1, repeat]");
    if (j.contains("target_steps_per_s")) {
      const json& v = j.at("target_steps_per_s");
      if (!v.is_number() || !(v.get<double>() > 0.0) || !(v.get<double>() <= 1e9))
        bad(origin, "target_steps_per_s", v.dump() + " is out of range", "a number in (0, 1e9] (steps/s)");
      s.target = v.get<double>();
    }
    if (j.contains("max_instances"))
      s.max_instances = static_cast<long>(JsonFields(origin).integer(j.at("max_instances"), "max_instances", 1,
                                                                     kMaxInstancesCap));
    if (j.contains("resolution")) {
      const json& v = j.at("resolution");
      if (!v.is_number() || !(v.get<double>() >= 0.0) || !(v.get<double>() < 1.0))
        bad(origin, "resolution", v.dump() + " is out of range",
            "a number in [0, 1): bisection stops at hi - lo <= max(1, resolution x lo); 0 = an integer bracket");
      s.resolution = v.get<double>();
    }
    if (j.contains("paper")) {
      if (!j.at("paper").is_object()) bad(origin, "paper", "not an object", "{\"SCENE\": {\"count\": N, \"source\": \"...\"}}");
      s.paper = j.at("paper");
    }
    if (!j.contains("scenes")) bad(origin, "scenes", "missing", "an array of scene names or files (one model each)");
    for (const auto& e : string_list(j, "scenes", origin)) s.scenes.push_back(resolve_scene(e, scene_dir, sweep_dir));
    s.windows.push_back(Window{"settled", s.warmup + 1, s.warmup + s.frames});
    s.frames = s.warmup + s.frames;  // steps to run
  } else if (s.kind == "divergence") {
    s.frames = get_int(j, "frames", origin, 1, 1000000, 300);
    s.warmup = 0;
    s.copies = get_int(j, "copies", origin, 1, 1024, 16);
    s.seed = static_cast<std::uint64_t>(JsonFields(origin).integer(j.value("seed", json(1)), "seed", 0, 1LL << 53));
    if (j.contains("rotation")) {
      if (!j.at("rotation").is_boolean()) bad(origin, "rotation", j.at("rotation").dump(), "true or false");
      s.rotation = j.at("rotation").get<bool>();
    }
    if (!j.contains("eps") || !j.at("eps").is_array() || j.at("eps").empty())
      bad(origin, "eps", "missing or not a non-empty array", "an array of perturbations in metres, each in [0, 1]");
    for (std::size_t i = 0; i < j.at("eps").size(); ++i) {
      const json& v = j.at("eps")[i];
      if (!v.is_number() || !std::isfinite(v.get<double>()) || !(v.get<double>() >= 0.0) || v.get<double>() > 1.0)
        bad(origin, fmt::format("eps[{}]", i), v.dump(),
            "a number of metres in [0, 1] (0: unperturbed copies, distance 0 for a deterministic engine)");
      if (std::find(s.eps.begin(), s.eps.end(), v.get<double>()) != s.eps.end())
        bad(origin, fmt::format("eps[{}]", i), v.dump() + " is listed twice", "each perturbation once");
      s.eps.push_back(v.get<double>());
    }
    if (!j.contains("scenes")) bad(origin, "scenes", "missing", "an array of scene names or files");
    for (const auto& e : string_list(j, "scenes", origin)) s.scenes.push_back(resolve_scene(e, scene_dir, sweep_dir));
  } else if (s.kind == "speed-accuracy") {
    parse_speed_accuracy(j, origin, s);
    if (!j.contains("scenes")) bad(origin, "scenes", "missing", "an array of scene names or files");
    for (const auto& e : string_list(j, "scenes", origin)) s.scenes.push_back(resolve_scene(e, scene_dir, sweep_dir));
  } else if (s.kind == "steps") {
    s.frames = get_int(j, "frames", origin, 1, 100000000, 300);
    s.warmup = get_int(j, "warmup", origin, 0, 100000000, 30);
    s.series_every = get_int(j, "series_every", origin, 0, 100000000, 0);
    if (j.contains("traced")) s.traced = checked_trace_modes(string_list(j, "traced", origin), origin + ": traced");
    if (j.contains("worlds")) {
      const json& w = j.at("worlds");
      if (!w.is_array() || w.empty())
        bad(origin, "worlds", "not a non-empty array", fmt::format("an array of integers in [1, {}]", kMaxWorlds));
      s.worlds.clear();
      for (std::size_t i = 0; i < w.size(); ++i)
        s.worlds.push_back(static_cast<long>(JsonFields(origin).integer(w[i], fmt::format("worlds[{}]", i), 1, kMaxWorlds)));
      s.worlds_given = true;
    }
    s.max_worlds = integer_map(j, "max_worlds", origin, 1, kMaxWorlds, "{\"ENGINE\": K}");
    if (j.contains("max_bodies")) {
      // {"ENGINE": {"bodies": N, "reason": "..."}}: that engine's points of scenes above N
      // bodies are skipped with the reason (a set-up that would not finish in time).
      const std::string allowed = "{\"ENGINE\": {\"bodies\": N, \"reason\": \"why\"}}, N in [0, " +
                                  std::to_string(kMaxSweepBodies) + "], ENGINE one of " +
                                  fmt::format("{}", fmt::join(engine_names(), ", "));
      if (!j.at("max_bodies").is_object()) bad(origin, "max_bodies", "not an object", allowed);
      for (auto it = j.at("max_bodies").begin(); it != j.at("max_bodies").end(); ++it) {
        const std::string k = "max_bodies." + it.key();
        if (std::find(engine_names().begin(), engine_names().end(), it.key()) == engine_names().end())
          bad(origin, k, "not an engine", allowed);
        const json& v = it.value();
        if (!v.is_object() || v.size() != 2 || !v.contains("bodies") || !v.contains("reason") ||
            !v.at("reason").is_string() || v.at("reason").get<std::string>().empty())
          bad(origin, k, v.dump(), allowed);
        s.max_bodies[it.key()] =
            static_cast<long>(JsonFields(origin).integer(v.at("bodies"), k + ".bodies", 0, kMaxSweepBodies));
        s.max_bodies_reason[it.key()] = v.at("reason").get<std::string>();
      }
    }
    if (!j.contains("scenes")) bad(origin, "scenes", "missing", "an array of scene names or files");
    for (const auto& e : string_list(j, "scenes", origin)) s.scenes.push_back(resolve_scene(e, scene_dir, sweep_dir));
    if (j.contains("axes")) {
      if (!j.at("axes").is_array()) bad(origin, "axes", "not an array", "an array of {name, key?, values, labels?}");
      for (std::size_t i = 0; i < j.at("axes").size(); ++i) {
        const json& a = j.at("axes")[i];
        const std::string k = fmt::format("axes[{}]", i);
        if (!a.is_object()) bad(origin, k, "not an object", "{name, key?, values, labels?}");
        for (auto it = a.begin(); it != a.end(); ++it)
          if (it.key() != "name" && it.key() != "key" && it.key() != "values" && it.key() != "labels")
            bad(origin, k + "." + it.key(), "unknown key", "name, key, values, labels");
        Axis ax;
        if (!a.contains("name") || !a.at("name").is_string()) bad(origin, k + ".name", "missing", "a string");
        ax.name = a.at("name");
        ax.key = a.contains("key") ? optional_string(a, "key", origin, "") : axis_key(ax.name);
        if (ax.key.empty() || ax.key[0] != '/')
          bad(origin, k + ".key", "missing for axis '" + ax.name + "'",
              "a JSON pointer into the scene, or an axis name among midphase, broadphase, cell_size, beta, delta, "
              "slop, alpha, iterations, count, mesh");
        if (!a.contains("values") || !a.at("values").is_array() || a.at("values").empty())
          bad(origin, k + ".values", "missing or empty", "a non-empty array");
        for (const auto& v : a.at("values")) ax.values.push_back(v);
        ax.labels.assign(ax.values.size(), "");
        if (a.contains("labels")) {
          const auto labels = string_list(a, "labels", origin + ": " + k);
          if (labels.size() != ax.values.size())
            bad(origin, k + ".labels", fmt::format("{} labels for {} values", labels.size(), ax.values.size()),
                "one label per value");
          ax.labels = labels;
        }
        s.axes.push_back(std::move(ax));
      }
    }
    if (j.contains("windows")) {
      if (!j.at("windows").is_array() || j.at("windows").empty())
        bad(origin, "windows", "not a non-empty array", "an array of {name, first, last}");
      int last = 0;
      for (std::size_t i = 0; i < j.at("windows").size(); ++i) {
        const json& w = j.at("windows")[i];
        const std::string k = fmt::format("windows[{}]", i);
        if (!w.is_object() || !w.contains("name") || !w.at("name").is_string())
          bad(origin, k, "not an object with a name", "{name, first, last}");
        Window win;
        win.name = w.at("name");
        win.first = get_int(w, "first", origin + ": " + k, 1, 100000000, 1);
        win.last = get_int(w, "last", origin + ": " + k, win.first, 100000000, win.first);
        last = std::max(last, win.last);
        s.windows.push_back(win);
      }
      s.frames = last;
      s.warmup = 0;
    } else {
      s.windows.push_back(Window{"all", s.warmup + 1, s.warmup + s.frames});
      s.frames = s.warmup + s.frames;  // steps to run
      s.cuttable = s.series_every == 0;
    }
  } else {
    s.frames = get_int(j, "frames", origin, 1, 100000, 5);
    s.warmup = get_int(j, "warmup", origin, 0, 100000, 10);
    s.warm_replays = get_int(j, "warm_replays", origin, 0, 1000, 1);
    s.min_time_ms = get_int(j, "min_time_ms", origin, 0, 600000, 50);
    const bool has_bodies = j.contains("bodies"), has_scenes = j.contains("scenes");
    if (has_bodies == has_scenes) bad(origin, "bodies", "give exactly one of bodies and scenes", "bodies or scenes");
    if (has_bodies) {
      if (!j.at("bodies").is_array() || j.at("bodies").empty())
        bad(origin, "bodies", "not a non-empty array", fmt::format("an array of integers in [2, {}]", kMaxSweepBodies));
      // Each count read through JsonFields: checked before it is converted (a huge unsigned
      // value never wraps).
      for (std::size_t i = 0; i < j.at("bodies").size(); ++i)
        s.bodies.push_back(static_cast<long>(
            JsonFields(origin).integer(j.at("bodies")[i], fmt::format("bodies[{}]", i), 2, kMaxSweepBodies)));
    } else {
      for (const auto& e : string_list(j, "scenes", origin)) s.scenes.push_back(resolve_scene(e, scene_dir, sweep_dir));
    }
    const auto known = any_engine_broadphase_names();
    if (j.contains("broadphases")) {
      s.broadphases = string_list(j, "broadphases", origin);
      for (std::size_t i = 0; i < s.broadphases.size(); ++i)
        if (std::find(known.begin(), known.end(), s.broadphases[i]) == known.end()) {
          std::string names;
          for (const auto& n : known) names += (names.empty() ? "" : ", ") + n;
          bad(origin, fmt::format("broadphases[{}]", i), "'" + s.broadphases[i] + "'", names);
        }
    } else {
      s.broadphases = known;
    }
    s.max_bodies = integer_map(j, "max_bodies", origin, 0, kMaxSweepBodies, "{\"NAME\" or \"ENGINE:NAME\": N}");
  }
  return s;
}

int cut_frames(int asked, int measured) {
  int n = std::max(asked, 1);
  while (n > std::max(measured, 1)) n = (n + 1) / 2;
  return n;
}

std::string stem(const std::string& path) { return fs::path(path).stem().string(); }

std::string value_text(const json& v) { return v.is_string() ? v.get<std::string>() : v.dump(); }

std::vector<Point> expand(const Sweep& s) {
  if (s.kind == "max-instances") {
    // Its probes are found while it runs (run_max_instances); the scenes must still be
    // distinct models (a probe's id names its scene by the file stem).
    std::set<std::string> stems;
    for (std::size_t i = 0; i < s.scenes.size(); ++i)
      if (!stems.insert(stem(s.scenes[i])).second)
        bad(s.origin, fmt::format("scenes[{}]", i), "listed twice ('" + stem(s.scenes[i]) + "')",
            "each scene (file name) once");
    return {};
  }
  {
    // Count first (saturating), so a sweep of 10^9 points is refused without allocating.
    std::size_t n = std::max<std::size_t>(s.engines.size(), 1);
    const auto times = [&](std::size_t k) { n = (k != 0 && n > kMaxPoints / k) ? kMaxPoints + 1 : n * k; };
    if (s.kind == "steps") {
      times(s.scenes.size());
      times(s.traced.size());
      times(s.worlds.size());
      for (const auto& a : s.axes) times(a.values.size());
    } else {
      times(s.bodies.empty() ? s.scenes.size() : s.bodies.size());
      times(s.broadphases.size());
    }
    if (n > kMaxPoints)
      bad(s.origin, s.kind == "steps" ? "axes" : "bodies",
          fmt::format("the sweep expands to {} points", n > kMaxPoints ? fmt::format("more than {}", kMaxPoints)
                                                                        : std::to_string(n)),
          fmt::format("at most {} points (scenes x axis values x engines)", kMaxPoints));
  }
  // Point ids name the scene by its file stem: a scene listed twice would give two points
  // one id (and --resume would take one for the other).
  std::set<std::string> stems;
  for (std::size_t i = 0; i < s.scenes.size(); ++i)
    if (!stems.insert(stem(s.scenes[i])).second)
      bad(s.origin, fmt::format("scenes[{}]", i), "listed twice ('" + stem(s.scenes[i]) + "')",
          "each scene (file name) once");
  std::vector<Point> pts;
  // A point numbered next in `pts`, of engine `e` and scene (or body-count) index `sc`.
  const auto next_point = [&pts](const std::string& e, std::size_t sc) {
    Point p;
    p.index = static_cast<int>(pts.size());
    p.engine = e;
    p.scene = sc;
    return p;
  };
  if (s.kind == "steps") {
    std::size_t combos = 1;
    for (const auto& a : s.axes) combos *= a.values.size();
    for (std::size_t sc = 0; sc < s.scenes.size(); ++sc) {
      for (std::size_t c = 0; c < combos; ++c) {
        std::vector<std::size_t> idx(s.axes.size(), 0);
        std::size_t rest = c;  // last axis fastest
        for (std::size_t a = s.axes.size(); a-- > 0;) {
          idx[a] = rest % s.axes[a].values.size();
          rest /= s.axes[a].values.size();
        }
        for (const long k : s.worlds)
          for (const auto& e : s.engines) {
            const auto cap = s.max_worlds.find(e);
            if (cap != s.max_worlds.end() && k > cap->second) continue;  // the engine's largest batch
            for (const auto& mode : s.traced) {
              Point p = next_point(e, sc);
              p.value = idx;
              p.traced = mode;
              p.worlds = k;
              p.id = stem(s.scenes[sc]);
              for (std::size_t a = 0; a < s.axes.size(); ++a)
                p.id += " | " + s.axes[a].name + "=" + value_text(s.axes[a].values[idx[a]]);
              if (s.worlds_given) p.id += fmt::format(" | worlds={}", k);  // ids of sweeps without worlds as before
              p.id += " | " + e;
              if (mode != "off") p.id += " | traced=" + mode;  // untraced ids as before
              pts.push_back(p);
            }
          }
      }
    }
  } else {
    const std::size_t sizes = s.bodies.empty() ? s.scenes.size() : s.bodies.size();
    for (std::size_t k = 0; k < sizes; ++k)
      for (const auto& bp : s.broadphases)
        for (const auto& e : s.engines) {
          Point p = next_point(e, k);
          p.broadphase = bp;
          p.bodies = s.bodies.empty() ? -1 : s.bodies[k];
          p.id = (s.bodies.empty() ? stem(s.scenes[k]) : fmt::format("bodies={}", s.bodies[k])) + " | " + bp + " | " + e;
          pts.push_back(p);
        }
  }
  return pts;
}

std::string scene_text(const Sweep& s, const Point& p, std::vector<std::string>* added) {
  const std::string& file = s.scenes[p.scene];
  const std::string text = octocd::read_input_file(
      file, s.origin + ": scenes", "a scene name under the scene folder (--scene-dir) or a readable scene file",
      octocd::limits::kMaxSceneFileBytes);
  json j;
  try {
    j = json::parse(text);
  } catch (const json::exception& e) {
    throw InputError(fmt::format("{}: not JSON ({}); allowed: a scene file (docs/scenes.md)", file, e.what()));
  }
  auto put = [&](const std::string& key, const json& v, const std::string& what) {
    try {
      const json::json_pointer ptr(key);
      if (added && !j.contains(ptr)) added->push_back(what + " (" + key + ")");
      j[ptr] = v;
    } catch (const json::exception& e) {
      bad(s.origin, what, "cannot set " + key + " in " + file + " (" + e.what() + ")", "a JSON pointer into the scene");
    }
  };
  for (auto it = s.set.begin(); it != s.set.end(); ++it) put(it.key(), it.value(), "set." + it.key());
  for (std::size_t a = 0; a < s.axes.size(); ++a)
    put(s.axes[a].key, s.axes[a].values[p.value[a]], fmt::format("axes[{}]", a));
  return j.dump(2);
}

std::string instance_scene(const Sweep& s, std::size_t sc, long n, json* layout_out) {
  Point p;
  p.scene = sc;
  json j = json::parse(scene_text(s, p));
  const std::string& file = s.scenes[sc];
  const auto refuse = [&](const std::string& key, const std::string& problem) {
    throw InputError(fmt::format("{}: {}: {} (sweep {}, kind max-instances); allowed: a scene of one group with a "
                                 "grid layout (min, max, spacing > 0) inside a domain (min, max), like "
                                 "datasets/scenes/bunny-random-400.json",
                                 file, key, problem, s.origin));
  };
  if (!j.contains("groups") || !j["groups"].is_array() || j["groups"].size() != 1)
    refuse("groups", "not exactly one group");
  json& g = j["groups"][0];
  if (!g.contains("layout") || !g["layout"].is_object() || g["layout"].value("type", "") != "grid")
    refuse("groups[0].layout.type", "not \"grid\"");
  json& l = g["layout"];
  const auto vec3 = [&](const json& o, const char* k, const std::string& key) {
    if (!o.contains(k) || !o[k].is_array() || o[k].size() != 3 || !o[k][0].is_number() || !o[k][1].is_number() ||
        !o[k][2].is_number())
      refuse(key, "missing or not 3 numbers");
    return std::array<double, 3>{o[k][0].get<double>(), o[k][1].get<double>(), o[k][2].get<double>()};
  };
  if (!l.contains("spacing") || !l["spacing"].is_number() || !(l["spacing"].get<double>() > 0.0))
    refuse("groups[0].layout.spacing", "missing or not > 0");
  if (!j.contains("domain") || !j["domain"].is_object()) refuse("domain", "missing");
  const auto lmin = vec3(l, "min", "groups[0].layout.min"), lmax = vec3(l, "max", "groups[0].layout.max");
  const auto dmin = vec3(j["domain"], "min", "domain.min"), dmax = vec3(j["domain"], "max", "domain.max");
  const double spacing = l["spacing"].get<double>();
  long k = 1;
  while (k * k * k < n) ++k;
  const double half = 0.5 * spacing * static_cast<double>(k - 1);
  // Rounded to 1e-9 m, so 0.15 x 7 is written 1.05 (as the scene files have it), not 1.0500000000000003.
  const auto round9 = [](double v) { return std::round(v * 1e9) / 1e9; };
  json nlmin = json::array(), nlmax = json::array(), ndmin = json::array(), ndmax = json::array();
  for (int a = 0; a < 3; ++a) {
    const double c = 0.5 * (lmin[a] + lmax[a]);
    nlmin.push_back(round9(c - half));
    nlmax.push_back(round9(c + half));
    ndmin.push_back(round9(c - half - (lmin[a] - dmin[a])));
    ndmax.push_back(round9(c + half + (dmax[a] - lmax[a])));
  }
  l["min"] = nlmin;
  l["max"] = nlmax;
  j["domain"]["min"] = ndmin;
  j["domain"]["max"] = ndmax;
  g["count"] = n;
  std::string name = j.value("name", stem(file));
  const auto dash = name.find_last_of('-');
  if (dash != std::string::npos && dash + 1 < name.size() &&
      name.find_first_not_of("0123456789", dash + 1) == std::string::npos)
    name.erase(dash);
  j["name"] = fmt::format("{}-{}", name, n);
  j["description"] = fmt::format("{} Grown to {} instances on {}^3 grid slots by octocd bench (kind max-instances).",
                                 j.value("description", ""), n, k);
  if (layout_out) *layout_out = {{"domain", j["domain"]}, {"layout", l}, {"slots_per_side", k}, {"count", n}};
  return j.dump(2);
}

std::string lattice_scene(long n) {
  long k = 1;
  while (k * k * k < n) ++k;
  const double half = 0.5 * 0.145 * static_cast<double>(k - 1);
  json j{{"name", fmt::format("boxes-lattice-{}", n)},
         {"description", "box lattice for the broadphase-scaling sweep (octocd bench)"},
         {"domain", {{"min", {-half - 0.1, -half - 0.1, -half - 0.1}}, {"max", {half + 0.1, half + 0.1, half + 0.1}}}},
         {"gravity", {0.0, 0.0, 0.0}},
         {"dt", 0.001},
         {"frames", 1000},
         {"walls", "closed-box"},
         {"broadphase", {{"name", broadphase_name(BroadPhaseId::octree)}, {"depth", "auto"}}},
         {"midphase", {{"levels", "aabb-only"}}},
         {"groups",
          {{{"name", "boxes"},
            {"shape", {{"box", {0.05, 0.05, 0.05}}}},
            {"count", n},
            {"mass", 1.0},
            {"layout",
             {{"type", "grid"}, {"min", {-half, -half, -half}}, {"max", {half, half, half}}, {"spacing", 0.145},
              {"jitter", 0.02}, {"seed", 11}}},
            {"velocity", {{"type", "random"}, {"max", 1.0}, {"seed", 12}}}}}}};
  return j.dump(2);
}
}  // namespace octocd::cli::bench
