// SPEC 7 item 9: an independent re-derivation of SPEC 4.1 and SPEC 6 in double precision,
// written from the SPEC text. It shares nothing with the engines' response code (no
// math.hpp formula is called here): it reads only the model (scene, local boxes, inverse
// masses) and one FrameRecord, and predicts the state the engine should have applied.
#include <algorithm>
#include <array>
#include <cmath>
#include <limits>

#include "octocd/validation.hpp"

namespace octocd {

namespace {

using D3 = std::array<double, 3>;

D3 d3(Vec3 v) { return {v.x, v.y, v.z}; }
double inf_norm(const D3& a) { return std::max({std::fabs(a[0]), std::fabs(a[1]), std::fabs(a[2])}); }
double norm2(const D3& a) { return std::sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2]); }

}  // namespace

StatePrediction predict_step(const Model& model, const FrameRecord& rec, const Tolerances& tol) {
  const Scene& sc = model.scene;
  const ContactParams& p = sc.response;
  const std::size_t n = rec.x_pre.size();
  const double dt = sc.dt;
  const D3 g = d3(sc.gravity);
  StatePrediction out;
  out.x_int.resize(n);
  out.x.resize(n);
  out.v.resize(n);
  out.judged.assign(n, 1);
  out.clamped.assign(n, 0);
  out.contact_count.assign(n, 0);
  std::vector<D3> scale_x(n), scale_v(n);
  std::vector<double> coord_max(n, 0.0), vel_max(n, 0.0);

  // SPEC 4.1, semi-implicit Euler: v <- v + dt g; x <- x + dt v (static bodies stay).
  for (std::size_t i = 0; i < n; ++i) {
    D3 x = d3(rec.x_pre[i]), v = d3(rec.v_pre[i]);
    if (model.initial.w[i] > 0.0f)
      for (int k = 0; k < 3; ++k) {
        v[k] = v[k] + dt * g[k];
        x[k] = x[k] + dt * v[k];
      }
    out.x_int[i] = out.x[i] = x;
    out.v[i] = v;
    for (int k = 0; k < 3; ++k) {
      scale_x[i][k] = std::fabs(x[k]) + std::fabs(dt * v[k]);
      scale_v[i][k] = std::fabs(v[k]) + std::fabs(dt * g[k]);
    }
  }

  // A decision closer to its threshold than float32 rounding can resolve is not judged:
  // the bodies it touches are excluded from this frame's comparison (and counted).
  const double eps32 = 1.0 / 8388608.0;  // 2^-23
  const double margin_rel = 16.0 * eps32 * (p.iterations + 2);
  auto ambiguous = [&](double value, double threshold, double scale) {
    return std::fabs(value - threshold) <= margin_rel * (1.0 + std::fabs(scale));
  };

  // SPEC 6, `iterations` Jacobi passes over the confirmed contacts in (a, b) order.
  const double w_eps = p.epsilon;
  for (int pass = 0; pass < p.iterations; ++pass) {
    std::vector<D3> dx_sum(n, D3{0, 0, 0}), dv_sum(n, D3{0, 0, 0});
    std::vector<std::uint32_t> count(n, 0);
    for (const Pair& q : rec.confirmed) {
      const std::uint32_t a = q.a, b = q.b;
      const double wa = model.initial.w[a], wb = model.initial.w[b];
      const Aabb& la = model.local_box(a);
      const Aabb& lb = model.local_box(b);
      D3 amin, amax, bmin, bmax, pen;
      double coord_scale = 0.0;
      for (int k = 0; k < 3; ++k) {
        amin[k] = la.min[k] + out.x[a][k];
        amax[k] = la.max[k] + out.x[a][k];
        bmin[k] = lb.min[k] + out.x[b][k];
        bmax[k] = lb.max[k] + out.x[b][k];
        coord_scale = std::max({coord_scale, std::fabs(amin[k]), std::fabs(amax[k]),
                                std::fabs(bmin[k]), std::fabs(bmax[k])});
      }
      bool unsure = false;
      bool hit = true;
      for (int k = 0; k < 3; ++k) {
        // Eq. 9: `separating` = the distance that separates the boxes along k; `paper` =
        // the width of the overlap interval.
        pen[k] = p.overlap == OverlapMode::Paper
                     ? std::min(amax[k], bmax[k]) - std::max(amin[k], bmin[k])
                     : std::min(amax[k] - bmin[k], bmax[k] - amin[k]);
        unsure = unsure || ambiguous(pen[k], 0.0, coord_scale);
        if (!(pen[k] > 0.0)) hit = false;
      }
      if (!hit) {  // Eq. 9: discarded
        if (unsure) out.judged[a] = out.judged[b] = 0;
        continue;
      }
      // Eq. 10 and the fixed axis: normal along the least overlap, from B to A by centres.
      D3 d;
      for (int k = 0; k < 3; ++k) d[k] = 0.5 * (amin[k] + amax[k]) - 0.5 * (bmin[k] + bmax[k]);
      int axis = 1;
      double depth;
      D3 nrm{0, 0, 0};
      const double dist = norm2(d);
      unsure = unsure || ambiguous(dist, w_eps, coord_scale);
      if (dist < w_eps) {
        depth = pen[1];
        nrm[1] = 1.0;
      } else {
        axis = 0;
        if (pen[1] < pen[axis]) axis = 1;
        if (pen[2] < pen[axis]) axis = 2;
        for (int k = 0; k < 3; ++k)
          if (k != axis) unsure = unsure || ambiguous(pen[k], pen[axis], coord_scale);
        depth = pen[axis];
        unsure = unsure || ambiguous(d[axis], 0.0, coord_scale);
        nrm[axis] = d[axis] < 0.0 ? -1.0 : 1.0;
      }
      // Eq. 11, 13 with Algorithm 3's weights: A gets w_A/(w_A+w_B) of c, B -w_B/(...).
      const double wsum = wa + wb;
      const double corr = static_cast<double>(p.alpha) * p.beta * std::max(depth - p.slop, 0.0);
      // Eq. 16-22.
      D3 vrel;
      for (int k = 0; k < 3; ++k) vrel[k] = out.v[a][k] - out.v[b][k];
      const double vn = vrel[0] * nrm[0] + vrel[1] * nrm[1] + vrel[2] * nrm[2];
      const double vscale = inf_norm(out.v[a]) + inf_norm(out.v[b]);
      double jn = 0.0, jt = 0.0;
      D3 t{0, 0, 0};
      if (wsum > 0.0) {
        unsure = unsure || ambiguous(vn, 0.0, vscale);
        if (vn < 0.0) {
          unsure = unsure || ambiguous(-vn, p.restitution_threshold, vscale);
          const double e_eff = -vn < p.restitution_threshold ? 0.0 : p.restitution;
          jn = std::max(-(1.0 + e_eff) * vn / wsum, static_cast<double>(p.impulse_floor));
        }
        D3 vt;
        for (int k = 0; k < 3; ++k) vt[k] = vrel[k] - vn * nrm[k];
        const double vt_len = norm2(vt);
        if (vt_len > 0.0) {
          for (int k = 0; k < 3; ++k) t[k] = vt[k] / vt_len;
          const double jt_star = -vt_len / wsum;
          unsure = unsure || ambiguous(std::fabs(jt_star), p.mu_static * jn, vscale / wsum);
          // A tiny slipping |v_t| has a direction float32 cannot resolve.
          if (std::fabs(jt_star) > p.mu_static * jn && jn > 0.0)
            unsure = unsure || vt_len <= margin_rel * (1.0 + vscale);
          jt = std::fabs(jt_star) <= p.mu_static * jn ? jt_star : -p.mu_kinetic * jn;
        }
      }
      for (int k = 0; k < 3; ++k) {
        const double c = corr * nrm[k];
        const double imp = jn * nrm[k] + jt * t[k];
        if (wsum > 0.0) {
          dx_sum[a][k] += wa / wsum * c;
          dx_sum[b][k] -= wb / wsum * c;
        }
        dv_sum[a][k] += wa * imp;
        dv_sum[b][k] -= wb * imp;
        scale_x[a][k] += std::fabs(c);
        scale_x[b][k] += std::fabs(c);
        scale_v[a][k] += std::fabs(wa * imp);
        scale_v[b][k] += std::fabs(wb * imp);
      }
      // Rounding of the inputs a contact's terms came from: the AABB coordinates (depth,
      // hence the correction) and both velocities (v_n, v_t, hence the impulses).
      for (const std::uint32_t body : {a, b}) {
        coord_max[body] = std::max(coord_max[body], coord_scale);
        vel_max[body] = std::max(vel_max[body], vscale);
      }
      ++count[a];
      ++count[b];
      if (unsure) out.judged[a] = out.judged[b] = 0;
    }
    // Parallel semantics: corrections averaged per body, velocity changes summed.
    for (std::size_t i = 0; i < n; ++i) {
      if (pass == 0) out.contact_count[i] = count[i];
      if (!(model.initial.w[i] > 0.0f) || count[i] == 0) continue;
      for (int k = 0; k < 3; ++k) {
        out.x[i][k] += dx_sum[i][k] / count[i];
        out.v[i][k] += dv_sum[i][k];
      }
    }
  }
  // Eq. 23: clamp each component to [-v_max, v_max].
  const double vmax = p.max_velocity;
  for (std::size_t i = 0; i < n; ++i) {
    if (!(model.initial.w[i] > 0.0f)) continue;
    for (int k = 0; k < 3; ++k) {
      // The clamp is continuous, so a component near v_max needs no exclusion; `clamped`
      // is conservative (within rounding counts) since it changes the group's momentum.
      if (std::fabs(out.v[i][k]) > vmax || ambiguous(std::fabs(out.v[i][k]), vmax, vmax)) out.clamped[i] = 1;
      out.v[i][k] = std::min(std::max(out.v[i][k], -vmax), vmax);
    }
  }
  // float32 tolerance: a few roundings of each magnitude that entered the value, per pass.
  const double ulps = tol.applied_state_ulps * eps32 * (p.iterations + 2);
  out.x_tol.resize(n);
  out.v_tol.resize(n);
  for (std::size_t i = 0; i < n; ++i)
    for (int k = 0; k < 3; ++k) {
      out.x_tol[i][k] = ulps * (scale_x[i][k] + coord_max[i]) + 1e-12;
      out.v_tol[i][k] = ulps * (scale_v[i][k] + vel_max[i]) + 1e-12;
    }
  return out;
}

}  // namespace octocd
