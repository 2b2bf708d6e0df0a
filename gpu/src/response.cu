// Response on the device (SPEC 6), the same Jacobi pass World::step runs:
// - contact entries: each confirmed contact k contributes (a, 2k) and (b, 2k + 1); a
//   stable sort by body (primitives.cu) keeps each body's entries in k order, which is
//   (a, b) order since the pairs are sorted; body_begin marks each body's segment;
// - per-contact terms: octocd::contact_terms on the world AABBs translated from the
//   current positions (the AABBs World uses: the Aabbs stage's on the first pass,
//   recomputed by the same translated() on later passes);
// - per body: dx and dv summed over its kept contacts, in that order, from zero, exactly
//   as World accumulates dx_sum / dv_sum (no float atomics), then apply_contact_sums.
#include "kernels.hpp"

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
  if (!d.confirmed[k]) {
    d.hit[k] = 0;
    if (d.depth0) d.depth0[k] = -1.0f;
    if (d.records) d.records[k].hit = 0;
    return;
  }
  const Pair p = d.pairs[k];
  const float wa = d.w[p.a], wb = d.w[p.b];
  const Vec3 va = d.v[p.a], vb = d.v[p.b];
  const Aabb box_a = translated(d.local[p.a], d.x[p.a]);
  const Aabb box_b = translated(d.local[p.b], d.x[p.b]);
  const ContactTerms t = contact_terms(box_a, box_b, va, vb, wa, wb, d.params);
  d.hit[k] = t.pen.hit ? 1 : 0;
  if (d.depth0) d.depth0[k] = t.pen.hit ? t.pen.depth : -1.0f;
  if (d.records) {
    DeviceContact r;
    r.hit = t.pen.hit ? 1u : 0u;
    r.axis = t.pen.axis;
    r.depth = t.pen.depth;
    r.jn = t.imp.jn;
    r.jt = t.imp.jt;
    r.normal = t.pen.normal;
    r.v_a = va;
    r.v_b = vb;
    r.dx_a = t.dx_a;
    r.dx_b = t.dx_b;
    r.dv_a = t.imp.dv_a;
    r.dv_b = t.imp.dv_b;
    d.records[k] = r;
  }
  if (!t.pen.hit) return;  // Eq. 9: discarded
  d.dx_a[k] = t.dx_a;
  d.dx_b[k] = t.dx_b;
  d.dv_a[k] = t.imp.dv_a;
  d.dv_b[k] = t.imp.dv_b;
}

__global__ void apply_sums_kernel(ApplyDesc d) {
  const std::uint32_t i = blockIdx.x * blockDim.x + threadIdx.x;
  if (i >= d.n) return;
  if (d.w[i] == 0.0f) return;
  Vec3 dx_sum{};
  Vec3 dv_sum{};
  unsigned count = 0;
  const std::uint32_t end = d.body_begin[i + 1];
  for (std::uint32_t e = d.body_begin[i]; e < end; ++e) {
    const std::uint32_t entry = d.entries[e];
    const std::uint32_t k = entry >> 1;
    if (!d.hit[k]) continue;
    if ((entry & 1u) == 0) {
      dx_sum += d.dx_a[k];
      dv_sum += d.dv_a[k];
    } else {
      dx_sum += d.dx_b[k];
      dv_sum += d.dv_b[k];
    }
    ++count;
  }
  Vec3 x = d.x[i];
  Vec3 v = d.v[i];
  apply_contact_sums(x, v, dx_sum, dv_sum, count);
  d.x[i] = x;
  d.v[i] = v;
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
