// A test build of the CPU reference step with planted faults (planted_faults.hpp):
// World::step's stages, in World's order, with each fault where it acts.
#include "faults/planted_faults.hpp"

#include <algorithm>
#include <cmath>
#include <utility>

#include <fmt/format.h>

#include "octocd/error.hpp"
#include "octocd/world.hpp"

namespace octocd {
namespace test {

bool PlantedFaults::any() const {
  return eq12_weights || friction_sign || momentum_leak || normal_sign || impulse_wrong_body || corrections_summed ||
         explicit_euler || skip_clamp || broadphase_drops_pair || midphase_drops_contact || jmin_first_pass_only ||
         one_pass_fewer || last_pass_no_corrections || other_rounding;
}

std::unique_ptr<Engine> cpu_engine(std::shared_ptr<const Model> model, std::unique_ptr<BroadPhase> broadphase,
                                   const PlantedFaults& faults) {
  if (!faults.any()) return std::make_unique<World>(std::move(model), std::move(broadphase));
  return std::make_unique<FaultyWorld>(std::move(model), std::move(broadphase), faults);
}

std::unique_ptr<Engine> cpu_engine(const Scene& scene, const PlantedFaults& faults) {
  return cpu_engine(build_model(scene), make_broadphase(scene.broadphase, scene.domain), faults);
}

ContactImpulse contact_impulse_other_rounding(Vec3 v_a, Vec3 v_b, float w_a, float w_b, Vec3 n,
                                              const ContactParams& p) {
  ContactImpulse r;
  const float w = w_a + w_b;
  if (!(w > 0.0f)) return r;
  const Vec3 v_rel = v_a - v_b;
  const float v_n = dot(v_rel, n);
  const Vec3 v_t = v_rel - v_n * n;
  const float vt_len = length(v_t);
  r.normal_velocity = v_n;
  r.tangent_speed = vt_len;
  if (v_n < 0.0f) {
    const float e_eff = (-v_n < p.restitution_threshold) ? 0.0f : p.restitution;
    r.jn = std::fmax(-(1.0f + e_eff) * (v_n / w), p.impulse_floor);  // contact_impulse: -(1 + e) v_n / w
  }
  if (vt_len > 0.0f) {
    r.tangent = Vec3{v_t.x / vt_len, v_t.y / vt_len, v_t.z / vt_len};  // contact_impulse: (1 / |v_t|) v_t
    const float jt_star = -vt_len / w;
    if (std::fabs(jt_star) <= p.mu_static * r.jn) {
      r.jt = jt_star;
      r.sticking = true;
    } else {
      r.jt = -p.mu_kinetic * r.jn;
    }
  }
  const Vec3 impulse = r.jn * n + r.jt * r.tangent;
  r.dv_a = w_a * impulse;
  r.dv_b = -(w_b * impulse);
  return r;
}

FaultyWorld::FaultyWorld(const Scene& scene, const PlantedFaults& faults)
    : FaultyWorld(build_model(scene), make_broadphase(scene.broadphase, scene.domain), faults) {}

FaultyWorld::FaultyWorld(std::shared_ptr<const Model> model, std::unique_ptr<BroadPhase> broadphase,
                         const PlantedFaults& faults)
    : model_(std::move(model)), faults_(faults), state_(model_->initial), broadphase_(std::move(broadphase)) {
  if (!broadphase_) throw InputError("FaultyWorld: no broadphase given");
  require_translation_only(model_->scene, "cpu");
  aabbs_.resize(state_.size());
  update_world_aabbs(*model_, state_.x, aabbs_);
}

void FaultyWorld::set_state(const BodyState& s) {
  const std::size_t n = state_.size();
  if (s.x.size() != n || s.v.size() != n || s.w.size() != n)
    throw InputError(fmt::format("FaultyWorld::set_state: expected {} bodies, got x {}, v {}, w {}", n,
                                 s.x.size(), s.v.size(), s.w.size()));
  state_ = s;
}

void FaultyWorld::respond_with_faults() {
  const Model& model = *model_;
  const ContactParams& params = model.scene.response;
  const std::size_t n = state_.size();
  ResponseScratch& r = response_;
  contacts_.clear();
  r.dx_sum.resize(n);
  r.dv_sum.resize(n);
  r.count.resize(n);
  const int passes = faults_.one_pass_fewer ? std::max(params.iterations - 1, 1) : params.iterations;
  ContactParams later = params;  // the parameters of the passes after the first
  if (faults_.jmin_first_pass_only) later.impulse_floor = 0.0f;
  for (int pass = 0; pass < passes; ++pass) {
    if (pass > 0) {
      r.pass_aabbs.resize(n);
      update_world_aabbs(model, state_.x, r.pass_aabbs);
    }
    pass_contact_terms(pass > 0 ? r.pass_aabbs : aabbs_, state_, pairs_, confirmed_, pass > 0 ? later : params,
                       r.terms);
    for (std::size_t k = 0; k < pairs_.size(); ++k) {
      ContactTerms& t = r.terms[k];
      if (!t.pen.hit) continue;
      const Pair p = pairs_[k];
      const float wa = state_.w[p.a], wb = state_.w[p.b];
      if (faults_.other_rounding)
        t.imp = contact_impulse_other_rounding(state_.v[p.a], state_.v[p.b], wa, wb, t.pen.normal, params);
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
    }
    if (pass == 0) contact_records(pairs_, r.terms, state_, contacts_);
    if (faults_.impulse_wrong_body) {
      // sum_contact_terms with B's velocity change added to A.
      std::fill(r.dx_sum.begin(), r.dx_sum.end(), Vec3{});
      std::fill(r.dv_sum.begin(), r.dv_sum.end(), Vec3{});
      std::fill(r.count.begin(), r.count.end(), 0u);
      for (std::size_t k = 0; k < pairs_.size(); ++k) {
        const ContactTerms& t = r.terms[k];
        if (!t.pen.hit) continue;
        const Pair p = pairs_[k];
        r.dx_sum[p.a] += t.dx_a;
        r.dx_sum[p.b] += t.dx_b;
        ++r.count[p.a];
        ++r.count[p.b];
        r.dv_sum[p.a] += t.imp.dv_a;
        r.dv_sum[p.a] += t.imp.dv_b;
      }
    } else {
      sum_contact_terms(pairs_, r.terms, r);
    }
    if (faults_.corrections_summed)
      for (std::uint32_t& c : r.count) c = std::min(c, 1u);
    apply_contact_sums(state_, r);
  }
}

const FrameMetrics& FaultyWorld::step() {
  const Model& model = *model_;
  const Scene& scene = model.scene;
  FrameMetrics m;
  m.frame = frame_ + 1;
  m.time = static_cast<double>(m.frame) * static_cast<double>(scene.dt);
  if (recording_) {
    record_.frame = m.frame;
    record_.x_pre = state_.x;
    record_.v_pre = state_.v;
  }
  // 1. Integrate.
  if (faults_.explicit_euler) {
    for (std::size_t i = 0; i < state_.size(); ++i) {
      if (state_.w[i] == 0.0f) continue;
      state_.x[i] = state_.x[i] + scene.dt * state_.v[i];
      state_.v[i] = state_.v[i] + scene.dt * scene.gravity;
    }
  } else {
    integrate_bodies(state_, scene.gravity, scene.dt);
  }
  // 2. World AABBs.
  update_world_aabbs(model, state_.x, aabbs_);
  // 3. Broadphase.
  BroadPhaseStats bp;
  broadphase_->find_pairs(aabbs_, pairs_, bp);
  if (faults_.broadphase_drops_pair) {
    auto it = std::find_if(pairs_.begin(), pairs_.end(),
                           [&](Pair p) { return state_.w[p.a] > 0.0f || state_.w[p.b] > 0.0f; });
    if (it != pairs_.end()) pairs_.erase(it);
  }
  m.cell_candidates = bp.cell_candidates;
  m.aabb_pairs = pairs_.size();
  // 4. Midphase + narrow phase.
  confirm_pairs(model, state_, aabbs_, pairs_, confirmed_, m);
  if (faults_.midphase_drops_contact) {
    auto it = std::find(confirmed_.begin(), confirmed_.end(), std::uint8_t{1});
    if (it != confirmed_.end()) *it = 0;
  }
  // 5. Response, then the clamp.
  respond_with_faults();
  if (!faults_.skip_clamp) clamp_velocities(state_, scene.response.max_velocity);
  m.contacts = contacts_.size();
  // 6. Metrics.
  frame_state_metrics(model, state_, contacts_, scene.response.slop, m);
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
  frame_ = m.frame;
  metrics_ = m;
  return metrics_;
}

}  // namespace test
}  // namespace octocd
