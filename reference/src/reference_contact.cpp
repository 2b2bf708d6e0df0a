/// \file reference_contact.cpp
/// Reference contact normals from FCL 0.7 / libccd (SPEC 7 validator 3); see
/// reference_contact.hpp for the conventions.

#include "octocd/reference_contact.hpp"

#include <LinearMath/btConvexHullComputer.h>
#include <ccd/ccd.h>
#include <ccd/vec3.h>
#include <fcl/geometry/bvh/BVH_model.h>
#include <fcl/geometry/shape/box.h>
#include <fcl/geometry/shape/convex.h>
#include <fcl/math/bv/OBBRSS.h>
#include <fcl/narrowphase/collision.h>
#include <fcl/narrowphase/collision_object.h>
#include <fcl/narrowphase/distance.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>
#include <vector>

#include "octocd/error.hpp"

namespace octocd {

namespace {

using S = double;
using V3 = fcl::Vector3<S>;

/// FCL / libccd geometry of one shape, in the shape's local frame.
struct ShapeGeom {
  std::shared_ptr<fcl::CollisionGeometry<S>> exact;  ///< BVH model (mesh) or box
  std::shared_ptr<fcl::CollisionGeometry<S>> hull;   ///< fcl::Convex (mesh) or the same box
  std::vector<V3> hull_vertices;                     ///< hull vertices (boxes: 8 corners)
  V3 offset = V3::Zero();  ///< local AABB centre (0 for our shapes; boxes are built around it)
};

/// A hull placed in the world for libccd (translation only).
struct CcdObject {
  const std::vector<V3>* vertices;
  V3 position;
};

void ccd_support(const void* obj, const ccd_vec3_t* dir, ccd_vec3_t* out) {
  const auto* o = static_cast<const CcdObject*>(obj);
  const V3 d(ccdVec3X(dir), ccdVec3Y(dir), ccdVec3Z(dir));
  const V3* best = nullptr;
  S best_dot = -std::numeric_limits<S>::infinity();
  for (const V3& v : *o->vertices) {
    const S t = v.dot(d);
    if (t > best_dot) {
      best_dot = t;
      best = &v;
    }
  }
  const V3 p = *best + o->position;
  ccdVec3Set(out, p.x(), p.y(), p.z());
}

void ccd_center(const void* obj, ccd_vec3_t* out) {
  const auto* o = static_cast<const CcdObject*>(obj);
  V3 c = V3::Zero();
  for (const V3& v : *o->vertices) c += v;
  c /= S(o->vertices->size());
  c += o->position;
  ccdVec3Set(out, c.x(), c.y(), c.z());
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

ShapeGeom build_box(const Shape& shape) {
  ShapeGeom g;
  const V3 lo = to_v3(shape.local.min), hi = to_v3(shape.local.max);
  g.offset = (lo + hi) * 0.5;
  const V3 side = hi - lo;
  auto box = std::make_shared<fcl::Box<S>>(side);
  box->computeLocalAABB();
  g.exact = box;
  g.hull = box;
  for (int i = 0; i < 8; ++i) {
    g.hull_vertices.emplace_back((i & 1) ? hi.x() : lo.x(), (i & 2) ? hi.y() : lo.y(),
                                 (i & 4) ? hi.z() : lo.z());
  }
  for (V3& v : g.hull_vertices) v -= g.offset;  // box geometry is centred on offset
  return g;
}

ShapeGeom build_mesh(const Shape& shape) {
  ShapeGeom g;
  const Mesh& mesh = *shape.mesh;
  std::vector<V3> pts;
  pts.reserve(mesh.vertices.size());
  for (const Vec3& v : mesh.vertices) pts.push_back(to_v3(v));
  std::vector<fcl::Triangle> tris;
  tris.reserve(mesh.triangles.size());
  for (const auto& t : mesh.triangles) tris.emplace_back(t[0], t[1], t[2]);
  auto bvh = std::make_shared<fcl::BVHModel<fcl::OBBRSS<S>>>();
  bvh->beginModel(int(tris.size()), int(pts.size()));
  bvh->addSubModel(pts, tris);
  bvh->endModel();
  bvh->computeLocalAABB();
  g.exact = bvh;

  // Convex hull (Bullet); hull vertices are mapped back to the exact mesh vertices.
  std::vector<double> coords;
  coords.reserve(pts.size() * 3);
  for (const V3& p : pts) {
    coords.push_back(p.x());
    coords.push_back(p.y());
    coords.push_back(p.z());
  }
  btConvexHullComputer hc;
  hc.compute(coords.data(), int(3 * sizeof(double)), int(pts.size()), 0.0, 0.0);
  auto verts = std::make_shared<std::vector<V3>>();
  for (int i = 0; i < hc.vertices.size(); ++i) {
    const int o = hc.original_vertex_index[i];
    verts->push_back(o >= 0 && o < int(pts.size())
                         ? pts[std::size_t(o)]
                         : V3(hc.vertices[i].x(), hc.vertices[i].y(), hc.vertices[i].z()));
  }
  if (verts->empty()) verts->assign(pts.begin(), pts.end());  // degenerate: support on all
  g.hull_vertices = *verts;
  V3 centroid = V3::Zero();
  for (const V3& v : *verts) centroid += v;
  centroid /= S(std::max<std::size_t>(verts->size(), 1));
  auto faces = std::make_shared<std::vector<int>>();
  int num_faces = 0;
  for (int f = 0; f < hc.faces.size(); ++f) {
    std::vector<int> idx;
    const btConvexHullComputer::Edge* first = &hc.edges[hc.faces[f]];
    const btConvexHullComputer::Edge* e = first;
    do {
      idx.push_back(e->getSourceVertex());
      e = e->getNextEdgeOfFace();
    } while (e != first && idx.size() <= std::size_t(hc.vertices.size()));
    if (idx.size() < 3) continue;
    // Newell normal; FCL wants counter-clockwise seen from outside.
    V3 n = V3::Zero();
    for (std::size_t k = 0; k < idx.size(); ++k) {
      const V3& p = (*verts)[std::size_t(idx[k])];
      const V3& q = (*verts)[std::size_t(idx[(k + 1) % idx.size()])];
      n += p.cross(q);
    }
    if (n.dot((*verts)[std::size_t(idx[0])] - centroid) < 0) {
      std::reverse(idx.begin(), idx.end());
    }
    faces->push_back(int(idx.size()));
    faces->insert(faces->end(), idx.begin(), idx.end());
    ++num_faces;
  }
  auto convex = std::make_shared<fcl::Convex<S>>(verts, num_faces, faces, false);
  convex->computeLocalAABB();
  g.hull = convex;
  return g;
}

}  // namespace

struct ReferenceGeometry::Impl {
  std::vector<ShapeGeom> shapes;
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

ReferenceGeometry::ReferenceGeometry(const Model& model) : impl_(std::make_unique<Impl>()) {
  for (const Shape& s : model.shapes) {
    impl_->shapes.push_back(s.mesh ? build_mesh(s) : build_box(s));
  }
  for (const BodyInfo& b : model.bodies) impl_->body_shape.push_back(b.shape);
}

ReferenceGeometry::~ReferenceGeometry() = default;

ReferenceNormal ReferenceGeometry::fcl_collide_normal(std::uint32_t a, std::uint32_t b, Vec3 xa,
                                                      Vec3 xb) const {
  const ShapeGeom& ga = impl_->geom(a);
  const ShapeGeom& gb = impl_->geom(b);
  fcl::Transform3<S> ta = fcl::Transform3<S>::Identity();
  fcl::Transform3<S> tb = fcl::Transform3<S>::Identity();
  ta.translation() = to_v3(xa) + ga.offset;
  tb.translation() = to_v3(xb) + gb.offset;
  fcl::CollisionObject<S> oa(ga.hull, ta), ob(gb.hull, tb);
  fcl::CollisionRequest<S> req(1, true);
  req.gjk_solver_type = fcl::GST_LIBCCD;
  fcl::CollisionResult<S> res;
  fcl::collide(&oa, &ob, req, res);
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

  // 1. Do the hulls intersect? (libccd GJK on the hull vertices.)
  CcdObject ca{&ga.hull_vertices, to_v3(xa) + ga.offset};
  CcdObject cb{&gb.hull_vertices, to_v3(xb) + gb.offset};
  ccd_t ccd;
  CCD_INIT(&ccd);
  ccd.support1 = ccd_support;
  ccd.support2 = ccd_support;
  ccd.center1 = ccd_center;
  ccd.center2 = ccd_center;
  ccd.max_iterations = 1000;
  ccd.epa_tolerance = 1e-9;
  ccd.dist_tolerance = 1e-12;
  if (ccdGJKIntersect(&ca, &cb, &ccd)) {
    ccd_real_t depth = 0;
    ccd_vec3_t dir, pos;
    if (ccdGJKPenetration(&ca, &cb, &ccd, &depth, &dir, &pos) == 0) {
      r.penetrating = true;
      // dir points from obj1 (A) towards obj2 (B): B-to-A is -dir.
      const V3 d(ccdVec3X(&dir), ccdVec3Y(&dir), ccdVec3Z(&dir));
      if (std::isfinite(depth) && unit(-d, r.normal)) {
        r.depth = std::max<S>(0, depth);
        r.point_a = r.point_b = Vec3{float(ccdVec3X(&pos)), float(ccdVec3Y(&pos)),
                                     float(ccdVec3Z(&pos))};
        r.valid = true;
        return r;
      }
    }
    return fcl_collide_normal(a, b, xa, xb);  // EPA failed: FCL's MPR estimate
  }

  // 2. Separated: FCL distance on the exact geometry (BVH models / boxes).
  fcl::Transform3<S> ta = fcl::Transform3<S>::Identity();
  fcl::Transform3<S> tb = fcl::Transform3<S>::Identity();
  ta.translation() = to_v3(xa) + ga.offset;
  tb.translation() = to_v3(xb) + gb.offset;
  fcl::CollisionObject<S> oa(ga.exact, ta), ob(gb.exact, tb);
  fcl::DistanceRequest<S> req(true);  // enable_nearest_points
  req.gjk_solver_type = fcl::GST_LIBCCD;
  req.distance_tolerance = 1e-9;
  req.abs_err = 0;
  req.rel_err = 0;
  fcl::DistanceResult<S> res;
  fcl::distance(&oa, &ob, req, res);
  r.penetrating = false;
  r.distance = res.min_distance;
  // nearest_points[0] is on o1 (A), [1] on o2 (B), world frame (FCL 0.7).
  const V3 pa = res.nearest_points[0], pb = res.nearest_points[1];
  r.point_a = to_vec3(pa);
  r.point_b = to_vec3(pb);
  if (!(res.min_distance > 0) || !std::isfinite(res.min_distance)) return r;
  r.valid = unit(pa - pb, r.normal);
  return r;
}

double angle_between(Vec3 u, Vec3 v) {
  const V3 a = to_v3(u), b = to_v3(v);
  return std::atan2(a.cross(b).norm(), a.dot(b));
}

}  // namespace octocd
