// Issue 10: the limits of docs/scenes.md ("Limits"), checked at load; the random layout
// with a grid of placed bodies; the spatial hash without its O(n^2) cliff; trace writer
// failures.
#include <gtest/gtest.h>

#include <signal.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "octocd/broadphase.hpp"
#include "octocd/error.hpp"
#include "octocd/mesh.hpp"
#include "octocd/parallel.hpp"
#include "octocd/scene.hpp"
#include "octocd/trace.hpp"

// This file's own names (its tests compile in unity batches with the folder's other files).
namespace octocd_test_limits {

namespace fs = std::filesystem;
using nlohmann::json;
using namespace octocd;

namespace {

json minimal() {
  return json::parse(R"({
    "name": "mini",
    "domain": {"min": [-1, 0, -1], "max": [1, 2, 1]},
    "groups": [{"shape": {"box": [0.1, 0.1, 0.1]}, "count": 2}]
  })");
}

/// The InputError message of parse_scene(j), "" when it parses.
std::string error_of(const json& j) {
  try {
    parse_scene(j.dump(), "lim.json");
  } catch (const InputError& e) {
    return e.what();
  }
  return "";
}

/// Expects `j` rejected naming `key` and `allowed` (a part of the allowed range).
void expect_rejected(const json& j, const std::string& key, const std::string& allowed) {
  const std::string msg = error_of(j);
  EXPECT_NE(msg.find("lim.json: " + key + ":"), std::string::npos) << "key " << key << ": " << msg;
  EXPECT_NE(msg.find("allowed: "), std::string::npos) << msg;
  EXPECT_NE(msg.find(allowed), std::string::npos) << "'" << allowed << "' not in: " << msg;
}

fs::path temp_dir(const std::string& name) {
  const fs::path d = fs::temp_directory_path() / ("octocd_test_limits_" + name + "_" + std::to_string(::getpid()));
  fs::remove_all(d);
  fs::create_directories(d);
  return d;
}

}  // namespace

// Each limit: the value just inside is accepted, just outside rejected with the range.
TEST(Limits, SceneRangesKeepFloat32Meaningful) {
  struct Case {
    std::string pointer;  // JSON pointer of the value
    json inside, outside;
    std::string key, allowed;
  };
  const std::vector<Case> cases = {
      {"/domain/max/0", 1000.0, 1000.5, "domain.max[0]", "[-1000, 1000]"},
      {"/domain/min/1", -1000.0, -3e38, "domain.min[1]", "[-1000, 1000]"},
      {"/domain/max/2", -0.999, -0.9995, "domain", "each side >= 0.001 m"},
      {"/groups/0/mass", 1e-6, 1e-40, "groups[0].mass", "0 (static) or a number in [1e-06, 1e+09]"},
      {"/groups/0/mass", 1e9, 2e9, "groups[0].mass", "[1e-06, 1e+09]"},
      {"/groups/0/shape/box/1", 0.0005, 0.0004, "groups[0].shape.box[1]", "[0.0005, 1000]"},
      {"/groups/0/shape/box/0", 1000.0, 1001.0, "groups[0].shape.box[0]", "[0.0005, 1000]"},
      {"/groups/0/count", 10000000, 10000001, "groups[0].count", "integer in [1, 10000000]"},
      {"/gravity", json::array({0, -1e4, 0}), json::array({0, -1.5e4, 0}), "gravity[1]", "[-10000, 10000]"},
      {"/wall_thickness", 0.001, 0.0001, "wall_thickness", "[0.001, 2000]"},
      {"/theta", 2000.0, 2001.0, "theta", "(0, 2000]"},
      {"/response", json{{"max_velocity", 1e4}}, json{{"max_velocity", 1e5}}, "response.max_velocity",
       "(0, 10000]"},
      {"/broadphase", json{{"cell_size", 0.001}}, json{{"cell_size", 1e-5}}, "broadphase.cell_size",
       "[0.001, 2000]"},
      {"/groups/0/velocity", json{{"type", "fixed"}, {"value", {0, 1e4, 0}}},
       json{{"type", "fixed"}, {"value", {0, 2e4, 0}}}, "groups[0].velocity.value[1]", "[-10000, 10000]"},
      {"/groups/0/velocity", json{{"type", "random"}, {"max", 1e4}}, json{{"type", "random"}, {"max", 1e5}},
       "groups[0].velocity.max", "[0, 10000]"},
      {"/groups/0/layout", json{{"type", "grid"}, {"min", {-1, 0, -1}}, {"max", {1, 2, 1}}},
       json{{"type", "grid"}, {"min", {-1, 0, -1}}, {"max", {1, 2, 1e4}}}, "groups[0].layout.max[2]",
       "[-1000, 1000]"},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.pointer);
    json j = minimal();
    j[json::json_pointer(c.pointer)] = c.inside;
    EXPECT_EQ(error_of(j), "") << c.inside.dump();
    j[json::json_pointer(c.pointer)] = c.outside;
    expect_rejected(j, c.key, c.allowed);
  }
  // Mass 0 is static; explicit positions are coordinates.
  json j = minimal();
  j["groups"][0]["mass"] = 0;
  EXPECT_EQ(error_of(j), "");
  j["groups"][0]["positions"] = {{0, 1, 0}, {0, 1, 2000}};
  expect_rejected(j, "groups[0].positions[1][2]", "[-1000, 1000]");
  // The whole scene's body count, over groups.
  j = minimal();
  j["groups"][0]["count"] = 6000000;
  j["groups"][1] = j["groups"][0];
  j["groups"][1]["name"] = "second";
  expect_rejected(j, "groups", "at most 10000000 bodies in a scene");
  // Scale of meshes (checked before the mesh is looked up).
  j = minimal();
  j["groups"][0]["shape"] = {{"mesh", "bunny"}, {"scale", 1e-4}};
  expect_rejected(j, "groups[0].shape.scale", "[0.001, 2000]");
  j["groups"][0]["shape"] = {{"icosphere", {{"radius", 1e-4}}}};
  expect_rejected(j, "groups[0].shape.icosphere.radius", "[0.0005, 1000]");
}

// A scene octocd generates itself (bench max-instances) may pass the file limit of 10^7
// bodies up to limits::kMaxGeneratedBodies (2^27), where memory checks bound it; a larger
// max_bodies is clamped to it, and any file keeps limits::kMaxBodies.
TEST(Limits, GeneratedScenesPassTheFileBodyLimitUpToTheirOwn) {
  json j = minimal();
  j["groups"][0]["count"] = 10000001;
  expect_rejected(j, "groups[0].count", "integer in [1, 10000000]");
  const Scene s = parse_scene(j.dump(), "generated.json", "", limits::kMaxGeneratedBodies);
  EXPECT_EQ(body_count(s), 10000001u);
  j["groups"][0]["count"] = 134217728;
  EXPECT_EQ(body_count(parse_scene(j.dump(), "generated.json", "", limits::kMaxGeneratedBodies)), 134217728u);
  j["groups"][0]["count"] = 134217729;
  for (const std::size_t cap : {limits::kMaxGeneratedBodies, std::size_t{1} << 31}) {
    try {
      (void)parse_scene(j.dump(), "generated.json", "", cap);
      ADD_FAILURE() << "2^27 + 1 bodies accepted with max_bodies " << cap;
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find("groups[0].count: value 134217729 out of range; allowed: integer in [1, "
                                           "134217728]"),
                std::string::npos)
          << e.what();
    }
  }
  j["groups"][0]["count"] = 100000000;
  j["groups"][1] = j["groups"][0];
  j["groups"][1]["name"] = "second";
  try {
    (void)parse_scene(j.dump(), "generated.json", "", limits::kMaxGeneratedBodies);
    ADD_FAILURE() << "2 x 10^8 bodies accepted";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("at most 134217728 bodies in a scene"), std::string::npos) << e.what();
  }
}

TEST(Limits, NestingAndSceneSize) {
  std::string deep = "1";
  for (int i = 0; i < 64; ++i) deep = "[" + deep + "]";
  json j = minimal();
  const std::string text = j.dump();
  // 64 levels of arrays inside the top-level object: 65 levels, one too many.
  const std::string bad = text.substr(0, text.size() - 1) + R"(, "description": )" + deep + "}";
  const std::string msg = [&] {
    try {
      parse_scene(bad, "deep.json");
    } catch (const InputError& e) {
      return std::string(e.what());
    }
    return std::string();
  }();
  EXPECT_NE(msg.find("deep.json: description"), std::string::npos) << msg;
  EXPECT_NE(msg.find("nesting deeper than 64"), std::string::npos) << msg;

  const fs::path dir = temp_dir("size");
  const fs::path big = dir / "big.json";
  {
    std::ofstream(big) << text;
  }
  fs::resize_file(big, limits::kMaxSceneFileBytes + 1);
  try {
    load_scene(big.string());
    ADD_FAILURE() << "a 64 MiB + 1 scene loaded";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("at most 67108864 bytes"), std::string::npos) << e.what();
  }
  fs::remove_all(dir);
}

// The exhaustive rejection sampling of design.md section 3 / docs/scenes.md: each try
// tested against every box placed (`before` and this group's), 1000 tries a body. Returns
// the centres placed and, when a body found no room, its index in `failed_at`.
std::vector<Vec3> exhaustive_layout(const GroupSpec& g, const Aabb& local, const std::vector<Aabb>& before,
                                    int& failed_at) {
  SplitMix64 rng(g.layout.seed);
  std::vector<Aabb> placed = before;
  std::vector<Vec3> want;
  failed_at = -1;
  for (int k = 0; k < g.count; ++k) {
    bool ok = false;
    for (int t = 0; t < 1000 && !ok; ++t) {
      Vec3 p;
      for (int a = 0; a < 3; ++a) p[a] = rng.uniform(g.layout.region.min[a], g.layout.region.max[a]);
      const Aabb box = translated(local, p);
      ok = true;
      for (const Aabb& b : placed) ok = ok && !overlaps(box, b);
      if (ok) {
        placed.push_back(box);
        want.push_back(p);
      }
    }
    if (!ok) {
      failed_at = k;
      break;
    }
  }
  return want;
}

GroupSpec random_group(int count, float side, std::uint64_t seed) {
  GroupSpec g;
  g.count = count;
  g.layout.kind = LayoutSpec::Kind::Random;
  g.layout.region = {{-side, -side, -side}, {side, side, side}};
  g.layout.region_from_domain = false;
  g.layout.seed = seed;
  return g;
}

// The random layout bins the placed bodies in a grid and draws and tests its tries in
// chunks on the threads; it must place exactly what testing every placed body places, one
// try after another (same draws, same rejections), on any thread count.
TEST(Limits, RandomLayoutEqualsExhaustiveRejection) {
  for (const float half : {0.05f, 0.013f}) {
    const GroupSpec g = random_group(600, 1, 11);
    const Aabb local{{-half, -2 * half, -half}, {half, 2 * half, half}};
    const std::vector<Vec3> got = group_positions(g, local, "r.json");
    int failed_at = 0;
    const std::vector<Vec3> want = exhaustive_layout(g, local, {}, failed_at);
    ASSERT_EQ(failed_at, -1);
    ASSERT_EQ(got.size(), want.size());
    for (std::size_t i = 0; i < got.size(); ++i)
      ASSERT_TRUE(got[i].x == want[i].x && got[i].y == want[i].y && got[i].z == want[i].z) << i;
  }
}

// Bodies packed until no more fit, beside 300 boxes of an earlier group: many tries
// rejected, several chunks, the first large enough for the threads. The first 4,000 bodies
// and the body the error names when 6,000 are asked for are the exhaustive test's, on 1, 2
// and 5 threads.
TEST(Limits, RandomLayoutInChunksEqualsExhaustiveRejectionOnAnyThreadCount) {
  const Aabb local{{-0.02f, -0.03f, -0.02f}, {0.02f, 0.03f, 0.02f}};
  std::vector<Aabb> before;
  SplitMix64 r(3);
  for (int i = 0; i < 300; ++i) {
    Vec3 c;
    for (int a = 0; a < 3; ++a) c[a] = r.uniform(-0.6f, 0.6f);
    before.push_back({c - Vec3{0.05f, 0.05f, 0.05f}, c + Vec3{0.05f, 0.05f, 0.05f}});
  }
  const GroupSpec full = random_group(6000, 0.58f, 17);
  int full_failed_at = 0;
  std::vector<Vec3> want = exhaustive_layout(full, local, before, full_failed_at);
  ASSERT_GT(full_failed_at, 4000);
  GroupSpec g = full;
  g.count = 4000;
  want.resize(4000);
  for (const int threads : {1, 2, 5}) {
    ThreadCount scope(threads);
    const std::vector<Vec3> got = group_positions(g, local, "r.json", before);
    ASSERT_EQ(got.size(), want.size()) << threads;
    for (std::size_t i = 0; i < got.size(); ++i)
      ASSERT_TRUE(got[i].x == want[i].x && got[i].y == want[i].y && got[i].z == want[i].z) << threads << " " << i;
    try {
      group_positions(full, local, "r.json", before);
      FAIL() << "6,000 bodies placed where " << full_failed_at << " fit";
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find("placed " + std::to_string(full_failed_at) + " of 6000 bodies"),
                std::string::npos)
          << e.what();
    }
  }
}

// A cell size much smaller than the bodies: every body at level 0 would touch thousands
// of cells. Before issue 10 such bodies were tested against all others (n^2/2
// candidates); now they sit in a coarser grid. Same pairs as `flat`, far fewer candidates.
TEST(Limits, SpatialHashWithTinyCellsStaysNearLinear) {
  SplitMix64 rng(5);
  std::vector<Aabb> boxes;
  for (int i = 0; i < 2000; ++i) {
    Vec3 c, h;
    for (int a = 0; a < 3; ++a) c[a] = rng.uniform(-1.7f, 1.7f);
    for (int a = 0; a < 3; ++a) h[a] = rng.uniform(0.02f, 0.08f);
    boxes.push_back({c - h, c + h});
  }
  boxes.push_back({{-1.8f, -1.8f, -1.8f}, {1.8f, -1.7f, 1.8f}});  // a floor: coarser still
  boxes.push_back({{1e6f, 0, 0}, {1e6f + 0.1f, 0.1f, 0.1f}});     // far away: beyond level 0
  boxes.push_back({{1e6f + 0.05f, 0, 0}, {1e6f + 0.2f, 0.1f, 0.1f}});
  const Aabb domain{{-2, -2, -2}, {2, 2, 2}};
  std::vector<Pair> want, got;
  BroadPhaseStats ws, gs;
  make_broadphase({"flat", 2, 0.25f}, domain)->find_pairs(boxes, want, ws);
  for (const float h : {0.002f, 0.01f, 0.25f}) {
    SCOPED_TRACE(h);
    make_broadphase({"spatial-hash", 2, h}, domain)->find_pairs(boxes, got, gs);
    EXPECT_EQ(got, want);
    const double n = static_cast<double>(boxes.size());
    EXPECT_LT(static_cast<double>(gs.cell_candidates), n * (n - 1) / 2 / 20) << "close to all pairs";
  }
}

// OFF faces are checked against the vertex count (assimp clamps them), and counts over
// the limits are rejected from the header, before the file is parsed.
TEST(Limits, MeshFilesAreCheckedBeforeAndAfterParsing) {
  const fs::path dir = temp_dir("mesh");
  auto expect_mesh_error = [&](const std::string& name, const std::string& text, const std::string& part) {
    const fs::path p = dir / name;
    {
      std::ofstream(p, std::ios::binary) << text;
    }
    try {
      load_mesh(p.string());
      ADD_FAILURE() << name << " loaded";
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find(part), std::string::npos) << e.what();
    }
  };
  expect_mesh_error("idx.off", "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 3\n",
                    "face 0 uses vertex 3 but the file has 3 vertices");
  expect_mesh_error("neg.off", "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 -1 2\n", "bad OFF index of face 0 '-1'");
  expect_mesh_error("short.off", "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1\n", "face 0 lists 2 of its 3 corners");
  expect_mesh_error("many.off", "OFF\n10000001 1 0\n0 0 0\n", "declares 10000001 vertices (expected at most 10000000)");
  expect_mesh_error("faces.off", "OFF\n3 20000001 0\n0 0 0\n", "declares 20000001 faces");
  expect_mesh_error("huge.ply",
                    "ply\nformat ascii 1.0\nelement vertex 99999999999\nproperty float x\nproperty float y\n"
                    "property float z\nend_header\n0 0 0\n",
                    "declares 99999999999 vertexs");
  // Found by fuzz_mesh: assimp 5.2 crashes or never returns on these.
  expect_mesh_error("vshort.off", "OFF\n3 1 0\n 000\n1 0 0\n0 1 0\n3 0 1 2\n", "vertex 0 is not three numbers");
  expect_mesh_error("corners.off", "OFF\n3 2 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n0\n", "face 1 has 0 corners");
  expect_mesh_error("noend.ply", "ply\nformat ascii 1.0\nelement vertex 4\nproperty flst ucha 0 1 3\n3 0 3 2\n",
                    "PLY header line 5 is not ply, format");
  expect_mesh_error("vt.ply",
                    "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nend_header\v0 0 1\n",
                    "PLY header line 5 is not");
  // Comments and blank lines in an OFF file are fine; a good one loads.
  const fs::path ok = dir / "ok.off";
  {
    std::ofstream(ok) << "OFF\n# a comment\n4 2 0\n\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n3 0 1 2\n3 0 1 3\n";
  }
  EXPECT_EQ(load_mesh(ok.string()).triangles.size(), 2u);
  fs::remove_all(dir);
}

// A trace writer whose file hits a size limit: the call that flushes throws one
// RuntimeError naming the frames kept; the writer is then closed, failed() says so, and
// the file holds every frame flushed before (a child process: the limit is per process).
TEST(Limits, TraceWriterKeepsFlushedFramesWhenWritesFail) {
  const fs::path dir = temp_dir("trace");
  const std::string path = (dir / "t.h5").string();
  int fds[2];
  ASSERT_EQ(::pipe(fds), 0);
  const pid_t child = ::fork();
  ASSERT_GE(child, 0);
  if (child == 0) {
    ::close(fds[0]);
    ::signal(SIGXFSZ, SIG_IGN);
    const rlimit lim{1024 * 1024, 1024 * 1024};
    ::setrlimit(RLIMIT_FSIZE, &lim);
    std::string report;
    int code = 10;
    try {
      TraceBodies tb;
      for (int i = 0; i < 20; ++i) {
        tb.shape_id.push_back(0);
        tb.inverse_mass.push_back(1.0f);
        tb.local_aabb.push_back({{-1, -1, -1}, {1, 1, 1}});
        tb.group.push_back("g");
      }
      tb.shape_names = {"box"};
      TraceOptions opt;
      opt.state_every = 1;
      opt.flush_every = 10;
      TraceMetadata meta;
      meta.scene_name = "t";
      TraceWriter w(path, meta, tb, opt);
      BodyState st;
      st.x.assign(20, Vec3{1, 2, 3});
      st.v.assign(20, Vec3{0, 0, 0});
      st.w.assign(20, 1.0f);
      std::int64_t f = 1;
      try {
        for (; f < 1000000; ++f) {
          FrameMetrics m;
          m.frame = f;
          w.append_frame(m, st, {});
        }
      } catch (const RuntimeError& e) {
        report = e.what();
        code = w.failed() && w.flushed_frames() > 0 && w.flushed_frames() % 10 == 0 ? 0 : 11;
        report += "\n" + std::to_string(w.flushed_frames());
        try {
          w.append_frame(FrameMetrics{}, st, {});
          code = 12;  // must throw: the writer is closed
        } catch (const RuntimeError&) {
        }
        w.close();  // a no-op now
      }
    } catch (const std::exception& e) {
      report = std::string("unexpected: ") + e.what();
      code = 13;
    }
    if (::write(fds[1], report.data(), report.size()) < 0) code = 14;
    ::_exit(code);
  }
  ::close(fds[1]);
  std::string report;
  char buf[4096];
  for (ssize_t n; (n = ::read(fds[0], buf, sizeof buf)) > 0;) report.append(buf, static_cast<std::size_t>(n));
  ::close(fds[0]);
  int status = 0;
  ::waitpid(child, &status, 0);
  ASSERT_TRUE(WIFEXITED(status)) << "the writer crashed (signal " << WTERMSIG(status) << ")";
  ASSERT_EQ(WEXITSTATUS(status), 0) << report;
  EXPECT_NE(report.find("trace '" + path + "': writing frame "), std::string::npos) << report;
  EXPECT_NE(report.find("failed (File too large); the file keeps the "), std::string::npos) << report;
  const std::int64_t kept = std::stoll(report.substr(report.rfind('\n') + 1));
  const TraceSummary s = read_trace_summary(path);
  EXPECT_GE(s.frames, kept);
  EXPECT_EQ(s.last_frame, s.frames);
  EXPECT_GE(s.state_rows, kept);
  fs::remove_all(dir);
}

}  // namespace octocd_test_limits
