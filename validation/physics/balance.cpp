// The physics tier's rows 7, momentum balance per body (a body's velocity change is its
// contact rows' impulses), and 8, free flight (a body without contacts follows gravity
// and its spin), on every frame with states (physics_impl.hpp).
#include "physics_impl.hpp"

#include "../src/row_clock.hpp"

#include <algorithm>
#include <cmath>
#include <optional>

#include "octocd/reference_contact.hpp"

namespace octocd {

using namespace dmath;
using namespace physics_detail;

// ---- Rows 7-8: momentum balance per body and free flight, every frame with states ---
namespace {
/// Unit vector of a (double; zero stays zero).
D3 unit3(D3 a) {
  const double l = len3(a);
  return l > 0 ? (1.0 / l) * a : D3{};
}
/// Angle (rad) between two orientations (the rotation q1 q0^-1), sign of q ignored.
double quat_angle(Quat a, Quat b) {
  const double na = std::sqrt(double(a.w) * a.w + double(a.x) * a.x + double(a.y) * a.y + double(a.z) * a.z);
  const double nb = std::sqrt(double(b.w) * b.w + double(b.x) * b.x + double(b.y) * b.y + double(b.z) * b.z);
  const double d = std::fabs(double(a.w) * b.w + double(a.x) * b.x + double(a.y) * b.y + double(a.z) * b.z) /
                   (na * nb);
  return 2.0 * std::acos(std::min(1.0, d));
}
/// q advanced by the rotation w dt (exponential map: the quaternion of angle |w| dt about
/// w, applied in the world frame: q' = dq q), in double.
std::array<double, 4> advanced(Quat q, D3 w, double dt) {
  const double angle = len3(w) * dt;
  double dw = 1, dx = 0, dy = 0, dz = 0;
  if (angle > 0) {
    const D3 axis = unit3(w);
    const double s = std::sin(0.5 * angle);
    dw = std::cos(0.5 * angle);
    dx = s * axis[0];
    dy = s * axis[1];
    dz = s * axis[2];
  }
  return {dw * q.w - dx * q.x - dy * q.y - dz * q.z, dw * q.x + dx * q.w + dy * q.z - dz * q.y,
          dw * q.y - dx * q.z + dy * q.w + dz * q.x, dw * q.z + dx * q.y - dy * q.x + dz * q.w};
}
double quat_angle(const std::array<double, 4>& a, Quat b) {
  return quat_angle(Quat{float(a[0]), float(a[1]), float(a[2]), float(a[3])}, b);
}
}  // namespace

void PhysicsValidators::Impl::balance(const FrameRecord& rec, const std::vector<Pose>& det) {
  const Model& m = *model;
  const std::size_t n = m.bodies.size();
  const std::int64_t frame = rec.frame;
  const bool states = rec.x_pre.size() == n && rec.v_pre.size() == n && rec.x_post.size() == n &&
                      rec.v_post.size() == n;
  if (!states) return;
  const bool rotating = rec.q_pre.size() == n && rec.q_post.size() == n && rec.w_pre.size() == n &&
                        rec.w_post.size() == n;
  const D3 g = d3(m.scene.gravity);
  const double dt = m.scene.dt;
  const double eps = tol.balance_ulps * kEps32;
  StopPoll poll(stop);
  std::optional<RowClock> clock(std::in_place, t_balance);
  auto v_int = [&](std::size_t i) { return d3(rec.v_pre[i]) + dt * g; };  // dynamic bodies
  auto w_of = [&](const std::vector<Vec3>& w, std::size_t i) { return rotating ? d3(w[i]) : D3{}; };
  auto locked = [&](std::size_t i) -> unsigned { return bodies.locked_dofs.empty() ? 0u : bodies.locked_dofs[i]; };
  // Zeroes the components about locked world axes (bits `first` .. first + 2).
  auto unlocked = [&](D3 a, std::size_t i, int first) {
    for (int k = 0; k < 3; ++k)
      if (locked(i) & (1u << (first + k))) a[static_cast<std::size_t>(k)] = 0;
    return a;
  };
  auto clamped = [&](std::size_t i) {
    if (!(bodies.velocity_clamp > 0.0)) return false;
    const Vec3 v = rec.v_post[i];
    const double c = bodies.velocity_clamp * (1.0 - 1e-6);
    return std::fabs(v.x) >= c || std::fabs(v.y) >= c || std::fabs(v.z) >= c;
  };

  // Each row's impulse J = jn n + J_t on A (and -J on B), summed per body with its torque
  // about the body's detection-pose position, and what the record leaves uncertain.
  std::vector<D3> force(n), torque(n);
  std::vector<double> mag(n, 0.0), tmag(n, 0.0), tallow(n, 0.0);
  // Per body, what the record leaves open of its rows' friction: a disc of radius u in the
  // plane normal to n per row (direction and size of J_t beyond the scalar jt).
  struct Disc {
    D3 n;
    double u;
  };
  std::vector<std::vector<Disc>> discs(n);
  std::vector<std::uint32_t> rows_of(n, 0);
  std::vector<std::uint8_t> in_contact(n, 0);
  for (const Pair& p : rec.confirmed) in_contact[p.a] = in_contact[p.b] = 1;
  for (std::size_t k = 0; k < rec.contacts.size(); ++k) {
    const ContactRecord& c = rec.contacts[k];
    const Pair p = c.pair;
    in_contact[p.a] = in_contact[p.b] = 1;
    ++rows_of[p.a];
    ++rows_of[p.b];
    const D3 nrm = unit3(d3(c.normal));
    const D3 xa = d3(det[p.a].position), xb = d3(det[p.b].position);
    const D3 pt = rec.has_points ? d3(c.point) : D3{};
    const D3 ra = rec.has_points ? pt - xa : D3{}, rb = rec.has_points ? pt - xb : D3{};
    // The friction impulse's direction: the trace convention's -v_t / |v_t|, v_t the
    // tangential velocity of A relative to B at the row's point before the solver
    // (v_pre + dt g on dynamic bodies, w_pre); octocd's records: J_t along +t.
    const D3 va = (dynamic(p.a) ? v_int(p.a) : d3(rec.v_pre[p.a])) + cross3(w_of(rec.w_pre, p.a), ra);
    const D3 vb = (dynamic(p.b) ? v_int(p.b) : d3(rec.v_pre[p.b])) + cross3(w_of(rec.w_pre, p.b), rb);
    const D3 rel = va - vb;
    const D3 vt = rel - dot3(rel, nrm) * nrm;
    const double vt_len = len3(vt);
    const bool vector_friction = rec.jt3.size() == rec.contacts.size();
    const double jt = vector_friction ? len3(d3(rec.jt3[k])) : std::fabs(double(c.jt));
    D3 jt_vec{};
    double uncertain = 0;  // |J_t - jt_vec| at most this (kg m/s), in the tangent plane
    if (vector_friction) {
      jt_vec = d3(rec.jt3[k]);  // /contacts/jt3: the friction impulse on A, nothing left open
    } else if (vt_len > tol.friction_direction_speed) {
      jt_vec = (bodies.jt_along_sliding ? double(c.jt) : -double(c.jt)) * ((1.0 / vt_len) * vt);
      if (rotating && rec.has_points) {
        // An engine may take each body's velocity at its own witness point (Bullet), up
        // to the depth or the contact margin apart along the normal: v_t there differs by
        // up to (|w_a| + |w_b|) s, turning the direction by at most that over |v_t|; the
        // part of J_t across the recorded direction is not in a scalar jt.
        const double s = double(c.depth) + pair_margin(p);
        const double turn =
            std::min(2.0, (len3(w_of(rec.w_pre, p.a)) + len3(w_of(rec.w_pre, p.b))) * s / vt_len);
        uncertain = turn * (jt + pair_mu(p) * std::fabs(double(c.jn)));
      }
    } else if (vt_len > kNoSliding) {
      // Nearly no sliding before the step: the engine picks the friction direction
      // itself (Bullet below sqrt(FLT_EPSILON) = 3.45e-4 m/s: btPlaneSpace1's axis), and a
      // scalar jt, the impulse's projection on the recorded -v_t, says neither which nor
      // how large J_t is; it lies in the cone (the friction row judges that).
      // A row's own cone, with the margin a sequential solver leaves on a row whose normal
      // impulse moved to the manifold's other rows after its friction was clamped (Bullet:
      // up to 13% above mu times the row's final jn; the friction row holds the pair's sum
      // to the cone itself). Never with jt3; what it leaves open is stated in
      // docs/validate-your-engine.md, "The row cone margin".
      constexpr double kRowConeMargin = 0.25;
      uncertain = std::max(jt, pair_mu(p) * std::fabs(double(c.jn)) * (1.0 + kRowConeMargin) + tol.friction_cone_abs);
    } else {
      // No sliding: v_t has no direction; jt is the friction impulse's magnitude (the
      // convention, and octocd's Bullet adapter below 1e-6 m/s), its direction open.
      uncertain = jt;
    }
    const D3 j = double(c.jn) * nrm + jt_vec;
    force[p.a] = force[p.a] + j;
    force[p.b] = force[p.b] - j;
    mag[p.a] += len3(j) + uncertain;
    mag[p.b] += len3(j) + uncertain;
    if (uncertain > 0) {
      discs[p.a].push_back({nrm, uncertain});
      discs[p.b].push_back({nrm, uncertain});
    }
    if (rec.has_points) {
      torque[p.a] = torque[p.a] + cross3(ra, j);
      torque[p.b] = torque[p.b] - cross3(rb, j);
      // An engine may apply the row at a witness point on each body (Bullet) instead of
      // the recorded point between them: the two lie the depth apart along the normal
      // (which moves the friction part's lever) and, in a persistent manifold, up to the
      // contact margin apart sideways as the bodies move before the point is dropped
      // (which moves the normal part's lever): half of that from the recorded point.
      const double s = double(c.depth) + pair_margin(p);
      const double lever = s * (jt + uncertain) + 0.5 * s * std::fabs(double(c.jn));
      tallow[p.a] += len3(ra) * uncertain + lever;
      tallow[p.b] += len3(rb) * uncertain + lever;
      tmag[p.a] += len3(ra) * (len3(j) + uncertain);
      tmag[p.b] += len3(rb) * (len3(j) + uncertain);
    }
  }

  for (std::size_t i = 0; i < n; ++i) {
    if (!dynamic(static_cast<std::uint32_t>(i))) continue;
    if ((i & 63u) == 0) poll();
    const double mi = mass[i];
    const D3 v0 = v_int(i), v1 = d3(rec.v_post[i]);
    const D3 w0 = w_of(rec.w_pre, i), w1 = w_of(rec.w_post, i);
    const M3 iw = rotating ? conjugated(rotation(det[i].orientation), inertia[i]) : M3{};
    // The gyroscopic term dt w x I_w w of the step (zero without rotation).
    const D3 gyro_term = rotating ? dt * cross3(w0, mul(iw, w0)) : D3{};
    const D3 gyro = bodies.gyroscopic ? gyro_term : D3{};
    const double locked_count = double(locked(i) != 0);
    if (clamped(i)) {
      ++balance_clamped;
      continue;
    }
    if (in_contact[i]) {
      // 7. Momentum balance.
      if (rows_of[i] == 0) {
        ++balance_no_rows;  // a confirmed pair without rows (octocd's later passes)
        continue;
      }
      if (!bodies.impulses_complete) continue;
      if (locked(i)) ++balance_locked;
      const D3 dp = unlocked(mi * (v1 - v0) - force[i], i, 0);
      const double float_bound =
          eps * double(rows_of[i] + 2) * (mi * (len3(d3(rec.v_pre[i])) + len3(v1) + len3(dt * g)) + mag[i]) + 1e-9;
      // The residual must lie in the sum of the rows' friction discs (plus rounding): its
      // component along a direction d is at most sum u |d x n| + the rounding bound. Tested
      // along the residual itself and along each row's normal (where a manifold's discs,
      // all normal to it, allow nothing: a dropped row's jn n shows there).
      double ratio = 0, open_along = 0;
      const double dpl = len3(dp);
      auto test_dir = [&](D3 d) {
        double support = 0;
        for (const Disc& dc : discs[i]) support += dc.u * len3(cross3(d, dc.n));
        const double r = std::fabs(dot3(dp, d)) / (support + float_bound);
        if (r > ratio) {
          ratio = r;
          open_along = support;
        }
      };
      if (dpl > 0) test_dir((1.0 / dpl) * dp);
      for (const Disc& dc : discs[i]) test_dir(dc.n);
      if (discs[i].empty()) ratio = dpl / float_bound;
      balance_lin.check(ratio <= 1.0, ratio, Where::of_body(frame, i), [&] {
        return fmt::format("frame {}: body {}: m (v' - v) - m g dt = ({:.4g}, {:.4g}, {:.4g}) kg m/s but its {} "
                           "contact rows' impulses sum to ({:.4g}, {:.4g}, {:.4g}): off by {:.4g} ({:.3g} of the "
                           "bound: rounding {:.3g}, friction the record leaves open {:.3g})",
                           frame, i, mi * (v1[0] - v0[0]), mi * (v1[1] - v0[1]), mi * (v1[2] - v0[2]), rows_of[i],
                           force[i][0], force[i][1], force[i][2], dpl, ratio, float_bound, open_along);
      });
      if (!rotating || !rec.has_points) continue;
      if ((locked(i) >> 3) == 7u) {  // every rotation locked by a joint
        ++balance_rot_locked;
        continue;
      }
      // Declared gyroscopic: the term is required (within gyroscopic_rel of it).
      // Undeclared: allowed either way on a body in contact: an engine may apply it only
      // to the bodies its solver sees (Bullet's BT_ENABLE_GYROSCOPIC_FORCE_IMPLICIT_BODY
      // acts in the solver's islands, on bodies with contacts, never on free ones:
      // bunny-stack-50, a bunny spinning at 8.9 rad/s on a row with jn = 0); free-flight
      // holds free bodies to the declaration.
      const double rounding =
          eps * double(rows_of[i] + 2) * (len3(mul(iw, w0)) + len3(mul(iw, w1)) + tmag[i]) + tallow[i] + 1e-9;
      const double gyro_allow = tol.gyroscopic_rel * len3(gyro_term);
      D3 lhs = mul(iw, w1 - w0) + gyro;
      double dll = len3(unlocked(lhs - torque[i], i, 3));
      double ang_bound = rounding + (bodies.gyroscopic ? gyro_allow : 0.0);
      bool with_term = bodies.gyroscopic;
      if (!bodies.gyroscopic && len3(gyro_term) > 0) {
        const D3 lhs_with = lhs + gyro_term;
        const double dl_with = len3(unlocked(lhs_with - torque[i], i, 3));
        if (dl_with / (rounding + gyro_allow) < dll / ang_bound) {
          lhs = lhs_with;
          dll = dl_with;
          ang_bound = rounding + gyro_allow;
          with_term = true;
        }
      }
      balance_ang.check(dll <= ang_bound, dll / ang_bound, Where::of_body(frame, i), [&] {
        return fmt::format("frame {}: body {}: I_w (w' - w){} = ({:.4g}, {:.4g}, {:.4g}) kg m^2/s but its {} "
                           "contact rows' torques (p - x) x J sum to ({:.4g}, {:.4g}, {:.4g}): off by {:.4g} "
                           "(bound {:.3g})",
                           frame, i, with_term ? " + dt w x I_w w" : "", lhs[0], lhs[1], lhs[2], rows_of[i],
                           torque[i][0], torque[i][1], torque[i][2], dll, ang_bound);
      });
      continue;
    }
    // 8. Free flight: no contact row and no confirmed pair in this step.
    if (locked_count > 0) ++free_locked;
    const D3 dv = unlocked(v1 - v0, i, 0);
    const double v_bound = 4.0 * kEps32 * (len3(d3(rec.v_pre[i])) + len3(v1) + len3(dt * g)) + 1e-12;
    const double dvl = len3(dv);
    free_vel.check(dvl <= v_bound, dvl, Where::of_body(frame, i), [&] {
      return fmt::format("frame {}: body {} without contacts: v' = ({:.6g}, {:.6g}, {:.6g}) m/s, v + g dt = "
                         "({:.6g}, {:.6g}, {:.6g}): off by {:.4g} m/s (bound {:.3g})",
                         frame, i, v1[0], v1[1], v1[2], v0[0], v0[1], v0[2], dvl, v_bound);
    });
    const D3 x0 = d3(rec.x_pre[i]), x1 = d3(rec.x_post[i]);
    const D3 semi = x0 + dt * v1, expl = x0 + dt * d3(rec.v_pre[i]);
    const double d_semi = len3(unlocked(x1 - semi, i, 0)), d_expl = len3(unlocked(x1 - expl, i, 0));
    const double dx = bodies.integrator == PhysicsBodies::Integrator::SemiImplicit ? d_semi
                      : bodies.integrator == PhysicsBodies::Integrator::Explicit ? d_expl
                                                                                  : std::min(d_semi, d_expl);
    const double x_bound =
        4.0 * kEps32 * (len3(x0) + len3(x1) + dt * (len3(v1) + len3(d3(rec.v_pre[i])))) + 1e-12;
    free_pos.check(dx <= x_bound, dx, Where::of_body(frame, i), [&] {
      return fmt::format("frame {}: body {} without contacts: x' = ({:.6g}, {:.6g}, {:.6g}) m is {:.4g} m from x + "
                         "dt v{} (integrator {}; bound {:.3g})",
                         frame, i, x1[0], x1[1], x1[2], dx,
                         bodies.integrator == PhysicsBodies::Integrator::Explicit ? "" : "'",
                         integrator_name(bodies.integrator), x_bound);
    });
    if (!rotating) continue;
    // w' = w, less the declared gyroscopic term: I_w (w' - w) = -dt w x I_w w.
    const D3 dw_expected = bodies.gyroscopic ? -1.0 * mul(inverse(iw), gyro) : D3{};
    const D3 dw = unlocked(w1 - w0 - dw_expected, i, 3);
    // 8 eps32 per |w|: a float engine's free step may turn w into the body frame and back
    // (Bullet's implicit gyroscopic step: two quatRotate, each two quaternion products);
    // Bullet on rot-pile-1000 measured 8.04 eps32 |w| (3.02e-05 rad/s at 31.6 rad/s).
    const double w_bound = 8.0 * kEps32 * (len3(w0) + len3(w1)) + tol.gyroscopic_rel * len3(dw_expected) + 1e-9;
    const double dwl = len3(dw);
    free_w.check(dwl <= w_bound, dwl, Where::of_body(frame, i), [&] {
      return fmt::format("frame {}: body {} without contacts: w' = ({:.6g}, {:.6g}, {:.6g}) rad/s, w{} = "
                         "({:.6g}, {:.6g}, {:.6g}): off by {:.4g} rad/s (bound {:.3g})",
                         frame, i, w1[0], w1[1], w1[2], bodies.gyroscopic ? " - dt I_w^-1 (w x I_w w)" : "",
                         w0[0] + dw_expected[0], w0[1] + dw_expected[1], w0[2] + dw_expected[2], dwl, w_bound);
    });
    if (locked(i) >> 3) continue;  // a joint turns it: counted in free_locked
    const Quat q0 = rec.q_pre[i], q1 = rec.q_post[i];
    const double a_semi = quat_angle(advanced(q0, w1, dt), q1), a_expl = quat_angle(advanced(q0, w0, dt), q1);
    const double angle = bodies.integrator == PhysicsBodies::Integrator::SemiImplicit ? a_semi
                         : bodies.integrator == PhysicsBodies::Integrator::Explicit ? a_expl
                                                                                     : std::min(a_semi, a_expl);
    const double wdt = std::max(len3(w0), len3(w1)) * dt;
    const double q_bound = tol.free_flight_angle_rad + wdt * wdt;
    free_q.check(angle <= q_bound, angle * 180.0 / kPi, Where::of_body(frame, i), [&] {
      return fmt::format("frame {}: body {} without contacts: q' is {:.4g} deg from q advanced by w{} dt (|w| dt "
                         "{:.3g} rad; bound {:.3g} deg)",
                         frame, i, angle * 180.0 / kPi,
                         bodies.integrator == PhysicsBodies::Integrator::Explicit ? "" : "'", wdt,
                         q_bound * 180.0 / kPi);
    });
  }
}

}  // namespace octocd
