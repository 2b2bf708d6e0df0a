// `octocd compare A.h5 B.h5` (SPEC 12, 14): golden-trace regression. First the structure:
// frame count, state rows and their frames, body count, scene name and scene parameters
// (naming every key that differs); then per quantity, with its own absolute and relative
// tolerance, the largest difference (frame, body, both values) and the first frame and
// body beyond the tolerance (0 = bit for bit). Exit 0 same, 3 different (structure or a
// quantity), 2 unreadable input or a bad option.
#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <map>
#include <optional>
#include <set>

#include <fmt/format.h>
#include <fmt/ranges.h>

#include "octocd/error.hpp"
#include "octocd/trace_reader.hpp"
#include "tools.hpp"

namespace octocd::cli {

namespace {

using json = nlohmann::json;

const std::vector<std::string>& quantity_names() {
  static const std::vector<std::string> names{"positions", "velocities", "contacts", "pairs", "energy"};
  return names;
}

const char* kToleranceAllowed =
    "VALUE or QUANTITY=VALUE, VALUE an absolute tolerance (ABS) or rel:R or ABS+rel:R, each a finite number >= 0, "
    "QUANTITY one of positions, velocities, contacts, pairs, energy (comma-separated or repeated)";

/// Parses a finite number >= 0 of one --tolerance item; throws InputError naming the item.
double tolerance_number(const std::string& text, const std::string& item) {
  errno = 0;
  char* end = nullptr;
  const double v = std::strtod(text.c_str(), &end);
  if (text.empty() || end != text.c_str() + text.size() || errno == ERANGE || !std::isfinite(v))
    throw InputError(fmt::format("--tolerance '{}': '{}' is not a number; allowed: {}", item, text, kToleranceAllowed));
  if (v < 0.0)
    throw InputError(fmt::format("--tolerance '{}': {} is negative; allowed: {}", item, text, kToleranceAllowed));
  return v;
}

}  // namespace

std::map<std::string, Tolerance> parse_tolerances(const std::vector<std::string>& args) {
  std::map<std::string, Tolerance> out;
  for (const auto& q : quantity_names()) out[q] = Tolerance{};
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

/// Positions or velocities at the states both traces hold.
QuantityResult compare_states(const TraceReader& a, const TraceReader& b, const char* dataset, const char* name,
                              std::int64_t bodies, const Tolerance& tol) {
  QuantityResult q;
  q.name = name;
  q.tol = tol;
  const auto rows = [&](const TraceReader& t) {
    const auto shape = t.shape(dataset);
    if (shape.size() != 3 || shape[1] != static_cast<std::uint64_t>(bodies) || shape[2] != 3)
      throw InputError(fmt::format("{}: {}: shape {}; allowed: states x {} bodies x 3", t.path(), dataset,
                                   fmt::join(shape, " x "), bodies));
    return t.complete_rows("/states");  // at most committed_states (docs/trace-format.md)
  };
  const std::int64_t ra = rows(a), rb = rows(b);
  const auto fa = increasing_frames(a, "/states/frame", ra), fb = increasing_frames(b, "/states/frame", rb);
  std::map<std::int64_t, std::int64_t> row_b;
  for (std::int64_t i = 0; i < rb; ++i) row_b[fb[static_cast<std::size_t>(i)]] = i;
  std::int64_t common = 0;
  for (std::int64_t i = 0; i < ra; ++i) {
    const auto it = row_b.find(fa[static_cast<std::size_t>(i)]);
    if (it == row_b.end()) continue;
    ++common;
    const std::int64_t frame = fa[static_cast<std::size_t>(i)];
    const auto xa = a.read_f32_rows(dataset, i, 1), xb = b.read_f32_rows(dataset, it->second, 1);
    for (std::int64_t body = 0; body < bodies; ++body) {
      bool hit = false;
      const std::size_t k0 = static_cast<std::size_t>(3 * body);
      const auto both = [&] { return fmt::format("A {} B {}", vec_text(&xa[k0]), vec_text(&xb[k0])); };
      for (std::size_t c = 0; c < 3; ++c) {
        double d = 0.0;
        if (beyond(xa[k0 + c], xb[k0 + c], tol, d)) hit = true;
        if (d > q.max_diff || (q.max_frame < 0 && d > 0.0))
          q.largest(d, frame, body, both, {xa[k0], xa[k0 + 1], xa[k0 + 2]}, {xb[k0], xb[k0 + 1], xb[k0 + 2]});
      }
      if (hit) ++q.beyond_count;
      if (hit && !q.differs) {
        q.differs = true;
        q.frame = frame;
        q.body = body;
        q.detail = both();
      }
    }
  }
  q.compared = fmt::format("{} common states x {} bodies", common, bodies);
  if (common == 0) {
    q.available = false;
    q.compared = "no state frame in common";
  }
  return q;
}

/// A per-frame column of /frames at the frames both traces hold.
template <class T>
QuantityResult compare_column(const TraceReader& a, const TraceReader& b, const std::string& column,
                              const char* name, const Tolerance& tol) {
  QuantityResult q;
  q.name = name;
  q.tol = tol;
  const std::string d = "/frames/" + column;
  if (!a.has_dataset(d) || !b.has_dataset(d)) {
    q.available = false;
    q.compared = fmt::format("{} missing in {}", d, a.has_dataset(d) ? "B" : "A");
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
    }
    q.largest(diff, fa[i], -1, both, {static_cast<double>(va[i])}, {static_cast<double>(vb[it->second])});
  }
  q.compared = fmt::format("{} common frames", common);
  return q;
}

/// /contacts records (pairs, then normal, depth, J_n, J_t) at the frames both hold.
void compare_contact_records(const TraceReader& a, const TraceReader& b, const Tolerance& tol, QuantityResult& q) {
  if (!a.has_dataset("/contacts/offsets") || !b.has_dataset("/contacts/offsets")) {
    q.compared += " (counts; /contacts records not in both)";
    return;
  }
  struct Rec {
    std::vector<std::int64_t> off, frame;
    std::vector<std::uint32_t> pair;
    std::vector<float> normal, depth, jn, jt;
  };
  const auto load = [](const TraceReader& t) {
    Rec r;
    // Complete rows: at most committed_frames (docs/trace-format.md).
    if (t.shape("/contacts/offsets").at(0) == 0) return r;
    const std::int64_t rows = t.complete_rows("/contacts");
    r.frame = increasing_frames(t, "/contacts/frame", rows);
    r.off = t.read_i64("/contacts/offsets", rows + 1);
    for (std::size_t i = 0; i < r.off.size(); ++i)
      if ((i == 0 && r.off[i] != 0) || (i > 0 && r.off[i] < r.off[i - 1]))
        throw InputError(fmt::format("{}: /contacts/offsets: row {} is {}{}; allowed: 0 first, never decreasing",
                                     t.path(), i, r.off[i], i > 0 ? fmt::format(" after {}", r.off[i - 1]) : ""));
    const auto flat = static_cast<std::int64_t>(std::min({t.shape("/contacts/pair").at(0),
                                                          t.shape("/contacts/depth").at(0),
                                                          t.shape("/contacts/normal").at(0),
                                                          t.shape("/contacts/jn").at(0), t.shape("/contacts/jt").at(0)}));
    // Offsets start at 0 and never decrease (else the file is garbage: exit 2); rows whose
    // records lie past the flat arrays' end are a killed run's unwritten tail: dropped.
    for (std::size_t i = 0; i < r.off.size(); ++i)
      if ((i == 0 && r.off[0] != 0) || (i > 0 && r.off[i] < r.off[i - 1]))
        throw InputError(fmt::format("{}: /contacts/offsets: row {} is {} after {}; allowed: offsets from 0, never "
                                     "decreasing (docs/trace-format.md)",
                                     t.path(), i, r.off[i], i == 0 ? std::int64_t{0} : r.off[i - 1]));
    std::size_t good = 0;
    while (good < r.frame.size() && r.off[good + 1] <= flat) ++good;
    r.frame.resize(good);
    r.off.resize(good + 1);
    const std::int64_t used = r.off.empty() ? 0 : r.off.back();
    r.pair = t.read_u32("/contacts/pair", used);
    r.normal = t.read_f32("/contacts/normal", used);
    r.depth = t.read_f32("/contacts/depth", used);
    r.jn = t.read_f32("/contacts/jn", used);
    r.jt = t.read_f32("/contacts/jt", used);
    return r;
  };
  const Rec ra = load(a), rb = load(b);
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
          if (beyond(*f.second.first, *f.second.second, tol, d) && what.empty()) what = both();
          q.largest(d, ra.frame[i], pa0, both, {*f.second.first}, {*f.second.second});
        }
      }
      if (!what.empty()) ++q.beyond_count;
      if (!what.empty() && (!q.differs || ra.frame[i] < q.frame)) {
        q.differs = true;
        q.frame = ra.frame[i];
        q.body = pa0;
        q.detail = what;
      }
      if (!what.empty()) break;
    }
  }
  q.compared += fmt::format(" + {} /contacts records on {} frames", records, common);
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

std::vector<std::int64_t> frames_of(const TraceReader& t, const std::string& dataset, std::int64_t rows) {
  return rows > 0 ? t.read_i64(dataset, rows) : std::vector<std::int64_t>{};
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

}  // namespace

CLI::App* add_compare_command(CLI::App& app, CompareOptions& o) {
  CLI::App* c = app.add_subcommand(
      "compare",
      "Compare two traces (golden-trace regression, CPU vs CUDA). First their structure: frame count, state rows and "
      "their frames, body count, scene name and scene parameters (every key that differs is named, e.g. "
      "`/response/beta: 1 vs 0.999`; the broadphase is not compared: every broadphase finds the same pairs). Then per "
      "quantity, with its own tolerance: the largest difference (frame, body, both values) and the first frame and "
      "body beyond the tolerance. Exit 0 same, 3 different (structure or a quantity beyond its tolerance), 2 "
      "unreadable input or bad option");
  c->add_option("a", o.a, "First trace (.h5), e.g. the golden one")->required();
  c->add_option("b", o.b, "Second trace (.h5)")->required();
  c->add_option("--tolerance", o.tolerance,
                "Tolerances, comma-separated or repeated: VALUE (every quantity) or QUANTITY=VALUE; VALUE is an "
                "absolute tolerance ABS (in the quantity's unit: m, m/s, counts, J; contacts: m for depth, N s for "
                "impulses, 1 for normals), rel:R (relative: |A-B| <= R max(|A|,|B|)) or ABS+rel:R (|A-B| <= ABS + R "
                "max(|A|,|B|)), each >= 0; 0 = bit for bit (the default). E.g. --tolerance positions=1e-6 "
                "--tolerance velocities=rel:1e-4")
      ->allow_extra_args(false);
  c->add_option("--quantity", o.quantities,
                "Comma-separated: positions, velocities (/states), contacts (/frames/contacts and /contacts when "
                "both have it), pairs (/frames/aabb_pairs), energy (/frames/kinetic_energy)")
      ->default_val("positions,velocities,contacts,pairs");
  c->add_option("--json", o.json,
                "Also write everything as JSON to this file: structure differences, per quantity its tolerance, "
                "largest difference (frame, body, values) and first difference");
  return c;
}

int compare_command(const CompareOptions& o) {
  const std::map<std::string, Tolerance> tols = parse_tolerances(o.tolerance);
  const std::vector<std::string> qs = split_list(o.quantities);
  if (qs.empty()) throw InputError("--quantity: empty; allowed: positions, velocities, contacts, pairs, energy");
  for (const auto& q : qs)
    if (std::find(quantity_names().begin(), quantity_names().end(), q) == quantity_names().end())
      throw InputError(fmt::format("--quantity: unknown quantity '{}'; allowed: positions, velocities, contacts, "
                                   "pairs, energy",
                                   q));
  const TraceReader a(o.a), b(o.b);
  for (const TraceReader* t : {&a, &b})
    for (const char* d : {"/bodies/shape_id", "/frames/frame"})
      if (!t->has_dataset(d))
        throw InputError(fmt::format("{}: {}: missing; allowed: a complete octocd trace", t->path(), d));
  const auto attr = [](const TraceReader& t, const char* n) {
    return t.has_attribute(n) ? t.string_attribute(n) : std::string("?");
  };
  const std::string sa = attr(a, "scene_name"), sb = attr(b, "scene_name");
  const auto na = static_cast<std::int64_t>(a.shape("/bodies/shape_id").at(0));
  const auto nb = static_cast<std::int64_t>(b.shape("/bodies/shape_id").at(0));

  // ---- structure: every difference here fails the comparison (exit 3)
  std::vector<std::string> structure;
  if (sa != sb) structure.push_back(fmt::format("scene_name: '{}' vs '{}'", sa, sb));
  if (na != nb) structure.push_back(fmt::format("/bodies: {} vs {} bodies", na, nb));
  const std::int64_t rows_a = a.complete_rows("/frames"), rows_b = b.complete_rows("/frames");
  const auto ffa = frames_of(a, "/frames/frame", rows_a), ffb = frames_of(b, "/frames/frame", rows_b);
  if (rows_a != rows_b)
    structure.push_back(fmt::format("/frames: {} vs {} frames (A frames {}, B frames {})", rows_a, rows_b,
                                    range_text(ffa), range_text(ffb)));
  else if (const std::string d = frame_set_difference(ffa, ffb); !d.empty())
    structure.push_back("/frames/frame: " + d);
  const bool states_a = a.has_dataset("/states/frame"), states_b = b.has_dataset("/states/frame");
  if (states_a != states_b) {
    structure.push_back(fmt::format("/states: {} vs {}", states_a ? "present" : "absent", states_b ? "present" : "absent"));
  } else if (states_a) {
    const auto srows = [](const TraceReader& t) {
      std::int64_t r = static_cast<std::int64_t>(t.shape("/states/frame").at(0));
      for (const char* d : {"/states/position", "/states/velocity"})
        if (t.has_dataset(d)) r = std::min(r, static_cast<std::int64_t>(t.shape(d).at(0)));
      return r;
    };
    const std::int64_t sra = srows(a), srb = srows(b);
    const auto sfa = frames_of(a, "/states/frame", sra), sfb = frames_of(b, "/states/frame", srb);
    if (sra != srb)
      structure.push_back(fmt::format("/states: {} vs {} state rows (A frames {}, B frames {})", sra, srb,
                                      range_text(sfa), range_text(sfb)));
    else if (const std::string d = frame_set_difference(sfa, sfb); !d.empty())
      structure.push_back("/states/frame: " + d);
  }
  // Scene parameters as the engine resolved them, then the scene file's other keys. The
  // broadphase is engine configuration (every broadphase finds the same pairs); the
  // frame count is judged above from the rows themselves.
  const std::vector<std::string> skip{"/broadphase", "/frames", "/description"};
  std::set<std::string> named;
  for (const auto& d : json_differences(parsed_attribute(a, "parameters"), parsed_attribute(b, "parameters"), skip)) {
    named.insert(d.substr(0, d.find(':')));
    structure.push_back(d + " (parameters)");
  }
  for (const auto& d : json_differences(parsed_attribute(a, "scene"), parsed_attribute(b, "scene"),
                                        std::vector<std::string>{"/broadphase", "/frames", "/description", "/name"}))
  {
    const std::string key = d.substr(0, d.find(':'));
    bool covered = false;  // the resolved parameter under or above this key is named already
    for (const auto& n : named)
      if (n == key || n.rfind(key + "/", 0) == 0 || key.rfind(n + "/", 0) == 0) covered = true;
    if (!covered) structure.push_back(d + " (scene)");
  }

  fmt::print("compare {} ({}, {}, {})\n   with {} ({}, {}, {})\n", o.a, attr(a, "engine"), attr(a, "broadphase"),
             attr(a, "build_id"), o.b, attr(b, "engine"), attr(b, "broadphase"), attr(b, "build_id"));
  fmt::print("scene {}, {} bodies; tolerances:", sa, na);
  for (const auto& q : qs) fmt::print(" {}={}", q, tols.at(q).text());
  fmt::print("\n\n");
  if (!structure.empty()) {
    fmt::print("structure differs ({} key{}):\n", structure.size(), structure.size() == 1 ? "" : "s");
    for (const auto& d : structure) fmt::print("  {}\n", d);
    fmt::print("\n");
  }

  std::vector<QuantityResult> results;
  for (const auto& q : qs) {
    const Tolerance& tol = tols.at(q);
    if (q == "positions" || q == "velocities") {
      const char* d = q == "positions" ? "/states/position" : "/states/velocity";
      QuantityResult r;
      r.name = q;
      r.tol = tol;
      if (!states_a || !states_b || !a.has_dataset(d) || !b.has_dataset(d)) {
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
      QuantityResult r = compare_column<std::uint64_t>(a, b, "contacts", "contacts", tol);
      if (r.available) compare_contact_records(a, b, tol, r);
      results.push_back(r);
    } else if (q == "pairs") {
      results.push_back(compare_column<std::uint64_t>(a, b, "aabb_pairs", "pairs", tol));
    } else {
      results.push_back(compare_column<double>(a, b, "kinetic_energy", "energy", tol));
    }
  }

  fmt::print("{:<11} {:<56} {:>12}  {}\n", "quantity", "compared", "max |A-B|", "largest difference / first beyond tolerance");
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
    fmt::print("{:<11} {:<56} {:>12}  {}\n", r.name, r.compared, r.available ? fmt::format("{:.6g}", r.max_diff) : "n/a",
               !r.available ? "not compared"
               : r.max_frame < 0 ? "-"
                                 : fmt::format("largest at {}: {}", at(r.max_frame, r.max_body), r.max_detail));
    if (r.differs)
      fmt::print("{:<11} {:<56} {:>12}  first beyond {} at {}: {} ({} beyond)\n", "", "", "", r.tol.text(),
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
  if (!structure.empty())
    fmt::print("\nDIFFERENT: structure ({}){}\n", structure.front(),
               first ? fmt::format("; values first at frame {}{} ({})", first->frame,
                                   first->body >= 0 ? fmt::format(", body {}", first->body) : "", first->name)
                     : "");
  else if (first)
    fmt::print("\nDIFFERENT: first at frame {}{} ({})\n", first->frame,
               first->body >= 0 ? fmt::format(", body {}", first->body) : "", first->name);
  else
    fmt::print("\nsame{}\n", any_missing ? " (in what both traces hold)" : "");
  if (!o.json.empty()) {
    json jt = json::object();
    for (const auto& q : qs) jt[q] = {{"abs", tols.at(q).abs}, {"rel", tols.at(q).rel}};
    json j{{"format", "octocd-compare"}, {"version", 2},      {"a", o.a},
           {"b", o.b},                   {"tolerance", jt},   {"scene", sa},
           {"bodies", na},               {"same", !differ},   {"structure", structure},
           {"quantities", jq}};
    if (first) j["first"] = {{"frame", first->frame}, {"body", first->body}, {"quantity", first->name}};
    write_file_atomically(o.json, j.dump(1) + "\n");
  }
  return differ ? 3 : 0;
}

}  // namespace octocd::cli
