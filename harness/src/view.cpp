// A viewer of a frame (design.md section 16, octocd/view.hpp): a trace read through the hardened
// external-trace reader, the bodies near an item, the engine's contacts and the physics
// tier's reference for them, written as one self-contained HTML page.
#include "octocd/view.hpp"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <initializer_list>
#include <map>
#include <memory>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "octocd/atomic_file.hpp"
#include "octocd/error.hpp"
#include "octocd/external.hpp"
#include "octocd/physics.hpp"
#include "octocd/reference_contact.hpp"
#include "physics/reference.hpp"  // validation/physics (private include of octocd_harness)
#include "view_page.hpp"

namespace octocd {

namespace {

using Json = nlohmann::ordered_json;

/// A float as the shortest decimal that reads back to it (keeps the page small).
Json as_float(double v) {
  if (!std::isfinite(v)) return nullptr;
  return std::strtod(fmt::format("{}", static_cast<float>(v)).c_str(), nullptr);
}
Json vec(Vec3 v) { return Json::array({as_float(v.x), as_float(v.y), as_float(v.z)}); }

std::string read_text(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in)
    throw RuntimeError(fmt::format("view: {}: cannot be read; allowed: Debian's libjs-three installed (apt-get "
                                   "install libjs-three), or ViewSettings::three_dir naming its folder",
                                   path.string()));
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

/// Text placed inside a <script> element: "</" never closes it early.
std::string script_safe(std::string text) {
  for (std::size_t at = text.find("</"); at != std::string::npos; at = text.find("</", at + 3))
    text.replace(at, 2, "<\\/");
  return text;
}

/// JSON placed inside <script type="application/json">: '<', '>' and '&' as \u escapes
/// (they can only occur inside JSON strings), so no markup can appear.
std::string json_safe(const std::string& text) {
  std::string out;
  out.reserve(text.size());
  for (char c : text) {
    if (c == '<') out += "\\u003c";
    else if (c == '>') out += "\\u003e";
    else if (c == '&') out += "\\u0026";
    else out += c;
  }
  return out;
}

double box_distance(const Aabb& a, const Aabb& b) {
  double s = 0;
  for (int k = 0; k < 3; ++k) {
    const double gap = std::max({0.0, double(a.min[k]) - b.max[k], double(b.min[k]) - a.max[k]});
    s += gap * gap;
  }
  return std::sqrt(s);
}

Aabb merged(const Aabb& a, const Aabb& b) {
  return {{std::min(a.min.x, b.min.x), std::min(a.min.y, b.min.y), std::min(a.min.z, b.min.z)},
          {std::max(a.max.x, b.max.x), std::max(a.max.y, b.max.y), std::max(a.max.z, b.max.z)}};
}

/// The pose each body had when the engine detected contacts (physics tier's rule), with
/// octocd's integration of x_pre when a record gives neither detection poses nor AABBs.
/// `recorded`: the frame has no state of its own (sparse states); the bodies are drawn at
/// the recorded state the reader gave (x_post, q_post).
std::vector<Pose> detection_poses(const Model& model, const FrameRecord& rec, bool recorded) {
  const std::size_t n = model.bodies.size();
  std::vector<Pose> out(n);
  for (std::size_t i = 0; i < n; ++i) {
    if (recorded && rec.x_post.size() == n) {
      out[i] = Pose{rec.x_post[i], rec.q_post.size() == n ? rec.q_post[i] : Quat{}};
    } else if (!rec.x_det.empty() || rec.aabbs.size() == n) {
      out[i] = detection_pose(model, rec, i);
    } else {
      Vec3 x = rec.x_pre[i], v = rec.v_pre[i];
      integrate(x, v, model.initial.w[i], model.scene.gravity, Vec3{}, model.scene.dt);
      out[i] = Pose{x, rec.q_pre.size() == n ? rec.q_pre[i] : Quat{}};
    }
  }
  return out;
}

/// One drawable shape: a body's shape as the engine declared it collided.
Json shape_json(const Model& model, const ReferenceGeometry& ref, std::uint32_t body, CollisionShape declared) {
  const Shape& s = model.shapes[model.bodies[body].shape];
  if (!s.mesh || declared == CollisionShape::Box)
    return Json{{"kind", "box"}, {"min", vec(s.local.min)}, {"max", vec(s.local.max)}};
  if (declared == CollisionShape::Sphere) {
    const Vec3 c = center(s.local);
    double r = 0;
    for (const Vec3& v : s.mesh->vertices) r = std::max(r, double(length(v - c)));
    return Json{{"kind", "sphere"}, {"center", vec(c)}, {"radius", as_float(r)}};
  }
  if (declared == CollisionShape::ConvexHull) {
    Json v = Json::array();
    for (const auto& p : ref.hull_features(body).vertices)
      for (double x : p) v.push_back(as_float(x));
    return Json{{"kind", "hull"}, {"vertices", std::move(v)}};
  }
  Json v = Json::array(), t = Json::array();
  for (const Vec3& p : s.mesh->vertices) {
    v.push_back(as_float(p.x));
    v.push_back(as_float(p.y));
    v.push_back(as_float(p.z));
  }
  for (const auto& tri : s.mesh->triangles)
    for (std::uint32_t k : tri) t.push_back(k);
  return Json{{"kind", "mesh"}, {"vertices", std::move(v)}, {"triangles", std::move(t)}};
}

Json reference_json(const char* kind, const ReferenceNormal& r) {
  return Json{{"kind", kind},
              {"valid", r.valid},
              {"penetrating", r.penetrating},
              {"normal", vec(r.normal)},
              {"depth", as_float(r.depth)},
              {"distance", as_float(r.distance)},
              {"depth_upper_bound", r.depth_upper_bound},
              {"point_a", vec(r.point_a)},
              {"point_b", vec(r.point_b)}};
}

/// Contact row k of `rec` as the page draws it: pair, normal, depth, jn, jt, the engine's
/// point (null without /contacts/point), its point on B (`point_b`, null without
/// /contacts/point_b: the impulse acts between the two) and its friction impulse vector on A
/// (`jt3`, null without /contacts/jt3), then `more`.
Json row_json(const FrameRecord& rec, std::size_t k, std::initializer_list<std::pair<const char*, Json>> more) {
  const ContactRecord& c = rec.contacts[k];
  Json out{{"a", c.pair.a},
           {"b", c.pair.b},
           {"normal", vec(c.normal)},
           {"depth", as_float(c.depth)},
           {"jn", as_float(c.jn)},
           {"jt", as_float(c.jt)},
           {"point", rec.has_points ? vec(c.point) : Json(nullptr)},
           {"point_b", rec.point_b.size() == rec.contacts.size() ? vec(rec.point_b[k]) : Json(nullptr)},
           {"jt3", rec.jt3.size() == rec.contacts.size() ? vec(rec.jt3[k]) : Json(nullptr)}};
  for (const auto& [key, value] : more) out[key] = value;
  return out;
}

/// A pair's friction as the friction row's cone judges it (validation/physics/friction.cpp,
/// docs/validation.md): its rows `rows` of `rec` together, |sum jt3| (or sum |jt| without
/// jt3) against the cone mu sum jn; the sums' vectors for the page to draw.
Json friction_json(const FrameRecord& rec, const std::vector<std::size_t>& rows, const PhysicsBodies& physics,
                   Pair p) {
  const bool vector_friction = rec.jt3.size() == rec.contacts.size() && !rec.jt3.empty();
  double jn_sum = 0, jt_abs = 0;
  double jt[3] = {0, 0, 0}, jn_vec[3] = {0, 0, 0};
  for (std::size_t k : rows) {
    const ContactRecord& c = rec.contacts[k];
    jn_sum += double(c.jn);
    for (int d = 0; d < 3; ++d) jn_vec[d] += double(c.jn) * double(c.normal[d]);
    if (vector_friction) {
      for (int d = 0; d < 3; ++d) jt[d] += double(rec.jt3[k][d]);
      jt_abs += double(length(rec.jt3[k]));
    } else {
      jt_abs += std::fabs(double(c.jt));
    }
  }
  const double jt_sum = vector_friction ? std::sqrt(jt[0] * jt[0] + jt[1] * jt[1] + jt[2] * jt[2]) : jt_abs;
  const double mu = pair_friction(physics, p.a, p.b);
  const double cone = mu * jn_sum;
  return Json{{"rule", vector_friction ? "jt3" : "scalar"},
              {"rows", rows.size()},
              {"jt_sum", as_float(jt_sum)},
              {"jt", vector_friction ? Json::array({as_float(jt[0]), as_float(jt[1]), as_float(jt[2])}) : Json(nullptr)},
              {"jn_sum", as_float(jn_sum)},
              {"jn", Json::array({as_float(jn_vec[0]), as_float(jn_vec[1]), as_float(jn_vec[2])})},
              {"mu", as_float(mu)},
              {"cone", as_float(cone)},
              {"ratio", cone > 0 ? as_float(jt_sum / cone) : Json(nullptr)}};
}

}  // namespace

ViewPage write_view(const std::string& trace, const ViewSettings& settings, const std::string& out_dir) {
  namespace fs = std::filesystem;
  if (settings.window < 0 || settings.window > kMaxWindow)
    throw InputError(fmt::format("--window: {}; allowed: 0 .. {} frames each side of --frame", settings.window,
                                 kMaxWindow));
  if (settings.has_pair && settings.has_body)
    throw InputError("--pair and --body: both given; allowed: one item (a pair or a body), or neither");
  if (settings.max_bodies < 2 || settings.max_bodies_all < 1)
    throw InputError(fmt::format("view: max_bodies {} and max_bodies_all {}; allowed: >= 2 and >= 1",
                                 settings.max_bodies, settings.max_bodies_all));
  if (out_dir.empty()) throw InputError("-o: empty; allowed: a folder for the page");
  // Debian's libjs-three, read before the trace: a missing package is said first.
  const fs::path three = settings.three_dir;
  const std::string js = script_safe(read_text(three / "three.min.js")) + "\n" +
                         script_safe(read_text(three / "examples/js/controls/OrbitControls.js")) + "\n" +
                         script_safe(read_text(three / "examples/js/math/ConvexHull.js")) + "\n" +
                         script_safe(read_text(three / "examples/js/geometries/ConvexGeometry.js"));

  // The hardened reader: every dataset, shape and range checked before it is used.
  std::unique_ptr<ExternalTrace> in;
  try {
    in = std::make_unique<ExternalTrace>(trace, TraceStates::Sparse);
  } catch (const RuntimeError& e) {  // not HDF5 at all: bad input for a viewer
    throw InputError(fmt::format("TRACE: {}", e.what()));
  }
  const ExternalTraceInfo& info = in->info();
  const std::size_t n = info.bodies;
  // Without --frame: the first frame with a contact row, else frame 1.
  const std::int64_t first_contact = in->first_contact_frame();
  const std::int64_t frame = settings.frame != 0 ? settings.frame : first_contact > 0 ? first_contact : 1;
  const bool sparse = in->sparse_states();
  if (frame < 1 || frame > info.frames)
    throw InputError(fmt::format("--frame: {}: outside the trace {} ({} frames); allowed: 1 .. {}", settings.frame,
                                 trace, info.frames, info.frames));
  auto check_body = [&](const char* arg, std::uint32_t i) {
    if (i >= n)
      throw InputError(fmt::format("{}: body {} does not exist in {} ({} bodies); allowed: 0 .. {}", arg, i, trace,
                                   n, n - 1));
  };
  std::uint32_t a = settings.pair_a, b = settings.pair_b;
  if (settings.has_pair) {
    check_body("--pair", a);
    check_body("--pair", b);
    if (a == b) throw InputError(fmt::format("--pair: {},{}: one body twice; allowed: two different bodies", a, b));
    if (a > b) std::swap(a, b);
  }
  if (settings.has_body) check_body("--body", settings.body);

  // The bodies as the validators see them: the model of the trace's bodies, the engine's
  // declared collision shapes, the separating-axis settings of the contact-geometry row.
  ExternalOptions eo;
  eo.engine = info.engine;
  eo.mesh_dir = settings.mesh_dir;
  eo.octocd_engine = info.octocd_conventions;  // declared by the trace, never by its engine name
  const ExternalValidator holder(in->bodies(), eo);
  const Model& model = holder.model();
  auto poses_of = [&](std::int64_t f, const FrameRecord& r) {
    return detection_poses(model, r, sparse && in->state_frame(f) != f);
  };
  const PhysicsBodies physics = eo.octocd_engine ? octocd_physics_bodies(model) : in->bodies().physics;
  const ReferenceGeometry ref(model, physics.collision_shape);
  const bool aabb_geometry = physics.contact_geometry == ContactGeometry::Aabb;
  // The friction row judges the rows' friction only where they carry it.
  const bool friction_judged = physics.impulses == PhysicsBodies::Impulses::Complete;
  const Tolerances tol;
  SatSettings sat;
  sat.abs_m = tol.geometry_slack_m;
  sat.rel = tol.sat_accept_rel;

  // The bodies drawn: chosen at the frame shown first, kept over the window.
  FrameRecord rec = in->frame(frame);
  std::vector<Pose> det = poses_of(frame, rec);
  FrameRecord shown = rec;  // kept for its turn in the window
  std::vector<Pose> shown_det = det;
  auto world_box = [&](const FrameRecord& r, const std::vector<Pose>& poses, std::uint32_t i) {
    return r.aabbs.size() == n ? r.aabbs[i] : ref.world_aabb(i, poses[i]);
  };
  std::vector<std::uint32_t> drawn;
  std::string note;
  if (settings.has_pair || settings.has_body) {
    const std::vector<std::uint32_t> item =
        settings.has_pair ? std::vector<std::uint32_t>{a, b} : std::vector<std::uint32_t>{settings.body};
    Aabb box = world_box(rec, det, item[0]);
    for (std::uint32_t i : item) box = merged(box, world_box(rec, det, i));
    const double size = std::max({double(box.max.x - box.min.x), double(box.max.y - box.min.y),
                                  double(box.max.z - box.min.z), 1e-3});
    std::vector<std::pair<double, std::uint32_t>> near;
    for (std::uint32_t i = 0; i < n; ++i) {
      if (std::find(item.begin(), item.end(), i) != item.end()) continue;
      const double d = box_distance(world_box(rec, det, i), box);
      if (d <= size) near.emplace_back(d, i);
    }
    std::sort(near.begin(), near.end());
    drawn = item;
    const std::size_t room = settings.max_bodies - item.size();
    for (std::size_t k = 0; k < near.size() && k < room; ++k) drawn.push_back(near[k].second);
    if (near.size() > room)
      note = fmt::format("{} bodies lie within {:.3g} m of the item; the nearest {} are drawn (cap {} bodies)",
                         near.size(), size, room, settings.max_bodies);
  } else {
    for (std::uint32_t i = 0; i < n && drawn.size() < settings.max_bodies_all; ++i) drawn.push_back(i);
    if (n > drawn.size())
      note = fmt::format("bodies 0 .. {} of {} are drawn (cap {} bodies without --pair or --body)", drawn.size() - 1,
                         n, settings.max_bodies_all);
  }
  std::map<std::uint32_t, std::size_t> index;  // body -> position in `drawn`
  for (std::size_t k = 0; k < drawn.size(); ++k) index[drawn[k]] = k;

  // Shapes: one per (shape, declared kind) among the bodies drawn.
  Json shapes = Json::array(), bodies = Json::array();
  std::map<std::pair<std::uint32_t, int>, std::size_t> shape_ids;
  for (std::uint32_t i : drawn) {
    const CollisionShape c = physics.collision_shape.empty() ? CollisionShape::Mesh : physics.collision_shape[i];
    const auto key = std::make_pair(model.bodies[i].shape, static_cast<int>(c));
    auto it = shape_ids.find(key);
    if (it == shape_ids.end()) {
      it = shape_ids.emplace(key, shapes.size()).first;
      shapes.push_back(shape_json(model, ref, i, c));
    }
    const bool item = (settings.has_pair && (i == a || i == b)) || (settings.has_body && i == settings.body);
    bodies.push_back(Json{{"id", i}, {"shape", it->second}, {"static", !(model.initial.w[i] > 0.0f)}, {"item", item}});
  }

  // The frames of the window: `window` frames each side of the frame asked for; with
  // sparse states, `window` recorded states each side (and the frame asked for).
  std::vector<std::int64_t> window;
  if (sparse) {
    const std::vector<std::int64_t>& recorded = in->state_frames();
    const auto at = std::lower_bound(recorded.begin(), recorded.end(), frame) - recorded.begin();
    const std::ptrdiff_t size = static_cast<std::ptrdiff_t>(recorded.size());
    const std::ptrdiff_t after = at < size && recorded[at] == frame ? settings.window + 1 : settings.window;
    for (std::ptrdiff_t k = std::max<std::ptrdiff_t>(0, at - settings.window);
         k < std::min<std::ptrdiff_t>(size, at + after); ++k)
      if (recorded[k] >= 1) window.push_back(recorded[k]);
    window.push_back(frame);
    std::sort(window.begin(), window.end());
    window.erase(std::unique(window.begin(), window.end()), window.end());
  } else {
    for (std::int64_t f = std::max<std::int64_t>(1, frame - settings.window);
         f <= std::min<std::int64_t>(info.frames, frame + settings.window); ++f)
      window.push_back(f);
  }
  Json frames = Json::array();
  bool pair_in_contact = false;
  auto poll = [&] {
    if (settings.stop && settings.stop()) throw ValidationStopped();
  };
  for (const std::int64_t f : window) {
    poll();
    if (f != frame) {
      rec = in->frame(f);
      det = poses_of(f, rec);
    } else {
      rec = std::move(shown);
      det = std::move(shown_det);
    }
    Json x = Json::array(), q = Json::array(), boxes = Json::array();
    for (std::uint32_t i : drawn) {
      x.push_back(vec(det[i].position));
      const Quat& o = det[i].orientation;
      q.push_back(Json::array({as_float(o.w), as_float(o.x), as_float(o.y), as_float(o.z)}));
      const Aabb w = world_box(rec, det, i);
      boxes.push_back(Json::array({vec(w.min), vec(w.max)}));
    }
    // Contact rows among the bodies drawn; the item pair's references first.
    Json contacts = Json::array();
    std::vector<Pair> pairs;
    if (settings.has_pair) pairs.push_back(Pair{a, b});
    std::size_t rows = 0, rows_left = 0;
    std::map<std::pair<std::uint32_t, std::uint32_t>, std::vector<std::size_t>> rows_of;
    for (std::size_t k = 0; k < rec.contacts.size(); ++k) {
      const ContactRecord& c = rec.contacts[k];
      if (!index.count(c.pair.a) || !index.count(c.pair.b)) continue;
      if (rows >= kMaxContactRows) {
        ++rows_left;
        continue;
      }
      ++rows;
      rows_of[{c.pair.a, c.pair.b}].push_back(k);
      if (std::find(pairs.begin(), pairs.end(), c.pair) == pairs.end()) pairs.push_back(c.pair);
    }
    const bool in_contact = settings.has_pair && rows_of.count({a, b});
    if (f == frame) pair_in_contact = in_contact;
    Json refs = Json::array();
    std::size_t refs_left = 0;
    for (std::size_t pi = 0; pi < pairs.size(); ++pi) {
      const Pair p = pairs[pi];
      const auto found = rows_of.find({p.a, p.b});
      if (pi >= kMaxReferencePairs) {
        ++refs_left;
        if (found != rows_of.end())
          for (std::size_t k : found->second) contacts.push_back(row_json(rec, k, {{"ref", nullptr}}));
        continue;
      }
      poll();
      // The physics tier's reference for the pair (reference.hpp), as contact-geometry judges it.
      const PairReference t = pair_reference(ref, p.a, p.b, det[p.a], det[p.b], sat);
      const ReferenceNormal r =
          aabb_geometry ? ReferenceGeometry::aabb_pair(world_box(rec, det, p.a), world_box(rec, det, p.b)) : t.g;
      const bool by_sat = !aabb_geometry && t.sat;
      Json entry{{"a", p.a},
                 {"b", p.b},
                 {"judge", aabb_geometry ? "AABB" : by_sat ? "SAT" : "FCL"},
                 {"judged", reference_json(aabb_geometry ? "AABB" : by_sat ? "SAT" : "FCL", r)},
                 {"shapes", reference_json(t.sat ? "SAT" : "FCL", t.g)}};
      if (t.sat) {
        Json axes = Json::array();
        for (const SatAxis& ax : t.sat_result.accepted)
          axes.push_back(Json{
              {"normal", Json::array({as_float(ax.normal[0]), as_float(ax.normal[1]), as_float(ax.normal[2])})},
              {"overlap", as_float(ax.overlap)}});
        entry["sat_accepted"] = std::move(axes);
        entry["sat_epsilon"] = as_float(t.sat_result.epsilon);
      }
      entry["in_contact"] = found != rows_of.end();
      if (found != rows_of.end() && friction_judged) entry["friction"] = friction_json(rec, found->second, physics, p);
      const std::size_t ref_index = refs.size();
      refs.push_back(std::move(entry));
      if (found == rows_of.end()) continue;
      for (std::size_t k : found->second) {
        const ContactRecord& c = rec.contacts[k];
        const RowReference rr = row_reference(t, r, by_sat, c.normal);
        contacts.push_back(row_json(rec, k,
                                    {{"ref", ref_index},
                                     {"ref_normal", vec(rr.normal)},
                                     {"angle_deg", as_float(rr.angle * 180.0 / 3.14159265358979323846)}}));
      }
    }
    Json fr{{"frame", f}, {"state_frame", in->state_frame(f)}, {"x", std::move(x)}, {"q", std::move(q)}, {"aabbs", std::move(boxes)},
            {"contacts", std::move(contacts)}, {"references", std::move(refs)}};
    if (rows_left > 0) fr["rows_not_drawn"] = rows_left;
    if (refs_left > 0) fr["pairs_without_reference"] = refs_left;
    if (settings.has_pair) fr["pair_in_contact"] = in_contact;
    frames.push_back(std::move(fr));
  }
  if (settings.has_pair && !pair_in_contact) {
    const std::string no = fmt::format("pair ({}, {}) has no contact row in frame {}: drawn anyway, with the "
                                       "reference for its shapes",
                                       a, b, frame);
    note = note.empty() ? no : no + "; " + note;
  }

  if (!info.has_contacts) {
    const std::string rows = "this trace has no contact rows (octocd run --contacts writes them): the bodies are "
                             "drawn without the engine's contacts";
    note = note.empty() ? rows : rows + "; " + note;
  }
  if (sparse) {
    const std::string states =
        "the trace records the states of some frames only (e.g. octocd run --state-every K): a frame without its "
        "own is drawn at the nearest recorded state, named beside the frame number";
    note = note.empty() ? states : note + "; " + states;
  }

  Json item = settings.has_pair   ? Json{{"kind", "pair"}, {"a", a}, {"b", b}}
              : settings.has_body ? Json{{"kind", "body"}, {"body", settings.body}}
                                  : Json{{"kind", "none"}};
  Json data{{"trace", fs::path(trace).filename().string()},
            {"trace_version", info.version},
            {"octocd_engine", eo.octocd_engine},
            {"contact_geometry", aabb_geometry ? "aabb" : "shape"},
            {"bodies_in_trace", n},
            {"has_contact_rows", info.has_contacts},
            {"first_contact_frame", first_contact},
            {"impulses", impulses_name(physics.impulses)},
            {"frames_in_trace", info.frames},
            {"frame", frame},
            {"window", settings.window},
            {"item", std::move(item)},
            {"cap", settings.has_pair || settings.has_body ? settings.max_bodies : settings.max_bodies_all},
            {"note", note},
            {"shapes", std::move(shapes)},
            {"bodies", std::move(bodies)},
            {"frames", std::move(frames)}};
  if (!settings.row.empty())
    data["failure"] = Json{{"row", settings.row}, {"cause", settings.cause}, {"figure", as_float(settings.figure)},
                           {"unit", settings.unit}};

  std::string name = settings.file_name;
  if (name.empty())
    name = settings.has_pair   ? fmt::format("view-f{}-pair-{}-{}.html", frame, a, b)
           : settings.has_body ? fmt::format("view-f{}-body-{}.html", frame, settings.body)
                               : fmt::format("view-f{}-all.html", frame);
  const std::string title =
      settings.has_pair   ? fmt::format("octocd view: frame {}, pair ({}, {})", frame, a, b)
      : settings.has_body ? fmt::format("octocd view: frame {}, body {}", frame, settings.body)
                          : fmt::format("octocd view: frame {}", frame);
  const std::string page = detail::view_page_html(title, json_safe(data.dump(-1, ' ', false, Json::error_handler_t::replace)), js);
  std::error_code ec;
  fs::create_directories(out_dir, ec);
  const fs::path path = fs::path(out_dir) / name;
  if (ec)
    throw RuntimeError(fmt::format("view: {}: the folder cannot be created ({})", out_dir, ec.message()));
  // Beside its name under an unpredictable one, then renamed: never written in place.
  write_file_atomically(path.string(), page, "view");
  // The page, its bytes, the bodies drawn, the frames on the slider, the first frame, the note.
  return ViewPage{path.string(), page.size(), drawn.size(), window.size(), frame, note};
}

}  // namespace octocd
