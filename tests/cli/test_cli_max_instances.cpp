// `octocd bench` sweeps of kind max-instances (the named sweep `max-instances`, issue 20):
// the grown scenes against the shipped paper scenes, the bracket of a search against its
// own recorded probes (the oracle: the found count passes, the next one does not), the 0
// and the cap outcomes, SIGTERM and --resume, bad input (exit 2), and on a CUDA machine the
// device-memory limit (the engine's memory check, lowered by --cuda memory_limit_bytes=N) as the
// end of the search. CPU runs use a box template, a 2 + 5 frame window and a target steps/s
// of their own, so a search ends in seconds; no assertion depends on timings.
#include <gtest/gtest.h>

#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <set>
#include <sstream>
#include <string>

#include <nlohmann/json.hpp>

#include "octocd/cuda_world.hpp"
#include "octocd/engine.hpp"
#include "octocd/scene.hpp"
#include "support/cli_run.hpp"
#include "support/wait_event.hpp"

// This file's own names (its tests compile in unity batches with the folder's other files).
namespace octocd_test_cli_max_instances {

namespace fs = std::filesystem;
using json = nlohmann::json;
using octocd::test::bin;
using octocd::test::Result;
using octocd::test::run_octocd;
using octocd::test::source_dir;

namespace {

/// Eight 0.1 m boxes on a 2 x 2 x 2 grid (spacing 0.3 m) in a closed box, random velocities:
/// the paper's random scene in miniature (its grid a cube, so the template's own count gives
/// the template back).
const char* kTemplate = R"({"name": "boxes-random-8", "description": "boxes",
  "domain": {"min": [-0.3, -0.3, -0.3], "max": [0.3, 0.3, 0.3]},
  "gravity": [0, 0, 0], "dt": 0.001, "frames": 100, "walls": "closed-box",
  "broadphase": {"name": "octree", "depth": 2}, "midphase": {"levels": "aabb-only"},
  "groups": [{"name": "b", "shape": {"box": [0.05, 0.05, 0.05]}, "count": 8, "mass": 1.0,
    "layout": {"type": "grid", "min": [-0.15, -0.15, -0.15], "max": [0.15, 0.15, 0.15], "spacing": 0.3,
               "jitter": 0.03, "seed": 1},
    "velocity": {"type": "random", "max": 1.0, "seed": 2}}]})";

json read_json(const fs::path& p) {
  std::ifstream in(p);
  return json::parse(in);
}

class MaxInstances : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("octocd-maxinst-" + std::to_string(::getpid()) + "-" +
                                        ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::create_directories(dir_);
    write("boxes.json", kTemplate);
  }
  void TearDown() override { fs::remove_all(dir_); }
  std::string write(const std::string& name, const std::string& text) {
    const fs::path p = dir_ / name;
    std::ofstream(p) << text;
    return p.string();
  }
  /// A max-instances sweep over the box template; `extra` adds keys ("\"repeat\": 3, ...").
  std::string sweep(const std::string& extra = "", const std::string& engines = R"(["cpu"])") {
    return write("sweep.json", R"({"name": "mi", "kind": "max-instances", "scenes": ["boxes.json"], "engines": )" +
                                   engines + R"(, "warmup": 2, "frames": 5)" + (extra.empty() ? "" : ", " + extra) +
                                   "}");
  }
  /// Runs `bench SWEEP -o OUT ARGS` (quiet) and reads the result.
  json bench(const std::string& sweep_file, const std::string& args, int expect = 0, const std::string& out = "r.json") {
    const Result r = run_octocd("bench " + sweep_file + " -o " + (dir_ / out).string() + " --quiet " + args);
    EXPECT_EQ(r.code, expect) << r.output;
    last_output_ = r.output;
    return fs::exists(dir_ / out) ? read_json(dir_ / out) : json();
  }
  fs::path dir_;
  std::string last_output_;
};

/// The deciding measurement of count n in a search's points: its confirmation when there
/// is one, else its probe.
const json* deciding(const json& result, const std::string& engine, long n) {
  const json* probe = nullptr;
  for (const auto& p : result["points"]) {
    if (p["params"]["engine"] != engine || p["params"]["axes"]["instances"] != n) continue;
    if (p["role"] == "confirm") return &p;
    probe = &p;
  }
  return probe;
}

double median_sps(const json& p) { return p["windows"]["settled"]["steps_per_s"]["median"].get<double>(); }

}  // namespace

// The grown scenes: for the paper's counts the named sweep gives the shipped Table 5 scenes'
// grid and domain exactly (the scenes' depth 2 becomes auto, as the sweep sets it); other
// counts keep the density (slots of the same spacing, k = ceil(cbrt(n)) a side).
TEST_F(MaxInstances, GrownScenesAreThePaperScenesAtThePaperCounts) {
  const std::string scenes = source_dir() + "/datasets/scenes";
  const std::map<std::string, long> paper{{"bunny-random-400", 400},
                                          {"armadillo-random-250", 250},
                                          {"dragon-random-250", 250},
                                          {"asian-dragon-random-60", 60}};
  for (const auto& [name, count] : paper) {
    const Result r = run_octocd("bench max-instances --print-scene " + std::to_string(count) + " --scene-dir " + scenes);
    ASSERT_EQ(r.code, 0) << r.output;
    const auto at = r.output.find("// " + name + "\n");
    ASSERT_NE(at, std::string::npos) << r.output;
    const auto start = at + name.size() + 4;
    const auto end = r.output.find("\n// ", start);
    const json grown = json::parse(r.output.substr(start, end == std::string::npos ? std::string::npos : end - start));
    const json shipped = read_json(scenes + "/" + name + ".json");
    EXPECT_EQ(grown["domain"], shipped["domain"]) << name;
    EXPECT_EQ(grown["groups"][0]["layout"], shipped["groups"][0]["layout"]) << name;
    EXPECT_EQ(grown["groups"][0]["count"], count) << name;
    EXPECT_EQ(grown["name"], name) << name;
    EXPECT_EQ(grown["broadphase"]["depth"], "auto") << name;
    EXPECT_EQ(grown["midphase"]["levels"], "1,2") << name;
  }
  // 1000 bunnies: 10 x 10 x 10 slots of 0.3 m around the same centre, the same 0.15 m margin.
  const Result r = run_octocd("bench max-instances --print-scene 1000 --scene-dir " + scenes);
  ASSERT_EQ(r.code, 0) << r.output;
  const auto at = r.output.find("// bunny-random-400\n");
  ASSERT_NE(at, std::string::npos);
  const auto start = at + std::string("// bunny-random-400\n").size();
  const json g = json::parse(r.output.substr(start, r.output.find("\n// ", start) - start));
  EXPECT_EQ(g["groups"][0]["count"], 1000);
  EXPECT_EQ(g["groups"][0]["layout"]["min"], json({-1.35, -1.35, -1.35}));
  EXPECT_EQ(g["groups"][0]["layout"]["max"], json({1.35, 1.35, 1.35}));
  EXPECT_EQ(g["domain"]["min"], json({-1.5, -1.5, -1.5}));
  EXPECT_EQ(g["name"], "bunny-random-1000");
}

// The named sweep end to end on the CPU (counts 1 and 2, a 1 + 2 frame window) and its
// report section: the table model x engine beside the paper's counts and source lines.
TEST_F(MaxInstances, NamedSweepAndItsReportSection) {
  const std::string cache = source_dir() + "/datasets/cache";
  if (!fs::exists(cache + "/bunny.obj") || !fs::exists(cache + "/asian-dragon.off"))
    GTEST_SKIP() << "needs the dataset cache (datasets/cache: scripts/fetch-datasets)";
  const json j = bench("max-instances", "--engines cpu --warmup 1 --frames 2 --max-instances 2 --target 0.000001 "
                       "--data-dir " + cache + " --scene-dir " + source_dir() + "/datasets/scenes");
  ASSERT_EQ(j["searches"].size(), 4u);
  const std::vector<std::pair<std::string, int>> paper{
      {"bunny", 400}, {"armadillo", 250}, {"dragon", 250}, {"asian-dragon", 60}};
  for (std::size_t i = 0; i < 4; ++i) {
    const json& s = j["searches"][i];
    EXPECT_EQ(s["model"], paper[i].first);
    EXPECT_EQ(s["engine"], "cpu");
    EXPECT_EQ(s["paper"]["count"], paper[i].second);
    EXPECT_NE(s["paper"]["source"].get<std::string>().find("paper "), std::string::npos);
    EXPECT_EQ(s["max_instances"], 2);
    EXPECT_EQ(s["limited_by"], "cap");
    EXPECT_EQ(s["window"], json({{"first", 2}, {"last", 3}}));
  }
  EXPECT_EQ(j["settings"]["window"]["first"], 2);
  EXPECT_EQ(j["settings"]["target_steps_per_s"], 0.000001);
  const Result r = run_octocd("report " + (dir_ / "r.json").string() + " -o " + (dir_ / "rep").string());
  ASSERT_EQ(r.code, 0) << r.output;
  std::ifstream in(dir_ / "rep" / "report.md");
  std::stringstream md;
  md << in.rdbuf();
  EXPECT_NE(md.str().find("## Most instances at 30 steps/s (paper section 5.3)"), std::string::npos) << md.str();
  // report.md escapes Markdown in every cell (brackets too: `[...]` could open a link).
  EXPECT_NE(md.str().find("| model (scene) | paper: most instances at >= 30 FPS | cpu: N \\[bracket\\]: steps/s at N |"),
            std::string::npos)
      << md.str();
  EXPECT_NE(md.str().find("| bunny (bunny-random-400) | 400 | >= 2 (cap)"), std::string::npos) << md.str();
  EXPECT_NE(md.str().find("| asian-dragon (asian-dragon-random-60) | 60 | >= 2 (cap)"), std::string::npos) << md.str();
  EXPECT_NE(md.str().find("'The Bunny model maintained over 30 fps up to 400 instances'"), std::string::npos);
}

// The oracle: with a target between the steps/s of 1 and of 64 boxes, the search ends at a
// bracket [N, N+1] whose deciding measurements say N passes and N+1 does not; every probe's
// verdict agrees with its median; a cut repetition's stored value is below the target; the
// first probes double from 1; the bracket's ends were confirmed with 3 repetitions.
TEST_F(MaxInstances, BracketIsConsistentWithTheRecordedProbes) {
  // First: every count up to 64 passes a negligible target: the cap outcome, and the
  // steps/s of 1 and of 64 boxes to put the real target between.
  const json all = bench(sweep(R"("repeat": 1, "max_instances": 64)"), "--target 0.000001");
  ASSERT_EQ(all["searches"].size(), 1u);
  const json& capped = all["searches"][0];
  EXPECT_EQ(capped["status"], "ok");
  EXPECT_EQ(capped["max_instances"], 64);
  EXPECT_EQ(capped["bracket"], json({64, nullptr}));
  EXPECT_EQ(capped["limited_by"], "cap");
  std::set<long> counts;
  for (const auto& p : all["points"]) counts.insert(p["params"]["axes"]["instances"].get<long>());
  EXPECT_EQ(counts, (std::set<long>{1, 2, 4, 8, 16, 32, 64}));
  const double s1 = median_sps(*deciding(all, "cpu", 1)), s64 = median_sps(*deciding(all, "cpu", 64));
  const double target = std::sqrt(s1 * s64);

  const json j = bench(sweep(R"("repeat": 3, "probe_repeat": 1, "max_instances": 4096)"),
                       "--target " + std::to_string(target), 0, "search.json");
  ASSERT_EQ(j["searches"].size(), 1u);
  const json& s = j["searches"][0];
  ASSERT_EQ(s["status"], "ok") << s.dump();
  const long lo = s["max_instances"].get<long>();
  ASSERT_TRUE(s["bracket"][1].is_number()) << s.dump();
  const long hi = s["bracket"][1].get<long>();
  EXPECT_EQ(s["bracket"][0], lo);
  EXPECT_EQ(hi, lo + 1) << "resolution 0 ends at an integer bracket";
  EXPECT_EQ(s["limited_by"], "steps/s");
  if (lo >= 1) {
    const json* at_lo = deciding(j, "cpu", lo);
    ASSERT_NE(at_lo, nullptr);
    EXPECT_GE(median_sps(*at_lo), target);
    EXPECT_EQ((*at_lo)["verdict"], "pass");
    EXPECT_EQ((*at_lo)["role"], "confirm");
    EXPECT_EQ(s["steps_per_s"], (*at_lo)["windows"]["settled"]["steps_per_s"]);
  }
  const json* at_hi = deciding(j, "cpu", hi);
  ASSERT_NE(at_hi, nullptr);
  EXPECT_LT(median_sps(*at_hi), target);
  EXPECT_EQ((*at_hi)["verdict"], "below");
  EXPECT_EQ((*at_hi)["role"], "confirm");
  // Every point: its verdict from its median; cut repetitions hold bounds below the target.
  std::set<std::string> ids;
  std::set<int> indices;
  long expect_doubling = 1;
  bool doubling = true;
  for (const auto& p : j["points"]) {
    EXPECT_TRUE(ids.insert(p["id"].get<std::string>()).second) << p["id"];
    EXPECT_TRUE(indices.insert(p["index"].get<int>()).second) << p["id"];
    ASSERT_EQ(p["status"], "ok") << p.dump();
    const double m = median_sps(p);
    EXPECT_EQ(p["verdict"], m >= target ? "pass" : "below") << p["id"];
    const json& sps = p["windows"]["settled"]["steps_per_s"];
    const int cut = p["cut"]["repetitions_cut"].get<int>(), run = p["cut"]["repetitions_run"].get<int>();
    EXPECT_EQ(sps["n"], run) << p["id"];
    EXPECT_EQ(p["cut"]["repetitions_planned"], p["role"] == "confirm" ? 3 : 1) << p["id"];
    int below = 0;
    for (const auto& v : sps["values"]) below += v.get<double>() < target;
    EXPECT_GE(below, cut) << p["id"];  // every cut repetition is below (and only below ones are cut)
    EXPECT_EQ(below, cut) << p["id"];
    // The first probes: 1, 2, 4, ... until the first failure.
    if (doubling && p["role"] == "probe") {
      EXPECT_EQ(p["params"]["axes"]["instances"], expect_doubling) << p["id"];
      if (p["verdict"] != "pass") doubling = false;
      expect_doubling *= 2;
    }
  }
  EXPECT_EQ(s["probes"].get<std::size_t>() + s["confirmations"].get<std::size_t>(), j["points"].size());
}

// A model whose single instance already runs under the target reports 0 with the reason.
TEST_F(MaxInstances, SingleInstanceBelowTheTargetReportsZero) {
  const json j = bench(sweep(R"("repeat": 2, "target_steps_per_s": 1000000000)"), "");
  ASSERT_EQ(j["searches"].size(), 1u);
  const json& s = j["searches"][0];
  EXPECT_EQ(s["status"], "ok");
  EXPECT_EQ(s["max_instances"], 0);
  EXPECT_EQ(s["bracket"], json({0, 1}));
  EXPECT_EQ(s["limited_by"], "steps/s");
  EXPECT_NE(s["reason"].get<std::string>().find("a single instance already runs under 1e+09 steps/s"),
            std::string::npos)
      << s["reason"];
  // Count 1 only: its probe, then its confirmation with 2 repetitions (each cut, so the
  // second one does not run once the first is: most were cut).
  ASSERT_EQ(j["points"].size(), 2u);
  EXPECT_EQ(j["points"][0]["id"], "boxes | instances=1 | cpu");
  EXPECT_EQ(j["points"][1]["id"], "boxes | instances=1 | cpu | confirm");
  EXPECT_EQ(j["points"][1]["verdict"], "below");
  EXPECT_TRUE(j["complete"].get<bool>());
}

// SIGTERM between probes' frames: exit 143, the finished probes kept (no summary yet);
// --resume replays the search from them and measures only the rest.
TEST_F(MaxInstances, SigtermKeepsTheProbesAndResumeGoesOn) {
  // 4000 frames a probe, every count passes: probes 1, 2, 4, ..., 256, each slower (256
  // boxes at octree depth 2 take about 1 s here, the first two a few ms).
  const std::string sw = write("sweep.json", R"({"name": "mi", "kind": "max-instances", "scenes": ["boxes.json"],
    "engines": ["cpu"], "warmup": 0, "frames": 4000, "repeat": 1, "max_instances": 256,
    "target_steps_per_s": 0.000001})");
  const fs::path out = dir_ / "stopped.json";
  const pid_t pid = fork();
  ASSERT_GE(pid, 0);
  if (pid == 0) {
    const std::string b = bin(), o = out.string();
    std::freopen((dir_ / "stderr.txt").c_str(), "w", stderr);
    execl(b.c_str(), b.c_str(), "bench", sw.c_str(), "-o", o.c_str(), "--quiet", static_cast<char*>(nullptr));
    _exit(127);
  }
  // Wait for two finished probes (the later ones take longer; the result is renamed into
  // dir_ after each), then SIGTERM.
  octocd::test::wait_until(
      [&] {
        try {
          return fs::exists(out) && read_json(out)["points"].size() >= 2;
        } catch (const std::exception&) {
          return false;
        }
      },
      {dir_}, std::chrono::seconds(60));
  kill(pid, SIGTERM);
  int status = 0;
  waitpid(pid, &status, 0);
  ASSERT_TRUE(WIFEXITED(status));
  ASSERT_EQ(WEXITSTATUS(status), 143) << "the search ended before the signal";
  const json stopped = read_json(out);
  EXPECT_EQ(stopped["stopped"], "SIGTERM");
  EXPECT_FALSE(stopped["complete"].get<bool>());
  EXPECT_TRUE(stopped["searches"].empty());
  const std::size_t kept = stopped["points"].size();
  ASSERT_GE(kept, 2u);
  ASSERT_LT(kept, 9u);
  {
    std::ifstream err(dir_ / "stderr.txt");
    std::stringstream es;
    es << err.rdbuf();
    EXPECT_NE(es.str().find("octocd bench: stopped by SIGTERM after " + std::to_string(kept) + " probes"),
              std::string::npos)
        << es.str();
  }
  const json j = bench(sw, "--resume", 0, "stopped.json");
  EXPECT_TRUE(j["complete"].get<bool>());
  EXPECT_FALSE(j.contains("stopped"));
  ASSERT_EQ(j["searches"].size(), 1u);
  EXPECT_EQ(j["searches"][0]["max_instances"], 256);
  EXPECT_EQ(j["searches"][0]["limited_by"], "cap");
  ASSERT_EQ(j["points"].size(), 9u);  // 1, 2, 4, ..., 256: the kept ones not measured again
  for (std::size_t i = 0; i < j["points"].size(); ++i) {
    EXPECT_EQ(j["points"][i]["index"], static_cast<int>(i));
    EXPECT_EQ(j["points"][i]["params"]["axes"]["instances"], 1L << i);
    if (i < kept) {
      EXPECT_EQ(j["points"][i], stopped["points"][i]) << "kept probe " << i << " was measured again";
    }
  }
  // Another target: not the same settings, refused (exit 2 naming the file and settings).
  const Result r = run_octocd("bench " + sw + " -o " + out.string() + " --resume --quiet --target 5");
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find("settings"), std::string::npos) << r.output;
}

// --search-time: once a search has run that long it measures no new count and ends with the
// bracket it has (here during doubling: at least the last passing count).
TEST_F(MaxInstances, SearchTimeLimitEndsTheSearchWithItsBracket) {
  const std::string sw = write("sweep.json", R"({"name": "mi", "kind": "max-instances", "scenes": ["boxes.json"],
    "engines": ["cpu"], "warmup": 0, "frames": 4000, "repeat": 1, "max_instances": 16384,
    "target_steps_per_s": 0.000001})");
  const json j = bench(sw, "--search-time 1");
  ASSERT_EQ(j["searches"].size(), 1u);
  const json& s = j["searches"][0];
  EXPECT_EQ(s["limited_by"], "time");
  EXPECT_EQ(s["time_limit_s"], 1);
  EXPECT_TRUE(s["bracket"][1].is_null());
  long largest = 0;
  for (const auto& p : j["points"]) largest = std::max(largest, p["params"]["axes"]["instances"].get<long>());
  EXPECT_EQ(s["max_instances"], largest);  // every count measured passed; no unmeasured count in the bracket
  EXPECT_LT(largest, 16384);
  EXPECT_NE(s["reason"].get<std::string>().find("time limit (1 s) ended it: the maximum is at least " +
                                                std::to_string(largest)),
            std::string::npos)
      << s["reason"];
  EXPECT_EQ(j["settings"]["search_time_s"], 1);
}

// Bad input: one line, exit 2, naming the file and the key with the allowed values.
TEST_F(MaxInstances, BadInputExits2) {
  struct Case {
    std::string sweep_extra, args, expect;
  };
  const std::vector<Case> cases{
      {R"("max_instances": 0)", "", "max_instances: 0 is out of range; allowed: an integer in [1, 134217728]"},
      {R"("target_steps_per_s": -30)", "", "target_steps_per_s: -30 is out of range"},
      {R"("resolution": 1.5)", "", "resolution: 1.5 is out of range"},
      {R"("repeat": 2, "probe_repeat": 3)", "", "probe_repeat: 3 is above repeat (2)"},
      {R"("windows": [{"name": "w", "first": 1, "last": 2}])", "", "windows: unknown key for kind 'max-instances'"},
      {"", "--target 0", "--target"},
      {"", "--max-instances 0", "--max-instances"},
  };
  for (const auto& c : cases) {
    const Result r = run_octocd("bench " + sweep(c.sweep_extra) + " -o " + (dir_ / "bad.json").string() + " --quiet " +
                                c.args);
    EXPECT_EQ(r.code, 2) << c.sweep_extra << c.args << "\n" << r.output;
    EXPECT_NE(r.output.find(c.expect), std::string::npos) << r.output;
    EXPECT_FALSE(fs::exists(dir_ / "bad.json"));
  }
  // A template the search cannot grow: two groups; a layout that is not a grid.
  json two = json::parse(kTemplate);
  two["groups"].push_back(two["groups"][0]);
  two["groups"][1]["name"] = "c";
  write("boxes.json", two.dump());
  Result r = run_octocd("bench " + sweep() + " -o " + (dir_ / "bad.json").string() + " --quiet");
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find("boxes.json: groups: not exactly one group"), std::string::npos) << r.output;
  json random = json::parse(kTemplate);
  random["groups"][0]["layout"] = {{"type", "random"}, {"seed", 3}};
  write("boxes.json", random.dump());
  r = run_octocd("bench " + sweep() + " -o " + (dir_ / "bad.json").string() + " --quiet");
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find("boxes.json: groups[0].layout.type: not \"grid\""), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(dir_ / "bad.json"));
  // The max-instances options on another kind of sweep.
  r = run_octocd("bench table5 -o " + (dir_ / "bad.json").string() + " --quiet --target 30");
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find("only for sweeps of kind max-instances"), std::string::npos) << r.output;
  // Every search skipped (cuda alone, on a build or machine without it): exit 2 naming the
  // reason, the result kept.
  write("boxes.json", kTemplate);
  r = run_octocd("bench " + sweep() + " -o " + (dir_ / "cuda.json").string() +
                 " --quiet --engines cuda --max-instances 1 --target 0.000001");
  if (r.code != 0) {
    EXPECT_EQ(r.code, 2) << r.output;
    EXPECT_NE(r.output.find("every search skipped"), std::string::npos) << r.output;
    EXPECT_TRUE(fs::exists(dir_ / "cuda.json"));
  }
}

// On a CUDA machine: a count that does not fit device memory stops the search there (the
// engine's memory check before its first step, lowered by --cuda memory_limit_bytes to the
// estimate for 40 boxes): the bracket is [40, 41] with the reason, never a crash.
TEST_F(MaxInstances, DeviceMemoryStopsTheSearchThere) {
  const std::string sw = sweep(R"("repeat": 1, "max_instances": 1024, "target_steps_per_s": 0.000001)", R"(["cuda"])");
  const Result first = run_octocd("bench " + sw + " -o " + (dir_ / "first.json").string() + " --quiet --max-instances 1");
  if (first.code == 2) GTEST_SKIP() << "no cuda engine here: " << first.output.substr(0, 200);
  ASSERT_EQ(first.code, 0) << first.output;
  // The grown scene of 40 boxes and the engine's own estimate for it.
  const Result scene = run_octocd("bench " + sw + " --print-scene 40");
  ASSERT_EQ(scene.code, 0) << scene.output;
  const auto model = octocd::build_model(octocd::parse_scene(scene.output, "grown", ""));
  const std::uint64_t bytes = octocd::cuda_device_bytes_needed(*model, "octree");
  const Result m = octocd::test::run(bin() + " bench " + sw + " -o " + (dir_ / "mem2.json").string() +
                                     " --quiet --cuda memory_limit_bytes=" + std::to_string(bytes));
  ASSERT_EQ(m.code, 0) << m.output;
  const json j = read_json(dir_ / "mem2.json");
  ASSERT_EQ(j["searches"].size(), 1u);
  const json& s = j["searches"][0];
  EXPECT_EQ(s["status"], "ok");
  EXPECT_EQ(s["max_instances"], 40);
  EXPECT_EQ(s["bracket"], json({40, 41}));
  EXPECT_EQ(s["limited_by"], "memory");
  EXPECT_NE(s["reason"].get<std::string>().find("41 instances do not fit"), std::string::npos) << s["reason"];
  EXPECT_NE(s["reason"].get<std::string>().find("of device memory"), std::string::npos) << s["reason"];
  const json* at41 = deciding(j, "cuda", 41);
  ASSERT_NE(at41, nullptr);
  EXPECT_EQ((*at41)["status"], "skipped");
  EXPECT_EQ((*at41)["verdict"], "limit");
  // Not even one instance fits: 0 with the reason (not a skipped search).
  const Result z = octocd::test::run(bin() + " bench " + sw + " -o " + (dir_ / "zero.json").string() +
                                     " --quiet --cuda memory_limit_bytes=1");
  ASSERT_EQ(z.code, 0) << z.output;
  const json zj = read_json(dir_ / "zero.json");
  EXPECT_EQ(zj["searches"][0]["status"], "ok");
  EXPECT_EQ(zj["searches"][0]["max_instances"], 0);
  EXPECT_EQ(zj["searches"][0]["limited_by"], "memory");
  EXPECT_NE(zj["searches"][0]["reason"].get<std::string>().find("a single instance does not fit"), std::string::npos);
}

}  // namespace octocd_test_cli_max_instances
