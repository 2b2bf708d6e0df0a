// Frame metrics on the device (SPEC 8 fields of FrameMetrics) and the non-finite guard:
// one block of kMetricsBlockSize threads; thread t accumulates elements t, t + B, ... in
// order, then a fixed shared-memory tree combines the threads. Same launch, same order:
// the doubles are reproducible run to run (they may differ from the CPU's sequential sums
// in the last bits, which SPEC 11 allows; the float32 state never depends on them).
#include "kernels.hpp"

namespace octocd {
namespace gpu {
namespace {

struct Acc {
  double ke, px, py, pz, pen_sum, pen_max;
  unsigned long long contacts, pen_above;
  std::uint32_t first_bad;
};

__device__ void combine(Acc& a, const Acc& b) {
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

__global__ void metrics_kernel(MetricsDesc d) {
  __shared__ Acc s[kMetricsBlockSize];
  const std::uint32_t t = threadIdx.x;
  Acc a{0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0ull, 0ull, d.n};
  for (std::uint32_t i = t; i < d.n; i += kMetricsBlockSize) {
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
  const std::uint32_t np = d.pair_capacity == 0 ? 0u : live_count(d.pair_count, d.pair_capacity);
  for (std::uint32_t k = t; k < np; k += kMetricsBlockSize) {
    const float depth = d.depth0[k];
    if (depth < 0.0f) continue;  // not a contact (Eq. 9 discards have no depth)
    a.contacts += 1;
    a.pen_sum += depth;
    a.pen_max = static_cast<double>(depth) > a.pen_max ? static_cast<double>(depth) : a.pen_max;
    if (depth > d.slop) a.pen_above += 1;
  }
  s[t] = a;
  __syncthreads();
  for (std::uint32_t half = kMetricsBlockSize / 2; half > 0; half /= 2) {
    if (t < half) combine(s[t], s[t + half]);
    __syncthreads();
  }
  if (t == 0) {
    const Acc& r = s[0];
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
    *d.out = out;
  }
}

}  // namespace

cudaError_t launch_metrics(const MetricsDesc& d, cudaStream_t stream) {
  metrics_kernel<<<1, kMetricsBlockSize, 0, stream>>>(d);
  return cudaGetLastError();
}

}  // namespace gpu
}  // namespace octocd
