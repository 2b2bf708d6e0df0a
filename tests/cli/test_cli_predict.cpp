// Predictability (design.md section 20, docs/predictability.md): `octocd validate --determinism`
// and `octocd bench` sweeps of kind divergence on small scenes (tests/data/bench-small-divergence.json:
// two free-falling boxes and box-stack, the cpu engine, 40 frames). Oracles: unperturbed
// copies (eps 0) of a deterministic engine stay at distance 0 at every frame; the distance
// at frame 0 is the perturbation itself (eps, up to float32 rounding of the positions), so
// it grows with eps; in free fall every body moves by the same closed form whatever its
// start, so the distance stays eps and the fitted growth exponent is 0.
#include <gtest/gtest.h>

#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <string>

#include <nlohmann/json.hpp>

#include "support/cli_run.hpp"

// This file's own names (its tests compile in unity batches with the folder's other files).
namespace octocd_test_cli_predict {

namespace fs = std::filesystem;
using json = nlohmann::json;
using octocd::test::Result;
using octocd::test::run_octocd;
using octocd::test::source_dir;

namespace {

class Predict : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("octocd-predict-" + std::to_string(::getpid()) + "-" +
                                        ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  static std::string src(const std::string& rel) { return (fs::path(source_dir()) / rel).string(); }
  static json read(const fs::path& p) {
    std::ifstream in(p);
    return json::parse(in);
  }
  fs::path dir_;
};

TEST_F(Predict, DivergenceOfUnperturbedCopiesIsZeroAndGrowsWithEps) {
  const Result r = run_octocd("bench " + src("tests/data/bench-small-divergence.json") + " -o " +
                              (dir_ / "d.json").string() + " --quiet");
  ASSERT_EQ(r.code, 0) << r.output;
  const json j = read(dir_ / "d.json");
  EXPECT_EQ(j["sweep"]["kind"], "divergence");
  EXPECT_EQ(j["complete"], true);
  std::map<std::string, std::map<double, json>> by_scene;  // scene -> eps -> point
  for (const json& p : j["points"]) {
    ASSERT_EQ(p["status"], "ok") << p.dump();
    ASSERT_EQ(p["mean_m"].size(), 41u) << p["id"];
    ASSERT_EQ(p["max_m"].size(), 41u) << p["id"];
    by_scene[p["params"]["scene"].get<std::string>()][p["eps_m"].get<double>()] = p;
  }
  ASSERT_EQ(by_scene.size(), 2u);
  for (const auto& [scene, points] : by_scene) {
    ASSERT_EQ(points.size(), 4u) << scene;
    // eps 0: the copies are the unperturbed run, bit for bit, at every frame.
    const json& zero = points.at(0.0);
    for (std::size_t f = 0; f < zero["mean_m"].size(); ++f) {
      EXPECT_EQ(zero["mean_m"][f].get<double>(), 0.0) << scene << " frame " << f;
      EXPECT_EQ(zero["max_m"][f].get<double>(), 0.0) << scene << " frame " << f;
    }
    EXPECT_TRUE(zero["exponent_per_s"].is_null()) << scene;
    EXPECT_FALSE(zero.value("exponent_reason", "").empty()) << scene;
    // Frame 0: the perturbation itself, eps within float32 rounding, increasing with eps.
    double before = 0.0;
    for (const double eps : {1e-5, 1e-4, 1e-3}) {
      const json& p = points.at(eps);
      const double d0 = p["mean_m"][0].get<double>();
      EXPECT_NEAR(d0, eps, 0.05 * eps + 2e-6) << scene << " eps " << eps;
      EXPECT_GT(d0, before) << scene << " eps " << eps;
      EXPECT_LE(d0, p["max_m"][0].get<double>()) << scene;
      before = d0;
    }
  }
  // Free fall: every body follows the same closed form from its start, so the distance stays
  // eps (up to float rounding) and the fitted growth exponent is ~0.
  for (const double eps : {1e-5, 1e-4, 1e-3}) {
    const json& p = by_scene.at("sa-free-fall").at(eps);
    ASSERT_TRUE(p["exponent_per_s"].is_number()) << p.dump();
    EXPECT_NEAR(p["exponent_per_s"].get<double>(), 0.0, 0.05) << "eps " << eps;
    EXPECT_NEAR(p["mean_m"][40].get<double>(), p["mean_m"][0].get<double>(), 0.05 * eps + 2e-6) << "eps " << eps;
  }
  // The CSV beside the result: a row per frame of every point.
  std::ifstream csv(dir_ / "d.csv");
  std::string line;
  std::size_t rows = 0;
  std::getline(csv, line);
  EXPECT_EQ(line.rfind("sweep,scene,engine,eps_m,", 0), 0u) << line;
  while (std::getline(csv, line)) ++rows;
  EXPECT_EQ(rows, 8u * 41u);
}

// The sweep's name comes from its file: on the terminal its escape sequences are shown as
// \x1b (octocd::printable), never run (a CSI that clears the screen, an OSC that retitles it).
TEST_F(Predict, DivergencePrintsItsSweepNameEscaped) {
  const fs::path sweep = dir_ / "esc.json";
  std::ofstream(sweep) << R"({"name": "dv\u001b[2J\u001b]0;pwned\u0007", "kind": "divergence", "scenes": [")"
                       << src("datasets/scenes/box-stack.json")
                       << R"("], "engines": ["cpu"], "eps": [1e-4], "copies": 1, "frames": 3})";
  const Result r = run_octocd("bench " + sweep.string() + " -o " + (dir_ / "e.json").string());
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_EQ(r.output.find('\x1b'), std::string::npos) << r.output;
  EXPECT_EQ(r.output.find('\x07'), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("bench dv\\x1b[2J\\x1b]0;pwned\\x07: 1 points"), std::string::npos) << r.output;
}

TEST_F(Predict, DivergenceRefusesBadLadders) {
  const fs::path sweep = dir_ / "bad.json";
  std::ofstream(sweep) << R"({"name": "b", "kind": "divergence", "scenes": [")" << src("datasets/scenes/box-stack.json")
                       << R"("], "eps": [1e-5, -1e-3]})";
  const Result r = run_octocd("bench " + sweep.string() + " -o " + (dir_ / "b.json").string() + " --quiet");
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find("eps[1]"), std::string::npos) << r.output;
}

TEST_F(Predict, DeterminismOfTheCpuEngineAcrossRunsAndThreads) {
  const Result r = run_octocd("validate " + src("datasets/scenes/box-stack.json") +
                              " --determinism --frames 30 --threads 2 --json " + (dir_ / "v.json").string());
  ASSERT_EQ(r.code, 0) << r.output;
  const json j = read(dir_ / "v.json");
  std::map<std::string, json> rows;
  for (const json& row : j["rows"]) rows[row["name"].get<std::string>()] = row;
  ASSERT_EQ(rows.size(), 3u) << j.dump(1);
  EXPECT_EQ(rows["determinism-runs"]["verdict"], "pass") << r.output;
  EXPECT_EQ(rows["determinism-threads"]["verdict"], "pass") << r.output;
  // cpu against cuda: compared where a GPU runs the cuda engine, else n/a naming why.
  const std::string cuda = rows["determinism-cpu-cuda"]["verdict"];
  EXPECT_TRUE(cuda == "pass" || cuda == "n/a") << r.output;
  EXPECT_NE(r.output.find("bit for bit over 30 frames"), std::string::npos) << r.output;
}

TEST_F(Predict, DeterminismRefusesATraceAndOneThread) {
  const std::string scene = src("datasets/scenes/box-stack.json");
  Result r = run_octocd("validate " + scene + " --determinism --frames 5 --trace " + (dir_ / "t.h5").string());
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find("--determinism"), std::string::npos) << r.output;
  r = run_octocd("validate " + scene + " --determinism --frames 5 --threads 1");
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find("--threads 1"), std::string::npos) << r.output;
}

}  // namespace

}  // namespace octocd_test_cli_predict
