// One step of an external trace as a FrameRecord (trace_in.hpp): its states or detection
// pose, pairs, contacts and version 2 fields (rotation, detection pose, sleeping flags,
// centre-of-mass states, contact points, friction vectors), each value checked
// (check_frame_record, and the magnitudes arithmetic must not overflow).
#include "trace_in.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

#include "octocd/math.hpp"

namespace octocd {

namespace detail {

FrameRecord TraceIn::frame(std::int64_t f) {
  FrameRecord rec;
  rec.frame = f;
  rec.has_contact_terms = false;  // a trace's contacts: pair, normal, depth, jn, jt (v2: point)
  const hsize_t r = static_cast<hsize_t>(f);
  if (info.has_aabbs) {
    const std::vector<float> lo = read<float>(aabb_min_, r - 1, 1), hi = read<float>(aabb_max_, r - 1, 1);
    rec.aabbs.resize(n_);
    for (hsize_t i = 0; i < n_; ++i)
      rec.aabbs[i] = {{lo[3 * i], lo[3 * i + 1], lo[3 * i + 2]}, {hi[3 * i], hi[3 * i + 1], hi[3 * i + 2]}};
  }
  if (info.has_states && pose_only()) {
    // TraceStates::Recorded: no states; the detection pose from the recorded state f - 1.
    if (posed(f)) {
      const hsize_t row = static_cast<hsize_t>(
          std::lower_bound(state_frames_.begin(), state_frames_.end(), f - 1) - state_frames_.begin());
      rec.x_det = vectors(read<float>(position_, row, 1));
      if (info.version == 1 || integrated_) {  // design.md section 4.1: v + dt g, then x + dt v
        const std::vector<Vec3> v = vectors(read<float>(velocity_, row, 1));
        for (std::size_t i = 0; i < rec.x_det.size(); ++i) {
          Vec3 vi = v[i];
          integrate(rec.x_det[i], vi, bodies.inverse_mass[i], det_gravity_, Vec3{}, det_dt_);
        }
      }
      if (info.has_rotation) rec.q_det = quats(read<float>(orientation_, row, 1));
    }
  } else if (info.has_states) {
    const auto [pre, post] = state_rows(f);
    rec.x_pre = vectors(read<float>(position_, pre, 1));
    rec.v_pre = vectors(read<float>(velocity_, pre, 1));
    rec.x_post = vectors(read<float>(position_, post, 1));
    rec.v_post = vectors(read<float>(velocity_, post, 1));
  }
  rec.has_pairs = info.has_pairs;
  if (info.has_pairs) rec.pairs = pairs(pairs_, pair_offsets_, f);
  if (info.has_contacts) {
    const std::vector<Pair> cp = pairs(c_pair_, contact_offsets_, f);
    const hsize_t first = static_cast<hsize_t>(contact_offsets_[r - 1]), count = cp.size();
    const std::vector<float> nrm = read<float>(c_normal_, first, count), depth = read<float>(c_depth_, first, count),
                             jn = read<float>(c_jn_, first, count), jt = read<float>(c_jt_, first, count);
    for (std::size_t k = 0; k < cp.size(); ++k) {
      ContactRecord c;
      c.pair = cp[k];
      c.normal = {nrm[3 * k], nrm[3 * k + 1], nrm[3 * k + 2]};
      c.depth = depth[k];
      c.jn = jn[k];
      c.jt = jt[k];
      rec.contacts.push_back(c);
    }
  }
  RecordFieldNames names;
  names.aabbs = "/aabbs/min, /aabbs/max";
  names.pairs = "/pairs/pair";
  names.contact_pair = "/contacts/pair";
  names.contact_normal = "/contacts/normal";
  names.contact_depth = "/contacts/depth";
  names.contact_jn = "/contacts/jn";
  names.contact_jt = "/contacts/jt";
  names.x_pre = names.x_post = "/states/position";
  names.v_pre = names.v_post = "/states/velocity";
  if (info.version == 2) fill_v2(rec, f, names);
  check_frame_record(rec, n_, path_, names);
  check_magnitudes(rec);
  return rec;
}

void TraceIn::fill_v2(FrameRecord& rec, std::int64_t f, RecordFieldNames& names) {
  const hsize_t r = static_cast<hsize_t>(f);
  names.q_pre = names.q_post = names.q_det = "/states/orientation";
  names.w_pre = names.w_post = "/states/angular_velocity";
  names.x_det = "/states/position";
  names.contact_point = "/contacts/point";
  if (info.has_rotation && !pose_only()) {
    const auto [pre, post] = state_rows(f);
    rec.q_pre = quats(read<float>(orientation_, pre, 1));
    rec.q_post = quats(read<float>(orientation_, post, 1));
    rec.w_pre = vectors(read<float>(angular_, pre, 1));
    rec.w_post = vectors(read<float>(angular_, post, 1));
  }
  if (info.has_sleeping && !pose_only()) {
    read_sleeping(rec, f);
  }
  if (info.has_states && !pose_only()) {
    // Where collision detection ran; never inferred from /aabbs.
    rec.x_det = rec.x_pre;
    rec.q_det = rec.q_pre;
    if (integrated_)  // design.md section 4.1: v + dt g, then x + dt v (float32, as octocd's engines)
      for (std::size_t i = 0; i < rec.x_det.size(); ++i) {
        Vec3 v = rec.v_pre[i];
        integrate(rec.x_det[i], v, bodies.inverse_mass[i], det_gravity_, Vec3{}, det_dt_);
      }
    if (!com_offset_.empty()) {  // the states at the centres of mass; x_det stays the origin
      com_state(rec.x_pre, rec.v_pre, rec.q_pre, rec.w_pre);
      com_state(rec.x_post, rec.v_post, rec.q_post, rec.w_post);
    }
  }
  rec.manifolds = true;
  if (info.has_contacts) {
    for (std::size_t k = 1; k < rec.contacts.size(); ++k)
      if (rec.contacts[k].pair == rec.contacts[k - 1].pair) info.manifolds = true;
    if (info.has_points) {
      const hsize_t first = static_cast<hsize_t>(contact_offsets_[r - 1]);
      const std::vector<Vec3> points = vectors(read<float>(c_point_, first, rec.contacts.size()));
      for (std::size_t k = 0; k < points.size(); ++k) rec.contacts[k].point = points[k];
      rec.has_points = true;
    }
    if (c_jt3_.present()) {
      const hsize_t first = static_cast<hsize_t>(contact_offsets_[r - 1]);
      rec.jt3 = vectors(read<float>(c_jt3_, first, rec.contacts.size()));
      names.contact_jt3 = "/contacts/jt3";
    }
    if (c_point_b_.present()) {
      const hsize_t first = static_cast<hsize_t>(contact_offsets_[r - 1]);
      rec.point_b = vectors(read<float>(c_point_b_, first, rec.contacts.size()));
      names.contact_point_b = "/contacts/point_b";
    }
  }
}

void TraceIn::read_sleeping(FrameRecord& rec, std::int64_t f) const {
  const hsize_t r = static_cast<hsize_t>(f);
  const std::vector<std::int64_t> flags = read<std::int64_t>(sleeping_, r - 1, 2);
  rec.asleep_pre.resize(n_);
  rec.asleep_post.resize(n_);
  for (hsize_t i = 0; i < n_; ++i)
    for (int k = 0; k < 2; ++k) {
      const std::int64_t v = flags[static_cast<std::size_t>(k) * n_ + i];
      if (v != 0 && v != 1)
        bad(sleeping_.name, fmt::format("frame {}: body {}: {}", f - 1 + k, i, v),
            "0 (awake) or 1 (the engine deactivated the body: asleep in that state)");
      (k == 0 ? rec.asleep_pre : rec.asleep_post)[i] = static_cast<std::uint8_t>(v);
    }
}

void TraceIn::com_state(std::vector<Vec3>& x, std::vector<Vec3>& v, const std::vector<Quat>& q,
                        const std::vector<Vec3>& w) const {
  for (std::size_t i = 0; i < x.size() && i < com_offset_.size(); ++i) {
    const auto& c = com_offset_[i];
    const Vec3 cb{static_cast<float>(c[0]), static_cast<float>(c[1]), static_cast<float>(c[2])};
    const Vec3 rc = q.empty() ? cb : rotate(q[i], cb);
    x[i] = x[i] + rc;
    if (velocity_at_origin_ && i < v.size() && !w.empty()) v[i] = v[i] + cross(w[i], rc);
  }
}

void TraceIn::check_magnitudes(const FrameRecord& rec) const {
  const auto coord = [&](const std::vector<Vec3>& xs, const char* name, bool with_extent) {
    for (std::size_t i = 0; i < xs.size(); ++i)
      for (int k = 0; k < 3; ++k) {
        double reach = 0.0;
        if (with_extent && i < bodies.local_boxes.size())
          reach = std::max(std::fabs(static_cast<double>(bodies.local_boxes[i].min[k])),
                           std::fabs(static_cast<double>(bodies.local_boxes[i].max[k])));
        if (!(std::fabs(static_cast<double>(xs[i][k])) + reach <= trace_limits::kMaxCoordinate))
          bad(name, fmt::format("frame {}: body {}: {} (+ local extent {})", rec.frame, i, xs[i][k], reach),
              fmt::format("|position| + |local extent| <= {:g} m on every axis", trace_limits::kMaxCoordinate));
      }
  };
  coord(rec.x_pre, "/states/position", true);
  coord(rec.x_post, "/states/position", true);
  // Every axis of the pre- and post-step vectors (`what` in `unit`) within `limit`.
  const auto per_axis = [&](const std::vector<Vec3>& pre, const std::vector<Vec3>& post, const char* name,
                            const char* what, double limit, const char* unit) {
    for (const std::vector<Vec3>* v : {&pre, &post})
      for (std::size_t i = 0; i < v->size(); ++i)
        for (int k = 0; k < 3; ++k)
          if (!(std::fabs((*v)[i][k]) <= limit))
            bad(name, fmt::format("frame {}: body {}: {}", rec.frame, i, (*v)[i][k]),
                fmt::format("|{}| <= {:g} {} per axis", what, limit, unit));
  };
  per_axis(rec.v_pre, rec.v_post, "/states/velocity", "velocity", trace_limits::kMaxSpeed, "m/s");
  per_axis(rec.w_pre, rec.w_post, "/states/angular_velocity", "angular velocity", trace_limits::kMaxAngularSpeed,
           "rad/s");
  const std::string impulse_allowed =
      fmt::format("|impulse| <= {:g} N s (trace_limits::kMaxImpulse)", trace_limits::kMaxImpulse);
  for (std::size_t k = 0; k < rec.contacts.size(); ++k) {
    const ContactRecord& c = rec.contacts[k];
    if (!(std::fabs(c.jn) <= trace_limits::kMaxImpulse))
      bad("/contacts/jn", fmt::format("frame {}: contact {}: {}", rec.frame, k, c.jn), impulse_allowed);
    if (!(std::fabs(c.jt) <= trace_limits::kMaxImpulse))
      bad("/contacts/jt", fmt::format("frame {}: contact {}: {}", rec.frame, k, c.jt), impulse_allowed);
    if (!(std::fabs(c.depth) <= trace_limits::kMaxCoordinate))
      bad("/contacts/depth", fmt::format("frame {}: contact {}: {}", rec.frame, k, c.depth),
          fmt::format("|depth| <= {:g} m", trace_limits::kMaxCoordinate));
    if (rec.has_points)
      for (int a = 0; a < 3; ++a)
        if (!(std::fabs(c.point[a]) <= trace_limits::kMaxCoordinate))
          bad("/contacts/point", fmt::format("frame {}: contact {}: {}", rec.frame, k, c.point[a]),
              fmt::format("|coordinate| <= {:g} m", trace_limits::kMaxCoordinate));
  }
  for (std::size_t k = 0; k < rec.point_b.size(); ++k)
    for (int a = 0; a < 3; ++a)
      if (!(std::fabs(rec.point_b[k][a]) <= trace_limits::kMaxCoordinate))
        bad("/contacts/point_b", fmt::format("frame {}: contact {}: {}", rec.frame, k, rec.point_b[k][a]),
            fmt::format("|coordinate| <= {:g} m", trace_limits::kMaxCoordinate));
  for (std::size_t k = 0; k < rec.jt3.size(); ++k)
    for (int a = 0; a < 3; ++a)
      if (!(std::fabs(rec.jt3[k][a]) <= trace_limits::kMaxImpulse))
        bad("/contacts/jt3", fmt::format("frame {}: contact {}: {}", rec.frame, k, rec.jt3[k][a]), impulse_allowed);
  for (std::size_t i = 0; i < rec.aabbs.size(); ++i)
    for (int k = 0; k < 3; ++k)
      for (float x : {rec.aabbs[i].min[k], rec.aabbs[i].max[k]})
        if (!(std::fabs(x) <= trace_limits::kMaxCoordinate))
          bad("/aabbs/min, /aabbs/max", fmt::format("frame {}: body {}: {}", rec.frame, i, x),
              fmt::format("|corner| <= {:g} m", trace_limits::kMaxCoordinate));
}

std::vector<Pair> TraceIn::pairs(const Dataset& d, const std::vector<std::int64_t>& o, std::int64_t f) const {
  const hsize_t first = static_cast<hsize_t>(o[static_cast<std::size_t>(f - 1)]);
  const hsize_t count = static_cast<hsize_t>(o[static_cast<std::size_t>(f)]) - first;
  const std::vector<std::int64_t> v = read<std::int64_t>(d, first, count);
  std::vector<Pair> out(count);
  for (std::size_t k = 0; k < out.size(); ++k) {
    const std::int64_t a = v[2 * k], b = v[2 * k + 1];
    if (a < 0 || b < 0 || a >= static_cast<std::int64_t>(n_) || b >= static_cast<std::int64_t>(n_))
      bad(d.name, fmt::format("frame {}: row {} is ({}, {}): body index out of range", f, k, a, b),
          fmt::format("body indices in [0, {})", n_));
    out[k] = {static_cast<std::uint32_t>(a), static_cast<std::uint32_t>(b)};
  }
  return out;
}

std::pair<hsize_t, hsize_t> TraceIn::state_rows(std::int64_t f) const {
  if (state_frames_.empty()) return {static_cast<hsize_t>(f - 1), static_cast<hsize_t>(f)};
  const hsize_t r = nearest_row(f);
  return {r, r};
}

std::vector<Quat> TraceIn::quats(const std::vector<float>& wxyz) {
  std::vector<Quat> out(wxyz.size() / 4);
  for (std::size_t i = 0; i < out.size(); ++i)
    out[i] = {wxyz[4 * i], wxyz[4 * i + 1], wxyz[4 * i + 2], wxyz[4 * i + 3]};
  return out;
}

std::vector<Vec3> TraceIn::vectors(const std::vector<float>& xyz) {
  std::vector<Vec3> out(xyz.size() / 3);
  for (std::size_t i = 0; i < out.size(); ++i) out[i] = {xyz[3 * i], xyz[3 * i + 1], xyz[3 * i + 2]};
  return out;
}

}  // namespace detail

}  // namespace octocd
