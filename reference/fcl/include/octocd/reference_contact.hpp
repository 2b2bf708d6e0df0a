#pragma once
/// \file reference_contact.hpp
/// Reference contact normals from FCL / libccd for design.md section 7 validator 3 ("Contact normals":
/// the response normal against a reference normal; distance query nearest points for
/// separated pairs, libccd GJK/EPA on the convex hulls for penetrating pairs).
///
/// Bodies only translate (design.md section 3), so every query uses identity rotations and the
/// translations x_a, x_b (BodyState::x, the world position of the shape's local frame).
///
/// Which path a pair takes is decided on the convex hulls: libccd ccdGJKIntersect on the
/// hulls (boxes: their 8 corners). Hulls intersect -> penetrating (EPA). Otherwise the
/// pair is separated and FCL's distance query on the meshes (BVH) / boxes gives the
/// nearest points. (Non-convex meshes whose hulls intersect while the meshes themselves
/// do not are reported as penetrating: the reference is defined on the hulls.)
///
/// Observed conventions (FCL 0.7.0, libccd 2.x double; pinned by
/// tests/reference/test_reference_contact.cpp):
///  - fcl::distance(o1, o2, ...) with enable_nearest_points: DistanceResult::nearest_points[0]
///    lies on o1 and nearest_points[1] on o2, both in the WORLD frame (FCL >= 0.6; 0.5 gave
///    them in each object's local frame). We call it with o1 = A, o2 = B, so
///    normal = normalize(nearest_points[0] - nearest_points[1]) points from B to A.
///  - libccd ccdGJKPenetration(obj1, obj2) (GJK + EPA): `dir` is unit and points from obj1
///    towards obj2 (translating obj2 by depth * dir separates them); depth >= 0; pos is the
///    midpoint of the two witness points, world frame. We pass obj1 = A, obj2 = B and return
///    normal = -dir (B to A).
///  - fcl::collide(o1, o2, CollisionRequest(1, true), ...) with GST_LIBCCD: for Convex
///    shapes FCL 0.7 does NOT run EPA: it runs libccd MPR (ccdMPRPenetration), and
///    Contact::normal points from o1 to o2 (FCL's documented convention: "normal points
///    from o1 to o2"); Contact::penetration_depth is >= 0. So B-to-A is -Contact::normal
///    with o1 = A. Because FCL's path is MPR, not EPA (its depth/normal are a portal
///    estimate, not the minimum translation), the main path calls libccd's
///    ccdGJKPenetration directly on the same hull vertices; fcl::collide is exposed as
///    fcl_collide_normal() for comparison and used as a fallback when EPA fails.
///  - FCL mesh-mesh (BVH-BVH) contacts are per triangle and are never used.
///
/// Posed queries (design.md section 13, the physics tier): the same queries for bodies that rotate,
/// each body at a `Pose` (body-frame origin + orientation, body to world). The shape is
/// in the body frame as the Model gives it: a box fills its local AABB; a mesh is placed
/// so that its vertex bounds are the shape's local AABB (octocd's meshes are centred on
/// it already; an external trace may give a local box off the body origin). Unlike the
/// translation-only normal(), posed() decides "penetrating" on the shapes themselves:
///  - two boxes: octocd's own box-box (reference_contact.cpp box_contact): the least
///    overlap over the 15 separating axes of two boxes (3 + 3 face normals, 9 edge-edge
///    crosses), which for convex polytopes is the exact minimum translation (depth) and
///    its axis (normal); the contact point is the midpoint of the deepest contact's
///    witnesses. FCL's box-box routine (ODE's dBoxBox) is its oracle in the tests: it keeps
///    a face axis unless an edge-edge one overlaps less than 1/1.05 of it, so its depth is
///    up to 5% above the minimum. FCL's distance when apart. (libccd's EPA on box corners
///    can cycle without end when faces are coplanar, as in a resting stack.)
///  - a declared sphere (CollisionShape::Sphere) with a box, sphere or hull: FCL's
///    collide on the primitives (sphere-box and sphere-sphere exact).
///  - other convex shapes (meshes whose every triangle lies on their hull): GJK on the
///    hulls decides; EPA gives the exact minimum translation (depth, normal).
///  - a non-convex mesh: when the hulls intersect, FCL's BVH collide on the meshes decides
///    whether the meshes themselves intersect. If they do not, the pair is separated and
///    FCL's BVH distance gives the distance and nearest points. If they do, the depth is
///    an UPPER BOUND of the true penetration depth (`depth_upper_bound`): the least, over
///    the hulls' EPA normal, the centre line and the six axes, of the smallest translation
///    of A along that direction that separates the meshes (bisection on BVH collide,
///    1e-6 m); along the EPA normal it is at most the hull EPA depth (translating by the
///    hull depth separates the hulls, hence the meshes). The normal is the direction
///    that gave it. The true minimum translation of two non-convex meshes is not computed.

#include <array>
#include <cstdint>
#include <memory>
#include <vector>

#include "octocd/math.hpp"
#include "octocd/physics_bodies.hpp"  // CollisionShape
#include "octocd/pose.hpp"
#include "octocd/world.hpp"

namespace octocd {

/// Reference contact geometry of a pair, from FCL / libccd.
struct ReferenceNormal {
  bool valid = false;        ///< false when FCL/libccd gave no usable answer (e.g. degenerate)
  bool penetrating = false;  ///< true: convex hulls intersect (GJK/EPA); false: separated (distance query)
  Vec3 normal;               ///< unit, pointing from B to A (design.md section 2)
  double distance = 0;       ///< m, >= 0, separated pairs (mesh-mesh BVH distance)
  double depth = 0;          ///< m, >= 0, penetrating pairs (EPA depth on the hulls)
  Vec3 point_a, point_b;     ///< nearest points (separated) or contact point (penetrating; a == b), world frame
  /// posed() on a non-convex mesh pair that intersects: `depth` is an upper bound (the
  /// separating translation along `normal`), not the minimum translation.
  bool depth_upper_bound = false;
  /// Signed distance (m): -depth when penetrating, distance otherwise.
  double signed_distance() const { return penetrating ? -depth : distance; }
};

/// A proof that two posed shapes penetrate, and by at least how much
/// (ReferenceGeometry::penetration_witness): FCL's BVH collide on the exact shapes (a
/// mesh's triangles, a box) and the deepest vertex of either shape inside the other.
struct PenetrationWitness {
  /// FCL's collide on the exact shapes reports them intersecting (touching counts).
  bool intersect = false;
  /// The first intersecting primitive pair FCL reports: a triangle index of body a's
  /// mesh and one of body b's (-1 for a box, or where FCL names none).
  int triangle_a = -1, triangle_b = -1;
  /// m, >= 0: a lower bound of the penetration depth (the least translation that
  /// separates the shapes' interiors): the distance from `vertex_point` to the surface of
  /// the other body, which the point lies inside (a box: inside its faces; a mesh: its
  /// generalised winding number above 1/2, closed meshes). Translating either body by less
  /// keeps that point inside. 0 when no vertex lies inside the other shape.
  double depth = 0;
  std::uint32_t vertex_body = 0;  ///< the body whose vertex gives `depth` (a or b)
  std::int64_t vertex = -1;       ///< its index (a mesh vertex; a box corner 0..7); -1: none
  Vec3 vertex_point;              ///< that vertex, world frame
};


/// A shape's convex hull in the body frame, as the separating-axis test needs it
/// (validation/physics/sat.hpp): a box's 8 corners, 3 face axes and 3 edge axes; a mesh's
/// convex hull (convex_hull.hpp: qhull on its vertices, the hull every adapter collides;
/// hull vertices are mesh vertices) with its faces' unit outward normals and its edges'
/// unit directions; a flat mesh (no hull with volume): its vertices, its triangles' normals
/// and edges.
/// Axes parallel or antiparallel to one already listed (|cross| < 1e-9) are dropped: the
/// test projects on both orientations of an axis. Double precision, metres.
struct HullFeatures {
  std::vector<std::array<double, 3>> vertices;      ///< body frame, m
  std::vector<std::array<double, 3>> face_normals;  ///< unit, body frame, one per direction
  std::vector<std::array<double, 3>> edge_dirs;     ///< unit, body frame, one per direction
};

/// Per-shape FCL geometry of a World, built once: for meshes fcl::BVHModel<fcl::OBBRSS<double>>
/// from Shape::mesh and fcl::Convex<double> from the convex hull of the mesh vertices
/// (convex_hull.hpp: qhull; hull vertices are the original mesh vertices, exact; a flat
/// mesh's hull is its BVH);
/// for boxes fcl::Box<double> with the local AABB's sides. Not owned by the World; must
/// not outlive it (it reads World::shapes() and World::bodies() at construction only, but
/// body indices passed to normal() must be the World's). Queries are const: they hand FCL
/// the shared geometries with each query's transforms and build no fcl::CollisionObject (whose
/// construction recomputes a mesh's local AABB over all its vertices, a write to the shared
/// geometry), so concurrent normal() calls are safe.
class ReferenceGeometry {
 public:
  explicit ReferenceGeometry(const Engine& world);
  /// The same from a model's shapes and bodies (read at construction only; body indices
  /// passed to normal() are the model's).
  explicit ReferenceGeometry(const Model& model);
  /// The same with each body collided as `declared[i]` (empty: every body as its shape;
  /// else one per body, else InputError). A sphere declared on a box shape is built as
  /// the box (callers refuse it first).
  ReferenceGeometry(const Model& model, const std::vector<CollisionShape>& declared);
  ~ReferenceGeometry();
  ReferenceGeometry(const ReferenceGeometry&) = delete;
  ReferenceGeometry& operator=(const ReferenceGeometry&) = delete;

  /// Reference normal for bodies a, b at positions xa, xb (world, m; identity rotation).
  /// Hulls intersect (libccd GJK): penetrating; normal = -dir of ccdGJKPenetration(A, B)
  /// (EPA), depth = EPA depth, point_a = point_b = EPA contact position; falls back to
  /// fcl_collide_normal() if EPA fails. Otherwise separated: fcl::distance(A, B) on the
  /// BVH models / boxes with enable_nearest_points; distance = min_distance,
  /// point_a = nearest_points[0], point_b = nearest_points[1],
  /// normal = normalize(point_a - point_b) (B to A). valid = false when the distance is
  /// not > 0 or the normal has no direction. Bodies a and b may be given in either order;
  /// swapping them flips the normal. Throws InputError for a body index out of range.
  ReferenceNormal normal(std::uint32_t a, std::uint32_t b, Vec3 xa, Vec3 xb) const;

  /// Penetrating-pair normal from fcl::collide on the convex hulls / boxes with
  /// CollisionRequest(1, enable_contact = true), gjk_solver_type = GST_LIBCCD (FCL 0.7
  /// runs MPR there for Convex, its box-box routine, ODE's dBoxBox, for two boxes). Converted to B-to-A
  /// (-Contact::normal with o1 = A). valid = false when FCL reports no contact.
  /// For comparison and fallback; normal() is the reference.
  ReferenceNormal fcl_collide_normal(std::uint32_t a, std::uint32_t b, Vec3 xa, Vec3 xb) const;

  /// Contact geometry of bodies a, b at poses pa, pb (design.md section 13; see the file comment for
  /// non-convex meshes). Penetrating: normal from B to A (the direction to translate A
  /// to separate), depth >= 0, point_a = point_b = the contact point (EPA's; two boxes: box-box's). Separated:
  /// distance > 0, point_a on A, point_b on B (FCL distance on the boxes / BVH models),
  /// normal = normalize(point_a - point_b). Touching (distance 0 without an EPA answer):
  /// penetrating with depth 0 and valid = false. Throws InputError for a body out of range.
  ReferenceNormal posed(std::uint32_t a, std::uint32_t b, const Pose& pa, const Pose& pb) const;

  /// An exact lower bound of the penetration of bodies a, b at poses pa, pb, for pairs
  /// where posed() gives only an upper bound (a non-convex mesh): FCL collide on the
  /// exact shapes (fcl::BVHModel<OBBRSS> for meshes) with one contact, and every vertex of
  /// each shape tested against the other (its surface distance first; only vertices
  /// deeper than `floor` m and the best so far are tested for inside). Linear in the
  /// candidate vertices times the other mesh's triangles: for rare pairs (a missing
  /// contact), not every pair. Declared spheres: their centre is no vertex (depth 0).
  /// Throws InputError for a body out of range.
  PenetrationWitness penetration_witness(std::uint32_t a, std::uint32_t b, const Pose& pa, const Pose& pb,
                                         double floor) const;

  /// Whether the posed shapes intersect (touching counts): hull GJK, then for a
  /// non-convex mesh FCL's BVH collide. Cheaper than posed().
  bool intersect(std::uint32_t a, std::uint32_t b, const Pose& pa, const Pose& pb) const;

  /// Distance (m, >= 0) from the world point p to the surface of body `body` at `pose`
  /// (box: its faces, also from inside; mesh: its triangles, FCL sphere-BVH distance).
  double surface_distance(std::uint32_t body, const Pose& pose, Vec3 p) const;

  /// The exact world AABB of body `body` at `pose` (design.md section 13): a box's posed_box_aabb, a
  /// mesh's bounds of its rotated hull vertices (double, rounded outward to float).
  Aabb world_aabb(std::uint32_t body, const Pose& pose) const;

  /// Whether the body's shape is convex (a box, or a mesh whose every triangle lies in a
  /// face plane of its convex hull, within 1e-6 m).
  bool convex(std::uint32_t body) const;

  /// How far the surface of the shape body `body` is collided as lies from its true
  /// shape (m, >= 0): the largest distance to the true surface over the declared shape's
  /// face centroids (hull), corners and face centres (box) or 14 axis and diagonal points
  /// (sphere); 0 when the body is collided as its shape. A figure, never a verdict.
  double declared_gap(std::uint32_t body) const;

  /// The convex hull of body `body`'s shape in the body frame (see HullFeatures). Throws
  /// InputError for a body out of range.
  const HullFeatures& hull_features(std::uint32_t body) const;

  /// Box-box geometry of two axis-aligned boxes given in the world (the box-box minimum
  /// translation of posed(); FCL distance when apart): what an engine that resolves
  /// contacts on world AABBs (octocd's design.md section 6) should find. Same conventions
  /// as posed().
  static ReferenceNormal aabb_pair(const Aabb& a, const Aabb& b);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

/// Angle in radians between two unit vectors, in [0, pi] (atan2 of |u x v| and u . v in
/// double, accurate near 0 and pi; inputs need not be exactly unit).
double angle_between(Vec3 u, Vec3 v);

}  // namespace octocd
