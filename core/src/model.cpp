// The model every engine is built from (design.md section 3): shapes, walls, bodies, theta.
#include <algorithm>
#include <cstring>
#include <map>
#include <utility>

#include <fmt/format.h>

#include "octocd/engine.hpp"
#include "octocd/error.hpp"
#include "octocd/mesh.hpp"

namespace octocd {

namespace {

/// A static wall: centre and half extents.
struct WallBox {
  const char* name;
  Vec3 center;
  Vec3 half;
};

/// design.md section 3 "static walls on/off": boxes of thickness t lying outside the domain and
/// touching it; side walls and the ceiling overlap at the edges so no body slips out.
std::vector<WallBox> make_walls(const Scene& s) {
  std::vector<WallBox> walls;
  if (s.walls == Walls::None) return walls;
  const Aabb& d = s.domain;
  const float t = s.wall_thickness;
  const Vec3 c = center(d);
  const Vec3 h = 0.5f * (d.max - d.min);
  walls.push_back({"floor", {c.x, d.min.y - 0.5f * t, c.z}, {h.x + t, 0.5f * t, h.z + t}});
  if (s.walls == Walls::Floor) return walls;
  walls.push_back({"wall-x-", {d.min.x - 0.5f * t, c.y, c.z}, {0.5f * t, h.y, h.z + t}});
  walls.push_back({"wall-x+", {d.max.x + 0.5f * t, c.y, c.z}, {0.5f * t, h.y, h.z + t}});
  walls.push_back({"wall-z-", {c.x, c.y, d.min.z - 0.5f * t}, {h.x, h.y, 0.5f * t}});
  walls.push_back({"wall-z+", {c.x, c.y, d.max.z + 0.5f * t}, {h.x, h.y, 0.5f * t}});
  if (s.walls == Walls::ClosedBox)
    walls.push_back({"ceiling", {c.x, d.max.y + 0.5f * t, c.z}, {h.x + t, 0.5f * t, h.z + t}});
  return walls;
}

}  // namespace

std::shared_ptr<const Model> build_model(const Scene& scene) {
  auto model = std::make_shared<Model>();
  model->scene = scene;
  const Scene& sc = model->scene;
  std::vector<Shape>& shapes = model->shapes;
  std::vector<BodyInfo>& bodies = model->bodies;
  BodyState& initial = model->initial;

  const int depth_setting = sc.mesh_octree_depth;
  const int needed = sc.midphase.aabb_only ? 0 : sc.midphase.max_level();
  // Rotating scenes (design.md section 13, `--engine bullet` only) also carry every body's initial
  // orientation and angular velocity; translation-only scenes leave them empty.
  const bool rotates = scene_rotates(sc);
  auto add_body = [&](std::uint32_t shape, const std::string& group, Vec3 x, Vec3 v, float w, Quat q = {},
                      Vec3 omega = {}) {
    initial.x.push_back(x);
    initial.v.push_back(v);
    initial.w.push_back(w);
    if (rotates) {
      initial.q.push_back(q);
      initial.omega.push_back(omega);
    }
    bodies.push_back({shape, group});
  };
  auto mesh_shape = [&](Mesh mesh, const std::string& name) {
    int depth = depth_setting < 0 ? auto_mesh_octree_depth(mesh) : depth_setting;
    depth = std::max(depth, needed);
    auto octree = std::make_shared<const MeshOctree>(build_mesh_octree(mesh, depth));
    const Aabb local = mesh_bounds(mesh);
    const float edge = mean_edge_length(mesh);
    return Shape{name, local, octree, std::make_shared<const Mesh>(std::move(mesh)), edge};
  };

  for (const WallBox& wall : make_walls(sc)) {
    shapes.push_back({wall.name, {-wall.half, wall.half}, nullptr, nullptr, 0.0f});
    add_body(static_cast<std::uint32_t>(shapes.size() - 1), "walls", wall.center, {}, 0.0f);
  }

  // Meshes are loaded once per (file, scale) and shared by all their instances.
  std::map<std::pair<std::string, float>, std::uint32_t> mesh_cache;
  std::vector<Aabb> group_boxes;  // world AABBs of the bodies placed so far (see group_positions)
  for (std::size_t gi = 0; gi < sc.groups.size(); ++gi) {
    const GroupSpec& g = sc.groups[gi];
    const std::string key = fmt::format("groups[{}]", gi);
    std::uint32_t shape_id = 0;
    switch (g.shape.kind) {
      case ShapeSpec::Kind::Box:
        shapes.push_back({fmt::format("box{}x{}x{}", 2 * g.shape.half_extents.x,
                                       2 * g.shape.half_extents.y, 2 * g.shape.half_extents.z),
                           {-g.shape.half_extents, g.shape.half_extents}, nullptr, nullptr, 0.0f});
        shape_id = static_cast<std::uint32_t>(shapes.size() - 1);
        break;
      case ShapeSpec::Kind::Icosphere:
        shapes.push_back(mesh_shape(make_icosphere(g.shape.radius, g.shape.subdivisions),
                                     fmt::format("icosphere-r{}-s{}", g.shape.radius,
                                                 g.shape.subdivisions)));
        shape_id = static_cast<std::uint32_t>(shapes.size() - 1);
        break;
      case ShapeSpec::Kind::Mesh: {
        const std::string path = resolve_mesh_path(sc, g.shape.mesh, key + ".shape.mesh");
        const auto cache_key = std::make_pair(path, g.shape.scale);
        auto it = mesh_cache.find(cache_key);
        if (it != mesh_cache.end()) {
          shape_id = it->second;
          break;
        }
        Mesh mesh;
        try {
          mesh = load_mesh(path);
          normalize_mesh(mesh);
          scale_mesh(mesh, g.shape.scale);
        } catch (const InputError& e) {
          // "<scene file>: groups[i].shape.mesh: mesh file '...': <problem>; allowed: ..."
          throw InputError(fmt::format("{}: {}.shape.mesh: {}", sc.path.empty() ? "<scene>" : sc.path, key,
                                       e.what()));
        }
        shapes.push_back(mesh_shape(std::move(mesh), fmt::format("{}@{}", g.shape.mesh, g.shape.scale)));
        shape_id = static_cast<std::uint32_t>(shapes.size() - 1);
        mesh_cache.emplace(cache_key, shape_id);
        break;
      }
    }
    // Layouts place the body's world AABB at its orientation (the exact box of the
    // rotated local box, centred on the origin; the local box itself when unrotated).
    const Aabb placed = posed_box_aabb(shapes[shape_id].local, Pose{Vec3{}, g.orientation});
    const std::vector<Vec3> xs = group_positions(g, placed, sc.path, group_boxes);
    const std::vector<Vec3> vs = group_velocities(g);
    // Random layouts of later groups keep apart from these bodies (not from the walls).
    if (std::any_of(sc.groups.begin() + static_cast<std::ptrdiff_t>(gi) + 1, sc.groups.end(),
                    [](const GroupSpec& later) { return later.layout.kind == LayoutSpec::Kind::Random; }))
      for (const Vec3& x : xs) group_boxes.push_back(translated(placed, x));
    const float w = g.mass > 0.0f ? 1.0f / g.mass : 0.0f;
    for (int i = 0; i < g.count; ++i)
      add_body(shape_id, g.name, xs[static_cast<std::size_t>(i)],
               w > 0.0f ? vs[static_cast<std::size_t>(i)] : Vec3{}, w, g.orientation,
               w > 0.0f ? g.angular_velocity : Vec3{});
  }
  // theta per shape pair (design.md section 6): the scene's value, or `auto` = the larger mean edge.
  model->theta_shape.resize(shapes.size());
  for (std::size_t a = 0; a < shapes.size(); ++a) model->theta_shape[a] = sc.theta ? *sc.theta : shapes[a].mean_edge;
  return model;
}

std::uint64_t static_static_pairs(const Model& model) {
  // Sweep along x over the static bodies' world AABBs (walls: a handful).
  std::vector<Aabb> boxes;
  for (std::size_t i = 0; i < model.initial.size(); ++i)
    if (model.initial.w[i] == 0.0f) boxes.push_back(translated(model.local_box(i), model.initial.x[i]));
  std::sort(boxes.begin(), boxes.end(), [](const Aabb& a, const Aabb& b) { return a.min.x < b.min.x; });
  std::uint64_t n = 0;
  for (std::size_t i = 0; i < boxes.size(); ++i)
    for (std::size_t j = i + 1; j < boxes.size() && boxes[j].min.x <= boxes[i].max.x; ++j)
      if (overlaps(boxes[i], boxes[j])) ++n;
  return n;
}

double largest_mean_leaf_vertices(const Model& model) {
  const MidphaseConfig& mc = model.scene.midphase;
  if (mc.aabb_only || mc.levels.empty()) return 0.0;
  const int level = mc.levels.back();
  double largest = 0.0;
  for (const Shape& s : model.shapes) {
    if (!s.octree || level > s.octree->depth) continue;
    const std::uint32_t cells = s.octree->level_end(level) - s.octree->level_begin(level);
    if (cells == 0) continue;
    largest = std::max(largest, static_cast<double>(s.octree->vertices.size()) / static_cast<double>(cells));
  }
  return largest;
}

const char* stage_name(Stage s) {
  switch (s) {
    case Stage::Integrate: return "integrate";
    case Stage::Aabbs: return "aabbs";
    case Stage::Broadphase: return "broadphase";
    case Stage::Midphase: return "midphase";
    case Stage::Response: return "response";
    case Stage::Metrics: return "metrics";
    case Stage::Count: break;
  }
  return "unknown";
}

std::uint64_t state_hash(const BodyState& state) {
  // FNV-1a 64 over the bytes of x then v.
  std::uint64_t h = 1469598103934665603ull;
  auto feed = [&h](const std::vector<Vec3>& a) {
    for (const Vec3& p : a) {
      unsigned char bytes[sizeof(float) * 3];
      std::memcpy(bytes, &p.x, sizeof(float));
      std::memcpy(bytes + 4, &p.y, sizeof(float));
      std::memcpy(bytes + 8, &p.z, sizeof(float));
      for (unsigned char c : bytes) {
        h ^= c;
        h *= 1099511628211ull;
      }
    }
  };
  feed(state.x);
  feed(state.v);
  return h;
}

std::uint64_t Engine::state_hash() const { return octocd::state_hash(state()); }

void Engine::set_state(const BodyState& /*state*/) {
  throw InputError("engine '" + name() + "' cannot take a state from outside (set_state); allowed: cpu, cuda");
}

}  // namespace octocd
