// Untrusted inputs, round four (issue 57): the files octocd writes and the files it reads
// on a hostile user's behalf. Every output (result files, traces, XDMF sidecars, view
// pages) is made beside its target under an unpredictable name and renamed over a target
// that is absent or a regular file: a FIFO, device, folder or symbolic link there is exit 2
// naming the option and the path, before any work, and a link planted at the temporary
// name of earlier versions (PATH.tmp.PID) is never followed. Inputs are regular files
// checked before they are opened (a FIFO never blocks); a trace's scene never names a mesh
// outside the data folder and --mesh-dir; a verdict is never lost to an unwritable --view
// folder; text from a trace reaches JSON, JUnit and the terminal safely.
#include <gtest/gtest.h>
#include <fcntl.h>
#include <sys/stat.h>
#include <sys/sysmacros.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <filesystem>
#include <map>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "support/cli_run.hpp"
#include "support/external_trace.hpp"

// This file's own names (its tests compile in unity batches with the folder's other files).
namespace octocd_test_cli_hostile_files {

namespace fs = std::filesystem;

namespace {

using octocd::test::Result;
using octocd::test::bin;
using octocd::test::run;
using octocd::test::source_dir;

std::string slurp(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

void spit(const std::string& path, const std::string& text) {
  std::ofstream out(path, std::ios::binary);
  out << text;
}

class HostileFiles : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("octocd-hostile-files-" + std::to_string(::getpid()) + "-" +
                                        ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }

  std::string at(const std::string& name) const { return (dir_ / name).string(); }

  /// spheres-drop (32 bodies, contacts, every state) for `frames` frames: a trace that
  /// validate --trace-in, compare and replay read.
  std::string base_trace(int frames = 5) {
    const std::string p = at("base.h5");
    if (!fs::exists(p)) {
      const Result r = run(bin() + " run " + scene() + " --frames " + std::to_string(frames) +
                           " --state-every 1 --contacts --quiet --no-xdmf --trace " + p);
      EXPECT_EQ(r.code, 0) << r.output;
    }
    return p;
  }

  static std::string scene() { return source_dir() + "/tests/data/spheres-drop.json"; }

  /// Makes at `path` each kind of thing that is not a regular file: "fifo", "device" (a
  /// private character device with /dev/null's numbers; a FIFO when mknod is refused),
  /// "folder", "link" (to `victim`, which does not exist).
  static void plant(const std::string& kind, const std::string& path, const std::string& victim) {
    if (kind == "fifo") {
      ASSERT_EQ(::mkfifo(path.c_str(), 0600), 0);
    }
    if (kind == "device" && ::mknod(path.c_str(), S_IFCHR | 0600, makedev(1, 3)) != 0) {
      ASSERT_EQ(::mkfifo(path.c_str(), 0600), 0);
    }
    if (kind == "folder") fs::create_directories(path);
    if (kind == "link") fs::create_symlink(victim, path);
  }

  fs::path dir_;
};

// Before: a FIFO, a device, a folder or a link at an output path was renamed over (run as
// root: a device node such as /dev/null replaced by a regular file; a link replaced), or
// written through in place (--trace on a FIFO blocked forever, on a device wrote to it),
// after all the work. Now each is exit 2 naming the option, the path and the type, within
// seconds, and the thing at the path is left as it was.
TEST_F(HostileFiles, AnOutputPathThatIsNotARegularFileIsRefusedBeforeAnyWork) {
  const std::string trace = base_trace();
  struct Case {
    std::string option, command;  // command: "{}" is the target
  };
  const std::vector<Case> cases = {
      {"--summary-json", "run " + scene() + " --frames 2 --quiet --no-xdmf --summary-json {}"},
      {"--trace", "run " + scene() + " --frames 2 --quiet --no-xdmf --trace {}"},
      {"--json", "validate --trace-in " + trace + " --json {}"},
      {"--junit", "validate --trace-in " + trace + " --junit {}"},
      {"--write-expect", "validate --trace-in " + trace + " --write-expect {}"},
      {"--json", "compare " + trace + " " + trace + " --json {}"},
      {"--json", "replay " + trace + " --broadphase octree --json {}"},
      {"-o", "bench " + source_dir() + "/tests/data/bench-small-scaling.json --quiet -o {}"},
  };
  int n = 0;
  for (const Case& c : cases)
    for (const std::string kind : {"fifo", "device", "folder", "link"}) {
      const std::string target = at("out-" + std::to_string(n++)), victim = at("victim-" + std::to_string(n));
      plant(kind, target, victim);
      std::string command = c.command;
      command.replace(command.find("{}"), 2, target);
      const auto t0 = std::chrono::steady_clock::now();
      const Result r = run("timeout -k 5 60 " + bin() + " " + command);
      const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
      EXPECT_EQ(r.code, 2) << kind << ": " << command << "\n" << r.output;
      EXPECT_NE(r.output.find(c.option + ": " + target + ": "), std::string::npos) << command << "\n" << r.output;
      EXPECT_NE(r.output.find("not a regular file; allowed: a new file or a regular file"), std::string::npos)
          << r.output;
      EXPECT_LT(s, 20.0) << command;
      EXPECT_FALSE(fs::exists(victim)) << command << ": the link was followed";
      struct stat st {};
      ASSERT_EQ(::lstat(target.c_str(), &st), 0) << command << ": the target was removed";
      EXPECT_FALSE(S_ISREG(st.st_mode)) << command << ": the " << kind << " was replaced by a regular file";
    }
}

// Before: result files were made as PATH.tmp.PID and traces staged as T.h5.tmp.PID, names
// anyone can predict: a link planted there was followed (O_CREAT|O_TRUNC through it, or
// HDF5's truncating create), writing the victim. The shell's PID is the PID octocd runs
// under (exec), so the link below sits at exactly that old name.
TEST_F(HostileFiles, ALinkPlantedAtThePredictableTemporaryNameIsNotFollowed) {
  const std::string trace = base_trace();
  const std::vector<std::pair<std::string, std::string>> cases = {
      {"s.json", "run " + scene() + " --frames 2 --quiet --no-xdmf --summary-json " + at("s.json")},
      {"t.h5", "run " + scene() + " --frames 2 --quiet --trace " + at("t.h5")},
      {"t.h5.xmf", "run " + scene() + " --frames 2 --quiet --trace " + at("t.h5")},
      {"v.json", "validate --trace-in " + trace + " --json " + at("v.json")},
      {"v.xml", "validate --trace-in " + trace + " --junit " + at("v.xml")},
      {"c.json", "compare " + trace + " " + trace + " --json " + at("c.json")},
  };
  for (const auto& [name, command] : cases) {
    const std::string victim = at("victim-" + name);
    spit(victim, "precious\n");
    const Result r = run("sh -c 'ln -s " + victim + " " + at(name) + ".tmp.$$; exec " + bin() + " " + command + "'");
    EXPECT_TRUE(r.code == 0 || r.code == 3) << command << "\n" << r.output;  // 3: a verdict with a failure
    EXPECT_EQ(slurp(victim), "precious\n") << command << ": the planted link was followed";
    struct stat st {};
    ASSERT_EQ(::lstat(at(name).c_str(), &st), 0) << name;
    EXPECT_TRUE(S_ISREG(st.st_mode)) << name;
    EXPECT_GT(st.st_size, 0) << name;
    for (const auto& e : fs::directory_iterator(dir_)) {  // only the planted links are left
      if (e.path().filename().string().find(".tmp.") != std::string::npos) {
        EXPECT_TRUE(fs::is_symlink(e.symlink_status())) << e.path();
      }
    }
    fs::remove(at(name));
    for (const auto& e : fs::directory_iterator(dir_))
      if (fs::is_symlink(e.symlink_status())) fs::remove(e.path());
  }
}

// Before: the view page was written in place with std::ofstream: a link at its name (to a
// victim) was followed and the victim overwritten; a FIFO there blocked forever. Now the
// page is made beside it and renamed: a link, FIFO or folder at its name is exit 2 naming
// it, and the -o folder itself may not be a link, a FIFO or a file.
TEST_F(HostileFiles, TheViewPageIsNeverWrittenInPlace) {
  const std::string trace = base_trace();
  fs::create_directories(at("pages"));
  const std::string page = at("pages/view-f1-all.html");
  spit(at("victim"), "precious\n");
  fs::create_symlink(at("victim"), page);
  Result r = run("timeout -k 5 60 " + bin() + " view " + trace + " --frame 1 -o " + at("pages"));
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find(page + ": a symbolic link"), std::string::npos) << r.output;
  EXPECT_EQ(slurp(at("victim")), "precious\n");
  fs::remove(page);
  ASSERT_EQ(::mkfifo(page.c_str(), 0600), 0);
  r = run("timeout -k 5 60 " + bin() + " view " + trace + " --frame 1 -o " + at("pages"));
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find(page + ": a FIFO"), std::string::npos) << r.output;
  fs::remove(page);
  r = run(bin() + " view " + trace + " --frame 1 -o " + at("pages"));
  EXPECT_EQ(r.code, 0) << r.output;
  EXPECT_TRUE(fs::is_regular_file(fs::symlink_status(page)));
  // The folder: a link to another folder is refused before the trace is read.
  fs::create_symlink(at("pages"), at("pages-link"));
  r = run(bin() + " view " + trace + " --frame 1 -o " + at("pages-link"));
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find("-o " + at("pages-link") + ": a symbolic link"), std::string::npos) << r.output;
}

// Before: bench_validation --json opened its file in place (std::ofstream): a symbolic link
// there was followed and its target overwritten, a FIFO blocked it forever. Now the file is
// checked before any work (exit 2 naming it) and written at the end as every octocd output
// (octocd/atomic_file.hpp: a temporary beside it renamed over a regular file).
// (bench_gpu_broadphase --json does the same; it needs a CUDA device, so it is not run here.)
TEST_F(HostileFiles, BenchValidationWritesItsJsonAsEveryOutput) {
  const std::string tool = OCTOCD_TEST_BENCH_VALIDATION;
  const std::string args = " --lattice --bodies 64 --reps 1 --only physics --json ";
  spit(at("victim"), "precious\n");
  fs::create_symlink(at("victim"), at("link.json"));
  Result r = run("timeout -k 5 60 " + tool + args + at("link.json"));
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find("--json: " + at("link.json") + ": a symbolic link"), std::string::npos) << r.output;
  EXPECT_EQ(r.output.find("physics "), std::string::npos) << "refused before any work: " << r.output;
  EXPECT_EQ(slurp(at("victim")), "precious\n");
  ASSERT_EQ(::mkfifo(at("fifo.json").c_str(), 0600), 0);
  r = run("timeout -k 5 60 " + tool + args + at("fifo.json"));
  EXPECT_EQ(r.code, 2) << r.output;  // before: 124, blocked in open() until the timeout
  EXPECT_NE(r.output.find("--json: " + at("fifo.json") + ": a FIFO"), std::string::npos) << r.output;
  // A regular file is replaced whole: one verdict document, no temporary left beside it.
  spit(at("out.json"), "old\n");
  r = run("timeout -k 5 120 " + tool + args + at("out.json"));
  EXPECT_EQ(r.code, 0) << r.output;
  const std::string text = slurp(at("out.json"));
  ASSERT_FALSE(text.empty());
  EXPECT_EQ(text.find("old"), std::string::npos) << text;
  EXPECT_EQ(std::count(text.begin(), text.end(), '\n'), 1) << text;
  EXPECT_TRUE(nlohmann::json::accept(text)) << text;
  for (const auto& e : fs::directory_iterator(dir_))
    EXPECT_EQ(e.path().filename().string().find(".tmp."), std::string::npos) << e.path();
}

// bench_validation's scene modes (no --lattice) scale a scene file. Before, a scene that
// was not there (the default one, the source tree's, seen from a binary run elsewhere)
// ended on an uncaught JSON parse error (abort); now it is exit 2 naming the file and what
// the mode needs, as is a file that is not a scene and a bad option value; a scene that
// is there is judged.
TEST_F(HostileFiles, BenchValidationSceneModesRunOrSayWhatTheyNeed) {
  const std::string tool = OCTOCD_TEST_BENCH_VALIDATION;
  const std::string args = " --bodies 200 --reps 1 --warmup 1 --only physics";
  Result r = run("timeout -k 5 60 " + tool + " " + at("missing.json") + args);
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find(at("missing.json")), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("--lattice"), std::string::npos) << r.output;
  EXPECT_EQ(r.output.find("terminate"), std::string::npos) << r.output;
  spit(at("not-json.json"), "{ not json");
  r = run("timeout -k 5 60 " + tool + " " + at("not-json.json") + args);
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find(at("not-json.json")), std::string::npos) << r.output;
  r = run("timeout -k 5 60 " + tool + " --bodies many --lattice");
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find("--bodies: 'many'"), std::string::npos) << r.output;
  r = run("timeout -k 5 120 " + tool + " " + source_dir() + "/datasets/scenes/boxes-uniform-10k.json" + args);
  EXPECT_EQ(r.code, 0) << r.output;
  EXPECT_NE(r.output.find("physics "), std::string::npos) << r.output;
}

// Before: --expect and --merge opened their files with std::ifstream: a FIFO blocked
// forever (no writer) and /dev/zero was read until memory ran out. Now each input is
// opened without blocking and checked on its descriptor: exit 2 naming the option, the
// path and the type, at once.
TEST_F(HostileFiles, AnInputThatIsNotARegularFileIsRefusedWithoutBlocking) {
  const std::string trace = base_trace();
  ASSERT_EQ(::mkfifo(at("fifo.json").c_str(), 0600), 0);
  ASSERT_EQ(::mknod(at("zero").c_str(), S_IFCHR | 0600, makedev(1, 5)), 0);  // /dev/zero's numbers
  const std::vector<std::pair<std::string, std::string>> cases = {
      {"--expect", "validate --trace-in " + trace + " --expect {}"},
      {"--merge", "validate --merge {}"},
  };
  for (const auto& [option, command] : cases)
    for (const std::string& input : {at("fifo.json"), at("zero")}) {
      std::string c = command;
      c.replace(c.find("{}"), 2, input);
      const auto t0 = std::chrono::steady_clock::now();
      const Result r = run("timeout -k 5 30 " + bin() + " " + c);
      EXPECT_EQ(r.code, 2) << c << "\n" << r.output;
      EXPECT_NE(r.output.find((option.empty() ? "" : option + ": ") + input + ": not a regular file (a "),
                std::string::npos)
          << c << "\n" << r.output;
      EXPECT_LT(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(), 20.0) << c;
    }
}

// Before: a trace's `scene` attribute could name any mesh file (an absolute path, `..`),
// which validate --trace-in and view then stat, read and drew (its vertices on the page).
// Now a trace's meshes come from the data dir or from --mesh-dir (default: the trace's
// folder) only, symbolic links resolved; a mesh named elsewhere is exit 2 naming the key,
// the mesh and --mesh-dir, and --mesh-dir lets the user say where the meshes are.
TEST_F(HostileFiles, ATraceSceneNamesNoMeshOutsideTheMeshDir) {
  fs::create_directories(at("secret"));
  fs::create_directories(at("traces"));
  const std::string tetra = "v 0 0 0\nv 0.2 0 0\nv 0 0.2 0\nv 0 0 0.2\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n";
  spit(at("secret/private.obj"), tetra);
  const auto trace_naming = [&](const std::string& name, const std::string& mesh) {
    octocd::test::Trace t;
    t.string_attrs["scene"] = R"({"name": "m", "domain": {"min": [-1, -2, -1], "max": [1, 1, 1]}, "walls": "none",
        "gravity": [0, 0, 0], "groups": [
          {"name": "floor", "shape": {"mesh": ")" + mesh + R"(", "scale": 0.2}, "count": 1, "mass": 0},
          {"name": "g", "shape": {"mesh": ")" + mesh + R"(", "scale": 0.2}, "count": 2,
           "layout": {"type": "grid", "spacing": 0.5}}]})";
    const std::string path = at("traces/" + name);
    t.write(path);
    return path;
  };
  for (const std::string& mesh : {at("secret/private.obj"), std::string("../secret/private.obj")}) {
    const std::string trace = trace_naming("outside.h5", mesh);
    for (const std::string& cmd : {"validate --trace-in " + trace, "view " + trace + " --frame 1 -o " + at("pages")}) {
      const Result r = run("timeout -k 5 60 " + bin() + " " + cmd);
      EXPECT_EQ(r.code, 2) << cmd << "\n" << r.output;
      EXPECT_NE(r.output.find("groups[0].shape.mesh: mesh \"" + mesh + "\" named by the scene inside the trace lies "
                              "outside --mesh-dir"),
                std::string::npos)
          << cmd << "\n" << r.output;
      EXPECT_NE(r.output.find("--mesh-dir DIR"), std::string::npos) << r.output;
    }
    // Saying where the meshes are lets the same trace be judged.
    const Result ok = run(bin() + " validate --trace-in " + trace + " --mesh-dir " + at("secret"));
    EXPECT_EQ(ok.output.find("--mesh-dir"), std::string::npos) << ok.output;
    EXPECT_TRUE(ok.code == 0 || ok.code == 3) << ok.output;
  }
  // A link beside the trace that leads out of its folder is outside too.
  fs::create_symlink(at("secret/private.obj"), at("traces/link.obj"));
  const Result r = run(bin() + " validate --trace-in " + trace_naming("link.h5", "link.obj"));
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find("lies outside --mesh-dir " + at("traces")), std::string::npos) << r.output;
  // A mesh beside the trace is found there by default.
  spit(at("traces/beside.obj"), tetra);
  const Result beside = run(bin() + " validate --trace-in " + trace_naming("beside.h5", "beside.obj"));
  EXPECT_TRUE(beside.code == 0 || beside.code == 3) << beside.output;
}

/// The test trace (external_trace.hpp) with frame 2's normal flipped: one failing example
/// (contact-geometry, pair (1, 2)) that --view draws.
std::string flipped_trace(const std::string& path, const std::map<std::string, std::string>& attrs = {}) {
  octocd::test::Trace t;
  t.normal[3] = 1.0f;
  t.string_attrs = attrs;
  t.write(path);
  return path;
}

// Before: a --view folder that refused the page (EACCES) ended validate with "runtime
// failure" and exit 1 before the table, the --json and the --junit were written: the
// verdict was lost. Now the verdict is printed and written, and exit 1 names the folder.
TEST_F(HostileFiles, AnUnwritableViewFolderLosesNoVerdict) {
  // /sys refuses new files to everyone, root included.
  const int probe = ::open("/sys/octocd-probe", O_WRONLY | O_CREAT | O_EXCL, 0600);
  if (probe >= 0) {
    ::close(probe);
    ::unlink("/sys/octocd-probe");
  }
  if (!fs::is_directory("/sys") || probe >= 0) GTEST_SKIP() << "no unwritable folder /sys here";
  const std::string trace = flipped_trace(at("flipped.h5"));
  const Result r = run(bin() + " validate --trace-in " + trace + " --view /sys --json " + at("v.json") + " --junit " +
                       at("v.xml"));
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_NE(r.output.find("VALIDATION FAILED"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("--view /sys: a page cannot be written"), std::string::npos) << r.output;
  const nlohmann::json doc = nlohmann::json::parse(slurp(at("v.json")), nullptr, false);
  ASSERT_TRUE(doc.is_object()) << slurp(at("v.json"));
  bool failed = false;
  for (const auto& row : doc["rows"])
    if (row["name"] == "contact-geometry") failed = row["verdict"] == "fail";
  EXPECT_TRUE(failed) << doc.dump(1);
  EXPECT_NE(slurp(at("v.xml")).find("<failure message="), std::string::npos);
}

/// Whether `text` is well-formed UTF-8 (RFC 3629).
bool valid_utf8(const std::string& text) {
  for (std::size_t i = 0; i < text.size();) {
    const auto c = static_cast<unsigned char>(text[i]);
    const std::size_t n = c < 0x80 ? 1 : c >= 0xC2 && c <= 0xDF ? 2 : c >= 0xE0 && c <= 0xEF ? 3 : c >= 0xF0 && c <= 0xF4 ? 4 : 0;
    if (n == 0 || i + n > text.size()) return false;
    for (std::size_t k = 1; k < n; ++k)
      if ((static_cast<unsigned char>(text[i + k]) & 0xC0) != 0x80) return false;
    i += n;
  }
  return true;
}

// Before: an engine name holding bytes that are not UTF-8 ended validate --json with
// nlohmann's "[json.exception.type_error.316] invalid UTF-8 byte" (exit 1, the verdict
// lost), the JUnit file was not UTF-8 (invalid XML), and an escape sequence in it reached
// the terminal raw. Now the JSON and JUnit are written (valid UTF-8) and the terminal gets
// the name with its control characters as \xNN. The trace's file name too.
TEST_F(HostileFiles, TextThatIsNotUtf8OrHoldsControlCharactersIsWrittenSafely) {
  const std::string engine = "eng\xff\xfe\x1b[31mred\x07";
  const std::string trace = flipped_trace(at("t\xff\x1b[2J.h5"), {{"engine", engine}});
  const Result r = run(bin() + " validate --trace-in '" + trace + "' --json " + at("v.json") + " --junit " +
                       at("v.xml"));
  EXPECT_EQ(r.code, 3) << r.output;
  EXPECT_EQ(r.output.find("type_error"), std::string::npos) << r.output;
  EXPECT_EQ(r.output.find('\x1b'), std::string::npos) << "a raw escape reached the terminal";
  EXPECT_EQ(r.output.find('\x07'), std::string::npos);
  EXPECT_NE(r.output.find("engine 'eng\\xff\\xfe\\x1b[31mred\\x07'"), std::string::npos) << r.output;
  const std::string json = slurp(at("v.json")), xml = slurp(at("v.xml"));
  EXPECT_TRUE(nlohmann::json::parse(json, nullptr, false).is_object()) << json;
  EXPECT_TRUE(valid_utf8(json));
  EXPECT_TRUE(valid_utf8(xml)) << xml;
  EXPECT_EQ(xml.find('\x1b'), std::string::npos) << xml;
  EXPECT_NE(xml.find("<testsuite"), std::string::npos) << xml;
  // trace-summary and compare print the trace's text escaped as well.
  for (const std::string& cmd : {"trace-summary '" + trace + "'", "trace-summary --json '" + trace + "'"}) {
    const Result s = run(bin() + " " + cmd);
    EXPECT_EQ(s.output.find('\x1b'), std::string::npos) << cmd << "\n" << s.output;
  }
}

// Before: an angular velocity of 3e38 rad/s in a version 2 trace was accepted, and the
// physics rows computed infinite energies from it. Now the reader refuses it, naming the
// dataset, the frame, the body and the range, as it refuses a velocity of 3e38 m/s.
TEST_F(HostileFiles, ANonPhysicalAngularVelocityIsRefusedNamingTheDataset) {
  octocd::test::Trace t = octocd::test::Trace::make_v2();
  t.angular_velocity[3 * (2 * octocd::test::Trace::kBodies + 2) + 1] = 3e38f;  // row 2, body 2, y
  t.write(at("spin.h5"));
  for (const std::string& cmd : {"validate --trace-in " + at("spin.h5"), "view " + at("spin.h5") + " --frame 2 -o " + at("p")}) {
    const Result r = run(bin() + " " + cmd);
    EXPECT_EQ(r.code, 2) << cmd << "\n" << r.output;
    EXPECT_NE(r.output.find("/states/angular_velocity: frame "), std::string::npos) << r.output;
    EXPECT_NE(r.output.find("body 2: 3e+38; "), std::string::npos) << r.output;
    EXPECT_NE(r.output.find("allowed: |angular velocity| <= 1e+06 rad/s per axis"), std::string::npos) << r.output;
  }
}

// Before: `scripts/nightly.sh --frames` (no value) ended through bash's ${2:?} with exit 1
// and "line 84: 2: --frames needs a number". Now every option without its value is exit 2
// in the project's form, naming the option.
TEST(NightlyOptions, AnOptionWithoutItsValueIsExitTwoNamingIt) {
  for (const std::string option : {"--frames", "--every", "--tolerance", "--matrix", "--out"}) {
    const Result r = run("bash " + source_dir() + "/scripts/nightly.sh " + option);
    EXPECT_EQ(r.code, 2) << option << "\n" << r.output;
    EXPECT_NE(r.output.find("nightly: " + option + ": missing value; allowed: "), std::string::npos) << r.output;
  }
}

}  // namespace

}  // namespace octocd_test_cli_hostile_files
