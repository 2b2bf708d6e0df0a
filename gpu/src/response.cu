// Response on the device (SPEC 6), the same Jacobi pass World::step runs:
// - contact entries: each confirmed contact k contributes (a, 2k) and (b, 2k + 1); a
//   stable sort by body (primitives.cu) keeps each body's entries in k order, which is
//   (a, b) order since the pairs are sorted; body_begin marks each body's segment;
// - per-contact terms: octocd::contact_terms on the world AABBs translated from the
//   current positions (the AABBs World uses: the Aabbs stage's on the first pass,
//   recomputed by the same translated() on later passes);
// - per body: dx and dv summed over its kept contacts, in that order, from zero, exactly
//   as World accumulates dx_sum / dv_sum (no float atomics), then apply_contact_sums
//   (the per-contact and per-body code is in response.cuh, which the fused small step of
//   small_step.cu calls too).
#include "kernels.hpp"
#include "response.cuh"

namespace octocd {
namespace gpu {
namespace {

__global__ void contact_entries_kernel(const Pair* pairs, const std::uint8_t* confirmed,
                                       const std::uint32_t* pair_count, std::uint32_t capacity, std::uint32_t n,
                                       std::uint32_t* keys, std::uint32_t* vals) {
  const std::uint32_t k = blockIdx.x * blockDim.x + threadIdx.x;
  if (k >= capacity) return;
  const bool c = k < live_count(pair_count, capacity) && confirmed[k] != 0;
  const Pair p = c ? pairs[k] : Pair{};
  keys[2 * k] = c ? p.a : n;
  keys[2 * k + 1] = c ? p.b : n;
  vals[2 * k] = 2 * k;
  vals[2 * k + 1] = 2 * k + 1;
}

__global__ void body_segments_kernel(const std::uint32_t* keys, std::uint32_t count, std::uint32_t n,
                                     std::uint32_t* body_begin) {
  const std::uint32_t i = blockIdx.x * blockDim.x + threadIdx.x;
  if (i > n) return;
  // Lower bound of i in the sorted keys.
  std::uint32_t lo = 0, hi = count;
  while (lo < hi) {
    const std::uint32_t mid = lo + (hi - lo) / 2;
    if (keys[mid] < i) lo = mid + 1;
    else hi = mid;
  }
  body_begin[i] = lo;
}

__global__ void contact_terms_kernel(TermsDesc d) {
  const std::uint32_t k = blockIdx.x * blockDim.x + threadIdx.x;
  if (k >= d.pair_capacity || k >= live_count(d.pair_count, d.pair_capacity)) return;
  contact_terms_at(d, k);
}

__global__ void apply_sums_kernel(ApplyDesc d) {
  const std::uint32_t i = blockIdx.x * blockDim.x + threadIdx.x;
  if (i >= d.n) return;
  if (d.w[i] == 0.0f) return;
  ContactSums sums;
  const std::uint32_t end = d.body_begin[i + 1];
  for (std::uint32_t e = d.body_begin[i]; e < end; ++e) {
    const std::uint32_t entry = d.entries[e];
    sums.add(d, entry >> 1, (entry & 1u) != 0);
  }
  sums.apply(d, i);
}

}  // namespace

cudaError_t launch_contact_entries(const Pair* pairs, const std::uint8_t* confirmed, const std::uint32_t* pair_count,
                                   std::uint32_t pair_capacity, std::uint32_t n, std::uint32_t* keys,
                                   std::uint32_t* vals, cudaStream_t stream) {
  if (pair_capacity == 0) return cudaSuccess;
  contact_entries_kernel<<<grid_for(pair_capacity), kBlockSize, 0, stream>>>(pairs, confirmed, pair_count,
                                                                             pair_capacity, n, keys, vals);
  return cudaGetLastError();
}

cudaError_t launch_body_segments(const std::uint32_t* sorted_keys, std::uint32_t entry_count, std::uint32_t n,
                                 std::uint32_t* body_begin, cudaStream_t stream) {
  body_segments_kernel<<<grid_for(static_cast<std::size_t>(n) + 1), kBlockSize, 0, stream>>>(
      sorted_keys, entry_count, n, body_begin);
  return cudaGetLastError();
}

cudaError_t launch_contact_terms(const TermsDesc& d, cudaStream_t stream) {
  if (d.pair_capacity == 0) return cudaSuccess;
  contact_terms_kernel<<<grid_for(d.pair_capacity), kBlockSize, 0, stream>>>(d);
  return cudaGetLastError();
}

cudaError_t launch_apply_sums(const ApplyDesc& d, cudaStream_t stream) {
  if (d.n == 0) return cudaSuccess;
  apply_sums_kernel<<<grid_for(d.n), kBlockSize, 0, stream>>>(d);
  return cudaGetLastError();
}

}  // namespace gpu
}  // namespace octocd
