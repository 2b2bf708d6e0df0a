// The reference contact geometry of one pair (see reference.hpp).
#include "reference.hpp"

#include "dmath.hpp"

namespace octocd {

PairReference pair_reference(const ReferenceGeometry& ref, std::uint32_t a, std::uint32_t b, const Pose& pa,
                             const Pose& pb, const SatSettings& settings) {
  PairReferenceScratch scratch;
  PairReference t = pair_reference_into(ref, a, b, pa, pb, settings, scratch);
  t.sat_result.accepted = std::move(scratch.accepted);
  return t;
}

PairReference pair_reference_into(const ReferenceGeometry& ref, std::uint32_t a, std::uint32_t b, const Pose& pa,
                                  const Pose& pb, const SatSettings& settings, PairReferenceScratch& scratch) {
  PairReference t;
  scratch.accepted.clear();
  t.g = ref.posed(a, b, pa, pb);
  t.fcl = t.g;
  if (t.g.penetrating && t.g.valid && ref.convex(a) && ref.convex(b)) {
    // Two boxes: the closed form (no vertex projected); else, or at non-finite poses, the
    // hull test on placed hulls.
    const HullFeatures &ha = ref.hull_features(a), &hb = ref.hull_features(b);
    auto seen = [](const HullFeatures& h, PairReferenceScratch::BoxSeen& s) -> const PairReferenceScratch::BoxSeen& {
      if (s.hull != &h) {
        s.hull = &h;
        s.box = hull_box(h, s.lo, s.hi);
      }
      return s;
    };
    const PairReferenceScratch::BoxSeen &ba = seen(ha, scratch.box_seen[0]), &bb = seen(hb, scratch.box_seen[1]);
    if (ba.box && bb.box) t.sat_result = sat_boxes(ba.lo, ba.hi, pa, bb.lo, bb.hi, pb, settings, scratch.accepted);
    if (!t.sat_result.tested) {
      if (scratch.placed_a != a) {
        place_hull(ha, pa, scratch.a);
        scratch.placed_a = a;
      }
      place_hull(hb, pb, scratch.b);
      t.sat_result = sat_min_translation_placed(scratch.a, scratch.b, settings, scratch.accepted);
    }
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
  return row_reference(t.sat_result.accepted, r, by_sat, n);
}

RowReference row_reference(const std::vector<SatAxis>& accepted, const ReferenceNormal& r, bool by_sat, Vec3 n) {
  RowReference out;
  if (by_sat && !accepted.empty()) {
    std::size_t nearest = 0;
    out.angle = sat_angle_to_accepted(accepted, dmath::d3(n), &nearest);
    const auto& u = accepted[nearest].normal;
    out.normal = Vec3{float(u[0]), float(u[1]), float(u[2])};
  } else {
    out.angle = angle_between(n, r.normal);
    out.normal = r.normal;
  }
  return out;
}

}  // namespace octocd
