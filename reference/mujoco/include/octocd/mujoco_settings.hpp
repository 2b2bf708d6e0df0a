#pragma once
/// \file mujoco_settings.hpp
/// The settings of the MuJoCo engine (`mujoco`): the constraint solver's iterations, the
/// friction cone, the contact spring's time constant, the contact margin and multi-point
/// convex collisions. Set in C++ (MujocoWorld's constructor) or as KEY=VALUE items
/// (apply_settings), like the Bullet engine's (bullet_settings.hpp);
/// docs/engines.md ("mujoco") says what each maps to in MuJoCo.

#include <string>
#include <vector>

#include "octocd/adapter_rows.hpp"

namespace octocd {

/// MuJoCo's friction cone (mjOption::cone).
enum class MujocoCone {
  /// mjCONE_ELLIPTIC (the default here): |f_t| <= mu f_n exactly, the Coulomb cone the
  /// physics tier judges.
  Elliptic,
  /// mjCONE_PYRAMIDAL (MuJoCo's own default): 2 (condim - 1) = 4 edge directions
  /// mu-scaled; mj_contactForce converts the pyramid's forces back to the contact frame.
  Pyramidal,
};

/// "elliptic" or "pyramidal".
const char* mujoco_cone_name(MujocoCone c);

/// The mujoco engine's settings. The defaults are what `octocd run --engine mujoco` runs.
struct MujocoSettings {
  /// Main solver iterations per step (mjOption::iterations, `<option iterations>`); key
  /// `iterations`, an integer in [1, 10000]. Default 100, MuJoCo's.
  int iterations = 100;
  /// Friction cone (mjOption::cone); key `cone`, values elliptic | pyramidal.
  MujocoCone cone = MujocoCone::Elliptic;
  /// Time constant of every contact's spring-damper (s): the first number of each geom's
  /// `solref` (timeconst, dampratio); key `timeconst`, a decimal number in [0, 1]. 0 (the
  /// default): 2 dt / dampratio, so the contact spring's natural frequency
  /// 1 / (timeconst dampratio) is 1 / (2 dt) whatever the restitution (a stiffer spring
  /// is not integrated stably by the explicit step: box-stack at e = 0.5 with
  /// timeconst = 2 dt flew apart); with e = 0 (dampratio 1) that is 2 dt, the smallest
  /// value MuJoCo keeps (mjDSBL_REFSAFE off: it raises smaller ones to 2 dt). MuJoCo's own
  /// default is 0.02 s.
  double timeconst = 0.0;
  /// Contact margin (m): every geom's `margin`, with `gap` equal to it, so pairs up to
  /// this distance apart are reported as contact rows (excluded from the solver: no
  /// force) and only penetrating rows act; key `margin`, a number in [0, 0.1]. Default 0:
  /// only penetrating contacts.
  double margin = 0.0;
  /// Multi-point convex collisions (mjENBL_MULTICCD, `<flag multiccd="enable"/>`): a
  /// hull or box resting on a face gets several contact points instead of MPR's one;
  /// key `multiccd`, values on | off. Default on.
  bool multiccd = true;
  /// Contact capacity (`<size nconmax>`; the constraint rows njmax follow: 3 per contact
  /// with the elliptic cone, 4 with the pyramidal one); key `max_contacts`, an integer in
  /// [0, 1000000]. 0 (the default): 6 per dynamic body, at least 256, at most 1500, and at
  /// most what keeps njmax x nv x 8 bytes within 2^29 (MuJoCo 2.2 allocates several njmax x
  /// nv arrays in one buffer sized as an int: docs/engines.md); a step that finds more
  /// contacts throws RuntimeError naming this key (MuJoCo would drop them).
  int max_contacts = 0;
};

/// The mujoco engine's settings table, one row a key in the struct's order:
/// iterations (an integer in [1, 10000]), cone (elliptic or pyramidal), timeconst (a
/// decimal number in [0, 1]), margin (a decimal number in [0, 0.1]), multiccd (on or off),
/// max_contacts (an integer in [0, 1000000]).
/// apply_settings(settings, items, where) (adapter_rows.hpp) sets a MujocoSettings from
/// "KEY=VALUE" items (`--mujoco KEY=VALUE`, repeatable), throwing InputError that names the
/// key, the value and what is allowed; setting_names<MujocoSettings>() lists the keys.
template <>
const SettingTable<MujocoSettings>& setting_table<MujocoSettings>();

}  // namespace octocd
