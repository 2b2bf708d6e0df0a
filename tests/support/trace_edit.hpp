#pragma once
// Editing an HDF5 trace in place, for tests that plant faults in another engine's trace:
// a dataset read whole as doubles with its shape, written back, or replaced by one of
// another shape keeping its file type.
#include <gtest/gtest.h>
#include <hdf5.h>

#include <string>
#include <vector>

namespace octocd::test {

/// A dataset read as doubles (integers converted exactly below 2^53), with its shape.
struct Data {
  std::vector<hsize_t> dims;
  std::vector<double> v;
  hsize_t rows() const { return dims.empty() ? 0 : dims[0]; }
  hsize_t row_size() const {
    hsize_t r = 1;
    for (std::size_t i = 1; i < dims.size(); ++i) r *= dims[i];
    return r;
  }
};

inline Data read(hid_t file, const std::string& name) {
  Data d;
  const hid_t ds = H5Dopen2(file, name.c_str(), H5P_DEFAULT);
  if (ds < 0) return d;
  const hid_t space = H5Dget_space(ds);
  d.dims.resize(static_cast<std::size_t>(H5Sget_simple_extent_ndims(space)));
  H5Sget_simple_extent_dims(space, d.dims.data(), nullptr);
  hsize_t n = 1;
  for (hsize_t x : d.dims) n *= x;
  d.v.resize(n);
  if (n > 0) H5Dread(ds, H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, H5P_DEFAULT, d.v.data());
  H5Sclose(space);
  H5Dclose(ds);
  return d;
}

/// Replaces dataset `name` by `d`, keeping its file type (integers stay integers).
inline void replace(hid_t file, const std::string& name, const Data& d) {
  const hid_t old = H5Dopen2(file, name.c_str(), H5P_DEFAULT);
  ASSERT_GE(old, 0) << name;
  const hid_t type = H5Dget_type(old);
  H5Dclose(old);
  ASSERT_GE(H5Ldelete(file, name.c_str(), H5P_DEFAULT), 0) << name;
  const hid_t space = H5Screate_simple(static_cast<int>(d.dims.size()), d.dims.data(), nullptr);
  const hid_t ds = H5Dcreate2(file, name.c_str(), type, space, H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
  ASSERT_GE(ds, 0) << name;
  if (!d.v.empty()) {
    ASSERT_GE(H5Dwrite(ds, H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, H5P_DEFAULT, d.v.data()), 0);
  }
  H5Dclose(ds);
  H5Sclose(space);
  H5Tclose(type);
}

/// Writes `d` back over dataset `name` (same shape; the file keeps its type).
inline void write(hid_t file, const std::string& name, const Data& d) {
  const hid_t ds = H5Dopen2(file, name.c_str(), H5P_DEFAULT);
  ASSERT_GE(ds, 0) << name;
  ASSERT_GE(H5Dwrite(ds, H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, H5P_DEFAULT, d.v.data()), 0) << name;
  H5Dclose(ds);
}

/// One float32 dataset of a trace written by write_minimal_trace: its path, shape and
/// row-major values (not owned: they outlive the call).
struct FloatDataset {
  std::string name;
  std::vector<hsize_t> dims;
  const std::vector<float>* values;
};

/// Writes a minimal external trace at `path` (docs/trace-format.md, version 1): the root
/// attributes format "octocd-trace" and version 1, then each dataset as float32, groups
/// created as needed. Fails the calling test on an HDF5 error.
inline void write_minimal_trace(const std::string& path, const std::vector<FloatDataset>& datasets) {
  const hid_t f = H5Fcreate(path.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT);
  ASSERT_GE(f, 0) << path;
  const hid_t t = H5Tcopy(H5T_C_S1);
  H5Tset_size(t, H5T_VARIABLE);
  const hid_t sc = H5Screate(H5S_SCALAR);
  const char* format = "octocd-trace";
  const hid_t a = H5Acreate2(f, "format", t, sc, H5P_DEFAULT, H5P_DEFAULT);
  H5Awrite(a, t, &format);
  H5Aclose(a);
  const int one = 1;
  const hid_t v = H5Acreate2(f, "version", H5T_STD_I32LE, sc, H5P_DEFAULT, H5P_DEFAULT);
  H5Awrite(v, H5T_NATIVE_INT, &one);
  H5Aclose(v);
  H5Sclose(sc);
  H5Tclose(t);
  const hid_t lcpl = H5Pcreate(H5P_LINK_CREATE);
  H5Pset_create_intermediate_group(lcpl, 1);
  for (const FloatDataset& ds : datasets) {
    const hid_t s = H5Screate_simple(static_cast<int>(ds.dims.size()), ds.dims.data(), nullptr);
    const hid_t d = H5Dcreate2(f, ds.name.c_str(), H5T_IEEE_F32LE, s, lcpl, H5P_DEFAULT, H5P_DEFAULT);
    EXPECT_GE(d, 0) << ds.name;
    EXPECT_GE(H5Dwrite(d, H5T_NATIVE_FLOAT, H5S_ALL, H5S_ALL, H5P_DEFAULT, ds.values->data()), 0) << ds.name;
    H5Dclose(d);
    H5Sclose(s);
  }
  H5Pclose(lcpl);
  H5Fclose(f);
}

}  // namespace octocd::test
