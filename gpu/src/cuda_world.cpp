// The CUDA engine's orchestration (SPEC 11): device buffers, the shapes' packed octrees,
// the step's stages in World::step's order, stage timing with CUDA events, recording and
// errors. The kernels are in the stage files (*.cu, through kernels.hpp); this file holds
// no float formula of the step.
#include "octocd/cuda_world.hpp"

#include <algorithm>
#include <chrono>
#include <cstddef>
#include <cstring>
#include <functional>
#include <initializer_list>
#include <utility>

#include <cuda_runtime_api.h>
#include <fmt/format.h>

#include "device_broadphase.hpp"
#include "device_buffer.hpp"
#include "device_footprint.hpp"
#include "kernels.hpp"
#include "octocd/error.hpp"
#include "octocd/vertex_blocks.hpp"

namespace octocd {

using gpu::BufferBase;
using gpu::check;
using gpu::cuda_text;
using gpu::DeviceBuffer;
using gpu::download;
using gpu::upload;

namespace {

using Clock = std::chrono::steady_clock;

double ms_since(Clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
}

/// The reason no device is usable, or "" when one is.
std::string no_device_reason() {
  int count = 0;
  const cudaError_t e = cudaGetDeviceCount(&count);
  if (e != cudaSuccess) {
    (void)cudaGetLastError();
    return fmt::format("cudaGetDeviceCount failed: {}", cuda_text(e));
  }
  if (count == 0) return "cudaGetDeviceCount found 0 devices";
  return "";
}

std::string describe_current_device() {
  int dev = 0;
  check(cudaGetDevice(&dev), "cudaGetDevice");
  cudaDeviceProp p{};
  check(cudaGetDeviceProperties(&p, dev), "cudaGetDeviceProperties");
  return fmt::format("{} (device {}, sm_{}{}, {:.1f} GiB)", p.name, dev, p.major, p.minor,
                     static_cast<double>(p.totalGlobalMem) / (1024.0 * 1024.0 * 1024.0));
}

constexpr int kEvents = static_cast<int>(Stage::Count) + 1;

// The host estimate (device_footprint.cpp) counts these structs by the sizes of
// device_footprint.hpp.
static_assert(sizeof(gpu::DeviceShape) == gpu::footprint::kDeviceShapeBytes, "device_footprint.hpp: DeviceShape");
static_assert(sizeof(gpu::MidItem) == gpu::footprint::kMidItemBytes, "device_footprint.hpp: MidItem");
static_assert(sizeof(gpu::DeviceContact) == gpu::footprint::kDeviceContactBytes, "device_footprint.hpp: DeviceContact");
static_assert(sizeof(gpu::StepStats) == gpu::footprint::kStepStatsBytes, "device_footprint.hpp: StepStats");
static_assert(sizeof(gpu::MetricsResult) == gpu::footprint::kMetricsResultBytes, "device_footprint.hpp: MetricsResult");
static_assert(gpu::kMetricsBlocks == gpu::footprint::kMetricsPartials, "device_footprint.hpp: kMetricsBlocks");

/// "1.23 GiB", "4.5 MiB" or "12.0 KiB": a byte count for a message.
std::string human_bytes(std::uint64_t bytes) {
  const double b = static_cast<double>(bytes);
  if (b >= 1024.0 * 1024.0 * 1024.0) return fmt::format("{:.2f} GiB", b / (1024.0 * 1024.0 * 1024.0));
  if (b >= 1024.0 * 1024.0) return fmt::format("{:.1f} MiB", b / (1024.0 * 1024.0));
  return fmt::format("{:.1f} KiB", b / 1024.0);
}

/// Throws RuntimeError when the current device has fewer than `needed` bytes free
/// (cudaMemGetInfo, or `free_bytes` of it where given: a test's seam), or more than
/// `limit` (CudaSettings::memory_limit_bytes, 0: none), naming the scene, the bytes needed
/// and free, and the device's total.
void check_free_memory(const Model& m, const std::string& broadphase, std::uint64_t needed, std::uint64_t limit,
                       const std::function<std::uint64_t(std::uint64_t)>& free_bytes) {
  std::size_t device_free = 0, total_bytes = 0;
  check(cudaMemGetInfo(&device_free, &total_bytes), "cudaMemGetInfo");
  std::uint64_t free = free_bytes ? free_bytes(device_free) : device_free;
  std::string why;
  if (limit > 0 && limit < free) {
    free = limit;
    why = fmt::format(" (memory_limit_bytes={})", limit);
  }
  if (needed <= free) return;
  throw RuntimeError(fmt::format(
      "scene '{}': the cuda engine needs about {} bytes ({}) of device memory for {} bodies before its first step "
      "(broadphase '{}'), but the device has {} bytes ({}) free{} of {} bytes ({}); run fewer bodies, or use "
      "--engine cpu",
      m.scene.name, needed, human_bytes(needed), m.initial.size(), broadphase, free, human_bytes(free), why,
      total_bytes, human_bytes(total_bytes)));
}

/// Blocks per multiprocessor of the fused small step (at most what fits, 2 on sm_90 at 119
/// registers per thread): one gives 8 warps per SM for every phase (1056 on an H100) while
/// each grid-wide barrier waits for as few blocks as possible.
constexpr int kSmallStepBlocksPerSm = 1;

/// Bodies up to which the fused small step's grid is half that (one block per two SMs):
/// its phases then have little work, and fewer blocks meet at each grid-wide barrier.
constexpr std::size_t kSmallHalfGridBodies = 64;

/// Pairs up to which the fused small step runs its response passes, clamp and metrics in
/// one block (SmallStepDesc::one_block_pairs).
constexpr std::uint32_t kSmallOneBlockPairs = 512;

/// How the host waits for the fused small step: true polls the step number the kernel
/// writes last into mapped memory (with a cudaStreamQuery now and then for errors), false
/// calls cudaStreamSynchronize. The resident kernel needs the polled wait.
constexpr bool kSmallPoll = true;

/// Whether the small path's kernel stays resident and steps on request (set_persistent
/// changes it per engine).
constexpr bool kSmallPersistent = true;

/// The resident kernel ends itself after this long without a request (unit: us; the next
/// step launches it again).
constexpr long kResidentIdleUs = 2000;

/// Bodies up to which the fused small step integrates, counts and fills without a
/// grid-wide barrier (SmallStepDesc::front_bodies; at most gpu::kSmallFrontMaxBodies).
constexpr std::uint32_t kSmallFrontBodies = 64;

/// The last midphase expand step of the graph path runs its items' leaves itself
/// (MidListDesc::fuse_leaves): -1 when it has at least kFuseItemsPerWarp items per warp,
/// as midphase.cuh decides.
constexpr int kMidFuseLeaves = -1;

/// A midphase leaf skips pairs of vertex tiles more than theta apart (MidListDesc::tile_cull).
constexpr int kMidTileCull = 1;

/// A midphase leaf stages, per tile of one mesh's vertices, only the other mesh's vertices
/// near that tile (MidListDesc::tile_filter).
constexpr int kMidTileFilter = 1;

/// The capacity to grow to when `needed` entries did not fit into `capacity`.
std::size_t grown(std::size_t needed, std::size_t capacity) {
  return std::max(needed + needed / 4 + 64, 2 * capacity);
}

}  // namespace

// ---- device state ----------------------------------------------------------------------

struct CudaWorld::Impl {
  cudaStream_t stream = nullptr;
  cudaEvent_t events[kEvents] = {};
  bool sync_each_launch = false;  // CudaSettings::sync_each_launch
  bool use_graph = true;          // CudaSettings::graph
  bool stage_times = true;        // CudaSettings::stage_times (off: no events, stage_ms stay 0)
  bool capturing = false;
  std::string device;
  std::string broadphase;
  std::unique_ptr<gpu::DeviceBroadPhase> bp;  // null for `flat`
  std::uint32_t n = 0;
  std::uint32_t shape_count = 0;
  hd::LevelList levels;
  int level_steps = 0;  // midphase steps (0: aabb-only, or no levels)
  unsigned warp_grid = 1;  // blocks of the warp-per-item midphase kernels
  int mid_fuse = kMidFuseLeaves;      // MidListDesc::fuse_leaves
  int mid_early_exit = 1;             // CudaSettings::midphase_early_exit (MidListDesc::early_exit)
  int mid_tile_cull = kMidTileCull;   // MidListDesc::tile_cull
  int mid_tile_filter = kMidTileFilter;  // MidListDesc::tile_filter
  bool small = false;       // the fused small-scene step (small_step.cu), fixed at construction
  unsigned small_grid = 1;  // its blocks (co-resident)
  gpu::StepStats* host_dev = nullptr;  // `host` as the device addresses it (mapped), or null
  std::uint32_t one_block_pairs = 0;   // SmallStepDesc::one_block_pairs
  bool small_poll = false;             // poll `done` instead of cudaStreamSynchronize
  // Pinned: [0] the last step number the kernel wrote, [1 ..] the profile's stamps.
  unsigned long long* small_host = nullptr;
  unsigned long long* small_dev = nullptr;  // the same, mapped (null: no polling, no profile)
  unsigned long long sequence = 0;
  bool small_profile = false;  // CudaSettings::small_profile
  double profile_ns[gpu::kSmallProfileSlots] = {};  // sums: slot p - slot p-1; [0]: host launch to seen done
  double profile_kernel_ns = 0.0;                   // sum of slot 9 - slot 0
  std::uint64_t profile_steps = 0;
  std::uint32_t front_bodies = 0;  // SmallStepDesc::front_bodies (kSmallFrontBodies)

  // The resident small step (kSmallPersistent, set_persistent): its own stream, so that the copies
  // and waits on `stream` never queue behind it.
  bool resident_possible = false;  // small path, polled wait, mapped memory, the kernel fits
  bool persistent = false;         // run steps through the resident kernel
  bool resident_alive = false;     // launched, and not yet seen to have exited
  bool resident_hung = false;      // an exit request went unanswered: nothing may be freed
  bool resident_stall = false;     // TestHooks::resident_ignores_requests
  unsigned resident_grid = 1;
  unsigned long long resident_idle_ns = 0;
  long resident_timeout_ms = 60000;  // CudaSettings::resident_timeout_ms
  unsigned long long epoch = 0;           // launches so far; the last one's number
  std::uint64_t resident_launches = 0;
  cudaStream_t resident_stream = nullptr;
  // Pinned: [0] the request (host writes), [8] the exit mark (kernel writes); apart, so the
  // two sides write different cache lines.
  static constexpr int kRequestWord = 0;
  static constexpr int kExitedWord = 8;
  unsigned long long* resident_host = nullptr;
  unsigned long long* resident_dev = nullptr;  // the same, mapped
  DeviceBuffer<unsigned long long> resident_control{"resident step control"};

  // Capacities of the variable-size buffers (entries); prepare() sizes the buffers.
  std::size_t pair_cap = 1;
  std::size_t list_cap = 1;
  bool prepared = false;
  std::uint64_t static_static = 0;  // static_static_pairs(model): constant over the run

  // Bodies (fixed size n).
  DeviceBuffer<Vec3> x{"body positions"};
  DeviceBuffer<Vec3> v{"body velocities"};
  DeviceBuffer<Vec3> x_saved{"body positions before the step"};
  DeviceBuffer<Vec3> v_saved{"body velocities before the step"};
  DeviceBuffer<float> w{"body inverse masses"};
  DeviceBuffer<Aabb> local{"body local boxes"};
  DeviceBuffer<std::uint32_t> shape{"body shapes"};
  DeviceBuffer<Aabb> aabb{"world AABBs"};
  // Shapes, packed once.
  DeviceBuffer<gpu::DeviceShape> shapes{"shapes"};
  DeviceBuffer<Vec3> vertices{"octree vertices"};
  DeviceBuffer<MeshOctreeCell> cells{"octree cells"};
  DeviceBuffer<std::uint32_t> level_offsets{"octree level offsets"};
  DeviceBuffer<Aabb> blocks{"octree vertex block boxes"};
  DeviceBuffer<float> theta{"per-shape theta"};
  DeviceBuffer<gpu::StepStats> stats{"step statistics"};
  DeviceBuffer<gpu::MetricsResult> metric_partials{"metrics partial sums"};
  // Variable size (pair_cap, list_cap), grown on overflow; reset_capacities shrinks them.
  DeviceBuffer<std::uint32_t> bp_count{"broadphase counts"};
  DeviceBuffer<std::uint32_t> bp_offset{"broadphase offsets"};
  DeviceBuffer<unsigned long long> pair_keys{"pair keys"};
  DeviceBuffer<unsigned long long> pair_keys_sorted{"sorted pair keys"};
  DeviceBuffer<Pair> pairs{"candidate pairs"};
  DeviceBuffer<std::uint8_t> confirmed{"confirmed flags"};
  DeviceBuffer<gpu::MidItem> items_a{"midphase work list A"};
  DeviceBuffer<gpu::MidItem> items_b{"midphase work list B"};
  DeviceBuffer<std::uint8_t> hit{"contact hit flags"};
  DeviceBuffer<Vec3> dx_a{"contact dx_a"};
  DeviceBuffer<Vec3> dx_b{"contact dx_b"};
  DeviceBuffer<Vec3> dv_a{"contact dv_a"};
  DeviceBuffer<Vec3> dv_b{"contact dv_b"};
  DeviceBuffer<float> depth0{"contact depths"};
  DeviceBuffer<gpu::DeviceContact> records{"contact records"};
  DeviceBuffer<std::uint32_t> keys_in{"contact index keys"};
  DeviceBuffer<std::uint32_t> keys_out{"sorted contact index keys"};
  DeviceBuffer<std::uint32_t> vals_in{"contact index entries"};
  DeviceBuffer<std::uint32_t> vals_out{"sorted contact index entries"};
  DeviceBuffer<std::uint32_t> body_begin{"body contact segments"};
  DeviceBuffer<std::uint32_t> in_count{"small-step column counts"};  // small path only
  DeviceBuffer<unsigned char> temp{"CUB temporary storage"};

  gpu::StepStats* host = nullptr;  // pinned
  cudaGraph_t graph = nullptr;
  cudaGraphExec_t graph_exec = nullptr;

  ~Impl() {
    try {
      stop_resident();
    } catch (const std::exception&) {  // a hung kernel: resident_hung is set
    }
    if (resident_hung) {
      // cudaFree and cudaFreeHost would wait for the kernel forever: leave the memory to the
      // process's end (the driver reclaims it).
      for (BufferBase* b : all_buffers()) b->abandon();
      resident_control.abandon();
      (void)bp.release();
      return;
    }
    drop_graph();
    if (host) (void)cudaFreeHost(host);
    if (small_host) (void)cudaFreeHost(small_host);
    if (resident_host) (void)cudaFreeHost(resident_host);
    for (cudaEvent_t& e : events)
      if (e) (void)cudaEventDestroy(e);
    if (stream) (void)cudaStreamDestroy(stream);
    if (resident_stream) (void)cudaStreamDestroy(resident_stream);
  }

  void drop_graph() {
    if (graph_exec) (void)cudaGraphExecDestroy(graph_exec);
    if (graph) (void)cudaGraphDestroy(graph);
    graph_exec = nullptr;
    graph = nullptr;
  }

  std::vector<BufferBase*> all_buffers() {
    std::vector<BufferBase*> all{&x, &v, &x_saved, &v_saved, &w, &local, &shape, &aabb, &shapes, &vertices, &cells,
                                 &level_offsets, &blocks, &theta, &stats, &metric_partials};
    for (BufferBase* b : scratch_buffers()) all.push_back(b);
    return all;
  }
  std::vector<BufferBase*> scratch_buffers() {
    return {&bp_count, &bp_offset, &pair_keys, &pair_keys_sorted, &pairs, &confirmed, &items_a, &items_b,
            &hit,      &dx_a,      &dx_b,      &dv_a,             &dv_b,  &depth0,    &records, &keys_in,
            &keys_out, &vals_in,   &vals_out,  &body_begin,       &temp,  &in_count};
  }

  /// Checks a launch; with sync_each_launch also waits for it and checks its execution.
  void launched(cudaError_t e, const char* kernel) {
    if (e != cudaSuccess) {
      (void)cudaGetLastError();
      throw RuntimeError(fmt::format("CUDA kernel '{}' failed to launch: {}", kernel, cuda_text(e)));
    }
    if (sync_each_launch && !capturing) {
      e = cudaStreamSynchronize(stream);
      if (e != cudaSuccess) throw RuntimeError(fmt::format("CUDA kernel '{}' failed: {}", kernel, cuda_text(e)));
    }
  }

  void record_event(int i) {
    if (!stage_times) return;
    check(cudaEventRecordWithFlags(events[i], stream, capturing ? cudaEventRecordExternal : cudaEventRecordDefault),
          "cudaEventRecord");
  }

  unsigned long long* counters() { return stats.get()->counters; }
  std::uint32_t* counts() { return stats.get()->counts; }

  gpu::BodiesDesc bodies() {
    gpu::BodiesDesc b;
    b.x = x.get();
    b.v = v.get();
    b.w = w.get();
    b.local = local.get();
    b.shape = shape.get();
    b.aabb = aabb.get();
    b.n = n;
    return b;
  }

  gpu::ShapesDesc shapes_desc() {
    gpu::ShapesDesc s;
    s.shapes = shapes.get();
    s.vertices = vertices.get();
    s.cells = cells.get();
    s.level_offsets = level_offsets.get();
    s.blocks = blocks.get();
    s.theta = theta.get();
    s.count = shape_count;
    return s;
  }

  std::uint32_t pcap() const { return static_cast<std::uint32_t>(pair_cap); }

  /// The midphase lists' common fields (in / out are set per step): pairs from `keys`.
  gpu::MidListDesc mid_desc(const unsigned long long* keys) {
    gpu::MidListDesc md;
    md.x = x.get();
    md.w = w.get();
    md.aabb = aabb.get();
    md.shape = shape.get();
    md.shapes = shapes_desc();
    md.levels = levels;
    md.pairs = pairs.get();
    md.pair_keys = keys;
    md.pair_shift = gpu::key_bits(n);
    md.pair_count = counts();
    md.pair_capacity = pcap();
    md.confirmed = confirmed.get();
    md.counters = counters();
    md.steps = level_steps;
    md.fuse_leaves = mid_fuse;
    md.early_exit = mid_early_exit;
    md.tile_cull = mid_tile_cull;
    md.tile_filter = mid_tile_filter;
    return md;
  }

  /// contact_terms' descriptor (depth0 and records unset: per pass).
  gpu::TermsDesc terms_desc(const ContactParams& params) {
    gpu::TermsDesc td;
    td.pairs = pairs.get();
    td.confirmed = confirmed.get();
    td.pair_count = counts();
    td.pair_capacity = pcap();
    td.x = x.get();
    td.v = v.get();
    td.w = w.get();
    td.local = local.get();
    td.params = params;
    td.hit = hit.get();
    td.dx_a = dx_a.get();
    td.dx_b = dx_b.get();
    td.dv_a = dv_a.get();
    td.dv_b = dv_b.get();
    return td;
  }

  /// apply_sums' descriptor over the sorted contact index.
  gpu::ApplyDesc apply_desc() {
    gpu::ApplyDesc ad;
    ad.x = x.get();
    ad.v = v.get();
    ad.w = w.get();
    ad.n = n;
    ad.body_begin = body_begin.get();
    ad.entries = vals_out.get();
    ad.hit = hit.get();
    ad.dx_a = dx_a.get();
    ad.dx_b = dx_b.get();
    ad.dv_a = dv_a.get();
    ad.dv_b = dv_b.get();
    return ad;
  }

  gpu::MetricsDesc metrics_desc(const ContactParams& params) {
    gpu::MetricsDesc xd;
    xd.x = x.get();
    xd.v = v.get();
    xd.w = w.get();
    xd.n = n;
    xd.depth0 = depth0.get();
    xd.pair_count = counts();
    xd.pair_capacity = pcap();
    xd.slop = params.slop;
    xd.out = &stats.get()->metrics;
    xd.partials = metric_partials.get();
    return xd;
  }

  /// The fused small step's descriptor (small_step.cu): the same buffers as the graph
  /// path; the in-lists live in keys_in, their offsets in body_begin.
  gpu::SmallStepDesc small_desc(const Scene& scene, bool recording) {
    const ContactParams& params = scene.response;
    gpu::SmallStepDesc s;
    s.bodies = bodies();
    s.bodies.x_saved = x_saved.get();
    s.bodies.v_saved = v_saved.get();
    s.gravity = scene.gravity;
    s.dt = scene.dt;
    s.max_velocity = params.max_velocity;
    s.iterations = params.iterations;
    s.out_count = bp_count.get();
    s.out_offset = bp_offset.get();
    s.in_count = in_count.get();
    s.in_offset = body_begin.get();
    s.in_list = keys_in.get();
    s.pair_keys = pair_keys.get();
    s.shift = gpu::key_bits(n);
    s.mid = mid_desc(pair_keys.get());  // the fill writes them in (a, b) order: no sort
    s.lists[0] = items_a.get();
    s.lists[1] = items_b.get();
    s.list_capacity = lcap();
    s.terms = terms_desc(params);
    s.terms.depth0 = depth0.get();
    s.terms.records = recording ? records.get() : nullptr;
    s.apply = apply_desc();
    s.metrics = metrics_desc(params);
    s.stats = stats.get();
    s.host_stats = host_dev;
    s.one_block_pairs = one_block_pairs;
    s.front_bodies = front_bodies;
    s.lean = n <= gpu::kSmallLeanBodies ? 1 : 0;
    if (small_dev) {
      s.done = small_dev;
      s.sequence = sequence;
      if (small_profile) s.profile = small_dev + 1;
    }
    return s;
  }
  std::uint32_t lcap() const { return static_cast<std::uint32_t>(list_cap); }

  /// Sizes every buffer for the current capacities (outside any capture); a change drops
  /// the captured graph.
  void prepare() {
    if (prepared) return;
    drop_graph();
    if (pair_cap > 0x7fffffffu || list_cap > 0x7fffffffu)
      throw RuntimeError(fmt::format("the step needs more than 2^31 - 1 pairs ({}) or midphase items ({})",
                                     pair_cap, list_cap));
    const std::size_t n1 = static_cast<std::size_t>(n) + 1;
    bp_count.ensure(n1);
    bp_offset.ensure(n1);
    for (BufferBase* b : std::initializer_list<BufferBase*>{&pair_keys, &pair_keys_sorted, &pairs, &confirmed, &hit,
                                                             &dx_a, &dx_b, &dv_a, &dv_b, &depth0, &records})
      b->ensure(pair_cap);
    for (BufferBase* b : std::initializer_list<BufferBase*>{&keys_in, &keys_out, &vals_in, &vals_out})
      b->ensure(2 * pair_cap);
    items_a.ensure(list_cap);
    items_b.ensure(list_cap);
    body_begin.ensure(n1);
    if (small) in_count.ensure(n1);
    std::size_t a = 0, b = 0, c = 0;
    check(gpu::sort_keys_u64(nullptr, a, pair_keys.get(), pair_keys_sorted.get(), pcap(), 2 * gpu::key_bits(n),
                             stream),
          "cub::DeviceRadixSort::SortKeys (size)");
    check(gpu::sort_pairs_u32(nullptr, b, keys_in.get(), keys_out.get(), vals_in.get(), vals_out.get(), 2 * pcap(),
                              gpu::key_bits(n), stream),
          "cub::DeviceRadixSort::SortPairs (size)");
    check(gpu::exclusive_scan_u32(nullptr, c, bp_count.get(), bp_offset.get(), n + 1, stream),
          "cub::DeviceScan::ExclusiveSum (size)");
    temp.ensure(std::max({a, b, c, std::size_t{1}}));
    if (bp) bp->reserve(n, stream);
    prepared = true;
  }

  /// Broadphase `flat` (SPEC 5.1): count, exclusive scan over n + 1 (the last count is 0,
  /// so offset[n] is the total), fill the keys that fit.
  void flat_broadphase() {
    const std::size_t n1 = static_cast<std::size_t>(n) + 1;
    check(cudaMemsetAsync(bp_count.get(), 0, n1 * sizeof(std::uint32_t), stream), "cudaMemset broadphase counts");
    launched(gpu::launch_flat_count(aabb.get(), n, bp_count.get(), stream), "flat_count");
    std::size_t bytes = temp.capacity();
    launched(gpu::exclusive_scan_u32(temp.get(), bytes, bp_count.get(), bp_offset.get(), n + 1, stream),
             "cub::DeviceScan::ExclusiveSum");
    check(cudaMemcpyAsync(counts(), bp_offset.get() + n, sizeof(std::uint32_t), cudaMemcpyDeviceToDevice, stream),
          "cudaMemcpy pair total");
    launched(gpu::launch_flat_fill(aabb.get(), n, bp_offset.get(), pair_keys.get(), pcap(), gpu::key_bits(n),
                                   stream),
             "flat_fill");
  }

  /// Enqueues one whole step on the stream: no allocation, no host synchronisation (it
  /// may be captured into a graph). `recording`: the first pass writes contact records.
  void enqueue_step(const Scene& scene, bool recording) {
    const ContactParams& params = scene.response;
    const gpu::BodiesDesc b = bodies();
    record_event(0);
    // 1. Integrate (Eq. 1-3), keeping the state before the step for a rerun.
    gpu::BodiesDesc bi = b;
    bi.x_saved = x_saved.get();
    bi.v_saved = v_saved.get();
    launched(gpu::launch_integrate(bi, scene.gravity, scene.dt, stream), "integrate");
    record_event(1);
    // 2. World AABBs.
    launched(gpu::launch_aabbs(b, stream), "aabbs");
    record_event(2);
    // 3. Broadphase (SPEC 5.1): pair keys (padding sorts last), sorted, unpacked.
    static_assert(offsetof(gpu::StepStats, counts) ==
                      offsetof(gpu::StepStats, counters) + sizeof(gpu::StepStats::counters),
                  "counters and counts are contiguous");
    check(cudaMemsetAsync(counters(), 0, sizeof(gpu::StepStats::counters) + sizeof(gpu::StepStats::counts), stream),
          "cudaMemset step counts");
    // A broadphase that sorts its own keys (`octree`) writes them straight into the sorted
    // buffer (pair_keys as its scratch), after which the padding stays all ones.
    const bool self_sorts = bp && bp->sorts_pairs();
    check(cudaMemsetAsync(self_sorts ? pair_keys_sorted.get() : pair_keys.get(), 0xff,
                          pair_cap * sizeof(unsigned long long), stream),
          "cudaMemset pair keys");
    if (bp) {
      gpu::PairOutput out;
      out.keys = self_sorts ? pair_keys_sorted.get() : pair_keys.get();
      out.scratch = self_sorts ? pair_keys.get() : nullptr;
      out.capacity = pcap();
      out.total = counts();
      out.candidates = counters() + 3;
      out.shift = gpu::key_bits(n);
      bp->find(aabb.get(), n, out, stream);
    } else {
      flat_broadphase();
    }
    std::size_t bytes = temp.capacity();
    // Keys are (a << key_bits(n)) | b: the sort covers 2 key_bits(n) bits (padding keys,
    // all ones, still sort after every real key: a < b < 2^key_bits(n)).
    if (!self_sorts)
      launched(gpu::sort_keys_u64(temp.get(), bytes, pair_keys.get(), pair_keys_sorted.get(), pcap(),
                                  2 * gpu::key_bits(n), stream),
               "cub::DeviceRadixSort::SortKeys");
    record_event(3);  // the pairs are unpacked from the sorted keys by mid_start
    // 4. Midphase + narrow phase (SPEC 5.2-5.3) as per-level work lists.
    gpu::MidListDesc md = mid_desc(pair_keys_sorted.get());
    gpu::MidItem* lists[2] = {items_a.get(), items_b.get()};
    md.out = lists[0];
    md.out_count = counts() + 1;
    md.out_capacity = lcap();
    launched(gpu::launch_mid_start(md, warp_grid, stream), "mid_start");
    for (int i = 0; i + 1 < level_steps; ++i) {
      md.in = lists[i % 2];
      md.in_count = counts() + 1 + i;
      md.in_capacity = lcap();
      md.out = lists[(i + 1) % 2];
      md.out_count = counts() + 2 + i;
      launched(gpu::launch_mid_expand(md, i, warp_grid, stream), "mid_expand");
    }
    if (level_steps > 0) {
      md.in = lists[(level_steps - 1) % 2];
      md.in_count = counts() + level_steps;
      md.in_capacity = lcap();
      md.out = nullptr;
      md.out_count = nullptr;
      md.out_capacity = 0;
      launched(gpu::launch_mid_leaf(md, warp_grid, stream), "mid_leaf");
    }
    record_event(4);
    // 5. Response (SPEC 6): body-major index of the confirmed contacts (stable sort by
    // body keeps (a, b) order per body), `iterations` passes, then the clamp (Eq. 23).
    const std::uint32_t entries = 2 * pcap();
    launched(gpu::launch_contact_entries(pairs.get(), confirmed.get(), counts(), pcap(), n, keys_in.get(),
                                         vals_in.get(), stream),
             "contact_entries");
    bytes = temp.capacity();
    launched(gpu::sort_pairs_u32(temp.get(), bytes, keys_in.get(), keys_out.get(), vals_in.get(), vals_out.get(),
                                 entries, gpu::key_bits(n), stream),
             "cub::DeviceRadixSort::SortPairs");
    launched(gpu::launch_body_segments(keys_out.get(), entries, n, body_begin.get(), stream), "body_segments");
    gpu::TermsDesc td = terms_desc(params);
    const gpu::ApplyDesc ad = apply_desc();
    for (int pass = 0; pass < params.iterations; ++pass) {
      td.depth0 = pass == 0 ? depth0.get() : nullptr;
      td.records = pass == 0 && recording ? records.get() : nullptr;
      launched(gpu::launch_contact_terms(td, stream), "contact_terms");
      launched(gpu::launch_apply_sums(ad, stream), "apply_sums");
    }
    launched(gpu::launch_clamp(b, params.max_velocity, stream), "clamp");
    record_event(5);
    // 6. Metrics, and everything the host reads, in one place.
    launched(gpu::launch_metrics(metrics_desc(params), stream), "metrics");
    check(cudaMemcpyAsync(host, stats.get(), sizeof(gpu::StepStats), cudaMemcpyDeviceToHost, stream),
          "cudaMemcpy step statistics");
    record_event(6);
  }

  /// Runs the step: from the captured graph when allowed (not recording, graphs on), else
  /// launch by launch; then waits for it.
  void run_step(const Scene& scene, bool recording) {
    if (!prepared) stop_resident();  // prepare() frees buffers: cudaFree waits for every kernel
    prepare();
    if (small) {  // one cooperative launch; the statistics come back through mapped memory
      const auto t0 = std::chrono::steady_clock::now();
      ++sequence;
      if (persistent) {
        resident_step(scene, recording);
      } else {
        launched(gpu::launch_small_step(small_desc(scene, recording), small_grid, stream), "small_step");
        if (!host_dev)
          check(cudaMemcpyAsync(host, stats.get(), sizeof(gpu::StepStats), cudaMemcpyDeviceToHost, stream),
                "cudaMemcpy step statistics");
        if (small_poll && host_dev && small_dev) wait_small_step();
        else check(cudaStreamSynchronize(stream), "cudaStreamSynchronize (step)");
      }
      if (small_profile && small_dev) {
        const double host_ns = std::chrono::duration<double, std::nano>(std::chrono::steady_clock::now() - t0).count();
        volatile const unsigned long long* p = small_host + 1;
        for (int i = 1; i < gpu::kSmallProfileSlots; ++i) profile_ns[i] += static_cast<double>(p[i] - p[i - 1]);
        profile_ns[0] += host_ns;
        profile_kernel_ns += static_cast<double>(p[gpu::kSmallProfileSlots - 1] - p[0]);
        ++profile_steps;
      }
      return;
    }
    if (use_graph && !sync_each_launch && !recording) {
      if (!graph_exec) {
        capturing = true;
        check(cudaStreamBeginCapture(stream, cudaStreamCaptureModeThreadLocal), "cudaStreamBeginCapture");
        try {
          enqueue_step(scene, false);
        } catch (...) {
          cudaGraph_t g = nullptr;
          (void)cudaStreamEndCapture(stream, &g);
          if (g) (void)cudaGraphDestroy(g);
          capturing = false;
          throw;
        }
        capturing = false;
        check(cudaStreamEndCapture(stream, &graph), "cudaStreamEndCapture");
        check(cudaGraphInstantiate(&graph_exec, graph, 0), "cudaGraphInstantiate");
      }
      check(cudaGraphLaunch(graph_exec, stream), "cudaGraphLaunch");
    } else {
      enqueue_step(scene, recording);
    }
    check(cudaStreamSynchronize(stream), "cudaStreamSynchronize (step)");
  }

  /// Spins until the fused step's kernel has written this step's number (its last write,
  /// after the statistics); every 1024 spins asks the stream, so a failed kernel throws and
  /// a finished one ends the wait whatever the flag says.
  void wait_small_step() {
    volatile const unsigned long long* done = small_host;
    for (unsigned spins = 1; *done != sequence; ++spins) {
      if ((spins & 1023u) != 0) continue;
      const cudaError_t e = cudaStreamQuery(stream);
      if (e == cudaSuccess) break;
      if (e != cudaErrorNotReady) check(e, "small_step (cudaStreamQuery)");
    }
  }

  // ---- the resident small step --------------------------------------------------------

  volatile unsigned long long* request_word() { return resident_host + kRequestWord; }
  unsigned long long exited_mark() const {
    return __atomic_load_n(resident_host + kExitedWord, __ATOMIC_ACQUIRE);
  }
  unsigned long long done_mark() const { return __atomic_load_n(small_host, __ATOMIC_ACQUIRE); }
  void write_request(unsigned long long value) {
    __atomic_store_n(resident_host + kRequestWord, value, __ATOMIC_SEQ_CST);  // drains the store buffer
  }

  /// Launches the resident kernel on its stream (after any earlier one there); the request
  /// already written is its first.
  void launch_resident(const Scene& scene) {
    gpu::ResidentDesc r;
    r.request = resident_dev + kRequestWord;
    r.exited = resident_dev + kExitedWord;
    r.control = resident_control.get();
    r.handled = 0;  // every request is > 0 (sequence >= 1)
    r.epoch = ++epoch;
    r.idle_ns = resident_stall ? 0 : resident_idle_ns;
    r.records = records.get();
    r.stall = resident_stall ? 1 : 0;
    const cudaError_t e = gpu::launch_small_resident(small_desc(scene, false), r, resident_grid, resident_stream);
    if (e != cudaSuccess) {
      (void)cudaGetLastError();
      throw RuntimeError(fmt::format("CUDA kernel 'small_resident' failed to launch: {}", cuda_text(e)));
    }
    resident_alive = true;
    ++resident_launches;
  }

  /// One step through the resident kernel: writes the request (launching the kernel when
  /// none is resident, or when the one resident ended itself, idle, without taking it), then
  /// spins until the kernel writes the step's number. Throws RuntimeError after
  /// resident_timeout_ms, or when the kernel failed.
  void resident_step(const Scene& scene, bool recording) {
    if (resident_alive && exited_mark() == epoch) stop_resident();  // it ended itself, idle
    write_request((sequence << gpu::kResidentShift) | (recording ? gpu::kResidentRecord : 0ull));
    if (!resident_alive) launch_resident(scene);
    const auto t0 = Clock::now();
    for (unsigned spins = 1;; ++spins) {
      if (done_mark() == sequence) return;
      if (exited_mark() == epoch) {
        if (done_mark() == sequence) return;  // it ran the step, then ended idle
        resident_alive = false;               // it ended without taking the request
        launch_resident(scene);
        continue;
      }
      if ((spins & 1023u) != 0) continue;
      const cudaError_t e = cudaStreamQuery(resident_stream);
      if (e != cudaSuccess && e != cudaErrorNotReady) {
        resident_alive = false;
        check(e, "small_resident (cudaStreamQuery)");
      }
      if (ms_since(t0) > static_cast<double>(resident_timeout_ms))
        throw RuntimeError(fmt::format(
            "the resident small-step kernel did not finish step {} within {} ms (resident_timeout_ms; "
            "launch {}{}); the engine cannot step any more: destroy it, and call set_persistent(false) on a new "
            "engine to launch a kernel per step",
            sequence, resident_timeout_ms, epoch,
            resident_stall ? ", the test hook resident_ignores_requests makes it ignore requests" : ""));
    }
  }

  /// Ends the resident kernel (when one runs) and waits for it: before anything frees or
  /// reallocates device memory, and in the destructor. Throws RuntimeError (and marks the
  /// engine hung: its memory is then never freed) when the kernel does not end within
  /// resident_timeout_ms.
  void stop_resident() {
    if (!resident_alive) return;
    const auto t0 = Clock::now();
    if (exited_mark() != epoch) {
      write_request((sequence << gpu::kResidentShift) | gpu::kResidentExit);
      for (unsigned spins = 1; exited_mark() != epoch; ++spins) {
        if ((spins & 1023u) != 0) continue;
        const cudaError_t e = cudaStreamQuery(resident_stream);
        if (e == cudaSuccess) break;  // ended (its mark is then visible too)
        if (e != cudaErrorNotReady) {
          resident_alive = false;
          check(e, "small_resident (cudaStreamQuery, exit)");
        }
        if (ms_since(t0) > static_cast<double>(resident_timeout_ms)) {
          resident_hung = true;
          throw RuntimeError(fmt::format("the resident small-step kernel did not end within {} ms of the exit "
                                         "request (resident_timeout_ms); its device memory is left "
                                         "allocated",
                                         resident_timeout_ms));
        }
      }
    }
    resident_alive = false;
    check(cudaStreamSynchronize(resident_stream), "cudaStreamSynchronize (resident kernel's end)");
  }

  /// True when a list overflowed its capacity; grows the capacities then (the state must
  /// be restored and the step run again).
  bool grow_if_needed() {
    bool grow = false;
    const std::size_t pairs_found = host->counts[0];
    if (pairs_found > pair_cap) {
      pair_cap = grown(pairs_found, pair_cap);
      grow = true;
    }
    std::size_t items = 0;
    for (int i = 0; i < level_steps; ++i) items = std::max<std::size_t>(items, host->counts[1 + i]);
    if (items > list_cap) {
      list_cap = grown(items, list_cap);
      grow = true;
    }
    if (grow) {
      prepared = false;
      stop_resident();  // before restore_state and prepare()
    }
    return grow;
  }

  void restore_state() {
    const std::size_t vec_bytes = static_cast<std::size_t>(n) * sizeof(Vec3);
    if (n == 0) return;
    check(cudaMemcpyAsync(x.get(), x_saved.get(), vec_bytes, cudaMemcpyDeviceToDevice, stream), "cudaMemcpy restore x");
    check(cudaMemcpyAsync(v.get(), v_saved.get(), vec_bytes, cudaMemcpyDeviceToDevice, stream), "cudaMemcpy restore v");
    check(cudaStreamSynchronize(stream), "cudaStreamSynchronize (restore)");
  }
};

// ---- free functions ----------------------------------------------------------------------

std::string cuda_device_status() {
  try {
    const std::string reason = no_device_reason();
    if (!reason.empty()) return "no CUDA device: " + reason;
    return describe_current_device();
  } catch (const std::exception& e) {
    return std::string("no CUDA device: ") + e.what();
  }
}

bool cuda_device_available() { return no_device_reason().empty(); }

std::unique_ptr<Engine> make_cuda_engine(std::shared_ptr<const Model> model, const std::string& broadphase,
                                         const CudaSettings& settings) {
  return std::make_unique<CudaWorld>(std::move(model), broadphase, settings);
}

// ---- CudaWorld ---------------------------------------------------------------------------

CudaWorld::CudaWorld(std::shared_ptr<const Model> model, const std::string& broadphase,
                     const CudaSettings& settings, const TestHooks& hooks)
    : model_(std::move(model)), impl_(std::make_unique<Impl>()) {
  if (!model_) throw InputError("CudaWorld: no model given");
  require_translation_only(model_->scene, "cuda");  // SPEC 3: octocd's engines translate only
  // Needs no device; throws InputError for more than kCudaMaxBodies bodies and for a
  // broadphase the device does not have, before anything is sized from the body count.
  const std::uint64_t needed = cuda_device_bytes_needed(*model_, broadphase);
  std::unique_ptr<gpu::DeviceBroadPhase> bp;
  if (broadphase != "flat") {  // checked before the device: an unknown name is an input error anywhere
    BroadPhaseConfig cfg = model_->scene.broadphase;
    cfg.name = broadphase;
    bp = gpu::make_device_broadphase(cfg, model_->scene.domain);
  }
  check_cuda_settings(settings, "cuda settings");  // input wherever it is read, device or not
  if (hooks.resident_idle_us < 0) throw InputError("CudaWorld::TestHooks: resident_idle_us < 0");
  const std::string reason = no_device_reason();
  if (!reason.empty()) throw RuntimeError("no CUDA device: " + reason + "; the cuda engine needs one");
  check_free_memory(*model_, broadphase, needed, settings.memory_limit_bytes,
                    hooks.free_bytes);  // before the first allocation

  Impl& d = *impl_;
  d.broadphase = broadphase;
  d.bp = std::move(bp);
  d.device = describe_current_device();
  d.mid_early_exit = settings.midphase_early_exit ? 1 : 0;
  d.sync_each_launch = settings.sync_each_launch;
  d.use_graph = settings.graph;
  d.stage_times = settings.stage_times;
  {
    int dev = 0, sms = 1;
    check(cudaGetDevice(&dev), "cudaGetDevice");
    check(cudaDeviceGetAttribute(&sms, cudaDevAttrMultiProcessorCount, dev), "cudaDeviceGetAttribute");
    d.warp_grid = static_cast<unsigned>(std::max(1, sms) * 4);
    // The fused small step: wanted for this scene, and launchable (a device that cannot
    // launch cooperative kernels, or a kernel that does not fit, keeps the graph).
    const std::size_t bodies = model_->initial.size();
    const bool wanted = bodies >= 1 && bodies <= kCudaSmallStepMaxBodies && !d.stage_times;
    int coop = 0, per_sm = 0;
    if (wanted) {
      check(cudaDeviceGetAttribute(&coop, cudaDevAttrCooperativeLaunch, dev), "cudaDeviceGetAttribute");
      if (coop) check(gpu::small_step_blocks_per_sm(per_sm), "cudaOccupancyMaxActiveBlocksPerMultiprocessor");
    }
    if (wanted && coop && per_sm > 0) {
      int blocks = std::min(per_sm, kSmallStepBlocksPerSm) * std::max(1, sms);
      if (bodies <= kSmallHalfGridBodies) blocks = (blocks + 1) / 2;
      d.small = true;
      d.small_grid = static_cast<unsigned>(blocks);
      // The resident kernel: the same grid where it fits (it may need more registers).
      int resident_per_sm = 0;
      check(gpu::small_resident_blocks_per_sm(resident_per_sm), "cudaOccupancyMaxActiveBlocksPerMultiprocessor");
      if (resident_per_sm > 0) {
        d.resident_grid = static_cast<unsigned>(std::min(blocks, resident_per_sm * std::max(1, sms)));
        d.resident_possible = true;
      }
    }
  }
  check(cudaMallocHost(reinterpret_cast<void**>(&d.host), sizeof(gpu::StepStats)), "cudaMallocHost (step read-back)");
  *d.host = gpu::StepStats{};
  if (d.small) {  // the kernel writes the statistics straight into the pinned host copy
    void* mapped = nullptr;
    if (cudaHostGetDevicePointer(&mapped, d.host, 0) == cudaSuccess) d.host_dev = static_cast<gpu::StepStats*>(mapped);
    else (void)cudaGetLastError();  // no mapping: a copy after the kernel instead
    d.one_block_pairs = kSmallOneBlockPairs;
    d.small_poll = kSmallPoll;
    d.small_profile = settings.small_profile;
    check(cudaMallocHost(reinterpret_cast<void**>(&d.small_host),
                         sizeof(unsigned long long) * (1 + gpu::kSmallProfileSlots)),
          "cudaMallocHost (step number, profile)");
    for (int i = 0; i <= gpu::kSmallProfileSlots; ++i) d.small_host[i] = 0;
    void* mapped_done = nullptr;
    if (d.host_dev && cudaHostGetDevicePointer(&mapped_done, d.small_host, 0) == cudaSuccess)
      d.small_dev = static_cast<unsigned long long*>(mapped_done);
    else (void)cudaGetLastError();
    d.front_bodies = kSmallFrontBodies;
    // The resident kernel needs the polled wait (mapped memory) and no per-launch sync.
    d.resident_possible = d.resident_possible && d.small_poll && d.small_dev && !d.sync_each_launch;
    if (d.resident_possible) {
      check(cudaMallocHost(reinterpret_cast<void**>(&d.resident_host), sizeof(unsigned long long) * 16),
            "cudaMallocHost (resident step request)");
      for (int i = 0; i < 16; ++i) d.resident_host[i] = 0;
      void* mapped_request = nullptr;
      if (cudaHostGetDevicePointer(&mapped_request, d.resident_host, 0) == cudaSuccess) {
        d.resident_dev = static_cast<unsigned long long*>(mapped_request);
      } else {
        (void)cudaGetLastError();
        d.resident_possible = false;
      }
    }
    d.persistent = kSmallPersistent && d.resident_possible;
    const long idle_us = hooks.resident_idle_us > 0 ? hooks.resident_idle_us : kResidentIdleUs;
    d.resident_idle_ns = static_cast<unsigned long long>(idle_us) * 1000ull;
    d.resident_timeout_ms = settings.resident_timeout_ms;
    d.resident_stall = hooks.resident_ignores_requests;
  }
  check(cudaStreamCreateWithFlags(&d.stream, cudaStreamNonBlocking), "cudaStreamCreate");
  if (d.resident_possible) {
    check(cudaStreamCreateWithFlags(&d.resident_stream, cudaStreamNonBlocking), "cudaStreamCreate (resident)");
    d.resident_control.reset(2);
    check(cudaMemsetAsync(d.resident_control.get(), 0, 2 * sizeof(unsigned long long), d.stream),
          "cudaMemset resident control");
  }
  for (cudaEvent_t& e : d.events) check(cudaEventCreate(&e), "cudaEventCreate");

  const Model& m = *model_;
  const std::size_t n = m.initial.size();  // <= kCudaMaxBodies (checked above)
  d.n = static_cast<std::uint32_t>(n);

  // Midphase level list (SPEC 5.2), as the CPU's confirm_contact converts it.
  const MidphaseConfig& mc = m.scene.midphase;
  d.levels.aabb_only = mc.aabb_only;
  d.levels.count = static_cast<int>(std::min<std::size_t>(mc.levels.size(), hd::kMidphaseMaxLevels));
  for (int i = 0; i < d.levels.count; ++i) d.levels.levels[i] = mc.levels[static_cast<std::size_t>(i)];
  d.level_steps = d.levels.aabb_only ? 0 : d.levels.count;

  // Shapes: every octree packed once.
  std::vector<gpu::DeviceShape> shapes;
  std::vector<Vec3> vertices;
  std::vector<MeshOctreeCell> cells;
  std::vector<std::uint32_t> level_offsets;
  std::vector<Aabb> blocks;
  for (const Shape& s : m.shapes) {
    gpu::DeviceShape ds;
    ds.bounds = s.local;
    if (s.octree) {
      const MeshOctree& t = *s.octree;
      ds.is_mesh = 1;
      ds.depth = t.depth;
      ds.bounds = t.bounds;
      ds.vertex_offset = static_cast<std::uint32_t>(vertices.size());
      ds.vertex_count = static_cast<std::uint32_t>(t.vertices.size());
      ds.cell_offset = static_cast<std::uint32_t>(cells.size());
      ds.level_offset_offset = static_cast<std::uint32_t>(level_offsets.size());
      ds.block_offset = static_cast<std::uint32_t>(blocks.size());
      const std::vector<Aabb> own = vertex_block_boxes(t.vertices);
      blocks.insert(blocks.end(), own.begin(), own.end());
      vertices.insert(vertices.end(), t.vertices.begin(), t.vertices.end());
      cells.insert(cells.end(), t.cells.begin(), t.cells.end());
      level_offsets.insert(level_offsets.end(), t.level_offset.begin(), t.level_offset.end());
    }
    shapes.push_back(ds);
  }
  d.shape_count = static_cast<std::uint32_t>(shapes.size());
  upload(d.shapes, shapes, d.stream);
  upload(d.vertices, vertices, d.stream);
  upload(d.cells, cells, d.stream);
  upload(d.level_offsets, level_offsets, d.stream);
  upload(d.blocks, blocks, d.stream);
  upload(d.theta, m.theta_shape, d.stream);

  // Bodies.
  std::vector<Aabb> local(n);
  std::vector<std::uint32_t> shape(n);
  for (std::size_t i = 0; i < n; ++i) {
    local[i] = m.local_box(i);
    shape[i] = m.bodies[i].shape;
  }
  upload(d.local, local, d.stream);
  upload(d.shape, shape, d.stream);
  upload(d.x, m.initial.x, d.stream);
  upload(d.v, m.initial.v, d.stream);
  upload(d.w, m.initial.w, d.stream);
  d.aabb.reset(n);
  upload(d.x_saved, m.initial.x, d.stream);  // == x at a step's start (the fused front reads them)
  upload(d.v_saved, m.initial.v, d.stream);
  d.stats.reset(1);
  d.metric_partials.reset(gpu::kMetricsBlocks);
  // First guesses; a step that needs more grows them and runs again.
  d.pair_cap = static_cast<std::size_t>(gpu::footprint::initial_pair_capacity(n));
  d.list_cap = static_cast<std::size_t>(gpu::footprint::initial_list_capacity(n));
  d.static_static = static_static_pairs(m);
  d.launched(gpu::launch_aabbs(d.bodies(), d.stream), "aabbs");
  check(cudaStreamSynchronize(d.stream), "cudaStreamSynchronize");
  state_ = m.initial;
  state_frame_ = 0;
}

CudaWorld::~CudaWorld() = default;

std::string CudaWorld::device() const { return impl_->device; }

std::string CudaWorld::broadphase_name() const { return impl_->broadphase; }

std::string CudaWorld::step_path() const {
  const Impl& d = *impl_;
  if (d.small) return "small";
  return d.use_graph && !d.sync_each_launch ? "graph" : "launches";
}

bool CudaWorld::has_stage(Stage s) const {
  (void)s;
  return !impl_->small;
}

std::string CudaWorld::small_profile() const {
  const Impl& d = *impl_;
  if (!d.small || !d.small_profile || d.profile_steps == 0) return "";
  const double k = 1e-3 / static_cast<double>(d.profile_steps);  // ns sums -> mean us
  std::string out = fmt::format("fused small step, mean over {} steps (us):", d.profile_steps);
  for (int i = 1; i < gpu::kSmallProfileSlots; ++i)
    out += fmt::format(" {} {:.2f};", gpu::kSmallProfilePhases[i], d.profile_ns[i] * k);
  out += fmt::format(" kernel (first to last stamp) {:.2f}; host launch call to completion seen {:.2f}; "
                     "launch + wake-up (host - kernel) {:.2f}; wait {}",
                     d.profile_kernel_ns * k, d.profile_ns[0] * k, (d.profile_ns[0] - d.profile_kernel_ns) * k,
                     d.small_poll && d.small_dev ? "poll" : "sync");
  return out;
}

std::string CudaWorld::notes() const {
  const Impl& d = *impl_;
  if (!d.small) return "";
  return fmt::format(
      "each step is one fused cooperative kernel ({} bodies, small-scene path up to {} with stage times off; "
      "stage_times=true turns it off){}: its broadphase is the all-pairs test whatever the broadphase named ('{}'; the same pairs), so "
      "'broadphase candidates' is n(n-1)/2, and its stages are not timed",
      d.n, kCudaSmallStepMaxBodies,
      d.persistent ? ", run by a resident kernel that steps on request" : "",
      d.broadphase);
}

bool CudaWorld::persistent() const { return impl_->persistent; }

void CudaWorld::set_persistent(bool on) {
  Impl& d = *impl_;
  if (!on) d.stop_resident();
  d.persistent = on && d.resident_possible;
}

std::uint64_t CudaWorld::resident_launches() const { return impl_->resident_launches; }

std::uint64_t CudaWorld::device_bytes() const {
  std::uint64_t total = 0;
  for (const BufferBase* b : impl_->all_buffers()) total += b->bytes();
  if (impl_->bp) total += impl_->bp->device_bytes();
  return total;
}

void CudaWorld::reset_capacities(std::size_t capacity) {
  if (capacity < 1) capacity = 1;
  Impl& d = *impl_;
  d.stop_resident();  // before any cudaFree
  d.drop_graph();
  for (BufferBase* b : d.scratch_buffers()) b->reset(capacity);
  d.pair_cap = capacity;
  d.list_cap = capacity;
  d.prepared = false;
}

void CudaWorld::set_state(const BodyState& s) {
  Impl& d = *impl_;
  if (s.x.size() != d.n || s.v.size() != d.n || s.w.size() != d.n)
    throw InputError(fmt::format("CudaWorld::set_state: expected {} bodies, got x {}, v {}, w {}", d.n, s.x.size(),
                                 s.v.size(), s.w.size()));
  // A resident kernel waits between steps and touches no state then: the copies (on the
  // engine's stream, not the kernel's) need not end it.
  upload(d.x, s.x, d.stream, false);
  upload(d.v, s.v, d.stream, false);
  upload(d.w, s.w, d.stream, false);
  upload(d.x_saved, s.x, d.stream, false);  // == x at a step's start (the fused front reads them)
  upload(d.v_saved, s.v, d.stream, false);
  state_ = s;
  state_frame_ = frame_;
}

const BodyState& CudaWorld::state() const {
  if (state_frame_ != frame_) {
    Impl& d = *impl_;
    download(state_.x, d.x, d.n, d.stream);
    download(state_.v, d.v, d.n, d.stream);
    download(state_.w, d.w, d.n, d.stream);
    state_frame_ = frame_;
  }
  return state_;
}

const std::vector<ContactRecord>& CudaWorld::contacts() const {
  static const std::vector<ContactRecord> kNone;
  return recording_ ? record_.contacts : kNone;
}

const FrameMetrics& CudaWorld::step() {
  const auto t_step = Clock::now();
  Impl& d = *impl_;
  const Scene& scene = model_->scene;
  const std::uint32_t n = d.n;
  FrameMetrics m;
  m.frame = frame_ + 1;
  m.time = static_cast<double>(m.frame) * static_cast<double>(scene.dt);
  if (recording_) {
    const BodyState& s = state();
    record_.frame = m.frame;
    record_.x_pre = s.x;
    record_.v_pre = s.v;
  }
  // The step, run again from the saved state with larger buffers while a list overflows.
  d.run_step(scene, recording_);
  while (d.grow_if_needed()) {
    d.restore_state();
    d.run_step(scene, recording_);
  }
  const gpu::MetricsResult r = d.host->metrics;
  const unsigned long long* counters = d.host->counters;
  const std::uint32_t np = d.host->counts[0];
  const bool flat = !d.bp || d.small;  // the small path's broadphase is the all-pairs test
  m.aabb_pairs = np;
  if (flat) m.cell_candidates = static_cast<std::uint64_t>(n) * (n == 0 ? 0 : n - 1) / 2;
  // Static bodies never move, so the static-static overlaps are the constant counted at
  // construction (World::step counts the same pairs one by one).
  m.dynamic_pairs = np >= d.static_static ? np - d.static_static : 0;

  // The state on the device is now this frame's; the host copy is stale.
  state_frame_ = -1;
  if (r.first_non_finite < n) {
    const std::uint32_t i = r.first_non_finite;
    Vec3 x, v;
    // The polled wait may return before the kernel has exited; the default stream's copies
    // below do not wait for the engine's (non-blocking) stream.
    check(cudaStreamSynchronize(d.stream), "cudaStreamSynchronize (non-finite body)");
    check(cudaMemcpy(&x, d.x.get() + i, sizeof(Vec3), cudaMemcpyDeviceToHost), "cudaMemcpy x");
    check(cudaMemcpy(&v, d.v.get() + i, sizeof(Vec3), cudaMemcpyDeviceToHost), "cudaMemcpy v");
    // The message World::step gives.
    throw RuntimeError(fmt::format(
        "frame {}: body {} (group '{}') has a non-finite {} ({}, {}, {}); the run stops here", m.frame, i,
        model_->bodies[i].group, is_finite(x) ? "velocity" : "position", is_finite(x) ? v.x : x.x,
        is_finite(x) ? v.y : x.y, is_finite(x) ? v.z : x.z));
  }
  m.box_tests = counters[0];
  m.box_pairs = counters[1];
  m.vertex_tests = counters[2];
  if (!flat) m.cell_candidates = counters[3];
  m.contacts = r.contacts;
  if (r.contacts > 0) {
    m.penetration_mean = r.pen_sum / static_cast<double>(r.contacts);
    m.penetration_max = r.pen_max;
    m.penetration_share_above_slop = static_cast<double>(r.pen_above) / static_cast<double>(r.contacts);
  }
  m.kinetic_energy = r.kinetic_energy;
  m.momentum = {r.momentum[0], r.momentum[1], r.momentum[2]};
  for (int s = 0; d.stage_times && !d.small && s < static_cast<int>(Stage::Count); ++s) {
    float ms = 0.0f;
    check(cudaEventElapsedTime(&ms, d.events[s], d.events[s + 1]), "cudaEventElapsedTime");
    m.stage_ms[static_cast<std::size_t>(s)] = static_cast<double>(ms);
  }
  m.memory_bytes = device_bytes();

  frame_ = m.frame;
  if (recording_) {
    download(record_.aabbs, d.aabb, n, d.stream);
    download(record_.pairs, d.pairs, np, d.stream);
    std::vector<std::uint8_t> confirmed;
    download(confirmed, d.confirmed, np, d.stream);
    std::vector<gpu::DeviceContact> recs;
    download(recs, d.records, np, d.stream);
    record_.confirmed.clear();
    record_.contacts.clear();
    for (std::size_t k = 0; k < np; ++k) {
      if (!confirmed[k]) continue;
      const Pair p = record_.pairs[k];
      record_.confirmed.push_back(p);
      const gpu::DeviceContact& c = recs[k];
      if (!c.hit) continue;
      ContactRecord rec;
      rec.pair = p;
      rec.normal = c.normal;
      rec.depth = c.depth;
      rec.axis = c.axis;
      rec.v_a = c.v_a;
      rec.v_b = c.v_b;
      rec.dx_a = c.dx_a;
      rec.dx_b = c.dx_b;
      rec.jn = c.jn;
      rec.jt = c.jt;
      rec.dv_a = c.dv_a;
      rec.dv_b = c.dv_b;
      record_.contacts.push_back(rec);
    }
    const BodyState& s = state();
    record_.x_post = s.x;
    record_.v_post = s.v;
  }
  m.step_ms = ms_since(t_step);
  metrics_ = m;
  return metrics_;
}

}  // namespace octocd
