#pragma once
/// \file scanned_counts.hpp
/// Per-item counts and their exclusive scan, as the counting passes of the cuda engine keep
/// them (the flat broadphase, the small step's in-lists, the strict octree's and the spatial
/// hash's pair counts, the spatial hash's cell counts, the octree's pair segments). Plain
/// C++ over the CUDA runtime API and primitives.cu.
#include <algorithm>
#include <cstddef>
#include <cstdint>

#include <cuda_runtime_api.h>

#include "device_buffer.hpp"
#include "kernels.hpp"

namespace octocd {
namespace gpu {

/// Per item a count and its offset (the exclusive scan of the counts), as named device
/// buffers of `items` entries each: a counting pass writes `count`, scan() writes `offset`;
/// with the last count 0 the last offset is the total. Owns its buffers; not copyable.
struct ScannedCounts {
  DeviceBuffer<std::uint32_t> count;
  DeviceBuffer<std::uint32_t> offset;

  /// The buffers' names (for out-of-memory errors); string literals.
  ScannedCounts(const char* count_name, const char* offset_name) : count(count_name), offset(offset_name) {}

  /// Makes room for `items` counts and offsets (DeviceBuffer::ensure).
  void ensure(std::size_t items) {
    count.ensure(items);
    offset.ensure(items);
  }

  /// exclusive_scan_u32 of the first `items` counts into the offsets, enqueued on `stream`,
  /// with `temp` of `bytes` bytes of temporary storage; with temp null it only sets `bytes`.
  /// Returns CUB's error code.
  cudaError_t scan(void* temp, std::size_t& bytes, std::uint32_t items, cudaStream_t stream) const {
    return exclusive_scan_u32(temp, bytes, count.get(), offset.get(), items, stream);
  }

  /// Grows `bytes` to the temporary storage scan() needs for `items` counts; a failed size
  /// query throws RuntimeError (check).
  void need_temp(std::size_t& bytes, std::uint32_t items, cudaStream_t stream) const {
    std::size_t b = 0;
    check(scan(nullptr, b, items, stream), "cub::DeviceScan::ExclusiveSum (size)");
    bytes = std::max(bytes, b);
  }

  /// Enqueues on `stream` the copy of offset[last] (the total when count[last] is 0) into the
  /// device word *total. Returns the CUDA error code.
  cudaError_t copy_total(std::uint32_t* total, std::uint32_t last, cudaStream_t stream) const {
    return cudaMemcpyAsync(total, offset.get() + last, sizeof(std::uint32_t), cudaMemcpyDeviceToDevice, stream);
  }

  /// The device memory the two buffers hold (bytes).
  std::uint64_t bytes() const { return total_bytes({&count, &offset}); }
};

}  // namespace gpu
}  // namespace octocd
