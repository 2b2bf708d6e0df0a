// Reading traces back (trace_reader.hpp): `octocd replay` and `octocd compare`.
#include "octocd/trace_reader.hpp"

#include <hdf5.h>

#include <algorithm>
#include <cstring>
#include <filesystem>

#include <fmt/format.h>

#include "octocd/error.hpp"
#include "hdf5_handle.hpp"

namespace octocd {

namespace {

using Quiet = detail::QuietHdf5;  // failures reach the caller as InputError only
using Id = detail::Hdf5Handle;

}  // namespace

struct TraceReader::Impl {
  std::string path;
  hid_t file = -1;

  [[noreturn]] void fail(const std::string& what, const std::string& problem) const {
    throw InputError(fmt::format("{}: {}: {}", path, what, problem));
  }
  // Whether every link of an absolute path exists (H5Lexists needs each parent).
  bool exists(const std::string& p) const {
    std::string part;
    std::size_t pos = 1;
    while (pos <= p.size()) {
      const std::size_t next = p.find('/', pos);
      part = p.substr(0, next == std::string::npos ? p.size() : next);
      if (H5Lexists(file, part.c_str(), H5P_DEFAULT) <= 0) return false;
      if (next == std::string::npos) break;
      pos = next + 1;
    }
    return true;
  }
  hid_t open_dataset(const std::string& d) const {
    if (!exists(d)) fail(d, "missing; allowed: a trace holding it (docs/trace-format.md)");
    const hid_t id = H5Dopen2(file, d.c_str(), H5P_DEFAULT);
    if (id < 0) fail(d, "cannot be opened as a dataset");
    return id;
  }
  std::vector<hsize_t> dims(hid_t dataset, const std::string& d) const {
    Id space(H5Dget_space(dataset));
    const int rank = space.ok() ? H5Sget_simple_extent_ndims(space) : -1;
    if (rank < 0) fail(d, "unreadable dataspace");
    std::vector<hsize_t> out(static_cast<std::size_t>(rank), 0);
    if (rank > 0) H5Sget_simple_extent_dims(space, out.data(), nullptr);
    return out;
  }
  template <class T>
  std::vector<T> read_rows(const std::string& d, std::int64_t first, std::int64_t count, hid_t mem_type) const {
    Quiet quiet;
    Id ds(open_dataset(d));
    const std::vector<hsize_t> dim = dims(ds, d);
    if (dim.empty()) fail(d, "is a scalar; allowed: a dataset of rank >= 1");
    if (first < 0 || count < 0 || static_cast<hsize_t>(first + count) > dim[0])
      fail(d, fmt::format("rows {}..{} asked, it has {}; allowed: rows below its length", first, first + count,
                          dim[0]));
    std::size_t per_row = 1;
    for (std::size_t i = 1; i < dim.size(); ++i) per_row *= static_cast<std::size_t>(dim[i]);
    std::vector<T> out(static_cast<std::size_t>(count) * per_row);
    if (out.empty()) return out;
    Id fspace(H5Dget_space(ds));
    std::vector<hsize_t> start(dim.size(), 0), cnt = dim;
    start[0] = static_cast<hsize_t>(first);
    cnt[0] = static_cast<hsize_t>(count);
    if (H5Sselect_hyperslab(fspace, H5S_SELECT_SET, start.data(), nullptr, cnt.data(), nullptr) < 0)
      fail(d, "cannot select rows");
    Id mspace(H5Screate_simple(static_cast<int>(cnt.size()), cnt.data(), nullptr));
    if (H5Dread(ds, mem_type, mspace, fspace, H5P_DEFAULT, out.data()) < 0)
      fail(d, "read failed (type not convertible, or the file is damaged)");
    return out;
  }
};

TraceReader::TraceReader(const std::string& path) : impl_(std::make_unique<Impl>()) {
  Quiet quiet;
  impl_->path = path;
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec))
    throw InputError(fmt::format("{}: no such file; allowed: an octocd trace (.h5)", path));
  if (H5Fis_hdf5(path.c_str()) <= 0)
    throw InputError(fmt::format("{}: not an HDF5 file; allowed: an octocd trace (docs/trace-format.md)", path));
  impl_->file = H5Fopen(path.c_str(), H5F_ACC_RDONLY | H5F_ACC_SWMR_READ, H5P_DEFAULT);
  if (impl_->file < 0) impl_->file = H5Fopen(path.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT);
  if (impl_->file < 0) throw InputError(fmt::format("{}: cannot open the HDF5 file read-only", path));
  if (!has_attribute("format"))
    throw InputError(fmt::format("{}: format: missing root attribute; allowed: \"octocd-trace\"", path));
  const std::string format = string_attribute("format");
  if (format != "octocd-trace")
    throw InputError(fmt::format("{}: format: '{}'; allowed: \"octocd-trace\"", path, format));
  const double version = has_attribute("version") ? number_attribute("version") : -1.0;
  if (version != 1.0)
    throw InputError(fmt::format("{}: version: {}; allowed: 1 (this octocd reads octocd-trace version 1)", path,
                                 version));
}

TraceReader::~TraceReader() {
  if (impl_ && impl_->file >= 0) H5Fclose(impl_->file);
}
TraceReader::TraceReader(TraceReader&&) noexcept = default;
TraceReader& TraceReader::operator=(TraceReader&&) noexcept = default;

const std::string& TraceReader::path() const { return impl_->path; }

bool TraceReader::has_attribute(const std::string& name) const {
  Quiet quiet;
  return H5Aexists(impl_->file, name.c_str()) > 0;
}

std::string TraceReader::string_attribute(const std::string& name) const {
  Quiet quiet;
  if (!has_attribute(name)) impl_->fail(name, "missing root attribute");
  Id a(H5Aopen(impl_->file, name.c_str(), H5P_DEFAULT));
  Id ft(H5Aget_type(a));
  if (!ft.ok() || H5Tget_class(ft) != H5T_STRING) impl_->fail(name, "not a string attribute");
  if (H5Tis_variable_str(ft) > 0) {
    Id mt(H5Tcopy(H5T_C_S1));
    H5Tset_size(mt, H5T_VARIABLE);
    H5Tset_cset(mt, H5Tget_cset(ft));
    char* p = nullptr;
    if (H5Aread(a, mt, &p) < 0) impl_->fail(name, "unreadable attribute");
    std::string s = p ? p : "";
    if (p) H5free_memory(p);
    return s;
  }
  std::string s(H5Tget_size(ft), '\0');
  if (H5Aread(a, ft, s.data()) < 0) impl_->fail(name, "unreadable attribute");
  s.resize(std::strlen(s.c_str()));
  return s;
}

double TraceReader::number_attribute(const std::string& name) const {
  Quiet quiet;
  if (!has_attribute(name)) impl_->fail(name, "missing root attribute");
  Id a(H5Aopen(impl_->file, name.c_str(), H5P_DEFAULT));
  double v = 0.0;
  if (H5Aread(a, H5T_NATIVE_DOUBLE, &v) < 0) impl_->fail(name, "not a number");
  return v;
}

bool TraceReader::has_dataset(const std::string& dataset) const {
  Quiet quiet;
  if (!impl_->exists(dataset)) return false;
  Id obj(H5Oopen(impl_->file, dataset.c_str(), H5P_DEFAULT));
  return obj.ok() && H5Iget_type(obj) == H5I_DATASET;
}

std::vector<std::uint64_t> TraceReader::shape(const std::string& dataset) const {
  Quiet quiet;
  Id ds(impl_->open_dataset(dataset));
  const auto d = impl_->dims(ds, dataset);
  return {d.begin(), d.end()};
}

std::int64_t TraceReader::complete_rows(const std::string& group) const {
  Quiet quiet;
  if (!impl_->exists(group)) impl_->fail(group, "missing group; allowed: a trace holding it (docs/trace-format.md)");
  Id g(H5Gopen2(impl_->file, group.c_str(), H5P_DEFAULT));
  if (!g.ok()) impl_->fail(group, "not a group");
  H5G_info_t info{};
  H5Gget_info(g, &info);
  std::int64_t rows = -1;
  for (hsize_t i = 0; i < info.nlinks; ++i) {
    char name[256];
    if (H5Lget_name_by_idx(g, ".", H5_INDEX_NAME, H5_ITER_INC, i, name, sizeof name, H5P_DEFAULT) < 0) continue;
    const std::string d = group + "/" + name;
    if (!has_dataset(d)) continue;
    const auto s = shape(d);
    if (s.empty()) continue;
    rows = rows < 0 ? static_cast<std::int64_t>(s[0]) : std::min(rows, static_cast<std::int64_t>(s[0]));
  }
  return std::max<std::int64_t>(rows, 0);
}

std::vector<double> TraceReader::read_f64(const std::string& d, std::int64_t rows) const {
  return impl_->read_rows<double>(d, 0, rows, H5T_NATIVE_DOUBLE);
}
std::vector<std::int64_t> TraceReader::read_i64(const std::string& d, std::int64_t rows) const {
  return impl_->read_rows<std::int64_t>(d, 0, rows, H5T_NATIVE_INT64);
}
std::vector<std::uint64_t> TraceReader::read_u64(const std::string& d, std::int64_t rows) const {
  return impl_->read_rows<std::uint64_t>(d, 0, rows, H5T_NATIVE_UINT64);
}
std::vector<std::uint32_t> TraceReader::read_u32(const std::string& d, std::int64_t rows) const {
  return impl_->read_rows<std::uint32_t>(d, 0, rows, H5T_NATIVE_UINT32);
}
std::vector<float> TraceReader::read_f32(const std::string& d, std::int64_t rows) const {
  return impl_->read_rows<float>(d, 0, rows, H5T_NATIVE_FLOAT);
}
std::vector<float> TraceReader::read_f32_rows(const std::string& d, std::int64_t first, std::int64_t count) const {
  return impl_->read_rows<float>(d, first, count, H5T_NATIVE_FLOAT);
}

std::vector<std::string> TraceReader::read_strings(const std::string& d) const {
  Quiet quiet;
  Id ds(impl_->open_dataset(d));
  const auto dim = impl_->dims(ds, d);
  if (dim.size() != 1) impl_->fail(d, "not a 1-D dataset");
  Id mt(H5Tcopy(H5T_C_S1));
  H5Tset_size(mt, H5T_VARIABLE);
  H5Tset_cset(mt, H5T_CSET_UTF8);
  std::vector<char*> raw(static_cast<std::size_t>(dim[0]), nullptr);
  if (!raw.empty() && H5Dread(ds, mt, H5S_ALL, H5S_ALL, H5P_DEFAULT, raw.data()) < 0)
    impl_->fail(d, "unreadable strings");
  std::vector<std::string> out;
  out.reserve(raw.size());
  for (char* p : raw) {
    out.emplace_back(p ? p : "");
    if (p) H5free_memory(p);
  }
  return out;
}

std::vector<Aabb> TraceReader::local_boxes() const {
  const auto n = static_cast<std::int64_t>(shape("/bodies/local_aabb_min").at(0));
  const std::vector<float> lo = read_f32("/bodies/local_aabb_min", n);
  const std::vector<float> hi = read_f32("/bodies/local_aabb_max", n);
  if (lo.size() != static_cast<std::size_t>(3 * n) || hi.size() != lo.size())
    impl_->fail("/bodies/local_aabb_min", "expected bodies x 3 floats");
  std::vector<Aabb> out(static_cast<std::size_t>(n));
  for (std::size_t i = 0; i < out.size(); ++i) {
    out[i].min = Vec3{lo[3 * i], lo[3 * i + 1], lo[3 * i + 2]};
    out[i].max = Vec3{hi[3 * i], hi[3 * i + 1], hi[3 * i + 2]};
  }
  return out;
}

}  // namespace octocd
