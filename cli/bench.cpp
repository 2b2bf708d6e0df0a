// `octocd bench NAME|SWEEP.json` (design.md section 12): the paper's experiments redone side by side on
// every engine this octocd has. A sweep expands to points (scene x axis values x engine,
// or bodies x broadphase x engine); each point is run `repeat` times (steps and
// speed-accuracy sweeps on a time budget per point, docs/bench-format.md "Time budget") and
// every figure is stored with its median and spread. The result file is rewritten
// (atomically) after every point, so a killed sweep keeps what it finished and `--resume`
// goes on from there.
// Named sweeps are the files of bench/sweeps/. This file holds the command; the sweep, its
// points, the max-instances search and the result file have files of their own
// (bench_sweep.hpp). Result format: docs/bench-format.md.
#include <algorithm>
#include <cmath>
#include <filesystem>
#include <map>

#include <fmt/format.h>

#include "bench_sweep.hpp"
#include "octocd/engine_registry.hpp"
#include "octocd/error.hpp"
#include "octocd/process_engines.hpp"
#include "octocd/shared_files.hpp"
#include "octocd/run_session.hpp"
#include "octocd/text.hpp"
#include "octocd/timing_limits.hpp"
#include "tools.hpp"

namespace octocd::cli {

namespace {

using namespace bench;
namespace fs = std::filesystem;

/// `bench`: from a SIGINT or SIGTERM to the end of the process, at most this long (s): a
/// step gets the 0.5 s grace (bench_points.cpp), building a point's model or closing its
/// trace is cut short at the bound; the result file keeps every point finished before
/// (rewritten atomically after each, so the bound never loses one).
constexpr double kBenchStopBound = 0.95;

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

/// --history: the finished result added to the history folder (cli/history.cpp).
void add_to_history(const BenchOptions& o, const json& result) {
  if (o.history.empty()) return;
  const std::string path = append_history(o.history, "bench", json::array({result}), json::array(), "--history");
  if (!o.quiet) fmt::print(stderr, "bench: added the result to the history: {}\n", path);
}

/// The budget on the start line: ", protocol paper (no time budget)" or ", at most 20 s a point ...".
std::string budget_text(const Sweep& s) {
  if (s.kind != "steps" && s.kind != "speed-accuracy") return "";
  if (s.protocol == "paper") return ", protocol paper (no time budget)";
  std::string t = s.max_time_s > 0 ? fmt::format(", at most {:g} s a point", s.max_time_s) : ", no time limit";
  if (s.min_time_s > 0) t += fmt::format(", repetitions until {:g} s", s.min_time_s);
  return t + (s.max_time_s > 0 ? " (--protocol paper: the full protocol)" : "");
}

std::string default_scene_dir() { return (fs::path(shared_dir()) / "datasets" / "scenes").string(); }

/// A finished point's timing figures (each window's steps_per_s, cpu_steps_per_s and
/// world_steps_per_s, a broadphase point's ms_per_frame: median, min, max, values) are
/// ones `report` takes: a finite number, 0 (not measured) or within [limits::kMinTiming,
/// limits::kMaxTiming]. Otherwise InputError naming the point, its engine, the field and
/// the range, before the point is written: no result holds a figure another command refuses.
void check_point_timings(const json& r, const Point& p) {
  const auto check = [&](const json& spread, const std::string& at) {
    if (!spread.is_object()) return;
    const auto one = [&](const json& v, const std::string& where) {
      const double x = v.is_number() ? v.get<double>() : std::nan("");
      if (x == 0.0 || (std::isfinite(x) && x >= limits::kMinTiming && x <= limits::kMaxTiming)) return;
      throw InputError(fmt::format("bench point {} (engine {}): {}: {}; allowed: a finite number from {:g} to {:g} "
                                   "(0: not measured); a timing octocd bench cannot have measured, so no result is "
                                   "written with it",
                                   printable(p.id), printable(p.engine), where, v.is_null() ? "not finite" : v.dump(),
                                   limits::kMinTiming, limits::kMaxTiming));
    };
    for (const char* k : {"median", "min", "max"})
      if (spread.contains(k)) one(spread[k], at + "." + k);
    if (spread.contains("values") && spread["values"].is_array())
      for (std::size_t i = 0; i < spread["values"].size(); ++i)
        one(spread["values"][i], fmt::format("{}.values[{}]", at, i));
  };
  if (r.value("status", "") != "ok") return;
  if (r.contains("windows") && r["windows"].is_object())
    for (const auto& [name, w] : r["windows"].items())
      for (const char* k : {"steps_per_s", "cpu_steps_per_s", "world_steps_per_s"})
        if (w.contains(k)) check(w[k], "windows." + name + "." + k);
  if (r.contains("ms_per_frame")) check(r["ms_per_frame"], "ms_per_frame");
}

}  // namespace

CLI::App* add_bench_command(CLI::App& app, BenchOptions& o) {
  CLI::App* c = add_table_command(app, CommandId::bench);
  c->add_option("sweep", o.sweep, "A named sweep (" + named_list() + ") or a sweep JSON file");
  c->add_option("-o,--output", o.output, "Result file (JSON), rewritten after every finished point");
  c->add_option("--engines", o.engines,
                "Comma-separated engines, overrides the sweep's: " + fmt::format("{}", fmt::join(engine_names(), ", ")));
  add_engine_settings_options(c, o.settings);
  c->add_option("--traced", o.traced,
                "Steps sweeps: comma-separated trace modes, each point run once per mode, overrides the sweep's "
                "(default off): off (no trace), states (a trace with the state every 10 frames, as run --trace), "
                "contacts (and every contact row, run --contacts); a traced point's steps/s counts the step, the "
                "copy-back and the trace write");
  c->add_option("--repeat", o.repeat, "Repetitions of every point, overrides the sweep's (>= 1)")
      ->check(CLI::PositiveNumber);
  c->add_option("--protocol", o.protocol,
                "Steps and speed-accuracy sweeps: budget (the default: each point runs at least its repetitions and "
                "--min-time, at most --max-time, a slow repetition cut to fewer timed frames) or paper (the sweep's "
                "full protocol, no time limit: table5's 300 frames after 30 warm-up, 5 repetitions)")
      ->check(CLI::IsMember({"budget", "paper"}));
  c->add_option("--min-time", o.min_time_s,
                fmt::format("Budget protocol: seconds a point keeps adding repetitions for once it has those asked, "
                            "overrides the sweep's min_time_s (default {:g})",
                            kDefaultMinTimeS))
      ->check(CLI::Range(0.0, 86400.0));
  c->add_option("--max-time", o.max_time_s,
                fmt::format("Budget protocol: the most seconds a point may take (its set-ups and frames), overrides the "
                            "sweep's max_time_s (default {:g}; 0: no limit); a point whose first repetition cannot "
                            "time a frame within its share is skipped with an estimate",
                            kDefaultMaxTimeS))
      ->check(CLI::Range(0.0, 86400.0));
  c->add_option("--frames", o.frames,
                "Timed frames per run (steps sweeps without windows; max-instances: the window's frames) or recorded "
                "frames (broadphase sweeps), or the frames of every run (divergence), overrides the sweep's (>= 1)")
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
              "Continue the result file of an interrupted run of the same sweep: keep its finished points, run the rest "
              "(steps, broadphase and max-instances sweeps; speed-accuracy keeps a finished result only, divergence "
              "starts over)");
  c->add_flag("--list", o.list, "List the named sweeps and exit");
  c->add_flag("--print", o.print, "Print the sweep's definition (JSON) and exit");
  c->add_option("--print-scene", o.print_scene,
                "max-instances: print the scene each of the sweep's models runs at N instances (JSON, one per model "
                "after a // SCENE line when there are several) and exit; above 10000000 bodies (limits::kMaxBodies) "
                "the scene is the bench's own: octocd run refuses it as a file")
      ->check(CLI::Range(1L, kMaxInstancesCap));
  c->add_flag("--quiet", o.quiet, "No progress output");
  c->add_option("--scene-dir", o.scene_dir,
                "Folder of the scenes named in sweeps (default: datasets/scenes of octocd's shared files: "
                "PREFIX/share/octocd when installed, else the source tree; $OCTOCD_SOURCE_DIR overrides, docs/install.md)");
  c->add_option("--data-dir", o.data_dir, "Folder of the dataset meshes (default as for `run`)");
  c->add_option("--csv", o.csv,
                "speed-accuracy: also write the points as CSV to this file; divergence: the mean and max distance per "
                "frame of every point (default: the result's name with .csv, beside it)");
  c->add_option("--trace-dir", o.trace_dir,
                "Also write the first repetition of every steps point as a trace (.h5) into this folder");
  c->add_option("--history", o.history,
                "Also add the finished result to this history folder (a new file DATE-COMMIT-bench.json, never one "
                "rewritten; `octocd report --history DIR` draws it: docs/regression.md)");
  return c;
}

int bench_command(const BenchOptions& o) {
  // Output paths before any work (atomic_file.hpp); -o's folder is created when missing.
  if (!o.output.empty()) check_output_file(o.output, "-o", true);
  if (!o.csv.empty()) check_output_file(o.csv, "--csv", true);
  if (!o.trace_dir.empty()) check_output_folder(o.trace_dir, "--trace-dir", false);
  if (!o.history.empty()) check_output_folder(o.history, "--history", true);
  check_engine_settings(o.settings, cli_argument_names());  // bad items are input errors before any point runs
  const std::vector<std::string> named = named_sweeps();
  if (o.list) {
    for (const auto& n : named) {
      const json j = read_sweep_file((fs::path(named_sweeps_dir()) / (n + ".json")).string());
      fmt::print("{:<20} {}\n", n, octocd::printable(j.value("description", "")));
    }
    return 0;
  }
  // An installed octocd without its shared files has no named sweeps: say where they were looked for.
  const std::string missing =
      named.empty() ? fmt::format(" (no named sweeps: {} holds no *.json)", named_sweeps_dir()) : std::string();
  if (o.sweep.empty())
    throw InputError("bench: no sweep given; allowed: a named sweep (" + named_list() + ") or a sweep JSON file" +
                     missing);
  const std::string scene_dir = o.scene_dir.empty() ? default_scene_dir() : o.scene_dir;
  json def;
  std::string origin, sweep_dir;
  if (std::find(named.begin(), named.end(), o.sweep) != named.end()) {
    def = read_sweep_file((fs::path(named_sweeps_dir()) / (o.sweep + ".json")).string());
    origin = "sweep '" + o.sweep + "'";
  } else {
    std::error_code ec;
    if (!fs::is_regular_file(o.sweep, ec)) {
      if (fs::path(o.sweep).extension() == ".json")
        throw InputError(fmt::format("{}: no such file; allowed: a sweep JSON file or a named sweep ({}){}", o.sweep,
                                     named_list(), missing));
      throw InputError(fmt::format("bench: unknown sweep '{}'; allowed: {}, or a sweep JSON file{}", o.sweep,
                                   named_list(), missing));
    }
    def = read_sweep_file(o.sweep);
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
        throw InputError(fmt::format("--engines: unknown engine '{}'; allowed: {}", e, fmt::join(engine_names(), ", ")));
    if (s.engines.empty())
      throw InputError(fmt::format("--engines: empty; allowed: a comma-separated list of {}", fmt::join(engine_names(), ", ")));
  }
  if (!o.traced.empty()) {
    if (s.kind != "steps")
      throw InputError(fmt::format("--traced: sweep '{}' is of kind '{}'; allowed: a steps sweep (table5, small-scenes, ...)",
                                   s.name, s.kind));
    s.traced = checked_trace_modes(split_list(o.traced), "--traced");
  }
  if (o.repeat > 0) {
    s.repeat = o.repeat;
    s.probe_repeat = std::min(s.probe_repeat, s.repeat);
  }
  // Every scene of the sweep is a file (bad input before anything runs).
  const auto check_scenes = [&] {
    for (const auto& sc : s.scenes) {
      std::error_code ec;
      if (!fs::is_regular_file(sc, ec))
        throw InputError(fmt::format("{}: scenes: '{}' not found; allowed: a scene name under {} (--scene-dir) or a "
                                     "scene file",
                                     origin, sc, scene_dir));
    }
  };
  // The time budget of a point (steps and speed-accuracy; docs/bench-format.md "Time budget").
  if (s.kind == "steps" || s.kind == "speed-accuracy") {
    s.protocol = o.protocol.empty() ? "budget" : o.protocol;
    if (s.protocol == "paper") {
      if (o.min_time_s >= 0 || o.max_time_s >= 0 || o.frames > 0 || o.warmup >= 0 || o.repeat > 0)
        throw InputError(fmt::format("--protocol paper: {} then runs its own frames, warm-up and repetitions with no "
                                     "time budget; allowed: no --min-time, --max-time, --frames, --warmup or --repeat "
                                     "with it (or --protocol budget)",
                                     origin));
      s.min_time_s = 0.0;
      s.max_time_s = 0.0;
    } else {
      s.min_time_s = o.min_time_s >= 0 ? o.min_time_s : s.min_time_s >= 0 ? s.min_time_s : kDefaultMinTimeS;
      s.max_time_s = o.max_time_s >= 0 ? o.max_time_s : s.max_time_s >= 0 ? s.max_time_s : kDefaultMaxTimeS;
      if (s.max_time_s > 0 && s.min_time_s > s.max_time_s)
        throw InputError(fmt::format("--min-time: {:g} s is above the most time a point may take ({:g} s, --max-time "
                                     "or the sweep's max_time_s); allowed: a minimum <= the maximum, or --max-time 0",
                                     s.min_time_s, s.max_time_s));
    }
  } else if (!o.protocol.empty() || o.min_time_s >= 0 || o.max_time_s >= 0) {
    throw InputError(fmt::format("--protocol, --min-time, --max-time: {} is of kind '{}'; allowed: steps and "
                                 "speed-accuracy sweeps (max-instances: --search-time)",
                                 origin, s.kind));
  }
  if (s.kind == "divergence") {
    if (o.warmup >= 0 || o.target > 0 || o.max_instances > 0 || o.resolution >= 0 || o.search_time_s >= 0 ||
        !o.trace_dir.empty() || !o.history.empty() || !o.traced.empty() || o.resume || !o.shard.empty() || o.repeat > 0)
      throw InputError(fmt::format("{} is of kind divergence; allowed: --engines, --frames, --csv, --quiet and the "
                                   "engine settings (no --warmup, --target, --max-instances, --resolution, "
                                   "--search-time, --trace-dir, --history, --traced, --resume, --shard, --repeat: one run per copy)",
                                   origin));
    if (o.frames > 0) s.frames = o.frames;
    check_scenes();
    return run_divergence(s, origin, def, o);
  }
  if (!o.csv.empty() && s.kind != "speed-accuracy" && s.kind != "divergence")
    throw InputError(fmt::format("--csv: {} is of kind '{}'; allowed: only for sweeps of kind speed-accuracy (others: "
                                 "octocd report --csv DIR)",
                                 origin, s.kind));
  if (s.kind == "speed-accuracy") {
    if (o.frames > 0 || o.warmup >= 0)
      throw InputError(fmt::format("--frames, --warmup: {} is of kind speed-accuracy; allowed: sim_seconds in the sweep "
                                   "file (every point runs the same simulated time)",
                                   origin));
    if (o.target > 0 || o.max_instances > 0 || o.resolution >= 0 || o.search_time_s >= 0)
      throw InputError(fmt::format("--target, --max-instances, --resolution, --search-time: {} is of kind "
                                   "'speed-accuracy'; allowed: only for sweeps of kind max-instances",
                                   origin));
    if (!o.trace_dir.empty())
      throw InputError(fmt::format("--trace-dir: {} is of kind speed-accuracy; allowed: only for steps sweeps", origin));
    if (!o.history.empty())
      throw InputError(fmt::format("--history: {} is of kind speed-accuracy; allowed: steps, broadphase and "
                                   "max-instances sweeps",
                                   origin));
    const auto [shard, shards] = parse_shard(o.shard);
    check_scenes();
    return run_speed_accuracy(s, origin, def, o, shard, shards, !o.engines.empty());
  }
  // --warmup and --frames move the frame range of a steps sweep only where it has no windows.
  const auto refuse_windows = [&](const char* option) {
    if (def.contains("windows"))
      throw InputError(fmt::format("{}: {} has windows (fixed frame ranges); allowed: {} only for sweeps without "
                                   "windows",
                                   option, origin, option));
  };
  if (o.warmup >= 0) {
    if (s.kind == "broadphase") {
      s.warmup = o.warmup;
    } else {
      refuse_windows("--warmup");
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
    } else {
      refuse_windows("--frames");
      s.frames = s.warmup + o.frames;
      s.windows.front().last = s.frames;
    }
  }
  const auto [shard, shards] = parse_shard(o.shard);
  check_scenes();
  const std::vector<Point> points = expand(s);

  const json settings = result_settings(s, shard, shards);
  if (s.kind == "max-instances")  // the template must be grown into a scene (bad input now, not after an hour)
    for (std::size_t sc = 0; sc < s.scenes.size(); ++sc) (void)instance_scene(s, sc, 1);
  json result = new_result(s, origin, def, settings, points.size());
  std::map<std::string, json> kept = resumed_points(o, s, origin, def, points, result);
  std::error_code ec;
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
  // Points of this shard the result already holds (--resume): the progress counts on from them.
  std::size_t kept_mine = 0;
  for (const Point* p : mine) kept_mine += kept.count(p->id);
  SweepProgress progress(s.kind == "max-instances" ? my_searches.size() : mine.size(), !o.quiet);
  ModelCache models;
  InputCache inputs;
  bool any_failed = false;
  // SIGINT/SIGTERM: stop between frames, or inside a step within the session's bound;
  // either way the result keeps the finished points.
  octocd::RunSession session("bench", {kBenchStopBound});
  auto write = [&] {
    result["updated"] = utc_time_now();
    write_file_atomically(o.output, result.dump(1) + "\n", "-o");
    session.keep(fmt::format("the result {} keeps the {} point(s) finished before (--resume goes on)", o.output,
                             result["points"].size()));
  };
  record_hygiene(result, s, o.quiet);
  if (!o.quiet && s.kind == "max-instances")
    fmt::print(stderr,
               "bench {}: {} searches ({} in this shard {}/{}), engines {}, target {:g} steps/s over frames {}-{}, "
               "counts 1 to {}, probes {} repetition(s), the bracket's ends {}; result {}\n",
               octocd::printable(s.name), s.scenes.size() * s.engines.size(), my_searches.size(), shard, shards, json(s.engines).dump(),
               s.target, s.windows[0].first, s.windows[0].last, s.max_instances, s.probe_repeat, s.repeat, o.output);
  else if (!o.quiet)
    fmt::print(stderr, "bench {}: {} points ({} in this shard {}/{}{}), engines {}, {} repetitions{}; result {}\n", octocd::printable(s.name),
               points.size(), mine.size(), shard, shards,
               kept_mine > 0 ? fmt::format(", {} of them kept from the result by --resume", kept_mine) : std::string(),
               o.engines.empty() ? json(s.engines).dump() : o.engines, s.repeat, budget_text(s), printable(o.output));
  for (const Point* p : mine) {
    const auto it = kept.find(p->id);
    if (it != kept.end()) result["points"].push_back(it->second);  // resumed: kept as they were
  }
  if (s.kind == "max-instances")
    for (const auto& [id, pt] : kept) result["points"].push_back(pt);
  session.keep(result["points"].empty()
                   ? fmt::format("no point finished yet: the result {} is not written", o.output)
                   : fmt::format("the result {} keeps the {} point(s) finished before (--resume goes on)", o.output,
                                 result["points"].size()));
  const auto stopped = [&](int sig) {
    result["stopped"] = octocd::stop_signal_name(sig);
    std::sort(result["points"].begin(), result["points"].end(),
              [](const json& a, const json& b) { return a.value("index", 0) < b.value("index", 0); });
    write();
    std::fputc('\n', stderr);
    if (s.kind == "max-instances")
      return session.stopped(sig, fmt::format(" after {} probes ({} of {} searches done)", result["points"].size(),
                                              result.contains("searches") ? result["searches"].size() : std::size_t{0},
                                              my_searches.size()));
    return session.stopped(sig, fmt::format(" after {} of {} points", result["points"].size(), mine.size()));
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
        fmt::print(stderr, "bench {}: {} on {}: {}\n", octocd::printable(s.name), octocd::printable(sum.value("model", "?")), engine, octocd::printable(line));
      }
    }
    std::sort(result["points"].begin(), result["points"].end(),
              [](const json& a, const json& b) { return a.value("index", 0) < b.value("index", 0); });
    record_complete(result, write);
    if (!my_searches.empty() && std::all_of(result["searches"].begin(), result["searches"].end(), [](const json& x) {
          return x.value("status", "") == "skipped";
        })) {
      const json& first = result["searches"].front();
      throw InputError(fmt::format("{}: every search skipped ({}; first: {} on {}: {}); allowed: a sweep with an "
                                   "engine this octocd can run (result kept in {})",
                                   origin, result["searches"].size(), first.value("scene", "?"),
                                   first.value("engine", "?"), first.value("reason", "?"), o.output));
    }
    if (!o.quiet) fmt::print(stderr, "bench {}: done, result {}\n", octocd::printable(s.name), o.output);
    add_to_history(o, result);
    run.bad_values.refuse(o.output);
    const bool failed = run.any_failed || std::any_of(result["searches"].begin(), result["searches"].end(),
                                                      [](const json& x) { return x.value("status", "") == "failed"; });
    return failed ? 1 : 0;
  }
  // A finished point (all its repetitions, or skipped/failed): stamped, stored, file rewritten.
  std::size_t finished = kept_mine;
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
    check_point_timings(r, p);
    if (r.value("status", "") == "failed") any_failed = true;
    std::string status = r.value("status", "?");
    if (status == "ok" && r.contains("windows")) {
      const json& w = r["windows"].begin().value();
      status += fmt::format(" ({:.1f} steps/s median", w["steps_per_s"].value("median", 0.0));
      if (r.contains("budget")) {  // the count reached, the frames measured, the time taken
        const json& b = r["budget"];
        status += fmt::format(", {} of {} repetitions", b.value("repetitions", 0), b.value("repetitions_asked", 0));
        if (b.contains("frames") && b.value("frames", 0) != b.value("frames_asked", 0))
          status += fmt::format(", {} of {} timed frames", b.value("frames", 0), b.value("frames_asked", 0));
        status += fmt::format(", {:.1f} s", b.value("time_s", 0.0));
        if (b.value("ended_by", "") == "max_time") status += ", max_time_s reached";
      }
      status += ")";
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
  // Points failed on a value an engine gave (EngineValueError): stored as failed, and the
  // bench ends with exit 2 naming the first.
  BadEngineValues bad_values;
  const auto run_point = [&](const Point& p, const StepsOverride& ov) {
    json r;
    try {
      r = s.kind == "steps" ? run_steps_point(s, p, models, o, progress, ov)
                            : run_broadphase_point(s, p, inputs, o, progress);
    } catch (const EngineValueError& e) {
      r["status"] = "failed";
      r["reason"] = bad_values.add(p.id, e);
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
    // Round-robin within groups of kRoundRobinGroup consecutive points: repetition r of each
    // of the group's points, then repetition r + 1, so a load burst hits their repetitions
    // alike (design.md section 14b); each point is stored as soon as it is finished, so a stop
    // drops at most the group's unfinished points. The budget (docs/bench-format.md "Time
    // budget"): a point's first repetition gets its share of max_time_s and is cut to fewer
    // timed frames (or the point skipped) when slower; later ones run its timed frames; no
    // repetition starts that would end past max_time_s, and one still running there is dropped.
    struct Run {
      std::vector<json> reps;
      std::vector<double> started;  // each repetition's start, s after t0
      double spent_s = 0.0;         // set-ups and frames of every repetition (the budget's time)
      int timed_frames = 0;         // > 0: the first repetition was cut to this many timed frames
      json cut;                     // that cut (budget_cut)
      bool over = false;
    };
    // The first repetition's share of max_time_s: 80 % of max_time_s / repeat, the rest a
    // margin for the later ones (the first also builds the model; a later one may meet load).
    constexpr double kFirstShare = 0.8;
    const double max_t = s.max_time_s > 0 ? s.max_time_s : 0.0, min_t = std::max(s.min_time_s, 0.0);
    const auto t0 = Clock::now();
    // The point's result from its repetitions, with what the budget did.
    const auto merged = [&](Run& st, const std::string& ended_by) {
      json m = merge_repetitions(st.reps);
      m.erase("budget_cut");
      m["repetition_start_s"] = st.started;
      const int asked_frames = s.windows.front().last - s.windows.front().first + 1;
      json b{{"protocol", s.protocol},
             {"min_time_s", min_t},
             {"max_time_s", max_t},
             {"time_s", st.spent_s},
             {"repetitions_asked", s.repeat},
             {"repetitions", static_cast<int>(st.reps.size())},
             {"ended_by", ended_by}};
      if (s.cuttable) {
        b["frames_asked"] = asked_frames;
        b["frames"] = st.timed_frames > 0 ? st.timed_frames : asked_frames;
      }
      if (!st.cut.is_null()) b["cut"] = st.cut;
      m["budget"] = b;
      return m;
    };
    std::vector<Run> runs(todo.size());
    for (std::size_t g0 = 0; g0 < todo.size(); g0 += kRoundRobinGroup) {
      const std::size_t g1 = std::min(todo.size(), g0 + kRoundRobinGroup);
      for (bool any = true; any;) {
        any = false;
        for (std::size_t k = g0; k < g1; ++k) {
          Run& st = runs[k];
          if (st.over) continue;
          const Point& p = *todo[k];
          if (const int sig = octocd::stop_signal()) return stopped(sig);
          const int n = static_cast<int>(st.reps.size());
          progress.start(finished, fmt::format("{} (repetition {}/{})", p.id, n + 1, s.repeat));
          StepsOverride ov;
          ov.repeat = 1;
          ov.trace = n == 0;
          if (max_t > 0) {
            if (n == 0) {
              ov.time_limit_s = kFirstShare * max_t / s.repeat;
            } else {
              ov.timed_frames = st.timed_frames;
              ov.time_limit_s = max_t - st.spent_s;
              ov.abandon_over_time = true;
            }
          }
          st.started.push_back(std::chrono::duration<double>(Clock::now() - t0).count());
          const auto t_rep = Clock::now();
          json r;
          try {
            r = run_point(p, ov);
          } catch (const BenchStopped&) {
            return stopped(octocd::stop_signal());
          }
          st.spent_s += std::chrono::duration<double>(Clock::now() - t_rep).count();
          const std::string status = r.value("status", "");
          if (status == "over_time") {  // a later repetition still running at max_time_s: dropped
            st.started.pop_back();
            st.over = true;
            finish_point(p, merged(st, "max_time"));
            continue;
          }
          if (status != "ok") {  // skipped (maybe by the budget) or failed: stored as it is
            st.over = true;
            if (max_t > 0 && r.contains("estimate_s"))
              r["budget"] = {{"protocol", s.protocol}, {"min_time_s", min_t}, {"max_time_s", max_t},
                             {"time_s", st.spent_s}, {"repetitions_asked", s.repeat}, {"repetitions", 0},
                             {"ended_by", "max_time"}};
            finish_point(p, r);
            continue;
          }
          if (n == 0 && r.contains("budget_cut")) {
            st.cut = r["budget_cut"];
            st.timed_frames = st.cut.value("frames", 0);
          }
          st.reps.push_back(std::move(r));
          // Another repetition: until those asked (while the next one is expected to end within
          // max_time_s), then while the point's time is below min_time_s.
          const double mean = st.spent_s / static_cast<double>(st.reps.size());
          const bool fits = max_t <= 0 || st.spent_s + mean <= max_t;
          const int have = static_cast<int>(st.reps.size());
          std::string ended_by;
          if (have >= kMaxRepetitions) ended_by = "repetitions";
          else if (have >= s.repeat && (st.spent_s >= min_t || !fits)) ended_by = have > s.repeat ? "min_time" : "repetitions";
          else if (!fits) ended_by = "max_time";  // fewer repetitions than asked
          if (ended_by.empty()) {
            any = true;
            continue;
          }
          st.over = true;
          finish_point(p, merged(st, ended_by));
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
  record_complete(result, write);
  // A sweep none of whose points could run measured nothing: bad input, not success.
  if (!mine.empty() && std::all_of(result["points"].begin(), result["points"].end(),
                                   [](const json& pt) { return pt.value("status", "") == "skipped"; })) {
    const json& first = result["points"].front();
    throw InputError(fmt::format("{}: every point skipped ({} of {}; first: {}: {}); allowed: a sweep with a point "
                                 "this octocd can run (result kept in {})",
                                 origin, result["points"].size(), mine.size(), first.value("id", "?"),
                                 first.value("reason", "?"), o.output));
  }
  if (!o.quiet) fmt::print(stderr, "bench {}: done, result {}\n", octocd::printable(s.name), o.output);
  add_to_history(o, result);
  bad_values.refuse(o.output);
  return any_failed ? 1 : 0;
}

}  // namespace octocd::cli
