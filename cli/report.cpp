// `octocd report RESULT.json|TRACE.h5 ... -o DIR` (design.md section 12): runs report/make_report.py
// (matplotlib; Debian python3-matplotlib) on bench results and traces, which writes
// DIR/index.html (self-contained: plots inline as SVG) and DIR/report.md (+ DIR/plots/);
// with --baseline a performance gate (exit 4 on a slowdown shown by a one-sided Mann-Whitney U test
// on the repetitions, or a failed new run), with --csv the data as CSV. The script reads
// traces through `octocd trace-summary --json` (this file too): octocd's hardened reader.
// SIGINT/SIGTERM to octocd (its run session records them) are forwarded to the script,
// which is waited for.
#include <signal.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <optional>

#include <fmt/format.h>
#include <fmt/ranges.h>
#include <nlohmann/json.hpp>

#include "octocd/atomic_file.hpp"
#include "octocd/error.hpp"
#include "octocd/text.hpp"
#include "octocd/run_session.hpp"
#include "octocd/shared_files.hpp"
#include "octocd/trace_reader.hpp"
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
  return (fs::path(shared_dir()) / "report" / "make_report.py").string();
}

/// From a forwarded SIGINT/SIGTERM to the script's SIGKILL: `report` ends within 1 s.
constexpr std::chrono::milliseconds kReportStopBound{700};

/// An input of the report: a regular file (a FIFO would block the script forever).
void check_input(const std::string& path, const char* what) {
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0)
    throw InputError(fmt::format("{}: no such file; allowed: {}", path, what));
  if (!S_ISREG(st.st_mode))
    throw InputError(fmt::format("{}: not a regular file ({}); allowed: {}", path, file_type_word(st.st_mode), what));
}

/// This executable (the script runs its `trace-summary`).
std::string self_path() {
  std::error_code ec;
  const fs::path p = fs::read_symlink("/proc/self/exe", ec);
  return ec ? std::string("octocd") : p.string();
}

/// A JSON number (an integer when integral), or null when not finite (JSON has no NaN or
/// infinity).
nlohmann::ordered_json number(double v) {
  if (!std::isfinite(v)) return nullptr;
  if (v == std::floor(v) && std::fabs(v) < 9007199254740992.0) return static_cast<std::int64_t>(v);  // 2^53
  return v;
}

}  // namespace

CLI::App* add_trace_summary_command(CLI::App& app, TraceSummaryOptions& o) {
  CLI::App* c = add_table_command(app, CommandId::trace_summary);
  c->add_option("trace", o.trace, "The trace (.h5)")->required();
  c->add_flag("--json", o.json,
              "One JSON object: format, version, path, frames, attributes {name: value}, columns {name: [values]} "
              "(frame, time, step_ms, the stage times, counters and figures of /frames; null for a non-finite value)");
  return c;
}

int trace_summary_command(const TraceSummaryOptions& o) {
  const TraceReader r(o.trace);
  const std::int64_t frames = r.complete_rows("/frames");
  nlohmann::ordered_json attrs = nlohmann::ordered_json::object();
  for (const char* name : {"scene_name", "engine", "broadphase", "midphase", "body_count", "device", "build_id",
                           "start_time", "dt", "state_every", "committed_frames", "committed_states"}) {
    if (!r.has_attribute(name)) continue;
    const TraceAttribute a = r.attribute(name);
    if (!a.scalar) continue;
    attrs[name] = a.is_string ? nlohmann::ordered_json(a.strings.front()) : number(a.numbers.front());
  }
  nlohmann::ordered_json cols = nlohmann::ordered_json::object();
  for (const std::string& name : TraceReader::frame_columns()) {
    const std::string d = "/frames/" + name;
    if (!r.has_dataset(d) || r.shape(d).size() != 1) continue;  // momentum (F x 3) is not a column
    nlohmann::ordered_json col = nlohmann::ordered_json::array();
    for (const double v : r.read_f64(d, frames)) col.push_back(number(v));
    cols[name] = std::move(col);
  }
  if (o.json) {
    nlohmann::ordered_json j;
    j["format"] = "octocd-trace";
    j["version"] = r.version();
    j["path"] = o.trace;
    j["frames"] = frames;
    j["attributes"] = std::move(attrs);
    j["columns"] = std::move(cols);
    fmt::print("{}\n", j.dump(-1, ' ', false, nlohmann::ordered_json::error_handler_t::replace));
    return 0;
  }
  // The trace's text reaches the terminal with its control characters escaped (\xNN).
  fmt::print("{}: octocd-trace version {}, {} complete frames\n", printable(o.trace), r.version(), frames);
  for (const auto& [k, v] : attrs.items())
    fmt::print("  {}: {}\n", printable(k),
               printable(v.is_string() ? v.get<std::string>()
                                       : v.dump(-1, ' ', false, nlohmann::ordered_json::error_handler_t::replace)));
  return 0;
}

CLI::App* add_report_command(CLI::App& app, ReportOptions& o) {
  CLI::App* c = add_table_command(app, CommandId::report);
  c->add_option("inputs", o.inputs, "Result files of `octocd bench` (.json) and traces (.h5); none with --history");
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
  c->add_option("--level", o.level,
                "The gate's significance level, one-sided (default 0.05); the repetitions must be able to reach it "
                "(5 a side: p >= 1/252 = 0.00397), else exit 2 naming the repetitions needed")
      ->check(CLI::Range(1e-6, 0.25));
  c->add_option("--timing", o.timing,
                "The gate's figure (and --history's): cpu (steps per process CPU second, recorded for host engines: another process's "
                "load on a shared machine hardly moves it), wall (wall-clock steps/s), or auto (default: cpu where "
                "both runs have it, else wall)")
      ->check(CLI::IsMember({"auto", "cpu", "wall"}));
  c->add_flag("--across-machines", o.across_machines,
              "Gate runs of two machines (without it a baseline of another host or CPU is exit 2)");
  c->add_option("--history", o.history,
                "Draw a history folder instead (docs/regression.md; written by `bench --history`, `scripts/nightly.sh "
                "--history`, `history-append`): per machine, steps/s of every point over commits (median and "
                "min-max of the repetitions; --timing picks the figure, a CPU figure's window named WINDOW (cpu)) with the "
                "change points a rank test finds, the engine matrix's verdicts "
                "(pass, expected, new, fixed) per engine x scene x row against night, and the night each current "
                "failure appeared; OUT/index.html (PNG plots inline) and OUT/*.csv. A damaged or foreign file in DIR "
                "is named and skipped");
  c->add_option("--change-level", o.change_level,
                "--history: the change-point test's level, family-wise over the series of one machine (default 0.05; "
                "each series is tested at level / series)")
      ->check(CLI::Range(1e-9, 0.5));
  c->add_option("--csv", o.csv,
                "Also write the data as CSV into this folder: per sweep one row per point, window and repetition plus "
                "a summary row per point (numbers only, units in the header); gate.csv with --baseline");
  return c;
}

int report_command(const ReportOptions& o) {
  std::error_code ec;
  for (const auto& in : o.baseline)
    check_input(in, "a result file of `octocd bench` (.json) for --baseline");
  for (const auto& in : o.inputs) check_input(in, "result files of `octocd bench` (.json) and traces (.h5)");
  if (o.history.empty() && o.inputs.empty())
    throw InputError("report: no inputs; allowed: result files of `octocd bench` (.json) and traces (.h5), or "
                     "--history DIR");
  if (!o.history.empty() && (!o.inputs.empty() || !o.baseline.empty()))
    throw InputError(fmt::format("--history {}: with inputs or --baseline; allowed: --history DIR alone (its files "
                                 "are the inputs)",
                                 o.history));
  if (!o.history.empty()) {
    struct stat st {};
    if (::stat(o.history.c_str(), &st) != 0 || !S_ISDIR(st.st_mode))
      throw InputError(fmt::format("--history: {}: not a folder; allowed: a history folder (docs/regression.md)",
                                   o.history));
  }
  check_output_folder(o.output, "-o", true);
  if (!o.csv.empty()) check_output_folder(o.csv, "--csv", true);
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
  if (!o.history.empty()) {
    args.push_back("--history");
    args.push_back(o.history);
    args.push_back("--change-level");
    args.push_back(fmt::format("{}", o.change_level));
  }
  args.push_back("--octocd");
  args.push_back(self_path());
  args.push_back("--");
  for (const auto& in : o.inputs) args.push_back(in);
  std::vector<char*> argv;
  for (auto& a : args) argv.push_back(a.data());
  argv.push_back(nullptr);
  std::fflush(stdout);
  std::fflush(stderr);
  // SIGINT/SIGTERM to octocd reach the script too (forwarded; a terminal's Ctrl-C reaches
  // both, the script being in octocd's process group), and octocd waits for it to end. The
  // session records them (a second one only counted: the loop below answers it).
  RunSession session("report", {0.0, SecondSignal::Recorded});
  const pid_t pid = fork();
  if (pid < 0) throw RuntimeError("report: fork failed");
  if (pid == 0) {
    signal(SIGINT, SIG_DFL);  // the script's own handling (Python: KeyboardInterrupt)
    signal(SIGTERM, SIG_DFL);
    execvp(argv[0], argv.data());
    std::fprintf(stderr, "octocd: runtime failure: report: cannot run %s (install Debian's python3-matplotlib, or set "
                         "OCTOCD_PYTHON)\n", argv[0]);
    _exit(1);
  }
  // Polled (10 ms): the first signal is forwarded to the script, which then has
  // kReportStopBound to end (Python inside a C extension answers its KeyboardInterrupt only
  // when it returns), then it is killed, so `report` ends within 1 s of the signal; a
  // second signal kills it at once.
  int status = 0;
  pid_t got = 0;
  std::optional<std::chrono::steady_clock::time_point> signalled;
  bool killed = false, insisted = false;
  for (;;) {
    got = waitpid(pid, &status, WNOHANG);
    if (got == pid || (got < 0 && errno != EINTR)) break;
    if (const int sig = session.signal()) {
      const auto now = std::chrono::steady_clock::now();
      if (!signalled) {
        signalled = now;
        ::kill(pid, sig);
      }
      if (!insisted && stop_signal_count() > 1) {
        ::kill(pid, SIGKILL);
        insisted = true;
      }
      if (!killed && now - *signalled >= kReportStopBound) {
        ::kill(pid, SIGKILL);
        killed = true;
      }
    }
    ::usleep(10000);
  }
  if (got < 0) throw RuntimeError("report: waitpid failed");
  if (const int sig = session.signal()) {
    // make_report.py says a stop itself ("octocd report: stopped by ..."; exit 128 + signal):
    // one line for the user, so this one only where the script did not (killed, or ended
    // otherwise).
    if (!killed && WIFEXITED(status) && WEXITSTATUS(status) == stop_exit_code(sig)) return stop_exit_code(sig);
    std::fprintf(stderr, "octocd: report stopped by %s; %s %s (the earlier report in %s, if any, is left as it "
                         "was)\n", stop_signal_name(sig), sc.c_str(),
                 killed ? fmt::format("did not end within {} ms and was killed", kReportStopBound.count()).c_str()
                        : "ended",
                 o.output.c_str());
    return stop_exit_code(sig);
  }
  if (!WIFEXITED(status))
    throw RuntimeError(fmt::format("report: {} was killed (signal {}) reading {}", sc, WTERMSIG(status),
                                   fmt::join(o.inputs, ", ")));
  const int rc = WEXITSTATUS(status);
  return rc == 0 || rc == 2 || rc == 4 ? rc : 1;
}

}  // namespace octocd::cli
