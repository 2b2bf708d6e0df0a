// The boxes and small helpers of the GPU broadphase bench (bench_gpu_common.hpp).
#include "bench_gpu_common.hpp"

namespace gpu_bench {

/// The device broadphases behind the seam (the rows of octocd/broadphase_table.def with
/// device `seam`), in the table's order: what `--only` accepts and its default.
std::vector<std::string> seam_names() {
  return octocd::broadphase_names_where(
      [](const octocd::BroadPhaseInfo& b) { return b.device == octocd::BroadPhaseDevice::seam; });
}

double cube_side(std::uint32_t n) { return kDensitySide * std::cbrt(static_cast<double>(n) / 1e4); }

/// n boxes: centres uniform in [-s/2, s/2)^3 (x, y, z drawn in that order), half extent
/// 0.06 for even and 0.03 for odd bodies.
std::vector<Aabb> make_boxes(std::uint32_t n, std::uint64_t seed) {
  octocd::SplitMix64 rng(seed);
  const float h = static_cast<float>(cube_side(n) / 2.0);
  std::vector<Aabb> boxes(n);
  for (std::uint32_t i = 0; i < n; ++i) {
    const float x = rng.uniform(-h, h), y = rng.uniform(-h, h), z = rng.uniform(-h, h);
    const float e = (i % 2 == 0) ? kHalfLarge : kHalfSmall;
    boxes[i] = {{x - e, y - e, z - e}, {x + e, y + e, z + e}};
  }
  return boxes;
}

/// The octrees' domain: the centres' cube grown by the largest half extent.
Aabb domain_for(std::uint32_t n) {
  const float h = static_cast<float>(cube_side(n) / 2.0) + kHalfLarge;
  return {{-h, -h, -h}, {h, h, h}};
}

/// The capacity to grow to when `needed` keys did not fit (cuda_world.cpp's rule).
std::size_t grown(std::size_t needed, std::size_t capacity) {
  return std::max(needed + needed / 4 + 64, 2 * capacity);
}

unsigned long long key_of(std::uint32_t a, std::uint32_t b) {
  return (static_cast<unsigned long long>(a) << 32) | b;
}

double median(std::vector<double> v) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  const std::size_t m = v.size() / 2;
  return v.size() % 2 ? v[m] : 0.5 * (v[m - 1] + v[m]);
}

/// A float as the double of its shortest decimal form (0.24f -> 0.24, for the JSON).
double decimal(float f) { return std::stod(fmt::format("{}", f)); }

double mib(std::uint64_t bytes) { return static_cast<double>(bytes) / (1024.0 * 1024.0); }

/// "10^4", "4x10^6" (one significant digit times a power of ten >= 10^3), or the plain number.
std::string size_label(std::uint64_t n) {
  int e = 0;
  std::uint64_t m = n;
  while (m >= 10 && m % 10 == 0) {
    m /= 10;
    ++e;
  }
  if (e < 3 || m >= 10) return std::to_string(n);
  return m == 1 ? fmt::format("10^{}", e) : fmt::format("{}x10^{}", m, e);
}

/// Parses "10000,1e5,4e6" into positive integers.
std::vector<std::uint32_t> parse_sizes(const std::string& text) {
  std::vector<std::uint32_t> out;
  std::stringstream ss(text);
  std::string item;
  while (std::getline(ss, item, ',')) {
    if (item.empty()) continue;
    std::size_t used = 0;
    double v = 0.0;
    try {
      v = std::stod(item, &used);
    } catch (const std::exception&) {
      used = 0;
    }
    if (used != item.size() || !(v >= 2.0) || v > 2.0e8 || v != std::floor(v))
      throw octocd::InputError(fmt::format("--sizes: '{}' is not a body count in [2, 2e8]", item));
    out.push_back(static_cast<std::uint32_t>(v));
  }
  if (out.empty()) throw octocd::InputError("--sizes: no size given");
  return out;
}

std::vector<std::string> split_names(const std::string& text) {
  std::vector<std::string> out;
  std::stringstream ss(text);
  std::string item;
  while (std::getline(ss, item, ','))
    if (!item.empty()) out.push_back(item);
  return out;
}

std::string utc_now() {
  const std::time_t t = std::time(nullptr);
  char buf[32];
  std::tm tm{};
  gmtime_r(&t, &tm);
  std::strftime(buf, sizeof buf, "%Y-%m-%dT%H:%M:%SZ", &tm);
  return buf;
}

double mean(const std::vector<double>& v) {
  double t = 0.0;
  for (double x : v) t += x;
  return v.empty() ? 0.0 : t / static_cast<double>(v.size());
}

/// A markdown table's header row and its alignment row; per column its title and whether
/// it is right-aligned (numbers).
void table_head(std::ostream& os, std::initializer_list<std::pair<const char*, bool>> columns) {
  std::string titles = "|", rule = "|";
  for (const auto& [title, right] : columns) {
    titles += fmt::format(" {} |", title);
    rule += right ? "---:|" : "---|";
  }
  os << titles << "\n" << rule << "\n";
}

std::string cuda_version_text(int v) { return fmt::format("{}.{}", v / 1000, (v % 1000) / 10); }

std::string machine_line(const Machine& m) {
  return fmt::format("{} (sm_{}{}, {} SMs, {:.1f} GiB), driver {} (CUDA {}), runtime CUDA {}", m.gpu, m.cc_major,
                     m.cc_minor, m.sms, static_cast<double>(m.memory) / (1024.0 * 1024.0 * 1024.0),
                     m.driver.empty() ? "unknown" : m.driver, cuda_version_text(m.driver_cuda),
                     cuda_version_text(m.runtime));
}

}  // namespace gpu_bench
