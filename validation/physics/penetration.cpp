// The physics tier's row 4, penetration (physics_impl.hpp): the largest true penetration
// of the checked frames after the settling window, exact depths judged, non-convex upper
// bounds a figure.
#include "physics_impl.hpp"

#include "../src/parallel.hpp"

#include <vector>

namespace octocd {

namespace {

/// The fewest truth entries whose figures are read on the validators' threads: a read is a
/// few instructions, so below it one thread costs less than waking another.
constexpr std::size_t kParallelReadsFrom = 16384;

/// Penetration's sums beyond its tally (Impl::row_state): the largest exact depth (m) and
/// where; the non-convex pairs' upper bounds (a figure): the largest and where, how many
/// above the bound; penetrating pair-frames, and of them those with an upper bound only.
struct PenetrationSums {
  double max = 0, upper_max = 0;
  std::string what, upper_what;
  std::uint64_t upper_over = 0, pairs = 0, upper_pairs = 0;
};

}  // namespace

using namespace physics_detail;

template <>
void PhysicsValidators::Impl::judge<RowId::Penetration>(CheckedFrame& f) {
  judge_penetration(f);
}

// On the device's geometry (device_rows.cpp): the same judgement.
template <>
bool PhysicsValidators::Impl::judge_device<RowId::Penetration>(DeviceCheckedFrame& f) {
  judge_penetration(f);
  return true;
}

template <class Frame>
void PhysicsValidators::Impl::judge_penetration(Frame& f) {
  Tally& pen = tally(RowId::Penetration, "penetration");
  PenetrationSums& ps = row_state<PenetrationSums>(RowId::Penetration);
  const std::int64_t frame = f.rec->frame;
  // 4. Penetration: the largest true penetration after the settling window.
  if (double(frame) >= tol.penetration_settle_frames) {
    const double pen_bound = tol.penetration_slops * bodies.slop;
    // Each pair's kind and depth on `threads` threads (the truth is large; its few
    // figures are read in parallel), then the tallies in pair order.
    enum Kind : char { kNone, kApart, kUpper, kExact };
    std::vector<char> kind(f.truth.size(), kNone);
    std::vector<double> depth_of(f.truth.size(), 0.0);
    parallel_items_on(f.truth.size(), loop_threads(threads, f.truth.size(), kParallelReadsFrom), stop,
                      [&](std::size_t i, unsigned) {
      const auto& t = f.truth[i];
      if (!t.have) return;
      kind[i] = !t.g.penetrating ? kApart : t.g.depth_upper_bound ? kUpper : kExact;
      depth_of[i] = t.g.depth;
    });
    for (std::size_t i = 0; i < f.truth.size(); ++i) {
      if (kind[i] == kNone) continue;
      const Pair p = f.truth_pairs[i];
      if (kind[i] == kApart) {  // exactly apart (or touching): judged at depth 0
        pen.check(true, 0.0, Where{frame, p}, [] { return std::string(); });
        continue;
      }
      ++ps.pairs;
      const double d = depth_of[i];
      // A non-convex pair's depth is an upper bound (the least separating translation
      // over 8 directions): it cannot prove a penetration beyond the bound, so it is a
      // figure; exact depths (boxes, convex shapes) are judged.
      if (kind[i] == kUpper) {
        if (d > ps.upper_max) {
          ps.upper_max = d;
          ps.upper_what = fmt::format("frame {}: pair ({}, {}) {:.4g} m", frame, p.a, p.b, d);
        }
        if (d > pen_bound) ++ps.upper_over;
        ++ps.upper_pairs;
        continue;
      }
      if (d > ps.max) {
        ps.max = d;
        ps.what = fmt::format("frame {}: pair ({}, {}) penetrates by {:.4g} m", frame, p.a, p.b, d);
      }
      pen.check(d <= pen_bound, d, Where{frame, p}, [&] {
        return fmt::format("frame {}: {} penetrates by {:.4g} m (bound {:.4g} m)", frame, pair_name(p), d,
                           pen_bound);
      });
    }
  }
}

// ---- penetration: its table entry -------------------------

template <>
ValidationResult PhysicsValidators::Impl::table<RowId::Penetration>() const {
  const Impl& s = *this;
  const Tally& pen = s.tally(RowId::Penetration, "penetration");
  const PenetrationSums& ps = s.row_state<PenetrationSums>(RowId::Penetration);
  ValidationResult r =
      start_row(RowId::Penetration, "largest true penetration (m)", "penetration_slops,penetration_settle_frames");
  r.measured = ps.max;
  r.bound = s.tol.penetration_slops * s.bodies.slop;
  r.pass = r.measured <= r.bound;
  // Judged: pair-frames with an exact depth. Where every penetrating pair-frame was a
  // non-convex pair's upper bound, the row proved no penetration: n/a.
  r.applicable = s.checked_frames > 0 && pen.checks > 0 && !(ps.upper_pairs > 0 && ps.upper_pairs == ps.pairs);
  if (s.checked_frames == 0) {
    r.detail = kNoChecked;
  } else if (!r.applicable) {
    r.detail = ps.upper_max > 0
                   ? fmt::format(
                         "no exact depth: every penetrating pair is a non-convex mesh pair, whose depth is "
                         "an upper bound only (the least separating translation over 8 directions: a "
                         "figure, not judged): largest {}, {} pair-frames above the bound {} m",
                         ps.upper_what, ps.upper_over, fmt::format("{:.3g}", r.bound))
                   : fmt::format("no pair-frame with an exact depth from frame {} on", s.tol.penetration_settle_frames);
  } else if (ps.pairs == 0) {
    r.detail =
        fmt::format("no penetrating pair on the checked frames from frame {} on", s.tol.penetration_settle_frames);
  } else {
    r.detail = (ps.what.empty() ? std::string("no exact depth (convex shapes)") : ps.what) +
               fmt::format(" (largest of {} penetrating pair-frames; bound {} x slop {} m)", ps.pairs,
                           s.tol.penetration_slops, s.bodies.slop);
    note(r.detail, ps.upper_max > 0,
         "non-convex meshes, upper bounds only (the least separating translation over 8 "
         "directions: a figure, not judged): largest {}, {} pair-frames above the bound",
         ps.upper_what, ps.upper_over);
  }
  if (s.device) note(r.detail, true, "{}", s.device_note());
  if (r.applicable) s.fill_causes(r, RowId::Penetration);
  return r;
}

}  // namespace octocd
