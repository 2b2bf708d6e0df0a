#pragma once
// What the GPU broadphase bench's files share (bench_gpu_broadphase.cpp: one measurement, the
// machine, main; bench_gpu_motion.cpp: the coherent-motion sequence; bench_gpu_report.cpp:
// issue 8's targets and the output): its options, results, CUDA runtime wrappers, the boxes
// and small helpers (bench_gpu_common.cpp). Part of the bench program only.
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

namespace gpu_bench {

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

/// The device broadphases behind the seam (the rows of octocd/broadphase_table.def with
/// device `seam`), in the table's order: what `--only` accepts and its default.
std::vector<std::string> seam_names();

constexpr double kDensitySide = 3.4;       // cube side (m) for 10^4 boxes (boxes-random-10000)
constexpr float kHalfLarge = 0.06f;        // half extent (m) of the even bodies
constexpr float kHalfSmall = 0.03f;        // half extent (m) of the odd bodies
constexpr double kLargestExtent = 0.12;  // 2 x kHalfLarge (m)

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

/// The side (m) of the centres' cube for n boxes at boxes-random-10000's number density.
double cube_side(std::uint32_t n);

/// n boxes: centres uniform in [-s/2, s/2)^3 (x, y, z drawn in that order), half extent
/// 0.06 for even and 0.03 for odd bodies.
std::vector<Aabb> make_boxes(std::uint32_t n, std::uint64_t seed);

/// The octrees' domain: the centres' cube grown by the largest half extent.
Aabb domain_for(std::uint32_t n);

/// The capacity to grow to when `needed` keys did not fit (cuda_world.cpp's rule).
std::size_t grown(std::size_t needed, std::size_t capacity);

/// The pair key of bodies a < b as the CPU oracle's pairs are compared: (a << 32) | b.
unsigned long long key_of(std::uint32_t a, std::uint32_t b);

/// The median of v (0 when empty).
double median(std::vector<double> v);

/// A float as the double of its shortest decimal form (0.24f -> 0.24, for the JSON).
double decimal(float f);

/// `bytes` in MiB.
double mib(std::uint64_t bytes);

/// "10^4", "4x10^6" (one significant digit times a power of ten >= 10^3), or the plain number.
std::string size_label(std::uint64_t n);

/// Parses "10000,1e5,4e6" into positive integers.
std::vector<std::uint32_t> parse_sizes(const std::string& text);

/// The comma-separated names of `text`, empty ones left out.
std::vector<std::string> split_names(const std::string& text);

/// The current UTC time as ISO 8601 ("2026-01-31T12:00:00Z").
std::string utc_now();

/// The mean of v (0 when empty).
double mean(const std::vector<double>& v);

/// A markdown table's header row and its alignment row; per column its title and whether
/// it is right-aligned (numbers).
void table_head(std::ostream& os, std::initializer_list<std::pair<const char*, bool>> columns);

/// A CUDA version number (12040) as "12.4".
std::string cuda_version_text(int v);

/// The machine in one line: GPU, compute capability, SMs, memory, driver and runtime.
std::string machine_line(const Machine& m);

}  // namespace gpu_bench
