// A process engine through the Engine interface (process_engines.hpp: make_process_engine):
// the request written, the command run bounded, its trace checked by the hardened reader
// and replayed frame by frame.
#include <stdlib.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>
#include <memory>
#include <optional>

#include <fmt/format.h>

#include "child_process.hpp"
#include "octocd/atomic_file.hpp"
#include "octocd/error.hpp"
#include "octocd/external_trace.hpp"
#include "octocd/process_engines.hpp"
#include "octocd/run_session.hpp"
#include "octocd/timing_limits.hpp"
#include "octocd/text.hpp"
#include "octocd/trace_reader.hpp"

namespace octocd {

namespace fs = std::filesystem;

namespace {

/// Whether `v` is a finite, non-negative number.
bool finite_non_negative(double v) { return std::isfinite(v) && v >= 0.0; }

class ProcessEngine final : public Engine {
 public:
  ProcessEngine(ProcessEngineSpec spec, std::shared_ptr<const Model> model, std::vector<std::string> items)
      : spec_(std::move(spec)), model_(std::move(model)), items_(std::move(items)) {
    state_ = model_->initial;
    const std::size_t n = state_.size();
    if (spec_.info.rotates) {
      state_.q.resize(n);      // identity where the model has none
      state_.omega.resize(n);  // zero where the model has none
    }
  }

  ~ProcessEngine() override { remove_folder(); }

  std::string name() const override { return spec_.info.name; }
  std::string device() const override {
    std::string cmd;
    for (const std::string& a : spec_.command) cmd += (cmd.empty() ? "" : " ") + fs::path(a).filename().string();
    return fmt::format("a process ({})", cmd);
  }
  std::string broadphase_name() const override { return spec_.info.own_broadphase; }
  const Model& model() const override { return *model_; }
  std::string midphase_name() const override { return "its own narrow phase"; }

  const FrameMetrics& step() override {
    if (!trace_) run();
    if (frame_ >= frames_)
      throw RuntimeError(fmt::format("engine '{}': its process ran {} frames (the request's); a step beyond them was "
                                     "asked; allowed: at most {} steps (plan_steps before the first step, or the "
                                     "scene's frames)",
                                     spec_.info.name, frames_, frames_));
    ++frame_;
    try {
      record_ = trace_->frame(frame_);
    } catch (const std::exception& e) {
      throw RuntimeError(fmt::format("engine '{}' wrote a trace the hardened reader refuses: {}", spec_.info.name,
                                     e.what()));
    }
    state_.x = record_.x_post;
    state_.v = record_.v_post;
    if (!record_.q_post.empty()) state_.q = record_.q_post;
    if (!record_.w_post.empty()) state_.omega = record_.w_post;
    fill_metrics();
    return metrics_;
  }

  void plan_steps(std::int64_t steps) override {
    if (!trace_ && steps > 0) planned_ = steps;
  }
  const BodyState& state() const override { return state_; }
  const FrameMetrics& last_metrics() const override { return metrics_; }
  std::int64_t frame() const override { return frame_; }
  const std::vector<ContactRecord>& contacts() const override { return record_.contacts; }
  std::string collision_geometry() const override {
    return fmt::format("engine {}'s own shapes (a process engine: its trace's /bodies/collision_shape and "
                       "declarations say which)",
                       spec_.info.name);
  }
  std::string notes() const override {
    return fmt::format("a process engine ({}): steps/s from its trace's wall_step_seconds ({:.3f} s in its step calls "
                       "for {} frames); no stage times; the counts are its trace's rows",
                       spec_.file, wall_step_seconds_, frames_);
  }
  bool can_record() const override { return true; }
  void set_recording(bool on) override { (void)on; }  // every frame of its trace is read
  const FrameRecord& record() const override { return record_; }
  bool has_stage(Stage s) const override {
    (void)s;
    return false;
  }
  bool writes_own_trace() const override { return true; }
  std::string own_trace() const override { return trace_ ? trace_path_ : std::string(); }

  /// Stops the process run by a step in flight (any thread; see cancel_process_engine_step).
  void cancel() { cancel_.store(true); }

  /// The run's progress goes to `report` (set_process_progress).
  void set_progress(std::function<void(const ProcessProgress&)> report) { progress_ = std::move(report); }

 private:
  void remove_folder() {
    if (folder_.empty()) return;
    // Removed, then forgotten: a process ended meanwhile by another thread (another copy of
    // `run --worlds` stopped) still removes it.
    std::error_code ec;
    fs::remove_all(folder_, ec);
    if (RunSession* session = RunSession::current()) session->forget_temporary(folder_);
    folder_.clear();
  }

  std::string request_path() const { return (fs::path(folder_) / "request.json").string(); }

  [[noreturn]] void fail(const std::string& what, const process_detail::ChildOutcome* o = nullptr) {
    const std::string tail = o ? process_detail::output_tail(*o) : std::string();
    trace_.reset();
    remove_folder();
    throw RuntimeError(fmt::format("engine '{}' ({}) {}{}", spec_.info.name, spec_.file, what, tail));
  }

  /// Runs the process for frames_ steps and opens its trace.
  void run() {
    // A missing runtime (its program, a file of its command, its check) is said as such.
    if (const std::string why = process_engine_unavailable(spec_); !why.empty())
      throw RuntimeError(fmt::format("engine '{}' ({}) is unavailable here: {}", spec_.info.name, spec_.file, why));
    frames_ = planned_ > 0 ? planned_ : model_->scene.frames;
    const char* tmp = std::getenv("TMPDIR");
    std::string templ = (fs::path(tmp && *tmp ? tmp : "/tmp") / ("octocd-" + spec_.info.name + "-XXXXXX")).string();
    if (::mkdtemp(templ.data()) == nullptr)
      throw RuntimeError(fmt::format("engine '{}': cannot create its temporary folder {}: {}", spec_.info.name, templ,
                                     std::strerror(errno)));
    folder_ = templ;
    const std::string request = request_path();
    trace_path_ = (fs::path(folder_) / "trace.h5").string();
    // A command's stop or failure (its run session) removes it and its files too.
    if (RunSession* session = RunSession::current()) session->add_temporary(folder_);
    {
      std::ofstream out(request, std::ios::binary);
      out << process_request(spec_, *model_, frames_, trace_path_, items_).dump(1) << "\n";
      out.close();
      if (!out) fail(fmt::format("could not be given its request: writing {} failed", request));
    }
    process_detail::ChildRun run;
    run.argv = spec_.command;
    run.argv[0] = process_detail::find_on_path(spec_.command[0]);
    if (run.argv[0].empty())
      fail(fmt::format("could not be started: '{}' is not found on PATH", printable(spec_.command[0])));
    run.argv.push_back(request);
    run.cwd = folder_;
    run.timeout_s = spec_.timeout_s;
    run.watched = trace_path_;
    run.watched_max = spec_.max_trace_bytes;
    run.cancel = &cancel_;
    if (progress_) run.on_poll = progress_reader();
    const process_detail::ChildOutcome o = process_detail::run_child(run);
    cancel_.store(false);
    using End = process_detail::ChildOutcome::End;
    if (o.end == End::Stopped) {
      // Nothing of the run was read yet: its temporary files go. Stopped by a signal, octocd
      // ends as a stopped command through its run session (stop.hpp: StopAtOnce's rule for
      // work with nothing to flush); cancelled by the caller (Python's Ctrl-C), the step
      // fails and octocd goes on.
      remove_folder();
      RunSession* session = RunSession::current();
      if (o.stop_signal != 0 && session)
        session->end_now(o.stop_signal, fmt::format(" while engine '{}' ran (its process tree stopped: SIGTERM, then "
                                                    "SIGKILL); no frame of it was read",
                                                    printable(spec_.info.name)));  // says what the command keeps
      throw RuntimeError(fmt::format("engine '{}' ({}) {}; no frame of it was read", printable(spec_.info.name),
                                     spec_.file, process_detail::describe(o)));
    }
    if (o.end == End::Oversize)
      fail(fmt::format("wrote a trace beyond its max_trace_bytes {} and was stopped after {:.2f} s",
                       spec_.max_trace_bytes, o.seconds),
           &o);
    if (o.end != End::Exited || o.code != 0) fail(process_detail::describe(o), &o);
    std::error_code ec;
    if (!fs::is_regular_file(trace_path_, ec))
      fail(fmt::format("exited with code 0 after {:.2f} s but wrote no trace at the request's `trace` ({})", o.seconds,
                       trace_path_),
           &o);
    if (fs::file_size(trace_path_, ec) > spec_.max_trace_bytes)
      fail(fmt::format("wrote a trace beyond its max_trace_bytes {} ({} bytes) in {:.2f} s", spec_.max_trace_bytes,
                       fs::file_size(trace_path_, ec), o.seconds),
           &o);
    ExternalTraceInfo info;
    try {
      info = check_external_trace(trace_path_);
      const TraceReader reader(trace_path_);
      if (!reader.has_attribute("wall_step_seconds"))
        throw InputError(fmt::format("{}: wall_step_seconds: missing; allowed: a float64 root attribute, the wall "
                                     "time (s) spent in the engine's step calls",
                                     trace_path_));
      wall_step_seconds_ = reader.number_attribute("wall_step_seconds");
    } catch (const std::exception& e) {
      fail(fmt::format("exited with code 0 after {:.2f} s but wrote a trace the hardened reader refuses: {}", o.seconds,
                       e.what()),
           &o);
    }
    // Its steps/s (frames over it) must be a figure a bench result can hold: a value outside
    // that is bad input from the engine (exit 2), never a run or a result another command refuses.
    const double steps_per_s = static_cast<double>(frames_) / wall_step_seconds_;
    if (!finite_non_negative(wall_step_seconds_) ||
        (frames_ > 0 && !(std::isfinite(steps_per_s) && steps_per_s <= limits::kMaxTiming))) {
      const std::string given = fmt::format("{:g}", wall_step_seconds_);
      trace_.reset();
      remove_folder();
      throw EngineValueError(fmt::format(
          "engine '{}' ({}) gave wall_step_seconds = {} (its trace's root attribute; {} frames over it: {} steps/s); "
          "allowed: a finite number of seconds > 0 whose {} frames over it are at most {:g} steps/s (0 only for a run "
          "of no frames)",
          printable(spec_.info.name), spec_.file, given, frames_,
          std::isnan(steps_per_s) ? std::string("not a number") : fmt::format("{:g}", steps_per_s), frames_,
          limits::kMaxTiming));
    }
    if (info.version != 2 || !info.has_states)
      fail(fmt::format("wrote a version {} trace{}; allowed: a version 2 trace with every state (docs/trace-format.md)",
                       info.version, info.has_states ? "" : " without /states"));
    if (info.bodies != model_->bodies.size())
      fail(fmt::format("wrote a trace of {} bodies; the request has {} (walls first, then each group's bodies)",
                       info.bodies, model_->bodies.size()));
    if (info.frames != frames_)
      fail(fmt::format("wrote a trace of {} frames; the request asked for {} (states 0..{})", info.frames, frames_,
                       frames_));
    try {
      trace_ = std::make_unique<ExternalTrace>(trace_path_);
    } catch (const std::exception& e) {
      fail(fmt::format("wrote a trace the hardened reader refuses: {}", e.what()));
    }
  }

  /// Reads the process's stdout lines `octocd-progress N` (docs/bring-your-engine.md,
  /// "Progress") into progress_ calls: at each such line, else once a second.
  std::function<void(const std::vector<std::string>&)> progress_reader() {
    const auto t0 = std::chrono::steady_clock::now();
    auto p = std::make_shared<ProcessProgress>();
    p->frames = frames_;
    auto said_s = std::make_shared<double>(0.0);
    return [this, t0, p, said_s](const std::vector<std::string>& lines) {
      p->seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
      bool news = false;
      for (const std::string& line : lines) {
        std::int64_t n = -1;
        if (!process_detail::progress_line(line, &n) || n > p->frames) continue;
        if (p->started_s < 0.0) p->started_s = p->seconds;
        p->stepped = std::max<std::int64_t>(p->stepped, n);
        news = true;
      }
      if (!news && p->seconds - *said_s < 1.0) return;
      *said_s = p->seconds;
      progress_(*p);
    };
  }

  void fill_metrics() {
    FrameMetrics m;
    m.frame = frame_;
    m.time = static_cast<double>(frame_) * model_->scene.dt;
    m.step_ms = frames_ > 0 ? 1000.0 * wall_step_seconds_ / static_cast<double>(frames_) : 0.0;
    m.contacts = record_.contacts.size();
    if (record_.has_pairs) m.aabb_pairs = m.dynamic_pairs = m.cell_candidates = record_.pairs.size();
    double depth_sum = 0.0;
    for (const ContactRecord& c : record_.contacts) {
      depth_sum += c.depth;
      m.penetration_max = std::max(m.penetration_max, static_cast<double>(c.depth));
      if (c.depth > model_->scene.response.slop) m.penetration_share_above_slop += 1.0;
    }
    if (!record_.contacts.empty()) {
      m.penetration_mean = depth_sum / static_cast<double>(record_.contacts.size());
      m.penetration_share_above_slop /= static_cast<double>(record_.contacts.size());
    }
    for (std::size_t i = 0; i < state_.size(); ++i) {
      const float w = state_.w[i];
      if (!(w > 0.0f)) continue;
      const double mass = 1.0 / static_cast<double>(w);
      const Vec3& v = state_.v[i];
      m.kinetic_energy += 0.5 * mass * (double(v.x) * v.x + double(v.y) * v.y + double(v.z) * v.z);
      m.momentum[0] += mass * v.x;
      m.momentum[1] += mass * v.y;
      m.momentum[2] += mass * v.z;
    }
    metrics_ = m;
  }

  ProcessEngineSpec spec_;
  std::shared_ptr<const Model> model_;
  std::vector<std::string> items_;
  std::int64_t planned_ = 0, frames_ = 0, frame_ = 0;
  std::string folder_, trace_path_;
  std::unique_ptr<ExternalTrace> trace_;
  double wall_step_seconds_ = 0.0;
  std::atomic<bool> cancel_{false};  ///< set by cancel(), cleared when the run it stopped returns
  std::function<void(const ProcessProgress&)> progress_;  ///< set_progress's; empty: none
  BodyState state_;
  FrameRecord record_;
  FrameMetrics metrics_;
};

}  // namespace

void copy_own_trace(const Engine& engine, const std::string& path, const std::string& label) {
  const std::string from = engine.own_trace();
  if (from.empty())
    throw RuntimeError(fmt::format("{}: engine '{}' has written no trace of its own", label, engine.name()));
  TemporaryFile tmp = create_temporary_beside(path, label);
  const TrackedTemporary tracked(tmp.path);  // until it is renamed, a stop removes it too
  ::close(tmp.fd);
  std::error_code ec;
  fs::copy_file(from, tmp.path, fs::copy_options::overwrite_existing, ec);
  if (ec) {
    fs::remove(tmp.path, ec);
    throw RuntimeError(fmt::format("{}: {}: copying engine '{}''s trace failed: {}", label, path, engine.name(),
                                   ec.message()));
  }
  rename_over(tmp.path, path, label);
}

bool cancel_process_engine_step(Engine& engine) {
  auto* p = dynamic_cast<ProcessEngine*>(&engine);
  if (p == nullptr) return false;
  p->cancel();
  return true;
}

bool set_process_progress(Engine& engine, std::function<void(const ProcessProgress&)> report) {
  auto* p = dynamic_cast<ProcessEngine*>(&engine);
  if (p == nullptr) return false;
  p->set_progress(std::move(report));
  return true;
}

std::unique_ptr<Engine> make_process_engine(const ProcessEngineSpec& spec, const std::shared_ptr<const Model>& model,
                                            const std::vector<std::string>& items, const std::string& where) {
  check_process_settings(spec, items, where);
  return std::make_unique<ProcessEngine>(spec, model, items);
}

}  // namespace octocd
