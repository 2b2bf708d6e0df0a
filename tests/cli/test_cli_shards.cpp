// `octocd validate --trace-in T --shard i/N --json` and `validate --merge` (issue 33 item
// 6), and `validate --threads` (the verdict does not depend on it): a Bullet run with
// rotation (a correct engine that is not octocd) and the same trace
// with every contact normal flipped (planted: failing rows with counts, figures, examples
// and items in every shard) are judged whole and in 3 shards; the merged verdict equals
// the whole run's row for row (tier, name, figure, measured, bound, verdict, judged,
// tolerances, causes with their counts, worst figures, examples and items). Bad shards
// exit 2 naming the file.
#include <gtest/gtest.h>
#include <hdf5.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <string>

#include <nlohmann/json.hpp>

#include "support/cli_run.hpp"
#include "support/trace_edit.hpp"

// This file's own names (its tests compile in unity batches with the folder's other files).
namespace octocd_test_cli_shards {

namespace fs = std::filesystem;

namespace {

using octocd::test::Result;
using octocd::test::run_octocd;

nlohmann::json load(const fs::path& p) {
  std::ifstream in(p);
  return nlohmann::json::parse(in);
}

/// The rows of a --json file (docs/validation-output.md), each without its seconds: the
/// verdict only, for comparing runs.
nlohmann::json verdict_rows(const fs::path& p) {
  nlohmann::json j = load(p);
  for (auto& row : j["rows"]) row.erase("seconds");
  return j["rows"];
}

class Shards : public ::testing::Test {
 protected:
  static fs::path dir_;
  static void SetUpTestSuite() {
    dir_ = fs::temp_directory_path() / ("octocd-shards-" + std::to_string(::getpid()));
    fs::create_directories(dir_);
    const fs::path scene = dir_ / "drop.json";
    std::ofstream(scene) << R"({
      "name": "shards", "rotation": true, "dt": 0.002, "frames": 90,
      "domain": {"min": [-0.4, 0, -0.4], "max": [0.4, 1.0, 0.4]}, "walls": "open-box",
      "groups": [
        {"name": "big", "shape": {"box": [0.06, 0.04, 0.05]}, "count": 6, "mass": 1,
         "orientation": {"axis": [0.6, 0, 0.8], "angle_deg": 30},
         "layout": {"type": "random", "min": [-0.25, 0.05, -0.25], "max": [0.25, 0.3, 0.25], "seed": 3}},
        {"name": "small", "shape": {"box": [0.03, 0.03, 0.03]}, "count": 6, "mass": 0.3,
         "layout": {"type": "random", "min": [-0.25, 0.32, -0.25], "max": [0.25, 0.5, 0.25], "seed": 5}}
      ]})";
    const Result r = run_octocd("run " + scene.string() + " --engine bullet --rotation --frames 90 --trace " +
                                (dir_ / "clean.h5").string() + " --state-every 1 --contacts --no-xdmf --quiet");
    ASSERT_EQ(r.code, 0) << r.output;
    // Planted: every contact normal flipped (it then points from A to B).
    fs::copy_file(dir_ / "clean.h5", dir_ / "flipped.h5", fs::copy_options::overwrite_existing);
    const hid_t f = H5Fopen((dir_ / "flipped.h5").string().c_str(), H5F_ACC_RDWR, H5P_DEFAULT);
    ASSERT_GE(f, 0);
    octocd::test::Data n = octocd::test::read(f, "/contacts/normal");
    ASSERT_GT(n.rows(), 30u) << "the run holds contacts";
    for (double& x : n.v) x = -x;
    octocd::test::write(f, "/contacts/normal", n);
    H5Fclose(f);
  }
  static void TearDownTestSuite() {
    std::error_code ec;
    fs::remove_all(dir_, ec);
  }
  static std::string path(const std::string& name) { return (dir_ / name).string(); }
  /// Judges `trace` whole (shard "") or as shard i/N, writing `json`.
  static Result judge(const std::string& trace, const std::string& shard, const std::string& json,
                      const std::string& extra = "") {
    return run_octocd("validate --trace-in " + path(trace) + " --every 3 " + extra +
                      (shard.empty() ? "" : " --shard " + shard) + " --json " + path(json));
  }

  /// Judges `trace` whole and in 3 shards, merges, and compares.
  static void same_as_whole(const std::string& trace, int want_code) {
    const Result whole = judge(trace, "", trace + ".whole.json");
    ASSERT_EQ(whole.code, want_code) << whole.output;
    std::string files;
    for (int i = 0; i < 3; ++i) {
      const std::string name = trace + ".s" + std::to_string(i) + ".json";
      const Result s = judge(trace, std::to_string(i) + "/3", name);
      ASSERT_TRUE(s.code == 0 || s.code == 3) << s.output;
      files += " " + path(name);
    }
    const Result merged = run_octocd("validate --merge" + files + " --json " + path(trace + ".merged.json"));
    ASSERT_EQ(merged.code, want_code) << merged.output;
    EXPECT_NE(merged.output.find("merged from 3 shards"), std::string::npos) << merged.output;
    const nlohmann::json a = load(dir_ / (trace + ".whole.json")), b = load(dir_ / (trace + ".merged.json"));
    ASSERT_EQ(a["rows"].size(), b["rows"].size());
    int failing = 0, counted = 0;
    for (std::size_t r = 0; r < a["rows"].size(); ++r) {
      const nlohmann::json& x = a["rows"][r];
      const nlohmann::json& y = b["rows"][r];
      for (const char* key : {"tier", "name", "figure", "measured", "bound", "verdict", "judged", "tolerances", "causes"})
        EXPECT_EQ(x[key], y[key]) << trace << ": row " << x["name"] << ", " << key;
      failing += x["verdict"] == "fail";
      for (const auto& c : x["causes"]) counted += c["count"].get<int>() > 5;
    }
    EXPECT_EQ(a["frames"], b["frames"]);
    if (want_code == 3) {
      EXPECT_GE(failing, 1) << "the planted fault fails rows: the comparison covers failures";
      EXPECT_GE(counted, 1) << "a cause with more failures than examples: counts and examples are merged";
    }
  }
};
fs::path Shards::dir_;

TEST_F(Shards, MergedShardsOfACleanBulletRunEqualTheWholeRun) { same_as_whole("clean.h5", 0); }

TEST_F(Shards, MergedShardsOfAPlantedFaultEqualTheWholeRun) { same_as_whole("flipped.h5", 3); }

TEST_F(Shards, BadShardsExitTwoNamingTheFile) {
  for (int i = 0; i < 3; ++i) {
    const int code = judge("flipped.h5", std::to_string(i) + "/3", "f" + std::to_string(i) + ".json").code;
    ASSERT_TRUE(code == 0 || code == 3) << code;
  }
  ASSERT_EQ(judge("clean.h5", "2/3", "c2.json").code, 0);
  ASSERT_EQ(judge("flipped.h5", "2/3", "t2.json", "--tolerance normal_angle_deg=50").code, 3);
  ASSERT_EQ(judge("flipped.h5", "", "whole.json").code, 3);
  auto merge = [&](const std::string& files) { return run_octocd("validate --merge " + files); };
  const std::string f0 = path("f0.json"), f1 = path("f1.json"), f2 = path("f2.json");
  // Overlapping: shard 0 twice.
  Result r = merge(f0 + " " + f0 + " " + f2);
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find("f0.json: shard 0/3 overlaps"), std::string::npos) << r.output;
  // Missing: shard 2.
  r = merge(f0 + " " + f1);
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find("shard 2/3 (frames 61..90) is missing"), std::string::npos) << r.output;
  // Another trace's shard.
  r = merge(f0 + " " + f1 + " " + path("c2.json"));
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find("c2.json: not a shard of the same run: trace"), std::string::npos) << r.output;
  // Other tolerances.
  r = merge(f0 + " " + f1 + " " + path("t2.json"));
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find("t2.json: not a shard of the same run: tolerances"), std::string::npos) << r.output;
  // Not a shard: an unsharded run's JSON.
  r = merge(f0 + " " + f1 + " " + path("whole.json"));
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find("whole.json: no \"shard\" object"), std::string::npos) << r.output;
  // --shard needs --trace-in; a malformed share.
  r = run_octocd("validate --trace-in " + path("clean.h5") + " --shard 3/3");
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find("--shard: '3/3'; allowed: i/N"), std::string::npos) << r.output;
}

}  // namespace

namespace {

// The geometric rows (contact-completeness, contact-geometry, penetration) judge their
// pairs and rows on threads. A Bullet run of 216 cubes stacked touching (about 8,000
// contact rows a checked frame), every normal flipped (planted) and judged with
// tolerances tight enough that contact-geometry and penetration fail far more items than
// they keep examples of, gives the same rows (verdicts, counts, worst and first examples,
// items, details) with 1 and with 2 threads.
TEST(ValidateThreads, GeometricRowsOnThreadsGiveTheSerialVerdict) {
  const fs::path dir = fs::temp_directory_path() / ("octocd-geometry-threads-" + std::to_string(::getpid()));
  fs::create_directories(dir);
  const fs::path scene = dir / "stack.json";
  std::ofstream(scene) << R"({
    "name": "threads-stack", "rotation": true, "dt": 0.002, "frames": 40,
    "domain": {"min": [-0.5, 0, -0.5], "max": [0.5, 1.0, 0.5]}, "walls": "open-box",
    "groups": [{"name": "cubes", "shape": {"box": [0.05, 0.05, 0.05]}, "count": 216, "mass": 1,
      "layout": {"type": "grid", "min": [-0.3, 0.0499, -0.3], "max": [0.3, 0.7, 0.3], "spacing": 0.0999}}]})";
  const std::string trace = (dir / "stack.h5").string();
  const Result run = run_octocd("run " + scene.string() + " --engine bullet --rotation --frames 40 --trace " + trace +
                                " --state-every 1 --contacts --no-xdmf --quiet");
  ASSERT_EQ(run.code, 0) << run.output;
  {  // planted: every contact normal flipped
    const hid_t f = H5Fopen(trace.c_str(), H5F_ACC_RDWR, H5P_DEFAULT);
    ASSERT_GE(f, 0);
    octocd::test::Data n = octocd::test::read(f, "/contacts/normal");
    ASSERT_GT(n.rows(), 20000u) << "the stack holds thousands of contact rows a frame";
    for (double& x : n.v) x = -x;
    octocd::test::write(f, "/contacts/normal", n);
    H5Fclose(f);
  }
  auto rows = [&](const std::string& threads) {
    const fs::path out = dir / ("t" + threads + ".json");
    const Result r = run_octocd("validate --trace-in " + trace +
                                " --every 10 --tolerance penetration_slops=0.02 --tolerance depth_m=1e-6 "
                                "--tolerance geometry_slack_m=0 --tolerance contact_depth_m=1e-6 --threads " +
                                threads + " --json " + out.string());
    EXPECT_EQ(r.code, 3) << r.output;
    return verdict_rows(out);
  };
  const nlohmann::json serial = rows("1"), threaded = rows("2");
  ASSERT_EQ(serial.size(), threaded.size());
  int crowded = 0;  // causes of the geometric rows failing more items than they keep examples of
  for (std::size_t k = 0; k < serial.size(); ++k) {
    EXPECT_EQ(serial[k], threaded[k]) << serial[k]["name"];
    const std::string name = serial[k]["name"];
    if (name == "contact-geometry" || name == "penetration" || name == "contact-completeness") {
      EXPECT_GT(serial[k]["judged"].get<std::uint64_t>(), 1000u) << name;
      for (const auto& c : serial[k]["causes"]) crowded += c["count"].get<std::size_t>() > 100;
    }
  }
  EXPECT_GE(crowded, 2) << "the comparison covers failing geometric rows beyond their examples";
  std::error_code ec;
  fs::remove_all(dir, ec);
}

// Threads (per frame: reference geometry, the reference pair set) and the pipeline (frame f
// judged while the engine runs f + 1) change no verdict: a settling pile with contacts
// judged serially (--threads 1) and with 3 threads gives the same rows (all but seconds).
TEST(ValidateThreads, ThreadsAndPipelineGiveTheSerialVerdict) {
  const fs::path dir = fs::temp_directory_path() / ("octocd-threads-" + std::to_string(::getpid()));
  fs::create_directories(dir);
  const std::string scene = octocd::test::source_dir() + "/datasets/scenes/mixed-pile-1000.json";
  auto judge = [&](const std::string& threads) {
    const fs::path out = dir / ("t" + threads + ".json");
    const Result r = run_octocd("validate " + scene + " --frames 150 --every 10 --against none --threads " + threads +
                                " --json " + out.string());
    EXPECT_TRUE(r.code == 0 || r.code == 3) << r.output;
    return verdict_rows(out);
  };
  const nlohmann::json serial = judge("1"), threaded = judge("3");
  ASSERT_EQ(serial.size(), threaded.size());
  std::uint64_t judged = 0;
  for (std::size_t k = 0; k < serial.size(); ++k) {
    EXPECT_EQ(serial[k], threaded[k]) << serial[k]["name"];
    if (serial[k]["name"] == "contact-geometry") judged = serial[k]["judged"].get<std::uint64_t>();
  }
  EXPECT_GT(judged, 0u) << "the pile has contacts: the comparison covers judged rows";
  std::error_code ec;
  fs::remove_all(dir, ec);
}

// The model tier's per-contact rows (non-penetration-eq14, friction-monotonicity,
// impulse-conservation) judge a frame's contacts in blocks on the threads, merged in order,
// a block holding a row's first failure judged again on the calling thread: over 2,000
// contacts a frame of boxes-uniform-100k, with Eq. 14's tolerance tightened until a
// thousand contacts fail, 1 and 2 threads give the same rows (all but seconds), the first
// failure's text included.
TEST(ValidateThreads, PerContactModelRowsOnThreadsGiveTheSerialVerdict) {
  const fs::path dir = fs::temp_directory_path() / ("octocd-contact-rows-" + std::to_string(::getpid()));
  fs::create_directories(dir);
  const std::string scene = octocd::test::source_dir() + "/datasets/scenes/boxes-uniform-100k.json";
  auto judge = [&](const std::string& threads) {
    const fs::path out = dir / ("t" + threads + ".json");
    const Result r = run_octocd("validate " + scene + " --frames 8 --every 8 --against none " +
                                "--tolerance contraction_m=1e-8 --threads " + threads + " --json " + out.string());
    EXPECT_EQ(r.code, 3) << r.output;
    return verdict_rows(out);
  };
  const nlohmann::json serial = judge("1"), threaded = judge("2");
  ASSERT_EQ(serial.size(), threaded.size());
  bool seen = false;
  for (std::size_t k = 0; k < serial.size(); ++k) {
    EXPECT_EQ(serial[k], threaded[k]) << serial[k]["name"];
    if (serial[k]["name"] != "non-penetration-eq14") continue;
    seen = true;
    EXPECT_EQ(serial[k]["verdict"], "fail");
    EXPECT_GT(serial[k]["measured"].get<double>(), 100.0) << "failures in many blocks";
    const std::string detail = serial[k]["detail"];
    EXPECT_EQ(detail.rfind("frame 1: pair", 0), 0u) << detail;
  }
  EXPECT_TRUE(seen);
  // Over 2,048 contacts a frame (the rows go to the threads from 1,024): friction-monotonicity
  // counts one check a contact.
  for (const auto& row : serial)
    if (row["name"] == "friction-monotonicity") {
      const std::string detail = row["detail"];
      EXPECT_GT(std::stoull(detail), 8u * 2048u) << detail;
    }
  std::error_code ec;
  fs::remove_all(dir, ec);
}

}  // namespace

}  // namespace octocd_test_cli_shards
