/// \file broadphase.cpp
/// Broadphase factory (the core rows of octocd/broadphase_table.def), `auto` octree depths,
/// the shared pair sort and the `flat` oracle (design.md section 5.1). `octree` (loose) is in
/// broadphase_octree_cache.cpp, `octree-strict` in broadphase_octree_strict.cpp,
/// `spatial-hash` in broadphase_spatial_hash.cpp.

#include "octocd/broadphase.hpp"

#include "broadphase_detail.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>

#include "octocd/error.hpp"
#include "octocd/loose_octree.hpp"
#include "octocd/parallel.hpp"
#include "octocd/strict_octree.hpp"

namespace octocd {

namespace detail {

namespace {

/// The fewest pairs whose sort runs on the worker team (octocd/parallel.hpp): below, the
/// two counting passes on one thread cost less than waking others.
constexpr std::size_t kParallelPairsFrom = 32768;

/// The most buckets (and input chunks) of the parallel sort: its table of counts holds
/// their product.
constexpr std::size_t kMaxBuckets = 256;

/// Runs of one `a` longer than this are sorted by b with std::sort, the others by
/// insertion (most runs hold a few pairs, nearly in order).
constexpr std::size_t kInsertionRunMax = 32;

/// The serial sort: a stable counting sort by b, then by a (tmp: m pairs, count: n + 1).
void sort_pairs_serial(std::vector<Pair>& pairs, std::size_t n, std::vector<Pair>& tmp,
                       std::vector<std::uint32_t>& count) {
  const std::size_t m = pairs.size();
  tmp.resize(m);
  count.assign(n + 1, 0);
  // Pass 1: by b, pairs -> tmp.
  for (const Pair& p : pairs) ++count[p.b + 1];
  for (std::size_t i = 1; i <= n; ++i) count[i] += count[i - 1];
  for (const Pair& p : pairs) tmp[count[p.b]++] = p;
  // Pass 2 (stable): by a, tmp -> pairs.
  std::fill(count.begin(), count.end(), 0u);
  for (const Pair& p : tmp) ++count[p.a + 1];
  for (std::size_t i = 1; i <= n; ++i) count[i] += count[i - 1];
  for (const Pair& p : tmp) pairs[count[p.a]++] = p;
}

}  // namespace

void sort_pairs(std::vector<Pair>& pairs, std::size_t n, std::vector<Pair>& tmp,
                std::vector<std::uint32_t>& count, unsigned threads) {
  const std::size_t m = pairs.size();
  if (m < 2) return;
  if (m < 64) {
    std::sort(pairs.begin(), pairs.end());
    return;
  }
  if (threads == 0) {
    LoopOptions by_pairs;
    by_pairs.min_items = kParallelPairsFrom;
    threads = loop_threads(m, by_pairs);
  }
  if (threads <= 1 || n < 2) {
    sort_pairs_serial(pairs, n, tmp, count);
    return;
  }
  // Buckets of consecutive a: bucket(a) = a B / n, bucket b holding a in [lo(b), lo(b + 1))
  // with lo(b) = ceil(b n / B). The input is cut into B chunks; each chunk's pairs go to
  // tmp, bucket after bucket (chunk order within a bucket); then each bucket is put in
  // order by a into its own range of `pairs` (a counting sort over its a, its counts in
  // count[lo(b), lo(b + 1))), each a's run sorted by b. Every step on the team; the order is
  // the one (a, b) order, whatever the thread count.
  const std::size_t buckets = std::min<std::size_t>(std::size_t(threads) * 8, kMaxBuckets);
  const auto bucket_of = [&](std::uint32_t a) {
    return static_cast<std::size_t>(std::uint64_t{a} * buckets / n);  // < 2^32 * 2^8: no overflow
  };
  const auto lo = [&](std::size_t b) {
    return static_cast<std::size_t>((std::uint64_t{b} * n + buckets - 1) / buckets);
  };
  tmp.resize(m);
  count.resize(n + 1);
  std::vector<std::size_t> at(buckets * buckets, 0);  // [chunk * buckets + bucket]
  LoopOptions one_each;
  one_each.threads = static_cast<int>(threads);
  one_each.chunk = 1;
  Pair* const in = pairs.data();
  Pair* const mid = tmp.data();
  parallel_for(buckets, one_each, [&](std::size_t c, unsigned) {
    std::vector<std::size_t> local(buckets, 0);
    for (std::size_t i = m * c / buckets; i < m * (c + 1) / buckets; ++i) ++local[bucket_of(in[i].a)];
    std::copy(local.begin(), local.end(), at.begin() + static_cast<std::ptrdiff_t>(c * buckets));
  });
  std::vector<std::size_t> begin(buckets + 1, 0);
  std::size_t sum = 0;
  for (std::size_t b = 0; b < buckets; ++b) {
    begin[b] = sum;
    for (std::size_t c = 0; c < buckets; ++c) {
      const std::size_t k = at[c * buckets + b];
      at[c * buckets + b] = sum;
      sum += k;
    }
  }
  begin[buckets] = sum;
  parallel_for(buckets, one_each, [&](std::size_t c, unsigned) {
    std::vector<std::size_t> local(at.begin() + static_cast<std::ptrdiff_t>(c * buckets),
                                   at.begin() + static_cast<std::ptrdiff_t>((c + 1) * buckets));
    for (std::size_t i = m * c / buckets; i < m * (c + 1) / buckets; ++i) mid[local[bucket_of(in[i].a)]++] = in[i];
  });
  std::uint32_t* const cnt = count.data();
  parallel_for(buckets, one_each, [&](std::size_t b, unsigned) {
    const std::size_t a0 = lo(b), a1 = lo(b + 1), first = begin[b], last = begin[b + 1];
    std::fill(cnt + a0, cnt + a1, 0u);
    for (std::size_t i = first; i < last; ++i) ++cnt[mid[i].a];
    std::uint32_t run = 0;  // each a's start (relative to first), then its end
    for (std::size_t a = a0; a < a1; ++a) {
      const std::uint32_t k = cnt[a];
      cnt[a] = run;
      run += k;
    }
    for (std::size_t i = first; i < last; ++i) in[first + cnt[mid[i].a]++] = mid[i];
    std::size_t start = first;
    for (std::size_t a = a0; a < a1; ++a) {
      const std::size_t end = first + cnt[a];
      if (end - start > kInsertionRunMax) {
        std::sort(in + start, in + end);
      } else {
        for (std::size_t i = start + 1; i < end; ++i) {
          const Pair x = in[i];
          std::size_t j = i;
          for (; j > start && x.b < in[j - 1].b; --j) in[j] = in[j - 1];
          in[j] = x;
        }
      }
      start = end;
    }
  });
}

}  // namespace detail

namespace {

/// The oracle: every one of the n(n-1)/2 pairs through Eq. 6. Output is produced in
/// (a, b) order directly.
class FlatBroadPhase final : public BroadPhase {
 public:
  std::string name() const override { return broadphase_name(BroadPhaseId::flat); }

  void find_pairs(const std::vector<Aabb>& boxes, std::vector<Pair>& out,
                  BroadPhaseStats& stats) override {
    out.clear();
    const std::size_t n = boxes.size();
    for (std::size_t i = 0; i < n; ++i) {
      const Aabb bi = boxes[i];
      for (std::size_t j = i + 1; j < n; ++j) {
        if (overlaps(bi, boxes[j])) {
          out.push_back({static_cast<std::uint32_t>(i), static_cast<std::uint32_t>(j)});
        }
      }
    }
    stats.cell_candidates = static_cast<std::uint64_t>(n) * (n == 0 ? 0 : n - 1) / 2;
    stats.pairs = out.size();
    stats.memory_bytes = 0;  // no structures of its own
  }
};

/// A CPU factory of a row of octocd/broadphase_table.def.
using HostFactory = std::unique_ptr<BroadPhase> (*)(const BroadPhaseConfig&, const Aabb&);

/// The core factory of every row, in the table's order (nullptr where another library or
/// no CPU builds it).
#define OCTOCD_CORE_FACTORY_core(ID) &detail::make_host_##ID
#define OCTOCD_CORE_FACTORY_bullet(ID) nullptr
#define OCTOCD_CORE_FACTORY_fcl(ID) nullptr
#define OCTOCD_CORE_FACTORY_none(ID) nullptr
constexpr HostFactory kCoreFactories[] = {
#define OCTOCD_BROADPHASE(ID, NAME, HOST, DEVICE, PAIRS, COST, SUMMARY) OCTOCD_CORE_FACTORY_##HOST(ID),
#include "octocd/broadphase_table.def"
#undef OCTOCD_BROADPHASE
};

}  // namespace

namespace detail {

std::unique_ptr<BroadPhase> make_host_flat(const BroadPhaseConfig&, const Aabb&) {
  return std::make_unique<FlatBroadPhase>();
}

}  // namespace detail

std::vector<std::string> broadphase_names() {
  return broadphase_names_where([](const BroadPhaseInfo& b) { return b.host == BroadPhaseHost::core; });
}

void check_broadphase_parameters(const BroadPhaseConfig& config) {
  if (config.octree_depth < -1 || config.octree_depth > 10) {
    std::ostringstream msg;
    msg << "broadphase.depth: " << config.octree_depth
        << " is out of range (expected -1 = auto, or an integer in [0, 10])";
    throw InputError(msg.str());
  }
  if (!(std::isfinite(config.cell_size) && config.cell_size > 0.0f)) {
    std::ostringstream msg;
    msg << "broadphase.cell_size: " << config.cell_size
        << " is out of range (expected a finite number > 0, in m)";
    throw InputError(msg.str());
  }
}

std::unique_ptr<BroadPhase> make_broadphase(const BroadPhaseConfig& config, const Aabb& domain) {
  check_broadphase_parameters(config);
  if (const BroadPhaseInfo* info = find_broadphase_info(config.name)) {
    if (const HostFactory make = kCoreFactories[static_cast<std::size_t>(info->id)]) return make(config, domain);
  }
  throw InputError("broadphase.name: unknown broadphase '" + config.name +
                   "'; allowed: " + join_broadphase_names(broadphase_names()));
}

int auto_octree_depth(const std::vector<Aabb>& boxes, const Aabb& domain) {
  // Mean body extent = mean over bodies of the longest side of the AABB (bodies with a
  // non-finite or negative side are left out of the mean).
  // (octocd/strict_octree.hpp: the same terms and decision as the CUDA engine's.)
  double sum = 0.0;
  std::size_t count = 0;
  for (const Aabb& b : boxes) {
    const double e = strict_auto_extent(b);
    if (strict_auto_counts(e)) {
      sum += e;
      ++count;
    }
  }
  return strict_auto_depth(sum, count, domain);
}

int auto_loose_octree_depth(const std::vector<Aabb>& boxes, const Aabb& domain) {
  const LooseGrid grid = loose_grid(domain);
  float min_ext = std::numeric_limits<float>::infinity();
  for (const Aabb& b : boxes) {
    if (loose_has_nan(b)) continue;
    float ext = loose_unit_extent(loose_unit(grid, b.min), loose_unit(grid, b.max));
    if (ext < 0.0f) ext = 0.0f;
    if (ext < min_ext) min_ext = ext;
  }
  return loose_auto_depth(min_ext);
}

}  // namespace octocd
