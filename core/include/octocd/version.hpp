#pragma once
/// \file version.hpp
/// Build identification recorded in traces and printed by `octocd --version`.

#include <string>

namespace octocd {

/// "MAJOR.MINOR.PATCH+GITID" of this build (git describe at configure time).
const char* build_id();

/// A short description of the host CPU ("model name" from /proc/cpuinfo and the number
/// of hardware threads), or "unknown CPU".
std::string cpu_description();

}  // namespace octocd
