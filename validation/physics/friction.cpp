// The physics tier's row 5, friction (physics_impl.hpp): the Coulomb cone per contact
// pair on every frame, and dissipation (friction does no positive work on the sliding)
// where the record's states and impulses show it.
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

using namespace dmath;
using namespace physics_detail;

template <class Sums, class T>
void PhysicsValidators::Impl::judge_pair_friction(const FrameRecord& rec, const std::vector<Pose>& det, Pair p,
                                                  std::size_t k0, std::size_t k1, Sums& sums, T& dissipation) const {
  const std::size_t n = model->bodies.size();
  const D3 g = d3(model->scene.gravity);
  const double dt = model->scene.dt;
  auto w_of = [&](const std::vector<Vec3>& w, std::size_t i) { return w.size() == n ? d3(w[i]) : D3{}; };
  auto v_int = [&](std::uint32_t i) { return dynamic(i) ? d3(rec.v_pre[i]) + dt * g : d3(rec.v_pre[i]); };
  const D3 xa = com_at(det[p.a], p.a), xb = com_at(det[p.b], p.b);
  // Three states of the bodies' velocities: before the solver (after gravity), with the
  // pair's normal impulses alone applied (rotating records with points), after the step.
  struct Vel {
    D3 va, wa, vb, wb;
  };
  const Vel before{v_int(p.a), w_of(rec.w_pre, p.a), v_int(p.b), w_of(rec.w_pre, p.b)};
  const Vel after{d3(rec.v_post[p.a]), w_of(rec.w_post, p.a), d3(rec.v_post[p.b]), w_of(rec.w_post, p.b)};
  Vel normal = before;
  const bool coupled = rec.w_pre.size() == n && rec.has_points;
  if (coupled) {
    const M3 ia = dynamic(p.a) ? conjugated(rotation(det[p.a].orientation), inverse(inertia[p.a])) : M3{};
    const M3 ib = dynamic(p.b) ? conjugated(rotation(det[p.b].orientation), inverse(inertia[p.b])) : M3{};
    for (std::size_t k = k0; k < k1; ++k) {
      const ContactRecord& c = rec.contacts[k];
      // B's impulse at its own witness point where the record gives one (point_b).
      const D3 j = double(c.jn) * d3(c.normal), pt = d3(c.point), pt_b = d3(point_on_b(rec, k));
      if (dynamic(p.a)) {
        normal.va = normal.va + (1.0 / mass[p.a]) * j;
        normal.wa = normal.wa + mul(ia, cross3(pt - xa, j));
      }
      if (dynamic(p.b)) {
        normal.vb = normal.vb - (1.0 / mass[p.b]) * j;
        normal.wb = normal.wb - mul(ib, cross3(pt_b - xb, j));
      }
    }
  }
  // The friction impulses' mean push along the sliding at the rows' points (m/s):
  // sum_k jt3_k . v_t,k / sum_k |jt3_k|; the largest tangential speed at a row.
  auto push = [&](const Vel& v, double& fastest) {
    double work = 0, impulse = 0;
    fastest = 0;
    for (std::size_t k = k0; k < k1; ++k) {
      const ContactRecord& c = rec.contacts[k];
      const D3 nrm = d3(c.normal), j = d3(rec.jt3[k]);
      const D3 ra = rec.has_points ? d3(c.point) - xa : D3{};
      const D3 rb = rec.has_points ? d3(point_on_b(rec, k)) - xb : D3{};
      const D3 rel = (v.va + cross3(v.wa, ra)) - (v.vb + cross3(v.wb, rb));
      const D3 vt = rel - dot3(rel, nrm) * nrm;
      work += dot3(j, vt);
      impulse += len3(j);
      fastest = std::max(fastest, len3(vt));
    }
    return impulse > 0 ? work / impulse : 0.0;
  };
  double impulse = 0, jn_sum = 0, gap = 0;
  D3 j_sum{};
  for (std::size_t k = k0; k < k1; ++k) {
    const ContactRecord& c = rec.contacts[k];
    impulse += len3(d3(rec.jt3[k]));
    j_sum = j_sum + d3(rec.jt3[k]);
    jn_sum += double(c.jn);
    if (rec.has_points && (len3(after.wa) + len3(after.wb)) > 0)
      gap = std::max(gap, std::max(double(c.depth), ref->surface_distance(p.a, det[p.a], c.point) +
                                                        ref->surface_distance(p.b, det[p.b], c.point)));
  }
  // No friction impulse (within float rounding of the normal impulses): nothing to judge.
  if (!(impulse > 16.0 * kEps32 * jn_sum + 1e-12)) {
    dissipation.judged();
    return;
  }
  // A friction impulse up to friction_cone_abs is a sequential-impulse solver's leftover
  // (warm start, clamped rows) and is not judged on its direction (Bullet: 2 pairs of
  // rot-drop-220 and 2 of rot-pile-1000, sum |jt3| 0.96e-3 - 0.99e-3 kg m/s, on a body
  // landing with a tiny normal impulse while sliding at 0.5 m/s). Counted.
  if (impulse <= tol.friction_cone_abs) {
    ++sums.dissipation_small;
    return;
  }
  ++sums.dissipation_jt3_pairs;
  double fast0 = 0, fastn = 0, fast1 = 0;
  const double along0 = push(before, fast0), alongn = coupled ? push(normal, fastn) : along0, along1 = push(after, fast1);
  // Coulomb friction opposes the sliding. A discrete solver takes the sliding before its
  // impulses (an explicit friction direction: Bullet's lateral friction direction is the
  // relative velocity when the row is set up), after the normal impulses, or after the
  // step (the maximal-dissipation condition of an implicit solve); the sliding turns
  // between them (a box landing on an edge spins). The friction is judged against all
  // three and fails when it pushes the points along their sliding in every one.
  const double along = std::min({along0, alongn, along1});
  const double allowance = (len3(after.wa) + len3(after.wb)) * gap;
  const std::int64_t frame = rec.frame;
  dissipation.check(along <= tol.friction_speed + allowance, along, Where{frame, p}, [&] {
    return fmt::format("frame {}: {} ({} rows): the friction impulse (sum jt3 ({:.4g}, {:.4g}, {:.4g}) kg m/s) "
                       "pushes the contact points along their sliding: {:.4g} m/s along the impulses before the "
                       "step, {:.4g} with the normal impulses, {:.4g} after it (largest tangential speed at a row "
                       "{:.6g} -> {:.6g} m/s; witness-point allowance {:.3g} m/s) [rule: jt3]",
                       frame, pair_name(p), k1 - k0, j_sum[0], j_sum[1], j_sum[2], along0, alongn, along1, fast0,
                       fast1, allowance);
  });
}

// ---- Row 5: friction, every frame (dissipation on frames with states) ----------------
namespace {
/// The fewest contact pairs whose cones are judged on the validators' threads
/// (judge_in_order): a pair's cone costs about 250 instructions.
constexpr std::size_t kParallelConesFrom = 2048;

/// friction()'s table kept from frame to frame in the row's state (Impl::row_state): the
/// first row of each contact pair, then the rows' count.
struct FrictionScratch {
  std::vector<std::size_t> first_row;
  std::vector<std::uint32_t> pairs_of;  ///< per body: its distinct contact pairs this frame
};

/// Dissipation's own counts that a block of pairs judged on a thread writes (judge_in_order).
struct DissipationDry {
  std::uint64_t dissipation_cone_only = 0, dissipation_small = 0, dissipation_jt3_pairs = 0;
  template <class Live>
  bool describes(const Live&) const {
    return false;
  }
  template <class Live>
  void merge_into(Live& s) const {
    s.dissipation_cone_only += dissipation_cone_only;
    s.dissipation_small += dissipation_small;
    s.dissipation_jt3_pairs += dissipation_jt3_pairs;
  }
};

/// The cone's own state that a block of pairs judged on a thread writes (judge_in_order).
struct ConeDry {
  std::uint64_t cone_jt3_pairs = 0, cone_scalar_pairs = 0;
  template <class Live>
  bool describes(const Live&) const {
    return false;
  }
  template <class Live>
  void merge_into(Live& s) const {
    s.cone_jt3_pairs += cone_jt3_pairs;
    s.cone_scalar_pairs += cone_scalar_pairs;
  }
};
}  // namespace

void PhysicsValidators::Impl::friction(const FrameRecord& rec, const std::vector<Pose>& det) {
  Tally& dissipation_tally = tally(RowId::Friction, "dissipation");
  // impulses "normal-only" or "none": the rows carry no friction impulse; whatever jt and
  // jt3 hold (zeros, typically) is never judged (the row is n/a, named).
  if (bodies.impulses != PhysicsBodies::Impulses::Complete) return;
  const Model& m = *model;
  const std::size_t n = m.bodies.size();
  const std::int64_t frame = rec.frame;
  const D3 g = d3(m.scene.gravity);
  const double dt = m.scene.dt;

  // 5a. The cone, per pair: a pair's rows together (a manifold is one contact patch):
  // |sum J_t| <= mu sum jn. A sequential-impulse solver clamps each row's friction by that
  // row's normal impulse (Bullet: |lateral impulse| <= mu jn of its row after the normal
  // rows of each iteration), so the patch's friction is within the cone of its total
  // normal impulse. Rules:
  //  - jt3 (the tangential impulse vectors): |sum_k jt3_k| <= mu sum_k jn_k + rounding
  //    (16 x 2^-23 of sum |jt3_k| + mu sum jn, + 1e-12 kg m/s): no relative slack.
  //  - scalar jt (no jt3): sum |jt_k| <= mu sum jn + the same rounding + friction_cone_abs
  //    (a scalar along -v_t / |v_t| cannot show a second friction direction).
  // Both with the floor of the stored states (docs/validation.md, "Floors"): an excess
  // that changes no stored velocity of the pair's dynamic bodies by more than its float32
  // precision, 4 x 2^-23 x sum m (|v| + |v'|), shows nothing a trace can hold (an
  // iterative solver's ppm excess on a sliding body).
  const bool have_states = rec.v_pre.size() == n && rec.v_post.size() == n;
  auto momentum_floor = [&](Pair p) {
    double s = 0;
    if (have_states)
      for (std::uint32_t i : {p.a, p.b})
        if (dynamic(i)) s += mass[i] * (len3(d3(rec.v_pre[i])) + len3(d3(rec.v_post[i])));
    return 4.0 * kEps32 * s;
  };
  const bool vector_friction = !rec.jt3.empty();
  // The pairs' first rows (rows of a pair are consecutive), judged on the threads and
  // tallied in pair order (judge_in_order).
  std::vector<std::size_t>& first_row = row_state<FrictionScratch>(RowId::Friction).first_row;
  pair_run_starts(rec.contacts, first_row, threads, stop);
  first_row.push_back(rec.contacts.size());
  auto judge_cones = [&](std::size_t first, std::size_t last, auto& s, auto& cone) {
    for (std::size_t q = first; q < last; ++q) {
      const std::size_t k0 = first_row[q], k1 = first_row[q + 1];
      const Pair pr = rec.contacts[k0].pair;
      double jt_sum = 0.0, jn_sum = 0.0, jt_abs = 0.0;
      D3 jt_vec{};
      for (std::size_t k = k0; k < k1; ++k) {
        if (vector_friction) {
          jt_vec = jt_vec + d3(rec.jt3[k]);
          jt_abs += len3(d3(rec.jt3[k]));
        } else {
          jt_abs += std::fabs(double(rec.contacts[k].jt));
        }
        jn_sum += double(rec.contacts[k].jn);
      }
      jt_sum = vector_friction ? len3(jt_vec) : jt_abs;
      const double mu = pair_mu(pr);
      const std::size_t rows = k1 - k0;
      const double rounding = 16.0 * kEps32 * (jt_abs + mu * jn_sum) + momentum_floor(pr) + 1e-12;
      const double limit = mu * jn_sum + rounding + (vector_friction ? 0.0 : tol.friction_cone_abs);
      const double excess = jt_sum - limit;
      (vector_friction ? ++s.cone_jt3_pairs : ++s.cone_scalar_pairs);
      cone.check(excess <= 0, excess, Where{frame, pr}, [&] {
        return fmt::format("frame {}: {} |{}| {:.6g} > mu {:.4g} x jn {:.6g} ({:.4g} x the cone){} [rule: {}]", frame,
                           pair_name(pr), vector_friction ? "sum jt3" : "jt", jt_sum, mu, jn_sum,
                           mu * jn_sum > 0 ? jt_sum / (mu * jn_sum) : std::numeric_limits<double>::infinity(),
                           rows > 1 ? fmt::format(" (sums over its {} rows)", rows) : std::string(),
                           vector_friction ? "jt3" : "scalar");
      });
    }
  };
  judge_in_order<ConeDry>(first_row.size() - 1, threads, kParallelConesFrom, stop, *this,
                          std::array<Tally*, 1>{&tally(RowId::Friction, "cone")}, judge_cones);

  const bool states = rec.x_pre.size() == n && rec.v_pre.size() == n && rec.x_post.size() == n &&
                      rec.v_post.size() == n;
  if (!states) {
    dissipation_cone_only += rec.contacts.size();
    return;
  }
  const bool rotating = rec.q_pre.size() == n && rec.q_post.size() == n && rec.w_pre.size() == n &&
                        rec.w_post.size() == n;
  auto w_of = [&](const std::vector<Vec3>& w, std::size_t i) { return w.size() == n ? d3(w[i]) : D3{}; };
  auto v_int = [&](std::size_t i) {  // velocity the step starts from: gravity on dynamic bodies
    return dynamic(static_cast<std::uint32_t>(i)) ? d3(rec.v_pre[i]) + dt * g : d3(rec.v_pre[i]);
  };
  auto inv_inertia = [&](std::size_t i) {
    if (!dynamic(static_cast<std::uint32_t>(i))) return M3{};
    return conjugated(rotation(det[i].orientation), inverse(inertia[i]));
  };

  // Distinct contact pairs per body: on the threads, each counting a range of bodies.
  std::vector<std::uint32_t>& pairs_of = row_state<FrictionScratch>(RowId::Friction).pairs_of;
  pairs_of.assign(n, 0);
  const unsigned count_threads = loop_threads(threads, first_row.size(), kParallelConesFrom);
  parallel_items_on(count_threads, count_threads, stop, [&](std::size_t range, unsigned) {
    const std::uint32_t lo = static_cast<std::uint32_t>(n * range / count_threads),
                        hi = static_cast<std::uint32_t>(n * (range + 1) / count_threads);
    for (std::size_t q = 0; q + 1 < first_row.size(); ++q) {
      const Pair p = rec.contacts[first_row[q]].pair;
      if (p.a >= lo && p.a < hi) ++pairs_of[p.a];
      if (p.b >= lo && p.b < hi) ++pairs_of[p.b];
    }
  });

  // 5b. Dissipation at the contact points, where the pair is its dynamic bodies' only one:
  // per pair on the threads, tallied in pair order (judge_in_order).
  auto judge_dissipation = [&](std::size_t first, std::size_t last, auto& s, auto& dissipation) {
    for (std::size_t q = first; q < last; ++q) {
      const std::size_t k0 = first_row[q], k1 = first_row[q + 1];
      const Pair p = rec.contacts[k0].pair;
      // "Where the contact is the only one on its dynamic bodies" (design.md section 13.5): a manifold
      // row is a contact; with several rows, friction at one row turns the bodies and so
      // moves the tangential velocity at the others (Bullet: a 4-row box pair raised one
      // row's speed from 1.05 to 1.12 m/s while dissipating): judged on the cone only.
      const bool pair_alone = (!dynamic(p.a) || pairs_of[p.a] == 1) && (!dynamic(p.b) || pairs_of[p.b] == 1);
      if (vector_friction && pair_alone) {
        // jt3: the pair's friction impulse is known, whatever else touches its bodies. It
        // must do no positive work on the final relative sliding at the rows' points
        // (maximal dissipation, summed over the manifold): sum_k jt3_k . v_t,k' <= 0, as a
        // mean speed along the impulses, sum_k jt3_k . v_t,k' / sum_k |jt3_k|, within
        // friction_speed + the witness-point allowance (|w_a| + |w_b|) s, s the largest
        // distance between a row's witness points (its depth, or the gap across its point).
        judge_pair_friction(rec, det, p, k0, k1, s, dissipation);
        continue;
      }
      const bool alone = k1 - k0 == 1 && (!dynamic(p.a) || pairs_of[p.a] == 1) &&
                         (!dynamic(p.b) || pairs_of[p.b] == 1);
      if (!alone) {
        s.dissipation_cone_only += k1 - k0;
        continue;
      }
      const D3 xa = com_at(det[p.a], p.a), xb = com_at(det[p.b], p.b);
      const D3 va0 = v_int(p.a), vb0 = v_int(p.b), wa0 = w_of(rec.w_pre, p.a), wb0 = w_of(rec.w_pre, p.b);
      const D3 va1 = d3(rec.v_post[p.a]), vb1 = d3(rec.v_post[p.b]);
      const D3 wa1 = w_of(rec.w_post, p.a), wb1 = w_of(rec.w_post, p.b);
      // A solver applies the normal impulses too; off the centre of mass they turn the
      // bodies and so change the tangential velocity at the point (a box landing on an
      // edge). Friction acts on the velocity after them, so the speed it must not raise is
      // the larger of the speed before the step and the speed with the pair's normal
      // impulses alone applied (the same for translation-only bodies or without points).
      D3 van = va0, vbn = vb0, wan = wa0, wbn = wb0;
      const bool coupled = rotating && rec.has_points;
      if (coupled) {
        const M3 ia = inv_inertia(p.a), ib = inv_inertia(p.b);
        for (std::size_t k = k0; k < k1; ++k) {
          const ContactRecord& c = rec.contacts[k];
          const D3 j = double(c.jn) * d3(c.normal);
          const D3 pt = d3(c.point), pt_b = d3(point_on_b(rec, k));
          if (dynamic(p.a)) {
            van = van + (1.0 / mass[p.a]) * j;
            wan = wan + mul(ia, cross3(pt - xa, j));
          }
          if (dynamic(p.b)) {
            vbn = vbn - (1.0 / mass[p.b]) * j;
            wbn = wbn - mul(ib, cross3(pt_b - xb, j));
          }
        }
      }
      for (std::size_t k = k0; k < k1; ++k) {
        const ContactRecord& c = rec.contacts[k];
        const D3 nrm = d3(c.normal);
        const D3 pt = rec.has_points ? d3(c.point) : D3{};
        const D3 ra = rec.has_points ? pt - xa : D3{}, rb = rec.has_points ? d3(point_on_b(rec, k)) - xb : D3{};
        auto tangential_speed = [&](D3 va, D3 wa, D3 vb, D3 wb) {
          const D3 rel = (va + cross3(wa, ra)) - (vb + cross3(wb, rb));
          return len3(rel - dot3(rel, nrm) * nrm);
        };
        const double before = tangential_speed(va0, wa0, vb0, wb0);
        const double with_normal = coupled ? tangential_speed(van, wan, vbn, wbn) : before;
        const double after = tangential_speed(va1, wa1, vb1, wb1);
        if (!coupled) {
          const double rise = after - std::max(before, with_normal);
          dissipation.check(rise <= tol.friction_speed, rise, Where{frame, p}, [&] {
            return fmt::format("frame {}: {} row {}: tangential speed at the {} {:.6g} -> {:.6g} m/s", frame,
                               pair_name(p), k - k0, rec.has_points ? "contact point" : "centres", before, after);
          });
          continue;
        }
        // Rotating bodies with contact points. The row's friction impulse on A is the
        // tangential part of A's momentum change (B's, negated, when A is static): the row
        // is its bodies' only contact, so no model of the solver is needed. Friction must
        // not push the point along its final sliding (it does no positive work: J_t . v_t'
        // <= 0, the maximal-dissipation condition, which exact Coulomb friction meets and
        // which implies |v_t'| <= |v_t| there). |v_t'| itself is not judged on spinning
        // bodies: a sequential-impulse solver's friction row along one fixed direction
        // changes the other tangential component through the bodies' rotation (the
        // point's effective mass is not isotropic), and Bullet raised |v_t| on 4 rows of
        // rot-drop-220 by 0.14-5% with friction opposing the sliding along its row.
        D3 imp = dynamic(p.a) ? mass[p.a] * (va1 - va0) : -mass[p.b] * (vb1 - vb0);
        imp = imp - dot3(imp, nrm) * nrm;
        const double imp_len = len3(imp);
        // integrated_point "origin": the centre of mass's drift under the origin's first-order
        // integration is in the momentum change too (momentum-balance's allowance).
        const double drift = dynamic(p.a) ? mass[p.a] * origin_drift(rec, p.a).velocity
                                          : mass[p.b] * origin_drift(rec, p.b).velocity;
        const double noise = 1e-6 * (dynamic(p.a) ? mass[p.a] * (len3(va1) + len3(va0))
                                                  : mass[p.b] * (len3(vb1) + len3(vb0))) + drift + 1e-12;
        if (imp_len <= noise) {  // no friction impulse (within float rounding or the drift): nothing to judge
          dissipation.judged();
          continue;
        }
        const D3 rel1 = (va1 + cross3(wa1, ra)) - (vb1 + cross3(wb1, rb));
        const double along = dot3(rel1 - dot3(rel1, nrm) * nrm, (1.0 / imp_len) * imp);
        // The row's point is one point between the bodies' witness points, which an engine
        // may use instead (Bullet: A's velocity at the point on A, B's at the point on B).
        // Moving a body's point by s along the normal moves its velocity there by up to
        // |w| s: on spinning bodies the sliding velocity is known to within |w_a| + |w_b|
        // times the distance between the witness points. A rolling icosphere of rot-drop-220
        // (|w| 3.9 rad/s, resting on a 1 mm hull margin, as the adapter then had) shows 1-3 mm/s at the midpoint
        // while it rolls without sliding. Judged beyond that allowance.
        double allowance = 0.0;
        if (along > tol.friction_speed + allowance) {
          // The witness points lie at most the row's depth apart (penetrating), or the gap
          // between the surfaces across the point (FCL: its distance to each surface).
          const double gap = std::max(double(c.depth), ref->surface_distance(p.a, det[p.a], c.point) +
                                                           ref->surface_distance(p.b, det[p.b], c.point));
          allowance += (len3(wa1) + len3(wb1)) * gap;
        }
        dissipation.check(along <= tol.friction_speed + allowance, along, Where{frame, p}, [&] {
          return fmt::format(
              "frame {}: {} row {}: the friction impulse ({:.4g} kg m/s, from the momentum change) pushes the contact "
              "point along its sliding: {:.4g} m/s along the impulse after the step (tangential speed at the contact "
              "point {:.6g} -> {:.6g} m/s, {:.6g} with the normal impulses alone; witness-point allowance {:.3g} m/s)",
              frame, pair_name(p), k - k0, imp_len, along, before, after, with_normal, allowance);
        });
      }
    }
  };
  judge_in_order<DissipationDry>(first_row.size() - 1, threads, kParallelConesFrom, stop, *this,
                                 std::array<Tally*, 1>{&dissipation_tally}, judge_dissipation);
}

// ---- friction: its measure of a frame and its table entry -------------------------

template <>
void PhysicsValidators::Impl::measure<RowId::Friction>(PhysicsFrame& f) {
  // Every frame: the cone; dissipation on frames with states.
  friction(f.rec, f.det);
}

template <>
ValidationResult PhysicsValidators::Impl::table<RowId::Friction>() const {
  const Impl& s = *this;
  auto [cone, dissipation] = s.tallies(RowId::Friction, "cone", "dissipation");
  ValidationResult r = failures_row(RowId::Friction, "contacts outside the cone or rows raising the tangential speed",
                                    "friction_cone_abs,friction_speed");
  r.applicable = cone.checks > 0;
  if (cone.failures) {
    r.detail = cone.first + fmt::format(" ({} of {} contacts outside the cone)", cone.failures, cone.checks);
  } else if (dissipation.failures) {
    r.detail = dissipation.first + fmt::format(" ({} of {} rows where friction raises the sliding)",
                                               dissipation.failures, dissipation.checks);
  } else if (s.bodies.impulses != PhysicsBodies::Impulses::Complete) {
    r.detail = fmt::format(
        "n/a: the trace declares impulses = \"{}\": its rows carry no friction impulse, so the "
        "cone and dissipation are not judged (on the zeros a writer puts in jt, jt3 they would "
        "pass vacuously){}",
        impulses_name(s.bodies.impulses),
        s.bodies.impulses == PhysicsBodies::Impulses::NormalOnly
            ? "; momentum-balance holds each body's residual within its rows' cones"
            : "");
  } else if (!r.applicable) {
    r.detail = "no contact rows";
  } else {
    r.detail = fmt::format(
        "{} contacts in the cone (worst {:.3g} kg m/s inside; rule jt3 on {} pairs, scalar jt on "
        "{}); dissipation on {} rows or pairs (worst {:.3g} m/s; {} pairs on jt3); {} rows judged "
        "on the cone only (scalar jt: the pair is not its bodies' only one, or no states)",
        cone.checks, -cone.worst_or(0.0), s.cone_jt3_pairs, s.cone_scalar_pairs, dissipation.checks,
        dissipation.worst_or(0.0), s.dissipation_jt3_pairs, s.dissipation_cone_only);
    note(r.detail, s.dissipation_small,
         "{} pairs with a friction impulse up to friction_cone_abs not judged on its "
         "direction",
         s.dissipation_small);
  }
  if (r.applicable) s.fill_causes(r, RowId::Friction);
  return r;
}

}  // namespace octocd
