#pragma once
/// \file trace_reader.hpp
/// Reads traces back (design.md section 8; layout in docs/trace-format.md, format
/// "octocd-trace" versions 1 and 2) for `octocd replay` and `octocd compare`: root attributes,
/// whole 1-D columns, and single rows of the per-body arrays of /states, without loading
/// the whole file. Opened read-only with the SWMR-read flag, so a trace still being
/// written or left by a killed run reads too (its complete rows: see complete_rows).
///
/// Every error is an InputError (a trace is input: `octocd` exits with 2) whose message
/// has the form `<file>: <dataset or attribute>: <problem>; allowed: ...`. The file is
/// opened and read under the rules of docs/trace-format.md, "Security rules and limits"
/// (regular files only, no external links, external storage or virtual datasets, every
/// attribute and dataset checked for type, shape and size before it is read).

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "octocd/math.hpp"

namespace octocd {

/// Limits on what a trace may declare or hold (docs/trace-format.md, "Security rules and
/// limits"). A file beyond them is an InputError (exit 2) before anything is allocated.
namespace trace_limits {
/// Most bodies of a trace (as scenes: limits::kMaxBodies).
constexpr std::uint64_t kMaxBodies = 10000000;
/// Most frames (rows of /frames, /aabbs, /states) of a trace: 10^8 (a day at 1 kHz).
constexpr std::uint64_t kMaxFrames = 100000000;
/// Most rows of a flat per-record dataset (/contacts/pair, /pairs/pair, ...): 2^32.
constexpr std::uint64_t kMaxRecords = 4294967296ull;
/// Largest string attribute or string element (bytes): 64 MiB (a scene file's text).
constexpr std::uint64_t kMaxStringBytes = 64ull << 20;
/// A dataset may declare at most this many bytes per byte of the file (plus
/// kSlackBytes): deflate, the only filter a trace may use, compresses at most 1032:1.
constexpr std::uint64_t kMaxExpansion = 1100;
/// Bytes any dataset may declare beyond kMaxExpansion x the file's size: 1 MiB.
constexpr std::uint64_t kSlackBytes = 1ull << 20;
/// One reader reads at most kMaxReadExpansion x the file's size + kReadSlackBytes of
/// values in all (every row read counts, each time it is read): a compression bomb (an
/// 11.8 MB file of deflated zeros declaring 13 GB) took 88 s for --check-only. octocd's own
/// traces store about 3 bytes of values per byte of file (positions shuffled and deflated
/// to about 1/2, velocities at rest to almost nothing) and `validate --trace-in` reads each
/// state row twice: 64 leaves a factor of 10 and bounds a bomb to seconds.
constexpr std::uint64_t kMaxReadExpansion = 64;
/// Bytes of values any reader may read beyond kMaxReadExpansion x the file's size: 64 MiB.
/// For a compressed chunked dataset the bytes counted are those inflated: every chunk a
/// read touches, whole, unless the reader's chunk cache holds it (the band of chunks of
/// the last rows read of that dataset stays cached while the reader lives), so a file
/// whose big chunks would be inflated again for each small row read is refused, not slow.
constexpr std::uint64_t kReadSlackBytes = 64ull << 20;
/// Largest chunk (bytes, inflated) of a compressed dataset, and largest band of chunks
/// one row spans (the reader's chunk cache per dataset): 256 MiB. octocd's own traces
/// chunk a row (a state row of 10^7 bodies: 120 MB); h5py's automatic chunks are below
/// 1 MiB. A larger chunk is refused naming the dataset before anything is read.
constexpr std::uint64_t kMaxChunkBytes = 256ull << 20;
/// Largest |coordinate| (m) of a position, an AABB corner or a local extent, and of a
/// position plus an extent: 10^6 m (a float32 step of 6 cm there), so that sums,
/// differences and squares stay finite in float32.
constexpr double kMaxCoordinate = 1e6;
/// Largest |velocity component| (m/s) and |gravity component| (m/s^2).
constexpr double kMaxSpeed = 1e6;
/// Largest |angular velocity component| (rad/s): 10^6 (a bead spinning at 160 kHz; scenes
/// allow 10^3), so that omega dt, omega x r and I omega stay finite in float32: 3e38 rad/s
/// made the integrated orientation and the energy infinite.
constexpr double kMaxAngularSpeed = 1e6;
/// Largest time step dt (s).
constexpr double kMaxDt = 10.0;
/// Smallest time step dt (s): 10^-7 s, ten times below the microsecond steps of stiff
/// contact solvers; a smaller dt (1e-300) rounds to 0 in float32 where the engines use it.
constexpr double kMinDt = 1e-7;
/// Largest contact margin (m), the distance up to which contacts are expected (Bullet's
/// breaking threshold 0.02 m, PhysX's contact offset about 0.02 m): 1 m, above any engine's
/// setting for bodies within the +-1000 m scenes; 1e300 switched the false-contact check off.
constexpr double kMaxContactMargin = 1.0;
/// Principal moments of inertia (the diagonal, kg m^2, body frame) of a dynamic body lie
/// in [kMinInertia, kMaxInertia]: 10^-12 is a 1 mm steel bead (4 mg, 0.4 m r^2 = 1.6e-12),
/// 10^15 a 10^8 kg ship of 100 m radius x 10; inertia 1e-45 let a body spin up for free.
constexpr double kMinInertia = 1e-12;
constexpr double kMaxInertia = 1e15;
/// Largest |contact impulse| (N s, jn, jt, each jt3 component): 10^9, a 10^6 kg body
/// stopped from 1000 m/s in one step; jn = 3e38 made every physics row pass.
constexpr double kMaxImpulse = 1e9;
}  // namespace trace_limits

/// A root attribute of a trace read whatever its kind (TraceReader::attribute).
struct TraceAttribute {
  bool is_string = false;            ///< strings (else numbers)
  bool scalar = true;                ///< stored as one value (a scalar or a 1-element array)
  std::vector<std::string> strings;  ///< its strings, when is_string
  std::vector<double> numbers;       ///< its numbers (integers converted), otherwise
};

/// One trace file, open read-only. Not thread-safe. Move-only.
class TraceReader {
 public:
  /// Opens `path` and checks the root attributes `format == "octocd-trace"` and
  /// `version` 1 or 2 (2: a rotating engine's trace, docs/trace-format.md "External
  /// traces, version 2"; what a reader does with it is the reader's business: `replay`
  /// refuses it, `compare` reads its rotation). Throws InputError naming the file when it
  /// does not exist, is not an HDF5 file, or is a trace of another format or version.
  explicit TraceReader(const std::string& path);
  ~TraceReader();
  TraceReader(TraceReader&&) noexcept;
  TraceReader& operator=(TraceReader&&) noexcept;

  /// The /frames columns of format version 1, in the writer's order ("frame", "time",
  /// "step_ms", the stage times, counters and figures, "momentum", "memory_bytes").
  static const std::vector<std::string>& frame_columns();

  /// The file's path as given.
  const std::string& path() const;
  /// The root attribute `version`: 1 or 2.
  int version() const;

  /// Whether the root attribute `name` exists.
  bool has_attribute(const std::string& name) const;
  /// Root string attribute (throws InputError when absent or not a string).
  std::string string_attribute(const std::string& name) const;
  /// Root numeric attribute, converted to double (throws InputError when absent).
  double number_attribute(const std::string& name) const;

  /// Root attribute `name`: strings or numbers (integer or float), at most 64 values, a
  /// string at most trace_limits::kMaxStringBytes. Throws InputError naming it when it is
  /// missing, of another type class (compound, reference, ...) or larger.
  TraceAttribute attribute(const std::string& name) const;

  /// Whether the dataset at `dataset` (e.g. "/states/position") exists.
  bool has_dataset(const std::string& dataset) const;
  /// The dataset's dimensions (throws InputError when absent).
  std::vector<std::uint64_t> shape(const std::string& dataset) const;
  /// Complete rows of "/frames", "/states" or "/contacts" (docs/trace-format.md: the first
  /// min(len) rows over the group's datasets of format version 1 (and
  /// version 2's /states/orientation and /states/angular_velocity), and at most the root
  /// attribute committed_frames or committed_states when the trace has it: rows past it
  /// may never have reached the disk); 0 for a group without them. Throws InputError when
  /// the group is absent or another group.
  std::int64_t complete_rows(const std::string& group) const;

  /// The first `rows` rows of a dataset, every element converted by HDF5 to the asked
  /// type (for a dataset of rank > 1, rows x the other dimensions, row-major). Throws
  /// InputError when absent, when `rows` exceeds its length, or when HDF5 cannot
  /// convert its type.
  std::vector<double> read_f64(const std::string& dataset, std::int64_t rows) const;
  std::vector<std::int64_t> read_i64(const std::string& dataset, std::int64_t rows) const;
  std::vector<std::uint64_t> read_u64(const std::string& dataset, std::int64_t rows) const;
  std::vector<std::uint32_t> read_u32(const std::string& dataset, std::int64_t rows) const;
  std::vector<float> read_f32(const std::string& dataset, std::int64_t rows) const;
  /// Rows [first, first + count) of a float dataset (e.g. one state of /states/position:
  /// count 1 gives bodies x 3 floats), row-major.
  std::vector<float> read_f32_rows(const std::string& dataset, std::int64_t first, std::int64_t count) const;
  /// Rows [first, first + count) of a numeric dataset converted to double / int64,
  /// row-major (as read_f32_rows).
  std::vector<double> read_f64_rows(const std::string& dataset, std::int64_t first, std::int64_t count) const;
  std::vector<std::int64_t> read_i64_rows(const std::string& dataset, std::int64_t first, std::int64_t count) const;
  /// The type class of a dataset's elements: "integer", "float", "string" or "other"
  /// (throws InputError when absent or refused: see the class comment).
  std::string element_kind(const std::string& dataset) const;
  /// Every element of a 1-D string dataset (e.g. /bodies/group).
  std::vector<std::string> read_strings(const std::string& dataset) const;

  /// Local AABBs of /bodies (local_aabb_min, local_aabb_max), one per body (m). Throws
  /// InputError naming the dataset unless both are bodies x 3 (at most
  /// trace_limits::kMaxBodies bodies), finite, |value| <= 10^6 m and min <= max.
  std::vector<Aabb> local_boxes() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace octocd
