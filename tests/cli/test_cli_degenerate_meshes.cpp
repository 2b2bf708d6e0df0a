// The reference engines on degenerate meshes (issue 68, docs/robustness.md "Reference
// engines' traces"): a mesh that spans no volume (flat, collinear) is the same exit 2 on
// Bullet, MuJoCo, ODE and DART, with no qhull dump on the terminal; a needle whose inertia
// no trace may hold is exit 2 naming the scene's body and shape before a step, never a
// refusal of the engine's own (deleted) temporary trace.
#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <regex>
#include <string>

#include "support/cli_run.hpp"

// This file's own names (its tests compile in unity batches with the folder's other files).
namespace octocd_test_cli_degenerate_meshes {

namespace fs = std::filesystem;
using octocd::test::bin;
using octocd::test::Result;
using octocd::test::run;

namespace {

class DegenerateMeshes : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() /
           ("octocd-degenerate-" + std::to_string(::getpid()) + "-" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }

  /// A rotating scene of two bodies of the mesh `obj` (its text) dropped on a floor.
  std::string scene(const std::string& name, const std::string& obj) {
    std::ofstream(dir_ / (name + ".obj")) << obj;
    const fs::path p = dir_ / (name + ".json");
    std::ofstream(p) << R"({"name": ")" << name << R"(", "domain": {"min": [-2, 0, -2], "max": [2, 3, 2]},)"
                     << R"( "walls": "floor", "frames": 20, "rotation": true, "groups": [{"name": "b", "shape":)"
                     << R"( {"mesh": ")" << name << R"(.obj"}, "count": 2, "layout": {"type": "grid",)"
                     << R"( "min": [-1, 0.5, -1], "max": [1, 2, 1]}}]})";
    return p.string();
  }

  /// The reference engines this octocd has.
  std::vector<std::string> engines() {
    const Result r = run(bin() + " engines");
    std::vector<std::string> out;
    for (const std::string e : {"bullet", "mujoco", "ode", "dart"})
      if (std::regex_search(r.output, std::regex("(^|\n)" + e + " +available"))) out.push_back(e);
    return out;
  }

  fs::path dir_;
};

std::size_t lines(const std::string& s) { return static_cast<std::size_t>(std::count(s.begin(), s.end(), '\n')); }

}  // namespace

// Before: exit 2 on ODE, exit 1 after a 57-line qhull dump on MuJoCo.
TEST_F(DegenerateMeshes, AMeshWithoutVolumeIsTheSameExit2OnEveryEngine) {
  const std::string flat = scene("flat", "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nf 1 2 3\nf 2 4 3\n");
  const std::string line = scene("line", "v 0 0 0\nv 1 0 0\nv 2 0 0\nv 3 0 0\nf 1 2 3\nf 2 3 4\n");
  const std::vector<std::string> es = engines();
  ASSERT_FALSE(es.empty()) << "no reference engine built";
  for (const std::string& e : es)
    for (const auto& [s, name] : {std::pair{flat, std::string("flat")}, std::pair{line, std::string("line")}}) {
      SCOPED_TRACE(e + " " + name);
      for (const std::string& cmd : {" validate " + s + " --against none", " run " + s + " --quiet --trace " +
                                                                                (dir_ / "t.h5").string()}) {
        const Result r = run(bin() + cmd + " --engine " + e + " --frames 5");
        EXPECT_EQ(r.code, 2) << r.output;
        EXPECT_NE(r.output.find(name + ".obj@1: the convex hull of its 4 vertices has 0 faces (they span no volume"),
                  std::string::npos)
            << r.output;
        EXPECT_LE(lines(r.output), 2u) << "a dump reached the terminal: " << r.output;
        EXPECT_EQ(r.output.find("qhull error"), std::string::npos) << r.output;
      }
    }
}

// A mesh file of the scene's own folder, judged through a temporary trace in $TMPDIR:
// before, the trace's scene looked its mesh up beside the trace (exit 2 "mesh file
// \"hull.obj\" not found (searched: /tmp/hull.obj)", naming the deleted temporary trace).
TEST_F(DegenerateMeshes, AMeshBesideTheSceneIsFoundWhenItsTraceIsJudged) {
  const std::string hull = scene("hull", "v 0.1 0 0\nv -0.1 0 0\nv 0 0.1 0\nv 0 -0.1 0\nv 0 0 0.1\nv 0 0 -0.1\nf 1 3 5\nf 3 2 5\nf 2 4 5\nf 4 1 5\nf 3 1 6\nf 2 3 6\nf 4 2 6\nf 1 4 6\n");
  for (const std::string& e : engines()) {
    SCOPED_TRACE(e);
    const Result r = run(bin() + " validate " + hull + " --against none --engine " + e + " --frames 5");
    EXPECT_TRUE(r.code == 0 || r.code == 3) << r.output;  // judged (a row may fail), not refused
    EXPECT_EQ(r.output.find("not found"), std::string::npos) << r.output;
  }
}

// A mesh named by an absolute path outside the scene's folder: the temporary trace's scene
// cannot be judged there (a trace's scene reads meshes inside --mesh-dir only). Before: exit
// 2 naming the deleted temporary trace as bad input; now a run failure (exit 1) naming the
// engine and the scene, never the temporary file.
TEST_F(DegenerateMeshes, ARefusedTemporaryTraceIsNamedAsTheRunsFailure) {
  const std::vector<std::string> es = engines();
  if (std::find(es.begin(), es.end(), "bullet") == es.end()) GTEST_SKIP() << "no bullet in this octocd";
  fs::create_directories(dir_ / "elsewhere");
  fs::create_directories(dir_ / "scenes");
  std::ofstream(dir_ / "elsewhere" / "o.obj")
      << "v 0.1 0 0\nv -0.1 0 0\nv 0 0.1 0\nv 0 -0.1 0\nv 0 0 0.1\nv 0 0 -0.1\nf 1 3 5\nf 3 2 5\nf 2 4 5\n"
         "f 4 1 5\nf 3 1 6\nf 2 3 6\nf 4 2 6\nf 1 4 6\n";
  const fs::path s = dir_ / "scenes" / "far.json";
  std::ofstream(s) << R"({"name": "far", "domain": {"min": [-2, 0, -2], "max": [2, 3, 2]}, "walls": "floor",)"
                   << R"( "frames": 5, "rotation": true, "groups": [{"name": "b", "shape": {"mesh": ")"
                   << (dir_ / "elsewhere" / "o.obj").string() << R"("}, "count": 2, "layout": {"type": "grid",)"
                   << R"( "min": [-1, 0.5, -1], "max": [1, 2, 1]}}]})";
  const Result r = run(bin() + " validate " + s.string() + " --against none --engine bullet --frames 3");
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_NE(r.output.find("engine bullet: its trace of scene 'far' (temporary, removed) is one octocd's reader "
                          "refuses: "),
            std::string::npos)
      << r.output;
  EXPECT_EQ(r.output.find("octocd-validate-"), std::string::npos) << "names the temporary trace: " << r.output;
}

// Before: a body that fell past 10^6 m (gravity 10^4 m/s^2, dt 0.1 s, no walls) was written
// into the trace, which octocd then refused (validate: exit 2 naming the deleted temporary
// trace; run: exit 0 and a trace no reader takes). Now the run stops before writing that
// frame, exit 1 naming engine, frame and body; run's trace keeps the frames before and is
// judgeable.
TEST_F(DegenerateMeshes, AStatePastTheTraceLimitsEndsTheRunNamingTheFrame) {
  const fs::path s = dir_ / "fall.json";
  std::ofstream(s) << R"({"name": "fall", "domain": {"min": [-2, -2, -2], "max": [2, 2, 2]}, "walls": "none",)"
                   << R"( "frames": 200, "dt": 0.1, "gravity": [0, -10000, 0], "rotation": true, "groups":)"
                   << R"( [{"name": "b", "shape": {"box": [0.1, 0.1, 0.1]}, "count": 1, "positions": [[0, 0, 0]]}]})";
  for (const std::string& e : engines()) {
    SCOPED_TRACE(e);
    const std::string trace = (dir_ / (e + ".h5")).string();
    for (const std::string& cmd : {" validate " + s.string() + " --against none", " run " + s.string() +
                                                                                   " --quiet --no-xdmf --trace " + trace}) {
      const Result r = run(bin() + cmd + " --engine " + e);
      EXPECT_EQ(r.code, 1) << r.output;
      EXPECT_TRUE(std::regex_search(r.output, std::regex("engine " + e + ": frame ([0-9]+): body 0: its position "
                                                         "\\(0, -1\\.[0-9]+e\\+06, 0\\) m is out of range; allowed")))
          << r.output;
      EXPECT_EQ(r.output.find("octocd-validate-"), std::string::npos) << r.output;
    }
    const Result judged = run(bin() + " validate --trace-in " + trace + " --against none");
    EXPECT_TRUE(judged.code == 0 || judged.code == 3) << "the trace run kept is judgeable: " << judged.output;
  }
}

// Before: ODE aborted ("ODE INTERNAL ERROR 1: assertion !bSafeNormalize4Fault", exit 134)
// on a tetrahedron whose bounding-box centre lies outside it; now exit 2 naming the shape.
TEST_F(DegenerateMeshes, OdeRefusesAHullAroundItsOriginInsteadOfAborting) {
  const std::vector<std::string> es = engines();
  if (std::find(es.begin(), es.end(), "ode") == es.end()) GTEST_SKIP() << "no ode in this octocd";
  const std::string tet = scene("tet", "v 0 0 0\nv 0.2 0 0\nv 0 0.2 0\nv 0 0 0.2\nf 1 3 2\nf 1 2 4\nf 2 3 4\nf 1 4 3\n");
  const Result r = run(bin() + " validate " + tet + " --against none --engine ode --frames 5");
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find("tet.obj"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("engine ode needs the centre of the mesh's bounding box inside its convex hull"),
            std::string::npos)
      << r.output;
  EXPECT_EQ(r.output.find("INTERNAL ERROR"), std::string::npos) << r.output;
}

// Before: exit 2 naming the engine's own deleted temporary trace ("/tmp/octocd-validate-
// bullet-XXXXXX.h5: /bodies/inertia: body 1: I[2][2] = 1.66667e-13"), and `run --trace`
// exit 0 writing a trace octocd then refused.
TEST_F(DegenerateMeshes, ANeedleWhoseInertiaNoTraceMayHoldIsRefusedBeforeAStep) {
  const std::string needle =
      scene("needle", "v 0.0000005 0 0\nv -0.0000005 0 0\nv 0 0.0000005 0\nv 0 -0.0000005 0\nv 0 0 0.5\nv 0 0 -0.5\nf 1 3 5\nf 3 2 5\nf 2 4 5\nf 4 1 5\nf 3 1 6\nf 2 3 6\nf 4 2 6\nf 1 4 6\n");
  for (const std::string& e : engines()) {
    SCOPED_TRACE(e);
    const std::string trace = (dir_ / (e + ".h5")).string();
    for (const std::string& cmd : {" validate " + needle + " --against none", " run " + needle + " --quiet --trace " +
                                                                                   trace}) {
      const Result r = run(bin() + cmd + " --engine " + e + " --frames 5");
      EXPECT_EQ(r.code, 2) << r.output;
      EXPECT_TRUE(std::regex_search(r.output, std::regex("scene 'needle': body [0-9]+ \\(group 'b', shape "
                                                         "'needle\\.obj(@[0-9]+)?'\\): engine " + e + " gives it inertia I")))
          << r.output;
      EXPECT_NE(r.output.find("the shape cannot give a positive inertia a trace may hold"), std::string::npos)
          << r.output;
      EXPECT_EQ(r.output.find("octocd-validate-"), std::string::npos) << "names a temporary trace: " << r.output;
      EXPECT_LE(lines(r.output), 8u) << r.output;
      EXPECT_EQ(r.output.find("\nWARNING"), std::string::npos) << "an engine's raw message: " << r.output;
    }
  }
}

// A cube mesh (a hull on ODE, dConvex) dropped on a static slab mesh (a dTriMesh): ODE's
// convex-trimesh collider needs the trimesh's face angles. Before: the first touch aborted
// the process, "ODE INTERNAL ERROR 2: Please preprocess the trimesh data with
// dTRIDATAPREPROCESS_BUILD_FACE_ANGLES", exit 134. Now the run ends normally and its trace
// is one the reader takes, the cube resting on the slab.
TEST_F(DegenerateMeshes, OdeDropsAHullOnAStaticMeshWithoutAborting) {
  const std::vector<std::string> es = engines();
  if (std::find(es.begin(), es.end(), "ode") == es.end()) GTEST_SKIP() << "no ode in this octocd";
  const auto box_obj = [](double hx, double hy, double hz) {
    std::string s;
    for (const int x : {-1, 1})
      for (const int y : {-1, 1})
        for (const int z : {-1, 1}) s += "v " + std::to_string(x * hx) + " " + std::to_string(y * hy) + " " +
                                         std::to_string(z * hz) + "\n";
    return s + "f 1 2 4\nf 1 4 3\nf 5 7 8\nf 5 8 6\nf 1 5 6\nf 1 6 2\nf 3 4 8\nf 3 8 7\nf 1 3 7\nf 1 7 5\nf 2 6 8\n"
               "f 2 8 4\n";
  };
  std::ofstream(dir_ / "slab.obj") << box_obj(1.0, 0.05, 1.0);
  std::ofstream(dir_ / "cube.obj") << box_obj(0.05, 0.05, 0.05);
  const fs::path s = dir_ / "drop.json";
  std::ofstream(s) << R"({"name": "drop", "domain": {"min": [-2, 0, -2], "max": [2, 3, 2]}, "walls": "none",)"
                   << R"( "frames": 300, "dt": 0.002, "rotation": true, "groups": [)"
                   << R"({"name": "slab", "shape": {"mesh": "slab.obj", "scale": 2}, "count": 1, "mass": 0, "positions": [[0, 0.5, 0]]},)"
                   << R"({"name": "cube", "shape": {"mesh": "cube.obj", "scale": 0.1}, "count": 1, "positions": [[0.1, 0.8, 0.2]]}]})";
  const std::string trace = (dir_ / "drop.h5").string();
  const Result r = run(bin() + " run " + s.string() + " --engine ode --quiet --contacts --state-every 1 --trace " + trace);
  EXPECT_EQ(r.code, 0) << r.output;
  EXPECT_EQ(r.output.find("INTERNAL ERROR"), std::string::npos) << r.output;
  const Result c = run(bin() + " validate --trace-in " + trace + " --check-only");
  EXPECT_EQ(c.code, 0) << c.output;
  // Resting on the slab (top face y = 0.55): the cube's centre 0.05 above it, within 1 cm.
  const Result y = run("/usr/bin/python3 -c \"import h5py; print(h5py.File('" + trace +
                       "', 'r')['states/position'][-1, 1, 1])\"");
  if (y.code == 0) {
    EXPECT_NEAR(std::stod(y.output), 0.6, 0.01) << y.output;
  }
}

}  // namespace octocd_test_cli_degenerate_meshes
