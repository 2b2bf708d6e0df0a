// libFuzzer target: the Python reader (issue 36), octocd.Trace, through the C++ functions
// the module binds. octocd.Trace (python/octocd/trace.py) is pure Python over
// _octocd.TraceFile (python/src/module.cpp, PyTraceFile), and each TraceFile method is one
// TraceReader call plus a NumPy copy: has -> has_dataset, shape, kind -> element_kind,
// complete_rows, rows(name, first, count, dtype) -> read_f32_rows / read_f64_rows /
// read_i64_rows, attribute (None when absent), strings -> read_strings. This target makes
// those calls in the order octocd.Trace's accessors make them (construction and its
// checks, attrs, frames, state_frames, state and rotation of the first and last state,
// orientations, angular_velocities, inertia, materials, contacts of the first and last
// frame), each accessor on its own as a user would call it, and checks what rows() then
// copies: exactly count x the trailing dimensions' values (the module's memcpy into the
// array it shapes so). Why a libFuzzer target and not the interpreter: the module is
// built without sanitizers (an instrumented extension needs the runtime preloaded into an
// uninstrumented python, and CMake turns it off under OCTOCD_SANITIZE and OCTOCD_FUZZ),
// while here ASan + UBSan and coverage feedback see every C++ line the module runs; the
// Python layer (NumPy, no memory of its own) is replayed in the real interpreter by
// python/tests/test_untrusted.py on the whole trace corpus (fuzz/regressions/trace).
// Findings: a crash, a hang, an exception other than InputError / RuntimeError, or a
// rows() result of another size.
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <functional>
#include <string>
#include <vector>

#include "fuzz_common.hpp"
#include "octocd/error.hpp"
#include "octocd/trace_reader.hpp"

namespace {

using octocd::TraceReader;

/// PyTraceFile::rows: the read, then the size its NumPy array has.
std::vector<double> rows(const TraceReader& t, const std::string& name, std::int64_t first, std::int64_t count,
                         char dtype) {
  const std::vector<std::uint64_t> dims = t.shape(name);
  if (dims.empty()) throw octocd::InputError(name + ": a scalar");
  std::uint64_t expect = static_cast<std::uint64_t>(count);
  for (std::size_t k = 1; k < dims.size(); ++k) expect *= dims[k];
  std::vector<double> out;
  std::size_t got = 0;
  if (dtype == 'f') {
    const std::vector<float> v = t.read_f32_rows(name, first, count);
    got = v.size();
    out.assign(v.begin(), v.end());
  } else if (dtype == 'd') {
    out = t.read_f64_rows(name, first, count);
    got = out.size();
  } else {
    const std::vector<std::int64_t> v = t.read_i64_rows(name, first, count);
    got = v.size();
    out.assign(v.begin(), v.end());
  }
  if (got != expect) {
    std::fprintf(stderr, "fuzz_pytrace: %s rows %lld+%lld: %zu values, the array holds %llu\n", name.c_str(),
                 static_cast<long long>(first), static_cast<long long>(count), got,
                 static_cast<unsigned long long>(expect));
    std::abort();
  }
  return out;
}

const char* const kRootAttributes[] = {
    "format", "version", "scene_name", "scene", "parameters", "engine", "broadphase", "midphase", "build_id",
    "device", "start_time", "dt", "state_every", "flush_every", "body_count", "committed_frames",
    "committed_states", "stage_names", "gravity", "response_model", "detection", "mu", "restitution",
    "friction_combine", "restitution_combine", "contact_margin", "broadphase_exact", "contact_geometry",
    "collision_shape", "contact_model", "integrator", "gyroscopic"};

std::int64_t body_count(const TraceReader& t) {
  if (!t.has_dataset("/bodies/inverse_mass")) throw octocd::InputError("no /bodies/inverse_mass");
  return static_cast<std::int64_t>(t.shape("/bodies/inverse_mass").at(0));
}

std::vector<double> state_frames(const TraceReader& t) {
  if (!t.has_dataset("/states/position")) throw octocd::InputError("no states");
  const std::int64_t s = t.complete_rows("/states");
  if (t.has_dataset("/states/frame")) return rows(t, "/states/frame", 0, s, 'i');
  std::vector<double> f(static_cast<std::size_t>(s));
  for (std::size_t i = 0; i < f.size(); ++i) f[i] = static_cast<double>(i);
  return f;
}

/// Trace.contacts(frame): the offsets of the frame's rows, then each contact dataset.
void contacts(const TraceReader& t, std::int64_t frame) {
  if (!t.has_dataset("/contacts/offsets")) return;
  const auto noff = static_cast<std::int64_t>(t.shape("/contacts/offsets").at(0));
  std::int64_t i = 0;
  if (t.has_dataset("/contacts/frame")) {
    const std::vector<double> fr = rows(t, "/contacts/frame", 0, t.complete_rows("/contacts"), 'i');
    i = -1;
    for (std::size_t k = 0; k < fr.size() && i < 0; ++k)
      if (fr[k] == static_cast<double>(frame)) i = static_cast<std::int64_t>(k);
    if (i < 0) return;
  } else {
    if (frame < 1 || frame > noff - 1) return;
    i = frame - 1;
  }
  const std::vector<double> ab = rows(t, "/contacts/offsets", i, 2, 'i');
  const auto a = static_cast<std::int64_t>(ab.at(0)), b = static_cast<std::int64_t>(ab.at(1));
  const auto total = static_cast<std::int64_t>(t.shape("/contacts/pair").at(0));
  if (!(0 <= a && a <= b && b <= total)) return;  // Trace refuses it (InputError)
  for (const char* k : {"pair", "normal", "depth", "jn", "jt", "point"}) {
    const std::string d = std::string("/contacts/") + k;
    if (t.has_dataset(d)) (void)rows(t, d, a, b - a, k[0] == 'p' && k[1] == 'a' ? 'i' : 'f');
  }
}

const std::vector<std::function<void(const TraceReader&)>>& accessors() {
  static const std::vector<std::function<void(const TraceReader&)>> list = {
      [](const TraceReader& t) {  // attrs
        for (const char* a : kRootAttributes)
          if (t.has_attribute(a)) (void)t.attribute(a);
      },
      [](const TraceReader& t) {  // frames
        if (!t.has_dataset("/frames/frame")) return;
        const std::int64_t n = t.complete_rows("/frames");
        for (const std::string& c : TraceReader::frame_columns())
          if (t.has_dataset("/frames/" + c))
            (void)rows(t, "/frames/" + c, 0, n, t.element_kind("/frames/" + c) == "integer" ? 'i' : 'd');
      },
      [](const TraceReader& t) {  // state and rotation of the first and last state row
        const std::vector<double> f = state_frames(t);
        if (f.empty()) return;
        for (const std::int64_t r : {std::int64_t{0}, static_cast<std::int64_t>(f.size()) - 1}) {
          (void)rows(t, "/states/position", r, 1, 'f');
          (void)rows(t, "/states/velocity", r, 1, 'f');
          if (t.has_dataset("/states/orientation")) {
            (void)body_count(t);
            (void)rows(t, "/states/orientation", r, 1, 'f');
            (void)rows(t, "/states/angular_velocity", r, 1, 'f');
          }
        }
      },
      [](const TraceReader& t) {  // orientations, angular_velocities
        const auto s = static_cast<std::int64_t>(state_frames(t).size());
        (void)body_count(t);
        if (!t.has_dataset("/states/orientation")) return;
        (void)rows(t, "/states/orientation", 0, s, 'f');
        (void)rows(t, "/states/angular_velocity", 0, s, 'f');
      },
      [](const TraceReader& t) {  // inertia
        const std::int64_t n = body_count(t);
        if (t.has_dataset("/bodies/inertia")) {
          const auto shape = t.shape("/bodies/inertia");
          if (shape == std::vector<std::uint64_t>{static_cast<std::uint64_t>(n), 3, 3})
            (void)rows(t, "/bodies/inertia", 0, n, 'f');
          return;
        }
        for (const char* k : {"/bodies/local_aabb_min", "/bodies/local_aabb_max"})
          if (t.shape(k) != std::vector<std::uint64_t>{static_cast<std::uint64_t>(n), 3}) return;
        (void)rows(t, "/bodies/local_aabb_min", 0, n, 'd');
        (void)rows(t, "/bodies/local_aabb_max", 0, n, 'd');
        (void)rows(t, "/bodies/inverse_mass", 0, n, 'd');
      },
      [](const TraceReader& t) {  // materials
        for (const char* a : {"mu", "restitution", "friction_combine", "restitution_combine", "contact_margin"})
          if (t.has_attribute(a)) (void)t.attribute(a);
        const std::int64_t n = body_count(t);
        for (const char* d : {"/bodies/friction", "/bodies/restitution"})
          if (t.has_dataset(d) && t.shape(d) == std::vector<std::uint64_t>{static_cast<std::uint64_t>(n)})
            (void)rows(t, d, 0, n, 'f');
      },
      [](const TraceReader& t) {  // contacts of the first and last frame
        std::int64_t last = 1;
        if (t.has_dataset("/frames/frame")) last = std::max<std::int64_t>(1, t.complete_rows("/frames"));
        else if (t.has_dataset("/contacts/offsets"))
          last = std::max<std::int64_t>(1, static_cast<std::int64_t>(t.shape("/contacts/offsets").at(0)) - 1);
        contacts(t, 1);
        if (last > 1) contacts(t, last);
      },
      [](const TraceReader& t) {  // groups (octocd.Trace's strings)
        if (t.has_dataset("/bodies/group")) (void)t.read_strings("/bodies/group");
      },
  };
  return list;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string path = octocd_fuzz::scratch_path("pytrace");
  octocd_fuzz::write_input(path, data, size);
  try {
    const TraceReader t(path);  // Trace(path): TraceFile(path), then _check
    (void)t.version();
    for (const char* d : {"/frames/frame", "/states/orientation", "/states/angular_velocity", "/bodies/inertia",
                          "/bodies/friction", "/bodies/restitution", "/contacts/point"})
      (void)t.has_dataset(d);
    for (const auto& accessor : accessors()) {
      try {
        accessor(t);
      } catch (const octocd::InputError&) {
      } catch (const octocd::RuntimeError&) {
      } catch (const std::out_of_range&) {  // .at(0) of an empty shape: Python raises IndexError
      }
    }
  } catch (const octocd::InputError&) {
  } catch (const octocd::RuntimeError&) {
  }
  std::remove(path.c_str());
  return 0;
}
