/// \file broadphase_spatial_hash.cpp
/// `spatial-hash`: uniform grid of cell size h, hashed by integer cell coordinates
/// (paper section 4.2; SPEC 5.1).
///
/// The "hash" is a sorted array of (cell key, body) entries, the cell key packing the
/// three integer cell coordinates (21 bits each), which is deterministic and needs no
/// hash function. The grid is unbounded. A body goes into every cell its AABB touches,
/// cells [floor(min/h), floor(max/h)] per axis (a monotone mapping, so touching boxes
/// share a cell). A body spanning more than kMaxCells cells, or beyond +-2^20 cells, or
/// with an infinite coordinate, goes to an "oversize" list tested against every body.
/// Bodies with a NaN coordinate never overlap anything (Eq. 6) and are left out.
///
/// De-duplication: a pair sharing several cells is reported only from the cell holding
/// the min corner of the two boxes' intersection, i.e. the cell (max of the two min
/// cells) per axis, which both boxes touch when they overlap. The result is then sorted
/// by (a, b) with a counting sort; it is unique by construction.
///
/// The cell math (cells of a box, keys, the de-duplication cell, the NaN and range rules)
/// is octocd/spatial_hash.hpp, shared with the CUDA engine's gpu/src/broadphase_hash.cu.

#include <algorithm>
#include <cmath>

#include "octocd/broadphase.hpp"
#include "octocd/spatial_hash.hpp"

#include "broadphase_detail.hpp"

namespace octocd {

namespace {

constexpr std::int64_t kMaxCells = 4096;        // more cells than this: oversize

struct Entry {
  std::uint64_t key;
  std::uint32_t body;
};

enum : std::uint8_t { kGrid = 0, kOversize = 1, kSkip = 2 };

class SpatialHashBroadPhase final : public BroadPhase {
 public:
  explicit SpatialHashBroadPhase(float cell_size) : h_(cell_size) {}

  std::string name() const override { return "spatial-hash"; }

  void find_pairs(const std::vector<Aabb>& boxes, std::vector<Pair>& out,
                  BroadPhaseStats& stats) override {
    out.clear();
    const std::size_t n = boxes.size();
    entries_.clear();
    oversize_.clear();
    kind_.assign(n, kGrid);
    cell0_.resize(3 * n);
    const double inv_h = hash_inv_cell_size(h_);
    std::uint64_t valid = 0;

    for (std::size_t i = 0; i < n; ++i) {
      // Cells, oversize and NaN rules: octocd/spatial_hash.hpp, shared with the CUDA engine.
      const HashSpan span = hash_span(boxes[i], inv_h, kMaxCells);
      if (span.kind == kHashSkip) {
        kind_[i] = kSkip;
        continue;
      }
      ++valid;
      if (span.kind == kHashOversize) {
        kind_[i] = kOversize;
        oversize_.push_back(static_cast<std::uint32_t>(i));
        continue;
      }
      const std::int32_t* c0 = span.c0;
      const std::int32_t* c1 = span.c1;
      for (int a = 0; a < 3; ++a) cell0_[3 * i + a] = c0[a];
      for (std::int64_t x = c0[0]; x <= c1[0]; ++x) {
        for (std::int64_t y = c0[1]; y <= c1[1]; ++y) {
          for (std::int64_t z = c0[2]; z <= c1[2]; ++z) {
            entries_.push_back({hash_cell_key(x, y, z), static_cast<std::uint32_t>(i)});
          }
        }
      }
    }

    std::sort(entries_.begin(), entries_.end(), [](const Entry& p, const Entry& q) {
      return p.key != q.key ? p.key < q.key : p.body < q.body;
    });

    std::uint64_t candidates = 0;
    const std::size_t m = entries_.size();
    std::size_t g = 0;
    while (g < m) {
      std::size_t e = g + 1;
      while (e < m && entries_[e].key == entries_[g].key) ++e;
      const std::uint64_t pop = e - g;
      candidates += pop * (pop - 1) / 2;
      if (pop > 1) {
        const std::uint64_t key = entries_[g].key;
        for (std::size_t i = g; i < e; ++i) {
          const std::uint32_t p = entries_[i].body;
          const std::int32_t* cp = &cell0_[3 * p];
          for (std::size_t j = i + 1; j < e; ++j) {
            const std::uint32_t q = entries_[j].body;
            const std::int32_t* cq = &cell0_[3 * q];
            // Report only from the cell of the intersection's min corner.
            if (hash_pair_cell_key(cp, cq) != key) continue;
            if (overlaps(boxes[p], boxes[q])) out.push_back({p, q});  // p < q: sorted by body
          }
        }
      }
      g = e;
    }

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
    stats.memory_bytes = entries_.capacity() * sizeof(Entry) +
                         oversize_.capacity() * sizeof(std::uint32_t) + kind_.capacity() +
                         cell0_.capacity() * sizeof(std::int32_t) +
                         tmp_pairs_.capacity() * sizeof(Pair) +
                         count_.capacity() * sizeof(std::uint32_t);
  }

 private:
  float h_;
  std::vector<Entry> entries_;
  std::vector<std::uint32_t> oversize_;
  std::vector<std::uint8_t> kind_;
  std::vector<std::int32_t> cell0_;
  std::vector<Pair> tmp_pairs_;
  std::vector<std::uint32_t> count_;
};

}  // namespace

namespace detail {

std::unique_ptr<BroadPhase> make_spatial_hash_broadphase(float cell_size) {
  return std::make_unique<SpatialHashBroadPhase>(cell_size);
}

}  // namespace detail

}  // namespace octocd
