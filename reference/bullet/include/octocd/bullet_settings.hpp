#pragma once
/// \file bullet_settings.hpp
/// The settings of the Bullet engine (`bullet`, design.md section 15): what geometry Bullet collides.
/// docs/settings.md lists them with the ways to set them: C++ (`make_engine("bullet",
/// model, {{"bullet", {"shape=box"}}})` or BulletWorld's constructor), the CLI (`--bullet KEY=VALUE`,
/// repeatable) and Python (`Engine(..., bullet={KEY: VALUE})`).

#include <string>
#include <vector>

#include "octocd/adapter_rows.hpp"

namespace octocd {

/// What Bullet collides a body as.
enum class BulletShape {
  /// The same meshes as octocd (design.md section 15, the default): a dynamic mesh is a
  /// btConvexHullShape of its mesh's convex hull (translation-only: the same hull with
  /// angular factor 0); a static mesh is a btBvhTriangleMeshShape of its triangles; a box
  /// shape is a btBoxShape. Collision margins 0: the shapes are exactly those declared
  /// in traces (collision_shape "convex_hull" / "mesh").
  Hull,
  /// Boxes equal to the shapes' local AABBs (design.md section 7.8's "box shapes equal to the
  /// AABBs"): every body, mesh or box, is a btBoxShape; box-box pairs through
  /// btBoxBoxDetector. Declared as collision_shape "box". With rotation, meshes are
  /// hulls whatever this setting (a rotating body is never its AABB).
  Box,
};

/// "hull" or "box".
const char* bullet_shape_name(BulletShape s);

/// The bullet engine's settings. The defaults are what `octocd run --engine bullet` runs.
struct BulletSettings {
  /// What Bullet collides each body as (BulletShape); key `shape`, values hull | box.
  /// Default hull: the same geometry octocd's mesh narrow phase works on, so speed and
  /// accuracy compare like with like.
  BulletShape shape = BulletShape::Hull;
  /// Iterations of the sequential-impulse solver per step (btContactSolverInfo::
  /// m_numIterations); key `iterations`, an integer in [1, 10000]. Default 10, Bullet's.
  /// The speed-accuracy sweep's second axis (docs/bench-format.md).
  int solver_iterations = 10;
};

/// The bullet engine's settings table, one row a key in the struct's order:
/// shape (hull or box), iterations (an integer in [1, 10000]).
/// apply_settings(settings, items, where) (adapter_rows.hpp) sets a BulletSettings from
/// "KEY=VALUE" items (`--bullet KEY=VALUE`, repeatable), throwing InputError that names the
/// key, the value and what is allowed; setting_names<BulletSettings>() lists the keys.
template <>
const SettingTable<BulletSettings>& setting_table<BulletSettings>();

}  // namespace octocd
