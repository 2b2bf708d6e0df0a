// The physics tier's table (physics_impl.hpp): results(), each row's verdict, figure,
// detail and causes from the tallies the rows filled.
#include "physics_impl.hpp"

#include <algorithm>
#include <initializer_list>
#include <stdexcept>

#include "octocd/validation_rows.hpp"

namespace octocd {

using namespace physics_detail;

namespace {

/// The row's failures by cause (causes with failures only), its judged count, its verdict
/// and n/a when it judged nothing: the detail gets "; causes: ..." listing every cause.
/// `tallies` are the tallies of `row`'s causes (validation_rows.hpp), in their order.
void fill_causes(ValidationResult& r, const RowInfo& row, std::initializer_list<const Tally*> tallies) {
  if (tallies.size() != row.causes.size())
    throw std::logic_error(fmt::format("physics table: row {} has {} causes, given {} tallies", row.name,
                                       row.causes.size(), tallies.size()));
  std::string list;
  std::uint64_t failing = 0, judged = 0;
  const RowCause* c = row.causes.data();
  for (const Tally* t : tallies) {
    judged += t->checks;
    if (t->failures) {
      r.causes.push_back(t->cause(c->name, c->unit));
      ++failing;
    }
    list += (list.empty() ? "" : "; ") + t->summary(c->name, c->items, c->unit);
    ++c;
  }
  r.judged = judged;
  if (failing) {
    r.pass = false;
    r.detail += "; causes: " + list;
  }
}

/// " (gyroscopic term declared)", " (no gyroscopic term declared)", or undeclared how
/// many passing body-steps kept w (no term) and how many met the invariants of the term.
std::string spin_note(PhysicsBodies::Gyroscopic g, std::uint64_t kept, std::uint64_t invariant) {
  switch (g) {
    case PhysicsBodies::Gyroscopic::Integrated: return " (gyroscopic term declared)";
    case PhysicsBodies::Gyroscopic::Absent: return " (no gyroscopic term declared)";
    case PhysicsBodies::Gyroscopic::Undeclared: break;
  }
  return fmt::format(" (gyroscopic term undeclared: {} kept w, {} precessed keeping L and the energy; declare "
                     "gyroscopic to sharpen the verdict)",
                     kept, invariant);
}

}  // namespace

std::vector<ValidationResult> PhysicsValidators::results() const {
  const Impl& s = *impl_;
  std::vector<ValidationResult> out;
  auto row = [](const RowInfo& info, const char* figure, const char* tolerances) {
    ValidationResult r;
    r.tier = info.tier;
    r.name = info.name;
    r.figure = figure;
    r.tolerances = tolerances;
    return r;
  };
  const std::string no_checked =
      "no checked frame with poses (AABBs or detection poses; a trace: add /states/position and /states/velocity, or "
      "/aabbs/min and /aabbs/max)";

  // 1. Broadphase completeness.
  {
    const RowInfo& info = row_info(RowId::BroadphaseCompleteness);
    ValidationResult r = row(info, "required pairs missing from the engine's candidates",
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
      r.detail = s.broad_no_pairs ? "the engine gave no candidate pairs (has_pairs false; a trace: add /pairs/offsets "
                                    "and /pairs/pair)"
                                  : no_checked;
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
    if (s.broad_asleep)
      r.detail += fmt::format("; {} pair-frames of bodies asleep before the step (/states/sleeping) not required",
                              s.broad_asleep);
    if (r.applicable)
      fill_causes(r, info, {&s.broad, &s.broad_exact});
    out.push_back(r);
  }
  // 2. Contact completeness.
  {
    const RowInfo& info = row_info(RowId::ContactCompleteness);
    ValidationResult r = row(info, "penetrating pairs without a contact + false contacts",
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
    if (s.bodies.speculative)
      r.detail += fmt::format("; speculative contacts declared: {} contact pair-frames allowed the pair's approach "
                              "within the step beyond the margin",
                              s.speculative_allowed);
    if (s.complete_asleep)
      r.detail += fmt::format("; {} penetrating pair-frames of bodies asleep before the step (/states/sleeping) "
                              "without a row, not required",
                              s.complete_asleep);
    if (s.complete_unproven)
      r.detail += fmt::format("; {} non-convex pair-frames without a row penetrate by an upper bound above "
                              "contact_depth_m that no vertex inside the other shape proves, n/a (largest: {})",
                              s.complete_unproven, s.complete_unproven_what);
    if (r.applicable)
      fill_causes(r, info, {&s.complete, &s.false_contact});
    out.push_back(r);
  }
  // 3. Contact geometry.
  {
    const RowInfo& info = row_info(RowId::ContactGeometry);
    ValidationResult r = row(info, "worst normal angle to the reference's (deg; SAT or FCL)",
                             "normal_angle_deg,depth_m,sat_accept_rel");
    r.measured = s.normal_angle.worst_or(0.0);
    r.bound = s.tol.normal_angle_deg;
    r.pass = s.normal_angle.failures == 0 && s.depth.failures == 0 && s.points.failures == 0;
    r.applicable = s.normal_angle.checks + s.depth.checks + s.points.checks > 0;
    const bool aabb = s.bodies.contact_geometry == ContactGeometry::Aabb;
    if (aabb) {
      r.figure = "worst normal angle to box-box on the world AABBs (deg; its sign judged)";
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
        r.detail += "; most normals point from A to B: the convention is from B to A (design.md section 2)";
    } else if (s.depth.failures) {
      r.detail = s.depth.worst_what + fmt::format(" (depth off by more than {} m on {} of {} pairs)", s.tol.depth_m,
                                                  s.depth.failures, s.depth.checks);
    } else if (s.points.failures) {
      r.detail = s.points.worst_what + fmt::format(" (points off the shapes by more than {} m on {} of {} rows)",
                                                   s.tol.depth_m, s.points.failures, s.points.checks);
    } else if (aabb) {
      r.detail = fmt::format("normal angle n/a: the engine resolves contacts on world AABBs (its normal is an AABB "
                             "axis; its angle to box-box on the same boxes judges nothing about the shapes: worst "
                             "{:.3g} deg over {} rows, a figure; its sign is judged on {} rows); depth of {} pairs "
                             "judged against box-box on the world AABBs: worst difference {:.3g} m; {}{}",
                             s.aabb_angle_worst, s.aabb_angle_rows, s.normal_angle.checks, s.depth.checks,
                             s.depth.worst_or(0.0), sign, stats);
    } else {
      r.detail = fmt::format("{} rows judged{} ({}): worst angle {:.3g} deg, worst depth difference {:.3g} m{}{}; {}{}",
                             s.normal_angle.checks, aabb ? " on the world AABBs" : "",
                             aabb ? std::string("box-box")
                                  : fmt::format("reference: SAT on {} convex pair-frames, box-box or FCL (EPA, distance "
                                                "or the non-convex BVH bound) on {}",
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
      if (s.sign_uncertain_rows)
        r.detail += fmt::format("; {} rows on convex hulls that FCL calls apart along an axis that does not "
                                "separate them: sign not judged",
                                s.sign_uncertain_rows);
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
      fill_causes(r, info, {&s.normal_angle, &s.depth, &s.points});
    if (s.points_persistent)
      r.detail += fmt::format("; manifold_points \"persistent\": {} row points not judged (they ride on each body "
                              "and may drift off the shapes)",
                              s.points_persistent);
    if (s.depth_unknown_pairs)
      r.detail += fmt::format("; depth n/a on {} pairs: depth_per \"unknown\" (the rows carry no depth; penetration "
                              "is judged on the posed shapes)",
                              s.depth_unknown_pairs);
    if (s.depth_manifold_pairs)
      r.detail += fmt::format("; depth_per \"manifold\": {} convex pairs' one depth judged against the hulls' overlap "
                              "along the manifold's normal",
                              s.depth_manifold_pairs);
    if (s.depth_spared_as_manifold)
      r.detail += fmt::format("; depth_per undeclared: {} pairs' depth fits the hulls' overlap along the row's normal "
                              "(a manifold's depth), not SAT's minimum: passed; declare depth_per to sharpen the "
                              "verdict",
                              s.depth_spared_as_manifold);
    if (s.rounded_pairs)
      r.detail += fmt::format("; {} pair-frames judged on shapes rounded by /bodies/convex_radius", s.rounded_pairs);
    out.push_back(r);
  }
  // 4. Penetration.
  {
    const RowInfo& info = row_info(RowId::Penetration);
    ValidationResult r = row(info, "largest true penetration (m)",
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
    if (r.applicable) fill_causes(r, info, {&s.pen});
    out.push_back(r);
  }
  // 5. Friction.
  {
    const RowInfo& info = row_info(RowId::Friction);
    ValidationResult r = row(info, "contacts outside the cone or rows raising the tangential speed",
                             "friction_cone_abs,friction_speed");
    r.measured = double(s.cone.failures + s.dissipation.failures);
    r.pass = r.measured == 0;
    r.applicable = s.cone.checks > 0;
    if (s.cone.failures) {
      r.detail = s.cone.first + fmt::format(" ({} of {} contacts outside the cone)", s.cone.failures, s.cone.checks);
    } else if (s.dissipation.failures) {
      r.detail = s.dissipation.first + fmt::format(" ({} of {} rows where friction raises the sliding)",
                                                   s.dissipation.failures, s.dissipation.checks);
    } else if (s.bodies.impulses != PhysicsBodies::Impulses::Complete) {
      r.detail = fmt::format("n/a: the trace declares impulses = \"{}\": its rows carry no friction impulse, so the "
                             "cone and dissipation are not judged (on the zeros a writer puts in jt, jt3 they would "
                             "pass vacuously){}",
                             impulses_name(s.bodies.impulses),
                             s.bodies.impulses == PhysicsBodies::Impulses::NormalOnly
                                 ? "; momentum-balance holds each body's residual within its rows' cones"
                                 : "");
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
      fill_causes(r, info, {&s.cone, &s.dissipation});
    out.push_back(r);
  }
  // 6. Conservation.
  {
    const RowInfo& info = row_info(RowId::Conservation);
    ValidationResult r = row(info, "isolated groups breaking momentum, angular momentum or energy",
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
                                : "no states (a trace: add /states/position and /states/velocity)";
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
    if (!s.bodies.contacts_complete)
      r.detail += fmt::format("; contacts_complete 0: {} group-frames near a body outside them (shapes within the "
                              "margin and the step's motion by the exact reference) not judged, an unreported contact "
                              "may join them",
                              s.groups_near);
    if (s.groups_angular_unreported)
      r.detail += fmt::format("; angular momentum not judged on {} group-frames: the trace declares impulses = "
                              "\"none\" (the witness-point lever of a row needs its impulse)",
                              s.groups_angular_unreported);
    if (s.groups_clamped)
      r.detail += fmt::format("; {} group-frames not judged (a body at the declared velocity clamp {} m/s)",
                              s.groups_clamped, s.bodies.velocity_clamp);
    if (s.groups_asleep)
      r.detail += fmt::format("; {} group-frames not judged (a body asleep before or after the step: "
                              "/states/sleeping)",
                              s.groups_asleep);
    if (s.bodies.contact_model == PhysicsBodies::ContactModel::Undeclared && s.restitution_le_1)
      r.detail += fmt::format("; contact_model undeclared: energy judged as rigid (per step) and as soft (per contact "
                              "episode: {} judged, {} not), a failure only where both fail ({} steps raising the "
                              "kinetic energy spared: their episode's energy did not rise or was not judged); declare "
                              "contact_model to sharpen the verdict",
                              s.episodes_judged, s.episodes_unjudged + s.owned_open(), s.rigid_rises_spared);
    if (s.bodies.contact_model == PhysicsBodies::ContactModel::Soft)
      r.detail += fmt::format("; contact_model soft: energy judged per contact episode of an isolated group, "
                              "from its first contact until none of its bodies touches another ({} episodes judged, "
                              "{} of them of 3 or more bodies; {} not judged: a body touched a static one, it began "
                              "in contact ({}: a pair touching in the step before, its soft contact's stored energy "
                              "unseen), a step had no states, or still in contact at the end ({} open)), not on {} "
                              "group-steps",
                              s.episodes_judged, s.episodes_judged_groups, s.episodes_unjudged + s.owned_open(),
                              s.episodes_begun_in_contact, s.owned_open(), s.energy_soft_steps);
    if (s.groups_locked)
      r.detail += fmt::format("; {} group-frames with a body whose axes are locked (locked_dofs): momentum along "
                              "locked translation axes not judged; {} with a rotation locked: angular momentum not "
                              "judged",
                              s.groups_locked, s.groups_rotation_locked);
    if (r.applicable) {
      fill_causes(r, info, {&s.momentum, &s.angular, &s.energy});
      r.judged = s.groups;
    }
    out.push_back(r);
  }
  // 7. Momentum balance per body.
  {
    const RowInfo& info = row_info(RowId::MomentumBalance);
    ValidationResult r = row(info, "bodies whose velocity change is not their rows' impulses",
                             "balance_ulps,friction_direction_speed");
    // The linear balance judged at the fitted systematic ratio too, and the ratio itself
    // (docs/validation.md, "A systematic impulse ratio").
    const auto fit = s.balance_fit();
    const Tally lin = s.fitted_balance(fit), bias = s.balance_bias(fit);
    r.measured = double(lin.failures + s.balance_ang.failures + bias.failures);
    r.pass = r.measured == 0;
    r.applicable = lin.checks + s.balance_ang.checks > 0;
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
                           : std::string()) +
        (s.fell_asleep ? fmt::format("; {} body-steps falling asleep (/states/sleeping: the engine zeroed the "
                                     "velocity), not judged",
                                     s.fell_asleep)
                       : std::string());
    if (s.bodies.impulses == PhysicsBodies::Impulses::None) {
      r.applicable = false;
      r.detail = "n/a: the trace declares impulses = \"none\" (the engine reports no impulse): a body's velocity "
                 "change cannot be held to its rows' impulses; conservation judges the isolated groups";
    } else if (!s.bodies.contacts_complete) {
      r.applicable = false;
      r.detail = fmt::format("n/a: the trace declares contacts_complete = 0: {} body-steps in contact not judged (a "
                             "row the engine did not report would read as a fault); free-flight and conservation "
                             "judge the bodies and groups the geometry shows apart",
                             s.balance_incomplete);
    } else if (!s.bodies.impulses_complete) {
      r.applicable = false;
      r.detail = fmt::format("n/a: the record holds the impulses of the first of response.iterations = {} "
                             "relaxation passes (octocd's ContactRecord); the later passes apply more impulses on the "
                             "same pairs, so the rows are not the step's impulses",
                             s.model->scene.response.iterations);
    } else if (!r.applicable) {
      r.detail = s.state_frames ? "no dynamic body with contact rows in a step with states"
                                : "no states (a trace: add /states/position and /states/velocity)";
    } else {
      r.detail = fmt::format("{} body-steps: linear worst {:.3g} of its bound; angular {}", lin.checks,
                             lin.worst_or(0.0),
                             s.balance_ang.checks
                                 ? fmt::format("{} body-steps, worst {:.3g} of its bound{}", s.balance_ang.checks,
                                               s.balance_ang.worst_or(0.0), spin_note(s.bodies.gyroscopic, s.balance_ang_plain,
                                                                                      s.balance_ang_invariant))
                                 : s.balance_rot_locked
                                       ? fmt::format("n/a: rotation locked (locked_dofs) on all {} body-steps with "
                                                     "rotation and points",
                                                     s.balance_rot_locked)
                                       : std::string("n/a: no rotation or no contact points (torques unknown)"));
      r.detail += extras;
      r.detail +=
          fit.fitted
              ? fmt::format("; impulse ratio {:.5f} (reported impulses over the momentum change: the median over {} "
                            "body-steps, quartiles {:.5f} .. {:.5f}; {}), the linear balance judged at 1 and at it: "
                            "{} body-steps failing at 1 pass at it",
                            fit.ratio, fit.samples, fit.q1, fit.q3,
                            fit.bias ? fmt::format("beyond the {:.3g}% a systematic ratio may take", 100.0 * s.kBiasMax)
                                     : fmt::format("within the {:.3g}% a systematic ratio may take", 100.0 * s.kBiasMax),
                            s.deferred.size() - (lin.failures - s.balance_lin.failures))
              : fmt::format("; impulse ratio not fitted ({} body-steps fix it to {:.3g}, {} needed)", fit.samples,
                            s.kFitPrecision, s.kFitMinSamples);
      if (s.deferred_over)
        r.detail += fmt::format("; {} failing body-steps beyond the {} kept for the fit judged at ratio 1",
                                s.deferred_over, s.kMaxDeferred);
      if (s.bodies.impulses == PhysicsBodies::Impulses::NormalOnly)
        r.detail += "; impulses \"normal-only\": each body's residual m (v' - v) - m g dt - sum jn n within the sum "
                    "of its rows' cones (mu jn), jt and jt3 not read";
      fill_causes(r, info, {&lin, &s.balance_ang, &bias});
      r.judged = lin.checks;
    }
    out.push_back(r);
  }
  // 8. Free flight.
  {
    const RowInfo& info = row_info(RowId::FreeFlight);
    ValidationResult r = row(info, "bodies without contacts not following gravity and their spin",
                             "free_flight_angle_rad");
    r.measured = double(s.free_vel.failures + s.free_pos.failures + s.free_w.failures + s.free_q.failures +
                        s.free_sleep.failures);
    r.pass = r.measured == 0;
    r.applicable = s.free_vel.checks + s.free_sleep.checks > 0;
    if (!r.applicable) {
      r.detail = s.state_frames ? "no dynamic body without contacts in a step with states"
                                : "no states (a trace: add /states/position and /states/velocity)";
    } else if (s.free_vel.checks == 0) {
      r.detail = fmt::format("no body-step in free flight; {} asleep body-steps (/states/sleeping)",
                             s.free_sleep.checks);
    } else {
      r.detail = fmt::format(
          "{} body-steps (integrator {}): worst velocity {:.3g} m/s, position {:.3g} m{}{}", s.free_vel.checks,
          integrator_name(s.bodies.integrator), s.free_vel.worst_or(0.0), s.free_pos.worst_or(0.0),
          s.free_w.checks ? fmt::format(", spin (angular velocity) {:.3g} of its bound{} over {}, orientation {:.3g} "
                                        "deg over {}",
                                        s.free_w.worst_or(0.0), spin_note(s.bodies.gyroscopic, s.free_spin_kept, s.free_spin_invariant),
                                        s.free_w.checks, s.free_q.worst_or(0.0), s.free_q.checks)
                          : std::string("; rotation n/a (translation-only records)"),
          s.free_locked ? fmt::format("; {} body-steps with locked axes (those components n/a)", s.free_locked)
                        : std::string());
      if (s.bodies.integrator == PhysicsBodies::Integrator::Undeclared)
        r.detail += "; integrator undeclared: x' = x + dt v + a g dt^2 for every a in [0, 1] and substepping's "
                    "orientation, a failure only where every integrator fails (declare integrator, and substeps, to "
                    "sharpen the verdict)";
    }
    if (!s.bodies.contacts_complete)
      r.detail += fmt::format("; contacts_complete 0: only bodies the exact reference shows apart from every other "
                              "body through the step (beyond the margin and both bodies' motion) are judged free; {} "
                              "body-steps without rows but near a body not judged ({} pairs tested)",
                              s.free_near, s.near_tested);
    if (r.applicable) {
      if (s.free_sleep.checks + s.fell_asleep)
        r.detail += fmt::format("; {} body-steps asleep through the step judged not to move (worst {:.3g} of one "
                                "rounding), {} falling asleep not judged (/states/sleeping)",
                                s.free_sleep.checks, s.free_sleep.worst_or(0.0), s.fell_asleep);
      fill_causes(r, info, {&s.free_vel, &s.free_pos, &s.free_w, &s.free_q, &s.free_sleep});
      r.judged = s.free_vel.checks + s.free_sleep.checks;
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
