#pragma once
/// \file loose_blocks.hpp
/// Block math of the device broadphase `octree` (broadphase_octree_tree.cu): its cell table
/// holds blocks, not cells. Every function is `OCTOCD_HD` (host and device), takes plain
/// values and pointers, allocates nothing and throws nothing, so the host tests run the
/// very code of the kernels (tests/gpu/test_device_broadphase.cpp, LooseBlockHostModel).
///
/// Blocks. A block of level m >= 1 is an aligned group of 2 x 2 x 2 cells of level m (the
/// children of one level m - 1 cell); its cells' keys are the 8 consecutive keys
/// [b, b + 8) with b = loose_cell_key(m, 2 px, 2 py, 2 pz) (morton3 puts the octant
/// o = x | y << 1 | z << 2 in the low 3 bits), so in slot order (key, body) its bodies
/// are one contiguous run of slots. Level 0's block is its one cell (key 0, span 1).
///
/// Table. One 64-bit entry per occupied block: (block key << 32) | the block's first slot,
/// open addressing with linear probing from loose_block_hash over a power-of-two array of
/// at least 2 n entries (footprint::loose_cell_table_entries; at most half full: at most n
/// blocks), empty entries all ones
/// (kLooseBlockEmpty; a block key is below 2^31, never 0xffffffff). One load per probe
/// (the key and the run's start in one word); a run ends where the keys leave the block.
///
/// Query. A window of w cells per axis at level m meets at most floor(w / 2) + 1 blocks per
/// axis (w <= 4: at most 3, 2 for w = 3), so a body probes 8 blocks where it probed 27
/// cells; the slots of a block whose cell is outside the window are skipped by the
/// block's octant mask (loose_octant_mask), so the slots visited, and the exact tests
/// made, are exactly those of the per-cell query (every cell of the window, at the
/// body's own level only the slots after its own).

#include <cstdint>

#include "octocd/loose_octree.hpp"
#include "octocd/math.hpp"

namespace octocd {
namespace gpu {

/// An empty entry of the block table.
constexpr unsigned long long kLooseBlockEmpty = ~0ull;
/// No slot: loose_block_find's answer for a block that holds no body.
constexpr std::uint32_t kLooseNoSlot = 0xffffffffu;

/// loose_key_level of a cell key (key < loose_level_base(kLooseMaxDepth + 1)) without its
/// loop: level l's keys are [(8^l - 1) / 7, (8^(l+1) - 1) / 7), so 7 key + 1 lies in
/// [2^(3 l), 2^(3 l + 3)) and l = floor(log2(7 key + 1) / 3) (64-bit: 7 key + 1 < 2^33).
OCTOCD_HD inline int loose_cell_key_level(std::uint32_t key) {
  const unsigned long long v = 7ull * key + 1ull;
  int log2 = 0;
#if defined(__CUDA_ARCH__)
  log2 = 63 - __clzll(static_cast<long long>(v));
#else
  while ((v >> (log2 + 1)) != 0) ++log2;
#endif
  return log2 / 3;
}

/// Cells (keys) in a block of `level`: 8, or 1 at level 0.
OCTOCD_HD inline std::uint32_t loose_block_span(int level) { return level == 0 ? 1u : 8u; }

/// The block key (its first cell's key) of cell `key` of `level`.
OCTOCD_HD inline std::uint32_t loose_block_key(std::uint32_t key, int level) {
  const std::uint32_t base = loose_level_base(level);
  return base + ((key - base) & ~7u);
}

/// The home entry of a block key in a table of mask + 1 entries (murmur3's 32-bit
/// finaliser: neighbouring block keys differ in low bits only).
OCTOCD_HD inline std::uint32_t loose_block_hash(std::uint32_t k, std::uint32_t mask) {
  k ^= k >> 16;
  k *= 0x85ebca6bu;
  k ^= k >> 13;
  k *= 0xc2b2ae35u;
  k ^= k >> 16;
  return k & mask;
}

/// The table entry of a block: its key and its first slot.
OCTOCD_HD inline unsigned long long loose_block_entry(std::uint32_t block_key, std::uint32_t first_slot) {
  return (static_cast<unsigned long long>(block_key) << 32) | first_slot;
}

/// The first slot of block `block_key`, or kLooseNoSlot when no entry holds it (the table
/// must hold an empty entry: at most half full).
OCTOCD_HD inline std::uint32_t loose_block_find(const unsigned long long* table, std::uint32_t mask,
                                                std::uint32_t block_key) {
  std::uint32_t h = loose_block_hash(block_key, mask);
  for (;;) {
    const unsigned long long e = table[h];
    const auto k = static_cast<std::uint32_t>(e >> 32);
    if (k == block_key) return static_cast<std::uint32_t>(e);
    if (e == kLooseBlockEmpty) return kLooseNoSlot;
    h = (h + 1) & mask;
  }
}

/// Occupancy map. A byte per block, in the order of the block keys: block `bk`'s byte is
/// loose_block_index(bk) (level 0's block 0, level m >= 1's blocks from
/// (loose_level_base(m) + 7) / 8 on: every level's blocks follow the coarser levels'), bit
/// o set when the block's cell of octant o holds a body. Stored as 32-bit words (4 blocks
/// a word: loose_gather_kernel sets the bits with atomicOr); a map of `blocks` bytes covers
/// the blocks of index < blocks (footprint::loose_occupancy_blocks(n): every level down to
/// the bench's deepest at 10^4 .. 4x10^6 bodies); a block outside it reads as every octant
/// occupied (loose_block_octants: 0xff), so the query probes it as without a map. The
/// query intersects a block's window mask with its byte and probes the block table only
/// for a block with an occupied cell in the window (most of a window's blocks are empty at
/// 10^6 bodies: each such probe is a miss of 2.5 entries on average, at a random address
/// of a table of 16-64 MiB), and stops walking a block's run after its last wanted octant.
OCTOCD_HD inline std::uint32_t loose_block_index(std::uint32_t block_key) { return (block_key + 7u) >> 3; }

/// Blocks of levels 0 .. depth (depth in [0, kLooseMaxDepth]): the occupancy index of
/// level depth + 1's first block, loose_block_index(loose_level_base(depth + 1)), in 64
/// bits (level 11's base is above 2^32).
OCTOCD_HD constexpr unsigned long long loose_blocks_through(int depth) {
  return ((((1ull << (3u * static_cast<unsigned>(depth + 1))) - 1ull) / 7ull) + 7ull) >> 3;
}

/// The occupancy byte of block `bk` from a map of `blocks` bytes (0xff outside the map).
OCTOCD_HD inline std::uint32_t loose_block_octants(const std::uint32_t* occupancy, std::uint32_t blocks,
                                                   std::uint32_t bk) {
  const std::uint32_t i = loose_block_index(bk);
  if (i >= blocks) return 0xffu;
  return (occupancy[i >> 2] >> ((i & 3u) * 8u)) & 0xffu;
}

/// The word and the bit of cell `key` (of `level`) in a map of `blocks` bytes: *word =
/// the word's index, the return the bit to set (0 when the cell's block is outside the
/// map: nothing to set).
OCTOCD_HD inline std::uint32_t loose_occupancy_bit(std::uint32_t key, int level, std::uint32_t blocks,
                                                   std::uint32_t* word) {
  const std::uint32_t bk = loose_block_key(key, level);
  const std::uint32_t i = loose_block_index(bk);
  *word = i >> 2;
  if (i >= blocks) return 0u;
  return 1u << ((i & 3u) * 8u + (key - bk));
}

/// Words of a map of `blocks` bytes that levels 0 .. depth use (the words to clear before
/// loose_gather_kernel sets the bits of a find with D_w = depth; overflow and NaN keys
/// have no bit).
OCTOCD_HD inline std::uint32_t loose_occupancy_words(std::uint32_t blocks, int depth) {
  const unsigned long long used = loose_blocks_through(depth);
  return static_cast<std::uint32_t>(((used < blocks ? used : blocks) + 3ull) >> 2);
}

/// Whether slot s (sorted keys, n slots) is the first of its block's run: its key is a
/// cell key of `level` and the slot before holds a key of an earlier block (or none).
OCTOCD_HD inline bool loose_block_first(const std::uint32_t* sorted_key, std::uint32_t s, int level) {
  return s == 0 || sorted_key[s - 1] < loose_block_key(sorted_key[s], level);
}

/// Which of the two cells 2 p and 2 p + 1 along one axis lie in the closed range r: bit 0
/// for 2 p, bit 1 for 2 p + 1.
OCTOCD_HD inline std::uint32_t loose_axis_pair_mask(int p, const LooseRange& r) {
  const int c = 2 * p;
  return (c >= r.lo && c <= r.hi ? 1u : 0u) | (c + 1 >= r.lo && c + 1 <= r.hi ? 2u : 0u);
}

/// The octants o of a block whose cell lies in the window (bit o set; o = x | y << 1 |
/// z << 2, morton3's order), from the three axes' pair masks (loose_axis_pair_mask).
OCTOCD_HD inline std::uint32_t loose_octant_mask(std::uint32_t mx, std::uint32_t my, std::uint32_t mz) {
  const std::uint32_t x = ((mx & 1u) ? 0x55u : 0u) | ((mx & 2u) ? 0xaau : 0u);
  const std::uint32_t y = ((my & 1u) ? 0x33u : 0u) | ((my & 2u) ? 0xccu : 0u);
  const std::uint32_t z = ((mz & 1u) ? 0x0fu : 0u) | ((mz & 2u) ? 0xf0u : 0u);
  return x & y & z;
}

/// The query of slot s (key `key`, a cell of `level`) at level m <= level, cell window
/// rx x ry x rz (loose_query_axis_q): visit(t) for every slot t in a window cell, at
/// m == level only t > s; find(block_key) gives a block's first slot or kLooseNoSlot,
/// octants(block_key) its occupancy byte (loose_block_octants; a set bit for every cell
/// that holds a body, 0xff when unknown): a block with no occupied cell in the window is
/// not looked up, and a block's walk ends after its last occupied cell of the window.
/// `sorted_key` holds the n slots' keys in ascending order (overflow and NaN keys last).
template <class Find, class Octants, class Visit>
OCTOCD_HD inline void loose_block_query(const std::uint32_t* sorted_key, std::uint32_t n, std::uint32_t s,
                                        std::uint32_t key, int level, int m, const LooseRange& rx,
                                        const LooseRange& ry, const LooseRange& rz, Find&& find,
                                        Octants&& octants, Visit&& visit) {
  if (rx.lo > rx.hi || ry.lo > ry.hi || rz.lo > rz.hi) return;
  const std::uint32_t span = loose_block_span(m);
  for (int pz = rz.lo >> 1; pz <= rz.hi >> 1; ++pz) {
    const std::uint32_t mz = loose_axis_pair_mask(pz, rz);
    for (int py = ry.lo >> 1; py <= ry.hi >> 1; ++py) {
      const std::uint32_t my = loose_axis_pair_mask(py, ry);
      for (int px = rx.lo >> 1; px <= rx.hi >> 1; ++px) {
        const std::uint32_t mask = loose_octant_mask(loose_axis_pair_mask(px, rx), my, mz);
        const std::uint32_t bk = loose_cell_key(m, 2u * static_cast<std::uint32_t>(px),
                                                2u * static_cast<std::uint32_t>(py), 2u * static_cast<std::uint32_t>(pz));
        // Same level: a block whose every cell precedes s's own holds only slots before s.
        if (mask == 0 || (m == level && bk + (span - 1) < key)) continue;
        const std::uint32_t want = mask & octants(bk);
        if (want == 0) continue;
        std::uint32_t t = find(bk);
        if (t == kLooseNoSlot) continue;
        if (m == level && t <= s) t = s + 1;
        // The last wanted octant (< span): past it the run holds no wanted slot.
#if defined(__CUDA_ARCH__)
        const std::uint32_t last = 31u - static_cast<std::uint32_t>(__clz(static_cast<int>(want)));
#else
        std::uint32_t last = 0;
        while ((want >> (last + 1)) != 0) ++last;
#endif
        for (; t < n; ++t) {
          const std::uint32_t o = sorted_key[t] - bk;  // the octant while the key is in the block
          if (o > last) break;
          if ((want >> o) & 1u) visit(t);
        }
      }
    }
  }
}

/// The run [*t0, *t1) of the slots of cell `key` of `level` (empty: *t0 == *t1), from its
/// block's first slot (find and octants, as loose_block_query's: a cell whose bit is
/// clear is not looked up).
template <class Find, class Octants>
OCTOCD_HD inline void loose_cell_run(const std::uint32_t* sorted_key, std::uint32_t n, std::uint32_t key, int level,
                                     Find&& find, Octants&& octants, std::uint32_t* t0, std::uint32_t* t1) {
  const std::uint32_t bk = loose_block_key(key, level);
  std::uint32_t t = ((octants(bk) >> (key - bk)) & 1u) != 0 ? find(bk) : kLooseNoSlot;
  if (t == kLooseNoSlot) {
    *t0 = *t1 = 0;
    return;
  }
  while (t < n && sorted_key[t] < key) ++t;  // the block's cells before this one
  *t0 = t;
  while (t < n && sorted_key[t] == key) ++t;
  *t1 = t;
}

}  // namespace gpu
/// The device octree's root with D_w `auto` (kLooseSnapRoot): the
/// domain's root cube `g` grown about its centre to the side e (1 + 2^-10) 2^D, e the
/// smallest body extent (`min_extent_u`, in units of g.side: loose_extent_kernel's
/// minimum) and D the smallest level in [0, 10] for which that side covers g, so that the
/// smallest bodies sit at level D in cells of their own side (plus the margin against the
/// unit rounding) instead of wherever e falls between two powers of two of g.side. The
/// pairs are the same with any root (exact tests); only the cells, so the tests, change
/// (bench boxes: 0.25 / 0.21 / 0.93 / 0.32 x the tests at 10^4 / 10^5 / 10^6 / 4x10^6,
/// test_device_broadphase's ExactTestsPerDepthOnTheBenchBoxes). *depth: D, or
/// loose_auto_depth(min_extent_u) with `g` returned as it is when e is 0, NaN, > 1, g is
/// not usable, or e 2^10 (1 + 2^-10) < 1 (the smallest bodies below level 10's cells).
OCTOCD_HD inline LooseGrid loose_snapped_grid(const LooseGrid& g, float min_extent_u, int* depth) {
  *depth = loose_auto_depth(min_extent_u);
  if (!(min_extent_u > 0.0f) || !(min_extent_u <= 1.0f) || g.inv_side == 0.0f) return g;
  float s = min_extent_u * (1.0f + 1.0f / 1024.0f);  // a level-D cell's side, in units of g.side
  int d = 0;
  while (s < 1.0f && d < kLooseMaxDepth) {
    s *= 2.0f;
    ++d;
  }
  if (s < 1.0f) return g;
  LooseGrid r;
  r.side = g.side * s;
  const float h = 0.5f * g.side, rh = 0.5f * r.side;
  r.origin = {(g.origin.x + h) - rh, (g.origin.y + h) - rh, (g.origin.z + h) - rh};
  if (!(r.side <= 3.4e38f) || !is_finite(r.origin)) return g;
  r.inv_side = 1.0f / r.side;
  *depth = d;
  return r;
}

}  // namespace octocd
