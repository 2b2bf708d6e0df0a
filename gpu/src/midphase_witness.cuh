#pragma once
// The midphase's witness cache (midphase.cuh, "Witnesses"): a pair's last witness, its test
// and the test of the vertex blocks beside it, and the witness pass. CUDA only.
#include "midphase_leaf.cuh"

namespace octocd {
namespace gpu {
namespace mid {

/// WitnessDesc::witness of a static-static pair that the witness pass decided (confirmed[k]
/// = 0, as the set-up would: World::step skips such pairs), which mid_start then skips.
/// Never a vertex pair (A's index ~0u - 1 is past any shape's vertices) and never kept
/// (keep_witness keeps the witnesses of confirmed pairs only).
constexpr unsigned long long kStaticStatic = ~0ull - 1ull;

/// The last step's witness of the pair with sorted key `key` whose first body is `a` (one
/// thread): the first kept key >= `key` from prev_begin[a] (a galloping search: a body's
/// run is short but a wall's holds thousands), kNoWitness unless it is `key` (the pair was
/// not a candidate then, or had no witness). A stale prev_begin[a] (a had no pairs then)
/// cannot find `key`.
__device__ inline unsigned long long last_witness(const MidListDesc& d, std::uint32_t a, unsigned long long key) {
  const WitnessDesc& w = d.wit;
  const std::uint32_t count = *w.prev_count;
  std::uint32_t lo = w.prev_begin[a];
  std::uint32_t hi = count;
  // Every kept key in [prev_begin[a], lo) is below `key`; probes at lo, lo + 1, lo + 3, ...
  for (std::uint32_t span = 1; lo < count; span *= 2) {
    const std::uint32_t probe = count - lo > span - 1 ? lo + span - 1 : count - 1;
    if (w.prev_keys[probe] >= key) {
      hi = probe;
      break;
    }
    lo = probe + 1;
  }
  while (lo < hi) {  // the first key >= `key` in [lo, hi], hi's (when < count) is
    const std::uint32_t mid = lo + (hi - lo) / 2;
    if (w.prev_keys[mid] < key) lo = mid + 1;
    else hi = mid;
  }
  return lo < count && w.prev_keys[lo] == key ? w.prev_witness[lo] : kNoWitness;
}

/// Pair p in context()'s order (A the mesh when one of the two is a box) as its witness
/// tests need it: the bodies, the shapes, theta^2 as hd::setup_pair computes it, and
/// witness w's vertex indices (A's, B's: indices into each shape's octree vertices).
struct WitnessSides {
  std::uint32_t ia, ib;      ///< bodies A and B
  const DeviceShape* A;
  const DeviceShape* B;
  float theta2;              ///< m^2
  std::uint32_t va, vb;      ///< w's vertices of A and B
};

/// Pair p's WitnessSides for witness w (w's vertices are not range-checked here).
__device__ inline WitnessSides witness_sides(const MidListDesc& d, const Pair& p, unsigned long long w) {
  const std::uint32_t sa = d.shape[p.a];
  const std::uint32_t sb = d.shape[p.b];
  const bool swap = d.shapes.shapes[sa].is_mesh == 0;  // as context()
  const float theta = pair_theta(d.shapes.theta[sa], d.shapes.theta[sb]);
  return {swap ? p.b : p.a,
          swap ? p.a : p.b,
          &d.shapes.shapes[swap ? sb : sa],
          &d.shapes.shapes[swap ? sa : sb],
          theta * theta,
          static_cast<std::uint32_t>(w >> 32),
          static_cast<std::uint32_t>(w)};
}

/// Whether pair p (sorted key `key`) is confirmed at its last witness (last_witness; one
/// thread), before and without its set-up: the leaves' vertex test (hd::vertex_close, or
/// hd::vertex_box_close against the box's world AABB) on the same world vertices, A the
/// mesh when one of the two is a box (context()'s order), theta^2 as hd::setup_pair
/// computes it. True only when the descent would confirm the pair: it confirms exactly
/// when some vertex pair passes that test, and such a pair is not decided by the set-up
/// (its early rejection's margin covers theta; aabb-only and level-less models keep no
/// witnesses). False for a static-static pair (never confirmed), no witness, a box-box
/// pair or an index out of range. A tested witness counts as one vertex test (`tests`);
/// *w is the witness.
__device__ inline bool witness_close(const MidListDesc& d, const Pair& p, unsigned long long key,
                                     std::uint32_t& tests, unsigned long long& w) {
  w = last_witness(d, p.a, key);
  if (w == kNoWitness) return false;
  tests += 1;
  if (d.w[p.a] == 0.0f && d.w[p.b] == 0.0f) return false;
  const WitnessSides ws = witness_sides(d, p, w);
  const std::uint32_t ia = ws.ia, ib = ws.ib, va = ws.va, vb = ws.vb;
  const DeviceShape& A = *ws.A;
  const DeviceShape& B = *ws.B;
  const float theta2 = ws.theta2;
  if (A.is_mesh == 0 || va >= A.vertex_count) return false;
  const Vec3 wa = hd::world_vertex(d.shapes.vertices[A.vertex_offset + va], d.x[ia]);
  if (B.is_mesh == 0) return hd::vertex_box_close(wa, d.aabb[ib], theta2);
  return vb < B.vertex_count &&
         hd::vertex_close(wa, hd::world_vertex(d.shapes.vertices[B.vertex_offset + vb], d.x[ib]), theta2);
}

/// Whether some vertex pair beside pair p's last witness w (which failed witness_close) is
/// within theta (the whole warp; warp-uniform): the 32 x 32 pairs of the 32-vertex blocks
/// of A's and B's vertices that hold the witness's two vertices, a lane per B vertex, A's
/// block broadcast by shuffles (mesh-box: A's block against the box). The vertices are in
/// Morton order, so a block is a compact patch: a contact that slid keeps a close pair
/// there. Confirms only as the descent would (any vertex pair that passes the leaves' test
/// confirms the pair); *found is the pair found. The vertex tests run are counted in t.
__device__ inline bool witness_block_close(const MidListDesc& d, const Pair& p, unsigned long long w, Tally& t,
                                           unsigned long long& found) {
  if (d.w[p.a] == 0.0f && d.w[p.b] == 0.0f) return false;  // static-static: never confirmed
  const WitnessSides ws = witness_sides(d, p, w);
  const std::uint32_t ia = ws.ia, ib = ws.ib, va = ws.va, vb = ws.vb;
  const DeviceShape& A = *ws.A;
  const DeviceShape& B = *ws.B;
  const float theta2 = ws.theta2;
  if (A.is_mesh == 0 || va >= A.vertex_count || (B.is_mesh != 0 && vb >= B.vertex_count)) return false;
  const std::uint32_t ja = (va & ~31u) + lane_id();
  const bool a_in = ja < A.vertex_count;
  bool close = false;
  unsigned long long mine = 0;
  if (B.is_mesh == 0) {
    t.vertex_tests += static_cast<unsigned long long>(__popc(__ballot_sync(kFull, a_in)));
    if (a_in) {
      close = hd::vertex_box_close(hd::world_vertex(d.shapes.vertices[A.vertex_offset + ja], d.x[ia]), d.aabb[ib], theta2);
      mine = static_cast<unsigned long long>(ja) << 32;
    }
  } else {
    const std::uint32_t jb = (vb & ~31u) + lane_id();
    const bool b_in = jb < B.vertex_count;
    const unsigned a_mask = __ballot_sync(kFull, a_in);
    t.vertex_tests += static_cast<unsigned long long>(__popc(a_mask)) *
                      static_cast<unsigned long long>(__popc(__ballot_sync(kFull, b_in)));
    const Vec3 wa = a_in ? hd::world_vertex(d.shapes.vertices[A.vertex_offset + ja], d.x[ia]) : Vec3{};
    const Vec3 wb = b_in ? hd::world_vertex(d.shapes.vertices[B.vertex_offset + jb], d.x[ib]) : Vec3{};
    int first = -1;  // the first of A's block within theta of this lane's B vertex
    for (int i = 0; i < 32; ++i) {
      Vec3 ai;
      ai.x = __shfl_sync(kFull, wa.x, i);
      ai.y = __shfl_sync(kFull, wa.y, i);
      ai.z = __shfl_sync(kFull, wa.z, i);
      if (first < 0 && b_in && ((a_mask >> i) & 1u) != 0 && hd::vertex_close(ai, wb, theta2)) first = i;
    }
    if (first >= 0) {
      close = true;
      mine = (static_cast<unsigned long long>((va & ~31u) + static_cast<std::uint32_t>(first)) << 32) | jb;
    }
  }
  const unsigned m = __ballot_sync(kFull, close);
  if (m == 0) return false;
  found = __shfl_sync(kFull, mine, __ffs(m) - 1);
  return true;
}

/// Whether the witness pass tests this step's witnesses (np live pairs; grid-uniform):
/// from d.witness_pass_pairs on (kWitnessPassPairsPerWarp per warp of mid_start's grid);
/// below, mid_start does.
__device__ inline bool witness_pass(const MidListDesc& d, std::uint32_t np) { return np >= d.witness_pass_pairs; }

/// mid_witness's work (before mid_start, with the witness cache on; nothing unless
/// witness_pass): one thread per live candidate pair k (grid-stride), pairs[k] from its
/// sorted key, and confirmed[k] = 1 with witness[k] its last witness when the pair is still
/// within theta there (witness_close), else confirmed[k] = 0 and witness[k] the failed
/// witness or kNoWitness (mid_start then tests the blocks beside it, or sets the pair up). A
/// static-static pair is decided here (confirmed[k] = 0, the set-up's answer: never a
/// contact; witness[k] = kStaticStatic, so mid_start skips it): it has no witness to look
/// up (none is kept for an unconfirmed pair), and mid_start's set-up of it would be a
/// warp's chain of dependent loads (batched worlds' walls: 505,856 such pairs a step at
/// 65,536 copies of bunny-stack-50). A thread per pair keeps every pair's chain of
/// dependent loads (the lookup, the shapes, the two vertices) in flight at once.
__device__ inline void mid_witness_items(const MidListDesc& d) {
  const std::uint32_t np = *d.pair_count < d.pair_capacity ? *d.pair_count : d.pair_capacity;
  if (!witness_pass(d, np)) return;
  std::uint32_t tests = 0;
  for (std::uint32_t k = blockIdx.x * blockDim.x + threadIdx.x; k < np; k += gridDim.x * blockDim.x) {
    const unsigned long long key = d.pair_keys[k];
    const Pair p = unpack_pair(d, key);
    d.pairs[k] = p;
    if (d.w[p.a] == 0.0f && d.w[p.b] == 0.0f) {
      d.confirmed[k] = 0;
      d.wit.witness[k] = kStaticStatic;
      continue;
    }
    unsigned long long w;
    const bool close = witness_close(d, p, key, tests, w);
    d.confirmed[k] = close ? 1 : 0;
    d.wit.witness[k] = w;  // a failed one for mid_start's block test (witness_block_close)
  }
  Tally t;
  t.vertex_tests = __reduce_add_sync(kFull, tests);
  flush(d, t);
}

}  // namespace mid
}  // namespace gpu
}  // namespace octocd
