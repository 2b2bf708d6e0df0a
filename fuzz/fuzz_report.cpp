// libFuzzer target: the report's trace input (issue 36). `octocd report` reads a trace only
// through `octocd trace-summary --json` (cli/report.cpp, trace_summary_command), whose JSON
// make_report.py parses with json.loads. The input is written as a file and given to
// trace_summary_command exactly as the report's child runs it; its stdout is captured.
// Findings: a crash, a hang, an exception other than InputError / RuntimeError, or output
// that make_report.py could not take: anything but one strict JSON object (no NaN or
// Infinity, valid UTF-8) with "format" "octocd-trace", "version" 1 or 2, "frames" >= 0,
// "attributes" an object of strings, numbers or null, and "columns" an object of arrays of
// exactly "frames" numbers or nulls (the report plots them against the frame number).
#include <fcntl.h>
#include <sys/mman.h>
#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string>

#include <nlohmann/json.hpp>

#include "../cli/tools.hpp"
#include "fuzz_common.hpp"
#include "octocd/error.hpp"

namespace {

[[noreturn]] void finding(const char* what, const std::string& out) {
  std::fprintf(stderr, "fuzz_report: %s: %.400s\n", what, out.c_str());
  std::abort();
}

/// Runs trace_summary_command({path, json}) with stdout in a memory file; returns what it
/// printed, or "" when it threw InputError or RuntimeError (exit 2 or 1: the report says so).
std::string summary_json(const std::string& path) {
  std::fflush(stdout);
  const int saved = dup(1);
  const int mem = memfd_create("octocd-fuzz-report", MFD_CLOEXEC);
  if (saved < 0 || mem < 0) std::abort();
  dup2(mem, 1);
  bool ok = true;
  try {
    octocd::cli::TraceSummaryOptions o;
    o.trace = path;
    o.json = true;
    (void)octocd::cli::trace_summary_command(o);
  } catch (const octocd::InputError&) {
    ok = false;
  } catch (const octocd::RuntimeError&) {
    ok = false;
  }
  std::fflush(stdout);
  dup2(saved, 1);
  close(saved);
  std::string out;
  if (ok) {
    const off_t n = lseek(mem, 0, SEEK_END);
    out.resize(static_cast<std::size_t>(n > 0 ? n : 0));
    if (n > 0 && pread(mem, out.data(), out.size(), 0) != n) std::abort();
  }
  close(mem);
  return out;
}

void check_report_input(const std::string& out) {
  using json = nlohmann::json;
  json j;
  try {
    j = json::parse(out);  // strict: no NaN, Infinity or comments; valid UTF-8
  } catch (const json::exception& e) {
    finding(e.what(), out);
  }
  if (!j.is_object() || j.value("format", "") != "octocd-trace") finding("not an octocd-trace object", out);
  if (!j["version"].is_number_integer() || (j["version"] != 1 && j["version"] != 2)) finding("version", out);
  if (!j["frames"].is_number_integer() || j["frames"].get<long long>() < 0) finding("frames", out);
  if (!j["attributes"].is_object()) finding("attributes", out);
  for (const auto& [k, v] : j["attributes"].items())
    if (!v.is_string() && !v.is_number() && !v.is_null()) finding("an attribute neither string nor number", out);
  if (!j["columns"].is_object()) finding("columns", out);
  const auto frames = j["frames"].get<std::size_t>();
  for (const auto& [k, v] : j["columns"].items()) {
    if (!v.is_array() || v.size() != frames) finding("a column not of `frames` values", out);
    for (const auto& x : v)
      if (!x.is_number() && !x.is_null()) finding("a column value neither number nor null", out);
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string path = octocd_fuzz::scratch_path("report");
  octocd_fuzz::write_input(path, data, size);
  const std::string out = summary_json(path);
  if (!out.empty()) check_report_input(out);
  std::remove(path.c_str());
  return 0;
}
