// Side-by-side broadphase timing on identical recorded frames (issue 3 item 6b, design.md section 9's
// `replay` idea, as Broadmark does): a scene is run once with the CPU reference, the world
// AABBs of `--frames` consecutive frames (after `--warmup` frames) are recorded, and every
// broadphase (octocd's and the Bullet/FCL references) replays exactly those frames.
// Each broadphase first replays the recorded frames `--warm-replays` times (default 1)
// untimed: proxy creation and tree build ("initial step can be expensive"), and time for
// incremental structures to settle (Bullet's dbvt re-balances a little on every call: its
// first replay of boxes-uniform-50000 is about 9x slower than the following ones). Reported: ms per frame (Google Benchmark's real time
// per iteration divided by the frame count) with counters `pairs` and `candidates`.
//
// With --benchmark_repetitions=R each broadphase is run R times; the aggregates include
// the minimum and maximum over the repetitions besides Google Benchmark's mean, median and stddev
// (bench/broadphase_table.py reports the median and the minimum).
//
// Usage: bench_broadphase SCENE.json [--frames N] [--warmup N] [--warm-replays N]
//                         [--only a,b] [benchmark flags]
#include <benchmark/benchmark.h>

#include <algorithm>
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
  int warm_replays = 1;
  std::vector<std::vector<octocd::Aabb>> frames;
};

void replay(benchmark::State& state, const Recording* rec, std::string name) {
  octocd::BroadPhaseConfig cfg = rec->scene.broadphase;
  cfg.name = name;
  auto bp = octocd::make_any_broadphase(cfg, rec->scene.domain);
  std::vector<octocd::Pair> pairs;
  octocd::BroadPhaseStats stats;
  for (int r = 0; r < rec->warm_replays; ++r) {  // not timed
    for (const auto& boxes : rec->frames) bp->find_pairs(boxes, pairs, stats);
  }
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
    std::fprintf(stderr,
                 "usage: %s SCENE.json [--frames N] [--warmup N] [--warm-replays N] [--only a,b] "
                 "[benchmark flags]\n",
                 argv[0]);
    return 2;
  }
  int frames = 20, warmup = 200, warm_replays = 1;
  std::string only;
  std::vector<char*> rest{argv[0]};
  for (int i = 2; i < argc; ++i) {
    if (!std::strcmp(argv[i], "--frames") && i + 1 < argc) {
      frames = std::atoi(argv[++i]);
    } else if (!std::strcmp(argv[i], "--warmup") && i + 1 < argc) {
      warmup = std::atoi(argv[++i]);
    } else if (!std::strcmp(argv[i], "--warm-replays") && i + 1 < argc) {
      warm_replays = std::atoi(argv[++i]);
    } else if (!std::strcmp(argv[i], "--only") && i + 1 < argc) {
      only = std::string(",") + argv[++i] + ",";
    } else {
      rest.push_back(argv[i]);
    }
  }
  static Recording rec;
  rec.warm_replays = warm_replays < 0 ? 0 : warm_replays;
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
    // On a shared machine the minimum over repetitions is the steadiest figure.
    b->ComputeStatistics("min", [](const std::vector<double>& v) {
      return *std::min_element(v.begin(), v.end());
    });
    b->ComputeStatistics("max", [](const std::vector<double>& v) {
      return *std::max_element(v.begin(), v.end());
    });
    // O(n^2) ones at 10k bodies take seconds per replay: one iteration, one repetition.
    if (octocd::find_broadphase_info(name)->cost == octocd::BroadPhaseCost::quadratic)
      b->Iterations(1)->Repetitions(1);
  }
  int bargc = static_cast<int>(rest.size());
  benchmark::Initialize(&bargc, rest.data());
  benchmark::AddCustomContext("scene", rec.scene.name);
  benchmark::AddCustomContext("recorded_frames", std::to_string(rec.frames.size()));
  benchmark::AddCustomContext("warmup_frames", std::to_string(warmup));
  benchmark::AddCustomContext("warm_replays", std::to_string(rec.warm_replays));
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
