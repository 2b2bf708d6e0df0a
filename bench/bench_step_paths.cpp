// Steps per second of the cuda engine's step paths in one process (issue 20, item 2):
// "graph" (the per-stage kernels replayed from a CUDA graph, OCTOCD_CUDA_SMALL=0), "small"
// (the whole step as one cooperative kernel launched per step, OCTOCD_CUDA_SMALL=1
// OCTOCD_CUDA_PERSISTENT=0) and "persistent" (the same kernel launched once and resident,
// stepping on request: OCTOCD_CUDA_SMALL=1 OCTOCD_CUDA_PERSISTENT=1), beside the cpu engine
// (World with the scene's broadphase; its threads: OpenMP's, e.g. OMP_NUM_THREADS=16).
// Stage events are off for both cuda paths (OCTOCD_CUDA_STAGE_TIMES=0, as
// reports/h100/floor.md measured the floor), so the figures are the per-step floor including
// the host's wait.
//
// Per scene and engine, --repeat times: a fresh engine, --warmup untimed steps (buffer
// growth, the graph's capture), then --frames timed steps; steps/s = frames / wall time.
// Reported: median, min and max over the repetitions, the path the engine ran, and the
// state hash after the last step (equal on every line of a scene: the paths are bit
// identical; a difference exits 3).
//
// The repetitions of the engines named alternate (rep 1 of each, then rep 2 of each, ...), so
// a drift of the machine spreads over every line alike instead of favouring one.
//
// Usage: bench_step_paths SCENE.json... [--frames 2000] [--warmup 20] [--repeat 5]
//          [--midphase 1,2] [--engines graph,small,persistent,cpu] [--small-blocks K,K,...]
//          [--small-wait poll,sync] [--one-block-pairs P,P,...] [--front-bodies B,B,...]
// --small-blocks runs the small and persistent paths once per grid size given
// (OCTOCD_CUDA_SMALL_BLOCKS; without the option: the environment's value, else the engine's
// own grid; the same for the three switches below), each its own line ("small/K");
// --small-wait once per host wait (OCTOCD_CUDA_SMALL_WAIT, "small/K/sync"; the persistent
// path needs poll: with sync it runs as small), --one-block-pairs once per threshold of the
// one-block response (OCTOCD_CUDA_SMALL_ONE_BLOCK_PAIRS, "small/K/poll/1b=P"),
// --front-bodies once per fused-front bound (OCTOCD_CUDA_SMALL_FRONT_BODIES, ".../front=B");
// all combinations. The path column says "small+resident" where the kernel was resident.
// With OCTOCD_CUDA_SMALL_PROFILE=1 each small line is followed by the engine's mean time per
// phase (CudaWorld::small_profile, the last repetition).
// Exit: 0; 1 runtime error (no CUDA device); 2 bad arguments; 3 the state hashes differ.
#include <algorithm>
#include <chrono>
#include <cstdint>
#include <cstdlib>
#include <exception>
#include <iostream>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include <CLI/CLI.hpp>
#include <fmt/format.h>

#include "octocd/cuda_world.hpp"
#include "octocd/engine.hpp"
#include "octocd/error.hpp"
#include "octocd/scene.hpp"
#include "octocd/world.hpp"

using namespace octocd;

namespace {

/// Sets the environment variable `name` to `value`; an empty `value` gives it back the value
/// it had when first set here (the caller's environment), or unsets it if it had none.
void set_or_restore(const char* name, const std::string& value) {
  static std::map<std::string, std::optional<std::string>> initial;
  auto it = initial.find(name);
  if (it == initial.end()) {
    const char* v = std::getenv(name);
    it = initial.emplace(name, v ? std::optional<std::string>(v) : std::nullopt).first;
  }
  const std::optional<std::string> want = value.empty() ? it->second : std::optional<std::string>(value);
  if (want) ::setenv(name, want->c_str(), 1);
  else ::unsetenv(name);
}

/// One measured configuration: the engine and, for the small path, its switches ("" = the
/// engine's default).
struct Run {
  std::string engine, blocks, wait, one_block, front;
  std::string label() const {
    std::string l = engine;
    if (!blocks.empty()) l += "/" + blocks;
    if (!wait.empty()) l += "/" + wait;
    if (!one_block.empty()) l += "/1b=" + one_block;
    if (!front.empty()) l += "/front=" + front;
    return l;
  }
};

bool fused(const std::string& engine) { return engine == "small" || engine == "persistent"; }

std::unique_ptr<Engine> make(const Run& run, const std::shared_ptr<const Model>& model) {
  const std::string& engine = run.engine;
  if (engine == "cpu")
    return std::make_unique<World>(model, make_broadphase(model->scene.broadphase, model->scene.domain));
  ::setenv("OCTOCD_CUDA_STAGE_TIMES", "0", 1);
  ::setenv("OCTOCD_CUDA_SMALL", fused(engine) ? "1" : "0", 1);
  ::setenv("OCTOCD_CUDA_PERSISTENT", engine == "persistent" ? "1" : "0", 1);
  set_or_restore("OCTOCD_CUDA_SMALL_BLOCKS", run.blocks);
  set_or_restore("OCTOCD_CUDA_SMALL_WAIT", run.wait);
  set_or_restore("OCTOCD_CUDA_SMALL_ONE_BLOCK_PAIRS", run.one_block);
  set_or_restore("OCTOCD_CUDA_SMALL_FRONT_BODIES", run.front);
  return std::make_unique<CudaWorld>(model, model->scene.broadphase.name);
}

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  const std::size_t m = v.size() / 2;
  return v.size() % 2 ? v[m] : 0.5 * (v[m - 1] + v[m]);
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"Steps per second of the cuda engine's graph and small step paths, and the cpu engine"};
  std::vector<std::string> scenes;
  int frames = 2000, warmup = 20, repeat = 5;
  std::string midphase;
  std::vector<std::string> small_blocks, small_waits, one_block_pairs, front_bodies;
  std::vector<std::string> engines = {"graph", "small", "persistent", "cpu"};
  app.add_option("scenes", scenes, "scene files")->required()->check(CLI::ExistingFile);
  app.add_option("--frames", frames, "timed steps per repetition")->check(CLI::Range(1, 10000000));
  app.add_option("--warmup", warmup, "untimed steps first")->check(CLI::Range(0, 10000000));
  app.add_option("--repeat", repeat, "repetitions (fresh engine each)")->check(CLI::Range(1, 1000));
  app.add_option("--midphase", midphase, "midphase level list for every scene (e.g. 1,2 or aabb-only)");
  app.add_option("--engines", engines, "graph, small (a launch per step), persistent (the resident kernel), cpu")
      ->delimiter(',')
      ->check(CLI::IsMember({"graph", "small", "persistent", "cpu"}));
  app.add_option("--small-blocks", small_blocks, "grid sizes (OCTOCD_CUDA_SMALL_BLOCKS) for the small path")
      ->delimiter(',');
  app.add_option("--small-wait", small_waits, "host waits (OCTOCD_CUDA_SMALL_WAIT: poll, sync) for the small path")
      ->delimiter(',')
      ->check(CLI::IsMember({"poll", "sync"}));
  app.add_option("--one-block-pairs", one_block_pairs,
                 "one-block response thresholds (OCTOCD_CUDA_SMALL_ONE_BLOCK_PAIRS) for the small path")
      ->delimiter(',');
  app.add_option("--front-bodies", front_bodies,
                 "fused-front bounds (OCTOCD_CUDA_SMALL_FRONT_BODIES, 0 .. 512) for the small path")
      ->delimiter(',');
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e) == 0 ? 0 : 2;
  }
  int rc = 0;
  try {
    fmt::print("| scene | bodies | engine | path | steps/s median | min | max | state hash |\n");
    fmt::print("|---|---|---|---|---|---|---|---|\n");
    for (const std::string& file : scenes) {
      Scene scene = load_scene(file);
      if (!midphase.empty()) scene.midphase = MidphaseConfig::parse(midphase);
      const std::shared_ptr<const Model> model = build_model(scene);
      std::map<std::string, std::uint64_t> hashes;
      std::vector<Run> runs;
      const auto or_default = [](const std::vector<std::string>& v) {
        return v.empty() ? std::vector<std::string>{""} : v;
      };
      for (const std::string& engine : engines) {
        if (!fused(engine)) {
          runs.push_back(Run{engine, "", "", "", ""});
          continue;
        }
        for (const std::string& k : or_default(small_blocks))
          for (const std::string& w : or_default(small_waits))
            for (const std::string& p : or_default(one_block_pairs))
              for (const std::string& b : or_default(front_bodies)) runs.push_back(Run{engine, k, w, p, b});
      }
      // Repetition-major: every run's first repetition, then every run's second, ...
      std::vector<std::vector<double>> rates(runs.size());
      std::vector<std::string> paths(runs.size()), profiles(runs.size());
      std::vector<std::uint64_t> run_hashes(runs.size(), 0);
      for (int r = 0; r < repeat; ++r) {
        for (std::size_t i = 0; i < runs.size(); ++i) {
          std::unique_ptr<Engine> e = make(runs[i], model);
          paths[i] = runs[i].engine;
          if (auto* c = dynamic_cast<CudaWorld*>(e.get()))
            paths[i] = c->step_path() + (c->persistent() ? "+resident" : "");
          for (int f = 0; f < warmup; ++f) e->step();
          const auto t0 = std::chrono::steady_clock::now();
          for (int f = 0; f < frames; ++f) e->step();
          const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
          rates[i].push_back(frames / s);
          run_hashes[i] = e->state_hash();
          if (auto* c = dynamic_cast<CudaWorld*>(e.get())) profiles[i] = c->small_profile();
        }
      }
      for (std::size_t i = 0; i < runs.size(); ++i) {
        const std::string label = runs[i].label();
        hashes[label] = run_hashes[i];
        const auto [lo, hi] = std::minmax_element(rates[i].begin(), rates[i].end());
        fmt::print("| {} | {} | {} | {} | {:.0f} | {:.0f} | {:.0f} | {:016x} |\n", scene.name, model->initial.size(),
                   label, paths[i], median(rates[i]), *lo, *hi, run_hashes[i]);
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
  } catch (const InputError& e) {
    std::cerr << "bench_step_paths: bad input: " << e.what() << "\n";
    return 2;
  } catch (const std::exception& e) {
    std::cerr << "bench_step_paths: runtime failure: " << e.what() << "\n";
    return 1;
  }
  return rc;
}
