#pragma once
/// \file adapter_rows.hpp
/// What every reference-engine adapter (reference/<engine>/) does alike when it fills a
/// FrameRecord from its engine's contacts, and when it parses its settings: written once
/// here so the adapters share it instead of copying it.

#include <functional>
#include <string>
#include <vector>

#include "octocd/engine.hpp"

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

/// Finishes a manifold record: `rows` (one per engine contact, pair (a, b) with a < b) and
/// their tangential impulse vectors `jt3` (same order, same size) go to `r.contacts` and
/// `r.jt3`, sorted by pair with a stable sort (a pair's rows consecutive, in the engine's
/// order); `r.confirmed` gets the pairs with a row; has_contact_terms false, manifolds and
/// has_points true. `rows` and `jt3` are left empty.
void finish_manifold_record(FrameRecord& r, std::vector<ContactRecord>& rows, std::vector<Vec3>& jt3);

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

}  // namespace octocd
