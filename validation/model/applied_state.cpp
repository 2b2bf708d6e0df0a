// design.md section 7 item 9: an independent re-derivation of design.md section 4.1 and design.md section 6 in double precision,
// written from the text of docs/design.md. It shares nothing with the engines' response code (no
// math.hpp formula is called here): it reads only the model (scene, local boxes, inverse
// masses) and one FrameRecord, and predicts the state the engine should have applied.
//
// Relaxation passes: a decision within float32 rounding of its threshold (a near-tie) may
// go either way in the engine, and its outcome feeds every later pass. Each near-tie is a
// branch; the branches of an island (dynamic bodies joined by confirmed contacts) are
// explored breadth-first by the number of outcomes that differ from the proposal, within
// the bounds of applied_state.hpp. A float32 evaluation of the same formulas, in the
// order docs/design.md writes them, runs beside the double one and proposes each near-tie's
// outcome; it never decides a verdict: an outcome is only taken where the double value
// allows it (within the rounding margin), and the engine's state is compared with the
// double re-derivation.
#include "applied_state.hpp"

#include "../physics/dmath.hpp"
#include "../src/components.hpp"
#include "../src/parallel.hpp"
#include "../src/row_clock.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <deque>
#include <functional>
#include <limits>

#include <fmt/format.h>

#include "octocd/validation_rows.hpp"

namespace octocd {

namespace {

using dmath::D3;
using dmath::d3;
using dmath::kEps32;
using dmath::len3;
using dmath::operator-;
using F3 = std::array<float, 3>;

F3 f3(Vec3 v) { return {v.x, v.y, v.z}; }
double inf_norm(const D3& a) { return std::max({std::fabs(a[0]), std::fabs(a[1]), std::fabs(a[2])}); }

/// The kinds of near-tie (for messages and statistics).
enum Kind : std::uint8_t { kHit, kFixedAxis, kAxis, kSign, kApproach, kRestitution, kStick, kKinds };

/// One near-tie met by a run: the outcome taken and the outcomes the double value allows.
struct Choice {
  std::uint8_t outcome = 0;
  std::uint8_t allowed = 0;  // bit o: outcome o is consistent
  std::uint16_t pass = 0;
  std::uint32_t contact = 0;  // index into the island's contacts
};

/// The fewest bodies and contacts, summed over a frame's islands, whose searches run on the
/// validators' threads (two islands or more): below it one thread costs less than waking
/// another (a few hundred instructions a body on islands of one body).
constexpr std::size_t kParallelIslandWorkFrom = 1024;
/// The fewest bodies integrated on the validators' threads (a few instructions each).
constexpr std::size_t kParallelIntegrateFrom = 1024;

/// An island: dynamic bodies joined by confirmed contacts, and the contacts (indices into
/// rec.confirmed, in (a, b) order) touching them. `local` lists every body the contacts
/// touch, the island's dynamic ones first.
struct Island {
  std::vector<std::uint32_t> local;
  std::uint32_t dynamic = 0;
  std::vector<std::uint32_t> contacts;
  std::vector<std::array<std::uint32_t, 2>> ends;  // local indices of (a, b)
};

/// The result of one run of an island's passes.
struct Run {
  std::vector<Choice> trace;
  bool open = false;  // a near-tie whose outcomes cannot be enumerated (an undefined direction)
  std::vector<D3> x, v, x_tol, v_tol;
  std::vector<std::uint8_t> clamped;
  std::vector<std::uint32_t> count0;  // first-pass contacts per local body
  std::uint64_t work = 0;
  // Worst ratio |engine - prediction| / tolerance over the island's dynamic bodies, and
  // how many bodies exceed 1.
  double worst = 0.0;
  std::uint32_t off = 0;
};


/// What the search of one island adds to the judge's counters.
struct SearchCounts {
  std::uint64_t near_ties = 0, runs = 0, searched = 0, resolved = 0, exceeded = 0;
};

/// An isolated dynamic group's figures on the applied state (an island of two dynamic
/// bodies or more with no static body, none clamped), judged in island order.
struct GroupFigures {
  std::uint32_t bodies = 0, first = 0;
  bool centre = false;  // an isolated pair, each body with one contact: the centre is judged
  double dp = 0, bound = 0, exchange = 0, dc = 0, cbound = 0, cexchange = 0;
};

/// What one thread's islands add to the frame's tallies: integer counts, the worst ratio
/// (a maximum) and the first failure of the lowest island, so the sums over the threads do
/// not depend on how the islands were shared out.
struct IslandTally {
  SearchCounts counts;
  std::uint64_t checks = 0, failures = 0, dynamic_frames = 0, unjudged = 0;
  double worst = 0.0;
  std::size_t first_island = std::numeric_limits<std::size_t>::max();
  std::string first;
};

/// Work space of one island's run (AppliedStateJudge::Impl::run), kept per thread.
struct RunScratch {
  std::vector<F3> xf, vf, dxf_sum, dvf_sum;
  std::vector<D3> scale_x, scale_v, dx_sum, dv_sum;
  std::vector<double> coord_max, vel_max, run_v;
  std::vector<float> w;
  std::vector<std::uint32_t> count;
};

/// A body's rounding scales at a run's start, per axis: |x| + |dt v| for its position and
/// |v| + |dt g| for its velocity (|v| for a static body), x and v the integrated state.
void start_scales(const D3& x, const D3& v, bool dynamic, double dt, const D3& g, D3& scale_x, D3& scale_v) {
  for (int k = 0; k < 3; ++k) {
    scale_x[k] = std::fabs(x[k]) + std::fabs(dt * v[k]);
    scale_v[k] = std::fabs(v[k]) + (dynamic ? std::fabs(dt * g[k]) : 0.0);
  }
}

/// Eq. 23 on a dynamic body's velocity after `iterations` passes: each component clamped to
/// [-v_max, v_max]. The clamp is continuous, so a component near v_max needs no branch;
/// returns true where a component is within rounding of v_max or beyond (conservative:
/// the clamp changes its group's momentum).
bool clamp_velocity(D3& v, double vmax, int iterations) {
  bool clamped = false;
  for (int k = 0; k < 3; ++k) {
    if (std::fabs(v[k]) > vmax * (1.0 - 16.0 * kEps32 * (iterations + 2))) clamped = true;
    v[k] = std::min(std::max(v[k], -vmax), vmax);
  }
  return clamped;
}

/// The float32 tolerance of a run's value: `ulps` (a few roundings per pass) of its start
/// scale and of the largest input that entered it, plus 1e-12.
double run_tolerance(double ulps, double scale, double largest) { return ulps * (scale + largest) + 1e-12; }

/// A dynamic body's worst ratio |engine - prediction| / tolerance over its world AABB's
/// min corner, position and velocity (infinity for NaN), and the quantity it is on.
struct BodyFigure {
  double ratio = 0.0;
  const char* quantity = nullptr;
  int k = 0;
  double got = 0, want = 0, tolerance = 0;
};

/// One thread's island (its vectors rebuilt per island), the run judged against, and the
/// thread's tally.
struct IslandWorker {
  Island island;
  Run run;
  std::vector<std::uint8_t> judged;
  IslandTally tally;
};

}  // namespace

struct AppliedStateJudge::Impl {
  const Model* model = nullptr;
  Tolerances tol;
  CheckTally bodies, group_momentum, group_centre;
  std::uint64_t dynamic_frames = 0, unjudged = 0, searched = 0, resolved = 0, exceeded = 0;
  std::uint64_t near_ties = 0, runs = 0;
  double worst = 0.0;
  bool any_response = false;
  std::function<bool()> stop;  // set_stop: polled per pass and per island
  /// Throws ValidationStopped when `stop` says so.
  void poll() const {
    if (stop && stop()) throw ValidationStopped();
  }

  // Per frame.
  const FrameRecord* rec = nullptr;
  std::vector<D3> x_int, v_int;
  std::vector<F3> xf_int, vf_int;
  /// The frame's islands, numbered in the order of their first dynamic body (ascending
  /// roots: components.hpp names each island by its lowest body): island j's root is
  /// firsts[j]; its dynamic bodies are by_root.items[dyn_start[j] .. dyn_start[j + 1]) (in
  /// body order; by_root groups the dynamic bodies per root), its contacts con's group j
  /// (indices into rec.confirmed, in order); `island_of`: per root, its island; `slot`:
  /// each dynamic body's index in its island's list.
  Components components;
  GroupScratch group_scratch;
  GroupedItems by_root, con;
  std::vector<std::uint32_t> firsts, dyn_start, slot;
  std::vector<std::int32_t> island_of;
  /// Per island: its group's figures (written by judge_island where `isolated` is 1).
  std::vector<GroupFigures> group_figures;
  std::vector<std::uint8_t> isolated;
  /// The islands whose `isolated` is 1, ascending.
  std::vector<std::uint32_t> isolated_islands;
  /// Per thread of the islands' loop (the memory of its island and run kept between frames).
  std::vector<IslandWorker> workers;


  /// Runs design.md section 6's passes over `is` with the first forced.size() near-ties taking the
  /// outcomes given, the rest the float32 proposal (where consistent).
  void run(const Island& is, const std::vector<std::uint8_t>& forced, Run& r) const;
  /// Compares the run's prediction of the island's dynamic bodies with the engine's.
  void compare(const Island& is, Run& r) const;
  /// Runs the island's passes into `out` (its vectors' memory reused) and, where the first
  /// run is off, explores the island's branches (search_branches); `out` ends as the run
  /// judged against, sets `judged` (per local dynamic body) and adds to `counts` (what a
  /// search adds to the judge's counters, summed over the threads after the islands are
  /// searched on the validators' threads). Reads only the frame's shared state: islands may
  /// be searched on several threads at once.
  void search(const Island& is, bool judge_response, std::vector<std::uint8_t>& judged, SearchCounts& counts,
              Run& out) const;
  /// The branches of an island whose first run `first` (compared) is off: the run judged against.
  Run search_branches(const Island& is, const Run& first, std::vector<std::uint8_t>& judged,
                      SearchCounts& counts) const;
  /// Builds island j of the frame in `is` (its locals: the dynamic bodies, then each static
  /// body its contacts touch, in the order first touched).
  void build_island(std::size_t j, Island& is) const;
  /// Searches island j on worker `w` and adds its bodies' verdicts to the worker's tally;
  /// where the island is an isolated group, writes its figures to `group` and 1 to
  /// `group_isolated` (left as they are otherwise).
  void judge_island(std::size_t j, bool judge_response, IslandWorker& w, GroupFigures& group,
                    std::uint8_t& group_isolated) const;
  /// The float32 tolerance's roundings per unit of scale after the scene's passes.
  double run_ulps() const {
    return tol.applied_state_ulps * kEps32 * (model->scene.response.iterations + 2);
  }
  /// Dynamic body i's figure against the prediction x, v with tolerances x_tol, v_tol.
  BodyFigure body_figure(std::uint32_t i, const D3& x, const D3& v, const D3& x_tol, const D3& v_tol) const;
  /// A body alone in its island, without contacts: its run (the integration, Eq. 23, its
  /// tolerances) judged; true with its verdict added to `t` where it passes, false (nothing
  /// added) where it does not.
  bool judge_free_body(std::uint32_t i, IslandTally& t) const;
  int threads = 0;  // set_threads: the islands' threads (0: the hardware's)
};

AppliedStateJudge::AppliedStateJudge(const Model& model, const Tolerances& tol) : impl_(std::make_unique<Impl>()) {
  impl_->model = &model;
  impl_->tol = tol;
}

AppliedStateJudge::~AppliedStateJudge() = default;

void AppliedStateJudge::set_stop(std::function<bool()> stop) { impl_->stop = std::move(stop); }

void AppliedStateJudge::set_threads(int threads) { impl_->threads = threads; }

void AppliedStateJudge::Impl::run(const Island& is, const std::vector<std::uint8_t>& forced, Run& r) const {
  const Model& m = *model;
  const ContactParams& p = m.scene.response;
  const std::size_t nl = is.local.size();
  const double dt = m.scene.dt;
  const D3 g = d3(m.scene.gravity);
  r.trace.clear();
  r.open = false;
  r.x.resize(nl);
  r.v.resize(nl);
  r.x_tol.resize(nl);
  r.v_tol.resize(nl);
  r.clamped.assign(nl, 0);
  r.count0.assign(nl, 0);
  // The island's work space, kept per thread: most islands are one body, and 13 vectors
  // allocated and freed for each were most of a sparse frame's malloc time. Each vector is
  // set to what a fresh one held (nl value-initialised elements).
  thread_local RunScratch scratch;
  std::vector<F3>& xf = scratch.xf;
  std::vector<F3>& vf = scratch.vf;
  std::vector<D3>& scale_x = scratch.scale_x;
  std::vector<D3>& scale_v = scratch.scale_v;
  std::vector<double>& coord_max = scratch.coord_max;
  std::vector<double>& vel_max = scratch.vel_max;
  std::vector<double>& run_v = scratch.run_v;
  std::vector<float>& w = scratch.w;
  xf.assign(nl, F3{});
  vf.assign(nl, F3{});
  scale_x.assign(nl, D3{});
  scale_v.assign(nl, D3{});
  coord_max.assign(nl, 0.0);
  vel_max.assign(nl, 0.0);
  run_v.assign(nl, 0.0);
  w.assign(nl, 0.0f);
  for (std::size_t l = 0; l < nl; ++l) {
    const std::uint32_t i = is.local[l];
    w[l] = m.initial.w[i];
    r.x[l] = x_int[i];
    r.v[l] = v_int[i];
    xf[l] = xf_int[i];
    vf[l] = vf_int[i];
    start_scales(r.x[l], r.v[l], w[l] > 0.0f, dt, g, scale_x[l], scale_v[l]);
    run_v[l] = inf_norm(scale_v[l]);
  }

  const std::size_t nc = is.contacts.size();
  std::vector<D3>& dx_sum = scratch.dx_sum;
  std::vector<D3>& dv_sum = scratch.dv_sum;
  std::vector<F3>& dxf_sum = scratch.dxf_sum;
  std::vector<F3>& dvf_sum = scratch.dvf_sum;
  std::vector<std::uint32_t>& count = scratch.count;
  dx_sum.assign(nl, D3{});
  dv_sum.assign(nl, D3{});
  dxf_sum.assign(nl, F3{});
  dvf_sum.assign(nl, F3{});
  count.assign(nl, 0);
  std::size_t next = 0;  // index of the next near-tie in the trace
  // A near-tie: `allowed` outcomes are consistent with the double value; one outcome
  // allowed is no branch. The outcome is the forced one, else the float32 proposal when
  // consistent, else the double one.
  auto decide = [&](std::uint8_t allowed, std::uint8_t by_double, std::uint8_t by_float, int pass,
                    std::size_t c) -> std::uint8_t {
    if ((allowed & (allowed - 1)) == 0) return by_double;
    std::uint8_t out = (allowed >> by_float & 1) ? by_float : by_double;
    if (next < forced.size()) out = forced[next];
    ++next;
    r.trace.push_back(Choice{out, allowed, static_cast<std::uint16_t>(pass), static_cast<std::uint32_t>(c)});
    return out;
  };

  // Without contacts (a body in free flight) a pass changes nothing: none is run.
  const int passes = nc > 0 ? p.iterations : 0;
  for (int pass = 0; pass < passes; ++pass) {
    poll();  // a pass over a pile's one island of 10^5 contacts: milliseconds
    // Rounding margin of a decision in this pass: a few roundings of the magnitudes that
    // entered its value, per pass so far.
    const double rel = 16.0 * kEps32 * (pass + 2);
    std::fill(dx_sum.begin(), dx_sum.end(), D3{0, 0, 0});
    std::fill(dv_sum.begin(), dv_sum.end(), D3{0, 0, 0});
    std::fill(dxf_sum.begin(), dxf_sum.end(), F3{0, 0, 0});
    std::fill(dvf_sum.begin(), dvf_sum.end(), F3{0, 0, 0});
    std::fill(count.begin(), count.end(), 0u);
    for (std::size_t c = 0; c < nc; ++c) {
      ++r.work;
      const std::uint32_t a = is.ends[c][0], b = is.ends[c][1];
      const double wa = w[a], wb = w[b];
      const Aabb& la = m.local_box(is.local[a]);
      const Aabb& lb = m.local_box(is.local[b]);
      D3 amin, amax, bmin, bmax, pen;
      F3 famin, famax, fbmin, fbmax, fpen;
      double coord_scale = 0.0;
      for (int k = 0; k < 3; ++k) {
        amin[k] = la.min[k] + r.x[a][k];
        amax[k] = la.max[k] + r.x[a][k];
        bmin[k] = lb.min[k] + r.x[b][k];
        bmax[k] = lb.max[k] + r.x[b][k];
        famin[k] = la.min[k] + xf[a][k];
        famax[k] = la.max[k] + xf[a][k];
        fbmin[k] = lb.min[k] + xf[b][k];
        fbmax[k] = lb.max[k] + xf[b][k];
        coord_scale = std::max({coord_scale, std::fabs(amin[k]), std::fabs(amax[k]), std::fabs(bmin[k]),
                                std::fabs(bmax[k])});
      }
      const double mx = rel * coord_scale + 1e-300;
      // Eq. 9: `separating` = the distance that separates the boxes along k; `paper` = the
      // width of the overlap interval. Any p_k <= 0: discarded.
      bool hit_d = true, hit_f = true, can_hit = true, can_miss = false;
      for (int k = 0; k < 3; ++k) {
        if (p.overlap == OverlapMode::Paper) {
          pen[k] = std::min(amax[k], bmax[k]) - std::max(amin[k], bmin[k]);
          fpen[k] = std::min(famax[k], fbmax[k]) - std::max(famin[k], fbmin[k]);
        } else {
          pen[k] = std::min(amax[k] - bmin[k], bmax[k] - amin[k]);
          fpen[k] = std::min(famax[k] - fbmin[k], fbmax[k] - famin[k]);
        }
        hit_d = hit_d && pen[k] > 0.0;
        hit_f = hit_f && fpen[k] > 0.0f;
        can_hit = can_hit && pen[k] > -mx;
        can_miss = can_miss || pen[k] <= mx;
      }
      if (!decide(static_cast<std::uint8_t>((can_miss ? 1 : 0) | (can_hit ? 2 : 0)), hit_d ? 1 : 0, hit_f ? 1 : 0,
                  pass, c))
        continue;
      // Eq. 10 and the fixed axis: the normal along the least overlap, from B to A by the
      // AABB centres; centres closer than epsilon: +y.
      D3 d;
      F3 fd;
      for (int k = 0; k < 3; ++k) {
        d[k] = 0.5 * (amin[k] + amax[k]) - 0.5 * (bmin[k] + bmax[k]);
        fd[k] = 0.5f * (famin[k] + famax[k]) - 0.5f * (fbmin[k] + fbmax[k]);
      }
      const double dist = len3(d);
      const float fdist = std::sqrt(fd[0] * fd[0] + fd[1] * fd[1] + fd[2] * fd[2]);
      const double eps = p.epsilon;
      const std::uint8_t fixed =
          decide(static_cast<std::uint8_t>((dist >= eps - mx ? 1 : 0) | (dist < eps + mx ? 2 : 0)),
                 dist < eps ? 1 : 0, fdist < p.epsilon ? 1 : 0, pass, c);
      int axis = 1;
      double sign = 1.0;
      if (!fixed) {
        int ad = 0, af = 0;
        if (pen[1] < pen[ad]) ad = 1;
        if (pen[2] < pen[ad]) ad = 2;
        if (fpen[1] < fpen[af]) af = 1;
        if (fpen[2] < fpen[af]) af = 2;
        std::uint8_t axes = 0;
        for (int k = 0; k < 3; ++k)
          if (pen[k] <= pen[ad] + mx) axes = static_cast<std::uint8_t>(axes | (1 << k));
        axis = decide(axes, static_cast<std::uint8_t>(ad), static_cast<std::uint8_t>(af), pass, c);
        // The sign by the centres along the axis; an exact tie falls back to +.
        const std::uint8_t positive =
            decide(static_cast<std::uint8_t>((d[axis] < mx ? 1 : 0) | (d[axis] >= -mx ? 2 : 0)),
                   d[axis] < 0.0 ? 0 : 1, fd[axis] < 0.0f ? 0 : 1, pass, c);
        sign = positive ? 1.0 : -1.0;
      }
      const float fsign = static_cast<float>(sign);
      // Eq. 11, 13 with Algorithm 3's weights: A gets w_A/(w_A+w_B) of c, B -w_B/(...).
      const double wsum = wa + wb;
      const float fwsum = w[a] + w[b];
      const double corr = static_cast<double>(p.alpha) * p.beta * std::max(pen[axis] - p.slop, 0.0);
      const float fcorr = p.alpha * p.beta * std::max(fpen[axis] - p.slop, 0.0f);
      // Eq. 16-22: the impulses from the relative velocity.
      D3 vrel, nrm{0, 0, 0};
      F3 fvrel, fn{0, 0, 0};
      nrm[axis] = sign;
      fn[axis] = fsign;
      for (int k = 0; k < 3; ++k) {
        vrel[k] = r.v[a][k] - r.v[b][k];
        fvrel[k] = vf[a][k] - vf[b][k];
      }
      const double vn = vrel[0] * nrm[0] + vrel[1] * nrm[1] + vrel[2] * nrm[2];
      const float fvn = fvrel[0] * fn[0] + fvrel[1] * fn[1] + fvrel[2] * fn[2];
      const double mv = rel * (run_v[a] + run_v[b]) + 1e-300;
      double jn = 0.0, jt = 0.0;
      float fjn = 0.0f, fjt = 0.0f;
      D3 t{0, 0, 0};
      F3 ft{0, 0, 0};
      if (wsum > 0.0) {
        const std::uint8_t approach = decide(static_cast<std::uint8_t>((vn > -mv ? 1 : 0) | (vn < mv ? 2 : 0)),
                                             vn < 0.0 ? 1 : 0, fvn < 0.0f ? 1 : 0, pass, c);
        double e_eff = 0.0;
        float fe = 0.0f;
        if (approach) {
          const double vth = p.restitution_threshold;
          const std::uint8_t fast =
              decide(static_cast<std::uint8_t>((-vn < vth + mv ? 1 : 0) | (-vn >= vth - mv ? 2 : 0)),
                     -vn < vth ? 0 : 1, -fvn < p.restitution_threshold ? 0 : 1, pass, c);
          e_eff = fast ? p.restitution : 0.0;
          fe = fast ? p.restitution : 0.0f;
          jn = std::max(-(1.0 + e_eff) * vn / wsum, static_cast<double>(p.impulse_floor));
          fjn = std::max(-(1.0f + fe) * fvn / fwsum, p.impulse_floor);
        }
        D3 vt;
        F3 fvt;
        for (int k = 0; k < 3; ++k) {
          vt[k] = vrel[k] - vn * nrm[k];
          fvt[k] = fvrel[k] - fvn * fn[k];
        }
        const double vt_len = len3(vt);
        const float fvt_len = std::sqrt(fvt[0] * fvt[0] + fvt[1] * fvt[1] + fvt[2] * fvt[2]);
        if (vt_len > 0.0 || fvt_len > 0.0f) {
          for (int k = 0; k < 3; ++k) {
            t[k] = vt_len > 0.0 ? vt[k] / vt_len : 0.0;
            ft[k] = fvt_len > 0.0f ? (1.0f / fvt_len) * fvt[k] : 0.0f;
          }
          // Eq. 21: stick when |J_t*| <= mu_s J_n, J_t* = -|v_t| / (w_A + w_B). Both sides
          // carry the velocity margin (J_n through v_n, with restitution).
          const double jt_star = -vt_len / wsum;
          const float fjt_star = -fvt_len / fwsum;
          const double mj = mv * (1.0 + p.mu_static * (1.0 + e_eff)) / wsum;
          const double gap = std::fabs(jt_star) - p.mu_static * jn;
          const std::uint8_t stick =
              decide(static_cast<std::uint8_t>((gap > -mj ? 1 : 0) | (gap <= mj ? 2 : 0)), gap <= 0.0 ? 1 : 0,
                     std::fabs(fjt_star) <= p.mu_static * fjn ? 1 : 0, pass, c);
          // A slipping |v_t| within rounding of 0 has a direction float32 cannot resolve.
          if (!stick && jn > 0.0 && vt_len <= mv) r.open = true;
          jt = stick ? jt_star : -p.mu_kinetic * jn;
          fjt = stick ? fjt_star : -p.mu_kinetic * fjn;
        }
      }
      D3 dva, dvb, dxa, dxb;
      for (int k = 0; k < 3; ++k) {
        const double cc = corr * nrm[k];
        const double imp = jn * nrm[k] + jt * t[k];
        dxa[k] = wsum > 0.0 ? wa / wsum * cc : 0.0;
        dxb[k] = wsum > 0.0 ? -(wb / wsum * cc) : 0.0;
        dva[k] = wa * imp;
        dvb[k] = -(wb * imp);
        dx_sum[a][k] += dxa[k];
        dx_sum[b][k] += dxb[k];
        dv_sum[a][k] += dva[k];
        dv_sum[b][k] += dvb[k];
        // float32: the same terms, in docs/design.md's order.
        const float fcc = fcorr * fn[k];
        const float fimp = fjn * fn[k] + fjt * ft[k];
        const float sa = fwsum > 0.0f ? w[a] / fwsum : 0.0f, sb = fwsum > 0.0f ? w[b] / fwsum : 0.0f;
        dxf_sum[a][k] += sa * fcc;
        dxf_sum[b][k] += -(sb * fcc);
        dvf_sum[a][k] += w[a] * fimp;
        dvf_sum[b][k] += -(w[b] * fimp);
        scale_x[a][k] += std::fabs(cc);
        scale_x[b][k] += std::fabs(cc);
        scale_v[a][k] += std::fabs(dva[k]);
        scale_v[b][k] += std::fabs(dvb[k]);
      }
      // Rounding of the inputs a contact's terms came from: the AABB coordinates (depth,
      // hence the correction) and both velocities (v_n, v_t, hence the impulses).
      const double vscale = inf_norm(r.v[a]) + inf_norm(r.v[b]);
      for (const std::uint32_t l : {a, b}) {
        coord_max[l] = std::max(coord_max[l], coord_scale);
        vel_max[l] = std::max(vel_max[l], vscale);
      }
      ++count[a];
      ++count[b];
    }
    // Parallel semantics: corrections averaged per body, velocity changes summed.
    for (std::size_t l = 0; l < nl; ++l) {
      if (pass == 0) r.count0[l] = count[l];
      if (!(w[l] > 0.0f) || count[l] == 0) continue;
      const float inv = 1.0f / static_cast<float>(count[l]);
      for (int k = 0; k < 3; ++k) {
        r.x[l][k] += dx_sum[l][k] / count[l];
        r.v[l][k] += dv_sum[l][k];
        xf[l][k] = xf[l][k] + inv * dxf_sum[l][k];
        vf[l][k] = vf[l][k] + dvf_sum[l][k];
      }
      run_v[l] = inf_norm(scale_v[l]);
    }
  }
  // Eq. 23 on the dynamic bodies.
  for (std::size_t l = 0; l < nl; ++l)
    if (w[l] > 0.0f && clamp_velocity(r.v[l], p.max_velocity, p.iterations)) r.clamped[l] = 1;
  const double ulps = run_ulps();
  for (std::size_t l = 0; l < nl; ++l)
    for (int k = 0; k < 3; ++k) {
      r.x_tol[l][k] = run_tolerance(ulps, scale_x[l][k], coord_max[l]);
      r.v_tol[l][k] = run_tolerance(ulps, scale_v[l][k], vel_max[l]);
    }
}

BodyFigure AppliedStateJudge::Impl::body_figure(std::uint32_t i, const D3& x, const D3& v, const D3& x_tol,
                                                const D3& v_tol) const {
  const FrameRecord& fr = *rec;
  BodyFigure b;
  auto judge = [&](const char* quantity, int k, double got, double want, double tolerance) {
    const double ratio = std::fabs(got - want) / tolerance;
    if ((ratio <= b.ratio || std::isnan(b.ratio)) && b.quantity) return;
    b = {std::isnan(ratio) ? std::numeric_limits<double>::infinity() : ratio, quantity, k, got, want, tolerance};
  };
  const Aabb& local = model->local_box(i);
  for (int k = 0; k < 3; ++k) {
    // The world AABB the engine used is its integrated position's box (design.md section 4.2); the
    // float32 sum local + x rounds at the scale of both.
    const double box_scale = std::max(std::fabs(local.min[k]), std::fabs(local.max[k]));
    judge("aabb.min", k, fr.aabbs[i].min[k], static_cast<double>(local.min[k]) + x_int[i][k],
          x_tol[k] + tol.applied_state_ulps * box_scale * kEps32);
    judge("x", k, fr.x_post[i][k], x[k], x_tol[k]);
    judge("v", k, fr.v_post[i][k], v[k], v_tol[k]);
  }
  return b;
}

bool AppliedStateJudge::Impl::judge_free_body(std::uint32_t i, IslandTally& t) const {
  const Scene& sc = model->scene;
  D3 x = x_int[i], v = v_int[i], scale_x, scale_v, x_tol, v_tol;
  start_scales(x, v, true, sc.dt, d3(sc.gravity), scale_x, scale_v);
  clamp_velocity(v, sc.response.max_velocity, sc.response.iterations);
  const double ulps = run_ulps();
  for (int k = 0; k < 3; ++k) {
    x_tol[k] = run_tolerance(ulps, scale_x[k], 0.0);
    v_tol[k] = run_tolerance(ulps, scale_v[k], 0.0);
  }
  const double ratio = body_figure(i, x, v, x_tol, v_tol).ratio;
  if (!(ratio <= 1.0)) return false;
  ++t.counts.runs;
  ++t.dynamic_frames;
  ++t.checks;
  t.worst = std::max(t.worst, ratio);
  return true;
}

void AppliedStateJudge::Impl::compare(const Island& is, Run& r) const {
  r.worst = 0.0;
  r.off = 0;
  for (std::uint32_t l = 0; l < is.dynamic; ++l) {
    const std::uint32_t i = is.local[l];
    double body = 0.0;
    for (int k = 0; k < 3; ++k) {
      body = std::max(body, std::fabs(rec->x_post[i][k] - r.x[l][k]) / r.x_tol[l][k]);
      body = std::max(body, std::fabs(rec->v_post[i][k] - r.v[l][k]) / r.v_tol[l][k]);
    }
    if (!(body <= 1.0)) ++r.off;  // NaN counts as off
    r.worst = std::max(r.worst, std::isnan(body) ? std::numeric_limits<double>::infinity() : body);
  }
}

void AppliedStateJudge::Impl::search(const Island& is, bool judge_response, std::vector<std::uint8_t>& judged,
                                     SearchCounts& counts, Run& out) const {
  out.work = 0;
  run(is, {}, out);
  judged.assign(is.dynamic, 1);
  if (!judge_response) return;
  compare(is, out);
  counts.near_ties += out.trace.size();
  ++counts.runs;
  if (out.off == 0) return;
  out = search_branches(is, out, judged, counts);
}

Run AppliedStateJudge::Impl::search_branches(const Island& is, const Run& first, std::vector<std::uint8_t>& judged,
                                             SearchCounts& counts) const {
  // Breadth-first over the near-ties by the number of outcomes changed from the first
  // run's: each queued branch forces a prefix of outcomes, the rest follow the proposal;
  // a branch only changes outcomes after its forced prefix, so no branch is run twice.
  ++counts.searched;
  struct Branch {
    std::vector<std::uint8_t> forced;
  };
  std::deque<Branch> queue;
  std::uint64_t queue_bytes = 0, work = 0;
  bool truncated = false;
  auto expand = [&](const Run& r, std::size_t from) {
    for (std::size_t i = from; i < r.trace.size(); ++i) {
      for (std::uint8_t o = 0; o < 8; ++o) {
        if (o == r.trace[i].outcome || !(r.trace[i].allowed >> o & 1)) continue;
        if (queue_bytes + i + 1 + sizeof(Branch) > kMaxQueueBytes || queue.size() >= static_cast<std::size_t>(kMaxRuns)) {
          truncated = true;
          return;
        }
        Branch b;
        b.forced.reserve(i + 1);
        for (std::size_t j = 0; j < i; ++j) b.forced.push_back(r.trace[j].outcome);
        b.forced.push_back(o);
        queue_bytes += b.forced.size() + sizeof(Branch);
        queue.push_back(std::move(b));
      }
    }
  };
  bool open = first.open;
  expand(first, 0);
  Run best = first;
  int done = 1;
  Run r;
  while (!queue.empty()) {
    if (done >= kMaxRuns || work >= kMaxWork) {
      truncated = true;
      break;
    }
    Branch b = std::move(queue.front());
    queue.pop_front();
    queue_bytes -= b.forced.size() + sizeof(Branch);
    r.work = 0;
    run(is, b.forced, r);
    work += r.work;
    ++done;
    ++counts.runs;
    compare(is, r);
    open = open || r.open;
    if (r.off == 0) {
      ++counts.resolved;
      return r;
    }
    if (r.off < best.off || (r.off == best.off && r.worst < best.worst)) best = r;
    expand(r, b.forced.size());
  }
  if (!truncated && !open) return best;  // every consistent choice explored: a failure
  // Bound exceeded: judge only the bodies no near-tie of the first run can reach. A
  // near-tie in pass p changes its two bodies at the end of pass p, their neighbours at
  // the end of pass p + 1, ...: N - 1 - p contact hops.
  ++counts.exceeded;
  const int passes = model->scene.response.iterations;
  std::vector<int> reach(is.local.size(), -1);
  std::vector<std::vector<std::uint32_t>> adj(is.local.size());
  for (const auto& e : is.ends) {
    adj[e[0]].push_back(e[1]);
    adj[e[1]].push_back(e[0]);
  }
  std::vector<std::vector<std::uint32_t>> bucket(static_cast<std::size_t>(passes));
  for (const Choice& c : first.trace)
    for (const std::uint32_t l : is.ends[c.contact]) {
      const int h = passes - 1 - c.pass;
      if (h > reach[l]) {
        reach[l] = h;
        bucket[static_cast<std::size_t>(h)].push_back(l);
      }
    }
  if (first.open)  // no trace entry for an undefined direction: the whole island
    for (std::uint32_t l = 0; l < is.dynamic; ++l) reach[l] = 0;
  for (int h = passes - 1; h > 0; --h)
    for (std::size_t q = 0; q < bucket[static_cast<std::size_t>(h)].size(); ++q) {
      const std::uint32_t l = bucket[static_cast<std::size_t>(h)][q];
      if (reach[l] != h || l >= is.dynamic) continue;  // static bodies pass nothing on
      for (const std::uint32_t nb : adj[l])
        if (reach[nb] < h - 1) {
          reach[nb] = h - 1;
          bucket[static_cast<std::size_t>(h - 1)].push_back(nb);
        }
    }
  for (std::uint32_t l = 0; l < is.dynamic; ++l) judged[l] = reach[l] < 0 ? 1 : 0;
  return first;
}

void AppliedStateJudge::Impl::build_island(std::size_t j, Island& is) const {
  const std::vector<float>& w = model->initial.w;
  is.local.assign(by_root.items.begin() + dyn_start[j], by_root.items.begin() + dyn_start[j + 1]);
  is.dynamic = static_cast<std::uint32_t>(is.local.size());
  is.contacts.clear();
  is.ends.clear();
  for (const std::uint32_t c : con.group(j)) {
    const Pair q = rec->confirmed[c];
    std::array<std::uint32_t, 2> e{};
    for (int side = 0; side < 2; ++side) {
      const std::uint32_t body = side == 0 ? q.a : q.b;
      if (w[body] > 0.0f) {
        e[static_cast<std::size_t>(side)] = slot[body];
      } else {  // a static body: local to this island (a floor may serve many)
        auto it = std::find(is.local.begin() + is.dynamic, is.local.end(), body);
        e[static_cast<std::size_t>(side)] = static_cast<std::uint32_t>(it - is.local.begin());
        if (it == is.local.end()) is.local.push_back(body);
      }
    }
    is.contacts.push_back(c);
    is.ends.push_back(e);
  }
}

void AppliedStateJudge::Impl::judge_island(std::size_t j, bool judge_response, IslandWorker& wk, GroupFigures& g,
                                           std::uint8_t& group_isolated) const {
  const Model& m = *model;
  const Scene& sc = m.scene;
  const FrameRecord& fr = *rec;
  const std::vector<float>& w = m.initial.w;
  IslandTally& t = wk.tally;
  // One dynamic body without contacts: judged from its integration alone when it passes
  // (the general way below names a failure and counts its search).
  if (judge_response && dyn_start[j + 1] - dyn_start[j] == 1 && con.size(j) == 0 &&
      judge_free_body(by_root.items[dyn_start[j]], t))
    return;
  Island& is = wk.island;
  build_island(j, is);
  search(is, judge_response, wk.judged, t.counts, wk.run);
  const Run& r = wk.run;
  if (judge_response)
    for (std::uint32_t l = 0; l < is.dynamic; ++l) {
      const std::uint32_t i = is.local[l];
      ++t.dynamic_frames;
      if (!wk.judged[l]) {
        ++t.unjudged;
        continue;
      }
      const BodyFigure b = body_figure(i, r.x[l], r.v[l], r.x_tol[l], r.v_tol[l]);
      const double body_worst = b.ratio;
      ++t.checks;
      t.worst = std::max(t.worst, body_worst);
      if (body_worst <= 1.0) continue;
      ++t.failures;
      if (j < t.first_island) {
        t.first_island = j;
        t.first = fmt::format("frame {}: body {} {}.{} = {:.9g}, design.md section 6 gives {:.9g} "
                              "(tolerance {:.3g}; {} contacts)",
                              fr.frame, i, b.quantity, "xyz"[b.k], b.got, b.want, b.tolerance, r.count0[l]);
      }
    }

  // The island's group: isolated when it holds two dynamic bodies or more, no static body
  // and no clamped one (clamped by the re-derivation's run, or at v_max in the engine's
  // state: a body the re-derivation did not judge may have been clamped in a branch it did
  // not run). Its sums run over its bodies in body order.
  if (is.dynamic < 2 || is.local.size() > is.dynamic) return;
  const double dt = sc.dt;
  const double vmax_near = sc.response.max_velocity * (1.0 - 16.0 * kEps32 * (sc.response.iterations + 2));
  auto x_at = [&](std::uint32_t i, int k) {
    return judge_response ? x_int[i][k]
                          : static_cast<double>(fr.aabbs[i].min[k]) - static_cast<double>(m.local_box(i).min[k]);
  };
  D3 p0{}, p1{}, c0{}, c1{};
  double exchange = 0, cexchange = 0, ctol = 0, mtol = 0;
  bool centre = true;
  for (std::uint32_t l = 0; l < is.dynamic; ++l) {
    const std::uint32_t i = is.local[l];
    bool at_vmax = false;
    for (int k = 0; k < 3; ++k) at_vmax = at_vmax || std::fabs(fr.v_post[i][k]) >= vmax_near;
    if (r.clamped[l] || at_vmax) return;
    if (r.count0[l] != 1) centre = false;  // the centre is not kept by design
    const double mi = 1.0 / w[i];
    for (int k = 0; k < 3; ++k) {
      const double vi = static_cast<double>(fr.v_pre[i][k]) + dt * sc.gravity[k];
      p0[k] += mi * vi;
      p1[k] += mi * fr.v_post[i][k];
      exchange += mi * std::fabs(fr.v_post[i][k] - vi);
      mtol += mi * r.v_tol[l][k];
      c0[k] += mi * x_at(i, k);
      c1[k] += mi * fr.x_post[i][k];
      cexchange += mi * std::fabs(fr.x_post[i][k] - x_at(i, k));
      ctol += mi * r.x_tol[l][k];
    }
  }
  group_isolated = 1;
  g.bodies = is.dynamic;
  g.first = is.local[0];
  g.dp = len3(p1 - p0);
  g.bound = tol.applied_conservation_rel * exchange + mtol + 1e-9;
  g.exchange = exchange;
  g.centre = is.dynamic == 2 && centre;
  g.dc = len3(c1 - c0);
  g.cbound = tol.applied_conservation_rel * cexchange + ctol + 1e-12;
  g.cexchange = cexchange;
}

void AppliedStateJudge::observe(const FrameRecord& rec, bool judge_response) {
  Impl& s = *impl_;
  if (rec.x_pre.empty()) return;
  const Model& model = *s.model;
  const Scene& sc = model.scene;
  const std::vector<float>& w = model.initial.w;
  const std::size_t n = rec.x_pre.size();
  const std::int64_t frame = rec.frame;
  s.rec = &rec;
  s.any_response = s.any_response || judge_response;

  // design.md section 4.1, semi-implicit Euler: v <- v + dt g; x <- x + dt v (static bodies stay); in
  // double for the prediction and in float32 for the proposal; on the threads.
  const double dt = sc.dt;
  s.x_int.resize(n);
  s.v_int.resize(n);
  s.xf_int.resize(n);
  s.vf_int.resize(n);
  const unsigned integrate_threads = loop_threads(s.threads, n, kParallelIntegrateFrom);
  parallel_ranges(n, integrate_threads, s.stop, [&](std::size_t first, std::size_t last) {
    for (std::size_t i = first; i < last; ++i) {
      D3 x = d3(rec.x_pre[i]), v = d3(rec.v_pre[i]);
      F3 xf = f3(rec.x_pre[i]), vf = f3(rec.v_pre[i]);
      if (w[i] > 0.0f)
        for (int k = 0; k < 3; ++k) {
          v[k] = v[k] + dt * sc.gravity[k];
          x[k] = x[k] + dt * v[k];
          vf[k] = vf[k] + sc.dt * sc.gravity[k];
          xf[k] = xf[k] + sc.dt * vf[k];
        }
      s.x_int[i] = x;
      s.v_int[i] = v;
      s.xf_int[i] = xf;
      s.vf_int[i] = vf;
    }
  });

  // Islands: dynamic bodies joined by confirmed contacts between two dynamic bodies; a
  // contact with a static body belongs to its dynamic body's island. Numbered in the order
  // of their first dynamic body; bodies and contacts listed per island in their order. On
  // the validators' threads (components.hpp: the unions by index, so each root is its
  // island's lowest body whatever the threads' order; the lists by group_items).
  const unsigned body_threads = loop_threads(s.threads, n, kParallelIntegrateFrom);
  auto dynamic = [&](std::size_t i) { return w[i] > 0.0f; };
  s.components.reset(n, body_threads, s.stop);
  s.components.join_all(
      rec.confirmed.size(), loop_threads(s.threads, rec.confirmed.size(), kParallelIntegrateFrom), s.stop,
      [&](std::size_t c) { return w[rec.confirmed[c].a] > 0.0f && w[rec.confirmed[c].b] > 0.0f; },
      [&](std::size_t c) { return rec.confirmed[c]; });
  s.components.settle(body_threads, s.stop);
  const std::vector<std::uint32_t>& root = s.components.roots();
  group_items(
      n, n, body_threads, s.stop, [&](std::size_t i) { return dynamic(i) ? std::size_t(root[i]) : n; },
      s.group_scratch, s.by_root);
  parallel_select(
      n, s.firsts, body_threads, s.stop, [&](std::size_t r) { return s.by_root.size(r) > 0; },
      [](std::size_t r) { return static_cast<std::uint32_t>(r); });
  const std::size_t islands = s.firsts.size();
  s.island_of.resize(n);
  s.dyn_start.resize(islands + 1);
  s.dyn_start[islands] = static_cast<std::uint32_t>(s.by_root.items.size());
  s.slot.resize(n);
  parallel_ranges(islands, loop_threads(s.threads, islands, kParallelIntegrateFrom), s.stop,
                  [&](std::size_t first_island, std::size_t last_island) {
    for (std::size_t j = first_island; j < last_island; ++j) {
      const std::uint32_t r = s.firsts[j];
      s.island_of[r] = static_cast<std::int32_t>(j);
      const std::size_t first = s.by_root.first[r];
      s.dyn_start[j] = static_cast<std::uint32_t>(first);
      for (std::size_t k = first; k < s.by_root.first[r + 1]; ++k)
        s.slot[s.by_root.items[k]] = static_cast<std::uint32_t>(k - first);
    }
  });
  const std::vector<std::uint32_t>& dyn = s.by_root.items;  // island j's: dyn[dyn_start[j] .. dyn_start[j + 1])
  auto island_of_contact = [&](const Pair& q) {
    return static_cast<std::size_t>(s.island_of[root[w[q.a] > 0.0f ? q.a : q.b]]);
  };
  group_items(
      rec.confirmed.size(), islands, loop_threads(s.threads, rec.confirmed.size(), kParallelIntegrateFrom), s.stop,
      [&](std::size_t c) {
        const Pair q = rec.confirmed[c];
        return w[q.a] > 0.0f || w[q.b] > 0.0f ? island_of_contact(q) : islands;  // static-static: changes nothing
      },
      s.group_scratch, s.con);

  // Per island, on the validators' threads: the run judged against, each dynamic body
  // against it, and its group's figures; the threads' tallies are then summed (a verdict
  // never depends on the thread count).
  const std::size_t island_work = dyn.size() + s.con.items.size();  // the search's size
  const unsigned island_threads = island_work >= kParallelIslandWorkFrom ? loop_threads(s.threads, islands, 2) : 1u;
  if (s.workers.size() < island_threads) s.workers.resize(island_threads);
  for (IslandWorker& wk : s.workers) wk.tally = IslandTally{};
  s.group_figures.resize(islands);
  s.isolated.resize(islands);
  parallel_items_on(islands, island_threads, s.stop, [&](std::size_t j, unsigned t) {
    s.isolated[j] = 0;
    s.judge_island(j, judge_response, s.workers[t], s.group_figures[j], s.isolated[j]);
  });
  std::size_t first_island = std::numeric_limits<std::size_t>::max();
  const std::string* first = nullptr;
  std::uint64_t failures = 0;
  for (const IslandWorker& wk : s.workers) {
    const IslandTally& t = wk.tally;
    s.near_ties += t.counts.near_ties;
    s.runs += t.counts.runs;
    s.searched += t.counts.searched;
    s.resolved += t.counts.resolved;
    s.exceeded += t.counts.exceeded;
    s.dynamic_frames += t.dynamic_frames;
    s.unjudged += t.unjudged;
    s.bodies.checks += t.checks;
    failures += t.failures;
    s.bodies.worst = std::max(s.bodies.worst, t.worst);
    s.worst = std::max(s.worst, t.worst);
    if (t.failures && t.first_island < first_island) {
      first_island = t.first_island;
      first = &t.first;
    }
  }
  if (first && s.bodies.failures == 0) s.bodies.first = *first;
  s.bodies.failures += failures;

  // Isolated dynamic groups, in island order. Momentum is exchanged in equal and opposite
  // impulses, so it is kept; the mass-weighted centre is kept where every body has one
  // contact (an isolated pair): elsewhere the per-body averaging moves it by design.
  // Listed on the threads (parallel_select: in island order), then judged in that order.
  parallel_select(
      islands, s.isolated_islands, loop_threads(s.threads, islands, kParallelSelectFrom), s.stop,
      [&](std::size_t j) { return s.isolated[j] != 0; }, [](std::size_t j) { return static_cast<std::uint32_t>(j); });
  for (const std::uint32_t j : s.isolated_islands) {
    const GroupFigures& gr = s.group_figures[j];
    s.group_momentum.check(gr.dp <= gr.bound, gr.dp / gr.bound, [&] {
      return fmt::format("frame {}: isolated group of {} bodies (body {} ...) changes momentum by "
                         "{:.3g} kg m/s (exchanged {:.3g}, bound {:.3g})",
                         frame, gr.bodies, gr.first, gr.dp, gr.exchange, gr.bound);
    });
    if (gr.centre)
      s.group_centre.check(gr.dc <= gr.cbound, gr.dc / gr.cbound, [&] {
        return fmt::format("frame {}: isolated pair (body {} ...) moves its mass-weighted centre by "
                           "{:.3g} kg m (corrections {:.3g}, bound {:.3g})",
                           frame, gr.first, gr.dc, gr.cexchange, gr.cbound);
      });
  }
  s.rec = nullptr;
}

ValidationResult AppliedStateJudge::result() const {
  const Impl& s = *impl_;
  ValidationResult r;
  r.tier = row_info(RowId::AppliedState).tier;
  r.name = row_info(RowId::AppliedState).name;
  r.figure = "bodies off the design.md section 6 re-derivation";
  r.measured = static_cast<double>(s.bodies.failures);
  r.bound = 0;
  r.pass = s.bodies.failures == 0;
  r.applicable = s.bodies.checks > 0;
  const double share =
      s.dynamic_frames ? static_cast<double>(s.bodies.checks) / static_cast<double>(s.dynamic_frames) : 0.0;
  const std::string coverage = fmt::format(
      "{} of {} dynamic body-frames judged ({:.1f}%); {} not judged (branch bound exceeded on {} island-frames); "
      "near-ties {} in {} runs, {} island-frames settled by a branch other than the float32 proposal",
      s.bodies.checks, s.dynamic_frames, 100.0 * share, s.unjudged, s.exceeded, s.near_ties, s.runs, s.resolved);
  r.detail = s.bodies.failures ? s.bodies.first + "; " + coverage
                               : fmt::format("worst {:.3g} of the float32 tolerance; {}", s.worst, coverage);
  r.tolerances = "applied_state_ulps";
  return r;
}

AppliedStateJudge::Groups AppliedStateJudge::groups() const {
  const Impl& s = *impl_;
  Groups out;
  out.groups = s.group_momentum.checks;
  out.pairs = s.group_centre.checks;
  out.failures = s.group_momentum.failures + s.group_centre.failures;
  out.worst = std::max(s.group_momentum.worst, s.group_centre.worst);
  out.first = !s.group_momentum.first.empty() ? s.group_momentum.first : s.group_centre.first;
  return out;
}

}  // namespace octocd
