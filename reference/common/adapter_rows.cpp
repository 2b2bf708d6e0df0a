// What the reference-engine adapters share when they fill a FrameRecord and parse their
// settings (adapter_rows.hpp).
#include "octocd/adapter_rows.hpp"

#include <algorithm>
#include <cmath>
#include <numeric>

#include <fmt/format.h>

#include "octocd/error.hpp"

namespace octocd {

float scalar_jt(const Vec3& j_t, const Vec3& v_rel, const Vec3& normal) {
  const Vec3 v_t = v_rel - dot(v_rel, normal) * normal;
  const float vt_len = length(v_t);
  return vt_len > 1e-6f ? dot(j_t, -(1.0f / vt_len) * v_t) : length(j_t);
}

float row_scalar_jt(const FrameRecord& r, const ContactRecord& c, const Vec3& j_a, const std::vector<float>& w,
                    double dt, const Vec3& gravity) {
  auto point_velocity = [&](std::uint32_t i) {
    Vec3 v = r.v_pre[i];
    if (w[i] > 0.0f) v += static_cast<float>(dt) * gravity;
    return r.w_pre.size() > i ? v + cross(r.w_pre[i], c.point - r.x_pre[i]) : v;
  };
  return scalar_jt(j_a, point_velocity(c.pair.a) - point_velocity(c.pair.b), c.normal);
}

void finish_manifold_record(FrameRecord& r, std::vector<ContactRecord>& rows, std::vector<Vec3>& jt3,
                            std::vector<Vec3>* point_b) {
  std::vector<std::size_t> order(rows.size());
  std::iota(order.begin(), order.end(), std::size_t{0});
  std::stable_sort(order.begin(), order.end(),
                   [&](std::size_t x, std::size_t y) { return rows[x].pair < rows[y].pair; });
  r.contacts.clear();
  r.jt3.clear();
  r.contacts.reserve(order.size());
  r.jt3.reserve(order.size());
  r.point_b.clear();
  for (std::size_t k : order) {
    r.contacts.push_back(rows[k]);
    r.jt3.push_back(jt3[k]);
    if (point_b) r.point_b.push_back((*point_b)[k]);
  }
  rows.clear();
  jt3.clear();
  if (point_b) point_b->clear();
  r.confirmed.clear();
  for (const ContactRecord& c : r.contacts)
    if (r.confirmed.empty() || !(r.confirmed.back() == c.pair)) r.confirmed.push_back(c.pair);
  r.has_contact_terms = false;
  r.manifolds = true;
  r.has_points = true;
}

void apply_setting_items(const std::vector<std::string>& items, const std::string& where, const std::string& example,
                         const std::function<void(const std::string& key, const std::string& value)>& set) {
  for (const std::string& item : items) {
    const std::size_t eq = item.find('=');
    if (eq == std::string::npos)
      throw InputError(
          fmt::format("{}: '{}' is not KEY=VALUE; allowed: e.g. {} (docs/settings.md)", where, item, example));
    set(item.substr(0, eq), item.substr(eq + 1));
  }
}

int setting_integer(const std::string& key, const std::string& value, long lo, long hi, const std::string& where,
                    const std::string& allowed) {
  std::size_t used = 0;
  long n = lo - 1;
  try {
    n = std::stol(value, &used);
  } catch (const std::exception&) {
    used = 0;
  }
  if (value.empty() || used != value.size() || n < lo || n > hi)
    throw InputError(fmt::format("{}: {}='{}' is not allowed; allowed: {}", where, key, value, allowed));
  return static_cast<int>(n);
}

double setting_number(const std::string& key, const std::string& value, double lo, double hi,
                      const std::string& where, const std::string& allowed) {
  std::size_t used = 0;
  double x = std::nan("");
  const bool decimal = !value.empty() && value.find_first_not_of("0123456789+-.eE") == std::string::npos;
  try {
    if (decimal) x = std::stod(value, &used);
  } catch (const std::exception&) {
    used = 0;
  }
  if (!decimal || used != value.size() || !(x >= lo && x <= hi))
    throw InputError(fmt::format("{}: {}='{}' is not allowed; allowed: {}", where, key, value, allowed));
  return x;
}

void SettingValue::not_allowed(const std::string& allowed) const {
  throw InputError(fmt::format("{}: {}='{}' is not allowed; allowed: {}", where, key, value, allowed));
}

void throw_unknown_setting(const std::string& engine, const std::string& key, const std::vector<std::string>& names,
                           const std::string& where, const std::string& doc) {
  std::string list;
  for (const std::string& n : names) list += (list.empty() ? "" : ", ") + n;
  throw InputError(fmt::format("{}: unknown {} setting '{}'; allowed: {} ({})", where, engine, key, list, doc));
}

}  // namespace octocd
