#pragma once
/// \file bench_sweep.hpp
/// What the files of `octocd bench` share (not a public header):
///   cli/bench.cpp               the command: options, overrides, the loop over points
///   cli/bench_sweep.cpp         a sweep's definition: the named sweeps (bench/sweeps/*.json),
///                               parsing and checking, its points, the scene text of a point
///   cli/bench_points.cpp        running a steps point or a broadphase point
///   cli/bench_max_instances.cpp the max-instances search (doubling, bisection, confirmation)
///   cli/bench_result.cpp        the result file: its header, resuming, timing hygiene, a
///                               stopped or finished sweep
/// Sweep and result formats: docs/bench-format.md.

#include <unistd.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <exception>
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "octocd/engine.hpp"
#include "octocd/run_session.hpp"
#include "octocd/text.hpp"
#include "octocd/world.hpp"
#include "tools.hpp"

namespace octocd::cli::bench {

using json = nlohmann::json;
using Clock = std::chrono::steady_clock;
constexpr int kStages = static_cast<int>(Stage::Count);

// ---- sweep definition (bench_sweep.cpp) -----------------------------------------------------

/// One axis of a steps sweep: a scene key and the values it takes.
struct Axis {
  std::string name;
  std::string key;                  ///< JSON pointer into the scene
  std::vector<json> values;
  std::vector<std::string> labels;  ///< same size as values ("" when none)
};

/// A range of frames whose figures are reported together (1-based, inclusive).
struct Window {
  std::string name;
  int first = 1, last = 1;
};

/// A parsed, checked sweep (docs/bench-format.md), with the command line's overrides
/// applied by bench_command.
struct Sweep {
  std::string name, kind, description, origin;
  json definition;
  std::vector<std::string> scenes;  ///< resolved files
  std::vector<std::string> engines;
  std::vector<Axis> axes;
  /// steps: how each point's run is traced (every point runs once per mode): "off" (no
  /// trace, the engine may run ahead), "states" (a trace with the state every 10 frames,
  /// as `octocd run --trace`), "contacts" (and every contact row, `--contacts`); a traced
  /// point's steps/s counts the whole frame: the step, the copy-back and the trace write.
  std::vector<std::string> traced{"off"};
  json set = json::object();
  int frames = 300, warmup = 30, repeat = 3, series_every = 0, warm_replays = 1;
  double min_time_ms = 50.0;
  std::vector<Window> windows;
  std::vector<long> bodies;
  std::vector<std::string> broadphases;
  std::map<std::string, long> max_bodies;
  // max-instances
  double target = 30.0;             ///< steps/s a count must reach
  long max_instances = 1048576;     ///< the search's cap
  double resolution = 0.0;          ///< bisection stops at hi - lo <= max(1, resolution * lo)
  int probe_repeat = 1;             ///< repetitions of a probe (the bracket's ends get `repeat`)
  int search_time_s = 0;            ///< > 0: no new count is measured once a search has run this long
  json paper = json::object();      ///< scene stem -> {"count", "source"}
  // speed-accuracy (docs/bench-format.md)
  std::vector<double> dts;              ///< the ladder of time steps (s), each dividing the largest
  double sim_seconds = 1.0;             ///< simulated time of every point (a multiple of the largest dt)
  std::vector<int> iterations;          ///< Bullet's solver iterations (one line each)
  std::vector<std::string> geometries;  ///< Bullet's shape settings: "box", "hull"
  std::vector<bool> rotations;          ///< false, true: without and with rotation (where the engine rotates)
  double diverge_beyond_m = 1e6;        ///< a body this far outside the domain (m) makes its run diverged
  // steps: batched worlds (octocd/worlds.hpp; docs/bench-format.md)
  std::vector<long> worlds{1};          ///< copies of each scene run as one world (`worlds`)
  bool worlds_given = false;            ///< the sweep has `worlds`: points report world_steps_per_s
  std::map<std::string, long> max_worlds;  ///< engine -> the most copies it runs (larger points are not made)
  /// steps: engine -> why its points above max_bodies[engine] bodies are skipped (the
  /// sweep's `max_bodies` {"ENGINE": {"bodies": N, "reason": "..."}}; max_bodies holds N).
  std::map<std::string, std::string> max_bodies_reason;
  // steps and speed-accuracy: the time budget of a point (docs/bench-format.md, "Time budget")
  /// The sweep file's `min_time_s` and `max_time_s` (-1: not given); bench_command resolves
  /// them with the protocol and the command's options before anything runs.
  double min_time_s = -1.0, max_time_s = -1.0;
  /// "budget" (the default: a point runs until it has `repeat` repetitions and min_time_s, and
  /// no longer than max_time_s) or "paper" (no budget: every point runs its full protocol).
  std::string protocol = "budget";
  /// steps: the sweep has no `windows` and no `series_every`: one window after the warm-up, so a
  /// budgeted repetition may be cut to fewer timed frames (with windows a point runs whole or is skipped).
  bool cuttable = false;
  // divergence (docs/bench-format.md, docs/predictability.md)
  std::vector<double> eps;              ///< the ladder of initial perturbations (m), each in [0, 1] (0: unperturbed copies)
  int copies = 16;                      ///< perturbed copies per eps
  std::uint64_t seed = 1;               ///< seeds every copy's perturbation
  bool rotation = false;                ///< rotation: true for every scene (engines that rotate only)
};

/// The largest instance count a max-instances sweep may search to: limits::kMaxGeneratedBodies
/// (2^27), the most bodies of the scenes it generates (a scene file stops at
/// limits::kMaxBodies); device or host memory ends a search below it.
constexpr long kMaxInstancesCap = static_cast<long>(limits::kMaxGeneratedBodies);

/// The most bodies of a broadphase sweep's lattice (`bodies`) and the largest `max_bodies`
/// cap: 2^24 (a larger cap would skip nothing).
constexpr long kMaxSweepBodies = 16777216;

/// The most points a sweep may expand to (docs/bench-format.md): a larger one is refused
/// before anything runs.
constexpr std::size_t kMaxPoints = 100000;

/// Throws InputError "<origin>: <key>: <problem>; allowed: <allowed>".
[[noreturn]] void bad(const std::string& origin, const std::string& key, const std::string& problem,
                      const std::string& allowed);

/// The folder of the named sweeps: bench/sweeps/ of octocd's shipped files (shared_dir()).
std::string named_sweeps_dir();

/// The named sweeps: the stems of the *.json files of named_sweeps_dir(), sorted; empty
/// when the folder is missing.
std::vector<std::string> named_sweeps();

/// named_sweeps() joined by ", ", for help texts and messages.
std::string named_list();

/// The JSON of a sweep file, named or given on the command line. Throws InputError
/// "<path>: not JSON (...); allowed: a sweep file (docs/bench-format.md)".
json read_sweep_file(const std::string& path);

/// Checks sweep definition `j` and resolves its scenes: a bare name is
/// `scene_dir`/NAME.json, a relative path is relative to `sweep_dir` (the sweep file's
/// folder; "" for named sweeps). Throws InputError naming `origin`, the key and the
/// allowed values.
Sweep parse_sweep(const json& j, const std::string& origin, const std::string& scene_dir,
                  const std::string& sweep_dir);

// ---- points (bench_sweep.cpp) --------------------------------------------------------------

/// One measurement of a sweep: a scene (or body count) x axis values (or broadphase) x engine.
struct Point {
  int index = 0;
  std::string id;
  std::string engine;
  std::size_t scene = 0;           ///< steps: index into Sweep::scenes
  std::vector<std::size_t> value;  ///< steps: value index per axis
  long bodies = 0;                 ///< broadphase: body count (bodies) or -1 (scenes)
  std::string traced = "off";      ///< steps: the trace mode (Sweep::traced)
  std::string broadphase;          ///< broadphase kind
  long worlds = 1;                 ///< steps: copies of the scene run as one world (Sweep::worlds)
};

/// The trace modes of a steps sweep (Sweep::traced), in order.
const std::vector<std::string>& trace_modes();
/// `modes` when each is a trace mode, listed once, and there is at least one; else
/// InputError "<what>: ...; allowed: ...".
std::vector<std::string> checked_trace_modes(const std::vector<std::string>& modes, const std::string& what);

/// The file name of `path` without its folder and extension.
std::string stem(const std::string& path);

/// A JSON value as text: a string as it is, anything else as JSON.
std::string value_text(const json& v);

/// The points of a steps or broadphase sweep in index order (scene-major, last axis
/// fastest, engine innermost); none for max-instances (its probes are found while it runs).
/// Throws InputError for more than kMaxPoints points or a scene listed twice.
std::vector<Point> expand(const Sweep& s);

/// The scene text of a steps point: the scene file with the sweep's `set` and the point's
/// axis values written at their JSON pointers. `added` (optional) receives the keys that
/// the scene file did not have.
std::string scene_text(const Sweep& s, const Point& p, std::vector<std::string>* added = nullptr);

/// The max-instances scene of `n` instances built from scene `sc` of the sweep (its
/// template, with the sweep's `set`): one group with a grid layout; its count becomes `n`
/// and its grid a cube of k = ceil(cbrt(n)) slots a side at the template's spacing, around
/// the template grid's centre, the domain keeping the template's margin around the grid
/// on every side. For the template's own count this gives the template's grid and domain
/// when the template is such a cube (the paper's random scenes are: 400 -> 8^3, 250 -> 7^3,
/// 60 -> 4^3 slots). `layout_out` (optional) receives the grown domain and layout. Throws
/// InputError naming the scene file and key when the template is not of that form.
std::string instance_scene(const Sweep& s, std::size_t sc, long n, json* layout_out = nullptr);

/// A box lattice of `n` bodies at the density of boxes-random-10000 (0.1 m boxes,
/// spacing 0.145 m, 2 cm jitter, random velocities up to 1 m/s, closed box, no gravity).
std::string lattice_scene(long n);

// ---- running points (bench_points.cpp) -------------------------------------------------------

/// Progress on stderr: a redrawn bar on a terminal, one line per finished point always
/// (unless disabled by --quiet).
class SweepProgress {
 public:
  SweepProgress(std::size_t total, bool enabled) : total_(total), enabled_(enabled), tty_(isatty(fileno(stderr)) != 0) {}
  void start(std::size_t done, const std::string& label) {
    done_ = done;
    label_ = octocd::printable(label);
    detail_.clear();
    draw(true);
  }
  void detail(const std::string& d) {
    detail_ = octocd::printable(d);
    draw(false);
  }
  /// A line of the point in progress ("[k/N] label: text"), on any stderr (the bar, on a
  /// terminal, drawn again below it): what a process engine's run says as it runs.
  void note(const std::string& text) {
    if (!line(text)) return;
    draw(true);
  }
  void finish(const std::string& status) { line(status); }

 private:
  /// "[k/N] label: text" on its own line (the bar, on a terminal, cleared first); false when
  /// disabled.
  bool line(const std::string& text) {
    if (!enabled_) return false;
    if (tty_) std::fprintf(stderr, "\r\033[K");
    std::fprintf(stderr, "[%zu/%zu] %s: %s\n", done_ + 1, total_, label_.c_str(), octocd::printable(text).c_str());
    std::fflush(stderr);
    return true;
  }
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

/// The default time budget of a point under protocol "budget" (s): at most kDefaultMaxTimeS
/// (set-ups and frames of all its repetitions), and more repetitions than asked while its
/// time is below kDefaultMinTimeS (none by default). With these, `bench table5` on every
/// engine of a CPU build (24 measured points) is bounded by about 24 x 20 s plus set-ups
/// (docs/bench-format.md "Time budget" has the measured time).
constexpr double kDefaultMaxTimeS = 20.0;
constexpr double kDefaultMinTimeS = 0.0;
/// The most repetitions of a point (a spread holds at most 1000 values).
constexpr int kMaxRepetitions = 1000;
/// Repetitions run round-robin within groups of this many consecutive points (design.md
/// section 14b): a load burst hits the group's points alike, and a point is stored once its
/// group's rounds have finished it, never waiting for the whole sweep.
constexpr std::size_t kRoundRobinGroup = 4;

/// The timed frames a budgeted repetition is cut to: the largest of `asked`, asked/2,
/// asked/4, ... (rounded up) that is <= `measured` (>= 1), so runs of one build on one
/// machine mostly cut to the same count (the gate compares like with like).
int cut_frames(int asked, int measured);

/// Thrown between two frames (or replays) once SIGINT or SIGTERM arrived: the point is
/// abandoned, the finished ones are kept (octocd/stop.hpp).
struct BenchStopped {};

/// The models of the last kRoundRobinGroup scene texts built, reused while a text recurs
/// (the points of a round-robin group).
struct ModelCache {
  std::vector<std::pair<std::string, std::shared_ptr<const Model>>> entries;  ///< most recent last
  /// The model of scene text `t` (parse_scene with `origin`, `data_dir` and `max_bodies`);
  /// InputError as parse_scene.
  std::shared_ptr<const Model> get(const std::string& t, const std::string& origin, const std::string& data_dir,
                                   std::size_t max_bodies = limits::kMaxBodies);
};

/// The recorded broadphase input of the last scene (or body count) replayed.
struct InputCache {
  std::size_t key = static_cast<std::size_t>(-1);
  std::unique_ptr<ReplayInput> input;
  std::string error;
};

/// What a max-instances probe changes in run_steps_point.
struct StepsOverride {
  const std::string* text = nullptr;  ///< the scene text instead of scene_text(s, p)
  int repeat = 0;                     ///< > 0: repetitions instead of s.repeat
  /// > 0: a repetition is cut once its first window's step time exceeds frames / cut_below
  /// seconds (its steps/s can then only end below cut_below: the stored value is that upper
  /// bound), and no more repetitions run once most of them were cut (the median is below).
  double cut_below = 0.0;
  bool trace = true;  ///< false: no trace even with --trace-dir (a later round-robin repetition)
  /// > 0: the time this one repetition may take (s, from the call, set-up included). Past it,
  /// between two frames: with `abandon_over_time` the repetition is dropped (status
  /// "over_time"); else, once a timed frame ran and the sweep is cuttable, the window is cut
  /// to cut_frames(asked, measured) frames (`budget_cut` says so); else the point is skipped
  /// with the time its repetitions would take, estimated from the frames stepped (`estimate_s`).
  double time_limit_s = 0.0;
  bool abandon_over_time = false;
  /// > 0: timed frames of the (only) window instead of the sweep's: a budgeted point's later
  /// repetitions run the count its first was cut to.
  int timed_frames = 0;
  /// The most bodies `text` may hold (parse_scene's max_bodies): limits::kMaxGeneratedBodies
  /// for the scenes max-instances generates.
  std::size_t max_bodies = limits::kMaxBodies;
};

/// Runs steps point `p` (its repetitions, windows, series; a trace with --trace-dir) and
/// returns its result object (docs/bench-format.md), status ok or skipped with the reason.
/// Throws BenchStopped on a signal, InputError when the sweep's pointer is wrong.
json run_steps_point(const Sweep& s, const Point& p, ModelCache& cache, const BenchOptions& o,
                     SweepProgress& progress, const StepsOverride& ov = {});

/// The results of one-repetition runs of one steps point (round-robin, in the order run)
/// as one result: every spread (an object with "values") over all the repetitions, the
/// series' per-block figures the median over the repetitions (kinetic energy, the trace and
/// every other field as the first repetition has them).
json merge_repetitions(const std::vector<json>& reps);

/// Runs broadphase point `p`: records the input frames once per scene (or body count),
/// replays them through the point's broadphase and engine; status ok, skipped (above
/// max_bodies, the engine lacks it) or failed (pairs differ from the recording run's).
json run_broadphase_point(const Sweep& s, const Point& p, InputCache& cache, const BenchOptions& o,
                          SweepProgress& progress);

/// The points of a sweep that failed on a value an engine gave (EngineValueError,
/// octocd/process_engines.hpp: bad input from the engine, e.g. a process engine's
/// wall_step_seconds of 0). Every kind of sweep stores such a point as failed with the error
/// as its reason and runs the others; once the result is written, refuse() ends the bench
/// with exit 2 (docs/bench-format.md).
struct BadEngineValues {
  std::vector<std::string> points;  ///< "point ID: the error", in the order met
  /// Records point `id`'s error `e`; returns its text (the point's reason).
  std::string add(const std::string& id, const std::exception& e);
  /// Throws the InputError "N point(s) failed on a value an engine gave, stored as failed in
  /// the result OUTPUT with the other points; the first: ..." when a point was added; else
  /// returns.
  void refuse(const std::string& output) const;
};

// ---- max-instances (bench_max_instances.cpp) --------------------------------------------------

/// Everything a max-instances search shares with bench_command.
struct MaxInstancesRun {
  const Sweep& s;
  const BenchOptions& o;
  json& result;
  std::map<std::string, json>& kept;  ///< resumed points by id
  std::set<std::string> visited;      ///< kept points met again
  ModelCache models;
  SweepProgress& progress;
  std::function<void()> write;
  int next_index = 0;
  bool any_failed = false;
  BadEngineValues bad_values{};  ///< probes failed on a value an engine gave
};

/// One (model, engine) search: doubling + bisection on probes of probe_repeat repetitions,
/// then the bracket's ends measured again with `repeat` repetitions (their median
/// decides); while that changes the bracket, the search goes on from the new decisions.
/// Every probe is appended to run.result["points"] and the file rewritten. Returns the
/// summary stored in result["searches"]; throws BenchStopped on a signal.
json search_max_instances(MaxInstancesRun& run, std::size_t sc, const std::string& engine, std::size_t search);

// ---- speed-accuracy (bench_speed_accuracy.cpp) ---------------------------------------------

/// Runs a sweep of kind speed-accuracy (docs/bench-format.md): every line (scene, engine,
/// geometry, rotation, iterations) over the ladder of time steps, the same simulated time
/// each, repetitions round-robin; consistency error against the line's smallest dt.
/// `engines_given`: --engines named the engines (an engine that cannot start, or cannot run
/// a scene at all, is then bad input). Writes o.output (and the CSV); returns the exit
/// code (0, or 1 when a point failed). Throws InputError (exit 2) for bad input.
int run_speed_accuracy(const Sweep& s, const std::string& origin, const json& def, const BenchOptions& o,
                       int shard, int shards, bool engines_given);

// ---- divergence (bench_divergence.cpp) -------------------------------------------------------

/// Runs a sweep of kind divergence (docs/bench-format.md, docs/predictability.md): per
/// scene and engine the unperturbed run and, per eps of the ladder, `copies` runs whose
/// dynamic bodies start eps metres away in seeded random directions; per frame the mean
/// and max distance of the bodies from the unperturbed run, and the growth exponent fitted
/// over the run. Writes o.output and the CSV (o.csv, default RESULT.csv beside it); returns
/// the exit code (0, or 1 when a point failed). Throws InputError (exit 2) for bad input.
int run_divergence(const Sweep& s, const std::string& origin, const json& def, const BenchOptions& o);

// ---- the result file (bench_result.cpp) -----------------------------------------------------

/// The result's "settings": engines, repeat, frames, warmup, shard, and the kind's own
/// (warm_replays and min_time_ms; the max-instances search's target, cap and window).
json result_settings(const Sweep& s, int shard, int shards);

/// A new result document (format octocd-bench version 1) of sweep `s` with definition
/// `def`: machine, build, start time, no points yet.
json new_result(const Sweep& s, const std::string& origin, const json& def, const json& settings,
                std::size_t points_total);

/// When `o.output` exists: with --resume, checks it is a result of the same definition,
/// settings and machine and returns its finished (ok or skipped) points by id, keeping its
/// start time in `result`; without --resume, InputError. Returns {} when there is no file.
/// Throws InputError naming the file and key for anything else.
std::map<std::string, json> resumed_points(const BenchOptions& o, const Sweep& s, const std::string& origin,
                                           const json& def, const std::vector<Point>& points, json& result);

/// resumed_points' checks of `old`, the parsed result file at `path`: its format, sweep
/// definition, settings and machine equal those of this run (`def`, result["settings"],
/// result["machine"]), and each of its points by presence, type and range (id, index,
/// status, verdict, params, windows and their steps/s spreads; docs/bench-format.md).
/// Returns the finished (ok or skipped) points by id and keeps the start time in
/// `result`. Throws InputError naming `path` and the field for anything else.
std::map<std::string, json> resumable_points(const json& old, const std::string& path, const Sweep& s,
                                             const std::string& origin, const json& def,
                                             const std::vector<Point>& points, json& result);

/// Whether `old` (the parsed result file at `path`) is a finished result (complete: true)
/// of sweep definition `def` with `settings`: what `bench --resume` of a speed-accuracy
/// sweep keeps as it is. Throws InputError naming `path` and the field when it is not a
/// result (not an object, another format, `complete` not a boolean, `sweep` not an object).
bool finished_result_matches(const json& old, const std::string& path, const json& def, const json& settings);

/// Records result["hygiene"] (threads, the CPU engine's threads, load average, warnings) and prints
/// its warnings: a loaded machine or oversubscribed threads make timings noisy.
void record_hygiene(json& result, const Sweep& s, bool quiet);

/// A sweep stopped by signal `sig` between two points (octocd/run_session.hpp): records
/// result["stopped"] (the signal's name), rewrites the result file with `write` (which
/// tells `session` what it keeps), and ends with session.stopped(): the stop line (with
/// `finished`, when given: how many points, e.g. "203 of 360 points"), the stop's exit code.
int record_stopped(json& result, int sig, const std::function<void()>& write, RunSession& session,
                   const std::string& finished = "");

/// A sweep's end: marks the result complete (result["complete"], the machine's
/// load_average_end) and rewrites the result file with `write`.
void record_complete(json& result, const std::function<void()>& write);

/// The end of a divergence or speed-accuracy sweep: when SIGINT or SIGTERM arrived,
/// record_stopped; else record_complete and nothing.
std::optional<int> finish_sweep(json& result, const std::function<void()>& write, RunSession& session);

}  // namespace octocd::cli::bench
