// Broadphase `octree` on the device with a pair cache across calls (temporal coherence):
// the CPU octree's step 6 (core/src/broadphase_octree_cache.cpp, the "fat AABB" idea of
// Bullet's dbvt; a Verlet list in molecular dynamics) over the one-shot device `octree`
// (broadphase_octree_tree.cu). The host decides each call's plan (coherent_plan.hpp):
// - Plain: the one-shot `octree` on the AABBs (the first call; backing off after a cache
//   that served no call);
// - Build: d = margin_fraction x the median largest side of at most 1023 bodies spaced
//   evenly in body order (one block: a block radix sort of the sample), as the CPU's
//   fatten(); every AABB grown by d on every side (a NaN box stays NaN); the one-shot
//   `octree` on the fattened boxes, in its sorted mode, into the cache (keys ascending,
//   the entries after its total all ones); then the filter;
// - Hit: one thread per body checks that its AABB lies inside its fattened box
//   (inclusive; a box with a NaN coordinate overlaps nothing and never counts as escaped),
//   counts those that do not and keeps the smallest slack of a side (the predictor's
//   input); then the filter.
// The filter: a flag per cache key (coherent_flag_kernel: one thread per key, set for a key
// below the cache's total whose AABBs overlap, Eq. 6), then cub::DeviceSelect::Flagged
// keeps the flagged keys in the cache's ascending order, into the output (straight when
// the cache fits the output's capacity, else through a buffer of the cache's size and a
// copy of the first min(total, capacity) keys). Exact: when every AABB lies in its fattened box, two
// overlapping AABBs have overlapping fattened boxes, so their pair is kept; a Hit that
// found an escaped body says so (settle(): Rerun) and the caller runs find() again, then
// a Build. The output is the sorted unique set `flat` gives, the order the CPU octree's
// cache gives too (its kept pairs are sorted, filtered in order).
//
// exact tests (candidates): Plain, the tree's; Build, the tree's on the fattened boxes
// plus the kept pairs; Hit, the kept pairs (the CPU octree's cell_candidates likewise).
#include <algorithm>
#include <initializer_list>
#include <string>

#include <cub/block/block_radix_sort.cuh>
#include <cub/block/block_reduce.cuh>
#include <cub/device/device_select.cuh>
#include <thrust/iterator/transform_iterator.h>
#include <cuda/functional>
#include <fmt/format.h>

#include "broadphase_common.cuh"
#include "coherent_plan.hpp"
#include "device_broadphase.hpp"
#include "device_buffer.hpp"
#include "device_footprint.hpp"
#include "kernels.hpp"
#include "octocd/error.hpp"
#include "octocd/loose_octree.hpp"

namespace octocd {
namespace gpu {
namespace {

static_assert(sizeof(CoherentStatus) == 16, "device_footprint.cpp counts the status as 16 bytes");

/// Bodies sampled (evenly spaced in body order) for the median size, as the CPU octree.
constexpr std::uint32_t kFatSample = 1023;
/// Sample entries per thread of the margin kernel's block radix sort (kBlockSize x 4 >=
/// kFatSample).
constexpr int kSampleItems = 4;
static_assert(kBlockSize * kSampleItems >= static_cast<int>(kFatSample), "margin sample");

/// Largest side of a box; 0 unless finite and > 0 (the CPU octree's largest_side).
__device__ inline float largest_side(const Aabb& b) {
  float ext = b.max.x - b.min.x;
  ext = ext > b.max.y - b.min.y ? ext : b.max.y - b.min.y;
  ext = ext > b.max.z - b.min.z ? ext : b.max.z - b.min.z;
  return (ext > 0.0f && ext <= 3.4e38f) ? ext : 0.0f;
}

/// One block: status->margin = fraction x the median (index count / 2 of the ascending
/// sizes) of the largest sides > 0 of bodies 0, stride, 2 stride, .. (stride = n / 1023 +
/// 1); 0 when none.
__global__ void __launch_bounds__(kBlockSize) coherent_margin_kernel(const Aabb* aabb, std::uint32_t n,
                                                                    float fraction, CoherentStatus* status) {
  using Sort = cub::BlockRadixSort<float, kBlockSize, kSampleItems>;
  using Reduce = cub::BlockReduce<std::uint32_t, kBlockSize>;
  __shared__ typename Sort::TempStorage sort_storage;
  __shared__ typename Reduce::TempStorage reduce_storage;
  const std::uint32_t stride = n / kFatSample + 1;
  float v[kSampleItems];
  std::uint32_t valid = 0;
  for (int k = 0; k < kSampleItems; ++k) {
    const std::uint64_t j = static_cast<std::uint64_t>(threadIdx.x) * kSampleItems + static_cast<std::uint64_t>(k);
    const std::uint64_t i = j * stride;
    float e = 0.0f;
    if (i < n) e = largest_side(aabb[i]);
    v[k] = e > 0.0f ? e : __int_as_float(0x7f800000);  // +inf: after every size
    valid += e > 0.0f ? 1u : 0u;
  }
  const std::uint32_t count = Reduce(reduce_storage).Sum(valid);
  __shared__ std::uint32_t shared_count;
  if (threadIdx.x == 0) shared_count = count;
  Sort(sort_storage).Sort(v);  // blocked: thread t holds ranks t x 4 .. t x 4 + 3
  __syncthreads();
  const std::uint32_t c = shared_count;
  const std::uint32_t mid = c / 2;
  const std::uint32_t first = threadIdx.x * kSampleItems;
  if (c == 0) {
    if (threadIdx.x == 0) status->margin = 0.0f;
  } else if (mid >= first && mid < first + kSampleItems) {
    status->margin = fraction * v[mid - first];
  }
}

/// Build: fat[i] = aabb[i] grown by status->margin on every side.
__global__ void coherent_fatten_kernel(const Aabb* aabb, std::uint32_t n, const CoherentStatus* status, Aabb* fat) {
  const std::uint32_t i = blockIdx.x * blockDim.x + threadIdx.x;
  if (i >= n) return;
  fat[i] = expanded(aabb[i], status->margin);
}

/// Build: the kept pairs are tested on the AABBs by the filter (candidates).
__global__ void coherent_count_kept_kernel(const CoherentStatus* status, unsigned long long* candidates) {
  atomicAdd(candidates, static_cast<unsigned long long>(status->cache_total));
}

/// Hit: per body, whether its AABB left its fattened box (not inside, inclusive, and no
/// NaN coordinate), counted into status->escaped; the smallest slack of a side of an
/// inside AABB to its fattened box into status->min_slack_bits (non-negative floats order
/// as their bits; a NaN slack, of an infinite side, is left out); the kept pairs counted
/// as exact tests.
__global__ void coherent_check_kernel(const Aabb* aabb, const Aabb* fat, std::uint32_t n, CoherentStatus* status,
                                      unsigned long long* candidates) {
  using Reduce = cub::BlockReduce<std::uint32_t, kBlockSize>;
  __shared__ typename Reduce::TempStorage storage;
  const std::uint32_t i = blockIdx.x * blockDim.x + threadIdx.x;
  std::uint32_t escaped = 0;
  std::uint32_t slack_bits = kNoSlack;
  if (i < n) {
    const Aabb b = aabb[i];
    const Aabb f = fat[i];
    const bool inside = b.min.x >= f.min.x && b.min.y >= f.min.y && b.min.z >= f.min.z && b.max.x <= f.max.x &&
                        b.max.y <= f.max.y && b.max.z <= f.max.z;
    if (!inside && !loose_has_nan(b)) escaped = 1;
    if (inside) {
      const float s = fminf(fminf(fminf(b.min.x - f.min.x, b.min.y - f.min.y), fminf(b.min.z - f.min.z, f.max.x - b.max.x)),
                            fminf(f.max.y - b.max.y, f.max.z - b.max.z));
      // fminf skips a NaN operand; all NaN gives NaN (left out).
      if (s == s) slack_bits = __float_as_uint(s > 0.0f ? s : 0.0f);
    }
  }
  const std::uint32_t block_escaped = Reduce(storage).Sum(escaped);
  __syncthreads();  // the storage is reused
  const std::uint32_t block_slack = Reduce(storage).Reduce(slack_bits, cuda::minimum<>{});
  if (threadIdx.x == 0) {
    if (block_escaped != 0) atomicAdd(&status->escaped, block_escaped);
    if (block_slack != kNoSlack) atomicMin(&status->min_slack_bits, block_slack);
    if (blockIdx.x == 0) atomicAdd(candidates, static_cast<unsigned long long>(status->cache_total));
  }
}

/// A cache key (a << 32) | b as the output's key (a << shift) | b; the all-ones padding
/// stays all ones (the order of the keys is the same at every shift).
struct Reshift {
  int shift;
  __host__ __device__ unsigned long long operator()(unsigned long long k) const {
    return k == ~0ull ? k : ((k >> 32) << shift) | (k & 0xffffffffull);
  }
};

/// The filter's flags: flags[i] = 1 for a cache key (a << 32) | b below the cache's total,
/// not the all-ones padding, whose AABBs overlap (Eq. 6), else 0; one thread per key of the
/// cache's capacity (the keys past the total are not read). A thread per key keeps every
/// key's two AABB loads in flight at once (the gathers dominate: 1.8 million kept pairs of
/// boxes-uniform-1m).
__global__ void coherent_flag_kernel(const unsigned long long* cache, const CoherentStatus* status, const Aabb* aabb,
                                     std::uint32_t capacity, std::uint8_t* flags) {
  const std::uint32_t i = blockIdx.x * blockDim.x + threadIdx.x;
  if (i >= capacity) return;
  std::uint8_t keep = 0;
  if (i < status->cache_total) {
    const unsigned long long k = cache[i];
    keep = k != ~0ull && overlaps(aabb[k >> 32], aabb[k & 0xffffffffull]) ? 1 : 0;
  }
  flags[i] = keep;
}

/// keys[i] = selected[i] for i < min(*total, capacity).
__global__ void coherent_copy_kernel(const unsigned long long* selected, const std::uint32_t* total,
                                     unsigned long long* keys, std::uint32_t capacity) {
  const std::uint32_t i = blockIdx.x * blockDim.x + threadIdx.x;
  if (i < capacity && i < *total) keys[i] = selected[i];
}

class CoherentOctreeDevice final : public DeviceBroadPhase {
 public:
  CoherentOctreeDevice(std::unique_ptr<DeviceBroadPhase> octree, float margin_fraction)
      : octree_(std::move(octree)), fraction_(margin_fraction) {}

  ~CoherentOctreeDevice() override {
    if (host_status_) (void)cudaFreeHost(host_status_);
  }

  std::string name() const override { return octree_->name(); }
  bool sorts_pairs() const override { return true; }
  int plan() const override { return static_cast<int>(current_plan()); }

  void reserve(std::uint32_t n, cudaStream_t stream) override {
    octree_->reserve(n, stream);
    if (n != n_) planner_.reset();
    if (!host_status_) {
      check(cudaMallocHost(reinterpret_cast<void**>(&host_status_), sizeof(CoherentStatus)),
            "cudaMallocHost (octree pair cache status)");
      *host_status_ = CoherentStatus{};
    }
    status_.ensure(1);
    fat_.ensure(n);
    const std::uint64_t want =
        std::max<std::uint64_t>(footprint::initial_pair_capacity(n), planner_.needed_capacity());
    if (want > 0x7fffffffu)
      throw RuntimeError(fmt::format("octree pair cache: {} fattened pairs; at most 2^31 - 1", want));
    cache_.ensure(want);
    cache_scratch_.ensure(want);
    selected_.ensure(want);
    flags_.ensure(want);
    cache_cap_ = static_cast<std::uint32_t>(std::min<std::size_t>({cache_.capacity(), cache_scratch_.capacity(),
                                                                  selected_.capacity(), flags_.capacity(),
                                                                  std::size_t{0x7fffffffu}}));
    std::size_t bytes = 0;
    check(cub::DeviceSelect::Flagged(nullptr, bytes, thrust::make_transform_iterator(cache_.get(), Reshift{32}),
                                     flags_.get(), selected_.get(), static_cast<std::uint32_t*>(nullptr),
                                     static_cast<int>(cache_cap_), stream),
          "cub::DeviceSelect::Flagged (size)");
    temp_.ensure(std::max<std::size_t>(bytes, 1));
    n_ = n;
  }

  void find(const Aabb* aabb, std::uint32_t n, const PairOutput& out, cudaStream_t stream) override {
    bp::check_reserved(n_ != kNotReserved, n_, n, broadphase_name(BroadPhaseId::octree));
    const CoherentPlan p = current_plan();
    if (p == CoherentPlan::Plain) {
      octree_->find(aabb, n, out, stream);
      return;
    }
    CoherentStatus* st = status_.get();
    if (p == CoherentPlan::Build) {
      coherent_margin_kernel<<<1, kBlockSize, 0, stream>>>(aabb, n, fraction_, st);
      bp::launched(cudaGetLastError(), "coherent_margin");
      coherent_fatten_kernel<<<grid_for(n), kBlockSize, 0, stream>>>(aabb, n, st, fat_.get());
      bp::launched(cudaGetLastError(), "coherent_fatten");
      check(cudaMemsetAsync(cache_.get(), 0xff, static_cast<std::size_t>(cache_cap_) * sizeof(unsigned long long),
                            stream),
            "cudaMemset octree pair cache");
      PairOutput fat_out;
      fat_out.keys = cache_.get();
      fat_out.scratch = cache_scratch_.get();
      fat_out.shift = 32;  // the cache's keys: (a << 32) | b, reshifted by the filter
      fat_out.capacity = cache_cap_;
      fat_out.total = &st->cache_total;
      fat_out.candidates = out.candidates;
      octree_->find(fat_.get(), n, fat_out, stream);
      coherent_count_kept_kernel<<<1, 1, 0, stream>>>(st, out.candidates);
      bp::launched(cudaGetLastError(), "coherent_count_kept");
    } else {
      check(cudaMemsetAsync(&st->escaped, 0, sizeof(std::uint32_t), stream), "cudaMemset octree escaped count");
      check(cudaMemsetAsync(&st->min_slack_bits, 0x7f, sizeof(std::uint32_t), stream), "cudaMemset octree slack");
      coherent_check_kernel<<<grid_for(n), kBlockSize, 0, stream>>>(aabb, fat_.get(), n, st, out.candidates);
      bp::launched(cudaGetLastError(), "coherent_check");
    }
    // The filter: the kept keys whose AABBs overlap, in order.
    coherent_flag_kernel<<<grid_for(cache_cap_), kBlockSize, 0, stream>>>(cache_.get(), st, aabb, cache_cap_,
                                                                          flags_.get());
    bp::launched(cudaGetLastError(), "coherent_flag");
    const bool direct = cache_cap_ <= out.capacity;
    std::size_t bytes = temp_.capacity();
    bp::launched(cub::DeviceSelect::Flagged(temp_.get(), bytes,
                                            thrust::make_transform_iterator(cache_.get(), Reshift{out.shift}),
                                            flags_.get(), direct ? out.keys : selected_.get(), out.total,
                                            static_cast<int>(cache_cap_), stream),
                 "cub::DeviceSelect::Flagged (octree pair cache)");
    if (!direct && out.capacity > 0) {
      coherent_copy_kernel<<<grid_for(out.capacity), kBlockSize, 0, stream>>>(selected_.get(), out.total, out.keys,
                                                                              out.capacity);
      bp::launched(cudaGetLastError(), "coherent_copy");
    }
    check(cudaMemcpyAsync(host_status_, st, sizeof(CoherentStatus), cudaMemcpyDeviceToHost, stream),
          "cudaMemcpy octree pair cache status");
  }

  /// The plan of the last find() (or of its captured graph's replay) is still current_plan():
  /// only settle() changes it.
  Settled settle() override {
    const CoherentPlan ran = current_plan();
    if (ran == CoherentPlan::Plain && n_ == 0) return Settled::Valid;
    return planner_.settle(ran, *host_status_, cache_cap_);
  }

  std::uint64_t device_bytes() const override {
    return octree_->device_bytes() +
           total_bytes({&status_, &fat_, &cache_, &cache_scratch_, &selected_, &flags_, &temp_});
  }

 private:
  /// The planner's plan; Plain for no body.
  CoherentPlan current_plan() const { return n_ == 0 || n_ == kNotReserved ? CoherentPlan::Plain : planner_.plan(); }

  static constexpr std::uint32_t kNotReserved = 0xffffffffu;
  std::unique_ptr<DeviceBroadPhase> octree_;  // the one-shot `octree`
  float fraction_;
  CoherencePlanner planner_;
  std::uint32_t n_ = kNotReserved;
  std::uint32_t cache_cap_ = 0;
  CoherentStatus* host_status_ = nullptr;  // pinned
  DeviceBuffer<CoherentStatus> status_{"octree pair cache status"};
  DeviceBuffer<Aabb> fat_{"octree fattened boxes"};
  DeviceBuffer<unsigned long long> cache_{"octree pair cache"};
  DeviceBuffer<unsigned long long> cache_scratch_{"octree pair cache scratch"};
  DeviceBuffer<unsigned long long> selected_{"octree pair cache selection"};
  DeviceBuffer<std::uint8_t> flags_{"octree pair cache filter flags"};
  DeviceBuffer<unsigned char> temp_{"octree pair cache CUB temporary storage"};
};

}  // namespace

std::unique_ptr<DeviceBroadPhase> make_device_coherent_octree(const BroadPhaseConfig& config, const Aabb& domain,
                                                              float margin_fraction) {
  if (!(margin_fraction >= 0.0f && margin_fraction <= 16.0f))
    throw InputError(fmt::format("octree pair cache: margin fraction {} is not allowed; allowed: 0 .. 16",
                                 margin_fraction));
  (void)make_broadphase(config, domain);  // the parameter checks of make_broadphase (InputError)
  return std::make_unique<CoherentOctreeDevice>(make_device_loose_octree(config, domain), margin_fraction);
}

std::unique_ptr<DeviceBroadPhase> make_device_broadphase_octree(const BroadPhaseConfig& config, const Aabb& domain,
                                                                DeviceUse use) {
  // The engine's steps keep the pair cache; one-shot calls run the loose octree alone.
  if (use == DeviceUse::Steps) return make_device_coherent_octree(config, domain);
  check_broadphase_parameters(config);
  return make_device_loose_octree(config, domain);
}

}  // namespace gpu
}  // namespace octocd
