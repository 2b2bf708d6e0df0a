// `octocd bench`, `replay`, `compare` and `report` (design.md section 12): exit codes, a tiny sweep end
// to end (shards, resume after a kill), a planted one-bit difference found at its frame and
// body, replayed pair counts against the recorded ones, and a report from a committed result.
#include <gtest/gtest.h>

#include <hdf5.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <regex>
#include <set>
#include <sstream>
#include <string>

#include <nlohmann/json.hpp>

#include "octocd/trace.hpp"
#include "octocd/trace_reader.hpp"
#include "support/cli_run.hpp"
#include "support/wait_event.hpp"

// This file's own names (its tests compile in unity batches with the folder's other files).
namespace octocd_test_cli_tools {

namespace fs = std::filesystem;
using json = nlohmann::json;

namespace {

using octocd::test::Result;
using octocd::test::bin;
using octocd::test::source_dir;
using octocd::test::run_octocd;

json read_json(const fs::path& p) {
  std::ifstream in(p);
  return json::parse(in);
}

/// Eight boxes in a 2 x 2 x 2 stack on a floor, nearly touching: pairs and contacts from the start.
const char* kPile = R"({"name": "pile", "domain": {"min": [-0.5, 0, -0.5], "max": [0.5, 2, 0.5]},
  "frames": 60, "walls": "floor",
  "groups": [{"name": "boxes", "shape": {"box": [0.1, 0.1, 0.1]}, "count": 8,
              "layout": {"type": "grid", "min": [-0.11, 0.1, -0.11], "max": [0.11, 0.6, 0.11], "spacing": 0.21,
                         "jitter": 0.01, "seed": 3},
              "velocity": {"type": "random", "max": 0.5, "seed": 4}}]})";

class Tools : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("octocd-tools-" + std::to_string(::getpid()) + "-" +
                                        ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }

  std::string write(const std::string& name, const std::string& text) {
    const fs::path p = dir_ / name;
    std::ofstream(p) << text;
    return p.string();
  }
  /// A steps sweep over the pile scene: midphase x engines (cpu, cuda, bullet).
  std::string tiny_sweep(int frames = 20, int scenes = 1) {
    write("pile.json", kPile);
    std::string sc = R"("pile.json")";
    for (int i = 1; i < scenes; ++i) {
      const std::string name = "pile" + std::to_string(i) + ".json";
      write(name, kPile);
      sc += ", \"" + name + "\"";
    }
    return write("sweep.json", R"({"name": "tiny", "kind": "steps", "scenes": [)" + sc +
                                   R"(], "engines": ["cpu", "cuda", "bullet"],
      "axes": [{"name": "midphase", "values": ["aabb-only", "1,2"], "labels": ["L0", "B"]}],
      "warmup": 5, "frames": )" + std::to_string(frames) + R"(, "repeat": 2})");
  }
  /// A trace of the pile scene with every state recorded.
  std::string pile_trace(const std::string& name, int frames = 60, const std::string& extra = "") {
    const std::string scene = write("pile.json", kPile);
    const std::string t = (dir_ / name).string();
    const Result r = run_octocd("run " + scene + " --frames " + std::to_string(frames) +
                                " --state-every 1 --quiet --trace " + t + " " + extra);
    EXPECT_EQ(r.code, 0) << r.output;
    return t;
  }
  fs::path dir_;
};

/// Flips the lowest bit of one float of /states/position (row, body, component).
void flip_position_bit(const std::string& path, hsize_t row, hsize_t body, hsize_t comp) {
  const hid_t f = H5Fopen(path.c_str(), H5F_ACC_RDWR, H5P_DEFAULT);
  ASSERT_GE(f, 0);
  const hid_t d = H5Dopen2(f, "/states/position", H5P_DEFAULT);
  const hid_t fs_ = H5Dget_space(d);
  const hsize_t start[3] = {row, body, comp}, count[3] = {1, 1, 1};
  H5Sselect_hyperslab(fs_, H5S_SELECT_SET, start, nullptr, count, nullptr);
  const hid_t ms = H5Screate_simple(3, count, nullptr);
  float v = 0.0f;
  ASSERT_GE(H5Dread(d, H5T_NATIVE_FLOAT, ms, fs_, H5P_DEFAULT, &v), 0);
  std::uint32_t bits = 0;
  std::memcpy(&bits, &v, 4);
  bits ^= 1u;
  std::memcpy(&v, &bits, 4);
  ASSERT_GE(H5Dwrite(d, H5T_NATIVE_FLOAT, ms, fs_, H5P_DEFAULT, &v), 0);
  H5Sclose(ms);
  H5Sclose(fs_);
  H5Dclose(d);
  H5Fclose(f);
}

/// compare's frame-count line, e.g. "/frames: 1050 vs 1000 frames".
std::string fmt_frames(std::int64_t a, std::int64_t b) {
  return "/frames: " + std::to_string(a) + " vs " + std::to_string(b) + " frames";
}

}  // namespace

// ---- bench ------------------------------------------------------------------------------------

TEST_F(Tools, BenchUnknownSweepListsTheNames) {
  const Result r = run_octocd("bench no-such-sweep -o " + (dir_ / "r.json").string());
  EXPECT_EQ(r.code, 2) << r.output;
  for (const char* n : {"table5", "table6", "tableA1", "figA2", "broadphase-scaling", "max-instances"})
    EXPECT_NE(r.output.find(n), std::string::npos) << n << "\n" << r.output;
  EXPECT_FALSE(fs::exists(dir_ / "r.json"));
  const Result list = run_octocd("bench --list");
  EXPECT_EQ(list.code, 0);
  EXPECT_NE(list.output.find("broadphase-scaling"), std::string::npos);
}

TEST_F(Tools, BenchMalformedSweepNamesFileKeyAndAllowed) {
  write("pile.json", kPile);
  const std::string bad_frames =
      write("bad1.json", R"({"name": "x", "scenes": ["pile.json"], "frames": "ten"})");
  Result r = run_octocd("bench " + bad_frames + " -o " + (dir_ / "r.json").string());
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find(bad_frames + ": frames:"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("allowed: an integer in [1, "), std::string::npos) << r.output;

  const std::string bad_key = write("bad2.json", R"({"name": "x", "scenes": ["pile.json"], "framez": 3})");
  r = run_octocd("bench " + bad_key + " -o " + (dir_ / "r.json").string());
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.output.find("framez: unknown key"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("allowed:"), std::string::npos) << r.output;

  const std::string bad_axis = write(
      "bad3.json", R"({"name": "x", "scenes": ["pile.json"], "axes": [{"name": "colour", "values": [1]}]})");
  r = run_octocd("bench " + bad_axis + " -o " + (dir_ / "r.json").string());
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.output.find("axes[0].key"), std::string::npos) << r.output;

  const std::string twice = write("bad6.json", R"({"name": "x", "scenes": ["pile.json", "pile.json"]})");
  r = run_octocd("bench " + twice + " -o " + (dir_ / "r.json").string());
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.output.find("scenes[1]: listed twice"), std::string::npos) << r.output;

  const std::string not_json = write("bad4.json", "{\"name\": ");
  r = run_octocd("bench " + not_json + " -o " + (dir_ / "r.json").string());
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.output.find("not JSON"), std::string::npos) << r.output;

  // A scene value out of range (beta > 1) names the scene key through the scene loader.
  const std::string bad_beta = write(
      "bad5.json", R"({"name": "x", "scenes": ["pile.json"], "engines": ["cpu"],
                       "axes": [{"name": "beta", "values": [1.5]}], "frames": 2, "warmup": 0})");
  r = run_octocd("bench " + bad_beta + " -o " + (dir_ / "r5.json").string() + " --quiet");
  // The point is skipped with the reason; as it is the sweep's only point, the sweep
  // measured nothing: exit 2 (issue 22.5), the result file still says why.
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find("every point skipped"), std::string::npos) << r.output;
  const json j = read_json(dir_ / "r5.json");
  EXPECT_EQ(j["points"][0]["status"], "skipped");
  EXPECT_NE(j["points"][0]["reason"].get<std::string>().find("response.beta"), std::string::npos)
      << j["points"][0]["reason"];

  const Result shard = run_octocd("bench " + tiny_sweep() + " --shard 2/2 -o " + (dir_ / "s.json").string());
  EXPECT_EQ(shard.code, 2);
  EXPECT_NE(shard.output.find("--shard: '2/2'"), std::string::npos) << shard.output;
}

TEST_F(Tools, BenchTinySweepEndToEnd) {
  const fs::path out = dir_ / "res" / "r.json";
  const Result r = run_octocd("bench " + tiny_sweep() + " -o " + out.string() + " --quiet");
  ASSERT_EQ(r.code, 0) << r.output;
  const json j = read_json(out);
  EXPECT_EQ(j["format"], "octocd-bench");
  EXPECT_EQ(j["version"], 1);
  EXPECT_TRUE(j["complete"].get<bool>());
  EXPECT_FALSE(j["machine"]["cpu"].get<std::string>().empty());
  EXPECT_FALSE(j["build"]["git_revision"].get<std::string>().empty());
  ASSERT_EQ(j["points"].size(), 6u);  // 2 midphases x 3 engines
  EXPECT_EQ(j["points_total"], 6);
  for (const auto& p : j["points"]) {
    const std::string engine = p["params"]["engine"];
    const std::string mid = p["params"]["axes"]["midphase"];
    if (engine == "cpu" || (engine == "bullet" && mid == "aabb-only")) {
      ASSERT_EQ(p["status"], "ok") << p.dump();
      const json& w = p["windows"]["all"];
      EXPECT_EQ(w["frames"], 20);
      EXPECT_EQ(w["first"], 6);
      EXPECT_EQ(w["last"], 25);
      const json& s = w["steps_per_s"];
      EXPECT_EQ(s["n"], 2);
      EXPECT_LE(s["min"].get<double>(), s["median"].get<double>());
      EXPECT_LE(s["median"].get<double>(), s["max"].get<double>());
      EXPECT_GT(s["min"].get<double>(), 0.0);
    } else if (engine == "bullet") {
      EXPECT_EQ(p["status"], "skipped");
      EXPECT_NE(p["reason"].get<std::string>().find("no midphase"), std::string::npos) << p["reason"];
    } else {  // cuda: measured where the build and the machine have it, else skipped with the reason
      if (p["status"] == "skipped") {
        EXPECT_FALSE(p["reason"].get<std::string>().empty());
      } else {
        EXPECT_EQ(p["status"], "ok");
      }
    }
  }
  // cpu is deterministic: both repetitions give the same contacts.
  const json& c = j["points"][0]["windows"]["all"]["contacts"];
  EXPECT_EQ(c["min"], c["max"]);

  // An existing result is not overwritten without --resume.
  const Result again = run_octocd("bench " + (dir_ / "sweep.json").string() + " -o " + out.string());
  EXPECT_EQ(again.code, 2);
  EXPECT_NE(again.output.find("--resume"), std::string::npos) << again.output;
}

// A steps sweep's max_bodies skips an engine's points above its body count with the
// sweep's reason (not a hang on a set-up that takes minutes); the points it runs record
// each repetition's engine set-up (setup_s, and setup_cpu_s on the host); a max_bodies of
// an unknown engine or without its reason is exit 2 naming the key.
TEST_F(Tools, BenchStepsMaxBodiesSkipsAnEngineAboveItsCountWithTheReason) {
  const std::string scene = "box-stack";  // under the default scene folder
  const fs::path sweep = dir_ / "large.json";
  std::ofstream(sweep) << R"({"name": "large", "kind": "steps", "scenes": [")" << scene
                       << R"("], "engines": ["cpu", "ode"], "warmup": 0, "frames": 3, "repeat": 2,
                           "max_bodies": {"ode": {"bodies": 2, "reason": "planted: too large for ode"},
                                          "cpu": {"bodies": 100, "reason": "never reached"}}})";
  const fs::path out = dir_ / "large-r.json";
  const Result r = run_octocd("bench " + sweep.string() + " -o " + out.string() + " --quiet");
  ASSERT_EQ(r.code, 0) << r.output;
  const json j = read_json(out);
  ASSERT_EQ(j["points"].size(), 2u);
  const json& cpu = j["points"][0];
  const json& ode = j["points"][1];
  ASSERT_EQ(cpu["params"]["engine"], "cpu");
  ASSERT_EQ(cpu["status"], "ok") << cpu.dump();
  EXPECT_EQ(cpu["setup_s"]["n"], 2);
  EXPECT_GT(cpu["setup_s"]["min"].get<double>(), 0.0);
  EXPECT_EQ(cpu["setup_cpu_s"]["n"], 2);
  ASSERT_EQ(ode["params"]["engine"], "ode");
  EXPECT_EQ(ode["status"], "skipped");
  const std::string bodies = std::to_string(cpu["bodies"].get<long>());
  EXPECT_EQ(ode["reason"], bodies + " bodies, above max_bodies 2 for ode: planted: too large for ode");
  for (const std::string& bad : {std::string(R"({"warp": {"bodies": 2, "reason": "x"}})"),
                                 std::string(R"({"ode": 2})"), std::string(R"({"ode": {"bodies": -1, "reason": "x"}})")}) {
    std::ofstream(sweep) << R"({"name": "large", "kind": "steps", "scenes": [")" << scene
                         << R"("], "max_bodies": )" << bad << "}";
    const Result refused = run_octocd("bench " + sweep.string() + " -o " + (dir_ / "bad.json").string() + " --quiet");
    EXPECT_EQ(refused.code, 2) << bad << ": " << refused.output;
    EXPECT_NE(refused.output.find("max_bodies."), std::string::npos) << refused.output;
  }
}

// `run` of a scene of 10^4 bodies or more says each stage of its start on stderr: the
// scene, the engine's world (wall and CPU seconds) and the first frame (seconds after the
// start, the process's CPU seconds), in that order; --quiet and a small scene say none.
TEST_F(Tools, RunOfALargeSceneSaysEachSetUpStageWithCpuSeconds) {
  const std::string large = source_dir() + "/datasets/scenes/boxes-uniform-10k.json";
  const Result r = run_octocd("run " + large + " --engine ode --frames 1");
  ASSERT_EQ(r.code, 0) << r.output;
  const std::regex stages(
      "set-up: scene and bodies [0-9.]+ s \\(10006 bodies\\); building the ode world\n"
      "set-up: ode world [0-9.]+ s \\([0-9.]+ CPU s\\); stepping\n"
      "(.*\n)*set-up: first frame [0-9.]+ s after the start \\([0-9.]+ CPU s of the process\\)\n");
  EXPECT_TRUE(std::regex_search(r.output, stages)) << r.output;
  const Result quiet = run_octocd("run " + large + " --engine ode --frames 1 --quiet");
  ASSERT_EQ(quiet.code, 0) << quiet.output;
  EXPECT_EQ(quiet.output.find("set-up:"), std::string::npos) << quiet.output;
  const Result small = run_octocd("run " + source_dir() + "/datasets/scenes/box-stack.json --engine ode --frames 1");
  ASSERT_EQ(small.code, 0) << small.output;
  EXPECT_EQ(small.output.find("set-up:"), std::string::npos) << small.output;
}

// --traced runs each point once per trace mode: the untraced point keeps its id, the
// traced ones say their mode in the id and params; a traced point writes its traces in a
// private folder of $TMPDIR that is gone afterwards; the cpu engine is deterministic, so
// every mode steps the same contacts; a mode that is not one, or --traced on a sweep of
// another kind, is exit 2 naming the option.
TEST_F(Tools, BenchTracedRunsEachPointOncePerTraceMode) {
  const std::string sweep = tiny_sweep();
  const fs::path out = dir_ / "traced.json";
  const fs::path tmp = dir_ / "tmp";
  fs::create_directories(tmp);
  const Result r = octocd::test::run("TMPDIR=" + tmp.string() + " " + bin() + " bench " + sweep +
                       " --engines cpu --traced off,states,contacts --repeat 1 -o " + out.string() + " --quiet");
  ASSERT_EQ(r.code, 0) << r.output;
  const json j = read_json(out);
  ASSERT_EQ(j["points"].size(), 6u);  // 2 midphases x 3 modes
  std::set<std::string> ids;
  std::vector<double> contacts;
  for (const auto& p : j["points"]) {
    ASSERT_EQ(p["status"], "ok") << p.dump();
    const std::string id = p["id"];
    ids.insert(id);
    const std::string mode = p["params"].value("traced", "off");
    if (mode == "off") {
      EXPECT_EQ(id.find("traced"), std::string::npos) << id;
    } else {
      EXPECT_NE(id.find(" | traced=" + mode), std::string::npos) << id;
    }
    if (p["params"]["axes"]["midphase"] == "1,2") contacts.push_back(p["windows"]["all"]["contacts"]["median"]);
  }
  EXPECT_EQ(ids.size(), 6u);
  ASSERT_EQ(contacts.size(), 3u);
  EXPECT_GT(contacts[0], 0.0);
  EXPECT_EQ(contacts[0], contacts[1]);
  EXPECT_EQ(contacts[0], contacts[2]);
  EXPECT_TRUE(fs::is_empty(tmp)) << "a traced point left files in $TMPDIR";

  const Result bad = run_octocd("bench " + sweep + " --traced off,sometimes -o " + (dir_ / "bad.json").string());
  EXPECT_EQ(bad.code, 2) << bad.output;
  EXPECT_NE(bad.output.find("--traced: 'sometimes' is not a trace mode"), std::string::npos) << bad.output;
  const Result kind = run_octocd("bench speed-accuracy --traced states -o " + (dir_ / "bad2.json").string());
  EXPECT_EQ(kind.code, 2) << kind.output;
  EXPECT_NE(kind.output.find("--traced"), std::string::npos) << kind.output;
}

TEST_F(Tools, BenchShardsSplitThePointsAndResumeKeepsFinishedOnes) {
  const std::string sweep = tiny_sweep(5);
  std::set<int> seen;
  for (int i = 0; i < 2; ++i) {
    const fs::path out = dir_ / ("part-" + std::to_string(i) + ".json");
    const Result r = run_octocd("bench " + sweep + " --engines cpu,bullet --shard " + std::to_string(i) +
                                "/2 -o " + out.string() + " --quiet");
    ASSERT_EQ(r.code, 0) << r.output;
    const json part = read_json(out);
    for (const auto& p : part["points"]) {
      EXPECT_EQ(p["index"].get<int>() % 2, i);
      EXPECT_TRUE(seen.insert(p["index"].get<int>()).second);
    }
  }
  EXPECT_EQ(seen, (std::set<int>{0, 1, 2, 3}));

  // Drop the last two points of shard 0's file, as if it had been killed; --resume redoes
  // exactly those and keeps the others untouched.
  const fs::path out = dir_ / "part-0.json";
  json j = read_json(out);
  const json keep = j["points"][0];
  j["points"] = json::array({keep});
  j["complete"] = false;
  std::ofstream(out) << j.dump(1);
  const Result r = run_octocd("bench " + sweep + " --engines cpu,bullet --shard 0/2 -o " + out.string() +
                              " --resume --quiet");
  ASSERT_EQ(r.code, 0) << r.output;
  const json k = read_json(out);
  ASSERT_EQ(k["points"].size(), 2u);
  EXPECT_EQ(k["points"][0], keep);
  EXPECT_TRUE(k["complete"].get<bool>());
  // The progress of a resumed run counts on from the kept points and says how many it kept
  // (before: "[1/2]" for the last point, and no word of the kept one).
  j = read_json(out);
  j["points"].erase(1);
  j["complete"] = false;
  std::ofstream(out) << j.dump(1);
  const Result told = run_octocd("bench " + sweep + " --engines cpu,bullet --shard 0/2 -o " + out.string() + " --resume");
  ASSERT_EQ(told.code, 0) << told.output;
  EXPECT_NE(told.output.find("(2 in this shard 0/2, 1 of them kept from the result by --resume)"), std::string::npos)
      << told.output;
  EXPECT_NE(told.output.find("[2/2] "), std::string::npos) << told.output;
  EXPECT_EQ(told.output.find("[1/2] "), std::string::npos) << told.output;
  // Another shard or sweep is not resumed.
  const Result other = run_octocd("bench " + sweep + " --engines cpu --shard 0/2 -o " + out.string() + " --resume");
  EXPECT_EQ(other.code, 2);
  EXPECT_NE(other.output.find("settings"), std::string::npos) << other.output;
}

// Issue 22.5: a result to resume whose points are not the sweep's is refused (exit 2,
// naming the result file, the key and the sweep), never taken as finished work.
TEST_F(Tools, BenchResumeRefusesPointsThatAreNotTheSweeps) {
  const std::string sweep = tiny_sweep(5);
  const fs::path out = dir_ / "r.json";
  ASSERT_EQ(run_octocd("bench " + sweep + " --engines cpu -o " + out.string() + " --quiet").code, 0);
  const json good = read_json(out);
  ASSERT_EQ(good["points"].size(), 2u);
  const auto resume = [&](const std::function<void(json&)>& plant) {
    json j = good;
    plant(j);
    j["complete"] = false;
    std::ofstream(out) << j.dump(1);
    return run_octocd("bench " + sweep + " --engines cpu -o " + out.string() + " --resume --quiet");
  };
  Result r = resume([](json& j) { j["points"][0]["index"] = 1000000000000000000LL; });
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find(out.string() + ": points[0].index: 1000000000000000000 (sweep " + sweep + ")"),
            std::string::npos) << r.output;
  r = resume([](json& j) { j["points"][1]["index"] = -1; });
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find("points[1].index: -1"), std::string::npos) << r.output;
  r = resume([](json& j) { j["points"][1]["windows"] = "nope"; });
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find("points[1].windows: a point of another shape"), std::string::npos) << r.output;
  r = resume([](json& j) { j["points"][0]["id"] = "elsewhere | cpu"; });
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find("points[0].id: 'elsewhere | cpu' is not a point of the sweep"), std::string::npos)
      << r.output;
  r = resume([](json& j) { j["points"][1] = j["points"][0]; });
  EXPECT_EQ(r.code, 2) << r.output;
  for (const Result& x : {r}) EXPECT_EQ(std::count(x.output.begin(), x.output.end(), '\n'), 1) << x.output;
  // The untouched result resumes (nothing left to run).
  std::ofstream(out) << good.dump(1);
  EXPECT_EQ(run_octocd("bench " + sweep + " --engines cpu -o " + out.string() + " --resume --quiet").code, 0);
}

// Issue 57 item 4: every field --resume reads from the existing result is checked by type
// and range, exit 2 naming the file and field. Before: a wrongly typed machine.hostname,
// started or status was nlohmann's type_error (exit 1, no file named), a steps/s spread of
// strings was kept as finished work, and a speed-accuracy result with "complete": "yes"
// ended in a type_error too.
TEST_F(Tools, BenchResumeChecksTheTypeAndRangeOfWhatItReads) {
  const std::string sweep = tiny_sweep(5);
  const fs::path out = dir_ / "typed.json";
  ASSERT_EQ(run_octocd("bench " + sweep + " --engines cpu -o " + out.string() + " --quiet").code, 0);
  const json good = read_json(out);
  const auto resume = [&](const std::function<void(json&)>& plant) {
    json j = good;
    plant(j);
    j["complete"] = false;
    std::ofstream(out) << j.dump(1);
    return run_octocd("bench " + sweep + " --engines cpu -o " + out.string() + " --resume --quiet");
  };
  const std::vector<std::pair<std::function<void(json&)>, std::string>> cases = {
      {[](json& j) { j["machine"]["hostname"] = 5; }, "machine.hostname: an integer 5; allowed: a string"},
      {[](json& j) { j["started"] = json::array(); }, "started: an array []; allowed: a string"},
      {[](json& j) { j["points"][0]["status"] = 3; }, "points[0].status: an integer 3; allowed: ok, skipped, failed"},
      {[](json& j) { j["points"][0]["id"] = json::object(); }, "points[0].id: an object {}; allowed: a string"},
      {[](json& j) { j["points"][1]["windows"]["all"]["steps_per_s"]["n"] = "5"; },
       "points[1].windows.all.steps_per_s.n: a string \"5\"; allowed: an integer in [0, 1000]"},
      {[](json& j) { j["points"][1]["windows"]["all"]["steps_per_s"]["n"] = 18446744073709551615ULL; },
       "points[1].windows.all.steps_per_s.n: 18446744073709551615 is out of range"},
      {[](json& j) { j["points"][1]["windows"]["all"]["steps_per_s"]["values"][0] = "fast"; },
       "points[1].windows.all.steps_per_s.values[0]: a string \"fast\"; allowed: null or a number"},
      // A figure bench never writes (check_point_timings) is not kept either: before, a
      // negative, denormal or null steps/s was resumed into the result as finished work.
      {[](json& j) { j["points"][1]["windows"]["all"]["steps_per_s"]["median"] = -5; },
       "points[1].windows.all.steps_per_s.median: -5; allowed: 0 (not measured) or a timing from 1e-12 to 1e+15"},
      {[](json& j) { j["points"][1]["windows"]["all"]["steps_per_s"]["values"][0] = 5e-324; },
       "points[1].windows.all.steps_per_s.values[0]: 5e-324; allowed: 0 (not measured)"},
      {[](json& j) { j["points"][1]["windows"]["all"]["cpu_steps_per_s"]["max"] = nullptr; },
       "points[1].windows.all.cpu_steps_per_s.max: null; allowed: 0 (not measured)"},
      {[](json& j) { j["points"][0]["reason"] = 7; }, "points[0].reason: an integer 7; allowed: a string"},
      {[](json& j) { j["points"] = json::object(); }, "points: an object {}; allowed: an array"},
      {[](json& j) { j.erase("machine"); }, "machine: missing"},
      {[](json& j) { j["sweep"] = 3; }, "sweep: an integer 3; allowed: an object"},
  };
  for (const auto& [plant, want] : cases) {
    const Result r = resume(plant);
    EXPECT_EQ(r.code, 2) << want << ": " << r.output;
    EXPECT_NE(r.output.find(out.string() + ": " + want), std::string::npos) << r.output;
    EXPECT_EQ(r.output.find("json.exception"), std::string::npos) << r.output;
    EXPECT_EQ(std::count(r.output.begin(), r.output.end(), '\n'), 1) << r.output;
  }
  // A speed-accuracy sweep keeps only a finished result: a wrongly typed one is refused.
  const std::string sa = source_dir() + "/tests/data/bench-small-speed-accuracy.json";
  const fs::path sa_out = dir_ / "sa.json";
  std::ofstream(sa_out) << R"({"format": "octocd-bench", "version": 1, "complete": "yes", "sweep": {}})";
  Result r = run_octocd("bench " + sa + " -o " + sa_out.string() + " --resume --quiet");
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find(sa_out.string() + ": complete: a string \"yes\"; allowed: true or false"), std::string::npos)
      << r.output;
  std::ofstream(sa_out) << R"({"format": "octocd-bench", "version": 1, "complete": true, "sweep": [],
                               "complete": true})";
  r = run_octocd("bench " + sa + " -o " + sa_out.string() + " --resume --quiet");
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find("complete: duplicate key"), std::string::npos) << r.output;
}

TEST_F(Tools, BenchRefusesMissingKeysAllSkippedAndOversizedSweeps) {
  write("pile.json", kPile);
  // A pointer to a key the scene does not have (and refuses): the sweep's key is named.
  std::string sweep = write("typo.json", R"({"name": "typo", "scenes": ["pile.json"], "engines": ["cpu"],
    "axes": [{"name": "b", "key": "/response/betta", "values": [0.2, 0.4]}], "warmup": 1, "frames": 2, "repeat": 1})");
  Result r = run_octocd("bench " + sweep + " -o " + (dir_ / "t.json").string() + " --quiet");
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find(sweep + ": axes[0] (/response/betta): not a key of scene file"), std::string::npos)
      << r.output;
  // Every point skipped (a value the scene refuses at a key it has): exit 2 naming the sweep.
  std::string scene = kPile;
  scene.replace(scene.find("\"frames\": 60"), 12, "\"frames\": 60, \"dt\": 0.001");
  write("pile-dt.json", scene);
  sweep = write("skip.json", R"({"name": "skip", "scenes": ["pile-dt.json"], "engines": ["cpu"],
    "axes": [{"name": "dt", "key": "/dt", "values": [-1, -2]}], "warmup": 1, "frames": 2, "repeat": 1})");
  r = run_octocd("bench " + sweep + " -o " + (dir_ / "s.json").string() + " --quiet");
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find(sweep + ": every point skipped (2 of 2"), std::string::npos) << r.output;
  EXPECT_FALSE(read_json(dir_ / "s.json")["points"].empty());  // the result says why, point by point
  // 10^9 points: refused up front, at once, with the limit named.
  std::string values = "[";
  for (int i = 0; i < 1000; ++i) values += (i ? "," : "") + std::to_string(i);
  values += "]";
  sweep = write("huge.json", R"({"name": "huge", "scenes": ["pile.json"], "engines": ["cpu"], "axes": [
    {"name": "a", "key": "/response/beta", "values": )" + values + R"(},
    {"name": "b", "key": "/response/slop", "values": )" + values + R"(},
    {"name": "c", "key": "/response/alpha", "values": )" + values + R"(}]})");
  r = run_octocd("bench " + sweep + " -o " + (dir_ / "h.json").string() + " --quiet");
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find(sweep + ": axes: the sweep expands to more than 100000 points; allowed: at most 100000"),
            std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(dir_ / "h.json"));
}

// Round-robin (design.md section 14b): repetition r of every point runs before repetition r + 1 of any,
// so a load burst hits every point alike; each point's repetitions are all in its spreads.
TEST_F(Tools, BenchRunsRepetitionsRoundRobinOverThePoints) {
  const std::string sweep = tiny_sweep(20);  // 2 midphases on the cpu engine
  const fs::path out = dir_ / "rr.json";
  const Result r = run_octocd("bench " + sweep + " --engines cpu --repeat 3 -o " + out.string() + " --quiet");
  ASSERT_EQ(r.code, 0) << r.output;
  const json j = read_json(out);
  std::vector<std::vector<double>> starts;
  for (const auto& p : j["points"]) {
    if (p["status"] != "ok") continue;
    ASSERT_EQ(p["repetition_start_s"].size(), 3u) << p.dump();
    starts.push_back(p["repetition_start_s"].get<std::vector<double>>());
    const json& sps = p["windows"].begin().value()["steps_per_s"];
    EXPECT_EQ(sps["n"], 3);
    EXPECT_EQ(sps["values"].size(), 3u);
  }
  ASSERT_GE(starts.size(), 2u);
  for (std::size_t rep = 0; rep + 1 < 3; ++rep)
    for (const auto& a : starts)
      for (const auto& b : starts) EXPECT_LT(a[rep], b[rep + 1]);
}

TEST_F(Tools, BenchKilledMidwayLeavesItsFinishedPointsAndResumes) {
  const std::string sweep = tiny_sweep(30000, 2);  // 2 scenes x 2 midphases x (cpu, bullet) = 8 points
  const fs::path out = dir_ / "killed.json";
  const pid_t pid = fork();
  ASSERT_GE(pid, 0);
  if (pid == 0) {
    const std::string b = bin();
    const std::string o = out.string();
    std::freopen("/dev/null", "w", stderr);
    execl(b.c_str(), b.c_str(), "bench", sweep.c_str(), "--engines", "cpu,bullet", "-o", o.c_str(), "--quiet",
          static_cast<char*>(nullptr));
    _exit(127);
  }
  // The result appears (renamed into place) after the first finished point; kill the sweep
  // right then.
  octocd::test::wait_until([&] { return fs::exists(out); }, {dir_}, std::chrono::seconds(60));
  kill(pid, SIGKILL);
  int status = 0;
  waitpid(pid, &status, 0);
  ASSERT_TRUE(fs::exists(out));
  const json j = read_json(out);  // a complete, valid JSON file (written atomically)
  EXPECT_FALSE(j["complete"].get<bool>());
  EXPECT_GE(j["points"].size(), 1u);
  EXPECT_LT(j["points"].size(), 8u);
  const Result r = run_octocd("bench " + sweep + " --engines cpu,bullet -o " + out.string() + " --resume --quiet");
  ASSERT_EQ(r.code, 0) << r.output;
  const json k = read_json(out);
  EXPECT_TRUE(k["complete"].get<bool>());
  ASSERT_EQ(k["points"].size(), 8u);
  for (std::size_t i = 0; i < k["points"].size(); ++i) EXPECT_EQ(k["points"][i]["index"], static_cast<int>(i));
  // The finished points were kept, not rerun (round-robin: a point finishes with its last
  // repetition, or at once when skipped).
  for (const auto& pt : j["points"]) EXPECT_EQ(k["points"][pt["index"].get<std::size_t>()], pt);
}

// SIGTERM mid-point: bench stops between two frames (not at the end of the point), keeps
// the finished points in the result with "stopped", exits 143, and --resume goes on. The
// signal follows an event: the first point's trace (--trace-dir) holds a flushed frame,
// so the point is inside its frames.
TEST_F(Tools, BenchStopsOnSigtermMidPointAndKeepsFinishedPoints) {
  const std::string sweep = tiny_sweep(100000000);  // one point would run for hours
  const fs::path out = dir_ / "stopped.json", traces = dir_ / "traces";
  const pid_t pid = fork();
  ASSERT_GE(pid, 0);
  if (pid == 0) {
    const std::string b = bin();
    const std::string o = out.string(), t = traces.string();
    std::freopen((dir_ / "stderr.txt").c_str(), "w", stderr);
    execl(b.c_str(), b.c_str(), "bench", sweep.c_str(), "--engines", "cpu", "-o", o.c_str(), "--trace-dir", t.c_str(),
          "--quiet", static_cast<char*>(nullptr));
    _exit(127);
  }
  // Checked after each change in dir_ and in traces/ (watched once bench creates it).
  const bool inside = octocd::test::wait_until(
      [&] {
        std::error_code ec;
        for (const auto& e : fs::directory_iterator(traces, ec)) {
          if (e.path().extension() != ".h5") continue;
          try {
            if (octocd::read_trace_summary(e.path().string()).frames > 0) return true;
          } catch (const std::exception&) {
          }
        }
        return false;
      },
      {dir_, traces}, std::chrono::seconds(60));
  ASSERT_TRUE(inside) << "no frame of the first point flushed within 60 s";
  kill(pid, SIGTERM);
  int status = 0;
  // Bounded wait (a functional bound: the point itself would take hours).
  if (!octocd::test::wait_child(pid, status, std::chrono::seconds(30))) {
    kill(pid, SIGKILL);
    waitpid(pid, &status, 0);
    FAIL() << "bench did not stop on SIGTERM within 30 s";
  }
  ASSERT_TRUE(WIFEXITED(status));
  EXPECT_EQ(WEXITSTATUS(status), 143);
  std::ifstream err(dir_ / "stderr.txt");
  std::stringstream es;
  es << err.rdbuf();
  EXPECT_NE(es.str().find("octocd bench: stopped by SIGTERM after 0 of 2 points"), std::string::npos) << es.str();
  ASSERT_TRUE(fs::exists(out));
  const json j = read_json(out);
  EXPECT_EQ(j["stopped"], "SIGTERM");
  EXPECT_FALSE(j["complete"].get<bool>());
  for (const auto& e : fs::recursive_directory_iterator(dir_))
    EXPECT_EQ(e.path().string().find(".tmp."), std::string::npos) << e.path();
}

TEST_F(Tools, BenchBroadphaseSweepMatchesTheRecordedPairs) {
  const std::string sweep = write("bp.json", R"({"name": "bp", "kind": "broadphase", "bodies": [300, 600],
    "broadphases": ["flat", "octree", "spatial-hash", "bullet-dbvt", "fcl-dynamic-aabb-tree"],
    "engines": ["cpu", "cuda", "bullet"], "max_bodies": {"flat": 400}, "warmup": 40, "frames": 3, "repeat": 2})");
  const fs::path out = dir_ / "bp-result.json";
  const Result r = run_octocd("bench " + sweep + " -o " + out.string() + " --quiet");
  ASSERT_EQ(r.code, 0) << r.output;
  const json j = read_json(out);
  ASSERT_EQ(j["points"].size(), 2u * 5u * 3u);
  int ok = 0;
  for (const auto& p : j["points"]) {
    const std::string e = p["params"]["engine"], b = p["params"]["broadphase"];
    if (e == "cpu" && !(b == "flat" && p["params"]["bodies"] == 600)) {
      ASSERT_EQ(p["status"], "ok") << p.dump();
      EXPECT_TRUE(p["matches_recorded"].get<bool>()) << p["recorded"];
      EXPECT_EQ(p["ms_per_frame"]["n"], 2);
      EXPECT_EQ(p["frames"], 3);
      ++ok;
    }
    if (b == "flat" && p["params"]["bodies"] == 600) {
      EXPECT_EQ(p["status"], "skipped");
      EXPECT_NE(p["reason"].get<std::string>().find("max_bodies 400"), std::string::npos);
    }
    if (e == "bullet") {
      EXPECT_EQ(p["status"], "skipped") << p.dump();
    }
  }
  EXPECT_EQ(ok, 9);
  // Every broadphase of one size saw the same frames: same mean pair count.
  for (int n : {300, 600}) {
    std::set<double> pairs;
    for (const auto& p : j["points"])
      if (p["status"] == "ok" && p["params"]["bodies"] == n) pairs.insert(p["pairs"].get<double>());
    EXPECT_EQ(pairs.size(), 1u) << n;
  }
}

// ---- compare ----------------------------------------------------------------------------------

TEST_F(Tools, CompareSameTracesExitZero) {
  const std::string a = pile_trace("a.h5"), b = pile_trace("b.h5");
  const Result r = run_octocd("compare " + a + " " + b);
  EXPECT_EQ(r.code, 0) << r.output;
  EXPECT_NE(r.output.find("same"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("61 common states x 9 bodies"), std::string::npos) << r.output;
}

TEST_F(Tools, CompareFindsAPlantedOneBitDifferenceAtItsFrameAndBody) {
  const std::string a = pile_trace("a.h5"), b = pile_trace("b.h5");
  flip_position_bit(b, 37, 5, 1);  // state row 37 = frame 37 (--state-every 1), body 5, y
  const Result r = run_octocd("compare " + a + " " + b + " --json " + (dir_ / "c.json").string());
  EXPECT_EQ(r.code, 3) << r.output;
  EXPECT_NE(r.output.find("DIFFERENT: first at frame 37, body 5 (positions)"), std::string::npos) << r.output;
  const json j = read_json(dir_ / "c.json");
  EXPECT_EQ(j["first"]["frame"], 37);
  EXPECT_EQ(j["first"]["body"], 5);
  EXPECT_GT(j["quantities"][0]["max_abs_difference"].get<double>(), 0.0);
  EXPECT_LT(j["quantities"][0]["max_abs_difference"].get<double>(), 1e-6);
  // One bit is far below a tolerance of 1e-6 m; velocities were not touched.
  EXPECT_EQ(run_octocd("compare " + a + " " + b + " --tolerance 1e-6").code, 0);
  EXPECT_EQ(run_octocd("compare " + a + " " + b + " --quantity velocities,pairs,contacts").code, 0);
}

TEST_F(Tools, CompareIncompatibleOrUnreadableExitTwo) {
  const std::string a = pile_trace("a.h5");
  const std::string scene = write("other.json", std::string(kPile).replace(std::string(kPile).find("\"count\": 8"),
                                                                            10, "\"count\": 6"));
  const std::string c = (dir_ / "c.h5").string();
  ASSERT_EQ(run_octocd("run " + scene + " --frames 10 --quiet --trace " + c).code, 0);
  Result r = run_octocd("compare " + a + " " + c);
  EXPECT_EQ(r.code, 3) << r.output;  // another body count is a difference, named
  EXPECT_NE(r.output.find("/bodies: 9 vs 7 bodies"), std::string::npos) << r.output;
  const std::string text = write("not-a-trace.h5", "hello");
  r = run_octocd("compare " + a + " " + text);
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.output.find(text + ": not an HDF5 file"), std::string::npos) << r.output;
  r = run_octocd("compare " + a + " " + (dir_ / "missing.h5").string());
  EXPECT_EQ(r.code, 2);
  r = run_octocd("compare " + a + " " + a + " --quantity colour");
  EXPECT_EQ(r.code, 2);
}

// A run killed with SIGKILL mid-way leaves a readable trace holding fewer frames: compare
// never passes it against the complete golden run, even though every frame it holds equals.
TEST_F(Tools, CompareFailsATruncatedTraceOfAKilledRun) {
  const std::string scene = write("long.json", std::string(kPile).replace(std::string(kPile).find("\"frames\": 60"),
                                                                           12, "\"frames\": 100000000"));
  const std::string killed = (dir_ / "killed.h5").string();
  ASSERT_TRUE(octocd::test::run_killed_after(scene, killed, 100).killed) << "the run ended before the kill";
  const std::int64_t kept = octocd::read_trace_summary(killed).frames;
  ASSERT_GE(kept, 100);
  // The golden run: the same scene, 50 frames further than the killed one got.
  const std::string golden = (dir_ / "golden.h5").string();
  ASSERT_EQ(run_octocd("run " + scene + " --frames " + std::to_string(kept + 50) + " --quiet --trace " + golden).code, 0);
  const Result r = run_octocd("compare " + golden + " " + killed + " --json " + (dir_ / "c.json").string());
  EXPECT_EQ(r.code, 3) << r.output;
  EXPECT_NE(r.output.find(fmt_frames(kept + 50, kept)), std::string::npos) << r.output;
  EXPECT_EQ(r.output.find("\nsame"), std::string::npos) << r.output;
  const json j = read_json(dir_ / "c.json");
  EXPECT_FALSE(j["same"].get<bool>());
  ASSERT_FALSE(j["structure"].empty());
  EXPECT_EQ(j["structure"][0].get<std::string>().rfind("/frames: ", 0), 0u) << j.dump();
  // Every quantity it holds equals the golden one's: only the structure fails it.
  for (const auto& q : j["quantities"]) EXPECT_FALSE(q["differs"].get<bool>()) << q.dump();
}

TEST_F(Tools, CompareFailsRunsOfDifferentLengthAndNamesASceneKeyThatDiffers) {
  const std::string a = pile_trace("a.h5", 1000), b = pile_trace("b.h5", 500);
  Result r = run_octocd("compare " + a + " " + b);
  EXPECT_EQ(r.code, 3) << r.output;
  EXPECT_NE(r.output.find("/frames: 1000 vs 500 frames"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("/states: 1001 vs 501 state rows"), std::string::npos) << r.output;
  r = run_octocd("compare " + b + " " + a);
  EXPECT_EQ(r.code, 3) << r.output;
  EXPECT_NE(r.output.find("/frames: 500 vs 1000 frames"), std::string::npos) << r.output;

  // One key changed in the scene: named with both values, and the comparison fails even
  // with tolerances wide enough for every quantity.
  const std::string p = pile_trace("p.h5");
  std::string text = kPile;
  text.replace(text.find("\"walls\": \"floor\","), 17, "\"walls\": \"floor\", \"response\": {\"beta\": 0.999},");
  const std::string scene = write("beta.json", text);
  const std::string q = (dir_ / "q.h5").string();
  ASSERT_EQ(run_octocd("run " + scene + " --frames 60 --state-every 1 --quiet --trace " + q).code, 0);
  r = run_octocd("compare " + p + " " + q + " --tolerance 1");
  EXPECT_EQ(r.code, 3) << r.output;
  EXPECT_NE(r.output.find("/response/beta: 1 vs 0.999"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("structure differs (1 key)"), std::string::npos) << r.output;
}

// cpu against bullet: the midphase differs by construction (bullet has none); --ignore
// leaves the key out (listed), the quantities still decide. A request of quantities neither
// trace holds is exit 2 naming what is missing, never "same".
TEST_F(Tools, CompareIgnoresNamedStructureKeysAndRefusesToCompareNothing) {
  // Bullet's box mode writes version 1, as cpu does (hull mode writes version 2).
  const std::string cpu = pile_trace("cpu.h5", 40),
                    bullet = pile_trace("bullet.h5", 40, "--engine bullet --bullet shape=box");
  // Two keys differ: the geometry each engine collided (parameters.geometry) and the midphase.
  Result r = run_octocd("compare " + cpu + " " + bullet + " --tolerance 100");
  EXPECT_EQ(r.code, 3) << r.output;
  EXPECT_NE(r.output.find("structure differs (2 keys):\n  /geometry: "), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("\n  /midphase: "), std::string::npos) << r.output;
  r = run_octocd("compare " + cpu + " " + bullet + " --tolerance 100 --ignore /midphase --ignore /geometry");
  EXPECT_EQ(r.code, 0) << r.output;
  EXPECT_NE(r.output.find("structure ignored (--ignore, 2 keys):\n  /geometry: "), std::string::npos) << r.output;
  // Ignoring a key leaves the quantities deciding: bit for bit, cpu and bullet differ.
  r = run_octocd("compare " + cpu + " " + bullet + " --ignore /midphase --ignore /geometry --quantity positions");
  EXPECT_EQ(r.code, 3) << r.output;
  // A key above the differing one covers it; another key does not.
  EXPECT_EQ(run_octocd("compare " + cpu + " " + bullet + " --tolerance 100 --ignore /geometry --ignore /mid").code, 3);
  // Orientations of two version 1 traces: nothing to compare, exit 2 naming what is missing.
  r = run_octocd("compare " + cpu + " " + bullet +
                 " --ignore /midphase --ignore /geometry --quantity orientations,angular_velocities");
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find("no requested quantity could be compared (orientations: /states/orientation in neither"),
            std::string::npos)
      << r.output;
  EXPECT_NE(r.output.find("angular_velocities: /states/angular_velocity in neither"), std::string::npos) << r.output;
}

TEST_F(Tools, CompareToleranceIsPerQuantityAbsoluteOrRelative) {
  const std::string a = pile_trace("a.h5"), b = pile_trace("b.h5");
  flip_position_bit(b, 37, 5, 1);
  // The largest difference is where the bit was flipped, with both values.
  Result r = run_octocd("compare " + a + " " + b + " --json " + (dir_ / "c.json").string());
  EXPECT_EQ(r.code, 3) << r.output;
  EXPECT_NE(r.output.find("largest at frame 37, body 5: A ("), std::string::npos) << r.output;
  json j = read_json(dir_ / "c.json");
  EXPECT_EQ(j["quantities"][0]["max"]["frame"], 37);
  EXPECT_EQ(j["quantities"][0]["max"]["body"], 5);
  EXPECT_EQ(j["quantities"][0]["beyond_count"], 1);
  ASSERT_EQ(j["quantities"][0]["max"]["a"].size(), 3u);  // both values of the body there, y differs
  EXPECT_EQ(j["quantities"][0]["max"]["a"][0], j["quantities"][0]["max"]["b"][0]);
  EXPECT_NE(j["quantities"][0]["max"]["a"][1], j["quantities"][0]["max"]["b"][1]);
  // An absolute tolerance for positions alone passes it; one for velocities alone does not.
  EXPECT_EQ(run_octocd("compare " + a + " " + b + " --tolerance positions=1e-6").code, 0);
  EXPECT_EQ(run_octocd("compare " + a + " " + b + " --tolerance velocities=1").code, 3);
  // Relative: one bit of a float32 is ~6e-8 of it.
  EXPECT_EQ(run_octocd("compare " + a + " " + b + " --tolerance positions=rel:1e-6").code, 0);
  EXPECT_EQ(run_octocd("compare " + a + " " + b + " --tolerance positions=rel:1e-9").code, 3);
  // design.md section 14's comma form; one quantity given twice is refused (before: the later silently won).
  r = run_octocd("compare " + a + " " + b + " --tolerance positions=1e-6,velocities=1e-5 --json " +
                 (dir_ / "d.json").string());
  EXPECT_EQ(r.code, 0) << r.output;
  j = read_json(dir_ / "d.json");
  EXPECT_EQ(j["tolerance"]["positions"]["abs"], 1e-6);
  EXPECT_EQ(j["tolerance"]["velocities"]["abs"], 1e-5);
  EXPECT_EQ(j["tolerance"]["pairs"]["abs"], 0.0);
  r = run_octocd("compare " + a + " " + b + " --tolerance positions=1e-6 --tolerance positions=0");
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find("positions given twice ('positions=1e-6' and 'positions=0')"), std::string::npos) << r.output;
}

/// Writes one int64 at `row` of a 1-D dataset.
void put_i64(const std::string& path, const char* dataset, hsize_t row, std::int64_t value) {
  const hid_t f = H5Fopen(path.c_str(), H5F_ACC_RDWR, H5P_DEFAULT);
  ASSERT_GE(f, 0);
  const hid_t d = H5Dopen2(f, dataset, H5P_DEFAULT);
  ASSERT_GE(d, 0) << dataset;
  const hid_t sp = H5Dget_space(d);
  const hsize_t count = 1;
  H5Sselect_hyperslab(sp, H5S_SELECT_SET, &row, nullptr, &count, nullptr);
  const hid_t m = H5Screate_simple(1, &count, nullptr);
  ASSERT_GE(H5Dwrite(d, H5T_NATIVE_INT64, m, sp, H5P_DEFAULT, &value), 0);
  H5Sclose(m);
  H5Sclose(sp);
  H5Dclose(d);
  H5Fclose(f);
}

// Issue 22: garbage /states/frame or /contacts/offsets never pass as "same" on what little
// still lines up.
TEST_F(Tools, CompareGarbageFramesOrOffsetsNeverPass) {
  const std::string a = pile_trace("a.h5", 60, "--contacts"), b = pile_trace("b.h5", 60, "--contacts");
  ASSERT_EQ(run_octocd("compare " + a + " " + b).code, 0);
  put_i64(b, "/states/frame", 5, 999);
  Result r = run_octocd("compare " + a + " " + b);
  // Never "same": the structure check names the frame (exit 3 material), then the frame
  // column is refused as bad input (exit 2: frames must increase).
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find("/states/frame: frame 5 only in A"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("/states/frame: row 6 is frame 6 after 999"), std::string::npos) << r.output;
  const std::string c = pile_trace("c.h5", 60, "--contacts");
  put_i64(c, "/contacts/offsets", 2, -5);
  r = run_octocd("compare " + a + " " + c);
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find(c + ": /contacts/offsets: row 2 is -5"), std::string::npos) << r.output;
}

TEST_F(Tools, CompareBadToleranceExitsTwoWithOneLine) {
  const std::string a = pile_trace("a.h5", 10);
  for (const std::string bad : {"positons=1e-6", "positions=-1e-6", "-1", "velocities=rel:-2", "positions=abc",
                                "positions=1e999", "positions=1e-6x"}) {
    const Result r = run_octocd("compare " + a + " " + a + " --tolerance " + bad);
    EXPECT_EQ(r.code, 2) << bad << ": " << r.output;
    EXPECT_NE(r.output.find("--tolerance '" + bad + "'"), std::string::npos) << r.output;
    EXPECT_NE(r.output.find("allowed: "), std::string::npos) << r.output;
    EXPECT_EQ(std::count(r.output.begin(), r.output.end(), '\n'), 1) << r.output;
  }
}

// ---- replay -----------------------------------------------------------------------------------

TEST_F(Tools, ReplayEqualsTheRecordedPairCounts) {
  const std::string t = pile_trace("t.h5");
  const fs::path out = dir_ / "replay.json";
  const Result r = run_octocd("replay " + t + " --broadphase flat,octree,octree-strict,spatial-hash,bullet-dbvt,"
                              "fcl-dynamic-aabb-tree --repeat 2 --json " + out.string());
  ASSERT_EQ(r.code, 0) << r.output;
  const json j = read_json(out);
  // The oracle: /frames/aabb_pairs of the run, read here directly.
  const octocd::TraceReader tr(t);
  const auto rows = tr.complete_rows("/frames");
  const auto frame = tr.read_i64("/frames/frame", rows);
  const auto pairs = tr.read_u64("/frames/aabb_pairs", rows);
  ASSERT_EQ(j["frames"].size(), 60u);  // states of frames 0..59 are each followed by a step
  double sum = 0.0;
  for (std::size_t k = 0; k < j["frames"].size(); ++k) {
    const std::int64_t f = j["frames"][k];
    const auto it = std::find(frame.begin(), frame.end(), f);
    ASSERT_NE(it, frame.end());
    const auto rec = pairs[static_cast<std::size_t>(it - frame.begin())];
    EXPECT_EQ(j["recorded_pairs"][k].get<std::uint64_t>(), rec) << "frame " << f;
    sum += static_cast<double>(rec);
  }
  EXPECT_GT(sum, 0.0);  // the pile has contacts
  for (const auto& run : j["runs"]) {
    EXPECT_TRUE(run["matches_recorded"].get<bool>()) << run.dump();
    EXPECT_TRUE(run["same_as_first"].get<bool>()) << run.dump();
    EXPECT_DOUBLE_EQ(run["pairs"].get<double>(), sum / static_cast<double>(j["frames"].size()));
    EXPECT_EQ(run["ms_per_frame"]["n"], 2);
  }
}

TEST_F(Tools, ReplayCatchesARecordedCountThatDiffers) {
  const std::string t = pile_trace("t.h5");
  // Plant a wrong pair count at frame 40 (row 39).
  const hid_t f = H5Fopen(t.c_str(), H5F_ACC_RDWR, H5P_DEFAULT);
  ASSERT_GE(f, 0);
  const hid_t d = H5Dopen2(f, "/frames/aabb_pairs", H5P_DEFAULT);
  const hid_t s = H5Dget_space(d);
  const hsize_t start = 39, count = 1;
  H5Sselect_hyperslab(s, H5S_SELECT_SET, &start, nullptr, &count, nullptr);
  const hid_t m = H5Screate_simple(1, &count, nullptr);
  std::uint64_t v = 0;
  H5Dread(d, H5T_NATIVE_UINT64, m, s, H5P_DEFAULT, &v);
  v += 1;
  H5Dwrite(d, H5T_NATIVE_UINT64, m, s, H5P_DEFAULT, &v);
  H5Sclose(m);
  H5Sclose(s);
  H5Dclose(d);
  H5Fclose(f);
  const Result r = run_octocd("replay " + t + " --broadphase flat,octree --repeat 1");
  EXPECT_EQ(r.code, 3) << r.output;
  EXPECT_NE(r.output.find("frame 40:"), std::string::npos) << r.output;
}

TEST_F(Tools, ReplayOfATraceWithoutWhatItNeedsExitsTwo) {
  const std::string t = pile_trace("t.h5");
  const hid_t f = H5Fopen(t.c_str(), H5F_ACC_RDWR, H5P_DEFAULT);
  ASSERT_GE(f, 0);
  ASSERT_GE(H5Ldelete(f, "/states/velocity", H5P_DEFAULT), 0);
  H5Fclose(f);
  Result r = run_octocd("replay " + t + " --broadphase flat,octree");
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find(t + ": /states/velocity: missing"), std::string::npos) << r.output;
  // With --state-every above the frame count only the initial state is there: one frame.
  const std::string scene = write("pile.json", kPile);
  const std::string t2 = (dir_ / "t2.h5").string();
  ASSERT_EQ(run_octocd("run " + scene + " --frames 20 --state-every 50 --quiet --trace " + t2).code, 0);
  r = run_octocd("replay " + t2 + " --broadphase flat");
  EXPECT_EQ(r.code, 0) << r.output;  // frame 0's state is followed by step 1
  EXPECT_NE(r.output.find("1 frames, steps 1"), std::string::npos) << r.output;
  const std::string t3 = (dir_ / "t3.h5").string();
  ASSERT_EQ(run_octocd("run " + scene + " --frames 20 --state-every 50 --quiet --trace " + t3).code, 0);
  r = run_octocd("replay " + t3 + " --broadphase no-such");
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.output.find("unknown broadphase 'no-such'"), std::string::npos) << r.output;
  r = run_octocd("replay " + t3 + " --broadphase flat --engine cuda");
  EXPECT_NE(r.code, 0);  // 1 without a CUDA device (the reason named), 0 with one
  if (r.code != 0) {
    EXPECT_NE(r.output.find("cuda"), std::string::npos) << r.output;
  }
}

// ---- report -----------------------------------------------------------------------------------

TEST_F(Tools, ReportRendersFromTheCommittedSmallResults) {
  const std::string data = source_dir() + "/tests/data/";
  const std::string t = pile_trace("t.h5");
  const fs::path out = dir_ / "report";
  const Result r = run_octocd("report " + data + "bench-small-table6.json " + data + "bench-small-figA2.json " + data +
                              "bench-small-scaling.json " + t + " -o " + out.string());
  ASSERT_EQ(r.code, 0) << r.output;
  std::ifstream in(out / "index.html");
  std::stringstream ss;
  ss << in.rdbuf();
  const std::string page = ss.str();
  EXPECT_NE(page.find("<svg"), std::string::npos);
  EXPECT_NE(page.find("Table 6"), std::string::npos);
  EXPECT_NE(page.find("81.14"), std::string::npos);  // the paper's bunny L0 figure beside ours
  EXPECT_NE(page.find("Broadphase scaling"), std::string::npos);
  EXPECT_NE(page.find("Fig. A2"), std::string::npos);
  EXPECT_NE(page.find("Trace t.h5"), std::string::npos);
  // Self-contained: nothing loaded from elsewhere.
  for (const char* s : {"<script src", "<link", "<img src=\"http", "url(http", "@import"})
    EXPECT_EQ(page.find(s), std::string::npos) << s;
  std::ifstream md(out / "report.md");
  std::stringstream ms;
  ms << md.rdbuf();
  EXPECT_NE(ms.str().find("| scene (bodies) | paper L0 FPS"), std::string::npos);
  EXPECT_TRUE(fs::exists(out / "plots"));
}

// The performance gate on committed results (tests/data/README.md): gate-new.json is
// gate-base.json with point 0 planted 20 % slower in every repetition and point 1 planted
// 20 % slower in four of five repetitions (one as fast as the baseline's best); points 2 and
// 3 are unchanged. The one-sided Mann-Whitney U test at level 0.05 flags point 0 only (p =
// 1/252; point 1: p = 0.075). Every refusal and exit code: tests/report/test_gate.py.
TEST_F(Tools, ReportGateFlagsThePlantedSlowerPointOnly) {
  const std::string data = source_dir() + "/tests/data/";
  const fs::path out = dir_ / "gate", csv = dir_ / "csv";
  Result r = run_octocd("report --baseline " + data + "gate-base.json " + data + "gate-new.json -o " + out.string() +
                        " --csv " + csv.string());
  EXPECT_EQ(r.code, 4) << r.output;
  EXPECT_NE(r.output.find("gate: SLOWER: pile | midphase=aabb-only | cpu: steps/s (all): time ratio 1.200 (90 % "
                          "interval 1.175-1.225"),
            std::string::npos)
      << r.output;
  EXPECT_EQ(r.output.find("gate: SLOWER: pile | midphase=1,2"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("1 of 4 figure(s) SLOWER"), std::string::npos) << r.output;
  // The gate's data: per point 5 + 5 repetition rows and a summary row.
  std::ifstream in(csv / "gate.csv");
  ASSERT_TRUE(in) << "no gate CSV in " << csv;
  std::string line;
  std::vector<std::string> lines;
  while (std::getline(in, line)) lines.push_back(line);
  ASSERT_EQ(lines.size(), 1u + 4u * 11u);
  EXPECT_NE(lines[0].find("kind,side,repetition,value,unit"), std::string::npos) << lines[0];
  EXPECT_NE(lines[11].find("summary"), std::string::npos) << lines[11];
  // A threshold above the planted 20 % passes; the baseline against itself passes.
  EXPECT_EQ(run_octocd("report --baseline " + data + "gate-base.json " + data + "gate-new.json -o " + out.string() +
                       " --threshold 25").code, 0);
  r = run_octocd("report --baseline " + data + "gate-base.json " + data + "gate-base.json -o " + out.string());
  EXPECT_EQ(r.code, 0) << r.output;
  // Reversed, the planted point is faster: no failure.
  EXPECT_EQ(run_octocd("report --baseline " + data + "gate-new.json " + data + "gate-base.json -o " + out.string()).code, 0);
}

TEST_F(Tools, ReportGateAndMergeRefuseMismatchedInputsWithOneLine) {
  const std::string data = source_dir() + "/tests/data/";
  const std::string o = " -o " + (dir_ / "rep").string();
  // A baseline of another sweep.
  Result r = run_octocd("report --baseline " + data + "bench-small-table6.json " + data + "gate-new.json" + o);
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find("baseline of another sweep"), std::string::npos) << r.output;
  EXPECT_EQ(std::count(r.output.begin(), r.output.end(), '\n'), 1) << r.output;
  // A baseline of another format.
  const std::string other = write("other.json", R"({"format": "something-else", "version": 1})");
  r = run_octocd("report --baseline " + other + " " + data + "gate-new.json" + o);
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find(other + ": format"), std::string::npos) << r.output;
  // Shards of different builds mixed in one report.
  r = run_octocd("report " + data + "gate-base.json " + data + "gate-new.json" + o);
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find("build.build_id"), std::string::npos) << r.output;
  EXPECT_EQ(std::count(r.output.begin(), r.output.end(), '\n'), 1) << r.output;
  // A kept point with garbage where its figures should be: one line, no traceback.
  json j = read_json(data + "gate-base.json");
  for (const json& bad : {json("nope"), json({{"all", 3}}), json({{"all", {{"steps_per_s", "fast"}}}})}) {
    j["points"][1]["windows"] = bad;
    const std::string f = write("bad.json", j.dump());
    r = run_octocd("report " + f + o);
    EXPECT_EQ(r.code, 2) << bad.dump() << ": " << r.output;
    EXPECT_EQ(r.output.find("Traceback"), std::string::npos) << r.output;
    EXPECT_NE(r.output.find(f + ": points[1].windows"), std::string::npos) << r.output;
    EXPECT_EQ(std::count(r.output.begin(), r.output.end(), '\n'), 1) << r.output;
  }
  r = run_octocd("report --baseline " + data + "gate-base.json " + data + "gate-new.json --threshold -3" + o);
  EXPECT_EQ(r.code, 2) << r.output;
}

TEST_F(Tools, ReportRejectsAResultOfAnotherFormatOrVersion) {
  const std::string other = write("other.json", R"({"format": "octocd-bench", "version": 7, "points": []})");
  Result r = run_octocd("report " + other + " -o " + (dir_ / "rep").string());
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find(other + ": format: 'octocd-bench' version 7; allowed: octocd-bench version 1"),
            std::string::npos)
      << r.output;
  const std::string junk = write("junk.json", "[1, 2");
  r = run_octocd("report " + junk + " -o " + (dir_ / "rep").string());
  EXPECT_EQ(r.code, 2) << r.output;
  r = run_octocd("report " + (dir_ / "missing.json").string() + " -o " + (dir_ / "rep").string());
  EXPECT_EQ(r.code, 2) << r.output;
  // Resuming a file of another format is refused too.
  write("pile.json", kPile);
  const std::string foreign = write("foreign.json", R"({"format": "something-else", "version": 1})");
  r = run_octocd("bench " + tiny_sweep() + " -o " + foreign + " --resume");
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find("allowed: octocd-bench version 1"), std::string::npos) << r.output;
}

TEST_F(Tools, ReportPageRendersInHeadlessChromium) {
  std::string chromium;
  for (const char* c : {"/usr/bin/chromium", "/usr/bin/chromium-browser", "/usr/bin/google-chrome"})
    if (fs::exists(c)) chromium = c;
  if (chromium.empty()) GTEST_SKIP() << "chromium not installed (Debian package chromium): no screenshot taken";
  const fs::path out = dir_ / "report";
  ASSERT_EQ(run_octocd("report " + source_dir() + "/tests/data/bench-small-table6.json -o " + out.string()).code, 0);
  const fs::path png = dir_ / "shot.png";
  const std::string cmd = "bash " + source_dir() + "/scripts/screenshot-report.sh " + (out / "index.html").string() +
                          " " + png.string() + " 1280 2000 > /dev/null 2>&1";
  ASSERT_EQ(std::system(cmd.c_str()), 0);
  ASSERT_TRUE(fs::exists(png));
  EXPECT_GT(fs::file_size(png), 30000u);  // a blank page is a few kB
}

}  // namespace octocd_test_cli_tools
