// Unit tests for octocd/mesh.hpp: welding, normalisation, procedural shapes, loading
// (errors included) and, when the dataset cache exists, the fetched datasets.

#include <gtest/gtest.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <ostream>
#include <string>
#include <utility>

#include "octocd/error.hpp"
#include "octocd/mesh.hpp"
#include "support/temp_files.hpp"

// This file's own names (its tests compile in unity batches with the folder's other files).
namespace octocd_test_mesh {

namespace {

namespace fs = std::filesystem;
using octocd::InputError;
using octocd::Mesh;
using octocd::Vec3;

/// This process's temp dir for mesh files (one per process: ctest runs each test in its own).
fs::path temp_root() {
  static const fs::path d = fs::temp_directory_path() / ("octocd_test_mesh_" + std::to_string(::getpid()));
  return d;
}

const auto* const kMeshCleanup = octocd::test::remove_at_exit(temp_root);  // unless OCTOCD_KEEP_TEST_FILES

/// Writes `text` to a fresh file in this process's temp dir and returns its path.
std::string write_temp(const std::string& name, const std::string& text) {
  const fs::path dir = temp_root();
  fs::create_directories(dir);
  const fs::path p = dir / name;
  std::ofstream(p, std::ios::binary) << text;
  return p.string();
}

/// Expects load_mesh(path) to throw InputError whose message names the path and holds `what`.
void expect_load_error(const std::string& path, const std::string& what) {
  try {
    (void)octocd::load_mesh(path);
    FAIL() << "no error for " << path;
  } catch (const InputError& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find(path), std::string::npos) << msg;
    EXPECT_NE(msg.find(what), std::string::npos) << msg;
  }
}

/// Counts of each undirected edge, and of each directed edge.
struct EdgeCounts {
  std::map<std::pair<std::uint32_t, std::uint32_t>, int> undirected, directed;
};
EdgeCounts edge_counts(const Mesh& m) {
  EdgeCounts c;
  for (const auto& t : m.triangles) {
    for (int k = 0; k < 3; ++k) {
      const std::uint32_t a = t[static_cast<std::size_t>(k)];
      const std::uint32_t b = t[static_cast<std::size_t>((k + 1) % 3)];
      ++c.directed[{a, b}];
      ++c.undirected[{std::min(a, b), std::max(a, b)}];
    }
  }
  return c;
}

/// Closed and consistently wound: every edge in exactly 2 triangles, each direction once.
void expect_closed_consistent(const Mesh& m) {
  const EdgeCounts c = edge_counts(m);
  for (const auto& [e, n] : c.undirected) {
    ASSERT_EQ(n, 2) << "edge " << e.first << "-" << e.second;
  }
  for (const auto& [e, n] : c.directed) {
    ASSERT_EQ(n, 1) << "directed edge " << e.first << "->" << e.second << " repeated";
  }
}

/// Signed volume (divergence theorem): positive when the winding faces outwards.
double signed_volume(const Mesh& m) {
  double v = 0.0;
  for (const auto& t : m.triangles) {
    const Vec3 a = m.vertices[t[0]], b = m.vertices[t[1]], c = m.vertices[t[2]];
    v += (static_cast<double>(a.x) * (static_cast<double>(b.y) * c.z - static_cast<double>(b.z) * c.y) -
          static_cast<double>(a.y) * (static_cast<double>(b.x) * c.z - static_cast<double>(b.z) * c.x) +
          static_cast<double>(a.z) * (static_cast<double>(b.x) * c.y - static_cast<double>(b.y) * c.x)) /
         6.0;
  }
  return v;
}

TEST(Weld, MergesExactDuplicatesAndDropsDegenerateTriangles) {
  Mesh m;
  // Two triangles of a unit square given as 6 separate vertices (soup), with -0 vs +0,
  // plus a triangle that collapses after welding.
  m.vertices = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0},            // tri 0
                {-0.0f, 0, 0}, {1, 1, 0}, {0, 1, 0},        // tri 1: 3 == 0, 4 == 2
                {1, 0, 0}, {1.0f, 0, 0}, {0.5f, 0.5f, 0}};  // tri 2: 6 == 7 == 1
  m.triangles = {{0, 1, 2}, {3, 4, 5}, {6, 7, 8}};
  octocd::weld_mesh(m);
  ASSERT_EQ(m.vertices.size(), 5u);  // (0,0,0) (1,0,0) (1,1,0) (0,1,0) (0.5,0.5,0)
  EXPECT_TRUE(m.vertices[0] == (Vec3{0, 0, 0}));
  EXPECT_TRUE(m.vertices[1] == (Vec3{1, 0, 0}));
  EXPECT_TRUE(m.vertices[2] == (Vec3{1, 1, 0}));
  EXPECT_TRUE(m.vertices[3] == (Vec3{0, 1, 0}));
  ASSERT_EQ(m.triangles.size(), 2u);
  EXPECT_EQ(m.triangles[0], (std::array<std::uint32_t, 3>{0, 1, 2}));
  EXPECT_EQ(m.triangles[1], (std::array<std::uint32_t, 3>{0, 2, 3}));
}

TEST(Weld, KeepsNearlyEqualVerticesApart) {
  Mesh m;
  m.vertices = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {std::nextafter(1.0f, 2.0f), 0, 0}};
  m.triangles = {{0, 1, 2}, {0, 3, 2}};
  octocd::weld_mesh(m);
  EXPECT_EQ(m.vertices.size(), 4u);
  EXPECT_EQ(m.triangles.size(), 2u);
}

TEST(Normalize, LongestSideOneAndCentred) {
  Mesh m = octocd::make_box_mesh({0.3f, 2.5f, 1.0f}, 1);
  for (Vec3& v : m.vertices) v += Vec3{10.0f, -3.0f, 7.5f};
  octocd::normalize_mesh(m);
  const octocd::Aabb b = octocd::mesh_bounds(m);
  EXPECT_NEAR(b.max.y - b.min.y, 1.0f, 1e-6f);
  EXPECT_NEAR(b.max.x - b.min.x, 0.6f / 5.0f, 1e-6f);
  EXPECT_NEAR(b.max.z - b.min.z, 2.0f / 5.0f, 1e-6f);
  for (int a = 0; a < 3; ++a) {
    EXPECT_NEAR(b.min[a] + b.max[a], 0.0f, 1e-6f) << "axis " << a;
  }
}

TEST(Normalize, RejectsEmptyAndFlatMeshes) {
  Mesh empty;
  EXPECT_THROW(octocd::normalize_mesh(empty), InputError);
  Mesh point;
  point.vertices = {{1, 2, 3}, {1, 2, 3}};
  EXPECT_THROW(octocd::normalize_mesh(point), InputError);
}

TEST(Scale, MultipliesAndRejectsNonPositive) {
  Mesh m = octocd::make_box_mesh({1, 1, 1});
  octocd::scale_mesh(m, 0.25f);
  const octocd::Aabb b = octocd::mesh_bounds(m);
  EXPECT_FLOAT_EQ(b.max.x, 0.25f);
  EXPECT_FLOAT_EQ(b.min.z, -0.25f);
  EXPECT_THROW(octocd::scale_mesh(m, 0.0f), InputError);
  EXPECT_THROW(octocd::scale_mesh(m, -1.0f), InputError);
}

TEST(Icosphere, VertexCountsAndRadius) {
  const std::size_t expected_v[] = {12, 42, 162, 642};
  for (int s = 0; s < 4; ++s) {
    const Mesh m = octocd::make_icosphere(0.7f, s);
    EXPECT_EQ(m.vertices.size(), expected_v[s]) << "subdivisions " << s;
    EXPECT_EQ(m.triangles.size(), 20u << (2 * s)) << "subdivisions " << s;
    for (const Vec3& v : m.vertices) {
      ASSERT_NEAR(octocd::length(v), 0.7f, 1e-6f);
    }
    expect_closed_consistent(m);
    EXPECT_GT(signed_volume(m), 0.0);
  }
  // The volume approaches the ball's (4/3 pi r^3) from below.
  const Mesh fine = octocd::make_icosphere(1.0f, 5);
  EXPECT_NEAR(signed_volume(fine), 4.0 / 3.0 * M_PI, 0.01);
  EXPECT_LT(signed_volume(fine), 4.0 / 3.0 * M_PI);
}

TEST(BoxMesh, ClosedConsistentOutwardWithExactVolume) {
  for (int s = 0; s <= 3; ++s) {
    const Mesh m = octocd::make_box_mesh({0.5f, 1.0f, 1.5f}, s);
    EXPECT_EQ(m.triangles.size(), 12u << (2 * s));
    // V - E + F = 2 for a closed genus-0 surface: V = 2 + F/2.
    EXPECT_EQ(m.vertices.size(), 2u + m.triangles.size() / 2) << "subdivisions " << s;
    expect_closed_consistent(m);
    EXPECT_NEAR(signed_volume(m), 1.0 * 2.0 * 3.0, 1e-5);
    for (const Vec3& v : m.vertices) {  // every vertex on the surface of the box
      const bool on_face = std::fabs(v.x) == 0.5f || std::fabs(v.y) == 1.0f ||
                           std::fabs(v.z) == 1.5f;
      ASSERT_TRUE(on_face);
    }
  }
  EXPECT_THROW(octocd::make_box_mesh({1, 1, 1}, 9), InputError);
  EXPECT_THROW(octocd::make_box_mesh({1, 0, 1}), InputError);
}

TEST(MeanEdgeLength, UnitBoxByHand) {
  // Unit cube, 12 triangles: 12 cube edges of length 1 and 6 face diagonals of sqrt(2).
  const Mesh m = octocd::make_box_mesh({0.5f, 0.5f, 0.5f}, 0);
  const double expected = (12.0 + 6.0 * std::sqrt(2.0)) / 18.0;
  EXPECT_NEAR(octocd::mean_edge_length(m), expected, 1e-6);
  Mesh no_tris;
  no_tris.vertices = {{0, 0, 0}};
  EXPECT_EQ(octocd::mean_edge_length(no_tris), 0.0f);
}

const char* kTetraOff =
    "OFF\n"
    "4 4 0\n"
    "0 0 0\n1 0 0\n0 1 0\n0 0 1\n"
    "3 0 2 1\n3 0 1 3\n3 0 3 2\n3 1 2 3\n";

TEST(LoadMesh, ReadsOffAndWelds) {
  const std::string p = write_temp("tetra.off", kTetraOff);
  const Mesh m = octocd::load_mesh(p);
  EXPECT_EQ(m.name, "tetra");
  EXPECT_EQ(m.vertices.size(), 4u);
  EXPECT_EQ(m.triangles.size(), 4u);
  expect_closed_consistent(m);
  EXPECT_NEAR(signed_volume(m), 1.0 / 6.0, 1e-7);
}

TEST(LoadMesh, ReadsObjSoupAndWeldsIt) {
  // Two triangles given with 6 separate vertices, two pairs equal: welded to 4.
  const std::string p = write_temp("quad.obj",
                                   "v 0 0 0\nv 1 0 0\nv 1 1 0\n"
                                   "v 0 0 0\nv 1 1 0\nv 0 1 0\n"
                                   "f 1 2 3\nf 4 5 6\n");
  const Mesh m = octocd::load_mesh(p);
  EXPECT_EQ(m.vertices.size(), 4u);
  EXPECT_EQ(m.triangles.size(), 2u);
}

TEST(LoadMesh, MissingFile) {
  expect_load_error("/nonexistent/octocd/no_such_mesh.off", "not found");
}

TEST(LoadMesh, EmptyFile) {
  expect_load_error(write_temp("empty.off", ""), "empty");
}

TEST(LoadMesh, NanVertex) {
  const std::string p = write_temp("nan.obj",
                                   "v 0 0 0\nv 1 0 0\nv 0 nan 0\nv 0 0 1\n"
                                   "f 1 2 3\nf 1 2 4\n");
  expect_load_error(p, "not finite");
  try {
    (void)octocd::load_mesh(p);
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("vertex 2"), std::string::npos) << e.what();
  }
}

TEST(LoadMesh, OffCommentInFaceSection) {
  const std::string p = write_temp("commented.off",
                                   "OFF\n"
                                   "4 4 0\n"
                                   "0 0 0\n1 0 0\n0 1 0\n0 0 1\n"
                                   "3 0 2 1\n3 0 1 3\n"
                                   "# a comment line\n"
                                   "3 0 3 2\n3 1 2 3\n");
  expect_load_error(p, "expected 4");
}

TEST(LoadMesh, GarbageFile) {
  expect_load_error(write_temp("garbage.off", "this is not a mesh\n"), "mesh file");
}

// ---- the fetched datasets (datasets/fetch.sh) ----------------------------------------

struct DatasetCase {
  const char* file;
  std::size_t vertices;
  std::size_t triangles;
};

void PrintTo(const DatasetCase& c, std::ostream* os) { *os << c.file; }

class Datasets : public ::testing::TestWithParam<DatasetCase> {};

TEST_P(Datasets, LoadWithExpectedCounts) {
  // OCTOCD_DATA_DIR, else <OCTOCD_SOURCE_DIR>/datasets/cache.
  fs::path dir;
  if (const char* d = std::getenv("OCTOCD_DATA_DIR")) {
    dir = d;
  } else if (const char* src = std::getenv("OCTOCD_SOURCE_DIR")) {
    dir = fs::path(src) / "datasets" / "cache";
  } else {
    GTEST_SKIP() << "neither OCTOCD_DATA_DIR nor OCTOCD_SOURCE_DIR is set";
  }
  const fs::path p = dir / GetParam().file;
  if (!fs::exists(p)) GTEST_SKIP() << p << " missing: run datasets/fetch.sh";
  Mesh m = octocd::load_mesh(p.string());
  EXPECT_EQ(m.vertices.size(), GetParam().vertices);
  EXPECT_EQ(m.triangles.size(), GetParam().triangles);
  EXPECT_GT(octocd::mean_edge_length(m), 0.0f);
  octocd::normalize_mesh(m);
  const octocd::Aabb b = octocd::mesh_bounds(m);
  const float longest =
      std::max({b.max.x - b.min.x, b.max.y - b.min.y, b.max.z - b.min.z});
  EXPECT_NEAR(longest, 1.0f, 1e-6f);
}

INSTANTIATE_TEST_SUITE_P(
    Fetched, Datasets,
    ::testing::Values(DatasetCase{"bunny.obj", 1839, 3674},
                      DatasetCase{"armadillo.off", 26002, 52000},
                      DatasetCase{"dragon.off", 39994, 79976},
                      DatasetCase{"asian-dragon.off", 159964, 319904}),
    [](const ::testing::TestParamInfo<DatasetCase>& param_info) {
      std::string n = fs::path(param_info.param.file).stem().string();
      std::replace(n.begin(), n.end(), '-', '_');
      return n;
    });

}  // namespace

// Issue 22: assimp's triangulation is quadratic in a face's corners (3 x 10^4 corners took
// 2.2 s; an OBJ face of 10^7 corners, minutes to days). A face of more than
// limits::kMaxFaceCorners corners is refused before triangulation; 10^5 corners here (about
// 25 s of triangulation before).
TEST(LoadMesh, AFaceWithTooManyCornersIsRefusedBeforeTriangulation) {
  constexpr int kCorners = 100000;
  std::string obj;
  obj.reserve(kCorners * 40);
  for (int i = 0; i < kCorners; ++i) {
    const double a = 2.0 * 3.141592653589793 * i / kCorners;
    obj += "v " + std::to_string(std::cos(a)) + " " + std::to_string(std::sin(a)) + " 0\n";
  }
  obj += "f";
  for (int i = 1; i <= kCorners; ++i) obj += " " + std::to_string(i);
  obj += "\n";
  const std::string p = write_temp("huge-face.obj", obj);
  expect_load_error(p, "face 0 has 100000 corners (expected at most 1024)");
  // At the limit: loaded and triangulated (a fan of 1022 triangles, welded).
  std::string ok;
  for (int i = 0; i < 1024; ++i) {
    const double a = 2.0 * 3.141592653589793 * i / 1024;
    ok += "v " + std::to_string(std::cos(a)) + " " + std::to_string(std::sin(a)) + " 0\n";
  }
  ok += "v 0 0 1\nf";
  for (int i = 1; i <= 1024; ++i) ok += " " + std::to_string(i);
  ok += "\n";
  for (int i = 1; i <= 1024; ++i) ok += "f " + std::to_string(i) + " " + std::to_string(i % 1024 + 1) + " 1025\n";
  EXPECT_GE(octocd::load_mesh(write_temp("limit-face.obj", ok)).triangles.size(), 1024u + 1022u - 10u);
}

/// A file of fuzz/regressions/mesh/ in the source tree ($OCTOCD_SOURCE_DIR, else ".").
std::string fuzz_regression(const std::string& name) {
  const char* src = std::getenv("OCTOCD_SOURCE_DIR");
  return std::string(src ? src : ".") + "/fuzz/regressions/mesh/" + name;
}

// Found by fuzz_mesh (issue 22, fuzz/regressions/mesh/fuzz-ply-ascii-list-4e18-oom.ply):
// assimp 5.2 allocates a PLY list's declared length before reading it, so a 237-byte
// file whose face declared 4 x 10^18 corners asked for 16 GB. Every list length of the
// body (ASCII and binary, little and big endian) is checked against kMaxFaceCorners first.
TEST(LoadMesh, APlyListLongerThanTheCornerLimitIsRefusedBeforeAssimp) {
  const std::string header_ascii =
      "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\n"
      "element face 2\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n";
  expect_load_error(write_temp("huge-list.ply", header_ascii + "3 0 1 2\n4000000000000000000 0 1 3\n"),
                    "PLY face 1 declares a list of 4000000000000000000 items (expected at most 1024 corners)");
  expect_load_error(write_temp("huge-list2.ply", header_ascii + "1025 0 1 2\n3 0 1 3\n"),
                    "PLY face 0 declares a list of 1025 items");
  EXPECT_EQ(octocd::load_mesh(write_temp("ok-list.ply", header_ascii + "3 0 1 2\n3 0 1 3\n")).triangles.size(), 2u);
  // Lines out of step with the header (the fuzzer's file had a short line and "3 0 F").
  expect_load_error(write_temp("word.ply", header_ascii + "3 0 F\n3 0 1 3\n"),
                    "PLY face 0: 'F' is not a number");
  expect_load_error(write_temp("short.ply", header_ascii + "3 0 1\n3 0 1 3\n"),
                    "PLY face 0: its line ends before its last property");
  expect_load_error(write_temp("long.ply", header_ascii + "3 0 1 2 3\n3 0 1 3\n"),
                    "PLY face 0: its line has values past its last property");
  expect_load_error(fuzz_regression("fuzz-ply-ascii-list-4e18-oom.ply"), "PLY vertex 2: its line ends before");
  // Binary: a uint count of 2^32 - 1 (little endian) and of 2000 (big endian).
  for (const bool little : {true, false}) {
    std::string f = std::string("ply\nformat ") + (little ? "binary_little_endian" : "binary_big_endian") +
                    " 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
                    "element face 1\nproperty list uint int vertex_indices\nend_header\n";
    f += std::string(36, '\0');  // 3 vertices at the origin
    const std::uint32_t c = little ? 0xFFFFFFFFu : 2000u;
    for (int k = 0; k < 4; ++k) f += static_cast<char>((c >> (8 * (little ? k : 3 - k))) & 0xFF);
    f += std::string(12, '\0');
    expect_load_error(write_temp(little ? "huge-list-le.ply" : "huge-list-be.ply", f),
                      "PLY face 0 declares a list of " + std::to_string(c) + " items");
  }
}

// Issue 57. Before: assimp allocated and parsed the arrays a PLY header declares, whatever
// the file holds: a 166-byte file declaring 9,999,999 vertices took seconds and hundreds of
// MB. Now the header's counts are checked against the bytes after it first.
TEST(LoadMesh, APlyHeaderDeclaringMoreThanItsBodyHoldsIsRefusedAtOnce) {
  const std::string text =
      "ply\nformat ascii 1.0\nelement vertex 9999999\nproperty float x\nproperty float y\nproperty float z\n"
      "element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n";
  const std::string path = write_temp("declares-ten-million.ply", text);
  const auto t0 = std::chrono::steady_clock::now();
  expect_load_error(path, "declares 9999999 vertex elements of at least 6 bytes each, but only 26 bytes follow");
  EXPECT_LT(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(), 0.5);
  // Binary: 12 bytes a vertex; the same 3 vertices with 9,999,999 declared.
  std::string bin = "ply\nformat binary_little_endian 1.0\nelement vertex 9999999\nproperty float x\nproperty float y\n"
                    "property float z\nend_header\n";
  bin += std::string(36, '\0');
  expect_load_error(write_temp("declares-ten-million-binary.ply", bin),
                    "declares 9999999 vertex elements of at least 12 bytes each, but only 36 bytes follow");
  // A body holding every declared element is read as before.
  const std::string fine =
      "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
      "element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n";
  EXPECT_EQ(octocd::load_mesh(write_temp("three.ply", fine)).triangles.size(), 1u);
}

// Issue 57. Before: an OBJ's `mtllib` was opened by assimp wherever it pointed: a FIFO
// there blocked the load forever (a device or /etc/... would be read). Now assimp opens
// the mesh file alone, so the FIFO is never opened and the geometry loads. The load runs in
// a child that an alarm ends, so the test fails rather than hangs.
TEST(LoadMesh, AnObjMaterialFileIsNeverOpened) {
  const std::string obj = write_temp("with-mtllib.obj", "mtllib blocks.mtl\nusemtl m\nv 0 0 0\nv 1 0 0\nv 0 1 0\n"
                                                          "v 0 0 1\nf 1 2 3\nf 1 2 4\nf 1 3 4\nf 2 3 4\n");
  const std::string fifo = (fs::path(obj).parent_path() / "blocks.mtl").string();
  fs::remove(fifo);
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
  const pid_t child = ::fork();
  ASSERT_GE(child, 0);
  if (child == 0) {
    ::alarm(20);
    try {
      const Mesh m = octocd::load_mesh(obj);
      ::_exit(m.triangles.size() == 4 ? 0 : 3);
    } catch (...) {
      ::_exit(4);
    }
  }
  int status = 0;
  ASSERT_EQ(::waitpid(child, &status, 0), child);
  fs::remove(fifo);
  ASSERT_FALSE(WIFSIGNALED(status)) << "the load blocked on the FIFO named by mtllib (signal " << WTERMSIG(status)
                                    << ")";
  EXPECT_EQ(WEXITSTATUS(status), 0) << "3: not the 4 triangles; 4: an exception";
}

}  // namespace octocd_test_mesh
