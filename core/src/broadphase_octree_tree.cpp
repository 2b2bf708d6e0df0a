/// \file broadphase_octree_tree.cpp
/// The tree of the `octree` broadphase (broadphase_octree_tree.hpp): steps 1-5 of the
/// description in broadphase_octree_cache.cpp (keys, order, tables, queries, sorted pairs) and
/// the query of every occupied level that the pair cache's updates use. The tree is a
/// class of this file only (so the compiler sees every call of its per-cell functions);
/// LooseOctreeTree forwards to it.

#include "broadphase_octree_tree.hpp"

#include <algorithm>
#include <cstring>
#include <limits>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif
#include "broadphase_detail.hpp"
#include "octocd/parallel.hpp"

namespace octocd::detail {

namespace {

/// Levels up to this one use a dense table of 8^l entries (8^6 = 262144: 1 MiB) and an
/// occupancy bit map (32 KiB at level 6).
constexpr int kDenseLevels = 6;
constexpr std::uint32_t kEmpty = 0xffffffffu;
/// Dense-table entries: (first slot + 1) in the low kSlotBits bits, (bodies - 1) in the
/// high bits, capped at kCountCap - 1 (then the count is read from Slot::run_end).
constexpr unsigned kSlotBits = 26;
constexpr std::uint32_t kSlotMask = (1u << kSlotBits) - 1u;
constexpr std::uint32_t kCountCap = 1u << (32 - kSlotBits);
/// Below this many bodies the query runs on the calling thread only (a parallel region
/// costs more than the work).
constexpr std::size_t kParallelMinBodies = 4096;
/// In-tree slots per task of the overflow tests when they run on several threads.
constexpr std::uint32_t kOverflowChunk = 4096;
/// Occupied cells per task of the cell queries when they run on several threads.
constexpr std::size_t kCellChunk = 256;
/// Bodies per task of the keys (step 1) when they run on several threads.
constexpr std::size_t kKeyChunk = 1024;

/// The cells of level m whose loose boxes meet q, per axis (loose_query_axis_q); false
/// when the range is empty on some axis.
inline bool level_ranges(const QBox& q, int m, LooseRange& rx, LooseRange& ry, LooseRange& rz) {
  rx = loose_query_axis_q(q.lo[0], q.hi[0], m);
  ry = loose_query_axis_q(q.lo[1], q.hi[1], m);
  rz = loose_query_axis_q(q.lo[2], q.hi[2], m);
  return rx.lo <= rx.hi && ry.lo <= ry.hi && rz.lo <= rz.hi;
}

/// An occupied cell: slots [begin, end) of the sorted order, its level and the union of
/// its bodies' fixed-point boxes (its query box).
struct Cell {
  std::uint32_t begin;
  std::uint32_t end;
  QBox q;
  std::int32_t level;
};

/// Open-addressing hash slot (key kLooseNoKey = free).
struct HashSlot {
  std::uint32_t key;
  std::uint32_t cell;
};

inline std::uint64_t item(std::uint32_t key, std::uint32_t body) {
  return (static_cast<std::uint64_t>(key) << 32) | body;
}

inline std::uint32_t hash_key(std::uint32_t key) { return key * 0x9E3779B1u; }

class Tree {
 public:
  Tree(int depth, const Aabb& domain)
      : depth_cfg_(depth), grid_(loose_grid(domain)) {
    for (std::uint32_t v = 0; v < 1024; ++v) spread_[v] = morton_spread3(v);
    for (int l = 0; l <= kLooseMaxDepth; ++l) level_base_[l] = loose_level_base(l);
    // Offsets of the 27 cells of a 3 x 3 x 3 block, per dense level (bit k = 9z + 3y + x).
    for (int l = 0; l <= kDenseLevels; ++l) {
      for (std::uint32_t k = 0; k < 27; ++k) {
        block_[l][k] = (k / 9u) * (1u << (2 * l)) + ((k / 3u) % 3u) * (1u << l) + k % 3u;
      }
    }
  }

  /// Steps 1-5 on `boxes`: out = the sorted overlapping pairs; returns the candidates.
  std::uint64_t find_pairs(const std::vector<Aabb>& boxes, std::vector<Pair>& out) {
    out.clear();
    const std::size_t n = boxes.size();
    LoopOptions by_bodies;
    by_bodies.min_items = kParallelMinBodies;
    const int threads = static_cast<int>(loop_threads(n, by_bodies));
    if (workers_.size() < static_cast<std::size_t>(threads)) workers_.resize(static_cast<std::size_t>(threads));
    for (int t = 0; t < threads; ++t) {
      auto& f = workers_[static_cast<std::size_t>(t)].flat;
      if (f.size() < 512) f.resize(512);
    }
    compute_keys(boxes, threads);
    sort_order();
    build_cells(boxes, threads);
    build_tables();
    std::uint64_t candidates = 0;
    const auto ncells = static_cast<std::int64_t>(cells_.size());
    if (threads == 1) {
      std::vector<std::uint32_t>& flat = workers_[0].flat;
      for (std::int64_t c = 0; c < ncells; ++c) candidates += query_cell(static_cast<std::uint32_t>(c), flat, out);
      candidates += query_overflow(0, overflow_begin_, true, out);
    } else {
      // Each worker appends to its own pair list; the lists are joined, then sorted (the
      // output does not depend on the thread count or on the schedule). Tasks: blocks of
      // kCellChunk cells, then (with overflow bodies) the overflow tests in chunks of
      // in-tree slots, the last task holding the overflow-overflow tests.
      const std::size_t cell_tasks = (static_cast<std::size_t>(ncells) + kCellChunk - 1) / kCellChunk;
      const std::size_t chunks = (overflow_begin_ + kOverflowChunk - 1) / kOverflowChunk;
      const bool any_overflow = overflow_end_ > overflow_begin_;
      const std::size_t tasks = cell_tasks + (any_overflow ? chunks + 1 : 0);
      for (int t = 0; t < threads; ++t) {
        workers_[static_cast<std::size_t>(t)].pairs.clear();
        workers_[static_cast<std::size_t>(t)].candidates = 0;
      }
      LoopOptions loop;
      loop.threads = threads;
      loop.chunk = 1;
      parallel_for(tasks, loop, [&](std::size_t task, unsigned worker) {
        Worker& w = workers_[worker];
        if (task < cell_tasks) {
          const std::size_t end = std::min(static_cast<std::size_t>(ncells), (task + 1) * kCellChunk);
          for (std::size_t c = task * kCellChunk; c < end; ++c) {
            w.candidates += query_cell(static_cast<std::uint32_t>(c), w.flat, w.pairs);
          }
          return;
        }
        const std::size_t k = task - cell_tasks;
        const auto lo = static_cast<std::uint32_t>(std::min<std::size_t>(k * kOverflowChunk, overflow_begin_));
        const auto hi = static_cast<std::uint32_t>(std::min<std::size_t>((k + 1) * kOverflowChunk, overflow_begin_));
        w.candidates += query_overflow(lo, hi, k == chunks, w.pairs);
      });
      std::size_t total = 0;
      for (int t = 0; t < threads; ++t) total += workers_[static_cast<std::size_t>(t)].pairs.size();
      out.resize(total);
      std::size_t at = 0;
      for (int t = 0; t < threads; ++t) {
        const Worker& w = workers_[static_cast<std::size_t>(t)];
        if (!w.pairs.empty()) std::memcpy(out.data() + at, w.pairs.data(), w.pairs.size() * sizeof(Pair));
        at += w.pairs.size();
        candidates += w.candidates;
      }
    }
    detail::sort_pairs(out, n, tmp_pairs_, count_);
    return candidates;
  }

  std::uint64_t tree_memory_bytes() const {
    std::uint64_t memory_bytes =
        (qbody_.capacity() + qslot_.capacity()) * sizeof(QBox) +
        (key_.capacity() + lin_.capacity() + slot_of_.capacity() + cell_linear_.capacity() +
         radix_count_.capacity() + count_.capacity()) *
            sizeof(std::uint32_t) +
        (order_.capacity() + moved_.capacity() + merge_buf_.capacity()) * sizeof(std::uint64_t) +
        slots_.capacity() * sizeof(Slot) + cells_.capacity() * sizeof(Cell) +
        hash_.capacity() * sizeof(HashSlot) + tmp_pairs_.capacity() * sizeof(Pair);
    for (const auto& t : dense_) memory_bytes += t.capacity() * sizeof(std::uint32_t);
    for (const auto& b : bits_) memory_bytes += b.capacity() * sizeof(std::uint64_t);
    for (const auto& a : soa_) memory_bytes += a.capacity() * sizeof(float);
    for (const auto& w : workers_) {
      memory_bytes += w.flat.capacity() * sizeof(std::uint32_t) + w.pairs.capacity() * sizeof(Pair);
    }
    return memory_bytes;
  }

  /// Step 1: D_w, then the key and fixed-point box of every body (in body order).
  void compute_keys(const std::vector<Aabb>& boxes, int threads) {
    const std::size_t n = boxes.size();
    qbody_.resize(n);
    key_.resize(n);
    lin_.resize(n);
    depth_ = depth_cfg_;
    if (depth_ < 0) {
      float min_ext = std::numeric_limits<float>::infinity();
      for (std::size_t i = 0; i < n; ++i) {
        const Aabb& b = boxes[i];
        float ext = loose_unit_extent(loose_unit(grid_, b.min), loose_unit(grid_, b.max));
        ext = ext < 0.0f ? 0.0f : ext;
        min_ext = ext < min_ext ? ext : min_ext;  // NaN extents are left out
      }
      depth_ = loose_auto_depth(min_ext);
    }
    LoopOptions loop;
    loop.threads = threads;
    loop.chunk = kKeyChunk;
    parallel_for(n, loop, [&](std::size_t i, unsigned) {
      const Aabb& b = boxes[i];
      if (loose_has_nan(b)) {
        key_[i] = kLooseNoKey;
        return;
      }
      const Vec3 lo = loose_unit(grid_, b.min);
      const Vec3 hi = loose_unit(grid_, b.max);
      const LoosePlace pl = loose_place_unit(lo, hi, depth_);
      if (pl.level < 0) {
        key_[i] = kLooseOverflowKey;
        return;
      }
      // = loose_place_key(pl), with tables for the bit spread and the level bases.
      const unsigned l = static_cast<unsigned>(pl.level);
      key_[i] = level_base_[l] + (spread_[pl.ix] | (spread_[pl.iy] << 1) | (spread_[pl.iz] << 2));
      lin_[i] = pl.ix | (pl.iy << l) | (pl.iz << (2 * l));
      qbody_[i] = qbox_of(lo, hi);
    });
  }

  /// Step 2: order_ = items (key << 32 | body) sorted ascending.
  void sort_order() {
    const std::size_t n = key_.size();
    if (order_.size() == n && n > 0) {
      // Reuse the previous order: unchanged items stay sorted; changed ones are merged.
      moved_.clear();
      std::size_t w = 0;
      for (std::size_t k = 0; k < n; ++k) {
        const std::uint32_t body = static_cast<std::uint32_t>(order_[k]);
        const std::uint64_t it = item(key_[body], body);
        if (it == order_[k]) {
          order_[w++] = it;
        } else {
          moved_.push_back(it);
        }
      }
      if (moved_.size() <= n / 4) {
        if (!moved_.empty()) {
          order_.resize(w);
          std::sort(moved_.begin(), moved_.end());
          merge_buf_.resize(n);
          std::merge(order_.begin(), order_.end(), moved_.begin(), moved_.end(),
                     merge_buf_.begin());
          order_.swap(merge_buf_);
        }
        return;
      }
    }
    // From scratch: stable LSD radix sort of the bodies (in body order) by key.
    order_.resize(n);
    merge_buf_.resize(n);
    for (std::size_t i = 0; i < n; ++i) order_[i] = item(key_[i], static_cast<std::uint32_t>(i));
    radix_count_.resize(2048);
    for (int shift = 32; shift < 64; shift += 11) {
      std::fill(radix_count_.begin(), radix_count_.end(), 0u);
      for (std::uint64_t it : order_) ++radix_count_[(it >> shift) & 2047u];
      std::uint32_t sum = 0;
      for (std::uint32_t& c : radix_count_) {
        const std::uint32_t k = c;
        c = sum;
        sum += k;
      }
      for (std::uint64_t it : order_) merge_buf_[radix_count_[(it >> shift) & 2047u]++] = it;
      order_.swap(merge_buf_);
    }
  }

  /// Step 3: the sorted slots, the occupied cells and the overflow run. Bodies are
  /// scattered to their slots in body order (stores, not dependent loads), on `threads`
  /// threads of the worker team.
  void build_cells(const std::vector<Aabb>& boxes, int threads) {
    // Reset the dense-table entries and bits of the previous call's cells.
    for (std::size_t c = 0; c < cells_.size(); ++c) {
      const int l = cells_[c].level;
      if (l > kDenseLevels) continue;
      const std::uint32_t p = cell_linear_[c];
      dense_[static_cast<std::size_t>(l)][p] = 0u;
      bits_[static_cast<std::size_t>(l)][p >> l] = 0u;
    }
    cells_.clear();
    cell_linear_.clear();
    std::fill(std::begin(level_cells_), std::end(level_cells_), 0u);
    const std::size_t n = order_.size();
    std::size_t m = n;  // slots in use: NaN boxes (key kLooseNoKey) sort last, left out
    while (m > 0 && static_cast<std::uint32_t>(order_[m - 1] >> 32) == kLooseNoKey) --m;
    slots_.resize(m);
    qslot_.resize(m);
    slot_of_.resize(n);
    LoopOptions loop;
    loop.threads = threads;
    loop.chunk = kKeyChunk;
    parallel_for(m, loop, [&](std::size_t k, unsigned) {
      slot_of_[static_cast<std::uint32_t>(order_[k])] = static_cast<std::uint32_t>(k);
    });
    parallel_for(n, loop, [&](std::size_t i, unsigned) {
      if (key_[i] == kLooseNoKey) return;
      const std::uint32_t k = slot_of_[i];
      slots_[k].box = boxes[i];
      slots_[k].body = static_cast<std::uint32_t>(i);
      qslot_[k] = qbody_[i];
    });
    overflow_begin_ = overflow_end_ = static_cast<std::uint32_t>(m);
    int level = 0;
    std::uint32_t next_base = loose_level_base(1);
    for (std::uint32_t k = 0; k < m;) {
      const std::uint32_t key = static_cast<std::uint32_t>(order_[k] >> 32);
      if (key == kLooseOverflowKey) {
        overflow_begin_ = k;
        for (; k < m; ++k) slots_[k].run_end = k + 1;
        break;
      }
      while (level < kLooseMaxDepth && key >= next_base) {
        ++level;
        next_base = level < kLooseMaxDepth ? loose_level_base(level + 1) : kLooseOverflowKey;
      }
      Cell cell;
      cell.level = level;
      cell.begin = k;
      cell.q = qslot_[k];
      for (++k; k < m && static_cast<std::uint32_t>(order_[k] >> 32) == key; ++k) {
        const QBox& q = qslot_[k];
        for (int a = 0; a < 3; ++a) {
          cell.q.lo[a] = std::min(cell.q.lo[a], q.lo[a]);
          cell.q.hi[a] = std::max(cell.q.hi[a], q.hi[a]);
        }
      }
      cell.end = k;
      for (std::uint32_t j = cell.begin; j < k; ++j) slots_[j].run_end = k;
      cell_linear_.push_back(lin_[static_cast<std::uint32_t>(order_[cell.begin])]);
      ++level_cells_[level];
      cells_.push_back(cell);
    }
    if (overflow_end_ > overflow_begin_) {
      // Structure of arrays of the in-tree slots, for the overflow tests.
      for (auto& a : soa_) a.resize(overflow_begin_);
      for (std::uint32_t k = 0; k < overflow_begin_; ++k) {
        const Aabb& b = slots_[k].box;
        soa_[0][k] = b.min.x;
        soa_[1][k] = b.min.y;
        soa_[2][k] = b.min.z;
        soa_[3][k] = b.max.x;
        soa_[4][k] = b.max.y;
        soa_[5][k] = b.max.z;
      }
    }
    // Occupied levels, coarse to fine.
    occupied_count_ = 0;
    for (int l = 0; l <= kLooseMaxDepth; ++l) {
      if (level_cells_[l] > 0) occupied_[occupied_count_++] = l;
    }
  }

  /// Step 4a: lookup structures for the occupied cells. Dense levels: a table of the
  /// cell's first slot + 1 (0 = empty) and an occupancy bit map, both indexed by
  /// x + 2^l y + 4^l z; sparse levels: a hash table from key to cell index.
  void build_tables() {
    std::size_t sparse = 0;
    for (int l = kDenseLevels + 1; l <= kLooseMaxDepth; ++l) sparse += level_cells_[l];
    for (int l = 0; l <= kDenseLevels; ++l) {
      if (level_cells_[l] > 0 && dense_[static_cast<std::size_t>(l)].empty()) {
        // Padding: the query reads 3 x 3 x 3 blocks from a range's low corner, up to one
        // plane, one row and 2 cells past the last cell.
        const std::size_t side = std::size_t{1} << l;
        const std::size_t size = side * side * side + side * side + side + 8;
        dense_[static_cast<std::size_t>(l)].assign(size, 0u);
        // A word per row (side^2 rows); the 3 x 3 x 3 block from the last row reads up to
        // two planes and two rows past it: side^2 + 2 side + 2 words (one plane is too
        // few: AddressSanitizer catches the read past its end).
        bits_[static_cast<std::size_t>(l)].assign(side * side + 2 * side + 4, 0u);
      }
    }
    hash_mask_ = 0;
    if (sparse > 0) {
      std::size_t cap = 16;
      while (cap < 2 * sparse) cap *= 2;
      hash_.assign(cap, HashSlot{kLooseNoKey, 0});
      hash_mask_ = static_cast<std::uint32_t>(cap - 1);
    }
    for (std::uint32_t c = 0; c < cells_.size(); ++c) {
      const Cell& cell = cells_[c];
      const std::uint32_t p = cell_linear_[c];
      if (cell.level <= kDenseLevels) {
        std::uint32_t code = std::min(cell.end - cell.begin, kCountCap) - 1u;
        if (slots_.size() >= kSlotMask) code = kCountCap - 1u;  // huge n: begin only
        dense_[static_cast<std::size_t>(cell.level)][p] = (cell.begin + 1u) | (code << kSlotBits);
        bits_[static_cast<std::size_t>(cell.level)][p >> cell.level] |=
            std::uint64_t{1} << (p & ((1u << cell.level) - 1u));
      } else {
        const std::uint32_t x = p & ((1u << cell.level) - 1u);
        const std::uint32_t y = (p >> cell.level) & ((1u << cell.level) - 1u);
        const std::uint32_t z = p >> (2 * cell.level);
        const std::uint32_t key = loose_cell_key(cell.level, x, y, z);
        std::uint32_t h = hash_key(key) & hash_mask_;
        while (hash_[h].key != kLooseNoKey) h = (h + 1) & hash_mask_;
        hash_[h] = {key, c};
      }
    }
  }

  /// Index of the occupied cell (level > kDenseLevels, morton), or kEmpty.
  std::uint32_t find_sparse_cell(int level, std::uint32_t morton) const {
    const std::uint32_t key = loose_level_base(level) + morton;
    for (std::uint32_t h = hash_key(key) & hash_mask_;; h = (h + 1) & hash_mask_) {
      if (hash_[h].key == key) return hash_[h].cell;
      if (hash_[h].key == kLooseNoKey) return kEmpty;
    }
  }

  /// Appends the slots of a cell given by its dense-table entry `e` to scratch at `n`.
  std::uint32_t append_cell(std::uint32_t e, std::uint32_t n, std::vector<std::uint32_t>& scratch) const {
    const std::uint32_t begin = (e & kSlotMask) - 1u;
    if ((e >> kSlotBits) == 0u) {  // one body: the common case
      scratch[n] = begin;
      return n + 1u;
    }
    std::uint32_t len = (e >> kSlotBits) + 1u;
    if (len == kCountCap) len = slots_[begin].run_end - begin;
    if (scratch.size() < n + len + 64) scratch.resize(2 * (n + len + 64));
    for (std::uint32_t j = 0; j < len; ++j) scratch[n + j] = begin + j;
    return n + len;
  }

  /// Appends to scratch (from `n`) the slots of the occupied cells of dense level m in the
  /// ranges; when `own` is not null (the querying cell's own level, cell coordinates
  /// own[0..2]), only the cells after it in the order x + 2^m y + 4^m z. Returns the new
  /// length.
  std::uint32_t gather_dense(int m, const LooseRange& rx, const LooseRange& ry,
                             const LooseRange& rz, const std::uint32_t* own, std::uint32_t n,
                             std::vector<std::uint32_t>& scratch) const {
    const std::uint32_t* table = dense_[static_cast<std::size_t>(m)].data();
    const std::uint64_t* bm = bits_[static_cast<std::size_t>(m)].data();
    const std::size_t row = std::size_t{1} << m;
    const std::size_t plane = std::size_t{1} << (2 * m);
    const std::size_t p0 = static_cast<std::size_t>(rz.lo) * plane +
                           static_cast<std::size_t>(ry.lo) * row + static_cast<std::size_t>(rx.lo);
    if (scratch.size() < n + 128) scratch.resize(2 * (n + 128));
    if (rx.hi - rx.lo <= 2 && ry.hi - ry.lo <= 2 && rz.hi - rz.lo <= 2) {
      // The usual case: the occupancy bits of a fixed 3 x 3 x 3 block from the low
      // corner (one 64-bit word per row: dense levels have rows of <= 64 cells; cells
      // past the range masked out) make a 27-bit mask, bit 9z + 3y + x: the same order
      // as the cells' positions x + 2^m y + 4^m z, so the cells after the own cell are
      // the bits above its bit. Only occupied cells' table entries are read.
      const std::uint64_t* w0 = bm + static_cast<std::size_t>(rz.lo) * row + static_cast<std::size_t>(ry.lo);
      const unsigned sx = static_cast<unsigned>(rx.lo);
      const auto row3 = [w0, sx](std::size_t r) { return static_cast<std::uint32_t>(w0[r] >> sx) & 7u; };
      std::uint32_t mask = row3(0) | (row3(1) << 3) | (row3(2) << 6) | (row3(row) << 9) |
                           (row3(row + 1) << 12) | (row3(row + 2) << 15) | (row3(2 * row) << 18) |
                           (row3(2 * row + 1) << 21) | (row3(2 * row + 2) << 24);
      const std::uint32_t wx = static_cast<std::uint32_t>(rx.hi - rx.lo);
      const std::uint32_t wy = static_cast<std::uint32_t>(ry.hi - ry.lo);
      const std::uint32_t wz = static_cast<std::uint32_t>(rz.hi - rz.lo);
      if ((wx & wy & wz) != 2u) {
        // A range narrower than 3 on some axis (at the grid's border, or a small box).
        const std::uint32_t xm = (2u << wx) - 1u;                                   // x
        const std::uint32_t ym = xm * (wy >= 2u ? 0x49u : wy >= 1u ? 0x9u : 0x1u);   // rows
        mask &= ym * (wz >= 2u ? 0x40201u : wz >= 1u ? 0x201u : 0x1u);              // planes
      }
      if (own != nullptr) {
        const std::uint32_t ko = 9u * (own[2] - static_cast<std::uint32_t>(rz.lo)) +
                                 3u * (own[1] - static_cast<std::uint32_t>(ry.lo)) +
                                 (own[0] - static_cast<std::uint32_t>(rx.lo));
        mask &= ~((2u << ko) - 1u);
      }
      const std::uint32_t* off = block_[m];
      const std::uint32_t* t0 = table + p0;
      while (mask != 0) {
        const int k = __builtin_ctz(mask);
        mask &= mask - 1u;
        n = append_cell(t0[off[k]], n, scratch);
      }
      return n;
    }
    // Wider ranges (a face touching a loose border exactly: up to 5 cells per axis).
    const std::size_t own_pos = own != nullptr ? own[0] + own[1] * row + own[2] * plane : 0;
    for (int z = rz.lo; z <= rz.hi; ++z) {
      for (int y = ry.lo; y <= ry.hi; ++y) {
        const std::size_t r = static_cast<std::size_t>(z) * plane + static_cast<std::size_t>(y) * row;
        for (int x = rx.lo; x <= rx.hi; ++x) {
          const std::uint32_t e = table[r + static_cast<std::size_t>(x)];
          if (e == 0u || (own != nullptr && r + static_cast<std::size_t>(x) <= own_pos)) continue;
          if (scratch.size() < n + 64) scratch.resize(2 * (n + 64));
          n = append_cell(e, n, scratch);
        }
      }
    }
    return n;
  }

  /// Step 4b: the pairs of cell c with its own level (larger slots) and coarser levels.
  std::uint64_t query_cell(std::uint32_t c, std::vector<std::uint32_t>& scratch, std::vector<Pair>& out) const {
    const Cell cell = cells_[c];
    std::uint64_t candidates = 0;
    // Own cell: later slots.
    for (std::uint32_t i = cell.begin + 1; i < cell.end; ++i) {
      const Slot si = slots_[i];
      for (std::uint32_t j = cell.begin; j < i; ++j) {
        if (overlaps_nb(slots_[j].box, si.box)) emit(slots_[j].body, si.body, out);
      }
    }
    const std::uint64_t pop = cell.end - cell.begin;
    candidates += pop * (pop - 1) / 2;

    for (int o = 0; o < occupied_count_; ++o) {
      const int m = occupied_[o];
      if (m > cell.level) break;
      LooseRange rx, ry, rz;
      if (!level_ranges(cell.q, m, rx, ry, rz)) continue;
      const bool own = m == cell.level;
      // The own cell's coordinates (for the own level's "cells after it" rule).
      const std::uint32_t pos = cell_linear_[c];
      const std::uint32_t side_mask = (1u << cell.level) - 1u;
      const std::uint32_t own_xyz[3] = {pos & side_mask, (pos >> cell.level) & side_mask,
                                        pos >> (2 * cell.level)};
      // The slots of the occupied cells of the range (at the own level only cells after
      // this one in the order x + 2^m y + 4^m z), then the tests, one rarely taken branch
      // each.
      std::uint32_t nflat = 0;
      if (m <= kDenseLevels) {
        nflat = gather_dense(m, rx, ry, rz, own ? own_xyz : nullptr, 0u, scratch);
      } else {
        for (int z = rz.lo; z <= rz.hi; ++z) {
          const std::uint32_t mz = morton_spread3(static_cast<std::uint32_t>(z)) << 2;
          for (int y = ry.lo; y <= ry.hi; ++y) {
            const std::uint32_t myz = mz | (morton_spread3(static_cast<std::uint32_t>(y)) << 1);
            for (int x = rx.lo; x <= rx.hi; ++x) {
              const std::uint32_t d = find_sparse_cell(m, myz | morton_spread3(static_cast<std::uint32_t>(x)));
              // At the own level only cells after this one in the order x + 2^m y + 4^m z.
              if (d == kEmpty ||
                  (own && (static_cast<std::uint64_t>(z) << (2 * m)) + (static_cast<std::uint64_t>(y) << m) +
                                  static_cast<std::uint64_t>(x) <= pos)) {
                continue;
              }
              const Cell& other = cells_[d];
              const std::uint32_t len = other.end - other.begin;
              if (scratch.size() < nflat + len) scratch.resize(2 * (nflat + len));
              for (std::uint32_t j = 0; j < len; ++j) scratch[nflat + j] = other.begin + j;
              nflat += len;
            }
          }
        }
      }
      candidates += static_cast<std::uint64_t>(nflat) * pop;
      const std::uint32_t* flat = scratch.data();
      const Slot* slots = slots_.data();
      for (std::uint32_t i = cell.begin; i < cell.end; ++i) {
        const Slot si = slots[i];
#if defined(__SSE2__)
        // Eq. 6 on four lanes at once: the slot's 32 bytes are (min.x, min.y, min.z,
        // max.x) and (max.x, max.y, max.z, body); lanes 0-2 of min <= X.max and of
        // max >= X.min are the six comparisons (same float semantics as overlaps()).
        const __m128 xmax = _mm_setr_ps(si.box.max.x, si.box.max.y, si.box.max.z, 0.0f);
        const __m128 xmin = _mm_setr_ps(si.box.min.x, si.box.min.y, si.box.min.z, 0.0f);
        for (std::uint32_t k = 0; k < nflat; ++k) {
          const float* p = &slots[flat[k]].box.min.x;
          const __m128 lo = _mm_loadu_ps(p);
          const __m128 hi = _mm_loadu_ps(p + 3);
          const int bits = _mm_movemask_ps(_mm_and_ps(_mm_cmple_ps(lo, xmax), _mm_cmpge_ps(hi, xmin)));
          if ((bits & 7) == 7) emit(si.body, slots[flat[k]].body, out);
        }
#else
        for (std::uint32_t k = 0; k < nflat; ++k) {
          const Slot& sj = slots[flat[k]];
          if (overlaps_nb(si.box, sj.box)) emit(si.body, sj.body, out);
        }
#endif
      }
    }
    return candidates;
  }

  /// Step 4c: overflow bodies against the in-tree slots [begin, end) and, when
  /// `with_overflow`, against later overflow bodies. The
  /// in-tree part reads the slots' coordinates as structure of arrays, 64 at a time, so
  /// the compiler vectorises the Eq. 6 test.
  std::uint64_t query_overflow(std::uint32_t begin, std::uint32_t end, bool with_overflow,
                               std::vector<Pair>& out) const {
    // Overflow slots come after every cell's slots (their key sorts last).
    std::uint64_t candidates = 0;
    const float* minx = soa_[0].data();
    const float* miny = soa_[1].data();
    const float* minz = soa_[2].data();
    const float* maxx = soa_[3].data();
    const float* maxy = soa_[4].data();
    const float* maxz = soa_[5].data();
    for (std::uint32_t o = overflow_begin_; o < overflow_end_; ++o) {
      const Aabb bo = slots_[o].box;
      const std::uint32_t body_o = slots_[o].body;
      for (std::uint32_t j0 = begin; j0 < end; j0 += 64) {
        const std::uint32_t len = std::min<std::uint32_t>(64u, end - j0);
        std::uint32_t hit[64];
        for (std::uint32_t k = 0; k < len; ++k) {
          const std::uint32_t j = j0 + k;
          hit[k] = static_cast<std::uint32_t>(minx[j] <= bo.max.x) &
                   static_cast<std::uint32_t>(maxx[j] >= bo.min.x) &
                   static_cast<std::uint32_t>(miny[j] <= bo.max.y) &
                   static_cast<std::uint32_t>(maxy[j] >= bo.min.y) &
                   static_cast<std::uint32_t>(minz[j] <= bo.max.z) &
                   static_cast<std::uint32_t>(maxz[j] >= bo.min.z);
        }
        std::uint32_t any = 0;
        for (std::uint32_t k = 0; k < len; ++k) any |= hit[k];
        if (any == 0) continue;
        for (std::uint32_t k = 0; k < len; ++k) {
          if (hit[k]) emit(body_o, slots_[j0 + k].body, out);
        }
      }
      candidates += end - begin;
      if (!with_overflow) continue;
      for (std::uint32_t j = o + 1; j < overflow_end_; ++j) {
        if (overlaps(bo, slots_[j].box)) emit(body_o, slots_[j].body, out);
      }
      candidates += overflow_end_ - o - 1;
    }
    return candidates;
  }

  static void emit(std::uint32_t p, std::uint32_t q, std::vector<Pair>& out) {
    out.push_back(p < q ? Pair{p, q} : Pair{q, p});
  }

  /// The slots of every occupied cell, at every occupied level, whose loose box meets
  /// the fixed-point box q (in scratch; returns their count).
  std::uint32_t gather_all_levels(const QBox& q, std::vector<std::uint32_t>& scratch) const {
    std::uint32_t nflat = 0;
    for (int o = 0; o < occupied_count_; ++o) {
      const int m = occupied_[o];
      LooseRange rx, ry, rz;
      if (!level_ranges(q, m, rx, ry, rz)) continue;
      for (int z = rz.lo; z <= rz.hi; ++z) {
        for (int y = ry.lo; y <= ry.hi; ++y) {
          for (int x = rx.lo; x <= rx.hi; ++x) {
            std::uint32_t begin = 0, len = 0;
            if (m <= kDenseLevels) {
              const std::size_t p = (static_cast<std::size_t>(z) << (2 * m)) + (static_cast<std::size_t>(y) << m) +
                                    static_cast<std::size_t>(x);
              const std::uint32_t e = dense_[static_cast<std::size_t>(m)][p];
              if (e == 0u) continue;
              begin = (e & kSlotMask) - 1u;
              len = slots_[begin].run_end - begin;
            } else {
              const std::uint32_t d = find_sparse_cell(
                  m, morton_spread3(static_cast<std::uint32_t>(x)) | (morton_spread3(static_cast<std::uint32_t>(y)) << 1) |
                         (morton_spread3(static_cast<std::uint32_t>(z)) << 2));
              if (d == kEmpty) continue;
              begin = cells_[d].begin;
              len = cells_[d].end - begin;
            }
            if (scratch.size() < nflat + len) scratch.resize(2 * (nflat + len));
            for (std::uint32_t j = 0; j < len; ++j) scratch[nflat + j] = begin + j;
            nflat += len;
          }
        }
      }
    }
    return nflat;
  }

  /// How many cells of the occupied levels a query with q visits.
  std::uint64_t cells_met(const QBox& q) const {
    std::uint64_t cells = 0;
    for (int o = 0; o < occupied_count_; ++o) {
      const int m = occupied_[o];
      LooseRange rx, ry, rz;
      if (!level_ranges(q, m, rx, ry, rz)) continue;
      cells += static_cast<std::uint64_t>(rx.hi - rx.lo + 1) * static_cast<std::uint64_t>(ry.hi - ry.lo + 1) *
               static_cast<std::uint64_t>(rz.hi - rz.lo + 1);
    }
    return cells;
  }

  int depth_cfg_;
  LooseGrid grid_;
  int depth_ = 0;
  std::uint32_t block_[kDenseLevels + 1][27];
  std::uint32_t spread_[1024];                 // morton_spread3 of every 10-bit value
  std::uint32_t level_base_[kLooseMaxDepth + 1];  // loose_level_base of every level
  std::vector<QBox> qbody_;               // per body
  std::vector<std::uint32_t> key_;        // per body
  std::vector<std::uint32_t> lin_;        // per body: its cell's x + 2^l y + 4^l z
  std::vector<std::uint64_t> order_;      // sorted (key << 32 | body)
  std::vector<std::uint64_t> moved_;
  std::vector<std::uint64_t> merge_buf_;
  std::vector<std::uint32_t> radix_count_;
  std::vector<std::uint32_t> slot_of_;    // per body: its slot
  std::vector<Slot> slots_;               // per slot (NaN boxes excluded)
  std::vector<QBox> qslot_;               // per slot
  std::vector<float> soa_[6];             // min x, y, z, max x, y, z of in-tree slots
  std::vector<Cell> cells_;               // occupied cells in key order
  std::vector<std::uint32_t> cell_linear_;  // their x + 2^l y + 4^l z
  std::uint32_t level_cells_[kLooseMaxDepth + 1] = {};
  int occupied_[kLooseMaxDepth + 1] = {};
  int occupied_count_ = 0;
  std::uint32_t overflow_begin_ = 0;
  std::uint32_t overflow_end_ = 0;
  std::vector<std::uint32_t> dense_[kDenseLevels + 1];
  std::vector<std::uint64_t> bits_[kDenseLevels + 1];
  std::vector<HashSlot> hash_;
  std::uint32_t hash_mask_ = 0;
  std::vector<Pair> tmp_pairs_;
  /// Per-thread query state: scratch slot list, pairs found, candidates counted.
  struct Worker {
    std::vector<std::uint32_t> flat;
    std::vector<Pair> pairs;
    std::uint64_t candidates = 0;
  };
  std::vector<Worker> workers_;
  std::vector<std::uint32_t> count_;
};

}  // namespace

class LooseOctreeTree::Impl : public Tree {
 public:
  using Tree::Tree;
};

LooseOctreeTree::LooseOctreeTree(int depth, const Aabb& domain) : impl_(std::make_unique<Impl>(depth, domain)) {}
LooseOctreeTree::~LooseOctreeTree() = default;

std::uint64_t LooseOctreeTree::find_pairs(const std::vector<Aabb>& boxes, std::vector<Pair>& out) {
  return impl_->find_pairs(boxes, out);
}
QBox LooseOctreeTree::query_box(const Aabb& box) const {
  return qbox_of(loose_unit(impl_->grid_, box.min), loose_unit(impl_->grid_, box.max));
}
std::uint64_t LooseOctreeTree::cells_met(const QBox& q) const { return impl_->cells_met(q); }
std::uint32_t LooseOctreeTree::gather_all_levels(const QBox& q, std::vector<std::uint32_t>& scratch) const {
  return impl_->gather_all_levels(q, scratch);
}
const Slot* LooseOctreeTree::slots() const { return impl_->slots_.data(); }
std::uint32_t LooseOctreeTree::overflow_begin() const { return impl_->overflow_begin_; }
std::uint32_t LooseOctreeTree::overflow_end() const { return impl_->overflow_end_; }
std::vector<std::uint32_t>& LooseOctreeTree::scratch() { return impl_->workers_[0].flat; }
std::uint64_t LooseOctreeTree::memory_bytes() const { return impl_->tree_memory_bytes(); }

}  // namespace octocd::detail
