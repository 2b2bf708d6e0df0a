// The convex hull of a mesh (convex_hull.hpp): btConvexHullComputer's faces, wound and
// given planes here, and the hull's mass properties.
#include "octocd/convex_hull.hpp"

#include <LinearMath/btConvexHullComputer.h>
#include <fmt/format.h>

#include <algorithm>
#include <cmath>

#include "octocd/error.hpp"

namespace octocd {

namespace {
using D3 = std::array<double, 3>;
D3 sub(const D3& a, const D3& b) { return {a[0] - b[0], a[1] - b[1], a[2] - b[2]}; }
D3 cross3(const D3& a, const D3& b) {
  return {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
}
double dot3(const D3& a, const D3& b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
}  // namespace

ConvexHull convex_hull(const std::vector<Vec3>& points, const std::string& what) {
  std::vector<double> coords;
  coords.reserve(3 * points.size());
  for (const Vec3& p : points) {
    coords.push_back(p.x);
    coords.push_back(p.y);
    coords.push_back(p.z);
  }
  btConvexHullComputer hc;
  if (!points.empty()) hc.compute(coords.data(), static_cast<int>(3 * sizeof(double)), static_cast<int>(points.size()), 0.0, 0.0);
  ConvexHull h;
  // Hull vertices: the input points they came from (exact), else Bullet's float copy.
  for (int i = 0; i < hc.vertices.size(); ++i) {
    const int o = hc.original_vertex_index[i];
    if (o >= 0 && static_cast<std::size_t>(o) < points.size()) {
      const Vec3& p = points[static_cast<std::size_t>(o)];
      h.vertices.push_back({p.x, p.y, p.z});
    } else {
      h.vertices.push_back({hc.vertices[i].x(), hc.vertices[i].y(), hc.vertices[i].z()});
    }
  }
  D3 centroid{0, 0, 0}, lo{HUGE_VAL, HUGE_VAL, HUGE_VAL}, hi{-HUGE_VAL, -HUGE_VAL, -HUGE_VAL};
  for (const D3& v : h.vertices)
    for (std::size_t k = 0; k < 3; ++k) {
      centroid[k] += v[k];
      lo[k] = std::min(lo[k], v[k]);
      hi[k] = std::max(hi[k], v[k]);
    }
  for (double& c : centroid) c /= static_cast<double>(std::max<std::size_t>(h.vertices.size(), 1));
  // btConvexHullComputer finds the hull on a grid of 1/10216 of the points' range
  // (btConvexHullInternal::compute), so in the input's coordinates its merged faces are
  // planar only to about a grid step, and among ~2,000 faces of a scanned mesh it returns a
  // few slivers of collinear corners (asian-dragon: 3), whose Newell normal is rounding
  // noise (their planes cut 20-37% of the hull's diagonal into it). A face thinner (twice
  // its area over its longest chord) than kSliver times the hull's bounding-box diagonal
  // is left out; its neighbours' planes bound the hull there.
  constexpr double kSliver = 1e-6;
  const double sliver = kSliver * std::sqrt(dot3(sub(hi, lo), sub(hi, lo)));
  for (int f = 0; f < hc.faces.size(); ++f) {
    std::vector<std::uint32_t> idx;
    const btConvexHullComputer::Edge* first = &hc.edges[hc.faces[f]];
    const btConvexHullComputer::Edge* e = first;
    do {
      idx.push_back(static_cast<std::uint32_t>(e->getSourceVertex()));
      e = e->getNextEdgeOfFace();
    } while (e != first && idx.size() <= static_cast<std::size_t>(hc.vertices.size()));
    if (idx.size() < 3) continue;
    // Newell's normal; the winding is made counter-clockwise seen from outside (the
    // normal pointing away from the vertices' mean, an interior point).
    D3 n{0, 0, 0};
    for (std::size_t k = 0; k < idx.size(); ++k) {
      const D3& p = h.vertices[idx[k]];
      const D3& q = h.vertices[idx[(k + 1) % idx.size()]];
      const D3 c = cross3(p, q);
      for (int j = 0; j < 3; ++j) n[static_cast<std::size_t>(j)] += c[static_cast<std::size_t>(j)];
    }
    const double len = std::sqrt(dot3(n, n));  // twice the face's area
    double chord = 0.0;                         // the longest chord from the first corner
    for (std::uint32_t v : idx) chord = std::max(chord, std::sqrt(dot3(sub(h.vertices[v], h.vertices[idx[0]]), sub(h.vertices[v], h.vertices[idx[0]]))));
    if (!(len > 0.0) || !(chord > 0.0) || len / chord <= sliver) continue;
    for (double& c : n) c /= len;
    if (dot3(n, sub(h.vertices[idx[0]], centroid)) < 0.0) {
      std::reverse(idx.begin(), idx.end());
      for (double& c : n) c = -c;
    }
    double d = -HUGE_VAL;
    for (std::uint32_t v : idx) d = std::max(d, dot3(n, h.vertices[v]));
    h.faces.push_back(std::move(idx));
    h.planes.push_back({n[0], n[1], n[2], d});
  }
  if (h.faces.size() < 4)
    throw InputError(fmt::format("{}: the convex hull of its {} vertices has {} faces (they span no volume); allowed: "
                                 "at least 4 vertices not in one plane",
                                 what, points.size(), h.faces.size()));
  return h;
}

ConvexHull convex_hull(const Mesh& mesh) { return convex_hull(mesh.vertices, mesh.name); }

HullMassProperties hull_mass_properties(const ConvexHull& hull) {
  HullMassProperties m;
  D3 o{0, 0, 0};  // the vertices' mean: inside the hull
  for (const D3& v : hull.vertices)
    for (std::size_t k = 0; k < 3; ++k) o[k] += v[k];
  for (double& c : o) c /= static_cast<double>(std::max<std::size_t>(hull.vertices.size(), 1));
  double first[3] = {0, 0, 0};
  double second[3][3] = {{0, 0, 0}, {0, 0, 0}, {0, 0, 0}};
  for (const std::vector<std::uint32_t>& face : hull.faces) {
    const D3& a = hull.vertices[face[0]];
    for (std::size_t k = 1; k + 1 < face.size(); ++k) {
      const D3& b = hull.vertices[face[k]];
      const D3& c = hull.vertices[face[k + 1]];
      // Tetrahedron (o, a, b, c): counter-clockwise faces seen from outside give V > 0.
      const double vol = dot3(sub(a, o), cross3(sub(b, o), sub(c, o))) / 6.0;
      const D3* p[4] = {&o, &a, &b, &c};
      D3 s{0, 0, 0};
      for (const D3* q : p)
        for (std::size_t i = 0; i < 3; ++i) s[i] += (*q)[i];
      m.volume += vol;
      for (std::size_t i = 0; i < 3; ++i) first[i] += vol * s[i] / 4.0;
      for (std::size_t i = 0; i < 3; ++i)
        for (std::size_t j = 0; j < 3; ++j) {
          double sum = s[i] * s[j];
          for (const D3* q : p) sum += (*q)[i] * (*q)[j];
          second[i][j] += vol / 20.0 * sum;
        }
    }
  }
  if (m.volume > 0.0)
    for (std::size_t i = 0; i < 3; ++i) m.centroid[i] = first[i] / m.volume;
  const double trace = second[0][0] + second[1][1] + second[2][2];
  for (std::size_t i = 0; i < 3; ++i)
    for (std::size_t j = 0; j < 3; ++j) m.inertia_origin[3 * i + j] = (i == j ? trace : 0.0) - second[i][j];
  return m;
}

}  // namespace octocd
