#pragma once
/// \file scene_detail.hpp
/// What the scene files share inside core/src (scene_parse.cpp, scene_paths.cpp,
/// scene_layout.cpp): the messages' key paths and number rendering, and Ctx, the error
/// reporting and typed readers of one scene. Not a public header.

#include <cmath>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "octocd/error.hpp"
#include "octocd/math.hpp"
#include "octocd/scene.hpp"

namespace octocd::scene_detail {

using json = nlohmann::json;

/// "%.9g" of a number, for messages.
inline std::string num(double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.9g", v);
  return buf;
}

/// Joins a key path and a member name: "" + "dt" = "dt", "response" + "beta" = "response.beta".
inline std::string child(const std::string& key, const std::string& name) {
  return key.empty() ? name : key + "." + name;
}

/// "groups" + 2 = "groups[2]".
inline std::string at(const std::string& key, std::size_t i) { return key + "[" + std::to_string(i) + "]"; }

/// The value's JSON type and a short rendering, for "expected X, got Y" messages.
/// Arrays and objects are described by their size, never serialised: a hostile value
/// can be huge or deeply nested.
inline std::string describe(const json& j) {
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
  std::size_t max_bodies = limits::kMaxBodies;  ///< parse_scene's max_bodies

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

/// The folder of a scene file as an absolute, normalised path, so `mix.json`,
/// `./mix.json` and `/abs/dir/mix.json` name the same folder ("" when `origin` is "").
std::filesystem::path scene_folder(const std::string& origin);

/// The data dir used for `origin` (docs/scenes.md, "Mesh resolution"): `data_dir` when
/// given; else $OCTOCD_DATA_DIR; else the first of default_data_dirs that exists (the
/// first one when none does, so the error names it).
std::string choose_data_dir(const std::string& origin, const std::string& data_dir);

}  // namespace octocd::scene_detail
