// CudaSettings: the range checks and the KEY=VALUE parser the CLI and Python share
// (cuda_settings.hpp). In every build, CUDA or not.
#include "octocd/cuda_settings.hpp"

#include <cerrno>
#include <cstdlib>

#include <fmt/format.h>

#include "octocd/error.hpp"

namespace octocd {

namespace {

constexpr long kMostTimeoutMs = 86400000L;
constexpr long kMostStageTimeEvery = 1000000L;
constexpr long kMostRecordBatch = 64;  // the resident kernel's batch: 1 + kResidentAheadMax steps

bool parse_bool(const std::string& where, const std::string& key, const std::string& value) {
  if (value == "1" || value == "true" || value == "on") return true;
  if (value == "0" || value == "false" || value == "off") return false;
  throw InputError(fmt::format("{}: {}='{}' is not a switch; allowed: true, false, 1, 0, on, off", where, key, value));
}

unsigned long long parse_integer(const std::string& where, const std::string& key, const std::string& value,
                                 unsigned long long lo, unsigned long long hi, const char* what) {
  const char* s = value.c_str();
  char* end = nullptr;
  errno = 0;
  const unsigned long long v = std::strtoull(s, &end, 10);
  if (*s < '0' || *s > '9' || end == s || *end != '\0' || errno != 0 || v < lo || v > hi)
    throw InputError(fmt::format("{}: {}='{}' is not allowed; allowed: an integer {} .. {} ({})", where, key, value,
                                 lo, hi, what));
  return v;
}

}  // namespace

void check_cuda_settings(const CudaSettings& s, const std::string& where) {
  if (s.resident_timeout_ms < 1 || s.resident_timeout_ms > kMostTimeoutMs)
    throw InputError(fmt::format("{}: resident_timeout_ms={} is not allowed; allowed: 1 .. {} (milliseconds)", where,
                                 s.resident_timeout_ms, kMostTimeoutMs));
  if (s.stage_time_every < 1 || s.stage_time_every > kMostStageTimeEvery)
    throw InputError(fmt::format("{}: stage_time_every={} is not allowed; allowed: 1 .. {} (steps per timed step)",
                                 where, s.stage_time_every, kMostStageTimeEvery));
  if (s.record_batch < 1 || s.record_batch > kMostRecordBatch)
    throw InputError(fmt::format("{}: record_batch={} is not allowed; allowed: 1 .. {} (recorded steps per batch)",
                                 where, s.record_batch, kMostRecordBatch));
}

std::vector<std::string> cuda_setting_names() {
  return {"midphase_early_exit", "memory_limit_bytes", "resident_timeout_ms", "stage_times", "stage_time_every",
          "sync_each_launch",    "graph",              "small_path",          "small_profile",
          "record_batch",        "resident_spin"};
}

void set_cuda_setting(CudaSettings& s, const std::string& key, const std::string& value, const std::string& where) {
  if (key == "midphase_early_exit") s.midphase_early_exit = parse_bool(where, key, value);
  else if (key == "memory_limit_bytes")
    s.memory_limit_bytes = parse_integer(where, key, value, 0, ~0ull, "bytes; 0: no limit");
  else if (key == "resident_timeout_ms")
    s.resident_timeout_ms =
        static_cast<long>(parse_integer(where, key, value, 1, kMostTimeoutMs, "milliseconds"));
  else if (key == "sync_each_launch") s.sync_each_launch = parse_bool(where, key, value);
  else if (key == "graph") s.graph = parse_bool(where, key, value);
  else if (key == "stage_times") s.stage_times = parse_bool(where, key, value);
  else if (key == "stage_time_every")
    s.stage_time_every =
        static_cast<long>(parse_integer(where, key, value, 1, kMostStageTimeEvery, "steps per timed step"));
  else if (key == "small_path") s.small_path = parse_bool(where, key, value);
  else if (key == "small_profile") s.small_profile = parse_bool(where, key, value);
  else if (key == "resident_spin") s.resident_spin = parse_bool(where, key, value);
  else if (key == "record_batch")
    s.record_batch = static_cast<long>(parse_integer(where, key, value, 1, kMostRecordBatch, "recorded steps per batch"));
  else {
    std::string names;
    for (const std::string& n : cuda_setting_names()) names += (names.empty() ? "" : ", ") + n;
    throw InputError(fmt::format("{}: unknown cuda setting '{}'; allowed: {} (docs/settings.md)", where, key, names));
  }
}

void apply_cuda_settings(CudaSettings& s, const std::vector<std::string>& items, const std::string& where) {
  for (const std::string& item : items) {
    const std::size_t eq = item.find('=');
    if (eq == std::string::npos)
      throw InputError(fmt::format("{}: '{}' is not KEY=VALUE; allowed: e.g. graph=false (docs/settings.md)", where,
                                   item));
    set_cuda_setting(s, item.substr(0, eq), item.substr(eq + 1), where);
  }
}

}  // namespace octocd
