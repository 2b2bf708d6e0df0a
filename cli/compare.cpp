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
#include "compare_quantities.hpp"
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

using namespace compare_detail;

namespace {

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
                "in each frame, each pair's row count (a manifold), then its rows: depth, jn, jt, normal, and point, "
                "point_b, jt3 where both have /contacts/point, /contacts/point_b, /contacts/jt3); pairs (/frames/aabb_pairs) and energy (/frames/kinetic_energy): "
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