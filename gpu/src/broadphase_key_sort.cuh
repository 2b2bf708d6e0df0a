#pragma once
// The sort by key that the sorting device broadphases share (broadphase_lbvh.cu,
// broadphase_octree_tree.cu, broadphase_octree_strict.cu, broadphase_spatial_hash.cu): its
// buffers, their sizes, the descriptor fields that point into them, and the CUB radix sort
// of (key, item) pairs into slot order. CUDA only (nvcc).
#include <algorithm>
#include <cstddef>
#include <cstdint>

#include <cub/device/device_radix_sort.cuh>

#include "device_buffer.hpp"
#include "kernels.hpp"

namespace octocd {
namespace gpu {
namespace bp {

/// A broadphase's items (bodies, or the spatial hash's cell entries) sorted by key, as named
/// device buffers: per item its key and index (`key`, `body`: the sort's input, which the
/// broadphase's keys kernel writes), per slot the sorted key and item (`sorted_key`,
/// `slot_body`: the sort's output, stable: equal keys in item order), and per slot the
/// item's box (`slot_box`) for the broadphases that gather them (sized only for those).
/// `Key`: std::uint32_t or unsigned long long. Owns its buffers; not copyable.
template <class Key>
struct KeySortBuffers {
  DeviceBuffer<Key> key;
  DeviceBuffer<std::uint32_t> body;
  DeviceBuffer<Key> sorted_key;
  DeviceBuffer<std::uint32_t> slot_body;
  DeviceBuffer<Aabb> slot_box;

  /// The buffers' names (for out-of-memory errors), in member order; string literals.
  KeySortBuffers(const char* key_name, const char* body_name, const char* sorted_key_name,
                 const char* slot_body_name, const char* slot_box_name)
      : key(key_name), body(body_name), sorted_key(sorted_key_name), slot_body(slot_body_name),
        slot_box(slot_box_name) {}

  /// Makes room for `items` items (DeviceBuffer::ensure), and for their slot boxes when
  /// `boxes`.
  void ensure(std::size_t items, bool boxes) {
    key.ensure(items);
    body.ensure(items);
    sorted_key.ensure(items);
    slot_body.ensure(items);
    if (boxes) slot_box.ensure(items);
  }

  /// Sets a descriptor's `d.key`, `d.body`, `d.sorted_key` and `d.slot_body` to the buffers.
  template <class Desc>
  void set(Desc& d) const {
    d.key = key.get();
    d.body = body.get();
    d.sorted_key = sorted_key.get();
    d.slot_body = slot_body.get();
  }

  /// set() and the slots' boxes (`d.slot_box`).
  template <class Desc>
  void set_with_boxes(Desc& d) const {
    set(d);
    d.slot_box = slot_box.get();
  }

  /// cub::DeviceRadixSort::SortPairs of the first `items` (key, body) pairs into
  /// (sorted_key, slot_body) over key bits [0, end_bit), enqueued on `stream`, with `temp`
  /// of `bytes` bytes of temporary storage; with temp null it only sets `bytes` to the
  /// storage it needs. Returns CUB's error code.
  cudaError_t sort(void* temp, std::size_t& bytes, std::uint32_t items, int end_bit, cudaStream_t stream) const {
    return cub::DeviceRadixSort::SortPairs(temp, bytes, key.get(), sorted_key.get(), body.get(), slot_body.get(),
                                           static_cast<int>(items), 0, end_bit, stream);
  }

  /// Grows `bytes` to the temporary storage sort() needs for `items` items; a failed size
  /// query throws RuntimeError (check).
  void need_temp(std::size_t& bytes, std::uint32_t items, int end_bit, cudaStream_t stream) const {
    std::size_t b = 0;
    check(sort(nullptr, b, items, end_bit, stream), "cub::DeviceRadixSort::SortPairs (size)");
    bytes = std::max(bytes, b);
  }

  /// The device memory the buffers hold (bytes).
  std::uint64_t bytes() const { return total_bytes({&key, &body, &sorted_key, &slot_body, &slot_box}); }
};

}  // namespace bp
}  // namespace gpu
}  // namespace octocd
