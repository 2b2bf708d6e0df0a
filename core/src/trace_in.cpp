// The external-trace reader (trace_in.hpp; docs/trace-format.md, "External traces"):
// opening a trace (root attributes, bodies, the per-frame datasets and their CSR offsets),
// the dataset helpers, ExternalTrace and check_external_trace (octocd/external_trace.hpp).
#include "trace_in.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

#include "octocd/text.hpp"

namespace octocd {

namespace detail {

TraceIn::TraceIn(const std::string& path, bool with_scene, bool sparse, bool recorded)
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
  read_incomplete_rows(bodies.physics);
  if (info.version == 2)
    read_v2();
  else
    reject_v2_datasets();
}

TraceIn::Dataset TraceIn::open(const std::string& name, H5T_class_t cls, int rank, bool required) const {
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

void TraceIn::expect(const Dataset& d, const std::vector<hsize_t>& dims, const std::string& allowed) const {
  if (d.dims == dims) return;
  std::string shape;
  for (hsize_t x : d.dims) shape += (shape.empty() ? "" : " x ") + std::to_string(x);
  bad(d.name, fmt::format("shape {}", shape), allowed);
}

std::vector<std::int64_t> TraceIn::offsets(const std::string& name) const {
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

void TraceIn::rows_match(const Dataset& d, const std::vector<std::int64_t>& o,
                         const std::string& offsets_name) const {
  if (static_cast<hsize_t>(o.back()) != d.dims[0])
    bad(offsets_name, fmt::format("last value {} but {} has {} rows", o.back(), d.name, d.dims[0]),
        fmt::format("the last offset equals the rows of {}", d.name));
}

hsize_t TraceIn::nearest_row(std::int64_t f) const {
  const auto at = std::lower_bound(state_frames_.begin(), state_frames_.end(), f);
  if (at == state_frames_.end()) return static_cast<hsize_t>(state_frames_.size() - 1);
  if (at == state_frames_.begin() || *at - f <= f - *(at - 1)) return static_cast<hsize_t>(at - state_frames_.begin());
  return static_cast<hsize_t>(at - state_frames_.begin() - 1);
}

bool TraceIn::posed(std::int64_t f) const {
  return !pose_only() || (info.has_aabbs && info.version == 1) ||
         std::binary_search(state_frames_.begin(), state_frames_.end(), f - 1);
}

std::int64_t TraceIn::first_contact_frame() const {
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

void TraceIn::check_frames(const std::function<void()>& poll,
                           const std::function<void(std::int64_t f, FrameRecord&& rec)>& take) {
  for (std::int64_t f = 1; f <= info.frames; ++f) {
    if (poll) poll();
    if (!posed(f)) continue;  // TraceStates::Recorded: a step without its pre-step state is not judged
    FrameRecord rec = frame(f);
    if (take) take(f, std::move(rec));
  }
}

}  // namespace detail

struct ExternalTrace::Impl {
  Impl(const std::string& file, TraceStates states)
      : in(file, true, states != TraceStates::EveryFrame, states == TraceStates::Recorded), path(file) {}
  detail::TraceIn in;
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

ExternalTraceInfo check_external_trace(const std::string& path) {
  // Every frame's values, read as recorded and without parsing the scene (as --check-only).
  detail::TraceIn in(path, false, true, true);
  in.check_frames({}, {});
  return in.info;
}

}  // namespace octocd
