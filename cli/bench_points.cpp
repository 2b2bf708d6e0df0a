// Running the points of `octocd bench` (bench_sweep.hpp): a steps point (its repetitions
// stepped on an engine, figures per window and series block, a trace with --trace-dir) and
// a broadphase point (recorded AABBs replayed through one broadphase of one engine).
#include <algorithm>
#include <cctype>
#include <cmath>
#include <ctime>
#include <filesystem>
#include <limits>
#include <memory>
#include <optional>

#include <fmt/format.h>

#include "bench_sweep.hpp"
#include "command_support.hpp"
#include "frame_sums.hpp"
#include "octocd/engine_registry.hpp"
#include "octocd/error.hpp"
#include "octocd/scene.hpp"
#include "octocd/run_session.hpp"
#include "octocd/trace.hpp"
#include "octocd/worlds.hpp"

namespace octocd::cli::bench {

namespace fs = std::filesystem;

namespace {

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

/// Removes the file at `path` (if any) when it goes; the run session (if any) removes it
/// should the process end at once.
struct RemovedAtEnd {
  explicit RemovedAtEnd(std::string p) : path(std::move(p)) {
    if (RunSession* session = RunSession::current(); session && !path.empty()) session->add_temporary(path);
  }
  ~RemovedAtEnd() {
    if (RunSession* session = RunSession::current(); session && !path.empty()) session->forget_temporary(path);
    std::error_code ec;
    if (!path.empty()) fs::remove(path, ec);
  }
  RemovedAtEnd(const RemovedAtEnd&) = delete;
  RemovedAtEnd& operator=(const RemovedAtEnd&) = delete;
  std::string path;
};

/// Sums over the frames of one window of one repetition.
struct WindowSums : FrameSums {
  std::int64_t bound_frames = 0;  // > 0: cut short; steps/s is then the bound bound_frames / step_ms
  double memory = 0;
  double pen_weighted = 0, share_weighted = 0, pen_max = 0;
  double cpu_ms = 0.0;  // process CPU time (every thread) spent in the step calls
  void add(const FrameMetrics& m) {
    FrameSums::add(m);
    const double c = static_cast<double>(m.contacts);
    memory += static_cast<double>(m.memory_bytes);
    pen_weighted += c * m.penetration_mean;
    share_weighted += c * m.penetration_share_above_slop;
    pen_max = std::max(pen_max, m.penetration_max);
  }
};

std::string file_safe(const std::string& id) {
  std::string out;
  for (char c : id) out += (std::isalnum(static_cast<unsigned char>(c)) || c == '.' || c == '-') ? c : '_';
  return out;
}

}  // namespace

std::shared_ptr<const Model> ModelCache::get(const std::string& t, const std::string& origin,
                                             const std::string& data_dir, std::size_t max_bodies) {
  for (auto it = entries.begin(); it != entries.end(); ++it)
    if (it->first == t) {
      auto e = std::move(*it);  // the most recent last
      entries.erase(it);
      entries.push_back(std::move(e));
      return entries.back().second;
    }
  if (entries.size() >= kRoundRobinGroup) entries.erase(entries.begin());
  entries.emplace_back(t, build_model(parse_scene(t, origin, data_dir, max_bodies)));
  return entries.back().second;
}

json run_steps_point(const Sweep& s, const Point& p, ModelCache& cache, const BenchOptions& o,
                     SweepProgress& progress, const StepsOverride& ov) {
  const auto t_call = Clock::now();  // a repetition dropped past max_time_s counts from here
  json r;
  json params{{"scene", stem(s.scenes[p.scene])}, {"engine", p.engine}};
  for (std::size_t a = 0; a < s.axes.size(); ++a) {
    params["axes"][s.axes[a].name] = s.axes[a].values[p.value[a]];
    if (!s.axes[a].labels[p.value[a]].empty()) params["labels"][s.axes[a].name] = s.axes[a].labels[p.value[a]];
  }
  if (p.traced != "off") params["traced"] = p.traced;
  if (s.worlds_given) params["worlds"] = p.worlds;
  r["params"] = params;
  std::vector<std::string> added;
  const std::string text = ov.text ? *ov.text : scene_text(s, p, &added);
  const int repeat = ov.repeat > 0 ? ov.repeat : s.repeat;
  const std::string origin = s.scenes[p.scene];
  std::shared_ptr<const Model> model;
  try {
    model = cache.get(text, origin, o.data_dir, ov.max_bodies);
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
  if (p.worlds > 1) {
    // Batched worlds (octocd/worlds.hpp): octocd's engines step the copies as one world.
    if (!engine_info(p.engine, "engines").batched_worlds) {
      r["status"] = "skipped";
      r["reason"] = fmt::format("worlds={}: engine {} steps one scene per run (batched worlds: {})",
                                p.worlds, p.engine,
                                engines_with([](const EngineInfo& e) { return e.batched_worlds; }));
      return r;
    }
    if (p.traced != "off") {
      r["status"] = "skipped";
      r["reason"] = fmt::format("worlds={}: a trace holds one scene (batched worlds are not traced)", p.worlds);
      return r;
    }
    WorldsSpec spec;
    spec.count = p.worlds;
    try {
      model = make_worlds_model(model, spec);
    } catch (const InputError& e) {
      r["status"] = "skipped";
      r["reason"] = std::string("worlds: ") + e.what();
      return r;
    }
  }
  r["bodies"] = model->initial.x.size();
  if (const auto cap = s.max_bodies.find(p.engine);
      cap != s.max_bodies.end() && static_cast<long>(model->initial.x.size()) > cap->second) {
    r["status"] = "skipped";
    r["reason"] = fmt::format("{} bodies, above max_bodies {} for {}: {}", model->initial.x.size(), cap->second,
                              p.engine, s.max_bodies_reason.at(p.engine));
    return r;
  }
  if (const EngineInfo& limited = octocd::engine_info(p.engine, "engines");
      limited.max_bodies > 0 && model->bodies.size() > limited.max_bodies) {
    r["status"] = "skipped";
    r["reason"] = fmt::format("{} bodies, above engine {}'s measured limit of {} bodies: {}", model->bodies.size(),
                              p.engine, limited.max_bodies, limited.max_bodies_reason);
    return r;
  }
  // Engines that step on the host: their steps per process CPU second are a figure too (the
  // gate's, on a shared machine). A device engine's CPU time would miss its kernels.
  // (Not a process engine: its steps run in another process, whose CPU time this one's is not.)
  const EngineInfo& stepping = octocd::engine_info(p.engine, "engines");
  const bool host_engine = !stepping.device && stepping.command.empty();
  // Each repetition's set-up: the engine built from the model (wall and, on the host, CPU s).
  std::vector<double> setup_s, setup_cpu_s;
  const auto build = [&] {
    const double cpu0 = host_engine ? process_cpu_ms() : 0.0;
    const auto t = Clock::now();
    std::unique_ptr<Engine> e = make_engine(p.engine, model, o.settings);
    setup_s.push_back(std::chrono::duration<double>(Clock::now() - t).count());
    if (host_engine) setup_cpu_s.push_back((process_cpu_ms() - cpu0) / 1000.0);
    return e;
  };
  progress.detail("set-up of the engine");
  std::unique_ptr<Engine> engine;
  try {
    engine = build();
  } catch (const std::exception& e) {
    r["status"] = "skipped";
    r["reason"] = e.what();
    return r;
  }
  // A first repetition's share of the budget counts its frames only (not building the model
  // or the engine: a set-up longer than the share would skip a point whose frames are quick;
  // the point's time, the later repetitions' budget, counts both).
  const auto t_budget = ov.abandon_over_time ? t_call : Clock::now();

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
  r["geometry"] = engine->collision_geometry();  // what the engine collided (design.md section 15)
  for (int st = 0; st < kStages; ++st)
    r["has_stage"][stage_name(static_cast<Stage>(st))] = engine->has_stage(static_cast<Stage>(st));

  // The windows as run: a budgeted repetition after the first runs the timed frames its
  // first was cut to (ov.timed_frames), and a cut shortens the only window.
  std::vector<Window> windows = s.windows;
  if (ov.timed_frames > 0 && s.cuttable) windows[0].last = windows[0].first + ov.timed_frames - 1;
  const int total = s.cuttable ? windows[0].last : s.frames;
  const bool budgeted = ov.time_limit_s > 0.0;
  // A budgeted cuttable repetition keeps its timed frames' figures, so a cut can sum the first n.
  std::vector<std::pair<FrameMetrics, double>> timed_frames;  // (metrics, CPU ms) per timed frame
  double stepped_ms = 0.0;  // wall ms of every step call so far (the warm-up's too): a skipped point's estimate
  std::vector<std::vector<WindowSums>> sums(windows.size());  // [window][rep]
  const int buckets = s.series_every > 0 ? (total + s.series_every - 1) / s.series_every : 0;
  std::vector<std::vector<WindowSums>> series(static_cast<std::size_t>(buckets));  // [bucket][rep]
  std::vector<double> energy_series(static_cast<std::size_t>(buckets), 0.0);
  std::vector<double> wall;
  int cut = 0;
  // A traced point writes every repetition's trace (a temporary file in $TMPDIR, removed
  // with the point) unless --trace-dir keeps its first.
  const bool traced = p.traced != "off";
  const RemovedAtEnd scratch{traced ? temporary_trace("bench") : std::string()};
  for (int rep = 0; rep < repeat; ++rep) {
    if (rep > 0) {
      engine.reset();  // the last repetition's device memory back first: the memory check sees one engine
      progress.detail(fmt::format("rep {}/{} set-up of the engine", rep + 1, repeat));
      engine = build();
    }
    std::unique_ptr<TraceWriter> trace;
    const bool kept = rep == 0 && ov.trace && !o.trace_dir.empty();
    TraceFeed feed{false, true};  // an untraced point's kept trace: version 1, states only
    if (kept || traced) {
      std::string path = scratch.path;
      if (kept) {
        fs::create_directories(o.trace_dir);
        path = (fs::path(o.trace_dir) / (file_safe(p.id) + ".h5")).string();
        r["trace"] = path;
      }
      TraceMetadata meta = trace_metadata(*engine, 10);
      meta.start_time = utc_time_now();
      TraceOptions topt;
      topt.state_every = 10;
      topt.flush_interval_s = kTraceFlushIntervalS;
      topt.contacts = p.traced == "contacts" && engine->can_record();
      if (topt.contacts) engine->set_recording(true);
      if (const RotationTraits* rt = engine->rotation_traits(); rt && traced) {  // as `run --trace` writes it
        topt.v2 = *rt;
        topt.gravity = model->scene.gravity;
      }
      if (traced) feed = TraceFeed::of(*engine, topt.contacts);
      trace = std::make_unique<TraceWriter>(path, meta, trace_bodies(*engine), topt);
      trace->append_state(0, engine->state());
    }
    for (auto& w : sums) w.emplace_back();
    for (auto& b : series) b.emplace_back();
    if (!trace) engine->plan_steps(total);  // nothing but the metrics is read between the steps
    else feed.start(*trace, *engine, total);
    // A process engine runs every frame in its first step: its start-up and steps as its
    // process says them (set_process_progress, the progress lines run and validate read).
    if (engine->writes_own_trace()) {
      auto said = std::make_shared<ProcessProgressLines>(printable(engine->name()), false);
      set_process_progress(*engine, [&progress, said](const ProcessProgress& pp) {
        progress.detail(pp.stepped < 0 ? fmt::format("its process is starting ({:.0f} s)", pp.seconds)
                                       : fmt::format("its process: frame {}/{}", pp.stepped, pp.frames));
        for (const std::string& line : said->next(pp)) progress.note(line);
      });
    }
    FrameMetrics timed;  // a traced point's frame: the step's metrics with the whole frame's time
    const auto t0 = Clock::now();
    for (int f = 1; f <= total; ++f) {
      if (octocd::stop_signal() != 0) {
        if (trace) trace->close();
        throw BenchStopped{};
      }
      // A step of a big scene may take seconds: a signal it does not answer within the
      // grace ends the bench there (the result file keeps the points finished before).
      std::optional<octocd::StopWithin> within(
          std::in_place, fmt::format("bench point {} stepped frame {} of {} (a step longer than the 0.5 s grace)",
                                     p.id, f, total));  // then the run session's kept text: what the result keeps
      const double cpu0 = host_engine ? process_cpu_ms() : 0.0;
      const auto t_frame = Clock::now();
      const FrameMetrics& stepped = engine->step();
      if (trace) {
        feed.append(*trace, *engine, stepped, total - f);
        // A traced point's step is the whole frame: the step, the copy-back and the write.
        if (traced) {
          timed = stepped;
          timed.step_ms = std::chrono::duration<double, std::milli>(Clock::now() - t_frame).count();
        }
      }
      const FrameMetrics& m = traced ? timed : stepped;
      const double cpu = host_engine ? process_cpu_ms() - cpu0 : 0.0;
      within.reset();
      stepped_ms += m.step_ms;
      for (std::size_t w = 0; w < windows.size(); ++w)
        if (f >= windows[w].first && f <= windows[w].last) {
          sums[w].back().add(m);
          sums[w].back().cpu_ms += cpu;
        }
      if (budgeted && s.cuttable && f >= windows[0].first) timed_frames.emplace_back(m, cpu);
      if (budgeted && f < total && std::chrono::duration<double>(Clock::now() - t_budget).count() > ov.time_limit_s) {
        if (ov.abandon_over_time) {
          if (trace) trace->close();
          r["status"] = "over_time";
          return r;
        }
        if (!s.cuttable || f < windows[0].first) {
          // Not one timed frame within the time: skipped, with what the point would take.
          if (trace) trace->close();
          const double per_frame_s = stepped_ms / 1000.0 / f;
          const double setup = setup_s.empty() ? 0.0 : setup_s.front();
          const double rep_s = setup + per_frame_s * s.frames;
          r["status"] = "skipped";
          r["estimate_s"] = {{"repetition", rep_s},
                             {"point", rep_s * s.repeat},
                             {"probe_frames", f},
                             {"probe_steps_per_s", per_frame_s > 0.0 ? 1.0 / per_frame_s : 0.0},
                             {"setup_s", setup}};
          r["reason"] = fmt::format(
              "over the time budget: probed {} frames in {:.1f} s ({:.3g} steps/s; set-up {:.1f} s), one repetition "
              "of {} frames would take about {:.0f} s and {} repetitions about {:.0f} s; the first repetition's share "
              "of max_time_s is {:.3g} s of frames, {}; --protocol paper or --max-time {:.0f} runs it",
              f, stepped_ms / 1000.0, per_frame_s > 0.0 ? 1.0 / per_frame_s : 0.0, setup, s.frames, rep_s, s.repeat,
              rep_s * s.repeat, ov.time_limit_s,
              s.cuttable ? "spent before the first timed frame" : "too short for the whole run (windows are never cut)",
              std::ceil(rep_s * s.repeat * 1.25));
          return r;
        }
        // Cut: the first n timed frames are the repetition's window.
        const int asked = windows[0].last - windows[0].first + 1;
        const int n = cut_frames(asked, f - windows[0].first + 1);
        WindowSums cut_sums;
        for (int k = 0; k < n; ++k) {
          cut_sums.add(timed_frames[static_cast<std::size_t>(k)].first);
          cut_sums.cpu_ms += timed_frames[static_cast<std::size_t>(k)].second;
        }
        sums[0].back() = cut_sums;
        r["budget_cut"] = {{"frames_asked", asked}, {"frames", n}, {"frames_stepped", f - windows[0].first + 1}};
        windows[0].last = windows[0].first + n - 1;
        break;
      }
      if (ov.cut_below > 0.0 && f >= windows[0].first) {
        WindowSums& w0 = sums[0].back();
        const std::int64_t planned = windows[0].last - windows[0].first + 1;
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
                                     windows[0].last - windows[0].first + 1, ov.cut_below, ov.cut_below)}};
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
  for (std::size_t w = 0; w < windows.size(); ++w) {
    json fw = figures(sums[w]);
    fw["first"] = windows[w].first;
    fw["last"] = windows[w].last;
    if (s.worlds_given) {  // steps/s x copies: every figure of the spread scales by K
      std::vector<double> ws = fw["steps_per_s"]["values"].get<std::vector<double>>();
      for (double& v : ws) v *= static_cast<double>(p.worlds);
      fw["world_steps_per_s"] = spread(ws);
    }
    r["windows"][windows[w].name] = fw;
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
  r["setup_s"] = spread(setup_s);
  if (host_engine) r["setup_cpu_s"] = spread(setup_cpu_s);
  r["status"] = "ok";
  return r;
}

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
      sc.broadphase.name = broadphase_name(BroadPhaseId::octree);
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
}  // namespace octocd::cli::bench
