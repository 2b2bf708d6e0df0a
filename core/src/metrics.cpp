// The metrics stage of the CPU step (design.md section 8 fields of FrameMetrics) and the non-finite
// guard; gpu/src/metrics.cu computes the same fields on the device.
#include "octocd/stages.hpp"

#include <algorithm>

#include <fmt/format.h>

#include "octocd/error.hpp"

namespace octocd {

void frame_state_metrics(const Model& model, const BodyState& state, const std::vector<ContactRecord>& contacts,
                         float slop, FrameMetrics& m) {
  if (!contacts.empty()) {
    double pen_sum = 0.0, pen_max = 0.0;
    std::uint64_t pen_above = 0;
    for (const ContactRecord& c : contacts) {
      pen_sum += c.depth;
      pen_max = std::max(pen_max, static_cast<double>(c.depth));
      if (c.depth > slop) ++pen_above;
    }
    m.penetration_mean = pen_sum / static_cast<double>(contacts.size());
    m.penetration_max = pen_max;
    m.penetration_share_above_slop = static_cast<double>(pen_above) / static_cast<double>(contacts.size());
  }
  const std::size_t n = state.size();
  for (std::size_t i = 0; i < n; ++i) {
    if (state.w[i] == 0.0f) continue;
    const Vec3 x = state.x[i];
    const Vec3 v = state.v[i];
    if (!is_finite(x) || !is_finite(v)) {
      const Vec3 bad = is_finite(x) ? v : x;
      throw RuntimeError(fmt::format(
          "frame {}: body {} (group '{}') has a non-finite {} ({}, {}, {}); the run stops here", m.frame, i,
          model.bodies[i].group, is_finite(x) ? "velocity" : "position", bad.x, bad.y, bad.z));
    }
    const double mass = 1.0 / static_cast<double>(state.w[i]);
    m.kinetic_energy += 0.5 * mass *
                        (static_cast<double>(v.x) * v.x + static_cast<double>(v.y) * v.y +
                         static_cast<double>(v.z) * v.z);
    m.momentum[0] += mass * v.x;
    m.momentum[1] += mass * v.y;
    m.momentum[2] += mass * v.z;
  }
}

}  // namespace octocd
