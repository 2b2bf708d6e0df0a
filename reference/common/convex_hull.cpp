// The convex hull of a mesh (convex_hull.hpp): qhull's facets (libqhull_r), wound and
// given planes here, and the hull's mass properties.
#include "octocd/convex_hull.hpp"

#include <fmt/format.h>

#include <libqhull_r/qhull_ra.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>

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
  auto refuse = [&](std::size_t faces, const std::string& why) {
    return InputError(fmt::format("{}: the convex hull of its {} vertices has {} faces (they span no volume{}); "
                                  "allowed: at least 4 vertices not in one plane",
                                  what, points.size(), faces, why));
  };
  if (points.size() < 4) throw refuse(0, "");
  std::vector<coordT> coords;
  coords.reserve(3 * points.size());
  for (const Vec3& p : points) coords.insert(coords.end(), {p.x, p.y, p.z});
  // qhull's own messages go to a memory stream: the first line names a refusal.
  char* message = nullptr;
  std::size_t message_size = 0;
  FILE* err = open_memstream(&message, &message_size);
  qhT qh_state;
  qhT* qh = &qh_state;
  qh_zero(qh, err);
  // Default options: the exact input in double, facets merged where qhull's roundoff
  // bound cannot tell them apart (C-0, Qx off in 3-d); no triangulation (Qt), so a face
  // is the merged polygon.
  char flags[] = "qhull";
  const int exit_code = qh_new_qhull(qh, 3, static_cast<int>(points.size()), coords.data(), False, flags, nullptr, err);
  ConvexHull h;
  std::size_t faces = 0;
  if (exit_code == 0) {
    // Hull vertices: the input points qhull keeps, in input order.
    std::vector<std::int64_t> hull_index(points.size(), -1);
    vertexT* vertex;
    FORALLvertices {
      const int id = qh_pointid(qh, vertex->point);
      if (id >= 0 && static_cast<std::size_t>(id) < points.size()) hull_index[static_cast<std::size_t>(id)] = 0;
    }
    for (std::size_t k = 0; k < points.size(); ++k) {
      if (hull_index[k] < 0) continue;
      hull_index[k] = static_cast<std::int64_t>(h.vertices.size());
      h.vertices.push_back({points[k].x, points[k].y, points[k].z});
    }
    facetT* facet;
    FORALLfacets {
      if (facet->degenerate || facet->redundant) continue;
      // qh_facet3vertex: the facet's vertices in order around it (3-d).
      setT* loop = qh_facet3vertex(qh, facet);
      std::vector<std::uint32_t> idx;
      vertexT** vertexp;
      FOREACHvertex_(loop) {
        const int id = qh_pointid(qh, vertex->point);
        if (id >= 0 && static_cast<std::size_t>(id) < points.size() && hull_index[static_cast<std::size_t>(id)] >= 0)
          idx.push_back(static_cast<std::uint32_t>(hull_index[static_cast<std::size_t>(id)]));
      }
      qh_settempfree(qh, &loop);
      if (idx.size() < 3) continue;
      // qhull's outward unit normal (from the exact input points); the winding is made
      // counter-clockwise seen from outside (Newell's normal along it).
      const D3 n{facet->normal[0], facet->normal[1], facet->normal[2]};
      D3 newell{0, 0, 0};
      for (std::size_t k = 0; k < idx.size(); ++k) {
        const D3 c = cross3(h.vertices[idx[k]], h.vertices[idx[(k + 1) % idx.size()]]);
        for (std::size_t a = 0; a < 3; ++a) newell[a] += c[a];
      }
      if (dot3(newell, n) < 0.0) std::reverse(idx.begin(), idx.end());
      double d = -HUGE_VAL;
      for (std::uint32_t v : idx) d = std::max(d, dot3(n, h.vertices[v]));
      h.faces.push_back(std::move(idx));
      h.planes.push_back({n[0], n[1], n[2], d});
    }
    faces = h.faces.size();
  }
  qh_freeqhull(qh, !qh_ALL);
  int still_long = 0, still_total = 0;
  qh_memfreeshort(qh, &still_long, &still_total);
  std::fclose(err);
  std::string first_line = message ? std::string(message, message_size) : std::string();
  std::free(message);
  first_line = first_line.substr(0, first_line.find('\n'));
  if (exit_code != 0 || faces < 4) throw refuse(faces, first_line.empty() ? "" : ": qhull " + first_line);
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
