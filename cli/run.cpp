// `octocd run SCENE`: an engine steps a scene, with a progress bar, a summary and an
// optional trace (docs/cli.md, "run").
#include <signal.h>
#include <unistd.h>
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <fstream>
#include <map>
#include <memory>
#include <new>
#include <optional>
#include <string>
#include <vector>
#include <climits>
#include <condition_variable>
#include <exception>
#include <mutex>
#include <thread>
#include <filesystem>
#include <CLI/CLI.hpp>
#include <fmt/format.h>
#include <nlohmann/json.hpp>
#include "octocd/broadphase.hpp"
#include "octocd/bullet_world.hpp"
#include "octocd/error.hpp"
#include "octocd/expect.hpp"
#include "octocd/shards.hpp"
#include "octocd/external.hpp"
#include "octocd/midphase.hpp"
#include "octocd/reference_broadphase.hpp"
#include "octocd/scene.hpp"
#include "octocd/atomic_file.hpp"
#include "octocd/run_session.hpp"
#include "octocd/trace.hpp"
#include "octocd/validation.hpp"
#include "octocd/version.hpp"
#include "octocd/world.hpp"
#include "octocd/text.hpp"
#include "octocd/worlds.hpp"
#include "octocd/world_copies.hpp"
#include "octocd/cuda_world.hpp"
#include "octocd/engines.hpp"
#include "octocd/process_engines.hpp"
#include "command.hpp"
#include "command_support.hpp"
#include "frame_sums.hpp"
#include "tools.hpp"
#include "view.hpp"

namespace octocd::cli {

namespace {


struct RunOptions {
  std::string scene;
  std::string engine = "cpu";
  std::string broadphase;
  std::string midphase;
  int frames = 0;
  std::string trace;
  int state_every = 10;
  bool contacts = false;
  bool quiet = false;
  std::string summary_json;
  std::string data_dir;
  bool no_xdmf = false;
  bool rotation = false;  ///< --rotation: the scene's bodies rotate (engine bullet only)
  octocd::WorldsSpec worlds;  ///< --worlds, --world-perturb, --seed, --world-margin (worlds.hpp)
  octocd::EngineSettingItems settings;  ///< --ENGINE KEY=VALUE items by engine
};

/// Running sums for the summary table.
struct Totals : octocd::cli::FrameSums {
  double dynamic_pairs = 0.0;
  std::uint64_t max_pairs = 0, max_dynamic_pairs = 0, max_candidates = 0, max_contacts = 0,
                max_box_pairs = 0, max_vertex_tests = 0, max_memory_bytes = 0;
  double pen_mean_sum = 0.0, pen_max = 0.0;
  std::int64_t frames_with_contacts = 0;
  double energy_sum = 0.0, energy_max = 0.0;
  double model_s = 0.0;   ///< set-up: scene file, meshes, bodies (build_model), s
  double engine_s = 0.0;  ///< set-up: the engine (cuda: device buffers and upload), s
  /// A process engine's start-up, set-up and trace writing (its first step's wall time less
  /// its step calls' seconds, as its trace reports them), s; counted in engine_s.
  double process_s = 0.0;
  /// The engine reports its pair counts (a process engine's trace may have no /pairs).
  bool pairs_reported = true;
  octocd::FrameMetrics last;  ///< the last frame's row (the "last" column)

  void add(const octocd::FrameMetrics& m) {
    FrameSums::add(m);
    dynamic_pairs += static_cast<double>(m.dynamic_pairs);
    max_pairs = std::max(max_pairs, m.aabb_pairs);
    max_dynamic_pairs = std::max(max_dynamic_pairs, m.dynamic_pairs);
    max_candidates = std::max(max_candidates, m.cell_candidates);
    max_contacts = std::max(max_contacts, m.contacts);
    max_box_pairs = std::max(max_box_pairs, m.box_pairs);
    max_vertex_tests = std::max(max_vertex_tests, m.vertex_tests);
    max_memory_bytes = std::max(max_memory_bytes, m.memory_bytes);
    if (m.contacts > 0) {
      ++frames_with_contacts;
      pen_mean_sum += m.penetration_mean;
    }
    pen_max = std::max(pen_max, m.penetration_max);
    energy_sum += m.kinetic_energy;
    energy_max = frames == 1 ? m.kinetic_energy : std::max(energy_max, m.kinetic_energy);
    last = m;
  }
};

/// Progress on a terminal: one line rewritten in place; otherwise a plain line per 10%.
class Progress {
 public:
  Progress(std::int64_t total, bool enabled)
      : total_(total), enabled_(enabled), tty_(isatty(fileno(stderr)) != 0) {}

  void update(const octocd::FrameMetrics& m, const Totals& t) {
    if (!enabled_) return;
    std::fflush(stdout);  // stdout and stderr to one file: the lines in the order they happened
    const auto now = Clock::now();
    const bool last = m.frame == total_;
    if (tty_) {
      if (!last && now - last_draw_ < std::chrono::milliseconds(100)) return;
      last_draw_ = now;
      constexpr int kWidth = 30;
      const int filled = static_cast<int>(kWidth * m.frame / std::max<std::int64_t>(total_, 1));
      std::fprintf(stderr, "\r[%s%s] frame %lld/%lld  %8.1f steps/s  pairs %s  contacts %llu ",
                   std::string(static_cast<std::size_t>(filled), '#').c_str(),
                   std::string(static_cast<std::size_t>(kWidth - filled), ' ').c_str(),
                   static_cast<long long>(m.frame), static_cast<long long>(total_),
                   rate(t), pairs_ ? std::to_string(m.aabb_pairs).c_str() : "n/a",
                   static_cast<unsigned long long>(m.contacts));
      if (last) std::fprintf(stderr, "\n");
      std::fflush(stderr);
    } else {
      const std::int64_t step = std::max<std::int64_t>(total_ / 10, 1);
      if (m.frame % step != 0 && !last) return;
      std::fprintf(stderr, "frame %lld/%lld  %.1f steps/s  pairs %s  contacts %llu%s\n",
                   static_cast<long long>(m.frame), static_cast<long long>(total_), rate(t),
                   pairs_ ? std::to_string(m.aabb_pairs).c_str() : "n/a",
                   static_cast<unsigned long long>(m.contacts), read_ ? "  (read from its trace)" : "");
      std::fflush(stderr);
    }
  }

 private:
  static double rate(const Totals& t) {
    return t.step_ms > 0.0 ? 1000.0 * static_cast<double>(t.frames) / t.step_ms : 0.0;
  }
  std::int64_t total_;
  bool enabled_;
  bool tty_;
  bool pairs_ = true;  // the engine reports its pair counts (else "n/a")
  bool read_ = false;  // the frames are read from a process engine's trace, run before

 public:
  /// A process engine's frames, read from its trace after its process ran them all;
  /// `pairs`: whether it reports pair counts (its trace may have no /pairs).
  void set_read_from_trace(bool pairs) {
    read_ = true;
    pairs_ = pairs;
  }
  Clock::time_point last_draw_{};
};

/// What `--worlds` made (worlds.hpp): the copies' layout and, after the run, the copies
/// whose bodies left their cells.
struct WorldsRun {
  long count = 1;
  octocd::WorldsLayout layout;
  std::vector<long> escaped;
};

double steps_per_s(const Totals& t) {
  return t.step_ms > 0 ? 1000.0 * static_cast<double>(t.frames) / t.step_ms : 0.0;
}

void print_summary(const octocd::Engine& world, const Totals& t, double wall_s,
                   const std::string& trace, const std::string& xdmf, const WorldsRun& worlds) {
  const std::string engine = world.name();
  const std::string memory_kind = octocd::engine_info(engine, "engine").memory_kind;
  const double n = static_cast<double>(std::max<std::int64_t>(t.frames, 1));
  const octocd::Scene& s = world.scene();
  // Names and descriptions from files (the scene's, an engines file's command items) are
  // written for the terminal (octocd::printable).
  using octocd::printable;
  fmt::print("\nscene        {} ({} bodies, {} shapes)\n", printable(s.name), world.bodies().size(),
             world.shapes().size());
  fmt::print("pipeline     engine {}, broadphase {}, midphase {}, on {}\n", printable(engine),
             printable(world.broadphase_name()), printable(world.midphase_name()), printable(world.device()));
  fmt::print("geometry     {}\n", printable(world.collision_geometry()));
  fmt::print("set-up       {:.2f} s (scene and bodies {:.2f} s, engine {:.2f} s{})\n", t.model_s + t.engine_s,
             t.model_s, t.engine_s,
             t.process_s > 0 ? fmt::format(", of which {:.2f} s its process's start-up, set-up and trace writing "
                                           "outside its step calls", t.process_s)
                             : std::string());
  fmt::print("frames       {} (dt {} s, simulated {:.3f} s, wall {:.2f} s)\n", t.frames, s.dt,
             static_cast<double>(t.frames) * s.dt, wall_s);
  fmt::print("steps/s      {:.1f}   (mean step {:.3f} ms)\n", steps_per_s(t), t.step_ms / n);
  if (worlds.count > 1) {
    const octocd::WorldsLayout& l = worlds.layout;
    fmt::print("worlds       {} copies of {} bodies (grid {} x {} on x, z; cells {:.3g} x {:.3g} m), "
               "world-steps/s {:.4g}\n",
               worlds.count, world.bodies().size() / static_cast<std::size_t>(worlds.count), l.nx, l.nz,
               l.spacing.x, l.spacing.z, steps_per_s(t) * static_cast<double>(worlds.count));
    if (worlds.escaped.empty())
      fmt::print("             every copy stayed in its cell (no pair can have joined two copies)\n");
    else
      fmt::print("             {} copies left their cells (first: copy {}): their bodies may have met another "
                 "copy's; a larger --world-margin keeps them apart\n",
                 worlds.escaped.size(), worlds.escaped.front());
  }
  if (t.max_memory_bytes > 0)  // engines that report it (cuda: device memory)
    fmt::print("memory       {:.1f} MiB held by the pipeline's buffers (largest over frames{})\n",
               static_cast<double>(t.max_memory_bytes) / 1048576.0, memory_kind.empty() ? "" : ", " + memory_kind);
  fmt::print("\n");
  fmt::print("{:<12} {:>10} {:>8}\n", "stage", "mean ms", "share");
  for (int st = 0; st < kStages; ++st) {
    const auto stage = static_cast<octocd::Stage>(st);
    if (!world.has_stage(stage)) {
      fmt::print("{:<12} {:>10} {:>8}\n", octocd::stage_name(stage), "n/a", "");
      continue;
    }
    fmt::print("{:<12} {:>10.4f} {:>7.1f}%\n", octocd::stage_name(stage), t.stage_ms[st] / n,
               t.step_ms > 0 ? 100.0 * t.stage_ms[st] / t.step_ms : 0.0);
  }
  // Every row: the mean over frames, the largest frame value, the last frame's value.
  fmt::print("\n{:<24} {:>14} {:>14} {:>14}\n", "per frame", "mean", "max", "last");
  auto row = [](const char* name, double sum_over_n, std::uint64_t max, std::uint64_t last) {
    fmt::print("{:<24} {:>14.1f} {:>14} {:>14}\n", name, sum_over_n, max, last);
  };
  // Counts the engine does not report: n/a, never 0.
  auto pair_row = [&](const char* name, double sum_over_n, std::uint64_t max, std::uint64_t last) {
    if (t.pairs_reported) row(name, sum_over_n, max, last);
    else fmt::print("{:<24} {:>14} {:>14} {:>14}\n", name, "n/a", "n/a", "n/a");
  };
  pair_row("broadphase candidates", t.candidates / n, t.max_candidates, t.last.cell_candidates);
  pair_row("AABB pairs", t.pairs / n, t.max_pairs, t.last.aabb_pairs);
  pair_row("  dynamic pairs", t.dynamic_pairs / n, t.max_dynamic_pairs, t.last.dynamic_pairs);
  row("midphase box pairs", t.box_pairs / n, t.max_box_pairs, t.last.box_pairs);
  row("vertex tests", t.vertex_tests / n, t.max_vertex_tests, t.last.vertex_tests);
  row("contacts", t.contacts / n, t.max_contacts, t.last.contacts);
  const double pen_mean =
      t.frames_with_contacts > 0 ? t.pen_mean_sum / static_cast<double>(t.frames_with_contacts) : 0.0;
  fmt::print("{:<24} {:>14.6f} {:>14.6f} {:>14.6f}\n", "penetration (m)", pen_mean, t.pen_max,
             t.last.penetration_max);
  fmt::print("{:<24} {:>14.4f} {:>14.4f} {:>14.4f}\n", "kinetic energy (J)", t.energy_sum / n, t.energy_max,
             t.last.kinetic_energy);
  fmt::print("\n(penetration: mean over frames with contacts of the frame mean; max and last are the "
             "largest d_p.\n AABB pairs include static-static pairs (walls touching walls); dynamic pairs "
             "are the ones\n that can produce a contact; broadphase candidates are the pairs tested before "
             "the exact AABB test{}.)\n",
             t.pairs_reported ? "" : ";\n n/a: the engine reports no pairs (its trace has no /pairs)");
  const std::string notes = world.notes();
  if (!notes.empty()) {
    std::string shown;  // each line printable, the lines kept
    for (std::size_t at = 0; at <= notes.size();) {
      const std::size_t end = std::min(notes.find('\n', at), notes.size());
      shown += (at ? "\n" : "") + printable(std::string_view(notes).substr(at, end - at), static_cast<std::size_t>(-1));
      at = end + 1;
    }
    fmt::print("\nengine {}: {}\n", printable(engine), shown);
  }
  if (!trace.empty()) fmt::print("\ntrace        {}\n", trace);
  if (!xdmf.empty()) fmt::print("xdmf         {} (ParaView, Xdmf3 reader)\n", xdmf);
}

void write_summary_json(const std::string& path, const octocd::Engine& world, const Totals& t,
                        double wall_s, const WorldsRun& worlds) {
  const std::string engine = world.name();
  const double n = static_cast<double>(std::max<std::int64_t>(t.frames, 1));
  nlohmann::json j;
  j["scene"] = world.scene().name;
  j["bodies"] = world.bodies().size();
  j["engine"] = engine;
  j["broadphase"] = world.broadphase_name();
  j["midphase"] = world.midphase_name();
  j["geometry"] = world.collision_geometry();
  j["frames"] = t.frames;
  j["wall_s"] = wall_s;
  // Set-up before the first step: scene file, meshes and bodies; the engine.
  j["setup_s"] = {{"model", t.model_s}, {"engine", t.engine_s}};
  j["steps_per_s"] = steps_per_s(t);
  // Batched worlds (--worlds): copies, world-steps/s (steps/s x copies), copies that left their cells.
  j["worlds"] = worlds.count;
  j["world_steps_per_s"] = steps_per_s(t) * static_cast<double>(worlds.count);
  j["worlds_escaped"] = worlds.escaped.size();
  j["mean_step_ms"] = t.step_ms / n;
  for (int st = 0; st < kStages; ++st) {
    const auto stage = static_cast<octocd::Stage>(st);
    // null: the engine has no such stage (not 0 ms).
    j["stage_ms"][octocd::stage_name(stage)] =
        world.has_stage(stage) ? nlohmann::json(t.stage_ms[st] / n) : nlohmann::json(nullptr);
  }
  j["mean_cell_candidates"] = t.candidates / n;
  j["mean_pairs"] = t.pairs / n;
  j["max_pairs"] = t.max_pairs;
  j["mean_dynamic_pairs"] = t.dynamic_pairs / n;
  j["max_dynamic_pairs"] = t.max_dynamic_pairs;
  j["mean_contacts"] = t.contacts / n;
  j["max_contacts"] = t.max_contacts;
  j["mean_box_pairs"] = t.box_pairs / n;
  j["mean_vertex_tests"] = t.vertex_tests / n;
  j["penetration_max"] = t.pen_max;
  // Bytes held by the pipeline's buffers, largest over frames (cuda: device memory).
  j["memory_bytes"] = t.max_memory_bytes;
  // Kinetic energy (J, dynamic bodies): mean over frames, largest, last frame's.
  j["kinetic_energy"] = {{"mean", t.energy_sum / n}, {"max", t.energy_max}, {"last", t.last.kinetic_energy}};
  j["device"] = world.device();
  j["build_id"] = octocd::build_id();
  octocd::write_file_atomically(path, j.dump(2) + "\n", "--summary-json");
}

/// octocd's engines step the copies of `--worlds` as one world; any other engine steps one
/// scene per run and runs the copies as separate runs (run_copies).
bool batched_worlds_engine(const std::string& engine) { return octocd::engine_info(engine, "--engine").batched_worlds; }

void check_worlds_trace(bool traced) {
  if (traced)
    throw octocd::InputError(
        "--trace with --worlds/--world-perturb: a trace holds one scene, and the copies are made in memory; "
        "allowed: --trace without --worlds (one copy), or --summary-json for the batched run's figures");
}

/// `run --worlds K` on an engine that steps one scene per run (docs/gpu.md): the K copies as
/// separate runs (world_copies.hpp), as many at once as the host has threads; progress on
/// stderr (the first copy run whole, then at most one line a second); a summary of the
/// copies (steps/s per copy, world-steps/s = the steps run / wall time). A stop says how many
/// copies ran whole and where the one cut short stopped.
int run_copies(octocd::RunSession& session, const RunOptions& o, const std::shared_ptr<const octocd::Model>& single,
               int frames, double model_s) {
  const long k = o.worlds.count;
  std::vector<int> copy_frames(static_cast<std::size_t>(std::max<long>(k, 1)), 0);  // one writer per copy
  std::atomic<long> whole_so_far{0};
  std::mutex print_mutex;
  const auto t0 = Clock::now();
  auto last_line = t0 - std::chrono::hours(1);
  const auto on_frame = [&](std::size_t c, const octocd::FrameMetrics&, const octocd::Engine&) {
    if (++copy_frames[c] != frames) return;
    const long whole = ++whole_so_far;
    if (o.quiet) return;
    const std::lock_guard<std::mutex> lock(print_mutex);
    const auto now = Clock::now();
    if (whole != k && now - last_line < std::chrono::seconds(1)) return;
    last_line = now;
    std::fflush(stdout);
    std::fprintf(stderr, "worlds: %ld of %ld copies run (%d frames each), %.1f s\n", whole, k, frames,
                 std::chrono::duration<double>(now - t0).count());
    std::fflush(stderr);
  };
  const octocd::CopiesRun r =
      octocd::run_copies_separately(o.engine, single, o.worlds, frames, 0, o.settings, on_frame);
  std::vector<double> per_copy;
  std::int64_t ran = 0;
  long whole = 0;
  std::size_t cut = r.frames.size();  // the first copy begun and cut short by a stop
  for (std::size_t c = 0; c < r.frames.size(); ++c) {
    ran += r.frames[c];
    if (r.frames[c] == frames) ++whole;
    else if (r.frames[c] > 0 && cut == r.frames.size()) cut = c;
    if (r.step_ms[c] > 0.0) per_copy.push_back(1000.0 * static_cast<double>(r.frames[c]) / r.step_ms[c]);
  }
  std::sort(per_copy.begin(), per_copy.end());
  const double median = per_copy.empty() ? 0.0 : per_copy[per_copy.size() / 2];
  const double world_steps = r.wall_s > 0.0 ? static_cast<double>(ran) / r.wall_s : 0.0;
  const std::string copies =
      whole == k ? fmt::format("{} copies", k) : fmt::format("{} of {} copies run whole (stopped)", whole, k);
  if (!o.quiet) {
    fmt::print("\nscene        {} ({} bodies) x {} copies as separate runs\n", octocd::printable(single->scene.name),
               single->initial.size(), k);
    const std::string& unsafe = octocd::engine_info(o.engine, "--engine").not_thread_safe;
    if (unsafe.empty()) fmt::print("pipeline     engine {}, {} copies at once\n", o.engine, r.threads);
    else fmt::print("pipeline     engine {}, one copy at a time (not thread-safe: {})\n", o.engine, unsafe);
    fmt::print("set-up       {:.2f} s (scene and bodies)\n", model_s);
    fmt::print("frames       {} per copy (dt {} s), wall {:.2f} s for {}\n", frames, single->scene.dt, r.wall_s,
               whole == k ? std::string("all copies") : copies);
    fmt::print("steps/s      {:.1f}   (a copy's steps over its step time, the median over copies)\n", median);
    fmt::print("worlds       {} as separate runs of engine {} ({} at once), world-steps/s {:.4g} (steps of "
               "all copies run over the wall time)\n",
               copies, o.engine, r.threads, world_steps);
  }
  if (!o.summary_json.empty()) {
    nlohmann::json j;
    j["scene"] = single->scene.name;
    j["bodies"] = single->initial.size();
    j["engine"] = o.engine;
    j["frames"] = frames;
    j["wall_s"] = r.wall_s;
    j["setup_s"] = {{"model", model_s}};
    j["steps_per_s"] = median;
    j["worlds"] = k;
    j["worlds_whole"] = whole;
    j["world_steps_per_s"] = world_steps;
    j["worlds_separate_runs"] = true;
    j["worlds_threads"] = r.threads;
    j["build_id"] = octocd::build_id();
    octocd::write_file_atomically(o.summary_json, j.dump(2) + "\n", "--summary-json");
  }
  if (const int sig = session.signal()) {
    session.keep(o.summary_json.empty() ? std::string("")
                                        : fmt::format("--summary-json {} holds the copies run", o.summary_json));
    return session.stopped(
        sig, fmt::format(" after {} of {} copies ({} frames each){}", whole, k, frames,
                         cut < r.frames.size() ? fmt::format("; copy {} stopped after frame {}", cut + 1, r.frames[cut])
                                               : std::string()));
  }
  return 0;
}

/// How long the read-back of what `run` keeps may take before the process ends with the
/// trace's last flush said instead (s).
constexpr double kRunReadBackBound = 0.2;

/// `run`: from a SIGINT or SIGTERM to the end of the process, at most this long (s) plus
/// kRunReadBackBound: the step in progress gets the 0.5 s grace, the trace's last flush is
/// bounded by TraceOptions::flush_bytes; past it the process ends keeping the flushed
/// frames, said as read back from the trace.
constexpr double kRunStopBound = 0.75;

int run_command(const RunOptions& o) {
  // SIGINT/SIGTERM: stop between frames, flush, 130/143, within kRunStopBound; the
  // session says what the trace keeps should the process end inside a step.
  octocd::RunSession session("run", {kRunStopBound});
  session.keep(o.trace.empty() ? std::string("no frame run yet")
                               : fmt::format("no frame run yet; the trace {} is not begun", o.trace));
  // Output paths before any work: absent or a regular file (atomic_file.hpp).
  if (!o.trace.empty()) octocd::check_output_file(o.trace, "--trace");
  if (!o.summary_json.empty()) octocd::check_output_file(o.summary_json, "--summary-json");
  const auto t_setup = Clock::now();
  std::optional<octocd::StopAtOnce> loading(std::in_place, "loading the scene and its meshes");
  octocd::Scene scene = load_scene_for(o.scene, o.data_dir);
  if (o.frames > 0) scene.frames = o.frames;
  octocd::EngineOptions eo;
  eo.broadphase = o.broadphase;
  eo.midphase = o.midphase;
  eo.rotation = o.rotation;
  octocd::check_engine_settings(o.settings, octocd::cli_argument_names());
  eo.settings = o.settings;
  octocd::apply_engine_options(scene, octocd::engine_info(o.engine, "--engine"), eo, octocd::cli_argument_names());

  std::shared_ptr<const octocd::Model> model = octocd::build_model(scene);
  WorldsRun worlds;
  if (o.worlds.count > 1 || o.worlds.perturb > 0.0) {
    check_worlds_trace(!o.trace.empty());
    if (!batched_worlds_engine(o.engine)) {
      loading.reset();
      return run_copies(session, o, model, scene.frames,
                        std::chrono::duration<double>(Clock::now() - t_setup).count());
    }
    worlds.count = o.worlds.count;
    worlds.layout = octocd::worlds_layout(*model, o.worlds);
    model = octocd::make_worlds_model(*model, worlds.layout.offsets, o.worlds);
  }
  loading.reset();  // from here on the loop polls the signal, flushes and reports
  const auto t_model = Clock::now();
  // Set-up progress of a large scene (kSetupLinesFrom bodies): its two stages on stderr.
  constexpr std::size_t kSetupLinesFrom = 10000;
  const bool setup_lines = !o.quiet && model->bodies.size() >= kSetupLinesFrom;
  // The process's CPU seconds (every thread, user + system) beside the wall seconds: on a
  // shared machine the wall time is the load's as much as the engine's.
  const auto cpu_s = [] {
    timespec ts{};
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
    return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
  };
  if (setup_lines)
    std::fprintf(stderr, "set-up: scene and bodies %.2f s (%zu bodies); building the %s world\n",
                 std::chrono::duration<double>(t_model - t_setup).count(), model->bodies.size(), o.engine.c_str());
  const double cpu_model = cpu_s();
  const std::unique_ptr<octocd::Engine> engine = make_engine(o.engine, model, eo.settings);
  octocd::Engine& world = *engine;
  Totals totals;
  totals.model_s = std::chrono::duration<double>(t_model - t_setup).count();
  totals.engine_s = std::chrono::duration<double>(Clock::now() - t_model).count();
  if (setup_lines)
    std::fprintf(stderr, "set-up: %s world %.2f s (%.2f CPU s); stepping\n", o.engine.c_str(), totals.engine_s,
                 cpu_s() - cpu_model);
  std::unique_ptr<octocd::TraceWriter> trace;
  // An engine that writes its own trace (a process engine) gives it whole after the loop.
  if (!o.trace.empty() && !world.writes_own_trace()) {
    octocd::TraceOptions topt;
    topt.state_every = o.state_every;
    topt.flush_interval_s = octocd::cli::kTraceFlushIntervalS;
    topt.contacts = o.contacts && world.can_record();
    if (topt.contacts) world.set_recording(true);  // the GPU copies contacts back only then
    if (const octocd::RotationTraits* traits = world.rotation_traits()) {  // a rotating engine: version 2
      topt.v2 = *traits;
      topt.gravity = scene.gravity;
      check_engine_inertia(world, *model, o.engine);  // a trace octocd would refuse is never begun
    }
    octocd::TraceMetadata meta = octocd::trace_metadata(world, o.state_every);
    meta.start_time = octocd::cli::utc_time_now();
    trace = std::make_unique<octocd::TraceWriter>(o.trace, meta, octocd::trace_bodies(world), topt);
    trace->append_state(0, world.state());
  }
  // Declared after `trace`: the session keeps the trace's frames (its last flush, read back
  // should the process end at once) until the trace is closed, whatever the way out.
  std::optional<octocd::RunSession::KeptTrace> kept;
  if (trace) kept.emplace(session.keep_trace(*trace, o.trace, ", no sidecar", kRunReadBackBound));
  else session.keep("");  // nothing written: the stop line says where it stopped

  Progress progress(scene.frames, !o.quiet);
  // Without a trace nothing but the metrics is read between the steps: the engine may run
  // ahead of the calls (the summary reads no state).
  // With a trace of states only the engine may run ahead to the next state frame (TraceFeed).
  const octocd::cli::TraceFeed feed = octocd::cli::TraceFeed::of(world, o.contacts);
  if (!trace) world.plan_steps(scene.frames);
  else feed.start(*trace, world, scene.frames);
  // A process engine runs every step in its first step() (process_engines.hpp): its
  // start-up and steps are said as they happen, its start-up measured into the set-up.
  const bool own_process = world.writes_own_trace();
  octocd::cli::show_process_progress(world, scene.frames, !o.quiet);
  const auto t0 = Clock::now();
  try {
    for (int f = 0; f < scene.frames && octocd::stop_signal() == 0; ++f) {
      // A step of a big scene may take seconds: a signal it does not answer within the
      // grace ends the run there, with the trace's flushed frames (SWMR, trace.hpp).
      std::optional<octocd::StopWithin> within(
          std::in_place,
          fmt::format("run stepped frame {} of {} (a step longer than the 0.5 s grace)", f + 1, scene.frames));
      const octocd::FrameMetrics& m = world.step();
      within.reset();
      if (setup_lines && f == 0)
        std::fprintf(stderr, "set-up: first frame %.2f s after the start (%.2f CPU s of the process)\n",
                     std::chrono::duration<double>(Clock::now() - t_setup).count(), cpu_s());
      if (own_process && f == 0) {
        const double first_s = std::chrono::duration<double>(Clock::now() - t0).count();
        const double steps_s = m.step_ms * static_cast<double>(scene.frames) / 1000.0;
        totals.process_s = std::max(0.0, first_s - steps_s);
        totals.engine_s += totals.process_s;
        totals.pairs_reported = world.record().has_pairs;
        progress.set_read_from_trace(totals.pairs_reported);
        if (!o.quiet)
          std::fprintf(stderr, "engine %s: its process ran %d frames in %.2f s (%.2f s in its step calls, %.2f s "
                       "start-up, set-up and trace writing); reading its frames\n",
                       octocd::printable(world.name()).c_str(), scene.frames, first_s, steps_s, totals.process_s);
      }
      totals.add(m);
      // A reference engine's state past the trace limits (a spinning needle) ends the run
      // before its frame is written: every trace `run` writes is judgeable.
      if (trace && world.rotation_traits()) check_engine_state(world.state(), f + 1, o.engine);
      if (trace) {
        feed.append(*trace, world, m, scene.frames - (f + 1));
        kept->frame_written();
      }
      progress.update(m, totals);
    }
  } catch (const octocd::RuntimeError&) {
    if (kept) kept->end();
    close_after_failure(trace, o.trace, o.no_xdmf);
    throw;
  }
  std::string xdmf;
  if (!o.trace.empty() && world.writes_own_trace() && octocd::stop_signal() == 0) {
    // The engine's own trace is another program's version 2 layout (docs/bring-your-engine.md),
    // not octocd's, which the XDMF sidecar's hyperslabs describe: no sidecar for it.
    octocd::copy_own_trace(world, o.trace, "--trace");
  }
  if (kept) kept->end();
  if (trace) {
    trace->close();
    // A stopped run has a second: the sidecar re-reads the whole trace (the hardened
    // reader walks its heaps: 1 s for 200 MB), so it is left out.
    if (octocd::stop_signal() == 0) xdmf = write_sidecar(o.trace, o.no_xdmf);
    session.keep(fmt::format("the trace {} holds frames 1..{}, closed", o.trace, totals.frames));
  }
  // The stepping's wall time; a process engine's start-up is in the set-up.
  const double wall_s = std::chrono::duration<double>(Clock::now() - t0).count() - totals.process_s;
  if (worlds.count > 1)
    worlds.escaped = octocd::worlds_escaped(*model, worlds.layout, o.worlds.margin, world.state());
  if (!o.quiet) print_summary(world, totals, wall_s, o.trace, xdmf, worlds);
  if (!o.summary_json.empty()) write_summary_json(o.summary_json, world, totals, wall_s, worlds);
  if (const int sig = session.signal())
    return stopped_after_frame(session, sig, totals.frames, scene.frames, o.trace,
                               o.no_xdmf ? "" : "; no XDMF sidecar (a stopped run writes none)");
  return 0;
}

}  // namespace

Command add_run_command(CLI::App& app) {
  const auto options = std::make_shared<RunOptions>();
  RunOptions& run = *options;
  CLI::App* run_cmd = add_table_command(app, CommandId::run);
  run_cmd->add_option("scene", run.scene, "Scene file (JSON, see docs/scenes.md)")->required();
  run_cmd->add_option("--engine", run.engine, engines_help())
      ->check(CLI::IsMember(octocd::engine_names()))
      ->default_val("cpu");
  std::string bp_help = "Broadphase, overrides the scene's broadphase.name:";
  for (const auto& name : octocd::all_broadphase_names()) bp_help += " " + name;
  for (const auto& name : octocd::cuda_only_broadphase_names()) bp_help += " " + name;
  for (const EngineInfo& e : engine_infos())
    if (!e.uses_scene_broadphase) bp_help += fmt::format(" (with --engine {}: {} only)", e.name, e.own_broadphase);
  bp_help += fmt::format(" (lbvh, a Karras 2012 linear BVH: with {} only)",
                         engines_with([](const EngineInfo& e) { return e.device_broadphases; }));
  run_cmd->add_option("--broadphase", run.broadphase, bp_help);
  run_cmd->add_option("--midphase", run.midphase,
                      "Midphase levels, overrides the scene's midphase.levels: aabb-only | 2 | 1,2 | "
                      "0,1,2 | any ascending list of levels in [0, midphase.depth] (with " +
                          engines_with([](const EngineInfo& e) { return e.has_midphase; }) + ")");
  run_cmd->add_option("--frames", run.frames, "Number of steps, overrides the scene (>= 1)")
      ->check(at_least_one());
  run_cmd->add_option("--trace", run.trace, "Write an HDF5 trace (docs/trace-format.md)");
  run_cmd->add_option("--state-every", run.state_every,
                      "Record positions and velocities every K-th frame in the trace (>= 1)")
      ->check(at_least_one())
      ->default_val(10);
  run_cmd->add_flag("--contacts", run.contacts, "Record every contact (/contacts) in the trace");
  run_cmd->add_flag("--quiet", run.quiet, "No progress and no summary table");
  run_cmd->add_option("--summary-json", run.summary_json,
                      "Also write the summary (steps/s, stage ms, counts, kinetic energy) as JSON to "
                      "this file");
  run_cmd->add_option("--data-dir", run.data_dir, data_dir_help());
  run_cmd->add_flag("--no-xdmf", run.no_xdmf,
                    "With --trace: do not write the XDMF sidecar FILE.h5.xmf (ParaView) beside it");
  run_cmd->add_flag("--rotation", run.rotation,
                    "The bodies rotate (as the scene key rotation: true; with " +
                        engines_with([](const EngineInfo& e) { return e.rotates; }) +
                        "); --trace writes format version 2 (orientation, angular velocity, inertia; with "
                        "--contacts manifold rows with points, /pairs, /aabbs)");
  run_cmd->add_option("--worlds", run.worlds.count,
                      std::string("Batched worlds: K copies of the scene (docs/gpu.md, \"Batched worlds\"). Engines cpu and "
                                  "cuda step them as one world: copies on an x-z grid, each in a cell of the scene's "
                                  "bounds (domain, walls, bodies) plus --world-margin, so no pair joins two copies; "
                                  "other engines run them as separate runs, as many at once as the host has threads. "
                                  "The summary adds world-steps/s. Not with --trace"))
      ->check(CLI::Range(1L, octocd::kMaxWorlds))
      ->default_val(1);
  run_cmd->add_option("--world-perturb", run.worlds.perturb,
                      "With --worlds: move each dynamic body of copies 1..K-1 by a uniform random offset in "
                      "[-EPS, EPS) per axis (m; copy 0 stays the reference)")
      ->check(CLI::Range(0.0, octocd::kMaxWorldPerturb))
      ->default_val(0.0);
  run_cmd->add_option("--seed", run.worlds.seed, "The --world-perturb random stream (an integer)")->default_val(1);
  run_cmd->add_option("--world-margin", run.worlds.margin,
                      "With --worlds: the gap (m) between neighbouring copies' bounds")
      ->check(CLI::Range(octocd::limits::kMinLength, octocd::limits::kMaxLength))
      ->default_val(0.5);
  add_engine_settings_options(run_cmd, run.settings);

  return {[run_cmd] { return run_cmd->parsed(); }, [options] { return run_command(*options); }};
}

}  // namespace octocd::cli
