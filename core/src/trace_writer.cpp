// The HDF5 trace writer (design.md section 8; layout: docs/trace-format.md). Its HDF5 write
// primitives are in trace_hdf5_out.cpp, the metadata and body tables it takes from an engine
// in trace_metadata.cpp, the summary of a trace read back in trace_summary.cpp, the XDMF
// sidecar in trace_xdmf.cpp.
//
// The file is created with the latest format, every group, dataset and attribute is
// created up front, then SWMR writing starts. Rows are buffered in memory and written in
// batches at each flush (every `flush_every` frames, for small batches no sooner than
// `flush_interval_s` after the previous one; or once `flush_bytes` are buffered), followed
// by H5Fflush: a process
// killed between flushes leaves a file that SWMR readers open, holding every flushed row.
// The flushes that appending frames triggers run on a writer thread of their own (HDF5's
// writes, deflate and H5Fflush beside the caller's next steps): the rows of one flush are
// handed over whole, the next waits for it, so at most two batches are held; a failure on
// that thread is thrown by the next call that appends, flushes or closes. flush() and
// close() write on the caller's thread once the writer thread is idle. With an HDF5 built
// without thread safety every flush runs on the caller's thread.


#include "octocd/trace.hpp"
#include "octocd/atomic_file.hpp"

#include <fcntl.h>
#include <hdf5.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <cstdio>
#include <cstring>
#include <ctime>
#include <filesystem>
#include <mutex>
#include <thread>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "octocd/error.hpp"
#include "octocd/stop.hpp"
#include "octocd/version.hpp"
#include "hdf5_handle.hpp"
#include "trace_hdf5_out.hpp"
#include "trace_detail.hpp"

namespace octocd {

namespace {

constexpr int kVersion = 1;
constexpr int kStageCount = static_cast<int>(Stage::Count);
constexpr const char* kCounterColumns[] = {"cell_candidates", "aabb_pairs", "dynamic_pairs", "box_tests",
                                           "box_pairs", "vertex_tests", "contacts"};
constexpr const char* kFigureColumns[] = {"penetration_mean", "penetration_max",
                                          "penetration_share_above_slop", "kinetic_energy"};

// The /frames columns of format version 1, in the writer's order (docs/trace-format.md).
const std::vector<std::string>& frame_column_names() {
  static const std::vector<std::string> names = [] {
    std::vector<std::string> n{"frame", "time", "step_ms"};
    for (int s = 0; s < kStageCount; ++s) n.push_back(std::string(stage_name(static_cast<Stage>(s))) + "_ms");
    for (const char* c : kCounterColumns) n.emplace_back(c);
    for (const char* c : kFigureColumns) n.emplace_back(c);
    n.emplace_back("momentum");
    n.emplace_back("memory_bytes");
    return n;
  }();
  return names;
}

using detail::QuietHdf5;

}  // namespace

const std::vector<std::string>& detail::trace_frame_columns() { return frame_column_names(); }

namespace {

// HDF5 closes every open file from an atexit handler. A trace abandoned after a failed
// write (a full disk) must never be flushed again: that would write metadata that points
// past the data on disk, or, after a failed H5Fclose, touch a freed file (SIGSEGV), and
// print "infinite loop closing library". So the handler is turned off before HDF5 starts
// (it must be, to take effect); TraceWriter closes every file it finishes itself.
const bool kHdf5NoAtexit = [] {
  H5dont_atexit();
  return true;
}();

}  // namespace

using namespace trace_out;


// ---------------------------------------------------------------------------------------

struct TraceWriter::Impl {
  std::string path;
  TraceOptions opt;
  std::size_t bodies = 0;
  Handle file;
  std::vector<Column> frames;  // "frame" first
  Column s_frame, s_pos, s_vel;
  Column c_offsets, c_frame, c_pair, c_normal, c_depth, c_jn, c_jt;
  std::int64_t contact_total = 0;
  // Version 2 (TraceOptions::v2): rotation, contact points, candidate pairs, AABBs.
  Column s_orient, s_angvel, c_point, c_jt3, c_point_b, p_offsets, p_pair, a_min, a_max;
  std::int64_t pair_total = 0;
  int since_flush = 0;
  std::chrono::steady_clock::time_point last_flush_start = std::chrono::steady_clock::now();
  bool closed = false;
  bool failed = false;               // a write failed: the file was abandoned
  std::int64_t last_appended = 0;    // frame of the last append_frame
  std::atomic<std::int64_t> flushed_rows{0};  // /frames rows on disk after the last good flush
  std::mutex io;                     // held by every write and flush (read_back_and_hold)
  std::int64_t last_flushed = 0;     // frame of the last of them
  std::vector<float> scratch;

  // The writer thread (started by the first flush handed over): one job at a time.
  std::thread writer;
  std::mutex mu;
  std::condition_variable cv;
  bool job = false;                  // a flush handed over, not yet done
  bool quit = false;
  std::string job_when;              // the job's "writing frame N" for a failure's message
  std::int64_t job_last = 0;         // last_appended when it was handed over
  bool job_failed = false;
  std::string job_reason;            // the HDF5 failure's reason

  ~Impl() { stop_writer(); }

  void stop_writer() noexcept {
    if (!writer.joinable()) return;
    {
      std::lock_guard<std::mutex> lock(mu);
      quit = true;
    }
    cv.notify_all();
    writer.join();
  }

  void writer_loop() {
    QuietHdf5 quiet;  // per thread: HDF5's error stacks are
    std::unique_lock<std::mutex> lock(mu);
    for (;;) {
      cv.wait(lock, [&] { return job || quit; });
      if (!job) return;  // quit with nothing handed over
      lock.unlock();
      bool ok = true;
      std::string reason;
      try {
        write_staged_and_flush();
      } catch (const Hdf5Failure& e) {
        ok = false;
        reason = e.reason();
      }
      lock.lock();
      if (ok) {
        flushed_rows = frames.empty() ? 0 : static_cast<std::int64_t>(frames[0].rows);
        last_flushed = job_last;
      } else {
        job_failed = true;
        job_reason = reason;
      }
      job = false;
      cv.notify_all();
      if (!ok) return;  // nothing more is written to an abandoned file
    }
  }

  // Whether a flush handed to the writer thread is still in flight.
  bool writer_busy() {
    if (!writer.joinable()) return false;
    std::lock_guard<std::mutex> lock(mu);
    return job;
  }

  // Waits until no flush is in flight; after a failed one abandons the file and throws
  // its message.
  void wait_writer() {
    if (!writer.joinable()) return;
    std::unique_lock<std::mutex> lock(mu);
    cv.wait(lock, [&] { return !job; });
    if (job_failed) {
      lock.unlock();
      stop_writer();
      const std::string when = job_when, reason = job_reason;
      abandon();
      throw RuntimeError(failure(when, reason));
    }
  }

  // Hands the appended rows to the writer thread (after the previous flush is done). An
  // HDF5 built without thread safety (not Debian's) is called from one thread only: the
  // flush then runs here.
  void flush_behind(const std::string& when) {
    static const bool threadsafe = [] {
      hbool_t ts = 0;
      return H5is_library_threadsafe(&ts) >= 0 && ts;
    }();
    if (!threadsafe) {
      QuietHdf5 quiet;
      write_and_flush(when);
      return;
    }
    wait_writer();
    for (Column* c : columns()) c->stage();
    since_flush = 0;
    last_flush_start = std::chrono::steady_clock::now();
    {
      std::lock_guard<std::mutex> lock(mu);
      job = true;
      job_when = when;
      job_last = last_appended;
    }
    if (!writer.joinable()) writer = std::thread([this] { writer_loop(); });
    cv.notify_all();
  }

  // Every column, for abandon().
  std::vector<Column*> columns() {
    std::vector<Column*> all{&s_frame, &s_pos, &s_vel, &c_offsets, &c_frame, &c_pair, &c_normal,
                             &c_depth, &c_jn, &c_jt};
    if (opt.v2)
      for (Column* c : {&s_orient, &s_angvel, &c_point, &c_jt3, &c_point_b, &p_offsets, &p_pair, &a_min, &a_max})
        all.push_back(c);
    for (Column& c : frames) all.push_back(&c);
    return all;
  }

  // After a failed write the file is left exactly as the writes so far made it (as if the
  // process had been killed there: every flushed frame readable, docs/trace-format.md):
  // nothing more is written, no identifier is closed (closing flushes), buffers are freed.
  // HDF5's own structures for the file leak, once per failed trace.
  void abandon() noexcept {
    failed = closed = true;
    for (Column* c : columns()) {
      c->dset.release();
      std::vector<unsigned char>().swap(c->buf);
      std::vector<unsigned char>().swap(c->out);
    }
    file.release();
  }

  // The one-line message for a write that failed for `reason`.
  std::string failure(const std::string& when, const std::string& reason) const {
    std::string msg = "trace '" + path + "': " + when + " failed (" + reason + "); ";
    if (flushed_rows == 0)
      msg += "no frame was flushed before the failure";
    else
      msg += "the file keeps the " + std::to_string(flushed_rows) + " frames up to frame " +
             std::to_string(last_flushed) + ", flushed before the failure";
    return msg;
  }

  // Writes the buffered rows and flushes; then, once they are on disk, records the new
  // row counts in the root attributes committed_frames and committed_states and flushes
  // again. Readers read no row past them (docs/trace-format.md): a failed write may leave
  // datasets extended over rows whose data never reached the disk (a full disk), and the
  // attributes still give the rows written in full. On failure abandons the file and
  // throws; the message gives the rows the attributes on disk vouch for.
  void write_and_flush(const std::string& when) {
    wait_writer();
    try {
      for (Column* c : columns()) c->stage();
      write_staged_and_flush();
    } catch (const Hdf5Failure& e) {
      abandon();
      throw RuntimeError(failure(when, e.reason()));
    }
    since_flush = 0;
    last_flush_start = std::chrono::steady_clock::now();
    flushed_rows = frames.empty() ? 0 : static_cast<std::int64_t>(frames[0].rows);
    last_flushed = last_appended;
  }

  // Writes the staged rows, flushes, records committed_frames / committed_states and
  // flushes again (write_and_flush); throws Hdf5Failure. Touches no column's buf.
  void write_staged_and_flush() {
    const std::lock_guard<std::mutex> lock(io);
    // After SIGINT/SIGTERM the process has a second to end: rows stored uncompressed.
    write_all(stop_signal() != 0);
    check(H5Fflush(file, H5F_SCOPE_GLOBAL), path, "flush");
    write_committed(static_cast<std::int64_t>(frames.empty() ? 0 : frames[0].rows),
                    static_cast<std::int64_t>(s_frame.rows));
    check(H5Fflush(file, H5F_SCOPE_GLOBAL), path, "flush");
  }

  // Version 2 columns, written before the version 1 ones they accompany.
  void write_v2(bool raw) {
    if (!opt.v2) return;
    s_orient.write_staged(path, raw);
    s_angvel.write_staged(path, raw);
    if (opt.contacts)
      for (Column* c : {&c_point, &c_jt3, &c_point_b, &a_min, &a_max, &p_pair, &p_offsets}) c->write_staged(path, raw);
  }

  // Version 2: the orientation and angular velocity rows of a state row.
  void push_rotation(const BodyState& st) {
    static_assert(sizeof(Quat) == 4 * sizeof(float), "Quat must be four packed floats");
    if (st.q.size() == bodies && st.omega.size() == bodies) {
      s_orient.push(reinterpret_cast<const float*>(st.q.data()), 4 * bodies);
      s_angvel.push(reinterpret_cast<const float*>(st.omega.data()), 3 * bodies);
      return;
    }
    const float identity[4] = {1.0f, 0.0f, 0.0f, 0.0f};  // (w, x, y, z)
    const float zero[3] = {0.0f, 0.0f, 0.0f};
    for (std::size_t i = 0; i < bodies; ++i) {
      s_orient.push(identity, 4);
      s_angvel.push(zero, 3);
    }
  }

  // Sets the root attributes committed_frames and committed_states (created with the file).
  void write_committed(std::int64_t frame_rows, std::int64_t state_rows) {
    for (const auto& [name, value] : {std::pair<const char*, std::int64_t>{"committed_frames", frame_rows},
                                      std::pair<const char*, std::int64_t>{"committed_states", state_rows}}) {
      Handle a(check(H5Aopen(file, name, H5P_DEFAULT), path, std::string("open attribute ") + name));
      check(H5Awrite(a, H5T_NATIVE_INT64, &value), path, std::string("write attribute ") + name);
    }
  }

  void write_all(bool raw) {
    write_v2(raw);
    // States before their frame column, contact arrays before offsets, /frames/frame
    // last: readers clip every group to the shortest column (docs/trace-format.md).
    s_pos.write_staged(path, raw);
    s_vel.write_staged(path, raw);
    s_frame.write_staged(path);
    if (opt.contacts) {
      for (Column* c : {&c_pair, &c_normal, &c_depth, &c_jn, &c_jt, &c_frame, &c_offsets})
        c->write_staged(path);
    }
    for (std::size_t i = frames.size(); i-- > 0;) frames[i].write_staged(path);
  }

  void push_state(std::int64_t frame, const BodyState& st) {
    if (st.x.size() != bodies || st.v.size() != bodies)
      throw RuntimeError("trace '" + path + "': state of frame " + std::to_string(frame) +
                         " has " + std::to_string(st.x.size()) + " positions and " +
                         std::to_string(st.v.size()) + " velocities, the trace has " +
                         std::to_string(bodies) + " bodies");
    s_frame.push1(frame);
    static_assert(sizeof(Vec3) == 3 * sizeof(float), "Vec3 must be three packed floats");
    s_pos.push(reinterpret_cast<const float*>(st.x.data()), 3 * bodies);
    s_vel.push(reinterpret_cast<const float*>(st.v.data()), 3 * bodies);
    if (opt.v2 && opt.v2->rotates) push_rotation(st);
  }
};

TraceWriter::TraceWriter(const std::string& path, const TraceMetadata& meta,
                         const TraceBodies& bodies, const TraceOptions& options)
    : impl_(std::make_unique<Impl>()) {
  Impl& m = *impl_;
  m.path = path;
  m.opt = options;
  if (m.opt.state_every < 1)
    throw RuntimeError("trace '" + path + "': state_every must be >= 1, got " +
                       std::to_string(m.opt.state_every));
  if (m.opt.flush_every < 1)
    throw RuntimeError("trace '" + path + "': flush_every must be >= 1, got " +
                       std::to_string(m.opt.flush_every));
  if (m.opt.flush_bytes < 1) throw RuntimeError("trace '" + path + "': flush_bytes must be >= 1, got 0");
  if (!(m.opt.flush_interval_s >= 0.0) || !std::isfinite(m.opt.flush_interval_s))
    throw RuntimeError("trace '" + path + "': flush_interval_s must be a finite number >= 0, got " +
                       std::to_string(m.opt.flush_interval_s));
  const std::size_t n = bodies.shape_id.size();
  if (bodies.inverse_mass.size() != n || bodies.local_aabb.size() != n || bodies.group.size() != n)
    throw RuntimeError("trace '" + path + "': body tables differ in length (shape_id " +
                       std::to_string(n) + ", inverse_mass " +
                       std::to_string(bodies.inverse_mass.size()) + ", local_aabb " +
                       std::to_string(bodies.local_aabb.size()) + ", group " +
                       std::to_string(bodies.group.size()) + ")");
  m.bodies = n;

  namespace fs = std::filesystem;
  const fs::path parent = fs::path(path).parent_path();
  std::error_code ec;
  if (!parent.empty() && !fs::is_directory(parent, ec))
    throw RuntimeError("trace '" + path + "': cannot create the file: directory '" +
                       parent.string() + "' does not exist");

  QuietHdf5 quiet;
  Handle fapl(check(H5Pcreate(H5P_FILE_ACCESS), path, "H5Pcreate"));
  check(H5Pset_libver_bounds(fapl, H5F_LIBVER_LATEST, H5F_LIBVER_LATEST), path,
        "H5Pset_libver_bounds");
  // Rows are only appended, so a written chunk is never touched again: a chunk cache of
  // 64 KiB per dataset (eight /frames chunks) that evicts fully written chunks first
  // (w0 = 1) keeps memory flat over a long run. HDF5's default keeps up to 1 MiB per
  // dataset: RSS grew by 160 bytes a frame up to +19 MiB (issue 10's soak). (Set on the
  // file: a dataset access list given to H5Dcreate2 is not used for this in HDF5 1.10.)
  check(H5Pset_cache(fapl, 0, 101, 64 * 1024, 1.0), path, "H5Pset_cache");
  // HDF5 locks a new file (flock) while it creates it and until SWMR writing starts; a
  // reader in another process (h5py, a viewer, a wait on the trace) that opens it in that
  // window makes the lock fail (EAGAIN: 140 of 300 runs with one reader in a loop). So the
  // trace is made as PATH.tmp.XXXXXX beside PATH (mkstemp: an unpredictable name created
  // O_EXCL, so nothing planted there is followed) and renamed onto PATH once SWMR writing
  // started: readers never see it locked, and an earlier trace at PATH stays whole until
  // then. PATH must be absent or a regular file: a device (/dev/full), a FIFO, a folder or
  // a symbolic link there is InputError, never written through (atomic_file.hpp).
  const TemporaryFile tmp = create_temporary_beside(path, "trace");
  const std::string& made = tmp.path;
  const TrackedTemporary tracked(made);  // until it is renamed, a stop removes it too
  struct stat made_st {};
  int made_fd = tmp.fd;  // open until HDF5 has the file, so that its inode cannot be reused
  const bool stat_ok = ::fstat(made_fd, &made_st) == 0;
  try {
    try {
      m.file = Handle(check(H5Fcreate(made.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, fapl), path, "create file"));
      // The file HDF5 opened by name is the one mkstemp created (not one swapped in since).
      void* handle = nullptr;
      struct stat opened {};
      if (H5Fget_vfd_handle(m.file, H5P_DEFAULT, &handle) < 0 || handle == nullptr ||
          ::fstat(*static_cast<int*>(handle), &opened) != 0 || !stat_ok || opened.st_ino != made_st.st_ino ||
          opened.st_dev != made_st.st_dev)
        throw Hdf5Failure(path, "create file", "the temporary file " + made + " was replaced while it was opened");
      ::close(made_fd);
      made_fd = -1;
      create_layout(meta, bodies);
    } catch (const Hdf5Failure& e) {
      m.abandon();
      throw RuntimeError(m.failure("creating the file", e.reason()));
    }
    try {
      rename_over(made, path, "trace");
    } catch (...) {
      m.abandon();
      throw;
    }
  } catch (...) {
    if (made_fd >= 0) ::close(made_fd);
    ::unlink(made.c_str());
    throw;
  }
}

void TraceWriter::create_layout(const TraceMetadata& meta, const TraceBodies& bodies) {
  Impl& m = *impl_;
  const std::string& path = m.path;
  const std::size_t n = m.bodies;
  QuietHdf5 quiet;

  // ---- root attributes
  const hid_t root = m.file;
  attr_string(root, "format", detail::kTraceFormat, path);
  attr_scalar(root, "version", H5T_STD_I32LE, H5T_NATIVE_INT, m.opt.v2 ? 2 : kVersion, path);
  attr_string(root, "scene_name", meta.scene_name, path);
  attr_string(root, "scene", meta.scene_json, path);
  attr_string(root, "parameters", meta.parameters_json, path);
  attr_string(root, "engine", meta.engine, path);
  attr_string(root, "broadphase", meta.broadphase, path);
  attr_string(root, "midphase", meta.midphase, path);
  attr_string(root, "build_id", meta.build_id, path);
  attr_string(root, "device", meta.device, path);
  attr_string(root, "start_time", meta.start_time, path);
  attr_scalar(root, "dt", H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE, meta.dt, path);
  {  // declarations (docs/trace-format.md, "Declarations"): only those the engine makes
    const TraceDeclarations& d = meta.declarations;
    const std::pair<const char*, const std::string*> text[] = {
        {"contact_margin_rule", &d.contact_margin_rule}, {"jt_direction", &d.jt_direction},
        {"response_scheme", &d.response_scheme},         {"deactivation", &d.deactivation}};
    for (const auto& [name, value] : text)
      if (!value->empty()) attr_string(root, name, *value, path);
    // Those a version 2 trace states through RotationTraits are written there.
    if (!m.opt.v2) {
      if (!d.contact_geometry.empty()) attr_string(root, "contact_geometry", d.contact_geometry, path);
      if (d.broadphase_exact >= 0)
        attr_scalar(root, "broadphase_exact", H5T_STD_I32LE, H5T_NATIVE_INT, d.broadphase_exact, path);
      if (!d.integrator.empty()) attr_string(root, "integrator", d.integrator, path);
      if (!d.contact_model.empty()) attr_string(root, "contact_model", d.contact_model, path);
    }
    if (d.velocity_clamp >= 0.0)
      attr_scalar(root, "velocity_clamp", H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE, d.velocity_clamp, path);
    if (d.impulses_complete >= 0)
      attr_scalar(root, "impulses_complete", H5T_STD_I32LE, H5T_NATIVE_INT, d.impulses_complete, path);
    if (d.friction_directions >= 0)
      attr_scalar(root, "friction_directions", H5T_STD_I32LE, H5T_NATIVE_INT, d.friction_directions, path);
  }
  attr_scalar(root, "state_every", H5T_STD_I32LE, H5T_NATIVE_INT, m.opt.state_every, path);
  attr_scalar(root, "flush_every", H5T_STD_I32LE, H5T_NATIVE_INT, m.opt.flush_every, path);
  attr_scalar(root, "body_count", H5T_STD_I64LE, H5T_NATIVE_INT64,
              static_cast<std::int64_t>(n), path);
  std::vector<std::string> stages;
  for (int i = 0; i < kStageCount; ++i) stages.emplace_back(stage_name(static_cast<Stage>(i)));
  attr_strings(root, "stage_names", stages, path);
  // Rows written in full (write_and_flush): readers read no row past them.
  attr_scalar(root, "committed_frames", H5T_STD_I64LE, H5T_NATIVE_INT64, std::int64_t{0}, path);
  attr_scalar(root, "committed_states", H5T_STD_I64LE, H5T_NATIVE_INT64, std::int64_t{0}, path);

  // ---- /bodies (fixed, written now)
  {
    Handle g(check(H5Gcreate2(root, "bodies", H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT), path,
                   "create group /bodies"));
    fixed_dataset(g, "shape_id", H5T_STD_U32LE, H5T_NATIVE_UINT32, {n}, bodies.shape_id.data(),
                  path);
    fixed_dataset(g, "inverse_mass", H5T_IEEE_F32LE, H5T_NATIVE_FLOAT, {n},
                  bodies.inverse_mass.data(), path);
    std::vector<float> lo(3 * n), hi(3 * n);
    for (std::size_t i = 0; i < n; ++i)
      for (int k = 0; k < 3; ++k) {
        lo[3 * i + k] = bodies.local_aabb[i].min[k];
        hi[3 * i + k] = bodies.local_aabb[i].max[k];
      }
    fixed_dataset(g, "local_aabb_min", H5T_IEEE_F32LE, H5T_NATIVE_FLOAT, {n, 3}, lo.data(), path);
    fixed_dataset(g, "local_aabb_max", H5T_IEEE_F32LE, H5T_NATIVE_FLOAT, {n, 3}, hi.data(), path);
    string_dataset(g, "group", bodies.group, path);
    string_dataset(g, "shape_names", bodies.shape_names, path);
    // Numeric forms for viewers (the XDMF sidecar): half extents, and the group as an
    // index into group_names (names in order of first appearance: "walls" first).
    std::vector<float> half(3 * n);
    for (std::size_t i = 0; i < 3 * n; ++i) half[i] = 0.5f * (hi[i] - lo[i]);
    fixed_dataset(g, "half_extents", H5T_IEEE_F32LE, H5T_NATIVE_FLOAT, {n, 3}, half.data(), path);
    std::vector<std::string> group_names;
    std::vector<std::int32_t> group_id(n);
    for (std::size_t i = 0; i < n; ++i) {
      const auto it = std::find(group_names.begin(), group_names.end(), bodies.group[i]);
      group_id[i] = static_cast<std::int32_t>(it - group_names.begin());
      if (it == group_names.end()) group_names.push_back(bodies.group[i]);
    }
    fixed_dataset(g, "group_id", H5T_STD_I32LE, H5T_NATIVE_INT32, {n}, group_id.data(), path);
    string_dataset(g, "group_names", group_names, path);
  }

  // ---- /frames
  {
    Handle g(check(H5Gcreate2(root, "frames", H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT), path,
                   "create group /frames"));
    constexpr hsize_t kChunk = 1024;
    auto add = [&](const std::string& name, hid_t ft, hid_t mt, std::vector<hsize_t> tail = {}) {
      m.frames.push_back(make_column(g, "/frames", name.c_str(), ft, mt, tail, kChunk, 0, path));
    };
    // In the order of frame_column_names() (the reader's list).
    add("frame", H5T_STD_I64LE, H5T_NATIVE_INT64);
    add("time", H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE);
    add("step_ms", H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE);
    for (int s = 0; s < kStageCount; ++s)
      add(std::string(stage_name(static_cast<Stage>(s))) + "_ms", H5T_IEEE_F64LE,
          H5T_NATIVE_DOUBLE);
    for (const char* c : kCounterColumns) add(c, H5T_STD_U64LE, H5T_NATIVE_UINT64);
    for (const char* c : kFigureColumns) add(c, H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE);
    add("momentum", H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE, {3});
    add("memory_bytes", H5T_STD_U64LE, H5T_NATIVE_UINT64);
    if (m.frames.size() != frame_column_names().size())
      throw RuntimeError("trace '" + path + "': internal: /frames columns differ from frame_column_names()");
  }

  // ---- /states
  {
    Handle g(check(H5Gcreate2(root, "states", H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT), path,
                   "create group /states"));
    m.s_frame = make_column(g, "/states", "frame", H5T_STD_I64LE, H5T_NATIVE_INT64, {}, 256, 0, path);
    m.s_pos = make_column(g, "/states", "position", H5T_IEEE_F32LE, H5T_NATIVE_FLOAT, {n, 3}, 1, 2,
                          path);
    m.s_vel = make_column(g, "/states", "velocity", H5T_IEEE_F32LE, H5T_NATIVE_FLOAT, {n, 3}, 1, 2,
                          path);
  }

  // ---- /contacts (optional)
  if (m.opt.contacts) {
    Handle g(check(H5Gcreate2(root, "contacts", H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT), path,
                   "create group /contacts"));
    constexpr hsize_t kChunk = 4096;
    m.c_offsets = make_column(g, "/contacts", "offsets", H5T_STD_I64LE, H5T_NATIVE_INT64, {}, 1024,
                              0, path);
    m.c_frame = make_column(g, "/contacts", "frame", H5T_STD_I64LE, H5T_NATIVE_INT64, {}, 1024, 0,
                            path);
    m.c_pair = make_column(g, "/contacts", "pair", H5T_STD_U32LE, H5T_NATIVE_UINT32, {2}, kChunk,
                           0, path);
    m.c_normal = make_column(g, "/contacts", "normal", H5T_IEEE_F32LE, H5T_NATIVE_FLOAT, {3},
                             kChunk, 0, path);
    m.c_depth = make_column(g, "/contacts", "depth", H5T_IEEE_F32LE, H5T_NATIVE_FLOAT, {}, kChunk,
                            0, path);
    m.c_jn = make_column(g, "/contacts", "jn", H5T_IEEE_F32LE, H5T_NATIVE_FLOAT, {}, kChunk, 0,
                         path);
    m.c_jt = make_column(g, "/contacts", "jt", H5T_IEEE_F32LE, H5T_NATIVE_FLOAT, {}, kChunk, 0,
                         path);
    m.c_offsets.push1<std::int64_t>(0);
    m.c_offsets.write(path);
  }

  if (m.opt.v2) create_v2_layout();

  check(H5Fstart_swmr_write(m.file), path, "H5Fstart_swmr_write");
  check(H5Fflush(m.file, H5F_SCOPE_GLOBAL), path, "flush");
}

// Version 2 (docs/trace-format.md, "Version 2"; V2-LAYOUT): the root attributes and
// datasets a rotating engine's trace adds to version 1. Called before SWMR starts.
void TraceWriter::create_v2_layout() {
  Impl& m = *impl_;
  const std::string& path = m.path;
  const std::size_t n = m.bodies;
  const RotationTraits& t = *m.opt.v2;
  const hid_t root = m.file;
  attr_string(root, "detection", t.detection, path);
  attr_scalar(root, "mu", H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE, static_cast<double>(t.mu), path);
  attr_scalar(root, "restitution", H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE, static_cast<double>(t.restitution), path);
  attr_string(root, "friction_combine", t.friction_combine, path);
  attr_string(root, "restitution_combine", t.restitution_combine, path);
  attr_scalar(root, "contact_margin", H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE, static_cast<double>(t.contact_margin),
              path);
  attr_scalar(root, "broadphase_exact", H5T_STD_I32LE, H5T_NATIVE_INT, t.broadphase_exact ? 1 : 0, path);
  attr_string(root, "contact_geometry", t.contact_geometry, path);
  if (!t.collision_shape.empty() && t.body_collision_shape.empty())
    attr_string(root, "collision_shape", t.collision_shape, path);
  if (!t.contact_model.empty()) attr_string(root, "contact_model", t.contact_model, path);
  if (!t.integrator.empty()) attr_string(root, "integrator", t.integrator, path);
  if (!t.gyroscopic.empty()) attr_string(root, "gyroscopic", t.gyroscopic, path);
  if (!t.deactivation.empty()) attr_string(root, "deactivation", t.deactivation, path);
  if (!t.impulse_points.empty()) attr_string(root, "impulse_points", t.impulse_points, path);
  if (t.normal_reuse_deg >= 0.0)
    attr_scalar(root, "normal_reuse_deg", H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE, t.normal_reuse_deg, path);
  {
    const hsize_t three = 3;
    Handle space(check(H5Screate_simple(1, &three, nullptr), path, "H5Screate_simple"));
    Handle a(check(H5Acreate2(root, "gravity", H5T_IEEE_F64LE, space, H5P_DEFAULT, H5P_DEFAULT), path,
                   "create attribute gravity"));
    const double g[3] = {m.opt.gravity.x, m.opt.gravity.y, m.opt.gravity.z};
    check(H5Awrite(a, H5T_NATIVE_DOUBLE, g), path, "write attribute gravity");
  }
  auto per_body = [&](const std::vector<float>& v, const char* what) {
    if (v.size() != n)
      throw RuntimeError("trace '" + path + "': " + what + " has " + std::to_string(v.size()) +
                         " values, the trace has " + std::to_string(n) + " bodies");
  };
  {
    Handle g(check(H5Gopen2(root, "bodies", H5P_DEFAULT), path, "open group /bodies"));
    if (t.rotates && t.inertia.size() != n)
      throw RuntimeError("trace '" + path + "': inertia has " + std::to_string(t.inertia.size()) +
                         " tensors, the trace has " + std::to_string(n) + " bodies");
    if (t.rotates) {  // a translation-only trace has no inertia (its bodies never turn)
      std::vector<float> inertia(9 * n);
      for (std::size_t i = 0; i < n; ++i) std::copy(t.inertia[i].begin(), t.inertia[i].end(), inertia.begin() + 9 * i);
      fixed_dataset(g, "inertia", H5T_IEEE_F32LE, H5T_NATIVE_FLOAT, {n, 3, 3}, inertia.data(), path);
    }
    if (!t.body_friction.empty()) {
      per_body(t.body_friction, "body_friction");
      fixed_dataset(g, "friction", H5T_IEEE_F32LE, H5T_NATIVE_FLOAT, {n}, t.body_friction.data(), path);
    }
    if (!t.body_restitution.empty()) {
      per_body(t.body_restitution, "body_restitution");
      fixed_dataset(g, "restitution", H5T_IEEE_F32LE, H5T_NATIVE_FLOAT, {n}, t.body_restitution.data(), path);
    }
    if (!t.body_collision_shape.empty()) {
      if (t.body_collision_shape.size() != n)
        throw RuntimeError("trace '" + path + "': body_collision_shape has " +
                           std::to_string(t.body_collision_shape.size()) + " values, the trace has " +
                           std::to_string(n) + " bodies");
      string_dataset(g, "collision_shape", t.body_collision_shape, path);
    }
  }
  if (t.rotates) {
    Handle g(check(H5Gopen2(root, "states", H5P_DEFAULT), path, "open group /states"));
    m.s_orient = make_column(g, "/states", "orientation", H5T_IEEE_F32LE, H5T_NATIVE_FLOAT, {n, 4}, 1, 2, path);
    m.s_angvel = make_column(g, "/states", "angular_velocity", H5T_IEEE_F32LE, H5T_NATIVE_FLOAT, {n, 3}, 1, 2, path);
  }
  if (!m.opt.contacts) return;
  constexpr hsize_t kChunk = 4096;
  {
    Handle g(check(H5Gopen2(root, "contacts", H5P_DEFAULT), path, "open group /contacts"));
    m.c_point = make_column(g, "/contacts", "point", H5T_IEEE_F32LE, H5T_NATIVE_FLOAT, {3}, kChunk, 0, path);
    if (t.jt3)
      m.c_jt3 = make_column(g, "/contacts", "jt3", H5T_IEEE_F32LE, H5T_NATIVE_FLOAT, {3}, kChunk, 0, path);
    if (t.point_b)
      m.c_point_b = make_column(g, "/contacts", "point_b", H5T_IEEE_F32LE, H5T_NATIVE_FLOAT, {3}, kChunk, 0, path);
  }
  if (t.candidate_pairs) {
    Handle g(check(H5Gcreate2(root, "pairs", H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT), path, "create group /pairs"));
    m.p_offsets = make_column(g, "/pairs", "offsets", H5T_STD_I64LE, H5T_NATIVE_INT64, {}, 1024, 0, path);
    m.p_pair = make_column(g, "/pairs", "pair", H5T_STD_U32LE, H5T_NATIVE_UINT32, {2}, kChunk, 0, path);
    m.p_offsets.push1<std::int64_t>(0);
    m.p_offsets.write(path);
  }
  {
    Handle g(check(H5Gcreate2(root, "aabbs", H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT), path, "create group /aabbs"));
    m.a_min = make_column(g, "/aabbs", "min", H5T_IEEE_F32LE, H5T_NATIVE_FLOAT, {n, 3}, 1, 2, path);
    m.a_max = make_column(g, "/aabbs", "max", H5T_IEEE_F32LE, H5T_NATIVE_FLOAT, {n, 3}, 1, 2, path);
  }
}

void TraceWriter::append_frame_v2(const FrameMetrics& fm, const BodyState& state, const FrameRecord& rec) {
  Impl& m = *impl_;
  if (m.closed) throw RuntimeError("trace '" + m.path + "': append_frame_v2 after close");
  if (!m.opt.v2) throw RuntimeError("trace '" + m.path + "': append_frame_v2 on a version 1 trace");
  if (m.opt.contacts) {
    if (rec.aabbs.size() != m.bodies)
      throw RuntimeError("trace '" + m.path + "': frame " + std::to_string(fm.frame) + " has " +
                         std::to_string(rec.aabbs.size()) + " AABBs, the trace has " + std::to_string(m.bodies) +
                         " bodies");
    for (const Aabb& b : rec.aabbs) {
      m.a_min.push(&b.min.x, 3);
      m.a_max.push(&b.max.x, 3);
    }
    if (m.opt.v2->candidate_pairs) {
      for (const Pair& p : rec.pairs) {
        m.p_pair.push1(p.a);
        m.p_pair.push1(p.b);
      }
      m.pair_total += static_cast<std::int64_t>(rec.pairs.size());
      m.p_offsets.push1(m.pair_total);
    }
    for (const ContactRecord& c : rec.contacts) m.c_point.push(&c.point.x, 3);
    // A vector per contact row (jt3, point_b): one for each row, else the frame is refused.
    const auto per_row = [&](const std::vector<Vec3>& vectors, const char* what, auto& column) {
      if (vectors.size() != rec.contacts.size())
        throw RuntimeError("trace '" + m.path + "': frame " + std::to_string(fm.frame) + " has " +
                           std::to_string(vectors.size()) + " " + what + " for " +
                           std::to_string(rec.contacts.size()) + " contacts");
      for (const Vec3& v : vectors) column.push(&v.x, 3);
    };
    if (m.opt.v2->jt3) per_row(rec.jt3, "tangential impulse vectors", m.c_jt3);
    if (m.opt.v2->point_b) per_row(rec.point_b, "points on B", m.c_point_b);
  }
  append_frame(fm, state, rec.contacts);
}

TraceWriter::~TraceWriter() {
  try {
    close();
  } catch (...) {
    // Destructors must not throw; call close() to see errors.
  }
}

void TraceWriter::append_frame(const FrameMetrics& fm, const BodyState& state,
                               const std::vector<ContactRecord>& contacts) {
  append_frame(fm, &state, contacts);
}

bool TraceWriter::state_due(std::int64_t frame) const { return frame % impl_->opt.state_every == 0; }

std::int64_t TraceWriter::steps_to_next_state(std::int64_t frame) const {
  const std::int64_t every = impl_->opt.state_every;
  return every - ((frame % every) + every) % every;
}

void TraceWriter::append_frame(const FrameMetrics& fm, const BodyState* state,
                               const std::vector<ContactRecord>& contacts) {
  Impl& m = *impl_;
  if (m.closed) throw RuntimeError("trace '" + m.path + "': append_frame after close");
  const bool due = state_due(fm.frame);
  if (due && state == nullptr)
    throw RuntimeError("trace '" + m.path + "': frame " + std::to_string(fm.frame) +
                       " writes a state (state_every " + std::to_string(m.opt.state_every) + ") but none was given");
  m.last_appended = fm.frame;
  // No HDF5 call here but a flush's: with a thread-safe HDF5 every call takes its global
  // lock, which the writer thread holds through each dataset's write and deflate.
  if (due) m.push_state(fm.frame, *state);

  std::size_t i = 0;
  m.frames[i++].push1(fm.frame);
  m.frames[i++].push1(fm.time);
  m.frames[i++].push1(fm.step_ms);
  for (int s = 0; s < kStageCount; ++s) m.frames[i++].push1(fm.stage_ms[s]);
  for (std::uint64_t v : {fm.cell_candidates, fm.aabb_pairs, fm.dynamic_pairs, fm.box_tests, fm.box_pairs,
                          fm.vertex_tests, fm.contacts})
    m.frames[i++].push1(v);
  for (double v : {fm.penetration_mean, fm.penetration_max, fm.penetration_share_above_slop,
                   fm.kinetic_energy})
    m.frames[i++].push1(v);
  m.frames[i++].push(fm.momentum.data(), 3);
  m.frames[i++].push1(fm.memory_bytes);

  if (m.opt.contacts) {
    for (const ContactRecord& c : contacts) {
      m.c_pair.push1(c.pair.a);
      m.c_pair.push1(c.pair.b);
      m.c_normal.push1(c.normal.x);
      m.c_normal.push1(c.normal.y);
      m.c_normal.push1(c.normal.z);
      m.c_depth.push1(c.depth);
      m.c_jn.push1(c.jn);
      m.c_jt.push1(c.jt);
    }
    m.contact_total += static_cast<std::int64_t>(contacts.size());
    m.c_frame.push1(fm.frame);
    m.c_offsets.push1(m.contact_total);
  }

  std::size_t buffered = 0;
  for (Column* c : m.columns()) buffered += c->buf.size();
  // With an interval, a flush_every flush also waits for the writer thread to be idle
  // (the frames stay buffered; flush_bytes bounds them): the caller never waits for it.
  const bool frames_due =
      ++m.since_flush >= m.opt.flush_every &&
      (m.opt.flush_interval_s <= 0.0 ||
       ((buffered >= kFlushIntervalBytes ||
         std::chrono::duration<double>(std::chrono::steady_clock::now() - m.last_flush_start).count() >=
             m.opt.flush_interval_s) &&
        !m.writer_busy()));
  if (frames_due || buffered >= m.opt.flush_bytes) {
    m.flush_behind("writing frame " + std::to_string(fm.frame));
  }
}

void TraceWriter::append_state(std::int64_t frame, const BodyState& state) {
  Impl& m = *impl_;
  if (m.closed) throw RuntimeError("trace '" + m.path + "': append_state after close");
  m.push_state(frame, state);
}

void TraceWriter::flush() {
  Impl& m = *impl_;
  if (m.closed) return;
  QuietHdf5 quiet;
  m.write_and_flush("flushing after frame " + std::to_string(m.last_appended));
}

void TraceWriter::wait_for_flush() {
  Impl& m = *impl_;
  if (m.closed) return;
  m.wait_writer();
}

void TraceWriter::close() {
  Impl& m = *impl_;
  if (m.closed) return;
  QuietHdf5 quiet;
  // Everything reaches the disk first: once the flush succeeded, closing the datasets and
  // the file writes nothing but the superblock's SWMR flags, in place.
  m.write_and_flush("writing the last frames (up to frame " + std::to_string(m.last_appended) + ")");
  const std::lock_guard<std::mutex> lock(m.io);
  m.closed = true;
  for (Column* c : m.columns()) c->dset.reset();
  const herr_t r = H5Fclose(m.file.get());
  // Never closed twice: after a failed H5Fclose the identifier may point to freed memory.
  m.file.release();
  if (r < 0) {
    m.failed = true;
    std::string message = hdf5_message();
    const std::string reason = os_reason(message);
    if (!reason.empty()) message = reason;
    std::replace(message.begin(), message.end(), '\n', ' ');
    throw RuntimeError(m.failure("closing the file", message));
  }
}

const std::string& TraceWriter::path() const { return impl_->path; }

bool TraceWriter::failed() const { return impl_->failed; }

std::int64_t TraceWriter::flushed_frames() const { return impl_->flushed_rows; }

std::int64_t TraceWriter::read_back_frames_and_hold() {
  Impl& m = *impl_;
  m.io.lock();  // never unlocked: no write starts after the read (the process is ending)
  hbool_t threadsafe = 0;
  if (m.closed || m.failed || H5is_library_threadsafe(&threadsafe) < 0 || !threadsafe) return -1;
  QuietHdf5 quiet;
  std::int64_t frames = -1;
  const hid_t a = H5Aopen(m.file.get(), "committed_frames", H5P_DEFAULT);
  if (a < 0) return -1;
  if (H5Aread(a, H5T_NATIVE_INT64, &frames) < 0) frames = -1;
  H5Aclose(a);
  return frames;
}

}  // namespace octocd
