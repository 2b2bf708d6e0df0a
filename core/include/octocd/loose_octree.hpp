#pragma once
/// \file loose_octree.hpp
/// Cell and level math of the loose octree broadphase `octree` (design.md section 5.1; Ulrich, "Loose
/// Octrees", Game Programming Gems 2000, looseness k = 2), shared by the CPU reference
/// (core/src/broadphase_octree_tree.cpp, broadphase_octree_cache.cpp) and the CUDA engine
/// (gpu/src/broadphase_octree_tree.cu, broadphase_octree_cache.cu).
///
/// Like math.hpp, every function is `OCTOCD_HD`, takes and returns plain values,
/// allocates nothing and throws nothing.
///
/// Geometry. The root is the bounding cube of the domain (centred on the domain centre,
/// side S = the longest domain side; the same cube as `octree-strict`). Level l in
/// [0, 10] splits it into 2^l cells per axis of side s_l = S / 2^l; cell (i, j, k) of level
/// l covers [i, i+1) x [j, j+1) x [k, k+1) in level-l cell units and its loose box is that
/// cell grown by s_l / 2 on every side: [i - 1/2, i + 3/2] x ... (looseness 2).
///
/// Unit coordinates. All decisions are taken on u = (p - origin) / S (the root cube is
/// [0, 1]^3), computed as (p - origin) * (1/S) in float: a non-decreasing function of p on
/// each axis. Level-l cell units are u * 2^l, an exact scaling. A body is put in a cell
/// only after checking, in these units, that its AABB lies in the cell's loose box
/// (loose_fits_axis); a query at level l takes every cell whose loose box meets the
/// querying box in the same units (loose_query_axis). Because the map is monotone and
/// the tests are exact float comparisons, a body overlapping the querying box under Eq. 6
/// always lies in a queried cell, whatever the rounding: the broadphase is exact.
///
/// Keys. Cell (i, j, k) of level l has the 32-bit key (8^l - 1) / 7 + morton3(i, j, k):
/// keys order cells by (level, Morton code) and every cell of levels 0..10 has one
/// (the largest is 1227133512). Bodies outside every loose box get kLooseOverflowKey,
/// bodies with a NaN coordinate (they overlap nothing under Eq. 6) kLooseNoKey; both sort
/// after every cell key.

#include <cstdint>

#include "octocd/math.hpp"

namespace octocd {

/// Deepest level of the loose octree (30-bit Morton codes: 10 bits per axis).
constexpr int kLooseMaxDepth = 10;
/// Key of a body in the overflow list (tested against every body).
constexpr std::uint32_t kLooseOverflowKey = 0xfffffffeu;
/// Key of a body with a NaN coordinate: it overlaps nothing and is left out.
constexpr std::uint32_t kLooseNoKey = 0xffffffffu;

/// The root cube of a loose octree.
struct LooseGrid {
  Vec3 origin;            ///< min corner of the root cube (m)
  float side = 0.0f;      ///< S, the root cube's side (m)
  float inv_side = 0.0f;  ///< 1 / S (1/m); 0 when the domain is unusable (see loose_grid)
};

/// The root cube of `domain` (m): centred on the domain's centre, side = its longest
/// side. When that side is not finite and > 0, or the origin is not finite, inv_side is
/// 0: every finite body then maps to u = 0 and lands in cell (0, 0, 0) of its level
/// (still exact: every body meets every other there).
OCTOCD_HD inline LooseGrid loose_grid(const Aabb& domain) {
  const float dx = domain.max.x - domain.min.x;
  const float dy = domain.max.y - domain.min.y;
  const float dz = domain.max.z - domain.min.z;
  float side = dx > dy ? dx : dy;
  side = side > dz ? side : dz;
  const Vec3 c = center(domain);
  LooseGrid g;
  g.side = side;
  g.origin = {c.x - 0.5f * side, c.y - 0.5f * side, c.z - 0.5f * side};
  const bool usable = side > 0.0f && side <= 3.4e38f && is_finite(g.origin);
  g.inv_side = usable ? 1.0f / side : 0.0f;
  return g;
}

/// Unit coordinates of a point p (m): (p - origin) * (1/S) per axis, the root cube being
/// [0, 1]^3. Non-decreasing in each coordinate of p (float rounding included).
OCTOCD_HD inline Vec3 loose_unit(const LooseGrid& g, Vec3 p) {
  return {(p.x - g.origin.x) * g.inv_side, (p.y - g.origin.y) * g.inv_side,
          (p.z - g.origin.z) * g.inv_side};
}

/// Cells per axis at `level` (2^level, in [1, 1024]) as a float (exact).
OCTOCD_HD inline float loose_cells_per_axis(int level) {
  return static_cast<float>(1u << static_cast<unsigned>(level));
}

/// The level of a body by size (design.md section 5.1): the deepest l in [0, max_depth] whose cell
/// side s_l = S / 2^l is >= the body's largest AABB side, given as `extent_u` = that side
/// / S (unit coordinates: the largest of u(max) - u(min) over the axes). Returns -1
/// (overflow) when extent_u > 1 (the body is bigger than the root cell) or is NaN.
/// `max_depth` in [0, 10].
OCTOCD_HD inline int loose_level_for_extent(float extent_u, int max_depth) {
  if (!(extent_u <= 1.0f)) return -1;
  int l = max_depth;
  while (l > 0 && extent_u * loose_cells_per_axis(l) > 1.0f) --l;
  return l;
}

/// Index along one axis of the level-`level` cell holding unit coordinate u:
/// floor(u * 2^level), clamped to [0, 2^level - 1] (NaN gives 0). Prefix property: the
/// index at level l is the index at level l + 1 shifted right by one.
OCTOCD_HD inline std::uint32_t loose_cell_index(float u, int level) {
  const float n = loose_cells_per_axis(level);
  const float t = u * n;
  if (!(t > 0.0f)) return 0u;
  if (t >= n) return (1u << static_cast<unsigned>(level)) - 1u;
  return static_cast<std::uint32_t>(t);  // truncation = floor for t > 0
}

/// True when the interval [umin, umax] (unit coordinates, one axis) lies inside the loose
/// interval of cell index i at `level`: i - 1/2 <= umin * 2^level and umax * 2^level <=
/// i + 3/2 (inclusive; exact in float for i < 2^22). False for NaN.
OCTOCD_HD inline bool loose_fits_axis(float umin, float umax, std::uint32_t i, int level) {
  const float n = loose_cells_per_axis(level);
  const float fi = static_cast<float>(i);
  return umin * n >= fi - 0.5f && umax * n <= fi + 1.5f;
}

/// Where a body goes: `level` in [0, 10] and its cell (ix, iy, iz), or level
/// kLooseOverflowLevel (-1) / kLooseNoLevel (-2).
struct LoosePlace {
  int level = -1;  ///< cell level; -1 = overflow list, -2 = NaN box (left out)
  std::uint32_t ix = 0, iy = 0, iz = 0;  ///< cell indices at `level`, each < 2^level
};
/// LoosePlace::level of a body in the overflow list.
constexpr int kLooseOverflowLevel = -1;
/// LoosePlace::level of a body with a NaN coordinate.
constexpr int kLooseNoLevel = -2;

/// True when some coordinate of `b` is NaN (such a box overlaps nothing under Eq. 6).
OCTOCD_HD inline bool loose_has_nan(const Aabb& b) {
  return b.min.x != b.min.x || b.min.y != b.min.y || b.min.z != b.min.z ||
         b.max.x != b.max.x || b.max.y != b.max.y || b.max.z != b.max.z;
}

/// Largest side of a unit box [lo, hi] (unit coordinates; negative for a box inverted on
/// every axis, NaN when a side is NaN, e.g. for an infinite box).
OCTOCD_HD inline float loose_unit_extent(Vec3 lo, Vec3 hi) {
  float ext = hi.x - lo.x;
  ext = ext > hi.y - lo.y ? ext : hi.y - lo.y;
  ext = ext > hi.z - lo.z ? ext : hi.z - lo.z;
  return ext;
}

/// loose_place on a body's unit box [lo, hi] = [loose_unit(g, b.min), loose_unit(g,
/// b.max)] of a world box with no NaN coordinate (the caller checks loose_has_nan on the
/// world box: an infinite box on an unusable grid has NaN unit coordinates and must go to
/// the overflow list, which this does). Never returns kLooseNoLevel.
OCTOCD_HD inline LoosePlace loose_place_unit(Vec3 lo, Vec3 hi, int max_depth) {
  LoosePlace r;
  int l = loose_level_for_extent(loose_unit_extent(lo, hi), max_depth);
  if (l < 0) {
    r.level = kLooseOverflowLevel;
    return r;
  }
  const Vec3 c{0.5f * lo.x + 0.5f * hi.x, 0.5f * lo.y + 0.5f * hi.y, 0.5f * lo.z + 0.5f * hi.z};
  for (; l >= 0; --l) {
    const std::uint32_t ix = loose_cell_index(c.x, l);
    const std::uint32_t iy = loose_cell_index(c.y, l);
    const std::uint32_t iz = loose_cell_index(c.z, l);
    if (loose_fits_axis(lo.x, hi.x, ix, l) && loose_fits_axis(lo.y, hi.y, iy, l) &&
        loose_fits_axis(lo.z, hi.z, iz, l)) {
      r.level = l;
      r.ix = ix;
      r.iy = iy;
      r.iz = iz;
      return r;
    }
  }
  r.level = kLooseOverflowLevel;
  return r;
}

/// Places a body with world AABB `b` (m) in a loose octree of depth `max_depth` in
/// [0, 10] (design.md section 5.1): level by size (loose_level_for_extent), cell holding the AABB's
/// centre (clamped to the grid), then the loose-box containment is checked in unit
/// coordinates and the body climbs one level at a time until it holds (it always holds
/// at the chosen level for a centre inside the root cube, up to rounding). A body that
/// fits no loose box (bigger than S, or not inside the root's loose box, e.g. infinite)
/// goes to the overflow list; one with a NaN coordinate is left out (kLooseNoLevel).
/// Guarantee used by the query: a placed body's unit box lies in its cell's loose box.
OCTOCD_HD inline LoosePlace loose_place(const LooseGrid& g, const Aabb& b, int max_depth) {
  if (loose_has_nan(b)) {
    LoosePlace r;
    r.level = kLooseNoLevel;
    return r;
  }
  return loose_place_unit(loose_unit(g, b.min), loose_unit(g, b.max), max_depth);
}

/// First key of `level` in [0, 10]: (8^level - 1) / 7, the number of cells of all
/// coarser levels. (Level 11 would shift past 32 bits: its base is kLooseKeysEnd.)
OCTOCD_HD inline std::uint32_t loose_level_base(int level) {
  return ((1u << (3u * static_cast<unsigned>(level))) - 1u) / 7u;
}

/// The first key after every cell key of levels 0 .. kLooseMaxDepth: (8^11 - 1) / 7 (the
/// largest cell key is one less). Sort keys after the cells' (the device octree's overflow,
/// stray and NaN keys) start here.
constexpr std::uint32_t kLooseKeysEnd =
    static_cast<std::uint32_t>(((1ull << (3 * (kLooseMaxDepth + 1))) - 1ull) / 7ull);
static_assert(kLooseKeysEnd == 1227133513u, "the largest cell key is 1227133512");

/// Key of cell (ix, iy, iz) of `level` (each index < 2^level): loose_level_base(level) +
/// morton3(ix, iy, iz). Orders cells by (level, Morton code).
OCTOCD_HD inline std::uint32_t loose_cell_key(int level, std::uint32_t ix, std::uint32_t iy,
                                              std::uint32_t iz) {
  return loose_level_base(level) + morton3(ix, iy, iz);
}

/// Key of a placement: loose_cell_key for a cell, kLooseOverflowKey or kLooseNoKey.
OCTOCD_HD inline std::uint32_t loose_place_key(const LoosePlace& p) {
  if (p.level == kLooseOverflowLevel) return kLooseOverflowKey;
  if (p.level < 0) return kLooseNoKey;
  return loose_cell_key(p.level, p.ix, p.iy, p.iz);
}

/// Level of a cell key (in [0, 10]); -1 for kLooseOverflowKey and kLooseNoKey.
OCTOCD_HD inline int loose_key_level(std::uint32_t key) {
  if (key >= kLooseOverflowKey) return -1;
  int l = 0;
  while (l < kLooseMaxDepth && key >= loose_level_base(l + 1)) ++l;
  return l;
}

/// A closed range [lo, hi] of cell indices along one axis; empty when lo > hi.
struct LooseRange {
  int lo = 0;
  int hi = -1;
};

/// The cell indices along one axis at `level` whose loose intervals [i - 1/2, i + 3/2]
/// (level-cell units) meet [umin, umax] (unit coordinates) inclusively, as Eq. 6 does,
/// clamped to [0, 2^level - 1]. Empty when none (or for NaN). At most 4 indices when
/// umax - umin <= 2^-level (3 unless a face touches exactly). Exact: every comparison is
/// of i +- 1/2 (exact) with u * 2^level (exact scaling).
OCTOCD_HD inline LooseRange loose_query_axis(float umin, float umax, int level) {
  LooseRange r;
  const int last = (1 << level) - 1;
  const float n = loose_cells_per_axis(level);
  const float tmin = umin * n;
  const float tmax = umax * n;
  // Cell i qualifies iff i + 1.5 >= tmin and i - 0.5 <= tmax.
  if (!(tmin <= static_cast<float>(last) + 1.5f) || !(tmax >= -0.5f)) return r;  // empty / NaN
  int lo = 0;
  if (tmin > 1.5f) {
    lo = static_cast<int>(tmin - 1.5f);  // near the answer; fixed by exact tests below
    while (lo > 0 && static_cast<float>(lo - 1) + 1.5f >= tmin) --lo;
    while (static_cast<float>(lo) + 1.5f < tmin) ++lo;
  }
  int hi = last;
  if (tmax < static_cast<float>(last) - 0.5f) {
    hi = static_cast<int>(tmax + 0.5f);  // tmax + 0.5 in [0, last): truncation = floor
    while (hi < last && static_cast<float>(hi + 1) - 0.5f <= tmax) ++hi;
    while (hi >= 0 && static_cast<float>(hi) - 0.5f > tmax) --hi;
  }
  r.lo = lo;
  r.hi = hi;
  return r;
}

/// Fixed-point form of loose_query_axis, for drivers that query often (the same
/// ranges, in integers): a box's unit interval [umin, umax] on one axis is stored once as
/// qmin = loose_q_min(umin) = ceil(umin * 2^11) and qmax = loose_q_max(umax) =
/// floor(umax * 2^11) (2^11 = two steps per level-10 cell; the scaling is exact), both
/// clamped to [-2^11, 2^12] (unit coordinates [-1, 2], outside which every range is
/// already all or nothing). NaN gives an empty range. Unions of boxes are min / max of
/// these integers (ceil and floor are monotone).
OCTOCD_HD inline std::int32_t loose_q_min(float umin) {
  if (!(umin > -1.0f)) return umin != umin ? 4096 : -2048;  // NaN: empty range
  if (umin >= 2.0f) return 4096;
  const float t = umin * 2048.0f;
  std::int32_t q = static_cast<std::int32_t>(t);  // truncation toward 0
  if (static_cast<float>(q) < t) ++q;             // ceil
  return q;
}

/// See loose_q_min: floor(umax * 2^11) clamped to [-2^11, 2^12]; NaN gives an empty range.
OCTOCD_HD inline std::int32_t loose_q_max(float umax) {
  if (!(umax < 2.0f)) return umax != umax ? -2048 : 4096;  // NaN: empty range
  if (umax <= -1.0f) return -2048;
  const float t = umax * 2048.0f;
  std::int32_t q = static_cast<std::int32_t>(t);
  if (static_cast<float>(q) > t) --q;  // floor
  return q;
}

/// floor(x / 2^s) for x >= -16384 and s in [1, 11], with shifts of non-negative numbers
/// only (no implementation-defined shifts of negative numbers).
OCTOCD_HD inline std::int32_t loose_floor_div_pow2(std::int32_t x, int s) {
  return static_cast<std::int32_t>(static_cast<std::uint32_t>(x + 16384) >> s) - (16384 >> s);
}

/// loose_query_axis(umin, umax, level) from qmin = loose_q_min(umin), qmax =
/// loose_q_max(umax): the same range, exactly. With k = 10 - level: cell i qualifies iff
/// i + 3/2 >= umin 2^level and i - 1/2 <= umax 2^level, i.e. (2^(k+1) i being an
/// integer multiple of 2^(k+1)) iff 2^(k+1) i >= qmin - 3 2^k and 2^(k+1) i <= qmax + 2^k
/// (qmin = ceil(umin 2^11) and qmax = floor(umax 2^11) lose nothing against integer
/// bounds), so lo = ceil((qmin - 3 2^k) / 2^(k+1)) and hi = floor((qmax + 2^k) /
/// 2^(k+1)), clamped to [0, 2^level - 1].
OCTOCD_HD inline LooseRange loose_query_axis_q(std::int32_t qmin, std::int32_t qmax, int level) {
  const int k = kLooseMaxDepth - level;
  const std::int32_t half = 1 << k;  // half a level cell in q units
  const std::int32_t lo = -loose_floor_div_pow2(3 * half - qmin, k + 1);
  const std::int32_t hi = loose_floor_div_pow2(qmax + half, k + 1);
  const std::int32_t last = (1 << level) - 1;
  LooseRange r;
  r.lo = lo < 0 ? 0 : lo;
  r.hi = hi > last ? last : hi;
  return r;
}

/// The loose box of cell (ix, iy, iz) of `level` in world coordinates (m): the cell
/// grown by s_l / 2 on every side. For reports and tests; the broadphase decides in unit
/// coordinates (loose_fits_axis, loose_query_axis), not with this rounded box.
OCTOCD_HD inline Aabb loose_cell_box(const LooseGrid& g, int level, std::uint32_t ix,
                                     std::uint32_t iy, std::uint32_t iz) {
  const float s = g.side / loose_cells_per_axis(level);
  const float fx = static_cast<float>(ix), fy = static_cast<float>(iy), fz = static_cast<float>(iz);
  return {{g.origin.x + (fx - 0.5f) * s, g.origin.y + (fy - 0.5f) * s, g.origin.z + (fz - 0.5f) * s},
          {g.origin.x + (fx + 1.5f) * s, g.origin.y + (fy + 1.5f) * s, g.origin.z + (fz + 1.5f) * s}};
}

/// D_w for `auto` (design.md section 5.1): the level whose cell side is the smallest body extent,
/// i.e. loose_level_for_extent(min_extent_u, 10) where `min_extent_u` is the smallest
/// largest-AABB-side over the bodies in unit coordinates (so the smallest body sits at
/// level D_w). 0 when min_extent_u > 1 or is NaN (no body fits below the root).
OCTOCD_HD inline int loose_auto_depth(float min_extent_u) {
  const int l = loose_level_for_extent(min_extent_u, kLooseMaxDepth);
  return l < 0 ? 0 : l;
}

}  // namespace octocd
