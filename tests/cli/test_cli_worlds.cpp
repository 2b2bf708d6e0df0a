// `octocd run --worlds K` (batched worlds, core/include/octocd/worlds.hpp; docs/gpu.md
// "Batched worlds"): the summary's world-steps/s, the copies' cells, and what is refused.
#include <gtest/gtest.h>

#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <string>

#include <nlohmann/json.hpp>

#include "support/cli_run.hpp"

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
