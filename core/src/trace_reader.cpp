// Reading traces back (trace_reader.hpp): `octocd replay` and `octocd compare`.
#include "octocd/trace_reader.hpp"

#include <hdf5.h>

#include <algorithm>
#include <cmath>
#include <iterator>
#include <cstring>
#include <filesystem>

#include <fmt/format.h>
#include <fmt/ranges.h>

#include "octocd/error.hpp"
#include "hdf5_handle.hpp"

namespace octocd {

struct TraceReader::Impl {
  std::unique_ptr<detail::Hdf5Reader> h5;
  int version = 1;  ///< root attribute `version` (1 or 2)

  [[noreturn]] void fail(const std::string& what, const std::string& problem, const std::string& allowed) const {
    h5->fail(what, problem, allowed);
  }
  template <class T>
  std::vector<T> read_rows(const std::string& d, std::int64_t first, std::int64_t count, hid_t mem_type) const {
    const detail::Hdf5Reader::Dataset ds = h5->open_dataset(d);
    if (ds.cls != H5T_INTEGER && ds.cls != H5T_FLOAT)
      fail(d, "not numbers", "a dataset of integers or floats (docs/trace-format.md)");
    if (ds.dims.empty()) fail(d, "a scalar", "a dataset of rank >= 1");
    if (first < 0 || count < 0) fail(d, fmt::format("rows {}..{} asked", first, first + count), "rows >= 0");
    // Bounded by the dataset's declared size, itself bounded by the file's (open_dataset).
    std::vector<T> out(static_cast<std::size_t>(std::min<std::uint64_t>(static_cast<std::uint64_t>(count),
                                                                        ds.dims[0])) *
                       static_cast<std::size_t>(ds.per_row()));
    // read_rows checks the rows before it writes to `out`.
    h5->read_rows(ds, static_cast<hsize_t>(first), static_cast<hsize_t>(count), mem_type, out.data());
    return out;
  }
  // The committed-rows attribute of a group's rows (docs/trace-format.md): a row past it
  // may hold data that never reached the disk (a write that failed). -1 when absent.
  std::int64_t committed(const std::string& group) const {
    const char* name = group == "/frames" ? "committed_frames" : group == "/states" ? "committed_states" : nullptr;
    if (name == nullptr || !h5->has_attribute(name)) return -1;
    const double v = h5->number_attribute(name);
    if (!(v >= 0.0 && v <= static_cast<double>(trace_limits::kMaxFrames)))
      fail(fmt::format("/ (root attribute {})", name), fmt::format("{}", v),
           fmt::format("a row count in [0, {}]", trace_limits::kMaxFrames));
    return static_cast<std::int64_t>(v);
  }
};

TraceReader::TraceReader(const std::string& path) : impl_(std::make_unique<Impl>()) {
  impl_->h5 = std::make_unique<detail::Hdf5Reader>(path, "an octocd trace");
  if (!has_attribute("format"))
    throw InputError(fmt::format("{}: format: missing root attribute; allowed: \"octocd-trace\"", path));
  const std::string format = string_attribute("format");
  if (format != "octocd-trace")
    throw InputError(fmt::format("{}: format: '{}'; allowed: \"octocd-trace\"", path, format));
  // A 32- or 64-bit integer (a float or uint8 version is refused naming its type).
  const double version = has_attribute("version") ? static_cast<double>(impl_->h5->integer_attribute("version")) : -1.0;
  if (version != 1.0 && version != 2.0)
    throw InputError(fmt::format("{}: version: {}; allowed: 1 or 2 (this octocd reads octocd-trace versions 1 and 2)",
                                 path, version));
  impl_->version = static_cast<int>(version);
}

TraceReader::~TraceReader() = default;
TraceReader::TraceReader(TraceReader&&) noexcept = default;
TraceReader& TraceReader::operator=(TraceReader&&) noexcept = default;

const std::vector<std::string>& TraceReader::frame_columns() { return detail::trace_frame_columns(); }

const std::string& TraceReader::path() const { return impl_->h5->path(); }

int TraceReader::version() const { return impl_->version; }

bool TraceReader::has_attribute(const std::string& name) const { return impl_->h5->has_attribute(name); }

std::string TraceReader::string_attribute(const std::string& name) const {
  return impl_->h5->string_attribute(name);
}

double TraceReader::number_attribute(const std::string& name) const { return impl_->h5->number_attribute(name); }

bool TraceReader::has_dataset(const std::string& dataset) const { return impl_->h5->is_dataset(dataset); }

std::vector<std::uint64_t> TraceReader::shape(const std::string& dataset) const {
  const auto d = impl_->h5->open_dataset(dataset);
  return {d.dims.begin(), d.dims.end()};
}

std::int64_t TraceReader::complete_rows(const std::string& group) const {
  if (!impl_->h5->exists(group))
    impl_->fail(group, "missing group", "a trace holding it (docs/trace-format.md)");
  // Datasets by name (format version 1), never listed by index: libhdf5 1.10 frees
  // uninitialised pointers when a corrupt group's link table fails to load (found by
  // fuzz_trace in read_trace_summary).
  std::vector<std::string> names;
  if (group == "/frames") names = detail::trace_frame_columns();
  else if (group == "/states") names = {"frame", "position", "velocity", "orientation", "angular_velocity"};
  else if (group == "/contacts") names = {"offsets", "frame"};
  else impl_->fail(group, "not a group of rows", "/frames, /states or /contacts");
  std::int64_t rows = -1;
  for (const std::string& n : names) {
    const std::string d = group + "/" + n;
    if (!has_dataset(d)) continue;
    const auto s = shape(d);
    if (s.empty()) continue;
    std::int64_t r = static_cast<std::int64_t>(s[0]);
    if (group == "/contacts" && n == "offsets") r = std::max<std::int64_t>(r - 1, 0);  // F + 1 offsets
    rows = rows < 0 ? r : std::min(rows, r);
  }
  const std::int64_t c = impl_->committed(group == "/contacts" ? "/frames" : group);
  if (c >= 0) rows = std::min(std::max<std::int64_t>(rows, 0), c);
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

std::vector<double> TraceReader::read_f64_rows(const std::string& d, std::int64_t first, std::int64_t count) const {
  return impl_->read_rows<double>(d, first, count, H5T_NATIVE_DOUBLE);
}
std::vector<std::int64_t> TraceReader::read_i64_rows(const std::string& d, std::int64_t first,
                                                     std::int64_t count) const {
  return impl_->read_rows<std::int64_t>(d, first, count, H5T_NATIVE_INT64);
}

std::string TraceReader::element_kind(const std::string& d) const {
  const detail::Hdf5Reader::Dataset ds = impl_->h5->open_dataset(d);
  return ds.cls == H5T_INTEGER ? "integer" : ds.cls == H5T_FLOAT ? "float" : ds.cls == H5T_STRING ? "string" : "other";
}

TraceAttribute TraceReader::attribute(const std::string& name) const {
  const std::string obj = "/ (root attribute " + name + ")";
  detail::Hdf5Reader& h5 = *impl_->h5;
  if (!h5.has_attribute(name)) impl_->fail(obj, "missing", "a root attribute of docs/trace-format.md");
  TraceAttribute out;
  hssize_t n = 0;
  H5T_class_t cls = H5T_NO_CLASS;
  bool vlen = false;
  {
    const detail::Hdf5Handle a(H5Aopen(h5.file(), name.c_str(), H5P_DEFAULT));
    const detail::Hdf5Handle type(a.ok() ? H5Aget_type(a) : -1), space(a.ok() ? H5Aget_space(a) : -1);
    if (!type.ok() || !space.ok()) impl_->fail(obj, "unreadable", "a readable attribute");
    cls = H5Tget_class(type);
    const H5S_class_t sc = H5Sget_simple_extent_type(space);
    n = sc == H5S_SCALAR ? 1 : sc == H5S_SIMPLE ? H5Sget_simple_extent_npoints(space) : 0;
    out.scalar = sc == H5S_SCALAR || n == 1;
    if (n < 1 || n > 64)
      impl_->fail(obj, sc == H5S_NULL ? "holds no value (null dataspace)" : fmt::format("{} values", n),
                  "1 to 64 values");
    vlen = cls == H5T_STRING && H5Tis_variable_str(type) > 0;
    if (cls == H5T_STRING && !vlen && H5Tget_size(type) > trace_limits::kMaxStringBytes / 64)
      impl_->fail(obj, fmt::format("strings of {} bytes", H5Tget_size(type)),
                  fmt::format("at most {} bytes", trace_limits::kMaxStringBytes / 64));
    if ((cls == H5T_INTEGER || cls == H5T_FLOAT) && H5Tget_size(type) > 16)
      impl_->fail(obj, "a number wider than 128 bits", "a number (integer or float)");
    if (cls == H5T_STRING && n > 1) {
      // An array of strings (stage_names): read here, each bounded.
      out.is_string = true;
      if (vlen) {
        detail::Hdf5Handle mem(H5Tcopy(H5T_C_S1));
        H5Tset_size(mem, H5T_VARIABLE);
        std::vector<char*> raw(static_cast<std::size_t>(n), nullptr);
        if (H5Aread(a, mem, raw.data()) < 0) impl_->fail(obj, "unreadable strings (damaged file?)", "strings");
        for (char* p : raw) {
          out.strings.emplace_back(p ? std::string(p, ::strnlen(p, trace_limits::kMaxStringBytes / 64)) : "");
          if (p) H5free_memory(p);
        }
      } else {
        const std::size_t size = H5Tget_size(type);
        std::vector<char> buf(static_cast<std::size_t>(n) * size);
        if (H5Aread(a, type, buf.data()) < 0) impl_->fail(obj, "unreadable strings (damaged file?)", "strings");
        for (hssize_t i = 0; i < n; ++i) {
          const char* p = buf.data() + static_cast<std::size_t>(i) * size;
          out.strings.emplace_back(p, ::strnlen(p, size));
        }
      }
      return out;
    }
  }
  if (cls == H5T_STRING) {
    out.is_string = true;
    out.strings.push_back(h5.string_attribute(name));
  } else if (cls == H5T_INTEGER || cls == H5T_FLOAT) {
    out.numbers = n == 1 ? std::vector<double>{h5.number_attribute(name)}
                         : h5.number_attributes(name, static_cast<std::size_t>(n));
  } else {
    impl_->fail(obj, "neither a string nor numbers", "strings or numbers (docs/trace-format.md)");
  }
  return out;
}

std::vector<std::string> TraceReader::read_strings(const std::string& d) const { return impl_->h5->read_strings(d); }

std::vector<Aabb> TraceReader::local_boxes() const {
  const auto dims = shape("/bodies/local_aabb_min");
  if (dims.size() != 2 || dims[1] != 3 || dims[0] > trace_limits::kMaxBodies)
    impl_->fail("/bodies/local_aabb_min", fmt::format("shape {}", fmt::join(dims, " x ")),
                fmt::format("bodies x 3 with at most {} bodies", trace_limits::kMaxBodies));
  if (shape("/bodies/local_aabb_max") != dims)
    impl_->fail("/bodies/local_aabb_max", fmt::format("shape {}", fmt::join(shape("/bodies/local_aabb_max"), " x ")),
                fmt::format("the shape of /bodies/local_aabb_min ({})", fmt::join(dims, " x ")));
  const auto n = static_cast<std::int64_t>(dims[0]);
  const std::vector<float> lo = read_f32("/bodies/local_aabb_min", n);
  const std::vector<float> hi = read_f32("/bodies/local_aabb_max", n);
  if (lo.size() != static_cast<std::size_t>(3 * n) || hi.size() != lo.size())
    impl_->fail("/bodies/local_aabb_min", "not bodies x 3 floats", "bodies x 3 floats");
  std::vector<Aabb> out(static_cast<std::size_t>(n));
  for (std::size_t i = 0; i < out.size(); ++i) {
    out[i].min = Vec3{lo[3 * i], lo[3 * i + 1], lo[3 * i + 2]};
    out[i].max = Vec3{hi[3 * i], hi[3 * i + 1], hi[3 * i + 2]};
    for (int k = 0; k < 3; ++k) {
      // Each corner on its own, so a NaN in local_aabb_max is reported against it.
      const float lo_k = out[i].min[k], hi_k = out[i].max[k];
      if (!(std::fabs(lo_k) <= trace_limits::kMaxCoordinate))
        impl_->fail("/bodies/local_aabb_min", fmt::format("body {}: {}", i, lo_k),
                    fmt::format("finite, |value| <= {:g} m", trace_limits::kMaxCoordinate));
      if (!(std::fabs(hi_k) <= trace_limits::kMaxCoordinate))
        impl_->fail("/bodies/local_aabb_max", fmt::format("body {}: {}", i, hi_k),
                    fmt::format("finite, |value| <= {:g} m", trace_limits::kMaxCoordinate));
      if (!(lo_k <= hi_k))
        impl_->fail("/bodies/local_aabb_max", fmt::format("body {}: below /bodies/local_aabb_min", i),
                    "min <= max on every axis");
    }
  }
  return out;
}

}  // namespace octocd
