// The physics tier's rows 7, momentum balance per body (a body's velocity change is its
// contact rows' impulses), and 8, free flight (a body without contacts follows gravity
// and its spin), on every frame with states (physics_impl.hpp).
#include "physics_impl.hpp"

#include "../src/parallel.hpp"
#include "../src/row_clock.hpp"
#include "ordered_judge.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <optional>

#include "octocd/reference_contact.hpp"

namespace octocd {

namespace {

/// " (gyroscopic term declared)", " (no gyroscopic term declared)", or undeclared how
/// many passing body-steps kept w (no term) and how many met the invariants of the term.
std::string spin_note(PhysicsBodies::Gyroscopic g, std::uint64_t kept, std::uint64_t invariant) {
  switch (g) {
    case PhysicsBodies::Gyroscopic::Integrated: return " (gyroscopic term declared)";
    case PhysicsBodies::Gyroscopic::Absent: return " (no gyroscopic term declared)";
    case PhysicsBodies::Gyroscopic::Undeclared: break;
  }
  return fmt::format(" (gyroscopic term undeclared: {} kept w, {} precessed keeping L and the energy; declare "
                     "gyroscopic to sharpen the verdict)",
                     kept, invariant);
}

}  // namespace

using namespace dmath;
using namespace physics_detail;

// ---- Rows 7-8: momentum balance per body and free flight, every frame with states ---
namespace {
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
    const D3 axis = unit(w);
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

/// Free rotation's bounds per torque-free step (docs/validation.md, "Free rotation: the
/// invariants"), for principal moments I1 <= I3 (pm), step dt, the larger of |w|, |w'|
/// (om), |w' - w| (dw) and the larger of |L|, |L'| (l): a first-order integrator of the
/// Euler equations (explicit, implicit or one Newton step of it; the orientation advanced
/// by w or w') keeps the world angular momentum L = R I R^T w to
///     |L' - L| <= 5/2 D dt^2 om^3 + (1 + dt om) dt dw l,  D = (I3 - I1) / 2,
/// D om^2 bounding |w x L| (zero for an isotropic body), and raises the rotational energy
/// w . L / 2 by at most 1/2 D^2 / I1 dt^2 om^4 + dt dw D om^2 (explicit Euler's rise; the
/// second term where the orientation is advanced by the other end's w).
struct SpinBounds {
  double momentum = 0, energy = 0;
};
SpinBounds spin_bounds(const std::array<double, 2>& pm, double dt, double om, double dw, double l) {
  const double i1 = pm[0], i3 = pm[1];
  const double d = i3 > i1 ? 0.5 * (i3 - i1) : 0.0, h2 = dt * dt * om * om;
  SpinBounds b;
  b.momentum = 2.5 * d * h2 * om + (1.0 + dt * om) * dt * dw * l;
  b.energy = (i1 > 0 ? 0.5 * d * d / i1 * h2 * om * om : 0.0) + dt * dw * d * om * om;
  return b;
}
/// The ratio (<= 1 passes) of a spin check judged two ways: `r_plain` without the
/// gyroscopic term, `r_inv` by the invariant of free rotation. An engine declaring its
/// gyroscopic term (Integrated) or its absence (Absent) is judged by that one; an undeclared
/// one by the better of the two, counting in `plain` or `invariant` which one passed.
double spin_ratio(PhysicsBodies::Gyroscopic g, double r_plain, double r_inv, std::uint64_t& plain,
                  std::uint64_t& invariant) {
  using G = PhysicsBodies::Gyroscopic;
  const double r = g == G::Integrated ? r_inv : g == G::Absent ? r_plain : std::min(r_plain, r_inv);
  if (g == G::Undeclared && r <= 1.0) ++(r_plain <= 1.0 ? plain : invariant);
  return r;
}

/// The fewest contact rows summed, and the fewest bodies judged, on the validators' threads
/// (rows 7 and 8): a row's terms cost about 300 instructions, a body's judgement about 500;
/// below these one thread costs less than waking another.
constexpr std::size_t kParallelBalanceRowsFrom = 1024;
constexpr std::size_t kParallelBodiesFrom = 1024;
/// The fewest bodies whose kept sums are reset on the threads after a frame (a byte read
/// per body, a few stores per body in contact).
constexpr std::size_t kParallelBalanceResetFrom = 16384;

/// Values a block adds to a RatioSample, added to the Impl's in block order.
struct SampleLog {
  std::vector<double> values;
  void add(double v) { values.push_back(v); }
};

/// Rows 7 and 8's own state that a block of bodies judged on a thread writes
/// (judge_in_order): the Impl's members of the same names. A body-step deferred to the
/// fitted ratio (a linear failure at ratio 1) makes its block be judged again live.
template <class Deferred, class Disc>
struct BalanceDry {
  std::uint64_t fell_asleep = 0, balance_clamped = 0, balance_incomplete = 0, balance_no_rows = 0,
                balance_locked = 0, origin_drift_balance = 0, deferred_over = 0, balance_rot_locked = 0,
                balance_ang_plain = 0, balance_ang_invariant = 0, free_near = 0, free_locked = 0,
                origin_drift_free = 0, free_spin_kept = 0, free_spin_invariant = 0;
  double origin_drift_balance_worst = 0, origin_drift_free_worst = 0;
  std::vector<Deferred> deferred;
  std::vector<Disc> deferred_discs;
  std::vector<D3> deferred_rows;
  SampleLog ratio_sample, spread_sample;
  template <class Live>
  bool describes(const Live&) const {
    return !deferred.empty() || deferred_over > 0;
  }
  template <class Live>
  void merge_into(Live& s) const {
    for (auto [to, from] : {std::pair{&s.fell_asleep, fell_asleep}, {&s.balance_clamped, balance_clamped},
                            {&s.balance_incomplete, balance_incomplete}, {&s.balance_no_rows, balance_no_rows},
                            {&s.balance_locked, balance_locked}, {&s.origin_drift_balance, origin_drift_balance},
                            {&s.balance_rot_locked, balance_rot_locked}, {&s.balance_ang_plain, balance_ang_plain},
                            {&s.balance_ang_invariant, balance_ang_invariant}, {&s.free_near, free_near},
                            {&s.free_locked, free_locked}, {&s.origin_drift_free, origin_drift_free},
                            {&s.free_spin_kept, free_spin_kept}, {&s.free_spin_invariant, free_spin_invariant}})
      *to += from;
    // The largest figures: the serial loop's running maxima (each starts at 0).
    s.origin_drift_balance_worst = std::max(s.origin_drift_balance_worst, origin_drift_balance_worst);
    s.origin_drift_free_worst = std::max(s.origin_drift_free_worst, origin_drift_free_worst);
    for (double v : ratio_sample.values) s.ratio_sample.add(v);
    for (double v : spread_sample.values) s.spread_sample.add(v);
  }
};

}  // namespace

void PhysicsValidators::Impl::balance(const FrameRecord& rec, const std::vector<Pose>& det) {
  const std::array<Tally*, 7> row_tallies{
      &tally(RowId::MomentumBalance, "linear"),    &tally(RowId::MomentumBalance, "angular"),
      &tally(RowId::FreeFlight, "velocity"),       &tally(RowId::FreeFlight, "position"),
      &tally(RowId::FreeFlight, "angular-velocity"), &tally(RowId::FreeFlight, "orientation"),
      &tally(RowId::FreeFlight, "sleeping")};
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
  // In the kept per-body sums (BalanceScratch: zero and empty on entry, the bodies of this
  // frame's rows and confirmed pairs reset on leaving).
  BalanceScratch& scratch = balance_scratch;
  if (scratch.force.size() != n) {
    scratch = BalanceScratch{};
    scratch.force.resize(n);
    scratch.torque.resize(n);
    for (auto* v : {&scratch.mag, &scratch.tmag, &scratch.tallow, &scratch.any_dir}) v->assign(n, 0.0);
    scratch.discs.resize(n);
    scratch.row_j.resize(n);
    scratch.rows_of.assign(n, 0);
    scratch.in_contact.assign(n, 0);
  }
  struct Reset {
    BalanceScratch& s;
    unsigned threads;
    ~Reset() {
      // Every body written below is marked in_contact (the counting pass), and only those
      // are cleared: each body once, on the threads (no stop: the sums must be clean).
      LoopOptions o;
      o.threads = static_cast<int>(threads);
      o.min_items = kParallelBalanceResetFrom;
      parallel_for(s.in_contact.size(), o, [&](std::size_t i, unsigned) {
        if (!s.in_contact[i]) return;
        s.force[i] = s.torque[i] = D3{};
        s.mag[i] = s.tmag[i] = s.tallow[i] = s.any_dir[i] = 0.0;
        s.discs[i].clear();
        s.row_j[i].clear();
        s.rows_of[i] = 0;
        s.in_contact[i] = 0;
      });
    }
  } reset{scratch, loop_threads(threads, n, kParallelBalanceResetFrom)};
  std::vector<D3>& force = scratch.force;
  std::vector<D3>& torque = scratch.torque;
  std::vector<double>& mag = scratch.mag;
  std::vector<double>& tmag = scratch.tmag;
  std::vector<double>& tallow = scratch.tallow;
  std::vector<double>& any_dir = scratch.any_dir;
  // Per body, what the record leaves open of its rows' friction: a disc of radius u in the
  // plane normal to n per row (direction and size of J_t beyond the scalar jt).
  using Disc = BalanceDisc;
  std::vector<std::vector<Disc>>& discs = scratch.discs;
  std::vector<std::vector<D3>>& row_j = scratch.row_j;  // each row's impulse on the body (the spread's terms)
  std::vector<std::uint32_t>& rows_of = scratch.rows_of;
  std::vector<std::uint8_t>& in_contact = scratch.in_contact;
  // On the threads, each owning a range of bodies: a thread computes the rows with a body
  // of its own and sums them into its bodies only, in row order (each body's sums are the
  // serial loop's, bit for bit). A row with bodies of two ranges is computed by both.
  const unsigned row_threads = loop_threads(threads, rec.contacts.size(), kParallelBalanceRowsFrom);
  // Each body's rows counted and its links marked (in_contact), then room made for its
  // rows (kept from frame to frame, grown where a body has more rows than before), by
  // the same ranges.
  parallel_items_on(row_threads, row_threads, stop, [&](std::size_t range, unsigned) {
    const std::uint32_t lo = static_cast<std::uint32_t>(n * range / row_threads),
                        hi = static_cast<std::uint32_t>(n * (range + 1) / row_threads);
    auto own = [&](std::uint32_t i) { return i >= lo && i < hi; };
    for (const Pair& p : rec.confirmed)
      for (const std::uint32_t i : {p.a, p.b})
        if (own(i)) in_contact[i] = 1;
    for (const ContactRecord& c : rec.contacts)
      for (const std::uint32_t i : {c.pair.a, c.pair.b})
        if (own(i)) {
          in_contact[i] = 1;
          ++rows_of[i];
        }
    for (std::uint32_t i = lo; i < hi; ++i)
      if (rows_of[i]) {
        row_j[i].reserve(rows_of[i]);
        discs[i].reserve(rows_of[i]);
      }
  });
  parallel_items_on(row_threads, row_threads, stop, [&](std::size_t range, unsigned) {
    const std::size_t lo = n * range / row_threads, hi = n * (range + 1) / row_threads;
    for (std::size_t k = 0; k < rec.contacts.size(); ++k) {
      const ContactRecord& c = rec.contacts[k];
      const Pair p = c.pair;
      const bool own_a = p.a >= lo && p.a < hi, own_b = p.b >= lo && p.b < hi;
      if (!own_a && !own_b) continue;
      const D3 nrm = unit(d3(c.normal));
      const D3 xa = com_at(det[p.a], p.a), xb = com_at(det[p.b], p.b);
      // The row's point on A, and on B where the record gives a second witness point
      // (FrameRecord::point_b: the engine applied B's impulse there).
      const bool two_points = rec.has_points && rec.point_b.size() == rec.contacts.size();
      const D3 pt = rec.has_points ? d3(c.point) : D3{};
      const D3 ra = rec.has_points ? pt - xa : D3{}, rb = rec.has_points ? d3(point_on_b(rec, k)) - xb : D3{};
      // The friction impulse's direction: the trace convention's -v_t / |v_t|, v_t the
      // tangential velocity of A relative to B at the row's point before the solver
      // (v_pre + dt g on dynamic bodies, w_pre); octocd's records: J_t along +t.
      const D3 va = (dynamic(p.a) ? v_int(p.a) : d3(rec.v_pre[p.a])) + cross3(w_of(rec.w_pre, p.a), ra);
      const D3 vb = (dynamic(p.b) ? v_int(p.b) : d3(rec.v_pre[p.b])) + cross3(w_of(rec.w_pre, p.b), rb);
      const D3 rel = va - vb;
      const D3 vt = rel - dot3(rel, nrm) * nrm;
      const double vt_len = len3(vt);
      const bool normal_only = bodies.impulses == PhysicsBodies::Impulses::NormalOnly;
      const bool vector_friction = rec.jt3.size() == rec.contacts.size() && !normal_only;
      const double jt = normal_only ? 0.0 : vector_friction ? len3(d3(rec.jt3[k])) : std::fabs(double(c.jt));
      D3 jt_vec{};
      double uncertain = 0;  // |J_t - jt_vec| at most this (kg m/s), in the tangent plane
      if (normal_only) {
        // The friction is not reported (jt, jt3 never read): J_t is anywhere in the row's
        // cone, with the row cone margin below (a sequential solver's row whose jn moved).
        uncertain = pair_mu(p) * std::fabs(double(c.jn)) * (1.0 + kRowConeMargin) + tol.friction_cone_abs;
      } else if (vector_friction) {
        jt_vec = d3(rec.jt3[k]);  // /contacts/jt3: the friction impulse on A, nothing left open
      } else if (vt_len > tol.friction_direction_speed) {
        jt_vec = (bodies.jt_along_sliding ? double(c.jt) : -double(c.jt)) * ((1.0 / vt_len) * vt);
        if (rotating && rec.has_points && !two_points) {
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
        uncertain = std::max(jt, pair_mu(p) * std::fabs(double(c.jn)) * (1.0 + kRowConeMargin) + tol.friction_cone_abs);
      } else {
        // No sliding: v_t has no direction; jt is the friction impulse's magnitude (the
        // convention, and octocd's Bullet adapter below 1e-6 m/s), its direction open.
        uncertain = jt;
      }
      // Substeps (declared or undeclared, rotating records): the engine applies the row's
      // impulse in parts through the step, its normal and its points turning with the two
      // bodies, by at most theta = (|w_a| + |w_b|) dt (the larger of |w|, |w'| each): jn n
      // leaves n into the tangent plane by |jn| theta (a disc), J_t leaves the plane by
      // |J_t| theta (any direction), and the lever of both turns by |r| |J| theta
      // (docs/validation.md, "Free flight: any consistent integrator").
      double theta = 0;
      if (bodies.may_substep() && rotating) {
        const double wa = std::max(len3(w_of(rec.w_pre, p.a)), len3(w_of(rec.w_post, p.a)));
        const double wb = std::max(len3(w_of(rec.w_pre, p.b)), len3(w_of(rec.w_post, p.b)));
        theta = std::min(2.0, (wa + wb) * dt);
        uncertain += theta * std::fabs(double(c.jn));
        if (own_a) any_dir[p.a] += theta * jt;
        if (own_b) any_dir[p.b] += theta * jt;
      }
      const D3 j = double(c.jn) * nrm + jt_vec;
      if (own_a) {
        force[p.a] = force[p.a] + j;
        row_j[p.a].push_back(j);
        mag[p.a] += len3(j) + uncertain;
        if (uncertain > 0) discs[p.a].push_back({nrm, uncertain});
      }
      if (own_b) {
        force[p.b] = force[p.b] - j;
        row_j[p.b].push_back(-1.0 * j);
        mag[p.b] += len3(j) + uncertain;
        if (uncertain > 0) discs[p.b].push_back({nrm, uncertain});
      }
      if (rec.has_points) {
        if (own_a) torque[p.a] = torque[p.a] + cross3(ra, j);
        if (own_b) torque[p.b] = torque[p.b] - cross3(rb, j);
        // An engine may apply the row at a witness point on each body (Bullet) instead of
        // the recorded point between them: the two lie the depth apart along the normal
        // (which moves the friction part's lever) and, in a persistent manifold, up to the
        // contact margin apart sideways as the bodies move before the point is dropped
        // (which moves the normal part's lever): half of that from the recorded point.
        // With both witness points recorded (point_b) each lever is the engine's own: none.
        const double s = two_points ? 0.0 : double(c.depth) + pair_margin(p);
        const double lever = s * (jt + uncertain) + 0.5 * s * std::fabs(double(c.jn));
        if (own_a) {
          tallow[p.a] += len3(ra) * (uncertain + theta * (std::fabs(double(c.jn)) + jt)) + lever;
          tmag[p.a] += len3(ra) * (len3(j) + uncertain);
        }
        if (own_b) {
          tallow[p.b] += len3(rb) * (uncertain + theta * (std::fabs(double(c.jn)) + jt)) + lever;
          tmag[p.b] += len3(rb) * (len3(j) + uncertain);
        }
      }
    }
  });

  // Bodies [first, last) into `s` (this Impl, or a block's BalanceDry) and the tallies,
  // on the threads and tallied in body order (judge_in_order).
  auto judge_bodies = [&](std::size_t first, std::size_t last, auto& s, auto& balance_lin, auto& balance_ang,
                          auto& free_vel, auto& free_pos, auto& free_w, auto& free_q, auto& free_sleep) {
    for (std::size_t i = first; i < last; ++i) {
      if (!dynamic(static_cast<std::uint32_t>(i))) continue;
      const double mi = mass[i];
      const D3 v0 = v_int(i), v1 = d3(rec.v_post[i]);
      const D3 w0 = w_of(rec.w_pre, i), w1 = w_of(rec.w_post, i);
      const M3 iw = rotating ? conjugated(rotation(det[i].orientation), inertia[i]) : M3{};
      const double locked_count = double(locked(i) != 0);
      if (asleep(rec.asleep_post, static_cast<std::uint32_t>(i))) {
        if (!asleep(rec.asleep_pre, static_cast<std::uint32_t>(i))) {
          ++s.fell_asleep;  // the engine zeroed its velocity: not a contact impulse, not free flight
          continue;
        }
        // Asleep through the step: the engine does not move it. Position, velocity,
        // orientation (q or -q) and angular velocity are kept within one float32 rounding
        // of each (2 x 2^-23 of the two values' magnitudes).
        const D3 x0 = d3(rec.x_pre[i]), x1 = d3(rec.x_post[i]), vb = d3(rec.v_pre[i]);
        double ratio = len3(x1 - x0) / (2.0 * kEps32 * (len3(x0) + len3(x1)) + 1e-12);
        ratio = std::max(ratio, len3(v1 - vb) / (2.0 * kEps32 * (len3(vb) + len3(v1)) + 1e-12));
        if (rotating) {
          ratio = std::max(ratio, len3(w1 - w0) / (2.0 * kEps32 * (len3(w0) + len3(w1)) + 1e-12));
          const Quat a = rec.q_pre[i], b = rec.q_post[i];
          const double dm = std::sqrt(double(a.w - b.w) * (a.w - b.w) + double(a.x - b.x) * (a.x - b.x) +
                                      double(a.y - b.y) * (a.y - b.y) + double(a.z - b.z) * (a.z - b.z));
          const double dp = std::sqrt(double(a.w + b.w) * (a.w + b.w) + double(a.x + b.x) * (a.x + b.x) +
                                      double(a.y + b.y) * (a.y + b.y) + double(a.z + b.z) * (a.z + b.z));
          ratio = std::max(ratio, std::min(dm, dp) / (4.0 * kEps32));
        }
        free_sleep.check(ratio <= 1.0, ratio, Where::of_body(frame, i), [&] {
          return fmt::format("frame {}: body {} asleep before and after the step (/states/sleeping) moved: x' - x = "
                             "({:.4g}, {:.4g}, {:.4g}) m, v' - v = ({:.4g}, {:.4g}, {:.4g}) m/s ({:.3g} of one "
                             "rounding); a sleeping body keeps its pose and velocity",
                             frame, i, x1[0] - x0[0], x1[1] - x0[1], x1[2] - x0[2], v1[0] - vb[0], v1[1] - vb[1],
                             v1[2] - vb[2], ratio);
        });
        continue;
      }
      if (clamped(i)) {
        ++s.balance_clamped;
        continue;
      }
      if (in_contact[i]) {
        // 7. Momentum balance.
        if (incomplete_body(frame, static_cast<std::uint32_t>(i))) {  // a row may be missing: not judged
          ++s.balance_incomplete;
          continue;
        }
        if (rows_of[i] == 0) {
          ++s.balance_no_rows;  // a confirmed pair without rows (octocd's later passes)
          continue;
        }
        if (!bodies.impulses_complete || bodies.impulses == PhysicsBodies::Impulses::None) continue;
        const D3& force_i = force[i];
        const D3& torque_i = torque[i];
        const double mag_i = mag[i], tmag_i = tmag[i], tallow_i = tallow[i], any_dir_i = any_dir[i];
        const std::vector<Disc>& discs_i = discs[i];
        const std::vector<D3>& row_j_i = row_j[i];
        if (locked(i)) ++s.balance_locked;
        const D3 dp = unlocked(mi * (v1 - v0) - force_i, i, 0);
        // integrated_point "origin": the centre of mass's drift under the origin's
        // first-order integration (docs/validation.md, "An engine that integrates the body origin").
        const OriginDrift drift = origin_drift(rec, static_cast<std::uint32_t>(i));
        if (bodies.integrated_origin && !bodies.com_offset.empty()) {
          ++s.origin_drift_balance;
          s.origin_drift_balance_worst = std::max(s.origin_drift_balance_worst, drift.velocity);
        }
        const double float_bound =
            eps * double(rows_of[i] + 2) * (mi * (len3(d3(rec.v_pre[i])) + len3(v1) + len3(dt * g)) + mag_i) + 1e-9 +
            any_dir_i + mi * drift.velocity;
        // The residual must lie in the sum of the rows' friction discs (plus rounding): its
        // component along a direction d is at most sum u |d x n| + the rounding bound. Tested
        // along the residual itself and along each row's normal (where a manifold's discs,
        // all normal to it, allow nothing: a dropped row's jn n shows there).
        const D3 mdv = unlocked(mi * (v1 - v0), i, 0), fi = unlocked(force_i, i, 0);
        double open_along = 0;
        const double ratio =
            balance_figure(mdv, fi, discs_i.data(), discs_i.size(), float_bound, 1.0, &open_along);
        const double dpl = len3(dp);
        // The systematic ratio's sample: s = (J . d) / (m dv . d) along the first direction d
        // (m dv's own, then each row's normal) where the record fixes it to kFitPrecision: the
        // rounding and the friction its rows leave open along d (sum u |d x n|) at most that
        // of m dv . d (docs/validation.md, "A systematic impulse ratio"). Where its rows all
        // push one way along d, s is also in the spread's sample ("A spread of reported
        // impulses").
        {
          auto sample_along = [&](const D3& d) {
            const double md = dot3(mdv, d);
            double open = float_bound;
            for (const Disc& dc : discs_i) open += dc.u * len3(cross3(d, dc.n));
            if (!(std::fabs(md) > 0) || open > kFitPrecision * std::fabs(md)) return false;
            const double jd = dot3(fi, d);
            s.ratio_sample.add(jd / md);
            double one_way = 0;
            for (const D3& j : row_j_i) one_way += std::fabs(dot3(unlocked(j, i, 0), d));
            if (one_way <= (1.0 + kFitPrecision) * std::fabs(jd)) s.spread_sample.add(jd / md);
            return true;
          };
          const double ml = len3(mdv);
          bool sampled = ml > 0 && sample_along((1.0 / ml) * mdv);
          for (const Disc& dc : discs_i)
            if (!sampled) sampled = sample_along(dc.n);
        }
        const bool defer = ratio > 1.0 && s.deferred.size() < kMaxDeferred;
        if (defer) {
          // Judged in results() at the fitted ratio too (fitted_balance).
          DeferredBalance d;
          d.frame = frame;
          d.body = static_cast<std::uint32_t>(i);
          d.rows = rows_of[i];
          d.mdv = mdv;
          d.force = fi;
          d.float_bound = float_bound;
          d.r1 = ratio;
          d.disc_first = s.deferred_discs.size();
          d.disc_count = discs_i.size();
          s.deferred_discs.insert(s.deferred_discs.end(), discs_i.begin(), discs_i.end());
          d.row_first = s.deferred_rows.size();
          d.row_count = row_j_i.size();
          for (const D3& j : row_j_i) s.deferred_rows.push_back(unlocked(j, i, 0));
          s.deferred.push_back(d);
        } else if (ratio > 1.0) {
          ++s.deferred_over;
        }
        if (!defer) balance_lin.check(ratio <= 1.0, ratio, Where::of_body(frame, i), [&] {
          return fmt::format("frame {}: body {}: m (v' - v) - m g dt = ({:.4g}, {:.4g}, {:.4g}) kg m/s but its {} "
                             "contact rows' impulses sum to ({:.4g}, {:.4g}, {:.4g}): off by {:.4g} ({:.3g} of the "
                             "bound: rounding {:.3g}{}, friction the record leaves open {:.3g})",
                             frame, i, mi * (v1[0] - v0[0]), mi * (v1[1] - v0[1]), mi * (v1[2] - v0[2]), rows_of[i],
                             force_i[0], force_i[1], force_i[2], dpl, ratio, float_bound,
                             drift.velocity > 0
                                 ? fmt::format(" with the origin integrator's drift m {:.3g}", mi * drift.velocity)
                                 : std::string(),
                             open_along);
        });
        if (!rotating || !rec.has_points) continue;
        if ((locked(i) >> 3) == 7u) {  // every rotation locked by a joint
          ++s.balance_rot_locked;
          continue;
        }
        // The contact torques' action on the spin (docs/validation.md, "Free rotation: the
        // invariants"). No gyroscopic term: I_w (w' - w) = the torques, I_w at the
        // detection pose. The term (any first-order form): the world angular momentum
        // L = R I R^T w, before the step and after it (R advanced by w' dt), changes by the
        // torques, within the free step's second-order bound and what applying the impulse
        // at either end of the step's rotation moves: dt (|I_w^-1 tau| |L| + |w| |tau|)
        // (the term taken from w or w', tau turned by the step). Undeclared: either.
        const double rounding =
            eps * double(rows_of[i] + 2) * (len3(mul(iw, w0)) + len3(mul(iw, w1)) + tmag_i) + tallow_i + 1e-9;
        const D3 plain = mul(iw, w1 - w0);
        const double d_plain = len3(unlocked(plain - torque_i, i, 3));
        // L' at q advanced by w' dt, not at the recorded q': an engine's position
        // correction turns a body in contact without changing its angular momentum
        // (Bullet's split impulse: 0.04 deg per step on a bunny 6 mm deep).
        const M3 iw0 = conjugated(rotation(rec.q_pre[i]), inertia[i]);
        const D3 l0 = mul(iw0, w0);
        const D3 l1 = turned(mul(iw0, w1), w1, dt);
        const double om = std::max(len3(w0), len3(w1));
        const double tau_hi = len3(torque_i) + tallow_i;
        const double i1 = principal[i][0];
        const double within = dt * (tau_hi * (i1 > 0 ? std::max(len3(l0), len3(l1)) / i1 : 0.0) + om * tau_hi);
        const double inv_bound =
            rounding + spin_bounds(principal[i], dt, om, len3(w1 - w0), std::max(len3(l0), len3(l1))).momentum + within;
        const double d_inv = len3(unlocked(l1 - l0 - torque_i, i, 3));
        const double r_plain = d_plain / rounding, r_inv = d_inv / inv_bound;
        using G = PhysicsBodies::Gyroscopic;
        const double r_ang = spin_ratio(bodies.gyroscopic, r_plain, r_inv, s.balance_ang_plain, s.balance_ang_invariant);
        balance_ang.check(r_ang <= 1.0, r_ang, Where::of_body(frame, i), [&] {
          const std::string plain_text =
              fmt::format("I_w (w' - w) = ({:.4g}, {:.4g}, {:.4g}) kg m^2/s (no gyroscopic term; off by {:.4g}, bound "
                          "{:.3g})",
                          plain[0], plain[1], plain[2], d_plain, rounding);
          const D3 dl = l1 - l0;
          const std::string inv_text = fmt::format(
              "L' - L = ({:.4g}, {:.4g}, {:.4g}) kg m^2/s (L = R I R^T w before the step and after it, R advanced by "
              "w' dt; off by {:.4g}, "
              "bound {:.3g}: rounding and witness points {:.3g}, free rotation's second order {:.3g}, the impulse "
              "within the step {:.3g})",
              dl[0], dl[1], dl[2], d_inv, inv_bound, rounding, inv_bound - rounding - within, within);
          const std::string lhs = bodies.gyroscopic == G::Integrated ? inv_text
                                  : bodies.gyroscopic == G::Absent   ? plain_text
                                                                     : plain_text + " and " + inv_text;
          return fmt::format("frame {}: body {}: {} but its {} contact rows' torques (p - x) x J sum to ({:.4g}, "
                             "{:.4g}, {:.4g}) (gyroscopic term {})",
                             frame, i, lhs, rows_of[i], torque_i[0], torque_i[1], torque_i[2],
                             gyroscopic_name(bodies.gyroscopic));
        });
        continue;
      }
      // 8. Free flight: no contact row and no confirmed pair in this step. On a step that may
      // lack rows (contacts_complete 0, /contacts/incomplete): and apart from every body of a
      // pair that may lack them through the step by the exact reference (apart.cpp).
      if (incomplete_body(frame, static_cast<std::uint32_t>(i)) && (near.frame != frame || near.body[i])) {
        ++s.free_near;
        continue;
      }
      if (locked_count > 0) ++s.free_locked;
      const D3 dv = unlocked(v1 - v0, i, 0);
      // Rounding: one float32 update of v (and of x below) per step, 4 eps32 of the
      // magnitudes; a declared substepped engine rounds once per substep: n - 1 more
      // (docs/validation.md, "Free flight: any consistent integrator").
      const double updates =
          bodies.integrator == PhysicsBodies::Integrator::Substepped ? 4.0 + double(bodies.substeps - 1) : 4.0;
      // integrated_point "origin": the centre of mass's drift under the origin's
      // first-order integration (docs/validation.md, "An engine that integrates the body origin").
      const OriginDrift drift = origin_drift(rec, static_cast<std::uint32_t>(i));
      if (bodies.integrated_origin && !bodies.com_offset.empty()) {
        ++s.origin_drift_free;
        s.origin_drift_free_worst = std::max(s.origin_drift_free_worst, drift.velocity);
      }
      const double v_bound = updates * kEps32 * (len3(d3(rec.v_pre[i])) + len3(v1) + len3(dt * g)) +
                             stored_origin_speed(rec, static_cast<std::uint32_t>(i)) * 2.0 * kEps32 + drift.velocity +
                             1e-12;
      const double dvl = len3(dv);
      free_vel.check(dvl <= v_bound, dvl, Where::of_body(frame, i), [&] {
        return fmt::format("frame {}: body {} without contacts: v' = ({:.6g}, {:.6g}, {:.6g}) m/s, v + g dt = "
                           "({:.6g}, {:.6g}, {:.6g}): off by {:.4g} m/s (bound {:.3g}{})",
                           frame, i, v1[0], v1[1], v1[2], v0[0], v0[1], v0[2], dvl, v_bound,
                           drift.velocity > 0 ? fmt::format(", the origin integrator's drift {:.3g}", drift.velocity)
                                              : std::string());
      });
      const D3 x0 = d3(rec.x_pre[i]), x1 = d3(rec.x_post[i]);
      // x' = x + dt v + a g dt^2 (v before the step): a = 1 semi-implicit (x + dt v'), 0
      // explicit, (n + 1) / (2n) for n substeps, any a in [0, 1] for `any` and undeclared
      // (the a nearest the record, clamped).
      using I = PhysicsBodies::Integrator;
      const D3 semi = x0 + dt * v1, expl = x0 + dt * d3(rec.v_pre[i]);
      const double d_semi = len3(unlocked(x1 - semi, i, 0)), d_expl = len3(unlocked(x1 - expl, i, 0));
      const D3 gdt2 = unlocked((dt * dt) * g, i, 0), rx = unlocked(x1 - expl, i, 0);
      const double g2 = dot3(gdt2, gdt2);
      double a_fit = bodies.integrator == I::Substepped ? 0.5 * double(bodies.substeps + 1) / double(bodies.substeps)
                     : g2 > 0                          ? std::clamp(dot3(rx, gdt2) / g2, 0.0, 1.0)
                                                       : 1.0;
      const double d_family = len3(rx - a_fit * gdt2);
      const double dx = bodies.integrator == I::SemiImplicit ? d_semi
                        : bodies.integrator == I::Explicit   ? d_expl
                        : bodies.integrator == I::Substepped ? d_family
                                                             : std::min({d_semi, d_expl, d_family});
      const double x_bound =
          updates * kEps32 * (len3(x0) + len3(x1) + dt * (len3(v1) + len3(d3(rec.v_pre[i])))) + drift.position + 1e-12;
      free_pos.check(dx <= x_bound, dx, Where::of_body(frame, i), [&] {
        const std::string rule =
            bodies.integrator == I::SemiImplicit ? std::string("x + dt v'")
            : bodies.integrator == I::Explicit   ? std::string("x + dt v")
            : bodies.integrator == I::Substepped
                ? fmt::format("x + dt v + a g dt^2, a = (n + 1) / (2n) = {:.4g} for n = {} substeps", a_fit,
                              bodies.substeps)
                : fmt::format("x + dt v + a g dt^2 for every a in [0, 1] (nearest a = {:.4g})", a_fit);
        return fmt::format("frame {}: body {} without contacts: x' = ({:.6g}, {:.6g}, {:.6g}) m is {:.4g} m from {} "
                           "(integrator {}; bound {:.3g}{})",
                           frame, i, x1[0], x1[1], x1[2], dx, rule, integrator_name(bodies.integrator), x_bound,
                           drift.position > 0 ? fmt::format(", the origin integrator's drift {:.3g}", drift.position)
                                              : std::string());
      });
      if (!rotating) continue;
      // The spin of a torque-free body (docs/validation.md, "Free rotation: the
      // invariants"). Without the gyroscopic term w' = w: 8 eps32 per |w|, a float engine's
      // free step may turn w into the body frame and back (Bullet: two quatRotate, each two
      // quaternion products; measured 8.04 eps32 |w|, 3.02e-05 rad/s at 31.6 rad/s on
      // rot-pile-1000). With it (any first-order form) w precesses while L = R I R^T w
      // (each state at its own orientation) is kept to second order in |w| dt and the
      // rotational energy w . L / 2 does not rise beyond its own second-order bound; float32
      // adds 12 eps32 I3 (|w| + |w'|): the w step's 8 and the two orientations' ~2 each.
      const D3 dw = unlocked(w1 - w0, i, 3);
      const double w_bound = 8.0 * kEps32 * (len3(w0) + len3(w1)) + 1e-9;
      const double r_kept = len3(dw) / w_bound;
      const D3 l0 = mul(conjugated(rotation(rec.q_pre[i]), inertia[i]), w0);
      const D3 l1 = mul(conjugated(rotation(rec.q_post[i]), inertia[i]), w1);
      const double om = std::max(len3(w0), len3(w1));
      const SpinBounds sb = spin_bounds(principal[i], dt, om, len3(w1 - w0), std::max(len3(l0), len3(l1)));
      const double l_round = 12.0 * kEps32 * principal[i][1] * (len3(w0) + len3(w1)) + 1e-12;
      const double l_bound = sb.momentum + l_round;
      const double dl = len3(unlocked(l1 - l0, i, 3));
      const double rise = 0.5 * (dot3(w1, l1) - dot3(w0, l0));
      const double e_bound = sb.energy + om * l_round + 1e-15;
      // A joint's torque about a locked axis may work on the spin: energy not judged there.
      const double r_energy = (locked(i) >> 3) ? 0.0 : rise / e_bound;
      const double r_inv = std::max(dl / l_bound, r_energy);
      using G = PhysicsBodies::Gyroscopic;
      const double ratio = spin_ratio(bodies.gyroscopic, r_kept, r_inv, s.free_spin_kept, s.free_spin_invariant);
      free_w.check(ratio <= 1.0, ratio, Where::of_body(frame, i), [&] {
        const std::string kept = fmt::format("w' - w off by {:.4g} rad/s (bound {:.3g}, no gyroscopic term)",
                                             len3(dw), w_bound);
        const D3 d = l1 - l0;
        const std::string inv = fmt::format(
            "L' - L = ({:.4g}, {:.4g}, {:.4g}) kg m^2/s, off by {:.4g} (bound {:.3g}: free rotation's second order "
            "{:.3g}, rounding {:.3g}), rotational energy {} by {:.4g} J (bound on a rise {:.3g})",
            d[0], d[1], d[2], dl, l_bound, sb.momentum, l_round, rise >= 0 ? "up" : "down", std::fabs(rise), e_bound);
        return fmt::format("frame {}: body {} without contacts: w' = ({:.6g}, {:.6g}, {:.6g}) rad/s from w = ({:.6g}, "
                           "{:.6g}, {:.6g}): {} (gyroscopic term {})",
                           frame, i, w1[0], w1[1], w1[2], w0[0], w0[1], w0[2],
                           bodies.gyroscopic == G::Integrated ? inv
                           : bodies.gyroscopic == G::Absent   ? kept
                                                              : kept + "; " + inv,
                           gyroscopic_name(bodies.gyroscopic));
      });
      if (locked(i) >> 3) continue;  // a joint turns it: counted in s.free_locked
      const Quat q0 = rec.q_pre[i], q1 = rec.q_post[i];
      const double a_semi = quat_angle(advanced(q0, w1, dt), q1), a_expl = quat_angle(advanced(q0, w0, dt), q1);
      const double angle = bodies.integrator == PhysicsBodies::Integrator::SemiImplicit ? a_semi
                           : bodies.integrator == PhysicsBodies::Integrator::Explicit ? a_expl
                                                                                       : std::min(a_semi, a_expl);
      const double wdt = std::max(len3(w0), len3(w1)) * dt;
      // Substeps advance q by each substep's w, which lies between w and w' (the spin changes
      // within the step by the gyroscopic term only): at most dt |w' - w| from either end.
      const double q_bound = tol.free_flight_angle_rad + wdt * wdt + (bodies.may_substep() ? dt * len3(w1 - w0) : 0.0);
      free_q.check(angle <= q_bound, angle * 180.0 / kPi, Where::of_body(frame, i), [&] {
        return fmt::format("frame {}: body {} without contacts: q' is {:.4g} deg from q advanced by w{} dt (|w| dt "
                           "{:.3g} rad; bound {:.3g} deg)",
                           frame, i, angle * 180.0 / kPi,
                           bodies.integrator == PhysicsBodies::Integrator::Explicit ? "" : "'", wdt,
                           q_bound * 180.0 / kPi);
      });
    }
  };
  judge_in_order<BalanceDry<DeferredBalance, BalanceDisc>>(n, threads, kParallelBodiesFrom, stop, *this, row_tallies,
                                                          judge_bodies);
}

}  // namespace octocd

// ---- Row 7's systematic ratio (docs/validation.md, "A systematic impulse ratio") -------
namespace octocd {

using namespace dmath;
using namespace physics_detail;

double PhysicsValidators::Impl::balance_figure(const D3& mdv, const D3& force, const BalanceDisc* discs,
                                               std::size_t count, double float_bound, double s, double* open_along,
                                               const D3* rows, std::size_t row_count, double allow) {
  const D3 dp = mdv - (1.0 / s) * force;
  double ratio = 0, open = 0;
  auto test_dir = [&](D3 d) {
    double support = 0;
    for (std::size_t k = 0; k < count; ++k) support += discs[k].u * len3(cross3(d, discs[k].n));
    for (std::size_t k = 0; k < row_count; ++k) support += allow * std::fabs(dot3(rows[k], d));
    const double r = std::fabs(dot3(dp, d)) / (support + float_bound);
    if (r > ratio) {
      ratio = r;
      open = support;
    }
  };
  const double dpl = len3(dp);
  if (dpl > 0) test_dir((1.0 / dpl) * dp);
  for (std::size_t k = 0; k < count; ++k) test_dir(discs[k].n);
  if (count == 0 && !(allow > 0 && row_count > 0)) ratio = dpl / float_bound;
  if (open_along) *open_along = open;
  return ratio;
}

void PhysicsValidators::Impl::RatioSample::add(double s) {
  const auto n = static_cast<std::size_t>(std::lround(2.0 * kFitSpan / kFitBin)) + 1;
  if (bins.empty()) bins.assign(n, 0);
  const double k = std::round((s - (1.0 - kFitSpan)) / kFitBin);
  if (!(k >= 0)) {
    ++below;
  } else if (k > double(n - 1)) {
    ++above;
  } else {
    ++bins[static_cast<std::size_t>(k)];
  }
}

std::uint64_t PhysicsValidators::Impl::RatioSample::total() const {
  std::uint64_t t = below + above;
  for (std::uint64_t c : bins) t += c;
  return t;
}

double PhysicsValidators::Impl::RatioSample::at(std::uint64_t r) const {
  if (r < below) return 1.0 - kFitSpan;
  std::uint64_t seen = below;
  for (std::size_t k = 0; k < bins.size(); ++k) {
    seen += bins[k];
    if (r < seen) return 1.0 - kFitSpan + double(k) * kFitBin;
  }
  return 1.0 + kFitSpan;
}

double PhysicsValidators::Impl::BalanceFit::row_allowance() const {
  if (!spread) return 0.0;
  return std::max(std::fabs(1.0 / lo - 1.0 / ratio), std::fabs(1.0 / hi - 1.0 / ratio));
}

PhysicsValidators::Impl::BalanceFit PhysicsValidators::Impl::balance_fit() const {
  BalanceFit fit;
  const std::uint64_t total = ratio_sample.total();
  fit.samples = total;
  if (total < kFitMinSamples) return fit;
  fit.fitted = true;
  fit.ratio = ratio_sample.at(total / 2);
  fit.q1 = ratio_sample.at(total / 4);
  fit.q3 = ratio_sample.at((3 * total) / 4);
  fit.lo = fit.hi = fit.ratio;
  const std::uint64_t one_way = spread_sample.total();
  fit.spread_samples = one_way;
  if (one_way >= kFitMinSamples) {
    // Tukey's far-out fences of the one-sided sample, widened to hold the centre, inside the span.
    fit.spread = true;
    fit.spread_q1 = spread_sample.at(one_way / 4);
    fit.spread_q3 = spread_sample.at((3 * one_way) / 4);
    const double iqr = fit.spread_q3 - fit.spread_q1;
    fit.lo = std::max(1.0 - kFitSpan, std::min(fit.ratio, fit.spread_q1 - kSpreadFence * iqr));
    fit.hi = std::min(1.0 + kFitSpan, std::max(fit.ratio, fit.spread_q3 + kSpreadFence * iqr));
  }
  fit.bias = std::max({std::fabs(fit.ratio - 1.0), 1.0 - fit.lo, fit.hi - 1.0}) > kBiasMax;
  return fit;
}

Tally PhysicsValidators::Impl::fitted_balance(const BalanceFit& fit, std::uint64_t* in_spread) const {
  const Tally& balance_lin = tally(RowId::MomentumBalance, "linear");
  Tally t = balance_lin;
  const double allow = fit.row_allowance();
  *in_spread = 0;
  for (const DeferredBalance& d : deferred) {
    const BalanceDisc* discs = deferred_discs.data() + d.disc_first;
    const D3* rows = deferred_rows.data() + d.row_first;
    double open1 = 0, open_s = 0, open_w = 0;
    balance_figure(d.mdv, d.force, discs, d.disc_count, d.float_bound, 1.0, &open1);
    const double rs =
        fit.fitted ? balance_figure(d.mdv, d.force, discs, d.disc_count, d.float_bound, fit.ratio, &open_s) : d.r1;
    // Each row's own ratio anywhere inside the spread's fences ("A spread of reported impulses").
    const double rw = rs > 1.0 && allow > 0 ? balance_figure(d.mdv, d.force, discs, d.disc_count, d.float_bound,
                                                             fit.ratio, &open_w, rows, d.row_count, allow)
                                            : rs;
    if (rs > 1.0 && rw <= 1.0) ++*in_spread;
    const bool ok = rw <= 1.0;
    t.check(ok, ok ? rw : std::min(d.r1, rw), Where::of_body(d.frame, d.body), [&] {
      const D3 dp = d.mdv - d.force;
      std::string s = fmt::format(
          "frame {}: body {}: m (v' - v) - m g dt = ({:.4g}, {:.4g}, {:.4g}) kg m/s but its {} contact rows' impulses "
          "sum to ({:.4g}, {:.4g}, {:.4g}): off by {:.4g} ({:.3g} of the bound: rounding {:.3g}, friction the record "
          "leaves open {:.3g})",
          d.frame, d.body, d.mdv[0], d.mdv[1], d.mdv[2], d.rows, d.force[0], d.force[1], d.force[2], len3(dp), d.r1,
          d.float_bound, open1);
      if (fit.fitted)
        s += fmt::format("; at the fitted impulse ratio {:.5f}: off by {:.4g} ({:.3g} of the bound)", fit.ratio,
                         len3(d.mdv - (1.0 / fit.ratio) * d.force), rs);
      if (allow > 0)
        s += fmt::format("; each row's ratio anywhere in the spread {:.5f} .. {:.5f}: {:.3g} of the bound", fit.lo,
                         fit.hi, rw);
      return s;
    });
  }
  return t;
}

Tally PhysicsValidators::Impl::balance_bias(const BalanceFit& fit) const {
  Tally t;
  if (!fit.fitted) return t;
  const double off = std::fabs(fit.ratio - 1.0);
  const double reach = std::max({off, 1.0 - fit.lo, fit.hi - 1.0});
  t.check(!fit.bias, reach, Where{-1, "impulse ratio"}, [&] {
    if (off > kBiasMax)
      return fmt::format("the reported impulses are {:.5f} of the momentum change (median over {} body-steps, "
                         "quartiles {:.5f} .. {:.5f}): {:.3g}% {}, beyond the {:.3g}% a systematic ratio may take "
                         "(the trace's masses are not the engine's, or its impulses are scaled)",
                         fit.ratio, fit.samples, fit.q1, fit.q3, 100.0 * off, fit.ratio < 1 ? "low" : "high",
                         100.0 * kBiasMax);
    return fmt::format("the reported impulses scatter from {:.5f} to {:.5f} of the momentum change (the fences of "
                       "the quartiles {:.5f} .. {:.5f} over {} body-steps whose rows push one way, about the centre "
                       "{:.5f}): {:.3g}% from 1, beyond the {:.3g}% a ratio may take",
                       fit.lo, fit.hi, fit.spread_q1, fit.spread_q3, fit.spread_samples, fit.ratio, 100.0 * reach,
                       100.0 * kBiasMax);
  });
  return t;
}

// ---- momentum-balance: its measure of a frame and its table entry -------------------------

template <>
void PhysicsValidators::Impl::measure<RowId::MomentumBalance>(PhysicsFrame& f) {
  // Every frame with states, in one pass over the bodies with free-flight (timed here).
  balance(f.rec, f.det);
}

template <>
ValidationResult PhysicsValidators::Impl::table<RowId::MomentumBalance>() const {
  const Impl& s = *this;
  auto [balance_lin, balance_ang] = s.tallies(RowId::MomentumBalance, "linear", "angular");
  const RowInfo& info = row_info(RowId::MomentumBalance);
  ValidationResult r = start_row(RowId::MomentumBalance, "bodies whose velocity change is not their rows' impulses",
                                 "balance_ulps,friction_direction_speed");
  // The linear balance judged at the fitted systematic ratio too, and the ratio itself
  // (docs/validation.md, "A systematic impulse ratio").
  const auto fit = s.balance_fit();
  std::uint64_t in_spread = 0;
  const Tally lin = s.fitted_balance(fit, &in_spread), bias = s.balance_bias(fit);
  r.measured = double(lin.failures + balance_ang.failures + bias.failures);
  r.pass = r.measured == 0;
  r.applicable = lin.checks + balance_ang.checks > 0;
  const std::string extras =
      (s.balance_locked ? fmt::format("; {} body-steps with locked axes (those components n/a: a joint's impulses "
                                      "are not in the rows)",
                                      s.balance_locked)
                        : std::string()) +
      (s.balance_no_rows
           ? fmt::format("; {} body-steps in a confirmed pair without rows, not judged", s.balance_no_rows)
           : std::string()) +
      (s.balance_clamped ? fmt::format("; {} body-steps at the declared velocity clamp, not judged", s.balance_clamped)
                         : std::string()) +
      (s.fell_asleep ? fmt::format("; {} body-steps falling asleep (/states/sleeping: the engine zeroed the "
                                   "velocity), not judged",
                                   s.fell_asleep)
                     : std::string());
  if (s.bodies.impulses == PhysicsBodies::Impulses::None) {
    r.applicable = false;
    r.detail =
        "n/a: the trace declares impulses = \"none\" (the engine reports no impulse): a body's velocity "
        "change cannot be held to its rows' impulses; conservation judges the isolated groups";
  } else if (!s.bodies.contacts_complete) {
    r.applicable = false;
    r.detail = fmt::format(
        "n/a: the trace declares contacts_complete = 0: {} body-steps in contact not judged (a "
        "row the engine did not report would read as a fault); free-flight and conservation "
        "judge the bodies and groups the geometry shows apart",
        s.balance_incomplete);
  } else if (!s.bodies.impulses_complete) {
    r.applicable = false;
    r.detail = fmt::format(
        "n/a: the record holds the impulses of the first of response.iterations = {} "
        "relaxation passes (octocd's ContactRecord); the later passes apply more impulses on the "
        "same pairs, so the rows are not the step's impulses",
        s.model->scene.response.iterations);
  } else if (!r.applicable) {
    r.detail = s.state_frames ? "no dynamic body with contact rows in a step with states"
                              : "no states (a trace: add /states/position and /states/velocity)";
  } else {
    r.detail = fmt::format(
        "{} body-steps: linear worst {:.3g} of its bound; angular {}", lin.checks, lin.worst_or(0.0),
        balance_ang.checks
            ? fmt::format("{} body-steps, worst {:.3g} of its bound{}", balance_ang.checks, balance_ang.worst_or(0.0),
                          spin_note(s.bodies.gyroscopic, s.balance_ang_plain, s.balance_ang_invariant))
        : s.balance_rot_locked ? fmt::format("n/a: rotation locked (locked_dofs) on all {} body-steps with "
                                             "rotation and points",
                                             s.balance_rot_locked)
                               : std::string("n/a: no rotation or no contact points (torques unknown)"));
    r.detail += extras;
    r.detail += fit.fitted
                    ? fmt::format(
                          "; impulse ratio {:.5f} (reported impulses over the momentum change: the median over {} "
                          "body-steps, quartiles {:.5f} .. {:.5f}; {}), the linear balance judged at 1 and at it: "
                          "{} body-steps failing at 1 pass at it",
                          fit.ratio, fit.samples, fit.q1, fit.q3,
                          std::fabs(fit.ratio - 1.0) > s.kBiasMax
                              ? fmt::format("beyond the {:.3g}% a systematic ratio may take", 100.0 * s.kBiasMax)
                                   : fmt::format("within the {:.3g}% a systematic ratio may take", 100.0 * s.kBiasMax),
                          s.deferred.size() - (lin.failures - balance_lin.failures) - in_spread) +
                          (in_spread ? fmt::format("; one finding, a spread of the reported impulses about the "
                                                   "momentum change: quartiles {:.5f} .. {:.5f} over {} body-steps "
                                                   "whose rows push one way, about the centre {:.5f}; {} body-steps "
                                                   "failing at it pass with each row's ratio inside the spread's "
                                                   "fences {:.5f} .. {:.5f} (3 interquartile ranges beyond the "
                                                   "quartiles)",
                                                   fit.spread_q1, fit.spread_q3, fit.spread_samples, fit.ratio,
                                                   in_spread, fit.lo, fit.hi)
                                     : std::string())
                    : fmt::format("; impulse ratio not fitted ({} body-steps fix it to {:.3g}, {} needed)", fit.samples,
                                  s.kFitPrecision, s.kFitMinSamples);
    note(r.detail, s.deferred_over, "{} failing body-steps beyond the {} kept for the fit judged at ratio 1",
         s.deferred_over, s.kMaxDeferred);
    note(r.detail, s.balance_incomplete,
         "{} body-steps in contact on the steps or pairs /contacts/incomplete declares (a row may be missing) not "
         "judged",
         s.balance_incomplete);
    note(r.detail, s.origin_drift_balance,
         "integrated_point \"origin\": {} body-steps allowed the centre of mass's drift under the origin's "
         "first-order integration, m |c| dt w (3 |w' - w| + 2 dt w^2) (at most {:.3g} m/s)",
         s.origin_drift_balance, s.origin_drift_balance_worst);
    if (s.bodies.impulses == PhysicsBodies::Impulses::NormalOnly)
      r.detail +=
          "; impulses \"normal-only\": each body's residual m (v' - v) - m g dt - sum jn n within the sum "
          "of its rows' cones (mu jn), jt and jt3 not read";
    physics_detail::fill_causes(r, info, {&lin, &balance_ang, &bias});
    r.judged = lin.checks;
  }
  return r;
}

// ---- free-flight: its measure of a frame and its table entry -------------------------

template <>
void PhysicsValidators::Impl::measure<RowId::FreeFlight>(PhysicsFrame&) {
  // Measured in momentum-balance's pass over the bodies (balance()): nothing of its own.
}

template <>
ValidationResult PhysicsValidators::Impl::table<RowId::FreeFlight>() const {
  const Impl& s = *this;
  auto [free_vel, free_pos, free_w, free_q, free_sleep] =
      s.tallies(RowId::FreeFlight, "velocity", "position", "angular-velocity", "orientation", "sleeping");
  ValidationResult r = failures_row(RowId::FreeFlight, "bodies without contacts not following gravity and their spin",
                                    "free_flight_angle_rad");
  r.applicable = free_vel.checks + free_sleep.checks > 0;
  if (!r.applicable) {
    r.detail = s.state_frames ? "no dynamic body without contacts in a step with states"
                              : "no states (a trace: add /states/position and /states/velocity)";
  } else if (free_vel.checks == 0) {
    r.detail = fmt::format("no body-step in free flight; {} asleep body-steps (/states/sleeping)", free_sleep.checks);
  } else {
    r.detail = fmt::format(
        "{} body-steps (integrator {}): worst velocity {:.3g} m/s, position {:.3g} m{}{}", free_vel.checks,
        integrator_name(s.bodies.integrator), free_vel.worst_or(0.0), free_pos.worst_or(0.0),
        free_w.checks
            ? fmt::format(", spin (angular velocity) {:.3g} of its bound{} over {}, orientation {:.3g} "
                          "deg over {}",
                          free_w.worst_or(0.0), spin_note(s.bodies.gyroscopic, s.free_spin_kept, s.free_spin_invariant),
                          free_w.checks, free_q.worst_or(0.0), free_q.checks)
            : std::string("; rotation n/a (translation-only records)"),
        s.free_locked ? fmt::format("; {} body-steps with locked axes (those components n/a)", s.free_locked)
                      : std::string());
    if (s.bodies.integrator == PhysicsBodies::Integrator::Undeclared)
      r.detail +=
          "; integrator undeclared: x' = x + dt v + a g dt^2 for every a in [0, 1] and substepping's "
          "orientation, a failure only where every integrator fails (declare integrator, and substeps, to "
          "sharpen the verdict)";
  }
  note(r.detail, !s.bodies.contacts_complete,
       "contacts_complete 0: only bodies the exact reference shows apart from every other "
       "body through the step (beyond the margin and the pair's motion) are judged free; {} "
       "body-steps without rows but near a body not judged ({} pairs tested)",
       s.free_near, s.near_tested);
  note(r.detail, s.bodies.contacts_complete && !s.bodies.incomplete_rows.empty(),
       "/contacts/incomplete: on its {} steps or pairs only bodies the exact reference shows apart from the declared "
       "pairs' bodies through the step are judged free; {} body-steps without rows but near a body not judged ({} "
       "pairs tested)",
       s.bodies.incomplete_rows.size(), s.free_near, s.near_tested);
  note(r.detail, s.origin_drift_free,
       "integrated_point \"origin\": {} body-steps allowed the centre of mass's drift under the origin's "
       "first-order integration, |c| dt w (3 |w' - w| + 2 dt w^2) in velocity (at most {:.3g} m/s) and |c| dt "
       "(|w' - w| + 2 dt w^2) in position",
       s.origin_drift_free, s.origin_drift_free_worst);
  if (r.applicable) {
    note(r.detail, free_sleep.checks + s.fell_asleep,
         "{} body-steps asleep through the step judged not to move (worst {:.3g} of one "
         "rounding), {} falling asleep not judged (/states/sleeping)",
         free_sleep.checks, free_sleep.worst_or(0.0), s.fell_asleep);
    s.fill_causes(r, RowId::FreeFlight);
    r.judged = free_vel.checks + free_sleep.checks;
  }
  return r;
}

}  // namespace octocd
