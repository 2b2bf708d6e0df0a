// The reference contact geometry of one pair (see reference.hpp).
#include "reference.hpp"

#include "dmath.hpp"

namespace octocd {

PairReference pair_reference(const ReferenceGeometry& ref, std::uint32_t a, std::uint32_t b, const Pose& pa,
                             const Pose& pb, const SatSettings& settings) {
  PairReference t;
  t.g = ref.posed(a, b, pa, pb);
  t.fcl = t.g;
  if (t.g.penetrating && t.g.valid && ref.convex(a) && ref.convex(b)) {
    t.sat_result = sat_min_translation(ref.hull_features(a), pa, ref.hull_features(b), pb, settings);
    if (t.sat_result.tested && !t.sat_result.separated) {
      t.sat = true;
      t.g.depth = t.sat_result.depth;
      t.g.depth_upper_bound = false;
      const auto& u = t.sat_result.normal;
      t.g.normal = Vec3{float(u[0]), float(u[1]), float(u[2])};
    }
  }
  return t;
}

RowReference row_reference(const PairReference& t, const ReferenceNormal& r, bool by_sat, Vec3 n) {
  RowReference out;
  if (by_sat && !t.sat_result.accepted.empty()) {
    std::size_t nearest = 0;
    out.angle = sat_angle_to_accepted(t.sat_result, dmath::d3(n), &nearest);
    const auto& u = t.sat_result.accepted[nearest].normal;
    out.normal = Vec3{float(u[0]), float(u[1]), float(u[2])};
  } else {
    out.angle = angle_between(n, r.normal);
    out.normal = r.normal;
  }
  return out;
}

}  // namespace octocd
