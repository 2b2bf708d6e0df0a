#pragma once
// Issue 8's targets and the GPU broadphase bench's Markdown and JSON output (bench_gpu_report.cpp).
#include "bench_gpu_common.hpp"

namespace gpu_bench {

/// Issue 8's targets, each met, missed or not measured by the results `rs`.
std::vector<Target> evaluate_targets(const std::vector<Result>& rs, const Options& o);

/// The Markdown report: the machine, the table of every result, the targets, the oracle notes.
void print_markdown(std::ostream& os, const Machine& m, const Options& o, const std::vector<Result>& rs,
                    const std::vector<Target>& ts, const std::vector<std::string>& oracle_notes, bool all_ok);

/// Everything print_markdown reports, as JSON.
Json to_json(const Machine& m, const Options& o, const std::vector<Result>& rs, const std::vector<Target>& ts,
             const std::vector<std::string>& oracle_notes, bool all_ok);

}  // namespace gpu_bench
