#pragma once
// Device code of the frame metrics (metrics.cu; see there for the order of the sums),
// shared by metrics.cu's kernels and the fused small-scene step (small_step.cu), which
// runs the one-block pass with fewer threads over the same kMetricsBlockSize slots, so the
// doubles come out with the same bits. CUDA only (nvcc).
#include "kernels.hpp"

namespace octocd {
namespace gpu {
namespace metrics {

struct Acc {
  double ke, px, py, pz, pen_sum, pen_max;
  unsigned long long contacts, pen_above;
  std::uint32_t first_bad;
};

__device__ inline void combine(Acc& a, const Acc& b) {
  a.ke += b.ke;
  a.px += b.px;
  a.py += b.py;
  a.pz += b.pz;
  a.pen_sum += b.pen_sum;
  a.pen_max = b.pen_max > a.pen_max ? b.pen_max : a.pen_max;
  a.contacts += b.contacts;
  a.pen_above += b.pen_above;
  a.first_bad = b.first_bad < a.first_bad ? b.first_bad : a.first_bad;
}

/// `a` of lane + delta (warp-wide, full mask).
__device__ inline Acc shfl_down(const Acc& a, unsigned delta) {
  constexpr unsigned kAll = 0xffffffffu;
  return Acc{__shfl_down_sync(kAll, a.ke, delta),       __shfl_down_sync(kAll, a.px, delta),
             __shfl_down_sync(kAll, a.py, delta),       __shfl_down_sync(kAll, a.pz, delta),
             __shfl_down_sync(kAll, a.pen_sum, delta),  __shfl_down_sync(kAll, a.pen_max, delta),
             __shfl_down_sync(kAll, a.contacts, delta), __shfl_down_sync(kAll, a.pen_above, delta),
             __shfl_down_sync(kAll, a.first_bad, delta)};
}

/// The block's combined accumulator of s[0 .. kMetricsBlockSize) lands in s[0]: a fixed
/// tree over the kMetricsBlockSize slots, whatever the block size (thread t combines the
/// slots t, t + blockDim.x, ... of each level; with blockDim.x == kMetricsBlockSize one
/// slot per thread). The last five levels (slots 0 .. 31) run in warp 0's registers: lane t
/// holds slot t and combines lane t + half's value into it, the same pairs in the same
/// order as in shared memory (so the same bits), without a block barrier per level.
/// blockDim.x >= 32. Every thread of the block calls it.
__device__ inline void block_combine(Acc* s) {
  __syncthreads();
  for (std::uint32_t half = kMetricsBlockSize / 2; half >= 32; half /= 2) {
    for (std::uint32_t t = threadIdx.x; t < half; t += blockDim.x) combine(s[t], s[t + half]);
    __syncthreads();
  }
  if (threadIdx.x < 32) {
    Acc a = s[threadIdx.x];
    for (unsigned half = 16; half > 0; half /= 2) {
      const Acc b = shfl_down(a, half);
      if (threadIdx.x < half) combine(a, b);
    }
    if (threadIdx.x == 0) s[0] = a;
  }
  __syncthreads();
}

__device__ inline MetricsResult to_result(const Acc& r) {
  MetricsResult out;
  out.kinetic_energy = r.ke;
  out.momentum[0] = r.px;
  out.momentum[1] = r.py;
  out.momentum[2] = r.pz;
  out.pen_sum = r.pen_sum;
  out.pen_max = r.pen_max;
  out.contacts = r.contacts;
  out.pen_above = r.pen_above;
  out.first_non_finite = r.first_bad;
  return out;
}

__device__ inline Acc from_result(const MetricsResult& r) {
  return Acc{r.kinetic_energy, r.momentum[0], r.momentum[1], r.momentum[2], r.pen_sum, r.pen_max,
             r.contacts,       r.pen_above,   r.first_non_finite};
}

/// First pass of block g of G: the kMetricsBlockSize slots t of the block (each taken by
/// thread t mod blockDim.x; blockDim.x divides kMetricsBlockSize) accumulate bodies and
/// first-pass contacts gB + t, gB + t + GB, ... (B = kMetricsBlockSize) in order, then
/// block_combine; thread 0 writes the result to *out. `s`: kMetricsBlockSize slots of the
/// block's shared memory. Every thread of the block calls it.
__device__ inline void metrics_block(const MetricsDesc& d, Acc* s, std::uint32_t g, std::uint32_t blocks,
                                     MetricsResult* out) {
  const std::uint32_t stride = blocks * kMetricsBlockSize;
  const std::uint32_t np = d.pair_capacity == 0 ? 0u : live_count(d.pair_count, d.pair_capacity);
  for (std::uint32_t t = threadIdx.x; t < kMetricsBlockSize; t += blockDim.x) {
    const std::uint32_t first = g * kMetricsBlockSize + t;
    Acc a{0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0ull, 0ull, d.n};
    for (std::uint32_t i = first; i < d.n; i += stride) {
      const float w = d.w[i];
      if (w == 0.0f) continue;
      const Vec3 x = d.x[i];
      const Vec3 v = d.v[i];
      if (!is_finite(x) || !is_finite(v)) {
        if (i < a.first_bad) a.first_bad = i;
        continue;
      }
      // As World::step: mass = 1 / double(w); 0.5 m |v|^2 and m v in double.
      const double mass = 1.0 / static_cast<double>(w);
      a.ke += 0.5 * mass *
              (static_cast<double>(v.x) * v.x + static_cast<double>(v.y) * v.y + static_cast<double>(v.z) * v.z);
      a.px += mass * v.x;
      a.py += mass * v.y;
      a.pz += mass * v.z;
    }
    for (std::uint32_t k = first; k < np; k += stride) {
      const float depth = d.depth0[k];
      if (depth < 0.0f) continue;  // not a contact (Eq. 9 discards have no depth)
      a.contacts += 1;
      a.pen_sum += depth;
      a.pen_max = static_cast<double>(depth) > a.pen_max ? static_cast<double>(depth) : a.pen_max;
      if (depth > d.slop) a.pen_above += 1;
    }
    s[t] = a;
  }
  block_combine(s);
  if (threadIdx.x == 0) *out = to_result(s[0]);
}

}  // namespace metrics
}  // namespace gpu
}  // namespace octocd
