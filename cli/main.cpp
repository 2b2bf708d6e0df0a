// The `octocd` command (SPEC section 9). Exit codes: 0 ok, 1 runtime failure, 2 bad input.
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <fstream>
#include <memory>
#include <new>
#include <optional>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>
#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "octocd/broadphase.hpp"
#include "octocd/bullet_world.hpp"
#include "octocd/error.hpp"
#include "octocd/midphase.hpp"
#include "octocd/reference_broadphase.hpp"
#include "octocd/scene.hpp"
#include "octocd/stop.hpp"
#include "octocd/trace.hpp"
#include "octocd/validation.hpp"
#include "octocd/version.hpp"
#include "octocd/world.hpp"
#include "octocd/cuda_world.hpp"

namespace {

using Clock = std::chrono::steady_clock;
constexpr int kStages = static_cast<int>(octocd::Stage::Count);

/// The engine `name` (cpu, cuda, bullet) built from `model`. Throws InputError for an
/// unknown name or a bad broadphase, RuntimeError when the engine cannot start (no CUDA).
std::unique_ptr<octocd::Engine> make_engine(const std::string& name,
                                            const std::shared_ptr<const octocd::Model>& model) {
  const octocd::Scene& scene = model->scene;
  if (name == "cpu")
    return std::make_unique<octocd::World>(model, octocd::make_any_broadphase(scene.broadphase, scene.domain));
  if (name == "bullet") return std::make_unique<octocd::BulletWorld>(model, model->initial);
  if (name == "cuda") return octocd::make_cuda_engine(model, scene.broadphase.name);
  throw octocd::InputError(fmt::format("--engine: unknown engine '{}'; allowed: cpu, cuda, bullet", name));
}

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
};

/// Running sums for the summary table.
struct Totals {
  std::int64_t frames = 0;
  double step_ms = 0.0;
  std::array<double, kStages> stage_ms{};
  double pairs = 0.0, contacts = 0.0, box_pairs = 0.0, vertex_tests = 0.0;
  std::uint64_t max_pairs = 0, max_contacts = 0;
  double pen_mean_sum = 0.0, pen_max = 0.0;
  std::int64_t frames_with_contacts = 0;

  void add(const octocd::FrameMetrics& m) {
    ++frames;
    step_ms += m.step_ms;
    for (int s = 0; s < kStages; ++s) stage_ms[s] += m.stage_ms[s];
    pairs += static_cast<double>(m.aabb_pairs);
    contacts += static_cast<double>(m.contacts);
    box_pairs += static_cast<double>(m.box_pairs);
    vertex_tests += static_cast<double>(m.vertex_tests);
    max_pairs = std::max(max_pairs, m.aabb_pairs);
    max_contacts = std::max(max_contacts, m.contacts);
    if (m.contacts > 0) {
      ++frames_with_contacts;
      pen_mean_sum += m.penetration_mean;
    }
    pen_max = std::max(pen_max, m.penetration_max);
  }
};

/// Progress on a terminal: one line rewritten in place; otherwise a plain line per 10%.
class Progress {
 public:
  Progress(std::int64_t total, bool enabled)
      : total_(total), enabled_(enabled), tty_(isatty(fileno(stderr)) != 0) {}

  void update(const octocd::FrameMetrics& m, const Totals& t) {
    if (!enabled_) return;
    const auto now = Clock::now();
    const bool last = m.frame == total_;
    if (tty_) {
      if (!last && now - last_draw_ < std::chrono::milliseconds(100)) return;
      last_draw_ = now;
      constexpr int kWidth = 30;
      const int filled = static_cast<int>(kWidth * m.frame / std::max<std::int64_t>(total_, 1));
      std::fprintf(stderr, "\r[%s%s] frame %lld/%lld  %8.1f steps/s  pairs %llu  contacts %llu ",
                   std::string(static_cast<std::size_t>(filled), '#').c_str(),
                   std::string(static_cast<std::size_t>(kWidth - filled), ' ').c_str(),
                   static_cast<long long>(m.frame), static_cast<long long>(total_),
                   rate(t), static_cast<unsigned long long>(m.aabb_pairs),
                   static_cast<unsigned long long>(m.contacts));
      if (last) std::fprintf(stderr, "\n");
      std::fflush(stderr);
    } else {
      const std::int64_t step = std::max<std::int64_t>(total_ / 10, 1);
      if (m.frame % step != 0 && !last) return;
      std::fprintf(stderr, "frame %lld/%lld  %.1f steps/s  pairs %llu  contacts %llu\n",
                   static_cast<long long>(m.frame), static_cast<long long>(total_), rate(t),
                   static_cast<unsigned long long>(m.aabb_pairs),
                   static_cast<unsigned long long>(m.contacts));
    }
  }

 private:
  static double rate(const Totals& t) {
    return t.step_ms > 0.0 ? 1000.0 * static_cast<double>(t.frames) / t.step_ms : 0.0;
  }
  std::int64_t total_;
  bool enabled_;
  bool tty_;
  Clock::time_point last_draw_{};
};

std::string utc_now() {
  const std::time_t t = std::time(nullptr);
  std::tm tm{};
  gmtime_r(&t, &tm);
  char buf[32];
  std::strftime(buf, sizeof buf, "%Y-%m-%dT%H:%M:%SZ", &tm);
  return buf;
}

void print_summary(const octocd::Engine& world, const Totals& t, double wall_s,
                   const std::string& trace) {
  const std::string engine = world.name();
  const double n = static_cast<double>(std::max<std::int64_t>(t.frames, 1));
  const octocd::Scene& s = world.scene();
  fmt::print("\nscene        {} ({} bodies, {} shapes)\n", s.name, world.state().size(),
             world.shapes().size());
  if (!world.has_stage(octocd::Stage::Midphase))
    fmt::print("pipeline     engine {} ({}, box shapes), on {}\n", engine, world.broadphase_name(),
               world.device());
  else
    fmt::print("pipeline     engine {}, broadphase {}, midphase {}, on {}\n", engine, world.broadphase_name(),
               s.midphase.to_string(), world.device());
  fmt::print("frames       {} (dt {} s, simulated {:.3f} s, wall {:.2f} s)\n", t.frames, s.dt,
             static_cast<double>(t.frames) * s.dt, wall_s);
  fmt::print("steps/s      {:.1f}   (mean step {:.3f} ms)\n\n",
             t.step_ms > 0 ? 1000.0 * static_cast<double>(t.frames) / t.step_ms : 0.0,
             t.step_ms / n);
  fmt::print("{:<12} {:>10} {:>8}\n", "stage", "mean ms", "share");
  for (int st = 0; st < kStages; ++st)
    fmt::print("{:<12} {:>10.4f} {:>7.1f}%\n", octocd::stage_name(static_cast<octocd::Stage>(st)),
               t.stage_ms[st] / n, t.step_ms > 0 ? 100.0 * t.stage_ms[st] / t.step_ms : 0.0);
  fmt::print("\n{:<22} {:>12} {:>12}\n", "per frame", "mean", "max");
  fmt::print("{:<22} {:>12.1f} {:>12}\n", "AABB pairs", t.pairs / n, t.max_pairs);
  fmt::print("{:<22} {:>12.1f} {:>12}\n", "contacts", t.contacts / n, t.max_contacts);
  fmt::print("{:<22} {:>12.1f} {:>12}\n", "midphase box pairs", t.box_pairs / n, "");
  fmt::print("{:<22} {:>12.1f} {:>12}\n", "vertex tests", t.vertex_tests / n, "");
  const double pen_mean =
      t.frames_with_contacts > 0 ? t.pen_mean_sum / static_cast<double>(t.frames_with_contacts) : 0.0;
  fmt::print("{:<22} {:>12.6f} {:>12.6f}\n", "penetration (m)", pen_mean, t.pen_max);
  fmt::print("{:<22} {:>12.4f}\n", "kinetic energy (J)", world.last_metrics().kinetic_energy);
  if (!trace.empty()) fmt::print("\ntrace        {}\n", trace);
}

void write_summary_json(const std::string& path, const octocd::Engine& world, const Totals& t,
                        double wall_s) {
  const std::string engine = world.name();
  const double n = static_cast<double>(std::max<std::int64_t>(t.frames, 1));
  nlohmann::json j;
  j["scene"] = world.scene().name;
  j["bodies"] = world.state().size();
  j["engine"] = engine;
  j["broadphase"] = world.broadphase_name();
  j["midphase"] = world.scene().midphase.to_string();
  j["frames"] = t.frames;
  j["wall_s"] = wall_s;
  j["steps_per_s"] = t.step_ms > 0 ? 1000.0 * static_cast<double>(t.frames) / t.step_ms : 0.0;
  j["mean_step_ms"] = t.step_ms / n;
  for (int st = 0; st < kStages; ++st)
    j["stage_ms"][octocd::stage_name(static_cast<octocd::Stage>(st))] = t.stage_ms[st] / n;
  j["mean_pairs"] = t.pairs / n;
  j["mean_contacts"] = t.contacts / n;
  j["mean_box_pairs"] = t.box_pairs / n;
  j["mean_vertex_tests"] = t.vertex_tests / n;
  j["penetration_max"] = t.pen_max;
  j["device"] = world.device();
  j["build_id"] = octocd::build_id();
  std::ofstream out(path);
  if (!out) throw octocd::RuntimeError(fmt::format("cannot write summary '{}'", path));
  out << j.dump(2) << "\n";
}

/// The line a command stopped by SIGINT/SIGTERM prints on stderr: where it stopped and
/// what it kept.
void report_stop(int sig, const char* command, std::int64_t done, std::int64_t total,
                 const std::string& trace) {
  std::string kept;
  if (!trace.empty())
    kept = done > 0 ? fmt::format("; the trace {} holds frames 1..{}", trace, done)
                    : fmt::format("; the trace {} holds no frame", trace);
  std::fprintf(stderr, "octocd %s: stopped by %s after frame %lld of %lld%s\n", command,
               octocd::stop_signal_name(sig), static_cast<long long>(done),
               static_cast<long long>(total), kept.c_str());
}

int run_command(const RunOptions& o) {
  octocd::StopOnSignals stop_on_signals;  // SIGINT/SIGTERM: stop between frames, flush, 130/143
  octocd::Scene scene = octocd::load_scene(o.scene);
  if (!o.broadphase.empty()) scene.broadphase.name = o.broadphase;
  if (!o.midphase.empty()) scene.midphase = octocd::MidphaseConfig::parse(o.midphase, "--midphase");
  if (o.frames > 0) scene.frames = o.frames;

  const std::unique_ptr<octocd::Engine> engine = make_engine(o.engine, octocd::build_model(scene));
  octocd::Engine& world = *engine;
  std::unique_ptr<octocd::TraceWriter> trace;
  if (!o.trace.empty()) {
    octocd::TraceOptions topt;
    topt.state_every = o.state_every;
    topt.contacts = o.contacts && world.can_record();
    if (topt.contacts) world.set_recording(true);  // the GPU copies contacts back only then
    octocd::TraceMetadata meta = octocd::trace_metadata(world, o.state_every);
    meta.start_time = utc_now();
    trace = std::make_unique<octocd::TraceWriter>(o.trace, meta, octocd::trace_bodies(world), topt);
    trace->append_state(0, world.state());
  }

  Totals totals;
  Progress progress(scene.frames, !o.quiet);
  const auto t0 = Clock::now();
  try {
    for (int f = 0; f < scene.frames && octocd::stop_signal() == 0; ++f) {
      const octocd::FrameMetrics& m = world.step();
      totals.add(m);
      if (trace) trace->append_frame(m, world.state(), world.contacts());
      progress.update(m, totals);
    }
  } catch (const octocd::RuntimeError&) {
    if (trace) trace->close();  // keep every frame written so far readable
    throw;
  }
  if (trace) trace->close();
  const double wall_s = std::chrono::duration<double>(Clock::now() - t0).count();
  if (!o.quiet) print_summary(world, totals, wall_s, o.trace);
  if (!o.summary_json.empty()) write_summary_json(o.summary_json, world, totals, wall_s);
  if (const int sig = octocd::stop_signal()) {
    report_stop(sig, "run", totals.frames, scene.frames, o.trace);
    return octocd::stop_exit_code(sig);
  }
  return 0;
}

struct ValidateOptions {
  std::string scene;
  std::string engine = "cpu";
  std::vector<std::string> tolerances;
  std::string against = "bullet,fcl";
  int frames = 300;
  int every = 10;
  std::string trace;
};

/// `octocd validate`: exit 0 when every validator passes, 3 when any fails.
int validate_command(const ValidateOptions& o) {
  octocd::StopOnSignals stop_on_signals;  // SIGINT/SIGTERM: stop between frames, flush, 130/143
  octocd::Scene scene = octocd::load_scene(o.scene);
  octocd::ValidationOptions vo;
  vo.frames = o.frames;
  vo.every = o.every;
  vo.against_bullet = vo.against_fcl = false;
  std::string rest = o.against;
  while (!rest.empty()) {
    const auto comma = rest.find(',');
    const std::string item = rest.substr(0, comma);
    rest = comma == std::string::npos ? "" : rest.substr(comma + 1);
    if (item == "bullet") {
      vo.against_bullet = true;
    } else if (item == "fcl") {
      vo.against_fcl = true;
    } else if (item != "none" && !item.empty()) {
      throw octocd::InputError(fmt::format(
          "--against: unknown reference '{}'; allowed: a comma-separated list of bullet, fcl, or none",
          item));
    }
  }
  for (const std::string& item : o.tolerances) {
    const auto eq = item.find('=');
    std::string names;
    for (const auto& e : octocd::tolerance_table()) names += (names.empty() ? "" : ", ") + std::string(e.name);
    if (eq == std::string::npos || eq == 0)
      throw octocd::InputError(fmt::format("--tolerance: '{}' is not NAME=VALUE; allowed names: {}", item, names));
    const std::string name = item.substr(0, eq), text = item.substr(eq + 1);
    double value = 0.0;
    std::size_t used = 0;
    try {
      value = std::stod(text, &used);
    } catch (const std::exception&) {
      used = 0;
    }
    if (used == 0 || used != text.size())
      throw octocd::InputError(
          fmt::format("--tolerance: {}: '{}' is not a number; allowed: a finite number >= 0", name, text));
    octocd::set_tolerance(vo.tol, name, value);
    vo.overridden.push_back(name);
  }
  const std::shared_ptr<const octocd::Model> model = octocd::build_model(scene);
  if (o.engine == "bullet")
    throw octocd::InputError("--engine: bullet cannot be validated (no per-frame record); allowed: cpu, cuda");
  std::unique_ptr<octocd::TraceWriter> trace;
  std::int64_t done = 0;  // frames of the validated engine
  vo.stop = [] { return octocd::stop_signal() != 0; };
  vo.on_step = [&](const octocd::Engine& w) {
    ++done;
    if (!o.trace.empty()) {
      if (!trace) {
        octocd::TraceMetadata meta = octocd::trace_metadata(w, 10);
        meta.start_time = utc_now();
        trace = std::make_unique<octocd::TraceWriter>(o.trace, meta, octocd::trace_bodies(w),
                                                      octocd::TraceOptions{});
      }
      trace->append_frame(w.last_metrics(), w.state(), w.contacts());
    }
  };
  std::vector<octocd::ValidationResult> results;
  try {
    results = octocd::validate_engine([&] { return make_engine(o.engine, model); }, vo);
  } catch (const octocd::RuntimeError&) {
    if (trace) trace->close();
    throw;
  }
  if (trace) {
    trace->close();
    octocd::write_validation(o.trace, results);
  }
  fmt::print("validate {} (engine {}, {} frames, checks every {}, against: {})\n\n", scene.name, o.engine,
             o.frames, o.every, o.against);
  fmt::print("{}", octocd::format_results(results, vo.overridden));
  const bool all_pass = std::all_of(results.begin(), results.end(),
                                    [](const octocd::ValidationResult& r) { return r.pass || !r.applicable; });
  if (const int sig = octocd::stop_signal()) {
    fmt::print("\nSTOPPED: the table covers frames 1..{} of {}\n", done, o.frames);
    std::fflush(stdout);
    report_stop(sig, "validate", done, o.frames, o.trace);
    return octocd::stop_exit_code(sig);
  }
  fmt::print("\n{}\n", all_pass ? "all validators pass" : "VALIDATION FAILED");
  return all_pass ? 0 : 3;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{
      "octocd: GPU hierarchical Octree-AABB collision detection and response (CPU reference).\n"
      "Exit codes: 0 ok, 1 runtime failure, 2 bad input, 3 a validator failed, 130/143 stopped by\n"
      "SIGINT/SIGTERM (run and validate stop between frames and close the trace)."};
  app.set_version_flag("--version", std::string("octocd ") + octocd::build_id());
  app.require_subcommand(1);

  RunOptions run;
  CLI::App* run_cmd = app.add_subcommand("run", "Run a scene through the pipeline and print a summary");
  run_cmd->add_option("scene", run.scene, "Scene file (JSON, see docs/scenes.md)")->required();
  run_cmd->add_option("--engine", run.engine,
                      "cpu: octocd's CPU reference pipeline; bullet: the same scene in Bullet's "
                      "btDiscreteDynamicsWorld (translation-only boxes), same trace layout")
      ->check(CLI::IsMember({"cpu", "cuda", "bullet"}))
      ->default_val("cpu");
  std::string bp_help = "Broadphase, overrides the scene's broadphase.name: ";
  for (const auto& name : octocd::all_broadphase_names()) bp_help += name + " ";
  run_cmd->add_option("--broadphase", run.broadphase, bp_help);
  run_cmd->add_option("--midphase", run.midphase,
                      "Midphase levels, overrides the scene: aabb-only | 2 | 1,2 | 0,1,2 | any "
                      "ascending list of levels in [0, 10]");
  run_cmd->add_option("--frames", run.frames, "Number of steps, overrides the scene (>= 1)")
      ->check(CLI::PositiveNumber);
  run_cmd->add_option("--trace", run.trace, "Write an HDF5 trace (docs/trace-format.md)");
  run_cmd->add_option("--state-every", run.state_every,
                      "Record positions and velocities every K-th frame in the trace (>= 1)")
      ->check(CLI::PositiveNumber)
      ->default_val(10);
  run_cmd->add_flag("--contacts", run.contacts, "Record every contact (/contacts) in the trace");
  run_cmd->add_flag("--quiet", run.quiet, "No progress and no summary table");
  run_cmd->add_option("--summary-json", run.summary_json,
                      "Also write the summary (steps/s, stage ms, counts) as JSON to this file");

  ValidateOptions val;
  CLI::App* val_cmd = app.add_subcommand(
      "validate", "Run the validators of SPEC 7 on a scene; exit 0 all pass, 3 any fails, 2 bad input");
  val_cmd->add_option("scene", val.scene, "Scene file (JSON, see docs/scenes.md)")->required();
  val_cmd->add_option("--against", val.against,
                      "References: comma-separated bullet, fcl (Bullet/FCL broadphases, FCL "
                      "normals, Bullet dynamics), or none")
      ->default_val("bullet,fcl");
  val_cmd->add_option("--frames", val.frames, "Steps to run (>= 1)")
      ->check(CLI::PositiveNumber)
      ->default_val(300);
  val_cmd->add_option("--every", val.every,
                      "Check candidate sets, midphase and normals every K-th frame (>= 1)")
      ->check(CLI::PositiveNumber)
      ->default_val(10);
  val_cmd->add_option("--engine", val.engine,
                      "cpu: the CPU reference; cuda: the GPU engine (needs a CUDA build and device)")
      ->check(CLI::IsMember({"cpu", "cuda"}))
      ->default_val("cpu");
  {
    std::string names;
    for (const auto& e : octocd::tolerance_table())
      names += (names.empty() ? "" : ", ") + std::string(e.name) + " (" + e.unit + ")";
    val_cmd->add_option("--tolerance", val.tolerances,
                        "Override a validator bound, NAME=VALUE, repeatable; marked '*' in the table. "
                        "Names: " + names);
  }
  val_cmd->add_option("--trace", val.trace,
                      "Write the validated run as a trace with the results under /validation");

  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    const int rc = app.exit(e);
    return rc == 0 ? 0 : 2;
  }

  try {
    if (*run_cmd) return run_command(run);
    if (*val_cmd) return validate_command(val);
  } catch (const octocd::InputError& e) {
    std::fprintf(stderr, "octocd: error: %s\n", e.what());
    return 2;
  } catch (const octocd::RuntimeError& e) {
    std::fprintf(stderr, "octocd: runtime failure: %s\n", e.what());
    return 1;
  } catch (const std::bad_alloc&) {
    std::fprintf(stderr, "octocd: runtime failure: out of memory (the scene needs more than this "
                         "process may allocate)\n");
    return 1;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "octocd: runtime failure: %s\n", e.what());
    return 1;
  }
  return 0;
}
