#pragma once
/// \file json_strict.hpp
/// JSON from untrusted files (sweeps, expectations, bench results), parsed strictly: what
/// nlohmann::json accepts silently is refused with an InputError naming the file and where.

#include <string>

#include <nlohmann/json.hpp>

namespace octocd {

/// Parses `text` (RFC 8259, no comments) and refuses, with InputError "<origin>: <where>:
/// <problem>; allowed: <values>": invalid JSON (with the byte), a NUL byte anywhere
/// (nlohmann's lexer ends the input there, so "{}\0garbage" parsed), a key twice in one
/// object (the last one silently won), nesting deeper than 64 levels. `origin` names the
/// file in messages.
nlohmann::json parse_json_strict(const std::string& text, const std::string& origin);

}  // namespace octocd
