#pragma once
/// \file cuda_impl.hpp
/// CudaWorld::Impl: the CUDA engine's device state (buffers, stream, graphs, the resident
/// kernel's control words) and the host side of its step, split by job over
///   cuda_world.cpp      construction, CudaWorld's methods, one step's dispatch and metrics;
///   device_status.cpp   the device's description and the free-memory check;
///   step_stages.cpp     the per-stage path: buffer sizes, descriptors, the stages in
///                       World::step's order, the CUDA graph, regrow and rerun;
///   small_step_host.cpp the fused small step (small_step.cu) from the host: its
///                       descriptor, the launch per step and the resident kernel;
///   stage_times.cpp     the stage times: which steps are timed, CUDA events on the
///                       per-stage path, %globaltimer stamps of the fused kernel.
/// Plain C++ over the CUDA runtime API; the kernels are behind kernels.hpp. Internal to gpu/.

#include <array>
#include <chrono>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include <cuda_runtime_api.h>

#include "device_broadphase.hpp"
#include "device_buffer.hpp"
#include "kernels.hpp"
#include "scanned_counts.hpp"
#include "octocd/cuda_world.hpp"
#include "record_ring.hpp"

namespace octocd {

namespace gpu {

using Clock = std::chrono::steady_clock;

/// Milliseconds since `t0`.
inline double ms_since(Clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
}

/// The reason no device is usable, or "" when one is (device_status.cpp).
std::string no_device_reason();
/// "NAME (device D, sm_XY, G GiB)" of the current device; throws RuntimeError when a CUDA call fails.
std::string describe_current_device();
/// Throws RuntimeError when the current device has fewer than `needed` bytes free
/// (cudaMemGetInfo, or `free_bytes` of it where given: a test's seam), or more than
/// `limit` (CudaSettings::memory_limit_bytes, 0: none), naming the scene, the bytes needed
/// and free, and the device's total (device_status.cpp).
void check_free_memory(const Model& m, const std::string& broadphase, std::uint64_t needed, std::uint64_t limit,
                       const std::function<std::uint64_t(std::uint64_t)>& free_bytes);

/// CUDA events around the stages: event s before stage s, event Stage::Count after the last.
constexpr int kStageEvents = static_cast<int>(Stage::Count) + 1;

/// Blocks per multiprocessor of the fused small step (at most what fits, 2 on sm_90 at 119
/// registers per thread): one gives 8 warps per SM for every phase (1056 on an H100) while
/// each grid-wide barrier waits for as few blocks as possible.
constexpr int kSmallStepBlocksPerSm = 1;

/// Pairs up to which the fused small step runs its response passes, clamp and metrics in
/// one block (SmallStepDesc::one_block_pairs).
constexpr std::uint32_t kSmallOneBlockPairs = 512;

/// The resident kernel ends itself after this long without a request (unit: us; the next
/// step launches it again).
constexpr long kResidentIdleUs = 2000;

/// Bodies up to which the fused small step integrates, counts and fills without a
/// grid-wide barrier (SmallStepDesc::front_bodies; at most gpu::kSmallFrontMaxBodies).
constexpr std::uint32_t kSmallFrontBodies = 64;

/// Bodies up to which the fused small step integrates into every block's shared memory and
/// runs its broadphase from there (SmallStepDesc::shared_boxes_bodies; at most
/// gpu::kSmallSharedBoxesMaxBodies).
constexpr std::uint32_t kSmallSharedBoxesBodies = 1024;
static_assert(kSmallFrontBodies <= kSmallFrontMaxBodies && kSmallSharedBoxesBodies <= kSmallSharedBoxesMaxBodies,
              "the fused front's and the shared boxes' bodies fit the block's shared memory (FrontShared)");

}  // namespace gpu

struct CudaWorld::Impl {
  cudaStream_t stream = nullptr;
  bool sync_each_launch = false;  // CudaSettings::sync_each_launch
  bool use_graph = true;          // CudaSettings::graph
  bool capturing = false;
  std::string device;
  std::string broadphase;
  std::unique_ptr<gpu::DeviceBroadPhase> bp;  // null for `flat`
  std::uint32_t n = 0;
  std::uint32_t shape_count = 0;
  hd::LevelList levels;
  int level_steps = 0;     // midphase steps (0: aabb-only, or no levels)
  bool any_mesh = false;   // some shape is a mesh: a pair may need the level steps
  unsigned warp_grid = 1;  // blocks of the warp-per-item midphase kernels
  int mid_early_exit = 1;  // CudaSettings::midphase_early_exit (MidListDesc::early_exit)
  std::uint32_t mid_fuse_min_items = 0;  // CudaTestHooks::fuse_min_items (MidListDesc)
  std::uint32_t mid_witness_pass_min_pairs = 0;  // CudaTestHooks::witness_pass_min_pairs

  // ---- stage times (stage_times.cpp) ---------------------------------------------------
  bool stage_times = true;        // CudaSettings::stage_times
  long stage_time_every = 64;     // CudaSettings::stage_time_every
  bool timed = false;             // the step under way is timed
  cudaEvent_t events[gpu::kStageEvents] = {};
  /// The last timed step's stage times (ms): what every untimed step reports.
  std::array<double, static_cast<std::size_t>(Stage::Count)> held_ms{};
  std::uint64_t timed_steps = 0;

  // ---- the fused small step (small_step_host.cpp) --------------------------------------
  bool small_lean = false;  // the small step's lean kernel (gpu::small_lean_kernel), fixed at construction
  double leaf_vertices = 0.0;  // largest_mean_leaf_vertices of the model
  bool small = false;       // the fused small-scene step (small_step.cu), fixed at construction
  unsigned small_grid = 1;  // its blocks (co-resident)
  gpu::StepStats* host_dev = nullptr;  // `host` as the device addresses it (mapped), or null
  // Pinned: [0] the last step number the kernel wrote, [1 ..] the phase stamps.
  unsigned long long* small_host = nullptr;
  unsigned long long* small_dev = nullptr;  // the same, mapped (null: no polling, no stamps)
  unsigned long long sequence = 0;
  bool small_profile = false;  // CudaSettings::small_profile
  double profile_ns[gpu::kSmallProfileSlots] = {};  // sums: slot p - slot p-1; [0]: host launch to seen done
  double profile_kernel_ns = 0.0;                   // sum of slot 9 - slot 0
  std::uint64_t profile_steps = 0;

  // The resident small step (set_persistent): its own stream, so that the copies and waits
  // on `stream` never queue behind it.
  bool resident_possible = false;  // small path, mapped memory, the kernel fits
  bool persistent = false;         // run steps through the resident kernel
  bool resident_alive = false;     // launched, and not yet seen to have exited
  bool resident_hung = false;      // an exit request went unanswered: nothing may be freed
  bool resident_stall = false;     // TestHooks::resident_ignores_requests
  unsigned resident_grid = 1;
  unsigned long long resident_idle_ns = 0;
  long resident_timeout_ms = 60000;  // CudaSettings::resident_timeout_ms
  unsigned long long epoch = 0;      // launches so far; the last one's number
  std::uint64_t resident_launches = 0;
  std::uint64_t resident_requests = 0;  // step requests written (a batch counts once)
  cudaStream_t resident_stream = nullptr;
  // Pinned: [0] the request (host writes), [8] the exit mark (kernel writes); apart, so the
  // two sides write different cache lines.
  static constexpr int kRequestWord = 0;
  static constexpr int kExitedWord = 8;
  unsigned long long* resident_host = nullptr;
  unsigned long long* resident_dev = nullptr;  // the same, mapped
  // Pinned: the resident kernel's statistics, gpu::kResidentStatsSlots of them (slot:
  // sequence % slots), and the same, mapped.
  gpu::StepStats* ring_host = nullptr;
  gpu::StepStats* ring_dev = nullptr;
  // Running ahead (Engine::plan_steps): the step() calls promised (the one under way
  // included), and the last sequence an earlier request's batch runs with no other request
  // (ahead_last > sequence: the device is ahead of the host's frame).
  std::int64_t promised = 0;
  unsigned long long ahead_last = 0;
  gpu::DeviceBuffer<unsigned long long> resident_control{"resident step control"};

  // ---- recorded batches (cuda_world.cpp; CudaSettings::record_batch, gpu::RecordRing) ----
  long record_batch = 1;  // CudaSettings::record_batch
  std::uint64_t ring_max_bytes = gpu::kRecordRingMaxBytes;  // TestHooks::record_ring_max_bytes
  std::uint32_t ring_slots = 0;  // slots of the ring now allocated (0: none)
  std::uint32_t ring_pairs = 0;  // pairs a slot holds
  gpu::DeviceBuffer<Vec3> ring_x_pre{"record ring: positions before the step"};
  gpu::DeviceBuffer<Vec3> ring_v_pre{"record ring: velocities before the step"};
  gpu::DeviceBuffer<Vec3> ring_x_post{"record ring: positions after the step"};
  gpu::DeviceBuffer<Vec3> ring_v_post{"record ring: velocities after the step"};
  gpu::DeviceBuffer<Aabb> ring_aabb{"record ring: world AABBs"};
  gpu::DeviceBuffer<Pair> ring_pair_list{"record ring: candidate pairs"};
  gpu::DeviceBuffer<std::uint8_t> ring_confirmed{"record ring: confirmed flags"};
  gpu::DeviceBuffer<gpu::DeviceContact> ring_records{"record ring: contact records"};
  // The ring's pinned host copy (the same layout), carved from one allocation.
  unsigned char* ring_copy = nullptr;
  Vec3* copy_x_pre = nullptr;
  Vec3* copy_v_pre = nullptr;
  Vec3* copy_x_post = nullptr;
  Vec3* copy_v_post = nullptr;
  Aabb* copy_aabb = nullptr;
  Pair* copy_pairs = nullptr;
  std::uint8_t* copy_confirmed = nullptr;
  gpu::DeviceContact* copy_records = nullptr;
  gpu::RecordWindow window;  // the steps the host copy holds, and the batch's first sequence
  std::vector<std::size_t> window_at;  // per slot of the batch: where its pairs start in the pool
  long long served_slot = -1;  // the last step's slot in the host copy (-1: not from the ring)
  bool recorded_batch = false;  // the request under way records with the ring
  bool resident_ring = false;   // the resident kernel was launched with the ring
  unsigned long long prefetched_first = 0;  // the first step of a batch requested by prefetch_records (0: none)
  static constexpr int kStoppedWord = 9;  // resident_host[9]: ResidentDesc::stopped (kernel writes)
  /// Whether recorded steps run in batches through the ring: the resident kernel, and
  /// record_batch > 1.
  bool batching_records() const { return persistent && record_batch > 1; }
  /// The ring's buffers (for device_bytes, and abandoned with the others after a hang).
  std::vector<gpu::BufferBase*> ring_buffers();
  /// Sizes the ring (record_batch slots, pairs per slot: gpu::record_ring_pairs) and its
  /// pinned host copy; no resident kernel may run (a change frees memory).
  void ensure_record_ring();
  /// The ring as the resident kernel's descriptor gets it (slots 0 when not batching).
  gpu::RecordRing ring_desc();
  /// Makes the host copy hold step `sequence`'s record: waits for the batch's steps up to
  /// window.copy_last (or the step that ended it early) and copies their slots back in one
  /// go. False when the step's record is not in the ring (its pairs did not fit a slot: read
  /// it from the live buffers).
  bool fetch_records(std::uint32_t pairs_found);
  /// After the host copy took a whole batch (its steps q .. last, q the step under way):
  /// requests the next batch of recorded steps at once, when the promise has steps left, so
  /// that the device runs it while the host takes this one (the statistics slots bound it:
  /// RecordWindow::next_batch_room; it ends at the next timed step, and is not asked for
  /// when both its last step and `last` are stamped: one set of stamps).
  void prefetch_records(unsigned long long q, unsigned long long last);

  // ---- buffers (step_stages.cpp sizes them) ---------------------------------------------
  // Capacities of the variable-size buffers (entries); prepare() sizes the buffers.
  std::size_t pair_cap = 1;
  std::size_t list_cap = 1;
  /// Pairs the response's contact index covers (min(index_cap, pair_cap)): grown like
  /// pair_cap when a step found more pairs (the step runs again).
  std::size_t index_cap = 1;
  bool prepared = false;
  std::uint64_t static_static = 0;  // static_static_pairs(model): constant over the run

  // Bodies (fixed size n).
  gpu::DeviceBuffer<Vec3> x{"body positions"};
  gpu::DeviceBuffer<Vec3> v{"body velocities"};
  gpu::DeviceBuffer<Vec3> x_saved{"body positions before the step"};
  gpu::DeviceBuffer<Vec3> v_saved{"body velocities before the step"};
  gpu::DeviceBuffer<float> w{"body inverse masses"};
  gpu::DeviceBuffer<Aabb> local{"body local boxes"};
  gpu::DeviceBuffer<std::uint32_t> shape{"body shapes"};
  gpu::DeviceBuffer<Aabb> aabb{"world AABBs"};
  // Recording only (CudaWorld::set_recording): the state at the last step's start.
  gpu::DeviceBuffer<Vec3> x_pre{"recorded positions before the step"};
  gpu::DeviceBuffer<Vec3> v_pre{"recorded velocities before the step"};
  // Shapes, packed once.
  gpu::DeviceBuffer<gpu::DeviceShape> shapes{"shapes"};
  gpu::DeviceBuffer<Vec3> vertices{"octree vertices"};
  gpu::DeviceBuffer<MeshOctreeCell> cells{"octree cells"};
  gpu::DeviceBuffer<std::uint32_t> level_offsets{"octree level offsets"};
  gpu::DeviceBuffer<Aabb> blocks{"octree vertex block boxes"};
  gpu::DeviceBuffer<float> theta{"per-shape theta"};
  gpu::DeviceBuffer<gpu::StepStats> stats{"step statistics"};
  gpu::DeviceBuffer<gpu::MetricsResult> metric_partials{"metrics partial sums"};
  // Variable size (pair_cap, list_cap), grown on overflow; reset_capacities shrinks them.
  // Broadphase `flat` (n + 1 each): per body i the count and offset of its pairs (i, j), j > i.
  gpu::ScannedCounts bp_counts{"broadphase counts", "broadphase offsets"};
  gpu::DeviceBuffer<unsigned long long> pair_keys{"pair keys"};
  gpu::DeviceBuffer<unsigned long long> pair_keys_sorted{"sorted pair keys"};
  gpu::DeviceBuffer<Pair> pairs{"candidate pairs"};
  gpu::DeviceBuffer<std::uint8_t> confirmed{"confirmed flags"};
  gpu::DeviceBuffer<gpu::MidItem> items_a{"midphase work list A"};
  gpu::DeviceBuffer<gpu::MidItem> items_b{"midphase work list B"};
  // The per-pair corrections: the contact terms' outputs, the apply's inputs (gpu::TermsDesc,
  // gpu::ApplyDesc; step_stages.cpp's set_corrections).
  struct Corrections {
    gpu::DeviceBuffer<std::uint8_t> hit{"contact hit flags"};
    gpu::DeviceBuffer<Vec3> dx_a{"contact dx_a"};
    gpu::DeviceBuffer<Vec3> dx_b{"contact dx_b"};
    gpu::DeviceBuffer<Vec3> dv_a{"contact dv_a"};
    gpu::DeviceBuffer<Vec3> dv_b{"contact dv_b"};
  } corrections;
  gpu::DeviceBuffer<float> depth0{"contact depths"};
  gpu::DeviceBuffer<gpu::DeviceContact> records{"contact records"};
  // The per-stage path's contact index (response.cu, gpu::IndexDesc).
  gpu::DeviceBuffer<unsigned long long> index_offsets{"contact index offsets"};
  gpu::DeviceBuffer<std::uint32_t> index_rank{"contact index ranks"};
  gpu::DeviceBuffer<std::uint32_t> index_entries{"contact index entries"};
  gpu::DeviceBuffer<std::uint32_t> index_long{"contact index long segments"};
  // The midphase's witness cache (gpu::WitnessDesc): this step's witnesses, the last
  // step's keys and witnesses, per body the start of its run of keys, their count.
  gpu::DeviceBuffer<unsigned long long> witness{"midphase witnesses"};
  gpu::DeviceBuffer<unsigned long long> prev_keys{"midphase kept pair keys"};
  gpu::DeviceBuffer<unsigned long long> prev_witness{"midphase kept witnesses"};
  gpu::DeviceBuffer<std::uint32_t> prev_begin{"midphase kept key runs"};
  gpu::DeviceBuffer<std::uint32_t> prev_count{"midphase kept key count"};
  gpu::DeviceBuffer<unsigned long long> leaf_items{"midphase leaf items"};  // MidListDesc::leaf_items
  // The small path's in-lists, per body their counts and offsets (n + 1 each; small path only).
  gpu::DeviceBuffer<std::uint32_t> in_list{"small-step in-lists"};
  gpu::ScannedCounts in_counts{"small-step column counts", "small-step in-list offsets"};
  gpu::DeviceBuffer<unsigned char> temp{"CUB temporary storage"};

  gpu::StepStats* host = nullptr;  // pinned

  // Pinned host staging of the small path's copy-backs, allocated once at construction (no
  // pinned allocation or free while a resident kernel runs: cudaFreeHost waits for it): the
  // state (x, v, w of the n bodies; state()) and a recorded step's pairs, confirmed flags
  // and contact records up to kStagedRecordPairs pairs (step(); more: pageable copies).
  // Each copy-back is then its copies queued on the stream and one synchronisation.
  static constexpr std::size_t kStagedRecordPairs = 8192;
  unsigned char* staging = nullptr;
  Vec3* staged_x = nullptr;
  Vec3* staged_v = nullptr;
  float* staged_w = nullptr;
  Pair* staged_pairs = nullptr;
  std::uint8_t* staged_confirmed = nullptr;
  gpu::DeviceContact* staged_records = nullptr;
  /// Allocates `staging` for n bodies and carves the arrays above from it.
  void allocate_staging();
  // The per-stage step captured per broadphase plan (DeviceBroadPhase::plan()), twice:
  // plain (untimed steps) and with the stage events.
  cudaGraph_t graph[gpu::kBroadPhasePlans] = {};
  cudaGraphExec_t graph_exec[gpu::kBroadPhasePlans] = {};
  cudaGraph_t timed_graph[gpu::kBroadPhasePlans] = {};
  cudaGraphExec_t timed_graph_exec[gpu::kBroadPhasePlans] = {};

  ~Impl();

  // ---- cuda_world.cpp -------------------------------------------------------------------
  /// Runs one step on the path fixed at construction and waits for it.
  void run_step(const Scene& scene, bool recording);

  // ---- step_stages.cpp: the per-stage path ---------------------------------------------
  void drop_graph();
  std::vector<gpu::BufferBase*> all_buffers();
  std::vector<gpu::BufferBase*> scratch_buffers();
  /// Checks a launch; with sync_each_launch also waits for it and checks its execution.
  void launched(cudaError_t e, const char* kernel);
  unsigned long long* counters() { return stats.get()->counters; }
  std::uint32_t* counts() { return stats.get()->counts; }
  std::uint32_t pcap() const { return static_cast<std::uint32_t>(pair_cap); }
  std::uint32_t lcap() const { return static_cast<std::uint32_t>(list_cap); }
  std::uint32_t icap() const { return static_cast<std::uint32_t>(std::min(index_cap, pair_cap)); }
  /// Bodies the contact index's long-segment list can hold: icap() / (kIndexShortSegment + 1) + 1.
  std::size_t long_cap() const { return pair_cap / (gpu::kIndexShortSegment + 1) + 1; }
  /// The contact index's descriptor (IndexDesc) over the first icap() pairs.
  gpu::IndexDesc index_desc();
  /// Blocks of the grid-stride kernels over the live pairs (decide, contact terms): two
  /// per warp_grid block (8 per SM), fewer when the pair buffer is smaller. The live count
  /// is known on the device only, and is often far below pair_cap.
  /// Whether the midphase keeps witnesses (gpu::WitnessDesc): the per-stage path with the
  /// early exit, on a model with meshes and levels (the fused small step keeps none); only
  /// then are the witness buffers allocated.
  bool witnesses() const { return mid_early_exit != 0 && any_mesh && level_steps > 0 && !small; }
  unsigned pair_grid() const { return std::min(gpu::grid_for(pair_cap), 2 * warp_grid); }
  gpu::BodiesDesc bodies();
  gpu::ShapesDesc shapes_desc();
  /// The midphase lists' common fields (in / out are set per step): pairs from `keys`.
  gpu::MidListDesc mid_desc(const unsigned long long* keys);
  /// contact_terms' descriptor (depth0 and records unset: per pass).
  gpu::TermsDesc terms_desc(const ContactParams& params);
  /// apply_sums' descriptor over the sorted contact index.
  gpu::ApplyDesc apply_desc();
  gpu::MetricsDesc metrics_desc(const ContactParams& params);
  /// Sizes every buffer for the current capacities (outside any capture); a change drops
  /// the captured graphs.
  void prepare();
  /// Broadphase `flat` (design.md section 5.1): count, exclusive scan over n + 1, fill the keys that fit.
  void flat_broadphase();
  /// Enqueues one whole step on the stream: no allocation, no host synchronisation (it
  /// may be captured into a graph). `recording`: the first pass writes contact records;
  /// `timed`: the stage events are recorded around the stages.
  void enqueue_step(const Scene& scene, bool recording, bool with_events);
  /// The per-stage step: replayed from the plain or the timed graph when allowed (not
  /// recording, graphs on), else launch by launch; then waits for it.
  void run_stages(const Scene& scene, bool recording);
  /// True when a list overflowed its capacity; grows the capacities then (the state must
  /// be restored and the step run again).
  bool grow_if_needed();
  /// After a step: true when it must run again (restored first): the broadphase's pairs
  /// did not hold (DeviceBroadPhase::settle; a regrown broadphase drops the graphs), or a
  /// list overflowed (grow_if_needed).
  bool rerun_needed();
  void restore_state();

  // ---- small_step_host.cpp: the fused small step ---------------------------------------
  /// The fused small step's descriptor (small_step.cu): the same buffers as the per-stage
  /// path; the in-lists live in in_list, their counts and offsets in in_counts.
  gpu::SmallStepDesc small_desc(const Scene& scene, bool recording);
  /// One fused step (resident or a launch), its statistics through mapped memory.
  void run_small(const Scene& scene, bool recording);
  /// Spins until the fused step's kernel has written this step's number.
  void wait_small_step();
  unsigned long long exited_mark() const;
  unsigned long long stopped_mark() const;  // resident_host[kStoppedWord]
  unsigned long long done_mark() const;
  void write_request(unsigned long long value);
  /// Launches the resident kernel; `ring`: with the record ring (ensure_record_ring).
  void launch_resident(const Scene& scene, bool ring);
  /// The steps after this one that its request asks for (ResidentDesc): at most
  /// kResidentAheadMax, promised - 1, and the steps to the next timed one (a batch ends at
  /// its timed step, the one its request stamps); 0 under small_profile.
  unsigned long long batch_extra() const;
  /// Waits for this step from the resident kernel (asking for it, and for the steps ahead
  /// the promise allows, unless an earlier batch covers it) and copies its statistics to `host`.
  void resident_step(const Scene& scene, bool recording);
  /// Throws RuntimeError naming `call` while the device has run, or runs, steps ahead of
  /// the host's frame (ahead_last > sequence): state, recording and buffers are then not
  /// the frame's.
  void refuse_ahead(const char* call) const;
  /// Ends the resident kernel (when one runs) and waits for it: before anything frees or
  /// reallocates device memory, and in the destructor. Throws RuntimeError (and marks the
  /// engine hung: its memory is then never freed) when the kernel does not end within
  /// resident_timeout_ms.
  void stop_resident();

  // ---- stage_times.cpp -----------------------------------------------------------------
  /// Decides whether step `frame` (1-based) is timed: frames 1, 1 + k, 1 + 2k, ... with
  /// k = stage_time_every, while stage times are on.
  void begin_step(std::int64_t frame);
  /// Whether step `frame` is timed (begin_step's rule).
  bool timed_frame(std::int64_t frame) const;
  std::int64_t step_frame = 0;  // the frame begin_step was given
  /// Records stage event `i` on the stream (only while enqueueing a timed step).
  void record_event(int i, bool with_events);
  /// The phase stamps of the fused kernel for this step, or null (untimed, no profile).
  unsigned long long* stamps() const;
  /// After the step: the timed step's stage times into held_ms (events, or the fused
  /// kernel's stamps), then held_ms into `stage_ms`.
  void end_step(std::array<double, static_cast<std::size_t>(Stage::Count)>& stage_ms);
  /// Whether stage `s` has a time on this engine's path.
  bool has_stage(Stage s) const;
  /// The summary's line on how the stage times were taken.
  std::string stage_times_note() const;
};

}  // namespace octocd
