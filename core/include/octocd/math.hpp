#pragma once
/// \file math.hpp
/// The geometry and contact math shared by the CPU reference and the CUDA engine.
///
/// Every function here is `OCTOCD_HD` (`__host__ __device__` under nvcc, nothing
/// otherwise), takes and returns plain values, allocates nothing and throws nothing,
/// so the CPU pipeline and the kernels run literally the same formulas.
/// Units: metres, seconds, kilograms (design.md section 2). State is float32.

#include <cmath>
#include <cstdint>

#if defined(__CUDACC__)
#define OCTOCD_HD __host__ __device__
#else
#define OCTOCD_HD
#endif

namespace octocd {

/// A 3-vector of float32 (positions in m, velocities in m/s, impulses in kg m/s).
struct Vec3 {
  float x = 0.0f;
  float y = 0.0f;
  float z = 0.0f;

  /// Component i (0 = x, 1 = y, 2 = z); i outside [0, 2] is undefined behaviour.
  OCTOCD_HD float operator[](int i) const { return i == 0 ? x : (i == 1 ? y : z); }
  /// Mutable component i (0 = x, 1 = y, 2 = z).
  OCTOCD_HD float& operator[](int i) { return i == 0 ? x : (i == 1 ? y : z); }
};

/// Component-wise sum.
OCTOCD_HD inline Vec3 operator+(Vec3 a, Vec3 b) { return {a.x + b.x, a.y + b.y, a.z + b.z}; }
/// Component-wise difference.
OCTOCD_HD inline Vec3 operator-(Vec3 a, Vec3 b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
/// Negation.
OCTOCD_HD inline Vec3 operator-(Vec3 a) { return {-a.x, -a.y, -a.z}; }
/// Scaling by s.
OCTOCD_HD inline Vec3 operator*(float s, Vec3 a) { return {s * a.x, s * a.y, s * a.z}; }
/// Scaling by s.
OCTOCD_HD inline Vec3 operator*(Vec3 a, float s) { return {s * a.x, s * a.y, s * a.z}; }
/// In-place sum.
OCTOCD_HD inline Vec3& operator+=(Vec3& a, Vec3 b) { a = a + b; return a; }
/// In-place difference.
OCTOCD_HD inline Vec3& operator-=(Vec3& a, Vec3 b) { a = a - b; return a; }
/// Exact component-wise equality.
OCTOCD_HD inline bool operator==(Vec3 a, Vec3 b) { return a.x == b.x && a.y == b.y && a.z == b.z; }
/// Dot product.
OCTOCD_HD inline float dot(Vec3 a, Vec3 b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
/// Euclidean length.
OCTOCD_HD inline float length(Vec3 a) { return sqrtf(dot(a, a)); }
/// Squared Euclidean length.
OCTOCD_HD inline float length2(Vec3 a) { return dot(a, a); }
/// True when every component is finite (no NaN, no infinity).
OCTOCD_HD inline bool is_finite(Vec3 a) {
#if defined(__CUDACC__)
  return isfinite(a.x) && isfinite(a.y) && isfinite(a.z);
#else
  return std::isfinite(a.x) && std::isfinite(a.y) && std::isfinite(a.z);
#endif
}

/// An axis-aligned bounding box [min, max] (paper Eq. 5), metres. A valid box has
/// min <= max on every axis.
struct Aabb {
  Vec3 min;
  Vec3 max;
};

/// Centre of an AABB.
OCTOCD_HD inline Vec3 center(const Aabb& b) { return 0.5f * (b.min + b.max); }

/// The local box translated by x: the world AABB of a body at position x (design.md section 4.2).
OCTOCD_HD inline Aabb translated(const Aabb& local, Vec3 x) { return {local.min + x, local.max + x}; }

/// The box grown by m on every side (m may be 0).
OCTOCD_HD inline Aabb expanded(const Aabb& b, float m) {
  return {{b.min.x - m, b.min.y - m, b.min.z - m}, {b.max.x + m, b.max.y + m, b.max.z + m}};
}

/// theta (m) of a shape pair (design.md section 6) from the two shapes' values (`theta_shape`: the
/// scene's theta, or with `auto` each shape's mean edge): the larger, as std::max gives it.
OCTOCD_HD inline float pair_theta(float theta_a, float theta_b) { return (theta_a < theta_b) ? theta_b : theta_a; }

/// overlaps() (paper Eq. 6) with all six comparisons evaluated (bitwise, not
/// short-circuit): the same answer for every input, NaN included, without a branch per
/// axis. For loops where most pairs miss at unpredictable axes (a spatial hash's cell
/// mates), and on the device, where a kernel then loads both boxes at once instead of a
/// chain of dependent loads and branches.
OCTOCD_HD inline bool overlaps_all_axes(const Aabb& a, const Aabb& b) {
  return (a.min.x <= b.max.x) & (a.max.x >= b.min.x) &  //
         (a.min.y <= b.max.y) & (a.max.y >= b.min.y) &  //
         (a.min.z <= b.max.z) & (a.max.z >= b.min.z);
}

/// Paper Eq. 6: inclusive AABB overlap on all three axes (touching faces overlap), the
/// rule Bullet and FCL use too. On the device overlaps_all_axes; the host keeps the early
/// exit (the CPU engine ran bunny-stack-50 5% slower evaluating all six).
OCTOCD_HD inline bool overlaps(const Aabb& a, const Aabb& b) {
#ifdef __CUDA_ARCH__
  return overlaps_all_axes(a, b);
#else
  return a.min.x <= b.max.x && a.max.x >= b.min.x &&  //
         a.min.y <= b.max.y && a.max.y >= b.min.y &&  //
         a.min.z <= b.max.z && a.max.z >= b.min.z;
#endif
}

/// True when `inner` lies entirely inside `outer` (inclusive).
OCTOCD_HD inline bool contains(const Aabb& outer, const Aabb& inner) {
  return outer.min.x <= inner.min.x && outer.min.y <= inner.min.y && outer.min.z <= inner.min.z &&
         outer.max.x >= inner.max.x && outer.max.y >= inner.max.y && outer.max.z >= inner.max.z;
}

/// Squared distance from point p to box b; 0 when p is inside or on b.
/// Used by the mesh-box narrow phase (design.md section 5.3).
OCTOCD_HD inline float distance2_point_aabb(Vec3 p, const Aabb& b) {
  float d2 = 0.0f;
  for (int i = 0; i < 3; ++i) {
    const float v = p[i];
    if (v < b.min[i]) d2 += (b.min[i] - v) * (b.min[i] - v);
    if (v > b.max[i]) d2 += (v - b.max[i]) * (v - b.max[i]);
  }
  return d2;
}

/// Spreads the low 10 bits of v so that bit i lands on bit 3i: one axis of a 30-bit
/// Morton code (Algorithm A1; design.md sections 5.1-5.2). Bits above 9 are dropped.
OCTOCD_HD inline std::uint32_t morton_spread3(std::uint32_t v) {
  v &= 0x3ffu;
  v = (v | (v << 16)) & 0x030000ffu;
  v = (v | (v << 8)) & 0x0300f00fu;
  v = (v | (v << 4)) & 0x030c30c3u;
  v = (v | (v << 2)) & 0x09249249u;
  return v;
}

/// 30-bit Morton code of integer cell coordinates (x, y, z), each in [0, 2^10) (higher
/// bits are dropped): bit 3i holds bit i of x, bit 3i+1 bit i of y, bit 3i+2 bit i of z
/// (x in the low bit of each triple). The one bit order of the project: the per-mesh
/// octree (design.md section 5.2, Algorithm A1) and the world octrees (design.md section 5.1) both use it. The
/// code of a cell at depth d is the code of any of its depth-(d+k) descendants >> 3k.
OCTOCD_HD inline std::uint32_t morton3(std::uint32_t x, std::uint32_t y, std::uint32_t z) {
  return morton_spread3(x) | (morton_spread3(y) << 1) | (morton_spread3(z) << 2);
}

/// How the per-axis overlap of Eq. 9 is read (design.md section 6, `response.overlap`).
enum class OverlapMode : int {
  /// p_i = min(max_A,i - min_B,i, max_B,i - min_A,i): the distance that separates the
  /// boxes along axis i (default). Equal to `Paper` unless one box contains the other
  /// along i, where it still separates them and Eq. 14's contraction holds.
  Separating = 0,
  /// Eq. 9 as written: p_i = min(max_A,i, max_B,i) - max(min_A,i, min_B,i), the width of
  /// the overlap interval (the inner box's width when one contains the other).
  Paper = 1,
};

/// Response parameters, paper Table 1 and section 3.3 (defaults are the paper's), plus
/// design.md section 6's `overlap` and `iterations`. Constraints (section 3.3.3) are checked by the
/// scene loader, not here.
struct ContactParams {
  float slop = 0.001f;          ///< delta: tolerated penetration (m), > 0.
  float beta = 1.0f;            ///< Baumgarte factor (Eq. 11), in (0, 1].
  float alpha = 1.0f;           ///< smoothing factor (Eq. 13), in (0, 1].
  float restitution = 0.5f;     ///< e, in [0, 1].
  float restitution_threshold = 0.3f;  ///< v_th (m/s): below it e_eff = 0 (Eq. 17), >= 0.
  float impulse_floor = 0.01f;  ///< J_min (kg m/s), the normal impulse floor (Eq. 18), >= 0.
  float mu_static = 0.6f;       ///< mu_s, static friction coefficient (Eq. 21), >= 0.
  float mu_kinetic = 0.5f;      ///< mu_k, kinetic friction coefficient (Eq. 21), >= 0.
  float max_velocity = 50.0f;   ///< v_max (m/s), per-component clamp (Eq. 23), finite > 0.
  float epsilon = 1e-6f;        ///< centre distance (m) below which n = +y (section 3.3 (3)).
  OverlapMode overlap = OverlapMode::Separating;  ///< Eq. 9 reading (design.md section 6)
  int iterations = 1;           ///< relaxation passes per step, in [1, 1000] (design.md section 6)
};

/// Result of the AABB penetration test (Eq. 9-10).
struct Penetration {
  bool hit = false;   ///< all three overlaps > 0
  int axis = 1;       ///< axis of least overlap: 0 = x, 1 = y, 2 = z
  float depth = 0.0f; ///< d_p = min(p_x, p_y, p_z) (m), >= 0
  Vec3 normal{0.0f, 1.0f, 0.0f};  ///< unit normal along `axis`, pointing from B to A
};

/// Paper Eq. 9-10 and the "fixed axis" safeguard (design.md section 6): overlaps per axis of the
/// world AABBs of A and B, read as `mode` says; any overlap <= 0 means no contact (hit =
/// false). The normal is the axis of least overlap, signed so it points from B's AABB
/// centre to A's; when the centres are closer than `epsilon` (m) the normal is +y (the
/// paper's "fixed axis") and the depth is the y overlap.
OCTOCD_HD inline Penetration penetration(const Aabb& a, const Aabb& b, float epsilon,
                                         OverlapMode mode = OverlapMode::Separating) {
  Penetration r;
  float p[3];
  for (int i = 0; i < 3; ++i) {
    p[i] = mode == OverlapMode::Paper ? fminf(a.max[i], b.max[i]) - fmaxf(a.min[i], b.min[i])
                                      : fminf(a.max[i] - b.min[i], b.max[i] - a.min[i]);
    if (!(p[i] > 0.0f)) return r;
  }
  const Vec3 d = center(a) - center(b);
  r.hit = true;
  if (length(d) < epsilon) {
    r.axis = 1;
    r.depth = p[1];
    r.normal = {0.0f, 1.0f, 0.0f};
    return r;
  }
  int axis = 0;
  if (p[1] < p[axis]) axis = 1;
  if (p[2] < p[axis]) axis = 2;
  r.axis = axis;
  r.depth = p[axis];
  Vec3 n{0.0f, 0.0f, 0.0f};
  // Sign by the centres along the axis; an exact tie on that axis falls back to +.
  n[axis] = d[axis] < 0.0f ? -1.0f : 1.0f;
  r.normal = n;
  return r;
}

/// Paper Eq. 11 and 13: the correction vector c = alpha * beta * max(d_p - delta, 0) * n
/// (m). The caller splits it with `correction_share`.
OCTOCD_HD inline Vec3 position_correction(const Penetration& pen, const ContactParams& p) {
  const float excess = fmaxf(pen.depth - p.slop, 0.0f);
  return (p.alpha * p.beta * excess) * pen.normal;
}

/// Algorithm 3, lines 7-8 (not Eq. 12, which swaps the weights; design.md section 6): the share of the
/// correction applied to body A is w_A/(w_A+w_B) (positive direction), to B
/// w_B/(w_A+w_B) (negative direction). w are inverse masses (1/kg), 0 = static.
/// Returns 0 when both are static.
OCTOCD_HD inline float correction_share(float w_self, float w_a, float w_b) {
  const float sum = w_a + w_b;
  return sum > 0.0f ? w_self / sum : 0.0f;
}

/// Impulses of one contact (Eq. 16-22) and the resulting velocity changes.
struct ContactImpulse {
  float normal_velocity = 0.0f;   ///< v_n = (v_A - v_B) . n (m/s), before the impulse
  float tangent_speed = 0.0f;     ///< |v_t| (m/s), before the impulse
  float jn = 0.0f;                ///< J_n (kg m/s), >= 0; 0 when separating (v_n >= 0)
  float jt = 0.0f;                ///< J_t (kg m/s), <= 0 along t (opposes sliding)
  bool sticking = false;          ///< static branch of Eq. 21 taken
  Vec3 tangent{0.0f, 0.0f, 0.0f}; ///< t = v_t/|v_t|, zero when |v_t| = 0
  Vec3 dv_a{0.0f, 0.0f, 0.0f};    ///< velocity change of A (m/s)
  Vec3 dv_b{0.0f, 0.0f, 0.0f};    ///< velocity change of B (m/s)
};

/// Paper Eq. 16-22 as fixed by design.md section 6, for one contact from the pre-response velocities:
/// - v_rel = v_A - v_B, v_n = v_rel . n, v_t = v_rel - v_n n (Eq. 16);
/// - if v_n < 0: e_eff = 0 when |v_n| < v_th else e (Eq. 17);
///   J_n = max(-(1 + e_eff) v_n / (w_A + w_B), J_min) (Eq. 17-18); else J_n = 0;
/// - if |v_t| > 0: t = v_t/|v_t|, J_t* = -|v_t|/(w_A + w_B) (Eq. 20);
///   J_t = J_t* when |J_t*| <= mu_s J_n (stick) else -mu_k J_n (slip) (Eq. 21);
/// - dv_A = w_A (J_n n + J_t t), dv_B = -w_B (J_n n + J_t t) (Eq. 19, 22).
/// n must be a unit vector from B to A. Both static (w_A + w_B = 0): no impulse.
OCTOCD_HD inline ContactImpulse contact_impulse(Vec3 v_a, Vec3 v_b, float w_a, float w_b, Vec3 n,
                                                const ContactParams& p) {
  ContactImpulse r;
  const float w = w_a + w_b;
  if (!(w > 0.0f)) return r;
  const Vec3 v_rel = v_a - v_b;
  const float v_n = dot(v_rel, n);
  const Vec3 v_t = v_rel - v_n * n;
  const float vt_len = length(v_t);
  r.normal_velocity = v_n;
  r.tangent_speed = vt_len;
  if (v_n < 0.0f) {
    const float e_eff = (-v_n < p.restitution_threshold) ? 0.0f : p.restitution;
    r.jn = fmaxf(-(1.0f + e_eff) * v_n / w, p.impulse_floor);
  }
  if (vt_len > 0.0f) {
    r.tangent = (1.0f / vt_len) * v_t;
    const float jt_star = -vt_len / w;
    if (fabsf(jt_star) <= p.mu_static * r.jn) {
      r.jt = jt_star;
      r.sticking = true;
    } else {
      r.jt = -p.mu_kinetic * r.jn;
    }
  }
  const Vec3 impulse = r.jn * n + r.jt * r.tangent;
  r.dv_a = w_a * impulse;
  r.dv_b = -(w_b * impulse);
  return r;
}

/// Paper Eq. 23: clamps each velocity component to [-v_max, v_max].
OCTOCD_HD inline Vec3 clamp_velocity(Vec3 v, float v_max) {
  return {fminf(fmaxf(v.x, -v_max), v_max), fminf(fmaxf(v.y, -v_max), v_max),
          fminf(fmaxf(v.z, -v_max), v_max)};
}

/// The response terms of one contact in one pass (design.md section 6): penetration (Eq. 9-10), the
/// correction split by Algorithm 3's weights (Eq. 11, 13), and the impulses (Eq. 16-22),
/// all from the current world AABBs and velocities of A and B. `pen.hit` false: Eq. 9
/// discards the contact and every term is zero.
struct ContactTerms {
  Penetration pen;      ///< depth, axis and normal (from B to A)
  ContactImpulse imp;   ///< J_n, J_t and the velocity changes dv_a, dv_b (m/s)
  Vec3 dx_a{0.0f, 0.0f, 0.0f};  ///< A's share of the correction, before averaging (m)
  Vec3 dx_b{0.0f, 0.0f, 0.0f};  ///< B's share of the correction, before averaging (m)
};

/// Computes ContactTerms for A and B (world AABBs box_a, box_b; velocities v_a, v_b in
/// m/s; inverse masses w_a, w_b in 1/kg). Both engines call this per contact and pass.
OCTOCD_HD inline ContactTerms contact_terms(const Aabb& box_a, const Aabb& box_b, Vec3 v_a,
                                            Vec3 v_b, float w_a, float w_b,
                                            const ContactParams& p) {
  ContactTerms t;
  t.pen = penetration(box_a, box_b, p.epsilon, p.overlap);
  if (!t.pen.hit) return t;
  const Vec3 c = position_correction(t.pen, p);
  t.dx_a = correction_share(w_a, w_a, w_b) * c;
  t.dx_b = -(correction_share(w_b, w_a, w_b) * c);
  t.imp = contact_impulse(v_a, v_b, w_a, w_b, t.pen.normal, p);
  return t;
}

/// Applies one pass's reduced terms to a dynamic body (design.md section 6 parallel semantics):
/// x += dx_sum / count (corrections averaged over the body's `count` contacts),
/// v += dv_sum (velocity changes summed). count = 0: nothing changes. dx_sum and dv_sum
/// are sums over the body's contacts in (a, b) order, starting from zero.
OCTOCD_HD inline void apply_contact_sums(Vec3& x, Vec3& v, Vec3 dx_sum, Vec3 dv_sum,
                                         unsigned count) {
  if (count == 0) return;
  x += (1.0f / static_cast<float>(count)) * dx_sum;
  v += dv_sum;
}

/// Paper Eq. 2-3 (semi-implicit "explicit" Euler, design.md section 4.1): v += dt (g + w F);
/// x += dt v. Static bodies (w = 0) do not move. `force` is in N.
OCTOCD_HD inline void integrate(Vec3& x, Vec3& v, float w, Vec3 gravity, Vec3 force, float dt) {
  if (w == 0.0f) return;
  v = v + dt * (gravity + w * force);
  x = x + dt * v;
}

}  // namespace octocd
