// libFuzzer target: the expectations reader of `validate --expect` and `--write-expect`
// (harness/src/expect.cpp; issue 57 item 6). The input is the text of an
// expectations file: parse_expectations_text (strict JSON, every entry's keys, types,
// rows, causes and figures checked). A file it accepts is matched against a fixed verdict
// (a failing conservation row with causes and items, a failing model row) and written back
// as --write-expect writes it (expectations_json), which must read back to the same
// entries. Bad input must end in InputError; anything else (a crash, a sanitizer report,
// another exception, a round trip that changes an entry) is a finding.
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "octocd/error.hpp"
#include "octocd/expect.hpp"

namespace {

/// The verdict expectations are matched against: scene "box-stack", trace "t.h5".
std::vector<octocd::ValidationResult> verdict() {
  octocd::ValidationResult r;
  r.tier = octocd::Tier::Physics;
  r.name = "conservation";
  r.figure = "isolated groups breaking momentum, angular momentum or energy";
  r.measured = 2;
  r.bound = 0;
  r.pass = false;
  r.judged = 40;
  r.detail = "frame 12: group (1, 2, 3): KE rose";
  octocd::ValidationCause c;
  c.name = "energy";
  c.unit = "rel";
  c.count = 2;
  c.worst = 0.25;
  c.examples.push_back({12, "group (1, 2, 3)", 0.25, "KE rose"});
  c.items = {"group (1, 2, 3)", "group (4, 5)"};
  r.causes.push_back(c);
  octocd::ValidationResult m;
  m.tier = octocd::Tier::Model;
  m.name = "non-penetration-eq14";
  m.figure = "contacts violating Eq. 14 contraction";
  m.measured = 3;
  m.bound = 0;
  m.pass = false;
  m.judged = 100;
  m.detail = "frame 3: pair (0, 1)";
  return {r, m};
}

[[noreturn]] void finding(const std::string& what) {
  std::fprintf(stderr, "fuzz_expect: %s\n", what.c_str());
  std::abort();
}

bool same(const octocd::Expectation& a, const octocd::Expectation& b) {
  return a.scene == b.scene && a.trace == b.trace && a.row == b.row && a.cause == b.cause &&
         a.has_items == b.has_items && a.items == b.items && a.worst == b.worst && a.reason == b.reason;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  octocd::Expectations e;
  try {
    e = octocd::parse_expectations_text(text, "fuzz-expect.json");
  } catch (const octocd::InputError&) {
    return 0;
  }
  std::printf("  %zu expectation(s)\n", e.entries.size());
  static const std::vector<octocd::ValidationResult> results = verdict();
  for (const octocd::RunName& run : {octocd::RunName{"box-stack", ""}, octocd::RunName{"", "t.h5"}}) {
    const octocd::ExpectationReport report = octocd::match_expectations(e, run, results);
    (void)report.exit_code(true);
    (void)octocd::results_json(results, run, &report, {})
        .dump(-1, ' ', false, nlohmann::ordered_json::error_handler_t::replace);
  }
  // Written back (as --write-expect writes it) and read again: the same entries.
  const std::string back =
      octocd::expectations_json(e.entries).dump(2, ' ', false, nlohmann::ordered_json::error_handler_t::replace);
  octocd::Expectations again;
  try {
    again = octocd::parse_expectations_text(back, "written");
  } catch (const octocd::InputError& x) {
    finding(std::string("its own output refused: ") + x.what());
  }
  if (again.entries.size() != e.entries.size()) finding("a round trip changed the number of entries");
  for (std::size_t i = 0; i < e.entries.size(); ++i)
    if (!same(e.entries[i], again.entries[i])) finding("a round trip changed entry " + std::to_string(i));
  return 0;
}
