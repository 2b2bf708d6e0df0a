/// \file junit.cpp
/// JUnit XML reports of `octocd validate --junit` (issue 9 item 4): CI servers (Jenkins,
/// GitLab, GitHub actions' test reporters) read them as one test case per validator.

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <sstream>

#include <fmt/format.h>

#include "octocd/junit.hpp"

#include "octocd/atomic_file.hpp"
#include "octocd/error.hpp"
#include "octocd/expect.hpp"
#include "octocd/validation.hpp"
#include "octocd/xml.hpp"

namespace octocd {
namespace {

/// "%.9g" of a figure (JUnit text, not for machines).
std::string junit_figure(double v) { return fmt::format("{:.9g}", v); }

// Atomically: a failed write (a full disk, a file size limit) leaves the previous report,
// if any, intact and no 0-byte or half file.
void write_file(const std::string& path, const std::string& text) { write_file_atomically(path, text, "--junit"); }

}  // namespace

void write_junit(const std::string& path, const std::string& suite,
                 const std::vector<ValidationResult>& results, double seconds,
                 const std::vector<std::pair<std::string, std::string>>& properties, const std::string& stopped,
                 const ExpectationReport* report) {
  int failures = 0, skipped = 0;
  for (const ValidationResult& r : results) {
    const std::string verdict = row_verdict(r, report);
    if (verdict == "n/a" || verdict == "expected") ++skipped;
    else if (verdict == "fail") ++failures;
  }
  // The outcomes of a row's causes, one line each (plain text; escaped below).
  auto outcome_lines = [&](const ValidationResult& r) {
    std::string lines;
    if (report)
      for (const ExpectationOutcome& o : report->outcomes)
        if (o.row == r.name && o.kind != ExpectationOutcome::Kind::Fixed) lines += "\n" + o.text;
    return lines;
  };
  const std::size_t tests = results.size() + (stopped.empty() ? 0 : 1);
  const int errors = stopped.empty() ? 0 : 1;
  const std::string s = xml_escape(suite);
  std::ostringstream o;
  o << "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n"
    << "<testsuites name=\"octocd validate\" tests=\"" << tests << "\" failures=\"" << failures
    << "\" errors=\"" << errors << "\" skipped=\"" << skipped << "\" time=\"" << fmt::format("{:.3f}", seconds)
    << "\">\n"
    << "  <testsuite name=\"" << s << "\" tests=\"" << tests << "\" failures=\"" << failures << "\" errors=\""
    << errors << "\" skipped=\"" << skipped << "\" time=\"" << fmt::format("{:.3f}", seconds) << "\">\n";
  if (!properties.empty()) {
    o << "    <properties>\n";
    for (const auto& [k, v] : properties)
      o << "      <property name=\"" << xml_escape(k) << "\" value=\"" << xml_escape(v) << "\"/>\n";
    o << "    </properties>\n";
  }
  for (const ValidationResult& r : results) {
    const std::string figures =
        fmt::format("{}: measured {}, bound {}", r.figure, junit_figure(r.measured), junit_figure(r.bound));
    // Each row's own time (ValidationResult::seconds), so the slow validator shows.
    o << "    <testcase classname=\"" << s << "." << tier_name(r.tier) << "\" name=\"" << xml_escape(r.name)
      << "\" time=\"" << fmt::format("{:.6f}", std::max(r.seconds, 0.0)) << "\"";
    if (!r.applicable) {
      o << ">\n      <skipped message=\"" << xml_escape("n/a: " + r.detail) << "\"/>\n    </testcase>\n";
    } else if (row_verdict(r, report) == "expected") {
      // Every failing cause within its expectation (design.md section 14b): skipped, with its figures.
      std::string message = "expected:";
      for (const ExpectationOutcome& x : report->outcomes)
        if (x.row == r.name && x.kind == ExpectationOutcome::Kind::Expected)
          message += fmt::format(" {} worst {} <= allowed {} ({} item(s)): {};", x.cause, junit_figure(x.worst),
                                 junit_figure(x.allowed), x.count, x.reason);
      message.pop_back();
      o << ">\n      <skipped message=\"" << xml_escape(message) << "\"/>\n      <system-out>"
        << xml_escape(figures + "\n" + r.detail) << "</system-out>\n    </testcase>\n";
    } else if (!r.pass) {
      // The measured value against the bound first: what a CI page shows in one line.
      const std::string message = fmt::format("measured {} {} bound {} ({}): {}", junit_figure(r.measured),
                                              r.measured > r.bound ? ">" : r.measured < r.bound ? "<" : "vs",
                                              junit_figure(r.bound), r.figure, r.detail);
      o << ">\n      <failure message=\"" << xml_escape(message) << "\" type=\"ValidatorFailure\">"
        << xml_escape(message + outcome_lines(r)) << "</failure>\n    </testcase>\n";
    } else {
      o << ">\n      <system-out>" << xml_escape(figures + "\n" + r.detail) << "</system-out>\n    </testcase>\n";
    }
  }
  if (!stopped.empty()) {
    // A run stopped by a signal: the rows above cover the frames judged so far.
    o << "    <testcase classname=\"" << s << "\" name=\"stopped\" time=\"0\">\n      <error message=\""
      << xml_escape(stopped) << "\" type=\"stopped\">" << xml_escape(stopped) << "</error>\n    </testcase>\n";
  }
  o << "  </testsuite>\n</testsuites>\n";
  write_file(path, o.str());
}

void write_junit_error(const std::string& path, const std::string& suite, const std::string& name,
                       const std::string& message) {
  const std::string s = xml_escape(suite);
  std::ostringstream o;
  o << "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n"
    << "<testsuites name=\"octocd validate\" tests=\"1\" failures=\"0\" errors=\"1\" skipped=\"0\">\n"
    << "  <testsuite name=\"" << s << "\" tests=\"1\" failures=\"0\" errors=\"1\" skipped=\"0\">\n"
    << "    <testcase classname=\"" << s << "\" name=\"" << xml_escape(name) << "\" time=\"0\">\n"
    << "      <error message=\"" << xml_escape(message) << "\" type=\"" << xml_escape(name) << "\">"
    << xml_escape(message) << "</error>\n"
    << "    </testcase>\n  </testsuite>\n</testsuites>\n";
  write_file(path, o.str());
}

}  // namespace octocd
