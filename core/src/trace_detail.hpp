#pragma once
// What the trace writer (trace_writer.cpp), the summary of a trace read back
// (trace_summary.cpp) and the XDMF sidecar (trace_xdmf.cpp) share. Private to the build
// (not installed): it needs HDF5's C headers through hdf5_handle.hpp.
#include <cstdint>
#include <string>

#include "octocd/trace.hpp"
#include "hdf5_handle.hpp"

namespace octocd {
namespace detail {

/// The root attribute `format` of every octocd trace (docs/trace-format.md).
inline constexpr const char* kTraceFormat = "octocd-trace";

/// Rows (the first dimension) of the dataset `name` of rank >= 1; a scalar is refused
/// through Hdf5Reader::fail (InputError naming the file and the dataset).
std::int64_t dataset_rows(const Hdf5Reader& h5, const std::string& name);

/// The summary of the trace `h5` holds (format, version, complete frames, state rows,
/// bodies, last frame): the shortest /frames column, at most committed_frames, and the
/// /states rows, at most committed_states. Throws RuntimeError when the file is not an
/// octocd trace, InputError (from Hdf5Reader) when a dataset or attribute is malformed.
TraceSummary trace_summary_of(const Hdf5Reader& h5);

}  // namespace detail
}  // namespace octocd
