// Scene files (design.md section 3): parsing, validation, mesh resolution, generators.

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <set>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "octocd/broadphase.hpp"
#include "octocd/error.hpp"
#include "octocd/engine.hpp"
#include "octocd/math.hpp"
#include "octocd/mesh.hpp"
#include "octocd/scene.hpp"

// This file's own names (its tests compile in unity batches with the folder's other files).
namespace octocd_test_scene {

namespace fs = std::filesystem;
using nlohmann::json;
using namespace octocd;

namespace {

/// The source tree: $OCTOCD_SOURCE_DIR (set by ctest) or two folders above this file.
fs::path source_dir() {
  if (const char* env = std::getenv("OCTOCD_SOURCE_DIR"); env != nullptr && *env != '\0') return env;
  return fs::path(__FILE__).parent_path().parent_path().parent_path();
}

/// A fresh empty temporary folder for one test.
fs::path temp_dir(const std::string& name) {
  const fs::path d = fs::temp_directory_path() / ("octocd_test_scene_" + name + "_" +
                                                  std::to_string(::testing::UnitTest::GetInstance()->random_seed()));
  fs::remove_all(d);
  fs::create_directories(d);
  return d;
}

void write_file(const fs::path& p, const std::string& text) {
  std::ofstream out(p, std::ios::binary);
  out << text;
}

/// A valid scene with one box group and nothing else.
json minimal() {
  return json::parse(R"({
    "name": "mini",
    "domain": {"min": [-1, 0, -1], "max": [1, 2, 1]},
    "groups": [{"shape": {"box": [0.1, 0.1, 0.1]}, "count": 2}]
  })");
}

/// Expects parse_scene(j) to throw InputError whose message holds the origin, `key` and
/// "allowed:"; returns the message.
std::string expect_error(const json& j, const std::string& key) {
  try {
    parse_scene(j.dump(), "test.json");
  } catch (const InputError& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find("test.json: "), std::string::npos) << msg;
    EXPECT_NE(msg.find(key), std::string::npos) << "key '" << key << "' not in: " << msg;
    EXPECT_NE(msg.find("allowed:"), std::string::npos) << msg;
    return msg;
  }
  ADD_FAILURE() << "no InputError for key " << key << " in " << j.dump();
  return "";
}

/// True when the interiors of two boxes intersect by more than float rounding (touching
/// faces do not count).
bool interiors_intersect(const Aabb& a, const Aabb& b) {
  const Penetration p = penetration(a, b, 1e-6f);
  return p.hit && p.depth > 1e-6f;
}

GroupSpec box_group(int count, Vec3 lo, Vec3 hi) {
  GroupSpec g;
  g.name = "g";
  g.count = count;
  g.layout.region = {lo, hi};
  g.layout.region_from_domain = false;
  return g;
}

const Aabb kBox01{{-0.1f, -0.1f, -0.1f}, {0.1f, 0.1f, 0.1f}};

}  // namespace

TEST(Scene, MinimalSceneGetsTable1Defaults) {
  const Scene s = parse_scene(minimal().dump(), "mini.json");
  EXPECT_EQ(s.name, "mini");
  EXPECT_EQ(s.path, "mini.json");
  EXPECT_EQ(s.json, minimal().dump());
  EXPECT_EQ(s.domain.min, (Vec3{-1, 0, -1}));
  EXPECT_EQ(s.domain.max, (Vec3{1, 2, 1}));
  EXPECT_EQ(s.gravity, (Vec3{0.0f, -9.81f, 0.0f}));
  EXPECT_FLOAT_EQ(s.dt, 0.001f);
  EXPECT_EQ(s.frames, 1000);
  EXPECT_EQ(s.walls, Walls::Floor);
  EXPECT_FLOAT_EQ(s.wall_thickness, 0.1f);
  // Paper Table 1.
  EXPECT_FLOAT_EQ(s.response.slop, 0.001f);
  EXPECT_FLOAT_EQ(s.response.beta, 1.0f);
  EXPECT_FLOAT_EQ(s.response.alpha, 1.0f);
  EXPECT_FLOAT_EQ(s.response.restitution, 0.5f);
  EXPECT_FLOAT_EQ(s.response.restitution_threshold, 0.3f);
  EXPECT_FLOAT_EQ(s.response.impulse_floor, 0.01f);
  EXPECT_FLOAT_EQ(s.response.mu_static, 0.6f);
  EXPECT_FLOAT_EQ(s.response.mu_kinetic, 0.5f);
  EXPECT_FLOAT_EQ(s.response.max_velocity, 50.0f);
  EXPECT_FLOAT_EQ(s.response.epsilon, 1e-6f);
  EXPECT_FALSE(s.theta.has_value());
  EXPECT_EQ(s.broadphase.name, "octree");
  EXPECT_EQ(s.broadphase.octree_depth, 2);
  EXPECT_FLOAT_EQ(s.broadphase.cell_size, 0.25f);
  EXPECT_FALSE(s.midphase.aabb_only);
  EXPECT_EQ(s.midphase.levels, (std::vector<int>{1, 2}));
  EXPECT_EQ(s.mesh_octree_depth, 2);
  ASSERT_EQ(s.groups.size(), 1u);
  const GroupSpec& g = s.groups[0];
  EXPECT_EQ(g.name, "group0");
  EXPECT_EQ(g.index, 0);
  EXPECT_EQ(g.count, 2);
  EXPECT_FLOAT_EQ(g.mass, 1.0f);
  EXPECT_EQ(g.shape.kind, ShapeSpec::Kind::Box);
  EXPECT_EQ(g.shape.half_extents, (Vec3{0.1f, 0.1f, 0.1f}));
  EXPECT_EQ(g.layout.kind, LayoutSpec::Kind::Grid);
  EXPECT_TRUE(g.layout.region_from_domain);
  EXPECT_EQ(g.velocity.kind, VelocitySpec::Kind::Fixed);
  EXPECT_EQ(g.velocity.value, (Vec3{0, 0, 0}));
  EXPECT_TRUE(g.positions.empty());
  EXPECT_EQ(body_count(s), 2u);
}

TEST(Scene, ExplicitValuesAreRead) {
  json j = minimal();
  j["gravity"] = {0, 0, 0};
  j["dt"] = 0.002;
  j["frames"] = 7;
  j["walls"] = "closed-box";
  j["theta"] = 0.004;
  j["response"] = {{"beta", 0.8}, {"restitution", 1.0}, {"mu_kinetic", 0.0}};
  j["broadphase"] = {{"name", "spatial-hash"}, {"depth", "auto"}, {"cell_size", 0.5}};
  j["midphase"] = {{"levels", json::array({0, 1, 2})}, {"depth", "auto"}};
  j["groups"][0]["velocity"] = {{"type", "random"}, {"max", 2.0}, {"seed", 9}};
  j["groups"][0]["layout"] = {{"type", "random"}, {"min", {0, 1, 0}}, {"max", {0.5, 1.5, 0.5}}, {"seed", 4}};
  j["groups"].push_back({{"name", "ball"}, {"shape", {{"icosphere", {{"radius", 0.2}}}}}, {"count", 1}, {"mass", 0}});
  const Scene s = parse_scene(j.dump(), "x.json");
  EXPECT_EQ(s.gravity, (Vec3{0, 0, 0}));
  EXPECT_FLOAT_EQ(s.dt, 0.002f);
  EXPECT_EQ(s.frames, 7);
  EXPECT_EQ(s.walls, Walls::ClosedBox);
  ASSERT_TRUE(s.theta.has_value());
  EXPECT_FLOAT_EQ(*s.theta, 0.004f);
  EXPECT_FLOAT_EQ(s.response.beta, 0.8f);
  EXPECT_FLOAT_EQ(s.response.restitution, 1.0f);
  EXPECT_FLOAT_EQ(s.response.mu_kinetic, 0.0f);
  EXPECT_FLOAT_EQ(s.response.alpha, 1.0f);
  EXPECT_EQ(s.broadphase.name, "spatial-hash");
  EXPECT_EQ(s.broadphase.octree_depth, -1);
  EXPECT_FLOAT_EQ(s.broadphase.cell_size, 0.5f);
  EXPECT_EQ(s.midphase.levels, (std::vector<int>{0, 1, 2}));
  EXPECT_EQ(s.mesh_octree_depth, -1);
  EXPECT_EQ(s.groups[0].velocity.kind, VelocitySpec::Kind::Random);
  EXPECT_FLOAT_EQ(s.groups[0].velocity.max_speed, 2.0f);
  EXPECT_EQ(s.groups[0].velocity.seed, 9u);
  EXPECT_EQ(s.groups[0].layout.kind, LayoutSpec::Kind::Random);
  EXPECT_FALSE(s.groups[0].layout.region_from_domain);
  EXPECT_EQ(s.groups[0].layout.region.min, (Vec3{0, 1, 0}));
  EXPECT_EQ(s.groups[0].layout.seed, 4u);
  EXPECT_EQ(s.groups[1].name, "ball");
  EXPECT_EQ(s.groups[1].shape.kind, ShapeSpec::Kind::Icosphere);
  EXPECT_FLOAT_EQ(s.groups[1].shape.radius, 0.2f);
  EXPECT_EQ(s.groups[1].shape.subdivisions, 2);
  EXPECT_FLOAT_EQ(s.groups[1].mass, 0.0f);

  j["midphase"] = {{"levels", "aabb-only"}, {"depth", 0}};
  const Scene a = parse_scene(j.dump(), "x.json");
  EXPECT_TRUE(a.midphase.aabb_only);
  EXPECT_EQ(a.mesh_octree_depth, 0);
}

TEST(Scene, UnknownKeys) {
  json j = minimal();
  j["gravty"] = {0, -9.81, 0};
  const std::string msg = expect_error(j, "gravty: unknown key");
  EXPECT_NE(msg.find("gravity"), std::string::npos) << "allowed keys listed: " << msg;

  j = minimal();
  j["groups"][0]["shape"]["colour"] = "red";
  expect_error(j, "groups[0].shape.colour: unknown key");

  j = minimal();
  j["response"] = {{"betta", 0.5}};
  expect_error(j, "response.betta");

  j = minimal();
  j["groups"][0]["layout"] = {{"type", "random"}, {"jitter", 0.1}};
  expect_error(j, "groups[0].layout.jitter");
}

TEST(Scene, WrongTypes) {
  json j = minimal();
  j["dt"] = "0.001";
  expect_error(j, "dt: expected a number");
  j = minimal();
  j["groups"][0]["count"] = 2.5;
  expect_error(j, "groups[0].count: expected an integer");
  j = minimal();
  j["groups"][0]["count"] = true;
  expect_error(j, "groups[0].count");
  j = minimal();
  j["gravity"] = {0, -9.81};
  expect_error(j, "gravity");
  j = minimal();
  j["groups"] = json::object();
  expect_error(j, "groups");
  j = minimal();
  j["name"] = 3;
  expect_error(j, "name: expected a string");
  j = minimal();
  j["theta"] = "big";
  expect_error(j, "theta");
}

TEST(Scene, ResponseRanges) {
  struct Case {
    const char* key;
    double value;
  };
  const Case bad[] = {{"beta", 0.0},          {"beta", 1.5},        {"alpha", 0.0},
                      {"alpha", -0.5},        {"slop", 0.0},        {"slop", -0.001},
                      {"impulse_floor", -0.01}, {"restitution", 1.5}, {"mu_static", -1.0},
                      {"epsilon", 0.0},       {"max_velocity", 0.0}};
  for (const Case& c : bad) {
    json j = minimal();
    j["response"] = {{c.key, c.value}};
    expect_error(j, std::string("response.") + c.key);
  }
  // Boundaries that are allowed.
  json j = minimal();
  j["response"] = {{"beta", 1.0}, {"alpha", 1.0}, {"impulse_floor", 0.0}, {"restitution", 0.0}};
  EXPECT_NO_THROW(parse_scene(j.dump(), "ok.json"));
}

// design.md section 6: response.overlap and response.iterations.
TEST(Scene, OverlapAndIterations) {
  json j = minimal();
  j["response"] = {{"overlap", "paper"}, {"iterations", 8}};
  const Scene s = parse_scene(j.dump(), "ok.json");
  EXPECT_EQ(s.response.overlap, OverlapMode::Paper);
  EXPECT_EQ(s.response.iterations, 8);
  EXPECT_EQ(parse_scene(minimal().dump(), "ok.json").response.overlap, OverlapMode::Separating);
  EXPECT_EQ(parse_scene(minimal().dump(), "ok.json").response.iterations, 1);
  j = minimal();
  j["response"] = {{"overlap", "loose"}};
  expect_error(j, "response.overlap: unknown value \"loose\"; allowed: \"separating\" (default) or \"paper\"");
  j["response"] = {{"overlap", 1}};
  expect_error(j, "response.overlap");
  for (const json& bad : {json(0), json(1001), json(1.5), json("8"), json(-3)}) {
    j = minimal();
    j["response"] = {{"iterations", bad}};
    expect_error(j, "response.iterations");
    try {
      parse_scene(j.dump(), "bad.json");
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find("integer in [1, 1000]"), std::string::npos) << e.what();
    }
  }
  j = minimal();
  j["response"] = {{"iterations", 1000}};
  EXPECT_NO_THROW(parse_scene(j.dump(), "ok.json"));
}

TEST(Scene, NonFiniteNumbersAreRejected) {
  // JSON has no NaN or infinity, but 1e400 parses as +inf.
  const std::string text =
      R"({"name": "x", "domain": {"min": [-1, 0, -1], "max": [1, 2, 1]},
          "response": {"max_velocity": 1e400},
          "groups": [{"shape": {"box": [0.1, 0.1, 0.1]}, "count": 1}]})";
  try {
    parse_scene(text, "inf.json");
    FAIL() << "1e400 accepted";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("response.max_velocity"), std::string::npos) << e.what();
  }
  // Finite as double but not as float32.
  json j = minimal();
  j["gravity"] = {0, -1e39, 0};
  expect_error(j, "gravity[1]");
}

TEST(Scene, CountsDomainAndTime) {
  json j = minimal();
  j["groups"][0]["count"] = 0;
  expect_error(j, "groups[0].count");
  j = minimal();
  j["groups"][0]["count"] = -3;
  expect_error(j, "groups[0].count");
  j = minimal();
  j["domain"]["min"] = {-1, 2, -1};
  expect_error(j, "domain");
  j = minimal();
  j["domain"]["max"][0] = -2;
  expect_error(j, "domain");
  j = minimal();
  j["dt"] = 0;
  expect_error(j, "dt");
  j = minimal();
  j["dt"] = 0.2;
  expect_error(j, "dt");
  j = minimal();
  j["frames"] = 0;
  expect_error(j, "frames");
  j = minimal();
  j["groups"] = json::array();
  expect_error(j, "groups");
  j = minimal();
  j.erase("domain");
  expect_error(j, "domain: missing");
  j = minimal();
  j["groups"][0].erase("count");
  expect_error(j, "groups[0].count: missing");
  j = minimal();
  j["walls"] = "roof";
  expect_error(j, "walls");
  j = minimal();
  j["broadphase"] = {{"depth", 11}};
  expect_error(j, "broadphase.depth");
  j = minimal();
  j["groups"][0]["shape"]["box"][2] = 0;
  expect_error(j, "groups[0].shape.box[2]");
  j = minimal();
  j["groups"][0]["shape"]["icosphere"] = {{"radius", 1}};
  expect_error(j, "groups[0].shape");
  j = minimal();
  j["groups"][0]["layout"] = {{"type", "grid"}, {"min", {0, 0, 0}}, {"max", {1, -1, 1}}};
  expect_error(j, "groups[0].layout");
  j = minimal();
  j["groups"][0]["mass"] = -1;
  expect_error(j, "groups[0].mass");
}

TEST(Scene, DuplicateNamesAndKeys) {
  json j = minimal();
  j["groups"][0]["name"] = "a";
  j["groups"].push_back(j["groups"][0]);
  expect_error(j, "groups[1].name");
  // The default name "group1" collides with an explicit one.
  j = minimal();
  j["groups"][0]["name"] = "group1";
  j["groups"].push_back({{"shape", {{"box", {0.1, 0.1, 0.1}}}}, {"count", 1}});
  expect_error(j, "groups[1].name");
  // Duplicated JSON keys (nlohmann would keep the last silently).
  const std::string text =
      R"({"name": "x", "dt": 0.001, "dt": 0.002, "domain": {"min": [-1, 0, -1], "max": [1, 2, 1]},
          "groups": [{"shape": {"box": [0.1, 0.1, 0.1]}, "count": 1}]})";
  try {
    parse_scene(text, "dup.json");
    FAIL() << "duplicate key accepted";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("dup.json: dt: duplicate key"), std::string::npos) << e.what();
  }
}

TEST(Scene, PositionsLengthMustMatchCount) {
  json j = minimal();
  j["groups"][0]["positions"] = {{0, 1, 0}};
  expect_error(j, "groups[0].positions");
  j["groups"][0]["positions"] = {{0, 1, 0}, {0, 1.5, 0}};
  const Scene s = parse_scene(j.dump(), "p.json");
  ASSERT_EQ(s.groups[0].positions.size(), 2u);
  EXPECT_EQ(group_positions(s.groups[0], kBox01, "p.json")[1], (Vec3{0, 1.5f, 0}));
}

TEST(Scene, MidphaseLevels) {
  json j = minimal();
  j["midphase"] = {{"levels", "2,1"}};
  try {
    parse_scene(j.dump(), "m.json");
    FAIL() << "\"2,1\" accepted";
  } catch (const InputError& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find("m.json: "), std::string::npos) << msg;
    EXPECT_NE(msg.find("midphase.levels"), std::string::npos) << msg;
  }
  j["midphase"] = {{"levels", json::array({2, 1})}};
  EXPECT_THROW(parse_scene(j.dump(), "m.json"), InputError);
  // Octree depth shallower than the deepest level.
  j["midphase"] = {{"levels", "1,2"}, {"depth", 1}};
  expect_error(j, "midphase.depth");
}

TEST(Scene, InvalidJsonAndFiles) {
  try {
    parse_scene("{\"name\": \"x\",, }", "bad.json");
    FAIL();
  } catch (const InputError& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find("bad.json: "), std::string::npos) << msg;
    EXPECT_NE(msg.find("invalid JSON at byte 14"), std::string::npos) << msg;
  }
  EXPECT_THROW(parse_scene("[1, 2]", "arr.json"), InputError);
  try {
    load_scene("/nonexistent/octocd/scene.json");
    FAIL();
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("/nonexistent/octocd/scene.json"), std::string::npos) << e.what();
  }
  const fs::path dir = temp_dir("files");
  write_file(dir / "s.json", minimal().dump(2));
  const Scene s = load_scene((dir / "s.json").string());
  EXPECT_EQ(s.path, (dir / "s.json").string());
  EXPECT_EQ(s.json, minimal().dump(2));
  fs::remove_all(dir);
}

TEST(Scene, MeshResolution) {
  const fs::path dir = temp_dir("mesh");
  const fs::path data = dir / "data";
  fs::create_directories(data);
  fs::create_directories(dir / "scenes" / "meshes");
  write_file(data / "thing.off", "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n");
  write_file(data / "hollow.obj", "");
  write_file(dir / "scenes" / "meshes" / "local.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");

  json j = minimal();
  j["groups"][0]["shape"] = {{"mesh", "thing"}, {"scale", 0.2}};
  write_file(dir / "scenes" / "a.json", j.dump());
  Scene s = load_scene((dir / "scenes" / "a.json").string(), data.string());
  EXPECT_EQ(s.groups[0].shape.kind, ShapeSpec::Kind::Mesh);
  EXPECT_FLOAT_EQ(s.groups[0].shape.scale, 0.2f);
  EXPECT_EQ(fs::path(s.groups[0].shape.mesh_path), data / "thing.off");

  // A path relative to the scene's folder.
  j["groups"][0]["shape"] = {{"mesh", "meshes/local.obj"}};
  write_file(dir / "scenes" / "b.json", j.dump());
  s = load_scene((dir / "scenes" / "b.json").string(), data.string());
  EXPECT_TRUE(fs::equivalent(s.groups[0].shape.mesh_path, dir / "scenes" / "meshes" / "local.obj"));

  // Default data dir: <scene folder>/../cache (when $OCTOCD_DATA_DIR is unset).
  if (std::getenv("OCTOCD_DATA_DIR") == nullptr) {
    fs::create_directories(dir / "cache");
    write_file(dir / "cache" / "thing.ply", "ply\n");
    j["groups"][0]["shape"] = {{"mesh", "thing"}};
    write_file(dir / "scenes" / "c.json", j.dump());
    s = load_scene((dir / "scenes" / "c.json").string());
    EXPECT_TRUE(fs::equivalent(s.groups[0].shape.mesh_path, dir / "cache" / "thing.ply"));
  }

  // Missing mesh.
  j["groups"][0]["shape"] = {{"mesh", "no-such-mesh"}};
  write_file(dir / "scenes" / "d.json", j.dump());
  try {
    load_scene((dir / "scenes" / "d.json").string(), data.string());
    FAIL() << "missing mesh accepted";
  } catch (const InputError& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find("groups[0].shape.mesh"), std::string::npos) << msg;
    // Not a dataset name: fetching the datasets would not help (issue 12).
    EXPECT_NE(msg.find("not a shipped dataset"), std::string::npos) << msg;
    EXPECT_EQ(msg.find("fetch.sh"), std::string::npos) << msg;
    EXPECT_NE(msg.find((data / "no-such-mesh.obj").string()), std::string::npos) << msg;
    EXPECT_NE(msg.find((data / "no-such-mesh.ply").string()), std::string::npos) << msg;
  }

  // Empty mesh file.
  j["groups"].push_back({{"shape", {{"mesh", "hollow"}}}, {"count", 1}});
  j["groups"][0]["shape"] = {{"mesh", "thing"}};
  write_file(dir / "scenes" / "e.json", j.dump());
  try {
    load_scene((dir / "scenes" / "e.json").string(), data.string());
    FAIL() << "empty mesh accepted";
  } catch (const InputError& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find("groups[1].shape.mesh"), std::string::npos) << msg;
    EXPECT_NE(msg.find("empty"), std::string::npos) << msg;
  }

  // scale is a mesh option only.
  json k = minimal();
  k["groups"][0]["shape"]["scale"] = 2;
  expect_error(k, "groups[0].shape.scale");
  fs::remove_all(dir);
}

TEST(SceneGenerators, SplitMix64MatchesReference) {
  SplitMix64 r(0);  // reference outputs of SplitMix64 seeded with 0
  EXPECT_EQ(r.next(), 0xE220A8397B1DCDAFULL);
  EXPECT_EQ(r.next(), 0x6E789E6AA1B965F4ULL);
  EXPECT_EQ(r.next(), 0x06C45D188009454FULL);
  SplitMix64 u(1);
  EXPECT_EQ(u.unit(), 0.5665615200996399f);
  EXPECT_EQ(u.unit(), 0.7457817196846008f);
  EXPECT_EQ(u.unit(), 0.9710026979446411f);
}

TEST(SceneGenerators, GridIsDeterministicAndPinned) {
  GroupSpec g = box_group(27, {0, 0, 0}, {1, 1, 1});
  g.layout.spacing = 0.25f;
  g.layout.jitter = 0.02f;
  g.layout.seed = 7;
  const auto a = group_positions(g, kBox01, "t.json");
  const auto b = group_positions(g, kBox01, "t.json");
  ASSERT_EQ(a.size(), 27u);
  for (std::size_t i = 0; i < a.size(); ++i) EXPECT_EQ(a[i], b[i]) << i;
  // Values from an independent implementation of the documented formulas.
  EXPECT_EQ(a[0], (Vec3{-0.004406812135130167f, -0.019328469410538673f, 0.01603042520582676f}));
  EXPECT_EQ(a[1], (Vec3{0.2533172070980072f, -0.0019023250788450241f, -0.010022739879786968f}));
  g.layout.seed = 8;
  EXPECT_FALSE(group_positions(g, kBox01, "t.json")[0] == a[0]);
}

TEST(SceneGenerators, GridFillsRegionLayerByLayer) {
  // 5 x 5 x 5 slots at spacing 0.25 in [0, 1]^3; 30 bodies: one full layer and 5 more.
  GroupSpec g = box_group(30, {0, 0, 0}, {1, 1, 1});
  g.layout.spacing = 0.25f;
  const auto p = group_positions(g, kBox01, "t.json");
  ASSERT_EQ(p.size(), 30u);
  EXPECT_EQ(p[0], (Vec3{0, 0, 0}));
  EXPECT_EQ(p[1], (Vec3{0.25f, 0, 0}));   // x fastest
  EXPECT_EQ(p[5], (Vec3{0, 0, 0.25f}));   // then z
  EXPECT_EQ(p[25], (Vec3{0, 0.25f, 0}));  // then y: the second layer
  for (std::size_t i = 0; i < p.size(); ++i) {
    EXPECT_TRUE(contains(g.layout.region, Aabb{p[i], p[i]})) << i;
    EXPECT_EQ(p[i].y, i < 25 ? 0.0f : 0.25f) << i;
    for (std::size_t k = 0; k < i; ++k) {
      EXPECT_FALSE(overlaps(translated(kBox01, p[i]), translated(kBox01, p[k]))) << i << " " << k;
    }
  }
  // Spacing equal to the body size: faces touch, interiors never intersect.
  g.layout.spacing = 0.2f;
  g.count = 100;
  const auto q = group_positions(g, kBox01, "t.json");
  for (std::size_t i = 0; i < q.size(); ++i)
    for (std::size_t k = 0; k < i; ++k)
      EXPECT_FALSE(interiors_intersect(translated(kBox01, q[i]), translated(kBox01, q[k]))) << i << " " << k;
  // Auto spacing: 1.1 x the largest side.
  g.layout.spacing = 0.0f;
  g.count = 2;
  const auto r = group_positions(g, kBox01, "t.json");
  EXPECT_FLOAT_EQ(r[1].x - r[0].x, 0.22f);
}

TEST(SceneGenerators, GridCapacityError) {
  GroupSpec g = box_group(126, {0, 0, 0}, {1, 1, 1});
  g.index = 3;
  g.layout.spacing = 0.25f;
  try {
    group_positions(g, kBox01, "cap.json");
    FAIL() << "126 bodies placed in 125 slots";
  } catch (const InputError& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find("cap.json: groups[3].layout"), std::string::npos) << msg;
    EXPECT_NE(msg.find("holds only 125"), std::string::npos) << msg;
  }
  g.count = 125;
  EXPECT_EQ(group_positions(g, kBox01, "cap.json").size(), 125u);
}

TEST(SceneGenerators, DefaultRegionKeepsBodiesInsideDomain) {
  const Scene s = parse_scene(minimal().dump(), "mini.json");
  GroupSpec g = s.groups[0];
  g.count = 30;
  const auto p = group_positions(g, kBox01, "mini.json");
  for (const Vec3& x : p) EXPECT_TRUE(contains(s.domain, translated(kBox01, x)));
  EXPECT_EQ(p[0], (Vec3{-0.9f, 0.1f, -0.9f}));
}

TEST(SceneGenerators, RandomLayoutDoesNotOverlap) {
  GroupSpec g = box_group(60, {-1, -1, -1}, {1, 1, 1});
  g.layout.kind = LayoutSpec::Kind::Random;
  g.layout.seed = 42;
  const auto p = group_positions(g, kBox01, "r.json");
  ASSERT_EQ(p.size(), 60u);
  EXPECT_EQ(p, group_positions(g, kBox01, "r.json"));
  for (std::size_t i = 0; i < p.size(); ++i) {
    EXPECT_TRUE(contains(g.layout.region, Aabb{p[i], p[i]})) << i;
    for (std::size_t k = 0; k < i; ++k)
      EXPECT_FALSE(overlaps(translated(kBox01, p[i]), translated(kBox01, p[k]))) << i << " " << k;
  }
  // Nine boxes of side 0.2 cannot lie apart with centres in a 0.1 m cube.
  GroupSpec tight = box_group(9, {0, 0, 0}, {0.1f, 0.1f, 0.1f});
  tight.layout.kind = LayoutSpec::Kind::Random;
  try {
    group_positions(tight, kBox01, "r.json");
    FAIL();
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("groups[0].layout: region too small"), std::string::npos) << e.what();
  }
}

TEST(SceneGenerators, RandomLayoutIsTheBruteForceRejectionAndAvoidsEarlierGroups) {
  // Oracle: the O(n^2) rejection sampler of the doc comment (same stream, every placed box
  // tested). The binned generator must give the same bits, with and without bodies of an
  // earlier group (placed_before, some outside the region and larger than the new boxes).
  auto brute = [](const GroupSpec& g, const Aabb& local, std::vector<Aabb> placed) {
    SplitMix64 rng(g.layout.seed);
    std::vector<Vec3> out;
    for (int k = 0; k < g.count; ++k) {
      for (int t = 0; t < 1000; ++t) {
        Vec3 p;
        for (int a = 0; a < 3; ++a) p[a] = rng.uniform(g.layout.region.min[a], g.layout.region.max[a]);
        const Aabb box = translated(local, p);
        if (std::none_of(placed.begin(), placed.end(), [&](const Aabb& b) { return overlaps(box, b); })) {
          placed.push_back(box);
          out.push_back(p);
          break;
        }
      }
    }
    return out;
  };
  GroupSpec large = box_group(100, {-1, -1, -1}, {1, 1, 1});
  large.layout.kind = LayoutSpec::Kind::Random;
  large.layout.seed = 5;
  const Aabb big{{-0.12f, -0.12f, -0.12f}, {0.12f, 0.12f, 0.12f}};
  const Aabb kSmall{{-0.04f, -0.04f, -0.04f}, {0.04f, 0.04f, 0.04f}};
  const auto pl = group_positions(large, big, "r.json");
  ASSERT_EQ(pl, brute(large, big, {}));
  std::vector<Aabb> before;
  for (const Vec3& x : pl) before.push_back(translated(big, x));
  before.push_back(translated(big, Vec3{1.1f, 0.0f, 0.0f}));   // outside the small group's region
  before.push_back(translated(big, Vec3{-40.0f, 3.0f, 0.0f}));  // far outside
  GroupSpec small = box_group(300, {-1, -1, -1}, {1, 1, 1});
  small.layout.kind = LayoutSpec::Kind::Random;
  small.layout.seed = 6;
  const auto ps = group_positions(small, kSmall, "r.json", before);
  ASSERT_EQ(ps.size(), 300u);
  EXPECT_EQ(ps, brute(small, kSmall, before));
  for (std::size_t i = 0; i < ps.size(); ++i)
    for (const Aabb& b : before) ASSERT_FALSE(overlaps(translated(kSmall, ps[i]), b)) << i;
  // Without `placed_before` the small boxes land on the large ones (the oracle is not vacuous).
  const auto alone = group_positions(small, kSmall, "r.json");
  EXPECT_TRUE(std::any_of(alone.begin(), alone.end(), [&](const Vec3& x) {
    return std::any_of(before.begin(), before.end(), [&](const Aabb& b) { return overlaps(translated(kSmall, x), b); });
  }));
  // The grid layout ignores placed_before.
  GroupSpec grid = box_group(27, {-1, -1, -1}, {1, 1, 1});
  EXPECT_EQ(group_positions(grid, kSmall, "g.json", before), group_positions(grid, kSmall, "g.json"));
}

TEST(SceneGenerators, Velocities) {
  GroupSpec g;
  g.count = 100;
  g.velocity.value = {1, 2, 3};
  for (const Vec3& v : group_velocities(g)) EXPECT_EQ(v, (Vec3{1, 2, 3}));
  g.velocity.kind = VelocitySpec::Kind::Random;
  g.velocity.max_speed = 1.0f;
  g.velocity.seed = 3;
  const auto v = group_velocities(g);
  ASSERT_EQ(v.size(), 100u);
  EXPECT_EQ(v, group_velocities(g));
  EXPECT_EQ(v[0], (Vec3{-0.773099422454834f, 0.40058696269989014f, 0.22594928741455078f}));
  for (const Vec3& x : v)
    for (int a = 0; a < 3; ++a) {
      EXPECT_GE(x[a], -1.0f);
      EXPECT_LE(x[a], 1.0f);
    }
  g.velocity.seed = 4;
  EXPECT_FALSE(group_velocities(g)[0] == v[0]);
}

namespace {

std::vector<fs::path> scene_files() {
  std::vector<fs::path> files;
  for (const auto& e : fs::directory_iterator(source_dir() / "datasets" / "scenes"))
    if (e.path().extension() == ".json") files.push_back(e.path());
  std::sort(files.begin(), files.end());
  return files;
}

}  // namespace

TEST(SceneFiles, AllLoadWithStandInMeshesAndFitTheirDomain) {
  // Every dataset name resolves to a non-empty stand-in file, so every scene is fully
  // validated without the dataset cache; bodies are taken as cubes of side `scale`
  // (a normalised mesh's AABB is at most that), except a mesh the scene names as a file
  // beside it (rods-150's datasets/scenes/meshes), placed by its own normalised bounds.
  const fs::path data = temp_dir("standin");
  for (const char* name : {"bunny", "armadillo", "dragon", "asian-dragon"})
    write_file(data / (std::string(name) + ".obj"), "v 0 0 0\n");
  const auto files = scene_files();
  ASSERT_GE(files.size(), 15u);
  for (const fs::path& f : files) {
    SCOPED_TRACE(f.string());
    Scene s;
    ASSERT_NO_THROW(s = load_scene(f.string(), data.string()));
    EXPECT_EQ(s.name + ".json", f.filename().string());
    std::vector<Aabb> boxes;  // every group's bodies, placed as build_model places them
    for (const GroupSpec& g : s.groups) {
      Aabb local;
      if (g.shape.kind == ShapeSpec::Kind::Box) {
        local = {-g.shape.half_extents, g.shape.half_extents};
      } else if (g.shape.kind == ShapeSpec::Kind::Mesh && g.shape.mesh.find('/') != std::string::npos) {
        Mesh mesh = load_mesh(resolve_mesh_path(s, g.shape.mesh, "shape.mesh"));
        normalize_mesh(mesh);
        scale_mesh(mesh, g.shape.scale);
        const Aabb b = mesh_bounds(mesh);
        const Vec3 h = 0.5f * (b.max - b.min);
        local = {-h, h};
      } else {
        const float h = 0.5f * (g.shape.kind == ShapeSpec::Kind::Mesh ? g.shape.scale : 2 * g.shape.radius);
        local = {{-h, -h, -h}, {h, h, h}};
      }
      std::vector<Vec3> p;
      ASSERT_NO_THROW(p = group_positions(g, local, s.path, boxes));
      ASSERT_EQ(p.size(), static_cast<std::size_t>(g.count));
      for (std::size_t i = 0; i < p.size(); ++i) {
        EXPECT_TRUE(contains(s.domain, translated(local, p[i]))) << g.name << " body " << i;
        boxes.push_back(translated(local, p[i]));
      }
      EXPECT_EQ(group_velocities(g).size(), static_cast<std::size_t>(g.count));
    }
    // No two bodies of any groups start interpenetrating: the candidate pairs of the CPU
    // loose octree (exact, tested against `flat` in test_broadphase; an implementation
    // apart from the layout's binning), then the interior test on each.
    BroadPhaseConfig cfg;
    cfg.name = "octree";
    cfg.octree_depth = -1;  // auto
    std::vector<Pair> pairs;
    BroadPhaseStats stats;
    make_broadphase(cfg, s.domain)->find_pairs(boxes, pairs, stats);
    std::size_t overlapping = 0;
    for (const Pair& pr : pairs)
      if (interiors_intersect(boxes[pr.a], boxes[pr.b]) && overlapping++ < 5)
        ADD_FAILURE() << "bodies " << pr.a << " and " << pr.b << " overlap at the start";
    EXPECT_EQ(overlapping, 0u);
  }
  fs::remove_all(data);
}

TEST(SceneFiles, AllLoadWithTheDatasetCache) {
  // With the real data dir ($OCTOCD_DATA_DIR, else datasets/cache): a missing mesh is
  // only tolerated when the cache folder does not exist at all.
  const char* env = std::getenv("OCTOCD_DATA_DIR");
  const fs::path cache = (env != nullptr && *env != '\0') ? fs::path(env) : source_dir() / "datasets" / "cache";
  const bool cache_absent = !fs::exists(cache);
  int skipped = 0;
  for (const fs::path& f : scene_files()) {
    try {
      load_scene(f.string(), cache.string());
    } catch (const InputError& e) {
      const std::string msg = e.what();
      if (cache_absent && msg.find("run datasets/fetch.sh") != std::string::npos) {
        ++skipped;
        continue;
      }
      ADD_FAILURE() << msg;
    }
  }
  if (skipped > 0) GTEST_SKIP() << skipped << " scenes need meshes from " << cache << " (run datasets/fetch.sh)";
}

TEST(SceneFiles, PaperScenesHaveThePaperSettings) {
  const fs::path dir = temp_dir("paper");
  for (const char* name : {"bunny", "armadillo", "dragon", "asian-dragon"})
    write_file(dir / (std::string(name) + ".obj"), "v 0 0 0\n");
  const fs::path scenes = source_dir() / "datasets" / "scenes";
  const Scene stack = load_scene((scenes / "bunny-stack-50.json").string(), dir.string());
  EXPECT_EQ(body_count(stack), 50u);
  EXPECT_EQ(stack.frames, 3000);
  EXPECT_EQ(stack.walls, Walls::OpenBox);
  EXPECT_EQ(stack.groups[0].shape.mesh, "bunny");
  EXPECT_EQ(stack.broadphase.octree_depth, 2);
  const auto p = group_positions(stack.groups[0], {{-0.1f, -0.1f, -0.1f}, {0.1f, 0.1f, 0.1f}}, stack.path);
  for (const Vec3& x : p) EXPECT_GT(x.y - 0.1f, stack.domain.min.y);  // all above the floor
  struct R {
    const char* file;
    const char* mesh;
    int count;
  };
  for (const R& r : {R{"bunny-random-400.json", "bunny", 400}, R{"armadillo-random-250.json", "armadillo", 250},
                     R{"dragon-random-250.json", "dragon", 250}, R{"asian-dragon-random-60.json", "asian-dragon", 60}}) {
    SCOPED_TRACE(r.file);
    const Scene s = load_scene((scenes / r.file).string(), dir.string());
    EXPECT_EQ(s.groups[0].shape.mesh, r.mesh);
    EXPECT_EQ(s.groups[0].count, r.count);
    EXPECT_EQ(s.gravity, (Vec3{0, 0, 0}));
    EXPECT_EQ(s.walls, Walls::ClosedBox);
    EXPECT_EQ(s.groups[0].velocity.kind, VelocitySpec::Kind::Random);
    EXPECT_FLOAT_EQ(s.groups[0].velocity.max_speed, 1.0f);
    EXPECT_FLOAT_EQ(s.groups[0].shape.scale, 0.2f);
  }
  fs::remove_all(dir);
}

// theta is per shape (O(shapes) memory, issue 8): a pair's theta is the larger of its two
// shapes' values, the mean edge with `auto`, the scene's value otherwise.
TEST(Model, ThetaIsPerShapeAndAPairTakesTheLarger) {
  json j = minimal();
  j["domain"] = {{"min", {-50, 0, -50}}, {"max", {50, 10, 50}}};
  j["walls"] = "none";
  j["gravity"] = {0, 0, 0};
  j["groups"] = json::array();
  const int groups = 3000;  // a shapes^2 table would be 9 million entries
  for (int g = 0; g < groups; ++g) {
    const double side = 0.01 + 0.0001 * g;
    j["groups"].push_back({{"shape", {{"box", {side, side, side}}}}, {"count", 1}});
  }
  const auto m = build_model(parse_scene(j.dump(), "theta.json"));
  ASSERT_EQ(m->theta_shape.size(), m->shapes.size());
  ASSERT_GE(m->shapes.size(), static_cast<std::size_t>(groups));
  for (std::uint32_t a = 0; a < m->shapes.size(); a += 97)
    for (std::uint32_t b = 0; b < m->shapes.size(); b += 89)
      EXPECT_EQ(m->theta(a, b), std::max(m->shapes[a].mean_edge, m->shapes[b].mean_edge)) << a << " " << b;
  j["theta"] = 0.002;
  const auto f = build_model(parse_scene(j.dump(), "theta.json"));
  EXPECT_EQ(f->theta(0, static_cast<std::uint32_t>(f->shapes.size() - 1)), 0.002f);
}

// largest_mean_leaf_vertices (the cuda engine's choice of its small-scene kernel): a mesh's
// vertices over its occupied cells at the midphase's deepest level, the largest over the
// shapes; 0 without a mesh or with an AABB-only midphase. Icospheres of 642 and 42 vertices
// (subdivisions 3 and 1): at level 0 one cell holds them all; at level L the mean lies
// between the vertices over 8^L and the vertices, and it grows from level 2 to level 1 (a
// level-1 cell holds the vertices of its occupied children); two shapes give the larger.
TEST(Model, LargestMeanLeafVerticesIsTheLargestShapesMeanAtTheDeepestLevel) {
  const auto value = [](const std::vector<int>& subdivisions, const std::string& levels) {
    json j = minimal();
    j["walls"] = "none";
    j["midphase"] = {{"levels", levels}, {"depth", 2}};
    j["groups"] = json::array();
    for (std::size_t g = 0; g < subdivisions.size(); ++g)
      j["groups"].push_back({{"shape", {{"icosphere", {{"radius", 0.1}, {"subdivisions", subdivisions[g]}}}}},
                             {"count", 1},
                             {"positions", {{0.5 * static_cast<double>(g) - 0.5, 1.0, 0.0}}}});
    return largest_mean_leaf_vertices(*build_model(parse_scene(j.dump(), "leaf.json")));
  };
  EXPECT_EQ(largest_mean_leaf_vertices(*build_model(parse_scene(minimal().dump(), "boxes.json"))), 0.0);
  EXPECT_EQ(value({3}, "aabb-only"), 0.0);
  EXPECT_EQ(value({3}, "0"), 642.0);
  EXPECT_EQ(value({1}, "0"), 42.0);
  const double big2 = value({3}, "1,2"), big1 = value({3}, "1"), small2 = value({1}, "1,2");
  EXPECT_GE(big2, 642.0 / 64.0);
  EXPECT_LT(big2, 642.0);
  EXPECT_GT(big1, big2);
  EXPECT_LE(big1, 642.0);
  EXPECT_GE(small2, 42.0 / 64.0);
  EXPECT_LT(small2, big2);
  EXPECT_EQ(value({1, 3}, "1,2"), big2);
  EXPECT_EQ(value({3, 1}, "1,2"), big2);
}

// Issue 22: a random layout whose region has min == max on an axis (e.g. [0, 1, 0] to
// [1, 1, 1]) put drawn centres in grid cell 0 by rounding, and the -1 neighbour read
// outside the grid's head array (crashed in 5 of 6 runs; ASan reports it in every run).
TEST(Scene, RandomLayoutWithAFlatRegionStaysInsideTheGrid) {
  for (float y : {0.0f, 0.1f, 0.3f, 1.0f, 1.7f, -2.3f, 123.4f}) {
    for (std::uint64_t seed : {1u, 2u, 3u}) {
      GroupSpec g = box_group(40, {0.0f, y, 0.0f}, {4.0f, y, 4.0f});
      g.layout.kind = LayoutSpec::Kind::Random;
      g.layout.seed = seed;
      const std::vector<Vec3> p = group_positions(g, kBox01, "flat.json");
      ASSERT_EQ(p.size(), 40u);
      for (std::size_t i = 0; i < p.size(); ++i) {
        EXPECT_EQ(p[i].y, y);
        for (std::size_t j = 0; j < i; ++j)
          EXPECT_FALSE(interiors_intersect(translated(kBox01, p[i]), translated(kBox01, p[j]))) << i << " " << j;
      }
    }
  }
}

}  // namespace octocd_test_scene
