// libFuzzer target: the shard reader of `octocd validate --merge` (issue 57 item 6). The
// input is the text of one shard's `--json` verdict; beside it a shard 0 is written with two
// fixed rows (causes, examples, items, as `validate --trace-in t.h5 --shard 0/N --json`
// writes them) and the input's own run identity (its "shard" object copied, index 0), so
// that a mutated shard reaches the merge past the identity check. Both files are merged
// with merge_validations exactly as `validate --merge` does (regular-file check, strict
// parse, every field checked), the merged verdict matched against no expectations and
// written as `--json` writes it. Bad input must end in InputError; anything else (a crash, a
// sanitizer report, nlohmann's exception, more examples or items than a cause keeps) is a
// finding. fuzz/regressions/shards/ holds shard 1 of 2 of that run
// (scripts/fuzz_json_seeds.py) and inputs that once failed.
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "fuzz_common.hpp"
#include "octocd/error.hpp"
#include "octocd/expect.hpp"
#include "octocd/json_strict.hpp"
#include "octocd/shards.hpp"
#include "support/shard_rows.hpp"

namespace {

using json = nlohmann::json;

/// Shard 0 of the input's run: shard_rows(0, 1) with the input's "shard" object (index 0, its
/// first and last frame), or a run of 2 shards of t.h5 when the input has none.
std::string shard0_text(const std::string& input) {
  nlohmann::ordered_json meta = octocd::test::shard_meta(0, 2);
  json in;
  try {
    in = octocd::parse_json_strict(input, "input");  // at most 64 levels, as the merge reads it
  } catch (const octocd::InputError&) {
  }
  if (in.is_object() && in.contains("shard") && in["shard"].is_object()) {
    meta["shard"] = nlohmann::ordered_json::parse(in["shard"].dump());
    meta["shard"]["index"] = 0;
    const json& c = in["shard"].contains("count") ? in["shard"]["count"] : json();
    const json& f = in["shard"].contains("frames") ? in["shard"]["frames"] : json();
    if (c.is_number_integer() && f.is_number_integer() && c.get<std::int64_t>() >= 1 && c.get<std::int64_t>() <= 100000 &&
        f.get<std::int64_t>() >= 0 && f.get<std::int64_t>() <= 100000000) {
      const auto fr = octocd::shard_frames({0, static_cast<int>(c.get<std::int64_t>())}, f.get<std::int64_t>());
      meta["shard"]["first_frame"] = fr.first;
      meta["shard"]["last_frame"] = fr.second;
    }
  }
  return octocd::results_json(octocd::test::shard_rows(0, 1), octocd::RunName{"", "t.h5"}, nullptr, meta).dump(1);
}

[[noreturn]] void finding(const std::string& what) {
  std::fprintf(stderr, "fuzz_shards: %s\n", what.c_str());
  std::abort();
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string input(reinterpret_cast<const char*>(data), size);
  const std::string shard0 = octocd_fuzz::scratch_path("shards-0") + ".json";
  const std::string text0 = shard0_text(input);
  octocd_fuzz::write_input(shard0, reinterpret_cast<const std::uint8_t*>(text0.data()), text0.size());
  const std::string shard1 = octocd_fuzz::scratch_path("shards-1") + ".json";
  octocd_fuzz::write_input(shard1, data, size);
  try {
    const octocd::MergedValidation m = octocd::merge_validations({shard0, shard1});
    std::printf("  merged: %zu rows\n", m.results.size());
    for (const octocd::ValidationResult& r : m.results)
      for (const octocd::ValidationCause& c : r.causes) {
        if (c.examples.size() > octocd::ValidationCause::kMaxExamples) finding("more examples than kept");
        if (c.items.size() > octocd::ValidationCause::kMaxItems) finding("more items than kept");
      }
    const octocd::ExpectationReport report = octocd::match_expectations(octocd::Expectations{}, m.run, m.results);
    const std::string out = octocd::results_json(m.results, m.run, &report, {})
                                .dump(2, ' ', false, nlohmann::ordered_json::error_handler_t::replace);
    if (out.empty()) finding("empty --json");
  } catch (const octocd::InputError&) {
  } catch (const json::exception& e) {
    finding(std::string("nlohmann exception: ") + e.what());
  }
  std::remove(shard0.c_str());
  std::remove(shard1.c_str());
  return 0;
}
