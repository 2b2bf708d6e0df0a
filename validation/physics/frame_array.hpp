#pragma once
/// \file frame_array.hpp
/// A fixed number of elements built and destroyed on threads (parallel_items): a checked
/// frame's truth (CheckedFrame::truth) holds one entry of ~100 bytes per pair, 10^5 - 10^6
/// of them, and its row figures one per contact row, whose fresh pages a std::vector's
/// resize touches on one thread. Elements without a destructor are not visited when the
/// array is freed. assign() rebuilds an array in the memory it holds (a checked frame's
/// tables kept frame to frame). Internal to validation/physics.

#include <cstddef>
#include <functional>
#include <memory>
#include <new>
#include <type_traits>
#include <utility>

#include "../src/parallel.hpp"

namespace octocd::physics_detail {

template <class T>
class FrameArray {
  static_assert(std::is_nothrow_default_constructible_v<T> && std::is_nothrow_destructible_v<T>,
                "built and destroyed on threads that cannot stop halfway");

 public:
  FrameArray() = default;
  /// `n` value-initialised elements, built on `threads` threads (0: the hardware's), which
  /// also destroy them.
  FrameArray(std::size_t n, int threads) { assign(n, threads); }
  FrameArray(FrameArray&& o) noexcept
      : data_(std::exchange(o.data_, nullptr)),
        size_(std::exchange(o.size_, 0)),
        capacity_(std::exchange(o.capacity_, 0)),
        threads_(o.threads_) {}
  FrameArray& operator=(FrameArray&& o) noexcept {
    if (this != &o) {
      release();
      data_ = std::exchange(o.data_, nullptr);
      size_ = std::exchange(o.size_, 0);
      capacity_ = std::exchange(o.capacity_, 0);
      threads_ = o.threads_;
    }
    return *this;
  }
  /// `n` value-initialised elements, as the constructor makes them, in the memory this
  /// array already holds when it holds room for `n` (a checked frame's tables reused frame
  /// to frame: their pages are not faulted in and freed again each frame), else in a new
  /// allocation. Throws std::bad_alloc only.
  void assign(std::size_t n, int threads) {
    destroy();
    threads_ = threads;
    if (n > capacity_) {
      release();
      data_ = std::allocator<T>().allocate(n);
      capacity_ = n;
    }
    if (n == 0) return;
    size_ = n;
    T* data = data_;
    parallel_items(n, threads_, std::function<bool()>(), [data](std::size_t i, unsigned) { ::new (static_cast<void*>(data + i)) T(); });
  }
  FrameArray(const FrameArray&) = delete;
  FrameArray& operator=(const FrameArray&) = delete;
  ~FrameArray() { release(); }

  std::size_t size() const { return size_; }
  T& operator[](std::size_t i) { return data_[i]; }
  const T& operator[](std::size_t i) const { return data_[i]; }

 private:
  /// Destroys the elements, keeping the memory.
  void destroy() noexcept {
    T* data = data_;
    if constexpr (!std::is_trivially_destructible_v<T>)
      if (size_) parallel_items(size_, threads_, std::function<bool()>(), [data](std::size_t i, unsigned) { data[i].~T(); });
    size_ = 0;
  }
  void release() noexcept {
    destroy();
    if (!data_) return;
    std::allocator<T>().deallocate(data_, capacity_);
    data_ = nullptr;
    capacity_ = 0;
  }

  T* data_ = nullptr;
  std::size_t size_ = 0, capacity_ = 0;
  int threads_ = 0;
};

}  // namespace octocd::physics_detail
