// The physics tier with a judge device (octocd/device_judge.hpp; physics_impl.hpp): a
// checked frame's candidates and box-box geometry from the device, every other pair's from
// the CPU reference, for rows 1 (broadphase-completeness) and 4 (penetration), which judge
// them as they judge the CPU's (candidates.cpp, penetration.cpp). Every other row stays on
// the CPU (physics_table.cpp); rows 2 and 3's CheckedFrame takes the device's candidates
// (PhysicsValidators::Impl::checked). impulse-feasibility and the near-pair search take their
// pairs within a step's reach from the device too (reach_pairs).
#include "physics_impl.hpp"

#include "../src/parallel.hpp"

#include <algorithm>
#include <chrono>
#include <iterator>
#include <stdexcept>

#include "octocd/exact_pairs.hpp"

namespace octocd {

using namespace physics_detail;

void PhysicsValidators::set_judge_device(std::unique_ptr<DeviceJudge> device) {
  impl_->device = std::move(device);
  impl_->device_bodies_set = false;
}

namespace {

/// A truth pair's answer while the frame is built: the device's, or the CPU reference's to come.
struct Pending {
  DeviceTruth t;
  bool cpu = false;  // still to be computed by the CPU reference
};

}  // namespace

void PhysicsValidators::Impl::set_device_bodies() {
  if (device_bodies_set) return;
  const std::size_t n = model->bodies.size();
  const double slack = tol.geometry_slack_m;
  const double reach = std::max(tol.broadphase_margin_m, max_margin) + slack;
  // A box on the device: a box shape (or a body declared as its box), its hull the 8
  // corners of its local box; any other body's pairs go to the CPU reference.
  std::vector<DeviceJudgeBody> b(n);
  device_box.assign(n, 0);
  for (std::size_t i = 0; i < n; ++i) {
    const auto body = static_cast<std::uint32_t>(i);
    const CollisionShape shape_as =
        bodies.collision_shape.empty() ? CollisionShape::Mesh : bodies.collision_shape[i];
    const bool box_shape = !model->shapes[model->bodies[i].shape].mesh;
    bool box = (box_shape && shape_as != CollisionShape::Sphere) || shape_as == CollisionShape::Box;
    if (box) {
      const HullFeatures& h = ref->hull_features(body);
      box = h.vertices.size() == 8 && h.face_normals.size() == 3;
      if (box) {
        b[i].lo = b[i].hi = h.vertices[0];
        for (const auto& v : h.vertices)
          for (int d = 0; d < 3; ++d) b[i].lo[d] = std::min(b[i].lo[d], v[d]), b[i].hi[d] = std::max(b[i].hi[d], v[d]);
      }
    }
    b[i].box = box;
    b[i].dynamic = dynamic(body);
    b[i].grow = 0.5 * reach + radius(body);
    device_box[i] = box ? 1 : 0;
  }
  device->set_bodies(b);
  device_bodies_set = true;
}

void PhysicsValidators::Impl::device_frame(const FrameRecord& rec, const std::vector<Pose>& det,
                                           DeviceCheckedFrame& f) {
  const std::size_t n = model->bodies.size();
  const double slack = tol.geometry_slack_m;
  const bool need_distance = tol.broadphase_margin_m - slack > 0;
  f.rec = &rec;
  set_device_bodies();
  // Non-box bodies' exact posed world AABBs (the CPU reference's), boxes posed on the device.
  std::vector<Aabb> world;
  if (std::find(device_box.begin(), device_box.end(), 0) != device_box.end()) {
    world.resize(n);
    parallel_items(n, threads, stop, [&](std::size_t i, unsigned) {
      if (!device_box[i]) world[i] = ref->world_aabb(static_cast<std::uint32_t>(i), det[i]);
    });
  }
  device->judge_frame(det, world, f.answer);
  device_seconds += f.answer.device_seconds;
  ++device_frames;
  const std::vector<Pair>& cand = f.answer.candidates;
  device_candidates += cand.size();

  // The loops below over the candidates, the contact rows and the truth pairs run on the
  // threads (each item writes its own slot; lists are selected in item order), so the
  // frame is the one a single thread builds.
  // The contact pairs: the pair of each run of one pair's rows (rows of a pair are
  // consecutive), sorted and made distinct where the engine's runs are not in pair order.
  std::vector<std::size_t> starts;
  pair_run_starts(rec.contacts, starts, threads, stop);
  f.contact_pairs.resize(starts.size());
  parallel_ranges(starts.size(), loop_threads(threads, starts.size(), kParallelSelectFrom), stop,
                  [&](std::size_t first, std::size_t last) {
    for (std::size_t k = first; k < last; ++k) f.contact_pairs[k] = rec.contacts[starts[k]].pair;
  });
  if (std::adjacent_find(f.contact_pairs.begin(), f.contact_pairs.end(), [](Pair a, Pair b) { return !(a < b); }) !=
      f.contact_pairs.end()) {
    std::sort(f.contact_pairs.begin(), f.contact_pairs.end());
    f.contact_pairs.erase(std::unique(f.contact_pairs.begin(), f.contact_pairs.end()), f.contact_pairs.end());
  }

  // Which candidates enter the truth: as the CPU's checked_frame, every candidate whose
  // shapes intersect (touching counts), every candidate with a broadphase margin or a
  // convex radius.
  std::vector<char> hit(cand.size(), 0);
  parallel_items(cand.size(), threads, stop, [&](std::size_t k, unsigned) {
    const Pair p = cand[k];
    const DeviceBoxSat& s = f.answer.sat[k];
    if (need_distance || inflation(p) > 0)
      hit[k] = 1;
    else if (s.box)
      hit[k] = s.overlap >= 0 ? 1 : 0;
    else
      hit[k] = ref->intersect(p.a, p.b, det[p.a], det[p.b]) ? 1 : 0;
  });
  std::vector<Pair> hits;
  parallel_select(
      cand.size(), hits, loop_threads(threads, cand.size(), kParallelSelectFrom), stop,
      [&](std::size_t k) { return hit[k] != 0; }, [&](std::size_t k) { return cand[k]; });
  f.truth_pairs.clear();
  std::set_union(hits.begin(), hits.end(), f.contact_pairs.begin(), f.contact_pairs.end(),
                 std::back_inserter(f.truth_pairs));
  f.truth_pairs.erase(std::unique(f.truth_pairs.begin(), f.truth_pairs.end()), f.truth_pairs.end());

  // Each truth pair's box test: the candidate's, or the device's for contact pairs that are
  // no candidates.
  // Both lists are sorted: each block of truth pairs looks its candidates up onwards.
  const std::size_t nt = f.truth_pairs.size();
  std::vector<DeviceBoxSat> sat(nt);
  std::vector<char> is_extra(nt, 0);
  parallel_ranges(nt, loop_threads(threads, nt, kParallelSelectFrom), stop, [&](std::size_t first, std::size_t last) {
    std::size_t cursor = 0;
    for (std::size_t i = first; i < last; ++i) {
      const Pair p = f.truth_pairs[i];
      const std::size_t k = seek(cand, p, cursor);
      if (k < cand.size() && cand[k] == p)
        sat[i] = f.answer.sat[k];
      else
        is_extra[i] = 1;
    }
  });
  std::vector<Pair> extra;
  std::vector<std::size_t> extra_at;
  parallel_select(
      nt, extra_at, loop_threads(threads, nt, kParallelSelectFrom), stop, [&](std::size_t i) { return is_extra[i] != 0; },
      [&](std::size_t i) { return i; });
  for (const std::size_t i : extra_at) extra.push_back(f.truth_pairs[i]);
  if (!extra.empty()) {
    std::vector<DeviceBoxSat> more;
    device->box_sat(extra, more);
    for (std::size_t k = 0; k < extra.size(); ++k) sat[extra_at[k]] = more[k];
  }

  // Decided on the device: two boxes that penetrate (the least overlap is the depth, the
  // rounded shapes' plus their radii), or that are apart by more than their radii and the
  // margin (the least overlap's negative bounds the distance from below). Touching boxes,
  // boxes closer than that, and every other pair: the CPU reference.
  std::vector<Pending> pending(nt);
  const double apart_beyond = std::max(0.0, tol.broadphase_margin_m - slack);
  parallel_ranges(nt, loop_threads(threads, nt, kParallelSelectFrom), stop, [&](std::size_t first, std::size_t last) {
    for (std::size_t i = first; i < last; ++i) {
      const Pair p = f.truth_pairs[i];
      const DeviceBoxSat& s = sat[i];
      const double r = inflation(p);
      Pending& e = pending[i];
      if (s.box && s.overlap > 0) {
        e.t.g.valid = true;
        e.t.g.penetrating = true;
        e.t.g.depth = s.overlap + r;
      } else if (s.box && -s.overlap - r > apart_beyond) {
        e.t.g.valid = true;
        e.t.g.penetrating = false;
        e.t.g.distance = -s.overlap - r;  // a lower bound: enough to decide rows 1 and 4
      } else {
        e.cpu = true;
      }
    }
  });
  std::vector<std::size_t> cpu;
  parallel_select(
      nt, cpu, loop_threads(threads, nt, kParallelSelectFrom), stop, [&](std::size_t i) { return pending[i].cpu; },
      [&](std::size_t i) { return i; });
  std::vector<PairReferenceScratch> scratch(loop_threads(threads, cpu.size()));
  parallel_items(cpu.size(), threads, stop, [&](std::size_t k, unsigned worker) {
    const std::size_t i = cpu[k];
    const Pair p = f.truth_pairs[i];
    ContactTruth t;
    t.assign(pair_reference_into(*ref, p.a, p.b, det[p.a], det[p.b], sat_settings, scratch[worker]));
    t.inflate(radius(p.a), radius(p.b));
    pending[i].t.g = t.g;
    pending[i].t.cpu = true;
  });
  f.truth.resize(nt);
  parallel_ranges(nt, loop_threads(threads, nt, kParallelSelectFrom), stop, [&](std::size_t first, std::size_t last) {
    for (std::size_t i = first; i < last; ++i) f.truth[i] = pending[i].t;
  });
  device_box_pairs += pending.size() - cpu.size();
  device_cpu_pairs += cpu.size();
  for (const std::size_t i : cpu) {
    const Pair p = f.truth_pairs[i];
    const std::string& a = model->shapes[model->bodies[p.a].shape].name;
    const std::string& b = model->shapes[model->bodies[p.b].shape].name;
    ++device_cpu_shapes[a < b ? a + " / " + b : b + " / " + a];
  }

  // The required pairs, as the CPU's checked_frame takes them: looked up in blocks, each
  // onwards from its own cursor, then listed in order.
  std::vector<char> is_required(cand.size(), 0);
  parallel_ranges(cand.size(), loop_threads(threads, cand.size(), kParallelSelectFrom), stop,
                  [&](std::size_t first, std::size_t last) {
    std::size_t cursor = 0;
    for (std::size_t k = first; k < last; ++k) is_required[k] = required_pair(f, cand[k], hit[k] != 0, cursor) ? 1 : 0;
  });
  parallel_select(
      cand.size(), f.required, loop_threads(threads, cand.size(), kParallelSelectFrom), stop,
      [&](std::size_t k) { return is_required[k] != 0; }, [&](std::size_t k) { return cand[k]; });
}

const DeviceTruth& PhysicsValidators::Impl::truth_after(DeviceCheckedFrame& f, Pair p, std::size_t& cursor) const {
  const std::size_t k = seek(f.truth_pairs, p, cursor);
  if (k >= f.truth_pairs.size() || !(f.truth_pairs[k] == p))
    throw std::logic_error(fmt::format("device frame: pair ({}, {}) has no truth", p.a, p.b));
  return f.truth[k];
}

void PhysicsValidators::Impl::reach_pairs(const std::vector<Aabb>& grown, std::vector<Pair>& out,
                                          ExactPairsTables& tables) {
  const std::size_t n = grown.size();
  if (device) {
    set_device_bodies();
    const auto t0 = std::chrono::steady_clock::now();
    device->overlapping_pairs(grown, out);
    device_reach_seconds += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    ++device_reach_calls;
    require_pair_limit(out.size(), n);
    return;
  }
  reach_pairs_cpu(grown, out, tables);
}

void PhysicsValidators::Impl::reach_pairs_cpu(const std::vector<Aabb>& grown, std::vector<Pair>& out,
                                              ExactPairsTables& tables) const {
  ExactPairsSettings settings;
  settings.threads = threads;
  settings.max_pairs_per_body = limits::kMaxPairsPerBody;
  exact_pairs(grown, out, settings, tables);
  out.erase(std::remove_if(out.begin(), out.end(), [&](Pair p) { return !dynamic(p.a) && !dynamic(p.b); }), out.end());
}

std::string PhysicsValidators::Impl::device_note() const {
  std::string shapes;
  for (const auto& [name, count] : device_cpu_shapes)
    shapes += fmt::format("{}{} {}", shapes.empty() ? "" : ", ", count, name);
  return fmt::format(
      "judged on the device ({}): {} checked frames, {:.3g} candidate pairs a frame, {} pair-frames of two boxes "
      "decided there (separating axes, double precision), {} by the CPU reference{}; device calls {:.3g} ms a frame "
      "(candidates and box tests), {:.3g} ms (flat's set on the engine's AABBs); {} searches of pairs within a step's "
      "reach (impulse-feasibility, the near pairs) {:.3g} ms each",
      device->device_name(), device_frames, device_frames ? double(device_candidates) / double(device_frames) : 0.0,
      device_box_pairs, device_cpu_pairs, shapes.empty() ? "" : " (" + shapes + ")",
      device_frames ? 1e3 * device_seconds / double(device_frames) : 0.0,
      device_frames ? 1e3 * device_flat_seconds / double(device_frames) : 0.0, device_reach_calls,
      device_reach_calls ? 1e3 * device_reach_seconds / double(device_reach_calls) : 0.0);
}

}  // namespace octocd
