#pragma once
/// \file adapter_rows.hpp
/// What every reference-engine adapter (reference/<engine>/) does alike when it fills a
/// FrameRecord from its engine's contacts, and when it parses its settings (SettingTable):
/// written once here so the adapters share it instead of copying it.

#include <algorithm>
#include <cstddef>
#include <functional>
#include <string>
#include <vector>

#include "octocd/engine.hpp"
#include "octocd/pyramid_friction.hpp"

namespace octocd {

/// The scalar friction impulse of a contact row (docs/trace-format.md, "The sign of jt"):
/// the tangential impulse on A, `j_t` (N s, world), projected on -v_t / |v_t|, where v_t is
/// the tangential part (orthogonal to the unit `normal`) of A's velocity relative to B's at
/// the point, `v_rel` (m/s); |j_t| when |v_t| <= 1e-6 m/s. >= 0 when friction opposes sliding.
float scalar_jt(const Vec3& j_t, const Vec3& v_rel, const Vec3& normal);

/// scalar_jt of row `c` of record `r`, from the tangential impulse on A `j_a` (N s,
/// world): v_rel is A's velocity relative to B's at c.point before the solver, each body's
/// r.v_pre plus dt `gravity` where its inverse mass `w[i]` (1/kg) is > 0, plus
/// r.w_pre x (c.point - r.x_pre) where the record has angular velocities. `dt` in s.
float row_scalar_jt(const FrameRecord& r, const ContactRecord& c, const Vec3& j_a, const std::vector<float>& w,
                    double dt, const Vec3& gravity);

/// Sets `r.aabbs` to `n` boxes, `box_of(i)` for body i (an Aabb: the engine's own world
/// AABB at the detection pose, m).
template <class BoxOf>
void fill_engine_aabbs(FrameRecord& r, std::size_t n, BoxOf box_of) {
  r.aabbs.resize(n);
  for (std::size_t i = 0; i < n; ++i) r.aabbs[i] = box_of(i);
}

/// Sorts `pairs` by (a, b) and drops repeats (an engine's candidate pairs, as a record holds them).
inline void sort_unique_pairs(std::vector<Pair>& pairs) {
  std::sort(pairs.begin(), pairs.end());
  pairs.erase(std::unique(pairs.begin(), pairs.end()), pairs.end());
}

/// Finishes a manifold record: `rows` (one per engine contact, pair (a, b) with a < b) and
/// their tangential impulse vectors `jt3` (same order, same size) go to `r.contacts` and
/// `r.jt3`, sorted by pair with a stable sort (a pair's rows consecutive, in the engine's
/// order); `r.confirmed` gets the pairs with a row; has_contact_terms false, manifolds and
/// has_points true. `rows` and `jt3` are left empty. `point_b` (same size, or null): each
/// row's point on B where the engine applies B's impulse, sorted alongside into
/// `r.point_b` and left empty; null: `r.point_b` empty (one point per row).
void finish_manifold_record(FrameRecord& r, std::vector<ContactRecord>& rows, std::vector<Vec3>& jt3,
                            std::vector<Vec3>* point_b = nullptr);

/// Applies "KEY=VALUE" items in order by calling `set(key, value)` (which throws InputError
/// for a bad key or value). Throws InputError "<where>: 'ITEM' is not KEY=VALUE; allowed:
/// e.g. <example> (docs/settings.md)" for an item without '='.
void apply_setting_items(const std::vector<std::string>& items, const std::string& where, const std::string& example,
                         const std::function<void(const std::string& key, const std::string& value)>& set);

/// An integer in [lo, hi] from the whole of `value` (a setting's text). Throws InputError
/// "<where>: KEY='VALUE' is not allowed; allowed: <allowed>" otherwise.
int setting_integer(const std::string& key, const std::string& value, long lo, long hi, const std::string& where,
                    const std::string& allowed);

/// A decimal number in [lo, hi] from the whole of `value` (digits, sign, point and exponent
/// only: no hex, inf or nan). Throws InputError "<where>: KEY='VALUE' is not allowed;
/// allowed: <allowed>" otherwise.
double setting_number(const std::string& key, const std::string& value, double lo, double hi,
                      const std::string& where, const std::string& allowed);

/// One engine setting's text as a setter reads it: KEY, VALUE and where it came from (an
/// option such as "--ode", or a Python keyword), with the checked readers a setter uses.
struct SettingValue {
  const std::string& key;    ///< KEY of KEY=VALUE
  const std::string& value;  ///< VALUE of KEY=VALUE
  const std::string& where;  ///< what the messages name first
  /// setting_integer(key, value, lo, hi, where, allowed).
  int integer(long lo, long hi, const std::string& allowed) const {
    return setting_integer(key, value, lo, hi, where, allowed);
  }
  /// setting_number(key, value, lo, hi, where, allowed).
  double number(double lo, double hi, const std::string& allowed) const {
    return setting_number(key, value, lo, hi, where, allowed);
  }
  /// `a` when VALUE is `name_a`, `b` when it is `name_b`; otherwise throws InputError
  /// "<where>: KEY='VALUE' is not allowed; allowed: <allowed>".
  template <class E>
  E choice(const char* name_a, E a, const char* name_b, E b, const std::string& allowed) const {
    if (value == name_a) return a;
    if (value == name_b) return b;
    not_allowed(allowed);
  }
  /// Throws InputError "<where>: KEY='VALUE' is not allowed; allowed: <allowed>".
  [[noreturn]] void not_allowed(const std::string& allowed) const;
};

/// Throws InputError "<where>: unknown <engine> setting 'KEY'; allowed: <names, comma
/// separated> (<doc>)".
[[noreturn]] void throw_unknown_setting(const std::string& engine, const std::string& key,
                                        const std::vector<std::string>& names, const std::string& where,
                                        const std::string& doc);

/// An engine's settings as one table: a row per key with the function that sets the
/// settings struct `S` from its text (throwing InputError for a value out of range). An
/// engine defines its one table as the specialization setting_table<S>() (below), which
/// setting_names<S>() and apply_settings() read; a new key is one row.
template <class S>
struct SettingTable {
  /// Sets the settings struct from one value's text.
  using Setter = std::function<void(S& s, const SettingValue& v)>;
  /// One key and its setter.
  struct Row {
    const char* key;
    Setter set;
  };
  /// A setter of an integer field in [lo, hi] (SettingValue::integer).
  template <class T>
  static Setter integer(T S::*field, long lo, long hi, std::string allowed) {
    return [=](S& s, const SettingValue& v) { s.*field = static_cast<T>(v.integer(lo, hi, allowed)); };
  }
  /// A setter of a decimal field in [lo, hi] (SettingValue::number).
  static Setter number(double S::*field, double lo, double hi, std::string allowed) {
    return [=](S& s, const SettingValue& v) { s.*field = v.number(lo, hi, allowed); };
  }
  /// A setter of a field with two named values (SettingValue::choice).
  template <class E>
  static Setter choice(E S::*field, const char* name_a, E a, const char* name_b, E b, std::string allowed) {
    return [=](S& s, const SettingValue& v) { s.*field = v.choice(name_a, a, name_b, b, allowed); };
  }
  /// A setter of a friction-pyramid bound (pyramid_friction.hpp: the ode and dart engines'
  /// `friction`), values inscribed | pyramid.
  static Setter pyramid_friction(PyramidFriction S::*field) {
    return choice(field, pyramid_friction_name(PyramidFriction::Inscribed), PyramidFriction::Inscribed,
                  pyramid_friction_name(PyramidFriction::Pyramid), PyramidFriction::Pyramid,
                  "inscribed (mu / sqrt 2 per friction direction: inside the Coulomb cone), pyramid (mu per "
                  "direction)");
  }
  const char* engine;   ///< the engine's name, as in messages ("ode")
  const char* doc;      ///< the page that lists the keys ("docs/engines.md")
  const char* example;  ///< an item shown when one is not KEY=VALUE ("stepper=quickstep")
  std::vector<Row> rows;

  /// The keys, in the table's order.
  std::vector<std::string> names() const {
    std::vector<std::string> out;
    for (const Row& r : rows) out.emplace_back(r.key);
    return out;
  }
  /// Sets `key` from `value`; throws InputError for an unknown key or a bad value.
  void set(S& s, const std::string& key, const std::string& value, const std::string& where) const {
    for (const Row& r : rows)
      if (key == r.key) return r.set(s, SettingValue{key, value, where});
    throw_unknown_setting(engine, key, names(), where, doc);
  }
  /// Applies "KEY=VALUE" items in order (apply_setting_items with set()).
  void apply(S& s, const std::vector<std::string>& items, const std::string& where) const {
    apply_setting_items(items, where, example,
                        [&](const std::string& k, const std::string& v) { set(s, k, v, where); });
  }
};

/// The settings table of an engine's settings struct `S` (BulletSettings, MujocoSettings,
/// OdeSettings, DartSettings): the engine's settings header declares the specialization
/// and its `<engine>_settings.cpp` defines it. No primary definition: a struct without a
/// table does not link.
template <class S>
const SettingTable<S>& setting_table();

/// The keys apply_settings takes for `S`, in its table's order (the struct's field order).
template <class S>
std::vector<std::string> setting_names() {
  return setting_table<S>().names();
}

/// Applies "KEY=VALUE" items (the CLI's repeated `--<engine> KEY=VALUE`, Python's keyword
/// dict) to `settings` in order, each through the row of setting_table<S>() for its KEY.
/// Throws InputError "<where>: unknown <engine> setting 'KEY'; allowed: <keys> (<doc>)" for
/// a key the table lacks, "<where>: KEY='VALUE' is not allowed; allowed: <range>" for a
/// value out of the row's range, and "<where>: 'ITEM' is not KEY=VALUE; ..." for an item
/// without '='.
template <class S>
void apply_settings(S& settings, const std::vector<std::string>& items, const std::string& where) {
  setting_table<S>().apply(settings, items, where);
}

}  // namespace octocd
