#pragma once
// Running an engine's command as a child process, bounded (process_engines.cpp and
// process_engine.cpp; not installed): posix_spawn of an argument vector (no shell), stdin
// /dev/null, stdout and stderr read through pipes of which only the tail is kept, its own
// process group, a wall-time bound, a watched output file's size bound, and octocd's stop
// signal (octocd/stop.hpp) answered by stopping the group (SIGTERM, then SIGKILL).

#include <cstdint>
#include <string>
#include <vector>

namespace octocd::process_detail {

/// What to run and its bounds.
struct ChildRun {
  std::vector<std::string> argv;  ///< argv[0] an executable's path (resolved), then its arguments
  std::string cwd;                ///< working folder of the child
  double timeout_s = 600.0;       ///< wall-time bound (s)
  std::string watched;            ///< a file whose size is bounded ("" none)
  std::uint64_t watched_max = 0;  ///< its largest size (bytes)
  double grace_s = 2.0;           ///< SIGTERM to SIGKILL when a bound is passed (s)
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
};

/// Runs `run` to its end (or a bound, or octocd's stop signal). Never throws for what the
/// child does; std::bad_alloc only.
ChildOutcome run_child(const ChildRun& run);

/// What the child did, in words: "exited with code 3 after 0.21 s", "was killed by signal
/// 11 (SIGSEGV) after ...", "ran past its bound of 2 s (timeout_s) and was stopped",
/// "wrote more than N bytes to FILE (max_trace_bytes) and was stopped", "could not be started: ...".
std::string describe(const ChildOutcome& o);

/// "; its stderr ended: <lines>" (else its stdout's, else ""): the last lines (at most 8
/// lines, 1000 bytes), each made printable (octocd/text.hpp), joined by " | ", with the
/// number of bytes it wrote when more than shown.
std::string output_tail(const ChildOutcome& o);

/// The full path of `program`: itself when it holds a '/', else the first executable
/// PATH entry holding it; "" when none.
std::string find_on_path(const std::string& program);

}  // namespace octocd::process_detail
