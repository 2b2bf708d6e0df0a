#pragma once
/// \file ode_settings.hpp
/// The settings of the ODE engine (`ode`): which ODE stepper runs, its constraint
/// parameters, how many contacts a pair may get and how friction is bounded. Set from
/// C++ (OdeWorld's constructor) or as KEY=VALUE items (apply_settings); docs/engines.md,
/// "ode", lists them with the ODE parameter each one sets.

#include <cstddef>
#include <string>
#include <vector>

#include "octocd/adapter_rows.hpp"
#include "octocd/pyramid_friction.hpp"

namespace octocd {

/// Which of ODE's steppers advances the world.
enum class OdeStepper {
  /// dWorldStep: every island's constraints as one LCP, solved by ODE's Dantzig solver
  /// (exact up to rounding; cost grows with the cube of an island's rows).
  Step,
  /// dWorldQuickStep: projected Gauss-Seidel (SOR) over the rows, OdeSettings::iterations
  /// sweeps (linear cost; the constraints are met only as well as the sweeps converge).
  QuickStep,
};

/// How a contact's two friction directions are bounded (ODE's dContactApprox1: the
/// friction pyramid, each direction's force within mu_dir times the contact's normal
/// force); Pyramid is ODE's usual set-up.
using OdeFriction = PyramidFriction;

/// Which ODE collision space holds the geoms (the broadphase that hands dSpaceCollide's
/// near callback its pairs).
enum class OdeSpace {
  /// dHashSpaceCreate: ODE's multi-resolution hash grid (levels -3 to 10, ODE's default).
  Hash,
  /// dSweepAndPruneSpaceCreate(dSAP_AXES_XYZ): sweep and prune, sorted on x, then y, z.
  Sap,
  /// dQuadTreeSpaceCreate: a quadtree over the scene's domain in x and y, depth from the
  /// body count (ode_quadtree_depth).
  QuadTree,
  /// Hash for scenes of fewer than kOdeAutoSapBodies bodies, Sap from there on.
  Auto,
};

/// The body count from which OdeSpace::Auto takes sweep and prune instead of the hash
/// grid: 10,000 (every nightly scene is smaller, so keeps dHashSpace's pair order).
constexpr std::size_t kOdeAutoSapBodies = 10000;

/// "hash", "sap", "quadtree" or "auto".
const char* ode_space_name(OdeSpace s);

/// The space a scene of `bodies` bodies gets: `s` itself, or for Auto, Hash below
/// kOdeAutoSapBodies and Sap from there on.
OdeSpace ode_resolved_space(OdeSpace s, std::size_t bodies);

/// The quadtree's depth for `bodies` bodies: about 16 bodies per leaf cell
/// (ceil(log4(bodies / 16))), at least 1 and at most 8.
int ode_quadtree_depth(std::size_t bodies);

/// "step" or "quickstep".
const char* ode_stepper_name(OdeStepper s);
/// "inscribed" or "pyramid".
inline const char* ode_friction_name(OdeFriction f) { return pyramid_friction_name(f); }

/// The ode engine's settings. The defaults are what `octocd run --engine ode` runs:
/// ODE's own defaults (double precision) where ODE has one.
struct OdeSettings {
  /// The stepper (OdeStepper); key `stepper`, values step | quickstep. Default step
  /// (dWorldStep, the exact LCP solve).
  OdeStepper stepper = OdeStepper::Step;
  /// Gauss-Seidel sweeps per step of dWorldQuickStep (dWorldSetQuickStepNumIterations);
  /// key `iterations`, an integer in [1, 10000]. Default 20, ODE's. Read only by the
  /// quickstep stepper.
  int iterations = 20;
  /// Error reduction parameter (dWorldSetERP): the share of a contact's depth the next
  /// step's constraint velocity removes (target normal velocity erp * depth / dt); key
  /// `erp`, a number in [0, 1]. Default 0.2, ODE's.
  double erp = 0.2;
  /// Constraint force mixing (dWorldSetCFM, m s^2/kg per row: how soft every contact
  /// row is); key `cfm`, a number in [0, 1]. Default 1e-10, ODE's in double precision.
  double cfm = 1e-10;
  /// Most contacts dCollide may return for one pair per step (the low 16 bits of its
  /// flags); key `contacts`, an integer in [1, 64]. Default 8 (dBoxBox gives at most 4;
  /// triangle meshes more).
  int max_contacts = 8;
  /// The friction bound (OdeFriction); key `friction`, values inscribed | pyramid.
  /// Default inscribed (the friction vector stays in the Coulomb cone).
  OdeFriction friction = OdeFriction::Inscribed;
  /// ODE's gyroscopic term (dBodySetGyroscopicMode on every dynamic body: the implicit
  /// step of Lacoursiere 2006 that ODE 0.16 applies); key `gyroscopic`, true | false.
  /// Default true, ODE's.
  bool gyroscopic = true;
  /// The collision space (OdeSpace); key `space`, values hash | sap | quadtree | auto.
  /// Default auto: dHashSpace below kOdeAutoSapBodies bodies, sweep and prune from there
  /// (dHashSpace's collide dominates the first frame of 10^5 bodies; docs/engines.md,
  /// "Set-up of large scenes (ODE)"). Another space hands the near callback the same pairs
  /// in another order, so contact rows and the solve differ in the last bits.
  OdeSpace space = OdeSpace::Auto;
};

/// ERP, CFM and QuickStep iterations of a freshly created dWorld (dWorldGetERP,
/// dWorldGetCFM, dWorldGetQuickStepNumIterations) and the gyroscopic mode of a fresh
/// body (dBodyGetGyroscopicMode), the other fields as OdeSettings: the linked ODE's own
/// defaults, which OdeSettings' defaults claim to be.
OdeSettings ode_library_defaults();

/// The ode engine's settings table, one row a key in the struct's order:
/// stepper (step or quickstep), iterations (an integer in [1, 10000]), erp, cfm (a decimal
/// number in [0, 1]), contacts (an integer in [1, 64]), friction (inscribed or pyramid),
/// gyroscopic (true or false), space (hash, sap, quadtree or auto).
/// apply_settings(settings, items, where) (adapter_rows.hpp) sets a OdeSettings from
/// "KEY=VALUE" items (`--ode KEY=VALUE`, repeatable), throwing InputError that names the
/// key, the value and what is allowed; setting_names<OdeSettings>() lists the keys.
template <>
const SettingTable<OdeSettings>& setting_table<OdeSettings>();

}  // namespace octocd
