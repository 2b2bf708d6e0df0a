// Steps per second of the cuda engine's step paths in one process (issue 20 item 2, issue 33
// item 1), beside the cpu engine (World with the scene's broadphase; its threads: the
// worker team's, octocd/parallel.hpp, e.g. OMP_NUM_THREADS=16). The lines (--engines):
//   run          CudaSettings{} as `octocd run --engine cuda` runs it: the path the scene
//                takes (the resident small step up to kCudaSmallStepMaxBodies bodies, else
//                the graph) with its stage times sampled (stage_time_every);
//   persistent   the bench path: the same path with stage times off (the resident kernel on
//                small scenes);
//   small-timed  the small step launched per step (set_persistent(false)), stage times
//                sampled; small: the same, stage times off;
//   graph-timed  the per-stage kernels from their CUDA graph (small_path off), stage times
//                sampled; graph: the same, stage times off; graph-every: stage times on
//                every step (stage_time_every 1: an event graph every step);
//   cpu          the cpu engine.
// A timed line's "vs untimed" column is its steps/s over its untimed twin's (run /
// persistent, small-timed / small, graph-timed and graph-every / graph), repetition by
// repetition: the median ratio, then the smallest and largest. The small paths' figures are
// the per-step floor including the host's wait.
//
// Per scene and engine, --repeat times: a fresh engine, --warmup untimed steps (buffer
// growth, the graphs' capture), then --frames timed steps; steps/s = frames / wall time.
// Both loops promise their steps (Engine::plan_steps), as `octocd run` without a trace
// does: the resident small step then runs up to 64 steps per request.
// Reported: median, min and max over the repetitions, the path the engine ran, and the
// state hash after the last step (equal on every line of a scene: the paths are bit
// identical; a difference exits 3).
//
// The repetitions of the engines named alternate (rep 1 of each, then rep 2 of each, ...), so
// a drift of the machine spreads over every line alike instead of favouring one.
//
// Usage: bench_step_paths SCENE.json... [--frames 2000] [--warmup 20] [--repeat 5]
//          [--midphase 1,2] [--engines run,persistent,small-timed,small,graph-timed,graph,cpu]
//          (also graph-every)
//          [--stage-time-every K] [--profile]
// The path column says "small+resident" where the kernel was resident. With --profile
// (CudaSettings::small_profile) each small line is followed by the engine's mean time per
// phase (CudaWorld::small_profile, the last repetition).
// Exit: 0; 1 runtime error (no CUDA device); 2 bad arguments; 3 the state hashes differ.
#include <algorithm>
#include <chrono>
#include <cstdint>
#include <exception>
#include <iostream>
#include <map>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include <CLI/CLI.hpp>
#include <fmt/format.h>

#include "octocd/cuda_world.hpp"
#include "octocd/engine.hpp"
#include "octocd/engines.hpp"
#include "octocd/error.hpp"
#include "octocd/scene.hpp"
#include "bench_main.hpp"

using namespace octocd;

namespace {

/// One measured line: an engine of the registry (engines.hpp) and, for the cuda engine,
/// its settings and step path.
struct Run {
  const char* label;
  const char* engine;
  bool stage_times;  ///< CudaSettings::stage_times
  bool every_step;   ///< CudaSettings::stage_time_every = 1 (else --stage-time-every)
  bool small_path;   ///< CudaSettings::small_path
  bool resident;     ///< CudaWorld::set_persistent
  const char* twin;  ///< the untimed line this one is compared with ("": none)
};

constexpr Run kRuns[] = {{"run", "cuda", true, false, true, true, "persistent"},
                         {"persistent", "cuda", false, false, true, true, ""},
                         {"small-timed", "cuda", true, false, true, false, "small"},
                         {"small", "cuda", false, false, true, false, ""},
                         {"graph-timed", "cuda", true, false, false, true, "graph"},
                         {"graph", "cuda", false, false, false, true, ""},
                         {"graph-every", "cuda", true, true, false, true, "graph"},
                         {"cpu", "cpu", true, false, true, true, ""}};

const Run& run_named(const std::string& label) {
  for (const Run& run : kRuns)
    if (label == run.label) return run;
  throw InputError("--engines: unknown line '" + label + "'");
}

/// The engine of the line labelled `label` (one of kRuns).
std::unique_ptr<Engine> make(const std::string& label, const std::shared_ptr<const Model>& model, bool profile,
                             long every) {
  const Run& run = run_named(label);
  // The line's CudaSettings as the registry's items (the cpu line ignores them).
  const auto flag = [](bool b) { return b ? "true" : "false"; };
  EngineSettingItems settings;
  settings["cuda"] = {fmt::format("stage_times={}", flag(run.stage_times)),
                      fmt::format("stage_time_every={}", run.every_step ? 1 : every),
                      fmt::format("small_path={}", flag(run.small_path)),
                      fmt::format("small_profile={}", flag(profile))};
  std::unique_ptr<Engine> e = make_engine(run.engine, model, settings);
  if (auto* c = dynamic_cast<CudaWorld*>(e.get())) c->set_persistent(run.resident);
  return e;
}

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  const std::size_t m = v.size() / 2;
  return v.size() % 2 ? v[m] : 0.5 * (v[m - 1] + v[m]);
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"Steps per second of the cuda engine's step paths, timed and untimed, and the cpu engine"};
  std::vector<std::string> scenes;
  int frames = 2000, warmup = 20, repeat = 5;
  long every = CudaSettings{}.stage_time_every;
  std::string midphase;
  bool profile = false;
  std::vector<std::string> engines = {"run", "persistent", "small-timed", "small", "graph-timed", "graph", "cpu"};
  app.add_option("scenes", scenes, "scene files")->required()->check(CLI::ExistingFile);
  app.add_option("--frames", frames, "timed steps per repetition")->check(CLI::Range(1, 10000000));
  app.add_option("--warmup", warmup, "untimed steps first")->check(CLI::Range(0, 10000000));
  app.add_option("--repeat", repeat, "repetitions (fresh engine each)")->check(CLI::Range(1, 1000));
  app.add_option("--midphase", midphase, "midphase level list for every scene (e.g. 1,2 or aabb-only)");
  app.add_option("--engines", engines,
                 "run, persistent, small-timed, small, graph-timed, graph, graph-every, cpu "
                 "(see the file's comment)")
      ->delimiter(',')
      ->check(CLI::IsMember({"run", "persistent", "small-timed", "small", "graph-timed", "graph", "graph-every",
                             "cpu"}));
  app.add_option("--stage-time-every", every, "CudaSettings::stage_time_every of the timed lines")
      ->check(CLI::Range(1L, 1000000L));
  app.add_flag("--profile", profile, "mean time per phase of the small path's kernel (CudaSettings::small_profile)");
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e) == 0 ? 0 : 2;
  }
  return octocd::bench::exit_code_of("bench_step_paths", [&] {
    int rc = 0;
    fmt::print("| scene | bodies | engine | path | steps/s median | min | max | vs untimed: median (min-max) | "
               "state hash |\n");
    fmt::print("|---|---|---|---|---|---|---|---|---|\n");
    for (const std::string& file : scenes) {
      Scene scene = load_scene(file);
      if (!midphase.empty()) scene.midphase = MidphaseConfig::parse(midphase);
      const std::shared_ptr<const Model> model = build_model(scene);
      std::map<std::string, std::uint64_t> hashes;
      const std::vector<std::string>& runs = engines;
      // Repetition-major: every run's first repetition, then every run's second, ...
      std::vector<std::vector<double>> rates(runs.size());
      std::vector<std::string> paths(runs.size()), profiles(runs.size());
      std::vector<std::uint64_t> run_hashes(runs.size(), 0);
      for (int r = 0; r < repeat; ++r) {
        for (std::size_t i = 0; i < runs.size(); ++i) {
          std::unique_ptr<Engine> e = make(runs[i], model, profile, every);
          paths[i] = runs[i];
          if (auto* c = dynamic_cast<CudaWorld*>(e.get()))
            paths[i] = c->step_path() + (c->persistent() ? "+resident" : "");
          e->plan_steps(warmup);
          for (int f = 0; f < warmup; ++f) e->step();
          const auto t0 = std::chrono::steady_clock::now();
          e->plan_steps(frames);
          for (int f = 0; f < frames; ++f) e->step();
          const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
          rates[i].push_back(frames / s);
          run_hashes[i] = e->state_hash();
          if (auto* c = dynamic_cast<CudaWorld*>(e.get())) profiles[i] = c->small_profile();
        }
      }
      for (std::size_t i = 0; i < runs.size(); ++i) {
        const std::string& label = runs[i];
        hashes[label] = run_hashes[i];
        const auto [lo, hi] = std::minmax_element(rates[i].begin(), rates[i].end());
        // Repetition by repetition against the untimed twin (measured in the same round).
        std::string vs = "";
        const std::string twin = run_named(label).twin;
        const auto t = std::find(runs.begin(), runs.end(), twin);
        if (!twin.empty() && t != runs.end()) {
          std::vector<double> ratio;
          for (std::size_t r = 0; r < rates[i].size(); ++r)
            ratio.push_back(rates[i][r] / rates[static_cast<std::size_t>(t - runs.begin())][r]);
          const auto [rlo, rhi] = std::minmax_element(ratio.begin(), ratio.end());
          vs = fmt::format("{:.3f} ({:.3f}-{:.3f}) of {}", median(ratio), *rlo, *rhi, twin);
        }
        fmt::print("| {} | {} | {} | {} | {:.0f} | {:.0f} | {:.0f} | {} | {:016x} |\n", scene.name,
                   model->initial.size(), label, paths[i], median(rates[i]), *lo, *hi, vs, run_hashes[i]);
        if (!profiles[i].empty()) fmt::print("\n{}: {}\n\n", label, profiles[i]);
        std::fflush(stdout);
      }
      for (const auto& [engine, h] : hashes)
        if (h != hashes.begin()->second) {
          std::cerr << scene.name << ": the state hash of " << engine << " differs from " << hashes.begin()->first
                    << "'s after " << warmup + frames << " steps\n";
          rc = 3;
        }
    }
    return rc;
  });
}
