// Frame metrics on the device (SPEC 8 fields of FrameMetrics) and the non-finite guard:
// G blocks of B = kMetricsBlockSize threads (G = 1 up to kMetricsOneBlockBodies bodies,
// else kMetricsBlocks); thread t of block g accumulates elements gB + t, gB + t + GB, ...
// in order, then a fixed shared-memory tree combines the threads of a block; with G > 1
// a second one-block pass combines the G partial results in the same tree. Same n, same
// order:
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

/// The block's combined accumulator lands in s[0] (every thread calls it).
__device__ void block_combine(Acc* s, std::uint32_t t) {
  __syncthreads();
  for (std::uint32_t half = kMetricsBlockSize / 2; half > 0; half /= 2) {
    if (t < half) combine(s[t], s[t + half]);
    __syncthreads();
  }
}

__device__ MetricsResult to_result(const Acc& r) {
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

__device__ Acc from_result(const MetricsResult& r) {
  return Acc{r.kinetic_energy, r.momentum[0], r.momentum[1], r.momentum[2], r.pen_sum, r.pen_max,
             r.contacts,       r.pen_above,   r.first_non_finite};
}

/// First pass: block g of G accumulates its stride of bodies and contacts; G == 1 writes
/// *d.out, else d.partials[g].
__global__ void metrics_kernel(MetricsDesc d) {
  __shared__ Acc s[kMetricsBlockSize];
  const std::uint32_t t = threadIdx.x;
  const std::uint32_t first = blockIdx.x * kMetricsBlockSize + t;
  const std::uint32_t stride = gridDim.x * kMetricsBlockSize;
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
  const std::uint32_t np = d.pair_capacity == 0 ? 0u : live_count(d.pair_count, d.pair_capacity);
  for (std::uint32_t k = first; k < np; k += stride) {
    const float depth = d.depth0[k];
    if (depth < 0.0f) continue;  // not a contact (Eq. 9 discards have no depth)
    a.contacts += 1;
    a.pen_sum += depth;
    a.pen_max = static_cast<double>(depth) > a.pen_max ? static_cast<double>(depth) : a.pen_max;
    if (depth > d.slop) a.pen_above += 1;
  }
  s[t] = a;
  block_combine(s, t);
  if (t == 0) (gridDim.x == 1 ? *d.out : d.partials[blockIdx.x]) = to_result(s[0]);
}

/// Second pass (G > 1): one block combines the G partial results.
__global__ void metrics_final_kernel(MetricsDesc d, std::uint32_t blocks) {
  __shared__ Acc s[kMetricsBlockSize];
  const std::uint32_t t = threadIdx.x;
  s[t] = t < blocks ? from_result(d.partials[t]) : Acc{0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0ull, 0ull, d.n};
  block_combine(s, t);
  if (t == 0) *d.out = to_result(s[0]);
}

}  // namespace

cudaError_t launch_metrics(const MetricsDesc& d, cudaStream_t stream) {
  static_assert(kMetricsBlocks <= static_cast<unsigned>(kMetricsBlockSize), "one thread per partial");
  if (d.n <= kMetricsOneBlockBodies || d.partials == nullptr) {
    metrics_kernel<<<1, kMetricsBlockSize, 0, stream>>>(d);
    return cudaGetLastError();
  }
  metrics_kernel<<<kMetricsBlocks, kMetricsBlockSize, 0, stream>>>(d);
  const cudaError_t e = cudaGetLastError();
  if (e != cudaSuccess) return e;
  metrics_final_kernel<<<1, kMetricsBlockSize, 0, stream>>>(d, kMetricsBlocks);
  return cudaGetLastError();
}

}  // namespace gpu
}  // namespace octocd
