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
#include <fcl/narrowphase/detail/primitive_shape_algorithm/box_box.h>

#include "octocd/error.hpp"
#include "octocd/reference_contact.hpp"
#include "octocd/scene.hpp"
#include "octocd/world.hpp"

// This file's own names (its tests compile in unity batches with the folder's other files).
namespace octocd_test_reference_contact {

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


// posed() on two boxes and aabb_pair() (octocd's box-box: the least overlap over the 15
// separating axes) against FCL's box-box routine (fcl::detail::boxBox2, ODE's dBoxBox), the
// oracle, on 6,000 pose pairs: turned boxes (face and edge-edge minima), axis-aligned ones
// (face-face, equal overlaps on several axes), near-parallel ones (B turned 1e-7 to 1e-2 rad
// from A) and touching ones (A moved out along the answer's normal by its depth), and the
// world boxes of each. FCL's depth is the overlap along its own axis (its `depth` output);
// it keeps a face axis unless an edge-edge axis overlaps less than 1/1.05 of it, so:
//  - the same verdict (FCL's code 0 <=> apart) except within 1e-9 m of touching;
//  - our depth D <= FCL's d_F + tol (the minimum is at most FCL's axis's overlap) and
//    d_F <= 1.05 D + tol (FCL's face preference); where d_F <= D + tol (FCL took a minimal
//    axis) the normals agree within 1e-5 rad, or FCL's axis overlaps by D too (a tie: both
//    are minimum translations); the contact point lies within D + 1e-6 m of both boxes;
//  - our normal is the least translation: projecting the 16 corners on it (the normal is
//    float: ~6e-8 rad) gives D within 1e-6 m.
// tol = 1e-9 m: each overlap is a sum of about seven double products of terms below 0.5 m
// (rounding ~1e-15 m); FCL pads |R| by 10 eps, which adds up to ~2e-15 m / |a_i x b_j| on
// an edge-edge axis: below 1e-9 m while the edges are more than 1e-6 rad from parallel
// (its nearly parallel edge axes only grow, never chosen as the minimum).
TEST(ReferenceContact, BoxBoxIsTheMinimumOverFclBoxBox) {
  const std::string text = R"({"name": "pair", "domain": {"min": [-2, -2, -2], "max": [2, 2, 2]}, "walls": "none",
    "groups": [{"name": "a", "shape": {"box": [0.1, 0.05, 0.08]}, "count": 1, "positions": [[0, 0, 0]]},
               {"name": "b", "shape": {"box": [0.07, 0.12, 0.04]}, "count": 1, "positions": [[0.5, 0, 0]]}]})";
  const World world(scene_from_text(text, "boxes_exact"));
  const ReferenceGeometry ref(world);
  std::mt19937 rng(11);
  std::uniform_real_distribution<float> pos(-0.15f, 0.15f), angle(-3.1f, 3.1f), axis(-1, 1), expo(-7, -2);
  auto random_axis = [&] {
    Vec3 u = v3(axis(rng), axis(rng), axis(rng));
    const float n = std::sqrt(u.x * u.x + u.y * u.y + u.z * u.z);
    return v3(u.x / n, u.y / n, u.z / n);
  };
  auto position = [&] { return v3(pos(rng), pos(rng), pos(rng)); };
  auto rotation = [](const Quat& q) -> fcl::Matrix3d {
    return fcl::Quaterniond(q.w, q.x, q.y, q.z).normalized().toRotationMatrix();
  };
  // A centred box as ReferenceGeometry places it, and the same box's world AABB.
  auto transform = [&](const Pose& p) -> fcl::Transform3d {
    fcl::Transform3d t = fcl::Transform3d::Identity();
    t.linear() = rotation(p.orientation);
    t.translation() = fcl::Vector3d(p.position.x, p.position.y, p.position.z);
    return t;
  };
  auto side_of = [](const Aabb& b) -> fcl::Vector3d {
    return fcl::Vector3d(b.max.x, b.max.y, b.max.z) - fcl::Vector3d(b.min.x, b.min.y, b.min.z);
  };
  const double tol = 1e-9;
  struct Box {
    fcl::Vector3d side;
    fcl::Transform3d t;
  };
  // The translation of A along the unit n that separates the boxes' 8 corners each.
  auto overlap_along = [](const Box& a, const Box& b, const fcl::Vector3d& n) {
    double a_lo = 1e30, b_hi = -1e30;
    for (int i = 0; i < 8; ++i) {
      const fcl::Vector3d c((i & 1) ? 0.5 : -0.5, (i & 2) ? 0.5 : -0.5, (i & 4) ? 0.5 : -0.5);
      a_lo = std::min(a_lo, n.dot(a.t * c.cwiseProduct(a.side)));
      b_hi = std::max(b_hi, n.dot(b.t * c.cwiseProduct(b.side)));
    }
    return b_hi - a_lo;
  };
  auto outside = [](const Box& b, const fcl::Vector3d& p) {
    const fcl::Vector3d q = b.t.linear().transpose() * (p - b.t.translation());
    return (q.cwiseAbs() - 0.5 * b.side).cwiseMax(0.0).norm();
  };
  auto dv = [](Vec3 v) { return fcl::Vector3d(v.x, v.y, v.z); };
  int hits[4] = {0, 0, 0, 0}, apart = 0, edge_min = 0, face_min = 0, fcl_face_deeper = 0, ties = 0, same = 0;
  // One pair: FCL's box-box and ours agree as the comment above says; returns ours.
  auto check = [&](const Box& a, const Box& b, const ReferenceNormal& got, int category, const std::string& what) {
    fcl::Vector3d normal;
    double depth = 0;
    int code = 0;
    std::vector<fcl::ContactPointd> contacts;
    fcl::detail::boxBox2(a.side, a.t, b.side, b.t, normal, &depth, &code, 4, contacts);
    const bool fcl_hit = code != 0;
    if (fcl_hit != got.penetrating) {
      // Only at touching: FCL's depth or our distance within tol.
      EXPECT_LE(fcl_hit ? depth : got.distance, tol) << what;
      return;
    }
    if (!fcl_hit) {
      ++apart;
      return;
    }
    ++hits[category];
    ASSERT_TRUE(got.valid) << what;
    const double D = got.depth;
    const fcl::Vector3d n_fcl = -normal.normalized();  // B to A
    EXPECT_LE(D, depth + tol) << what;
    EXPECT_LE(depth, 1.05 * D + tol) << what;
    const fcl::Vector3d n = dv(got.normal).normalized();
    EXPECT_NEAR(overlap_along(a, b, n), D, 1e-6) << what;
    const double between = std::atan2(n.cross(n_fcl).norm(), n.dot(n_fcl));
    if (depth <= D + tol) {
      if (between <= 1e-5) {
        ++same;
      } else {
        ++ties;
        EXPECT_NEAR(overlap_along(a, b, n_fcl), D, 1e-6) << what << " (FCL's axis: a tie)";
      }
    } else {
      ++fcl_face_deeper;  // FCL's axis overlaps more (a face kept, or a nearly parallel one)
    }
    const fcl::Vector3d p = dv(got.point_a);
    EXPECT_LE(outside(a, p), D + 1e-6) << what;
    EXPECT_LE(outside(b, p), D + 1e-6) << what;
    bool face = false;
    for (const Box* x : {&a, &b})
      for (int k = 0; k < 3; ++k) face = face || std::abs(x->t.linear().col(k).dot(n)) > 1 - 1e-6;
    (face ? face_min : edge_min) += 1;
  };
  const fcl::Vector3d side_a = side_of(world.model().local_box(0)), side_b = side_of(world.model().local_box(1));
  for (int k = 0; k < 6000; ++k) {
    const int category = k % 4;  // 0 turned, 1 axis-aligned, 2 near-parallel, 3 touching
    Pose pa{position(), category == 1 ? Quat{} : axis_angle(random_axis(), angle(rng))};
    Pose pb{position(), category == 1 ? Quat{} : axis_angle(random_axis(), angle(rng))};
    if (category == 2) pb.orientation = normalized(pa.orientation * axis_angle(random_axis(), std::pow(10.0f, expo(rng))));
    if (category == 3) {
      const ReferenceNormal r = ref.posed(0, 1, pa, pb);
      if (!r.penetrating || !r.valid) continue;
      pa.position = pa.position + float(r.depth) * r.normal;
    }
    const std::string what = "pair " + std::to_string(k) + " category " + std::to_string(category);
    const Box a{side_a, transform(pa)}, b{side_b, transform(pb)};
    const ReferenceNormal got = ref.posed(0, 1, pa, pb);
    if (category == 3) {
      // Moved out by the depth (float poses: within 1e-6 m): touching.
      EXPECT_LT(got.penetrating ? got.depth : got.distance, 1e-6) << what;
    }
    check(a, b, got, category, what);
    // The world boxes of the same poses, as an engine resolving on AABBs collides them.
    const Aabb wa = posed_box_aabb(world.model().local_box(0), pa), wb = posed_box_aabb(world.model().local_box(1), pb);
    Box aw{side_of(wa), fcl::Transform3d::Identity()}, bw{side_of(wb), fcl::Transform3d::Identity()};
    aw.t.translation() = (dv(wa.min) + dv(wa.max)) * 0.5;
    bw.t.translation() = (dv(wb.min) + dv(wb.max)) * 0.5;
    check(aw, bw, ReferenceGeometry::aabb_pair(wa, wb), 1, what + " (world boxes)");
  }
  // Every kind of pair met: each category penetrates often, both kinds of minimum occur,
  // FCL's axis is deeper, and most answers are FCL's own axis.
  for (int c = 0; c < 4; ++c) EXPECT_GT(hits[c], 300) << "category " << c;
  EXPECT_GT(apart, 300);
  EXPECT_GT(edge_min, 100);
  EXPECT_GT(face_min, 1000);
  EXPECT_GT(fcl_face_deeper, 20);
  EXPECT_GT(same, 5 * (ties + fcl_face_deeper));
  std::printf("box-box against FCL: %d/%d/%d/%d penetrating (turned, aligned and world, near-parallel, touching), "
              "%d apart; minimum on a face %d, edge-edge %d; FCL's axis the same %d, a tie %d, a deeper face %d\n",
              hits[0], hits[1], hits[2], hits[3], apart, face_min, edge_min, same, ties, fcl_face_deeper);
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

}  // namespace octocd_test_reference_contact
