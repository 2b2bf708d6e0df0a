// The cuda engine's stage times (FrameMetrics::stage_ms): one step in
// CudaSettings::stage_time_every is timed, the others run untimed on the same path and
// report the last timed step's times. On the per-stage path a timed step records CUDA
// events between the stages (from a second CUDA graph captured with them); on the fused
// small step thread 0 of block 0 stamps %globaltimer at the end of each phase into mapped
// host memory. Neither changes what the step computes.
#include <fmt/format.h>

#include "cuda_impl.hpp"

namespace octocd {

using gpu::check;

namespace {

constexpr std::size_t kStages = static_cast<std::size_t>(Stage::Count);

/// The fused kernel's stamp slots (kernels.hpp, kSmallProfilePhases) at the end of each
/// stage: integrate and AABBs are one phase (slot 1), the broadphase's count, scan and fill
/// end at slot 4, the midphase (start, the in-lists' pair indices, expand, leaf) at 7, the
/// response passes and clamp at 8, the metrics and the statistics' copy at 9.
constexpr int kStageEndSlot[kStages] = {1, 1, 4, 7, 8, 9};

}  // namespace

bool CudaWorld::Impl::timed_frame(std::int64_t frame) const {
  return stage_times && (frame - 1) % stage_time_every == 0;
}

void CudaWorld::Impl::begin_step(std::int64_t frame) {
  step_frame = frame;
  timed = timed_frame(frame);
}

void CudaWorld::Impl::record_event(int i, bool with_events) {
  if (!with_events) return;
  check(cudaEventRecordWithFlags(events[i], stream, capturing ? cudaEventRecordExternal : cudaEventRecordDefault),
        "cudaEventRecord");
}

unsigned long long* CudaWorld::Impl::stamps() const {
  return small_dev && (timed || small_profile) ? small_dev + 1 : nullptr;
}

void CudaWorld::Impl::end_step(std::array<double, kStages>& stage_ms) {
  if (timed) {
    if (small) {
      if (small_dev) {
        volatile const unsigned long long* p = small_host + 1;
        unsigned long long prev = p[0];
        for (std::size_t s = 0; s < kStages; ++s) {
          const unsigned long long end = p[kStageEndSlot[s]];
          held_ms[s] = end > prev ? static_cast<double>(end - prev) * 1e-6 : 0.0;
          prev = end > prev ? end : prev;
        }
      }
    } else {
      for (std::size_t s = 0; s < kStages; ++s) {
        float ms = 0.0f;
        check(cudaEventElapsedTime(&ms, events[s], events[s + 1]), "cudaEventElapsedTime");
        held_ms[s] = static_cast<double>(ms);
      }
    }
    ++timed_steps;
  }
  stage_ms = held_ms;
}

bool CudaWorld::Impl::has_stage(Stage s) const {
  if (!stage_times) return false;
  if (!small) return true;
  // The fused kernel integrates and builds the boxes in one phase (timed as `integrate`).
  return small_dev != nullptr && s != Stage::Aabbs;
}

std::string CudaWorld::Impl::stage_times_note() const {
  if (!stage_times) return "stage times: off (stage_times=false)";
  const long k = stage_time_every;
  const std::string which = k == 1 ? std::string("on every step")
                                   : fmt::format("sampled 1 step in {} (steps 1, {}, {}, ...; the others report the "
                                                 "last sample)",
                                                 k, 1 + k, 1 + 2 * k);
  if (small)
    return small_dev ? fmt::format("stage times: %globaltimer stamps at the fused kernel's phase ends, {}; "
                                   "integrate includes the world AABBs",
                                   which)
                     : "stage times: none (no mapped host memory for the fused kernel's stamps)";
  return fmt::format("stage times: CUDA events between the stages, {}", which);
}

}  // namespace octocd
