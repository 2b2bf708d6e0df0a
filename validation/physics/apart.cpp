// contacts_complete 0 (design.md section 13d item 5b; physics_impl.hpp): an engine whose API
// may drop contact rows (Havok's "collision finished" events carry no impulse) is judged on
// the geometry; with /contacts/incomplete only on the steps or pairs it lists. free-flight
// judges a body without rows there only where the exact reference shows it apart from every
// other body (of a declared pair) through the whole step by the pair's relative motion, and
// conservation judges a group only where it is apart from every such body outside it: an
// unreported contact is never a false alarm, and a body edited in free flight still fails
// (docs/validation.md, "Incomplete contact reporting").
#include "physics_impl.hpp"

#include "../src/parallel.hpp"
#include "../src/row_clock.hpp"

#include <algorithm>
#include <cmath>

#include "octocd/exact_pairs.hpp"
#include "octocd/reference_contact.hpp"

namespace octocd {

using namespace dmath;
using namespace physics_detail;

double PhysicsValidators::Impl::step_motion(const FrameRecord& rec, std::uint32_t i) const {
  const double dt = model->scene.dt;
  const D3 g = d3(model->scene.gravity);
  const double linear = std::max({dt * len3(d3(rec.v_pre[i])), dt * len3(d3(rec.v_post[i])),
                                  len3(d3(rec.x_post[i]) - d3(rec.x_pre[i]))}) +
                        len3(g) * dt * dt;
  return linear + step_turn(rec, i);
}

double PhysicsValidators::Impl::step_turn(const FrameRecord& rec, std::uint32_t i) const {
  const std::size_t n = model->bodies.size();
  const double dt = model->scene.dt;
  if (rec.q_pre.size() != n || rec.q_post.size() != n || rec.w_pre.size() != n || rec.w_post.size() != n)
    return 0.0;
  // The turn from q to q' (sign of q ignored) and the spin's own turn through the step.
  const Quat a = rec.q_pre[i], b = rec.q_post[i];
  const double na = std::sqrt(double(a.w) * a.w + double(a.x) * a.x + double(a.y) * a.y + double(a.z) * a.z);
  const double nb = std::sqrt(double(b.w) * b.w + double(b.x) * b.x + double(b.y) * b.y + double(b.z) * b.z);
  const double c = std::fabs(double(a.w) * b.w + double(a.x) * b.x + double(a.y) * b.y + double(a.z) * b.z) /
                   (na * nb > 0 ? na * nb : 1.0);
  const double turn = std::max({2.0 * std::acos(std::min(1.0, c)), dt * len3(d3(rec.w_pre[i])),
                                dt * len3(d3(rec.w_post[i]))});
  // The farthest point of the local box from the body's origin.
  const Aabb& box = model->local_box(i);
  const double reach = len3(D3{std::max(std::fabs(double(box.min.x)), std::fabs(double(box.max.x))),
                               std::max(std::fabs(double(box.min.y)), std::fabs(double(box.max.y))),
                               std::max(std::fabs(double(box.min.z)), std::fabs(double(box.max.z)))});
  // From the states' point (the centre of mass), the rounded surface reaches extra_reach farther.
  return (reach + extra_reach(i)) * std::min(turn, 2.0);  // a chord never exceeds the diameter
}

double PhysicsValidators::Impl::pair_motion(const FrameRecord& rec, std::uint32_t a, std::uint32_t b) const {
  const double dt = model->scene.dt;
  // Each body's path through the step lies within the larger of its displacements along v,
  // v' and x' - x of its start, and gravity bends both paths alike: the distance between
  // the two shapes changes by at most their relative displacement (and one |g| dt^2 for a
  // path's bend beside a body gravity does not move) plus both turns.
  const D3 dv0 = d3(rec.v_pre[a]) - d3(rec.v_pre[b]), dv1 = d3(rec.v_post[a]) - d3(rec.v_post[b]);
  const D3 dx = (d3(rec.x_post[a]) - d3(rec.x_pre[a])) - (d3(rec.x_post[b]) - d3(rec.x_pre[b]));
  const double relative = std::max({dt * len3(dv0), dt * len3(dv1), len3(dx)}) +
                          len3(d3(model->scene.gravity)) * dt * dt + step_turn(rec, a) + step_turn(rec, b);
  return std::min(relative, step_motion(rec, a) + step_motion(rec, b));
}

std::pair<const PhysicsBodies::IncompleteRows*, const PhysicsBodies::IncompleteRows*>
PhysicsValidators::Impl::incomplete_of(std::int64_t frame) const {
  const auto& rows = bodies.incomplete_rows;
  const auto lo = std::lower_bound(rows.begin(), rows.end(), frame,
                                   [](const PhysicsBodies::IncompleteRows& e, std::int64_t f) { return e.frame < f; });
  auto hi = lo;
  while (hi != rows.end() && hi->frame == frame) ++hi;
  return {rows.data() + (lo - rows.begin()), rows.data() + (hi - rows.begin())};
}

bool PhysicsValidators::Impl::incomplete_step(std::int64_t frame) const {
  if (!bodies.contacts_complete) return true;
  const auto [lo, hi] = incomplete_of(frame);
  return lo != hi;
}

bool PhysicsValidators::Impl::incomplete_whole_step(std::int64_t frame) const {
  if (!bodies.contacts_complete) return true;
  const auto [lo, hi] = incomplete_of(frame);
  return std::any_of(lo, hi, [](const PhysicsBodies::IncompleteRows& e) { return e.a == PhysicsBodies::kEveryPair; });
}

bool PhysicsValidators::Impl::incomplete_pair(std::int64_t frame, Pair p) const {
  if (!bodies.contacts_complete) return true;
  const auto [lo, hi] = incomplete_of(frame);
  const std::uint32_t a = std::min(p.a, p.b), b = std::max(p.a, p.b);
  return std::any_of(lo, hi, [&](const PhysicsBodies::IncompleteRows& e) {
    return e.a == PhysicsBodies::kEveryPair || (e.a == a && e.b == b);
  });
}

bool PhysicsValidators::Impl::incomplete_body(std::int64_t frame, std::uint32_t i) const {
  if (!bodies.contacts_complete) return true;
  const auto [lo, hi] = incomplete_of(frame);
  return std::any_of(lo, hi, [&](const PhysicsBodies::IncompleteRows& e) {
    return e.a == PhysicsBodies::kEveryPair || e.a == i || e.b == i;
  });
}

void PhysicsValidators::Impl::find_near(const FrameRecord& rec) {
  const std::size_t n = model->bodies.size();
  near.frame = -1;
  near.body.assign(n, 0);
  near.pairs.clear();
  if (rec.x_pre.size() != n || rec.v_pre.size() != n || rec.x_post.size() != n || rec.v_post.size() != n) return;
  near.frame = rec.frame;
  StopPoll poll(stop);
  const bool oriented = rec.q_pre.size() == n;
  const double slack = tol.geometry_slack_m;
  // Candidates: each body's exact AABB at its pre-step pose grown by its motion through
  // the step plus half the largest margin and the slack (exact_pairs). Two shapes that come
  // within margin + slack of each other during the step are within that plus both motions
  // at the pre-step pose, so their grown boxes overlap.
  std::vector<Pose> pose(n);
  std::vector<double> motion(n);
  std::vector<Aabb> grown(n);
  parallel_items_on(n, loop_threads(threads, n, kParallelBodyBoxesFrom), stop, [&](std::size_t i, unsigned) {
    const auto u = static_cast<std::uint32_t>(i);
    pose[i] = frame_pose(rec.x_pre[i], oriented ? rec.q_pre[i] : Quat{}, u);  // the shapes' frame
    motion[i] = step_motion(rec, u);
    grown[i] = expanded(ref->world_aabb(u, pose[i]),
                        static_cast<float>(motion[i] + radius(u) + 0.5 * (max_margin + slack)));
  });
  std::vector<Pair> cand;
  reach_pairs(grown, cand, near_tables);
  ContactGraph graph;
  contact_graph(rec, graph);
  const bool whole = incomplete_whole_step(rec.frame);
  // reach_pairs: a body of every pair is dynamic.
  for (const Pair& p : cand) {
    poll();
    if (graph.find(p.a) == graph.find(p.b)) continue;  // one component: exchanged within it
    if (!whole && !incomplete_pair(rec.frame, p)) continue;  // /contacts/incomplete: this pair's rows are complete
    ++near_tested;
    const ReferenceNormal r = ref->posed(p.a, p.b, pose[p.a], pose[p.b]);
    // Rounded shapes (convex_radius) are apart by the posed distance less their radii.
    const bool apart =
        r.valid && r.signed_distance() > pair_margin(p) + slack + pair_motion(rec, p.a, p.b) + inflation(p);
    if (apart) continue;
    near.pairs.push_back(p);
    near.body[p.a] = near.body[p.b] = 1;
  }
}

std::uint64_t PhysicsValidators::Impl::open_near_groups(ContactGraph& graph) const {
  std::uint64_t opened = 0;
  for (const Pair& p : near.pairs) {
    const std::uint32_t ra = graph.find(p.a), rb = graph.find(p.b);
    for (const std::uint32_t r : {ra, rb}) {
      if (graph.statics[r]) continue;
      graph.statics[r] = 1;  // an unreported contact may join it to another body
      const std::size_t gi = graph.group_of(r);
      if (gi < graph.groups() && graph.members.size(gi) >= 2) ++opened;
    }
  }
  return opened;
}

}  // namespace octocd
