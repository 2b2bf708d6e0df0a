// The worker team of octocd/parallel.hpp: every item once, a stalled worker never holds
// up the items it did not claim, exceptions and stops, nested and concurrent loops; the
// tuner that runs a loop on the team or on its caller alone.
#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <cstdint>
#include <cmath>
#include <condition_variable>
#include <mutex>
#include <stdexcept>
#include <thread>
#include <vector>

#include "../../core/src/loop_tuner.hpp"
#include "octocd/parallel.hpp"

// This file's own names (its tests compile in unity batches with the folder's other files).
namespace octocd_test_parallel {

namespace {

using octocd::LoopOptions;

LoopOptions with(int threads, std::size_t chunk = 0) {
  LoopOptions o;
  o.threads = threads;
  o.chunk = chunk;
  return o;
}

TEST(Parallel, EveryItemRunsOnceOnAWorkerBelowTheLoopThreads) {
  for (int threads : {1, 2, 3, 8}) {
    for (std::size_t n : {std::size_t{0}, std::size_t{1}, std::size_t{7}, std::size_t{100000}}) {
      std::vector<std::atomic<int>> runs(n);
      std::atomic<unsigned> worst_worker{0};
      const unsigned bound = octocd::loop_threads(n, with(threads));
      EXPECT_LE(bound, static_cast<unsigned>(threads));
      const bool done = octocd::parallel_for(n, with(threads), [&](std::size_t i, unsigned w) {
        runs[i].fetch_add(1);
        unsigned seen = worst_worker.load();
        while (w > seen && !worst_worker.compare_exchange_weak(seen, w)) {
        }
      });
      EXPECT_TRUE(done);
      for (std::size_t i = 0; i < n; ++i) ASSERT_EQ(runs[i].load(), 1) << "item " << i << ", " << threads << " threads";
      if (n > 0) {
        EXPECT_LT(worst_worker.load(), std::max(1u, bound)) << threads << " threads, " << n << " items";
      }
    }
  }
}

// A worker that claimed an item and then stalls holds up only that item: the caller does
// every other one. The stalled item waits (on an event, no sleep) until all the others
// are done, so the loop can only end if the caller took them all.
TEST(Parallel, TheCallerDoesEveryItemAStalledWorkerDidNotClaim) {
  constexpr std::size_t n = 2000;
  std::mutex m;
  std::condition_variable cv;
  std::size_t done = 0;
  std::atomic<std::size_t> by_caller{0}, by_workers{0};
  const bool finished = octocd::parallel_for(n, with(2, 1), [&](std::size_t, unsigned w) {
    std::unique_lock<std::mutex> lock(m);
    if (w != 0) {
      cv.wait(lock, [&] { return done == n - 1; });  // stalls until the caller did the rest
      ++by_workers;
    } else {
      ++by_caller;
    }
    ++done;
    cv.notify_all();
  });
  EXPECT_TRUE(finished);
  EXPECT_EQ(done, n);
  EXPECT_LE(by_workers.load(), 1u);  // one chunk of one item at most
  EXPECT_GE(by_caller.load(), n - 1);
}

TEST(Parallel, TheFirstExceptionIsRethrownAndTheTeamStaysUsable) {
  for (int threads : {1, 3}) {
    std::atomic<std::size_t> ran{0};
    EXPECT_THROW(octocd::parallel_for(10000, with(threads, 4),
                                      [&](std::size_t i, unsigned) {
                                        ++ran;
                                        if (i == 5000) throw std::runtime_error("item 5000");
                                      }),
                 std::runtime_error);
    if (threads == 1) {
      EXPECT_EQ(ran.load(), 5001u);  // the items after the throw are skipped
    }
    std::atomic<std::size_t> again{0};
    EXPECT_TRUE(octocd::parallel_for(1000, with(threads), [&](std::size_t, unsigned) { ++again; }));
    EXPECT_EQ(again.load(), 1000u);
  }
}

TEST(Parallel, AStopSkipsTheItemsNotStarted) {
  for (int threads : {1, 2}) {
    std::atomic<std::size_t> ran{0};
    LoopOptions o = with(threads, 8);
    o.stop = [&] { return ran.load() >= 100; };
    EXPECT_FALSE(octocd::parallel_for(100000, o, [&](std::size_t, unsigned) { ++ran; }));
    if (threads == 1) {
      EXPECT_EQ(ran.load(), 104u);  // polled between chunks of 8
    }
    EXPECT_GE(ran.load(), 100u);
    o.stop = [] { return false; };
    ran = 0;
    EXPECT_TRUE(octocd::parallel_for(5000, o, [&](std::size_t, unsigned) { ++ran; }));
    EXPECT_EQ(ran.load(), 5000u);
  }
}

TEST(Parallel, AStopPollThatThrowsIsRethrownAfterTheWorkersLeft) {
  for (int threads : {1, 2}) {
    std::atomic<std::size_t> ran{0};
    LoopOptions o = with(threads, 8);
    o.stop = [&]() -> bool {
      if (ran.load() >= 100) throw std::runtime_error("stop poll");
      return false;
    };
    EXPECT_THROW(octocd::parallel_for(100000, o, [&](std::size_t, unsigned) { ++ran; }), std::runtime_error);
    std::atomic<std::size_t> again{0};
    EXPECT_TRUE(octocd::parallel_for(1000, with(threads), [&](std::size_t, unsigned) { ++again; }));
    EXPECT_EQ(again.load(), 1000u);
  }
}

TEST(Parallel, ALoopInsideAnItemRunsSeriallyOnItsThread) {
  std::atomic<int> wrong{0};
  std::atomic<std::size_t> inner{0};
  octocd::parallel_for(64, with(4, 1), [&](std::size_t, unsigned) {
    if (octocd::current_threads() != 1) ++wrong;
    if (octocd::loop_threads(1000, with(4)) != 1) ++wrong;
    const std::thread::id me = std::this_thread::get_id();
    octocd::parallel_for(1000, with(4), [&](std::size_t, unsigned w) {
      if (w != 0 || std::this_thread::get_id() != me) ++wrong;
      ++inner;
    });
  });
  EXPECT_EQ(wrong.load(), 0);
  EXPECT_EQ(inner.load(), 64u * 1000u);
}

// Two callers at once: one gets the team, the other runs its loop alone; both complete.
TEST(Parallel, LoopsFromTwoThreadsAtOnceBothComplete) {
  constexpr std::size_t n = 200000;
  std::vector<std::atomic<int>> a(n), b(n);
  auto fill = [](std::vector<std::atomic<int>>& v) {
    for (int round = 0; round < 20; ++round)
      octocd::parallel_for(v.size(), with(3), [&](std::size_t i, unsigned) { v[i].fetch_add(1); });
  };
  std::thread other([&] { fill(b); });
  fill(a);
  other.join();
  for (std::size_t i = 0; i < n; ++i) {
    ASSERT_EQ(a[i].load(), 20) << i;
    ASSERT_EQ(b[i].load(), 20) << i;
  }
}

TEST(Parallel, ThreadCountSetsTheCallersCountForItsScope) {
  const int outside = octocd::current_threads();
  EXPECT_GE(octocd::default_threads(), 1);
  EXPECT_EQ(outside, octocd::default_threads());
  {
    const octocd::ThreadCount three(3);
    EXPECT_EQ(octocd::current_threads(), 3);
    EXPECT_EQ(octocd::loop_threads(1000, LoopOptions{}), 3u);
    EXPECT_EQ(octocd::loop_threads(2, LoopOptions{}), 2u);  // never more than the items
    LoopOptions few;
    few.min_items = 64;
    EXPECT_EQ(octocd::loop_threads(63, few), 1u);  // below the call site's threshold
    {
      const octocd::ThreadCount dflt(0);
      EXPECT_EQ(octocd::current_threads(), octocd::default_threads());
    }
    EXPECT_EQ(octocd::current_threads(), 3);
    std::thread([] { EXPECT_EQ(octocd::current_threads(), octocd::default_threads()); }).join();  // per thread
  }
  EXPECT_EQ(octocd::current_threads(), outside);
}

// parallel_sort against std::sort: keys drawn from few values (long runs of equal keys across
// the merge paths' cuts) with distinct ids as the tie-break, every size from one chunk to an
// odd number of runs per round, on thread counts that leave a run unpaired.
TEST(Parallel, ParallelSortGivesStdSortsOrderWhateverTheThreadCount) {
  struct Item {
    std::uint32_t key;
    std::uint32_t id;
  };
  const auto less = [](const Item& p, const Item& q) { return p.key != q.key ? p.key < q.key : p.id < q.id; };
  std::uint64_t state = 12345;
  for (const std::size_t n : {std::size_t(4096), std::size_t(5001), std::size_t(65537)}) {
    for (const std::uint32_t values : {2u, 97u, 1u << 30}) {
      std::vector<Item> items(n);
      for (std::size_t i = 0; i < n; ++i) {
        state = state * 6364136223846793005ull + 1442695040888963407ull;
        items[i] = {static_cast<std::uint32_t>((state >> 33) % values), static_cast<std::uint32_t>(i)};
      }
      std::vector<Item> want = items;
      std::sort(want.begin(), want.end(), less);
      for (const unsigned threads : {2u, 3u, 5u, 8u, 13u}) {
        std::vector<Item> got = items;
        octocd::parallel_sort(got, threads, less);
        ASSERT_EQ(got.size(), want.size());
        for (std::size_t i = 0; i < n; ++i) {
          ASSERT_EQ(got[i].id, want[i].id) << "n " << n << ", " << values << " keys, " << threads << " threads, at " << i;
        }
      }
    }
  }
}

}  // namespace


// The tuner of the team (core/src/loop_tuner.hpp), fed with made-up measurements: which way
// each loop runs, when a probe ends, what it decides and how long the choice holds.
namespace tuner {

using octocd::detail::LoopTuner;

constexpr double kWall = 0.0011;  // seconds a loop, where not said

// A made-up process: loops of `wall` seconds one after the other, in which the process gets
// `team_rate` CPU seconds per second when the loop runs on the team and `alone_rate` when
// it runs on its caller alone; after each loop `gap` seconds of serial work at `alone_rate`
// (with `gap_at_loop_rate`, at the rate of the loop before it). It tells the tuner each
// loop's wall time while it probes, as the team does.
struct Process {
  double now = 100.0;
  double cpu = 0.0;
  double gap = 0.0;
  bool gap_at_loop_rate = false;
  int calls = 0;  // of the CPU clock

  // Runs `loops` loops through the tuner; returns how many ran on the team.
  int run(LoopTuner& t, int loops, double wall, double team_rate, double alone_rate) {
    int on_team = 0;
    for (int i = 0; i < loops; ++i) {
      const bool team = t.begin(now, [this] {
        ++calls;
        return cpu;
      });
      const bool probing = t.probing();
      now += wall;
      cpu += wall * (team ? team_rate : alone_rate);
      if (probing) t.ended(wall);
      now += gap;
      cpu += gap * (gap_at_loop_rate && team ? team_rate : alone_rate);
      on_team += team ? 1 : 0;
    }
    return on_team;
  }
};

TEST(LoopTuner, AProbeRunsTeamAloneAloneTeamPhasesAndKeepsTheTeamWhereItGetsMoreCpu) {
  LoopTuner t;
  Process p;
  // 1.1 ms loops: a phase is the loops that start within kPhaseSeconds of its first.
  const int per_phase = static_cast<int>(std::ceil(LoopTuner::kPhaseSeconds / kWall));
  EXPECT_EQ(p.run(t, per_phase, kWall, 1.3, 1.0), per_phase);
  EXPECT_EQ(p.run(t, per_phase, kWall, 1.3, 1.0), 0);
  EXPECT_EQ(p.run(t, per_phase, kWall, 1.3, 1.0), 0);
  EXPECT_TRUE(t.probing());
  EXPECT_EQ(p.run(t, per_phase, kWall, 1.3, 1.0), per_phase);
  EXPECT_EQ(t.decisions(), 0u);
  EXPECT_EQ(p.run(t, 1, kWall, 1.3, 1.0), 1);  // the fifth phase's start decides
  EXPECT_FALSE(t.probing());
  EXPECT_EQ(t.decisions(), 1u);
  EXPECT_TRUE(t.team());
  EXPECT_NEAR(t.last_team_rate(), 1.3, 1e-9);
  EXPECT_NEAR(t.last_alone_rate(), 1.0, 1e-9);
  // The CPU clock was read where phases changed only.
  EXPECT_EQ(p.calls, 5);
  // Settled: on the team, the clock unread, until kSettleSeconds after the decision or
  // kSettleOverAlone x the probe's two phases alone, whichever is later.
  const double decided = p.now - kWall;
  const double alone = 2 * per_phase * kWall;
  const double hold = std::max(LoopTuner::kSettleSeconds, LoopTuner::kSettleOverAlone * alone);
  const int settled = static_cast<int>((hold - 0.002) / kWall);
  EXPECT_EQ(p.run(t, settled, kWall, 1.3, 1.0), settled);
  EXPECT_EQ(p.calls, 5);
  EXPECT_EQ(t.decisions(), 1u);
  p.now = decided + hold + 1e-9;
  p.run(t, 1, kWall, 1.3, 1.0);  // a new probe
  EXPECT_TRUE(t.probing());
}

TEST(LoopTuner, AClearGainEndsTheProbeAfterTwoPhases) {
  LoopTuner t;
  Process p;
  // An idle machine: the team gets 1.6 CPU seconds a second, alone 1.
  const int per_phase = static_cast<int>(std::ceil(LoopTuner::kPhaseSeconds / kWall));
  p.run(t, 2 * per_phase + 1, kWall, 1.6, 1.0);
  EXPECT_FALSE(t.probing());
  EXPECT_TRUE(t.team());
  EXPECT_EQ(t.decisions(), 1u);
  // A many-core machine: 10 CPU seconds a second on the team end the probe after its
  // first phase (no phase alone, which would cost a loop at a tenth of its speed).
  LoopTuner many;
  Process m;
  m.run(many, per_phase + 1, kWall, 10.0, 1.0);
  EXPECT_FALSE(many.probing());
  EXPECT_TRUE(many.team());
  EXPECT_EQ(many.last_alone_rate(), 0.0);
  // Below the clear gain the probe goes on to its four phases.
  LoopTuner u;
  Process q;
  q.run(u, 2 * per_phase + 1, kWall, 0.99 * LoopTuner::kClearGain, 1.0);
  EXPECT_TRUE(u.probing());
}

TEST(LoopTuner, TheCallerAloneIsChosenBelowTheGainAndTheTeamIsProbedAgain) {
  LoopTuner t;
  Process p;
  // Beside one busy process on two cores a woken worker shares the caller's core: about
  // the same CPU a second either way.
  p.run(t, 80, kWall, 1.05, 1.0);
  ASSERT_EQ(t.decisions(), 1u);
  EXPECT_FALSE(t.team());
  EXPECT_EQ(p.run(t, 900, kWall, 1.05, 1.0), 0);  // 0.99 s: alone, the clock unread
  EXPECT_EQ(t.decisions(), 1u);
  p.now += LoopTuner::kSettleOverAlone * 0.04;  // past 100 x its two phases alone (< 40 ms)
  // The load went away: the next probe gives the team back.
  p.run(t, 80, kWall, 1.9, 1.0);
  EXPECT_EQ(t.decisions(), 2u);
  EXPECT_TRUE(t.team());
  // Just above the gain the team is kept, just below it not. Beside two busy processes
  // the caller alone gets part of a core and the team wins with less than one.
  LoopTuner above, below, shared;
  Process a, b, c;
  a.run(above, 80, kWall, 1.01 * LoopTuner::kTeamGain, 1.0);
  b.run(below, 80, kWall, 0.99 * LoopTuner::kTeamGain, 1.0);
  c.run(shared, 80, kWall, 0.8, 0.5);
  EXPECT_EQ(above.decisions() + below.decisions() + shared.decisions(), 3u);
  EXPECT_TRUE(above.team());
  EXPECT_FALSE(below.team());
  EXPECT_TRUE(shared.team());
}

TEST(LoopTuner, LongLoopsMakeLongPhasesAndTheChoiceHoldsLongerTheLongerItsTimeAlone) {
  LoopTuner t;
  Process p;
  // Loops of 0.5 s: each phase one loop; the team clearly ahead (below the sure rate), so
  // two phases.
  p.run(t, 3, 0.5, 2.0, 1.0);
  ASSERT_EQ(t.decisions(), 1u);
  EXPECT_TRUE(t.team());
  // Its phase alone took 0.5 s: the choice holds for kSettleOverAlone x that.
  const double decided = p.now - 0.5;
  Process later = p;
  later.now = decided + 0.99 * LoopTuner::kSettleOverAlone * 0.5;
  later.run(t, 1, kWall, 2.0, 1.0);
  EXPECT_FALSE(t.probing());
  later.now = decided + LoopTuner::kSettleOverAlone * 0.5;
  later.run(t, 1, kWall, 2.0, 1.0);
  EXPECT_TRUE(t.probing());
}

TEST(LoopTuner, SparseLoopsBetweenLongSerialPartsAreJudgedByTheLoopsAlone) {
  // A validator's rows: 2 ms loops between 30 ms of serial work. On an idle machine the
  // loops run twice as fast on the team but the phases' whole rates are 1.06 and 1.0 (the team
  // would lose at kTeamGain); the loops' own rates decide: the team.
  LoopTuner t;
  Process p;
  p.gap = 0.030;
  // Each phase one loop and its serial part; the clear gain ends the probe at the third
  // loop's start.
  p.run(t, 3, 0.002, 2.0, 1.0);
  ASSERT_EQ(t.decisions(), 1u);
  EXPECT_TRUE(t.team());
  EXPECT_NEAR(t.last_team_rate(), 2.0, 1e-9);
  EXPECT_NEAR(t.last_alone_rate(), 1.0, 1e-9);
  // The choice holds kSettleSeconds: the probe's loop alone took 2 ms (its phase alone 32 ms,
  // whose 100 x would hold it 3.2 s: the serial part costs the same either way).
  const double decided = p.now - 0.032;
  Process later = p;
  later.now = decided + 0.99 * LoopTuner::kSettleSeconds;
  later.run(t, 1, 0.002, 2.0, 1.0);
  EXPECT_FALSE(t.probing());
  later.now = decided + LoopTuner::kSettleSeconds + 1e-9;
  later.run(t, 1, 0.002, 2.0, 1.0);
  EXPECT_TRUE(t.probing());
  // Beside one busy process the same loops get no more CPU on the team: the caller alone.
  LoopTuner busy;
  Process q;
  q.gap = 0.020;
  q.run(busy, 10, 0.002, 1.0, 1.0);
  ASSERT_EQ(busy.decisions(), 1u);
  EXPECT_FALSE(busy.team());
  // Serial parts that get more CPU while the team is chosen (beside two busy processes the
  // workers' share of the cores reaches them) count for the team.
  LoopTuner shared;
  Process r;
  r.gap = 0.020;
  r.gap_at_loop_rate = true;
  r.run(shared, 3, 0.002, 0.8, 0.5);
  ASSERT_EQ(shared.decisions(), 1u);
  EXPECT_TRUE(shared.team());
}

}  // namespace tuner

}  // namespace octocd_test_parallel
