// Device-to-device copy bandwidth (the reference for "achieved memory throughput as a
// share of the measured copy bandwidth", issue 8 item 5): cudaMemcpyAsync of a buffer
// into another, timed with CUDA events, median of 20 after 3 warm-up copies. A copy
// reads and writes every byte, so the bandwidth counted is 2 x bytes / time.
// Usage: bench_copy_bandwidth [MiB (default 1024)]. Prints one line of JSON.
#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <vector>

#include <cuda_runtime.h>

namespace {
void check(cudaError_t e, const char* what) {
  if (e != cudaSuccess) {
    std::fprintf(stderr, "bench_copy_bandwidth: %s: %s\n", what, cudaGetErrorString(e));
    std::exit(1);
  }
}
}  // namespace

int main(int argc, char** argv) {
  const double mib = argc > 1 ? std::atof(argv[1]) : 1024.0;
  if (!(mib >= 1.0 && mib <= 65536.0)) {
    std::fprintf(stderr, "bench_copy_bandwidth: MiB must be in [1, 65536], got %s\n", argv[1]);
    return 2;
  }
  const std::size_t bytes = static_cast<std::size_t>(mib * 1048576.0);
  cudaDeviceProp prop{};
  check(cudaGetDeviceProperties(&prop, 0), "cudaGetDeviceProperties");
  void* a = nullptr;
  void* b = nullptr;
  check(cudaMalloc(&a, bytes), "cudaMalloc");
  check(cudaMalloc(&b, bytes), "cudaMalloc");
  check(cudaMemset(a, 1, bytes), "cudaMemset");
  cudaEvent_t t0, t1;
  check(cudaEventCreate(&t0), "cudaEventCreate");
  check(cudaEventCreate(&t1), "cudaEventCreate");
  std::vector<float> ms;
  for (int r = 0; r < 23; ++r) {
    check(cudaEventRecord(t0), "cudaEventRecord");
    check(cudaMemcpyAsync(b, a, bytes, cudaMemcpyDeviceToDevice), "cudaMemcpyAsync");
    check(cudaEventRecord(t1), "cudaEventRecord");
    check(cudaEventSynchronize(t1), "cudaEventSynchronize");
    float m = 0.0f;
    check(cudaEventElapsedTime(&m, t0, t1), "cudaEventElapsedTime");
    if (r >= 3) ms.push_back(m);
  }
  std::sort(ms.begin(), ms.end());
  const double med = ms[ms.size() / 2];
  std::printf("{\"device\": \"%s\", \"bytes\": %zu, \"median_ms\": %.4f, \"copy_bandwidth_GBps\": %.1f}\n", prop.name,
              bytes, med, 2.0 * static_cast<double>(bytes) / (med * 1e-3) / 1e9);
  return 0;
}
