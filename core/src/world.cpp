// The CPU reference step (SPEC section 4) and its response (SPEC section 6).
#include "octocd/world.hpp"

#include <algorithm>
#include <chrono>
#include <utility>

#include <fmt/format.h>

#include "octocd/error.hpp"
#include "octocd/version.hpp"

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

}  // namespace

World::World(const Scene& scene) : World(scene, make_broadphase(scene.broadphase, scene.domain)) {}

World::World(const Scene& scene, std::unique_ptr<BroadPhase> broadphase)
    : World(build_model(scene), std::move(broadphase)) {}

World::World(std::shared_ptr<const Model> model, std::unique_ptr<BroadPhase> broadphase)
    : model_(std::move(model)), state_(model_->initial), broadphase_(std::move(broadphase)) {
  if (!broadphase_) throw InputError("World: no broadphase given");
  require_translation_only(model_->scene, "cpu");  // SPEC 3: octocd's engines translate only
  const std::size_t n = state_.size();
  aabbs_.resize(n);
  for (std::size_t i = 0; i < n; ++i) aabbs_[i] = translated(model_->local_box(i), state_.x[i]);
  dx_sum_.resize(n);
  dv_sum_.resize(n);
  contact_count_.resize(n);
}

std::string World::device() const { return cpu_description(); }

const FrameMetrics& World::step() {
  const auto t_step = Clock::now();
  const Scene& scene = model_->scene;
  FrameMetrics m;
  m.frame = frame_ + 1;
  m.time = static_cast<double>(m.frame) * static_cast<double>(scene.dt);
  auto stage_ms = [&m](Stage s) -> double& { return m.stage_ms[static_cast<int>(s)]; };
  const std::size_t n = state_.size();
  const ContactParams& params = scene.response;
  if (recording_) {
    record_.frame = m.frame;
    record_.x_pre = state_.x;
    record_.v_pre = state_.v;
  }

  // 1. Integrate (Eq. 1-3).
  auto t0 = Clock::now();
  if (faults_.explicit_euler) {
    for (std::size_t i = 0; i < n; ++i) {
      if (state_.w[i] == 0.0f) continue;
      state_.x[i] = state_.x[i] + scene.dt * state_.v[i];
      state_.v[i] = state_.v[i] + scene.dt * scene.gravity;
    }
  } else {
    for (std::size_t i = 0; i < n; ++i)
      integrate(state_.x[i], state_.v[i], state_.w[i], scene.gravity, Vec3{}, scene.dt);
  }
  stage_ms(Stage::Integrate) = ms_since(t0);

  // 2. World AABBs.
  t0 = Clock::now();
  for (std::size_t i = 0; i < n; ++i) aabbs_[i] = translated(model_->local_box(i), state_.x[i]);
  stage_ms(Stage::Aabbs) = ms_since(t0);

  // 3. Broadphase (SPEC 5.1).
  t0 = Clock::now();
  BroadPhaseStats bp;
  broadphase_->find_pairs(aabbs_, pairs_, bp);
  if (faults_.broadphase_drops_pair) {
    auto it = std::find_if(pairs_.begin(), pairs_.end(),
                           [&](Pair p) { return state_.w[p.a] > 0.0f || state_.w[p.b] > 0.0f; });
    if (it != pairs_.end()) pairs_.erase(it);
  }
  m.cell_candidates = bp.cell_candidates;
  m.aabb_pairs = pairs_.size();
  stage_ms(Stage::Broadphase) = ms_since(t0);

  // 4. Midphase + narrow phase (SPEC 5.2-5.3). Pairs are independent, so they run in
  // parallel; the confirmed flags are gathered in pair order, so the result does not
  // depend on the thread count.
  t0 = Clock::now();
  confirmed_.assign(pairs_.size(), 0);
  std::uint64_t box_tests = 0, box_pairs = 0, vertex_tests = 0, dynamic_pairs = 0;
  const std::int64_t np = static_cast<std::int64_t>(pairs_.size());
  // Few pairs are cheaper on one thread than waking the team.
#pragma omp parallel for schedule(dynamic, 8) \
    reduction(+ : box_tests, box_pairs, vertex_tests, dynamic_pairs) if (np >= 64)
  for (std::int64_t k = 0; k < np; ++k) {
    const Pair p = pairs_[static_cast<std::size_t>(k)];
    if (state_.w[p.a] == 0.0f && state_.w[p.b] == 0.0f) continue;  // static-static
    ++dynamic_pairs;
    const std::uint32_t sa = model_->bodies[p.a].shape, sb = model_->bodies[p.b].shape;
    const PlacedShape a{model_->shapes[sa].octree.get(), state_.x[p.a], aabbs_[p.a]};
    const PlacedShape b{model_->shapes[sb].octree.get(), state_.x[p.b], aabbs_[p.b]};
    MidphaseStats st;
    confirmed_[static_cast<std::size_t>(k)] =
        confirm_contact(a, b, model_->theta(sa, sb), scene.midphase, st) ? 1 : 0;
    box_tests += st.box_tests;
    box_pairs += st.box_pairs;
    vertex_tests += st.vertex_tests;
  }
  if (faults_.midphase_drops_contact) {
    auto it = std::find(confirmed_.begin(), confirmed_.end(), std::uint8_t{1});
    if (it != confirmed_.end()) *it = 0;
  }
  m.dynamic_pairs = dynamic_pairs;
  m.box_tests = box_tests;
  m.box_pairs = box_pairs;
  m.vertex_tests = vertex_tests;
  stage_ms(Stage::Midphase) = ms_since(t0);

  // 5. Response (SPEC 6), Jacobi style, `iterations` passes over the confirmed contacts:
  // every contact of a pass reads the state the previous pass left (the first: the
  // integrated state); per body, position corrections are averaged over its contacts and
  // velocity changes summed, in (a, b) order. The first pass's terms are the contact
  // records. Then the clamp (Eq. 23).
  t0 = Clock::now();
  contacts_.clear();
  double pen_sum = 0.0, pen_max = 0.0;
  std::uint64_t pen_above = 0;
  pass_aabbs_ = aabbs_;
  const int passes = faults_.one_pass_fewer ? std::max(params.iterations - 1, 1) : params.iterations;
  ContactParams later = params;  // the parameters of the passes after the first
  if (faults_.jmin_first_pass_only) later.impulse_floor = 0.0f;
  for (int pass = 0; pass < passes; ++pass) {
    std::fill(dx_sum_.begin(), dx_sum_.end(), Vec3{});
    std::fill(dv_sum_.begin(), dv_sum_.end(), Vec3{});
    std::fill(contact_count_.begin(), contact_count_.end(), 0u);
    if (pass > 0)
      for (std::size_t i = 0; i < n; ++i) pass_aabbs_[i] = translated(model_->local_box(i), state_.x[i]);
    for (std::size_t k = 0; k < pairs_.size(); ++k) {
      if (!confirmed_[k]) continue;
      const Pair p = pairs_[k];
      const float wa = state_.w[p.a], wb = state_.w[p.b];
      ContactTerms t = contact_terms(pass_aabbs_[p.a], pass_aabbs_[p.b], state_.v[p.a], state_.v[p.b],
                                     wa, wb, pass > 0 ? later : params);
      if (!t.pen.hit) continue;  // Eq. 9: no overlap on an axis: discard
      if (faults_.other_rounding)
        t.imp = contact_impulse<true>(state_.v[p.a], state_.v[p.b], wa, wb, t.pen.normal, params);
      if (faults_.last_pass_no_corrections && pass == passes - 1) t.dx_a = t.dx_b = Vec3{};
      if (faults_.normal_sign) {
        t.pen.normal = -t.pen.normal;
        const Vec3 c = position_correction(t.pen, params);
        t.dx_a = correction_share(wa, wa, wb) * c;
        t.dx_b = -(correction_share(wb, wa, wb) * c);
        t.imp = contact_impulse(state_.v[p.a], state_.v[p.b], wa, wb, t.pen.normal, params);
      }
      if (faults_.eq12_weights) {  // the paper's Eq. 12 swaps the weights
        const Vec3 c = position_correction(t.pen, params);
        t.dx_a = correction_share(wb, wa, wb) * c;
        t.dx_b = -(correction_share(wa, wa, wb) * c);
      }
      if (faults_.friction_sign) {
        t.imp.dv_a -= (2.0f * wa * t.imp.jt) * t.imp.tangent;
        t.imp.dv_b += (2.0f * wb * t.imp.jt) * t.imp.tangent;
        t.imp.jt = -t.imp.jt;
      }
      if (faults_.momentum_leak) t.imp.dv_b = 0.9f * t.imp.dv_b;
      dx_sum_[p.a] += t.dx_a;
      dx_sum_[p.b] += t.dx_b;
      ++contact_count_[p.a];
      ++contact_count_[p.b];
      dv_sum_[p.a] += t.imp.dv_a;
      dv_sum_[faults_.impulse_wrong_body ? p.a : p.b] += t.imp.dv_b;
      if (pass > 0) continue;
      pen_sum += t.pen.depth;
      pen_max = std::max(pen_max, static_cast<double>(t.pen.depth));
      if (t.pen.depth > params.slop) ++pen_above;
      ContactRecord rec;
      rec.pair = p;
      rec.normal = t.pen.normal;
      rec.depth = t.pen.depth;
      rec.axis = t.pen.axis;
      rec.v_a = state_.v[p.a];
      rec.v_b = state_.v[p.b];
      rec.dx_a = t.dx_a;
      rec.dx_b = t.dx_b;
      rec.jn = t.imp.jn;
      rec.jt = t.imp.jt;
      rec.dv_a = t.imp.dv_a;
      rec.dv_b = t.imp.dv_b;
      contacts_.push_back(rec);
    }
    for (std::size_t i = 0; i < n; ++i) {
      if (state_.w[i] == 0.0f) continue;
      if (faults_.corrections_summed && contact_count_[i] > 0) contact_count_[i] = 1;
      apply_contact_sums(state_.x[i], state_.v[i], dx_sum_[i], dv_sum_[i], contact_count_[i]);
    }
  }
  if (!faults_.skip_clamp)
    for (std::size_t i = 0; i < n; ++i)
      if (state_.w[i] != 0.0f) state_.v[i] = clamp_velocity(state_.v[i], params.max_velocity);  // Eq. 23
  m.contacts = contacts_.size();
  stage_ms(Stage::Response) = ms_since(t0);

  // 6. Metrics and the NaN guard.
  t0 = Clock::now();
  if (!contacts_.empty()) {
    m.penetration_mean = pen_sum / static_cast<double>(contacts_.size());
    m.penetration_max = pen_max;
    m.penetration_share_above_slop = static_cast<double>(pen_above) / static_cast<double>(contacts_.size());
  }
  for (std::size_t i = 0; i < n; ++i) {
    if (state_.w[i] == 0.0f) continue;
    if (!is_finite(state_.x[i]) || !is_finite(state_.v[i]))
      throw RuntimeError(fmt::format(
          "frame {}: body {} (group '{}') has a non-finite {} ({}, {}, {}); the run stops here",
          m.frame, i, model_->bodies[i].group, is_finite(state_.x[i]) ? "velocity" : "position",
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
                        capacity_bytes(aabbs_) + capacity_bytes(pass_aabbs_) + capacity_bytes(pairs_) +
                        capacity_bytes(confirmed_) + capacity_bytes(contacts_) + capacity_bytes(dx_sum_) +
                        capacity_bytes(dv_sum_) + capacity_bytes(contact_count_) + bp.memory_bytes;
  for (const Shape& s : model_->shapes)
    if (s.octree) bytes += octree_bytes(*s.octree);
  m.memory_bytes = bytes;
  stage_ms(Stage::Metrics) = ms_since(t0);

  if (recording_) {
    record_.aabbs = aabbs_;
    record_.pairs = pairs_;
    record_.confirmed.clear();
    for (std::size_t k = 0; k < pairs_.size(); ++k)
      if (confirmed_[k]) record_.confirmed.push_back(pairs_[k]);
    record_.contacts = contacts_;
    record_.x_post = state_.x;
    record_.v_post = state_.v;
  }

  m.step_ms = ms_since(t_step);
  frame_ = m.frame;
  metrics_ = m;
  return metrics_;
}

void World::set_state(const BodyState& s) {
  const std::size_t n = state_.size();
  if (s.x.size() != n || s.v.size() != n || s.w.size() != n)
    throw InputError(fmt::format("World::set_state: expected {} bodies, got x {}, v {}, w {}", n, s.x.size(),
                                 s.v.size(), s.w.size()));
  state_ = s;
}

}  // namespace octocd
