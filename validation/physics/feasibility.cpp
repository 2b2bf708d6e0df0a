// The physics tier's row 9, impulse feasibility (docs/validation.md, "Motion explained by
// feasible contact impulses"; momentum-balance is its reported-impulse twin): on every
// checked step (the --every cadence) with states, whether compressive contact impulses
// inside each pair's friction cone, at contact points octocd finds itself on the posed
// shapes, can produce every dynamic body's observed change of linear (and, with rotation,
// angular) momentum, gravity removed. It needs nothing of the engine's contact rows (an
// engine that reports poses and velocities only is judged); rows with two witness points
// (/contacts/point_b) add their points to their pair's. Per island (dynamic bodies
// joined through such contacts) a linear programme (COIN-OR CLP) finds the impulses that
// minimise the largest residual in units of each body's bound; above 1 the motion has no
// explanation by contact.
#include "feasibility.hpp"

#include "../src/parallel.hpp"
#include "../src/row_clock.hpp"

#include <algorithm>
#include <cmath>
#include <mutex>
#include <numeric>

#include "octocd/exact_pairs.hpp"

namespace octocd {

using namespace physics_detail;

namespace {
/// The fewest items of the islands' index (roots, ranges: a few instructions an item) that
/// go to the validators' threads: below it, waking them costs more than the loop.
constexpr std::size_t kParallelIndexFrom = 16384;
}  // namespace

bool PhysicsValidators::Impl::feasibility_step(const PhysicsFrame& f) const {
  const std::size_t n = model->bodies.size();
  const FrameRecord& rec = f.rec;
  return f.sampled && rec.x_pre.size() == n && rec.v_pre.size() == n && rec.x_post.size() == n &&
         rec.v_post.size() == n;
}

void PhysicsValidators::Impl::step_reach_boxes(const FrameRecord& rec, const std::vector<Pose>& det,
                                               std::vector<double>& motion, std::vector<Aabb>& world,
                                               std::vector<Aabb>& grown) const {
  // Each body's exact AABB at its detection pose grown by its motion through the step, its
  // convex radius and half the largest margin and the slack (apart.cpp's reach).
  const std::size_t n = model->bodies.size();
  const double slack = tol.geometry_slack_m;
  const bool aabb_geometry = bodies.contact_geometry == ContactGeometry::Aabb;
  motion.resize(n);
  world.resize(n);
  grown.resize(n);
  parallel_items_on(n, loop_threads(threads, n, kParallelBodyBoxesFrom), stop, [&](std::size_t i, unsigned) {
    const auto u = static_cast<std::uint32_t>(i);
    motion[i] = step_motion(rec, u);
    world[i] = aabb_geometry && rec.aabbs.size() == n ? rec.aabbs[i] : ref->world_aabb(u, det[i]);
    grown[i] = expanded(world[i], static_cast<float>(motion[i] + radius(u) + 0.5 * (max_margin + slack)));
  });
}

template <>
void PhysicsValidators::Impl::measure<RowId::ImpulseFeasibility>(PhysicsFrame& f) {
  using namespace feasibility;
  const FrameRecord& rec = f.rec;
  const std::vector<Pose>& det = f.det;
  const Model& m = *model;
  const std::size_t n = m.bodies.size();
  auto& st = row_state<FeasibilityState>(RowId::ImpulseFeasibility);
  // Every step's detection poses join the past (after this step is judged): a gap in the
  // frames or a step without poses starts it anew. An engine whose normals are each step's
  // own (`normal_reuse_deg` 0) needs none.
  const bool keep_past = det.size() == n && rec.x_pre.size() == n && bodies.normal_reuse_deg > 0.0;
  if (!keep_past || rec.frame != st.past_frame + 1) st.past.clear();
  struct Remember {
    FeasibilityState& st;
    const std::vector<Pose>& det;
    std::int64_t frame;
    bool keep_past;
    std::size_t cap;
    unsigned threads;
    ~Remember() {
      if (!keep_past) return;
      // The oldest poses' memory, once the past is full, takes this step's (no fresh pages:
      // at 10^6 bodies a step's poses are 28 MB), copied in ranges on the threads (no stop:
      // the past must be whole).
      std::vector<Pose> poses;
      if (st.past.size() >= cap) {
        poses = std::move(st.past.back());
        st.past.pop_back();
      }
      poses.resize(det.size());
      LoopOptions o;
      o.threads = static_cast<int>(threads);
      o.chunk = std::max<std::size_t>(1, det.size() / (8 * std::size_t(threads)));
      parallel_chunks(det.size(), o, [&](std::size_t first, std::size_t last, unsigned) {
        std::copy(det.begin() + std::ptrdiff_t(first), det.begin() + std::ptrdiff_t(last),
                  poses.begin() + std::ptrdiff_t(first));
      });
      st.past.push_front(std::move(poses));
      st.past_frame = frame;
      while (st.past.size() > cap) st.past.pop_back();
    }
  } remember{st, det, rec.frame, keep_past,
             std::max<std::size_t>(1, std::min(kMaxPastSteps, kMaxPastPoses / std::max<std::size_t>(n, 1))),
             loop_threads(threads, n, kParallelIndexFrom)};
  if (!feasibility_step(f)) return;
  auto [infeasible] = tallies(RowId::ImpulseFeasibility, "infeasible");
  ++st.steps;
  const bool rotating = rec.q_pre.size() == n && rec.q_post.size() == n && rec.w_pre.size() == n &&
                        rec.w_post.size() == n && bodies.contact_geometry == ContactGeometry::Shape;

  // Candidates: the pairs within the step's reach (step_reach_boxes), searched with the
  // checked frame's candidates where this step's checked frame holds them.
  const CheckedFrame* shared = f.geometry && f.geometry->work.reach ? &*f.geometry : nullptr;
  if (!shared) {
    step_reach_boxes(rec, det, st.motion, st.world, st.grown);
    reach_pairs(st.grown, st.cand, st.pair_tables);
  }
  const std::vector<double>& motion = shared ? shared->work.motion : st.motion;
  const std::vector<Aabb>& world = shared ? shared->work.world : st.world;
  const std::vector<Pair>& cand = shared ? shared->work.reach_cand : st.cand;

  // Each pair within reach: its contact points and normal.
  // Each candidate pair's contact points on `threads` threads, each into its own slot.
  std::vector<PairContacts>& pair_out = st.pair_out;
  pair_out.resize(cand.size());
  std::mutex hulls_mutex;
  // Rows with two witness points (FrameRecord::point_b), by pair.
  std::vector<std::pair<Pair, std::size_t>> witness_rows;
  if (rec.has_points && !rec.contacts.empty() && rec.point_b.size() == rec.contacts.size()) {
    for (std::size_t k = 0; k < rec.contacts.size(); ++k) witness_rows.emplace_back(rec.contacts[k].pair, k);
    std::stable_sort(witness_rows.begin(), witness_rows.end(),
                     [](const auto& x, const auto& y) { return x.first < y.first; });
  }
  const ContactSearch search{st, hulls_mutex, det, world, motion, rec, witness_rows};
  parallel_items(cand.size(), threads, stop,
                 [&](std::size_t ci, unsigned) {
                   pair_out[ci].clear();
                   feasibility_contacts(search, cand[ci], pair_out[ci]);
                 });
  // In candidate order: the pairs with contacts, the islands they join, and their dynamic
  // bodies. The contacts stay in their pairs' slots: only an island the programme may judge
  // takes a copy of its own.
  // The counts summed per block of candidates on the threads (integers: any order), the
  // pairs with contacts selected on them; the unions then in candidate order.
  std::vector<std::size_t>& with_contacts = st.with_contacts;
  std::vector<std::uint32_t>& bodies_touched = st.bodies_touched;
  {
    const unsigned count_threads = loop_threads(threads, cand.size(), kParallelSelectFrom);
    const std::size_t blocks = std::max<std::size_t>(1, std::size_t(count_threads) * 8);
    struct Counts {
      std::uint64_t persisted = 0, crossings = 0, crossings_skipped = 0, witness = 0, found = 0;
      std::size_t persisted_steps = 0;
    };
    std::vector<Counts> sums(blocks);
    parallel_items_on(blocks, count_threads, stop, [&](std::size_t b, unsigned) {
      Counts& sum = sums[b];
      for (std::size_t ci = cand.size() * b / blocks; ci < cand.size() * (b + 1) / blocks; ++ci) {
        const PairContacts& out = pair_out[ci];
        sum.persisted += out.persisted;
        sum.crossings += out.crossings;
        sum.crossings_skipped += out.crossings_skipped;
        sum.witness += out.witness;
        sum.persisted_steps = std::max(sum.persisted_steps, out.persisted_steps);
        sum.found += out.contacts.size();
      }
    });
    for (std::size_t b = 0; b < blocks; ++b) {
      st.persisted += sums[b].persisted;
      st.crossings += sums[b].crossings;
      st.crossings_skipped += sums[b].crossings_skipped;
      st.witness += sums[b].witness;
      st.persisted_steps = std::max(st.persisted_steps, sums[b].persisted_steps);
      st.contacts += sums[b].found;
    }
  }
  parallel_select(
      cand.size(), with_contacts, loop_threads(threads, cand.size(), kParallelSelectFrom), stop,
      [&](std::size_t ci) { return !pair_out[ci].contacts.empty(); }, [](std::size_t ci) { return ci; });
  st.pairs += with_contacts.size();
  // The bodies of the pairs with contacts marked, those between dynamic bodies joined, on
  // `threads` threads (components.hpp: each root its island's lowest body, whatever the
  // threads' order); then each body's root.
  Components& components = st.components;
  components.reset(n, loop_threads(threads, n, kParallelIndexFrom), stop);
  components.join_all(
      with_contacts.size(), loop_threads(threads, with_contacts.size(), kParallelIndexFrom), stop,
      [&](std::size_t k) {
        const Pair p = cand[with_contacts[k]];
        components.mark(p.a);
        components.mark(p.b);
        return dynamic(p.a) && dynamic(p.b);
      },
      [&](std::size_t k) { return cand[with_contacts[k]]; });
  components.settle(loop_threads(threads, n, kParallelIndexFrom), stop);
  const std::vector<std::uint32_t>& root = components.roots();
  // The dynamic bodies touched, ascending: a scan of the n marks.
  parallel_select(
      n, bodies_touched, loop_threads(threads, n, kParallelSelectFrom), stop,
      [&](std::size_t i) {
        const auto u = static_cast<std::uint32_t>(i);
        return components.marked(u) && dynamic(u);
      },
      [](std::size_t i) { return static_cast<std::uint32_t>(i); });

  // Islands: the dynamic bodies joined through contacts between dynamic bodies, in the
  // order of their roots, their lowest bodies (a pair with contacts has a dynamic body:
  // feasibility_contacts), each island's bodies ascending (the programme finds a body's
  // slot by bisection); read off the bodies touched: a root is a body touched that is its
  // own root, so the roots come out ascending. The index's loops go to the threads from
  // kParallelIndexFrom items.
  std::vector<std::uint32_t>& roots = st.roots;
  parallel_select(
      bodies_touched.size(), roots, loop_threads(threads, bodies_touched.size(), kParallelSelectFrom), stop,
      [&](std::size_t k) { return root[bodies_touched[k]] == bodies_touched[k]; },
      [&](std::size_t k) { return bodies_touched[k]; });
  std::vector<std::int32_t>& island_of = st.island_of;
  island_of.resize(n);
  parallel_items_on(roots.size(), loop_threads(threads, roots.size(), kParallelIndexFrom), stop,
                    [&](std::size_t ii, unsigned) { island_of[roots[ii]] = static_cast<std::int32_t>(ii); });
  // Each island's bodies and its pairs with contacts (candidate order), as ranges of two
  // flat lists: first[ii] .. first[ii + 1] (group_items: a stable counting sort by island,
  // on `threads` threads).
  auto ranges = [&](std::size_t items, auto island_of_item, std::vector<std::size_t>& first, auto& flat, auto value) {
    group_items(items, roots.size(), loop_threads(threads, items, kParallelIndexFrom), stop, island_of_item,
                st.group_scratch, st.grouped);
    first.swap(st.grouped.first);
    flat.resize(items);
    parallel_ranges(items, loop_threads(threads, items, kParallelIndexFrom), stop,
                    [&](std::size_t first_item, std::size_t last_item) {
                      for (std::size_t j = first_item; j < last_item; ++j)
                        flat[j] = value(std::size_t(st.grouped.items[j]));
                    });
  };
  std::vector<std::size_t>& member_first = st.member_first;
  std::vector<std::size_t>& pair_first = st.pair_first;
  std::vector<std::size_t>& pairs_flat = st.pairs_flat;
  std::vector<std::uint32_t>& members_flat = st.members_flat;
  ranges(bodies_touched.size(), [&](std::size_t k) { return std::size_t(island_of[root[bodies_touched[k]]]); },
         member_first, members_flat, [&](std::size_t k) { return bodies_touched[k]; });
  ranges(with_contacts.size(),
         [&](std::size_t k) {
           const Pair p = cand[with_contacts[k]];
           return std::size_t(island_of[root[dynamic(p.a) ? p.a : p.b]]);
         },
         pair_first, pairs_flat, [&](std::size_t k) { return with_contacts[k]; });
  // Each island's bodies, and its contacts in candidate order copied only where it has at
  // most kMaxIslandBodies bodies (feasibility_islands decides a larger one without reading
  // them), on `threads` threads.
  std::vector<std::vector<std::uint32_t>>& island_members = st.island_members;
  std::vector<std::vector<Contact>>& island_contacts = st.island_contacts;
  island_members.resize(roots.size());
  island_contacts.resize(roots.size());
  parallel_items(roots.size(), threads, stop, [&](std::size_t ii, unsigned) {
    island_members[ii].assign(members_flat.begin() + std::ptrdiff_t(member_first[ii]),
                              members_flat.begin() + std::ptrdiff_t(member_first[ii + 1]));
    island_contacts[ii].clear();
    if (island_members[ii].size() > kMaxIslandBodies) return;
    std::size_t count = 0;
    for (std::size_t k = pair_first[ii]; k < pair_first[ii + 1]; ++k) count += pair_out[pairs_flat[k]].contacts.size();
    island_contacts[ii].reserve(count);
    for (std::size_t k = pair_first[ii]; k < pair_first[ii + 1]; ++k)
      for (const Contact& c : pair_out[pairs_flat[k]].contacts) island_contacts[ii].push_back(c);
  });
  // The islands judged in three passes, each over runs of islands on `threads` threads,
  // each island into its own slot, then tallied in island order (the verdicts do not depend
  // on the thread count): every island's witness; the programmes of the islands without a
  // witness within the bound and of the kProbeIslands with the largest witness figures; the
  // programmes of the islands whose witness figure exceeds the largest figure found so far
  // (at most 1). Any other island's witness figure stands: its programme's figure could not
  // exceed the step's largest, nor its bound (docs/validation.md, "Motion explained by
  // feasible contact impulses", 3).
  const std::size_t islands = island_members.size();
  std::vector<IslandVerdict>& verdicts = st.verdicts;
  verdicts.assign(islands, IslandVerdict{});
  auto judge = [&](const std::vector<std::uint32_t>& ids, IslandPass pass) {
    const std::size_t run = std::clamp<std::size_t>(ids.size() / kMinIslandRuns, 1, kIslandsPerSolve);
    parallel_items((ids.size() + run - 1) / run, threads, stop, [&](std::size_t ri, unsigned) {
      const std::size_t first = ri * run;
      feasibility_islands(rec, det, island_contacts, island_members, ids.data() + first,
                          std::min(run, ids.size() - first), rotating, pass, verdicts);
    });
  };
  {
    std::vector<std::uint32_t> all(islands);
    std::iota(all.begin(), all.end(), 0u);
    judge(all, IslandPass::Witness);
  }
  std::vector<std::uint32_t> first_round, probes;
  for (std::size_t ii = 0; ii < islands; ++ii) {
    if (verdicts[ii].outcome != Outcome::Judged) continue;
    (verdicts[ii].witness <= 1.0 ? probes : first_round).push_back(static_cast<std::uint32_t>(ii));
  }
  const auto larger_witness = [&](std::uint32_t x, std::uint32_t y) {
    return verdicts[x].witness > verdicts[y].witness || (verdicts[x].witness == verdicts[y].witness && x < y);
  };
  const std::size_t probe_count = std::min(probes.size(), kProbeIslands);
  std::partial_sort(probes.begin(), probes.begin() + std::ptrdiff_t(probe_count), probes.end(), larger_witness);
  first_round.insert(first_round.end(), probes.begin(), probes.begin() + std::ptrdiff_t(probe_count));
  std::sort(first_round.begin(), first_round.end());
  judge(first_round, IslandPass::Programme);
  double largest = -std::numeric_limits<double>::infinity();
  for (const std::uint32_t ii : first_round)
    if (verdicts[ii].outcome == Outcome::Judged) largest = std::max(largest, verdicts[ii].figure);
  const double threshold = std::min(largest, 1.0);
  std::vector<std::uint32_t> second_round;
  for (std::size_t k = probe_count; k < probes.size(); ++k)
    if (verdicts[probes[k]].witness > threshold) second_round.push_back(probes[k]);
  std::sort(second_round.begin(), second_round.end());
  judge(second_round, IslandPass::Programme);
  st.witnessed += probes.size() - probe_count - second_round.size();
  for (std::size_t ii = 0; ii < verdicts.size(); ++ii) {
    const IslandVerdict& verdict = verdicts[ii];
    const std::vector<std::uint32_t>& members = island_members[ii];
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
  using namespace feasibility;
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
  note(r.detail, st.witness,
       "{} contact points at the two witness points of the engine's rows (/contacts/point_b: the impulse on A at "
       "point, on B at point_b), each along the normal found nearest the row's",
       st.witness);
  note(r.detail, st.persisted,
       "{} contact points also given the normals they carried on earlier steps (a persistent manifold's; up to {} "
       "steps back)",
       st.persisted, st.persisted_steps);
  note(r.detail, bodies.normal_reuse_deg == 0.0,
       "normal_reuse_deg 0: every contact point takes its step's own normals only (none carried from earlier steps)");
  note(r.detail, bodies.normal_reuse_deg > 0.0 && std::isfinite(bodies.normal_reuse_deg),
       "normal_reuse_deg {:g}: earlier normals only from steps whose pair turned by at most {:g} deg from this one",
       bodies.normal_reuse_deg, bodies.normal_reuse_deg);
  note(r.detail, st.crossings,
       "{} contact points where an edge of one hull (hulls too large for the separating-axis test) passes the other",
       st.crossings);
  note(r.detail, st.crossings_skipped, "{} pair-steps with more than {} pairs of edges near the contact: no edge crossings taken",
       st.crossings_skipped, kMaxCrossingWork);
  note(r.detail, st.witnessed,
       "{} island-steps passed on impulses found by Gauss-Seidel sweeps within their pyramids (their figures within "
       "the step's largest and the bound: their programmes not solved)",
       st.witnessed);
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
