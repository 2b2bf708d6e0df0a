#pragma once
/// \file stop.hpp
/// Stopping a long run on SIGINT or SIGTERM (issue 10): the handlers only record the
/// signal (async-signal-safe); the command's loop polls stop_signal() between steps,
/// flushes its trace or result, says where it stopped and exits with stop_exit_code()
/// (130 for SIGINT, 143 for SIGTERM, the shells' 128 + signal). A second signal while
/// the first is being handled ends the process at once with 128 + sig and one line on
/// stderr saying what is kept (set_stop_kept), so a stuck flush can still be interrupted;
/// so does a deadline passed (StopOnSignals' `deadline_s`, e.g. `run`'s 1 s bound).
///
/// A command holds these through its run session (run_session.hpp: RunSession), which owns
/// what it keeps (the kept text, temporary files, child processes); the functions below are
/// its machinery. Use:
///
///     octocd::StopOnSignals stop;              // installs the handlers, restores on exit
///     for (int f = 0; f < frames && !octocd::stop_signal(); ++f) step();
///     if (const int sig = octocd::stop_signal()) { flush(); report(sig); return octocd::stop_exit_code(sig); }

#include <functional>
#include <string>

namespace octocd {

/// The signal (SIGINT or SIGTERM) received since the handlers were installed, 0 when none.
/// Safe to call from any thread.
int stop_signal();

/// 128 + sig: the exit status of a command stopped by `sig` (130 SIGINT, 143 SIGTERM).
int stop_exit_code(int sig);

/// How many SIGINT/SIGTERM arrived since the handlers were installed (a second one while
/// stopping: the user insists). Safe to call from any thread.
int stop_signal_count();

/// Tracks (`tracked` true) or forgets a temporary file or folder that a process ended at
/// once while stopping (a second signal, the deadline, a grace) removes: the files
/// unlinked, then the folders emptied of their files (one level) and removed. At most 64
/// at once and paths under 4096 bytes: false when it is not
/// tracked (no free slot, too long) or, forgetting, was not. Any thread; use RunSession
/// (run_session.hpp), which owns these for a command.
bool stop_track_temporary(const std::string& path, bool tracked);

/// While alive, `path` is a tracked temporary (stop_track_temporary), so a stop removes it:
/// a file written under a temporary name and then renamed (write_file_atomically's
/// PATH.tmp.XXXXXX, a trace being created, a history entry); the guard ends once the file
/// is renamed or removed. Not tracked when no slot is free (stop_track_temporary's false).
/// Any thread.
class TrackedTemporary {
 public:
  /// `path`: copied.
  explicit TrackedTemporary(std::string path);
  TrackedTemporary(const TrackedTemporary&) = delete;
  TrackedTemporary& operator=(const TrackedTemporary&) = delete;
  /// Forgets the path (stop_track_temporary), when it was tracked.
  ~TrackedTemporary();

 private:
  std::string path_;
  bool tracked_;  ///< stop_track_temporary's answer
};

/// Tracks or forgets a child process group (its id, > 0) that a process ended at once
/// while stopping kills (SIGKILL to the group), so no child outlives octocd. At most 64 at
/// once: false when it is not tracked or, forgetting, was not. Any thread.
bool stop_track_child(int group, bool tracked);

/// Kills the tracked child process groups and removes the tracked temporary files and
/// folders now (what exit_now does on its way out), forgetting them all: the end of a
/// command's own stop path (RunSession::stopped).
void stop_clean_up();

/// "SIGINT", "SIGTERM" or "signal N".
const char* stop_signal_name(int sig);

/// What the process keeps should it end at once while stopping (a second signal, the
/// deadline, a StopWithin's grace), e.g. "the trace t.h5 holds frames 1..40 (its last
/// flush)"; the line on stderr then ends with "; <text>". Copied (at most 1023 bytes);
/// "" clears it. Call from the thread that runs the command, at most once a frame or so
/// (a ring of four buffers: a handler never reads one being rewritten).
void set_stop_kept(const std::string& text);

/// What the process keeps, read back when it ends at once while stopping (a second signal,
/// the deadline, a StopWithin's grace) instead of a text set beforehand: `reader` runs on a
/// thread of its own (never in the signal handler; the process's other threads go on) and
/// returns the text set_stop_kept would give, read from the output itself (e.g. `run`'s
/// trace: the committed rows in the file once no flush is in flight); the line on stderr
/// then ends with "; <its text>" and the process ends with 128 + sig. When it returns ""
/// or throws, or has not returned within `bound_s` (the process ends then all the same),
/// set_stop_kept's text is used. An empty function clears it; `reader` must stay callable
/// until cleared. Call from the thread that runs the command (not while a stop ends it).
void set_stop_kept_reader(std::function<std::string()> reader, double bound_s = 0.2);

/// Installs handlers for SIGINT and SIGTERM that record the signal (see stop_signal) and
/// clears any signal recorded before; the destructor restores the previous handlers.
/// `deadline_s` > 0: the process ends at most that long after the first signal, with
/// 128 + sig and one line "octocd: stopped by SIG...: stopping took longer than its
/// bound; <set_stop_kept's text>" when the command has not returned by then (a 20 ms
/// SIGALRM tick checks it, ITIMER_REAL). 0: no deadline.
/// `second`: SecondSignal::EndsAtOnce (the default) ends the process at once on a second
/// signal, saying what it keeps; SecondSignal::Recorded only counts it (stop_signal_count)
/// for a command whose main thread stays responsive and writes what it keeps itself (e.g.
/// `validate`, whose verdict of the frames judged so far must not be lost); the deadline
/// still holds.
/// One at a time per process (not nestable); not thread-safe to construct.
enum class SecondSignal { EndsAtOnce, Recorded };

class StopOnSignals {
 public:
  explicit StopOnSignals(double deadline_s = 0.0, SecondSignal second = SecondSignal::EndsAtOnce);
  ~StopOnSignals();
  StopOnSignals(const StopOnSignals&) = delete;
  StopOnSignals& operator=(const StopOnSignals&) = delete;
};

/// While alive (inside a StopOnSignals), a SIGINT or SIGTERM ends the process at once
/// with stop_exit_code(sig), after one line on stderr "octocd: stopped by SIG... while
/// <what>; nothing was written": for work that polls no flag and has nothing to flush
/// (loading a scene and its meshes in assimp, checking or judging a trace another engine
/// wrote), so a signal is honoured within a second there too (issue 22). A signal
/// recorded before the guard is honoured when it is constructed. Not nestable.
class StopAtOnce {
 public:
  /// `what`: a short phrase, e.g. "loading the scene"; must outlive the guard.
  explicit StopAtOnce(const char* what);
  ~StopAtOnce();
  StopAtOnce(const StopAtOnce&) = delete;
  StopAtOnce& operator=(const StopAtOnce&) = delete;
};

/// Around one long step of work that polls no flag (an engine's step() on a big scene: a
/// frame may take seconds): while alive (inside a StopOnSignals), a SIGINT or SIGTERM
/// that the loop does not reach within `grace_s` ends the process: one line on stderr
/// "octocd: stopped by SIG... while <what>" and exit stop_exit_code(sig). Within the grace
/// the guard is destroyed as usual and the loop polls stop_signal() and stops cleanly
/// (flush, summary). `what` says what is kept, since nothing more is written, e.g.
/// "run stepped frame 12 of 100; the trace t.h5 holds frames 1..10 (its last flush)".
/// The grace counts from the signal (a signal recorded before the guard: from its
/// construction). Uses SIGALRM (ITIMER_REAL). Not nestable, not with StopAtOnce.
class StopWithin {
 public:
  /// `what`: copied. `grace_s` > 0.
  StopWithin(std::string what, double grace_s = 0.5);
  ~StopWithin();
  StopWithin(const StopWithin&) = delete;
  StopWithin& operator=(const StopWithin&) = delete;

 private:
  std::string what_;
  double grace_s_;
};

}  // namespace octocd
