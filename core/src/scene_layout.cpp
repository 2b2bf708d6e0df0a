/// \file scene_layout.cpp
/// The deterministic body generators of a scene's groups (design.md section 3): grid and
/// random layouts of the bodies' centres, fixed and random initial velocities
/// (SplitMix64 streams, the same on every platform).

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

#include "octocd/error.hpp"
#include "octocd/parallel.hpp"
#include "octocd/scene.hpp"
#include "scene_detail.hpp"

namespace octocd {

using namespace scene_detail;

namespace {

/// The fewest tries of a random layout's chunk drawn and tested on the threads (a try is
/// its 27 cells' chains, about a microsecond; fewer run on the caller).
constexpr std::size_t kParallelTriesFrom = 4096;

}  // namespace

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
  //
  // The tries are drawn and tested in chunks on the threads: try t's centre is the
  // stream's outputs 3t, 3t + 1, 3t + 2 (SplitMix64::skip), so each try of a chunk is
  // drawn on its own and tested against the bodies placed before the chunk; a free try is
  // then tested against the chunk's earlier free tries (binned in a second grid of the
  // same cells); the chunk's tries are then taken in order, each placed when free and
  // overlapping no try placed earlier in the chunk (tries past the last body are dropped):
  // what one try after another places, on any thread count. A chunk on one thread runs
  // its tries one after another.
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

  // One chunk of tries: centres, boxes, cells (x + dims_x (y + dims_y z), clamped as below),
  // whether free of the bodies placed before the chunk (kFree), and of the chunk's earlier
  // free tries too (kFree without kNearEarlier).
  constexpr std::size_t kChunkTries = std::size_t{1} << 16;
  constexpr std::uint8_t kFree = 1, kNearEarlier = 2;
  std::vector<Vec3> try_centre;
  std::vector<Aabb> try_box;
  std::vector<std::int64_t> try_cell;
  std::vector<std::uint8_t> try_state, try_placed;
  // The chunk's free tries binned like the placed boxes: the lowest-numbered free try of
  // each cell, then each free try's next in its cell (ascending).
  std::vector<std::uint32_t> chunk_head;  // as many cells as `head`, once a chunk runs on threads
  std::vector<std::uint32_t> chunk_next;
  // Whether try i overlaps a box `boxes[j]` with taken(j) binned (chains `heads`, `nexts`)
  // in its own or the 26 neighbouring cells; a chain is followed while j < `limit` (kNone:
  // to its end; the chunk's chains ascend, so `i` stops them at the earlier tries).
  auto near_hit = [&](std::size_t i, const std::vector<std::uint32_t>& heads, const std::vector<std::uint32_t>& nexts,
                      const auto& boxes, std::size_t limit, auto&& taken) {
    const std::int64_t home = try_cell[i];
    for (std::int64_t dz = -1; dz <= 1; ++dz)
      for (std::int64_t dy = -1; dy <= 1; ++dy)
        for (std::int64_t dx = -1; dx <= 1; ++dx)
          for (std::uint32_t j = heads[static_cast<std::size_t>(home + dx + dims[0] * (dy + dims[1] * dz))]; j < limit;
               j = nexts[j])
            if (taken(j) && overlaps(try_box[i], boxes[j])) return true;
    return false;
  };
  // Whether an earlier free try j < i of the chunk with taken(j) overlaps try i.
  auto earlier_overlap = [&](std::size_t i, auto&& taken) {
    return near_hit(i, chunk_head, chunk_next, try_box, i, taken);
  };
  // Try `first_try + i` of the stream into slot i of the chunk.
  std::uint64_t first_try = 0;
  auto draw = [&](std::size_t i) {
    SplitMix64 r(g.layout.seed);
    r.skip(3 * (first_try + i));
    Vec3 p;
    for (int a = 0; a < 3; ++a) p[a] = r.uniform(region.min[a], region.max[a]);
    std::int64_t cc[3];
    // A drawn centre lies in the region, so its cell is in [1, dims - 2]; clamped there
    // against rounding: a region with min == max on an axis put it in cell 0, and the
    // -1 neighbour below read outside `head` (issue 22).
    for (int a = 0; a < 3; ++a) cc[a] = std::clamp<std::int64_t>(cell_of(static_cast<double>(p[a]), a), 1, dims[a] - 2);
    try_centre[i] = p;
    try_box[i] = translated(body_local_aabb, p);
    try_cell[i] = static_cast<std::int64_t>(cell_index(cc[0], cc[1], cc[2]));
  };
  // Whether try i overlaps no placed box.
  auto free_of_placed = [&](std::size_t i) {
    return !near_hit(i, head, next, placed, kNone, [](std::size_t) { return true; });
  };
  std::size_t k = 0;  // bodies placed
  int rejected = 0;   // consecutive tries rejected for body k
  auto place = [&](std::size_t i) {
    try_placed[i] = 1;
    insert(try_box[i]);
    out.push_back(try_centre[i]);
    ++k;
    rejected = 0;
  };
  auto reject = [&] {
    if (++rejected == kTries)
      c.fail(key,
             "region too small: placed " + std::to_string(k) + " of " + std::to_string(count) +
                 " bodies without overlap, then " + std::to_string(kTries) + " tries failed for body " +
                 std::to_string(k),
             "a region where count bodies fit apart: enlarge layout.min/max, reduce count, or use a grid");
  };
  LoopOptions loop;
  loop.threads = current_threads();
  loop.min_items = kParallelTriesFrom;
  while (k < count) {
    const std::size_t left = count - k;
    const std::size_t m = std::min(kChunkTries, left + left / 4 + 64);
    try_centre.resize(m);
    try_box.resize(m);
    try_cell.resize(m);
    try_state.assign(m, 0);
    try_placed.assign(m, 0);
    if (loop_threads(m, loop) <= 1) {
      // On one thread, one try after another, each placed before the next is drawn.
      for (std::size_t i = 0; i < m && k < count; ++i) {
        draw(i);
        if (free_of_placed(i))
          place(i);
        else
          reject();
      }
      first_try += m;
      continue;
    }
    parallel_for(m, loop, [&](std::size_t i, unsigned) {
      draw(i);
      if (free_of_placed(i)) try_state[i] = kFree;
    });
    if (chunk_head.empty()) chunk_head.assign(head.size(), kNone);
    chunk_next.resize(m);
    for (std::size_t i = m; i-- > 0;)
      if (try_state[i] & kFree) {
        std::uint32_t& h = chunk_head[static_cast<std::size_t>(try_cell[i])];
        chunk_next[i] = h;
        h = static_cast<std::uint32_t>(i);
      }
    parallel_for(m, loop, [&](std::size_t i, unsigned) {
      if ((try_state[i] & kFree) && earlier_overlap(i, [](std::size_t) { return true; })) try_state[i] |= kNearEarlier;
    });
    for (std::size_t i = 0; i < m && k < count; ++i) {
      if ((try_state[i] & kFree) &&
          (!(try_state[i] & kNearEarlier) || !earlier_overlap(i, [&](std::size_t j) { return try_placed[j] != 0; })))
        place(i);
      else
        reject();
    }
    for (std::size_t i = 0; i < m; ++i)
      if (try_state[i] & kFree) chunk_head[static_cast<std::size_t>(try_cell[i])] = kNone;
    first_try += m;
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
