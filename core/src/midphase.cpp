/// \file midphase.cpp
/// Midphase over per-mesh octree levels (SPEC 5.2) and the vertex-proximity narrow phase
/// (paper Eq. 7-8, Algorithm A2; SPEC 5.3).
///
/// Exactness: the pruned path (confirm_contact) and the oracle (exhaustive_contact) run
/// literally the same vertex tests (`vertex_close`, `vertex_box_close`) on the same float
/// world positions. Pruning only skips pairs that cannot pass them: cell boxes are tested
/// with the full margin theta (each box grown by theta/2) plus a small tolerance `tol`
/// (1e-5 relative to every magnitude involved) that covers the float rounding of the
/// translations and of the distance, so pruning is conservative, never lossy.

#include "octocd/midphase.hpp"

#include <algorithm>
#include <cctype>
#include <cmath>

#include "octocd/error.hpp"

namespace octocd {
namespace {

// ---- the narrow-phase tests, shared by both paths ------------------------------------

/// Paper Eq. 7: world vertices wa and wb closer than theta (theta2 = theta * theta).
inline bool vertex_close(Vec3 wa, Vec3 wb, float theta2) {
  const float dx = wa.x - wb.x;
  const float dy = wa.y - wb.y;
  const float dz = wa.z - wb.z;
  return dx * dx + dy * dy + dz * dz < theta2;
}

/// SPEC 5.3 mesh-box: world vertex wa within theta of (or inside) the world box.
inline bool vertex_box_close(Vec3 wa, const Aabb& box, float theta2) {
  return distance2_point_aabb(wa, box) < theta2;
}

/// World position of a local vertex (the one expression both paths use).
inline Vec3 world(Vec3 v, Vec3 position) { return {v.x + position.x, v.y + position.y, v.z + position.z}; }

// ---- helpers ---------------------------------------------------------------------------

inline float max_abs(Vec3 v) { return std::max({std::fabs(v.x), std::fabs(v.y), std::fabs(v.z)}); }
inline float max_abs(const Aabb& b) { return std::max(max_abs(b.min), max_abs(b.max)); }

/// Inclusive overlap of a and b, b shifted by `shift`, with a total margin m (each box
/// grown by m/2).
inline bool overlaps_margin(const Aabb& a, const Aabb& b, float m) {
  return a.min.x - m <= b.max.x && a.max.x + m >= b.min.x &&  //
         a.min.y - m <= b.max.y && a.max.y + m >= b.min.y &&  //
         a.min.z - m <= b.max.z && a.max.z + m >= b.min.z;
}

inline bool inside(Vec3 p, const Aabb& b) {
  return p.x >= b.min.x && p.x <= b.max.x && p.y >= b.min.y && p.y <= b.max.y && p.z >= b.min.z &&
         p.z <= b.max.z;
}

/// The cells at level `to` descending from cell c of level `from` (<= to): a contiguous
/// range [begin, end) of `cells` (children are stored contiguously in Morton order).
inline void descendants(const MeshOctree& t, std::uint32_t c, int from, int to, std::uint32_t& begin,
                        std::uint32_t& end) {
  std::uint32_t lo = c;
  std::uint32_t hi = c;
  for (int l = from; l < to; ++l) {
    lo = t.cells[lo].first_child;
    const MeshOctreeCell& h = t.cells[hi];
    hi = h.first_child + h.child_count - 1;
  }
  begin = lo;
  end = hi + 1;
}

constexpr int kMaxLevels = 11;  // levels are strictly ascending in [0, 10]

/// Level list clamped to an octree's depth (a level deeper than the octree is its deepest).
inline int clamp_levels(const MidphaseConfig& cfg, const MeshOctree& t, int* out) {
  const int k = std::min(static_cast<int>(cfg.levels.size()), kMaxLevels);
  for (int i = 0; i < k; ++i) out[i] = std::min(cfg.levels[static_cast<std::size_t>(i)], t.depth);
  return k;
}

struct Counters {
  std::uint64_t box_tests = 0;
  std::uint64_t box_pairs = 0;
  std::uint64_t vertex_tests = 0;
};

/// Reused scratch of world vertex positions (grows, never shrinks: no allocation once warm).
std::vector<Vec3>& scratch() {
  thread_local std::vector<Vec3> s;
  return s;
}

// ---- mesh-mesh ---------------------------------------------------------------------------

struct MeshMesh {
  const MeshOctree* A;
  const MeshOctree* B;
  Vec3 pa, pb;
  Vec3 d;        // pa - pb: A's local frame -> B's local frame (for pruning only)
  float margin;  // theta + tol
  float theta2;
  int la[kMaxLevels];
  int lb[kMaxLevels];
  int k;
  Counters n;

  /// Narrow phase on one surviving deepest pair (cell ca of A, cb of B).
  bool vertices_pair(const MeshOctreeCell& ca, const MeshOctreeCell& cb, const Aabb& a_in_b) {
    // Conservative filters: only B's vertices inside A's expanded box, only A's vertices
    // inside B's expanded box can be closer than theta.
    std::vector<Vec3>& wb = scratch();
    if (wb.size() < cb.vertex_count) wb.resize(cb.vertex_count);
    std::size_t nb = 0;
    const Vec3* vb = B->vertices.data() + cb.first_vertex;
    for (std::uint32_t j = 0; j < cb.vertex_count; ++j) {
      if (inside(vb[j], a_in_b)) wb[nb++] = world(vb[j], pb);
    }
    if (nb == 0) return false;
    const Aabb b_in_a{{cb.box.min.x - d.x - margin, cb.box.min.y - d.y - margin, cb.box.min.z - d.z - margin},
                      {cb.box.max.x - d.x + margin, cb.box.max.y - d.y + margin, cb.box.max.z - d.z + margin}};
    const Vec3* va = A->vertices.data() + ca.first_vertex;
    const Vec3* w = wb.data();
    for (std::uint32_t i = 0; i < ca.vertex_count; ++i) {
      if (!inside(va[i], b_in_a)) continue;
      const Vec3 wa = world(va[i], pa);
      n.vertex_tests += nb;
      for (std::size_t j = 0; j < nb; ++j) {
        if (vertex_close(wa, w[j], theta2)) return true;
      }
    }
    return false;
  }

  /// Level step i: cells [a0, a1) of A against [b0, b1) of B at levels la[i], lb[i].
  bool step(int i, std::uint32_t a0, std::uint32_t a1, std::uint32_t b0, std::uint32_t b1) {
    const MeshOctreeCell* cb = B->cells.data();
    for (std::uint32_t a = a0; a < a1; ++a) {
      const MeshOctreeCell& ca = A->cells[a];
      // A's cell box in B's local frame, grown by the whole margin.
      const Aabb e{{ca.box.min.x + d.x - margin, ca.box.min.y + d.y - margin, ca.box.min.z + d.z - margin},
                   {ca.box.max.x + d.x + margin, ca.box.max.y + d.y + margin, ca.box.max.z + d.z + margin}};
      n.box_tests += b1 - b0;
      for (std::uint32_t b = b0; b < b1; ++b) {
        const Aabb& bb = cb[b].box;
        if (!(e.min.x <= bb.max.x && e.max.x >= bb.min.x && e.min.y <= bb.max.y && e.max.y >= bb.min.y &&
              e.min.z <= bb.max.z && e.max.z >= bb.min.z)) {
          continue;
        }
        if (i + 1 == k) {
          ++n.box_pairs;
          if (vertices_pair(ca, cb[b], e)) return true;
          continue;
        }
        std::uint32_t na0, na1, nb0, nb1;
        descendants(*A, a, la[i], la[i + 1], na0, na1);
        descendants(*B, b, lb[i], lb[i + 1], nb0, nb1);
        if (step(i + 1, na0, na1, nb0, nb1)) return true;
      }
    }
    return false;
  }
};

// ---- mesh-box ----------------------------------------------------------------------------

struct MeshBox {
  const MeshOctree* A;
  Vec3 pa;
  Aabb box;        // world box
  Aabb box_local;  // box in A's local frame, grown by theta + tol (pruning only)
  float theta2;
  int la[kMaxLevels];
  int k;
  Counters n;

  bool step(int i, std::uint32_t a0, std::uint32_t a1) {
    n.box_tests += a1 - a0;
    for (std::uint32_t a = a0; a < a1; ++a) {
      const MeshOctreeCell& ca = A->cells[a];
      if (!overlaps(ca.box, box_local)) continue;
      if (i + 1 == k) {
        ++n.box_pairs;
        const Vec3* va = A->vertices.data() + ca.first_vertex;
        n.vertex_tests += ca.vertex_count;
        for (std::uint32_t j = 0; j < ca.vertex_count; ++j) {
          if (vertex_box_close(world(va[j], pa), box, theta2)) return true;
        }
        continue;
      }
      std::uint32_t na0, na1;
      descendants(*A, a, la[i], la[i + 1], na0, na1);
      if (step(i + 1, na0, na1)) return true;
    }
    return false;
  }
};

void add(MidphaseStats& s, const Counters& c) {
  s.box_tests += c.box_tests;
  s.box_pairs += c.box_pairs;
  s.vertex_tests += c.vertex_tests;
}

/// Rounding tolerance added to the margin theta (see the file comment).
inline float tolerance(float theta, float magnitudes) { return 1e-5f * (theta + magnitudes); }

std::string trim(const std::string& s) {
  std::size_t b = 0;
  std::size_t e = s.size();
  while (b < e && std::isspace(static_cast<unsigned char>(s[b]))) ++b;
  while (e > b && std::isspace(static_cast<unsigned char>(s[e - 1]))) --e;
  return s.substr(b, e - b);
}

}  // namespace

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
  if (config.aabb_only) return overlaps(a_in.box, b_in.box);
  if (!a_in.octree && !b_in.octree) return overlaps(a_in.box, b_in.box);
  const bool swap = !a_in.octree;  // (box, mesh) -> (mesh, box)
  const PlacedShape& a = swap ? b_in : a_in;
  const PlacedShape& b = swap ? a_in : b_in;
  const float theta2 = theta * theta;
  const MeshOctree& A = *a.octree;

  if (!b.octree) {
    MeshBox mb;
    mb.A = &A;
    mb.pa = a.position;
    mb.box = b.box;
    const float tol = tolerance(theta, max_abs(a.position) + max_abs(A.bounds) + max_abs(b.box));
    const Vec3 lo = b.box.min - a.position;
    const Vec3 hi = b.box.max - a.position;
    mb.box_local = expanded(Aabb{lo, hi}, theta + tol);
    // Early rejection: the mesh's bounds against the box, with the margin.
    if (!overlaps(A.bounds, mb.box_local)) return false;
    mb.theta2 = theta2;
    mb.k = clamp_levels(config, A, mb.la);
    if (mb.k == 0) return exhaustive_contact(a, b, theta);  // no levels: nothing to prune
    const bool hit = mb.step(0, A.level_begin(mb.la[0]), A.level_end(mb.la[0]));
    add(stats, mb.n);
    return hit;
  }

  const MeshOctree& B = *b.octree;
  MeshMesh mm;
  mm.A = &A;
  mm.B = &B;
  mm.pa = a.position;
  mm.pb = b.position;
  mm.d = a.position - b.position;
  const float tol =
      tolerance(theta, max_abs(a.position) + max_abs(b.position) + max_abs(A.bounds) + max_abs(B.bounds));
  mm.margin = theta + tol;
  // Early rejection (SPEC 5.3): the two bounds, each grown by theta/2, must overlap.
  {
    const Aabb e{A.bounds.min + mm.d, A.bounds.max + mm.d};
    if (!overlaps_margin(e, B.bounds, mm.margin)) return false;
  }
  mm.theta2 = theta2;
  mm.k = clamp_levels(config, A, mm.la);
  clamp_levels(config, B, mm.lb);
  if (mm.k == 0) return exhaustive_contact(a, b, theta);  // no levels: nothing to prune
  const bool hit = mm.step(0, A.level_begin(mm.la[0]), A.level_end(mm.la[0]), B.level_begin(mm.lb[0]),
                           B.level_end(mm.lb[0]));
  add(stats, mm.n);
  return hit;
}

bool exhaustive_contact(const PlacedShape& a_in, const PlacedShape& b_in, float theta) {
  if (!a_in.octree && !b_in.octree) return overlaps(a_in.box, b_in.box);
  const bool swap = !a_in.octree;
  const PlacedShape& a = swap ? b_in : a_in;
  const PlacedShape& b = swap ? a_in : b_in;
  const float theta2 = theta * theta;
  const std::vector<Vec3>& va = a.octree->vertices;
  if (!b.octree) {
    for (const Vec3& v : va) {
      if (vertex_box_close(world(v, a.position), b.box, theta2)) return true;
    }
    return false;
  }
  const std::vector<Vec3>& vb = b.octree->vertices;
  for (const Vec3& v : va) {
    const Vec3 wa = world(v, a.position);
    for (const Vec3& u : vb) {
      if (vertex_close(wa, world(u, b.position), theta2)) return true;
    }
  }
  return false;
}

}  // namespace octocd
