#pragma once
// The external-trace reader behind octocd/external_trace.hpp (docs/trace-format.md,
// "External traces", versions 1 and 2): a file opened and checked through core's one HDF5
// reader (hdf5_handle.hpp), then read frame by frame into checked FrameRecords. Private to
// the build: ExternalTrace and check_external_trace (trace_in.cpp) wrap it, and the judging
// of a trace (validation/src/trace_judge.cpp) reads it directly for what it needs beyond
// them (the frames a check pass kept, the steps with a pose).
// Its jobs, a file each:
// - trace_in.cpp: opening (root attributes, bodies, the per-frame datasets and their CSR
//   offsets), the dataset helpers, ExternalTrace and check_external_trace;
// - trace_in_declarations.cpp: what a trace declares of its engine and bodies (the
//   declarations of design.md section 13b.12, the version 2 physics, rotation and contact
//   points, collision shapes, centre-of-mass offsets, locked axes, sleeping flags);
// - trace_in_frames.cpp: one step as a FrameRecord (states or detection poses, pairs,
//   contacts, the version 2 fields), each value checked.
#include <hdf5.h>

#include <array>
#include <cstdint>
#include <cstring>
#include <functional>
#include <memory>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

#include <fmt/format.h>

#include "hdf5_handle.hpp"
#include "octocd/error.hpp"
#include "octocd/external_trace.hpp"

namespace octocd::detail {

class TraceIn {
 public:
  /// One dataset: its handle, type and dimensions (hdf5_handle.hpp).
  using Dataset = Hdf5Reader::Dataset;

  /// Opens and checks `path`. `with_scene`: the root attribute `scene` is parsed for the
  /// physics defaults (its response's mu_s, e and slop; dt and gravity of the "integrated"
  /// detection pose); false (--check-only) leaves the scene to the validator, as in v1.
  /// `sparse`: /states/frame may skip frames (strictly increasing from 0, as `octocd run
  /// --state-every K` writes); frame f's states are then the recorded row nearest to f
  /// (state_frame(f) names it). Otherwise every frame's state is required.
  /// `recorded` (with `sparse`): TraceStates::Recorded, frames judged on what they carry.
  explicit TraceIn(const std::string& path, bool with_scene = true, bool sparse = false, bool recorded = false);

  ExternalTraceInfo info;
  ExternalBodies bodies;

  /// Step f (1 .. frames) as a FrameRecord, its values checked (check_frame_record).
  FrameRecord frame(std::int64_t f);

  /// Reads and checks every step that can be judged on its pose (posed), in order: `poll`
  /// (may be empty) is called before each step and may throw to stop the reading; `take`
  /// (may be empty) receives each step's record.
  void check_frames(const std::function<void()>& poll,
                    const std::function<void(std::int64_t f, FrameRecord&& rec)>& take);

  /// TraceStates::Recorded with sparse states: records carry detection poses, no states.
  bool pose_only() const { return recorded_ && !state_frames_.empty(); }
  /// Step f can be judged on its pose: every step unless pose_only(), then the steps whose
  /// pre-step state (frame f - 1) is recorded, or any step of a version 1 trace with
  /// /aabbs (its poses are the boxes; version 2 never infers a pose from them).
  bool posed(std::int64_t f) const;
  /// The frame whose recorded state frame(f) carries: f itself unless states are sparse.
  std::int64_t state_frame(std::int64_t f) const {
    return state_frames_.empty() ? f : state_frames_[nearest_row(f)];
  }
  /// The first frame with a contact row (0: none). Without /contacts, octocd's own
  /// per-frame counts (/frames/frame, /frames/contacts) when the trace has them.
  std::int64_t first_contact_frame() const;
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
  // ---- What a trace declares (trace_in_declarations.cpp). Version 2: design.md section 13;
  // docs/trace-format.md, "Version 2".

  /// The datasets version 2 adds: an error in a version 1 file.
  static constexpr const char* kV2Datasets[] = {"/states/orientation", "/states/angular_velocity",
                                                "/bodies/inertia",     "/contacts/point",
                                                "/bodies/friction",    "/bodies/restitution",
                                                "/contacts/jt3",       "/bodies/collision_shape",
                                                "/bodies/locked_dofs", "/states/sleeping",
                                                "/contacts/point_b"};
  void reject_v2_datasets() const;
  /// The physics defaults from the scene (both versions): its response's mu_s, e and slop
  /// (the root attributes and /bodies tables of version 2 override them); its dt and
  /// gravity for the "integrated" detection pose.
  void scene_defaults();
  /// Root attributes, /bodies physics, rotation and contact points of a version 2 file.
  void read_v2();
  /// What the engine collided each body as (design.md section 13b.10): the root attribute
  /// `collision_shape` (every body) or `/bodies/collision_shape` (one string per body),
  /// each "mesh", "convex_hull", "box" or "sphere"; absent: every body as its shape.
  void read_collision_shapes(PhysicsBodies& p) const;
  /// The declarations of design.md section 13b.12 (docs/trace-format.md, "Declarations"),
  /// root attributes of either version: `contact_model`, `gyroscopic`, `integrator`,
  /// `contact_geometry`, `broadphase_exact`, `contact_margin_rule`, `jt_direction`,
  /// `velocity_clamp`, `impulses_complete`, `response_scheme`, `deactivation` (with
  /// /states/sleeping). A version 1 trace of octocd's TraceWriter that declares none of
  /// them (written before they existed: /frames and the root attribute `parameters`) is
  /// read as declaring octocd's conventions (ExternalTraceInfo::octocd_conventions).
  void read_declarations(PhysicsBodies& p);
  /// `/contacts/incomplete` (either version, with /contacts and contacts_complete 1):
  /// K frames (1 .. F) or K x 3 rows (frame, body_a, body_b) whose contact rows the engine
  /// may have dropped, into PhysicsBodies::incomplete_rows (sorted, pairs as a < b); any
  /// other shape, type, frame or body is an error naming the row and the allowed range.
  void read_incomplete_rows(PhysicsBodies& p) const;
  /// /bodies/convex_radius (n, m, >= 0: PhysicsBodies::convex_radius) and
  /// /bodies/com_offset (n x 3, m, body frame: the centre of mass relative to the body
  /// frame's origin that /states/position gives; with a nonzero offset the root attribute
  /// `velocity_at` says which point /states/velocity is the velocity of). The records'
  /// states are turned into the centres of mass (com_state); the detection poses stay the
  /// body frame's (the shapes are placed in it).
  void read_shape_offsets(PhysicsBodies& p);
  /// /bodies/locked_dofs (version 2) and /states/sleeping (version 2, with /states).
  void read_locked_dofs(PhysicsBodies& p);
  /// A string attribute that must be one of `allowed` (absent: `fallback`).
  std::string choice_attr(const char* name, const std::vector<std::string>& allowed,
                          const std::string& fallback) const;
  /// A 0/1 root attribute as a bool (absent: `fallback`); any other number is an error
  /// naming the attribute with `allowed`.
  bool flag_attr(const char* name, bool fallback, const std::string& allowed) const;
  /// A material combination rule named by one of `names` (absent: "product").
  MaterialCombine combine_attr(const char* name, const std::vector<std::string>& names) const;

  // ---- One step as a record (trace_in_frames.cpp).

  /// Step f's version 2 fields (the v1 fields are read already).
  void fill_v2(FrameRecord& rec, std::int64_t f, RecordFieldNames& names);
  /// Rows f - 1 and f of /states/sleeping: 0 awake, 1 asleep (any other value exits 2).
  void read_sleeping(FrameRecord& rec, std::int64_t f) const;
  /// With a nonzero /bodies/com_offset: the state's positions (and, with `velocity_at`
  /// "origin", velocities) of the body frame's origin turned into its centre of mass's,
  /// x_c = x + R c and v_c = v + w x (R c), so every rule on states (momentum-balance,
  /// free-flight, conservation) judges the centre of mass.
  void com_state(std::vector<Vec3>& x, std::vector<Vec3>& v, const std::vector<Quat>& q,
                 const std::vector<Vec3>& w) const;
  /// Values that arithmetic must not overflow (docs/trace-format.md, "Security rules and
  /// limits"): every position, position + local extent and AABB corner within
  /// trace_limits::kMaxCoordinate, every velocity within kMaxSpeed, every angular velocity
  /// within kMaxAngularSpeed; checked before FCL or
  /// any tree is built from them.
  void check_magnitudes(const FrameRecord& rec) const;
  /// Frame f's rows of a P x 2 pair dataset.
  std::vector<Pair> pairs(const Dataset& d, const std::vector<std::int64_t>& o, std::int64_t f) const;
  /// The state rows of frame f: (f - 1, f) when every frame has its state; with sparse
  /// states both are the row nearest to f (state_frame(f)).
  std::pair<hsize_t, hsize_t> state_rows(std::int64_t f) const;
  static std::vector<Quat> quats(const std::vector<float>& wxyz);
  static std::vector<Vec3> vectors(const std::vector<float>& xyz);

  // ---- Datasets and attributes (trace_in.cpp).

  bool has_attr(const char* name) const { return h5_->has_attribute(name); }
  bool exists(const std::string& name) const { return h5_->exists(name); }
  std::string string_attr(const char* name) const {
    return h5_->has_attribute(name) ? h5_->string_attribute(name) : std::string();
  }
  double number_attr(const char* name, double missing) const {
    return h5_->has_attribute(name) ? h5_->number_attribute(name) : missing;
  }
  [[noreturn]] void bad(const std::string& dataset, const std::string& problem, const std::string& allowed) const {
    throw InputError(fmt::format("{}: {}: {}; allowed: {}", path_, dataset, problem, allowed));
  }
  /// In an octocd trace (root attribute committed_states), rows past the committed ones
  /// may never have been written (a failed write: docs/trace-format.md): not read.
  void clip(Dataset& d, hsize_t rows) const {
    if (committed_ && d.present() && !d.dims.empty() && d.dims[0] > rows) d.dims[0] = rows;
  }
  /// `name` of class `cls` and rank `rank` (float32 or float64 for H5T_FLOAT); absent and
  /// not `required`: a Dataset that is not present().
  Dataset open(const std::string& name, H5T_class_t cls, int rank, bool required) const;
  /// `d` has the dimensions `dims`, else an error naming `allowed`.
  void expect(const Dataset& d, const std::vector<hsize_t>& dims, const std::string& allowed) const;
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
  /// A CSR offsets dataset: F + 1 values, 0 first, never decreasing. Empty when absent.
  std::vector<std::int64_t> offsets(const std::string& name) const;
  /// The last offset of `o` is the rows of `d`.
  void rows_match(const Dataset& d, const std::vector<std::int64_t>& o, const std::string& offsets_name) const;
  /// The row of the recorded state nearest to frame f (ties: the earlier one).
  hsize_t nearest_row(std::int64_t f) const;

  std::string path_;
  bool sparse_ = false;                     // /states/frame may skip frames
  bool recorded_ = false;                   // TraceStates::Recorded (with sparse_)
  std::vector<std::int64_t> state_frames_;  // with sparse states: /states/frame; else empty
  std::unique_ptr<Hdf5Reader> h5_;          // quiets HDF5's error printing while it lives
  bool committed_ = false;                  // the trace has committed_states (octocd's own)
  hsize_t n_ = 0;
  std::int64_t frames_ = 0;
  Dataset position_, velocity_, aabb_min_, aabb_max_, pairs_, c_pair_, c_normal_, c_depth_, c_jn_, c_jt_, c_jt3_, c_point_b_;
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

}  // namespace octocd::detail
