// The summary of a trace read back (read_trace_summary; docs/trace-format.md): complete
// frames, state rows and bodies of a file its writer may have left mid-run, through the
// hardened reader (detail::Hdf5Reader). The writer is in trace_writer.cpp.
#include <hdf5.h>

#include <algorithm>
#include <cstdint>
#include <string>

#include <fmt/format.h>

#include "octocd/error.hpp"
#include "octocd/trace.hpp"
#include "octocd/trace_reader.hpp"
#include "hdf5_handle.hpp"
#include "trace_detail.hpp"

namespace octocd {

namespace {

// The committed-rows root attribute (committed_frames, committed_states), -1 when absent
// (a trace written before it existed).
std::int64_t committed_rows(const detail::Hdf5Reader& h5, const char* name) {
  if (!h5.has_attribute(name)) return -1;
  const double v = h5.number_attribute(name);
  if (!(v >= 0.0 && v <= static_cast<double>(trace_limits::kMaxFrames)))
    h5.fail(std::string("/ (root attribute ") + name + ")", fmt::format("{}", v),
            fmt::format("a row count in [0, {}]", trace_limits::kMaxFrames));
  return static_cast<std::int64_t>(v);
}

}  // namespace

std::int64_t detail::dataset_rows(const Hdf5Reader& h5, const std::string& name) {
  const Hdf5Reader::Dataset d = h5.open_dataset(name);
  if (d.dims.empty()) h5.fail(name, "a scalar", "a dataset of rank >= 1 (docs/trace-format.md)");
  return static_cast<std::int64_t>(d.dims[0]);
}

TraceSummary detail::trace_summary_of(const Hdf5Reader& h5) {
  const std::string& path = h5.path();
  TraceSummary s;
  if (!h5.has_attribute("format"))
    throw RuntimeError("trace '" + path + "': not an octocd trace (no root attribute 'format')");
  s.format = h5.string_attribute("format");
  if (s.format != kTraceFormat)
    throw RuntimeError("trace '" + path + "': not an octocd trace (format '" + s.format + "')");
  const double version = static_cast<double>(h5.integer_attribute("version"));
  if (!(version >= 0.0 && version <= 1000.0))
    h5.fail("/ (root attribute version)", fmt::format("{}", version), "1");
  s.version = static_cast<int>(version);
  // Every /frames column of format version 1, opened by name; the shortest gives the
  // complete rows (docs/trace-format.md), and at most committed_frames. Not listed by
  // index: libhdf5 1.10 frees uninitialised pointers (SIGSEGV) when a corrupt group's link
  // table fails to load (H5Lget_name_by_idx -> H5G__link_release_table; found by fuzz_trace).
  std::int64_t rows = -1;
  for (const std::string& name : trace_frame_columns()) {
    const std::int64_t r = dataset_rows(h5, "/frames/" + name);
    rows = rows < 0 ? r : std::min(rows, r);
  }
  const std::int64_t cf = committed_rows(h5, "committed_frames");
  if (cf >= 0) rows = std::min(rows, cf);
  s.frames = std::max<std::int64_t>(rows, 0);
  s.state_rows = std::min({dataset_rows(h5, "/states/frame"), dataset_rows(h5, "/states/position"),
                           dataset_rows(h5, "/states/velocity")});
  const std::int64_t cs = committed_rows(h5, "committed_states");
  if (cs >= 0) s.state_rows = std::min(s.state_rows, cs);
  s.bodies = dataset_rows(h5, "/bodies/shape_id");
  if (s.frames > 0) {
    const Hdf5Reader::Dataset d = h5.open_numeric("/frames/frame", 1);
    h5.read_rows(d, static_cast<hsize_t>(s.frames - 1), 1, H5T_NATIVE_INT64, &s.last_frame);
  }
  return s;
}

TraceSummary read_trace_summary(const std::string& path) {
  try {
    const detail::Hdf5Reader h5(path, "an octocd trace");
    return detail::trace_summary_of(h5);
  } catch (const InputError& e) {  // a trace read back: a runtime failure of its writer's command
    throw RuntimeError(std::string("trace ") + e.what());
  }
}

}  // namespace octocd
