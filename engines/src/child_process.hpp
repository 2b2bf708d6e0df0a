#pragma once
// Running an engine's command as a child process, bounded (process_engines.cpp and
// process_engine.cpp; not installed): an argument vector executed (no shell) under a keeper
// process, a child subreaper that ends the engine's whole process tree with it (a
// descendant that calls setsid() included: docs/bring-your-engine.md, "The invocation");
// stdin /dev/null, stdout and stderr read through pipes of which only the tail is kept, its
// own process group, a wall-time bound, a watched output file's size bound, and octocd's
// stop signal (octocd/stop.hpp) or the caller's cancel flag answered by stopping the tree
// (SIGTERM, then SIGKILL).

#include <atomic>
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

namespace octocd::process_detail {

/// What to run and its bounds.
struct ChildRun {
  std::vector<std::string> argv;  ///< argv[0] an executable's path (resolved), then its arguments
  std::string cwd;                ///< working folder of the child
  double timeout_s = 600.0;       ///< wall-time bound (s)
  std::string timeout_setting = "timeout_s";  ///< the bound's name in messages ("timeout_s")
  std::string watched;            ///< a file whose size is bounded ("" none)
  std::uint64_t watched_max = 0;  ///< its largest size (bytes)
  double grace_s = 2.0;           ///< SIGTERM to SIGKILL when a bound is passed (s)
  /// When set (any thread), the tree is stopped as on octocd's stop signal (End::Stopped,
  /// stop_signal 0): Python's Ctrl-C inside Engine.step(). nullptr: none. Not owned.
  const std::atomic<bool>* cancel = nullptr;
  /// When set: called on run_child's thread after each wait for output (about 10 ms apart
  /// while the child runs; once more after it ended when lines are left) with the complete
  /// lines its stdout gave since the last call (without their '\n'; a line over 4 KiB is
  /// cut there), often none. It must not throw. Empty: none.
  std::function<void(const std::vector<std::string>& stdout_lines)> on_poll;
};

/// How the child ended.
struct ChildOutcome {
  enum class End { Exited, Signalled, TimedOut, Oversize, Stopped, SpawnFailed };
  End end = End::Exited;
  int code = 0;            ///< Exited: the exit status; Signalled: the signal
  int stop_signal = 0;     ///< Stopped: octocd's signal (SIGINT, SIGTERM)
  double seconds = 0.0;    ///< wall time the child ran
  std::string spawn_error; ///< SpawnFailed: why
  std::string out_tail, err_tail;  ///< the last bytes of stdout and stderr (raw)
  std::uint64_t out_bytes = 0, err_bytes = 0;  ///< all bytes written to each
  double timeout_s = 0.0;       ///< the run's wall-time bound (s), as set
  std::string timeout_setting;  ///< its name (ChildRun::timeout_setting)
  double grace_s = 0.0;         ///< the run's SIGTERM to SIGKILL grace (s)
};

/// Runs `run` to its end (or a bound, octocd's stop signal, the cancel flag); when it
/// returns, the process and every descendant of it have ended (killed when still running)
/// and been reaped. Never throws for what the child does; std::bad_alloc only.
ChildOutcome run_child(const ChildRun& run);

/// What the child did, in words: "exited with code 3 after 0.21 s", "was killed by signal
/// 11 (SIGSEGV) after ...", "ran past its timeout_s of 4 s and was stopped after 6.01 s
/// (...)", "wrote a trace beyond its max_trace_bytes ...", "could not be started: PATH:
/// No such file or directory (ENOENT)".
std::string describe(const ChildOutcome& o);

/// Whether `line` is a progress line `octocd-progress N` (docs/bring-your-engine.md,
/// "Progress": N an integer >= 0, nothing after it); N then goes to `*frames` (when not
/// null). The one reader of those lines: the progress of a run and the failure messages.
bool progress_line(const std::string& line, std::int64_t* frames);

/// "; its stderr ended: <lines>" (else its stdout's, less its progress lines: "; its stdout
/// ended (its octocd-progress lines left out): <lines>"; else "; no error output (...)"):
/// the last lines (at most 8 lines, 1000 bytes), each made printable (octocd/text.hpp),
/// joined by " | ", with the number of bytes it wrote when more than shown.
std::string output_tail(const ChildOutcome& o);

/// The full path of `program`: itself when it holds a '/' and is an executable regular
/// file, else the first PATH entry holding one of that name; "" when none.
std::string find_on_path(const std::string& program);

/// "" when find_on_path(program) finds it, else why not: "not found on PATH" (a name), or
/// for a path "cannot be run: " and the reason with its errno name ("No such file or
/// directory (ENOENT)", "Permission denied (EACCES)", "a folder (EISDIR)").
std::string why_not_runnable(const std::string& program);

}  // namespace octocd::process_detail
