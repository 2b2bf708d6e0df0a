/// \file scene.cpp
/// Scene files (SPEC section 3): parsing, validation, mesh resolution and the
/// deterministic body generators. The key list with ranges is in docs/scenes.md.

#include "octocd/scene.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <limits>
#include <set>
#include <sstream>
#include <utility>

#include "octocd/error.hpp"
#include "octocd/mesh.hpp"

namespace octocd {
namespace {

namespace fs = std::filesystem;
using json = nlohmann::json;

constexpr double kInf = std::numeric_limits<double>::infinity();

/// "%.9g" of a number, for messages.
std::string num(double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.9g", v);
  return buf;
}

/// Joins a key path and a member name: "" + "dt" = "dt", "response" + "beta" = "response.beta".
std::string child(const std::string& key, const std::string& name) {
  return key.empty() ? name : key + "." + name;
}

/// "groups" + 2 = "groups[2]".
std::string at(const std::string& key, std::size_t i) { return key + "[" + std::to_string(i) + "]"; }

/// The value's JSON type and a short rendering, for "expected X, got Y" messages.
/// Arrays and objects are described by their size, never serialised: a hostile value
/// can be huge or deeply nested.
std::string describe(const json& j) {
  if (j.is_array() || j.is_object())
    return std::string(j.type_name()) + " of " + std::to_string(j.size()) +
           (j.is_array() ? " elements" : " members");
  std::string text = j.dump();
  if (text.size() > 40) text = text.substr(0, 37) + "...";
  return std::string(j.type_name()) + " " + text;
}

/// Error reporting for one scene: every message is "<origin>: <key>: <problem>; allowed: <range>".
struct Ctx {
  std::string origin;

  [[noreturn]] void fail(const std::string& key, const std::string& problem,
                         const std::string& allowed) const {
    std::string msg = origin + ": ";
    if (!key.empty()) msg += key + ": ";
    msg += problem + "; allowed: " + allowed;
    throw InputError(msg);
  }

  /// Fails on any member of object `j` (at `key`) not in `allowed`.
  void check_keys(const json& j, const std::string& key, const std::vector<std::string>& allowed) const {
    for (auto it = j.begin(); it != j.end(); ++it) {
      if (std::find(allowed.begin(), allowed.end(), it.key()) != allowed.end()) continue;
      std::string list;
      for (const auto& a : allowed) list += (list.empty() ? "" : ", ") + a;
      fail(child(key, it.key()), "unknown key",
           (key.empty() ? std::string("top-level keys ") : "keys of " + key + ": ") + list);
    }
  }

  void expect_object(const json& j, const std::string& key, const std::string& allowed) const {
    if (!j.is_object()) fail(key, "expected an object, got " + describe(j), allowed);
  }

  /// A finite number that stays finite as float32.
  float number(const json& j, const std::string& key, const std::string& allowed) const {
    if (!j.is_number()) fail(key, "expected a number, got " + describe(j), allowed);
    const double v = j.get<double>();
    if (!std::isfinite(v)) fail(key, "number is not finite (" + num(v) + ")", allowed);
    const float f = static_cast<float>(v);
    if (!std::isfinite(f)) fail(key, "number " + num(v) + " overflows float32", allowed);
    return f;
  }

  /// A number in the range given by lo/hi (inclusive or not), checked on the float value.
  float ranged(const json& j, const std::string& key, double lo, bool lo_incl, double hi,
               bool hi_incl, const std::string& allowed) const {
    const float f = number(j, key, allowed);
    const double v = f;
    // Bounds are rounded to float32 too, so a documented bound is itself accepted
    // ("dt": 0.1 is float 0.100000001490116, above the double 0.1).
    const double lo_f = std::isfinite(lo) ? static_cast<double>(static_cast<float>(lo)) : lo;
    const double hi_f = std::isfinite(hi) ? static_cast<double>(static_cast<float>(hi)) : hi;
    const bool ok_lo = lo_incl ? v >= lo_f : v > lo_f;
    const bool ok_hi = hi_incl ? v <= hi_f : v < hi_f;
    if (!ok_lo || !ok_hi) fail(key, "value " + num(v) + " out of range", allowed);
    return f;
  }

  /// An integer in [lo, hi].
  long long integer(const json& j, const std::string& key, long long lo, long long hi,
                    const std::string& allowed) const {
    if (!j.is_number_integer()) fail(key, "expected an integer, got " + describe(j), allowed);
    if (j.is_number_unsigned()) {
      const auto u = j.get<std::uint64_t>();
      if (u > static_cast<std::uint64_t>(hi) || (lo > 0 && u < static_cast<std::uint64_t>(lo)))
        fail(key, "value " + j.dump() + " out of range", allowed);
      return static_cast<long long>(u);
    }
    const auto v = j.get<long long>();
    if (v < lo || v > hi) fail(key, "value " + std::to_string(v) + " out of range", allowed);
    return v;
  }

  /// An unsigned 64-bit integer (seeds).
  std::uint64_t seed(const json& j, const std::string& key) const {
    const std::string allowed = "integer in [0, 18446744073709551615]";
    if (!j.is_number_integer()) fail(key, "expected an integer, got " + describe(j), allowed);
    if (!j.is_number_unsigned()) {
      if (j.get<long long>() < 0) fail(key, "value " + j.dump() + " is negative", allowed);
    }
    return j.get<std::uint64_t>();
  }

  std::string string(const json& j, const std::string& key, const std::string& allowed) const {
    if (!j.is_string()) fail(key, "expected a string, got " + describe(j), allowed);
    return j.get<std::string>();
  }

  /// An array of three finite numbers.
  Vec3 vec3(const json& j, const std::string& key, const std::string& allowed) const {
    if (!j.is_array() || j.size() != 3)
      fail(key, "expected an array of 3 numbers, got " + describe(j), allowed);
    Vec3 v;
    for (int i = 0; i < 3; ++i) v[i] = number(j[static_cast<std::size_t>(i)], at(key, static_cast<std::size_t>(i)), allowed);
    return v;
  }

  /// An array of three coordinates, each within +-limits::kMaxCoordinate (m).
  Vec3 coordinates(const json& j, const std::string& key) const {
    const std::string allowed = "array of 3 finite numbers in [-" + num(limits::kMaxCoordinate) + ", " +
                                num(limits::kMaxCoordinate) + "] (m; float32 loses the slop beyond)";
    const Vec3 v = vec3(j, key, allowed);
    for (int i = 0; i < 3; ++i)
      if (!(std::fabs(static_cast<double>(v[i])) <= limits::kMaxCoordinate))
        fail(at(key, static_cast<std::size_t>(i)), "value " + num(v[i]) + " out of range", allowed);
    return v;
  }

  /// An array of three numbers, each |component| <= bound.
  Vec3 bounded_vec3(const json& j, const std::string& key, double bound, const std::string& unit) const {
    const std::string allowed = "array of 3 finite numbers in [-" + num(bound) + ", " + num(bound) + "] (" + unit + ")";
    const Vec3 v = vec3(j, key, allowed);
    for (int i = 0; i < 3; ++i)
      if (!(std::fabs(static_cast<double>(v[i])) <= bound))
        fail(at(key, static_cast<std::size_t>(i)), "value " + num(v[i]) + " out of range", allowed);
    return v;
  }

  /// `auto` (-> -1) or an integer depth in [0, 10].
  int depth(const json& j, const std::string& key) const {
    const std::string allowed = "integer in [0, 10] or \"auto\"";
    if (j.is_string()) {
      if (j.get<std::string>() == "auto") return -1;
      fail(key, "unknown value " + j.dump(), allowed);
    }
    return static_cast<int>(integer(j, key, 0, 10, allowed));
  }
};

const std::string kVecAllowed = "array of 3 finite numbers";
const std::string kPositive = "finite number > 0";
const std::string kNonNegative = "finite number >= 0";

/// "domain" or a layout's region from its "min"/"max" members (both required here).
/// `strict` (the domain): min < max with every side >= limits::kMinLength; otherwise
/// (a layout region) min <= max. Every coordinate within +-limits::kMaxCoordinate.
Aabb parse_box(const Ctx& c, const json& j, const std::string& key, bool strict) {
  Aabb b;
  b.min = c.coordinates(j.at("min"), child(key, "min"));
  b.max = c.coordinates(j.at("max"), child(key, "max"));
  const char* axes = "xyz";
  const std::string allowed_strict =
      "min < max on every axis, each side >= " + num(limits::kMinLength) + " m";
  for (int i = 0; i < 3; ++i) {
    // 1e-4 relative: the two coordinates were rounded to float32.
    const bool bad = strict ? !(static_cast<double>(b.max[i]) - b.min[i] >= limits::kMinLength * (1 - 1e-4))
                            : !(b.min[i] <= b.max[i]);
    if (bad)
      c.fail(key,
             std::string("min.") + axes[i] + " = " + num(b.min[i]) + (strict ? ", " : " > ") +
                 "max." + axes[i] + " = " + num(b.max[i]),
             strict ? allowed_strict : "min <= max on every axis");
  }
  return b;
}

ShapeSpec parse_shape(const Ctx& c, const json& j, const std::string& key) {
  const std::string allowed_shape =
      "an object with exactly one of {\"mesh\": name|path, \"scale\": >0}, {\"box\": [hx,hy,hz]}, "
      "{\"icosphere\": {\"radius\": >0, \"subdivisions\": 0.." + std::to_string(limits::kMaxIcosphereSubdivisions) + "}}";
  c.expect_object(j, key, allowed_shape);
  c.check_keys(j, key, {"mesh", "scale", "box", "icosphere"});
  const int kinds = int(j.contains("mesh")) + int(j.contains("box")) + int(j.contains("icosphere"));
  if (kinds != 1)
    c.fail(key, "needs exactly one of mesh, box, icosphere (got " + std::to_string(kinds) + ")",
           allowed_shape);
  ShapeSpec s;
  if (j.contains("mesh")) {
    s.kind = ShapeSpec::Kind::Mesh;
    s.mesh = c.string(j["mesh"], child(key, "mesh"), "a dataset name (bunny, armadillo, dragon, asian-dragon) or a mesh file path");
    if (s.mesh.empty()) c.fail(child(key, "mesh"), "empty mesh name", "a dataset name or a mesh file path");
    if (j.contains("scale"))
      s.scale = c.ranged(j["scale"], child(key, "scale"), limits::kMinLength, true, limits::kMaxLength, true,
                         "number in [" + num(limits::kMinLength) + ", " + num(limits::kMaxLength) + "] (m)");
  } else {
    if (j.contains("scale"))
      c.fail(child(key, "scale"), "scale applies only to mesh shapes", "scale together with mesh");
    if (j.contains("box")) {
      s.kind = ShapeSpec::Kind::Box;
      const std::string k = child(key, "box");
      const std::string allowed = "array of 3 half extents, each a number in [" + num(limits::kMinLength / 2) +
                                  ", " + num(limits::kMaxLength / 2) + "] (m)";
      s.half_extents = c.vec3(j["box"], k, allowed);
      for (int i = 0; i < 3; ++i)
        if (!(s.half_extents[i] >= limits::kMinLength / 2 && s.half_extents[i] <= limits::kMaxLength / 2))
          c.fail(at(k, static_cast<std::size_t>(i)), "value " + num(s.half_extents[i]) + " out of range", allowed);
    } else {
      s.kind = ShapeSpec::Kind::Icosphere;
      const std::string k = child(key, "icosphere");
      const std::string most = std::to_string(limits::kMaxIcosphereSubdivisions);
      c.expect_object(j["icosphere"], k, "{\"radius\": >0, \"subdivisions\": 0.." + most + "}");
      const json& ico = j["icosphere"];
      c.check_keys(ico, k, {"radius", "subdivisions"});
      if (ico.contains("radius"))
        s.radius = c.ranged(ico["radius"], child(k, "radius"), limits::kMinLength / 2, true, limits::kMaxLength / 2,
                            true, "number in [" + num(limits::kMinLength / 2) + ", " + num(limits::kMaxLength / 2) + "] (m)");
      if (ico.contains("subdivisions"))
        s.subdivisions = static_cast<int>(c.integer(ico["subdivisions"], child(k, "subdivisions"), 0,
                                                    limits::kMaxIcosphereSubdivisions, "integer in [0, " + most + "]"));
    }
  }
  return s;
}

LayoutSpec parse_layout(const Ctx& c, const json& j, const std::string& key, const Aabb& domain) {
  const std::string allowed_obj = "{\"type\": \"grid\"|\"random\", \"min\", \"max\", \"spacing\", \"jitter\", \"seed\"}";
  c.expect_object(j, key, allowed_obj);
  LayoutSpec l;
  l.region = domain;
  if (!j.contains("type")) c.fail(child(key, "type"), "missing required key", "\"grid\" or \"random\"");
  const std::string type = c.string(j["type"], child(key, "type"), "\"grid\" or \"random\"");
  if (type == "grid") {
    l.kind = LayoutSpec::Kind::Grid;
    c.check_keys(j, key, {"type", "min", "max", "spacing", "jitter", "seed"});
  } else if (type == "random") {
    l.kind = LayoutSpec::Kind::Random;
    c.check_keys(j, key, {"type", "min", "max", "seed"});
  } else {
    c.fail(child(key, "type"), "unknown layout type " + j["type"].dump(), "\"grid\" or \"random\"");
  }
  const bool has_min = j.contains("min");
  const bool has_max = j.contains("max");
  if (has_min != has_max)
    c.fail(child(key, has_min ? "max" : "min"), "missing (min and max go together)",
           "both min and max (arrays of 3 finite numbers, min <= max), or neither (the domain)");
  if (has_min) {
    l.region = parse_box(c, j, key, false);
    l.region_from_domain = false;
  }
  if (j.contains("spacing"))
    l.spacing = c.ranged(j["spacing"], child(key, "spacing"), 0, true, limits::kMaxLength, true,
                         "number in [0, " + num(limits::kMaxLength) + "] (m; 0 = auto)");
  if (j.contains("jitter"))
    l.jitter = c.ranged(j["jitter"], child(key, "jitter"), 0, true, limits::kMaxLength, true,
                        "number in [0, " + num(limits::kMaxLength) + "] (m)");
  if (j.contains("seed")) l.seed = c.seed(j["seed"], child(key, "seed"));
  return l;
}

VelocitySpec parse_velocity(const Ctx& c, const json& j, const std::string& key) {
  const std::string allowed_obj =
      "{\"type\": \"fixed\", \"value\": [x,y,z]} or {\"type\": \"random\", \"max\": >=0, \"seed\": uint}";
  c.expect_object(j, key, allowed_obj);
  VelocitySpec v;
  if (!j.contains("type")) c.fail(child(key, "type"), "missing required key", "\"fixed\" or \"random\"");
  const std::string type = c.string(j["type"], child(key, "type"), "\"fixed\" or \"random\"");
  if (type == "fixed") {
    v.kind = VelocitySpec::Kind::Fixed;
    c.check_keys(j, key, {"type", "value"});
    if (j.contains("value")) v.value = c.bounded_vec3(j["value"], child(key, "value"), limits::kMaxSpeed, "m/s");
  } else if (type == "random") {
    v.kind = VelocitySpec::Kind::Random;
    c.check_keys(j, key, {"type", "max", "seed"});
    const std::string allowed = "number in [0, " + num(limits::kMaxSpeed) + "] (m/s)";
    if (!j.contains("max")) c.fail(child(key, "max"), "missing required key", allowed);
    v.max_speed = c.ranged(j["max"], child(key, "max"), 0, true, limits::kMaxSpeed, true, allowed);
    if (j.contains("seed")) v.seed = c.seed(j["seed"], child(key, "seed"));
  } else {
    c.fail(child(key, "type"), "unknown velocity type " + j["type"].dump(), "\"fixed\" or \"random\"");
  }
  return v;
}

/// A group's `orientation` (SPEC 13): a unit quaternion [w, x, y, z] (|q| within 1e-3 of
/// 1, then normalised), or {"axis": [x, y, z] (non-zero, normalised here), "angle_deg": A
/// in [-360, 360]}.
Quat parse_orientation(const Ctx& c, const json& j, const std::string& key) {
  const std::string allowed =
      "a unit quaternion [w, x, y, z] (| |q| - 1 | <= 1e-3) or {\"axis\": [x, y, z] (non-zero), \"angle_deg\": "
      "number in [-360, 360]}";
  if (j.is_array()) {
    if (j.size() != 4) c.fail(key, "expected 4 numbers [w, x, y, z], got " + describe(j), allowed);
    Quat q;
    float* parts[4] = {&q.w, &q.x, &q.y, &q.z};
    for (std::size_t i = 0; i < 4; ++i) *parts[i] = c.number(j[i], at(key, i), allowed);
    const double n = std::sqrt(double(q.w) * q.w + double(q.x) * q.x + double(q.y) * q.y + double(q.z) * q.z);
    if (!(std::fabs(n - 1.0) <= 1e-3)) c.fail(key, "quaternion norm " + num(n) + " is not 1", allowed);
    return normalized(q);
  }
  if (!j.is_object()) c.fail(key, "expected an array or an object, got " + describe(j), allowed);
  c.check_keys(j, key, {"axis", "angle_deg"});
  for (const char* k : {"axis", "angle_deg"})
    if (!j.contains(k)) c.fail(child(key, k), "missing required key", allowed);
  const Vec3 axis = c.vec3(j["axis"], child(key, "axis"), allowed);
  const double len = std::sqrt(double(axis.x) * axis.x + double(axis.y) * axis.y + double(axis.z) * axis.z);
  if (!(len > 1e-6)) c.fail(child(key, "axis"), "axis has length " + num(len), allowed);
  const float angle = c.ranged(j["angle_deg"], child(key, "angle_deg"), -360, true, 360, true, allowed);
  const double half = 0.5 * static_cast<double>(angle) * 3.14159265358979323846 / 180.0;
  const double s = std::sin(half) / len;
  return normalized(Quat{static_cast<float>(std::cos(half)), static_cast<float>(s * axis.x),
                         static_cast<float>(s * axis.y), static_cast<float>(s * axis.z)});
}

GroupSpec parse_group(const Ctx& c, const json& j, std::size_t index, const Aabb& domain) {
  const std::string key = at("groups", index);
  c.expect_object(j, key, "an object with keys name, shape, count, mass, layout, positions, velocity");
  c.check_keys(j, key, {"name", "shape", "count", "mass", "layout", "positions", "velocity", "orientation",
                        "angular_velocity"});
  GroupSpec g;
  g.index = static_cast<int>(index);
  g.name = "group" + std::to_string(index);
  if (j.contains("name")) {
    g.name = c.string(j["name"], child(key, "name"), "a non-empty string, unique among groups");
    if (g.name.empty()) c.fail(child(key, "name"), "empty name", "a non-empty string, unique among groups");
  }
  if (!j.contains("shape")) c.fail(child(key, "shape"), "missing required key", "a shape object (mesh, box or icosphere)");
  g.shape = parse_shape(c, j["shape"], child(key, "shape"));
  const std::string count_allowed = "integer in [1, " + std::to_string(limits::kMaxBodies) +
                                    "] (bodies in the whole scene at most " + std::to_string(limits::kMaxBodies) + ")";
  if (!j.contains("count")) c.fail(child(key, "count"), "missing required key", count_allowed);
  g.count = static_cast<int>(c.integer(j["count"], child(key, "count"), 1,
                                       static_cast<long long>(limits::kMaxBodies), count_allowed));
  if (j.contains("mass")) {
    const std::string allowed = "0 (static) or a number in [" + num(limits::kMinMass) + ", " +
                                num(limits::kMaxMass) + "] (kg; the inverse mass must be a normal float32)";
    g.mass = c.number(j["mass"], child(key, "mass"), allowed);
    if (!(g.mass == 0.0f || (g.mass >= static_cast<float>(limits::kMinMass) &&
                             g.mass <= static_cast<float>(limits::kMaxMass))))
      c.fail(child(key, "mass"), "value " + num(g.mass) + " out of range", allowed);
  }
  g.layout.region = domain;
  if (j.contains("layout")) g.layout = parse_layout(c, j["layout"], child(key, "layout"), domain);
  if (j.contains("velocity")) g.velocity = parse_velocity(c, j["velocity"], child(key, "velocity"));
  if (j.contains("positions")) {
    const std::string k = child(key, "positions");
    const std::string allowed = "an array of `count` (" + std::to_string(g.count) + ") arrays of 3 finite numbers (m)";
    const json& p = j["positions"];
    if (!p.is_array()) c.fail(k, "expected an array, got " + describe(p), allowed);
    if (p.size() != static_cast<std::size_t>(g.count))
      c.fail(k, "has " + std::to_string(p.size()) + " entries but count is " + std::to_string(g.count), allowed);
    g.positions.reserve(p.size());
    for (std::size_t i = 0; i < p.size(); ++i) g.positions.push_back(c.coordinates(p[i], at(k, i)));
  }
  if (j.contains("orientation")) g.orientation = parse_orientation(c, j["orientation"], child(key, "orientation"));
  if (j.contains("angular_velocity"))
    g.angular_velocity =
        c.bounded_vec3(j["angular_velocity"], child(key, "angular_velocity"), limits::kMaxAngularSpeed, "rad/s, world frame");
  return g;
}

/// A SAX pass over the text before the real parse: it tracks the key path so that
/// syntax errors, numbers that overflow to infinity (1e400: nlohmann reports error 406)
/// and duplicated keys (nlohmann keeps the last silently) are reported with their key.
class PathTracker : public nlohmann::json_sax<json> {
 public:
  std::string error_path;   ///< key path at the first parse error
  std::size_t error_byte = 0;
  std::string error_what;
  bool overflow = false;    ///< the error is a number overflow (406)
  std::string duplicate;    ///< key path of the first duplicated key
  bool too_deep = false;    ///< nesting deeper than limits::kMaxJsonDepth (error_path says where)

  bool null() override { return value(); }
  bool boolean(bool) override { return value(); }
  bool number_integer(number_integer_t) override { return value(); }
  bool number_unsigned(number_unsigned_t) override { return value(); }
  bool number_float(number_float_t, const string_t&) override { return value(); }
  bool string(string_t&) override { return value(); }
  bool binary(binary_t&) override { return value(); }
  bool start_object(std::size_t) override {
    if (frames_.size() >= static_cast<std::size_t>(limits::kMaxJsonDepth)) return too_deep_here();
    frames_.push_back(Frame{false, 0, "", {}});
    return true;
  }
  bool key(string_t& k) override {
    Frame& f = frames_.back();
    f.key = k;
    f.has_key = true;
    if (!f.keys.insert(k).second && duplicate.empty()) duplicate = path();
    return true;
  }
  bool end_object() override {
    frames_.pop_back();
    return value();
  }
  bool start_array(std::size_t) override {
    if (frames_.size() >= static_cast<std::size_t>(limits::kMaxJsonDepth)) return too_deep_here();
    frames_.push_back(Frame{true, 0, "", {}});
    return true;
  }
  bool end_array() override {
    frames_.pop_back();
    return value();
  }
  bool parse_error(std::size_t position, const std::string&, const nlohmann::detail::exception& ex) override {
    error_path = path();
    error_byte = position;
    error_what = ex.what();
    overflow = ex.id == 406;
    return false;
  }

  /// "groups[0].shape.mesh" style path of the current position.
  std::string path() const {
    std::string p;
    for (const Frame& f : frames_) {
      if (f.array) p += "[" + std::to_string(f.index) + "]";
      else if (f.has_key) p += (p.empty() ? "" : ".") + f.key;
    }
    return p;
  }

 private:
  bool too_deep_here() {
    too_deep = true;
    error_path = path();
    return false;  // stops the parse
  }
  struct Frame {
    bool array;
    std::size_t index;
    std::string key;
    std::set<std::string> keys;
    bool has_key = false;
  };
  bool value() {
    if (!frames_.empty() && frames_.back().array) ++frames_.back().index;
    return true;
  }
  std::vector<Frame> frames_;
};

json parse_json(const Ctx& c, const std::string& text) {
  // nlohmann's lexer ends the input at a NUL: a scene followed by "\0garbage" parsed.
  if (const std::size_t nul = text.find('\0'); nul != std::string::npos)
    c.fail("", "a NUL byte at byte " + std::to_string(nul), "a JSON text (RFC 8259, UTF-8) without NUL bytes");
  PathTracker tracker;
  json::sax_parse(text, &tracker, json::input_format_t::json, true, false);
  if (tracker.too_deep)
    c.fail(tracker.error_path, "nesting deeper than " + std::to_string(limits::kMaxJsonDepth) + " arrays/objects",
           "at most " + std::to_string(limits::kMaxJsonDepth) + " levels (a scene needs 5)");
  if (!tracker.error_what.empty()) {
    if (tracker.overflow)
      c.fail(tracker.error_path, "number at byte " + std::to_string(tracker.error_byte) +
                                     " overflows to infinity (" + tracker.error_what + ")",
             "finite numbers");
    c.fail("", "invalid JSON at byte " + std::to_string(tracker.error_byte) +
                   (tracker.error_path.empty() ? std::string() : " (near " + tracker.error_path + ")") + ": " +
                   tracker.error_what,
           "a JSON object (RFC 8259, no comments)");
  }
  if (!tracker.duplicate.empty())
    c.fail(tracker.duplicate, "duplicate key in one object", "each key at most once per object");
  try {
    return json::parse(text, nullptr, true, false);
  } catch (const json::exception& e) {  // unreachable after the SAX pass; kept for safety
    c.fail("", std::string("invalid JSON: ") + e.what(), "a JSON object (RFC 8259, no comments)");
  }
}

/// The folder of a scene file as an absolute, normalised path, so `mix.json`,
/// `./mix.json` and `/abs/dir/mix.json` name the same folder ("" when `origin` is "").
fs::path scene_folder(const std::string& origin) {
  if (origin.empty()) return {};
  std::error_code ec;
  fs::path p = fs::absolute(fs::path(origin), ec);
  if (ec) p = fs::path(origin);
  return p.lexically_normal().parent_path();
}

bool is_directory(const fs::path& p) {
  std::error_code ec;
  return fs::is_directory(p, ec);
}

}  // namespace

std::vector<std::string> default_data_dirs(const std::string& origin) {
  if (const char* env = std::getenv("OCTOCD_DATA_DIR"); env != nullptr && *env != '\0') return {env};
  std::vector<std::string> dirs;
  const fs::path folder = scene_folder(origin);
  if (!folder.empty()) dirs.push_back((folder / ".." / "cache").lexically_normal().string());
#ifdef OCTOCD_SOURCE_DIR
  const std::string built = (fs::path(OCTOCD_SOURCE_DIR) / "datasets" / "cache").lexically_normal().string();
#else
  const std::string built = (fs::current_path() / "datasets" / "cache").lexically_normal().string();
#endif
  if (std::find(dirs.begin(), dirs.end(), built) == dirs.end()) dirs.push_back(built);
  return dirs;
}

namespace {

/// The data dir used for `origin` (docs/scenes.md, "Mesh resolution"): `data_dir` when
/// given; else $OCTOCD_DATA_DIR; else the first of default_data_dirs that exists (the
/// first one when none does, so the error names it).
std::string choose_data_dir(const std::string& origin, const std::string& data_dir) {
  if (!data_dir.empty()) return data_dir;
  const std::vector<std::string> dirs = default_data_dirs(origin);
  for (const std::string& d : dirs)
    if (is_directory(d)) return d;
  return dirs.front();
}

const char* const kDatasetNames[] = {"bunny", "armadillo", "dragon", "asian-dragon"};

/// True when `mesh` is spelled as a file (has a folder or an extension), not a dataset name.
/// "a folder", "a FIFO", ... for a path's type in messages (the trace readers' words).
std::string file_type_text(fs::file_type t) {
  switch (t) {
    case fs::file_type::directory: return "a folder";
    case fs::file_type::fifo: return "a FIFO";
    case fs::file_type::character:
    case fs::file_type::block: return "a device";
    case fs::file_type::socket: return "a socket";
    default: return "not a plain file";
  }
}

bool looks_like_file(const std::string& mesh) {
  const fs::path m(mesh);
  return m.has_parent_path() || m.has_extension();
}

}  // namespace

bool scene_rotates(const Scene& scene) {
  if (scene.rotation) return true;
  for (const GroupSpec& g : scene.groups)
    if (!is_identity(g.orientation) || !(g.angular_velocity == Vec3{0.0f, 0.0f, 0.0f})) return true;
  return false;
}

void require_translation_only(const Scene& scene, const std::string& engine) {
  if (!scene_rotates(scene)) return;
  std::string key = "rotation";
  if (!scene.rotation)
    for (const GroupSpec& g : scene.groups) {
      const std::string gk = at("groups", static_cast<std::size_t>(g.index));
      if (!is_identity(g.orientation)) {
        key = child(gk, "orientation");
        break;
      }
      if (!(g.angular_velocity == Vec3{0.0f, 0.0f, 0.0f})) {
        key = child(gk, "angular_velocity");
        break;
      }
    }
  const Ctx c{scene.path.empty() ? std::string("<scene>") : scene.path};
  c.fail(key,
         "engine " + engine + " translates only (SPEC 3: no orientation, no angular velocity) but the scene " +
             (key == "rotation" ? std::string("has rotation: true") : "sets " + key),
         "rotation false (default), identity orientations and zero angular velocities for engines cpu and cuda; "
         "or use --engine bullet (Bullet with rotation, SPEC 13)");
}

std::size_t body_count(const Scene& scene) {
  std::size_t n = 0;
  for (const auto& g : scene.groups) n += static_cast<std::size_t>(g.count);
  return n;
}

Scene parse_scene(const std::string& text, const std::string& origin, const std::string& data_dir) {
  const Ctx c{origin.empty() ? std::string("<scene>") : origin};
  if (text.size() > limits::kMaxSceneFileBytes)
    c.fail("", "scene text is " + std::to_string(text.size()) + " bytes",
           "a scene of at most " + std::to_string(limits::kMaxSceneFileBytes) + " bytes (64 MiB)");
  const json j = parse_json(c, text);
  if (!j.is_object()) c.fail("", "top level is " + describe(j), "a JSON object");
  c.check_keys(j, "", {"name", "description", "domain", "gravity", "dt", "frames", "walls", "wall_thickness",
                       "response", "theta", "broadphase", "midphase", "groups", "rotation"});
  Scene s;
  s.path = origin;
  s.json = text;
  s.data_dir = choose_data_dir(origin, data_dir);

  if (!j.contains("name")) c.fail("name", "missing required key", "a non-empty string");
  s.name = c.string(j["name"], "name", "a non-empty string");
  if (s.name.empty()) c.fail("name", "empty name", "a non-empty string");
  if (j.contains("description")) s.description = c.string(j["description"], "description", "a string");

  const std::string domain_allowed = "{\"min\": [x,y,z], \"max\": [x,y,z]}, finite, min < max on every axis (m)";
  if (!j.contains("domain")) c.fail("domain", "missing required key", domain_allowed);
  c.expect_object(j["domain"], "domain", domain_allowed);
  c.check_keys(j["domain"], "domain", {"min", "max"});
  for (const char* k : {"min", "max"})
    if (!j["domain"].contains(k)) c.fail(child("domain", k), "missing required key", kVecAllowed);
  s.domain = parse_box(c, j["domain"], "domain", true);

  if (j.contains("gravity")) s.gravity = c.bounded_vec3(j["gravity"], "gravity", limits::kMaxAcceleration, "m/s^2");
  if (j.contains("dt")) s.dt = c.ranged(j["dt"], "dt", 0, false, 0.1, true, "number in (0, 0.1] (s)");
  if (j.contains("frames"))
    s.frames = static_cast<int>(c.integer(j["frames"], "frames", 1, std::numeric_limits<int>::max(), "integer in [1, 2147483647]"));
  if (j.contains("walls")) {
    const std::string allowed = "\"none\", \"floor\", \"open-box\", \"closed-box\"";
    const std::string w = c.string(j["walls"], "walls", allowed);
    if (w == "none") s.walls = Walls::None;
    else if (w == "floor") s.walls = Walls::Floor;
    else if (w == "open-box") s.walls = Walls::OpenBox;
    else if (w == "closed-box") s.walls = Walls::ClosedBox;
    else c.fail("walls", "unknown value " + j["walls"].dump(), allowed);
  }
  if (j.contains("rotation")) {
    if (!j["rotation"].is_boolean())
      c.fail("rotation", "expected true or false, got " + describe(j["rotation"]),
             "true (the bodies rotate: --engine bullet only) or false (default)");
    s.rotation = j["rotation"].get<bool>();
  }
  if (j.contains("wall_thickness"))
    s.wall_thickness = c.ranged(j["wall_thickness"], "wall_thickness", limits::kMinLength, true, limits::kMaxLength, true,
                                "number in [" + num(limits::kMinLength) + ", " + num(limits::kMaxLength) + "] (m)");

  if (j.contains("response")) {
    const json& r = j["response"];
    c.expect_object(r, "response", "an object of Table 1 parameters");
    c.check_keys(r, "response", {"slop", "beta", "alpha", "restitution", "restitution_threshold", "impulse_floor",
                                 "mu_static", "mu_kinetic", "max_velocity", "epsilon", "overlap",
                                 "iterations"});
    struct Param {
      const char* name;
      float ContactParams::*member;
      double lo;
      bool lo_incl;
      double hi;
      bool hi_incl;
      const char* allowed;
    };
    const Param params[] = {
        {"slop", &ContactParams::slop, 0, false, kInf, false, "finite number > 0 (m)"},
        {"beta", &ContactParams::beta, 0, false, 1, true, "number in (0, 1]"},
        {"alpha", &ContactParams::alpha, 0, false, 1, true, "number in (0, 1]"},
        {"restitution", &ContactParams::restitution, 0, true, 1, true, "number in [0, 1]"},
        {"restitution_threshold", &ContactParams::restitution_threshold, 0, true, kInf, false, "finite number >= 0 (m/s)"},
        {"impulse_floor", &ContactParams::impulse_floor, 0, true, kInf, false, "finite number >= 0 (kg m/s)"},
        {"mu_static", &ContactParams::mu_static, 0, true, kInf, false, "finite number >= 0"},
        {"mu_kinetic", &ContactParams::mu_kinetic, 0, true, kInf, false, "finite number >= 0"},
        {"max_velocity", &ContactParams::max_velocity, 0, false, limits::kMaxSpeed, true, "number in (0, 10000] (m/s)"},
        {"epsilon", &ContactParams::epsilon, 0, false, kInf, false, "finite number > 0 (m)"},
    };
    for (const Param& p : params)
      if (r.contains(p.name))
        s.response.*(p.member) = c.ranged(r[p.name], child("response", p.name), p.lo, p.lo_incl, p.hi, p.hi_incl, p.allowed);
    // SPEC 6: the reading of Eq. 9 and the relaxation passes.
    if (r.contains("overlap")) {
      const std::string allowed = "\"separating\" (default) or \"paper\"";
      const std::string o = c.string(r["overlap"], "response.overlap", allowed);
      if (o == "separating") s.response.overlap = OverlapMode::Separating;
      else if (o == "paper") s.response.overlap = OverlapMode::Paper;
      else c.fail("response.overlap", "unknown value " + r["overlap"].dump(), allowed);
    }
    if (r.contains("iterations"))
      s.response.iterations = static_cast<int>(
          c.integer(r["iterations"], "response.iterations", 1, 1000, "integer in [1, 1000]"));
  }

  if (j.contains("theta")) {
    const std::string allowed = "\"auto\" or a number in (0, " + num(limits::kMaxLength) + "] (m)";
    if (j["theta"].is_string()) {
      if (j["theta"].get<std::string>() != "auto") c.fail("theta", "unknown value " + j["theta"].dump(), allowed);
    } else {
      s.theta = c.ranged(j["theta"], "theta", 0, false, limits::kMaxLength, true, allowed);
    }
  }

  if (j.contains("broadphase")) {
    const json& b = j["broadphase"];
    c.expect_object(b, "broadphase", "{\"name\": str, \"depth\": 0..10|\"auto\", \"cell_size\": >0}");
    c.check_keys(b, "broadphase", {"name", "depth", "cell_size"});
    if (b.contains("name")) {
      s.broadphase.name = c.string(b["name"], "broadphase.name", "a broadphase name (flat, octree, spatial-hash, ...)");
      if (s.broadphase.name.empty()) c.fail("broadphase.name", "empty name", "a broadphase name (flat, octree, spatial-hash, ...)");
    }
    if (b.contains("depth")) s.broadphase.octree_depth = c.depth(b["depth"], "broadphase.depth");
    if (b.contains("cell_size"))
      s.broadphase.cell_size = c.ranged(b["cell_size"], "broadphase.cell_size", limits::kMinLength, true, limits::kMaxLength,
                                        true, "number in [" + num(limits::kMinLength) + ", " + num(limits::kMaxLength) + "] (m)");
  }

  if (j.contains("midphase")) {
    const json& m = j["midphase"];
    c.expect_object(m, "midphase", "{\"levels\": \"aabb-only\"|\"1,2\"|[1,2], \"depth\": 0..10|\"auto\"}");
    c.check_keys(m, "midphase", {"levels", "depth"});
    if (m.contains("levels")) {
      const json& lv = m["levels"];
      const std::string allowed = "\"aabb-only\", or strictly ascending levels in [0, 10] as \"1,2\" or [1, 2]";
      std::string text_levels;
      if (lv.is_string()) {
        text_levels = lv.get<std::string>();
      } else if (lv.is_array()) {
        for (std::size_t i = 0; i < lv.size(); ++i) {
          const long long l = c.integer(lv[i], at("midphase.levels", i), 0, 10, allowed);
          text_levels += (i ? "," : "") + std::to_string(l);
        }
      } else {
        c.fail("midphase.levels", "expected a string or an array, got " + describe(lv), allowed);
      }
      try {
        s.midphase = MidphaseConfig::parse(text_levels, "midphase.levels");
      } catch (const InputError& e) {
        throw InputError(c.origin + ": " + e.what());
      }
    }
    if (m.contains("depth")) s.mesh_octree_depth = c.depth(m["depth"], "midphase.depth");
  }
  if (s.mesh_octree_depth >= 0 && !s.midphase.aabb_only && s.mesh_octree_depth < s.midphase.max_level())
    c.fail("midphase.depth",
           std::to_string(s.mesh_octree_depth) + " is shallower than the deepest midphase level " +
               std::to_string(s.midphase.max_level()),
           "\"auto\" or an integer in [" + std::to_string(s.midphase.max_level()) + ", 10]");

  const std::string groups_allowed = "a non-empty array of group objects";
  if (!j.contains("groups")) c.fail("groups", "missing required key", groups_allowed);
  const json& gs = j["groups"];
  if (!gs.is_array()) c.fail("groups", "expected an array, got " + describe(gs), groups_allowed);
  if (gs.empty()) c.fail("groups", "no groups", groups_allowed);
  std::set<std::string> names;
  for (std::size_t i = 0; i < gs.size(); ++i) {
    GroupSpec g = parse_group(c, gs[i], i, s.domain);
    if (!names.insert(g.name).second)
      c.fail(child(at("groups", i), "name"), "duplicate group name \"" + g.name + "\"",
             "names unique among groups (default \"group<i>\")");
    s.groups.push_back(std::move(g));
  }
  if (body_count(s) > limits::kMaxBodies)
    c.fail("groups", "the groups' counts add up to " + std::to_string(body_count(s)) + " bodies",
           "at most " + std::to_string(limits::kMaxBodies) + " bodies in a scene");
  for (auto& g : s.groups)
    if (g.shape.kind == ShapeSpec::Kind::Mesh)
      g.shape.mesh_path = resolve_mesh_path(s, g.shape.mesh, child(at("groups", static_cast<std::size_t>(g.index)), "shape.mesh"));
  return s;
}

Scene load_scene(const std::string& path, const std::string& data_dir) {
  const Ctx c{path};
  std::error_code ec;
  if (!fs::exists(path, ec)) c.fail("", "scene file not found", "a readable JSON scene file");
  if (!fs::is_regular_file(path, ec)) c.fail("", "not a regular file", "a readable JSON scene file");
  const std::uintmax_t bytes = fs::file_size(path, ec);
  if (!ec && bytes > limits::kMaxSceneFileBytes)
    c.fail("", "scene file is " + std::to_string(bytes) + " bytes",
           "a scene file of at most " + std::to_string(limits::kMaxSceneFileBytes) + " bytes (64 MiB)");
  std::ifstream in(path, std::ios::binary);
  if (!in) c.fail("", "cannot open the scene file", "a readable JSON scene file");
  std::ostringstream ss;
  ss << in.rdbuf();
  if (in.bad()) c.fail("", "error reading the scene file", "a readable JSON scene file");
  return parse_scene(ss.str(), path, data_dir);
}

std::string resolve_mesh_path(const Scene& scene, const std::string& mesh, const std::string& key) {
  const Ctx c{scene.path.empty() ? std::string("<scene>") : scene.path};
  const bool file_like = looks_like_file(mesh);
  std::vector<fs::path> searched;
  const fs::path m(mesh);
  searched.push_back(m.is_absolute() ? m : scene_folder(scene.path) / m);
  // A dataset name is looked up in the data dir; a file path (with a folder or an
  // extension) is not: "meshes/bunny.obj" must not become ".../bunny.obj.obj".
  if (!scene.data_dir.empty() && !file_like)
    for (const char* ext : {".obj", ".off", ".ply"}) searched.push_back(fs::path(scene.data_dir) / (mesh + ext));
  // stat only, never open here: opening a FIFO blocks, a device never ends. The first
  // regular file wins; when there is none, a place that exists as something else (a
  // folder, FIFO, device, socket) is named with its type rather than "not found".
  for (const auto& p : searched) {
    std::error_code ec;
    if (!fs::is_regular_file(p, ec)) continue;
    const auto size = fs::file_size(p, ec);
    if (ec || size == 0)
      c.fail(key, "mesh file " + p.string() + " is empty (0 bytes)",
             "a non-empty mesh file (for datasets, run datasets/fetch.sh again)");
    return p.string();
  }
  for (const auto& p : searched) {
    std::error_code ec;
    const fs::file_status st = fs::status(p, ec);
    if (st.type() == fs::file_type::not_found) continue;
    if (st.type() == fs::file_type::none || ec)
      c.fail(key, "mesh path " + p.string() + " cannot be examined: " + ec.message(),
             "a readable regular mesh file");
    c.fail(key, "mesh path " + p.string() + ": not a regular file (" + file_type_text(st.type()) + ")",
           "a regular mesh file (.obj, .off, .ply, .stl), absolute or relative to the scene file's folder; or "
           "a dataset name (bunny, armadillo, dragon, asian-dragon)");
  }
  std::string list;
  for (const auto& p : searched) list += (list.empty() ? "" : ", ") + p.string();
  if (file_like)
    c.fail(key, "mesh file \"" + mesh + "\" not found (searched: " + list + ")",
           "an existing mesh file, absolute or relative to the scene file's folder; or a dataset "
           "name without extension (bunny, armadillo, dragon, asian-dragon)");
  const bool dataset = std::find(std::begin(kDatasetNames), std::end(kDatasetNames), mesh) != std::end(kDatasetNames);
  std::string advice;
  if (!is_directory(scene.data_dir))
    advice = "the data dir " + scene.data_dir + " does not exist: run datasets/fetch.sh, or give " +
             "--data-dir / $OCTOCD_DATA_DIR";
  else if (dataset)
    advice = "the data dir " + scene.data_dir + " lacks it: run datasets/fetch.sh, or give --data-dir / " +
             "$OCTOCD_DATA_DIR";
  else
    advice = "not a shipped dataset (bunny, armadillo, dragon, asian-dragon) and no such file";
  c.fail(key, "mesh \"" + mesh + "\" not found (searched: " + list + "); " + advice,
         "an existing mesh file (absolute or relative to the scene's folder), or a dataset name with "
         "NAME.obj|.off|.ply in the data dir (--data-dir, $OCTOCD_DATA_DIR, else <scene folder>/../cache, "
         "else the datasets/cache of the source tree octocd was built from)");
}

std::vector<Vec3> group_positions(const GroupSpec& g, const Aabb& body_local_aabb, const std::string& origin,
                                  const std::vector<Aabb>& placed_before) {
  if (!g.positions.empty()) return g.positions;
  const Ctx c{origin.empty() ? std::string("<scene>") : origin};
  const std::string key = child(at("groups", static_cast<std::size_t>(g.index)), "layout");
  const Vec3 size = body_local_aabb.max - body_local_aabb.min;
  const std::size_t count = static_cast<std::size_t>(std::max(g.count, 0));

  Aabb region = g.layout.region;
  if (g.layout.region_from_domain) {
    for (int a = 0; a < 3; ++a) {
      const float lo = region.min[a] + 0.5f * size[a];
      const float hi = region.max[a] - 0.5f * size[a];
      if (lo <= hi) {
        region.min[a] = lo;
        region.max[a] = hi;
      } else {
        region.min[a] = region.max[a] = 0.5f * (region.min[a] + region.max[a]);
      }
    }
  }

  std::vector<Vec3> out;
  SplitMix64 rng(g.layout.seed);
  if (g.layout.kind == LayoutSpec::Kind::Grid) {
    const float largest = std::max(size.x, std::max(size.y, size.z));
    const float s = g.layout.spacing > 0.0f ? g.layout.spacing : 1.1f * largest;
    if (!(s > 0.0f) || !std::isfinite(s))
      c.fail(key, "grid spacing is 0 (auto) and the body has zero size", "layout.spacing > 0");
    double n[3];
    for (int a = 0; a < 3; ++a) {
      const double extent = static_cast<double>(region.max[a]) - static_cast<double>(region.min[a]);
      n[a] = std::min(std::floor(extent / static_cast<double>(s) + 1e-4) + 1.0, 1e9);
    }
    const double capacity = n[0] * n[1] * n[2];
    if (static_cast<double>(count) > capacity)
      c.fail(key,
             "the region holds only " + num(capacity) + " bodies (" + num(n[0]) + " x " + num(n[1]) + " x " +
                 num(n[2]) + " in x, y, z at spacing " + num(s) + " m) but count is " + std::to_string(count),
             "a region holding count bodies: enlarge layout.min/max or reduce layout.spacing");
    out.reserve(count);  // after the capacity check: a hostile count fails above, not here
    const auto nx = static_cast<std::size_t>(n[0]);
    const auto nz = static_cast<std::size_t>(n[2]);
    const float j = g.layout.jitter;
    for (std::size_t k = 0; k < count; ++k) {
      const std::size_t idx[3] = {k % nx, k / (nx * nz), (k / nx) % nz};
      Vec3 p;
      for (int a = 0; a < 3; ++a)
        p[a] = static_cast<float>(static_cast<double>(region.min[a]) +
                                  static_cast<double>(idx[a]) * static_cast<double>(s));
      if (j > 0.0f)
        for (int a = 0; a < 3; ++a) p[a] += rng.uniform(-j, j);
      out.push_back(p);
    }
    return out;
  }

  // Random: rejection sampling against the bodies already placed (this group's and
  // `placed_before`). The placed boxes are binned by centre in a uniform grid of cells
  // wider than the largest of them (plus rounding): two overlapping boxes then have
  // centres less than one cell apart per axis, so a drawn box can only overlap boxes
  // binned in its own and the 26 neighbouring cells: the same draws and the same result
  // as testing every placed box, in O(count) instead of O(count^2) (10^6 bodies would
  // otherwise take hours).
  constexpr int kTries = 1000;
  out.reserve(std::min<std::size_t>(count, std::size_t{1} << 24));
  std::vector<Aabb> placed;
  placed.reserve(std::min<std::size_t>(count + placed_before.size(), std::size_t{1} << 24));
  float largest = std::max(size.x, std::max(size.y, size.z));
  for (const Aabb& b : placed_before)
    for (int a = 0; a < 3; ++a) largest = std::max(largest, b.max[a] - b.min[a]);
  // Bins: a dense grid over the region plus one cell of margin on every side, each cell
  // the head of a chain of placed boxes (next index per box). A box is binned by its
  // centre, clamped into the grid: a box of an earlier group centred beyond the margin is
  // more than one cell from every drawn centre, so it cannot overlap a drawn box and its
  // clamped cell only adds a candidate. Cells are at least 1.01 x the largest box (plus
  // rounding), widened until the grid has at most 2^24 cells (a wider cell only adds
  // candidates, never loses one).
  double cell = 1.01 * static_cast<double>(largest) + 1e-3;
  std::int64_t dims[3];
  for (;;) {
    double cells = 1.0;
    for (int a = 0; a < 3; ++a) {
      const double extent = static_cast<double>(region.max[a]) - static_cast<double>(region.min[a]);
      dims[a] = static_cast<std::int64_t>(std::floor(extent / cell)) + 3;
      cells *= static_cast<double>(dims[a]);
    }
    if (cells <= static_cast<double>(1 << 24)) break;
    cell *= 1.25;
  }
  constexpr std::uint32_t kNone = 0xffffffffu;
  std::vector<std::uint32_t> head(static_cast<std::size_t>(dims[0] * dims[1] * dims[2]), kNone);
  std::vector<std::uint32_t> next;
  next.reserve(placed.capacity());
  auto cell_of = [&](double coord, int a) {
    const double grid_min = static_cast<double>(region.min[a]) - cell;
    const double k = std::floor((coord - grid_min) / cell);
    return static_cast<std::int64_t>(std::min(std::max(k, 0.0), static_cast<double>(dims[a] - 1)));
  };
  auto cell_index = [&](std::int64_t x, std::int64_t y, std::int64_t z) {
    return static_cast<std::size_t>(x + dims[0] * (y + dims[1] * z));
  };
  auto centre_cell = [&](const Aabb& b) {
    std::int64_t ci[3];
    for (int a = 0; a < 3; ++a) ci[a] = cell_of(0.5 * (static_cast<double>(b.min[a]) + b.max[a]), a);
    return cell_index(ci[0], ci[1], ci[2]);
  };
  auto insert = [&](const Aabb& b) {
    const auto id = static_cast<std::uint32_t>(placed.size());
    placed.push_back(b);
    std::uint32_t& h = head[centre_cell(b)];
    next.push_back(h);
    h = id;
  };
  for (const Aabb& b : placed_before) insert(b);
  for (std::size_t k = 0; k < count; ++k) {
    bool ok = false;
    for (int t = 0; t < kTries && !ok; ++t) {
      Vec3 p;
      for (int a = 0; a < 3; ++a) p[a] = rng.uniform(region.min[a], region.max[a]);
      const Aabb box = translated(body_local_aabb, p);
      std::int64_t cc[3];
      // A drawn centre lies in the region, so its cell is in [1, dims - 2]; clamped there
      // against rounding: a region with min == max on an axis put it in cell 0, and the
      // -1 neighbour below read outside `head` (issue 22).
      for (int a = 0; a < 3; ++a) cc[a] = std::clamp<std::int64_t>(cell_of(static_cast<double>(p[a]), a), 1, dims[a] - 2);
      ok = true;
      for (std::int64_t dx = -1; dx <= 1 && ok; ++dx)
        for (std::int64_t dy = -1; dy <= 1 && ok; ++dy)
          for (std::int64_t dz = -1; dz <= 1 && ok; ++dz) {
            // A drawn centre lies in the region: its cell is >= 1 and <= dims - 2.
            for (std::uint32_t b = head[cell_index(cc[0] + dx, cc[1] + dy, cc[2] + dz)]; b != kNone; b = next[b])
              if (overlaps(box, placed[b])) {
                ok = false;
                break;
              }
          }
      if (ok) {
        insert(box);
        out.push_back(p);
      }
    }
    if (!ok)
      c.fail(key,
             "region too small: placed " + std::to_string(k) + " of " + std::to_string(count) +
                 " bodies without overlap, then " + std::to_string(kTries) + " tries failed for body " +
                 std::to_string(k),
             "a region where count bodies fit apart: enlarge layout.min/max, reduce count, or use a grid");
  }
  return out;
}

std::vector<Vec3> group_velocities(const GroupSpec& g) {
  const std::size_t count = static_cast<std::size_t>(std::max(g.count, 0));
  if (g.velocity.kind == VelocitySpec::Kind::Fixed) return std::vector<Vec3>(count, g.velocity.value);
  std::vector<Vec3> out;
  out.reserve(count);
  SplitMix64 rng(g.velocity.seed);
  const float m = g.velocity.max_speed;
  for (std::size_t k = 0; k < count; ++k) {
    Vec3 v;
    for (int a = 0; a < 3; ++a) v[a] = rng.uniform(-m, m);
    out.push_back(v);
  }
  return out;
}

}  // namespace octocd
