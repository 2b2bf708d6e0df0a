/// \file validation_rows.cpp
/// The table of validator rows (octocd/validation_rows.hpp).

#include "octocd/validation_rows.hpp"

namespace octocd {

const std::vector<RowInfo>& validation_rows() {
  using M = RowMerge;
  constexpr Tier P = Tier::Physics, Mo = Tier::Model;
  static const std::vector<RowInfo> rows = {
      // physics tier (validation/physics/)
      {RowId::BroadphaseCompleteness, "broadphase-completeness", P, M::Sum,
       {{"missing-pair", "required pairs", "m"}, {"not-flat", "frames", "pairs"}}},
      {RowId::ContactCompleteness, "contact-completeness", P, M::Sum,
       {{"missing-contact", "penetrating pairs", "m"}, {"false-contact", "contact pairs", "m"}}},
      {RowId::ContactGeometry, "contact-geometry", P, M::Max,
       {{"normal-angle", "rows", "deg"}, {"depth", "pairs", "m"}, {"point-off-shape", "points", "m"}}},
      {RowId::Penetration, "penetration", P, M::Max, {{"penetration", "pair-frames", "m"}}},
      {RowId::Friction, "friction", P, M::Sum, {{"cone", "contacts", "kg m/s"}, {"dissipation", "rows", "m/s"}}},
      {RowId::Conservation, "conservation", P, M::Sum,
       {{"momentum", "group-frames", "of bound"},
        {"angular-momentum", "group-frames", "of bound"},
        {"energy", "group-frames", "rel"}}},
      {RowId::MomentumBalance, "momentum-balance", P, M::Sum,
       {{"linear", "body-steps", "of bound"}, {"angular", "body-steps", "of bound"}}},
      {RowId::FreeFlight, "free-flight", P, M::Sum,
       {{"velocity", "body-steps", "m/s"},
        {"position", "body-steps", "m"},
        {"angular-velocity", "body-steps", "of bound"},
        {"orientation", "body-steps", "deg"},
        {"sleeping", "body-steps", "of rounding"}}},
      // model tier (validation/model/, the scene rows of validation/src/validate.cpp)
      {RowId::CandidateSets, "candidate-sets", Mo, M::Sum, {}},
      {RowId::MidphaseCompleteness, "midphase-completeness", Mo, M::Sum, {}},
      {RowId::NonPenetrationEq14, "non-penetration-eq14", Mo, M::Sum, {}},
      {RowId::FrictionMonotonicity, "friction-monotonicity", Mo, M::Sum, {}},
      {RowId::ImpulseConservation, "impulse-conservation", Mo, M::Sum, {}},
      {RowId::AppliedState, "applied-state", Mo, M::Sum, {}},
      {RowId::Analytic, "analytic", Mo, M::Max, {}},
      {RowId::BulletDynamics, "bullet-dynamics", Mo, M::Max, {{"height", "", "rel"}, {"still-moving", "", "m/s"}}},
  };
  return rows;
}

const RowInfo& row_info(RowId id) { return validation_rows()[static_cast<std::size_t>(id)]; }

const RowInfo* find_row_info(const std::string& name) {
  for (const RowInfo& r : validation_rows())
    if (name == r.name) return &r;
  return nullptr;
}

}  // namespace octocd
