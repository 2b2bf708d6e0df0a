#pragma once
/// \file py_validator.hpp
/// octocd.Validator's compiled half: judging another engine's frames (octocd/external.hpp's
/// ExternalValidator) from arrays, its declarations and tolerances (docs/python.md).

#include "py_arrays.hpp"

namespace octocd::python_binding {

// ---- judging another engine ----------------------------------------------------------

inline MaterialCombine parse_combine(const std::string& s) {
  for (MaterialCombine c : {MaterialCombine::Product, MaterialCombine::Min, MaterialCombine::Max,
                            MaterialCombine::Average, MaterialCombine::Geometric})
    if (s == material_combine_name(c)) return c;
  throw InputError(fmt::format("physics['combine']: '{}'; allowed: product, min, max, average, geometric", s));
}

/// What an engine that declares nothing gets, as a trace without declarations: the
/// integrator and the contact model undeclared (every admissible value,
/// docs/validation.md, "Undeclared: every admissible value").
inline PhysicsBodies undeclared_physics() {
  PhysicsBodies p;
  p.integrator = PhysicsBodies::Integrator::Undeclared;
  p.contact_model = PhysicsBodies::ContactModel::Undeclared;
  return p;
}

/// PhysicsBodies from a dict (keys as the C++ member names).
inline PhysicsBodies parse_physics(const py::dict& d, py::ssize_t n) {
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

inline void apply_tolerances(ExternalOptions& o, const py::object& tolerances) {
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
inline void check_mesh_argument(const Mesh& mesh, const std::string& arg) {
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
/// One component `c` of row `row` of argument `arg`: InputError naming them unless |c| <= limit.
inline void check_coordinate(float c, std::size_t row, const char* arg, double limit, const char* what) {
  if (!(std::fabs(c) <= limit))
    throw InputError(fmt::format("{}: row {} holds {}; allowed: {} with |component| <= {:g}", arg, row, c, what, limit));
}

/// Every component of every row of `xs` (check_coordinate).
inline void check_coordinates(const std::vector<Vec3>& xs, const char* arg, double limit, const char* what) {
  for (std::size_t i = 0; i < xs.size(); ++i)
    for (int k = 0; k < 3; ++k) check_coordinate(xs[i][k], i, arg, limit, what);
}

/// Every corner component of every box of `boxes`, row by row (check_coordinate).
inline void check_coordinates(const std::vector<Aabb>& boxes, const char* arg, double limit, const char* what) {
  for (std::size_t i = 0; i < boxes.size(); ++i)
    for (int k = 0; k < 3; ++k) {
      check_coordinate(boxes[i].min[k], i, arg, limit, what);
      check_coordinate(boxes[i].max[k], i, arg, limit, what);
    }
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
      check_coordinates(b.local_boxes, "local_boxes", trace_limits::kMaxCoordinate, "local box corners (m)");
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
                         "(C,), 'jt': (C,)[, 'point': (C, 3)[, 'point_b': (C, 3)]][, 'jt3': (C, 3)]}");
      const py::dict c = py::reinterpret_borrow<py::dict>(contacts);
      // octocd's own FrameRecord.contacts adds the design.md section 6 terms: accepted and ignored (the
      // validators derive them from the states), so an octocd record can be fed back.
      static const char* const kKeys[] = {"pair", "normal", "depth", "jn", "jt", "point", "point_b", "jt3",
                                          "axis", "v_a", "v_b", "dx_a", "dx_b", "dv_a", "dv_b"};
      for (auto item : c) {
        const std::string k = py::str(item.first);
        if (std::find(std::begin(kKeys), std::end(kKeys), k) == std::end(kKeys))
          throw InputError(fmt::format("contacts: unknown key '{}'; allowed: pair, normal, depth, jn, jt, point, point_b, jt3 "
                                       "(and, ignored, the design.md section 6 terms of octocd's records: axis, v_a, v_b, dx_a, "
                                       "dx_b, dv_a, dv_b)",
                                       k));
      }
      for (const char* k : {"pair", "normal", "depth", "jn", "jt"})
        if (!c.contains(k))
          throw InputError(fmt::format("contacts: no '{}'; allowed: a dict with pair (C, 2), normal (C, 3), depth, "
                                       "jn, jt (C,) and optionally point, point_b, jt3 (C, 3)",
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
      // Each row's point on B (two witness points per row: checked to come with `point`) and
      // its tangential impulse vector on A (docs/trace-format.md, /contacts/point_b, /contacts/jt3).
      if (c.contains("point_b"))
        rec.point_b = vec3s(c["point_b"], "contacts['point_b']", cn, "world contact point on B (m)");
      if (c.contains("jt3"))
        rec.jt3 = vec3s(c["jt3"], "contacts['jt3']", cn, "friction impulse vector on A (kg m/s)");
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
    check_coordinates(rec.aabbs, "aabbs", trace_limits::kMaxCoordinate, "world AABB corners (m)");
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

inline ValidationResult result_from(const py::handle& r) {
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

}  // namespace octocd::python_binding
