#pragma once
/// \file worlds.hpp
/// Batched worlds (docs/gpu.md, "Batched worlds"): K independent copies of a scene
/// run as one world by octocd's engines (`octocd run SCENE --worlds K`). The copies are
/// placed apart on a grid in the x-z plane, each in its own cell: a cell is the scene's
/// bounds (the domain and every body's initial world AABB, walls and other static bodies
/// included) grown by a margin, so no broadphase pair joins two copies while every body
/// stays inside its copy's bounds. Each copy may be perturbed (its dynamic bodies' initial
/// positions moved by up to eps per axis, seeded) for divergence runs.
///
/// Body order: copy-major. Copy c holds bodies [c N, (c + 1) N) of the batched model, in
/// the single model's order (walls first, then the groups), N = the single model's body
/// count; so pairs within a copy come in the same (a, b) order as in the single world.
///
/// Bits: body state is float32, so a copy translated by a non-zero offset rounds
/// differently from the untranslated scene (an offset of 100 m has a float spacing of
/// 7.6e-6 m). A copy is bit for bit the single-world run of the same scene translated by
/// the same offset (make_worlds_model with that one offset): the oracle of the tests. Copy
/// 0 sits at offset zero, so it equals the plain single-world run bit for bit.

#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "octocd/engine.hpp"
#include "octocd/math.hpp"

namespace octocd {

/// What `--worlds K --world-perturb EPS --seed S --world-margin M` ask for.
struct WorldsSpec {
  /// K, the number of copies, in [1, kMaxWorlds].
  long count = 1;
  /// eps (m), >= 0 and <= kMaxWorldPerturb: each dynamic body of copies 1 .. K-1 gets
  /// x += (u_x, u_y, u_z), each uniform in [-eps, eps) (SplitMix64::uniform). Copy 0 is
  /// never perturbed (the reference of a divergence run). 0: every copy equal.
  double perturb = 0.0;
  /// The perturbation's stream: copy c (c >= 1) draws from SplitMix64(s_c), where s_1,
  /// s_2, ... are the successive outputs of SplitMix64(seed); its bodies in order, x, y,
  /// z per body.
  std::uint64_t seed = 1;
  /// Gap (m) between the bounds of neighbouring copies, in [limits::kMinLength,
  /// limits::kMaxLength].
  double margin = 0.5;
};

/// The most copies `--worlds` takes: 2^20.
constexpr long kMaxWorlds = 1L << 20;
/// The largest `--world-perturb` (m).
constexpr double kMaxWorldPerturb = 1.0;

/// Where the copies lie.
struct WorldsLayout {
  Aabb bounds;               ///< the single scene's bounds (domain and initial world AABBs), m
  Vec3 spacing;              ///< distance of neighbouring cells on x and z (m); y unused (0)
  long nx = 1, nz = 1;       ///< grid columns on x and rows on z (nx nz >= K)
  std::vector<Vec3> offsets; ///< per copy, the translation (m): copy c at column c mod nx, row c div nx
};

/// The layout of `spec.count` copies of `single` (a model of one world): cells of the
/// bounds' x and z sides plus the margin, nx = ceil(sqrt(K)) columns, rows as needed,
/// copy 0 at offset zero. Throws InputError naming `--worlds`, `--world-margin` or
/// `--world-perturb` when a value is out of range, and `--worlds` when the grid would reach
/// past limits::kMaxCoordinate (saying how many copies fit).
WorldsLayout worlds_layout(const Model& single, const WorldsSpec& spec);

/// The model of K copies of `single` at `offsets` (one per copy; K = offsets.size() >= 1),
/// copy-major (see the file comment), perturbed as `spec` says (spec.count is ignored;
/// spec.perturb, spec.seed are used). Shapes and theta are shared with `single`; the scene
/// is `single`'s with: the name "<name> x<K> worlds", walls "none" (the copies' walls are
/// bodies already), the domain the smallest box holding every copy's bounds, and an
/// octree broadphase's fixed depth deepened by ceil(log2(grid side / single side)) (at most
/// 10) so its cells keep their size (the pair set does not depend on it). The scene's JSON
/// text is the single scene's: a trace of the batched model cannot be re-read as it (run
/// refuses --trace with --worlds).
std::shared_ptr<const Model> make_worlds_model(const Model& single, const std::vector<Vec3>& offsets,
                                               const WorldsSpec& spec);

/// make_worlds_model(single, worlds_layout(single, spec).offsets, spec); the model itself
/// when spec.count == 1 and spec.perturb == 0 (shared, not copied).
std::shared_ptr<const Model> make_worlds_model(std::shared_ptr<const Model> single, const WorldsSpec& spec);

/// Copy `copy` alone, at offset zero: a model equal to `single` but for the initial
/// positions, perturbed as copy `copy` of make_worlds_model(single, ..., spec) is (so a
/// copy run by itself, e.g. on a reference engine, starts where the batched copy starts
/// before its translation). Copy 0, or spec.perturb == 0, gives `single`'s positions.
/// Throws InputError as worlds_layout for spec.perturb, spec.margin or a copy >= kMaxWorlds.
std::shared_ptr<const Model> worlds_copy_model(const Model& single, const WorldsSpec& spec, std::size_t copy);

/// Copy `copy`'s bodies out of a batched state: bodies [copy n, (copy + 1) n) of x, v
/// and w (n = `bodies_per_world`), positions as they are (translated by the copy's
/// offset). Throws InputError when the state holds fewer than (copy + 1) n bodies.
BodyState world_state(const BodyState& all, std::size_t bodies_per_world, std::size_t copy);

/// The copies whose bodies left their cell: for each copy, whether every body's world
/// AABB in `state` lies inside the copy's cell on x and z (the bounds translated by its
/// offset, grown by a quarter of the margin, so neighbouring cells stay half the margin
/// apart; y is free). Returns the indices of the copies that
/// did not (empty: no pair can have crossed copies). `batched` is the model of
/// make_worlds_model(single, layout.offsets, ...) (its local boxes and body count).
std::vector<long> worlds_escaped(const Model& batched, const WorldsLayout& layout, double margin,
                                 const BodyState& state);

}  // namespace octocd
