// Response on the device (design.md section 6), the same Jacobi pass World::step runs:
// - contact index: body i's confirmed contacts in k order are its pairs (a, i), a < i,
//   then its pairs (i, b), since the pairs are sorted by (a, b). The second are a run of
//   the candidate pairs; the first are the b-side entries of i. One 64-bit count per body
//   holds both (a-side pairs high, b-side entries low: index_count, integer atomics), one
//   in-place exclusive scan turns the counts into both offsets, index_fill puts each entry
//   at its body's offset plus its atomic rank (an order that varies run to run), and the
//   segments are then sorted by k: up to kIndexShortSegment entries by the body's own
//   thread in the first apply pass, longer ones (listed by index_count) by a block that
//   scans the pairs in order (index_long). Only dynamic bodies get b-side entries (apply_sums
//   skips static ones);
// - per-contact terms: octocd::contact_terms on the world AABBs translated from the
//   current positions (the AABBs World uses: the Aabbs stage's on the first pass,
//   recomputed by the same translated() on later passes);
// - per body: dx and dv summed over its kept contacts, in that order, from zero, exactly
//   as World accumulates dx_sum / dv_sum (no float atomics), then apply_contact_sums
//   (the per-contact and per-body code is in response.cuh, which the fused small step of
//   small_step.cu calls too); the last pass clamps too (Eq. 23).
#include "kernels.hpp"
#include "response.cuh"

namespace octocd {
namespace gpu {
namespace {

constexpr unsigned long long kASide = 1ull << 32;

__device__ inline std::uint32_t lo32(unsigned long long v) { return static_cast<std::uint32_t>(v); }
__device__ inline std::uint32_t hi32(unsigned long long v) { return static_cast<std::uint32_t>(v >> 32); }

/// Whether live pair k is a b-side entry: confirmed, with a dynamic b.
__device__ inline bool b_entry(const IndexDesc& d, std::uint32_t k, const Pair& p) {
  return d.confirmed[k] != 0 && d.w[p.b] != 0.0f;
}

__global__ void index_count_kernel(IndexDesc d) {
  const std::uint32_t live = live_count(d.pair_count, d.capacity);
  for (std::uint32_t k = blockIdx.x * blockDim.x + threadIdx.x; k < live; k += gridDim.x * blockDim.x) {
    const Pair p = d.pairs[k];
    atomicAdd(&d.offsets[p.a], kASide);
    if (!b_entry(d, k, p)) continue;
    const std::uint32_t rank = lo32(atomicAdd(&d.offsets[p.b], 1ull));
    d.rank[k] = rank;
    if (rank == kIndexShortSegment) d.long_list[atomicAdd(d.long_count, 1u)] = p.b;
  }
}

__global__ void index_fill_kernel(IndexDesc d) {
  const std::uint32_t live = live_count(d.pair_count, d.capacity);
  for (std::uint32_t k = blockIdx.x * blockDim.x + threadIdx.x; k < live; k += gridDim.x * blockDim.x) {
    const Pair p = d.pairs[k];
    if (b_entry(d, k, p)) d.entries[lo32(d.offsets[p.b]) + d.rank[k]] = k;
  }
}

/// A block per listed body i: the live pairs in order, 32 per warp and kBlockSize per
/// round; each pair (a, i) that is an entry goes to the next place of i's segment.
__global__ void index_long_kernel(IndexDesc d) {
  __shared__ std::uint32_t warp_hits[kBlockSize / 32];
  __shared__ std::uint32_t round_base;
  const std::uint32_t live = live_count(d.pair_count, d.capacity);
  const std::uint32_t lane = threadIdx.x & 31u;
  const std::uint32_t warp = threadIdx.x >> 5;
  const std::uint32_t listed = *d.long_count;
  for (std::uint32_t j = blockIdx.x; j < listed; j += gridDim.x) {
    const std::uint32_t i = d.long_list[j];
    const std::uint32_t begin = lo32(d.offsets[i]);
    if (threadIdx.x == 0) round_base = 0;
    __syncthreads();
    for (std::uint32_t k0 = 0; k0 < live; k0 += blockDim.x) {
      const std::uint32_t k = k0 + threadIdx.x;
      bool hit = false;
      if (k < live) {
        const Pair p = d.pairs[k];
        hit = p.b == i && b_entry(d, k, p);
      }
      const unsigned mask = __ballot_sync(0xffffffffu, hit);
      if (lane == 0) warp_hits[warp] = static_cast<std::uint32_t>(__popc(mask));
      __syncthreads();
      std::uint32_t before = round_base;
      for (std::uint32_t w = 0; w < warp; ++w) before += warp_hits[w];
      if (hit) d.entries[begin + before + static_cast<std::uint32_t>(__popc(mask & ((1u << lane) - 1u)))] = k;
      __syncthreads();  // every thread has read round_base and warp_hits
      if (threadIdx.x == 0)
        for (std::uint32_t w = 0; w < blockDim.x / 32; ++w) round_base += warp_hits[w];
      __syncthreads();
    }
  }
}

__global__ void contact_terms_kernel(TermsDesc d) {
  const std::uint32_t live = live_count(d.pair_count, d.pair_capacity);
  for (std::uint32_t k = blockIdx.x * blockDim.x + threadIdx.x; k < live; k += gridDim.x * blockDim.x)
    contact_terms_at(d, k);
}

__global__ void apply_sums_kernel(ApplyDesc d) {
  const std::uint32_t i = blockIdx.x * blockDim.x + threadIdx.x;
  if (i >= d.n) return;
  if (d.w[i] == 0.0f) return;
  const unsigned long long o0 = d.offsets[i];
  const unsigned long long o1 = d.offsets[i + 1];
  const std::uint32_t e0 = lo32(o0), e1 = lo32(o1);
  if (d.sort_entries && e1 - e0 >= 2 && e1 - e0 <= kIndexShortSegment) {
    // Insertion sort of the segment by k (distinct values), in place.
    for (std::uint32_t e = e0 + 1; e < e1; ++e) {
      const std::uint32_t k = d.entries[e];
      std::uint32_t f = e;
      for (; f > e0 && d.entries[f - 1] > k; --f) d.entries[f] = d.entries[f - 1];
      d.entries[f] = k;
    }
  }
  ContactSums sums;
  for (std::uint32_t e = e0; e < e1; ++e) sums.add(d, d.entries[e], true);
  const std::uint32_t k1 = hi32(o1);
  for (std::uint32_t k = hi32(o0); k < k1; ++k) sums.add(d, k, false);
  sums.apply(d, i);
}

}  // namespace

cudaError_t launch_index_count(const IndexDesc& d, unsigned grid, cudaStream_t stream) {
  return launch_when(d.capacity != 0, index_count_kernel, d, grid, stream);
}

cudaError_t launch_index_fill(const IndexDesc& d, unsigned grid, cudaStream_t stream) {
  return launch_when(d.capacity != 0, index_fill_kernel, d, grid, stream);
}

cudaError_t launch_index_long(const IndexDesc& d, unsigned grid, cudaStream_t stream) {
  return launch_when(d.capacity != 0, index_long_kernel, d, grid, stream);
}

cudaError_t launch_contact_terms(const TermsDesc& d, unsigned grid, cudaStream_t stream) {
  return launch_when(d.pair_capacity != 0, contact_terms_kernel, d, grid, stream);
}

cudaError_t launch_apply_sums(const ApplyDesc& d, cudaStream_t stream) {
  return launch_when(d.n != 0, apply_sums_kernel, d, grid_for(d.n), stream);
}

}  // namespace gpu
}  // namespace octocd
