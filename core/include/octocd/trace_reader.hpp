#pragma once
/// \file trace_reader.hpp
/// Reads traces back (SPEC section 8; layout in docs/trace-format.md, format
/// "octocd-trace" version 1) for `octocd replay` and `octocd compare`: root attributes,
/// whole 1-D columns, and single rows of the per-body arrays of /states, without loading
/// the whole file. Opened read-only with the SWMR-read flag, so a trace still being
/// written or left by a killed run reads too (its complete rows: see complete_rows).
///
/// Every error is an InputError (a trace is input: `octocd` exits with 2) whose message
/// has the form `<file>: <dataset or attribute>: <problem>; allowed: ...`.

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "octocd/math.hpp"

namespace octocd {

/// One trace file, open read-only. Not thread-safe. Move-only.
class TraceReader {
 public:
  /// Opens `path` and checks the root attributes `format == "octocd-trace"` and
  /// `version == 1`. Throws InputError naming the file when it does not exist, is not an
  /// HDF5 file, or is a trace of another format or version.
  explicit TraceReader(const std::string& path);
  ~TraceReader();
  TraceReader(TraceReader&&) noexcept;
  TraceReader& operator=(TraceReader&&) noexcept;

  /// The file's path as given.
  const std::string& path() const;

  /// Whether the root attribute `name` exists.
  bool has_attribute(const std::string& name) const;
  /// Root string attribute (throws InputError when absent or not a string).
  std::string string_attribute(const std::string& name) const;
  /// Root numeric attribute, converted to double (throws InputError when absent).
  double number_attribute(const std::string& name) const;

  /// Whether the dataset at `dataset` (e.g. "/states/position") exists.
  bool has_dataset(const std::string& dataset) const;
  /// The dataset's dimensions (throws InputError when absent).
  std::vector<std::uint64_t> shape(const std::string& dataset) const;
  /// Complete rows of a group (docs/trace-format.md: the first min(len) rows over its
  /// datasets); 0 for a group without datasets. Throws InputError when absent.
  std::int64_t complete_rows(const std::string& group) const;

  /// The first `rows` rows of a dataset, every element converted by HDF5 to the asked
  /// type (for a dataset of rank > 1, rows x the other dimensions, row-major). Throws
  /// InputError when absent, when `rows` exceeds its length, or when HDF5 cannot
  /// convert its type.
  std::vector<double> read_f64(const std::string& dataset, std::int64_t rows) const;
  std::vector<std::int64_t> read_i64(const std::string& dataset, std::int64_t rows) const;
  std::vector<std::uint64_t> read_u64(const std::string& dataset, std::int64_t rows) const;
  std::vector<std::uint32_t> read_u32(const std::string& dataset, std::int64_t rows) const;
  std::vector<float> read_f32(const std::string& dataset, std::int64_t rows) const;
  /// Rows [first, first + count) of a float dataset (e.g. one state of /states/position:
  /// count 1 gives bodies x 3 floats), row-major.
  std::vector<float> read_f32_rows(const std::string& dataset, std::int64_t first, std::int64_t count) const;
  /// Every element of a 1-D string dataset (e.g. /bodies/group).
  std::vector<std::string> read_strings(const std::string& dataset) const;

  /// Local AABBs of /bodies (local_aabb_min, local_aabb_max), one per body (m).
  std::vector<Aabb> local_boxes() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace octocd
