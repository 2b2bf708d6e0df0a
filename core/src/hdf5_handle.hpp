#pragma once
// HDF5 C API helpers shared by the trace writer (trace.cpp), the trace reader
// (trace_reader.cpp) and the external-trace reader (validation/src/trace_in.cpp). Private
// to the build (not installed): it needs HDF5's C headers.
#include <hdf5.h>

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

}  // namespace detail
}  // namespace octocd
