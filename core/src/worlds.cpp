// Batched worlds (docs/gpu.md, "Batched worlds"): K copies of a scene placed apart
// on an x-z grid as one model, each optionally perturbed.
#include "octocd/worlds.hpp"

#include <algorithm>
#include <cmath>

#include <fmt/format.h>

#include "octocd/broadphase.hpp"
#include "octocd/error.hpp"
#include "octocd/scene.hpp"

namespace octocd {

namespace {

/// The domain and every body's initial world AABB of `m`.
Aabb model_bounds(const Model& m) {
  Aabb b = m.scene.domain;
  for (std::size_t i = 0; i < m.initial.size(); ++i) {
    const Aabb w = translated(m.local_box(i), m.initial.x[i]);
    b.min = {std::min(b.min.x, w.min.x), std::min(b.min.y, w.min.y), std::min(b.min.z, w.min.z)};
    b.max = {std::max(b.max.x, w.max.x), std::max(b.max.y, w.max.y), std::max(b.max.z, w.max.z)};
  }
  return b;
}

void check_spec(const WorldsSpec& spec) {
  if (spec.count < 1 || spec.count > kMaxWorlds)
    throw InputError(fmt::format("--worlds: {}; allowed: [1, {}]", spec.count, kMaxWorlds));
  if (!(spec.perturb >= 0.0 && spec.perturb <= kMaxWorldPerturb))
    throw InputError(fmt::format("--world-perturb: {}; allowed: [0, {}] m", spec.perturb, kMaxWorldPerturb));
  if (!(spec.margin >= limits::kMinLength && spec.margin <= limits::kMaxLength))
    throw InputError(
        fmt::format("--world-margin: {}; allowed: [{}, {}] m", spec.margin, limits::kMinLength, limits::kMaxLength));
}

/// The initial positions of copy `copy` at offset zero into `out`: `single`'s, each dynamic
/// body moved by uniform(-eps, eps) per axis when copy > 0 and eps > 0. `seeds` is the
/// stream of the copies' seeds (SplitMix64(spec.seed)), advanced once per perturbed copy;
/// copies must come in order 0, 1, 2, ...
void perturbed_positions(const Model& single, const WorldsSpec& spec, std::size_t copy, SplitMix64& seeds,
                         std::vector<Vec3>& out) {
  out = single.initial.x;
  if (copy == 0 || spec.perturb <= 0.0) return;
  SplitMix64 rng(seeds.next());
  const float eps = static_cast<float>(spec.perturb);
  for (std::size_t i = 0; i < out.size(); ++i) {
    if (single.initial.w[i] <= 0.0f) continue;
    const float ux = rng.uniform(-eps, eps), uy = rng.uniform(-eps, eps), uz = rng.uniform(-eps, eps);
    out[i] = {out[i].x + ux, out[i].y + uy, out[i].z + uz};
  }
}

double longest_side(const Aabb& b) {
  return std::max({static_cast<double>(b.max.x) - b.min.x, static_cast<double>(b.max.y) - b.min.y,
                   static_cast<double>(b.max.z) - b.min.z});
}

}  // namespace

WorldsLayout worlds_layout(const Model& single, const WorldsSpec& spec) {
  check_spec(spec);
  WorldsLayout l;
  l.bounds = model_bounds(single);
  const double sx = static_cast<double>(l.bounds.max.x) - l.bounds.min.x + spec.margin;
  const double sz = static_cast<double>(l.bounds.max.z) - l.bounds.min.z + spec.margin;
  l.spacing = {static_cast<float>(sx), 0.0f, static_cast<float>(sz)};
  l.nx = static_cast<long>(std::ceil(std::sqrt(static_cast<double>(spec.count))));
  while (l.nx * l.nx < spec.count) ++l.nx;  // sqrt's rounding
  l.nz = (spec.count + l.nx - 1) / l.nx;
  // The far corner of the grid stays within the coordinate limit (scene.hpp, limits).
  const double far_x = static_cast<double>(l.bounds.max.x) + static_cast<double>(l.nx - 1) * sx;
  const double far_z = static_cast<double>(l.bounds.max.z) + static_cast<double>(l.nz - 1) * sz;
  const double lim = limits::kMaxCoordinate;
  if (far_x > lim || far_z > lim || l.bounds.min.x < -lim || l.bounds.min.z < -lim) {
    const long fit_x = std::max(0L, static_cast<long>(std::floor((lim - l.bounds.max.x) / sx)) + 1);
    const long fit_z = std::max(0L, static_cast<long>(std::floor((lim - l.bounds.max.z) / sz)) + 1);
    const long side = std::min(fit_x, fit_z);
    throw InputError(fmt::format(
        "--worlds: {} copies of scene '{}' (cells of {:.3g} x {:.3g} m on x and z with --world-margin {}) "
        "reach {:.1f} m; allowed: at most {} copies, whose grid stays within |coordinate| <= {} m",
        spec.count, single.scene.name, sx, sz, spec.margin, std::max(far_x, far_z), side * side, lim));
  }
  l.offsets.reserve(static_cast<std::size_t>(spec.count));
  for (long c = 0; c < spec.count; ++c)
    l.offsets.push_back({static_cast<float>(static_cast<double>(c % l.nx) * sx), 0.0f,
                         static_cast<float>(static_cast<double>(c / l.nx) * sz)});
  return l;
}

std::shared_ptr<const Model> make_worlds_model(const Model& single, const std::vector<Vec3>& offsets,
                                               const WorldsSpec& spec) {
  if (offsets.empty()) throw InputError("--worlds: 0 copies; allowed: [1, " + std::to_string(kMaxWorlds) + "]");
  WorldsSpec checked = spec;
  checked.count = static_cast<long>(offsets.size());
  check_spec(checked);
  const std::size_t n = single.initial.size();
  const std::size_t k = offsets.size();
  auto m = std::make_shared<Model>();
  m->shapes = single.shapes;
  m->theta_shape = single.theta_shape;
  m->scene = single.scene;
  const bool rotates = !single.initial.q.empty();
  m->bodies.reserve(n * k);
  BodyState& s = m->initial;
  s.x.reserve(n * k);
  s.v.reserve(n * k);
  s.w.reserve(n * k);
  SplitMix64 seeds(spec.seed);
  std::vector<Vec3> xs;
  for (std::size_t c = 0; c < k; ++c) {
    const Vec3 off = offsets[c];
    perturbed_positions(single, spec, c, seeds, xs);
    for (std::size_t i = 0; i < n; ++i) {
      s.x.push_back(xs[i] + off);
      s.v.push_back(single.initial.v[i]);
      s.w.push_back(single.initial.w[i]);
      if (rotates) {
        s.q.push_back(single.initial.q[i]);
        s.omega.push_back(single.initial.omega[i]);
      }
      m->bodies.push_back(single.bodies[i]);
    }
  }
  // The scene of the batch: every copy's bounds in the domain, the walls already bodies.
  Scene& sc = m->scene;
  const Aabb b = model_bounds(single);
  Aabb dom = b;
  for (const Vec3& off : offsets) {
    dom.min = {std::min(dom.min.x, b.min.x + off.x), std::min(dom.min.y, b.min.y + off.y),
               std::min(dom.min.z, b.min.z + off.z)};
    dom.max = {std::max(dom.max.x, b.max.x + off.x), std::max(dom.max.y, b.max.y + off.y),
               std::max(dom.max.z, b.max.z + off.z)};
  }
  const double side_1 = longest_side(single.scene.domain), side_k = longest_side(dom);
  sc.domain = dom;
  sc.walls = Walls::None;
  sc.name = fmt::format("{} x{} worlds", single.scene.name, k);
  const std::string& bp = sc.broadphase.name;
  const bool octree = bp == broadphase_name(BroadPhaseId::octree) || bp == broadphase_name(BroadPhaseId::octree_strict);
  if (octree && sc.broadphase.octree_depth >= 0 && side_k > side_1) {
    const int deeper = static_cast<int>(std::ceil(std::log2(side_k / side_1) - 1e-9));
    sc.broadphase.octree_depth = std::min(10, sc.broadphase.octree_depth + std::max(0, deeper));
  }
  return m;
}

std::shared_ptr<const Model> make_worlds_model(std::shared_ptr<const Model> single, const WorldsSpec& spec) {
  check_spec(spec);
  if (spec.count == 1 && spec.perturb == 0.0) return single;
  return make_worlds_model(*single, worlds_layout(*single, spec).offsets, spec);
}

std::shared_ptr<const Model> worlds_copy_model(const Model& single, const WorldsSpec& spec, std::size_t copy) {
  WorldsSpec checked = spec;
  checked.count = std::max<long>(1, static_cast<long>(copy) + 1);
  check_spec(checked);
  SplitMix64 seeds(spec.seed);
  std::vector<Vec3> xs;
  for (std::size_t c = 1; c < copy && spec.perturb > 0.0; ++c) (void)seeds.next();  // the earlier copies' seeds
  perturbed_positions(single, spec, copy, seeds, xs);
  auto m = std::make_shared<Model>(single);
  m->initial.x = std::move(xs);
  return m;
}

BodyState world_state(const BodyState& all, std::size_t bodies_per_world, std::size_t copy) {
  const std::size_t lo = copy * bodies_per_world, hi = lo + bodies_per_world;
  if (hi > all.size())
    throw InputError(fmt::format("world {}: bodies [{}, {}) of a state of {}; allowed: a copy whose bodies the "
                                 "state holds",
                                 copy, lo, hi, all.size()));
  BodyState out;
  const auto a = static_cast<std::ptrdiff_t>(lo), z = static_cast<std::ptrdiff_t>(hi);
  out.x.assign(all.x.begin() + a, all.x.begin() + z);
  out.v.assign(all.v.begin() + a, all.v.begin() + z);
  if (all.w.size() >= hi) out.w.assign(all.w.begin() + a, all.w.begin() + z);
  if (all.q.size() >= hi) out.q.assign(all.q.begin() + a, all.q.begin() + z);
  if (all.omega.size() >= hi) out.omega.assign(all.omega.begin() + a, all.omega.begin() + z);
  return out;
}

std::vector<long> worlds_escaped(const Model& batched, const WorldsLayout& layout, double margin,
                                 const BodyState& state) {
  std::vector<long> out;
  const std::size_t k = layout.offsets.size();
  if (k == 0) return out;
  const std::size_t n = batched.initial.size() / k;
  const double half = 0.25 * margin;  // cells of neighbours stay margin / 2 apart
  for (std::size_t c = 0; c < k; ++c) {
    const Vec3 off = layout.offsets[c];
    const double lx = static_cast<double>(layout.bounds.min.x) + off.x - half;
    const double hx = static_cast<double>(layout.bounds.max.x) + off.x + half;
    const double lz = static_cast<double>(layout.bounds.min.z) + off.z - half;
    const double hz = static_cast<double>(layout.bounds.max.z) + off.z + half;
    for (std::size_t i = c * n; i < (c + 1) * n && i < state.size(); ++i) {
      const Aabb w = translated(batched.local_box(i), state.x[i]);
      // NaN compares false, so a non-finite body counts as escaped.
      if (!(w.min.x >= lx && w.max.x <= hx && w.min.z >= lz && w.max.z <= hz)) {
        out.push_back(static_cast<long>(c));
        break;
      }
    }
  }
  return out;
}

}  // namespace octocd
