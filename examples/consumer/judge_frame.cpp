// Judges one frame of "your own engine" with octocd's validators (octocd/external.hpp):
// four boxes, the engine's candidate pairs and its contacts. The toy engine below tests
// AABB overlap strictly (min_A < max_B), so it misses the box that rests exactly on the
// floor: octocd's rule is inclusive (Eq. 6), and the candidate-sets verdict says so.
// Prints the verdicts table; exit 0 when every validator passes, 3 when one fails, 2 on
// input that breaks the conventions.
#include <cstdio>
#include <vector>

#include "octocd/error.hpp"
#include "octocd/external.hpp"

using octocd::Aabb;
using octocd::Pair;
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

  octocd::ExternalOptions options;
  options.engine = "toy-strict";
  try {
    const std::vector<octocd::ValidationResult> results = octocd::validate_frame(bodies, frame, options);
    std::printf("%s", octocd::format_results(results).c_str());
    for (const auto& r : results)
      if (r.applicable && !r.pass) return 3;
    return 0;
  } catch (const octocd::InputError& e) {
    std::fprintf(stderr, "judge_frame: %s\n", e.what());
    return 2;
  }
}
