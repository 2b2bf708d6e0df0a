// Issue 12: the command line as a new user meets it. Each test reproduces one item of the
// issue: data lookup however the scene's path is spelled, the nightly script's exit codes,
// the summary's energy against the trace, `--frames` honoured by every validator, the
// command line checked as strictly as the scene file, messages in the documented form,
// the XDMF sidecar against the datasets it names, JUnit reports, docs/cli.md against
// `--help`.
#include <gtest/gtest.h>

#include <hdf5.h>
#include <libxml/parser.h>
#include <libxml/tree.h>
#include <libxml/xpath.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <memory>
#include <numeric>
#include <regex>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "command_table.hpp"
#include "octocd/engine_registry.hpp"
#include "octocd/validation_rows.hpp"
#include "support/cli_run.hpp"

// This file's own names (its tests compile in unity batches with the folder's other files).
namespace octocd_test_cli_usage {

namespace fs = std::filesystem;

namespace {

using octocd::test::Result;
using octocd::test::run;


/// The binary under test as an absolute path (the tests run it from other folders).
std::string bin() { return fs::absolute(octocd::test::bin()).string(); }

fs::path source_dir() {
  const char* s = std::getenv("OCTOCD_SOURCE_DIR");
  return s ? fs::path(s) : fs::path(".");
}

std::string quote(const std::string& s) { return "'" + s + "'"; }


/// `octocd ARGS`, run in folder `cwd` ("" = the current one).
Result octocd_cmd(const std::string& args, const fs::path& cwd = {}) {
  const std::string cd = cwd.empty() ? "" : "cd " + quote(cwd.string()) + " && ";
  return run(cd + quote(bin()) + " " + args);
}

std::string slurp(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::ostringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

void write_file(const fs::path& p, const std::string& text) {
  fs::create_directories(p.parent_path());
  std::ofstream(p, std::ios::binary) << text;
}

/// A closed tetrahedron, 1 m across (any small valid mesh).
constexpr const char* kTetraObj =
    "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n";

// ---- HDF5 reading (plain C API, read-only) ------------------------------------------

std::vector<hsize_t> dims_of(hid_t file, const std::string& name) {
  const hid_t d = H5Dopen2(file, name.c_str(), H5P_DEFAULT);
  if (d < 0) return {};
  const hid_t sp = H5Dget_space(d);
  std::vector<hsize_t> dims(static_cast<std::size_t>(H5Sget_simple_extent_ndims(sp)));
  H5Sget_simple_extent_dims(sp, dims.data(), nullptr);
  H5Sclose(sp);
  H5Dclose(d);
  return dims;
}

template <class T>
std::vector<T> read_all(hid_t file, const std::string& name, hid_t mem_type) {
  const std::vector<hsize_t> dims = dims_of(file, name);
  std::size_t n = dims.empty() ? 0 : 1;
  for (hsize_t x : dims) n *= static_cast<std::size_t>(x);
  std::vector<T> out(n);
  const hid_t d = H5Dopen2(file, name.c_str(), H5P_DEFAULT);
  EXPECT_GE(d, 0) << name;
  if (d < 0) return {};
  if (n > 0) {
    EXPECT_GE(H5Dread(d, mem_type, H5S_ALL, H5S_ALL, H5P_DEFAULT, out.data()), 0) << name;
  }
  H5Dclose(d);
  return out;
}

std::vector<std::string> read_strings(hid_t obj, const char* name, bool attribute) {
  const hid_t t = H5Tcopy(H5T_C_S1);
  H5Tset_size(t, H5T_VARIABLE);
  H5Tset_cset(t, H5T_CSET_UTF8);
  const hid_t h = attribute ? H5Aopen(obj, name, H5P_DEFAULT) : H5Dopen2(obj, name, H5P_DEFAULT);
  EXPECT_GE(h, 0) << name;
  std::vector<std::string> out;
  if (h >= 0) {
    const hid_t sp = attribute ? H5Aget_space(h) : H5Dget_space(h);
    const hssize_t n = H5Sget_simple_extent_npoints(sp);
    std::vector<char*> p(static_cast<std::size_t>(n), nullptr);
    if (n > 0) {
      const herr_t r = attribute ? H5Aread(h, t, p.data()) : H5Dread(h, t, H5S_ALL, H5S_ALL, H5P_DEFAULT, p.data());
      EXPECT_GE(r, 0) << name;
    }
    for (char* s : p) {
      out.emplace_back(s ? s : "");
      if (s) H5free_memory(s);
    }
    H5Sclose(sp);
    attribute ? H5Aclose(h) : H5Dclose(h);
  }
  H5Tclose(t);
  return out;
}

/// A trace opened read-only, closed on scope exit.
struct H5File {
  hid_t id;
  explicit H5File(const std::string& path) : id(H5Fopen(path.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT)) {}
  ~H5File() {
    if (id >= 0) H5Fclose(id);
  }
};

// ---- XML (libxml2, XPath) ---------------------------------------------------------------

/// An XML document parsed from a file; `nodes(xpath)` returns the matching elements.
class Xml {
 public:
  explicit Xml(const fs::path& path)
      : doc_(xmlReadFile(path.c_str(), nullptr, XML_PARSE_NONET | XML_PARSE_NOERROR | XML_PARSE_NOWARNING)) {}
  ~Xml() {
    if (doc_) xmlFreeDoc(doc_);
  }
  Xml(const Xml&) = delete;
  Xml& operator=(const Xml&) = delete;
  bool ok() const { return doc_ != nullptr; }

  std::vector<xmlNodePtr> nodes(const std::string& xpath, xmlNodePtr context = nullptr) const {
    std::vector<xmlNodePtr> out;
    if (!doc_) return out;
    xmlXPathContextPtr ctx = xmlXPathNewContext(doc_);
    if (context) ctx->node = context;
    xmlXPathObjectPtr r = xmlXPathEvalExpression(reinterpret_cast<const xmlChar*>(xpath.c_str()), ctx);
    if (r && r->nodesetval)
      for (int i = 0; i < r->nodesetval->nodeNr; ++i) out.push_back(r->nodesetval->nodeTab[i]);
    xmlXPathFreeObject(r);
    xmlXPathFreeContext(ctx);
    return out;
  }

  static std::string attr(xmlNodePtr n, const char* name) {
    xmlChar* v = xmlGetProp(n, reinterpret_cast<const xmlChar*>(name));
    std::string s = v ? reinterpret_cast<const char*>(v) : "";
    xmlFree(v);
    return s;
  }
  static std::string text(xmlNodePtr n) {
    xmlChar* v = xmlNodeGetContent(n);
    std::string s = v ? reinterpret_cast<const char*>(v) : "";
    xmlFree(v);
    return s;
  }

 private:
  xmlDocPtr doc_;
};

std::vector<hsize_t> parse_dims(const std::string& text) {
  std::istringstream in(text);
  std::vector<hsize_t> d;
  hsize_t x = 0;
  while (in >> x) d.push_back(x);
  return d;
}

/// The four groups of an XDMF 3 HDF5 hyperslab "file:/dataset|start:stride:count:dims"
/// (each a space-separated list, one value per dimension); empty when `ref` has no '|'.
std::vector<std::string> hdf_hyperslab(const std::string& ref) {
  const auto bar = ref.find('|');
  if (bar == std::string::npos) return {};
  std::vector<std::string> groups;
  std::istringstream in(ref.substr(bar + 1));
  for (std::string g; std::getline(in, g, ':');) groups.push_back(g);
  return groups;
}

class CliUser : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("octocd-user-" + std::to_string(::getpid()) + "-" +
                                        ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }

  /// A small valid scene: `count` boxes over a floor, top-level `extra` and group `shape`.
  static std::string scene_text(const std::string& extra = "", const std::string& shape = R"({"box": [0.1, 0.1, 0.1]})",
                                int count = 2, const std::string& name = "t") {
    return R"({"name": ")" + name + R"(", "domain": {"min": [-1, 0, -1], "max": [1, 2, 1]}, "frames": 20)" + extra +
           R"(, "groups": [{"name": "boxes", "shape": )" + shape + R"(, "count": )" + std::to_string(count) +
           "}]}";
  }
  std::string scene(const std::string& name, const std::string& text) {
    const fs::path p = dir_ / (name + ".json");
    write_file(p, text);
    return p.string();
  }

  fs::path dir_;
};

// The box-in-box scene of issue 6: Eq. 9 read as written never separates them, so
// non-penetration fails (exit 3) in a few frames.
constexpr const char* kFailingScene = R"({
  "name": "box-in-box", "domain": {"min": [-2, -2, -2], "max": [2, 2, 2]},
  "gravity": [0, 0, 0], "walls": "none", "frames": 20, "response": {"overlap": "paper"},
  "groups": [
    {"name": "big", "shape": {"box": [0.5, 0.5, 0.5]}, "count": 1, "mass": 1.0, "positions": [[0, 0, 0]]},
    {"name": "small", "shape": {"box": [0.1, 0.1, 0.1]}, "count": 1, "mass": 1.0, "positions": [[0.05, 0.2, 0.0]]}
  ]})";

}  // namespace

// ---- 1. data lookup independent of how the scene's path is spelled ------------------

// A project laid out as docs/scenes.md says (scenes/ beside cache/): `mix.json` from the
// scene's folder, `./mix.json`, an absolute path and a path from elsewhere all find
// cache/thing.obj. (Before: the bare name looked in the source tree's cache instead.)
TEST_F(CliUser, SceneNextToCacheFindsItHoweverSpelled) {
  write_file(dir_ / "proj" / "cache" / "thing.obj", kTetraObj);
  const fs::path scenes = dir_ / "proj" / "scenes";
  write_file(scenes / "mix.json", scene_text("", R"({"mesh": "thing", "scale": 0.2})"));
  for (const auto& [cwd, arg] : std::vector<std::pair<fs::path, std::string>>{
           {scenes, "mix.json"}, {scenes, "./mix.json"}, {scenes, (scenes / "mix.json").string()},
           {dir_, "proj/scenes/mix.json"}, {dir_ / "proj", "scenes/../scenes/mix.json"}}) {
    const Result r = octocd_cmd("run " + quote(arg) + " --quiet --frames 2", cwd);
    EXPECT_EQ(r.code, 0) << "cwd " << cwd << ", scene '" << arg << "':\n" << r.output;
  }
}

// A user's own folder (no ../cache) with a shipped dataset: every spelling falls back
// to the source tree's datasets/cache. (Before: `./mix.json` and absolute paths failed
// with exit 2 and "run datasets/fetch.sh" although the cache was there.)
TEST_F(CliUser, UserFolderFindsShippedDatasetsHoweverSpelled) {
  const fs::path cache = source_dir() / "datasets" / "cache";
  if (!fs::exists(cache / "bunny.obj") && !fs::exists(cache / "bunny.off") && !fs::exists(cache / "bunny.ply"))
    GTEST_SKIP() << "no bunny in " << cache << " (run datasets/fetch.sh)";
  const fs::path mine = dir_ / "mine";
  write_file(mine / "mix.json", scene_text("", R"({"mesh": "bunny", "scale": 0.2})"));
  for (const std::string& arg : {std::string("mix.json"), std::string("./mix.json"), (mine / "mix.json").string()}) {
    const Result r = run("cd " + quote(mine.string()) + " && env -u OCTOCD_DATA_DIR " + quote(bin()) + " run " +
                           quote(arg) + " --quiet --frames 2");
    EXPECT_EQ(r.code, 0) << "scene '" << arg << "':\n" << r.output;
  }
}

// --data-dir (docs/scenes.md's first place) works for run and validate; a folder that
// is not there is bad input naming the option.
TEST_F(CliUser, DataDirOption) {
  write_file(dir_ / "meshes" / "thing.obj", kTetraObj);
  const std::string path = scene("lonely", scene_text("", R"({"mesh": "thing", "scale": 0.2})"));
  Result r = octocd_cmd("run " + path + " --quiet --frames 2");
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find("groups[0].shape.mesh"), std::string::npos) << r.output;
  EXPECT_EQ(r.output.find("fetch.sh"), std::string::npos) << "'thing' is no dataset:\n" << r.output;
  r = octocd_cmd("run " + path + " --quiet --frames 2 --data-dir " + (dir_ / "meshes").string());
  EXPECT_EQ(r.code, 0) << r.output;
  r = octocd_cmd("validate " + path + " --frames 2 --against none --data-dir " + (dir_ / "meshes").string());
  EXPECT_EQ(r.code, 0) << r.output;
  r = octocd_cmd("run " + path + " --quiet --data-dir " + (dir_ / "nowhere").string());
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find("--data-dir: "), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("; allowed: "), std::string::npos) << r.output;
}

// ---- 6. messages in the documented form `file: key: problem; allowed: ...` -----------

TEST_F(CliUser, MessagesNameFileKeyAndAllowed) {
  // A wrong relative mesh path is searched as given, not as ".../bunny.obj.obj".
  std::string path = scene("relpath", scene_text("", R"({"mesh": "meshes/bunny.obj"})"));
  Result r = octocd_cmd("run " + path + " --quiet");
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_EQ(r.output.find(".obj.obj"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find(path + ": groups[0].shape.mesh: "), std::string::npos) << r.output;
  EXPECT_NE(r.output.find((dir_ / "meshes" / "bunny.obj").string()), std::string::npos) << r.output;

  // A mesh file without vertices: the scene file and the key come first.
  write_file(dir_ / "hollow.obj", "# no vertices here\no thing\n");
  path = scene("hollow", scene_text("", R"({"mesh": "hollow.obj"})"));
  r = octocd_cmd("run " + path + " --quiet");
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find(path + ": groups[0].shape.mesh: mesh file '"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("; allowed: "), std::string::npos) << r.output;

  // An unsupported format says which ones are.
  write_file(dir_ / "thing.gltf", R"({"asset": {"version": "2.0"}})");
  path = scene("gltf", scene_text("", R"({"mesh": "thing.gltf"})"));
  r = octocd_cmd("run " + path + " --quiet");
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find(path + ": groups[0].shape.mesh: "), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("allowed: a triangle mesh file in OBJ, OFF, PLY or STL format"), std::string::npos)
      << r.output;

  // An unknown broadphase: from the scene file (file and key) or from --broadphase.
  path = scene("kd", scene_text(R"(, "broadphase": {"name": "kd-tree"})"));
  for (const char* cmd : {"run", "validate"}) {
    r = octocd_cmd(std::string(cmd) + " " + path + " --frames 2");
    EXPECT_EQ(r.code, 2) << r.output;
    EXPECT_NE(r.output.find(path + ": broadphase.name: unknown broadphase 'kd-tree'; allowed: flat, octree"),
              std::string::npos)
        << r.output;
  }
  r = octocd_cmd("run " + scene("ok", scene_text()) + " --broadphase kd-tree --quiet");
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find("--broadphase: unknown broadphase 'kd-tree'; allowed: flat, octree"), std::string::npos)
      << r.output;
  EXPECT_NE(r.output.find("lbvh (--engine cuda)"), std::string::npos) << r.output;
  // `lbvh` exists on the device only: with the cpu engine (from either place) it is bad
  // input naming --engine cuda.
  r = octocd_cmd("run " + scene("ok", scene_text()) + " --broadphase lbvh --quiet");
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find("--broadphase: broadphase 'lbvh' exists on the device only; allowed: --engine cuda"),
            std::string::npos)
      << r.output;
  path = scene("lbvh", scene_text(R"(, "broadphase": {"name": "lbvh"})"));
  r = octocd_cmd("run " + path + " --frames 2 --quiet");
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find(path + ": broadphase.name: broadphase 'lbvh' exists on the device only"),
            std::string::npos)
      << r.output;
}

// ---- 5. the command line is checked as the scene file is ----------------------------

TEST_F(CliUser, CommandLineCheckedLikeSceneFile) {
  const std::string ok = scene("ok", scene_text());
  // The scene file rejects levels deeper than midphase.depth (default 2); so does --midphase.
  Result r = octocd_cmd("run " + scene("deep", scene_text(R"(, "midphase": {"levels": "3"})")) + " --quiet");
  EXPECT_EQ(r.code, 2) << r.output;
  r = octocd_cmd("run " + ok + " --midphase 3 --quiet");
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find("--midphase: "), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("midphase.depth"), std::string::npos) << r.output;
  EXPECT_EQ(octocd_cmd("run " + scene("deep-ok", scene_text(R"(, "midphase": {"depth": 3})")) +
                   " --midphase 3 --quiet").code,
            0);

  // Bullet runs neither an octocd midphase nor another broadphase: saying so is bad input.
  r = octocd_cmd("run " + ok + " --engine bullet --midphase 0,1,2 --quiet");
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find("--midphase: engine bullet"), std::string::npos) << r.output;
  r = octocd_cmd("run " + ok + " --engine bullet --broadphase fcl-naive --quiet");
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find("--broadphase: engine bullet"), std::string::npos) << r.output;
  // ... and its trace records what it ran (box mode: btBoxBoxDetector on the AABB boxes).
  const std::string trace = (dir_ / "bullet.h5").string();
  r = octocd_cmd("run " + ok + " --engine bullet --bullet shape=box --quiet --trace " + trace);
  ASSERT_EQ(r.code, 0) << r.output;
  {
    H5File f(trace);
    ASSERT_GE(f.id, 0);
    EXPECT_EQ(read_strings(f.id, "midphase", true), std::vector<std::string>{"bullet-box-box"});
    EXPECT_EQ(read_strings(f.id, "broadphase", true), std::vector<std::string>{"bullet-dbvt"});
    const auto params = nlohmann::json::parse(read_strings(f.id, "parameters", true).at(0));
    EXPECT_EQ(params["midphase"], "bullet-box-box");
    EXPECT_EQ(params["broadphase"]["name"], "bullet-dbvt");
  }

  // --frames 0 says the range in a line, not a 300-digit double.
  for (const char* cmd : {"run", "validate"}) {
    r = octocd_cmd(std::string(cmd) + " " + ok + " --frames 0");
    EXPECT_EQ(r.code, 2) << r.output;
    EXPECT_NE(r.output.find("--frames: 0 is out of range; allowed: an integer in [1, 2147483647]"), std::string::npos)
        << r.output;
    EXPECT_LT(r.output.size(), 200u) << r.output;
  }

  // "dt": 0.1 is the documented inclusive maximum (float32 0.1 is above the double 0.1).
  r = octocd_cmd("run " + scene("dt", scene_text(R"(, "dt": 0.1)")) + " --quiet --frames 2");
  EXPECT_EQ(r.code, 0) << r.output;
  r = octocd_cmd("run " + scene("dt-big", scene_text(R"(, "dt": 0.1000001)")) + " --quiet --frames 2");
  EXPECT_EQ(r.code, 2) << r.output;
}

// ---- 4. the summary: energy against the trace, pairs apart, Bullet comparable ------

namespace {

struct TraceColumns {
  std::vector<double> energy;
  std::vector<std::uint64_t> aabb, dynamic, candidates;
};

TraceColumns read_columns(const std::string& trace) {
  H5File f(trace);
  EXPECT_GE(f.id, 0) << trace;
  TraceColumns c;
  if (f.id < 0) return c;
  c.energy = read_all<double>(f.id, "/frames/kinetic_energy", H5T_NATIVE_DOUBLE);
  c.aabb = read_all<std::uint64_t>(f.id, "/frames/aabb_pairs", H5T_NATIVE_UINT64);
  c.dynamic = read_all<std::uint64_t>(f.id, "/frames/dynamic_pairs", H5T_NATIVE_UINT64);
  c.candidates = read_all<std::uint64_t>(f.id, "/frames/cell_candidates", H5T_NATIVE_UINT64);
  return c;
}

}  // namespace

// The summary's kinetic energy (mean, max, last) is the trace's, for the CPU engine and
// for Bullet (before: the last frame's value in the "mean" column, 0 for Bullet while
// the trace held 23 J, and nothing in --summary-json).
TEST_F(CliUser, SummaryEnergyMatchesTrace) {
  // Boxes in a closed box with random velocities: energy changes every frame.
  const std::string path = scene(
      "energy",
      scene_text(R"(, "walls": "closed-box", "gravity": [0, -3, 0])",
                 R"({"box": [0.1, 0.1, 0.1]}, "velocity": {"type": "random", "max": 2, "seed": 3})", 12));
  for (const char* engine : {"cpu", "bullet"}) {
    const std::string trace = (dir_ / (std::string(engine) + ".h5")).string();
    const std::string json = (dir_ / (std::string(engine) + ".json")).string();
    const Result r = octocd_cmd("run " + path + " --engine " + engine + " --frames 150 --trace " + trace +
                            " --summary-json " + json + " 2>/dev/null");
    ASSERT_EQ(r.code, 0) << r.output;
    const TraceColumns c = read_columns(trace);
    ASSERT_EQ(c.energy.size(), 150u);
    const double mean = std::accumulate(c.energy.begin(), c.energy.end(), 0.0) / 150.0;
    const double max = *std::max_element(c.energy.begin(), c.energy.end());
    ASSERT_GT(max, 0.1) << engine;
    const auto j = nlohmann::json::parse(slurp(json));
    EXPECT_NEAR(j["kinetic_energy"]["mean"].get<double>(), mean, 1e-9 * max) << engine;
    EXPECT_NEAR(j["kinetic_energy"]["max"].get<double>(), max, 1e-12 * max) << engine;
    EXPECT_NEAR(j["kinetic_energy"]["last"].get<double>(), c.energy.back(), 1e-12 * max) << engine;
    // The printed row: label, mean, max, last (4 decimals).
    const std::regex row(R"(kinetic energy \(J\)\s+([0-9.]+)\s+([0-9.]+)\s+([0-9.]+))");
    std::smatch m;
    ASSERT_TRUE(std::regex_search(r.output, m, row)) << r.output;
    EXPECT_NEAR(std::stod(m[1]), mean, 1e-4) << engine;
    EXPECT_NEAR(std::stod(m[2]), max, 1e-4) << engine;
    EXPECT_NEAR(std::stod(m[3]), c.energy.back(), 1e-4) << engine;
    EXPECT_NE(r.output.find("per frame                          mean            max           last"),
              std::string::npos)
        << r.output;
  }
}

// AABB pairs keep their meaning (static-static included); dynamic_pairs leaves out the
// wall-wall pairs: 12 in a closed box, 8 in an open one, on every frame of every engine.
TEST_F(CliUser, DynamicPairsLeaveOutWallPairs) {
  for (const auto& [walls, static_pairs] : std::vector<std::pair<std::string, std::uint64_t>>{
           {"closed-box", 12}, {"open-box", 8}, {"floor", 0}}) {
    const std::string path = scene(walls, scene_text(R"(, "walls": ")" + walls + R"(")", R"({"box": [0.1, 0.1, 0.1]})", 30));
    for (const char* engine : {"cpu", "bullet"}) {
      const std::string trace = (dir_ / (walls + engine + ".h5")).string();
      const std::string json = (dir_ / (walls + engine + ".json")).string();
      const Result r = octocd_cmd("run " + path + " --engine " + engine + " --frames 40 --quiet --trace " + trace +
                              " --summary-json " + json);
      ASSERT_EQ(r.code, 0) << r.output;
      const TraceColumns c = read_columns(trace);
      ASSERT_EQ(c.aabb.size(), 40u);
      ASSERT_EQ(c.dynamic.size(), 40u);
      std::uint64_t landed = 0;
      for (std::size_t i = 0; i < c.aabb.size(); ++i) {
        EXPECT_EQ(c.aabb[i] - c.dynamic[i], static_pairs) << walls << " " << engine << " frame " << i + 1;
        landed = std::max(landed, c.dynamic[i]);
      }
      EXPECT_GT(landed, 0u) << walls << " " << engine;  // the bottom layer touches the floor
      const auto j = nlohmann::json::parse(slurp(json));
      EXPECT_NEAR(j["mean_pairs"].get<double>() - j["mean_dynamic_pairs"].get<double>(),
                  static_cast<double>(static_pairs), 1e-9);
    }
  }
}

// The Bullet engine reports every stage and counts pairs as octocd does: on the same
// state both engines count the same AABB and dynamic pairs; its candidates (the pair
// cache) are its own, and the summary says why (before: all stages but "response" 0
// and 338 "AABB pairs" against the CPU's 11.6).
TEST_F(CliUser, BulletStagesAndPairsCompare) {
  // No gravity, at rest: three pairs overlap by 2 cm (two box-box, one box-floor), one box
  // is alone; 12 wall-wall pairs. Frame 1 of both engines sees the initial positions.
  const std::string path = scene("pairs", R"({"name": "pairs", "domain": {"min": [-1, 0, -1], "max": [1, 2, 1]},
    "gravity": [0, 0, 0], "walls": "closed-box", "frames": 50,
    "groups": [{"name": "b", "shape": {"box": [0.1, 0.1, 0.1]}, "count": 6,
                "positions": [[0, 1, 0], [0.18, 1, 0], [0.6, 1, 0], [0.6, 1.18, 0], [-0.6, 1, 0], [-0.6, 0.08, 0]]}]})");
  std::map<std::string, nlohmann::json> summary;
  std::map<std::string, TraceColumns> cols;
  for (const char* engine : {"cpu", "bullet"}) {
    const std::string json = (dir_ / (std::string(engine) + ".json")).string();
    const std::string trace = (dir_ / (std::string(engine) + ".h5")).string();
    // Bullet in box mode (boxes equal to the AABBs): the scene's boxes either way, named so.
    const std::string settings = std::string(engine) == "bullet" ? " --bullet shape=box" : "";
    const Result r = octocd_cmd("run " + path + " --engine " + engine + settings + " --trace " + trace +
                                " --summary-json " + json + " 2>/dev/null");
    ASSERT_EQ(r.code, 0) << r.output;
    summary[engine] = nlohmann::json::parse(slurp(json));
    cols[engine] = read_columns(trace);
    ASSERT_EQ(cols[engine].aabb.size(), 50u) << engine;
    ASSERT_EQ(cols[engine].dynamic.size(), 50u) << engine;
    ASSERT_EQ(cols[engine].candidates.size(), 50u) << engine;
    EXPECT_EQ(cols[engine].aabb[0], 15u) << engine;
    EXPECT_EQ(cols[engine].dynamic[0], 3u) << engine;
    if (std::string(engine) == "bullet") {
      EXPECT_NE(r.output.find("engine bullet: broadphase candidates are Bullet's pair cache"), std::string::npos)
          << r.output;
      EXPECT_NE(r.output.find("midphase bullet-box-box"), std::string::npos) << r.output;
    }
  }
  for (const char* stage : {"integrate", "aabbs", "broadphase", "midphase", "response", "metrics"}) {
    ASSERT_TRUE(summary["bullet"]["stage_ms"][stage].is_number()) << stage;
    EXPECT_GT(summary["bullet"]["stage_ms"][stage].get<double>(), 0.0) << stage;
  }
  // Bullet's cache holds at least the pairs whose exact AABBs overlap (fattened boxes).
  for (std::size_t i = 0; i < 50; ++i)
    EXPECT_GE(cols["bullet"].candidates[i], cols["bullet"].dynamic[i]) << "frame " << i + 1;
}

// ---- 3. validate --frames N is honoured by every validator ---------------------------

namespace {

/// Every frame number the output mentions ("frame 319", "after 3000 frames", "300 frames").
std::vector<long> frame_numbers(const std::string& text) {
  std::vector<long> out;
  const std::regex re(R"(\bframes? (\d+)\b|\b(\d+) frames\b)");
  for (std::sregex_iterator it(text.begin(), text.end(), re), end; it != end; ++it)
    out.push_back(std::stol((*it)[1].matched ? (*it)[1].str() : (*it)[2].str()));
  return out;
}

}  // namespace

TEST_F(CliUser, ValidateFramesHonouredByEveryValidator) {
  const fs::path scenes = source_dir() / "datasets" / "scenes";
  // bounce: the bounce happens at frame ~320, after the 300 asked for; box-stack: the
  // settling time (200) is longer than the 150 asked for; both compared with Bullet.
  for (const auto& [name, frames] : std::vector<std::pair<std::string, long>>{{"bounce", 300}, {"box-stack", 150}}) {
    const Result r = octocd_cmd("validate " + (scenes / (name + ".json")).string() + " --frames " +
                            std::to_string(frames) + " --every 50 --against bullet");
    EXPECT_EQ(r.code, 3) << name << ": the event lies past --frames, analytic must fail:\n" << r.output;
    const std::vector<long> seen = frame_numbers(r.output);
    ASSERT_FALSE(seen.empty()) << r.output;
    for (long f : seen) EXPECT_LE(f, frames) << name << ": a validator ran past --frames " << frames << ":\n" << r.output;
    EXPECT_NE(std::find(seen.begin(), seen.end(), frames), seen.end()) << r.output;
  }
  // A long enough run passes and the Bullet comparison says how long it ran.
  const Result r = octocd_cmd("validate " + (scenes / "box-stack.json").string() + " --frames 230 --every 50 --against bullet");
  EXPECT_EQ(r.code, 0) << r.output;
  EXPECT_NE(r.output.find("after 230 frames"), std::string::npos) << r.output;
  for (long f : frame_numbers(r.output)) EXPECT_LE(f, 230) << r.output;
}

// ---- 7. XDMF sidecar, checked as XML against the HDF5 datasets it names --------------

TEST_F(CliUser, TraceWritesXdmfSidecarMatchingTheTrace) {
  const std::string path = scene("two", R"({"name": "two", "domain": {"min": [-1, 0, -1], "max": [1, 2, 1]},
    "walls": "open-box", "frames": 25,
    "groups": [{"name": "small", "shape": {"box": [0.05, 0.1, 0.15]}, "count": 3},
               {"name": "big", "shape": {"box": [0.2, 0.2, 0.2]}, "count": 2}]})");
  const std::string trace = (dir_ / "two.h5").string();
  Result r = octocd_cmd("run " + path + " --trace " + trace + " --state-every 10 2>/dev/null");
  ASSERT_EQ(r.code, 0) << r.output;
  const fs::path xmf = trace + ".xmf";
  ASSERT_TRUE(fs::exists(xmf)) << r.output;
  EXPECT_NE(r.output.find(xmf.string()), std::string::npos) << "the summary names the sidecar:\n" << r.output;

  Xml x(xmf);
  ASSERT_TRUE(x.ok()) << "not well-formed XML:\n" << slurp(xmf);
  H5File f(trace);
  ASSERT_GE(f.id, 0);
  const std::vector<std::int64_t> state_frames = read_all<std::int64_t>(f.id, "/states/frame", H5T_NATIVE_INT64);
  ASSERT_EQ(state_frames, (std::vector<std::int64_t>{0, 10, 20}));
  const std::size_t n = 5 + 5;  // walls (floor + 4 sides) + bodies

  // One grid per state row, at time frame x dt.
  const auto grids = x.nodes("/Xdmf/Domain/Grid[@CollectionType='Temporal']/Grid");
  ASSERT_EQ(grids.size(), state_frames.size());
  for (std::size_t g = 0; g < grids.size(); ++g) {
    const auto time = x.nodes("Time", grids[g]);
    ASSERT_EQ(time.size(), 1u);
    EXPECT_NEAR(std::stod(Xml::attr(time[0], "Value")), 0.001 * static_cast<double>(state_frames[g]), 1e-6);
    // Geometry: row g of /states/position, as an XDMF 3 HDF5 hyperslab
    // "file:/dataset|start:stride:count:dataset dimensions" of n x 3 values.
    const auto geo = x.nodes("Geometry[@GeometryType='XYZ']/DataItem[@Format='HDF']", grids[g]);
    ASSERT_EQ(geo.size(), 1u);
    EXPECT_EQ(parse_dims(Xml::attr(geo[0], "Dimensions")), (std::vector<hsize_t>{n, 3}));
    const std::vector<std::string> slab = hdf_hyperslab(Xml::text(geo[0]));
    ASSERT_EQ(slab.size(), 4u) << Xml::text(geo[0]);
    EXPECT_EQ(parse_dims(slab[0]), (std::vector<hsize_t>{g, 0, 0})) << "start";
    EXPECT_EQ(parse_dims(slab[1]), (std::vector<hsize_t>{1, 1, 1})) << "stride";
    EXPECT_EQ(parse_dims(slab[2]), (std::vector<hsize_t>{1, n, 3})) << "count";
    EXPECT_EQ(parse_dims(slab[3]), dims_of(f.id, "/states/position")) << "dataset dimensions";
    // Every attribute a viewer needs to draw the boxes the right size and colour.
    std::set<std::string> names;
    for (xmlNodePtr a : x.nodes("Attribute", grids[g])) names.insert(Xml::attr(a, "Name"));
    EXPECT_EQ(names, (std::set<std::string>{"velocity", "shape_id", "inverse_mass", "half_extents", "group_id"}));
  }

  // Every HDF item names a dataset of this trace, with its dimensions.
  const auto items = x.nodes("//DataItem[@Format='HDF']");
  // position and velocity slabs, shape_id, inverse_mass, half_extents, group_id
  ASSERT_EQ(items.size(), 6u * grids.size());
  for (xmlNodePtr item : items) {
    const std::string ref = Xml::text(item);
    const auto colon = ref.find(':');
    ASSERT_NE(colon, std::string::npos) << ref;
    EXPECT_EQ(ref.substr(0, colon), "two.h5") << "the sidecar names the trace by file name";
    const auto bar = ref.find('|');
    const std::string dataset = ref.substr(colon + 1, bar == std::string::npos ? std::string::npos : bar - colon - 1);
    if (bar == std::string::npos) {
      EXPECT_EQ(parse_dims(Xml::attr(item, "Dimensions")), dims_of(f.id, dataset)) << dataset;
      continue;
    }
    // A hyperslab: its dataset dimensions are the dataset's, it lies inside them, and the
    // item's Dimensions are its count without the leading 1 (one state row).
    const std::vector<std::string> slab = hdf_hyperslab(ref);
    ASSERT_EQ(slab.size(), 4u) << ref;
    const auto start = parse_dims(slab[0]), count = parse_dims(slab[2]), dims = parse_dims(slab[3]);
    EXPECT_EQ(dims, dims_of(f.id, dataset)) << ref;
    ASSERT_EQ(start.size(), dims.size()) << ref;
    ASSERT_EQ(count.size(), dims.size()) << ref;
    for (std::size_t k = 0; k < dims.size(); ++k) EXPECT_LE(start[k] + count[k], dims[k]) << ref;
    EXPECT_EQ(count.front(), 1u) << ref;
    EXPECT_EQ(parse_dims(Xml::attr(item, "Dimensions")), std::vector<hsize_t>(count.begin() + 1, count.end())) << ref;
  }

  // The values: half extents of each body, and group ids that map to the group names.
  const auto half = read_all<float>(f.id, "/bodies/half_extents", H5T_NATIVE_FLOAT);
  const auto lo = read_all<float>(f.id, "/bodies/local_aabb_min", H5T_NATIVE_FLOAT);
  const auto hi = read_all<float>(f.id, "/bodies/local_aabb_max", H5T_NATIVE_FLOAT);
  ASSERT_EQ(half.size(), 3 * n);
  for (std::size_t i = 0; i < 3 * n; ++i) EXPECT_FLOAT_EQ(half[i], 0.5f * (hi[i] - lo[i])) << i;
  EXPECT_FLOAT_EQ(half[3 * 5 + 0], 0.05f);  // the first body after the walls: small
  EXPECT_FLOAT_EQ(half[3 * 5 + 2], 0.15f);
  EXPECT_FLOAT_EQ(half[3 * 9 + 1], 0.2f);  // the last: big
  const auto gid = read_all<std::int32_t>(f.id, "/bodies/group_id", H5T_NATIVE_INT32);
  const auto gnames = read_strings(f.id, "/bodies/group_names", false);
  const auto group = read_strings(f.id, "/bodies/group", false);
  EXPECT_EQ(gnames, (std::vector<std::string>{"walls", "small", "big"}));
  ASSERT_EQ(gid.size(), n);
  for (std::size_t i = 0; i < n; ++i) EXPECT_EQ(gnames.at(static_cast<std::size_t>(gid[i])), group[i]) << i;

  // --no-xdmf: no sidecar.
  const std::string quiet = (dir_ / "quiet.h5").string();
  r = octocd_cmd("run " + path + " --trace " + quiet + " --no-xdmf --quiet");
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_TRUE(fs::exists(quiet));
  EXPECT_FALSE(fs::exists(quiet + ".xmf"));
}

// ---- JUnit reports (issue 9 item 4) ---------------------------------------------------

TEST_F(CliUser, ValidateWritesJUnit) {
  const std::string stack = (source_dir() / "datasets" / "scenes" / "box-stack.json").string();
  const fs::path pass_xml = dir_ / "pass.xml";
  Result r = octocd_cmd("validate " + stack + " --frames 210 --every 70 --against none --junit " + pass_xml.string());
  ASSERT_EQ(r.code, 0) << r.output;
  {
    Xml x(pass_xml);
    ASSERT_TRUE(x.ok()) << slurp(pass_xml);
    const auto cases = x.nodes("//testsuite/testcase");
    // One case per row of the table (validation_rows.def), each row in the printed table.
    std::size_t rows = 0;
    for (const octocd::RowInfo& v : octocd::validation_rows())
      rows += r.output.find(std::string(" ") + v.name + " ") != std::string::npos ? 1 : 0;
    EXPECT_EQ(cases.size(), rows);
    EXPECT_EQ(cases.size(), octocd::validation_rows().size());
    EXPECT_GE(cases.size(), 16u);
    // Each row of the table (tier, validator) is one case "box-stack.TIER" / validator,
    // with its own time (s): >= 0, and together within the suite's time.
    std::set<std::string> table_rows, names;
    std::istringstream table(r.output);
    for (std::string line; std::getline(table, line);) {
      std::istringstream w(line);
      std::string tier, name;
      if (w >> tier >> name && (tier == "physics" || tier == "model")) table_rows.insert(tier + "/" + name);
    }
    EXPECT_EQ(table_rows.size(), octocd::validation_rows().size()) << r.output;
    double sum = 0;
    for (xmlNodePtr c : cases) {
      const std::string classname = Xml::attr(c, "classname");
      ASSERT_EQ(classname.rfind("box-stack.", 0), 0u) << classname;
      names.insert(classname.substr(std::string("box-stack.").size()) + "/" + Xml::attr(c, "name"));
      const std::string time = Xml::attr(c, "time");
      ASSERT_FALSE(time.empty());
      EXPECT_GE(std::stod(time), 0.0) << time;
      sum += std::stod(time);
    }
    EXPECT_EQ(names, table_rows) << "one case per row of the table";
    EXPECT_TRUE(names.count("model/analytic"));
    EXPECT_TRUE(names.count("physics/penetration"));
    EXPECT_GT(sum, 0.0) << "the rows' own times are measured";
    EXPECT_LE(sum, std::stod(Xml::attr(x.nodes("//testsuite")[0], "time")) + 1e-3);
    EXPECT_TRUE(x.nodes("//failure").empty());
    EXPECT_TRUE(x.nodes("//error").empty());
    const auto suite = x.nodes("//testsuite");
    ASSERT_EQ(suite.size(), 1u);
    EXPECT_EQ(Xml::attr(suite[0], "tests"), std::to_string(cases.size()));
    EXPECT_EQ(Xml::attr(suite[0], "failures"), "0");
    EXPECT_EQ(Xml::attr(suite[0], "skipped"), std::to_string(x.nodes("//testcase/skipped").size()));
  }

  // A failing scene: the report is written, with the failure's detail line.
  const fs::path fail_xml = dir_ / "fail.xml";
  r = octocd_cmd("validate " + scene("box-in-box", kFailingScene) + " --frames 20 --every 5 --against none --junit " +
             fail_xml.string());
  ASSERT_EQ(r.code, 3) << r.output;
  {
    Xml x(fail_xml);
    ASSERT_TRUE(x.ok()) << slurp(fail_xml);
    const auto failures = x.nodes("//testcase/failure");
    ASSERT_GE(failures.size(), 1u);
    EXPECT_EQ(Xml::attr(x.nodes("//testsuite")[0], "failures"), std::to_string(failures.size()));
    const auto np = x.nodes("//testcase[@name='non-penetration-eq14']/failure");
    ASSERT_EQ(np.size(), 1u);
    // "measured X > bound Y (figure): detail": the figures first, then the table's detail line.
    const std::string message = Xml::attr(np[0], "message");
    ASSERT_EQ(message.rfind("measured ", 0), 0u) << message;
    EXPECT_NE(message.find(" > bound 0 (contacts violating Eq. 14 contraction): "), std::string::npos) << message;
    const std::string detail = message.substr(message.find("): ") + 3);
    EXPECT_FALSE(detail.empty());
    EXPECT_NE(r.output.find(detail.substr(0, 40)), std::string::npos) << "the table's detail line:\n" << r.output;
    for (xmlNodePtr c : x.nodes("//testcase")) EXPECT_EQ(Xml::attr(c, "classname").rfind("box-in-box.", 0), 0u);
    for (xmlNodePtr f : failures) EXPECT_EQ(Xml::attr(f, "message").rfind("measured ", 0), 0u);
  }

  // Bad input: one errored case, exit 2.
  const fs::path bad_xml = dir_ / "bad.xml";
  r = octocd_cmd("validate " + scene("bad", scene_text(R"(, "dt": -1)")) + " --junit " + bad_xml.string());
  ASSERT_EQ(r.code, 2) << r.output;
  Xml x(bad_xml);
  ASSERT_TRUE(x.ok()) << slurp(bad_xml);
  EXPECT_EQ(x.nodes("//testcase/error").size(), 1u);
  EXPECT_NE(Xml::attr(x.nodes("//testcase/error")[0], "message").find("dt"), std::string::npos);
}

// ---- 2. the nightly script: non-zero on any failure, 2 on bad input ------------------

// ---- expectations (design.md section 14b) and --json: box-in-box fails non-penetration-eq14 (4 contacts)
TEST_F(CliUser, ValidateExpectationsGateOnNewAndGrownFailures) {
  const std::string fail = scene("box-in-box", kFailingScene);
  const std::string args = " --frames 20 --every 5 --against none";
  const fs::path expect = dir_ / "expect.json", out_json = dir_ / "out.json", xml = dir_ / "j.xml";
  // Without expectations: the failure is new, named in plain text (no XML escapes).
  Result r = octocd_cmd("validate " + fail + args);
  ASSERT_EQ(r.code, 3) << r.output;
  EXPECT_NE(r.output.find("NEW FAILURE non-penetration-eq14/non-penetration-eq14: measured 4 > bound 0"),
            std::string::npos) << r.output;
  EXPECT_EQ(r.output.find("&gt;"), std::string::npos) << r.output;
  // --write-expect records it (exit 0); --expect then passes, the row reads `expected`.
  r = octocd_cmd("validate " + fail + args + " --write-expect " + expect.string());
  ASSERT_EQ(r.code, 0) << r.output;
  nlohmann::json e = nlohmann::json::parse(slurp(expect));
  ASSERT_EQ(e["expectations"].size(), 1u) << e.dump();
  EXPECT_EQ(e["expectations"][0]["scene"], "box-in-box");
  EXPECT_EQ(e["expectations"][0]["worst"], 4.0);
  r = octocd_cmd("validate " + fail + args + " --expect " + expect.string() + " --junit " + xml.string() +
                 " --json " + out_json.string());
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_NE(r.output.find("expected non-penetration-eq14/non-penetration-eq14: worst 4 <= allowed 4"),
            std::string::npos) << r.output;
  EXPECT_EQ(r.output.find("within 10% of the allowance"), std::string::npos) << r.output;  // a count, exact
  EXPECT_NE(r.output.find("all validators pass or fail as expected (1 expected failure(s)"), std::string::npos);
  {
    Xml x(xml);
    ASSERT_TRUE(x.ok()) << slurp(xml);
    EXPECT_TRUE(x.nodes("//testcase/failure").empty());
    const auto skipped = x.nodes("//testcase[@name='non-penetration-eq14']/skipped");
    ASSERT_EQ(skipped.size(), 1u);
    EXPECT_EQ(Xml::attr(skipped[0], "message").rfind("expected: non-penetration-eq14 worst 4 <= allowed 4", 0), 0u)
        << Xml::attr(skipped[0], "message");
  }
  const nlohmann::json j = nlohmann::json::parse(slurp(out_json));
  ASSERT_EQ(j["rows"].size(), octocd::validation_rows().size());
  for (const auto& row : j["rows"]) {
    if (row["name"] == "non-penetration-eq14") {
      EXPECT_EQ(row["verdict"], "expected");
      ASSERT_EQ(row["causes"].size(), 1u);
      EXPECT_EQ(row["causes"][0]["count"], 4);
    } else if (row["name"] == "analytic") {
      EXPECT_EQ(row["verdict"], "n/a");
    }
  }
  // Grown: a figure below the measured one fails (exit 3), named.
  e["expectations"][0]["worst"] = 3;
  write_file(expect, e.dump());
  r = octocd_cmd("validate " + fail + args + " --expect " + expect.string() + " --junit " + xml.string());
  EXPECT_EQ(r.code, 3) << r.output;
  EXPECT_NE(r.output.find("GROWN non-penetration-eq14/non-penetration-eq14: worst 4 > allowed 3"), std::string::npos)
      << r.output;
  {
    Xml x(xml);
    ASSERT_EQ(x.nodes("//testcase[@name='non-penetration-eq14']/failure").size(), 1u);
  }
  // Fixed: an expectation of a row that passes is reported; exit 3 only with --strict.
  e["expectations"][0]["worst"] = 4;
  e["expectations"].push_back({{"scene", "box-in-box"}, {"row", "conservation"}, {"cause", "energy"},
                               {"worst", 0.01}, {"reason", "planted"}});
  write_file(expect, e.dump());
  r = octocd_cmd("validate " + fail + args + " --expect " + expect.string());
  EXPECT_EQ(r.code, 0) << r.output;
  EXPECT_NE(r.output.find("fixed conservation/energy: no longer fails: remove it from " + expect.string()),
            std::string::npos) << r.output;
  EXPECT_EQ(octocd_cmd("validate " + fail + args + " --expect " + expect.string() + " --strict").code, 3);
  // Bad input: exit 2 naming the file and the entry, before anything runs.
  write_file(expect, R"({"expectations": [{"scene": "box-in-box", "row": "non-penetration-eq14",
      "cause": "non-penetration-eq14", "worst": -1, "reason": "r"}]})");
  r = octocd_cmd("validate " + fail + args + " --expect " + expect.string());
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.output.find(expect.string() + ": expectations[0] (worst): -1 is out of range"), std::string::npos)
      << r.output;
  write_file(expect, "not json");
  EXPECT_EQ(octocd_cmd("validate " + fail + args + " --expect " + expect.string()).code, 2);
}

TEST_F(CliUser, NightlyScriptExitCodesAndJUnit) {
  const std::string script = (source_dir() / "scripts" / "nightly.sh").string();
  ASSERT_TRUE(fs::exists(script));
  const std::string pass = (source_dir() / "datasets" / "scenes" / "free-fall.json").string();
  const std::string fail = scene("box-in-box", kFailingScene);
  const std::string bad = scene("bad", scene_text(R"(, "dt": "fast")"));
  auto nightly = [&](const std::string& out, const std::string& scenes) {
    return run("OCTOCD_BIN=" + quote(bin()) + " bash " + quote(script) + " --frames 20 --every 10 --out " +
                 quote((dir_ / out).string()) + " " + scenes);
  };
  Result r = nightly("ok", pass);
  EXPECT_EQ(r.code, 0) << r.output;
  r = nightly("failing", pass + " " + fail);
  EXPECT_EQ(r.code, 3) << r.output;
  EXPECT_NE(r.output.find("FAILED"), std::string::npos) << r.output;
  r = nightly("bad", pass + " " + fail + " " + bad);
  EXPECT_EQ(r.code, 2) << r.output;

  // One merged JUnit report over the scenes (and one per scene).
  Xml x(dir_ / "bad" / "junit.xml");
  ASSERT_TRUE(x.ok()) << slurp(dir_ / "bad" / "junit.xml");
  const auto suites = x.nodes("/testsuites/testsuite");
  ASSERT_EQ(suites.size(), 3u);
  std::size_t physics = 0, model = 0;
  for (const octocd::RowInfo& row : octocd::validation_rows()) ++(row.tier == octocd::Tier::Physics ? physics : model);
  EXPECT_EQ(x.nodes("//testcase[@classname='free-fall.physics']").size(), physics);
  EXPECT_EQ(x.nodes("//testcase[@classname='free-fall.model']").size(), model);
  EXPECT_GE(x.nodes("//testcase[starts-with(@classname, 'box-in-box.')]/failure").size(), 1u);
  {
    // The merged report keeps each case's own time, as the scene's report has it.
    Xml one(dir_ / "bad" / "junit" / "free-fall.xml");
    ASSERT_TRUE(one.ok());
    std::vector<std::string> merged_times, own_times;
    for (xmlNodePtr c : x.nodes("//testcase[starts-with(@classname, 'free-fall.')]"))
      merged_times.push_back(Xml::attr(c, "time"));
    for (xmlNodePtr c : one.nodes("//testcase")) own_times.push_back(Xml::attr(c, "time"));
    EXPECT_EQ(merged_times, own_times);
    EXPECT_TRUE(std::any_of(own_times.begin(), own_times.end(), [](const std::string& t) { return std::stod(t) > 0; }));
  }
  EXPECT_EQ(x.nodes("//testcase/error").size(), 1u);
  const auto root = x.nodes("/testsuites");
  EXPECT_EQ(Xml::attr(root[0], "tests"), std::to_string(x.nodes("//testcase").size()));
  EXPECT_EQ(Xml::attr(root[0], "failures"), std::to_string(x.nodes("//testcase/failure").size()));
  EXPECT_EQ(Xml::attr(root[0], "errors"), "1");
  for (const char* s : {"free-fall", "box-in-box", "bad"}) EXPECT_TRUE(fs::exists(dir_ / "bad" / "junit" / (std::string(s) + ".xml"))) << s;
  for (xmlNodePtr f : x.nodes("//testcase/failure"))
    EXPECT_EQ(Xml::attr(f, "message").rfind("measured ", 0), 0u) << Xml::attr(f, "message");

  // --tolerance reaches validate (an unknown name is validate's bad input: exit 2), a
  // wide enough tolerance passes the failing scene's non-penetration row.
  r = nightly("tol", pass + " --tolerance no_such_bound=1");
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(slurp(dir_ / "tol" / "free-fall.log").find("no_such_bound"), std::string::npos);
  // --timeout: a scene that runs longer is stopped, an errored case says so with its time.
  r = run("OCTOCD_BIN=" + quote(bin()) + " bash " + quote(script) + " --frames 100000000 --every 1 --timeout 2 --out " +
          quote((dir_ / "slow").string()) + " " + quote((source_dir() / "datasets" / "scenes" / "bunny-stack-50.json").string()));
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_NE(r.output.find("TIMEOUT  bunny-stack-50 (after 2 s"), std::string::npos) << r.output;
  Xml slow(dir_ / "slow" / "junit.xml");
  ASSERT_TRUE(slow.ok()) << slurp(dir_ / "slow" / "junit.xml");
  ASSERT_EQ(slow.nodes("//testcase/error").size(), 1u);
  EXPECT_NE(Xml::attr(slow.nodes("//testcase/error")[0], "message").find("timed out after 2 s"), std::string::npos);
  EXPECT_GE(std::stod(Xml::attr(slow.nodes("//testcase")[0], "time")), 2.0);
  // Called wrongly: exit 2.
  EXPECT_EQ(run("bash " + quote(script) + " --scenes everything").code, 2);
  EXPECT_EQ(run("bash " + quote(script) + " --timeout -5").code, 2);
  // --engines names registry engines only: a typo is exit 2 naming it and the allowed names.
  r = run("OCTOCD_BIN=" + quote(bin()) + " bash " + quote(script) + " --scenes none --matrix quick --engines cpu,bulet --out " +
          quote((dir_ / "engines").string()));
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find("--engines 'bulet': not an engine of this octocd; allowed: cpu,"), std::string::npos) << r.output;
  // --matrix-scenes names the matrix's scenes only: a typo is exit 2 naming it and the allowed ones.
  r = run("OCTOCD_BIN=" + quote(bin()) + " bash " + quote(script) + " --scenes none --matrix quick --engines cpu " +
          "--matrix-scenes rot-slope,rot-stak-10 --out " + quote((dir_ / "matrix-scenes").string()));
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find("--matrix-scenes 'rot-stak-10': not a scene of the matrix; allowed: rot-stack-10,rot-slope,"),
            std::string::npos) << r.output;
}

// The nightly's gate (design.md section 14b): green on a healthy build whose only failure is expected,
// red on a planted regression. box-in-box's non-penetration-eq14 failure (a box inside a
// box: the paper's AABB response cannot separate them, 4 contacts) stands for a known
// finding like the Jacobi energy rise. Two regressions are planted the only ways a test
// can without touching the engine: (a) the expected failure grown (its committed figure
// lowered below the measured one: to the gate the same as the figure growing past it),
// (b) a new failure on a scene that passed (--tolerance penetration_slops=0 makes the
// resting stack's true penetration exceed its bound: the same comparison a deeper
// penetration after an engine change would fail).
TEST_F(CliUser, NightlyScriptGatesOnExpectations) {
  const std::string script = (source_dir() / "scripts" / "nightly.sh").string();
  const std::string pass = (source_dir() / "datasets" / "scenes" / "free-fall.json").string();
  const std::string fail = scene("box-in-box", kFailingScene);
  const fs::path expect = dir_ / "nightly-expect.json";
  auto nightly = [&](const std::string& out, const std::string& args) {
    return run("OCTOCD_BIN=" + quote(bin()) + " bash " + quote(script) + " --frames 20 --every 10 --against none " +
               "--out " + quote((dir_ / out).string()) + " " + args);
  };
  // The committed expectations file parses (octocd refuses a malformed one with exit 2).
  Result r = nightly("committed", pass);
  EXPECT_EQ(r.code, 0) << r.output;
  // Record the known failure, then the healthy build is green with it listed as expected.
  r = nightly("write", "--expect none --write-expect " + quote(expect.string()) + " " + pass + " " + fail);
  ASSERT_EQ(r.code, 0) << r.output;
  nlohmann::json e = nlohmann::json::parse(slurp(expect));
  ASSERT_EQ(e["expectations"].size(), 1u) << e.dump();
  r = nightly("healthy", "--expect " + quote(expect.string()) + " " + pass + " " + fail);
  EXPECT_EQ(r.code, 0) << r.output;
  EXPECT_NE(r.output.find("pass     box-in-box (20 frames"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("expected non-penetration-eq14/non-penetration-eq14: worst 4 <= allowed 4"),
            std::string::npos) << r.output;
  {
    Xml x(dir_ / "healthy" / "junit.xml");
    ASSERT_TRUE(x.ok());
    EXPECT_TRUE(x.nodes("//testcase/failure").empty());
    const auto skipped = x.nodes("//testcase[@classname='box-in-box.model'][@name='non-penetration-eq14']/skipped");
    ASSERT_EQ(skipped.size(), 1u);
    EXPECT_EQ(Xml::attr(skipped[0], "message").rfind("expected: ", 0), 0u);
    const std::string total = Xml::attr(x.nodes("/testsuites")[0], "time");  // the whole run's time
    ASSERT_FALSE(total.empty());
    EXPECT_GT(std::stod(total), 0.0);
  }
  // An allowance less than 10 % above the figure (4 of 4.2) still passes, and the summary names
  // it with its margin; 10 % or more (4 of 4.5) is not named.
  e["expectations"][0]["worst"] = 4.2;
  write_file(dir_ / "thin.json", e.dump());
  r = nightly("thin", "--expect " + quote((dir_ / "thin.json").string()) + " " + pass + " " + fail);
  EXPECT_EQ(r.code, 0) << r.output;
  EXPECT_NE(r.output.find("nightly: 1 expected failure(s) within 10% of the allowance"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("box-in-box non-penetration-eq14/non-penetration-eq14 worst 4 of allowed 4.2 (margin 4.8%)"),
            std::string::npos) << r.output;
  e["expectations"][0]["worst"] = 4.5;
  write_file(dir_ / "wide.json", e.dump());
  r = nightly("wide", "--expect " + quote((dir_ / "wide.json").string()) + " " + pass + " " + fail);
  EXPECT_EQ(r.code, 0) << r.output;
  EXPECT_EQ(r.output.find("within 10% of the allowance"), std::string::npos) << r.output;
  // (a) grown: exit 3, named in plain text.
  e["expectations"][0]["worst"] = 3;
  write_file(dir_ / "grown.json", e.dump());
  r = nightly("grown", "--expect " + quote((dir_ / "grown.json").string()) + " " + pass + " " + fail);
  EXPECT_EQ(r.code, 3) << r.output;
  EXPECT_NE(r.output.find("GROWN non-penetration-eq14/non-penetration-eq14: worst 4 > allowed 3"), std::string::npos)
      << r.output;
  // (b) a new failure: exit 3, "measured X > bound Y" in plain text, never XML-escaped.
  r = nightly("new", "--expect " + quote(expect.string()) + " --tolerance penetration_slops=0 " + fail);
  EXPECT_EQ(r.code, 3) << r.output;
  EXPECT_NE(r.output.find("NEW FAILURE penetration/penetration: measured "), std::string::npos) << r.output;
  EXPECT_EQ(r.output.find("&gt;"), std::string::npos) << r.output;
  // A missing expectations file is bad input.
  EXPECT_EQ(nightly("missing", "--expect " + quote((dir_ / "no-such.json").string()) + " " + pass).code, 2);
}

// ---- docs/cli.md is `--help`, checked so they cannot drift ---------------------------

TEST_F(CliUser, CliDocMatchesHelp) {
  const std::string doc = slurp(source_dir() / "docs" / "cli.md");
  ASSERT_FALSE(doc.empty());
  const Result top = octocd_cmd("--help");
  ASSERT_EQ(top.code, 0);
  // Every subcommand `octocd --help` lists.
  std::vector<std::string> commands = {""};
  const auto sub = top.output.find("Subcommands:");
  ASSERT_NE(sub, std::string::npos) << top.output;
  std::istringstream lines(top.output.substr(sub));
  std::string line;
  std::getline(lines, line);
  while (std::getline(lines, line)) {
    std::istringstream w(line);
    std::string name;
    if (line.empty() || line[0] != ' ' || !(w >> name)) break;
    commands.push_back(name);
  }
  ASSERT_GE(commands.size(), 3u);
  for (const std::string& c : commands) {
    const std::string label = c.empty() ? "octocd --help" : "octocd " + c + " --help";
    const std::string begin = "<!-- BEGIN " + label + " -->\n```text\n";
    const std::string end = "```\n<!-- END " + label + " -->";
    const auto b = doc.find(begin);
    ASSERT_NE(b, std::string::npos) << "docs/cli.md lacks the block '" << label
                                    << "': run scripts/cli-doc.sh BUILD_DIR to regenerate it";
    const auto e = doc.find(end, b);
    ASSERT_NE(e, std::string::npos) << label;
    const Result help = octocd_cmd(c.empty() ? "--help" : c + " --help");
    ASSERT_EQ(help.code, 0);
    EXPECT_EQ(doc.substr(b + begin.size(), e - b - begin.size()), help.output)
        << "docs/cli.md differs from `" << label << "`: run scripts/cli-doc.sh BUILD_DIR";
  }
}

// `octocd --help` fits a screen: one line per subcommand (at most 100 columns), 40 lines in
// all; each subcommand's own --help keeps its whole description.
TEST_F(CliUser, TopHelpListsOneLinePerSubcommand) {
  const Result top = octocd_cmd("--help");
  ASSERT_EQ(top.code, 0);
  std::size_t lines_total = 0, listed = 0;
  bool in_list = false;
  std::istringstream lines(top.output);
  for (std::string line; std::getline(lines, line);) {
    ++lines_total;
    EXPECT_LE(line.size(), 100u) << line;
    if (line == "Subcommands:") {
      in_list = true;
      continue;
    }
    if (!in_list) continue;
    if (line.empty()) break;
    std::istringstream w(line);
    std::string name, first_word;
    ASSERT_TRUE(w >> name >> first_word) << "a subcommand without its line: '" << line << "'";
    ++listed;
    const Result own = octocd_cmd(name + " --help");
    ASSERT_EQ(own.code, 0) << name;
    const std::string summary = line.substr(line.find(first_word));
    EXPECT_EQ(own.output.rfind(summary, 0), 0u) << name << ": its own help opens with the line the list gives";
    EXPECT_GT(own.output.find('\n'), summary.size() - 1) << name;
  }
  EXPECT_GE(listed, 9u) << top.output;
  EXPECT_LE(lines_total, 40u) << top.output;
}

// `octocd --help` lists the rows of cli/command_table.def, in their order, and each
// subcommand's own help opens with its row's description.
TEST_F(CliUser, HelpFollowsTheCommandTable) {
  const Result top = octocd_cmd("--help");
  ASSERT_EQ(top.code, 0);
  const auto sub = top.output.find("\nSubcommands:\n");
  ASSERT_NE(sub, std::string::npos) << top.output;
  std::istringstream lines(top.output.substr(sub + 14));
  std::vector<std::string> listed;
  for (std::string line; std::getline(lines, line) && !line.empty() && line[0] == ' ';) {
    std::istringstream w(line);
    std::string name;
    w >> name;
    listed.push_back(name);
  }
  const std::vector<std::string>& names = octocd::cli::command_names();
  EXPECT_EQ(listed, names) << top.output;
  for (std::size_t i = 0; i < names.size(); ++i) {
    const auto id = static_cast<octocd::cli::CommandId>(i);
    EXPECT_EQ(names[i], octocd::cli::command_name(id));
    const Result own = octocd_cmd(names[i] + " --help");
    ASSERT_EQ(own.code, 0) << names[i];
    // The description, wrapped at 100 characters a line (its line breaks read as spaces).
    const std::string description = octocd::cli::command_description(id);
    ASSERT_GT(own.output.size(), description.size()) << names[i];
    std::string head = own.output.substr(0, description.size());
    std::replace(head.begin(), head.end(), '\n', ' ');
    EXPECT_EQ(head, description) << names[i] << ": " << own.output;
    EXPECT_EQ(own.output[description.size()], '\n') << names[i] << ": " << own.output;
  }
}

// `octocd engines` lists every engine of the registry, each available or unavailable with
// its reason; `--available` prints the available ones, which `run --engine` accepts.
TEST(CliEngines, ListsTheRegistryWithAvailability) {
  const Result all = run(bin() + " engines");
  ASSERT_EQ(all.code, 0) << all.output;
  const Result avail = run(bin() + " engines --available");
  ASSERT_EQ(avail.code, 0) << avail.output;
  std::set<std::string> available;
  std::istringstream lines(avail.output);
  for (std::string line; std::getline(lines, line);)
    if (!line.empty()) available.insert(line);
  EXPECT_TRUE(available.count("cpu")) << avail.output;  // the reference is always built
  for (const octocd::EngineInfo& e : octocd::engine_infos()) {
    const std::regex row("(^|\n)" + e.name + " +(available|unavailable: [^\n]+)\n");
    std::smatch m;
    ASSERT_TRUE(std::regex_search(all.output, m, row)) << e.name << " not listed:\n" << all.output;
    EXPECT_EQ(m[2] == "available", available.count(e.name) == 1) << e.name;
    if (available.count(e.name) == 0) {
      // An engine that cannot run here is refused by `run`, saying why.
      const Result r = run(bin() + " run " + octocd::test::source_dir() +
                           "/datasets/scenes/free-fall.json --frames 1 --quiet --engine " + e.name);
      EXPECT_NE(r.code, 0) << e.name;
    }
  }
}

}  // namespace octocd_test_cli_usage
