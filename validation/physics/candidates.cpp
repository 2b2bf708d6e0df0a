// The physics tier's checked frames (physics_impl.hpp): the candidate pairs through the
// exact posed world AABBs, their reference geometry (SAT, FCL) and row 3's figures in one
// pass on threads, and row 1, broadphase completeness.
#include "physics_impl.hpp"

#include "../src/parallel.hpp"
#include "../src/row_clock.hpp"
#include "ordered_judge.hpp"

#include <algorithm>
#include <array>
#include <chrono>
#include <iterator>
#include <type_traits>

#include "octocd/exact_pairs.hpp"
#include "octocd/reference_contact.hpp"

namespace octocd {

using namespace dmath;
using namespace physics_detail;

namespace {
std::pair<std::uint32_t, std::uint32_t> key(Pair p) { return std::make_pair(p.a, p.b); }

/// The fewest candidates whose intersection tests, and the fewest pairs whose truth, run on
/// the validators' threads: below them one thread costs less than waking another (two
/// boxes' test about 900 instructions, their truth and row figures about 4,700).
constexpr std::size_t kParallelTestsFrom = 1024;
constexpr std::size_t kParallelTruthFrom = 256;
/// The fewest required pairs row 1 looks up on the threads (judge_in_order).
constexpr std::size_t kParallelRequiredFrom = 2048;

/// The smallest box that holds boxes a and b.
Aabb hull_of(const Aabb& a, const Aabb& b) {
  return {{std::min(a.min.x, b.min.x), std::min(a.min.y, b.min.y), std::min(a.min.z, b.min.z)},
          {std::max(a.max.x, b.max.x), std::max(a.max.y, b.max.y), std::max(a.max.z, b.max.z)}};
}

/// Whether each of `boxes` lies within the box of `grown` of the same index (bounds
/// inclusive; a NaN bound does not), as many of each.
bool within_grown(const std::vector<Aabb>& boxes, const std::vector<Aabb>& grown) {
  if (boxes.size() != grown.size()) return false;
  for (std::size_t i = 0; i < boxes.size(); ++i) {
    const Aabb &b = boxes[i], &g = grown[i];
    if (!(b.min.x >= g.min.x && b.min.y >= g.min.y && b.min.z >= g.min.z && b.max.x <= g.max.x &&
          b.max.y <= g.max.y && b.max.z <= g.max.z))
      return false;
  }
  return true;
}

/// flat's set on `boxes` less its static-static pairs (`dynamic`), sorted, read off `cand`,
/// flat's set on `grown` less its static-static pairs, where each box lies within its
/// grown box: two boxes that overlap (Eq. 6, bounds inclusive) have overlapping grown
/// boxes (a.min >= grown_a.min, b.max <= grown_b.max, and so on), so every pair of flat's
/// set is among `cand`, and the exact test keeps exactly those (on `threads` threads,
/// parallel_select). False, `out` untouched, where a box is not within its grown one (a
/// NaN bound is not) or the sizes differ.
template <class Dynamic>
bool flat_within_grown(const std::vector<Aabb>& boxes, const std::vector<Aabb>& grown, const std::vector<Pair>& cand,
                       Dynamic&& dynamic, std::vector<Pair>& out, int threads, const std::function<bool()>& stop) {
  if (!within_grown(boxes, grown)) return false;
  parallel_select(
      cand.size(), out, loop_threads(threads, cand.size(), kParallelSelectFrom), stop,
      [&](std::size_t i) {
        const Pair p = cand[i];
        return (dynamic(p.a) || dynamic(p.b)) && overlaps(boxes[p.a], boxes[p.b]);
      },
      [&](std::size_t i) { return cand[i]; });
  return true;
}

/// Row 1's own state that a block of required pairs judged on a thread writes.
struct BroadphaseDry {
  std::uint64_t broad_asleep = 0;
  template <class Live>
  bool describes(const Live&) const {
    return false;
  }
  template <class Live>
  void merge_into(Live& s) const {
    s.broad_asleep += broad_asleep;
  }
};
}  // namespace

void physics_detail::pair_run_starts(const std::vector<ContactRecord>& contacts, std::vector<std::size_t>& starts,
                                     int threads, const std::function<bool()>& stop) {
  parallel_select(
      contacts.size(), starts, loop_threads(threads, contacts.size(), kParallelSelectFrom), stop,
      [&](std::size_t k) { return k == 0 || !(contacts[k - 1].pair == contacts[k].pair); },
      [](std::size_t k) { return k; });
}

const ContactTruth& PhysicsValidators::Impl::full_truth(CheckedFrame& f, Pair p) const {
  const std::size_t k = f.find(p);
  if (k < f.truth.size()) return f.truth[k];
  ContactTruth& t = f.extra[key(p)];
  if (!t.have) {
    PairReferenceScratch scratch;
    t.assign(pair_reference_into(*ref, p.a, p.b, (*f.det)[p.a], (*f.det)[p.b], sat_settings, scratch));
    t.inflate(radius(p.a), radius(p.b));
  }
  return t;
}

void PhysicsValidators::Impl::checked_frame(const FrameRecord& rec, const std::vector<Pose>& det,
                                           CheckedFrame& f, const std::vector<Pair>* candidates,
                                           bool with_reach) const {
  const std::size_t n = model->bodies.size();
  const double slack = tol.geometry_slack_m;
  // Every table of f is rebuilt below in the memory it holds (a previous frame's).
  f.rec = &rec;
  f.det = &det;
  f.truth_pairs.clear();
  f.extra.clear();
  f.rows.clear();
  f.contact_pairs.clear();
  f.required.clear();
  CheckedFrame::Work& work = f.work;
  // Candidates: exact posed world AABBs, each grown by half the largest distance any row
  // asks about, through exact_pairs (flat's set in O(n log n + pairs), independent of
  // octocd's broadphases): every pair whose shapes are that close has overlapping grown
  // boxes (the AABB gap is at most the shapes' distance).
  // The judge device's candidates (device_rows.cpp) are the same set, found there, under
  // the same limit of limits::kMaxPairsPerBody pairs a body as exact_pairs' below.
  work.cand_of_grown = candidates == nullptr;
  // Impulse-feasibility's pairs within the step's reach, found here for the row to read
  // (CheckedFrame::Work::reach), in the candidates' search (below). A reach search over its
  // limit is left to the row, which meets it in its own place.
  work.reach = false;
  const bool reach_boxes = with_reach && !candidates;
  if (reach_boxes) step_reach_boxes(rec, det, work.motion, work.world, work.reach_grown);
  auto is_dynamic = [&](std::uint32_t i) { return dynamic(i); };
  if (candidates) {
    require_pair_limit(candidates->size(), n);
    f.cand.assign(candidates->begin(), candidates->end());
  } else {
    const double reach = std::max(tol.broadphase_margin_m, max_margin) + slack;
    std::vector<Aabb>& grown = work.grown;
    grown.resize(n);
    parallel_items_on(n, loop_threads(threads, n, kParallelBodyBoxesFrom), stop, [&](std::size_t i, unsigned) {
      grown[i] = expanded(ref->world_aabb(static_cast<std::uint32_t>(i), det[i]),
                          static_cast<float>(0.5 * reach + radius(static_cast<std::uint32_t>(i))));
    });
    // At most limits::kMaxPairsPerBody pairs a body (PairLimitError, counted before the
    // tests): the truth below costs about 0.7 KiB and 3.5 us a pair.
    // With the reach: one search of the boxes that hold each body's grown and reach boxes,
    // both sets read off it (flat_within_grown; neither holds a static-static pair). Where
    // that search is over its limit (or a NaN bound keeps a box out), each set is searched
    // on its own boxes.
    bool have_cand = false;
    if (reach_boxes) {
      std::vector<Aabb>& both = work.both;
      both.resize(n);
      parallel_items_on(n, loop_threads(threads, n, kParallelBodyBoxesFrom), stop, [&](std::size_t i, unsigned) {
        both[i] = hull_of(grown[i], work.reach_grown[i]);
      });
      bool searched = false;
      try {
        reach_pairs_cpu(both, work.both_cand, work.reach_tables);
        searched = true;
      } catch (const PairLimitError&) {
      }
      if (searched) {
        have_cand = flat_within_grown(grown, both, work.both_cand, is_dynamic, f.cand, threads, stop);
        work.reach =
            flat_within_grown(work.reach_grown, both, work.both_cand, is_dynamic, work.reach_cand, threads, stop);
      }
    }
    if (!have_cand) {
      ExactPairsSettings pair_threads;
      pair_threads.threads = threads;
      pair_threads.max_pairs_per_body = limits::kMaxPairsPerBody;
      exact_pairs(grown, f.cand, pair_threads, work.pair_tables);
      f.cand.erase(std::remove_if(f.cand.begin(), f.cand.end(), [&](Pair p) { return !dynamic(p.a) && !dynamic(p.b); }),
                   f.cand.end());
    }
    if (reach_boxes && !work.reach) {
      try {
        reach_pairs_cpu(work.reach_grown, work.reach_cand, work.reach_tables);
        work.reach = true;
      } catch (const PairLimitError&) {
      }
    }
  }

  // Truth per pair: intersect() for every candidate, posed() where a row needs the depth
  // or the distance.
  // Two convex shapes (boxes, convex meshes) that penetrate get the exact minimum
  // translation of the separating-axis test (design.md section 13b.9); the posed answer
  // (two boxes: octocd's box-box, the same minimum; hulls: FCL's EPA) stays beside it as
  // the second opinion.
  const bool need_distance = tol.broadphase_margin_m - slack > 0;

  // Contact rows per pair (rows of a pair are consecutive).
  std::vector<PairRows>& rows = f.rows;
  std::vector<Pair>& contact_pairs = f.contact_pairs;
  {
    const std::vector<std::size_t>& starts = work.row_starts;
    pair_run_starts(rec.contacts, work.row_starts, threads, stop);
    rows.resize(starts.size());
    contact_pairs.resize(starts.size());
    parallel_items_on(starts.size(), loop_threads(threads, starts.size(), kParallelSelectFrom), stop,
                      [&](std::size_t g, unsigned) {
      const std::size_t first = starts[g], last = g + 1 < starts.size() ? starts[g + 1] : rec.contacts.size();
      rows[g] = {rec.contacts[first].pair, first, last - first};
      contact_pairs[g] = rows[g].p;
    });
  }
  if (!std::is_sorted(contact_pairs.begin(), contact_pairs.end())) std::sort(contact_pairs.begin(), contact_pairs.end());

  // The truth the rows below read, on `threads` threads (parallel_items): every candidate
  // that intersects (or, with a broadphase margin, every candidate) and every contact
  // pair; the rows then read it in their own order, so their verdicts, causes and
  // examples are those of a serial run.
  const std::vector<Pair>& cand = f.cand;
  std::vector<char>& hit = f.hit;
  hit.assign(cand.size(), 1);
  if (!need_distance)
    parallel_items_on(cand.size(), loop_threads(threads, cand.size(), kParallelTestsFrom), stop, [&](std::size_t i, unsigned) {
      // Rounded shapes (a convex radius): the posed shapes may be apart and the rounded
      // ones meet, so their truth is computed.
      hit[i] = inflation(cand[i]) > 0 || ref->intersect(cand[i].a, cand[i].b, det[cand[i].a], det[cand[i].b]) ? 1 : 0;
    });
  {
    std::vector<Pair>& todo = work.todo;
    parallel_select(
        cand.size(), todo, loop_threads(threads, cand.size(), kParallelSelectFrom), stop,
        [&](std::size_t i) { return hit[i] != 0; }, [&](std::size_t i) { return cand[i]; });
    std::vector<Pair>& all = f.truth_pairs;
    // Both sorted, so their union is (a pair repeated in contact_pairs is kept once).
    std::set_union(todo.begin(), todo.end(), contact_pairs.begin(), contact_pairs.end(), std::back_inserter(all));
    all.erase(std::unique(all.begin(), all.end()), all.end());
    f.truth.assign(all.size(), threads);
    // Row 3's figures of each pair's groups of rows come from the same pass, while the
    // pair's SAT axes are at hand: groups listed per truth entry (counting sort).
    const std::size_t n_groups = rows.size();
    f.pair_fig.assign(n_groups, threads);
    f.row_fig.assign(rec.contacts.size(), threads);
    f.aabb_ref.assign(bodies.contact_geometry == ContactGeometry::Aabb ? n_groups : 0, threads);
    {
      // Each group's truth entry, looked up in blocks on the threads (each block onwards
      // from its own cursor), then the groups listed per entry in group order (group_items;
      // a group whose pair is not in the truth is in no list).
      std::vector<std::size_t>& group_truth = work.group_truth;
      group_truth.resize(n_groups);
      const std::size_t group_blocks = (n_groups + kOrderedBlock - 1) / kOrderedBlock;
      parallel_items_on(group_blocks, loop_threads(threads, n_groups, kParallelRequiredFrom), stop,
                        [&](std::size_t b, unsigned) {
        std::size_t cursor = 0;
        for (std::size_t g = b * kOrderedBlock; g < std::min(n_groups, (b + 1) * kOrderedBlock); ++g)
          group_truth[g] = f.find_after(rows[g].p, cursor);
      });
      group_items(n_groups, all.size(), loop_threads(threads, n_groups, kParallelRequiredFrom), stop,
                  [&](std::size_t g) { return group_truth[g]; }, work.group_scratch, work.truth_groups);
    }
    const GroupedItems& truth_groups = work.truth_groups;
    // Per worker: the placed hulls and accepted axes of its last pair (pairs in a chunk
    // share their first body, placed once).
    std::vector<PairReferenceScratch>& scratch = work.scratch;
    const unsigned truth_threads = loop_threads(threads, all.size(), kParallelTruthFrom);
    scratch.resize(truth_threads);
    for (PairReferenceScratch& sc : scratch) sc.placed_a = 0xffffffffu;  // no hull placed at these poses yet
    parallel_items_on(all.size(), truth_threads, stop, [&](std::size_t i, unsigned worker) {
      PairReferenceScratch& s = scratch[worker];
      const Pair p = all[i];
      ContactTruth& t = f.truth[i];
      t.assign(pair_reference_into(*ref, p.a, p.b, det[p.a], det[p.b], sat_settings, s));
      t.inflate(radius(p.a), radius(p.b));
      for (const std::uint32_t g : truth_groups.group(i)) pair_figures(f, g, t, s.accepted);
    });
  }
  // The candidates are sorted: their truth is looked up onwards from the last one, in
  // blocks on the threads (every pair looked up is among the truth's: with a broadphase
  // margin every candidate is, else each one that intersects), then listed in order.
  std::vector<char>& is_required = work.is_required;
  is_required.assign(cand.size(), 0);
  const std::size_t blocks = (cand.size() + kOrderedBlock - 1) / kOrderedBlock;
  parallel_items_on(blocks, loop_threads(threads, cand.size(), kParallelRequiredFrom), stop,
                    [&](std::size_t b, unsigned) {
    std::size_t cursor = 0;
    for (std::size_t i = b * kOrderedBlock; i < std::min(cand.size(), (b + 1) * kOrderedBlock); ++i)
      is_required[i] = required_pair(f, cand[i], hit[i] != 0, cursor) ? 1 : 0;
  });
  parallel_select(
      cand.size(), f.required, loop_threads(threads, cand.size(), kParallelSelectFrom), stop,
      [&](std::size_t i) { return is_required[i] != 0; }, [&](std::size_t i) { return cand[i]; });
}

// ---- Row 1: broadphase completeness ------------------------------------------------
// The first row to judge a checked frame: its clock holds the frame's candidates and
// reference geometry (checked(), shared with rows 2-4).
template <>
void PhysicsValidators::Impl::judge<RowId::BroadphaseCompleteness>(CheckedFrame& f) {
  judge_broadphase(f);
}

// On the device's geometry (device_rows.cpp): the same judgement, flat's set on the
// engine's AABBs from the device too.
template <>
bool PhysicsValidators::Impl::judge_device<RowId::BroadphaseCompleteness>(DeviceCheckedFrame& f) {
  judge_broadphase(f);
  return true;
}

template <class Frame>
void PhysicsValidators::Impl::judge_broadphase(Frame& f) {
  const std::array<Tally*, 1> required_tally{&tally(RowId::BroadphaseCompleteness, "missing-pair")};
  Tally& broad_exact = tally(RowId::BroadphaseCompleteness, "not-flat");
  const FrameRecord& rec = *f.rec;
  const std::int64_t frame = rec.frame;
  ExactPairsSettings pair_threads;
  pair_threads.threads = threads;
  pair_threads.max_pairs_per_body = limits::kMaxPairsPerBody;
  if (!rec.has_pairs) {
    ++broad_no_pairs;
  } else {
    ++broad_frames;
    broad_candidates += rec.pairs.size();
    broad_true += f.required.size();
    // The required pairs are sorted, and so are the engine's (FrameRecord::pairs): both
    // looked up onwards from the last answer (binary_search where the engine's are not),
    // on the threads and tallied in order (judge_in_order). Every required pair is among
    // the truth's pairs (checked_frame, device_frame), so truth_after only reads here.
    const bool engine_sorted = std::is_sorted(rec.pairs.begin(), rec.pairs.end());
    auto judge_required = [&](std::size_t first, std::size_t last, auto& s, auto& broad) {
      std::size_t engine_cursor = 0, truth_cursor = 0;
      for (std::size_t i = first; i < last; ++i) {
        const Pair p = f.required[i];
        bool found;
        if (engine_sorted) {
          const std::size_t k = seek(rec.pairs, p, engine_cursor);
          found = k < rec.pairs.size() && rec.pairs[k] == p;
        } else {
          found = std::binary_search(rec.pairs.begin(), rec.pairs.end(), p);
        }
        const ReferenceNormal& g = truth_after(f, p, truth_cursor).g;
        if (!found && pair_asleep(rec, p)) {  // a pair of sleeping bodies need not be a candidate
          ++s.broad_asleep;
          continue;
        }
        broad.check(found, g.penetrating ? g.depth : -g.distance, Where{frame, p}, [&] {
          return fmt::format("frame {}: {} misses {} whose shapes are {} {:.3g} m (margin {} m)", frame, label,
                             pair_name(p), g.penetrating ? "penetrating by" : "apart by",
                             g.penetrating ? g.depth : g.distance, tol.broadphase_margin_m);
        });
      }
    };
    judge_in_order<BroadphaseDry>(f.required.size(), threads, kParallelRequiredFrom, stop, *this, required_tally,
                                  judge_required);
    if (bodies.broadphase_exact) {
      // Set equality with `flat` on the engine's own world AABBs, static-static dropped:
      // flat's set through exact_pairs (O(n log n + pairs); tests/validation/test_exact_pairs).
      // Where the engine's boxes lie within the candidates' grown boxes (an engine's boxes
      // without a margin wider than the reach: octocd's), the set is read off the
      // candidates (flat_within_grown), one search of the frame fewer.
      std::vector<Pair> want, got;
      if constexpr (std::is_same_v<Frame, DeviceCheckedFrame>) {
        const auto t0 = std::chrono::steady_clock::now();
        device->overlapping_pairs(rec.aabbs, want);
        device_flat_seconds += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
      } else if (!f.work.cand_of_grown ||
                 !flat_within_grown(rec.aabbs, f.work.grown, f.cand, [&](std::uint32_t i) { return dynamic(i); }, want,
                                    threads, stop)) {
        exact_pairs(rec.aabbs, want, pair_threads, f.work.pair_tables);
      }
      // Both sets less their static-static pairs, on the threads (parallel_select).
      auto dynamic_of = [&](const std::vector<Pair>& from, std::vector<Pair>& to) {
        parallel_select(
            from.size(), to, loop_threads(threads, from.size(), kParallelSelectFrom), stop,
            [&](std::size_t i) { return dynamic(from[i].a) || dynamic(from[i].b); },
            [&](std::size_t i) { return from[i]; });
      };
      dynamic_of(want, got);
      want.swap(got);
      dynamic_of(rec.pairs, got);
      std::vector<Pair> missing, extra;  // computed only where the sets differ (both sorted)
      if (want != got) {
        std::set_difference(want.begin(), want.end(), got.begin(), got.end(), std::back_inserter(missing));
        std::set_difference(got.begin(), got.end(), want.begin(), want.end(), std::back_inserter(extra));
      }
      const bool same = missing.empty() && extra.empty();
      const Pair first_diff = !missing.empty() ? missing.front() : !extra.empty() ? extra.front() : Pair{};
      broad_exact.check(same, double(missing.size() + extra.size()),
                        Where{frame, same ? std::string() : pair_name(first_diff)}, [&] {
        if (same) return fmt::format("frame {}: equal to flat", frame);
        const Pair q = !missing.empty() ? missing.front() : extra.front();
        // Pairs whose boxes only touch (zero overlap on an axis) are pairs under the
        // inclusive rule of Eq. 6; an engine with a strict test misses exactly those.
        const bool all_touch = !missing.empty() && std::all_of(missing.begin(), missing.end(), [&](Pair mp) {
          for (int k = 0; k < 3; ++k)
            if (std::min(rec.aabbs[mp.a].max[k], rec.aabbs[mp.b].max[k]) ==
                std::max(rec.aabbs[mp.a].min[k], rec.aabbs[mp.b].min[k]))
              return true;
          return false;
        });
        return fmt::format("frame {}: {} declares an exact AABB broadphase but {} {} of flat on its world "
                           "AABBs ({} missing, {} extra){}",
                           frame, label, missing.empty() ? "adds" : "misses", pair_name(q), missing.size(),
                           extra.size(),
                           all_touch ? "; the missing pairs only touch (zero overlap on an axis): overlap is "
                                       "inclusive (Eq. 6), min_A <= max_B and max_A >= min_B"
                                     : "");
      });
      flat_dynamic.swap(want);  // candidate-sets reads it (flat_pairs)
      flat_frame = frame;
    }
  }
}

// ---- broadphase-completeness: its table entry -------------------------

template <>
ValidationResult PhysicsValidators::Impl::table<RowId::BroadphaseCompleteness>() const {
  const Impl& s = *this;
  auto [broad, broad_exact] = s.tallies(RowId::BroadphaseCompleteness, "missing-pair", "not-flat");
  ValidationResult r = failures_row(RowId::BroadphaseCompleteness, "required pairs missing from the engine's candidates",
                                    "broadphase_margin_m,geometry_slack_m");
  if (s.broad_frames > 0 && broad.checks + broad_exact.checks == 0) {
    r.applicable = false;
    r.detail = fmt::format(
        "no pair required on {} checked frames (no shapes within the margin) and no exact "
        "broadphase declared: nothing judged ({:.3g} candidates per frame)",
        s.broad_frames, double(s.broad_candidates) / double(s.broad_frames));
  } else if (s.broad_frames == 0) {
    r.applicable = false;
    r.detail = s.broad_no_pairs ? "the engine gave no candidate pairs (has_pairs false; a trace: add /pairs/offsets "
                                  "and /pairs/pair)"
                                : kNoChecked;
  } else if (broad.failures) {
    r.detail = broad.first + fmt::format(" ({} of {} required pairs missing)", broad.failures, broad.checks);
  } else if (broad_exact.failures) {
    r.detail = broad_exact.first;
  } else {
    r.detail =
        fmt::format("{} required pairs over {} frames, all candidates; {:.3g} candidates per true pair{}", broad.checks,
                    s.broad_frames, s.broad_true ? double(s.broad_candidates) / double(s.broad_true) : 0.0,
                    s.bodies.broadphase_exact ? "; equal to flat on the engine's AABBs (static-static "
                                                "pairs dropped)"
                                              : "");
  }
  note(r.detail, s.broad_asleep, "{} pair-frames of bodies asleep before the step (/states/sleeping) not required",
       s.broad_asleep);
  if (s.device) note(r.detail, true, "{}", s.device_note());
  if (r.applicable) s.fill_causes(r, RowId::BroadphaseCompleteness);
  return r;
}

}  // namespace octocd
