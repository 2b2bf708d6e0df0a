#pragma once
// HDF5 C API helpers shared by the trace writer (trace_writer.cpp), the trace reader
// (trace_reader.cpp: replay, compare), read_trace_summary (trace_summary.cpp), the XDMF
// sidecar (trace_xdmf.cpp) and the external-trace reader (trace_in.hpp). Private to the
// build (not installed): it needs HDF5's C headers.
//
// Every trace is untrusted input (issue 22): Hdf5Reader is the one way octocd opens and
// reads an HDF5 file. Its rules and limits are documented in docs/trace-format.md,
// "Security rules and limits".
#include <hdf5.h>

#include <cstddef>
#include <cstdint>
#include <map>
#include <string>
#include <vector>

#include "octocd/trace_reader.hpp"  // trace_limits

namespace octocd {


namespace detail {

/// Owns one HDF5 identifier of any kind (file, group, dataset, dataspace, datatype,
/// attribute, property list) and closes it with the matching call when it goes out of
/// scope or is reset. Movable, not copyable. A negative identifier (a failed HDF5 call)
/// is held as "none" and never closed.
class Hdf5Handle {
 public:
  Hdf5Handle() = default;
  explicit Hdf5Handle(hid_t id) : id_(id) {}
  ~Hdf5Handle() { reset(); }
  Hdf5Handle(const Hdf5Handle&) = delete;
  Hdf5Handle& operator=(const Hdf5Handle&) = delete;
  Hdf5Handle(Hdf5Handle&& o) noexcept : id_(o.id_) { o.id_ = -1; }
  Hdf5Handle& operator=(Hdf5Handle&& o) noexcept {
    if (this != &o) {
      reset();
      id_ = o.id_;
      o.id_ = -1;
    }
    return *this;
  }
  /// The identifier (negative: none).
  hid_t get() const { return id_; }
  /// Whether an identifier is held.
  bool ok() const { return id_ >= 0; }
  /// Forgets the identifier without closing it (a file abandoned after a failed write).
  void release() { id_ = -1; }
  operator hid_t() const { return id_; }  // NOLINT: used as an hid_t in C calls
  /// Closes the identifier now (if any).
  void reset() {
    if (id_ >= 0) {
      switch (H5Iget_type(id_)) {
        case H5I_FILE: H5Fclose(id_); break;
        case H5I_GROUP: H5Gclose(id_); break;
        case H5I_DATATYPE: H5Tclose(id_); break;
        case H5I_DATASPACE: H5Sclose(id_); break;
        case H5I_DATASET: H5Dclose(id_); break;
        case H5I_ATTR: H5Aclose(id_); break;
        case H5I_GENPROP_LST: H5Pclose(id_); break;
        default: break;
      }
    }
    id_ = -1;
  }

 private:
  hid_t id_ = -1;
};

/// Silences HDF5's automatic error printing for the guard's lifetime (the previous
/// handler is restored afterwards), so failures reach the caller only as exceptions.
class QuietHdf5 {
 public:
  QuietHdf5() {
    H5Eget_auto2(H5E_DEFAULT, &func_, &data_);
    H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr);
  }
  ~QuietHdf5() { H5Eset_auto2(H5E_DEFAULT, func_, data_); }
  QuietHdf5(const QuietHdf5&) = delete;
  QuietHdf5& operator=(const QuietHdf5&) = delete;

 private:
  H5E_auto2_t func_ = nullptr;
  void* data_ = nullptr;
};

/// The objects of a file's global heap collections: collection address -> (object index
/// -> object size in bytes).
using GlobalHeaps = std::map<std::uint64_t, std::map<unsigned, std::uint64_t>>;

/// A read-only HDF5 file from an untrusted source, opened and read under the rules of
/// docs/trace-format.md ("Security rules and limits"):
/// - a regular file only (a FIFO, a device or a folder is refused before HDF5 opens it);
/// - global heap collections checked before HDF5 reads them (libhdf5 1.10 loops forever
///   or reads past the heap on a corrupt one); metadata read retries capped (SWMR);
/// - objects reached through hard links only: external links (to another file), soft
///   links and user-defined links are refused;
/// - datasets stored in the file only: external storage (raw data in another file) and
///   virtual datasets (a view of other files) are refused; every filter must be available;
/// - every attribute checked for its type class and for holding one value (not an array)
///   before it is read; strings at most trace_limits::kMaxStringBytes;
/// - every dataset checked for its type class, rank and declared size (bytes at most
///   trace_limits::kMaxExpansion x the file's size + kSlackBytes) before it is read.
/// Every failure is an InputError "<file>: <object>: <problem>; allowed: <values>".
/// HDF5's error printing is off while the reader lives. Not thread-safe. Not movable.
class Hdf5Reader {
 public:
  /// Opens `path` read-only (SWMR read first, so a trace being written reads too).
  /// `what` names the expected content in messages (e.g. "an octocd trace").
  Hdf5Reader(const std::string& path, const std::string& what);
  Hdf5Reader(const Hdf5Reader&) = delete;
  Hdf5Reader& operator=(const Hdf5Reader&) = delete;

  /// The file's path as given.
  const std::string& path() const { return path_; }
  /// The file identifier.
  hid_t file() const { return file_.get(); }
  /// The file's size in bytes when opened.
  std::uint64_t file_bytes() const { return file_bytes_; }

  /// Throws InputError "<path>: <object>: <problem>; allowed: <allowed>".
  [[noreturn]] void fail(const std::string& object, const std::string& problem, const std::string& allowed) const;

  /// Whether the object at the absolute path `name` exists; throws InputError when any
  /// link on the way is not a hard link (external, soft or user-defined).
  bool exists(const std::string& name) const;
  /// Whether `name` exists and is a dataset (same link rules).
  bool is_dataset(const std::string& name) const;

  /// Whether the root attribute `name` exists.
  bool has_attribute(const std::string& name) const;
  /// Root attribute `name` as one string (scalar or one element; fixed or variable
  /// length). Throws InputError when missing, not a string, an array, or too long.
  std::string string_attribute(const std::string& name) const;
  /// Root attribute `name` as one number (an integer or float scalar, or one element).
  double number_attribute(const std::string& name) const;
  /// Root attribute `name` as one integer stored as a 32- or 64-bit integer (a float, an
  /// 8- or 16-bit integer are refused naming the type: a format version is written so).
  std::int64_t integer_attribute(const std::string& name) const;
  /// Root attribute `name` as exactly `count` numbers (any simple shape of `count`).
  std::vector<double> number_attributes(const std::string& name, std::size_t count) const;

  /// One dataset, checked: a hard-linked dataset with contiguous, compact or chunked
  /// storage inside this file, filters available, declared size within the limit.
  struct Dataset {
    std::string name;            ///< absolute path, for messages
    Hdf5Handle id;               ///< the open dataset
    H5T_class_t cls = H5T_NO_CLASS;  ///< type class of the stored elements
    std::size_t type_size = 0;   ///< bytes per stored element
    std::vector<hsize_t> dims;   ///< dimensions (empty for a scalar)
    /// Compressed chunked storage: rows per chunk and the inflated bytes of the band of
    /// chunks that rows [k x chunk_rows, (k + 1) x chunk_rows) span; 0 otherwise.
    hsize_t chunk_rows = 0;
    std::uint64_t band_bytes = 0;
    /// Elements per row (product of dims[1..]).
    std::uint64_t per_row() const;
    /// Whether a dataset is held (an optional dataset that is absent holds none).
    bool present() const { return id.ok(); }
  };
  /// Opens dataset `name` (throws InputError when missing, not a dataset, or refused).
  /// A compressed chunked dataset is opened once per reader, with a chunk cache holding
  /// the chunks of one band of rows (Dataset::band_bytes); chunks above
  /// trace_limits::kMaxChunkBytes, or a band above it, are refused.
  Dataset open_dataset(const std::string& name) const;
  /// As open_dataset, and checks the class (H5T_INTEGER or H5T_FLOAT: either is
  /// accepted when `numeric`) and rank.
  Dataset open_numeric(const std::string& name, int rank) const;

  /// Rows [first, first + count) of `d` converted to `mem_type` into `out` (which must
  /// hold count x per_row elements). Throws InputError for rows outside the dataset, a
  /// failed read (a missing filter, a type HDF5 cannot convert, a damaged file), or a read
  /// that takes the values read from this file past trace_limits::kMaxReadExpansion x its
  /// size + kReadSlackBytes (a compression bomb). Of a compressed chunked dataset, the
  /// bytes counted are the bands of chunks inflated (every band the rows touch except the
  /// one the dataset's chunk cache holds), or the values read when more.
  void read_rows(const Dataset& d, hsize_t first, hsize_t count, hid_t mem_type, void* out) const;
  /// Every element of a 1-D string dataset (fixed or variable length).
  std::vector<std::string> read_strings(const std::string& name) const;

 private:
  std::string path_;
  std::string what_;
  std::uint64_t file_bytes_ = 0;
  GlobalHeaps heaps_;  // every global heap object, checked before HDF5 opened the file
  mutable std::uint64_t read_bytes_ = 0;  // values read so far (read_rows), against the read budget
  QuietHdf5 quiet_;  // declared before file_: outlives it
  Hdf5Handle file_;
  /// Compressed chunked datasets, kept open with a chunk cache of one band (declared after
  /// file_: closed before it), and the band of rows whose chunks that cache holds (-1: none).
  struct Cached {
    Hdf5Handle id;
    std::int64_t band = -1;
  };
  mutable std::map<std::string, Cached> chunked_;
  Hdf5Handle attribute(const std::string& name, H5T_class_t cls, std::size_t count) const;
  void check_vlen_lengths(const Dataset& d) const;
  void open_chunked(Dataset& d, hid_t dcpl) const;
};

/// The /frames columns of trace format version 1, in the writer's order (trace_writer.cpp).
const std::vector<std::string>& trace_frame_columns();

/// Walks every global heap collection of `path` the way libhdf5 1.10 does and throws
/// InputError naming the file when one would make HDF5 loop forever or read past it.
/// Returns the objects found.
GlobalHeaps check_global_heaps(const std::string& path);

}  // namespace detail
}  // namespace octocd
