#pragma once
/// \file py_engine.hpp
/// octocd.Scene and octocd.Engine's compiled half: scenes, the engines this build has, engines
/// files, and an engine stepped with the GIL released (docs/python.md).

#include "octocd/names.hpp"
#include "py_arrays.hpp"

namespace octocd::python_binding {

// ---- scenes and engines --------------------------------------------------------------

/// A loaded scene (shared: several engines can be built from one).
struct PyScene {
  std::shared_ptr<const Scene> scene;
};

/// The engines this build has (octocd.engines), in engine_infos() order: read on each call,
/// so that an engines file loaded after import (octocd.load_engines_file) is listed.
inline std::vector<std::string> built_engines() { return built_engine_names(); }

/// octocd.load_engines_file: names the process's engines file (octocd/process_engines.hpp,
/// set_engines_file) and reads the registry at once, so that a malformed file is an
/// InputError here ("FILE: FIELD: PROBLEM; allowed: ...") and its engines are listed by
/// octocd.engines. Throws RuntimeError when the registry was read already with another
/// file (one engines file per process), InputError for a path that is not a file.
inline std::vector<std::string> load_engines_file(const std::string& path) {
  if (path.empty()) throw InputError("path: ''; allowed: the path of an engines file (docs/bring-your-engine.md)");
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec))
    throw InputError(fmt::format("{}: not a readable file; allowed: an engines file (JSON, docs/bring-your-engine.md)",
                                 path));
  const std::string file = std::filesystem::absolute(path, ec).lexically_normal().string();
  try {
    set_engines_file(file);
  } catch (const RuntimeError&) {
    const std::vector<std::string> read = engines_files_read();
    throw RuntimeError(fmt::format("octocd.load_engines_file('{}'): the engine registry was read already (engines "
                                   "files: {}); allowed: one engines file per process, loaded before the first "
                                   "engine is looked up (octocd.engines, octocd.Engine)",
                                   path, read.empty() ? std::string("none") : join_names(read)));
  }
  return built_engine_names();
}


class PyEngine {
 public:
  PyEngine(const PyScene& scene, const std::string& engine, const std::optional<std::string>& broadphase,
           const std::optional<std::string>& midphase, bool record, const EngineSettingItems& settings) {
    const EngineInfo* info = find_engine_info(engine);
    const std::vector<std::string> names = built_engines();
    if (info == nullptr)
      throw InputError(fmt::format("engine: unknown engine '{}'; allowed: {}", printable(engine), join_names(names)));
    if (!engine_built(*info))
      throw InputError(fmt::format("engine: '{}' is not built in this octocd (configured with OCTOCD_CUDA=OFF "
                                   "or without nvcc); allowed: {}",
                                   engine, join_names(names)));
    EngineOptions options;
    options.broadphase = broadphase.value_or("");
    options.midphase = midphase.value_or("");
    // Every engine's items are checked whatever the engine runs: a bad key is an input error.
    check_engine_settings(settings, python_argument_names());
    options.settings = settings;
    Scene sc = *scene.scene;
    apply_engine_options(sc, *info, options, python_argument_names());
    if (const std::string why = engine_unavailable(*info); !why.empty()) {
      std::vector<std::string> others;
      for (const std::string& n : names)
        if (n != engine) others.push_back("'" + n + "'");
      throw RuntimeError(fmt::format("engine '{}': {}; allowed: engine={} on this machine", engine, why,
                                     join_names(others, " or ")));
    }
    model_ = build_model(sc);
    engine_ = make_engine(engine, model_, options.settings);
    if (record && engine_->can_record()) engine_->set_recording(true);
    recording_ = record && engine_->can_record();
  }

  py::dict step(long n) {
    if (n < 0) throw InputError(fmt::format("n: {}; allowed: n >= 0 steps", n));
    BusyGuard busy(busy_, "this Engine");
    settle();
    // Nothing but step() and frame() runs between the steps below, so when they run inline
    // they are promised (Engine::plan_steps: the cuda engine's resident small step then runs
    // up to 64 a host round trip). A plan ends (end_plan) when a step turns slow (the next
    // ones may run on the helper thread), on an error or interrupt, and at the end.
    bool planned = false;
    auto end_plan = [&] {
      if (!planned) return;
      planned = false;
      engine_->plan_steps(0);
      py::gil_scoped_release release;
      while (engine_->steps_ahead() > 0) engine_->step();  // already run: no new work
      frames_.store(engine_->frame());
    };
    try {
      for (long i = 0; i < n; ++i) {
        if (!planned && !recording_ && n - i > 1 && last_step_ms_ < kInlineStepMs) {
          engine_->plan_steps(n - i);
          planned = true;
        }
        const auto t0 = std::chrono::steady_clock::now();
        if (planned || last_step_ms_ < kInlineStepMs) {
          py::gil_scoped_release release;
          engine_->step();
        } else {
          step_in_background();
        }
        last_step_ms_ = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
        frames_.store(engine_->frame());  // `frame`: the whole steps done, readable from another thread
        if (last_step_ms_ >= kInlineStepMs) end_plan();
        // Ctrl-C between steps: KeyboardInterrupt with the engine at its last whole step.
        if (PyErr_CheckSignals() != 0) throw py::error_already_set();
      }
    } catch (...) {
      end_plan();
      throw;
    }
    end_plan();
    return out_metrics(engine_->last_metrics(), engine_.get());
  }

  py::dict last_frame() {
    BusyGuard busy(busy_, "this Engine");
    settle();
    const Engine& e = *engine_;
    py::dict d;
    d["frame"] = e.frame();
    d["metrics"] = out_metrics(e.last_metrics(), &e);
    if (recording_ && e.frame() > 0) {
      const FrameRecord& r = e.record();
      d["x_pre"] = out_vec3(r.x_pre), d["v_pre"] = out_vec3(r.v_pre);
      d["x_post"] = out_vec3(r.x_post), d["v_post"] = out_vec3(r.v_post);
      d["aabbs"] = out_boxes(r.aabbs);
      d["pairs"] = r.has_pairs ? py::object(out_pairs(r.pairs)) : py::object(py::none());
      d["confirmed"] = out_pairs(r.confirmed);
      d["contacts"] = out_contacts(r.contacts, r.has_contact_terms, r.has_points);
      d["q_pre"] = out_quat_or_none(r.q_pre), d["q_post"] = out_quat_or_none(r.q_post);
      d["w_pre"] = out_vec3_or_none(r.w_pre), d["w_post"] = out_vec3_or_none(r.w_post);
      d["x_det"] = out_vec3_or_none(r.x_det), d["q_det"] = out_quat_or_none(r.q_det);
      d["manifolds"] = r.manifolds;
    } else {
      // Not recording (record=False, or `bullet`): the state after the step and the
      // engine's own contacts only.
      d["x_post"] = out_vec3(e.state().x), d["v_post"] = out_vec3(e.state().v);
      d["contacts"] = out_contacts(e.contacts(), !e.contacts().empty(), false);
    }
    return d;
  }

  py::array_t<float> positions() {
    BusyGuard busy(busy_, "this Engine");
    settle();
    return out_vec3(engine_->state().x);
  }
  py::array_t<float> velocities() {
    BusyGuard busy(busy_, "this Engine");
    settle();
    return out_vec3(engine_->state().v);
  }
  std::uint64_t state_hash() {
    BusyGuard busy(busy_, "this Engine");
    settle();
    return engine_->state_hash();
  }
  py::array_t<float> inverse_masses() const {
    const auto& w = engine_->state().w;
    py::array_t<float> a(static_cast<py::ssize_t>(w.size()));
    if (!w.empty()) std::memcpy(a.mutable_data(), w.data(), w.size() * sizeof(float));
    return a;
  }
  py::array_t<float> local_boxes() const {
    std::vector<Aabb> b;
    for (std::size_t i = 0; i < model_->bodies.size(); ++i) b.push_back(model_->local_box(i));
    return out_boxes(b);
  }
  py::list groups() const {
    py::list l;
    for (const BodyInfo& b : model_->bodies) l.append(b.group);
    return l;
  }

  void set_state(py::handle x, py::handle v) {
    const auto n = static_cast<py::ssize_t>(engine_->state().size());
    BodyState s = engine_->state();
    s.x = vec3s(x, "positions", n, "positions (m)");
    s.v = vec3s(v, "velocities", n, "velocities (m/s)");
    // The scene's limits (docs/scenes.md, "Limits"): the engines' float32 arithmetic
    // stays finite and keeps the slop within them.
    const auto bound = [](const std::vector<Vec3>& xs, const char* arg, double limit, const char* unit) {
      for (std::size_t i = 0; i < xs.size(); ++i)
        for (int k = 0; k < 3; ++k)
          if (!(std::fabs(xs[i][k]) <= limit))
            throw InputError(fmt::format("{}: row {} holds {}; allowed: |component| <= {:g} {} (docs/scenes.md, "
                                         "Limits)",
                                         arg, i, xs[i][k], limit, unit));
    };
    bound(s.x, "positions", limits::kMaxCoordinate, "m");
    bound(s.v, "velocities", limits::kMaxSpeed, "m/s");
    BusyGuard busy(busy_, "this Engine");
    settle();
    engine_->set_state(s);
  }

  const Engine& engine() const { return *engine_; }
  bool recording() const { return recording_; }
  /// Steps done (Engine::frame() after the last whole step); safe to read while another
  /// thread is inside step().
  std::int64_t frames() const { return frames_.load(); }

 private:
  /// A step is run on a helper thread, the caller polling Ctrl-C every 20 ms, unless the
  /// previous step took less than this (ms): the threshold keeps a small scene's steps
  /// free of a thread start (tens of microseconds) while a step of a large one (10^6
  /// bodies on the CPU: seconds) is cut short within a fraction of a second.
  static constexpr double kInlineStepMs = 50.0;

  /// One step on a helper thread; Ctrl-C raises KeyboardInterrupt at once and leaves the
  /// step to complete in the background (work_): the engine stays at a whole step.
  void step_in_background() {
    std::future<void> step = std::async(std::launch::async, [this] {
      engine_->step();
      frames_.store(engine_->frame());
    });
    work_.wait(step);
    step.get();  // the step's error, if any, raised here
  }
  /// Before any call that reads or changes the engine: a step an earlier Ctrl-C left
  /// completing in the background ends first (InterruptibleWork::settle).
  void settle() { work_.settle(); }

  std::shared_ptr<const Model> model_;
  std::unique_ptr<Engine> engine_;
  bool recording_ = false;
  std::atomic<bool> busy_{false};
  std::atomic<std::int64_t> frames_{0};
  double last_step_ms_ = std::numeric_limits<double>::infinity();  // the first step runs on the helper
  /// The steps run on a helper thread, one cut short by Ctrl-C completing there (declared
  /// after engine_: destroyed first, it waits for the step). A process engine's step is
  /// stopped by Ctrl-C (its process tree ended within 0.2 s; the step fails, settle()
  /// raises that): the caller's KeyboardInterrupt does not wait for the process's timeout_s.
  InterruptibleWork work_{[this] { (void)cancel_process_engine_step(*engine_); }};
};

}  // namespace octocd::python_binding
