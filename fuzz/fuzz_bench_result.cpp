// libFuzzer target: the bench-result reader of `octocd bench --resume` (issue 57 item 6):
// the input is the existing result file's text, parsed strictly (parse_json_strict) and
// checked by resumable_points against three fixed sweeps (steps with two windows,
// max-instances, broadphase) whose result header has a fixed machine, so that seeds of the
// same sweep reach the per-point checks; and by finished_result_matches (a speed-accuracy
// --resume). Bad input must end in InputError; anything else (a crash, a sanitizer report,
// another exception such as nlohmann's type_error) is a finding, as is a kept point that is
// not an object with a string id, a status ok or skipped and, when ok, the sweep's windows.
// The replay build prints how many points each sweep kept (the seeds' coverage).
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "../cli/bench_sweep.hpp"
#include "octocd/error.hpp"
#include "octocd/json_strict.hpp"

namespace {

namespace B = octocd::cli::bench;
using json = nlohmann::json;

/// The sweeps a fuzzed result is resumed against (fuzz/regressions/bench_result/ holds
/// results of each, made by scripts/fuzz_bench_result_seeds.py).
constexpr const char* kSweeps[] = {
    R"({"name": "fuzz-steps", "kind": "steps", "scenes": ["pile.json", "pile-b.json"], "engines": ["cpu"],
        "axes": [{"name": "midphase", "values": ["aabb-only", "1,2"], "labels": ["L0", "B"]}],
        "windows": [{"name": "early", "first": 1, "last": 2}, {"name": "late", "first": 3, "last": 4}],
        "repeat": 2})",
    R"({"name": "fuzz-mi", "kind": "max-instances", "scenes": ["pile.json"], "engines": ["cpu"],
        "frames": 2, "warmup": 1, "repeat": 2, "max_instances": 64})",
    R"({"name": "fuzz-bp", "kind": "broadphase", "bodies": [100, 1000], "broadphases": ["octree", "flat"],
        "engines": ["cpu"], "frames": 2, "warmup": 1, "repeat": 2})",
};

struct Case {
  json def;
  B::Sweep s;
  std::vector<B::Point> points;
  json result;
};

const std::vector<Case>& cases() {
  static const std::vector<Case> all = [] {
    std::vector<Case> v;
    for (const char* text : kSweeps) {
      Case c;
      c.def = json::parse(text);
      c.s = B::parse_sweep(c.def, "fuzz-sweep.json", "/nonexistent-octocd-fuzz", "/nonexistent-octocd-fuzz");
      c.points = B::expand(c.s);
      c.result = {{"settings", B::result_settings(c.s, 0, 1)},
                  {"machine", {{"hostname", "fuzz-host"}, {"cpu", "fuzz-cpu"}, {"gpu", "none"}}},
                  {"started", "2026-01-01T00:00:00Z"}};
      v.push_back(std::move(c));
    }
    return v;
  }();
  return all;
}

[[noreturn]] void finding(const std::string& what) {
  std::fprintf(stderr, "fuzz_bench_result: %s\n", what.c_str());
  std::abort();
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  json old;
  try {
    old = octocd::parse_json_strict(text, "fuzz-result.json");
  } catch (const octocd::InputError&) {
    return 0;
  }
  for (const Case& c : cases()) {
    json result = c.result;
    std::size_t kept_count = 0;
    try {
      const auto kept = B::resumable_points(old, "fuzz-result.json", c.s, "fuzz-sweep.json", c.def, c.points, result);
      kept_count = kept.size();
      for (const auto& [id, pt] : kept) {
        if (!pt.is_object() || !pt.contains("id") || pt["id"] != id) finding("a kept point without its id");
        const std::string status = pt["status"].get<std::string>();
        if (status != "ok" && status != "skipped") finding("a kept point of status " + status);
        if (status == "ok" && c.s.kind != "broadphase")
          for (const auto& w : c.s.windows) (void)pt.at("windows").at(w.name).at("steps_per_s").at("n").get<int>();
      }
      if (!result["started"].is_string()) finding("started not a string after resuming");
    } catch (const octocd::InputError&) {
    } catch (const json::exception& e) {
      finding(std::string("nlohmann exception: ") + e.what());
    }
    std::printf("  %s: kept %zu point(s)\n", c.s.name.c_str(), kept_count);
    try {
      (void)B::finished_result_matches(old, "fuzz-result.json", c.def, c.result["settings"]);
    } catch (const octocd::InputError&) {
    } catch (const json::exception& e) {
      finding(std::string("nlohmann exception: ") + e.what());
    }
  }
  return 0;
}
