#pragma once
/// \file results_table.hpp
/// The results' table that `octocd validate` prints (docs/validation-output.md).

#include <string>
#include <utility>
#include <vector>

#include "octocd/validation.hpp"

namespace octocd {

struct ExpectationReport;  // octocd/expect.hpp

/// Prints results as a table (name, figure, measured, bound, verdict, detail); a bound
/// that depends on an overridden tolerance is marked with '*'. Under a failing row, its
/// causes (failure_causes, octocd/expect.hpp) with their counts and worst figures and the
/// first examples (at most 3 per cause); a row that judged nothing reads `n/a`. With
/// `report` (may be null), a row whose every failing cause is expected reads `expected`.
std::string format_results(const std::vector<ValidationResult>& results,
                           const std::vector<std::string>& overridden = {},
                           const ExpectationReport* report = nullptr);

}  // namespace octocd
