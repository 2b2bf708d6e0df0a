// GPU broadphase scaling (issue 8 item 2): the device broadphases behind the seam
// gpu/src/device_broadphase.hpp (`octree`, `octree-strict`, `spatial-hash`, and `lbvh`, a
// Karras 2012 linear BVH: the field's standard GPU baseline measured in the same process), and the
// engine's device `flat` at the smallest sizes as the oracle, on identical AABB sets of
// 10^4 .. 4x10^6 boxes in one process.
//
// Boxes: n uniform random cubes, half extents 0.06 m and 0.03 m (even and odd bodies),
// centres uniform (SplitMix64, --seed) in a cube of side 3.4 (n / 10^4)^(1/3) m centred on
// the origin: the number density of boxes-random-10000 (10^4 bodies in 3.4^3 m^3, about
// 254 per m^3). Overlaps are allowed (as GPU LBVH benchmarks do); about 0.85 pairs per
// body. The domain given to the octrees is the cube grown by the largest half extent, so
// every box lies inside it. The same boxes go to every broadphase of a size.
//
// Timed: what the engine needs for its sorted unique pair set: find() into a pair-key
// buffer (keys (a << bits(n)) | b, as the engine writes them), then the CUB radix sort
// of the keys (gpu::sort_keys_u64, bits [0, 2 bits(n))), between two CUDA events on one
// stream; a broadphase that sorts its own pairs (sorts_pairs(): `octree`) gets a scratch
// buffer of the capacity (PairOutput::scratch) and find() alone is timed, its keys already
// in order (what the engine does with it too). The capacity is grown on overflow and the
// pair count is read before timing (untimed), so the sort covers exactly the pairs (the
// engine also sorts its padding: capacity >= 1.25 x pairs). Then --warmup untimed
// calls, then --reps timed ones: median, min and max.
//
// Checked: every broadphase's sorted keys are pairs a < b < n, strictly increasing (so
// unique), equal to the other broadphases' at the same size and, up to --oracle-max
// bodies (default: every default size), to the CPU oracle (core's `flat` up to 20,000
// bodies, else core's `octree`, itself tested against `flat`; about 2 s per 10^6 bodies
// on one core); the pair count is the same on every repetition. Any difference: exit 3 (after the report).
//
// Reported (Markdown on stdout, JSON with --json FILE; progress on stderr): per
// broadphase and size the median/min/max ms, ns per body, the growth of the time per
// body per doubling of n against the previous size, ((t2/n2) / (t1/n1))^(1/log2(n2/n1)),
// pairs, exact AABB tests, device bytes; the machine; issue 8's targets met or not.
//
// Coherent motion (issue 33 item 4): the same boxes moving at constant velocity for
// --motion-steps steps (reflected at the centres' cube); per step the one-shot `octree` and
// `octree` with its pair cache (broadphase_octree_cache.cu: a Build, a Hit, or after a miss a
// rerun, all timed) on the same boxes; their keys compared bit for bit every step and with
// the CPU oracle every --motion-oracle-every steps; per margin of the fattened boxes: mean,
// median, min and max ms a step, the mean of Build and of Hit steps, the plans and reruns.
//
// Usage: bench_gpu_broadphase [--sizes 1e4,1e5,1e6,4e6] [--reps 20] [--warmup 3]
//          [--only octree,octree-strict,spatial-hash,lbvh] [--cell-size 0.24] [--depth -1]
//          [--seed 1] [--flat-max 10000] [--oracle-max 4000000] [--graph] [--json FILE]
//          [--motion-steps 100] [--motion-sizes 1e6] [--motion-margins 0.125,0.25]
//          [--motion-speed 1] [--motion-dt 0.001] [--motion-oracle-every 1]
// --graph times one CUDA graph launch of find() + sort (captured once; the engine replays
// its step from a graph) instead of the launches on the stream.
// Exit: 0 all checks passed; 1 runtime error (no CUDA device, CUDA error); 2 bad
#include "bench_gpu_common.hpp"
#include "bench_gpu_motion.hpp"
#include "bench_gpu_report.hpp"

namespace gpu_bench {

// ---- the engine's device `flat`, behind the seam ----------------------------------------------

/// The CUDA engine's `flat` (cuda_world.cpp's flat_broadphase, same kernels from
/// broadphase_flat.cu and the same CUB scan): count, exclusive scan of n + 1 counts (the
/// last one 0, so offset[n] is the total), total copied device to device, fill below the
/// capacity. The exact tests are n(n-1)/2; find() does not count them.
class DeviceFlat final : public DeviceBroadPhase {
 public:
  std::string name() const override { return broadphase_name(BroadPhaseId::flat); }
  void reserve(std::uint32_t n, cudaStream_t stream) override {
    const std::size_t n1 = static_cast<std::size_t>(n) + 1;
    count_.ensure(n1);
    offset_.ensure(n1);
    std::size_t bytes = 0;
    check(octocd::gpu::exclusive_scan_u32(nullptr, bytes, count_.get(), offset_.get(), n + 1, stream),
          "cub::DeviceScan::ExclusiveSum (size)");
    temp_.ensure(std::max<std::size_t>(bytes, 1));
  }
  void find(const Aabb* aabb, std::uint32_t n, const octocd::gpu::PairOutput& out, cudaStream_t stream) override {
    const std::size_t n1 = static_cast<std::size_t>(n) + 1;
    check(cudaMemsetAsync(count_.get(), 0, n1 * sizeof(std::uint32_t), stream), "cudaMemsetAsync (flat counts)");
    check(octocd::gpu::launch_flat_count(aabb, n, count_.get(), stream), "flat_count launch");
    std::size_t bytes = temp_.capacity();
    check(octocd::gpu::exclusive_scan_u32(temp_.get(), bytes, count_.get(), offset_.get(), n + 1, stream),
          "cub::DeviceScan::ExclusiveSum (flat offsets)");
    check(cudaMemcpyAsync(out.total, offset_.get() + n, sizeof(std::uint32_t), cudaMemcpyDeviceToDevice, stream),
          "cudaMemcpyAsync (flat pair total)");
    check(octocd::gpu::launch_flat_fill(aabb, n, offset_.get(), out.keys, out.capacity, out.shift, stream),
          "flat_fill launch");
  }
  std::uint64_t device_bytes() const override { return count_.bytes() + offset_.bytes() + temp_.bytes(); }

 private:
  DeviceBuffer<std::uint32_t> count_{"flat counts"};
  DeviceBuffer<std::uint32_t> offset_{"flat offsets"};
  DeviceBuffer<unsigned char> temp_{"flat CUB temporary storage"};
};

/// Runs one broadphase on the boxes already on the device: grows the capacity, warms up,
/// times, downloads the sorted keys.
Result measure(std::unique_ptr<DeviceBroadPhase> bp, const DeviceBuffer<Aabb>& boxes, std::uint32_t n,
               std::size_t initial_capacity, const Options& o, cudaStream_t stream) {
  Result r;
  r.broadphase = bp->name();
  r.n = n;
  const std::string what = fmt::format("{} at n = {}", r.broadphase, n);
  auto ctx = [&](const char* call) { return fmt::format("{} ({})", call, what); };
  // Messages of the calls inside the timed loop, formatted once.
  const std::string c_memset = ctx("cudaMemsetAsync (exact tests)"), c_find = ctx("find"),
                    c_total = ctx("cudaMemcpyAsync (pair total)"), c_sort = ctx("cub::DeviceRadixSort::SortKeys"),
                    c_start = ctx("cudaEventRecord (start)"), c_stop = ctx("cudaEventRecord (stop)"),
                    c_esync = ctx("cudaEventSynchronize"), c_ssync = ctx("cudaStreamSynchronize (after a repetition)"),
                    c_elapsed = ctx("cudaEventElapsedTime"), c_launch = ctx("cudaGraphLaunch");

  DeviceBuffer<unsigned long long> keys("pair keys");
  DeviceBuffer<unsigned long long> sorted("sorted pair keys");
  // A broadphase that sorts its own keys (PairOutput::scratch) needs no sort here.
  const bool self_sorts = bp->sorts_pairs();
  DeviceBuffer<unsigned long long> scratch("pair key scratch");
  DeviceBuffer<std::uint32_t> total("pair total");
  DeviceBuffer<unsigned long long> candidates("exact AABB tests");
  DeviceBuffer<unsigned char> temp("pair sort temporary storage");
  total.reset(1);
  candidates.reset(1);
  HostCounters host;
  Event start, stop;
  Graph graph;
  // The engine's keys: (a << key_bits(n)) | b, sorted over 2 key_bits(n) bits.
  const int shift = octocd::gpu::key_bits(n);
  const int end_bit = 2 * shift;

  bp->reserve(n, stream);
  check(cudaStreamSynchronize(stream), ctx("cudaStreamSynchronize (after reserve)").c_str());
  std::size_t cap = std::max<std::size_t>(initial_capacity, 1);
  auto out_for = [&]() {
    octocd::gpu::PairOutput out;
    out.keys = keys.get();
    out.capacity = static_cast<std::uint32_t>(cap);
    out.total = total.get();
    out.candidates = candidates.get();
    out.shift = shift;
    out.scratch = self_sorts ? scratch.get() : nullptr;
    return out;
  };
  // One untimed call; read back the total and the exact tests.
  auto call_and_read = [&]() {
    check(cudaMemsetAsync(candidates.get(), 0, sizeof(unsigned long long), stream), c_memset.c_str());
    bp->find(boxes.get(), n, out_for(), stream);
    check(cudaGetLastError(), c_find.c_str());
    check(cudaMemcpyAsync(host.total, total.get(), sizeof(std::uint32_t), cudaMemcpyDeviceToHost, stream),
          c_total.c_str());
    check(cudaMemcpyAsync(host.candidates, candidates.get(), sizeof(unsigned long long), cudaMemcpyDeviceToHost,
                          stream),
          ctx("cudaMemcpyAsync (exact tests)").c_str());
    check(cudaStreamSynchronize(stream), ctx("cudaStreamSynchronize (after find)").c_str());
  };

  // Capacity: grow until the pairs fit (outside the timed region).
  keys.ensure(cap);
  if (self_sorts) scratch.ensure(cap);
  call_and_read();
  while (*host.total > cap) {
    if (*host.total > 0x7fffffffu)
      throw octocd::RuntimeError(fmt::format("{}: {} pairs, more than 2^31 - 1", what, *host.total));
    cap = grown(*host.total, cap);
    keys.reset(cap);
    if (self_sorts) scratch.reset(cap);
    ++r.regrows;
    call_and_read();
  }
  const std::uint32_t pairs = *host.total;
  r.pairs = pairs;
  r.candidates = r.broadphase == broadphase_name(BroadPhaseId::flat) ? static_cast<std::uint64_t>(n) * (n - 1) / 2 : *host.candidates;
  r.capacity = cap;
  std::size_t temp_bytes = 0;
  if (!self_sorts) {
    sorted.reset(std::max<std::uint32_t>(pairs, 1));
    check(octocd::gpu::sort_keys_u64(nullptr, temp_bytes, keys.get(), sorted.get(), pairs, end_bit, stream),
          ctx("cub::DeviceRadixSort::SortKeys (size)").c_str());
    temp.reset(std::max<std::size_t>(temp_bytes, 1));
  }

  // find() + sort of exactly `pairs` keys: what is timed.
  auto enqueue = [&]() {
    bp->find(boxes.get(), n, out_for(), stream);
    check(cudaGetLastError(), c_find.c_str());
    std::size_t bytes = temp.capacity();
    if (pairs > 0 && !self_sorts)
      check(octocd::gpu::sort_keys_u64(temp.get(), bytes, keys.get(), sorted.get(), pairs, end_bit, stream),
            c_sort.c_str());
  };
  if (o.graph) {  // the same work captured once, then replayed (as the engine replays its step)
    check(cudaStreamBeginCapture(stream, cudaStreamCaptureModeThreadLocal), ctx("cudaStreamBeginCapture").c_str());
    try {
      enqueue();
    } catch (...) {
      cudaGraph_t broken = nullptr;
      (void)cudaStreamEndCapture(stream, &broken);
      if (broken) (void)cudaGraphDestroy(broken);
      (void)cudaGetLastError();
      throw;
    }
    check(cudaStreamEndCapture(stream, &graph.graph), ctx("cudaStreamEndCapture").c_str());
    check(cudaGraphInstantiate(&graph.exec, graph.graph, 0), ctx("cudaGraphInstantiate").c_str());
  }
  auto launch = [&]() {
    if (graph.exec)
      check(cudaGraphLaunch(graph.exec, stream), c_launch.c_str());
    else
      enqueue();
  };
  for (int i = 0; i < o.warmup; ++i) {
    check(cudaMemsetAsync(candidates.get(), 0, sizeof(unsigned long long), stream), c_memset.c_str());
    launch();
  }
  check(cudaStreamSynchronize(stream), ctx("cudaStreamSynchronize (after warm-up)").c_str());
  r.times.reserve(static_cast<std::size_t>(o.reps));
  for (int i = 0; i < o.reps; ++i) {
    check(cudaMemsetAsync(candidates.get(), 0, sizeof(unsigned long long), stream), c_memset.c_str());
    check(cudaEventRecord(start.e, stream), c_start.c_str());
    launch();
    check(cudaEventRecord(stop.e, stream), c_stop.c_str());
    check(cudaMemcpyAsync(host.total, total.get(), sizeof(std::uint32_t), cudaMemcpyDeviceToHost, stream),
          c_total.c_str());
    check(cudaEventSynchronize(stop.e), c_esync.c_str());
    check(cudaStreamSynchronize(stream), c_ssync.c_str());
    float ms = 0.0f;
    check(cudaEventElapsedTime(&ms, start.e, stop.e), c_elapsed.c_str());
    r.times.push_back(static_cast<double>(ms));
    if (*host.total != pairs && r.check_ok) {
      r.check_ok = false;
      r.check = fmt::format("the pair count changed between calls: {} then {}", pairs, *host.total);
    }
  }
  r.median_ms = median(r.times);
  r.min_ms = *std::min_element(r.times.begin(), r.times.end());
  r.max_ms = *std::max_element(r.times.begin(), r.times.end());
  r.scratch_bytes = bp->device_bytes();
  r.output_bytes = self_sorts ? 2ull * 8ull * cap : 2ull * 8ull * pairs + temp_bytes;

  // The sorted pair set of the last repetition (--reps >= 1; the same input each time).
  r.keys.resize(pairs);
  if (pairs > 0)
    check(cudaMemcpyAsync(r.keys.data(), self_sorts ? keys.get() : sorted.get(), static_cast<std::size_t>(pairs) * 8,
                          cudaMemcpyDeviceToHost,
                          stream),
          ctx("cudaMemcpyAsync (sorted keys)").c_str());
  check(cudaStreamSynchronize(stream), ctx("cudaStreamSynchronize (download)").c_str());
  // Back to the canonical (a << 32) | b of the checks and the CPU oracle (same order).
  for (unsigned long long& k : r.keys) k = ((k >> shift) << 32) | (k & ((1ull << shift) - 1ull));
  r.ok = true;
  return r;
}

/// "" when the sorted keys are pairs a < b < n, strictly increasing; else what is wrong.
std::string validate_keys(const std::vector<unsigned long long>& keys, std::uint32_t n) {
  for (std::size_t i = 0; i < keys.size(); ++i) {
    const auto a = static_cast<std::uint32_t>(keys[i] >> 32);
    const auto b = static_cast<std::uint32_t>(keys[i] & 0xffffffffull);
    if (!(a < b && b < n)) return fmt::format("bad key 0x{:016x} at {}: pair ({}, {}), n = {}", keys[i], i, a, b, n);
    if (i > 0 && keys[i - 1] >= keys[i])
      return keys[i - 1] == keys[i] ? fmt::format("pair ({}, {}) reported twice", a, b)
                                    : fmt::format("keys not sorted at {}", i);
  }
  return "";
}

/// "" when equal; else the counts and the first missing and extra pair.
std::string compare_keys(const std::vector<unsigned long long>& got, const std::vector<unsigned long long>& want,
                         const std::string& want_name) {
  if (got == want) return "";
  std::vector<unsigned long long> missing, extra;
  std::set_difference(want.begin(), want.end(), got.begin(), got.end(), std::back_inserter(missing));
  std::set_difference(got.begin(), got.end(), want.begin(), want.end(), std::back_inserter(extra));
  std::string s = fmt::format("{} pairs, {} has {}: {} missing, {} extra", got.size(), want_name, want.size(),
                              missing.size(), extra.size());
  if (!missing.empty()) s += fmt::format("; first missing ({}, {})", missing[0] >> 32, missing[0] & 0xffffffffull);
  if (!extra.empty()) s += fmt::format("; first extra ({}, {})", extra[0] >> 32, extra[0] & 0xffffffffull);
  return s;
}

// ---- the machine ----------------------------------------------------------------------------

/// "580.159.04" from /proc/driver/nvidia/version's NVRM line, or "".
std::string nvidia_driver_version() {
  std::ifstream f("/proc/driver/nvidia/version");
  std::string line;
  if (!std::getline(f, line)) return "";
  // "NVRM version: NVIDIA UNIX x86_64 Kernel Module  580.159.04  Tue ..."
  std::istringstream ss(line);
  std::string word;
  while (ss >> word) {
    if (!word.empty() && std::isdigit(static_cast<unsigned char>(word[0])) &&
        std::count(word.begin(), word.end(), '.') >= 1)
      return word;
  }
  return "";
}

Machine describe_machine(int device) {
  Machine m;
  cudaDeviceProp p{};
  check(cudaGetDeviceProperties(&p, device), "cudaGetDeviceProperties");
  m.gpu = p.name;
  m.cc_major = p.major;
  m.cc_minor = p.minor;
  m.sms = p.multiProcessorCount;
  m.memory = p.totalGlobalMem;
  check(cudaDriverGetVersion(&m.driver_cuda), "cudaDriverGetVersion");
  check(cudaRuntimeGetVersion(&m.runtime), "cudaRuntimeGetVersion");
  m.driver = nvidia_driver_version();
  m.host_cpu = octocd::cpu_description();
  m.build_id = octocd::build_id();
  m.date = utc_now();
  return m;
}

// ---- main -------------------------------------------------------------------------------------

int run(const Options& o) {
  int devices = 0;
  const cudaError_t e = cudaGetDeviceCount(&devices);
  if (e != cudaSuccess || devices == 0) {
    (void)cudaGetLastError();
    std::cerr << "bench_gpu_broadphase: no CUDA device: "
              << (e != cudaSuccess ? "cudaGetDeviceCount failed: " + octocd::gpu::cuda_text(e)
                                   : std::string("cudaGetDeviceCount found 0 devices"))
              << "\n";
    return 1;
  }
  check(cudaSetDevice(0), "cudaSetDevice(0)");
  check(cudaFree(nullptr), "cudaFree(nullptr) (context creation)");
  const Machine machine = describe_machine(0);
  std::cerr << "bench_gpu_broadphase: " << machine_line(machine) << "; octocd " << machine.build_id << "\n";

  Stream stream;
  std::vector<Result> results;
  std::vector<std::string> notes;
  bool all_ok = true;
  const auto t_start = std::chrono::steady_clock::now();

  for (const std::uint32_t n : o.sizes) {
    const std::vector<Aabb> boxes = make_boxes(n, o.seed);
    const Aabb domain = domain_for(n);
    DeviceBuffer<Aabb> d_boxes("benchmark AABBs");
    octocd::gpu::upload(d_boxes, boxes, stream.s);
    const std::size_t initial_capacity = 2 * static_cast<std::size_t>(n) + 64;  // the engine's first pair_cap

    std::vector<std::string> names;
    if (n <= o.flat_max) names.push_back(broadphase_name(BroadPhaseId::flat));
    names.insert(names.end(), o.broadphases.begin(), o.broadphases.end());

    std::vector<Result> here;
    for (const std::string& name : names) {
      std::cerr << fmt::format("  {} n = {} ...", name, n) << std::flush;
      Result r;
      try {
        std::unique_ptr<DeviceBroadPhase> bp;
        if (name == broadphase_name(BroadPhaseId::flat)) {
          bp = std::make_unique<DeviceFlat>();
        } else {
          BroadPhaseConfig cfg;
          cfg.name = name;
          cfg.octree_depth = o.depth;
          cfg.cell_size = o.cell_size;
          bp = octocd::gpu::make_device_broadphase(cfg, domain);
        }
        r = measure(std::move(bp), d_boxes, n, initial_capacity, o, stream.s);
      } catch (const std::exception& ex) {
        r = Result{};
        r.broadphase = name;
        r.n = n;
        r.ok = false;
        mark_failed(r, ex, stream.s);
      }
      if (r.ok) {
        std::cerr << fmt::format(" {:.3f} ms (min {:.3f}, max {:.3f}), {} pairs\n", r.median_ms, r.min_ms, r.max_ms,
                                 r.pairs);
        const std::string bad = validate_keys(r.keys, n);
        if (!bad.empty()) {
          r.check_ok = false;
          r.check = bad;
        }
      } else {
        std::cerr << " failed: " << r.error << "\n";
      }
      here.push_back(std::move(r));
    }

    // The same sorted pair set everywhere: against the first valid device set, and the CPU oracle.
    const Result* ref = nullptr;
    for (const Result& r : here)
      if (r.ok && r.check_ok) {
        ref = &r;
        break;
      }
    std::vector<unsigned long long> oracle;
    std::string oracle_name;
    if (n <= o.oracle_max) {
      BroadPhaseConfig cfg;
      cfg.name = broadphase_name(n <= o.cpu_flat_max ? BroadPhaseId::flat : BroadPhaseId::octree);
      cfg.octree_depth = -1;
      oracle_name = "CPU `" + cfg.name + "`";
      std::cerr << fmt::format("  oracle {} n = {} ...", oracle_name, n) << std::flush;
      std::vector<octocd::Pair> pairs;
      octocd::BroadPhaseStats stats;
      octocd::make_broadphase(cfg, domain)->find_pairs(boxes, pairs, stats);
      oracle.reserve(pairs.size());
      for (const octocd::Pair& p : pairs) oracle.push_back(key_of(p.a, p.b));
      std::cerr << fmt::format(" {} pairs\n", oracle.size());
    }
    bool size_ok = true;
    for (Result& r : here) {
      if (!r.ok || !r.check_ok) {
        size_ok = false;
        continue;
      }
      std::string diff;
      if (&r != ref && ref) diff = compare_keys(r.keys, ref->keys, "`" + ref->broadphase + "`");
      if (diff.empty() && !oracle_name.empty()) diff = compare_keys(r.keys, oracle, oracle_name);
      if (!diff.empty()) {
        r.check_ok = false;
        r.check = diff;
        size_ok = false;
      } else {
        r.check = oracle_name.empty() ? "identical to the other broadphases"
                                      : "identical to the other broadphases and " + oracle_name;
      }
    }
    std::string note = fmt::format("n = {}: ", size_label(n));
    if (size_ok) {
      note += fmt::format("{} broadphases give the same {} pairs{}", here.size(), ref ? ref->pairs : 0,
                          oracle_name.empty() ? std::string(" (no CPU oracle above --oracle-max)")
                                              : ", equal to " + oracle_name);
    } else {
      note += "MISMATCH or failure:";
      for (const Result& r : here)
        if (!r.check_ok) note += fmt::format(" `{}`: {};", r.broadphase, r.ok ? r.check : "failed: " + r.error);
    }
    notes.push_back(note);
    all_ok = all_ok && size_ok;
    for (Result& r : here) {
      r.keys.clear();
      r.keys.shrink_to_fit();
      results.push_back(std::move(r));
    }
  }

  // Growth per doubling against the previous measured size of the same broadphase.
  for (Result& r : results) {
    if (!r.ok) continue;
    const Result* prev = nullptr;
    for (const Result& q : results)
      if (q.ok && q.broadphase == r.broadphase && q.n < r.n && (!prev || q.n > prev->n)) prev = &q;
    if (prev && prev->median_ms > 0 && r.median_ms > 0)
      r.growth = std::pow((r.median_ms / r.n) / (prev->median_ms / prev->n),
                          1.0 / std::log2(static_cast<double>(r.n) / prev->n));
  }
  const std::vector<Target> targets = evaluate_targets(results, o);
  std::vector<MotionResult> motions;
  if (o.motion_steps > 0) {
    for (const std::uint32_t n : o.motion_sizes) {
      for (const float margin : o.motion_margins) {
        std::cerr << fmt::format("  coherent motion n = {}, margin {}, {} steps ...", n, margin, o.motion_steps)
                  << std::flush;
        MotionResult m;
        try {
          m = run_motion(n, margin, o, stream.s);
          std::cerr << fmt::format(" cache {:.3f} ms, one-shot {:.3f} ms a step (means); {}\n", mean(m.coherent_ms),
                                   mean(m.oneshot_ms), m.check);
        } catch (const std::exception& ex) {
          m = MotionResult{};
          m.n = n;
          m.margin = margin;
          mark_failed(m, ex, stream.s);
          std::cerr << " failed: " << m.error << "\n";
        }
        all_ok = all_ok && m.check_ok;
        motions.push_back(std::move(m));
      }
    }
  }
  print_markdown(std::cout, machine, o, results, targets, notes, all_ok);
  print_motion(std::cout, o, motions);
  std::cout.flush();
  if (!o.json_path.empty()) {
    // As every octocd output (octocd/atomic_file.hpp): a temporary beside the file,
    // renamed over it; never written in place.
    Json j = to_json(machine, o, results, targets, notes, all_ok);
    j["motion"] = motion_json(motions);
    try {
      octocd::write_file_atomically(o.json_path, j.dump(2) + "\n", "--json");
    } catch (const std::exception& err) {
      std::cerr << "bench_gpu_broadphase: " << err.what() << "\n";
      return dynamic_cast<const octocd::InputError*>(&err) ? 2 : 1;
    }
  }
  std::cerr << fmt::format("bench_gpu_broadphase: {:.1f} s, {}\n",
                           std::chrono::duration<double>(std::chrono::steady_clock::now() - t_start).count(),
                           all_ok ? "all pair sets identical" : "PAIR SETS DIFFER (exit 3)");
  return all_ok ? 0 : 3;
}

/// Adds the option `name` bound to `value`, its default shown in --help, checked to be in
/// [lo, hi] (CLI::Range).
template <class T>
CLI::Option* add_ranged(CLI::App& app, const std::string& name, T& value, const std::string& what, T lo, T hi) {
  return app.add_option(name, value, what)->capture_default_str()->check(CLI::Range(lo, hi));
}
}  // namespace gpu_bench

using namespace gpu_bench;

int main(int argc, char** argv) {
  Options o;
  std::string sizes = "10000,100000,1000000,4000000";
  std::string only = "octree,octree-strict,spatial-hash,lbvh";
  CLI::App app{"GPU broadphase scaling: the device broadphases on identical random box sets (issue 8)",
               "bench_gpu_broadphase"};
  app.add_option("--sizes", sizes, "body counts, comma separated (1e5 and 4e6 are accepted)")
      ->capture_default_str();
  app.add_option("--only", only, "device broadphases: " + octocd::join_broadphase_names(seam_names()))
      ->capture_default_str();
  add_ranged(app, "--reps", o.reps, "timed repetitions per broadphase and size", 1, 100000);
  add_ranged(app, "--warmup", o.warmup, "untimed calls before the repetitions", 0, 100000);
  app.add_option("--cell-size", o.cell_size, "spatial-hash cell size h (m)")->capture_default_str();
  add_ranged(app, "--depth", o.depth, "octree depth, -1 = auto", -1, 10);
  app.add_option("--seed", o.seed, "SplitMix64 seed of the boxes")->capture_default_str();
  app.add_option("--flat-max", o.flat_max, "the device `flat` runs up to this n")->capture_default_str();
  app.add_option("--oracle-max", o.oracle_max,
                 "the CPU oracle (flat up to 20000 bodies, else octree) checks up to this n")
      ->capture_default_str();
  app.add_flag("--graph", o.graph,
               "time one CUDA graph launch of find() + sort (captured once, as the engine replays its step) "
               "instead of the launches on the stream");
  app.add_option("--json", o.json_path, "also write the results as JSON to this file");
  std::string motion_sizes = "1000000", motion_margins = "0.125";
  add_ranged(app, "--motion-steps", o.motion_steps, "steps of the coherent-motion sequence (0: none)", 0, 100000);
  app.add_option("--motion-sizes", motion_sizes, "body counts of the coherent-motion sequence")->capture_default_str();
  app.add_option("--motion-margins", motion_margins,
                 "margins of the pair cache's fattened boxes, fractions of the median body size, comma separated")
      ->capture_default_str();
  add_ranged(app, "--motion-speed", o.motion_speed, "largest speed of the moving boxes (m/s)", 0.0f, 1000.0f);
  add_ranged(app, "--motion-dt", o.motion_dt, "time step of the moving boxes (s)", 0.0f, 1.0f);
  add_ranged(app, "--motion-oracle-every", o.motion_oracle_every,
             "check the pair cache against the CPU oracle every this many steps (0: never)", 0, 100000);
  try {
    app.parse(argc, argv);
    o.sizes = parse_sizes(sizes);
    o.broadphases = split_names(only);
    o.motion_sizes = parse_sizes(motion_sizes);
    o.motion_margins.clear();
    for (const std::string& m : split_names(motion_margins)) {
      char* end = nullptr;
      const float f = std::strtof(m.c_str(), &end);
      if (end == m.c_str() || *end != '\0' || !(f >= 0.0f && f <= 16.0f))
        throw octocd::InputError(fmt::format("--motion-margins: '{}' is not a fraction in [0, 16]", m));
      o.motion_margins.push_back(f);
    }
    if (o.broadphases.empty()) throw octocd::InputError("--only: no broadphase given");
    for (const std::string& b : o.broadphases)
      if (const octocd::BroadPhaseInfo* info = octocd::find_broadphase_info(b);
          !info || info->device != octocd::BroadPhaseDevice::seam)
        throw octocd::InputError(fmt::format(
            "--only: '{}' is not a device broadphase behind the seam ({}; `{}` runs by itself up to --flat-max)", b,
            octocd::join_broadphase_names(seam_names()), broadphase_name(BroadPhaseId::flat)));
    if (!(o.cell_size > 0.0f) || !std::isfinite(o.cell_size))
      throw octocd::InputError("--cell-size: must be finite and > 0");
    // Before any work: a FIFO, device, folder or link at --json is exit 2.
    if (!o.json_path.empty()) octocd::check_output_file(o.json_path, "--json");
  } catch (const CLI::ParseError& e) {
    return app.exit(e);
  } catch (const octocd::InputError& e) {
    std::cerr << "bench_gpu_broadphase: " << e.what() << "\n";
    return 2;
  }
  try {
    return run(o);
  } catch (const std::exception& e) {
    std::cerr << "\nbench_gpu_broadphase: " << e.what() << "\n";
    return 1;
  }
}
