// `octocd run --worlds K` (batched worlds, core/include/octocd/worlds.hpp; docs/gpu.md
// "Batched worlds"): the summary's world-steps/s, the copies' cells, what is refused, and
// what a stopped run of copies says.
#include <fcntl.h>
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <regex>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "support/cli_run.hpp"
#include "support/wait_event.hpp"

// This file's own names (its tests compile in unity batches with the folder's other files).
namespace octocd_test_cli_worlds {

namespace fs = std::filesystem;
using octocd::test::Result;
using octocd::test::run_octocd;
using octocd::test::source_dir;

namespace {

std::string box_stack() { return source_dir() + "/datasets/scenes/box-stack.json"; }

fs::path temp_dir() {
  const fs::path d = fs::temp_directory_path() / ("octocd_worlds_" + std::to_string(::getpid()));
  fs::create_directories(d);
  return d;
}

}  // namespace

TEST(CliWorlds, SummaryGivesWorldStepsPerSecondAndEveryCopyInItsCell) {
  const fs::path d = temp_dir();
  const std::string js = (d / "summary.json").string();
  const Result r = run_octocd("run " + box_stack() + " --worlds 9 --frames 50 --summary-json " + js);
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_NE(r.output.find("box-stack x9 worlds (45 bodies"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("worlds       9 copies of 5 bodies (grid 3 x 3 on x, z"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("every copy stayed in its cell"), std::string::npos) << r.output;
  std::ifstream f(js);
  const nlohmann::json j = nlohmann::json::parse(f);
  EXPECT_EQ(j.at("bodies"), 45);
  EXPECT_EQ(j.at("worlds"), 9);
  EXPECT_EQ(j.at("worlds_escaped"), 0);
  EXPECT_DOUBLE_EQ(j.at("world_steps_per_s").get<double>(), 9.0 * j.at("steps_per_s").get<double>());
  fs::remove_all(d);
}

TEST(CliWorlds, AReferenceEngineRunsTheCopiesAsSeparateRuns) {
  const fs::path d = temp_dir();
  const std::string js = (d / "summary.json").string();
  const Result r = run_octocd("run " + box_stack() + " --worlds 3 --world-perturb 1e-4 --frames 20 --engine bullet "
                              "--summary-json " + js);
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_NE(r.output.find("box-stack (5 bodies) x 3 copies as separate runs"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("worlds       3 copies as separate runs of engine bullet"), std::string::npos) << r.output;
  std::ifstream f(js);
  const nlohmann::json j = nlohmann::json::parse(f);
  EXPECT_EQ(j.at("worlds"), 3);
  EXPECT_EQ(j.at("worlds_separate_runs"), true);
  EXPECT_GT(j.at("world_steps_per_s").get<double>(), 0.0);
  fs::remove_all(d);
}

TEST(CliWorlds, TracesAndOutOfRangeCountsAreRefusedWithTheReason) {
  const fs::path d = temp_dir();
  for (const std::string engine : {"cpu", "bullet"}) {
    const Result traced = run_octocd("run " + box_stack() + " --worlds 4 --frames 5 --quiet --engine " + engine +
                                     " --trace " + (d / "t.h5").string());
    EXPECT_EQ(traced.code, 2) << traced.output;
    EXPECT_NE(traced.output.find("--trace with --worlds"), std::string::npos) << traced.output;
    EXPECT_FALSE(fs::exists(d / "t.h5"));
  }
  fs::remove_all(d);
  const Result zero = run_octocd("run " + box_stack() + " --worlds 0 --quiet");
  EXPECT_EQ(zero.code, 2) << zero.output;
  EXPECT_NE(zero.output.find("--worlds"), std::string::npos) << zero.output;
}

TEST(CliWorlds, BenchSweepsTakeWorldsAndReportWorldStepsPerSecond) {
  const fs::path d = temp_dir();
  const fs::path sweep = d / "w.json";
  std::ofstream(sweep) << R"({"name": "w", "kind": "steps", "scenes": [")" << box_stack()
                       << R"("], "engines": ["cpu", "bullet"], "worlds": [1, 3, 5], "max_worlds": {"cpu": 3},
                           "warmup": 2, "frames": 10, "repeat": 2})";
  const std::string out = (d / "r.json").string();
  const Result r = run_octocd("bench " + sweep.string() + " -o " + out + " --quiet");
  ASSERT_EQ(r.code, 0) << r.output;
  std::ifstream f(out);
  const nlohmann::json res = nlohmann::json::parse(f);
  std::vector<std::string> ids;
  for (const auto& p : res.at("points")) {
    ids.push_back(p.at("id"));
    const long k = p.at("params").at("worlds");
    if (p.at("params").at("engine") == "bullet" && k > 1) {
      EXPECT_EQ(p.at("status"), "skipped") << p.at("id");
      EXPECT_NE(p.at("reason").get<std::string>().find("steps one scene per run"), std::string::npos);
      continue;
    }
    ASSERT_EQ(p.at("status"), "ok") << p.dump();
    EXPECT_EQ(p.at("bodies"), 5 * k);
    const auto& w = p.at("windows").at("all");
    const auto sps = w.at("steps_per_s").at("values").get<std::vector<double>>();
    const auto wsps = w.at("world_steps_per_s").at("values").get<std::vector<double>>();
    ASSERT_EQ(sps.size(), 2u);
    ASSERT_EQ(wsps.size(), 2u);
    for (std::size_t i = 0; i < 2; ++i) EXPECT_DOUBLE_EQ(wsps[i], static_cast<double>(k) * sps[i]) << p.at("id");
  }
  // cpu stops at 3 copies (max_worlds); bullet has every count, skipped above one.
  const std::vector<std::string> want{"box-stack | worlds=1 | cpu", "box-stack | worlds=1 | bullet",
                                      "box-stack | worlds=3 | cpu", "box-stack | worlds=3 | bullet",
                                      "box-stack | worlds=5 | bullet"};
  EXPECT_EQ(ids, want);
  std::ofstream(sweep) << R"({"name": "w", "kind": "steps", "scenes": [")" << box_stack() << R"("], "worlds": [0]})";
  const Result bad = run_octocd("bench " + sweep.string() + " -o " + out + " --quiet");
  EXPECT_EQ(bad.code, 2) << bad.output;
  EXPECT_NE(bad.output.find("worlds[0]"), std::string::npos) << bad.output;
  fs::remove_all(d);
}

// `run --worlds K` on a reference engine stopped by SIGTERM while its copies run one at a
// time (ode): the line says how many copies ran whole and where the one cut short stopped,
// the summary and --summary-json say the same. Before: "stopped by SIGTERM after frame 1 of
// 20" beside "10000 copies ..., wall 4.25 s for all copies", and every copy not begun was
// still made. The event: the progress line of the first copy run whole.
TEST(CliWorlds, AStoppedRunOfCopiesSaysHowManyCopiesRan) {
  const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
  const fs::path d = temp_dir() / info->name();
  fs::create_directories(d);
  const fs::path err_file = d / "stderr.txt", js = d / "summary.json";
  const pid_t pid = ::fork();
  if (pid == 0) {
    const int out = ::open((d / "stdout.txt").c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    const int err = ::open(err_file.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    ::dup2(out, 1);
    ::dup2(err, 2);
    const std::string b = octocd::test::bin(), scene = box_stack();
    ::execl(b.c_str(), b.c_str(), "run", scene.c_str(), "--engine", "ode", "--worlds", "100000", "--frames", "20",
            "--summary-json", js.c_str(), static_cast<char*>(nullptr));
    ::_exit(127);
  }
  const auto slurp = [](const fs::path& p) {
    std::ifstream in(p);
    return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  };
  const bool one_whole = octocd::test::wait_until(
      [&] { return slurp(err_file).find("worlds: 1 of 100000 copies run") != std::string::npos; }, {d},
      std::chrono::seconds(60));
  ::kill(pid, SIGTERM);
  int status = 0;
  ASSERT_TRUE(octocd::test::wait_child(pid, status, std::chrono::seconds(30)));
  const std::string out = slurp(d / "stdout.txt"), err = slurp(err_file);
  if (err.find("not built") != std::string::npos) GTEST_SKIP() << err;
  ASSERT_TRUE(one_whole) << err;
  ASSERT_TRUE(WIFEXITED(status)) << err;
  EXPECT_EQ(WEXITSTATUS(status), 143) << err;
  std::smatch m;
  ASSERT_TRUE(std::regex_search(err, m, std::regex("octocd run: stopped by SIGTERM after ([0-9]+) of 100000 copies "
                                                   "\\(20 frames each\\)(; copy [0-9]+ stopped after frame [0-9]+)?; "
                                                   "--summary-json .* holds the copies run\n")))
      << err;
  const long whole = std::stol(m[1].str());
  EXPECT_GE(whole, 1);
  EXPECT_LT(whole, 100000);
  EXPECT_NE(out.find("frames       20 per copy (dt 0.001 s), wall "), std::string::npos) << out;
  EXPECT_NE(out.find(std::to_string(whole) + " of 100000 copies run whole (stopped)"), std::string::npos) << out;
  std::ifstream f(js);
  const nlohmann::json j = nlohmann::json::parse(f);
  EXPECT_EQ(j.at("worlds"), 100000);
  EXPECT_EQ(j.at("worlds_whole"), whole);
  fs::remove_all(temp_dir());
}

}  // namespace octocd_test_cli_worlds
