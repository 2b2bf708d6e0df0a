/// \file json_fields.cpp
/// JsonFields (json_fields.hpp): typed, range-checked reads of untrusted JSON.

#include "octocd/json_fields.hpp"

#include <cmath>
#include <limits>

#include <fmt/format.h>

#include "octocd/error.hpp"

namespace octocd {

namespace {

/// `v` as JSON text for a message, at most 60 bytes.
std::string shown(const nlohmann::json& v) {
  std::string s = v.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace);
  if (s.size() > 60) s = s.substr(0, 57) + "...";
  return s;
}

}  // namespace

std::string json_type_text(const nlohmann::json& v) {
  switch (v.type()) {
    case nlohmann::json::value_t::null: return "null";
    case nlohmann::json::value_t::object: return "an object";
    case nlohmann::json::value_t::array: return "an array";
    case nlohmann::json::value_t::string: return "a string";
    case nlohmann::json::value_t::boolean: return "a boolean";
    case nlohmann::json::value_t::number_integer:
    case nlohmann::json::value_t::number_unsigned: return "an integer";
    case nlohmann::json::value_t::number_float: return "a number";
    default: return "a value";
  }
}

JsonFields::JsonFields(std::string prefix) : prefix_(std::move(prefix)) {}

void JsonFields::fail(const std::string& field, const std::string& problem, const std::string& allowed) const {
  // A NUL of the file (a key, a quoted value) is shown as \x00: what() is a C string, cut
  // at the first NUL.
  std::string text = fmt::format("{}: {}: {}; allowed: {}", prefix_, field, problem, allowed);
  for (std::size_t at = text.find('\0'); at != std::string::npos; at = text.find('\0', at + 4))
    text.replace(at, 1, "\\x00");
  throw InputError(text);
}

const nlohmann::json& JsonFields::member(const nlohmann::json& obj, const std::string& where, const char* key,
                                         const std::string& allowed) const {
  const std::string field = where.empty() ? std::string(key) : where + "." + key;
  if (!obj.is_object()) fail(where.empty() ? "(the document)" : where, json_type_text(obj) + ", not an object", "an object");
  const auto it = obj.find(key);
  if (it == obj.end()) fail(field, "missing", allowed);
  return *it;
}

const nlohmann::json& JsonFields::object(const nlohmann::json& v, const std::string& field) const {
  if (!v.is_object()) fail(field, json_type_text(v) + " " + shown(v), "an object");
  return v;
}

const nlohmann::json& JsonFields::array(const nlohmann::json& v, const std::string& field, std::size_t max_size) const {
  if (!v.is_array()) fail(field, json_type_text(v) + " " + shown(v), "an array");
  if (v.size() > max_size)
    fail(field, fmt::format("an array of {} elements", v.size()), fmt::format("at most {} elements", max_size));
  return v;
}

std::int64_t JsonFields::integer(const nlohmann::json& v, const std::string& field, std::int64_t lo,
                                 std::int64_t hi) const {
  const std::string allowed = fmt::format("an integer in [{}, {}]", lo, hi);
  if (v.is_number_unsigned()) {
    const std::uint64_t u = v.get<std::uint64_t>();
    // nlohmann reads every integer >= 0 as unsigned: both ends are checked here too.
    if (hi < 0 || u > static_cast<std::uint64_t>(hi) || (lo > 0 && u < static_cast<std::uint64_t>(lo)))
      fail(field, fmt::format("{} is out of range", u), allowed);
    return static_cast<std::int64_t>(u);
  }
  if (v.is_number_integer()) {
    const std::int64_t i = v.get<std::int64_t>();
    if (i < lo || i > hi) fail(field, fmt::format("{} is out of range", i), allowed);
    return i;
  }
  // A float: 1e30, 2.5, or an integer too large for 64 bits (nlohmann reads it as a float).
  fail(field, json_type_text(v) + " " + shown(v), allowed);
}

std::uint64_t JsonFields::count(const nlohmann::json& v, const std::string& field, std::uint64_t hi) const {
  const std::string allowed = fmt::format("an integer in [0, {}]", hi);
  if (v.is_number_unsigned()) {
    const std::uint64_t u = v.get<std::uint64_t>();
    if (u > hi) fail(field, fmt::format("{} is out of range", u), allowed);
    return u;
  }
  if (v.is_number_integer()) {
    const std::int64_t i = v.get<std::int64_t>();
    if (i < 0 || static_cast<std::uint64_t>(i) > hi) fail(field, fmt::format("{} is out of range", i), allowed);
    return static_cast<std::uint64_t>(i);
  }
  fail(field, json_type_text(v) + " " + shown(v), allowed);
}

double JsonFields::number_or_null(const nlohmann::json& v, const std::string& field, double lo, double hi) const {
  const std::string allowed = fmt::format("null or a number in [{:g}, {:g}]", lo, hi);
  if (v.is_null()) return std::numeric_limits<double>::quiet_NaN();
  if (!v.is_number()) fail(field, json_type_text(v) + " " + shown(v), allowed);
  const double d = v.get<double>();
  if (!std::isfinite(d) || d < lo || d > hi) fail(field, fmt::format("{:g} is out of range", d), allowed);
  return d;
}

std::string JsonFields::text(const nlohmann::json& v, const std::string& field, std::size_t max_bytes) const {
  if (!v.is_string()) fail(field, json_type_text(v) + " " + shown(v), "a string");
  const std::string& s = v.get_ref<const std::string&>();
  if (s.size() > max_bytes)
    fail(field, fmt::format("a string of {} bytes", s.size()), fmt::format("a string of at most {} bytes", max_bytes));
  return s;
}

std::string JsonFields::one_of(const nlohmann::json& v, const std::string& field,
                               const std::vector<std::string>& allowed) const {
  std::string list;
  for (const std::string& a : allowed) list += (list.empty() ? "" : ", ") + a;
  if (!v.is_string()) fail(field, json_type_text(v) + " " + shown(v), list);
  const std::string& s = v.get_ref<const std::string&>();
  for (const std::string& a : allowed)
    if (s == a) return s;
  fail(field, "'" + (s.size() > 60 ? s.substr(0, 57) + "..." : s) + "'", list);
}

bool JsonFields::boolean(const nlohmann::json& v, const std::string& field) const {
  if (!v.is_boolean()) fail(field, json_type_text(v) + " " + shown(v), "true or false");
  return v.get<bool>();
}

}  // namespace octocd
