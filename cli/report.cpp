// `octocd report RESULT.json|TRACE.h5 ... -o DIR` (SPEC 12): runs reports/make_report.py
// (matplotlib; Debian python3-matplotlib) on bench results and traces, which writes
// DIR/index.html (self-contained: plots inline as SVG) and DIR/report.md (+ DIR/plots/);
// with --baseline a performance gate (exit 4 on a slowdown shown by a one-sided Mann-Whitney U test
// on the repetitions, or a failed new run), with --csv the data as CSV.
#include <sys/wait.h>
#include <unistd.h>

#include <cstdlib>
#include <filesystem>

#include <fmt/format.h>

#include "octocd/error.hpp"
#include "octocd/shared_files.hpp"
#include "tools.hpp"

namespace octocd::cli {

namespace {

namespace fs = std::filesystem;

std::string python() {
  if (const char* p = std::getenv("OCTOCD_PYTHON"); p && *p) return p;
  std::error_code ec;
  // Debian's interpreter is the one with python3-matplotlib and python3-h5py.
  if (fs::exists("/usr/bin/python3", ec)) return "/usr/bin/python3";
  return "python3";
}

std::string script() {
  if (const char* p = std::getenv("OCTOCD_REPORT_SCRIPT"); p && *p) return p;
  return (fs::path(shared_dir()) / "reports" / "make_report.py").string();
}

}  // namespace

CLI::App* add_report_command(CLI::App& app, ReportOptions& o) {
  CLI::App* c = app.add_subcommand(
      "report",
      "Make a report of bench results and traces: DIR/index.html (self-contained, plots inline) and DIR/report.md "
      "(plots in DIR/plots/): the paper's Tables 5, 6, A1 beside ours per engine, steps/s and stage shares, broadphase "
      "scaling, the beta-delta heatmap, and per trace energy, contacts and penetration over frames. Shards of one "
      "sweep (one build) are merged. With --baseline, a performance gate. Exit 0 ok, 1 failure (e.g. no "
      "matplotlib), 2 bad input (one line naming the file and key, never a traceback; too few repetitions to "
      "decide), 4 the gate fails: a slowdown against --baseline, or a point of the baseline missing, failed or "
      "unmeasured in the new run");
  c->add_option("inputs", o.inputs, "Result files of `octocd bench` (.json) and traces (.h5)")->required();
  c->add_option("-o,--output", o.output, "Output folder (created)")->required();
  c->add_option("--title", o.title, "Title of the report");
  c->add_option("--baseline", o.baseline,
                "Performance gate: baseline result file(s) of the same sweep (shards merged, runs of one build pooled; repeat "
                "the option). Per "
                "point and timing figure, the repetitions of both runs: SLOWER (exit 4) when the one-sided "
                "Mann-Whitney U test of the new times against the baseline times x (1 + threshold) rejects at --level; "
                "the time ratio (Hodges-Lehmann) and its interval are printed for every slower point. Fewer than 5 "
                "repetitions a side: exit 2; a baseline point the new run lacks, failed, skipped or measured as "
                "non-finite or <= 0, or a stopped new run: exit 4 (named)")
      ->allow_extra_args(false);
  c->add_option("--threshold", o.threshold, "Slowdown in percent that fails the gate (default 10: on a shared 2-core machine the same build twice differs by up to 30 % between runs; docs/bench-format.md, error rates)")
      ->check(CLI::Range(0.0, 999.0));
  c->add_option("--level", o.level, "The gate's significance level, one-sided (default 0.05)")
      ->check(CLI::Range(1e-6, 0.25));
  c->add_option("--timing", o.timing,
                "The gate's figure: cpu (steps per process CPU second, recorded for host engines: another process's "
                "load on a shared machine hardly moves it), wall (wall-clock steps/s), or auto (default: cpu where "
                "both runs have it, else wall)")
      ->check(CLI::IsMember({"auto", "cpu", "wall"}));
  c->add_flag("--across-machines", o.across_machines,
              "Gate runs of two machines (without it a baseline of another host or CPU is exit 2)");
  c->add_option("--csv", o.csv,
                "Also write the data as CSV into this folder: per sweep one row per point, window and repetition plus "
                "a summary row per point (numbers only, units in the header); gate.csv with --baseline");
  return c;
}

int report_command(const ReportOptions& o) {
  std::error_code ec;
  for (const auto& in : o.baseline)
    if (!fs::is_regular_file(in, ec))
      throw InputError(fmt::format("--baseline {}: no such file; allowed: a result file of `octocd bench` (.json)", in));
  for (const auto& in : o.inputs)
    if (!fs::is_regular_file(in, ec))
      throw InputError(fmt::format("{}: no such file; allowed: result files of `octocd bench` (.json) and traces (.h5)",
                                   in));
  const std::string py = python(), sc = script();
  if (!fs::is_regular_file(sc, ec))
    throw RuntimeError(fmt::format("report script {} not found (an octocd installed without its share/octocd? set "
                                   "OCTOCD_SOURCE_DIR to the octocd source tree, or OCTOCD_REPORT_SCRIPT to the script)",
                                   sc));
  std::vector<std::string> args{py, sc, "-o", o.output};
  if (!o.title.empty()) {
    args.push_back("--title");
    args.push_back(o.title);
  }
  for (const auto& in : o.baseline) {
    args.push_back("--baseline");
    args.push_back(in);
  }
  args.push_back("--threshold");
  args.push_back(fmt::format("{}", o.threshold));
  args.push_back("--level");
  args.push_back(fmt::format("{}", o.level));
  if (o.across_machines) args.push_back("--across-machines");
  args.push_back("--timing");
  args.push_back(o.timing);
  if (!o.csv.empty()) {
    args.push_back("--csv");
    args.push_back(o.csv);
  }
  args.push_back("--");
  for (const auto& in : o.inputs) args.push_back(in);
  std::vector<char*> argv;
  for (auto& a : args) argv.push_back(a.data());
  argv.push_back(nullptr);
  std::fflush(stdout);
  std::fflush(stderr);
  const pid_t pid = fork();
  if (pid < 0) throw RuntimeError("report: fork failed");
  if (pid == 0) {
    execvp(argv[0], argv.data());
    std::fprintf(stderr, "octocd: runtime failure: report: cannot run %s (install Debian's python3-matplotlib, or set "
                         "OCTOCD_PYTHON)\n", argv[0]);
    _exit(1);
  }
  int status = 0;
  if (waitpid(pid, &status, 0) < 0) throw RuntimeError("report: waitpid failed");
  if (!WIFEXITED(status)) throw RuntimeError(fmt::format("report: {} was killed (signal {})", sc, WTERMSIG(status)));
  const int rc = WEXITSTATUS(status);
  return rc == 0 || rc == 2 || rc == 4 ? rc : 1;
}

}  // namespace octocd::cli
