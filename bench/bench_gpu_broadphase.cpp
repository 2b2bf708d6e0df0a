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
// arguments; 3 a pair set differs or a broadphase failed.
#include <algorithm>
#include <cctype>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <ctime>
#include <exception>
#include <fstream>
#include <initializer_list>
#include <iostream>
#include <iterator>
#include <memory>
#include <optional>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

#include <CLI/CLI.hpp>
#include <cuda_runtime_api.h>
#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "device_broadphase.hpp"
#include "device_buffer.hpp"
#include "kernels.hpp"
#include "octocd/atomic_file.hpp"
#include "octocd/broadphase.hpp"
#include "octocd/error.hpp"
#include "octocd/scene.hpp"
#include "octocd/version.hpp"

namespace {

using octocd::Aabb;
using octocd::BroadPhaseConfig;
using octocd::BroadPhaseId;
using octocd::broadphase_name;
using octocd::gpu::check;
using octocd::gpu::DeviceBroadPhase;
using octocd::gpu::DeviceBuffer;
using Json = nlohmann::ordered_json;

/// Writes members of `t` into the JSON object `j`, each under its own name, in the order
/// given: j["a"] = t.a; j["b"] = t.b; ... (nlohmann's NLOHMANN_JSON_TO for each member, as
/// its NLOHMANN_DEFINE_TYPE_* macros do; those write nlohmann::json only, and Json keeps the
/// keys in insertion order).
#define BENCH_JSON_MEMBERS(j, t, ...)                                        \
  do {                                                                       \
    Json& nlohmann_json_j = (j);                                             \
    const auto& nlohmann_json_t = (t);                                       \
    NLOHMANN_JSON_EXPAND(NLOHMANN_JSON_PASTE(NLOHMANN_JSON_TO, __VA_ARGS__)) \
  } while (false)

// ---- the boxes ----------------------------------------------------------------------------

constexpr double kDensitySide = 3.4;       // cube side (m) for 10^4 boxes (boxes-random-10000)
constexpr float kHalfLarge = 0.06f;        // half extent (m) of the even bodies
constexpr float kHalfSmall = 0.03f;        // half extent (m) of the odd bodies
constexpr double kLargestExtent = 0.12;  // 2 x kHalfLarge (m)

double cube_side(std::uint32_t n) { return kDensitySide * std::cbrt(static_cast<double>(n) / 1e4); }

/// n boxes: centres uniform in [-s/2, s/2)^3 (x, y, z drawn in that order), half extent
/// 0.06 for even and 0.03 for odd bodies.
std::vector<Aabb> make_boxes(std::uint32_t n, std::uint64_t seed) {
  octocd::SplitMix64 rng(seed);
  const float h = static_cast<float>(cube_side(n) / 2.0);
  std::vector<Aabb> boxes(n);
  for (std::uint32_t i = 0; i < n; ++i) {
    const float x = rng.uniform(-h, h), y = rng.uniform(-h, h), z = rng.uniform(-h, h);
    const float e = (i % 2 == 0) ? kHalfLarge : kHalfSmall;
    boxes[i] = {{x - e, y - e, z - e}, {x + e, y + e, z + e}};
  }
  return boxes;
}

/// The octrees' domain: the centres' cube grown by the largest half extent.
Aabb domain_for(std::uint32_t n) {
  const float h = static_cast<float>(cube_side(n) / 2.0) + kHalfLarge;
  return {{-h, -h, -h}, {h, h, h}};
}

// ---- small helpers ------------------------------------------------------------------------

/// The capacity to grow to when `needed` keys did not fit (cuda_world.cpp's rule).
std::size_t grown(std::size_t needed, std::size_t capacity) {
  return std::max(needed + needed / 4 + 64, 2 * capacity);
}

unsigned long long key_of(std::uint32_t a, std::uint32_t b) {
  return (static_cast<unsigned long long>(a) << 32) | b;
}

double median(std::vector<double> v) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  const std::size_t m = v.size() / 2;
  return v.size() % 2 ? v[m] : 0.5 * (v[m - 1] + v[m]);
}

/// A float as the double of its shortest decimal form (0.24f -> 0.24, for the JSON).
double decimal(float f) { return std::stod(fmt::format("{}", f)); }

double mib(std::uint64_t bytes) { return static_cast<double>(bytes) / (1024.0 * 1024.0); }

/// "10^4", "4x10^6" (one significant digit times a power of ten >= 10^3), or the plain number.
std::string size_label(std::uint64_t n) {
  int e = 0;
  std::uint64_t m = n;
  while (m >= 10 && m % 10 == 0) {
    m /= 10;
    ++e;
  }
  if (e < 3 || m >= 10) return std::to_string(n);
  return m == 1 ? fmt::format("10^{}", e) : fmt::format("{}x10^{}", m, e);
}

/// Parses "10000,1e5,4e6" into positive integers.
std::vector<std::uint32_t> parse_sizes(const std::string& text) {
  std::vector<std::uint32_t> out;
  std::stringstream ss(text);
  std::string item;
  while (std::getline(ss, item, ',')) {
    if (item.empty()) continue;
    std::size_t used = 0;
    double v = 0.0;
    try {
      v = std::stod(item, &used);
    } catch (const std::exception&) {
      used = 0;
    }
    if (used != item.size() || !(v >= 2.0) || v > 2.0e8 || v != std::floor(v))
      throw octocd::InputError(fmt::format("--sizes: '{}' is not a body count in [2, 2e8]", item));
    out.push_back(static_cast<std::uint32_t>(v));
  }
  if (out.empty()) throw octocd::InputError("--sizes: no size given");
  return out;
}

std::vector<std::string> split_names(const std::string& text) {
  std::vector<std::string> out;
  std::stringstream ss(text);
  std::string item;
  while (std::getline(ss, item, ','))
    if (!item.empty()) out.push_back(item);
  return out;
}

std::string utc_now() {
  const std::time_t t = std::time(nullptr);
  char buf[32];
  std::tm tm{};
  gmtime_r(&t, &tm);
  std::strftime(buf, sizeof buf, "%Y-%m-%dT%H:%M:%SZ", &tm);
  return buf;
}

// ---- RAII wrappers over the CUDA runtime ----------------------------------------------------

struct Stream {
  cudaStream_t s = nullptr;
  Stream() { check(cudaStreamCreateWithFlags(&s, cudaStreamNonBlocking), "cudaStreamCreateWithFlags"); }
  ~Stream() {
    if (s) (void)cudaStreamDestroy(s);
  }
  Stream(const Stream&) = delete;
  Stream& operator=(const Stream&) = delete;
};

struct Event {
  cudaEvent_t e = nullptr;
  Event() { check(cudaEventCreate(&e), "cudaEventCreate"); }
  ~Event() {
    if (e) (void)cudaEventDestroy(e);
  }
  Event(const Event&) = delete;
  Event& operator=(const Event&) = delete;
};

/// Page-locked host words the stream copies the pair total and test count into.
struct HostCounters {
  std::uint32_t* total = nullptr;
  unsigned long long* candidates = nullptr;
  HostCounters() {
    check(cudaMallocHost(reinterpret_cast<void**>(&total), sizeof(std::uint32_t)), "cudaMallocHost (pair total)");
    check(cudaMallocHost(reinterpret_cast<void**>(&candidates), sizeof(unsigned long long)),
          "cudaMallocHost (exact tests)");
  }
  ~HostCounters() {
    if (total) (void)cudaFreeHost(total);
    if (candidates) (void)cudaFreeHost(candidates);
  }
  HostCounters(const HostCounters&) = delete;
  HostCounters& operator=(const HostCounters&) = delete;
};

/// A captured graph and its executable form.
struct Graph {
  cudaGraph_t graph = nullptr;
  cudaGraphExec_t exec = nullptr;
  Graph() = default;
  ~Graph() {
    if (exec) (void)cudaGraphExecDestroy(exec);
    if (graph) (void)cudaGraphDestroy(graph);
  }
  Graph(const Graph&) = delete;
  Graph& operator=(const Graph&) = delete;
};

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

/// The device broadphases behind the seam (the rows of octocd/broadphase_table.def with
/// device `seam`), in the table's order: what `--only` accepts and its default.
std::vector<std::string> seam_names() {
  return octocd::broadphase_names_where(
      [](const octocd::BroadPhaseInfo& b) { return b.device == octocd::BroadPhaseDevice::seam; });
}

// ---- one measurement --------------------------------------------------------------------------

struct Options {
  std::vector<std::uint32_t> sizes{10000, 100000, 1000000, 4000000};
  std::vector<std::string> broadphases = seam_names();
  int reps = 20;
  int warmup = 3;
  float cell_size = 0.24f;
  int depth = -1;
  std::uint64_t seed = 1;
  std::uint32_t flat_max = 10000;
  std::uint32_t oracle_max = 4000000;
  std::uint32_t cpu_flat_max = 20000;
  bool graph = false;
  std::string json_path;
  // The coherent-motion sequence (`octree` with its pair cache against the one-shot `octree`).
  std::vector<std::uint32_t> motion_sizes{1000000};
  int motion_steps = 100;
  std::vector<float> motion_margins{0.125f};
  float motion_speed = 1.0f;   ///< largest speed (m/s)
  float motion_dt = 0.001f;    ///< step (s)
  int motion_oracle_every = 1; ///< CPU oracle every this many steps (0: never)
};

struct Result {
  std::string broadphase;
  std::uint32_t n = 0;
  bool ok = false;             ///< measured (no exception)
  std::string error;           ///< the exception's text when !ok
  std::vector<double> times;   ///< ms per rep
  double median_ms = 0, min_ms = 0, max_ms = 0;
  std::optional<double> growth;  ///< time per body per doubling vs the previous size
  std::uint64_t pairs = 0;
  std::uint64_t candidates = 0;
  std::uint64_t scratch_bytes = 0;  ///< DeviceBroadPhase::device_bytes()
  std::uint64_t output_bytes = 0;   ///< keys + sorted keys (pairs each) + the sort's temporary storage
  std::uint64_t capacity = 0;       ///< key buffer entries after growing
  int regrows = 0;                  ///< times the capacity grew (untimed)
  std::string check = "not checked";  ///< "identical", or what differed
  bool check_ok = true;
  std::vector<unsigned long long> keys;  ///< sorted keys (freed after the checks)
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

struct Machine {
  std::string gpu;
  int cc_major = 0, cc_minor = 0, sms = 0;
  std::uint64_t memory = 0;
  std::string driver;  ///< the kernel module's version (/proc/driver/nvidia/version), or ""
  int driver_cuda = 0, runtime = 0;
  std::string host_cpu;
  std::string build_id;
  std::string date;
};

std::string cuda_version_text(int v) { return fmt::format("{}.{}", v / 1000, (v % 1000) / 10); }

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

std::string machine_line(const Machine& m) {
  return fmt::format("{} (sm_{}{}, {} SMs, {:.1f} GiB), driver {} (CUDA {}), runtime CUDA {}", m.gpu, m.cc_major,
                     m.cc_minor, m.sms, static_cast<double>(m.memory) / (1024.0 * 1024.0 * 1024.0),
                     m.driver.empty() ? "unknown" : m.driver, cuda_version_text(m.driver_cuda),
                     cuda_version_text(m.runtime));
}

// ---- targets (issue 8) ------------------------------------------------------------------------

constexpr double kBestTargetMs = 0.6;     // 10^6 boxes, the best broadphase
constexpr double kOctreeTargetMs = 1.2;   // 10^6 boxes, `octree`
constexpr double kGrowthTarget = 1.2;     // time per body per doubling, 10^5 .. 4x10^6
constexpr double kLbvhReferenceMs = 1.2;  // Karras 2012 style LBVH, build + self-query, H100

struct Target {
  std::string name;
  std::string value;       ///< what was measured, in words
  std::optional<bool> met;  ///< nullopt: not measured (a size or broadphase missing)
  Json json;
};

const Result* find_result(const std::vector<Result>& rs, const std::string& bp, std::uint32_t n) {
  for (const Result& r : rs)
    if (r.broadphase == bp && r.n == n && r.ok) return &r;
  return nullptr;
}

std::vector<Target> evaluate_targets(const std::vector<Result>& rs, const Options& o) {
  std::vector<Target> ts;
  // 1. the best broadphase at 10^6.
  {
    Target t{"best broadphase at 10^6 boxes <= 0.6 ms", "not measured (10^6 not in --sizes)", std::nullopt, {}};
    const Result* best = nullptr;
    for (const std::string& bp : o.broadphases)
      if (const Result* r = find_result(rs, bp, 1000000))
        if (!best || r->median_ms < best->median_ms) best = r;
    if (best) {
      t.met = best->median_ms <= kBestTargetMs;
      t.value = fmt::format("{}: {:.3f} ms", best->broadphase, best->median_ms);
      t.json = {{"broadphase", best->broadphase}, {"median_ms", best->median_ms}, {"limit_ms", kBestTargetMs}};
    }
    t.json["met"] = t.met ? Json(*t.met) : Json(nullptr);
    ts.push_back(t);
  }
  // 2. `octree` at 10^6.
  {
    Target t{"`octree` at 10^6 boxes <= 1.2 ms", "not measured (octree or 10^6 missing)", std::nullopt, {}};
    if (const Result* r = find_result(rs, broadphase_name(BroadPhaseId::octree), 1000000)) {
      t.met = r->median_ms <= kOctreeTargetMs;
      t.value = fmt::format("{:.3f} ms", r->median_ms);
      t.json = {{"broadphase", broadphase_name(BroadPhaseId::octree)}, {"median_ms", r->median_ms}, {"limit_ms", kOctreeTargetMs}};
    }
    t.json["met"] = t.met ? Json(*t.met) : Json(nullptr);
    ts.push_back(t);
  }
  // 3. `octree` ahead of the measured GPU LBVH (`lbvh`) at every size both ran (issue 20).
  {
    Target t{"`octree` faster than `lbvh` (Karras 2012 LBVH, same process) at every size",
             "not measured (octree or lbvh missing)", std::nullopt, {}};
    Json sizes = Json::array();
    bool all_faster = true;
    std::string worst;
    double worst_ratio = 0.0;
    for (std::uint32_t n : o.sizes) {
      const Result* oct = find_result(rs, broadphase_name(BroadPhaseId::octree), n);
      const Result* lbvh = find_result(rs, broadphase_name(BroadPhaseId::lbvh), n);
      if (!oct || !lbvh) continue;
      const double ratio = oct->median_ms / lbvh->median_ms;
      all_faster = all_faster && ratio < 1.0;
      if (ratio > worst_ratio) {
        worst_ratio = ratio;
        worst = fmt::format("n = {}: octree {:.3f} ms vs lbvh {:.3f} ms", size_label(n), oct->median_ms,
                            lbvh->median_ms);
      }
      sizes.push_back({{"n", n}, {"octree_ms", oct->median_ms}, {"lbvh_ms", lbvh->median_ms}, {"ratio", ratio}});
    }
    if (!sizes.empty()) {
      t.met = all_faster;
      t.value = fmt::format("{} sizes; closest {} ({:.2f}x the lbvh time)", sizes.size(), worst, worst_ratio);
      t.json = {{"sizes", sizes}, {"worst_ratio", worst_ratio}};
    }
    t.json["met"] = t.met ? Json(*t.met) : Json(nullptr);
    ts.push_back(t);
  }
  // 4. growth of the time per body, per broadphase: every measured step between 10^5 and
  // 4x10^6 (the largest step ratio), and over the whole span.
  for (const std::string& bp : o.broadphases) {
    Target t{fmt::format("`{}`: time per body grows <= 1.2x per doubling, 10^5 .. 4x10^6", bp),
             "not measured (needs 10^5, 4x10^6 and the sizes between)", std::nullopt, {}};
    std::vector<const Result*> span;
    for (std::uint32_t n : o.sizes)
      if (n >= 100000 && n <= 4000000) span.push_back(find_result(rs, bp, n));
    const bool complete = std::find(o.sizes.begin(), o.sizes.end(), 100000u) != o.sizes.end() &&
                          std::find(o.sizes.begin(), o.sizes.end(), 4000000u) != o.sizes.end() &&
                          std::all_of(span.begin(), span.end(), [](const Result* r) { return r != nullptr; });
    if (complete && span.size() >= 2) {
      double worst = 0.0;
      Json steps = Json::array();
      for (std::size_t i = 1; i < span.size(); ++i) {
        const double g = std::pow((span[i]->median_ms / span[i]->n) / (span[i - 1]->median_ms / span[i - 1]->n),
                                  1.0 / std::log2(static_cast<double>(span[i]->n) / span[i - 1]->n));
        worst = std::max(worst, g);
        steps.push_back({{"from", span[i - 1]->n}, {"to", span[i]->n}, {"per_doubling", g}});
      }
      const Result* a = span.front();
      const Result* b = span.back();
      const double overall = std::pow((b->median_ms / b->n) / (a->median_ms / a->n),
                                      1.0 / std::log2(static_cast<double>(b->n) / a->n));
      t.met = worst <= kGrowthTarget;
      t.value = fmt::format("worst step {:.2f}x, whole span {:.2f}x per doubling", worst, overall);
      t.json = {{"broadphase", bp},       {"worst_step_per_doubling", worst}, {"span_per_doubling", overall},
                {"steps", steps},         {"limit_per_doubling", kGrowthTarget}};
    }
    t.json["met"] = t.met ? Json(*t.met) : Json(nullptr);
    ts.push_back(t);
  }
  return ts;
}

// ---- the coherent-motion sequence ------------------------------------------------------------

/// One sequence: per step the time of `octree` with its pair cache (every find() of the
/// step, reruns included) and of the one-shot `octree`, on the same boxes.
struct MotionResult {
  std::uint32_t n = 0;
  float margin = 0.0f;  ///< margin fraction of the median body size
  bool ok = false;
  std::string error;
  std::vector<double> coherent_ms, oneshot_ms;  ///< per step
  std::vector<int> plans;                       ///< per step: the plan of the valid find()
  int reruns = 0, regrows = 0, oracle_checks = 0;
  std::uint64_t pairs_first = 0, pairs_last = 0;
  std::string check = "identical";
  bool check_ok = true;
};

/// A measured point's JSON (Result, MotionResult): `e` (the point's identity), then the
/// error when it failed, else what measured(e) adds; then its pair check.
template <class R, class Measured>
Json point_json(Json e, const R& r, Measured measured) {
  if (!r.ok) {
    e["error"] = r.error;
  } else {
    measured(e);
  }
  e["check"] = r.check;
  e["check_ok"] = r.check_ok;
  return e;
}

/// Marks a Result or MotionResult failed with `ex`'s message, then clears CUDA's sticky
/// error and waits for `stream` (clearing its error too) so the next point starts clean.
template <class R>
void mark_failed(R& r, const std::exception& ex, cudaStream_t stream) {
  r.error = ex.what();
  r.check_ok = false;
  r.check = "failed";
  (void)cudaGetLastError();
  (void)cudaStreamSynchronize(stream);
  (void)cudaGetLastError();
}

double mean(const std::vector<double>& v) {
  double t = 0.0;
  for (double x : v) t += x;
  return v.empty() ? 0.0 : t / static_cast<double>(v.size());
}

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

/// A markdown table's header row and its alignment row; per column its title and whether
/// it is right-aligned (numbers).
void table_head(std::ostream& os, std::initializer_list<std::pair<const char*, bool>> columns) {
  std::string titles = "|", rule = "|";
  for (const auto& [title, right] : columns) {
    titles += fmt::format(" {} |", title);
    rule += right ? "---:|" : "---|";
  }
  os << titles << "\n" << rule << "\n";
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

// ---- output -----------------------------------------------------------------------------------

std::string fmt_opt_growth(const std::optional<double>& g) { return g ? fmt::format("{:.2f}x", *g) : "-"; }

std::string yes_no(const std::optional<bool>& b) { return b ? (*b ? "yes" : "no") : "not measured"; }

void print_markdown(std::ostream& os, const Machine& m, const Options& o, const std::vector<Result>& rs,
                    const std::vector<Target>& ts, const std::vector<std::string>& oracle_notes, bool all_ok) {
  os << "# GPU broadphase scaling (`bench_gpu_broadphase`)\n\n";
  os << fmt::format("- GPU: {}\n", machine_line(m));
  os << fmt::format("- host: {}; octocd {}; {}\n", m.host_cpu, m.build_id, m.date);
  os << fmt::format(
      "- boxes: n uniform random cubes, half extents {} m and {} m (half each), centres uniform in a cube of side "
      "3.4 (n/10^4)^(1/3) m ({:.1f} bodies/m^3, as boxes-random-10000), overlaps allowed, SplitMix64 seed {}; the "
      "same boxes for every broadphase\n",
      kHalfLarge, kHalfSmall, 1e4 / (kDensitySide * kDensitySide * kDensitySide), o.seed);
  os << fmt::format(
      "- parameters: octree depth {}; spatial-hash cell size h = {} m (2 x the largest box extent {} m); "
      "`flat` (the engine's device flat) up to n = {}\n",
      o.depth < 0 ? std::string("auto") : std::to_string(o.depth), o.cell_size, kLargestExtent, o.flat_max);
  os << fmt::format(
      "- timed: find() + CUB radix sort of the pair keys (the sorted unique pair set; `octree` sorts its own "
      "keys given a scratch buffer: find() alone), {}, CUDA events, {} "
      "warm-up calls, median (min, max) of {} repetitions; capacity grown before timing\n",
      o.graph ? "replayed from a CUDA graph" : "launched on one stream", o.warmup, o.reps);
  os << "- device MiB: the broadphase's scratch (device_bytes()) + pair keys, sorted keys and the sort's "
        "temporary storage (`octree`: pair keys and their scratch, capacity each); the input AABBs (24 B per body) "
        "not included\n\n";

  table_head(os, {{"broadphase", false}, {"n", true}, {"median ms", true}, {"min ms", true}, {"max ms", true},
                  {"ns/body", true}, {"per doubling", true}, {"pairs", true}, {"exact tests", true},
                  {"device MiB", true}});
  for (const Result& r : rs) {
    if (!r.ok) {
      os << fmt::format("| {} | {} | failed: {} | | | | | | | |\n", r.broadphase, size_label(r.n), r.error);
      continue;
    }
    os << fmt::format("| {} | {} | {:.3f} | {:.3f} | {:.3f} | {:.2f} | {} | {} | {} | {:.1f} |\n", r.broadphase,
                      size_label(r.n), r.median_ms, r.min_ms, r.max_ms, r.median_ms * 1e6 / r.n,
                      fmt_opt_growth(r.growth), r.pairs, r.candidates, mib(r.scratch_bytes + r.output_bytes));
  }
  os << "\n`per doubling`: ((t2/n2) / (t1/n1))^(1/log2(n2/n1)) against the previous size (1.00x = linear).\n\n";

  os << "## Targets (issue 8)\n\n| target | measured | met |\n|---|---|---|\n";
  for (const Target& t : ts) os << fmt::format("| {} | {} | {} |\n", t.name, t.value, yes_no(t.met));
  os << fmt::format(
      "\nReference: a GPU LBVH (Karras 2012 style, build + self-query, unsorted pairs) takes about {} ms at 10^6 "
      "boxes on an H100 (published figure, not measured here); `lbvh` in the table is such an LBVH measured in "
      "this process, on the same boxes, with the sort of its pairs.",
      kLbvhReferenceMs);
  std::vector<std::string> at6;
  for (const std::string& bp : o.broadphases)
    if (const Result* r = find_result(rs, bp, 1000000))
      at6.push_back(fmt::format("`{}` {:.2f}x", bp, kLbvhReferenceMs / r->median_ms));
  if (!at6.empty()) {
    os << " Speed-up over it at 10^6 (this bench also sorts): ";
    for (std::size_t i = 0; i < at6.size(); ++i) os << (i ? ", " : "") << at6[i];
    os << ".";
  }
  os << "\n\n## Checks\n\n";
  for (const std::string& note : oracle_notes) os << "- " << note << "\n";
  os << fmt::format("\nAll pair sets identical: {}\n", all_ok ? "yes" : "NO (exit status 3)");
}

Json to_json(const Machine& m, const Options& o, const std::vector<Result>& rs, const std::vector<Target>& ts,
             const std::vector<std::string>& oracle_notes, bool all_ok) {
  Json j;
  j["program"] = "bench_gpu_broadphase";
  j["octocd"] = m.build_id;
  j["date"] = m.date;
  j["machine"] = {{"gpu", m.gpu},
                  {"compute_capability", fmt::format("{}.{}", m.cc_major, m.cc_minor)},
                  {"sms", m.sms},
                  {"memory_bytes", m.memory},
                  {"driver", m.driver},
                  {"driver_cuda", cuda_version_text(m.driver_cuda)},
                  {"runtime_cuda", cuda_version_text(m.runtime)},
                  {"host_cpu", m.host_cpu}};
  Json config;
  BENCH_JSON_MEMBERS(config, o, sizes, broadphases, flat_max, oracle_max, reps, warmup, seed);
  config.update(Json{{"octree_depth", o.depth},
                     {"cell_size_m", decimal(o.cell_size)},
                     {"half_extents_m", {decimal(kHalfLarge), decimal(kHalfSmall)}},
                     {"cube_side_m", "3.4 * (n / 1e4)^(1/3)"},
                     {"density_per_m3", 1e4 / (kDensitySide * kDensitySide * kDensitySide)},
                     {"graph", o.graph},
                     {"timed", "find() + cub radix sort of the pair keys (exactly the pairs), CUDA events"}});
  j["config"] = std::move(config);
  Json results = Json::array();
  for (const Result& r : rs) {
    results.push_back(point_json({{"broadphase", r.broadphase}, {"n", r.n}, {"ok", r.ok}}, r, [&](Json& e) {
      BENCH_JSON_MEMBERS(e, r, median_ms, min_ms, max_ms);
      e["ns_per_body"] = r.median_ms * 1e6 / r.n;
      e["growth_per_doubling"] = r.growth ? Json(*r.growth) : Json(nullptr);
      BENCH_JSON_MEMBERS(e, r, pairs);
      e["exact_tests"] = r.candidates;
      e["device_bytes"] = r.scratch_bytes + r.output_bytes;
      BENCH_JSON_MEMBERS(e, r, scratch_bytes, output_bytes);
      e["key_capacity"] = r.capacity;
      e["capacity_regrows"] = r.regrows;
      e["times_ms"] = r.times;
    }));
  }
  j["results"] = results;
  Json targets = Json::array();
  for (const Target& t : ts) {
    Json e = t.json;
    e["target"] = t.name;
    e["measured"] = t.value;
    targets.push_back(e);
  }
  j["targets"] = targets;
  j["lbvh_reference"] = {{"median_ms_at_1e6", kLbvhReferenceMs},
                         {"what", "GPU LBVH, Karras 2012 style, build + self-query, unsorted pairs, H100 (published)"}};
  j["checks"] = oracle_notes;
  j["all_checks_passed"] = all_ok;
  return j;
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

}  // namespace

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
