// `octocd bench` sweeps of kind divergence (design.md section 20, after Chung and Pollard,
// CAVW 2016; docs/predictability.md): per scene and engine an unperturbed run and, per eps
// of the ladder, K copies whose dynamic bodies start eps metres away in seeded random
// directions; per frame the mean and max distance of the bodies from the unperturbed run
// and the growth exponent fitted over the run. Format: docs/bench-format.md.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <limits>
#include <optional>
#include <random>
#include <sstream>

#include <fmt/format.h>

#include "bench_sweep.hpp"
#include "octocd/atomic_file.hpp"
#include "octocd/engine_registry.hpp"
#include "octocd/engines.hpp"
#include "octocd/error.hpp"
#include "octocd/process_engines.hpp"
#include "octocd/scene.hpp"
#include "octocd/run_session.hpp"
#include "predict.hpp"

namespace octocd::cli::bench {

namespace fs = std::filesystem;

namespace {

/// One point: a (scene, engine, eps) with its distances per frame.
struct DvPoint {
  int index = 0;
  std::size_t scene = 0;
  std::string engine;
  double eps = 0.0;
  std::string id;
  std::string status = "ok", reason;
  std::vector<double> mean, max;  ///< per frame 0..F (m)
  std::optional<double> exponent;  ///< fitted growth exponent (1/s)
  std::string exponent_reason;     ///< why there is none
  long bodies = 0;                 ///< dynamic bodies
  double dt = 0.0;
  double seconds = 0.0;            ///< wall time of its copies' runs
  bool finished = false;
};

std::string eps_text(double eps) { return fmt::format("{:.0e}", eps); }

/// A double in [0, 1) from the top 53 bits of a 64-bit draw (the same on every platform,
/// unlike std::uniform_real_distribution).
double unit(std::mt19937_64& rng) { return static_cast<double>(rng() >> 11) * 0x1.0p-53; }

/// The model of copy `copy` of eps ladder entry `eps_index`: every dynamic body (w > 0)
/// moved `eps` metres in a direction uniform on the sphere, from a generator seeded with
/// (seed, eps_index, copy). Positions are float32: a move below the resolution of a
/// body's coordinates rounds away (the measured distance at frame 0 says what remained).
std::shared_ptr<const Model> perturbed(const Model& base, double eps, std::uint64_t seed, std::size_t eps_index,
                                       int copy) {
  auto m = std::make_shared<Model>(base);
  std::seed_seq seq{static_cast<std::uint32_t>(seed), static_cast<std::uint32_t>(seed >> 32),
                    static_cast<std::uint32_t>(eps_index), static_cast<std::uint32_t>(copy)};
  std::mt19937_64 rng(seq);
  for (std::size_t i = 0; i < m->initial.size(); ++i) {
    if (!(m->initial.w[i] > 0.0f)) continue;
    const double z = 2.0 * unit(rng) - 1.0, phi = 2.0 * 3.14159265358979323846 * unit(rng);
    const double r = std::sqrt(std::max(0.0, 1.0 - z * z));
    Vec3& x = m->initial.x[i];
    x = Vec3{static_cast<float>(x.x + eps * r * std::cos(phi)), static_cast<float>(x.y + eps * r * std::sin(phi)),
             static_cast<float>(x.z + eps * z)};
  }
  return m;
}

/// Least-squares slope of ln(d) over time t (s) at the frames where d > 0: the growth
/// exponent lambda of d(t) ~ d0 exp(lambda t) (1/s); nullopt with `why` for fewer than 2.
std::optional<double> fit_exponent(const std::vector<double>& d, double dt, std::string& why) {
  double n = 0, st = 0, sy = 0, stt = 0, sty = 0;
  for (std::size_t f = 0; f < d.size(); ++f) {
    if (!(d[f] > 0.0) || !std::isfinite(d[f])) continue;
    const double t = static_cast<double>(f) * dt, y = std::log(d[f]);
    n += 1;
    st += t;
    sy += y;
    stt += t * t;
    sty += t * y;
  }
  const double den = n * stt - st * st;
  if (n < 2 || !(den > 0.0)) {
    why = n < 2 ? "the copies stayed bit for bit on the unperturbed run (distance 0) at all but at most one frame"
                : "too few frames";
    return std::nullopt;
  }
  return (n * sty - st * sy) / den;
}

}  // namespace

int run_divergence(const Sweep& s, const std::string& origin, const json& def, const BenchOptions& o) {
  check_engine_settings(o.settings, cli_argument_names());
  {
    std::error_code ec;
    if (fs::exists(o.output, ec))
      throw InputError(fmt::format("{}: exists; allowed: a new result file (a divergence run starts over)", o.output));
    const fs::path parent = fs::path(o.output).parent_path();
    if (!parent.empty()) fs::create_directories(parent, ec);
  }
  const std::string csv_path =
      !o.csv.empty() ? o.csv : (fs::path(o.output).parent_path() / (fs::path(o.output).stem().string() + ".csv")).string();
  check_output_file(csv_path, "--csv");
  // The scene text of scene `sc`: the sweep's `set`, its frames, rotation when asked.
  const auto scene_of = [&](std::size_t sc) {
    Point p;
    p.scene = sc;
    json j = json::parse(scene_text(s, p));
    j["frames"] = s.frames;
    if (s.rotation) j["rotation"] = true;
    return j.dump(2);
  };
  std::vector<DvPoint> points;
  for (std::size_t sc = 0; sc < s.scenes.size(); ++sc)
    for (const std::string& e : s.engines)
      for (const double eps : s.eps) {
        DvPoint p;
        p.index = static_cast<int>(points.size());
        p.scene = sc;
        p.engine = e;
        p.eps = eps;
        p.id = fmt::format("{} | {} | eps={}", stem(s.scenes[sc]), e, eps_text(eps));
        points.push_back(p);
      }
  if (points.size() > kMaxPoints)
    bad(origin, "eps", fmt::format("the sweep expands to {} points", points.size()),
        fmt::format("at most {} points", kMaxPoints));

  json settings = result_settings(s, 0, 1);
  settings["warmup"] = 0;
  settings["repeat"] = 1;  // one run per copy
  settings["eps"] = s.eps;
  settings["copies"] = s.copies;
  settings["seed"] = s.seed;
  settings["rotation"] = s.rotation;
  json result = new_result(s, origin, def, settings, points.size());
  record_hygiene(result, s, o.quiet);

  const auto num = [](double v) { return std::isfinite(v) ? json(v) : json(nullptr); };
  const auto point_json = [&](const DvPoint& p) {
    json r;
    r["id"] = p.id;
    r["index"] = p.index;
    r["status"] = p.status;
    if (!p.reason.empty()) r["reason"] = p.reason;
    r["params"] = {{"scene", stem(s.scenes[p.scene])}, {"engine", p.engine}, {"axes", {{"eps", eps_text(p.eps)}}}};
    r["eps_m"] = p.eps;
    r["copies"] = s.copies;
    r["seed"] = s.seed;
    r["frames"] = s.frames;
    r["dt"] = p.dt;
    r["bodies"] = p.bodies;
    r["seconds"] = p.seconds;
    if (p.status == "ok") {
      json mean = json::array(), max = json::array();
      for (std::size_t f = 0; f < p.mean.size(); ++f) {
        mean.push_back(num(p.mean[f]));
        max.push_back(num(p.max[f]));
      }
      r["initial_mean_m"] = p.mean.empty() ? json(nullptr) : num(p.mean.front());
      r["final_mean_m"] = p.mean.empty() ? json(nullptr) : num(p.mean.back());
      r["mean_m"] = std::move(mean);
      r["max_m"] = std::move(max);
      r["exponent_per_s"] = p.exponent ? num(*p.exponent) : json(nullptr);
      if (!p.exponent) r["exponent_reason"] = p.exponent_reason;
    }
    return r;
  };
  // SIGINT/SIGTERM: the sweep stops between points, or ends inside a step within the
  // session's bound; either way the result and the CSV keep the finished points.
  octocd::RunSession session("bench");
  session.keep(fmt::format("no point finished yet: the result {} is not written", o.output));
  const auto write = [&] {
    json out = result;
    out["points"] = json::array();
    std::ostringstream csv;
    csv << "sweep,scene,engine,eps_m,copies,seed,frame,t_s,mean_m,max_m,exponent_per_s,status\n";
    for (const DvPoint& p : points) {
      if (!p.finished) continue;
      out["points"].push_back(point_json(p));
      const std::string expo = p.exponent ? fmt::format("{:.9g}", *p.exponent) : "";
      const std::string head = fmt::format("{},{},{},{:g},{},{}", s.name, stem(s.scenes[p.scene]), p.engine, p.eps,
                                           s.copies, s.seed);
      if (p.status != "ok") {
        csv << head << ",,,,,," << p.status << '\n';
        continue;
      }
      for (std::size_t f = 0; f < p.mean.size(); ++f)
        csv << head << ',' << f << ',' << fmt::format("{:.9g}", static_cast<double>(f) * p.dt) << ','
            << fmt::format("{:.9g}", p.mean[f]) << ',' << fmt::format("{:.9g}", p.max[f]) << ',' << expo << ",ok\n";
    }
    out["updated"] = utc_time_now();
    write_file_atomically(o.output, out.dump(1) + "\n", "-o");
    write_file_atomically(csv_path, csv.str(), "--csv");
    session.keep(fmt::format("the result {} and the CSV {} keep the {} finished point(s)", o.output, csv_path,
                             out["points"].size()));
  };

  if (!o.quiet)
    fmt::print(stderr,
               "bench {}: {} points ({} scenes x {} engines x {} eps), {} copies each and one unperturbed run, {} "
               "frames; result {} and {}\n",
               printable(s.name), points.size(), s.scenes.size(), s.engines.size(), s.eps.size(), s.copies, s.frames,
               printable(o.output), printable(csv_path));
  SweepProgress progress(points.size(), !o.quiet);
  ModelCache models;
  bool any_failed = false;
  BadEngineValues bad_values;  // points failed on a value an engine gave: exit 2 at the end
  std::size_t done = 0;
  // Scene-major, then engine: the unperturbed run once per (scene, engine), then its eps.
  for (std::size_t first = 0; first < points.size(); first += s.eps.size()) {
    const DvPoint& head = points[first];
    const std::string scene = stem(s.scenes[head.scene]);
    const EngineInfo& info = engine_info(head.engine, "engines");
    std::string skip = engine_built(info) ? engine_unavailable(info) : std::string("not built in this octocd");
    if (!skip.empty()) skip = "engine " + head.engine + ": " + skip;
    // The unperturbed run failed (its points failed, else skipped); on a value the engine gave.
    bool ref_failed = false;
    std::optional<EngineValueError> ref_bad_value;
    std::shared_ptr<const Model> model;
    std::vector<std::vector<Vec3>> ref;
    const auto t_ref = Clock::now();
    if (skip.empty()) {
      try {
        model = models.get(scene_of(head.scene), s.scenes[head.scene], o.data_dir);
        progress.start(done, fmt::format("{} | {} | unperturbed", scene, head.engine));
        ref = run_positions(head.engine, model, o.settings, s.frames);
      } catch (const EngineValueError& e) {
        skip = fmt::format("engine {} failed on scene {}: {}", head.engine, scene, e.what());
        ref_failed = true;
        ref_bad_value = e;
      } catch (const InputError& e) {
        skip = fmt::format("engine {} cannot run scene {}: {}", head.engine, scene, e.what());
      } catch (const std::exception& e) {
        skip = fmt::format("engine {} failed on scene {}: {}", head.engine, scene, e.what());
        ref_failed = true;
      }
    }
    const double ref_s = std::chrono::duration<double>(Clock::now() - t_ref).count();
    for (std::size_t k = first; k < first + s.eps.size(); ++k) {
      DvPoint& p = points[k];
      if (const int sig = octocd::stop_signal()) return record_stopped(result, sig, write, session);
      progress.start(done++, p.id);
      if (!skip.empty()) {
        p.status = ref_failed ? "failed" : "skipped";
        p.reason = skip;
        if (ref_failed) any_failed = true;
        if (ref_bad_value) bad_values.add(p.id, *ref_bad_value);
        p.finished = true;
        progress.finish(p.status + ": " + p.reason);
        write();
        continue;
      }
      p.dt = model->scene.dt;
      std::vector<std::size_t> dynamic;
      for (std::size_t i = 0; i < model->initial.size(); ++i)
        if (model->initial.w[i] > 0.0f) dynamic.push_back(i);
      p.bodies = static_cast<long>(dynamic.size());
      p.mean.assign(static_cast<std::size_t>(s.frames) + 1, 0.0);
      p.max.assign(static_cast<std::size_t>(s.frames) + 1, 0.0);
      const auto t0 = Clock::now();
      try {
        for (int c = 0; c < s.copies && octocd::stop_signal() == 0; ++c) {
          const std::vector<std::vector<Vec3>> x =
              run_positions(p.engine, perturbed(*model, p.eps, s.seed, k - first, c), o.settings, s.frames);
          for (std::size_t f = 0; f < x.size() && f < ref.size(); ++f)
            for (const std::size_t i : dynamic) {
              const double dx = double(x[f][i].x) - ref[f][i].x, dy = double(x[f][i].y) - ref[f][i].y,
                           dz = double(x[f][i].z) - ref[f][i].z;
              const double d = std::sqrt(dx * dx + dy * dy + dz * dz);
              p.mean[f] += d;
              p.max[f] = std::isnan(d) ? d : std::max(p.max[f], d);
            }
        }
      } catch (const EngineValueError& e) {
        p.status = "failed";
        p.reason = fmt::format("engine {} failed on a perturbed copy of scene {}: {}", p.engine, scene,
                               bad_values.add(p.id, e));
        any_failed = true;
      } catch (const std::exception& e) {
        p.status = "failed";
        p.reason = fmt::format("engine {} failed on a perturbed copy of scene {}: {}", p.engine, scene, e.what());
        any_failed = true;
      }
      if (octocd::stop_signal() != 0) continue;  // reported at the next point
      const double n = static_cast<double>(std::max<std::size_t>(dynamic.size(), 1)) * s.copies;
      for (double& m : p.mean) m /= n;
      p.seconds = std::chrono::duration<double>(Clock::now() - t0).count() + (k == first ? ref_s : 0.0);
      if (p.status == "ok") {
        if (dynamic.empty()) {
          p.exponent_reason = "no dynamic bodies";
        } else {
          p.exponent = fit_exponent(p.mean, p.dt, p.exponent_reason);
        }
      }
      p.finished = true;
      progress.finish(p.status == "ok"
                          ? fmt::format("ok: mean distance {:.3g} m at frame 0, {:.3g} m at frame {}; exponent {}",
                                        p.mean.front(), p.mean.back(), s.frames,
                                        p.exponent ? fmt::format("{:.3g}/s", *p.exponent) : "none")
                          : p.status + ": " + p.reason);
      write();
    }
  }
  if (const std::optional<int> stopped = finish_sweep(result, write, session)) return *stopped;
  if (std::all_of(points.begin(), points.end(), [](const DvPoint& p) { return p.status == "skipped"; }))
    throw InputError(fmt::format("{}: every point skipped (first: {}: {}); allowed: a sweep with a point this octocd "
                                 "can run (result kept in {})",
                                 origin, points.front().id, points.front().reason, o.output));
  if (!o.quiet)
    fmt::print(stderr, "bench {}: done, result {}, CSV {}\n", printable(s.name), printable(o.output), printable(csv_path));
  bad_values.refuse(o.output);
  return any_failed ? 1 : 0;
}

}  // namespace octocd::cli::bench
