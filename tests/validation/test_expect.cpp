// Expectations (design.md section 14b) and the causes of a row (design.md section 13b.13): octocd/expect.hpp.
// Results are built by hand, so each outcome (expected, new, grown, fixed, strict) is
// planted exactly; the CLI's use of them is tested in tests/cli/test_cli_usage.cpp
// (CliUser.ValidateExpectationsGateOnNewAndGrownFailures).

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <limits>
#include <string>

#include <unistd.h>

#include "octocd/error.hpp"
#include "octocd/expect.hpp"
#include "octocd/results_table.hpp"
#include "octocd/validation_rows.hpp"

namespace octocd {
namespace octocd_test_expect {
namespace {

using Kind = ExpectationOutcome::Kind;

/// A physics row `conservation` failing on energy with figure `worst` on `items`.
ValidationResult energy_row(double worst, std::vector<std::string> items) {
  ValidationResult r;
  r.tier = Tier::Physics;
  r.name = "conservation";
  r.figure = "isolated groups breaking momentum, angular momentum or energy";
  r.measured = static_cast<double>(items.size());
  r.bound = 0;
  r.pass = false;
  r.judged = 40;
  r.detail = "frame 12: group (1, 2, 3): KE rose";
  ValidationCause c;
  c.name = "energy";
  c.unit = "rel";
  c.count = items.size();
  c.worst = worst;
  for (const std::string& item : items) c.examples.push_back({12, item, worst, "KE rose by " + std::to_string(worst)});
  c.items = items;
  r.causes.push_back(c);
  return r;
}

/// A model row without causes, failing `n` items (bound 0, measured = count).
ValidationResult model_row(const std::string& name, double measured) {
  ValidationResult r;
  r.tier = Tier::Model;
  r.name = name;
  r.figure = "contacts violating Eq. 14 contraction";
  r.measured = measured;
  r.bound = 0;
  r.pass = measured == 0;
  r.judged = 100;
  r.detail = "frame 3: pair (0, 1)";
  return r;
}

Expectations parse(const std::string& text) { return parse_expectations_text(text, "e.json"); }

std::string error_of(const std::string& text) {
  try {
    parse(text);
  } catch (const InputError& e) {
    return e.what();
  }
  return "";
}

TEST(Expect, TheRowTableIsInRowIdOrderWithUniqueNamesAndCauses) {
  const std::vector<RowInfo>& rows = validation_rows();
  ASSERT_EQ(rows.size(), static_cast<std::size_t>(RowId::BulletDynamics) + 1);
  std::vector<std::string> names;
  for (std::size_t k = 0; k < rows.size(); ++k) {
    const RowInfo& row = rows[k];
    EXPECT_EQ(static_cast<std::size_t>(row.id), k) << row.name;
    EXPECT_EQ(&row_info(row.id), &row);
    EXPECT_EQ(find_row_info(row.name), &row);
    // The physics tier first, then the model tier (the order of `validate`'s table).
    if (k > 0 && rows[k - 1].tier == Tier::Model) {
      EXPECT_EQ(row.tier, Tier::Model) << row.name;
    }
    for (const std::string& n : names) EXPECT_NE(n, row.name);
    names.push_back(row.name);
    std::vector<std::string> causes;
    for (const RowCause& c : row.causes) {
      for (const std::string& other : causes) EXPECT_NE(other, c.name) << row.name;
      causes.push_back(c.name);
      EXPECT_STRNE(c.unit, "") << row.name << "/" << c.name;
    }
    EXPECT_EQ(documented_causes(row.name), causes);
  }
  EXPECT_EQ(validation_row_names(), names);
  EXPECT_EQ(rows.front().tier, Tier::Physics);
  EXPECT_EQ(find_row_info("no-such-row"), nullptr);
  EXPECT_TRUE(documented_causes("no-such-row").empty());
  // The rows whose figure is the largest judged merge by the maximum, the counts by the sum.
  EXPECT_EQ(row_info(RowId::Penetration).merge, RowMerge::Max);
  EXPECT_EQ(row_info(RowId::Friction).merge, RowMerge::Sum);
}

TEST(Expect, FailureCausesGiveAModelRowOneCauseNamedLikeIt) {
  const std::vector<ValidationCause> c = failure_causes(model_row("non-penetration-eq14", 7));
  ASSERT_EQ(c.size(), 1u);
  EXPECT_EQ(c[0].name, "non-penetration-eq14");
  EXPECT_EQ(c[0].count, 7u);  // bound 0 and a whole measured figure: it counts failures
  EXPECT_EQ(c[0].worst, 7);
  ValidationResult ratio = model_row("bullet-dynamics", 0.25);
  ratio.bound = 0.1;
  EXPECT_EQ(failure_causes(ratio).at(0).count, 1u);  // a figure, not a count
  EXPECT_TRUE(failure_causes(model_row("analytic", 0)).empty());  // passed
  ValidationResult na = model_row("analytic", 3);
  na.applicable = false;
  EXPECT_TRUE(failure_causes(na).empty());
  // A row with its own causes keeps them (and drops causes with no failure).
  ValidationResult split = energy_row(0.006, {"group (1, 2, 3)"});
  split.causes.push_back(ValidationCause{"momentum", "kg m/s", 0, 0, {}, {}, true});
  ASSERT_EQ(failure_causes(split).size(), 1u);
  EXPECT_EQ(failure_causes(split)[0].name, "energy");
}

TEST(Expect, ParsesEntriesAndRefusesBadOnesNamingTheEntry) {
  const Expectations e = parse(R"J({"expectations": [
      {"scene": "bunny-stack-50", "row": "conservation", "cause": "energy", "worst": 0.01, "reason": "Jacobi"},
      {"trace": "run.h5", "row": "non-penetration-eq14", "cause": "non-penetration-eq14",
       "items": ["pair (3, 4)", "pair (1, 2)"], "worst": 5, "reason": "r"}]})J");
  ASSERT_EQ(e.entries.size(), 2u);
  EXPECT_EQ(e.entries[0].scene, "bunny-stack-50");
  EXPECT_FALSE(e.entries[0].has_items);
  EXPECT_EQ(e.entries[1].trace, "run.h5");
  EXPECT_EQ(e.entries[1].items, (std::vector<std::string>{"pair (1, 2)", "pair (3, 4)"}));  // sorted
  EXPECT_NE(error_of("{\"expectations\": [").find("e.json: not JSON"), std::string::npos);
  EXPECT_NE(error_of(R"J({"expectations": [{"scene": "s", "row": "nope", "cause": "x", "worst": 1, "reason": "r"}]})J")
                .find("e.json: expectations[0] (row): unknown row 'nope'; allowed: broadphase-completeness"),
            std::string::npos);
  EXPECT_NE(error_of(R"J({"expectations": [{"scene": "s", "row": "friction", "cause": "x", "worst": 1, "reason": "r"}]})J")
                .find("(cause): unknown cause 'x' of row friction; allowed: cone, dissipation, friction"),
            std::string::npos);
  EXPECT_NE(
      error_of(R"J({"expectations": [{"scene": "s", "row": "friction", "cause": "cone", "worst": -1, "reason": "r"}]})J")
          .find("(worst): -1 is out of range; allowed: a finite number >= 0"),
      std::string::npos);
  EXPECT_NE(error_of(R"J({"expectations": [{"row": "friction", "cause": "cone", "worst": 1, "reason": "r"}]})J")
                .find("(scene/trace)"),
            std::string::npos);
  EXPECT_NE(error_of(R"J({"expectations": [{"scene": "s", "row": "friction", "cause": "cone", "worst": 1}]})J")
                .find("(reason): missing"),
            std::string::npos);
  const std::string twice = R"J({"scene": "s", "row": "friction", "cause": "cone", "worst": 1, "reason": "r"})J";
  EXPECT_NE(error_of("{\"expectations\": [" + twice + ", " + twice + "]}").find("expectations[1] (entry): a second"),
            std::string::npos);
}

TEST(Expect, ExpectedWithinItsFigureGrownBeyondItNewWithoutOne) {
  const Expectations e = parse(R"J({"expectations": [
      {"scene": "s", "row": "conservation", "cause": "energy", "worst": 0.01, "reason": "Jacobi passes"}]})J");
  const RunName run{"s", ""};
  ExpectationReport ok = match_expectations(e, run, {energy_row(0.006, {"group (1, 2, 3)"})});
  ASSERT_EQ(ok.outcomes.size(), 1u);
  EXPECT_EQ(ok.outcomes[0].kind, Kind::Expected);
  EXPECT_EQ(ok.exit_code(true), 0);
  EXPECT_TRUE(ok.row_expected("conservation"));
  EXPECT_EQ(row_verdict(energy_row(0.006, {"g"}), &ok), "expected");
  EXPECT_NE(ok.outcomes[0].text.find("Jacobi passes"), std::string::npos);

  ExpectationReport grown = match_expectations(e, run, {energy_row(0.02, {"group (1, 2, 3)"})});
  EXPECT_EQ(grown.outcomes.at(0).kind, Kind::Grown);
  EXPECT_EQ(grown.exit_code(false), 3);
  EXPECT_NE(grown.outcomes[0].text.find("GROWN conservation/energy: worst 0.02 > allowed 0.01"), std::string::npos);
  // NaN is never within a figure.
  EXPECT_EQ(match_expectations(e, run, {energy_row(std::nan(""), {"g"})}).outcomes.at(0).kind, Kind::Grown);

  // Another run's entry does not apply: the same failure there is new.
  ExpectationReport other = match_expectations(e, RunName{"t", ""}, {energy_row(0.006, {"g"})});
  EXPECT_EQ(other.outcomes.at(0).kind, Kind::New);
  EXPECT_EQ(other.exit_code(false), 3);
  EXPECT_EQ(row_verdict(energy_row(0.006, {"g"}), &other), "fail");
  // A second failing row next to an expected one is new.
  ExpectationReport both = match_expectations(e, run, {energy_row(0.006, {"g"}), model_row("applied-state", 2)});
  EXPECT_EQ(both.count(Kind::Expected), 1u);
  EXPECT_EQ(both.count(Kind::New), 1u);
  EXPECT_NE(both.outcomes[1].text.find("NEW FAILURE applied-state/applied-state: measured 2 > bound 0"),
            std::string::npos);
  // Without expectations every failure is new.
  EXPECT_EQ(match_expectations(Expectations{}, run, {energy_row(0.006, {"g"})}).exit_code(false), 3);
  // One cause of several gives its own figure and unit (the row's may be within its bound).
  ValidationResult moving;
  moving.name = "bullet-dynamics";
  moving.figure = "settled centre-of-mass height difference / mean body height";
  moving.measured = 0.0624;
  moving.bound = 0.1;
  moving.pass = false;
  ValidationCause still;
  still.name = "still-moving";
  still.unit = "m/s";
  still.count = 1;
  still.worst = 0.199;
  still.examples.push_back({3000, "", 0.199, "octocd's bodies still move"});
  moving.causes.push_back(still);
  const ExpectationReport m = match_expectations(Expectations{}, run, {moving});
  ASSERT_EQ(m.outcomes.size(), 1u);
  EXPECT_NE(m.outcomes[0].text.find("NEW FAILURE bullet-dynamics/still-moving: worst 0.199 m/s (1 item(s); the row's "
                                    "settled centre-of-mass height difference / mean body height: 0.0624 of bound 0.1)"),
            std::string::npos)
      << m.outcomes[0].text;
}

TEST(Expect, ItemsOutsideTheListedOnesGrow) {
  const Expectations e = parse(R"J({"expectations": [{"scene": "s", "row": "conservation", "cause": "energy",
      "items": ["group (1, 2, 3)"], "worst": 0.01, "reason": "r"}]})J");
  const RunName run{"s", ""};
  EXPECT_EQ(match_expectations(e, run, {energy_row(0.006, {"group (1, 2, 3)"})}).outcomes.at(0).kind, Kind::Expected);
  const ExpectationReport r = match_expectations(e, run, {energy_row(0.006, {"group (1, 2, 3)", "group (7, 8)"})});
  EXPECT_EQ(r.outcomes.at(0).kind, Kind::Grown);
  EXPECT_EQ(r.outcomes[0].outside, (std::vector<std::string>{"group (7, 8)"}));
  ValidationResult truncated = energy_row(0.006, {"group (1, 2, 3)"});
  truncated.causes[0].items_complete = false;  // more failed than were recorded: unknown items
  EXPECT_EQ(match_expectations(e, run, {truncated}).outcomes.at(0).kind, Kind::Grown);
}

TEST(Expect, AFixedExpectationIsReportedAndFailsOnlyWhenStrict) {
  Expectations e = parse(R"J({"expectations": [
      {"scene": "s", "row": "conservation", "cause": "energy", "worst": 0.01, "reason": "r"}]})J");
  e.path = "nightly.json";
  ValidationResult passed = energy_row(0, {});
  passed.pass = true;
  passed.causes.clear();
  const ExpectationReport r = match_expectations(e, RunName{"s", ""}, {passed});
  ASSERT_EQ(r.outcomes.size(), 1u);
  EXPECT_EQ(r.outcomes[0].kind, Kind::Fixed);
  EXPECT_NE(r.outcomes[0].text.find("fixed conservation/energy: no longer fails: remove it from nightly.json"),
            std::string::npos);
  EXPECT_EQ(r.exit_code(false), 0);
  EXPECT_EQ(r.exit_code(true), 3);
}

TEST(Expect, WrittenExpectationsAcceptTheRunTheyWereWrittenFrom) {
  const RunName run{"", "run.h5"};
  const std::vector<ValidationResult> results = {energy_row(0.0061234, {"group (1, 2, 3)"}),
                                                 model_row("non-penetration-eq14", 4), model_row("analytic", 0)};
  const std::vector<Expectation> written = expectations_from(run, results);
  ASSERT_EQ(written.size(), 2u);
  EXPECT_EQ(written[0].trace, "run.h5");
  // 0.0061234 / (1 - 0.1) = 0.0068038, rounded up to 3 digits: the measured figure is <= 90% of it.
  EXPECT_DOUBLE_EQ(written[0].worst, 0.00681);
  EXPECT_LE(0.0061234, (1.0 - kExpectHeadroom) * written[0].worst);
  EXPECT_EQ(written[1].worst, 4.0);  // a count: exact
  EXPECT_EQ(written[0].items, (std::vector<std::string>{"group (1, 2, 3)"}));
  EXPECT_EQ(written[1].cause, "non-penetration-eq14");
  // Through the file format and back: every failure expected.
  const Expectations back = parse_expectations_text(expectations_json(written).dump(), "written");
  EXPECT_EQ(match_expectations(back, run, results).exit_code(true), 0);

  // write_expectations replaces this run's entries and keeps the others.
  const std::string path =
      (std::filesystem::temp_directory_path() / ("octocd-test-expect-" + std::to_string(::getpid()) + ".json")).string();
  write_expectations(path, RunName{"other", ""}, expectations_from(RunName{"other", ""}, results));
  write_expectations(path, run, written);
  write_expectations(path, run, written);
  const Expectations file = load_expectations(path);
  std::remove(path.c_str());
  EXPECT_EQ(file.entries.size(), 4u);
}

TEST(Expect, JsonHasEveryRowWithItsVerdictCausesAndExamples) {
  const Expectations e = parse(R"J({"expectations": [
      {"scene": "s", "row": "conservation", "cause": "energy", "worst": 0.01, "reason": "r"}]})J");
  ValidationResult na = model_row("analytic", 0);
  na.applicable = false;
  const std::vector<ValidationResult> results = {energy_row(0.006, {"group (1, 2, 3)"}),
                                                 model_row("applied-state", 2), na, model_row("candidate-sets", 0)};
  const ExpectationReport report = match_expectations(e, RunName{"s", ""}, results);
  const nlohmann::ordered_json j = results_json(results, RunName{"s", ""}, &report, {{"engine", "cpu"}});
  EXPECT_EQ(j["scene"], "s");
  EXPECT_EQ(j["engine"], "cpu");
  ASSERT_EQ(j["rows"].size(), 4u);
  EXPECT_EQ(j["rows"][0]["verdict"], "expected");
  EXPECT_EQ(j["rows"][0]["causes"][0]["examples"][0]["item"], "group (1, 2, 3)");
  EXPECT_EQ(j["rows"][0]["causes"][0]["examples"][0]["frame"], 12);
  EXPECT_EQ(j["rows"][0]["judged"], 40);
  EXPECT_EQ(j["rows"][1]["verdict"], "fail");
  EXPECT_EQ(j["rows"][1]["causes"][0]["name"], "applied-state");
  EXPECT_EQ(j["rows"][2]["verdict"], "n/a");
  EXPECT_EQ(j["rows"][3]["verdict"], "pass");
  EXPECT_EQ(j["expectations"]["outcomes"].size(), 2u);
  ValidationResult inf = model_row("bullet-dynamics", std::numeric_limits<double>::infinity());
  EXPECT_TRUE(results_json({inf}, RunName{"s", ""})["rows"][0]["measured"].is_null());
}

TEST(Expect, TableShowsCausesExamplesAndExpectedRows) {
  const Expectations e = parse(R"J({"expectations": [
      {"scene": "s", "row": "conservation", "cause": "energy", "worst": 0.01, "reason": "r"}]})J");
  const std::vector<ValidationResult> results = {energy_row(0.006, {"group (1, 2, 3)"}), model_row("applied-state", 2)};
  const ExpectationReport report = match_expectations(e, RunName{"s", ""}, results);
  const std::string table = format_results(results, {}, &report);
  EXPECT_NE(table.find("expected"), std::string::npos);
  EXPECT_NE(table.find("cause energy: 1 item(s), worst 0.006 rel"), std::string::npos);
  EXPECT_NE(table.find("frame 12 group (1, 2, 3): KE rose"), std::string::npos);
  EXPECT_NE(table.find("FAIL"), std::string::npos);
}

}  // namespace
}  // namespace octocd_test_expect
}  // namespace octocd
