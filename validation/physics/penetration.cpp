// The physics tier's row 4, penetration (physics_impl.hpp): the largest true penetration
// of the checked frames after the settling window, exact depths judged, non-convex upper
// bounds a figure.
#include "physics_impl.hpp"

#include "../src/row_clock.hpp"

#include <algorithm>
#include <cmath>

#include "octocd/reference_contact.hpp"

namespace octocd {

using namespace dmath;
using namespace physics_detail;

void PhysicsValidators::Impl::judge_penetration(CheckedFrame& f) {
  const std::int64_t frame = f.rec->frame;
  // 4. Penetration: the largest true penetration after the settling window.
  if (double(frame) >= tol.penetration_settle_frames) {
    const double pen_bound = tol.penetration_slops * bodies.slop;
    for (auto& [k, t] : f.truth) {
      if (!t.have) continue;
      const Pair p{k.first, k.second};
      if (!t.g.penetrating) {  // exactly apart (or touching): judged at depth 0
        pen.check(true, 0.0, Where{frame, pair_name(p)}, [] { return std::string(); });
        continue;
      }
      ++pen_pairs;
      // A non-convex pair's depth is an upper bound (the least separating translation
      // over 8 directions): it cannot prove a penetration beyond the bound, so it is a
      // figure; exact depths (boxes, convex shapes) are judged.
      if (t.g.depth_upper_bound) {
        if (t.g.depth > pen_upper_max) {
          pen_upper_max = t.g.depth;
          pen_upper_what = fmt::format("frame {}: pair ({}, {}) {:.4g} m", frame, k.first, k.second, t.g.depth);
        }
        if (t.g.depth > pen_bound) ++pen_upper_over;
        ++pen_upper_pairs;
        continue;
      }
      if (t.g.depth > pen_max) {
        pen_max = t.g.depth;
        pen_what = fmt::format("frame {}: pair ({}, {}) penetrates by {:.4g} m", frame, k.first, k.second,
                               t.g.depth);
      }
      const double d = t.g.depth;
      pen.check(d <= pen_bound, d, Where{frame, pair_name(p)}, [&] {
        return fmt::format("frame {}: {} penetrates by {:.4g} m (bound {:.4g} m)", frame, pair_name(p), d,
                           pen_bound);
      });
    }
  }
}

}  // namespace octocd
