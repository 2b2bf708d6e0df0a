/// \file json_strict.cpp
/// parse_json_strict (json_strict.hpp): a parser callback tracks the keys of each open
/// object and the depth.

#include "octocd/json_strict.hpp"

#include <set>
#include <vector>

#include <fmt/format.h>

#include "octocd/error.hpp"

namespace octocd {

nlohmann::json parse_json_strict(const std::string& text, const std::string& origin) {
  using json = nlohmann::json;
  constexpr int kMaxDepth = 64;
  if (const std::size_t nul = text.find('\0'); nul != std::string::npos)
    throw InputError(fmt::format("{}: a NUL byte at byte {}; allowed: a JSON text (RFC 8259, UTF-8) without NUL bytes",
                                 origin, nul));
  std::vector<std::set<std::string>> keys;  // one set per open object (arrays: none)
  std::vector<std::string> where;           // the key path, for messages
  std::vector<bool> is_object;
  const json::parser_callback_t callback = [&](int depth, json::parse_event_t event, json& parsed) {
    switch (event) {
      case json::parse_event_t::object_start:
      case json::parse_event_t::array_start:
        if (depth >= kMaxDepth)
          throw InputError(fmt::format("{}: nesting deeper than {} levels; allowed: at most {}", origin, kMaxDepth,
                                       kMaxDepth));
        is_object.push_back(event == json::parse_event_t::object_start);
        keys.emplace_back();
        where.emplace_back();
        break;
      case json::parse_event_t::key: {
        const std::string k = parsed.get<std::string>();
        if (!keys.empty() && !keys.back().insert(k).second) {
          std::string path;
          for (std::size_t i = 0; i + 1 < where.size(); ++i)
            if (!where[i].empty()) path += where[i] + ".";
          throw InputError(fmt::format("{}: {}{}: duplicate key in one object; allowed: each key at most once per object",
                                       origin, path, k));
        }
        if (!where.empty()) where.back() = k;
        break;
      }
      case json::parse_event_t::object_end:
      case json::parse_event_t::array_end:
        if (!keys.empty()) {
          keys.pop_back();
          where.pop_back();
          is_object.pop_back();
        }
        break;
      case json::parse_event_t::value: break;
    }
    return true;
  };
  try {
    return json::parse(text, callback, true, false);
  } catch (const json::parse_error& e) {
    throw InputError(fmt::format("{}: not JSON (invalid at byte {}: {}); allowed: JSON (RFC 8259, no comments)",
                                 origin, e.byte, e.what()));
  } catch (const json::exception& e) {
    throw InputError(fmt::format("{}: not JSON ({}); allowed: JSON (RFC 8259, no comments)", origin, e.what()));
  }
}

}  // namespace octocd
