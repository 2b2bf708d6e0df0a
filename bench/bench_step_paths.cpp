// Steps per second of the cuda engine's two step paths in one process (issue 20, item 2):
// "graph" (the per-stage kernels replayed from a CUDA graph, OCTOCD_CUDA_SMALL=0) and
// "small" (the whole step as one cooperative kernel, OCTOCD_CUDA_SMALL=1), beside the cpu
// engine (World with the scene's broadphase; its threads: OpenMP's, e.g. OMP_NUM_THREADS=16).
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
// Usage: bench_step_paths SCENE.json... [--frames 2000] [--warmup 20] [--repeat 5]
//          [--midphase 1,2] [--engines graph,small,cpu] [--small-blocks K,K,...]
// --small-blocks runs the small path once per grid size given (OCTOCD_CUDA_SMALL_BLOCKS;
// default: the engine's own grid), each its own line ("small/K").
// Exit: 0; 1 runtime error (no CUDA device); 2 bad arguments; 3 the state hashes differ.
#include <algorithm>
#include <chrono>
#include <cstdint>
#include <cstdlib>
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
#include "octocd/error.hpp"
#include "octocd/scene.hpp"
#include "octocd/world.hpp"

using namespace octocd;

namespace {

std::unique_ptr<Engine> make(const std::string& engine, const std::shared_ptr<const Model>& model,
                             const std::string& small_blocks) {
  if (engine == "cpu")
    return std::make_unique<World>(model, make_broadphase(model->scene.broadphase, model->scene.domain));
  ::setenv("OCTOCD_CUDA_STAGE_TIMES", "0", 1);
  ::setenv("OCTOCD_CUDA_SMALL", engine == "small" ? "1" : "0", 1);
  if (small_blocks.empty()) ::unsetenv("OCTOCD_CUDA_SMALL_BLOCKS");
  else ::setenv("OCTOCD_CUDA_SMALL_BLOCKS", small_blocks.c_str(), 1);
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
  std::vector<std::string> small_blocks;
  std::vector<std::string> engines = {"graph", "small", "cpu"};
  app.add_option("scenes", scenes, "scene files")->required()->check(CLI::ExistingFile);
  app.add_option("--frames", frames, "timed steps per repetition")->check(CLI::Range(1, 10000000));
  app.add_option("--warmup", warmup, "untimed steps first")->check(CLI::Range(0, 10000000));
  app.add_option("--repeat", repeat, "repetitions (fresh engine each)")->check(CLI::Range(1, 1000));
  app.add_option("--midphase", midphase, "midphase level list for every scene (e.g. 1,2 or aabb-only)");
  app.add_option("--engines", engines, "graph, small, cpu")
      ->delimiter(',')
      ->check(CLI::IsMember({"graph", "small", "cpu"}));
  app.add_option("--small-blocks", small_blocks, "grid sizes (OCTOCD_CUDA_SMALL_BLOCKS) for the small path")
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
      std::vector<std::pair<std::string, std::string>> runs;  // (engine, small blocks)
      for (const std::string& engine : engines) {
        if (engine == "small" && !small_blocks.empty())
          for (const std::string& k : small_blocks) runs.emplace_back(engine, k);
        else
          runs.emplace_back(engine, "");
      }
      for (const auto& [engine, blocks] : runs) {
        std::vector<double> rates;
        std::string path = engine;
        std::uint64_t hash = 0;
        for (int r = 0; r < repeat; ++r) {
          std::unique_ptr<Engine> e = make(engine, model, blocks);
          if (auto* c = dynamic_cast<CudaWorld*>(e.get())) path = c->step_path();
          for (int f = 0; f < warmup; ++f) e->step();
          const auto t0 = std::chrono::steady_clock::now();
          for (int f = 0; f < frames; ++f) e->step();
          const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
          rates.push_back(frames / s);
          hash = e->state_hash();
        }
        const std::string label = blocks.empty() ? engine : engine + "/" + blocks;
        hashes[label] = hash;
        const auto [lo, hi] = std::minmax_element(rates.begin(), rates.end());
        fmt::print("| {} | {} | {} | {} | {:.0f} | {:.0f} | {:.0f} | {:016x} |\n", scene.name, model->initial.size(),
                   label, path, median(rates), *lo, *hi, hash);
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
