// The validators' reference pair set (octocd/exact_pairs.hpp): `flat`'s set through a
// hierarchical uniform grid.
#include "octocd/exact_pairs.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <functional>
#include <string>

#include <fmt/format.h>

#include "parallel.hpp"

namespace octocd {

namespace {

using Cell = std::array<std::int64_t, 3>;

/// One box's presence in one cell of a level.
struct Entry {
  Cell cell;
  std::uint32_t box;
};

/// (cell, box) in lexicographic order, compared coordinate by coordinate (std::array's
/// operators go through memcmp for == and a generic loop for <).
bool entry_less(const Entry& x, const Entry& y) {
  if (x.cell[0] != y.cell[0]) return x.cell[0] < y.cell[0];
  if (x.cell[1] != y.cell[1]) return x.cell[1] < y.cell[1];
  if (x.cell[2] != y.cell[2]) return x.cell[2] < y.cell[2];
  return x.box < y.box;
}

/// Cell indices are clamped here: far boxes share the border cells (slower, never wrong:
/// the clamp is monotone).
constexpr double kCellClamp = 1099511627776.0;  // 2^40
constexpr int kMaxLevel = 60;

struct Grid {
  std::array<double, 3> origin{};
  std::vector<double> side;  // per level

  std::int64_t index(double x, int k, int level) const {
    const double c = std::floor((x - origin[k]) / side[level]);
    return static_cast<std::int64_t>(std::clamp(c, -kCellClamp, kCellClamp));
  }
};

struct Hull {
  std::array<double, 3> lo, hi;
};

/// Below this many boxes the default is one thread (threads cost more than they save).
constexpr std::size_t kSerialBelow = 4096;

unsigned thread_count(const ExactPairsSettings& s, std::size_t n) {
  if (s.threads > 0) return static_cast<unsigned>(s.threads);
  return loop_threads(0, n, kSerialBelow);
}

/// a + b, saturating at UINT64_MAX.
std::uint64_t add_saturating(std::uint64_t a, std::uint64_t b) { return a > UINT64_MAX - b ? UINT64_MAX : a + b; }

/// k (k - 1) / 2, saturating.
std::uint64_t pairs_of(std::uint64_t k) {
  if (k < 2) return 0;
  const std::uint64_t x = k % 2 == 0 ? k / 2 : k, y = k % 2 == 0 ? k - 1 : (k - 1) / 2;
  return y != 0 && x > UINT64_MAX / y ? UINT64_MAX : x * y;
}

std::string limit_message(std::uint64_t count, bool tests, std::uint64_t limit, std::size_t bodies) {
  const std::uint64_t pairs = bodies == 0 ? 0 : limit / (tests ? limits::kCandidateTestsPerPair : 1) / bodies;
  if (tests)
    return fmt::format("{} bodies' boxes crowd together: {} candidate pair tests (boxes sharing a grid cell), more "
                       "than the limit {} ({} tests for each of {} pairs a body); allowed: at most {} overlapping "
                       "pairs a body (coincident or piled-up bodies are refused)",
                       bodies, count, limit, limits::kCandidateTestsPerPair, pairs, pairs);
  return fmt::format("{} bodies' boxes overlap in {} pairs, more than the limit {} ({} pairs a body); allowed: at "
                     "most {} overlapping pairs a body (coincident or piled-up bodies are refused)",
                     bodies, count, limit, pairs, pairs);
}

/// Where each cell's entries lie in one level's sorted entries, for the cells of a dense
/// span (counting_sort_entries): cell c's are [begin(c), end(c)), found in O(1) where a
/// binary search over the entries costs log2(entries) comparisons of three coordinates.
struct DenseCells {
  bool dense = false;  ///< false: no index (the entries were sorted by comparisons)
  Cell lo{};
  std::array<std::uint64_t, 3> span{};
  std::vector<std::size_t> end;  ///< per cell rank: one past its last entry
  /// The cell's rank in the span, or false when it lies outside.
  bool rank(const Cell& c, std::uint64_t& r) const {
    for (int k = 0; k < 3; ++k)
      if (c[k] < lo[k] || std::uint64_t(c[k] - lo[k]) >= span[k]) return false;
    r = (std::uint64_t(c[0] - lo[0]) * span[1] + std::uint64_t(c[1] - lo[1])) * span[2] + std::uint64_t(c[2] - lo[2]);
    return true;
  }
  /// [first, last) of cell c's entries (first == last: none).
  void range(const Cell& c, std::size_t& first, std::size_t& last) const {
    std::uint64_t r = 0;
    if (!rank(c, r)) {
      first = last = 0;
      return;
    }
    first = r == 0 ? 0 : end[r - 1];
    last = end[r];
  }
};

/// Fewest boxes (or cell entries) whose per-item passes (hulls, levels, cell entries and
/// their ranks, the limit's lookups, the three pair searches, the pairs' sort) run on
/// threads: below it one thread costs less than waking another.
constexpr std::size_t kParallelBoxesFrom = 1024;

/// Sorts one level's entries into entry_less's order when the cells they span number at
/// most 4 x the entries + 1024: a stable counting sort on the cell's lexicographic rank
/// (the entries are appended in box order, and a box is in a cell once, so equal cells keep
/// their boxes ascending), leaving each cell's entries located in `index`. False (nothing
/// done, `index` not dense) when the cells are too many. The span and each entry's rank
/// are found on `threads` threads (from kParallelBoxesFrom entries), the counts and the
/// scatter on the caller; `buffer` and `ranks` are work space.
bool counting_sort_entries(std::vector<Entry>& e, DenseCells& index, std::vector<Entry>& buffer,
                           std::vector<std::uint64_t>& ranks, unsigned threads) {
  index.dense = false;
  if (e.size() < 2) return true;
  const unsigned th = e.size() >= kParallelBoxesFrom ? std::max(threads, 1u) : 1u;
  const std::function<bool()> never;
  std::vector<std::array<Cell, 2>> part(th, {e[0].cell, e[0].cell});  // per worker: lowest, highest
  parallel_items_on(e.size(), th, never, [&](std::size_t i, unsigned worker) {
    std::array<Cell, 2>& b = part[worker];
    for (int k = 0; k < 3; ++k) {
      b[0][k] = std::min(b[0][k], e[i].cell[k]);
      b[1][k] = std::max(b[1][k], e[i].cell[k]);
    }
  });
  Cell lo = e[0].cell, hi = e[0].cell;
  for (const std::array<Cell, 2>& b : part)
    for (int k = 0; k < 3; ++k) {
      lo[k] = std::min(lo[k], b[0][k]);
      hi[k] = std::max(hi[k], b[1][k]);
    }
  const std::uint64_t limit = 4 * std::uint64_t(e.size()) + 1024;
  std::array<std::uint64_t, 3> span{};
  std::uint64_t cells = 1;
  for (int k = 0; k < 3; ++k) {
    span[k] = std::uint64_t(hi[k] - lo[k]) + 1;  // cell indices lie within +-2^40
    if (span[k] > limit || cells > limit / span[k]) return false;
    cells *= span[k];
  }
  index.lo = lo;
  index.span = span;
  ranks.resize(e.size());
  parallel_items_on(e.size(), th, never, [&](std::size_t i, unsigned) { index.rank(e[i].cell, ranks[i]); });
  std::vector<std::size_t>& start = index.end;
  start.assign(cells + 1, 0);
  for (std::size_t i = 0; i < e.size(); ++i) ++start[ranks[i] + 1];
  for (std::uint64_t c = 0; c < cells; ++c) start[c + 1] += start[c];
  buffer.resize(e.size());
  for (std::size_t i = 0; i < e.size(); ++i) buffer[start[ranks[i]]++] = e[i];
  // start[r] is now one past cell r's last entry.
  e.swap(buffer);
  index.dense = true;
  return true;
}

/// Whether two cells are the same (three comparisons; std::array's == calls memcmp).
bool same_cell(const Cell& x, const Cell& y) { return x[0] == y[0] && x[1] == y[1] && x[2] == y[2]; }

/// Sorts pairs of boxes below n into Pair order: counted by a, each a's pairs (a body's:
/// few) then sorted by b, those sorts on `threads` threads. `start`, `fill` and `buffer` are
/// work space (their memory kept by the caller); `buffer` ends holding v's old elements.
void sort_pairs(std::vector<Pair>& v, std::size_t n, std::vector<std::size_t>& start, std::vector<std::size_t>& fill,
                std::vector<Pair>& buffer, unsigned threads) {
  start.assign(n + 1, 0);
  for (const Pair& p : v) ++start[p.a + 1];
  for (std::size_t a = 0; a < n; ++a) start[a + 1] += start[a];
  buffer.resize(v.size());
  fill.assign(start.begin(), start.end() - 1);
  for (const Pair& p : v) buffer[fill[p.a]++] = p;
  parallel_items_on(n, threads, std::function<bool()>(), [&](std::size_t a, unsigned) {
    std::sort(buffer.begin() + std::ptrdiff_t(start[a]), buffer.begin() + std::ptrdiff_t(start[a + 1]),
              [](Pair p, Pair q) { return p.b < q.b; });
  });
  v.swap(buffer);
}

/// One cell's run of two or more entries on a level: [first, last) of its sorted entries.
struct Run {
  int level;
  std::size_t first, last;
};

}  // namespace

/// Every table exact_pairs fills, kept with its memory for the next call.
struct ExactPairsTables::Impl {
  std::vector<Hull> hull;                   ///< per box
  std::vector<int> level;                   ///< per box: its level; -1 NaN, -2 unbounded
  std::vector<double> ext;                  ///< per box: its hull's largest side
  std::vector<double> extents;              ///< the finite boxes' largest sides (their median)
  std::vector<std::array<double, 6>> span;  ///< per worker: the finite hulls' lowest and highest corner
  std::vector<std::uint32_t> entry_count;   ///< per box: its cells on its level
  std::vector<std::size_t> entry_first;     ///< per box: its first entry on its level
  std::vector<std::uint32_t> unbounded;     ///< the unbounded boxes, ascending
  std::vector<std::vector<Entry>> entries;  ///< per level: (cell, box), sorted
  std::vector<Entry> sorted;                ///< the counting sort's output, swapped with a level's entries
  std::vector<std::uint64_t> ranks;         ///< the counting sort's cell rank per entry
  std::vector<DenseCells> cell_index;       ///< per level
  std::vector<Run> runs;                    ///< cells of two or more entries
  std::vector<std::vector<Run>> run_parts;  ///< per part of a level's entries: the runs it begins
  std::vector<std::uint64_t> tests;         ///< per box: step 2's candidate tests (the limit)
  std::vector<std::vector<Pair>> found;     ///< per worker: the pairs it found
  std::vector<std::size_t> pair_start, pair_fill;  ///< sort_pairs' counts
  std::vector<Pair> pairs;                  ///< sort_pairs' output, swapped with the result
};

PairLimitError::PairLimitError(std::uint64_t count_, bool tests_, std::uint64_t limit_, std::size_t bodies_)
    : InputError(limit_message(count_, tests_, limit_, bodies_)),
      count(count_),
      tests(tests_),
      limit(limit_),
      bodies(bodies_) {}

PairLimitError::PairLimitError(const std::string& message, const PairLimitError& from)
    : InputError(message), count(from.count), tests(from.tests), limit(from.limit), bodies(from.bodies) {}

void exact_pairs(const std::vector<Aabb>& boxes, std::vector<Pair>& out, const ExactPairsSettings& settings) {
  ExactPairsTables tables;
  exact_pairs(boxes, out, settings, tables);
}

void exact_pairs(const std::vector<Aabb>& boxes, std::vector<Pair>& out, const ExactPairsSettings& settings,
                 ExactPairsTables& tables) {
  out.clear();
  const std::size_t n = boxes.size();
  if (n < 2) return;
  ExactPairsTables::Impl& t = tables.impl();
  const unsigned threads = thread_count(settings, n);
  // The per-box passes (hulls, levels, cell entries, the limit's lookups, the pair
  // searches) on threads from kParallelBoxesFrom boxes; each box writes its own slots (the
  // searches their worker's list, merged and sorted), so the tables are those of one thread.
  const unsigned box_threads = n >= kParallelBoxesFrom ? threads : 1u;
  const std::function<bool()> never;
  // Hulls; NaN boxes (which overlap nothing) and unbounded ones set apart.
  std::vector<Hull>& hull = t.hull;
  std::vector<int>& level = t.level;  // -1: NaN (skipped), -2: unbounded (tested against all)
  std::vector<double>& ext = t.ext;
  hull.resize(n);
  level.resize(n);
  ext.resize(n);
  t.span.assign(std::max(box_threads, 1u), {HUGE_VAL, HUGE_VAL, HUGE_VAL, -HUGE_VAL, -HUGE_VAL, -HUGE_VAL});
  parallel_items_on(n, box_threads, never, [&](std::size_t i, unsigned worker) {
    const Aabb& b = boxes[i];
    bool nan = false, finite = true;
    double e = 0;
    for (int k = 0; k < 3; ++k) {
      const double lo = b.min[k], hi = b.max[k];
      if (std::isnan(lo) || std::isnan(hi)) nan = true;
      if (!std::isfinite(lo) || !std::isfinite(hi)) finite = false;
      hull[i].lo[k] = std::min(lo, hi);
      hull[i].hi[k] = std::max(lo, hi);
      e = std::max(e, hull[i].hi[k] - hull[i].lo[k]);
    }
    ext[i] = e;
    level[i] = nan ? -1 : !finite ? -2 : 0;
    if (level[i] == 0) {
      std::array<double, 6>& s = t.span[worker];
      for (int k = 0; k < 3; ++k) {
        s[k] = std::min(s[k], hull[i].lo[k]);
        s[3 + k] = std::max(s[3 + k], hull[i].hi[k]);
      }
    }
  });
  std::array<double, 3> lowest{HUGE_VAL, HUGE_VAL, HUGE_VAL}, highest{-HUGE_VAL, -HUGE_VAL, -HUGE_VAL};
  for (const std::array<double, 6>& s : t.span)
    for (int k = 0; k < 3; ++k) {
      lowest[k] = std::min(lowest[k], s[k]);
      highest[k] = std::max(highest[k], s[3 + k]);
    }
  std::vector<double>& extents = t.extents;
  extents.clear();
  for (std::size_t i = 0; i < n; ++i)
    if (level[i] == 0) extents.push_back(ext[i]);
  Grid grid;
  double c0 = 1.0;
  if (!extents.empty()) {
    std::nth_element(extents.begin(), extents.begin() + extents.size() / 2, extents.end());
    c0 = extents[extents.size() / 2];
    if (!(c0 > 0)) {  // mostly points: about one box per cell of the occupied span
      double span = 0;
      for (int k = 0; k < 3; ++k) span = std::max(span, highest[k] - lowest[k]);
      c0 = span > 0 ? span / std::cbrt(double(extents.size())) : 1.0;
    }
    grid.origin = lowest;
  }
  if (!(c0 > 0) || !std::isfinite(c0)) c0 = 1.0;
  for (int l = 0, done = 0; l <= kMaxLevel && !done; ++l) {
    grid.side.push_back(std::ldexp(c0, l));
    done = !std::isfinite(grid.side.back() * 2);
  }
  const int levels = int(grid.side.size());
  // A box's range of cells on level l.
  auto cell_range = [&](std::uint32_t a, int l, Cell& lo, Cell& hi) {
    for (int k = 0; k < 3; ++k) {
      lo[k] = grid.index(hull[a].lo[k], k, l);
      hi[k] = grid.index(hull[a].hi[k], k, l);
    }
  };
  // Each bounded box's level (the lowest whose side is at least its largest side) and its
  // count of cells there; a box wider than every level joins the unbounded ones.
  std::vector<std::uint32_t>& entry_count = t.entry_count;
  entry_count.resize(n);
  parallel_items_on(n, box_threads, never, [&](std::size_t i, unsigned) {
    entry_count[i] = 0;
    if (level[i] < 0) return;
    int l = 0;
    while (l < levels && ext[i] > grid.side[l]) ++l;
    if (l == levels) {
      level[i] = -2;
      return;
    }
    level[i] = l;
    Cell lo, hi;
    cell_range(std::uint32_t(i), l, lo, hi);
    std::uint64_t cells = 1;  // at most 3 a side (a side within the cell's, rounded)
    for (int k = 0; k < 3; ++k) cells *= std::uint64_t(hi[k] - lo[k] + 1);
    entry_count[i] = std::uint32_t(cells);
  });
  // Each box's entries follow the entries of the boxes before it on its level (box order,
  // as a serial pass appends them), then are written on threads.
  std::vector<std::uint32_t>& unbounded = t.unbounded;
  unbounded.clear();
  std::vector<int> used(levels, 0);
  std::vector<std::size_t> level_size(levels, 0);
  std::vector<std::size_t>& entry_first = t.entry_first;
  entry_first.resize(n);
  for (std::size_t i = 0; i < n; ++i) {
    if (level[i] == -2) unbounded.push_back(std::uint32_t(i));
    if (level[i] < 0) continue;
    const auto l = std::size_t(level[i]);
    used[l] = 1;
    entry_first[i] = level_size[l];
    level_size[l] += entry_count[i];
  }
  if (t.entries.size() < std::size_t(levels)) t.entries.resize(std::size_t(levels));
  if (t.cell_index.size() < std::size_t(levels)) t.cell_index.resize(std::size_t(levels));
  std::vector<std::vector<Entry>>& entries = t.entries;
  for (int l = 0; l < levels; ++l) entries[std::size_t(l)].resize(level_size[std::size_t(l)]);
  parallel_items_on(n, box_threads, never, [&](std::size_t i, unsigned) {
    const int l = level[i];
    if (l < 0) return;
    Cell lo, hi;
    cell_range(std::uint32_t(i), l, lo, hi);
    Entry* e = entries[std::size_t(l)].data() + entry_first[i];
    for (std::int64_t x = lo[0]; x <= hi[0]; ++x)
      for (std::int64_t y = lo[1]; y <= hi[1]; ++y)
        for (std::int64_t z = lo[2]; z <= hi[2]; ++z) *e++ = {{x, y, z}, std::uint32_t(i)};
  });
  std::vector<DenseCells>& cell_index = t.cell_index;
  for (int l = 0; l < levels; ++l)
    if (!counting_sort_entries(entries[std::size_t(l)], cell_index[std::size_t(l)], t.sorted, t.ranks, box_threads))
      parallel_sort(entries[std::size_t(l)], threads, entry_less);

  // The cell of the lowest corner of two hulls' intersection, on `l`.
  auto reference_cell = [&](std::uint32_t a, std::uint32_t b, int l) {
    Cell c;
    for (int k = 0; k < 3; ++k) c[k] = grid.index(std::max(hull[a].lo[k], hull[b].lo[k]), k, l);
    return c;
  };
  std::vector<std::vector<Pair>>& found = t.found;
  if (found.size() < std::max(threads, 1u)) found.resize(std::max(threads, 1u));
  for (std::vector<Pair>& f : found) f.clear();
  auto emit = [&](unsigned worker, std::uint32_t a, std::uint32_t b) {
    found[worker].push_back(a < b ? Pair{a, b} : Pair{b, a});
  };

  // 1. Pairs of one level, in their shared cell (every level's cells, one list). A level's
  // runs are found in parts of its entries on threads: a run belongs to the part holding
  // its first entry (it may reach beyond it), and the parts' lists joined in order are the
  // list of a serial scan.
  std::vector<Run>& runs = t.runs;
  runs.clear();
  const std::size_t parts = box_threads > 1 ? std::size_t(box_threads) * 4 : 1;
  if (t.run_parts.size() < parts) t.run_parts.resize(parts);
  for (int l = 0; l < levels; ++l) {
    const std::vector<Entry>& e = entries[std::size_t(l)];
    const std::size_t level_parts = e.size() >= kParallelBoxesFrom ? parts : 1;
    parallel_items_on(level_parts, level_parts > 1 ? box_threads : 1u, never, [&](std::size_t q, unsigned) {
      std::vector<Run>& found_runs = t.run_parts[q];
      found_runs.clear();
      std::size_t k = e.size() * q / level_parts;
      const std::size_t end = e.size() * (q + 1) / level_parts;
      while (k > 0 && k < end && same_cell(e[k].cell, e[k - 1].cell)) ++k;  // a run begun before the part
      while (k < end) {
        std::size_t j = k + 1;
        while (j < e.size() && same_cell(e[j].cell, e[k].cell)) ++j;
        if (j - k > 1) found_runs.push_back({l, k, j});
        k = j;
      }
    });
    for (std::size_t q = 0; q < level_parts; ++q) runs.insert(runs.end(), t.run_parts[q].begin(), t.run_parts[q].end());
  }

  int finest_used = levels;
  for (int l = levels - 1; l >= 0; --l)
    if (used[std::size_t(l)]) finest_used = l;
  bool coarser = false;
  for (int l = finest_used + 1; l < levels; ++l) coarser = coarser || used[std::size_t(l)];
  auto cell_less = [](const Entry& en, const Cell& key) { return en.cell < key; };
  // Step 2's lookups of box a: visit(l, cell, first, last) for every cell of every coarser
  // used level in a's range, [first, last) the entries of that cell (through the level's
  // dense index where its entries were counting-sorted, else a binary search).
  auto each_coarser_cell = [&](std::uint32_t a, auto&& visit) {
    for (int l = level[a] + 1; l < levels; ++l) {
      if (!used[std::size_t(l)]) continue;
      const std::vector<Entry>& e = entries[std::size_t(l)];
      const DenseCells& index = cell_index[std::size_t(l)];
      Cell lo, hi;
      cell_range(a, l, lo, hi);
      for (std::int64_t x = lo[0]; x <= hi[0]; ++x)
        for (std::int64_t y = lo[1]; y <= hi[1]; ++y)
          for (std::int64_t z = lo[2]; z <= hi[2]; ++z) {
            const Cell c{x, y, z};
            if (index.dense) {
              std::size_t f = 0, to = 0;
              index.range(c, f, to);
              visit(l, c, e.begin() + std::ptrdiff_t(f), e.begin() + std::ptrdiff_t(to));
              continue;
            }
            const auto first = std::lower_bound(e.begin(), e.end(), c, cell_less);
            auto last = first;
            while (last != e.end() && last->cell == c) ++last;
            visit(l, c, first, last);
          }
    }
  };

  // The limit: the candidate tests counted before any test (O(n log n): run lengths and
  // the lookups of step 2, never a pair), the pairs found after.
  const std::uint64_t max_pairs =
      settings.max_pairs_per_body == 0
          ? 0
          : (settings.max_pairs_per_body > UINT64_MAX / n ? UINT64_MAX : settings.max_pairs_per_body * n);
  if (max_pairs > 0) {
    const std::uint64_t max_tests = max_pairs > UINT64_MAX / limits::kCandidateTestsPerPair
                                        ? UINT64_MAX
                                        : max_pairs * limits::kCandidateTestsPerPair;
    std::uint64_t tests = 0;
    for (const Run& run : runs) tests = add_saturating(tests, pairs_of(run.last - run.first));
    tests = add_saturating(tests, pairs_of(unbounded.size()));
    const std::uint64_t rest = n - unbounded.size();
    tests = add_saturating(tests, unbounded.size() > 0 && rest > UINT64_MAX / unbounded.size()
                                      ? UINT64_MAX
                                      : std::uint64_t(unbounded.size()) * rest);
    if (tests > max_tests) throw PairLimitError(tests, true, max_tests, n);
    if (coarser) {
      // Step 2's lookups, each box's cells' boxes counted on threads, then summed in box
      // order and stopped once past the limit (the count a serial pass stops at).
      std::vector<std::uint64_t>& box_tests = t.tests;
      box_tests.resize(n);
      parallel_items_on(n, box_threads, never, [&](std::size_t i, unsigned) {
        std::uint64_t c = 0;
        const std::uint32_t a = std::uint32_t(i);
        if (level[a] >= 0)
          each_coarser_cell(a, [&](int, const Cell&, auto first, auto last) {
            c = add_saturating(c, std::uint64_t(last - first));
          });
        box_tests[i] = c;
      });
      for (std::size_t i = 0; i < n && tests <= max_tests; ++i) tests = add_saturating(tests, box_tests[i]);
      if (tests > max_tests) throw PairLimitError(tests, true, max_tests, n);
    }
  }

  parallel_items_on(runs.size(), std::min<unsigned>(box_threads, unsigned(std::max<std::size_t>(runs.size(), 1))), never,
                    [&](std::size_t r, unsigned worker) {
    const Run& run = runs[r];
    const std::vector<Entry>& e = entries[std::size_t(run.level)];
    for (std::size_t p = run.first; p < run.last; ++p)
      for (std::size_t q = p + 1; q < run.last; ++q) {
        const std::uint32_t a = e[p].box, b = e[q].box;
        if (overlaps_all_axes(boxes[a], boxes[b]) && same_cell(reference_cell(a, b, run.level), e[p].cell)) emit(worker, a, b);
      }
  });

  // 2. A box against the boxes of every coarser level, in its own range of their cells.
  if (coarser)
    parallel_items_on(n, box_threads, never, [&](std::size_t i, unsigned worker) {
      const std::uint32_t a = std::uint32_t(i);
      if (level[a] < 0) return;
      each_coarser_cell(a, [&](int l, const Cell& c, auto first, auto last) {
        for (auto it = first; it != last; ++it) {
          const std::uint32_t b = it->box;
          if (overlaps_all_axes(boxes[a], boxes[b]) && same_cell(reference_cell(a, b, l), c)) emit(worker, a, b);
        }
      });
    });

  // 3. Unbounded boxes against every other box (pairs of two unbounded boxes once).
  parallel_items_on(unbounded.size(), std::min<unsigned>(box_threads, unsigned(std::max<std::size_t>(unbounded.size(), 1))),
                    never, [&](std::size_t u, unsigned worker) {
    const std::uint32_t a = unbounded[u];
    for (std::uint32_t b = 0; b < n; ++b) {
      if (b == a || level[b] == -1 || (level[b] == -2 && b < a)) continue;
      if (overlaps(boxes[a], boxes[b])) emit(worker, a, b);
    }
  });

  std::size_t total = 0;
  for (const auto& f : found) total += f.size();
  if (max_pairs > 0 && total > max_pairs) throw PairLimitError(total, false, max_pairs, n);
  out.reserve(total);
  for (const auto& f : found) out.insert(out.end(), f.begin(), f.end());
  sort_pairs(out, n, t.pair_start, t.pair_fill, t.pairs, box_threads);  // every index is below n
}

ExactPairsTables::ExactPairsTables() : impl_(std::make_unique<Impl>()) {}
ExactPairsTables::~ExactPairsTables() = default;
ExactPairsTables::ExactPairsTables(ExactPairsTables&&) noexcept = default;
ExactPairsTables& ExactPairsTables::operator=(ExactPairsTables&&) noexcept = default;
ExactPairsTables::Impl& ExactPairsTables::impl() {
  if (!impl_) impl_ = std::make_unique<Impl>();  // a moved-from object is usable again
  return *impl_;
}

namespace {

class ExactPairsBroadPhase final : public BroadPhase {
 public:
  explicit ExactPairsBroadPhase(const ExactPairsSettings& s) : settings_(s) {}
  std::string name() const override { return "exact-grid"; }
  void find_pairs(const std::vector<Aabb>& boxes, std::vector<Pair>& out, BroadPhaseStats& stats) override {
    exact_pairs(boxes, out, settings_);
    stats.pairs = out.size();
    stats.cell_candidates = out.size();
    stats.memory_bytes = 0;
  }

 private:
  ExactPairsSettings settings_;
};

}  // namespace

std::unique_ptr<BroadPhase> make_exact_pairs_broadphase(const ExactPairsSettings& settings) {
  return std::make_unique<ExactPairsBroadPhase>(settings);
}

}  // namespace octocd
