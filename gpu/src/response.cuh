#pragma once
// Per-contact and per-body device code of the response (design.md section 6), shared by response.cu's
// kernels and the fused small-scene step (small_step.cu): the terms of one candidate pair
// (octocd::contact_terms) and a body's sequential reduction of its kept contacts' terms
// (no float atomics) followed by apply_contact_sums. The caller decides the order in which
// a body's contacts are added (the same order in both steps: (a, b) order). CUDA only.
#include "kernels.hpp"

namespace octocd {
namespace gpu {

/// contact_terms for candidate pair k (k below the live pair count): pairs that are not
/// confirmed get hit = 0 (and depth0 = -1, records[k].hit = 0 when those are set).
__device__ inline void contact_terms_at(const TermsDesc& d, std::uint32_t k) {
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

/// Whether a and b hold the same bits (a clamp that changed nothing, NaN included).
__device__ inline bool same_bits(const Vec3& a, const Vec3& b) {
  return __float_as_uint(a.x) == __float_as_uint(b.x) && __float_as_uint(a.y) == __float_as_uint(b.y) &&
         __float_as_uint(a.z) == __float_as_uint(b.z);
}

/// One body's sums over its kept contacts, added in the caller's order from zero, exactly
/// as World accumulates dx_sum / dv_sum / contact_count.
struct ContactSums {
  Vec3 dx;
  Vec3 dv;
  unsigned count = 0;

  /// Adds contact k's terms for side b (true: the body is the pair's b) when kept (hit).
  __device__ void add(const ApplyDesc& d, std::uint32_t k, bool side_b) {
    if (!d.hit[k]) return;
    if (!side_b) {
      dx += d.dx_a[k];
      dv += d.dv_a[k];
    } else {
      dx += d.dx_b[k];
      dv += d.dv_b[k];
    }
    ++count;
  }

  /// apply_contact_sums on body i's state, then clamp_velocity when d.clamp. Stores only
  /// what changed: x and v of a body with kept contacts, v of one the clamp changed.
  __device__ void apply(const ApplyDesc& d, std::uint32_t i) const {
    if (count == 0 && !d.clamp) return;  // apply_contact_sums changes nothing
    const Vec3 v0 = d.v[i];
    Vec3 v = v0;
    if (count != 0) {
      Vec3 x = d.x[i];
      apply_contact_sums(x, v, dx, dv, count);
      d.x[i] = x;
    }
    if (d.clamp) v = clamp_velocity(v, d.max_velocity);
    if (count != 0 || !same_bits(v, v0)) d.v[i] = v;
  }
};

}  // namespace gpu
}  // namespace octocd
