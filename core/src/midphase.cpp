/// \file midphase.cpp
/// Midphase over per-mesh octree levels (design.md section 5.2) and the vertex-proximity narrow phase
/// (paper Eq. 7-8, Algorithm A2; design.md section 5.3), and the step's midphase stage (confirm_pairs:
/// every broadphase pair of a frame; gpu/src/midphase.cu is the CUDA engine's).
///
/// The per-pair tests themselves live in octocd/midphase_hd.hpp (OCTOCD_HD functions that
/// the CUDA engine's kernels call too); this file parses level lists and adapts the host
/// octrees to the shared header's views. See midphase_hd.hpp for why pruning is exact.

#include "octocd/midphase.hpp"

#include <algorithm>
#include <cctype>
#include <cmath>

#include "octocd/error.hpp"
#include "octocd/midphase_hd.hpp"
#include "octocd/midphase_views.hpp"
#include "octocd/parallel.hpp"
#include "octocd/stages.hpp"

namespace octocd {
namespace {

/// Pairs from which confirm_pairs runs on the worker team (octocd/parallel.hpp); fewer
/// are cheaper on the calling thread than waking a worker.
constexpr std::size_t kParallelMinPairs = 64;

/// A host octree as the shared header's view.
hd::OctreeView view(const MeshOctree& t) {
  hd::OctreeView v;
  v.depth = t.depth;
  v.bounds = t.bounds;
  v.vertices = t.vertices.data();
  v.vertex_count = static_cast<std::uint32_t>(t.vertices.size());
  v.cells = t.cells.data();
  v.level_offset = t.level_offset.data();
  return v;
}

/// Reused scratch of world vertex positions (grows, never shrinks: no allocation once warm).
std::vector<Vec3>& scratch() {
  thread_local std::vector<Vec3> s;
  return s;
}

std::string trim(const std::string& s) {
  std::size_t b = 0;
  std::size_t e = s.size();
  while (b < e && std::isspace(static_cast<unsigned char>(s[b]))) ++b;
  while (e > b && std::isspace(static_cast<unsigned char>(s[e - 1]))) --e;
  return s.substr(b, e - b);
}

}  // namespace

hd::PlacedView placed_view(const PlacedShape& s) {
  hd::PlacedView v;
  v.is_mesh = s.octree != nullptr;
  if (s.octree) v.octree = view(*s.octree);
  v.position = s.position;
  v.box = s.box;
  return v;
}

hd::LevelList level_list(const MidphaseConfig& cfg) {
  hd::LevelList l;
  l.aabb_only = cfg.aabb_only;
  l.count = static_cast<int>(std::min(cfg.levels.size(), static_cast<std::size_t>(hd::kMidphaseMaxLevels)));
  for (int i = 0; i < l.count; ++i) l.levels[i] = cfg.levels[static_cast<std::size_t>(i)];
  return l;
}

// ---- MidphaseConfig ------------------------------------------------------------------------

MidphaseConfig MidphaseConfig::parse(const std::string& text, const std::string& field) {
  auto bad = [&](const std::string& why) {
    return InputError(field + ": invalid midphase '" + text + "' (" + why +
                      "); allowed: 'aabb-only' or a strictly ascending list of levels in [0, 10], "
                      "e.g. '2', '1,2', '0,1,2', '[1, 2]'");
  };
  std::string s = trim(text);
  MidphaseConfig cfg;
  if (s == "aabb-only") {
    cfg.aabb_only = true;
    cfg.levels.clear();
    return cfg;
  }
  if (!s.empty() && s.front() == '[') {
    if (s.size() < 2 || s.back() != ']') throw bad("unbalanced brackets");
    s = trim(s.substr(1, s.size() - 2));
  }
  if (s.empty()) throw bad("no levels");
  cfg.levels.clear();
  std::size_t pos = 0;
  while (true) {
    const std::size_t comma = s.find(',', pos);
    const std::string tok = trim(s.substr(pos, comma == std::string::npos ? std::string::npos : comma - pos));
    if (tok.empty()) throw bad("empty level");
    if (tok.size() > 2 || !std::all_of(tok.begin(), tok.end(), [](char c) { return c >= '0' && c <= '9'; })) {
      throw bad("'" + tok + "' is not a level in [0, 10]");
    }
    const int level = std::stoi(tok);
    if (level > 10) throw bad("level " + tok + " is outside [0, 10]");
    if (!cfg.levels.empty() && level <= cfg.levels.back()) throw bad("levels must be strictly ascending");
    cfg.levels.push_back(level);
    if (comma == std::string::npos) break;
    pos = comma + 1;
  }
  return cfg;
}

std::string MidphaseConfig::to_string() const {
  if (aabb_only) return "aabb-only";
  std::string s;
  for (std::size_t i = 0; i < levels.size(); ++i) {
    if (i) s += ',';
    s += std::to_string(levels[i]);
  }
  return s;
}

int MidphaseConfig::max_level() const {
  if (aabb_only || levels.empty()) return 0;
  return levels.back();
}

// ---- contact tests --------------------------------------------------------------------------

bool confirm_contact(const PlacedShape& a_in, const PlacedShape& b_in, float theta,
                     const MidphaseConfig& config, MidphaseStats& stats) {
  const hd::PlacedView a = placed_view(a_in);
  const hd::PlacedView b = placed_view(b_in);
  // Scratch for B's filtered world vertices: a leaf cell holds at most all of a mesh's
  // vertices, so this size always takes the cached path (same tests as the uncached one).
  std::vector<Vec3>& s = scratch();
  const std::size_t need = std::max(a_in.octree ? a_in.octree->vertices.size() : 0,
                                    b_in.octree ? b_in.octree->vertices.size() : 0);
  if (s.size() < need) s.resize(need);
  hd::MidphaseCounters n;
  const bool hit = hd::confirm_contact(a, b, theta, level_list(config), n, s.data(),
                                       static_cast<std::uint32_t>(s.size()));
  stats.box_tests += n.box_tests;
  stats.box_pairs += n.box_pairs;
  stats.vertex_tests += n.vertex_tests;
  return hit;
}

bool exhaustive_contact(const PlacedShape& a_in, const PlacedShape& b_in, float theta) {
  return hd::exhaustive_contact(placed_view(a_in), placed_view(b_in), theta);
}

// ---- the step's midphase stage ----------------------------------------------------------

void confirm_pairs(const Model& model, const BodyState& state, const std::vector<Aabb>& boxes,
                   const std::vector<Pair>& pairs, std::vector<std::uint8_t>& confirmed, FrameMetrics& m) {
  // Pairs are independent, so they run in parallel; the confirmed flags are stored in
  // pair order, so the result does not depend on the thread count.
  confirmed.assign(pairs.size(), 0);
  const std::size_t np = pairs.size();
  const MidphaseConfig& config = model.scene.midphase;
  // Per-worker tallies, summed in worker order afterwards (integer sums: the totals do
  // not depend on which worker tested which pair).
  struct Tally {
    std::uint64_t box_tests = 0, box_pairs = 0, vertex_tests = 0, dynamic_pairs = 0;
    char pad[32];  // one cache line each
  };
  LoopOptions loop;
  loop.min_items = kParallelMinPairs;
  loop.chunk = 8;
  std::vector<Tally> tally(loop_threads(np, loop));
  parallel_for(np, loop, [&](std::size_t k, unsigned worker) {
    const Pair p = pairs[k];
    if (state.w[p.a] == 0.0f && state.w[p.b] == 0.0f) return;  // static-static
    Tally& t = tally[worker];
    ++t.dynamic_pairs;
    const std::uint32_t sa = model.bodies[p.a].shape, sb = model.bodies[p.b].shape;
    const PlacedShape a{model.shapes[sa].octree.get(), state.x[p.a], boxes[p.a]};
    const PlacedShape b{model.shapes[sb].octree.get(), state.x[p.b], boxes[p.b]};
    MidphaseStats st;
    confirmed[k] = confirm_contact(a, b, model.theta(sa, sb), config, st) ? 1 : 0;
    t.box_tests += st.box_tests;
    t.box_pairs += st.box_pairs;
    t.vertex_tests += st.vertex_tests;
  });
  std::uint64_t box_tests = 0, box_pairs = 0, vertex_tests = 0, dynamic_pairs = 0;
  for (const Tally& t : tally) {
    box_tests += t.box_tests;
    box_pairs += t.box_pairs;
    vertex_tests += t.vertex_tests;
    dynamic_pairs += t.dynamic_pairs;
  }
  m.dynamic_pairs = dynamic_pairs;
  m.box_tests = box_tests;
  m.box_pairs = box_pairs;
  m.vertex_tests = vertex_tests;
}

}  // namespace octocd
