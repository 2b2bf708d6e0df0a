// Validators 1-6 of SPEC section 7, fed frame by frame from a World.
#include <algorithm>
#include <cmath>
#include <optional>
#include <string>
#include <vector>

#include <fmt/format.h>

#include "octocd/reference_contact.hpp"
#include "octocd/validation.hpp"

namespace octocd {

namespace {

/// Signed overlap of two boxes along `axis` (Eq. 9); negative when apart.
double overlap_along(const Aabb& a, const Aabb& b, int axis) {
  return static_cast<double>(std::min(a.max[axis], b.max[axis])) -
         static_cast<double>(std::max(a.min[axis], b.min[axis]));
}

Aabb shifted(const Aabb& box, Vec3 d) { return {box.min + d, box.max + d}; }

double norm(double x, double y, double z) { return std::sqrt(x * x + y * y + z * z); }

/// Tangential part of v relative to n.
Vec3 tangential(Vec3 v, Vec3 n) { return v - dot(v, n) * n; }

/// Mesh vertices (world) of `s` lying within `margin` of the world box `other`.
std::vector<Vec3> candidates(const PlacedShape& s, const Aabb& other, float margin) {
  std::vector<Vec3> out;
  const Aabb e = expanded(other, margin);
  for (const Vec3& v : s.octree->vertices) {
    const Vec3 w = v + s.position;
    if (contains(e, Aabb{w, w})) out.push_back(w);
  }
  return out;
}

/// The exhaustive vertex test (SPEC 5.3) over candidate vertices only: a vertex farther
/// than theta from the other body's AABB cannot be within theta of any of its vertices,
/// so dropping it changes nothing; the remaining pairs are all tested, with no pruning.
bool exhaustive_oracle(const PlacedShape& a_in, const PlacedShape& b_in, float theta) {
  if (!a_in.octree || !b_in.octree) return exhaustive_contact(a_in, b_in, theta);
  const float margin = 1.01f * theta + 1e-6f;
  const std::vector<Vec3> ca = candidates(a_in, b_in.box, margin);
  if (ca.empty()) return false;
  const std::vector<Vec3> cb = candidates(b_in, a_in.box, margin);
  const float theta2 = theta * theta;
  for (const Vec3& u : ca)
    for (const Vec3& w : cb)
      if (length2(u - w) < theta2) return true;
  return false;
}

/// A running count of checks and failures with the first failure's description.
struct Tally {
  std::uint64_t checks = 0;
  std::uint64_t failures = 0;
  double worst = 0.0;
  std::string first;
  void check(bool ok, double excess, const std::string& what) {
    ++checks;
    worst = std::max(worst, excess);
    if (ok) return;
    if (failures == 0) first = what;
    ++failures;
  }
};

}  // namespace

struct FrameValidators::Impl {
  ValidationOptions options;
  ContactParams params;
  std::unique_ptr<BroadPhase> flat;
  std::vector<std::unique_ptr<BroadPhase>> broadphases;
  std::vector<MidphaseConfig> configs;
  ConfirmFn confirm;
  std::unique_ptr<ReferenceGeometry> reference;
  std::vector<Pair> expected, got;

  Tally candidates, midphase, contraction, friction, momentum, centre;
  std::uint64_t candidate_frames = 0, midphase_pairs = 0, dynamic_pairs = 0;
  std::uint64_t normals = 0, normals_agree = 0;
  std::vector<double> angles;
  std::string normal_first;
  double pen_max = 0.0, share_above_max = 0.0;
};

FrameValidators::FrameValidators(const World& world, const ValidationOptions& options,
                                 std::vector<std::unique_ptr<BroadPhase>> broadphases)
    : impl_(std::make_unique<Impl>()) {
  Impl& s = *impl_;
  s.options = options;
  s.params = world.scene().response;
  BroadPhaseConfig flat_cfg = world.scene().broadphase;
  flat_cfg.name = "flat";
  s.flat = make_broadphase(flat_cfg, world.scene().domain);
  s.broadphases = std::move(broadphases);
  // The paper's configurations A, B, C and the scene's own (SPEC 5.2).
  for (const char* text : {"2", "1,2", "0,1,2"}) s.configs.push_back(MidphaseConfig::parse(text));
  if (!world.scene().midphase.aabb_only &&
      std::none_of(s.configs.begin(), s.configs.end(), [&](const MidphaseConfig& c) {
        return c.levels == world.scene().midphase.levels;
      }))
    s.configs.push_back(world.scene().midphase);
  s.confirm = [](const PlacedShape& a, const PlacedShape& b, float theta, const MidphaseConfig& c,
                 MidphaseStats& st) { return confirm_contact(a, b, theta, c, st); };
  if (options.against_fcl) s.reference = std::make_unique<ReferenceGeometry>(world);
}

FrameValidators::~FrameValidators() = default;

void FrameValidators::set_midphase(ConfirmFn fn) { impl_->confirm = std::move(fn); }

void FrameValidators::observe(const World& world, bool checked) {
  Impl& s = *impl_;
  const std::int64_t frame = world.frame();
  const std::vector<Aabb>& boxes = world.world_aabbs();
  const BodyState& st = world.state();
  const ContactParams& p = s.params;
  const Tolerances& tol = s.options.tol;
  auto pre_position = [&](std::uint32_t i) {
    return boxes[i].min - world.shapes()[world.bodies()[i].shape].local.min;
  };
  auto placed = [&](std::uint32_t i) {
    const Shape& shape = world.shapes()[world.bodies()[i].shape];
    return PlacedShape{shape.octree.get(), pre_position(i), boxes[i]};
  };

  const FrameMetrics& m = world.last_metrics();
  s.pen_max = std::max(s.pen_max, m.penetration_max);
  s.share_above_max = std::max(s.share_above_max, m.penetration_share_above_slop);

  if (checked) {
    // 1. Candidate sets: every broadphase equals `flat` as a set (SPEC 7.1).
    BroadPhaseStats bs;
    s.flat->find_pairs(boxes, s.expected, bs);
    ++s.candidate_frames;
    for (auto& bp : s.broadphases) {
      bp->find_pairs(boxes, s.got, bs);
      const bool same = s.got == s.expected;
      std::string what;
      if (!same) {
        std::vector<Pair> missing, extra;
        std::set_difference(s.expected.begin(), s.expected.end(), s.got.begin(), s.got.end(),
                            std::back_inserter(missing));
        std::set_difference(s.got.begin(), s.got.end(), s.expected.begin(), s.expected.end(),
                            std::back_inserter(extra));
        const bool miss = !missing.empty();
        const Pair q = miss ? missing.front() : (extra.empty() ? Pair{} : extra.front());
        what = fmt::format("frame {}: {} {} pair ({}, {}) ({} missing, {} extra)", frame, bp->name(),
                           miss ? "misses" : "adds", q.a, q.b, missing.size(), extra.size());
      }
      s.candidates.check(same, same ? 0.0 : 1.0, what);
    }

    // 2. Midphase completeness: every level list equals the exhaustive test (SPEC 7.2).
    {
      for (const Pair& q : s.expected) {
        if (st.w[q.a] == 0.0f && st.w[q.b] == 0.0f) continue;
        const std::uint32_t sa = world.bodies()[q.a].shape, sb = world.bodies()[q.b].shape;
        const PlacedShape a = placed(q.a), b = placed(q.b);
        const float theta = world.theta(sa, sb);
        const bool truth = exhaustive_oracle(a, b, theta);
        ++s.midphase_pairs;
        for (const MidphaseConfig& c : s.configs) {
          MidphaseStats ms;
          const bool got = s.confirm(a, b, theta, c, ms);
          s.midphase.check(got == truth, got == truth ? 0.0 : 1.0,
                           fmt::format("frame {}: midphase {} says {} for pair ({}, {}), "
                                       "exhaustive says {}",
                                       frame, c.to_string(), got, q.a, q.b, truth));
        }
      }
    }

    // 3. Contact normals against FCL (SPEC 7.3).
    if (s.reference) {
      for (const ContactRecord& c : world.contacts()) {
        const ReferenceNormal r = s.reference->normal(c.pair.a, c.pair.b, pre_position(c.pair.a),
                                                      pre_position(c.pair.b));
        if (!r.valid) continue;
        ++s.normals;
        const bool agree = dot(c.normal, r.normal) > 0.0f;
        if (agree) {
          ++s.normals_agree;
        } else if (s.normal_first.empty()) {
          s.normal_first = fmt::format(
              "frame {}: pair ({}, {}) normal ({}, {}, {}) vs FCL ({:.3f}, {:.3f}, {:.3f}) {}",
              frame, c.pair.a, c.pair.b, c.normal.x, c.normal.y, c.normal.z, r.normal.x,
              r.normal.y, r.normal.z, r.penetrating ? "(EPA)" : "(distance)");
        }
        s.angles.push_back(angle_between(c.normal, r.normal));
      }
    }
  }

  for (const ContactRecord& c : world.contacts()) {
    const float wa = st.w[c.pair.a], wb = st.w[c.pair.b];
    // 4. Non-penetration contraction (Eq. 14, section 3.3.3), this contact's own
    // correction only: d' - delta <= (1 - alpha beta)(d - delta) and no overshoot past
    // the slop (the sequence is monotone).
    {
      const double d = overlap_along(boxes[c.pair.a], boxes[c.pair.b], c.axis);
      const double d1 = overlap_along(shifted(boxes[c.pair.a], c.dx_a),
                                      shifted(boxes[c.pair.b], c.dx_b), c.axis);
      const double slop = p.slop;
      const double rate = 1.0 - static_cast<double>(p.alpha) * p.beta;
      double excess = 0.0;
      bool ok = true;
      if (wa + wb > 0.0f) {
        if (d > slop) {
          excess = std::max(d1 - slop - rate * (d - slop), (slop - d1));
          ok = d1 - slop <= rate * (d - slop) + tol.contraction_m && d1 - slop >= -tol.contraction_m;
        } else {
          excess = std::fabs(d1 - d);
          ok = excess <= tol.contraction_m;
        }
      }
      s.contraction.check(ok, std::max(excess, 0.0),
                          fmt::format("frame {}: pair ({}, {}) depth {:.6g} -> {:.6g} m (slop {}, "
                                      "alpha beta {})",
                                      frame, c.pair.a, c.pair.b, d, d1, p.slop, p.alpha * p.beta));
    }
    // 5. Friction: no rise of the relative tangential speed, |J_t| <= mu_s J_n (3.3.2).
    {
      const Vec3 before = tangential(c.v_a - c.v_b, c.normal);
      const Vec3 after = tangential((c.v_a + c.dv_a) - (c.v_b + c.dv_b), c.normal);
      const double rise = static_cast<double>(length(after)) - length(before);
      const double cone = std::fabs(c.jt) - static_cast<double>(p.mu_static) * c.jn;
      const bool ok = rise <= tol.friction_speed &&
                      cone <= tol.friction_cone_rel * static_cast<double>(p.mu_static) * c.jn + 1e-9;
      s.friction.check(ok, std::max(rise, cone),
                       fmt::format("frame {}: pair ({}, {}) |v_t| {:.6g} -> {:.6g} m/s, |J_t| {:.6g} "
                                   "vs mu_s J_n {:.6g}",
                                   frame, c.pair.a, c.pair.b, length(before), length(after),
                                   std::fabs(c.jt), p.mu_static * c.jn));
    }
    // 6. Conservation per dynamic-dynamic contact: momentum and mass-weighted centre.
    if (wa > 0.0f && wb > 0.0f) {
      ++s.dynamic_pairs;
      const double ma = 1.0 / wa, mb = 1.0 / wb;
      auto check_pair = [&](Tally& t, Vec3 da, Vec3 db, double rel, const char* what) {
        const double sx = ma * da.x + mb * db.x, sy = ma * da.y + mb * db.y,
                     sz = ma * da.z + mb * db.z;
        const double scale = ma * length(da) + mb * length(db);
        const double residual = norm(sx, sy, sz);
        const double share = scale > 0 ? residual / scale : 0.0;
        t.check(residual <= rel * scale + 1e-9, share,
                fmt::format("frame {}: pair ({}, {}) {} changes by {:.3g} ({:.3g} of the exchange)",
                            frame, c.pair.a, c.pair.b, what, residual, share));
      };
      check_pair(s.momentum, c.dv_a, c.dv_b, tol.momentum_rel, "momentum");
      check_pair(s.centre, c.dx_a, c.dx_b, tol.centre_rel, "mass-weighted centre");
    }
  }
}

std::vector<ValidationResult> FrameValidators::results() const {
  const Impl& s = *impl_;
  std::vector<ValidationResult> out;
  auto tally = [](const char* name, const char* figure, const Tally& t, const std::string& ok_note) {
    ValidationResult r;
    r.name = name;
    r.figure = figure;
    r.measured = static_cast<double>(t.failures);
    r.bound = 0;
    r.pass = t.failures == 0;
    r.applicable = t.checks > 0;
    r.detail = t.failures ? t.first : fmt::format("{} checks; {}", t.checks, ok_note);
    return r;
  };
  {
    std::string names = "flat vs";
    for (const auto& bp : s.broadphases) names += " " + bp->name();
    out.push_back(tally("candidate-sets", "frames x broadphases differing from flat", s.candidates,
                        fmt::format("{} frames, {}", s.candidate_frames, names)));
  }
  {
    std::string cfgs;
    for (const auto& c : s.configs) cfgs += (cfgs.empty() ? "" : " ") + std::string("[") + c.to_string() + "]";
    out.push_back(tally("midphase-completeness", "pair x level lists differing from exhaustive",
                        s.midphase, fmt::format("{} pairs, lists {}", s.midphase_pairs, cfgs)));
  }
  {
    ValidationResult r;
    r.name = "contact-normals";
    r.figure = "sign agreement with FCL (share)";
    r.applicable = s.normals > 0;
    r.measured = s.normals ? static_cast<double>(s.normals_agree) / static_cast<double>(s.normals) : 1.0;
    r.bound = s.options.tol.normal_sign_agreement;
    r.pass = r.measured >= r.bound;
    std::vector<double> a = s.angles;
    std::sort(a.begin(), a.end());
    const double deg = 180.0 / 3.14159265358979323846;
    double mean = 0;
    for (double x : a) mean += x;
    if (!a.empty()) mean /= static_cast<double>(a.size());
    r.detail = s.reference == nullptr
                   ? "FCL not requested (--against)"
                   : fmt::format("{} contacts; angle mean {:.1f} deg, median {:.1f}, p95 {:.1f}, max {:.1f}{}",
                                 s.normals, mean * deg, a.empty() ? 0.0 : a[a.size() / 2] * deg,
                                 a.empty() ? 0.0 : a[a.size() * 95 / 100] * deg,
                                 a.empty() ? 0.0 : a.back() * deg,
                                 s.normal_first.empty() ? "" : "; first disagreement " + s.normal_first);
    out.push_back(r);
  }
  out.push_back(tally("non-penetration", "contacts violating Eq. 14 contraction", s.contraction,
                      fmt::format("worst excess {:.3g} m; AABB penetration max {:.4g} m, share above "
                                  "slop up to {:.2f}",
                                  s.contraction.worst, s.pen_max, s.share_above_max)));
  out.push_back(tally("friction", "contacts raising |v_t| or leaving the cone", s.friction,
                      fmt::format("worst excess {:.3g}", s.friction.worst)));
  {
    ValidationResult r = tally("conservation", "dynamic contacts breaking momentum or centre",
                               Tally{}, "");
    r.measured = static_cast<double>(s.momentum.failures + s.centre.failures);
    r.pass = r.measured == 0;
    r.applicable = s.dynamic_pairs > 0;
    r.detail = !s.momentum.first.empty() ? s.momentum.first
               : !s.centre.first.empty() ? s.centre.first
                                         : fmt::format("{} dynamic contacts; worst relative residual "
                                                       "momentum {:.3g}, centre {:.3g}",
                                                       s.dynamic_pairs, s.momentum.worst, s.centre.worst);
    out.push_back(r);
  }
  return out;
}

}  // namespace octocd
