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

/// Sorts one level's entries into entry_less's order when the cells they span number at
/// most 4 x the entries + 1024: a stable counting sort on the cell's lexicographic rank
/// (the entries are appended in box order, and a box is in a cell once, so equal cells keep
/// their boxes ascending), leaving each cell's entries located in `index`. False (nothing
/// done, `index` not dense) when the cells are too many.
bool counting_sort_entries(std::vector<Entry>& e, DenseCells& index) {
  index.dense = false;
  if (e.size() < 2) return true;
  Cell lo = e[0].cell, hi = e[0].cell;
  for (const Entry& x : e)
    for (int k = 0; k < 3; ++k) {
      lo[k] = std::min(lo[k], x.cell[k]);
      hi[k] = std::max(hi[k], x.cell[k]);
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
  std::uint64_t r = 0;
  std::vector<std::size_t>& start = index.end;
  start.assign(cells + 1, 0);
  for (const Entry& x : e) {
    index.rank(x.cell, r);
    ++start[r + 1];
  }
  for (std::uint64_t c = 0; c < cells; ++c) start[c + 1] += start[c];
  std::vector<Entry> out(e.size());
  for (const Entry& x : e) {
    index.rank(x.cell, r);
    out[start[r]++] = x;
  }
  // start[r] is now one past cell r's last entry.
  e.swap(out);
  index.dense = true;
  return true;
}

/// Sorts pairs of boxes below n into Pair order: counted by a, each a's pairs (a body's:
/// few) then sorted by b.
void sort_pairs(std::vector<Pair>& v, std::size_t n) {
  std::vector<std::size_t> start(n + 1, 0);
  for (const Pair& p : v) ++start[p.a + 1];
  for (std::size_t a = 0; a < n; ++a) start[a + 1] += start[a];
  std::vector<Pair> out(v.size());
  {
    std::vector<std::size_t> fill(start.begin(), start.end() - 1);
    for (const Pair& p : v) out[fill[p.a]++] = p;
  }
  for (std::size_t a = 0; a < n; ++a)
    std::sort(out.begin() + std::ptrdiff_t(start[a]), out.begin() + std::ptrdiff_t(start[a + 1]),
              [](Pair p, Pair q) { return p.b < q.b; });
  v.swap(out);
}

}  // namespace

PairLimitError::PairLimitError(std::uint64_t count_, bool tests_, std::uint64_t limit_, std::size_t bodies_)
    : InputError(limit_message(count_, tests_, limit_, bodies_)),
      count(count_),
      tests(tests_),
      limit(limit_),
      bodies(bodies_) {}

PairLimitError::PairLimitError(const std::string& message, const PairLimitError& from)
    : InputError(message), count(from.count), tests(from.tests), limit(from.limit), bodies(from.bodies) {}

void exact_pairs(const std::vector<Aabb>& boxes, std::vector<Pair>& out, const ExactPairsSettings& settings) {
  out.clear();
  const std::size_t n = boxes.size();
  if (n < 2) return;
  // Hulls; NaN boxes (which overlap nothing) and unbounded ones set apart.
  std::vector<Hull> hull(n);
  std::vector<int> level(n, 0);  // -1: NaN (skipped), -2: unbounded (tested against all)
  std::vector<double> extents;
  extents.reserve(n);
  std::array<double, 3> lowest{HUGE_VAL, HUGE_VAL, HUGE_VAL}, highest{-HUGE_VAL, -HUGE_VAL, -HUGE_VAL};
  for (std::size_t i = 0; i < n; ++i) {
    const Aabb& b = boxes[i];
    bool nan = false, finite = true;
    double ext = 0;
    for (int k = 0; k < 3; ++k) {
      const double lo = b.min[k], hi = b.max[k];
      if (std::isnan(lo) || std::isnan(hi)) nan = true;
      if (!std::isfinite(lo) || !std::isfinite(hi)) finite = false;
      hull[i].lo[k] = std::min(lo, hi);
      hull[i].hi[k] = std::max(lo, hi);
      ext = std::max(ext, hull[i].hi[k] - hull[i].lo[k]);
    }
    if (nan) {
      level[i] = -1;
    } else if (!finite) {
      level[i] = -2;
    } else {
      extents.push_back(ext);
      for (int k = 0; k < 3; ++k) {
        lowest[k] = std::min(lowest[k], hull[i].lo[k]);
        highest[k] = std::max(highest[k], hull[i].hi[k]);
      }
    }
  }
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
  std::vector<std::uint32_t> unbounded;
  std::vector<std::vector<Entry>> entries(levels);
  std::vector<int> used(levels, 0);
  for (std::size_t i = 0; i < n; ++i) {
    if (level[i] == -1) continue;
    if (level[i] == -2) {
      unbounded.push_back(std::uint32_t(i));
      continue;
    }
    double ext = 0;
    for (int k = 0; k < 3; ++k) ext = std::max(ext, hull[i].hi[k] - hull[i].lo[k]);
    int l = 0;
    while (l < levels && ext > grid.side[l]) ++l;
    if (l == levels) {
      level[i] = -2;
      unbounded.push_back(std::uint32_t(i));
      continue;
    }
    level[i] = l;
    used[l] = 1;
    Cell c0c, c1c;
    for (int k = 0; k < 3; ++k) {
      c0c[k] = grid.index(hull[i].lo[k], k, l);
      c1c[k] = grid.index(hull[i].hi[k], k, l);
    }
    for (std::int64_t x = c0c[0]; x <= c1c[0]; ++x)
      for (std::int64_t y = c0c[1]; y <= c1c[1]; ++y)
        for (std::int64_t z = c0c[2]; z <= c1c[2]; ++z) entries[l].push_back({{x, y, z}, std::uint32_t(i)});
  }
  const unsigned threads = thread_count(settings, n);
  std::vector<DenseCells> cell_index(levels);
  for (int l = 0; l < levels; ++l)
    if (!counting_sort_entries(entries[l], cell_index[l])) parallel_sort(entries[l], threads, entry_less);

  // The cell of the lowest corner of two hulls' intersection, on `l`.
  auto reference_cell = [&](std::uint32_t a, std::uint32_t b, int l) {
    Cell c;
    for (int k = 0; k < 3; ++k) c[k] = grid.index(std::max(hull[a].lo[k], hull[b].lo[k]), k, l);
    return c;
  };
  std::vector<std::vector<Pair>> found(std::max(threads, 1u));
  auto emit = [&](unsigned worker, std::uint32_t a, std::uint32_t b) {
    found[worker].push_back(a < b ? Pair{a, b} : Pair{b, a});
  };
  const std::function<bool()> never;

  // 1. Pairs of one level, in their shared cell (every level's cells, one list).
  struct Run {
    int level;
    std::size_t first, last;
  };
  std::vector<Run> runs;
  for (int l = 0; l < levels; ++l) {
    const std::vector<Entry>& e = entries[l];
    for (std::size_t k = 0; k < e.size();) {
      std::size_t j = k + 1;
      while (j < e.size() && e[j].cell == e[k].cell) ++j;
      if (j - k > 1) runs.push_back({l, k, j});
      k = j;
    }
  }

  int finest_used = levels;
  for (int l = levels - 1; l >= 0; --l)
    if (used[l]) finest_used = l;
  bool coarser = false;
  for (int l = finest_used + 1; l < levels; ++l) coarser = coarser || used[l];
  // A box's range of cells on level l.
  auto cell_range = [&](std::uint32_t a, int l, Cell& lo, Cell& hi) {
    for (int k = 0; k < 3; ++k) {
      lo[k] = grid.index(hull[a].lo[k], k, l);
      hi[k] = grid.index(hull[a].hi[k], k, l);
    }
  };
  auto cell_less = [](const Entry& en, const Cell& key) { return en.cell < key; };
  // Step 2's lookups of box a: visit(l, cell, first, last) for every cell of every coarser
  // used level in a's range, [first, last) the entries of that cell (through the level's
  // dense index where its entries were counting-sorted, else a binary search).
  auto each_coarser_cell = [&](std::uint32_t a, auto&& visit) {
    for (int l = level[a] + 1; l < levels; ++l) {
      if (!used[l]) continue;
      const std::vector<Entry>& e = entries[l];
      const DenseCells& index = cell_index[l];
      Cell lo, hi;
      cell_range(a, l, lo, hi);
      for (std::int64_t x = lo[0]; x <= hi[0]; ++x)
        for (std::int64_t y = lo[1]; y <= hi[1]; ++y)
          for (std::int64_t z = lo[2]; z <= hi[2]; ++z) {
            const Cell c{x, y, z};
            if (index.dense) {
              std::size_t f = 0, t = 0;
              index.range(c, f, t);
              visit(l, c, e.begin() + std::ptrdiff_t(f), e.begin() + std::ptrdiff_t(t));
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
      // Step 2's lookups, counting each cell's boxes (std::equal_range), stopped once past the limit.
      for (std::size_t i = 0; i < n && tests <= max_tests; ++i) {
        const std::uint32_t a = std::uint32_t(i);
        if (level[a] < 0) continue;
        each_coarser_cell(a, [&](int, const Cell&, auto first, auto last) {
          tests = add_saturating(tests, std::uint64_t(last - first));
        });
      }
      if (tests > max_tests) throw PairLimitError(tests, true, max_tests, n);
    }
  }

  parallel_items_on(runs.size(), std::min<unsigned>(threads, unsigned(std::max<std::size_t>(runs.size(), 1))), never,
                    [&](std::size_t r, unsigned worker) {
    const Run& run = runs[r];
    const std::vector<Entry>& e = entries[run.level];
    for (std::size_t p = run.first; p < run.last; ++p)
      for (std::size_t q = p + 1; q < run.last; ++q) {
        const std::uint32_t a = e[p].box, b = e[q].box;
        if (overlaps(boxes[a], boxes[b]) && reference_cell(a, b, run.level) == e[p].cell) emit(worker, a, b);
      }
  });

  // 2. A box against the boxes of every coarser level, in its own range of their cells.
  if (coarser)
    parallel_items_on(n, threads, never, [&](std::size_t i, unsigned worker) {
      const std::uint32_t a = std::uint32_t(i);
      if (level[a] < 0) return;
      each_coarser_cell(a, [&](int l, const Cell& c, auto first, auto last) {
        for (auto it = first; it != last; ++it) {
          const std::uint32_t b = it->box;
          if (overlaps(boxes[a], boxes[b]) && reference_cell(a, b, l) == c) emit(worker, a, b);
        }
      });
    });

  // 3. Unbounded boxes against every other box (pairs of two unbounded boxes once).
  parallel_items_on(unbounded.size(), std::min<unsigned>(threads, unsigned(std::max<std::size_t>(unbounded.size(), 1))),
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
  sort_pairs(out, n);  // every index is below n
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
