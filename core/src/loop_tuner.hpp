#pragma once
/// \file loop_tuner.hpp
/// Whether the worker team's loops run on the team or on their caller alone, chosen from
/// measurement (design.md section 4, "Threads on a shared machine"; issue 77 item 1: more
/// threads are never slower than one, at any load).
///
/// A loop on the team is faster than on its caller alone only when the scheduler runs the
/// workers beside the caller. On an idle machine it does; beside one busy process on two
/// cores a woken worker shares the caller's core instead (the kernel places it there), and
/// the loop takes longer than the caller alone would; beside two, the team's threads get a
/// larger share of the cores than one thread does. So the tuner measures both ways in turn
/// and compares the CPU the process gets per second of loop (CPU time of all its threads
/// over the loops' wall time; the work is the same either way):
///   1. a probe: loops alternate between the team and the caller alone (both see the same
///      load) until each way has kProbeLoops loops and kProbeSeconds of loop time (or
///      either has kProbeLongSeconds, for loops too long to count); kProbeSeconds spans
///      several of the kernel's scheduling periods, so a share of a core shows as such,
///   2. the team when its CPU per loop second is >= kTeamGain x the caller's alone, else
///      the caller alone, for kSettleSeconds (and at least kSettleOverProbe x the caller
///      alone's loop time in the probe, so a probe of long loops costs a bounded share),
///      then 1. again.
/// Results never depend on the choice (parallel.hpp: each item writes its own result).
/// Not thread-safe: the team calls it under a lock.

#include <algorithm>
#include <cstdint>

namespace octocd::detail {

/// The probe-and-settle state machine of the file comment. Times in seconds on a steady
/// clock, CPU in seconds of the whole process (all threads).
class LoopTuner {
 public:
  /// Loops and loop seconds of each way in a probe; a probe also ends when either way
  /// has kProbeLongSeconds.
  static constexpr int kProbeLoops = 4;
  static constexpr double kProbeSeconds = 0.01;
  static constexpr double kProbeLongSeconds = 0.05;
  /// The team is kept when its CPU per loop second is at least this times the caller's
  /// alone (the rest is what waking and feeding workers costs without a gain).
  static constexpr double kTeamGain = 1.25;
  /// How long a choice holds before the next probe, at least, and at least this many
  /// times the caller-alone loop seconds of the probe.
  static constexpr double kSettleSeconds = 1.0;
  static constexpr double kSettleOverProbe = 50.0;

  /// How the next loop runs: on the team or not, and whether it is measured (then the
  /// caller passes its wall and CPU seconds to end()).
  struct Use {
    bool team = true;
    bool measure = false;
  };

  /// At a loop's start, `now` in seconds.
  Use begin(double now) {
    if (!probing_) {
      if (now < settled_until_) return {team_, false};
      team_probe_ = Probe{};
      alone_probe_ = Probe{};
      probing_ = true;
      next_on_team_ = true;
    }
    const bool team = next_on_team_;
    next_on_team_ = !next_on_team_;
    return {team, true};
  }

  /// After a measured loop: how it ran, its wall seconds, the process's CPU seconds
  /// meanwhile, and `now`. Ignored outside a probe.
  void end(bool team, double wall_s, double cpu_s, double now) {
    if (!probing_) return;
    Probe& p = team ? team_probe_ : alone_probe_;
    ++p.loops;
    p.wall += std::max(0.0, wall_s);
    p.cpu += std::max(0.0, cpu_s);
    const bool enough = (team_probe_.full() && alone_probe_.full()) ||
                        (team_probe_.wall >= kProbeLongSeconds && alone_probe_.loops > 0) ||
                        (alone_probe_.wall >= kProbeLongSeconds && team_probe_.loops > 0);
    if (!enough) return;
    team_ = team_probe_.rate() >= kTeamGain * alone_probe_.rate();
    settled_until_ = now + std::max(kSettleSeconds, kSettleOverProbe * alone_probe_.wall);
    probing_ = false;
    ++decisions_;
    last_team_rate_ = team_probe_.rate();
    last_alone_rate_ = alone_probe_.rate();
  }

  /// Whether a probe is under way; the last probe's choice (true: the team; true before
  /// any); how many probes have decided.
  bool probing() const { return probing_; }
  bool team() const { return team_; }
  std::uint64_t decisions() const { return decisions_; }
  /// The last decided probe's CPU per loop second on the team and alone (0 before one).
  double last_team_rate() const { return last_team_rate_; }
  double last_alone_rate() const { return last_alone_rate_; }

 private:
  struct Probe {
    int loops = 0;
    double wall = 0.0;
    double cpu = 0.0;
    bool full() const { return loops >= kProbeLoops && wall >= kProbeSeconds; }
    double rate() const { return wall > 0.0 ? cpu / wall : 0.0; }
  };

  bool probing_ = false;
  bool next_on_team_ = true;
  bool team_ = true;
  double settled_until_ = -1e300;  // the first loop starts a probe
  Probe team_probe_, alone_probe_;
  std::uint64_t decisions_ = 0;
  double last_team_rate_ = 0.0, last_alone_rate_ = 0.0;
};

}  // namespace octocd::detail
