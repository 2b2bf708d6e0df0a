#pragma once
/// \file physics_impl.hpp
/// The physics tier's state (PhysicsValidators::Impl) and what its rows share: the
/// tallies of judged items (Tally), the names of judged items, the checked frame's
/// candidate pairs and reference geometry (CheckedFrame). Internal to validation/physics.
///
/// The rows live in files per family:
///  - physics_validators.cpp: the settings' names, the constructor and the frame driver
///    (observe: detection poses, then every row's measure: rows 1-4 judge checked frames,
///    5-8 every frame);
///  - candidates.cpp: a checked frame's candidate pairs and their reference geometry,
///    row 1 (broadphase completeness);
///  - contact_rows.cpp: rows 2 (contact completeness) and 3 (contact geometry);
///  - penetration.cpp: row 4;
///  - friction.cpp: row 5 (the cone and dissipation);
///  - conservation.cpp: row 6 (momentum, angular momentum, energy of isolated groups;
///    the soft-contact episodes);
///  - balance.cpp: rows 7 (momentum balance per body) and 8 (free flight);
///  - feasibility.cpp: row 9 (impulse feasibility: the motion explained by contact
///    impulses octocd finds itself, on the sampled frames with states), with
///    feasibility_contacts.cpp (the contact points found on the posed shapes) and
///    feasibility_programme.cpp (each island's linear programme, COIN-OR CLP);
///  - ordered_judge.hpp: judge_in_order, a row's tally loop judged on the threads in
///    blocks and tallied in item order with the serial loop's verdict, figures and texts
///    (rows 1, 2, 3, 5, 7 and 8);
///  - physics_table.cpp: the generic sums (RowSums), observe()'s calls of every row's
///    measure and results()' of every row's table entry, in validation_rows.def's order
///    (physics_rows.inc: the physics rows of the table by the frames they measure).
/// Each row's measure (Impl::measure<RowId> of every frame, or Impl::judge<RowId> of the
/// checked frames) and table entry (Impl::table<RowId>: its ValidationResult from the sums)
/// sit in its file; its tallies are its RowSums.

#include <algorithm>
#include <cstdint>
#include <functional>
#include <initializer_list>
#include <limits>
#include <map>
#include <memory>
#include <optional>
#include <set>
#include <string>
#include <tuple>
#include <utility>
#include <vector>

#include <fmt/format.h>

#include "octocd/device_judge.hpp"
#include "octocd/exact_pairs.hpp"
#include "octocd/physics.hpp"
#include "octocd/validation_rows.hpp"
#include "../src/components.hpp"
#include "dmath.hpp"
#include "reference.hpp"
#include "frame_array.hpp"
#include "sat.hpp"
#include "seek.hpp"

namespace octocd {

namespace physics_detail {

using dmath::D3;
using dmath::kEps32;
using dmath::M3;

constexpr double kPi = 3.14159265358979323846;
/// Fewest bodies whose per-body boxes (a posed box grown by its reach: rows 1 and 9, the
/// near-pair search) are computed on threads: below it one thread costs less than waking
/// another (exact_pairs' per-box passes use the same 1,024).
constexpr std::size_t kParallelBodyBoxesFrom = 1024;
/// Throws PairLimitError (the count, the limit, the bodies) when `pairs` exceeds
/// limits::kMaxPairsPerBody pairs a body of `bodies`: the limit exact_pairs applies, for a
/// pair set found elsewhere (the judge device's). Saturates instead of overflowing.
inline void require_pair_limit(std::size_t pairs, std::size_t bodies) {
  const std::uint64_t limit = limits::kMaxPairsPerBody > UINT64_MAX / std::max<std::size_t>(bodies, 1)
                                  ? UINT64_MAX
                                  : std::uint64_t(limits::kMaxPairsPerBody) * bodies;
  if (pairs > limit) throw PairLimitError(pairs, false, limit, bodies);
}
/// A relative sliding speed (m/s) below which v_t has no direction: jt is then J_t's
/// magnitude (the trace convention; octocd's Bullet adapter uses the same threshold).
constexpr double kNoSliding = 1e-6;
/// The margin a sequential solver leaves on a row's own cone: a row whose normal impulse
/// moved to the manifold's other rows after its friction was clamped (Bullet: up to 13%
/// above mu times the row's final jn; the friction row holds the pair's sum to the cone
/// itself). What it leaves open is stated in docs/validate-your-engine.md, "The row cone
/// margin".
constexpr double kRowConeMargin = 0.25;
/// An engine's friction floor: the smallest friction coefficient an engine may apply
/// where the scene says less (MuJoCo turns mu 0 into mjMINMU = 1e-5). Every rule takes a
/// pair's mu as at least this (docs/validation.md, "Floors"): a frictionless scene's
/// friction of 1e-5 jn is never a cone failure.
constexpr double kMuFloor = 1e-5;

/// R M R^T.
M3 conjugated(const M3& r, const M3& m);
/// Inverse of a symmetric positive definite 3x3 (zeros when singular).
M3 inverse(const M3& m);

/// "pair (A, B)".
std::string pair_name(Pair p);
/// "body I".
std::string body_name(std::size_t i);
/// A borrowed list of body indices: a vector's or a flat list's range (a contact graph's
/// group), valid while its storage is.
struct BodyList {
  const std::uint32_t* first = nullptr;
  const std::uint32_t* last = nullptr;
  BodyList() = default;
  BodyList(const std::uint32_t* b, const std::uint32_t* e) : first(b), last(e) {}
  BodyList(const std::vector<std::uint32_t>& v) : first(v.data()), last(v.data() + v.size()) {}  // NOLINT: a view
  const std::uint32_t* begin() const { return first; }
  const std::uint32_t* end() const { return last; }
  std::size_t size() const { return std::size_t(last - first); }
  std::uint32_t front() const { return *first; }
  std::uint32_t operator[](std::size_t k) const { return first[k]; }
};

/// "group (I, J, K)": an isolated group by its first bodies (up to 3, then "...").
std::string group_name(BodyList members);

/// Where a judged item is: its frame and its name as expectations write it ("pair (A, B)",
/// "body I", "group (I, J, K)"). A pair's, a body's or a group's name is written only when a
/// Tally needs it (a failure): most items pass, and a frame judges 10^5 - 10^6 of them.
struct Where {
  enum class Kind { Text, Pair, Body, Group };
  std::int64_t frame = -1;
  Kind kind = Kind::Text;
  std::string text;  ///< Kind::Text: the name ("" for none)
  Pair pair{};       ///< Kind::Pair
  std::size_t body = 0;  ///< Kind::Body
  BodyList members;      ///< Kind::Group: borrowed for the check's call
  Where() = default;
  Where(std::int64_t f, std::string name) : frame(f), text(std::move(name)) {}
  Where(std::int64_t f, Pair p) : frame(f), kind(Kind::Pair), pair(p) {}
  static Where of_body(std::int64_t f, std::size_t i) {
    Where w;
    w.frame = f;
    w.kind = Kind::Body;
    w.body = i;
    return w;
  }
  /// An isolated group by its members (ascending), which must outlive the Tally::check
  /// the Where is given to.
  static Where of_group(std::int64_t f, BodyList m) {
    Where w;
    w.frame = f;
    w.kind = Kind::Group;
    w.members = m;
    return w;
  }
  /// The item's name: "pair (A, B)", "body I", "group (I, J, K)" or the text.
  std::string name() const {
    return kind == Kind::Pair    ? pair_name(pair)
           : kind == Kind::Body  ? body_name(body)
           : kind == Kind::Group ? group_name(members)
                                 : text;
  }
};

/// One cause of a row (design.md section 13b.13): judged items, failures, the worst judged figure with
/// its description (pass details), the first failing examples (at most
/// ValidationCause::kMaxExamples) with frame, item and figure, the worst failure, and the
/// distinct failing items (at most ValidationCause::kMaxItems).
struct Tally {
  std::uint64_t checks = 0;
  std::uint64_t failures = 0;
  double worst = -std::numeric_limits<double>::infinity();
  std::string worst_what, first;
  std::vector<ValidationExample> examples;
  ValidationExample worst_failure;
  std::set<std::string> items;
  bool items_complete = true;
  template <class F>
  void check(bool ok, double figure, const Where& where, F&& describe) {
    ++checks;
    const bool new_worst = figure > worst;
    if (ok && !new_worst) return;
    const std::string what = describe();
    if (new_worst) {
      worst = figure;
      worst_what = what;
    }
    if (ok) return;
    if (failures == 0) first = what;
    ++failures;
    const std::string item = where.name();
    ValidationExample e{where.frame, item, figure, what};
    if (failures == 1 || figure > worst_failure.figure) worst_failure = e;
    if (examples.size() < ValidationCause::kMaxExamples) examples.push_back(std::move(e));
    if (!item.empty()) {
      if (items.size() < ValidationCause::kMaxItems || items.count(item))
        items.insert(item);
      else
        items_complete = false;
    }
  }
  /// The same without a named item (the frame and item then come from the text only).
  template <class F>
  void check(bool ok, double figure, F&& describe) {
    check(ok, figure, Where{}, std::forward<F>(describe));
  }
  /// A judged item that cannot fail, with figure 0.
  void judged() {
    ++checks;
    worst = std::max(worst, 0.0);
  }
  double worst_or(double none) const { return checks ? worst : none; }
  /// This tally as a ValidationCause named `name` with figures in `unit`.
  ValidationCause cause(const char* name, const char* unit) const;
  /// "NAME N of M NOUN (worst W UNIT, frame F ITEM: TEXT[; first: TEXT])", or "NAME 0 of M NOUN".
  std::string summary(const char* name, const char* noun, const char* unit) const;
};

/// A pair's reference geometry as the rows read it (reference.hpp, PairReference, without
/// SAT's accepted axes: the figures of row 3 that need them are computed beside it,
/// RowFigures and PairFigures): `have` once computed, `intersects` when the shapes
/// penetrate.
struct ContactTruth {
  ReferenceNormal g;          ///< PairReference::g: FCL's answer, SAT's depth and normal where `sat`
  bool sat = false;           ///< PairReference::sat
  bool intersects = false, have = false;
  Vec3 fcl_normal;            ///< PairReference::fcl.normal (the second opinion where `sat`)
  double fcl_depth = 0;       ///< PairReference::fcl.depth
  std::uint32_t sat_accepted = 0;  ///< where `sat`: SAT's accepted axes (sat_result.accepted.size())
  double sat_epsilon = 0;     ///< where `sat`: sat_result.epsilon (m)
  /// The rows' fields of `t`.
  void assign(const PairReference& t) {
    g = t.g;
    sat = t.sat;
    fcl_normal = t.fcl.normal;
    fcl_depth = t.fcl.depth;
    sat_accepted = static_cast<std::uint32_t>(t.sat ? t.sat_result.accepted.size() : 0);
    sat_epsilon = t.sat_result.epsilon;
    have = true;
    intersects = g.penetrating;
  }
  /// The same pair with A rounded by `ra` and B by `rb` (m, >= 0: each shape's Minkowski
  /// sum with a sphere, PhysicsBodies::convex_radius). Exact: the rounded shapes' depth is
  /// the posed ones' plus ra + rb along the same normal (every support value grows by the
  /// radius, so SAT's accepted axes stay); shapes apart by d <= ra + rb penetrate by
  /// ra + rb - d along their nearest-points direction; farther ones are d - ra - rb apart.
  /// The witness points move onto the rounded surfaces.
  void inflate(double ra, double rb) {
    const double s = ra + rb;
    if (!(s > 0)) return;
    if (g.penetrating) {
      g.depth += s;
      fcl_depth += s;
    } else if (g.distance > s) {
      g.distance -= s;
    } else {
      g.penetrating = true;
      g.depth = s - g.distance;
      g.distance = 0;
      fcl_depth = g.depth;
      fcl_normal = g.normal;
    }
    if (g.valid) {
      g.point_a = g.point_a - static_cast<float>(ra) * g.normal;
      g.point_b = g.point_b + static_cast<float>(rb) * g.normal;
    }
    intersects = g.penetrating;
  }
};

/// The first row of each run of consecutive rows of one pair in `contacts`, ascending,
/// into `starts`, on up to `threads` threads (0: the hardware's; parallel_select in
/// candidates.cpp); `stop` as the validators' loops (ValidationStopped).
void pair_run_starts(const std::vector<ContactRecord>& contacts, std::vector<std::size_t>& starts, int threads,
                     const std::function<bool()>& stop);

/// A pair's contact rows [first, first + count) (rows of a pair are consecutive).
struct PairRows {
  Pair p;
  std::size_t first = 0, count = 0;
};

/// Row 3's figures of one group of a pair's rows (CheckedFrame::rows), from its truth.
struct PairFigures {
  double fcl_angle = 0;    ///< by SAT: FCL's normal to SAT's nearest accepted axis (deg)
  double fcl_minimum = 0;  ///< by SAT: FCL's normal to SAT's minimum (deg)
  bool done = false;       ///< computed (with the row figures of the group)
};
/// Row 3's figures of one contact row.
struct RowFigures {
  RowReference ref;       ///< the reference normal the row is judged against, and its angle
  double da = 0, db = 0;  ///< the point's distance to A's and B's surfaces (m; has_points)
  /// The point on B's (FrameRecord::point_b) distance to A's and B's surfaces (m; 0 without).
  double da_b = 0, db_b = 0;
};

/// One checked frame as rows 1-4 read it (PhysicsValidators::Impl::checked_frame).
struct CheckedFrame {
  const FrameRecord* rec = nullptr;
  const std::vector<Pose>* det = nullptr;  ///< detection poses, one per body
  std::vector<Pair> cand;  ///< candidates: grown exact posed boxes overlap, a body dynamic (sorted)
  std::vector<char> hit;   ///< per candidate: the shapes intersect (all 1 with a broadphase margin)
  /// The reference geometry of every candidate that intersects (or, with a broadphase
  /// margin, every candidate) and every contact pair: truth[k] is truth_pairs[k]'s
  /// (sorted, distinct). Every pair a row asks about is among them.
  std::vector<Pair> truth_pairs;
  FrameArray<ContactTruth> truth;
  /// Pairs asked about beyond truth_pairs (none by construction; computed on demand).
  std::map<std::pair<std::uint32_t, std::uint32_t>, ContactTruth> extra;
  /// Pair p's index in truth_pairs, or truth_pairs.size() when absent.
  std::size_t find(Pair p) const {
    const auto it = std::lower_bound(truth_pairs.begin(), truth_pairs.end(), p);
    return it != truth_pairs.end() && *it == p ? std::size_t(it - truth_pairs.begin()) : truth_pairs.size();
  }
  /// find() through seek(): for pairs asked in ascending order (any order is answered).
  std::size_t find_after(Pair p, std::size_t& cursor) const {
    const std::size_t k = seek(truth_pairs, p, cursor);
    return k < truth_pairs.size() && truth_pairs[k] == p ? k : truth_pairs.size();
  }
  std::vector<PairRows> rows;       ///< the record's rows grouped by pair, in record order
  std::vector<Pair> contact_pairs;  ///< the pairs of rows (sorted)
  std::vector<Pair> required;       ///< candidates whose shapes are within the broadphase margin
  // Row 3's figures, computed in the truth's pass (each pair's SAT axes read while at hand).
  FrameArray<PairFigures> pair_fig;      ///< per group of rows
  FrameArray<ReferenceNormal> aabb_ref;  ///< per group: box-box on the world AABBs (Aabb geometry only)
  FrameArray<RowFigures> row_fig;        ///< per record row
  /// checked_frame's own work space (its contents serve one frame's pass only).
  struct Work {
    std::vector<Aabb> grown;         ///< per body: its exact posed box grown by the reach
    std::vector<Pair> todo;          ///< the candidates that intersect
    std::vector<std::size_t> row_starts;  ///< pair_run_starts of the frame's rows
    std::vector<char> is_required;   ///< per candidate: row 1 requires it
    GroupedItems truth_groups;  ///< per truth entry: its groups of rows, ascending
    GroupScratch group_scratch;  ///< truth_groups' counts
    std::vector<std::size_t> group_truth;  ///< per group of rows: its truth entry (row 3 reads it too)
    std::vector<PairReferenceScratch> scratch;                 ///< per worker
    ExactPairsTables pair_tables;  ///< exact_pairs' tables: the candidates', then row 1's flat set
    /// Whether `cand` is flat's set on `grown` less its static-static pairs (checked_frame's
    /// own search; not where the candidates came from the judge device).
    bool cand_of_grown = false;
    /// Impulse-feasibility's search of this step (checked_frame's `with_reach`): `reach` when
    /// done; its boxes (step_reach_boxes) and pairs (reach_pairs_cpu), the row reads them.
    bool reach = false;
    std::vector<double> motion;
    std::vector<Aabb> world, reach_grown;
    std::vector<Pair> reach_cand;
    ExactPairsTables reach_tables;
    /// Per body the box holding its grown and reach boxes, and their pairs: the one search
    /// both sets are read off.
    std::vector<Aabb> both;
    std::vector<Pair> both_cand;
  } work;
};

/// One pair's reference geometry on a device-judged frame: the device's separating-axis
/// test for two boxes, the CPU reference (pair_reference_into) for any other pair.
struct DeviceTruth {
  ReferenceNormal g;  ///< penetrating, depth (and distance where the CPU reference gave it)
  bool have = true;   ///< always computed (the rows read it as ContactTruth::have)
  bool cpu = false;   ///< from the CPU reference (a pair with another shape, or undecided)
};

/// One checked frame as the device rows read it (PhysicsValidators::Impl::device_frame):
/// the same tables as CheckedFrame's that rows 1 and 4 read, from the device judge.
struct DeviceCheckedFrame {
  const FrameRecord* rec = nullptr;
  DeviceFrameAnswer answer;         ///< the device's candidates and box tests
  std::vector<Pair> contact_pairs;  ///< the pairs of rows (sorted, distinct)
  std::vector<Pair> truth_pairs;    ///< hit candidates and contact pairs (sorted, distinct)
  std::vector<DeviceTruth> truth;   ///< per truth pair
  std::vector<Pair> required;       ///< candidates whose shapes are within the broadphase margin
};

/// A physics row's sums (PhysicsValidators::Impl::row_sums): one Tally per cause of its
/// validation_rows.def entry, in the entry's order; its own time (s, RowClock around its
/// measure: shared work goes to the first row that needs it, e.g. the candidates and the
/// FCL/SAT truth of every pair to broadphase-completeness); its own state beyond the
/// tallies (Impl::row_state; empty until the row makes it).
struct RowSums {
  std::vector<Tally> causes;
  double seconds = 0;
  std::shared_ptr<void> state;
};
/// One RowSums per row of validation_rows(), with a Tally per cause (physics_table.cpp).
std::vector<RowSums> make_row_sums();
/// The index of cause `name` among row `id`'s causes (validation_rows.def); throws
/// std::logic_error naming both when the row has no such cause.
std::size_t cause_index(RowId id, const char* name);

/// One frame as the rows' measures read it (Impl::measure): its record, its detection
/// poses (one per body; the pre-step poses without them), whether it is a checked frame
/// with poses, and its candidates and reference geometry once a row asked (Impl::checked).
struct PhysicsFrame {
  const FrameRecord& rec;
  const std::vector<Pose>& det;
  bool checked = false;
  std::optional<CheckedFrame> geometry;
  std::optional<DeviceCheckedFrame> device_geometry;  ///< with a judge device (Impl::device_checked)
  bool counted = false;  ///< counted in Impl::checked_frames
  /// A checked frame by the --every cadence, with poses or not (PhysicsValidators::observe's
  /// `checked`): the frames impulse-feasibility judges.
  bool sampled = false;
};

/// The detail of a row with no checked frame to judge.
extern const char* const kNoChecked;

/// The row's failures by cause (causes with failures only), its judged count, its verdict
/// and n/a when it judged nothing: the detail gets "; causes: ..." listing every cause.
/// `tallies` are the tallies of `row`'s causes (validation_rows.hpp), in their order;
/// throws std::logic_error when their count is not the row's.
void fill_causes(ValidationResult& r, const RowInfo& row, const std::vector<const Tally*>& tallies);
inline void fill_causes(ValidationResult& r, const RowInfo& row, std::initializer_list<const Tally*> tallies) {
  fill_causes(r, row, std::vector<const Tally*>(tallies));
}

/// Appends "; " and `format` of `args` to `detail` when `when` holds (a row's detail notes).
template <class... A>
void note(std::string& detail, bool when, fmt::format_string<A...> format, A&&... args) {
  if (when) detail += "; " + fmt::format(format, std::forward<A>(args)...);
}

}  // namespace physics_detail

/// The impulse-feasibility row's parts (feasibility.hpp).
namespace feasibility {
struct Contact;
struct ContactSearch;
struct PairContacts;
struct IslandVerdict;
enum class IslandPass : int;
}  // namespace feasibility

struct PhysicsValidators::Impl {
  using D3 = dmath::D3;
  using M3 = dmath::M3;
  using Tally = physics_detail::Tally;

  const Model* model = nullptr;
  PhysicsBodies bodies;
  Tolerances tol;
  std::string label;
  std::unique_ptr<ReferenceGeometry> ref;
  std::vector<M3> inertia;  // body frame
  /// Per body its smallest and largest principal moment (I1, I3; kg m^2): the spin bounds
  /// of free rotation (balance.cpp).
  std::vector<std::array<double, 2>> principal;
  std::vector<double> mass;  // 0 for static bodies
  double max_margin = 0;
  bool restitution_le_1 = true;

  /// The rows' sums, indexed by RowId: each physics row's tallies (one per cause of
  /// validation_rows.def, in its order) and its clock (physics_detail::RowSums).
  std::vector<physics_detail::RowSums> row_sums = physics_detail::make_row_sums();
  /// Row `id`'s sums.
  physics_detail::RowSums& sums(RowId id) { return row_sums[std::size_t(id)]; }
  const physics_detail::RowSums& sums(RowId id) const { return row_sums[std::size_t(id)]; }
  /// The tally of row `id`'s cause named `cause` (validation_rows.def); throws
  /// std::logic_error naming both when the row has no such cause (physics_detail::cause_index).
  Tally& tally(RowId id, const char* cause) { return sums(id).causes[physics_detail::cause_index(id, cause)]; }
  const Tally& tally(RowId id, const char* cause) const {
    return sums(id).causes[physics_detail::cause_index(id, cause)];
  }
  /// The tallies of row `id`'s causes named `causes` (each a const char*), as a tuple of
  /// references in the order named: `auto [a, b] = tallies(RowId::ID, "a", "b");`. Throws as
  /// tally() does.
  template <class... Names>
  auto tallies(RowId id, Names... causes) {
    return std::tie(tally(id, causes)...);
  }
  template <class... Names>
  auto tallies(RowId id, Names... causes) const {
    return std::tie(tally(id, causes)...);
  }
  /// A row's own state beyond its tallies: a T kept in its RowSums, made on first use
  /// (the row's file defines T; a row that never wrote one reads a default T).
  template <class T>
  T& row_state(RowId id) {
    auto& p = sums(id).state;
    if (!p) p = std::make_shared<T>();
    return *static_cast<T*>(p.get());
  }
  template <class T>
  const T& row_state(RowId id) const {
    static const T none{};
    const auto& p = sums(id).state;
    return p ? *static_cast<const T*>(p.get()) : none;
  }
  /// Row `id`'s measure of one frame (the row's file defines it for every physics row of
  /// validation_rows.def that measures Every frame; observe() calls them in the table's
  /// order, each on its row's clock).
  template <RowId id>
  void measure(physics_detail::PhysicsFrame& f);
  /// Row `id`'s judgement of one checked frame with poses, its candidates and reference
  /// geometry (checked()): the measure of a row of validation_rows.def that measures
  /// Checked frames (the row's file defines it; measure_rows calls it on such frames only).
  template <RowId id>
  void judge(physics_detail::CheckedFrame& f);
  /// Row `id`'s result from the sums (the row's file; results() calls them in order).
  template <RowId id>
  ValidationResult table() const;
  /// Every physics row's measure of frame `f`, in validation_rows.def's order, each on its
  /// row's clock (physics_table.cpp).
  void measure_rows(physics_detail::PhysicsFrame& f);
  /// The frame's candidates and reference geometry (checked_frame) on a checked frame with
  /// poses, computed on the first call (counted in checked_frames; its time goes to the row
  /// that asked first); nullptr on other frames. With a judge device the candidates are the
  /// device's (device_checked: the same set of grown boxes, posed on the device), the reference
  /// geometry of the pairs the rows read the CPU's.
  physics_detail::CheckedFrame* checked(physics_detail::PhysicsFrame& f) {
    if (!f.checked) return nullptr;
    if (!f.geometry) {
      const std::vector<Pair>* from_device = device ? &device_checked(f)->answer.candidates : nullptr;
      count_checked(f);
      if (spare_frame) {
        f.geometry = std::move(spare_frame);
        spare_frame.reset();
      } else {
        f.geometry.emplace();
      }
      checked_frame(f.rec, f.det, *f.geometry, from_device, !from_device && feasibility_step(f));
      if (from_device) ++device_cpu_geometry_frames;
    }
    return &*f.geometry;
  }
  /// Counts `f` once in checked_frames (by the first of checked() and device_checked()).
  void count_checked(physics_detail::PhysicsFrame& f) {
    if (!f.counted) ++checked_frames;
    f.counted = true;
  }
  /// With a judge device: the frame's device geometry (device_frame), computed on the first
  /// call (its time goes to the row that asked first); nullptr on frames that are not checked.
  physics_detail::DeviceCheckedFrame* device_checked(physics_detail::PhysicsFrame& f) {
    if (!f.checked) return nullptr;
    if (!f.device_geometry) {
      count_checked(f);
      f.device_geometry.emplace();
      device_frame(f.rec, f.det, *f.device_geometry);
    }
    return &*f.device_geometry;
  }
  /// With a judge device: row `id`'s judgement of a checked frame from the device's
  /// geometry, true when it judged there; false: the row needs the CPU's CheckedFrame
  /// (judge). Every row that judges Checked frames defines it in its file.
  template <RowId id>
  bool judge_device(physics_detail::DeviceCheckedFrame& f);
  /// A physics result of row `id` with its tier, name, figure and tolerances.
  static ValidationResult start_row(RowId id, const char* figure, const char* tolerances);
  /// start_row for a row whose figure is its failures: measured is the failures of all its
  /// tallies summed (bound 0), pass when there are none.
  ValidationResult failures_row(RowId id, const char* figure, const char* tolerances) const;
  /// fill_causes with row `id`'s own tallies.
  void fill_causes(ValidationResult& r, RowId id) const;

  /// Sleeping bodies (PhysicsBodies::Deactivation::Flagged): free-flight's `sleeping` cause
  /// (asleep through the step, must not move); body-steps that fell asleep (not judged);
  /// groups with a sleeping body (not judged on conservation); pairs of sleeping bodies not
  /// required among the candidates or the contacts.
  std::uint64_t fell_asleep = 0, groups_asleep = 0, broad_asleep = 0, complete_asleep = 0;
  /// Contact completeness on non-convex pairs: pair-frames without a row whose depth
  /// above contact_depth_m is only an upper bound, no exact test proving it (n/a); the
  /// largest such bound (m) and where.
  std::uint64_t complete_unproven = 0;
  double complete_unproven_worst = 0;
  std::string complete_unproven_what;
  std::uint64_t balance_clamped = 0, balance_no_rows = 0, balance_locked = 0, free_locked = 0, balance_rot_locked = 0;
  // Gyroscopic term undeclared: body-steps whose spin met the invariants (the term) and
  // those that kept w (no term) (figures of free-flight and momentum-balance).
  std::uint64_t free_spin_invariant = 0, free_spin_kept = 0, balance_ang_invariant = 0, balance_ang_plain = 0;
  std::uint64_t broad_frames = 0, broad_candidates = 0, broad_true = 0, broad_no_pairs = 0;
  std::uint64_t checked_frames = 0, rows_unjudged = 0, upper_bound_pairs = 0;
  std::uint64_t sign_rows = 0, sign_agree = 0, shape_angle_rows = 0;
  /// Angles in degrees ([0, 180]) streamed into bins of kBinDeg: the count, mean and largest
  /// exact, a quantile to within half a bin (its bin's centre, at most the largest), in
  /// memory that does not grow with the run (a figure, not judged).
  struct AngleSample {
    static constexpr double kBinDeg = 0.01;
    std::vector<std::uint64_t> bins;  // allocated at the first angle
    std::uint64_t count = 0;
    double sum = 0, max = 0;
    /// Adds one angle (deg); NaN and values outside [0, 180] go to the end bins.
    void push_back(double deg);
    bool empty() const { return count == 0; }
    /// The angle of rank r (0-based, r < count) to within kBinDeg / 2.
    double at(std::uint64_t r) const;
  };
  AngleSample shape_angles;  // Aabb geometry: angle to the posed shapes (figure)
  std::uint64_t aabb_angle_rows = 0;  // Aabb geometry: rows compared with box-box on the AABBs (figure)
  double aabb_angle_worst = 0;
  std::uint64_t speculative_rows = 0;  // rows on shapes that do not penetrate (figure)
  /// Resting rows (depth 0 or no depth, beside a deeper row, or on shapes that penetrate by
  /// no more than contact_depth_m) judged on the posed shapes' exact direction (SAT's
  /// accepted axes, or box-box on the world AABBs); of them, rows passed along an axis on
  /// which the touching shapes overlap by no more than contact_depth_m (not SAT's minimum).
  std::uint64_t resting_rows = 0, resting_wide = 0;
  double resting_worst = 0;  ///< deg: the largest judged angle of a resting row (not aabb)
  std::uint64_t sign_uncertain_rows = 0;  // of them, on hulls FCL calls apart along no separating axis
  // Contact geometry's references: pairs judged by the separating-axis test and by the posed
  // reference; where the posed reference's normal lies outside SAT's accepted axes (a figure).
  std::uint64_t sat_pairs = 0, fcl_pairs = 0, sat_fcl_other = 0, sat_fcl_disagree = 0;
  double sat_fcl_worst_excess = 0, sat_fcl_other_excess = 0;
  std::string sat_fcl_what;
  SatSettings sat_settings;
  // Declared collision shapes other than the body's own (figure): bodies per kind and the
  // largest gap between the declared shape and the true one (m).
  std::map<std::string, std::pair<std::uint64_t, double>> declared;
  double speculative_worst = 0;
  // Friction rules: pairs judged on jt3 (vectors) and on the scalar jt.
  std::uint64_t cone_jt3_pairs = 0, cone_scalar_pairs = 0, dissipation_jt3_pairs = 0, dissipation_small = 0;
  std::uint64_t dissipation_cone_only = 0, groups = 0, groups_rotating = 0, state_frames = 0, groups_clamped = 0;
  std::int64_t last_frame = 0;
  /// The observed step's detection poses (memory kept from step to step).
  std::vector<Pose> step_poses;
  /// broadphase-completeness' set of `flat` on the world AABBs of frame `flat_frame`, less its
  /// static-static pairs (PhysicsValidators::flat_pairs); flat_frame -1: none kept.
  std::vector<Pair> flat_dynamic;
  std::int64_t flat_frame = -1;
  std::function<bool()> stop;  // polled inside the long loops (set_stop)
  int threads = 0;              // set_threads (0: the hardware's)

  double pair_margin(Pair p) const {
    if (!bodies.theta_margin) return bodies.contact_margin;
    return model->theta(model->bodies[p.a].shape, model->bodies[p.b].shape);
  }
  /// The pair's friction coefficient, at least physics_detail::kMuFloor.
  double pair_mu(Pair p) const { return pair_friction(bodies, p.a, p.b); }
  bool dynamic(std::uint32_t i) const { return mass[i] > 0; }
  /// Body i asleep in the state before (pre) or after the step (FrameRecord::asleep_pre /
  /// asleep_post; PhysicsBodies::Deactivation).
  static bool asleep(const std::vector<std::uint8_t>& flags, std::uint32_t i) { return !flags.empty() && flags[i]; }
  /// Every dynamic body of p was asleep before the step: the engine need not collide it.
  bool pair_asleep(const FrameRecord& rec, Pair p) const {
    if (rec.asleep_pre.empty()) return false;
    const bool a = !dynamic(p.a) || asleep(rec.asleep_pre, p.a), b = !dynamic(p.b) || asleep(rec.asleep_pre, p.b);
    return a && b && (dynamic(p.a) || dynamic(p.b));
  }

  /// `speculative`: how far pair p's shapes may approach within the step (m; infinity
  /// without states): dt (|v_a - v_b| + |w_a| R_a + |w_b| R_b), the larger of before and after.
  double speculative_reach(const FrameRecord& rec, Pair p) const;
  std::uint64_t speculative_allowed = 0;  ///< contact pairs given a speculative reach
  std::uint64_t points_persistent = 0;    ///< rows whose point check is not applied (persistent points)
  // ---- depth_per and rounded shapes (contact_rows.cpp, candidates.cpp) -----------------
  std::uint64_t depth_unknown_pairs = 0;   ///< depth_per "unknown": pairs whose depth is not judged
  std::uint64_t depth_manifold_pairs = 0;  ///< depth_per "manifold": pairs judged along their normal
  /// depth_per undeclared: pairs whose deepest row misses SAT's minimum but fits the hulls'
  /// overlap along its normal (a manifold's depth): passed, counted.
  std::uint64_t depth_spared_as_manifold = 0;
  std::uint64_t rounded_pairs = 0;         ///< pairs judged on shapes inflated by a convex radius
  /// Pair p's convex radii summed (m; PhysicsBodies::convex_radius, 0 without): how far the
  /// rounded shapes reach beyond the posed ones.
  double inflation(Pair p) const { return radius(p.a) + radius(p.b); }
  /// Where row k of `rec` applies its impulse on B (m, world): FrameRecord::point_b where
  /// the record carries it (two witness points per row), else the row's point (one point
  /// for both bodies). Only meaningful with rec.has_points.
  static Vec3 point_on_b(const FrameRecord& rec, std::size_t k) {
    return rec.point_b.size() == rec.contacts.size() ? rec.point_b[k] : rec.contacts[k].point;
  }
  /// Body i's centre of mass at pose `pose` (m, world): the pose's position plus the
  /// rotated PhysicsBodies::com_offset (the position itself without one). The lever origin
  /// of a row's impulse at the detection pose (momentum-balance, friction).
  D3 com_at(const Pose& pose, std::uint32_t i) const {
    const D3 x = dmath::d3(pose.position);
    if (bodies.com_offset.empty()) return x;
    const auto& c = bodies.com_offset[i];
    return dmath::operator+(x, dmath::mul(dmath::rotation(pose.orientation), D3{c[0], c[1], c[2]}));
  }
  /// The body frame's pose of body i whose centre of mass is at x (a state's position)
  /// with orientation q: x - R c (PhysicsBodies::com_offset; x itself without one). Where
  /// a rule places the shapes from the states.
  Pose frame_pose(Vec3 x, Quat q, std::uint32_t i) const {
    if (bodies.com_offset.empty()) return Pose{x, q};
    const auto& c = bodies.com_offset[i];
    const D3 rc = dmath::mul(dmath::rotation(q), D3{c[0], c[1], c[2]});
    return Pose{Vec3{static_cast<float>(x.x - rc[0]), static_cast<float>(x.y - rc[1]), static_cast<float>(x.z - rc[2])},
                q};
  }
  /// How far body i's collided surface reaches beyond its local box's farthest point from
  /// the states' point (m): its convex radius plus |com_offset| (apart.cpp, the
  /// speculative reach).
  double extra_reach(std::uint32_t i) const {
    const double com = bodies.com_offset.empty() ? 0.0
                                                 : dmath::len3(D3{bodies.com_offset[i][0], bodies.com_offset[i][1],
                                                                  bodies.com_offset[i][2]});
    return radius(i) + com;
  }
  /// With `velocity_at` "origin" (PhysicsBodies::velocity_at_origin): the speeds of the
  /// origin's motion about the centre of mass before and after the step, |w x R c| summed
  /// (m/s): the stored velocity was rounded at the origin's magnitude, so the converted
  /// one carries u of it on each side (free-flight's velocity floor; 0 otherwise).
  double stored_origin_speed(const FrameRecord& rec, std::uint32_t i) const {
    if (!bodies.velocity_at_origin || bodies.com_offset.empty() || rec.w_pre.empty() || rec.w_post.empty()) return 0.0;
    const D3 c{bodies.com_offset[i][0], bodies.com_offset[i][1], bodies.com_offset[i][2]};
    // |w x R c| <= |w| |c| whatever R: the bound needs no orientation.
    return dmath::len3(c) * (dmath::len3(dmath::d3(rec.w_pre[i])) + dmath::len3(dmath::d3(rec.w_post[i])));
  }
  /// What an engine integrating the body frame's origin (PhysicsBodies::integrated_origin)
  /// moves the centre of mass off its own rule in one step (docs/validation.md, "An engine
  /// that integrates the body origin"): with c = |com_offset|, w the larger of |w|, |w'|
  /// and dw = |w' - w|, velocity c dt w (3 dw + 2 dt w^2) (m/s), position c dt (dw + 2 dt
  /// w^2) (m); both 0 without the declaration, an offset or angular velocities.
  struct OriginDrift {
    double velocity = 0, position = 0;
  };
  OriginDrift origin_drift(const FrameRecord& rec, std::uint32_t i) const {
    if (!bodies.integrated_origin || bodies.com_offset.empty() || rec.w_pre.empty() || rec.w_post.empty()) return {};
    const double c = dmath::len3(D3{bodies.com_offset[i][0], bodies.com_offset[i][1], bodies.com_offset[i][2]});
    const D3 w0 = dmath::d3(rec.w_pre[i]), w1 = dmath::d3(rec.w_post[i]);
    const double w = std::max(dmath::len3(w0), dmath::len3(w1));
    const double dw = dmath::len3(dmath::operator-(w1, w0)), dt = model->scene.dt;
    return {c * dt * w * (3.0 * dw + 2.0 * dt * w * w), c * dt * (dw + 2.0 * dt * w * w)};
  }
  /// integrated_point "origin": body-steps judged with OriginDrift's allowance (free-flight,
  /// momentum-balance) and the largest velocity allowance given to each (m/s).
  std::uint64_t origin_drift_free = 0, origin_drift_balance = 0;
  double origin_drift_free_worst = 0, origin_drift_balance_worst = 0;
  /// Body i's convex radius (m; 0 without /bodies/convex_radius).
  double radius(std::uint32_t i) const { return bodies.convex_radius.empty() ? 0.0 : bodies.convex_radius[i]; }

  // ---- The judge device (device_rows.cpp; octocd/device_judge.hpp) ------------------
  /// The device that judges rows 1 and 4 (set_judge_device); null: every row on the CPU.
  std::unique_ptr<DeviceJudge> device;
  bool device_bodies_set = false;
  std::vector<char> device_box;  ///< per body: a box on the device
  /// Device figures: frames, candidate pairs, truth pairs the CPU reference answered and
  /// their shape pairs ("bunny@0.2 / box": count), the device calls' seconds.
  std::uint64_t device_frames = 0, device_candidates = 0, device_cpu_pairs = 0, device_box_pairs = 0;
  std::map<std::string, std::uint64_t> device_cpu_shapes;
  double device_seconds = 0, device_flat_seconds = 0;  ///< judge_frame's; overlapping_pairs' (not-flat)
  /// reach_pairs' calls on the device and their seconds (impulse-feasibility, the near pairs).
  std::uint64_t device_reach_calls = 0;
  double device_reach_seconds = 0;
  /// Every pair (a < b, sorted) whose `grown` boxes overlap (inclusive), at least one body
  /// dynamic: the device's overlapping_pairs when a judge device is set, else exact_pairs on
  /// the validators' threads with `tables` (whose set also holds static-static pairs, which
  /// are dropped here too: no caller reads them). At most limits::kMaxPairsPerBody pairs a
  /// body (PairLimitError naming the count). Candidates of impulse-feasibility and of the
  /// near-pair search (design.md section 13; device_rows.cpp).
  void reach_pairs(const std::vector<Aabb>& grown, std::vector<Pair>& out, ExactPairsTables& tables);
  /// reach_pairs' search on the CPU (exact_pairs), whatever the judge device.
  void reach_pairs_cpu(const std::vector<Aabb>& grown, std::vector<Pair>& out, ExactPairsTables& tables) const;
  /// Impulse-feasibility's boxes of a step (feasibility.cpp): per body its motion through
  /// the step (step_motion, m), its exact AABB at its detection pose (the record's world
  /// AABB where the engine resolves on AABBs) and that box grown by the motion, its convex
  /// radius and half the largest margin and the slack: two shapes that come within the
  /// margin of each other in the step have overlapping grown boxes.
  void step_reach_boxes(const FrameRecord& rec, const std::vector<Pose>& det, std::vector<double>& motion,
                        std::vector<Aabb>& world, std::vector<Aabb>& grown) const;
  /// Whether impulse-feasibility judges frame `f`'s step (a checked frame by the cadence,
  /// every body's states before and after the step recorded).
  bool feasibility_step(const physics_detail::PhysicsFrame& f) const;
  /// Checked frames whose CPU geometry (rows 2 and 3) took the device's candidates (checked()).
  std::uint64_t device_cpu_geometry_frames = 0;
  /// The bodies on the device (DeviceJudge::set_bodies), once: the boxes, their local boxes and
  /// growth, the dynamic flags (device_rows.cpp).
  void set_device_bodies();
  /// The device geometry of a checked frame into `f` (device_rows.cpp).
  void device_frame(const FrameRecord& rec, const std::vector<Pose>& det, physics_detail::DeviceCheckedFrame& f);
  /// The note a device row's detail carries: where it ran, what went to the CPU reference.
  std::string device_note() const;
  /// truth_after() on a device frame: every pair a row asks is among its truth pairs
  /// (throws std::logic_error otherwise).
  const physics_detail::DeviceTruth& truth_after(physics_detail::DeviceCheckedFrame& f, Pair p,
                                                 std::size_t& cursor) const;
  /// Row 1's judgement on either frame kind (candidates.cpp).
  template <class Frame>
  void judge_broadphase(Frame& f);
  /// Row 4's judgement on either frame kind (penetration.cpp).
  template <class Frame>
  void judge_penetration(Frame& f);

  // ---- Rows 1-4 (checked frames with poses) --------------------------------------
  /// The frame's candidates, their reference geometry (on `threads` threads) and the
  /// pairs row 1 requires, written into `f` (candidates.cpp): every table of `f` is
  /// rebuilt for this frame in the memory it already holds (a checked frame's tables are
  /// kept from frame to frame: spare_frame).
  /// `candidates`: the frame's candidate pairs found elsewhere (the judge device's: sorted,
  /// a < b, a body dynamic, every pair whose grown boxes overlap), taken instead of
  /// exact_pairs' search; null: searched here.
  /// `with_reach`: impulse-feasibility judges this step (feasibility_step): its pairs within
  /// the step's reach are found here too (CheckedFrame::Work::reach), both sets read off one
  /// search of the boxes that hold each body's two boxes (one search of the frame fewer).
  void checked_frame(const FrameRecord& rec, const std::vector<Pose>& det, physics_detail::CheckedFrame& f,
                     const std::vector<Pair>* candidates = nullptr, bool with_reach = false) const;
  /// The last checked frame's tables, kept for the next one's (checked(), observe()): their
  /// memory, 0.2-0.3 KB a pair, is allocated and first touched once per judge instead of
  /// once per frame.
  std::optional<physics_detail::CheckedFrame> spare_frame;
  /// Pair p's reference geometry, computed into f.truth when missing.
  const physics_detail::ContactTruth& full_truth(physics_detail::CheckedFrame& f, Pair p) const;
  /// full_truth() with the look-up through CheckedFrame::find_after (`cursor` as there).
  const physics_detail::ContactTruth& truth_after(physics_detail::CheckedFrame& f, Pair p,
                                                  std::size_t& cursor) const {
    const std::size_t k = f.find_after(p, cursor);
    return k < f.truth.size() ? f.truth[k] : full_truth(f, p);
  }
  /// Whether candidate `p` of a checked frame (either kind) is a pair row 1 requires of
  /// the broadphase: its shapes within broadphase_margin_m less geometry_slack_m. With that
  /// margin above 0 every candidate's distance is looked up; else only a candidate whose
  /// shapes intersect (`hit`) is, and it is required when it penetrates by less than the
  /// slack less the margin. `cursor` as in truth_after (candidates in sorted order).
  template <class Frame>
  bool required_pair(Frame& f, Pair p, bool hit, std::size_t& cursor) const {
    const double within = tol.broadphase_margin_m - tol.geometry_slack_m;
    if (within > 0) return truth_after(f, p, cursor).g.signed_distance() < within;
    if (!hit) return false;
    const ReferenceNormal& g = truth_after(f, p, cursor).g;
    return g.penetrating && -g.depth < within;
  }
  /// Row 3's figures of group `i` of f.rows (PairFigures, RowFigures, CheckedFrame::aabb_ref)
  /// from its truth `t` and SAT's accepted axes (contact_rows.cpp). Thread-safe across groups.
  void pair_figures(physics_detail::CheckedFrame& f, std::size_t i, const physics_detail::ContactTruth& t,
                    const std::vector<SatAxis>& accepted) const;

  // ---- Rows 5-8 (every frame) -------------------------------------------------------
  /// Row 5: the cone on every frame, dissipation on frames with states (friction.cpp).
  void friction(const FrameRecord& rec, const std::vector<Pose>& det);
  /// Dissipation of pair p's rows [k0, k1) from their tangential impulse vectors (jt3),
  /// into `dissipation` (the friction row's tally of that cause, or a block's DryTally)
  /// and the counts of `sums` (the Impl, or a block's sums: judge_in_order).
  template <class Sums, class T>
  void judge_pair_friction(const FrameRecord& rec, const std::vector<Pose>& det, Pair p, std::size_t k0,
                           std::size_t k1, Sums& sums, T& dissipation) const;
  /// Row 6 on frames with states: isolated groups' momentum, energy, angular momentum;
  /// soft contacts' episodes (conservation.cpp).
  void conservation(const FrameRecord& rec);
  /// Rows 7-8 on frames with states (balance.cpp).
  void balance(const FrameRecord& rec, const std::vector<Pose>& det);
  /// A step's contact graph: the contact rows' and confirmed pairs joined (components.hpp:
  /// each component named by its lowest body, statics included), per root whether a member
  /// touches a static body, and the groups: the components with a dynamic body in contact,
  /// in ascending order of their roots, each listing those dynamic bodies ascending.
  struct ContactGraph {
    Components components;
    std::vector<std::uint8_t> statics;  ///< per root: 1 where it touches a static body
    std::vector<std::uint32_t> roots;   ///< per group: its root
    GroupedItems members;               ///< per group: its dynamic bodies in contact
    /// Per body: the index of its group (read for the groups' members only).
    std::vector<std::uint32_t> group_index;
    /// Body i's root (its component's lowest body).
    std::uint32_t find(std::uint32_t i) const { return components.root(i); }
    /// The group count.
    std::size_t groups() const { return roots.size(); }
    /// Group g's dynamic bodies, ascending.
    physics_detail::BodyList group(std::size_t g) const { return {members.begin(g), members.end(g)}; }
    /// The index of root r's group, or groups() when r has none.
    std::size_t group_of(std::uint32_t r) const;
    /// The grouping's scratch and its groups per root (every body a root of its own).
    GroupScratch scratch;
    GroupedItems by_root;
  };
  /// Fills `graph` with rec's contact graph, in the memory it holds (a previous step's).
  void contact_graph(const FrameRecord& rec, ContactGraph& graph) const;
  /// Conservation's graph and per-group sums, kept from step to step (at 10^6 bodies fresh
  /// pages for them each step cost more than the passes that fill them).
  struct ConservationMemory {
    ContactGraph graph;
    GroupScratch scratch;
    GroupedItems group_rows;
    std::vector<double> witness_torque;
    std::vector<D3> witness_turn;
  } conservation_memory;
  /// Mechanical energy of body i (kinetic + rotational - m g . x), before or after the step.
  double mechanical_energy(const FrameRecord& rec, std::uint32_t i, bool post) const;
  /// A step's component of the contact graph: its dynamic bodies (sorted) and whether it
  /// touches no static body.
  struct Component {
    std::vector<std::uint32_t> members;
    bool isolated = false;
  };
  /// contact_model soft: opens, grows, spoils and closes (judging energy) the contact
  /// episodes of isolated groups; `components`: this step's components with a dynamic body.
  void soft_episodes(const FrameRecord& rec, const std::vector<Component>& components);
  /// The graph's components with a dynamic body.
  std::vector<Component> components(const ContactGraph& graph) const;
  /// A frame outside the judged ones: the episodes only (PhysicsValidators::observe_episodes).
  void advance_episodes(const FrameRecord& rec);
  /// Energy is judged per contact episode (contact_model soft, restitution <= 1).
  bool tracks_episodes() const {
    return bodies.contact_model != PhysicsBodies::ContactModel::Rigid && restitution_le_1;
  }
  /// Episodes judged here: those begun in [episode_first, episode_last] (set_episode_frames).
  std::int64_t episode_first = std::numeric_limits<std::int64_t>::min();
  std::int64_t episode_last = std::numeric_limits<std::int64_t>::max();
  bool owned(std::int64_t start) const { return start >= episode_first && start <= episode_last; }
  /// Open episodes judged here.
  std::size_t owned_open() const {
    return std::size_t(
        std::count_if(episodes.begin(), episodes.end(), [&](const Episode& e) { return owned(e.start); }));
  }
  /// A contact episode of an isolated group (contact_model soft): its dynamic bodies
  /// (sorted), from its first contact step until none of them touches another; energy and
  /// kinetic energy at the start (a body joining later: at the step it joins).
  struct Episode {
    std::int64_t start = 0;
    std::vector<std::uint32_t> bodies;
    double e0 = 0, ke0 = 0, scale = 0;
    bool spoiled = false;
    bool began_in_contact = false;  ///< a pair of it touched in the step before it opened
    /// contact_model undeclared: its steps whose kinetic energy rose beyond the rigid
    /// bound, and the first one's description.
    std::uint64_t rigid_rises = 0;
    std::string first_rise;
  };
  /// contact_model undeclared: this step's isolated groups whose kinetic energy rose beyond
  /// the rigid bound (their first body, the description), attached to their episodes.
  std::vector<std::pair<std::uint32_t, std::string>> rigid_rises_now;
  /// Of them, those in no episode judged to fail (a soft contact may return the energy):
  /// not failures (counted).
  std::uint64_t rigid_rises_spared = 0;
  /// The rigid energy rule on an isolated group's step: its kinetic energy before (after
  /// gravity) and after, the bound, and whether it rose beyond it.
  struct StepEnergy {
    double ke0 = 0, ke1 = 0, bound = 0;
    bool rose = false;
  };
  StepEnergy step_energy(const FrameRecord& rec, physics_detail::BodyList members) const;
  std::vector<Episode> episodes;  // contact_model soft: open episodes
  /// The pairs of dynamic bodies with a contact row in frame `pairs_frame` (the last frame
  /// soft_episodes saw; 0: none yet, the state before frame 1), sorted.
  std::vector<Pair> pairs_before;
  std::int64_t pairs_frame = 0;
  std::uint64_t episodes_judged = 0, episodes_judged_groups = 0, episodes_unjudged = 0, energy_soft_steps = 0;
  std::uint64_t episodes_begun_in_contact = 0;
  std::uint64_t groups_locked = 0, groups_rotation_locked = 0;
  /// impulses "none": rotating groups whose angular momentum is not judged (the
  /// witness-point lever of its rows needs their impulses).
  std::uint64_t groups_angular_unreported = 0;

  // ---- contacts_complete 0: what the geometry shows apart (apart.cpp) ---------------
  /// This step's bodies that may touch another body without a row (contacts_complete 0 or
  /// /contacts/incomplete, design.md section 13d item 5b): the pairs whose shapes, at the
  /// pre-step poses, lie within the pair's margin + geometry_slack_m + the pair's motion
  /// through the step (pair_motion), by the exact reference (ReferenceGeometry::posed; no
  /// answer: near). Pairs inside one component of the contact graph are not tested (an
  /// impulse between them is exchanged within it).
  struct NearPairs {
    std::int64_t frame = -1;          ///< the step they are of (-1: none computed)
    std::vector<std::uint8_t> body;   ///< per body: 1 when in a near pair
    std::vector<Pair> pairs;          ///< the near pairs (sorted)
  };
  NearPairs near;
  /// find_near's exact_pairs tables, kept from frame to frame.
  ExactPairsTables near_tables;
  /// Computes `near` for rec's step (states needed; nothing without them). With
  /// `/contacts/incomplete` naming pairs of the step (not the whole step), only those pairs
  /// are kept: every other pair's rows are complete.
  void find_near(const FrameRecord& rec);
  /// How far body i's shape may move through rec's step (m): the larger of dt |v|, dt |v'|
  /// and |x' - x|, plus |g| dt^2, plus its reach from its origin times the larger of
  /// dt |w|, dt |w'| and the turn from q to q' (step_turn).
  double step_motion(const FrameRecord& rec, std::uint32_t i) const;
  /// The rotating part of step_motion: body i's reach from its origin times its turn (m).
  double step_turn(const FrameRecord& rec, std::uint32_t i) const;
  /// How far the shapes of a and b may move towards each other through rec's step (m):
  /// their relative translation, the larger of dt |v_a - v_b|, dt |v'_a - v'_b| and
  /// |(x'_a - x_a) - (x'_b - x_b)|, plus |g| dt^2, plus both turns (step_turn); at most the
  /// sum of both step_motion. Two bodies falling side by side do not approach.
  double pair_motion(const FrameRecord& rec, std::uint32_t a, std::uint32_t b) const;
  // ---- impulse feasibility's parts (feasibility.hpp) ----------------------------------
  /// Pair p's contact points and normals found on the posed shapes (docs/validation.md,
  /// "Motion explained by feasible contact impulses", 1), into `found`: none when the pair is
  /// out of reach or has no dynamic body (feasibility_contacts.cpp).
  void feasibility_contacts(const feasibility::ContactSearch& search, Pair p, feasibility::PairContacts& found) const;
  /// One pass over islands ids[0 .. count - 1] of step `rec` (island ii: its dynamic bodies
  /// island_members[ii], its contacts island_contacts[ii]; `rotating`: angular momentum
  /// judged too) into verdicts[ii] (the same section, 2-4; feasibility_programme.cpp):
  /// IslandPass::Witness decides which islands are judged and gives each judged one its
  /// witness figure; IslandPass::Programme (judged islands, ascending, after their witness
  /// pass) solves their linear programmes, the first programmes of consecutive small islands
  /// as one, an island whose impulses found there leave more than its bound solved again
  /// alone, and the figure is the smaller of the programme's and the witness'.
  void feasibility_islands(const FrameRecord& rec, const std::vector<Pose>& det,
                           const std::vector<std::vector<feasibility::Contact>>& island_contacts,
                           const std::vector<std::vector<std::uint32_t>>& island_members, const std::uint32_t* ids,
                           std::size_t count, bool rotating, feasibility::IslandPass pass,
                           std::vector<feasibility::IslandVerdict>& verdicts) const;
  // ---- where rows may be missing: contacts_complete 0 (every step) or /contacts/incomplete
  /// Step `frame` may lack some pair's rows.
  bool incomplete_step(std::int64_t frame) const;
  /// Step `frame` may lack every pair's rows (contacts_complete 0, or the frame listed whole).
  bool incomplete_whole_step(std::int64_t frame) const;
  /// Step `frame` may lack the rows of pair p (a < b).
  bool incomplete_pair(std::int64_t frame, Pair p) const;
  /// Step `frame` may lack rows of a pair with body i.
  bool incomplete_body(std::int64_t frame, std::uint32_t i) const;
  /// The entries of bodies.incomplete_rows of `frame` (a range of it).
  std::pair<const PhysicsBodies::IncompleteRows*, const PhysicsBodies::IncompleteRows*> incomplete_of(
      std::int64_t frame) const;
  std::uint64_t complete_declared = 0;  ///< contact-completeness: penetrating pair-frames without rows declared incomplete
  /// A step that may lack rows: marks as touching a static body (not isolated) every group of
  /// `graph` in a near pair with a body outside it; returns how many such groups of 2 or
  /// more dynamic bodies were isolated before.
  std::uint64_t open_near_groups(ContactGraph& graph) const;
  std::uint64_t free_near = 0;     ///< free-flight: body-steps without rows but near a body, not judged
  std::uint64_t groups_near = 0;   ///< conservation: groups near a body outside them, not judged
  std::uint64_t near_tested = 0;   ///< pairs the exact reference was asked about
  std::uint64_t balance_incomplete = 0;  ///< momentum-balance: body-steps not judged (a row may be missing)

  // ---- momentum-balance's systematic ratio (balance.cpp; docs/validation.md, "A systematic
  // impulse ratio") -----------------------------------------------------------------------
  /// What a row leaves open of a body's friction: a disc of radius u (kg m/s) normal to n.
  struct BalanceDisc {
    D3 n;
    double u = 0;
  };
  /// balance()'s per-body sums of a frame's rows, kept from frame to frame (their memory
  /// allocated and faulted in once, not each frame: at 10^6 bodies 130 MB that took most of
  /// the row's time). Between frames every entry is zero or empty: balance() resets the
  /// bodies of its frame's rows and confirmed pairs as it leaves, by return or exception.
  struct BalanceScratch {
    std::vector<D3> force, torque;
    std::vector<double> mag, tmag, tallow, any_dir;
    std::vector<std::vector<BalanceDisc>> discs;
    std::vector<std::vector<D3>> row_j;
    std::vector<std::uint32_t> rows_of;
    std::vector<std::uint8_t> in_contact;
  };
  BalanceScratch balance_scratch;
  /// A body-step whose linear balance failed at ratio 1: judged again in results() at the
  /// fitted ratio (it fails only where it fails at both).
  struct DeferredBalance {
    std::int64_t frame = 0;
    std::uint32_t body = 0, rows = 0;
    D3 mdv, force;              ///< m (v' - v - g dt) and its rows' impulses summed (kg m/s)
    double float_bound = 0;     ///< the rounding bound (kg m/s)
    double r1 = 0;              ///< its figure at ratio 1 (of the bound)
    std::size_t disc_first = 0, disc_count = 0;  ///< its discs in deferred_discs
    std::size_t row_first = 0, row_count = 0;    ///< its rows' impulses on it in deferred_rows
  };
  /// At most this many deferred body-steps (and their discs) are kept; the rest stay failures
  /// at ratio 1 (counted: deferred_over).
  static constexpr std::size_t kMaxDeferred = std::size_t(1) << 18;
  std::vector<DeferredBalance> deferred;
  std::vector<BalanceDisc> deferred_discs;
  std::vector<D3> deferred_rows;  ///< each deferred body-step's rows' impulses on it (kg m/s)
  std::uint64_t deferred_over = 0;
  /// The fit's sample: s = (J . d) / (m dv . d) (reported impulses over the momentum change)
  /// of body-steps whose s the record fixes to kFitPrecision along d (m dv's direction or a
  /// row's normal: the open friction there and the rounding at most that of m dv . d), in
  /// bins of kFitBin over [1 - kFitSpan, 1 + kFitSpan].
  static constexpr double kFitPrecision = 1e-3, kFitBin = 1e-6, kFitSpan = 0.1;
  /// A ratio beyond 1 +- this is itself a failure (the row's `ratio` cause, one finding).
  static constexpr double kBiasMax = 0.01;
  /// Fewer samples than this: no ratio is fitted (ratio 1).
  static constexpr std::uint64_t kFitMinSamples = 10;
  /// The spread's fences: Tukey's far-out fences, this many interquartile ranges beyond the
  /// quartiles of the one-sided sample (docs/validation.md, "A spread of reported impulses").
  static constexpr double kSpreadFence = 3.0;
  /// A sample in bins of kFitBin over [1 - kFitSpan, 1 + kFitSpan], counts below and above.
  struct RatioSample {
    std::vector<std::uint64_t> bins;
    std::uint64_t below = 0, above = 0;
    /// Adds one value.
    void add(double s);
    /// The number of values.
    std::uint64_t total() const;
    /// The value at rank r (0-based; below the span: 1 - kFitSpan, above: 1 + kFitSpan).
    double at(std::uint64_t r) const;
  };
  /// Every body-step's s (the centre's sample) and those whose rows all push one way along d
  /// (sum |J_k . d| = |J . d| within kFitPrecision: s is a weighted mean of the rows' own
  /// ratios, the spread's sample).
  RatioSample ratio_sample, spread_sample;
  /// The fitted ratio: the sample's median (its bin's centre), quartiles, size; `fitted`
  /// when the sample has kFitMinSamples or more. The spread: the one-sided sample's quartiles
  /// and fences [lo, hi] (the centre inside), `spread` when that sample has kFitMinSamples
  /// or more. `bias` when the centre or a fence lies beyond kBiasMax of 1.
  struct BalanceFit {
    double ratio = 1, q1 = 1, q3 = 1;
    std::uint64_t samples = 0;
    bool fitted = false, bias = false;
    double spread_q1 = 1, spread_q3 = 1, lo = 1, hi = 1;
    std::uint64_t spread_samples = 0;
    bool spread = false;
    /// How far a row's 1/s may lie from the centre's inside the fences (0 without a spread).
    double row_allowance() const;
  };
  BalanceFit balance_fit() const;
  /// The linear balance's figure of a body-step at impulse ratio s: |m dv - J / s| along the
  /// residual and each disc's normal, over the discs' support there, `allow` x sum |J_k . d|
  /// of its rows' impulses J_k (the spread) and the rounding; `open_along`: the support of the
  /// worst direction.
  static double balance_figure(const D3& mdv, const D3& force, const BalanceDisc* discs, std::size_t count,
                               double float_bound, double s, double* open_along, const D3* rows = nullptr,
                               std::size_t row_count = 0, double allow = 0);
  /// balance_lin with the deferred body-steps judged at `fit` (failures where they fail at
  /// ratio 1, at fit.ratio and with each row's ratio anywhere in the spread's fences;
  /// `in_spread`: those passing only the last), and the fit's own finding (a centre or a
  /// fence beyond kBiasMax) apart.
  physics_detail::Tally fitted_balance(const BalanceFit& fit, std::uint64_t* in_spread) const;
  physics_detail::Tally balance_bias(const BalanceFit& fit) const;
};

// Every physics row of validation_rows.def has a measure (Impl::measure of every frame, or
// Impl::judge of the checked frames, as its FRAMES says) and a table entry (Impl::table),
// defined in the row's own file.
#define OCTOCD_PHYSICS_EVERY(id)                                                      \
  template <>                                                                         \
  void PhysicsValidators::Impl::measure<RowId::id>(physics_detail::PhysicsFrame & f); \
  template <>                                                                         \
  ValidationResult PhysicsValidators::Impl::table<RowId::id>() const;
#define OCTOCD_PHYSICS_CHECKED(id)                                                    \
  template <>                                                                         \
  void PhysicsValidators::Impl::judge<RowId::id>(physics_detail::CheckedFrame & f);   \
  template <>                                                                         \
  ValidationResult PhysicsValidators::Impl::table<RowId::id>() const;
#include "physics_rows.inc"

}  // namespace octocd
