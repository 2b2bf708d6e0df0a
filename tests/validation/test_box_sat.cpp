// The separating-axis test of two boxes in closed form (octocd/box_sat.hpp: the physics
// tier's sat_boxes and the device judge's least overlap) against its oracle, the hull test
// that projects every vertex on every axis (sat_min_translation, validation/physics/sat.hpp):
// the same axes, kinds and normals, overlaps equal to rounding, the same minimum and
// accepted axes, on random posed box pairs that penetrate, touch, lie apart or deep inside
// each other, and with parallel and nearly parallel edges.
#include <fmt/format.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <random>
#include <string>
#include <vector>

#include "octocd/pose.hpp"
#include "octocd/reference_contact.hpp"
#include "octocd/scene.hpp"
#include "../../validation/device/include/octocd/box_sat.hpp"
#include "../../validation/physics/dmath.hpp"
#include "../../validation/physics/reference.hpp"
#include "../../validation/physics/sat.hpp"

namespace octocd {
namespace octocd_test_box_sat {
namespace {

using D3 = std::array<double, 3>;

/// The hull of the box [lo, hi] as reference_contact.hpp builds a box shape's: its 8
/// corners (corner k takes hi on axis d where bit d of k is set), the unit axes as faces
/// and edges.
HullFeatures box_hull(const D3& lo, const D3& hi) {
  HullFeatures h;
  for (int k = 0; k < 8; ++k) h.vertices.push_back({(k & 1) ? hi[0] : lo[0], (k & 2) ? hi[1] : lo[1], (k & 4) ? hi[2] : lo[2]});
  for (int k = 0; k < 3; ++k) {
    D3 e{0, 0, 0};
    e[k] = 1;
    h.face_normals.push_back(e);
    h.edge_dirs.push_back(e);
  }
  return h;
}

Quat normalised(float w, float x, float y, float z) { return normalized(Quat{w, x, y, z}); }

/// One pair of posed boxes.
struct BoxPair {
  D3 lo_a, hi_a, lo_b, hi_b;
  Pose pa, pb;
  std::string what;
};

/// Pair `k` of a family chosen by k % 7 (see the file comment).
BoxPair draw(std::mt19937& rng, int k) {
  std::uniform_real_distribution<float> u(-1.0f, 1.0f), half(0.01f, 0.5f), off(-0.1f, 0.1f), near(-0.3f, 0.3f);
  BoxPair p;
  for (int d = 0; d < 3; ++d) {
    const double ca = off(rng), cb = off(rng), ha = half(rng), hb = half(rng);
    p.lo_a[d] = float(ca - ha), p.hi_a[d] = float(ca + ha);
    p.lo_b[d] = float(cb - hb), p.hi_b[d] = float(cb + hb);
  }
  p.pa.orientation = normalised(u(rng), u(rng), u(rng), u(rng));
  p.pb.orientation = normalised(u(rng), u(rng), u(rng), u(rng));
  p.pa.position = Vec3{near(rng), near(rng), near(rng)};
  p.pb.position = Vec3{near(rng), near(rng), near(rng)};
  switch (k % 7) {
    case 0:
      p.what = "random";
      break;
    case 1:  // turned alike: a_i x b_i vanish, the other crosses are face axes again
      p.what = "turned alike";
      p.pb.orientation = p.pa.orientation;
      break;
    case 2: {  // a quarter turn about one of A's axes: parallel edges to float rounding
      p.what = "quarter turn";
      const float s = std::sqrt(0.5f);
      const int axis = int(rng() % 3);
      p.pb.orientation = p.pa.orientation * Quat{s, axis == 0 ? s : 0.0f, axis == 1 ? s : 0.0f, axis == 2 ? s : 0.0f};
      break;
    }
    case 3: {  // nearly parallel edges: turned by 1e-7 .. 1e-3 rad
      p.what = "nearly alike";
      const float angle = std::pow(10.0f, -7.0f + 4.0f * (0.5f + 0.5f * u(rng)));
      p.pb.orientation = p.pa.orientation * normalised(1.0f, 0.5f * angle * u(rng), 0.5f * angle * u(rng),
                                                            0.5f * angle);
      break;
    }
    case 4: {  // unturned, faces touching exactly (dyadic sizes and offsets) or 2^-10 apart or in
      p.what = "touching";
      const int sizes[3] = {2, 4, 8};
      for (int d = 0; d < 3; ++d) {
        const double ha = 1.0 / sizes[rng() % 3], hb = 1.0 / sizes[rng() % 3];
        p.lo_a[d] = -ha, p.hi_a[d] = ha, p.lo_b[d] = -hb, p.hi_b[d] = hb;
      }
      p.pa.orientation = p.pb.orientation = Quat{1, 0, 0, 0};
      p.pa.position = Vec3{0.25f, -0.5f, 0.125f};
      const int axis = int(rng() % 3), gap = int(rng() % 3) - 1;
      Vec3 x = p.pa.position;
      for (int d = 0; d < 3; ++d) x[d] += float(d == axis ? p.hi_a[d] + p.hi_b[d] + gap / 1024.0 : (int(rng() % 9) - 4) / 64.0);
      p.pb.position = x;
      break;
    }
    case 5:  // deep: the centres within 1 mm
      p.what = "deep";
      p.pb.position = p.pa.position + 0.001f * Vec3{u(rng), u(rng), u(rng)};
      break;
    case 6:  // far apart
      p.what = "apart";
      p.pb.position = p.pa.position + Vec3{2.0f, u(rng), u(rng)};
      break;
  }
  return p;
}

/// The world centre of box [lo, hi] at pose p, as sat_box places it.
D3 centre(const D3& lo, const D3& hi, const Pose& p) {
  const dmath::M3 r = dmath::rotation(p.orientation);
  const D3 c = dmath::mul(r, D3{0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1]), 0.5 * (lo[2] + hi[2])});
  return {c[0] + p.position.x, c[1] + p.position.y, c[2] + p.position.z};
}

// Every axis of the closed form against the hull test's (all of them accepted: rel 1e9), on
// 14,000 pairs of seven families: the same kinds and normals (either sign where the centres
// project within 1e-12 m of each other on it: both translations are then the same), overlaps
// within 1e-12 m (edge-edge axes: plus 1e-14 m / the cross's length, the conditioning of a
// short cross in both tests), the same minimum, separation and accepted axes at the
// default settings; the device's least overlap (box_sat_least_overlap) is the same minimum.
TEST(BoxSeparatingAxis, ClosedFormIsTheHullTest) {
  std::mt19937 rng(2026);
  SatSettings all_axes;
  all_axes.rel = 1e9;
  const SatSettings defaults;
  int penetrating = 0, separated = 0, touching = 0, short_crosses = 0;
  std::vector<SatAxis> got_all, got_acc;
  for (int k = 0; k < 14000; ++k) {
    const BoxPair p = draw(rng, k);
    SCOPED_TRACE(fmt::format("pair {} ({})", k, p.what));
    const HullFeatures ha = box_hull(p.lo_a, p.hi_a), hb = box_hull(p.lo_b, p.hi_b);
    D3 lo, hi;
    ASSERT_TRUE(hull_box(ha, lo, hi));
    ASSERT_EQ(lo, p.lo_a);
    ASSERT_EQ(hi, p.hi_a);
    const SatResult want = sat_min_translation(ha, p.pa, hb, p.pb, all_axes);
    const SatResult got = sat_boxes(p.lo_a, p.hi_a, p.pa, p.lo_b, p.hi_b, p.pb, all_axes, got_all);
    ASSERT_TRUE(want.tested && got.tested);
    ASSERT_EQ(got.axes, want.axes);
    // Each tested axis's tolerance (see above), in the order tested.
    const dmath::M3 ra = dmath::rotation(p.pa.orientation), rb = dmath::rotation(p.pb.orientation);
    std::vector<double> tol(6, 1e-12);
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) {
        const double len = dmath::len3(dmath::cross3({ra[i], ra[3 + i], ra[6 + i]}, {rb[j], rb[3 + j], rb[6 + j]}));
        if (!(len > 1e-9)) continue;
        tol.push_back(1e-12 + 1e-14 / len);
        if (len < 1e-6) ++short_crosses;
      }
    ASSERT_EQ(tol.size(), want.axes);
    EXPECT_NEAR(got.depth, want.depth, *std::max_element(tol.begin(), tol.end()));
    ASSERT_EQ(got.separated, want.separated) << "depth " << got.depth << " against " << want.depth;
    if (p.what == "touching" && want.depth == 0) {
      ++touching;
      EXPECT_EQ(got.depth, 0.0);
    }
    const D3 d = dmath::operator-(centre(p.lo_a, p.hi_a, p.pa), centre(p.lo_b, p.hi_b, p.pb));
    if (!want.separated) {
      ++penetrating;
      ASSERT_EQ(got_all.size(), want.accepted.size());
      ASSERT_EQ(got_all.size(), want.axes);
      for (std::size_t m = 0; m < got_all.size(); ++m) {
        const SatAxis &g = got_all[m], &w = want.accepted[m];
        SCOPED_TRACE(fmt::format("axis {} (kind {})", m, w.kind));
        ASSERT_EQ(g.kind, w.kind);
        const bool flip = g.normal == D3{-w.normal[0], -w.normal[1], -w.normal[2]};
        EXPECT_TRUE(g.normal == w.normal || (flip && std::abs(dmath::dot3(d, w.normal)) <= 1e-12));
        EXPECT_NEAR(g.overlap, w.overlap, tol[m]);
      }
    } else {
      ++separated;
      EXPECT_TRUE(got_all.empty());
    }
    // The default settings: the same minimum's axis and the same accepted axes.
    const SatResult want_d = sat_min_translation(ha, p.pa, hb, p.pb, defaults);
    const SatResult got_d = sat_boxes(p.lo_a, p.hi_a, p.pa, p.lo_b, p.hi_b, p.pb, defaults, got_acc);
    ASSERT_EQ(got_acc.size(), want_d.accepted.size());
    for (std::size_t m = 0; m < got_acc.size(); ++m) {
      EXPECT_EQ(got_acc[m].kind, want_d.accepted[m].kind);
      EXPECT_LT(sat_angle_to_accepted(want_d.accepted, got_acc[m].normal), 1e-9);
    }
    if (!want_d.separated) {
      EXPECT_LT(sat_angle_to_accepted(got_acc, want_d.normal), 1e-9);
    }
    // The device's figure: the least overlap alone.
    auto place = [](const D3& l, const D3& h, const Pose& pose) {
      const dmath::M3 r = dmath::rotation(pose.orientation);
      const double x[3] = {pose.position.x, pose.position.y, pose.position.z};
      return sat_box(l.data(), h.data(), r.data(), x);
    };
    EXPECT_EQ(box_sat_least_overlap(place(p.lo_a, p.hi_a, p.pa), place(p.lo_b, p.hi_b, p.pb)), got.depth);
  }
  // Every family met: most pairs penetrate, some lie apart or touch, some crosses are short.
  EXPECT_GT(penetrating, 7000);
  EXPECT_GT(separated, 2000);
  EXPECT_GT(touching, 100);
  EXPECT_GT(short_crosses, 100);
}

// hull_box accepts a box shape's hull (a scene's box, and a mesh body declared as its box)
// with its local extent, and refuses a convex mesh's hull and a box hull whose corners or
// axes are not a box's; pair_reference then gives two boxes the closed form's figures.
TEST(BoxSeparatingAxis, BoxHullsAreRecognised) {
  const std::string text = R"({"name": "two", "domain": {"min": [-2, -2, -2], "max": [2, 2, 2]}, "walls": "none",
    "groups": [{"name": "box", "shape": {"box": [0.1, 0.05, 0.08]}, "count": 2, "mass": 1,
                "positions": [[0, 0, 0], [0.1, 0.05, 0]]},
               {"name": "ball", "shape": {"icosphere": {"radius": 0.08, "subdivisions": 1}}, "count": 1, "mass": 1,
                "positions": [[1, 0, 0]]}]})";
  const auto model = build_model(parse_scene(text, "boxes and a ball (test)"));
  const ReferenceGeometry ref(*model);
  D3 lo, hi;
  ASSERT_TRUE(hull_box(ref.hull_features(0), lo, hi));
  EXPECT_EQ(lo, (D3{-0.1f, -0.05f, -0.08f}));
  EXPECT_EQ(hi, (D3{0.1f, 0.05f, 0.08f}));
  EXPECT_FALSE(hull_box(ref.hull_features(2), lo, hi));
  const std::vector<CollisionShape> declared{CollisionShape::Mesh, CollisionShape::Mesh, CollisionShape::Box};
  const ReferenceGeometry as_box(*model, declared);
  EXPECT_TRUE(hull_box(as_box.hull_features(2), lo, hi));
  HullFeatures h = box_hull({-1, -1, -1}, {1, 1, 1});
  h.vertices[7] = h.vertices[6];  // a corner twice
  EXPECT_FALSE(hull_box(h, lo, hi));
  h = box_hull({-1, -1, -1}, {1, 1, 1});
  h.vertices[3][0] = 0;  // not a corner
  EXPECT_FALSE(hull_box(h, lo, hi));
  h = box_hull({-1, -1, -1}, {1, 1, 1});
  std::swap(h.face_normals[0], h.face_normals[1]);  // axes in another order
  EXPECT_FALSE(hull_box(h, lo, hi));
  // Two turned boxes through the reference: the closed form's answer.
  const Pose pa{Vec3{0, 0, 0}, normalised(0.9f, 0.1f, 0.2f, 0.3f)}, pb{Vec3{0.1f, 0.08f, 0.02f}, normalised(0.7f, -0.3f, 0.1f, 0.2f)};
  const PairReference t = pair_reference(ref, 0, 1, pa, pb, SatSettings{});
  ASSERT_TRUE(t.sat);
  std::vector<SatAxis> acc;
  const SatResult s = sat_boxes(D3{-0.1f, -0.05f, -0.08f}, D3{0.1f, 0.05f, 0.08f}, pa, D3{-0.1f, -0.05f, -0.08f},
                                D3{0.1f, 0.05f, 0.08f}, pb, SatSettings{}, acc);
  EXPECT_EQ(t.sat_result.depth, s.depth);
  EXPECT_EQ(t.sat_result.normal, s.normal);
  EXPECT_EQ(t.sat_result.accepted.size(), acc.size());
}

}  // namespace
}  // namespace octocd_test_box_sat
}  // namespace octocd
