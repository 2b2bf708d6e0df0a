#pragma once
/// \file trace.hpp
/// HDF5 traces (design.md section 8; layout in docs/trace-format.md, format "octocd-trace"
/// version 1). The file is written in SWMR mode and flushed every `flush_every` frames,
/// so a process killed with SIGKILL leaves a readable file holding every flushed frame.

#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "octocd/math.hpp"
#include "octocd/engine.hpp"

namespace octocd {

/// What an engine declares of its contacts in a trace's root attributes (docs/trace-format.md,
/// "Declarations"; docs/validate-your-engine.md lists each): the facts the physics tier's
/// rules read instead of an engine's name. Empty strings and negative numbers are not
/// written (a reader then takes the documented default). octocd's cpu and cuda engines
/// declare all of them (octocd_trace_declarations); a rotating engine states its own in
/// RotationTraits.
struct TraceDeclarations {
  std::string contact_geometry;     ///< `contact_geometry`: "aabb" (design.md section 6: contacts on the world AABBs) or "shape"
  int broadphase_exact = -1;        ///< `broadphase_exact`: 1 = the candidate pairs are exactly the overlapping world AABBs
  std::string contact_margin_rule;  ///< `contact_margin_rule`: "theta" (each pair's vertex-proximity theta, design.md section 5.3) or "fixed"
  std::string jt_direction;         ///< `jt_direction`: "along-sliding" (design.md section 6's J_t along +v_t) or "against-sliding"
  double velocity_clamp = -1.0;     ///< `velocity_clamp` (m/s per component, 0 = none): design.md section 6's Eq. 23 v_max
  int impulses_complete = -1;       ///< `impulses_complete`: 0 = the contact rows hold only the first relaxation pass's impulses
  std::string response_scheme;      ///< `response_scheme`: "jacobi" (design.md section 6: impulses summed from one pre-response state) or "sequential"
  std::string integrator;           ///< `integrator`: "semi-implicit", "explicit" or "any"
  std::string contact_model;        ///< `contact_model`: "rigid" or "soft"
  std::string deactivation;         ///< `deactivation`: "off" (the engine never deactivates a body)
  int friction_directions = -1;     ///< `friction_directions`: 1 = each row's friction along its sliding (the scalar jt is all of it)
};

/// The declarations of octocd's own cpu and cuda engines for `model`: contacts on the
/// world AABBs, an exact AABB broadphase, each pair's theta as contact margin, J_t along
/// the sliding, the scene's velocity clamp (response.max_velocity), impulses complete only
/// with response.iterations = 1, the Jacobi response, semi-implicit Euler (design.md
/// section 4.1), rigid contacts, no deactivation. The writer-side twin of the validators'
/// octocd_physics_bodies.
TraceDeclarations octocd_trace_declarations(const Model& model);

/// Root attributes of a trace.
struct TraceMetadata {
  std::string scene_name;
  std::string scene_json;     ///< the scene file's text
  std::string parameters_json;  ///< response parameters, theta, dt, gravity as JSON
  std::string engine = "cpu"; ///< cpu | cuda | bullet
  std::string broadphase;     ///< e.g. "octree"
  std::string midphase;       ///< e.g. "1,2" or "aabb-only"
  std::string build_id;       ///< octocd version + git id
  std::string device;         ///< CPU model or GPU name
  std::string start_time;     ///< ISO 8601 UTC
  double dt = 0.0;            ///< s
  int state_every = 10;       ///< informational: the file's `state_every` attribute is
                              ///< TraceOptions::state_every, the value actually used
  /// Declarations written as root attributes (trace_metadata: octocd_trace_declarations
  /// for an engine whose Engine::octocd_contacts() is true, none otherwise).
  TraceDeclarations declarations;
};

/// Per-body constant data for /bodies.
struct TraceBodies {
  std::vector<std::uint32_t> shape_id;
  std::vector<float> inverse_mass;       ///< 1/kg
  std::vector<Aabb> local_aabb;          ///< m
  std::vector<std::string> shape_names;  ///< indexed by shape id
  std::vector<std::string> group;        ///< per body
};

/// The buffered rows from which TraceOptions::flush_interval_s no longer defers a flush
/// (bytes): 64 KiB, about 200 frames of a 50-body trace with the state every 10th frame.
constexpr std::size_t kFlushIntervalBytes = std::size_t{64} << 10;

/// Writer options.
struct TraceOptions {
  int state_every = 10;     ///< record positions/velocities every k-th frame (k >= 1)
  bool contacts = false;    ///< record /contacts
  int flush_every = 50;     ///< flush to disk every this many frames (>= 1)
  /// With a value > 0, a flush that flush_every frames call for waits, while the rows buffered
  /// since the last flush hold under kFlushIntervalBytes, until at least this many seconds (>= 0)
  /// have passed since the previous flush began (the frames stay buffered; flush_bytes still
  /// flushes at once). A flush writes every dataset and calls H5Fflush twice, about 1 ms however
  /// few its rows: on a small scene stepping at 50,000 steps/s a flush every 50 frames keeps the
  /// writer thread busy and the caller waiting on it (reports/h100/README.md, "Experiments and A/B
  /// results", "Traced runs"); batches of kFlushIntervalBytes or more flush every flush_every
  /// frames, so a full disk still keeps the frames written before it. With an interval, a
  /// flush_every flush also waits (buffering) while the writer thread still writes the previous
  /// batch, so the caller never waits for it (bunny-random-400 with the state every 10th frame
  /// flushes about 1.3 KB a frame, and the writer falls behind a flush every 50 frames).
  /// 0 (the default): every flush_every frames, waiting for the previous flush. `run --trace`
  /// and `bench --traced` use 0.1 s (cli/tools.hpp, kTraceFlushIntervalS).
  double flush_interval_s = 0.0;
  /// Also flush once the rows buffered since the last flush hold this many bytes (>= 1):
  /// a stopped or failed run then writes at most about this much (or one frame) at its
  /// end, so it ends within a second (deflate runs at about 60 MB/s on a slow core), and
  /// a process killed at any instant keeps every frame but the last few. 8 MiB: a scene
  /// of 350,000 bodies flushes every state row (24 bytes a body for position and velocity).
  std::size_t flush_bytes = std::size_t{8} << 20;
  /// Set: write format version 2 (docs/trace-format.md, "Version 2": a rotating engine,
  /// Engine::rotation_traits()): root attributes detection, mu, restitution,
  /// friction_combine, restitution_combine, contact_margin, broadphase_exact,
  /// contact_geometry, gravity; /bodies/inertia, friction, restitution;
  /// /states/orientation and angular_velocity beside every state row; with `contacts`,
  /// /contacts/point (and /contacts/jt3 when RotationTraits::jt3, /contacts/point_b when
  /// RotationTraits::point_b), /pairs (offsets, pair)
  /// and /aabbs (min, max) from append_frame_v2.
  /// Unset: version 1 (with TraceMetadata::declarations as root attributes).
  std::optional<RotationTraits> v2;
  /// Version 2: gravity (m/s^2) for the root attribute `gravity`.
  Vec3 gravity{0.0f, -9.81f, 0.0f};
};

/// Writes one trace file. Creates (truncates) `path`. All writes append; nothing written
/// is rewritten. Throws RuntimeError naming the path on any HDF5 failure.
///
/// A failed write (a full disk, a file size limit, an I/O error) abandons the file: nothing
/// more is written to it, so it stays as a killed run would leave it, readable with every
/// frame flushed before the failure; the RuntimeError is one line saying what failed, the
/// operating system's reason and which frames the file keeps; later calls do nothing
/// (append_frame and append_state throw "after close").
class TraceWriter {
 public:
  TraceWriter(const std::string& path, const TraceMetadata& meta, const TraceBodies& bodies,
              const TraceOptions& options);
  ~TraceWriter();
  TraceWriter(const TraceWriter&) = delete;
  TraceWriter& operator=(const TraceWriter&) = delete;

  /// Appends one row to /frames; writes positions/velocities to /states when
  /// m.frame % state_every == 0 (and for frame 0, the initial state, via
  /// `append_state`); flushes every `flush_every` rows, or sooner once the buffered rows
  /// hold `flush_bytes`.
  void append_frame(const FrameMetrics& m, const BodyState& state,
                    const std::vector<ContactRecord>& contacts);
  /// As above with the state given only where it is written: `state` may be null on a
  /// frame with !state_due(m.frame) (a device engine then copies no state back for the
  /// frames between); a null state on a due frame throws RuntimeError naming the frame.
  void append_frame(const FrameMetrics& m, const BodyState* state,
                    const std::vector<ContactRecord>& contacts);
  /// True when append_frame writes the state of `frame` (frame % state_every == 0).
  bool state_due(std::int64_t frame) const;
  /// The steps from `frame` to the next frame whose state is written (1 .. state_every):
  /// what a caller may let an engine run ahead (Engine::plan_steps) when it reads nothing
  /// else between the steps.
  std::int64_t steps_to_next_state(std::int64_t frame) const;
  /// Appends a state row for `frame` (used for the initial state, frame 0). Version 2:
  /// also the row of /states/orientation and /states/angular_velocity (state.q, omega;
  /// identity and zero when empty).
  void append_state(std::int64_t frame, const BodyState& state);
  /// Version 2 (TraceOptions::v2): one step of a rotating engine from its record: with
  /// `contacts`, rec.aabbs (/aabbs, one row of n boxes), rec.pairs (/pairs, CSR) and
  /// rec.contacts with their points (/contacts/point); then append_frame(m, state,
  /// rec.contacts). Throws RuntimeError when the trace is version 1 or the record's sizes
  /// do not match the bodies.
  void append_frame_v2(const FrameMetrics& m, const BodyState& state, const FrameRecord& rec);
  /// Flushes everything written so far to disk.
  void flush();
  /// Waits until the rows a flush handed to the writer thread are on disk (the flushes
  /// append_frame starts run there, beside the caller's next steps); flushed_frames() then
  /// counts them. Throws RuntimeError as append_frame does when that flush failed.
  void wait_for_flush();
  /// Flushes and closes the file (idempotent; the destructor calls it).
  void close();
  /// Path of the file.
  const std::string& path() const;
  /// True after a write failed and the file was abandoned.
  bool failed() const;
  /// Rows of /frames on disk after the last successful flush (one on the writer thread
  /// counts once it has ended: wait_for_flush).
  std::int64_t flushed_frames() const;
  /// For a process that ends at once while stopping (stop.hpp, set_stop_kept_reader; from
  /// any thread): waits until no write or flush is in flight, keeps every later one from
  /// starting (the writer is unusable after it: call it only on the way out), and returns
  /// the root attribute committed_frames read back from the file: the /frames rows every
  /// reader takes, which the file then holds. -1 when the file was closed or abandoned,
  /// the attribute cannot be read, or HDF5 is not thread-safe.
  std::int64_t read_back_frames_and_hold();

 private:
  void create_layout(const TraceMetadata& meta, const TraceBodies& bodies);
  void create_v2_layout();
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

/// Builds the root metadata of a trace for `engine` (its name, device, broadphase; the
/// scene and its parameters, including response.overlap and response.iterations).
TraceMetadata trace_metadata(const Engine& engine, int state_every);
/// Per-body tables of an engine's model for /bodies.
TraceBodies trace_bodies(const Engine& engine);

/// What a trace holds, read back (for tests and `octocd` tools).
struct TraceSummary {
  std::string format;
  int version = 0;
  std::int64_t frames = 0;        ///< complete rows in /frames (its shortest column)
  std::int64_t state_rows = 0;    ///< complete rows in /states (its shortest dataset)
  std::int64_t bodies = 0;
  std::int64_t last_frame = 0;    ///< /frames/frame of the last row (0 when empty)
};

/// Opens a trace read-only and summarises it. Throws RuntimeError naming the path when
/// the file is not a readable octocd trace.
TraceSummary read_trace_summary(const std::string& path);

/// Writes an XDMF 3 sidecar `<trace_path>.xmf` next to the trace, so that ParaView (Xdmf3
/// reader) opens the trace as an animation: one Polyvertex grid per /states row (time =
/// state frame x dt), geometry = that row of /states/position (an XDMF 3 HDF5 hyperslab
/// "file:/dataset|start:stride:count:dims", which ParaView's Xdmf3 readers read and its
/// legacy XDMF reader does not), node attributes velocity, shape_id, inverse_mass and, where
/// the trace has them, half_extents and group_id. The sidecar references the trace by file name, so keep them
/// in one folder. Reads the trace as it is now (a trace still being written gets the rows
/// flushed so far). Returns the sidecar's path. Throws RuntimeError naming the path when
/// the trace is unreadable or the sidecar cannot be written.
std::string write_xdmf_sidecar(const std::string& trace_path);

}  // namespace octocd
