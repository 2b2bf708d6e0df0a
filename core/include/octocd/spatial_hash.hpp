#pragma once
/// \file spatial_hash.hpp
/// Cell math of the `spatial-hash` broadphase (paper section 4.2; design.md section 5.1: a uniform grid
/// of cell size h), shared by the CPU reference (core/src/broadphase_spatial_hash.cpp)
/// and the CUDA engine (gpu/src/broadphase_spatial_hash.cu), so both put every body in the same
/// cells and de-duplicate pairs by the same cell. Which bodies skip the grid for the
/// oversize list (`max_cells`) is each driver's policy; the pair set does not depend on it.
///
/// Like math.hpp, every function is `OCTOCD_HD`, takes and returns plain values,
/// allocates nothing and throws nothing.
///
/// Cells. The grid is unbounded; a coordinate v (m) lies in cell floor(v / h), computed as
/// floor(double(v) * (1 / double(h))): a non-decreasing function of v, so two boxes that
/// overlap under Eq. 6 (touching faces included) share a cell. A body covers the cells
/// [floor(min / h), floor(max / h)] on each axis. Cell coordinates are kept in
/// (-2^20, 2^20); a cell's key packs the three coordinates, 21 bits each, into 63 bits.
///
/// De-duplication. Two overlapping boxes share every cell of their intersection; the one
/// holding its min corner, (max of the two min cells) per axis, reports the pair.

#include <cstdint>

#include "octocd/math.hpp"

namespace octocd {

/// Cell coordinates lie in (-kHashCoordLimit, kHashCoordLimit) on each axis.
constexpr std::int64_t kHashCoordLimit = std::int64_t{1} << 20;

/// Where a body goes (HashSpan::kind).
enum HashKind : std::uint8_t {
  kHashGrid = 0,      ///< in the grid: its cells are c0 .. c1
  kHashOversize = 1,  ///< tested against every body (too many cells, out of range, infinite)
  kHashSkip = 2,      ///< a NaN coordinate: overlaps nothing (Eq. 6), left out
};

/// The cells of one body.
struct HashSpan {
  std::int32_t c0[3] = {0, 0, 0};  ///< min cell per axis (valid for kHashGrid)
  std::int32_t c1[3] = {0, 0, 0};  ///< max cell per axis (valid for kHashGrid)
  std::uint8_t kind = kHashGrid;   ///< HashKind
  std::uint32_t cells = 0;         ///< number of cells covered (kHashGrid only)
};

/// 1 / h in double precision, h the cell size (m, finite > 0).
OCTOCD_HD inline double hash_inv_cell_size(float h) { return 1.0 / static_cast<double>(h); }

/// floor(double(v) * inv_h): the cell of coordinate v along one axis (as a double; may be
/// out of range, infinite or NaN). Non-decreasing in v.
OCTOCD_HD inline double hash_cell_floor(float v, double inv_h) {
#if defined(__CUDA_ARCH__)
  return floor(static_cast<double>(v) * inv_h);
#else
  return std::floor(static_cast<double>(v) * inv_h);
#endif
}

/// The cells of the body with world AABB `b` (m) for 1 / h = `inv_h`: kHashSkip when a
/// coordinate is NaN; kHashOversize when on some axis the cells are out of
/// (-kHashCoordLimit, kHashCoordLimit) or inverted (min cell > max cell), or when it covers
/// more than `max_cells` cells (>= 1, < 2^31); otherwise kHashGrid with its cell range and
/// count.
OCTOCD_HD inline HashSpan hash_span(const Aabb& b, double inv_h, std::int64_t max_cells) {
  HashSpan s;
  bool over = false;
  std::int64_t count = 1;
  for (int a = 0; a < 3; ++a) {
    const float lo = b.min[a], hi = b.max[a];
    if (lo != lo || hi != hi) {
      s.kind = kHashSkip;
      return s;
    }
    const double f0 = hash_cell_floor(lo, inv_h);
    const double f1 = hash_cell_floor(hi, inv_h);
    if (!(f0 > static_cast<double>(-kHashCoordLimit) && f1 < static_cast<double>(kHashCoordLimit) && f0 <= f1)) {
      over = true;  // keep scanning: a NaN on a later axis still means kHashSkip
      continue;
    }
    s.c0[a] = static_cast<std::int32_t>(f0);
    s.c1[a] = static_cast<std::int32_t>(f1);
    if (over) continue;
    count *= static_cast<std::int64_t>(s.c1[a]) - s.c0[a] + 1;  // each factor < 2^21, count <= max_cells
    if (count > max_cells) over = true;
  }
  if (over) {
    s.kind = kHashOversize;
    return s;
  }
  s.kind = kHashGrid;
  s.cells = static_cast<std::uint32_t>(count);
  return s;
}

/// Key of cell (x, y, z), each coordinate in (-kHashCoordLimit, kHashCoordLimit): the
/// three offset coordinates, 21 bits each, x in the high bits (63 bits; orders cells by
/// x, then y, then z).
OCTOCD_HD inline std::uint64_t hash_cell_key(std::int64_t x, std::int64_t y, std::int64_t z) {
  return (static_cast<std::uint64_t>(x + kHashCoordLimit) << 42) |
         (static_cast<std::uint64_t>(y + kHashCoordLimit) << 21) | static_cast<std::uint64_t>(z + kHashCoordLimit);
}

/// Key of the cell that reports the pair of two grid bodies with min cells `cp` and `cq`:
/// the cell of the min corner of their boxes' intersection, (max of the min cells) per
/// axis, which both boxes cover when they overlap.
OCTOCD_HD inline std::uint64_t hash_pair_cell_key(const std::int32_t* cp, const std::int32_t* cq) {
  return hash_cell_key(cp[0] > cq[0] ? cp[0] : cq[0], cp[1] > cq[1] ? cp[1] : cq[1], cp[2] > cq[2] ? cp[2] : cq[2]);
}

}  // namespace octocd
