// The separating-axis test of two posed convex hulls (see sat.hpp).
#include "sat.hpp"
#include "dmath.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace octocd {

namespace {

using namespace dmath;

/// Per-thread work space of sat_min_translation: both placed hulls, and of
/// sat_min_translation_placed: every tested axis. Kept between calls (thread_local), so a
/// test allocates nothing but its accepted axes once these have grown to the largest hulls
/// seen.
/// Axes whose memory the scratch keeps between calls (two boxes test 15; a box against a
/// 162-vertex icosphere ~1,500).
constexpr std::size_t kKeptAxes = 4096;
struct Scratch {
  PlacedHull a, b;
  std::vector<SatAxis> all;
};
Scratch& scratch() {
  thread_local Scratch s;
  return s;
}

void project(const std::vector<D3>& vs, const D3& u, double& lo, double& hi) {
  lo = std::numeric_limits<double>::infinity();
  hi = -lo;
  for (const D3& v : vs) {
    const double t = dot3(v, u);
    lo = std::min(lo, t);
    hi = std::max(hi, t);
  }
}

}  // namespace

void place_hull(const HullFeatures& h, const Pose& p, PlacedHull& out) {
  const auto r = rotation(p.orientation);
  const D3 x{double(p.position.x), double(p.position.y), double(p.position.z)};
  out.vertices.clear();
  out.faces.clear();
  out.edges.clear();
  for (const D3& v : h.vertices) {
    const D3 w = mul(r, v);
    out.vertices.push_back({w[0] + x[0], w[1] + x[1], w[2] + x[2]});
  }
  for (const D3& f : h.face_normals) out.faces.push_back(mul(r, f));
  for (const D3& e : h.edge_dirs) out.edges.push_back(mul(r, e));
}

SatResult sat_min_translation(const HullFeatures& a, const Pose& pa, const HullFeatures& b, const Pose& pb,
                              const SatSettings& settings) {
  Scratch& work = scratch();
  place_hull(a, pa, work.a);
  place_hull(b, pb, work.b);
  std::vector<SatAxis> accepted;
  SatResult r = sat_min_translation_placed(work.a, work.b, settings, accepted);
  r.accepted = std::move(accepted);
  return r;
}

SatResult sat_min_translation_placed(const PlacedHull& A, const PlacedHull& B, const SatSettings& settings,
                                     std::vector<SatAxis>& accepted) {
  SatResult r;
  accepted.clear();
  if (A.vertices.empty() || B.vertices.empty()) return r;
  const double naxes =
      double(A.faces.size() + B.faces.size()) + double(A.edges.size()) * double(B.edges.size());
  if (naxes * double(A.vertices.size() + B.vertices.size()) > settings.max_work) return r;
  r.tested = true;
  Scratch& work = scratch();

  // Every axis with its overlap, in the order tested.
  std::vector<SatAxis>& all = work.all;
  all.clear();
  auto test = [&](D3 u, int kind) {
    const double len = std::sqrt(dot3(u, u));
    if (!(len > 1e-9)) return;
    u = {u[0] / len, u[1] / len, u[2] / len};
    double a0, a1, b0, b1;
    project(A.vertices, u, a0, a1);
    project(B.vertices, u, b0, b1);
    const double plus = b1 - a0, minus = a1 - b0;  // translate A along +u, or along -u
    SatAxis ax;
    ax.kind = kind;
    if (plus <= minus) {
      ax.normal = u;
      ax.overlap = plus;
    } else {
      ax.normal = {-u[0], -u[1], -u[2]};
      ax.overlap = minus;
    }
    ++r.axes;
    all.push_back(ax);
  };
  for (const D3& f : A.faces) test(f, 0);
  for (const D3& f : B.faces) test(f, 1);
  for (const D3& ea : A.edges)
    for (const D3& eb : B.edges) test(cross3(ea, eb), 2);
  if (all.empty()) {
    r.tested = false;
    return r;
  }
  const auto min_it =
      std::min_element(all.begin(), all.end(), [](const SatAxis& x, const SatAxis& y) { return x.overlap < y.overlap; });
  r.depth = min_it->overlap;
  r.normal = min_it->normal;
  r.separated = r.depth <= 0;
  r.epsilon = settings.abs_m + settings.rel * std::max(r.depth, 0.0);
  if (!r.separated) {
    const double within = r.depth + r.epsilon;
    for (const SatAxis& ax : all)
      if (ax.overlap <= within) accepted.push_back(ax);
  }
  // A large pair (up to SatSettings::max_work axes) does not keep its axes' memory.
  if (all.capacity() > kKeptAxes) std::vector<SatAxis>().swap(all);
  return r;
}

double sat_angle_to_accepted(const SatResult& r, const std::array<double, 3>& n, std::size_t* nearest) {
  return sat_angle_to_accepted(r.accepted, n, nearest);
}

double sat_angle_to_accepted(const std::vector<SatAxis>& accepted, const std::array<double, 3>& n,
                             std::size_t* nearest) {
  double best = 3.14159265358979323846;
  for (std::size_t k = 0; k < accepted.size(); ++k) {
    const D3& u = accepted[k].normal;
    const D3 c = cross3(n, u);
    const double angle = std::atan2(std::sqrt(dot3(c, c)), dot3(n, u));
    if (angle < best) {
      best = angle;
      if (nearest) *nearest = k;
    }
  }
  return best;
}

}  // namespace octocd
