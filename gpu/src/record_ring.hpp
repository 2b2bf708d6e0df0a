#pragma once
/// \file record_ring.hpp
/// The host's bookkeeping of recorded batches (CudaSettings::record_batch; the device side
/// is gpu::RecordRing in kernels.hpp): how many pairs a ring slot holds, and which steps the
/// host's copy of the ring holds. Plain C++ with no CUDA header, so that it is tested
/// without a device (tests/gpu/test_cuda_footprint.cpp). Internal to gpu/.

#include <algorithm>
#include <cstddef>
#include <cstdint>

namespace octocd::gpu {

/// The most bytes the ring of recorded steps holds on the device (and its pinned host copy
/// on the host): the pairs a slot holds shrink to fit (record_ring_pairs).
constexpr std::uint64_t kRecordRingMaxBytes = 64ull << 20;

/// The pairs the ring's pool holds (gpu::RecordRing::pair_capacity: the pairs of a batch's
/// steps one after the other): `slots` steps at the engine's pair capacity, or fewer so that
/// the whole ring (`slots` x `bodies` x `body_bytes` for the states and boxes, and the pool at
/// `pair_bytes` a pair) stays within `max_bytes`; at least 1. A step whose pairs do not fit
/// the pool's rest ends its batch and is read from the live buffers.
inline std::uint32_t record_ring_pairs(std::uint64_t pair_capacity, std::uint64_t slots, std::uint64_t bodies,
                                       std::uint64_t body_bytes, std::uint64_t pair_bytes,
                                       std::uint64_t max_bytes = kRecordRingMaxBytes) {
  if (slots == 0 || pair_bytes == 0) return 1;
  const std::uint64_t fixed = slots * bodies * body_bytes;
  const std::uint64_t room = max_bytes > fixed ? (max_bytes - fixed) / pair_bytes : 0;
  const std::uint64_t pairs = std::max<std::uint64_t>(1, std::min(pair_capacity * slots, room));
  return static_cast<std::uint32_t>(std::min<std::uint64_t>(pairs, 0xffffffffull));
}

/// The steps (by their sequence number, CudaWorld::Impl::sequence) whose records the host's
/// copy of the ring holds, and the batch they belong to: the step with sequence `base` is in
/// slot 0, step q in slot q - base.
struct RecordWindow {
  unsigned long long base = 0;  ///< the sequence of slot 0: the first step of the request
  unsigned long long lo = 1;    ///< the first sequence held (lo > hi: none)
  unsigned long long hi = 0;    ///< the last sequence held
  /// The first sequence of the next batch, requested before this one's steps are taken
  /// (0: none): its slots count from there once the host asks for one of its steps.
  unsigned long long next_base = 0;

  /// Whether step `q`'s record is in the host copy.
  bool holds(unsigned long long q) const { return lo <= q && q <= hi; }
  /// Step q's slot (q >= base).
  std::size_t slot(unsigned long long q) const { return static_cast<std::size_t>(q - base); }
  /// Holds nothing (a new request, a rerun, a regrow).
  void clear() {
    lo = 1;
    hi = 0;
  }
  /// A new request whose first step has sequence `first`: nothing is held yet.
  void start(unsigned long long first) {
    base = first;
    next_base = 0;
    clear();
  }
  /// Before a copy for step `q` that the window does not hold: moves to the next batch when
  /// q is in it.
  void advance(unsigned long long q) {
    if (next_base != 0 && q >= next_base) start(next_base);
  }
  /// The most steps ahead (after its first) of the next batch, requested while the host
  /// still takes the steps up to `last` of this one, copied back from `first_held`: the
  /// device's statistics slots (`stat_slots`, one per step by sequence modulo) of the steps
  /// not yet taken must survive, so the next batch ends by first_held + stat_slots - 1.
  /// Returns false when no step of it fits.
  static bool next_batch_room(unsigned long long first_held, unsigned long long last, unsigned long long stat_slots,
                              unsigned long long& room) {
    const unsigned long long end = first_held + stat_slots - 1;  // the last sequence allowed
    if (end <= last) return false;
    room = end - (last + 1);  // steps after the next batch's first
    return true;
  }
  /// The last step to copy back with step `q` (q >= base): the batch's last step
  /// (`batch_last`, the request's sequence plus its steps ahead), at most `batch` steps from
  /// q, and never beyond the ring's `slots` slots.
  unsigned long long copy_last(unsigned long long q, unsigned long long batch_last, unsigned long long batch,
                               unsigned long long slots) const {
    unsigned long long last = std::max(q, batch_last);
    if (batch > 0) last = std::min(last, q + batch - 1);
    if (slots > 0) last = std::min(last, base + slots - 1);
    return std::max(last, q);
  }
  /// The steps lo .. last were copied back (a new window: the older ones are dropped).
  void copied(unsigned long long first, unsigned long long last) {
    lo = first;
    hi = last;
  }
};

}  // namespace octocd::gpu
