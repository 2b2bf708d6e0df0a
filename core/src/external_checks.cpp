// The checks of what another engine hands octocd (octocd/external_trace.hpp): a
// FrameRecord's fields against the conventions of design.md section 2 and 13, the bodies'
// physics declarations, and the solid-box inertia a trace without /bodies/inertia is read with.
#include "octocd/external_trace.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>

#include <fmt/format.h>

#include "octocd/error.hpp"
#include "octocd/trace_reader.hpp"  // trace_limits

namespace octocd {

namespace {

bool finite(Vec3 v) { return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z); }

[[noreturn]] void fail(const std::string& origin, const std::string& field, std::int64_t frame,
                       const std::string& problem, const std::string& allowed) {
  throw InputError(fmt::format("{}: {}: frame {}: {}; allowed: {}", origin, field, frame, problem, allowed));
}

/// Row `i` of a pair list, `q`: a < b < n.
void check_pair_row(Pair q, std::size_t i, std::size_t n, const std::string& origin, const std::string& field,
                    std::int64_t frame, const std::string& allowed) {
  if (q.a >= q.b) fail(origin, field, frame, fmt::format("row {} is ({}, {}): a >= b", i, q.a, q.b), allowed);
  if (q.b >= n)
    fail(origin, field, frame, fmt::format("row {} is ({}, {}): body {} out of range", i, q.a, q.b, q.b), allowed);
}

/// Pairs sorted by (a, b), unique, a < b < n.
void check_pairs(const std::vector<Pair>& pairs, std::size_t n, const std::string& origin,
                 const std::string& field, std::int64_t frame) {
  const std::string allowed =
      fmt::format("pairs (a, b) with a < b < {} bodies, sorted by (a, b), each once", n);
  for (std::size_t i = 0; i < pairs.size(); ++i) {
    const Pair q = pairs[i];
    check_pair_row(q, i, n, origin, field, frame, allowed);
    if (i > 0 && !(pairs[i - 1] < q))
      fail(origin, field, frame,
           fmt::format("row {} is ({}, {}) after ({}, {}): {}", i, q.a, q.b, pairs[i - 1].a, pairs[i - 1].b,
                       pairs[i - 1] == q ? "duplicated" : "not sorted"),
           allowed);
  }
}

void check_vectors(const std::vector<Vec3>& v, std::size_t n, const std::string& origin,
                   const std::string& field, std::int64_t frame) {
  if (v.size() != n)
    fail(origin, field, frame, fmt::format("{} rows for {} bodies", v.size(), n), "one row per body");
  for (std::size_t i = 0; i < n; ++i)
    if (!finite(v[i]))
      fail(origin, field, frame, fmt::format("body {} is ({}, {}, {}): not finite", i, v[i].x, v[i].y, v[i].z),
           "finite numbers");
}

/// Contact pairs of a record with manifolds: a < b < n, sorted by (a, b) non-decreasingly,
/// so the rows of one pair are consecutive.
void check_manifold_pairs(const std::vector<Pair>& pairs, std::size_t n, const std::string& origin,
                          const std::string& field, std::int64_t frame) {
  const std::string allowed = fmt::format(
      "pairs (a, b) with a < b < {} bodies, sorted by (a, b) non-decreasingly: the rows of one pair (a manifold) "
      "consecutive",
      n);
  for (std::size_t i = 0; i < pairs.size(); ++i) {
    const Pair q = pairs[i];
    check_pair_row(q, i, n, origin, field, frame, allowed);
    if (i > 0 && q < pairs[i - 1]) {
      const bool repeated = std::find(pairs.begin(), pairs.begin() + static_cast<std::ptrdiff_t>(i), q) !=
                            pairs.begin() + static_cast<std::ptrdiff_t>(i);
      fail(origin, field, frame,
           repeated ? fmt::format("row {} is ({}, {}) again after ({}, {}): manifold rows of one pair not "
                                  "consecutive",
                                  i, q.a, q.b, pairs[i - 1].a, pairs[i - 1].b)
                    : fmt::format("row {} is ({}, {}) after ({}, {}): not sorted", i, q.a, q.b, pairs[i - 1].a,
                                  pairs[i - 1].b),
           allowed);
    }
  }
}

/// Quaternions: empty (identity) or one unit quaternion per body.
void check_quats(const std::vector<Quat>& q, std::size_t n, const std::string& origin, const std::string& field,
                 std::int64_t frame, const char* when) {
  if (q.size() != n)
    fail(origin, field, frame, fmt::format("{} rows for {} bodies", q.size(), n), "one row per body");
  for (std::size_t i = 0; i < n; ++i) {
    const double len = std::sqrt(static_cast<double>(q[i].w) * q[i].w + static_cast<double>(q[i].x) * q[i].x +
                                 static_cast<double>(q[i].y) * q[i].y + static_cast<double>(q[i].z) * q[i].z);
    if (!std::isfinite(len) || !(std::fabs(len - 1.0) <= 1e-3))
      fail(origin, field, frame,
           fmt::format("body {} {} is ({}, {}, {}, {}), |q| = {:.6g}", i, when, q[i].w, q[i].x, q[i].y, q[i].z, len),
           "unit quaternions (w, x, y, z), body to world, | |q| - 1 | <= 1e-3");
  }
}

/// Leading principal minors of a symmetric 3x3 matrix (row-major), in double.
std::array<double, 3> leading_minors(const std::array<double, 9>& m) {
  return {m[0], m[0] * m[4] - m[1] * m[3],
          m[0] * (m[4] * m[8] - m[5] * m[7]) - m[1] * (m[3] * m[8] - m[5] * m[6]) +
              m[2] * (m[3] * m[7] - m[4] * m[6])};
}

}  // namespace

std::array<double, 9> box_inertia(const Aabb& local, float inverse_mass) {
  std::array<double, 9> out{};
  if (!(inverse_mass > 0.0f)) return out;
  const double m = 1.0 / inverse_mass;
  const double a = static_cast<double>(local.max.x) - local.min.x, b = static_cast<double>(local.max.y) - local.min.y,
               c = static_cast<double>(local.max.z) - local.min.z;
  out[0] = m / 12.0 * (b * b + c * c);
  out[4] = m / 12.0 * (a * a + c * c);
  out[8] = m / 12.0 * (a * a + b * b);
  return out;
}

void check_physics_bodies(const PhysicsBodies& p, const std::vector<float>& inverse_mass, const std::string& origin,
                          const PhysicsFieldNames& names) {
  const std::size_t n = inverse_mass.size();
  auto bad = [&](const std::string& field, const std::string& problem, const std::string& allowed) {
    throw InputError(fmt::format("{}: {}: {}; allowed: {}", origin, field, problem, allowed));
  };
  if (!p.inertia.empty()) {
    if (p.inertia.size() != n)
      bad(names.inertia, fmt::format("{} tensors for {} bodies", p.inertia.size(), n), "one 3 x 3 tensor per body");
    for (std::size_t i = 0; i < n; ++i) {
      const std::array<double, 9>& m = p.inertia[i];
      const std::string I =
          fmt::format("[[{:.6g}, {:.6g}, {:.6g}], [{:.6g}, {:.6g}, {:.6g}], [{:.6g}, {:.6g}, {:.6g}]]", m[0], m[1],
                      m[2], m[3], m[4], m[5], m[6], m[7], m[8]);
      double largest = 0.0;
      for (double x : m) {
        if (!std::isfinite(x))
          bad(names.inertia, fmt::format("body {}: {} not finite", i, I), "finite numbers (kg m^2)");
        largest = std::max(largest, std::fabs(x));
      }
      if (!(inverse_mass[i] > 0.0f)) continue;  // static: never used
      const std::string allowed =
          "a symmetric positive definite tensor (kg m^2, body frame) for a dynamic body: |I_rc - I_cr| <= 1e-4 "
          "max |I|, leading minors > 0";
      for (int r = 0; r < 3; ++r)
        for (int c = r + 1; c < 3; ++c)
          if (!(std::fabs(m[3 * r + c] - m[3 * c + r]) <= 1e-4 * largest))
            bad(names.inertia, fmt::format("body {}: {} not symmetric (I[{}][{}] = {}, I[{}][{}] = {})", i, I, r, c,
                                           m[3 * r + c], c, r, m[3 * c + r]),
                allowed);
      const std::array<double, 3> minors = leading_minors(m);
      for (int k = 0; k < 3; ++k)
        if (!(minors[static_cast<std::size_t>(k)] > 0.0))
          bad(names.inertia,
              fmt::format("body {}: {} not positive definite (leading minor {} is {:.6g})", i, I, k + 1,
                          minors[static_cast<std::size_t>(k)]),
              allowed);
      for (int k = 0; k < 3; ++k)  // principal moments a real body has (trace_limits)
        if (!(m[4 * k] >= trace_limits::kMinInertia && m[4 * k] <= trace_limits::kMaxInertia))
          bad(names.inertia, fmt::format("body {}: I[{}][{}] = {:g}", i, k, k, m[4 * k]),
              fmt::format("diagonal moments in [{:g}, {:g}] kg m^2 for a dynamic body", trace_limits::kMinInertia,
                          trace_limits::kMaxInertia));
    }
  }
  if (!p.locked_dofs.empty()) {
    if (p.locked_dofs.size() != n)
      bad(names.locked_dofs, fmt::format("{} values for {} bodies", p.locked_dofs.size(), n), "0 or one per body");
    for (std::size_t i = 0; i < n; ++i)
      if (p.locked_dofs[i] > 63)
        bad(names.locked_dofs, fmt::format("body {}: {}", i, unsigned(p.locked_dofs[i])),
            "0 .. 63: bits 0-2 translation along world x, y, z, bits 3-5 rotation about world x, y, z locked");
  }
  if (!p.body_friction.empty()) {
    if (p.body_friction.size() != n)
      bad(names.body_friction, fmt::format("{} values for {} bodies", p.body_friction.size(), n), "one per body");
    for (std::size_t i = 0; i < n; ++i)
      if (!std::isfinite(p.body_friction[i]) || p.body_friction[i] < 0.0f)
        bad(names.body_friction, fmt::format("body {}: {}", i, p.body_friction[i]),
            "a finite friction coefficient >= 0 per body");
  }
  if (!p.body_restitution.empty()) {
    if (p.body_restitution.size() != n)
      bad(names.body_restitution, fmt::format("{} values for {} bodies", p.body_restitution.size(), n),
          "one per body");
    for (std::size_t i = 0; i < n; ++i)
      if (!(p.body_restitution[i] >= 0.0f && p.body_restitution[i] <= 1.0f))
        bad(names.body_restitution, fmt::format("body {}: {}", i, p.body_restitution[i]),
            "a restitution in [0, 1] per body");
  }
  if (!std::isfinite(p.mu) || p.mu < 0.0) bad(names.mu, fmt::format("{}", p.mu), "a finite friction coefficient >= 0");
  if (!(p.restitution >= 0.0 && p.restitution <= 1.0))
    bad(names.restitution, fmt::format("{}", p.restitution), "a restitution in [0, 1]");
  if (!(p.contact_margin >= 0.0 && p.contact_margin <= trace_limits::kMaxContactMargin))
    bad(names.contact_margin, fmt::format("{}", p.contact_margin),
        fmt::format("a finite distance >= 0 (m), at most {:g} m", trace_limits::kMaxContactMargin));
  if (!std::isfinite(p.slop) || !(p.slop > 0.0)) bad(names.slop, fmt::format("{}", p.slop), "a finite slop > 0 (m)");
}

void check_frame_record(const FrameRecord& rec, std::size_t n, const std::string& origin,
                        const RecordFieldNames& names) {
  const std::int64_t f = rec.frame;
  const bool states = !rec.x_pre.empty() || !rec.v_pre.empty() || !rec.x_post.empty() || !rec.v_post.empty();
  if (rec.aabbs.empty() && !states && rec.x_det.empty())
    fail(origin, names.aabbs, f, "no world AABBs, no states and no detection pose",
         "the AABBs, or x_pre, v_pre, x_post, v_post, or the detection pose x_det");
  if (!rec.aabbs.empty()) {
    if (rec.aabbs.size() != n)
      fail(origin, names.aabbs, f, fmt::format("{} boxes for {} bodies", rec.aabbs.size(), n), "one per body");
    for (std::size_t i = 0; i < n; ++i) {
      const Aabb& b = rec.aabbs[i];
      if (!finite(b.min) || !finite(b.max))
        fail(origin, names.aabbs, f, fmt::format("body {}: not finite", i), "finite numbers");
      if (!(b.min.x <= b.max.x && b.min.y <= b.max.y && b.min.z <= b.max.z))
        fail(origin, names.aabbs, f,
             fmt::format("body {}: min ({}, {}, {}) above max ({}, {}, {})", i, b.min.x, b.min.y, b.min.z, b.max.x,
                         b.max.y, b.max.z),
             "min <= max on every axis");
    }
  }
  if (states) {
    check_vectors(rec.x_pre, n, origin, names.x_pre, f);
    check_vectors(rec.v_pre, n, origin, names.v_pre, f);
    check_vectors(rec.x_post, n, origin, names.x_post, f);
    check_vectors(rec.v_post, n, origin, names.v_post, f);
  }
  const bool rotation = !rec.q_pre.empty() || !rec.q_post.empty() || !rec.w_pre.empty() || !rec.w_post.empty();
  if (rotation) {
    if (!states)
      fail(origin, names.q_pre, f, "orientations without positions and velocities",
           "orientations and angular velocities with x_pre, v_pre, x_post, v_post");
    const std::string together =
        "orientations and angular velocities before and after the step together (or none: no rotation)";
    const bool q = !rec.q_pre.empty() || !rec.q_post.empty(), w = !rec.w_pre.empty() || !rec.w_post.empty();
    if (!q) fail(origin, names.q_pre, f, "angular velocities without orientations", together);
    if (!w) fail(origin, names.w_pre, f, "orientations without angular velocities", together);
    if (rec.q_pre.empty() || rec.q_post.empty())
      fail(origin, rec.q_pre.empty() ? names.q_pre : names.q_post, f,
           rec.q_pre.empty() ? "missing (q_post given)" : "missing (q_pre given)", together);
    if (rec.w_pre.empty() || rec.w_post.empty())
      fail(origin, rec.w_pre.empty() ? names.w_pre : names.w_post, f,
           rec.w_pre.empty() ? "missing (w_post given)" : "missing (w_pre given)", together);
    check_quats(rec.q_pre, n, origin, names.q_pre, f, "before the step");
    check_quats(rec.q_post, n, origin, names.q_post, f, "after the step");
    check_vectors(rec.w_pre, n, origin, names.w_pre, f);
    check_vectors(rec.w_post, n, origin, names.w_post, f);
  }
  if (!rec.x_det.empty()) check_vectors(rec.x_det, n, origin, names.x_det, f);
  if (!rec.q_det.empty()) {
    if (rec.x_det.empty())
      fail(origin, names.q_det, f, "a detection orientation without a detection position (x_det)",
           "x_det with q_det (or x_det alone: identity orientation)");
    check_quats(rec.q_det, n, origin, names.q_det, f, "at detection");
  }
  if (rec.has_pairs) check_pairs(rec.pairs, n, origin, names.pairs, f);
  std::vector<Pair> contact_pairs(rec.contacts.size());
  for (std::size_t i = 0; i < rec.contacts.size(); ++i) contact_pairs[i] = rec.contacts[i].pair;
  if (rec.manifolds)
    check_manifold_pairs(contact_pairs, n, origin, names.contact_pair, f);
  else
    check_pairs(contact_pairs, n, origin, names.contact_pair, f);
  for (std::size_t i = 0; i < rec.contacts.size(); ++i) {
    const ContactRecord& c = rec.contacts[i];
    const std::string which = fmt::format("row {} (pair ({}, {}))", i, c.pair.a, c.pair.b);
    const double len = length(c.normal);
    if (!finite(c.normal) || !(std::fabs(len - 1.0) <= 1e-3))
      fail(origin, names.contact_normal, f,
           fmt::format("{} is ({}, {}, {}), length {}", which, c.normal.x, c.normal.y, c.normal.z, len),
           "a finite unit vector (|n| within 1e-3 of 1) from B to A");
    if (!std::isfinite(c.depth) || c.depth < 0.0f)
      fail(origin, names.contact_depth, f, fmt::format("{} is {}", which, c.depth), "a finite depth >= 0 (m)");
    if (!std::isfinite(c.jn) || c.jn < 0.0f)
      fail(origin, names.contact_jn, f, fmt::format("{} is {}", which, c.jn),
           "a finite normal impulse >= 0 (kg m/s)");
    if (!std::isfinite(c.jt))
      fail(origin, names.contact_jt, f, fmt::format("{} is {}", which, c.jt), "a finite impulse (kg m/s)");
    if (rec.has_points && !finite(c.point))
      fail(origin, names.contact_point, f,
           fmt::format("{} is ({}, {}, {}): not finite", which, c.point.x, c.point.y, c.point.z),
           "a finite world point (m)");
  }
  if (!rec.point_b.empty()) {
    if (!rec.has_points || rec.point_b.size() != rec.contacts.size())
      fail(origin, names.contact_point_b, f,
           fmt::format("{} points for {} contact rows{}", rec.point_b.size(), rec.contacts.size(),
                       rec.has_points ? "" : " without contact points"),
           "one point on B per contact row, with the rows' points (or none)");
    for (std::size_t i = 0; i < rec.point_b.size(); ++i) {
      const Vec3 p = rec.point_b[i];
      if (!finite(p))
        fail(origin, names.contact_point_b, f,
             fmt::format("row {} (pair ({}, {})) is ({}, {}, {}): not finite", i, rec.contacts[i].pair.a,
                         rec.contacts[i].pair.b, p.x, p.y, p.z),
             "a finite world point (m)");
    }
  }
  if (!rec.jt3.empty()) {
    if (rec.jt3.size() != rec.contacts.size())
      fail(origin, names.contact_jt3, f, fmt::format("{} vectors for {} contact rows", rec.jt3.size(), rec.contacts.size()),
           "one tangential impulse vector per contact row (or none)");
    const double max_sin = std::sin(kJt3MaxAngleDeg * 3.14159265358979323846 / 180.0);
    for (std::size_t i = 0; i < rec.jt3.size(); ++i) {
      const ContactRecord& c = rec.contacts[i];
      const Vec3 j = rec.jt3[i];
      const std::string which = fmt::format("row {} (pair ({}, {}))", i, c.pair.a, c.pair.b);
      if (!finite(j))
        fail(origin, names.contact_jt3, f, fmt::format("{} is ({}, {}, {}): not finite", which, j.x, j.y, j.z),
             "a finite impulse vector (kg m/s)");
      const double jl = std::sqrt(double(j.x) * j.x + double(j.y) * j.y + double(j.z) * j.z);
      if (!(jl > 1e-9)) continue;
      const double along = std::fabs(double(j.x) * c.normal.x + double(j.y) * c.normal.y + double(j.z) * c.normal.z) /
                           (jl * double(length(c.normal)));
      if (along > max_sin)
        fail(origin, names.contact_jt3, f,
             fmt::format("{} is ({}, {}, {}), {:.3g} deg out of the contact plane of its normal ({}, {}, {})", which,
                         j.x, j.y, j.z, std::asin(std::min(1.0, along)) * 180.0 / 3.14159265358979323846, c.normal.x,
                         c.normal.y, c.normal.z),
             fmt::format("a tangential impulse orthogonal to the row's normal (within {} deg)", kJt3MaxAngleDeg));
    }
  }
}

}  // namespace octocd
