// `octocd compare A.h5 B.h5` (SPEC 12): golden-trace regression. For each quantity, the
// largest difference and the first frame and body where the traces differ beyond the
// tolerance (0 = bit for bit). Exit 0 same, 3 different, 2 unreadable or incompatible.
#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <map>
#include <optional>

#include <fmt/format.h>
#include <fmt/ranges.h>

#include "octocd/error.hpp"
#include "octocd/trace_reader.hpp"
#include "tools.hpp"

namespace octocd::cli {

namespace {

/// The result for one quantity.
struct QuantityResult {
  std::string name;
  std::string compared;        ///< what was compared, e.g. "301 states x 55 bodies"
  double max_diff = 0.0;       ///< largest |A - B| (inf when a NaN differs)
  bool differs = false;
  std::int64_t frame = -1;     ///< first frame beyond the tolerance
  std::int64_t body = -1;      ///< first body there (-1 for per-frame quantities)
  std::string detail;          ///< the values there
  bool available = true;       ///< false when a trace lacks the data (then `compared` says why)
};

/// |a - b| for floats; with tolerance 0 two values are equal only with equal bits.
template <class T>
bool beyond(T a, T b, double tol, double& diff) {
  if constexpr (std::is_floating_point_v<T>) {
    const bool same_bits = std::memcmp(&a, &b, sizeof(T)) == 0;
    if (same_bits) {
      diff = 0.0;
      return false;
    }
    if (std::isnan(a) || std::isnan(b)) {
      diff = std::numeric_limits<double>::infinity();
      return true;
    }
    diff = std::fabs(static_cast<double>(a) - static_cast<double>(b));
    return tol == 0.0 ? true : diff > tol;
  } else {
    diff = std::fabs(static_cast<double>(a) - static_cast<double>(b));
    return diff > tol;
  }
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
                              std::int64_t bodies, double tol) {
  QuantityResult q;
  q.name = name;
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
    const auto xa = a.read_f32_rows(dataset, i, 1), xb = b.read_f32_rows(dataset, it->second, 1);
    for (std::int64_t body = 0; body < bodies; ++body) {
      bool hit = false;
      for (int c = 0; c < 3; ++c) {
        const std::size_t k = static_cast<std::size_t>(3 * body + c);
        double d = 0.0;
        if (beyond(xa[k], xb[k], tol, d)) hit = true;
        q.max_diff = std::max(q.max_diff, d);
      }
      if (hit && !q.differs) {
        q.differs = true;
        q.frame = fa[static_cast<std::size_t>(i)];
        q.body = body;
        q.detail = fmt::format("A {} B {}", vec_text(&xa[static_cast<std::size_t>(3 * body)]),
                               vec_text(&xb[static_cast<std::size_t>(3 * body)]));
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
                              const char* name, double tol) {
  QuantityResult q;
  q.name = name;
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
    if (beyond(va[i], vb[it->second], tol, diff) && !q.differs) {
      q.differs = true;
      q.frame = fa[i];
      q.detail = fmt::format("A {} B {}", va[i], vb[it->second]);
    }
    q.max_diff = std::max(q.max_diff, diff);
  }
  q.compared = fmt::format("{} common frames", common);
  return q;
}

/// /contacts records (pairs, then normal, depth, J_n, J_t) at the frames both hold.
void compare_contact_records(const TraceReader& a, const TraceReader& b, double tol, QuantityResult& q) {
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
    while (!r.frame.empty() && r.off.back() > flat) {  // rows whose records are incomplete
      r.frame.pop_back();
      r.off.pop_back();
    }
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
      double diff = 0.0;
      if (pa0 != pb0 || pa1 != pb1) {
        what = fmt::format("contact {}: pair A ({}, {}) B ({}, {})", k, pa0, pa1, pb0, pb1);
        diff = std::numeric_limits<double>::infinity();
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
          if (beyond(*f.second.first, *f.second.second, tol, d) && what.empty())
            what = fmt::format("contact ({}, {}) {}: A {} B {}", pa0, pa1, f.first, *f.second.first, *f.second.second);
          diff = std::max(diff, d);
        }
      }
      q.max_diff = std::max(q.max_diff, diff);
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

}  // namespace

CLI::App* add_compare_command(CLI::App& app, CompareOptions& o) {
  CLI::App* c = app.add_subcommand(
      "compare",
      "Compare two traces (golden-trace regression, CPU vs CUDA): the first frame and body where they differ beyond "
      "the tolerance, and the largest difference per quantity. Exit 0 same, 3 different, 2 unreadable or "
      "incompatible (another scene or body count)");
  c->add_option("a", o.a, "First trace (.h5), e.g. the golden one")->required();
  c->add_option("b", o.b, "Second trace (.h5)")->required();
  c->add_option("--tolerance", o.tolerance,
                "Largest allowed |A - B| in each quantity's unit (m, m/s, counts, J); 0 = bit for bit")
      ->check(CLI::NonNegativeNumber)
      ->default_val(0.0);
  c->add_option("--quantity", o.quantities,
                "Comma-separated: positions, velocities (/states), contacts (/frames/contacts and /contacts when "
                "both have it), pairs (/frames/aabb_pairs), energy (/frames/kinetic_energy)")
      ->default_val("positions,velocities,contacts,pairs");
  c->add_option("--json", o.json, "Also write the table as JSON to this file");
  return c;
}

int compare_command(const CompareOptions& o) {
  const TraceReader a(o.a), b(o.b);
  const std::vector<std::string> qs = split_list(o.quantities);
  static const std::vector<std::string> allowed{"positions", "velocities", "contacts", "pairs", "energy"};
  if (qs.empty()) throw InputError("--quantity: empty; allowed: positions, velocities, contacts, pairs, energy");
  for (const auto& q : qs)
    if (std::find(allowed.begin(), allowed.end(), q) == allowed.end())
      throw InputError(fmt::format("--quantity: unknown quantity '{}'; allowed: positions, velocities, contacts, "
                                   "pairs, energy",
                                   q));
  for (const TraceReader* t : {&a, &b})
    for (const char* d : {"/bodies/shape_id", "/frames/frame"})
      if (!t->has_dataset(d))
        throw InputError(fmt::format("{}: {}: missing; allowed: a complete octocd trace", t->path(), d));
  const std::string sa = a.has_attribute("scene_name") ? a.string_attribute("scene_name") : "?";
  const std::string sb = b.has_attribute("scene_name") ? b.string_attribute("scene_name") : "?";
  if (sa != sb)
    throw InputError(fmt::format("{}: scene_name: '{}', but {} has '{}'; allowed: two traces of the same scene", o.b,
                                 sb, o.a, sa));
  const auto na = static_cast<std::int64_t>(a.shape("/bodies/shape_id").at(0));
  const auto nb = static_cast<std::int64_t>(b.shape("/bodies/shape_id").at(0));
  if (na != nb)
    throw InputError(fmt::format("{}: /bodies: {} bodies, but {} has {}; allowed: two traces of the same bodies", o.b,
                                 nb, o.a, na));
  const bool same_text = !a.has_attribute("scene") || !b.has_attribute("scene") ||
                         a.string_attribute("scene") == b.string_attribute("scene");
  const auto attr = [](const TraceReader& t, const char* n) {
    return t.has_attribute(n) ? t.string_attribute(n) : std::string("?");
  };

  fmt::print("compare {} ({}, {}, {})\n   with {} ({}, {}, {})\n", o.a, attr(a, "engine"), attr(a, "broadphase"),
             attr(a, "build_id"), o.b, attr(b, "engine"), attr(b, "broadphase"), attr(b, "build_id"));
  fmt::print("scene {}, {} bodies; tolerance {}\n", sa, na,
             o.tolerance == 0.0 ? std::string("0 (bit for bit)") : fmt::format("{}", o.tolerance));
  if (!same_text) fmt::print("note: the two traces' scene files differ in text (same name and bodies)\n");
  fmt::print("\n");

  std::vector<QuantityResult> results;
  for (const auto& q : qs) {
    if (q == "positions" || q == "velocities") {
      const bool have = a.has_dataset("/states/frame") && b.has_dataset("/states/frame");
      if (!have) {
        QuantityResult r;
        r.name = q;
        r.available = false;
        r.compared = "/states missing";
        results.push_back(r);
        continue;
      }
      results.push_back(compare_states(a, b, q == "positions" ? "/states/position" : "/states/velocity", q.c_str(),
                                       na, o.tolerance));
    } else if (q == "contacts") {
      QuantityResult r = compare_column<std::uint64_t>(a, b, "contacts", "contacts", o.tolerance);
      if (r.available) compare_contact_records(a, b, o.tolerance, r);
      results.push_back(r);
    } else if (q == "pairs") {
      results.push_back(compare_column<std::uint64_t>(a, b, "aabb_pairs", "pairs", o.tolerance));
    } else {
      results.push_back(compare_column<double>(a, b, "kinetic_energy", "energy", o.tolerance));
    }
  }

  fmt::print("{:<11} {:<58} {:>12}  {}\n", "quantity", "compared", "max |A-B|", "first difference");
  const QuantityResult* first = nullptr;
  bool any_missing = false;
  nlohmann::json jq = nlohmann::json::array();
  for (const auto& r : results) {
    std::string where = "-";
    if (r.differs) {
      where = fmt::format("frame {}", r.frame);
      if (r.body >= 0) where += fmt::format(", body {}", r.body);
      where += ": " + r.detail;
      if (!first || r.frame < first->frame) first = &r;
    }
    if (!r.available) any_missing = true;
    fmt::print("{:<11} {:<58} {:>12}  {}\n", r.name, r.compared, r.available ? fmt::format("{:.6g}", r.max_diff) : "n/a",
               r.available ? where : "not compared");
    jq.push_back({{"quantity", r.name},
                  {"compared", r.compared},
                  {"available", r.available},
                  {"max_abs_difference", std::isfinite(r.max_diff) ? nlohmann::json(r.max_diff) : nlohmann::json("inf")},
                  {"differs", r.differs},
                  {"frame", r.frame},
                  {"body", r.body},
                  {"detail", r.detail}});
  }
  const bool differ = first != nullptr;
  if (differ)
    fmt::print("\nDIFFERENT: first at frame {}{} ({})\n", first->frame,
               first->body >= 0 ? fmt::format(", body {}", first->body) : "", first->name);
  else
    fmt::print("\nsame{}\n", any_missing ? " (in what both traces hold)" : "");
  if (!o.json.empty()) {
    nlohmann::json j{{"format", "octocd-compare"}, {"version", 1},        {"a", o.a},
                     {"b", o.b},                   {"tolerance", o.tolerance}, {"scene", sa},
                     {"bodies", na},               {"same", !differ},     {"quantities", jq}};
    if (differ) j["first"] = {{"frame", first->frame}, {"body", first->body}, {"quantity", first->name}};
    write_file_atomically(o.json, j.dump(1) + "\n");
  }
  return differ ? 3 : 0;
}

}  // namespace octocd::cli
