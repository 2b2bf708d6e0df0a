// `octocd compare A.h5 B.h5` (design.md sections 12, 14): golden-trace regression. First the structure:
// frame count, state rows and their frames, body count, scene name and scene parameters
// (naming every key that differs); then per quantity, with its own absolute and relative
// tolerance, the largest difference (frame, body, both values) and the first frame and
// body beyond the tolerance (0 = bit for bit). --ignore KEY leaves structure keys out.
// Exit 0 same, 3 different (structure or a quantity), 2 unreadable input, a bad option, or
// no requested quantity in both traces (nothing compared is not "same").
//
// Either trace may be octocd's own (it has /frames; version 1, or 2 for a rotating engine:
// `--engine bullet --rotation`) or an external trace (no /frames; docs/trace-format.md,
// "External traces", versions 1 and 2: checked in full by check_external_trace first).
// Version 2 adds orientations (the angle between the two quaternions; q and -q are one
// orientation) and angular velocities; a trace without rotation counts as the identity
// and zero. Contacts of a version 2 or an external trace are compared by pair (the set of
// pairs with contacts, each pair's row count, then its rows in order: manifolds).
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
#include "tools.hpp"

namespace octocd::cli {

namespace {

using json = nlohmann::json;

const std::vector<std::string>& quantity_names() {
  static const std::vector<std::string> names{"positions",  "velocities", "orientations", "angular_velocities",
                                              "contacts",   "pairs",      "energy"};
  return names;
}

const char* kToleranceAllowed =
    "VALUE or QUANTITY=VALUE, VALUE an absolute tolerance (ABS) or rel:R or ABS+rel:R, each a finite number >= 0, "
    "QUANTITY one of positions, velocities, orientations, angular_velocities, contacts, pairs, energy "
    "(comma-separated or repeated)";

/// Parses a finite number >= 0 of one --tolerance item; throws InputError naming the item.
double tolerance_number(const std::string& text, const std::string& item) {
  errno = 0;
  char* end = nullptr;
  const double v = std::strtod(text.c_str(), &end);
  // Decimal only: strtod also reads "0x10" (16), "inf" and "nan".
  if (text.empty() || text.find_first_not_of("0123456789+-.eE") != std::string::npos || end != text.c_str() + text.size() || errno == ERANGE || !std::isfinite(v))
    throw InputError(fmt::format("--tolerance '{}': '{}' is not a number; allowed: {}", item, text, kToleranceAllowed));
  if (v < 0.0)
    throw InputError(fmt::format("--tolerance '{}': {} is negative; allowed: {}", item, text, kToleranceAllowed));
  return v;
}

}  // namespace

std::map<std::string, Tolerance> parse_tolerances(const std::vector<std::string>& args) {
  std::map<std::string, Tolerance> out;
  for (const auto& q : quantity_names()) out[q] = Tolerance{};
  std::map<std::string, std::string> named;  // QUANTITY=VALUE items given: the item
  for (const auto& arg : args) {
    if (split_list(arg).empty())
      throw InputError(fmt::format("--tolerance '{}': empty; allowed: {}", arg, kToleranceAllowed));
    for (const auto& item : split_list(arg)) {
      const auto eq = item.find('=');
      std::vector<std::string> targets;
      std::string spec = item;
      if (eq != std::string::npos) {
        const std::string q = item.substr(0, eq);
        if (std::find(quantity_names().begin(), quantity_names().end(), q) == quantity_names().end())
          throw InputError(fmt::format("--tolerance '{}': unknown quantity '{}'; allowed: {}", item, q, kToleranceAllowed));
        if (const auto before = named.find(q); before != named.end())
          throw InputError(fmt::format("--tolerance '{}': {} given twice ('{}' and '{}'); allowed: each quantity once",
                                       item, q, before->second, item));
        named[q] = item;
        targets.push_back(q);
        spec = item.substr(eq + 1);
      } else {
        targets = quantity_names();
      }
      Tolerance t;
      const auto rel = spec.find("rel:");
      if (rel == std::string::npos) {
        t.abs = tolerance_number(spec, item);
      } else {
        if (rel > 0) {
          if (spec[rel - 1] != '+')
            throw InputError(fmt::format("--tolerance '{}': '{}' is not ABS+rel:R; allowed: {}", item, spec,
                                         kToleranceAllowed));
          t.abs = tolerance_number(spec.substr(0, rel - 1), item);
        }
        t.rel = tolerance_number(spec.substr(rel + 4), item);
      }
      for (const auto& q : targets) out[q] = t;
    }
  }
  return out;
}

std::string Tolerance::text() const {
  if (exact()) return "0 (bit for bit)";
  if (rel == 0.0) return fmt::format("{:g}", abs);
  if (abs == 0.0) return fmt::format("rel:{:g}", rel);
  return fmt::format("{:g}+rel:{:g}", abs, rel);
}

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

/// The result for one quantity.
struct QuantityResult {
  std::string name;
  Tolerance tol;
  std::string compared;        ///< what was compared, e.g. "301 states x 55 bodies"
  double max_diff = 0.0;       ///< largest |A - B| (inf when a NaN differs)
  std::int64_t max_frame = -1, max_body = -1;  ///< where the largest difference is
  std::string max_detail;      ///< both values there
  bool differs = false;
  std::int64_t frame = -1;     ///< first frame beyond the tolerance
  std::int64_t body = -1;      ///< first body there (-1 for per-frame quantities)
  std::string detail;          ///< the values there
  std::int64_t beyond_count = 0;  ///< values beyond the tolerance
  double first_size = 0.0;     ///< |A - B| at the first difference (inf: a NaN, a pair or row on one side only)
  bool available = true;       ///< false when a trace lacks the data (then `compared` says why)

  /// Records a difference `d` at (frame, body) with the values' text, if it is the largest.
  std::vector<double> max_a, max_b;  ///< both values there (a vector's components; empty for contact pairs)
  void largest(double d, std::int64_t f, std::int64_t b, const std::function<std::string()>& values,
               std::vector<double> va = {}, std::vector<double> vb = {}) {
    if (d > max_diff || (max_frame < 0 && d > 0.0)) {
      max_diff = d;
      max_frame = f;
      max_body = b;
      max_detail = values();
      max_a = std::move(va);
      max_b = std::move(vb);
    }
  }
};

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

/// One trace of the comparison: octocd's own (it has /frames: docs/trace-format.md, format
/// version 1, or 2 for a rotating engine) or an external trace (no /frames: "External
/// traces", versions 1 and 2; checked in full by check_external_trace before anything is
/// compared, so every bad value is an InputError naming dataset, frame and allowed values).
struct Side {
  const TraceReader* t = nullptr;
  bool external = false;                   ///< no /frames: an external trace
  int version = 1;                         ///< root attribute `version`
  std::string engine;                      ///< root attribute `engine`
  std::int64_t bodies = 0;
  std::string scene_name = "?";            ///< root attribute scene_name (external: the scene's name)
  bool scene_known = true;                 ///< false: an external trace that names no scene
  std::int64_t frame_rows = 0;             ///< steps recorded (rows of /frames; external: F)
  std::vector<std::int64_t> frames;        ///< their frames, as written
  bool has_states = false;                 ///< octocd: /states/frame; external: /states/position
  std::int64_t state_rows = 0;             ///< state rows (structure)
  std::vector<std::int64_t> state_frames;  ///< their frames, as written
  bool rotation = false;                   ///< /states/orientation and /states/angular_velocity
  bool has_contacts = false;               ///< /contacts/offsets
  bool points = false;                     ///< /contacts/point
  const std::string& path() const { return t->path(); }
  /// "octocd trace version 1" or "external trace version 2".
  std::string kind() const { return fmt::format("{} trace version {}", external ? "external" : "octocd", version); }
};

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
  return s;
}

/// The state rows a quantity is compared at: complete rows, their frames checked.
std::pair<std::int64_t, std::vector<std::int64_t>> state_rows(const Side& s) {
  if (s.external) return {s.state_rows, s.state_frames};  // 0..F, checked by check_external_trace
  const std::int64_t r = s.t->complete_rows("/states");  // at most committed_states (docs/trace-format.md)
  return {r, increasing_frames(*s.t, "/states/frame", r)};
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

/// The /contacts records of a trace: rows of frame[i] are off[i] .. off[i+1]-1.
struct Contacts {
  std::vector<std::int64_t> off, frame;
  std::vector<std::uint32_t> pair;
  std::vector<float> normal, depth, jn, jt, point;  ///< point: empty without /contacts/point
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
    if (s.points) {
      const auto shape = t.shape("/contacts/point");
      if (shape.size() != 2 || shape[1] != 3)
        throw InputError(fmt::format("{}: /contacts/point: shape {}; allowed: C x 3 (one world point per contact row)",
                                     t.path(), fmt::join(shape, " x ")));
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
  return r;
}

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
  const bool points = a.points && b.points;
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
  q.compared = fmt::format("{} common frames: {} pairs, {} rows by pair{}", common, pairs, rows,
                           points                  ? " with points"
                           : a.points || b.points ? fmt::format(" (/contacts/point only in {})", a.points ? "A" : "B")
                                                   : "");
  return q;
}

/// A JSON value as text; a number stored from a float32 prints as that float (0.999, not
/// 0.9990000128746033), an integral one without ".0".
std::string json_text(const json& v) {
  if (v.is_string()) return v.get<std::string>();
  if (v.is_number_float()) {
    const double d = v.get<double>();
    const auto f = static_cast<float>(d);
    return static_cast<double>(f) == d ? fmt::format("{}", f) : fmt::format("{}", d);
  }
  return v.dump();
}

/// The keys (JSON pointers) where two JSON documents differ, as "KEY: A vs B", skipping
/// keys under `skip`.
std::vector<std::string> json_differences(const json& a, const json& b, const std::vector<std::string>& skip) {
  std::vector<std::string> out;
  for (const auto& op : json::diff(a, b)) {
    const std::string path = op.value("path", "");
    bool skipped = false;
    for (const auto& s : skip)
      if (path == s || path.rfind(s + "/", 0) == 0) skipped = true;
    if (skipped) continue;
    const json::json_pointer ptr(path);
    const std::string va = a.contains(ptr) ? json_text(a.at(ptr)) : "(absent)";
    const std::string vb = b.contains(ptr) ? json_text(b.at(ptr)) : "(absent)";
    out.push_back(fmt::format("{}: {} vs {}", path.empty() ? "/" : path, va, vb));
  }
  return out;
}

json parsed_attribute(const TraceReader& t, const char* name) {
  if (!t.has_attribute(name)) return json();
  try {
    return json::parse(t.string_attribute(name));
  } catch (const json::exception&) {
    return json(t.string_attribute(name));
  }
}

/// "frames 0..499" or the first frame only one side holds.
std::string frame_set_difference(const std::vector<std::int64_t>& fa, const std::vector<std::int64_t>& fb) {
  const std::set<std::int64_t> sa(fa.begin(), fa.end()), sb(fb.begin(), fb.end());
  for (auto f : sa)
    if (!sb.count(f)) return fmt::format("frame {} only in A", f);
  for (auto f : sb)
    if (!sa.count(f)) return fmt::format("frame {} only in B", f);
  if (sa.size() != fa.size() || sb.size() != fb.size()) return "a frame recorded twice";
  return "";
}

std::string range_text(const std::vector<std::int64_t>& f) {
  if (f.empty()) return "none";
  return fmt::format("{}..{}", *std::min_element(f.begin(), f.end()), *std::max_element(f.begin(), f.end()));
}

/// The bodies and materials a trace states beyond the scene (an external trace, or one of
/// version 2), where both traces hold them: /bodies tables (the first body that differs,
/// bit for bit) and the version 2 root attributes (docs/trace-format.md). A table or
/// attribute that only one trace has is not compared (its default may be the same).
std::vector<std::string> body_differences(const Side& a, const Side& b) {
  std::vector<std::string> out;
  if (a.bodies != b.bodies) return out;  // named already
  const auto n = static_cast<std::uint64_t>(a.bodies);
  const std::pair<const char*, std::uint64_t> tables[] = {{"/bodies/inverse_mass", 1},   {"/bodies/local_aabb_min", 3},
                                                          {"/bodies/local_aabb_max", 3}, {"/bodies/inertia", 9},
                                                          {"/bodies/friction", 1},       {"/bodies/restitution", 1}};
  for (const auto& [d, k] : tables) {
    if (!a.t->has_dataset(d) || !b.t->has_dataset(d)) continue;
    for (const Side* s : {&a, &b}) {
      const auto shape = s->t->shape(d);
      std::uint64_t per = 1;
      for (std::size_t i = 1; i < shape.size(); ++i) per *= shape[i];
      if (shape.empty() || shape[0] != n || per != k)
        throw InputError(fmt::format("{}: {}: shape {}; allowed: {} bodies{}", s->path(), d, fmt::join(shape, " x "), n,
                                     k == 1 ? "" : k == 3 ? " x 3" : " x 3 x 3"));
    }
    const auto va = a.t->read_f32(d, a.bodies), vb = b.t->read_f32(d, b.bodies);
    for (std::uint64_t i = 0; i < n; ++i)
      if (std::memcmp(&va[i * k], &vb[i * k], k * sizeof(float)) != 0) {
        const std::uint64_t width = k;  // a structured binding is not captured before C++20 (clang)
        const auto text = [&, k = width](const std::vector<float>& v) {
          return k == 1 ? fmt::format("{}", v[i]) : fmt::format("({})", fmt::join(v.begin() + static_cast<std::ptrdiff_t>(i * k), v.begin() + static_cast<std::ptrdiff_t>((i + 1) * k), ", "));
        };
        out.push_back(fmt::format("{}: body {}: {} vs {}", d, i, text(va), text(vb)));
        break;
      }
  }
  for (const char* name : {"mu", "restitution", "contact_margin", "broadphase_exact"})
    if (a.t->has_attribute(name) && b.t->has_attribute(name) &&
        a.t->number_attribute(name) != b.t->number_attribute(name))
      out.push_back(fmt::format("{}: {} vs {} (root attribute)", name, json_text(a.t->number_attribute(name)),
                                json_text(b.t->number_attribute(name))));
  for (const char* name : {"detection", "friction_combine", "restitution_combine", "contact_geometry", "response_model"})
    if (a.t->has_attribute(name) && b.t->has_attribute(name) &&
        a.t->string_attribute(name) != b.t->string_attribute(name))
      out.push_back(fmt::format("{}: '{}' vs '{}' (root attribute)", name, a.t->string_attribute(name),
                                b.t->string_attribute(name)));
  return out;
}

const char* state_dataset(const std::string& q) {
  if (q == "positions") return "/states/position";
  if (q == "velocities") return "/states/velocity";
  if (q == "orientations") return "/states/orientation";
  return "/states/angular_velocity";
}

}  // namespace

CLI::App* add_compare_command(CLI::App& app, CompareOptions& o) {
  CLI::App* c = add_table_command(app, CommandId::compare);
  c->add_option("a", o.a, "First trace (.h5), e.g. the golden one")->required();
  c->add_option("b", o.b, "Second trace (.h5)")->required();
  c->add_option("--tolerance", o.tolerance,
                "Tolerances, comma-separated or repeated: VALUE (every quantity) or QUANTITY=VALUE; VALUE is an "
                "absolute tolerance ABS (in the quantity's unit: m, m/s, rad (orientations: the angle between the "
                "two), rad/s, counts, J; contacts: m for depth and points, N s for impulses, 1 for normals), rel:R "
                "(relative: |A-B| <= R max(|A|,|B|); orientations: R rad, as |q| = 1) or ABS+rel:R (|A-B| <= ABS + R "
                "max(|A|,|B|)), each >= 0; 0 = bit for bit (the default; orientations: q or -q bit for bit, or an "
                "angle of exactly 0). E.g. --tolerance positions=1e-6 --tolerance velocities=rel:1e-4 --tolerance "
                "orientations=1e-4")
      ->allow_extra_args(false);
  c->add_option("--quantity", o.quantities,
                "Comma-separated, each from /states, /contacts or /frames: positions, velocities (/states/position, "
                "/states/velocity: every version, per component); orientations (/states/orientation, version 2: the "
                "angle between the two quaternions, q and -q the same orientation) and angular_velocities "
                "(/states/angular_velocity, version 2, per component), a trace without them counting as unrotated "
                "(identity, zero: version 1 against version 2 works); contacts (two octocd version 1 traces: "
                "/frames/contacts and the /contacts records in order; otherwise by pair: the pairs with contact rows "
                "in each frame, each pair's row count (a manifold), then its rows: depth, jn, jt, normal, and point "
                "when both have /contacts/point); pairs (/frames/aabb_pairs) and energy (/frames/kinetic_energy): "
                "octocd traces only (an external trace has no /frames). Default: positions,velocities,contacts,pairs, "
                "and orientations,angular_velocities when either trace is of version 2");
  c->add_option("--ignore", o.ignore,
                "A structure key not to compare (repeatable), as the structure lines name it: e.g. --ignore /midphase "
                "(cpu against bullet, which has no midphase), --ignore /response (and every key under it), --ignore "
                "dt, --ignore scene_name; the ignored differences are listed")
      ->allow_extra_args(false);
  c->add_option("--json", o.json,
                "Also write everything as JSON to this file: structure differences, per quantity its tolerance, "
                "largest difference (frame, body, values) and first difference");
  return c;
}

void compare_traces(const CompareOptions& o, CompareOutcome& out) {
  const std::map<std::string, Tolerance> tols = parse_tolerances(o.tolerance);
  const char* kQuantityAllowed =
      "positions, velocities, orientations, angular_velocities, contacts, pairs, energy";
  std::vector<std::string> qs = split_list(o.quantities);
  if (!o.quantities.empty() && qs.empty()) throw InputError(fmt::format("--quantity: empty; allowed: {}", kQuantityAllowed));
  for (const auto& q : qs)
    if (std::find(quantity_names().begin(), quantity_names().end(), q) == quantity_names().end())
      throw InputError(fmt::format("--quantity: unknown quantity '{}'; allowed: {}", q, kQuantityAllowed));
  const TraceReader ta(o.a), tb(o.b);
  const Side a = make_side(ta), b = make_side(tb);
  if (qs.empty()) {
    qs = {"positions", "velocities"};
    if (a.version == 2 || b.version == 2) qs.insert(qs.end(), {"orientations", "angular_velocities"});
    qs.insert(qs.end(), {"contacts", "pairs"});
  }
  const std::string& sa = a.scene_name;
  const std::string& sb = b.scene_name;
  const std::int64_t na = a.bodies, nb = b.bodies;
  const bool octocd_both = !a.external && !b.external;

  // ---- structure: every difference here fails the comparison (exit 3)
  std::vector<std::string> structure;
  if (a.scene_known && b.scene_known && sa != sb) structure.push_back(fmt::format("scene_name: '{}' vs '{}'", sa, sb));
  if (na != nb) structure.push_back(fmt::format("/bodies: {} vs {} bodies", na, nb));
  const std::int64_t rows_a = a.frame_rows, rows_b = b.frame_rows;
  const auto& ffa = a.frames;
  const auto& ffb = b.frames;
  const char* frames_name = octocd_both ? "/frames" : "frames";
  if (rows_a != rows_b)
    structure.push_back(fmt::format("{}: {} vs {} frames (A frames {}, B frames {})", frames_name, rows_a, rows_b,
                                    range_text(ffa), range_text(ffb)));
  else if (const std::string d = frame_set_difference(ffa, ffb); !d.empty())
    structure.push_back(fmt::format("{}: {}", octocd_both ? "/frames/frame" : "frames", d));
  const bool states_a = a.has_states, states_b = b.has_states;
  if (states_a != states_b) {
    structure.push_back(fmt::format("/states: {} vs {}", states_a ? "present" : "absent", states_b ? "present" : "absent"));
  } else if (states_a) {
    const std::int64_t sra = a.state_rows, srb = b.state_rows;
    const auto& sfa = a.state_frames;
    const auto& sfb = b.state_frames;
    if (sra != srb)
      structure.push_back(fmt::format("/states: {} vs {} state rows (A frames {}, B frames {})", sra, srb,
                                      range_text(sfa), range_text(sfb)));
    else if (const std::string d = frame_set_difference(sfa, sfb); !d.empty())
      structure.push_back("/states/frame: " + d);
  }
  // Scene parameters as the engine resolved them, then the scene file's other keys. The
  // broadphase is engine configuration (every broadphase finds the same pairs); the
  // frame count is judged above from the rows themselves. An external trace has no
  // `parameters`: then the scene (when both have one) and the root attribute dt.
  const std::vector<std::string> skip{"/broadphase", "/frames", "/description"};
  std::set<std::string> named;
  if (octocd_both)
    for (const auto& d : json_differences(parsed_attribute(ta, "parameters"), parsed_attribute(tb, "parameters"), skip)) {
      named.insert(d.substr(0, d.find(':')));
      structure.push_back(d + " (parameters)");
    }
  if (octocd_both || (ta.has_attribute("scene") && tb.has_attribute("scene")))
    for (const auto& d : json_differences(parsed_attribute(ta, "scene"), parsed_attribute(tb, "scene"),
                                          std::vector<std::string>{"/broadphase", "/frames", "/description", "/name"}))
    {
      const std::string key = d.substr(0, d.find(':'));
      bool covered = false;  // the resolved parameter under or above this key is named already
      for (const auto& n : named)
        if (n == key || n.rfind(key + "/", 0) == 0 || key.rfind(n + "/", 0) == 0) covered = true;
      if (!covered) structure.push_back(d + " (scene)");
    }
  if (!octocd_both && ta.has_attribute("dt") && tb.has_attribute("dt") &&
      ta.number_attribute("dt") != tb.number_attribute("dt"))
    structure.push_back(fmt::format("dt: {} vs {} (root attribute)", json_text(ta.number_attribute("dt")),
                                    json_text(tb.number_attribute("dt"))));
  if (!octocd_both || a.version == 2 || b.version == 2)
    for (const auto& d : body_differences(a, b)) structure.push_back(d);
  // --ignore: a difference whose key is an ignored key or lies under one is listed, not failed.
  std::vector<std::string> ignored;
  for (const auto& k : o.ignore)
    if (k.empty() || k.back() == '/')
      throw InputError(fmt::format("--ignore '{}': allowed: a structure key as `compare` names it, e.g. /midphase, "
                                   "/response/beta, dt, scene_name",
                                   k));
  {
    std::vector<std::string> kept;
    for (const auto& d : structure) {
      const std::string key = d.substr(0, d.find(':'));
      const bool drop = std::any_of(o.ignore.begin(), o.ignore.end(), [&](const std::string& k) {
        return key == k || key.rfind(k + "/", 0) == 0;
      });
      (drop ? ignored : kept).push_back(d);
    }
    structure = std::move(kept);
  }

  const auto attr = [](const TraceReader& t, const char* n) {
    return t.has_attribute(n) ? t.string_attribute(n) : std::string("?");
  };
  const auto header = [&](const Side& s) {
    if (s.external) return fmt::format("{}, engine {}", s.kind(), s.engine);
    return fmt::format("{}, {}, {}{}", attr(*s.t, "engine"), attr(*s.t, "broadphase"), attr(*s.t, "build_id"),
                       s.version == 1 ? "" : fmt::format(", version {}", s.version));
  };
  // The traces' text reaches the terminal with its control characters escaped (\xNN).
  fmt::format_to(std::back_inserter(out.text), "compare {} ({})\n   with {} ({})\n", printable(o.a), printable(header(a)), printable(o.b),
             printable(header(b)));
  fmt::format_to(std::back_inserter(out.text), "scene {}, {} bodies; tolerances:", printable(a.scene_known ? sa : sb), na);
  for (const auto& q : qs) fmt::format_to(std::back_inserter(out.text), " {}={}", q, tols.at(q).text());
  fmt::format_to(std::back_inserter(out.text), "\n");
  if (a.version != b.version || a.rotation != b.rotation)
    fmt::format_to(std::back_inserter(out.text), "note: {} (A) vs {} (B); a trace without rotation counts as unrotated (orientation identity, angular "
               "velocity zero)\n",
               a.kind() + (a.rotation ? " with rotation" : ""), b.kind() + (b.rotation ? " with rotation" : ""));
  fmt::format_to(std::back_inserter(out.text), "\n");
  if (!structure.empty()) {
    fmt::format_to(std::back_inserter(out.text), "structure differs ({} key{}):\n", structure.size(), structure.size() == 1 ? "" : "s");
    for (const auto& d : structure) fmt::format_to(std::back_inserter(out.text), "  {}\n", printable(d));
    fmt::format_to(std::back_inserter(out.text), "\n");
  }
  if (!ignored.empty()) {
    fmt::format_to(std::back_inserter(out.text), "structure ignored (--ignore, {} key{}):\n", ignored.size(), ignored.size() == 1 ? "" : "s");
    for (const auto& d : ignored) fmt::format_to(std::back_inserter(out.text), "  {}\n", d);
    fmt::format_to(std::back_inserter(out.text), "\n");
  }

  std::vector<QuantityResult> results;
  for (const auto& q : qs) {
    const Tolerance& tol = tols.at(q);
    if (q == "positions" || q == "velocities" || q == "orientations" || q == "angular_velocities") {
      const char* d = state_dataset(q);
      const bool rotation = q == "orientations" || q == "angular_velocities";
      QuantityResult r;
      r.name = q;
      r.tol = tol;
      if (!states_a || !states_b) {
        r.available = false;
        r.compared = fmt::format("/states missing in {}", !states_a && !states_b ? "both" : states_a ? "B" : "A");
      } else if (!rotation && (!ta.has_dataset(d) || !tb.has_dataset(d))) {
        r.available = false;
        r.compared = std::string(d) + " missing";
      } else if (na != nb) {
        r.available = false;
        r.compared = "body counts differ";
      } else {
        r = compare_states(a, b, d, q.c_str(), na, tol);
      }
      results.push_back(r);
    } else if (q == "contacts") {
      if (octocd_both && a.version == 1 && b.version == 1) {
        QuantityResult r = compare_column<std::uint64_t>(a, b, "contacts", "contacts", tol);
        if (r.available) compare_contact_records(a, b, tol, r);
        results.push_back(r);
      } else {
        results.push_back(compare_contacts_by_pair(a, b, tol));
      }
    } else if (q == "pairs") {
      results.push_back(compare_column<std::uint64_t>(a, b, "aabb_pairs", "pairs", tol));
    } else {
      results.push_back(compare_column<double>(a, b, "kinetic_energy", "energy", tol));
    }
  }
  fmt::format_to(std::back_inserter(out.text), "{:<18} {:<56} {:>12}  {}\n", "quantity", "compared", "max |A-B|", "largest difference / first beyond tolerance");
  const QuantityResult* first = nullptr;
  bool any_missing = false;
  json jq = json::array();
  const auto num = [](double v) { return std::isfinite(v) ? json(v) : json("inf"); };
  for (const auto& r : results) {
    if (r.differs && (!first || r.frame < first->frame)) first = &r;
    if (!r.available) any_missing = true;
    const auto at = [](std::int64_t f, std::int64_t body) {
      return body >= 0 ? fmt::format("frame {}, body {}", f, body) : fmt::format("frame {}", f);
    };
    fmt::format_to(std::back_inserter(out.text), "{:<18} {:<56} {:>12}  {}\n", r.name, r.compared, r.available ? fmt::format("{:.6g}", r.max_diff) : "n/a",
               !r.available ? "not compared"
               : r.max_frame < 0 ? "-"
                                 : fmt::format("largest at {}: {}", at(r.max_frame, r.max_body), r.max_detail));
    if (r.differs)
      fmt::format_to(std::back_inserter(out.text), "{:<18} {:<56} {:>12}  first beyond {} at {}: {} ({} beyond)\n", "", "", "", r.tol.text(),
                 at(r.frame, r.body), r.detail, r.beyond_count);
    jq.push_back({{"quantity", r.name},
                  {"tolerance", {{"abs", r.tol.abs}, {"rel", r.tol.rel}}},
                  {"compared", r.compared},
                  {"available", r.available},
                  {"max_abs_difference", num(r.max_diff)},
                  {"max", {{"frame", r.max_frame}, {"body", r.max_body}, {"values", r.max_detail},
                           {"a", r.max_a}, {"b", r.max_b}}},
                  {"differs", r.differs},
                  {"beyond_count", r.beyond_count},
                  {"frame", r.frame},
                  {"body", r.body},
                  {"detail", r.detail}});
  }
  const bool differ = first != nullptr || !structure.empty();
  const bool compared_any =
      std::any_of(results.begin(), results.end(), [](const QuantityResult& r) { return r.available; });
  if (!compared_any)
    fmt::format_to(std::back_inserter(out.text), "\nNOTHING COMPARED: no requested quantity is in both traces\n");
  else if (!structure.empty())
    fmt::format_to(std::back_inserter(out.text), "\nDIFFERENT: structure ({}){}\n", structure.front(),
               first ? fmt::format("; values first at frame {}{} ({})", first->frame,
                                   first->body >= 0 ? fmt::format(", body {}", first->body) : "", first->name)
                     : "");
  else if (first)
    fmt::format_to(std::back_inserter(out.text), "\nDIFFERENT: first at frame {}{} ({})\n", first->frame,
               first->body >= 0 ? fmt::format(", body {}", first->body) : "", first->name);
  else
    fmt::format_to(std::back_inserter(out.text), "\nsame{}\n", any_missing ? " (in what both traces hold)" : "");
  {
    json jt = json::object();
    for (const auto& q : qs) jt[q] = {{"abs", tols.at(q).abs}, {"rel", tols.at(q).rel}};
    json j{{"format", "octocd-compare"},
           {"version", 2},
           {"a", o.a},
           {"b", o.b},
           {"traces", {{{"version", a.version}, {"external", a.external}, {"rotation", a.rotation}},
                       {{"version", b.version}, {"external", b.external}, {"rotation", b.rotation}}}},
           {"tolerance", jt},
           {"scene", a.scene_known ? sa : sb},
           {"bodies", na},
           {"same", !differ},
           {"structure", structure},
           {"ignored", ignored},
           {"compared_any", compared_any},
           {"quantities", jq}};
    if (first) {
      j["first"] = {{"frame", first->frame}, {"body", first->body}, {"quantity", first->name}};
      out.first_frame = first->frame;
      out.first_body = first->body;
      out.first_quantity = first->name;
      out.first_detail = first->detail;
      out.first_size = first->first_size;
    }
    out.doc = std::move(j);
  }
  out.same = !differ;
  out.structure = structure;
  if (!compared_any) {
    // Nothing requested could be compared: not "same" (exit 2, naming what each trace lacks).
    std::string why;
    for (const auto& r : results) why += fmt::format("{}{}: {}", why.empty() ? "" : "; ", r.name, r.compared);
    out.nothing_compared = fmt::format("{} and {}: no requested quantity could be compared ({}); allowed: a quantity "
                                       "both traces hold (--quantity positions,velocities works on every trace with "
                                       "/states)",
                                       o.a, o.b, why);
  }
}

CompareOutcome compare_traces(const CompareOptions& o) {
  CompareOutcome out;
  compare_traces(o, out);
  return out;
}

int compare_command(const CompareOptions& o) {
  if (!o.json.empty()) check_output_file(o.json, "--json");  // before any work (atomic_file.hpp)
  CompareOutcome out;
  try {
    compare_traces(o, out);
  } catch (...) {  // what was found before the malformed part stays on stdout
    fmt::print("{}", out.text);
    throw;
  }
  fmt::print("{}", out.text);
  if (!o.json.empty())
    write_file_atomically(o.json, out.doc.dump(1, ' ', false, json::error_handler_t::replace) + "\n", "--json");
  if (!out.nothing_compared.empty()) throw InputError(out.nothing_compared);
  return out.same ? 0 : 3;
}

}  // namespace octocd::cli
