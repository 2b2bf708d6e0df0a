#pragma once
// The HDF5 writing primitives of the trace writer (trace_writer.cpp) and of what it takes
// from an engine (trace_metadata.cpp): failures that name the trace and the operation,
// attributes, fixed datasets and the buffered extendable columns. Private to the build (not
// installed): it needs HDF5's C headers.
#include <hdf5.h>

#include <cstdint>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "octocd/error.hpp"
#include "octocd/math.hpp"
#include "hdf5_handle.hpp"

namespace octocd::trace_out {

/// The innermost (most specific) and outermost messages of HDF5's current error stack.
std::string hdf5_message();

/// The operating system's reason in an HDF5 I/O error ("... error message = 'No space left
/// on device', ..."), or "" when the message holds none.
std::string os_reason(const std::string& message);

// An HDF5 call that failed: the message names the trace and the operation; `reason` is
// the operating system's reason when HDF5 gives one ("No space left on device"), else
// HDF5's own message, on one line.
class Hdf5Failure : public RuntimeError {
 public:
  Hdf5Failure(const std::string& path, const std::string& op, std::string reason)
      : RuntimeError("trace '" + path + "': " + op + " failed: " + reason), reason_(std::move(reason)) {}
  const std::string& reason() const { return reason_; }

 private:
  std::string reason_;
};

/// Throws Hdf5Failure for the HDF5 call `op` on the trace `path`, with HDF5's or the operating system's reason.
[[noreturn]] void fail(const std::string& path, const std::string& op);

/// `ret`, or Hdf5Failure (fail) when it is negative (an HDF5 call failed).
template <class T>
T check(T ret, const std::string& path, const std::string& op) {
  if (ret < 0) fail(path, op);
  return ret;
}

using Handle = detail::Hdf5Handle;

/// A variable-length UTF-8 string type.
Handle vlen_string_type(const std::string& path);

/// Writes the scalar string attribute `name` of `obj`.
void attr_string(hid_t obj, const char* name, const std::string& value, const std::string& path);

/// Writes the string array attribute `name` of `obj`.
void attr_strings(hid_t obj, const char* name, const std::vector<std::string>& values,
                  const std::string& path);

/// Writes the scalar attribute `name` of `obj`.
template <class T>
void attr_scalar(hid_t obj, const char* name, hid_t file_type, hid_t mem_type, T value,
                 const std::string& path) {
  Handle space(check(H5Screate(H5S_SCALAR), path, "H5Screate"));
  Handle a(check(H5Acreate2(obj, name, file_type, space, H5P_DEFAULT, H5P_DEFAULT), path,
                 std::string("create attribute ") + name));
  check(H5Awrite(a, mem_type, &value), path, std::string("write attribute ") + name);
}

/// A fixed-size dataset written once, before SWMR starts.
void fixed_dataset(hid_t group, const char* name, hid_t file_type, hid_t mem_type,
                   std::vector<hsize_t> dims, const void* data, const std::string& path);

/// A fixed-size dataset of strings written once, before SWMR starts.
void string_dataset(hid_t group, const char* name, const std::vector<std::string>& values,
                    const std::string& path);

// One extendable dataset whose rows are buffered in memory until the next flush.
struct Column {
  std::string name;          // full path in the file, for messages
  Handle dset;
  hid_t mem_type = -1;       // a native type (not owned)
  std::size_t elem = 0;      // bytes per element
  std::vector<hsize_t> tail; // dimensions after the row dimension
  std::size_t width = 1;     // elements per row
  std::vector<unsigned char> buf;  // rows appended since the last stage()
  std::vector<unsigned char> out;  // rows staged for the next write
  hsize_t rows = 0;          // rows on disk
  bool filtered = false;     // shuffle + deflate, one row a chunk (make_column)

  hsize_t pending() const { return elem * width == 0 ? 0 : out.size() / (elem * width); }  // 0: never created

  /// Moves the appended rows behind the staged ones.
  void stage() {
    if (out.empty())
      out.swap(buf);
    else
      out.insert(out.end(), buf.begin(), buf.end());
    buf.clear();
  }

  template <class T>
  void push(const T* p, std::size_t count) {
    const auto* b = reinterpret_cast<const unsigned char*>(p);
    buf.insert(buf.end(), b, b + count * sizeof(T));
  }
  template <class T>
  void push1(T v) {
    push(&v, 1);
  }

  /// Appends the buffered rows. `raw`: a filtered column's rows are stored as they are,
  /// one chunk each with its filters marked skipped (H5Dwrite_chunk; every reader of
  /// HDF5 1.10.2+ reads them), so the last flush of a stopped run costs a copy, not
  /// deflate (0.4 s a frame of 10^6 bodies' positions and velocities on a slow core).
  void write(const std::string& path, bool raw = false) {
    stage();
    write_staged(path, raw);
  }

  /// Appends the staged rows (write() without stage(): the writer thread's, while the
  /// caller appends to buf).
  void write_staged(const std::string& path, bool raw = false) {
    const hsize_t n = pending();
    if (n == 0) return;
    std::vector<hsize_t> size{rows + n}, start{rows}, count{n};
    for (hsize_t t : tail) {
      size.push_back(t);
      start.push_back(0);
      count.push_back(t);
    }
    const int rank = static_cast<int>(size.size());
    check(H5Dset_extent(dset, size.data()), path, "extend " + name);
    if (raw && filtered) {
      const std::size_t row_bytes = elem * width;
      std::vector<hsize_t> offset(size.size(), 0);
      constexpr std::uint32_t kSkipShuffleAndDeflate = 0x3;  // filter i skipped: bit i set
      for (hsize_t r = 0; r < n; ++r) {
        offset[0] = rows + r;
        check(H5Dwrite_chunk(dset, H5P_DEFAULT, kSkipShuffleAndDeflate, offset.data(), row_bytes,
                             out.data() + r * row_bytes),
              path, "write rows of " + name);
      }
      rows += n;
      out.clear();
      return;
    }
    Handle fspace(check(H5Dget_space(dset), path, "H5Dget_space " + name));
    check(H5Sselect_hyperslab(fspace, H5S_SELECT_SET, start.data(), nullptr, count.data(),
                              nullptr),
          path, "select rows of " + name);
    Handle mspace(check(H5Screate_simple(rank, count.data(), nullptr), path, "H5Screate_simple"));
    check(H5Dwrite(dset, mem_type, mspace, fspace, H5P_DEFAULT, out.data()), path,
          "write rows of " + name);
    rows += n;
    out.clear();
  }
};

/// Creates the extendable dataset GROUP_NAME/NAME of rows shaped `tail`, chunked by `chunk_rows`
/// rows, deflated at level `gzip` (0: none).
Column make_column(hid_t group, const std::string& group_name, const char* name, hid_t file_type,
                   hid_t mem_type, std::vector<hsize_t> tail, hsize_t chunk_rows, int gzip,
                   const std::string& path);

/// The current UTC time as ISO 8601 ("2026-01-31T12:00:00Z").
std::string iso_utc_now();

/// A vector as a JSON array [x, y, z].
nlohmann::json vec_json(Vec3 v);

}  // namespace octocd::trace_out
