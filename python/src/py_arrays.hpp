#pragma once
/// \file py_arrays.hpp
/// The compiled module's shared part (python/src/module.cpp): NumPy arrays in (dtype, shape and
/// finiteness checked, InputError naming the argument) and out (fresh copies the caller owns),
/// results and metrics as Python objects, and the guards of long calls (BusyGuard: one call at a
/// time per object; InterruptibleWork and PythonStop: Ctrl-C raises KeyboardInterrupt within a
/// fraction of a second). Included only by the module's own files.

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

namespace py = pybind11;

namespace octocd::python_binding {

// ---- arrays in -----------------------------------------------------------------------

/// Shape text "(n, 3)" for messages; -1 dims print as their name.
inline std::string shape_text(const std::vector<py::ssize_t>& shape, const std::vector<std::string>& names) {
  std::string s = "(";
  for (std::size_t i = 0; i < shape.size(); ++i) {
    if (i) s += ", ";
    s += shape[i] >= 0 ? std::to_string(shape[i]) : names[i];
  }
  return s + (shape.size() == 1 ? ",)" : ")");
}

inline std::string actual_shape(const py::array& a) {
  std::vector<py::ssize_t> s(a.shape(), a.shape() + a.ndim());
  return shape_text(s, std::vector<std::string>(s.size()));
}

/// True on a little-endian machine (NumPy's byteorder '<' is then the native one).
inline constexpr bool kNativeLittle = __BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__;

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
inline std::vector<Vec3> vec3s(py::handle obj, const std::string& arg, py::ssize_t n, const std::string& what) {
  auto a = take<float>(obj, arg, {n, 3}, {"n", "3"}, what);
  std::vector<Vec3> v(static_cast<std::size_t>(a.shape(0)));
  if (!v.empty()) std::memcpy(static_cast<void*>(v.data()), a.data(), v.size() * sizeof(Vec3));
  return v;
}

/// (n, 4) floats (w, x, y, z) as Quats.
inline std::vector<Quat> quats(py::handle obj, const std::string& arg, py::ssize_t n) {
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
inline std::vector<Aabb> boxes(py::handle obj, const std::string& arg, py::ssize_t n, const std::string& what) {
  auto a = take<float>(obj, arg, {n, 2, 3}, {"n", "2", "3"}, what);
  std::vector<Aabb> b(static_cast<std::size_t>(a.shape(0)));
  if (!b.empty()) std::memcpy(static_cast<void*>(b.data()), a.data(), b.size() * sizeof(Aabb));
  for (std::size_t i = 0; i < b.size(); ++i)
    if (!(b[i].min.x <= b[i].max.x && b[i].min.y <= b[i].max.y && b[i].min.z <= b[i].max.z))
      throw InputError(fmt::format("{}: row {}: min above max; allowed: [:, 0] = min <= [:, 1] = max", arg, i));
  return b;
}

/// (P, 2) integers as Pairs.
inline std::vector<Pair> pairs(py::handle obj, const std::string& arg) {
  auto a = take<std::uint32_t>(obj, arg, {-1, 2}, {"P", "2"}, "body-index pair (a, b), a < b,");
  std::vector<Pair> p(static_cast<std::size_t>(a.shape(0)));
  if (!p.empty()) std::memcpy(static_cast<void*>(p.data()), a.data(), p.size() * sizeof(Pair));
  return p;
}

/// (C,) floats.
inline std::vector<float> floats(py::handle obj, const std::string& arg, py::ssize_t n, const std::string& what) {
  auto a = take<float>(obj, arg, {n}, {n >= 0 ? "" : "C"}, what);
  return std::vector<float>(a.data(), a.data() + a.size());
}

// ---- arrays out ----------------------------------------------------------------------

inline py::array_t<float> out_vec3(const std::vector<Vec3>& v) {
  py::array_t<float> a({static_cast<py::ssize_t>(v.size()), py::ssize_t{3}});
  if (!v.empty()) std::memcpy(a.mutable_data(), v.data(), v.size() * sizeof(Vec3));
  return a;
}
inline py::object out_vec3_or_none(const std::vector<Vec3>& v) { return v.empty() ? py::object(py::none()) : out_vec3(v); }
inline py::object out_quat_or_none(const std::vector<Quat>& q) {
  if (q.empty()) return py::none();
  py::array_t<float> a({static_cast<py::ssize_t>(q.size()), py::ssize_t{4}});
  float* d = a.mutable_data();
  for (std::size_t i = 0; i < q.size(); ++i) {
    d[4 * i] = q[i].w, d[4 * i + 1] = q[i].x, d[4 * i + 2] = q[i].y, d[4 * i + 3] = q[i].z;
  }
  return a;
}
inline py::array_t<float> out_boxes(const std::vector<Aabb>& b) {
  py::array_t<float> a({static_cast<py::ssize_t>(b.size()), py::ssize_t{2}, py::ssize_t{3}});
  if (!b.empty()) std::memcpy(a.mutable_data(), b.data(), b.size() * sizeof(Aabb));
  return a;
}
inline py::array_t<std::int32_t> out_pairs(const std::vector<Pair>& p) {
  py::array_t<std::int32_t> a({static_cast<py::ssize_t>(p.size()), py::ssize_t{2}});
  std::int32_t* d = a.mutable_data();
  for (std::size_t i = 0; i < p.size(); ++i) {
    d[2 * i] = static_cast<std::int32_t>(p[i].a);
    d[2 * i + 1] = static_cast<std::int32_t>(p[i].b);
  }
  return a;
}

inline py::dict out_contacts(const std::vector<ContactRecord>& cs, bool terms, bool points) {
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

inline py::dict out_metrics(const FrameMetrics& m, const Engine* engine) {
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
inline py::list out_results(const std::vector<ValidationResult>& rs, const ExpectationReport* report = nullptr) {
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
inline py::list out_outcomes(const ExpectationReport& report) {
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
inline void string_keys(const py::dict& d, const std::string& arg) {
  for (auto item : d)
    if (!py::isinstance<py::str>(item.first))
      throw InputError(fmt::format("{}: key {} is a {}; allowed: string keys (each at most once)", arg,
                                   std::string(py::repr(item.first)),
                                   std::string(py::str(item.first.get_type().attr("__name__")))));
}

}  // namespace octocd::python_binding
