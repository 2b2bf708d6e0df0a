// Side-by-side broadphase timing on identical recorded frames (issue 3 item 6b, SPEC 9's
// `replay` idea, as Broadmark does): a scene is run once with the CPU reference, the world
// AABBs of `--frames` consecutive frames (after `--warmup` frames) are recorded, and every
// broadphase (octocd's and the Bullet/FCL references) replays exactly those frames.
// Each broadphase's first call (proxy creation, tree build) is made before timing, apart
// ("initial step can be expensive"). Reported: ms per frame (Google Benchmark's real time
// per iteration divided by the frame count) with counters `pairs` and `candidates`.
//
// Usage: bench_broadphase SCENE.json [--frames N] [--warmup N] [--only a,b] [benchmark flags]
#include <benchmark/benchmark.h>

#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

#include "octocd/reference_broadphase.hpp"
#include "octocd/scene.hpp"
#include "octocd/world.hpp"

namespace {

struct Recording {
  octocd::Scene scene;
  std::vector<std::vector<octocd::Aabb>> frames;
};

void replay(benchmark::State& state, const Recording* rec, std::string name) {
  octocd::BroadPhaseConfig cfg = rec->scene.broadphase;
  cfg.name = name;
  auto bp = octocd::make_any_broadphase(cfg, rec->scene.domain);
  std::vector<octocd::Pair> pairs;
  octocd::BroadPhaseStats stats;
  bp->find_pairs(rec->frames.front(), pairs, stats);  // first call, not timed
  double total_pairs = 0, total_candidates = 0;
  for (auto _ : state) {
    total_pairs = total_candidates = 0;
    for (const auto& boxes : rec->frames) {
      bp->find_pairs(boxes, pairs, stats);
      total_pairs += static_cast<double>(pairs.size());
      total_candidates += static_cast<double>(stats.cell_candidates);
    }
    benchmark::DoNotOptimize(pairs.data());
  }
  const double n = static_cast<double>(rec->frames.size());
  state.counters["frames"] = n;
  state.counters["pairs"] = total_pairs / n;
  state.counters["candidates"] = total_candidates / n;
  state.counters["bodies"] = static_cast<double>(rec->frames.front().size());
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 2 || argv[1][0] == '-') {
    std::fprintf(stderr, "usage: %s SCENE.json [--frames N] [--warmup N] [--only a,b] [benchmark flags]\n",
                 argv[0]);
    return 2;
  }
  int frames = 20, warmup = 200;
  std::string only;
  std::vector<char*> rest{argv[0]};
  for (int i = 2; i < argc; ++i) {
    if (!std::strcmp(argv[i], "--frames") && i + 1 < argc) {
      frames = std::atoi(argv[++i]);
    } else if (!std::strcmp(argv[i], "--warmup") && i + 1 < argc) {
      warmup = std::atoi(argv[++i]);
    } else if (!std::strcmp(argv[i], "--only") && i + 1 < argc) {
      only = std::string(",") + argv[++i] + ",";
    } else {
      rest.push_back(argv[i]);
    }
  }
  static Recording rec;
  try {
    rec.scene = octocd::load_scene(argv[1]);
    octocd::World world(rec.scene);
    for (int f = 0; f < warmup; ++f) world.step();
    for (int f = 0; f < frames; ++f) {
      world.step();
      rec.frames.push_back(world.world_aabbs());
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "bench_broadphase: %s\n", e.what());
    return 2;
  }
  for (const std::string& name : octocd::all_broadphase_names()) {
    if (!only.empty() && only.find("," + name + ",") == std::string::npos) continue;
    auto* b = benchmark::RegisterBenchmark((rec.scene.name + "/" + name).c_str(), replay, &rec, name);
    b->Unit(benchmark::kMillisecond)->UseRealTime();
    // O(n^2) ones at 10k bodies take seconds per replay: one repetition is enough.
    if (name == "flat" || name == "fcl-naive") b->Iterations(1);
  }
  int bargc = static_cast<int>(rest.size());
  benchmark::Initialize(&bargc, rest.data());
  benchmark::AddCustomContext("scene", rec.scene.name);
  benchmark::AddCustomContext("recorded_frames", std::to_string(rec.frames.size()));
  benchmark::AddCustomContext("warmup_frames", std::to_string(warmup));
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
