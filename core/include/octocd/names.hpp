#pragma once
/// \file names.hpp
/// The names of a table's entries, for the `allowed: ...` lists and name lookups of the
/// registries (engines, validation rows, their causes). Header-only.

#include <string>
#include <vector>

namespace octocd {

/// The `name` member (a std::string) of every element of `items` (a range of entries such
/// as EngineInfo, RowInfo or RowCause), in the range's order.
template <class Items>
std::vector<std::string> names_of(const Items& items) {
  std::vector<std::string> out;
  for (const auto& item : items) out.push_back(item.name);
  return out;
}

/// `names` with `sep` between them, in their order ({"a", "b"} -> "a, b"; none -> ""): an
/// `allowed: ...` list, a command line for a message.
inline std::string join_names(const std::vector<std::string>& names, const char* sep = ", ") {
  std::string out;
  for (const std::string& n : names) out += (out.empty() ? "" : sep) + n;
  return out;
}

}  // namespace octocd
