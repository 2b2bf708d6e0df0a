#pragma once
/// \file setting_error.hpp
/// SettingError: bad input in one named setting, as fields for each front end to word.

#include <string>
#include <utility>

#include "octocd/error.hpp"

namespace octocd {

/// Bad input in one named setting (a validator's tolerance, say), as fields: what the
/// setting is (`kind`, e.g. "tolerance"), the name given, the value given as text, whether
/// the name is known, and what is allowed (the names, or the range with its unit). Each
/// front end words it with the place the setting came from: the CLI as "--tolerance: "
/// + describe(), Python as "tolerances['NAME']: " + describe(). what() is describe().
class SettingError : public InputError {
 public:
  SettingError(std::string kind_, std::string name_, std::string value_, bool known_, std::string allowed_)
      : InputError(describe(kind_, name_, value_, known_, allowed_)),
        kind(std::move(kind_)),
        name(std::move(name_)),
        value(std::move(value_)),
        known(known_),
        allowed(std::move(allowed_)) {}
  std::string kind;     ///< what the setting is ("tolerance")
  std::string name;     ///< the name given
  std::string value;    ///< the value given, as text ("" when the name is unknown)
  bool known = false;   ///< the name is a setting of this kind (then the value is what is wrong)
  std::string allowed;  ///< the names (unknown name) or the range and unit (known name)
  /// "unknown KIND 'NAME'; allowed: ALLOWED" or "NAME=VALUE: out of range; allowed: ALLOWED".
  std::string describe() const { return describe(kind, name, value, known, allowed); }

 private:
  static std::string describe(const std::string& kind, const std::string& name, const std::string& value, bool known,
                              const std::string& allowed) {
    return known ? name + "=" + value + ": out of range; allowed: " + allowed
                 : "unknown " + kind + " '" + name + "'; allowed: " + allowed;
  }
};

}  // namespace octocd
