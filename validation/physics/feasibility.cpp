// The physics tier's row 9, impulse feasibility (docs/validation.md, "Motion explained by
// feasible contact impulses"; momentum-balance is its reported-impulse twin): on every
// checked step (the --every cadence) with states, whether compressive contact impulses
// inside each pair's friction cone, at contact points octocd finds itself on the posed
// shapes, can produce every dynamic body's observed change of linear (and, with rotation,
// angular) momentum, gravity removed. It reads nothing of the engine's contact rows: an
// engine that reports poses and velocities only is judged. Per island (dynamic bodies
// joined through such contacts) a linear programme (COIN-OR CLP) finds the impulses that
// minimise the largest residual in units of each body's bound; above 1 the motion has no
// explanation by contact.
#include "physics_impl.hpp"
#include "feasibility_geometry.hpp"

#include "../src/parallel.hpp"
#include "../src/row_clock.hpp"

#include <algorithm>
#include <cmath>
#include <deque>
#include <mutex>
#include <numeric>

#include <ClpSimplex.hpp>
#include <CoinPackedMatrix.hpp>

#include "octocd/exact_pairs.hpp"
#include "octocd/reference_contact.hpp"

namespace octocd {

using namespace dmath;
using namespace physics_detail;
using namespace feasibility_geometry;

namespace {

/// Islands with more dynamic bodies than this are not judged (counted and named): the
/// programme has 3-6 rows a body and 8 columns a contact point.
constexpr std::size_t kMaxIslandBodies = 16;
/// Friction-cone generators per contact point: the cone mu is replaced by the pyramid of
/// kConeSides sides circumscribed about it (every feasible friction impulse stays feasible;
/// the pyramid reaches 1 / cos(pi / kConeSides) = 1.082 mu along its edges).
constexpr int kConeSides = 8;
/// The most separating axes a pair is given (its least translation's, then every axis
/// within the pair's reach of it, least overlap first).
constexpr std::size_t kMaxNormals = 6;
/// Of a failing island, the most bodies whose motion is left free in turn to find which
/// explain the failure.
constexpr std::size_t kMaxLeftFree = 16;
/// The most earlier steps whose poses the row keeps to find the normals a persistent manifold
/// point may still carry (a persistent point keeps the normal it was found with while the
/// bodies turn: Bullet), and the most poses kept in all (bodies x steps: 2^21, 64 MiB).
constexpr std::size_t kMaxPastSteps = 64;
constexpr std::size_t kMaxPastPoses = std::size_t(1) << 21;
/// Of the normals a point carried on earlier steps, those kept as columns lie at least this
/// far apart (deg), the oldest always kept: the cones about two normals span the cones about
/// every normal between them (a friction cone of half-angle > 0 about each end).
constexpr double kPersistSpacingDeg = 5.0;
/// The least angle of an earlier normal from the ones a point has for it to be kept: 0.1 deg.
constexpr double kPersistLeastCos = 0.99999847691328769;
/// The separating-axis test's largest work on a pair here (axes x vertices): two boxes, a
/// box and a small hull; larger hulls take the posed reference's normal, and their faces
/// near a vertex are not listed (kMaxFaceScan).
constexpr double kMaxSatWork = 5e4;
/// The most faces x vertices of the other shape scanned for faces near a patch's vertex.
constexpr std::size_t kMaxFaceScan = 4096;
/// The most pairs of edges (one of each hull near the contact) examined for edge crossings
/// on hulls too large for the separating-axis test: a box against a tessellated ball has a
/// few dozen; two finely tessellated hulls resting on each other have thousands, their
/// patch's outline is found without them.
constexpr std::size_t kMaxCrossingWork = 256;
/// Edge crossings whose normals lie within this angle (deg) of each other are given one
/// normal (the first's), their outline kept.
constexpr double kCrossingGroupDeg = 0.5;
/// The widest angle between a vertex's own face normal and its pair's normal that the row
/// takes as a normal the engine may use there (cos 45 degrees).
constexpr double kFeatureCos = 0.70710678118654752;

/// How far an engine's own normal may lie from octocd's (deg): an engine queries the shapes
/// its own way (Jolt's normals lie up to 1.17 deg from a fresh query of the same pair).
/// Every normal within it is admitted by widening each cone to tilted_mu.
constexpr double kNormalSlackDeg = 1.5;
/// The friction coefficient of the cone about n that holds every cone of coefficient mu
/// about a normal within kNormalSlackDeg of n: tan(atan(mu) + the slack).
double tilted_mu(double mu, double slack_deg) {
  return std::tan(std::min(std::atan(mu) + slack_deg * 3.14159265358979323846 / 180.0, 1.5));
}
/// The same slack where the normal is the posed reference's (FCL / libccd EPA on hulls too
/// large for the separating-axis test here, or a mesh): Bullet's bunny-stack-50 takes a
/// normal beyond 1.5 deg of it (frame 292, pair (31, 40)).
constexpr double kPosedNormalSlackDeg = 5.0;


/// One contact of a pair as the programme reads it: a point (world) and the pair's normal
/// (unit, B to A), with the pair's friction coefficient.
struct Contact {
  Pair pair;
  D3 point, normal;
  double mu = 0;
  double lever = 0;  ///< how far the engine's point may lie from `point` (m)
  double slack_deg = kNormalSlackDeg;  ///< how far the engine's normal may lie from `normal`
};

/// The row's counts beyond its tally (PhysicsValidators::Impl::row_state).
struct FeasibilityState {
  std::uint64_t steps = 0, islands = 0, contacts = 0, pairs = 0;
  std::uint64_t too_large = 0, asleep = 0, clamped = 0, locked = 0, unsolved = 0;
  std::string too_large_first, unsolved_first;
  std::size_t largest = 0;
  /// The detection poses of the steps before this one (most recent first, consecutive
  /// frames, at most kMaxPastSteps and kMaxPastPoses in all), and the frame of the first.
  std::deque<std::vector<Pose>> past;
  std::int64_t past_frame = -1;
  /// Each hull's edges and supporting planes (HullEdges), found once.
  std::map<const HullFeatures*, HullEdges> hulls;
  std::uint64_t crossings = 0;  ///< contact points on an edge of one hull within reach of the other
  std::uint64_t crossings_skipped = 0;  ///< pair-steps above kMaxCrossingWork
  std::uint64_t persisted = 0;  ///< contact points given normals of their earlier steps
  std::size_t persisted_steps = 0;  ///< the most earlier steps a point's normals came from
};

}  // namespace

template <>
void PhysicsValidators::Impl::measure<RowId::ImpulseFeasibility>(PhysicsFrame& f) {
  const FrameRecord& rec = f.rec;
  const std::vector<Pose>& det = f.det;
  const Model& m = *model;
  const std::size_t n = m.bodies.size();
  auto& st = row_state<FeasibilityState>(RowId::ImpulseFeasibility);
  // Every step's detection poses join the past (after this step is judged): a gap in the
  // frames or a step without poses starts it anew.
  const bool posed = det.size() == n && rec.x_pre.size() == n;
  if (!posed || rec.frame != st.past_frame + 1) st.past.clear();
  struct Remember {
    FeasibilityState& st;
    const std::vector<Pose>& det;
    std::int64_t frame;
    bool posed;
    std::size_t cap;
    ~Remember() {
      if (!posed) return;
      st.past.push_front(det);
      st.past_frame = frame;
      while (st.past.size() > cap) st.past.pop_back();
    }
  } remember{st, det, rec.frame, posed, std::max<std::size_t>(1, std::min(kMaxPastSteps, kMaxPastPoses / std::max<std::size_t>(n, 1)))};
  if (!f.sampled) return;
  if (rec.x_pre.size() != n || rec.v_pre.size() != n || rec.x_post.size() != n || rec.v_post.size() != n) return;
  auto [infeasible] = tallies(RowId::ImpulseFeasibility, "infeasible");
  ++st.steps;
  const bool rotating = rec.q_pre.size() == n && rec.q_post.size() == n && rec.w_pre.size() == n &&
                        rec.w_post.size() == n && bodies.contact_geometry == ContactGeometry::Shape;
  const D3 g = d3(m.scene.gravity);
  const double dt = m.scene.dt;
  const double eps = tol.balance_ulps * kEps32;
  const double slack = tol.geometry_slack_m;
  const bool aabb_geometry = bodies.contact_geometry == ContactGeometry::Aabb;

  // Candidates: each body's exact AABB at its detection pose grown by its motion through
  // the step, its convex radius and half the largest margin and the slack (apart.cpp's
  // reach): two shapes that come within the margin of each other in the step overlap.
  std::vector<double> motion(n);
  std::vector<Aabb> grown(n), world(n);
  for (std::size_t i = 0; i < n; ++i) {
    const auto u = static_cast<std::uint32_t>(i);
    motion[i] = step_motion(rec, u);
    world[i] = aabb_geometry && rec.aabbs.size() == n ? rec.aabbs[i] : ref->world_aabb(u, det[i]);
    grown[i] = expanded(world[i], static_cast<float>(motion[i] + radius(u) + 0.5 * (max_margin + slack)));
  }
  std::vector<Pair> cand;
  ExactPairsSettings settings;
  settings.threads = threads;
  settings.max_pairs_per_body = limits::kMaxPairsPerBody;
  exact_pairs(grown, cand, settings);

  // Each pair within reach: its contact points and normal.
  std::vector<std::uint32_t> parent(n);
  std::iota(parent.begin(), parent.end(), 0u);
  auto find = [&](std::uint32_t i) {
    while (parent[i] != i) i = parent[i] = parent[parent[i]];
    return i;
  };
  std::vector<std::uint8_t> touched(n, 0);
  // The normals a persistent manifold point at `pt` may carry from the earlier steps (the
  // past), beyond `nrm` (B to A): a point keeps the normal it was found with while its two
  // material points (pt on A and on B, carried back with each body's pose) stay within the
  // pair's margin (+ slack) of each other along and across it (Bullet's breaking
  // threshold); the normal found then is `nrm` as it lay on A's or on B's earlier pose
  // (the face it belongs to turns with its body: `sides` bit 0 A, bit 1 B, both for an
  // edge cross or a normal of unknown origin). Walks back while a carried normal keeps the
  // point; appends those kept (kPersistSpacingDeg apart, the oldest kept).
  const double spacing_cos = std::cos(kPersistSpacingDeg * kPi / 180.0);
  auto earlier_normals = [&](const Pair& p, const D3& pt, const D3& nrm, unsigned sides, std::vector<D3>& out, std::size_t& steps_back) {
    if (st.past.empty()) return;
    const M3 ra = rotation(det[p.a].orientation), rb = rotation(det[p.b].orientation);
    const D3 la = mul_t(ra, pt - d3(det[p.a].position)), lb = mul_t(rb, pt - d3(det[p.b].position));
    const std::array<D3, 2> local{mul_t(ra, nrm), mul_t(rb, nrm)};
    std::array<D3, 2> last{nrm, nrm}, pending{nrm, nrm};
    std::array<bool, 2> open{(sides & 1u) != 0, (sides & 2u) != 0};
    const double thr = pair_margin(p) + slack;
    std::size_t k = 0;
    for (; k < st.past.size() && (open[0] || open[1]); ++k) {
      const Pose& qa = st.past[k][p.a];
      const Pose& qb = st.past[k][p.b];
      const M3 pa = rotation(qa.orientation), pb = rotation(qb.orientation);
      const D3 d = (d3(qa.position) + mul(pa, la)) - (d3(qb.position) + mul(pb, lb));
      for (int side = 0; side < 2; ++side) {
        if (!open[side]) continue;
        const D3 nk = mul(side == 0 ? pa : pb, local[std::size_t(side)]);
        const double along = dot3(d, nk);
        if (along > thr || len3(d - along * nk) > thr) {
          open[side] = false;
          continue;
        }
        if (dot3(nk, last[std::size_t(side)]) < spacing_cos) {
          out.push_back(nk);
          last[std::size_t(side)] = pending[std::size_t(side)] = nk;
        } else {
          pending[std::size_t(side)] = nk;
        }
      }
    }
    for (int side = 0; side < 2; ++side)
      if ((sides >> side & 1u) && dot3(pending[std::size_t(side)], last[std::size_t(side)]) < kPersistLeastCos)
        out.push_back(pending[std::size_t(side)]);
    steps_back = std::max(steps_back, k);
  };
  // Each candidate pair's contact points on `threads` threads, each into its own slot.
  struct PairContacts {
    std::vector<Contact> contacts;
    std::uint64_t persisted = 0, crossings = 0, crossings_skipped = 0;
    std::size_t persisted_steps = 0;
  };
  std::vector<PairContacts> pair_out(cand.size());
  std::mutex hulls_mutex;
  parallel_items(cand.size(), threads, stop, [&](std::size_t ci, unsigned) {
    const Pair p = cand[ci];
    PairContacts& found = pair_out[ci];
    std::vector<Contact>& contacts = found.contacts;
    if (!dynamic(p.a) && !dynamic(p.b)) return;
    const double reach = pair_margin(p) + slack + motion[p.a] + motion[p.b] + inflation(p);
    const double mu = pair_mu(p);
    if (aabb_geometry) {
      // The engine resolves on the world AABBs: the normal is the axis of least overlap
      // (or of the gap), from B's centre to A's; the point the overlap box's centre.
      const Aabb& a = world[p.a];
      const Aabb& b = world[p.b];
      double least = std::numeric_limits<double>::infinity();
      int axis = 0;
      D3 centre{};
      for (int k = 0; k < 3; ++k) {
        const double amin = double((&a.min.x)[k]), amax = double((&a.max.x)[k]);
        const double bmin = double((&b.min.x)[k]), bmax = double((&b.max.x)[k]);
        const double overlap = std::min(amax - bmin, bmax - amin);
        if (overlap < -reach) {
          least = -std::numeric_limits<double>::infinity();
          break;
        }
        centre[std::size_t(k)] = 0.5 * (std::max(amin, bmin) + std::min(amax, bmax));
        if (overlap < least) {
          least = overlap;
          axis = k;
        }
      }
      if (!(least > -reach)) return;
      D3 nrm{};
      const double ca = 0.5 * (double((&a.min.x)[axis]) + double((&a.max.x)[axis]));
      const double cb = 0.5 * (double((&b.min.x)[axis]) + double((&b.max.x)[axis]));
      nrm[std::size_t(axis)] = ca >= cb ? 1.0 : -1.0;
      contacts.push_back({p, centre, nrm, mu, 0.0});
      if (ca == cb) {  // concentric along the axis: either direction
        nrm[std::size_t(axis)] = -nrm[std::size_t(axis)];
        contacts.push_back({p, centre, nrm, mu, 0.0});
      }
    } else {
      // The posed shapes: the separating-axis test on their hulls where it runs (its
      // normal is the least overlap's axis, or the largest gap's), else the posed
      // reference (FCL / libccd).
      const HullFeatures& ha = ref->hull_features(p.a);
      const HullFeatures& hb = ref->hull_features(p.b);
      // Every axis within the pair's reach of the least overlap is a plane the engine may
      // take within its margin (an edge of one shape across an edge of the other, touching:
      // Bullet's normal is their cross product while SAT's least is a face's).
      SatSettings cheap = sat_settings;
      cheap.max_work = kMaxSatWork;  // larger hulls: the posed reference (FCL / libccd)
      cheap.abs_m = std::max(cheap.abs_m, reach);
      cheap.rel = 0;
      cheap.accept_separated = true;
      const SatResult sat = sat_min_translation(ha, det[p.a], hb, det[p.b], cheap);
      const M3 ra = rotation(det[p.a].orientation), rb = rotation(det[p.b].orientation);
      const D3 xa = d3(det[p.a].position), xb = d3(det[p.b].position);
      std::vector<D3> va(ha.vertices.size()), vb(hb.vertices.size());
      for (std::size_t k = 0; k < va.size(); ++k) va[k] = xa + mul(ra, ha.vertices[k]);
      for (std::size_t k = 0; k < vb.size(); ++k) vb[k] = xb + mul(rb, hb.vertices[k]);
      std::vector<D3> normals;
      std::vector<unsigned> sides_of;  // per normal: whose face it is (earlier_normals' `sides`)
      double gap = 0;
      if (sat.tested) {
        gap = -sat.depth;
        // The accepted axes (the least among them), least overlap first, distinct
        // directions, at most kMaxNormals.
        std::vector<SatAxis> by_overlap(sat.accepted);
        std::stable_sort(by_overlap.begin(), by_overlap.end(),
                         [](const SatAxis& x, const SatAxis& y) { return x.overlap < y.overlap; });
        for (const SatAxis& ax : by_overlap) {
          if (normals.size() >= kMaxNormals) break;
          const D3 u{ax.normal[0], ax.normal[1], ax.normal[2]};
          bool known = false;
          for (const D3& q : normals) known = known || dot3(u, q) > 1.0 - 1e-9;
          if (known) continue;
          normals.push_back(u);
          sides_of.push_back(ax.kind == 0 ? 1u : ax.kind == 1 ? 2u : 3u);
        }
        if (normals.empty()) {
          normals.push_back(D3{sat.normal[0], sat.normal[1], sat.normal[2]});
          sides_of.push_back(3u);
        }
        // Apart: the direction of the nearest points (an engine's GJK normal) is no
        // separating axis where the nearest features are a vertex and an edge or two
        // vertices: the posed reference's (FCL's distance) is taken too.
        if (gap > slack && gap <= reach) {
          const ReferenceNormal r = ref->posed(p.a, p.b, det[p.a], det[p.b]);
          if (r.valid && !r.penetrating && r.distance > slack) {
            const D3 nr = unit(d3(r.normal));
            if (dot3(nr, normals[0]) < 1.0 - 1e-9) {
              normals.push_back(nr);
              sides_of.push_back(3u);
            }
          }
        }
      } else {
        // The posed reference (FCL / libccd); where it finds the shapes touching (|signed
        // distance| within the slack, or no answer) its direction is its nearest points'
        // rounding: the separating-axis test on the two hulls' face normals alone instead
        // (a large hull resting on a face or a vertex).
        const ReferenceNormal r = ref->posed(p.a, p.b, det[p.a], det[p.b]);
        if (r.valid && std::fabs(r.signed_distance()) > slack) {
          gap = r.signed_distance();
          normals.push_back(unit(d3(r.normal)));
          sides_of.push_back(3u);
        } else {
          double face_gap = 0;
          const D3 axis = face_axes_least(va, ha, ra, vb, hb, rb, face_gap);
          if (len3(axis) == 0) return;
          gap = r.valid ? r.signed_distance() : face_gap;
          normals.push_back(axis);
          sides_of.push_back(3u);
          // The posed reference's own direction too, where the shapes' overlap along it
          // lies within the pair's reach of the face axes' least: an edge of one shape
          // across an edge of the other (a box's edge over an icosphere's ridge: ODE's and
          // FCL's normal is their cross product, and the slab of the face axes' least
          // holds no point of both).
          if (r.valid) {
            const D3 nr = unit(d3(r.normal));
            double lo_a = std::numeric_limits<double>::infinity(), hi_b = -lo_a;
            for (const D3& v : va) lo_a = std::min(lo_a, dot3(nr, v));
            for (const D3& v : vb) hi_b = std::max(hi_b, dot3(nr, v));
            if (len3(nr) > 0 && dot3(nr, axis) < 1.0 - 1e-9 && hi_b - lo_a <= -face_gap + reach) {
              normals.push_back(nr);
              sides_of.push_back(3u);
            }
          }
        }
      }
      if (gap > reach) return;
      // A contact point with its normal, and with each normal it may carry from earlier steps.
      std::vector<D3> earlier;
      // A point already given this normal with the same earlier poses (by another axis's
      // patch, or as a face near a vertex) is not given it again; its lever is the larger.
      std::vector<std::pair<std::size_t, unsigned>> given;  // contacts' index, its `sides`
      auto add_point = [&](const D3& pt, const D3& normal, unsigned sides, double lever) {
        for (const auto& [k, s] : given) {
          const D3 d = contacts[k].point - pt;
          if (s == sides && dot3(d, d) <= 1e-24 && dot3(contacts[k].normal, normal) > 1.0 - 1e-12) {
            contacts[k].lever = std::max(contacts[k].lever, lever);  // the bound reads each body's largest
            return;
          }
        }
        given.emplace_back(contacts.size(), sides);
        const double slack_deg = sat.tested ? kNormalSlackDeg : kPosedNormalSlackDeg;
        contacts.push_back({p, pt, normal, mu, lever, slack_deg});
        earlier.clear();
        earlier_normals(p, pt, normal, sides, earlier, found.persisted_steps);
        found.persisted += !earlier.empty();
        for (const D3& e : earlier) contacts.push_back({p, pt, e, mu, lever, slack_deg});
      };
      for (std::size_t ni = 0; ni < normals.size(); ++ni) {
        const D3 nrm = unit(normals[ni]);
        if (len3(nrm) == 0) continue;
        double min_a = std::numeric_limits<double>::infinity(), max_b = -min_a;
        for (const D3& v : va) min_a = std::min(min_a, dot3(nrm, v));
        for (const D3& v : vb) max_b = std::max(max_b, dot3(nrm, v));
        const auto [e1, e2] = tangent_basis(nrm);
        // The vertices of each shape within the reach of the contact slab, projected on
        // the plane normal to n; the patch is where their hulls overlap (within reach).
        std::vector<D3> pts;
        std::vector<P2> pa, pb;
        const double top = std::max(min_a, max_b) + reach, bottom = std::min(min_a, max_b) - reach;
        for (const D3& v : va)
          if (dot3(nrm, v) <= top) {
            pa.push_back({dot3(e1, v), dot3(e2, v), pts.size()});
            pts.push_back(v);
          }
        for (const D3& v : vb)
          if (dot3(nrm, v) >= bottom) {
            pb.push_back({dot3(e1, v), dot3(e2, v), pts.size()});
            pts.push_back(v);
          }
        const std::vector<P2> hA = hull2(pa), hB = hull2(pb);
        const double mid = 0.5 * (min_a + max_b);
        // The patch's points, each with the shape whose vertex it is (0: A, 1: B, 2: a
        // crossing of the two outlines).
        std::vector<D3> patch;
        std::vector<int> from;
        const std::size_t na_near = pa.size();
        for (const P2& q : hA)
          if (within(q, hB, reach)) {
            patch.push_back(pts[q.k]);
            from.push_back(0);
          }
        for (const P2& q : hB)
          if (within(q, hA, reach)) {
            patch.push_back(pts[q.k]);
            from.push_back(1);
          }
        if (hA.size() >= 2 && hB.size() >= 2)
          for (std::size_t i = 0; i < hA.size(); ++i)
            for (std::size_t j = 0; j < hB.size(); ++j) {
              P2 c;
              if (hA.size() == 2 && i == 1) break;
              if (hB.size() == 2 && j == 1) break;
              if (crossing(hA[i], hA[(i + 1) % hA.size()], hB[j], hB[(j + 1) % hB.size()], c)) {
                patch.push_back(c.x * e1 + c.y * e2 + mid * nrm);
                from.push_back(2);
              }
            }
        if (patch.empty()) {
          // Nothing of the two within the other's outline (a corner beside a face's
          // edge): every vertex of the smaller side within the slab.
          const auto& side = hA.size() <= hB.size() ? hA : hB;
          for (const P2& q : side) {
            patch.push_back(pts[q.k]);
            from.push_back(q.k < na_near ? 0 : 1);
          }
        }
        // The patch's outline only: impulses at points inside it are combinations of
        // impulses at its corners (a point's torque is linear in it).
        std::vector<P2> flat;
        for (std::size_t k = 0; k < patch.size(); ++k) flat.push_back({dot3(e1, patch[k]), dot3(e2, patch[k]), k});
        const std::vector<P2> outline = hull2(flat);
        const double lever = std::max(0.0, max_b - min_a) + reach;
        for (const P2& q : outline) {
          const D3& pt = patch[q.k];
          add_point(pt, nrm, sides_of[ni], lever);
          // A vertex of one shape near a face of the other: that face's normal, where it is
          // within kFeatureCos of the pair's (an engine's manifold point keeps the normal of
          // the feature it was found on; a box's corner beside another's face takes the
          // face's).
          if (from[q.k] == 2) continue;
          const bool vertex_of_a = from[q.k] == 0;
          const HullFeatures& other = vertex_of_a ? hb : ha;
          if (other.face_normals.size() * (vertex_of_a ? vb : va).size() > kMaxFaceScan) continue;
          const M3& rot = vertex_of_a ? rb : ra;
          const std::vector<D3>& verts = vertex_of_a ? vb : va;
          for (const auto& fl : other.face_normals) {
            const D3 fw = mul(rot, D3{fl[0], fl[1], fl[2]});
            for (const double sign : {1.0, -1.0}) {
              const D3 out = sign * fw;  // outward of the other shape
              double support = -std::numeric_limits<double>::infinity();
              for (const D3& v : verts) support = std::max(support, dot3(out, v));
              if (std::fabs(dot3(out, pt) - support) > reach) continue;  // not near that face's plane
              const D3 face_n = vertex_of_a ? out : -1.0 * out;          // B to A
              const double c = dot3(face_n, nrm);
              if (c < kFeatureCos || c > 1.0 - 1e-9) continue;
              add_point(pt, face_n, vertex_of_a ? 2u : 1u, lever);
            }
          }
        }
      }
      // Edge crossings, on hulls too large for the separating-axis test (whose edge-cross
      // axes give them otherwise): an edge of A passing within the pair's reach of an edge
      // of B is a contact point, its normal their cross product (B to A). A box's edge lying
      // over a tessellated ball's ridges touches each ridge it crosses, none of them in the
      // slab of the pair's one normal (DART's rows on a box resting on an icosphere).
      if (!sat.tested) {
        auto extras = [&](const HullFeatures& h) -> const HullEdges& {
          const std::lock_guard<std::mutex> lock(hulls_mutex);  // found once per hull, by any thread
          auto it = st.hulls.find(&h);
          if (it == st.hulls.end()) it = st.hulls.emplace(&h, hull_edges_and_planes(h)).first;
          return it->second;
        };
        // Along each of the pair's normals n (B to A) the other shape lies below
        // max(n . B) (A's points) or above min(n . A) (B's): a point of contact within
        // the reach lies in that band grown by the reach.
        std::vector<std::array<double, 2>> band;  // per normal: min(n . A), max(n . B)
        for (const D3& nrm : normals) {
          double lo = std::numeric_limits<double>::infinity(), hi = -lo;
          for (const D3& v : va) lo = std::min(lo, dot3(nrm, v));
          for (const D3& v : vb) hi = std::max(hi, dot3(nrm, v));
          band.push_back({lo, hi});
        }
        // The edges (world) of one hull that reach into that band for every normal and
        // whose box meets the other body's grown by the reach.
        auto near_edges = [&](const HullFeatures& h, const std::vector<D3>& w, const Aabb& other, bool of_a) {
          std::vector<std::pair<D3, D3>> out;
          for (const auto& [i0, i1] : extras(h).edges) {
            const D3& x = w[i0];
            const D3& y = w[i1];
            bool meets = true;
            for (std::size_t k = 0; k < normals.size() && meets; ++k) {
              const double px = dot3(normals[k], x), py = dot3(normals[k], y);
              meets = of_a ? std::min(px, py) <= band[k][1] + reach : std::max(px, py) >= band[k][0] - reach;
            }
            for (int k = 0; k < 3 && meets; ++k) {
              const double lo = std::min(x[std::size_t(k)], y[std::size_t(k)]);
              const double hi = std::max(x[std::size_t(k)], y[std::size_t(k)]);
              meets = hi >= double((&other.min.x)[k]) - reach && lo <= double((&other.max.x)[k]) + reach;
            }
            if (meets) out.emplace_back(x, y);
          }
          return out;
        };
        struct Crossing {
          D3 point, normal;
          unsigned sides;
          double lever;
        };
        std::vector<Crossing> crossing;
        const std::vector<std::pair<D3, D3>> ea = near_edges(ha, va, world[p.b], true),
                                             eb = near_edges(hb, vb, world[p.a], false);
        if (ea.size() * eb.size() > kMaxCrossingWork) {
          ++found.crossings_skipped;
        } else {
          D3 ca{}, cb{};
          for (const D3& v : va) ca = ca + v;
          for (const D3& v : vb) cb = cb + v;
          ca = (1.0 / double(std::max<std::size_t>(va.size(), 1))) * ca;
          cb = (1.0 / double(std::max<std::size_t>(vb.size(), 1))) * cb;
          for (const auto& [a0, a1] : ea)
            for (const auto& [b0, b1] : eb) {
              D3 on_a, on_b;
              closest_on_segments(a0, a1, b0, b1, on_a, on_b);
              const D3 d = on_a - on_b;
              if (dot3(d, d) > reach * reach) continue;
              D3 nrm = unit(cross3(a1 - a0, b1 - b0));
              if (len3(nrm) == 0) continue;
              if (dot3(nrm, ca - cb) < 0) nrm = -1.0 * nrm;
              crossing.push_back({0.5 * (on_a + on_b), nrm, 3u, reach + len3(d)});
            }
          // An edge of one hull inside the other grown by the reach: the part of it within
          // (clipped by the other's supporting half-spaces moved out by the reach); its two
          // ends are contact points, each with the normal of the other's plane nearest it
          // (the face the edge enters or leaves by). A box's edge sunk into a ball's facets
          // meets them where it enters and leaves.
          auto clip = [&](const std::vector<std::pair<D3, D3>>& edges, const HullFeatures& other, const Pose& pose,
                          bool edge_of_a) {
            const HullEdges& he = extras(other);
            const M3 r = rotation(pose.orientation);
            const D3 x = d3(pose.position);
            std::vector<D3> nw(he.normals.size());
            std::vector<double> off(he.normals.size());
            for (std::size_t k = 0; k < nw.size(); ++k) {
              nw[k] = mul(r, he.normals[k]);
              off[k] = dot3(nw[k], x) + he.support[k] + reach;
            }
            for (const auto& [e0, e1] : edges) {
              double t0 = 0, t1 = 1;
              const D3 de = e1 - e0;
              for (std::size_t k = 0; k < nw.size() && t0 <= t1; ++k) {
                const double s0 = dot3(nw[k], e0) - off[k], ds = dot3(nw[k], de);
                if (std::fabs(ds) < 1e-300) {
                  if (s0 > 0) t1 = -1;
                } else if (ds > 0) {
                  t1 = std::min(t1, -s0 / ds);
                } else {
                  t0 = std::max(t0, -s0 / ds);
                }
              }
              if (!(t0 <= t1)) continue;
              for (const double t : {t0, t1}) {
                const D3 pt = e0 + t * de;
                std::size_t best = 0;
                double nearest = -std::numeric_limits<double>::infinity();
                for (std::size_t k = 0; k < nw.size(); ++k) {
                  const double sd = dot3(nw[k], pt) - off[k];
                  if (sd > nearest) {
                    nearest = sd;
                    best = k;
                  }
                }
                // The other's outward normal at its face: B to A when the other is B.
                crossing.push_back({pt, edge_of_a ? nw[best] : -1.0 * nw[best], edge_of_a ? 2u : 1u, 2.0 * reach});
                if (t1 == t0) break;
              }
            }
          };
          clip(ea, hb, det[p.b], true);
          clip(eb, ha, det[p.a], false);
          // Points whose normals lie within kCrossingGroupDeg of each other (and of the same
          // face's body) share the first one's; of each group only its outline along it is
          // kept (impulses inside are combinations of impulses at its corners).
          struct Group {
            D3 normal;
            unsigned sides;
            double lever;
            std::vector<D3> points;
          };
          std::vector<Group> groups;
          const double group_cos = std::cos(kCrossingGroupDeg * kPi / 180.0);
          for (const Crossing& c : crossing) {
            Group* g = nullptr;
            for (Group& h : groups)
              if (h.sides == c.sides && dot3(h.normal, c.normal) >= group_cos) {
                g = &h;
                break;
              }
            if (!g) {
              groups.push_back({c.normal, c.sides, 0.0, {}});
              g = &groups.back();
            }
            g->lever = std::max(g->lever, c.lever);
            g->points.push_back(c.point);
          }
          for (const Group& g : groups) {
            const auto [e1, e2] = tangent_basis(g.normal);
            std::vector<P2> flat;
            for (std::size_t k = 0; k < g.points.size(); ++k)
              flat.push_back({dot3(e1, g.points[k]), dot3(e2, g.points[k]), k});
            for (const P2& q : hull2(flat)) {
              ++found.crossings;
              add_point(g.points[q.k], g.normal, g.sides, g.lever);
            }
          }
        }
      }
    }
  });
  // In candidate order: the contacts, the pairs with any, the islands they join.
  std::vector<Contact> contacts;
  for (std::size_t ci = 0; ci < cand.size(); ++ci) {
    const PairContacts& out = pair_out[ci];
    st.persisted += out.persisted;
    st.crossings += out.crossings;
    st.crossings_skipped += out.crossings_skipped;
    st.persisted_steps = std::max(st.persisted_steps, out.persisted_steps);
    if (out.contacts.empty()) continue;
    const Pair p = cand[ci];
    contacts.insert(contacts.end(), out.contacts.begin(), out.contacts.end());
    ++st.pairs;
    if (dynamic(p.a) && dynamic(p.b)) parent[find(p.a)] = find(p.b);
    touched[p.a] = touched[p.b] = 1;
  }
  st.contacts += contacts.size();

  // Islands: the dynamic bodies joined through contacts between dynamic bodies.
  std::map<std::uint32_t, std::vector<std::uint32_t>> islands;
  for (std::uint32_t i = 0; i < n; ++i)
    if (dynamic(i) && touched[i]) islands[find(i)].push_back(i);
  std::map<std::uint32_t, std::vector<std::size_t>> island_contacts;
  for (std::size_t k = 0; k < contacts.size(); ++k) {
    const Pair p = contacts[k].pair;
    island_contacts[find(dynamic(p.a) ? p.a : p.b)].push_back(k);
  }
  auto locked = [&](std::uint32_t i) -> unsigned { return bodies.locked_dofs.empty() ? 0u : bodies.locked_dofs[i]; };
  // Each island judged on `threads` threads into its own slot, then tallied in island order
  // (the verdicts do not depend on the thread count).
  enum class Outcome { Judged, Asleep, Locked, Clamped, TooLarge, Unsolved };
  struct IslandVerdict {
    Outcome outcome = Outcome::Judged;
    double figure = 0;
    std::uint32_t body = 0;
    std::string text;  ///< the failure's, where figure > 1
  };
  std::vector<const std::vector<std::uint32_t>*> island_members;
  std::vector<const std::vector<std::size_t>*> island_ks;
  for (const auto& [root, members] : islands) {
    island_members.push_back(&members);
    island_ks.push_back(&island_contacts[root]);
  }
  std::vector<IslandVerdict> verdicts(island_members.size());
  parallel_items(island_members.size(), threads, stop, [&](std::size_t ii, unsigned) {
    const std::vector<std::uint32_t>& members = *island_members[ii];
    IslandVerdict& verdict = verdicts[ii];
    // Islands the row does not judge, counted.
    for (const std::uint32_t i : members) {
      if (asleep(rec.asleep_pre, i) || asleep(rec.asleep_post, i)) {
        verdict.outcome = Outcome::Asleep;
        return;
      }
      if (locked(i)) {
        verdict.outcome = Outcome::Locked;
        return;
      }
      if (bodies.velocity_clamp > 0.0) {
        const Vec3 v = rec.v_post[i];
        const double c = bodies.velocity_clamp * (1.0 - 1e-6);
        if (std::fabs(v.x) >= c || std::fabs(v.y) >= c || std::fabs(v.z) >= c) {
          verdict.outcome = Outcome::Clamped;
          return;
        }
      }
    }
    if (members.size() > kMaxIslandBodies) {
      verdict.outcome = Outcome::TooLarge;
      return;
    }
    const std::vector<std::size_t>& ks = *island_ks[ii];
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
        reach_of[it->second] = std::max(reach_of[it->second], len3(c.point - com_at(det[i], i)));
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
          const D3 t = kind == Kind::Torsion ? dir : cross3(c.point - com_at(det[i], i), dir);
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
    // for every row r; solved with each row scaled by 1 / sigma_r. Returns the largest
    // scaled residual of the solution (recomputed in double) and the solution.
    auto solve = [&](const std::vector<double>& rhs, const std::vector<double>& sig, std::vector<double>& lambda) {
      std::vector<int> idx;
      std::vector<double> val;
      std::vector<CoinBigIndex> start{0};
      for (std::size_t c = 0; c < ncols; ++c) {
        for (int e = col_start[c]; e < col_start[c + 1]; ++e) {
          const std::size_t r = std::size_t(row_index[std::size_t(e)]);
          idx.push_back(int(2 * r));
          val.push_back(value[std::size_t(e)] / sig[r]);
          idx.push_back(int(2 * r + 1));
          val.push_back(value[std::size_t(e)] / sig[r]);
        }
        for (const auto& [bi, v] : budget_of[c]) {
          idx.push_back(int(2 * rows) + bi);
          val.push_back(v);
        }
        start.push_back(CoinBigIndex(idx.size()));
      }
      for (std::size_t r = 0; r < rows; ++r) {  // the column of t
        idx.push_back(int(2 * r));
        val.push_back(-1.0);
        idx.push_back(int(2 * r + 1));
        val.push_back(1.0);
      }
      start.push_back(CoinBigIndex(idx.size()));
      std::vector<int> len(ncols + 1);
      for (std::size_t c = 0; c <= ncols; ++c) len[c] = int(start[c + 1] - start[c]);
      const int nrows = int(2 * rows + budgets.size());
      const CoinPackedMatrix a(true, nrows, int(ncols + 1), CoinBigIndex(idx.size()), val.data(), idx.data(),
                               start.data(), len.data());
      std::vector<double> col_lo(ncols + 1, 0.0), col_hi(ncols + 1, COIN_DBL_MAX), obj(ncols + 1, 0.0);
      obj[ncols] = 1.0;
      std::vector<double> row_lo(std::size_t(nrows), -COIN_DBL_MAX), row_hi(std::size_t(nrows), 0.0);
      for (std::size_t r = 0; r < rows; ++r) {
        const double br = rhs[r] / sig[r];
        row_lo[2 * r] = -COIN_DBL_MAX;  // A' lambda - t <= b'
        row_hi[2 * r] = br;
        row_lo[2 * r + 1] = br;  // A' lambda + t >= b'
        row_hi[2 * r + 1] = COIN_DBL_MAX;
      }
      ClpSimplex lp;
      lp.setLogLevel(0);
      lp.scaling(0);  // its scaled tolerances would leave unscaled residuals of several bounds
      lp.loadProblem(a, col_lo.data(), col_hi.data(), obj.data(), row_lo.data(), row_hi.data());
      lp.dual();
      lambda.assign(ncols, 0.0);
      if (lp.status() != 0 && lp.status() != 1) return std::numeric_limits<double>::quiet_NaN();
      const double* x = lp.primalColumnSolution();
      for (std::size_t c = 0; c < ncols; ++c) lambda[c] = std::max(0.0, x[c]);
      std::vector<double> res(rhs);
      for (std::size_t c = 0; c < ncols; ++c)
        for (int e = col_start[c]; e < col_start[c + 1]; ++e)
          res[std::size_t(row_index[std::size_t(e)])] -= value[std::size_t(e)] * lambda[c];
      double worst = 0;
      for (std::size_t r = 0; r < rows; ++r) worst = std::max(worst, std::fabs(res[r]) / sig[r]);
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
      return;
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
    if (figure <= 1.0) return;
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
          rec.frame, group_name(members), members.size(), ks.size(), body, angular ? "angular momentum" : "momentum",
          angular ? "dL" : "m (v' - v) - m g dt", (*rhs)[r0], (*rhs)[r0 + 1], (*rhs)[r0 + 2],
          angular ? "kg m^2/s" : "kg m/s", res[r0], res[r0 + 1], res[r0 + 2], figure, sigma[worst_row],
          pairs.empty() ? "none" : pairs, culprit_text);
    }();
  });
  for (std::size_t ii = 0; ii < verdicts.size(); ++ii) {
    const IslandVerdict& verdict = verdicts[ii];
    const std::vector<std::uint32_t>& members = *island_members[ii];
    switch (verdict.outcome) {
      case Outcome::Asleep:
        ++st.asleep;
        break;
      case Outcome::Locked:
        ++st.locked;
        break;
      case Outcome::Clamped:
        ++st.clamped;
        break;
      case Outcome::TooLarge:
        if (!st.too_large)
          st.too_large_first = fmt::format("frame {}: {} of {} bodies", rec.frame, group_name(members), members.size());
        ++st.too_large;
        break;
      case Outcome::Unsolved:
        if (!st.unsolved) st.unsolved_first = fmt::format("frame {}: {}", rec.frame, group_name(members));
        ++st.unsolved;
        ++st.islands;
        st.largest = std::max(st.largest, members.size());
        break;
      case Outcome::Judged:
        ++st.islands;
        st.largest = std::max(st.largest, members.size());
        infeasible.check(verdict.figure <= 1.0, verdict.figure, Where::of_body(rec.frame, verdict.body),
                         [&] { return verdict.text; });
        break;
    }
  }
}

template <>
ValidationResult PhysicsValidators::Impl::table<RowId::ImpulseFeasibility>() const {
  const auto& st = row_state<FeasibilityState>(RowId::ImpulseFeasibility);
  auto [infeasible] = tallies(RowId::ImpulseFeasibility, "infeasible");
  ValidationResult r = failures_row(RowId::ImpulseFeasibility,
                                    "islands whose momentum change no feasible contact impulses explain",
                                    "balance_ulps,geometry_slack_m");
  r.applicable = infeasible.checks > 0;
  if (!r.applicable) {
    r.detail = st.steps ? "no island in contact in a step with states"
                        : "no states (a trace: add /states/position and /states/velocity)";
  } else {
    r.detail = fmt::format(
        "{} island-steps of {} steps ({} pairs, {} contact points found on the posed shapes; largest island {} "
        "bodies): worst {:.3g} of its bound; friction cones as {}-sided circumscribed pyramids ({:.3f} mu along "
        "their edges)",
        infeasible.checks, st.steps, st.pairs, st.contacts, st.largest, infeasible.worst_or(0.0), kConeSides,
        1.0 / std::cos(kPi / kConeSides));
  }
  note(r.detail, bodies.friction_per_manifold,
       "friction per manifold (friction_per \"manifold\"): each pair's friction one tangential impulse of at most "
       "mu x its normal impulse at any point of its patch, and a torsion about its normal of at most mu x its extent x "
       "its normal impulse");
  note(r.detail, st.persisted,
       "{} contact points also given the normals they carried on earlier steps (a persistent manifold's; up to {} "
       "steps back)",
       st.persisted, st.persisted_steps);
  note(r.detail, st.crossings,
       "{} contact points where an edge of one hull (hulls too large for the separating-axis test) passes the other",
       st.crossings);
  note(r.detail, st.crossings_skipped, "{} pair-steps with more than {} pairs of edges near the contact: no edge crossings taken",
       st.crossings_skipped, kMaxCrossingWork);
  note(r.detail, st.too_large, "{} islands above {} bodies not judged (first: {})", st.too_large, kMaxIslandBodies,
       st.too_large_first);
  note(r.detail, st.unsolved, "{} islands the programme did not solve, not judged (first: {})", st.unsolved,
       st.unsolved_first);
  note(r.detail, st.asleep, "{} islands with a sleeping body not judged", st.asleep);
  note(r.detail, st.locked, "{} islands with locked axes not judged", st.locked);
  note(r.detail, st.clamped, "{} islands with a body at the declared velocity clamp not judged", st.clamped);
  fill_causes(r, RowId::ImpulseFeasibility);
  return r;
}

}  // namespace octocd
