// Device-wide primitives from CCCL's CUB (shipped with the CUDA toolkit): the exclusive
// scan of the counting passes and the stable radix sort of the body-major contact index.
#include <cub/device/device_radix_sort.cuh>
#include <cub/device/device_scan.cuh>

#include "kernels.hpp"

namespace octocd {
namespace gpu {

cudaError_t exclusive_scan_u32(void* temp, std::size_t& temp_bytes, const std::uint32_t* in, std::uint32_t* out,
                               std::uint32_t count, cudaStream_t stream) {
  return cub::DeviceScan::ExclusiveSum(temp, temp_bytes, in, out, static_cast<int>(count), stream);
}

cudaError_t sort_pairs_u32(void* temp, std::size_t& temp_bytes, const std::uint32_t* keys_in,
                           std::uint32_t* keys_out, const std::uint32_t* vals_in, std::uint32_t* vals_out,
                           std::uint32_t count, int end_bit, cudaStream_t stream) {
  return cub::DeviceRadixSort::SortPairs(temp, temp_bytes, keys_in, keys_out, vals_in, vals_out,
                                         static_cast<int>(count), 0, end_bit, stream);
}

}  // namespace gpu
}  // namespace octocd
