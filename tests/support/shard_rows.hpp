// A two-shard `validate --trace-in t.h5 --shard i/2 --json` run: its rows and identity, the
// fixture of the shard merge's tests (tests/validation/test_shards.cpp) and of its fuzz
// target (fuzz/fuzz_shards.cpp).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "octocd/shards.hpp"
#include "octocd/validation.hpp"

namespace octocd::test {

/// The rows of shard `index`: `penetration` (merged by the maximum; measured 1 mm x
/// (index + 1) against a 0.5 mm bound, its example on frame `example_frame`, failing items
/// "pair (0, 1)" and "pair (index, 2)") and `contact-completeness` (merged by the sum; 2
/// missing contacts, the example on frame example_frame + 2).
inline std::vector<ValidationResult> shard_rows(int index, std::int64_t example_frame) {
  ValidationResult pen;
  pen.tier = Tier::Physics;
  pen.name = "penetration";
  pen.figure = "deepest penetration (m)";
  pen.measured = 0.001 * (index + 1);
  pen.bound = 0.0005;
  pen.pass = false;
  pen.judged = 10;
  pen.seconds = 0.5;
  pen.detail = "frame " + std::to_string(example_frame) + ": pair (0, 1)";
  pen.tolerances = "penetration_slops";
  ValidationCause c;
  c.name = "penetration";
  c.unit = "m";
  c.count = 3;
  c.worst = pen.measured;
  c.examples.push_back({example_frame, "pair (0, 1)", pen.measured, "too deep"});
  c.items = {"pair (0, 1)", "pair (" + std::to_string(index) + ", 2)"};
  pen.causes.push_back(c);
  ValidationResult cc;
  cc.tier = Tier::Physics;
  cc.name = "contact-completeness";
  cc.figure = "contacts missing or false";
  cc.measured = 2;
  cc.bound = 0;
  cc.pass = false;
  cc.judged = 20;
  cc.detail = "frame 3: pair (1, 2)";
  ValidationCause m;
  m.name = "missing-contact";
  m.unit = "m";
  m.count = 2;
  m.worst = 0.01;
  m.examples.push_back({example_frame + 2, "pair (1, 2)", 0.01, "missing"});
  m.items = {"pair (1, 2)"};
  cc.causes.push_back(m);
  return {pen, cc};
}

/// The run's header as `validate --json` writes it (engine bullet, 90 frames of a trace of 8
/// bodies judged every 3rd, against none) with the "shard" object of shard `index` of
/// `count`.
inline nlohmann::ordered_json shard_meta(int index, int count) {
  ShardIdentity id;
  id.trace = "t.h5";
  id.trace_bytes = 12345;
  id.engine = "bullet";
  id.bodies = 8;
  id.frames = 90;
  id.every = 3;
  id.against = "none";
  nlohmann::ordered_json meta = {{"engine", "bullet"}, {"frames", 90}, {"every", 3}, {"against", "none"}};
  meta["shard"] = shard_json({index, count}, id);
  return meta;
}

}  // namespace octocd::test
