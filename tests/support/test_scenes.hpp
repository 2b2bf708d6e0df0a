#pragma once
/// \file test_scenes.hpp
/// Scenes built in code, shared by the validator tests (no dataset needed).
#include <string>

#include "octocd/scene.hpp"

namespace octocd::test {

/// 12 light (1 kg) and 12 heavy (4 kg) boxes thrown into an open box: sliding, stacking
/// and dynamic-dynamic contacts within a few hundred frames. `max_velocity` is v_max
/// (m/s, Eq. 23); a low value makes the clamp act on every frame.
inline Scene mixed_boxes(float max_velocity = 50.0f) {
  const std::string text = R"({
    "name": "mixed-boxes", "domain": {"min": [-0.5, 0, -0.5], "max": [0.5, 1.5, 0.5]},
    "frames": 400, "walls": "open-box",
    "response": {"max_velocity": )" + std::to_string(max_velocity) + R"(},
    "groups": [
      {"name": "light", "shape": {"box": [0.06, 0.05, 0.07]}, "count": 12, "mass": 1.0,
       "layout": {"type": "grid", "min": [-0.35, 0.1, -0.35], "max": [0.35, 0.5, 0.35], "spacing": 0.16, "jitter": 0.01, "seed": 5},
       "velocity": {"type": "random", "max": 1.5, "seed": 6}},
      {"name": "heavy", "shape": {"box": [0.08, 0.06, 0.05]}, "count": 12, "mass": 4.0,
       "layout": {"type": "grid", "min": [-0.35, 0.6, -0.35], "max": [0.35, 1.2, 0.35], "spacing": 0.18, "jitter": 0.01, "seed": 7},
       "velocity": {"type": "random", "max": 1.5, "seed": 8}}
    ]})";
  return parse_scene(text, "mixed-boxes (test)");
}

}  // namespace octocd::test
