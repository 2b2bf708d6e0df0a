// octocd._octocd: the compiled half of the `octocd` Python package (issue 21). The
// package's public names, their docstrings and the small conveniences (scene dicts,
// result objects) are in python/octocd/*.py (one module per job). This file binds the classes of
// its four headers, which convert arrays and call the C++ API: py_arrays.hpp (arrays in and out,
// the guards of long calls), py_trace_file.hpp (octocd.Trace), py_engine.hpp (scenes and the
// engines: build_model + octocd/engine.hpp) and py_validator.hpp (ExternalValidator and
// validate_external_trace, octocd/external.hpp).
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
#include "py_arrays.hpp"
#include "py_engine.hpp"
#include "py_trace_file.hpp"
#include "py_validator.hpp"

using namespace octocd;
using namespace octocd::python_binding;

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
