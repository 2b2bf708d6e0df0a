// `octocd bench NAME|SWEEP.json` (SPEC 12): the paper's experiments redone side by side on
// every engine this octocd has. A sweep expands to points (scene x axis values x engine,
// or bodies x broadphase x engine); each point is run `repeat` times and every figure is
// stored with its median and spread. The result file is rewritten (atomically) after every
// point, so a killed sweep keeps what it finished and `--resume` goes on from there.
// Result format: docs/bench-format.md.
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <limits>
#include <functional>
#include <map>
#include <optional>
#include <set>
#include <sstream>

#include <fmt/format.h>

#include "octocd/engine_registry.hpp"
#include "octocd/error.hpp"
#include "octocd/reference_broadphase.hpp"
#include "octocd/scene.hpp"
#include "octocd/stop.hpp"
#include "octocd/trace.hpp"
#include "tools.hpp"

namespace octocd::cli {

namespace {

namespace fs = std::filesystem;
using json = nlohmann::json;
using Clock = std::chrono::steady_clock;
constexpr int kStages = static_cast<int>(Stage::Count);

// ---- the named sweeps ------------------------------------------------------------------------
// Each is an ordinary sweep file (docs/bench-format.md); `octocd bench NAME --print` shows it.

struct NamedSweep {
  const char* name;
  const char* text;
};

const NamedSweep kNamed[] = {
    {"table5", R"({
  "name": "table5",
  "kind": "steps",
  "description": "Paper Table 5: the four Table 5 scenes (paper counts: bunny 400, armadillo 250, dragon 250, asian dragon 60) x midphase A [2], B [1,2], C [0,1,2]: steps/s, per-stage ms, pairs, contacts.",
  "scenes": ["bunny-random-400", "armadillo-random-250", "dragon-random-250", "asian-dragon-random-60"],
  "engines": ["cpu", "cuda", "bullet"],
  "axes": [{"name": "midphase", "values": ["2", "1,2", "0,1,2"], "labels": ["A", "B", "C"]}],
  "warmup": 30,
  "frames": 300,
  "repeat": 5
})"},
    {"table6", R"({
  "name": "table6",
  "kind": "steps",
  "description": "Paper Table 6: Level 0 (aabb-only) vs hierarchical C [0,1,2] on the four Table 5 scenes.",
  "scenes": ["bunny-random-400", "armadillo-random-250", "dragon-random-250", "asian-dragon-random-60"],
  "engines": ["cpu", "cuda", "bullet"],
  "axes": [{"name": "midphase", "values": ["aabb-only", "0,1,2"], "labels": ["L0", "C"]}],
  "warmup": 30,
  "frames": 300,
  "repeat": 5
})"},
    {"tableA1", R"({
  "name": "tableA1",
  "kind": "steps",
  "description": "Paper Table A1: spatial hash (h = 0.25 m) vs octree broadphase on the 50-instance stacking scene (bunny-stack-50, and the same scene with each of the other meshes), early phase (frames 1-300) and late phase (frames 2701-3000 of 3000).",
  "scenes": ["bunny-stack-50"],
  "engines": ["cpu", "cuda", "bullet"],
  "set": {"/broadphase/cell_size": 0.25},
  "axes": [{"name": "mesh", "key": "/groups/0/shape/mesh", "values": ["bunny", "armadillo", "dragon", "asian-dragon"]},
           {"name": "broadphase", "values": ["spatial-hash", "octree"], "labels": ["SH", "O-A"]}],
  "frames": 3000,
  "windows": [{"name": "early", "first": 1, "last": 300}, {"name": "late", "first": 2701, "last": 3000}],
  "series_every": 100,
  "repeat": 5
})"},
    {"figA2", R"({
  "name": "figA2",
  "kind": "steps",
  "description": "Paper Fig. A2: Baumgarte factor beta x slop delta on the stacking scene (bunny-stack-50, dt 0.001, 3000 frames): mean and max AABB penetration and the share of contacts above delta. Bullet is left out: its solver has neither beta nor delta. One repetition: the figures are penetrations, the same in every run (the report says so); its steps/s are no verdict.",
  "scenes": ["bunny-stack-50"],
  "engines": ["cpu", "cuda"],
  "axes": [{"name": "beta", "key": "/response/beta", "values": [0.2, 0.4, 0.6, 0.8, 1.0]},
           {"name": "delta", "key": "/response/slop", "values": [0.0005, 0.001, 0.002, 0.005]}],
  "frames": 3000,
  "warmup": 0,
  "series_every": 100,
  "repeat": 1
})"},
    {"broadphase-scaling", R"({
  "name": "broadphase-scaling",
  "kind": "broadphase",
  "description": "Every broadphase of every engine (octocd's, Bullet's and FCL's on the CPU; the device's on cuda, with lbvh, a Karras 2012 linear BVH, the standard GPU baseline) on identical recorded AABBs of box lattices (0.1 m boxes, spacing 0.145 m, 2 cm jitter, random velocities up to 1 m/s, closed box, no gravity: the density of boxes-random-10000) of 1,000 to 1,024,000 bodies, doubling; each broadphase skipped above its max_bodies, where one replay would take minutes.",
  "bodies": [1000, 2000, 4000, 8000, 16000, 32000, 64000, 128000, 256000, 512000, 1024000],
  "engines": ["cpu", "cuda"],
  "max_bodies": {"flat": 16000, "fcl-naive": 4000, "fcl-sap": 32000, "fcl-interval-tree": 32000,
                 "fcl-spatial-hash": 128000, "bullet-sap": 32000, "octree-strict": 512000, "cuda:flat": 256000},
  "warmup": 10,
  "frames": 5,
  "warm_replays": 1,
  "repeat": 5
})"},
    {"max-instances", R"J({
  "name": "max-instances",
  "kind": "max-instances",
  "description": "The paper's headline (section 5.3, Table 5): per model and engine, the largest number of instances whose steps/s over a settled window stays >= 30, found by doubling from 1, then bisection to an integer bracket [N, N+1]. Each count runs the model's Table 5 random scene (closed box, no gravity, random velocities) grown at the same density: k = ceil(cbrt(N)) slots a side at the scene's 0.3 m spacing and margin (N = 400, 250, 60 give the shipped scenes exactly), broadphase depth auto (the scenes' fixed depth 2 has 64 leaf cells: about n/64 bodies a cell, a broadphase growing as n^2), midphase B [1,2]. Window: frames 701-1000: 400 bunnies start on the grid without contact; AABB pairs and contacts per frame rise over the first 600-700 frames (pairs 25, 124, 151, 178, 186, 198, 223 per 100-frame block) and then hold (230-236 pairs, 42-49 contacts per frame to frame 1200), so the window times the steady collision load. Probes run 1 repetition, and a repetition is cut as soon as its window's step time exceeds frames / 30 s (its steps/s can then only be below 30); the bracket's two ends are measured again with 3 repetitions (median decides).",
  "scenes": ["bunny-random-400", "armadillo-random-250", "dragon-random-250", "asian-dragon-random-60"],
  "engines": ["cpu", "cuda", "bullet"],
  "set": {"/broadphase/depth": "auto", "/midphase/levels": "1,2"},
  "target_steps_per_s": 30,
  "max_instances": 1048576,
  "resolution": 0,
  "warmup": 700,
  "frames": 300,
  "repeat": 3,
  "probe_repeat": 1,
  "paper": {
    "bunny-random-400": {"count": 400, "source": "paper section 5.3: 'The Bunny model maintained over 30 fps up to 400 instances' (Table 5, B: 46.7 fps at 400, 40.1 at 450, the table's last row)"},
    "armadillo-random-250": {"count": 250, "source": "paper section 5.3: 'The Armadillo model sustained real-time performance up to around 250 instances' (Table 5, B: 45.14 fps at 250, 36.51 at 300, the table's last row)"},
    "dragon-random-250": {"count": 250, "source": "paper Table 5, B: 40.35 fps at 250, 25.6 at 300 (section 5.3 says instead that the Dragon 'fell below 30 fps at approximately 200 instances')"},
    "asian-dragon-random-60": {"count": 60, "source": "paper Table 5, B: 48.14 fps at 60, 20.15 at 70 (section 5.3 leaves the Asian Dragon out)"}
  }
})J"},
};

std::string named_list() {
  std::string s;
  for (const auto& n : kNamed) s += (s.empty() ? "" : ", ") + std::string(n.name);
  return s;
}

// ---- sweep definition ------------------------------------------------------------------------

struct Axis {
  std::string name;
  std::string key;  // JSON pointer into the scene
  std::vector<json> values;
  std::vector<std::string> labels;  // same size as values ("" when none)
};

struct Window {
  std::string name;
  int first = 1, last = 1;
};

struct Sweep {
  std::string name, kind, description, origin;
  json definition;
  std::vector<std::string> scenes;  // resolved files
  std::vector<std::string> engines;
  std::vector<Axis> axes;
  json set = json::object();
  int frames = 300, warmup = 30, repeat = 3, series_every = 0, warm_replays = 1;
  double min_time_ms = 50.0;
  std::vector<Window> windows;
  std::vector<long> bodies;
  std::vector<std::string> broadphases;
  std::map<std::string, long> max_bodies;
  // max-instances
  double target = 30.0;             // steps/s a count must reach
  long max_instances = 1048576;     // the search's cap
  double resolution = 0.0;          // bisection stops at hi - lo <= max(1, resolution * lo)
  int probe_repeat = 1;             // repetitions of a probe (the bracket's ends get `repeat`)
  int search_time_s = 0;            // > 0: no new count is measured once a search has run this long
  json paper = json::object();      // scene stem -> {"count", "source"}
};

/// The largest instance count a max-instances sweep may search to (the scene format's body
/// limit is far above; the CUDA engine's kCudaMaxBodies is 16,777,216).
constexpr long kMaxInstancesCap = 16777216;

[[noreturn]] void bad(const std::string& origin, const std::string& key, const std::string& problem,
                      const std::string& allowed) {
  throw InputError(fmt::format("{}: {}: {}; allowed: {}", origin, key, problem, allowed));
}

int get_int(const json& j, const std::string& key, const std::string& origin, int lo, int hi, int def) {
  if (!j.contains(key)) return def;
  const json& v = j.at(key);
  if (!v.is_number_integer() || v.get<long long>() < lo || v.get<long long>() > hi)
    bad(origin, key, fmt::format("{} is not an integer in range", v.dump()), fmt::format("an integer in [{}, {}]", lo, hi));
  return v.get<int>();
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

Sweep parse_sweep(const json& j, const std::string& origin, const std::string& scene_dir, const std::string& sweep_dir) {
  Sweep s;
  s.origin = origin;
  s.definition = j;
  if (!j.is_object()) bad(origin, "(top level)", "not a JSON object", "an object with name, kind, ...");
  static const std::set<std::string> common{"name",  "kind",   "description", "engines", "frames",
                                            "warmup", "repeat", "format",      "version"};
  static const std::set<std::string> steps{"scenes", "axes", "set", "windows", "series_every"};
  static const std::set<std::string> bp{"bodies",       "scenes", "broadphases", "max_bodies",
                                        "warm_replays", "set",    "min_time_ms"};
  if (!j.contains("name") || !j.at("name").is_string() || j.at("name").get<std::string>().empty())
    bad(origin, "name", "missing or not a non-empty string", "a non-empty string");
  s.name = j.at("name");
  s.kind = j.value("kind", "steps");
  static const std::set<std::string> mi{"scenes", "set",          "target_steps_per_s", "max_instances",
                                        "resolution", "paper", "probe_repeat", "search_time_s"};
  if (s.kind != "steps" && s.kind != "broadphase" && s.kind != "max-instances")
    bad(origin, "kind", "'" + s.kind + "'", "\"steps\", \"broadphase\", \"max-instances\"");
  const auto& extra = s.kind == "steps" ? steps : s.kind == "broadphase" ? bp : mi;
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
  s.description = j.value("description", "");
  s.engines = j.contains("engines") ? string_list(j, "engines", origin) : engine_names();
  for (std::size_t i = 0; i < s.engines.size(); ++i)
    if (std::find(engine_names().begin(), engine_names().end(), s.engines[i]) == engine_names().end())
      bad(origin, fmt::format("engines[{}]", i), "'" + s.engines[i] + "'", "cpu, cuda, bullet");
  s.repeat = get_int(j, "repeat", origin, 1, 1000, 5);
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
    if (j.contains("max_instances")) {
      const json& v = j.at("max_instances");
      if (!v.is_number_integer() || v.get<long long>() < 1 || v.get<long long>() > kMaxInstancesCap)
        bad(origin, "max_instances", v.dump() + " is out of range", fmt::format("an integer in [1, {}]", kMaxInstancesCap));
      s.max_instances = v.get<long>();
    }
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
  } else if (s.kind == "steps") {
    s.frames = get_int(j, "frames", origin, 1, 100000000, 300);
    s.warmup = get_int(j, "warmup", origin, 0, 100000000, 30);
    s.series_every = get_int(j, "series_every", origin, 0, 100000000, 0);
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
        ax.key = a.contains("key") ? a.at("key").get<std::string>() : axis_key(ax.name);
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
        bad(origin, "bodies", "not a non-empty array", "an array of integers in [2, 16777216]");
      for (std::size_t i = 0; i < j.at("bodies").size(); ++i) {
        const json& v = j.at("bodies")[i];
        if (!v.is_number_integer() || v.get<long>() < 2 || v.get<long>() > 16777216)
          bad(origin, fmt::format("bodies[{}]", i), v.dump(), "an integer in [2, 16777216]");
        s.bodies.push_back(v.get<long>());
      }
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
    if (j.contains("max_bodies")) {
      if (!j.at("max_bodies").is_object()) bad(origin, "max_bodies", "not an object", "{\"NAME\" or \"ENGINE:NAME\": N}");
      for (auto it = j.at("max_bodies").begin(); it != j.at("max_bodies").end(); ++it) {
        if (!it.value().is_number_integer() || it.value().get<long>() < 0)
          bad(origin, "max_bodies." + it.key(), it.value().dump(), "an integer >= 0");
        s.max_bodies[it.key()] = it.value().get<long>();
      }
    }
  }
  return s;
}

// ---- points ----------------------------------------------------------------------------------

struct Point {
  int index = 0;
  std::string id;
  std::string engine;
  std::size_t scene = 0;          // steps: index into Sweep::scenes
  std::vector<std::size_t> value;  // steps: value index per axis
  long bodies = 0;                // broadphase: body count (bodies) or -1 (scenes)
  std::string broadphase;         // broadphase kind
};

std::string stem(const std::string& path) { return fs::path(path).stem().string(); }

std::string value_text(const json& v) { return v.is_string() ? v.get<std::string>() : v.dump(); }

/// The most points a sweep may expand to (docs/bench-format.md): a larger one is refused
/// before anything runs.
constexpr std::size_t kMaxPoints = 100000;

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
        for (const auto& e : s.engines) {
          Point p;
          p.index = static_cast<int>(pts.size());
          p.engine = e;
          p.scene = sc;
          p.value = idx;
          p.id = stem(s.scenes[sc]);
          for (std::size_t a = 0; a < s.axes.size(); ++a)
            p.id += " | " + s.axes[a].name + "=" + value_text(s.axes[a].values[idx[a]]);
          p.id += " | " + e;
          pts.push_back(p);
        }
      }
    }
  } else {
    const std::size_t sizes = s.bodies.empty() ? s.scenes.size() : s.bodies.size();
    for (std::size_t k = 0; k < sizes; ++k)
      for (const auto& bp : s.broadphases)
        for (const auto& e : s.engines) {
          Point p;
          p.index = static_cast<int>(pts.size());
          p.engine = e;
          p.broadphase = bp;
          p.scene = k;
          p.bodies = s.bodies.empty() ? -1 : s.bodies[k];
          p.id = (s.bodies.empty() ? stem(s.scenes[k]) : fmt::format("bodies={}", s.bodies[k])) + " | " + bp + " | " + e;
          pts.push_back(p);
        }
  }
  return pts;
}

/// The scene text of a steps point: the scene file with the sweep's `set` and the point's
/// axis values written at their JSON pointers.
std::string scene_text(const Sweep& s, const Point& p, std::vector<std::string>* added = nullptr) {
  const std::string& file = s.scenes[p.scene];
  std::ifstream in(file);
  if (!in) bad(s.origin, "scenes", "cannot read scene file '" + file + "'",
               "a scene name under the scene folder (--scene-dir) or a readable file");
  std::stringstream ss;
  ss << in.rdbuf();
  json j;
  try {
    j = json::parse(ss.str());
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

/// The max-instances scene of `n` instances built from scene `sc` of the sweep (its
/// template, with the sweep's `set`): one group with a grid layout; its count becomes `n`
/// and its grid a cube of k = ceil(cbrt(n)) slots a side at the template's spacing, around
/// the template grid's centre, the domain keeping the template's margin around the grid
/// on every side. For the template's own count this gives the template's grid and domain
/// when the template is such a cube (the paper's random scenes are: 400 -> 8^3, 250 -> 7^3,
/// 60 -> 4^3 slots). Throws InputError naming the scene file and key when the template is
/// not of that form.
std::string instance_scene(const Sweep& s, std::size_t sc, long n, json* layout_out = nullptr) {
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

/// A box lattice of `n` bodies at the density of boxes-random-10000 (0.1 m boxes,
/// spacing 0.145 m, 2 cm jitter, random velocities up to 1 m/s, closed box, no gravity).
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
         {"broadphase", {{"name", "octree"}, {"depth", "auto"}}},
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

// ---- progress --------------------------------------------------------------------------------

class SweepProgress {
 public:
  SweepProgress(std::size_t total, bool enabled) : total_(total), enabled_(enabled), tty_(isatty(fileno(stderr)) != 0) {}
  void start(std::size_t done, const std::string& label) {
    done_ = done;
    label_ = label;
    detail_.clear();
    draw(true);
  }
  void detail(const std::string& d) {
    detail_ = d;
    draw(false);
  }
  void finish(const std::string& status) {
    if (!enabled_) return;
    if (tty_) std::fprintf(stderr, "\r\033[K");
    std::fprintf(stderr, "[%zu/%zu] %s: %s\n", done_ + 1, total_, label_.c_str(), status.c_str());
    std::fflush(stderr);
  }

 private:
  void draw(bool force) {
    if (!enabled_ || !tty_) return;
    const auto now = Clock::now();
    if (!force && now - last_ < std::chrono::milliseconds(100)) return;
    last_ = now;
    constexpr int kWidth = 24;
    const int filled = static_cast<int>(kWidth * done_ / std::max<std::size_t>(total_, 1));
    std::fprintf(stderr, "\r\033[K[%s%s] %zu/%zu  %s  %s", std::string(static_cast<std::size_t>(filled), '#').c_str(),
                 std::string(static_cast<std::size_t>(kWidth - filled), ' ').c_str(), done_, total_, label_.c_str(),
                 detail_.c_str());
    std::fflush(stderr);
  }
  std::size_t total_, done_ = 0;
  bool enabled_, tty_;
  std::string label_, detail_;
  Clock::time_point last_{};
};

// ---- running steps points ----------------------------------------------------------------------

/// Thrown between two frames (or replays) once SIGINT or SIGTERM arrived: the point is
/// abandoned, the finished ones are kept (octocd/stop.hpp).
struct BenchStopped {};

void throw_if_stopped() {
  if (octocd::stop_signal() != 0) throw BenchStopped{};
}

/// The process's CPU time (every thread, user + system) in ms: what a step costs the machine,
/// without the time the scheduler gave other processes (a shared machine's load).
double process_cpu_ms() {
  timespec ts{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
  return 1e3 * static_cast<double>(ts.tv_sec) + 1e-6 * static_cast<double>(ts.tv_nsec);
}

/// Sums over the frames of one window of one repetition.
struct WindowSums {
  std::int64_t frames = 0;
  std::int64_t bound_frames = 0;  // > 0: cut short; steps/s is then the bound bound_frames / step_ms
  double step_ms = 0.0;
  std::array<double, kStages> stage_ms{};
  double pairs = 0, candidates = 0, box_pairs = 0, vertex_tests = 0, contacts = 0, memory = 0;
  double pen_weighted = 0, share_weighted = 0, pen_max = 0;
  double cpu_ms = 0.0;  // process CPU time (every thread) spent in the step calls
  void add(const FrameMetrics& m) {
    ++frames;
    step_ms += m.step_ms;
    for (int s = 0; s < kStages; ++s) stage_ms[s] += m.stage_ms[s];
    pairs += static_cast<double>(m.aabb_pairs);
    candidates += static_cast<double>(m.cell_candidates);
    box_pairs += static_cast<double>(m.box_pairs);
    vertex_tests += static_cast<double>(m.vertex_tests);
    const double c = static_cast<double>(m.contacts);
    contacts += c;
    memory += static_cast<double>(m.memory_bytes);
    pen_weighted += c * m.penetration_mean;
    share_weighted += c * m.penetration_share_above_slop;
    pen_max = std::max(pen_max, m.penetration_max);
  }
};

struct ModelCache {
  std::string text;
  std::shared_ptr<const Model> model;
  std::shared_ptr<const Model> get(const std::string& t, const std::string& origin, const std::string& data_dir) {
    if (t != text || !model) {
      model.reset();
      model = build_model(parse_scene(t, origin, data_dir));
      text = t;
    }
    return model;
  }
};

std::string file_safe(const std::string& id) {
  std::string out;
  for (char c : id) out += (std::isalnum(static_cast<unsigned char>(c)) || c == '.' || c == '-') ? c : '_';
  return out;
}

/// What a max-instances probe changes in run_steps_point.
struct StepsOverride {
  const std::string* text = nullptr;  ///< the scene text instead of scene_text(s, p)
  int repeat = 0;                     ///< > 0: repetitions instead of s.repeat
  /// > 0: a repetition is cut once its first window's step time exceeds frames / cut_below
  /// seconds (its steps/s can then only end below cut_below: the stored value is that upper
  /// bound), and no more repetitions run once most of them were cut (the median is below).
  double cut_below = 0.0;
  bool trace = true;  ///< false: no trace even with --trace-dir (a later round-robin repetition)
};

json run_steps_point(const Sweep& s, const Point& p, ModelCache& cache, const BenchOptions& o,
                     SweepProgress& progress, const StepsOverride& ov = {}) {
  json r;
  json params{{"scene", stem(s.scenes[p.scene])}, {"engine", p.engine}};
  for (std::size_t a = 0; a < s.axes.size(); ++a) {
    params["axes"][s.axes[a].name] = s.axes[a].values[p.value[a]];
    if (!s.axes[a].labels[p.value[a]].empty()) params["labels"][s.axes[a].name] = s.axes[a].labels[p.value[a]];
  }
  r["params"] = params;
  std::vector<std::string> added;
  const std::string text = ov.text ? *ov.text : scene_text(s, p, &added);
  const int repeat = ov.repeat > 0 ? ov.repeat : s.repeat;
  const std::string origin = s.scenes[p.scene];
  std::shared_ptr<const Model> model;
  try {
    model = cache.get(text, origin, o.data_dir);
  } catch (const InputError& e) {
    // A key the sweep sets that the scene file does not have, and the scene refuses: the
    // sweep's pointer is wrong, not the scene.
    if (!added.empty() && std::string(e.what()).find("unknown key") != std::string::npos)
      bad(s.origin, added.front(),
          fmt::format("not a key of scene file {}, and the scene refuses it ({})", origin, e.what()),
          "a JSON pointer to a scene key (docs/scenes.md), e.g. /response/beta");
    r["status"] = "skipped";
    r["reason"] = std::string("scene: ") + e.what();
    return r;
  }
  r["bodies"] = model->initial.x.size();
  std::unique_ptr<Engine> engine;
  try {
    engine = make_engine(p.engine, model, cuda_settings_from(o.cuda), bullet_settings_from(o.bullet));
  } catch (const std::exception& e) {
    r["status"] = "skipped";
    r["reason"] = e.what();
    return r;
  }
  // An engine that ignores an axis (its own broadphase, no midphase stage) is measured once,
  // under the axis's first value.
  for (std::size_t a = 0; a < s.axes.size(); ++a) {
    bool ignores = false;
    std::string why;
    if (s.axes[a].key == "/broadphase/name" && engine->broadphase_name() != model->scene.broadphase.name) {
      ignores = true;
      why = fmt::format("engine {} runs its own broadphase ({})", p.engine, engine->broadphase_name());
    }
    if (s.axes[a].key == "/midphase/levels" && engine->midphase_name() != model->scene.midphase.to_string()) {
      ignores = true;
      why = fmt::format("engine {} has no midphase level list (it runs {})", p.engine, engine->midphase_name());
    }
    if (ignores) {
      r["ignores"][s.axes[a].name] = why;
      // The point is labelled by what it ran (the registry's name of the engine's own
      // broadphase, e.g. btDbvtBroadphase), not by the axis value it ignored.
      const EngineInfo& info = engine_info(p.engine, "engines");
      if (s.axes[a].key == "/broadphase/name" && !info.own_broadphase_class.empty())
        r["params"]["labels"][s.axes[a].name] = info.own_broadphase_class;
      if (p.value[a] != 0) {
        r["status"] = "skipped";
        r["reason"] = why + fmt::format(": measured once, under {}={}", s.axes[a].name, value_text(s.axes[a].values[0]));
        return r;
      }
    }
  }
  r["device"] = engine->device();
  r["engine_broadphase"] = engine->broadphase_name();
  r["geometry"] = engine->collision_geometry();  // what the engine collided (SPEC 15)
  for (int st = 0; st < kStages; ++st)
    r["has_stage"][stage_name(static_cast<Stage>(st))] = engine->has_stage(static_cast<Stage>(st));

  const int total = s.frames;
  // Engines that step on the host: their steps per process CPU second are a figure too (the
  // gate's, on a shared machine). A device engine's CPU time would miss its kernels.
  const bool host_engine = !octocd::engine_info(p.engine, "engines").device;
  std::vector<std::vector<WindowSums>> sums(s.windows.size());  // [window][rep]
  const int buckets = s.series_every > 0 ? (total + s.series_every - 1) / s.series_every : 0;
  std::vector<std::vector<WindowSums>> series(static_cast<std::size_t>(buckets));  // [bucket][rep]
  std::vector<double> energy_series(static_cast<std::size_t>(buckets), 0.0);
  std::vector<double> wall;
  int cut = 0;
  for (int rep = 0; rep < repeat; ++rep) {
    if (rep > 0) {
      engine.reset();  // the last repetition's device memory back first: the memory check sees one engine
      engine = make_engine(p.engine, model, cuda_settings_from(o.cuda), bullet_settings_from(o.bullet));
    }
    std::unique_ptr<TraceWriter> trace;
    if (rep == 0 && ov.trace && !o.trace_dir.empty()) {
      fs::create_directories(o.trace_dir);
      TraceMetadata meta = trace_metadata(*engine, 10);
      meta.start_time = utc_time_now();
      const std::string path = (fs::path(o.trace_dir) / (file_safe(p.id) + ".h5")).string();
      trace = std::make_unique<TraceWriter>(path, meta, trace_bodies(*engine), TraceOptions{});
      trace->append_state(0, engine->state());
      r["trace"] = path;
    }
    for (auto& w : sums) w.emplace_back();
    for (auto& b : series) b.emplace_back();
    const auto t0 = Clock::now();
    for (int f = 1; f <= total; ++f) {
      if (octocd::stop_signal() != 0) {
        if (trace) trace->close();
        throw BenchStopped{};
      }
      // A step of a big scene may take seconds: a signal it does not answer within the
      // grace ends the bench there (the result file keeps the points finished before).
      std::optional<octocd::StopWithin> within(
          std::in_place, fmt::format("bench point {} stepped frame {} of {} (a step longer than the 0.5 s grace); "
                                     "the result {} keeps the points finished before it (--resume goes on)",
                                     p.id, f, total, o.output));
      const double cpu0 = host_engine ? process_cpu_ms() : 0.0;
      const FrameMetrics& m = engine->step();
      const double cpu = host_engine ? process_cpu_ms() - cpu0 : 0.0;
      within.reset();
      for (std::size_t w = 0; w < s.windows.size(); ++w)
        if (f >= s.windows[w].first && f <= s.windows[w].last) {
          sums[w].back().add(m);
          sums[w].back().cpu_ms += cpu;
        }
      if (ov.cut_below > 0.0 && f >= s.windows[0].first) {
        WindowSums& w0 = sums[0].back();
        const std::int64_t planned = s.windows[0].last - s.windows[0].first + 1;
        if (w0.step_ms > 1000.0 * static_cast<double>(planned) / ov.cut_below) {
          w0.bound_frames = planned;
          ++cut;
          break;
        }
      }
      if (buckets > 0) {
        const auto b = static_cast<std::size_t>((f - 1) / s.series_every);
        series[b].back().add(m);
        if (rep == 0) energy_series[b] = m.kinetic_energy;
      }
      if (trace) trace->append_frame(m, engine->state(), engine->contacts());
      if ((f & 15) == 0 || f == total)
        progress.detail(fmt::format("rep {}/{} frame {}/{}", rep + 1, repeat, f, total));
    }
    wall.push_back(std::chrono::duration<double>(Clock::now() - t0).count());
    if (trace) trace->close();
    if (2 * cut > repeat) break;  // most repetitions below cut_below: the median is, whatever the rest
  }
  if (ov.cut_below > 0.0) {
    r["cut"] = {{"repetitions_run", static_cast<int>(wall.size())},
                {"repetitions_cut", cut},
                {"repetitions_planned", repeat},
                {"note", fmt::format("a repetition is cut once its window's step time exceeds {} frames / {} steps/s: "
                                     "its steps/s value is then the upper bound frames / step time so far, below {}; "
                                     "repetitions stop once most were cut",
                                     s.windows[0].last - s.windows[0].first + 1, ov.cut_below, ov.cut_below)}};
  }

  auto figures = [&](const std::vector<WindowSums>& reps) {
    json w;
    std::vector<double> sps, cpu_sps, step, pairs, cand, boxes, verts, contacts, mem, pen, share, penmax;
    std::vector<std::vector<double>> stage(kStages);
    for (const auto& x : reps) {
      const double n = static_cast<double>(std::max<std::int64_t>(x.frames, 1));
      const std::int64_t fr = x.bound_frames > 0 ? x.bound_frames : x.frames;
      sps.push_back(x.step_ms > 0 ? 1000.0 * static_cast<double>(fr) / x.step_ms : 0.0);
      cpu_sps.push_back(x.cpu_ms > 0 ? 1000.0 * static_cast<double>(x.frames) / x.cpu_ms : 0.0);
      step.push_back(x.step_ms / n);
      for (int st = 0; st < kStages; ++st) stage[st].push_back(x.stage_ms[st] / n);
      pairs.push_back(x.pairs / n);
      cand.push_back(x.candidates / n);
      boxes.push_back(x.box_pairs / n);
      verts.push_back(x.vertex_tests / n);
      contacts.push_back(x.contacts / n);
      mem.push_back(x.memory / n);
      pen.push_back(x.contacts > 0 ? x.pen_weighted / x.contacts : 0.0);
      share.push_back(x.contacts > 0 ? x.share_weighted / x.contacts : 0.0);
      penmax.push_back(x.pen_max);
    }
    w["frames"] = reps.empty() ? 0 : reps.front().frames;
    w["steps_per_s"] = spread(sps);
    if (host_engine && ov.cut_below <= 0.0) w["cpu_steps_per_s"] = spread(cpu_sps);
    w["step_ms"] = spread(step);
    for (int st = 0; st < kStages; ++st) w["stage_ms"][stage_name(static_cast<Stage>(st))] = spread(stage[st]);
    w["pairs"] = spread(pairs);
    w["cell_candidates"] = spread(cand);
    w["box_pairs"] = spread(boxes);
    w["vertex_tests"] = spread(verts);
    w["contacts"] = spread(contacts);
    w["memory_bytes"] = spread(mem);
    w["penetration_mean"] = spread(pen);
    w["penetration_max"] = spread(penmax);
    w["penetration_share_above_slop"] = spread(share);
    return w;
  };
  for (std::size_t w = 0; w < s.windows.size(); ++w) {
    json fw = figures(sums[w]);
    fw["first"] = s.windows[w].first;
    fw["last"] = s.windows[w].last;
    r["windows"][s.windows[w].name] = fw;
  }
  if (buckets > 0) {
    json ser;
    ser["every"] = s.series_every;
    for (int b = 0; b < buckets; ++b) {
      const json f = figures(series[static_cast<std::size_t>(b)]);
      ser["last_frame"].push_back(std::min(total, (b + 1) * s.series_every));
      ser["steps_per_s"].push_back(f["steps_per_s"]["median"]);
      ser["contacts"].push_back(f["contacts"]["median"]);
      ser["pairs"].push_back(f["pairs"]["median"]);
      ser["penetration_mean"].push_back(f["penetration_mean"]["median"]);
      ser["penetration_max"].push_back(f["penetration_max"]["median"]);
      ser["kinetic_energy"].push_back(energy_series[static_cast<std::size_t>(b)]);
    }
    r["series"] = ser;
  }
  r["wall_s"] = spread(wall);
  r["status"] = "ok";
  return r;
}

/// The results of one-repetition runs of one steps point (round-robin, in the order run)
/// as one result: every spread (an object with "values") over all the repetitions, the
/// series' per-block figures the median over the repetitions (kinetic energy, the trace and
/// every other field as the first repetition has them).
json merge_repetitions(const std::vector<json>& reps) {
  json out = reps.front();
  std::function<void(json&, const std::vector<const json*>&)> walk = [&](json& o,
                                                                        const std::vector<const json*>& all) {
    if (!o.is_object()) return;
    if (o.contains("values") && o["values"].is_array() && o.contains("n")) {
      std::vector<double> v;
      for (const json* a : all)
        for (const auto& x : (*a)["values"])
          v.push_back(x.is_number() ? x.get<double>() : std::numeric_limits<double>::quiet_NaN());
      o = spread(v);
      return;
    }
    for (auto it = o.begin(); it != o.end(); ++it) {
      std::vector<const json*> sub;
      for (const json* a : all)
        if (a->is_object() && a->contains(it.key())) sub.push_back(&(*a)[it.key()]);
      if (sub.size() == all.size()) walk(it.value(), sub);
    }
  };
  std::vector<const json*> all;
  for (const json& r : reps) all.push_back(&r);
  walk(out, all);
  if (out.contains("series")) {
    for (const char* key : {"steps_per_s", "contacts", "pairs", "penetration_mean", "penetration_max"}) {
      json& col = out["series"][key];
      for (std::size_t b = 0; b < col.size(); ++b) {
        std::vector<double> v;
        for (const json& r : reps) {
          const json& x = r["series"][key];
          if (b < x.size() && x[b].is_number()) v.push_back(x[b].get<double>());
        }
        if (!v.empty()) col[b] = spread(v)["median"];
      }
    }
  }
  return out;
}

// ---- running broadphase points -----------------------------------------------------------------

struct InputCache {
  std::size_t key = static_cast<std::size_t>(-1);
  std::unique_ptr<ReplayInput> input;
  std::string error;
};

json run_broadphase_point(const Sweep& s, const Point& p, InputCache& cache, const BenchOptions& o,
                          SweepProgress& progress) {
  json r;
  r["params"] = {{"broadphase", p.broadphase}, {"engine", p.engine}};
  if (p.bodies > 0) r["params"]["bodies"] = p.bodies;
  else r["params"]["scene"] = stem(s.scenes[p.scene]);
  long limit = -1;
  for (const std::string& k : {p.engine + ":" + p.broadphase, p.broadphase}) {
    const auto it = s.max_bodies.find(k);
    if (it != s.max_bodies.end()) {
      limit = it->second;
      break;
    }
  }
  if (p.bodies > 0 && limit >= 0 && p.bodies > limit) {
    r["status"] = "skipped";
    r["reason"] = fmt::format("above max_bodies {} for {} on {} (one replay would take minutes)", limit, p.broadphase,
                              p.engine);
    return r;
  }
  if (cache.key != p.scene) {
    cache.input.reset();
    cache.error.clear();
    cache.key = p.scene;
    progress.detail("recording the input frames");
    try {
      const Scene scene = p.bodies > 0 ? parse_scene(lattice_scene(p.bodies), "", o.data_dir)
                                       : load_scene(s.scenes[p.scene], o.data_dir);
      Scene sc = scene;
      sc.broadphase.name = "octree";
      cache.input = std::make_unique<ReplayInput>(replay_input_from_scene(sc, s.warmup, s.frames));
    } catch (const InputError& e) {
      cache.error = e.what();
    }
  }
  if (!cache.input) {
    r["status"] = "skipped";
    r["reason"] = "scene: " + cache.error;
    return r;
  }
  const ReplayInput& in = *cache.input;
  r["bodies"] = in.model->initial.x.size();
  if (p.bodies <= 0 && limit >= 0 && static_cast<long>(in.model->initial.x.size()) > limit) {
    r["status"] = "skipped";
    r["reason"] = fmt::format("above max_bodies {} for {} on {}", limit, p.broadphase, p.engine);
    return r;
  }
  std::size_t ticks = 0;
  const std::size_t total = in.x.size() * static_cast<std::size_t>(s.warm_replays + s.repeat);
  ReplayRun run = replay_broadphase(in, p.engine, p.broadphase, s.repeat, s.warm_replays, s.min_time_ms, [&] {
    throw_if_stopped();
    ++ticks;
    progress.detail(fmt::format("replay {}/{}", ticks, total));
  });
  if (!run.ok) {
    r["status"] = "skipped";
    r["reason"] = run.reason;
    return r;
  }
  r["device"] = run.device;
  r["frames"] = in.frames.size();
  r["ms_per_frame"] = spread(run.ms);
  r["pairs"] = run.pairs;
  r["cell_candidates"] = run.candidates;
  r["matches_recorded"] = run.matches_recorded;
  r["recorded"] = run.recorded_detail;
  r["status"] = run.matches_recorded ? "ok" : "failed";
  if (!run.matches_recorded) r["reason"] = "pairs differ from the recording run's: " + run.recorded_detail;
  return r;
}

// ---- max-instances: the largest count at the target steps/s -----------------------------------

/// A probe's outcome as the search sees it.
enum class Verdict {
  Pass,     ///< steps/s (median over the repetitions) >= the target
  Below,    ///< steps/s below the target
  Limit,    ///< the count does not fit (device or host memory, the engine's body limit): above the maximum
  Skipped,  ///< the engine cannot run at all (count 1): the search is skipped
  Failed,   ///< a runtime failure (e.g. a non-finite state): the search stops
  TimeUp    ///< the search's time limit passed before this count was measured: it ends as it is
};

/// The bracket a search ends with: lo = the largest count found to pass (0: none), hi = the
/// smallest count above lo found not to pass (-1: none, lo is the cap).
struct Bracket {
  long lo = 0, hi = -1;
};

/// Doubling from 1, then bisection, on `decide` (called once per count it needs; the caller
/// memoizes): ends when hi - lo <= max(1, floor(resolution x lo)). A count that is not Pass
/// counts as above the maximum (Below, Limit); Skipped, Failed or TimeUp end the search at
/// once (`*stop` set to that verdict).
Bracket search_bracket(long cap, double resolution, const std::function<Verdict(long)>& decide, Verdict* stop) {
  *stop = Verdict::Pass;
  const auto pass = [&](long n) {
    const Verdict v = decide(n);
    if (v == Verdict::Skipped || v == Verdict::Failed || v == Verdict::TimeUp) *stop = v;
    return v == Verdict::Pass;
  };
  Bracket b;
  if (!pass(1)) {
    b.hi = 1;
    return b;
  }
  b.lo = 1;
  // One count: false when the search ends there (the bracket left as it was).
  const auto step = [&](long n) {
    const bool ok = pass(n);
    if (*stop != Verdict::Pass) return false;
    (ok ? b.lo : b.hi) = n;
    return true;
  };
  while (b.hi < 0) {
    if (b.lo >= cap) return b;  // the cap still passes
    if (!step(std::min(2 * b.lo, cap))) return b;
  }
  while (b.hi - b.lo > std::max<long>(1, static_cast<long>(std::floor(resolution * static_cast<double>(b.lo))))) {
    if (!step(b.lo + (b.hi - b.lo) / 2)) return b;
  }
  return b;
}

/// Whether a runtime failure is memory running out (cudaMalloc, the CUDA engine's memory
/// check, std::bad_alloc's text): the count does not fit, a limit, not a failure.
bool is_memory_failure(const std::string& what) {
  for (const char* k : {"cudaMalloc", "out of memory", "of device memory", "std::bad_alloc", "bad_alloc"})
    if (what.find(k) != std::string::npos) return true;
  return false;
}

/// Everything run_max_instances shares with bench_command.
struct MaxInstancesRun {
  const Sweep& s;
  const BenchOptions& o;
  json& result;
  std::map<std::string, json>& kept;  // resumed points by id
  std::set<std::string> visited;      // kept points met again
  ModelCache models;
  SweepProgress& progress;
  std::function<void()> write;
  int next_index = 0;
  bool any_failed = false;
};

/// One measured (or resumed) count: its point in the result and the verdict.
struct Measured {
  Verdict verdict = Verdict::Below;
  json point;
};

Measured measure_count(MaxInstancesRun& run, std::size_t sc, const std::string& engine, long n, bool confirm,
                       std::size_t search) {
  const Sweep& s = run.s;
  const int reps = confirm ? s.repeat : s.probe_repeat;
  Point p;
  p.scene = sc;
  p.engine = engine;
  p.id = fmt::format("{} | instances={} | {}{}", stem(s.scenes[sc]), n, engine, confirm ? " | confirm" : "");
  json r;
  const auto kept = run.kept.find(p.id);
  if (kept != run.kept.end()) {
    r = kept->second;  // resumed: already in result["points"]
    run.visited.insert(p.id);
  } else {
    if (const int sig = octocd::stop_signal()) {
      (void)sig;
      throw BenchStopped{};
    }
    p.index = run.next_index++;
    run.progress.start(search, p.id);
    json layout;
    std::string text;
    try {
      text = instance_scene(s, sc, n, &layout);
      StepsOverride ov;
      ov.text = &text;
      ov.repeat = reps;
      ov.cut_below = s.target;
      r = run_steps_point(s, p, run.models, run.o, run.progress, ov);
    } catch (const BenchStopped&) {
      throw;
    } catch (const InputError& e) {
      if (n == 1) throw;  // the template itself is refused: bad input
      r = json::object();
      r["status"] = "skipped";
      r["reason"] = std::string("scene: ") + e.what();
    } catch (const std::bad_alloc&) {
      r = json::object();
      r["status"] = "skipped";
      r["reason"] = fmt::format("host memory: {} instances do not fit (std::bad_alloc)", n);
      run.models = ModelCache{};
    } catch (const std::exception& e) {
      r = json::object();
      r["status"] = is_memory_failure(e.what()) ? "skipped" : "failed";
      r["reason"] = e.what();
    }
    r["id"] = p.id;
    r["index"] = p.index;
    r["params"]["scene"] = stem(s.scenes[sc]);
    r["params"]["engine"] = engine;
    r["params"]["axes"]["instances"] = n;
    r["role"] = confirm ? "confirm" : "probe";
    r["target_steps_per_s"] = s.target;
    if (!layout.is_null()) r["scene"] = layout;
    r["finished"] = utc_time_now();
    r["load_average"] = load_average();
    {
      const long threads = run.result["machine"].value("threads", 0L);
      const json& la = r["load_average"];
      r["under_load"] = threads > 0 && !la.empty() && la[0].get<double>() > static_cast<double>(threads) + 1.0;
    }
    // The verdict, stored with the point so that a resumed run decides the same.
    const std::string status = r.value("status", "");
    if (status == "ok") {
      const double med = r["windows"][s.windows[0].name]["steps_per_s"].value("median", 0.0);
      r["verdict"] = med >= s.target ? "pass" : "below";
    } else if (status == "skipped") {
      // Count 1 that cannot start: the engine is missing (skip the search), unless the one
      // instance does not fit (a limit: the result is 0 with the reason).
      r["verdict"] = n == 1 && !is_memory_failure(r.value("reason", "")) ? "skipped" : "limit";
    } else {
      r["verdict"] = "failed";
    }
    std::string line = r.value("status", "?");
    if (status == "ok")
      line += fmt::format(" ({:.1f} steps/s median, {} {} {:g}{})",
                          r["windows"][s.windows[0].name]["steps_per_s"].value("median", 0.0),
                          r["verdict"] == "pass" ? "pass:" : "below", r["verdict"] == "pass" ? ">=" : "<", s.target,
                          r.contains("cut") && r["cut"].value("repetitions_cut", 0) > 0 ? ", cut short" : "");
    else
      line += ": " + r.value("reason", "");
    run.progress.finish(line);
    if (status == "failed") run.any_failed = true;
    run.result["points"].push_back(r);
    run.result["points_total"] = run.result["points"].size();
    run.write();
  }
  Measured m;
  m.point = r;
  const std::string v = r.value("verdict", "");
  m.verdict = v == "pass"      ? Verdict::Pass
              : v == "below"   ? Verdict::Below
              : v == "limit"   ? Verdict::Limit
              : v == "skipped" ? Verdict::Skipped
                               : Verdict::Failed;
  return m;
}

/// One (model, engine) search: doubling + bisection on probes of probe_repeat repetitions,
/// then the bracket's ends measured again with `repeat` repetitions (their median
/// decides); while that changes the bracket, the search goes on from the new decisions.
/// Returns the summary stored in result["searches"].
json search_max_instances(MaxInstancesRun& run, std::size_t sc, const std::string& engine, std::size_t search) {
  const Sweep& s = run.s;
  std::map<long, Measured> probe, full;
  const auto started = Clock::now();
  const auto time_up = [&] {
    return s.search_time_s > 0 &&
           std::chrono::duration<double>(Clock::now() - started).count() > static_cast<double>(s.search_time_s);
  };
  const auto decide = [&](long n) {
    const auto f = full.find(n);
    if (f != full.end()) return f->second.verdict;
    auto it = probe.find(n);
    if (it == probe.end()) {
      if (time_up() && !run.kept.count(fmt::format("{} | instances={} | {}", stem(s.scenes[sc]), n, engine)))
        return Verdict::TimeUp;
      it = probe.emplace(n, measure_count(run, sc, engine, n, false, search)).first;
    }
    return it->second.verdict;
  };
  const bool confirming = s.repeat > s.probe_repeat;
  Bracket b;
  Verdict stop = Verdict::Pass;
  bool unconfirmed = false;  // the time limit came before the bracket's ends were confirmed
  for (;;) {
    b = search_bracket(s.max_instances, s.resolution, decide, &stop);
    if (stop != Verdict::Pass || !confirming) break;
    if (time_up()) {
      unconfirmed = (b.lo >= 1 && !full.count(b.lo)) || (b.hi >= 1 && !full.count(b.hi));
      break;
    }
    bool measured = false;
    for (const long n : {b.lo, b.hi}) {
      if (n < 1 || full.count(n)) continue;
      if (probe.count(n) && probe.at(n).verdict != Verdict::Pass && probe.at(n).verdict != Verdict::Below) continue;
      full.emplace(n, measure_count(run, sc, engine, n, true, search));
      measured = true;
    }
    if (!measured) break;
  }
  const auto measured_at = [&](long n) -> const Measured* {
    if (full.count(n)) return &full.at(n);
    if (probe.count(n)) return &probe.at(n);
    return nullptr;
  };
  const std::string scene = stem(s.scenes[sc]);
  json sum{{"scene", scene}, {"engine", engine}, {"target_steps_per_s", s.target}, {"max_instances_cap", s.max_instances},
           {"resolution", s.resolution}, {"window", {{"first", s.windows[0].first}, {"last", s.windows[0].last}}},
           {"probes", probe.size()}, {"confirmations", full.size()}};
  try {
    const json t = json::parse(scene_text(s, [&] {
      Point p;
      p.scene = sc;
      return p;
    }()));
    sum["model"] = t["groups"][0]["shape"].value("mesh", t["groups"][0].value("name", scene));
  } catch (const std::exception&) {
    sum["model"] = scene;
  }
  if (s.paper.contains(scene)) sum["paper"] = s.paper[scene];
  const auto sps = [&](long n) -> json {
    const Measured* m = measured_at(n);
    if (!m || m->point.value("status", "") != "ok") return nullptr;
    return m->point["windows"][s.windows[0].name]["steps_per_s"];
  };
  if (stop == Verdict::Skipped) {
    const Measured* m = measured_at(1);
    sum["status"] = "skipped";
    sum["reason"] = m ? m->point.value("reason", "") : "";
    return sum;
  }
  if (stop == Verdict::Failed) {
    long at = -1;
    for (const auto& [n, m] : probe)
      if (m.verdict == Verdict::Failed) at = n;
    for (const auto& [n, m] : full)
      if (m.verdict == Verdict::Failed) at = n;
    const Measured* m = measured_at(at);
    sum["status"] = "failed";
    sum["reason"] = fmt::format("{} instances: {}", at, m ? m->point.value("reason", "") : "");
    sum["bracket"] = {b.lo, nullptr};
    return sum;
  }
  sum["status"] = "ok";
  sum["max_instances"] = b.lo;
  const bool timed_out = stop == Verdict::TimeUp || unconfirmed;
  sum["bracket"] = {b.lo, b.hi < 0 ? json(nullptr) : json(b.hi)};
  sum["steps_per_s"] = sps(b.lo);
  if (b.hi > 0) {
    sum["steps_per_s_above"] = sps(b.hi);
    // Cut repetitions hold upper bounds (docs/bench-format.md): say so beside the figure.
    const Measured* m = measured_at(b.hi);
    sum["steps_per_s_above_cut"] = m && m->point.contains("cut") && m->point["cut"].value("repetitions_cut", 0) > 0;
  }
  const Measured* at_lo = measured_at(b.lo);
  const Measured* at_hi = b.hi > 0 ? measured_at(b.hi) : nullptr;
  if (at_lo) sum["repetitions_at_max"] = at_lo->point["windows"][s.windows[0].name]["steps_per_s"].value("n", 0);
  std::string reason;
  if (b.lo == 0) {
    sum["limited_by"] = !(at_hi && at_hi->verdict == Verdict::Limit) ? "steps/s"
                        : is_memory_failure(at_hi->point.value("reason", "")) ? "memory"
                                                                               : "limit";
    reason = at_hi && at_hi->verdict == Verdict::Limit
                 ? "a single instance does not fit: " + at_hi->point.value("reason", "")
                 : fmt::format("a single instance already runs under {:g} steps/s ({:.2f} steps/s median over {} "
                               "repetition(s))",
                               s.target, sps(1).is_null() ? 0.0 : sps(1).value("median", 0.0),
                               sps(1).is_null() ? 0 : sps(1).value("n", 0));
  } else if (b.hi < 0 && stop == Verdict::TimeUp) {
    reason = fmt::format("{} instances run at >= {:g} steps/s; no higher count was measured", b.lo, s.target);
  } else if (b.hi < 0) {
    sum["limited_by"] = "cap";
    reason = fmt::format("the cap max_instances = {} still runs at >= {:g} steps/s: the maximum is at least {} (raise "
                         "--max-instances)",
                         s.max_instances, s.target, s.max_instances);
  } else if (at_hi && at_hi->verdict == Verdict::Limit) {
    sum["limited_by"] = is_memory_failure(at_hi->point.value("reason", "")) ? "memory" : "limit";
    reason = fmt::format("{} instances do not fit, so the search stopped there: {}", b.hi,
                         at_hi->point.value("reason", ""));
  } else {
    sum["limited_by"] = "steps/s";
    reason = b.hi == b.lo + 1
                 ? fmt::format("{} instances run at >= {:g} steps/s, {} below", b.lo, s.target, b.hi)
                 : fmt::format("{} instances run at >= {:g} steps/s, {} below; counts between were not probed "
                               "(resolution {:g})",
                               b.lo, s.target, b.hi, s.resolution);
  }
  if (timed_out) {
    sum["time_limit_s"] = s.search_time_s;
    const long width = std::max<long>(1, static_cast<long>(std::floor(s.resolution * static_cast<double>(b.lo))));
    reason += fmt::format(
        "; the search's time limit ({} s) ended it{}", s.search_time_s,
        b.hi < 0 && b.lo < s.max_instances
            ? ": the maximum is at least " + std::to_string(b.lo)
            : b.hi - b.lo > width ? std::string(" before the bracket was narrowed further")
                                  : fmt::format(" before the bracket's ends were measured with {} repetitions", s.repeat));
    if (b.hi < 0 && b.lo < s.max_instances) sum["limited_by"] = "time";
  }
  sum["reason"] = reason;
  return sum;
}

// ---- the command -----------------------------------------------------------------------------

std::pair<int, int> parse_shard(const std::string& text) {
  if (text.empty()) return {0, 1};
  const auto slash = text.find('/');
  int i = -1, n = -1;
  try {
    if (slash != std::string::npos) {
      std::size_t u1 = 0, u2 = 0;
      i = std::stoi(text.substr(0, slash), &u1);
      n = std::stoi(text.substr(slash + 1), &u2);
      if (u1 != slash || u2 != text.size() - slash - 1) i = n = -1;
    }
  } catch (const std::exception&) {
    i = n = -1;
  }
  if (n < 1 || i < 0 || i >= n)
    throw InputError(fmt::format("--shard: '{}'; allowed: i/N with N >= 1 and 0 <= i < N (e.g. "
                                 "$SLURM_ARRAY_TASK_ID/$SLURM_ARRAY_TASK_COUNT with --array=0-(N-1))",
                                 text));
  return {i, n};
}

std::string default_scene_dir() { return (fs::path(source_dir()) / "datasets" / "scenes").string(); }

}  // namespace

CLI::App* add_bench_command(CLI::App& app, BenchOptions& o) {
  CLI::App* c = app.add_subcommand(
      "bench",
      "Run a benchmark sweep (the paper's Tables 5, 6, A1, Fig. A2, broadphase scaling, the most instances at 30 "
      "steps/s) on every engine this octocd has, side by side; results as JSON (docs/bench-format.md). Exit 0 ok, 1 a point failed, 2 bad input");
  c->add_option("sweep", o.sweep, "A named sweep (" + named_list() + ") or a sweep JSON file");
  c->add_option("-o,--output", o.output, "Result file (JSON), rewritten after every finished point");
  c->add_option("--engines", o.engines, "Comma-separated engines, overrides the sweep's: cpu, cuda, bullet");
  add_cuda_settings_option(c, o.cuda);
  add_bullet_settings_option(c, o.bullet);
  c->add_option("--repeat", o.repeat, "Repetitions of every point, overrides the sweep's (>= 1)")
      ->check(CLI::PositiveNumber);
  c->add_option("--frames", o.frames,
                "Timed frames per run (steps sweeps without windows; max-instances: the window's frames) or recorded "
                "frames (broadphase sweeps), overrides the sweep's (>= 1)")
      ->check(CLI::PositiveNumber);
  c->add_option("--warmup", o.warmup,
                "Untimed frames before the timed ones (steps and max-instances sweeps without windows) or steps before "
                "recording (broadphase sweeps), overrides the sweep's (>= 0)")
      ->check(CLI::NonNegativeNumber);
  c->add_option("--target", o.target,
                "max-instances: the steps/s a count must reach over the window, overrides the sweep's (default 30)")
      ->check(CLI::Range(1e-6, 1e9));
  c->add_option("--max-instances", o.max_instances,
                "max-instances: the largest count to try (the search's cap), overrides the sweep's (default 1048576)")
      ->check(CLI::Range(1L, kMaxInstancesCap));
  c->add_option("--resolution", o.resolution,
                "max-instances: stop bisecting at hi - lo <= max(1, resolution x lo), overrides the sweep's (default 0: "
                "an integer bracket [N, N+1]; 0.05 saves device time)")
      ->check(CLI::Range(0.0, 0.999));
  c->add_option("--search-time", o.search_time_s,
                "max-instances: seconds after which a search measures no new count and ends with the bracket it has "
                "(0: no limit), overrides the sweep's; bounds device time")
      ->check(CLI::Range(0, 100000000));
  c->add_option("--shard", o.shard,
                "i/N: run only the points whose index is i modulo N (0 <= i < N), for job arrays; `report` merges "
                "the shards' result files");
  c->add_flag("--resume", o.resume,
              "Continue the result file of an interrupted run of the same sweep: keep its finished points, run the rest");
  c->add_flag("--list", o.list, "List the named sweeps and exit");
  c->add_flag("--print", o.print, "Print the sweep's definition (JSON) and exit");
  c->add_option("--print-scene", o.print_scene,
                "max-instances: print the scene each of the sweep's models runs at N instances (JSON, one per model "
                "after a // SCENE line when there are several) and exit")
      ->check(CLI::Range(1L, kMaxInstancesCap));
  c->add_flag("--quiet", o.quiet, "No progress output");
  c->add_option("--scene-dir", o.scene_dir,
                "Folder of the scenes named in sweeps (default: datasets/scenes of the source tree, or "
                "$OCTOCD_SOURCE_DIR/datasets/scenes)");
  c->add_option("--data-dir", o.data_dir, "Folder of the dataset meshes (default as for `run`)");
  c->add_option("--trace-dir", o.trace_dir,
                "Also write the first repetition of every steps point as a trace (.h5) into this folder");
  return c;
}

int bench_command(const BenchOptions& o) {
  (void)cuda_settings_from(o.cuda);  // bad --cuda items are input errors before any point runs
  (void)bullet_settings_from(o.bullet);
  if (o.list) {
    for (const auto& n : kNamed) {
      const json j = json::parse(n.text);
      fmt::print("{:<20} {}\n", n.name, j.value("description", ""));
    }
    return 0;
  }
  if (o.sweep.empty())
    throw InputError("bench: no sweep given; allowed: a named sweep (" + named_list() + ") or a sweep JSON file");
  const std::string scene_dir = o.scene_dir.empty() ? default_scene_dir() : o.scene_dir;
  json def;
  std::string origin, sweep_dir;
  const NamedSweep* named = nullptr;
  for (const auto& n : kNamed)
    if (o.sweep == n.name) named = &n;
  if (named) {
    def = json::parse(named->text);
    origin = "sweep '" + o.sweep + "'";
  } else {
    std::error_code ec;
    if (!fs::is_regular_file(o.sweep, ec)) {
      if (fs::path(o.sweep).extension() == ".json")
        throw InputError(fmt::format("{}: no such file; allowed: a sweep JSON file or a named sweep ({})", o.sweep,
                                     named_list()));
      throw InputError(fmt::format("bench: unknown sweep '{}'; allowed: {}, or a sweep JSON file", o.sweep,
                                   named_list()));
    }
    std::ifstream in(o.sweep);
    std::stringstream ss;
    ss << in.rdbuf();
    try {
      def = json::parse(ss.str());
    } catch (const json::exception& e) {
      throw InputError(fmt::format("{}: not JSON ({}); allowed: a sweep file (docs/bench-format.md)", o.sweep, e.what()));
    }
    origin = o.sweep;
    sweep_dir = fs::path(o.sweep).parent_path().string();
  }
  Sweep s = parse_sweep(def, origin, scene_dir, sweep_dir);
  if (o.print) {
    fmt::print("{}\n", def.dump(2));
    return 0;
  }
  if (o.print_scene > 0) {
    if (s.kind != "max-instances")
      throw InputError(fmt::format("--print-scene: {} is of kind '{}'; allowed: a sweep of kind max-instances", origin,
                                   s.kind));
    for (std::size_t sc = 0; sc < s.scenes.size(); ++sc) {
      std::error_code ec;
      if (!fs::is_regular_file(s.scenes[sc], ec))
        throw InputError(fmt::format("{}: scenes: '{}' not found; allowed: a scene name under {} (--scene-dir) or a "
                                     "scene file",
                                     origin, s.scenes[sc], scene_dir));
      if (s.scenes.size() > 1) fmt::print("// {}\n", stem(s.scenes[sc]));
      fmt::print("{}\n", instance_scene(s, sc, o.print_scene));
    }
    return 0;
  }
  if (o.output.empty()) throw InputError("bench: -o: missing; allowed: the result file to write (RESULT.json)");
  if (!o.engines.empty()) {
    s.engines = split_list(o.engines);
    for (const auto& e : s.engines)
      if (std::find(engine_names().begin(), engine_names().end(), e) == engine_names().end())
        throw InputError(fmt::format("--engines: unknown engine '{}'; allowed: cpu, cuda, bullet", e));
    if (s.engines.empty()) throw InputError("--engines: empty; allowed: a comma-separated list of cpu, cuda, bullet");
  }
  if (o.repeat > 0) {
    s.repeat = o.repeat;
    s.probe_repeat = std::min(s.probe_repeat, s.repeat);
  }
  if (o.warmup >= 0) {
    if (s.kind == "broadphase") {
      s.warmup = o.warmup;
    } else if (def.contains("windows")) {
      throw InputError(fmt::format("--warmup: {} has windows (fixed frame ranges); allowed: --warmup only for sweeps "
                                   "without windows",
                                   origin));
    } else {
      const int timed = s.windows.front().last - s.windows.front().first + 1;
      s.warmup = o.warmup;
      s.windows.front().first = s.warmup + 1;
      s.windows.front().last = s.warmup + timed;
      s.frames = s.warmup + timed;
    }
  }
  if (s.kind != "max-instances" && (o.target > 0 || o.max_instances > 0 || o.resolution >= 0 || o.search_time_s >= 0))
    throw InputError(fmt::format("--target, --max-instances, --resolution, --search-time: {} is of kind '{}'; allowed: only for "
                                 "sweeps of kind max-instances",
                                 origin, s.kind));
  if (o.target > 0) s.target = o.target;
  if (o.max_instances > 0) s.max_instances = o.max_instances;
  if (o.resolution >= 0) s.resolution = o.resolution;
  if (o.search_time_s >= 0) s.search_time_s = o.search_time_s;
  if (o.frames > 0) {
    if (s.kind == "broadphase") {
      s.frames = o.frames;
    } else if (def.contains("windows")) {
      throw InputError(fmt::format("--frames: {} has windows (fixed frame ranges); allowed: --frames only for sweeps "
                                   "without windows",
                                   origin));
    } else {
      s.frames = s.warmup + o.frames;
      s.windows.front().last = s.frames;
    }
  }
  const auto [shard, shards] = parse_shard(o.shard);
  for (const auto& sc : s.scenes) {
    std::error_code ec;
    if (!fs::is_regular_file(sc, ec))
      throw InputError(fmt::format("{}: scenes: '{}' not found; allowed: a scene name under {} (--scene-dir) or a "
                                   "scene file",
                                   origin, sc, scene_dir));
  }
  const std::vector<Point> points = expand(s);

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
    // The template must be grown into a scene (bad input now, not after an hour).
    for (std::size_t sc = 0; sc < s.scenes.size(); ++sc) (void)instance_scene(s, sc, 1);
  }
  json result{{"format", "octocd-bench"},
              {"version", 1},
              {"sweep", {{"name", s.name}, {"kind", s.kind}, {"description", s.description}, {"origin", origin},
                         {"definition", def}}},
              {"settings", settings},
              {"machine", machine_description()},
              {"build", build_description()},
              {"started", utc_time_now()},
              {"points_total", points.size()},
              {"complete", false},
              {"points", json::array()}};
  std::map<std::string, json> kept;
  std::error_code ec;
  if (fs::exists(o.output, ec)) {
    if (!o.resume)
      throw InputError(fmt::format("{}: exists; allowed: a new file, or --resume to continue it (remove it to start "
                                   "over)",
                                   o.output));
    json old;
    try {
      std::ifstream in(o.output);
      old = json::parse(in);
    } catch (const json::exception& e) {
      throw InputError(fmt::format("{}: not JSON ({}); allowed: a result file of octocd bench to resume", o.output,
                                   e.what()));
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
  } else if (o.resume) {
    // Nothing to resume: start afresh.
  }
  const fs::path parent = fs::path(o.output).parent_path();
  if (!parent.empty()) fs::create_directories(parent, ec);

  std::vector<const Point*> mine;
  for (const auto& p : points)
    if (p.index % shards == shard) mine.push_back(&p);
  // max-instances: one search per (scene, engine), scene-major; a shard takes every N-th.
  std::vector<std::pair<std::size_t, std::string>> my_searches;
  if (s.kind == "max-instances") {
    std::size_t k = 0;
    for (std::size_t sc = 0; sc < s.scenes.size(); ++sc)
      for (const auto& e : s.engines)
        if (k++ % static_cast<std::size_t>(shards) == static_cast<std::size_t>(shard)) my_searches.emplace_back(sc, e);
  }
  SweepProgress progress(s.kind == "max-instances" ? my_searches.size() : mine.size(), !o.quiet);
  ModelCache models;
  InputCache inputs;
  bool any_failed = false;
  auto write = [&] {
    result["updated"] = utc_time_now();
    write_file_atomically(o.output, result.dump(1) + "\n");
  };
  // Timing hygiene: a loaded machine or oversubscribed OpenMP threads make timings noisy;
  // warn, record it, and let the report mark the verdicts taken so.
  {
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
    if (s.repeat < 2 && !o.quiet)
      fmt::print(stderr, "bench {}: note: 1 repetition per point: no spread, so no timing verdict\n", s.name);
  }
  if (!o.quiet && s.kind == "max-instances")
    fmt::print(stderr,
               "bench {}: {} searches ({} in this shard {}/{}), engines {}, target {:g} steps/s over frames {}-{}, "
               "counts 1 to {}, probes {} repetition(s), the bracket's ends {}; result {}\n",
               s.name, s.scenes.size() * s.engines.size(), my_searches.size(), shard, shards, json(s.engines).dump(),
               s.target, s.windows[0].first, s.windows[0].last, s.max_instances, s.probe_repeat, s.repeat, o.output);
  else if (!o.quiet)
    fmt::print(stderr, "bench {}: {} points ({} in this shard {}/{}), engines {}, {} repetitions; result {}\n", s.name,
               points.size(), mine.size(), shard, shards, o.engines.empty() ? json(s.engines).dump() : o.engines,
               s.repeat, o.output);
  for (const Point* p : mine) {
    const auto it = kept.find(p->id);
    if (it != kept.end()) result["points"].push_back(it->second);  // resumed: kept as they were
  }
  if (s.kind == "max-instances")
    for (const auto& [id, pt] : kept) result["points"].push_back(pt);
  octocd::StopOnSignals stop_on_signals;  // SIGINT/SIGTERM: stop between frames, keep the finished points
  const auto stopped = [&](int sig) {
    result["stopped"] = octocd::stop_signal_name(sig);
    std::sort(result["points"].begin(), result["points"].end(),
              [](const json& a, const json& b) { return a.value("index", 0) < b.value("index", 0); });
    write();
    if (s.kind == "max-instances")
      std::fprintf(stderr,
                   "\noctocd bench: stopped by %s after %zu probes (%zu of %zu searches done); result %s keeps them "
                   "(--resume goes on)\n",
                   octocd::stop_signal_name(sig), result["points"].size(),
                   result.contains("searches") ? result["searches"].size() : std::size_t{0}, my_searches.size(),
                   o.output.c_str());
    else
      std::fprintf(stderr, "\noctocd bench: stopped by %s after %zu of %zu points; result %s keeps them (--resume goes on)\n",
                   octocd::stop_signal_name(sig), result["points"].size(), mine.size(), o.output.c_str());
    return octocd::stop_exit_code(sig);
  };
  if (s.kind == "max-instances") {
    MaxInstancesRun run{s, o, result, kept, {}, {}, progress, write};
    for (const auto& pt : result["points"]) run.next_index = std::max(run.next_index, pt.value("index", 0) + 1);
    result["searches"] = json::array();
    result["points_total"] = result["points"].size();
    std::size_t k = 0;
    for (const auto& [sc, engine] : my_searches) {
      json sum;
      try {
        sum = search_max_instances(run, sc, engine, k++);
      } catch (const BenchStopped&) {
        return stopped(octocd::stop_signal());
      }
      result["searches"].push_back(sum);
      write();
      if (!o.quiet) {
        const std::string line =
            sum.value("status", "") == "ok"
                ? fmt::format("max {} instances at >= {:g} steps/s ({})", sum["max_instances"].get<long>(), s.target,
                              sum.value("reason", ""))
                : sum.value("status", "") + ": " + sum.value("reason", "");
        fmt::print(stderr, "bench {}: {} on {}: {}\n", s.name, sum.value("model", "?"), engine, line);
      }
    }
    std::sort(result["points"].begin(), result["points"].end(),
              [](const json& a, const json& b) { return a.value("index", 0) < b.value("index", 0); });
    result["complete"] = true;
    result["machine"]["load_average_end"] = load_average();
    write();
    if (!my_searches.empty() && std::all_of(result["searches"].begin(), result["searches"].end(), [](const json& x) {
          return x.value("status", "") == "skipped";
        })) {
      const json& first = result["searches"].front();
      throw InputError(fmt::format("{}: every search skipped ({}; first: {} on {}: {}); allowed: a sweep with an "
                                   "engine this octocd can run (result kept in {})",
                                   origin, result["searches"].size(), first.value("scene", "?"),
                                   first.value("engine", "?"), first.value("reason", "?"), o.output));
    }
    if (!o.quiet) fmt::print(stderr, "bench {}: done, result {}\n", s.name, o.output);
    const bool failed = run.any_failed || std::any_of(result["searches"].begin(), result["searches"].end(),
                                                      [](const json& x) { return x.value("status", "") == "failed"; });
    return failed ? 1 : 0;
  }
  // A finished point (all its repetitions, or skipped/failed): stamped, stored, file rewritten.
  std::size_t finished = 0;
  const auto finish_point = [&](const Point& p, json r) {
    r["id"] = p.id;
    r["index"] = p.index;
    r["finished"] = utc_time_now();
    r["load_average"] = load_average();  // at the point's end: how busy the machine was meanwhile
    {
      const long threads = result["machine"].value("threads", 0L);
      const json& la = r["load_average"];
      // More runnable threads than cores (the bench's own included) while it measured.
      r["under_load"] = threads > 0 && !la.empty() && la[0].get<double>() > static_cast<double>(threads) + 1.0;
    }
    if (r.value("status", "") == "failed") any_failed = true;
    std::string status = r.value("status", "?");
    if (status == "ok" && r.contains("windows")) {
      const json& w = r["windows"].begin().value();
      status += fmt::format(" ({:.1f} steps/s median)", w["steps_per_s"].value("median", 0.0));
    } else if (status == "ok" && r.contains("ms_per_frame")) {
      status += fmt::format(" ({:.4f} ms/frame median)", r["ms_per_frame"].value("median", 0.0));
    } else if (r.contains("reason")) {
      status += ": " + r.value("reason", "");
    }
    progress.start(finished++, p.id);
    progress.finish(status);
    result["points"].push_back(r);
    write();
  };
  const auto run_point = [&](const Point& p, const StepsOverride& ov) {
    json r;
    try {
      r = s.kind == "steps" ? run_steps_point(s, p, models, o, progress, ov)
                            : run_broadphase_point(s, p, inputs, o, progress);
    } catch (const InputError&) {
      throw;
    } catch (const BenchStopped&) {
      throw;
    } catch (const std::exception& e) {
      r["status"] = "failed";
      r["reason"] = e.what();
    }
    return r;
  };
  std::vector<const Point*> todo;
  for (const Point* p : mine)
    if (!kept.count(p->id)) todo.push_back(p);
  if (s.kind == "steps") {
    // Round-robin: repetition r of every point, then repetition r + 1 of every point, so a
    // load burst on the machine hits every point's repetitions alike (SPEC 14b). A point
    // is stored once its last repetition ran (a stop before that drops its repetitions).
    std::vector<std::vector<json>> reps(todo.size());
    std::vector<std::vector<double>> started(todo.size());  // each repetition's start, s after t0
    std::vector<bool> over(todo.size(), false);
    const auto t0 = Clock::now();
    for (int rep = 0; rep < s.repeat; ++rep) {
      for (std::size_t k = 0; k < todo.size(); ++k) {
        if (over[k]) continue;
        const Point& p = *todo[k];
        if (const int sig = octocd::stop_signal()) return stopped(sig);
        progress.start(finished, fmt::format("{} (repetition {}/{})", p.id, rep + 1, s.repeat));
        StepsOverride ov;
        ov.repeat = 1;
        ov.trace = rep == 0;
        started[k].push_back(std::chrono::duration<double>(Clock::now() - t0).count());
        json r;
        try {
          r = run_point(p, ov);
        } catch (const BenchStopped&) {
          return stopped(octocd::stop_signal());
        }
        if (r.value("status", "") != "ok") {
          over[k] = true;
          finish_point(p, r);
          continue;
        }
        reps[k].push_back(std::move(r));
        if (rep + 1 == s.repeat) {
          over[k] = true;
          json m = merge_repetitions(reps[k]);
          m["repetition_start_s"] = started[k];
          finish_point(p, std::move(m));
          reps[k].clear();
        }
      }
    }
  }
  for (const Point* pp : todo) {
    if (s.kind == "steps") break;
    const Point& p = *pp;
    if (const int sig = octocd::stop_signal()) return stopped(sig);
    progress.start(finished, p.id);
    json r;
    try {
      r = run_point(p, {});
    } catch (const BenchStopped&) {
      return stopped(octocd::stop_signal());
    }
    finish_point(p, r);
  }
  // Keep the points in sweep order (resumed ones first otherwise).
  std::sort(result["points"].begin(), result["points"].end(),
            [](const json& a, const json& b) { return a.value("index", 0) < b.value("index", 0); });
  result["complete"] = true;
  result["machine"]["load_average_end"] = load_average();
  write();
  // A sweep none of whose points could run measured nothing: bad input, not success.
  if (!mine.empty() && std::all_of(result["points"].begin(), result["points"].end(),
                                   [](const json& pt) { return pt.value("status", "") == "skipped"; })) {
    const json& first = result["points"].front();
    throw InputError(fmt::format("{}: every point skipped ({} of {}; first: {}: {}); allowed: a sweep with a point "
                                 "this octocd can run (result kept in {})",
                                 origin, result["points"].size(), mine.size(), first.value("id", "?"),
                                 first.value("reason", "?"), o.output));
  }
  if (!o.quiet) fmt::print(stderr, "bench {}: done, result {}\n", s.name, o.output);
  return any_failed ? 1 : 0;
}

}  // namespace octocd::cli
