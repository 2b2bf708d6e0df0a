#pragma once
/// \file json_fields.hpp
/// Typed reads of a JSON document that came from an untrusted file (a shard's verdict, a
/// bench result to resume): every value checked for its type and range before it is
/// converted, so a wrong type is never a library exception (exit 1) and a large integer
/// never wraps. Errors are InputError (exit 2) "<prefix>: <field>: <problem>; allowed:
/// <values>", naming the file (in the prefix) and the field (docs/robustness.md, "JSON").

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

namespace octocd {

/// The type of a JSON value with its article for messages: "a string", "an integer", "null".
std::string json_type_text(const nlohmann::json& v);

/// The checks; `prefix` starts every error (e.g. "--merge: s0.json"). Field names are the
/// caller's paths ("shard.count", "rows[3].causes[0].count").
class JsonFields {
 public:
  /// `prefix`: the option and the file; it is written printable (octocd/text.hpp).
  explicit JsonFields(std::string prefix);

  /// Throws InputError "<prefix>: <field>: <problem>; allowed: <allowed>", each NUL in it
  /// written \x00 (what() would end at it).
  [[noreturn]] void fail(const std::string& field, const std::string& problem, const std::string& allowed) const;

  /// `obj[key]` of an object `obj` (field `where`); missing: InputError naming
  /// "<where>.<key>" and `allowed`.
  const nlohmann::json& member(const nlohmann::json& obj, const std::string& where, const char* key,
                               const std::string& allowed) const;
  /// `v` when it is an object, else InputError.
  const nlohmann::json& object(const nlohmann::json& v, const std::string& field) const;
  /// `v` when it is an array of at most `max_size` elements, else InputError.
  const nlohmann::json& array(const nlohmann::json& v, const std::string& field, std::size_t max_size) const;
  /// An integer in [lo, hi] (a JSON integer, signed or unsigned, never a float), else
  /// InputError naming the range.
  std::int64_t integer(const nlohmann::json& v, const std::string& field, std::int64_t lo, std::int64_t hi) const;
  /// An unsigned integer in [0, hi], else InputError.
  std::uint64_t count(const nlohmann::json& v, const std::string& field, std::uint64_t hi) const;
  /// A number in [lo, hi] (finite), or NaN for null (as octocd writes non-finite figures);
  /// else InputError.
  double number_or_null(const nlohmann::json& v, const std::string& field, double lo, double hi) const;
  /// A string of at most `max_bytes` bytes, else InputError.
  std::string text(const nlohmann::json& v, const std::string& field, std::size_t max_bytes) const;
  /// A string among `allowed`, else InputError listing them.
  std::string one_of(const nlohmann::json& v, const std::string& field, const std::vector<std::string>& allowed) const;
  /// true or false, else InputError.
  bool boolean(const nlohmann::json& v, const std::string& field) const;

 private:
  std::string prefix_;
};

}  // namespace octocd
