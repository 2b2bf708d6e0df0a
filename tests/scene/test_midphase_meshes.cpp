// Midphase on real meshes (design.md sections 5.2-5.3): every level list confirms exactly the contacts of
// the exhaustive vertex test, on bunny-bunny, armadillo-bunny and dragon-dragon pairs at
// many random placements near contact. Needs the fetched datasets ($OCTOCD_DATA_DIR);
// skipped without them.
//
// The oracle here is exhaustive_contact run on candidate vertices only: a vertex of A can
// be closer than theta to a vertex of B only if it lies within theta of B's world AABB
// (and vice versa), so the vertices outside (AABB expanded by 1.01 theta + 1e-6) are
// dropped first. Over the candidates the test is still the full, unpruned vertex-pair
// test (same floats, same expression), and the dragon's 40k x 40k pairs stay affordable.

#include <gtest/gtest.h>

#include <cstdlib>
#include <fstream>
#include <random>
#include <string>
#include <vector>

#include "octocd/mesh.hpp"
#include "octocd/mesh_octree.hpp"
#include "octocd/midphase.hpp"

// This file's own names (its tests compile in unity batches with the folder's other files).
namespace octocd_test_midphase_meshes {

namespace {

using octocd::Aabb;
using octocd::Mesh;
using octocd::MeshOctree;
using octocd::MidphaseConfig;
using octocd::MidphaseStats;
using octocd::PlacedShape;
using octocd::Vec3;

std::string data_path(const std::string& name) {
  // $OCTOCD_DATA_DIR, else $OCTOCD_SOURCE_DIR/datasets/cache, else ./datasets/cache.
  const char* dir = std::getenv("OCTOCD_DATA_DIR");
  const char* src = std::getenv("OCTOCD_SOURCE_DIR");
  const std::string base = dir ? std::string(dir) : src ? std::string(src) + "/datasets/cache" : "datasets/cache";
  const std::string path = base + "/" + name;
  return std::ifstream(path).good() ? path : std::string();
}

Mesh load_scaled(const std::string& path, float scale) {
  Mesh m = octocd::load_mesh(path);
  octocd::normalize_mesh(m);
  octocd::scale_mesh(m, scale);
  return m;
}

PlacedShape place(const MeshOctree& t, Vec3 p) {
  PlacedShape s;
  s.octree = &t;
  s.position = p;
  s.box = octocd::translated(t.bounds, p);
  return s;
}

/// Local vertices of `t` at `pos` lying within `margin` of the world box `other`.
Mesh candidates(const MeshOctree& t, Vec3 pos, const Aabb& other, float margin) {
  Mesh m;
  const Aabb e = octocd::expanded(other, margin);
  for (const Vec3& v : t.vertices) {
    const Vec3 w = v + pos;
    if (octocd::contains(e, Aabb{w, w})) m.vertices.push_back(v);
  }
  return m;
}

/// exhaustive_contact over the candidate vertices (see the file comment).
bool oracle(const MeshOctree& ta, Vec3 pa, const MeshOctree& tb, Vec3 pb, float theta) {
  const Aabb wa = octocd::translated(ta.bounds, pa);
  const Aabb wb = octocd::translated(tb.bounds, pb);
  const float margin = 1.01f * theta + 1e-6f;
  const Mesh ca = candidates(ta, pa, wb, margin);
  const Mesh cb = candidates(tb, pb, wa, margin);
  if (ca.vertices.empty() || cb.vertices.empty()) return false;
  const MeshOctree oa = octocd::build_mesh_octree(ca, 0);
  const MeshOctree ob = octocd::build_mesh_octree(cb, 0);
  return octocd::exhaustive_contact(place(oa, pa), place(ob, pb), theta);
}

void check_meshes(const std::string& file_a, const std::string& file_b, int placements, std::uint32_t seed) {
  const std::string pa_path = data_path(file_a);
  const std::string pb_path = data_path(file_b);
  if (pa_path.empty() || pb_path.empty()) GTEST_SKIP() << file_a << " or " << file_b << " not in $OCTOCD_DATA_DIR";
  const Mesh ma = load_scaled(pa_path, 0.2f);
  const Mesh mb = load_scaled(pb_path, 0.2f);
  const float theta = std::max(octocd::mean_edge_length(ma), octocd::mean_edge_length(mb));
  ASSERT_GT(theta, 0.0f);
  const MeshOctree ta = octocd::build_mesh_octree(ma, 3);
  const MeshOctree tb = octocd::build_mesh_octree(mb, 3);
  ASSERT_EQ(ta.validate(), "");
  ASSERT_EQ(tb.validate(), "");
  const MeshOctree ta_auto = octocd::build_mesh_octree(ma, -1);
  ASSERT_EQ(ta_auto.validate(), "");

  const std::vector<std::string> configs = {"0", "1", "2", "1,2", "0,1,2", "0,2", "3", "0,1,2,3"};
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> base(-3.0f, 3.0f);
  std::normal_distribution<float> g(0.0f, 1.0f);
  std::uniform_real_distribution<float> dist(0.35f, 1.0f);
  const float reach = 0.5f * (octocd::length(ta.bounds.max - ta.bounds.min) +
                              octocd::length(tb.bounds.max - tb.bounds.min));
  int hits = 0;
  int misses = 0;
  for (int p = 0; p < placements; ++p) {
    const Vec3 pa{base(rng), base(rng), base(rng)};
    Vec3 d{g(rng), g(rng), g(rng)};
    d = (reach * dist(rng) / octocd::length(d)) * d;
    const Vec3 pb = pa + d;
    const bool truth = oracle(ta, pa, tb, pb, theta);
    (truth ? hits : misses)++;
    const PlacedShape a = place(ta, pa);
    const PlacedShape b = place(tb, pb);
    for (const std::string& c : configs) {
      MidphaseStats st;
      ASSERT_EQ(octocd::confirm_contact(a, b, theta, MidphaseConfig::parse(c), st), truth)
          << file_a << "-" << file_b << " config " << c << " placement " << p;
    }
    MidphaseStats st;
    ASSERT_EQ(octocd::confirm_contact(place(ta_auto, pa), b, theta, MidphaseConfig::parse("1,2"), st), truth);
  }
  EXPECT_GT(hits, placements / 20);
  EXPECT_GT(misses, placements / 20);
}

TEST(MidphaseMeshes, BunnyBunny) { check_meshes("bunny.obj", "bunny.obj", 300, 1); }
TEST(MidphaseMeshes, ArmadilloBunny) { check_meshes("armadillo.off", "bunny.obj", 150, 2); }
TEST(MidphaseMeshes, DragonDragon) { check_meshes("dragon.off", "dragon.off", 60, 3); }

TEST(MidphaseMeshes, BunnyExhaustiveOracleAgrees) {
  // The candidate-filtered oracle equals the plain exhaustive test (checked on the bunny,
  // where the plain one is cheap).
  const std::string path = data_path("bunny.obj");
  if (path.empty()) GTEST_SKIP() << "bunny.obj not in $OCTOCD_DATA_DIR";
  const Mesh m = load_scaled(path, 0.2f);
  const float theta = octocd::mean_edge_length(m);
  const MeshOctree t = octocd::build_mesh_octree(m, 2);
  std::mt19937 rng(4);
  std::normal_distribution<float> g(0.0f, 1.0f);
  std::uniform_real_distribution<float> dist(0.05f, 0.25f);
  for (int p = 0; p < 40; ++p) {
    Vec3 d{g(rng), g(rng), g(rng)};
    d = (dist(rng) / octocd::length(d)) * d;
    EXPECT_EQ(oracle(t, {0, 0, 0}, t, d, theta), octocd::exhaustive_contact(place(t, {0, 0, 0}), place(t, d), theta));
  }
}

}  // namespace

}  // namespace octocd_test_midphase_meshes
