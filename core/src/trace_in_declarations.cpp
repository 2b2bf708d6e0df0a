// What an external trace declares of its engine and bodies (trace_in.hpp): the
// declarations of design.md section 13b.12, the version 2 physics (inertia, materials,
// contact margin), rotation and contact points, collision shapes, centre-of-mass offsets,
// locked axes and sleeping flags, each checked as it is read.
#include "trace_in.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <string>
#include <tuple>
#include <vector>

#include "octocd/scene.hpp"

namespace octocd {

namespace detail {

void TraceIn::reject_v2_datasets() const {
  for (const char* name : kV2Datasets)
    if (exists(name))
      bad(name, "present in a version 1 file (v1/v2 fields mixed)",
          "root attribute version = 2 with the version 2 datasets, or a version 1 file without them");
}

void TraceIn::scene_defaults() {
  // The numbers only: no mesh named by the trace is looked up here.
  const Scene scene = parse_embedded_scene(bodies.scene_json, path_ + ": / (root attribute scene)", "");
  bodies.physics.mu = scene.response.mu_static;
  bodies.physics.restitution = scene.response.restitution;
  bodies.physics.slop = scene.response.slop;
  det_dt_ = scene.dt;
  det_gravity_ = scene.gravity;
}

void TraceIn::read_v2() {
  PhysicsBodies& p = bodies.physics;
  // The trace's datasets and root attributes of PhysicsBodies' fields, in PhysicsFieldNames' order.
  const PhysicsFieldNames names{"/bodies/inertia",
                                "/bodies/friction",
                                "/bodies/restitution",
                                "/ (root attribute mu)",
                                "/ (root attribute restitution)",
                                "/ (root attribute contact_margin)",
                                "/ (root attribute scene: response.slop)",
                                "/bodies/locked_dofs"};
  const std::string detection = choice_attr("detection", {"pre-step", "integrated"}, "pre-step");
  integrated_ = detection == "integrated";
  if (has_attr("mu")) p.mu = number_attr("mu", 0.0);
  if (has_attr("restitution")) p.restitution = number_attr("restitution", 0.0);
  std::vector<std::string> combines;
  for (MaterialCombine c : {MaterialCombine::Product, MaterialCombine::Min, MaterialCombine::Max,
                            MaterialCombine::Average, MaterialCombine::Geometric})
    combines.push_back(material_combine_name(c));
  p.combine = combine_attr("friction_combine", combines);
  p.restitution_combine = combine_attr("restitution_combine", combines);
  if (has_attr("contact_margin")) p.contact_margin = number_attr("contact_margin", 0.0);
  read_locked_dofs(p);
  read_shape_offsets(p);

  // Per-body tables.
  Dataset inertia = open("/bodies/inertia", H5T_FLOAT, 3, false);
  if (inertia.present()) {
    expect(inertia, {n_, 3, 3}, fmt::format("{} x 3 x 3: one body-frame tensor per body (kg m^2)", n_));
    const std::vector<double> v = read<double>(inertia, 0, n_);
    p.inertia.resize(n_);
    for (hsize_t i = 0; i < n_; ++i)
      std::copy_n(v.begin() + static_cast<std::ptrdiff_t>(9 * i), 9, p.inertia[i].begin());
  } else {
    for (hsize_t i = 0; i < n_; ++i) p.inertia.push_back(box_inertia(bodies.local_boxes[i], bodies.inverse_mass[i]));
  }
  for (const char* name : {"/bodies/friction", "/bodies/restitution"}) {
    Dataset d = open(name, H5T_FLOAT, 1, false);
    if (!d.present()) continue;
    expect(d, {n_}, fmt::format("{} values, one per body (as /bodies/inverse_mass)", n_));
    (std::string(name) == "/bodies/friction" ? p.body_friction : p.body_restitution) = read<float>(d, 0, n_);
  }
  check_physics_bodies(p, bodies.inverse_mass, path_, names);
  read_collision_shapes(p);

  // Rotation: both datasets or neither, with /states.
  orientation_ = open("/states/orientation", H5T_FLOAT, 3, false);
  angular_ = open("/states/angular_velocity", H5T_FLOAT, 3, false);
  if (orientation_.present() != angular_.present())
    bad(orientation_.present() ? "/states/angular_velocity" : "/states/orientation",
        orientation_.present() ? "missing (orientation without angular_velocity)"
                               : "missing (angular_velocity without orientation)",
        "/states/orientation and /states/angular_velocity together, or neither (no rotation)");
  if (orientation_.present()) {
    if (!info.has_states)
      bad(orientation_.name, "without /states/position", "orientations with /states/position and /states/velocity");
    const hsize_t rows = position_.dims[0];
    expect(orientation_, {rows, n_, 4},
           fmt::format("{} x {} x 4, as /states/position: (w, x, y, z) per body", rows, n_));
    expect(angular_, {rows, n_, 3}, fmt::format("{} x {} x 3, as /states/position (rad/s, world frame)", rows, n_));
    info.has_rotation = true;
  }
  c_point_ = open("/contacts/point", H5T_FLOAT, 2, false);
  if (c_point_.present()) {
    if (!info.has_contacts) bad(c_point_.name, "without /contacts/pair", "contact points with /contacts");
    expect(c_point_, {c_pair_.dims[0], 3},
           fmt::format("{} x 3, one world point per contact row (as /contacts/pair)", c_pair_.dims[0]));
    info.has_points = true;
  }
  c_jt3_ = open("/contacts/jt3", H5T_FLOAT, 2, false);
  info.has_jt3 = c_jt3_.present();
  if (c_jt3_.present()) {
    if (!info.has_contacts) bad(c_jt3_.name, "without /contacts/pair", "tangential impulse vectors with /contacts");
    expect(c_jt3_, {c_pair_.dims[0], 3},
           fmt::format("{} x 3, one tangential impulse vector (world, N s) per contact row (as /contacts/pair)",
                       c_pair_.dims[0]));
  }
  // Each row's point on B, where the engine applies B's impulse (two witness points per row).
  c_point_b_ = open("/contacts/point_b", H5T_FLOAT, 2, false);
  info.has_point_b = c_point_b_.present();
  if (c_point_b_.present()) {
    if (!info.has_points)
      bad(c_point_b_.name, "without /contacts/point",
          "each row's point on B with /contacts/point (the row's point on A)");
    expect(c_point_b_, {c_pair_.dims[0], 3},
           fmt::format("{} x 3, one world point (m) on B per contact row (as /contacts/pair)", c_pair_.dims[0]));
  }
}

void TraceIn::read_collision_shapes(PhysicsBodies& p) const {
  const std::vector<std::pair<std::string, CollisionShape>> kinds = {
      {"mesh", CollisionShape::Mesh},
      {"convex_hull", CollisionShape::ConvexHull},
      {"box", CollisionShape::Box},
      {"sphere", CollisionShape::Sphere}};
  const std::string allowed =
      "\"mesh\", \"convex_hull\", \"box\" or \"sphere\" (what the engine collided the body as; docs/trace-format.md)";
  auto kind_of = [&](const std::string& where, const std::string& value) {
    for (const auto& [name, kind] : kinds)
      if (value == name) return kind;
    bad(where, fmt::format("'{}' unknown", value), allowed);
  };
  const bool attr = has_attr("collision_shape"), table = exists("/bodies/collision_shape");
  if (attr && table)
    bad("/bodies/collision_shape", "given with the root attribute collision_shape",
        "one of them: the root attribute (every body) or the dataset (one per body)");
  if (attr) {
    p.collision_shape.assign(n_, kind_of("/ (root attribute collision_shape)", string_attr("collision_shape")));
  } else if (table) {
    const std::vector<std::string> values = h5_->read_strings("/bodies/collision_shape");
    if (values.size() != n_)
      bad("/bodies/collision_shape", fmt::format("{} values", values.size()),
          fmt::format("{} strings, one per body (as /bodies/inverse_mass)", n_));
    for (std::size_t i = 0; i < values.size(); ++i)
      p.collision_shape.push_back(kind_of(fmt::format("/bodies/collision_shape: body {}", i), values[i]));
  }
}

void TraceIn::read_declarations(PhysicsBodies& p) {
  p.broadphase_exact = flag_attr("broadphase_exact", p.broadphase_exact,
                                 "0 (default: any broadphase, extras allowed) or 1 (exactly the overlapping world AABBs)");
  p.contact_geometry = choice_attr("contact_geometry", {"shape", "aabb"}, "shape") == "aabb" ? ContactGeometry::Aabb
                                                                                             : ContactGeometry::Shape;
  p.theta_margin = choice_attr("contact_margin_rule", {"fixed", "theta"}, "fixed") == "theta";
  if (p.theta_margin && !info.has_scene)
    bad("/ (root attribute contact_margin_rule)", "\"theta\" without the root attribute scene",
        "\"theta\" with a scene (each pair's theta comes from its shapes, design.md section 5.3), or \"fixed\"");
  p.jt_along_sliding =
      choice_attr("jt_direction", {"against-sliding", "along-sliding"}, "against-sliding") == "along-sliding";
  if (has_attr("velocity_clamp")) {
    const double c = number_attr("velocity_clamp", 0.0);
    if (!(c >= 0.0 && c <= trace_limits::kMaxSpeed))
      bad("/ (root attribute velocity_clamp)", fmt::format("{}", c),
          fmt::format("a speed per component in [0, {:g}] m/s (0: no clamp)", trace_limits::kMaxSpeed));
    p.velocity_clamp = c;
  }
  p.impulses_complete = flag_attr(
      "impulses_complete", p.impulses_complete,
      "1 (default: the contact rows carry every impulse of the step) or 0 (they do not: momentum-balance n/a)");
  {
    const std::string impulses = choice_attr("impulses", {"complete", "normal-only", "none"}, "complete");
    p.impulses = impulses == "none"          ? PhysicsBodies::Impulses::None
                 : impulses == "normal-only" ? PhysicsBodies::Impulses::NormalOnly
                                             : PhysicsBodies::Impulses::Complete;
  }
  // Fourth-round declarations (docs/trace-format.md, "Declarations").
  p.speculative = flag_attr(
      "speculative", p.speculative,
      "1 (rows may join shapes apart by the contact margin plus their approach within the step) or 0 (default)");
  p.contacts_complete =
      flag_attr("contacts_complete", p.contacts_complete,
                "1 (default: every contact of every step has its rows) or 0 (the engine's API may drop rows)");
  p.persistent_points = choice_attr("manifold_points", {"fixed", "persistent"}, "fixed") == "persistent";
  if (has_attr("normal_reuse_deg")) {
    const double a = number_attr("normal_reuse_deg", 0.0);
    if (!(a >= 0.0 && a <= 180.0))
      bad("/ (root attribute normal_reuse_deg)", fmt::format("{}", a),
          "an angle in [0, 180] degrees: the most a pair's two bodies turn relative to each other while the engine "
          "applies a normal found on an earlier step (0: every step's normals are its own; absent: no bound)");
    p.normal_reuse_deg = a;
  }
  {
    const std::string depth_per = choice_attr("depth_per", {"point", "manifold", "unknown"}, "point");
    p.depth_per_manifold = depth_per == "manifold";
    p.depth_unknown = depth_per == "unknown";
    p.depth_per_declared = has_attr("depth_per");
  }
  p.friction_per_manifold = choice_attr("friction_per", {"point", "manifold"}, "point") == "manifold";
  if (has_attr("friction_directions")) {
    const double d = number_attr("friction_directions", 0.0);
    if (d != 1.0 && d != 2.0)
      bad("/ (root attribute friction_directions)", fmt::format("{}", d),
          "1 (each row's friction along its sliding: the scalar jt is all of it) or 2 (two friction directions: "
          "write /contacts/jt3)");
    p.friction_directions = static_cast<int>(d);
  }
  p.jacobi_response = choice_attr("response_scheme", {"sequential", "jacobi"}, "sequential") == "jacobi";
  p.witness_pair_impulses = choice_attr("impulse_points", {"one", "witness-pair"}, "one") == "witness-pair";
  const std::string deactivation = choice_attr("deactivation", {"undeclared", "off", "on"}, "undeclared");
  p.deactivation = deactivation == "off"  ? PhysicsBodies::Deactivation::Off
                   : deactivation == "on" ? PhysicsBodies::Deactivation::Flagged
                                          : PhysicsBodies::Deactivation::Undeclared;
  const bool declares = has_attr("contact_geometry") || has_attr("jt_direction") || has_attr("contact_margin_rule") ||
                        has_attr("friction_directions") ||
                        has_attr("response_scheme") || has_attr("deactivation");
  info.octocd_conventions = info.version == 1 && !declares && has_attr("parameters") && exists("/frames");
  const std::string contact_model = choice_attr("contact_model", {"rigid", "soft"}, "undeclared");
  p.contact_model = contact_model == "soft"    ? PhysicsBodies::ContactModel::Soft
                    : contact_model == "rigid" ? PhysicsBodies::ContactModel::Rigid
                                               : PhysicsBodies::ContactModel::Undeclared;
  const std::string integrator =
      choice_attr("integrator", {"semi-implicit", "explicit", "any", "substepped"}, "undeclared");
  p.integrator = integrator == "explicit"        ? PhysicsBodies::Integrator::Explicit
                 : integrator == "any"           ? PhysicsBodies::Integrator::Any
                 : integrator == "substepped"    ? PhysicsBodies::Integrator::Substepped
                 : integrator == "semi-implicit" ? PhysicsBodies::Integrator::SemiImplicit
                                                 : PhysicsBodies::Integrator::Undeclared;
  if (integrator == "substepped" || has_attr("substeps")) {
    // An integer n >= 1: the semi-implicit substeps of dt / n the engine takes per step.
    const double n = has_attr("substeps") ? number_attr("substeps", 0.0) : 0.0;
    if (integrator != "substepped")
      bad("/ (root attribute substeps)", "given without integrator = \"substepped\"",
          "substeps with the root attribute integrator = \"substepped\" only");
    if (!(n >= 1.0 && n <= 1e6 && n == std::floor(n)))
      bad("/ (root attribute substeps)", has_attr("substeps") ? fmt::format("{}", n) : "missing",
          "an integer n in [1, 1000000]: the substeps of dt / n per step (integrator \"substepped\")");
    p.substeps = static_cast<int>(n);
  }
  if (has_attr("gyroscopic")) {
    // A string "true" / "false", or an integer 0 / 1 (as broadphase_exact).
    const char* allowed = "\"true\" or \"false\" (a string), or the integer 1 or 0 (default \"false\")";
    std::string text;
    try {
      text = string_attr("gyroscopic");
    } catch (const InputError&) {
      double v = -1.0;
      try {
        v = number_attr("gyroscopic", -1.0);
      } catch (const InputError&) {
        bad("/ (root attribute gyroscopic)", "neither a string nor a number (h5py: write np.int32(1) or \"true\", "
            "not a Python bool, which HDF5 stores as an enum)", allowed);
      }
      if (v != 0.0 && v != 1.0) bad("/ (root attribute gyroscopic)", fmt::format("{}", v), allowed);
      text = v == 1.0 ? "true" : "false";
    }
    if (text != "true" && text != "false")
      bad("/ (root attribute gyroscopic)", fmt::format("'{}' unknown", text), allowed);
    p.gyroscopic = text == "true" ? PhysicsBodies::Gyroscopic::Integrated : PhysicsBodies::Gyroscopic::Absent;
  }
}

void TraceIn::read_incomplete_rows(PhysicsBodies& p) const {
  const std::string name = "/contacts/incomplete";
  if (!exists(name)) return;
  const std::string allowed_shape =
      "K frames (integers, each in 1 .. F: every pair of the step may lack rows) or K x 3 rows (frame, body_a, "
      "body_b: that pair's rows may be missing in that step)";
  const int rank = static_cast<int>(h5_->open_dataset(name).dims.size());
  if (rank != 1 && rank != 2) bad(name, fmt::format("{} dimensions", rank), allowed_shape);
  const Dataset d = open(name, H5T_INTEGER, rank, false);
  if (rank == 2 && d.dims[1] != 3) bad(name, fmt::format("shape {} x {}", d.dims[0], d.dims[1]), allowed_shape);
  if (!info.has_contacts)
    bad(name, "without /contacts", "the steps or pairs whose rows may be missing, with /contacts (offsets and rows)");
  if (!p.contacts_complete)
    bad(name, "given with the root attribute contacts_complete = 0 (every step may lack rows already)",
        "contacts_complete 1 (default) with the steps or pairs listed here, or contacts_complete 0 without them");
  const std::vector<std::int64_t> v = read<std::int64_t>(d, 0, d.dims[0]);
  const std::size_t k = static_cast<std::size_t>(d.dims[0]);
  std::vector<PhysicsBodies::IncompleteRows> rows(k);
  for (std::size_t r = 0; r < k; ++r) {
    const std::int64_t frame = rank == 1 ? v[r] : v[3 * r];
    if (frame < 1 || frame > frames_)
      bad(name, fmt::format("row {}: frame {}", r, frame), fmt::format("a frame in 1 .. {} (the trace's steps)", frames_));
    rows[r].frame = frame;
    rows[r].a = rows[r].b = PhysicsBodies::kEveryPair;
    if (rank == 1) continue;
    const std::int64_t a = v[3 * r + 1], b = v[3 * r + 2];
    for (const std::int64_t body : {a, b})
      if (body < 0 || body >= static_cast<std::int64_t>(n_))
        bad(name, fmt::format("row {}: body {}", r, body),
            fmt::format("a body index in 0 .. {} (as /bodies/inverse_mass)", n_ - 1));
    if (a == b) bad(name, fmt::format("row {}: pair ({}, {})", r, a, b), "two different bodies");
    rows[r].a = static_cast<std::uint32_t>(std::min(a, b));
    rows[r].b = static_cast<std::uint32_t>(std::max(a, b));
  }
  auto key = [](const PhysicsBodies::IncompleteRows& e) { return std::make_tuple(e.frame, e.a, e.b); };
  std::sort(rows.begin(), rows.end(), [&](const auto& l, const auto& r) { return key(l) < key(r); });
  rows.erase(std::unique(rows.begin(), rows.end(), [&](const auto& l, const auto& r) { return key(l) == key(r); }),
             rows.end());
  p.incomplete_rows = std::move(rows);
}

void TraceIn::read_shape_offsets(PhysicsBodies& p) {
  Dataset radius = open("/bodies/convex_radius", H5T_FLOAT, 1, false);
  if (radius.present()) {
    expect(radius, {n_}, fmt::format("{} values, one per body (as /bodies/inverse_mass)", n_));
    const std::vector<double> r = read<double>(radius, 0, n_);
    bool any = false;
    for (hsize_t i = 0; i < n_; ++i) {
      if (!(r[i] >= 0.0 && r[i] <= trace_limits::kMaxCoordinate))
        bad(radius.name, fmt::format("body {}: {}", i, r[i]),
            fmt::format("a radius in [0, {:g}] m per body: the shape the engine collided is the body's shape "
                        "inflated by it (0: not rounded)",
                        trace_limits::kMaxCoordinate));
      any = any || r[i] > 0.0;
    }
    if (any) p.convex_radius = r;
  }
  Dataset com = open("/bodies/com_offset", H5T_FLOAT, 2, false);
  if (com.present()) {
    expect(com, {n_, 3}, fmt::format("{} x 3, one offset per body (m, body frame)", n_));
    const std::vector<double> c = read<double>(com, 0, n_);
    bool any = false;
    for (hsize_t i = 0; i < n_; ++i)
      for (int k = 0; k < 3; ++k) {
        if (!(std::fabs(c[3 * i + k]) <= trace_limits::kMaxCoordinate))
          bad(com.name, fmt::format("body {}: component {}: {}", i, k, c[3 * i + k]),
              fmt::format("|offset| <= {:g} m per component (the centre of mass in the body frame)",
                          trace_limits::kMaxCoordinate));
        any = any || c[3 * i + k] != 0.0;
      }
    if (any) {
      p.com_offset.resize(n_);
      for (hsize_t i = 0; i < n_; ++i) p.com_offset[i] = {c[3 * i], c[3 * i + 1], c[3 * i + 2]};
      com_offset_ = p.com_offset;
      if (!has_attr("velocity_at"))
        bad("/ (root attribute velocity_at)", "missing (with a nonzero /bodies/com_offset)",
            "\"com\" (/states/velocity is the centre of mass's velocity: Jolt, PhysX, Rapier) or \"origin\" "
            "(the body frame origin's, the derivative of /states/position: MuJoCo's free joint)");
      velocity_at_origin_ = choice_attr("velocity_at", {"com", "origin"}, "com") == "origin";
      p.velocity_at_origin = velocity_at_origin_;
    }
  }
  if (com_offset_.empty() && has_attr("velocity_at"))
    choice_attr("velocity_at", {"com", "origin"}, "com");  // checked; the same point without an offset
  // Which point the engine's integrator advances; without an offset both are one point.
  p.integrated_origin = choice_attr("integrated_point", {"com", "origin"}, "com") == "origin";
}

void TraceIn::read_locked_dofs(PhysicsBodies& p) {
  sleeping_ = open("/states/sleeping", H5T_INTEGER, 2, false);
  if (sleeping_.present()) {
    if (!info.has_states) bad(sleeping_.name, "without /states/position", "sleeping flags with /states");
    expect(sleeping_, {position_.dims[0], n_},
           fmt::format("{} x {}: one flag per state row and body, as /states/position", position_.dims[0], n_));
    if (p.deactivation == PhysicsBodies::Deactivation::Off)
      bad(sleeping_.name, "given with the root attribute deactivation = \"off\"",
          "deactivation \"off\" (no body ever sleeps) without /states/sleeping, or the flags with deactivation "
          "\"on\" or undeclared");
    p.deactivation = PhysicsBodies::Deactivation::Flagged;
    info.has_sleeping = true;
  } else if (p.deactivation == PhysicsBodies::Deactivation::Flagged) {
    bad("/states/sleeping", "missing (root attribute deactivation = \"on\")",
        "the flags of the bodies the engine deactivated, S x n (0 awake, 1 asleep), with deactivation \"on\"");
  }
  Dataset locked = open("/bodies/locked_dofs", H5T_INTEGER, 1, false);
  if (locked.present()) {
    expect(locked, {n_}, fmt::format("{} values, one per body (as /bodies/inverse_mass)", n_));
    const std::vector<std::int64_t> v = read<std::int64_t>(locked, 0, n_);
    p.locked_dofs.resize(n_);
    for (hsize_t i = 0; i < n_; ++i) {
      if (v[i] < 0 || v[i] > 63)
        bad(locked.name, fmt::format("body {}: {}", i, v[i]),
            "0 .. 63: bits 0-2 translation along world x, y, z, bits 3-5 rotation about world x, y, z locked");
      p.locked_dofs[i] = static_cast<std::uint8_t>(v[i]);
    }
  }
}

std::string TraceIn::choice_attr(const char* name, const std::vector<std::string>& allowed,
                                 const std::string& fallback) const {
  if (!has_attr(name)) return fallback;
  const std::string value = string_attr(name);
  if (std::find(allowed.begin(), allowed.end(), value) != allowed.end()) return value;
  std::string list;
  for (const std::string& a : allowed) list += (list.empty() ? "\"" : ", \"") + a + "\"";
  bad(fmt::format("/ (root attribute {})", name), fmt::format("'{}' unknown", value),
      fmt::format("{} (default \"{}\")", list, fallback));
}

bool TraceIn::flag_attr(const char* name, bool fallback, const std::string& allowed) const {
  if (!has_attr(name)) return fallback;
  const double v = h5_->number_attribute(name);
  if (v != 0.0 && v != 1.0) bad(fmt::format("/ (root attribute {})", name), fmt::format("{}", v), allowed);
  return v == 1.0;
}

MaterialCombine TraceIn::combine_attr(const char* name, const std::vector<std::string>& names) const {
  const std::string value = choice_attr(name, names, "product");
  for (MaterialCombine c : {MaterialCombine::Product, MaterialCombine::Min, MaterialCombine::Max,
                            MaterialCombine::Average, MaterialCombine::Geometric})
    if (value == material_combine_name(c)) return c;
  return MaterialCombine::Product;
}

}  // namespace detail

}  // namespace octocd
