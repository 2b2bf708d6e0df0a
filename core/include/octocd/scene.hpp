#pragma once
/// \file scene.hpp
/// Scenes (design.md section 3): a JSON file describing the domain, gravity, time step, walls,
/// groups of bodies, response parameters, broadphase and midphase. The full key list
/// with ranges is in docs/scenes.md. The same scene and seeds give the same bodies on
/// every engine.

#include <cstddef>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "octocd/broadphase.hpp"
#include "octocd/math.hpp"
#include "octocd/midphase.hpp"
#include "octocd/pose.hpp"

namespace octocd {

/// Limits checked when a scene is loaded (docs/scenes.md, "Limits"); a value outside is an
/// InputError (exit code 2). They keep float32 arithmetic meaningful: body state is
/// float32 (design.md section 2), whose spacing at |x| = 1000 m is 2^-14 m = 6.1e-5 m, 1/16 of the
/// default slop (1 mm); further out, the slop, theta and a step's displacement dt*v drown
/// in rounding.
namespace limits {
/// Largest |coordinate| (m) of the domain, layout regions and explicit positions.
constexpr double kMaxCoordinate = 1000.0;
/// Smallest body side (m): box half extents and icosphere radii >= half of it, mesh
/// `scale` >= it, also the smallest wall thickness and domain side. 16 float32 steps at
/// kMaxCoordinate.
constexpr double kMinLength = 1e-3;
/// Largest body side (m): half extents and radii <= half of it, `scale` <= it; also the
/// largest wall thickness, theta and spatial-hash cell size.
constexpr double kMaxLength = 2000.0;
/// Masses (kg) other than 0 (static) lie in [kMinMass, kMaxMass]: the inverse mass is a
/// normal float32 and Eq. 19's impulse -(1+e) v_n / (w_A + w_B) stays finite.
constexpr double kMinMass = 1e-6;
constexpr double kMaxMass = 1e9;
/// Largest |velocity component| and response.max_velocity (m/s): a step (dt <= 0.1 s)
/// moves a body at most 1 km, half the largest domain.
constexpr double kMaxSpeed = 1e4;
/// Largest |gravity component| (m/s^2).
constexpr double kMaxAcceleration = 1e4;
/// Largest |angular velocity component| (rad/s) of a group's `angular_velocity`
/// (rotating scenes, `--engine bullet` only): 1000 rad/s turns a body 1 rad in a 1 ms step.
constexpr double kMaxAngularSpeed = 1e3;
/// Most bodies in a scene (sum of the groups' counts; walls excluded). Body indices are
/// 32-bit; the CPU engine takes about 300 B a body (3 GB at 10^7).
constexpr std::size_t kMaxBodies = 10000000;
/// Most bodies in a scene that octocd generates itself (`octocd bench max-instances`, whose
/// cap this is): not an untrusted file, so the engines' memory checks bound it (host memory:
/// std::bad_alloc; device memory: the cuda engine's free-memory check before its first
/// allocation) instead of kMaxBodies. 2^27 bunnies need about 110 GiB of device memory.
constexpr std::size_t kMaxGeneratedBodies = std::size_t{1} << 27;
/// Largest scene file (bytes): 64 MiB holds explicit positions for about 10^6 bodies.
constexpr std::uintmax_t kMaxSceneFileBytes = 64ull << 20;
/// Deepest JSON nesting (objects and arrays); a scene needs 5.
constexpr int kMaxJsonDepth = 64;
}  // namespace limits

/// The shape of a group's bodies.
struct ShapeSpec {
  /// Which of "mesh", "box", "icosphere" the scene gave.
  enum class Kind { Mesh, Box, Icosphere };
  Kind kind = Kind::Box;     ///< the shape kind
  std::string mesh;          ///< Mesh: dataset name ("bunny", ...) or a file path
  Vec3 half_extents{0.5f, 0.5f, 0.5f};  ///< Box: half extents (m), each > 0
  float radius = 0.5f;       ///< Icosphere: radius (m), > 0
  int subdivisions = 2;      ///< Icosphere: in [0, limits::kMaxIcosphereSubdivisions] (6)
  float scale = 1.0f;        ///< Mesh: longest side after normalisation (m), > 0
  std::string mesh_path;     ///< Mesh: the file `mesh` resolved to by load_scene/parse_scene
};

/// How a group's bodies are placed.
struct LayoutSpec {
  /// "grid" or "random" (see group_positions).
  enum class Kind { Grid, Random };
  Kind kind = Kind::Grid;    ///< placement rule
  Aabb region;               ///< box the body centres are placed in (m)
  float spacing = 0.0f;      ///< Grid: centre distance (m); 0 = 1.1 x largest extent
  float jitter = 0.0f;       ///< Grid: uniform random offset per axis (m), >= 0
  std::uint64_t seed = 1;    ///< random stream for jitter / random placement
  /// True when the scene gave no region ("layout" or its "min"/"max" absent): `region`
  /// then holds the scene's domain and group_positions shrinks it by the body's local
  /// AABB half extents per axis, so the bodies lie inside the domain (an axis where the
  /// domain is narrower than the body collapses to the domain's centre).
  bool region_from_domain = true;
};

/// Initial velocity of a group's bodies.
struct VelocitySpec {
  /// "fixed" or "random" (see group_velocities).
  enum class Kind { Fixed, Random };
  Kind kind = Kind::Fixed;       ///< velocity rule
  Vec3 value{0.0f, 0.0f, 0.0f};  ///< Fixed: m/s
  float max_speed = 0.0f;        ///< Random: each component uniform in [-max, max] (m/s)
  std::uint64_t seed = 1;        ///< Random: stream for the components
};

/// A group of identical bodies.
struct GroupSpec {
  std::string name;          ///< label, unique within the scene (default "group<i>")
  int index = 0;             ///< position in Scene::groups (names `groups[<index>]` in errors)
  ShapeSpec shape;           ///< the bodies' shape
  int count = 1;             ///< >= 1
  float mass = 1.0f;         ///< kg, >= 0; 0 makes the group static (inverse mass 0)
  LayoutSpec layout;         ///< placement when `positions` is empty
  VelocitySpec velocity;     ///< initial velocities
  std::vector<Vec3> positions;  ///< explicit centres (m), overrides layout when non-empty
  /// Initial orientation of every body of the group (unit quaternion, body to world;
  /// scene key `orientation`: [w, x, y, z] or {"axis": [x, y, z], "angle_deg": A}).
  /// Identity by default. Only `--engine bullet` rotates (design.md section 13); cpu and cuda refuse a
  /// non-identity value (require_translation_only).
  Quat orientation;
  /// Initial angular velocity (rad/s, world frame) of every dynamic body of the group
  /// (scene key `angular_velocity`); zero by default; static bodies get zero.
  Vec3 angular_velocity{0.0f, 0.0f, 0.0f};
};

/// Static walls generated from the domain box ("none", "floor", "open-box",
/// "closed-box"): no walls; a floor whose top is domain.min.y; the floor and the four
/// side walls; those plus a ceiling. Thickness Scene::wall_thickness, outside the domain.
enum class Walls { None, Floor, OpenBox, ClosedBox };

/// A parsed, validated scene.
struct Scene {
  std::string name;          ///< the scene's "name"
  std::string description;   ///< free text, "" when absent
  std::string path;          ///< the file it came from ("" when built in code)
  std::string json;          ///< the scene file's text, stored in traces
  Aabb domain;               ///< min < max on every axis (m)
  Vec3 gravity{0.0f, -9.81f, 0.0f};  ///< m/s^2
  float dt = 0.001f;         ///< s, > 0
  int frames = 1000;         ///< >= 1
  Walls walls = Walls::Floor;
  float wall_thickness = 0.1f;  ///< m, > 0; walls lie outside the domain, touching it
  std::vector<GroupSpec> groups;  ///< non-empty, names unique
  ContactParams response;    ///< Table 1 parameters
  std::optional<float> theta;   ///< m, > 0; empty = `auto` (design.md section 6)
  BroadPhaseConfig broadphase;  ///< name not validated here (make_broadphase does it)
  MidphaseConfig midphase;      ///< "midphase.levels"
  int mesh_octree_depth = 2;    ///< D_m in [0, 10]; -1 = `auto`
  std::string data_dir;      ///< where dataset meshes are looked up
  /// A scene found inside another file (parse_embedded_scene: a trace's `scene` attribute,
  /// untrusted): its meshes resolve only to files inside `mesh_dir` or `data_dir`, never
  /// elsewhere (resolve_mesh_path). False for a scene file or text the caller gives.
  bool embedded = false;
  std::string mesh_dir;      ///< embedded: the folder its mesh files may lie in (besides data_dir)
  /// Scene key `rotation` (default false): the bodies rotate (design.md section 13). Only
  /// `--engine bullet` runs such a scene (BulletWorld's rotation mode); `octocd run
  /// --rotation` sets it on the loaded scene.
  bool rotation = false;
};

/// True when the scene needs a rotating engine: `rotation` is true, or some group has a
/// non-identity `orientation` or a non-zero `angular_velocity`.
bool scene_rotates(const Scene& scene);

/// Refuses a rotating scene (scene_rotates) for an engine that translates only (design.md section 3:
/// `cpu`, `cuda`): throws InputError "<scene file>: KEY: engine ENGINE translates only
/// (design.md section 3) ...; allowed: ..., or --engine bullet" naming the first key that asks for
/// rotation (`rotation`, `groups[i].orientation` or `groups[i].angular_velocity`).
void require_translation_only(const Scene& scene, const std::string& engine);

/// Total number of bodies over all groups.
std::size_t body_count(const Scene& scene);

/// Reads and validates a scene file. Mesh names are resolved against `data_dir`
/// (`--data-dir`; default: $OCTOCD_DATA_DIR, else the first existing folder of
/// default_data_dirs(path)). The scene's folder is taken as an absolute path, so the
/// same scene finds the same meshes however its path is spelled.
/// Throws InputError naming the file, the JSON key (e.g. `groups[1].count`) and the
/// allowed range for: unknown keys, wrong types, non-finite numbers, beta/alpha outside
/// (0, 1], slop <= 0, negative J_min, non-finite v_max, counts of zero, domain min >= max,
/// and a missing mesh file.
Scene load_scene(const std::string& path, const std::string& data_dir = "");

/// Same as load_scene from JSON text; `origin` names it in errors and is stored as
/// Scene::path (relative mesh paths resolve against its folder; "" or a name without a
/// folder means the current directory). The default data_dir is $OCTOCD_DATA_DIR, else
/// the first existing folder of default_data_dirs(origin). Meshes are resolved and
/// checked exactly as in load_scene. `max_bodies`: the most bodies the scene may hold
/// (limits::kMaxBodies for any file; at most limits::kMaxGeneratedBodies for a scene
/// octocd generates itself); larger values are clamped to kMaxGeneratedBodies.
Scene parse_scene(const std::string& text, const std::string& origin,
                  const std::string& data_dir = "", std::size_t max_bodies = limits::kMaxBodies);

/// A scene found inside an untrusted file (a trace's root attribute `scene`), parsed and
/// checked as parse_scene with Scene::embedded set: the files its meshes name are looked up
/// only inside `mesh_dir` (relative names resolve against it; absolute ones must lie in
/// it) and, for dataset names, in the data dir; a name that resolves elsewhere (an absolute
/// path, `..`, a symbolic link leading out; symbolic links resolved) is InputError naming
/// the key, the file and `--mesh-dir` (docs/robustness.md, "Untrusted traces"). An empty
/// `mesh_dir` resolves no mesh at all (Mesh groups keep an empty mesh_path): for callers
/// that need the scene's numbers only, never its geometry.
Scene parse_embedded_scene(const std::string& text, const std::string& origin, const std::string& mesh_dir,
                           const std::string& data_dir = "");

/// The data dirs tried, in order, when neither `--data-dir` nor $OCTOCD_DATA_DIR is
/// given (docs/scenes.md, "Mesh resolution"): `<scene folder>/../cache` (the scene's
/// folder made absolute; omitted when `origin` is "") and the `datasets/cache` of the
/// source tree octocd was built from. Returns {$OCTOCD_DATA_DIR} when that is set and
/// non-empty. Paths are absolute when `origin` is.
std::vector<std::string> default_data_dirs(const std::string& origin);

/// Resolves a group's mesh name to a file: an existing regular file (absolute, or
/// relative to the folder of Scene::path; for an embedded scene relative to
/// Scene::mesh_dir and inside it or the data dir only), else, when `mesh` has no folder and no
/// extension (a dataset name), DATA_DIR/NAME.obj, NAME.off, NAME.ply (first found;
/// DATA_DIR = Scene::data_dir). Throws InputError naming `key` and the places searched,
/// with advice that fits (run datasets/fetch.sh only for a shipped dataset name or a
/// missing data dir); also when the file found is empty (size 0), and, when no regular
/// file is found but a place searched exists as a folder, FIFO, device or socket, naming
/// that place and its type (found with stat: nothing is opened, so a FIFO cannot block).
std::string resolve_mesh_path(const Scene& scene, const std::string& mesh, const std::string& key);

/// SplitMix64 (Steele, Lea, Flood 2014): the scene's random stream. Integer-only, so it
/// gives the same numbers on every platform and compiler (no std distributions).
class SplitMix64 {
 public:
  /// Starts the stream at `seed` (the state; the first output mixes seed + golden gamma).
  explicit SplitMix64(std::uint64_t seed) : state_(seed) {}
  /// Next 64-bit output: state += 0x9E3779B97F4A7C15, then the SplitMix64 finaliser.
  std::uint64_t next() {
    std::uint64_t z = (state_ += 0x9E3779B97F4A7C15ULL);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ULL;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBULL;
    return z ^ (z >> 31);
  }
  /// Advances the stream by `n` outputs in O(1) (the state is a counter): the next output is
  /// the one `n` calls of next() would have been followed by.
  void skip(std::uint64_t n) { state_ += n * 0x9E3779B97F4A7C15ULL; }
  /// Uniform float in [0, 1): (next() >> 40) * 2^-24 (exact: 24 bits fit a float).
  float unit() { return static_cast<float>(next() >> 40) * (1.0f / 16777216.0f); }
  /// Uniform in [lo, hi): float(double(lo) + double(unit()) * (double(hi) - double(lo))),
  /// rounded once to float. Returns lo when hi == lo.
  float uniform(float lo, float hi) {
    const double u = static_cast<double>(unit());
    return static_cast<float>(static_cast<double>(lo) +
                              u * (static_cast<double>(hi) - static_cast<double>(lo)));
  }

 private:
  std::uint64_t state_;
};

/// The centres (m) of group `g`'s bodies, in body order, deterministic (SplitMix64):
/// - explicit `positions` when non-empty (returned as is);
/// - grid: spacing s = layout.spacing, or 1.1 x the largest side of `body_local_aabb`
///   when 0. Region R = layout.region (shrunk by the body's half extents when
///   region_from_domain). Slots per axis n_a = floor((R.max_a - R.min_a) / s + 1e-4) + 1;
///   slot i on axis a is at R.min_a + i s (the lattice starts at R.min, so an axis with
///   min == max gives one slot). Body k takes slot (ix, iy, iz) with ix = k mod n_x,
///   iz = (k div n_x) mod n_z, iy = k div (n_x n_z): x fastest, then z, then y, so
///   stacks fill layer by layer upward from R.min.y. Jitter j > 0 then adds
///   uniform(-j, j) to x, y, z in that order (one stream seeded with layout.seed, body
///   order). Throws InputError naming `<origin>: groups[<g.index>].layout` when
///   count > n_x n_y n_z, saying how many fit;
/// - random: centres uniform in R (x, y, z drawn in that order from one stream seeded
///   with layout.seed), rejected while the body's AABB overlaps (Eq. 6, inclusive) one
///   already placed, by this group or in `placed_before`; at most 1000 tries per body,
///   else InputError (region too small). Time O(count + placed_before.size()): the
///   placed boxes are binned in a grid of cells wider than the largest of them; the tries
///   are drawn and tested in chunks on current_threads() threads, with the same result on
///   any thread count.
/// `body_local_aabb` is the local AABB of one body (centred on the origin, design.md section 3).
/// `placed_before`: world AABBs (m) a random layout keeps apart from (build_model passes
/// the bodies of the earlier groups, not the walls); ignored by the grid layout.
std::vector<Vec3> group_positions(const GroupSpec& g, const Aabb& body_local_aabb,
                                  const std::string& origin,
                                  const std::vector<Aabb>& placed_before = {});

/// The initial velocities (m/s) of group `g`'s bodies, in body order: `value` for all
/// (fixed), or each component uniform(-max, max) drawn x, y, z per body in body order
/// from one SplitMix64 stream seeded with velocity.seed (random).
std::vector<Vec3> group_velocities(const GroupSpec& g);

}  // namespace octocd
