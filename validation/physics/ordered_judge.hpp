#pragma once
/// \file ordered_judge.hpp
/// A row's serial tally loop run on the validators' threads with the serial loop's
/// verdict, figures, examples and texts bit for bit (internal to validation/physics).
///
/// A row judges items [0, n) in order with a body `judge(first, last, sums, tallies...)`
/// written once, generic in the types it writes to: the row's own state (`sums`, the
/// Impl itself or a block's DrySums with the same member names) and its Tallies (Tally,
/// or a block's DryTally). judge_in_order runs it in blocks of kOrderedBlock items:
///  1. every block on the threads into its own DrySums and DryTallies (no text written:
///     a DryTally counts its checks, whether all passed and their largest figure);
///  2. then, block by block in order, on the calling thread: a block none of whose checks
///     would write a description in the live tallies (every check passed, and none beats
///     the worst the tally holds: Tally::check's only other step is ++checks) adds its
///     counts to the tallies and merges its sums (DrySums::merge_into: counts added,
///     largest figures kept, lists appended, all in block order); any other block (a
///     failure, a new worst, or a figure DrySums::describes says the live state would
///     describe) is judged again live, exactly as the serial loop judges it.
/// So the tallies see every check in item order with the serial loop's effect, and the
/// result does not depend on the thread count or on the blocks' order on the threads.
/// On one thread (or fewer than `serial_below` items) the body runs live, block by block.
/// `stop` is polled before every block on the calling thread and between the threads'
/// chunks (the body itself need not poll).

#include <array>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <limits>
#include <tuple>
#include <utility>
#include <vector>

#include "../src/parallel.hpp"
#include "physics_impl.hpp"

namespace octocd::physics_detail {

/// Items a block of judge_in_order holds: about 10^3 blocks on the lattice's 240,534
/// contact pairs, each merged in a few dozen instructions, and a replayed block (a failure
/// or a new worst: few once a tally's worst has settled) costs 256 items on the calling
/// thread.
constexpr std::size_t kOrderedBlock = 256;

/// A Tally's checks of one block judged off the calling thread: counted, never described.
struct DryTally {
  std::uint64_t checks = 0;
  bool all_ok = true;
  double top = -std::numeric_limits<double>::infinity();  ///< the largest figure (Tally::worst's rule)
  template <class F>
  void check(bool ok, double figure, const Where&, F&&) {
    ++checks;
    all_ok = all_ok && ok;
    if (figure > top) top = figure;
  }
  template <class F>
  void check(bool ok, double figure, F&& describe) {
    check(ok, figure, Where{}, std::forward<F>(describe));
  }
  void judged() {
    ++checks;
    if (0.0 > top) top = 0.0;
  }
  /// Whether `t`, given these checks in turn, would describe one: a failure, or a figure
  /// above its worst (Tally::check writes a text for both).
  bool describes(const Tally& t) const { return !all_ok || top > t.worst; }
  /// These checks added to `t` where none describes (Tally::check then only counts).
  void add_to(Tally& t) const { t.checks += checks; }
};

/// Runs `judge` over items [0, n) as the file comment says: `live` is the row's own
/// state (the Impl), `tallies` its tallies in the order `judge` takes them; DrySums is
/// default-constructible with the members `judge` writes, `merge_into(live)` and
/// `describes(live)` (a figure of the block the live state would write a text for).
template <class DrySums, class Live, std::size_t N, class Judge>
void judge_in_order(std::size_t n, int threads, std::size_t serial_below, const std::function<bool()>& stop,
                    Live& live, const std::array<Tally*, N>& tallies, Judge&& judge) {
  const std::size_t blocks = (n + kOrderedBlock - 1) / kOrderedBlock;
  // Block b live on the calling thread, `stop` polled before it.
  auto live_judge = [&](std::size_t b) {
    if (stop && stop()) throw ValidationStopped();
    std::apply([&](auto*... t) { judge(b * kOrderedBlock, std::min(n, (b + 1) * kOrderedBlock), live, *t...); },
               tallies);
  };
  const unsigned th = loop_threads(threads, n, serial_below);
  if (th <= 1 || blocks < 2) {
    for (std::size_t b = 0; b < blocks; ++b) live_judge(b);
    return;
  }
  struct Block {
    DrySums sums;
    std::array<DryTally, N> t;
  };
  std::vector<Block> dry(blocks);
  parallel_items_on(blocks, static_cast<unsigned>(std::min<std::size_t>(th, blocks)), stop,
                    [&](std::size_t b, unsigned) {
    Block& d = dry[b];
    std::apply([&](auto&... t) { judge(b * kOrderedBlock, std::min(n, (b + 1) * kOrderedBlock), d.sums, t...); },
               d.t);
  });
  for (std::size_t b = 0; b < blocks; ++b) {
    const Block& d = dry[b];
    bool replay = d.sums.describes(live);
    for (std::size_t k = 0; k < N; ++k) replay = replay || d.t[k].describes(*tallies[k]);
    if (replay) {
      live_judge(b);
      continue;
    }
    d.sums.merge_into(live);
    for (std::size_t k = 0; k < N; ++k) d.t[k].add_to(*tallies[k]);
  }
}

}  // namespace octocd::physics_detail
