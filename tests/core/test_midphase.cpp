// Unit tests of the per-mesh octree (design.md section 5.2) and the midphase / narrow phase (design.md section 5.3).
// Meshes are built by hand (point clouds, Fibonacci spheres): the midphase only uses vertices.

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <numeric>
#include <random>
#include <string>
#include <vector>

#include "octocd/error.hpp"
#include "octocd/midphase.hpp"
#include "octocd/mesh_octree.hpp"
#include "octocd/midphase_hd.hpp"
#include "octocd/midphase_views.hpp"
#include "octocd/vertex_blocks.hpp"

// This file's own names (its tests compile in unity batches with the folder's other files).
namespace octocd_test_midphase {

namespace {

using octocd::Aabb;
using octocd::Mesh;
using octocd::MeshOctree;
using octocd::MidphaseConfig;
using octocd::MidphaseStats;
using octocd::PlacedShape;
using octocd::Vec3;
namespace hd = octocd::hd;

Mesh random_cloud(std::mt19937& rng, int n, Vec3 half) {
  std::uniform_real_distribution<float> u(-1.0f, 1.0f);
  Mesh m;
  m.name = "cloud";
  for (int i = 0; i < n; ++i) m.vertices.push_back({half.x * u(rng), half.y * u(rng), half.z * u(rng)});
  return m;
}

/// Points on a sphere (Fibonacci lattice), optionally jittered.
Mesh sphere_cloud(float r, int n) {
  Mesh m;
  m.name = "sphere";
  const float golden = 2.399963229728653f;
  for (int i = 0; i < n; ++i) {
    const float y = 1.0f - 2.0f * (static_cast<float>(i) + 0.5f) / static_cast<float>(n);
    const float rr = std::sqrt(1.0f - y * y);
    const float phi = golden * static_cast<float>(i);
    m.vertices.push_back({r * rr * std::cos(phi), r * y, r * rr * std::sin(phi)});
  }
  return m;
}

PlacedShape place(const MeshOctree& t, Vec3 p) {
  PlacedShape s;
  s.octree = &t;
  s.position = p;
  s.box = octocd::translated(t.bounds, p);
  return s;
}

PlacedShape place_box(const Aabb& b) {
  PlacedShape s;
  s.box = b;
  return s;
}

const std::vector<std::string> kConfigs = {"0", "1", "2", "1,2", "0,1,2", "0,2", "3", "0,1,2,3"};

// ---- octree -------------------------------------------------------------------------------

TEST(MeshOctree, ValidOnRandomCloudsAllDepths) {
  std::mt19937 rng(1);
  for (int trial = 0; trial < 5; ++trial) {
    const Mesh m = random_cloud(rng, 200 + 300 * trial, {0.5f, 0.2f * static_cast<float>(trial + 1), 0.3f});
    for (int d = -1; d <= 6; ++d) {
      const MeshOctree t = octocd::build_mesh_octree(m, d);
      EXPECT_EQ(t.validate(), "") << "depth " << d;
      if (d >= 0) {
        EXPECT_EQ(t.depth, d);
      }
      ASSERT_EQ(t.vertices.size(), m.vertices.size());
      for (std::size_t i = 0; i < t.vertices.size(); ++i) {
        ASSERT_TRUE(t.vertices[i] == m.vertices[t.original_index[i]]);
      }
      // Every cell's vertex range lies inside its box.
      for (const auto& c : t.cells) {
        for (std::uint32_t v = c.first_vertex; v < c.first_vertex + c.vertex_count; ++v) {
          const Vec3 p = t.vertices[v];
          ASSERT_TRUE(octocd::contains(c.box, Aabb{p, p}));
        }
      }
    }
  }
}

// The vertices follow the depth-10 Morton order at every depth (a leaf cell's vertices too,
// so that its blocks of kVertexBlock vertices are compact patches): the order of a depth-D
// octree is the one of the depth-10 octree, whose cells hold one code each.
TEST(MeshOctree, VertexOrderIsTheDepth10MortonOrderAtEveryDepth) {
  std::mt19937 rng(3);
  const Mesh m = random_cloud(rng, 2000, {0.7f, 0.4f, 0.5f});
  const MeshOctree finest = octocd::build_mesh_octree(m, 10);
  ASSERT_EQ(finest.validate(), "");
  for (int d = 0; d < 10; ++d) {
    const MeshOctree t = octocd::build_mesh_octree(m, d);
    ASSERT_EQ(t.validate(), "") << "depth " << d;
    EXPECT_EQ(t.original_index, finest.original_index) << "depth " << d;
  }
  // A planted fault: the depth-D order with ties kept in input order (a stable sort by the
  // depth-2 code alone) differs from it.
  std::vector<std::uint32_t> coarse(m.vertices.size());
  std::iota(coarse.begin(), coarse.end(), 0u);
  const MeshOctree two = octocd::build_mesh_octree(m, 2);
  std::vector<std::uint32_t> cell_of(m.vertices.size());
  for (std::uint32_t c = two.level_begin(2); c < two.level_end(2); ++c)
    for (std::uint32_t v = two.cells[c].first_vertex; v < two.cells[c].first_vertex + two.cells[c].vertex_count; ++v)
      cell_of[two.original_index[v]] = two.cells[c].morton;
  std::stable_sort(coarse.begin(), coarse.end(),
                   [&](std::uint32_t a, std::uint32_t b) { return cell_of[a] < cell_of[b]; });
  EXPECT_NE(coarse, finest.original_index);
}

TEST(MeshOctree, DegenerateClouds) {
  Mesh one;
  one.vertices = {{1.0f, 2.0f, 3.0f}};
  for (int d = 0; d <= 10; ++d) EXPECT_EQ(octocd::build_mesh_octree(one, d).validate(), "");
  Mesh flat;  // all on a plane, plus duplicates
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> u(-1.0f, 1.0f);
  for (int i = 0; i < 300; ++i) flat.vertices.push_back({u(rng), 0.25f, u(rng)});
  flat.vertices.push_back(flat.vertices[0]);
  for (int d = 0; d <= 10; ++d) EXPECT_EQ(octocd::build_mesh_octree(flat, d).validate(), "");
  EXPECT_EQ(octocd::build_mesh_octree(flat, -1).validate(), "");
}

TEST(MeshOctree, ValidateDetectsCorruption) {
  std::mt19937 rng(2);
  const MeshOctree t = octocd::build_mesh_octree(random_cloud(rng, 500, {1, 1, 1}), 3);
  ASSERT_EQ(t.validate(), "");
  MeshOctree bad = t;
  bad.cells.back().box.max.x += 1.0f;
  EXPECT_NE(bad.validate(), "");
  bad = t;
  std::swap(bad.vertices[0], bad.vertices.back());
  EXPECT_NE(bad.validate(), "");
  bad = t;
  bad.cells[1].child_count += 1;
  EXPECT_NE(bad.validate(), "");
  bad = t;
  bad.level_offset[2] += 1;
  EXPECT_NE(bad.validate(), "");
}

TEST(MeshOctree, RejectsBadInput) {
  Mesh empty;
  EXPECT_THROW(octocd::build_mesh_octree(empty, 2), octocd::InputError);
  Mesh one;
  one.vertices = {{0, 0, 0}};
  EXPECT_THROW(octocd::build_mesh_octree(one, 11), octocd::InputError);
  EXPECT_THROW(octocd::build_mesh_octree(one, -2), octocd::InputError);
}

TEST(MeshOctree, AutoDepthRule) {
  // Cloud in [0,1]^3 (corners pin the bounds): cluster of 65 coincident-ish points in the
  // first depth-1 octant... Build: 8 grid clusters of 40 points each at depth-1 cell centres
  // -> depth 0 holds 320 > 64, depth 1 leaves hold 40 (+corner) <= 64 -> auto = 1.
  Mesh m;
  for (int c = 0; c < 8; ++c) {
    const Vec3 centre{(c & 1) ? 0.75f : 0.25f, (c & 2) ? 0.75f : 0.25f, (c & 4) ? 0.75f : 0.25f};
    for (int i = 0; i < 40; ++i) {
      const float e = 0.001f * static_cast<float>(i);
      m.vertices.push_back({centre.x + e, centre.y - e, centre.z + e});
    }
  }
  m.vertices.push_back({0, 0, 0});
  m.vertices.push_back({1, 1, 1});
  EXPECT_EQ(octocd::auto_mesh_octree_depth(m), 1);
  EXPECT_EQ(octocd::build_mesh_octree(m, -1).depth, 1);
  // Add 30 more points to one cluster: that leaf holds 70 at depth 1, and the cluster
  // spans 0.07 < 1/8, so it stays whole at depth 2 too; it splits only where cells get
  // smaller than its spread. Compute the expected depth by brute force.
  for (int i = 0; i < 30; ++i) {
    const float e = 0.001f * static_cast<float>(40 + i);
    m.vertices.push_back({0.25f + e, 0.25f - e, 0.25f + e});
  }
  int expected = 8;
  for (int d = 0; d <= 8; ++d) {
    const MeshOctree t = octocd::build_mesh_octree(m, d);
    std::uint32_t largest = 0;
    for (std::uint32_t c = t.level_begin(d); c < t.level_end(d); ++c) largest = std::max(largest, t.cells[c].vertex_count);
    if (largest <= 64) {
      expected = d;
      break;
    }
  }
  EXPECT_GT(expected, 1);
  EXPECT_EQ(octocd::auto_mesh_octree_depth(m), expected);
  // 65 coincident points can never be split: auto stops at 8.
  Mesh same;
  for (int i = 0; i < 65; ++i) same.vertices.push_back({0.5f, 0.5f, 0.5f});
  same.vertices.push_back({0, 0, 0});
  EXPECT_EQ(octocd::auto_mesh_octree_depth(same), 8);
  // <= 64 vertices: depth 0.
  std::mt19937 rng(3);
  EXPECT_EQ(octocd::auto_mesh_octree_depth(random_cloud(rng, 64, {1, 1, 1})), 0);
}

/// Vertices [begin, end) inside `x` found by skipping the kVertexBlock blocks whose box
/// misses `x` (the CUDA leaf filter's scan), in order.
std::vector<std::uint32_t> block_scan(const std::vector<Vec3>& v, const std::vector<Aabb>& boxes, std::uint32_t begin,
                                      std::uint32_t end, const Aabb& x) {
  std::vector<std::uint32_t> out;
  for (std::uint32_t g = begin / octocd::kVertexBlock; g * octocd::kVertexBlock < end; ++g) {
    if (!octocd::overlaps(boxes[g], x)) continue;
    for (std::uint32_t j = std::max(begin, g * octocd::kVertexBlock);
         j < std::min(end, (g + 1) * octocd::kVertexBlock); ++j)
      if (octocd::hd::inside(v[j], x)) out.push_back(j);
  }
  return out;
}

TEST(MeshOctree, VertexBlockBoxesSkipNoVertexInside) {
  std::mt19937 rng(11);
  const MeshOctree t = octocd::build_mesh_octree(random_cloud(rng, 1000, {1.0f, 0.5f, 0.25f}), 3);
  const std::vector<Aabb> boxes = octocd::vertex_block_boxes(t.vertices);
  ASSERT_EQ(boxes.size(), (t.vertices.size() + 31) / 32);
  EXPECT_TRUE(octocd::vertex_block_boxes({}).empty());
  // Each box is the tight box of its 32 vertices (the last block: the rest).
  for (std::size_t b = 0; b < boxes.size(); ++b) {
    Aabb tight{t.vertices[32 * b], t.vertices[32 * b]};
    for (std::size_t j = 32 * b; j < std::min(t.vertices.size(), 32 * b + 32); ++j) {
      const Vec3 p = t.vertices[j];
      tight.min = {std::min(tight.min.x, p.x), std::min(tight.min.y, p.y), std::min(tight.min.z, p.z)};
      tight.max = {std::max(tight.max.x, p.x), std::max(tight.max.y, p.y), std::max(tight.max.z, p.z)};
    }
    EXPECT_TRUE(tight.min == boxes[b].min && tight.max == boxes[b].max) << "block " << b;
  }
  // Against brute force: every leaf cell's range, query boxes around random vertices,
  // including degenerate ones touching a single vertex exactly.
  std::uniform_int_distribution<std::size_t> pick(0, t.vertices.size() - 1);
  std::uniform_real_distribution<float> half(0.0f, 0.2f);
  std::vector<Aabb> queries;
  for (int q = 0; q < 200; ++q) {
    const Vec3 c = t.vertices[pick(rng)];
    const float h = q % 4 == 0 ? 0.0f : half(rng);
    queries.push_back({{c.x - h, c.y - h, c.z - h}, {c.x + h, c.y + h, c.z + h}});
  }
  auto brute = [&](std::uint32_t begin, std::uint32_t end, const Aabb& x) {
    std::vector<std::uint32_t> out;
    for (std::uint32_t j = begin; j < end; ++j)
      if (octocd::hd::inside(t.vertices[j], x)) out.push_back(j);
    return out;
  };
  std::size_t found = 0;
  for (std::uint32_t c = 0; c < t.cells.size(); ++c) {
    const std::uint32_t b0 = t.cells[c].first_vertex, b1 = b0 + t.cells[c].vertex_count;
    for (const Aabb& x : queries) {
      const std::vector<std::uint32_t> want = brute(b0, b1, x);
      found += want.size();
      EXPECT_EQ(block_scan(t.vertices, boxes, b0, b1, x), want) << "cell " << c;
    }
  }
  EXPECT_GT(found, 0u);
  // The planted fault: a box shrunk by one ulp below its largest x drops that vertex.
  std::vector<Aabb> bad = boxes;
  const Aabb b0 = boxes[0];
  bad[0].max.x = std::nextafter(b0.max.x, b0.min.x - 1.0f);
  std::uint32_t at = 0;
  while (t.vertices[at].x != b0.max.x) ++at;
  const Aabb x{t.vertices[at], t.vertices[at]};
  EXPECT_EQ(block_scan(t.vertices, boxes, 0, 32, x), brute(0, 32, x));
  EXPECT_NE(block_scan(t.vertices, bad, 0, 32, x), brute(0, 32, x));
}

// ---- configuration ---------------------------------------------------------------------------

TEST(MidphaseConfig, ParsesAcceptedForms) {
  EXPECT_TRUE(MidphaseConfig::parse("aabb-only").aabb_only);
  EXPECT_EQ(MidphaseConfig::parse("aabb-only").to_string(), "aabb-only");
  EXPECT_EQ(MidphaseConfig::parse("2").levels, (std::vector<int>{2}));
  EXPECT_EQ(MidphaseConfig::parse("1,2").levels, (std::vector<int>{1, 2}));
  EXPECT_EQ(MidphaseConfig::parse("0,1,2").levels, (std::vector<int>{0, 1, 2}));
  EXPECT_EQ(MidphaseConfig::parse("[1, 2]").levels, (std::vector<int>{1, 2}));
  EXPECT_EQ(MidphaseConfig::parse(" [ 0 , 1 ,2 ] ").levels, (std::vector<int>{0, 1, 2}));
  EXPECT_EQ(MidphaseConfig::parse("10").levels, (std::vector<int>{10}));
  EXPECT_EQ(MidphaseConfig::parse("[1, 2]").to_string(), "1,2");
  EXPECT_FALSE(MidphaseConfig::parse("0,1,2").aabb_only);
  EXPECT_EQ(MidphaseConfig::parse("0,1,2").max_level(), 2);
  EXPECT_EQ(MidphaseConfig::parse("aabb-only").max_level(), 0);
  const MidphaseConfig def;
  EXPECT_EQ(def.to_string(), "1,2");
}

TEST(MidphaseConfig, RejectsMalformed) {
  for (const char* s : {"", " ", "[]", "2,1", "1,1", "11", "-1", "1,,2", "1,2,", "a", "[1,2", "1 2",
                        "aabb", "1.5", "0x1", "100"}) {
    EXPECT_THROW(MidphaseConfig::parse(s), octocd::InputError) << "'" << s << "'";
  }
  try {
    MidphaseConfig::parse("2,1", "/solver/midphase");
    FAIL();
  } catch (const octocd::InputError& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find("/solver/midphase"), std::string::npos) << msg;
    EXPECT_NE(msg.find("aabb-only"), std::string::npos) << msg;
  }
}

// ---- contact: equality with the oracle --------------------------------------------------------

/// Random offsets near contact: direction random, distance around the sum of radii.
Vec3 near_contact(std::mt19937& rng, float reach, float lo = 0.75f, float hi = 1.05f) {
  std::normal_distribution<float> g(0.0f, 1.0f);
  std::uniform_real_distribution<float> u(lo, hi);
  Vec3 d{g(rng), g(rng), g(rng)};
  const float len = octocd::length(d);
  return (reach * u(rng) / len) * d;
}

void check_pairs(const Mesh& ma, const Mesh& mb, float reach, float lo, float hi, float theta, int placements,
                 std::uint32_t seed, float spread = 5.0f) {
  const MeshOctree ta = octocd::build_mesh_octree(ma, 3);
  const MeshOctree tb = octocd::build_mesh_octree(mb, 3);
  ASSERT_EQ(ta.validate(), "");
  ASSERT_EQ(tb.validate(), "");
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> base(-spread, spread);
  int hits = 0;
  int misses = 0;
  for (int p = 0; p < placements; ++p) {
    const Vec3 pa{base(rng), base(rng), base(rng)};
    const Vec3 pb = pa + near_contact(rng, reach, lo, hi);
    const PlacedShape a = place(ta, pa);
    const PlacedShape b = place(tb, pb);
    const bool truth = octocd::exhaustive_contact(a, b, theta);
    ASSERT_EQ(truth, octocd::exhaustive_contact(b, a, theta));
    (truth ? hits : misses)++;
    for (const std::string& c : kConfigs) {
      MidphaseStats st;
      const MidphaseConfig cfg = MidphaseConfig::parse(c);
      ASSERT_EQ(octocd::confirm_contact(a, b, theta, cfg, st), truth) << "config " << c << " placement " << p;
      ASSERT_EQ(octocd::confirm_contact(b, a, theta, cfg, st), truth) << "config " << c << " swapped";
    }
    MidphaseStats st;
    MidphaseConfig aabb;
    aabb.aabb_only = true;
    EXPECT_EQ(octocd::confirm_contact(a, b, theta, aabb, st), octocd::overlaps(a.box, b.box));
  }
  EXPECT_GT(hits, placements / 20) << "too few contacts: the test would not catch false negatives";
  EXPECT_GT(misses, placements / 20) << "too few non-contacts";
}

TEST(Midphase, EqualsExhaustiveOnRandomClouds) {
  std::mt19937 rng(11);
  const Mesh a = random_cloud(rng, 400, {0.1f, 0.08f, 0.06f});
  const Mesh b = random_cloud(rng, 300, {0.05f, 0.1f, 0.07f});
  // theta ~ mean neighbour spacing of the clouds.
  check_pairs(a, b, 0.2f, 0.75f, 1.05f, 0.02f, 400, 21);
}

TEST(Midphase, EqualsExhaustiveOnSpheres) {
  const Mesh a = sphere_cloud(0.1f, 642);
  const Mesh b = sphere_cloud(0.07f, 400);
  // Surfaces only: contacts depend on the precise gap, so both outcomes appear.
  check_pairs(a, b, 0.17f, 0.95f, 1.1f, 0.01f, 400, 22);
}

TEST(Midphase, EqualsExhaustiveFarFromOrigin) {
  // Positions ~1 km from the origin: the float rounding of the translations is about
  // 6e-5 m, a visible fraction of theta; pruning must stay conservative.
  std::mt19937 rng(16);
  const Mesh a = random_cloud(rng, 300, {0.1f, 0.08f, 0.06f});
  const Mesh b = sphere_cloud(0.07f, 400);
  check_pairs(a, b, 0.17f, 0.75f, 1.05f, 0.003f, 300, 23, 1000.0f);
}

TEST(Midphase, EqualsExhaustiveShallowOctree) {
  // Octree depth 1 < levels 2, 3: levels clamp to the deepest level.
  std::mt19937 rng(12);
  const Mesh ma = random_cloud(rng, 150, {0.1f, 0.1f, 0.1f});
  const MeshOctree ta = octocd::build_mesh_octree(ma, 1);
  const MeshOctree tb = octocd::build_mesh_octree(ma, 4);
  int hits = 0;
  for (int p = 0; p < 200; ++p) {
    const PlacedShape a = place(ta, {0, 0, 0});
    const PlacedShape b = place(tb, near_contact(rng, 0.25f, 0.8f, 1.2f));
    const bool truth = octocd::exhaustive_contact(a, b, 0.02f);
    hits += truth;
    for (const std::string& c : kConfigs) {
      MidphaseStats st;
      ASSERT_EQ(octocd::confirm_contact(a, b, 0.02f, MidphaseConfig::parse(c), st), truth) << c;
    }
  }
  EXPECT_GT(hits, 10);
  EXPECT_LT(hits, 190);
}

TEST(Midphase, MeshBoxEqualsExhaustive) {
  std::mt19937 rng(13);
  const Mesh m = sphere_cloud(0.1f, 642);
  const MeshOctree t = octocd::build_mesh_octree(m, 3);
  std::uniform_real_distribution<float> u(-0.25f, 0.25f);
  std::uniform_real_distribution<float> h(0.01f, 0.15f);
  const float theta = 0.01f;
  int hits = 0;
  int misses = 0;
  for (int p = 0; p < 600; ++p) {
    const Vec3 pos{2.0f, -1.0f, 0.5f};
    const Vec3 c = pos + Vec3{u(rng), u(rng), u(rng)};
    const Vec3 e{h(rng), h(rng), h(rng)};
    const PlacedShape box = place_box({c - e, c + e});
    const PlacedShape mesh = place(t, pos);
    const bool truth = octocd::exhaustive_contact(mesh, box, theta);
    ASSERT_EQ(truth, octocd::exhaustive_contact(box, mesh, theta));
    (truth ? hits : misses)++;
    for (const std::string& s : kConfigs) {
      MidphaseStats st;
      const MidphaseConfig cfg = MidphaseConfig::parse(s);
      ASSERT_EQ(octocd::confirm_contact(mesh, box, theta, cfg, st), truth) << s;
      ASSERT_EQ(octocd::confirm_contact(box, mesh, theta, cfg, st), truth) << s;
    }
  }
  EXPECT_GT(hits, 30);
  EXPECT_GT(misses, 30);
}

TEST(Midphase, BoxBoxIsAabbOverlap) {
  const PlacedShape a = place_box({{0, 0, 0}, {1, 1, 1}});
  const PlacedShape touching = place_box({{1, 0, 0}, {2, 1, 1}});
  const PlacedShape apart = place_box({{1.001f, 0, 0}, {2, 1, 1}});
  MidphaseStats st;
  const MidphaseConfig cfg;
  EXPECT_TRUE(octocd::confirm_contact(a, touching, 0.01f, cfg, st));
  EXPECT_TRUE(octocd::exhaustive_contact(a, touching, 0.01f));
  EXPECT_FALSE(octocd::confirm_contact(a, apart, 0.01f, cfg, st));
  EXPECT_FALSE(octocd::exhaustive_contact(a, apart, 0.01f));
}

TEST(Midphase, PlantedPairAtTheta) {
  // Two clouds far apart except one planted pair of vertices along x.
  std::mt19937 rng(14);
  Mesh ma = random_cloud(rng, 200, {0.1f, 0.1f, 0.1f});
  Mesh mb = random_cloud(rng, 200, {0.1f, 0.1f, 0.1f});
  ma.vertices.push_back({0.25f, 0.0f, 0.0f});   // sticks out on +x
  mb.vertices.push_back({-0.25f, 0.0f, 0.0f});  // sticks out on -x
  const MeshOctree ta = octocd::build_mesh_octree(ma, 3);
  const MeshOctree tb = octocd::build_mesh_octree(mb, 3);
  const float theta = 0.0625f;  // every number here is exact in binary
  const float xb = 0.5625f;     // world gap (-0.25 + 0.5625) - 0.25 = 0.0625 = theta exactly
  const PlacedShape a = place(ta, {0, 0, 0});
  const PlacedShape b = place(tb, {xb, 0, 0});
  ASSERT_EQ((-0.25f + xb) - 0.25f, theta);
  for (const std::string& s : kConfigs) {
    MidphaseStats st;
    EXPECT_FALSE(octocd::confirm_contact(a, b, theta, MidphaseConfig::parse(s), st)) << s;
  }
  EXPECT_FALSE(octocd::exhaustive_contact(a, b, theta));
  const float closer = std::nextafter(xb, 0.0f);
  const PlacedShape b2 = place(tb, {closer, 0, 0});
  EXPECT_TRUE(octocd::exhaustive_contact(a, b2, theta));
  for (const std::string& s : kConfigs) {
    MidphaseStats st;
    EXPECT_TRUE(octocd::confirm_contact(a, b2, theta, MidphaseConfig::parse(s), st)) << s;
    EXPECT_GT(st.vertex_tests, 0u);
    EXPECT_GT(st.box_pairs, 0u);
    EXPECT_GT(st.box_tests, 0u);
  }
  // Mesh-box: the planted vertex exactly theta from the box face -> no contact.
  const PlacedShape box = place_box({{0.25f + theta, -1, -1}, {1, 1, 1}});
  EXPECT_FALSE(octocd::exhaustive_contact(a, box, theta));
  const PlacedShape box2 = place_box({{std::nextafter(0.25f + theta, 0.0f), -1, -1}, {1, 1, 1}});
  EXPECT_TRUE(octocd::exhaustive_contact(a, box2, theta));
  for (const std::string& s : kConfigs) {
    MidphaseStats st;
    EXPECT_FALSE(octocd::confirm_contact(a, box, theta, MidphaseConfig::parse(s), st)) << s;
    EXPECT_TRUE(octocd::confirm_contact(a, box2, theta, MidphaseConfig::parse(s), st)) << s;
  }
}

TEST(Midphase, FarApartIsRejectedEarly) {
  std::mt19937 rng(15);
  const MeshOctree t = octocd::build_mesh_octree(random_cloud(rng, 100, {0.1f, 0.1f, 0.1f}), 2);
  MidphaseStats st;
  EXPECT_FALSE(octocd::confirm_contact(place(t, {0, 0, 0}), place(t, {1, 0, 0}), 0.01f, MidphaseConfig{}, st));
  EXPECT_EQ(st.box_tests, 0u);
  EXPECT_EQ(st.vertex_tests, 0u);
}

// The CUDA midphase (gpu/src/midphase_warp.cuh, context) puts the mesh first itself and calls
// hd::setup_pair on the ordered pair, so no placed shape is chosen by reference on the
// device; that is only right if the set-up of (box, mesh) is the set-up of (mesh, box) but
// for `swap`, field for field, and if the box-box / aabb-only answer does not depend on the
// order. Checked on random placements (hits, misses and early rejections) for every level
// list, with hd::clamped_level equal to the entries clamp_levels writes. The views are the
// ones confirm_contact hands to the shared header (midphase_views.hpp).
bool same_box(const Aabb& a, const Aabb& b) {
  return a.min.x == b.min.x && a.min.y == b.min.y && a.min.z == b.min.z && a.max.x == b.max.x &&
         a.max.y == b.max.y && a.max.z == b.max.z;
}

/// Every field of two set-ups but `swap` (levels up to k) equal; "" or the first difference.
std::string setup_difference(const hd::PairSetup& x, const hd::PairSetup& y) {
  if (x.kind != y.kind) return "kind";
  if (x.result != y.result) return "result";
  if (x.theta2 != y.theta2) return "theta2";
  if (x.d.x != y.d.x || x.d.y != y.d.y || x.d.z != y.d.z) return "d";
  if (x.margin != y.margin) return "margin";
  if (!same_box(x.box_local, y.box_local)) return "box_local";
  if (x.k != y.k) return "k";
  for (int i = 0; i < x.k; ++i)
    if (x.la[i] != y.la[i] || x.lb[i] != y.lb[i]) return "levels";
  return "";
}

TEST(Midphase, SetupOfTheOrderedPairIsTheSetup) {
  std::mt19937 rng(17);
  const MeshOctree ta = octocd::build_mesh_octree(random_cloud(rng, 300, {0.1f, 0.08f, 0.06f}), 3);
  const MeshOctree tb = octocd::build_mesh_octree(sphere_cloud(0.07f, 400), 2);
  std::uniform_real_distribution<float> u(-0.3f, 0.3f);
  std::uniform_real_distribution<float> h(0.01f, 0.15f);
  std::vector<std::string> configs = kConfigs;
  configs.push_back("aabb-only");
  int kinds[4] = {0, 0, 0, 0};
  for (int p = 0; p < 300; ++p) {
    const Vec3 pa{u(rng), u(rng), u(rng)};
    const Vec3 pb = pa + near_contact(rng, 0.2f, 0.3f, 1.6f);
    const Vec3 c = pa + Vec3{u(rng), u(rng), u(rng)};
    const Vec3 e{h(rng), h(rng), h(rng)};
    const hd::PlacedView ma = octocd::placed_view(place(ta, pa));
    const hd::PlacedView mb = octocd::placed_view(place(tb, pb));
    const hd::PlacedView box = octocd::placed_view(place_box({c - e, c + e}));
    const hd::PlacedView box2 = octocd::placed_view(place_box({pb - e, pb + e}));
    for (const std::string& cs : configs) {
      const MidphaseConfig cfg = cs == "aabb-only" ? [] {
        MidphaseConfig a;
        a.aabb_only = true;
        return a;
      }()
                                                   : MidphaseConfig::parse(cs);
      const hd::LevelList l = octocd::level_list(cfg);
      const float theta = 0.01f;
      // (box, mesh) is set up as (mesh, box) with swap; (mesh, box) has no swap.
      const hd::PairSetup bm = hd::setup_pair(box, ma, theta, l);
      const hd::PairSetup mbx = hd::setup_pair(ma, box, theta, l);
      EXPECT_EQ(setup_difference(bm, mbx), "") << cs << " placement " << p;
      EXPECT_EQ(mbx.swap, false);
      EXPECT_EQ(bm.swap, !cfg.aabb_only) << cs;  // aabb-only is decided before the order
      kinds[static_cast<int>(mbx.kind)]++;
      // Box-box: the AABB overlap, either order.
      const hd::PairSetup bb = hd::setup_pair(box, box2, theta, l);
      const hd::PairSetup bb2 = hd::setup_pair(box2, box, theta, l);
      EXPECT_EQ(setup_difference(bb, bb2), "") << cs;
      EXPECT_EQ(bb.result, octocd::overlaps(box.box, box2.box));
      // Mesh-mesh: never swapped.
      const hd::PairSetup mm = hd::setup_pair(ma, mb, theta, l);
      EXPECT_FALSE(mm.swap);
      kinds[static_cast<int>(mm.kind)]++;
      // The exhaustive oracle: either order, as the brute force over all vertices.
      bool truth = false;
      for (const Vec3& v : ta.vertices) truth = truth || octocd::distance2_point_aabb(v + pa, box.box) < theta * theta;
      EXPECT_EQ(hd::exhaustive_contact(box, ma, theta), truth);
      EXPECT_EQ(hd::exhaustive_contact(ma, box, theta), truth);
      // clamped_level: the entries clamp_levels writes.
      int out[hd::kMidphaseMaxLevels];
      const int k = hd::clamp_levels(l, ta.depth, out);
      for (int i = 0; i < k; ++i) EXPECT_EQ(hd::clamped_level(l, i, ta.depth), out[i]) << cs;
    }
  }
  EXPECT_GT(kinds[static_cast<int>(hd::PairKind::Decided)], 50) << "early rejections and aabb-only";
  EXPECT_GT(kinds[static_cast<int>(hd::PairKind::MeshBox)], 50);
  EXPECT_GT(kinds[static_cast<int>(hd::PairKind::MeshMesh)], 50);
}

}  // namespace

}  // namespace octocd_test_midphase
