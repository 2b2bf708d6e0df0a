// The physics tier's contact rows on checked frames (physics_impl.hpp): row 2, contact
// completeness (penetrating pairs need a contact; contacts need closeness), and row 3,
// contact geometry (normal angle, depth, points against SAT or FCL).
#include "physics_impl.hpp"

#include "../src/parallel.hpp"
#include "../src/row_clock.hpp"
#include "ordered_judge.hpp"

#include <algorithm>
#include <array>
#include <cmath>

#include "octocd/reference_contact.hpp"
#include "dmath.hpp"

namespace octocd {

namespace {
/// The fewest contact pairs whose rows 2 and 3 judge on the validators' threads
/// (judge_in_order): below them one thread costs less than waking another.
constexpr std::size_t kParallelGroupsFrom = 2048;

/// Row 3's own state that a block of pairs judged on a thread writes (judge_in_order): the
/// Impl's members of the same names, merged into it in block order.
struct GeometryDry {
  std::uint64_t sat_pairs = 0, fcl_pairs = 0, sat_fcl_other = 0, sat_fcl_disagree = 0, rows_unjudged = 0,
                upper_bound_pairs = 0, rounded_pairs = 0, sign_rows = 0, sign_agree = 0, resting_rows = 0,
                resting_wide = 0, speculative_rows = 0, sign_uncertain_rows = 0, aabb_angle_rows = 0,
                shape_angle_rows = 0, points_persistent = 0, depth_unknown_pairs = 0, depth_manifold_pairs = 0,
                depth_spared_as_manifold = 0;
  double sat_fcl_worst_excess = 0, sat_fcl_other_excess = 0, resting_worst = 0, speculative_worst = 0,
         aabb_angle_worst = 0;
  std::string sat_fcl_what;
  std::vector<double> shape_angles;
  /// Made on the judging thread with room for a block's rows (one a pair mostly): memory a
  /// worker allocated would return to its arena when freed here, and fault in again.
  GeometryDry() { shape_angles.reserve(physics_detail::kOrderedBlock); }
  /// A new largest FCL excess is described (sat_fcl_what): the block is judged again live.
  template <class Live>
  bool describes(const Live& s) const {
    return sat_fcl_worst_excess > s.sat_fcl_worst_excess;
  }
  template <class Live>
  void merge_into(Live& s) const {
    for (auto [to, from] : {std::pair{&s.sat_pairs, sat_pairs}, {&s.fcl_pairs, fcl_pairs},
                            {&s.sat_fcl_other, sat_fcl_other}, {&s.sat_fcl_disagree, sat_fcl_disagree},
                            {&s.rows_unjudged, rows_unjudged}, {&s.upper_bound_pairs, upper_bound_pairs},
                            {&s.rounded_pairs, rounded_pairs}, {&s.sign_rows, sign_rows}, {&s.sign_agree, sign_agree},
                            {&s.resting_rows, resting_rows}, {&s.resting_wide, resting_wide},
                            {&s.speculative_rows, speculative_rows}, {&s.sign_uncertain_rows, sign_uncertain_rows},
                            {&s.aabb_angle_rows, aabb_angle_rows}, {&s.shape_angle_rows, shape_angle_rows},
                            {&s.points_persistent, points_persistent}, {&s.depth_unknown_pairs, depth_unknown_pairs},
                            {&s.depth_manifold_pairs, depth_manifold_pairs},
                            {&s.depth_spared_as_manifold, depth_spared_as_manifold}})
      *to += from;
    // The largest figures: the serial loop's running maxima (each starts at 0).
    for (auto [to, from] : {std::pair{&s.sat_fcl_other_excess, sat_fcl_other_excess},
                            {&s.resting_worst, resting_worst}, {&s.speculative_worst, speculative_worst},
                            {&s.aabb_angle_worst, aabb_angle_worst}})
      *to = std::max(*to, from);
    for (double a : shape_angles) s.shape_angles.push_back(a);
  }
};

/// Row 2's own state that a block of pairs judged on a thread writes (judge_in_order).
struct CompletenessDry {
  std::uint64_t complete_asleep = 0, complete_declared = 0, complete_unproven = 0, speculative_allowed = 0;
  double complete_unproven_worst = 0;
  std::string complete_unproven_what;
  /// A new largest unproven bound is described (complete_unproven_what): judged again live.
  template <class Live>
  bool describes(const Live& s) const {
    return complete_unproven_worst > s.complete_unproven_worst;
  }
  template <class Live>
  void merge_into(Live& s) const {
    s.complete_asleep += complete_asleep;
    s.complete_declared += complete_declared;
    s.complete_unproven += complete_unproven;
    s.speculative_allowed += speculative_allowed;
  }
};

/// What a row's normal was compared with where SAT judges the pair: the nearest of its
/// accepted axes (those within `epsilon` m of the minimum translation `depth`), or the
/// minimum translation itself when SAT kept no axis (row_reference).
std::string sat_axes_text(std::uint32_t accepted, double epsilon, double depth) {
  if (accepted == 0) return fmt::format("minimum translation {:.4g} m", depth);
  if (accepted == 1)
    return fmt::format("minimum translation {:.4g} m, the only axis within {:.3g} m of it", depth, epsilon);
  return fmt::format("the nearest of {} axes within {:.3g} m of the minimum translation {:.4g} m", accepted, epsilon,
                     depth);
}
}  // namespace

void PhysicsValidators::Impl::AngleSample::push_back(double deg) {
  constexpr std::size_t n = static_cast<std::size_t>(180.0 / kBinDeg) + 1;
  if (bins.empty()) bins.assign(n, 0);
  const double k = deg / kBinDeg;
  bins[k >= 0 ? (k < double(n - 1) ? static_cast<std::size_t>(k) : n - 1) : 0] += 1;
  ++count;
  sum += deg;
  max = std::max(max, deg);
}

double PhysicsValidators::Impl::AngleSample::at(std::uint64_t r) const {
  std::uint64_t seen = 0;
  for (std::size_t k = 0; k < bins.size(); ++k) {
    seen += bins[k];
    if (r < seen) return std::min(max, (double(k) + 0.5) * kBinDeg);
  }
  return max;
}

namespace {

/// A unit normal points against a direction when their cosine is below -kAgainstCos: a
/// normal perpendicular to the direction pushes the bodies neither together nor apart, and
/// its cosine reads a few rounding steps off 0 (Bullet's axis normals on boxes 2.3 mm
/// apart along another axis, boxes-uniform-10k: 90.0000000000018 deg).
constexpr double kAgainstCos = 1e-6;

/// Whether the unit normal n points against the unit direction u (kAgainstCos).
bool points_against(Vec3 n, Vec3 u) {
  return static_cast<double>(n.x) * u.x + static_cast<double>(n.y) * u.y + static_cast<double>(n.z) * u.z <
         -kAgainstCos;
}

/// The separation (m) of convex hull A from hull B along the unit world axis u (from B
/// towards A): min over A's vertices of u.a minus max over B's of u.b, at poses pa, pb.
/// Positive: u separates the hulls by that much (a certificate that they are apart along
/// it, whatever the query that found u).
double hull_separation(const HullFeatures& a, const Pose& pa, const HullFeatures& b, const Pose& pb, Vec3 u) {
  const dmath::D3 ud = dmath::d3(u);
  auto extreme = [&](const HullFeatures& h, const Pose& pose, double sign) {
    const dmath::M3 r = dmath::rotation(pose.orientation);
    const dmath::D3 x = dmath::d3(pose.position);
    double best = -HUGE_VAL;
    for (const auto& v : h.vertices) best = std::max(best, sign * dmath::dot3(ud, dmath::operator+(dmath::mul(r, v), x)));
    return best;
  };
  return -extreme(a, pa, -1.0) - extreme(b, pb, 1.0);
}

}  // namespace

using namespace dmath;
using namespace physics_detail;

double PhysicsValidators::Impl::speculative_reach(const FrameRecord& rec, Pair p) const {
  const std::size_t n = model->bodies.size();
  if (rec.v_pre.size() != n || rec.v_post.size() != n) return std::numeric_limits<double>::infinity();
  const bool spin = rec.w_pre.size() == n && rec.w_post.size() == n;
  auto reach = [&](std::uint32_t i) {
    // The farthest point of the local box from the origin, rounded by the convex radius;
    // from the centre of mass (the states' point) up to |com_offset| farther.
    const Aabb& b = model->local_box(i);
    return len3(D3{std::max(std::fabs(double(b.min.x)), std::fabs(double(b.max.x))),
                   std::max(std::fabs(double(b.min.y)), std::fabs(double(b.max.y))),
                   std::max(std::fabs(double(b.min.z)), std::fabs(double(b.max.z)))}) +
           extra_reach(i);
  };
  const double v = std::max(len3(d3(rec.v_pre[p.a]) - d3(rec.v_pre[p.b])), len3(d3(rec.v_post[p.a]) - d3(rec.v_post[p.b])));
  const double w = spin ? std::max(len3(d3(rec.w_pre[p.a])), len3(d3(rec.w_post[p.a]))) * reach(p.a) +
                              std::max(len3(d3(rec.w_pre[p.b])), len3(d3(rec.w_post[p.b]))) * reach(p.b)
                        : 0.0;
  return model->scene.dt * (v + w);
}

// ---- Row 2: contact completeness -----------------------------------------------------
// Judged on the CPU's reference normals and separating axes; with a judge device, of the
// device's candidates (checked()): the CPU's candidate search is skipped.
template <>
bool PhysicsValidators::Impl::judge_device<RowId::ContactCompleteness>(DeviceCheckedFrame&) {
  return false;
}

template <>
void PhysicsValidators::Impl::judge<RowId::ContactCompleteness>(CheckedFrame& f) {
  const std::array<Tally*, 1> missing{&tally(RowId::ContactCompleteness, "missing-contact")};
  const std::array<Tally*, 1> false_contacts{&tally(RowId::ContactCompleteness, "false-contact")};
  const std::int64_t frame = f.rec->frame;
  const double slack = tol.geometry_slack_m;
  // 2. Contact completeness: penetrating pairs need a contact; contacts need closeness.
  // The candidates, the truth's pairs and the contact pairs are sorted: each candidate's
  // truth and whether it has rows are looked up onwards from the last answer (seek). Both
  // loops judge on the threads and tally in order (judge_in_order).
  const std::vector<Pair>& cand = f.cand;
  const std::size_t none = f.truth.size();
  auto judge_candidates = [&](std::size_t first, std::size_t last, auto& s, auto& complete) {
    std::size_t truth_cursor = 0, contact_cursor = 0;
    for (std::size_t i = first; i < last; ++i) {
      const Pair p = cand[i];
      const std::size_t t = f.find_after(p, truth_cursor);
      if (t == none || !f.truth[t].have || !f.truth[t].g.penetrating || !(f.truth[t].g.depth > tol.contact_depth_m))
        continue;
      const std::size_t c = seek(f.contact_pairs, p, contact_cursor);
      const bool found = c < f.contact_pairs.size() && f.contact_pairs[c] == p;
      if (!found && pair_asleep(*f.rec, p)) {  // engines do not collide sleeping bodies
        ++s.complete_asleep;
        continue;
      }
      if (!found && incomplete_pair(frame, p)) {  // /contacts/incomplete: its rows may be missing here
        ++s.complete_declared;
        continue;
      }
      const ReferenceNormal& g = f.truth[t].g;
      if (!found && g.depth_upper_bound) {
        // A non-convex pair: its depth is only an upper bound. The row fails where an exact
        // test proves a penetration deeper than contact_depth_m (a vertex of one shape that
        // deep inside the other: FCL's BVH collide and the mesh's winding number); an upper
        // bound alone is n/a.
        const std::vector<Pose>& det = *f.det;
        const PenetrationWitness w = ref->penetration_witness(p.a, p.b, det[p.a], det[p.b], tol.contact_depth_m);
        if (!(w.depth > tol.contact_depth_m)) {
          ++s.complete_unproven;
          if (g.depth > s.complete_unproven_worst) {
            s.complete_unproven_worst = g.depth;
            s.complete_unproven_what = fmt::format(
                "frame {}: {} (upper bound {:.4g} m; {})", frame, pair_name(p), g.depth,
                !w.intersect ? std::string("FCL's BVH collide finds no intersection")
                : w.vertex < 0 ? std::string("no vertex of either shape lies deeper than contact_depth_m in the other")
                               : fmt::format("the deepest vertex inside the other shape lies {:.4g} m deep", w.depth));
          }
          continue;
        }
        complete.check(false, w.depth, Where{frame, p}, [&] {
          const std::uint32_t other = w.vertex_body == p.a ? p.b : p.a;
          return fmt::format("frame {}: {} penetrates by at least {:.4g} m and has no contact: vertex {} of body {} at "
                             "({:.4f}, {:.4f}, {:.4f}) lies {:.4g} m inside body {}; triangles ({}, {}) intersect "
                             "[exact: FCL BVH collide on the posed meshes; the minimum translation is at most {:.4g} m]",
                             frame, pair_name(p), w.depth, w.vertex, w.vertex_body, w.vertex_point.x,
                             w.vertex_point.y, w.vertex_point.z, w.depth, other, w.triangle_a, w.triangle_b, g.depth);
        });
        continue;
      }
      complete.check(found, g.depth, Where{frame, p}, [&] {
        return fmt::format("frame {}: {} penetrates by {:.4g} m and has no contact", frame, pair_name(p), g.depth);
      });
    }
  };
  judge_in_order<CompletenessDry>(cand.size(), threads, kParallelGroupsFrom, stop, *this, missing, judge_candidates);
  // Every contact pair is among the truth's pairs (checked_frame: their union), so
  // truth_after only reads here.
  const std::vector<Pair>& pairs = f.contact_pairs;
  auto judge_contacts = [&](std::size_t first, std::size_t last, auto& s, auto& false_contact) {
    std::size_t truth_cursor = 0;
    for (std::size_t i = first; i < last; ++i) {
      const Pair p = pairs[i];
      const ReferenceNormal& g = truth_after(f, p, truth_cursor).g;
      const double reach = bodies.speculative ? speculative_reach(*f.rec, p) : 0.0;
      if (!std::isfinite(reach)) continue;  // speculative without states: not judged
      if (reach > 0) ++s.speculative_allowed;
      const double bound = pair_margin(p) + slack + reach;
      const double d = g.signed_distance();
      false_contact.check(d <= bound, d - bound, Where{frame, p}, [&] {
        return fmt::format("frame {}: false contact on {}: shapes {:.4g} m apart (margin {:.4g} m)", frame,
                           pair_name(p), d, pair_margin(p));
      });
    }
  };
  judge_in_order<CompletenessDry>(pairs.size(), threads, kParallelGroupsFrom, stop, *this, false_contacts,
                                  judge_contacts);
}

// ---- Row 3: contact geometry -------------------------------------------------------
void PhysicsValidators::Impl::pair_figures(CheckedFrame& f, std::size_t i, const ContactTruth& t,
                                           const std::vector<SatAxis>& accepted) const {
  // The figures of group i (the reference a pair is judged on, each row's reference normal
  // and angle, its point's distance to both surfaces, FCL's angle to SAT's axes): each
  // group writes its own slots.
  const FrameRecord& rec = *f.rec;
  const std::vector<Pose>& det = *f.det;
  const bool aabb = bodies.contact_geometry == ContactGeometry::Aabb;
  const PairRows& pr = f.rows[i];
  const Pair p = pr.p;
  const bool by_sat = !aabb && t.sat;
  PairFigures& pf = f.pair_fig[i];
  pf.done = true;
  if (by_sat) {
    pf.fcl_angle = sat_angle_to_accepted(accepted, d3(t.fcl_normal)) * 180.0 / kPi;
    pf.fcl_minimum = angle_between(t.fcl_normal, t.g.normal) * 180.0 / kPi;
  }
  if (aabb) f.aabb_ref[i] = ReferenceGeometry::aabb_pair(rec.aabbs[p.a], rec.aabbs[p.b]);
  const ReferenceNormal& r = aabb ? f.aabb_ref[i] : t.g;
  if (!r.valid) return;
  for (std::size_t k = pr.first; k < pr.first + pr.count; ++k) {
    const ContactRecord& c = rec.contacts[k];
    RowFigures& rf = f.row_fig[k];
    rf.ref = row_reference(accepted, r, by_sat, c.normal);
    if (rec.has_points) {
      // A rounded shape's surface lies its convex radius beyond the posed one: a point
      // outside the posed shape is |d - r| from it, one inside (d unsigned) at least
      // max(0, d - r), taken for both (never stricter than the rounded surface).
      rf.da = std::max(0.0, ref->surface_distance(p.a, det[p.a], c.point) - radius(p.a));
      rf.db = std::max(0.0, ref->surface_distance(p.b, det[p.b], c.point) - radius(p.b));
      if (rec.point_b.size() == rec.contacts.size()) {  // the row's point on B: the same measure
        rf.da_b = std::max(0.0, ref->surface_distance(p.a, det[p.a], rec.point_b[k]) - radius(p.a));
        rf.db_b = std::max(0.0, ref->surface_distance(p.b, det[p.b], rec.point_b[k]) - radius(p.b));
      }
    }
  }
}

// Judged on the CPU's reference normals, separating axes and surfaces, as row 2.
template <>
bool PhysicsValidators::Impl::judge_device<RowId::ContactGeometry>(DeviceCheckedFrame&) {
  return false;
}

template <>
void PhysicsValidators::Impl::judge<RowId::ContactGeometry>(CheckedFrame& f) {
  const std::array<Tally*, 3> row_tallies{&tally(RowId::ContactGeometry, "normal-angle"),
                                          &tally(RowId::ContactGeometry, "depth"),
                                          &tally(RowId::ContactGeometry, "point-off-shape")};
  const FrameRecord& rec = *f.rec;
  const std::vector<Pose>& det = *f.det;
  const std::int64_t frame = rec.frame;
  // 3. Contact geometry, per row: normal angle, the pair's deepest row's depth, points.
  // The figures come from the truth's pass (pair_figures); the groups are judged on the
  // threads and tallied in record order (judge_in_order), so the verdict, causes and
  // examples are those of a serial run.
  const double deg = 180.0 / kPi;
  const bool aabb = bodies.contact_geometry == ContactGeometry::Aabb;
  // Each group's truth: its entry found in the truth's pass (CheckedFrame::Work::group_truth).
  std::vector<const ContactTruth*> truth_of(f.rows.size());
  for (std::size_t i = 0; i < f.rows.size(); ++i) {
    const std::size_t t = f.work.group_truth[i];
    truth_of[i] = t < f.truth.size() ? &f.truth[t] : &full_truth(f, f.rows[i].p);
    if (!f.pair_fig[i].done) {
      // A pair outside the truth's table (none by construction): its figures now.
      PairReferenceScratch scratch;
      pair_reference_into(*ref, f.rows[i].p.a, f.rows[i].p.b, det[f.rows[i].p.a], det[f.rows[i].p.b], sat_settings,
                          scratch);
      pair_figures(f, i, *truth_of[i], scratch.accepted);
    }
  }
  const FrameArray<PairFigures>& pair_fig = f.pair_fig;
  const FrameArray<RowFigures>& row_fig = f.row_fig;
  // Groups [first, last) into `s` (this Impl, or a block's GeometryDry) and the tallies.
  auto judge_groups = [&](std::size_t first, std::size_t last, auto& s, auto& normal_angle, auto& depth,
                          auto& points) {
    for (std::size_t i = first; i < last; ++i) {
      const PairRows& pr = f.rows[i];
      const Pair p = pr.p;
      const ContactTruth& shape_truth = *truth_of[i];
      const ReferenceNormal& shape_ref = shape_truth.g;
      // The reference that judges this pair: the separating-axis test (every near-minimal
      // axis accepted) or the posed reference (box-box for two boxes; FCL's EPA, distance or
      // the BVH bound of non-convex meshes).
      const bool by_sat = !aabb && shape_truth.sat;
      const char* judge = by_sat ? "SAT" : "FCL";
      if (by_sat) {
        ++s.sat_pairs;
        // The second opinion: FCL's normal outside SAT's accepted axes is a figure.
        const double fcl_angle = pair_fig[i].fcl_angle;
        const double fcl_excess = shape_truth.fcl_depth - shape_truth.g.depth;
        if (pair_fig[i].fcl_minimum > 1.0) {
          ++s.sat_fcl_other;
          if (fcl_excess > s.sat_fcl_other_excess) s.sat_fcl_other_excess = fcl_excess;
        }
        if (fcl_angle > 1.0) {
          ++s.sat_fcl_disagree;
          if (fcl_excess > s.sat_fcl_worst_excess) {
            s.sat_fcl_worst_excess = fcl_excess;
            s.sat_fcl_what = fmt::format("frame {}: {} FCL {:.4g} m along ({:.3f}, {:.3f}, {:.3f}), {:.1f} deg from "
                                       "SAT's accepted axes, minimum {:.4g} m",
                                       frame, pair_name(p), shape_truth.fcl_depth, shape_truth.fcl_normal.x,
                                       shape_truth.fcl_normal.y, shape_truth.fcl_normal.z, fcl_angle,
                                       shape_truth.g.depth);
          }
        }
      } else if (!aabb) {
        ++s.fcl_pairs;
      }
      const ReferenceNormal& r = aabb ? f.aabb_ref[i] : shape_ref;
      if (!r.valid) {
        s.rows_unjudged += pr.count;
        continue;
      }
      if (r.depth_upper_bound) ++s.upper_bound_pairs;
      if (inflation(p) > 0) ++s.rounded_pairs;
      std::size_t deepest = pr.first;
      for (std::size_t k = pr.first; k < pr.first + pr.count; ++k)
        if (rec.contacts[k].depth > rec.contacts[deepest].depth) deepest = k;
      // The engine places the pair's penetration in some rows of its manifold: a row of
      // depth 0 (or within geometry_slack_m) beside a deeper one is a point the manifold
      // keeps at or out of contact (a persistent manifold keeps a point, with the normal it
      // was found with, while the bodies turn, until it drifts beyond the breaking
      // threshold: Bullet on rot-pile-1000 kept a row 73 deg off for a cube pair that
      // penetrated 0.05 mm at another row, and one 41.5 deg off at depth 4.8e-6 m beside a
      // fresh row of 0.53 mm on the minimum translation).
      // depth_per "unknown": no row's depth says where the engine placed the penetration.
      const bool depth_known = !bodies.depth_unknown;
      const bool engine_places_depth = depth_known && rec.contacts[deepest].depth > tol.geometry_slack_m;
      for (std::size_t k = pr.first; k < pr.first + pr.count; ++k) {
        const ContactRecord& c = rec.contacts[k];
        const RowReference& row_ref = row_fig[k].ref;
        const double angle = row_ref.angle * deg;
        const Vec3 ref_normal = row_ref.normal;
        ++s.sign_rows;
        if (dot(c.normal, r.normal) > 0.0f) ++s.sign_agree;
        // A resting row: the engine places it at depth 0 (or gives no depth) on a pair that
        // penetrates by no more than contact_depth_m (a pair that needs no contact at all,
        // item 2), or beside a deeper row of its manifold, or its shapes touch within
        // geometry_slack_m: a loaded resting contact as much as a touching one.
        const bool touching = (!depth_known || c.depth <= 0.0f) && r.depth <= tol.contact_depth_m;
        const bool resting = !r.penetrating || r.depth <= tol.geometry_slack_m || touching ||
                             (engine_places_depth && c.depth <= tol.geometry_slack_m);
        // Whatever the row's depth, its normal is judged where the posed shapes' separating
        // direction is exact: SAT's accepted axes on two convex polytopes that penetrate or
        // touch (every axis within SAT's epsilon of the minimum translation: the face normal
        // of a face contact, each candidate of an edge or corner contact), and box-box on the
        // world AABBs (aabb: its sign). FCL's answer on shapes that touch is no such
        // direction: a non-convex pair's depth is an upper bound along the direction that
        // gave it, and GJK's nearest points of shapes within tens of micrometres point
        // either way.
        const bool exact_direction = r.penetrating && (by_sat || aabb);
        double judged_angle = angle;
        Vec3 judged_normal = ref_normal;
        if (resting && exact_direction) {
          ++s.resting_rows;
          if (!aabb && angle > tol.normal_angle_deg && r.depth < tol.contact_depth_m) {
            // Two shapes that touch are in contact along every axis on which they overlap by
            // no more than contact_depth_m (the depth that needs no contact): the row's normal
            // itself (any direction between the faces of an edge that rests on an edge), or
            // the nearest SAT axis that overlaps that little (two boxes grazing edge on edge:
            // a detector may keep a face normal far from the edge-edge minimum translation).
            const double along = inflation(p) - hull_separation(ref->hull_features(p.a), det[p.a],
                                                                ref->hull_features(p.b), det[p.b], c.normal);
            double a = 0.0;
            Vec3 axis = c.normal;
            if (along > tol.contact_depth_m) {
              SatSettings wide = sat_settings;
              wide.abs_m = std::max(sat_settings.abs_m, tol.contact_depth_m - r.depth);
              const SatResult touch = sat_min_translation(ref->hull_features(p.a), det[p.a], ref->hull_features(p.b),
                                                          det[p.b], wide);
              std::size_t nearest = 0;
              a = touch.tested ? sat_angle_to_accepted(touch, d3(c.normal), &nearest) * deg : 180.0;
              if (touch.tested && !touch.accepted.empty()) {
                const auto& u = touch.accepted[nearest].normal;
                axis = Vec3{float(u[0]), float(u[1]), float(u[2])};
              }
            }
            if (a < judged_angle) {
              ++s.resting_wide;
              judged_angle = a;
              judged_normal = axis;
            }
          }
        }
        if (resting && !exact_direction) {
          // A row on shapes that do not penetrate (or touch without an exact direction,
          // above): the nearest-points direction of two shapes that (nearly) touch at an
          // edge or a corner is no contact normal, and a persistent manifold (Bullet) keeps
          // the normal a point was found with while the bodies turn. Its angle is a figure;
          // the normal is judged where the shapes penetrate or touch (SAT's accepted axes,
          // which a correct engine's normal follows).
          ++s.speculative_rows;
          s.speculative_worst = std::max(s.speculative_worst, angle);
          // Its sign is judged where the shapes are apart (design.md section 13c.2): the
          // engine claims the normal, and one pointing against the separation direction (the
          // nearest points, from B to A: SAT's axis or FCL's distance query) would push the
          // bodies into each other, whatever the row's depth or impulse.
          // The direction is judged where it is certain: for two convex hulls the hulls must
          // be apart along it (hull_separation > slack); FCL's GJK nearest points of hulls
          // that touch within tens of micrometres may point either way (Bullet
          // bunny-stack-50: FCL 3.2e-5 m apart along the reverse of the axis they were
          // 1.4e-4 m apart along two frames before).
          const bool certain =
              !r.penetrating && r.distance > tol.geometry_slack_m &&
              (!ref->convex(p.a) || !ref->convex(p.b) ||
               hull_separation(ref->hull_features(p.a), det[p.a], ref->hull_features(p.b), det[p.b], r.normal) -
                       inflation(p) >
                   tol.geometry_slack_m);
          if (!r.penetrating && r.distance > tol.geometry_slack_m && !certain) ++s.sign_uncertain_rows;
          if (certain) {
            normal_angle.check(!points_against(c.normal, ref_normal), angle, Where{frame, p}, [&] {
              return fmt::format("frame {}: {} row {}: normal ({:.3f}, {:.3f}, {:.3f}) points against the separation "
                                 "direction ({:.3f}, {:.3f}, {:.3f}) of shapes {:.4g} m apart: {:.1f} deg (a row on "
                                 "shapes that do not penetrate is judged by its sign)",
                                 frame, pair_name(p), k - pr.first, c.normal.x, c.normal.y, c.normal.z, ref_normal.x,
                                 ref_normal.y, ref_normal.z, r.distance, angle);
            });
          }
        } else if (aabb) {
          // The engine's normal is an axis of the two world AABBs (Eq. 10): compared with
          // box-box on the same boxes its angle says nothing about the shapes (a
          // figure; the angle to the posed shapes is the other figure, below). Its sign is
          // judged: a normal pointing from A to B pushes the bodies into each other.
          ++s.aabb_angle_rows;
          s.aabb_angle_worst = std::max(s.aabb_angle_worst, angle);
          normal_angle.check(!points_against(c.normal, ref_normal), angle, Where{frame, p}, [&] {
            return fmt::format("frame {}: {} row {}: normal ({:.3f}, {:.3f}, {:.3f}) points against the world AABBs' "
                               "minimum translation ({:.3f}, {:.3f}, {:.3f}): {:.1f} deg (sign judged only: the engine "
                               "resolves on world AABBs)",
                               frame, pair_name(p), k - pr.first, c.normal.x, c.normal.y, c.normal.z, r.normal.x,
                               r.normal.y, r.normal.z, angle);
          });
        } else {
          if (resting) s.resting_worst = std::max(s.resting_worst, judged_angle);
          normal_angle.check(judged_angle <= tol.normal_angle_deg, judged_angle, Where{frame, p}, [&] {
            return fmt::format("frame {}: {} row {}: normal ({:.3f}, {:.3f}, {:.3f}) is {:.1f} deg from {}'s "
                               "({:.3f}, {:.3f}, {:.3f}) ({}){}{}",
                               frame, pair_name(p), k - pr.first, c.normal.x, c.normal.y, c.normal.z, judged_angle,
                               judge, judged_normal.x, judged_normal.y, judged_normal.z,
                               by_sat ? sat_axes_text(shape_truth.sat_accepted, shape_truth.sat_epsilon, r.depth)
                                      : std::string("minimum translation"),
                               resting ? fmt::format("; a resting row: depth {:.4g} m{}, judged whatever its depth",
                                                     c.depth, depth_known ? "" : " (depth_per \"unknown\")")
                                       : std::string(),
                               by_sat ? " [reference: SAT]" : " [reference: FCL]");
          });
        }
        if (aabb && shape_ref.valid) {
          ++s.shape_angle_rows;
          s.shape_angles.push_back(angle_between(c.normal, shape_ref.normal) * deg);
        }
        if (rec.has_points) {
          // A row's point lies on one of the two surfaces (a witness point), or between
          // them (a midpoint: within the pair's depth or distance of each, since any point
          // of the intersection is within the depth of both surfaces; a persistent
          // manifold's row may be up to the contact margin apart, its midpoint half of it
          // from each). So the nearer surface is at most that far.
          // Both surfaces: a point is where the two bodies meet, so it lies within the
          // pair's depth or distance (or the contact margin, for a persistent manifold's
          // row) of each; a point placed with a wrong orientation leaves at least one.
          const double reach_p = std::max(
              {r.penetrating ? r.depth : r.distance, depth_known ? double(c.depth) : 0.0, pair_margin(p)});
          const double da = row_fig[k].da, db = row_fig[k].db;
          const double off = std::max(da, db) - reach_p;
          if (bodies.persistent_points) {  // manifold_points "persistent": may drift off the shapes
            ++s.points_persistent;
            continue;
          }
          points.check(off <= tol.depth_m, off, Where{frame, p}, [&] {
            return fmt::format("frame {}: {} row {}: point ({:.4f}, {:.4f}, {:.4f}) is {:.4g} m from body {} "
                               "and {:.4g} m from body {} (depth or distance {:.4g} m)",
                               frame, pair_name(p), k - pr.first, c.point.x, c.point.y, c.point.z, da, p.a, db, p.b,
                               reach_p);
          });
          if (rec.point_b.size() == rec.contacts.size()) {
            // The row's point on B (/contacts/point_b): judged as its point, on both surfaces.
            const Vec3 pb = rec.point_b[k];
            const double da_b = row_fig[k].da_b, db_b = row_fig[k].db_b;
            const double off_b = std::max(da_b, db_b) - reach_p;
            points.check(off_b <= tol.depth_m, off_b, Where{frame, p}, [&] {
              return fmt::format("frame {}: {} row {}: point_b ({:.4f}, {:.4f}, {:.4f}) is {:.4g} m from body {} "
                                 "and {:.4g} m from body {} (depth or distance {:.4g} m)",
                                 frame, pair_name(p), k - pr.first, pb.x, pb.y, pb.z, da_b, p.a, db_b, p.b, reach_p);
            });
          }
        }
      }
      if (!depth_known) {  // depth_per "unknown": the depth cause is n/a (counted)
        ++s.depth_unknown_pairs;
        continue;
      }
      const ContactRecord& c = rec.contacts[deepest];
      double want = r.penetrating ? r.depth : 0.0;
      const char* want_what = by_sat ? "SAT minimum" : "FCL";
      // The deepest point of the shapes' overlap along the deepest row's normal n: the
      // translation of A along n that separates them (sat_depth_along: >= the minimum
      // translation, equal where n is the minimum's, d / cos of the angle across the same
      // face; the hulls' overlap projected on n would read the far side of a large face
      // instead: a 6 m floor under a normal 1 degree off adds 5 cm). depth_per "manifold" is
      // judged on it, and an undeclared depth_per admits it beside the minimum ("point").
      auto along_normal = [&] {
        const SatAlong along = sat_depth_along(ref->hull_features(p.a), det[p.a], ref->hull_features(p.b), det[p.b],
                                               d3(c.normal), inflation(p), sat_settings);
        if (along.tested) return along.depth;
        // No axis across n (none by construction where SAT judged the pair): the hulls'
        // overlap projected on n, an upper bound of the translation along it.
        return std::max(0.0, inflation(p) - hull_separation(ref->hull_features(p.a), det[p.a], ref->hull_features(p.b),
                                                            det[p.b], c.normal));
      };
      if (bodies.depth_per_manifold && by_sat && r.penetrating) {
        want = along_normal();
        want_what = "the deepest point of the overlap along the manifold's normal";
        ++s.depth_manifold_pairs;
      } else if (!bodies.depth_per_declared && by_sat && r.penetrating && !r.depth_upper_bound &&
                 std::fabs(double(c.depth) - want) > tol.depth_m) {
        const double along = along_normal();
        if (std::fabs(double(c.depth) - along) <= tol.depth_m) ++s.depth_spared_as_manifold;
        if (std::fabs(double(c.depth) - along) < std::fabs(double(c.depth) - want)) {
          want = along;
          want_what = "the deepest point of the overlap along the row's normal (depth_per undeclared: nearer than SAT's "
                      "minimum)";
        }
      }
      // An upper bound (non-convex meshes) judges one side only: the engine may be shallower.
      const double diff = r.depth_upper_bound ? double(c.depth) - want : std::fabs(double(c.depth) - want);
      depth.check(diff <= tol.depth_m, diff, Where{frame, p}, [&] {
        return fmt::format("frame {}: {} {} depth {:.4g} m, {} {:.4g} m{} [reference: {}]", frame, pair_name(p),
                           bodies.depth_per_manifold ? "manifold" : "deepest row", c.depth, want_what, want,
                           r.depth_upper_bound ? " (upper bound)" : "", judge);
      });
    }
  };
  judge_in_order<GeometryDry>(f.rows.size(), threads, kParallelGroupsFrom, stop, *this, row_tallies, judge_groups);
}

// ---- contact-completeness: its table entry -------------------------

template <>
ValidationResult PhysicsValidators::Impl::table<RowId::ContactCompleteness>() const {
  const Impl& s = *this;
  auto [complete, false_contact] = s.tallies(RowId::ContactCompleteness, "missing-contact", "false-contact");
  ValidationResult r = failures_row(RowId::ContactCompleteness, "penetrating pairs without a contact + false contacts",
                                    "contact_depth_m,geometry_slack_m");
  r.applicable = s.checked_frames > 0 && (complete.checks + false_contact.checks) > 0;
  const std::string margin =
      s.bodies.theta_margin ? std::string("the pair's theta") : fmt::format("{} m", s.bodies.contact_margin);
  if (complete.failures) {
    r.detail = complete.first + fmt::format(" ({} such pairs)", complete.failures);
  } else if (false_contact.failures) {
    r.detail = false_contact.first + fmt::format(" ({} false contacts)", false_contact.failures);
  } else if (!r.applicable) {
    r.detail = s.checked_frames ? "no pair penetrated deeper than contact_depth_m and no contact" : kNoChecked;
  } else {
    r.detail = fmt::format(
        "{} penetrating pairs all with contacts; {} contact pairs all within {} (farthest "
        "{:.3g} m beyond it)",
        complete.checks, false_contact.checks, margin, false_contact.worst_or(0.0));
  }
  note(r.detail, s.bodies.speculative,
       "speculative contacts declared: {} contact pair-frames allowed the pair's approach "
       "within the step beyond the margin",
       s.speculative_allowed);
  note(r.detail, s.complete_asleep,
       "{} penetrating pair-frames of bodies asleep before the step (/states/sleeping) "
       "without a row, not required",
       s.complete_asleep);
  note(r.detail, s.complete_declared && s.bodies.contacts_complete,
       "{} penetrating pair-frames without a row on the steps or pairs /contacts/incomplete declares, not required",
       s.complete_declared);
  note(r.detail, s.complete_unproven,
       "{} non-convex pair-frames without a row penetrate by an upper bound above "
       "contact_depth_m that no vertex inside the other shape proves, n/a (largest: {})",
       s.complete_unproven, s.complete_unproven_what);
  note(r.detail, s.device_cpu_geometry_frames,
       "candidates of {} checked frames from the device ({}); the reference geometry of rows 2 and 3 on the CPU",
       s.device_cpu_geometry_frames, s.device ? s.device->device_name() : std::string());
  if (r.applicable) s.fill_causes(r, RowId::ContactCompleteness);
  return r;
}

// ---- contact-geometry: its table entry -------------------------

template <>
ValidationResult PhysicsValidators::Impl::table<RowId::ContactGeometry>() const {
  const Impl& s = *this;
  auto [normal_angle, depth, points] = s.tallies(RowId::ContactGeometry, "normal-angle", "depth", "point-off-shape");
  ValidationResult r = start_row(RowId::ContactGeometry, "worst normal angle to the reference's (deg; SAT or FCL)",
                                 "normal_angle_deg,depth_m,sat_accept_rel");
  r.measured = normal_angle.worst_or(0.0);
  r.bound = s.tol.normal_angle_deg;
  r.pass = normal_angle.failures == 0 && depth.failures == 0 && points.failures == 0;
  r.applicable = normal_angle.checks + depth.checks + points.checks > 0;
  const bool aabb = s.bodies.contact_geometry == ContactGeometry::Aabb;
  if (aabb) {
    r.figure = "worst normal angle to box-box on the world AABBs (deg; its sign judged)";
    r.bound = 90.0;
  }
  std::string stats;
  if (aabb && !s.shape_angles.empty()) {
    const AngleSample& a = s.shape_angles;
    stats = fmt::format(
        "; against the posed shapes (figure, not judged: the engine resolves on world AABBs): "
        "mean {:.1f} deg, median {:.1f}, p95 {:.1f}, max {:.1f}",
        a.sum / double(a.count), a.at(a.count / 2), a.at(a.count * 95 / 100), a.max);
  }
  const std::string sign = fmt::format("sign agreement {:.4f} of {} rows",
                                       s.sign_rows ? double(s.sign_agree) / double(s.sign_rows) : 1.0, s.sign_rows);
  if (!r.applicable) {
    r.detail = s.checked_frames ? "no contact rows on checked frames" : kNoChecked;
  } else if (normal_angle.failures) {
    r.detail = normal_angle.worst_what + fmt::format(" ({} of {} rows beyond {} deg; {})", normal_angle.failures,
                                                     normal_angle.checks, aabb ? 90.0 : s.tol.normal_angle_deg, sign);
    if (s.sign_rows > 0 && 2 * s.sign_agree < s.sign_rows)
      r.detail += "; most normals point from A to B: the convention is from B to A (design.md section 2)";
  } else if (depth.failures) {
    r.detail = depth.worst_what + fmt::format(" (depth off by more than {} m on {} of {} pairs)", s.tol.depth_m,
                                              depth.failures, depth.checks);
  } else if (points.failures) {
    r.detail = points.worst_what + fmt::format(" (points off the shapes by more than {} m on {} of {} rows)",
                                               s.tol.depth_m, points.failures, points.checks);
  } else if (aabb) {
    r.detail = fmt::format(
        "normal angle n/a: the engine resolves contacts on world AABBs (its normal is an AABB "
        "axis; its angle to box-box on the same boxes judges nothing about the shapes: worst "
        "{:.3g} deg over {} rows, a figure; its sign is judged on {} rows); depth of {} pairs "
        "judged against box-box on the world AABBs: worst difference {:.3g} m; {}{}",
        s.aabb_angle_worst, s.aabb_angle_rows, normal_angle.checks, depth.checks, depth.worst_or(0.0), sign, stats);
  } else {
    r.detail = fmt::format(
        "{} rows judged{} ({}): worst angle {:.3g} deg, worst depth difference {:.3g} m{}{}; {}{}", normal_angle.checks,
        aabb ? " on the world AABBs" : "",
        aabb ? std::string("box-box")
             : fmt::format("reference: SAT on {} convex pair-frames, box-box or FCL (EPA, distance "
                           "or the non-convex BVH bound) on {}",
                           s.sat_pairs, s.fcl_pairs),
        normal_angle.worst_or(0.0), depth.worst_or(0.0),
        points.checks ? fmt::format(", {} points, worst {:.3g} m beyond the depth", points.checks, points.worst_or(0.0))
                      : "",
        s.rows_unjudged ? fmt::format("; {} rows not judged (FCL gave no normal)", s.rows_unjudged) : "", sign, stats);
    note(r.detail, s.speculative_rows,
         "{} rows on shapes that do not penetrate, or on a non-convex pair within contact_depth_m, "
         "not judged on the angle (worst angle {:.3g} deg to FCL's direction)",
         s.speculative_rows, s.speculative_worst);
    note(r.detail, s.resting_rows,
         "{} resting rows (depth 0 or none, beside a deeper row, or on shapes within contact_depth_m) judged "
         "on the posed shapes' separating direction (worst {:.3g} deg){}",
         s.resting_rows, s.resting_worst,
         s.resting_wide ? fmt::format(" ({} along an axis the touching shapes overlap by at most contact_depth_m)",
                                      s.resting_wide)
                        : std::string());
    note(r.detail, s.sign_uncertain_rows,
         "{} rows on convex hulls that FCL calls apart along an axis that does not "
         "separate them: sign not judged",
         s.sign_uncertain_rows);
    note(r.detail, s.upper_bound_pairs, "{} non-convex mesh pairs: depth judged one-sided against an upper bound",
         s.upper_bound_pairs);
    for (const auto& [kind, figure] : s.declared)
      r.detail += fmt::format(
          "; {} bodies collided as declared \"{}\" (judged on it; its surface lies up to "
          "{:.3g} m from the true shape: a figure)",
          figure.first, kind, figure.second);
    note(r.detail, s.sat_fcl_other,
         "second opinion: FCL's normal on another axis than the minimum on {} pair-frames "
         "(figure; FCL up to {:.3g} m deeper)",
         s.sat_fcl_other, s.sat_fcl_other_excess);
    note(r.detail, s.sat_fcl_disagree,
         "FCL's normal outside SAT's accepted axes on {} pair-frames "
         "(figure; largest depth excess {}: {:.3g} m)",
         s.sat_fcl_disagree, s.sat_fcl_what, s.sat_fcl_worst_excess);
  }
  if (r.applicable) s.fill_causes(r, RowId::ContactGeometry);
  note(r.detail, s.points_persistent,
       "manifold_points \"persistent\": {} row points not judged (they ride on each body "
       "and may drift off the shapes)",
       s.points_persistent);
  note(r.detail, s.depth_unknown_pairs,
       "depth n/a on {} pairs: depth_per \"unknown\" (the rows carry no depth; penetration "
       "is judged on the posed shapes)",
       s.depth_unknown_pairs);
  note(r.detail, s.depth_manifold_pairs,
       "depth_per \"manifold\": {} convex pairs' one depth judged against the deepest point of "
       "the overlap along the manifold's normal",
       s.depth_manifold_pairs);
  note(r.detail, s.depth_spared_as_manifold,
       "depth_per undeclared: {} pairs' depth fits the deepest point of the overlap along the row's normal "
       "(a manifold's depth), not SAT's minimum: passed; declare depth_per to sharpen the "
       "verdict",
       s.depth_spared_as_manifold);
  note(r.detail, s.rounded_pairs, "{} pair-frames judged on shapes rounded by /bodies/convex_radius", s.rounded_pairs);
  return r;
}

}  // namespace octocd
