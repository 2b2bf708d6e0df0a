#pragma once
// What `octocd compare` (compare.cpp) compares quantity by quantity: each trace's side (what it
// holds, read through the hardened reader) and the comparison of states, /frames columns and
// contacts at the frames both traces hold (compare_quantities.cpp). Internal to cli/.
#include <cstdint>
#include <functional>
#include <string>
#include <utility>
#include <vector>

#include <fmt/format.h>

#include "octocd/trace_reader.hpp"
#include "tools.hpp"

namespace octocd::cli::compare_detail {

/// The result for one quantity.
struct QuantityResult {
  std::string name;
  Tolerance tol;
  std::string compared;        ///< what was compared, e.g. "301 states x 55 bodies"
  double max_diff = 0.0;       ///< largest |A - B| (inf when a NaN differs)
  std::int64_t max_frame = -1, max_body = -1;  ///< where the largest difference is
  std::string max_detail;      ///< both values there
  bool differs = false;
  std::int64_t frame = -1;     ///< first frame beyond the tolerance
  std::int64_t body = -1;      ///< first body there (-1 for per-frame quantities)
  std::string detail;          ///< the values there
  std::int64_t beyond_count = 0;  ///< values beyond the tolerance
  double first_size = 0.0;     ///< |A - B| at the first difference (inf: a NaN, a pair or row on one side only)
  bool available = true;       ///< false when a trace lacks the data (then `compared` says why)

  /// Records a difference `d` at (frame, body) with the values' text, if it is the largest.
  std::vector<double> max_a, max_b;  ///< both values there (a vector's components; empty for contact pairs)
  void largest(double d, std::int64_t f, std::int64_t b, const std::function<std::string()>& values,
               std::vector<double> va = {}, std::vector<double> vb = {}) {
    if (d > max_diff || (max_frame < 0 && d > 0.0)) {
      max_diff = d;
      max_frame = f;
      max_body = b;
      max_detail = values();
      max_a = std::move(va);
      max_b = std::move(vb);
    }
  }
};

/// One trace of the comparison: octocd's own (it has /frames: docs/trace-format.md, format
/// version 1, or 2 for a rotating engine) or an external trace (no /frames: "External
/// traces", versions 1 and 2; checked in full by check_external_trace before anything is
/// compared, so every bad value is an InputError naming dataset, frame and allowed values).
struct Side {
  const TraceReader* t = nullptr;
  bool external = false;                   ///< no /frames: an external trace
  int version = 1;                         ///< root attribute `version`
  std::string engine;                      ///< root attribute `engine`
  std::int64_t bodies = 0;
  std::string scene_name = "?";            ///< root attribute scene_name (external: the scene's name)
  bool scene_known = true;                 ///< false: an external trace that names no scene
  std::int64_t frame_rows = 0;             ///< steps recorded (rows of /frames; external: F)
  std::vector<std::int64_t> frames;        ///< their frames, as written
  bool has_states = false;                 ///< octocd: /states/frame; external: /states/position
  std::int64_t state_rows = 0;             ///< state rows (structure)
  std::vector<std::int64_t> state_frames;  ///< their frames, as written
  bool rotation = false;                   ///< /states/orientation and /states/angular_velocity
  bool has_contacts = false;               ///< /contacts/offsets
  bool points = false;                     ///< /contacts/point
  bool point_b = false;                    ///< /contacts/point_b (each row's point on B; with point)
  bool jt3 = false;                        ///< /contacts/jt3 (each row's friction impulse vector on A)
  const std::string& path() const { return t->path(); }
  /// "octocd trace version 1" or "external trace version 2".
  std::string kind() const { return fmt::format("{} trace version {}", external ? "external" : "octocd", version); }
};

/// Reads what trace `t` holds (checking an external trace in full with check_external_trace).
Side make_side(const TraceReader& t);


/// The state rows a quantity is compared at: complete rows, their frames checked.
std::pair<std::int64_t, std::vector<std::int64_t>> state_rows(const Side& s);

/// Positions, velocities, orientations or angular velocities at the states both traces
/// hold. A trace without the dataset (no rotation) holds the identity / zero there.
/// Orientations: the difference is the angle between the two (rad); with |q| = 1 the
/// relative part of the tolerance counts as radians too (numpy.isclose's rule with max(|A|,
/// |B|) = 1).
QuantityResult compare_states(const Side& a, const Side& b, const char* dataset, const char* name,
                              std::int64_t bodies, const Tolerance& tol);

/// A per-frame column of /frames at the frames both traces hold.
template <class T>
QuantityResult compare_column(const Side& sa, const Side& sb, const std::string& column, const char* name,
                              const Tolerance& tol);

/// /contacts records (pairs, then normal, depth, J_n, J_t) at the frames both hold, record
/// by record in order: two octocd traces of version 1 (one contact per pair, in (a, b) order).
void compare_contact_records(const Side& a, const Side& b, const Tolerance& tol, QuantityResult& q);

/// Contacts by pair at the frames both traces hold (a version 2 or an external trace on
/// either side): per frame the set of pairs with contact rows, each pair's row count (a
/// manifold's points), then its rows in the order written: depth, jn, jt, normal and, when
/// both traces have them, /contacts/point, /contacts/point_b (the row's point on B) and
/// /contacts/jt3 (its friction impulse vector). A pair on one side only, or with another
/// row count, is an infinite difference.
QuantityResult compare_contacts_by_pair(const Side& a, const Side& b, const Tolerance& tol);

}  // namespace octocd::cli::compare_detail
