// The `octocd` command: exit codes, error messages naming the field, traces of killed runs.
#include <gtest/gtest.h>

#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>

#include "octocd/trace.hpp"
#include "support/cli_run.hpp"

// This file's own names (its tests compile in unity batches with the folder's other files).
namespace octocd_test_cli {

namespace fs = std::filesystem;

namespace {

using octocd::test::Result;
using octocd::test::bin;
using octocd::test::run_octocd;

class Cli : public ::testing::Test {
 protected:
  void SetUp() override {
    // One folder level: a parameterised test's name ("Name/3") holds a slash.
    std::string name = ::testing::UnitTest::GetInstance()->current_test_info()->name();
    std::replace(name.begin(), name.end(), '/', '_');
    dir_ = fs::temp_directory_path() / ("octocd-cli-" + std::to_string(::getpid()) + "-" + name);
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }

  /// Writes a scene file and returns its path.
  std::string scene(const std::string& name, const std::string& text) {
    const fs::path p = dir_ / (name + ".json");
    std::ofstream(p) << text;
    return p.string();
  }

  /// A valid box scene with `extra` spliced into the top-level object and `group_extra`
  /// into the group.
  /// `shape` replaces the group's box shape, `frames` the frame count.
  static std::string box_scene(const std::string& extra, const std::string& group_extra = "",
                               const std::string& domain = kDomain,
                               const std::string& shape = R"({"box": [0.1, 0.1, 0.1]})",
                               const std::string& frames = "20") {
    return R"({"name": "t", "domain": )" + domain + R"(, "frames": )" + frames + extra +
           R"(, "groups": [{"name": "boxes", "shape": )" + shape + R"(, "count": 2)" +
           group_extra + "}]}";
  }
  static constexpr const char* kDomain = R"({"min": [-1, 0, -1], "max": [1, 2, 1]})";

  fs::path dir_;
};

}  // namespace

TEST_F(Cli, HelpListsEveryOption) {
  const Result r = run_octocd("run --help");
  EXPECT_EQ(r.code, 0) << r.output;
  for (const char* opt : {"--broadphase", "--midphase", "--frames", "--trace", "--state-every",
                          "--quiet", "flat", "octree", "spatial-hash", "aabb-only"})
    EXPECT_NE(r.output.find(opt), std::string::npos) << opt << " missing from:\n" << r.output;
  EXPECT_EQ(run_octocd("--help").code, 0);
}

TEST_F(Cli, ValidBoxSceneRunsAndPrintsSummary) {
  const Result r = run_octocd("run " + scene("ok", box_scene("")) + " --broadphase flat");
  EXPECT_EQ(r.code, 0) << r.output;
  EXPECT_NE(r.output.find("steps/s"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("broadphase"), std::string::npos) << r.output;
}

TEST_F(Cli, NoArgumentsAndUnknownOptionsAreBadInput) {
  EXPECT_EQ(run_octocd("").code, 2);
  EXPECT_EQ(run_octocd("run").code, 2);
  EXPECT_EQ(run_octocd("run x.json --frobnicate").code, 2);
  EXPECT_EQ(run_octocd("run " + scene("ok", box_scene("")) + " --frames 0").code, 2);
}

struct BadInput {
  const char* label;
  const char* shape;        // replaces the group's shape ("" keeps the box)
  const char* extra;        // spliced into the scene's top level
  const char* group_extra;  // spliced into the group
  const char* domain;       // replaces the domain ("" keeps the default)
  const char* cli;          // extra command-line options
  const char* expect;       // a substring the error must contain (the field)
};

class CliBadInput : public Cli, public ::testing::WithParamInterface<BadInput> {};

TEST_P(CliBadInput, ExitsTwoAndNamesTheField) {
  const BadInput& b = GetParam();
  const std::string text = box_scene(b.extra, b.group_extra, *b.domain ? b.domain : kDomain,
                                     *b.shape ? b.shape : R"({"box": [0.1, 0.1, 0.1]})");
  const std::string path = scene(b.label, text);
  const Result r = run_octocd("run " + path + " --quiet " + b.cli);
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find(b.expect), std::string::npos)
      << "error does not name '" << b.expect << "':\n" << r.output;
  EXPECT_EQ(r.output.find("steps/s"), std::string::npos) << "ran anyway:\n" << r.output;
}

INSTANTIATE_TEST_SUITE_P(
    Items, CliBadInput,
    ::testing::Values(
        BadInput{"unknown_key", "", R"(, "gravty": [0, -9.81, 0])", "", "", "", "gravty"},
        BadInput{"unknown_group_key", "", "", R"(, "colour": "red")", "", "", "colour"},
        BadInput{"wrong_type", "", R"(, "dt": "fast")", "", "", "", "dt"},
        BadInput{"beta_zero", "", R"(, "response": {"beta": 0})", "", "", "", "beta"},
        BadInput{"beta_big", "", R"(, "response": {"beta": 1.5})", "", "", "", "beta"},
        BadInput{"alpha_zero", "", R"(, "response": {"alpha": 0})", "", "", "", "alpha"},
        BadInput{"alpha_big", "", R"(, "response": {"alpha": 2})", "", "", "", "alpha"},
        BadInput{"slop_negative", "", R"(, "response": {"slop": -0.001})", "", "", "", "slop"},
        BadInput{"non_finite", "", R"(, "response": {"max_velocity": 1e400})", "", "", "",
                 "max_velocity"},
        BadInput{"count_zero", "", "", R"(, "count": 0)", "", "", "count"},
        BadInput{"domain_inverted", "", "", "", R"({"min": [0, 0, 0], "max": [1, 0, 1]})", "",
                 "domain"},
        BadInput{"missing_mesh", R"({"mesh": "no-such-mesh"})", "", "", "", "",
                 "no-such-mesh"},
        BadInput{"bad_broadphase", "", "", "", "", "--broadphase kd-tree", "kd-tree"},
        BadInput{"bad_midphase", "", "", "", "", "--midphase 2,1", "midphase"}),
    [](const ::testing::TestParamInfo<BadInput>& p) { return std::string(p.param.label); });

TEST_F(Cli, MissingAndInvalidSceneFiles) {
  Result r = run_octocd("run " + (dir_ / "absent.json").string());
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.output.find("absent.json"), std::string::npos) << r.output;
  r = run_octocd("run " + scene("broken", "{\"name\": "));
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.output.find("broken.json"), std::string::npos) << r.output;
}

TEST_F(Cli, EmptyAndNonFiniteMeshFilesAreBadInput) {
  std::ofstream(dir_ / "empty.obj").flush();
  Result r = run_octocd("run " + scene("e", box_scene("", "", kDomain, R"({"mesh": "empty.obj"})")) +
                    " --quiet");
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find("empty.obj"), std::string::npos) << r.output;
  std::ofstream(dir_ / "nan.obj") << "v 0 0 0\nv 1 0 0\nv nan 1 0\nf 1 2 3\n";
  r = run_octocd("run " + scene("n", box_scene("", "", kDomain, R"({"mesh": "nan.obj"})")) + " --quiet");
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find("nan.obj"), std::string::npos) << r.output;
}

// A trace written by a process killed with SIGKILL mid-run is readable and holds the
// frames flushed before the kill.
TEST_F(Cli, TraceOfKilledRunIsReadable) {
  const std::string path = scene(
      "long", box_scene(R"(, "walls": "floor")",
                        R"(, "layout": {"type": "grid", "min": [-0.5, 0.1, -0.5], "max": [0.5, 1.5, 0.5]})",
                        kDomain, R"({"box": [0.1, 0.1, 0.1]})", "100000000"));
  const std::string trace = (dir_ / "killed.h5").string();
  // Killed without warning once some frames are on disk.
  const octocd::test::KilledRun k = octocd::test::run_killed_after(path, trace, 500);
  ASSERT_TRUE(k.killed) << "the run ended before the kill";
  ASSERT_GE(k.frames, 500) << "no frames flushed within 60 s";
  const octocd::TraceSummary s = octocd::read_trace_summary(trace);
  EXPECT_EQ(s.format, "octocd-trace");
  EXPECT_GE(s.frames, k.frames);
  EXPECT_EQ(s.last_frame, s.frames);  // rows are frames 1..N with none missing
  EXPECT_GE(s.state_rows, 1);
}

TEST_F(Cli, ValidatePassesPrintsTableAndStoresResults) {
  const char* root = std::getenv("OCTOCD_SOURCE_DIR");
  const std::string scene_file = std::string(root ? root : ".") + "/datasets/scenes/box-stack.json";
  const std::string trace = (dir_ / "validated.h5").string();
  // 250 frames: the resting-stack check needs its 200 settling frames within --frames.
  const Result r = run_octocd("validate " + scene_file + " --frames 250 --every 50 --trace " + trace);
  EXPECT_EQ(r.code, 0) << r.output;
  for (const char* name : {"physics  broadphase-completeness", "physics  contact-completeness",
                           "physics  contact-geometry", "physics  penetration", "physics  friction",
                           "physics  conservation", "model    candidate-sets", "model    midphase-completeness",
                           "model    non-penetration-eq14", "model    friction-monotonicity",
                           "model    impulse-conservation", "model    applied-state", "model    analytic",
                           "model    bullet-dynamics", "all validators pass"})
    EXPECT_NE(r.output.find(name), std::string::npos) << name << " missing:\n" << r.output;
  EXPECT_EQ(octocd::read_trace_summary(trace).frames, 250);
  const Result h5 = [&] {
    Result x;
    FILE* p = popen(("h5dump -d /validation/pass " + trace + " 2>&1").c_str(), "r");
    char buf[4096];
    while (p && std::fgets(buf, sizeof buf, p)) x.output += buf;
    x.code = p ? WEXITSTATUS(pclose(p)) : -1;
    return x;
  }();
  EXPECT_EQ(h5.code, 0) << h5.output;
  EXPECT_NE(h5.output.find("(0): 1, 1, 1, 1, 1, 1, 1, 1"), std::string::npos) << h5.output;
}

TEST_F(Cli, ValidateBadInputExitsTwo) {
  const std::string path = scene("ok", box_scene(""));
  Result r = run_octocd("validate " + path + " --against physx");
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find("--against"), std::string::npos) << r.output;
  r = run_octocd("validate " + path + " --frames 0");
  EXPECT_EQ(r.code, 2) << r.output;
  r = run_octocd("run " + path + " --engine physx");
  EXPECT_EQ(r.code, 2) << r.output;
}

// Issue 6: `octocd validate` exits 3 when a validator fails. A small box inside a bigger
// one with Eq. 9 read as written (`paper`) is never separated: Eq. 14 fails.
TEST_F(Cli, ValidateFailingSceneExitsThreeAndToleranceOverrides) {
  const std::string text = R"({
    "name": "box-in-box", "domain": {"min": [-2, -2, -2], "max": [2, 2, 2]},
    "gravity": [0, 0, 0], "walls": "none", "frames": 20, "response": {"overlap": "paper"},
    "groups": [
      {"name": "big", "shape": {"box": [0.5, 0.5, 0.5]}, "count": 1, "mass": 1.0, "positions": [[0, 0, 0]]},
      {"name": "small", "shape": {"box": [0.1, 0.1, 0.1]}, "count": 1, "mass": 1.0, "positions": [[0.05, 0.2, 0.0]]}
    ]})";
  const std::string path = scene("box-in-box", text);
  Result r = run_octocd("validate " + path + " --frames 20 --every 5 --against none");
  EXPECT_EQ(r.code, 3) << r.output;
  EXPECT_NE(r.output.find("VALIDATION FAILED"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("non-penetration-eq14"), std::string::npos) << r.output;
  // The same bound loosened by the user: passes, and the table marks the bound.
  r = run_octocd("validate " + path + " --frames 20 --every 5 --against none --tolerance contraction_m=1");
  EXPECT_EQ(r.code, 0) << r.output;
  EXPECT_NE(r.output.find("* bound set with --tolerance"), std::string::npos) << r.output;
  r = run_octocd("validate " + path + " --tolerance no_such=1");
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find("allowed: contraction_m"), std::string::npos) << r.output;
  r = run_octocd("validate " + path + " --tolerance contraction_m=abc");
  EXPECT_EQ(r.code, 2) << r.output;
}

// Issue 7: `--engine cuda` without a device (or in a build without CUDA) exits 1 and says
// which; with a device it runs.
TEST_F(Cli, CudaEngineWithoutDeviceExitsOne) {
  const Result r = run_octocd("run " + scene("ok", box_scene("")) + " --engine cuda --quiet");
  if (r.code == 0) GTEST_SKIP() << "a CUDA device is present: the engine ran";
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_NE(r.output.find("CUDA"), std::string::npos) << r.output;
}

}  // namespace octocd_test_cli
