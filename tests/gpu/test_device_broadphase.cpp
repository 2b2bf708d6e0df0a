// The device broadphases behind DeviceBroadPhase (gpu/src/device_broadphase.hpp; design.md section 5.1,
// 11) against the CPU oracle `flat`: `octree-strict` at depths 0..10 and auto,
// `spatial-hash` at cell sizes from 1e-6 m (every body out of cell range) to 1000 m (one
// cell), `octree` (loose) when gpu/src/broadphase_octree_tree.cu has make_device_loose_octree,
// and `lbvh` (Karras 2012 linear BVH, broadphase_lbvh.cu).
//
// Oracles and properties, on every AABB set (random 1k and 10k, touching lattices with
// faces on the octree split planes and on the hash cell faces, boxes outside the domain,
// huge and infinite boxes, NaN boxes, zero-size boxes, everything in one cell, empty and
// single-body sets, and the world AABBs of boxes-random-10000 after 100 CPU steps):
// - the device's keys, unpacked, are pairs a < b < n, with no duplicate, and their set is
//   the CPU `flat` set;
// - `octree-strict`: the exact tests counted on the device equal the CPU octree-strict's
//   cell_candidates (both are the pairs in related nodes, same node math);
// - `spatial-hash`: the exact tests are at least the pairs;
// - `lbvh`: the exact tests equal those of the same tree built and queried on the host
//   (LbvhHostModel below: the functions of gpu/src/lbvh.hpp, one slot after another);
// - a rerun on the same instance gives the same total, test count and key set.
// The PairOutput contract: with capacity 0 or 1 the total is still the true count and
// nothing is written past the capacity; a rerun with capacity = total gives the full set.
// find() makes no allocation and no host synchronisation: it is captured into a CUDA
// graph, which then runs on two different sets of boxes (same n) and gives each one's set.
//
// `octree` with its pair cache (broadphase_octree_cache.cu): on a coherent motion every settled
// call's keys are flat's in flat's order (Plain, Build and Hit; a jump makes a Rerun), from
// one CUDA graph per plan too, and incoherent input backs off to the one-shot octree; the
// host planner (coherent_plan.hpp) is checked verdict by verdict without a device.
//
// Without a usable CUDA device the device tests are SKIPPED with the reason; the error
// paths, a check of the AABB sets themselves and the host model of `lbvh` (its tree
// checked node by node and its pairs against `flat` on every set, a planted fault caught)
// need no device and run everywhere.
//
// Environment: OCTOCD_SOURCE_DIR (scenes; default: the source tree this was built from).
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cctype>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <map>
#include <memory>
#include <ostream>
#include <random>
#include <set>
#include <string>
#include <unordered_map>
#include <vector>

#include <cuda_runtime_api.h>
#include <fmt/format.h>

#include "device_broadphase.hpp"
#include "device_buffer.hpp"
#include "device_footprint.hpp"
#include "coherent_plan.hpp"
#include "lbvh.hpp"
#include "loose_blocks.hpp"
#include "octocd/broadphase.hpp"
#include "octocd/cuda_world.hpp"
#include "octocd/engine.hpp"
#include "octocd/error.hpp"
#include "octocd/scene.hpp"
#include "octocd/world.hpp"

using namespace octocd;
using gpu::DeviceBroadPhase;
using gpu::DeviceBuffer;

namespace {

#ifndef OCTOCD_TEST_SOURCE_DIR
#define OCTOCD_TEST_SOURCE_DIR "."
#endif

#define REQUIRE_CUDA_DEVICE()                                           \
  do {                                                                  \
    if (!cuda_device_available()) GTEST_SKIP() << cuda_device_status(); \
  } while (0)

std::string source_dir() {
  const char* root = std::getenv("OCTOCD_SOURCE_DIR");
  return root ? root : OCTOCD_TEST_SOURCE_DIR;
}

constexpr float kInf = std::numeric_limits<float>::infinity();
constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();

// ---- AABB sets ------------------------------------------------------------------------

struct BoxSet {
  std::string name;
  Aabb domain;
  std::vector<Aabb> boxes;
  std::vector<Pair> flat;  ///< the CPU oracle's pairs
};

Aabb cube(float lo, float hi) { return {{lo, lo, lo}, {hi, hi, hi}}; }

Aabb box_at(Vec3 c, Vec3 h) { return {{c.x - h.x, c.y - h.y, c.z - h.z}, {c.x + h.x, c.y + h.y, c.z + h.z}}; }

/// n boxes with centres uniform in `region` and half sides uniform in [hmin, hmax].
std::vector<Aabb> random_boxes(std::size_t n, unsigned seed, const Aabb& region, float hmin, float hmax) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> ux(region.min.x, region.max.x), uy(region.min.y, region.max.y),
      uz(region.min.z, region.max.z), uh(hmin, hmax);
  std::vector<Aabb> out;
  out.reserve(n);
  for (std::size_t i = 0; i < n; ++i) {
    const Vec3 c{ux(rng), uy(rng), uz(rng)};
    const Vec3 h{uh(rng), uh(rng), uh(rng)};
    out.push_back(box_at(c, h));
  }
  return out;
}

/// Unit cubes [i, i+1] x [j, j+1] x [k, k+1] filling [0, 8]^3 (every face shared, every
/// face on a split plane of the octree over [0, 8]^3 and on a hash cell face for h = 1,
/// 0.5, 0.25), plus cubes of side 2 on the even lattice (touching and containing).
std::vector<Aabb> touching_lattice() {
  std::vector<Aabb> out;
  for (int i = 0; i < 8; ++i)
    for (int j = 0; j < 8; ++j)
      for (int k = 0; k < 8; ++k)
        out.push_back({{float(i), float(j), float(k)}, {float(i + 1), float(j + 1), float(k + 1)}});
  for (int i = 0; i < 8; i += 2)
    for (int j = 0; j < 8; j += 2)
      for (int k = 0; k < 8; k += 2)
        out.push_back({{float(i), float(j), float(k)}, {float(i + 2), float(j + 2), float(k + 2)}});
  return out;
}

/// Zero-size boxes (points) and zero-thickness plates on a lattice of multiples of 1/8 in
/// [-1, 1]: many coincide (and so overlap), all lie on octree split planes and hash cell
/// faces.
std::vector<Aabb> degenerate_boxes() {
  std::mt19937 rng(7);
  std::uniform_int_distribution<int> u(0, 16);
  auto coord = [&] { return static_cast<float>(u(rng)) / 8.0f - 1.0f; };
  std::vector<Aabb> out;
  for (int i = 0; i < 800; ++i) {
    const Vec3 p{coord(), coord(), coord()};
    out.push_back({p, p});
  }
  for (int i = 0; i < 200; ++i) {  // plates: zero thickness on one axis
    Vec3 a{coord(), coord(), coord()}, b{coord(), coord(), coord()};
    Aabb box{{std::min(a.x, b.x), std::min(a.y, b.y), std::min(a.z, b.z)},
             {std::max(a.x, b.x), std::max(a.y, b.y), std::max(a.z, b.z)}};
    const int axis = i % 3;
    box.max[axis] = box.min[axis];
    out.push_back(box);
  }
  return out;
}

/// Cubes of every loose-octree level 0 .. 7 of the root cube [-1, 1]^3 (side 0.9 x 2^(1 - l)
/// for level l: 3 of level 0, 10 of level 1, 60 of each finer level), centred near the
/// origin and on the split planes x, y, z in {0, +-0.5, +-0.25} (block and cell borders of
/// every level), so bodies of every level meet bodies of every coarser level, level 0's
/// one-cell block sits right before level 1's first block in key order, and windows cross
/// block borders.
std::vector<Aabb> nested_levels() {
  std::mt19937 rng(11);
  std::uniform_int_distribution<int> plane(-4, 4);
  std::uniform_real_distribution<float> jitter(-0.02f, 0.02f);
  auto coord = [&] {
    const float p = static_cast<float>(plane(rng)) * 0.125f;
    return p + jitter(rng);
  };
  std::vector<Aabb> out;
  for (int level = 0; level <= 7; ++level) {
    const int count = level == 0 ? 3 : (level == 1 ? 10 : 60);
    const float h = 0.45f * 2.0f / static_cast<float>(1 << level);  // half side
    for (int i = 0; i < count; ++i) {
      const Vec3 c{coord(), coord(), coord()};  // braced: evaluated in order
      out.push_back(box_at(c, {h, h, h}));
    }
  }
  return out;
}

/// The world AABBs of a shipped scene after `steps` CPU steps (its own broadphase).
std::vector<Aabb> scene_frame(const std::string& name, int steps, Aabb& domain) {
  const Scene scene = load_scene(source_dir() + "/datasets/scenes/" + name + ".json");
  domain = scene.domain;
  World world(build_model(scene), make_broadphase(scene.broadphase, scene.domain));
  for (int i = 0; i < steps; ++i) world.step();
  return world.world_aabbs();
}

std::vector<Pair> flat_pairs(const std::vector<Aabb>& boxes, const Aabb& domain) {
  BroadPhaseConfig cfg;
  cfg.name = "flat";
  std::vector<Pair> out;
  BroadPhaseStats stats;
  make_broadphase(cfg, domain)->find_pairs(boxes, out, stats);
  return out;
}

/// The names of the AABB sets, in test order.
const std::vector<std::string>& box_set_names() {
  static const std::vector<std::string> names = {
      "empty",    "single", "uniform-1000", "uniform-10000", "touching-lattice", "outside-domain", "huge-and-infinite",
      "nan", "degenerate", "one-cell", "nested-levels", "long-segments", "boxes-random-10000-frame-100",
      "thrown-out"};
  return names;
}

/// The AABB set `name`, with its `flat` pairs (built on first use, then kept).
BoxSet make_box_set(const std::string& name) {
  const Aabb unit = cube(-1.0f, 1.0f);
  BoxSet s{name, unit, {}, {}};
  if (name == "empty") {
  } else if (name == "single") {
    s.boxes = {cube(-0.1f, 0.1f)};
  } else if (name == "uniform-1000") {
    s.boxes = random_boxes(1000, 1, unit, 0.005f, 0.06f);
  } else if (name == "uniform-10000") {
    s.boxes = random_boxes(10000, 2, unit, 0.002f, 0.03f);
  } else if (name == "touching-lattice") {
    s.domain = cube(0.0f, 8.0f);
    s.boxes = touching_lattice();
  } else if (name == "outside-domain") {
    s.boxes = random_boxes(2000, 3, cube(-3.0f, 3.0f), 0.01f, 0.3f);
  } else if (name == "huge-and-infinite") {
    s.boxes = random_boxes(1000, 4, unit, 0.005f, 0.06f);
    s.boxes.insert(s.boxes.begin() + 10, cube(-100.0f, 100.0f));
    s.boxes.insert(s.boxes.begin() + 500, cube(-kInf, kInf));
    s.boxes.push_back(unit);                                               // exactly the domain
    s.boxes.push_back({{0.0f, -0.5f, -0.5f}, {kInf, 0.5f, 0.5f}});         // half-infinite
    s.boxes.push_back({{-kInf, -kInf, -kInf}, {-2.0f, -2.0f, -2.0f}});     // infinite, outside
  } else if (name == "nan") {
    s.boxes = random_boxes(1000, 5, unit, 0.01f, 0.08f);
    for (std::size_t i = 0; i < s.boxes.size(); i += 10) {
      const int axis = static_cast<int>(i / 10) % 3;
      if ((i / 10) % 2 == 0) s.boxes[i].min[axis] = kNaN;
      else s.boxes[i].max[axis] = kNaN;
    }
    s.boxes.push_back({{kNaN, kNaN, kNaN}, {kNaN, kNaN, kNaN}});
    s.boxes.push_back({{-kInf, -kInf, kNaN}, {kInf, kInf, kInf}});  // infinite with a NaN
  } else if (name == "degenerate") {
    s.boxes = degenerate_boxes();
  } else if (name == "one-cell") {
    s.boxes = random_boxes(600, 6, cube(0.3f, 0.31f), 0.0f, 0.002f);
  } else if (name == "nested-levels") {
    s.boxes = nested_levels();
  } else if (name == "long-segments") {
    // Body 0 meets every other body (a segment of 8999 pairs (0, b): two chunks of the
    // octree's sorted mode, whose block radix sorts take 8192 each, spread over blocks),
    // body 1 about 300 (one block's sort: over 64), the rest a handful each (one thread's).
    s.boxes = random_boxes(9000, 8, unit, 0.002f, 0.02f);
    s.boxes[0] = cube(-1.0f, 1.0f);
    s.boxes[1] = cube(-0.6f, 0.0f);
  } else if (name == "thrown-out") {
    // A pile in the domain and bodies thrown out of it (stray bodies of the device octree):
    // small and large ones just past the top face (overlapping the pile's top, each other
    // and boxes whose cells lie deeper than their level by size), a column far above, and
    // a few past a side face.
    s.boxes = random_boxes(4000, 9, cube(-1.0f, 1.0f), 0.01f, 0.05f);
    const auto small = random_boxes(600, 10, {{-1.0f, 0.9f, -1.0f}, {1.0f, 1.6f, 1.0f}}, 0.005f, 0.02f);
    const auto large = random_boxes(200, 11, {{-1.0f, 0.95f, -1.0f}, {1.0f, 1.4f, 1.0f}}, 0.05f, 0.12f);
    const auto far = random_boxes(300, 12, {{-0.2f, 3.0f, -0.2f}, {0.2f, 40.0f, 0.2f}}, 0.01f, 0.05f);
    const auto side = random_boxes(100, 13, {{1.0f, -1.0f, -1.0f}, {1.3f, 1.0f, 1.0f}}, 0.01f, 0.05f);
    for (const auto* v : {&small, &large, &far, &side}) s.boxes.insert(s.boxes.end(), v->begin(), v->end());
  } else if (name == "boxes-random-10000-frame-100") {
    s.boxes = scene_frame("boxes-random-10000", 100, s.domain);
  } else {
    throw std::runtime_error("no box set " + name);
  }
  s.flat = flat_pairs(s.boxes, s.domain);
  return s;
}

const BoxSet& box_set(const std::string& name) {
  static std::map<std::string, BoxSet> cache;
  auto it = cache.find(name);
  if (it == cache.end()) it = cache.emplace(name, make_box_set(name)).first;
  return it->second;
}

// ---- `lbvh` on the host -----------------------------------------------------------------

/// The `lbvh` of gpu/src/lbvh.hpp run on the host, one slot after another, as the kernels
/// of broadphase_lbvh.cu run it: the same tree (CUB's radix sort is stable, so the slots
/// are in (code, body) order), the same boxes, the same query.
struct HostLbvh {
  std::vector<std::uint32_t> code;       ///< per slot
  std::vector<std::uint32_t> slot_body;  ///< per slot
  std::vector<Aabb> slot_box;            ///< per slot
  std::vector<gpu::LbvhNode> nodes;      ///< n - 1 internal nodes
  std::vector<Aabb> node_box;            ///< n - 1 internal boxes (refitted)
  std::vector<Pair> pairs;               ///< found by the query, sorted
  std::uint64_t tests = 0;               ///< the query's exact tests (leaf tests)
  int depth = 0;                         ///< internal nodes on the longest root-to-leaf path
  std::string broken;                    ///< "" when the tree checks out, else what is wrong
};

/// The pairs and exact tests of the query of every slot on the built tree `h`.
void host_lbvh_query(HostLbvh& h) {
  h.pairs.clear();
  h.tests = 0;
  const auto n = static_cast<std::uint32_t>(h.slot_box.size());
  if (n < 2) return;
  for (std::uint32_t s = 0; s < n; ++s) {
    const Aabb box = h.slot_box[s];
    gpu::lbvh_query(h.nodes.data(), h.node_box.data(), s, box, [&](std::uint32_t t) {
      ++h.tests;
      if (overlaps(box, h.slot_box[t]))
        h.pairs.push_back({std::min(h.slot_body[s], h.slot_body[t]), std::max(h.slot_body[s], h.slot_body[t])});
    });
  }
  std::sort(h.pairs.begin(), h.pairs.end());
}

std::string refit_and_check(HostLbvh& h);

/// Builds the tree over `boxes` in `domain` (codes, sort, Karras nodes, the refit with
/// arrival counters as the device does), checks it (every slot one leaf, every internal
/// node but the root one parent, each node's range contiguous and its `last` right, each
/// box the union of its children's, every node refitted, depth within the query stack),
/// then queries it.
HostLbvh host_lbvh(const std::vector<Aabb>& boxes, const Aabb& domain) {
  HostLbvh h;
  const auto n = static_cast<std::uint32_t>(boxes.size());
  const LooseGrid grid = loose_grid(domain);
  std::vector<std::pair<std::uint32_t, std::uint32_t>> order(n);
  for (std::uint32_t i = 0; i < n; ++i) order[i] = {gpu::lbvh_code(grid, boxes[i]), i};
  std::sort(order.begin(), order.end());
  for (const auto& [c, b] : order) {
    if (c >= (1u << gpu::kLbvhCodeBits)) h.broken = fmt::format("code {} of body {} has more than 30 bits", c, b);
    h.code.push_back(c);
    h.slot_body.push_back(b);
    h.slot_box.push_back(boxes[b]);
  }
  if (n < 2) return h;
  h.nodes.resize(n - 1);
  for (std::uint32_t i = 0; i + 1 < n; ++i) h.nodes[i] = gpu::lbvh_internal(h.code.data(), n, i);
  if (h.broken.empty()) h.broken = refit_and_check(h);
  if (h.broken.empty()) host_lbvh_query(h);
  return h;
}

/// The refit and the checks of host_lbvh on the nodes of `h` (n >= 2 slots): "" when the
/// tree checks out, else the first thing wrong. Writes h.node_box and h.depth.
std::string refit_and_check(HostLbvh& h) {
  std::string broken;
  const auto n = static_cast<std::uint32_t>(h.slot_box.size());
  const std::uint32_t inner = n - 1;
  // Parents.
  std::vector<std::uint32_t> leaf_parent(n, gpu::kLbvhNone), node_parent(inner, gpu::kLbvhNone);
  std::vector<int> leaf_refs(n, 0), node_refs(inner, 0);
  auto fail = [&](std::string what) {
    if (broken.empty()) broken = std::move(what);
  };
  for (std::uint32_t i = 0; i < inner; ++i)
    for (const std::uint32_t ref : {h.nodes[i].left, h.nodes[i].right}) {
      const std::uint32_t k = ref & ~gpu::kLbvhLeaf;
      if ((ref & gpu::kLbvhLeaf) ? k >= n : k >= inner) {
        fail(fmt::format("node {}: child reference 0x{:08x} out of range", i, ref));
        continue;
      }
      if (ref & gpu::kLbvhLeaf) {
        ++leaf_refs[k];
        leaf_parent[k] = i;
      } else {
        ++node_refs[k];
        node_parent[k] = i;
      }
    }
  for (std::uint32_t s = 0; s < n; ++s)
    if (leaf_refs[s] != 1) fail(fmt::format("slot {} is the leaf of {} nodes", s, leaf_refs[s]));
  for (std::uint32_t i = 0; i < inner; ++i)
    if (node_refs[i] != (i == 0 ? 0 : 1)) fail(fmt::format("internal node {} has {} parents", i, node_refs[i]));
  if (!broken.empty()) return broken;
  // Refit as lbvh_refit_kernel: per leaf, climb; the second arrival at a node writes its box.
  h.node_box.assign(inner, Aabb{});
  std::vector<int> arrivals(inner, 0);
  auto box_of = [&](std::uint32_t ref) {
    return (ref & gpu::kLbvhLeaf) ? h.slot_box[ref & ~gpu::kLbvhLeaf] : h.node_box[ref];
  };
  for (std::uint32_t s = 0; s < n; ++s) {
    std::uint32_t p = leaf_parent[s];
    for (std::uint32_t steps = 0; p != gpu::kLbvhNone && steps < n; ++steps) {
      if (arrivals[p]++ == 0) break;
      h.node_box[p] = gpu::lbvh_union(box_of(h.nodes[p].left), box_of(h.nodes[p].right));
      p = node_parent[p];
    }
  }
  for (std::uint32_t i = 0; i < inner; ++i)
    if (arrivals[i] != 2) fail(fmt::format("internal node {}: {} arrivals in the refit, not 2", i, arrivals[i]));
  // Ranges, `last`, unions and depth, depth first from the root.
  struct Visit {
    std::uint32_t node;
    int depth;
  };
  std::vector<Visit> stack{{0u, 1}};
  std::vector<std::uint32_t> lo(inner), hi(inner), leaves(inner);
  std::vector<std::uint32_t> post;  // nodes in visit order; ranges are filled children first below
  while (!stack.empty() && post.size() <= inner) {
    const Visit v = stack.back();
    stack.pop_back();
    post.push_back(v.node);
    h.depth = std::max(h.depth, v.depth);
    for (const std::uint32_t ref : {h.nodes[v.node].left, h.nodes[v.node].right})
      if (!(ref & gpu::kLbvhLeaf)) stack.push_back({ref, v.depth + 1});
  }
  if (post.size() != inner) fail(fmt::format("{} internal nodes reached from the root, not {}", post.size(), inner));
  for (auto it = post.rbegin(); it != post.rend() && broken.empty(); ++it) {
    const std::uint32_t i = *it;
    std::uint32_t l = ~0u, u = 0, count = 0;
    for (const std::uint32_t ref : {h.nodes[i].left, h.nodes[i].right}) {
      const std::uint32_t k = ref & ~gpu::kLbvhLeaf;
      const bool leaf = (ref & gpu::kLbvhLeaf) != 0;
      l = std::min(l, leaf ? k : lo[k]);
      u = std::max(u, leaf ? k : hi[k]);
      count += leaf ? 1u : leaves[k];
    }
    lo[i] = l;
    hi[i] = u;
    leaves[i] = count;
    if (u - l + 1 != count) fail(fmt::format("node {}: slots [{}, {}] hold {} leaves: not contiguous", i, l, u, count));
    if (h.nodes[i].last != u) fail(fmt::format("node {}: last {} but its last slot is {}", i, h.nodes[i].last, u));
    const Aabb want = gpu::lbvh_union(box_of(h.nodes[i].left), box_of(h.nodes[i].right));
    if (std::memcmp(&want, &h.node_box[i], sizeof(Aabb)) != 0) fail(fmt::format("node {}: box is not the union", i));
  }
  if (broken.empty() && (lo[0] != 0 || hi[0] != n - 1)) fail("the root does not cover every slot");
  if (h.depth > gpu::kLbvhStack - 2) fail(fmt::format("depth {} exceeds the query stack", h.depth));
  return broken;
}

// ---- the broadphases under test ------------------------------------------------------

struct Variant {
  std::string label;
  BroadPhaseConfig config;
  gpu::LooseOctreeQuery octree_query = gpu::LooseOctreeQuery::Auto;  ///< `octree`'s query kernel
};

/// gtest prints a parameter by its label.
void PrintTo(const Variant& v, std::ostream* os) { *os << v.label; }

std::vector<Variant> variants() {
  std::vector<Variant> v;
  for (int depth = -1; depth <= 10; ++depth) {
    BroadPhaseConfig c;
    c.name = "octree-strict";
    c.octree_depth = depth;
    v.push_back({depth < 0 ? std::string("strict_auto") : fmt::format("strict_depth_{}", depth), c});
  }
  const std::vector<std::pair<const char*, float>> sizes = {
      {"1e_6", 1e-6f}, {"0_002", 0.002f}, {"0_02", 0.02f}, {"0_05", 0.05f},
      {"0_25", 0.25f}, {"1", 1.0f},       {"1000", 1000.0f}};
  for (const auto& [label, h] : sizes) {
    BroadPhaseConfig c;
    c.name = "spatial-hash";
    c.cell_size = h;
    v.push_back({std::string("hash_h_") + label, c});
  }
#if defined(OCTOCD_HAVE_DEVICE_LOOSE_OCTREE)
  for (int depth : {-1, 0, 2, 10}) {
    BroadPhaseConfig c;
    c.name = "octree";
    c.octree_depth = depth;
    v.push_back({depth < 0 ? std::string("loose_auto") : fmt::format("loose_depth_{}", depth), c});
    // The box sets are small: the thread-per-slot query of large scenes, forced.
    v.push_back({depth < 0 ? std::string("loose_thread_auto") : fmt::format("loose_thread_depth_{}", depth), c,
                 gpu::LooseOctreeQuery::Thread});
  }
#endif
  BroadPhaseConfig lbvh;
  lbvh.name = "lbvh";
  v.push_back({"lbvh", lbvh});
  // Every other device broadphase of the registry (device `seam`), with its default parameters.
  for (const BroadPhaseInfo& info : broadphase_infos()) {
    if (info.device != BroadPhaseDevice::seam) continue;
    if (std::any_of(v.begin(), v.end(), [&](const Variant& x) { return x.config.name == info.name; })) continue;
    BroadPhaseConfig c;
    c.name = info.name;
    std::string label = info.name;
    std::replace(label.begin(), label.end(), '-', '_');
    v.push_back({label, c});
  }
  return v;
}

/// The device broadphase of `c` (one-shot); `octree` with the query kernel `query`.
std::unique_ptr<DeviceBroadPhase> make_device(const BroadPhaseConfig& c, const Aabb& domain,
                                              gpu::LooseOctreeQuery query = gpu::LooseOctreeQuery::Auto) {
#if defined(OCTOCD_HAVE_DEVICE_LOOSE_OCTREE)
  if (c.name == "octree") return gpu::make_device_loose_octree(c, domain, query);
#endif
  (void)query;
  return gpu::make_device_broadphase(c, domain);  // the registry's device factory, one-shot
}

/// make_device with the variant's octree query.
std::unique_ptr<DeviceBroadPhase> make_device(const Variant& v, const Aabb& domain) {
  return make_device(v.config, domain, v.octree_query);
}

// ---- running a device broadphase -----------------------------------------------------

/// A stream owned by a test.
struct Stream {
  cudaStream_t s = nullptr;
  Stream() { gpu::check(cudaStreamCreateWithFlags(&s, cudaStreamNonBlocking), "cudaStreamCreate"); }
  ~Stream() {
    if (s) (void)cudaStreamDestroy(s);
  }
};

template <class T>
T read_one(const T* device_ptr, cudaStream_t s) {
  T v{};
  gpu::check(cudaMemcpyAsync(&v, device_ptr, sizeof(T), cudaMemcpyDeviceToHost, s), "cudaMemcpy");
  gpu::check(cudaStreamSynchronize(s), "cudaStreamSynchronize");
  return v;
}

constexpr unsigned long long kSentinel = ~0ull;

/// What one find() wrote.
struct FindResult {
  std::uint32_t total = 0;
  unsigned long long candidates = 0;
  std::vector<unsigned long long> keys;  ///< the first min(total, capacity) keys, as written
  bool wrote_past_capacity = false;      ///< the slot after `capacity` was overwritten
  int shift = 32;                        ///< the PairOutput::shift the keys were written with
};

/// Output buffers of one find(): capacity + 1 key slots filled with the sentinel (the
/// last one must survive), the total (pre-set to a value find must overwrite) and the
/// candidate counter (0).
struct Output {
  DeviceBuffer<unsigned long long> keys{"test pair keys"};
  DeviceBuffer<std::uint32_t> total{"test pair total"};
  DeviceBuffer<unsigned long long> candidates{"test candidates"};
  std::uint32_t capacity = 0;
  int shift = 32;  // PairOutput::shift

  Output(std::uint32_t cap, cudaStream_t s, int key_shift = 32) : capacity(cap), shift(key_shift) {
    keys.reset(static_cast<std::size_t>(cap) + 1);
    total.reset(1);
    candidates.reset(1);
    clear(s);
  }
  void clear(cudaStream_t s) {
    gpu::check(cudaMemsetAsync(keys.get(), 0xff, (static_cast<std::size_t>(capacity) + 1) * 8, s), "cudaMemset");
    gpu::check(cudaMemsetAsync(total.get(), 0xab, 4, s), "cudaMemset");
    gpu::check(cudaMemsetAsync(candidates.get(), 0, 8, s), "cudaMemset");
  }
  gpu::PairOutput pair_output() const {
    gpu::PairOutput o;
    o.keys = keys.get();
    o.capacity = capacity;
    o.total = total.get();
    o.candidates = candidates.get();
    o.shift = shift;
    return o;
  }
  FindResult read(cudaStream_t s) const {
    gpu::check(cudaStreamSynchronize(s), "cudaStreamSynchronize (after find)");
    FindResult r;
    r.shift = shift;
    r.total = read_one(total.get(), s);
    r.candidates = read_one(candidates.get(), s);
    std::vector<unsigned long long> all;
    gpu::download(all, keys, static_cast<std::size_t>(capacity) + 1, s);
    r.wrote_past_capacity = all[capacity] != kSentinel;
    all.resize(std::min<std::size_t>(r.total, capacity));
    r.keys = std::move(all);
    return r;
  }
};

FindResult find_once(DeviceBroadPhase& bp, const DeviceBuffer<Aabb>& boxes, std::uint32_t n, std::uint32_t capacity,
                     cudaStream_t s, int shift = 32) {
  Output out(capacity, s, shift);
  bp.find(boxes.get(), n, out.pair_output(), s);
  return out.read(s);
}

/// find() as the engine uses it: a small output first, regrown to the total and rerun
/// when it overflows.
FindResult find_all(DeviceBroadPhase& bp, const DeviceBuffer<Aabb>& boxes, std::uint32_t n, cudaStream_t s) {
  FindResult r = find_once(bp, boxes, n, 16, s, gpu::key_bits(n));
  if (r.total > 16) r = find_once(bp, boxes, n, r.total, s, gpu::key_bits(n));
  return r;
}

/// The keys as pairs, checked (a < b < n, no duplicate) and sorted.
::testing::AssertionResult to_pairs(const std::vector<unsigned long long>& keys, std::size_t n,
                                    std::vector<Pair>& pairs, int shift) {
  pairs.clear();
  for (const unsigned long long k : keys) {
    const Pair p{static_cast<std::uint32_t>(k >> shift), static_cast<std::uint32_t>(k & ((1ull << shift) - 1ull))};
    if ((k >> shift) >> 32 != 0)
      return ::testing::AssertionFailure() << fmt::format("bad key 0x{:016x}: a above 32 bits (shift {})", k, shift);
    if (!(p.a < p.b && p.b < n))
      return ::testing::AssertionFailure() << fmt::format("bad key 0x{:016x}: pair ({}, {}) with n = {}", k, p.a, p.b, n);
    pairs.push_back(p);
  }
  std::sort(pairs.begin(), pairs.end());
  const auto dup = std::adjacent_find(pairs.begin(), pairs.end());
  if (dup != pairs.end())
    return ::testing::AssertionFailure() << fmt::format("pair ({}, {}) reported twice", dup->a, dup->b);
  return ::testing::AssertionSuccess();
}

std::string describe(const Aabb& b) {
  return fmt::format("[({}, {}, {}), ({}, {}, {})]", b.min.x, b.min.y, b.min.z, b.max.x, b.max.y, b.max.z);
}

/// Equal sorted pair sets, or the first missing and the first extra pair with their boxes.
::testing::AssertionResult same_pairs(const std::vector<Pair>& device, const std::vector<Pair>& flat,
                                      const std::vector<Aabb>& boxes) {
  if (device == flat) return ::testing::AssertionSuccess();
  std::vector<Pair> missing, extra;
  std::set_difference(flat.begin(), flat.end(), device.begin(), device.end(), std::back_inserter(missing));
  std::set_difference(device.begin(), device.end(), flat.begin(), flat.end(), std::back_inserter(extra));
  auto msg = ::testing::AssertionFailure();
  msg << fmt::format("device {} pairs, flat {}: {} missing, {} extra", device.size(), flat.size(), missing.size(),
                     extra.size());
  if (!missing.empty())
    msg << fmt::format("; first missing ({}, {}): {} {}", missing[0].a, missing[0].b, describe(boxes[missing[0].a]),
                       describe(boxes[missing[0].b]));
  if (!extra.empty())
    msg << fmt::format("; first extra ({}, {}): {} {}", extra[0].a, extra[0].b, describe(boxes[extra[0].a]),
                       describe(boxes[extra[0].b]));
  return msg;
}

std::uint64_t cpu_candidates(const BroadPhaseConfig& c, const BoxSet& set) {
  std::vector<Pair> out;
  BroadPhaseStats stats;
  make_broadphase(c, set.domain)->find_pairs(set.boxes, out, stats);
  return stats.cell_candidates;
}

class DeviceBroadPhaseTest : public ::testing::TestWithParam<Variant> {};

std::string variant_name(const ::testing::TestParamInfo<Variant>& info) { return info.param.label; }

// ---- tests -----------------------------------------------------------------------------

TEST_P(DeviceBroadPhaseTest, PairSetEqualsFlatOnEveryBoxSet) {
  REQUIRE_CUDA_DEVICE();
  const Variant& v = GetParam();
  Stream stream;
  for (const std::string& name : box_set_names()) {
    SCOPED_TRACE(name);
    const BoxSet& set = box_set(name);
    const auto n = static_cast<std::uint32_t>(set.boxes.size());
    auto bp = make_device(v, set.domain);
    EXPECT_EQ(bp->name(), v.config.name);
    DeviceBuffer<Aabb> boxes("test boxes");
    gpu::upload(boxes, set.boxes, stream.s);
    bp->reserve(n, stream.s);
    const FindResult r = find_all(*bp, boxes, n, stream.s);
    ASSERT_EQ(r.total, set.flat.size());
    EXPECT_FALSE(r.wrote_past_capacity);
    std::vector<Pair> pairs;
    ASSERT_TRUE(to_pairs(r.keys, n, pairs, r.shift));
    EXPECT_TRUE(same_pairs(pairs, set.flat, set.boxes));
    if (v.config.name == "octree-strict") {
      // Same node math: the related pairs the device tests are the CPU's cell candidates.
      EXPECT_EQ(r.candidates, cpu_candidates(v.config, set));
    } else if (v.config.name == "lbvh") {
      // Same tree, same boxes, same query: the leaf tests of the host model.
      EXPECT_EQ(r.candidates, host_lbvh(set.boxes, set.domain).tests);
      EXPECT_GE(r.candidates, static_cast<unsigned long long>(r.total));
    } else {
      EXPECT_GE(r.candidates, static_cast<unsigned long long>(r.total));
    }
    // Determinism: the same instance again gives the same set (the order of the keys may
    // vary run to run: the loose octree appends with atomics; the caller sorts them),
    // here with the default key shift 32 instead of the engine's.
    const FindResult again = find_once(*bp, boxes, n, std::max<std::uint32_t>(r.total, 1), stream.s, 32);
    EXPECT_EQ(again.total, r.total);
    EXPECT_EQ(again.candidates, r.candidates);
    std::vector<Pair> pairs_again;
    ASSERT_TRUE(to_pairs(again.keys, n, pairs_again, again.shift));
    EXPECT_TRUE(pairs_again == pairs) << "the pair set changed between two runs (shift 32 vs " << r.shift << ")";
    EXPECT_GT(bp->device_bytes(), 0u);
  }
}

TEST_P(DeviceBroadPhaseTest, CapacityOverflowGivesTheTotalAndRerunGivesTheSet) {
  REQUIRE_CUDA_DEVICE();
  const Variant& v = GetParam();
  const BoxSet& set = box_set("uniform-1000");
  ASSERT_GT(set.flat.size(), 10u);
  Stream stream;
  const auto n = static_cast<std::uint32_t>(set.boxes.size());
  auto bp = make_device(v, set.domain);
  DeviceBuffer<Aabb> boxes("test boxes");
  gpu::upload(boxes, set.boxes, stream.s);
  bp->reserve(n, stream.s);

  const FindResult none = find_once(*bp, boxes, n, 0, stream.s);
  EXPECT_EQ(none.total, set.flat.size());
  EXPECT_FALSE(none.wrote_past_capacity) << "capacity 0: a key was written";

  const FindResult one = find_once(*bp, boxes, n, 1, stream.s, gpu::key_bits(n));
  EXPECT_EQ(one.total, set.flat.size());
  EXPECT_FALSE(one.wrote_past_capacity) << "capacity 1: a key was written past it";
  ASSERT_EQ(one.keys.size(), 1u);
  std::vector<Pair> first;
  ASSERT_TRUE(to_pairs(one.keys, n, first, one.shift));
  EXPECT_TRUE(std::binary_search(set.flat.begin(), set.flat.end(), first[0]));
  EXPECT_EQ(one.candidates, none.candidates);

  const FindResult all = find_once(*bp, boxes, n, one.total, stream.s, gpu::key_bits(n));
  EXPECT_EQ(all.total, one.total);
  EXPECT_FALSE(all.wrote_past_capacity);
  std::vector<Pair> pairs;
  ASSERT_TRUE(to_pairs(all.keys, n, pairs, all.shift));
  EXPECT_TRUE(same_pairs(pairs, set.flat, set.boxes));
}

TEST_P(DeviceBroadPhaseTest, FindIsCapturedInAGraphAndReplaysOnNewBoxes) {
  REQUIRE_CUDA_DEVICE();
  const Variant& v = GetParam();
  // Two sets of the same size: the graph captured on the first runs on the second.
  const BoxSet& a = box_set("uniform-1000");
  std::vector<Aabb> moved = random_boxes(a.boxes.size(), 99, cube(-0.5f, 0.5f), 0.01f, 0.1f);
  const std::vector<Pair> moved_flat = flat_pairs(moved, a.domain);
  const auto n = static_cast<std::uint32_t>(a.boxes.size());
  const auto capacity = static_cast<std::uint32_t>(std::max(a.flat.size(), moved_flat.size()));

  Stream stream;
  auto bp = make_device(v, a.domain);
  DeviceBuffer<Aabb> boxes("test boxes");
  gpu::upload(boxes, a.boxes, stream.s);
  bp->reserve(n, stream.s);
  Output out(capacity, stream.s, gpu::key_bits(n));
  gpu::check(cudaStreamSynchronize(stream.s), "cudaStreamSynchronize");

  cudaGraph_t graph = nullptr;
  gpu::check(cudaStreamBeginCapture(stream.s, cudaStreamCaptureModeThreadLocal), "cudaStreamBeginCapture");
  try {
    bp->find(boxes.get(), n, out.pair_output(), stream.s);
  } catch (...) {
    (void)cudaStreamEndCapture(stream.s, &graph);
    if (graph) (void)cudaGraphDestroy(graph);
    throw;
  }
  const cudaError_t captured = cudaStreamEndCapture(stream.s, &graph);
  ASSERT_EQ(captured, cudaSuccess) << "find() is not capturable (a synchronisation or an allocation?): "
                                   << gpu::cuda_text(captured);
  cudaGraphExec_t exec = nullptr;
  gpu::check(cudaGraphInstantiate(&exec, graph, 0), "cudaGraphInstantiate");

  for (int round = 0; round < 2; ++round) {
    SCOPED_TRACE(round == 0 ? "captured boxes" : "new boxes, same graph");
    const std::vector<Aabb>& host = round == 0 ? a.boxes : moved;
    const std::vector<Pair>& flat = round == 0 ? a.flat : moved_flat;
    ASSERT_EQ(boxes.capacity(), host.size());
    gpu::upload(boxes, host, stream.s, /*allocate=*/false);  // into the captured buffer
    out.clear(stream.s);
    gpu::check(cudaGraphLaunch(exec, stream.s), "cudaGraphLaunch");
    const FindResult r = out.read(stream.s);
    EXPECT_EQ(r.total, flat.size());
    std::vector<Pair> pairs;
    ASSERT_TRUE(to_pairs(r.keys, n, pairs, r.shift));
    EXPECT_TRUE(same_pairs(pairs, flat, host));
  }
  (void)cudaGraphExecDestroy(exec);
  (void)cudaGraphDestroy(graph);
}

// With PairOutput::scratch: a broadphase whose sorts_pairs() is true (`octree`) writes
// exactly flat's keys in flat's order (every segment length: one thread's, one block's radix
// sort, one block's ranks), leaves the entries after the total alone, and on overflow
// reports the total and writes nothing past the capacity (keys or scratch); the others
// ignore the scratch (the set, in any order).
TEST_P(DeviceBroadPhaseTest, WithScratchSortsWhenItSaysSo) {
  REQUIRE_CUDA_DEVICE();
  const Variant& v = GetParam();
  Stream stream;
  for (const std::string& name : box_set_names()) {
    SCOPED_TRACE(name);
    const BoxSet& set = box_set(name);
    const auto n = static_cast<std::uint32_t>(set.boxes.size());
    auto bp = make_device(v, set.domain);
    EXPECT_EQ(bp->sorts_pairs(), v.config.name == "octree");
    DeviceBuffer<Aabb> boxes("test boxes");
    gpu::upload(boxes, set.boxes, stream.s);
    bp->reserve(n, stream.s);
    const int shift = gpu::key_bits(std::max<std::uint32_t>(n, 1));
    std::vector<unsigned long long> want;
    for (const Pair p : set.flat) want.push_back((static_cast<unsigned long long>(p.a) << shift) | p.b);
    const auto total = static_cast<std::uint32_t>(want.size());
    for (const std::uint32_t cap : {total + 5, total / 2}) {
      SCOPED_TRACE(fmt::format("capacity {} for {} pairs", cap, total));
      Output out(cap, stream.s, shift);
      DeviceBuffer<unsigned long long> scratch("test scratch");
      scratch.reset(static_cast<std::size_t>(cap) + 1);
      gpu::check(cudaMemsetAsync(scratch.get(), 0xff, (static_cast<std::size_t>(cap) + 1) * 8, stream.s), "cudaMemset");
      gpu::PairOutput po = out.pair_output();
      po.scratch = scratch.get();
      bp->find(boxes.get(), n, po, stream.s);
      const FindResult r = out.read(stream.s);
      std::vector<unsigned long long> scratch_host;
      gpu::download(scratch_host, scratch, static_cast<std::size_t>(cap) + 1, stream.s);
      ASSERT_EQ(r.total, total);
      EXPECT_FALSE(r.wrote_past_capacity);
      EXPECT_EQ(scratch_host[cap], kSentinel) << "the scratch was written past the capacity";
      if (cap < total) {
        // Overflow: the caller grows the output and runs find() again, but reads the
        // capacity's keys first (the engine's midphase decodes keys [0, min(total,
        // capacity)) as pairs, the step is discarded after): each must be a pair of the
        // set, once, never the padding. (With the sorted mode's segments an overflowed
        // find() left padding among them: an illegal address in the engine's mid_start.)
        std::vector<unsigned long long> head;
        gpu::download(head, out.keys, cap, stream.s);
        std::vector<unsigned long long> sorted_want = want;
        std::sort(sorted_want.begin(), sorted_want.end());
        std::sort(head.begin(), head.end());
        EXPECT_TRUE(std::adjacent_find(head.begin(), head.end()) == head.end()) << "a key twice";
        for (const unsigned long long k : head)
          EXPECT_TRUE(std::binary_search(sorted_want.begin(), sorted_want.end(), k))
              << fmt::format("key 0x{:x} below the capacity is not a pair of the set", k);
        continue;
      }
      std::vector<unsigned long long> all;
      gpu::download(all, out.keys, static_cast<std::size_t>(cap) + 1, stream.s);
      EXPECT_TRUE(std::all_of(all.begin() + total, all.end(), [](unsigned long long k) { return k == kSentinel; }))
          << "an entry after the total was written";
      if (bp->sorts_pairs()) {
        ASSERT_EQ(r.keys.size(), want.size());
        std::size_t first = 0;
        while (first < want.size() && r.keys[first] == want[first]) ++first;
        EXPECT_EQ(first, want.size()) << fmt::format("first difference at {} of {}: 0x{:x} for 0x{:x}", first,
                                                     want.size(), first < want.size() ? r.keys[first] : 0ull,
                                                     first < want.size() ? want[first] : 0ull);
      } else {
        std::vector<Pair> pairs;
        ASSERT_TRUE(to_pairs(r.keys, n, pairs, shift));
        EXPECT_TRUE(same_pairs(pairs, set.flat, set.boxes));
      }
    }
  }
}

INSTANTIATE_TEST_SUITE_P(Device, DeviceBroadPhaseTest, ::testing::ValuesIn(variants()), variant_name);

// ---- needs no device -----------------------------------------------------------------

bool has_nan(const Aabb& b) {
  for (int a = 0; a < 3; ++a)
    if (std::isnan(b.min[a]) || std::isnan(b.max[a])) return true;
  return false;
}

TEST(DeviceBroadPhaseSets, EverySetHoldsWhatItsNameSays) {  // the fixtures, on the CPU
  for (const std::string& name : box_set_names()) {
    SCOPED_TRACE(name);
    const BoxSet& s = box_set(name);
    auto any = [&](auto pred) { return std::any_of(s.boxes.begin(), s.boxes.end(), pred); };
    auto any_pair = [&](auto pred) { return std::any_of(s.flat.begin(), s.flat.end(), pred); };
    if (name == "empty") {
      EXPECT_TRUE(s.boxes.empty());
    } else if (name == "single") {
      EXPECT_EQ(s.boxes.size(), 1u);
    } else {
      EXPECT_FALSE(s.flat.empty());
    }
    if (name == "touching-lattice") {  // some pairs only touch (zero-width overlap)
      EXPECT_TRUE(any_pair([&](Pair p) {
        const Aabb& a = s.boxes[p.a];
        const Aabb& b = s.boxes[p.b];
        return a.max.x == b.min.x || a.max.y == b.min.y || a.max.z == b.min.z;
      }));
    }
    if (name == "outside-domain") {
      EXPECT_TRUE(any([&](const Aabb& b) { return !contains(s.domain, b); }));
    }
    if (name == "huge-and-infinite") {
      EXPECT_TRUE(any([](const Aabb& b) { return std::isinf(b.min.x); }));
    }
    if (name == "nan") {
      EXPECT_TRUE(any([](const Aabb& b) { return has_nan(b); }));
      EXPECT_FALSE(any_pair([&](Pair p) { return has_nan(s.boxes[p.a]) || has_nan(s.boxes[p.b]); }));
    }
    if (name == "degenerate") {
      EXPECT_TRUE(any([](const Aabb& b) { return b.min == b.max; }));
    }
    if (name == "one-cell") {
      EXPECT_TRUE(std::all_of(s.boxes.begin(), s.boxes.end(),
                              [](const Aabb& b) { return contains(cube(0.29f, 0.32f), b); }));
    }
    if (name == "nested-levels") {  // bodies on every level 0 .. 7 (depth 10)
      const LooseGrid g = loose_grid(s.domain);
      std::set<int> levels;
      for (const Aabb& b : s.boxes) levels.insert(loose_place(g, b, kLooseMaxDepth).level);
      EXPECT_EQ(levels, (std::set<int>{0, 1, 2, 3, 4, 5, 6, 7}));
    }
    if (name == "long-segments") {  // segments (pairs (a, b) of one a) of every length class
      std::map<std::uint32_t, std::size_t> seg;
      for (const Pair p : s.flat) ++seg[p.a];
      EXPECT_EQ(seg[0], s.boxes.size() - 1);
      EXPECT_GT(seg[0], 2u * 4096u);  // three chunks
      EXPECT_GT(seg[1], 64u);
      EXPECT_LE(seg[1], 4096u);
      EXPECT_TRUE(std::any_of(seg.begin(), seg.end(), [](const auto& e) { return e.second >= 2 && e.second <= 64; }));
    }
    if (name == "boxes-random-10000-frame-100") {
      EXPECT_GE(s.boxes.size(), 10000u);
    }
    if (name == "thrown-out") {  // centres outside the domain, near it and far (strays), overlapping the pile
      const auto outside = std::count_if(s.boxes.begin(), s.boxes.end(), [&](const Aabb& b) {
        const Vec3 c = center(b);
        return !contains(s.domain, Aabb{c, c});
      });
      const auto far = std::count_if(s.boxes.begin(), s.boxes.end(), [](const Aabb& b) { return b.min.y > 10.0f; });
      EXPECT_GT(outside, 500);
      EXPECT_GT(far, 100);
      EXPECT_LT(far, outside);
    }
  }
}

TEST(DeviceBroadPhaseErrors, ParametersAreCheckedAsOnTheCpu) {
  BroadPhaseConfig c;
  c.name = "octree-strict";
  for (int depth : {-2, 11, 100}) {
    c.octree_depth = depth;
    try {
      (void)gpu::make_device_strict_octree(c, cube(-1.0f, 1.0f));
      ADD_FAILURE() << "depth " << depth << " accepted";
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find("broadphase.depth"), std::string::npos) << e.what();
    }
  }
  c.name = "spatial-hash";
  c.octree_depth = 2;
  for (float h : {0.0f, -1.0f, kNaN, kInf}) {
    c.cell_size = h;
    try {
      (void)gpu::make_device_spatial_hash(c);
      ADD_FAILURE() << "cell size " << h << " accepted";
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find("broadphase.cell_size"), std::string::npos) << e.what();
    }
  }
}

TEST(DeviceBroadPhaseErrors, FindWithoutReserveIsRefused) {
  BroadPhaseConfig c;
  c.name = "octree-strict";
  auto strict = gpu::make_device_strict_octree(c, cube(-1.0f, 1.0f));
  c.name = "spatial-hash";
  auto hash = gpu::make_device_spatial_hash(c);
  auto lbvh = gpu::make_device_lbvh(cube(-1.0f, 1.0f));
  for (DeviceBroadPhase* bp : {strict.get(), hash.get(), lbvh.get()}) {
    EXPECT_THROW(bp->find(nullptr, 5, gpu::PairOutput{}, nullptr), RuntimeError) << bp->name();
  }
}

// ---- `lbvh` on the host (needs no device) ----------------------------------------------

TEST(LbvhHostModel, TreeChecksOutAndPairSetEqualsFlatOnEveryBoxSet) {
  for (const std::string& name : box_set_names()) {
    SCOPED_TRACE(name);
    const BoxSet& set = box_set(name);
    const HostLbvh h = host_lbvh(set.boxes, set.domain);
    EXPECT_EQ(h.broken, "");
    EXPECT_TRUE(same_pairs(h.pairs, set.flat, set.boxes));
    EXPECT_GE(h.tests, h.pairs.size());
    if (set.boxes.size() >= 2) {
      EXPECT_LE(h.depth, gpu::kLbvhStack - 2);
    }
    // Fewer exact tests than `flat` once there are many boxes (the tree prunes).
    if (set.boxes.size() >= 1000 && name != "huge-and-infinite" && name != "one-cell") {
      EXPECT_LT(h.tests, static_cast<std::uint64_t>(set.boxes.size()) * (set.boxes.size() - 1) / 8) << name;
    }
  }
}

// Equal codes (Karras's tie-break on the slot), tiny sets and codes on every level-10
// cell border: n = 2 .. 70 identical boxes, the same with half of them moved far away, and
// random small sets.
TEST(LbvhHostModel, EqualCodesAndSmallSets) {
  const Aabb unit = cube(-1.0f, 1.0f);
  for (std::size_t n = 2; n <= 70; ++n) {
    SCOPED_TRACE(n);
    std::vector<Aabb> same(n, cube(0.1f, 0.2f));
    HostLbvh h = host_lbvh(same, unit);
    EXPECT_EQ(h.broken, "");
    EXPECT_EQ(h.pairs.size(), n * (n - 1) / 2);
    EXPECT_TRUE(same_pairs(h.pairs, flat_pairs(same, unit), same));
    for (std::size_t i = 0; i < n; i += 2) same[i] = cube(-0.9f, -0.85f);
    h = host_lbvh(same, unit);
    EXPECT_EQ(h.broken, "");
    EXPECT_TRUE(same_pairs(h.pairs, flat_pairs(same, unit), same));
    const std::vector<Aabb> rnd = random_boxes(n, static_cast<unsigned>(100 + n), unit, 0.01f, 0.4f);
    h = host_lbvh(rnd, unit);
    EXPECT_EQ(h.broken, "");
    EXPECT_TRUE(same_pairs(h.pairs, flat_pairs(rnd, unit), rnd));
  }
  // Every centre in one level-10 cell (cell 665 of [-1, 1] covers [0.29883, 0.30079] m):
  // a radix tree over the 13 bits of the slots alone, at most 13 internal nodes deep.
  const std::vector<Aabb> packed = random_boxes(5000, 17, cube(0.2992f, 0.3004f), 0.0f, 0.0001f);
  const HostLbvh h = host_lbvh(packed, unit);
  EXPECT_EQ(h.broken, "");
  EXPECT_TRUE(std::all_of(h.code.begin(), h.code.end(), [&](std::uint32_t c) { return c == h.code[0]; }));
  EXPECT_LE(h.depth, 13);
  EXPECT_TRUE(same_pairs(h.pairs, flat_pairs(packed, unit), packed));
}

// Planted faults: the checks above can fail. A root box that misses everything loses every
// pair; a child reference pointed at the wrong slot is a broken tree.
TEST(LbvhHostModel, PlantedFaultsAreCaught) {
  const BoxSet& set = box_set("uniform-1000");
  HostLbvh h = host_lbvh(set.boxes, set.domain);
  ASSERT_EQ(h.broken, "");
  ASSERT_TRUE(same_pairs(h.pairs, set.flat, set.boxes));
  HostLbvh shrunk = h;
  shrunk.node_box[0] = cube(5.0f, 6.0f);  // the root's box misses every body
  host_lbvh_query(shrunk);
  EXPECT_FALSE(same_pairs(shrunk.pairs, set.flat, set.boxes));
  // One node of two leaves moved away: a pair of its second leaf with a body of a smaller
  // slot is met only through that node's box, so it is lost.
  HostLbvh moved = h;
  std::vector<std::uint32_t> slot_of(moved.slot_body.size());
  for (std::uint32_t t = 0; t < moved.slot_body.size(); ++t) slot_of[moved.slot_body[t]] = t;
  std::uint32_t leaf_node = 0;
  for (std::uint32_t i = 1; i < moved.nodes.size() && leaf_node == 0; ++i) {
    const gpu::LbvhNode nd = moved.nodes[i];
    if (!(nd.left & gpu::kLbvhLeaf) || !(nd.right & gpu::kLbvhLeaf)) continue;
    const std::uint32_t a = nd.left & ~gpu::kLbvhLeaf;
    for (const Pair q : set.flat) {
      const std::uint32_t sa = slot_of[q.a], sb = slot_of[q.b];
      if ((sa == a + 1 && sb < a) || (sb == a + 1 && sa < a)) leaf_node = i;
    }
  }
  ASSERT_NE(leaf_node, 0u) << "no node of two leaves whose second leaf pairs with a smaller slot";
  moved.node_box[leaf_node] = cube(5.0f, 6.0f);
  host_lbvh_query(moved);
  EXPECT_FALSE(same_pairs(moved.pairs, set.flat, set.boxes));
  // Broken trees: the structure check names them.
  HostLbvh twice = h;  // a leaf referenced twice, another never
  twice.nodes[leaf_node].right = twice.nodes[leaf_node].left;
  EXPECT_NE(refit_and_check(twice), "");
  HostLbvh late = h;  // a wrong `last`: the query would skip a subtree it needs
  late.nodes[0].last -= 1;
  EXPECT_NE(refit_and_check(late), "");
  HostLbvh cut = h;  // a subtree hung under the root a second time
  cut.nodes[0].right = cut.nodes[0].left;
  EXPECT_NE(refit_and_check(cut), "");
}

// ---- `octree`'s block table on the host (needs no device) ------------------------------

/// A fault planted in the host model of the block table (to show its checks can fail).
enum class BlockFault {
  None,
  DropFirstSlot,  ///< find() answers a block's second slot: its first body is never tested
  Misplaced,      ///< entries stored one past their home: find() meets an empty entry
  NarrowWindow,   ///< the window loses its last cell along x when it has more than one
  DropOctant,     ///< the occupancy map misses the bit of every octant-0 cell
};

/// broadphase_octree_tree.cu on the host, slot after slot, with the functions of
/// loose_blocks.hpp: the keys of loose_keys_kernel (D_w fixed, or `auto` from the smallest
/// extent), the stable (key, body) sort, the block table of loose_gather_kernel (inserted
/// in slot order, as one of the device's insertion orders), the block query of
/// loose_query_kernel and the cell runs of loose_query_warp_kernel, checked slot by slot
/// against the per-cell query (every cell of the window looked up in the sorted keys);
/// then the overflow list (loose_overflow_kernel) and the exact tests.
struct HostLooseBlocks {
  std::vector<std::uint32_t> key;        ///< per slot, ascending
  std::vector<std::uint32_t> slot_body;  ///< per slot
  std::vector<unsigned long long> table;
  std::vector<std::uint32_t> occupancy;  ///< the occupancy map (words), blocks bytes
  std::uint32_t occupancy_blocks = 0;
  std::vector<Pair> pairs;               ///< sorted
  std::uint64_t tests = 0;               ///< exact tests of the block query + overflow
  std::uint64_t probes = 0;              ///< block probes (find calls)
  std::uint64_t cell_probes = 0;         ///< cells the per-cell query looks up
  std::string broken;                    ///< "" when every check holds, else the first failure
};

/// The host model's sort keys after the cells' (broadphase_octree_tree.cu's LooseDesc with
/// D_w = 10): the overflow list, the stray bodies by their level by size, NaN boxes.
constexpr std::uint32_t kHostOverflowKey = kLooseKeysEnd;
constexpr std::uint32_t kHostNanKey = kHostOverflowKey + kLooseMaxDepth + 2;
/// An stray body's key, its level by size `l` (loose_keys_kernel's stray_key).
constexpr std::uint32_t host_stray_key(int l) { return kHostOverflowKey + 1u + static_cast<std::uint32_t>(l); }

/// loose_keys_kernel's key of a box with no NaN coordinate: its cell's, the overflow
/// list's, or, when it climbed above its level by size (it left the root cube), an
/// stray key.
std::uint32_t host_loose_key(const Vec3& lo, const Vec3& hi, int depth) {
  const LoosePlace p = loose_place_unit(lo, hi, depth);
  const int by_size = loose_level_for_extent(loose_unit_extent(lo, hi), depth);
  if (by_size >= 0 && p.level < by_size) return host_stray_key(by_size);
  return p.level == kLooseOverflowLevel ? kHostOverflowKey : loose_place_key(p);
}

HostLooseBlocks host_loose_blocks(const std::vector<Aabb>& boxes, const Aabb& domain, int depth,
                                  BlockFault fault = BlockFault::None) {
  HostLooseBlocks h;
  auto fail = [&](std::string what) {
    if (h.broken.empty()) h.broken = std::move(what);
  };
  const auto n = static_cast<std::uint32_t>(boxes.size());
  const LooseGrid grid = loose_grid(domain);
  if (depth < 0) {  // `auto`: loose_extent_kernel + the CUB minimum
    float mn = kInf;
    for (const Aabb& b : boxes) {
      float e = loose_unit_extent(loose_unit(grid, b.min), loose_unit(grid, b.max));
      e = e < 0.0f ? 0.0f : e;
      mn = std::min(mn, e != e ? kInf : e);
    }
    depth = loose_auto_depth(mn);
  }
  std::vector<std::pair<std::uint32_t, std::uint32_t>> order(n);
  std::vector<std::array<std::int32_t, 6>> q(n);
  for (std::uint32_t i = 0; i < n; ++i) {
    const Aabb& b = boxes[i];
    std::uint32_t k = kHostNanKey;
    if (!loose_has_nan(b)) {
      const Vec3 lo = loose_unit(grid, b.min), hi = loose_unit(grid, b.max);
      k = host_loose_key(lo, hi, depth);
      q[i] = {loose_q_min(lo.x), loose_q_min(lo.y), loose_q_min(lo.z),
              loose_q_max(hi.x), loose_q_max(hi.y), loose_q_max(hi.z)};
    }
    order[i] = {k, i};
  }
  std::sort(order.begin(), order.end());  // = the stable sort by key of bodies 0 .. n-1
  for (const auto& [k, b] : order) {
    h.key.push_back(k);
    h.slot_body.push_back(b);
  }
  // The block table (loose_gather_kernel).
  const std::uint32_t mask = static_cast<std::uint32_t>(gpu::footprint::loose_cell_table_entries(n) - 1);
  h.table.assign(static_cast<std::size_t>(mask) + 1, gpu::kLooseBlockEmpty);
  std::uint32_t blocks = 0;
  for (std::uint32_t s = 0; s < n; ++s) {
    if (h.key[s] >= kHostOverflowKey) continue;
    const int level = loose_key_level(h.key[s]);
    const std::uint32_t bk = gpu::loose_block_key(h.key[s], level);
    if (h.key[s] - bk >= gpu::loose_block_span(level)) fail(fmt::format("slot {}: key {} outside its block {}", s, h.key[s], bk));
    if (!gpu::loose_block_first(h.key.data(), s, level)) continue;
    ++blocks;
    std::uint32_t e = gpu::loose_block_hash(bk, mask);
    if (fault == BlockFault::Misplaced) e = (e + 1) & mask;
    while (h.table[e] != gpu::kLooseBlockEmpty) e = (e + 1) & mask;
    h.table[e] = gpu::loose_block_entry(bk, s);
  }
  if (2ull * blocks > h.table.size()) fail(fmt::format("{} blocks in a table of {} entries", blocks, h.table.size()));
  // The occupancy map (loose_keys_kernel clears the words of levels <= D_w, then
  // loose_gather_kernel sets a bit per cell from the cell's first slot).
  h.occupancy_blocks = static_cast<std::uint32_t>(gpu::footprint::loose_occupancy_blocks(n));
  h.occupancy.assign(h.occupancy_blocks / 4, 0xdeadbeefu);  // not cleared: garbage
  const std::uint32_t words = gpu::loose_occupancy_words(h.occupancy_blocks, depth);
  if (words > h.occupancy.size()) fail(fmt::format("{} words to clear in a map of {}", words, h.occupancy.size()));
  std::fill(h.occupancy.begin(), h.occupancy.begin() + std::min<std::size_t>(words, h.occupancy.size()), 0u);
  for (std::uint32_t s = 0; s < n; ++s) {
    if (h.key[s] >= kHostOverflowKey || (s > 0 && h.key[s - 1] == h.key[s])) continue;
    const int level = loose_key_level(h.key[s]);
    std::uint32_t w = 0;
    const std::uint32_t bit = gpu::loose_occupancy_bit(h.key[s], level, h.occupancy_blocks, &w);
    if (bit == 0) continue;
    if (w >= words) fail(fmt::format("slot {}: key {} sets word {}, past the {} cleared", s, h.key[s], w, words));
    if (fault == BlockFault::DropOctant && h.key[s] == gpu::loose_block_key(h.key[s], level)) continue;
    h.occupancy[w] |= bit;
  }
  auto octants = [&](std::uint32_t bk) {
    return gpu::loose_block_octants(h.occupancy.data(), h.occupancy_blocks, bk);
  };
  auto find = [&](std::uint32_t bk) {
    ++h.probes;
    std::uint32_t t = gpu::loose_block_find(h.table.data(), mask, bk);
    if (fault == BlockFault::DropFirstSlot && t != gpu::kLooseNoSlot) ++t;
    return t;
  };
  auto emit = [&](std::uint32_t s, std::uint32_t t) {
    ++h.tests;
    if (overlaps(boxes[h.slot_body[s]], boxes[h.slot_body[t]]))
      h.pairs.push_back({std::min(h.slot_body[s], h.slot_body[t]), std::max(h.slot_body[s], h.slot_body[t])});
  };
  auto first_slot = [&](std::uint32_t key) {
    return static_cast<std::uint32_t>(std::lower_bound(h.key.begin(), h.key.end(), key) - h.key.begin());
  };
  const std::uint32_t stray_begin = first_slot(host_stray_key(0)), nan_begin = first_slot(kHostNanKey);
  // The query of a cell's body and of an stray body (no own cell: every slot of the
  // cells it meets at the levels up to its level by size), against the per-cell query.
  for (std::uint32_t s = 0; s < n; ++s) {
    const std::uint32_t key = h.key[s];
    if (key == kHostOverflowKey || key >= kHostNanKey) continue;
    const bool stray = key > kHostOverflowKey;
    const int level = stray ? static_cast<int>(key - kHostOverflowKey - 1u) : loose_key_level(key);
    const int own = stray ? -1 : level;
    const auto& qb = q[h.slot_body[s]];
    if (stray) {
      for (std::uint32_t t = s + 1; t < nan_begin; ++t) emit(s, t);  // the stray bodies after it
    } else {
      for (std::uint32_t t = stray_begin; t < first_slot(host_stray_key(level)); ++t) emit(s, t);  // stray above
    }
    for (int m = 0; m <= level; ++m) {
      LooseRange rx = loose_query_axis_q(qb[0], qb[3], m);
      const LooseRange ry = loose_query_axis_q(qb[1], qb[4], m);
      const LooseRange rz = loose_query_axis_q(qb[2], qb[5], m);
      std::vector<std::uint32_t> want;
      for (int iz = rz.lo; iz <= rz.hi; ++iz)
        for (int iy = ry.lo; iy <= ry.hi; ++iy)
          for (int ix = rx.lo; ix <= rx.hi; ++ix) {
            const std::uint32_t ck = loose_cell_key(m, static_cast<std::uint32_t>(ix), static_cast<std::uint32_t>(iy),
                                                    static_cast<std::uint32_t>(iz));
            const auto range = std::equal_range(h.key.begin(), h.key.end(), ck);
            auto t0 = static_cast<std::uint32_t>(range.first - h.key.begin());
            const auto t1 = static_cast<std::uint32_t>(range.second - h.key.begin());
            // The warp kernel's run of the cell, through its block.
            std::uint32_t r0 = 0, r1 = 0;
            gpu::loose_cell_run(h.key.data(), n, ck, m, find, octants, &r0, &r1);
            if ((t0 == t1) ? r0 != r1 : (r0 != t0 || r1 != t1))
              fail(fmt::format("slot {}: cell {} holds slots [{}, {}), its run through the block table is [{}, {})", s,
                               ck, t0, t1, r0, r1));
            if (m == own && ck < key) continue;
            ++h.cell_probes;
            if (m == own) t0 = std::max(t0, s + 1);
            for (std::uint32_t t = t0; t < t1; ++t) want.push_back(t);
          }
      if (fault == BlockFault::NarrowWindow && rx.hi > rx.lo) --rx.hi;
      std::vector<std::uint32_t> got;
      gpu::loose_block_query(h.key.data(), n, s, key, own, m, rx, ry, rz, find, octants,
                             [&](std::uint32_t t) { got.push_back(t); });
      std::sort(want.begin(), want.end());
      std::sort(got.begin(), got.end());
      if (got != want)
        fail(fmt::format("slot {} (key {}, level {}) at level {}: the block query visits {} slots, the cells hold {}",
                         s, key, level, m, got.size(), want.size()));
      for (const std::uint32_t t : got) emit(s, t);
    }
  }
  // The overflow list (loose_query_kernel's overflow slots: the overflow and stray
  // bodies after each; loose_overflow_kernel: every cell's body).
  const std::uint32_t ov_begin = first_slot(kHostOverflowKey);
  for (std::uint32_t o = ov_begin; o < stray_begin; ++o) {
    for (std::uint32_t t = o + 1; t < nan_begin; ++t) emit(o, t);
    for (std::uint32_t t = 0; t < ov_begin; ++t) emit(t, o);
  }
  std::sort(h.pairs.begin(), h.pairs.end());
  return h;
}

TEST(LooseBlockHostModel, BlockQueryVisitsThePerCellSlotsAndPairSetEqualsFlat) {
  for (const std::string& name : box_set_names()) {
    for (int depth : {-1, 0, 1, 2, 3, 10}) {
      SCOPED_TRACE(fmt::format("{} depth {}", name, depth));
      const BoxSet& set = box_set(name);
      const HostLooseBlocks h = host_loose_blocks(set.boxes, set.domain, depth);
      EXPECT_EQ(h.broken, "");
      EXPECT_TRUE(same_pairs(h.pairs, set.flat, set.boxes));
    }
  }
}

// Fewer probes: on the bench's distribution (cubes of half side 0.06 / 0.03 at
// boxes-random-10000's density) the block query probes at most half as often as the
// per-cell query looked cells up (the cell runs of the warp kernel's check excluded).
TEST(LooseBlockHostModel, FewerProbesThanCells) {
  const std::uint32_t n = 20000;
  const float side = 3.4f * std::cbrt(2.0f);
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> u(-side / 2, side / 2);
  std::vector<Aabb> boxes;
  for (std::uint32_t i = 0; i < n; ++i) {
    const float e = i % 2 == 0 ? 0.06f : 0.03f;
    boxes.push_back(box_at({u(rng), u(rng), u(rng)}, {e, e, e}));
  }
  const float h = side / 2 + 0.06f;
  const Aabb domain{{-h, -h, -h}, {h, h, h}};
  HostLooseBlocks m = host_loose_blocks(boxes, domain, -1);
  EXPECT_EQ(m.broken, "");
  EXPECT_TRUE(same_pairs(m.pairs, flat_pairs(boxes, domain), boxes));
  // host_loose_blocks counts the warp kernel's cell-run probes too: count the block query's
  // alone, without the occupancy map (every block's byte 0xff) and with it.
  std::uint64_t block_probes = 0, map_probes = 0, visits = 0, map_visits = 0;
  {
    const LooseGrid grid = loose_grid(domain);
    const std::uint32_t mask = static_cast<std::uint32_t>(m.table.size() - 1);
    for (const bool map : {false, true}) {
      std::uint64_t& probes = map ? map_probes : block_probes;
      std::uint64_t& visited = map ? map_visits : visits;
      for (std::uint32_t s = 0; s < n && m.key[s] < kHostOverflowKey; ++s) {
        const Aabb& b = boxes[m.slot_body[s]];
        const Vec3 lo = loose_unit(grid, b.min), hi = loose_unit(grid, b.max);
        const int level = loose_key_level(m.key[s]);
        for (int l = 0; l <= level; ++l)
          gpu::loose_block_query(
              m.key.data(), n, s, m.key[s], level, l, loose_query_axis_q(loose_q_min(lo.x), loose_q_max(hi.x), l),
              loose_query_axis_q(loose_q_min(lo.y), loose_q_max(hi.y), l),
              loose_query_axis_q(loose_q_min(lo.z), loose_q_max(hi.z), l),
              [&](std::uint32_t bk) {
                ++probes;
                return gpu::loose_block_find(m.table.data(), mask, bk);
              },
              [&](std::uint32_t bk) {
                return map ? gpu::loose_block_octants(m.occupancy.data(), m.occupancy_blocks, bk) : 0xffu;
              },
              [&](std::uint32_t) { ++visited; });
      }
    }
  }
  EXPECT_GT(m.cell_probes, 0u);
  // The map skips the blocks with no occupied cell in the window: the same slots, at most a
  // quarter of the probes (levels 0 .. 7 of this set are in the map).
  EXPECT_EQ(visits, map_visits);
  EXPECT_LE(4 * map_probes, block_probes) << map_probes << " probes with the map, " << block_probes << " without";
  RecordProperty("map_probes", std::to_string(map_probes));
  RecordProperty("blocks", std::to_string(std::count_if(m.table.begin(), m.table.end(), [](unsigned long long e) {
                   return e != gpu::kLooseBlockEmpty;
                 })));
  RecordProperty("block_probes", std::to_string(block_probes));
  RecordProperty("cell_probes", std::to_string(m.cell_probes));
  EXPECT_LE(2 * block_probes, m.cell_probes) << block_probes << " block probes, " << m.cell_probes << " cells";
}

// The loop-free level of a cell key (the kernels' loose_cell_key_level) against
// loose_key_level on every level's first and last keys, their neighbours and random keys.
TEST(LooseBlockHostModel, CellKeyLevelEqualsTheLoop) {
  // Level l's keys: [(8^l - 1) / 7, (8^(l+1) - 1) / 7) (64-bit: level 11's base is above 2^30).
  auto base = [](int l) { return static_cast<std::uint32_t>(((1ull << (3 * l)) - 1) / 7); };
  std::vector<std::uint32_t> keys;
  for (int l = 0; l <= kLooseMaxDepth; ++l) {
    ASSERT_EQ(base(l), loose_level_base(l));
    const std::uint32_t b = base(l), e = base(l + 1);
    for (std::uint32_t k : {b, b + 1, b + 7, b + 8, e - 2, e - 1})
      if (k >= b && k < e) keys.push_back(k);
  }
  std::mt19937 rng(5);
  std::uniform_int_distribution<std::uint32_t> u(0, base(kLooseMaxDepth + 1) - 1);
  for (int i = 0; i < 100000; ++i) keys.push_back(u(rng));
  for (const std::uint32_t k : keys) ASSERT_EQ(gpu::loose_cell_key_level(k), loose_key_level(k)) << "key " << k;
  // Planted fault: the formula with a 32-bit product wraps from key 613566757 (level 10)
  // on: 7 k + 1 = 2^32 + 4 reads as level 0.
  auto level32 = [](std::uint32_t k) {
    const std::uint32_t v = 7u * k + 1u;
    int l2 = 0;
    while (l2 < 31 && (v >> (l2 + 1)) != 0) ++l2;
    return l2 / 3;
  };
  EXPECT_EQ(level32(5u), loose_key_level(5u));
  EXPECT_EQ(loose_key_level(613566757u), 10);
  EXPECT_NE(level32(613566757u), loose_key_level(613566757u));
}

// Planted faults: the checks above can fail.
TEST(LooseBlockHostModel, PlantedFaultsAreCaught) {
  for (const char* name : {"uniform-1000", "touching-lattice", "nested-levels"}) {
    SCOPED_TRACE(name);
    const BoxSet& set = box_set(name);
    for (const BlockFault f :
         {BlockFault::DropFirstSlot, BlockFault::Misplaced, BlockFault::NarrowWindow, BlockFault::DropOctant}) {
      SCOPED_TRACE(static_cast<int>(f));
      const HostLooseBlocks h = host_loose_blocks(set.boxes, set.domain, -1, f);
      EXPECT_NE(h.broken, "");
      EXPECT_FALSE(same_pairs(h.pairs, set.flat, set.boxes));
    }
  }
}

// ---- exact tests per depth on the bench's distribution (issue 20 item 5) ----------------
//
// count_loose_tests counts the exact tests of loose_query_kernel + loose_overflow_kernel
// (what host_loose_blocks counts in `tests`) without visiting slots: a body at level L
// with key k tests every body of each cell of its window at levels m < L, of the cells
// with keys > k at level L, and the c(c - 1) / 2 pairs of each cell with c bodies once;
// the overflow bodies test each other and every tree body. The same header functions as
// the device (loose_place_key, loose_query_axis_q, loose_cell_key), O(n x windows) with a
// hash map of the cells, so the bench's 4x10^6 boxes count in seconds.
struct LooseTestCount {
  int depth = 0;                            ///< D_w used (auto resolved)
  std::uint64_t tests = 0;                  ///< exact tests
  std::array<std::uint32_t, kLooseMaxDepth + 2> per_level{};  ///< bodies per level, [11] = overflow and stray
};

/// The smallest unit extent of `boxes` on `grid` (loose_extent_kernel's minimum).
float smallest_unit_extent(const std::vector<Aabb>& boxes, const LooseGrid& grid) {
  float mn = kInf;
  for (const Aabb& b : boxes) {
    float e = loose_unit_extent(loose_unit(grid, b.min), loose_unit(grid, b.max));
    e = e < 0.0f ? 0.0f : e;
    mn = std::min(mn, e != e ? kInf : e);
  }
  return mn;
}

/// count_loose_tests on the root `grid` with D_w `depth` (>= 0).
LooseTestCount count_loose_tests_on(const std::vector<Aabb>& boxes, const LooseGrid& grid, int depth) {
  LooseTestCount r;
  r.depth = depth;
  const auto n = boxes.size();
  std::vector<std::uint32_t> key(n);
  std::unordered_map<std::uint32_t, std::uint32_t> cell;
  cell.reserve(n);
  std::uint64_t overflow = 0, tree = 0, strays = 0;
  std::array<std::uint64_t, kLooseMaxDepth + 2> stray_below{};  // [l]: stray bodies of levels < l
  for (std::size_t i = 0; i < n; ++i) {
    const Vec3 lo = loose_unit(grid, boxes[i].min), hi = loose_unit(grid, boxes[i].max);
    key[i] = loose_has_nan(boxes[i]) ? kHostNanKey : host_loose_key(lo, hi, depth);
    if (key[i] == kHostNanKey) continue;
    if (key[i] > kHostOverflowKey) {
      ++strays;
      ++r.per_level[kLooseMaxDepth + 1];
      for (int l = static_cast<int>(key[i] - kHostOverflowKey - 1u) + 1; l <= kLooseMaxDepth + 1; ++l)
        ++stray_below[static_cast<std::size_t>(l)];
      continue;
    }
    if (key[i] == kHostOverflowKey) {
      ++overflow;
      ++r.per_level[kLooseMaxDepth + 1];
      continue;
    }
    ++tree;
    ++r.per_level[loose_key_level(key[i])];
    ++cell[key[i]];
  }
  for (const auto& [k, c] : cell) r.tests += static_cast<std::uint64_t>(c) * (c - 1) / 2;
  for (std::size_t i = 0; i < n; ++i) {
    if (key[i] == kHostOverflowKey || key[i] >= kHostNanKey) continue;
    const bool stray = key[i] > kHostOverflowKey;
    const int level = stray ? static_cast<int>(key[i] - kHostOverflowKey - 1u) : loose_key_level(key[i]);
    const int own = stray ? -1 : level;
    if (!stray) r.tests += stray_below[static_cast<std::size_t>(level)];
    const Vec3 lo = loose_unit(grid, boxes[i].min), hi = loose_unit(grid, boxes[i].max);
    for (int m = 0; m <= level; ++m) {
      if (r.per_level[m] == 0) continue;
      const LooseRange rx = loose_query_axis_q(loose_q_min(lo.x), loose_q_max(hi.x), m);
      const LooseRange ry = loose_query_axis_q(loose_q_min(lo.y), loose_q_max(hi.y), m);
      const LooseRange rz = loose_query_axis_q(loose_q_min(lo.z), loose_q_max(hi.z), m);
      for (int iz = rz.lo; iz <= rz.hi; ++iz)
        for (int iy = ry.lo; iy <= ry.hi; ++iy)
          for (int ix = rx.lo; ix <= rx.hi; ++ix) {
            const std::uint32_t ck = loose_cell_key(m, static_cast<std::uint32_t>(ix), static_cast<std::uint32_t>(iy),
                                                    static_cast<std::uint32_t>(iz));
            if (m == own && ck <= key[i]) continue;
            const auto it = cell.find(ck);
            if (it != cell.end()) r.tests += it->second;
          }
    }
  }
  const std::uint64_t lists = overflow + strays;  // each tests the ones after it
  r.tests += (lists > 0 ? lists * (lists - 1) / 2 : 0) + overflow * tree;
  return r;
}

/// The exact tests with the domain's root (D_w `depth`, -1 = auto).
LooseTestCount count_loose_tests(const std::vector<Aabb>& boxes, const Aabb& domain, int depth) {
  const LooseGrid grid = loose_grid(domain);
  return count_loose_tests_on(boxes, grid, depth >= 0 ? depth : loose_auto_depth(smallest_unit_extent(boxes, grid)));
}

/// The exact tests of the device octree with depth `auto` and the snapped root
/// (loose_snapped_grid of the smallest extent, broadphase_octree_tree.cu's kLooseSnapRoot).
LooseTestCount count_loose_tests_snapped(const std::vector<Aabb>& boxes, const Aabb& domain) {
  const LooseGrid grid = loose_grid(domain);
  int depth = 0;
  const LooseGrid snapped = loose_snapped_grid(grid, smallest_unit_extent(boxes, grid), &depth);
  return count_loose_tests_on(boxes, snapped, depth);
}

/// bench_gpu_broadphase's boxes (make_boxes, domain_for): n cubes of half side 0.06 m
/// (even bodies) and 0.03 m (odd), centres uniform (SplitMix64 `seed`, x, y, z in that
/// order) in a cube of side 3.4 (n / 10^4)^(1/3) m; the domain is that cube grown by 0.06.
std::pair<std::vector<Aabb>, Aabb> bench_boxes(std::uint32_t n, std::uint64_t seed = 1) {
  const double side = 3.4 * std::cbrt(static_cast<double>(n) / 1e4);
  SplitMix64 rng(seed);
  const float h = static_cast<float>(side / 2.0);
  std::vector<Aabb> boxes(n);
  for (std::uint32_t i = 0; i < n; ++i) {
    const float x = rng.uniform(-h, h), y = rng.uniform(-h, h), z = rng.uniform(-h, h);
    const float e = (i % 2 == 0) ? 0.06f : 0.03f;
    boxes[i] = {{x - e, y - e, z - e}, {x + e, y + e, z + e}};
  }
  const float d = h + 0.06f;
  return {boxes, Aabb{{-d, -d, -d}, {d, d, d}}};
}

/// The domain grown about its centre to the side e 2^D (a hair more, so that a body of
/// extent e fits level D through the unit rounding), D the smallest level whose cell of
/// that side covers the domain: the smallest bodies then sit in cells of their own size.
Aabb snapped_domain(const Aabb& domain, float e) {
  const LooseGrid g = loose_grid(domain);
  double side = e;
  while (side < g.side) side *= 2.0;
  side *= 1.0 + 1.0 / 4096.0;
  const Vec3 c = center(domain);
  const auto h = static_cast<float>(side / 2.0);
  return {{c.x - h, c.y - h, c.z - h}, {c.x + h, c.y + h, c.z + h}};
}

// The counter agrees with the host model's test count (every variant of host_loose_blocks'
// walk) on the shipped box sets and the bench's distribution, at auto and fixed depths.
TEST(LooseBlockHostModel, TestCountEqualsTheModel) {
  for (const std::string& name : box_set_names()) {
    for (int depth : {-1, 0, 2, 10}) {
      SCOPED_TRACE(fmt::format("{} depth {}", name, depth));
      const BoxSet& set = box_set(name);
      EXPECT_EQ(count_loose_tests(set.boxes, set.domain, depth).tests,
                host_loose_blocks(set.boxes, set.domain, depth).tests);
    }
  }
  const auto [boxes, domain] = bench_boxes(20000, 7);
  for (const Aabb& d : {domain, snapped_domain(domain, 0.06f)}) {
    for (int depth : {-1, 4, 7}) {
      SCOPED_TRACE(fmt::format("bench 2e4, side {}, depth {}", loose_grid(d).side, depth));
      const HostLooseBlocks h = host_loose_blocks(boxes, d, depth);
      EXPECT_EQ(h.broken, "");
      EXPECT_EQ(count_loose_tests(boxes, d, depth).tests, h.tests);
    }
  }
}

// Exact tests per depth on the bench's boxes (10^4 .. 4x10^6 with OCTOCD_BP_COUNT_LARGE=1,
// else 10^4 and 10^5): D_w above auto changes nothing (no body fits a deeper cell), so
// `auto` is the best D_w of the domain's grid; what decides the count is how the smallest
// extent falls between two powers of two of the root side. A grid snapped to the
// smallest extent (snapped_domain) puts the small cubes in cells of their own side at
// every size. Printed: the table for the report; asserted: auto <= every fixed depth,
// and the snapped grid at most the domain grid's count where its cells fit worse.
TEST(LooseBlockHostModel, ExactTestsPerDepthOnTheBenchBoxes) {
  std::vector<std::uint32_t> sizes{10000, 100000};
  const char* large = std::getenv("OCTOCD_BP_COUNT_LARGE");
  if (large != nullptr && std::string(large) == "1") sizes = {10000, 100000, 1000000, 4000000};
  for (const std::uint32_t n : sizes) {
    const auto [boxes, domain] = bench_boxes(n);
    const LooseTestCount a = count_loose_tests(boxes, domain, -1);
    const Aabb snapped = snapped_domain(domain, 0.06f);
    const LooseTestCount s = count_loose_tests(boxes, snapped, -1);
    const LooseTestCount dev = count_loose_tests_snapped(boxes, domain);
    const float cell = loose_grid(domain).side / static_cast<float>(1 << a.depth);
    std::string line = fmt::format("n {}: domain side {:.3f} m, auto D_w {} (cell {:.4f} m = {:.2f} x 0.06): {} tests;",
                                   n, loose_grid(domain).side, a.depth, cell, cell / 0.06f, a.tests);
    for (int depth = std::max(0, a.depth - 3); depth <= std::min(kLooseMaxDepth, a.depth + 2); ++depth) {
      const LooseTestCount f = count_loose_tests(boxes, domain, depth);
      line += fmt::format(" D {} {},", depth, f.tests);
      EXPECT_LE(a.tests, f.tests) << "depth " << depth;
    }
    line += fmt::format(" snapped side {:.3f} m, D_w {}: {} tests ({:.2f} x); levels", loose_grid(snapped).side,
                        s.depth, s.tests, static_cast<double>(s.tests) / static_cast<double>(a.tests));
    for (int l = 0; l <= kLooseMaxDepth + 1; ++l)
      if (s.per_level[l] != 0) line += fmt::format(" {}:{}", l, s.per_level[l]);
    line += fmt::format("; device root (loose_snapped_grid): D_w {}, {} tests", dev.depth, dev.tests);
    std::printf("%s\n", line.c_str());
    if (cell > 1.25f * 0.06f) {
      EXPECT_LT(dev.tests, a.tests);
    }
    // The snapped grid puts the small cubes at a level of cell side 0.06 m (their extent).
    const float scell = loose_grid(snapped).side / static_cast<float>(1 << s.depth);
    EXPECT_NEAR(scell, 0.06f, 0.001f);
    if (cell > 1.25f * 0.06f) {
      EXPECT_LT(s.tests, a.tests);
    }
  }
}

// bp::PairBuffer (the warp appends a thread's first pairs at the end) in the
// one-thread-per-slot queries of `octree` and `lbvh`: flat's total and pair set, with the
// first find at capacity 16 (find_all: the keys that fit, the total counted in full), on
// sets whose bodies have more pairs than the buffer keeps (one-cell) and on the bench's
// boxes.
TEST(DevicePairBuffer, ThreadQueriesGiveFlatsPairs) {
  REQUIRE_CUDA_DEVICE();
  Stream stream;
  std::vector<std::pair<std::string, std::pair<std::vector<Aabb>, Aabb>>> sets;
  sets.push_back({"bench-50000", bench_boxes(50000, 5)});
  for (const char* name : {"one-cell", "uniform-10000", "nested-levels", "huge-and-infinite"})
    sets.push_back({name, {box_set(name).boxes, box_set(name).domain}});
  for (const char* bp_name : {"octree", "lbvh"}) {
    BroadPhaseConfig c;
    c.name = bp_name;
    c.octree_depth = -1;
    for (const auto& [name, set] : sets) {
      SCOPED_TRACE(fmt::format("{} on {}", bp_name, name));
      const auto& [boxes, domain] = set;
      const auto n = static_cast<std::uint32_t>(boxes.size());
      const std::vector<Pair> flat = flat_pairs(boxes, domain);
      DeviceBuffer<Aabb> dboxes("test boxes");
      gpu::upload(dboxes, boxes, stream.s);
      auto bp = make_device(c, domain, gpu::LooseOctreeQuery::Thread);
      bp->reserve(n, stream.s);
      const FindResult r = find_all(*bp, dboxes, n, stream.s);
      ASSERT_EQ(r.total, flat.size());
      EXPECT_FALSE(r.wrote_past_capacity);
      std::vector<Pair> pairs;
      ASSERT_TRUE(to_pairs(r.keys, n, pairs, r.shift));
      EXPECT_TRUE(same_pairs(pairs, flat, boxes));
    }
  }
}

// The device octree (depth auto, the snapped root, the occupancy map) tests exactly what the
// counter says for its snapped root, and its pair set is flat's.
TEST(DeviceOctreeRoot, CandidatesEqualTheCountOfItsRoot) {
  REQUIRE_CUDA_DEVICE();
  Stream stream;
  std::vector<std::pair<std::string, std::pair<std::vector<Aabb>, Aabb>>> sets;
  sets.push_back({"bench-20000", bench_boxes(20000, 7)});
  sets.push_back({"bench-50000", bench_boxes(50000, 3)});
  for (const char* name : {"uniform-1000", "nested-levels", "touching-lattice"})
    sets.push_back({name, {box_set(name).boxes, box_set(name).domain}});
  BroadPhaseConfig c;
  c.name = "octree";
  c.octree_depth = -1;
  for (const auto& [name, set] : sets) {
    SCOPED_TRACE(name);
    const auto& [boxes, domain] = set;
    const auto n = static_cast<std::uint32_t>(boxes.size());
    const std::vector<Pair> flat = flat_pairs(boxes, domain);
    DeviceBuffer<Aabb> dboxes("test boxes");
    gpu::upload(dboxes, boxes, stream.s);
    auto bp = make_device(c, domain);
    bp->reserve(n, stream.s);
    const FindResult r = find_all(*bp, dboxes, n, stream.s);
    std::vector<Pair> pairs;
    ASSERT_TRUE(to_pairs(r.keys, n, pairs, r.shift));
    EXPECT_TRUE(same_pairs(pairs, flat, boxes));
    EXPECT_EQ(r.candidates, count_loose_tests_snapped(boxes, domain).tests);
  }
}

// ---- `octree` with a pair cache (broadphase_octree_cache.cu, coherent_plan.hpp) -------------

/// Boxes moving at constant velocity, reflected at the faces of `region` (a coherent
/// motion: each call moves every box by at most vmax x dt per axis).
struct Motion {
  Aabb region;
  std::vector<Vec3> c, h, v;

  Motion(std::size_t n, unsigned seed, const Aabb& r, float hmin, float hmax, float vmax) : region(r) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<float> ux(r.min.x, r.max.x), uy(r.min.y, r.max.y), uz(r.min.z, r.max.z),
        uh(hmin, hmax), uv(-vmax, vmax);
    for (std::size_t i = 0; i < n; ++i) {
      c.push_back({ux(rng), uy(rng), uz(rng)});
      h.push_back({uh(rng), uh(rng), uh(rng)});
      v.push_back({uv(rng), uv(rng), uv(rng)});
    }
  }
  std::vector<Aabb> boxes() const {
    std::vector<Aabb> out;
    for (std::size_t i = 0; i < c.size(); ++i) out.push_back(box_at(c[i], h[i]));
    return out;
  }
  void step(float dt) {
    for (std::size_t i = 0; i < c.size(); ++i) {
      float* p[3] = {&c[i].x, &c[i].y, &c[i].z};
      float* w[3] = {&v[i].x, &v[i].y, &v[i].z};
      const float lo[3] = {region.min.x, region.min.y, region.min.z}, hi[3] = {region.max.x, region.max.y, region.max.z};
      for (int a = 0; a < 3; ++a) {
        *p[a] += *w[a] * dt;
        if (*p[a] < lo[a] || *p[a] > hi[a]) *w[a] = -*w[a];
      }
    }
  }
};

/// flat's pairs as the keys (a << shift) | b, ascending.
std::vector<unsigned long long> flat_keys(const std::vector<Aabb>& boxes, const Aabb& domain, int shift) {
  std::vector<unsigned long long> keys;
  for (const Pair p : flat_pairs(boxes, domain)) keys.push_back((static_cast<unsigned long long>(p.a) << shift) | p.b);
  return keys;
}

/// What settled_find saw: the result, and the verdicts before it was Valid.
struct SettledFind {
  FindResult r;
  int plan = 0;       ///< the plan of the valid find()
  int reruns = 0;     ///< Rerun verdicts
  int regrows = 0;    ///< Regrow verdicts
};

/// find() as the engine runs it (`capacity` keys of output and a scratch of as many, so
/// the keys come sorted): settle() after each; Rerun runs it again, Regrow reserves first
/// (at most 4 tries).
SettledFind settled_find(DeviceBroadPhase& bp, const DeviceBuffer<Aabb>& boxes, std::uint32_t n, std::uint32_t capacity,
                     cudaStream_t s, int shift) {
  SettledFind out;
  DeviceBuffer<unsigned long long> scratch("test scratch");
  scratch.reset(std::max<std::uint32_t>(capacity, 1));
  for (int attempt = 0; attempt < 4; ++attempt) {
    out.plan = bp.plan();
    Output o(capacity, s, shift);
    gpu::PairOutput po = o.pair_output();
    po.scratch = scratch.get();
    bp.find(boxes.get(), n, po, s);
    out.r = o.read(s);
    const gpu::Settled v = bp.settle();
    if (v == gpu::Settled::Valid) return out;
    if (v == gpu::Settled::Regrow) {
      ++out.regrows;
      bp.reserve(n, s);
    } else {
      ++out.reruns;
    }
  }
  ADD_FAILURE() << "find() did not settle in 4 tries";
  return out;
}

// The planner on its own (no device): Plain first, then Build, then Hits; a Hit that found
// an stray body is a Rerun with a Build next, or, when the cache served no call, Plain
// for 2, then 4 calls (the back-off), reset by a cache that served; a Build that did not fit
// is a Regrow to 1.25 x its pairs + 64; the predictor builds before the displacement
// reaches the margin.
TEST(CoherencePlanner, PlansFollowTheVerdicts) {
  using gpu::CoherentPlan;
  using gpu::CoherentStatus;
  gpu::CoherencePlanner p;
  auto slack = [](float s) {
    CoherentStatus st;
    std::memcpy(&st.min_slack_bits, &s, sizeof s);
    return st;
  };
  CoherentStatus built;
  built.margin = 1.0f;
  built.cache_total = 100;
  EXPECT_EQ(p.plan(), CoherentPlan::Plain);
  EXPECT_EQ(p.settle(CoherentPlan::Plain, {}, 1000), gpu::Settled::Valid);
  ASSERT_EQ(p.plan(), CoherentPlan::Build);
  CoherentStatus too_many = built;
  too_many.cache_total = 2000;
  EXPECT_EQ(p.settle(CoherentPlan::Build, too_many, 1000), gpu::Settled::Regrow);
  EXPECT_EQ(p.needed_capacity(), 2000u + 500u + 64u);
  ASSERT_EQ(p.plan(), CoherentPlan::Build);
  EXPECT_EQ(p.settle(CoherentPlan::Build, built, 3000), gpu::Settled::Valid);
  ASSERT_EQ(p.plan(), CoherentPlan::Hit);
  // 0.1 used per call: after 0.7, 0.7 + 2 x 0.1 < 1 hits on; after 0.8 it builds.
  for (int k = 1; k <= 7; ++k) {
    EXPECT_EQ(p.settle(CoherentPlan::Hit, slack(1.0f - 0.1f * static_cast<float>(k)), 3000), gpu::Settled::Valid);
    EXPECT_EQ(p.plan(), CoherentPlan::Hit) << "after " << k << " hits";
  }
  EXPECT_EQ(p.settle(CoherentPlan::Hit, slack(0.2f), 3000), gpu::Settled::Valid);
  EXPECT_EQ(p.plan(), CoherentPlan::Build) << "0.8 used at 0.1 a call: the predictor builds";
  EXPECT_EQ(p.settle(CoherentPlan::Build, built, 3000), gpu::Settled::Valid);
  // A jump: Rerun, then Build (the cache had served 0 calls: back-off).
  CoherentStatus escaped;
  escaped.escaped = 3;
  EXPECT_EQ(p.settle(CoherentPlan::Hit, escaped, 3000), gpu::Settled::Rerun);
  for (int round : {2, 4}) {
    for (int k = 0; k < round; ++k) {
      ASSERT_EQ(p.plan(), CoherentPlan::Plain) << "back-off round " << round << ", call " << k;
      EXPECT_EQ(p.settle(CoherentPlan::Plain, {}, 3000), gpu::Settled::Valid);
    }
    ASSERT_EQ(p.plan(), CoherentPlan::Build);
    EXPECT_EQ(p.settle(CoherentPlan::Build, built, 3000), gpu::Settled::Valid);
    ASSERT_EQ(p.plan(), CoherentPlan::Hit);
    EXPECT_EQ(p.settle(CoherentPlan::Hit, escaped, 3000), gpu::Settled::Rerun);
  }
  for (int k = 0; k < 8; ++k) EXPECT_EQ(p.settle(p.plan(), built, 3000), gpu::Settled::Valid);  // 8 Plain
  ASSERT_EQ(p.plan(), CoherentPlan::Build);
  EXPECT_EQ(p.settle(CoherentPlan::Build, built, 3000), gpu::Settled::Valid);
  EXPECT_EQ(p.settle(CoherentPlan::Hit, slack(1.0f), 3000), gpu::Settled::Valid);  // the cache served
  EXPECT_EQ(p.settle(CoherentPlan::Hit, escaped, 3000), gpu::Settled::Rerun);
  EXPECT_EQ(p.plan(), CoherentPlan::Build) << "a cache that served resets the back-off";
  EXPECT_EQ(p.misses(), 4u);
  // Nothing moves with a margin 0 (points): the cache serves, no predicted build.
  gpu::CoherencePlanner q;
  CoherentStatus zero = built;
  zero.margin = 0.0f;
  EXPECT_EQ(q.settle(q.plan(), {}, 10), gpu::Settled::Valid);
  EXPECT_EQ(q.settle(q.plan(), zero, 1000), gpu::Settled::Valid);
  for (int k = 0; k < 3; ++k) {
    ASSERT_EQ(q.plan(), CoherentPlan::Hit);
    EXPECT_EQ(q.settle(CoherentPlan::Hit, slack(0.0f), 1000), gpu::Settled::Valid);
  }
}

// A coherent motion of 3000 boxes over 120 calls (a scratch given, as the engine gives): every
// settled call's keys are flat's, in flat's order (ascending (a, b), what the engine's pair list and the CPU octree's cache
// give), at the engine's key shift and at 32 on alternate calls; Builds and Hits both
// occur, with few reruns; a body that jumps makes a Rerun and the set stays exact; an
// output smaller than the cache gives the total and the first keys, nothing past it.
TEST(DeviceCoherentOctree, PairsEqualFlatInOrderOnEveryCallOfACoherentMotion) {
  REQUIRE_CUDA_DEVICE();
  Stream stream;
  const Aabb region = cube(-1.0f, 1.0f);
  const Aabb domain = cube(-1.2f, 1.2f);
  Motion m(3000, 11, region, 0.02f, 0.06f, 1.0f);
  BroadPhaseConfig c;
  c.name = "octree";
  c.octree_depth = -1;
  auto bp = gpu::make_device_coherent_octree(c, domain);
  EXPECT_EQ(bp->name(), "octree");
  EXPECT_TRUE(bp->sorts_pairs());
  const auto n = static_cast<std::uint32_t>(m.c.size());
  bp->reserve(n, stream.s);
  DeviceBuffer<Aabb> boxes("test boxes");
  int plans[gpu::kBroadPhasePlans] = {};
  int reruns = 0, regrows = 0;
  for (int call = 0; call < 120; ++call) {
    SCOPED_TRACE(fmt::format("call {}", call));
    if (call == 60) m.c[7] = {0.9f, -0.9f, 0.9f};  // a jump
    const std::vector<Aabb> host = m.boxes();
    gpu::upload(boxes, host, stream.s, call == 0);
    const int shift = call % 2 == 0 ? gpu::key_bits(n) : 32;
    const std::vector<unsigned long long> want = flat_keys(host, domain, shift);
    const auto cap = static_cast<std::uint32_t>(want.size() + 5);
    const SettledFind got = settled_find(*bp, boxes, n, cap, stream.s, shift);
    ++plans[got.plan];
    reruns += got.reruns;
    regrows += got.regrows;
    ASSERT_EQ(got.r.total, want.size());
    EXPECT_FALSE(got.r.wrote_past_capacity);
    EXPECT_TRUE(got.r.keys == want) << "the keys are not flat's in flat's order (plan " << got.plan << ")";
    EXPECT_GE(got.r.candidates, static_cast<unsigned long long>(got.r.total));
    if (call == 90) {  // a small output: the total, the first keys (the copy through the selection)
      const SettledFind small = settled_find(*bp, boxes, n, static_cast<std::uint32_t>(want.size() / 3), stream.s, shift);
      EXPECT_EQ(small.r.total, want.size());
      EXPECT_FALSE(small.r.wrote_past_capacity);
      EXPECT_TRUE(std::equal(small.r.keys.begin(), small.r.keys.end(), want.begin()));
    }
    m.step(0.001f);
  }
  std::cout << fmt::format("[ info ] plans Plain {} Build {} Hit {}; reruns {}, regrows {}\n", plans[0], plans[1],
                           plans[2], reruns, regrows);
  EXPECT_EQ(plans[0], 1) << "only the first call runs the one-shot octree on the boxes";
  EXPECT_GE(plans[1], 2);
  EXPECT_GE(plans[2], 60) << "the cache must serve most calls of a coherent motion";
  EXPECT_GE(reruns, 1) << "the jump must miss";
  EXPECT_LE(reruns, 5);
}

// The engine's use: one CUDA graph per plan, captured when the plan first comes, replayed
// on moving boxes (the boxes' buffer rewritten in place) with a scratch given; each replay
// settled; flat's keys in order every call. Incoherent input (new random boxes every call) stays exact and backs
// off to the one-shot octree.
TEST(DeviceCoherentOctree, GraphsPerPlanReplayAndIncoherentInputStaysExact) {
  REQUIRE_CUDA_DEVICE();
  Stream stream;
  const Aabb region = cube(-1.0f, 1.0f);
  const Aabb domain = cube(-1.2f, 1.2f);
  BroadPhaseConfig c;
  c.name = "octree";
  c.octree_depth = -1;
  for (const bool coherent : {true, false}) {
    SCOPED_TRACE(coherent ? "coherent motion" : "new boxes every call");
    Motion m(2000, 5, region, 0.02f, 0.06f, coherent ? 1.0f : 0.0f);
    auto bp = gpu::make_device_coherent_octree(c, domain);
    const auto n = static_cast<std::uint32_t>(m.c.size());
    const int shift = gpu::key_bits(n);
    bp->reserve(n, stream.s);
    DeviceBuffer<Aabb> boxes("test boxes");
    gpu::upload(boxes, m.boxes(), stream.s);
    Output out(4 * n, stream.s, shift);
    DeviceBuffer<unsigned long long> scratch("test scratch");
    scratch.reset(4 * static_cast<std::size_t>(n));
    gpu::PairOutput po = out.pair_output();
    po.scratch = scratch.get();  // the engine's: the keys come sorted on every plan
    cudaGraphExec_t exec[gpu::kBroadPhasePlans] = {};
    cudaGraph_t graph[gpu::kBroadPhasePlans] = {};
    int plans[gpu::kBroadPhasePlans] = {};
    for (int call = 0; call < 40; ++call) {
      SCOPED_TRACE(fmt::format("call {}", call));
      const std::vector<Aabb> host =
          coherent ? m.boxes() : random_boxes(n, 100 + static_cast<unsigned>(call), region, 0.02f, 0.06f);
      gpu::upload(boxes, host, stream.s, false);
      const std::vector<unsigned long long> want = flat_keys(host, domain, shift);
      ASSERT_LE(want.size(), out.capacity);
      for (int attempt = 0;; ++attempt) {
        ASSERT_LT(attempt, 3) << "no valid find in 3 tries";
        const int p = bp->plan();
        ASSERT_GE(p, 0);
        ASSERT_LT(p, gpu::kBroadPhasePlans);
        if (!exec[p]) {
          gpu::check(cudaStreamSynchronize(stream.s), "cudaStreamSynchronize");
          gpu::check(cudaStreamBeginCapture(stream.s, cudaStreamCaptureModeThreadLocal), "cudaStreamBeginCapture");
          bp->find(boxes.get(), n, po, stream.s);
          ASSERT_EQ(cudaStreamEndCapture(stream.s, &graph[p]), cudaSuccess) << "plan " << p << " is not capturable";
          gpu::check(cudaGraphInstantiate(&exec[p], graph[p], 0), "cudaGraphInstantiate");
        }
        out.clear(stream.s);
        gpu::check(cudaGraphLaunch(exec[p], stream.s), "cudaGraphLaunch");
        const FindResult r = out.read(stream.s);
        const gpu::Settled v = bp->settle();
        ASSERT_NE(v, gpu::Settled::Regrow) << "the first cache (2 n + 64 keys) holds these boxes' pairs";
        if (v == gpu::Settled::Rerun) continue;
        ++plans[p];
        ASSERT_EQ(r.total, want.size()) << "plan " << p;
        EXPECT_TRUE(r.keys == want) << "plan " << p << ": not flat's keys in order";
        break;
      }
      m.step(0.001f);
    }
    for (int p = 0; p < gpu::kBroadPhasePlans; ++p) {
      if (exec[p]) (void)cudaGraphExecDestroy(exec[p]);
      if (graph[p]) (void)cudaGraphDestroy(graph[p]);
    }
    std::cout << fmt::format("[ info ] {}: plans Plain {} Build {} Hit {}\n", coherent ? "coherent" : "incoherent",
                             plans[0], plans[1], plans[2]);
    if (coherent) {
      EXPECT_GE(plans[2], 30);
    } else {
      EXPECT_GE(plans[0], 30) << "incoherent input backs off to the one-shot octree";
      EXPECT_EQ(plans[2], 0);
    }
  }
}

}  // namespace
