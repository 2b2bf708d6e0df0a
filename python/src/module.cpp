// octocd._octocd: the compiled half of the `octocd` Python package (issue 21). The
// package's public names, their docstrings and the small conveniences (scene dicts,
// result objects) are in python/octocd/*.py (one module per job); this file converts arrays and calls
// the C++ API: build_model + the engines (octocd/engine.hpp), ExternalValidator and
// validate_external_trace (octocd/external.hpp).
//
// Arrays in: float arguments take any float dtype (float32 as is; float64 and others
// rounded to float32, as `octocd validate --trace-in` reads float64 datasets), integer
// arguments any integer dtype (range-checked); any other dtype (int for positions, float
// for pairs, bool, complex, object) is an InputError naming the argument. Non-contiguous
// arrays and plain sequences are converted (copied). Shapes are checked exactly and every
// float must be finite. Arrays out are fresh copies the caller owns.
//
// The GIL is released while an engine steps, while frames are judged and while a trace is
// read; an object already busy in another thread raises RuntimeError instead of racing.
// Long calls poll Python's signal handlers (PythonStop), or run on a helper thread while the
// caller does (Validator.observe, a long Engine.step), so Ctrl-C raises KeyboardInterrupt
// within a fraction of a second. Traces are read only through octocd::TraceReader, the
// hardened reader of the CLI (docs/trace-format.md, "Security rules and limits").
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <functional>
#include <future>
#include <limits>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include <fmt/format.h>

#include "octocd/atomic_file.hpp"
#include "octocd/cuda_world.hpp"
#include "octocd/engine.hpp"
#include "octocd/engines.hpp"
#include "octocd/error.hpp"
#include "octocd/setting_error.hpp"
#include "octocd/expect.hpp"
#include "octocd/junit.hpp"
#include "octocd/process_engines.hpp"
#include "octocd/results_table.hpp"
#include "octocd/external.hpp"
#include "octocd/reference_broadphase.hpp"
#include "octocd/scene.hpp"
#include "octocd/shards.hpp"
#include "octocd/text.hpp"
#include "octocd/trace_reader.hpp"
#include "octocd/validation.hpp"
#include "octocd/version.hpp"
#include "octocd/view.hpp"
#include "octocd/world.hpp"

namespace py = pybind11;
using namespace octocd;

namespace {

// ---- arrays in -----------------------------------------------------------------------

/// Shape text "(n, 3)" for messages; -1 dims print as their name.
std::string shape_text(const std::vector<py::ssize_t>& shape, const std::vector<std::string>& names) {
  std::string s = "(";
  for (std::size_t i = 0; i < shape.size(); ++i) {
    if (i) s += ", ";
    s += shape[i] >= 0 ? std::to_string(shape[i]) : names[i];
  }
  return s + (shape.size() == 1 ? ",)" : ")");
}

std::string actual_shape(const py::array& a) {
  std::vector<py::ssize_t> s(a.shape(), a.shape() + a.ndim());
  return shape_text(s, std::vector<std::string>(s.size()));
}

/// True on a little-endian machine (NumPy's byteorder '<' is then the native one).
constexpr bool kNativeLittle = __BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__;

/// Checks `obj` against `shape` (-1: any length) and returns a C-contiguous copy or view
/// of dtype T. `names` names each dimension in messages ("n", "P", ...); `what` is the
/// allowed content ("positions (m)").
template <class T>
py::array_t<T, py::array::c_style> take(py::handle obj, const std::string& arg, std::vector<py::ssize_t> shape,
                                        const std::vector<std::string>& names, const std::string& what) {
  constexpr bool is_float = std::is_floating_point_v<T>;
  const std::string allowed = fmt::format("{} {} array of shape {}", is_float ? "a float32" : "an integer", what,
                                          shape_text(shape, names));
  py::array arr;
  if (py::isinstance<py::array>(obj)) {
    arr = py::reinterpret_borrow<py::array>(obj);
    const char kind = arr.dtype().kind();
    // docs/python.md: float32 or float64 (not float16 or longer), integers of any width, in
    // the machine's byte order (a big-endian array is refused, not silently swapped).
    const std::string order = py::str(arr.dtype().attr("byteorder"));
    const py::ssize_t width = arr.dtype().itemsize();
    const bool ok = order != (kNativeLittle ? ">" : "<") &&
                    (is_float ? kind == 'f' && (width == 4 || width == 8) : (kind == 'i' || kind == 'u'));
    if (!ok && arr.size() > 0)  // an empty array of any dtype stands for 'none'
      throw InputError(fmt::format("{}: dtype {}{}; allowed: {}{}", arg, std::string(py::str(arr.dtype())),
                                   order == (kNativeLittle ? ">" : "<") ? " (big-endian)" : "", allowed,
                                   is_float ? " (float64 is rounded to float32), in the machine's byte order"
                                            : ", in the machine's byte order"));
  } else {
    // A plain sequence: converted to the dtype (numbers only).
    try {
      arr = py::array::ensure(obj);
    } catch (const py::error_already_set&) {
      arr = py::array();
    }
    if (!arr) throw InputError(fmt::format("{}: not an array; allowed: {}", arg, allowed));
    const char kind = arr.dtype().kind();
    const bool ok = is_float ? (kind == 'f' || kind == 'i' || kind == 'u') : (kind == 'i' || kind == 'u');
    if (!ok && arr.size() > 0)
      throw InputError(fmt::format("{}: a sequence of {}; allowed: {}", arg, std::string(py::str(arr.dtype())),
                                   allowed));
  }
  bool shape_ok = arr.ndim() == static_cast<py::ssize_t>(shape.size());
  for (std::size_t i = 0; shape_ok && i < shape.size(); ++i)
    shape_ok = shape[i] < 0 || arr.shape(static_cast<py::ssize_t>(i)) == shape[i];
  // An empty sequence ([] for "no pairs") stands for (0, k).
  if (!shape_ok && arr.size() == 0 && arr.ndim() == 1 && shape.size() == 2 && shape[0] < 0) {
    arr = py::array(py::dtype::of<T>(), std::vector<py::ssize_t>{0, shape[1]});
    shape_ok = true;
  }
  if (!shape_ok)
    throw InputError(fmt::format("{}: shape {}; allowed: {}", arg, actual_shape(arr), allowed));
  if constexpr (!is_float) {
    // Range-check in int64 before narrowing (uint64 above 2^63 is refused too).
    if (arr.dtype().kind() == 'u' && arr.dtype().itemsize() == 8) {
      auto u = py::array_t<std::uint64_t, py::array::c_style | py::array::forcecast>::ensure(arr);
      for (py::ssize_t i = 0; i < u.size(); ++i)
        if (u.data()[i] > 0xffffffffull)
          throw InputError(fmt::format("{}: element {} is {}; allowed: body indices in [0, 2^32)", arg, i,
                                       u.data()[i]));
    } else {
      auto s = py::array_t<std::int64_t, py::array::c_style | py::array::forcecast>::ensure(arr);
      for (py::ssize_t i = 0; i < s.size(); ++i)
        if (s.data()[i] < 0 || s.data()[i] > 0xffffffffll)
          throw InputError(fmt::format("{}: element {} is {}; allowed: body indices in [0, 2^32)", arg, i,
                                       s.data()[i]));
    }
  }
  auto out = py::array_t<T, py::array::c_style | py::array::forcecast>::ensure(arr);
  if (!out) throw InputError(fmt::format("{}: cannot be converted; allowed: {}", arg, allowed));
  if constexpr (is_float) {
    const T* d = out.data();
    const py::ssize_t row = out.ndim() > 1 ? out.size() / std::max<py::ssize_t>(out.shape(0), 1) : 1;
    for (py::ssize_t i = 0; i < out.size(); ++i)
      if (!std::isfinite(d[i]))
        throw InputError(fmt::format("{}: row {} holds {} (as float32); allowed: finite values", arg, i / row,
                                     static_cast<double>(d[i])));
  }
  return out;
}

/// (n, 3) floats as Vec3s.
std::vector<Vec3> vec3s(py::handle obj, const std::string& arg, py::ssize_t n, const std::string& what) {
  auto a = take<float>(obj, arg, {n, 3}, {"n", "3"}, what);
  std::vector<Vec3> v(static_cast<std::size_t>(a.shape(0)));
  if (!v.empty()) std::memcpy(static_cast<void*>(v.data()), a.data(), v.size() * sizeof(Vec3));
  return v;
}

/// (n, 4) floats (w, x, y, z) as Quats.
std::vector<Quat> quats(py::handle obj, const std::string& arg, py::ssize_t n) {
  auto a = take<float>(obj, arg, {n, 4}, {"n", "4"}, "unit quaternion (w, x, y, z)");
  std::vector<Quat> q(static_cast<std::size_t>(a.shape(0)));
  for (std::size_t i = 0; i < q.size(); ++i) {
    const float* r = a.data() + 4 * i;
    q[i] = {r[0], r[1], r[2], r[3]};
    if (std::fabs(norm(q[i]) - 1.0f) > 1e-3f)
      throw InputError(fmt::format("{}: row {} has norm {}; allowed: unit quaternions (w, x, y, z), |q| within "
                                   "1e-3 of 1",
                                   arg, i, norm(q[i])));
  }
  return q;
}

/// (n, 2, 3) floats as Aabbs ([:, 0] = min, [:, 1] = max).
std::vector<Aabb> boxes(py::handle obj, const std::string& arg, py::ssize_t n, const std::string& what) {
  auto a = take<float>(obj, arg, {n, 2, 3}, {"n", "2", "3"}, what);
  std::vector<Aabb> b(static_cast<std::size_t>(a.shape(0)));
  if (!b.empty()) std::memcpy(static_cast<void*>(b.data()), a.data(), b.size() * sizeof(Aabb));
  for (std::size_t i = 0; i < b.size(); ++i)
    if (!(b[i].min.x <= b[i].max.x && b[i].min.y <= b[i].max.y && b[i].min.z <= b[i].max.z))
      throw InputError(fmt::format("{}: row {}: min above max; allowed: [:, 0] = min <= [:, 1] = max", arg, i));
  return b;
}

/// (P, 2) integers as Pairs.
std::vector<Pair> pairs(py::handle obj, const std::string& arg) {
  auto a = take<std::uint32_t>(obj, arg, {-1, 2}, {"P", "2"}, "body-index pair (a, b), a < b,");
  std::vector<Pair> p(static_cast<std::size_t>(a.shape(0)));
  if (!p.empty()) std::memcpy(static_cast<void*>(p.data()), a.data(), p.size() * sizeof(Pair));
  return p;
}

/// (C,) floats.
std::vector<float> floats(py::handle obj, const std::string& arg, py::ssize_t n, const std::string& what) {
  auto a = take<float>(obj, arg, {n}, {n >= 0 ? "" : "C"}, what);
  return std::vector<float>(a.data(), a.data() + a.size());
}

// ---- arrays out ----------------------------------------------------------------------

py::array_t<float> out_vec3(const std::vector<Vec3>& v) {
  py::array_t<float> a({static_cast<py::ssize_t>(v.size()), py::ssize_t{3}});
  if (!v.empty()) std::memcpy(a.mutable_data(), v.data(), v.size() * sizeof(Vec3));
  return a;
}
py::object out_vec3_or_none(const std::vector<Vec3>& v) { return v.empty() ? py::object(py::none()) : out_vec3(v); }
py::object out_quat_or_none(const std::vector<Quat>& q) {
  if (q.empty()) return py::none();
  py::array_t<float> a({static_cast<py::ssize_t>(q.size()), py::ssize_t{4}});
  float* d = a.mutable_data();
  for (std::size_t i = 0; i < q.size(); ++i) {
    d[4 * i] = q[i].w, d[4 * i + 1] = q[i].x, d[4 * i + 2] = q[i].y, d[4 * i + 3] = q[i].z;
  }
  return a;
}
py::array_t<float> out_boxes(const std::vector<Aabb>& b) {
  py::array_t<float> a({static_cast<py::ssize_t>(b.size()), py::ssize_t{2}, py::ssize_t{3}});
  if (!b.empty()) std::memcpy(a.mutable_data(), b.data(), b.size() * sizeof(Aabb));
  return a;
}
py::array_t<std::int32_t> out_pairs(const std::vector<Pair>& p) {
  py::array_t<std::int32_t> a({static_cast<py::ssize_t>(p.size()), py::ssize_t{2}});
  std::int32_t* d = a.mutable_data();
  for (std::size_t i = 0; i < p.size(); ++i) {
    d[2 * i] = static_cast<std::int32_t>(p[i].a);
    d[2 * i + 1] = static_cast<std::int32_t>(p[i].b);
  }
  return a;
}

py::dict out_contacts(const std::vector<ContactRecord>& cs, bool terms, bool points) {
  const auto c = static_cast<py::ssize_t>(cs.size());
  std::vector<Pair> pr;
  py::array_t<float> depth(c), jn(c), jt(c);
  py::array_t<std::int32_t> axis(c);
  std::vector<Vec3> normal, v_a, v_b, dx_a, dx_b, dv_a, dv_b, point;
  for (py::ssize_t i = 0; i < c; ++i) {
    const ContactRecord& r = cs[static_cast<std::size_t>(i)];
    pr.push_back(r.pair);
    normal.push_back(r.normal);
    depth.mutable_data()[i] = r.depth;
    jn.mutable_data()[i] = r.jn;
    jt.mutable_data()[i] = r.jt;
    axis.mutable_data()[i] = r.axis;
    v_a.push_back(r.v_a), v_b.push_back(r.v_b), dx_a.push_back(r.dx_a), dx_b.push_back(r.dx_b);
    dv_a.push_back(r.dv_a), dv_b.push_back(r.dv_b), point.push_back(r.point);
  }
  py::dict d;
  d["pair"] = out_pairs(pr);
  d["normal"] = out_vec3(normal);
  d["depth"] = depth;
  d["jn"] = jn;
  d["jt"] = jt;
  if (terms) {
    d["axis"] = axis;
    d["v_a"] = out_vec3(v_a), d["v_b"] = out_vec3(v_b);
    d["dx_a"] = out_vec3(dx_a), d["dx_b"] = out_vec3(dx_b);
    d["dv_a"] = out_vec3(dv_a), d["dv_b"] = out_vec3(dv_b);
  }
  if (points) d["point"] = out_vec3(point);
  return d;
}

py::dict out_metrics(const FrameMetrics& m, const Engine* engine) {
  py::dict d;
  d["frame"] = m.frame;
  d["time"] = m.time;
  d["step_ms"] = m.step_ms;
  py::dict stages;
  for (int s = 0; s < static_cast<int>(Stage::Count); ++s) {
    const auto st = static_cast<Stage>(s);
    stages[stage_name(st)] = (engine && !engine->has_stage(st)) ? py::object(py::none()) : py::float_(m.stage_ms[s]);
  }
  d["stage_ms"] = stages;
  d["cell_candidates"] = m.cell_candidates;
  d["aabb_pairs"] = m.aabb_pairs;
  d["dynamic_pairs"] = m.dynamic_pairs;
  d["box_tests"] = m.box_tests;
  d["box_pairs"] = m.box_pairs;
  d["vertex_tests"] = m.vertex_tests;
  d["contacts"] = m.contacts;
  d["penetration_mean"] = m.penetration_mean;
  d["penetration_max"] = m.penetration_max;
  d["penetration_share_above_slop"] = m.penetration_share_above_slop;
  d["kinetic_energy"] = m.kinetic_energy;
  d["momentum"] = py::make_tuple(m.momentum[0], m.momentum[1], m.momentum[2]);
  d["memory_bytes"] = m.memory_bytes;
  return d;
}

/// The rows as dicts (octocd.ValidationResult's fields); causes normalised by
/// failure_causes (octocd/expect.hpp). With `report`, a row whose every failing cause is
/// expected has verdict "expected".
py::list out_results(const std::vector<ValidationResult>& rs, const ExpectationReport* report = nullptr) {
  py::list l;
  for (const ValidationResult& r : rs) {
    py::dict d;
    d["tier"] = tier_name(r.tier);
    d["name"] = r.name;
    d["figure"] = r.figure;
    d["measured"] = r.measured;
    d["bound"] = r.bound;
    d["passed"] = r.pass;
    d["applicable"] = r.applicable;
    const std::string verdict = row_verdict(r, report);
    d["verdict"] = verdict == "fail" ? "FAIL" : verdict;
    d["detail"] = r.detail;
    d["tolerances"] = r.tolerances;
    d["judged"] = r.judged;
    d["seconds"] = r.seconds;
    py::list causes;
    for (const ValidationCause& c : failure_causes(r)) {
      py::dict cd;
      cd["name"] = c.name;
      cd["unit"] = c.unit;
      cd["count"] = c.count;
      cd["worst"] = c.worst;
      py::list examples;
      for (const ValidationExample& x : c.examples) {
        py::dict xd;
        xd["frame"] = x.frame;
        xd["item"] = x.item;
        xd["figure"] = x.figure;
        xd["text"] = x.text;
        examples.append(xd);
      }
      cd["examples"] = examples;
      cd["items"] = c.items;
      cd["items_complete"] = c.items_complete;
      causes.append(cd);
    }
    d["causes"] = causes;
    l.append(d);
  }
  return l;
}

/// The outcomes of matching expectations, as dicts (octocd.ExpectationOutcome's fields).
py::list out_outcomes(const ExpectationReport& report) {
  py::list l;
  for (const ExpectationOutcome& o : report.outcomes) {
    py::dict d;
    d["outcome"] = outcome_name(o.kind);
    d["row"] = o.row;
    d["cause"] = o.cause;
    d["unit"] = o.unit;
    d["count"] = o.count;
    d["worst"] = o.worst;
    d["allowed"] = o.allowed;
    d["outside"] = o.outside;
    d["reason"] = o.reason;
    d["text"] = o.text;
    l.append(d);
  }
  return l;
}

/// Marks an object busy while the GIL is released; a second thread gets RuntimeError.
class BusyGuard {
 public:
  BusyGuard(std::atomic<bool>& flag, const char* what) : flag_(flag) {
    if (flag_.exchange(true))
      throw RuntimeError(fmt::format("{} is busy in another thread; allowed: one call at a time per object", what));
  }
  ~BusyGuard() { flag_ = false; }
  BusyGuard(const BusyGuard&) = delete;
  BusyGuard& operator=(const BusyGuard&) = delete;

 private:
  std::atomic<bool>& flag_;
};

/// Work run on a helper thread while the calling thread, the GIL released, runs Python's
/// signal handlers every 20 ms: Ctrl-C raises KeyboardInterrupt at once, whatever loop the
/// work is in. Work a Ctrl-C cut short stays in flight (it completes on its thread) and
/// settle() waits for it before the object is used again. Declare it after what the work
/// uses: destroyed first, the in-flight future's destructor waits for the work.
class InterruptibleWork {
 public:
  /// `on_interrupt` (may be empty) runs when a signal handler raised, before the exception
  /// propagates (e.g. a stop flag the work polls).
  explicit InterruptibleWork(std::function<void()> on_interrupt = {}) : on_interrupt_(std::move(on_interrupt)) {}

  /// Waits for `f`; when a signal handler raises, `f` becomes the work in flight and the
  /// exception (py::error_already_set) propagates. The caller then calls f.get().
  void wait(std::future<void>& f) {
    for (;;) {
      bool ready = false;
      {
        py::gil_scoped_release release;
        ready = f.wait_for(std::chrono::milliseconds(20)) == std::future_status::ready;
      }
      if (ready) return;
      if (PyErr_CheckSignals() != 0) {
        if (on_interrupt_) on_interrupt_();
        inflight_ = std::move(f);
        throw py::error_already_set();
      }
    }
  }

  /// Waits (Ctrl-C honoured) for work an earlier Ctrl-C left in flight; raises its error,
  /// if any.
  void settle() {
    if (!inflight_.valid()) return;
    std::future<void> f = std::move(inflight_);
    wait(f);
    f.get();
  }

 private:
  std::function<void()> on_interrupt_;
  std::future<void> inflight_;
};

/// Ctrl-C for C++ work that runs without the GIL: poll() is the stop callback of the core's
/// loops (ValidationOptions::stop, ExternalOptions::stop, validate_external_trace). At
/// most every 20 ms it takes the GIL and runs Python's signal handlers
/// (PyErr_CheckSignals); once one raised (KeyboardInterrupt from SIGINT), poll() returns
/// true from then on and rethrow() raises that exception in the calling thread. Live on
/// the stack of the call, with the GIL held at construction and at rethrow(). Thread-safe
/// (the validators may poll from helper threads; Python runs handlers on the main thread
/// only, which polls too).
class PythonStop {
 public:
  bool poll() {
    if (stopped_.load()) return true;
    const std::lock_guard<std::mutex> lock(mutex_);
    const auto now = std::chrono::steady_clock::now();
    if (now - last_ < std::chrono::milliseconds(20)) return false;
    last_ = now;
    const py::gil_scoped_acquire gil;
    if (PyErr_CheckSignals() != 0) {
      error_ = std::make_unique<py::error_already_set>();
      stopped_ = true;
    }
    return stopped_.load();
  }
  std::function<bool()> callback() {
    return [this] { return poll(); };
  }
  bool stopped() const { return stopped_.load(); }
  /// Raises the exception a signal handler raised (the GIL held); no-op when none.
  void rethrow() {
    if (error_) {
      error_->restore();
      error_.reset();
      throw py::error_already_set();
    }
  }

 private:
  std::mutex mutex_;
  std::chrono::steady_clock::time_point last_{};
  std::atomic<bool> stopped_{false};
  std::unique_ptr<py::error_already_set> error_;
};

/// `arg` names a dict whose keys must be strings (refuses 1, b"mu", ...: a key that is not
/// text would otherwise print like another one and silently win).
void string_keys(const py::dict& d, const std::string& arg) {
  for (auto item : d)
    if (!py::isinstance<py::str>(item.first))
      throw InputError(fmt::format("{}: key {} is a {}; allowed: string keys (each at most once)", arg,
                                   std::string(py::repr(item.first)),
                                   std::string(py::str(item.first.get_type().attr("__name__")))));
}

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

// ---- scenes and engines --------------------------------------------------------------

/// A loaded scene (shared: several engines can be built from one).
struct PyScene {
  std::shared_ptr<const Scene> scene;
};

/// The engines this build has (octocd.engines), in engine_infos() order: read on each call,
/// so that an engines file loaded after import (octocd.load_engines_file) is listed.
std::vector<std::string> built_engines() { return built_engine_names(); }

/// octocd.load_engines_file: names the process's engines file (octocd/process_engines.hpp,
/// set_engines_file) and reads the registry at once, so that a malformed file is an
/// InputError here ("FILE: FIELD: PROBLEM; allowed: ...") and its engines are listed by
/// octocd.engines. Throws RuntimeError when the registry was read already with another
/// file (one engines file per process), InputError for a path that is not a file.
std::vector<std::string> load_engines_file(const std::string& path) {
  if (path.empty()) throw InputError("path: ''; allowed: the path of an engines file (docs/bring-your-engine.md)");
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec))
    throw InputError(fmt::format("{}: not a readable file; allowed: an engines file (JSON, docs/bring-your-engine.md)",
                                 path));
  const std::string file = std::filesystem::absolute(path, ec).lexically_normal().string();
  try {
    set_engines_file(file);
  } catch (const RuntimeError&) {
    const std::vector<std::string> read = engines_files_read();
    throw RuntimeError(fmt::format("octocd.load_engines_file('{}'): the engine registry was read already (engines "
                                   "files: {}); allowed: one engines file per process, loaded before the first "
                                   "engine is looked up (octocd.engines, octocd.Engine)",
                                   path, read.empty() ? std::string("none") : fmt::format("{}", fmt::join(read, ", "))));
  }
  return built_engine_names();
}

std::string join(const std::vector<std::string>& v, const char* sep = ", ") {
  std::string s;
  for (const auto& x : v) s += (s.empty() ? "" : sep) + x;
  return s;
}

class PyEngine {
 public:
  PyEngine(const PyScene& scene, const std::string& engine, const std::optional<std::string>& broadphase,
           const std::optional<std::string>& midphase, bool record, const EngineSettingItems& settings) {
    const EngineInfo* info = find_engine_info(engine);
    const std::vector<std::string> names = built_engines();
    if (info == nullptr)
      throw InputError(fmt::format("engine: unknown engine '{}'; allowed: {}", printable(engine), join(names)));
    if (!engine_built(*info))
      throw InputError(fmt::format("engine: '{}' is not built in this octocd (configured with OCTOCD_CUDA=OFF "
                                   "or without nvcc); allowed: {}",
                                   engine, join(names)));
    EngineOptions options;
    options.broadphase = broadphase.value_or("");
    options.midphase = midphase.value_or("");
    // Every engine's items are checked whatever the engine runs: a bad key is an input error.
    check_engine_settings(settings, python_argument_names());
    options.settings = settings;
    Scene sc = *scene.scene;
    apply_engine_options(sc, *info, options, python_argument_names());
    if (const std::string why = engine_unavailable(*info); !why.empty()) {
      std::vector<std::string> others;
      for (const std::string& n : names)
        if (n != engine) others.push_back("'" + n + "'");
      throw RuntimeError(fmt::format("engine '{}': {}; allowed: engine={} on this machine", engine, why,
                                     join(others, " or ")));
    }
    model_ = build_model(sc);
    engine_ = make_engine(engine, model_, options.settings);
    if (record && engine_->can_record()) engine_->set_recording(true);
    recording_ = record && engine_->can_record();
  }

  py::dict step(long n) {
    if (n < 0) throw InputError(fmt::format("n: {}; allowed: n >= 0 steps", n));
    BusyGuard busy(busy_, "this Engine");
    settle();
    // Nothing but step() and frame() runs between the steps below, so when they run inline
    // they are promised (Engine::plan_steps: the cuda engine's resident small step then runs
    // up to 64 a host round trip). A plan ends (end_plan) when a step turns slow (the next
    // ones may run on the helper thread), on an error or interrupt, and at the end.
    bool planned = false;
    auto end_plan = [&] {
      if (!planned) return;
      planned = false;
      engine_->plan_steps(0);
      py::gil_scoped_release release;
      while (engine_->steps_ahead() > 0) engine_->step();  // already run: no new work
      frames_.store(engine_->frame());
    };
    try {
      for (long i = 0; i < n; ++i) {
        if (!planned && !recording_ && n - i > 1 && last_step_ms_ < kInlineStepMs) {
          engine_->plan_steps(n - i);
          planned = true;
        }
        const auto t0 = std::chrono::steady_clock::now();
        if (planned || last_step_ms_ < kInlineStepMs) {
          py::gil_scoped_release release;
          engine_->step();
        } else {
          step_in_background();
        }
        last_step_ms_ = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
        frames_.store(engine_->frame());  // `frame`: the whole steps done, readable from another thread
        if (last_step_ms_ >= kInlineStepMs) end_plan();
        // Ctrl-C between steps: KeyboardInterrupt with the engine at its last whole step.
        if (PyErr_CheckSignals() != 0) throw py::error_already_set();
      }
    } catch (...) {
      end_plan();
      throw;
    }
    end_plan();
    return out_metrics(engine_->last_metrics(), engine_.get());
  }

  py::dict last_frame() {
    BusyGuard busy(busy_, "this Engine");
    settle();
    const Engine& e = *engine_;
    py::dict d;
    d["frame"] = e.frame();
    d["metrics"] = out_metrics(e.last_metrics(), &e);
    if (recording_ && e.frame() > 0) {
      const FrameRecord& r = e.record();
      d["x_pre"] = out_vec3(r.x_pre), d["v_pre"] = out_vec3(r.v_pre);
      d["x_post"] = out_vec3(r.x_post), d["v_post"] = out_vec3(r.v_post);
      d["aabbs"] = out_boxes(r.aabbs);
      d["pairs"] = r.has_pairs ? py::object(out_pairs(r.pairs)) : py::object(py::none());
      d["confirmed"] = out_pairs(r.confirmed);
      d["contacts"] = out_contacts(r.contacts, r.has_contact_terms, r.has_points);
      d["q_pre"] = out_quat_or_none(r.q_pre), d["q_post"] = out_quat_or_none(r.q_post);
      d["w_pre"] = out_vec3_or_none(r.w_pre), d["w_post"] = out_vec3_or_none(r.w_post);
      d["x_det"] = out_vec3_or_none(r.x_det), d["q_det"] = out_quat_or_none(r.q_det);
      d["manifolds"] = r.manifolds;
    } else {
      // Not recording (record=False, or `bullet`): the state after the step and the
      // engine's own contacts only.
      d["x_post"] = out_vec3(e.state().x), d["v_post"] = out_vec3(e.state().v);
      d["contacts"] = out_contacts(e.contacts(), !e.contacts().empty(), false);
    }
    return d;
  }

  py::array_t<float> positions() {
    BusyGuard busy(busy_, "this Engine");
    settle();
    return out_vec3(engine_->state().x);
  }
  py::array_t<float> velocities() {
    BusyGuard busy(busy_, "this Engine");
    settle();
    return out_vec3(engine_->state().v);
  }
  std::uint64_t state_hash() {
    BusyGuard busy(busy_, "this Engine");
    settle();
    return engine_->state_hash();
  }
  py::array_t<float> inverse_masses() const {
    const auto& w = engine_->state().w;
    py::array_t<float> a(static_cast<py::ssize_t>(w.size()));
    if (!w.empty()) std::memcpy(a.mutable_data(), w.data(), w.size() * sizeof(float));
    return a;
  }
  py::array_t<float> local_boxes() const {
    std::vector<Aabb> b;
    for (std::size_t i = 0; i < model_->bodies.size(); ++i) b.push_back(model_->local_box(i));
    return out_boxes(b);
  }
  py::list groups() const {
    py::list l;
    for (const BodyInfo& b : model_->bodies) l.append(b.group);
    return l;
  }

  void set_state(py::handle x, py::handle v) {
    const auto n = static_cast<py::ssize_t>(engine_->state().size());
    BodyState s = engine_->state();
    s.x = vec3s(x, "positions", n, "positions (m)");
    s.v = vec3s(v, "velocities", n, "velocities (m/s)");
    // The scene's limits (docs/scenes.md, "Limits"): the engines' float32 arithmetic
    // stays finite and keeps the slop within them.
    const auto bound = [](const std::vector<Vec3>& xs, const char* arg, double limit, const char* unit) {
      for (std::size_t i = 0; i < xs.size(); ++i)
        for (int k = 0; k < 3; ++k)
          if (!(std::fabs(xs[i][k]) <= limit))
            throw InputError(fmt::format("{}: row {} holds {}; allowed: |component| <= {:g} {} (docs/scenes.md, "
                                         "Limits)",
                                         arg, i, xs[i][k], limit, unit));
    };
    bound(s.x, "positions", limits::kMaxCoordinate, "m");
    bound(s.v, "velocities", limits::kMaxSpeed, "m/s");
    BusyGuard busy(busy_, "this Engine");
    settle();
    engine_->set_state(s);
  }

  const Engine& engine() const { return *engine_; }
  bool recording() const { return recording_; }
  /// Steps done (Engine::frame() after the last whole step); safe to read while another
  /// thread is inside step().
  std::int64_t frames() const { return frames_.load(); }

 private:
  /// A step is run on a helper thread, the caller polling Ctrl-C every 20 ms, unless the
  /// previous step took less than this (ms): the threshold keeps a small scene's steps
  /// free of a thread start (tens of microseconds) while a step of a large one (10^6
  /// bodies on the CPU: seconds) is cut short within a fraction of a second.
  static constexpr double kInlineStepMs = 50.0;

  /// One step on a helper thread; Ctrl-C raises KeyboardInterrupt at once and leaves the
  /// step to complete in the background (work_): the engine stays at a whole step.
  void step_in_background() {
    std::future<void> step = std::async(std::launch::async, [this] {
      engine_->step();
      frames_.store(engine_->frame());
    });
    work_.wait(step);
    step.get();  // the step's error, if any, raised here
  }
  /// Before any call that reads or changes the engine: a step an earlier Ctrl-C left
  /// completing in the background ends first (InterruptibleWork::settle).
  void settle() { work_.settle(); }

  std::shared_ptr<const Model> model_;
  std::unique_ptr<Engine> engine_;
  bool recording_ = false;
  std::atomic<bool> busy_{false};
  std::atomic<std::int64_t> frames_{0};
  double last_step_ms_ = std::numeric_limits<double>::infinity();  // the first step runs on the helper
  /// The steps run on a helper thread, one cut short by Ctrl-C completing there (declared
  /// after engine_: destroyed first, it waits for the step). A process engine's step is
  /// stopped by Ctrl-C (its process tree ended within 0.2 s; the step fails, settle()
  /// raises that): the caller's KeyboardInterrupt does not wait for the process's timeout_s.
  InterruptibleWork work_{[this] { (void)cancel_process_engine_step(*engine_); }};
};

// ---- judging another engine ----------------------------------------------------------

MaterialCombine parse_combine(const std::string& s) {
  for (MaterialCombine c : {MaterialCombine::Product, MaterialCombine::Min, MaterialCombine::Max,
                            MaterialCombine::Average, MaterialCombine::Geometric})
    if (s == material_combine_name(c)) return c;
  throw InputError(fmt::format("physics['combine']: '{}'; allowed: product, min, max, average, geometric", s));
}

/// What an engine that declares nothing gets, as a trace without declarations: the
/// integrator and the contact model undeclared (every admissible value,
/// docs/validation.md, "Undeclared: every admissible value").
PhysicsBodies undeclared_physics() {
  PhysicsBodies p;
  p.integrator = PhysicsBodies::Integrator::Undeclared;
  p.contact_model = PhysicsBodies::ContactModel::Undeclared;
  return p;
}

/// PhysicsBodies from a dict (keys as the C++ member names).
PhysicsBodies parse_physics(const py::dict& d, py::ssize_t n) {
  PhysicsBodies p = undeclared_physics();
  string_keys(d, "physics");
  for (auto item : d) {
    const std::string key = py::str(item.first);
    const py::handle v = item.second;
    const std::string arg = "physics['" + key + "']";
    auto number = [&](double lo) {
      double x = 0;
      if (py::isinstance<py::bool_>(v) || !(py::isinstance<py::float_>(v) || py::isinstance<py::int_>(v) ||
                                            py::hasattr(v, "__float__")))
        throw InputError(fmt::format("{}: {} ({}); allowed: a finite number >= {}", arg, std::string(py::repr(v)),
                                     std::string(py::str(v.get_type().attr("__name__"))), lo));
      try {
        x = v.cast<double>();
      } catch (const py::cast_error&) {
        throw InputError(fmt::format("{}: not a number; allowed: a finite number >= {}", arg, lo));
      }
      if (!std::isfinite(x) || x < lo)
        throw InputError(fmt::format("{}: {}; allowed: a finite number >= {}", arg, x, lo));
      return x;
    };
    // True or False only (also NumPy's bool_): "yes", 2 or None are refused, not cast.
    auto flag = [&]() {
      const bool is_bool = py::isinstance<py::bool_>(v) || std::string(py::str(v.get_type().attr("__name__"))) == "bool_";
      if (!is_bool)
        throw InputError(fmt::format("{}: {} ({}); allowed: True or False", arg, std::string(py::repr(v)),
                                     std::string(py::str(v.get_type().attr("__name__")))));
      return v.cast<bool>();
    };
    auto text = [&]() {
      if (!py::isinstance<py::str>(v))
        throw InputError(fmt::format("{}: {} ({}); allowed: a string", arg, std::string(py::repr(v)),
                                     std::string(py::str(v.get_type().attr("__name__")))));
      return std::string(py::str(v));
    };
    if (key == "inertia") {
      auto a = take<float>(v, arg, {n, 3, 3}, {"n", "3", "3"}, "body-frame inertia tensor (kg m^2)");
      p.inertia.resize(static_cast<std::size_t>(n));
      for (std::size_t i = 0; i < p.inertia.size(); ++i)
        for (int k = 0; k < 9; ++k) p.inertia[i][static_cast<std::size_t>(k)] = a.data()[9 * i + static_cast<std::size_t>(k)];
    } else if (key == "body_friction" || key == "body_restitution") {
      std::vector<float> f = floats(v, arg, n, "per-body value (>= 0)");
      (key == "body_friction" ? p.body_friction : p.body_restitution) = f;
    } else if (key == "mu") {
      p.mu = number(0.0);
    } else if (key == "restitution") {
      p.restitution = number(0.0);
    } else if (key == "contact_margin") {
      p.contact_margin = number(0.0);
    } else if (key == "slop") {
      p.slop = number(0.0);
    } else if (key == "combine") {
      p.combine = parse_combine(text());
    } else if (key == "theta_margin") {
      p.theta_margin = flag();
    } else if (key == "broadphase_exact") {
      p.broadphase_exact = flag();
    } else if (key == "contact_geometry") {
      const std::string g = text();
      if (g == "shape") p.contact_geometry = ContactGeometry::Shape;
      else if (g == "aabb") p.contact_geometry = ContactGeometry::Aabb;
      else throw InputError(fmt::format("{}: '{}'; allowed: 'shape' or 'aabb'", arg, g));
    } else {
      throw InputError(fmt::format("physics: unknown key '{}'; allowed: inertia, body_friction, body_restitution, "
                                   "mu, restitution, combine, contact_margin, theta_margin, broadphase_exact, "
                                   "contact_geometry, slop",
                                   key));
    }
  }
  return p;
}

void apply_tolerances(ExternalOptions& o, const py::object& tolerances) {
  if (tolerances.is_none()) return;
  if (!py::isinstance<py::dict>(tolerances))
    throw InputError("tolerances: not a dict; allowed: {name: value} with names of octocd.tolerances()");
  string_keys(py::reinterpret_borrow<py::dict>(tolerances), "tolerances");
  for (auto item : py::reinterpret_borrow<py::dict>(tolerances)) {
    const std::string name = py::str(item.first);
    double value = 0;
    if (py::isinstance<py::bool_>(item.second) || py::isinstance<py::str>(item.second))
      throw InputError(fmt::format("tolerances['{}']: {}; allowed: a finite number >= 0", name,
                                   std::string(py::repr(item.second))));
    try {
      value = item.second.cast<double>();
    } catch (const py::cast_error&) {
      throw InputError(fmt::format("tolerances['{}']: not a number; allowed: a finite number >= 0", name));
    }
    try {
      set_tolerance(o.tol, name, value);
    } catch (const SettingError& e) {
      throw InputError(fmt::format("tolerances['{}']: {}", name, e.describe()));
    }
    o.overridden.push_back(name);
  }
}

/// A mesh given to Validator(meshes=...) that FCL can build: at least 3 vertices, at least
/// one triangle, and at least one triangle of non-zero area (FCL's traversal reads past a
/// mesh without triangles: SIGSEGV). `arg` names it ("meshes[3]").
void check_mesh_argument(const Mesh& mesh, const std::string& arg) {
  const std::string allowed =
      "(V x 3 float vertices, V >= 3; T x 3 integer triangles, T >= 1, at least one of non-zero area)";
  if (mesh.vertices.size() < 3)
    throw InputError(fmt::format("{}[0]: {} vertices; allowed: a triangle mesh {}", arg, mesh.vertices.size(), allowed));
  if (mesh.triangles.empty())
    throw InputError(fmt::format("{}[1]: no triangles; allowed: a triangle mesh {}", arg, allowed));
  for (const auto& t : mesh.triangles) {
    const Vec3 a = mesh.vertices[t[0]], b = mesh.vertices[t[1]], c = mesh.vertices[t[2]];
    if (length(cross(b - a, c - a)) > 0.0f) return;
  }
  throw InputError(fmt::format("{}: every triangle is degenerate (zero area: repeated or collinear vertices); "
                               "allowed: a triangle mesh {}",
                               arg, allowed));
}

/// Magnitudes the validators' float32 arithmetic stays finite with: the bounds of a
/// trace's values (docs/trace-format.md, "Security rules and limits"), as the CLI's
/// `validate --trace-in` checks them.
void check_coordinates(const std::vector<Vec3>& xs, const char* arg, double limit, const char* what) {
  for (std::size_t i = 0; i < xs.size(); ++i)
    for (int k = 0; k < 3; ++k)
      if (!(std::fabs(xs[i][k]) <= limit))
        throw InputError(fmt::format("{}: row {} holds {}; allowed: {} with |component| <= {:g}", arg, i, xs[i][k],
                                     what, limit));
}

class PyValidator {
 public:
  PyValidator(py::object local_boxes, py::object inverse_mass, const std::string& scene_json, float dt,
              py::object gravity, py::object domain, py::object meshes, py::object physics,
              const std::string& engine, bool against_fcl, bool spec6_response, py::object tolerances) {
    ExternalBodies b;
    b.scene_json = scene_json;
    b.dt = dt;
    if (!local_boxes.is_none()) {
      if (py::hasattr(local_boxes, "__len__") && py::len(local_boxes) > trace_limits::kMaxBodies)
        throw_body_cap("local_boxes", py::len(local_boxes));
      b.local_boxes = boxes(local_boxes, "local_boxes", -1, "local box (m)");
      for (std::size_t i = 0; i < b.local_boxes.size(); ++i)
        for (int k = 0; k < 3; ++k)
          for (const float c : {b.local_boxes[i].min[k], b.local_boxes[i].max[k]})
            if (!(std::fabs(c) <= trace_limits::kMaxCoordinate))
              throw InputError(fmt::format("local_boxes: row {} holds {}; allowed: local box corners (m) with "
                                           "|component| <= {:g}",
                                           i, c, trace_limits::kMaxCoordinate));
    }
    const auto n = static_cast<py::ssize_t>(b.local_boxes.size());
    if (!inverse_mass.is_none())
      b.inverse_mass = floats(inverse_mass, "inverse_mass", b.local_boxes.empty() ? -1 : n, "inverse mass (1/kg)");
    if (!gravity.is_none()) {
      auto g = take<float>(gravity, "gravity", {3}, {"3"}, "gravity (m/s^2)");
      b.gravity = {g.data()[0], g.data()[1], g.data()[2]};
    }
    if (!domain.is_none()) {
      auto d = boxes(py::array(take<float>(domain, "domain", {2, 3}, {"2", "3"}, "domain [min, max] (m)"))
                         .attr("reshape")(1, 2, 3),
                     "domain", 1, "domain [min, max] (m)");
      b.domain = d[0];
    }
    if (!meshes.is_none()) {
      // A list with one entry per body: None (the body is its box) or (vertices, triangles);
      // entries that are the same Python object share one Mesh.
      std::vector<std::pair<PyObject*, std::shared_ptr<const Mesh>>> seen;
      const py::list l = py::list(meshes);
      for (std::size_t i = 0; i < l.size(); ++i) {
        const py::handle e = l[i];
        if (e.is_none()) {
          b.meshes.push_back(nullptr);
          continue;
        }
        auto it = std::find_if(seen.begin(), seen.end(), [&](const auto& s) { return s.first == e.ptr(); });
        if (it != seen.end()) {
          b.meshes.push_back(it->second);
          continue;
        }
        const std::string arg = fmt::format("meshes[{}]", i);
        if (!py::isinstance<py::sequence>(e) || py::len(e) != 2)
          throw InputError(fmt::format("{}: not a (vertices, triangles) pair; allowed: None or (V x 3 float32 "
                                       "vertices in the body's local-box frame, T x 3 integer triangles)",
                                       arg));
        const py::sequence t = py::reinterpret_borrow<py::sequence>(e);
        auto mesh = std::make_shared<Mesh>();
        mesh->name = arg;
        if (py::hasattr(t[0], "__len__") && py::len(t[0]) > limits::kMaxMeshVertices)
          throw InputError(fmt::format("{}[0]: {} vertices; allowed: at most {} (docs/scenes.md, Limits)", arg,
                                       py::len(t[0]), limits::kMaxMeshVertices));
        if (py::hasattr(t[1], "__len__") && py::len(t[1]) > limits::kMaxMeshFaces)
          throw InputError(fmt::format("{}[1]: {} triangles; allowed: at most {} (docs/scenes.md, Limits)", arg,
                                       py::len(t[1]), limits::kMaxMeshFaces));
        mesh->vertices = vec3s(t[0], arg + "[0]", -1, "vertex (m)");
        auto tri = take<std::uint32_t>(t[1], arg + "[1]", {-1, 3}, {"T", "3"}, "triangle (vertex indices)");
        mesh->triangles.resize(static_cast<std::size_t>(tri.shape(0)));
        for (std::size_t k = 0; k < mesh->triangles.size(); ++k)
          for (std::size_t c = 0; c < 3; ++c) {
            const std::uint32_t idx = tri.data()[3 * k + c];
            if (idx >= mesh->vertices.size())
              throw InputError(fmt::format("{}[1]: triangle {} names vertex {}; allowed: indices below {}", arg, k,
                                           idx, mesh->vertices.size()));
            mesh->triangles[k][c] = idx;
          }
        check_mesh_argument(*mesh, arg);
        seen.emplace_back(e.ptr(), mesh);
        b.meshes.push_back(mesh);
      }
    }
    b.physics = undeclared_physics();
    if (!physics.is_none()) {
      if (!py::isinstance<py::dict>(physics)) throw InputError("physics: not a dict; allowed: a dict of PhysicsBodies fields");
      b.physics = parse_physics(py::reinterpret_borrow<py::dict>(physics), n > 0 ? n : -1);
    }
    ExternalOptions o;
    o.engine = engine;
    o.against_fcl = against_fcl;
    o.spec6_response = spec6_response;
    apply_tolerances(o, tolerances);
    o.stop = [flag = interrupted_] { return flag->load(); };
    {
      py::gil_scoped_release release;
      validator_ = std::make_unique<ExternalValidator>(b, o);
    }
    if (validator_->body_count() > trace_limits::kMaxBodies)
      throw_body_cap(scene_json.empty() ? "local_boxes" : "scene", validator_->body_count());
  }

  /// The CLI's cap (trace_limits::kMaxBodies: the most bodies of a trace `validate
  /// --trace-in` reads; the reference pair set is exact_pairs, O(n log n + pairs)).
  [[noreturn]] static void throw_body_cap(const char* arg, std::size_t n) {
    throw InputError(fmt::format("{}: {} bodies; allowed: at most {} bodies to judge, as `octocd validate "
                                 "--trace-in` (trace_limits::kMaxBodies)",
                                 arg, n, trace_limits::kMaxBodies));
  }

  std::size_t bodies() const { return validator_->body_count(); }

  void observe(std::int64_t frame, py::object aabbs, py::object pair_arr, py::object contacts, py::object x_pre,
               py::object v_pre, py::object x_post, py::object v_post, py::object q_pre, py::object q_post,
               py::object w_pre, py::object w_post, py::object x_det, py::object q_det, bool manifolds,
               bool checked) {
    const auto n = static_cast<py::ssize_t>(validator_->body_count());
    FrameRecord rec;
    rec.frame = frame;
    if (!aabbs.is_none()) rec.aabbs = boxes(aabbs, "aabbs", n, "world AABB [min, max] (m)");
    const std::pair<const char*, std::vector<Vec3>*> states[] = {
        {"x_pre", &rec.x_pre}, {"v_pre", &rec.v_pre}, {"x_post", &rec.x_post}, {"v_post", &rec.v_post}};
    const py::object* state_in[] = {&x_pre, &v_pre, &x_post, &v_post};
    int given = 0;
    for (int i = 0; i < 4; ++i)
      if (!state_in[i]->is_none()) {
        *states[i].second = vec3s(*state_in[i], states[i].first, n, i % 2 ? "velocity (m/s)" : "position (m)");
        ++given;
      }
    if (given != 0 && given != 4)
      throw InputError("x_pre, v_pre, x_post, v_post: some given, some None; allowed: all four (n, 3) arrays, or "
                       "none (then aabbs is required)");
    if (rec.aabbs.empty() && given == 0)
      throw InputError("aabbs: None and no states; allowed: aabbs (n, 2, 3) and/or the four states x_pre, v_pre, "
                       "x_post, v_post (n, 3)");
    if (pair_arr.is_none()) rec.has_pairs = false;
    else rec.pairs = pairs(pair_arr, "pairs");
    if (!q_pre.is_none()) rec.q_pre = quats(q_pre, "q_pre", n);
    if (!q_post.is_none()) rec.q_post = quats(q_post, "q_post", n);
    if (!w_pre.is_none()) rec.w_pre = vec3s(w_pre, "w_pre", n, "angular velocity (rad/s)");
    if (!w_post.is_none()) rec.w_post = vec3s(w_post, "w_post", n, "angular velocity (rad/s)");
    if (!x_det.is_none()) rec.x_det = vec3s(x_det, "x_det", n, "detection position (m)");
    if (!q_det.is_none()) rec.q_det = quats(q_det, "q_det", n);
    rec.manifolds = manifolds;
    if (!contacts.is_none()) {
      if (!py::isinstance<py::dict>(contacts))
        throw InputError("contacts: not a dict; allowed: {'pair': (C, 2), 'normal': (C, 3), 'depth': (C,), 'jn': "
                         "(C,), 'jt': (C,)[, 'point': (C, 3)]}");
      const py::dict c = py::reinterpret_borrow<py::dict>(contacts);
      // octocd's own FrameRecord.contacts adds the design.md section 6 terms: accepted and ignored (the
      // validators derive them from the states), so an octocd record can be fed back.
      static const char* const kKeys[] = {"pair", "normal", "depth", "jn", "jt", "point", "axis",
                                          "v_a", "v_b", "dx_a", "dx_b", "dv_a", "dv_b"};
      for (auto item : c) {
        const std::string k = py::str(item.first);
        if (std::find(std::begin(kKeys), std::end(kKeys), k) == std::end(kKeys))
          throw InputError(fmt::format("contacts: unknown key '{}'; allowed: pair, normal, depth, jn, jt, point "
                                       "(and, ignored, the design.md section 6 terms of octocd's records: axis, v_a, v_b, dx_a, "
                                       "dx_b, dv_a, dv_b)",
                                       k));
      }
      for (const char* k : {"pair", "normal", "depth", "jn", "jt"})
        if (!c.contains(k))
          throw InputError(fmt::format("contacts: no '{}'; allowed: a dict with pair (C, 2), normal (C, 3), depth, "
                                       "jn, jt (C,) and optionally point (C, 3)",
                                       k));
      const std::vector<Pair> cp = pairs(c["pair"], "contacts['pair']");
      const auto cn = static_cast<py::ssize_t>(cp.size());
      const std::vector<Vec3> normal = vec3s(c["normal"], "contacts['normal']", cn, "unit normal from B to A");
      const std::vector<float> depth = floats(c["depth"], "contacts['depth']", cn, "depth (m)");
      const std::vector<float> jn = floats(c["jn"], "contacts['jn']", cn, "normal impulse (kg m/s)");
      const std::vector<float> jt = floats(c["jt"], "contacts['jt']", cn, "friction impulse (kg m/s)");
      std::vector<Vec3> point;
      if (c.contains("point")) {
        point = vec3s(c["point"], "contacts['point']", cn, "world contact point (m)");
        rec.has_points = true;
      }
      rec.contacts.resize(cp.size());
      for (std::size_t i = 0; i < cp.size(); ++i) {
        ContactRecord& r = rec.contacts[i];
        r.pair = cp[i], r.normal = normal[i], r.depth = depth[i], r.jn = jn[i], r.jt = jt[i];
        if (rec.has_points) r.point = point[i];
      }
    }
    for (const std::vector<Vec3>* x : {&rec.x_pre, &rec.x_post, &rec.x_det})
      check_coordinates(*x, x == &rec.x_det ? "x_det" : x == &rec.x_pre ? "x_pre" : "x_post",
                        trace_limits::kMaxCoordinate, "positions (m)");
    check_coordinates(rec.v_pre, "v_pre", trace_limits::kMaxSpeed, "velocities (m/s)");
    check_coordinates(rec.v_post, "v_post", trace_limits::kMaxSpeed, "velocities (m/s)");
    for (std::size_t i = 0; i < rec.aabbs.size(); ++i)
      for (int k = 0; k < 3; ++k)
        for (const float c : {rec.aabbs[i].min[k], rec.aabbs[i].max[k]})
          if (!(std::fabs(c) <= trace_limits::kMaxCoordinate))
            throw InputError(fmt::format("aabbs: row {} holds {}; allowed: world AABB corners (m) with |component| "
                                         "<= {:g}",
                                         i, c, trace_limits::kMaxCoordinate));
    BusyGuard busy(busy_, "this Validator");
    settle();
    interrupted_->store(false);
    // The frame is judged on a helper thread while this one runs Python's signal handlers
    // every 20 ms: Ctrl-C raises KeyboardInterrupt at once, whatever loop the judging is in.
    std::future<void> judging = std::async(std::launch::async, [this, r = std::move(rec), checked]() mutable {
      try {
        validator_->observe(std::move(r), checked);
      } catch (const ValidationStopped&) {
        // Stopped by the Ctrl-C already raised (the frame is partly judged).
      }
    });
    work_.wait(judging);
    judging.get();  // the judging's error (InputError, ...), if any, raised here
  }

  py::list results() {
    BusyGuard busy(busy_, "this Validator");
    settle();
    return out_results(validator_->results());
  }

 private:
  /// Before any call that reads or changes the validator: a judging an earlier Ctrl-C left
  /// ending in the background ends first (InterruptibleWork::settle).
  void settle() { work_.settle(); }

  std::unique_ptr<ExternalValidator> validator_;
  std::atomic<bool> busy_{false};
  /// Set by Ctrl-C during observe() (cleared when the next one begins): the validators'
  /// stop callback reads it, so a judging cut short ends at its next poll.
  std::shared_ptr<std::atomic<bool>> interrupted_ = std::make_shared<std::atomic<bool>>(false);
  /// The judging runs on a helper thread; a Ctrl-C sets interrupted_ (the judging ends at
  /// its next poll) and leaves it ending there (declared after validator_ and interrupted_:
  /// destroyed first, it waits for the judging).
  InterruptibleWork work_{[flag = interrupted_] { flag->store(true); }};
};

ValidationResult result_from(const py::handle& r) {
  ValidationResult v;
  auto get = [&](const char* k) { return r.attr(k); };
  const std::string tier = py::str(get("tier"));
  v.tier = find_tier(tier).value_or(Tier::Model);
  v.name = py::str(get("name"));
  v.figure = py::str(get("figure"));
  v.measured = get("measured").cast<double>();
  v.bound = get("bound").cast<double>();
  v.pass = get("passed").cast<bool>();
  v.applicable = get("applicable").cast<bool>();
  v.detail = py::str(get("detail"));
  v.tolerances = py::str(get("tolerances"));
  if (py::hasattr(r, "judged")) v.judged = get("judged").cast<std::uint64_t>();
  if (py::hasattr(r, "seconds")) v.seconds = get("seconds").cast<double>();
  if (py::hasattr(r, "causes")) {
    for (const py::handle c : get("causes")) {
      ValidationCause vc;
      vc.name = py::str(c.attr("name"));
      vc.unit = py::str(c.attr("unit"));
      vc.count = c.attr("count").cast<std::uint64_t>();
      vc.worst = c.attr("worst").cast<double>();
      for (const py::handle x : c.attr("examples"))
        vc.examples.push_back(ValidationExample{x.attr("frame").cast<std::int64_t>(), py::str(x.attr("item")),
                                                x.attr("figure").cast<double>(), py::str(x.attr("text"))});
      vc.items = c.attr("items").cast<std::vector<std::string>>();
      vc.items_complete = c.attr("items_complete").cast<bool>();
      v.causes.push_back(std::move(vc));
    }
  }
  return v;
}

}  // namespace

PYBIND11_MODULE(_octocd, m) {
  m.doc() = "octocd's compiled core; use the `octocd` package (python/octocd/).";

  static py::exception<InputError> input_error(m, "InputError", PyExc_ValueError);
  static py::exception<RuntimeError> runtime_error(m, "RuntimeError", PyExc_RuntimeError);
  py::register_exception_translator([](std::exception_ptr p) {
    try {
      if (p) std::rethrow_exception(p);
    } catch (const InputError& e) {  // bounded, valid UTF-8: a message naming hostile bytes still decodes
      PyErr_SetString(input_error.ptr(), utf8_replaced(bounded(e.what(), kMaxLineBytes, 1024)).c_str());
    } catch (const RuntimeError& e) {
      PyErr_SetString(runtime_error.ptr(), utf8_replaced(bounded(e.what(), kMaxLineBytes, 1024)).c_str());
    }
  });

  m.attr("build_id") = build_id();
  m.def("engines", &built_engines);
  m.def("load_engines_file", &load_engines_file);
  m.def("cuda_device_status", &cuda_device_status);
  m.def("broadphases", &any_engine_broadphase_names);
  m.def("tolerances", [] {
    py::dict d;
    const Tolerances def;
    for (const ToleranceEntry& e : tolerance_table()) d[e.name] = def.*(e.member);
    return d;
  });

  py::class_<PyScene>(m, "Scene",
                      "A loaded, validated scene (octocd.load_scene; docs/scenes.md). Read-only; one Scene can "
                      "build several engines.")
      .def("__repr__",
           [](const PyScene& s) {
             return fmt::format("octocd.Scene('{}', {} bodies in groups, dt {} s, {} frames, broadphase '{}')",
                                s.scene->name, body_count(*s.scene), s.scene->dt, s.scene->frames,
                                s.scene->broadphase.name);
           })
      .def_property_readonly("name", [](const PyScene& s) { return s.scene->name; })
      .def_property_readonly("description", [](const PyScene& s) { return s.scene->description; })
      .def_property_readonly("path", [](const PyScene& s) { return s.scene->path; })
      .def_property_readonly("json", [](const PyScene& s) { return s.scene->json; })
      .def_property_readonly("dt", [](const PyScene& s) { return s.scene->dt; })
      .def_property_readonly("frames", [](const PyScene& s) { return s.scene->frames; })
      .def_property_readonly("gravity",
                             [](const PyScene& s) { return out_vec3({s.scene->gravity}).attr("reshape")(3); })
      .def_property_readonly("domain", [](const PyScene& s) { return out_boxes({s.scene->domain}).attr("reshape")(2, 3); })
      .def_property_readonly("body_count", [](const PyScene& s) { return body_count(*s.scene); })
      .def_property_readonly("broadphase", [](const PyScene& s) { return s.scene->broadphase.name; })
      .def_property_readonly("midphase", [](const PyScene& s) { return s.scene->midphase.to_string(); });

  m.def("load_scene", [](const std::string& path, const std::string& data_dir) {
    py::gil_scoped_release release;
    return PyScene{std::make_shared<const Scene>(load_scene(path, data_dir))};
  });
  m.def("parse_scene", [](const std::string& text, const std::string& origin, const std::string& data_dir) {
    py::gil_scoped_release release;
    return PyScene{std::make_shared<const Scene>(parse_scene(text, origin, data_dir))};
  });

  py::class_<PyEngine>(m, "Engine")
      .def(py::init<const PyScene&, const std::string&, const std::optional<std::string>&,
                    const std::optional<std::string>&, bool, const EngineSettingItems&>(),
           py::arg("scene"), py::arg("engine"), py::arg("broadphase"), py::arg("midphase"), py::arg("record"),
           py::arg("settings") = EngineSettingItems{})
      .def("step", &PyEngine::step, py::arg("n"))
      .def("last_frame", &PyEngine::last_frame)
      .def("set_state", &PyEngine::set_state)
      .def_property_readonly("positions", &PyEngine::positions)
      .def_property_readonly("velocities", &PyEngine::velocities)
      .def_property_readonly("inverse_masses", &PyEngine::inverse_masses)
      .def_property_readonly("local_boxes", &PyEngine::local_boxes)
      .def_property_readonly("groups", &PyEngine::groups)
      .def_property_readonly("recording", &PyEngine::recording)
      .def_property_readonly("name", [](const PyEngine& e) { return e.engine().name(); })
      .def_property_readonly("device", [](const PyEngine& e) { return e.engine().device(); })
      .def_property_readonly("broadphase", [](const PyEngine& e) { return e.engine().broadphase_name(); })
      .def_property_readonly("midphase", [](const PyEngine& e) { return e.engine().midphase_name(); })
      .def_property_readonly("frame", &PyEngine::frames)
      .def_property_readonly("body_count", [](const PyEngine& e) { return e.engine().state().size(); })
      .def_property_readonly("notes", [](const PyEngine& e) { return e.engine().notes(); })
      .def_property_readonly("state_hash", &PyEngine::state_hash);

  py::class_<PyValidator>(m, "Validator")
      .def(py::init<py::object, py::object, const std::string&, float, py::object, py::object, py::object, py::object,
                    const std::string&, bool, bool, py::object>(),
           py::arg("local_boxes"), py::arg("inverse_mass"), py::arg("scene_json"), py::arg("dt"), py::arg("gravity"),
           py::arg("domain"), py::arg("meshes"), py::arg("physics"), py::arg("engine"), py::arg("against_fcl"),
           py::arg("spec6_response"), py::arg("tolerances"))
      .def("observe", &PyValidator::observe, py::arg("frame"), py::arg("aabbs"), py::arg("pairs"),
           py::arg("contacts"), py::arg("x_pre"), py::arg("v_pre"), py::arg("x_post"), py::arg("v_post"),
           py::arg("q_pre"), py::arg("q_post"), py::arg("w_pre"), py::arg("w_post"), py::arg("x_det"),
           py::arg("q_det"), py::arg("manifolds"), py::arg("checked"))
      .def("results", &PyValidator::results)
      .def_property_readonly("body_count", &PyValidator::bodies);

  py::class_<PyTraceFile>(m, "TraceFile",
                          "A trace open through octocd's hardened reader (octocd.Trace reads with it).")
      .def(py::init<const std::string&>(), py::arg("path"))
      .def_property_readonly("version", &PyTraceFile::version)
      .def_property_readonly("path", &PyTraceFile::path)
      .def_property_readonly("closed", &PyTraceFile::closed)
      .def("has", &PyTraceFile::has, py::arg("name"))
      .def("shape", &PyTraceFile::shape, py::arg("name"))
      .def("kind", &PyTraceFile::kind, py::arg("name"))
      .def("complete_rows", &PyTraceFile::complete_rows, py::arg("group"))
      .def("rows", &PyTraceFile::rows, py::arg("name"), py::arg("first"), py::arg("count"), py::arg("dtype"))
      .def("attribute", &PyTraceFile::attribute, py::arg("name"))
      .def("strings", &PyTraceFile::strings, py::arg("name"))
      .def("close", &PyTraceFile::close);
  m.attr("trace_frame_columns") = TraceReader::frame_columns();
  m.attr("max_judged_bodies") = trace_limits::kMaxBodies;

  m.def(
      "validate_trace",
      [](const std::string& path, int every, std::int64_t max_frames, bool against_fcl, py::object tolerances,
         const std::optional<std::string>& expect_json, const std::string& expect_origin, bool strict,
         const std::optional<std::string>& shard, const std::string& mesh_dir) {
        if (every < 1) throw InputError(fmt::format("every: {}; allowed: >= 1", every));
        if (max_frames < 0) throw InputError(fmt::format("max_frames: {}; allowed: >= 0 (0 = all)", max_frames));
        ExternalOptions o;  // engine name and response model: from the trace
        o.against_fcl = against_fcl;
        o.mesh_dir = mesh_dir;  // "" = the trace's folder (`validate --trace-in --mesh-dir`)
        apply_tolerances(o, tolerances);
        if (shard) o.shard = parse_shard(*shard);
        // Expectations are read (and refused) before the trace is judged.
        const Expectations expect =
            expect_json ? parse_expectations_text(*expect_json, expect_origin) : Expectations{};
        std::vector<ValidationResult> rs;
        ExternalTraceInfo info;
        PythonStop stop;
        o.stop = stop.callback();
        try {
          py::gil_scoped_release release;
          rs = validate_external_trace(path, o, every, max_frames, &info);
        } catch (const ValidationStopped&) {
          stop.rethrow();  // KeyboardInterrupt
          throw RuntimeError("validate_trace: stopped");
        }
        const ExpectationReport report = match_expectations(expect, trace_run(path), rs);
        // A shard's verdict as `validate --shard --json` writes it (merge_validations reads it).
        std::string doc;
        if (shard) {
          ShardIdentity id;
          id.trace = trace_run(path).trace;
          std::error_code ec;
          id.trace_bytes = std::filesystem::file_size(path, ec);
          id.engine = info.engine;
          id.bodies = info.bodies;
          id.frames = info.frames;
          id.every = every;
          id.against = against_fcl ? "fcl" : "none";
          id.tol = o.tol;
          nlohmann::ordered_json meta = {{"engine", info.engine}, {"frames", info.frames}, {"every", every}};
          meta["shard"] = shard_json(o.shard, id);
          doc = results_json(rs, trace_run(path), &report, meta)
                    .dump(-1, ' ', false, nlohmann::ordered_json::error_handler_t::replace);
        }
        return py::make_tuple(out_results(rs, expect_json ? &report : nullptr), out_outcomes(report),
                              report.exit_code(strict), doc);
      },
      py::arg("path"), py::arg("every"), py::arg("max_frames"), py::arg("against_fcl"), py::arg("tolerances"),
      py::arg("expect_json"), py::arg("expect_origin"), py::arg("strict"), py::arg("shard"), py::arg("mesh_dir"));

  m.def(
      "merge_validations",
      [](const std::vector<std::string>& texts, const std::vector<std::string>& names) {
        std::vector<nlohmann::json> docs;
        for (std::size_t k = 0; k < texts.size(); ++k) {
          nlohmann::json d = nlohmann::json::parse(texts[k], nullptr, false);
          if (d.is_discarded())
            throw InputError(fmt::format("merge_validations: {}: not JSON; allowed: a shard's verdict", names[k]));
          docs.push_back(std::move(d));
        }
        const MergedValidation merged = merge_validation_docs(docs, names);
        const ExpectationReport report = match_expectations({}, merged.run, merged.results);
        return py::make_tuple(out_results(merged.results, nullptr), out_outcomes(report), report.exit_code(false));
      },
      py::arg("texts"), py::arg("names"));

  // The CLI's reader of JSON inputs (octocd/atomic_file.hpp): a FIFO, a device or a folder is
  // refused without blocking, /dev/zero is never read, at most 64 MiB.
  m.def(
      "read_input_file",
      [](const std::string& path, const std::string& label, const std::string& allowed) {
        return py::bytes(read_input_file(path, label, allowed));
      },
      py::arg("path"), py::arg("label"), py::arg("allowed"));

  m.def("format_results", [](const py::list& results, const std::vector<std::string>& overridden) {
    std::vector<ValidationResult> rs;
    for (const py::handle r : results) rs.push_back(result_from(r));
    return format_results(rs, overridden);
  });

  // octocd.view (design.md section 16): the page of `octocd view`, by the same code (octocd/view.hpp).
  m.def(
      "view",
      [](const std::string& trace, std::int64_t frame, const std::optional<std::pair<std::int64_t, std::int64_t>>& pair,
         const std::optional<std::int64_t>& body, int window, const std::string& out_dir) {
        ViewSettings vs;
        auto index = [](const char* arg, std::int64_t i) {
          if (i < 0 || i > 0xffffffffll)
            throw InputError(fmt::format("{}: body {} does not exist; allowed: a body index 0 .. bodies - 1", arg, i));
          return static_cast<std::uint32_t>(i);
        };
        if (frame < 1) throw InputError(fmt::format("frame: {}: outside the trace; allowed: 1 .. the trace's frames", frame));
        vs.frame = frame;
        vs.window = window;
        if (pair) {
          vs.has_pair = true;
          vs.pair_a = index("pair", pair->first);
          vs.pair_b = index("pair", pair->second);
        }
        if (body) {
          vs.has_body = true;
          vs.body = index("body", *body);
        }
        ViewPage page;
        PythonStop stop;
        vs.stop = stop.callback();
        try {
          py::gil_scoped_release release;
          page = write_view(trace, vs, out_dir);
        } catch (const ValidationStopped&) {
          stop.rethrow();  // KeyboardInterrupt (no page written)
          throw RuntimeError("view: stopped");
        } catch (const InputError& e) {  // the CLI's option names as the keyword arguments
          std::string msg = e.what();
          for (const char* o : {"--frame", "--pair", "--body", "--window"})
            if (msg.rfind(o, 0) == 0) msg = msg.substr(2);
          if (msg.rfind("-o:", 0) == 0) msg = "out_dir:" + msg.substr(3);
          if (msg.rfind("pair and --body", 0) == 0) msg = "pair and body" + msg.substr(15);
          throw InputError(msg);
        }
        py::dict d;
        d["path"] = page.path;
        d["bytes"] = page.bytes;
        d["bodies"] = page.bodies;
        d["frames"] = page.frames;
        d["frame"] = page.frame;
        d["note"] = page.note;
        return d;
      },
      py::arg("trace"), py::arg("frame"), py::arg("pair"), py::arg("body"), py::arg("window"), py::arg("out_dir"));
}
