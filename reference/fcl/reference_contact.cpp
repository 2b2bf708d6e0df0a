/// \file reference_contact.cpp
/// Reference contact normals from FCL 0.7 / libccd (design.md section 7 validator 3); see
/// reference_contact.hpp for the conventions.

#include "octocd/reference_contact.hpp"

#include <ccd/ccd.h>
#include <ccd/vec3.h>
#include <fcl/geometry/bvh/BVH_model.h>
#include <fcl/geometry/shape/box.h>
#include <fcl/geometry/shape/convex.h>
#include <fcl/geometry/shape/sphere.h>
#include <fcl/math/bv/OBBRSS.h>
#include <fcl/narrowphase/collision.h>
#include <fcl/narrowphase/distance.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <string>
#include <vector>

#include "octocd/convex_hull.hpp"
#include "octocd/error.hpp"

namespace octocd {

namespace {

using S = double;
using V3 = fcl::Vector3<S>;

/// FCL / libccd geometry of one shape, in the shape's local frame.
struct ShapeGeom {
  std::shared_ptr<fcl::CollisionGeometry<S>> exact;  ///< BVH model (mesh) or box
  std::shared_ptr<fcl::CollisionGeometry<S>> hull;   ///< fcl::Convex (mesh) or the same box
  /// Hull vertices in the body frame (boxes: 8 corners; meshes: hull vertices + offset).
  std::vector<V3> hull_vertices;
  /// Where the FCL geometry's own frame sits in the body frame: a box's local AABB
  /// centre (fcl::Box is centred on its frame); for a mesh, the local AABB centre minus
  /// the mesh's vertex bounds centre (0 for octocd's recentred meshes).
  V3 offset = V3::Zero();
  bool is_box = false;
  bool convex = true;  ///< box, or a mesh whose every triangle lies on its hull
  V3 half = V3::Zero();  ///< box half extents
  HullFeatures features;  ///< the hull for the separating-axis test (body frame)
  bool is_sphere = false;  ///< a declared sphere: centre `offset`, radius `radius`
  bool bvh = false;        ///< `exact` is a BVH model (a mesh collided as its triangles)
  S radius = 0;
  /// Points on the surface of the shape collided (body frame): a hull's face centroids, a
  /// box's corners and face centres, a sphere's 14 axis and diagonal points; for the gap
  /// between a declared shape and the true one (ReferenceGeometry::declared_gap).
  std::vector<V3> surface_samples;
};

/// Adds the unit direction of d to `dirs` unless it is (anti)parallel to one there.
void add_direction(std::vector<std::array<double, 3>>& dirs, const V3& d) {
  const S n = d.norm();
  if (!(n > 0) || !std::isfinite(n)) return;
  const V3 u = d / n;
  for (const auto& e : dirs)
    if (u.cross(V3(e[0], e[1], e[2])).norm() < 1e-9) return;
  dirs.push_back({u.x(), u.y(), u.z()});
}

/// A hull placed in the world for libccd: world = R v + position.
struct CcdObject {
  const std::vector<V3>* vertices;
  fcl::Matrix3<S> rotation;
  V3 position;
  S radius = 0;  ///< a sphere: its centre is the one vertex, its surface this far out
};

void ccd_support(const void* obj, const ccd_vec3_t* dir, ccd_vec3_t* out) {
  const auto* o = static_cast<const CcdObject*>(obj);
  const V3 d = o->rotation.transpose() * V3(ccdVec3X(dir), ccdVec3Y(dir), ccdVec3Z(dir));
  const V3* best = nullptr;
  S best_dot = -std::numeric_limits<S>::infinity();
  for (const V3& v : *o->vertices) {
    const S t = v.dot(d);
    if (t > best_dot) {
      best_dot = t;
      best = &v;
    }
  }
  V3 p = o->rotation * *best + o->position;
  if (o->radius > 0) {
    const V3 w(ccdVec3X(dir), ccdVec3Y(dir), ccdVec3Z(dir));
    const S n = w.norm();
    if (n > 0) p += (o->radius / n) * w;
  }
  ccdVec3Set(out, p.x(), p.y(), p.z());
}

void ccd_center(const void* obj, ccd_vec3_t* out) {
  const auto* o = static_cast<const CcdObject*>(obj);
  V3 c = V3::Zero();
  for (const V3& v : *o->vertices) c += v;
  c /= S(o->vertices->size());
  c = o->rotation * c + o->position;
  ccdVec3Set(out, c.x(), c.y(), c.z());
}

/// libccd settings of every query.
ccd_t make_ccd() {
  ccd_t ccd;
  CCD_INIT(&ccd);
  ccd.support1 = ccd_support;
  ccd.support2 = ccd_support;
  ccd.center1 = ccd_center;
  ccd.center2 = ccd_center;
  ccd.max_iterations = 1000;
  ccd.epa_tolerance = 1e-9;
  ccd.dist_tolerance = 1e-12;
  return ccd;
}

V3 to_v3(Vec3 v) { return V3(S(v.x), S(v.y), S(v.z)); }
Vec3 to_vec3(const V3& v) { return {float(v.x()), float(v.y()), float(v.z())}; }

/// Unit float vector of v, or false when v has no usable direction.
bool unit(const V3& v, Vec3& out) {
  const S n = v.norm();
  if (!(n > 0) || !std::isfinite(n)) return false;
  out = to_vec3(v / n);
  return true;
}

/// The 8 corners of the box [lo, hi].
std::vector<V3> corners(const V3& lo, const V3& hi) {
  std::vector<V3> out;
  for (int i = 0; i < 8; ++i)
    out.emplace_back((i & 1) ? hi.x() : lo.x(), (i & 2) ? hi.y() : lo.y(), (i & 4) ? hi.z() : lo.z());
  return out;
}

ShapeGeom build_box(const Shape& shape) {
  ShapeGeom g;
  const V3 lo = to_v3(shape.local.min), hi = to_v3(shape.local.max);
  g.offset = (lo + hi) * 0.5;
  const V3 side = hi - lo;
  auto box = std::make_shared<fcl::Box<S>>(side);
  box->computeLocalAABB();
  g.exact = box;
  g.hull = box;
  g.is_box = true;
  g.half = side * 0.5;
  g.hull_vertices = corners(lo, hi);  // body frame
  for (const V3& v : g.hull_vertices) g.features.vertices.push_back({v.x(), v.y(), v.z()});
  for (int k = 0; k < 3; ++k) {
    add_direction(g.features.face_normals, V3::Unit(k));
    add_direction(g.features.edge_dirs, V3::Unit(k));
  }
  g.surface_samples = g.hull_vertices;
  for (int k = 0; k < 3; ++k)
    for (S sign : {-1.0, 1.0}) g.surface_samples.push_back(g.offset + sign * g.half[k] * V3::Unit(k));
  return g;
}

ShapeGeom build_mesh(const Shape& shape) {
  ShapeGeom g;
  const Mesh& mesh = *shape.mesh;
  std::vector<V3> pts;
  pts.reserve(mesh.vertices.size());
  for (const Vec3& v : mesh.vertices) pts.push_back(to_v3(v));
  if (!pts.empty()) {
    V3 lo = pts[0], hi = pts[0];
    for (const V3& p : pts) {
      lo = lo.cwiseMin(p);
      hi = hi.cwiseMax(p);
    }
    g.offset = (to_v3(shape.local.min) + to_v3(shape.local.max)) * 0.5 - (lo + hi) * 0.5;
  }
  std::vector<fcl::Triangle> tris;
  tris.reserve(mesh.triangles.size());
  for (const auto& t : mesh.triangles) tris.emplace_back(t[0], t[1], t[2]);
  auto bvh = std::make_shared<fcl::BVHModel<fcl::OBBRSS<S>>>();
  bvh->beginModel(int(tris.size()), int(pts.size()));
  bvh->addSubModel(pts, tris);
  bvh->endModel();
  bvh->computeLocalAABB();
  g.exact = bvh;
  g.bvh = true;

  // The convex hull (convex_hull.hpp: qhull, the hull every adapter collides); its
  // vertices are mesh vertices, exact. A flat mesh spans no hull: its support is all its
  // vertices, its faces and edges the triangles'.
  ConvexHull hull;
  try {
    hull = convex_hull(mesh.vertices, shape.name);
  } catch (const InputError&) {
    for (const V3& p : pts) hull.vertices.push_back({p.x(), p.y(), p.z()});
  }
  auto verts = std::make_shared<std::vector<V3>>();
  for (const auto& v : hull.vertices) verts->emplace_back(v[0], v[1], v[2]);
  g.hull_vertices = *verts;
  for (V3& v : g.hull_vertices) v += g.offset;  // body frame
  for (const V3& v : g.hull_vertices) g.features.vertices.push_back({v.x(), v.y(), v.z()});
  auto faces = std::make_shared<std::vector<int>>();
  std::vector<std::pair<V3, S>> planes;  // unit outward normal, offset
  const int num_faces = static_cast<int>(hull.faces.size());
  for (std::size_t f = 0; f < hull.faces.size(); ++f) {
    const std::vector<std::uint32_t>& idx = hull.faces[f];  // counter-clockwise seen from outside, as FCL wants
    faces->push_back(int(idx.size()));
    faces->insert(faces->end(), idx.begin(), idx.end());
    const V3 n(hull.planes[f][0], hull.planes[f][1], hull.planes[f][2]);
    add_direction(g.features.face_normals, n);
    V3 c = V3::Zero();
    for (std::uint32_t v : idx) c += (*verts)[v];
    g.surface_samples.push_back(c / S(idx.size()) + g.offset);
    for (std::size_t k = 0; k < idx.size(); ++k)
      add_direction(g.features.edge_dirs, (*verts)[idx[(k + 1) % idx.size()]] - (*verts)[idx[k]]);
    planes.emplace_back(n, hull.planes[f][3]);
  }
  if (hull.faces.empty())
    for (const auto& t : mesh.triangles) {
      const V3 a = pts[t[0]], b = pts[t[1]], c = pts[t[2]];
      add_direction(g.features.face_normals, (b - a).cross(c - a));
      for (const V3& e : {V3(b - a), V3(c - b), V3(a - c)}) add_direction(g.features.edge_dirs, e);
      g.surface_samples.push_back((a + b + c) / S(3) + g.offset);
    }
  // Convex when every triangle lies in a face plane of the hull (within 1e-6 m, relative
  // to the mesh's size above 1 m): a vertex inside the hull, or a face across it (two
  // boxes side by side: every vertex on the hull, the facing sides inside), shows it is
  // not. Stops at the first such triangle.
  S extent = 1;
  for (const V3& p : pts) extent = std::max(extent, p.cwiseAbs().maxCoeff());
  const S tol = 1e-6 * extent;
  g.convex = !planes.empty();
  for (const auto& t : tris) {
    bool on_face = false;
    for (const auto& pl : planes) {
      if (std::abs(pl.first.dot(pts[std::size_t(t[0])]) - pl.second) <= tol &&
          std::abs(pl.first.dot(pts[std::size_t(t[1])]) - pl.second) <= tol &&
          std::abs(pl.first.dot(pts[std::size_t(t[2])]) - pl.second) <= tol) {
        on_face = true;
        break;
      }
    }
    if (!on_face) {
      g.convex = false;
      break;
    }
  }
  if (num_faces == 0) {  // flat: the triangles themselves
    g.hull = g.exact;
    return g;
  }
  auto convex = std::make_shared<fcl::Convex<S>>(verts, num_faces, faces, false);
  convex->computeLocalAABB();
  g.hull = convex;
  return g;
}


/// A declared sphere of a shape: centred on its local box, through its farthest mesh
/// vertex (the mesh placed as build_mesh places it). Boxes have none (a body's shape
/// cannot be a sphere when it is a box: PhysicsValidators refuses it).
ShapeGeom build_sphere(const Shape& shape) {
  ShapeGeom g;
  const V3 centre = (to_v3(shape.local.min) + to_v3(shape.local.max)) * 0.5;
  const ShapeGeom m = build_mesh(shape);
  S r = 0;
  for (const V3& v : m.hull_vertices) r = std::max(r, (v - centre).norm());
  g.is_sphere = true;
  g.radius = r;
  g.offset = centre;
  auto sphere = std::make_shared<fcl::Sphere<S>>(r);
  sphere->computeLocalAABB();
  g.exact = sphere;
  g.hull = sphere;
  g.hull_vertices = {centre};
  for (int k = 0; k < 3; ++k)
    for (S sign : {-1.0, 1.0}) g.surface_samples.push_back(centre + sign * r * V3::Unit(k));
  for (int i = 0; i < 8; ++i)
    g.surface_samples.push_back(centre + (r / std::sqrt(3.0)) * V3((i & 1) ? 1 : -1, (i & 2) ? 1 : -1, (i & 4) ? 1 : -1));
  return g;
}

/// The geometry body shapes are collided as (CollisionShape) for `shape`.
ShapeGeom build_declared(const Shape& shape, CollisionShape kind) {
  switch (kind) {
    case CollisionShape::Mesh: return shape.mesh ? build_mesh(shape) : build_box(shape);
    case CollisionShape::ConvexHull: {
      if (!shape.mesh) return build_box(shape);
      ShapeGeom g = build_mesh(shape);
      g.exact = g.hull;
      g.bvh = false;
      g.convex = true;
      return g;
    }
    case CollisionShape::Box: return build_box(shape);
    case CollisionShape::Sphere: return build_sphere(shape);
  }
  return build_box(shape);
}

/// Distance (m, >= 0) from the world point p to the surface of geometry g placed at
/// (r, x) (box: its faces, also from inside; sphere: | |p - c| - radius |; mesh: its
/// triangles, FCL sphere-BVH distance).
double geometry_surface_distance(const ShapeGeom& g, const fcl::Matrix3<S>& r, const V3& x, const V3& p);

/// The FCL transform of a shape's geometry frame for a body at (R, x): R, x + R offset.
fcl::Transform3<S> geometry_transform(const ShapeGeom& g, const fcl::Matrix3<S>& r, const V3& x) {
  fcl::Transform3<S> t = fcl::Transform3<S>::Identity();
  t.linear() = r;
  t.translation() = x + r * g.offset;
  return t;
}

fcl::Matrix3<S> rotation_of(const Pose& p) {
  const Quat q = p.orientation;
  const fcl::Quaternion<S> e(S(q.w), S(q.x), S(q.y), S(q.z));
  return e.normalized().toRotationMatrix();
}

/// Two bodies' shapes at their poses: each one's geometry, rotation, position and the FCL
/// transform of its geometry frame (geometry_transform). The shapes are referenced, not
/// copied: they must outlive it.
struct PosedShapes {
  PosedShapes(const ShapeGeom& a, const ShapeGeom& b, const Pose& pa, const Pose& pb)
      : ga(a),
        gb(b),
        ra(rotation_of(pa)),
        rb(rotation_of(pb)),
        xa(to_v3(pa.position)),
        xb(to_v3(pb.position)),
        ta(geometry_transform(a, ra, xa)),
        tb(geometry_transform(b, rb, xb)) {}
  const ShapeGeom& ga;
  const ShapeGeom& gb;
  fcl::Matrix3<S> ra, rb;
  V3 xa, xb;
  fcl::Transform3<S> ta, tb;
};

/// FCL collide on the exact geometries (boxes / BVH models): do they intersect?
bool exact_collide(const ShapeGeom& ga, const fcl::Transform3<S>& ta, const ShapeGeom& gb,
                   const fcl::Transform3<S>& tb) {
  fcl::CollisionRequest<S> req(1, false);
  req.gjk_solver_type = fcl::GST_LIBCCD;
  fcl::CollisionResult<S> res;
  fcl::collide(ga.exact.get(), ta, gb.exact.get(), tb, req, res);
  return res.isCollision();
}

/// FCL distance on the exact geometries, nearest points in the world frame.
void exact_distance(const ShapeGeom& ga, const fcl::Transform3<S>& ta, const ShapeGeom& gb,
                    const fcl::Transform3<S>& tb, ReferenceNormal& r) {
  fcl::DistanceRequest<S> req(true);  // enable_nearest_points
  req.gjk_solver_type = fcl::GST_LIBCCD;
  req.distance_tolerance = 1e-9;
  req.abs_err = 0;
  req.rel_err = 0;
  fcl::DistanceResult<S> res;
  // FCL 0.7 answers a shape (o1) against a BVH mesh (o2) with its nearest points
  // swapped (pinned by PosedReference.SeparatedMeshAboveFloorNormal): ask mesh first.
  const bool swap = !ga.bvh && gb.bvh;
  if (swap) {
    fcl::distance(gb.exact.get(), tb, ga.exact.get(), ta, req, res);
  } else {
    fcl::distance(ga.exact.get(), ta, gb.exact.get(), tb, req, res);
  }
  r.penetrating = false;
  r.distance = res.min_distance;
  // nearest_points[0] is on o1, [1] on o2, world frame (FCL 0.7).
  const V3 pa = res.nearest_points[swap ? 1 : 0], pb = res.nearest_points[swap ? 0 : 1];
  r.point_a = to_vec3(pa);
  r.point_b = to_vec3(pb);
  if (!(res.min_distance > 0) || !std::isfinite(res.min_distance)) return;
  r.valid = unit(pa - pb, r.normal);
}

/// libccd GJK + EPA on two placed hulls. Returns false when the hulls do not intersect;
/// otherwise fills r (penetrating; valid when EPA answered).
bool hull_penetration(const CcdObject& ca, const CcdObject& cb, ReferenceNormal& r) {
  ccd_t ccd = make_ccd();
  if (!ccdGJKIntersect(&ca, &cb, &ccd)) return false;
  r.penetrating = true;
  ccd_real_t depth = 0;
  ccd_vec3_t dir, pos;
  if (ccdGJKPenetration(&ca, &cb, &ccd, &depth, &dir, &pos) == 0) {
    // dir points from obj1 (A) towards obj2 (B): B-to-A is -dir.
    const V3 d(ccdVec3X(&dir), ccdVec3Y(&dir), ccdVec3Z(&dir));
    if (std::isfinite(depth) && unit(-d, r.normal)) {
      r.depth = std::max<S>(0, depth);
      r.point_a = r.point_b = Vec3{float(ccdVec3X(&pos)), float(ccdVec3Y(&pos)), float(ccdVec3Z(&pos))};
      r.valid = true;
    }
  }
  return true;
}

/// The minimum translation of two boxes by the separating-axis theorem (octocd's own box-box
/// reference): boxes of sides side_a, side_b, centred at ta, tb's translations with axes the
/// columns of their rotations. For two convex polytopes the least translation that separates
/// them is along a face normal of either or the cross product of an edge of each (Gottschalk);
/// along a unit axis u the boxes' projections overlap by
///   |ha . |R_a^T u|| + |hb . |R_b^T u|| - |(x_a - x_b) . u|   (m),
/// and the penetration depth is the least of the overlaps over the 6 face normals and the 9
/// edge-edge crosses (a cross shorter than 1e-12, two edges parallel within 1e-12 rad, gives
/// no axis: its plane is spanned by face normals already tested). The normal is that axis,
/// pointing from B to A (-u where x_a - x_b is perpendicular to it); equal overlaps keep the
/// first axis in the order A's faces, B's faces, then a_i x b_j by i then j. An edge-edge
/// cross is compared unnormalised (its overlap times its length, against the least so far
/// times its length); the least overlap is computed on its unit axis itself, so the depth
/// is the overlap along the returned normal up to double rounding of the sums (~1e-16 of
/// the boxes' and centres' scale). A negative overlap on any axis: apart (false, r untouched); all >= 0: penetrating
/// (touching: depth 0). The contact point (point_a == point_b) is the midpoint of the deepest
/// contact's witnesses, as libccd's EPA gives it: for a face axis, the incident box's
/// deepest point (its support toward the reference face; the centre of an edge or face of it
/// lying parallel to that face within 1e-9), clamped onto the reference face's rectangle, and
/// its projection on that face; for an edge-edge axis, the closest points of the two edges
/// along which the boxes touch (clamped to the edges).
bool box_contact(const V3& side_a, const fcl::Transform3<S>& ta, const V3& side_b, const fcl::Transform3<S>& tb,
                 ReferenceNormal& r) {
  const V3 ha = side_a * 0.5, hb = side_b * 0.5;
  const fcl::Matrix3<S> ra = ta.linear(), rb = tb.linear();
  const V3 xa = ta.translation(), xb = tb.translation();
  const V3 d = xa - xb;  // B's centre to A's, world
  // Every axis in A's frame: B's axes there are the columns of c = R_a^T R_b.
  const fcl::Matrix3<S> c = ra.transpose() * rb;
  const V3 da = ra.transpose() * d;
  S best = std::numeric_limits<S>::infinity();
  V3 best_u = V3::Zero();  // A's frame, unit, from B to A
  int best_axis = -1;      // 0-2 A's faces, 3-5 B's faces, 6 + 3 i + j: a_i x b_j
  // Overlap along the axis u (A's frame), scaled by |u|: ha . |u| + hb . |R_b^T u| - |d . u|.
  auto scaled_overlap = [&](const V3& u, S& t) {
    const S rad_a = ha[0] * std::abs(u[0]) + ha[1] * std::abs(u[1]) + ha[2] * std::abs(u[2]);
    const S rad_b = hb[0] * std::abs(c.col(0).dot(u)) + hb[1] * std::abs(c.col(1).dot(u)) +
                    hb[2] * std::abs(c.col(2).dot(u));
    t = da.dot(u);
    return rad_a + rad_b - std::abs(t);
  };
  // The unit axis u: false when it separates the boxes; the least overlap so far kept.
  auto axis = [&](const V3& u, int id) {
    S t = 0;
    const S overlap = scaled_overlap(u, t);
    if (overlap < 0) return false;
    if (overlap < best) {
      best = overlap;
      best_u = t > 0 ? u : V3(-u);
      best_axis = id;
    }
    return true;
  };
  for (int i = 0; i < 3; ++i)
    if (!axis(V3::Unit(i), i)) return false;
  // Two unturned boxes (world AABBs, an unturned pose): B's faces and the edge crosses are
  // A's face axes again, with the same overlaps bit for bit (c = I: every product by 0 or
  // 1 is exact), so A's three decide (equal overlaps keep A's).
  const bool unturned = ra == fcl::Matrix3<S>::Identity() && rb == fcl::Matrix3<S>::Identity();
  for (int j = 0; j < 3 && !unturned; ++j)
    if (!axis(c.col(j), 3 + j)) return false;
  // Edge-edge axes: the sign and the comparison with the least overlap on the unnormalised
  // cross (overlap x |u|); only a candidate for the least is normalised and taken as above.
  for (int i = 0; i < 3 && !unturned; ++i)
    for (int j = 0; j < 3; ++j) {
      const V3 u = V3::Unit(i).cross(V3(c.col(j)));
      const S len2 = u.squaredNorm();
      if (!(len2 > 1e-24)) continue;
      S t = 0;
      const S scaled = scaled_overlap(u, t);
      if (scaled < 0) return false;
      if (!(scaled * scaled < best * best * len2)) continue;
      if (!axis(u / std::sqrt(len2), 6 + 3 * i + j)) return false;
    }
  if (best_axis < 0 || !std::isfinite(best)) return false;
  const V3 n = ra * best_u;  // world, B to A
  r.penetrating = true;
  if (!unit(n, r.normal)) return true;
  r.depth = std::max<S>(0, best);
  // The contact point.
  // Support of a box (centre x, axes R, half extents h) toward the direction w: its deepest
  // vertex, or the centre of the edge or face that lies across w within 1e-9.
  auto support = [](const V3& x, const fcl::Matrix3<S>& rot, const V3& h, const V3& w) {
    V3 p = x;
    for (int k = 0; k < 3; ++k) {
      const S s = rot.col(k).dot(w);
      if (std::abs(s) > 1e-9) p += (s > 0 ? h[k] : -h[k]) * rot.col(k);
    }
    return p;
  };
  V3 point;
  if (best_axis < 6) {
    // Reference face: A's (its face toward B, on -n) or B's (toward A, on +n); the incident
    // box's deepest point toward it, clamped onto the face, lies `best` inside it.
    const bool a_face = best_axis < 3;
    const int k = best_axis % 3;
    const fcl::Matrix3<S>& rx = a_face ? ra : rb;
    const V3& x_ref = a_face ? xa : xb;
    const V3& h_ref = a_face ? ha : hb;
    const V3 deep = a_face ? support(xb, rb, hb, n) : support(xa, ra, ha, -n);
    V3 q = rx.transpose() * (deep - x_ref);
    for (int m = 0; m < 3; ++m)
      if (m != k) q[m] = std::min(h_ref[m], std::max(-h_ref[m], q[m]));
    point = x_ref + rx * q + (a_face ? -0.5 : 0.5) * best * n;
  } else {
    // Edge a_i of A (A's support toward B, -n) against edge b_j of B (its support toward A).
    const int i = (best_axis - 6) / 3, j = (best_axis - 6) % 3;
    const V3 ea = ra.col(i), eb = rb.col(j);
    V3 pa = support(xa, ra, ha, -n), pb = support(xb, rb, hb, n);
    pa -= ea * ea.dot(pa - xa);  // the edge's centre (its own axis is not a support direction)
    pb -= eb * eb.dot(pb - xb);
    const V3 w = pa - pb;
    const S e = ea.dot(eb), f = ea.dot(w), g = eb.dot(w), den = 1 - e * e;
    S s = 0, t = 0;
    if (den > 1e-24) {
      s = (e * g - f) / den;
      t = (g - e * f) / den;
    }
    s = std::min(ha[i], std::max(-ha[i], s));
    t = std::min(hb[j], std::max(-hb[j], t));
    point = 0.5 * ((pa + s * ea) + (pb + t * eb));
  }
  r.point_a = r.point_b = to_vec3(point);
  r.valid = std::isfinite(r.depth);
  return true;
}

/// Two boxes (half extents ha, hb; centres ta, tb; axes the columns of ra, rb) by the 15
/// separating axes: +1 when they overlap by more than `band_in` (m) along every axis
/// tested (they penetrate), -1 when an axis separates them by more than `band_out`, 0 in
/// between (touching within the bands: left to GJK). Any axis that separates the
/// projections separates the boxes, however rounded its direction; edge-edge axes of
/// (nearly) parallel edges, |e_a x e_b| < 1e-7, are not tested, so a penetration is claimed
/// only beyond band_in, larger than what such an axis could add (1e-7 x the boxes' scale).
/// Non-finite centres or rotations: 0.
int box_box_overlap_class(const V3& ha, const fcl::Matrix3<S>& ra, const V3& ta, const V3& hb,
                          const fcl::Matrix3<S>& rb, const V3& tb, S band_in, S band_out) {
  const V3 d = tb - ta;
  if (!d.allFinite() || !ra.allFinite() || !rb.allFinite()) return 0;
  // Separation along u scaled by |u|: |d . u| - (A's and B's half projections on u).
  auto scaled_separation = [&](const V3& u) {
    const S ra_n = ha[0] * std::abs(ra.col(0).dot(u)) + ha[1] * std::abs(ra.col(1).dot(u)) +
                   ha[2] * std::abs(ra.col(2).dot(u));
    const S rb_n = hb[0] * std::abs(rb.col(0).dot(u)) + hb[1] * std::abs(rb.col(1).dot(u)) +
                   hb[2] * std::abs(rb.col(2).dot(u));
    return std::abs(d.dot(u)) - (ra_n + rb_n);
  };
  // An axis separating by more than band_out decides -1 at once; +1 needs every axis tested
  // to overlap by more than band_in.
  bool all_in = true;
  auto face = [&](const V3& u) {
    const S len = u.norm();
    if (!(len >= 1e-7)) return false;
    const S sep = scaled_separation(u / len);
    if (sep > band_out) return true;
    all_in = all_in && sep < -band_in;
    return false;
  };
  for (int i = 0; i < 3; ++i)
    if (face(ra.col(i))) return -1;
  // Two unturned boxes: B's faces and the edge crosses are A's face axes again (the same
  // separations: products by 0 and 1 are exact), so A's three decide. (The crosses'
  // squared test could only turn a +1 whose overlap exceeds band_in by a rounding into a 0
  // left to GJK, which then finds the same intersection.)
  if (ra == fcl::Matrix3<S>::Identity() && rb == fcl::Matrix3<S>::Identity()) return all_in ? 1 : 0;
  for (int i = 0; i < 3; ++i)
    if (face(rb.col(i))) return -1;
  // Edge-edge crosses unnormalised: sep > band_out <=> s > band_out |u|, sep < -band_in
  // <=> s < -band_in |u| (s = sep |u|), compared squared.
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) {
      const V3 u = ra.col(i).cross(rb.col(j));
      const S len2 = u.squaredNorm();
      if (!(len2 >= 1e-14)) continue;
      const S s = scaled_separation(u);
      if (s > 0 && s * s > band_out * band_out * len2) return -1;
      all_in = all_in && s < 0 && s * s > band_in * band_in * len2;
    }
  return all_in ? 1 : 0;
}

/// The fcl::Box of a geometry, or null.
const fcl::Box<S>* as_box(const ShapeGeom& g) {
  return g.exact && g.exact->getNodeType() == fcl::GEOM_BOX ? static_cast<const fcl::Box<S>*>(g.exact.get()) : nullptr;
}

/// Two posed boxes as boxes: box_contact (the minimum translation over the 15 separating
/// axes; libccd's EPA on box corners can cycle without end on coplanar faces); a declared
/// sphere and a primitive: FCL's collide (sphere-box and sphere-sphere exact), its deepest
/// contact. FCL distance when apart.
ReferenceNormal box_box(const ShapeGeom& ga, const fcl::Transform3<S>& ta, const ShapeGeom& gb,
                        const fcl::Transform3<S>& tb) {
  ReferenceNormal r;
  const fcl::Box<S>* box_a = as_box(ga);
  const fcl::Box<S>* box_b = as_box(gb);
  if (box_a && box_b) {
    if (!box_contact(box_a->side, ta, box_b->side, tb, r)) exact_distance(ga, ta, gb, tb, r);
    return r;
  }
  fcl::CollisionRequest<S> req(8, true);
  req.gjk_solver_type = fcl::GST_LIBCCD;
  fcl::CollisionResult<S> res;
  fcl::collide(ga.exact.get(), ta, gb.exact.get(), tb, req, res);
  if (res.numContacts() == 0) {
    exact_distance(ga, ta, gb, tb, r);
    return r;
  }
  r.penetrating = true;
  std::size_t deepest = 0;
  for (std::size_t k = 1; k < res.numContacts(); ++k)
    if (res.getContact(k).penetration_depth > res.getContact(deepest).penetration_depth) deepest = k;
  const fcl::Contact<S>& c = res.getContact(deepest);
  // Contact::normal points from o1 (A) to o2 (B): B-to-A is its negation.
  if (!unit(-c.normal, r.normal)) return r;
  r.depth = std::max<S>(0, c.penetration_depth);
  r.point_a = r.point_b = to_vec3(c.pos);
  r.valid = std::isfinite(r.depth);
  return r;
}

}  // namespace

struct ReferenceGeometry::Impl {
  std::vector<ShapeGeom> shapes;
  std::vector<double> gaps;  ///< per entry of `shapes`: declared_gap
  std::vector<std::uint32_t> body_shape;

  const ShapeGeom& geom(std::uint32_t body) const {
    if (body >= body_shape.size()) {
      throw InputError("ReferenceGeometry: body " + std::to_string(body) + " out of range (" +
                       std::to_string(body_shape.size()) + " bodies)");
    }
    return shapes[body_shape[body]];
  }
};

ReferenceGeometry::ReferenceGeometry(const Engine& world) : ReferenceGeometry(world.model()) {}

ReferenceGeometry::ReferenceGeometry(const Model& model) : ReferenceGeometry(model, {}) {}

ReferenceGeometry::ReferenceGeometry(const Model& model, const std::vector<CollisionShape>& declared)
    : impl_(std::make_unique<Impl>()) {
  if (!declared.empty() && declared.size() != model.bodies.size())
    throw InputError("ReferenceGeometry: " + std::to_string(declared.size()) + " collision shapes for " +
                     std::to_string(model.bodies.size()) + " bodies; allowed: none or one per body");
  // One geometry per (shape, declared kind) in use; the true shape of each kind's shape
  // for the gap figure.
  std::map<std::pair<std::uint32_t, int>, std::uint32_t> ids;
  std::map<std::uint32_t, ShapeGeom> truth;
  for (std::size_t i = 0; i < model.bodies.size(); ++i) {
    const std::uint32_t shape = model.bodies[i].shape;
    const CollisionShape kind = declared.empty() ? CollisionShape::Mesh : declared[i];
    const auto key = std::make_pair(shape, static_cast<int>(kind));
    auto it = ids.find(key);
    if (it == ids.end()) {
      it = ids.emplace(key, static_cast<std::uint32_t>(impl_->shapes.size())).first;
      impl_->shapes.push_back(build_declared(model.shapes[shape], kind));
      double gap = 0;
      const Shape& s = model.shapes[shape];
      const bool same = kind == CollisionShape::Mesh || (!s.mesh && kind != CollisionShape::Sphere);
      if (!same) {
        auto t = truth.find(shape);
        if (t == truth.end()) t = truth.emplace(shape, build_declared(s, CollisionShape::Mesh)).first;
        const fcl::Matrix3<S> id = fcl::Matrix3<S>::Identity();
        for (const V3& p : impl_->shapes.back().surface_samples)
          gap = std::max(gap, geometry_surface_distance(t->second, id, V3::Zero(), p));
      }
      impl_->gaps.push_back(gap);
    }
    impl_->body_shape.push_back(it->second);
  }
}

double ReferenceGeometry::declared_gap(std::uint32_t body) const {
  impl_->geom(body);  // range check
  return impl_->gaps[impl_->body_shape[body]];
}

ReferenceGeometry::~ReferenceGeometry() = default;

ReferenceNormal ReferenceGeometry::fcl_collide_normal(std::uint32_t a, std::uint32_t b, Vec3 xa,
                                                      Vec3 xb) const {
  const ShapeGeom& ga = impl_->geom(a);
  const ShapeGeom& gb = impl_->geom(b);
  const fcl::Matrix3<S> id = fcl::Matrix3<S>::Identity();
  fcl::CollisionRequest<S> req(1, true);
  req.gjk_solver_type = fcl::GST_LIBCCD;
  fcl::CollisionResult<S> res;
  fcl::collide(ga.hull.get(), geometry_transform(ga, id, to_v3(xa)), gb.hull.get(),
               geometry_transform(gb, id, to_v3(xb)), req, res);
  ReferenceNormal r;
  r.penetrating = true;
  if (res.numContacts() == 0) return r;
  const fcl::Contact<S>& c = res.getContact(0);
  // Contact::normal points from o1 (A) to o2 (B): B-to-A is its negation.
  if (!unit(-c.normal, r.normal)) return r;
  r.depth = std::max<S>(0, c.penetration_depth);
  r.point_a = r.point_b = to_vec3(c.pos);
  r.valid = std::isfinite(r.depth);
  return r;
}

ReferenceNormal ReferenceGeometry::normal(std::uint32_t a, std::uint32_t b, Vec3 xa,
                                          Vec3 xb) const {
  const ShapeGeom& ga = impl_->geom(a);
  const ShapeGeom& gb = impl_->geom(b);
  ReferenceNormal r;
  const fcl::Matrix3<S> id = fcl::Matrix3<S>::Identity();
  // 1. Do the hulls intersect? (libccd GJK on the hull vertices.)
  const CcdObject ca{&ga.hull_vertices, id, to_v3(xa), ga.radius};
  const CcdObject cb{&gb.hull_vertices, id, to_v3(xb), gb.radius};
  if (hull_penetration(ca, cb, r)) {
    if (r.valid) return r;
    return fcl_collide_normal(a, b, xa, xb);  // EPA failed: FCL's MPR estimate
  }
  // 2. Separated: FCL distance on the exact geometry (BVH models / boxes).
  exact_distance(ga, geometry_transform(ga, id, to_v3(xa)), gb, geometry_transform(gb, id, to_v3(xb)), r);
  return r;
}

bool ReferenceGeometry::intersect(std::uint32_t a, std::uint32_t b, const Pose& pa, const Pose& pb) const {
  const ShapeGeom& ga = impl_->geom(a);
  const ShapeGeom& gb = impl_->geom(b);
  const fcl::Matrix3<S> ra = rotation_of(pa), rb = rotation_of(pb);
  if (ga.is_box && gb.is_box && ga.radius == 0 && gb.radius == 0) {
    // Two boxes that clearly penetrate or are clearly apart: the separating axes decide
    // (GJK's answer on their corners, whose error is orders of magnitude below the bands);
    // pairs within the bands of touching go to GJK below. Bands: 1e-6 (penetrating) and
    // 1e-9 (apart) of the boxes' and the centres' scale (m, at least 1).
    const V3 xa = to_v3(pa.position) + ra * ga.offset, xb = to_v3(pb.position) + rb * gb.offset;
    const S scale = 1 + ga.half.maxCoeff() + gb.half.maxCoeff() + xa.cwiseAbs().maxCoeff() + xb.cwiseAbs().maxCoeff();
    const int c = box_box_overlap_class(ga.half, ra, xa, gb.half, rb, xb, 1e-6 * scale, 1e-9 * scale);
    if (c != 0) return c > 0;
  }
  const CcdObject ca{&ga.hull_vertices, ra, to_v3(pa.position), ga.radius};
  const CcdObject cb{&gb.hull_vertices, rb, to_v3(pb.position), gb.radius};
  ccd_t ccd = make_ccd();
  if (!ccdGJKIntersect(&ca, &cb, &ccd)) return false;
  if (ga.convex && gb.convex) return true;
  return exact_collide(ga, geometry_transform(ga, ra, to_v3(pa.position)), gb,
                       geometry_transform(gb, rb, to_v3(pb.position)));
}

ReferenceNormal ReferenceGeometry::posed(std::uint32_t a, std::uint32_t b, const Pose& pa, const Pose& pb) const {
  const PosedShapes pq(impl_->geom(a), impl_->geom(b), pa, pb);
  ReferenceNormal r;
  if (pq.ga.is_box && pq.gb.is_box) return box_box(pq.ga, pq.ta, pq.gb, pq.tb);
  // A declared sphere against a primitive or a hull: FCL's own test (sphere-box and
  // sphere-sphere exact, GJK/EPA on its sphere support otherwise); libccd's EPA on a
  // sphere's support may stop short when the centres coincide.
  if ((pq.ga.is_sphere || pq.gb.is_sphere) && !pq.ga.bvh && !pq.gb.bvh) return box_box(pq.ga, pq.ta, pq.gb, pq.tb);
  const CcdObject ca{&pq.ga.hull_vertices, pq.ra, pq.xa, pq.ga.radius};
  const CcdObject cb{&pq.gb.hull_vertices, pq.rb, pq.xb, pq.gb.radius};
  if (hull_penetration(ca, cb, r)) {
    if (pq.ga.convex && pq.gb.convex) return r;  // exact: EPA on the shapes themselves
    if (!exact_collide(pq.ga, pq.ta, pq.gb, pq.tb)) {
      // Hulls meet, the meshes do not: separated, BVH distance.
      ReferenceNormal d;
      exact_distance(pq.ga, pq.ta, pq.gb, pq.tb, d);
      return d;
    }
    if (!r.valid) return r;
    // The meshes intersect: the smallest translation of A along the hulls' normal that
    // separates the meshes (bisection; the hull depth separates them).
    r.depth_upper_bound = true;
    // Directional depths: the smallest translation of A along a direction that separates
    // the meshes is an upper bound of the minimum translation; the least over a few
    // directions is the tighter bound. Directions: the hulls' EPA normal first, then the
    // centre line (B to A) and the six axes. A direction is bisected only when it
    // separates the meshes within the best depth so far.
    auto separated_at = [&](const V3& n, S t) {
      fcl::Transform3<S> moved = pq.ta;
      moved.translation() += t * n;
      return !exact_collide(pq.ga, moved, pq.gb, pq.tb);
    };
    std::vector<V3> dirs = {to_v3(r.normal)};
    const V3 centre_line = pq.xa + pq.ra * pq.ga.offset - (pq.xb + pq.rb * pq.gb.offset);
    if (centre_line.norm() > 0) dirs.push_back(centre_line.normalized());
    for (int k = 0; k < 3; ++k) {
      dirs.push_back(V3::Unit(k));
      dirs.push_back(-V3::Unit(k));
    }
    S best = r.depth + 1e-6;
    std::size_t best_dir = 0;
    bool found = false;
    for (std::size_t d = 0; d < dirs.size(); ++d) {
      S hi = best;
      if (d == 0)
        for (int k = 0; k < 8 && !separated_at(dirs[d], hi); ++k) hi = hi * 1.5 + 1e-6;
      if (!separated_at(dirs[d], hi)) continue;
      S lo = 0;
      while (hi - lo > 1e-6) {
        const S mid = 0.5 * (lo + hi);
        (separated_at(dirs[d], mid) ? hi : lo) = mid;
      }
      if (!found || hi < best) {
        best = hi;
        best_dir = d;
        found = true;
      }
    }
    if (!found) return r;  // keep the hull depth
    r.depth = best;
    if (best_dir != 0) r.normal = to_vec3(dirs[best_dir]);
    return r;
  }
  exact_distance(pq.ga, pq.ta, pq.gb, pq.tb, r);
  return r;
}

namespace {
/// Whether the point q (geometry frame of g) lies inside the shape g: a box's faces, a
/// mesh's generalised winding number (the sum of its triangles' signed solid angles seen
/// from q, over 4 pi; either orientation of the triangles) above 1/2. Spheres: never.
bool geometry_contains(const ShapeGeom& g, const V3& q) {
  if (g.is_box) return (q.cwiseAbs() - g.half).maxCoeff() < 0;
  if (!g.bvh) return false;
  const auto* m = static_cast<const fcl::BVHModel<fcl::OBBRSS<S>>*>(g.exact.get());
  const fcl::AABB<S>& box = m->aabb_local;
  for (int k = 0; k < 3; ++k)
    if (q[k] < box.min_[k] || q[k] > box.max_[k]) return false;
  S omega = 0;
  for (int t = 0; t < m->num_tris; ++t) {
    const fcl::Triangle& tri = m->tri_indices[t];
    const V3 a = m->vertices[tri[0]] - q, b = m->vertices[tri[1]] - q, c = m->vertices[tri[2]] - q;
    const S la = a.norm(), lb = b.norm(), lc = c.norm();
    // Van Oosterom and Strackee: tan(omega / 2) = a.(b x c) / (la lb lc + (a.b) lc + (a.c) lb + (b.c) la).
    omega += 2 * std::atan2(a.dot(b.cross(c)), la * lb * lc + a.dot(b) * lc + a.dot(c) * lb + b.dot(c) * la);
  }
  return std::abs(omega) > 2 * fcl::constants<S>::pi();
}

/// The vertices of g in its geometry frame: a mesh's, a box's 8 corners, a declared hull's;
/// none for a sphere.
std::vector<V3> geometry_vertices(const ShapeGeom& g) {
  if (g.is_box) return corners(-g.half, g.half);
  std::vector<V3> out;
  if (g.is_sphere) return out;
  if (!g.bvh) {  // a declared convex hull: its vertices (body frame) in the geometry frame
    for (const V3& v : g.hull_vertices) out.push_back(v - g.offset);
    return out;
  }
  const auto* m = static_cast<const fcl::BVHModel<fcl::OBBRSS<S>>*>(g.exact.get());
  out.assign(m->vertices, m->vertices + m->num_vertices);
  return out;
}
}  // namespace

PenetrationWitness ReferenceGeometry::penetration_witness(std::uint32_t a, std::uint32_t b, const Pose& pa,
                                                          const Pose& pb, double floor) const {
  const PosedShapes pq(impl_->geom(a), impl_->geom(b), pa, pb);
  PenetrationWitness w;
  {
    fcl::CollisionRequest<S> req(1, true);
    req.gjk_solver_type = fcl::GST_LIBCCD;
    fcl::CollisionResult<S> res;
    fcl::collide(pq.ga.exact.get(), pq.ta, pq.gb.exact.get(), pq.tb, req, res);
    if (!res.isCollision()) return w;
    w.intersect = true;
    if (res.numContacts() > 0) {
      const fcl::Contact<S>& c = res.getContact(0);
      if (pq.ga.bvh) w.triangle_a = static_cast<int>(c.b1);
      if (pq.gb.bvh) w.triangle_b = static_cast<int>(c.b2);
    }
  }
  // Each shape's vertices against the other: the surface distance (cheap, BVH) first,
  // the inside test only for a vertex that would deepen the bound.
  auto search = [&](std::uint32_t body, const ShapeGeom& g, const fcl::Transform3<S>& t, const ShapeGeom& other,
                    const fcl::Matrix3<S>& r_other, const V3& x_other, const fcl::Transform3<S>& t_other) {
    const fcl::Transform3<S> to_other = t_other.inverse() * t;
    const std::vector<V3> vs = geometry_vertices(g);
    for (std::size_t i = 0; i < vs.size(); ++i) {
      const V3 q = to_other * vs[i];
      const fcl::AABB<S>& box = other.exact->aabb_local;
      bool in_box = true;
      for (int k = 0; k < 3; ++k) in_box = in_box && q[k] >= box.min_[k] && q[k] <= box.max_[k];
      if (!in_box) continue;
      const V3 p = t * vs[i];
      const S d = geometry_surface_distance(other, r_other, x_other, p);
      if (!(d > floor) || !(d > w.depth)) continue;
      if (!geometry_contains(other, q)) continue;
      w.depth = d;
      w.vertex_body = body;
      w.vertex = std::int64_t(i);
      w.vertex_point = to_vec3(p);
    }
  };
  search(a, pq.ga, pq.ta, pq.gb, pq.rb, pq.xb, pq.tb);
  search(b, pq.gb, pq.tb, pq.ga, pq.ra, pq.xa, pq.ta);
  return w;
}

double ReferenceGeometry::surface_distance(std::uint32_t body, const Pose& pose, Vec3 p) const {
  return geometry_surface_distance(impl_->geom(body), rotation_of(pose), to_v3(pose.position), to_v3(p));
}

namespace {
double geometry_surface_distance(const ShapeGeom& g, const fcl::Matrix3<S>& r, const V3& x, const V3& p) {
  if (g.is_box) {
    const V3 q = r.transpose() * (p - x) - g.offset;
    const V3 out = (q.cwiseAbs() - g.half).cwiseMax(0.0);
    if (out.squaredNorm() > 0) return out.norm();
    return (g.half - q.cwiseAbs()).minCoeff();  // inside: to the nearest face
  }
  if (g.is_sphere) return std::abs((p - (x + r * g.offset)).norm() - g.radius);
  auto sphere = std::make_shared<fcl::Sphere<S>>(1e-9);
  sphere->computeLocalAABB();
  fcl::Transform3<S> tp = fcl::Transform3<S>::Identity();
  tp.translation() = p;
  fcl::DistanceRequest<S> req(false);
  req.gjk_solver_type = fcl::GST_LIBCCD;
  fcl::DistanceResult<S> res;
  fcl::distance(sphere.get(), tp, g.exact.get(), geometry_transform(g, r, x), req, res);
  return std::max<S>(0, res.min_distance + 1e-9);
}
}  // namespace

Aabb ReferenceGeometry::world_aabb(std::uint32_t body, const Pose& pose) const {
  const ShapeGeom& g = impl_->geom(body);
  if (g.is_sphere) {
    const V3 c = rotation_of(pose) * g.offset + to_v3(pose.position);
    Aabb out;
    for (int k = 0; k < 3; ++k) {
      out.min[k] = std::nextafter(float(c[k] - g.radius), -std::numeric_limits<float>::infinity());
      out.max[k] = std::nextafter(float(c[k] + g.radius), std::numeric_limits<float>::infinity());
    }
    return out;
  }
  if (g.is_box) {
    Aabb local;
    const V3 lo = g.offset - g.half, hi = g.offset + g.half;
    local.min = to_vec3(lo);
    local.max = to_vec3(hi);
    return posed_box_aabb(local, pose);
  }
  const fcl::Matrix3<S> r = rotation_of(pose);
  const V3 x = to_v3(pose.position);
  V3 lo = V3::Constant(std::numeric_limits<S>::infinity()), hi = -lo;
  for (const V3& v : g.hull_vertices) {
    const V3 w = r * v + x;
    lo = lo.cwiseMin(w);
    hi = hi.cwiseMax(w);
  }
  Aabb out;
  for (int k = 0; k < 3; ++k) {
    out.min[k] = std::nextafter(float(lo[k]), -std::numeric_limits<float>::infinity());
    out.max[k] = std::nextafter(float(hi[k]), std::numeric_limits<float>::infinity());
  }
  return out;
}

bool ReferenceGeometry::convex(std::uint32_t body) const { return impl_->geom(body).convex; }

const HullFeatures& ReferenceGeometry::hull_features(std::uint32_t body) const { return impl_->geom(body).features; }

ReferenceNormal ReferenceGeometry::aabb_pair(const Aabb& a, const Aabb& b) {
  const fcl::Matrix3<S> id = fcl::Matrix3<S>::Identity();
  ShapeGeom ga, gb;
  const V3 side_a = to_v3(a.max) - to_v3(a.min), side_b = to_v3(b.max) - to_v3(b.min);
  ga.offset = (to_v3(a.min) + to_v3(a.max)) * 0.5;
  gb.offset = (to_v3(b.min) + to_v3(b.max)) * 0.5;
  const fcl::Transform3<S> ta = geometry_transform(ga, id, V3::Zero()), tb = geometry_transform(gb, id, V3::Zero());
  ReferenceNormal r;
  if (box_contact(side_a, ta, side_b, tb, r)) return r;
  // Apart: FCL's distance needs the boxes as geometry.
  ga.exact = std::make_shared<fcl::Box<S>>(side_a);
  gb.exact = std::make_shared<fcl::Box<S>>(side_b);
  exact_distance(ga, ta, gb, tb, r);
  return r;
}

double angle_between(Vec3 u, Vec3 v) {
  const V3 a = to_v3(u), b = to_v3(v);
  return std::atan2(a.cross(b).norm(), a.dot(b));
}

}  // namespace octocd
