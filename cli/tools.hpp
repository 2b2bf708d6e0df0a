#pragma once
/// \file tools.hpp
/// The `octocd` subcommands of design.md section 12 beside `run` and `validate`: `bench` (sweeps,
/// cli/bench.cpp), `replay` (recorded AABBs through several broadphases, cli/replay.cpp),
/// `compare` (two traces, cli/compare.cpp) and `report` (HTML + Markdown with plots,
/// cli/report.cpp), plus what they share (cli/tools.cpp): the engine factory, statistics
/// over repetitions, the machine description and atomic file writes.
///
/// Exit codes as everywhere in octocd: 0 ok, 1 runtime failure, 2 bad input, 3 a check
/// failed (compare: the traces differ; replay: a broadphase disagrees), 4 the performance
/// gate failed (`report --baseline`: a point shown slower, or a baseline point missing,
/// failed or unmeasured in the new run).

#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include "octocd/atomic_file.hpp"
#include "octocd/engine.hpp"
#include "octocd/engines.hpp"
#include "octocd/trace.hpp"
#include "command_table.hpp"

namespace octocd::cli {

/// Adds a repeatable `--ENGINE KEY=VALUE` option to `command` for every engine of the
/// registry that has settings (engine_setting_names; help from engine_settings_help, or
/// with `brief` one line that sends the reader to `octocd engines` for the keys),
/// collecting each engine's items into `items[ENGINE]` (docs/settings.md). The items are
/// checked by check_engine_settings.
void add_engine_settings_options(CLI::App* command, EngineSettingItems& items, bool brief = false);

/// Median, minimum, maximum, mean and sample standard deviation of repeated measurements,
/// as stored in bench results: {"median", "min", "max", "mean", "stdev", "n", "values"}.
/// An empty `values` gives n = 0 and no other keys.
nlohmann::json spread(const std::vector<double>& values);

/// Where and on what this runs: {"hostname", "cpu", "threads", "omp_threads",
/// "load_average", "gpu", "driver"} (gpu is the CUDA engine's device line, e.g. "no CUDA
/// device: ..."; driver from /proc/driver/nvidia/version, "" when absent).
nlohmann::json machine_description();

/// The 1, 5 and 15 minute load averages now (getloadavg), [] when unknown: how busy a
/// shared machine was while it measured.
nlohmann::json load_average();

/// The build: {"build_id", "git_revision"} (git_revision from `git rev-parse` in the source
/// tree when it is there, else the id compiled in).
nlohmann::json build_description();

/// Atomic result files (octocd/atomic_file.hpp), as the subcommands call them.
using octocd::write_file_atomically;
/// Output paths checked before any work (octocd/atomic_file.hpp).
using octocd::check_output_file;

/// An output folder (`report -o`, `--csv`, `view -o`, `validate --view`, `bench
/// --trace-dir`): a folder, or a path that can become one. Refuses a file, a FIFO, a device
/// (/dev/null) and a symbolic link (e.g. to /etc), naming the option and the type; with
/// `writable`, also a read-only folder (no write bit: refused even for root). InputError.
void check_output_folder(const std::string& path, const char* option, bool writable);

/// Splits "a,b,c" into {"a", "b", "c"} (empty items dropped).
std::vector<std::string> split_list(const std::string& text);

/// ISO 8601 UTC time now, e.g. 2025-01-01T12:00:00Z.
std::string utc_time_now();

/// TraceOptions::flush_interval_s of the run traces the commands write (`run --trace`, `bench
/// --traced`; `validate` flushes every checked frame): batches under kFlushIntervalBytes
/// (64 KiB) flush at most every 0.1 s, larger ones every flush_every frames, so a process
/// killed at any instant keeps every frame but those of about its last 0.1 s or 64 KiB.
/// Traced cuda runs, H100, bunny-stack-50 (50 bodies, state every 10th frame): a flush
/// every 50 frames held the caller 17 us a frame on average.
constexpr double kTraceFlushIntervalS = 0.1;

/// How a run's steps reach its trace (`run --trace`, `bench --traced`): a rotating engine
/// that records writes version 2 records; otherwise version 1 rows, the state given only on
/// the frames whose state the trace writes, and with no contact rows the engine may run
/// ahead to the next such frame (Engine::plan_steps; nothing else is read in between). A
/// recording feed (contact rows, or version 2) promises the run's steps at once: a
/// recording engine may run ahead of them too, with state(), contacts() and record()
/// still read (Engine::plan_steps; the cuda engine runs recorded steps ahead in batches, docs/gpu.md).
struct TraceFeed {
  bool v2 = false;           ///< append_frame_v2 with the engine's record
  bool states_only = false;  ///< no contact rows and not v2: the engine runs ahead between state frames

  /// The feed of `engine` into a trace that records contact rows or not.
  static TraceFeed of(const Engine& engine, bool contacts);
  /// Promises the steps to the first state frame (at most `steps`, the run's), or, for a
  /// recording feed, all `steps`; call after set_recording and before the first step.
  void start(const TraceWriter& trace, Engine& engine, std::int64_t steps) const;
  /// Appends the step `m` just taken and, at a state frame of a states-only feed, promises
  /// the steps to the next one (at most `remaining`, the run's steps left). Throws what
  /// TraceWriter throws.
  void append(TraceWriter& trace, Engine& engine, const FrameMetrics& m, std::int64_t remaining) const;
};

/// A new empty file in the temp folder ($TMPDIR), "octocd-WHAT-XXXXXX.h5" with an
/// unpredictable suffix, created with O_EXCL (mkstemps): nothing planted at its name is
/// followed; the caller removes it. RuntimeError naming it when it cannot be created.
std::string temporary_trace(const std::string& what);


// ---- replaying recorded broadphase input (cli/replay.cpp; `replay` and bench sweeps) ----

/// The broadphase input of recorded frames, the same bits for every engine: a model of box
/// shapes with the recorded local boxes (so no mesh is needed, and an engine's midphase is
/// the AABB test), gravity 0, and per replayed frame the positions its broadphase saw.
/// Setting those positions with zero velocity and taking one step leaves them unchanged
/// (Eq. 2-3 with g = 0, v = 0), so the engine's Aabbs stage rebuilds exactly the recorded
/// world AABBs (translated(local, x)) and its broadphase stage sees exactly them.
struct ReplayInput {
  std::shared_ptr<const Model> model;   ///< box shapes, recorded local boxes, gravity 0
  std::vector<std::int64_t> frames;     ///< the step each replayed frame reproduces
  std::vector<std::vector<Vec3>> x;     ///< per frame: positions the broadphase saw (m)
  std::vector<std::int64_t> recorded_pairs;  ///< per frame: the run's pair count, -1 unknown
  std::vector<std::vector<Pair>> recorded_sets;  ///< per frame: the run's pairs (may be empty)
  std::string source;                   ///< the trace or scene it came from
};

/// From a trace: the state recorded after frame f (/states position and velocity, every
/// `every`-th row), advanced by Eq. 2-3 exactly as the engine's next step did
/// (octocd::integrate with the trace's gravity and dt), is step f+1's broadphase input;
/// /frames/aabb_pairs of frame f+1 is its recorded count. At most `max_frames` (> 0)
/// frames. Throws InputError naming the file and dataset when the trace lacks /bodies,
/// /states (position, velocity, frame) or the parameters attribute, or holds no state row
/// with a following frame.
ReplayInput replay_input_from_trace(const std::string& path, int every, int max_frames);

/// From a scene: run it on the CPU engine for `warmup` steps, then record `frames` steps'
/// broadphase input and pair sets.
ReplayInput replay_input_from_scene(const Scene& scene, int warmup, int frames);

/// One broadphase of one engine replayed over a ReplayInput.
struct ReplayRun {
  std::string engine, broadphase;
  bool ok = false;
  std::string reason;            ///< why it was skipped (when !ok)
  std::vector<double> ms;        ///< per timed repetition: broadphase-stage ms per frame
  double pairs = 0.0;            ///< mean pairs per frame
  double candidates = 0.0;       ///< mean cell-level candidates per frame
  std::string device;            ///< the engine's device
  bool matches_recorded = true;  ///< every frame's pairs equal the recorded set (or count)
  std::string recorded_detail;   ///< first frame that differs, or what was compared
  std::vector<std::vector<Pair>> sets;  ///< the pairs of each frame (last repetition)
};

/// Replays `input` through `broadphase` on `engine` (make_engine on a copy of the model
/// naming that broadphase): `warm_replays` untimed passes over every frame, then `repeat`
/// timed ones (the engine's own broadphase-stage time); a timed repetition replays the
/// frames again until its broadphase time reaches `min_ms` (so tiny scenes are not timed
/// at the clock's resolution) and reports ms per frame over all its replays. An InputError or RuntimeError
/// while building the engine (a broadphase the engine lacks, no CUDA device) gives
/// ok = false with the reason; a failure while stepping is thrown.
ReplayRun replay_broadphase(const ReplayInput& input, const std::string& engine, const std::string& broadphase,
                            int repeat, int warm_replays, double min_ms = 0.0,
                            const std::function<void()>& tick = {});

/// The first frame (index into input.frames) where `a` and `b` differ, with the first pair
/// in one set and not the other; "" when equal.
std::string first_set_difference(const ReplayInput& input, const std::vector<std::vector<Pair>>& a,
                                 const std::vector<std::vector<Pair>>& b);

// ---- the commands (one file each) ------------------------------------------------------

/// `octocd bench` options (cli/bench.cpp).
struct BenchOptions {
  std::string sweep;              ///< a named sweep or a sweep JSON file
  std::string engines;            ///< comma-separated, overrides the sweep's
  std::string traced;             ///< comma-separated trace modes (off, states, contacts), overrides a steps sweep's
  int repeat = 0;                 ///< > 0 overrides the sweep's repetitions
  int frames = 0;                 ///< > 0 overrides the sweep's timed (or recorded) frames
  int warmup = -1;                ///< >= 0 overrides the sweep's untimed frames first
  double target = 0.0;            ///< > 0 overrides a max-instances sweep's target steps/s
  long max_instances = 0;         ///< > 0 overrides a max-instances sweep's cap
  double resolution = -1.0;       ///< >= 0 overrides a max-instances sweep's bisection resolution
  int search_time_s = -1;         ///< >= 0 overrides a max-instances sweep's time limit per search (0: none)
  std::string protocol;           ///< "budget" (default: a time budget per point) or "paper" (the sweep's full protocol)
  double min_time_s = -1.0;       ///< >= 0 overrides the time a point runs repetitions for at least (budget protocol)
  double max_time_s = -1.0;       ///< >= 0 overrides the most time a point may take (budget protocol; 0: no limit)
  std::string shard;              ///< "i/N"
  std::string output;             ///< RESULT.json
  bool resume = false;
  bool list = false;
  bool print = false;
  long print_scene = 0;           ///< > 0: print a max-instances sweep's scenes at this count and exit
  bool quiet = false;
  std::string scene_dir;          ///< where named sweeps find their scenes
  std::string data_dir;           ///< meshes (as load_scene's data_dir)
  std::string trace_dir;          ///< write one trace per steps point here
  EngineSettingItems settings;  ///< --ENGINE KEY=VALUE items by engine (add_engine_settings_options)
  std::string csv;                ///< speed-accuracy: the CSV file (default RESULT.csv beside -o)
  std::string history;            ///< --history DIR: add the finished result to this history folder (cli/history.cpp)
};
CLI::App* add_bench_command(CLI::App& app, BenchOptions& o);
int bench_command(const BenchOptions& o);

/// `octocd replay` options (cli/replay.cpp).
struct ReplayOptions {
  std::string trace;
  std::string broadphases;        ///< comma-separated
  std::string engine = "cpu";
  int repeat = 3;
  int warm_replays = 1;
  int every = 1;                  ///< replay every K-th state row
  double min_ms = 0.0;            ///< replay each timed repetition until this much time
  int max_frames = 0;             ///< > 0: at most this many frames
  std::string json;               ///< write the result table as JSON
};
CLI::App* add_replay_command(CLI::App& app, ReplayOptions& o);
int replay_command(const ReplayOptions& o);

/// One quantity's tolerance in `octocd compare`: A and B differ when |A - B| > abs + rel *
/// max(|A|, |B|) (numpy.isclose's rule); both 0 = bit for bit.
struct Tolerance {
  double abs = 0.0;  ///< absolute, in the quantity's unit (m, m/s, counts, J), >= 0
  double rel = 0.0;  ///< relative, >= 0
  /// Whether this is bit for bit (abs = rel = 0).
  bool exact() const { return abs == 0.0 && rel == 0.0; }
  /// "1e-06", "rel:0.0001", "1e-06+rel:0.0001" or "0 (bit for bit)".
  std::string text() const;
};

/// Parses `--tolerance` arguments (each comma-separated items VALUE or QUANTITY=VALUE, VALUE
/// ABS, rel:R or ABS+rel:R; later items override earlier ones) into one tolerance per
/// quantity (positions, velocities, orientations, angular_velocities, contacts, pairs,
/// energy; unnamed ones 0). Throws
/// InputError naming the item for an unknown quantity, a negative or non-numeric value.
std::map<std::string, Tolerance> parse_tolerances(const std::vector<std::string>& args);

/// `octocd compare` options (cli/compare.cpp).
struct CompareOptions {
  std::string a, b;
  std::vector<std::string> tolerance;  ///< --tolerance arguments (parse_tolerances)
  /// --quantity; empty: positions, velocities, contacts, pairs, plus orientations and
  /// angular_velocities when either trace is of format version 2.
  std::string quantities;
  std::string json;
  /// --ignore: structure keys not compared (a key such as /midphase, and every key under it).
  std::vector<std::string> ignore;
};
CLI::App* add_compare_command(CLI::App& app, CompareOptions& o);
int compare_command(const CompareOptions& o);

/// What `octocd compare` finds for two traces (compare_traces), without printing or writing.
struct CompareOutcome {
  bool same = false;               ///< no structure difference and no quantity beyond its tolerance
  std::string text;                ///< what `compare` prints (the structure, the table, the verdict line)
  nlohmann::json doc;              ///< what `compare --json` writes (format octocd-compare, version 2)
  std::vector<std::string> structure;  ///< structure keys that differ (not --ignore'd)
  std::int64_t first_frame = -1;   ///< the first differing value: frame (-1: none)
  std::int64_t first_body = -1;    ///< its body (or a contact pair's first body; -1 per-frame quantities)
  std::string first_quantity;      ///< its quantity (positions, velocities, ..., contacts, pairs, energy)
  std::string first_detail;        ///< both values there
  double first_size = 0.0;         ///< |A - B| there (unit of the quantity; inf: a side lacks the pair or a NaN)
  /// Non-empty when no requested quantity is in both traces: the error `compare` exits 2 with.
  std::string nothing_compared;
};
/// Compares traces o.a and o.b as `octocd compare` does (o.json is ignored: the caller writes
/// CompareOutcome::doc). Throws InputError for unreadable or malformed traces and bad options.
CompareOutcome compare_traces(const CompareOptions& o);
/// As above, into `out`: on an exception `out.text` holds what was found before it.
void compare_traces(const CompareOptions& o, CompareOutcome& out);

/// `octocd report` options (cli/report.cpp).
struct ReportOptions {
  std::vector<std::string> inputs;
  std::string output;
  std::string title;
  std::vector<std::string> baseline;  ///< --baseline result files: the performance gate
  double threshold = 10.0;            ///< --threshold: slowdown in % that fails the gate (docs/bench-format.md: error rates)
  double level = 0.05;                ///< --level: the gate's significance level (one-sided Mann-Whitney U)
  bool across_machines = false;       ///< --across-machines: gate runs of two machines
  std::string timing = "auto";        ///< --timing: the gate's figure, auto, cpu or wall
  std::string csv;                    ///< --csv DIR: the data as CSV (docs/bench-format.md)
  std::string history;                ///< --history DIR: draw a history folder (docs/regression.md)
  double change_level = 0.05;         ///< --change-level: family-wise level of the change-point test
};
CLI::App* add_report_command(CLI::App& app, ReportOptions& o);
int report_command(const ReportOptions& o);

/// `octocd history-append` options (cli/history.cpp; docs/regression.md).
struct HistoryAppendOptions {
  std::string dir;                      ///< the history folder
  std::vector<std::string> bench;       ///< --bench: results of `octocd bench`
  std::vector<std::string> validation;  ///< --validation: verdicts of `octocd validate --json`
  std::vector<std::string> errored;     ///< --errored: cases without a verdict (SCENE or ENGINE--SCENE)
  std::string kind = "nightly";         ///< --kind: nightly or bench
};
CLI::App* add_history_append_command(CLI::App& app, HistoryAppendOptions& o);
int history_append_command(const HistoryAppendOptions& o);

/// The build as a history file records it: build_description() plus "version" and
/// "commit" (build_id()'s parts before and after its '+').
nlohmann::json history_build();

/// The rows of a verdict of `octocd validate --json` at `path` (read by octocd's strict
/// reader) as history rows: {"engine", "scene", "row", "tier", "verdict" (pass, fail, n/a,
/// expected), "status" (pass, expected, new, fixed, n/a), "expectations" [the row's
/// outcomes: outcome, cause, worst, allowed, reason (cut to 2000 bytes)]}. A matrix trace
/// ENGINE--SCENE[--quick].h5 gives the engine and scene. InputError naming the file and field.
nlohmann::json history_verdicts(const std::string& path);

/// Adds one run to the history folder `dir` (created; check_output_folder): the file
/// DIR/YYYYMMDDTHHMMSSZ-COMMIT-KIND.json {"format": "octocd-history", "version": 1, "kind",
/// "date", "build" (history_build), "machine" (machine_description), "bench" [results],
/// "verdicts" [history_verdicts rows]}, written to a temporary file beside it, fsynced and
/// hard-linked to its name, which is never an existing file (a name taken gets -2, -3,
/// ...). Returns the path written. RuntimeError naming `label` and the path when writing
/// fails (the folder is then left as it was).
std::string append_history(const std::string& dir, const std::string& kind, nlohmann::json bench,
                           nlohmann::json verdicts, const std::string& label);

/// `octocd trace-summary` options (cli/report.cpp).
struct TraceSummaryOptions {
  std::string trace;  ///< the trace (.h5)
  bool json = false;  ///< --json: one JSON object on stdout (else a few lines of text)
};
/// `octocd trace-summary [--json] TRACE`: what the report generator reads of a trace, read
/// through octocd::TraceReader (the hardened reader): root attributes, the complete rows of
/// /frames (at most committed_frames) and its columns. An InputError (exit 2) names the
/// file and dataset for a trace it refuses.
CLI::App* add_trace_summary_command(CLI::App& app, TraceSummaryOptions& o);
int trace_summary_command(const TraceSummaryOptions& o);

}  // namespace octocd::cli
