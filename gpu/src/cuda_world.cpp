// The CUDA engine (design.md section 11): construction (the device, its memory check, the shapes'
// packed octrees and the bodies uploaded once), CudaWorld's methods, and one step: the path
// fixed at construction (step_stages.cpp or small_step_host.cpp), a rerun with larger buffers
// while a list overflows, then the metrics, stage times (stage_times.cpp) and recording read
// back. This file holds no float formula of the step.
#include "octocd/cuda_world.hpp"

#include <algorithm>
#include <cstddef>
#include <utility>

#include <fmt/format.h>

#include "cuda_impl.hpp"
#include "device_footprint.hpp"
#include "octocd/error.hpp"
#include "octocd/vertex_blocks.hpp"

namespace octocd {

using gpu::BufferBase;
using gpu::check;
using gpu::Clock;
using gpu::download;
using gpu::ms_since;
using gpu::upload;

CudaWorld::Impl::~Impl() {
  try {
    stop_resident();
  } catch (const std::exception&) {  // a hung kernel: resident_hung is set
  }
  if (resident_hung) {
    // cudaFree and cudaFreeHost would wait for the kernel forever: leave the memory to the
    // process's end (the driver reclaims it).
    for (BufferBase* b : all_buffers()) b->abandon();
    for (BufferBase* b : ring_buffers()) b->abandon();
    resident_control.abandon();
    (void)bp.release();
    return;
  }
  drop_graph();
  if (host) (void)cudaFreeHost(host);
  if (small_host) (void)cudaFreeHost(small_host);
  if (resident_host) (void)cudaFreeHost(resident_host);
  if (ring_host) (void)cudaFreeHost(ring_host);
  if (staging) (void)cudaFreeHost(staging);
  if (ring_copy) (void)cudaFreeHost(ring_copy);
  for (cudaEvent_t& e : events)
    if (e) (void)cudaEventDestroy(e);
  if (stream) (void)cudaStreamDestroy(stream);
  if (resident_stream) (void)cudaStreamDestroy(resident_stream);
}

void CudaWorld::Impl::allocate_staging() {
  const auto rounded = [](std::size_t bytes) { return (bytes + 63) / 64 * 64; };
  const std::size_t vec = rounded(sizeof(Vec3) * n), w_bytes = rounded(sizeof(float) * n);
  const std::size_t pair_bytes = rounded(sizeof(Pair) * kStagedRecordPairs);
  const std::size_t flag_bytes = rounded(sizeof(std::uint8_t) * kStagedRecordPairs);
  const std::size_t record_bytes = rounded(sizeof(gpu::DeviceContact) * kStagedRecordPairs);
  check(cudaMallocHost(reinterpret_cast<void**>(&staging), 2 * vec + w_bytes + pair_bytes + flag_bytes + record_bytes),
        "cudaMallocHost (state and record staging)");
  unsigned char* p = staging;
  const auto take = [&p](std::size_t bytes) {
    unsigned char* at = p;
    p += bytes;
    return at;
  };
  staged_x = reinterpret_cast<Vec3*>(take(vec));
  staged_v = reinterpret_cast<Vec3*>(take(vec));
  staged_w = reinterpret_cast<float*>(take(w_bytes));
  staged_pairs = reinterpret_cast<Pair*>(take(pair_bytes));
  staged_confirmed = take(flag_bytes);
  staged_records = reinterpret_cast<gpu::DeviceContact*>(take(record_bytes));
}

// ---- recorded batches (CudaSettings::record_batch) ----------------------------------------

std::vector<BufferBase*> CudaWorld::Impl::ring_buffers() {
  return {&ring_x_pre, &ring_v_pre, &ring_x_post, &ring_v_post, &ring_aabb, &ring_pair_list, &ring_confirmed,
          &ring_records};
}

void CudaWorld::Impl::ensure_record_ring() {
  const std::uint32_t slots = static_cast<std::uint32_t>(record_batch);
  constexpr std::uint64_t body_bytes = 4 * sizeof(Vec3) + sizeof(Aabb);
  constexpr std::uint64_t pair_bytes = sizeof(Pair) + sizeof(std::uint8_t) + sizeof(gpu::DeviceContact);
  const std::uint32_t pool = gpu::record_ring_pairs(pair_cap, slots, n, body_bytes, pair_bytes, ring_max_bytes);
  if (ring_copy && slots == ring_slots && pool == ring_pairs) return;
  if (ring_copy) (void)cudaFreeHost(ring_copy);  // no resident kernel runs (launch_resident)
  ring_copy = nullptr;
  ring_slots = 0;
  window.clear();
  const std::size_t states = static_cast<std::size_t>(slots) * n;
  for (gpu::DeviceBuffer<Vec3>* b : {&ring_x_pre, &ring_v_pre, &ring_x_post, &ring_v_post}) b->reset(states);
  ring_aabb.reset(states);
  ring_pair_list.reset(pool);
  ring_confirmed.reset(pool);
  ring_records.reset(pool);
  const auto rounded = [](std::size_t bytes) { return (bytes + 63) / 64 * 64; };
  const std::size_t vec = rounded(sizeof(Vec3) * states), box = rounded(sizeof(Aabb) * states);
  const std::size_t pair_b = rounded(sizeof(Pair) * pool), flag_b = rounded(pool),
                    rec_b = rounded(sizeof(gpu::DeviceContact) * pool);
  check(cudaMallocHost(reinterpret_cast<void**>(&ring_copy), 4 * vec + box + pair_b + flag_b + rec_b),
        "cudaMallocHost (record ring's host copy)");
  unsigned char* p = ring_copy;
  const auto take = [&p](std::size_t bytes) {
    unsigned char* at = p;
    p += bytes;
    return at;
  };
  copy_x_pre = reinterpret_cast<Vec3*>(take(vec));
  copy_v_pre = reinterpret_cast<Vec3*>(take(vec));
  copy_x_post = reinterpret_cast<Vec3*>(take(vec));
  copy_v_post = reinterpret_cast<Vec3*>(take(vec));
  copy_aabb = reinterpret_cast<Aabb*>(take(box));
  copy_pairs = reinterpret_cast<Pair*>(take(pair_b));
  copy_confirmed = take(flag_b);
  copy_records = reinterpret_cast<gpu::DeviceContact*>(take(rec_b));
  ring_slots = slots;
  ring_pairs = pool;
  window_at.assign(static_cast<std::size_t>(slots) + 1, 0);
}

gpu::RecordRing CudaWorld::Impl::ring_desc() {
  gpu::RecordRing r;
  r.x_pre = ring_x_pre.get();
  r.v_pre = ring_v_pre.get();
  r.x_post = ring_x_post.get();
  r.v_post = ring_v_post.get();
  r.aabb = ring_aabb.get();
  r.pairs = ring_pair_list.get();
  r.confirmed = ring_confirmed.get();
  r.records = ring_records.get();
  r.pair_capacity = ring_pairs;
  r.slots = ring_slots;
  return r;
}

bool CudaWorld::Impl::fetch_records(std::uint32_t pairs_found) {
  const unsigned long long q = sequence;
  if (window.holds(q)) return true;
  window.advance(q);  // the first step of a batch prefetch_records asked for
  if (ring_slots == 0 || q < window.base || pairs_found > ring_pairs) return false;
  unsigned long long last = window.copy_last(q, ahead_last, static_cast<unsigned long long>(record_batch), ring_slots);
  // Wait for the batch's steps up to `last`, or up to the step that ended it early (its own
  // record then stays in the live buffers when it is this one). done before stopped: the
  // kernel writes the stop mark before the step's number.
  const auto t0 = Clock::now();
  for (unsigned spins = 1;; ++spins) {
    const unsigned long long done = done_mark();
    const unsigned long long stopped = stopped_mark();
    if (stopped >= q && stopped <= last && done >= stopped) {
      if (stopped == q) return false;
      last = stopped - 1;
      break;
    }
    if (done >= last) break;
    if (exited_mark() == epoch) {
      // Its marks are final now: look once more, then give up.
      const unsigned long long d2 = done_mark(), s2 = stopped_mark();
      if (d2 >= last || (s2 >= q && s2 <= last && d2 >= s2)) continue;
      resident_alive = false;
      throw RuntimeError(fmt::format("the resident small-step kernel ended before recorded step {} (batch to {})",
                                     last, ahead_last));
    }
    if ((spins & 1023u) != 0) continue;
    const cudaError_t e = cudaStreamQuery(resident_stream);
    if (e != cudaSuccess && e != cudaErrorNotReady) {
      resident_alive = false;
      check(e, "small_resident (cudaStreamQuery, recorded batch)");
    }
    if (ms_since(t0) > static_cast<double>(resident_timeout_ms))
      throw RuntimeError(fmt::format("the resident small-step kernel did not finish recorded step {} within {} ms "
                                     "(resident_timeout_ms)",
                                     last, resident_timeout_ms));
  }
  // The pool offsets of the batch's slots from its steps' pair counts (each step's
  // statistics slot, written before its number), as the kernel advanced them.
  const std::size_t first = window.slot(q), count = static_cast<std::size_t>(last - q + 1);
  window_at[0] = 0;
  for (std::size_t k = 0; k < first + count; ++k)
    window_at[k + 1] = window_at[k] + ring_host[(window.base + k) % gpu::kResidentStatsSlots].counts[0];
  const std::size_t b0 = first * n, bn = count * n;
  const auto back = [this](void* to, const void* from, std::size_t bytes, const char* what) {
    if (bytes > 0) check(cudaMemcpyAsync(to, from, bytes, cudaMemcpyDeviceToHost, stream), what);
  };
  back(copy_x_pre + b0, ring_x_pre.get() + b0, sizeof(Vec3) * bn, "cudaMemcpy from 'record ring: x_pre'");
  back(copy_v_pre + b0, ring_v_pre.get() + b0, sizeof(Vec3) * bn, "cudaMemcpy from 'record ring: v_pre'");
  back(copy_x_post + b0, ring_x_post.get() + b0, sizeof(Vec3) * bn, "cudaMemcpy from 'record ring: x_post'");
  back(copy_v_post + b0, ring_v_post.get() + b0, sizeof(Vec3) * bn, "cudaMemcpy from 'record ring: v_post'");
  back(copy_aabb + b0, ring_aabb.get() + b0, sizeof(Aabb) * bn, "cudaMemcpy from 'record ring: AABBs'");
  const std::size_t p0 = window_at[first], pn = window_at[first + count] - p0;
  back(copy_pairs + p0, ring_pair_list.get() + p0, sizeof(Pair) * pn, "cudaMemcpy from 'record ring: pairs'");
  back(copy_confirmed + p0, ring_confirmed.get() + p0, pn, "cudaMemcpy from 'record ring: confirmed flags'");
  back(copy_records + p0, ring_records.get() + p0, sizeof(gpu::DeviceContact) * pn,
       "cudaMemcpy from 'record ring: contact records'");
  check(cudaStreamSynchronize(stream), "cudaStreamSynchronize (recorded batch)");
  window.copied(q, last);
  if (last == ahead_last) prefetch_records(q, last);
  return true;
}

void CudaWorld::Impl::prefetch_records(unsigned long long q, unsigned long long last) {
  if (small_profile || !resident_alive || exited_mark() == epoch) return;  // (an exited kernel: the next step asks)
  const std::int64_t remaining = promised - static_cast<std::int64_t>(last - q);  // promised after `last`
  if (remaining <= 0) return;
  unsigned long long room = 0;
  if (!gpu::RecordWindow::next_batch_room(q, last, gpu::kResidentStatsSlots, room)) return;
  const unsigned long long first = last + 1;
  const std::int64_t frame = step_frame + static_cast<std::int64_t>(first - q);
  unsigned long long extra = 0;
  if (!timed_frame(frame)) {  // as batch_extra: up to the next timed step, which ends the batch
    extra = std::min({room, static_cast<unsigned long long>(remaining - 1),
                      static_cast<unsigned long long>(record_batch - 1), gpu::kResidentAheadMax});
    if (stage_times)
      extra = std::min(extra, static_cast<unsigned long long>(stage_time_every - (frame - 1) % stage_time_every));
  }
  const bool stamp = timed_frame(frame + static_cast<std::int64_t>(extra));
  // The phase stamps have one place: not while this batch's last step's are still to be read.
  if (stamp && timed_frame(step_frame + static_cast<std::int64_t>(last - q))) return;
  ahead_last = first + extra;
  prefetched_first = first;
  window.next_base = first;
  ++resident_requests;
  write_request((first << gpu::kResidentShift) | (extra << gpu::kResidentAheadShift) | gpu::kResidentRecord |
                (stamp && small_dev ? gpu::kResidentStamp : 0ull));
}

void CudaWorld::Impl::run_step(const Scene& scene, bool recording) {
  if (!prepared) stop_resident();  // prepare() frees buffers: cudaFree waits for every kernel
  prepare();
  if (small) run_small(scene, recording);
  else run_stages(scene, recording);
}

// ---- CudaWorld ---------------------------------------------------------------------------

std::unique_ptr<Engine> make_cuda_engine(std::shared_ptr<const Model> model, const std::string& broadphase,
                                         const CudaSettings& settings) {
  return std::make_unique<CudaWorld>(std::move(model), broadphase, settings);
}

CudaWorld::CudaWorld(std::shared_ptr<const Model> model, const std::string& broadphase,
                     const CudaSettings& settings, const TestHooks& hooks)
    : model_(std::move(model)), impl_(std::make_unique<Impl>()) {
  if (!model_) throw InputError("CudaWorld: no model given");
  require_translation_only(model_->scene, "cuda");  // design.md section 3: octocd's engines translate only
  // Needs no device; throws InputError for more than kCudaMaxBodies bodies and for a
  // broadphase the device does not have, before anything is sized from the body count.
  const std::uint64_t needed = cuda_device_bytes_needed(*model_, broadphase);
  std::unique_ptr<gpu::DeviceBroadPhase> bp;
  // Made before the device is asked for: a parameter out of range is an input error
  // anywhere. A row whose device is `step` (flat) runs in the step itself, with no bp.
  if (find_broadphase_info(broadphase)->device == BroadPhaseDevice::seam) {  // known: checked above
    BroadPhaseConfig cfg = model_->scene.broadphase;
    cfg.name = broadphase;
    bp = gpu::make_device_broadphase(cfg, model_->scene.domain, gpu::DeviceUse::Steps);
  }
  check_cuda_settings(settings, "cuda settings");  // input wherever it is read, device or not
  if (hooks.resident_idle_us < 0) throw InputError("CudaWorld::TestHooks: resident_idle_us < 0");
  const std::string reason = gpu::no_device_reason();
  if (!reason.empty()) throw RuntimeError("no CUDA device: " + reason + "; the cuda engine needs one");
  gpu::check_free_memory(*model_, broadphase, needed, settings.memory_limit_bytes,
                    hooks.free_bytes);  // before the first allocation

  Impl& d = *impl_;
  d.broadphase = broadphase;
  d.bp = std::move(bp);
  d.device = gpu::describe_current_device();
  d.mid_early_exit = settings.midphase_early_exit ? 1 : 0;
  d.mid_fuse_min_items = hooks.fuse_min_items;
  d.mid_witness_pass_min_pairs = hooks.witness_pass_min_pairs;
  d.sync_each_launch = settings.sync_each_launch;
  d.use_graph = settings.graph;
  d.stage_times = settings.stage_times;
  d.stage_time_every = settings.stage_time_every;
  d.record_batch = settings.record_batch;
  if (hooks.record_ring_max_bytes > 0) d.ring_max_bytes = hooks.record_ring_max_bytes;
  {
    int dev = 0, sms = 1;
    check(cudaGetDevice(&dev), "cudaGetDevice");
    check(cudaDeviceGetAttribute(&sms, cudaDevAttrMultiProcessorCount, dev), "cudaDeviceGetAttribute");
    d.warp_grid = static_cast<unsigned>(std::max(1, sms) * 4);
    // The fused small step: wanted for this scene, and launchable (a device that cannot
    // launch cooperative kernels, or a kernel that does not fit, keeps the per-stage path).
    const std::size_t bodies = model_->initial.size();
    const bool wanted = bodies >= 1 && bodies <= kCudaSmallStepMaxBodies && settings.small_path;
    int coop = 0, per_sm = 0;
    if (wanted) {
      check(cudaDeviceGetAttribute(&coop, cudaDevAttrCooperativeLaunch, dev), "cudaDeviceGetAttribute");
      if (coop) check(gpu::small_step_blocks_per_sm(per_sm), "cudaOccupancyMaxActiveBlocksPerMultiprocessor");
    }
    if (wanted && coop && per_sm > 0) {
      int blocks = std::min(per_sm, gpu::kSmallStepBlocksPerSm) * std::max(1, sms);
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
    d.small_profile = settings.small_profile;
    check(cudaMallocHost(reinterpret_cast<void**>(&d.small_host),
                         sizeof(unsigned long long) * (1 + gpu::kSmallProfileSlots)),
          "cudaMallocHost (step number, phase stamps)");
    for (int i = 0; i <= gpu::kSmallProfileSlots; ++i) d.small_host[i] = 0;
    void* mapped_done = nullptr;
    if (d.host_dev && cudaHostGetDevicePointer(&mapped_done, d.small_host, 0) == cudaSuccess)
      d.small_dev = static_cast<unsigned long long*>(mapped_done);
    else (void)cudaGetLastError();
    // The resident kernel needs the polled wait (mapped memory) and no per-launch sync.
    d.resident_possible = d.resident_possible && d.small_dev && !d.sync_each_launch;
    if (d.resident_possible) {
      check(cudaMallocHost(reinterpret_cast<void**>(&d.resident_host), sizeof(unsigned long long) * 16),
            "cudaMallocHost (resident step request)");
      for (int i = 0; i < 16; ++i) d.resident_host[i] = 0;
      check(cudaMallocHost(reinterpret_cast<void**>(&d.ring_host), sizeof(gpu::StepStats) * gpu::kResidentStatsSlots),
            "cudaMallocHost (resident step statistics)");
      for (std::uint32_t i = 0; i < gpu::kResidentStatsSlots; ++i) d.ring_host[i] = gpu::StepStats{};
      void* mapped_request = nullptr;
      void* mapped_ring = nullptr;
      if (cudaHostGetDevicePointer(&mapped_request, d.resident_host, 0) == cudaSuccess &&
          cudaHostGetDevicePointer(&mapped_ring, d.ring_host, 0) == cudaSuccess) {
        d.resident_dev = static_cast<unsigned long long*>(mapped_request);
        d.ring_dev = static_cast<gpu::StepStats*>(mapped_ring);
      } else {
        (void)cudaGetLastError();
        d.resident_possible = false;
      }
    }
    d.persistent = d.resident_possible;  // the default; set_persistent changes it
    const long idle_us = hooks.resident_idle_us > 0 ? hooks.resident_idle_us : gpu::kResidentIdleUs;
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

  // Midphase level list (design.md section 5.2), as the CPU's confirm_contact converts it.
  const MidphaseConfig& mc = m.scene.midphase;
  d.levels.aabb_only = mc.aabb_only;
  d.levels.count = static_cast<int>(std::min<std::size_t>(mc.levels.size(), hd::kMidphaseMaxLevels));
  for (int i = 0; i < d.levels.count; ++i) d.levels.levels[i] = mc.levels[static_cast<std::size_t>(i)];
  d.level_steps = d.levels.aabb_only ? 0 : d.levels.count;
  d.leaf_vertices = largest_mean_leaf_vertices(m);
  d.small_lean = gpu::small_lean_kernel(d.leaf_vertices);

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
      d.any_mesh = true;
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
  d.index_cap = n / 8 + 64;  // a first guess (about 1 pair per 8 bodies); grown like pair_cap
  d.static_static = static_static_pairs(m);
  if (d.small && n > 0) {
    d.allocate_staging();
    d.x_pre.ensure(n);  // the recorded steps' state at their start, written by the kernel
    d.v_pre.ensure(n);
  }
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

bool CudaWorld::has_stage(Stage s) const { return impl_->has_stage(s); }

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
                     d.small_dev ? "poll" : "sync");
  return out;
}

std::string CudaWorld::notes() const {
  const Impl& d = *impl_;
  if (!d.small) return d.stage_times_note();
  return fmt::format(
      "each step is one fused cooperative kernel ({} bodies: the small-scene path, up to {}; small_path=false runs "
      "the per-stage kernels){}: its broadphase is the all-pairs test whatever the broadphase named ('{}'; the same "
      "pairs), so 'broadphase candidates' is n(n-1)/2; its {} kernel (the largest mean leaf cell holds {:.0f} "
      "vertices, the lean kernel up to {:.0f}){}; {}",
      d.n, kCudaSmallStepMaxBodies, d.persistent ? ", run by a resident kernel that steps on request" : "",
      d.broadphase, d.small_lean ? "lean" : "plain", d.leaf_vertices, gpu::kSmallLeanLeafVertices,
      d.small_lean && d.n <= gpu::kSmallFrontBodies ? ", its midphase a block per pair" : "", d.stage_times_note());
}

bool CudaWorld::persistent() const { return impl_->persistent; }

void CudaWorld::plan_steps(std::int64_t steps) { impl_->promised = steps > 0 ? steps : 0; }

std::int64_t CudaWorld::steps_ahead() const {
  const Impl& d = *impl_;
  return d.ahead_last > d.sequence ? static_cast<std::int64_t>(d.ahead_last - d.sequence) : 0;
}

void CudaWorld::set_persistent(bool on) {
  Impl& d = *impl_;
  d.refuse_ahead("set_persistent");
  if (!on) d.stop_resident();
  d.persistent = on && d.resident_possible;
}

std::uint64_t CudaWorld::resident_launches() const { return impl_->resident_launches; }
std::uint64_t CudaWorld::resident_requests() const { return impl_->resident_requests; }

std::uint64_t CudaWorld::device_bytes() const {
  std::uint64_t total = 0;
  for (const BufferBase* b : impl_->all_buffers()) total += b->bytes();
  for (const BufferBase* b : impl_->ring_buffers()) total += b->bytes();
  if (impl_->bp) total += impl_->bp->device_bytes();
  return total;
}

void CudaWorld::reset_capacities(std::size_t capacity) {
  if (capacity < 1) capacity = 1;
  Impl& d = *impl_;
  d.refuse_ahead("reset_capacities");
  d.stop_resident();  // before any cudaFree
  d.drop_graph();
  for (BufferBase* b : d.scratch_buffers()) b->reset(capacity);
  d.pair_cap = capacity;
  d.list_cap = capacity;
  d.index_cap = capacity;
  d.prepared = false;
}

void CudaWorld::set_state(const BodyState& s) {
  Impl& d = *impl_;
  d.refuse_ahead("set_state");
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

void CudaWorld::set_recording(bool on) {
  if (on != recording_) impl_->refuse_ahead("set_recording");
  recording_ = on;
  if (on) {  // kept once made: a run records from its start to its end
    impl_->x_pre.ensure(impl_->n);
    impl_->v_pre.ensure(impl_->n);
  }
}

const FrameRecord& CudaWorld::record() const {
  if (!record_whole_) {
    const Impl& d = *impl_;
    if (d.served_slot >= 0) {  // from the recorded batch's host copy
      const std::size_t at = static_cast<std::size_t>(d.served_slot) * d.n;
      record_.x_pre.assign(d.copy_x_pre + at, d.copy_x_pre + at + d.n);
      record_.v_pre.assign(d.copy_v_pre + at, d.copy_v_pre + at + d.n);
      record_.aabbs.assign(d.copy_aabb + at, d.copy_aabb + at + d.n);
    } else {
      download(record_.x_pre, d.x_pre, d.n, d.stream);
      download(record_.v_pre, d.v_pre, d.n, d.stream);
      download(record_.aabbs, d.aabb, d.n, d.stream);
    }
    const BodyState& s = state();
    record_.x_post = s.x;
    record_.v_post = s.v;
    record_whole_ = true;
  }
  return record_;
}

const BodyState& CudaWorld::state() const {
  if (state_frame_ != frame_) {
    Impl& d = *impl_;
    if (d.served_slot >= 0) {
      // A recorded batch's step: its state after it from the host copy (the kernel may run
      // ahead); w never changes in a step, so the host's copy of it holds.
      const std::size_t at = static_cast<std::size_t>(d.served_slot) * d.n;
      state_.x.assign(d.copy_x_post + at, d.copy_x_post + at + d.n);
      state_.v.assign(d.copy_v_post + at, d.copy_v_post + at + d.n);
      state_frame_ = frame_;
      return state_;
    }
    d.refuse_ahead("state");
    if (d.staging) {
      const std::size_t n = d.n;
      check(cudaMemcpyAsync(d.staged_x, d.x.get(), sizeof(Vec3) * n, cudaMemcpyDeviceToHost, d.stream),
            "cudaMemcpy from 'body positions'");
      check(cudaMemcpyAsync(d.staged_v, d.v.get(), sizeof(Vec3) * n, cudaMemcpyDeviceToHost, d.stream),
            "cudaMemcpy from 'body velocities'");
      check(cudaMemcpyAsync(d.staged_w, d.w.get(), sizeof(float) * n, cudaMemcpyDeviceToHost, d.stream),
            "cudaMemcpy from 'body inverse masses'");
      check(cudaStreamSynchronize(d.stream), "cudaStreamSynchronize (state)");
      state_.x.assign(d.staged_x, d.staged_x + n);
      state_.v.assign(d.staged_v, d.staged_v + n);
      state_.w.assign(d.staged_w, d.staged_w + n);
    } else {
      download(state_.x, d.x, d.n, d.stream);
      download(state_.v, d.v, d.n, d.stream);
      download(state_.w, d.w, d.n, d.stream);
    }
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
  d.served_slot = -1;
  m.time = static_cast<double>(m.frame) * static_cast<double>(scene.dt);
  if (recording_) {
    // The state at the step's start stays on the device until record() asks for it; on the
    // small path the recorded step's kernel copies it (SmallStepDesc::x_pre).
    const std::size_t bytes = sizeof(Vec3) * n;
    if (n > 0 && !d.small) {
      check(cudaMemcpyAsync(d.x_pre.get(), d.x.get(), bytes, cudaMemcpyDeviceToDevice, d.stream), "cudaMemcpy x_pre");
      check(cudaMemcpyAsync(d.v_pre.get(), d.v.get(), bytes, cudaMemcpyDeviceToDevice, d.stream), "cudaMemcpy v_pre");
      check(cudaStreamSynchronize(d.stream), "cudaStreamSynchronize (x_pre, v_pre)");
    }
    record_.frame = m.frame;
    record_whole_ = false;
  }
  // The step, run again from the saved state with larger buffers while a list overflows.
  d.begin_step(m.frame);
  d.run_step(scene, recording_);
  while (d.rerun_needed()) {
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
  if (d.promised > 0) --d.promised;
  if (r.first_non_finite < n) {
    // The resident kernel's batch stopped at this step: nothing runs ahead.
    d.ahead_last = d.sequence;
    d.promised = 0;
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
  d.end_step(m.stage_ms);
  m.memory_bytes = device_bytes();

  frame_ = m.frame;
  if (recording_) {
    std::vector<std::uint8_t> confirmed_pageable;
    std::vector<gpu::DeviceContact> records_pageable;
    const std::uint8_t* confirmed = nullptr;
    const gpu::DeviceContact* recs = nullptr;
    const bool from_ring = d.recorded_batch && d.fetch_records(np);
    // A recorded batch's step not in the ring (its pairs did not fit) ended the batch: the
    // next step is a new request.
    if (d.recorded_batch && !from_ring) d.ahead_last = std::min(d.ahead_last, d.sequence);
    if (from_ring) {
      const std::size_t slot = d.window.slot(d.sequence), at = d.window_at[slot];
      d.served_slot = static_cast<long long>(slot);
      record_.pairs.assign(d.copy_pairs + at, d.copy_pairs + at + np);
      confirmed = d.copy_confirmed + at;
      recs = d.copy_records + at;
    } else if (d.staging && np <= Impl::kStagedRecordPairs) {
      if (np > 0) {
        check(cudaMemcpyAsync(d.staged_pairs, d.pairs.get(), sizeof(Pair) * np, cudaMemcpyDeviceToHost, d.stream),
              "cudaMemcpy from 'candidate pairs'");
        check(cudaMemcpyAsync(d.staged_confirmed, d.confirmed.get(), np, cudaMemcpyDeviceToHost, d.stream),
              "cudaMemcpy from 'confirmed flags'");
        check(cudaMemcpyAsync(d.staged_records, d.records.get(), sizeof(gpu::DeviceContact) * np,
                              cudaMemcpyDeviceToHost, d.stream),
              "cudaMemcpy from 'contact records'");
        check(cudaStreamSynchronize(d.stream), "cudaStreamSynchronize (record)");
      }
      record_.pairs.assign(d.staged_pairs, d.staged_pairs + np);
      confirmed = d.staged_confirmed;
      recs = d.staged_records;
    } else {
      download(record_.pairs, d.pairs, np, d.stream);
      download(confirmed_pageable, d.confirmed, np, d.stream);
      download(records_pageable, d.records, np, d.stream);
      confirmed = confirmed_pageable.data();
      recs = records_pageable.data();
    }
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
  }
  m.step_ms = ms_since(t_step);
  metrics_ = m;
  return metrics_;
}

}  // namespace octocd
