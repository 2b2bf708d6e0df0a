// `octocd bench` sweeps of kind speed-accuracy (design.md section 15, docs/bench-format.md) on the test
// sweeps tests/data/bench-small-speed-accuracy*.json (two free-falling boxes, three time
// steps, cpu and bullet). Oracle: the closed form of semi-implicit Euler in free fall,
// x_n = x0 + g t^2 / 2 + g t dt / 2, so two runs of one line differ by g t (dt - dt_ref) / 2
// at every matched time and the consistency errors at dt = 4h and 2h against h are in the
// ratio (4h - h) / (2h - h) = 3 exactly. Also: 0 at the reference, a run that leaves the
// domain (diverge_beyond_m 0) recorded as diverged, the exit-2 cases, and shards merged
// equal to the whole run. No assertion depends on timings.
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
namespace octocd_test_cli_speed_accuracy {

namespace fs = std::filesystem;
using json = nlohmann::json;
using octocd::test::Result;
using octocd::test::run_octocd;
using octocd::test::source_dir;

namespace {

class SpeedAccuracy : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("octocd-sa-" + std::to_string(::getpid()) + "-" +
                                        ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  static std::string data(const std::string& name) { return (fs::path(source_dir()) / "tests" / "data" / name).string(); }
  std::string write(const std::string& name, const std::string& text) {
    const fs::path p = dir_ / name;
    std::ofstream(p) << text;
    return p.string();
  }
  /// Runs `bench SWEEP -o DIR/OUT --quiet ARGS`, expects exit `expect`, returns the result.
  json bench(const std::string& sweep, const std::string& args, int expect = 0, const std::string& out = "r.json") {
    const Result r = run_octocd("bench " + sweep + " -o " + (dir_ / out).string() + " --quiet " + args);
    EXPECT_EQ(r.code, expect) << r.output;
    last_ = r.output;
    if (r.code != 0 || !fs::exists(dir_ / out)) return json();
    std::ifstream in(dir_ / out);
    return json::parse(in);
  }
  fs::path dir_;
  std::string last_;
};

std::map<std::string, json> by_id(const json& result) {
  std::map<std::string, json> m;
  for (const json& p : result["points"]) m[p["id"].get<std::string>()] = p;
  return m;
}

TEST_F(SpeedAccuracy, ConsistencyIsZeroAtTheReferenceAndLinearInDt) {
  const json r = bench(data("bench-small-speed-accuracy.json"), "--repeat 1");
  ASSERT_TRUE(r.is_object());
  EXPECT_EQ(r["sweep"]["kind"], "speed-accuracy");
  std::map<std::string, std::map<double, json>> lines;
  int ok = 0, skipped = 0;
  for (const json& p : r["points"]) {
    for (const char* k : {"params", "geometry", "rotation", "line", "engine_label", "dt", "iterations", "steps",
                          "sim_seconds", "speed", "steps_per_s", "error", "status"})
      EXPECT_TRUE(p.contains(k)) << k << " missing in " << p["id"];
    EXPECT_EQ(p["params"]["axes"]["dt"].get<std::string>().empty(), false);
    if (p["status"] == "skipped") {
      ++skipped;
      EXPECT_FALSE(p.value("reason", "").empty()) << p["id"];
      continue;
    }
    ASSERT_EQ(p["status"], "ok") << p.dump();
    ++ok;
    // Every point of a line runs the same simulated time: steps x dt = 0.4 s.
    EXPECT_NEAR(p["sim_seconds"].get<double>(), 0.4, 1e-12);
    EXPECT_NEAR(p["steps"].get<double>() * p["dt"].get<double>(), 0.4, 1e-12);
    EXPECT_EQ(p["speed"]["n"], 1);
    EXPECT_GT(p["speed"]["median"].get<double>(), 0.0);
    // How busy the machine was while the point ran (the report's load mark reads it).
    ASSERT_TRUE(p.contains("load_average") && p["load_average"].size() == 3u) << p.dump();
    EXPECT_GE(p["load_average"][0].get<double>(), 0.0);
    EXPECT_TRUE(p["under_load"].is_boolean()) << p.dump();
    EXPECT_EQ(p["error"]["reference_dt"], 0.001);
    EXPECT_EQ(p["error"]["max_penetration_m"], 0.0);  // two boxes falling side by side never touch
    EXPECT_TRUE(p["error"]["momentum_residual"].is_null());
    lines[p["line"].get<std::string>()][p["dt"].get<double>()] = p;
  }
  // cpu: 1 line; bullet: hull x {translation, rotation} + box x translation, x 2 iteration counts;
  // box x rotation skipped (the hull run), 2 lines x 3 dts.
  EXPECT_EQ(lines.size(), 7u);
  EXPECT_EQ(ok, 21);
  EXPECT_EQ(skipped, 6);
  for (const auto& [line, pts] : lines) {
    ASSERT_EQ(pts.size(), 3u) << line;
    EXPECT_EQ(pts.at(0.001)["error"]["consistency"], 0.0) << line;
    const double e4 = pts.at(0.004)["error"]["consistency"], e2 = pts.at(0.002)["error"]["consistency"];
    EXPECT_GT(e4, e2) << line;
    EXPECT_NEAR(e4 / e2, 3.0, 0.01) << line;  // (4h - h) / (2h - h)
    // Closed form of the RMS over the 100 matched times t_k = 0.004 k of |g t_k (dt - h) / 2| / size,
    // size = the 0.2 m cube's diagonal.
    double sum = 0.0;
    for (int k = 1; k <= 100; ++k) {
      const double d = 9.81 * 0.004 * k * (0.004 - 0.001) / 2.0 / std::sqrt(3.0 * 0.2 * 0.2);
      sum += d * d;
    }
    EXPECT_NEAR(e4, std::sqrt(sum / 100.0), 2e-3 * e4) << line;
    // Semi-implicit Euler in free fall loses energy in proportion to dt.
    EXPECT_LT(pts.at(0.004)["error"]["energy_drift"].get<double>(), pts.at(0.001)["error"]["energy_drift"].get<double>());
  }
  const json& b = lines.at("sa-free-fall | bullet | hull | rotation | iterations=5").at(0.002);
  EXPECT_EQ(b["engine_label"], "bullet (btDbvtBroadphase, hulls, rotation)");
  EXPECT_EQ(b["iterations"], 5);
  EXPECT_EQ(b["params"]["axes"]["iterations"], "5");
  EXPECT_EQ(b["geometry"], "hull");
  EXPECT_EQ(b["rotation"], true);
  EXPECT_TRUE(lines.at("sa-free-fall | cpu | mesh | translation").at(0.002)["iterations"].is_null());
  // The CSV beside the result: a header and one row per point.
  std::ifstream csv(dir_ / "r.csv");
  ASSERT_TRUE(csv.good());
  std::string header, row;
  std::getline(csv, header);
  EXPECT_NE(header.find("error.consistency"), std::string::npos);
  EXPECT_NE(header.find("speed.median"), std::string::npos);
  int rows = 0;
  while (std::getline(csv, row)) ++rows;
  EXPECT_EQ(rows, 27);
  // --resume keeps the finished result as it is; without it an existing file is refused.
  const Result again = run_octocd("bench " + data("bench-small-speed-accuracy.json") + " --repeat 1 -o " +
                                  (dir_ / "r.json").string() + " --quiet --resume");
  EXPECT_EQ(again.code, 0) << again.output;
  std::ifstream in(dir_ / "r.json");
  EXPECT_EQ(json::parse(in)["started"], r["started"]);
  bench(data("bench-small-speed-accuracy.json"), "--repeat 1", 2);
  EXPECT_NE(last_.find("exists"), std::string::npos) << last_;
  bench(data("bench-small-speed-accuracy.json"), "--repeat 2 --resume", 2);  // other settings
  EXPECT_NE(last_.find("not a finished result"), std::string::npos) << last_;
}

TEST_F(SpeedAccuracy, ARunLeavingTheDomainIsADivergedPointNotACrash) {
  const json r = bench(data("bench-small-speed-accuracy-diverge.json"), "--csv " + (dir_ / "d.csv").string());
  ASSERT_TRUE(r.is_object());
  const auto pts = by_id(r);
  const json& big = pts.at("sa-free-fall | cpu | mesh | translation | dt=0.1");
  EXPECT_EQ(big["status"], "diverged");
  EXPECT_NE(big["reason"].get<std::string>().find("outside the domain"), std::string::npos) << big["reason"];
  EXPECT_TRUE(big["error"]["consistency"].is_null());
  EXPECT_TRUE(big["speed"].is_null());
  EXPECT_EQ(pts.at("sa-free-fall | cpu | mesh | translation | dt=0.05")["status"], "ok");
  EXPECT_EQ(pts.at("sa-free-fall | cpu | mesh | translation | dt=0.025")["error"]["consistency"], 0.0);
  EXPECT_TRUE(fs::exists(dir_ / "d.csv"));
}

TEST_F(SpeedAccuracy, BadInputExitsTwoNamingIt) {
  const std::string scene = data("sa-free-fall.json");
  const auto sweep = [&](const std::string& keys) {
    return write("s.json", R"({"name": "x", "kind": "speed-accuracy", "engines": ["cpu"], "repeat": 1, "scenes": [")" +
                               scene + R"("], "sim_seconds": 0.04, )" + keys + "}");
  };
  bench(sweep(R"("dts": [0.004, 0, 0.001])"), "", 2);
  EXPECT_NE(last_.find("dts[1]"), std::string::npos) << last_;
  bench(sweep(R"("dts": [0.004, -0.002])"), "", 2);
  EXPECT_NE(last_.find("dts[1]"), std::string::npos) << last_;
  bench(sweep(R"("dts": [0.004, 0.003])"), "", 2);  // 0.003 does not divide 0.004
  EXPECT_NE(last_.find("dts[1]"), std::string::npos) << last_;
  // A scene the engine named by --engines cannot run (cpu translates only; the scene rotates).
  bench(write("rot.json",
              R"({"name": "x", "kind": "speed-accuracy", "repeat": 1, "scenes": [")" + scene +
                  R"("], "set": {"/rotation": true}, "dts": [0.004, 0.002], "sim_seconds": 0.04})"),
        "--engines cpu", 2);
  EXPECT_NE(last_.find("engine cpu cannot run scene 'sa-free-fall'"), std::string::npos) << last_;
  EXPECT_NE(last_.find("rotates"), std::string::npos) << last_;
  // --frames has no meaning here; an unknown engine is refused.
  bench(sweep(R"("dts": [0.004, 0.002])"), "--frames 10", 2);
  EXPECT_NE(last_.find("sim_seconds"), std::string::npos) << last_;
  bench(sweep(R"("dts": [0.004, 0.002])"), "--engines cpu,bogus", 2);
  // An engine named by --engines that cannot run here (cuda without a device) is bad input.
  const Result cuda = run_octocd("bench " + sweep(R"("dts": [0.004, 0.002])") + " -o " + (dir_ / "c.json").string() +
                                 " --quiet --engines cuda");
  if (cuda.code == 0) GTEST_SKIP() << "the cuda engine runs here";
  EXPECT_EQ(cuda.code, 2) << cuda.output;
  EXPECT_NE(cuda.output.find("--engines: engine cuda cannot run here"), std::string::npos) << cuda.output;
}

TEST_F(SpeedAccuracy, ShardsKeepLinesWholeAndMergeToTheWholeRun) {
  const std::string sweep = data("bench-small-speed-accuracy.json");
  const json whole = bench(sweep, "--repeat 1", 0, "whole.json");
  const json s0 = bench(sweep, "--repeat 1 --shard 0/2", 0, "s0.json");
  const json s1 = bench(sweep, "--repeat 1 --shard 1/2", 0, "s1.json");
  ASSERT_TRUE(whole.is_object() && s0.is_object() && s1.is_object());
  std::map<std::string, json> merged = by_id(s0);
  for (const auto& [id, p] : by_id(s1)) EXPECT_TRUE(merged.emplace(id, p).second) << id << " in both shards";
  const auto all = by_id(whole);
  ASSERT_EQ(merged.size(), all.size());
  std::map<std::string, int> line_shard;
  for (const auto& [id, p] : merged) {
    const json& w = all.at(id);
    for (const char* k : {"index", "status", "line", "steps", "dt", "iterations", "geometry", "rotation"})
      EXPECT_EQ(p[k], w[k]) << id << " " << k;
    EXPECT_EQ(p["error"]["consistency"], w["error"]["consistency"]) << id;
    EXPECT_EQ(p["error"]["energy_drift"], w["error"]["energy_drift"]) << id;
  }
  for (const auto& [id, p] : by_id(s0)) line_shard[p["line"].get<std::string>()] |= 1;
  for (const auto& [id, p] : by_id(s1)) line_shard[p["line"].get<std::string>()] |= 2;
  for (const auto& [line, shards] : line_shard) EXPECT_NE(shards, 3) << line << " split over the shards";
  EXPECT_EQ(s0["settings"]["shard_by"], "line");
}

}  // namespace

}  // namespace octocd_test_cli_speed_accuracy
