#pragma once
/// \file dmath.hpp
/// Double-precision 3-vectors and row-major 3x3 matrices of the judges (the physics tier's
/// row files physics_impl.hpp lists, sat.cpp; the model tier's applied-state re-derivation,
/// model/applied_state.cpp): they recompute in double what engines did in float32.
/// Internal to validation/.

#include <array>
#include <cmath>

#include "octocd/math.hpp"
#include "octocd/pose.hpp"

namespace octocd::dmath {

using D3 = std::array<double, 3>;  ///< (x, y, z)
using M3 = std::array<double, 9>;  ///< row-major 3x3

/// 2^-23: the relative rounding of a float32 (its unit in the last place at 1, FLT_EPSILON).
inline constexpr double kEps32 = 1.0 / 8388608.0;

/// A float32 vector in double.
inline D3 d3(Vec3 v) { return {double(v.x), double(v.y), double(v.z)}; }
inline D3 operator+(const D3& a, const D3& b) { return {a[0] + b[0], a[1] + b[1], a[2] + b[2]}; }
inline D3 operator-(const D3& a, const D3& b) { return {a[0] - b[0], a[1] - b[1], a[2] - b[2]}; }
inline D3 operator*(double s, const D3& a) { return {s * a[0], s * a[1], s * a[2]}; }
inline double dot3(const D3& a, const D3& b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
inline D3 cross3(const D3& a, const D3& b) {
  return {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
}
inline double len3(const D3& a) { return std::sqrt(dot3(a, a)); }
/// a / |a|, or zero for a zero vector.
inline D3 unit(const D3& a) {
  const double l = len3(a);
  return l > 0 ? (1.0 / l) * a : D3{};
}
/// v turned by the rotation w dt (Rodrigues; w in rad/s, dt in s).
inline D3 turned(const D3& v, const D3& w, double dt) {
  const double angle = len3(w) * dt;
  if (!(angle > 0)) return v;
  const D3 k = unit(w);
  const D3 kv = cross3(k, v);
  return v + std::sin(angle) * kv + (1.0 - std::cos(angle)) * cross3(k, kv);
}
/// m v.
inline D3 mul(const M3& m, const D3& v) {
  return {m[0] * v[0] + m[1] * v[1] + m[2] * v[2], m[3] * v[0] + m[4] * v[1] + m[5] * v[2],
          m[6] * v[0] + m[7] * v[1] + m[8] * v[2]};
}
/// The body-to-world rotation matrix of a unit quaternion (w, x, y, z), normalised in double
/// first (a float32 quaternion is unit only to rounding).
inline M3 rotation(Quat q) {
  double w = q.w, x = q.x, y = q.y, z = q.z;
  const double n = std::sqrt(w * w + x * x + y * y + z * z);
  if (n > 0) {
    w /= n;
    x /= n;
    y /= n;
    z /= n;
  }
  return {1 - 2 * (y * y + z * z), 2 * (x * y - w * z),     2 * (x * z + w * y),
          2 * (x * y + w * z),     1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
          2 * (x * z - w * y),     2 * (y * z + w * x),     1 - 2 * (x * x + y * y)};
}

/// The smallest and largest eigenvalues of a symmetric 3x3 (the principal moments of an
/// inertia tensor), by the trigonometric closed form of the characteristic cubic
/// (O. K. Smith, Comm. ACM 4(4), 1961), in double.
inline std::array<double, 2> sym_eigen_range(const M3& a) {
  const double p1 = a[1] * a[1] + a[2] * a[2] + a[5] * a[5];
  if (p1 == 0.0) {
    const double lo = std::fmin(a[0], std::fmin(a[4], a[8])), hi = std::fmax(a[0], std::fmax(a[4], a[8]));
    return {lo, hi};
  }
  const double q = (a[0] + a[4] + a[8]) / 3.0;
  const double p2 = (a[0] - q) * (a[0] - q) + (a[4] - q) * (a[4] - q) + (a[8] - q) * (a[8] - q) + 2.0 * p1;
  const double p = std::sqrt(p2 / 6.0);
  const M3 b{(a[0] - q) / p, a[1] / p, a[2] / p, a[3] / p, (a[4] - q) / p, a[5] / p, a[6] / p, a[7] / p, (a[8] - q) / p};
  const double det = b[0] * (b[4] * b[8] - b[5] * b[7]) - b[1] * (b[3] * b[8] - b[5] * b[6]) +
                     b[2] * (b[3] * b[7] - b[4] * b[6]);
  const double r = std::fmax(-1.0, std::fmin(1.0, det / 2.0));
  const double phi = std::acos(r) / 3.0;
  constexpr double kThird = 2.0943951023931954923;  // 2 pi / 3
  return {q + 2.0 * p * std::cos(phi + kThird), q + 2.0 * p * std::cos(phi)};
}

}  // namespace octocd::dmath
