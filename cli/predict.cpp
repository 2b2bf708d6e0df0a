// Determinism of an engine's run (`octocd validate --determinism`) and the recorded runs of
// the divergence sweep (cli/predict.hpp, docs/predictability.md).
#include "predict.hpp"


#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <limits>
#include <thread>
#include <tuple>

#include <fmt/format.h>

#include "octocd/engine_registry.hpp"
#include "octocd/error.hpp"
#include "octocd/process_engines.hpp"
#include "octocd/run_session.hpp"
#include "octocd/trace.hpp"
#include "octocd/trace_reader.hpp"
#include "tools.hpp"

namespace octocd::cli {

namespace {

using Clock = std::chrono::steady_clock;

/// Temporary trace files, removed when it goes out of scope (also on an exception).
class TemporaryTraces {
 public:
  TemporaryTraces() = default;
  TemporaryTraces(const TemporaryTraces&) = delete;
  TemporaryTraces& operator=(const TemporaryTraces&) = delete;
  ~TemporaryTraces() {
    for (const std::string& p : paths_) {
      if (RunSession* session = RunSession::current()) session->forget_temporary(p);
      std::error_code ec;
      std::filesystem::remove(p, ec);
    }
  }
  /// A new empty file (temporary_trace) named after `what`; the run session (if any)
  /// removes it should the process end at once.
  const std::string& make(const std::string& what) {
    paths_.push_back(temporary_trace(what));
    if (RunSession* session = RunSession::current()) session->add_temporary(paths_.back());
    return paths_.back();
  }

 private:
  std::vector<std::string> paths_;
};


/// The unit of `compare`'s quantity (its --tolerance help).
const char* quantity_unit(const std::string& q) {
  if (q == "positions") return "m";
  if (q == "velocities") return "m/s";
  if (q == "orientations") return "rad";
  if (q == "angular_velocities") return "rad/s";
  if (q == "energy") return "J";
  if (q == "pairs") return "pairs";
  return "contact field";
}

/// A row from `compare`'s outcome of traces `a_what` against `b_what`.
ValidationResult comparison_row(const std::string& name, const std::string& a_what, const std::string& b_what,
                                const CompareOutcome& c, int frames, double seconds) {
  ValidationResult r;
  r.tier = Tier::Physics;
  r.name = name;
  r.figure = "|A-B| at the first difference";
  r.bound = 0.0;
  r.judged = static_cast<std::uint64_t>(frames);
  r.seconds = seconds;
  r.pass = c.same;
  if (c.same) {
    std::string compared;
    for (const nlohmann::json& q : c.doc.value("quantities", nlohmann::json::array()))
      if (q.value("available", false)) compared += (compared.empty() ? "" : ", ") + q.value("quantity", std::string());
    r.detail = fmt::format("{} and {}: bit for bit over {} frames ({})", a_what, b_what, frames, compared);
    return r;
  }
  ValidationCause cause;
  cause.name = "differs";
  cause.count = 1;
  ValidationExample ex;
  if (c.first_frame >= 0) {
    r.measured = c.first_size;
    cause.unit = quantity_unit(c.first_quantity);
    cause.worst = c.first_size;
    ex.frame = c.first_frame;
    ex.item = c.first_body >= 0 ? fmt::format("body {}", c.first_body) : "";
    ex.figure = c.first_size;
    r.detail = fmt::format("{} and {} differ: first at frame {}{}, {}, |A-B| = {:.6g} {} ({})", a_what, b_what,
                           c.first_frame, c.first_body >= 0 ? fmt::format(", body {}", c.first_body) : "",
                           c.first_quantity, c.first_size, cause.unit, c.first_detail);
  } else {
    r.measured = std::numeric_limits<double>::infinity();
    cause.unit = "structure";
    cause.worst = r.measured;
    r.detail = fmt::format("{} and {} differ in structure: {}", a_what, b_what,
                           c.structure.empty() ? std::string("?") : c.structure.front());
  }
  if (!c.structure.empty() && c.first_frame >= 0) r.detail += fmt::format("; structure: {}", c.structure.front());
  ex.text = r.detail;
  cause.examples.push_back(ex);
  if (!ex.item.empty()) cause.items.push_back(ex.item);
  r.causes.push_back(cause);
  return r;
}

/// A row that does not apply, with the reason.
ValidationResult not_applicable(const std::string& name, const std::string& why) {
  ValidationResult r;
  r.tier = Tier::Physics;
  r.name = name;
  r.figure = "|A-B| at the first difference";
  r.applicable = false;
  r.detail = why;
  return r;
}

}  // namespace

bool record_trace(const std::string& engine, const std::shared_ptr<const Model>& model,
                  const EngineSettingItems& settings, int frames, const std::string& path,
                  const std::function<bool()>& stop) {
  const std::unique_ptr<Engine> made = make_engine(engine, model, settings);
  Engine& world = *made;
  if (world.writes_own_trace()) {  // a process engine: its process runs every frame at once
    world.plan_steps(frames);
    world.step();
    copy_own_trace(world, path, "the recorded run");
    return true;
  }
  TraceOptions topt;
  topt.state_every = 1;
  topt.contacts = world.can_record();
  if (topt.contacts) world.set_recording(true);
  if (const RotationTraits* traits = world.rotation_traits()) {
    topt.v2 = *traits;
    topt.gravity = model->scene.gravity;
  }
  TraceWriter trace(path, trace_metadata(world, 1), trace_bodies(world), topt);
  trace.append_state(0, world.state());
  const TraceFeed feed = TraceFeed::of(world, topt.contacts);
  feed.start(trace, world, frames);
  for (int f = 0; f < frames; ++f) {
    if (stop && stop()) {
      trace.close();
      return false;
    }
    const FrameMetrics& m = world.step();
    feed.append(trace, world, m, frames - (f + 1));
  }
  trace.close();
  return true;
}

std::vector<std::vector<Vec3>> run_positions(const std::string& engine, const std::shared_ptr<const Model>& model,
                                             const EngineSettingItems& settings, int frames) {
  std::vector<std::vector<Vec3>> out;
  const std::unique_ptr<Engine> made = make_engine(engine, model, settings);
  Engine& world = *made;
  if (!world.writes_own_trace()) {
    out.reserve(static_cast<std::size_t>(frames) + 1);
    out.push_back(world.state().x);
    world.plan_steps(frames);
    for (int f = 0; f < frames; ++f) {
      world.step();
      out.push_back(world.state().x);
    }
    return out;
  }
  world.plan_steps(frames);
  world.step();
  TemporaryTraces tmp;
  const std::string& path = tmp.make("divergence-" + engine);
  copy_own_trace(world, path, "the divergence run");
  const TraceReader t(path);
  const std::vector<std::uint64_t> shape = t.shape("/states/position");
  const std::size_t n = model->initial.size();
  if (shape.size() != 3 || shape[1] != n || shape[2] != 3 || shape[0] < static_cast<std::uint64_t>(frames) + 1)
    throw RuntimeError(fmt::format("engine {}: its trace's /states/position has shape {}; needed: {} states x {} "
                                   "bodies x 3 (every frame and the initial state)",
                                   engine, fmt::join(shape, " x "), frames + 1, n));
  for (int r = 0; r <= frames; ++r) {
    const std::vector<float> v = t.read_f32_rows("/states/position", r, 1);
    std::vector<Vec3> x(n);
    for (std::size_t i = 0; i < n; ++i) x[i] = Vec3{v[3 * i], v[3 * i + 1], v[3 * i + 2]};
    out.push_back(std::move(x));
  }
  return out;
}

std::vector<ValidationResult> determinism_rows(const DeterminismOptions& o) {
  const EngineInfo& info = engine_info(o.engine, "--engine");
  const int threads = o.threads > 0 ? o.threads : std::max(2, static_cast<int>(std::thread::hardware_concurrency()));
  TemporaryTraces tmp;
  // One run into a temporary trace (at `n` threads through the engine's thread setting,
  // 0: as the caller's settings say), its wall seconds.
  const auto run = [&](const std::string& engine, int n, const std::string& what) {
    const std::string& path = tmp.make("determinism-" + engine + "-" + what);
    const auto t0 = Clock::now();
    EngineSettingItems settings = o.settings;
    const std::string& key = engine_info(engine, "--engine").threads_setting;
    if (n > 0 && !key.empty()) settings[engine].push_back(fmt::format("{}={}", key, n));
    const bool whole = record_trace(engine, o.model, settings, o.frames, path, o.stop);
    return std::make_tuple(path, std::chrono::duration<double>(Clock::now() - t0).count(), whole);
  };
  const auto compare = [](const std::string& a, const std::string& b) {
    CompareOptions c;
    c.a = a;
    c.b = b;
    const CompareOutcome out = compare_traces(c);
    if (!out.nothing_compared.empty()) throw RuntimeError(out.nothing_compared);
    return out;
  };
  std::vector<ValidationResult> rows;
  // What a process that ends inside a run (a process engine's, stop.hpp) keeps: the rows
  // finished so far are counted, not written (the caller writes them on its own stop path).
  const auto finished = [&rows] {
    if (RunSession* session = RunSession::current())
      session->keep(fmt::format("{} of 3 determinism rows had finished; none written (the stop came inside a run)",
                                rows.size()));
  };
  finished();
  const bool threaded = !info.threads_setting.empty();
  const int n = threaded ? threads : 0;
  const std::string at_n = threaded ? fmt::format(" at {} threads", threads) : "";
  const auto [first, s1, whole1] = run(o.engine, n, "1");
  if (!whole1) return rows;
  const auto [second, s2, whole2] = run(o.engine, n, "2");
  if (!whole2) return rows;
  rows.push_back(comparison_row("determinism-runs", "run 1" + at_n, "run 2" + at_n, compare(first, second), o.frames,
                                s1 + s2));
  finished();
  if (threaded) {
    const auto [serial, s3, whole3] = run(o.engine, 1, "serial");
    if (!whole3) return rows;
    rows.push_back(comparison_row("determinism-threads", fmt::format("run 1 at {} threads", threads), "a run at 1 thread",
                                  compare(first, serial), o.frames, s3));
    finished();
  } else {
    rows.push_back(not_applicable(
        "determinism-threads",
        info.device ? fmt::format("{} steps on the GPU; no host thread count to vary", o.engine)
        : !info.command.empty()
            ? fmt::format("{} is a process engine (its own program); octocd sets no thread count for it", o.engine)
            : fmt::format("{} steps on one host thread (no thread setting); no thread count to vary", o.engine)));
  }
  if (!info.device_twin.empty()) {
    const std::string& other = info.device_twin;
    const EngineInfo& oi = engine_info(other, "--engine");
    const std::string why = engine_built(oi) ? engine_unavailable(oi) : std::string("not built in this octocd");
    if (!why.empty()) {
      rows.push_back(not_applicable("determinism-cpu-cuda", fmt::format("skipped: {} cannot run here ({})", other, why)));
    } else {
      const auto [theirs, s4, whole4] = run(other, oi.threads_setting.empty() ? 0 : threads, "other");
      if (!whole4) return rows;
      rows.push_back(comparison_row("determinism-cpu-cuda", o.engine, other, compare(first, theirs), o.frames, s4));
    }
  } else {
    rows.push_back(not_applicable("determinism-cpu-cuda",
                                  fmt::format("{} has no twin on another kind of processor (EngineInfo::device_twin: "
                                              "octocd's cpu and cuda run one pipeline on both)",
                                              o.engine)));
  }
  return rows;
}

}  // namespace octocd::cli
