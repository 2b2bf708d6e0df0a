// The impulse-feasibility row's linear programme (feasibility.hpp; docs/validation.md,
// "Motion explained by feasible contact impulses", 2-4): per island, the compressive
// impulses inside each pair's friction cone (a circumscribed pyramid) that minimise the
// largest residual of every body's momentum change (and, with rotation, its angular
// momentum change) in units of its bound, solved with COIN-OR CLP; above 1 of the bound, a
// failure naming the body, its residual, the nearest feasible impulses and the bodies whose
// motion, left free, explains it.
#include "feasibility.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

#include <ClpSimplex.hpp>

namespace octocd::feasibility {

using namespace dmath;
using namespace feasibility_geometry;
using physics_detail::conjugated;
using physics_detail::kEps32;
using physics_detail::kPi;

namespace {

/// Of a failing island, the most bodies whose motion is left free in turn to find which
/// explain the failure.
constexpr std::size_t kMaxLeftFree = 16;

/// The friction coefficient of the cone about n that holds every cone of coefficient mu
/// about a normal within `slack_deg` of n: tan(atan(mu) + the slack).
double tilted_mu(double mu, double slack_deg) {
  return std::tan(std::min(std::atan(mu) + slack_deg * kPi / 180.0, 1.5));
}

/// A ClpSimplex as its constructor leaves it, copied for every solve: the constructor builds
/// CLP's message catalogue, a tenth of a judged step's instructions on Bullet's rot-drop-220
/// (callgrind), which a copy takes ready-made. Never destroyed: a judging thread may copy it
/// until the process ends.
const ClpSimplex& pristine_simplex() {
  static const ClpSimplex* const pristine = new ClpSimplex;
  return *pristine;
}

}  // namespace

}  // namespace octocd::feasibility

namespace octocd {

feasibility::IslandVerdict PhysicsValidators::Impl::feasibility_island(
    const FrameRecord& rec, const std::vector<Pose>& det, const std::vector<feasibility::Contact>& contacts,
    const std::vector<std::uint32_t>& members, const std::vector<std::size_t>& ks, bool rotating) const {
  using namespace feasibility;
  const D3 g = d3(model->scene.gravity);
  const double dt = model->scene.dt;
  const double eps = tol.balance_ulps * kEps32;
  auto locked = [&](std::uint32_t i) -> unsigned { return bodies.locked_dofs.empty() ? 0u : bodies.locked_dofs[i]; };
  IslandVerdict verdict;
  // Islands the row does not judge, counted.
  for (const std::uint32_t i : members) {
    if (asleep(rec.asleep_pre, i) || asleep(rec.asleep_post, i)) {
      verdict.outcome = Outcome::Asleep;
      return verdict;
    }
    if (locked(i)) {
      verdict.outcome = Outcome::Locked;
      return verdict;
    }
    if (bodies.velocity_clamp > 0.0) {
      const Vec3 v = rec.v_post[i];
      const double c = bodies.velocity_clamp * (1.0 - 1e-6);
      if (std::fabs(v.x) >= c || std::fabs(v.y) >= c || std::fabs(v.z) >= c) {
        verdict.outcome = Outcome::Clamped;
        return verdict;
      }
    }
  }
  if (members.size() > kMaxIslandBodies) {
    verdict.outcome = Outcome::TooLarge;
    return verdict;
  }
  // Rows: per body 3 linear, with rotation 3 angular; row r of body slot s is 6 s + r.
  const std::size_t per = rotating ? 6 : 3;
  const std::size_t rows = per * members.size();
  std::map<std::uint32_t, std::size_t> slot;
  for (std::size_t s = 0; s < members.size(); ++s) slot[members[s]] = s;
  std::vector<double> b(rows), b_alt, sigma(rows), sigma0(rows);
  std::vector<std::uint32_t> points_of(members.size(), 0);
  std::vector<double> lever_of(members.size(), 0.0), reach_of(members.size(), 0.0);
  for (const std::size_t k : ks) {
    const Contact& c = contacts[k];
    for (const std::uint32_t i : {c.pair.a, c.pair.b}) {
      const auto it = slot.find(i);
      if (it == slot.end()) continue;
      ++points_of[it->second];
      lever_of[it->second] = std::max(lever_of[it->second], c.lever);
      reach_of[it->second] = std::max(reach_of[it->second], len3(c.point_of(i) - com_at(det[i], i)));
    }
  }
  if (rotating) b_alt.assign(rows, 0.0);
  std::vector<double> turn(members.size(), 0.0), spin_turn(members.size(), 0.0);
  for (std::size_t s = 0; s < members.size(); ++s) {
    const std::uint32_t i = members[s];
    const double mi = mass[i];
    const D3 v0 = d3(rec.v_pre[i]) + dt * g, v1 = d3(rec.v_post[i]);
    const D3 dp = mi * (v1 - v0);
    const double k2 = double(points_of[s] + 2);
    const double lin = eps * k2 * mi * (len3(d3(rec.v_pre[i])) + len3(v1) + len3(dt * g)) + 1e-9;
    // integrated_point "origin": the centre of mass's drift under the origin's first-order
    // integration, momentum-balance's allowance (docs/validation.md, "An engine that
    // integrates the body origin").
    const double drift = mi * origin_drift(rec, i).velocity;
    for (int r = 0; r < 3; ++r) {
      b[per * s + r] = dp[std::size_t(r)];
      sigma0[per * s + r] = lin + drift;
      if (rotating) b_alt[per * s + r] = dp[std::size_t(r)];
    }
    if (!rotating) continue;
    // The spin: L' - L with L = R I R^T w (the gyroscopic term, any first-order form), and
    // I_w (w' - w) (no term); the declared one, or either when undeclared.
    const D3 w0 = d3(rec.w_pre[i]), w1 = d3(rec.w_post[i]);
    const M3 iw = conjugated(rotation(det[i].orientation), inertia[i]);
    const M3 iw0 = conjugated(rotation(rec.q_pre[i]), inertia[i]);
    // L' at q advanced by w' dt, not at the recorded q' (balance.cpp): an engine's
    // position correction turns a body in contact without changing its angular momentum.
    const D3 l0 = mul(iw0, w0), l1 = turned(mul(iw0, w1), w1, dt), plain = mul(iw, w1 - w0);
    const double om = std::max(len3(w0), len3(w1));
    turn[s] = std::min(2.0, om * dt);
    spin_turn[s] = dt * (principal[i][0] > 0 ? std::max(len3(l0), len3(l1)) / principal[i][0] : 0.0) + dt * om;
    const double pm1 = principal[i][0], pm3 = principal[i][1];
    const double d = pm3 > pm1 ? 0.5 * (pm3 - pm1) : 0.0;
    // Free rotation's second-order change of L in a first-order step (balance.cpp's
    // spin bounds): 5/2 D dt^2 om^3 + (1 + dt om) dt |w' - w| |L|.
    const double spin = 2.5 * d * dt * dt * om * om * om +
                        (1.0 + dt * om) * dt * len3(w1 - w0) * std::max(len3(l0), len3(l1));
    // Rounding of the spin, and the torque an impulse of the linear bound's size has at
    // the body's farthest contact point (the impulses that absorb the linear rounding).
    const double ang = eps * k2 * (len3(mul(iw, w0)) + len3(mul(iw, w1))) + reach_of[s] * lin + 1e-9;
    const D3 dl = l1 - l0;
    const bool use_plain = bodies.gyroscopic == PhysicsBodies::Gyroscopic::Absent;
    for (int r = 0; r < 3; ++r) {
      b[per * s + 3 + r] = use_plain ? plain[std::size_t(r)] : dl[std::size_t(r)];
      b_alt[per * s + 3 + r] = plain[std::size_t(r)];
      sigma0[per * s + 3 + r] = ang + (use_plain ? 0.0 : spin);
    }
  }
  // Columns: kConeSides generators per contact point (the circumscribed pyramid); with
  // friction_per "manifold" a normal per contact point, kConeSides unit tangents per
  // contact point whose sum over a pair is bounded by its normal impulses (a budget row),
  // and with rotation a torsion about each of the pair's normals (a second budget row).
  const double widen = 1.0 / std::cos(kPi / kConeSides);
  std::vector<int> col_start{0};
  std::vector<int> row_index;
  std::vector<double> value;
  enum class Kind { Cone, Normal, Friction, Torsion };
  struct Column {
    std::size_t contact;
    D3 dir;  ///< the impulse on A (Torsion: the torque on A)
    Kind kind = Kind::Cone;
  };
  std::vector<Column> columns;
  // A column acting on A (+) and B (-): an impulse `dir` at the contact's point, or a torque.
  auto add_column = [&](std::size_t k, const D3& dir, Kind kind) {
    const Contact& c = contacts[k];
    columns.push_back({k, dir, kind});
    for (const auto& [i, sign] : {std::pair<std::uint32_t, double>{c.pair.a, 1.0}, {c.pair.b, -1.0}}) {
      const auto it = slot.find(i);
      if (it == slot.end()) continue;
      const std::size_t s = it->second;
      if (kind != Kind::Torsion)
        for (int r = 0; r < 3; ++r) {
          row_index.push_back(int(per * s + r));
          value.push_back(sign * dir[std::size_t(r)]);
        }
      if (rotating) {
        const D3 t = kind == Kind::Torsion ? dir : cross3(c.point_of(i) - com_at(det[i], i), dir);
        for (int r = 0; r < 3; ++r) {
          row_index.push_back(int(per * s + 3 + r));
          value.push_back(sign * t[std::size_t(r)]);
        }
      }
    }
    col_start.push_back(int(row_index.size()));
  };
  // Budget rows (friction_per "manifold"): sum over columns of coef x lambda <= 0, each
  // divided by `scale` (a row of the pair's first dynamic body in sigma0) for the programme.
  struct Budget {
    std::vector<std::pair<std::size_t, double>> coef;  // column, coefficient
    std::size_t scale_row = 0;
  };
  std::vector<Budget> budgets;
  if (!bodies.friction_per_manifold) {
    for (const std::size_t k : ks) {
      const Contact& c = contacts[k];
      const auto [e1, e2] = tangent_basis(c.normal);
      for (int j = 0; j < kConeSides; ++j) {
        const double a = 2.0 * kPi * j / kConeSides;
        add_column(k, c.normal + (tilted_mu(c.mu, c.slack_deg) * widen) * (std::cos(a) * e1 + std::sin(a) * e2),
                   Kind::Cone);
      }
    }
  } else {
    // Per pair: its normal impulses N_k, friction generators g (unit tangents at its points,
    // kConeSides a point: any tangential impulse at any point of the patch costs at most
    // 1 / cos(pi / kConeSides) its magnitude), sum g <= widen sum mu_k N_k; with rotation
    // torsions t about its normals, sum t <= sum mu_k D N_k, D the largest distance between
    // two of its points plus twice their largest lever (the engine's points may lie that
    // far from octocd's: each engine point's distance from the engine's mean point is <= D).
    std::map<std::pair<std::uint32_t, std::uint32_t>, std::vector<std::size_t>> by_pair;
    for (const std::size_t k : ks) by_pair[{contacts[k].pair.a, contacts[k].pair.b}].push_back(k);
    for (const auto& [pr, pks] : by_pair) {
      const auto it = slot.count(pr.first) ? slot.find(pr.first) : slot.find(pr.second);
      Budget linear, torsion;
      linear.scale_row = per * it->second;
      torsion.scale_row = per * it->second + 3;
      double span = 0, lever = 0;
      for (const std::size_t k : pks) {
        lever = std::max(lever, contacts[k].lever);
        for (const std::size_t q : pks) span = std::max(span, len3(contacts[k].point - contacts[q].point));
      }
      const double extent = span + 2.0 * lever;
      std::vector<D3> axes;
      for (const std::size_t k : pks) {
        const Contact& c = contacts[k];
        const double mu_t = tilted_mu(c.mu, c.slack_deg);
        linear.coef.emplace_back(columns.size(), -widen * mu_t);
        torsion.coef.emplace_back(columns.size(), -mu_t * extent);
        add_column(k, c.normal, Kind::Normal);
        const auto [e1, e2] = tangent_basis(c.normal);
        for (int j = 0; j < kConeSides; ++j) {
          const double a = 2.0 * kPi * j / kConeSides;
          linear.coef.emplace_back(columns.size(), 1.0);
          add_column(k, std::cos(a) * e1 + std::sin(a) * e2, Kind::Friction);
        }
        if (!rotating) continue;
        bool known = false;
        for (const D3& u : axes) known = known || dot3(u, c.normal) > 1.0 - 1e-9;
        if (known) continue;
        axes.push_back(c.normal);
        for (const double sign : {1.0, -1.0}) {
          torsion.coef.emplace_back(columns.size(), 1.0);
          add_column(k, sign * c.normal, Kind::Torsion);
        }
      }
      budgets.push_back(std::move(linear));
      if (rotating) budgets.push_back(std::move(torsion));
    }
  }
  const std::size_t ncols = columns.size();
  std::vector<std::vector<std::pair<int, double>>> budget_of(ncols);  // per column: budget row, coefficient
  for (std::size_t bi = 0; bi < budgets.size(); ++bi)
    for (const auto& [c, v] : budgets[bi].coef)
      budget_of[c].emplace_back(int(bi), v / sigma0[budgets[bi].scale_row]);
  // The programme: minimise t over impulses lambda >= 0 with |A lambda - b|_r <= t sigma_r
  // for every row r; solved with each row scaled by 1 / sigma_r. Its matrix, column-major:
  // row r of A as rows 2r (A' lambda - t <= b') and 2r + 1 (A' lambda + t >= b'), the
  // budget rows after them, the column of t last; the pattern is the island's, the values
  // and row bounds each solve's.
  const int nrows = int(2 * rows + budgets.size());
  std::vector<int> idx;
  std::vector<CoinBigIndex> start{0};
  for (std::size_t c = 0; c < ncols; ++c) {
    for (int e = col_start[c]; e < col_start[c + 1]; ++e) {
      const int r = row_index[std::size_t(e)];
      idx.push_back(2 * r);
      idx.push_back(2 * r + 1);
    }
    for (const auto& entry : budget_of[c]) idx.push_back(int(2 * rows) + entry.first);
    start.push_back(CoinBigIndex(idx.size()));
  }
  for (std::size_t r = 0; r < rows; ++r) {  // the column of t
    idx.push_back(int(2 * r));
    idx.push_back(int(2 * r + 1));
  }
  start.push_back(CoinBigIndex(idx.size()));
  std::vector<double> val(idx.size());
  std::vector<double> col_lo(ncols + 1, 0.0), col_hi(ncols + 1, COIN_DBL_MAX), obj(ncols + 1, 0.0);
  obj[ncols] = 1.0;
  std::vector<double> row_lo(std::size_t(nrows), -COIN_DBL_MAX), row_hi(std::size_t(nrows), 0.0), residual(rows);
  for (std::size_t r = 0; r < rows; ++r) row_hi[2 * r + 1] = COIN_DBL_MAX;
  // Solves the programme for `rhs` with bounds `sig`: the largest scaled residual of the
  // solution (recomputed in double; NaN when CLP finds none) and the solution.
  auto solve = [&](const std::vector<double>& rhs, const std::vector<double>& sig, std::vector<double>& lambda) {
    std::size_t at = 0;
    for (std::size_t c = 0; c < ncols; ++c) {
      for (int e = col_start[c]; e < col_start[c + 1]; ++e) {
        const double v = value[std::size_t(e)] / sig[std::size_t(row_index[std::size_t(e)])];
        val[at++] = v;
        val[at++] = v;
      }
      for (const auto& entry : budget_of[c]) val[at++] = entry.second;
    }
    for (std::size_t r = 0; r < rows; ++r) {
      val[at++] = -1.0;
      val[at++] = 1.0;
    }
    for (std::size_t r = 0; r < rows; ++r) row_hi[2 * r] = row_lo[2 * r + 1] = rhs[r] / sig[r];
    ClpSimplex lp(pristine_simplex());
    lp.setLogLevel(0);
    lp.scaling(0);  // its scaled tolerances would leave unscaled residuals of several bounds
    lp.loadProblem(int(ncols + 1), nrows, start.data(), idx.data(), val.data(), col_lo.data(), col_hi.data(),
                   obj.data(), row_lo.data(), row_hi.data());
    lp.dual();
    lambda.assign(ncols, 0.0);
    if (lp.status() != 0 && lp.status() != 1) return std::numeric_limits<double>::quiet_NaN();
    const double* x = lp.primalColumnSolution();
    for (std::size_t c = 0; c < ncols; ++c) lambda[c] = std::max(0.0, x[c]);
    residual.assign(rhs.begin(), rhs.end());
    for (std::size_t c = 0; c < ncols; ++c)
      for (int e = col_start[c]; e < col_start[c + 1]; ++e)
        residual[std::size_t(row_index[std::size_t(e)])] -= value[std::size_t(e)] * lambda[c];
    double worst = 0;
    for (std::size_t r = 0; r < rows; ++r) worst = std::max(worst, std::fabs(residual[r]) / sig[r]);
    return worst;
  };
  // The bound grows with the impulses found: rounding of each impulse's sum (eps (k + 2)
  // |J|) and, with rotation, the lever the engine's point may take beside octocd's (its
  // depth and reach: `lever`), the turn of the body through the step and the impulse's
  // action within the step on the spin (balance.cpp: dt (|I_w^-1 tau| |L| + |w| |tau|)).
  auto widened = [&](const std::vector<double>& lambda) {
    std::vector<double> sig(sigma0);
    std::vector<double> jsum(members.size(), 0.0), tsum(members.size(), 0.0);
    for (std::size_t c = 0; c < ncols; ++c) {
      const Contact& ct = contacts[columns[c].contact];
      const double j = lambda[c] * len3(columns[c].dir);
      for (const std::uint32_t i : {ct.pair.a, ct.pair.b}) {
        const auto it = slot.find(i);
        if (it != slot.end()) (columns[c].kind == Kind::Torsion ? tsum : jsum)[it->second] += j;
      }
    }
    for (std::size_t s = 0; s < members.size(); ++s) {
      const double k2 = double(points_of[s] + 2);
      for (int r = 0; r < 3; ++r) sig[per * s + r] += eps * k2 * jsum[s];
      if (rotating)
        for (int r = 0; r < 3; ++r)
          sig[per * s + 3 + r] += jsum[s] * (eps * k2 * reach_of[s] + lever_of[s] + reach_of[s] * (turn[s] + spin_turn[s])) +
                                  tsum[s] * (eps * k2 + turn[s] + spin_turn[s]);
    }
    return sig;
  };
  std::vector<double> lambda;
  double figure = solve(b, sigma0, lambda);
  const std::vector<double>* rhs = &b;
  if (!(figure <= 1.0) && std::isfinite(figure)) {
    sigma = widened(lambda);
    figure = solve(b, sigma, lambda);
  } else {
    sigma = sigma0;
  }
  if (!(figure <= 1.0) && rotating && bodies.gyroscopic == PhysicsBodies::Gyroscopic::Undeclared) {
    std::vector<double> lambda2;
    std::vector<double> s2 = sigma0;
    double f2 = solve(b_alt, s2, lambda2);
    if (!(f2 <= 1.0) && std::isfinite(f2)) {
      s2 = widened(lambda2);
      f2 = solve(b_alt, s2, lambda2);
    }
    if (f2 < figure || !std::isfinite(figure)) {
      figure = f2;
      lambda = lambda2;
      sigma = s2;
      rhs = &b_alt;
    }
  }
  if (!std::isfinite(figure)) {
    verdict.outcome = Outcome::Unsolved;
    return verdict;
  }
  // The worst body of the nearest feasible impulses, named.
  std::vector<double> res(*rhs);
  for (std::size_t c = 0; c < ncols; ++c)
    for (int e = col_start[c]; e < col_start[c + 1]; ++e)
      res[std::size_t(row_index[std::size_t(e)])] -= value[std::size_t(e)] * lambda[c];
  // Which bodies' motion is in question: those whose own rows, left free, make the island
  // feasible (one body or a few: along a chain of contacts the same residual may sit on
  // any of its bodies). The body named is the one of them with the largest scaled residual
  // in the nearest feasible impulses (the island's worst body when none alone does).
  auto body_figure = [&](std::size_t s) {
    double w = 0;
    for (std::size_t r = per * s; r < per * (s + 1); ++r) w = std::max(w, std::fabs(res[r]) / sigma[r]);
    return w;
  };
  std::vector<std::size_t> culprits;
  if (!(figure <= 1.0)) {
    for (std::size_t s = 0; s < members.size() && s < kMaxLeftFree; ++s) {
      std::vector<double> free_sig(sigma), unused;
      for (std::size_t r = per * s; r < per * (s + 1); ++r) free_sig[r] *= 1e12;
      if (solve(*rhs, free_sig, unused) <= 1.0) culprits.push_back(s);
    }
  }
  std::size_t ws = 0;
  if (!culprits.empty()) {
    ws = culprits[0];
    for (const std::size_t s : culprits)
      if (body_figure(s) > body_figure(ws)) ws = s;
  } else {
    for (std::size_t s = 1; s < members.size(); ++s)
      if (body_figure(s) > body_figure(ws)) ws = s;
  }
  std::size_t worst_row = per * ws;
  for (std::size_t r = per * ws; r < per * (ws + 1); ++r)
    if (std::fabs(res[r]) / sigma[r] > std::fabs(res[worst_row]) / sigma[worst_row]) worst_row = r;
  const std::uint32_t body = members[ws];
  verdict.figure = figure;
  verdict.body = body;
  if (figure <= 1.0) return verdict;
  verdict.text = [&] {
    std::string culprit_text;
    for (const std::size_t s : culprits)
      culprit_text += fmt::format("{}body {}", culprit_text.empty() ? "" : ", ", members[s]);
    culprit_text = culprits.empty() ? std::string("no single body's motion left free makes it feasible")
                                    : "feasible with the motion of any one of " + culprit_text + " left free";
    const bool angular = worst_row % per >= 3;
    const std::size_t r0 = per * ws + (angular ? 3 : 0);
    // The pairs of the worst body and the impulses the programme put on them.
    std::map<std::pair<std::uint32_t, std::uint32_t>, D3> on_pair;
    for (std::size_t c = 0; c < ncols; ++c) {
      const Contact& ct = contacts[columns[c].contact];
      if (columns[c].kind == Kind::Torsion || (ct.pair.a != body && ct.pair.b != body)) continue;
      on_pair[{ct.pair.a, ct.pair.b}] = on_pair[{ct.pair.a, ct.pair.b}] + lambda[c] * columns[c].dir;
    }
    std::string pairs;
    for (const auto& [pr, j] : on_pair) {
      if (pairs.size() > 300) {
        pairs += ", ...";
        break;
      }
      pairs += fmt::format("{}pair ({}, {}) ({:.4g}, {:.4g}, {:.4g})", pairs.empty() ? "" : ", ", pr.first,
                           pr.second, j[0], j[1], j[2]);
    }
    return fmt::format(
        "frame {}: island {} ({} bodies, {} contact points): no compressive impulses inside the friction cones "
        "explain body {}'s {} change {} = ({:.4g}, {:.4g}, {:.4g}) {}: the nearest feasible impulses leave "
        "({:.4g}, {:.4g}, {:.4g}), {:.3g} of the bound {:.3g} (on A of each pair: {}); {}",
        rec.frame, physics_detail::group_name(members), members.size(), ks.size(), body, angular ? "angular momentum" : "momentum",
        angular ? "dL" : "m (v' - v) - m g dt", (*rhs)[r0], (*rhs)[r0 + 1], (*rhs)[r0 + 2],
        angular ? "kg m^2/s" : "kg m/s", res[r0], res[r0 + 1], res[r0 + 2], figure, sigma[worst_row],
        pairs.empty() ? "none" : pairs, culprit_text);
  }();
  return verdict;
}

}  // namespace octocd
