// The CPU reference step (SPEC section 4) and its response (SPEC section 6).
#include "octocd/world.hpp"

#include <algorithm>
#include <chrono>
#include <cstring>
#include <map>
#include <utility>

#include <fmt/format.h>

#include "octocd/error.hpp"
#include "octocd/mesh.hpp"

namespace octocd {

namespace {

using Clock = std::chrono::steady_clock;

double ms_since(Clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
}

template <class T>
std::uint64_t capacity_bytes(const std::vector<T>& v) {
  return static_cast<std::uint64_t>(v.capacity() * sizeof(T));
}

std::uint64_t octree_bytes(const MeshOctree& o) {
  return capacity_bytes(o.vertices) + capacity_bytes(o.original_index) + capacity_bytes(o.cells) +
         capacity_bytes(o.level_offset);
}

/// A static wall: centre and half extents.
struct WallBox {
  const char* name;
  Vec3 center;
  Vec3 half;
};

/// SPEC 3 "static walls on/off": boxes of thickness t lying outside the domain and
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

World::World(const Scene& scene) : World(scene, make_broadphase(scene.broadphase, scene.domain)) {}

World::World(const Scene& scene, std::unique_ptr<BroadPhase> broadphase)
    : scene_(scene), broadphase_(std::move(broadphase)) {
  if (!broadphase_) throw InputError("World: no broadphase given");
  build_shapes_and_bodies();
  const std::size_t n = state_.size();
  aabbs_.resize(n);
  for (std::size_t i = 0; i < n; ++i) aabbs_[i] = translated(shapes_[info_[i].shape].local, state_.x[i]);
  dx_sum_.resize(n);
  dv_sum_.resize(n);
  contact_count_.resize(n);
  // theta per shape pair (SPEC 6): the scene's value, or `auto` = the larger mean edge.
  const std::size_t ns = shapes_.size();
  theta_table_.assign(ns * ns, 0.0f);
  for (std::size_t a = 0; a < ns; ++a)
    for (std::size_t b = 0; b < ns; ++b)
      theta_table_[a * ns + b] =
          scene_.theta ? *scene_.theta : std::max(shapes_[a].mean_edge, shapes_[b].mean_edge);
}

void World::build_shapes_and_bodies() {
  const int depth_setting = scene_.mesh_octree_depth;
  const int needed = scene_.midphase.aabb_only ? 0 : scene_.midphase.max_level();
  auto add_body = [&](std::uint32_t shape, const std::string& group, Vec3 x, Vec3 v, float w) {
    state_.x.push_back(x);
    state_.v.push_back(v);
    state_.w.push_back(w);
    info_.push_back({shape, group});
  };
  auto mesh_shape = [&](Mesh mesh, const std::string& name) {
    int depth = depth_setting < 0 ? auto_mesh_octree_depth(mesh) : depth_setting;
    depth = std::max(depth, needed);
    auto octree = std::make_shared<const MeshOctree>(build_mesh_octree(mesh, depth));
    const Aabb local = mesh_bounds(mesh);
    const float edge = mean_edge_length(mesh);
    return Shape{name, local, octree, std::make_shared<const Mesh>(std::move(mesh)), edge};
  };

  for (const WallBox& wall : make_walls(scene_)) {
    shapes_.push_back({wall.name, {-wall.half, wall.half}, nullptr, nullptr, 0.0f});
    add_body(static_cast<std::uint32_t>(shapes_.size() - 1), "walls", wall.center, {}, 0.0f);
  }

  // Meshes are loaded once per (file, scale) and shared by all their instances.
  std::map<std::pair<std::string, float>, std::uint32_t> mesh_cache;
  for (std::size_t gi = 0; gi < scene_.groups.size(); ++gi) {
    const GroupSpec& g = scene_.groups[gi];
    const std::string key = fmt::format("groups[{}]", gi);
    std::uint32_t shape_id = 0;
    switch (g.shape.kind) {
      case ShapeSpec::Kind::Box:
        shapes_.push_back({fmt::format("box{}x{}x{}", 2 * g.shape.half_extents.x,
                                       2 * g.shape.half_extents.y, 2 * g.shape.half_extents.z),
                           {-g.shape.half_extents, g.shape.half_extents}, nullptr, nullptr, 0.0f});
        shape_id = static_cast<std::uint32_t>(shapes_.size() - 1);
        break;
      case ShapeSpec::Kind::Icosphere:
        shapes_.push_back(mesh_shape(make_icosphere(g.shape.radius, g.shape.subdivisions),
                                     fmt::format("icosphere-r{}-s{}", g.shape.radius,
                                                 g.shape.subdivisions)));
        shape_id = static_cast<std::uint32_t>(shapes_.size() - 1);
        break;
      case ShapeSpec::Kind::Mesh: {
        const std::string path = resolve_mesh_path(scene_, g.shape.mesh, key + ".shape.mesh");
        const auto cache_key = std::make_pair(path, g.shape.scale);
        auto it = mesh_cache.find(cache_key);
        if (it != mesh_cache.end()) {
          shape_id = it->second;
          break;
        }
        Mesh mesh = load_mesh(path);
        normalize_mesh(mesh);
        scale_mesh(mesh, g.shape.scale);
        shapes_.push_back(mesh_shape(std::move(mesh), fmt::format("{}@{}", g.shape.mesh, g.shape.scale)));
        shape_id = static_cast<std::uint32_t>(shapes_.size() - 1);
        mesh_cache.emplace(cache_key, shape_id);
        break;
      }
    }
    const std::vector<Vec3> xs = group_positions(g, shapes_[shape_id].local, scene_.path);
    const std::vector<Vec3> vs = group_velocities(g);
    const float w = g.mass > 0.0f ? 1.0f / g.mass : 0.0f;
    for (int i = 0; i < g.count; ++i)
      add_body(shape_id, g.name, xs[static_cast<std::size_t>(i)],
               w > 0.0f ? vs[static_cast<std::size_t>(i)] : Vec3{}, w);
  }
}

float World::theta(std::uint32_t shape_a, std::uint32_t shape_b) const {
  return theta_table_[shape_a * shapes_.size() + shape_b];
}

const FrameMetrics& World::step() {
  const auto t_step = Clock::now();
  FrameMetrics m;
  m.frame = frame_ + 1;
  m.time = static_cast<double>(m.frame) * static_cast<double>(scene_.dt);
  auto stage_ms = [&m](Stage s) -> double& { return m.stage_ms[static_cast<int>(s)]; };
  const std::size_t n = state_.size();
  const ContactParams& params = scene_.response;

  // 1. Integrate (Eq. 1-3).
  auto t0 = Clock::now();
  for (std::size_t i = 0; i < n; ++i)
    integrate(state_.x[i], state_.v[i], state_.w[i], scene_.gravity, Vec3{}, scene_.dt);
  stage_ms(Stage::Integrate) = ms_since(t0);

  // 2. World AABBs.
  t0 = Clock::now();
  for (std::size_t i = 0; i < n; ++i) aabbs_[i] = translated(shapes_[info_[i].shape].local, state_.x[i]);
  stage_ms(Stage::Aabbs) = ms_since(t0);

  // 3. Broadphase (SPEC 5.1).
  t0 = Clock::now();
  BroadPhaseStats bp;
  broadphase_->find_pairs(aabbs_, pairs_, bp);
  m.cell_candidates = bp.cell_candidates;
  m.aabb_pairs = pairs_.size();
  stage_ms(Stage::Broadphase) = ms_since(t0);

  // 4. Midphase + narrow phase (SPEC 5.2-5.3). Pairs are independent, so they run in
  // parallel; the confirmed flags are gathered in pair order, so the result does not
  // depend on the thread count.
  t0 = Clock::now();
  confirmed_.assign(pairs_.size(), 0);
  std::uint64_t box_tests = 0, box_pairs = 0, vertex_tests = 0;
  const std::int64_t np = static_cast<std::int64_t>(pairs_.size());
  // Few pairs are cheaper on one thread than waking the team.
#pragma omp parallel for schedule(dynamic, 8) reduction(+ : box_tests, box_pairs, vertex_tests) \
    if (np >= 64)
  for (std::int64_t k = 0; k < np; ++k) {
    const Pair p = pairs_[static_cast<std::size_t>(k)];
    if (state_.w[p.a] == 0.0f && state_.w[p.b] == 0.0f) continue;  // static-static
    const std::uint32_t sa = info_[p.a].shape, sb = info_[p.b].shape;
    const PlacedShape a{shapes_[sa].octree.get(), state_.x[p.a], aabbs_[p.a]};
    const PlacedShape b{shapes_[sb].octree.get(), state_.x[p.b], aabbs_[p.b]};
    MidphaseStats st;
    confirmed_[static_cast<std::size_t>(k)] =
        confirm_contact(a, b, theta(sa, sb), scene_.midphase, st) ? 1 : 0;
    box_tests += st.box_tests;
    box_pairs += st.box_pairs;
    vertex_tests += st.vertex_tests;
  }
  m.box_tests = box_tests;
  m.box_pairs = box_pairs;
  m.vertex_tests = vertex_tests;
  stage_ms(Stage::Midphase) = ms_since(t0);

  // 5. Response (SPEC 6), Jacobi style: every contact reads the pre-response state;
  // position corrections are averaged per body, velocity changes summed, in (a, b) order.
  t0 = Clock::now();
  contacts_.clear();
  std::fill(dx_sum_.begin(), dx_sum_.end(), Vec3{});
  std::fill(dv_sum_.begin(), dv_sum_.end(), Vec3{});
  std::fill(contact_count_.begin(), contact_count_.end(), 0u);
  double pen_sum = 0.0, pen_max = 0.0;
  std::uint64_t pen_above = 0, pen_count = 0;
  for (std::size_t k = 0; k < pairs_.size(); ++k) {
    if (!confirmed_[k]) continue;
    const Pair p = pairs_[k];
    ++m.contacts;
    Penetration pen = penetration(aabbs_[p.a], aabbs_[p.b], params.epsilon);
    if (!pen.hit) continue;  // Eq. 9: no overlap on an axis: discard
    if (faults_.normal_sign) pen.normal = -pen.normal;
    ++pen_count;
    pen_sum += pen.depth;
    pen_max = std::max(pen_max, static_cast<double>(pen.depth));
    if (pen.depth > params.slop) ++pen_above;
    const float wa = state_.w[p.a], wb = state_.w[p.b];
    const Vec3 c = position_correction(pen, params);
    ContactRecord rec;
    rec.pair = p;
    rec.normal = pen.normal;
    rec.depth = pen.depth;
    rec.axis = pen.axis;
    rec.v_a = state_.v[p.a];
    rec.v_b = state_.v[p.b];
    // Algorithm 3's weights (SPEC 6); the planted fault swaps them as Eq. 12 does.
    const bool swap = faults_.eq12_weights;
    rec.dx_a = correction_share(swap ? wb : wa, wa, wb) * c;
    rec.dx_b = -(correction_share(swap ? wa : wb, wa, wb) * c);
    ContactImpulse imp = contact_impulse(rec.v_a, rec.v_b, wa, wb, pen.normal, params);
    if (faults_.friction_sign) {
      imp.dv_a -= (2.0f * wa * imp.jt) * imp.tangent;
      imp.dv_b += (2.0f * wb * imp.jt) * imp.tangent;
      imp.jt = -imp.jt;
    }
    if (faults_.momentum_leak) imp.dv_b = 0.9f * imp.dv_b;
    rec.jn = imp.jn;
    rec.jt = imp.jt;
    rec.dv_a = imp.dv_a;
    rec.dv_b = imp.dv_b;
    dx_sum_[p.a] += rec.dx_a;
    dx_sum_[p.b] += rec.dx_b;
    ++contact_count_[p.a];
    ++contact_count_[p.b];
    dv_sum_[p.a] += rec.dv_a;
    dv_sum_[p.b] += rec.dv_b;
    contacts_.push_back(rec);
  }
  for (std::size_t i = 0; i < n; ++i) {
    if (state_.w[i] == 0.0f) continue;
    if (contact_count_[i] > 0) {
      state_.x[i] += (1.0f / static_cast<float>(contact_count_[i])) * dx_sum_[i];
      state_.v[i] += dv_sum_[i];
    }
    state_.v[i] = clamp_velocity(state_.v[i], params.max_velocity);  // Eq. 23
  }
  stage_ms(Stage::Response) = ms_since(t0);

  // 6. Metrics and the NaN guard.
  t0 = Clock::now();
  if (pen_count > 0) {
    m.penetration_mean = pen_sum / static_cast<double>(pen_count);
    m.penetration_max = pen_max;
    m.penetration_share_above_slop = static_cast<double>(pen_above) / static_cast<double>(pen_count);
  }
  for (std::size_t i = 0; i < n; ++i) {
    if (state_.w[i] == 0.0f) continue;
    if (!is_finite(state_.x[i]) || !is_finite(state_.v[i]))
      throw RuntimeError(fmt::format(
          "frame {}: body {} (group '{}') has a non-finite {} ({}, {}, {}); the run stops here",
          m.frame, i, info_[i].group, is_finite(state_.x[i]) ? "velocity" : "position",
          is_finite(state_.x[i]) ? state_.v[i].x : state_.x[i].x,
          is_finite(state_.x[i]) ? state_.v[i].y : state_.x[i].y,
          is_finite(state_.x[i]) ? state_.v[i].z : state_.x[i].z));
    const double mass = 1.0 / static_cast<double>(state_.w[i]);
    const Vec3 v = state_.v[i];
    m.kinetic_energy += 0.5 * mass *
                        (static_cast<double>(v.x) * v.x + static_cast<double>(v.y) * v.y +
                         static_cast<double>(v.z) * v.z);
    m.momentum[0] += mass * v.x;
    m.momentum[1] += mass * v.y;
    m.momentum[2] += mass * v.z;
  }
  std::uint64_t bytes = capacity_bytes(state_.x) + capacity_bytes(state_.v) + capacity_bytes(state_.w) +
                        capacity_bytes(aabbs_) + capacity_bytes(pairs_) + capacity_bytes(confirmed_) +
                        capacity_bytes(contacts_) + capacity_bytes(dx_sum_) + capacity_bytes(dv_sum_) +
                        capacity_bytes(contact_count_) + bp.memory_bytes;
  for (const Shape& s : shapes_)
    if (s.octree) bytes += octree_bytes(*s.octree);
  m.memory_bytes = bytes;
  stage_ms(Stage::Metrics) = ms_since(t0);

  m.step_ms = ms_since(t_step);
  frame_ = m.frame;
  metrics_ = m;
  return metrics_;
}

std::uint64_t World::state_hash() const {
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
  feed(state_.x);
  feed(state_.v);
  return h;
}

}  // namespace octocd
