#pragma once
/// \file pose.hpp
/// Rigid-body poses for engines that rotate (design.md section 13): a unit quaternion (w, x, y, z),
/// body to world, a 3x3 matrix, and a `Pose` (position + orientation) that feeds every
/// geometric query of the physics-tier validators and the world AABB of a rotated body.
///
/// octocd's own engines translate only (design.md section 3): their poses have the identity
/// orientation. Every function is `OCTOCD_HD`, allocates nothing and throws nothing.
/// Units: metres, radians, seconds.

#include "octocd/math.hpp"

namespace octocd {

/// A quaternion w + x i + y j + z k (float32). A rotation is a unit quaternion; it maps
/// body-frame vectors to the world frame (design.md section 13: `/states/orientation`, body to world).
struct Quat {
  float w = 1.0f;
  float x = 0.0f;
  float y = 0.0f;
  float z = 0.0f;
};

/// Hamilton product a * b (apply b, then a).
OCTOCD_HD inline Quat operator*(Quat a, Quat b) {
  return {a.w * b.w - a.x * b.x - a.y * b.y - a.z * b.z, a.w * b.x + a.x * b.w + a.y * b.z - a.z * b.y,
          a.w * b.y - a.x * b.z + a.y * b.w + a.z * b.x, a.w * b.z + a.x * b.y - a.y * b.x + a.z * b.w};
}
/// Conjugate (the inverse of a unit quaternion).
OCTOCD_HD inline Quat conjugate(Quat q) { return {q.w, -q.x, -q.y, -q.z}; }
/// Euclidean norm of the 4 components.
OCTOCD_HD inline float norm(Quat q) { return sqrtf(q.w * q.w + q.x * q.x + q.y * q.y + q.z * q.z); }
/// q / |q| (the identity for a zero quaternion).
OCTOCD_HD inline Quat normalized(Quat q) {
  const float n = norm(q);
  if (!(n > 0.0f)) return Quat{};
  return {q.w / n, q.x / n, q.y / n, q.z / n};
}
/// True when every component is exactly that of the identity (1, 0, 0, 0).
OCTOCD_HD inline bool is_identity(Quat q) { return q.w == 1.0f && q.x == 0.0f && q.y == 0.0f && q.z == 0.0f; }

/// Cross product a x b.
OCTOCD_HD inline Vec3 cross(Vec3 a, Vec3 b) {
  return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}

/// q v q* for a unit quaternion q: the body-frame vector v in the world frame.
OCTOCD_HD inline Vec3 rotate(Quat q, Vec3 v) {
  const Vec3 u{q.x, q.y, q.z};
  const Vec3 t = 2.0f * cross(u, v);
  return v + q.w * t + cross(u, t);
}

/// Rotation by `angle` radians about the unit axis `axis`.
OCTOCD_HD inline Quat axis_angle(Vec3 axis, float angle) {
  const float s = sinf(0.5f * angle);
  return {cosf(0.5f * angle), s * axis.x, s * axis.y, s * axis.z};
}

/// A 3x3 matrix of float32, row-major: m[r][c].
struct Mat3 {
  float m[3][3] = {{1.0f, 0.0f, 0.0f}, {0.0f, 1.0f, 0.0f}, {0.0f, 0.0f, 1.0f}};
};
/// M v.
OCTOCD_HD inline Vec3 operator*(const Mat3& a, Vec3 v) {
  return {a.m[0][0] * v.x + a.m[0][1] * v.y + a.m[0][2] * v.z, a.m[1][0] * v.x + a.m[1][1] * v.y + a.m[1][2] * v.z,
          a.m[2][0] * v.x + a.m[2][1] * v.y + a.m[2][2] * v.z};
}
/// The rotation matrix of a unit quaternion (columns: the body axes in the world frame).
OCTOCD_HD inline Mat3 to_matrix(Quat q) {
  Mat3 r;
  const float xx = q.x * q.x, yy = q.y * q.y, zz = q.z * q.z;
  const float xy = q.x * q.y, xz = q.x * q.z, yz = q.y * q.z;
  const float wx = q.w * q.x, wy = q.w * q.y, wz = q.w * q.z;
  r.m[0][0] = 1.0f - 2.0f * (yy + zz);
  r.m[0][1] = 2.0f * (xy - wz);
  r.m[0][2] = 2.0f * (xz + wy);
  r.m[1][0] = 2.0f * (xy + wz);
  r.m[1][1] = 1.0f - 2.0f * (xx + zz);
  r.m[1][2] = 2.0f * (yz - wx);
  r.m[2][0] = 2.0f * (xz - wy);
  r.m[2][1] = 2.0f * (yz + wx);
  r.m[2][2] = 1.0f - 2.0f * (xx + yy);
  return r;
}

/// Where a body is: the world position of its body frame's origin (m) and its
/// orientation (body to world). octocd's engines: the identity orientation and the
/// centre of the world AABB (design.md section 3).
struct Pose {
  Vec3 position;
  Quat orientation;
};

/// A body-frame point in the world frame: R p + x.
OCTOCD_HD inline Vec3 to_world(const Pose& pose, Vec3 p) { return rotate(pose.orientation, p) + pose.position; }

/// The exact world AABB of a box given in the body frame (`local`, min <= max) at
/// `pose`: the bounds of its 8 rotated corners (design.md section 13: "the bounds of its rotated
/// corners, not the rotated local box"), computed as centre +- |R| half extents.
/// For the identity orientation this is `translated(local, pose.position)` up to rounding.
OCTOCD_HD inline Aabb posed_box_aabb(const Aabb& local, const Pose& pose) {
  if (is_identity(pose.orientation)) return translated(local, pose.position);
  const Mat3 r = to_matrix(pose.orientation);
  const Vec3 c = to_world(pose, center(local));
  const Vec3 h = 0.5f * (local.max - local.min);
  Vec3 e;
  for (int i = 0; i < 3; ++i)
    e[i] = fabsf(r.m[i][0]) * h.x + fabsf(r.m[i][1]) * h.y + fabsf(r.m[i][2]) * h.z;
  return {c - e, c + e};
}

}  // namespace octocd
