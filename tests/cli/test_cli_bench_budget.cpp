// `octocd bench` on a time budget per point (issue 77 item 2; docs/bench-format.md "Time
// budget"): the result file is valid after every point and a stop keeps the finished ones,
// the budget cuts a slow point's timed frames (or skips it with an estimate) and states the
// count reached, and --protocol paper keeps the sweep's full protocol.
#include <gtest/gtest.h>

#include <fcntl.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <regex>
#include <sstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "support/cli_run.hpp"
#include "support/wait_event.hpp"

// This file's own names (its tests compile in unity batches with the folder's other files).
namespace octocd_test_cli_bench_budget {

namespace fs = std::filesystem;
using json = nlohmann::json;

namespace {

std::string slurp(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

class BenchBudget : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() /
           ("octocd_budget_" + std::to_string(::getpid()) + "_" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
    // 8 boxes, no gravity: a step of microseconds.
    std::ofstream(dir_ / "small.json") << R"({"name": "small", "domain": {"min": [-2, -2, -2], "max": [2, 2, 2]},
      "gravity": [0, 0, 0], "frames": 10, "groups": [{"name": "b", "shape": {"box": [0.1, 0.1, 0.1]}, "count": 8,
      "layout": {"type": "grid", "min": [-1, -1, -1], "max": [1, 1, 1]}}]})";
  }
  void TearDown() override { fs::remove_all(dir_); }
  /// `octocd bench SWEEP ARGS -o OUT` with the test's folder as the scene folder.
  octocd::test::Result bench(const std::string& sweep, const std::string& args, const fs::path& out) {
    return octocd::test::run_octocd("bench " + (dir_ / sweep).string() + " -o " + out.string() + " --scene-dir " +
                                    dir_.string() + " " + args);
  }
  fs::path dir_;
};

// The result holds each point as soon as its group of round-robin repetitions finished it (not
// after the last point's last repetition), valid JSON at every write; SIGINT then keeps every
// finished point, each with all its repetitions, and says how many. The signal follows an
// event: the file holding a point (checked after every change in its folder).
TEST_F(BenchBudget, ResultHoldsEachPointAsItEndsAndAStopKeepsThem) {
  // Points 0-3 (one round-robin group) step 8 boxes; point 4 (the next group) 3000 boxes
  // overlapping each other, a step of about a second: with no time limit it runs until stopped.
  for (int k = 1; k <= 4; ++k) fs::copy_file(dir_ / "small.json", dir_ / ("small" + std::to_string(k) + ".json"));
  std::ofstream(dir_ / "dense.json") << R"({"name": "dense", "domain": {"min": [-2, -2, -2], "max": [2, 2, 2]},
    "gravity": [0, 0, 0], "frames": 100, "groups": [{"name": "b", "shape": {"box": [0.3, 0.3, 0.3]}, "count": 3000,
    "layout": {"type": "grid", "min": [-0.02, -0.02, -0.02], "max": [0.02, 0.02, 0.02], "spacing": 0.001}}]})";
  std::ofstream(dir_ / "sweep.json") << R"({"name": "each", "kind": "steps", "engines": ["cpu"], "warmup": 0,
    "frames": 30, "repeat": 3, "scenes": ["small1", "small2", "small3", "small4", "dense"]})";
  const fs::path out = dir_ / "r.json";
  const fs::path err = dir_ / "stderr.txt";
  const pid_t pid = ::fork();
  if (pid == 0) {
    const int e = ::open(err.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    ::dup2(e, 2);
    const std::string b = octocd::test::bin(), sw = (dir_ / "sweep.json").string(), o = out.string(),
                      sd = dir_.string();
    ::execl(b.c_str(), b.c_str(), "bench", sw.c_str(), "-o", o.c_str(), "--scene-dir", sd.c_str(), "--max-time",
            "0", static_cast<char*>(nullptr));
    ::_exit(127);
  }
  ASSERT_GT(pid, 0);
  json first;
  std::string invalid;  // a state of the file that was not a whole JSON document
  const bool held = octocd::test::wait_until(
      [&] {
        const std::string text = slurp(out);
        if (text.empty()) return false;
        json j = json::parse(text, nullptr, false);
        if (j.is_discarded()) {
          invalid = text;
          return false;
        }
        if (!j.contains("points") || j["points"].empty()) return false;
        first = j;
        return true;
      },
      {dir_}, std::chrono::seconds(120));
  if (!held) ::kill(pid, SIGKILL);
  ASSERT_TRUE(held) << "no point in the result within 120 s: " << slurp(err);
  EXPECT_TRUE(invalid.empty()) << "the result was read as invalid JSON: " << invalid;
  // The first point is stored while the sweep still runs: not complete, not stopped.
  EXPECT_EQ(first["complete"], false);
  EXPECT_FALSE(first.contains("stopped"));
  ::kill(pid, SIGINT);
  int status = 0;
  const bool ended = octocd::test::wait_child(pid, status, std::chrono::seconds(60));
  if (!ended) ::kill(pid, SIGKILL);
  ASSERT_TRUE(ended) << "still running 60 s after SIGINT";
  ASSERT_TRUE(WIFEXITED(status)) << slurp(err);
  EXPECT_EQ(WEXITSTATUS(status), 130) << slurp(err);
  const json j = json::parse(slurp(out));  // valid after the stop too
  // Stopped between two frames: `stopped` recorded; inside a step longer than the grace (the
  // dense point's), the stop ends the process with the file as written after the last point.
  if (j.contains("stopped")) {
    EXPECT_EQ(j["stopped"], "SIGINT");
  }
  EXPECT_EQ(j["complete"], false);
  ASSERT_GE(j["points"].size(), 1u);
  EXPECT_LE(j["points"].size(), 4u) << "the long point never finishes before the stop";
  for (const auto& p : j["points"]) {
    EXPECT_EQ(p["status"], "ok") << p.dump();
    EXPECT_EQ(p["windows"]["all"]["steps_per_s"]["n"], p["budget"]["repetitions"]) << p.dump();
    EXPECT_EQ(p["budget"]["repetitions"], 3) << "no time limit: the repetitions asked, " << p.dump();
    EXPECT_EQ(p["budget"]["ended_by"], "repetitions") << p.dump();
    EXPECT_NE(p["id"], "dense | cpu");
  }
  const std::string e = slurp(err);
  const std::string n = std::to_string(j["points"].size());
  EXPECT_TRUE(e.find("octocd bench: stopped by SIGINT after " + n + " of 5 points") != std::string::npos ||
              e.find("the result " + out.string() + " keeps the " + n + " point(s) finished before") != std::string::npos)
      << e;
}

// Round-robin within groups of 4 consecutive points (design.md section 14b): inside a group,
// repetition r of each point starts before repetition r + 1 of any; the next group starts once
// the group's points are finished (and stored), never interleaved with them.
TEST_F(BenchBudget, RepetitionsRunRoundRobinWithinGroupsOfFourPoints) {
  for (int k = 1; k <= 6; ++k) fs::copy_file(dir_ / "small.json", dir_ / ("s" + std::to_string(k) + ".json"));
  std::ofstream(dir_ / "sweep.json") << R"({"name": "groups", "kind": "steps", "engines": ["cpu"], "warmup": 0,
    "frames": 5, "repeat": 3, "scenes": ["s1", "s2", "s3", "s4", "s5", "s6"]})";
  const fs::path out = dir_ / "r.json";
  const auto r = bench("sweep.json", "--max-time 0 --quiet", out);
  ASSERT_EQ(r.code, 0) << r.output;
  const json j = json::parse(slurp(out));
  ASSERT_EQ(j["points"].size(), 6u);
  std::vector<std::vector<double>> starts;
  for (const auto& p : j["points"]) {
    ASSERT_EQ(p["status"], "ok") << p.dump();
    ASSERT_EQ(p["repetition_start_s"].size(), 3u) << p.dump();
    starts.push_back(p["repetition_start_s"].get<std::vector<double>>());
  }
  for (std::size_t rep = 0; rep + 1 < 3; ++rep)
    for (std::size_t a = 0; a < 4; ++a)
      for (std::size_t b = 0; b < 4; ++b) EXPECT_LT(starts[a][rep], starts[b][rep + 1]) << a << " " << b;
  for (std::size_t a = 0; a < 4; ++a)
    for (std::size_t b = 4; b < 6; ++b) EXPECT_LT(starts[a][2], starts[b][0]) << a << " " << b;
  for (std::size_t rep = 0; rep + 1 < 3; ++rep) EXPECT_LT(starts[4][rep], starts[5][rep + 1]);
}

// A point whose repetitions would take minutes: the budget cuts its first repetition at its
// share of max_time_s to a count of timed frames on the halving ladder, the later ones run
// that count, and the point states the frames and repetitions reached (result and progress line).
TEST_F(BenchBudget, BudgetCutsASlowPointAndStatesTheCountReached) {
  std::ofstream(dir_ / "sweep.json") << R"({"name": "slow", "kind": "steps", "engines": ["cpu"], "warmup": 2,
    "frames": 80000000, "repeat": 3, "scenes": ["small"]})";
  const fs::path out = dir_ / "r.json";
  const auto r = bench("sweep.json", "--max-time 3", out);
  ASSERT_EQ(r.code, 0) << r.output;
  const json j = json::parse(slurp(out));
  EXPECT_EQ(j["settings"]["protocol"], "budget");
  EXPECT_EQ(j["settings"]["max_time_s"], 3.0);
  ASSERT_EQ(j["points"].size(), 1u);
  const json& p = j["points"][0];
  ASSERT_EQ(p["status"], "ok") << p.dump();
  const json& b = p["budget"];
  EXPECT_EQ(b["frames_asked"], 80000000);
  const int frames = b["frames"].get<int>();
  EXPECT_LT(frames, 80000000);
  EXPECT_GE(frames, 1);
  int ladder = 80000000;  // 80M, 40M, 20M, ... rounded up
  while (ladder > frames) ladder = (ladder + 1) / 2;
  EXPECT_EQ(ladder, frames) << "a count of the halving ladder";
  EXPECT_EQ(p["windows"]["all"]["frames"], frames);
  EXPECT_EQ(p["windows"]["all"]["first"], 3);
  EXPECT_EQ(p["windows"]["all"]["last"], 2 + frames);
  const int reps = b["repetitions"].get<int>();
  EXPECT_EQ(b["repetitions_asked"], 3);
  EXPECT_GE(reps, 1);
  EXPECT_EQ(p["windows"]["all"]["steps_per_s"]["n"], reps);
  EXPECT_EQ(p["windows"]["all"]["steps_per_s"]["values"].size(), static_cast<std::size_t>(reps));
  // The point's time is its set-ups and frames: not the 80M frames asked (minutes).
  EXPECT_LT(b["time_s"].get<double>(), 3.0 + 10.0) << b.dump();
  EXPECT_EQ(b["cut"]["frames"], frames);
  EXPECT_NE(r.output.find(std::to_string(reps) + " of 3 repetitions, " + std::to_string(frames) +
                          " of 80000000 timed frames"),
            std::string::npos)
      << r.output;
}

// A point that cannot time one frame within its share of the budget is skipped, saying why
// and how long it would take, estimated from the frames it stepped; --protocol paper runs the
// same sweep's full protocol (every frame and repetition asked, no budget), refuses options
// that would change it, and the named table5 keeps the paper's 300 frames after 30, 5 times.
TEST_F(BenchBudget, SkippedPointStatesItsEstimateAndPaperKeepsTheFullProtocol) {
  std::ofstream(dir_ / "sweep.json") << R"({"name": "paper", "kind": "steps", "engines": ["cpu"], "warmup": 3000000,
    "frames": 7, "repeat": 5, "max_time_s": 0.5, "scenes": ["small"]})";
  const fs::path skipped = dir_ / "skipped.json";
  const auto r = bench("sweep.json", "", skipped);
  EXPECT_EQ(r.code, 2) << "its only point skipped: " << r.output;
  const json s = json::parse(slurp(skipped));
  ASSERT_EQ(s["points"].size(), 1u);
  const json& p = s["points"][0];
  EXPECT_EQ(p["status"], "skipped");
  EXPECT_NE(p["reason"].get<std::string>().find("over the time budget"), std::string::npos) << p.dump();
  EXPECT_NE(p["reason"].get<std::string>().find("--protocol paper"), std::string::npos) << p.dump();
  // Estimated from the frames stepped: the repetition's 3,000,007 frames at the probe's rate.
  const json& e = p["estimate_s"];
  ASSERT_TRUE(e.is_object()) << p.dump();
  EXPECT_GT(e["probe_frames"].get<int>(), 0);
  EXPECT_NEAR(e["repetition"].get<double>(),
              e["setup_s"].get<double>() + 3000007.0 / e["probe_steps_per_s"].get<double>(), 1e-6 * e["repetition"].get<double>());
  EXPECT_NEAR(e["point"].get<double>(), 5 * e["repetition"].get<double>(), 1e-9 * e["point"].get<double>());
  EXPECT_GT(e["point"].get<double>(), 0.5);

  // The paper protocol: a short sweep, so every frame runs; the sweep's max_time_s is ignored.
  std::ofstream(dir_ / "short.json") << R"({"name": "short", "kind": "steps", "engines": ["cpu"], "warmup": 3,
    "frames": 7, "repeat": 5, "max_time_s": 0.000001, "scenes": ["small"]})";
  const fs::path paper = dir_ / "paper.json";
  const auto rp = bench("short.json", "--protocol paper", paper);
  ASSERT_EQ(rp.code, 0) << rp.output;
  const json j = json::parse(slurp(paper));
  EXPECT_EQ(j["settings"]["protocol"], "paper");
  EXPECT_EQ(j["settings"]["max_time_s"], 0.0);
  EXPECT_EQ(j["settings"]["repeat"], 5);
  const json& q = j["points"][0];
  ASSERT_EQ(q["status"], "ok") << q.dump();
  EXPECT_EQ(q["windows"]["all"]["frames"], 7);
  EXPECT_EQ(q["windows"]["all"]["first"], 4);
  EXPECT_EQ(q["windows"]["all"]["last"], 10);
  EXPECT_EQ(q["windows"]["all"]["steps_per_s"]["n"], 5);
  EXPECT_EQ(q["budget"]["repetitions"], 5);
  EXPECT_EQ(q["budget"]["ended_by"], "repetitions");
  // The same sweep under its own budget (1 us a point) is skipped: the budget was what paper lifted.
  const auto rb = bench("short.json", "", dir_ / "budget.json");
  EXPECT_EQ(rb.code, 2) << rb.output;
  EXPECT_NE(slurp(dir_ / "budget.json").find("over the time budget"), std::string::npos);

  for (const std::string opt : {"--frames 3", "--warmup 1", "--repeat 2", "--max-time 5", "--min-time 1"}) {
    const auto bad = bench("short.json", "--protocol paper " + opt, dir_ / "bad.json");
    EXPECT_EQ(bad.code, 2) << opt << ": " << bad.output;
    EXPECT_NE(bad.output.find("--protocol paper"), std::string::npos) << bad.output;
    EXPECT_FALSE(fs::exists(dir_ / "bad.json"));
  }
  // The named table5 under the paper protocol: 30 warm-up + 300 timed frames, 5 repetitions,
  // no budget (its settings, checked through --print of the definition and a run whose every
  // point is skipped: the cuda engine of a build without CUDA).
  const auto engines = octocd::test::run_octocd("engines");
  if (std::regex_search(engines.output, std::regex("(^|\n)cuda +available")))
    GTEST_SKIP() << "this build runs cuda: table5 would run";
  const fs::path t5 = dir_ / "t5.json";
  const auto rt = octocd::test::run_octocd("bench table5 --protocol paper --engines cuda -o " + t5.string());
  ASSERT_EQ(rt.code, 2) << rt.output;
  const json t = json::parse(slurp(t5));
  EXPECT_EQ(t["settings"]["frames"], 330);
  EXPECT_EQ(t["settings"]["warmup"], 30);
  EXPECT_EQ(t["settings"]["repeat"], 5);
  EXPECT_EQ(t["settings"]["protocol"], "paper");
  EXPECT_EQ(t["settings"]["max_time_s"], 0.0);
  EXPECT_NE(rt.output.find("protocol paper (no time budget)"), std::string::npos) << rt.output;
}

}  // namespace

}  // namespace octocd_test_cli_bench_budget
