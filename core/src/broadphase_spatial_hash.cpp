/// \file broadphase_spatial_hash.cpp
/// `spatial-hash`: uniform grid of cell size h, hashed by integer cell coordinates
/// (paper section 4.2; design.md section 5.1), with coarser grids for bodies much larger than h.
///
/// The "hash" is a sorted array of (cell key, body) entries, the cell key packing a grid
/// level (4 bits) and the three integer cell coordinates (20 bits each), which is
/// deterministic and needs no hash function. The grids are unbounded. Level 0 is the
/// paper's grid of cell size h; level k has cells of h 2^k (a hierarchical grid, Ericson,
/// Real-Time Collision Detection, ch. 7). A body goes to the finest level where its AABB
/// touches at most kMaxCells cells, cells [floor(min/h_k), floor(max/h_k)] per axis (a
/// monotone mapping, so touching boxes share a cell), within +-2^19 cells; it is entered
/// in every cell it touches there. With the paper's h (bodies about h in size) every body
/// sits at level 0 and this is the plain spatial hash. The levels keep a small h from
/// making every body oversize (tested against every body) and the broadphase O(n^2)
/// (220 ms/frame on boxes-random-10000 with a single level).
/// Only a body with an infinite coordinate, or beyond every level's range, goes to an
/// "oversize" list tested against every body. Bodies with a NaN coordinate never overlap
/// anything (Eq. 6) and are left out.
///
/// Pairs at one level: bodies sharing a cell there, reported only from the cell holding
/// the min corner of the two boxes' intersection, i.e. the cell (max of the two min
/// cells) per axis, which both boxes touch when they overlap. Pairs across levels: each
/// body looks up, at every coarser occupied level, the cells its AABB touches there, and
/// reports a body of that level only from the same min-corner cell (at that level). So
/// each overlapping pair is found exactly once; the result is then sorted by (a, b) with
/// a counting sort.
///
/// Threads: the bodies' cells, the entries' sort and the pairs (in blocks of cells, then of
/// bodies, joined in order) run on the worker team (octocd/parallel.hpp, current_threads());
/// the pairs and counts do not depend on the thread count.

#include <algorithm>
#include <cmath>

#include "octocd/broadphase.hpp"
#include "octocd/parallel.hpp"

#include "broadphase_detail.hpp"

namespace octocd {

namespace {

constexpr std::int64_t kMaxCells = 64;          // cells per body at its level
constexpr std::int64_t kCoordLimit = 1 << 19;   // |cell coordinate| < 2^19 (20 bits)
constexpr int kLevels = 16;                     // levels 0..15 (4 bits)
/// The fewest bodies whose passes run on the worker team (octocd/parallel.hpp): below, one
/// thread costs less than waking others.
constexpr std::size_t kParallelBodiesFrom = 4096;

struct Entry {
  std::uint64_t key;
  std::uint32_t body;
};

enum : std::uint8_t { kGrid = 0, kOversize = 1, kSkip = 2 };

class SpatialHashBroadPhase final : public BroadPhase {
 public:
  explicit SpatialHashBroadPhase(float cell_size) : h_(cell_size) {}

  std::string name() const override { return broadphase_name(BroadPhaseId::spatial_hash); }

  void find_pairs(const std::vector<Aabb>& boxes, std::vector<Pair>& out,
                  BroadPhaseStats& stats) override {
    out.clear();
    const std::size_t n = boxes.size();
    oversize_.clear();
    kind_.assign(n, kGrid);
    level_.assign(n, 0);
    cell0_.resize(3 * n);
    first_.assign(n + 1, 0);
    LoopOptions by_bodies;
    by_bodies.min_items = kParallelBodiesFrom;
    const unsigned threads = loop_threads(n, by_bodies);
    // Per worker, each on its own cache line (the loop adds to them body by body).
    struct alignas(64) Tally {
      std::uint64_t valid = 0;
      std::uint32_t occupied = 0;  // bit k: level k holds a body
    };
    std::vector<Tally> by_worker(threads);

    // Each body's level and cells (their count in first_[i + 1]), on the team.
    parallel_for(n, by_bodies, [&](std::size_t i, unsigned worker) {
      const Aabb& b = boxes[i];
      if (has_nan(b)) {
        kind_[i] = kSkip;
        return;
      }
      ++by_worker[worker].valid;
      std::int64_t c0[3] = {0, 0, 0}, c1[3] = {0, 0, 0};
      int level = 0;
      while (level < kLevels && !cells_at(b, level, c0, c1)) ++level;
      if (level == kLevels) {
        kind_[i] = kOversize;
        return;
      }
      level_[i] = static_cast<std::uint8_t>(level);
      by_worker[worker].occupied |= 1u << level;
      for (int a = 0; a < 3; ++a) cell0_[3 * i + a] = static_cast<std::int32_t>(c0[a]);
      first_[i + 1] = static_cast<std::size_t>((c1[0] - c0[0] + 1) * (c1[1] - c0[1] + 1) * (c1[2] - c0[2] + 1));
    });
    std::uint32_t occupied = 0;
    std::uint64_t valid = 0;
    for (unsigned w = 0; w < threads; ++w) {
      occupied |= by_worker[w].occupied;
      valid += by_worker[w].valid;
    }
    for (std::size_t i = 0; i < n; ++i) {
      first_[i + 1] += first_[i];
      if (kind_[i] == kOversize) oversize_.push_back(static_cast<std::uint32_t>(i));
    }
    // The entries, body by body (each body's cells at first_[i]), then sorted by (key, body).
    entries_.resize(first_[n]);
    parallel_for(n, by_bodies, [&](std::size_t i, unsigned) {
      if (kind_[i] != kGrid) return;
      std::int64_t c0[3] = {0, 0, 0}, c1[3] = {0, 0, 0};
      cells_at(boxes[i], level_[i], c0, c1);
      std::size_t e = first_[i];
      for (std::int64_t x = c0[0]; x <= c1[0]; ++x)
        for (std::int64_t y = c0[1]; y <= c1[1]; ++y)
          for (std::int64_t z = c0[2]; z <= c1[2]; ++z)
            entries_[e++] = {pack(level_[i], x, y, z), static_cast<std::uint32_t>(i)};
    });
    parallel_sort(entries_, threads, [](const Entry& p, const Entry& q) {
      return p.key != q.key ? p.key < q.key : p.body < q.body;
    });

    // Pairs within one level (bodies sharing a cell), then across levels (every body against
    // the bodies of each coarser occupied level in the cells it touches there), each in
    // blocks on the team (a block of entries starts at a cell's first), the blocks' pairs
    // joined in order: the order of one thread.
    const std::size_t m = entries_.size();
    const std::size_t cell_blocks = threads <= 1 ? 1 : std::size_t(threads) * 8;
    const bool across = (occupied & (occupied - 1)) != 0;
    const std::size_t body_blocks = !across ? 0 : threads <= 1 ? 1 : std::size_t(threads) * 8;
    block_out_.resize(cell_blocks + body_blocks);
    std::vector<std::uint64_t> block_candidates(cell_blocks + body_blocks, 0);
    std::vector<std::size_t> cell_start(cell_blocks + 1, m);
    for (std::size_t blk = 0; blk < cell_blocks; ++blk) {
      std::size_t g = m * blk / cell_blocks;
      while (g > 0 && g < m && entries_[g].key == entries_[g - 1].key) ++g;
      cell_start[blk] = g;
    }
    LoopOptions by_block;
    by_block.threads = static_cast<int>(threads);
    by_block.chunk = 1;
    parallel_for(cell_blocks + body_blocks, by_block, [&](std::size_t blk, unsigned) {
      std::vector<Pair>& pairs = block_out_[blk];
      pairs.clear();
      std::uint64_t& candidates = block_candidates[blk];
      if (blk < cell_blocks) {
        std::size_t g = cell_start[blk];
        const std::size_t end = std::max(g, cell_start[blk + 1]);
        while (g < end) {
          std::size_t e = g + 1;
          while (e < m && entries_[e].key == entries_[g].key) ++e;
          const std::uint64_t pop = e - g;
          candidates += pop * (pop - 1) / 2;
          if (pop > 1) {
            const std::uint64_t key = entries_[g].key;
            const int level = static_cast<int>(key >> 60);
            for (std::size_t i = g; i < e; ++i) {
              const std::uint32_t p = entries_[i].body;
              const std::int32_t* cp = &cell0_[3 * p];
              for (std::size_t j = i + 1; j < e; ++j) {
                const std::uint32_t q = entries_[j].body;
                const std::int32_t* cq = &cell0_[3 * q];
                // Overlapping (most cell mates are not), and reported only from the cell of
                // the intersection's min corner.
                if (!overlaps_all_axes(boxes[p], boxes[q]) ||
                    pack(level, std::max(cp[0], cq[0]), std::max(cp[1], cq[1]), std::max(cp[2], cq[2])) != key)
                  continue;
                pairs.push_back({p, q});  // p < q: sorted by body
              }
            }
          }
          g = e;
        }
        return;
      }
      const std::size_t b = blk - cell_blocks;
      for (std::size_t i = n * b / body_blocks; i < n * (b + 1) / body_blocks; ++i) {
        if (kind_[i] != kGrid) continue;
        const std::uint32_t p = static_cast<std::uint32_t>(i);
        for (int level = level_[i] + 1; level < kLevels; ++level) {
          if ((occupied & (1u << level)) == 0) continue;
          std::int64_t c0[3] = {0, 0, 0}, c1[3] = {0, 0, 0};
          cells_at(boxes[i], level, c0, c1);  // coarser than its own: fits
          for (std::int64_t x = c0[0]; x <= c1[0]; ++x)
            for (std::int64_t y = c0[1]; y <= c1[1]; ++y)
              for (std::int64_t z = c0[2]; z <= c1[2]; ++z) {
                const std::uint64_t key = pack(level, x, y, z);
                auto it = std::lower_bound(entries_.begin(), entries_.end(), key,
                                           [](const Entry& en, std::uint64_t k) { return en.key < k; });
                for (; it != entries_.end() && it->key == key; ++it) {
                  const std::uint32_t q = it->body;
                  ++candidates;
                  const std::int32_t* cq = &cell0_[3 * q];
                  if (pack(level, std::max<std::int64_t>(c0[0], cq[0]), std::max<std::int64_t>(c0[1], cq[1]),
                           std::max<std::int64_t>(c0[2], cq[2])) != key)
                    continue;
                  if (overlaps(boxes[p], boxes[q])) pairs.push_back(p < q ? Pair{p, q} : Pair{q, p});
                }
              }
        }
      }
    });
    std::uint64_t candidates = 0;
    std::size_t total = 0;
    for (std::size_t blk = 0; blk < block_out_.size(); ++blk) {
      candidates += block_candidates[blk];
      total += block_out_[blk].size();
    }
    out.reserve(total);
    for (const std::vector<Pair>& pairs : block_out_) out.insert(out.end(), pairs.begin(), pairs.end());

    // Oversize bodies against every other body (oversize pairs once).
    const std::uint64_t o = oversize_.size();
    candidates += o * (valid - o) + o * (o == 0 ? 0 : o - 1) / 2;
    for (const std::uint32_t p : oversize_) {
      for (std::size_t q = 0; q < n; ++q) {
        if (q == p || kind_[q] == kSkip || (kind_[q] == kOversize && q < p)) continue;
        if (overlaps(boxes[p], boxes[q])) {
          const auto qq = static_cast<std::uint32_t>(q);
          out.push_back(p < qq ? Pair{p, qq} : Pair{qq, p});
        }
      }
    }

    detail::sort_pairs(out, n, tmp_pairs_, count_);
    stats.cell_candidates = candidates;
    stats.pairs = out.size();
    std::size_t block_bytes = 0;
    for (const std::vector<Pair>& pairs : block_out_) block_bytes += pairs.capacity() * sizeof(Pair);
    stats.memory_bytes = entries_.capacity() * sizeof(Entry) + oversize_.capacity() * sizeof(std::uint32_t) +
                         kind_.capacity() + level_.capacity() + cell0_.capacity() * sizeof(std::int32_t) +
                         first_.capacity() * sizeof(std::size_t) + block_bytes +
                         tmp_pairs_.capacity() * sizeof(Pair) + count_.capacity() * sizeof(std::uint32_t);
  }

 private:
  static bool has_nan(const Aabb& b) {
    for (int a = 0; a < 3; ++a)
      if (std::isnan(b.min[a]) || std::isnan(b.max[a])) return true;
    return false;
  }

  /// The cell range [c0, c1] of `b` at `level` (cell side h 2^level); false when a
  /// coordinate is out of range or the box touches more than kMaxCells cells there.
  bool cells_at(const Aabb& b, int level, std::int64_t c0[3], std::int64_t c1[3]) const {
    const double inv = 1.0 / (static_cast<double>(h_) * static_cast<double>(std::int64_t{1} << level));
    std::int64_t count = 1;
    for (int a = 0; a < 3; ++a) {
      const double f0 = std::floor(static_cast<double>(b.min[a]) * inv);  // monotone
      const double f1 = std::floor(static_cast<double>(b.max[a]) * inv);
      if (!(f0 > -kCoordLimit && f1 < kCoordLimit && f0 <= f1)) return false;  // also inf
      c0[a] = static_cast<std::int64_t>(f0);
      c1[a] = static_cast<std::int64_t>(f1);
      count *= c1[a] - c0[a] + 1;  // each factor < 2^20 and count <= kMaxCells: no overflow
      if (count > kMaxCells) return false;
    }
    return true;
  }

  static std::uint64_t pack(int level, std::int64_t x, std::int64_t y, std::int64_t z) {
    return (static_cast<std::uint64_t>(level) << 60) |
           (static_cast<std::uint64_t>(x + kCoordLimit) << 40) |
           (static_cast<std::uint64_t>(y + kCoordLimit) << 20) |
           static_cast<std::uint64_t>(z + kCoordLimit);
  }

  float h_;
  std::vector<Entry> entries_;
  std::vector<std::uint32_t> oversize_;
  std::vector<std::uint8_t> kind_;
  std::vector<std::uint8_t> level_;
  std::vector<std::int32_t> cell0_;
  std::vector<std::size_t> first_;               // body i's entries: first_[i] .. first_[i + 1]
  std::vector<std::vector<Pair>> block_out_;     // each block's pairs (cells, then bodies)
  std::vector<Pair> tmp_pairs_;
  std::vector<std::uint32_t> count_;
};

}  // namespace

namespace detail {

std::unique_ptr<BroadPhase> make_host_spatial_hash(const BroadPhaseConfig& config, const Aabb&) {
  return std::make_unique<SpatialHashBroadPhase>(config.cell_size);
}

}  // namespace detail

}  // namespace octocd
