/// \file scene_layout.cpp
/// The deterministic body generators of a scene's groups (design.md section 3): grid and
/// random layouts of the bodies' centres, fixed and random initial velocities
/// (SplitMix64 streams, the same on every platform).

#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

#include "octocd/error.hpp"
#include "octocd/scene.hpp"
#include "scene_detail.hpp"

namespace octocd {

using namespace scene_detail;

std::vector<Vec3> group_positions(const GroupSpec& g, const Aabb& body_local_aabb, const std::string& origin,
                                  const std::vector<Aabb>& placed_before) {
  if (!g.positions.empty()) return g.positions;
  const Ctx c{origin.empty() ? std::string("<scene>") : origin};
  const std::string key = child(at("groups", static_cast<std::size_t>(g.index)), "layout");
  const Vec3 size = body_local_aabb.max - body_local_aabb.min;
  const std::size_t count = static_cast<std::size_t>(std::max(g.count, 0));

  Aabb region = g.layout.region;
  if (g.layout.region_from_domain) {
    for (int a = 0; a < 3; ++a) {
      const float lo = region.min[a] + 0.5f * size[a];
      const float hi = region.max[a] - 0.5f * size[a];
      if (lo <= hi) {
        region.min[a] = lo;
        region.max[a] = hi;
      } else {
        region.min[a] = region.max[a] = 0.5f * (region.min[a] + region.max[a]);
      }
    }
  }

  std::vector<Vec3> out;
  SplitMix64 rng(g.layout.seed);
  if (g.layout.kind == LayoutSpec::Kind::Grid) {
    const float largest = std::max(size.x, std::max(size.y, size.z));
    const float s = g.layout.spacing > 0.0f ? g.layout.spacing : 1.1f * largest;
    if (!(s > 0.0f) || !std::isfinite(s))
      c.fail(key, "grid spacing is 0 (auto) and the body has zero size", "layout.spacing > 0");
    double n[3];
    for (int a = 0; a < 3; ++a) {
      const double extent = static_cast<double>(region.max[a]) - static_cast<double>(region.min[a]);
      n[a] = std::min(std::floor(extent / static_cast<double>(s) + 1e-4) + 1.0, 1e9);
    }
    const double capacity = n[0] * n[1] * n[2];
    if (static_cast<double>(count) > capacity)
      c.fail(key,
             "the region holds only " + num(capacity) + " bodies (" + num(n[0]) + " x " + num(n[1]) + " x " +
                 num(n[2]) + " in x, y, z at spacing " + num(s) + " m) but count is " + std::to_string(count),
             "a region holding count bodies: enlarge layout.min/max or reduce layout.spacing");
    out.reserve(count);  // after the capacity check: a hostile count fails above, not here
    const auto nx = static_cast<std::size_t>(n[0]);
    const auto nz = static_cast<std::size_t>(n[2]);
    const float j = g.layout.jitter;
    for (std::size_t k = 0; k < count; ++k) {
      const std::size_t idx[3] = {k % nx, k / (nx * nz), (k / nx) % nz};
      Vec3 p;
      for (int a = 0; a < 3; ++a)
        p[a] = static_cast<float>(static_cast<double>(region.min[a]) +
                                  static_cast<double>(idx[a]) * static_cast<double>(s));
      if (j > 0.0f)
        for (int a = 0; a < 3; ++a) p[a] += rng.uniform(-j, j);
      out.push_back(p);
    }
    return out;
  }

  // Random: rejection sampling against the bodies already placed (this group's and
  // `placed_before`). The placed boxes are binned by centre in a uniform grid of cells
  // wider than the largest of them (plus rounding): two overlapping boxes then have
  // centres less than one cell apart per axis, so a drawn box can only overlap boxes
  // binned in its own and the 26 neighbouring cells: the same draws and the same result
  // as testing every placed box, in O(count) instead of O(count^2) (10^6 bodies would
  // otherwise take hours).
  constexpr int kTries = 1000;
  out.reserve(std::min<std::size_t>(count, std::size_t{1} << 24));
  std::vector<Aabb> placed;
  placed.reserve(std::min<std::size_t>(count + placed_before.size(), std::size_t{1} << 24));
  float largest = std::max(size.x, std::max(size.y, size.z));
  for (const Aabb& b : placed_before)
    for (int a = 0; a < 3; ++a) largest = std::max(largest, b.max[a] - b.min[a]);
  // Bins: a dense grid over the region plus one cell of margin on every side, each cell
  // the head of a chain of placed boxes (next index per box). A box is binned by its
  // centre, clamped into the grid: a box of an earlier group centred beyond the margin is
  // more than one cell from every drawn centre, so it cannot overlap a drawn box and its
  // clamped cell only adds a candidate. Cells are at least 1.01 x the largest box (plus
  // rounding), widened until the grid has at most 2^24 cells (a wider cell only adds
  // candidates, never loses one).
  double cell = 1.01 * static_cast<double>(largest) + 1e-3;
  std::int64_t dims[3];
  for (;;) {
    double cells = 1.0;
    for (int a = 0; a < 3; ++a) {
      const double extent = static_cast<double>(region.max[a]) - static_cast<double>(region.min[a]);
      dims[a] = static_cast<std::int64_t>(std::floor(extent / cell)) + 3;
      cells *= static_cast<double>(dims[a]);
    }
    if (cells <= static_cast<double>(1 << 24)) break;
    cell *= 1.25;
  }
  constexpr std::uint32_t kNone = 0xffffffffu;
  std::vector<std::uint32_t> head(static_cast<std::size_t>(dims[0] * dims[1] * dims[2]), kNone);
  std::vector<std::uint32_t> next;
  next.reserve(placed.capacity());
  auto cell_of = [&](double coord, int a) {
    const double grid_min = static_cast<double>(region.min[a]) - cell;
    const double k = std::floor((coord - grid_min) / cell);
    return static_cast<std::int64_t>(std::min(std::max(k, 0.0), static_cast<double>(dims[a] - 1)));
  };
  auto cell_index = [&](std::int64_t x, std::int64_t y, std::int64_t z) {
    return static_cast<std::size_t>(x + dims[0] * (y + dims[1] * z));
  };
  auto centre_cell = [&](const Aabb& b) {
    std::int64_t ci[3];
    for (int a = 0; a < 3; ++a) ci[a] = cell_of(0.5 * (static_cast<double>(b.min[a]) + b.max[a]), a);
    return cell_index(ci[0], ci[1], ci[2]);
  };
  auto insert = [&](const Aabb& b) {
    const auto id = static_cast<std::uint32_t>(placed.size());
    placed.push_back(b);
    std::uint32_t& h = head[centre_cell(b)];
    next.push_back(h);
    h = id;
  };
  for (const Aabb& b : placed_before) insert(b);
  for (std::size_t k = 0; k < count; ++k) {
    bool ok = false;
    for (int t = 0; t < kTries && !ok; ++t) {
      Vec3 p;
      for (int a = 0; a < 3; ++a) p[a] = rng.uniform(region.min[a], region.max[a]);
      const Aabb box = translated(body_local_aabb, p);
      std::int64_t cc[3];
      // A drawn centre lies in the region, so its cell is in [1, dims - 2]; clamped there
      // against rounding: a region with min == max on an axis put it in cell 0, and the
      // -1 neighbour below read outside `head` (issue 22).
      for (int a = 0; a < 3; ++a) cc[a] = std::clamp<std::int64_t>(cell_of(static_cast<double>(p[a]), a), 1, dims[a] - 2);
      ok = true;
      for (std::int64_t dx = -1; dx <= 1 && ok; ++dx)
        for (std::int64_t dy = -1; dy <= 1 && ok; ++dy)
          for (std::int64_t dz = -1; dz <= 1 && ok; ++dz) {
            // A drawn centre lies in the region: its cell is >= 1 and <= dims - 2.
            for (std::uint32_t b = head[cell_index(cc[0] + dx, cc[1] + dy, cc[2] + dz)]; b != kNone; b = next[b])
              if (overlaps(box, placed[b])) {
                ok = false;
                break;
              }
          }
      if (ok) {
        insert(box);
        out.push_back(p);
      }
    }
    if (!ok)
      c.fail(key,
             "region too small: placed " + std::to_string(k) + " of " + std::to_string(count) +
                 " bodies without overlap, then " + std::to_string(kTries) + " tries failed for body " +
                 std::to_string(k),
             "a region where count bodies fit apart: enlarge layout.min/max, reduce count, or use a grid");
  }
  return out;
}

std::vector<Vec3> group_velocities(const GroupSpec& g) {
  const std::size_t count = static_cast<std::size_t>(std::max(g.count, 0));
  if (g.velocity.kind == VelocitySpec::Kind::Fixed) return std::vector<Vec3>(count, g.velocity.value);
  std::vector<Vec3> out;
  out.reserve(count);
  SplitMix64 rng(g.velocity.seed);
  const float m = g.velocity.max_speed;
  for (std::size_t k = 0; k < count; ++k) {
    Vec3 v;
    for (int a = 0; a < 3; ++a) v[a] = rng.uniform(-m, m);
    out.push_back(v);
  }
  return out;
}

}  // namespace octocd
