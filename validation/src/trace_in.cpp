// External traces (docs/trace-format.md, "External traces"): another engine's run read
// frame by frame into FrameRecords, checked, and judged by ExternalValidator.
#include <hdf5.h>

#include <algorithm>
#include <chrono>
#include <future>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <functional>
#include <memory>
#include <string>
#include <tuple>
#include <type_traits>
#include <vector>

#include <fmt/format.h>

#include "octocd/error.hpp"
#include "octocd/exact_pairs.hpp"
#include "octocd/external.hpp"
#include "octocd/shard_spec.hpp"
#include "octocd/text.hpp"
#include "octocd/physics.hpp"
#include "octocd/scene.hpp"
#include "hdf5_handle.hpp"  // core/src (private include)

namespace octocd {

namespace {

using Handle = detail::Hdf5Handle;

/// One dataset: its handle, type and dimensions (hdf5_handle.hpp).
using Dataset = detail::Hdf5Reader::Dataset;

class TraceIn {
 public:
  /// Opens and checks `path`. `with_scene`: the root attribute `scene` is parsed for the
  /// physics defaults (its response's mu_s, e and slop; dt and gravity of the "integrated"
  /// detection pose); false (--check-only) leaves the scene to the validator, as in v1.
  /// `sparse`: /states/frame may skip frames (strictly increasing from 0, as `octocd run
  /// --state-every K` writes); frame f's states are then the recorded row nearest to f
  /// (state_frame(f) names it). Otherwise every frame's state is required.
  /// `recorded` (with `sparse`): TraceStates::Recorded, frames judged on what they carry.
  explicit TraceIn(const std::string& path, bool with_scene = true, bool sparse = false, bool recorded = false)
      : path_(path), sparse_(sparse), recorded_(recorded && sparse) {
    // Opened and read under docs/trace-format.md, "Security rules and limits".
    h5_ = std::make_unique<detail::Hdf5Reader>(path, "an external trace");

    // Root attributes.
    const std::string format = string_attr("format");
    if (format != "octocd-trace")
      bad("/ (root attribute format)", format.empty() ? "missing" : fmt::format("'{}'", format), "\"octocd-trace\"");
    // A 32- or 64-bit integer: a float or uint8 version is refused naming its type.
    const double version = has_attr("version") ? static_cast<double>(h5_->integer_attribute("version")) : -1.0;
    if (version != 1 && version != 2)
      bad("/ (root attribute version)", version < 0 ? "missing" : fmt::format("{}", version),
          "1 or 2 (docs/trace-format.md, External traces)");
    info.version = static_cast<int>(version);
    const std::string engine = string_attr("engine");
    if (!engine.empty()) info.engine = printable(engine);  // shown and stored: control bytes as \xNN
    bodies.scene_json = string_attr("scene");
    bodies.scene_file = path_;  // untrusted: its meshes confined (parse_embedded_scene)
    info.has_scene = !bodies.scene_json.empty();
    if (has_attr("response_model")) {
      const std::string model = string_attr("response_model");
      if (model != "spec6")
        bad("/ (root attribute response_model)", fmt::format("'{}' unknown", model),
            "\"spec6\" (the engine claims octocd's response, design.md section 6), or no attribute (no claim)");
      info.spec6_response = true;
    }
    if (has_attr("dt")) {  // one check for --check-only and the judged run (0, -0 and 1e-300 included)
      const double dt = number_attr("dt", 0.0);
      if (!(dt >= trace_limits::kMinDt && dt <= trace_limits::kMaxDt))
        bad("/ (root attribute dt)", fmt::format("{}", dt),
            fmt::format("a time step in [{:g}, {:g}] s", trace_limits::kMinDt, trace_limits::kMaxDt));
      bodies.dt = static_cast<float>(dt);
    }
    if (h5_->has_attribute("gravity")) {
      const std::vector<double> g = h5_->number_attributes("gravity", 3);
      for (double x : g)
        if (!(std::fabs(x) <= trace_limits::kMaxSpeed))
          bad("/ (root attribute gravity)", fmt::format("({}, {}, {})", g[0], g[1], g[2]),
              fmt::format("gravity (x, y, z) in m/s^2, finite, |component| <= {:g}", trace_limits::kMaxSpeed));
      bodies.gravity = {static_cast<float>(g[0]), static_cast<float>(g[1]), static_cast<float>(g[2])};
    }

    // Bodies.
    Dataset lmin = open("/bodies/local_aabb_min", H5T_FLOAT, 2, true);
    Dataset lmax = open("/bodies/local_aabb_max", H5T_FLOAT, 2, true);
    Dataset mass = open("/bodies/inverse_mass", H5T_FLOAT, 1, true);
    n_ = lmin.dims[0];
    info.bodies = n_;
    if (n_ == 0) bad(lmin.name, "0 bodies", "at least one body");
    if (n_ > trace_limits::kMaxBodies)
      bad(lmin.name, fmt::format("{} bodies", n_), fmt::format("at most {} bodies", trace_limits::kMaxBodies));
    expect(lmin, {n_, 3}, "n x 3 with n = the body count");
    expect(lmax, {n_, 3}, fmt::format("{} x 3, as /bodies/local_aabb_min", n_));
    expect(mass, {n_}, fmt::format("{} values, one per body (as /bodies/local_aabb_min)", n_));
    const std::vector<float> lo = read<float>(lmin, 0, n_), hi = read<float>(lmax, 0, n_);
    bodies.inverse_mass = read<float>(mass, 0, n_);
    for (hsize_t i = 0; i < n_; ++i) {
      bodies.local_boxes.push_back({{lo[3 * i], lo[3 * i + 1], lo[3 * i + 2]}, {hi[3 * i], hi[3 * i + 1], hi[3 * i + 2]}});
      const Aabb& b = bodies.local_boxes.back();
      for (int k = 0; k < 3; ++k) {  // each corner on its own: a NaN max is reported against max
        if (!(std::fabs(b.min[k]) <= trace_limits::kMaxCoordinate))
          bad(lmin.name, fmt::format("body {}: {}", i, b.min[k]), fmt::format("finite, |value| <= {:g} m", trace_limits::kMaxCoordinate));
        if (!(std::fabs(b.max[k]) <= trace_limits::kMaxCoordinate))
          bad(lmax.name, fmt::format("body {}: {}", i, b.max[k]), fmt::format("finite, |value| <= {:g} m", trace_limits::kMaxCoordinate));
      }
      if (!(b.min.x <= b.max.x && b.min.y <= b.max.y && b.min.z <= b.max.z))
        bad(lmax.name, fmt::format("body {}: below /bodies/local_aabb_min", i), "min <= max on every axis");
      const float w = bodies.inverse_mass[i];
      if (!std::isfinite(w) || w < 0.0f)
        bad(mass.name, fmt::format("body {} is {}", i, w), "finite >= 0 (1/kg, 0 = static)");
    }
    // With a scene the bodies come from it; the tables above must agree (checked there).

    // Per-frame data: states and/or world AABBs.
    position_ = open("/states/position", H5T_FLOAT, 3, false);
    velocity_ = open("/states/velocity", H5T_FLOAT, 3, false);
    aabb_min_ = open("/aabbs/min", H5T_FLOAT, 3, false);
    aabb_max_ = open("/aabbs/max", H5T_FLOAT, 3, false);
    if (position_.present() != velocity_.present())
      bad(position_.present() ? "/states/velocity" : "/states/position", "missing",
          "/states/position and /states/velocity together");
    if (aabb_min_.present() != aabb_max_.present())
      bad(aabb_min_.present() ? "/aabbs/max" : "/aabbs/min", "missing", "/aabbs/min and /aabbs/max together");
    if (h5_->has_attribute("committed_states")) {  // an octocd trace: no row past it (docs/trace-format.md)
      const double c = h5_->number_attribute("committed_states");
      if (!(c >= 0.0 && c <= static_cast<double>(trace_limits::kMaxFrames)))
        bad("/ (root attribute committed_states)", fmt::format("{}", c), "a row count >= 0");
      committed_ = true;
      for (Dataset* d : {&position_, &velocity_}) clip(*d, static_cast<hsize_t>(c));
    }
    info.has_states = position_.present();
    info.has_aabbs = aabb_min_.present();
    if (!info.has_states && !info.has_aabbs)
      bad("/states/position", "missing (and no /aabbs/min)",
          "per-frame positions (/states/position, /states/velocity) or world AABBs (/aabbs/min, /aabbs/max)");
    if (info.has_states) {
      if (position_.dims[0] < 2) bad(position_.name, "fewer than 2 rows", "the initial state (row 0) and one row per frame");
      frames_ = static_cast<std::int64_t>(position_.dims[0]) - 1;
      expect(position_, {position_.dims[0], n_, 3}, fmt::format("S x {} x 3 ({} bodies)", n_, n_));
      expect(velocity_, position_.dims, fmt::format("{} x {} x 3, as /states/position", position_.dims[0], n_));
      Dataset frame = open("/states/frame", H5T_INTEGER, 1, false);
      if (frame.present() && frame.dims[0] > position_.dims[0]) frame.dims[0] = position_.dims[0];  // committed rows
      if (frame.present()) {
        expect(frame, {position_.dims[0]}, fmt::format("{} values, one per state row", position_.dims[0]));
        const std::vector<std::int64_t> f = read<std::int64_t>(frame, 0, position_.dims[0]);
        if (sparse_) {
          for (std::size_t r = 0; r < f.size(); ++r)
            if (r == 0 ? f[r] != 0 : !(f[r] > f[r - 1] && f[r] <= static_cast<std::int64_t>(trace_limits::kMaxFrames)))
              bad(frame.name, fmt::format("row {} is frame {}", r, f[r]),
                  fmt::format("frame 0 first, then strictly increasing frames <= {}", trace_limits::kMaxFrames));
          if (f.back() != static_cast<std::int64_t>(f.size()) - 1) {
            state_frames_ = f;
            frames_ = f.back();
            info.sparse_states = true;
          }
        } else {
          for (std::size_t r = 0; r < f.size(); ++r)
            if (f[r] != static_cast<std::int64_t>(r))
              bad(frame.name, fmt::format("row {} is frame {}", r, f[r]),
                  "every frame: 0, 1, 2, ... (write every state, e.g. octocd run --state-every 1)");
        }
      }
    }
    if (info.has_aabbs) {
      const std::int64_t rows = static_cast<std::int64_t>(aabb_min_.dims[0]);
      if (info.has_states && rows != frames_)
        bad(aabb_min_.name, fmt::format("{} rows for {} frames (/states/position has {} rows)", rows, frames_, frames_ + 1),
            "one row per frame (F rows; /states has F + 1, row 0 the initial state)");
      frames_ = rows;
      if (frames_ < 1) bad(aabb_min_.name, "no rows", "one row per frame");
      expect(aabb_min_, {aabb_min_.dims[0], n_, 3}, fmt::format("F x {} x 3 ({} bodies)", n_, n_));
      expect(aabb_max_, aabb_min_.dims, "the shape of /aabbs/min");
    }
    if (static_cast<std::uint64_t>(frames_) > trace_limits::kMaxFrames)
      bad(info.has_aabbs ? aabb_min_.name : position_.name, fmt::format("{} frames", frames_),
          fmt::format("at most {} frames", trace_limits::kMaxFrames));
    info.frames = frames_;

    // Optional pairs and contacts (CSR: offsets per frame into flat rows).
    pair_offsets_ = offsets("/pairs/offsets");
    if (!pair_offsets_.empty()) {
      info.has_pairs = true;
      pairs_ = open("/pairs/pair", H5T_INTEGER, 2, true);
      clip(pairs_, static_cast<hsize_t>(pair_offsets_.back()));
      expect(pairs_, {pairs_.dims[0], 2}, "P x 2 (body indices a, b)");
      rows_match(pairs_, pair_offsets_, "/pairs/offsets");
    }
    contact_offsets_ = offsets("/contacts/offsets");
    if (!contact_offsets_.empty()) {
      info.has_contacts = true;
      c_pair_ = open("/contacts/pair", H5T_INTEGER, 2, true);
      c_normal_ = open("/contacts/normal", H5T_FLOAT, 2, true);
      c_depth_ = open("/contacts/depth", H5T_FLOAT, 1, true);
      c_jn_ = open("/contacts/jn", H5T_FLOAT, 1, true);
      c_jt_ = open("/contacts/jt", H5T_FLOAT, 1, true);
      for (Dataset* d : {&c_pair_, &c_normal_, &c_depth_, &c_jn_, &c_jt_})
        clip(*d, static_cast<hsize_t>(contact_offsets_.back()));
      const hsize_t c = c_pair_.dims[0];
      expect(c_pair_, {c, 2}, "C x 2 (body indices a, b)");
      expect(c_normal_, {c, 3}, fmt::format("{} x 3, one row per contact (as /contacts/pair)", c));
      for (Dataset* d : {&c_depth_, &c_jn_, &c_jt_})
        expect(*d, {c}, fmt::format("{} values, one per contact (as /contacts/pair)", c));
      rows_match(c_pair_, contact_offsets_, "/contacts/offsets");
    }
    det_dt_ = bodies.dt;
    det_gravity_ = bodies.gravity;
    if (with_scene && info.has_scene) scene_defaults();
    read_declarations(bodies.physics);
    if (info.version == 2)
      read_v2();
    else
      reject_v2_datasets();
  }

  ExternalTraceInfo info;
  ExternalBodies bodies;

  /// Step f (1 .. frames) as a FrameRecord, its values checked (check_frame_record).
  FrameRecord frame(std::int64_t f) {
    FrameRecord rec;
    rec.frame = f;
    rec.has_contact_terms = false;  // a trace's contacts: pair, normal, depth, jn, jt (v2: point)
    const hsize_t r = static_cast<hsize_t>(f);
    if (info.has_aabbs) {
      const std::vector<float> lo = read<float>(aabb_min_, r - 1, 1), hi = read<float>(aabb_max_, r - 1, 1);
      rec.aabbs.resize(n_);
      for (hsize_t i = 0; i < n_; ++i)
        rec.aabbs[i] = {{lo[3 * i], lo[3 * i + 1], lo[3 * i + 2]}, {hi[3 * i], hi[3 * i + 1], hi[3 * i + 2]}};
    }
    if (info.has_states && pose_only()) {
      // TraceStates::Recorded: no states; the detection pose from the recorded state f - 1.
      if (posed(f)) {
        const hsize_t row = static_cast<hsize_t>(
            std::lower_bound(state_frames_.begin(), state_frames_.end(), f - 1) - state_frames_.begin());
        rec.x_det = vectors(read<float>(position_, row, 1));
        if (info.version == 1 || integrated_) {  // design.md section 4.1: v + dt g, then x + dt v
          const std::vector<Vec3> v = vectors(read<float>(velocity_, row, 1));
          for (std::size_t i = 0; i < rec.x_det.size(); ++i) {
            Vec3 vi = v[i];
            integrate(rec.x_det[i], vi, bodies.inverse_mass[i], det_gravity_, Vec3{}, det_dt_);
          }
        }
        if (info.has_rotation) rec.q_det = quats(read<float>(orientation_, row, 1));
      }
    } else if (info.has_states) {
      const auto [pre, post] = state_rows(f);
      rec.x_pre = vectors(read<float>(position_, pre, 1));
      rec.v_pre = vectors(read<float>(velocity_, pre, 1));
      rec.x_post = vectors(read<float>(position_, post, 1));
      rec.v_post = vectors(read<float>(velocity_, post, 1));
    }
    rec.has_pairs = info.has_pairs;
    if (info.has_pairs) rec.pairs = pairs(pairs_, pair_offsets_, f);
    if (info.has_contacts) {
      const std::vector<Pair> cp = pairs(c_pair_, contact_offsets_, f);
      const hsize_t first = static_cast<hsize_t>(contact_offsets_[r - 1]), count = cp.size();
      const std::vector<float> nrm = read<float>(c_normal_, first, count), depth = read<float>(c_depth_, first, count),
                               jn = read<float>(c_jn_, first, count), jt = read<float>(c_jt_, first, count);
      for (std::size_t k = 0; k < cp.size(); ++k) {
        ContactRecord c;
        c.pair = cp[k];
        c.normal = {nrm[3 * k], nrm[3 * k + 1], nrm[3 * k + 2]};
        c.depth = depth[k];
        c.jn = jn[k];
        c.jt = jt[k];
        rec.contacts.push_back(c);
      }
    }
    RecordFieldNames names;
    names.aabbs = "/aabbs/min, /aabbs/max";
    names.pairs = "/pairs/pair";
    names.contact_pair = "/contacts/pair";
    names.contact_normal = "/contacts/normal";
    names.contact_depth = "/contacts/depth";
    names.contact_jn = "/contacts/jn";
    names.contact_jt = "/contacts/jt";
    names.x_pre = names.x_post = "/states/position";
    names.v_pre = names.v_post = "/states/velocity";
    if (info.version == 2) fill_v2(rec, f, names);
    check_frame_record(rec, n_, path_, names);
    check_magnitudes(rec);
    return rec;
  }

 private:
  // ---- Version 2 (design.md section 13; docs/trace-format.md, "Version 2"): kept apart from the v1
  // reading above.

  /// The datasets version 2 adds: an error in a version 1 file.
  static constexpr const char* kV2Datasets[] = {"/states/orientation", "/states/angular_velocity",
                                                "/bodies/inertia",     "/contacts/point",
                                                "/bodies/friction",    "/bodies/restitution",
                                                "/contacts/jt3",       "/bodies/collision_shape",
                                                "/bodies/locked_dofs", "/states/sleeping"};

  void reject_v2_datasets() const {
    for (const char* name : kV2Datasets)
      if (exists(name))
        bad(name, "present in a version 1 file (v1/v2 fields mixed)",
            "root attribute version = 2 with the version 2 datasets, or a version 1 file without them");
  }

  /// The physics defaults from the scene (both versions): its response's mu_s, e and slop
  /// (the root attributes and /bodies tables of version 2 override them); its dt and
  /// gravity for the "integrated" detection pose.
  void scene_defaults() {
    // The numbers only: no mesh named by the trace is looked up here.
    const Scene scene = parse_embedded_scene(bodies.scene_json, path_ + ": / (root attribute scene)", "");
    bodies.physics.mu = scene.response.mu_static;
    bodies.physics.restitution = scene.response.restitution;
    bodies.physics.slop = scene.response.slop;
    det_dt_ = scene.dt;
    det_gravity_ = scene.gravity;
  }

  /// Root attributes, /bodies physics, rotation and contact points of a version 2 file.
  void read_v2() {
    PhysicsBodies& p = bodies.physics;
    PhysicsFieldNames names;
    names.inertia = "/bodies/inertia";
    names.body_friction = "/bodies/friction";
    names.body_restitution = "/bodies/restitution";
    names.mu = "/ (root attribute mu)";
    names.restitution = "/ (root attribute restitution)";
    names.contact_margin = "/ (root attribute contact_margin)";
    names.slop = "/ (root attribute scene: response.slop)";
    names.locked_dofs = "/bodies/locked_dofs";
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
  }

  /// What the engine collided each body as (design.md section 13b.10): the root attribute
  /// `collision_shape` (every body) or `/bodies/collision_shape` (one string per body),
  /// each "mesh", "convex_hull", "box" or "sphere"; absent: every body as its shape.
  void read_collision_shapes(PhysicsBodies& p) const {
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

  /// The declarations of design.md section 13b.12 (docs/trace-format.md, "Declarations"),
  /// root attributes of either version: `contact_model`, `gyroscopic`, `integrator`,
  /// `contact_geometry`, `broadphase_exact`, `contact_margin_rule`, `jt_direction`,
  /// `velocity_clamp`, `impulses_complete`, `response_scheme`, `deactivation` (with
  /// /states/sleeping). A version 1 trace of octocd's TraceWriter that declares none of
  /// them (written before they existed: /frames and the root attribute `parameters`) is
  /// read as declaring octocd's conventions (ExternalTraceInfo::octocd_conventions).
  void read_declarations(PhysicsBodies& p) {
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
    {
      const std::string depth_per = choice_attr("depth_per", {"point", "manifold", "unknown"}, "point");
      p.depth_per_manifold = depth_per == "manifold";
      p.depth_unknown = depth_per == "unknown";
      p.depth_per_declared = has_attr("depth_per");
    }
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

  /// /bodies/convex_radius (n, m, >= 0: PhysicsBodies::convex_radius) and
  /// /bodies/com_offset (n x 3, m, body frame: the centre of mass relative to the body
  /// frame's origin that /states/position gives; with a nonzero offset the root attribute
  /// `velocity_at` says which point /states/velocity is the velocity of). The records'
  /// states are turned into the centres of mass (com_state); the detection poses stay the
  /// body frame's (the shapes are placed in it).
  void read_shape_offsets(PhysicsBodies& p) {
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
  }

  /// With a nonzero /bodies/com_offset: the state's positions (and, with `velocity_at`
  /// "origin", velocities) of the body frame's origin turned into its centre of mass's,
  /// x_c = x + R c and v_c = v + w x (R c), so every rule on states (momentum-balance,
  /// free-flight, conservation) judges the centre of mass.
  void com_state(std::vector<Vec3>& x, std::vector<Vec3>& v, const std::vector<Quat>& q,
                 const std::vector<Vec3>& w) const {
    for (std::size_t i = 0; i < x.size() && i < com_offset_.size(); ++i) {
      const auto& c = com_offset_[i];
      const Vec3 cb{static_cast<float>(c[0]), static_cast<float>(c[1]), static_cast<float>(c[2])};
      const Vec3 rc = q.empty() ? cb : rotate(q[i], cb);
      x[i] = x[i] + rc;
      if (velocity_at_origin_ && i < v.size() && !w.empty()) v[i] = v[i] + cross(w[i], rc);
    }
  }

  /// /bodies/locked_dofs (version 2) and /states/sleeping (version 2, with /states).
  void read_locked_dofs(PhysicsBodies& p) {
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

  /// Step f's version 2 fields (the v1 fields are read already).
  void fill_v2(FrameRecord& rec, std::int64_t f, RecordFieldNames& names) {
    const hsize_t r = static_cast<hsize_t>(f);
    names.q_pre = names.q_post = names.q_det = "/states/orientation";
    names.w_pre = names.w_post = "/states/angular_velocity";
    names.x_det = "/states/position";
    names.contact_point = "/contacts/point";
    if (info.has_rotation && !pose_only()) {
      const auto [pre, post] = state_rows(f);
      rec.q_pre = quats(read<float>(orientation_, pre, 1));
      rec.q_post = quats(read<float>(orientation_, post, 1));
      rec.w_pre = vectors(read<float>(angular_, pre, 1));
      rec.w_post = vectors(read<float>(angular_, post, 1));
    }
    if (info.has_sleeping && !pose_only()) {
      read_sleeping(rec, f);
    }
    if (info.has_states && !pose_only()) {
      // Where collision detection ran; never inferred from /aabbs.
      rec.x_det = rec.x_pre;
      rec.q_det = rec.q_pre;
      if (integrated_)  // design.md section 4.1: v + dt g, then x + dt v (float32, as octocd's engines)
        for (std::size_t i = 0; i < rec.x_det.size(); ++i) {
          Vec3 v = rec.v_pre[i];
          integrate(rec.x_det[i], v, bodies.inverse_mass[i], det_gravity_, Vec3{}, det_dt_);
        }
      if (!com_offset_.empty()) {  // the states at the centres of mass; x_det stays the origin
        com_state(rec.x_pre, rec.v_pre, rec.q_pre, rec.w_pre);
        com_state(rec.x_post, rec.v_post, rec.q_post, rec.w_post);
      }
    }
    rec.manifolds = true;
    if (info.has_contacts) {
      for (std::size_t k = 1; k < rec.contacts.size(); ++k)
        if (rec.contacts[k].pair == rec.contacts[k - 1].pair) info.manifolds = true;
      if (info.has_points) {
        const hsize_t first = static_cast<hsize_t>(contact_offsets_[r - 1]);
        const std::vector<Vec3> points = vectors(read<float>(c_point_, first, rec.contacts.size()));
        for (std::size_t k = 0; k < points.size(); ++k) rec.contacts[k].point = points[k];
        rec.has_points = true;
      }
      if (c_jt3_.present()) {
        const hsize_t first = static_cast<hsize_t>(contact_offsets_[r - 1]);
        rec.jt3 = vectors(read<float>(c_jt3_, first, rec.contacts.size()));
        names.contact_jt3 = "/contacts/jt3";
      }
    }
  }

  /// Rows f - 1 and f of /states/sleeping: 0 awake, 1 asleep (any other value exits 2).
  void read_sleeping(FrameRecord& rec, std::int64_t f) const {
    const hsize_t r = static_cast<hsize_t>(f);
    const std::vector<std::int64_t> flags = read<std::int64_t>(sleeping_, r - 1, 2);
    rec.asleep_pre.resize(n_);
    rec.asleep_post.resize(n_);
    for (hsize_t i = 0; i < n_; ++i)
      for (int k = 0; k < 2; ++k) {
        const std::int64_t v = flags[static_cast<std::size_t>(k) * n_ + i];
        if (v != 0 && v != 1)
          bad(sleeping_.name, fmt::format("frame {}: body {}: {}", f - 1 + k, i, v),
              "0 (awake) or 1 (the engine deactivated the body: asleep in that state)");
        (k == 0 ? rec.asleep_pre : rec.asleep_post)[i] = static_cast<std::uint8_t>(v);
      }
  }

  static std::vector<Quat> quats(const std::vector<float>& wxyz) {
    std::vector<Quat> out(wxyz.size() / 4);
    for (std::size_t i = 0; i < out.size(); ++i)
      out[i] = {wxyz[4 * i], wxyz[4 * i + 1], wxyz[4 * i + 2], wxyz[4 * i + 3]};
    return out;
  }

  bool has_attr(const char* name) const { return h5_->has_attribute(name); }

  /// A string attribute that must be one of `allowed` (absent: `fallback`).
  std::string choice_attr(const char* name, const std::vector<std::string>& allowed,
                          const std::string& fallback) const {
    if (!has_attr(name)) return fallback;
    const std::string value = string_attr(name);
    if (std::find(allowed.begin(), allowed.end(), value) != allowed.end()) return value;
    std::string list;
    for (const std::string& a : allowed) list += (list.empty() ? "\"" : ", \"") + a + "\"";
    bad(fmt::format("/ (root attribute {})", name), fmt::format("'{}' unknown", value),
        fmt::format("{} (default \"{}\")", list, fallback));
  }

  /// A 0/1 root attribute as a bool (absent: `fallback`); any other number is an error
  /// naming the attribute with `allowed`.
  bool flag_attr(const char* name, bool fallback, const std::string& allowed) const {
    if (!has_attr(name)) return fallback;
    const double v = h5_->number_attribute(name);
    if (v != 0.0 && v != 1.0) bad(fmt::format("/ (root attribute {})", name), fmt::format("{}", v), allowed);
    return v == 1.0;
  }

  MaterialCombine combine_attr(const char* name, const std::vector<std::string>& names) const {
    const std::string value = choice_attr(name, names, "product");
    for (MaterialCombine c : {MaterialCombine::Product, MaterialCombine::Min, MaterialCombine::Max,
                              MaterialCombine::Average, MaterialCombine::Geometric})
      if (value == material_combine_name(c)) return c;
    return MaterialCombine::Product;
  }

  [[noreturn]] void bad(const std::string& dataset, const std::string& problem, const std::string& allowed) const {
    throw InputError(fmt::format("{}: {}: {}; allowed: {}", path_, dataset, problem, allowed));
  }

  bool exists(const std::string& name) const { return h5_->exists(name); }

  /// In an octocd trace (root attribute committed_states), rows past the committed ones
  /// may never have been written (a failed write: docs/trace-format.md): not read.
  void clip(Dataset& d, hsize_t rows) const {
    if (committed_ && d.present() && !d.dims.empty() && d.dims[0] > rows) d.dims[0] = rows;
  }

  std::string string_attr(const char* name) const {
    return h5_->has_attribute(name) ? h5_->string_attribute(name) : std::string();
  }

  double number_attr(const char* name, double missing) const {
    return h5_->has_attribute(name) ? h5_->number_attribute(name) : missing;
  }

  Dataset open(const std::string& name, H5T_class_t cls, int rank, bool required) const {
    if (!exists(name)) {
      if (required) bad(name, "missing", "a dataset (docs/trace-format.md, External traces)");
      Dataset d;
      d.name = name;
      return d;
    }
    Dataset d = h5_->open_dataset(name);
    if (d.cls != cls)
      bad(name, "wrong type", cls == H5T_FLOAT ? "floating point (float32 or float64)" : "integers");
    if (cls == H5T_FLOAT && d.type_size != 4 && d.type_size != 8)
      bad(name, fmt::format("float{}", 8 * d.type_size), "floating point (float32 or float64)");
    const int r = static_cast<int>(d.dims.size());
    if (r != rank) bad(name, fmt::format("{} dimensions", r), fmt::format("{} dimensions", rank));
    return d;
  }

  void expect(const Dataset& d, const std::vector<hsize_t>& dims, const std::string& allowed) const {
    if (d.dims == dims) return;
    std::string shape;
    for (hsize_t x : d.dims) shape += (shape.empty() ? "" : " x ") + std::to_string(x);
    bad(d.name, fmt::format("shape {}", shape), allowed);
  }

  /// Rows [row, row + count) of `d` (all its trailing dimensions), converted to T.
  template <typename T>
  std::vector<T> read(const Dataset& d, hsize_t row, hsize_t count) const {
    // Sized after the range check: the dataset's declared size is bounded by the file's.
    if (row > d.dims[0] || count > d.dims[0] - row)
      bad(d.name, fmt::format("rows {}..{} asked, it has {}", row, row + count, d.dims[0]), "rows below its length");
    std::vector<T> out(static_cast<std::size_t>(count * d.per_row()));
    if (count == 0) return out;
    hid_t mem_type = H5T_NATIVE_FLOAT;
    if constexpr (std::is_same_v<T, std::int64_t>) mem_type = H5T_NATIVE_INT64;
    if constexpr (std::is_same_v<T, double>) mem_type = H5T_NATIVE_DOUBLE;
    h5_->read_rows(d, row, count, mem_type, out.data());
    return out;
  }

  /// Values that arithmetic must not overflow (docs/trace-format.md, "Security rules and
  /// limits"): every position, position + local extent and AABB corner within
  /// trace_limits::kMaxCoordinate, every velocity within kMaxSpeed, every angular velocity
  /// within kMaxAngularSpeed; checked before FCL or
  /// any tree is built from them.
  void check_magnitudes(const FrameRecord& rec) const {
    const auto coord = [&](const std::vector<Vec3>& xs, const char* name, bool with_extent) {
      for (std::size_t i = 0; i < xs.size(); ++i)
        for (int k = 0; k < 3; ++k) {
          double reach = 0.0;
          if (with_extent && i < bodies.local_boxes.size())
            reach = std::max(std::fabs(static_cast<double>(bodies.local_boxes[i].min[k])),
                             std::fabs(static_cast<double>(bodies.local_boxes[i].max[k])));
          if (!(std::fabs(static_cast<double>(xs[i][k])) + reach <= trace_limits::kMaxCoordinate))
            bad(name, fmt::format("frame {}: body {}: {} (+ local extent {})", rec.frame, i, xs[i][k], reach),
                fmt::format("|position| + |local extent| <= {:g} m on every axis", trace_limits::kMaxCoordinate));
        }
    };
    coord(rec.x_pre, "/states/position", true);
    coord(rec.x_post, "/states/position", true);
    // Every axis of the pre- and post-step vectors (`what` in `unit`) within `limit`.
    const auto per_axis = [&](const std::vector<Vec3>& pre, const std::vector<Vec3>& post, const char* name,
                              const char* what, double limit, const char* unit) {
      for (const std::vector<Vec3>* v : {&pre, &post})
        for (std::size_t i = 0; i < v->size(); ++i)
          for (int k = 0; k < 3; ++k)
            if (!(std::fabs((*v)[i][k]) <= limit))
              bad(name, fmt::format("frame {}: body {}: {}", rec.frame, i, (*v)[i][k]),
                  fmt::format("|{}| <= {:g} {} per axis", what, limit, unit));
    };
    per_axis(rec.v_pre, rec.v_post, "/states/velocity", "velocity", trace_limits::kMaxSpeed, "m/s");
    per_axis(rec.w_pre, rec.w_post, "/states/angular_velocity", "angular velocity", trace_limits::kMaxAngularSpeed,
             "rad/s");
    const std::string impulse_allowed =
        fmt::format("|impulse| <= {:g} N s (trace_limits::kMaxImpulse)", trace_limits::kMaxImpulse);
    for (std::size_t k = 0; k < rec.contacts.size(); ++k) {
      const ContactRecord& c = rec.contacts[k];
      if (!(std::fabs(c.jn) <= trace_limits::kMaxImpulse))
        bad("/contacts/jn", fmt::format("frame {}: contact {}: {}", rec.frame, k, c.jn), impulse_allowed);
      if (!(std::fabs(c.jt) <= trace_limits::kMaxImpulse))
        bad("/contacts/jt", fmt::format("frame {}: contact {}: {}", rec.frame, k, c.jt), impulse_allowed);
      if (!(std::fabs(c.depth) <= trace_limits::kMaxCoordinate))
        bad("/contacts/depth", fmt::format("frame {}: contact {}: {}", rec.frame, k, c.depth),
            fmt::format("|depth| <= {:g} m", trace_limits::kMaxCoordinate));
      if (rec.has_points)
        for (int a = 0; a < 3; ++a)
          if (!(std::fabs(c.point[a]) <= trace_limits::kMaxCoordinate))
            bad("/contacts/point", fmt::format("frame {}: contact {}: {}", rec.frame, k, c.point[a]),
                fmt::format("|coordinate| <= {:g} m", trace_limits::kMaxCoordinate));
    }
    for (std::size_t k = 0; k < rec.jt3.size(); ++k)
      for (int a = 0; a < 3; ++a)
        if (!(std::fabs(rec.jt3[k][a]) <= trace_limits::kMaxImpulse))
          bad("/contacts/jt3", fmt::format("frame {}: contact {}: {}", rec.frame, k, rec.jt3[k][a]), impulse_allowed);
    for (std::size_t i = 0; i < rec.aabbs.size(); ++i)
      for (int k = 0; k < 3; ++k)
        for (float x : {rec.aabbs[i].min[k], rec.aabbs[i].max[k]})
          if (!(std::fabs(x) <= trace_limits::kMaxCoordinate))
            bad("/aabbs/min, /aabbs/max", fmt::format("frame {}: body {}: {}", rec.frame, i, x),
                fmt::format("|corner| <= {:g} m", trace_limits::kMaxCoordinate));
  }

  std::vector<Vec3> vectors(const std::vector<float>& xyz) const {
    std::vector<Vec3> out(xyz.size() / 3);
    for (std::size_t i = 0; i < out.size(); ++i) out[i] = {xyz[3 * i], xyz[3 * i + 1], xyz[3 * i + 2]};
    return out;
  }

  /// A CSR offsets dataset: F + 1 values, 0 first, never decreasing. Empty when absent.
  std::vector<std::int64_t> offsets(const std::string& name) const {
    Dataset d = open(name, H5T_INTEGER, 1, false);
    clip(d, static_cast<hsize_t>(frames_ + 1));
    if (!d.present()) {
      const std::string group = name.substr(0, name.rfind('/'));
      if (exists(group)) bad(name, "missing", fmt::format("{} with {} as CSR offsets (F + 1 values)", group, name));
      return {};
    }
    expect(d, {static_cast<hsize_t>(frames_ + 1)},
           fmt::format("{} values: F + 1 for the {} frames", frames_ + 1, frames_));
    std::vector<std::int64_t> o = read<std::int64_t>(d, 0, d.dims[0]);
    if (o[0] != 0) bad(name, fmt::format("row 0 is {}", o[0]), "0 first");
    for (std::size_t i = 1; i < o.size(); ++i)
      if (o[i] < o[i - 1])
        bad(name, fmt::format("frame {}: row {} is {} after {}", i, i, o[i], o[i - 1]),
            "offsets that never decrease (frame f's rows are offsets[f-1] .. offsets[f]-1)");
    return o;
  }

  void rows_match(const Dataset& d, const std::vector<std::int64_t>& o, const std::string& offsets_name) const {
    if (static_cast<hsize_t>(o.back()) != d.dims[0])
      bad(offsets_name, fmt::format("last value {} but {} has {} rows", o.back(), d.name, d.dims[0]),
          fmt::format("the last offset equals the rows of {}", d.name));
  }

  /// Frame f's rows of a P x 2 pair dataset.
  std::vector<Pair> pairs(const Dataset& d, const std::vector<std::int64_t>& o, std::int64_t f) const {
    const hsize_t first = static_cast<hsize_t>(o[static_cast<std::size_t>(f - 1)]);
    const hsize_t count = static_cast<hsize_t>(o[static_cast<std::size_t>(f)]) - first;
    const std::vector<std::int64_t> v = read<std::int64_t>(d, first, count);
    std::vector<Pair> out(count);
    for (std::size_t k = 0; k < out.size(); ++k) {
      const std::int64_t a = v[2 * k], b = v[2 * k + 1];
      if (a < 0 || b < 0 || a >= static_cast<std::int64_t>(n_) || b >= static_cast<std::int64_t>(n_))
        bad(d.name, fmt::format("frame {}: row {} is ({}, {}): body index out of range", f, k, a, b),
            fmt::format("body indices in [0, {})", n_));
      out[k] = {static_cast<std::uint32_t>(a), static_cast<std::uint32_t>(b)};
    }
    return out;
  }

  /// The state rows of frame f: (f - 1, f) when every frame has its state; with sparse
  /// states both are the row nearest to f (state_frame(f)).
  std::pair<hsize_t, hsize_t> state_rows(std::int64_t f) const {
    if (state_frames_.empty()) return {static_cast<hsize_t>(f - 1), static_cast<hsize_t>(f)};
    const hsize_t r = nearest_row(f);
    return {r, r};
  }

  hsize_t nearest_row(std::int64_t f) const {
    const auto at = std::lower_bound(state_frames_.begin(), state_frames_.end(), f);
    if (at == state_frames_.end()) return static_cast<hsize_t>(state_frames_.size() - 1);
    if (at == state_frames_.begin() || *at - f <= f - *(at - 1)) return static_cast<hsize_t>(at - state_frames_.begin());
    return static_cast<hsize_t>(at - state_frames_.begin() - 1);
  }

 public:
  /// TraceStates::Recorded with sparse states: records carry detection poses, no states.
  bool pose_only() const { return recorded_ && !state_frames_.empty(); }
  /// Step f can be judged on its pose: every step unless pose_only(), then the steps whose
  /// pre-step state (frame f - 1) is recorded, or any step of a version 1 trace with
  /// /aabbs (its poses are the boxes; version 2 never infers a pose from them).
  bool posed(std::int64_t f) const {
    return !pose_only() || (info.has_aabbs && info.version == 1) ||
           std::binary_search(state_frames_.begin(), state_frames_.end(), f - 1);
  }
  /// The frame whose recorded state frame(f) carries: f itself unless states are sparse.
  std::int64_t state_frame(std::int64_t f) const {
    return state_frames_.empty() ? f : state_frames_[nearest_row(f)];
  }
  /// The first frame with a contact row (0: none). Without /contacts, octocd's own
  /// per-frame counts (/frames/frame, /frames/contacts) when the trace has them.
  std::int64_t first_contact_frame() const {
    for (std::size_t f = 1; f < contact_offsets_.size(); ++f)
      if (contact_offsets_[f] > contact_offsets_[f - 1]) return static_cast<std::int64_t>(f);
    if (info.has_contacts || !exists("/frames/frame") || !exists("/frames/contacts")) return 0;
    Dataset frame = open("/frames/frame", H5T_INTEGER, 1, false), count = open("/frames/contacts", H5T_INTEGER, 1, false);
    const hsize_t rows = std::min({frame.dims[0], count.dims[0], static_cast<hsize_t>(frames_)});
    const std::vector<std::int64_t> f = read<std::int64_t>(frame, 0, rows), c = read<std::int64_t>(count, 0, rows);
    for (hsize_t r = 0; r < rows; ++r)
      if (c[r] > 0 && f[r] >= 1 && f[r] <= frames_) return f[r];
    return 0;
  }
  /// With sparse states: the recorded state frames (/states/frame); else empty.
  const std::vector<std::int64_t>& state_frames() const { return state_frames_; }
  /// What frame(f) depends on beyond the file: whether states may be sparse, and the
  /// "integrated" detection pose's dt and gravity (the scene's when read with it).
  struct RecordSettings {
    bool sparse = false, integrated = false;
    float dt = 0.0f;
    Vec3 gravity{};
    bool recorded = false;
  };
  RecordSettings record_settings() const { return {sparse_, integrated_, det_dt_, det_gravity_, recorded_}; }
  /// True when frame(f) of a reader of the same file with `other` settings gives this
  /// reader's record: the same state rows and the same detection pose.
  bool same_records(const RecordSettings& other) const {
    const auto same_bits = [](const auto& a, const auto& b) { return std::memcmp(&a, &b, sizeof a) == 0; };
    return sparse_ == other.sparse && recorded_ == other.recorded && integrated_ == other.integrated &&
           (!(integrated_ || recorded_) || (same_bits(det_dt_, other.dt) && same_bits(det_gravity_, other.gravity)));
  }
  /// True when /states/frame skips frames (read with `sparse`).
  bool sparse_states() const { return !state_frames_.empty(); }

 private:
  std::string path_;
  bool sparse_ = false;                     // /states/frame may skip frames
  bool recorded_ = false;                   // TraceStates::Recorded (with sparse_)
  std::vector<std::int64_t> state_frames_;  // with sparse states: /states/frame; else empty
  std::unique_ptr<detail::Hdf5Reader> h5_;  // quiets HDF5's error printing while it lives
  bool committed_ = false;                  // the trace has committed_states (octocd's own)
  hsize_t n_ = 0;
  std::int64_t frames_ = 0;
  Dataset position_, velocity_, aabb_min_, aabb_max_, pairs_, c_pair_, c_normal_, c_depth_, c_jn_, c_jt_, c_jt3_;
  // Version 2.
  Dataset orientation_, angular_, c_point_, sleeping_;
  bool integrated_ = false;  ///< root attribute detection = "integrated"
  /// /bodies/com_offset (body frame, m; empty: every offset 0) and root attribute
  /// `velocity_at` "origin" (read_shape_offsets, com_state).
  std::vector<std::array<double, 3>> com_offset_;
  bool velocity_at_origin_ = false;
  float det_dt_ = 0.001f;    ///< dt and gravity of the "integrated" detection pose
  Vec3 det_gravity_{};
  std::vector<std::int64_t> pair_offsets_, contact_offsets_;
};

}  // namespace

struct ExternalTrace::Impl {
  Impl(const std::string& file, TraceStates states)
      : in(file, true, states != TraceStates::EveryFrame, states == TraceStates::Recorded), path(file) {}
  TraceIn in;
  std::string path;
};

ExternalTrace::ExternalTrace(const std::string& path, TraceStates states)
    : impl_(std::make_unique<Impl>(path, states)) {}
std::int64_t ExternalTrace::state_frame(std::int64_t f) const { return impl_->in.state_frame(f); }
std::int64_t ExternalTrace::first_contact_frame() const { return impl_->in.first_contact_frame(); }
bool ExternalTrace::sparse_states() const { return impl_->in.sparse_states(); }
const std::vector<std::int64_t>& ExternalTrace::state_frames() const { return impl_->in.state_frames(); }
ExternalTrace::~ExternalTrace() = default;
const ExternalTraceInfo& ExternalTrace::info() const { return impl_->in.info; }
const ExternalBodies& ExternalTrace::bodies() const { return impl_->in.bodies; }
FrameRecord ExternalTrace::frame(std::int64_t f) {
  if (f < 1 || f > impl_->in.info.frames)
    throw InputError(
        fmt::format("{}: frame {}: out of range; allowed: 1 .. {}", impl_->path, f, impl_->in.info.frames));
  return impl_->in.frame(f);
}

namespace {

/// The bytes a decoded record holds in its arrays (the check pass's budget for the frames
/// it keeps).
std::size_t record_bytes(const FrameRecord& r) {
  return sizeof(FrameRecord) +
         (r.x_pre.size() + r.v_pre.size() + r.x_post.size() + r.v_post.size() + r.w_pre.size() + r.w_post.size() +
          r.x_det.size() + r.jt3.size()) *
             sizeof(Vec3) +
         (r.q_pre.size() + r.q_post.size() + r.q_det.size()) * sizeof(Quat) + r.aabbs.size() * sizeof(Aabb) +
         (r.pairs.size() + r.confirmed.size()) * sizeof(Pair) + r.contacts.size() * sizeof(ContactRecord) +
         r.asleep_pre.size() + r.asleep_post.size();
}

/// At most this many bytes of decoded frames are kept from the check pass for the judging
/// (the frames beyond are decoded a second time, as the judging reaches them).
constexpr std::size_t kKeptFrameBytes = std::size_t(256) << 20;

/// The frames the check pass decoded that the judging takes instead of decoding them again:
/// frames first .. first + records.size() - 1, each taken once.
struct KeptFrames {
  std::int64_t max_frames = 0;  ///< the frames judged: 1 .. max_frames (0: all) ...
  ShardSpec shard;              ///< ... this shard's block of them, which is kept
  std::int64_t first = 1;
  std::vector<FrameRecord> records;
  TraceIn::RecordSettings settings;  ///< what the records were read with
  bool has(std::int64_t f) const { return f >= first && f - first < static_cast<std::int64_t>(records.size()); }
  FrameRecord take(std::int64_t f) { return std::move(records[static_cast<std::size_t>(f - first)]); }
};

/// Every frame's values checked with a reader that does not parse the scene (as
/// --check-only); `stop` (may be empty) polled between frames. With `keep`: the frames its
/// run judges are kept as decoded, from the first on, up to kKeptFrameBytes, and
/// `keep->settings` says what they were read with. The reader is closed on return.
ExternalTraceInfo check_frames(const std::string& path, const std::function<bool()>& stop,
                               KeptFrames* keep = nullptr, bool recorded = false) {
  TraceIn in(path, false, recorded, recorded);
  std::int64_t last = 0;
  if (keep) {
    const std::int64_t run = keep->max_frames > 0 ? std::min(keep->max_frames, in.info.frames) : in.info.frames;
    std::tie(keep->first, last) = shard_frames(keep->shard, run);
  }
  std::size_t bytes = 0;
  bool keeping = keep != nullptr;
  for (std::int64_t f = 1; f <= in.info.frames; ++f) {
    if (stop && stop()) throw ValidationStopped();
    if (!in.posed(f)) continue;  // TraceStates::Recorded: a step without its pre-step state is not judged
    FrameRecord rec = in.frame(f);
    if (!keeping || f < keep->first) continue;
    bytes += record_bytes(rec);
    keeping = f <= last && bytes <= kKeptFrameBytes;
    if (keeping) keep->records.push_back(std::move(rec));
  }
  if (keep) keep->settings = in.record_settings();
  return in.info;
}

}  // namespace

ExternalTraceInfo check_external_trace(const std::string& path) { return check_frames(path, {}, nullptr, true); }

std::vector<ValidationResult> validate_external_trace(const std::string& path, ExternalOptions options, int every,
                                                      std::int64_t max_frames, ExternalTraceInfo* info) {
  if (every < 1) throw InputError(fmt::format("--every: {}; allowed: >= 1", every));
  // The trace is decoded once: the check pass (every frame's values, before any verdict)
  // keeps the frames this run judges (the shard's block, or frames 1 .. --frames), up to
  // kKeptFrameBytes, and the judging takes them instead of reading them again.
  KeptFrames kept;
  kept.max_frames = max_frames;
  kept.shard = options.shard;
  // States every K-th frame are read as recorded (TraceStates::Recorded): each step is
  // judged on what it carries.
  const ExternalTraceInfo checked = check_frames(path, options.stop, &kept, true);
  TraceIn in(path, true, true, true);
  if (!in.same_records(kept.settings)) kept.records.clear();  // an "integrated" pose from the scene's dt and gravity
  options.engine = in.info.engine;
  options.spec6_response = in.info.spec6_response;
  options.octocd_engine = in.info.octocd_conventions;  // declared by the trace's layout, never by its engine name
  // With a scene, the bodies come from it and the trace's tables must match it.
  // The bodies' declarations are checked against the scene's shapes where the validators
  // are built: an error about them names the file and its dataset.
  auto named = [&](const InputError& e) {
    std::string what = e.what();
    const std::string field = "PhysicsBodies.collision_shape";
    const std::size_t at = what.find(field);
    if (at == std::string::npos || in.bodies.physics.collision_shape.empty()) throw;  // as it came
    what.replace(at, field.size(), "/bodies/collision_shape (or the root attribute collision_shape)");
    throw InputError(fmt::format("{}: {}", path, what));
  };
  std::unique_ptr<ExternalValidator> made;
  const std::int64_t frames = max_frames > 0 ? std::min(max_frames, in.info.frames) : in.info.frames;
  std::int64_t judged_to = 0, judging = 0;  // the last frame judged whole; the frame in its checks
  constexpr std::chrono::milliseconds kSnapshotEvery{20};  // options.on_judged's pace
  std::chrono::steady_clock::time_point last_snapshot{};
  bool stopped = false;
  try {
    made = std::make_unique<ExternalValidator>(in.bodies, options);
    if (options.on_judged) {  // judging begins: the verdict of no whole frame
      ExternalTraceInfo now = checked;
      now.frames = frames;
      now.judged_to = 0;
      options.on_judged(made->results(), now);
    }
    // A shard judges its block of the run's frames; checked frames keep the run's numbering.
    // Frame f + 1 is read (HDF5, on a second thread: the only one that calls HDF5 meanwhile)
    // while frame f is judged.
    const auto [first, last] = shard_frames(options.shard, frames);
    // A shard of soft contacts: the energy of an isolated group is judged over its contact
    // episode, which may cross the shard's borders. The shard judges the episodes that
    // begin in its frames: it follows the episodes through the frames before its own
    // (those open at its first frame began in an earlier shard, which judges them) and
    // reads on past its last frame until its own episodes have closed, so the merged
    // verdict equals the whole run's.
    const bool episodes = options.shard.count > 1 && made->judges_episodes() && first <= last && !in.pose_only();
    if (episodes) {
      made->set_episode_frames(first, last);
      for (std::int64_t f = 1; f < first; ++f) {
        if (options.stop && options.stop()) throw ValidationStopped();
        made->observe_episodes(in.frame(f));
      }
    }
    // A frame the check pass kept is taken as it is; another is read on the second thread.
    auto fetch = [&in, &kept](std::int64_t f) {
      if (kept.has(f)) return std::async(std::launch::deferred, [&kept, f] { return kept.take(f); });
      return std::async(std::launch::async, [&in, f] { return in.frame(f); });
    };
    // With sparse states only the steps whose pre-step state is recorded (each checked:
    // they are already one in K).
    auto next_posed = [&in, last](std::int64_t f) {
      while (f <= last && !in.posed(f)) ++f;
      return f;
    };
    std::future<FrameRecord> next;
    std::int64_t f = next_posed(first);
    if (f <= last) next = fetch(f);
    for (; f <= last;) {
      if (options.stop && options.stop()) throw ValidationStopped();
      const FrameRecord rec = next.get();
      const std::int64_t after = next_posed(f + 1);
      if (after <= last) next = fetch(after);
      judging = f;
      made->observe(rec, in.pose_only() || f % every == 0);
      judged_to = std::min(after - 1, last);  // the steps skipped up to the next posed one are done
      judging = 0;
      if (options.on_judged &&
          (f == next_posed(first) || std::chrono::steady_clock::now() - last_snapshot >= kSnapshotEvery)) {
        ExternalTraceInfo now = checked;
        now.frames = frames;
        now.judged_to = judged_to;
        options.on_judged(made->results(), now);
        last_snapshot = std::chrono::steady_clock::now();
      }
      f = after;
    }
    if (first <= last && next_posed(first) > last) judged_to = last;
    for (std::int64_t f = last + 1; episodes && f <= frames && made->episodes_pending(); ++f) {
      if (options.stop && options.stop()) throw ValidationStopped();
      made->observe_episodes(in.frame(f));
    }
  } catch (const PairLimitError& e) {
    throw PairLimitError(fmt::format("{}: {}", path, e.what()), e);  // "T: frame F: ..."
  } catch (const InputError& e) {
    named(e);
  } catch (const ValidationStopped&) {
    if (!options.keep_on_stop || !made) throw;
    stopped = true;  // the verdict of the frames judged so far
  }
  ExternalValidator& validator = *made;
  std::vector<ValidationResult> results = validator.results();
  apply_trace_plan(results, plan_trace_rows(checked, in.bodies));
  if (info) {
    *info = checked;
    info->frames = frames;
    info->judged_to = judged_to;
    info->stopped_in = judging;
    info->stopped = stopped;
  }
  return results;
}

}  // namespace octocd
