// The results' table of `octocd validate` (octocd/results_table.hpp).
#include "octocd/results_table.hpp"

#include <algorithm>

#include <fmt/format.h>

#include "octocd/expect.hpp"

namespace octocd {

std::string format_results(const std::vector<ValidationResult>& results,
                           const std::vector<std::string>& overridden, const ExpectationReport* report) {
  auto marked = [&](const ValidationResult& r) {
    for (const std::string& o : overridden)
      if (("," + r.tolerances + ",").find("," + o + ",") != std::string::npos) return true;
    return false;
  };
  std::string out = fmt::format("{:<8} {:<24} {:>12} {:>10}  {:<8}  {}\n", "tier", "validator", "measured",
                                "bound", "", "figure / detail");
  for (const ValidationResult& r : results) {
    std::string verdict = row_verdict(r, report);
    if (verdict == "fail") verdict = "FAIL";
    out += fmt::format("{:<8} {:<24} {:>12.6g} {:>10} {:<8}  {}\n", tier_name(r.tier), r.name, r.measured,
                       fmt::format("{:.4g}{}", r.bound, marked(r) ? "*" : " "), verdict, r.figure);
    out += fmt::format("{:<8} {:<24} {:>12} {:>10}  {:<8}  {}\n", "", "", "", "", "", r.detail);
    // Each failing cause: its count and worst figure, then its first examples (design.md section 13b.13).
    const std::vector<ValidationCause> causes = failure_causes(r);
    const bool own = causes.size() == 1 && causes.front().name == r.name && r.causes.empty();
    if (own) continue;  // the row's detail line is its only example
    for (const ValidationCause& c : causes) {
      out += fmt::format("{:<58}  cause {}: {} item(s), worst {:.6g}{}{}\n", "", c.name, c.count, c.worst,
                         c.unit.empty() ? "" : " ", c.unit);
      constexpr std::size_t kShown = 3;
      for (std::size_t i = 0; i < c.examples.size() && i < kShown; ++i) {
        const ValidationExample& x = c.examples[i];
        out += fmt::format("{:<58}    {}{}{}\n", "", x.frame >= 0 ? fmt::format("frame {} ", x.frame) : "",
                           x.item.empty() ? "" : x.item + ": ", x.text);
      }
      if (c.count > std::min(c.examples.size(), kShown))
        out += fmt::format("{:<58}    ... {} more\n", "", c.count - std::min(c.examples.size(), kShown));
    }
  }
  if (!overridden.empty()) out += "* bound set with --tolerance\n";
  return out;
}

}  // namespace octocd
