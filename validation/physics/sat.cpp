// The separating-axis test of two posed convex hulls (see sat.hpp).
#include "sat.hpp"
#include "dmath.hpp"

#include "octocd/box_sat.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

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

/// Whether a and b are equal bit for bit (-0 and +0 differ, a NaN equals its own bits).
bool same_bits(const D3& a, const D3& b) { return std::memcmp(a.data(), b.data(), sizeof(D3)) == 0; }

/// The extremes [lo, hi] of hull h's vertices projected on u: each projection is
/// dot3(v, u) ((x u0 + y u1) + z u2, no fused multiply-add), the extremes those of
/// std::min / std::max taken vertex by vertex (a NaN projection is skipped, as there), so
/// the figures are the scalar loop's bit for bit; with SSE2 two vertices an instruction.
void project(const PlacedHull& h, const D3& u, double& lo, double& hi) {
  const std::size_t n = h.x.size();  // even (place_hull pads)
  const double* xs = h.x.data();
  const double* ys = h.y.data();
  const double* zs = h.z.data();
#if defined(__SSE2__)
  const __m128d u0 = _mm_set1_pd(u[0]), u1 = _mm_set1_pd(u[1]), u2 = _mm_set1_pd(u[2]);
  __m128d lo2 = _mm_set1_pd(std::numeric_limits<double>::infinity());
  __m128d hi2 = _mm_set1_pd(-std::numeric_limits<double>::infinity());
  for (std::size_t k = 0; k < n; k += 2) {
    const __m128d t = _mm_add_pd(_mm_add_pd(_mm_mul_pd(_mm_loadu_pd(xs + k), u0), _mm_mul_pd(_mm_loadu_pd(ys + k), u1)),
                                 _mm_mul_pd(_mm_loadu_pd(zs + k), u2));
    lo2 = _mm_min_pd(t, lo2);  // t < lo ? t : lo, as std::min(lo, t)
    hi2 = _mm_max_pd(t, hi2);  // t > hi ? t : hi, as std::max(hi, t)
  }
  double l[2], m[2];
  _mm_storeu_pd(l, lo2);
  _mm_storeu_pd(m, hi2);
  lo = std::min(l[0], l[1]);
  hi = std::max(m[0], m[1]);
#else
  lo = std::numeric_limits<double>::infinity();
  hi = -lo;
  for (std::size_t k = 0; k < n; ++k) {
    const double t = xs[k] * u[0] + ys[k] * u[1] + zs[k] * u[2];
    lo = std::min(lo, t);
    hi = std::max(hi, t);
  }
#endif
}

}  // namespace

void place_hull(const HullFeatures& h, const Pose& p, PlacedHull& out) {
  const auto r = rotation(p.orientation);
  const D3 x{double(p.position.x), double(p.position.y), double(p.position.z)};
  const std::size_t n = h.vertices.size(), padded = n + (n & 1);
  out.vertex_count = n;
  out.x.resize(padded);
  out.y.resize(padded);
  out.z.resize(padded);
  for (std::size_t k = 0; k < n; ++k) {
    const D3 w = mul(r, h.vertices[k]);
    out.x[k] = w[0] + x[0];
    out.y[k] = w[1] + x[1];
    out.z[k] = w[2] + x[2];
  }
  if (padded != n) {
    out.x[n] = out.x[n - 1];
    out.y[n] = out.y[n - 1];
    out.z[n] = out.z[n - 1];
  }
  out.faces.resize(h.face_normals.size());
  out.edges.resize(h.edge_dirs.size());
  for (std::size_t k = 0; k < h.face_normals.size(); ++k) out.faces[k] = mul(r, h.face_normals[k]);
  for (std::size_t k = 0; k < h.edge_dirs.size(); ++k) out.edges[k] = mul(r, h.edge_dirs[k]);
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
  if (A.vertex_count == 0 || B.vertex_count == 0) return r;
  const double naxes =
      double(A.faces.size() + B.faces.size()) + double(A.edges.size()) * double(B.edges.size());
  if (naxes * double(A.vertex_count + B.vertex_count) > settings.max_work) return r;
  r.tested = true;
  Scratch& work = scratch();

  // Every axis with its overlap, in the order tested.
  std::vector<SatAxis>& all = work.all;
  all.clear();
  // Directions already tested, as given (before normalisation), with their axis in `all`:
  // a direction equal bit for bit to one of them (B's faces when both hulls are turned
  // alike, an edge cross along a face normal) has the same unit axis, projections and
  // overlap, so its axis is copied (with its own kind) instead of computed again. Up to
  // kRemembered directions are remembered (two boxes have at most 15).
  constexpr std::size_t kRemembered = 16;
  D3 seen[kRemembered];
  std::size_t seen_axis[kRemembered];
  std::size_t n_seen = 0;
  auto test = [&](const D3& given, int kind) {
    for (std::size_t k = 0; k < n_seen; ++k)
      if (same_bits(seen[k], given)) {
        SatAxis ax = all[seen_axis[k]];
        ax.kind = kind;
        ++r.axes;
        all.push_back(ax);
        return;
      }
    const double len = std::sqrt(dot3(given, given));
    if (!(len > 1e-9)) return;
    const D3 u{given[0] / len, given[1] / len, given[2] / len};
    double a0, a1, b0, b1;
    project(A, u, a0, a1);
    project(B, u, b0, b1);
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
    if (n_seen < kRemembered) {
      seen[n_seen] = given;
      seen_axis[n_seen++] = all.size();
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
  if (!r.separated || settings.accept_separated) {
    const double within = r.depth + r.epsilon;
    for (const SatAxis& ax : all)
      if (ax.overlap <= within) accepted.push_back(ax);
  }
  // A large pair (up to SatSettings::max_work axes) does not keep its axes' memory.
  if (all.capacity() > kKeptAxes) std::vector<SatAxis>().swap(all);
  return r;
}

SatAlong sat_depth_along(const HullFeatures& a, const Pose& pa, const HullFeatures& b, const Pose& pb, const D3& n,
                         double radius, const SatSettings& settings) {
  SatAlong out;
  Scratch& work = scratch();
  place_hull(a, pa, work.a);
  place_hull(b, pb, work.b);
  const PlacedHull &A = work.a, &B = work.b;
  if (A.vertex_count == 0 || B.vertex_count == 0) return out;
  const double naxes = double(A.faces.size() + B.faces.size()) + double(A.edges.size()) * double(B.edges.size());
  if (naxes * double(A.vertex_count + B.vertex_count) > settings.max_work) return out;
  out.tested = true;
  double best = std::numeric_limits<double>::infinity();
  auto test = [&](const D3& given) {
    const double len = std::sqrt(dot3(given, given));
    if (!(len > 1e-9)) return;
    const D3 u{given[0] / len, given[1] / len, given[2] / len};
    const double un = dot3(u, n);
    if (un == 0) return;  // parallel to the ray: never its exit
    double a0, a1, b0, b1;
    project(A, u, a0, a1);
    project(B, u, b0, b1);
    // Along +u, B - A reaches b1 - a0; along -u, a1 - b0 (the overlaps of the two
    // translations), each grown by the radius.
    const double reach = un > 0 ? b1 - a0 : a1 - b0;
    const double t = (reach + radius) / std::fabs(un);
    if (t < best) {
      best = t;
      out.axis = un > 0 ? u : D3{-u[0], -u[1], -u[2]};
    }
  };
  for (const D3& f : A.faces) test(f);
  for (const D3& f : B.faces) test(f);
  for (const D3& ea : A.edges)
    for (const D3& eb : B.edges) test(cross3(ea, eb));
  out.tested = std::isfinite(best);
  out.depth = out.tested ? std::max(0.0, best) : 0.0;
  return out;
}

bool hull_box(const HullFeatures& h, std::array<double, 3>& lo, std::array<double, 3>& hi) {
  if (h.vertices.size() != 8 || h.face_normals.size() != 3 || h.edge_dirs.size() != 3) return false;
  for (int k = 0; k < 3; ++k) {
    const D3 e{k == 0 ? 1.0 : 0.0, k == 1 ? 1.0 : 0.0, k == 2 ? 1.0 : 0.0};
    if (h.face_normals[k] != e || h.edge_dirs[k] != e) return false;
  }
  D3 l = h.vertices[0], u = h.vertices[0];
  for (const D3& v : h.vertices)
    for (int d = 0; d < 3; ++d) {
      l[d] = std::min(l[d], v[d]);
      u[d] = std::max(u[d], v[d]);
    }
  // Each vertex a corner (every coordinate its least or greatest), the 8 all different.
  unsigned corners = 0;
  for (const D3& v : h.vertices) {
    unsigned bits = 0;
    for (int d = 0; d < 3; ++d) {
      if (v[d] == u[d] && l[d] < u[d]) bits |= 1u << d;
      else if (v[d] != l[d]) return false;
    }
    corners |= 1u << bits;
  }
  if (corners != 0xffu) return false;
  lo = l;
  hi = u;
  return true;
}

SatResult sat_boxes(const std::array<double, 3>& lo_a, const std::array<double, 3>& hi_a, const Pose& pa,
                    const std::array<double, 3>& lo_b, const std::array<double, 3>& hi_b, const Pose& pb,
                    const SatSettings& settings, std::vector<SatAxis>& accepted) {
  SatResult r;
  accepted.clear();
  for (const Pose* p : {&pa, &pb}) {
    const float v[7] = {p->position.x, p->position.y, p->position.z, p->orientation.w,
                        p->orientation.x, p->orientation.y, p->orientation.z};
    for (float x : v)
      if (!std::isfinite(x)) return r;
  }
  if (15.0 * 16.0 > settings.max_work) return r;  // the hull test's count for two boxes
  auto place = [](const D3& lo, const D3& hi, const Pose& p) {
    const M3 rot = rotation(p.orientation);
    const double x[3] = {double(p.position.x), double(p.position.y), double(p.position.z)};
    return sat_box(lo.data(), hi.data(), rot.data(), x);
  };
  const SatBox A = place(lo_a, hi_a, pa), B = place(lo_b, hi_b, pb);
  // The axes' figures; a normal is computed for the minimum and the accepted axes only.
  BoxSatAxis all[15];
  int n = 0, least = 0;
  box_sat_each(A, B, [&](const BoxSatAxis& x) {
    if (n == 0 || x.overlap < all[least].overlap) least = n;  // the first least (std::min_element)
    all[n++] = x;
  });
  if (n == 0) return r;
  r.tested = true;
  r.axes = std::size_t(n);
  auto unit = [](const BoxSatAxis& x) {
    D3 u;
    box_sat_normal(x, u.data());
    return u;
  };
  r.depth = all[least].overlap;
  r.normal = unit(all[least]);
  r.separated = r.depth <= 0;
  r.epsilon = settings.abs_m + settings.rel * std::max(r.depth, 0.0);
  if (!r.separated) {
    const double within = r.depth + r.epsilon;
    for (int k = 0; k < n; ++k)
      if (all[k].overlap <= within) {
        SatAxis& ax = accepted.emplace_back();  // filled in place: no copy through the stack
        box_sat_normal(all[k], ax.normal.data());
        ax.overlap = all[k].overlap;
        ax.kind = all[k].kind;
      }
  }
  return r;
}

double sat_angle_to_accepted(const SatResult& r, const std::array<double, 3>& n, std::size_t* nearest) {
  return sat_angle_to_accepted(r.accepted, n, nearest);
}

double sat_angle_to_accepted(const std::vector<SatAxis>& accepted, const std::array<double, 3>& n,
                             std::size_t* nearest) {
  double best = 3.14159265358979323846;
  // An axis whose normal equals bit for bit an earlier one's has the same angle, which
  // cannot be below `best` (strictly) again: skipped. The first kRemembered distinct
  // normals are remembered.
  constexpr std::size_t kRemembered = 16;
  std::size_t seen[kRemembered];
  std::size_t n_seen = 0;
  for (std::size_t k = 0; k < accepted.size(); ++k) {
    const D3& u = accepted[k].normal;
    bool repeated = false;
    for (std::size_t m = 0; m < n_seen && !repeated; ++m)
      repeated = same_bits(accepted[seen[m]].normal, u);
    if (repeated) continue;
    if (n_seen < kRemembered) seen[n_seen++] = k;
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
