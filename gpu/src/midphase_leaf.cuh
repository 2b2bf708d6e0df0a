#pragma once
// The midphase's cell pairs (midphase.cuh): the narrow phase of a leaf item, the test of a
// step's cell pairs, pairs decided without a level step and the first step. CUDA only.
#include "midphase_tiles.cuh"

namespace octocd {
namespace gpu {
namespace mid {

/// The narrow phase of one leaf item of pair k (the whole warp): mesh-box, A's cell `ca`
/// against the box (as mesh_box_descend's last step); mesh-mesh, leaf item `chunk` of A's
/// cell `ca` and B's cell `cb` (MidItem::chunk, leaf_ranges: a chunk of B's vertices against
/// a part of A's, as mesh_mesh_leaf on those). Sets confirmed[k] on a vertex pair within theta;
/// adds the vertex tests to `t`. Early exit off: the item's whole count (the vertex count of
/// A's cell, or filtered A x filtered B of its part and chunk),
/// whether or not the tests are cut short because the pair is confirmed (here or by another
/// warp), so the counts do not depend on timing. Early exit on (the caller skips the item
/// when the pair is already confirmed): mesh-box, the cell's vertex count; mesh-mesh,
/// na x nb for every pair of tiles tested (a tile pair cut short by a hit counts in full),
/// no count over the whole ranges is run, and the pair is checked before every tile of B
/// and of A. `tiles`: the warp's kLeafTile-vertex tiles (warp_tiles). The leaf that
/// confirms the pair stores the vertex pair it found (confirm: the witness) when kWitness
/// and d keeps witnesses; !kWitness compiles the leaf without them (the fused small step);
/// kLean: as exit_on.
template <bool kWitness, bool kLean = false>
__device__ inline void leaf_item(const MidListDesc& d, const PairContext& c, std::uint32_t k, std::uint32_t ca_index,
                                 std::uint32_t cb_index, std::uint32_t chunk, const WarpTiles& tiles, Tally& t) {
  Vec3* const tile_a = tiles.a;
  Vec3* const tile_b = tiles.b;
  std::uint32_t* const id_a = kWitness ? tiles.id_a : nullptr;
  std::uint32_t* const id_b = kWitness ? tiles.id_b : nullptr;
  const std::uint32_t lane = lane_id();
  const hd::OctreeView& A = c.a.octree;
  const MeshOctreeCell ca = A.cells[ca_index];
  std::uint32_t a_begin = ca.first_vertex;  // mesh-mesh: this item's part of A's cell (below)
  std::uint32_t a_end = ca.first_vertex + ca.vertex_count;
  const Vec3 pa = c.a.position;
  const bool exit_early = exit_on<kLean>(d);
  if (c.s.kind == hd::PairKind::MeshBox) {  // as mesh_box_descend's last step
    t.vertex_tests += ca.vertex_count;
    // The answer is known: the tests would not change it (early exit on: checked already).
    if (!exit_early && confirmed_now(d, k)) return;
    // Only the blocks whose box overlaps box_local (the box in A's frame grown by
    // theta + tolerance, as the cell test) can hold a vertex within theta of the box.
    bool hit = false;
    std::uint32_t hj = 0;  // this lane's vertex within theta, once `hit` (kWitness)
    const std::uint32_t g1 = block_end(a_end);
    for (std::uint32_t g0 = a_begin / kVertexBlock; g0 < g1; g0 += 32) {
      unsigned m = blocks_overlapping(c.blocks_a, g0, g1, c.s.box_local);
      while (m) {
        const std::uint32_t j = (g0 + static_cast<std::uint32_t>(__ffs(m) - 1)) * kVertexBlock + lane;
        m &= m - 1u;
        if constexpr (kWitness) {
          if (!hit && j >= a_begin && j < a_end &&
              hd::vertex_box_close(hd::world_vertex(A.vertices[j], pa), c.b.box, c.s.theta2)) {
            hit = true;
            hj = j;
          }
        } else {
          hit = hit || (j >= a_begin && j < a_end &&
                        hd::vertex_box_close(hd::world_vertex(A.vertices[j], pa), c.b.box, c.s.theta2));
        }
      }
    }
    if constexpr (kWitness) {
      const unsigned hits = __ballot_sync(kFull, hit);
      if (hits != 0) {
        const std::uint32_t w = __shfl_sync(kFull, hj, __ffs(hits) - 1);
        if (lane == 0) confirm(d, k, static_cast<unsigned long long>(w) << 32);
      }
    } else {
      if (__any_sync(kFull, hit) && lane == 0) d.confirmed[k] = 1;
    }
    return;
  }
  // As mesh_mesh_leaf: B's vertices inside A's grown cell box (in B's frame) against
  // A's vertices inside B's grown cell box (in A's frame), vertex_close(wa, wb).
  const hd::OctreeView& B = c.b.octree;
  const MeshOctreeCell cb = B.cells[cb_index];
  // This item's share (MidItem::chunk): a chunk of B's cell's vertices against a part of
  // A's cell's vertices.
  std::uint32_t a0, a1, b0, b1;
  leaf_ranges(chunk, ca.vertex_count, cb.vertex_count, a0, a1, b0, b1);
  a_begin = ca.first_vertex + a0;
  a_end = ca.first_vertex + a1;
  const std::uint32_t b_begin = cb.first_vertex + b0;
  const std::uint32_t b_end = cb.first_vertex + b1;
  const Vec3 pb = c.b.position;
  const Aabb a_in_b = hd::moved_grown(ca.box, c.s.d, c.s.margin);
  const Aabb b_in_a = hd::moved_back_grown(cb.box, c.s.d, c.s.margin);
  // Early exit off: the filtered counts, whole blocks of 32 vertices skipped when their box
  // misses the filter box (no vertex of theirs is inside it): the first tile of each range
  // is staged while counting (stage_tile counts what it stages), the rest of the range only
  // counted; the counts are those of the whole ranges. Early exit on: only the first tiles
  // are staged (a tile short of full ends its range, so an empty first tile means no
  // filtered vertex: no vertex test, as mesh_mesh_leaf); with the tile filter as well
  // (d.tile_filter) A's first tile is not staged here: A's tiles are staged per tile of B,
  // only the vertices near it (near_tile).
  const bool filter = filter_on<kLean>(d);
  const bool a_first = !(exit_early && filter);  // A's first tile staged before the tiles of B
  std::uint32_t jb = b_begin / kVertexBlock;  // the next vertex block of B's range to stage
  const std::uint32_t jb_end = block_end(b_end);
  std::uint32_t nb = 0;
  stage_tile(B.vertices, c.blocks_b, b_begin, b_end, a_in_b, pb, tile_b, id_b, jb, nb);
  const std::uint32_t nbf =
      exit_early ? nb
                 : nb + (jb < jb_end ? count_inside(B.vertices, c.blocks_b, jb * kVertexBlock, b_end, a_in_b) : 0u);
  if (nbf == 0) return;  // as mesh_mesh_leaf: no vertex test
  const std::uint32_t ia_end = block_end(a_end);
  std::uint32_t ia_first = a_begin / kVertexBlock;  // A's next block after its first tile
  std::uint32_t na_first = 0;
  if (a_first) {
    stage_tile(A.vertices, c.blocks_a, a_begin, a_end, b_in_a, pa, tile_a, id_a, ia_first, na_first);
    const std::uint32_t naf =
        exit_early ? na_first
                   : na_first + (ia_first < ia_end
                                     ? count_inside(A.vertices, c.blocks_a, ia_first * kVertexBlock, a_end, b_in_a)
                                     : 0u);
    if (!exit_early) t.vertex_tests += static_cast<unsigned long long>(naf) * static_cast<unsigned long long>(nbf);
    if (naf == 0) return;
  }
  // Tiles of B's filtered world vertices against tiles of A's (B's first tile and, for it,
  // A's first tile are already staged); another leaf of this pair may confirm it first
  // (checked between B's tiles, and with the early exit on between A's too): the answer is
  // the same.
  bool found = false;
  bool b_staged = true;  // tile_b holds B's next tile (nb vertices)
  while (!found) {
    if (!b_staged || !exit_early) {  // early exit on: the caller has just checked
      if (confirmed_now(d, k)) break;
    }
    if (!b_staged) {
      if (jb >= jb_end) break;
      nb = 0;
      stage_tile(B.vertices, c.blocks_b, b_begin, b_end, a_in_b, pb, tile_b, id_b, jb, nb);
    }
    if (nb == 0) break;  // (only at the range's end)
    const bool cull = cull_on<kLean>(d);
    Aabb box_b{};
    if (cull || filter) {
      box_b = tile_box(tile_b, nb);
      __syncwarp();  // tile_b is read; it is staged again only after the loop below
    }
    // A's vertices staged for this tile of B: with the tile filter only those near the
    // tile (near_tile), else every one inside b_in_a. An empty filter box holds none of A's
    // vertices: no vertex of this tile can be close to A's (the next tile of B is taken).
    const Aabb a_filter = filter ? near_tile(b_in_a, box_b, pa, c.s.margin) : b_in_a;
    if (filter && box_empty(a_filter)) {
      b_staged = false;
      continue;
    }
    // tile_a still holds A's first tile (if staged: a_first) only while B's first tile is
    // tested.
    bool a_staged = b_staged && a_first;
    b_staged = false;
    std::uint32_t ia = a_staged ? ia_first : a_begin / kVertexBlock;
    std::uint32_t na = a_staged ? na_first : 0u;
    while (!found && nb > 0) {
      if (!a_staged) {
        if (ia >= ia_end) break;
        if (exit_early && confirmed_now(d, k)) break;
        na = 0;
        stage_tile(A.vertices, c.blocks_a, a_begin, a_end, a_filter, pa, tile_a, id_a, ia, na);
      }
      a_staged = false;
      // A pair of tiles whose boxes are apart by theta on some axis has no close vertex
      // pair (tiles_apart: exact), so its tests are skipped (not counted with the exit on).
      if (na > 0 && !(cull && tiles_apart(tile_box(tile_a, na), box_b, c.s.theta2))) {
        if (exit_early) t.vertex_tests += static_cast<unsigned long long>(na) * static_cast<unsigned long long>(nb);
        found = tiles_close(tile_a, na, tile_b, nb, c.s.theta2);
        if constexpr (kWitness) {
          if (found) {
            const unsigned long long w = d.wit.witness != nullptr
                                             ? tiles_witness(tile_a, id_a, na, tile_b, id_b, nb, c.s.theta2)
                                             : kNoWitness;
            if (lane == 0) confirm(d, k, w);
          }
        }
      }
      __syncwarp();
    }
  }
  if constexpr (!kWitness) {
    if (found && lane == 0) d.confirmed[k] = 1;
  }
}

/// The last step's cell pairs of `mask` (bit l: lane l's `item` survived), run as leaves by
/// this warp in lane order instead of being appended to the leaf list: each mesh-mesh cell
/// pair as its leaf_items items, each mesh-box cell once, exactly the items the list would
/// have held (so the same tests and counts); with the early exit on, none after the pair is
/// confirmed, and the cell pairs in the order of `depth` (lane's overlap_depth), deepest
/// first (the likelier hits first; ties in lane order), else in lane order.
__device__ inline void run_leaves(const MidListDesc& d, const PairContext& c, std::uint32_t k, unsigned mask,
                                  const MidItem& item, float depth, LeafTiles& tiles, Tally& t) {
  const WarpTiles warp = warp_tiles(d, tiles);
  const bool mesh_box = c.s.kind == hd::PairKind::MeshBox;
  const bool deepest_first = d.early_exit != 0;
  const unsigned key = __float_as_uint(depth);  // depth >= +0: ordered as the floats
  while (mask) {
    int l;
    if (deepest_first) {
      const bool in = ((mask >> lane_id()) & 1u) != 0;
      const unsigned best = __reduce_max_sync(kFull, in ? key : 0u);
      l = __ffs(__ballot_sync(kFull, in && key == best)) - 1;
    } else {
      l = __ffs(mask) - 1;
    }
    mask &= ~(1u << l);
    const std::uint32_t ca = __shfl_sync(kFull, item.ca, l);
    const std::uint32_t cb = __shfl_sync(kFull, item.cb, l);
    const std::uint32_t chunks =
        mesh_box ? 1u : leaf_items(c.a.octree.cells[ca].vertex_count, c.b.octree.cells[cb].vertex_count);
    for (std::uint32_t ch = 0; ch < chunks; ++ch) {
      if (skip_confirmed(d, k)) return;
      leaf_item<true>(d, c, k, ca, cb, ch, warp, t);
    }
  }
}

/// The smallest extent of the overlap of two boxes (+0 when they touch or miss): how deep a
/// leaf cell pair overlaps, the fused leaves' order with the early exit (run_leaves).
__device__ inline float overlap_depth(const Aabb& a, const Aabb& b) {
  const float x = fminf(a.max.x, b.max.x) - fmaxf(a.min.x, b.min.x);
  const float y = fminf(a.max.y, b.max.y) - fmaxf(a.min.y, b.min.y);
  const float z = fminf(a.max.z, b.max.z) - fmaxf(a.min.z, b.min.z);
  const float m = fminf(x, fminf(y, z));
  return m > 0.0f ? m : 0.0f;
}

/// Tests the cell pairs [a0, a1) x [b0, b1) of pair k (mesh-box: [a0, a1) against the
/// box; b is unused) with the lanes of the warp and appends the overlapping ones; at the
/// last step (`last`) a mesh-mesh cell pair is appended once per leaf item (leaf_items),
/// and the surviving leaf box pairs are counted; with `leaves` (last step only)
/// the surviving cell pairs are run here as leaves (run_leaves) instead of appended. Box
/// tests are counted per 32 cell pairs tested; with the early exit on, the test stops before
/// the next 32 once the pair is confirmed (the caller checked it before the first).
template <bool kLean = false>
__device__ inline void test_cells(const MidListDesc& d, const PairContext& c, std::uint32_t k, std::uint32_t a0,
                                  std::uint32_t a1, std::uint32_t b0, std::uint32_t b1, bool last, Tally& t,
                                  LeafTiles* leaves = nullptr) {
  const bool mesh_box = c.s.kind == hd::PairKind::MeshBox;
  const std::uint32_t nb = mesh_box ? 1u : b1 - b0;
  const std::uint32_t total = (a1 - a0) * nb;
  const hd::OctreeView& A = c.a.octree;
  const hd::OctreeView& B = c.b.octree;
  for (std::uint32_t c0 = 0; c0 < total; c0 += 32) {
    if (c0 > 0 && skip_confirmed<kLean>(d, k)) break;
    t.box_tests += total - c0 < 32u ? total - c0 : 32u;
    const std::uint32_t i = c0 + lane_id();
    bool keep = false;
    MidItem item{k, 0, 0};
    if (i < total) {
      item.ca = a0 + i / nb;
      item.cb = mesh_box ? 0u : b0 + i % nb;
      keep = mesh_box ? overlaps(A.cells[item.ca].box, c.s.box_local)
                      : overlaps(hd::moved_grown(A.cells[item.ca].box, c.s.d, c.s.margin), B.cells[item.cb].box);
    }
    // The leaf items of a surviving cell pair at the last step (one for mesh-box), for the
    // leaf list or the fuse decision's count.
    const bool counted = last && keep && (leaves == nullptr || d.leaf_items != nullptr);
    const std::uint32_t chunks =
        counted ? (mesh_box ? 1u : leaf_items(A.cells[item.ca].vertex_count, B.cells[item.cb].vertex_count)) : 0u;
    if (last) {
      const unsigned mask = __ballot_sync(kFull, keep);
      t.box_pairs += static_cast<unsigned long long>(__popc(mask));
      if (d.leaf_items != nullptr) t.leaf_items += __reduce_add_sync(kFull, chunks);
      if (leaves != nullptr) {
        float depth = 0.0f;  // the order of the leaves with the early exit
        if (keep && exit_on<kLean>(d))
          depth = mesh_box ? overlap_depth(A.cells[item.ca].box, c.s.box_local)
                           : overlap_depth(hd::moved_grown(A.cells[item.ca].box, c.s.d, c.s.margin),
                                           B.cells[item.cb].box);
        run_leaves(d, c, k, mask, item, depth, *leaves, t);
        continue;
      }
    }
    if (last && !mesh_box) {
      append_chunks(d, chunks, item);
    } else {
      append(d, keep, item);
    }
  }
}

/// The pair of sorted key `key` (PairOutput: (a << pair_shift) | b).
__device__ inline Pair unpack_pair(const MidListDesc& d, unsigned long long key) {
  Pair p;
  p.a = static_cast<std::uint32_t>(key >> d.pair_shift);
  p.b = static_cast<std::uint32_t>(key & ((1ull << d.pair_shift) - 1ull));
  return p;
}

/// Whether pair context c is decided without a level step: static-static, hd::setup_pair's
/// PairKind::Decided, or PairKind::Exhaustive.
__device__ inline bool decided_alone(const PairContext& c) {
  return c.static_static || c.s.kind == hd::PairKind::Decided || c.s.kind == hd::PairKind::Exhaustive;
}

/// The answer of a pair decided_alone (one thread): false for static-static, the set-up's
/// result, or hd::exhaustive_contact (also the answer of any other pair, by every level list).
__device__ inline bool alone_answer(const PairContext& c) {
  if (c.static_static) return false;
  return c.s.kind == hd::PairKind::Decided ? c.s.result : hd::exhaustive_contact(c.a, c.b, c.theta);
}

/// Step 0 of a pair not decided_alone, by the warp: the cell pairs of levels la[0] x
/// lb[0] (or A's cells against the box), the overlapping ones appended (every lane calls it).
template <bool kLean = false>
__device__ inline void first_step(const MidListDesc& d, const PairContext& c, std::uint32_t k, Tally& t) {
  const hd::OctreeView& A = c.a.octree;
  const hd::OctreeView& B = c.b.octree;
  const bool mesh_box = c.s.kind == hd::PairKind::MeshBox;
  const int la0 = step_level(d, c, 0, false);
  const int lb0 = mesh_box ? 0 : step_level(d, c, 0, true);
  test_cells<kLean>(d, c, k, A.level_begin(la0), A.level_end(la0), mesh_box ? 0u : B.level_begin(lb0),
             mesh_box ? 1u : B.level_end(lb0), d.steps == 1, t);
}

}  // namespace mid
}  // namespace gpu
}  // namespace octocd
