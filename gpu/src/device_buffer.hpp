#pragma once
/// \file device_buffer.hpp
/// Named device allocations for the CUDA engine's stages (cuda_world.cpp and the
/// broadphase classes): a buffer knows its name, element size and capacity, so an
/// out-of-memory error names the buffer and the bytes. Plain C++ over the CUDA runtime API.

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <initializer_list>
#include <string>
#include <vector>

#include <cuda_runtime_api.h>
#include <fmt/format.h>

#include "octocd/error.hpp"

namespace octocd {
namespace gpu {

/// "message (cudaErrorName)" for a CUDA error code.
inline std::string cuda_text(cudaError_t e) {
  return fmt::format("{} ({})", cudaGetErrorString(e), cudaGetErrorName(e));
}

/// Throws RuntimeError naming `what` when a CUDA runtime call failed.
inline void check(cudaError_t e, const char* what) {
  if (e != cudaSuccess) {
    (void)cudaGetLastError();  // clear a non-sticky error
    throw RuntimeError(fmt::format("CUDA error in {}: {}", what, cuda_text(e)));
  }
}

/// An untyped device allocation with a name (for errors) and a capacity in elements.
class BufferBase {
 public:
  BufferBase(const char* name, std::size_t elem_size) : name_(name), elem_size_(elem_size) {}
  virtual ~BufferBase() { release(); }
  BufferBase(const BufferBase&) = delete;
  BufferBase& operator=(const BufferBase&) = delete;

  /// Makes room for `count` elements (contents are lost when it grows): grows to
  /// max(count, 2 x capacity) so a growing scene reallocates rarely.
  void ensure(std::size_t count) {
    if (count <= cap_ && ptr_) return;
    allocate(std::max(count, 2 * cap_));
  }
  /// Frees the buffer and allocates exactly `count` elements (>= 1).
  void reset(std::size_t count) { allocate(std::max<std::size_t>(count, 1)); }
  /// Forgets the allocation without freeing it (cudaFree would wait for a kernel that never
  /// ends: CudaWorld after a hung resident kernel); the process's end reclaims it.
  void abandon() {
    ptr_ = nullptr;
    cap_ = 0;
  }
  std::size_t capacity() const { return cap_; }
  std::uint64_t bytes() const { return static_cast<std::uint64_t>(cap_) * elem_size_; }
  const char* name() const { return name_; }

 protected:
  void* ptr_ = nullptr;

 private:
  void allocate(std::size_t count) {
    release();
    count = std::max<std::size_t>(count, 1);
    const std::size_t bytes = count * elem_size_;
    void* p = nullptr;
    const cudaError_t e = cudaMalloc(&p, bytes);
    if (e != cudaSuccess) {
      (void)cudaGetLastError();
      throw RuntimeError(fmt::format("out of device memory: cudaMalloc of {} bytes ({:.1f} MiB) for the "
                                     "buffer '{}' failed: {}",
                                     bytes, static_cast<double>(bytes) / (1024.0 * 1024.0), name_, cuda_text(e)));
    }
    ptr_ = p;
    cap_ = count;
  }
  void release() {
    if (ptr_) (void)cudaFree(ptr_);
    ptr_ = nullptr;
    cap_ = 0;
  }

  const char* name_;
  std::size_t elem_size_;
  std::size_t cap_ = 0;
};

template <class T>
class DeviceBuffer : public BufferBase {
 public:
  explicit DeviceBuffer(const char* name) : BufferBase(name, sizeof(T)) {}
  T* get() const { return static_cast<T*>(ptr_); }
};

/// The device memory (bytes) the buffers of `buffers` hold together: BufferBase::bytes
/// summed over any range of BufferBase pointers.
template <class Range>
inline std::uint64_t total_bytes(const Range& buffers) {
  std::uint64_t total = 0;
  for (const BufferBase* b : buffers) total += b->bytes();
  return total;
}
/// total_bytes of a braced list of buffers: total_bytes({&a_, &b_}).
inline std::uint64_t total_bytes(std::initializer_list<const BufferBase*> buffers) {
  return total_bytes<std::initializer_list<const BufferBase*>>(buffers);
}

/// Copies a host vector into a device buffer on `stream` and waits for it. With
/// `allocate`, the buffer is first reallocated to the vector's size.
template <class T>
inline void upload(DeviceBuffer<T>& buf, const std::vector<T>& host, cudaStream_t stream, bool allocate = true) {
  if (allocate) buf.reset(host.size());
  if (host.empty()) return;
  check(cudaMemcpyAsync(buf.get(), host.data(), host.size() * sizeof(T), cudaMemcpyHostToDevice, stream),
        fmt::format("cudaMemcpy to '{}'", buf.name()).c_str());
  check(cudaStreamSynchronize(stream), "cudaStreamSynchronize");
}

template <class T>
inline void download(std::vector<T>& host, const DeviceBuffer<T>& buf, std::size_t count, cudaStream_t stream) {
  host.resize(count);
  if (count == 0) return;
  check(cudaMemcpyAsync(host.data(), buf.get(), count * sizeof(T), cudaMemcpyDeviceToHost, stream),
        fmt::format("cudaMemcpy from '{}'", buf.name()).c_str());
  check(cudaStreamSynchronize(stream), "cudaStreamSynchronize");
}

}  // namespace gpu
}  // namespace octocd
