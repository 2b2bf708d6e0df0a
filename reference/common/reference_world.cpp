// The adapter base of the reference engines (reference_world.hpp).
#include "octocd/reference_world.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <utility>

#include "octocd/adapter_rows.hpp"
#include "octocd/error.hpp"
#include "octocd/pose.hpp"
#include "octocd/version.hpp"

namespace octocd {

void ReferenceCore::start(std::shared_ptr<const Model> m, const BodyState& initial, const std::string& engine) {
  model = std::move(m);
  const Model& src = *model;
  const std::size_t n = initial.size();
  if (src.bodies.size() != n)
    throw InputError(fmt::format("{}: the initial state has {} bodies, the model {}", engine, n, src.bodies.size()));
  dt = src.scene.dt;
  gravity = src.scene.gravity;
  slop = src.scene.response.slop;
  w = initial.w;
  static_static = static_static_pairs(src);
  state = initial;
  state.q.resize(n);      // identity where the model has none
  state.omega.resize(n);  // zero where the model has none
  traits.rotates = true;
  traits.jt3 = true;
  traits.detection = "pre-step";
  traits.broadphase_exact = false;
  traits.contact_geometry = "shape";
  traits.integrator = "semi-implicit";
}

FrameMetrics ReferenceCore::next_frame() {
  FrameMetrics fm;
  fm.frame = ++frame;
  fm.time = static_cast<double>(frame) * dt;
  return fm;
}

const FrameMetrics& ReferenceCore::finish_step(FrameMetrics& fm, std::chrono::steady_clock::time_point t0) {
  fm.step_ms = ms_since(t0);
  metrics = fm;
  return metrics;
}

void ReferenceCore::save_pre_state() {
  record.frame = frame + 1;
  record.x_pre = state.x;
  record.v_pre = state.v;
  record.q_pre = state.q;
  record.w_pre = state.omega;
}

void ReferenceCore::save_post_state() {
  record.x_post = state.x;
  record.v_post = state.v;
  record.q_post = state.q;
  record.w_post = state.omega;
  record.x_det = record.x_pre;
  record.q_det = record.q_pre;
}

void ReferenceCore::check_finite(const std::string& who) const {
  for (std::size_t i = 0; i < w.size(); ++i)
    if (dynamic(i) && !(is_finite(state.x[i]) && is_finite(state.v[i]) && is_finite(state.omega[i])))
      throw RuntimeError(fmt::format("frame {}: body {} has a non-finite state after {} step (x ({}, {}, {}), v "
                                     "({}, {}, {}))",
                                     frame, i, who, state.x[i].x, state.x[i].y, state.x[i].z, state.v[i].x,
                                     state.v[i].y, state.v[i].z));
}

std::uint64_t ReferenceCore::posed_overlapping_pairs() {
  FrameRecord& r = record;
  const std::size_t n = w.size();
  r.aabbs.resize(n);
  for (std::size_t i = 0; i < n; ++i) r.aabbs[i] = posed_box_aabb(model->local_box(i), {r.x_pre[i], r.q_pre[i]});
  const std::vector<Aabb>& boxes = r.aabbs;
  std::vector<std::uint32_t> order(boxes.size());
  for (std::uint32_t i = 0; i < order.size(); ++i) order[i] = i;
  std::sort(order.begin(), order.end(),
            [&](std::uint32_t a, std::uint32_t b) { return boxes[a].min.x < boxes[b].min.x; });
  std::uint64_t count = 0;
  for (std::size_t k = 0; k < order.size(); ++k) {
    const Aabb& a = boxes[order[k]];
    for (std::size_t j = k + 1; j < order.size() && boxes[order[j]].min.x <= a.max.x; ++j) {
      if (!dynamic(order[k]) && !dynamic(order[j])) continue;
      if (overlaps(a, boxes[order[j]])) ++count;
    }
  }
  return count;
}

ContactRecord ReferenceCore::manifold_row(std::uint32_t i1, std::uint32_t i2, const double normal21[3],
                                          const double impulse1[3], double depth, Vec3 point,
                                          std::vector<Vec3>& jt3) const {
  const bool swap = i1 > i2;  // A is body 2
  const double sa = swap ? -1.0 : 1.0;
  // The engine's normal may be unit only to its own rounding (|n| - 1 ~ 1e-8 from a
  // collider); its friction directions are orthogonal to n whatever its length, so the
  // impulse splits along the unit n: normal part (J.n) n, the rest in the contact plane.
  const double len = std::sqrt(normal21[0] * normal21[0] + normal21[1] * normal21[1] + normal21[2] * normal21[2]);
  const double sn = len > 0.0 ? sa / len : sa;
  const double nrm[3] = {sn * normal21[0], sn * normal21[1], sn * normal21[2]};
  const double j_a[3] = {sa * impulse1[0], sa * impulse1[1], sa * impulse1[2]};
  // The tangential part is J less its whole normal part, J.n of either sign: an engine's
  // normal row has lo = 0, but its summed impulse projected back may round a little below
  // 0 (a solver's tolerance), and that rounding belongs to the normal, never to friction
  // (subtracting max(0, J.n) left it in jt3: a 1.5e-8 row 78 deg out of its plane).
  const double along = j_a[0] * nrm[0] + j_a[1] * nrm[1] + j_a[2] * nrm[2];
  const double jn = std::max(0.0, along);
  double jt_d[3] = {j_a[0] - along * nrm[0], j_a[1] - along * nrm[1], j_a[2] - along * nrm[2]};
  // J's components carry the engine's rounding, a few double epsilons of |J| (its rows are
  // summed, the normal's and the friction's orthogonal, so nothing cancels), and so does the
  // split: a tangential part below kRoundingOfTheSplit |J| (about 4,500 epsilons) is that
  // rounding, of no direction of its own, and no friction (0). Above it the rounding is under
  // 1/400 of the part: within 0.15 deg of the plane. ODE on a static triangle soup gave rows of
  // 2.3e7 kg m/s whose residue of 1.1e-8 kg m/s sat 89.6 deg out of the plane.
  constexpr double kRoundingOfTheSplit = 1e-12;
  const double j_len = std::sqrt(j_a[0] * j_a[0] + j_a[1] * j_a[1] + j_a[2] * j_a[2]);
  const double jt_len = std::sqrt(jt_d[0] * jt_d[0] + jt_d[1] * jt_d[1] + jt_d[2] * jt_d[2]);
  if (jt_len <= kRoundingOfTheSplit * j_len) jt_d[0] = jt_d[1] = jt_d[2] = 0.0;
  ContactRecord c;
  c.pair = swap ? Pair{i2, i1} : Pair{i1, i2};
  c.normal = {static_cast<float>(nrm[0]), static_cast<float>(nrm[1]), static_cast<float>(nrm[2])};
  c.depth = static_cast<float>(std::max(0.0, depth));
  c.point = point;
  c.jn = static_cast<float>(jn);
  const Vec3 j_t{static_cast<float>(jt_d[0]), static_cast<float>(jt_d[1]), static_cast<float>(jt_d[2])};
  c.jt = row_scalar_jt(record, c, j_t, w, dt, gravity);
  jt3.push_back(j_t);
  return c;
}

ReferenceWorld::ReferenceWorld(std::unique_ptr<ReferenceCore> core) : core_(std::move(core)) {}
ReferenceWorld::~ReferenceWorld() = default;

const BodyState& ReferenceWorld::state() const { return core_->state; }
const FrameMetrics& ReferenceWorld::last_metrics() const { return core_->metrics; }
std::int64_t ReferenceWorld::frame() const { return core_->frame; }
std::string ReferenceWorld::device() const { return cpu_description(); }
const Model& ReferenceWorld::model() const { return *core_->model; }
const std::vector<ContactRecord>& ReferenceWorld::contacts() const {
  return core_->recording ? core_->record.contacts : core_->no_contacts;
}
std::string ReferenceWorld::collision_geometry() const { return core_->geometry; }
const RotationTraits* ReferenceWorld::rotation_traits() const { return &core_->traits; }
void ReferenceWorld::set_recording(bool on) { core_->recording = on; }
const FrameRecord& ReferenceWorld::record() const { return core_->record; }

}  // namespace octocd
