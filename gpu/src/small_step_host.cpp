// The fused small step of the cuda engine (small_step.cu) from the host: its descriptor,
// one cooperative launch per step with a polled wait on mapped memory, and the resident
// kernel that stays launched and steps on request, several steps a request when the caller
// promised them (Engine::plan_steps; CudaWorld's class comment).
#include <algorithm>
#include <chrono>
#include <cstring>

#include <fmt/format.h>

#include "cuda_impl.hpp"
#include "octocd/error.hpp"

namespace octocd {

using gpu::check;
using gpu::Clock;
using gpu::cuda_text;
using gpu::ms_since;

gpu::SmallStepDesc CudaWorld::Impl::small_desc(const Scene& scene, bool recording) {
  const ContactParams& params = scene.response;
  gpu::SmallStepDesc s;
  s.bodies = bodies();
  s.bodies.x_saved = x_saved.get();
  s.bodies.v_saved = v_saved.get();
  s.gravity = scene.gravity;
  s.dt = scene.dt;
  s.max_velocity = params.max_velocity;
  s.iterations = params.iterations;
  s.out_count = bp_counts.count.get();
  s.out_offset = bp_counts.offset.get();
  s.in_count = in_counts.count.get();
  s.in_offset = in_counts.offset.get();
  s.in_list = in_list.get();
  s.pair_keys = pair_keys.get();
  s.shift = gpu::key_bits(n);
  s.mid = mid_desc(pair_keys.get());  // the fill writes them in (a, b) order: no sort
  s.mid.leaf_items = nullptr;  // the small path's leaves are never fused by count
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
  s.one_block_pairs = gpu::kSmallOneBlockPairs;
  s.front_bodies = gpu::kSmallFrontBodies;
  s.shared_boxes_bodies = gpu::kSmallSharedBoxesBodies;
  s.lean = small_lean ? 1 : 0;
  s.x_pre = x_pre.get();  // allocated at construction on the small path: a resident kernel keeps the pointers
  s.v_pre = v_pre.get();
  if (small_dev) {
    s.done = small_dev;
    s.sequence = sequence;
    s.profile = stamps();
  }
  return s;
}

void CudaWorld::Impl::run_small(const Scene& scene, bool recording) {
  const auto t0 = Clock::now();
  ++sequence;
  if (persistent) {
    resident_step(scene, recording);
  } else {
    recorded_batch = false;  // a recorded step's record is read from the live buffers
    launched(gpu::launch_small_step(small_desc(scene, recording), small_grid, stream), "small_step");
    if (!host_dev)
      check(cudaMemcpyAsync(host, stats.get(), sizeof(gpu::StepStats), cudaMemcpyDeviceToHost, stream),
            "cudaMemcpy step statistics");
    if (host_dev && small_dev) wait_small_step();
    else check(cudaStreamSynchronize(stream), "cudaStreamSynchronize (step)");
  }
  if (small_profile && small_dev) {
    const double host_ns = std::chrono::duration<double, std::nano>(Clock::now() - t0).count();
    volatile const unsigned long long* p = small_host + 1;
    for (int i = 1; i < gpu::kSmallProfileSlots; ++i) profile_ns[i] += static_cast<double>(p[i] - p[i - 1]);
    profile_ns[0] += host_ns;
    profile_kernel_ns += static_cast<double>(p[gpu::kSmallProfileSlots - 1] - p[0]);
    ++profile_steps;
  }
}

void CudaWorld::Impl::wait_small_step() {
  volatile const unsigned long long* done = small_host;
  for (unsigned spins = 1; *done != sequence; ++spins) {
    if ((spins & 1023u) != 0) continue;
    const cudaError_t e = cudaStreamQuery(stream);
    if (e == cudaSuccess) break;
    if (e != cudaErrorNotReady) check(e, "small_step (cudaStreamQuery)");
  }
}

// ---- the resident small step ------------------------------------------------------------

unsigned long long CudaWorld::Impl::exited_mark() const {
  return __atomic_load_n(resident_host + kExitedWord, __ATOMIC_ACQUIRE);
}
unsigned long long CudaWorld::Impl::stopped_mark() const {
  return __atomic_load_n(resident_host + kStoppedWord, __ATOMIC_ACQUIRE);
}
unsigned long long CudaWorld::Impl::done_mark() const { return __atomic_load_n(small_host, __ATOMIC_ACQUIRE); }
void CudaWorld::Impl::write_request(unsigned long long value) {
  __atomic_store_n(resident_host + kRequestWord, value, __ATOMIC_SEQ_CST);  // drains the store buffer
}

void CudaWorld::Impl::launch_resident(const Scene& scene, bool ring) {
  if (ring) ensure_record_ring();  // no kernel runs: the ring may be (re)allocated
  gpu::ResidentDesc r;
  r.request = resident_dev + kRequestWord;
  r.exited = resident_dev + kExitedWord;
  r.control = resident_control.get();
  r.handled = 0;  // every request is > 0 (sequence >= 1)
  r.epoch = ++epoch;
  r.idle_ns = resident_stall ? 0 : resident_idle_ns;
  r.records = records.get();
  r.stall = resident_stall ? 1 : 0;
  if (ring) r.ring = ring_desc();
  r.stopped = resident_dev + kStoppedWord;
  resident_ring = ring;
  gpu::SmallStepDesc s = small_desc(scene, false);
  s.profile = small_dev + 1;  // stamped on the requests that carry kResidentStamp
  s.host_stats = ring_dev;
  s.host_slots = gpu::kResidentStatsSlots;
  const cudaError_t e = gpu::launch_small_resident(s, r, resident_grid, resident_stream);
  if (e != cudaSuccess) {
    (void)cudaGetLastError();
    throw RuntimeError(fmt::format("CUDA kernel 'small_resident' failed to launch: {}", cuda_text(e)));
  }
  resident_alive = true;
  ++resident_launches;
}

unsigned long long CudaWorld::Impl::batch_extra() const {
  if (promised <= 1 || small_profile || timed) return 0;
  std::int64_t extra = std::min<std::int64_t>(promised - 1, static_cast<std::int64_t>(gpu::kResidentAheadMax));
  if (stage_times) {  // up to the next timed step (frames 1, 1 + k, ..), stamped as the batch's last
    const std::int64_t k = stage_time_every;
    extra = std::min<std::int64_t>(extra, k - (step_frame - 1) % k);
  }
  return static_cast<unsigned long long>(extra);
}

void CudaWorld::Impl::refuse_ahead(const char* call) const {
  if (ahead_last <= sequence) return;
  throw RuntimeError(fmt::format(
      "CudaWorld::{}: refused while the resident small-step kernel runs {} step(s) ahead of the last step() "
      "(Engine::plan_steps promised them with nothing read or changed in between); call step() through them first",
      call, ahead_last - sequence));
}

void CudaWorld::Impl::resident_step(const Scene& scene, bool recording) {
  const bool covered = sequence <= ahead_last;  // an earlier request's batch runs this step
  if (!covered) {
    if (resident_alive && exited_mark() == epoch) stop_resident();  // it ended itself, idle
    // A recorded run with record_batch > 1 and steps promised runs ahead too, each step's
    // record into the ring (a kernel launched without one is ended first); else a recorded
    // step runs alone and is read from the live buffers.
    const bool ring = recording && batching_records() && promised > 1;
    if (ring && resident_alive && !resident_ring) stop_resident();
    unsigned long long extra = recording && !ring ? 0 : batch_extra();
    if (ring) extra = std::min<unsigned long long>(extra, static_cast<unsigned long long>(record_batch - 1));
    recorded_batch = ring;
    prefetched_first = 0;
    if (ring) window.start(sequence);
    const bool stamp = small_profile || timed_frame(step_frame + static_cast<std::int64_t>(extra));
    ahead_last = sequence + extra;
    ++resident_requests;
    write_request((sequence << gpu::kResidentShift) | (extra << gpu::kResidentAheadShift) |
                  (recording ? gpu::kResidentRecord : 0ull) | (stamp && small_dev ? gpu::kResidentStamp : 0ull));
    if (!resident_alive) launch_resident(scene, ring);
  }
  const auto t0 = Clock::now();
  for (unsigned spins = 1;; ++spins) {
    if (done_mark() >= sequence) break;
    if (exited_mark() == epoch) {
      if (done_mark() >= sequence) break;  // it ran the step, then ended idle
      resident_alive = false;
      // A batch stops early only after a step the host reruns (stop_resident) or throws on
      // (ahead_last reset): its later steps are never waited for.
      // A batch requested ahead (prefetch_records) that the kernel, idle, ended without
      // taking: launched again, it takes the request still in the word.
      if (covered && prefetched_first != 0 && sequence >= prefetched_first && done_mark() < prefetched_first) {
        launch_resident(scene, true);
        continue;
      }
      if (covered)
        throw RuntimeError(fmt::format("the resident small-step kernel ended before step {} of its batch (to {})",
                                       sequence, ahead_last));
      launch_resident(scene, recorded_batch && !covered);  // it ended without taking the request
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
  std::memcpy(static_cast<void*>(host), static_cast<const void*>(ring_host + sequence % gpu::kResidentStatsSlots),
              sizeof(gpu::StepStats));
}

void CudaWorld::Impl::stop_resident() {
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
  ahead_last = 0;  // no batch runs on
  recorded_batch = false;
  prefetched_first = 0;
  window.next_base = 0;
  check(cudaStreamSynchronize(resident_stream), "cudaStreamSynchronize (resident kernel's end)");
}

}  // namespace octocd
