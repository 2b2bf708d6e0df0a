// The impulse-feasibility row's linear programme (feasibility.hpp; docs/validation.md,
// "Motion explained by feasible contact impulses", 2-4): per island, the compressive
// impulses inside each pair's friction cone (a circumscribed pyramid) that minimise the
// largest residual of every body's momentum change (and, with rotation, its angular
// momentum change) in units of its bound, solved with COIN-OR CLP; above 1 of the bound, a
// failure naming the body, its residual, the nearest feasible impulses and the bodies whose
// motion, left free, explains it. The first programmes of consecutive small translation-
// only islands are solved as one (block-diagonal) programme; an island whose impulses
// found there leave more than its bound is solved again on its own.
#include "feasibility.hpp"

#include <algorithm>
#include <array>
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

/// Programmes solved as one (translation only): each of at most kMaxSharedProgramme matrix
/// entries (CLP's set-up is most of such a programme's solve; a larger one's iterations
/// outweigh it), at most kMaxSharedEntries in all (larger arrays leave the allocator's
/// reused memory).
constexpr std::size_t kMaxSharedProgramme = 256;
constexpr std::size_t kMaxSharedEntries = 4096;

/// CLP's iteration limit of a solve: kIterationsPerEntry per matrix entry, at least
/// kMinIterations (an island's programme takes tens of iterations).
constexpr int kMinIterations = 10000;
constexpr int kIterationsPerEntry = 20;

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

enum class Kind { Cone, Normal, Friction, Torsion };

/// One island's programme: minimise t over impulses lambda >= 0 with |A lambda - b|_r <= t
/// sigma_r for every row r (rows: per body 3 linear, with rotation 3 angular; row r of body
/// slot s is per s + r), and with friction per manifold its budget rows. Built once per
/// island; each solve scales its values and row bounds by that solve's bounds.
struct Programme {
  const std::vector<Contact>* contacts = nullptr;
  const std::vector<std::uint32_t>* members = nullptr;
  std::size_t per = 3, rows = 0;
  /// Body i's slot in `members` (ascending), or kNone.
  static constexpr std::size_t kNone = std::size_t(-1);
  std::size_t slot(std::uint32_t i) const {
    const auto it = std::lower_bound(members->begin(), members->end(), i);
    return it != members->end() && *it == i ? std::size_t(it - members->begin()) : kNone;
  }
  /// The momentum changes (b; b_alt: the angular rows without the gyroscopic term) and the
  /// bounds before the impulses' own rounding (sigma0).
  std::vector<double> b, b_alt, sigma0;
  std::vector<std::uint32_t> points_of;
  std::vector<double> lever_of, reach_of, turn, spin_turn;
  struct Column {
    std::size_t contact;
    D3 dir;  ///< the impulse on A (Torsion: the torque on A)
    Kind kind = Kind::Cone;
  };
  std::vector<Column> columns;
  /// A, column-major: column c's entries col_start[c] .. col_start[c + 1] at rows row_index.
  std::vector<int> col_start{0};
  std::vector<int> row_index;
  std::vector<double> value;
  /// Per column: its budget rows and coefficients (already divided by their scales).
  std::vector<std::vector<std::pair<int, double>>> budget_of;
  std::size_t budgets = 0;
  /// CLP's pattern: row r of A as rows 2r (A' lambda - t <= b') and 2r + 1 (A' lambda + t
  /// >= b'), the budget rows after them, the column of t last.
  std::vector<int> idx;
  std::vector<CoinBigIndex> start{0};

  /// Empties every list (keeping its memory) for the next island's build.
  void clear() {
    for (auto* v : {&b, &b_alt, &sigma0, &lever_of, &reach_of, &turn, &spin_turn, &value}) v->clear();
    points_of.clear();
    columns.clear();
    col_start.assign(1, 0);
    row_index.clear();
    budget_of.clear();
    budgets = 0;
    idx.clear();
    start.assign(1, 0);
  }
  std::size_t ncols() const { return columns.size(); }
  int nrows() const { return int(2 * rows + budgets); }
  /// The largest scaled residual |b - A lambda|_r / sig_r of impulses `lambda`, in double;
  /// `residual` takes b - A lambda.
  double figure_of(const std::vector<double>& rhs, const std::vector<double>& sig, const std::vector<double>& lambda,
                   std::vector<double>& residual) const {
    residual.assign(rhs.begin(), rhs.end());
    for (std::size_t c = 0; c < ncols(); ++c)
      for (int e = col_start[c]; e < col_start[c + 1]; ++e)
        residual[std::size_t(row_index[std::size_t(e)])] -= value[std::size_t(e)] * lambda[c];
    double worst = 0;
    for (std::size_t r = 0; r < rows; ++r) worst = std::max(worst, std::fabs(residual[r]) / sig[r]);
    return worst;
  }
};

/// The impulse on A of one contact point's generators (programme columns c0 .. c0 +
/// kConeSides - 1) at impulses `lambda` (kg m/s).
D3 pyramid_impulse(const Programme& P, std::size_t c0, const std::vector<double>& lambda) {
  D3 j{0, 0, 0};
  for (int q = 0; q < kConeSides; ++q) j = j + lambda[c0 + std::size_t(q)] * P.columns[c0 + std::size_t(q)].dir;
  return j;
}

/// Impulses on the kConeSides generators of one contact point's pyramid (programme columns
/// c0 .. c0 + kConeSides - 1, each the impulse `dir` on A) whose sum on A comes near `x`
/// (kg m/s), in closed form: x's component along the pyramid's axis (zero where it points
/// out of the pyramid) shared by the generators, its tangential component taken by the one
/// or two generators nearest its direction, scaled into the pyramid where it reaches
/// beyond. Written into `lambda` (the other columns untouched).
void pyramid_witness(const Programme& P, std::size_t c0, const D3& x, std::vector<double>& lambda) {
  D3 axis{0, 0, 0};
  for (int j = 0; j < kConeSides; ++j) axis = axis + (1.0 / kConeSides) * P.columns[c0 + std::size_t(j)].dir;
  const double beta = dot3(x, axis) / dot3(axis, axis);
  for (int j = 0; j < kConeSides; ++j) lambda[c0 + std::size_t(j)] = 0.0;
  if (!(beta > 0.0)) return;
  const D3 t = x - beta * axis;
  std::array<D3, kConeSides> w;
  std::size_t k = 0;
  for (int j = 0; j < kConeSides; ++j) {
    w[std::size_t(j)] = P.columns[c0 + std::size_t(j)].dir - axis;
    if (dot3(t, w[std::size_t(j)]) > dot3(t, w[k])) k = std::size_t(j);
  }
  const std::size_t next = (k + 1) % kConeSides, prev = (k + kConeSides - 1) % kConeSides;
  const std::size_t k2 = dot3(t, w[next]) >= dot3(t, w[prev]) ? next : prev;
  // t = a w_k + c w_k2 (least squares in the plane of the two), else along w_k alone.
  const double g11 = dot3(w[k], w[k]), g12 = dot3(w[k], w[k2]), g22 = dot3(w[k2], w[k2]);
  const double r1 = dot3(t, w[k]), r2 = dot3(t, w[k2]), det = g11 * g22 - g12 * g12;
  double a = det > 0.0 ? (r1 * g22 - r2 * g12) / det : -1.0, c = det > 0.0 ? (r2 * g11 - r1 * g12) / det : -1.0;
  if (!(a >= 0.0 && c >= 0.0)) {
    a = g11 > 0.0 ? std::max(0.0, r1 / g11) : 0.0;
    c = 0.0;
  }
  a /= beta;
  c /= beta;
  if (a + c <= 1.0) {
    const double share = beta * (1.0 - a - c) / kConeSides;
    for (int j = 0; j < kConeSides; ++j) lambda[c0 + std::size_t(j)] = share;
    lambda[c0 + k] += beta * a;
    lambda[c0 + k2] += beta * c;
  } else {
    lambda[c0 + k] = beta * a / (a + c);
    lambda[c0 + k2] = beta * c / (a + c);
  }
}

/// The figure of impulses found by projected Gauss-Seidel sweeps for a translation-only
/// island with friction per contact point: contact point by contact point, the impulse in
/// its pyramid (pyramid_witness) that takes up the residual its bodies are left with by the
/// other points (split between two dynamic bodies row by row in proportion to their
/// bounds: the split that minimises the larger of the two scaled residuals), at most
/// `sweeps` sweeps, until a sweep lowers the figure no further; the smallest figure of the
/// sweeps and of no impulse (recomputed from the impulses: a witness, an upper bound on the
/// programme's minimum); `lambda` its impulses. Infinity where the form does not apply
/// (rotation, friction per manifold).
double witness_figure(const Programme& P, const std::vector<double>& rhs, const std::vector<double>& sig,
                      std::vector<double>& lambda, std::vector<double>& residual, int sweeps) {
  const std::vector<Contact>& contacts = *P.contacts;
  if (P.per != 3 || P.ncols() != kConeSides * contacts.size()) return std::numeric_limits<double>::infinity();
  for (const auto& column : P.columns)
    if (column.kind != Kind::Cone) return std::numeric_limits<double>::infinity();
  lambda.assign(P.ncols(), 0.0);
  double best = P.figure_of(rhs, sig, lambda, residual);
  std::vector<double> trial(P.ncols(), 0.0), res(rhs.begin(), rhs.end());
  for (int sweep = 0; sweep < sweeps && best > 0.0; ++sweep) {
    for (std::size_t k = 0; k < contacts.size(); ++k) {
      const Contact& c = contacts[k];
      const std::size_t sa = P.slot(c.pair.a), sb = P.slot(c.pair.b), c0 = kConeSides * k;
      const D3 j = pyramid_impulse(P, c0, trial);
      D3 x;
      for (std::size_t r = 0; r < 3; ++r) {
        const double ra = sa != Programme::kNone ? res[3 * sa + r] + j[r] : 0.0;
        const double rb = sb != Programme::kNone ? res[3 * sb + r] - j[r] : 0.0;
        if (sa == Programme::kNone)
          x[r] = -rb;
        else if (sb == Programme::kNone)
          x[r] = ra;
        else
          x[r] = (ra * sig[3 * sb + r] - rb * sig[3 * sa + r]) / (sig[3 * sa + r] + sig[3 * sb + r]);
      }
      pyramid_witness(P, c0, x, trial);
      const D3 j2 = pyramid_impulse(P, c0, trial);
      for (std::size_t r = 0; r < 3; ++r) {
        if (sa != Programme::kNone) res[3 * sa + r] += j[r] - j2[r];
        if (sb != Programme::kNone) res[3 * sb + r] -= j[r] - j2[r];
      }
    }
    const double f = P.figure_of(rhs, sig, trial, residual);
    if (!(f < best)) break;
    best = f;
    lambda = trial;
  }
  return best;
}

/// One programme of a solve: the island's, its right-hand side and bounds, and what the
/// solve returns (its impulses and figure: NaN when CLP finds none).
struct Solve {
  const Programme* p;
  const std::vector<double>* rhs;
  const std::vector<double>* sig;
  std::vector<double> lambda;
  double figure = std::numeric_limits<double>::quiet_NaN();
};

/// How CLP solves a programme: its dual simplex with scaling off (every solve), then, as
/// second opinions, its dual simplex with its automatic scaling and its primal simplex.
enum class Simplex { Dual, DualScaled, Primal };

/// Solves the programmes of `solves` as one CLP programme (block-diagonal: each island's
/// impulse columns then its t, its rows after the island before it; objective the sum of
/// the t's, whose optimum is each island's own) with `simplex`. One programme alone is the
/// island's own programme exactly (CLP's status 0 or 1 taken); several take status 0 only
/// (else none is solved). Each figure is recomputed in double from the island's impulses.
void solve_together(std::vector<Solve>& solves, Simplex simplex = Simplex::Dual) {
  std::size_t ncols = 0, nnz = 0;
  int nrows = 0;
  for (const Solve& s : solves) {
    ncols += s.p->ncols() + 1;
    nrows += s.p->nrows();
    nnz += s.p->idx.size();
  }
  std::vector<int> idx;
  std::vector<CoinBigIndex> start{0};
  std::vector<double> val, col_lo(ncols, 0.0), col_hi(ncols, COIN_DBL_MAX), obj(ncols, 0.0);
  std::vector<double> row_lo(std::size_t(nrows), -COIN_DBL_MAX), row_hi(std::size_t(nrows), 0.0);
  idx.reserve(nnz);
  val.reserve(nnz);
  start.reserve(ncols + 1);
  // Each impulse column is scaled so that its largest entry (in units of its rows' bounds)
  // is 1: CLP's tolerance on a column's bound (lambda >= 0, about 1e-7) then stands for at
  // most 1e-7 of a bound, where in kg m/s it would be a hundred times a resting body's bound
  // of 1e-9 (an impulse a few 1e-9 below 0, taken as 0, leaves that body several bounds
  // off). lambda_c = scale_c x_c.
  std::vector<double> scale(ncols, 1.0);
  int row0 = 0;
  std::size_t col0 = 0;
  for (const Solve& s : solves) {
    const Programme& p = *s.p;
    const std::vector<double>& sig = *s.sig;
    const std::vector<double>& rhs = *s.rhs;
    for (std::size_t c = 0; c < p.ncols(); ++c) {
      double largest = 0;
      for (int e = p.col_start[c]; e < p.col_start[c + 1]; ++e)
        largest = std::max(largest, std::fabs(p.value[std::size_t(e)] / sig[std::size_t(p.row_index[std::size_t(e)])]));
      const double k = largest > 0 ? 1.0 / largest : 1.0;
      scale[col0 + c] = k;
      for (int e = p.col_start[c]; e < p.col_start[c + 1]; ++e) {
        const double v = k * (p.value[std::size_t(e)] / sig[std::size_t(p.row_index[std::size_t(e)])]);
        val.push_back(v);
        val.push_back(v);
      }
      for (const auto& entry : p.budget_of[c]) val.push_back(k * entry.second);
    }
    for (std::size_t r = 0; r < p.rows; ++r) {
      val.push_back(-1.0);
      val.push_back(1.0);
    }
    for (std::size_t k = 0; k + 1 < p.start.size(); ++k) {
      for (CoinBigIndex e = p.start[k]; e < p.start[k + 1]; ++e) idx.push_back(row0 + p.idx[std::size_t(e)]);
      start.push_back(CoinBigIndex(idx.size()));
    }
    obj[col0 + p.ncols()] = 1.0;
    for (std::size_t r = 0; r < p.rows; ++r) {
      row_hi[std::size_t(row0) + 2 * r] = row_lo[std::size_t(row0) + 2 * r + 1] = rhs[r] / sig[r];
      row_hi[std::size_t(row0) + 2 * r + 1] = COIN_DBL_MAX;
    }
    row0 += p.nrows();
    col0 += p.ncols() + 1;
  }
  ClpSimplex lp(pristine_simplex());
  lp.setLogLevel(0);
  // Scaling off but for the second opinion that asks for it: CLP's scaled tolerances would
  // leave unscaled residuals of several bounds.
  lp.scaling(simplex == Simplex::DualScaled ? 3 : 0);
  lp.loadProblem(int(ncols), nrows, start.data(), idx.data(), val.data(), col_lo.data(), col_hi.data(), obj.data(),
                 row_lo.data(), row_hi.data());
  // CLP's simplex can cycle without end on a programme whose bounds span twelve orders of
  // magnitude (a body's rows left free by 1e12, beside 1e-9); a solve stopped at the limit
  // (status 3) finds nothing.
  lp.setMaximumIterations(std::max(kMinIterations, kIterationsPerEntry * int(idx.size())));
  if (simplex == Simplex::Primal)
    lp.primal();
  else
    lp.dual();
  const bool solved = lp.status() == 0 || (solves.size() == 1 && lp.status() == 1);
  const double* x = lp.primalColumnSolution();
  std::vector<double> residual;
  col0 = 0;
  for (Solve& s : solves) {
    const Programme& p = *s.p;
    s.lambda.assign(p.ncols(), 0.0);
    s.figure = std::numeric_limits<double>::quiet_NaN();
    if (solved) {
      for (std::size_t c = 0; c < p.ncols(); ++c) s.lambda[c] = scale[col0 + c] * std::max(0.0, x[col0 + c]);
      s.figure = p.figure_of(*s.rhs, *s.sig, s.lambda, residual);
    }
    col0 += p.ncols() + 1;
  }
}

/// One island's programme solved alone for `rhs` with bounds `sig` by `simplex`: its figure
/// (NaN when CLP finds none); `lambda` its impulses.
double solve_alone(const Programme& p, const std::vector<double>& rhs, const std::vector<double>& sig,
                   std::vector<double>& lambda, Simplex simplex = Simplex::Dual) {
  std::vector<Solve> one{Solve{&p, &rhs, &sig, {}}};
  solve_together(one, simplex);
  lambda = std::move(one[0].lambda);
  return one[0].figure;
}

}  // namespace

}  // namespace octocd::feasibility

namespace octocd {

void PhysicsValidators::Impl::feasibility_islands(const FrameRecord& rec, const std::vector<Pose>& det,
                                                  const std::vector<std::vector<feasibility::Contact>>& island_contacts,
                                                  const std::vector<std::vector<std::uint32_t>>& island_members,
                                                  const std::uint32_t* ids, std::size_t count, bool rotating,
                                                  feasibility::IslandPass pass,
                                                  std::vector<feasibility::IslandVerdict>& verdicts) const {
  using namespace feasibility;
  const D3 g = d3(model->scene.gravity);
  const double dt = model->scene.dt;
  const double eps = tol.balance_ulps * kEps32;
  auto locked = [&](std::uint32_t i) -> unsigned { return bodies.locked_dofs.empty() ? 0u : bodies.locked_dofs[i]; };
  // Islands the row does not judge, counted: false when `verdict` is decided here.
  auto judged = [&](const std::vector<std::uint32_t>& members, IslandVerdict& verdict) {
    for (const std::uint32_t i : members) {
      if (asleep(rec.asleep_pre, i) || asleep(rec.asleep_post, i)) {
        verdict.outcome = Outcome::Asleep;
        return false;
      }
      if (locked(i)) {
        verdict.outcome = Outcome::Locked;
        return false;
      }
      if (bodies.velocity_clamp > 0.0) {
        const Vec3 v = rec.v_post[i];
        const double c = bodies.velocity_clamp * (1.0 - 1e-6);
        if (std::fabs(v.x) >= c || std::fabs(v.y) >= c || std::fabs(v.z) >= c) {
          verdict.outcome = Outcome::Clamped;
          return false;
        }
      }
    }
    if (members.size() > kMaxIslandBodies) {
      verdict.outcome = Outcome::TooLarge;
      return false;
    }
    return true;
  };
  // The island's programme: its rows' momentum changes and bounds, its columns, and where
  // `pattern`, CLP's pattern.
  auto build = [&](Programme& P, bool pattern) {
    const std::vector<Contact>& contacts = *P.contacts;
    const std::vector<std::uint32_t>& members = *P.members;
    P.per = rotating ? 6 : 3;
    const std::size_t per = P.per;
    const std::size_t rows = P.rows = per * members.size();
    auto& b = P.b;
    auto& b_alt = P.b_alt;
    auto& sigma0 = P.sigma0;
    b.assign(rows, 0.0);
    sigma0.assign(rows, 0.0);
    P.points_of.assign(members.size(), 0);
    P.lever_of.assign(members.size(), 0.0);
    P.reach_of.assign(members.size(), 0.0);
    for (const Contact& c : contacts) {
      for (const std::uint32_t i : {c.pair.a, c.pair.b}) {
        const std::size_t s = P.slot(i);
        if (s == Programme::kNone) continue;
        ++P.points_of[s];
        P.lever_of[s] = std::max(P.lever_of[s], c.lever);
        P.reach_of[s] = std::max(P.reach_of[s], len3(c.point_of(i) - com_at(det[i], i)));
      }
    }
    if (rotating) b_alt.assign(rows, 0.0);
    P.turn.assign(members.size(), 0.0);
    P.spin_turn.assign(members.size(), 0.0);
    for (std::size_t s = 0; s < members.size(); ++s) {
      const std::uint32_t i = members[s];
      const double mi = mass[i];
      const D3 v0 = d3(rec.v_pre[i]) + dt * g, v1 = d3(rec.v_post[i]);
      const D3 dp = mi * (v1 - v0);
      const double k2 = double(P.points_of[s] + 2);
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
      P.turn[s] = std::min(2.0, om * dt);
      P.spin_turn[s] = dt * (principal[i][0] > 0 ? std::max(len3(l0), len3(l1)) / principal[i][0] : 0.0) + dt * om;
      const double pm1 = principal[i][0], pm3 = principal[i][1];
      const double d = pm3 > pm1 ? 0.5 * (pm3 - pm1) : 0.0;
      // Free rotation's second-order change of L in a first-order step (balance.cpp's
      // spin bounds): 5/2 D dt^2 om^3 + (1 + dt om) dt |w' - w| |L|.
      const double spin = 2.5 * d * dt * dt * om * om * om +
                          (1.0 + dt * om) * dt * len3(w1 - w0) * std::max(len3(l0), len3(l1));
      // Rounding of the spin, and the torque an impulse of the linear bound's size has at
      // the body's farthest contact point (the impulses that absorb the linear rounding).
      const double ang = eps * k2 * (len3(mul(iw, w0)) + len3(mul(iw, w1))) + P.reach_of[s] * lin + 1e-9;
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
    // A column acting on A (+) and B (-): an impulse `dir` at the contact's point, or a torque.
    auto add_column = [&](std::size_t k, const D3& dir, Kind kind) {
      const Contact& c = contacts[k];
      P.columns.push_back({k, dir, kind});
      for (const auto& [i, sign] : {std::pair<std::uint32_t, double>{c.pair.a, 1.0}, {c.pair.b, -1.0}}) {
        const std::size_t s = P.slot(i);
        if (s == Programme::kNone) continue;
        if (kind != Kind::Torsion)
          for (int r = 0; r < 3; ++r) {
            P.row_index.push_back(int(per * s + r));
            P.value.push_back(sign * dir[std::size_t(r)]);
          }
        if (rotating) {
          const D3 t = kind == Kind::Torsion ? dir : cross3(c.point_of(i) - com_at(det[i], i), dir);
          for (int r = 0; r < 3; ++r) {
            P.row_index.push_back(int(per * s + 3 + r));
            P.value.push_back(sign * t[std::size_t(r)]);
          }
        }
      }
      P.col_start.push_back(int(P.row_index.size()));
    };
    // Budget rows (friction_per "manifold"): sum over columns of coef x lambda <= 0, each
    // divided by `scale` (a row of the pair's first dynamic body in sigma0) for the programme.
    struct Budget {
      std::vector<std::pair<std::size_t, double>> coef;  // column, coefficient
      std::size_t scale_row = 0;
    };
    std::vector<Budget> budgets;
    if (!bodies.friction_per_manifold) {
      for (std::size_t k = 0; k < contacts.size(); ++k) {
        const Contact& c = contacts[k];
        const auto [e1, e2] = tangent_basis(c.normal);
        const double reach = tilted_mu(c.mu, c.slack_deg) * widen;
        for (int j = 0; j < kConeSides; ++j) {
          const double a = 2.0 * kPi * j / kConeSides;
          add_column(k, c.normal + reach * (std::cos(a) * e1 + std::sin(a) * e2), Kind::Cone);
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
      for (std::size_t k = 0; k < contacts.size(); ++k) by_pair[{contacts[k].pair.a, contacts[k].pair.b}].push_back(k);
      for (const auto& [pr, pks] : by_pair) {
        const std::size_t first_slot = P.slot(pr.first) != Programme::kNone ? P.slot(pr.first) : P.slot(pr.second);
        Budget linear, torsion;
        linear.scale_row = per * first_slot;
        torsion.scale_row = per * first_slot + 3;
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
          linear.coef.emplace_back(P.columns.size(), -widen * mu_t);
          torsion.coef.emplace_back(P.columns.size(), -mu_t * extent);
          add_column(k, c.normal, Kind::Normal);
          const auto [e1, e2] = tangent_basis(c.normal);
          for (int j = 0; j < kConeSides; ++j) {
            const double a = 2.0 * kPi * j / kConeSides;
            linear.coef.emplace_back(P.columns.size(), 1.0);
            add_column(k, std::cos(a) * e1 + std::sin(a) * e2, Kind::Friction);
          }
          if (!rotating) continue;
          bool known = false;
          for (const D3& u : axes) known = known || dot3(u, c.normal) > 1.0 - 1e-9;
          if (known) continue;
          axes.push_back(c.normal);
          for (const double sign : {1.0, -1.0}) {
            torsion.coef.emplace_back(P.columns.size(), 1.0);
            add_column(k, sign * c.normal, Kind::Torsion);
          }
        }
        budgets.push_back(std::move(linear));
        if (rotating) budgets.push_back(std::move(torsion));
      }
    }
    if (!pattern) return;
    const std::size_t ncols = P.ncols();
    P.budgets = budgets.size();
    P.budget_of.assign(ncols, {});
    for (std::size_t bi = 0; bi < budgets.size(); ++bi)
      for (const auto& [c, v] : budgets[bi].coef)
        P.budget_of[c].emplace_back(int(bi), v / sigma0[budgets[bi].scale_row]);
    for (std::size_t c = 0; c < ncols; ++c) {
      for (int e = P.col_start[c]; e < P.col_start[c + 1]; ++e) {
        const int r = P.row_index[std::size_t(e)];
        P.idx.push_back(2 * r);
        P.idx.push_back(2 * r + 1);
      }
      for (const auto& entry : P.budget_of[c]) P.idx.push_back(int(2 * rows) + entry.first);
      P.start.push_back(CoinBigIndex(P.idx.size()));
    }
    for (std::size_t r = 0; r < rows; ++r) {  // the column of t
      P.idx.push_back(int(2 * r));
      P.idx.push_back(int(2 * r + 1));
    }
    P.start.push_back(CoinBigIndex(P.idx.size()));
  };
  // The verdict on a built island; `shared`: impulses within its bounds found by the
  // islands' shared solve (null: its programme is solved alone).
  auto finish = [&](const Programme& P, const Solve* shared, double witness) {
    const std::vector<Contact>& contacts = *P.contacts;
    const std::vector<std::uint32_t>& members = *P.members;
    const std::size_t per = P.per, ncols = P.ncols();
    const std::vector<double>& b = P.b;
    const std::vector<double>& sigma0 = P.sigma0;
    IslandVerdict verdict;
    verdict.witness = witness;
    // The bound grows with the impulses found: rounding of each impulse's sum (eps (k + 2)
    // |J|) and, with rotation, the lever the engine's point may take beside octocd's (its
    // depth and reach: `lever`), the turn of the body through the step and the impulse's
    // action within the step on the spin (balance.cpp: dt (|I_w^-1 tau| |L| + |w| |tau|)).
    auto widened = [&](const std::vector<double>& lambda) {
      std::vector<double> sig(sigma0);
      std::vector<double> jsum(members.size(), 0.0), tsum(members.size(), 0.0);
      for (std::size_t c = 0; c < ncols; ++c) {
        const Contact& ct = contacts[P.columns[c].contact];
        const double j = lambda[c] * len3(P.columns[c].dir);
        for (const std::uint32_t i : {ct.pair.a, ct.pair.b}) {
          const std::size_t s = P.slot(i);
          if (s != Programme::kNone) (P.columns[c].kind == Kind::Torsion ? tsum : jsum)[s] += j;
        }
      }
      for (std::size_t s = 0; s < members.size(); ++s) {
        const double k2 = double(P.points_of[s] + 2);
        for (int r = 0; r < 3; ++r) sig[per * s + r] += eps * k2 * jsum[s];
        if (rotating)
          for (int r = 0; r < 3; ++r)
            sig[per * s + 3 + r] +=
                jsum[s] * (eps * k2 * P.reach_of[s] + P.lever_of[s] + P.reach_of[s] * (P.turn[s] + P.spin_turn[s])) +
                tsum[s] * (eps * k2 + P.turn[s] + P.spin_turn[s]);
      }
      return sig;
    };
    std::vector<double> lambda, sigma;
    double figure = shared ? shared->figure : solve_alone(P, b, sigma0, lambda);
    if (shared) lambda = shared->lambda;
    const std::vector<double>* rhs = &b;
    if (!(figure <= 1.0) && std::isfinite(figure)) {
      sigma = widened(lambda);
      figure = solve_alone(P, b, sigma, lambda);
    } else {
      sigma = sigma0;
    }
    // A failure only where CLP's second opinions find no impulses within the bounds either
    // (a programme's bounds span 1e-9 to 1e-5 kg m/s where a resting box meets moving
    // ones). Any impulses found are a witness, so the smallest figure stands.
    for (const Simplex second : {Simplex::DualScaled, Simplex::Primal}) {
      if (figure <= 1.0 || !std::isfinite(figure)) break;
      std::vector<double> lambda2;
      const double f2 = solve_alone(P, b, sigma, lambda2, second);
      if (f2 < figure) {
        figure = f2;
        lambda = std::move(lambda2);
      }
    }
    if (!(figure <= 1.0) && rotating && bodies.gyroscopic == PhysicsBodies::Gyroscopic::Undeclared) {
      std::vector<double> lambda2;
      std::vector<double> s2 = sigma0;
      double f2 = solve_alone(P, P.b_alt, s2, lambda2);
      if (!(f2 <= 1.0) && std::isfinite(f2)) {
        s2 = widened(lambda2);
        f2 = solve_alone(P, P.b_alt, s2, lambda2);
      }
      if (f2 < figure || !std::isfinite(figure)) {
        figure = f2;
        lambda = lambda2;
        sigma = s2;
        rhs = &P.b_alt;
      }
    }
    // The witness impulses where they leave less than every solve.
    if (std::isfinite(witness) && !(figure <= witness)) {
      std::vector<double> unused;
      figure = witness_figure(P, b, sigma0, lambda, unused, kWitnessSweeps);
      sigma = sigma0;
      rhs = &b;
    }
    if (!std::isfinite(figure)) {
      verdict.outcome = Outcome::Unsolved;
      return verdict;
    }
    // The worst body of the nearest feasible impulses, named.
    std::vector<double> res;
    P.figure_of(*rhs, sigma, lambda, res);
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
        if (solve_alone(P, *rhs, free_sig, unused) <= 1.0) culprits.push_back(s);
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
        const Contact& ct = contacts[P.columns[c].contact];
        if (P.columns[c].kind == Kind::Torsion || (ct.pair.a != body && ct.pair.b != body)) continue;
        on_pair[{ct.pair.a, ct.pair.b}] = on_pair[{ct.pair.a, ct.pair.b}] + lambda[c] * P.columns[c].dir;
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
          rec.frame, physics_detail::group_name(members), members.size(), contacts.size(), body,
          angular ? "angular momentum" : "momentum", angular ? "dL" : "m (v' - v) - m g dt", (*rhs)[r0],
          (*rhs)[r0 + 1], (*rhs)[r0 + 2], angular ? "kg m^2/s" : "kg m/s", res[r0], res[r0 + 1], res[r0 + 2], figure,
          sigma[worst_row], pairs.empty() ? "none" : pairs, culprit_text);
    }();
    return verdict;
  };

  // IslandPass::Witness: each island's outcome, and for a judged one its witness figure
  // (witness_figure; infinity where none), which stands as its figure until a programme is
  // solved for it.
  if (pass == IslandPass::Witness) {
    Programme P;
    std::vector<double> lambda, residual;
    for (std::size_t k = 0; k < count; ++k) {
      const std::size_t ii = ids[k];
      verdicts[ii] = IslandVerdict{};
      if (!judged(island_members[ii], verdicts[ii]) || rotating || bodies.friction_per_manifold) continue;
      P.clear();
      P.contacts = &island_contacts[ii];
      P.members = &island_members[ii];
      build(P, false);
      verdicts[ii].witness = witness_figure(P, P.b, P.sigma0, lambda, residual, kWitnessSweeps);
      verdicts[ii].figure = verdicts[ii].witness;
      verdicts[ii].body = island_members[ii].front();
    }
    return;
  }
  // IslandPass::Programme: the islands `ids` (judged ones, ascending) in order, each built;
  // a rotating one or one of more than kMaxSharedProgramme entries finished at once (solved
  // alone: a rotating island's angular bounds are far apart in scale, and the shared solve
  // left a tenth of Bullet's rot-drop-220 islands above their bound, solved again), the
  // others gathered while their entries stay within kMaxSharedEntries, their first
  // programmes solved as one, then each finished (solved alone again where the impulses
  // found together leave more than its bound).
  std::vector<Programme> group;
  std::vector<std::size_t> group_at;
  std::size_t group_entries = 0;
  auto flush = [&] {
    std::vector<Solve> solves;
    for (const Programme& P : group) solves.push_back(Solve{&P, &P.b, &P.sigma0, {}});
    if (group.size() > 1) solve_together(solves);
    for (std::size_t k = 0; k < group.size(); ++k)
      verdicts[group_at[k]] = finish(group[k], group.size() > 1 && solves[k].figure <= 1.0 ? &solves[k] : nullptr,
                                     verdicts[group_at[k]].witness);
    group.clear();
    group_at.clear();
    group_entries = 0;
  };
  for (std::size_t k = 0; k < count; ++k) {
    const std::size_t ii = ids[k];
    Programme P;
    P.contacts = &island_contacts[ii];
    P.members = &island_members[ii];
    build(P, true);
    if (rotating || P.idx.size() > kMaxSharedProgramme) {
      verdicts[ii] = finish(P, nullptr, verdicts[ii].witness);
      continue;
    }
    if (group_entries + P.idx.size() > kMaxSharedEntries) flush();
    group_entries += P.idx.size();
    group.push_back(std::move(P));
    group_at.push_back(ii);
  }
  flush();
}

}  // namespace octocd
