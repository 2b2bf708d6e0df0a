// What bench, replay, compare and report share (tools.hpp), and their registration.
#include "tools.hpp"

#include <omp.h>
#include <fcntl.h>
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
#include "octocd/version.hpp"

#ifndef OCTOCD_SOURCE_DIR
#define OCTOCD_SOURCE_DIR "."
#endif

namespace octocd::cli {

void add_cuda_settings_option(CLI::App* command, std::vector<std::string>& items) {
  std::string keys;
  for (const std::string& k : cuda_setting_names()) keys += (keys.empty() ? "" : ", ") + k;
  command->add_option("--cuda", items,
                      "A setting of the cuda engine, KEY=VALUE, repeatable (docs/settings.md); keys: " + keys);
}

CudaSettings cuda_settings_from(const std::vector<std::string>& items) {
  CudaSettings s;
  apply_cuda_settings(s, items, "--cuda");
  check_cuda_settings(s, "--cuda");
  return s;
}

void add_bullet_settings_option(CLI::App* command, std::vector<std::string>& items) {
  std::string keys;
  for (const std::string& k : bullet_setting_names()) keys += (keys.empty() ? "" : ", ") + k;
  command->add_option("--bullet", items,
                      "A setting of the bullet engine, KEY=VALUE, repeatable (docs/settings.md); keys: " + keys +
                          " (shape=hull: convex hulls of dynamic meshes, triangle meshes of static ones, the "
                          "default; shape=box: boxes equal to the AABBs)");
}

BulletSettings bullet_settings_from(const std::vector<std::string>& items) {
  BulletSettings s;
  apply_bullet_settings(s, items, "--bullet");
  return s;
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
  m["omp_threads"] = omp_get_max_threads();  // the CPU engine's midphase team
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
  const std::string dir = source_dir();
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

void write_file_atomically(const std::string& path, const std::string& text) {
  // POSIX calls, so a failure names errno (ENOSPC, EFBIG, ...) and the temporary file is
  // removed whatever fails (before: `bench -o` left o.json.tmp.PID on a full disk).
  const std::string tmp = path + ".tmp." + std::to_string(::getpid());
  const auto reason = [](int e) {
    const char* name = ::strerrorname_np(e);
    return fmt::format("{} ({})", std::strerror(e), name ? name : ("errno " + std::to_string(e)).c_str());
  };
  const int fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd < 0)
    throw RuntimeError(fmt::format("{}: cannot create the temporary file {}: {}; {} is unchanged", path, tmp,
                                   reason(errno), path));
  int err = 0;
  for (std::size_t done = 0; done < text.size() && err == 0;) {
    const ssize_t n = ::write(fd, text.data() + done, text.size() - done);
    if (n < 0 && errno == EINTR) continue;
    if (n < 0) err = errno;
    else done += static_cast<std::size_t>(n);
  }
  if (err == 0 && ::fsync(fd) != 0 && errno != EINVAL) err = errno;
  if (::close(fd) != 0 && err == 0) err = errno;
  if (err == 0 && ::rename(tmp.c_str(), path.c_str()) != 0) err = errno;
  if (err != 0) {
    ::unlink(tmp.c_str());
    throw RuntimeError(fmt::format("{}: writing failed: {}; {} is unchanged (its last complete version, if any) and "
                                   "no temporary file is left",
                                   path, reason(err), path));
  }
}

std::string source_dir() {
  const char* env = std::getenv("OCTOCD_SOURCE_DIR");
  return env && *env ? env : OCTOCD_SOURCE_DIR;
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

std::string utc_time_now() {
  const std::time_t t = std::time(nullptr);
  std::tm tm{};
  gmtime_r(&t, &tm);
  char buf[32];
  std::strftime(buf, sizeof buf, "%Y-%m-%dT%H:%M:%SZ", &tm);
  return buf;
}

// ---- registration ------------------------------------------------------------------------

struct ToolCommands::Impl {
  BenchOptions bench;
  ReplayOptions replay;
  CompareOptions compare;
  ReportOptions report;
  CLI::App* bench_cmd = nullptr;
  CLI::App* replay_cmd = nullptr;
  CLI::App* compare_cmd = nullptr;
  CLI::App* report_cmd = nullptr;
};

ToolCommands::ToolCommands(CLI::App& app) : impl_(std::make_unique<Impl>()) {
  impl_->bench_cmd = add_bench_command(app, impl_->bench);
  impl_->replay_cmd = add_replay_command(app, impl_->replay);
  impl_->compare_cmd = add_compare_command(app, impl_->compare);
  impl_->report_cmd = add_report_command(app, impl_->report);
}

ToolCommands::~ToolCommands() = default;

bool ToolCommands::selected() const {
  for (CLI::App* s : {impl_->bench_cmd, impl_->replay_cmd, impl_->compare_cmd, impl_->report_cmd})
    if (s && s->parsed()) return true;
  return false;
}

int ToolCommands::run() {
  if (impl_->bench_cmd && impl_->bench_cmd->parsed()) return bench_command(impl_->bench);
  if (impl_->replay_cmd && impl_->replay_cmd->parsed()) return replay_command(impl_->replay);
  if (impl_->compare_cmd && impl_->compare_cmd->parsed()) return compare_command(impl_->compare);
  if (impl_->report_cmd && impl_->report_cmd->parsed()) return report_command(impl_->report);
  return 0;
}

}  // namespace octocd::cli
