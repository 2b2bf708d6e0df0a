// Frame metrics on the device (design.md section 8 fields of FrameMetrics) and the non-finite guard:
// G blocks of B = kMetricsBlockSize threads (G = 1 up to kMetricsOneBlockBodies bodies,
// else kMetricsBlocks); thread t of block g accumulates elements gB + t, gB + t + GB, ...
// in order, then a fixed shared-memory tree combines the threads of a block; with G > 1
// a second one-block pass combines the G partial results in the same tree. Same n, same
// order:
// the doubles are reproducible run to run (they may differ from the CPU's sequential sums
// in the last bits, which design.md section 11 allows; the float32 state never depends on them).
#include "kernels.hpp"
#include "metrics.cuh"

namespace octocd {
namespace gpu {
namespace {

using metrics::Acc;
using metrics::block_combine;
using metrics::from_result;
using metrics::to_result;

/// First pass: block g of G writes *d.out (G == 1) or d.partials[g] (metrics.cuh).
__global__ void metrics_kernel(MetricsDesc d) {
  __shared__ Acc s[kMetricsBlockSize];
  metrics::metrics_block(d, s, blockIdx.x, gridDim.x, gridDim.x == 1 ? d.out : d.partials + blockIdx.x);
}

/// Second pass (G > 1): one block combines the G partial results.
__global__ void metrics_final_kernel(MetricsDesc d, std::uint32_t blocks) {
  __shared__ Acc s[kMetricsBlockSize];
  for (std::uint32_t t = threadIdx.x; t < kMetricsBlockSize; t += blockDim.x)
    s[t] = t < blocks ? from_result(d.partials[t]) : Acc{0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0ull, 0ull, d.n};
  block_combine(s);
  if (threadIdx.x == 0) *d.out = to_result(s[0]);
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
