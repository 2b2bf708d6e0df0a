// Engines as processes (issue 66, docs/bring-your-engine.md): small Python engines
// registered in tests/data/process_engines/engines.json (tests/support/process_engines/
// boxes_engine.py) driven by `octocd` through `--engines-file`. The correct one (resting
// and free-falling boxes) is judged clean by `validate SCENE --engine NAME`, `run --trace`
// gives its trace and `bench` its steps/s; each planted fault (a non-zero exit, a signal,
// a hang past timeout_s, a truncated trace, a wrong body or frame count, hostile output, a
// missing timing attribute, a trace over max_trace_bytes) is exit 1 naming the engine and
// what it did, with no terminal escape and no temporary file left; SIGINT to octocd stops
// the child; a bad engines file is exit 2 naming the file and the field.
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <regex>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "octocd/trace_reader.hpp"
#include "support/cli_run.hpp"
#include "support/wait_event.hpp"

// This file's own names (its tests compile in unity batches with the folder's other files).
namespace octocd_test_cli_process_engines {

namespace fs = std::filesystem;
using octocd::test::Result;

namespace {

std::string data(const std::string& name) {
  return (fs::path(octocd::test::source_dir()) / "tests/data/process_engines" / name).string();
}

/// A fresh folder for one test (its TMPDIR and outputs).
class ProcessEngines : public ::testing::Test {
 protected:
  void SetUp() override {
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    dir_ = fs::temp_directory_path() / (std::string("octocd-proc-") + info->name() + "-" + std::to_string(::getpid()));
    fs::remove_all(dir_);
    fs::create_directories(dir_ / "tmp");
  }
  void TearDown() override { fs::remove_all(dir_); }

  /// `octocd --engines-file FILE ARGS` with TMPDIR = the test's tmp folder.
  Result octocd(const std::string& args, const std::string& engines = data("engines.json")) const {
    return octocd::test::run("TMPDIR=" + (dir_ / "tmp").string() + " " + octocd::test::bin() + " --engines-file " +
                             engines + " " + args);
  }
  /// The test's TMPDIR holds nothing (every temporary file removed).
  bool tmp_empty() const { return fs::is_empty(dir_ / "tmp"); }
  std::string path(const std::string& name) const { return (dir_ / name).string(); }

  fs::path dir_;
};

TEST_F(ProcessEngines, ListedBesideTheBuiltInOnesWithTheirAvailability) {
  const Result r = octocd("engines");
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_NE(r.output.find("bullet "), std::string::npos) << r.output;
  EXPECT_TRUE(std::regex_search(r.output, std::regex("pyboxes +available")));
  EXPECT_TRUE(std::regex_search(r.output, std::regex("pymissing +unavailable: command 'no-such-runtime-octocd' not "
                                                     "found on PATH")))
      << r.output;
  // The check command's exit code and the tail of its stderr.
  EXPECT_TRUE(std::regex_search(r.output, std::regex("pycheckfails +unavailable: its check .* exited with code 4.*no "
                                                     "module named rapier")))
      << r.output;
  // The shipped engines file's rapier and jolt are listed, available or not.
  EXPECT_TRUE(std::regex_search(r.output, std::regex("\\nrapier +(available|unavailable: .+)"))) << r.output;
  EXPECT_TRUE(std::regex_search(r.output, std::regex("\\njolt +(available|unavailable: .+)"))) << r.output;

  const Result a = octocd("engines --available");
  ASSERT_EQ(a.code, 0) << a.output;
  EXPECT_TRUE(std::regex_search(a.output, std::regex("(^|\\n)pyboxes\\n")));
  EXPECT_EQ(a.output.find("pymissing"), std::string::npos);

  const Result j = octocd("engines --json");
  ASSERT_EQ(j.code, 0) << j.output;
  const nlohmann::json doc = nlohmann::json::parse(j.output);
  std::map<std::string, nlohmann::json> by;
  for (const auto& e : doc.at("engines")) by[e.at("name").get<std::string>()] = e;
  ASSERT_TRUE(by.count("cpu") && by.count("bullet") && by.count("pyboxes") && by.count("rapier") && by.count("jolt"));
  EXPECT_EQ(by["cpu"]["kind"], "builtin");
  EXPECT_EQ(by["pyboxes"]["kind"], "process");
  EXPECT_EQ(by["pyboxes"]["available"], true);
  EXPECT_EQ(by["pyboxes"]["why"], "");
  EXPECT_EQ(by["pyboxes"]["rotates"], true);
  EXPECT_EQ(by["pyboxes"]["geometries"], nlohmann::json::array({"box"}));
  EXPECT_EQ(by["pyboxes"]["settings"], nlohmann::json::array({"ready", "escape", "wall_step_seconds", "hold"}));
  // Command items naming files are made absolute against the engines file's folder.
  EXPECT_TRUE(fs::path(by["pyboxes"]["command"][1].get<std::string>()).is_absolute());
  EXPECT_EQ(by["pymissing"]["available"], false);
  EXPECT_NE(by["pymissing"]["why"].get<std::string>().find("not found on PATH"), std::string::npos);
  EXPECT_EQ(doc.at("engines_files").back(), data("engines.json"));

  // --no-checks: the same registry facts; a process engine's availability null, not said;
  // a built-in engine's answered as with the checks. Without --json it is refused.
  const Result n = octocd("engines --json --no-checks");
  ASSERT_EQ(n.code, 0) << n.output;
  const nlohmann::json unchecked = nlohmann::json::parse(n.output);
  ASSERT_EQ(unchecked.at("engines").size(), doc.at("engines").size());
  for (const auto& e : unchecked.at("engines")) {
    nlohmann::json checked = by.at(e.at("name").get<std::string>());
    SCOPED_TRACE(e.at("name").get<std::string>());
    if (e.at("kind") == "process") {
      EXPECT_TRUE(e.at("available").is_null());
      EXPECT_EQ(e.at("why"), "not checked (--no-checks)");
    } else {
      EXPECT_EQ(e.at("available"), checked.at("available"));
      EXPECT_EQ(e.at("why"), checked.at("why"));
    }
    for (const char* key : {"available", "why"}) {
      checked.erase(key);
    }
    nlohmann::json facts = e;
    facts.erase("available");
    facts.erase("why");
    EXPECT_EQ(facts, checked);
  }
  EXPECT_EQ(unchecked.at("engines_files"), doc.at("engines_files"));
  const Result t = octocd("engines --no-checks");
  EXPECT_EQ(t.code, 2) << t.output;
  EXPECT_NE(t.output.find("--no-checks: without --json; allowed: with --json only"), std::string::npos) << t.output;
}

TEST_F(ProcessEngines, TheUsersEnginesFileIsReadAndTheOptionsFileReplacesItsEntries) {
  // $XDG_CONFIG_HOME/octocd/engines.json: read after the shipped file, before --engines-file.
  fs::create_directories(dir_ / "config" / "octocd");
  std::ofstream(dir_ / "config" / "octocd" / "engines.json")
      << R"({"format": "octocd-engines", "version": 1, "engines": [
           {"name": "mine", "description": "the user's", "command": ["/usr/bin/python3", "-c", "pass"]},
           {"name": "pyboxes", "description": "replaced by --engines-file", "command": ["/usr/bin/python3"]}]})";
  const Result r = octocd::test::run("XDG_CONFIG_HOME=" + (dir_ / "config").string() + " " + octocd::test::bin() +
                                     " --engines-file " + data("engines.json") + " engines --json");
  ASSERT_EQ(r.code, 0) << r.output;
  const nlohmann::json doc = nlohmann::json::parse(r.output);
  const std::vector<std::string> files = doc.at("engines_files");
  ASSERT_EQ(files.size(), 3u) << r.output;  // the build tree's, the user's, the option's
  EXPECT_EQ(files[1], (dir_ / "config" / "octocd" / "engines.json").string());
  EXPECT_EQ(files[2], data("engines.json"));
  int mine = 0, pyboxes = 0;
  for (const auto& e : doc.at("engines")) {
    if (e.at("name") == "mine") ++mine;
    if (e.at("name") == "pyboxes") {
      ++pyboxes;
      EXPECT_NE(e.at("description"), "replaced by --engines-file");
    }
  }
  EXPECT_EQ(mine, 1);
  EXPECT_EQ(pyboxes, 1);
}

TEST_F(ProcessEngines, TheCorrectEngineIsJudgedCleanThroughItsOwnTrace) {
  const std::string trace = path("pyboxes.h5");
  const Result r = octocd("validate " + data("boxes.json") + " --engine pyboxes --frames 120 --trace " + trace);
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_NE(r.output.find("engine pyboxes"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("all validators pass"), std::string::npos) << r.output;
  // --trace keeps the process's own trace, as it wrote it (its engine attribute, its frames).
  const Result check = octocd::test::run_octocd("validate --trace-in " + trace + " --check-only");
  ASSERT_EQ(check.code, 0) << check.output;
  EXPECT_NE(check.output.find("engine 'boxes_engine 1.0', 4 bodies, 120 frames, version 2"), std::string::npos)
      << check.output;
  EXPECT_TRUE(tmp_empty());
}

TEST_F(ProcessEngines, RunGivesTheTraceAndBenchTheStepsPerSecondOfItsTiming) {
  const std::string trace = path("run.h5"), summary = path("summary.json");
  const Result r = octocd("run " + data("boxes.json") + " --engine pyboxes --frames 80 --trace " + trace +
                          " --quiet --summary-json " + summary);
  ASSERT_EQ(r.code, 0) << r.output;
  // The process's own layout gets no XDMF sidecar (it describes octocd's own traces).
  EXPECT_FALSE(std::filesystem::exists(trace + ".xmf"));
  const Result check = octocd::test::run_octocd("validate --trace-in " + trace + " --check-only");
  ASSERT_EQ(check.code, 0) << check.output;
  EXPECT_NE(check.output.find("80 frames"), std::string::npos) << check.output;
  std::ifstream in(summary);
  const nlohmann::json s = nlohmann::json::parse(in);
  EXPECT_EQ(s.at("frames"), 80);
  EXPECT_EQ(s.at("engine"), "pyboxes");
  // steps/s: the frames over the process's own timing (its trace's wall_step_seconds).
  const double wall = octocd::TraceReader(trace).number_attribute("wall_step_seconds");
  ASSERT_GT(wall, 0.0);
  EXPECT_NEAR(s.at("steps_per_s").get<double>(), 80.0 / wall, 1e-6 * 80.0 / wall);
  // The falling box (body 3, 2 kg) after 80 steps of semi-implicit Euler: v = -9.81 * 0.08.
  EXPECT_NEAR(s.at("kinetic_energy").at("last").get<double>(), 0.5 * 2.0 * std::pow(9.81 * 0.08, 2), 1e-3);
  EXPECT_TRUE(tmp_empty());

  // bench: a sweep naming the process engine reports its steps/s from the same timing.
  const std::string result = path("bench.json");
  const Result b = octocd("bench " + data("bench.json") + " --scene-dir " + data("") + " --quiet -o " + result);
  ASSERT_EQ(b.code, 0) << b.output;
  std::ifstream bin(result);
  const nlohmann::json bench = nlohmann::json::parse(bin);
  const nlohmann::json& point = bench.at("points").at(0);
  EXPECT_EQ(point.at("status"), "ok");
  EXPECT_GT(point.at("windows").at("all").at("steps_per_s").at("median").get<double>(), 0.0);
  EXPECT_FALSE(point.at("windows").at("all").contains("cpu_steps_per_s"));  // octocd's CPU time is not the engine's
  EXPECT_TRUE(tmp_empty());
}

// A process engine's timing is checked before it is used: a wall_step_seconds of 0, the
// smallest subnormal, 1e-300, a negative number, inf or NaN (steps/s 0, inf or 10^302) is
// bad input from the engine, exit 2 naming the engine, the field, the value and the allowed
// range; bench stores the point as failed with that reason instead of a steps/s `report`
// refuses, and exits 2 naming it. (Before: exit 1, a runtime failure.) So do sweeps of the
// kinds speed-accuracy, divergence and max-instances, the cpu's point beside it run and
// kept. (Before: speed-accuracy called the point diverged and divergence skipped it, both
// with exit 0; max-instances ended at once with exit 2, writing no result.)
TEST_F(ProcessEngines, AHostileTimingIsRefusedNamingTheFieldAndTheRange) {
  // The smallest sweep of each kind: 2 frames of pyboxes, then of cpu (which translates only).
  std::ofstream(path("sa.json")) << R"({"name": "sa", "kind": "speed-accuracy", "scenes": ["boxes"],
      "set": {"/rotation": false}, "engines": ["pyboxes", "cpu"], "repeat": 1, "dts": [0.001],
      "sim_seconds": 0.002, "rotation": [false]})";
  std::ofstream(path("dv.json")) << R"({"name": "dv", "kind": "divergence", "scenes": ["boxes"],
      "set": {"/rotation": false}, "engines": ["pyboxes", "cpu"], "frames": 2, "eps": [0.0001], "copies": 1})";
  std::ofstream(path("mi.json")) << R"({"name": "mi", "kind": "max-instances", "scenes": ["grid.json"],
      "engines": ["pyboxes", "cpu"], "warmup": 0, "frames": 2, "repeat": 1, "max_instances": 1,
      "target_steps_per_s": 0.000001})";
  std::ofstream(path("grid.json")) << R"({"name": "grid", "domain": {"min": [-1, 0, -1], "max": [1, 2, 1]},
      "dt": 0.001, "frames": 2, "walls": "floor", "groups": [{"name": "b", "shape": {"box": [0.1, 0.1, 0.1]},
      "count": 8, "mass": 1.0, "layout": {"type": "grid", "min": [-0.25, 0.5, -0.25], "max": [0.25, 1.0, 0.25],
      "spacing": 0.5}}]})";
  for (const char* wall : {"0", "5e-324", "1e-300", "-1", "inf", "nan"}) {
    SCOPED_TRACE(wall);
    const std::string item = std::string(" --pyboxes wall_step_seconds=") + wall;
    const std::string said = std::string(wall) == "5e-324" ? "4.94066e-324" : wall;
    const std::regex refused("octocd: error: engine 'pyboxes' \\(.*engines.json\\) gave wall_step_seconds = " + said +
                             " \\(its trace's root attribute; 30 frames over it: .* steps/s\\); allowed: a finite "
                             "number of seconds > 0 whose 30 frames over it are at most 1e\\+15 steps/s");
    const Result r = octocd("run " + data("boxes.json") + " --engine pyboxes --frames 30 --quiet" + item);
    EXPECT_EQ(r.code, 2) << r.output;
    EXPECT_TRUE(std::regex_search(r.output, refused)) << r.output;
    if (std::string(wall) == "0") {  // validate SCENE --engine: the same refusal
      const Result v = octocd("validate " + data("boxes.json") + " --engine pyboxes --frames 30" + item);
      EXPECT_EQ(v.code, 2) << v.output;
      EXPECT_TRUE(std::regex_search(v.output, refused)) << v.output;
    }
    const std::string result = path(std::string("bench-") + wall + ".json");
    const Result b = octocd("bench " + data("bench.json") + " --scene-dir " + data("") + " --quiet -o " + result + item);
    EXPECT_EQ(b.code, 2) << b.output;
    EXPECT_NE(b.output.find("octocd: error: 1 point(s) failed on a value an engine gave"), std::string::npos)
        << b.output;
    EXPECT_NE(b.output.find("gave wall_step_seconds = " + said), std::string::npos) << b.output;
    std::ifstream bin(result);
    const nlohmann::json bench = nlohmann::json::parse(bin);
    const nlohmann::json& point = bench.at("points").at(0);
    EXPECT_EQ(point.at("status"), "failed");
    EXPECT_NE(point.at("reason").get<std::string>().find("wall_step_seconds = " + said), std::string::npos);
    EXPECT_FALSE(point.contains("windows"));
    EXPECT_TRUE(tmp_empty());
    if (std::string(wall) != "0") continue;
    for (const char* kind : {"sa", "dv", "mi"}) {
      SCOPED_TRACE(kind);
      const std::string out = path(std::string(kind) + "-result.json");
      const Result k = octocd("bench " + path(std::string(kind) + ".json") + " --scene-dir " + data("") +
                              " --quiet -o " + out + item);
      EXPECT_EQ(k.code, 2) << k.output;
      EXPECT_NE(k.output.find("octocd: error: 1 point(s) failed on a value an engine gave"), std::string::npos)
          << k.output;
      ASSERT_TRUE(fs::exists(out)) << k.output;  // the result written
      std::ifstream kin(out);
      const nlohmann::json swept = nlohmann::json::parse(kin);
      std::map<std::string, nlohmann::json> by;  // each engine's point
      for (const auto& pt : swept.at("points")) by[pt.at("params").at("engine").get<std::string>()] = pt;
      ASSERT_TRUE(by.count("pyboxes") && by.count("cpu")) << swept.dump(1);
      EXPECT_EQ(by["pyboxes"].at("status"), "failed");
      EXPECT_NE(by["pyboxes"].at("reason").get<std::string>().find("gave wall_step_seconds = 0 "), std::string::npos)
          << by["pyboxes"].dump(1);
      EXPECT_EQ(by["cpu"].at("status"), "ok") << by["cpu"].dump(1);
      EXPECT_TRUE(tmp_empty());
    }
  }
}

// The engines file's command items reach the terminal on `run`'s "pipeline ... on a process
// (...)" line: their escape sequences are shown as \x1b (octocd::printable), never run.
TEST_F(ProcessEngines, RunPrintsTheCommandItemsEscaped) {
  const std::string script =
      (fs::path(octocd::test::source_dir()) / "tests/support/process_engines/boxes_engine.py").string();
  const std::string engines = path("esc-engines.json");
  std::ofstream(engines) << R"({"format": "octocd-engines", "version": 1, "engines": [{"name": "pyesc",
      "command": ["/usr/bin/python3", ")" << script << R"(", "--mode", "ok\u001b[2J\u001b]0;pwned\u0007"],
      "rotates": true, "geometries": ["box"]}]})";
  const Result r = octocd("run " + data("boxes.json") + " --engine pyesc --frames 5", engines);
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_EQ(r.output.find('\x1b'), std::string::npos) << r.output;
  EXPECT_EQ(r.output.find('\x07'), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("on a process (python3 boxes_engine.py --mode ok\\x1b[2J\\x1b]0;pwned\\x07)"),
            std::string::npos)
      << r.output;
  EXPECT_TRUE(tmp_empty());
}

// `octocd engines` runs every process engine's check at once under one bound: six checks
// that never end (one after another: 6 x 2 s, 6 x 30 s by default) are all answered within
// the 2 s bound and its 2 s grace, each named as timed out.
TEST_F(ProcessEngines, HangingChecksAreAnsweredWithinOneBoundEachNamed) {
  const std::string script =
      (fs::path(octocd::test::source_dir()) / "tests/support/process_engines/boxes_engine.py").string();
  const std::string engines = path("hang-engines.json");
  {
    std::ofstream f(engines);
    f << R"({"format": "octocd-engines", "version": 1, "engines": [)";
    for (int i = 0; i < 6; ++i)
      f << (i ? "," : "") << R"({"name": "hang)" << i << R"(", "command": ["/usr/bin/python3", ")" << script
        << R"("], "check": ["/bin/sleep", "1000"]})";
    f << "]}";
  }
  const auto t0 = std::chrono::steady_clock::now();
  const Result r = octocd("engines --check-timeout 2", engines);
  const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  ASSERT_EQ(r.code, 0) << r.output;
  for (int i = 0; i < 6; ++i)
    EXPECT_TRUE(std::regex_search(r.output, std::regex("hang" + std::to_string(i) +
                                                       " +unavailable: its check \\(/bin/sleep 1000\\) timed out: "
                                                       "it ran past [0-9.]+ s \\(the checks' bound, 2 s for all")))
        << r.output;
  EXPECT_LT(s, 8.0) << "six checks of 2 s one after another take 12 s";
  EXPECT_EQ(octocd("engines --check-timeout 31", engines).code, 2);
}

// A file item of a check or a command that is a FIFO is examined, never opened: the engine
// is unavailable at once naming the item and its type. (Before: python3 opened the FIFO and
// blocked until the checks' bound, reported "timed out".)
TEST_F(ProcessEngines, AFifoItemIsSaidAsSuchWithoutWaiting) {
  const std::string script =
      (fs::path(octocd::test::source_dir()) / "tests/support/process_engines/boxes_engine.py").string();
  const std::string fifo = path("check.py");
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0) << std::strerror(errno);
  const std::string engines = path("fifo-engines.json");
  std::ofstream(engines) << R"({"format": "octocd-engines", "version": 1, "engines": [
      {"name": "fifocheck", "command": ["/usr/bin/python3", ")" << script << R"("],
       "check": ["/usr/bin/python3", ")" << fifo << R"("]},
      {"name": "fifocommand", "command": ["/usr/bin/python3", ")" << fifo << R"("], "timeout_s": 3}]})";
  // The shipped engines' checks run beside these under the same bound: the time of the
  // listing is theirs; the FIFO's line says it was not run (never "timed out").
  const Result r = octocd("engines --check-timeout 5", engines);
  ASSERT_EQ(r.code, 0) << r.output;
  for (const char* what : {"fifocheck +unavailable: check", "fifocommand +unavailable: command"})
    EXPECT_TRUE(std::regex_search(r.output, std::regex(std::string(what) + " item '" + fifo +
                                                       "' is not a regular file \\(a FIFO\\); not run")))
        << r.output;
  EXPECT_FALSE(std::regex_search(r.output, std::regex("fifocheck +unavailable: [^\\n]*timed out"))) << r.output;
  const Result run = octocd("run " + data("boxes.json") + " --engine fifocommand --frames 5 --quiet", engines);
  EXPECT_EQ(run.code, 1) << run.output;
  EXPECT_NE(run.output.find("is unavailable here: command item '" + fifo + "' is not a regular file (a FIFO)"),
            std::string::npos)
      << run.output;
  EXPECT_TRUE(tmp_empty());
}

struct Fault {
  const char* engine;
  const char* what;  // a regular expression the message must match
};

TEST_F(ProcessEngines, EveryFaultIsAClearRuntimeFailureNamingTheEngine) {
  const std::vector<Fault> faults{
      {"pycrash", "engine 'pycrash' \\(.*engines.json\\) exited with code 3 after .* s; its stderr ended: "
                  "boxes_engine: planted crash"},
      {"pysignal", "engine 'pysignal' .* was killed by signal 6 \\(SIGABRT\\)"},
      {"pyhang", "engine 'pyhang' .* ran past its timeout_s of 1 s and was stopped after 1\\.[0-9]+ s"},
      {"pytruncated", "engine 'pytruncated' .* wrote a trace the hardened reader refuses: "},
      {"pybodies", "engine 'pybodies' .* wrote a trace of 3 bodies; the request has 4"},
      {"pyframes", "engine 'pyframes' .* wrote a trace of 29 frames; the request asked for 30"},
      {"pynotiming", "engine 'pynotiming' .* wall_step_seconds: missing"},
      // An empty stderr: the last lines of stdout but its progress lines, else "no error
      // output" (before: the progress lines were quoted as the error).
      {"pystdout", "engine 'pystdout' .* exited with code 5 after .* s; its stdout ended \\(its octocd-progress lines "
                   "left out\\): boxes_engine: planted failure said on stdout\\n"},
      {"pyquiet", "engine 'pyquiet' .* exited with code 5 after .* s; no error output \\(its stderr is empty, its "
                  "stdout holds only octocd-progress lines\\)\\n"},
      {"pybig", "engine 'pybig' .* wrote a trace beyond its max_trace_bytes 1000"},
      {"pyhostile", "engine 'pyhostile' .* exited with code 1 .*its stderr ended \\(the last [0-9]+ of 1048[0-9]+ "
                    "bytes\\): .*last line \\\\x1b\\[0m"},
      {"pymissing", "engine 'pymissing' .* is unavailable here: command 'no-such-runtime-octocd' not found on PATH"},
      {"pycheckfails", "engine 'pycheckfails' .* is unavailable here: its check .* exited with code 4 .*no module "
                       "named rapier"},
  };
  for (const Fault& f : faults) {
    for (const char* command : {"validate", "run"}) {
      SCOPED_TRACE(std::string(f.engine) + " " + command);
      const Result r = octocd(std::string(command) + " " + data("boxes.json") + " --engine " + f.engine +
                              " --frames 30" + (std::string(command) == "run" ? " --quiet" : ""));
      EXPECT_EQ(r.code, 1) << r.output;
      EXPECT_TRUE(std::regex_search(r.output, std::regex(std::string("runtime failure: ") + f.what))) << r.output;
      // Nothing raw reaches the terminal: no escape, no BEL, no C1 control; a bounded message.
      EXPECT_EQ(r.output.find('\x1b'), std::string::npos);
      EXPECT_EQ(r.output.find('\x07'), std::string::npos);
      EXPECT_EQ(r.output.find("\xc2\x9b"), std::string::npos);
      EXPECT_LT(r.output.size(), 8000u);
      EXPECT_TRUE(tmp_empty()) << "a temporary file is left in " << (dir_ / "tmp");
    }
  }
}

TEST_F(ProcessEngines, SigintToOctocdStopsTheChild) {
  const std::string ready = path("ready");
  const std::string tmp = "TMPDIR=" + (dir_ / "tmp").string();
  const pid_t pid = ::fork();
  ASSERT_GE(pid, 0);
  if (pid == 0) {
    ::setenv("TMPDIR", (dir_ / "tmp").c_str(), 1);
    const std::string b = octocd::test::bin(), engines = data("engines.json"), scene = data("boxes.json"),
                      item = "ready=" + ready;
    ::execl(b.c_str(), b.c_str(), "--engines-file", engines.c_str(), "validate", scene.c_str(), "--engine", "pystop",
            "--pystop", item.c_str(), static_cast<char*>(nullptr));
    ::_exit(127);
  }
  // The child engine writes its process id to `ready` once it has read the request.
  const bool started = octocd::test::wait_until([&] { return fs::exists(ready); }, {dir_}, std::chrono::seconds(60));
  ASSERT_TRUE(started);
  pid_t engine = 0;
  std::ifstream(ready) >> engine;
  ASSERT_GT(engine, 0);
  ASSERT_EQ(::kill(engine, 0), 0);  // running
  ::kill(pid, SIGINT);
  int status = 0;
  ASSERT_TRUE(octocd::test::wait_child(pid, status, std::chrono::seconds(30)));
  ASSERT_TRUE(WIFEXITED(status));
  EXPECT_EQ(WEXITSTATUS(status), 130);
  // octocd stopped and reaped it: no such process any more.
  EXPECT_EQ(::kill(engine, 0), -1);
  EXPECT_EQ(errno, ESRCH);
  EXPECT_TRUE(tmp_empty());
}

TEST_F(ProcessEngines, ABadEnginesFileIsBadInputNamingTheFileAndTheField) {
  struct Bad {
    const char* json;
    const char* what;
  };
  const std::vector<Bad> bad{
      {R"({"format": "octocd-engines", "version": 1, "engines": [{"name": "x", "command": ["python3"], "colour": 1}]})",
       "engines\\[0\\]\\.colour: an unknown field; allowed: name, description, command"},
      {R"({"format": "octocd-engines", "version": 1, "engines": [{"name": "bullet", "command": ["python3"]}]})",
       "engines\\[0\\]\\.name: 'bullet' is a built-in engine; allowed: a name no built-in engine has"},
      {R"({"format": "octocd-engines", "version": 1, "engines": [{"name": "x", "command": "python3 x.py"}]})",
       "engines\\[0\\]\\.command: a string .*: a shell command line is never run; allowed: an argument vector"},
      {R"({"format": "octocd-engines", "version": 1, "engines": [{"name": "x", "command": ["python3 x.py | sh"]}]})",
       "engines\\[0\\]\\.command\\[0\\]: 'python3 x.py \\| sh' reads as a shell command line"},
      {R"({"format": "octocd-engines", "version": 1, "engines": [{"name": "X Y", "command": ["python3"]}]})",
       "engines\\[0\\]\\.name: 'X Y'; allowed: a name of \\[a-z0-9_-\\]\\{1,32\\}"},
      {R"({"format": "octocd-engines", "version": 2, "engines": []})", "version: .*allowed"},
      {R"({"format": "octocd-engines", "version": 1, "engines": [{"name": "x", "command": ["python3"],
           "timeout_s": -1}]})",
       "engines\\[0\\]\\.timeout_s: "},
  };
  int k = 0;
  for (const Bad& b : bad) {
    SCOPED_TRACE(b.json);
    const std::string file = path("bad" + std::to_string(k++) + ".json");
    std::ofstream(file) << b.json;
    const Result r = octocd("engines", file);
    EXPECT_EQ(r.code, 2) << r.output;
    EXPECT_TRUE(std::regex_search(r.output, std::regex("octocd: error: " + std::regex_replace(file, std::regex("[.]"),
                                                                                               "[.]") +
                                                       ": " + b.what)))
        << r.output;
  }
  // A missing engines file too.
  const Result r = octocd("engines", path("absent.json"));
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find("absent.json: not a readable file"), std::string::npos) << r.output;
}

}  // namespace

}  // namespace octocd_test_cli_process_engines
