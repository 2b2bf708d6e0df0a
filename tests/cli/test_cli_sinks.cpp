// The sinks of untrusted text (issue 68, docs/robustness.md "Sinks"): the terminal (control
// characters as visible escapes), CSV (no formula), every value and line bounded. The
// Markdown/HTML sinks of the report: tests/report/test_report_sinks.py.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>

#include <nlohmann/json.hpp>

#include "support/cli_run.hpp"
#include "octocd/text.hpp"

// This file's own names (its tests compile in unity batches with the folder's other files).
namespace octocd_test_cli_sinks {

namespace fs = std::filesystem;
using octocd::test::bin;
using octocd::test::Result;
using octocd::test::run;
using octocd::test::source_dir;

namespace {

constexpr const char* kFailingScene = R"({
  "name": "box-in-box", "domain": {"min": [-2, -2, -2], "max": [2, 2, 2]},
  "gravity": [0, 0, 0], "walls": "none", "frames": 20, "response": {"overlap": "paper"},
  "groups": [
    {"name": "big", "shape": {"box": [0.5, 0.5, 0.5]}, "count": 1, "mass": 1.0, "positions": [[0, 0, 0]]},
    {"name": "small", "shape": {"box": [0.1, 0.1, 0.1]}, "count": 1, "mass": 1.0, "positions": [[0.05, 0.2, 0.0]]}
  ]})";

class Sinks : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() /
           ("octocd-sinks-" + std::to_string(::getpid()) + "-" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  fs::path dir_;
};

bool has_control_byte(const std::string& s) {
  for (const char c : s)
    if ((static_cast<unsigned char>(c) < 0x20 && c != '\n') || c == 0x7F) return true;
  return false;
}

}  // namespace

TEST(SinkText, PrintableEscapesControlCharactersAndBoundsLongValues) {
  EXPECT_EQ(octocd::printable("a\x1b]0;t\x07\rb"), "a\\x1b]0;t\\x07\\x0db");
  const std::string big(16u << 20, 'A');
  const std::string shown = octocd::printable(big);
  EXPECT_LE(shown.size(), octocd::kMaxShownBytes + 32);
  EXPECT_NE(shown.find("... (16,777,216 bytes)"), std::string::npos);
  // A cut never splits a UTF-8 sequence (é is 2 bytes): no \xNN from the cut itself.
  const std::string accents = std::string(4095, 'x') + "\xc3\xa9\xc3\xa9";
  EXPECT_EQ(octocd::printable(accents).find("\\x"), std::string::npos);
  // A line keeps its head and its tail (what is allowed).
  const std::string line = "head " + big + " allowed: a name";
  const std::string l = octocd::printable_line(line);
  EXPECT_LE(l.size(), octocd::kMaxLineBytes + 64);
  EXPECT_EQ(l.rfind("allowed: a name"), l.size() - 15);
  EXPECT_EQ(l.rfind("head ", 0), 0u);
  EXPECT_EQ(octocd::grouped_count(1000), "1,000");
  EXPECT_EQ(octocd::grouped_count(999), "999");
}

TEST(SinkText, CsvTextCellsNeverBeginAFormulaAndNumbersStayNumbers) {
  EXPECT_EQ(octocd::csv_text_cell("=1+1"), "'=1+1");
  EXPECT_EQ(octocd::csv_text_cell("@SUM(A1)"), "'@SUM(A1)");
  EXPECT_EQ(octocd::csv_text_cell("+cmd|' /C calc'!A0"), "'+cmd|' /C calc'!A0");
  EXPECT_EQ(octocd::csv_text_cell("-x"), "'-x");
  EXPECT_EQ(octocd::csv_text_cell("\tA"), "'\tA");
  EXPECT_EQ(octocd::csv_text_cell("\rA"), "'\rA");
  EXPECT_EQ(octocd::csv_text_cell("-3.5"), "-3.5");
  EXPECT_EQ(octocd::csv_text_cell("+2e-3"), "+2e-3");
  EXPECT_EQ(octocd::csv_text_cell("-1E+10"), "-1E+10");
  EXPECT_EQ(octocd::csv_text_cell("-"), "'-");
  EXPECT_EQ(octocd::csv_text_cell("bunny"), "bunny");
  EXPECT_EQ(octocd::csv_text_cell(""), "");
}

// Before: `bench` printed a sweep's name raw: an OSC title sequence and a screen clear ran.
TEST_F(Sinks, BenchShowsASweepNamesEscapesVisibly) {
  fs::copy_file(source_dir() + "/tests/data/spheres-drop.json", dir_ / "spheres-drop.json");
  const std::string sweep = (dir_ / "sweep.json").string();
  std::ofstream(sweep) << R"({"name": "x\u001b]0;pwned\u0007\u001b[2J\rPASS", "scenes": ["spheres-drop.json"],)"
                       << R"( "frames": 2, "engines": ["cpu"], "repeat": 1})";
  const Result r = run("timeout -k 5 120 " + bin() + " bench " + sweep + " -o " + (dir_ / "o.json").string());
  EXPECT_EQ(r.code, 0) << r.output;
  EXPECT_FALSE(has_control_byte(r.output)) << r.output;
  EXPECT_NE(r.output.find("bench x\\x1b]0;pwned\\x07\\x1b[2J\\x0dPASS:"), std::string::npos) << r.output;
}

// Before: an --expect reason reached the terminal raw (escape, conceal, a carriage return
// rewriting the line), and a 60 MiB reason gave a 63 MB "expected" line.
TEST_F(Sinks, ExpectReasonsAreEscapedAndBounded) {
  const std::string scene = (dir_ / "box-in-box.json").string();
  std::ofstream(scene) << kFailingScene;
  const std::string args = " --frames 20 --every 5 --against none";
  for (const std::string& reason :
       {std::string(R"(ok\u001b[8mhidden\u001b[0m\rall validators pass)"), std::string(8u << 20, 'R')}) {
    const std::string expect = (dir_ / "e.json").string();
    std::ofstream(expect) << R"({"expectations": [{"scene": "box-in-box", "row": "non-penetration-eq14", )"
                          << R"("cause": "non-penetration-eq14", "worst": 4, "reason": ")" << reason << R"("}]})";
    const Result r = run(bin() + " validate " + scene + args + " --expect " + expect + " --json " +
                         (dir_ / "o.json").string());
    EXPECT_EQ(r.code, 0) << r.output.substr(0, 4000);
    EXPECT_FALSE(has_control_byte(r.output)) << r.output.substr(0, 4000);
    EXPECT_LT(r.output.size(), 64u << 10) << "an unbounded line";
    EXPECT_LT(fs::file_size(dir_ / "o.json"), 256u << 10) << "an unbounded --json";
    if (reason.size() < 100)
      EXPECT_NE(r.output.find("reason: ok\\x1b[8mhidden\\x1b[0m\\x0dall validators pass"), std::string::npos)
          << r.output;
    else
      EXPECT_NE(r.output.find("RRR... (8,388,608 bytes)"), std::string::npos) << r.output.substr(0, 6000);
  }
}

// Before: a 16 MiB name in an input gave a 16 MB error line. Now the line keeps its head
// and its tail, with the length said.
TEST_F(Sinks, AnErrorLineNamingAHugeValueIsBounded) {
  const std::string scene = (dir_ / "s.json").string();
  std::ofstream(scene) << R"({"name": "s", ")" << std::string(16u << 20, 'K') << R"(": 1})";
  const Result r = run(bin() + " validate " + scene + " --frames 1");
  EXPECT_EQ(r.code, 2) << r.output.substr(0, 2000);
  EXPECT_LT(r.output.size(), 32u << 10) << r.output.substr(0, 2000);
  EXPECT_NE(r.output.find("bytes)"), std::string::npos) << r.output.substr(0, 2000);
}

// Before: a scene file name with a newline forged a line ("pass ...") in the nightly's output.
TEST_F(Sinks, TheNightlyShowsAFileNamesNewlineEscaped) {
  const fs::path scene = dir_ / "a\npass     forged (1 frames, 0.0 s)\x1b[2J.json";
  fs::copy_file(source_dir() + "/tests/data/spheres-drop.json", scene);
  const fs::path out = dir_ / "out";
  const Result r = run("OCTOCD_BIN=" + bin() + " timeout -k 5 300 bash " + source_dir() +
                       "/scripts/nightly.sh --matrix none --frames 2 --expect none --out " + out.string() + " '" +
                       scene.string() + "'");
  EXPECT_EQ(r.output.find("\npass     forged"), std::string::npos) << r.output;
  EXPECT_FALSE(has_control_byte(r.output)) << r.output;
  EXPECT_NE(r.output.find("a\\x0apass     forged (1 frames, 0.0 s)\\x1b[2J"), std::string::npos) << r.output;
}

// Before: a --junit that failed under a file-size limit was said to be unchanged, then held
// a runtime-failure case written after the message. Now it is left as the message says.
TEST_F(Sinks, AJunitThatCouldNotBeWrittenIsLeftAsTheMessageSays) {
  const std::string scene = (dir_ / "box-in-box.json").string();
  std::ofstream(scene) << kFailingScene;
  const std::string xml = (dir_ / "j.xml").string();
  std::ofstream(xml) << "OLD";
  // 2 KiB: the whole JUnit (about 6 KB) fails; a runtime-failure case alone would fit.
  const Result r = run("sh -c \"ulimit -f 2; exec " + bin() + " validate " + scene +
                       " --frames 20 --every 5 --against none --junit " + xml + "\"");
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_NE(r.output.find("--junit: " + xml + ": writing failed: File too large (EFBIG)"), std::string::npos)
      << r.output;
  EXPECT_NE(r.output.find(xml + " is unchanged"), std::string::npos) << r.output;
  std::ifstream in(xml);
  const std::string kept((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  EXPECT_EQ(kept, "OLD") << "the file the message calls unchanged was rewritten";
}

TEST_F(Sinks, AJsonIsWrittenWhenTheJunitCannotBe) {
  const std::string scene = (dir_ / "box-in-box.json").string();
  std::ofstream(scene) << kFailingScene;
  // A --junit name of 250 bytes passes the output checks, but its temporary file beside it
  // (NAME.tmp.XXXXXX) is longer than a file name may be: writing it fails (ENAMETOOLONG).
  const std::string xml = (dir_ / std::string(250, 'j')).string();
  const std::string json = (dir_ / "o.json").string();
  const Result r = run(bin() + " validate " + scene + " --frames 20 --every 5 --against none --junit " + xml +
                       " --json " + json);
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_NE(r.output.find("--junit: " + xml + ": cannot create a temporary file in its folder"), std::string::npos)
      << r.output;
  EXPECT_NE(r.output.find(xml + " is unchanged"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("octocd: --junit " + xml + " was not written (above); --json " + json +
                          " holds the whole verdict (written)"),
            std::string::npos)
      << r.output;
  EXPECT_FALSE(fs::exists(xml));
  EXPECT_NE(r.output.find("VALIDATION FAILED"), std::string::npos) << r.output;
  // The verdict is whole in --json: its rows are those of the same run with a --junit it could write.
  const std::string good = (dir_ / "good.json").string();
  const Result g = run(bin() + " validate " + scene + " --frames 20 --every 5 --against none --junit " +
                       (dir_ / "j.xml").string() + " --json " + good);
  ASSERT_EQ(g.code, 3) << g.output;
  const auto rows = [](const std::string& path) {
    std::ifstream in(path);
    EXPECT_TRUE(in.good()) << path << " was not written";
    const nlohmann::json doc = nlohmann::json::parse(in, nullptr, false);
    EXPECT_TRUE(doc.is_object() && doc.contains("rows")) << path;
    nlohmann::json out = doc.is_object() ? doc.value("rows", nlohmann::json::array()) : nlohmann::json::array();
    for (auto& row : out) row.erase("seconds");  // timings differ between runs
    return out;
  };
  const nlohmann::json kept = rows(json), whole = rows(good);
  EXPECT_FALSE(kept.empty());
  EXPECT_EQ(kept, whole);
}

}  // namespace octocd_test_cli_sinks
