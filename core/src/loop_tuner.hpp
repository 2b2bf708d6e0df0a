#pragma once
/// \file loop_tuner.hpp
/// Whether the worker team's loops run on the team or on their caller alone, chosen from
/// measurement (design.md section 4, "Threads on a shared machine"; issue 77 item 1: more
/// threads are never slower than one, at any load).
///
/// A loop on the team is faster than on its caller alone only when the scheduler runs the
/// workers beside the caller. On an idle machine it does; beside one busy process on two
/// cores a woken worker shares the caller's core instead (the kernel places it there), and
/// the loop takes longer than on the caller alone; beside two, the team's threads get a
/// larger share of the cores than one thread does, and a worker goes on with the loop while
/// the caller waits for a core. So the tuner measures both ways in turn and compares the
/// CPU the process gets per wall second (all its threads; the work is the same either way):
///   1. a probe of four phases, each at least kPhaseSeconds (several of the kernel's
///      scheduling periods, so a share of a core shows as such), its loops on the team,
///      alone, alone, on the team (a drift of the load hits both ways alike); it ends
///      after one where the team's loops get kSureTeamRate CPU seconds a second, after two
///      where they get kClearGain x alone's,
///   2. the team when its loops' CPU per second is >= kTeamGain x alone's, else the caller
///      alone, for kSettleSeconds and at least kSettleOverAlone x the wall time of the
///      probe's loops alone (so those loops, the costly ones where the team wins, take at
///      most 1% of the time, stretched as they may be by a long loop), then 1. again.
/// The team's loops' rate: the team phases' CPU less what one thread gets outside the loops
/// (alone's rate; at most 1 before a phase alone), over the loops' wall time (ended()).
/// A phase is mostly serial where loops are sparse between long serial parts (a
/// validator's row, a large scene's set-up): its rate on the team is near 1 even where its
/// loops run twice as fast, and the loops' rate keeps the choice about the loops.
/// Anything the team gets outside its loops (beside busy processes the workers' share of
/// the cores reaches the caller's serial parts too) counts for the team.
/// Phases change at a loop's start; the process's CPU time is read only there.
/// Results never depend on the choice (parallel.hpp: each item writes its own result).
/// Not thread-safe: the team calls it under a lock.

#include <algorithm>
#include <cstdint>

namespace octocd::detail {

/// The probe-and-settle state machine of the file comment. Times in seconds on a steady
/// clock, CPU in seconds of the whole process (all threads).
class LoopTuner {
 public:
  /// The least wall time of each of the probe's four phases.
  static constexpr double kPhaseSeconds = 0.015;
  /// The team is kept when the process's CPU per second on it is at least this times
  /// alone's (less is what waking and feeding workers costs without a gain: beside one
  /// busy process on two cores 0.99-1.00 against 0.99). The ratio is the team's speed-up
  /// of the whole process, serial parts included, so a margin above it would give up
  /// that much where loops are a small part of the work.
  static constexpr double kTeamGain = 1.08;
  /// A probe ends after its first two phases when the team gets at least this times
  /// alone's CPU per second (an idle machine: 1.6 on two cores).
  static constexpr double kClearGain = 1.4;
  /// A probe ends after its first phase when the team gets at least this many CPU seconds
  /// a second: more than one thread alone and a helper thread of the process could (an idle
  /// 16-core host: 8-12). It spares the phase alone where it costs most: on 16 threads a
  /// loop of 9 ms on the team takes 140 ms alone.
  static constexpr double kSureTeamRate = 2.5;
  /// How long a choice holds before the next probe, at least, and at least this many
  /// times the wall time of the probe's phases alone.
  static constexpr double kSettleSeconds = 1.0;
  static constexpr double kSettleOverAlone = 100.0;

  /// Whether the loop starting at `now` (seconds) runs on the team. `cpu` returns the
  /// process's CPU seconds; it is called only where a phase starts or ends. While
  /// probing() after it, the loop's wall time goes to ended().
  template <class Cpu>
  bool begin(double now, Cpu&& cpu) {
    if (phase_ < 0) {
      if (now < settled_until_) return team_;
      phase_ = 0;
      phase_start_ = now;
      phase_cpu_ = cpu();
      phase_loops_ = 0.0;
      team_cpu_ = team_wall_ = team_loops_ = alone_cpu_ = alone_wall_ = alone_loops_ = 0.0;
      return kPhaseTeam[0];
    }
    if (now - phase_start_ < kPhaseSeconds) return kPhaseTeam[phase_];
    const double c = cpu();
    const double wall = now - phase_start_;
    (kPhaseTeam[phase_] ? team_cpu_ : alone_cpu_) += std::max(0.0, c - phase_cpu_);
    (kPhaseTeam[phase_] ? team_wall_ : alone_wall_) += wall;
    (kPhaseTeam[phase_] ? team_loops_ : alone_loops_) += std::min(phase_loops_, wall);
    ++phase_;
    const double alone_rate = alone_wall_ > 0.0 ? alone_cpu_ / alone_wall_ : 0.0;
    const double team_rate = team_loop_rate(alone_wall_ > 0.0 ? alone_rate : 1.0);
    const bool clear = (phase_ == 1 && team_rate >= kSureTeamRate) || (phase_ == 2 && team_rate >= kClearGain * alone_rate);
    if (phase_ < kPhases && !clear) {
      phase_start_ = now;
      phase_cpu_ = c;
      phase_loops_ = 0.0;
      return kPhaseTeam[phase_];
    }
    last_team_rate_ = team_rate;
    last_alone_rate_ = alone_rate;
    team_ = team_rate >= kTeamGain * alone_rate;
    settled_until_ = now + std::max(kSettleSeconds, kSettleOverAlone * alone_loops_);
    phase_ = -1;
    ++decisions_;
    return team_;
  }

  /// A loop that began() during a probe ran for `wall` seconds (on the team or alone, as
  /// begin() said); nothing outside a probe.
  void ended(double wall) {
    if (phase_ >= 0) phase_loops_ += std::max(0.0, wall);
  }

  /// Whether a probe is under way; the last probe's choice (true: the team; true before
  /// any); how many probes have decided.
  bool probing() const { return phase_ >= 0; }
  bool team() const { return team_; }
  std::uint64_t decisions() const { return decisions_; }
  /// The last probe's CPU seconds per wall second in the team's loops (as the file comment
  /// reckons it) and alone (0 before one).
  double last_team_rate() const { return last_team_rate_; }
  double last_alone_rate() const { return last_alone_rate_; }

 private:
  static constexpr int kPhases = 4;
  static constexpr bool kPhaseTeam[kPhases] = {true, false, false, true};

  /// The team phases' CPU per second in their loops, where one thread outside them gets
  /// `serial_rate`; the phases' whole rate where no loop's time was told (ended()).
  double team_loop_rate(double serial_rate) const {
    if (team_wall_ <= 0.0) return 0.0;
    if (team_loops_ <= 0.0) return team_cpu_ / team_wall_;
    return std::max(0.0, team_cpu_ - serial_rate * (team_wall_ - team_loops_)) / team_loops_;
  }

  int phase_ = -1;  // -1: settled
  bool team_ = true;
  double settled_until_ = -1e300;  // the first loop starts a probe
  double phase_start_ = 0.0, phase_cpu_ = 0.0, phase_loops_ = 0.0;
  double team_cpu_ = 0.0, team_wall_ = 0.0, team_loops_ = 0.0;
  double alone_cpu_ = 0.0, alone_wall_ = 0.0, alone_loops_ = 0.0;
  std::uint64_t decisions_ = 0;
  double last_team_rate_ = 0.0, last_alone_rate_ = 0.0;
};

}  // namespace octocd::detail
