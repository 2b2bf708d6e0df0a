#pragma once
/// \file lbvh.hpp
/// Tree math of the device broadphase `lbvh` (broadphase_lbvh.cu): a linear BVH, the
/// radix tree of Karras ("Maximizing parallelism in the construction of BVHs, octrees,
/// and k-d trees", HPG 2012) over the bodies sorted by the 30-bit Morton code of their
/// AABB centre. Every function is `OCTOCD_HD` (host and device), takes plain values and
/// pointers, allocates nothing and throws nothing, so the host tests run the very code
/// of the kernels (tests/gpu/test_device_broadphase.cpp, LbvhHostModel).
///
/// Layout for n >= 2 sorted bodies ("slots" 0 .. n-1): internal nodes 0 .. n-2, node 0 the
/// root; a child reference is an internal node index, or kLbvhLeaf | slot for a leaf.
/// Internal node i covers the slots [lbvh_first, last] of one contiguous range; `last`
/// is stored per node (LbvhNode::last) so a query can skip every subtree whose slots all
/// come before its own.
///
/// Codes. A body's code is morton3 (math.hpp) of the level-10 cell (loose_cell_index,
/// loose_octree.hpp) of its AABB centre in the unit coordinates of the loose octree's
/// root cube of the scene domain (loose_grid, loose_unit): bodies outside the domain
/// clamp to its border cells and a NaN centre gives cell 0. The codes only shape the
/// tree; the pairs do not depend on them: every internal box is the exact union of its
/// leaves' boxes and every test is octocd::overlaps (Eq. 6).
///
/// Equal codes: delta (Karras's δ) compares (code, slot) as one key, so the tree is the
/// radix tree of distinct keys: 30 code bits and 32 slot bits, depth at most 62
/// internal nodes below the root (δ grows strictly along a path and lies in [2, 63]).

#include <cmath>
#include <cstdint>

#include "octocd/loose_octree.hpp"
#include "octocd/math.hpp"

namespace octocd {
namespace gpu {

/// Bits of an `lbvh` code (3 x 10, morton3); the end bit of the code sort.
constexpr int kLbvhCodeBits = 30;
/// Marks a child reference as a leaf (the low 31 bits are its slot).
constexpr std::uint32_t kLbvhLeaf = 0x80000000u;
/// The root's parent.
constexpr std::uint32_t kLbvhNone = 0xffffffffu;
/// Entries of a query's stack: more than the deepest path (62 internal nodes, see the
/// file comment), so it never overflows.
constexpr int kLbvhStack = 64;

/// An internal node: its children (node index or kLbvhLeaf | slot) and the last slot of
/// its range.
struct LbvhNode {
  std::uint32_t left = 0;
  std::uint32_t right = 0;
  std::uint32_t last = 0;
};

/// The code of an AABB (m) in grid `g`: morton3 of the level-10 cell of its centre (see
/// the file comment). Any box (infinite, NaN) gets a code in [0, 2^30).
OCTOCD_HD inline std::uint32_t lbvh_code(const LooseGrid& g, const Aabb& b) {
  const Vec3 u = loose_unit(g, center(b));
  return morton3(loose_cell_index(u.x, kLooseMaxDepth), loose_cell_index(u.y, kLooseMaxDepth),
                 loose_cell_index(u.z, kLooseMaxDepth));
}

/// Karras's δ(i, j) over the sorted codes (n of them): the length of the common prefix of
/// the keys (code, slot) of slots i and j, -1 when j is outside [0, n). i in [0, n).
OCTOCD_HD inline int lbvh_delta(const std::uint32_t* code, std::int64_t n, std::int64_t i, std::int64_t j) {
  if (j < 0 || j >= n) return -1;
  const std::uint32_t a = code[i], b = code[j];
#if defined(__CUDA_ARCH__)
  if (a != b) return __clz(static_cast<int>(a ^ b));
  return 32 + __clz(static_cast<int>(static_cast<std::uint32_t>(i) ^ static_cast<std::uint32_t>(j)));
#else
  auto clz = [](std::uint32_t x) {
    int c = 0;
    for (std::uint32_t bit = 0x80000000u; bit != 0 && (x & bit) == 0; bit >>= 1) ++c;
    return c;
  };
  if (a != b) return clz(a ^ b);
  return 32 + clz(static_cast<std::uint32_t>(i) ^ static_cast<std::uint32_t>(j));
#endif
}

/// Internal node i (in [0, n - 2], n >= 2) of the radix tree over the n sorted codes
/// (Karras 2012, Algorithm 1): the direction of its range, the range's other end j by an
/// exponential then a binary search, the split by a binary search; a child is a leaf when
/// its range is one slot.
OCTOCD_HD inline LbvhNode lbvh_internal(const std::uint32_t* code, std::int64_t n, std::int64_t i) {
  const std::int64_t d = lbvh_delta(code, n, i, i + 1) > lbvh_delta(code, n, i, i - 1) ? 1 : -1;
  const int delta_min = lbvh_delta(code, n, i, i - d);
  std::int64_t l_max = 2;
  while (lbvh_delta(code, n, i, i + l_max * d) > delta_min) l_max *= 2;
  std::int64_t l = 0;
  for (std::int64_t t = l_max / 2; t >= 1; t /= 2)
    if (lbvh_delta(code, n, i, i + (l + t) * d) > delta_min) l += t;
  const std::int64_t j = i + l * d;
  const int delta_node = lbvh_delta(code, n, i, j);
  std::int64_t s = 0;
  std::int64_t t = l;
  do {  // t = ceil(l / 2), ceil(l / 4), ..., 1
    t = (t + 1) / 2;
    if (lbvh_delta(code, n, i, i + (s + t) * d) > delta_node) s += t;
  } while (t > 1);
  const std::int64_t gamma = i + s * d + (d < 0 ? -1 : 0);
  const std::int64_t lo = i < j ? i : j;
  const std::int64_t hi = i < j ? j : i;
  LbvhNode node;
  node.left = static_cast<std::uint32_t>(gamma) | (lo == gamma ? kLbvhLeaf : 0u);
  node.right = static_cast<std::uint32_t>(gamma + 1) | (hi == gamma + 1 ? kLbvhLeaf : 0u);
  node.last = static_cast<std::uint32_t>(hi);
  return node;
}

/// The smallest box holding a and b. A NaN coordinate of one box is ignored (fminf /
/// fmaxf), so the union of boxes with NaN coordinates still holds every box that can
/// overlap anything: a box with a NaN coordinate overlaps nothing under Eq. 6.
OCTOCD_HD inline Aabb lbvh_union(const Aabb& a, const Aabb& b) {
  return {{fminf(a.min.x, b.min.x), fminf(a.min.y, b.min.y), fminf(a.min.z, b.min.z)},
          {fmaxf(a.max.x, b.max.x), fmaxf(a.max.y, b.max.y), fmaxf(a.max.z, b.max.z)}};
}

/// The query of slot s (box `box`) in a built tree of n >= 2 slots: visits, once each,
/// every slot t > s whose leaf lies under internal nodes whose boxes overlap `box`, in
/// depth-first order, calling leaf(t) (which makes the exact test). Subtrees whose last
/// slot is <= s are skipped, so a pair is met only from its smaller slot. `nodes`,
/// `node_box`: the n - 1 internal nodes and their boxes.
#if defined(__CUDACC__)
#pragma nv_exec_check_disable  // leaf is a device lambda in the kernel, a host one in the tests
#endif
template <class Leaf>
OCTOCD_HD inline void lbvh_query(const LbvhNode* nodes, const Aabb* node_box, std::uint32_t s, const Aabb& box,
                                 Leaf&& leaf) {
  std::uint32_t stack[kLbvhStack];
  int top = 0;
  std::uint32_t node = 0;
  if (!(nodes[0].last > s && overlaps(box, node_box[0]))) return;
  for (;;) {
    const LbvhNode nd = nodes[node];
    bool go[2] = {false, false};
    const std::uint32_t child[2] = {nd.left, nd.right};
    for (int c = 0; c < 2; ++c) {
      const std::uint32_t ref = child[c];
      if (ref & kLbvhLeaf) {
        const std::uint32_t t = ref & ~kLbvhLeaf;
        if (t > s) leaf(t);
      } else {
        go[c] = nodes[ref].last > s && overlaps(box, node_box[ref]);
      }
    }
    if (go[0]) {
      if (go[1]) stack[top++] = child[1];
      node = child[0];
    } else if (go[1]) {
      node = child[1];
    } else if (top > 0) {
      node = stack[--top];
    } else {
      return;
    }
  }
}

}  // namespace gpu
}  // namespace octocd
