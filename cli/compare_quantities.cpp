// The quantities `octocd compare` (compare.cpp) compares: each trace's side, states (positions,
// velocities, orientations, angular velocities), /frames columns and contacts (records in order,
// or by pair) at the frames both traces hold, each against its tolerance.
#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <map>
#include <optional>
#include <iterator>
#include <set>

#include <fmt/format.h>
#include <fmt/ranges.h>

#include "octocd/error.hpp"
#include "octocd/text.hpp"
#include "octocd/external.hpp"
#include "octocd/trace_reader.hpp"
#include <type_traits>

#include "compare_quantities.hpp"
#include "tools.hpp"

namespace octocd::cli::compare_detail {

using json = nlohmann::json;

namespace {


/// Rows of `dataset` (its first dimension). Throws InputError naming the file and the
/// dataset when it is a scalar (before: std::out_of_range "vector::_M_range_check", exit 1).
std::uint64_t rows_of(const TraceReader& t, const std::string& dataset) {
  const std::vector<std::uint64_t> shape = t.shape(dataset);
  if (shape.empty())
    throw InputError(fmt::format("{}: {}: a scalar; allowed: a dataset of rows (rank >= 1; docs/trace-format.md)",
                                 t.path(), dataset));
  return shape[0];
}


/// Whether a and b differ beyond the tolerance (numpy.isclose's rule: |a - b| > abs + rel *
/// max(|a|, |b|)); with tolerance 0 two floats are equal only with equal bits; a NaN on one
/// side only (or NaNs of other bits) is an infinite difference.
template <class T>
bool beyond(T a, T b, const Tolerance& tol, double& diff) {
  if constexpr (std::is_floating_point_v<T>) {
    if (std::memcmp(&a, &b, sizeof(T)) == 0) {
      diff = 0.0;
      return false;
    }
    if (std::isnan(a) || std::isnan(b)) {
      diff = std::numeric_limits<double>::infinity();
      return true;
    }
  }
  const double x = static_cast<double>(a), y = static_cast<double>(b);
  diff = std::fabs(x - y);
  if (tol.exact()) return diff != 0.0;
  return diff > tol.abs + tol.rel * std::max(std::fabs(x), std::fabs(y));
}

std::string vec_text(const float* p) { return fmt::format("({}, {}, {})", p[0], p[1], p[2]); }
std::string quat_text(const float* p) { return fmt::format("({}, {}, {}, {})", p[0], p[1], p[2], p[3]); }

/// The first `rows` values of a frame column, checked: frames >= 0, strictly increasing
/// (as octocd writes them); garbage would otherwise match nothing and compare as "same".
std::vector<std::int64_t> increasing_frames(const TraceReader& t, const char* dataset, std::int64_t rows) {
  std::vector<std::int64_t> f = t.read_i64(dataset, rows);
  for (std::size_t i = 0; i < f.size(); ++i)
    if (f[i] < 0 || (i > 0 && f[i] <= f[i - 1]))
      throw InputError(fmt::format("{}: {}: row {} is frame {}{}; allowed: frames >= 0, strictly increasing", t.path(),
                                   dataset, i, f[i], i > 0 ? fmt::format(" after {}", f[i - 1]) : ""));
  return f;
}

std::vector<std::int64_t> frames_of(const TraceReader& t, const std::string& dataset, std::int64_t rows) {
  return rows > 0 ? t.read_i64(dataset, rows) : std::vector<std::int64_t>{};
}


/// The angle (rad) of the rotation from a to b, unit quaternions (w, x, y, z): 2 atan2(|r_xyz|,
/// |r_w|) of r = conj(a) b, in double; q and -q give 0 exactly.
double quat_angle(const float* a, const float* b) {
  const double aw = a[0], ax = a[1], ay = a[2], az = a[3], bw = b[0], bx = b[1], by = b[2], bz = b[3];
  const double rw = aw * bw + ax * bx + ay * by + az * bz;
  const double rx = aw * bx - bw * ax - (ay * bz - az * by);
  const double ry = aw * by - bw * ay - (az * bx - ax * bz);
  const double rz = aw * bz - bw * az - (ax * by - ay * bx);
  return 2.0 * std::atan2(std::sqrt(rx * rx + ry * ry + rz * rz), std::fabs(rw));
}

/// Throws InputError naming the body unless each quaternion of one state row is finite and
/// unit within 1e-3 (the external format's rule, docs/trace-format.md).
void check_unit_quaternions(const Side& s, const std::vector<float>& q, std::int64_t frame) {
  for (std::size_t i = 0; 4 * i + 3 < q.size(); ++i) {
    const float* p = &q[4 * i];
    const double n = std::sqrt(static_cast<double>(p[0]) * p[0] + static_cast<double>(p[1]) * p[1] +
                               static_cast<double>(p[2]) * p[2] + static_cast<double>(p[3]) * p[3]);
    if (!(std::fabs(n - 1.0) <= 1e-3))
      throw InputError(fmt::format("{}: /states/orientation: frame {}: body {}: {}, |q| = {:g}; allowed: unit "
                                   "quaternions (w, x, y, z), body to world, | |q| - 1 | <= 1e-3",
                                   s.path(), frame, i, quat_text(p), n));
  }
}


/// The /contacts records of a trace: rows of frame[i] are off[i] .. off[i+1]-1.
struct Contacts {
  std::vector<std::int64_t> off, frame;
  std::vector<std::uint32_t> pair;
  std::vector<float> normal, depth, jn, jt, point;  ///< point: empty without /contacts/point
  std::vector<float> point_b, jt3;                  ///< empty without /contacts/point_b, /contacts/jt3
};

Contacts load_contacts(const Side& s) {
  const TraceReader& t = *s.t;
  Contacts r;
  if (s.external) {
    // Checked by check_external_trace: F + 1 offsets from 0, never decreasing, within the
    // flat datasets; step f's rows are offsets[f-1] .. offsets[f]-1.
    r.off = t.read_i64("/contacts/offsets", s.frame_rows + 1);
    r.frame = s.frames;
  } else {
    // Complete rows: at most committed_frames (docs/trace-format.md).
    if (rows_of(t, "/contacts/offsets") == 0) return r;
    const std::int64_t rows = t.complete_rows("/contacts");
    r.frame = increasing_frames(t, "/contacts/frame", rows);
    r.off = t.read_i64("/contacts/offsets", rows + 1);
    // Offsets start at 0 and never decrease (else the file is garbage: exit 2); rows whose
    // records lie past the flat arrays' end are a killed run's unwritten tail: dropped.
    for (std::size_t i = 0; i < r.off.size(); ++i)
      if ((i == 0 && r.off[i] != 0) || (i > 0 && r.off[i] < r.off[i - 1]))
        throw InputError(fmt::format("{}: /contacts/offsets: row {} is {}{}; allowed: 0 first, never decreasing",
                                     t.path(), i, r.off[i], i > 0 ? fmt::format(" after {}", r.off[i - 1]) : ""));
    std::uint64_t flat = std::min({rows_of(t, "/contacts/pair"), rows_of(t, "/contacts/depth"),
                                   rows_of(t, "/contacts/normal"), rows_of(t, "/contacts/jn"),
                                   rows_of(t, "/contacts/jt")});
    const std::pair<bool, const char*> vectors[] = {{s.points, "/contacts/point"},
                                                    {s.point_b, "/contacts/point_b"},
                                                    {s.jt3, "/contacts/jt3"}};
    for (const auto& [present, name] : vectors) {
      if (!present) continue;
      const auto shape = t.shape(name);
      if (shape.size() != 2 || shape[1] != 3)
        throw InputError(fmt::format("{}: {}: shape {}; allowed: C x 3 (one vector per contact row)", t.path(), name,
                                     fmt::join(shape, " x ")));
      flat = std::min(flat, shape[0]);
    }
    std::size_t good = 0;
    while (good < r.frame.size() && r.off[good + 1] <= static_cast<std::int64_t>(flat)) ++good;
    r.frame.resize(good);
    r.off.resize(good + 1);
  }
  const std::int64_t used = r.off.empty() ? 0 : r.off.back();
  r.pair = t.read_u32("/contacts/pair", used);
  r.normal = t.read_f32("/contacts/normal", used);
  r.depth = t.read_f32("/contacts/depth", used);
  r.jn = t.read_f32("/contacts/jn", used);
  r.jt = t.read_f32("/contacts/jt", used);
  if (s.points) r.point = t.read_f32("/contacts/point", used);
  if (s.point_b) r.point_b = t.read_f32("/contacts/point_b", used);
  if (s.jt3) r.jt3 = t.read_f32("/contacts/jt3", used);
  return r;
}

}  // namespace

Side make_side(const TraceReader& t) {
  Side s;
  s.t = &t;
  s.version = t.version();
  s.external = !t.has_dataset("/frames/frame");
  s.engine = t.has_attribute("engine") ? t.string_attribute("engine") : std::string(s.external ? "external" : "?");
  if (t.has_attribute("scene_name")) s.scene_name = t.string_attribute("scene_name");
  if (s.external) {
    const ExternalTraceInfo info = check_external_trace(t.path());  // exit 2 on the first bad value
    s.bodies = static_cast<std::int64_t>(info.bodies);
    s.frame_rows = info.frames;
    for (std::int64_t f = 1; f <= info.frames; ++f) s.frames.push_back(f);
    s.has_states = info.has_states;
    if (s.has_states) {
      s.state_rows = info.frames + 1;  // row f: the state after step f (checked: /states/frame is 0..F)
      for (std::int64_t f = 0; f <= info.frames; ++f) s.state_frames.push_back(f);
    }
    s.rotation = info.has_rotation;
    s.has_contacts = info.has_contacts;
    s.points = info.has_points;
    s.point_b = info.has_point_b;
    s.jt3 = info.has_jt3;
    if (!t.has_attribute("scene_name")) {
      s.scene_known = false;
      if (info.has_scene) try {
          const json scene = json::parse(t.string_attribute("scene"));
          if (scene.is_object() && scene.contains("name") && scene["name"].is_string()) {
            s.scene_name = scene["name"].get<std::string>();
            s.scene_known = true;
          }
        } catch (const json::exception&) {  // checked by validate, not needed here
        }
    }
    return s;
  }
  if (!t.has_dataset("/bodies/shape_id"))
    throw InputError(fmt::format("{}: /bodies/shape_id: missing; allowed: a complete octocd trace (with /frames and "
                                 "/bodies) or an external trace (without /frames; docs/trace-format.md)",
                                 t.path()));
  s.bodies = static_cast<std::int64_t>(rows_of(t, "/bodies/shape_id"));
  s.frame_rows = t.complete_rows("/frames");
  s.frames = frames_of(t, "/frames/frame", s.frame_rows);
  s.has_states = t.has_dataset("/states/frame");
  if (s.has_states) {
    std::int64_t r = static_cast<std::int64_t>(rows_of(t, "/states/frame"));
    for (const char* d : {"/states/position", "/states/velocity", "/states/orientation", "/states/angular_velocity"})
      if (t.has_dataset(d)) r = std::min(r, static_cast<std::int64_t>(rows_of(t, d)));
    s.state_rows = r;
    s.state_frames = frames_of(t, "/states/frame", r);
  }
  const bool q = t.has_dataset("/states/orientation"), w = t.has_dataset("/states/angular_velocity");
  for (const char* d : {"/states/orientation", "/states/angular_velocity", "/contacts/point"})
    if (s.version == 1 && t.has_dataset(d))
      throw InputError(fmt::format("{}: {}: a version 2 dataset in a version 1 trace (v1/v2 fields mixed); allowed: "
                                   "/states/orientation, /states/angular_velocity and /contacts/point only with the "
                                   "root attribute version = 2 (docs/trace-format.md)",
                                   t.path(), d));
  if (q != w)
    throw InputError(fmt::format("{}: {}: missing ({} present); allowed: /states/orientation and "
                                 "/states/angular_velocity together, or neither (no rotation)",
                                 t.path(), q ? "/states/angular_velocity" : "/states/orientation",
                                 q ? "/states/orientation" : "/states/angular_velocity"));
  s.rotation = q && w;
  s.has_contacts = t.has_dataset("/contacts/offsets");
  s.points = s.has_contacts && t.has_dataset("/contacts/point");
  s.point_b = s.points && t.has_dataset("/contacts/point_b");
  s.jt3 = s.has_contacts && t.has_dataset("/contacts/jt3");
  return s;
}


/// The state rows a quantity is compared at: complete rows, their frames checked.
std::pair<std::int64_t, std::vector<std::int64_t>> state_rows(const Side& s) {
  if (s.external) return {s.state_rows, s.state_frames};  // 0..F, checked by check_external_trace
  const std::int64_t r = s.t->complete_rows("/states");  // at most committed_states (docs/trace-format.md)
  return {r, increasing_frames(*s.t, "/states/frame", r)};
}

/// Positions, velocities, orientations or angular velocities at the states both traces
/// hold. A trace without the dataset (no rotation) holds the identity / zero there.
/// Orientations: the difference is the angle between the two (rad); with |q| = 1 the
/// relative part of the tolerance counts as radians too (numpy.isclose's rule with max(|A|,
/// |B|) = 1).
QuantityResult compare_states(const Side& a, const Side& b, const char* dataset, const char* name,
                              std::int64_t bodies, const Tolerance& tol) {
  QuantityResult q;
  q.name = name;
  q.tol = tol;
  const bool quat = std::strcmp(dataset, "/states/orientation") == 0;
  const std::size_t dim = quat ? 4 : 3;
  const auto has = [&](const Side& s) {
    if (!s.t->has_dataset(dataset)) return false;
    const auto shape = s.t->shape(dataset);
    if (shape.size() != 3 || shape[1] != static_cast<std::uint64_t>(bodies) || shape[2] != dim)
      throw InputError(fmt::format("{}: {}: shape {}; allowed: states x {} bodies x {}", s.path(), dataset,
                                   fmt::join(shape, " x "), bodies, dim));
    return true;
  };
  const bool ha = has(a), hb = has(b);
  if (!ha && !hb) {
    q.available = false;
    q.compared = fmt::format("{} in neither (no rotation)", dataset);
    return q;
  }
  const auto [ra, fa] = state_rows(a);
  const auto [rb, fb] = state_rows(b);
  const auto row = [&](const Side& s, bool held, std::int64_t r, std::int64_t frame) {
    if (!held) {  // no rotation: identity orientation, zero angular velocity
      std::vector<float> v(static_cast<std::size_t>(bodies) * dim, 0.0f);
      if (quat)
        for (std::size_t i = 0; i < v.size(); i += 4) v[i] = 1.0f;
      return v;
    }
    std::vector<float> v = s.t->read_f32_rows(dataset, r, 1);
    if (quat) check_unit_quaternions(s, v, frame);
    return v;
  };
  // A body beyond the tolerance: counted, and the first one kept with its detail.
  const auto count_hit = [&](bool hit, std::int64_t frame, std::int64_t body, const auto& detail, double size) {
    if (!hit) return;
    ++q.beyond_count;
    if (q.differs) return;
    q.differs = true;
    q.frame = frame;
    q.body = body;
    q.detail = detail();
    q.first_size = size;
  };
  std::map<std::int64_t, std::int64_t> row_b;
  for (std::int64_t i = 0; i < rb; ++i) row_b[fb[static_cast<std::size_t>(i)]] = i;
  std::int64_t common = 0;
  for (std::int64_t i = 0; i < ra; ++i) {
    const auto it = row_b.find(fa[static_cast<std::size_t>(i)]);
    if (it == row_b.end()) continue;
    ++common;
    const std::int64_t frame = fa[static_cast<std::size_t>(i)];
    const auto xa = row(a, ha, i, frame), xb = row(b, hb, it->second, frame);
    for (std::int64_t body = 0; body < bodies; ++body) {
      bool hit = false;
      const std::size_t k0 = dim * static_cast<std::size_t>(body);
      if (quat) {
        const float* pa = &xa[k0];
        const float* pb = &xb[k0];
        const double d = quat_angle(pa, pb);
        bool same = std::memcmp(pa, pb, 4 * sizeof(float)) == 0;
        if (!same) {  // -q is the same orientation, bit for bit too
          const float nb[4] = {-pb[0], -pb[1], -pb[2], -pb[3]};
          same = std::memcmp(pa, nb, sizeof nb) == 0;
        }
        hit = !same && (tol.exact() ? d != 0.0 : d > tol.abs + tol.rel);
        const auto both = [&] {
          return fmt::format("A {} B {}, angle {:.6g} deg", quat_text(pa), quat_text(pb), d * 57.29577951308232);
        };
        q.largest(same ? 0.0 : d, frame, body, both, {pa[0], pa[1], pa[2], pa[3]}, {pb[0], pb[1], pb[2], pb[3]});
        count_hit(hit, frame, body, both, d);
        continue;
      }
      const auto both = [&] { return fmt::format("A {} B {}", vec_text(&xa[k0]), vec_text(&xb[k0])); };
      double size = 0.0;  // the largest component difference of this body
      for (std::size_t c = 0; c < 3; ++c) {
        double d = 0.0;
        if (beyond(xa[k0 + c], xb[k0 + c], tol, d)) hit = true;
        size = std::max(size, d);
        if (d > q.max_diff || (q.max_frame < 0 && d > 0.0))
          q.largest(d, frame, body, both, {xa[k0], xa[k0 + 1], xa[k0 + 2]}, {xb[k0], xb[k0 + 1], xb[k0 + 2]});
      }
      count_hit(hit, frame, body, both, size);
    }
  }
  q.compared = fmt::format("{} common states x {} bodies", common, bodies);
  if (!ha || !hb)
    q.compared += fmt::format(" ({}: {} absent, no rotation: {})", ha ? "B" : "A", dataset, quat ? "identity" : "zero");
  if (common == 0) {
    q.available = false;
    q.compared = "no state frame in common";
  }
  return q;
}


/// A per-frame column of /frames at the frames both traces hold.
template <class T>
QuantityResult compare_column(const Side& sa, const Side& sb, const std::string& column, const char* name,
                              const Tolerance& tol) {
  const TraceReader& a = *sa.t;
  const TraceReader& b = *sb.t;
  QuantityResult q;
  q.name = name;
  q.tol = tol;
  const std::string d = "/frames/" + column;
  if (!a.has_dataset(d) || !b.has_dataset(d)) {
    q.available = false;
    const Side& missing = a.has_dataset(d) ? sb : sa;
    q.compared = fmt::format("{} missing in {}{}", d, a.has_dataset(d) ? "B" : "A",
                             missing.external ? " (an external trace: no /frames)" : "");
    return q;
  }
  const std::int64_t ra = a.complete_rows("/frames"), rb = b.complete_rows("/frames");
  const auto fa = increasing_frames(a, "/frames/frame", ra), fb = increasing_frames(b, "/frames/frame", rb);
  std::vector<T> va, vb;
  if constexpr (std::is_floating_point_v<T>) {
    va = a.read_f64(d, ra);
    vb = b.read_f64(d, rb);
  } else {
    va = a.read_u64(d, ra);
    vb = b.read_u64(d, rb);
  }
  std::map<std::int64_t, std::size_t> row_b;
  for (std::size_t i = 0; i < fb.size(); ++i) row_b[fb[i]] = i;
  std::int64_t common = 0;
  for (std::size_t i = 0; i < fa.size(); ++i) {
    const auto it = row_b.find(fa[i]);
    if (it == row_b.end()) continue;
    ++common;
    double diff = 0.0;
    const auto both = [&] { return fmt::format("A {} B {}", va[i], vb[it->second]); };
    const bool hit = beyond(va[i], vb[it->second], tol, diff);
    if (hit) ++q.beyond_count;
    if (hit && !q.differs) {
      q.differs = true;
      q.frame = fa[i];
      q.detail = both();
      q.first_size = diff;
    }
    q.largest(diff, fa[i], -1, both, {static_cast<double>(va[i])}, {static_cast<double>(vb[it->second])});
  }
  q.compared = fmt::format("{} common frames", common);
  return q;
}

template QuantityResult compare_column<std::uint64_t>(const Side&, const Side&, const std::string&, const char*,
                                                      const Tolerance&);
template QuantityResult compare_column<double>(const Side&, const Side&, const std::string&, const char*,
                                                const Tolerance&);

/// /contacts records (pairs, then normal, depth, J_n, J_t) at the frames both hold, record
/// by record in order: two octocd traces of version 1 (one contact per pair, in (a, b) order).
void compare_contact_records(const Side& a, const Side& b, const Tolerance& tol, QuantityResult& q) {
  if (!a.has_contacts || !b.has_contacts) {
    q.compared += " (counts; /contacts records not in both)";
    return;
  }
  const Contacts ra = load_contacts(a), rb = load_contacts(b);
  std::map<std::int64_t, std::size_t> row_b;
  for (std::size_t i = 0; i < rb.frame.size(); ++i) row_b[rb.frame[i]] = i;
  std::int64_t common = 0, records = 0;
  for (std::size_t i = 0; i < ra.frame.size(); ++i) {
    const auto it = row_b.find(ra.frame[i]);
    if (it == row_b.end()) continue;
    ++common;
    const auto a0 = static_cast<std::size_t>(ra.off[i]), a1 = static_cast<std::size_t>(ra.off[i + 1]);
    const auto b0 = static_cast<std::size_t>(rb.off[it->second]), b1 = static_cast<std::size_t>(rb.off[it->second + 1]);
    const std::size_t m = std::min(a1 - a0, b1 - b0);
    for (std::size_t k = 0; k < m; ++k) {
      ++records;
      const std::size_t ka = a0 + k, kb = b0 + k;
      const std::uint32_t pa0 = ra.pair[2 * ka], pa1 = ra.pair[2 * ka + 1];
      const std::uint32_t pb0 = rb.pair[2 * kb], pb1 = rb.pair[2 * kb + 1];
      std::string what;
      double size = std::numeric_limits<double>::infinity();
      if (pa0 != pb0 || pa1 != pb1) {
        what = fmt::format("contact {}: pair A ({}, {}) B ({}, {})", k, pa0, pa1, pb0, pb1);
        q.largest(std::numeric_limits<double>::infinity(), ra.frame[i], pa0, [&] { return what; });
      } else {
        const std::pair<const char*, std::pair<const float*, const float*>> fields[] = {
            {"depth", {&ra.depth[ka], &rb.depth[kb]}},
            {"jn", {&ra.jn[ka], &rb.jn[kb]}},
            {"jt", {&ra.jt[ka], &rb.jt[kb]}},
            {"normal.x", {&ra.normal[3 * ka], &rb.normal[3 * kb]}},
            {"normal.y", {&ra.normal[3 * ka + 1], &rb.normal[3 * kb + 1]}},
            {"normal.z", {&ra.normal[3 * ka + 2], &rb.normal[3 * kb + 2]}}};
        for (const auto& f : fields) {
          double d = 0.0;
          const auto both = [&] {
            return fmt::format("contact ({}, {}) {}: A {} B {}", pa0, pa1, f.first, *f.second.first, *f.second.second);
          };
          if (beyond(*f.second.first, *f.second.second, tol, d) && what.empty()) {
            what = both();
            size = d;
          }
          q.largest(d, ra.frame[i], pa0, both, {*f.second.first}, {*f.second.second});
        }
      }
      if (!what.empty()) ++q.beyond_count;
      if (!what.empty() && (!q.differs || ra.frame[i] < q.frame)) {
        q.differs = true;
        q.frame = ra.frame[i];
        q.body = pa0;
        q.detail = what;
        q.first_size = size;
      }
      if (!what.empty()) break;
    }
  }
  q.compared += fmt::format(" + {} /contacts records on {} frames", records, common);
}


/// Contacts by pair at the frames both traces hold (a version 2 or an external trace on
/// either side): per frame the set of pairs with contact rows, each pair's row count (a
/// manifold's points), then its rows in the order written: depth, jn, jt, normal and, when
/// both traces have /contacts/point, the point. A pair on one side only, or with another
/// row count, is an infinite difference.
QuantityResult compare_contacts_by_pair(const Side& a, const Side& b, const Tolerance& tol) {
  QuantityResult q;
  q.name = "contacts";
  q.tol = tol;
  if (!a.has_contacts || !b.has_contacts) {
    q.available = false;
    q.compared = fmt::format("/contacts missing in {}", !a.has_contacts && !b.has_contacts ? "both"
                                                        : a.has_contacts                    ? "B"
                                                                                            : "A");
    return q;
  }
  const Contacts ca = load_contacts(a), cb = load_contacts(b);
  const bool points = a.points && b.points, point_b = a.point_b && b.point_b, jt3 = a.jt3 && b.jt3;
  std::map<std::int64_t, std::size_t> row_b;
  for (std::size_t i = 0; i < cb.frame.size(); ++i) row_b[cb.frame[i]] = i;
  using Key = std::pair<std::uint32_t, std::uint32_t>;
  const auto by_pair = [](const Contacts& c, std::size_t i) {
    std::map<Key, std::vector<std::size_t>> m;
    for (auto k = static_cast<std::size_t>(c.off[i]); k < static_cast<std::size_t>(c.off[i + 1]); ++k)
      m[{c.pair[2 * k], c.pair[2 * k + 1]}].push_back(k);
    return m;
  };
  const auto rows_text = [](std::size_t n) { return n == 0 ? std::string("none") : fmt::format("{} row{}", n, n == 1 ? "" : "s"); };
  std::int64_t common = 0, pairs = 0, rows = 0;
  for (std::size_t i = 0; i < ca.frame.size(); ++i) {
    const auto it = row_b.find(ca.frame[i]);
    if (it == row_b.end()) continue;
    ++common;
    const std::int64_t frame = ca.frame[i];
    const auto pa = by_pair(ca, i), pb = by_pair(cb, it->second);
    std::set<Key> keys;
    for (const auto& [k, v] : pa) keys.insert(k);
    for (const auto& [k, v] : pb) keys.insert(k);
    for (const Key& key : keys) {
      ++pairs;
      const auto ia = pa.find(key), ib = pb.find(key);
      const std::size_t na = ia == pa.end() ? 0 : ia->second.size(), nb = ib == pb.end() ? 0 : ib->second.size();
      std::string what;
      double size = std::numeric_limits<double>::infinity();
      if (na != nb) {
        what = fmt::format("pair ({}, {}): {} in A, {} in B", key.first, key.second, rows_text(na), rows_text(nb));
        q.largest(std::numeric_limits<double>::infinity(), frame, key.first, [&] { return what; });
      } else {
        for (std::size_t r = 0; r < na; ++r) {
          ++rows;
          const std::size_t ka = ia->second[r], kb = ib->second[r];
          std::vector<std::pair<std::string, std::pair<float, float>>> fields{
              {"depth", {ca.depth[ka], cb.depth[kb]}},
              {"jn", {ca.jn[ka], cb.jn[kb]}},
              {"jt", {ca.jt[ka], cb.jt[kb]}},
              {"normal.x", {ca.normal[3 * ka], cb.normal[3 * kb]}},
              {"normal.y", {ca.normal[3 * ka + 1], cb.normal[3 * kb + 1]}},
              {"normal.z", {ca.normal[3 * ka + 2], cb.normal[3 * kb + 2]}}};
          if (points)
            for (std::size_t c = 0; c < 3; ++c)
              fields.push_back({fmt::format("point.{}", "xyz"[c]), {ca.point[3 * ka + c], cb.point[3 * kb + c]}});
          if (point_b)
            for (std::size_t c = 0; c < 3; ++c)
              fields.push_back({fmt::format("point_b.{}", "xyz"[c]), {ca.point_b[3 * ka + c], cb.point_b[3 * kb + c]}});
          if (jt3)
            for (std::size_t c = 0; c < 3; ++c)
              fields.push_back({fmt::format("jt3.{}", "xyz"[c]), {ca.jt3[3 * ka + c], cb.jt3[3 * kb + c]}});
          for (const auto& [field, v] : fields) {
            double d = 0.0;
            const auto both = [&, &field = field, &v = v] {
              return fmt::format("pair ({}, {}) row {} of {}: {}: A {} B {}", key.first, key.second, r, na, field,
                                 v.first, v.second);
            };
            if (beyond(v.first, v.second, tol, d) && what.empty()) {
              what = both();
              size = d;
            }
            q.largest(d, frame, key.first, both, {v.first}, {v.second});
          }
        }
      }
      if (what.empty()) continue;
      ++q.beyond_count;
      if (!q.differs || frame < q.frame) {
        q.differs = true;
        q.frame = frame;
        q.body = key.first;
        q.detail = what;
        q.first_size = size;
      }
    }
  }
  // The per-row vectors compared (both traces have them), and those only one side has.
  std::string with, only;
  const std::pair<const char*, std::pair<bool, bool>> vectors[] = {{"point", {a.points, b.points}},
                                                                   {"point_b", {a.point_b, b.point_b}},
                                                                   {"jt3", {a.jt3, b.jt3}}};
  for (const auto& [name, has] : vectors) {
    if (has.first && has.second) with += fmt::format("{}{}", with.empty() ? " with " : ", ", name);
    else if (has.first || has.second)
      only += fmt::format(" (/contacts/{} only in {})", name, has.first ? "A" : "B");
  }
  q.compared = fmt::format("{} common frames: {} pairs, {} rows by pair{}{}", common, pairs, rows, with, only);
  return q;
}

}  // namespace octocd::cli::compare_detail
