// `octocd bench` sweeps of kind speed-accuracy (design.md section 15, after Erez, Tassa and Todorov,
// ICRA 2015): every engine on identical scenes over a ladder of time steps, the same
// simulated time each; accuracy as the consistency error against the same line's smallest
// time step, speed as simulated seconds per wall second. Format: docs/bench-format.md.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <optional>
#include <sstream>

#include <fmt/format.h>

#include "bench_sweep.hpp"
#include "octocd/atomic_file.hpp"
#include "octocd/engine_registry.hpp"
#include "octocd/engines.hpp"
#include "octocd/error.hpp"
#include "octocd/json_strict.hpp"
#include "octocd/process_engines.hpp"
#include "octocd/scene.hpp"
#include "octocd/run_session.hpp"

namespace octocd::cli::bench {

namespace fs = std::filesystem;

namespace {

/// One line: the points of one (scene, engine, geometry, rotation, iterations) over the dts.
struct Line {
  /// The line of scene `sc` (file stem `scene_stem`) on engine `e` with geometry `geo`,
  /// rotation `rot` and Bullet's iterations `it`; its name "SCENE | ENGINE | GEOMETRY |
  /// rotation|translation[ | iterations=N]".
  Line(std::size_t sc, const std::string& scene_stem, const std::string& e, const std::string& geo, bool rot,
       std::optional<int> it)
      : scene(sc), engine(e), geometry(geo), rotation(rot), iterations(it),
        name(fmt::format("{} | {} | {} | {}{}", scene_stem, e, geo, rot ? "rotation" : "translation",
                         it ? fmt::format(" | iterations={}", *it) : std::string())) {}
  std::size_t scene = 0;
  std::string engine, geometry;  ///< geometry: what the engine collides: mesh, hull, box
  bool rotation = false;
  std::optional<int> iterations;  ///< Bullet's solver iterations; none for other engines
  std::string name;               ///< the stable line string
  std::string label;              ///< the registry's label of the engine as run
  std::string skip;               ///< why none of its points runs ("" when they do)
  bool cannot_run = false;        ///< skip says the engine cannot run the scene (not merely unavailable)
};

/// One point: a line at one time step, with what its repetitions measured.
struct SaPoint {
  int index = 0;
  std::size_t line = 0;
  double dt = 0.0;
  long steps = 0;
  long every = 1;  ///< steps between matched times (the largest dt over this dt)
  std::string id;
  std::string status = "ok", reason;
  std::vector<double> speed, sps, started;
  std::vector<float> samples;  ///< repetition 1: x of the dynamic bodies at every matched time
  double pen_max = 0.0;
  double e_first = std::numeric_limits<double>::quiet_NaN(), e_last = std::numeric_limits<double>::quiet_NaN();
  long bodies = 0;
  /// The load average (1, 5, 15 min) at the end of the repetition whose 1-minute figure was
  /// highest: how busy the machine was while this point was measured (report's load mark).
  json load_average = json::array();
  bool finished = false;
  double spent_s = 0.0;     ///< wall time of its repetitions (set-up and steps): the budget's time
  std::string ended_by;     ///< why its repetitions ended: repetitions, min_time, max_time
  long probe_steps = 0;     ///< a repetition over max_time_s: the steps it ran
  double probe_wall_s = 0;  ///< and their wall time
  json estimate;            ///< a point skipped by the budget: the time it would take (s)
};

std::string dt_text(double dt) { return fmt::format("{:.6g}", dt); }

/// "bullet (btDbvtBroadphase, hulls, rotation)": the registry's engine with what it ran.
std::string engine_label(const EngineInfo& info, const std::string& broadphase, const std::string& geometry,
                         bool rotation) {
  const std::string bp = info.own_broadphase_class.empty() ? broadphase : info.own_broadphase_class;
  const std::string geo = geometry == "hull" ? "hulls" : geometry == "box" ? "boxes" : "meshes";
  return fmt::format("{} ({}, {}, {})", info.name, bp, geo, rotation ? "rotation" : "translation only");
}

/// The scene text of a point: the scene file with the sweep's `set`, dt, frames and (with
/// rotation) rotation: true.
std::string point_scene(const Sweep& s, std::size_t sc, double dt, long steps, bool rotation) {
  Point p;
  p.scene = sc;
  json j = json::parse(scene_text(s, p));
  j["dt"] = dt;
  j["frames"] = steps;
  if (rotation) j["rotation"] = true;
  return j.dump(2);
}

bool finite3(const Vec3& v) { return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z); }

/// Total energy (J): the engine's kinetic energy plus the dynamic bodies' gravitational
/// potential above the domain's lowest corner along gravity.
double total_energy(const Model& m, const BodyState& st, double kinetic) {
  const Vec3 g = m.scene.gravity;
  const double gl = std::sqrt(double(g.x) * g.x + double(g.y) * g.y + double(g.z) * g.z);
  double e = kinetic;
  if (gl <= 0.0) return e;
  const Vec3 lo = m.scene.domain.min, hi = m.scene.domain.max;
  // The domain corner lowest along gravity: per axis, the side gravity points to.
  const double base_x = g.x > 0 ? hi.x : lo.x, base_y = g.y > 0 ? hi.y : lo.y, base_z = g.z > 0 ? hi.z : lo.z;
  for (std::size_t i = 0; i < st.size(); ++i) {
    if (!(st.w[i] > 0.0f)) continue;
    const double h = -((st.x[i].x - base_x) * g.x + (st.x[i].y - base_y) * g.y + (st.x[i].z - base_z) * g.z) / gl;
    e += gl * h / static_cast<double>(st.w[i]);
  }
  return e;
}

/// Distance (m) of p outside the box [lo, hi] (0 inside).
double outside(const Vec3& p, const Vec3& lo, const Vec3& hi) {
  const double dx = std::max({double(lo.x) - p.x, 0.0, double(p.x) - hi.x});
  const double dy = std::max({double(lo.y) - p.y, 0.0, double(p.y) - hi.y});
  const double dz = std::max({double(lo.z) - p.z, 0.0, double(p.z) - hi.z});
  return std::sqrt(dx * dx + dy * dy + dz * dz);
}

}  // namespace

int run_speed_accuracy(const Sweep& s, const std::string& origin, const json& def, const BenchOptions& o, int shard,
                       int shards, bool engines_given) {
  const double dt_max = *std::max_element(s.dts.begin(), s.dts.end());
  const double dt_ref = *std::min_element(s.dts.begin(), s.dts.end());
  const long matched = std::lround(s.sim_seconds / dt_max);  // matched times per point
  check_engine_settings(o.settings, cli_argument_names());
  // A line's settings: the command's items, then its geometry and iteration count.
  auto line_settings = [&](const EngineInfo& info, const std::string& geometry, std::optional<int> iterations) {
    EngineSettingItems items = o.settings;
    if (!info.geometry_setting.empty()) items[info.name].push_back(info.geometry_setting + "=" + geometry);
    if (iterations && !info.iterations_setting.empty())
      items[info.name].push_back(fmt::format("{}={}", info.iterations_setting, *iterations));
    return items;
  };

  // Engines named on the command line must run here.
  for (const std::string& e : s.engines) {
    const EngineInfo& info = engine_info(e, "--engines");
    const std::string why = engine_built(info) ? engine_unavailable(info) : std::string("not built in this octocd");
    if (engines_given && !why.empty())
      throw InputError(fmt::format("--engines: engine {} cannot run here ({}); allowed: {}", e, why,
                                   fmt::join(built_engine_names(), ", ")));
  }

  // Lines, scene-major, then engine, geometry, rotation, iterations; each checked once on
  // its scene at the largest dt (the engine built, the rotation it needs).
  ModelCache models;
  std::vector<Line> lines;
  for (std::size_t sc = 0; sc < s.scenes.size(); ++sc) {
    const std::string scene = stem(s.scenes[sc]);
    for (const std::string& e : s.engines) {
      const EngineInfo& info = engine_info(e, "engines");
      // An engine with a shape setting runs the sweep's geometries (those it has), one line each.
      std::vector<std::string> geos;
      for (const std::string& g : s.geometries)
        if (info.geometries.size() > 1 &&
            std::find(info.geometries.begin(), info.geometries.end(), g) != info.geometries.end())
          geos.push_back(g);
      if (info.geometries.size() <= 1) geos = info.geometries;
      for (const std::string& geo : geos) {
        for (const bool rot : s.rotations) {
          if (rot && !info.rotates) continue;  // lines an engine can have
          const std::vector<std::optional<int>> its =
              !info.iterations_setting.empty() ? std::vector<std::optional<int>>(s.iterations.begin(), s.iterations.end())
                        : std::vector<std::optional<int>>{std::nullopt};
          for (const auto& it : its) {
            Line l(sc, scene, e, geo, rot, it);
            std::string broadphase = "?";
            const std::string why_not = engine_built(info) ? engine_unavailable(info) : "not built in this octocd";
            try {
              const std::string text = point_scene(s, sc, dt_max, matched, rot);
              std::shared_ptr<const Model> model = models.get(text, s.scenes[sc], o.data_dir);
              broadphase = model->scene.broadphase.name;
              if (!why_not.empty()) {
                l.skip = "engine " + e + ": " + why_not;
              } else if (!rot && scene_rotates(model->scene)) {
                l.skip = fmt::format("scene {} rotates (rotation: true, or a group with an orientation or angular "
                                     "velocity): it has no translation-only run",
                                     scene);
                l.cannot_run = true;
              } else if (info.geometries.size() > 1 && rot && geo == "box") {
                l.skip = "with rotation Bullet collides meshes as convex hulls whatever shape=box says: the run of "
                         "the hull line";
              } else {
                (void)make_engine(e, model, line_settings(info, geo, it));
              }
            } catch (const std::exception& ex) {
              l.skip = fmt::format("engine {} cannot run scene {}: {}", e, scene, ex.what());
              l.cannot_run = true;
            }
            l.label = engine_label(info, broadphase, geo, rot);
            lines.push_back(l);
          }
        }
      }
    }
  }
  // A scene an engine named on the command line cannot run at all: bad input.
  if (engines_given) {
    for (std::size_t sc = 0; sc < s.scenes.size(); ++sc)
      for (const std::string& e : s.engines) {
        bool any = false, all_cannot = true;
        std::string why;
        for (const Line& l : lines)
          if (l.scene == sc && l.engine == e) {
            any = true;
            if (!l.cannot_run) all_cannot = false;
            else if (why.empty()) why = l.skip;
          }
        if (any && all_cannot)
          throw InputError(fmt::format("{}: scenes: engine {} cannot run scene '{}' ({}); allowed: scenes every engine "
                                       "of --engines can run, or other --engines",
                                       origin, e, stem(s.scenes[sc]), why));
      }
  }

  // Points: lines in order, each over the dts as listed.
  std::vector<SaPoint> points;
  for (std::size_t li = 0; li < lines.size(); ++li) {
    for (const double dt : s.dts) {
      SaPoint p;
      p.index = static_cast<int>(points.size());
      p.line = li;
      p.dt = dt;
      p.every = std::lround(dt_max / dt);
      p.steps = matched * p.every;
      p.id = lines[li].name + " | dt=" + dt_text(dt);
      if (!lines[li].skip.empty()) {
        p.status = "skipped";
        p.reason = lines[li].skip;
      }
      points.push_back(p);
    }
  }
  if (points.size() > kMaxPoints)
    bad(origin, "dts", fmt::format("the sweep expands to {} points", points.size()),
        fmt::format("at most {} points", kMaxPoints));
  // A line's points stay in one shard (its consistency error needs its reference run).
  std::vector<std::size_t> mine;
  for (std::size_t k = 0; k < points.size(); ++k)
    if (static_cast<int>(points[k].line % static_cast<std::size_t>(shards)) == shard) mine.push_back(k);

  json settings = result_settings(s, shard, shards);
  settings.erase("frames");
  settings.erase("warmup");
  settings["dts"] = s.dts;
  settings["sim_seconds"] = static_cast<double>(matched) * dt_max;
  settings["iterations"] = s.iterations;
  settings["geometries"] = s.geometries;
  settings["rotation"] = s.rotations;
  settings["reference_dt"] = dt_ref;
  settings["shard_by"] = "line";
  json result = new_result(s, origin, def, settings, points.size());
  {
    // --resume keeps a finished result of the same sweep and settings (nothing to run); an
    // unfinished one cannot go on: its consistency errors need every line's reference run
    // in one process.
    std::error_code ec;
    if (fs::exists(o.output, ec)) {
      if (!o.resume)
        throw InputError(fmt::format("{}: exists; allowed: a new result file, or --resume for a finished run of the "
                                     "same sweep",
                                     o.output));
      // Strict (a key twice, a NUL byte, > 64 levels refused); every field read checked by type.
      const json old = octocd::parse_json_strict(
          octocd::read_input_file(o.output, "-o", "a finished result of the same sweep to --resume"), o.output);
      if (!finished_result_matches(old, o.output, def, settings))
        throw InputError(fmt::format("{}: --resume: not a finished result of {} with these settings; allowed: a "
                                     "finished one (kept as it is), else delete it and run again (a speed-accuracy "
                                     "run cannot go on midway: its errors need each line's reference run)",
                                     o.output, origin));
      if (!o.quiet) fmt::print(stderr, "bench {}: {} is finished; kept as it is\n", octocd::printable(s.name), o.output);
      return 0;
    }
    const fs::path parent = fs::path(o.output).parent_path();
    if (!parent.empty()) fs::create_directories(parent, ec);
  }
  record_hygiene(result, s, o.quiet);
  const std::string csv_path =
      !o.csv.empty() ? o.csv : (fs::path(o.output).parent_path() / (fs::path(o.output).stem().string() + ".csv")).string();

  const double max_t = s.max_time_s > 0 ? s.max_time_s : 0.0, min_t = std::max(s.min_time_s, 0.0);
  const auto point_json = [&](const SaPoint& p) {
    const Line& l = lines[p.line];
    json r;
    r["id"] = p.id;
    r["index"] = p.index;
    r["status"] = p.status;
    if (!p.reason.empty()) r["reason"] = p.reason;
    json axes{{"dt", dt_text(p.dt)}};
    if (l.iterations) axes["iterations"] = std::to_string(*l.iterations);
    r["params"] = {{"scene", stem(s.scenes[l.scene])}, {"engine", l.engine}, {"axes", axes}};
    r["geometry"] = l.geometry;
    r["rotation"] = l.rotation;
    r["line"] = l.name;
    r["engine_label"] = l.label;
    r["dt"] = p.dt;
    r["iterations"] = l.iterations ? json(*l.iterations) : json(nullptr);
    r["steps"] = p.steps;
    r["sim_seconds"] = static_cast<double>(p.steps) * p.dt;
    r["bodies"] = p.bodies;
    const bool ok = p.status == "ok";
    r["speed"] = ok ? spread(p.speed) : json(nullptr);
    r["steps_per_s"] = ok ? spread(p.sps) : json(nullptr);
    json err{{"consistency", nullptr},
             {"reference_dt", dt_ref},
             {"max_penetration_m", nullptr},
             {"energy_drift", nullptr},
             {"momentum_residual", nullptr}};
    json why{{"momentum_residual",
              "not computed: the momentum-balance residual needs every step's contact rows and impulses (octocd "
              "validate judges it per run)"}};
    if (ok) {
      err["max_penetration_m"] = p.pen_max;
      if (std::isfinite(p.e_first) && std::isfinite(p.e_last) && std::abs(p.e_first) > 0.0)
        err["energy_drift"] = (p.e_last - p.e_first) / std::abs(p.e_first);
      else
        why["energy_drift"] = "no energy at the first matched time";
      // The line's reference: its point at the smallest dt.
      const SaPoint* ref = nullptr;
      for (const SaPoint& q : points)
        if (q.line == p.line && q.dt == dt_ref) ref = &q;
      if (ref && ref->status == "ok" && ref->samples.size() == p.samples.size() && !p.samples.empty()) {
        const Model& m = *models.get(point_scene(s, l.scene, dt_max, matched, l.rotation), s.scenes[l.scene], o.data_dir);
        std::vector<double> size;
        for (std::size_t i = 0; i < m.initial.size(); ++i) {
          if (!(m.initial.w[i] > 0.0f)) continue;
          const Aabb& b = m.local_box(i);
          const Vec3 d = b.max - b.min;
          size.push_back(std::sqrt(double(d.x) * d.x + double(d.y) * d.y + double(d.z) * d.z));
        }
        double sum = 0.0;
        std::size_t n = 0;
        for (std::size_t k = 0; k + 2 < p.samples.size(); k += 3) {
          const std::size_t body = (k / 3) % std::max<std::size_t>(size.size(), 1);
          double d2 = 0.0;
          for (int c = 0; c < 3; ++c) {
            const double d = double(p.samples[k + c]) - double(ref->samples[k + c]);
            d2 += d * d;
          }
          const double sz = size.empty() ? 1.0 : std::max(size[body], 1e-12);
          sum += d2 / (sz * sz);
          ++n;
        }
        err["consistency"] = n > 0 ? std::sqrt(sum / static_cast<double>(n)) : 0.0;
      } else if (!ref || ref->status != "ok") {
        why["consistency"] = fmt::format("the line's reference (dt {}) is {}", dt_text(dt_ref),
                                         ref ? ref->status + (ref->reason.empty() ? "" : ": " + ref->reason) : "missing");
      } else {
        why["consistency"] = "no dynamic bodies";
      }
    }
    r["error"] = err;
    r["error_reasons"] = why;
    if (!p.started.empty()) r["repetition_start_s"] = p.started;
    if (!p.estimate.is_null()) r["estimate_s"] = p.estimate;
    if (!p.ended_by.empty() || !p.estimate.is_null())
      r["budget"] = {{"protocol", s.protocol},
                     {"min_time_s", min_t},
                     {"max_time_s", max_t},
                     {"time_s", p.spent_s},
                     {"repetitions_asked", s.repeat},
                     {"repetitions", static_cast<int>(p.speed.size())},
                     {"ended_by", p.ended_by.empty() ? std::string("max_time") : p.ended_by}};
    if (!p.load_average.empty()) {
      r["load_average"] = p.load_average;
      // More runnable threads than cores (the bench's own included) while it measured.
      const long threads = result["machine"].value("threads", 0L);
      r["under_load"] = threads > 0 && p.load_average[0].get<double>() > static_cast<double>(threads) + 1.0;
    }
    return r;
  };

  // SIGINT/SIGTERM: the sweep stops between points, or ends inside a step within the
  // session's bound; either way the result and the CSV keep the finished points.
  octocd::RunSession session("bench");
  session.keep(fmt::format("no point finished yet: the result {} is not written", o.output));
  const auto write = [&]() {
    json out = result;
    out["points"] = json::array();
    for (const std::size_t k : mine)
      if (points[k].finished) out["points"].push_back(point_json(points[k]));
    out["updated"] = utc_time_now();
    write_file_atomically(o.output, out.dump(1) + "\n", "-o");
    // The CSV: one row per finished point, the fields flattened.
    std::ostringstream csv;
    csv << "sweep,index,id,line,scene,engine,engine_label,geometry,rotation,iterations,dt,steps,sim_seconds,status,"
           "reason";
    for (const char* f : {"speed", "steps_per_s"})
      for (const char* k : {"median", "min", "max", "mean", "stdev", "n"}) csv << ',' << f << '.' << k;
    csv << ",error.consistency,error.reference_dt,error.max_penetration_m,error.energy_drift,error.momentum_residual\n";
    // Text cells: bounded, and a leading = + - @ TAB CR made text (octocd::csv_text_cell).
    const auto q = [](const std::string& t) {
      std::string r = "\"";
      for (char c : octocd::csv_text_cell(octocd::bounded(t))) r += c == '"' ? std::string("\"\"") : std::string(1, c);
      return r + "\"";
    };
    const auto num = [](const json& v) { return v.is_null() ? std::string() : v.dump(); };
    for (const json& r : out["points"]) {
      csv << q(s.name) << ',' << r["index"].get<int>() << ',' << q(r["id"]) << ',' << q(r["line"]) << ','
          << q(r["params"]["scene"]) << ',' << r["params"]["engine"].get<std::string>() << ',' << q(r["engine_label"])
          << ',' << r["geometry"].get<std::string>() << ',' << (r["rotation"].get<bool>() ? "true" : "false") << ','
          << num(r["iterations"]) << ',' << num(r["dt"]) << ',' << num(r["steps"]) << ',' << num(r["sim_seconds"])
          << ',' << r["status"].get<std::string>() << ',' << q(r.value("reason", ""));
      for (const char* f : {"speed", "steps_per_s"})
        for (const char* k : {"median", "min", "max", "mean", "stdev", "n"})
          csv << ',' << (r[f].is_null() ? std::string() : num(r[f][k]));
      for (const char* k : {"consistency", "reference_dt", "max_penetration_m", "energy_drift", "momentum_residual"})
        csv << ',' << num(r["error"][k]);
      csv << '\n';
    }
    write_file_atomically(csv_path, csv.str(), "--csv");
    session.keep(fmt::format("the result {} and the CSV {} keep the {} finished point(s)", o.output, csv_path,
                             out["points"].size()));
  };

  SweepProgress progress(mine.size(), !o.quiet);
  if (!o.quiet)
    fmt::print(stderr,
               "bench {}: {} points ({} in this shard {}/{}, whole lines), engines {}, dts {}, {:g} simulated s each, "
               "{} repetitions; result {} and {}\n",
               octocd::printable(s.name), points.size(), mine.size(), shard, shards, json(s.engines).dump(), json(s.dts).dump(),
               static_cast<double>(matched) * dt_max, s.repeat, o.output, csv_path);
  std::size_t finished = 0;
  const auto finish = [&](SaPoint& p) {
    p.finished = true;
    progress.start(finished++, p.id);
    progress.finish(p.status == "ok"
                        ? fmt::format("ok ({:.3g} simulated s per s median, {} of {} repetitions, {:.1f} s{})",
                                      spread(p.speed)["median"].get<double>(), p.speed.size(), s.repeat, p.spent_s,
                                      p.ended_by == "max_time" ? ", max_time_s reached" : "")
                        : p.status + ": " + p.reason);
    write();
  };
  for (const std::size_t k : mine)
    if (points[k].status == "skipped") finish(points[k]);

  const auto t0 = Clock::now();
  bool any_failed = false;
  BadEngineValues bad_values;  // points failed on a value an engine gave: exit 2 at the end
  // Round-robin within groups of kRoundRobinGroup points (design.md section 14b); the budget
  // (docs/bench-format.md "Time budget"): a repetition runs the whole simulated time (the
  // errors need it), so the first may take all of max_time_s (beyond it the point is skipped
  // with an estimate); a later one starts only when expected to end within max_time_s and is
  // dropped if still running there.
  std::vector<std::size_t> todo;
  for (const std::size_t k : mine)
    if (!points[k].finished) todo.push_back(k);
  for (std::size_t g0 = 0; g0 < todo.size(); g0 += kRoundRobinGroup) {
    const std::size_t g1 = std::min(todo.size(), g0 + kRoundRobinGroup);
    for (int rep = 0;; ++rep) {
      bool any = false;
      for (std::size_t gi = g0; gi < g1; ++gi) {
        SaPoint& p = points[todo[gi]];
        if (p.finished) continue;
        any = true;
        const Line& l = lines[p.line];
        if (const int sig = octocd::stop_signal())
          return record_stopped(result, sig, write, session, fmt::format("{} of {} points", finished, mine.size()));
        progress.start(finished, fmt::format("{} (repetition {}/{})", p.id, rep + 1, s.repeat));
        p.started.push_back(std::chrono::duration<double>(Clock::now() - t0).count());
        const auto t_rep = Clock::now();
        const double limit = max_t > 0 ? max_t - p.spent_s : 0.0;
        bool over_time = false;
        std::shared_ptr<const Model> model;
        std::unique_ptr<Engine> engine;
        try {
          model = models.get(point_scene(s, l.scene, p.dt, p.steps, l.rotation), s.scenes[l.scene], o.data_dir);
          engine = make_engine(l.engine, model, line_settings(engine_info(l.engine, "engines"), l.geometry, l.iterations));
        } catch (const std::exception& e) {
          p.status = "skipped";
          p.reason = fmt::format("engine {} cannot run scene {}: {}", l.engine, stem(s.scenes[l.scene]), e.what());
          finish(p);
          continue;
        }
        p.bodies = static_cast<long>(model->initial.size());
        const Vec3 lo = model->scene.domain.min, hi = model->scene.domain.max;
        double wall = 0.0, pen = 0.0;
        std::string diverged;
        std::vector<float> samples;
        double e_first = std::numeric_limits<double>::quiet_NaN(), e_last = e_first;
        try {
          for (long step = 1; step <= p.steps && diverged.empty(); ++step) {
            if (session.signal() != 0) break;
            // A step of a big scene may take seconds (Bullet's GJK on hulls): a signal it does
            // not answer within the grace ends the bench there, the session saying what the
            // result keeps. Made outside the timed step.
            std::optional<octocd::StopWithin> within(
                std::in_place, fmt::format("bench point {} stepped step {} of {} (a step longer than the 0.5 s grace)",
                                           p.id, step, p.steps));
            const auto ts = Clock::now();
            const FrameMetrics& m = engine->step();
            const auto te = Clock::now();
            within.reset();
            wall += std::chrono::duration<double>(te - ts).count();
            if (limit > 0.0 && step < p.steps && std::chrono::duration<double>(te - t_rep).count() > limit) {
              over_time = true;  // past max_time_s: the first repetition skips the point, a later one is dropped
              p.probe_steps = step;
              p.probe_wall_s = wall;
              break;
            }
            if (std::isfinite(m.penetration_max)) pen = std::max(pen, m.penetration_max);
            if (step % p.every != 0) continue;
            const BodyState& st = engine->state();
            for (std::size_t i = 0; i < st.size() && diverged.empty(); ++i) {
              if (!finite3(st.x[i]) || !finite3(st.v[i]))
                diverged = fmt::format("non-finite state at step {} (t = {:g} s): body {}", step, static_cast<double>(step) * p.dt, i);
              else if (outside(st.x[i], lo, hi) > s.diverge_beyond_m)
                diverged = fmt::format("body {} {:.4g} m outside the domain at step {} (t = {:g} s; diverge_beyond_m {:g})",
                                       i, outside(st.x[i], lo, hi), step, static_cast<double>(step) * p.dt, s.diverge_beyond_m);
            }
            if (!diverged.empty()) break;
            const double e = total_energy(*model, st, m.kinetic_energy);
            if (!std::isfinite(e_first)) e_first = e;
            e_last = e;
            if (rep == 0)
              for (std::size_t i = 0; i < st.size(); ++i)
                if (st.w[i] > 0.0f) samples.insert(samples.end(), {st.x[i].x, st.x[i].y, st.x[i].z});
          }
        } catch (const EngineValueError& e) {  // bad input from the engine (its timing): never a divergence
          p.status = "failed";
          p.reason = bad_values.add(p.id, e);
          any_failed = true;
          finish(p);
          continue;
        } catch (const std::exception& e) {
          // A runtime failure: a non-finite state the engine found itself is a divergence.
          const std::string what = e.what();
          const bool nonfinite = what.find("non-finite") != std::string::npos || what.find("NaN") != std::string::npos ||
                                 what.find("nan") != std::string::npos || what.find("inf") != std::string::npos;
          if (nonfinite) {
            diverged = what;
          } else {
            p.status = "failed";
            p.reason = what;
            any_failed = true;
            finish(p);
            continue;
          }
        }
        p.spent_s += std::chrono::duration<double>(Clock::now() - t_rep).count();
        if (over_time && diverged.empty()) {
          p.started.pop_back();
          if (p.speed.empty()) {
            const double sps = p.probe_wall_s > 0.0 ? static_cast<double>(p.probe_steps) / p.probe_wall_s : 0.0;
            const double rep_s = sps > 0.0 ? static_cast<double>(p.steps) / sps : 0.0;
            p.status = "skipped";
            p.estimate = {{"repetition", rep_s}, {"point", rep_s * s.repeat}, {"probe_steps", p.probe_steps},
                          {"probe_steps_per_s", sps}};
            p.reason = fmt::format("over the time budget: probed {} of {} steps in {:.1f} s ({:.3g} steps/s), one "
                                   "repetition would take about {:.0f} s and {} repetitions about {:.0f} s, beyond "
                                   "max_time_s {:.3g} s (a repetition runs the whole simulated time); --protocol paper or "
                                   "--max-time {:.0f} runs it",
                                   p.probe_steps, p.steps, p.probe_wall_s, sps, rep_s, s.repeat, rep_s * s.repeat, max_t,
                                   std::ceil(rep_s * s.repeat * 1.25));
          } else {
            p.ended_by = "max_time";
          }
          finish(p);
          continue;
        }
        if (octocd::stop_signal() != 0 && diverged.empty() && engine->frame() < p.steps) continue;  // stopped mid-run
        if (!diverged.empty()) {
          p.status = "diverged";
          p.reason = diverged;
          finish(p);
          continue;
        }
        const double sim = static_cast<double>(p.steps) * p.dt;
        p.speed.push_back(wall > 0.0 ? sim / wall : std::numeric_limits<double>::infinity());
        p.sps.push_back(wall > 0.0 ? static_cast<double>(p.steps) / wall : std::numeric_limits<double>::infinity());
        p.pen_max = std::max(p.pen_max, pen);
        if (const json la = load_average(); !la.empty() && (p.load_average.empty() || la[0] > p.load_average[0]))
          p.load_average = la;
        if (rep == 0) {
          p.samples = std::move(samples);
          p.e_first = e_first;
          p.e_last = e_last;
        }
        // Another repetition: until those asked (while the next is expected to end within
        // max_time_s), then while the point's time is below min_time_s.
        const int have = static_cast<int>(p.speed.size());
        const bool fits = max_t <= 0 || p.spent_s + p.spent_s / have <= max_t;
        if (have >= kMaxRepetitions) p.ended_by = "repetitions";
        else if (have >= s.repeat && (p.spent_s >= min_t || !fits)) p.ended_by = have > s.repeat ? "min_time" : "repetitions";
        else if (!fits) p.ended_by = "max_time";  // fewer repetitions than asked
        if (!p.ended_by.empty()) finish(p);
      }
      if (!any) break;
    }
  }
  if (const std::optional<int> stopped = finish_sweep(result, write, session)) return *stopped;
  if (!mine.empty() && std::all_of(mine.begin(), mine.end(), [&](std::size_t k) { return points[k].status == "skipped"; }))
    throw InputError(fmt::format("{}: every point skipped ({}; first: {}: {}); allowed: a sweep with a point this "
                                 "octocd can run (result kept in {})",
                                 origin, mine.size(), points[mine.front()].id, points[mine.front()].reason, o.output));
  if (!o.quiet) fmt::print(stderr, "bench {}: done, result {}, CSV {}\n", octocd::printable(s.name), o.output, csv_path);
  bad_values.refuse(o.output);
  return any_failed ? 1 : 0;
}

}  // namespace octocd::cli::bench
