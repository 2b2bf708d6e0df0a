// The physics tier (SPEC 13): any engine judged on its posed shapes with FCL, never on
// octocd's own response model (that is validation/model/). Eight rows: broadphase
// completeness, contact completeness, contact geometry, penetration (the costly,
// geometric rows, run on checked frames, O(candidate pairs) each) and friction,
// conservation, momentum balance and free flight (every frame that has states,
// O(bodies + contact rows)).
#include "octocd/physics.hpp"

#include "../src/parallel.hpp"
#include "../src/row_clock.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <map>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include <fmt/format.h>

#include "octocd/error.hpp"
#include "octocd/exact_pairs.hpp"
#include "octocd/reference_contact.hpp"
#include "dmath.hpp"
#include "reference.hpp"
#include "sat.hpp"

namespace octocd {

const char* material_combine_name(MaterialCombine c) {
  switch (c) {
    case MaterialCombine::Product: return "product";
    case MaterialCombine::Min: return "min";
    case MaterialCombine::Max: return "max";
    case MaterialCombine::Average: return "average";
    case MaterialCombine::Geometric: return "geometric";
  }
  return "product";
}

double combine_material(MaterialCombine c, double a, double b) {
  switch (c) {
    case MaterialCombine::Product: return a * b;
    case MaterialCombine::Min: return a < b ? a : b;
    case MaterialCombine::Max: return a > b ? a : b;
    case MaterialCombine::Average: return 0.5 * (a + b);
    case MaterialCombine::Geometric: return std::sqrt(a * b);
  }
  return a * b;
}

Pose detection_pose(const Model& model, const FrameRecord& rec, std::size_t i) {
  Pose p;
  if (!rec.x_det.empty()) {
    p.position = rec.x_det[i];
    if (!rec.q_det.empty()) p.orientation = rec.q_det[i];
    return p;
  }
  p.position = rec.aabbs[i].min - model.local_box(i).min;
  return p;
}

PhysicsBodies octocd_physics_bodies(const Model& model) {
  PhysicsBodies b;
  const ContactParams& p = model.scene.response;
  b.mu = p.mu_static;
  b.restitution = p.restitution;
  b.theta_margin = true;
  b.broadphase_exact = true;
  b.contact_geometry = ContactGeometry::Aabb;
  b.slop = p.slop;
  b.velocity_clamp = p.max_velocity;
  b.integrator = PhysicsBodies::Integrator::SemiImplicit;  // SPEC 4.1: v += dt g, then x += dt v
  b.jt_along_sliding = true;
  b.impulses_complete = p.iterations <= 1;
  b.jacobi_response = true;
  return b;
}

const char* contact_model_name(PhysicsBodies::ContactModel m) {
  return m == PhysicsBodies::ContactModel::Soft ? "soft" : "rigid";
}

const char* integrator_name(PhysicsBodies::Integrator i) {
  switch (i) {
    case PhysicsBodies::Integrator::SemiImplicit: return "semi-implicit";
    case PhysicsBodies::Integrator::Explicit: return "explicit";
    case PhysicsBodies::Integrator::Any: return "any";
  }
  return "semi-implicit";
}

namespace {

using namespace dmath;

constexpr double kPi = 3.14159265358979323846;
constexpr double kEps32 = 1.0 / 8388608.0;  // 2^-23
/// A relative sliding speed (m/s) below which v_t has no direction: jt is then J_t's
/// magnitude (the trace convention; octocd's Bullet adapter uses the same threshold).
constexpr double kNoSliding = 1e-6;

/// R M R^T.
M3 conjugated(const M3& r, const M3& m) {
  M3 rm{}, out{};
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j)
      for (int k = 0; k < 3; ++k) rm[3 * i + j] += r[3 * i + k] * m[3 * k + j];
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j)
      for (int k = 0; k < 3; ++k) out[3 * i + j] += rm[3 * i + k] * r[3 * j + k];
  return out;
}
/// Inverse of a symmetric positive definite 3x3 (zeros when singular).
M3 inverse(const M3& m) {
  const double c00 = m[4] * m[8] - m[5] * m[7], c01 = m[5] * m[6] - m[3] * m[8], c02 = m[3] * m[7] - m[4] * m[6];
  const double det = m[0] * c00 + m[1] * c01 + m[2] * c02;
  if (!(std::fabs(det) > 0)) return M3{};
  const double k = 1.0 / det;
  return {c00 * k, (m[2] * m[7] - m[1] * m[8]) * k, (m[1] * m[5] - m[2] * m[4]) * k,
          c01 * k, (m[0] * m[8] - m[2] * m[6]) * k, (m[2] * m[3] - m[0] * m[5]) * k,
          c02 * k, (m[1] * m[6] - m[0] * m[7]) * k, (m[0] * m[4] - m[1] * m[3]) * k};
}

std::string pair_name(Pair p) { return fmt::format("pair ({}, {})", p.a, p.b); }
std::string body_name(std::size_t i) { return fmt::format("body {}", i); }
/// "group (I, J, K)": an isolated group by its first bodies (up to 3, then "...").
std::string group_name(const std::vector<std::uint32_t>& members) {
  std::string s = "group (";
  for (std::size_t k = 0; k < members.size() && k < 3; ++k) s += (k ? ", " : "") + std::to_string(members[k]);
  return s + (members.size() > 3 ? ", ...)" : ")");
}

/// Where a judged item is: its frame and its name as expectations write it ("pair (A, B)",
/// "body I", "group (I, J, K)").
struct Where {
  std::int64_t frame = -1;
  std::string item;
};

/// One cause of a row (SPEC 13b.13): judged items, failures, the worst judged figure with
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
    ValidationExample e{where.frame, where.item, figure, what};
    if (failures == 1 || figure > worst_failure.figure) worst_failure = e;
    if (examples.size() < ValidationCause::kMaxExamples) examples.push_back(std::move(e));
    if (!where.item.empty()) {
      if (items.size() < ValidationCause::kMaxItems || items.count(where.item))
        items.insert(where.item);
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
  ValidationCause cause(const char* name, const char* unit) const {
    ValidationCause c;
    c.name = name;
    c.unit = unit;
    c.count = failures;
    c.worst = failures ? worst_failure.figure : 0.0;
    c.examples = examples;
    c.items.assign(items.begin(), items.end());
    c.items_complete = items_complete;
    return c;
  }
  /// "NAME N of M NOUN (worst W UNIT, frame F ITEM: TEXT[; first: TEXT])", or "NAME 0 of M NOUN".
  std::string summary(const char* name, const char* noun, const char* unit) const {
    if (failures == 0) return fmt::format("{} 0 of {} {}", name, checks, noun);
    std::string s = fmt::format("{} {} of {} {} (worst {:.4g} {}", name, failures, checks, noun, worst_failure.figure,
                                unit);
    if (worst_failure.frame >= 0) s += fmt::format(", frame {}", worst_failure.frame);
    if (!worst_failure.item.empty()) s += " " + worst_failure.item;
    s += ": " + worst_failure.text;
    if (!examples.empty() && examples.front().text != worst_failure.text) s += "; first: " + examples.front().text;
    return s + ")";
  }
};

/// The row's failures by cause (causes with failures only), its judged count, its verdict
/// and n/a when it judged nothing: the detail gets "; causes: ..." listing every cause.
struct CauseSpec {
  const Tally* tally;
  const char* name;
  const char* noun;
  const char* unit;
};
void fill_causes(ValidationResult& r, std::initializer_list<CauseSpec> causes) {
  std::string list;
  std::uint64_t failing = 0, judged = 0;
  for (const CauseSpec& c : causes) {
    judged += c.tally->checks;
    if (c.tally->failures) {
      r.causes.push_back(c.tally->cause(c.name, c.unit));
      ++failing;
    }
    list += (list.empty() ? "" : "; ") + c.tally->summary(c.name, c.noun, c.unit);
  }
  r.judged = judged;
  if (failing) {
    r.pass = false;
    r.detail += "; causes: " + list;
  }
}

}  // namespace

struct PhysicsValidators::Impl {
  const Model* model = nullptr;
  PhysicsBodies bodies;
  Tolerances tol;
  std::string label;
  std::unique_ptr<ReferenceGeometry> ref;
  std::vector<M3> inertia;  // body frame
  std::vector<double> mass;  // 0 for static bodies
  double max_margin = 0;
  bool restitution_le_1 = true;

  // Rows.
  Tally broad, broad_exact, complete, false_contact, normal_angle, depth, points, pen, cone, dissipation;
  Tally momentum, angular, energy;
  Tally balance_lin, balance_ang, free_vel, free_pos, free_w, free_q;
  std::uint64_t balance_clamped = 0, balance_no_rows = 0, balance_locked = 0, free_locked = 0, balance_rot_locked = 0;
  double t_balance = 0;
  std::uint64_t broad_frames = 0, broad_candidates = 0, broad_true = 0, broad_no_pairs = 0;
  std::uint64_t checked_frames = 0, rows_unjudged = 0, upper_bound_pairs = 0;
  std::uint64_t sign_rows = 0, sign_agree = 0, shape_angle_rows = 0;
  std::vector<double> shape_angles;  // Aabb geometry: angle to the posed shapes (figure)
  std::uint64_t aabb_angle_rows = 0;  // Aabb geometry: rows compared with box-box on the AABBs (figure)
  double aabb_angle_worst = 0;
  std::uint64_t speculative_rows = 0;  // rows on shapes that do not penetrate (figure)
  // Contact geometry's references: pairs judged by the separating-axis test and by FCL;
  // where FCL's normal lies outside SAT's accepted axes (figure: FCL's box-box keeps a
  // face axis up to 5% deeper than the minimum).
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
  double pen_max = 0, pen_upper_max = 0;
  std::string pen_what, pen_upper_what;
  std::uint64_t pen_upper_over = 0;
  std::uint64_t pen_pairs = 0, pen_upper_pairs = 0;
  std::int64_t last_frame = 0;
  std::function<bool()> stop;  // polled inside the long loops (set_stop)
  int threads = 0;              // set_threads (0: the hardware's)
  // Each row's own time (s): RowClock around its work; shared work goes to the first row
  // that needs it (the candidates and FCL truth of every pair: broadphase-completeness).
  double t_broad = 0, t_complete = 0, t_geometry = 0, t_pen = 0, t_friction = 0, t_conservation = 0;

  double pair_margin(Pair p) const {
    if (!bodies.theta_margin) return bodies.contact_margin;
    return model->theta(model->bodies[p.a].shape, model->bodies[p.b].shape);
  }
  double pair_mu(Pair p) const {
    if (bodies.body_friction.empty()) return bodies.mu;
    return combine_material(bodies.combine, bodies.body_friction[p.a], bodies.body_friction[p.b]);
  }
  bool dynamic(std::uint32_t i) const { return mass[i] > 0; }

  void geometry(const FrameRecord& rec, const std::vector<Pose>& det);
  /// Dissipation of pair p's rows [k0, k1) from their tangential impulse vectors (jt3).
  void judge_pair_friction(const FrameRecord& rec, const std::vector<Pose>& det, Pair p, std::size_t k0,
                           std::size_t k1);
  void dynamics(const FrameRecord& rec, const std::vector<Pose>& det);
  void balance(const FrameRecord& rec, const std::vector<Pose>& det);
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
  /// A contact episode of an isolated group (contact_model soft): its dynamic bodies
  /// (sorted), from its first contact step until none of them touches another; energy and
  /// kinetic energy at the start (a body joining later: at the step it joins).
  struct Episode {
    std::int64_t start = 0;
    std::vector<std::uint32_t> bodies;
    double e0 = 0, ke0 = 0, scale = 0;
    bool spoiled = false;
  };
  std::vector<Episode> episodes;  // contact_model soft: open episodes
  std::uint64_t episodes_judged = 0, episodes_judged_groups = 0, episodes_unjudged = 0, energy_soft_steps = 0;
  std::uint64_t groups_locked = 0, groups_rotation_locked = 0;
};

PhysicsValidators::PhysicsValidators(const Model& model, const PhysicsBodies& bodies, const Tolerances& tol,
                                     std::string label)
    : impl_(std::make_unique<Impl>()) {
  Impl& s = *impl_;
  s.model = &model;
  s.bodies = bodies;
  s.tol = tol;
  s.label = std::move(label);
  const std::size_t n = model.bodies.size();
  auto bad = [&](const std::string& field, const std::string& what) {
    throw InputError(fmt::format("physics validators ({}): PhysicsBodies.{}: {}", s.label, field, what));
  };
  if (!bodies.inertia.empty() && bodies.inertia.size() != n)
    bad("inertia", fmt::format("{} tensors for {} bodies; allowed: 0 (derived) or {}", bodies.inertia.size(), n, n));
  if (!bodies.body_friction.empty() && bodies.body_friction.size() != n)
    bad("body_friction", fmt::format("{} values for {} bodies; allowed: 0 or {}", bodies.body_friction.size(), n, n));
  if (!bodies.body_restitution.empty() && bodies.body_restitution.size() != n)
    bad("body_restitution",
        fmt::format("{} values for {} bodies; allowed: 0 or {}", bodies.body_restitution.size(), n, n));
  for (std::size_t i = 0; i < bodies.body_friction.size(); ++i)
    if (!(bodies.body_friction[i] >= 0) || !std::isfinite(bodies.body_friction[i]))
      bad("body_friction", fmt::format("body {}: {}; allowed: finite >= 0", i, bodies.body_friction[i]));
  for (std::size_t i = 0; i < bodies.body_restitution.size(); ++i)
    if (!(bodies.body_restitution[i] >= 0) || !std::isfinite(bodies.body_restitution[i]))
      bad("body_restitution", fmt::format("body {}: {}; allowed: finite >= 0", i, bodies.body_restitution[i]));
  if (!(bodies.mu >= 0) || !std::isfinite(bodies.mu)) bad("mu", fmt::format("{}; allowed: finite >= 0", bodies.mu));
  if (!(bodies.restitution >= 0) || !std::isfinite(bodies.restitution))
    bad("restitution", fmt::format("{}; allowed: finite >= 0", bodies.restitution));
  if (!(bodies.contact_margin >= 0) || !std::isfinite(bodies.contact_margin))
    bad("contact_margin", fmt::format("{}; allowed: finite >= 0 m", bodies.contact_margin));
  if (!bodies.locked_dofs.empty() && bodies.locked_dofs.size() != n)
    bad("locked_dofs", fmt::format("{} values for {} bodies; allowed: 0 or {}", bodies.locked_dofs.size(), n, n));
  for (std::size_t i = 0; i < bodies.locked_dofs.size(); ++i)
    if (bodies.locked_dofs[i] > 63)
      bad("locked_dofs", fmt::format("body {}: {}; allowed: 0 .. 63 (6 bits)", i, unsigned(bodies.locked_dofs[i])));
  if (!(bodies.slop >= 0) || !std::isfinite(bodies.slop))
    bad("slop", fmt::format("{}; allowed: finite >= 0 m", bodies.slop));

  s.mass.assign(n, 0.0);
  s.inertia.assign(n, M3{});
  for (std::size_t i = 0; i < n; ++i) {
    const float w = model.initial.w[i];
    if (!(w > 0.0f)) continue;
    s.mass[i] = 1.0 / w;
    if (!bodies.inertia.empty()) {
      s.inertia[i] = bodies.inertia[i];
      for (double v : s.inertia[i])
        if (!std::isfinite(v)) bad("inertia", fmt::format("body {}: not finite", i));
    } else {
      // A solid box of the local AABB (Bullet's rule for convex shapes).
      const Aabb& b = model.local_box(i);
      const double a = b.max.x - b.min.x, bb = b.max.y - b.min.y, c = b.max.z - b.min.z;
      const double k = s.mass[i] / 12.0;
      s.inertia[i] = M3{k * (bb * bb + c * c), 0, 0, 0, k * (a * a + c * c), 0, 0, 0, k * (a * a + bb * bb)};
    }
  }
  if (bodies.body_restitution.empty()) {
    s.restitution_le_1 = bodies.restitution <= 1.0;
  } else {
    // The largest pair value of any rule is at most the largest body value, or its square.
    double r = 0;
    for (float v : bodies.body_restitution) r = std::max(r, double(v));
    s.restitution_le_1 = combine_material(bodies.restitution_combine, r, r) <= 1.0 && r <= 1.0;
  }
  s.max_margin = bodies.contact_margin;
  if (bodies.theta_margin) {
    s.max_margin = 0;
    for (float t : model.theta_shape) s.max_margin = std::max(s.max_margin, double(t));
  }
  if (!bodies.collision_shape.empty()) {
    if (bodies.collision_shape.size() != n)
      bad("collision_shape", fmt::format("{} values for {} bodies; allowed: 0 (every body as its shape) or {}",
                                         bodies.collision_shape.size(), n, n));
    for (std::size_t i = 0; i < n; ++i)
      if (bodies.collision_shape[i] == CollisionShape::Sphere && !model.shapes[model.bodies[i].shape].mesh)
        bad("collision_shape", fmt::format("body {}: \"sphere\" on a box shape (a box cannot be collided as a "
                                           "sphere); allowed for a box: \"mesh\", \"convex_hull\", \"box\" (each the "
                                           "box itself)",
                                           i));
  }
  s.ref = std::make_unique<ReferenceGeometry>(model, bodies.collision_shape);
  for (std::size_t i = 0; i < bodies.collision_shape.size(); ++i) {
    const CollisionShape c = bodies.collision_shape[i];
    if (c == CollisionShape::Mesh) continue;
    auto& [count, gap] = s.declared[collision_shape_name(c)];
    ++count;
    gap = std::max(gap, s.ref->declared_gap(static_cast<std::uint32_t>(i)));
  }
  s.sat_settings.abs_m = tol.geometry_slack_m;
  s.sat_settings.rel = tol.sat_accept_rel;
}

PhysicsValidators::~PhysicsValidators() = default;

void PhysicsValidators::set_stop(std::function<bool()> stop) { impl_->stop = std::move(stop); }

void PhysicsValidators::set_threads(int threads) { impl_->threads = threads; }

void PhysicsValidators::observe(const FrameRecord& rec, bool checked) {
  Impl& s = *impl_;
  const std::size_t n = s.model->bodies.size();
  s.last_frame = rec.frame;
  std::vector<Pose> det(n);
  const bool poses = !rec.x_det.empty() || rec.aabbs.size() == n;
  if (poses) {
    for (std::size_t i = 0; i < n; ++i) det[i] = detection_pose(*s.model, rec, i);
  } else if (rec.x_pre.size() == n) {
    // No detection pose: the pre-step pose serves the contact-point lever arms.
    for (std::size_t i = 0; i < n; ++i) det[i] = Pose{rec.x_pre[i], rec.q_pre.size() == n ? rec.q_pre[i] : Quat{}};
  }
  if (checked && poses) s.geometry(rec, det);
  s.dynamics(rec, det);
  s.balance(rec, det);
}

// ---- Rows 1-4: the geometric rows, on checked frames ------------------------------
void PhysicsValidators::Impl::geometry(const FrameRecord& rec, const std::vector<Pose>& det) {
  const Model& m = *model;
  const std::size_t n = m.bodies.size();
  const std::int64_t frame = rec.frame;
  const double slack = tol.geometry_slack_m;
  ++checked_frames;
  StopPoll poll(stop);
  std::optional<RowClock> clock(std::in_place, t_broad);  // candidates, truth, row 1

  // Candidates: exact posed world AABBs, each grown by half the largest distance any row
  // asks about, through exact_pairs (flat's set in O(n log n + pairs), independent of
  // octocd's broadphases): every pair whose shapes are that close has overlapping grown
  // boxes (the AABB gap is at most the shapes' distance).
  const double reach = std::max(tol.broadphase_margin_m, max_margin) + slack;
  std::vector<Aabb> grown(n);
  for (std::size_t i = 0; i < n; ++i)
    grown[i] = expanded(ref->world_aabb(static_cast<std::uint32_t>(i), det[i]), static_cast<float>(0.5 * reach));
  std::vector<Pair> cand;
  ExactPairsSettings pair_threads;
  pair_threads.threads = threads;
  exact_pairs(grown, cand, pair_threads);
  cand.erase(std::remove_if(cand.begin(), cand.end(), [&](Pair p) { return !dynamic(p.a) && !dynamic(p.b); }),
             cand.end());

  // Truth per pair, lazily: intersect() for every candidate, posed() where a row needs
  // the depth or the distance.
  // Two convex shapes (boxes, convex meshes) that penetrate get the exact minimum
  // translation of the separating-axis test (SPEC 13b.9: FCL's box-box keeps a face axis
  // up to 5% deeper than an edge-edge one, so its depth and normal are not the minimum
  // there); FCL's answer stays beside it as the second opinion.
  struct Truth : PairReference {  // reference.hpp: g, sat, sat_result, fcl
    bool intersects = false, have = false;
  };
  std::map<std::pair<std::uint32_t, std::uint32_t>, Truth> truth;
  auto key = [](Pair p) { return std::make_pair(p.a, p.b); };
  // One pair's truth (const, thread-safe: ReferenceGeometry's queries build their FCL
  // objects locally).
  auto compute_truth = [&](Pair p, Truth& t) {
    static_cast<PairReference&>(t) = pair_reference(*ref, p.a, p.b, det[p.a], det[p.b], sat_settings);
    t.have = true;
    t.intersects = t.g.penetrating;
  };
  auto full_truth = [&](Pair p) -> const Truth& {
    Truth& t = truth[key(p)];
    if (!t.have) compute_truth(p, t);
    return t;
  };
  auto full = [&](Pair p) -> const ReferenceNormal& { return full_truth(p).g; };
  const bool need_distance = tol.broadphase_margin_m - slack > 0;

  // Contact rows per pair (rows of a pair are consecutive).
  struct PairRows {
    Pair p;
    std::size_t first = 0, count = 0;
  };
  std::vector<PairRows> rows;
  for (std::size_t k = 0; k < rec.contacts.size(); ++k) {
    const Pair p = rec.contacts[k].pair;
    if (!rows.empty() && rows.back().p == p && rows.back().first + rows.back().count == k) {
      ++rows.back().count;
    } else {
      rows.push_back({p, k, 1});
    }
  }
  std::vector<Pair> contact_pairs;
  for (const PairRows& r : rows) contact_pairs.push_back(r.p);
  std::sort(contact_pairs.begin(), contact_pairs.end());

  // The truth the rows below read, on `threads` threads (parallel_items): every candidate
  // that intersects (or, with a broadphase margin, every candidate) and every contact
  // pair; the rows then read it in their own order, so their verdicts, causes and
  // examples are those of a serial run.
  std::vector<char> hit(cand.size(), 1);
  if (!need_distance)
    parallel_items(cand.size(), threads, stop, [&](std::size_t i, unsigned) {
      hit[i] = ref->intersect(cand[i].a, cand[i].b, det[cand[i].a], det[cand[i].b]) ? 1 : 0;
    });
  {
    std::vector<Pair> todo;
    for (std::size_t i = 0; i < cand.size(); ++i)
      if (hit[i]) todo.push_back(cand[i]);
    std::vector<Pair> all;
    std::set_union(todo.begin(), todo.end(), contact_pairs.begin(), contact_pairs.end(), std::back_inserter(all));
    all.erase(std::unique(all.begin(), all.end()), all.end());
    std::vector<Truth> computed(all.size());
    parallel_items(all.size(), threads, stop, [&](std::size_t i, unsigned) { compute_truth(all[i], computed[i]); });
    for (std::size_t i = 0; i < all.size(); ++i) truth.emplace_hint(truth.end(), key(all[i]), std::move(computed[i]));
  }
  std::vector<Pair> required;
  for (std::size_t i = 0; i < cand.size(); ++i) {
    const Pair p = cand[i];
    poll();
    bool close = false;
    if (need_distance) {
      close = full(p).signed_distance() < tol.broadphase_margin_m - slack;
    } else if (hit[i]) {
      const ReferenceNormal& g = full(p);
      close = g.penetrating && -g.depth < tol.broadphase_margin_m - slack;
    }
    if (close) required.push_back(p);
  }

  // 1. Broadphase completeness.
  if (!rec.has_pairs) {
    ++broad_no_pairs;
  } else {
    ++broad_frames;
    broad_candidates += rec.pairs.size();
    broad_true += required.size();
    for (const Pair& p : required) {
      const bool found = std::binary_search(rec.pairs.begin(), rec.pairs.end(), p);
      const ReferenceNormal& g = full(p);
      broad.check(found, g.penetrating ? g.depth : -g.distance, Where{frame, pair_name(p)}, [&] {
        return fmt::format("frame {}: {} misses {} whose shapes are {} {:.3g} m (margin {} m)", frame, label,
                           pair_name(p), g.penetrating ? "penetrating by" : "apart by",
                           g.penetrating ? g.depth : g.distance, tol.broadphase_margin_m);
      });
    }
    if (bodies.broadphase_exact) {
      // Set equality with `flat` on the engine's own world AABBs, static-static dropped:
      // flat's set through exact_pairs (O(n log n + pairs); tests/unit/test_exact_pairs).
      std::vector<Pair> want, got;
      exact_pairs(rec.aabbs, want, pair_threads);
      auto dyn = [&](Pair p) { return dynamic(p.a) || dynamic(p.b); };
      std::copy_if(want.begin(), want.end(), std::back_inserter(got), dyn);
      want.swap(got);
      got.clear();
      std::copy_if(rec.pairs.begin(), rec.pairs.end(), std::back_inserter(got), dyn);
      std::vector<Pair> missing, extra;
      std::set_difference(want.begin(), want.end(), got.begin(), got.end(), std::back_inserter(missing));
      std::set_difference(got.begin(), got.end(), want.begin(), want.end(), std::back_inserter(extra));
      const bool same = missing.empty() && extra.empty();
      const Pair first_diff = !missing.empty() ? missing.front() : !extra.empty() ? extra.front() : Pair{};
      broad_exact.check(same, double(missing.size() + extra.size()),
                        Where{frame, same ? std::string() : pair_name(first_diff)}, [&] {
        if (same) return fmt::format("frame {}: equal to flat", frame);
        const Pair q = !missing.empty() ? missing.front() : extra.front();
        // Pairs whose boxes only touch (zero overlap on an axis) are pairs under the
        // inclusive rule of Eq. 6; an engine with a strict test misses exactly those.
        const bool all_touch = !missing.empty() && std::all_of(missing.begin(), missing.end(), [&](Pair mp) {
          for (int k = 0; k < 3; ++k)
            if (std::min(rec.aabbs[mp.a].max[k], rec.aabbs[mp.b].max[k]) ==
                std::max(rec.aabbs[mp.a].min[k], rec.aabbs[mp.b].min[k]))
              return true;
          return false;
        });
        return fmt::format("frame {}: {} declares an exact AABB broadphase but {} {} of flat on its world "
                           "AABBs ({} missing, {} extra){}",
                           frame, label, missing.empty() ? "adds" : "misses", pair_name(q), missing.size(),
                           extra.size(),
                           all_touch ? "; the missing pairs only touch (zero overlap on an axis): overlap is "
                                       "inclusive (Eq. 6), min_A <= max_B and max_A >= min_B"
                                     : "");
      });
    }
  }

  // 2. Contact completeness: penetrating pairs need a contact; contacts need closeness.
  clock.emplace(t_complete);
  for (const Pair& p : cand) {
    auto it = truth.find(key(p));
    if (it == truth.end() || !it->second.have || !it->second.g.penetrating) continue;
    const ReferenceNormal& g = it->second.g;
    if (!(g.depth > tol.contact_depth_m)) continue;
    const bool found = std::binary_search(contact_pairs.begin(), contact_pairs.end(), p);
    complete.check(found, g.depth, Where{frame, pair_name(p)}, [&] {
      return fmt::format("frame {}: {} penetrates by {:.4g} m{} and has no contact", frame, pair_name(p), g.depth,
                         g.depth_upper_bound ? " (upper bound: non-convex mesh)" : "");
    });
  }
  for (const Pair& p : contact_pairs) {
    poll();
    const ReferenceNormal& g = full(p);
    const double bound = pair_margin(p) + slack;
    const double d = g.signed_distance();
    false_contact.check(d <= bound, d - bound, Where{frame, pair_name(p)}, [&] {
      return fmt::format("frame {}: false contact on {}: shapes {:.4g} m apart (margin {:.4g} m)", frame,
                         pair_name(p), d, pair_margin(p));
    });
  }

  // 3. Contact geometry, per row: normal angle, the pair's deepest row's depth, points.
  clock.emplace(t_geometry);
  const double deg = 180.0 / kPi;
  for (const PairRows& pr : rows) {
    poll();
    const Pair p = pr.p;
    const Truth& shape_truth = full_truth(p);
    const ReferenceNormal& shape_ref = shape_truth.g;
    const bool aabb = bodies.contact_geometry == ContactGeometry::Aabb;
    // The reference that judges this pair: the separating-axis test (every near-minimal
    // axis accepted) or FCL (box-box, EPA, or the BVH bound of non-convex meshes).
    const bool by_sat = !aabb && shape_truth.sat;
    const char* judge = by_sat ? "SAT" : "FCL";
    if (by_sat) {
      ++sat_pairs;
      // The second opinion: FCL's normal outside SAT's accepted axes is a figure.
      const double fcl_angle = sat_angle_to_accepted(shape_truth.sat_result, d3(shape_truth.fcl.normal)) * 180.0 / kPi;
      const double fcl_excess = shape_truth.fcl.depth - shape_truth.g.depth;
      if (angle_between(shape_truth.fcl.normal, shape_truth.g.normal) * 180.0 / kPi > 1.0) {
        ++sat_fcl_other;
        if (fcl_excess > sat_fcl_other_excess) sat_fcl_other_excess = fcl_excess;
      }
      if (fcl_angle > 1.0) {
        ++sat_fcl_disagree;
        if (fcl_excess > sat_fcl_worst_excess) {
          sat_fcl_worst_excess = fcl_excess;
          sat_fcl_what = fmt::format("frame {}: {} FCL {:.4g} m along ({:.3f}, {:.3f}, {:.3f}), {:.1f} deg from "
                                     "SAT's accepted axes, minimum {:.4g} m",
                                     frame, pair_name(p), shape_truth.fcl.depth, shape_truth.fcl.normal.x,
                                     shape_truth.fcl.normal.y, shape_truth.fcl.normal.z, fcl_angle,
                                     shape_truth.g.depth);
        }
      }
    } else if (!aabb) {
      ++fcl_pairs;
    }
    const ReferenceNormal r = aabb ? ReferenceGeometry::aabb_pair(rec.aabbs[p.a], rec.aabbs[p.b]) : shape_ref;
    if (!r.valid) {
      rows_unjudged += pr.count;
      continue;
    }
    if (r.depth_upper_bound) ++upper_bound_pairs;
    std::size_t deepest = pr.first;
    for (std::size_t k = pr.first; k < pr.first + pr.count; ++k)
      if (rec.contacts[k].depth > rec.contacts[deepest].depth) deepest = k;
    // The engine places the pair's penetration in some rows of its manifold: a row of
    // depth 0 (or within geometry_slack_m) beside a deeper one is a point the manifold
    // keeps at or out of contact (a persistent manifold keeps a point, with the normal it
    // was found with, while the bodies turn, until it drifts beyond the breaking
    // threshold: Bullet on rot-pile-1000 kept a row 73 deg off for a cube pair that
    // penetrated 0.05 mm at another row, and one 41.5 deg off at depth 4.8e-6 m beside a
    // fresh row of 0.53 mm on the minimum translation).
    const bool engine_places_depth = rec.contacts[deepest].depth > tol.geometry_slack_m;
    for (std::size_t k = pr.first; k < pr.first + pr.count; ++k) {
      const ContactRecord& c = rec.contacts[k];
      const RowReference row_ref = row_reference(shape_truth, r, by_sat, c.normal);
      const double angle = row_ref.angle * deg;
      const Vec3 ref_normal = row_ref.normal;
      ++sign_rows;
      if (dot(c.normal, r.normal) > 0.0f) ++sign_agree;
      // A row the engine places at depth 0 on a pair that penetrates less than
      // contact_depth_m (which needs no contact at all, item 2) is a touching contact:
      // two boxes grazing edge on edge by 30 um have a minimum translation 60 deg from
      // the face normal Bullet's detector keeps at depth 0 (rot-pile-1000).
      const bool touching = c.depth <= 0.0f && r.depth <= tol.contact_depth_m;
      if (!r.penetrating || r.depth <= tol.geometry_slack_m || touching ||
          (engine_places_depth && c.depth <= tol.geometry_slack_m)) {
        // A row on shapes that do not penetrate (or out of contact, above): the
        // nearest-points direction of two shapes that (nearly) touch at an edge or a
        // corner is no contact normal, and a persistent manifold (Bullet) keeps the normal
        // a point was found with while the bodies turn. Its angle is a figure; the normal
        // is judged where the shapes penetrate (the minimum translation, which a correct
        // engine's normal follows).
        ++speculative_rows;
        speculative_worst = std::max(speculative_worst, angle);
      } else if (aabb) {
        // The engine's normal is an axis of the two world AABBs (Eq. 10): compared with
        // FCL box-box on the same boxes its angle says nothing about the shapes (a
        // figure; the angle to the posed shapes is the other figure, below). Its sign is
        // judged: a normal pointing from A to B pushes the bodies into each other.
        ++aabb_angle_rows;
        aabb_angle_worst = std::max(aabb_angle_worst, angle);
        normal_angle.check(angle < 90.0, angle, Where{frame, pair_name(p)}, [&] {
          return fmt::format("frame {}: {} row {}: normal ({:.3f}, {:.3f}, {:.3f}) points against the world AABBs' "
                             "minimum translation ({:.3f}, {:.3f}, {:.3f}): {:.1f} deg (sign judged only: the engine "
                             "resolves on world AABBs)",
                             frame, pair_name(p), k - pr.first, c.normal.x, c.normal.y, c.normal.z, r.normal.x,
                             r.normal.y, r.normal.z, angle);
        });
      } else {
        normal_angle.check(angle <= tol.normal_angle_deg, angle, Where{frame, pair_name(p)}, [&] {
          return fmt::format("frame {}: {} row {}: normal ({:.3f}, {:.3f}, {:.3f}) is {:.1f} deg from {}'s "
                             "({:.3f}, {:.3f}, {:.3f}) ({}){}",
                             frame, pair_name(p), k - pr.first, c.normal.x, c.normal.y, c.normal.z, angle, judge,
                             ref_normal.x, ref_normal.y, ref_normal.z,
                             aabb     ? "box-box on the world AABBs, minimum translation"
                             : by_sat ? fmt::format("the nearest of {} axes within {:.3g} m of the minimum "
                                                    "translation {:.4g} m",
                                                    shape_truth.sat_result.accepted.size(),
                                                    shape_truth.sat_result.epsilon, r.depth)
                                      : std::string("minimum translation"),
                             by_sat ? " [reference: SAT]" : " [reference: FCL]");
        });
      }
      if (aabb && shape_ref.valid) {
        ++shape_angle_rows;
        shape_angles.push_back(angle_between(c.normal, shape_ref.normal) * deg);
      }
      if (rec.has_points) {
        // A row's point lies on one of the two surfaces (a witness point), or between
        // them (a midpoint: within the pair's depth or distance of each, since any point
        // of the intersection is within the depth of both surfaces; a persistent
        // manifold's row may be up to the contact margin apart, its midpoint half of it
        // from each). So the nearer surface is at most that far.
        // Both surfaces: a point is where the two bodies meet, so it lies within the
        // pair's depth or distance (or the contact margin, for a persistent manifold's
        // row) of each; a point placed with a wrong orientation leaves at least one.
        const double reach_p =
            std::max({r.penetrating ? r.depth : r.distance, double(c.depth), pair_margin(p)});
        const double da = ref->surface_distance(p.a, det[p.a], c.point);
        const double db = ref->surface_distance(p.b, det[p.b], c.point);
        const double off = std::max(da, db) - reach_p;
        points.check(off <= tol.depth_m, off, Where{frame, pair_name(p)}, [&] {
          return fmt::format("frame {}: {} row {}: point ({:.4f}, {:.4f}, {:.4f}) is {:.4g} m from body {} "
                             "and {:.4g} m from body {} (depth or distance {:.4g} m)",
                             frame, pair_name(p), k - pr.first, c.point.x, c.point.y, c.point.z, da, p.a, db, p.b,
                             reach_p);
        });
      }
    }
    const ContactRecord& c = rec.contacts[deepest];
    const double want = r.penetrating ? r.depth : 0.0;
    // An upper bound (non-convex meshes) judges one side only: the engine may be shallower.
    const double diff = r.depth_upper_bound ? double(c.depth) - want : std::fabs(double(c.depth) - want);
    depth.check(diff <= tol.depth_m, diff, Where{frame, pair_name(p)}, [&] {
      return fmt::format("frame {}: {} deepest row depth {:.4g} m, {} {:.4g} m{} [reference: {}]", frame,
                         pair_name(p), c.depth, by_sat ? "SAT minimum" : "FCL", want,
                         r.depth_upper_bound ? " (upper bound)" : "", judge);
    });
  }

  // 4. Penetration: the largest true penetration after the settling window.
  clock.emplace(t_pen);
  if (double(frame) >= tol.penetration_settle_frames) {
    const double pen_bound = tol.penetration_slops * bodies.slop;
    for (auto& [k, t] : truth) {
      if (!t.have) continue;
      const Pair p{k.first, k.second};
      if (!t.g.penetrating) {  // exactly apart (or touching): judged at depth 0
        pen.check(true, 0.0, Where{frame, pair_name(p)}, [] { return std::string(); });
        continue;
      }
      ++pen_pairs;
      // A non-convex pair's depth is an upper bound (the least separating translation
      // over 8 directions): it cannot prove a penetration beyond the bound, so it is a
      // figure; exact depths (boxes, convex shapes) are judged.
      if (t.g.depth_upper_bound) {
        if (t.g.depth > pen_upper_max) {
          pen_upper_max = t.g.depth;
          pen_upper_what = fmt::format("frame {}: pair ({}, {}) {:.4g} m", frame, k.first, k.second, t.g.depth);
        }
        if (t.g.depth > pen_bound) ++pen_upper_over;
        ++pen_upper_pairs;
        continue;
      }
      if (t.g.depth > pen_max) {
        pen_max = t.g.depth;
        pen_what = fmt::format("frame {}: pair ({}, {}) penetrates by {:.4g} m", frame, k.first, k.second,
                               t.g.depth);
      }
      const double d = t.g.depth;
      pen.check(d <= pen_bound, d, Where{frame, pair_name(p)}, [&] {
        return fmt::format("frame {}: {} penetrates by {:.4g} m (bound {:.4g} m)", frame, pair_name(p), d,
                           pen_bound);
      });
    }
  }
}

void PhysicsValidators::Impl::judge_pair_friction(const FrameRecord& rec, const std::vector<Pose>& det, Pair p,
                                                  std::size_t k0, std::size_t k1) {
  const std::size_t n = model->bodies.size();
  const D3 g = d3(model->scene.gravity);
  const double dt = model->scene.dt;
  auto w_of = [&](const std::vector<Vec3>& w, std::size_t i) { return w.size() == n ? d3(w[i]) : D3{}; };
  auto v_int = [&](std::uint32_t i) { return dynamic(i) ? d3(rec.v_pre[i]) + dt * g : d3(rec.v_pre[i]); };
  const D3 xa = d3(det[p.a].position), xb = d3(det[p.b].position);
  // Three states of the bodies' velocities: before the solver (after gravity), with the
  // pair's normal impulses alone applied (rotating records with points), after the step.
  struct Vel {
    D3 va, wa, vb, wb;
  };
  const Vel before{v_int(p.a), w_of(rec.w_pre, p.a), v_int(p.b), w_of(rec.w_pre, p.b)};
  const Vel after{d3(rec.v_post[p.a]), w_of(rec.w_post, p.a), d3(rec.v_post[p.b]), w_of(rec.w_post, p.b)};
  Vel normal = before;
  const bool coupled = rec.w_pre.size() == n && rec.has_points;
  if (coupled) {
    const M3 ia = dynamic(p.a) ? conjugated(rotation(det[p.a].orientation), inverse(inertia[p.a])) : M3{};
    const M3 ib = dynamic(p.b) ? conjugated(rotation(det[p.b].orientation), inverse(inertia[p.b])) : M3{};
    for (std::size_t k = k0; k < k1; ++k) {
      const ContactRecord& c = rec.contacts[k];
      const D3 j = double(c.jn) * d3(c.normal), pt = d3(c.point);
      if (dynamic(p.a)) {
        normal.va = normal.va + (1.0 / mass[p.a]) * j;
        normal.wa = normal.wa + mul(ia, cross3(pt - xa, j));
      }
      if (dynamic(p.b)) {
        normal.vb = normal.vb - (1.0 / mass[p.b]) * j;
        normal.wb = normal.wb - mul(ib, cross3(pt - xb, j));
      }
    }
  }
  // The friction impulses' mean push along the sliding at the rows' points (m/s):
  // sum_k jt3_k . v_t,k / sum_k |jt3_k|; the largest tangential speed at a row.
  auto push = [&](const Vel& v, double& fastest) {
    double work = 0, impulse = 0;
    fastest = 0;
    for (std::size_t k = k0; k < k1; ++k) {
      const ContactRecord& c = rec.contacts[k];
      const D3 nrm = d3(c.normal), j = d3(rec.jt3[k]);
      const D3 ra = rec.has_points ? d3(c.point) - xa : D3{}, rb = rec.has_points ? d3(c.point) - xb : D3{};
      const D3 rel = (v.va + cross3(v.wa, ra)) - (v.vb + cross3(v.wb, rb));
      const D3 vt = rel - dot3(rel, nrm) * nrm;
      work += dot3(j, vt);
      impulse += len3(j);
      fastest = std::max(fastest, len3(vt));
    }
    return impulse > 0 ? work / impulse : 0.0;
  };
  double impulse = 0, jn_sum = 0, gap = 0;
  D3 j_sum{};
  for (std::size_t k = k0; k < k1; ++k) {
    const ContactRecord& c = rec.contacts[k];
    impulse += len3(d3(rec.jt3[k]));
    j_sum = j_sum + d3(rec.jt3[k]);
    jn_sum += double(c.jn);
    if (rec.has_points && (len3(after.wa) + len3(after.wb)) > 0)
      gap = std::max(gap, std::max(double(c.depth), ref->surface_distance(p.a, det[p.a], c.point) +
                                                        ref->surface_distance(p.b, det[p.b], c.point)));
  }
  // No friction impulse (within float rounding of the normal impulses): nothing to judge.
  if (!(impulse > 16.0 * kEps32 * jn_sum + 1e-12)) {
    dissipation.judged();
    return;
  }
  // A friction impulse up to friction_cone_abs is a sequential-impulse solver's leftover
  // (warm start, clamped rows) and is not judged on its direction (Bullet: 2 pairs of
  // rot-drop-220 and 2 of rot-pile-1000, sum |jt3| 0.96e-3 - 0.99e-3 kg m/s, on a body
  // landing with a tiny normal impulse while sliding at 0.5 m/s). Counted.
  if (impulse <= tol.friction_cone_abs) {
    ++dissipation_small;
    return;
  }
  ++dissipation_jt3_pairs;
  double fast0 = 0, fastn = 0, fast1 = 0;
  const double along0 = push(before, fast0), alongn = coupled ? push(normal, fastn) : along0, along1 = push(after, fast1);
  // Coulomb friction opposes the sliding. A discrete solver takes the sliding before its
  // impulses (an explicit friction direction: Bullet's lateral friction direction is the
  // relative velocity when the row is set up), after the normal impulses, or after the
  // step (the maximal-dissipation condition of an implicit solve); the sliding turns
  // between them (a box landing on an edge spins). The friction is judged against all
  // three and fails when it pushes the points along their sliding in every one.
  const double along = std::min({along0, alongn, along1});
  const double allowance = (len3(after.wa) + len3(after.wb)) * gap;
  const std::int64_t frame = rec.frame;
  dissipation.check(along <= tol.friction_speed + allowance, along, Where{frame, pair_name(p)}, [&] {
    return fmt::format("frame {}: {} ({} rows): the friction impulse (sum jt3 ({:.4g}, {:.4g}, {:.4g}) kg m/s) "
                       "pushes the contact points along their sliding: {:.4g} m/s along the impulses before the "
                       "step, {:.4g} with the normal impulses, {:.4g} after it (largest tangential speed at a row "
                       "{:.6g} -> {:.6g} m/s; witness-point allowance {:.3g} m/s) [rule: jt3]",
                       frame, pair_name(p), k1 - k0, j_sum[0], j_sum[1], j_sum[2], along0, alongn, along1, fast0,
                       fast1, allowance);
  });
}

// ---- Rows 5-6: friction and conservation, every frame ------------------------------
void PhysicsValidators::Impl::dynamics(const FrameRecord& rec, const std::vector<Pose>& det) {
  const Model& m = *model;
  const std::size_t n = m.bodies.size();
  const std::int64_t frame = rec.frame;
  const D3 g = d3(m.scene.gravity);
  const double dt = m.scene.dt;
  StopPoll poll(stop);
  std::optional<RowClock> clock(std::in_place, t_friction);  // rows 5a-5b

  // 5a. The cone, per pair: a pair's rows together (a manifold is one contact patch):
  // |sum J_t| <= mu sum jn. A sequential-impulse solver clamps each row's friction by that
  // row's normal impulse (Bullet: |lateral impulse| <= mu jn of its row after the normal
  // rows of each iteration), so the patch's friction is within the cone of its total
  // normal impulse. Rules:
  //  - jt3 (the tangential impulse vectors): |sum_k jt3_k| <= mu sum_k jn_k + rounding
  //    (16 x 2^-23 of sum |jt3_k| + mu sum jn, + 1e-12 kg m/s): no relative slack.
  //  - scalar jt (no jt3): sum |jt_k| <= mu sum jn + the same rounding + friction_cone_abs
  //    (a scalar along -v_t / |v_t| cannot show a second friction direction).
  const bool vector_friction = !rec.jt3.empty();
  for (std::size_t k0 = 0; k0 < rec.contacts.size();) {
    poll();
    const Pair pr = rec.contacts[k0].pair;
    std::size_t k1 = k0;
    double jt_sum = 0.0, jn_sum = 0.0, jt_abs = 0.0;
    D3 jt_vec{};
    for (; k1 < rec.contacts.size() && rec.contacts[k1].pair == pr; ++k1) {
      if (vector_friction) {
        jt_vec = jt_vec + d3(rec.jt3[k1]);
        jt_abs += len3(d3(rec.jt3[k1]));
      } else {
        jt_abs += std::fabs(double(rec.contacts[k1].jt));
      }
      jn_sum += double(rec.contacts[k1].jn);
    }
    jt_sum = vector_friction ? len3(jt_vec) : jt_abs;
    const double mu = pair_mu(pr);
    const std::size_t rows = k1 - k0;
    const double rounding = 16.0 * kEps32 * (jt_abs + mu * jn_sum) + 1e-12;
    const double limit = mu * jn_sum + rounding + (vector_friction ? 0.0 : tol.friction_cone_abs);
    const double excess = jt_sum - limit;
    (vector_friction ? ++cone_jt3_pairs : ++cone_scalar_pairs);
    cone.check(excess <= 0, excess, Where{frame, pair_name(pr)}, [&] {
      return fmt::format("frame {}: {} |{}| {:.6g} > mu {:.4g} x jn {:.6g} ({:.4g} x the cone){} [rule: {}]", frame,
                         pair_name(pr), vector_friction ? "sum jt3" : "jt", jt_sum, mu, jn_sum,
                         mu * jn_sum > 0 ? jt_sum / (mu * jn_sum) : std::numeric_limits<double>::infinity(),
                         rows > 1 ? fmt::format(" (sums over its {} rows)", rows) : std::string(),
                         vector_friction ? "jt3" : "scalar");
    });
    k0 = k1;
  }

  const bool states = rec.x_pre.size() == n && rec.v_pre.size() == n && rec.x_post.size() == n &&
                      rec.v_post.size() == n;
  if (!states) {
    dissipation_cone_only += rec.contacts.size();
    for (auto& e : episodes) e.spoiled = true;  // a step without states: the episode is not seen whole
    return;
  }
  ++state_frames;
  const bool rotating = rec.q_pre.size() == n && rec.q_post.size() == n && rec.w_pre.size() == n &&
                        rec.w_post.size() == n;
  auto w_of = [&](const std::vector<Vec3>& w, std::size_t i) { return w.size() == n ? d3(w[i]) : D3{}; };
  auto v_int = [&](std::size_t i) {  // velocity the step starts from: gravity on dynamic bodies
    return dynamic(static_cast<std::uint32_t>(i)) ? d3(rec.v_pre[i]) + dt * g : d3(rec.v_pre[i]);
  };
  auto inv_inertia = [&](std::size_t i) {
    if (!dynamic(static_cast<std::uint32_t>(i))) return M3{};
    return conjugated(rotation(det[i].orientation), inverse(inertia[i]));
  };

  // Distinct contact pairs per body.
  std::vector<std::uint32_t> pairs_of(n, 0);
  for (std::size_t k = 0; k < rec.contacts.size(); ++k) {
    const Pair p = rec.contacts[k].pair;
    if (k > 0 && rec.contacts[k - 1].pair == p) continue;
    ++pairs_of[p.a];
    ++pairs_of[p.b];
  }

  // 5b. Dissipation at the contact points, where the pair is its dynamic bodies' only one.
  for (std::size_t k0 = 0; k0 < rec.contacts.size();) {
    poll();
    const Pair p = rec.contacts[k0].pair;
    std::size_t k1 = k0;
    while (k1 < rec.contacts.size() && rec.contacts[k1].pair == p) ++k1;
    // "Where the contact is the only one on its dynamic bodies" (SPEC 13.5): a manifold
    // row is a contact; with several rows, friction at one row turns the bodies and so
    // moves the tangential velocity at the others (Bullet: a 4-row box pair raised one
    // row's speed from 1.05 to 1.12 m/s while dissipating): judged on the cone only.
    const bool pair_alone = (!dynamic(p.a) || pairs_of[p.a] == 1) && (!dynamic(p.b) || pairs_of[p.b] == 1);
    if (vector_friction && pair_alone) {
      // jt3: the pair's friction impulse is known, whatever else touches its bodies. It
      // must do no positive work on the final relative sliding at the rows' points
      // (maximal dissipation, summed over the manifold): sum_k jt3_k . v_t,k' <= 0, as a
      // mean speed along the impulses, sum_k jt3_k . v_t,k' / sum_k |jt3_k|, within
      // friction_speed + the witness-point allowance (|w_a| + |w_b|) s, s the largest
      // distance between a row's witness points (its depth, or the gap across its point).
      judge_pair_friction(rec, det, p, k0, k1);
      k0 = k1;
      continue;
    }
    const bool alone = k1 - k0 == 1 && (!dynamic(p.a) || pairs_of[p.a] == 1) &&
                       (!dynamic(p.b) || pairs_of[p.b] == 1);
    if (!alone) {
      dissipation_cone_only += k1 - k0;
      k0 = k1;
      continue;
    }
    const D3 xa = d3(det[p.a].position), xb = d3(det[p.b].position);
    const D3 va0 = v_int(p.a), vb0 = v_int(p.b), wa0 = w_of(rec.w_pre, p.a), wb0 = w_of(rec.w_pre, p.b);
    const D3 va1 = d3(rec.v_post[p.a]), vb1 = d3(rec.v_post[p.b]);
    const D3 wa1 = w_of(rec.w_post, p.a), wb1 = w_of(rec.w_post, p.b);
    // A solver applies the normal impulses too; off the centre of mass they turn the
    // bodies and so change the tangential velocity at the point (a box landing on an
    // edge). Friction acts on the velocity after them, so the speed it must not raise is
    // the larger of the speed before the step and the speed with the pair's normal
    // impulses alone applied (the same for translation-only bodies or without points).
    D3 van = va0, vbn = vb0, wan = wa0, wbn = wb0;
    const bool coupled = rotating && rec.has_points;
    if (coupled) {
      const M3 ia = inv_inertia(p.a), ib = inv_inertia(p.b);
      for (std::size_t k = k0; k < k1; ++k) {
        const ContactRecord& c = rec.contacts[k];
        const D3 j = double(c.jn) * d3(c.normal);
        const D3 pt = d3(c.point);
        if (dynamic(p.a)) {
          van = van + (1.0 / mass[p.a]) * j;
          wan = wan + mul(ia, cross3(pt - xa, j));
        }
        if (dynamic(p.b)) {
          vbn = vbn - (1.0 / mass[p.b]) * j;
          wbn = wbn - mul(ib, cross3(pt - xb, j));
        }
      }
    }
    for (std::size_t k = k0; k < k1; ++k) {
      const ContactRecord& c = rec.contacts[k];
      const D3 nrm = d3(c.normal);
      const D3 pt = rec.has_points ? d3(c.point) : D3{};
      const D3 ra = rec.has_points ? pt - xa : D3{}, rb = rec.has_points ? pt - xb : D3{};
      auto tangential_speed = [&](D3 va, D3 wa, D3 vb, D3 wb) {
        const D3 rel = (va + cross3(wa, ra)) - (vb + cross3(wb, rb));
        return len3(rel - dot3(rel, nrm) * nrm);
      };
      const double before = tangential_speed(va0, wa0, vb0, wb0);
      const double with_normal = coupled ? tangential_speed(van, wan, vbn, wbn) : before;
      const double after = tangential_speed(va1, wa1, vb1, wb1);
      if (!coupled) {
        const double rise = after - std::max(before, with_normal);
        dissipation.check(rise <= tol.friction_speed, rise, Where{frame, pair_name(p)}, [&] {
          return fmt::format("frame {}: {} row {}: tangential speed at the {} {:.6g} -> {:.6g} m/s", frame,
                             pair_name(p), k - k0, rec.has_points ? "contact point" : "centres", before, after);
        });
        continue;
      }
      // Rotating bodies with contact points. The row's friction impulse on A is the
      // tangential part of A's momentum change (B's, negated, when A is static): the row
      // is its bodies' only contact, so no model of the solver is needed. Friction must
      // not push the point along its final sliding (it does no positive work: J_t . v_t'
      // <= 0, the maximal-dissipation condition, which exact Coulomb friction meets and
      // which implies |v_t'| <= |v_t| there). |v_t'| itself is not judged on spinning
      // bodies: a sequential-impulse solver's friction row along one fixed direction
      // changes the other tangential component through the bodies' rotation (the
      // point's effective mass is not isotropic), and Bullet raised |v_t| on 4 rows of
      // rot-drop-220 by 0.14-5% with friction opposing the sliding along its row.
      D3 imp = dynamic(p.a) ? mass[p.a] * (va1 - va0) : -mass[p.b] * (vb1 - vb0);
      imp = imp - dot3(imp, nrm) * nrm;
      const double imp_len = len3(imp);
      const double noise = 1e-6 * (dynamic(p.a) ? mass[p.a] * (len3(va1) + len3(va0))
                                                : mass[p.b] * (len3(vb1) + len3(vb0))) + 1e-12;
      if (imp_len <= noise) {  // no friction impulse (within float rounding): nothing to judge
        dissipation.judged();
        continue;
      }
      const D3 rel1 = (va1 + cross3(wa1, ra)) - (vb1 + cross3(wb1, rb));
      const double along = dot3(rel1 - dot3(rel1, nrm) * nrm, (1.0 / imp_len) * imp);
      // The row's point is one point between the bodies' witness points, which an engine
      // may use instead (Bullet: A's velocity at the point on A, B's at the point on B).
      // Moving a body's point by s along the normal moves its velocity there by up to
      // |w| s: on spinning bodies the sliding velocity is known to within |w_a| + |w_b|
      // times the distance between the witness points. A rolling icosphere of rot-drop-220
      // (|w| 3.9 rad/s, resting on a 1 mm hull margin, as the adapter then had) shows 1-3 mm/s at the midpoint
      // while it rolls without sliding. Judged beyond that allowance.
      double allowance = 0.0;
      if (along > tol.friction_speed + allowance) {
        // The witness points lie at most the row's depth apart (penetrating), or the gap
        // between the surfaces across the point (FCL: its distance to each surface).
        const double gap = std::max(double(c.depth), ref->surface_distance(p.a, det[p.a], c.point) +
                                                         ref->surface_distance(p.b, det[p.b], c.point));
        allowance += (len3(wa1) + len3(wb1)) * gap;
      }
      dissipation.check(along <= tol.friction_speed + allowance, along, Where{frame, pair_name(p)}, [&] {
        return fmt::format(
            "frame {}: {} row {}: the friction impulse ({:.4g} kg m/s, from the momentum change) pushes the contact "
            "point along its sliding: {:.4g} m/s along the impulse after the step (tangential speed at the contact "
            "point {:.6g} -> {:.6g} m/s, {:.6g} with the normal impulses alone; witness-point allowance {:.3g} m/s)",
            frame, pair_name(p), k - k0, imp_len, along, before, after, with_normal, allowance);
      });
    }
    k0 = k1;
  }

  // 6. Conservation on isolated dynamic groups: components of the contact graph with at
  // least 2 dynamic bodies and no static body among their contacts.
  clock.emplace(t_conservation);
  std::vector<std::uint32_t> parent(n);
  for (std::size_t i = 0; i < n; ++i) parent[i] = static_cast<std::uint32_t>(i);
  auto find = [&](std::uint32_t i) {
    while (parent[i] != i) i = parent[i] = parent[parent[i]];
    return i;
  };
  // The contact graph: the contact rows' pairs and the engine's confirmed pairs (octocd's
  // later relaxation passes may resolve a confirmed pair that the first pass's Eq. 9
  // discarded, so its impulses are in the state but not in the rows).
  std::vector<Pair> linked;
  for (const ContactRecord& c : rec.contacts) linked.push_back(c.pair);
  linked.insert(linked.end(), rec.confirmed.begin(), rec.confirmed.end());
  std::vector<std::uint8_t> touched(n, 0), statics(n, 0);
  for (const Pair& q : linked) {
    parent[find(q.a)] = find(q.b);
    touched[q.a] = touched[q.b] = 1;
  }
  for (const Pair& q : linked)
    if (!dynamic(q.a) || !dynamic(q.b)) statics[find(q.a)] = 1;
  // An engine may apply a row's impulse at two witness points (Bullet: one on each
  // body), apart along the normal by the depth or distance: the friction part then turns
  // the pair by up to that lever times |jt|. Summed per group, it joins the bound.
  std::map<std::uint32_t, double> witness_torque;
  for (const ContactRecord& c : rec.contacts)
    if (dynamic(c.pair.a) && dynamic(c.pair.b))
      witness_torque[find(c.pair.a)] += (double(c.depth) + pair_margin(c.pair)) * std::fabs(double(c.jt));
  std::map<std::uint32_t, std::vector<std::uint32_t>> groups_of;
  for (std::size_t i = 0; i < n; ++i)
    if (touched[i] && dynamic(static_cast<std::uint32_t>(i))) groups_of[find(static_cast<std::uint32_t>(i))].push_back(
        static_cast<std::uint32_t>(i));
  for (auto& group : groups_of) {
    poll();
    // Not a structured binding: lambdas below capture it (clang 14, the fuzz preset's
    // compiler, refuses to capture structured bindings before C++20).
    const std::uint32_t root = group.first;
    const std::vector<std::uint32_t>& members = group.second;
    if (statics[root] || members.size() < 2) continue;
    if (bodies.velocity_clamp > 0.0 &&
        std::any_of(members.begin(), members.end(), [&](std::uint32_t i) {
          const Vec3 v = rec.v_post[i];
          const double c = bodies.velocity_clamp * (1.0 - 1e-6);
          return std::fabs(v.x) >= c || std::fabs(v.y) >= c || std::fabs(v.z) >= c;
        })) {
      ++groups_clamped;
      continue;
    }
    ++groups;
    // Axes locked by a joint on any member: the joint's impulses are not in the rows, so
    // the momentum along them and (rotation) the angular momentum are not judged.
    unsigned group_locks = 0;
    if (!bodies.locked_dofs.empty())
      for (std::uint32_t i : members) group_locks |= bodies.locked_dofs[i];
    if (group_locks) ++groups_locked;
    // Linear momentum: only gravity's m g dt (already in v_int).
    D3 p0{}, p1{};
    double exchanged = 0, scale = 0, mass_sum = 0;
    D3 c0{};
    for (std::uint32_t i : members) {
      const double mi = mass[i];
      const D3 v0 = v_int(i), v1 = d3(rec.v_post[i]);
      p0 = p0 + mi * v0;
      p1 = p1 + mi * v1;
      exchanged += mi * len3(v1 - v0);
      scale += mi * (len3(d3(rec.v_pre[i])) + len3(v1) + len3(dt * g));
      mass_sum += mi;
      c0 = c0 + mi * d3(rec.x_pre[i]);
    }
    c0 = (1.0 / mass_sum) * c0;
    D3 dp3 = p1 - p0;
    for (int k = 0; k < 3; ++k)
      if (group_locks & (1u << k)) dp3[static_cast<std::size_t>(k)] = 0;
    const double dp = len3(dp3);
    const double pbound = tol.momentum_rel * exchanged + 8.0 * kEps32 * scale + 1e-9;
    momentum.check(dp <= pbound, dp / pbound, Where{frame, group_name(members)}, [&] {
      return fmt::format("frame {}: isolated group of {} bodies (body {} ...): momentum changes by {:.4g} kg m/s "
                         "beyond gravity (exchanged {:.4g}, bound {:.3g})",
                         frame, members.size(), members.front(), dp, exchanged, pbound);
    });
    // Energy: KE' <= KE after gravity, translational + rotational.
    double ke0 = 0, ke1 = 0;
    for (std::uint32_t i : members) {
      const D3 v0 = v_int(i), v1 = d3(rec.v_post[i]);
      ke0 += 0.5 * mass[i] * dot3(v0, v0);
      ke1 += 0.5 * mass[i] * dot3(v1, v1);
      if (rotating) {
        const D3 w0 = d3(rec.w_pre[i]), w1 = d3(rec.w_post[i]);
        ke0 += 0.5 * dot3(w0, mul(conjugated(rotation(rec.q_pre[i]), inertia[i]), w0));
        ke1 += 0.5 * dot3(w1, mul(conjugated(rotation(rec.q_post[i]), inertia[i]), w1));
      }
    }
    if (restitution_le_1 && bodies.contact_model == PhysicsBodies::ContactModel::Soft) {
      ++energy_soft_steps;  // judged per contact episode (soft_episodes)
    } else if (restitution_le_1) {
      const double ebound = ke0 * (1.0 + tol.energy_rel) + 16.0 * kEps32 * (ke0 + ke1) + 1e-12;
      energy.check(ke1 <= ebound, ke0 > 0 ? (ke1 - ke0) / ke0 : 0.0, Where{frame, group_name(members)}, [&] {
        return fmt::format("frame {}: isolated group of {} bodies (body {} ...): kinetic energy {:.6g} -> {:.6g} J "
                           "(+{:.3g} of it){}",
                           frame, members.size(), members.front(), ke0, ke1, ke0 > 0 ? (ke1 - ke0) / ke0 : 0.0,
                           bodies.jacobi_response
                               ? ": a property of the paper's model (SPEC 6's Jacobi response sums each body's "
                                 "impulses computed from one pre-response state, which overshoots on chains; "
                                 "SPEC 13b.13: reported, not loosened)"
                               : "");
      });
    }
    // Angular momentum about the group's centre of mass (rotating records only).
    if (!rotating) continue;
    if (group_locks >> 3) {
      ++groups_rotation_locked;
      continue;
    }
    ++groups_rotating;
    D3 l0{}, l1{};
    double lexchanged = 0, lscale = 0, gyro = 0;
    for (std::uint32_t i : members) {
      const double mi = mass[i];
      const D3 v0 = v_int(i), v1 = d3(rec.v_post[i]);
      const D3 w0 = d3(rec.w_pre[i]), w1 = d3(rec.w_post[i]);
      const M3 i0 = conjugated(rotation(rec.q_pre[i]), inertia[i]);
      const M3 i1 = conjugated(rotation(rec.q_post[i]), inertia[i]);
      // The orbital term at the pre-step positions, before and after: impulses exchanged
      // there keep it exactly, and it does not see how the engine moves the bodies
      // afterwards (x_post = x_pre + dt v_post gives the same sum; a split-impulse or
      // position-projection step does not).
      const D3 li0 = mi * cross3(d3(rec.x_pre[i]) - c0, v0) + mul(i0, w0);
      const D3 li1 = mi * cross3(d3(rec.x_pre[i]) - c0, v1) + mul(i1, w1);
      l0 = l0 + li0;
      l1 = l1 + li1;
      lexchanged += len3(li1 - li0);
      lscale += mi * (len3(d3(rec.x_pre[i])) + len3(c0)) * (len3(v0) + len3(v1)) + len3(mul(i0, w0)) +
                len3(mul(i1, w1));
      // Free rotation of a body whose inertia is not isotropic turns I w: an engine
      // integrating the orientation explicitly (no gyroscopic term) misses dt w x (I w).
      // One with the term (declared gyroscopic) keeps L to second order in |w| dt: its
      // explicit or implicit form differs from the exact rotation by (|w| dt)^2 |I w|.
      gyro += dt * len3(cross3(w1, mul(i1, w1)));
      if (bodies.gyroscopic) gyro += dt * dt * dot3(w1, w1) * len3(mul(i1, w1));
    }
    const double dl = len3(l1 - l0);
    const double lbound =
        tol.angular_momentum_rel * lexchanged + gyro + witness_torque[root] + 16.0 * kEps32 * lscale + 1e-9;
    angular.check(dl <= lbound, dl / lbound, Where{frame, group_name(members)}, [&] {
      return fmt::format("frame {}: isolated group of {} bodies (body {} ...): angular momentum about its centre "
                         "of mass changes by {:.4g} kg m^2/s (exchanged {:.4g}, bound {:.3g})",
                         frame, members.size(), members.front(), dl, lexchanged, lbound);
    });
  }
  if (bodies.contact_model == PhysicsBodies::ContactModel::Soft && restitution_le_1) {
    std::vector<Component> components;  // this step's, with their dynamic bodies
    for (const auto& group : groups_of) components.push_back({group.second, !statics[group.first]});
    soft_episodes(rec, components);
  }
}

double PhysicsValidators::Impl::mechanical_energy(const FrameRecord& rec, std::uint32_t i, bool post) const {
  const std::size_t n = model->bodies.size();
  const bool rotating = rec.q_pre.size() == n && rec.w_pre.size() == n;
  const D3 x = d3(post ? rec.x_post[i] : rec.x_pre[i]), v = d3(post ? rec.v_post[i] : rec.v_pre[i]);
  double e = 0.5 * mass[i] * dot3(v, v) - mass[i] * dot3(d3(model->scene.gravity), x);
  if (rotating) {
    const D3 w = d3(post ? rec.w_post[i] : rec.w_pre[i]);
    e += 0.5 * dot3(w, mul(conjugated(rotation(post ? rec.q_post[i] : rec.q_pre[i]), inertia[i]), w));
  }
  return e;
}

void PhysicsValidators::Impl::soft_episodes(const FrameRecord& rec, const std::vector<Component>& components) {
  const std::int64_t frame = rec.frame;
  const double g2dt2 = dot3(d3(model->scene.gravity), d3(model->scene.gravity)) * model->scene.dt * model->scene.dt;
  auto kinetic = [&](std::uint32_t i) {
    const D3 v = d3(rec.v_pre[i]);
    return 0.5 * mass[i] * dot3(v, v);
  };
  std::set<std::uint32_t> busy;  // dynamic bodies in contact this step
  for (const Component& c : components) busy.insert(c.members.begin(), c.members.end());
  // Close the episodes none of whose bodies is in contact this step: judged on the state
  // before it (the state after the episode's last step). Between contacts a member flies
  // free (free-flight judges it), so the group's energy is judged over the whole episode.
  for (auto it = episodes.begin(); it != episodes.end();) {
    if (std::any_of(it->bodies.begin(), it->bodies.end(), [&](std::uint32_t i) { return busy.count(i) > 0; })) {
      ++it;
      continue;
    }
    const Episode& ep = *it;
    if (ep.spoiled) {
      ++episodes_unjudged;
    } else {
      double e1 = 0, masses = 0;
      for (std::uint32_t i : ep.bodies) {
        e1 += mechanical_energy(rec, i, false);
        masses += mass[i];
      }
      const std::int64_t steps = frame - ep.start;
      // Gravity's integration changes E by up to m |g|^2 dt^2 per step and body (explicit
      // Euler gains half of it, semi-implicit loses half); rounding of E's terms.
      const double slack = double(steps) * masses * g2dt2 +
                           16.0 * kEps32 * double(steps + 1) * (ep.scale + std::fabs(e1)) + 1e-12;
      const double bound = ep.e0 + tol.energy_rel * ep.ke0 + slack;
      const double rise = ep.ke0 > 0 ? (e1 - ep.e0) / ep.ke0 : 0.0;
      const std::string item = ep.bodies.size() == 2 ? pair_name(Pair{ep.bodies[0], ep.bodies[1]})
                                                     : group_name(ep.bodies);
      energy.check(e1 <= bound, rise, Where{frame, item}, [&] {
        return fmt::format("frame {}: {}{} (soft contacts) over its contact episode, frames {}..{}: mechanical "
                           "energy {:.6g} -> {:.6g} J (+{:.3g} of its kinetic energy {:.4g} J at the start; bound "
                           "{:.6g})",
                           frame, item,
                           ep.bodies.size() == 2 ? std::string() : fmt::format(" of {} bodies", ep.bodies.size()),
                           ep.start, frame - 1, ep.e0, e1, rise, ep.ke0, bound);
      });
      ++episodes_judged;
      if (ep.bodies.size() > 2) ++episodes_judged_groups;
    }
    it = episodes.erase(it);
  }
  // Open, grow (a component touching an episode's bodies, or two episodes', merges them;
  // a body joining brings its energy at this step) or spoil (a member touches a static
  // body) the episodes.
  for (const Component& c : components) {
    std::vector<std::size_t> hit;  // open episodes sharing a body with c
    for (std::size_t e = 0; e < episodes.size(); ++e)
      if (std::any_of(c.members.begin(), c.members.end(), [&](std::uint32_t i) {
            return std::binary_search(episodes[e].bodies.begin(), episodes[e].bodies.end(), i);
          }))
        hit.push_back(e);
    if (!c.isolated || c.members.size() < 2) {
      for (std::size_t e : hit) episodes[e].spoiled = true;
      continue;
    }
    Episode merged;
    merged.start = frame;
    for (std::size_t e : hit) {
      const Episode& ep = episodes[e];
      merged.start = std::min(merged.start, ep.start);
      merged.bodies.insert(merged.bodies.end(), ep.bodies.begin(), ep.bodies.end());
      merged.e0 += ep.e0;
      merged.ke0 += ep.ke0;
      merged.scale += ep.scale;
      merged.spoiled = merged.spoiled || ep.spoiled;
    }
    for (std::uint32_t i : c.members) {
      if (std::find(merged.bodies.begin(), merged.bodies.end(), i) != merged.bodies.end()) continue;
      const double e = mechanical_energy(rec, i, false), ke = kinetic(i);
      merged.bodies.push_back(i);
      merged.e0 += e;
      merged.ke0 += ke;
      merged.scale += std::fabs(e) + ke;
    }
    std::sort(merged.bodies.begin(), merged.bodies.end());
    for (auto e = hit.rbegin(); e != hit.rend(); ++e) episodes.erase(episodes.begin() + static_cast<std::ptrdiff_t>(*e));
    episodes.push_back(std::move(merged));
  }
}

// ---- Rows 7-8: momentum balance per body and free flight, every frame with states ---
namespace {
/// Unit vector of a (double; zero stays zero).
D3 unit3(D3 a) {
  const double l = len3(a);
  return l > 0 ? (1.0 / l) * a : D3{};
}
/// Angle (rad) between two orientations (the rotation q1 q0^-1), sign of q ignored.
double quat_angle(Quat a, Quat b) {
  const double na = std::sqrt(double(a.w) * a.w + double(a.x) * a.x + double(a.y) * a.y + double(a.z) * a.z);
  const double nb = std::sqrt(double(b.w) * b.w + double(b.x) * b.x + double(b.y) * b.y + double(b.z) * b.z);
  const double d = std::fabs(double(a.w) * b.w + double(a.x) * b.x + double(a.y) * b.y + double(a.z) * b.z) /
                   (na * nb);
  return 2.0 * std::acos(std::min(1.0, d));
}
/// q advanced by the rotation w dt (exponential map: the quaternion of angle |w| dt about
/// w, applied in the world frame: q' = dq q), in double.
std::array<double, 4> advanced(Quat q, D3 w, double dt) {
  const double angle = len3(w) * dt;
  double dw = 1, dx = 0, dy = 0, dz = 0;
  if (angle > 0) {
    const D3 axis = unit3(w);
    const double s = std::sin(0.5 * angle);
    dw = std::cos(0.5 * angle);
    dx = s * axis[0];
    dy = s * axis[1];
    dz = s * axis[2];
  }
  return {dw * q.w - dx * q.x - dy * q.y - dz * q.z, dw * q.x + dx * q.w + dy * q.z - dz * q.y,
          dw * q.y - dx * q.z + dy * q.w + dz * q.x, dw * q.z + dx * q.y - dy * q.x + dz * q.w};
}
double quat_angle(const std::array<double, 4>& a, Quat b) {
  return quat_angle(Quat{float(a[0]), float(a[1]), float(a[2]), float(a[3])}, b);
}
}  // namespace

void PhysicsValidators::Impl::balance(const FrameRecord& rec, const std::vector<Pose>& det) {
  const Model& m = *model;
  const std::size_t n = m.bodies.size();
  const std::int64_t frame = rec.frame;
  const bool states = rec.x_pre.size() == n && rec.v_pre.size() == n && rec.x_post.size() == n &&
                      rec.v_post.size() == n;
  if (!states) return;
  const bool rotating = rec.q_pre.size() == n && rec.q_post.size() == n && rec.w_pre.size() == n &&
                        rec.w_post.size() == n;
  const D3 g = d3(m.scene.gravity);
  const double dt = m.scene.dt;
  const double eps = tol.balance_ulps * kEps32;
  StopPoll poll(stop);
  std::optional<RowClock> clock(std::in_place, t_balance);
  auto v_int = [&](std::size_t i) { return d3(rec.v_pre[i]) + dt * g; };  // dynamic bodies
  auto w_of = [&](const std::vector<Vec3>& w, std::size_t i) { return rotating ? d3(w[i]) : D3{}; };
  auto locked = [&](std::size_t i) -> unsigned { return bodies.locked_dofs.empty() ? 0u : bodies.locked_dofs[i]; };
  // Zeroes the components about locked world axes (bits `first` .. first + 2).
  auto unlocked = [&](D3 a, std::size_t i, int first) {
    for (int k = 0; k < 3; ++k)
      if (locked(i) & (1u << (first + k))) a[static_cast<std::size_t>(k)] = 0;
    return a;
  };
  auto clamped = [&](std::size_t i) {
    if (!(bodies.velocity_clamp > 0.0)) return false;
    const Vec3 v = rec.v_post[i];
    const double c = bodies.velocity_clamp * (1.0 - 1e-6);
    return std::fabs(v.x) >= c || std::fabs(v.y) >= c || std::fabs(v.z) >= c;
  };

  // Each row's impulse J = jn n + J_t on A (and -J on B), summed per body with its torque
  // about the body's detection-pose position, and what the record leaves uncertain.
  std::vector<D3> force(n), torque(n);
  std::vector<double> mag(n, 0.0), tmag(n, 0.0), tallow(n, 0.0);
  // Per body, what the record leaves open of its rows' friction: a disc of radius u in the
  // plane normal to n per row (direction and size of J_t beyond the scalar jt).
  struct Disc {
    D3 n;
    double u;
  };
  std::vector<std::vector<Disc>> discs(n);
  std::vector<std::uint32_t> rows_of(n, 0);
  std::vector<std::uint8_t> in_contact(n, 0);
  for (const Pair& p : rec.confirmed) in_contact[p.a] = in_contact[p.b] = 1;
  for (std::size_t k = 0; k < rec.contacts.size(); ++k) {
    const ContactRecord& c = rec.contacts[k];
    const Pair p = c.pair;
    in_contact[p.a] = in_contact[p.b] = 1;
    ++rows_of[p.a];
    ++rows_of[p.b];
    const D3 nrm = unit3(d3(c.normal));
    const D3 xa = d3(det[p.a].position), xb = d3(det[p.b].position);
    const D3 pt = rec.has_points ? d3(c.point) : D3{};
    const D3 ra = rec.has_points ? pt - xa : D3{}, rb = rec.has_points ? pt - xb : D3{};
    // The friction impulse's direction: the trace convention's -v_t / |v_t|, v_t the
    // tangential velocity of A relative to B at the row's point before the solver
    // (v_pre + dt g on dynamic bodies, w_pre); octocd's records: J_t along +t.
    const D3 va = (dynamic(p.a) ? v_int(p.a) : d3(rec.v_pre[p.a])) + cross3(w_of(rec.w_pre, p.a), ra);
    const D3 vb = (dynamic(p.b) ? v_int(p.b) : d3(rec.v_pre[p.b])) + cross3(w_of(rec.w_pre, p.b), rb);
    const D3 rel = va - vb;
    const D3 vt = rel - dot3(rel, nrm) * nrm;
    const double vt_len = len3(vt);
    const bool vector_friction = rec.jt3.size() == rec.contacts.size();
    const double jt = vector_friction ? len3(d3(rec.jt3[k])) : std::fabs(double(c.jt));
    D3 jt_vec{};
    double uncertain = 0;  // |J_t - jt_vec| at most this (kg m/s), in the tangent plane
    if (vector_friction) {
      jt_vec = d3(rec.jt3[k]);  // /contacts/jt3: the friction impulse on A, nothing left open
    } else if (vt_len > tol.friction_direction_speed) {
      jt_vec = (bodies.jt_along_sliding ? double(c.jt) : -double(c.jt)) * ((1.0 / vt_len) * vt);
      if (rotating && rec.has_points) {
        // An engine may take each body's velocity at its own witness point (Bullet), up
        // to the depth or the contact margin apart along the normal: v_t there differs by
        // up to (|w_a| + |w_b|) s, turning the direction by at most that over |v_t|; the
        // part of J_t across the recorded direction is not in a scalar jt.
        const double s = double(c.depth) + pair_margin(p);
        const double turn =
            std::min(2.0, (len3(w_of(rec.w_pre, p.a)) + len3(w_of(rec.w_pre, p.b))) * s / vt_len);
        uncertain = turn * (jt + pair_mu(p) * std::fabs(double(c.jn)));
      }
    } else if (vt_len > kNoSliding) {
      // Nearly no sliding before the step: the engine picks the friction direction
      // itself (Bullet below sqrt(FLT_EPSILON) = 3.45e-4 m/s: btPlaneSpace1's axis), and a
      // scalar jt, the impulse's projection on the recorded -v_t, says neither which nor
      // how large J_t is; it lies in the cone (the friction row judges that).
      // A row's own cone, with the margin a sequential solver leaves on a row whose normal
      // impulse moved to the manifold's other rows after its friction was clamped (Bullet:
      // up to 13% above mu times the row's final jn; the friction row holds the pair's sum
      // to the cone itself). Never with jt3; what it leaves open is stated in
      // docs/validate-your-engine.md, "The row cone margin".
      constexpr double kRowConeMargin = 0.25;
      uncertain = std::max(jt, pair_mu(p) * std::fabs(double(c.jn)) * (1.0 + kRowConeMargin) + tol.friction_cone_abs);
    } else {
      // No sliding: v_t has no direction; jt is the friction impulse's magnitude (the
      // convention, and octocd's Bullet adapter below 1e-6 m/s), its direction open.
      uncertain = jt;
    }
    const D3 j = double(c.jn) * nrm + jt_vec;
    force[p.a] = force[p.a] + j;
    force[p.b] = force[p.b] - j;
    mag[p.a] += len3(j) + uncertain;
    mag[p.b] += len3(j) + uncertain;
    if (uncertain > 0) {
      discs[p.a].push_back({nrm, uncertain});
      discs[p.b].push_back({nrm, uncertain});
    }
    if (rec.has_points) {
      torque[p.a] = torque[p.a] + cross3(ra, j);
      torque[p.b] = torque[p.b] - cross3(rb, j);
      // An engine may apply the row at a witness point on each body (Bullet) instead of
      // the recorded point between them: the two lie the depth apart along the normal
      // (which moves the friction part's lever) and, in a persistent manifold, up to the
      // contact margin apart sideways as the bodies move before the point is dropped
      // (which moves the normal part's lever): half of that from the recorded point.
      const double s = double(c.depth) + pair_margin(p);
      const double lever = s * (jt + uncertain) + 0.5 * s * std::fabs(double(c.jn));
      tallow[p.a] += len3(ra) * uncertain + lever;
      tallow[p.b] += len3(rb) * uncertain + lever;
      tmag[p.a] += len3(ra) * (len3(j) + uncertain);
      tmag[p.b] += len3(rb) * (len3(j) + uncertain);
    }
  }

  for (std::size_t i = 0; i < n; ++i) {
    if (!dynamic(static_cast<std::uint32_t>(i))) continue;
    if ((i & 63u) == 0) poll();
    const double mi = mass[i];
    const D3 v0 = v_int(i), v1 = d3(rec.v_post[i]);
    const D3 w0 = w_of(rec.w_pre, i), w1 = w_of(rec.w_post, i);
    const M3 iw = rotating ? conjugated(rotation(det[i].orientation), inertia[i]) : M3{};
    // The gyroscopic term dt w x I_w w of the step (zero without rotation).
    const D3 gyro_term = rotating ? dt * cross3(w0, mul(iw, w0)) : D3{};
    const D3 gyro = bodies.gyroscopic ? gyro_term : D3{};
    const double locked_count = double(locked(i) != 0);
    if (clamped(i)) {
      ++balance_clamped;
      continue;
    }
    if (in_contact[i]) {
      // 7. Momentum balance.
      if (rows_of[i] == 0) {
        ++balance_no_rows;  // a confirmed pair without rows (octocd's later passes)
        continue;
      }
      if (!bodies.impulses_complete) continue;
      if (locked(i)) ++balance_locked;
      const D3 dp = unlocked(mi * (v1 - v0) - force[i], i, 0);
      const double float_bound =
          eps * double(rows_of[i] + 2) * (mi * (len3(d3(rec.v_pre[i])) + len3(v1) + len3(dt * g)) + mag[i]) + 1e-9;
      // The residual must lie in the sum of the rows' friction discs (plus rounding): its
      // component along a direction d is at most sum u |d x n| + the rounding bound. Tested
      // along the residual itself and along each row's normal (where a manifold's discs,
      // all normal to it, allow nothing: a dropped row's jn n shows there).
      double ratio = 0, open_along = 0;
      const double dpl = len3(dp);
      auto test_dir = [&](D3 d) {
        double support = 0;
        for (const Disc& dc : discs[i]) support += dc.u * len3(cross3(d, dc.n));
        const double r = std::fabs(dot3(dp, d)) / (support + float_bound);
        if (r > ratio) {
          ratio = r;
          open_along = support;
        }
      };
      if (dpl > 0) test_dir((1.0 / dpl) * dp);
      for (const Disc& dc : discs[i]) test_dir(dc.n);
      if (discs[i].empty()) ratio = dpl / float_bound;
      balance_lin.check(ratio <= 1.0, ratio, Where{frame, body_name(i)}, [&] {
        return fmt::format("frame {}: body {}: m (v' - v) - m g dt = ({:.4g}, {:.4g}, {:.4g}) kg m/s but its {} "
                           "contact rows' impulses sum to ({:.4g}, {:.4g}, {:.4g}): off by {:.4g} ({:.3g} of the "
                           "bound: rounding {:.3g}, friction the record leaves open {:.3g})",
                           frame, i, mi * (v1[0] - v0[0]), mi * (v1[1] - v0[1]), mi * (v1[2] - v0[2]), rows_of[i],
                           force[i][0], force[i][1], force[i][2], dpl, ratio, float_bound, open_along);
      });
      if (!rotating || !rec.has_points) continue;
      if ((locked(i) >> 3) == 7u) {  // every rotation locked by a joint
        ++balance_rot_locked;
        continue;
      }
      // Declared gyroscopic: the term is required (within gyroscopic_rel of it).
      // Undeclared: allowed either way on a body in contact: an engine may apply it only
      // to the bodies its solver sees (Bullet's BT_ENABLE_GYROSCOPIC_FORCE_IMPLICIT_BODY
      // acts in the solver's islands, on bodies with contacts, never on free ones:
      // bunny-stack-50, a bunny spinning at 8.9 rad/s on a row with jn = 0); free-flight
      // holds free bodies to the declaration.
      const double rounding =
          eps * double(rows_of[i] + 2) * (len3(mul(iw, w0)) + len3(mul(iw, w1)) + tmag[i]) + tallow[i] + 1e-9;
      const double gyro_allow = tol.gyroscopic_rel * len3(gyro_term);
      D3 lhs = mul(iw, w1 - w0) + gyro;
      double dll = len3(unlocked(lhs - torque[i], i, 3));
      double ang_bound = rounding + (bodies.gyroscopic ? gyro_allow : 0.0);
      bool with_term = bodies.gyroscopic;
      if (!bodies.gyroscopic && len3(gyro_term) > 0) {
        const D3 lhs_with = lhs + gyro_term;
        const double dl_with = len3(unlocked(lhs_with - torque[i], i, 3));
        if (dl_with / (rounding + gyro_allow) < dll / ang_bound) {
          lhs = lhs_with;
          dll = dl_with;
          ang_bound = rounding + gyro_allow;
          with_term = true;
        }
      }
      balance_ang.check(dll <= ang_bound, dll / ang_bound, Where{frame, body_name(i)}, [&] {
        return fmt::format("frame {}: body {}: I_w (w' - w){} = ({:.4g}, {:.4g}, {:.4g}) kg m^2/s but its {} "
                           "contact rows' torques (p - x) x J sum to ({:.4g}, {:.4g}, {:.4g}): off by {:.4g} "
                           "(bound {:.3g})",
                           frame, i, with_term ? " + dt w x I_w w" : "", lhs[0], lhs[1], lhs[2], rows_of[i],
                           torque[i][0], torque[i][1], torque[i][2], dll, ang_bound);
      });
      continue;
    }
    // 8. Free flight: no contact row and no confirmed pair in this step.
    if (locked_count > 0) ++free_locked;
    const D3 dv = unlocked(v1 - v0, i, 0);
    const double v_bound = 4.0 * kEps32 * (len3(d3(rec.v_pre[i])) + len3(v1) + len3(dt * g)) + 1e-12;
    const double dvl = len3(dv);
    free_vel.check(dvl <= v_bound, dvl, Where{frame, body_name(i)}, [&] {
      return fmt::format("frame {}: body {} without contacts: v' = ({:.6g}, {:.6g}, {:.6g}) m/s, v + g dt = "
                         "({:.6g}, {:.6g}, {:.6g}): off by {:.4g} m/s (bound {:.3g})",
                         frame, i, v1[0], v1[1], v1[2], v0[0], v0[1], v0[2], dvl, v_bound);
    });
    const D3 x0 = d3(rec.x_pre[i]), x1 = d3(rec.x_post[i]);
    const D3 semi = x0 + dt * v1, expl = x0 + dt * d3(rec.v_pre[i]);
    const double d_semi = len3(unlocked(x1 - semi, i, 0)), d_expl = len3(unlocked(x1 - expl, i, 0));
    const double dx = bodies.integrator == PhysicsBodies::Integrator::SemiImplicit ? d_semi
                      : bodies.integrator == PhysicsBodies::Integrator::Explicit ? d_expl
                                                                                  : std::min(d_semi, d_expl);
    const double x_bound =
        4.0 * kEps32 * (len3(x0) + len3(x1) + dt * (len3(v1) + len3(d3(rec.v_pre[i])))) + 1e-12;
    free_pos.check(dx <= x_bound, dx, Where{frame, body_name(i)}, [&] {
      return fmt::format("frame {}: body {} without contacts: x' = ({:.6g}, {:.6g}, {:.6g}) m is {:.4g} m from x + "
                         "dt v{} (integrator {}; bound {:.3g})",
                         frame, i, x1[0], x1[1], x1[2], dx,
                         bodies.integrator == PhysicsBodies::Integrator::Explicit ? "" : "'",
                         integrator_name(bodies.integrator), x_bound);
    });
    if (!rotating) continue;
    // w' = w, less the declared gyroscopic term: I_w (w' - w) = -dt w x I_w w.
    const D3 dw_expected = bodies.gyroscopic ? -1.0 * mul(inverse(iw), gyro) : D3{};
    const D3 dw = unlocked(w1 - w0 - dw_expected, i, 3);
    // 8 eps32 per |w|: a float engine's free step may turn w into the body frame and back
    // (Bullet's implicit gyroscopic step: two quatRotate, each two quaternion products);
    // Bullet on rot-pile-1000 measured 8.04 eps32 |w| (3.02e-05 rad/s at 31.6 rad/s).
    const double w_bound = 8.0 * kEps32 * (len3(w0) + len3(w1)) + tol.gyroscopic_rel * len3(dw_expected) + 1e-9;
    const double dwl = len3(dw);
    free_w.check(dwl <= w_bound, dwl, Where{frame, body_name(i)}, [&] {
      return fmt::format("frame {}: body {} without contacts: w' = ({:.6g}, {:.6g}, {:.6g}) rad/s, w{} = "
                         "({:.6g}, {:.6g}, {:.6g}): off by {:.4g} rad/s (bound {:.3g})",
                         frame, i, w1[0], w1[1], w1[2], bodies.gyroscopic ? " - dt I_w^-1 (w x I_w w)" : "",
                         w0[0] + dw_expected[0], w0[1] + dw_expected[1], w0[2] + dw_expected[2], dwl, w_bound);
    });
    if (locked(i) >> 3) continue;  // a joint turns it: counted in free_locked
    const Quat q0 = rec.q_pre[i], q1 = rec.q_post[i];
    const double a_semi = quat_angle(advanced(q0, w1, dt), q1), a_expl = quat_angle(advanced(q0, w0, dt), q1);
    const double angle = bodies.integrator == PhysicsBodies::Integrator::SemiImplicit ? a_semi
                         : bodies.integrator == PhysicsBodies::Integrator::Explicit ? a_expl
                                                                                     : std::min(a_semi, a_expl);
    const double wdt = std::max(len3(w0), len3(w1)) * dt;
    const double q_bound = tol.free_flight_angle_rad + wdt * wdt;
    free_q.check(angle <= q_bound, angle * 180.0 / kPi, Where{frame, body_name(i)}, [&] {
      return fmt::format("frame {}: body {} without contacts: q' is {:.4g} deg from q advanced by w{} dt (|w| dt "
                         "{:.3g} rad; bound {:.3g} deg)",
                         frame, i, angle * 180.0 / kPi,
                         bodies.integrator == PhysicsBodies::Integrator::Explicit ? "" : "'", wdt,
                         q_bound * 180.0 / kPi);
    });
  }
}

std::vector<ValidationResult> PhysicsValidators::results() const {
  const Impl& s = *impl_;
  std::vector<ValidationResult> out;
  auto row = [](const char* name, const char* figure, const char* tolerances) {
    ValidationResult r;
    r.tier = Tier::Physics;
    r.name = name;
    r.figure = figure;
    r.tolerances = tolerances;
    return r;
  };
  const std::string no_checked = "no checked frame with poses (AABBs or detection poses)";

  // 1. Broadphase completeness.
  {
    ValidationResult r = row("broadphase-completeness", "required pairs missing from the engine's candidates",
                             "broadphase_margin_m,geometry_slack_m");
    r.measured = double(s.broad.failures + s.broad_exact.failures);
    r.bound = 0;
    r.pass = r.measured == 0;
    if (s.broad_frames > 0 && s.broad.checks + s.broad_exact.checks == 0) {
      r.applicable = false;
      r.detail = fmt::format("no pair required on {} checked frames (no shapes within the margin) and no exact "
                             "broadphase declared: nothing judged ({:.3g} candidates per frame)",
                             s.broad_frames, double(s.broad_candidates) / double(s.broad_frames));
    } else if (s.broad_frames == 0) {
      r.applicable = false;
      r.detail = s.broad_no_pairs ? "the engine gave no candidate pairs (has_pairs false)" : no_checked;
    } else if (s.broad.failures) {
      r.detail = s.broad.first + fmt::format(" ({} of {} required pairs missing)", s.broad.failures, s.broad.checks);
    } else if (s.broad_exact.failures) {
      r.detail = s.broad_exact.first;
    } else {
      r.detail = fmt::format("{} required pairs over {} frames, all candidates; {:.3g} candidates per true pair{}",
                             s.broad.checks, s.broad_frames,
                             s.broad_true ? double(s.broad_candidates) / double(s.broad_true) : 0.0,
                             s.bodies.broadphase_exact ? "; equal to flat on the engine's AABBs (static-static "
                                                         "pairs dropped)"
                                                       : "");
    }
    if (r.applicable)
      fill_causes(r, {{&s.broad, "missing-pair", "required pairs", "m"},
                      {&s.broad_exact, "not-flat", "frames", "pairs"}});
    out.push_back(r);
  }
  // 2. Contact completeness.
  {
    ValidationResult r = row("contact-completeness", "penetrating pairs without a contact + false contacts",
                             "contact_depth_m,geometry_slack_m");
    r.measured = double(s.complete.failures + s.false_contact.failures);
    r.pass = r.measured == 0;
    r.applicable = s.checked_frames > 0 && (s.complete.checks + s.false_contact.checks) > 0;
    const std::string margin =
        s.bodies.theta_margin ? std::string("the pair's theta") : fmt::format("{} m", s.bodies.contact_margin);
    if (s.complete.failures) {
      r.detail = s.complete.first + fmt::format(" ({} such pairs)", s.complete.failures);
    } else if (s.false_contact.failures) {
      r.detail = s.false_contact.first + fmt::format(" ({} false contacts)", s.false_contact.failures);
    } else if (!r.applicable) {
      r.detail = s.checked_frames ? "no pair penetrated deeper than contact_depth_m and no contact" : no_checked;
    } else {
      r.detail = fmt::format("{} penetrating pairs all with contacts; {} contact pairs all within {} (farthest "
                             "{:.3g} m beyond it)",
                             s.complete.checks, s.false_contact.checks, margin, s.false_contact.worst_or(0.0));
    }
    if (r.applicable)
      fill_causes(r, {{&s.complete, "missing-contact", "penetrating pairs", "m"},
                      {&s.false_contact, "false-contact", "contact pairs", "m"}});
    out.push_back(r);
  }
  // 3. Contact geometry.
  {
    ValidationResult r = row("contact-geometry", "worst normal angle to the reference's (deg; SAT or FCL)",
                             "normal_angle_deg,depth_m,sat_accept_rel");
    r.measured = s.normal_angle.worst_or(0.0);
    r.bound = s.tol.normal_angle_deg;
    r.pass = s.normal_angle.failures == 0 && s.depth.failures == 0 && s.points.failures == 0;
    r.applicable = s.normal_angle.checks + s.depth.checks + s.points.checks > 0;
    const bool aabb = s.bodies.contact_geometry == ContactGeometry::Aabb;
    if (aabb) {
      r.figure = "worst normal angle to FCL box-box on the world AABBs (deg; its sign judged)";
      r.bound = 90.0;
    }
    std::string stats;
    if (aabb && !s.shape_angles.empty()) {
      std::vector<double> a = s.shape_angles;
      std::sort(a.begin(), a.end());
      double mean = 0;
      for (double x : a) mean += x;
      mean /= double(a.size());
      stats = fmt::format("; against the posed shapes (figure, not judged: the engine resolves on world AABBs): "
                          "mean {:.1f} deg, median {:.1f}, p95 {:.1f}, max {:.1f}",
                          mean, a[a.size() / 2], a[a.size() * 95 / 100], a.back());
    }
    const std::string sign =
        fmt::format("sign agreement {:.4f} of {} rows", s.sign_rows ? double(s.sign_agree) / double(s.sign_rows) : 1.0,
                    s.sign_rows);
    if (!r.applicable) {
      r.detail = s.checked_frames ? "no contact rows on checked frames" : no_checked;
    } else if (s.normal_angle.failures) {
      r.detail = s.normal_angle.worst_what + fmt::format(" ({} of {} rows beyond {} deg; {})", s.normal_angle.failures,
                                                         s.normal_angle.checks, aabb ? 90.0 : s.tol.normal_angle_deg, sign);
      if (s.sign_rows > 0 && 2 * s.sign_agree < s.sign_rows)
        r.detail += "; most normals point from A to B: the convention is from B to A (SPEC 2)";
    } else if (s.depth.failures) {
      r.detail = s.depth.worst_what + fmt::format(" (depth off by more than {} m on {} of {} pairs)", s.tol.depth_m,
                                                  s.depth.failures, s.depth.checks);
    } else if (s.points.failures) {
      r.detail = s.points.worst_what + fmt::format(" (points off the shapes by more than {} m on {} of {} rows)",
                                                   s.tol.depth_m, s.points.failures, s.points.checks);
    } else if (aabb) {
      r.detail = fmt::format("normal angle n/a: the engine resolves contacts on world AABBs (its normal is an AABB "
                             "axis; its angle to FCL box-box on the same boxes judges nothing about the shapes: worst "
                             "{:.3g} deg over {} rows, a figure; its sign is judged on {} rows); depth of {} pairs "
                             "judged against FCL box-box on the world AABBs: worst difference {:.3g} m; {}{}",
                             s.aabb_angle_worst, s.aabb_angle_rows, s.normal_angle.checks, s.depth.checks,
                             s.depth.worst_or(0.0), sign, stats);
    } else {
      r.detail = fmt::format("{} rows judged{} ({}): worst angle {:.3g} deg, worst depth difference {:.3g} m{}{}; {}{}",
                             s.normal_angle.checks, aabb ? " on the world AABBs" : "",
                             aabb ? std::string("FCL box-box")
                                  : fmt::format("reference: SAT on {} convex pair-frames, FCL (box-box, EPA or the "
                                                "non-convex BVH bound) on {}",
                                                s.sat_pairs, s.fcl_pairs),
                             s.normal_angle.worst_or(0.0),
                             s.depth.worst_or(0.0),
                             s.points.checks ? fmt::format(", {} points, worst {:.3g} m beyond the depth",
                                                           s.points.checks, s.points.worst_or(0.0))
                                             : "",
                             s.rows_unjudged ? fmt::format("; {} rows not judged (FCL gave no normal)", s.rows_unjudged)
                                             : "",
                             sign, stats);
      if (s.speculative_rows)
        r.detail += fmt::format("; {} rows on shapes that do not penetrate, or of depth 0 beside a penetrating "
                                "row of their pair, not judged on the normal (worst angle {:.3g} deg to FCL's "
                                "direction)",
                                s.speculative_rows, s.speculative_worst);
      if (s.upper_bound_pairs)
        r.detail += fmt::format("; {} non-convex mesh pairs: depth judged one-sided against an upper bound",
                                s.upper_bound_pairs);
      for (const auto& [kind, figure] : s.declared)
        r.detail += fmt::format("; {} bodies collided as declared \"{}\" (judged on it; its surface lies up to "
                                "{:.3g} m from the true shape: a figure)",
                                figure.first, kind, figure.second);
      if (s.sat_fcl_other)
        r.detail += fmt::format("; second opinion: FCL's normal on another axis than the minimum on {} pair-frames "
                                "(figure; FCL up to {:.3g} m deeper)",
                                s.sat_fcl_other, s.sat_fcl_other_excess);
      if (s.sat_fcl_disagree)
        r.detail += fmt::format("; FCL's normal outside SAT's accepted axes on {} pair-frames "
                                "(figure; largest depth excess {}: {:.3g} m)",
                                s.sat_fcl_disagree, s.sat_fcl_what, s.sat_fcl_worst_excess);
    }
    if (r.applicable)
      fill_causes(r, {{&s.normal_angle, "normal-angle", "rows", "deg"},
                      {&s.depth, "depth", "pairs", "m"},
                      {&s.points, "point-off-shape", "points", "m"}});
    out.push_back(r);
  }
  // 4. Penetration.
  {
    ValidationResult r = row("penetration", "largest true penetration (m)",
                             "penetration_slops,penetration_settle_frames");
    r.measured = s.pen_max;
    r.bound = s.tol.penetration_slops * s.bodies.slop;
    r.pass = r.measured <= r.bound;
    // Judged: pair-frames with an exact depth. Where every penetrating pair-frame was a
    // non-convex pair's upper bound, the row proved no penetration: n/a.
    r.applicable = s.checked_frames > 0 && s.pen.checks > 0 && !(s.pen_upper_pairs > 0 && s.pen_upper_pairs == s.pen_pairs);
    if (s.checked_frames == 0) {
      r.detail = no_checked;
    } else if (!r.applicable) {
      r.detail = s.pen_upper_max > 0
                     ? fmt::format("no exact depth: every penetrating pair is a non-convex mesh pair, whose depth is "
                                   "an upper bound only (the least separating translation over 8 directions: a "
                                   "figure, not judged): largest {}, {} pair-frames above the bound {} m",
                                   s.pen_upper_what, s.pen_upper_over, fmt::format("{:.3g}", r.bound))
                     : fmt::format("no pair-frame with an exact depth from frame {} on",
                                   s.tol.penetration_settle_frames);
    } else if (s.pen_pairs == 0) {
      r.detail = fmt::format("no penetrating pair on the checked frames from frame {} on",
                             s.tol.penetration_settle_frames);
    } else {
      r.detail = (s.pen_what.empty() ? std::string("no exact depth (convex shapes)") : s.pen_what) +
                 fmt::format(" (largest of {} penetrating pair-frames; bound {} x slop {} m)", s.pen_pairs,
                             s.tol.penetration_slops, s.bodies.slop);
      if (s.pen_upper_max > 0)
        r.detail += fmt::format("; non-convex meshes, upper bounds only (the least separating translation over 8 "
                                "directions: a figure, not judged): largest {}, {} pair-frames above the bound",
                                s.pen_upper_what, s.pen_upper_over);
    }
    if (r.applicable) fill_causes(r, {{&s.pen, "penetration", "pair-frames", "m"}});
    out.push_back(r);
  }
  // 5. Friction.
  {
    ValidationResult r = row("friction", "contacts outside the cone or rows raising the tangential speed",
                             "friction_cone_abs,friction_speed");
    r.measured = double(s.cone.failures + s.dissipation.failures);
    r.pass = r.measured == 0;
    r.applicable = s.cone.checks > 0;
    if (s.cone.failures) {
      r.detail = s.cone.first + fmt::format(" ({} of {} contacts outside the cone)", s.cone.failures, s.cone.checks);
    } else if (s.dissipation.failures) {
      r.detail = s.dissipation.first + fmt::format(" ({} of {} rows where friction raises the sliding)",
                                                   s.dissipation.failures, s.dissipation.checks);
    } else if (!r.applicable) {
      r.detail = "no contact rows";
    } else {
      r.detail = fmt::format("{} contacts in the cone (worst {:.3g} kg m/s inside; rule jt3 on {} pairs, scalar jt on "
                             "{}); dissipation on {} rows or pairs (worst {:.3g} m/s; {} pairs on jt3); {} rows judged "
                             "on the cone only (scalar jt: the pair is not its bodies' only one, or no states)",
                             s.cone.checks, -s.cone.worst_or(0.0), s.cone_jt3_pairs, s.cone_scalar_pairs,
                             s.dissipation.checks, s.dissipation.worst_or(0.0), s.dissipation_jt3_pairs,
                             s.dissipation_cone_only);
      if (s.dissipation_small)
        r.detail += fmt::format("; {} pairs with a friction impulse up to friction_cone_abs not judged on its "
                                "direction",
                                s.dissipation_small);
    }
    if (r.applicable)
      fill_causes(r, {{&s.cone, "cone", "contacts", "kg m/s"}, {&s.dissipation, "dissipation", "rows", "m/s"}});
    out.push_back(r);
  }
  // 6. Conservation.
  {
    ValidationResult r = row("conservation", "isolated groups breaking momentum, angular momentum or energy",
                             "momentum_rel,angular_momentum_rel,energy_rel");
    r.measured = double(s.momentum.failures + s.angular.failures + s.energy.failures);
    r.pass = r.measured == 0;
    r.applicable = s.groups > 0;
    if (s.momentum.failures) {
      r.detail = s.momentum.first;
    } else if (s.energy.failures) {
      r.detail = s.energy.first;
    } else if (s.angular.failures) {
      r.detail = s.angular.first;
    } else if (!r.applicable) {
      r.detail = s.state_frames ? "no isolated dynamic group (2+ dynamic bodies in contact, no static contact)"
                                : "no states";
    } else {
      r.detail = fmt::format("{} isolated group-frames: worst momentum change {:.3g} of its bound; energy {}; "
                             "angular momentum {}",
                             s.groups, s.momentum.worst_or(0.0),
                             s.restitution_le_1 ? fmt::format("worst rise {:.3g} of KE", s.energy.worst_or(0.0))
                                                : std::string("not judged (a restitution above 1)"),
                             s.groups_rotating
                                 ? fmt::format("{} groups, worst change {:.3g} of its bound", s.groups_rotating,
                                               s.angular.worst_or(0.0))
                             : s.groups_rotation_locked
                                 ? std::string("n/a: every group has a body whose rotation is locked (locked_dofs)")
                                 : std::string("n/a: translation-only records (no orientation or angular "
                                               "velocity), contact torques are not modelled"));
    }
    if (s.groups_clamped)
      r.detail += fmt::format("; {} group-frames not judged (a body at the declared velocity clamp {} m/s)",
                              s.groups_clamped, s.bodies.velocity_clamp);
    if (s.bodies.contact_model == PhysicsBodies::ContactModel::Soft)
      r.detail += fmt::format("; contact_model soft: energy judged per contact episode of an isolated group, "
                              "from its first contact until none of its bodies touches another ({} episodes judged, "
                              "{} of them of 3 or more bodies; {} not judged: a body touched a static one, a step "
                              "had no states, or still in contact at the end ({} open)), not on {} group-steps",
                              s.episodes_judged, s.episodes_judged_groups, s.episodes_unjudged + s.episodes.size(),
                              s.episodes.size(), s.energy_soft_steps);
    if (s.groups_locked)
      r.detail += fmt::format("; {} group-frames with a body whose axes are locked (locked_dofs): momentum along "
                              "locked translation axes not judged; {} with a rotation locked: angular momentum not "
                              "judged",
                              s.groups_locked, s.groups_rotation_locked);
    if (r.applicable) {
      fill_causes(r, {{&s.momentum, "momentum", "group-frames", "of bound"},
                      {&s.angular, "angular-momentum", "group-frames", "of bound"},
                      {&s.energy, "energy", "group-frames", "rel"}});
      r.judged = s.groups;
    }
    out.push_back(r);
  }
  // 7. Momentum balance per body.
  {
    ValidationResult r = row("momentum-balance", "bodies whose velocity change is not their rows' impulses",
                             "balance_ulps,gyroscopic_rel,friction_direction_speed");
    r.measured = double(s.balance_lin.failures + s.balance_ang.failures);
    r.pass = r.measured == 0;
    r.applicable = s.balance_lin.checks + s.balance_ang.checks > 0;
    const std::string extras =
        (s.balance_locked ? fmt::format("; {} body-steps with locked axes (those components n/a: a joint's impulses "
                                        "are not in the rows)",
                                        s.balance_locked)
                          : std::string()) +
        (s.balance_no_rows ? fmt::format("; {} body-steps in a confirmed pair without rows, not judged",
                                         s.balance_no_rows)
                           : std::string()) +
        (s.balance_clamped ? fmt::format("; {} body-steps at the declared velocity clamp, not judged",
                                         s.balance_clamped)
                           : std::string());
    if (!s.bodies.impulses_complete) {
      r.applicable = false;
      r.detail = fmt::format("n/a: the record holds the impulses of the first of response.iterations = {} "
                             "relaxation passes (octocd's ContactRecord); the later passes apply more impulses on the "
                             "same pairs, so the rows are not the step's impulses",
                             s.model->scene.response.iterations);
    } else if (!r.applicable) {
      r.detail = s.state_frames ? "no dynamic body with contact rows in a step with states" : "no states";
    } else {
      r.detail = fmt::format("{} body-steps: linear worst {:.3g} of its bound; angular {}", s.balance_lin.checks,
                             s.balance_lin.worst_or(0.0),
                             s.balance_ang.checks
                                 ? fmt::format("{} body-steps, worst {:.3g} of its bound{}", s.balance_ang.checks,
                                               s.balance_ang.worst_or(0.0),
                                               s.bodies.gyroscopic ? " (gyroscopic term declared)" : "")
                                 : s.balance_rot_locked
                                       ? fmt::format("n/a: rotation locked (locked_dofs) on all {} body-steps with "
                                                     "rotation and points",
                                                     s.balance_rot_locked)
                                       : std::string("n/a: no rotation or no contact points (torques unknown)"));
      r.detail += extras;
      fill_causes(r, {{&s.balance_lin, "linear", "body-steps", "of bound"},
                      {&s.balance_ang, "angular", "body-steps", "of bound"}});
      r.judged = s.balance_lin.checks;
    }
    out.push_back(r);
  }
  // 8. Free flight.
  {
    ValidationResult r = row("free-flight", "bodies without contacts not following gravity and their spin",
                             "free_flight_angle_rad,gyroscopic_rel");
    r.measured = double(s.free_vel.failures + s.free_pos.failures + s.free_w.failures + s.free_q.failures);
    r.pass = r.measured == 0;
    r.applicable = s.free_vel.checks > 0;
    if (!r.applicable) {
      r.detail = s.state_frames ? "no dynamic body without contacts in a step with states" : "no states";
    } else {
      r.detail = fmt::format(
          "{} body-steps (integrator {}): worst velocity {:.3g} m/s, position {:.3g} m{}{}", s.free_vel.checks,
          integrator_name(s.bodies.integrator), s.free_vel.worst_or(0.0), s.free_pos.worst_or(0.0),
          s.free_w.checks ? fmt::format(", angular velocity {:.3g} rad/s{} over {}, orientation {:.3g} deg over {}",
                                        s.free_w.worst_or(0.0), s.bodies.gyroscopic ? " (gyroscopic term declared)" : "",
                                        s.free_w.checks, s.free_q.worst_or(0.0), s.free_q.checks)
                          : std::string("; rotation n/a (translation-only records)"),
          s.free_locked ? fmt::format("; {} body-steps with locked axes (those components n/a)", s.free_locked)
                        : std::string());
      fill_causes(r, {{&s.free_vel, "velocity", "body-steps", "m/s"},
                      {&s.free_pos, "position", "body-steps", "m"},
                      {&s.free_w, "angular-velocity", "body-steps", "rad/s"},
                      {&s.free_q, "orientation", "body-steps", "deg"}});
      r.judged = s.free_vel.checks;
    }
    out.push_back(r);
  }
  // Free flight's work is charged to momentum-balance (one pass over the bodies).
  const double seconds[] = {s.t_broad, s.t_complete, s.t_geometry, s.t_pen, s.t_friction, s.t_conservation,
                            s.t_balance, 0.0};
  for (std::size_t i = 0; i < out.size() && i < 8; ++i) out[i].seconds = seconds[i];
  return out;
}

}  // namespace octocd
