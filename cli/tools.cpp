// What bench, replay, compare and report share (tools.hpp), and their registration.
#include "tools.hpp"

#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <filesystem>
#include <fstream>

#include <fmt/format.h>

#include "octocd/cuda_world.hpp"
#include "octocd/error.hpp"
#include "octocd/parallel.hpp"
#include "octocd/shared_files.hpp"
#include "octocd/version.hpp"

namespace octocd::cli {

void add_engine_settings_options(CLI::App* command, EngineSettingItems& items, bool brief) {
  for (const EngineInfo& info : engine_infos()) {
    const std::string help = engine_settings_help(info);
    if (help.empty()) continue;
    command->add_option("--" + info.name, items[info.name],
                        brief ? fmt::format("Setting KEY=VALUE of engine {}, repeatable (keys: octocd engines)", info.name)
                              : help);
  }
}

nlohmann::json spread(const std::vector<double>& values) {
  nlohmann::json j;
  j["n"] = values.size();
  if (values.empty()) return j;
  std::vector<double> v = values;
  std::sort(v.begin(), v.end());
  const std::size_t n = v.size();
  const double median = n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
  double mean = 0.0;
  for (double x : v) mean += x;
  mean /= static_cast<double>(n);
  double var = 0.0;
  for (double x : v) var += (x - mean) * (x - mean);
  j["median"] = median;
  j["min"] = v.front();
  j["max"] = v.back();
  j["mean"] = mean;
  j["stdev"] = n > 1 ? std::sqrt(var / static_cast<double>(n - 1)) : 0.0;
  j["values"] = values;
  return j;
}

nlohmann::json load_average() {
  double avg[3] = {-1.0, -1.0, -1.0};
  if (getloadavg(avg, 3) != 3) return nlohmann::json::array();
  return {avg[0], avg[1], avg[2]};
}

nlohmann::json machine_description() {
  nlohmann::json m;
  char host[256] = {0};
  if (gethostname(host, sizeof host - 1) != 0) host[0] = '\0';
  m["hostname"] = host;
  m["cpu"] = cpu_description();
  m["threads"] = static_cast<long>(sysconf(_SC_NPROCESSORS_ONLN));
  m["omp_threads"] = default_threads();  // the CPU engine's threads (octocd/parallel.hpp)
  m["load_average"] = load_average();
  m["gpu"] = cuda_device_status();
  std::string driver;
  std::ifstream in("/proc/driver/nvidia/version");
  if (in) std::getline(in, driver);
  m["driver"] = driver;
  return m;
}

nlohmann::json build_description() {
  nlohmann::json b;
  b["build_id"] = build_id();
  std::string rev;
  const std::string dir = shared_dir();  // a source tree has .git; an installed share/octocd has not
  std::error_code ec;
  if (std::filesystem::exists(std::filesystem::path(dir) / ".git", ec)) {
    const std::string cmd = "git -C '" + dir + "' describe --always --dirty --tags 2>/dev/null";
    if (FILE* p = popen(cmd.c_str(), "r")) {
      char buf[256];
      if (std::fgets(buf, sizeof buf, p)) rev = buf;
      pclose(p);
      while (!rev.empty() && (rev.back() == '\n' || rev.back() == '\r')) rev.pop_back();
    }
  }
  if (rev.empty()) {
    const std::string id = build_id();
    const auto plus = id.find('+');
    rev = plus == std::string::npos ? id : id.substr(plus + 1);
  }
  b["git_revision"] = rev;
  return b;
}

std::vector<std::string> split_list(const std::string& text) {
  std::vector<std::string> out;
  std::string item;
  for (char c : text + ",") {
    if (c == ',') {
      if (!item.empty()) out.push_back(item);
      item.clear();
    } else if (c != ' ') {
      item += c;
    }
  }
  return out;
}

TraceFeed TraceFeed::of(const Engine& engine, bool contacts) {
  TraceFeed f;
  f.v2 = engine.rotation_traits() != nullptr && engine.can_record();
  f.states_only = !f.v2 && !(contacts && engine.can_record());
  return f;
}

void TraceFeed::start(const TraceWriter& trace, Engine& engine, std::int64_t steps) const {
  if (states_only) engine.plan_steps(std::min<std::int64_t>(trace.steps_to_next_state(0), steps));
  else engine.plan_steps(steps);  // a recording engine's promise: state(), contacts(), record() stay allowed
}

void TraceFeed::append(TraceWriter& trace, Engine& engine, const FrameMetrics& m, std::int64_t remaining) const {
  if (v2) {
    trace.append_frame_v2(m, engine.state(), engine.record());
    return;
  }
  const bool due = trace.state_due(m.frame);
  trace.append_frame(m, due ? &engine.state() : nullptr, engine.contacts());
  if (states_only && due) engine.plan_steps(std::min<std::int64_t>(trace.steps_to_next_state(m.frame), remaining));
}

std::string temporary_trace(const std::string& what) {
  std::string name = (std::filesystem::temp_directory_path() / fmt::format("octocd-{}-XXXXXX.h5", what)).string();
  const int fd = ::mkstemps(name.data(), 3);
  if (fd < 0)
    throw RuntimeError(fmt::format("{}: a temporary trace cannot be created ({})", name, std::strerror(errno)));
  ::close(fd);
  return name;
}

std::string utc_time_now() {
  const std::time_t t = std::time(nullptr);
  std::tm tm{};
  gmtime_r(&t, &tm);
  char buf[32];
  std::strftime(buf, sizeof buf, "%Y-%m-%dT%H:%M:%SZ", &tm);
  return buf;
}

void check_output_folder(const std::string& path, const char* option, bool writable) {
  struct stat st {};
  if (::lstat(path.c_str(), &st) != 0) {
    if (errno != ENOENT)
      throw InputError(fmt::format("{} {}: cannot be examined ({}); allowed: a folder octocd may write in", option,
                                   path, std::strerror(errno)));
    return;  // created by the script (its parents must be writable: it says so otherwise)
  }
  if (S_ISLNK(st.st_mode)) {
    std::error_code ec;
    const std::filesystem::path to = std::filesystem::read_symlink(path, ec);
    throw InputError(fmt::format("{} {}: a symbolic link (to {}); allowed: a folder path that is not a link", option,
                                 path, ec ? "?" : to.string()));
  }
  if (!S_ISDIR(st.st_mode))
    throw InputError(fmt::format("{} {}: {}, not a folder; allowed: a folder (created when missing)", option, path,
                                 S_ISFIFO(st.st_mode)                        ? "a FIFO"
                                 : S_ISCHR(st.st_mode) || S_ISBLK(st.st_mode) ? "a device"
                                                                              : "a file"));
  if (writable && ((st.st_mode & 0222) == 0 || ::access(path.c_str(), W_OK) != 0))
    throw InputError(fmt::format("{} {}: a read-only folder; allowed: a folder octocd may write in", option, path));
}

}  // namespace octocd::cli
