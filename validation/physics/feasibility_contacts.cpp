// The impulse-feasibility row's contact points (feasibility.hpp; docs/validation.md,
// "Motion explained by feasible contact impulses", 1): for one candidate pair, the points
// and normals octocd finds on the posed shapes (the separating-axis test's axes, the posed
// reference's, a patch's outline, the faces near its vertices, edge crossings on large
// hulls, and the normals a persistent manifold point carried on earlier steps).
#include "feasibility.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace octocd::feasibility {

using namespace dmath;
using namespace feasibility_geometry;
using physics_detail::kPi;

namespace {

/// The most separating axes a pair is given (its least translation's, then every axis
/// within the pair's reach of it, least overlap first).
constexpr std::size_t kMaxNormals = 6;
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
/// Edge crossings whose normals lie within this angle (deg) of each other are given one
/// normal (the first's), their outline kept.
constexpr double kCrossingGroupDeg = 0.5;
/// The widest angle between a vertex's own face normal and its pair's normal that the row
/// takes as a normal the engine may use there (cos 45 degrees).
constexpr double kFeatureCos = 0.70710678118654752;

/// The rotations of a pair's two bodies at the row's earlier poses, most recent first,
/// computed as far back as the walks of its points have gone.
struct PastRotations {
  std::vector<M3> a, b;
};

/// The normals a persistent manifold point at `pt` of pair p may carry from the earlier steps
/// (the row's past poses), beyond `nrm` (B to A): a point keeps the normal it was found with
/// while its two material points (pt on A and on B, carried back with each body's pose) stay
/// within `thr` (the pair's margin + slack) of each other along and across it (Bullet's breaking
/// threshold); the normal found then is `nrm` as it lay on A's or on B's earlier pose (the
/// face it belongs to turns with its body: `sides` bit 0 A, bit 1 B, both for an edge cross
/// or a normal of unknown origin). Walks back while a carried normal keeps the point;
/// appends those kept (kPersistSpacingDeg apart, the oldest kept) to `out`; `steps_back`
/// becomes at least the steps walked. With a finite `reuse_deg` (the trace's
/// `normal_reuse_deg`), a step's normal is kept only where the pair's relative rotation then
/// lies within reuse_deg of its rotation now (|q_now . q_then| >= cos(reuse_deg / 2) for the
/// relative quaternions conj(q_a) q_b: Jolt's own body-pair cache test), and the walk ends at
/// the first step beyond 2 reuse_deg (a manifold found at step m is reused while each later
/// step lies within reuse_deg of m's, so within 2 reuse_deg of one another).
void earlier_normals(const ContactSearch& search, const Pair& p, double thr, const D3& pt, const D3& nrm,
                     unsigned sides, double reuse_deg, std::vector<D3>& out, std::size_t& steps_back,
                     PastRotations& past) {
  const FeasibilityState& st = search.st;
  const std::vector<Pose>& det = search.det;
  if (st.past.empty() || !(reuse_deg > 0.0)) return;
  const bool bounded = std::isfinite(reuse_deg);
  const double keep_cos = std::cos(std::min(reuse_deg, 180.0) * kPi / 360.0);  // cos(reuse / 2)
  const double walk_cos = std::cos(std::min(reuse_deg, 180.0) * kPi / 180.0);  // cos(2 reuse / 2)
  const Quat rel_now = conjugate(det[p.a].orientation) * det[p.b].orientation;  // B relative to A
  const double spacing_cos = std::cos(kPersistSpacingDeg * kPi / 180.0);
  const M3 ra = rotation(det[p.a].orientation), rb = rotation(det[p.b].orientation);
  const D3 la = mul_t(ra, pt - d3(det[p.a].position)), lb = mul_t(rb, pt - d3(det[p.b].position));
  const std::array<D3, 2> local{mul_t(ra, nrm), mul_t(rb, nrm)};
  std::array<D3, 2> last{nrm, nrm}, pending{nrm, nrm};
  std::array<bool, 2> open{(sides & 1u) != 0, (sides & 2u) != 0};
  std::size_t k = 0;
  for (; k < st.past.size() && (open[0] || open[1]); ++k) {
    const Pose& qa = st.past[k][p.a];
    const Pose& qb = st.past[k][p.b];
    if (past.a.size() == k) {
      past.a.push_back(rotation(qa.orientation));
      past.b.push_back(rotation(qb.orientation));
    }
    bool keep = true;
    if (bounded) {
      const Quat rel = conjugate(qa.orientation) * qb.orientation;
      const double c = std::fabs(double(rel.w) * rel_now.w + double(rel.x) * rel_now.x + double(rel.y) * rel_now.y +
                                 double(rel.z) * rel_now.z);
      if (c < walk_cos) break;
      keep = c >= keep_cos;
    }
    const M3& pa = past.a[k];
    const M3& pb = past.b[k];
    const D3 d = (d3(qa.position) + mul(pa, la)) - (d3(qb.position) + mul(pb, lb));
    for (int side = 0; side < 2; ++side) {
      if (!open[side]) continue;
      const D3 nk = mul(side == 0 ? pa : pb, local[std::size_t(side)]);
      const double along = dot3(d, nk);
      if (along > thr || len3(d - along * nk) > thr) {
        open[side] = false;
        continue;
      }
      if (!keep) continue;
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
}

}  // namespace

}  // namespace octocd::feasibility

namespace octocd {

void PhysicsValidators::Impl::feasibility_contacts(const feasibility::ContactSearch& search, Pair p,
                                                   feasibility::PairContacts& found) const {
  using namespace feasibility;
  const std::vector<Pose>& det = search.det;
  const std::vector<Aabb>& world = search.world;
  const std::vector<double>& motion = search.motion;
  const double slack = tol.geometry_slack_m;
  const bool aabb_geometry = bodies.contact_geometry == ContactGeometry::Aabb;
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
    PastRotations past;
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
      earlier_normals(search, p, pair_margin(p) + slack, pt, normal, sides, bodies.normal_reuse_deg, earlier,
                      found.persisted_steps, past);
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
        const std::lock_guard<std::mutex> lock(search.hulls_mutex);  // found once per hull, by any thread
        auto it = search.st.hulls.find(&h);
        if (it == search.st.hulls.end()) it = search.st.hulls.emplace(&h, hull_edges_and_planes(h)).first;
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
        std::vector<Group> crossing_groups;
        const double group_cos = std::cos(kCrossingGroupDeg * kPi / 180.0);
        for (const Crossing& c : crossing) {
          Group* g = nullptr;
          for (Group& h : crossing_groups)
            if (h.sides == c.sides && dot3(h.normal, c.normal) >= group_cos) {
              g = &h;
              break;
            }
          if (!g) {
            crossing_groups.push_back({c.normal, c.sides, 0.0, {}});
            g = &crossing_groups.back();
          }
          g->lever = std::max(g->lever, c.lever);
          g->points.push_back(c.point);
        }
        for (const Group& g : crossing_groups) {
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
  // Two witness points per row (/contacts/point_b): the engine applied each of the pair's rows
  // at its point on A and its point_b on B; each row is a contact at those two points (no
  // lever beside them: they are the engine's own), along the normal found above nearest the
  // row's own.
  if (contacts.empty() || search.witness_rows.empty()) return;
  const auto [lo, hi] = std::equal_range(search.witness_rows.begin(), search.witness_rows.end(),
                                         std::pair<Pair, std::size_t>{p, 0}, [](const auto& x, const auto& y) {
                                           return x.first < y.first;
                                         });
  const std::size_t found_points = contacts.size();
  for (auto it = lo; it != hi; ++it) {
    const ContactRecord& row = search.rec.contacts[it->second];
    const D3 own = d3(row.normal);
    std::size_t nearest = 0;
    for (std::size_t k = 1; k < found_points; ++k)
      if (dot3(contacts[k].normal, own) > dot3(contacts[nearest].normal, own)) nearest = k;
    Contact c = contacts[nearest];
    c.point = d3(row.point);
    c.point_b = d3(search.rec.point_b[it->second]);
    c.lever = 0.0;
    contacts.push_back(c);
    ++found.witness;
  }
}

}  // namespace octocd
