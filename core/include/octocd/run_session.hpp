#pragma once
/// \file run_session.hpp
/// The run session of a long command (`run`, `validate`, `bench`, `report`, the process
/// engines they start): the one object that owns what the command keeps should a SIGINT or
/// SIGTERM stop it or should it fail, and that states it. The command registers, as it goes:
///   - what its output holds now (keep: "the result r.json keeps the 3 point(s) finished
///     before"), or how to read that back from the output itself (keep_read_back; a trace
///     being written: keep_trace, its frames as flushed and read back);
///   - its temporary files and folders (add_temporary): removed on any stop or failure;
///   - the child process groups it started (add_child): killed on any stop.
/// A stop then ends the same way whichever path it takes: the command's own stop path
/// (stopped(): one line "octocd CMD: stopped by SIG...<where>; <kept>", exit 128 + sig) or
/// the process ended at once inside a step that outlasts the bound (stop.hpp's deadline,
/// a second signal, a StopWithin's grace: one line "octocd: stopped by SIG...; <kept>").
/// Either way the temporaries go and the children are killed (docs/robustness.md, "Stops").
///
/// Use:
///
///     octocd::RunSession session("bench");       // the handlers, the 1 s bound
///     for (point : points) {
///       if (const int sig = session.signal()) return session.stopped(sig, " after 3 of 8 points");
///       measure(point); write(result);
///       session.keep("the result r.json keeps the 3 point(s) finished before");
///     }

#include <cstdint>
#include <functional>
#include <string>

#include "octocd/stop.hpp"

namespace octocd {

class TraceWriter;

/// From the first SIGINT/SIGTERM to the end of a session's process, at most this long (s)
/// by default: 1 s less the 20 ms tick and the process's exit (docs/robustness.md).
inline constexpr double kStopBoundS = 0.8;

/// How a run session stops (see RunSession).
struct RunSessionSettings {
  /// > 0: the process ends at most this long after the first signal, inside whatever it
  /// runs (an engine's step), stating what is kept; 0: no bound (the command answers the
  /// signal itself, e.g. `validate`, whose verdict must not be cut).
  double bound_s = kStopBoundS;
  /// What a second signal does (stop.hpp, SecondSignal).
  SecondSignal second = SecondSignal::EndsAtOnce;
};

/// One long command's run session: installs the SIGINT/SIGTERM handlers (a StopOnSignals
/// with the bound) and owns what the command keeps when stopped or failing. One at a time
/// per process (not nestable); construct and use it from the command's thread, except
/// add_temporary / forget_temporary / add_child / forget_child (any thread: a process
/// engine's copy of `run --worlds` registers its folder from its own). On destruction (a normal end or an exception)
/// the temporaries still registered are removed and the children still registered killed.
class RunSession {
 public:
  /// `command`: its name in the stop line ("run", "bench", ...).
  explicit RunSession(std::string command, RunSessionSettings settings = {});
  ~RunSession();
  RunSession(const RunSession&) = delete;
  RunSession& operator=(const RunSession&) = delete;

  /// The session alive in this process, nullptr when none (an engine's child process
  /// registers with it).
  static RunSession* current();

  /// The command's name, as given.
  const std::string& command() const { return command_; }

  /// The signal that stopped the command, 0 when none (stop_signal()).
  int signal() const { return stop_signal(); }

  /// What the command's output holds now, said by every stop ("" clears it). Call after
  /// each write of the output, at most about once a frame.
  void keep(const std::string& text);

  /// The text keep() last gave ("" when none).
  const std::string& kept() const { return kept_; }

  /// What is kept, read back from the output itself on a process ended at once (stop.hpp,
  /// set_stop_kept_reader: its own thread, at most `bound_s`, keep()'s text when it fails).
  /// `reader` must stay callable until forget_read_back() or the session's end.
  void keep_read_back(std::function<std::string()> reader, double bound_s = 0.2);

  /// Clears keep_read_back's reader (before what it reads goes).
  void forget_read_back();

  /// While alive, the trace being written is what the command keeps (RunSession::keep_trace).
  /// Its end clears the read-back (declare it after the trace: it ends first, whatever the
  /// way out).
  class KeptTrace {
   public:
    KeptTrace(KeptTrace&& other) noexcept;
    KeptTrace(const KeptTrace&) = delete;
    KeptTrace& operator=(const KeptTrace&) = delete;
    KeptTrace& operator=(KeptTrace&&) = delete;
    ~KeptTrace();

    /// After each frame written: keep()'s text follows the trace's flushed frames, those a
    /// writer thread ended meanwhile too (a new text only when they changed).
    void frame_written();

    /// Clears the read-back now (before the trace is closed); keep()'s text stays.
    void end();

   private:
    friend class RunSession;
    KeptTrace(RunSession* session, TraceWriter* trace, std::string path, std::string tail);
    void keep_flushed();
    RunSession* session_;
    TraceWriter* trace_;
    std::string path_, tail_;
    std::int64_t flushed_ = -1;
  };

  /// The trace `trace` being written at `path` is what the command keeps: keep() says its
  /// flushed frames now and at each KeptTrace::frame_written() ("the trace PATH holds frames
  /// 1..K (its last flush)TAIL", or "holds no frame (none flushed yet)TAIL"), and a process
  /// ended at once reads them back from the file (keep_read_back, at most `bound_s`;
  /// TraceWriter::read_back_frames_and_hold: "the trace PATH holds frames 1..K (read
  /// back)TAIL", "holds no frame (read back)TAIL"). `tail`: what follows, e.g. ", no
  /// sidecar". `trace` must outlive the returned KeptTrace.
  KeptTrace keep_trace(TraceWriter& trace, const std::string& path, const std::string& tail, double bound_s = 0.2);

  /// A temporary file, or a folder for temporary files, that no stop or failure leaves
  /// behind (a folder is emptied of its files, one level, then removed). At most 64 at
  /// once; false (not owned) beyond. Any thread.
  bool add_temporary(const std::string& path);

  /// Hands a temporary back to the command (it was removed, or renamed into the output).
  /// Any thread.
  void forget_temporary(const std::string& path);

  /// A child process group (its id) that no stop leaves running. Any thread.
  bool add_child(int group);

  /// The child group ended and was reaped. Any thread.
  void forget_child(int group);

  /// The command's own stop path: removes the temporaries, kills the children, prints
  /// "octocd COMMAND: stopped by SIG...<where>; <kept()>" (or without "; ..." when nothing
  /// is kept) on stderr and returns stop_exit_code(sig) for the command to return.
  /// `where`: e.g. " after frame 12 of 100".
  int stopped(int sig, const std::string& where);

  /// stopped() after frame `done` of `total` (run, validate): the command keeps what the
  /// trace `trace` holds ("the trace T holds frames 1..DONE", or "the trace T holds no
  /// frame", then `kept_tail`; nothing when `trace` is "") and says " after frame DONE of
  /// TOTAL<where_tail>". Returns stop_exit_code(sig).
  int stopped_after_frame(int sig, std::int64_t done, std::int64_t total, const std::string& trace,
                          const std::string& kept_tail = "", const std::string& where_tail = "");

  /// Ends the process now, from work that cannot return to the command's stop path (a
  /// process engine whose child was stopped): stopped()'s line, then _Exit(128 + sig).
  [[noreturn]] void end_now(int sig, const std::string& where);

 private:
  std::string command_;
  std::string kept_;
  StopOnSignals signals_;
};

}  // namespace octocd
