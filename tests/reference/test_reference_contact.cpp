// Reference contact normals from FCL / libccd (design.md section 7 validator 3): sign conventions,
// distances and depths on scenes with known answers.
//
// Conventions pinned here (see reference_contact.hpp):
//  - FCL distance: nearest_points[0] on o1 (= A), [1] on o2 (= B), world frame
//    (SeparatedBoxes*: point_a lies on A's face, point_b on B's face).
//  - libccd ccdGJKPenetration(A, B): dir points from A to B; we return -dir (B to A)
//    (OverlappingBoxes*: A above B gives +y).
//  - fcl::collide Contact::normal points from o1 (= A) to o2 (= B); we return -normal
//    (FclCollideNormal*: A above B gives +y); penetration_depth >= 0.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <memory>
#include <random>
#include <string>

#include <fcl/geometry/shape/box.h>
#include <fcl/narrowphase/collision.h>
#include <fcl/narrowphase/collision_object.h>

#include "octocd/error.hpp"
#include "octocd/reference_contact.hpp"
#include "octocd/scene.hpp"
#include "octocd/world.hpp"

using namespace octocd;

namespace {

constexpr double kPi = 3.14159265358979323846;
double deg(double rad) { return rad * 180.0 / kPi; }

/// Writes `json` to a temp file and loads it as a scene.
Scene scene_from_text(const std::string& json, const std::string& stem) {
  const std::string path = testing::TempDir() + "octocd_refcontact_" + stem + ".json";
  {
    std::ofstream f(path);
    f << json;
  }
  Scene s = load_scene(path);
  std::remove(path.c_str());
  return s;
}

/// Two bodies of one shape, no walls (bodies 0 and 1; positions are overwritten by tests).
std::string two_bodies(const std::string& shape, const std::string& walls = "none") {
  return R"({"name": "pair", "domain": {"min": [-2, -2, -2], "max": [2, 2, 2]},
    "walls": ")" + walls + R"(",
    "groups": [{"name": "g", "shape": )" + shape + R"(, "count": 2,
                "positions": [[0.5, 0, 0], [-0.5, 0, 0]]}]})";
}

const std::string kBox = R"({"box": [0.1, 0.1, 0.1]})";
const std::string kSphere = R"({"icosphere": {"radius": 0.1, "subdivisions": 3}})";

Vec3 v3(double x, double y, double z) { return {float(x), float(y), float(z)}; }

/// Circumradius (max vertex distance from the local origin) and inradius (min distance
/// of a face plane from the origin) of a mesh shape: its surface lies between them.
void radii(const Shape& s, double& r_out, double& r_in) {
  r_out = 0;
  r_in = 1e30;
  for (const Vec3& v : s.mesh->vertices) {
    r_out = std::max(r_out, std::sqrt(double(v.x) * v.x + double(v.y) * v.y + double(v.z) * v.z));
  }
  for (const auto& t : s.mesh->triangles) {
    const Vec3 a = s.mesh->vertices[t[0]], b = s.mesh->vertices[t[1]], c = s.mesh->vertices[t[2]];
    const double ux = b.x - a.x, uy = b.y - a.y, uz = b.z - a.z;
    const double wx = c.x - a.x, wy = c.y - a.y, wz = c.z - a.z;
    double nx = uy * wz - uz * wy, ny = uz * wx - ux * wz, nz = ux * wy - uy * wx;
    const double n = std::sqrt(nx * nx + ny * ny + nz * nz);
    r_in = std::min(r_in, std::abs(nx * a.x + ny * a.y + nz * a.z) / n);
  }
}

/// Largest angle (degrees) between the reference normal and the centre direction that two
/// convex polyhedra with surfaces between r_in and r_out, centres d apart, allow: the
/// normal n maximises separation (minimises penetration) d cos(a) - h(n), where the
/// support h of A - B lies in [2 r_in, 2 r_out]; compared with n = centre direction this
/// needs d (1 - cos a) <= 2 (r_out - r_in). Plus 0.01 degree for float positions.
double max_normal_deviation_deg(double r_out, double r_in, double d) {
  return deg(std::acos(1.0 - 2.0 * (r_out - r_in) / d)) + 0.01;
}

void expect_unit_axis(Vec3 n, Vec3 axis, double tol) {
  EXPECT_NEAR(n.x, axis.x, tol);
  EXPECT_NEAR(n.y, axis.y, tol);
  EXPECT_NEAR(n.z, axis.z, tol);
}

}  // namespace

TEST(AngleBetween, KnownAngles) {
  EXPECT_NEAR(angle_between({1, 0, 0}, {1, 0, 0}), 0.0, 1e-12);
  EXPECT_NEAR(angle_between({1, 0, 0}, {0, 1, 0}), kPi / 2, 1e-12);
  EXPECT_NEAR(angle_between({1, 0, 0}, {-1, 0, 0}), kPi, 1e-12);
  EXPECT_NEAR(angle_between({1, 0, 0}, v3(std::cos(0.001), std::sin(0.001), 0)), 0.001, 1e-7);
}

// Separated boxes (half 0.1) with a 0.05 gap along +x, -y, +z from B to A. FCL's
// nearest_points[0] is on o1 = A: point_a is on A's face that faces B.
TEST(ReferenceContact, SeparatedBoxesNearestPointsOrderAndAxisNormal) {
  const World world(scene_from_text(two_bodies(kBox), "boxes"));
  const ReferenceGeometry ref(world);
  const Vec3 axes[] = {{1, 0, 0}, {0, -1, 0}, {0, 0, 1}};
  for (const Vec3 axis : axes) {
    SCOPED_TRACE("axis " + std::to_string(axis.x) + " " + std::to_string(axis.y) + " " +
                 std::to_string(axis.z));
    const Vec3 xb = v3(0.01, 0.02, -0.03);
    const Vec3 xa = xb + 0.25f * axis;  // centres 0.25 apart, faces 0.05 apart
    const double gap = 0.25 - 2 * double(0.1f);
    const ReferenceNormal r = ref.normal(0, 1, xa, xb);
    ASSERT_TRUE(r.valid);
    EXPECT_FALSE(r.penetrating);
    EXPECT_NEAR(r.distance, gap, 1e-6);
    expect_unit_axis(r.normal, axis, 1e-6);
    // point_a lies on A's face towards B, point_b on B's face towards A.
    EXPECT_NEAR(dot(r.point_a - xa, axis), -0.1, 1e-6);
    EXPECT_NEAR(dot(r.point_b - xb, axis), 0.1, 1e-6);
    // Swapping a and b flips the normal.
    const ReferenceNormal s = ref.normal(1, 0, xb, xa);
    ASSERT_TRUE(s.valid);
    expect_unit_axis(s.normal, -axis, 1e-6);
    EXPECT_NEAR(s.distance, r.distance, 1e-9);
  }
}

// Boxes overlapping by 0.01 along y. ccdGJKPenetration(A, B) gives dir from A to B; the
// reference returns -dir, so A above B gives +y. EPA depth within 1e-6 m (epa_tolerance
// 1e-9 plus float positions).
TEST(ReferenceContact, OverlappingBoxesEpaNormalFromBToAAndDepth) {
  const World world(scene_from_text(two_bodies(kBox), "boxes_overlap"));
  const ReferenceGeometry ref(world);
  const Vec3 xb = v3(0.0, 0.0, 0.0);
  const Vec3 xa = v3(0.03, 0.19, -0.02);  // y overlap 0.01, x/z overlap 0.17/0.18
  const ReferenceNormal r = ref.normal(0, 1, xa, xb);
  ASSERT_TRUE(r.valid);
  EXPECT_TRUE(r.penetrating);
  EXPECT_NEAR(r.depth, 0.2 - double(0.19f), 1e-6);
  expect_unit_axis(r.normal, {0, 1, 0}, 1e-6);
  // Swapped: B above A, normal -y.
  const ReferenceNormal s = ref.normal(1, 0, xb, xa);
  ASSERT_TRUE(s.valid);
  EXPECT_TRUE(s.penetrating);
  expect_unit_axis(s.normal, {0, -1, 0}, 1e-6);
  EXPECT_NEAR(s.depth, r.depth, 1e-6);
}

// FCL's own path (fcl::collide, GST_LIBCCD; box-box is ODE's boxBox there): Contact::normal
// points from o1 = A to o2 = B, so the converted normal for A above B is +y.
TEST(ReferenceContact, FclCollideNormalConventionOnBoxes) {
  const World world(scene_from_text(two_bodies(kBox), "boxes_fcl"));
  const ReferenceGeometry ref(world);
  const Vec3 xb = v3(0.0, 0.0, 0.0);
  const Vec3 xa = v3(0.03, 0.19, -0.02);
  const ReferenceNormal r = ref.fcl_collide_normal(0, 1, xa, xb);
  ASSERT_TRUE(r.valid);
  expect_unit_axis(r.normal, {0, 1, 0}, 1e-6);
  EXPECT_NEAR(r.depth, 0.2 - double(0.19f), 1e-6);
  const ReferenceNormal s = ref.fcl_collide_normal(1, 0, xb, xa);
  ASSERT_TRUE(s.valid);
  expect_unit_axis(s.normal, {0, -1, 0}, 1e-6);
  // Separated: no contact, invalid.
  EXPECT_FALSE(ref.fcl_collide_normal(0, 1, v3(0, 0.3, 0), xb).valid);
}

// Separated icospheres (r = 0.1, 3 subdivisions) along a diagonal. The surfaces lie between
// the inradius r_in and circumradius r_out (r_out - r_in ~ 0.3 mm here), so the BVH
// distance is in [d - 2 r_out, d - 2 r_in] (+1e-6 for float positions), and the normal is
// within max_normal_deviation_deg of the centre direction (4.8 degrees here; measured:
// 0, 2.6, 2.9 degrees).
TEST(ReferenceContact, SeparatedIcospheresDistanceWithinPolyhedralErrorAndCentreNormal) {
  const World world(scene_from_text(two_bodies(kSphere), "spheres"));
  const ReferenceGeometry ref(world);
  double r_out = 0, r_in = 0;
  radii(world.shapes()[world.bodies()[0].shape], r_out, r_in);
  ASSERT_GT(r_in, 0.099);
  ASSERT_LE(r_out, 0.1 + 1e-6);
  const double dirs[][3] = {{1, 1, 1}, {1, -2, 0.5}, {-0.3, 0.2, -1}};
  for (const auto& d : dirs) {
    const double len = std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
    const Vec3 u = v3(d[0] / len, d[1] / len, d[2] / len);
    const Vec3 xb = v3(0.1, -0.2, 0.05);
    const Vec3 xa = xb + 0.26f * u;  // nominal gap 0.06
    const Vec3 c = xa - xb;
    const double dist = std::sqrt(double(dot(c, c)));
    const ReferenceNormal r = ref.normal(0, 1, xa, xb);
    ASSERT_TRUE(r.valid);
    EXPECT_FALSE(r.penetrating);
    EXPECT_GE(r.distance, dist - 2 * r_out - 1e-6);
    EXPECT_LE(r.distance, dist - 2 * r_in + 1e-6);
    const double ang = deg(angle_between(r.normal, u));
    const double bound = max_normal_deviation_deg(r_out, r_in, dist);
    EXPECT_LT(ang, bound) << "normal deviates " << ang << " deg";
    const ReferenceNormal s = ref.normal(1, 0, xb, xa);
    ASSERT_TRUE(s.valid);
    EXPECT_LT(deg(angle_between(s.normal, -r.normal)), 1e-3);
    std::printf("separated icospheres: dist %.6f in [%.6f, %.6f], normal %.3f deg (< %.3f)\n",
                r.distance, dist - 2 * r_out, dist - 2 * r_in, ang, bound);
  }
}

// Intersecting icospheres (centres 0.18 apart: overlap ~0.02): EPA on the hulls, normal
// within max_normal_deviation_deg of the centre direction B -> A (5.75 degrees here;
// measured 0, 2.6 and 5.3 degrees: along y the minimum translation of the two polyhedra
// is NOT along the centre line, depth 0.019915 < 0.02 there), depth in
// [2 r_in - d, 2 r_out - d].
TEST(ReferenceContact, IntersectingIcospheresEpaNormalAlongCentres) {
  const World world(scene_from_text(two_bodies(kSphere), "spheres_overlap"));
  const ReferenceGeometry ref(world);
  double r_out = 0, r_in = 0;
  radii(world.shapes()[world.bodies()[0].shape], r_out, r_in);
  const double dirs[][3] = {{1, 1, 1}, {1, -2, 0.5}, {0, 1, 0}};
  for (const auto& d : dirs) {
    const double len = std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
    const Vec3 u = v3(d[0] / len, d[1] / len, d[2] / len);
    const Vec3 xb = v3(0.0, 0.3, 0.0);
    const Vec3 xa = xb + 0.18f * u;
    const Vec3 c = xa - xb;
    const double dist = std::sqrt(double(dot(c, c)));
    const ReferenceNormal r = ref.normal(0, 1, xa, xb);
    ASSERT_TRUE(r.valid);
    EXPECT_TRUE(r.penetrating);
    EXPECT_GE(r.depth, 2 * r_in - dist - 1e-6);
    EXPECT_LE(r.depth, 2 * r_out - dist + 1e-6);
    const double ang = deg(angle_between(r.normal, u));
    const double bound = max_normal_deviation_deg(r_out, r_in, dist);
    EXPECT_LT(ang, bound) << "normal deviates " << ang << " deg";
    const ReferenceNormal s = ref.normal(1, 0, xb, xa);
    ASSERT_TRUE(s.valid);
    EXPECT_TRUE(s.penetrating);
    EXPECT_LT(deg(angle_between(s.normal, -r.normal)), 1e-3);
    // FCL's MPR path agrees in sign (and roughly in direction).
    const ReferenceNormal m = ref.fcl_collide_normal(0, 1, xa, xb);
    ASSERT_TRUE(m.valid);
    EXPECT_LT(deg(angle_between(m.normal, u)), 10.0);
    std::printf("intersecting icospheres: depth %.6f in [%.6f, %.6f], EPA %.3f deg "
                "(< %.3f), FCL MPR %.3f deg, MPR depth %.6f\n",
                r.depth, 2 * r_in - dist, 2 * r_out - dist, ang, bound,
                deg(angle_between(m.normal, u)), m.depth);
  }
}

// Icosphere above the floor (walls "floor": body 0 is the static slab with its top face at
// domain.min.y): normal +y, separated and touching-through cases.
TEST(ReferenceContact, IcosphereAboveFloorGivesPlusY) {
  const std::string json =
      R"({"name": "floor", "domain": {"min": [-1, 0, -1], "max": [1, 2, 1]}, "walls": "floor",
         "groups": [{"name": "s", "shape": )" + kSphere + R"(, "count": 1,
                     "positions": [[0, 0.5, 0]]}]})";
  const World world(scene_from_text(json, "floor"));
  ASSERT_EQ(world.bodies().size(), 2u);
  const ReferenceGeometry ref(world);
  const std::uint32_t floor = 0, sphere = 1;
  ASSERT_FALSE(world.shapes()[world.bodies()[floor].shape].mesh);
  const Vec3 xf = world.state().x[floor];
  const float top = xf.y + world.shapes()[world.bodies()[floor].shape].local.max.y;
  EXPECT_NEAR(top, 0.0f, 1e-6f);
  double r_out = 0, r_in = 0;
  radii(world.shapes()[world.bodies()[sphere].shape], r_out, r_in);
  // Separated by 0.02 (sphere A above floor B): +y, distance within the polyhedral error.
  const Vec3 xs = v3(0.13, 0.12, -0.07);
  const ReferenceNormal r = ref.normal(sphere, floor, xs, xf);
  ASSERT_TRUE(r.valid);
  EXPECT_FALSE(r.penetrating);
  EXPECT_LT(deg(angle_between(r.normal, {0, 1, 0})), 1e-3);
  EXPECT_GE(r.distance, 0.12 - r_out - 1e-6);
  EXPECT_LE(r.distance, 0.12 - r_in + 1e-6);
  // Sinking 0.01 into the floor: penetrating, +y, depth ~0.01 (the lowest point of the
  // polyhedron is within r_out - r_in of the sphere's).
  const Vec3 xp = v3(0.13, 0.09, -0.07);
  const ReferenceNormal p = ref.normal(sphere, floor, xp, xf);
  ASSERT_TRUE(p.valid);
  EXPECT_TRUE(p.penetrating);
  EXPECT_LT(deg(angle_between(p.normal, {0, 1, 0})), 1e-3);
  EXPECT_GE(p.depth, r_in - 0.09 - 1e-6);
  EXPECT_LE(p.depth, r_out - 0.09 + 1e-6);
  // Floor as A, sphere as B: normal -y.
  const ReferenceNormal q = ref.normal(floor, sphere, xf, xp);
  ASSERT_TRUE(q.valid);
  EXPECT_LT(deg(angle_between(q.normal, {0, -1, 0})), 1e-3);
}

TEST(ReferenceContact, BodyOutOfRangeThrows) {
  const World world(scene_from_text(two_bodies(kBox), "range"));
  const ReferenceGeometry ref(world);
  EXPECT_THROW(ref.normal(0, 2, {0, 0, 0}, {1, 0, 0}), InputError);
}

namespace {

/// FCL's own answer for two fcl::Box of sides sa, sb at ta, tb: fcl::collide with
/// CollisionRequest(8, true) and libccd, its deepest contact (the first of equal depths)
/// as B-to-A normal, depth and point; `hit` false when FCL reports no contact.
struct FclBoxes {
  bool hit = false;
  Vec3 normal, point;
  double depth = 0;
};
FclBoxes fcl_boxes(const fcl::Vector3d& sa, const fcl::Transform3d& ta, const fcl::Vector3d& sb,
                   const fcl::Transform3d& tb) {
  fcl::CollisionObjectd oa(std::make_shared<fcl::Boxd>(sa), ta), ob(std::make_shared<fcl::Boxd>(sb), tb);
  fcl::CollisionRequestd req(8, true);
  req.gjk_solver_type = fcl::GST_LIBCCD;
  fcl::CollisionResultd res;
  fcl::collide(&oa, &ob, req, res);
  FclBoxes out;
  if (res.numContacts() == 0) return out;
  std::size_t deepest = 0;
  for (std::size_t k = 1; k < res.numContacts(); ++k)
    if (res.getContact(k).penetration_depth > res.getContact(deepest).penetration_depth) deepest = k;
  const fcl::Contactd& c = res.getContact(deepest);
  const fcl::Vector3d n = -c.normal / c.normal.norm();
  out.hit = true;
  out.normal = v3(n.x(), n.y(), n.z());
  out.depth = std::max(0.0, c.penetration_depth);
  out.point = v3(c.pos.x(), c.pos.y(), c.pos.z());
  return out;
}

}  // namespace

// posed() on two boxes and aabb_pair() answer exactly what fcl::collide answers on
// fcl::Box objects at the same transforms (they call FCL's box-box routine directly):
// the same normal, depth and point, bit for bit, on 300 random overlapping pairs of
// turned boxes of different sides and on the world boxes of each.
TEST(ReferenceContact, BoxBoxIsFclCollideExactly) {
  const std::string text = R"({"name": "pair", "domain": {"min": [-2, -2, -2], "max": [2, 2, 2]}, "walls": "none",
    "groups": [{"name": "a", "shape": {"box": [0.1, 0.05, 0.08]}, "count": 1, "positions": [[0, 0, 0]]},
               {"name": "b", "shape": {"box": [0.07, 0.12, 0.04]}, "count": 1, "positions": [[0.5, 0, 0]]}]})";
  const World world(scene_from_text(text, "boxes_exact"));
  const ReferenceGeometry ref(world);
  std::mt19937 rng(11);
  std::uniform_real_distribution<float> pos(-0.15f, 0.15f), angle(-3.1f, 3.1f), axis(-1, 1);
  auto pose = [&](float scale) {
    Vec3 u = v3(axis(rng), axis(rng), axis(rng));
    const float n = std::sqrt(u.x * u.x + u.y * u.y + u.z * u.z);
    u = v3(u.x / n, u.y / n, u.z / n);
    return Pose{v3(scale * pos(rng), scale * pos(rng), scale * pos(rng)), axis_angle(u, angle(rng))};
  };
  // The FCL transform of a centred box at a pose, as ReferenceGeometry places it.
  auto transform = [](const Pose& p) -> fcl::Transform3d {
    fcl::Transform3d t = fcl::Transform3d::Identity();
    t.linear() = fcl::Quaterniond(p.orientation.w, p.orientation.x, p.orientation.y, p.orientation.z)
                     .normalized()
                     .toRotationMatrix();
    t.translation() = fcl::Vector3d(p.position.x, p.position.y, p.position.z) + t.linear() * fcl::Vector3d::Zero();
    return t;
  };
  auto side = [](const Aabb& b) -> fcl::Vector3d {
    return fcl::Vector3d(b.max.x, b.max.y, b.max.z) - fcl::Vector3d(b.min.x, b.min.y, b.min.z);
  };
  int hits = 0, aabb_hits = 0;
  for (int k = 0; k < 300; ++k) {
    const Pose pa = pose(1.0f), pb = pose(1.0f);
    const FclBoxes want = fcl_boxes(side(world.model().local_box(0)), transform(pa),
                                    side(world.model().local_box(1)), transform(pb));
    const ReferenceNormal got = ref.posed(0, 1, pa, pb);
    ASSERT_EQ(got.penetrating, want.hit) << "pair " << k;
    if (want.hit) {
      ++hits;
      ASSERT_TRUE(got.valid);
      EXPECT_EQ(got.depth, want.depth) << "pair " << k;
      EXPECT_TRUE(got.normal.x == want.normal.x && got.normal.y == want.normal.y && got.normal.z == want.normal.z)
          << "pair " << k;
      EXPECT_TRUE(got.point_a.x == want.point.x && got.point_a.y == want.point.y && got.point_a.z == want.point.z)
          << "pair " << k;
    }
    // The world boxes of the same poses, as an engine resolving on AABBs collides them.
    const Aabb wa = posed_box_aabb(world.model().local_box(0), pa), wb = posed_box_aabb(world.model().local_box(1), pb);
    fcl::Transform3d twa = fcl::Transform3d::Identity(), twb = fcl::Transform3d::Identity();
    twa.translation() = (fcl::Vector3d(wa.min.x, wa.min.y, wa.min.z) + fcl::Vector3d(wa.max.x, wa.max.y, wa.max.z)) * 0.5;
    twb.translation() = (fcl::Vector3d(wb.min.x, wb.min.y, wb.min.z) + fcl::Vector3d(wb.max.x, wb.max.y, wb.max.z)) * 0.5;
    const FclBoxes want_w = fcl_boxes(side(wa), twa, side(wb), twb);
    const ReferenceNormal got_w = ReferenceGeometry::aabb_pair(wa, wb);
    ASSERT_EQ(got_w.penetrating, want_w.hit) << "world boxes " << k;
    if (want_w.hit) {
      ++aabb_hits;
      EXPECT_EQ(got_w.depth, want_w.depth) << "world boxes " << k;
      EXPECT_TRUE(got_w.normal.x == want_w.normal.x && got_w.normal.y == want_w.normal.y &&
                  got_w.normal.z == want_w.normal.z)
          << "world boxes " << k;
      EXPECT_TRUE(got_w.point_a.x == want_w.point.x && got_w.point_a.y == want_w.point.y &&
                  got_w.point_a.z == want_w.point.z)
          << "world boxes " << k;
    }
  }
  // Most pairs meet (centres within 0.26 m of boxes 0.08-0.24 m across), some do not.
  EXPECT_GT(hits, 100);
  EXPECT_LT(hits, 300);
  EXPECT_GT(aabb_hits, hits);
}

// intersect() on two boxes (the separating axes where the boxes clearly penetrate or are
// clearly apart, GJK within the bands) against FCL's box-box test: the same answer on
// 5,000 random pairs of turned and axis-aligned boxes, except pairs within 1e-5 m of
// touching (FCL's depth, or the distance of the separated), where either answer is right.
TEST(ReferenceContact, BoxIntersectIsFclBoxBoxAwayFromTouching) {
  const std::string text = R"({"name": "pair", "domain": {"min": [-2, -2, -2], "max": [2, 2, 2]}, "walls": "none",
    "groups": [{"name": "a", "shape": {"box": [0.1, 0.05, 0.08]}, "count": 1, "positions": [[0, 0, 0]]},
               {"name": "b", "shape": {"box": [0.07, 0.12, 0.04]}, "count": 1, "positions": [[0.5, 0, 0]]}]})";
  const World world(scene_from_text(text, "boxes_intersect"));
  const ReferenceGeometry ref(world);
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> pos(-0.12f, 0.12f), angle(-3.1f, 3.1f), axis(-1, 1);
  std::uniform_int_distribution<int> turned(0, 2);
  auto pose = [&](bool turn) {
    Vec3 u = v3(axis(rng), axis(rng), axis(rng));
    const float n = std::sqrt(u.x * u.x + u.y * u.y + u.z * u.z);
    u = v3(u.x / n, u.y / n, u.z / n);
    return Pose{v3(pos(rng), pos(rng), pos(rng)), turn ? axis_angle(u, angle(rng)) : Quat{}};
  };
  int meet = 0, apart = 0;
  for (int k = 0; k < 5000; ++k) {
    const bool turn = turned(rng) > 0;
    const Pose pa = pose(turn), pb = pose(turn);
    const ReferenceNormal want = ref.posed(0, 1, pa, pb);  // FCL's box-box, FCL's distance when apart
    if (want.penetrating ? want.depth < 1e-5 : want.distance < 1e-5) continue;
    ASSERT_EQ(ref.intersect(0, 1, pa, pb), want.penetrating) << "pair " << k;
    (want.penetrating ? meet : apart) += 1;
  }
  EXPECT_GT(meet, 500);
  EXPECT_GT(apart, 500);
}
