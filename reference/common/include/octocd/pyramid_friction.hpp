#pragma once
/// \file pyramid_friction.hpp
/// How a reference engine bounds a contact's two friction directions when it solves a
/// friction pyramid (each direction's impulse within mu_dir times the contact's normal
/// impulse: ODE's dContactApprox1, DART's ContactConstraint): the setting `friction` of
/// the ode and dart engines (docs/settings.md).

namespace octocd {

/// mu_dir of a friction pyramid against the Coulomb cone of mu.
enum class PyramidFriction {
  /// mu_dir = mu / sqrt(2) in both directions: the pyramid inscribed in the Coulomb cone,
  /// so the friction vector never leaves the cone (sliding along one direction: 0.707 mu).
  Inscribed,
  /// mu_dir = mu in both directions: sliding along a direction gets mu, but along the
  /// pyramid's diagonal up to sqrt(2) mu, outside the cone.
  Pyramid,
};

/// "inscribed" or "pyramid".
inline const char* pyramid_friction_name(PyramidFriction f) {
  return f == PyramidFriction::Pyramid ? "pyramid" : "inscribed";
}

}  // namespace octocd
