#pragma once
/// \file junit.hpp
/// The JUnit XML report of `octocd validate --junit` (docs/validation-output.md).

#include <string>
#include <utility>
#include <vector>

#include "octocd/validation.hpp"

namespace octocd {

struct ExpectationReport;  // octocd/expect.hpp

/// Writes a JUnit XML report to `path` (`octocd validate --junit`): one <testsuite> named
/// `suite` (the scene's name) inside <testsuites>, one <testcase> per result; a failed result carries
/// <failure message="detail"> (text: figure, measured, bound, detail), an n/a result
/// <skipped>, a pass its figures in <system-out>. A testcase's classname is "SUITE.TIER"
/// (e.g. "box-stack.physics": CI servers show scene, tier and validator), its name the
/// validator, its time the result's `seconds`; a failure's message starts with
/// "measured X > bound Y". `seconds` is the suite's time; `properties` (engine,
/// frames, ...) go to <properties>. `stopped` non-empty (a run stopped by a signal): one
/// more testcase "stopped" with <error message="stopped">, so a CI server never reads a
/// stopped run as passed. With `report` (octocd/expect.hpp; may be null) a row whose every
/// failing cause is expected is <skipped message="expected: ..."> (one line per cause, its
/// figure, allowance and reason), and a failing row's message names its new or grown
/// causes. Text is XML-escaped. Throws RuntimeError naming the path when it cannot be
/// written.
void write_junit(const std::string& path, const std::string& suite,
                 const std::vector<ValidationResult>& results, double seconds,
                 const std::vector<std::pair<std::string, std::string>>& properties = {},
                 const std::string& stopped = "", const ExpectationReport* report = nullptr);

/// Writes a JUnit XML report with one errored test case (classname `suite`, name `name`,
/// e.g. "bad-input" or "runtime-failure", <error message="message">): what `validate
/// --junit` leaves when the scene cannot be loaded or the run stops, so a CI server sees
/// the scene as broken rather than missing. Throws RuntimeError naming the path.
void write_junit_error(const std::string& path, const std::string& suite, const std::string& name,
                       const std::string& message);

}  // namespace octocd
