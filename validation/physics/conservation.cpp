// The physics tier's row 6, conservation (physics_impl.hpp): momentum, kinetic energy and
// angular momentum of isolated dynamic groups per step; with contact_model soft, energy
// over each isolated group's contact episode instead of per step.
#include "physics_impl.hpp"

#include "../src/parallel.hpp"
#include "../src/row_clock.hpp"
#include "ordered_judge.hpp"

#include <algorithm>
#include <cmath>
#include <optional>

#include "octocd/reference_contact.hpp"

namespace octocd {

using namespace dmath;
using namespace physics_detail;

namespace {
/// The fewest isolated groups judged on the validators' threads (judge_in_order): a group of
/// two boxes costs about 10^3 instructions.
constexpr std::size_t kParallelIsolatedGroupsFrom = 512;

/// Row 6's own state that a block of groups judged on a thread writes (judge_in_order): its
/// counts added, its rigid rises appended in group order.
struct IsolatedGroupDry {
  std::uint64_t groups = 0, groups_clamped = 0, groups_asleep = 0, groups_locked = 0, groups_rotation_locked = 0,
                groups_angular_unreported = 0, groups_rotating = 0, energy_soft_steps = 0;
  std::vector<std::pair<std::uint32_t, std::string>> rigid_rises_now;
  template <class Live>
  bool describes(const Live&) const {
    return false;
  }
  template <class Live>
  void merge_into(Live& s) const {
    s.groups += groups;
    s.groups_clamped += groups_clamped;
    s.groups_asleep += groups_asleep;
    s.groups_locked += groups_locked;
    s.groups_rotation_locked += groups_rotation_locked;
    s.groups_angular_unreported += groups_angular_unreported;
    s.groups_rotating += groups_rotating;
    s.energy_soft_steps += energy_soft_steps;
    s.rigid_rises_now.insert(s.rigid_rises_now.end(), rigid_rises_now.begin(), rigid_rises_now.end());
  }
};
}  // namespace

// ---- Row 6: conservation, every frame with states -----------------------------------
void PhysicsValidators::Impl::conservation(const FrameRecord& rec) {
  auto [momentum_tally, angular_tally, energy_tally] =
      tallies(RowId::Conservation, "momentum", "angular-momentum", "energy");
  const Model& m = *model;
  const std::size_t n = m.bodies.size();
  const std::int64_t frame = rec.frame;
  const D3 g = d3(m.scene.gravity);
  const double dt = m.scene.dt;
  const bool states = rec.x_pre.size() == n && rec.v_pre.size() == n && rec.x_post.size() == n &&
                      rec.v_post.size() == n;
  if (!states) {
    for (auto& e : episodes) e.spoiled = true;  // a step without states: the episode is not seen whole
    return;
  }
  ++state_frames;
  const bool rotating = rec.q_pre.size() == n && rec.q_post.size() == n && rec.w_pre.size() == n &&
                        rec.w_post.size() == n;
  auto v_int = [&](std::size_t i) {  // velocity the step starts from: gravity on dynamic bodies
    return dynamic(static_cast<std::uint32_t>(i)) ? d3(rec.v_pre[i]) + dt * g : d3(rec.v_pre[i]);
  };

  // 6. Conservation on isolated dynamic groups: components of the contact graph with at
  // least 2 dynamic bodies and no static body among their contacts.
  ConservationMemory& memory = conservation_memory;
  ContactGraph& graph = memory.graph;
  contact_graph(rec, graph);
  // A step that may lack rows (contacts_complete 0, /contacts/incomplete): a group near a
  // body outside it (of a pair that may lack rows) may exchange an unreported impulse with
  // it; judged as touching a static body (apart.cpp). One apart from every such body is judged.
  if (incomplete_step(frame)) {
    if (near.frame == frame)
      groups_near += open_near_groups(graph);
    else
      for (const std::uint32_t root : graph.roots) graph.statics[root] = 1;  // no states: nothing shown apart
  }
  const std::vector<std::uint8_t>& statics = graph.statics;
  // An engine may apply a row's impulse at two witness points (Bullet: one on each
  // body), apart along the normal by the depth or distance: the friction part then turns
  // the pair by up to that lever times |jt|. Where the engine declares `impulse_points`
  // "witness-pair" the two points may also lie apart across the normal (a persistent
  // manifold's drift), and the lever applies to the whole impulse (jn and jt). Summed per
  // group, it joins the bound.
  // With both witness points recorded (FrameRecord::point_b) a row turns its pair by
  // exactly (p_a - p_b) x J: summed per group into the expected change (witness_turn), it
  // leaves open only the friction impulse a record without jt3 gives as a scalar
  // (|p_a - p_b| |jt|) and the points' float32 rounding.
  std::vector<double>& witness_torque = memory.witness_torque;  // per group
  std::vector<D3>& witness_turn = memory.witness_turn;
  witness_torque.resize(graph.groups());
  witness_turn.resize(graph.groups());
  const bool two_points = rec.has_points && rec.point_b.size() == rec.contacts.size();
  const bool normal_only = bodies.impulses == PhysicsBodies::Impulses::NormalOnly;
  const bool vector_friction = rec.jt3.size() == rec.contacts.size() && !normal_only;
  // Each group's rows between two dynamic bodies, in row order (group_items), summed per
  // group on the threads: the same sums as one pass over the rows in order.
  GroupedItems& group_rows = memory.group_rows;
  group_items(
      rec.contacts.size(), graph.groups(), loop_threads(threads, rec.contacts.size(), kParallelComponentsFrom), stop,
      [&](std::size_t k) {
        const Pair q = rec.contacts[k].pair;
        return dynamic(q.a) && dynamic(q.b) ? std::size_t(graph.group_index[q.a])  // a member
                                            : graph.groups();
      },
      memory.scratch, group_rows);
  parallel_ranges(graph.groups(), loop_threads(threads, graph.groups(), kParallelComponentsFrom), stop,
                  [&](std::size_t first, std::size_t last) {
    for (std::size_t gi = first; gi < last; ++gi) {
      witness_torque[gi] = 0.0;
      witness_turn[gi] = D3{};
      for (const std::uint32_t k : group_rows.group(gi)) {
        const ContactRecord& c = rec.contacts[k];
        // impulses "normal-only": |jt| unknown, at most mu jn (the row cone margin as in
        // momentum-balance) + friction_cone_abs.
        const double jt = normal_only
                              ? pair_mu(c.pair) * std::fabs(double(c.jn)) * (1.0 + kRowConeMargin) +
                                    tol.friction_cone_abs
                              : std::fabs(double(c.jt));
        if (two_points) {
          const D3 pa = d3(c.point), pb = d3(rec.point_b[k]);
          const D3 nrm = d3(c.normal);
          const D3 j = (double(c.jn) / len3(nrm)) * nrm + (vector_friction ? d3(rec.jt3[k]) : D3{});
          witness_turn[gi] = witness_turn[gi] + cross3(pa - pb, j);
          witness_torque[gi] += vector_friction
                                    ? 4.0 * kEps32 * (len3(pa) + len3(pb)) * len3(j)
                                    : len3(pa - pb) * jt + 4.0 * kEps32 * (len3(pa) + len3(pb)) * (len3(j) + jt);
          continue;
        }
        const double j = bodies.witness_pair_impulses ? std::hypot(double(c.jn), jt) : jt;
        witness_torque[gi] += (double(c.depth) + pair_margin(c.pair)) * j;
      }
    }
  });
  // The isolated groups, judged on the threads and tallied in group order (judge_in_order).
  auto judge_groups = [&](std::size_t first, std::size_t last, auto& s, auto& momentum, auto& energy, auto& angular) {
    for (std::size_t gi = first; gi < last; ++gi) {
      const std::uint32_t root = graph.roots[gi];
      const BodyList members = graph.group(gi);
      if (statics[root] || members.size() < 2) continue;
      if (bodies.velocity_clamp > 0.0 &&
          std::any_of(members.begin(), members.end(), [&](std::uint32_t i) {
            const Vec3 v = rec.v_post[i];
            const double c = bodies.velocity_clamp * (1.0 - 1e-6);
            return std::fabs(v.x) >= c || std::fabs(v.y) >= c || std::fabs(v.z) >= c;
          })) {
        ++s.groups_clamped;
        continue;
      }
      if (std::any_of(members.begin(), members.end(),
                      [&](std::uint32_t i) { return asleep(rec.asleep_pre, i) || asleep(rec.asleep_post, i); })) {
        ++s.groups_asleep;  // the engine zeroes a sleeping body's velocity: momentum is not kept by design
        continue;
      }
      ++s.groups;
      // Axes locked by a joint on any member: the joint's impulses are not in the rows, so
      // the momentum along them and (rotation) the angular momentum are not judged.
      unsigned group_locks = 0;
      if (!bodies.locked_dofs.empty())
        for (std::uint32_t i : members) group_locks |= bodies.locked_dofs[i];
      if (group_locks) ++s.groups_locked;
      // Linear momentum: only gravity's m g dt (already in v_int).
      D3 p0{}, p1{};
      double exchanged = 0, scale = 0, mass_sum = 0, drift = 0;
      D3 c0{};
      for (std::uint32_t i : members) {
        const double mi = mass[i];
        const D3 v0 = v_int(i), v1 = d3(rec.v_post[i]);
        p0 = p0 + mi * v0;
        p1 = p1 + mi * v1;
        drift += mi * origin_drift(rec, i).velocity;  // integrated_point "origin" (momentum-balance's allowance)
        exchanged += mi * len3(v1 - v0);
        scale += mi * (len3(d3(rec.v_pre[i])) + len3(v1) + len3(dt * g));
        mass_sum += mi;
        c0 = c0 + mi * d3(rec.x_pre[i]);
      }
      c0 = (1.0 / mass_sum) * c0;
      D3 dp3 = p1 - p0;
      for (int k = 0; k < 3; ++k)
        if (group_locks & (1u << k)) dp3[static_cast<std::size_t>(k)] = 0;
      const double dp = len3(dp3);
      const double pbound = tol.momentum_rel * exchanged + 8.0 * kEps32 * scale + drift + 1e-9;
      momentum.check(dp <= pbound, dp / pbound, Where::of_group(frame, members), [&] {
        return fmt::format("frame {}: isolated group of {} bodies (body {} ...): momentum changes by {:.4g} kg m/s "
                           "beyond gravity (exchanged {:.4g}, bound {:.3g})",
                           frame, members.size(), members.front(), dp, exchanged, pbound);
      });
      // Energy: KE' <= KE after gravity, translational + rotational.
      const StepEnergy se = step_energy(rec, members);
      const double ke0 = se.ke0, ke1 = se.ke1;
      using CM = PhysicsBodies::ContactModel;
      if (restitution_le_1 && bodies.contact_model == CM::Soft) {
        ++s.energy_soft_steps;  // judged per contact episode (soft_episodes)
      } else if (restitution_le_1 && bodies.contact_model == CM::Undeclared && se.rose) {
        // Undeclared: a failure only where the soft rule fails too (its episode, soft_episodes).
        s.rigid_rises_now.emplace_back(
            members.front(), fmt::format("frame {}: isolated group of {} bodies (body {} ...): kinetic energy {:.6g} -> "
                                         "{:.6g} J (+{:.3g} of it)",
                                         frame, members.size(), members.front(), ke0, ke1, (ke1 - ke0) / ke0));
      } else if (restitution_le_1) {
        const double ebound = se.bound;
        energy.check(ke1 <= ebound, ke0 > 0 ? (ke1 - ke0) / ke0 : 0.0, Where::of_group(frame, members), [&] {
          return fmt::format("frame {}: isolated group of {} bodies (body {} ...): kinetic energy {:.6g} -> {:.6g} J "
                             "(+{:.3g} of it){}",
                             frame, members.size(), members.front(), ke0, ke1, ke0 > 0 ? (ke1 - ke0) / ke0 : 0.0,
                             bodies.jacobi_response
                                 ? ": a property of the paper's model (design.md section 6's Jacobi response sums each body's "
                                   "impulses computed from one pre-response state, which overshoots on chains; "
                                   "design.md section 13b.13: reported, not loosened)"
                                 : "");
        });
      }
      // Angular momentum about the group's centre of mass (rotating records only).
      if (!rotating) continue;
      if (group_locks >> 3) {
        ++s.groups_rotation_locked;
        continue;
      }
      if (bodies.impulses == PhysicsBodies::Impulses::None) {  // the witness-point lever needs |J|
        ++s.groups_angular_unreported;
        continue;
      }
      ++s.groups_rotating;
      D3 l0{}, l1{};
      double lexchanged = 0, lscale = 0, gyro = 0, orbital_drift = 0;
      for (std::uint32_t i : members) {
        const double mi = mass[i];
        const D3 v0 = v_int(i), v1 = d3(rec.v_post[i]);
        const D3 w0 = d3(rec.w_pre[i]), w1 = d3(rec.w_post[i]);
        const M3 i0 = conjugated(rotation(rec.q_pre[i]), inertia[i]);
        const M3 i1 = conjugated(rotation(rec.q_post[i]), inertia[i]);
        // The orbital term at the pre-step positions, before and after: impulses exchanged
        // there keep it exactly, and it does not see how the engine moves the bodies
        // afterwards (x_post = x_pre + dt v_post gives the same sum; a split-impulse or
        // position-projection step does not).
        const D3 li0 = mi * cross3(d3(rec.x_pre[i]) - c0, v0) + mul(i0, w0);
        const D3 li1 = mi * cross3(d3(rec.x_pre[i]) - c0, v1) + mul(i1, w1);
        l0 = l0 + li0;
        l1 = l1 + li1;
        lexchanged += len3(li1 - li0);
        // integrated_point "origin": the centre of mass's drift in the orbital term.
        orbital_drift += mi * len3(d3(rec.x_pre[i]) - c0) * origin_drift(rec, i).velocity;
        lscale += mi * (len3(d3(rec.x_pre[i])) + len3(c0)) * (len3(v0) + len3(v1)) + len3(mul(i0, w0)) +
                  len3(mul(i1, w1));
        // Free rotation of a body whose inertia is not isotropic turns I w: an engine
        // integrating the orientation explicitly (no gyroscopic term) misses dt w x (I w).
        // One with the term (declared gyroscopic) keeps L to second order in |w| dt: its
        // explicit or implicit form differs from the exact rotation by (|w| dt)^2 |I w|.
        // Either term may be taken at the step's start (ODE and DART: the torque before the
        // contact impulses) or its end (implicit forms): where the impulses change w within
        // the step, the larger of the two bounds it.
        const D3 iw0 = mul(i0, w0), iw1 = mul(i1, w1);
        gyro += dt * std::max(len3(cross3(w0, iw0)), len3(cross3(w1, iw1)));
        if (bodies.gyroscopic != PhysicsBodies::Gyroscopic::Absent)  // declared or admitted (undeclared)
          gyro += dt * dt * std::max(dot3(w0, w0) * len3(iw0), dot3(w1, w1) * len3(iw1));
      }
      const D3 turn = witness_turn[gi];  // zero without point_b
      const double dl = len3(l1 - l0 - turn);
      const double lbound =
          tol.angular_momentum_rel * lexchanged + gyro + orbital_drift + witness_torque[gi] + 16.0 * kEps32 * lscale +
          1e-9;
      angular.check(dl <= lbound, dl / lbound, Where::of_group(frame, members), [&] {
        return fmt::format("frame {}: isolated group of {} bodies (body {} ...): angular momentum about its centre "
                           "of mass changes by {:.4g} kg m^2/s{} (exchanged {:.4g}, bound {:.3g})",
                           frame, members.size(), members.front(), dl,
                           two_points ? fmt::format(" beyond its rows' (p_a - p_b) x J = ({:.4g}, {:.4g}, {:.4g}) "
                                                    "(/contacts/point_b)",
                                                    turn[0], turn[1], turn[2])
                                      : std::string(),
                           lexchanged, lbound);
      });
    }
  };
  judge_in_order<IsolatedGroupDry>(graph.groups(), threads, kParallelIsolatedGroupsFrom, stop, *this,
                                   std::array<Tally*, 3>{&momentum_tally, &energy_tally, &angular_tally}, judge_groups);
  if (tracks_episodes()) soft_episodes(rec, components(graph));
  rigid_rises_spared += rigid_rises_now.size();  // in no episode (none tracked)
  rigid_rises_now.clear();
}

PhysicsValidators::Impl::StepEnergy PhysicsValidators::Impl::step_energy(const FrameRecord& rec,
                                                                        BodyList members) const {
  const std::size_t n = model->bodies.size();
  const D3 g = d3(model->scene.gravity);
  const double dt = model->scene.dt;
  const bool rotating = rec.q_pre.size() == n && rec.q_post.size() == n && rec.w_pre.size() == n &&
                        rec.w_post.size() == n;
  StepEnergy s;
  for (std::uint32_t i : members) {
    const D3 v0 = d3(rec.v_pre[i]) + dt * g, v1 = d3(rec.v_post[i]);  // members are dynamic
    s.ke0 += 0.5 * mass[i] * dot3(v0, v0);
    s.ke1 += 0.5 * mass[i] * dot3(v1, v1);
    if (rotating) {
      const D3 w0 = d3(rec.w_pre[i]), w1 = d3(rec.w_post[i]);
      s.ke0 += 0.5 * dot3(w0, mul(conjugated(rotation(rec.q_pre[i]), inertia[i]), w0));
      s.ke1 += 0.5 * dot3(w1, mul(conjugated(rotation(rec.q_post[i]), inertia[i]), w1));
    }
  }
  s.bound = s.ke0 * (1.0 + tol.energy_rel) + 16.0 * kEps32 * (s.ke0 + s.ke1) + 1e-12;
  s.rose = !(s.ke1 <= s.bound);
  return s;
}

void PhysicsValidators::Impl::contact_graph(const FrameRecord& rec, ContactGraph& graph) const {
  const std::size_t n = model->bodies.size();
  const unsigned body_threads = loop_threads(threads, n, kParallelComponentsFrom);
  const unsigned link_threads =
      loop_threads(threads, rec.contacts.size() + rec.confirmed.size(), kParallelComponentsFrom);
  // The contact graph: the contact rows' pairs and the engine's confirmed pairs (octocd's
  // later relaxation passes may resolve a confirmed pair that the first pass's Eq. 9
  // discarded, so its impulses are in the state but not in the rows), joined on the threads
  // (components.hpp: the same roots whatever the threads' order), each body of a pair
  // marked as touched.
  graph.components.reset(n, body_threads, stop);
  for (const bool rows : {true, false}) {
    const std::size_t count = rows ? rec.contacts.size() : rec.confirmed.size();
    graph.components.join_all(count, link_threads, stop, [](std::size_t) { return true; }, [&](std::size_t k) {
      const Pair q = rows ? rec.contacts[k].pair : rec.confirmed[k];
      graph.components.mark(q.a);
      graph.components.mark(q.b);
      return q;
    });
  }
  graph.components.settle(body_threads, stop);
  // The links with a static body (selected on the threads), their roots marked.
  std::vector<Pair> with_static;
  graph.statics.resize(n);
  parallel_ranges(n, body_threads, stop, [&](std::size_t first, std::size_t last) {
    std::fill(graph.statics.begin() + std::ptrdiff_t(first), graph.statics.begin() + std::ptrdiff_t(last), 0);
  });
  const unsigned select_threads = loop_threads(threads, rec.contacts.size() + rec.confirmed.size(), kParallelSelectFrom);
  for (const bool rows : {true, false}) {
    const std::size_t count = rows ? rec.contacts.size() : rec.confirmed.size();
    auto link = [&](std::size_t k) { return rows ? rec.contacts[k].pair : rec.confirmed[k]; };
    parallel_select(
        count, with_static, select_threads, stop,
        [&](std::size_t k) {
          const Pair q = link(k);
          return !dynamic(q.a) || !dynamic(q.b);
        },
        link);
    for (const Pair& q : with_static) graph.statics[graph.find(q.a)] = 1;
  }
  // The groups: the dynamic bodies touched, gathered by root (components.hpp's group_items:
  // roots ascending, each root's bodies ascending), then the roots with bodies numbered.
  GroupedItems& by_root = graph.by_root;
  group_items(
      n, n, body_threads, stop,
      [&](std::size_t i) {
        const auto u = static_cast<std::uint32_t>(i);
        return graph.components.marked(u) && dynamic(u) ? std::size_t(graph.find(u)) : n;
      },
      graph.scratch, by_root);
  parallel_select(
      n, graph.roots, body_threads, stop, [&](std::size_t r) { return by_root.size(r) > 0; },
      [](std::size_t r) { return static_cast<std::uint32_t>(r); });
  const std::size_t group_count = graph.roots.size();
  graph.members.items.swap(by_root.items);
  graph.members.first.resize(group_count + 1);
  graph.members.first[group_count] = graph.members.items.size();
  graph.group_index.resize(n);
  const unsigned group_threads = loop_threads(threads, group_count, kParallelComponentsFrom);
  parallel_ranges(group_count, group_threads, stop, [&](std::size_t first_group, std::size_t last_group) {
    for (std::size_t g = first_group; g < last_group; ++g) {
      const std::size_t first = by_root.first[graph.roots[g]];
      graph.members.first[g] = first;
      for (std::size_t k = first; k < by_root.first[graph.roots[g] + 1]; ++k)
        graph.group_index[graph.members.items[k]] = static_cast<std::uint32_t>(g);
    }
  });
}

std::size_t PhysicsValidators::Impl::ContactGraph::group_of(std::uint32_t r) const {
  const auto it = std::lower_bound(roots.begin(), roots.end(), r);
  return it != roots.end() && *it == r ? std::size_t(it - roots.begin()) : roots.size();
}

std::vector<PhysicsValidators::Impl::Component> PhysicsValidators::Impl::components(const ContactGraph& graph) const {
  std::vector<Component> out;  // this step's, with their dynamic bodies
  for (std::size_t g = 0; g < graph.groups(); ++g) {
    const BodyList members = graph.group(g);
    out.push_back({std::vector<std::uint32_t>(members.begin(), members.end()), !graph.statics[graph.roots[g]]});
  }
  return out;
}

void PhysicsValidators::Impl::advance_episodes(const FrameRecord& rec) {
  if (!tracks_episodes()) return;
  const std::size_t n = model->bodies.size();
  const bool states = rec.x_pre.size() == n && rec.v_pre.size() == n && rec.x_post.size() == n &&
                      rec.v_post.size() == n;
  if (!states) {
    for (auto& e : episodes) e.spoiled = true;  // as conservation(): the episode is not seen whole
    return;
  }
  ContactGraph graph;
  contact_graph(rec, graph);
  if (incomplete_step(rec.frame)) {  // as conservation() opens them
    find_near(rec);
    open_near_groups(graph);
  }
  const std::vector<Component> comps = components(graph);
  if (bodies.contact_model == PhysicsBodies::ContactModel::Undeclared)  // as conservation() finds them
    for (const Component& c : comps)
      if (c.isolated && c.members.size() >= 2 && step_energy(rec, c.members).rose)
        rigid_rises_now.emplace_back(c.members.front(), fmt::format("frame {}: kinetic energy rose", rec.frame));
  soft_episodes(rec, comps);
  rigid_rises_now.clear();
}

double PhysicsValidators::Impl::mechanical_energy(const FrameRecord& rec, std::uint32_t i, bool post) const {
  const std::size_t n = model->bodies.size();
  const bool rotating = rec.q_pre.size() == n && rec.w_pre.size() == n;
  const D3 x = d3(post ? rec.x_post[i] : rec.x_pre[i]), v = d3(post ? rec.v_post[i] : rec.v_pre[i]);
  double e = 0.5 * mass[i] * dot3(v, v) - mass[i] * dot3(d3(model->scene.gravity), x);
  if (rotating) {
    const D3 w = d3(post ? rec.w_post[i] : rec.w_pre[i]);
    e += 0.5 * dot3(w, mul(conjugated(rotation(post ? rec.q_post[i] : rec.q_pre[i]), inertia[i]), w));
  }
  return e;
}

void PhysicsValidators::Impl::soft_episodes(const FrameRecord& rec, const std::vector<Component>& components) {
  Tally& energy = tally(RowId::Conservation, "energy");
  const std::int64_t frame = rec.frame;
  const double g2dt2 = dot3(d3(model->scene.gravity), d3(model->scene.gravity)) * model->scene.dt * model->scene.dt;
  auto kinetic = [&](std::uint32_t i) {
    const D3 v = d3(rec.v_pre[i]);
    return 0.5 * mass[i] * dot3(v, v);
  };
  std::set<std::uint32_t> busy;  // dynamic bodies in contact this step
  for (const Component& c : components) busy.insert(c.members.begin(), c.members.end());
  // This step's pairs of dynamic bodies in contact, and whether the previous step's are
  // known (seen by this function: a step without states leaves them unknown).
  std::vector<Pair> pairs;
  for (const ContactRecord& c : rec.contacts)
    if (dynamic(c.pair.a) && dynamic(c.pair.b)) pairs.push_back(c.pair);
  for (const Pair& q : rec.confirmed)
    if (dynamic(q.a) && dynamic(q.b)) pairs.push_back(q);
  std::sort(pairs.begin(), pairs.end());
  pairs.erase(std::unique(pairs.begin(), pairs.end()), pairs.end());
  const bool before_known = pairs_frame == frame - 1;
  // Close the episodes none of whose bodies is in contact this step: judged on the state
  // before it (the state after the episode's last step). Between contacts a member flies
  // free (free-flight judges it), so the group's energy is judged over the whole episode.
  for (auto it = episodes.begin(); it != episodes.end();) {
    if (std::any_of(it->bodies.begin(), it->bodies.end(), [&](std::uint32_t i) { return busy.count(i) > 0; })) {
      ++it;
      continue;
    }
    const Episode& ep = *it;
    if (!owned(ep.start)) {
      // Begun outside this validator's frames (a shard's): judged where it began.
    } else if (ep.spoiled) {
      rigid_rises_spared += ep.rigid_rises;
      ++episodes_unjudged;
      if (ep.began_in_contact) ++episodes_begun_in_contact;
    } else {
      double e1 = 0, masses = 0;
      for (std::uint32_t i : ep.bodies) {
        e1 += mechanical_energy(rec, i, false);
        masses += mass[i];
      }
      const std::int64_t steps = frame - ep.start;
      // Gravity's integration changes E by up to m |g|^2 dt^2 per step and body (explicit
      // Euler gains half of it, semi-implicit loses half); rounding of E's terms.
      const double slack = double(steps) * masses * g2dt2 +
                           16.0 * kEps32 * double(steps + 1) * (ep.scale + std::fabs(e1)) + 1e-12;
      const double bound = ep.e0 + tol.energy_rel * ep.ke0 + slack;
      const double rise = ep.ke0 > 0 ? (e1 - ep.e0) / ep.ke0 : 0.0;
      const std::string item = ep.bodies.size() == 2 ? pair_name(Pair{ep.bodies[0], ep.bodies[1]})
                                                     : group_name(ep.bodies);
      const bool undeclared = bodies.contact_model == PhysicsBodies::ContactModel::Undeclared;
      const bool fails = !(e1 <= bound) && (!undeclared || ep.rigid_rises > 0);
      if (undeclared && !fails) rigid_rises_spared += ep.rigid_rises;
      energy.check(!fails, rise, Where{frame, item}, [&] {
        return fmt::format("frame {}: {}{} ({}) over its contact episode, frames {}..{}: mechanical "
                           "energy {:.6g} -> {:.6g} J (+{:.3g} of its kinetic energy {:.4g} J at the start; bound "
                           "{:.6g}){}",
                           frame, item,
                           ep.bodies.size() == 2 ? std::string() : fmt::format(" of {} bodies", ep.bodies.size()),
                           undeclared ? "contact_model undeclared: judged soft" : "soft contacts", ep.start, frame - 1,
                           ep.e0, e1, rise, ep.ke0, bound,
                           undeclared ? fmt::format("; and rigid: {} of its steps raise the kinetic energy (first: {}); "
                                                    "it fails both ways: declare contact_model to sharpen the verdict",
                                                    ep.rigid_rises, ep.first_rise)
                                      : std::string());
      });
      ++episodes_judged;
      if (ep.bodies.size() > 2) ++episodes_judged_groups;
    }
    it = episodes.erase(it);
  }
  // Open, grow (a component touching an episode's bodies, or two episodes', merges them;
  // a body joining brings its energy at this step) or spoil (a member touches a static
  // body) the episodes.
  for (const Component& c : components) {
    std::vector<std::size_t> hit;  // open episodes sharing a body with c
    for (std::size_t e = 0; e < episodes.size(); ++e)
      if (std::any_of(c.members.begin(), c.members.end(), [&](std::uint32_t i) {
            return std::binary_search(episodes[e].bodies.begin(), episodes[e].bodies.end(), i);
          }))
        hit.push_back(e);
    if (!c.isolated || c.members.size() < 2) {
      for (std::size_t e : hit) episodes[e].spoiled = true;
      continue;
    }
    Episode merged;
    merged.start = frame;
    for (std::size_t e : hit) {
      const Episode& ep = episodes[e];
      merged.start = std::min(merged.start, ep.start);
      merged.bodies.insert(merged.bodies.end(), ep.bodies.begin(), ep.bodies.end());
      merged.e0 += ep.e0;
      merged.ke0 += ep.ke0;
      merged.scale += ep.scale;
      merged.spoiled = merged.spoiled || ep.spoiled;
      merged.began_in_contact = merged.began_in_contact || ep.began_in_contact;
      merged.rigid_rises += ep.rigid_rises;
      if (merged.first_rise.empty()) merged.first_rise = ep.first_rise;
    }
    for (std::uint32_t i : c.members) {
      if (std::find(merged.bodies.begin(), merged.bodies.end(), i) != merged.bodies.end()) continue;
      const double e = mechanical_energy(rec, i, false), ke = kinetic(i);
      merged.bodies.push_back(i);
      merged.e0 += e;
      merged.ke0 += ke;
      merged.scale += std::fabs(e) + ke;
    }
    // The episode starts from the state before its first contact row: a pair of this step
    // that already touched in the previous step, while its group was not isolated (a body
    // on a static one) or outside the open episodes, carries the energy its soft contact
    // stored then, which the bodies' mechanical energy does not hold; releasing it would
    // read as a gain. Such an episode began in contact and is not judged.
    for (const Pair& q : pairs) {
      if (!std::binary_search(c.members.begin(), c.members.end(), q.a)) continue;
      const bool tracked = std::any_of(hit.begin(), hit.end(), [&](std::size_t e) {
        return std::binary_search(episodes[e].bodies.begin(), episodes[e].bodies.end(), q.a) &&
               std::binary_search(episodes[e].bodies.begin(), episodes[e].bodies.end(), q.b);
      });
      if (tracked) continue;
      if (!before_known || std::binary_search(pairs_before.begin(), pairs_before.end(), q)) {
        merged.spoiled = true;
        merged.began_in_contact = true;
      }
    }
    std::sort(merged.bodies.begin(), merged.bodies.end());
    for (auto e = hit.rbegin(); e != hit.rend(); ++e) episodes.erase(episodes.begin() + static_cast<std::ptrdiff_t>(*e));
    episodes.push_back(std::move(merged));
  }
  // contact_model undeclared: this step's rigid rises join the episodes of their groups.
  for (auto it = rigid_rises_now.begin(); it != rigid_rises_now.end();) {
    const auto ep = std::find_if(episodes.begin(), episodes.end(), [&](const Episode& e) {
      return std::binary_search(e.bodies.begin(), e.bodies.end(), it->first);
    });
    if (ep == episodes.end()) {
      ++it;
      continue;
    }
    if (ep->rigid_rises++ == 0) ep->first_rise = it->second;
    it = rigid_rises_now.erase(it);
  }
  pairs_before = std::move(pairs);
  pairs_frame = frame;
}

// ---- conservation: its measure of a frame and its table entry -------------------------

template <>
void PhysicsValidators::Impl::measure<RowId::Conservation>(PhysicsFrame& f) {
  // Every frame with states; with contacts_complete 0 first the pairs the geometry shows near (apart.cpp, shared with
  // free-flight, timed here).
  if (incomplete_step(f.rec.frame)) find_near(f.rec);
  conservation(f.rec);
}

template <>
ValidationResult PhysicsValidators::Impl::table<RowId::Conservation>() const {
  const Impl& s = *this;
  auto [momentum, angular, energy] = s.tallies(RowId::Conservation, "momentum", "angular-momentum", "energy");
  ValidationResult r = failures_row(RowId::Conservation, "isolated groups breaking momentum, angular momentum or energy",
                                    "momentum_rel,angular_momentum_rel,energy_rel");
  r.applicable = s.groups > 0;
  if (momentum.failures) {
    r.detail = momentum.first;
  } else if (energy.failures) {
    r.detail = energy.first;
  } else if (angular.failures) {
    r.detail = angular.first;
  } else if (!r.applicable) {
    r.detail = s.state_frames ? "no isolated dynamic group (2+ dynamic bodies in contact, no static contact)"
                              : "no states (a trace: add /states/position and /states/velocity)";
  } else {
    r.detail = fmt::format(
        "{} isolated group-frames: worst momentum change {:.3g} of its bound; energy {}; "
        "angular momentum {}",
        s.groups, momentum.worst_or(0.0),
        s.restitution_le_1 ? fmt::format("worst rise {:.3g} of KE", energy.worst_or(0.0))
                           : std::string("not judged (a restitution above 1)"),
        s.groups_rotating
            ? fmt::format("{} groups, worst change {:.3g} of its bound", s.groups_rotating, angular.worst_or(0.0))
        : s.groups_rotation_locked ? std::string("n/a: every group has a body whose rotation is locked (locked_dofs)")
                                   : std::string("n/a: translation-only records (no orientation or angular "
                                                 "velocity), contact torques are not modelled"));
  }
  note(r.detail, !s.bodies.contacts_complete,
       "contacts_complete 0: {} group-frames near a body outside them (shapes within the "
       "margin and the pair's motion through the step by the exact reference) not judged, an "
       "unreported contact may join them",
       s.groups_near);
  note(r.detail, s.bodies.contacts_complete && !s.bodies.incomplete_rows.empty(),
       "/contacts/incomplete: {} group-frames on its steps or pairs near a body of a declared pair outside them not "
       "judged, an unreported contact may join them",
       s.groups_near);
  note(r.detail, s.groups_angular_unreported,
       "angular momentum not judged on {} group-frames: the trace declares impulses = "
       "\"none\" (the witness-point lever of a row needs its impulse)",
       s.groups_angular_unreported);
  note(r.detail, s.groups_clamped, "{} group-frames not judged (a body at the declared velocity clamp {} m/s)",
       s.groups_clamped, s.bodies.velocity_clamp);
  note(r.detail, s.groups_asleep,
       "{} group-frames not judged (a body asleep before or after the step: "
       "/states/sleeping)",
       s.groups_asleep);
  note(r.detail, s.bodies.contact_model == PhysicsBodies::ContactModel::Undeclared && s.restitution_le_1,
       "contact_model undeclared: energy judged as rigid (per step) and as soft (per contact "
       "episode: {} judged, {} not), a failure only where both fail ({} steps raising the "
       "kinetic energy spared: their episode's energy did not rise or was not judged); declare "
       "contact_model to sharpen the verdict",
       s.episodes_judged, s.episodes_unjudged + s.owned_open(), s.rigid_rises_spared);
  note(r.detail, s.bodies.contact_model == PhysicsBodies::ContactModel::Soft,
       "contact_model soft: energy judged per contact episode of an isolated group, "
       "from its first contact until none of its bodies touches another ({} episodes judged, "
       "{} of them of 3 or more bodies; {} not judged: a body touched a static one, it began "
       "in contact ({}: a pair touching in the step before, its soft contact's stored energy "
       "unseen), a step had no states, or still in contact at the end ({} open)), not on {} "
       "group-steps",
       s.episodes_judged, s.episodes_judged_groups, s.episodes_unjudged + s.owned_open(), s.episodes_begun_in_contact,
       s.owned_open(), s.energy_soft_steps);
  note(r.detail, s.groups_locked,
       "{} group-frames with a body whose axes are locked (locked_dofs): momentum along "
       "locked translation axes not judged; {} with a rotation locked: angular momentum not "
       "judged",
       s.groups_locked, s.groups_rotation_locked);
  if (r.applicable) {
    s.fill_causes(r, RowId::Conservation);
    r.judged = s.groups;
  }
  return r;
}

}  // namespace octocd
