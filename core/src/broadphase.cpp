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
#include "octocd/strict_octree.hpp"

namespace octocd {

namespace detail {

void sort_pairs(std::vector<Pair>& pairs, std::size_t n, std::vector<Pair>& tmp,
                std::vector<std::uint32_t>& count) {
  const std::size_t m = pairs.size();
  if (m < 2) return;
  if (m < 64) {
    std::sort(pairs.begin(), pairs.end());
    return;
  }
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
