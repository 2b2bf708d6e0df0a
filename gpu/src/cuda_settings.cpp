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

namespace {

/// One cuda setting of `--cuda KEY=VALUE`: a switch (`flag`) or an integer in lo .. hi (`unit`
/// names it in the refusal) stored by `set`.
struct CudaSettingRow {
  const char* key;
  bool CudaSettings::*flag;
  void (*set)(CudaSettings&, unsigned long long);
  unsigned long long lo, hi;
  const char* unit;
};

/// Every cuda setting, in the order `--help` and the refusals list them.
const CudaSettingRow kCudaSettingRows[] = {
    {"midphase_early_exit", &CudaSettings::midphase_early_exit, nullptr, 0, 0, nullptr},
    {"memory_limit_bytes", nullptr, [](CudaSettings& s, unsigned long long v) { s.memory_limit_bytes = v; }, 0,
     ~0ull, "bytes; 0: no limit"},
    {"resident_timeout_ms", nullptr,
     [](CudaSettings& s, unsigned long long v) { s.resident_timeout_ms = static_cast<long>(v); }, 1,
     static_cast<unsigned long long>(kMostTimeoutMs), "milliseconds"},
    {"stage_times", &CudaSettings::stage_times, nullptr, 0, 0, nullptr},
    {"stage_time_every", nullptr,
     [](CudaSettings& s, unsigned long long v) { s.stage_time_every = static_cast<long>(v); }, 1,
     static_cast<unsigned long long>(kMostStageTimeEvery), "steps per timed step"},
    {"sync_each_launch", &CudaSettings::sync_each_launch, nullptr, 0, 0, nullptr},
    {"graph", &CudaSettings::graph, nullptr, 0, 0, nullptr},
    {"small_path", &CudaSettings::small_path, nullptr, 0, 0, nullptr},
    {"small_profile", &CudaSettings::small_profile, nullptr, 0, 0, nullptr},
    {"record_batch", nullptr, [](CudaSettings& s, unsigned long long v) { s.record_batch = static_cast<long>(v); },
     1, static_cast<unsigned long long>(kMostRecordBatch), "recorded steps per batch"},
};

}  // namespace

std::vector<std::string> cuda_setting_names() {
  std::vector<std::string> names;
  for (const CudaSettingRow& row : kCudaSettingRows) names.emplace_back(row.key);
  return names;
}

void set_cuda_setting(CudaSettings& s, const std::string& key, const std::string& value, const std::string& where) {
  for (const CudaSettingRow& row : kCudaSettingRows) {
    if (key != row.key) continue;
    if (row.flag) s.*row.flag = parse_bool(where, key, value);
    else row.set(s, parse_integer(where, key, value, row.lo, row.hi, row.unit));
    return;
  }
  std::string names;
  for (const std::string& n : cuda_setting_names()) names += (names.empty() ? "" : ", ") + n;
  throw InputError(fmt::format("{}: unknown cuda setting '{}'; allowed: {} (docs/settings.md)", where, key, names));
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
