// `validate --merge` on untrusted shard files (issue 57 item 4; octocd/shards.hpp): every
// field a merge reads is checked for its presence, type and range before it is used. Shard
// documents are written here as `validate --shard i/N --json` writes them (results_json with
// the "shard" object of shard_json), then one field at a time is removed, retyped or set out
// of range. Before: a missing figure merged silently as NaN, a wrong type was nlohmann's
// exception (exit 1 without the file), a large integer wrapped (get<int>).
// The end-to-end merge of real shards is tests/cli/test_cli_shards.cpp.

#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "octocd/error.hpp"
#include "octocd/expect.hpp"
#include "octocd/shards.hpp"
#include "support/shard_rows.hpp"

namespace octocd {
namespace octocd_test_shards {
namespace {

using json = nlohmann::json;

/// Shard `index` of `count` as `validate --trace-in t.h5 --shard index/count --json` writes it.
json shard_doc(int index, int count) {
  return json::parse(
      results_json(test::shard_rows(index, index * 45 + 1), RunName{"", "t.h5"}, nullptr, test::shard_meta(index, count))
          .dump());
}

std::vector<json> two_shards() { return {shard_doc(0, 2), shard_doc(1, 2)}; }

const std::vector<std::string> kNames = {"s0.json", "s1.json"};

/// The InputError text of merging `docs`, or "" when it merged.
std::string merge_error(const std::vector<json>& docs) {
  try {
    (void)merge_validation_docs(docs, kNames);
  } catch (const InputError& e) {
    return e.what();
  }
  return "";
}

TEST(MergeShards, WellFormedShardsMerge) {
  const MergedValidation m = merge_validation_docs(two_shards(), kNames);
  ASSERT_EQ(m.results.size(), 2u);
  EXPECT_DOUBLE_EQ(m.results[0].measured, 0.002);  // penetration: the largest
  EXPECT_EQ(m.results[0].causes.at(0).count, 6u);
  EXPECT_EQ(m.results[0].causes.at(0).items.size(), 3u);  // the union
  EXPECT_DOUBLE_EQ(m.results[1].measured, 4);  // contact-completeness: the sum
  EXPECT_EQ(m.results[1].judged, 40u);
  EXPECT_EQ(m.identity.frames, 90);
  EXPECT_EQ(m.identity.every, 3);
}

/// Applies `edit` to shard 1 and expects an InputError holding `want` (and the file).
void expect_refused(const std::function<void(json&)>& edit, const std::string& want) {
  std::vector<json> docs = two_shards();
  edit(docs[1]);
  const std::string e = merge_error(docs);
  EXPECT_NE(e.find("--merge: s1.json: "), std::string::npos) << want << ": " << e;
  EXPECT_NE(e.find(want), std::string::npos) << e;
}

TEST(MergeShards, AMissingKeyIsRefusedNamingFileAndKey) {
  // Before: merged with NaN figures (measured, seconds) or empty texts.
  expect_refused([](json& d) { d["rows"][0].erase("measured"); }, "rows[0].measured: missing");
  expect_refused([](json& d) { d["rows"][1].erase("verdict"); }, "rows[1].verdict: missing");
  expect_refused([](json& d) { d["rows"][0].erase("causes"); }, "rows[0].causes: missing");
  expect_refused([](json& d) { d["rows"][0]["causes"][0].erase("count"); }, "rows[0].causes[0].count: missing");
  expect_refused([](json& d) { d["shard"].erase("trace"); }, "shard.trace: missing");
  expect_refused([](json& d) { d["shard"]["tolerances"].erase("penetration_slops"); },
                 "shard.tolerances.penetration_slops: missing");
  expect_refused([](json& d) { d.erase("rows"); }, "rows: missing");
}

TEST(MergeShards, AWrongTypeIsRefusedNamingFileKeyAndAllowedType) {
  // Before: nlohmann's type_error (exit 1, "[json.exception.type_error.302] type must be ...").
  expect_refused([](json& d) { d["rows"][0]["measured"] = "0.1"; },
                 "rows[0].measured: a string \"0.1\"; allowed: null or a number in");
  expect_refused([](json& d) { d["rows"][0]["judged"] = 1.5; }, "rows[0].judged: a number 1.5; allowed: an integer");
  expect_refused([](json& d) { d["rows"][0]["detail"] = 7; }, "rows[0].detail: an integer 7; allowed: a string");
  expect_refused([](json& d) { d["rows"][0]["causes"][0]["items"][0] = 3; },
                 "rows[0].causes[0].items[0]: an integer 3; allowed: a string");
  expect_refused([](json& d) { d["rows"][0]["causes"][0]["examples"] = json::object(); },
                 "rows[0].causes[0].examples: an object {}; allowed: an array");
  expect_refused([](json& d) { d["rows"][0]["causes"][0]["items_complete"] = "yes"; },
                 "items_complete: a string \"yes\"; allowed: true or false");
  expect_refused([](json& d) { d["shard"]["engine"] = json::array(); }, "shard.engine: an array []; allowed: a string");
  expect_refused([](json& d) { d["shard"]["every"] = "3"; }, "shard.every: a string \"3\"; allowed: an integer");
  expect_refused([](json& d) { d["rows"][0]["verdict"] = "maybe"; },
                 "rows[0].verdict: 'maybe'; allowed: pass, fail, expected, n/a");
  expect_refused([](json& d) { d["rows"][0]["name"] = "no-such-row"; }, "rows[0].name: 'no-such-row'; allowed: ");
  expect_refused([](json& d) { d["rows"][1]["causes"][0]["name"] = "penetration"; },
                 "rows[1].causes[0].name: 'penetration'; allowed: missing-contact, false-contact");
}

TEST(MergeShards, OutOfRangeIntegersAreRefusedNotWrapped) {
  // Before: get<int>() wrapped 2^32 + 2 to 2, 2^40 frames overflowed k * F.
  expect_refused([](json& d) { d["shard"]["count"] = 4294967298ULL; },
                 "shard.count: 4294967298 is out of range; allowed: an integer in [1, 100000]");
  expect_refused([](json& d) { d["shard"]["index"] = -1; }, "shard.index: -1 is out of range");
  expect_refused([](json& d) { d["shard"]["frames"] = 1099511627776LL; }, "shard.frames: 1099511627776 is out of range");
  expect_refused([](json& d) { d["shard"]["every"] = 4294967299ULL; }, "shard.every: 4294967299 is out of range");
  expect_refused([](json& d) { d["rows"][0]["judged"] = 18446744073709551615ULL; },
                 "rows[0].judged: 18446744073709551615 is out of range");
  expect_refused([](json& d) { d["rows"][0]["causes"][0]["examples"][0]["frame"] = 4611686018427387904LL; },
                 "examples[0].frame: 4611686018427387904 is out of range");
  expect_refused([](json& d) { d["rows"][0]["measured"] = 1e300; }, "rows[0].measured: 1e+300 is out of range");
  expect_refused([](json& d) { d["shard"]["tolerances"]["penetration_slops"] = -1; },
                 "shard.tolerances.penetration_slops: -1 is out of range");
  // More examples or items than a shard keeps: bounded memory.
  expect_refused(
      [](json& d) {
        for (int k = 0; k < 10; ++k) d["rows"][0]["causes"][0]["examples"].push_back(d["rows"][0]["causes"][0]["examples"][0]);
      },
      "rows[0].causes[0].examples: an array of 11 elements; allowed: at most 5 elements");
}

TEST(MergeShards, IdentitiesAndRowsMustBeTheSame) {
  expect_refused([](json& d) { d["rows"][0]["bound"] = 0.9; }, "its rows differ from s0.json's");
  expect_refused([](json& d) { d["rows"][1] = d["rows"][0]; }, "rows[1].name: 'penetration' is also rows[0]");
  std::vector<json> docs = two_shards();
  docs[1]["shard"]["trace_bytes"] = 1;
  EXPECT_NE(merge_error(docs).find("s1.json: not a shard of the same run: trace_bytes 1 differs from s0.json's 12345"),
            std::string::npos)
      << merge_error(docs);
}

TEST(MergeShards, AKeyTwiceInAShardFileIsRefused) {
  // Before: nlohmann's parse let the last "measured" win.
  const std::filesystem::path dir =
      std::filesystem::temp_directory_path() / ("octocd-merge-" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  std::vector<std::string> files;
  for (int i = 0; i < 2; ++i) {
    std::string text = shard_doc(i, 2).dump();
    if (i == 1) text.replace(text.find("\"measured\":"), 11, "\"measured\":1,\"measured\":");
    files.push_back((dir / ("s" + std::to_string(i) + ".json")).string());
    std::ofstream(files.back()) << text;
  }
  std::string e;
  try {
    (void)merge_validations(files);
  } catch (const InputError& x) {
    e = x.what();
  }
  EXPECT_NE(e.find("s1.json: rows.measured: duplicate key"), std::string::npos) << e;
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace octocd_test_shards
}  // namespace octocd
