// The max-instances search of `octocd bench` (bench_sweep.hpp): per model and engine, the
// largest instance count whose steps/s over the window reach the target, by doubling from 1,
// bisection, and the bracket's ends measured again with the sweep's repetitions.
#include <algorithm>
#include <cmath>
#include <new>

#include <fmt/format.h>

#include "bench_sweep.hpp"
#include "octocd/error.hpp"
#include "octocd/process_engines.hpp"
#include "octocd/stop.hpp"

namespace octocd::cli::bench {

namespace {

/// A probe's outcome as the search sees it.
enum class Verdict {
  Pass,     ///< steps/s (median over the repetitions) >= the target
  Below,    ///< steps/s below the target
  Limit,    ///< the count does not fit (device or host memory, the engine's body limit): above the maximum
  Skipped,  ///< the engine cannot run at all (count 1): the search is skipped
  Failed,   ///< a runtime failure (e.g. a non-finite state): the search stops
  TimeUp    ///< the search's time limit passed before this count was measured: it ends as it is
};

/// The bracket a search ends with: lo = the largest count found to pass (0: none), hi = the
/// smallest count above lo found not to pass (-1: none, lo is the cap).
struct Bracket {
  long lo = 0, hi = -1;
};

/// Doubling from 1, then bisection, on `decide` (called once per count it needs; the caller
/// memoizes): ends when hi - lo <= max(1, floor(resolution x lo)). A count that is not Pass
/// counts as above the maximum (Below, Limit); Skipped, Failed or TimeUp end the search at
/// once (`*stop` set to that verdict).
Bracket search_bracket(long cap, double resolution, const std::function<Verdict(long)>& decide, Verdict* stop) {
  *stop = Verdict::Pass;
  const auto pass = [&](long n) {
    const Verdict v = decide(n);
    if (v == Verdict::Skipped || v == Verdict::Failed || v == Verdict::TimeUp) *stop = v;
    return v == Verdict::Pass;
  };
  Bracket b;
  if (!pass(1)) {
    b.hi = 1;
    return b;
  }
  b.lo = 1;
  // One count: false when the search ends there (the bracket left as it was).
  const auto step = [&](long n) {
    const bool ok = pass(n);
    if (*stop != Verdict::Pass) return false;
    (ok ? b.lo : b.hi) = n;
    return true;
  };
  while (b.hi < 0) {
    if (b.lo >= cap) return b;  // the cap still passes
    if (!step(std::min(2 * b.lo, cap))) return b;
  }
  while (b.hi - b.lo > std::max<long>(1, static_cast<long>(std::floor(resolution * static_cast<double>(b.lo))))) {
    if (!step(b.lo + (b.hi - b.lo) / 2)) return b;
  }
  return b;
}

/// Whether a runtime failure is memory running out (cudaMalloc, the CUDA engine's memory
/// check, std::bad_alloc's text): the count does not fit, a limit, not a failure.
bool is_memory_failure(const std::string& what) {
  for (const char* k : {"cudaMalloc", "out of memory", "of device memory", "std::bad_alloc", "bad_alloc"})
    if (what.find(k) != std::string::npos) return true;
  return false;
}

/// One measured (or resumed) count: its point in the result and the verdict.
struct Measured {
  Verdict verdict = Verdict::Below;
  json point;
};

Measured measure_count(MaxInstancesRun& run, std::size_t sc, const std::string& engine, long n, bool confirm,
                       std::size_t search) {
  const Sweep& s = run.s;
  const int reps = confirm ? s.repeat : s.probe_repeat;
  Point p;
  p.scene = sc;
  p.engine = engine;
  p.id = fmt::format("{} | instances={} | {}{}", stem(s.scenes[sc]), n, engine, confirm ? " | confirm" : "");
  json r;
  const auto kept = run.kept.find(p.id);
  if (kept != run.kept.end()) {
    r = kept->second;  // resumed: already in result["points"]
    run.visited.insert(p.id);
  } else {
    if (const int sig = octocd::stop_signal()) {
      (void)sig;
      throw BenchStopped{};
    }
    p.index = run.next_index++;
    run.progress.start(search, p.id);
    json layout;
    std::string text;
    try {
      text = instance_scene(s, sc, n, &layout);
      StepsOverride ov;
      ov.text = &text;
      ov.repeat = reps;
      ov.cut_below = s.target;
      ov.max_bodies = limits::kMaxGeneratedBodies;  // memory, not the file limit, ends the search
      r = run_steps_point(s, p, run.models, run.o, run.progress, ov);
    } catch (const BenchStopped&) {
      throw;
    } catch (const EngineValueError& e) {  // bad input from the engine: the probe fails, the bench exits 2
      r = json::object();
      r["status"] = "failed";
      r["reason"] = run.bad_values.add(p.id, e);
    } catch (const InputError& e) {
      if (n == 1) throw;  // the template itself is refused: bad input
      r = json::object();
      r["status"] = "skipped";
      r["reason"] = std::string("scene: ") + e.what();
    } catch (const std::bad_alloc&) {
      r = json::object();
      r["status"] = "skipped";
      r["reason"] = fmt::format("host memory: {} instances do not fit (std::bad_alloc)", n);
      run.models = ModelCache{};
    } catch (const std::exception& e) {
      r = json::object();
      r["status"] = is_memory_failure(e.what()) ? "skipped" : "failed";
      r["reason"] = e.what();
    }
    r["id"] = p.id;
    r["index"] = p.index;
    r["params"]["scene"] = stem(s.scenes[sc]);
    r["params"]["engine"] = engine;
    r["params"]["axes"]["instances"] = n;
    r["role"] = confirm ? "confirm" : "probe";
    r["target_steps_per_s"] = s.target;
    if (!layout.is_null()) r["scene"] = layout;
    r["finished"] = utc_time_now();
    r["load_average"] = load_average();
    {
      const long threads = run.result["machine"].value("threads", 0L);
      const json& la = r["load_average"];
      r["under_load"] = threads > 0 && !la.empty() && la[0].get<double>() > static_cast<double>(threads) + 1.0;
    }
    // The verdict, stored with the point so that a resumed run decides the same.
    const std::string status = r.value("status", "");
    if (status == "ok") {
      const double med = r["windows"][s.windows[0].name]["steps_per_s"].value("median", 0.0);
      r["verdict"] = med >= s.target ? "pass" : "below";
    } else if (status == "skipped") {
      // Count 1 that cannot start: the engine is missing (skip the search), unless the one
      // instance does not fit (a limit: the result is 0 with the reason).
      r["verdict"] = n == 1 && !is_memory_failure(r.value("reason", "")) ? "skipped" : "limit";
    } else {
      r["verdict"] = "failed";
    }
    std::string line = r.value("status", "?");
    if (status == "ok")
      line += fmt::format(" ({:.1f} steps/s median, {} {} {:g}{})",
                          r["windows"][s.windows[0].name]["steps_per_s"].value("median", 0.0),
                          r["verdict"] == "pass" ? "pass:" : "below", r["verdict"] == "pass" ? ">=" : "<", s.target,
                          r.contains("cut") && r["cut"].value("repetitions_cut", 0) > 0 ? ", cut short" : "");
    else
      line += ": " + r.value("reason", "");
    run.progress.finish(line);
    if (status == "failed") run.any_failed = true;
    run.result["points"].push_back(r);
    run.result["points_total"] = run.result["points"].size();
    run.write();
  }
  Measured m;
  m.point = r;
  const std::string v = r.value("verdict", "");
  m.verdict = v == "pass"      ? Verdict::Pass
              : v == "below"   ? Verdict::Below
              : v == "limit"   ? Verdict::Limit
              : v == "skipped" ? Verdict::Skipped
                               : Verdict::Failed;
  return m;
}

}  // namespace

json search_max_instances(MaxInstancesRun& run, std::size_t sc, const std::string& engine, std::size_t search) {
  const Sweep& s = run.s;
  std::map<long, Measured> probe, full;
  const auto started = Clock::now();
  const auto time_up = [&] {
    return s.search_time_s > 0 &&
           std::chrono::duration<double>(Clock::now() - started).count() > static_cast<double>(s.search_time_s);
  };
  const auto decide = [&](long n) {
    const auto f = full.find(n);
    if (f != full.end()) return f->second.verdict;
    auto it = probe.find(n);
    if (it == probe.end()) {
      if (time_up() && !run.kept.count(fmt::format("{} | instances={} | {}", stem(s.scenes[sc]), n, engine)))
        return Verdict::TimeUp;
      it = probe.emplace(n, measure_count(run, sc, engine, n, false, search)).first;
    }
    return it->second.verdict;
  };
  const bool confirming = s.repeat > s.probe_repeat;
  Bracket b;
  Verdict stop = Verdict::Pass;
  bool unconfirmed = false;  // the time limit came before the bracket's ends were confirmed
  for (;;) {
    b = search_bracket(s.max_instances, s.resolution, decide, &stop);
    if (stop != Verdict::Pass || !confirming) break;
    if (time_up()) {
      unconfirmed = (b.lo >= 1 && !full.count(b.lo)) || (b.hi >= 1 && !full.count(b.hi));
      break;
    }
    bool measured = false;
    for (const long n : {b.lo, b.hi}) {
      if (n < 1 || full.count(n)) continue;
      if (probe.count(n) && probe.at(n).verdict != Verdict::Pass && probe.at(n).verdict != Verdict::Below) continue;
      full.emplace(n, measure_count(run, sc, engine, n, true, search));
      measured = true;
    }
    if (!measured) break;
  }
  const auto measured_at = [&](long n) -> const Measured* {
    if (full.count(n)) return &full.at(n);
    if (probe.count(n)) return &probe.at(n);
    return nullptr;
  };
  const std::string scene = stem(s.scenes[sc]);
  json sum{{"scene", scene}, {"engine", engine}, {"target_steps_per_s", s.target}, {"max_instances_cap", s.max_instances},
           {"resolution", s.resolution}, {"window", {{"first", s.windows[0].first}, {"last", s.windows[0].last}}},
           {"probes", probe.size()}, {"confirmations", full.size()}};
  try {
    const json t = json::parse(scene_text(s, [&] {
      Point p;
      p.scene = sc;
      return p;
    }()));
    sum["model"] = t["groups"][0]["shape"].value("mesh", t["groups"][0].value("name", scene));
  } catch (const std::exception&) {
    sum["model"] = scene;
  }
  if (s.paper.contains(scene)) sum["paper"] = s.paper[scene];
  const auto sps = [&](long n) -> json {
    const Measured* m = measured_at(n);
    if (!m || m->point.value("status", "") != "ok") return nullptr;
    return m->point["windows"][s.windows[0].name]["steps_per_s"];
  };
  if (stop == Verdict::Skipped) {
    const Measured* m = measured_at(1);
    sum["status"] = "skipped";
    sum["reason"] = m ? m->point.value("reason", "") : "";
    return sum;
  }
  if (stop == Verdict::Failed) {
    long at = -1;
    for (const auto& [n, m] : probe)
      if (m.verdict == Verdict::Failed) at = n;
    for (const auto& [n, m] : full)
      if (m.verdict == Verdict::Failed) at = n;
    const Measured* m = measured_at(at);
    sum["status"] = "failed";
    sum["reason"] = fmt::format("{} instances: {}", at, m ? m->point.value("reason", "") : "");
    sum["bracket"] = {b.lo, nullptr};
    return sum;
  }
  sum["status"] = "ok";
  sum["max_instances"] = b.lo;
  const bool timed_out = stop == Verdict::TimeUp || unconfirmed;
  sum["bracket"] = {b.lo, b.hi < 0 ? json(nullptr) : json(b.hi)};
  sum["steps_per_s"] = sps(b.lo);
  if (b.hi > 0) {
    sum["steps_per_s_above"] = sps(b.hi);
    // Cut repetitions hold upper bounds (docs/bench-format.md): say so beside the figure.
    const Measured* m = measured_at(b.hi);
    sum["steps_per_s_above_cut"] = m && m->point.contains("cut") && m->point["cut"].value("repetitions_cut", 0) > 0;
  }
  const Measured* at_lo = measured_at(b.lo);
  const Measured* at_hi = b.hi > 0 ? measured_at(b.hi) : nullptr;
  if (at_lo) sum["repetitions_at_max"] = at_lo->point["windows"][s.windows[0].name]["steps_per_s"].value("n", 0);
  std::string reason;
  if (b.lo == 0) {
    sum["limited_by"] = !(at_hi && at_hi->verdict == Verdict::Limit) ? "steps/s"
                        : is_memory_failure(at_hi->point.value("reason", "")) ? "memory"
                                                                               : "limit";
    reason = at_hi && at_hi->verdict == Verdict::Limit
                 ? "a single instance does not fit: " + at_hi->point.value("reason", "")
                 : fmt::format("a single instance already runs under {:g} steps/s ({:.2f} steps/s median over {} "
                               "repetition(s))",
                               s.target, sps(1).is_null() ? 0.0 : sps(1).value("median", 0.0),
                               sps(1).is_null() ? 0 : sps(1).value("n", 0));
  } else if (b.hi < 0 && stop == Verdict::TimeUp) {
    reason = fmt::format("{} instances run at >= {:g} steps/s; no higher count was measured", b.lo, s.target);
  } else if (b.hi < 0) {
    sum["limited_by"] = "cap";
    reason = fmt::format("the cap max_instances = {} still runs at >= {:g} steps/s: the maximum is at least {} (raise "
                         "--max-instances)",
                         s.max_instances, s.target, s.max_instances);
  } else if (at_hi && at_hi->verdict == Verdict::Limit) {
    sum["limited_by"] = is_memory_failure(at_hi->point.value("reason", "")) ? "memory" : "limit";
    reason = fmt::format("{} instances do not fit, so the search stopped there: {}", b.hi,
                         at_hi->point.value("reason", ""));
  } else {
    sum["limited_by"] = "steps/s";
    reason = b.hi == b.lo + 1
                 ? fmt::format("{} instances run at >= {:g} steps/s, {} below", b.lo, s.target, b.hi)
                 : fmt::format("{} instances run at >= {:g} steps/s, {} below; counts between were not probed "
                               "(resolution {:g})",
                               b.lo, s.target, b.hi, s.resolution);
  }
  if (timed_out) {
    sum["time_limit_s"] = s.search_time_s;
    const long width = std::max<long>(1, static_cast<long>(std::floor(s.resolution * static_cast<double>(b.lo))));
    reason += fmt::format(
        "; the search's time limit ({} s) ended it{}", s.search_time_s,
        b.hi < 0 && b.lo < s.max_instances
            ? ": the maximum is at least " + std::to_string(b.lo)
            : b.hi - b.lo > width ? std::string(" before the bracket was narrowed further")
                                  : fmt::format(" before the bracket's ends were measured with {} repetitions", s.repeat));
    if (b.hi < 0 && b.lo < s.max_instances) sum["limited_by"] = "time";
  }
  sum["reason"] = reason;
  return sum;
}
}  // namespace octocd::cli::bench
