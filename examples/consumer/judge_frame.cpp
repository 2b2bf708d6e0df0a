// Judges frames of "your own engine" with octocd's validators (octocd/external.hpp).
// 1. A toy engine: four boxes, its candidate pairs and its contacts. It tests AABB overlap
//    strictly (min_A < max_B), so it misses the box that rests exactly on the floor. It
//    declares an exact AABB broadphase (physics.broadphase_exact), so the physics tier's
//    broadphase-completeness holds it to flat's set and says octocd's rule is inclusive
//    (Eq. 6). (A touching pair is not a penetrating one: without the declaration a
//    conservative broadphase may leave it out.)
// 2. A rotating engine (design.md section 13): two boxes, one turned 45 degrees about y and spinning,
//    with orientations, angular velocities, its pre-step detection pose and a two-row
//    contact manifold with world points, judged the same way.
// Prints each verdicts table (every row names its tier: physics or model); exit 0 when
// every validator passes, 3 when one fails, 2 on input that breaks the conventions.
#include <cmath>
#include <cstdio>
#include <vector>

#include "octocd/error.hpp"
#include "octocd/external.hpp"
#include "octocd/results_table.hpp"

using octocd::Aabb;
using octocd::Pair;
using octocd::Quat;
using octocd::Vec3;

namespace {

/// The toy engine's broadphase: all pairs, strict overlap test (the bug under test).
std::vector<Pair> toy_pairs(const std::vector<Aabb>& boxes) {
  std::vector<Pair> out;
  for (std::uint32_t a = 0; a < boxes.size(); ++a)
    for (std::uint32_t b = a + 1; b < boxes.size(); ++b) {
      const Aabb &p = boxes[a], &q = boxes[b];
      if (p.min.x < q.max.x && p.max.x > q.min.x && p.min.y < q.max.y && p.max.y > q.min.y &&
          p.min.z < q.max.z && p.max.z > q.min.z)
        out.push_back({a, b});
    }
  return out;
}

/// One step (dt = 0.01 s, no gravity) of a rotating engine: body 0, a 1 kg cube of half
/// side 0.1 turned 45 degrees about y and spinning at 1 rad/s about y, slides at 0.5 m/s
/// into body 1, an unturned 1 kg cube at rest. Its vertical edge (x = 0.1 sqrt 2) enters
/// body 1's face by 5 mm: two contact rows (a manifold) at the ends of the edge, normal
/// from body 1 to body 0 (-x), 0.125 kg m/s each. Equal masses: both leave at 0.25 m/s;
/// the two rows' torques about body 0's centre cancel, so its spin is kept.
std::vector<octocd::ValidationResult> judge_rotating_frame() {
  const float dt = 0.01f, edge = 0.1f * std::sqrt(2.0f), depth = 0.005f;
  octocd::ExternalBodies bodies;
  bodies.local_boxes = {{{-0.1f, -0.1f, -0.1f}, {0.1f, 0.1f, 0.1f}}, {{-0.1f, -0.1f, -0.1f}, {0.1f, 0.1f, 0.1f}}};
  bodies.inverse_mass = {1.0f, 1.0f};
  bodies.dt = dt;
  bodies.gravity = {0.0f, 0.0f, 0.0f};
  bodies.physics.mu = 0.5;  // the engine's friction coefficient (no friction acts here)

  octocd::FrameRecord frame;
  frame.frame = 1;
  const Vec3 spin{0.0f, 1.0f, 0.0f};
  frame.x_pre = {{0.0f, 0.0f, 0.0f}, {edge + 0.1f - depth, 0.0f, 0.0f}};
  frame.v_pre = {{0.5f, 0.0f, 0.0f}, {0.0f, 0.0f, 0.0f}};
  frame.q_pre = {octocd::axis_angle({0.0f, 1.0f, 0.0f}, 0.785398f), Quat{}};
  frame.w_pre = {spin, {0.0f, 0.0f, 0.0f}};
  frame.v_post = {{0.25f, 0.0f, 0.0f}, {0.25f, 0.0f, 0.0f}};
  frame.w_post = frame.w_pre;
  frame.x_post = {frame.x_pre[0] + dt * frame.v_post[0], frame.x_pre[1] + dt * frame.v_post[1]};
  frame.q_post = {octocd::axis_angle({0.0f, 1.0f, 0.0f}, 0.785398f + dt * spin.y), Quat{}};
  frame.x_det = frame.x_pre;  // detection ran on the pre-step pose (Bullet, PhysX)
  frame.q_det = frame.q_pre;
  frame.pairs = {{0, 1}};
  frame.manifolds = true;
  frame.has_points = true;
  for (const float y : {-0.1f, 0.1f}) {
    octocd::ContactRecord c;
    c.pair = {0, 1};
    c.normal = {-1.0f, 0.0f, 0.0f};  // from body 1 to body 0: +n moves body 0 away
    c.depth = depth;
    c.jn = 0.125f;
    c.jt = 0.0f;
    c.point = {edge - 0.5f * depth, y, 0.0f};
    frame.contacts.push_back(c);
  }
  octocd::ExternalOptions options;
  options.engine = "spinner";
  return octocd::validate_frame(bodies, frame, options);
}

}  // namespace

int main() {
  // Bodies: 0 a static floor slab, 1 a box resting exactly on it, 2 and 3 two boxes
  // overlapping by 1 cm along x in mid-air. Local boxes are centred on the positions.
  octocd::ExternalBodies bodies;
  bodies.local_boxes = {{{-2.0f, -0.1f, -2.0f}, {2.0f, 0.1f, 2.0f}},
                        {{-0.1f, -0.1f, -0.1f}, {0.1f, 0.1f, 0.1f}},
                        {{-0.1f, -0.1f, -0.1f}, {0.1f, 0.1f, 0.1f}},
                        {{-0.1f, -0.1f, -0.1f}, {0.1f, 0.1f, 0.1f}}};
  bodies.inverse_mass = {0.0f, 1.0f, 1.0f, 1.0f};  // 1/kg; the floor is static
  const std::vector<Vec3> positions = {{0.0f, -0.1f, 0.0f}, {0.0f, 0.1f, 0.0f}, {1.0f, 1.0f, 0.0f},
                                       {1.19f, 1.0f, 0.0f}};

  octocd::FrameRecord frame;
  frame.frame = 1;
  for (std::size_t i = 0; i < positions.size(); ++i)
    frame.aabbs.push_back(octocd::translated(bodies.local_boxes[i], positions[i]));
  frame.pairs = toy_pairs(frame.aabbs);  // sorted, a < b: the convention
  // The engine's one contact: pair (2, 3), normal from body 3 to body 2 (-x), depth 1 cm.
  octocd::ContactRecord c;
  c.pair = {2, 3};
  c.normal = {-1.0f, 0.0f, 0.0f};
  c.depth = 0.01f;
  c.jn = 0.0f;
  c.jt = 0.0f;
  frame.contacts.push_back(c);

  bodies.physics.broadphase_exact = true;  // its pairs claim to be the overlapping AABBs
  octocd::ExternalOptions options;
  options.engine = "toy-strict";
  try {
    std::printf("toy engine 'toy-strict' (strict AABB overlap):\n");
    const std::vector<octocd::ValidationResult> results = octocd::validate_frame(bodies, frame, options);
    std::printf("%s\n", octocd::format_results(results).c_str());
    std::printf("rotating engine 'spinner' (orientations, angular velocities, a manifold):\n");
    const std::vector<octocd::ValidationResult> rotating = judge_rotating_frame();
    std::printf("%s", octocd::format_results(rotating).c_str());
    int code = 0;
    for (const auto* rs : {&results, &rotating})
      for (const auto& r : *rs)
        if (r.applicable && !r.pass) code = 3;
    return code;
  } catch (const octocd::InputError& e) {
    std::fprintf(stderr, "judge_frame: %s\n", e.what());
    return 2;
  }
}
