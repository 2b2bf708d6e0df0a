// Device-wide primitives from CCCL's CUB (shipped with the CUDA toolkit): the exclusive
// scans of the counting passes (the contact index's too), the radix sort of the pair keys,
// a minimum (the loose octree's auto depth) and sums (the strict octree's auto depth). The
// sorting broadphases' key sorts: bp::KeySortBuffers (broadphase_key_sort.cuh).
#include <cub/device/device_radix_sort.cuh>
#include <cub/device/device_reduce.cuh>
#include <cub/device/device_scan.cuh>

#include "kernels.hpp"

namespace octocd {
namespace gpu {

cudaError_t exclusive_scan_u32(void* temp, std::size_t& temp_bytes, const std::uint32_t* in, std::uint32_t* out,
                               std::uint32_t count, cudaStream_t stream) {
  return cub::DeviceScan::ExclusiveSum(temp, temp_bytes, in, out, static_cast<int>(count), stream);
}

cudaError_t exclusive_scan_u64(void* temp, std::size_t& temp_bytes, const unsigned long long* in,
                               unsigned long long* out, std::uint32_t count, cudaStream_t stream) {
  return cub::DeviceScan::ExclusiveSum(temp, temp_bytes, in, out, static_cast<int>(count), stream);
}

cudaError_t sort_keys_u64(void* temp, std::size_t& temp_bytes, const unsigned long long* keys_in,
                          unsigned long long* keys_out, std::uint32_t count, int end_bit, cudaStream_t stream) {
  return cub::DeviceRadixSort::SortKeys(temp, temp_bytes, keys_in, keys_out, static_cast<int>(count), 0, end_bit,
                                        stream);
}

cudaError_t min_f32(void* temp, std::size_t& temp_bytes, const float* in, float* out, std::uint32_t count,
                    cudaStream_t stream) {
  return cub::DeviceReduce::Min(temp, temp_bytes, in, out, static_cast<int>(count), stream);
}

cudaError_t sum_f64(void* temp, std::size_t& temp_bytes, const double* in, double* out, std::uint32_t count,
                    cudaStream_t stream) {
  return cub::DeviceReduce::Sum(temp, temp_bytes, in, out, static_cast<int>(count), stream);
}

cudaError_t sum_u32(void* temp, std::size_t& temp_bytes, const std::uint32_t* in, std::uint32_t* out,
                    std::uint32_t count, cudaStream_t stream) {
  return cub::DeviceReduce::Sum(temp, temp_bytes, in, out, static_cast<int>(count), stream);
}

}  // namespace gpu
}  // namespace octocd
