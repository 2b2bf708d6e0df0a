#pragma once
/// \file py_trace_file.hpp
/// octocd.Trace's compiled half: a trace read through octocd::TraceReader, the CLI's hardened
/// reader (docs/trace-format.md, "Security rules and limits").

#include "py_arrays.hpp"

namespace octocd::python_binding {

// ---- traces (octocd::TraceReader: the CLI's hardened reader) -------------------------

/// One trace open read-only through octocd::TraceReader (what octocd.Trace reads with):
/// regular files only; external links, external storage and virtual datasets refused;
/// every dataset checked for type and declared size before it is read; rows honour the
/// root attributes committed_frames / committed_states (complete_rows). Errors are
/// InputError "PATH: DATASET: PROBLEM; allowed: ..." as the CLI's.
class PyTraceFile {
 public:
  explicit PyTraceFile(const std::string& path) {
    py::gil_scoped_release release;
    reader_ = std::make_unique<TraceReader>(path);
  }
  int version() { return open().version(); }
  const std::string& path() { return open().path(); }
  bool has(const std::string& name) {
    BusyGuard busy(busy_, "this Trace");
    return open().has_dataset(name);
  }
  py::tuple shape(const std::string& name) {
    BusyGuard busy(busy_, "this Trace");
    return py::cast(open().shape(name));
  }
  std::string kind(const std::string& name) {
    BusyGuard busy(busy_, "this Trace");
    return open().element_kind(name);
  }
  std::int64_t complete_rows(const std::string& group) {
    BusyGuard busy(busy_, "this Trace");
    return open().complete_rows(group);
  }
  /// Rows [first, first + count) as a NumPy array of `dtype` ("f4", "f8" or "i8") of shape
  /// (count, dims[1:]...).
  py::array rows(const std::string& name, std::int64_t first, std::int64_t count, const std::string& dtype) {
    BusyGuard busy(busy_, "this Trace");
    TraceReader& r = open();
    const std::vector<std::uint64_t> dims = r.shape(name);
    if (dims.empty()) throw InputError(fmt::format("{}: {}: a scalar; allowed: a dataset of rank >= 1", r.path(), name));
    std::vector<py::ssize_t> shape{static_cast<py::ssize_t>(count)};
    for (std::size_t k = 1; k < dims.size(); ++k) shape.push_back(static_cast<py::ssize_t>(dims[k]));
    auto to_array = [&](auto&& v, auto tag) {
      using T = decltype(tag);
      py::array_t<T> a(shape);
      if (!v.empty()) std::memcpy(a.mutable_data(), v.data(), v.size() * sizeof(T));
      return py::array(a);
    };
    if (dtype == "f4") {
      std::vector<float> v;
      {
        py::gil_scoped_release release;
        v = r.read_f32_rows(name, first, count);
      }
      return to_array(v, float{});
    }
    if (dtype == "f8") {
      std::vector<double> v;
      {
        py::gil_scoped_release release;
        v = r.read_f64_rows(name, first, count);
      }
      return to_array(v, double{});
    }
    if (dtype == "i8") {
      std::vector<std::int64_t> v;
      {
        py::gil_scoped_release release;
        v = r.read_i64_rows(name, first, count);
      }
      return to_array(v, std::int64_t{});
    }
    throw InputError(fmt::format("dtype: '{}'; allowed: 'f4', 'f8' or 'i8'", dtype));
  }
  /// A root attribute as str, int (an integer-valued number), float or a list of them;
  /// None when absent.
  py::object attribute(const std::string& name) {
    BusyGuard busy(busy_, "this Trace");
    TraceReader& r = open();
    if (!r.has_attribute(name)) return py::none();
    const TraceAttribute a = r.attribute(name);
    auto number = [](double x) -> py::object {
      if (std::isfinite(x) && x == std::floor(x) && std::fabs(x) < 9007199254740992.0)
        return py::int_(static_cast<long long>(x));
      return py::float_(x);
    };
    if (a.is_string) {
      if (a.scalar) return py::str(a.strings.front());
      return py::cast(a.strings);
    }
    if (a.scalar) return number(a.numbers.front());
    py::list l;
    for (double x : a.numbers) l.append(number(x));
    return l;
  }
  std::vector<std::string> strings(const std::string& name) {
    BusyGuard busy(busy_, "this Trace");
    return open().read_strings(name);
  }
  void close() {
    BusyGuard busy(busy_, "this Trace");
    reader_.reset();
  }
  bool closed() const { return !reader_; }

 private:
  TraceReader& open() {
    if (!reader_) throw InputError("trace: closed; allowed: reading an open octocd.Trace (use it inside `with`)");
    return *reader_;
  }
  std::unique_ptr<TraceReader> reader_;
  std::atomic<bool> busy_{false};
};

}  // namespace octocd::python_binding
