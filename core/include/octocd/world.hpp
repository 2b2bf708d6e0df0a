#pragma once
/// \file world.hpp
/// The CPU reference pipeline (SPEC section 4): bodies in structure-of-arrays hot state,
/// shapes with their per-mesh octrees, and one step of named, timed stages.

#include <array>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "octocd/broadphase.hpp"
#include "octocd/math.hpp"
#include "octocd/mesh.hpp"
#include "octocd/mesh_octree.hpp"
#include "octocd/midphase.hpp"
#include "octocd/scene.hpp"

namespace octocd {

/// The named stages of one step, in execution order (like Box2D's profile).
enum class Stage : int {
  Integrate = 0,   ///< Eq. 1-3
  Aabbs,           ///< world AABBs from positions
  Broadphase,      ///< SPEC 5.1
  Midphase,        ///< SPEC 5.2-5.3: per-mesh octree levels + vertex proximity
  Response,        ///< SPEC 6: corrections, impulses, friction, clamp
  Metrics,         ///< energy, momentum, penetration statistics
  Count
};

/// Stage name as used in traces and summaries ("integrate", "aabbs", "broadphase",
/// "midphase", "response", "metrics").
const char* stage_name(Stage s);

/// Everything measured in one step (one row of the trace's /frames).
struct FrameMetrics {
  std::int64_t frame = 0;          ///< 1-based index of the step just taken
  double time = 0.0;               ///< simulated time after the step (s)
  double step_ms = 0.0;            ///< wall time of the whole step (ms)
  std::array<double, static_cast<int>(Stage::Count)> stage_ms{};  ///< wall ms per stage
  std::uint64_t cell_candidates = 0;  ///< broadphase pairs before the exact AABB test
  std::uint64_t aabb_pairs = 0;       ///< broadphase pairs (overlapping world AABBs)
  std::uint64_t box_tests = 0;        ///< midphase cell-box tests
  std::uint64_t box_pairs = 0;        ///< midphase surviving deepest-level box pairs
  std::uint64_t vertex_tests = 0;     ///< narrow-phase vertex tests
  std::uint64_t contacts = 0;         ///< confirmed contacts
  double penetration_mean = 0.0;   ///< mean AABB d_p over confirmed contacts (m), Eq. 10
  double penetration_max = 0.0;    ///< max d_p (m)
  double penetration_share_above_slop = 0.0;  ///< share of contacts with d_p > delta, [0, 1]
  double kinetic_energy = 0.0;     ///< sum 0.5 m |v|^2 over dynamic bodies (J)
  std::array<double, 3> momentum{};  ///< sum m v over dynamic bodies (kg m/s)
  std::uint64_t memory_bytes = 0;  ///< bytes held by the pipeline's buffers
};

/// One confirmed contact as resolved this step (optional /contacts in traces; the
/// validators read the per-contact deltas).
struct ContactRecord {
  Pair pair;            ///< (a, b), a < b
  Vec3 normal;          ///< from b to a (unit)
  float depth = 0.0f;   ///< AABB d_p (m) before correction
  float jn = 0.0f;      ///< normal impulse (kg m/s)
  float jt = 0.0f;      ///< friction impulse along t (kg m/s)
  int axis = 1;         ///< axis of the normal (0 = x, 1 = y, 2 = z)
  Vec3 v_a, v_b;        ///< pre-response velocities (m/s)
  Vec3 dx_a, dx_b;      ///< this contact's position corrections, before per-body averaging (m)
  Vec3 dv_a, dv_b;      ///< this contact's velocity changes (m/s)
};

/// Deliberate faults for validator self-tests (issue 3: "a validator that cannot fail is
/// a defect"). All off by default; `octocd` never sets them.
struct PlantedFaults {
  bool eq12_weights = false;     ///< split corrections with the paper's Eq. 12 (swapped) weights
  bool friction_sign = false;    ///< apply friction with the wrong sign (speeds sliding up)
  bool momentum_leak = false;    ///< apply only 90% of each impulse to body B
  bool normal_sign = false;      ///< use the contact normal pointing from A to B
};

/// A shape shared by bodies: a box or a mesh with its octree. Local frame centred on the
/// local AABB centre, so a body's position is its AABB centre.
struct Shape {
  std::string name;                          ///< e.g. "bunny@0.2" or "box"
  Aabb local;                                ///< local AABB (m)
  std::shared_ptr<const MeshOctree> octree;  ///< nullptr for boxes
  std::shared_ptr<const Mesh> mesh;          ///< welded, normalised, scaled; nullptr for boxes
  float mean_edge = 0.0f;                    ///< mean edge length (m), 0 for boxes
};

/// Hot body state in structure-of-arrays form (SPEC 3), float32. Index = body id.
struct BodyState {
  std::vector<Vec3> x;   ///< positions: centre of the world AABB (m)
  std::vector<Vec3> v;   ///< velocities (m/s)
  std::vector<float> w;  ///< inverse masses (1/kg); 0 = static
  /// Number of bodies.
  std::size_t size() const { return x.size(); }
};

/// Cold per-body data, kept apart from the hot state.
struct BodyInfo {
  std::uint32_t shape = 0;  ///< index into World::shapes()
  std::string group;        ///< scene group name ("walls" for generated walls)
};

/// The CPU reference world. Owns shapes, bodies and the chosen broadphase.
class World {
 public:
  /// Builds shapes (loading, welding, normalising meshes; building their octrees to
  /// max(D_m, deepest midphase level)) and bodies from a validated scene. Walls come
  /// first, then groups in order. Throws InputError for unreadable meshes.
  explicit World(const Scene& scene);

  /// Same, with a broadphase made by the caller (e.g. a Bullet or FCL reference from
  /// make_any_broadphase). Takes ownership; `broadphase` must not be null.
  World(const Scene& scene, std::unique_ptr<BroadPhase> broadphase);

  /// Turns planted faults on or off (validator self-tests only).
  void plant_faults(const PlantedFaults& faults) { faults_ = faults; }

  /// Runs one step (SPEC 4) and returns its metrics. Throws RuntimeError naming the body
  /// and frame when a position or velocity becomes non-finite.
  const FrameMetrics& step();

  /// The scene this world was built from.
  const Scene& scene() const { return scene_; }
  /// Hot state (read-only).
  const BodyState& state() const { return state_; }
  /// Hot state (mutable: tests and validators set up states with it).
  BodyState& mutable_state() { return state_; }
  /// Cold per-body data.
  const std::vector<BodyInfo>& bodies() const { return info_; }
  /// Shapes, indexed by BodyInfo::shape.
  const std::vector<Shape>& shapes() const { return shapes_; }
  /// World AABBs as of the last step's Aabbs stage (before the response).
  const std::vector<Aabb>& world_aabbs() const { return aabbs_; }
  /// Broadphase pairs of the last step.
  const std::vector<Pair>& candidate_pairs() const { return pairs_; }
  /// Confirmed contacts of the last step, in (a, b) order, with their impulses.
  const std::vector<ContactRecord>& contacts() const { return contacts_; }
  /// Metrics of the last step.
  const FrameMetrics& last_metrics() const { return metrics_; }
  /// The broadphase in use.
  const BroadPhase& broadphase() const { return *broadphase_; }
  /// Steps taken so far.
  std::int64_t frame() const { return frame_; }
  /// theta (m) used for a pair of shapes: the scene's value or `auto` (SPEC 6).
  float theta(std::uint32_t shape_a, std::uint32_t shape_b) const;
  /// FNV-1a 64-bit hash of the bits of every x then every v: bit-identical states hash
  /// equal (determinism checks, SPEC/STYLE: pinned state hash).
  std::uint64_t state_hash() const;

 private:
  void build_shapes_and_bodies();
  Scene scene_;
  std::vector<Shape> shapes_;
  std::vector<BodyInfo> info_;
  BodyState state_;
  std::unique_ptr<BroadPhase> broadphase_;
  std::vector<Aabb> aabbs_;
  std::vector<Pair> pairs_;
  std::vector<std::uint8_t> confirmed_;  // per pair: midphase verdict
  std::vector<ContactRecord> contacts_;
  std::vector<float> theta_table_;
  FrameMetrics metrics_;
  PlantedFaults faults_;
  std::int64_t frame_ = 0;
  // Response scratch (SPEC 6 Jacobi reduction).
  std::vector<Vec3> dx_sum_, dv_sum_;
  std::vector<std::uint32_t> contact_count_;
};

}  // namespace octocd
