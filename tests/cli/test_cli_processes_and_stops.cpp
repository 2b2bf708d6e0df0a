// Processes and stops (issue 79, items 1, 2 and 7; docs/bring-your-engine.md, "The
// invocation"). Item 1: the small Python engine of tests/data/process_engines/engines.json,
// given its `escape` setting, first starts a grandchild that leaves the engine's tree as
// far as a process can (a double fork and setsid(): a new session and process group,
// re-parented) and writes its pid. That grandchild, asserted by pid, has ended once octocd
// returns after a run that succeeds, fails or times out, after SIGTERM to octocd, after
// octocd is killed outright (SIGKILL), and after `octocd engines` ran a check that starts
// one. Item 2: a stopped `run --worlds` of a process engine leaves no engine process and no
// octocd-* folder in TMPDIR; a stopped `validate --determinism` keeps its finished rows and
// says so. Item 7: a command that cannot start is unavailable with the reason (errno), a
// timeout is stated as set, NULs are shown as \x00, a check's code (python3 -c CODE) is run, never
// taken for a missing file.
#include <fcntl.h>
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/syscall.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <regex>
#include <string>
#include <vector>

#include "support/cli_run.hpp"
#include "support/wait_event.hpp"

// This file's own names (its tests compile in unity batches with the folder's other files).
namespace octocd_test_cli_processes_and_stops {

namespace fs = std::filesystem;
using octocd::test::Result;

namespace {

std::string data(const std::string& name) {
  return (fs::path(octocd::test::source_dir()) / "tests/data/process_engines" / name).string();
}

/// The process id written in `file` (0 when none).
pid_t pid_in(const fs::path& file) {
  pid_t pid = 0;
  std::ifstream(file) >> pid;
  return pid;
}

/// Waits, for at most `limit`, until the process `pid` (not a child of this one) has
/// ended: its pidfd turns readable (pidfd_open(2)); true at once when no such process.
bool ended_within(pid_t pid, std::chrono::milliseconds limit) {
  const int fd = static_cast<int>(::syscall(SYS_pidfd_open, pid, 0));
  if (fd < 0) return errno == ESRCH;
  const bool ended = octocd::test::readable_before(fd, std::chrono::steady_clock::now() + limit);
  ::close(fd);
  return ended;
}

/// Whether the process `pid` has ended now (gone, or a zombie about to be reaped).
bool ended_now(pid_t pid) { return ended_within(pid, std::chrono::milliseconds(0)); }

class ProcessTree : public ::testing::Test {
 protected:
  void SetUp() override {
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    dir_ = fs::temp_directory_path() / (std::string("octocd-tree-") + info->name() + "-" + std::to_string(::getpid()));
    fs::remove_all(dir_);
    fs::create_directories(dir_ / "tmp");
  }
  void TearDown() override {
    // A grandchild a failing case left behind is not left running.
    for (const auto& e : fs::directory_iterator(dir_))
      if (e.path().extension() == ".pid")
        if (const pid_t p = pid_in(e.path()); p > 0 && !ended_now(p)) ::kill(p, SIGKILL);
    fs::remove_all(dir_);
  }

  /// `octocd --engines-file FILE ARGS` with TMPDIR = the test's tmp folder.
  Result octocd(const std::string& args, const std::string& engines = data("engines.json")) const {
    return octocd::test::run("TMPDIR=" + (dir_ / "tmp").string() + " " + octocd::test::bin() + " --engines-file " +
                             engines + " " + args);
  }
  /// `run` of the boxes scene on `engine`, its grandchild's pid written to `pid_file`.
  Result run_escaping(const std::string& engine, const fs::path& pid_file) const {
    return octocd("run " + data("boxes.json") + " --engine " + engine + " --frames 20 --quiet --" + engine +
                  " escape=" + pid_file.string());
  }

  fs::path dir_;
};

TEST_F(ProcessTree, ASetsidGrandchildEndsWithARunThatSucceedsFailsOrTimesOut) {
  struct Case {
    const char* engine;
    int code;
    const char* says;
  };
  for (const Case& c : {Case{"pyboxes", 0, ""}, Case{"pycrash", 1, "exited with code 3"},
                        Case{"pyhang", 1, "ran past its timeout_s of 1 s and was stopped after 1\\.[0-9]+ s"}}) {
    SCOPED_TRACE(c.engine);
    const fs::path pid_file = dir_ / (std::string(c.engine) + ".pid");
    const Result r = run_escaping(c.engine, pid_file);
    EXPECT_EQ(r.code, c.code) << r.output;
    EXPECT_TRUE(std::regex_search(r.output, std::regex(c.says))) << r.output;
    const pid_t grandchild = pid_in(pid_file);
    ASSERT_GT(grandchild, 0) << r.output;
    EXPECT_TRUE(ended_now(grandchild)) << "the setsid() grandchild " << grandchild << " outlived octocd";
    EXPECT_TRUE(fs::is_empty(dir_ / "tmp"));
  }
}

/// The processes whose command line names `text` (the engines started for a request in the
/// test's TMPDIR, and their forks), from /proc.
std::vector<pid_t> processes_naming(const std::string& text) {
  std::vector<pid_t> out;
  for (const auto& e : fs::directory_iterator("/proc")) {
    const std::string name = e.path().filename().string();
    if (name.find_first_not_of("0123456789") != std::string::npos) continue;
    std::ifstream in(e.path() / "cmdline", std::ios::binary);
    const std::string cmd((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    if (cmd.find(text) != std::string::npos) out.push_back(static_cast<pid_t>(std::stol(name)));
  }
  return out;
}

/// `octocd --engines-file engines.json ARGS` on `pystop` (hangs until stopped), started in
/// the background with its stderr in dir/stderr.txt, `ready` and `escape` items added; returns
/// octocd's pid once an engine and its grandchild run (their pids in `engine`, `grandchild`).
pid_t start_hanging(const fs::path& dir, std::vector<std::string> args, pid_t& engine, pid_t& grandchild) {
  const fs::path ready = dir / "engine.pid", escaped = dir / "grandchild.pid";
  args.insert(args.end(), {"--pystop", "ready=" + ready.string(), "--pystop", "escape=" + escaped.string()});
  args.insert(args.begin(), {octocd::test::bin(), "--engines-file", data("engines.json")});
  const pid_t pid = ::fork();
  if (pid == 0) {
    ::setenv("TMPDIR", (dir / "tmp").c_str(), 1);
    const int err = ::open((dir / "stderr.txt").c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    ::dup2(err, 2);
    std::vector<char*> argv;
    for (std::string& a : args) argv.push_back(a.data());
    argv.push_back(nullptr);
    ::execv(argv[0], argv.data());
    ::_exit(127);
  }
  // The engine writes its pid once its grandchild's is written (or octocd ended first).
  const auto ended = [pid] {
    siginfo_t info{};
    return ::waitid(P_PID, static_cast<id_t>(pid), &info, WEXITED | WNOHANG | WNOWAIT) == 0 && info.si_pid == pid;
  };
  if (!octocd::test::wait_until([&] { return fs::exists(ready) || ended(); }, {dir}, std::chrono::seconds(60)) ||
      !fs::exists(ready))
    return pid;
  engine = pid_in(ready);
  grandchild = pid_in(escaped);
  return pid;
}

pid_t start_hanging(const fs::path& dir, pid_t& engine, pid_t& grandchild) {
  return start_hanging(dir, {"validate", data("boxes.json"), "--engine", "pystop"}, engine, grandchild);
}

TEST_F(ProcessTree, SigtermToOctocdEndsTheEngineAndItsSetsidGrandchild) {
  pid_t engine = 0, grandchild = 0;
  const pid_t pid = start_hanging(dir_, engine, grandchild);
  ASSERT_GT(engine, 0);
  ASSERT_GT(grandchild, 0);
  ASSERT_FALSE(ended_now(grandchild));
  ::kill(pid, SIGTERM);
  int status = 0;
  ASSERT_TRUE(octocd::test::wait_child(pid, status, std::chrono::seconds(30)));
  ASSERT_TRUE(WIFEXITED(status));
  EXPECT_EQ(WEXITSTATUS(status), 143);
  EXPECT_TRUE(ended_now(engine));
  EXPECT_TRUE(ended_now(grandchild)) << "the setsid() grandchild " << grandchild << " outlived octocd";
  EXPECT_TRUE(fs::is_empty(dir_ / "tmp"));
}

TEST_F(ProcessTree, OctocdKilledOutrightStillTakesTheTreeWithIt) {
  // SIGKILL: octocd runs no code; its keeper (PR_SET_PDEATHSIG) ends the tree.
  pid_t engine = 0, grandchild = 0;
  const pid_t pid = start_hanging(dir_, engine, grandchild);
  ASSERT_GT(grandchild, 0);
  ::kill(pid, SIGKILL);
  int status = 0;
  ASSERT_TRUE(octocd::test::wait_child(pid, status, std::chrono::seconds(30)));
  EXPECT_TRUE(ended_within(engine, std::chrono::seconds(10)));
  EXPECT_TRUE(ended_within(grandchild, std::chrono::seconds(10)))
      << "the setsid() grandchild " << grandchild << " outlived octocd";
}

TEST_F(ProcessTree, AStoppedRunOfWorldsLeavesNoEngineAndNoTemporaryFolder) {
  // `run --worlds 6` on a process engine: the copies as separate runs, as many at once as
  // the host has threads, each in its own octocd-pystop-XXXXXX folder in TMPDIR.
  pid_t engine = 0, grandchild = 0;
  const pid_t pid =
      start_hanging(dir_, {"run", data("boxes.json"), "--engine", "pystop", "--worlds", "6", "--quiet"}, engine,
                    grandchild);
  ASSERT_GT(engine, 0);
  const std::vector<pid_t> running = processes_naming((dir_ / "tmp").string());
  ASSERT_FALSE(running.empty());
  ::kill(pid, SIGTERM);
  int status = 0;
  ASSERT_TRUE(octocd::test::wait_child(pid, status, std::chrono::seconds(30)));
  std::ifstream in(dir_ / "stderr.txt");
  const std::string err((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  ASSERT_TRUE(WIFEXITED(status)) << err;
  EXPECT_EQ(WEXITSTATUS(status), 143) << err;
  EXPECT_NE(err.find("octocd run: stopped by SIGTERM while engine 'pystop' ran"), std::string::npos) << err;
  // The copy that saw the stop ended octocd; the others' keepers end their trees as octocd goes.
  for (const pid_t p : running) EXPECT_TRUE(ended_within(p, std::chrono::seconds(10))) << "process " << p << " left";
  EXPECT_TRUE(ended_within(grandchild, std::chrono::seconds(10))) << "the grandchild " << grandchild << " left";
  std::vector<std::string> left;
  for (const auto& e : fs::directory_iterator(dir_ / "tmp")) left.push_back(e.path().filename().string());
  EXPECT_TRUE(left.empty()) << "left in TMPDIR: " << left.front();
}

TEST_F(ProcessTree, ACheckCommandsSetsidGrandchildEndsWithTheCheck) {
  // The check runs in the engines file's folder: its grandchild writes escaped.pid there.
  const std::string code =
      "import os, time\n"
      "r, w = os.pipe()\n"
      "if os.fork() == 0:\n"
      "    os.setsid()\n"
      "    if os.fork() == 0:\n"
      "        open('escaped.pid', 'w').write(str(os.getpid()))\n"
      "        os.write(w, b'1')\n"
      "        time.sleep(1000)\n"
      "    os._exit(0)\n"
      "os.read(r, 1)\n";
  std::string escaped;
  for (char c : code) escaped += c == '\n' ? std::string("\\n") : std::string(1, c);
  const fs::path file = dir_ / "engines.json";
  std::ofstream(file) << R"({"format": "octocd-engines", "version": 1, "engines": [
      {"name": "pychecktree", "description": "its check leaves a grandchild", "command": ["/usr/bin/python3"],
       "check": ["/usr/bin/python3", "-c", ")"
                      << escaped << R"("]}]})";
  const Result r = octocd("engines", file.string());
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_TRUE(std::regex_search(r.output, std::regex("pychecktree +available"))) << r.output;
  const pid_t grandchild = pid_in(dir_ / "escaped.pid");
  ASSERT_GT(grandchild, 0) << r.output;
  EXPECT_TRUE(ended_now(grandchild)) << "the check's setsid() grandchild " << grandchild << " outlived octocd";
}

// `octocd engines` stopped by SIGTERM while a check runs: the check's process ends, nothing
// is listed, one line says so, exit 143. Before: the default action (no line, killed by the
// signal). The event: the check's file written beside the engines file.
TEST_F(ProcessTree, AStoppedEnginesListingEndsItsChecksAndSaysSo) {
  const fs::path file = dir_ / "engines.json";
  std::ofstream(file) << R"J({"format": "octocd-engines", "version": 1, "engines": [
      {"name": "pyslowcheck", "command": ["/usr/bin/python3"], "check": ["/usr/bin/python3", "-c",
       "import os, time\nopen('check.pid', 'w').write(str(os.getpid()))\ntime.sleep(1000)\n"]}]})J";
  const pid_t pid = ::fork();
  if (pid == 0) {
    ::setenv("TMPDIR", (dir_ / "tmp").c_str(), 1);
    const int out = ::open((dir_ / "stdout.txt").c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    const int err = ::open((dir_ / "stderr.txt").c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    ::dup2(out, 1);
    ::dup2(err, 2);
    const std::string b = octocd::test::bin();
    ::execl(b.c_str(), b.c_str(), "--engines-file", file.c_str(), "engines", static_cast<char*>(nullptr));
    ::_exit(127);
  }
  const bool started = octocd::test::wait_until([&] { return pid_in(dir_ / "check.pid") > 0; }, {dir_},
                                                std::chrono::seconds(60));
  ::kill(pid, SIGTERM);
  int status = 0;
  ASSERT_TRUE(octocd::test::wait_child(pid, status, std::chrono::seconds(30)));
  std::ifstream in(dir_ / "stderr.txt");
  const std::string err((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  std::ifstream in_out(dir_ / "stdout.txt");
  const std::string out((std::istreambuf_iterator<char>(in_out)), std::istreambuf_iterator<char>());
  ASSERT_TRUE(started) << err;
  ASSERT_TRUE(WIFEXITED(status)) << "ended by signal " << (WIFSIGNALED(status) ? WTERMSIG(status) : 0) << ": " << err;
  EXPECT_EQ(WEXITSTATUS(status), 143) << err;
  EXPECT_TRUE(std::regex_search(
      err, std::regex("octocd engines: stopped by SIGTERM while the checks of [0-9]+ process engine\\(s\\) ran; "
                      "nothing listed\n")))
      << err;
  EXPECT_EQ(out.find("available"), std::string::npos) << out;
  EXPECT_TRUE(ended_within(pid_in(dir_ / "check.pid"), std::chrono::seconds(10))) << "the check outlived octocd";
}

TEST_F(ProcessTree, ACommandThatCannotStartIsUnavailableWithTheReason) {
  // A folder, a file without the execute bit, a relative path resolved against the engines
  // file's folder (as its other items are) that is not there.
  fs::create_directories(dir_ / "afolder");
  std::ofstream(dir_ / "notexec.sh") << "#!/bin/sh\nexit 0\n";
  const fs::path file = dir_ / "engines.json";
  std::ofstream(file) << R"({"format": "octocd-engines", "version": 1, "engines": [
      {"name": "folder", "description": "a folder", "command": [")"
                      << (dir_ / "afolder").string() << R"("]},
      {"name": "notexec", "description": "not executable", "command": ["./notexec.sh"]},
      {"name": "absent", "description": "not there", "command": ["./absent-engine"]}]})";
  const Result r = octocd("engines", file.string());
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_TRUE(std::regex_search(r.output, std::regex("folder +unavailable: command '.*afolder' cannot be run: a "
                                                     "folder \\(EISDIR\\)")))
      << r.output;
  EXPECT_TRUE(std::regex_search(r.output, std::regex("notexec +unavailable: command '.*/notexec\\.sh' cannot be run: "
                                                     "Permission denied \\(EACCES\\)")))
      << r.output;
  EXPECT_TRUE(std::regex_search(r.output, std::regex("absent +unavailable: command '.*/absent-engine' cannot be run: "
                                                     "No such file or directory \\(ENOENT\\)")))
      << r.output;
}

// A check's code is run, never taken for a file: `python3 -c "print(1/1)"` used to be
// unavailable, "check file '.../print(1/1)' is missing", without being run. A script the
// check names that is not there is still said at once.
TEST_F(ProcessTree, ACheckThatIsCodeIsRunNotTakenForAMissingFile) {
  const fs::path file = dir_ / "engines.json";
  std::ofstream(file) << R"J({"format": "octocd-engines", "version": 1, "engines": [
      {"name": "divides", "command": ["/usr/bin/python3"], "check": ["/usr/bin/python3", "-c", "print(1/1)"]},
      {"name": "halves", "command": ["/usr/bin/python3"],
       "check": ["/usr/bin/python3", "-c", "import sys; sys.exit(int(4/2))"]},
      {"name": "noscript", "command": ["/usr/bin/python3"], "check": ["/usr/bin/python3", "checks/absent.py"]},
      {"name": "parens", "command": ["/usr/bin/python3", "eng(1).py"]}]})J";
  const Result r = octocd("engines", file.string());
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_TRUE(std::regex_search(r.output, std::regex("divides +available"))) << r.output;
  EXPECT_TRUE(std::regex_search(r.output, std::regex("halves +unavailable: its check \\(/usr/bin/python3 -c import sys; "
                                                     "sys\\.exit\\(int\\(4/2\\)\\)\\) exited with code 2")))
      << r.output;
  EXPECT_TRUE(std::regex_search(r.output, std::regex("noscript +unavailable: check file '.*/checks/absent\\.py' is "
                                                     "missing")))
      << r.output;
  EXPECT_TRUE(std::regex_search(r.output, std::regex("parens +unavailable: command file '.*/eng\\(1\\)\\.py' is missing")))
      << r.output;
}

}  // namespace

namespace {

TEST_F(ProcessTree, NulsInAnEnginesFileOrAnEnginesOutputAreShownEscaped) {
  // A NUL in a name, a setting key or a field's name: the message goes on past it.
  struct Bad {
    const char* entry;
    const char* says;
  };
  for (const Bad& b : {Bad{R"("name": "a\u0000b", "command": ["python3"])", R"(engines\[0\]\.name: 'a\\x00b')"},
                       Bad{R"("name": "ok", "command": ["python3"], "settings": ["k\u0000ey"])",
                           R"(engines\[0\]\.settings\[0\]: 'k\\x00ey'; allowed: a key)"},
                       Bad{R"("name": "ok", "command": ["python3"], "colour\u0000x": 1)",
                           R"(engines\[0\]\.colour\\x00x: an unknown field; allowed:)"}}) {
    SCOPED_TRACE(b.entry);
    const fs::path file = dir_ / "bad.json";
    std::ofstream(file) << R"({"format": "octocd-engines", "version": 1, "engines": [{)" << b.entry << "}]}";
    const Result r = octocd("engines", file.string());
    EXPECT_EQ(r.code, 2) << r.output;
    EXPECT_TRUE(std::regex_search(r.output, std::regex(b.says))) << r.output;
  }
  // An engine's stderr holding a NUL: its tail is shown whole, the NUL as \x00.
  const fs::path file = dir_ / "engines.json";
  std::ofstream(file) << R"J({"format": "octocd-engines", "version": 1, "engines": [
      {"name": "nul", "description": "a NUL on stderr", "geometries": ["box"], "command": ["/usr/bin/python3", "-c",
       "import sys; sys.stderr.write('before\\u0000after'); sys.exit(1)"]}]})J";
  const Result r =
      octocd("run " + data("boxes.json") + " --engine nul --frames 3 --quiet", file.string());
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_NE(r.output.find("exited with code 1 after "), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("its stderr ended: before\\x00after"), std::string::npos) << r.output;
}

}  // namespace

namespace {

/// A lattice of n^3 touching unit-spaced boxes without gravity (a few ms a step).
std::string lattice(const fs::path& dir, int n) {
  const fs::path p = dir / "lattice.json";
  const double h = 0.55 * (n - 1) / 2;
  std::ofstream(p) << R"({"name": "lattice", "domain": {"min": [)" << -h - 2 << ", " << -h - 2 << ", " << -h - 2
                   << R"(], "max": [)" << h + 2 << ", " << h + 2 << ", " << h + 2 << R"(]},
    "gravity": [0, 0, 0], "frames": 100,
    "groups": [{"name": "b", "shape": {"box": [0.3, 0.3, 0.3]}, "count": )"
                   << n * n * n << R"(, "layout": {"type": "grid", "min": [)" << -h << ", " << -h << ", " << -h
                   << R"(], "max": [)" << h << ", " << h << ", " << h << R"(], "spacing": 0.55}}]})";
  return p.string();
}

std::string slurp(const fs::path& p) {
  std::ifstream in(p);
  return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}

// `validate --determinism` stopped by a signal used to end at once, "nothing was written",
// its finished rows lost. Now it stops between frames and keeps them: stopped inside the
// third run (the 1-thread one, its temporary trace appearing in TMPDIR: an event), the table,
// --json and --junit hold the first row (two runs compared), the line says so, exit 130, no
// temporary trace is left.
TEST_F(ProcessTree, AStoppedDeterminismValidationKeepsItsFinishedRows) {
  const fs::path json = dir_ / "d.json", junit = dir_ / "d.xml", tmp = dir_ / "tmp";
  const pid_t pid = ::fork();
  if (pid == 0) {
    ::setenv("TMPDIR", tmp.c_str(), 1);
    const int out = ::open((dir_ / "stdout.txt").c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    const int err = ::open((dir_ / "stderr.txt").c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    ::dup2(out, 1);
    ::dup2(err, 2);
    const std::string b = octocd::test::bin(), scene = lattice(dir_, 8);
    ::execl(b.c_str(), b.c_str(), "validate", scene.c_str(), "--engine", "cpu", "--determinism", "--threads", "2",
            "--frames", "300", "--json", json.c_str(), "--junit", junit.c_str(), static_cast<char*>(nullptr));
    ::_exit(127);
  }
  const auto serial = [&] {
    for (const auto& e : fs::directory_iterator(tmp))
      if (e.path().filename().string().find("serial") != std::string::npos) return true;
    return false;
  };
  const bool third = octocd::test::wait_until(serial, {tmp}, std::chrono::seconds(120));
  ::kill(pid, SIGINT);
  int status = 0;
  ASSERT_TRUE(octocd::test::wait_child(pid, status, std::chrono::seconds(60)));
  const std::string out = slurp(dir_ / "stdout.txt"), err = slurp(dir_ / "stderr.txt");
  ASSERT_TRUE(third) << err;
  ASSERT_TRUE(WIFEXITED(status)) << err;
  EXPECT_EQ(WEXITSTATUS(status), 130) << err;
  EXPECT_NE(err.find("octocd validate: stopped by SIGINT after 1 of 3 determinism rows; the table above holds the 1 "
                     "finished row(s), --junit " + junit.string() + " too, --json " + json.string() + " too\n"),
            std::string::npos)
      << err;
  EXPECT_NE(out.find("determinism-runs"), std::string::npos) << out;
  EXPECT_NE(out.find("STOPPED: stopped by SIGINT after 1 of 3 determinism rows"), std::string::npos) << out;
  const std::string j = slurp(json);
  EXPECT_NE(j.find("\"determinism-runs\""), std::string::npos) << j;
  EXPECT_EQ(j.find("\"determinism-threads\""), std::string::npos) << j;
  EXPECT_NE(j.find("stopped by SIGINT after 1 of 3 determinism rows"), std::string::npos) << j;
  EXPECT_NE(slurp(junit).find("determinism-runs"), std::string::npos);
  EXPECT_TRUE(fs::is_empty(tmp)) << "a temporary trace was left";
}

}  // namespace

}  // namespace octocd_test_cli_processes_and_stops
