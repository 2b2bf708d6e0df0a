// The coherent-motion sequence of the GPU broadphase bench (bench_gpu_broadphase.cpp's
// comment: "Coherent motion"): the boxes moving, `octree` with its pair cache against the
// one-shot `octree`, checked every step; its table and JSON.
#include "bench_gpu_motion.hpp"

namespace gpu_bench {

/// Mean of v over the steps whose plan is `plan` (0 when none).
double mean_of_plan(const std::vector<double>& v, const std::vector<int>& plans, int plan) {
  double t = 0.0;
  int k = 0;
  for (std::size_t i = 0; i < v.size(); ++i)
    if (plans[i] == plan) {
      t += v[i];
      ++k;
    }
  return k ? t / k : 0.0;
}

/// The bench's boxes moving at constant velocity (a random direction, speed uniform in
/// [0, --motion-speed)), reflected at the centres' cube; the oracle (CPU `flat` up to
/// --cpu-flat-max bodies, else the CPU `octree`, one instance over the sequence) every
/// --motion-oracle-every steps; the two device sets compared every step. Each broadphase
/// is replayed from CUDA graphs with --graph (the coherent one: a graph per plan).
MotionResult run_motion(std::uint32_t n, float fraction, const Options& o, cudaStream_t stream) {
  MotionResult r;
  r.n = n;
  r.margin = fraction;
  std::vector<Aabb> boxes = make_boxes(n, o.seed);
  const Aabb domain = domain_for(n);
  const float h = static_cast<float>(cube_side(n) / 2.0);
  std::vector<float> c(3 * static_cast<std::size_t>(n)), v(3 * static_cast<std::size_t>(n));
  octocd::SplitMix64 rng(o.seed + 0x5bd1e995ull);
  for (std::uint32_t i = 0; i < n; ++i) {
    float d[3];
    float len = 0.0f;
    do {
      for (float& x : d) x = rng.uniform(-1.0f, 1.0f);
      len = std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
    } while (len > 1.0f || len < 1e-3f);
    const float speed = o.motion_speed * rng.unit();
    for (int a = 0; a < 3; ++a) v[3 * i + a] = speed * d[a] / len;
    c[3 * i] = 0.5f * (boxes[i].min.x + boxes[i].max.x);
    c[3 * i + 1] = 0.5f * (boxes[i].min.y + boxes[i].max.y);
    c[3 * i + 2] = 0.5f * (boxes[i].min.z + boxes[i].max.z);
  }
  BroadPhaseConfig cfg;
  cfg.name = broadphase_name(BroadPhaseId::octree);
  cfg.octree_depth = o.depth;
  auto coherent = octocd::gpu::make_device_coherent_octree(cfg, domain, fraction);
  auto oneshot = octocd::gpu::make_device_broadphase(cfg, domain);
  BroadPhaseConfig ocfg;
  ocfg.name = broadphase_name(n <= o.cpu_flat_max ? BroadPhaseId::flat : BroadPhaseId::octree);
  ocfg.octree_depth = -1;
  auto cpu = octocd::make_broadphase(ocfg, domain);
  const int shift = octocd::gpu::key_bits(n);
  DeviceBuffer<Aabb> d_boxes("motion AABBs");
  octocd::gpu::upload(d_boxes, boxes, stream);
  coherent->reserve(n, stream);
  oneshot->reserve(n, stream);
  std::size_t cap = 2 * static_cast<std::size_t>(n) + 64;
  DeviceBuffer<unsigned long long> keys_c("coherent keys"), scratch_c("coherent scratch"), keys_o("one-shot keys"),
      scratch_o("one-shot scratch");
  DeviceBuffer<std::uint32_t> total("pair total");
  DeviceBuffer<unsigned long long> candidates("exact tests");
  total.reset(1);
  candidates.reset(1);
  for (auto* b : {&keys_c, &scratch_c, &keys_o, &scratch_o}) b->reset(cap);
  HostCounters host;
  Event start, stop;
  Graph g_oneshot;
  Graph g_plan[octocd::gpu::kBroadPhasePlans];
  auto drop_graphs = [&] {
    for (Graph* g : {&g_oneshot, &g_plan[0], &g_plan[1], &g_plan[2]}) {
      if (g->exec) (void)cudaGraphExecDestroy(g->exec);
      if (g->graph) (void)cudaGraphDestroy(g->graph);
      g->exec = nullptr;
      g->graph = nullptr;
    }
  };
  auto out_for = [&](DeviceBuffer<unsigned long long>& k, DeviceBuffer<unsigned long long>& sc) {
    octocd::gpu::PairOutput out;
    out.keys = k.get();
    out.scratch = sc.get();
    out.capacity = static_cast<std::uint32_t>(cap);
    out.total = total.get();
    out.candidates = candidates.get();
    out.shift = shift;
    return out;
  };
  // Enqueues bp's find() (from its graph with --graph, captured on first use); returns
  // the GPU time between events around it and the total it reports.
  auto timed_find = [&](DeviceBroadPhase& bp, Graph& g, const octocd::gpu::PairOutput& out) {
    if (o.graph && !g.exec) {
      check(cudaStreamBeginCapture(stream, cudaStreamCaptureModeThreadLocal), "cudaStreamBeginCapture (motion)");
      bp.find(d_boxes.get(), n, out, stream);
      check(cudaStreamEndCapture(stream, &g.graph), "cudaStreamEndCapture (motion)");
      check(cudaGraphInstantiate(&g.exec, g.graph, 0), "cudaGraphInstantiate (motion)");
    }
    check(cudaEventRecord(start.e, stream), "cudaEventRecord");
    if (o.graph)
      check(cudaGraphLaunch(g.exec, stream), "cudaGraphLaunch (motion)");
    else
      bp.find(d_boxes.get(), n, out, stream);
    check(cudaEventRecord(stop.e, stream), "cudaEventRecord");
    check(cudaMemcpyAsync(host.total, total.get(), sizeof(std::uint32_t), cudaMemcpyDeviceToHost, stream),
          "cudaMemcpyAsync (motion total)");
    check(cudaStreamSynchronize(stream), "cudaStreamSynchronize (motion)");
    float ms = 0.0f;
    check(cudaEventElapsedTime(&ms, start.e, stop.e), "cudaEventElapsedTime");
    return std::make_pair(static_cast<double>(ms), *host.total);
  };
  auto grow = [&](std::uint32_t needed) {
    cap = grown(needed, cap);
    for (auto* b : {&keys_c, &scratch_c, &keys_o, &scratch_o}) b->reset(cap);
    drop_graphs();
  };
  std::vector<unsigned long long> hc, ho, oracle;
  std::vector<octocd::Pair> cpu_pairs;
  for (int step = 0; step < o.motion_steps; ++step) {
    // The one-shot octree (its pairs sorted given the scratch).
    std::pair<double, std::uint32_t> t1 = timed_find(*oneshot, g_oneshot, out_for(keys_o, scratch_o));
    while (t1.second > cap) {
      grow(t1.second);
      t1 = timed_find(*oneshot, g_oneshot, out_for(keys_o, scratch_o));
    }
    // The pair cache: every find() of the step is timed, reruns included.
    double ms = 0.0;
    std::uint32_t pairs = 0;
    int plan = 0;
    for (int attempt = 0;; ++attempt) {
      if (attempt > 8) throw octocd::RuntimeError("the pair cache did not settle in 8 calls");
      plan = coherent->plan();
      const auto t2 = timed_find(*coherent, g_plan[plan], out_for(keys_c, scratch_c));
      ms += t2.first;
      const octocd::gpu::Settled verdict = coherent->settle();
      if (verdict == octocd::gpu::Settled::Regrow) {
        ++r.regrows;
        coherent->reserve(n, stream);
        drop_graphs();
        continue;
      }
      if (verdict == octocd::gpu::Settled::Rerun) {
        ++r.reruns;
        continue;
      }
      if (t2.second > cap) {
        grow(t2.second);
        continue;
      }
      pairs = t2.second;
      break;
    }
    r.coherent_ms.push_back(ms);
    r.oneshot_ms.push_back(t1.first);
    r.plans.push_back(plan);
    if (step == 0) r.pairs_first = pairs;
    r.pairs_last = pairs;
    // The checks: the two device sets bit for bit (keys and order), the CPU oracle.
    hc.resize(pairs);
    ho.resize(t1.second);
    if (pairs > 0)
      check(cudaMemcpyAsync(hc.data(), keys_c.get(), pairs * 8ull, cudaMemcpyDeviceToHost, stream), "download");
    if (t1.second > 0)
      check(cudaMemcpyAsync(ho.data(), keys_o.get(), t1.second * 8ull, cudaMemcpyDeviceToHost, stream), "download");
    check(cudaStreamSynchronize(stream), "cudaStreamSynchronize (motion download)");
    if (r.check_ok && hc != ho) {
      r.check_ok = false;
      r.check = fmt::format("step {}: the pair cache's {} keys differ from the one-shot octree's {}", step, hc.size(),
                            ho.size());
    }
    if (r.check_ok && o.motion_oracle_every > 0 && step % o.motion_oracle_every == 0) {
      octocd::BroadPhaseStats stats;
      cpu->find_pairs(boxes, cpu_pairs, stats);
      oracle.clear();
      for (const octocd::Pair& p : cpu_pairs) oracle.push_back((static_cast<unsigned long long>(p.a) << shift) | p.b);
      ++r.oracle_checks;
      if (oracle != hc) {
        r.check_ok = false;
        r.check = fmt::format("step {}: the pair cache's {} keys differ from CPU `{}`'s {}", step, hc.size(),
                              ocfg.name, oracle.size());
      }
    }
    // Move: x += v dt, velocities reflected at the cube's faces.
    for (std::uint32_t i = 0; i < n; ++i) {
      const float e = (i % 2 == 0) ? kHalfLarge : kHalfSmall;
      for (int a = 0; a < 3; ++a) {
        float& x = c[3 * i + a];
        x += v[3 * i + a] * o.motion_dt;
        if (x < -h || x > h) v[3 * i + a] = -v[3 * i + a];
      }
      boxes[i] = {{c[3 * i] - e, c[3 * i + 1] - e, c[3 * i + 2] - e}, {c[3 * i] + e, c[3 * i + 1] + e, c[3 * i + 2] + e}};
    }
    octocd::gpu::upload(d_boxes, boxes, stream, false);
  }
  drop_graphs();
  r.ok = true;
  return r;
}

std::string plan_counts(const MotionResult& r) {
  int k[3] = {};
  for (int p : r.plans) ++k[p];
  return fmt::format("{} / {} / {}", k[0], k[1], k[2]);
}

void print_motion(std::ostream& os, const Options& o, const std::vector<MotionResult>& ms) {
  if (ms.empty()) return;
  os << "\n## Coherent motion: `octree` with its pair cache against the one-shot `octree`\n\n";
  os << fmt::format(
      "- the boxes above moving {} steps of {} s at constant velocity (random direction, speed uniform in [0, {}) "
      "m/s), reflected at the centres' cube; per step, on the same boxes: the one-shot `octree` (sorted keys) and "
      "the pair cache (every find() of the step, a rerun after a miss included), {}, CUDA events\n",
      o.motion_steps, o.motion_dt, o.motion_speed,
      o.graph ? "each replayed from CUDA graphs (one per plan)" : "launched");
  os << "- margin: the fattened boxes' margin as a fraction of the median body size; plans: steps whose valid "
        "find() was Plain / Build / Hit\n\n";
  table_head(os, {{"n", true}, {"margin", true}, {"cache mean ms", true}, {"median", true}, {"min", true},
                  {"max", true}, {"one-shot mean ms", true}, {"median", true}, {"speed-up (means)", true},
                  {"Build ms", true}, {"Hit ms", true}, {"plans P/B/H", false}, {"reruns", true},
                  {"pairs (first, last)", false}, {"check", false}});
  for (const MotionResult& r : ms) {
    if (!r.ok) {
      os << fmt::format("| {} | {} | failed: {} |||||||||||||\n", size_label(r.n), r.margin, r.error);
      continue;
    }
    const auto mn = [](const std::vector<double>& v) { return *std::min_element(v.begin(), v.end()); };
    const auto mx = [](const std::vector<double>& v) { return *std::max_element(v.begin(), v.end()); };
    os << fmt::format(
        "| {} | {} | {:.3f} | {:.3f} | {:.3f} | {:.3f} | {:.3f} | {:.3f} | {:.2f}x | {:.3f} | {:.3f} | {} | {} | {}, "
        "{} | {} ({} oracle checks) |\n",
        size_label(r.n), r.margin, mean(r.coherent_ms), median(r.coherent_ms), mn(r.coherent_ms), mx(r.coherent_ms),
        mean(r.oneshot_ms), median(r.oneshot_ms), mean(r.oneshot_ms) / std::max(mean(r.coherent_ms), 1e-9),
        mean_of_plan(r.coherent_ms, r.plans, 1), mean_of_plan(r.coherent_ms, r.plans, 2), plan_counts(r), r.reruns,
        r.pairs_first, r.pairs_last, r.check, r.oracle_checks);
  }
}

Json motion_json(const std::vector<MotionResult>& ms) {
  Json a = Json::array();
  for (const MotionResult& r : ms) {
    a.push_back(point_json({{"n", r.n}, {"margin_fraction", decimal(r.margin)}, {"ok", r.ok}}, r, [&](Json& e) {
      e["coherent_mean_ms"] = mean(r.coherent_ms);
      e["coherent_median_ms"] = median(r.coherent_ms);
      e["oneshot_mean_ms"] = mean(r.oneshot_ms);
      e["oneshot_median_ms"] = median(r.oneshot_ms);
      e["build_mean_ms"] = mean_of_plan(r.coherent_ms, r.plans, 1);
      e["hit_mean_ms"] = mean_of_plan(r.coherent_ms, r.plans, 2);
      BENCH_JSON_MEMBERS(e, r, coherent_ms, oneshot_ms, plans, reruns, regrows, pairs_first, pairs_last, oracle_checks);
    }));
  }
  return a;
}

}  // namespace gpu_bench
