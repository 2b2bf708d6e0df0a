#pragma once
/// \file scene.hpp
/// Scenes (SPEC section 3): a JSON file describing the domain, gravity, time step, walls,
/// groups of bodies, response parameters, broadphase and midphase. The full key list
/// with ranges is in docs/scenes.md. The same scene and seeds give the same bodies on
/// every engine.

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "octocd/broadphase.hpp"
#include "octocd/math.hpp"
#include "octocd/midphase.hpp"

namespace octocd {

/// The shape of a group's bodies.
struct ShapeSpec {
  enum class Kind { Mesh, Box, Icosphere };
  Kind kind = Kind::Box;
  std::string mesh;          ///< Mesh: dataset name ("bunny", ...) or a file path
  Vec3 half_extents{0.5f, 0.5f, 0.5f};  ///< Box: half extents (m), each > 0
  float radius = 0.5f;       ///< Icosphere: radius (m), > 0
  int subdivisions = 2;      ///< Icosphere: in [0, 7]
  float scale = 1.0f;        ///< Mesh: longest side after normalisation (m), > 0
};

/// How a group's bodies are placed.
struct LayoutSpec {
  enum class Kind { Grid, Random };
  Kind kind = Kind::Grid;
  Aabb region;               ///< box the body centres are placed in (m)
  float spacing = 0.0f;      ///< Grid: centre distance (m); 0 = 1.1 x largest extent
  float jitter = 0.0f;       ///< Grid: uniform random offset per axis (m), >= 0
  std::uint64_t seed = 1;    ///< random stream for jitter / random placement
};

/// Initial velocity of a group's bodies.
struct VelocitySpec {
  enum class Kind { Fixed, Random };
  Kind kind = Kind::Fixed;
  Vec3 value{0.0f, 0.0f, 0.0f};  ///< Fixed: m/s
  float max_speed = 0.0f;        ///< Random: each component uniform in [-max, max] (m/s)
  std::uint64_t seed = 1;
};

/// A group of identical bodies.
struct GroupSpec {
  std::string name;          ///< label, unique within the scene
  ShapeSpec shape;
  int count = 1;             ///< >= 1
  float mass = 1.0f;         ///< kg, > 0; 0 makes the group static (inverse mass 0)
  LayoutSpec layout;
  VelocitySpec velocity;
  std::vector<Vec3> positions;  ///< explicit centres (m), overrides layout when non-empty
};

/// Static walls generated from the domain box.
enum class Walls { None, Floor, OpenBox, ClosedBox };

/// A parsed, validated scene.
struct Scene {
  std::string name;
  std::string path;          ///< the file it came from ("" when built in code)
  std::string json;          ///< the scene file's text, stored in traces
  Aabb domain;               ///< min < max on every axis (m)
  Vec3 gravity{0.0f, -9.81f, 0.0f};  ///< m/s^2
  float dt = 0.001f;         ///< s, > 0
  int frames = 1000;         ///< >= 1
  Walls walls = Walls::Floor;
  float wall_thickness = 0.1f;  ///< m, > 0; walls lie outside the domain, touching it
  std::vector<GroupSpec> groups;
  ContactParams response;    ///< Table 1 parameters
  std::optional<float> theta;   ///< m, > 0; empty = `auto` (SPEC 6)
  BroadPhaseConfig broadphase;
  MidphaseConfig midphase;
  int mesh_octree_depth = 2;    ///< D_m in [0, 10]; -1 = `auto`
  std::string data_dir;      ///< where dataset meshes are looked up
};

/// Reads and validates a scene file. Mesh names are resolved against `data_dir`
/// (default: $OCTOCD_DATA_DIR, else datasets/cache next to the scene's folder).
/// Throws InputError naming the file, the JSON key (e.g. `groups[1].count`) and the
/// allowed range for: unknown keys, wrong types, non-finite numbers, beta/alpha outside
/// (0, 1], slop <= 0, negative J_min, non-finite v_max, counts of zero, domain min >= max,
/// and a missing mesh file.
Scene load_scene(const std::string& path, const std::string& data_dir = "");

/// Same as load_scene from JSON text; `origin` names it in errors.
Scene parse_scene(const std::string& text, const std::string& origin,
                  const std::string& data_dir = "");

/// Resolves a group's mesh name to a file: an existing path (relative to the scene's
/// folder or absolute), or DATA_DIR/NAME.{off,obj,ply}. Throws InputError naming the key
/// and the places searched, and saying to run datasets/fetch.sh.
std::string resolve_mesh_path(const Scene& scene, const std::string& mesh, const std::string& key);

}  // namespace octocd
