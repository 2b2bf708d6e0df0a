#pragma once
/// \file strict_octree.hpp
/// Node and level math of the `octree-strict` broadphase (design.md section 5.1: the paper's world
/// octree read literally, paper section 3.2, Algorithms 1-2), shared by the CPU reference
/// (core/src/broadphase_octree_strict.cpp, auto depth in core/src/broadphase.cpp) and the
/// CUDA engine (gpu/src/broadphase_octree_strict.cu), so both put every body in the same node.
///
/// Like math.hpp, every function is `OCTOCD_HD`, takes and returns plain values,
/// allocates nothing and throws nothing.
///
/// Geometry. The root is the bounding cube of the domain (centred on the domain centre,
/// side = the longest domain side), split D_w times (D_w in [0, 10]). A coordinate p maps
/// to the depth-D_w leaf grid as u = (p - origin) * (2^D_w / side), monotone in p, so a
/// body goes into the deepest node whose cell holds both its min and its max corner leaf
/// cell. Node cells are half-open [lo, hi) in grid space (closed only on the root's upper
/// faces): two bodies in unrelated nodes are strictly separated on some axis and cannot
/// overlap, not even by touching faces, whatever the float rounding (the map is monotone).
/// A body not inside the root (or with an infinite coordinate) stays at the root.
///
/// Keys. A node at level l with Morton code m (of its level-l cell; morton3 of math.hpp)
/// covers the depth-D_w leaf Morton codes [m * 8^(D_w-l), (m+1) * 8^(D_w-l)); its key is
/// (that range's lo << 4) | l, at most 3 D_w + 4 bits. Sorting by key lists nodes in
/// pre-order: a node's subtree is the contiguous key range [key, strict_subtree_key_end).

#include <cstdint>

#include "octocd/math.hpp"

namespace octocd {

/// Deepest level of `octree-strict` (30-bit Morton codes of the leaves).
constexpr int kStrictMaxDepth = 10;

/// std::isfinite on the host, isfinite under nvcc.
OCTOCD_HD inline bool strict_isfinite(double v) {
#if defined(__CUDACC__)
  return isfinite(v);
#else
  return std::isfinite(v);
#endif
}

/// The leaf grid of a strict octree of depth D_w over a domain.
struct StrictGrid {
  Vec3 origin;              ///< min corner of the root cube (m)
  float cells = 1.0f;       ///< leaf cells per axis, 2^D_w (exact)
  float scale = 0.0f;       ///< leaf cells per metre, 2^D_w / side (1/m); 0 when unusable
  std::uint32_t top = 0;    ///< last leaf index per axis, 2^D_w - 1
  int depth = 0;            ///< D_w in [0, 10]
  bool usable = false;      ///< false: every body stays at the root (depth 0, or a domain
                            ///< whose side is not finite and > 0)
};

/// The leaf grid of the root cube of `domain` (m) at depth `depth` in [0, 10]: the cube is
/// centred on the domain's centre with side = its longest side (the first largest of the
/// x, y, z sides, as std::max({...}) picks it).
OCTOCD_HD inline StrictGrid strict_grid(const Aabb& domain, int depth) {
  const Vec3 c = center(domain);
  float side = domain.max.x - domain.min.x;
  if (side < domain.max.y - domain.min.y) side = domain.max.y - domain.min.y;
  if (side < domain.max.z - domain.min.z) side = domain.max.z - domain.min.z;
  StrictGrid g;
  g.origin = {c.x - 0.5f * side, c.y - 0.5f * side, c.z - 0.5f * side};
  g.depth = depth;
  g.usable = strict_isfinite(side) && side > 0.0f && is_finite(g.origin) && depth > 0;
  g.cells = static_cast<float>(1u << static_cast<unsigned>(depth));
  g.scale = g.usable ? g.cells / side : 0.0f;
  g.top = (1u << static_cast<unsigned>(depth)) - 1u;
  return g;
}

/// The leaf indices [t0, t1] (each clamped to g.top) that the interval [lo, hi] (m) of a box
/// covers along `axis` of grid `g`; false where the interval is not inside the root cube
/// (or is inverted, infinite or NaN), t0 and t1 then unset.
OCTOCD_HD inline bool strict_leaf_span(const StrictGrid& g, float lo, float hi, int axis, std::uint32_t& t0,
                                       std::uint32_t& t1) {
  const float u0 = (lo - g.origin[axis]) * g.scale;  // monotone in lo
  const float u1 = (hi - g.origin[axis]) * g.scale;
  if (!(u0 >= 0.0f && u1 <= g.cells && u0 <= u1)) return false;
  const std::uint32_t f0 = static_cast<std::uint32_t>(u0);
  const std::uint32_t f1 = static_cast<std::uint32_t>(u1);
  t0 = f0 < g.top ? f0 : g.top;
  t1 = f1 < g.top ? f1 : g.top;
  return true;
}

/// Node key ((leaf range lo) << 4 | level, see the file comment) of the deepest node that
/// holds the body with world AABB `b` (m), which must have no NaN coordinate (the caller
/// leaves NaN boxes out: they overlap nothing under Eq. 6). Bodies not inside the root
/// cube, inverted boxes and any body of an unusable grid get the root's key 0.
OCTOCD_HD inline std::uint64_t strict_node_key(const StrictGrid& g, const Aabb& b) {
  if (!g.usable) return 0;
  std::uint32_t i0[3], i1[3];
  for (int a = 0; a < 3; ++a)
    if (!strict_leaf_span(g, b.min[a], b.max[a], a, i0[a], i1[a])) return 0;  // not inside the root
  const std::uint32_t diff = (i0[0] ^ i1[0]) | (i0[1] ^ i1[1]) | (i0[2] ^ i1[2]);
  int s = 0;  // levels above the leaves
  while ((diff >> s) != 0u) ++s;
  const int level = g.depth - s;
  const std::uint64_t lo = static_cast<std::uint64_t>(morton3(i0[0] >> s, i0[1] >> s, i0[2] >> s)) << (3 * s);
  return (lo << 4) | static_cast<std::uint64_t>(level);
}

/// Level (in [0, D_w]) of a node key.
OCTOCD_HD inline int strict_key_level(std::uint64_t key) { return static_cast<int>(key & 15u); }

/// End of the depth-`depth` leaf Morton range of a node key (its subtree's leaves are
/// [key >> 4, this)).
OCTOCD_HD inline std::uint64_t strict_subtree_leaf_end(std::uint64_t key, int depth) {
  return (key >> 4) + (std::uint64_t{1} << (3 * (depth - strict_key_level(key))));
}

/// First key after the subtree of a node key: the node and its descendants are exactly the
/// keys in [key, strict_subtree_key_end(key, depth)).
OCTOCD_HD inline std::uint64_t strict_subtree_key_end(std::uint64_t key, int depth) {
  return strict_subtree_leaf_end(key, depth) << 4;
}

/// One body's term of the `auto` depth (auto_octree_depth in broadphase.hpp): the longest
/// side of `b` in double precision (the first largest of the x, y, z sides, as
/// std::max({...}) picks it; NaN when a side is NaN).
OCTOCD_HD inline double strict_auto_extent(const Aabb& b) {
  double e = static_cast<double>(b.max.x) - static_cast<double>(b.min.x);
  const double ey = static_cast<double>(b.max.y) - static_cast<double>(b.min.y);
  const double ez = static_cast<double>(b.max.z) - static_cast<double>(b.min.z);
  if (e < ey) e = ey;
  if (e < ez) e = ez;
  return e;
}

/// True when a body's strict_auto_extent enters the mean: finite and >= 0.
OCTOCD_HD inline bool strict_auto_counts(double extent) { return strict_isfinite(extent) && extent >= 0.0; }

/// The `auto` depth of `octree-strict` (design.md section 5.1) from the sum and the number of the
/// counted body extents (strict_auto_extent, strict_auto_counts): the deepest level in
/// [1, 8] whose cells (side = longest domain side / 2^level, m) are still at least twice
/// the mean extent; 2 when no body counts.
OCTOCD_HD inline int strict_auto_depth(double extent_sum, std::uint64_t count, const Aabb& domain) {
  if (count == 0) return 2;
  const double mean = extent_sum / static_cast<double>(count);
  double side = static_cast<double>(domain.max.x) - static_cast<double>(domain.min.x);
  const double sy = static_cast<double>(domain.max.y) - static_cast<double>(domain.min.y);
  const double sz = static_cast<double>(domain.max.z) - static_cast<double>(domain.min.z);
  if (side < sy) side = sy;
  if (side < sz) side = sz;
  for (int level = 8; level >= 1; --level) {
    if (side / static_cast<double>(1u << level) >= 2.0 * mean) return level;
  }
  return 1;
}

}  // namespace octocd
