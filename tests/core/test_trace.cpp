// Tests of the HDF5 trace writer (design.md section 8, docs/trace-format.md). Traces are
// written from hand-made tables and read back with the HDF5 C API.



#include <gtest/gtest.h>
#include <hdf5.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <limits>
#include <string>
#include <vector>

#include "octocd/error.hpp"
#include "octocd/trace.hpp"
#include "support/temp_files.hpp"

// This file's own names (its tests compile in unity batches with the folder's other files).
namespace octocd_test_trace {

namespace fs = std::filesystem;
using namespace octocd;

namespace {

constexpr int kStages = static_cast<int>(Stage::Count);

fs::path temp_root() {
  static const fs::path d =
      fs::temp_directory_path() / ("octocd_test_trace_" + std::to_string(::getpid()));
  return d;
}

fs::path temp_dir() {
  fs::create_directories(temp_root());
  return temp_root();
}

const auto* const kCleanup = octocd::test::remove_at_exit(temp_root);  // unless OCTOCD_KEEP_TEST_FILES

TraceMetadata make_meta() {
  TraceMetadata m;
  m.scene_name = "unit";
  m.scene_json = R"({"name": "unit", "frames": 10})";
  m.parameters_json = R"({"dt": 0.001})";
  m.engine = "cpu";
  m.broadphase = "octree";
  m.midphase = "1,2";
  m.build_id = "test-build";
  m.device = "test device";
  m.start_time = "2025-01-01T00:00:00Z";
  m.dt = 0.001;
  m.state_every = 5;
  return m;
}

TraceBodies make_bodies(std::size_t n) {
  TraceBodies b;
  for (std::size_t i = 0; i < n; ++i) {
    const auto f = static_cast<float>(i);
    b.shape_id.push_back(static_cast<std::uint32_t>(i % 2));
    b.inverse_mass.push_back(i == 0 ? 0.0f : 1.0f / (f + 1.0f));
    b.local_aabb.push_back({{-f, -0.5f, -0.25f}, {f, 0.5f, 0.25f + f}});
    b.group.push_back(i == 0 ? "walls" : "group-" + std::to_string(i));
  }
  b.shape_names = {"box", "bunny@0.2"};
  return b;
}

// Deterministic metrics of frame f: every column gets a distinct value.
FrameMetrics make_metrics(std::int64_t f) {
  FrameMetrics m;
  const auto d = static_cast<double>(f);
  m.frame = f;
  m.time = 0.001 * d;
  m.step_ms = 1.5 + d;
  for (int s = 0; s < kStages; ++s) m.stage_ms[s] = 0.1 * s + d;
  m.cell_candidates = static_cast<std::uint64_t>(100 + f);
  m.aabb_pairs = static_cast<std::uint64_t>(200 + f);
  m.box_tests = static_cast<std::uint64_t>(300 + f);
  m.box_pairs = static_cast<std::uint64_t>(400 + f);
  m.vertex_tests = static_cast<std::uint64_t>(500 + f);
  m.contacts = static_cast<std::uint64_t>(f % 4);
  m.penetration_mean = 1e-4 * d;
  m.penetration_max = 2e-4 * d;
  m.penetration_share_above_slop = 0.01 * d;
  m.kinetic_energy = 10.0 + d;
  m.momentum = {d, -d, 0.5 * d};
  m.memory_bytes = static_cast<std::uint64_t>(1000000 + f);
  return m;
}

BodyState make_state(std::int64_t f, std::size_t n) {
  BodyState s;
  for (std::size_t i = 0; i < n; ++i) {
    const float a = static_cast<float>(f) + 0.01f * static_cast<float>(i);
    s.x.push_back({a, 2.0f * a, -a});
    s.v.push_back({-a, 0.5f, 3.0f * a});
    s.w.push_back(1.0f);
  }
  return s;
}

// f % 4 contacts in frame f.
std::vector<ContactRecord> make_contacts(std::int64_t f) {
  std::vector<ContactRecord> c;
  for (std::int64_t k = 0; k < f % 4; ++k) {
    ContactRecord r;
    r.pair = {static_cast<std::uint32_t>(k), static_cast<std::uint32_t>(k + 1)};
    r.normal = {0.0f, 1.0f, static_cast<float>(f)};
    r.depth = 0.001f * static_cast<float>(f);
    r.jn = static_cast<float>(f + k);
    r.jt = -static_cast<float>(k);
    c.push_back(r);
  }
  return c;
}

// ---- small HDF5 readers ---------------------------------------------------------------

struct H5File {
  hid_t id;
  explicit H5File(const std::string& p)
      : id(H5Fopen(p.c_str(), H5F_ACC_RDONLY | H5F_ACC_SWMR_READ, H5P_DEFAULT)) {}
  ~H5File() {
    if (id >= 0) H5Fclose(id);
  }
};

std::vector<hsize_t> dims_of(hid_t file, const char* name) {
  const hid_t d = H5Dopen2(file, name, H5P_DEFAULT);
  EXPECT_GE(d, 0) << name;
  if (d < 0) return {};
  const hid_t sp = H5Dget_space(d);
  std::vector<hsize_t> dims(static_cast<std::size_t>(H5Sget_simple_extent_ndims(sp)));
  H5Sget_simple_extent_dims(sp, dims.data(), nullptr);
  H5Sclose(sp);
  H5Dclose(d);
  return dims;
}

template <class T>
std::vector<T> read_all(hid_t file, const char* name, hid_t mem_type) {
  std::vector<hsize_t> dims = dims_of(file, name);
  std::size_t n = 1;
  for (hsize_t x : dims) n *= static_cast<std::size_t>(x);
  std::vector<T> out(n);
  const hid_t d = H5Dopen2(file, name, H5P_DEFAULT);
  if (d < 0) return {};
  if (n > 0) {
    EXPECT_GE(H5Dread(d, mem_type, H5S_ALL, H5S_ALL, H5P_DEFAULT, out.data()), 0) << name;
  }
  H5Dclose(d);
  return out;
}

std::vector<std::string> read_strings(hid_t obj, const char* name, bool attribute) {
  const hid_t t = H5Tcopy(H5T_C_S1);
  H5Tset_size(t, H5T_VARIABLE);
  H5Tset_cset(t, H5T_CSET_UTF8);
  const hid_t h = attribute ? H5Aopen(obj, name, H5P_DEFAULT) : H5Dopen2(obj, name, H5P_DEFAULT);
  EXPECT_GE(h, 0) << name;
  std::vector<std::string> out;
  if (h >= 0) {
    const hid_t sp = attribute ? H5Aget_space(h) : H5Dget_space(h);
    const hssize_t n = H5Sget_simple_extent_npoints(sp);
    std::vector<char*> p(static_cast<std::size_t>(n), nullptr);
    if (n > 0) {
      const herr_t r = attribute ? H5Aread(h, t, p.data())
                                 : H5Dread(h, t, H5S_ALL, H5S_ALL, H5P_DEFAULT, p.data());
      EXPECT_GE(r, 0) << name;
    }
    for (char* s : p) {
      out.emplace_back(s ? s : "");
      if (s) H5free_memory(s);
    }
    H5Sclose(sp);
    attribute ? H5Aclose(h) : H5Dclose(h);
  }
  H5Tclose(t);
  return out;
}

std::string attr_string(hid_t obj, const char* name) {
  auto v = read_strings(obj, name, true);
  return v.size() == 1 ? v[0] : "<missing>";
}

template <class T>
T attr_scalar(hid_t obj, const char* name, hid_t mem_type) {
  T v{};
  const hid_t a = H5Aopen(obj, name, H5P_DEFAULT);
  EXPECT_GE(a, 0) << name;
  if (a >= 0) {
    EXPECT_GE(H5Aread(a, mem_type, &v), 0);
    H5Aclose(a);
  }
  return v;
}

// Writes `frames` frames (plus the initial state) to `path`.
void write_trace(const std::string& path, std::size_t bodies, std::int64_t frames,
                 const TraceOptions& opt) {
  TraceWriter w(path, make_meta(), make_bodies(bodies), opt);
  w.append_state(0, make_state(0, bodies));
  for (std::int64_t f = 1; f <= frames; ++f)
    w.append_frame(make_metrics(f), make_state(f, bodies), make_contacts(f));
  w.close();
}

}  // namespace

TEST(Trace, RootAttributesAndBodies) {
  const std::string path = (temp_dir() / "attrs.h5").string();
  TraceOptions opt;
  opt.state_every = 5;
  write_trace(path, 3, 4, opt);

  H5File f(path);
  ASSERT_GE(f.id, 0);
  EXPECT_EQ(attr_string(f.id, "format"), "octocd-trace");
  EXPECT_EQ(attr_scalar<int>(f.id, "version", H5T_NATIVE_INT), 1);
  EXPECT_EQ(attr_string(f.id, "scene_name"), "unit");
  EXPECT_EQ(attr_string(f.id, "scene"), R"({"name": "unit", "frames": 10})");
  EXPECT_EQ(attr_string(f.id, "parameters"), R"({"dt": 0.001})");
  EXPECT_EQ(attr_string(f.id, "engine"), "cpu");
  EXPECT_EQ(attr_string(f.id, "broadphase"), "octree");
  EXPECT_EQ(attr_string(f.id, "midphase"), "1,2");
  EXPECT_EQ(attr_string(f.id, "build_id"), "test-build");
  EXPECT_EQ(attr_string(f.id, "device"), "test device");
  EXPECT_EQ(attr_string(f.id, "start_time"), "2025-01-01T00:00:00Z");
  EXPECT_EQ(attr_scalar<double>(f.id, "dt", H5T_NATIVE_DOUBLE), 0.001);
  EXPECT_EQ(attr_scalar<int>(f.id, "state_every", H5T_NATIVE_INT), 5);
  const std::vector<std::string> stages = read_strings(f.id, "stage_names", true);
  ASSERT_EQ(stages.size(), static_cast<std::size_t>(kStages));
  for (int s = 0; s < kStages; ++s) EXPECT_EQ(stages[s], stage_name(static_cast<Stage>(s)));
  EXPECT_EQ(stages[0], "integrate");
  EXPECT_EQ(stages[5], "metrics");

  const TraceBodies b = make_bodies(3);
  EXPECT_EQ(read_all<std::uint32_t>(f.id, "/bodies/shape_id", H5T_NATIVE_UINT32), b.shape_id);
  EXPECT_EQ(read_all<float>(f.id, "/bodies/inverse_mass", H5T_NATIVE_FLOAT), b.inverse_mass);
  EXPECT_EQ(dims_of(f.id, "/bodies/local_aabb_min"), (std::vector<hsize_t>{3, 3}));
  const auto lo = read_all<float>(f.id, "/bodies/local_aabb_min", H5T_NATIVE_FLOAT);
  const auto hi = read_all<float>(f.id, "/bodies/local_aabb_max", H5T_NATIVE_FLOAT);
  ASSERT_EQ(lo.size(), 9u);
  ASSERT_EQ(hi.size(), 9u);
  for (std::size_t i = 0; i < 3; ++i)
    for (int k = 0; k < 3; ++k) {
      EXPECT_EQ(lo[3 * i + k], b.local_aabb[i].min[k]);
      EXPECT_EQ(hi[3 * i + k], b.local_aabb[i].max[k]);
    }
  EXPECT_EQ(read_strings(f.id, "/bodies/group", false), b.group);
  EXPECT_EQ(read_strings(f.id, "/bodies/shape_names", false), b.shape_names);
  // Contacts were not requested: no /contacts group.
  EXPECT_LE(H5Lexists(f.id, "contacts", H5P_DEFAULT), 0);
}

TEST(Trace, FramesStatesAndContactsReadBack) {
  const std::string path = (temp_dir() / "full.h5").string();
  const std::size_t nb = 4;
  const std::int64_t n = 37;
  TraceOptions opt;
  opt.state_every = 5;
  opt.flush_every = 7;
  opt.contacts = true;
  write_trace(path, nb, n, opt);

  H5File f(path);
  ASSERT_GE(f.id, 0);
  const auto N = static_cast<std::size_t>(n);

  // /frames: every column, every row.
  const std::vector<hsize_t> one{static_cast<hsize_t>(n)};
  EXPECT_EQ(dims_of(f.id, "/frames/frame"), one);
  EXPECT_EQ(dims_of(f.id, "/frames/momentum"), (std::vector<hsize_t>{one[0], 3}));
  const auto frame = read_all<std::int64_t>(f.id, "/frames/frame", H5T_NATIVE_INT64);
  auto dcol = [&](const std::string& c) {
    EXPECT_EQ(dims_of(f.id, ("/frames/" + c).c_str()), one) << c;
    return read_all<double>(f.id, ("/frames/" + c).c_str(), H5T_NATIVE_DOUBLE);
  };
  auto ucol = [&](const std::string& c) {
    EXPECT_EQ(dims_of(f.id, ("/frames/" + c).c_str()), one) << c;
    return read_all<std::uint64_t>(f.id, ("/frames/" + c).c_str(), H5T_NATIVE_UINT64);
  };
  const auto time = dcol("time"), step = dcol("step_ms");
  std::vector<std::vector<double>> stage;
  for (int s = 0; s < kStages; ++s) stage.push_back(dcol(std::string(stage_name(static_cast<Stage>(s))) + "_ms"));
  const auto cc = ucol("cell_candidates"), ap = ucol("aabb_pairs"), bt = ucol("box_tests"),
             bp = ucol("box_pairs"), vt = ucol("vertex_tests"), ct = ucol("contacts"),
             mem = ucol("memory_bytes");
  const auto pm = dcol("penetration_mean"), px = dcol("penetration_max"),
             ps = dcol("penetration_share_above_slop"), ke = dcol("kinetic_energy");
  const auto mom = read_all<double>(f.id, "/frames/momentum", H5T_NATIVE_DOUBLE);
  ASSERT_EQ(frame.size(), N);
  ASSERT_EQ(mom.size(), 3 * N);
  for (std::size_t r = 0; r < N; ++r) {
    const FrameMetrics e = make_metrics(static_cast<std::int64_t>(r) + 1);
    EXPECT_EQ(frame[r], e.frame);
    EXPECT_EQ(time[r], e.time);
    EXPECT_EQ(step[r], e.step_ms);
    for (int s = 0; s < kStages; ++s) EXPECT_EQ(stage[s][r], e.stage_ms[s]);
    EXPECT_EQ(cc[r], e.cell_candidates);
    EXPECT_EQ(ap[r], e.aabb_pairs);
    EXPECT_EQ(bt[r], e.box_tests);
    EXPECT_EQ(bp[r], e.box_pairs);
    EXPECT_EQ(vt[r], e.vertex_tests);
    EXPECT_EQ(ct[r], e.contacts);
    EXPECT_EQ(pm[r], e.penetration_mean);
    EXPECT_EQ(px[r], e.penetration_max);
    EXPECT_EQ(ps[r], e.penetration_share_above_slop);
    EXPECT_EQ(ke[r], e.kinetic_energy);
    for (int k = 0; k < 3; ++k) EXPECT_EQ(mom[3 * r + k], e.momentum[k]);
    EXPECT_EQ(mem[r], e.memory_bytes);
  }

  // /states: frames 0, 5, ..., 35 (frame 0 from append_state).
  const auto sf = read_all<std::int64_t>(f.id, "/states/frame", H5T_NATIVE_INT64);
  std::vector<std::int64_t> expect_sf;
  for (std::int64_t k = 0; k <= n; k += 5) expect_sf.push_back(k);
  EXPECT_EQ(sf, expect_sf);
  const std::vector<hsize_t> sd{expect_sf.size(), nb, 3};
  EXPECT_EQ(dims_of(f.id, "/states/position"), sd);
  EXPECT_EQ(dims_of(f.id, "/states/velocity"), sd);
  const auto pos = read_all<float>(f.id, "/states/position", H5T_NATIVE_FLOAT);
  const auto vel = read_all<float>(f.id, "/states/velocity", H5T_NATIVE_FLOAT);
  ASSERT_EQ(pos.size(), expect_sf.size() * nb * 3);
  ASSERT_EQ(vel.size(), pos.size());
  for (std::size_t r = 0; r < expect_sf.size(); ++r) {
    const BodyState s = make_state(expect_sf[r], nb);
    for (std::size_t i = 0; i < nb; ++i)
      for (int k = 0; k < 3; ++k) {
        EXPECT_EQ(pos[(r * nb + i) * 3 + k], s.x[i][k]) << "row " << r << " body " << i;
        EXPECT_EQ(vel[(r * nb + i) * 3 + k], s.v[i][k]) << "row " << r << " body " << i;
      }
  }
  // Chunked one state per chunk, compressed.
  {
    const hid_t d = H5Dopen2(f.id, "/states/position", H5P_DEFAULT);
    const hid_t dcpl = H5Dget_create_plist(d);
    EXPECT_EQ(H5Pget_layout(dcpl), H5D_CHUNKED);
    hsize_t chunk[3] = {0, 0, 0};
    EXPECT_EQ(H5Pget_chunk(dcpl, 3, chunk), 3);
    EXPECT_EQ(chunk[0], 1u);
    EXPECT_EQ(chunk[1], nb);
    EXPECT_EQ(chunk[2], 3u);
    unsigned flags = 0;
    unsigned cd[8] = {};
    size_t nelmts = 8;
    const bool deflate = H5Pget_filter_by_id2(dcpl, H5Z_FILTER_DEFLATE, &flags, &nelmts, cd, 0,
                                              nullptr, nullptr) >= 0;
    EXPECT_TRUE(deflate);
    H5Pclose(dcpl);
    H5Dclose(d);
  }

  // /contacts: CSR offsets over flat arrays.
  const auto off = read_all<std::int64_t>(f.id, "/contacts/offsets", H5T_NATIVE_INT64);
  const auto cf = read_all<std::int64_t>(f.id, "/contacts/frame", H5T_NATIVE_INT64);
  const auto pair = read_all<std::uint32_t>(f.id, "/contacts/pair", H5T_NATIVE_UINT32);
  const auto normal = read_all<float>(f.id, "/contacts/normal", H5T_NATIVE_FLOAT);
  const auto depth = read_all<float>(f.id, "/contacts/depth", H5T_NATIVE_FLOAT);
  const auto jn = read_all<float>(f.id, "/contacts/jn", H5T_NATIVE_FLOAT);
  const auto jt = read_all<float>(f.id, "/contacts/jt", H5T_NATIVE_FLOAT);
  ASSERT_EQ(off.size(), N + 1);
  ASSERT_EQ(cf.size(), N);
  EXPECT_EQ(off[0], 0);
  std::int64_t total = 0;
  for (std::size_t r = 0; r < N; ++r) {
    const std::int64_t fr = static_cast<std::int64_t>(r) + 1;
    EXPECT_EQ(cf[r], fr);
    const auto expect = make_contacts(fr);
    EXPECT_EQ(off[r + 1] - off[r], static_cast<std::int64_t>(expect.size())) << "frame " << fr;
    for (std::size_t k = 0; k < expect.size(); ++k) {
      const auto j = static_cast<std::size_t>(off[r]) + k;
      ASSERT_LT(j, depth.size());
      EXPECT_EQ(pair[2 * j], expect[k].pair.a);
      EXPECT_EQ(pair[2 * j + 1], expect[k].pair.b);
      for (int c = 0; c < 3; ++c) EXPECT_EQ(normal[3 * j + c], expect[k].normal[c]);
      EXPECT_EQ(depth[j], expect[k].depth);
      EXPECT_EQ(jn[j], expect[k].jn);
      EXPECT_EQ(jt[j], expect[k].jt);
    }
    total += static_cast<std::int64_t>(expect.size());
  }
  EXPECT_EQ(off[N], total);
  EXPECT_EQ(depth.size(), static_cast<std::size_t>(total));
  EXPECT_EQ(dims_of(f.id, "/contacts/pair"), (std::vector<hsize_t>{static_cast<hsize_t>(total), 2}));
  EXPECT_EQ(dims_of(f.id, "/contacts/normal"), (std::vector<hsize_t>{static_cast<hsize_t>(total), 3}));

  const TraceSummary s = read_trace_summary(path);
  EXPECT_EQ(s.format, "octocd-trace");
  EXPECT_EQ(s.version, 1);
  EXPECT_EQ(s.frames, n);
  EXPECT_EQ(s.state_rows, static_cast<std::int64_t>(expect_sf.size()));
  EXPECT_EQ(s.bodies, static_cast<std::int64_t>(nb));
  EXPECT_EQ(s.last_frame, n);
}

TEST(Trace, FlushMakesRowsVisibleBeforeClose) {
  const std::string path = (temp_dir() / "flush.h5").string();
  TraceOptions opt;
  opt.state_every = 2;
  opt.flush_every = 1000;
  TraceWriter w(path, make_meta(), make_bodies(2), opt);
  w.append_state(0, make_state(0, 2));
  for (std::int64_t fr = 1; fr <= 6; ++fr) w.append_frame(make_metrics(fr), make_state(fr, 2), {});
  EXPECT_EQ(read_trace_summary(path).frames, 0);  // buffered, not yet flushed
  w.flush();
  TraceSummary s = read_trace_summary(path);
  EXPECT_EQ(s.frames, 6);
  EXPECT_EQ(s.state_rows, 4);  // 0, 2, 4, 6
  EXPECT_EQ(s.last_frame, 6);
  w.close();
  w.close();  // idempotent
  EXPECT_EQ(read_trace_summary(path).frames, 6);
}

// A caller may give the state only on the frames whose state is written (a device engine
// then copies nothing back between them): with state_every 3 over frames 1..7 the states
// of 0, 3 and 6 are on disk, equal to what was given; a missing state on a due frame
// throws naming the frame; steps_to_next_state counts to the next due frame.
TEST(Trace, StateGivenOnlyOnTheFramesWhoseStateIsWritten) {
  const std::string path = (temp_dir() / "due.h5").string();
  TraceOptions opt;
  opt.state_every = 3;
  {
    TraceWriter w(path, make_meta(), make_bodies(2), opt);
    EXPECT_EQ(w.steps_to_next_state(0), 3);
    EXPECT_EQ(w.steps_to_next_state(1), 2);
    EXPECT_EQ(w.steps_to_next_state(2), 1);
    EXPECT_EQ(w.steps_to_next_state(3), 3);
    w.append_state(0, make_state(0, 2));
    for (std::int64_t fr = 1; fr <= 7; ++fr) {
      EXPECT_EQ(w.state_due(fr), fr % 3 == 0) << fr;
      const BodyState s = make_state(fr, 2);
      w.append_frame(make_metrics(fr), w.state_due(fr) ? &s : nullptr, {});
    }
    try {
      w.append_frame(make_metrics(9), static_cast<const BodyState*>(nullptr), {});
      ADD_FAILURE() << "a due frame without a state was accepted";
    } catch (const RuntimeError& e) {
      EXPECT_NE(std::string(e.what()).find("frame 9"), std::string::npos) << e.what();
    }
  }
  H5File f(path);
  ASSERT_GE(f.id, 0);
  EXPECT_EQ(read_all<std::int64_t>(f.id, "/states/frame", H5T_NATIVE_INT64), (std::vector<std::int64_t>{0, 3, 6}));
  const auto pos = read_all<float>(f.id, "/states/position", H5T_NATIVE_FLOAT);
  ASSERT_EQ(pos.size(), 3u * 2u * 3u);
  for (std::size_t r = 0; r < 3; ++r) {
    const BodyState s = make_state(static_cast<std::int64_t>(3 * r), 2);
    for (std::size_t i = 0; i < 2; ++i) {
      EXPECT_EQ(pos[(r * 2 + i) * 3 + 0], s.x[i].x);
      EXPECT_EQ(pos[(r * 2 + i) * 3 + 1], s.x[i].y);
      EXPECT_EQ(pos[(r * 2 + i) * 3 + 2], s.x[i].z);
    }
  }
  EXPECT_EQ(read_all<std::int64_t>(f.id, "/frames/frame", H5T_NATIVE_INT64).size(), 7u);
}

TEST(Trace, WrongStateSizeThrows) {
  const std::string path = (temp_dir() / "size.h5").string();
  TraceWriter w(path, make_meta(), make_bodies(3), TraceOptions{});
  EXPECT_THROW(w.append_state(0, make_state(0, 2)), RuntimeError);
}

TEST(Trace, SigkillLeavesReadableFileWithFlushedFrames) {
  const std::string path = (temp_dir() / "killed.h5").string();
  fs::remove(path);
  const std::size_t nb = 16;
  int ready[2];
  ASSERT_EQ(::pipe(ready), 0);
  const pid_t child = ::fork();
  ASSERT_GE(child, 0);
  if (child == 0) {
    // Child: 35 frames, flushed every 10 (frames 31..35 appended, not flushed); once the
    // writer thread has the flush of frame 30 on disk it says so on the pipe and waits to
    // be killed with the writer open.
    ::close(ready[0]);
    try {
      TraceOptions opt;
      opt.state_every = 5;
      opt.flush_every = 10;
      opt.contacts = true;
      TraceWriter w(path, make_meta(), make_bodies(nb), opt);
      w.append_state(0, make_state(0, nb));
      for (std::int64_t fr = 1; fr <= 35; ++fr) w.append_frame(make_metrics(fr), make_state(fr, nb), make_contacts(fr));
      w.wait_for_flush();
      const char done = 'w';
      if (::write(ready[1], &done, 1) == 1)
        for (;;) ::pause();
    } catch (...) {
    }
    ::_exit(3);
  }

  // Parent: wait for the child's word (the pipe reads end of file if it exits instead),
  // then kill the writer.
  ::close(ready[1]);
  char word = 0;
  const bool wrote = ::read(ready[0], &word, 1) == 1;
  ::close(ready[0]);
  ::kill(child, SIGKILL);
  int status = 0;
  ::waitpid(child, &status, 0);
  ASSERT_TRUE(wrote) << "the writer ended before its 35 frames";
  EXPECT_TRUE(WIFSIGNALED(status));

  TraceSummary s = read_trace_summary(path);
  EXPECT_EQ(s.format, "octocd-trace");
  EXPECT_EQ(s.frames, 30) << "only whole flushes reach the file: frames 31..35 were never flushed";
  EXPECT_EQ(s.last_frame, s.frames);
  EXPECT_EQ(s.bodies, static_cast<std::int64_t>(nb));
  EXPECT_GE(s.state_rows, s.frames / 5 + 1 - 2);

  // The last complete row is consistent, in /frames and in /states.
  H5File f(path);
  ASSERT_GE(f.id, 0);
  const auto r = static_cast<std::size_t>(s.frames - 1);
  const auto frame = read_all<std::int64_t>(f.id, "/frames/frame", H5T_NATIVE_INT64);
  const auto time = read_all<double>(f.id, "/frames/time", H5T_NATIVE_DOUBLE);
  const auto ke = read_all<double>(f.id, "/frames/kinetic_energy", H5T_NATIVE_DOUBLE);
  ASSERT_GT(frame.size(), r);
  ASSERT_GT(time.size(), r);
  ASSERT_GT(ke.size(), r);
  const FrameMetrics e = make_metrics(s.last_frame);
  EXPECT_EQ(frame[r], e.frame);
  EXPECT_EQ(time[r], e.time);
  EXPECT_EQ(ke[r], e.kinetic_energy);
  const auto sf = read_all<std::int64_t>(f.id, "/states/frame", H5T_NATIVE_INT64);
  const auto pos = read_all<float>(f.id, "/states/position", H5T_NATIVE_FLOAT);
  ASSERT_GE(sf.size(), static_cast<std::size_t>(s.state_rows));
  ASSERT_GE(pos.size(), static_cast<std::size_t>(s.state_rows) * nb * 3);
  const auto last = static_cast<std::size_t>(s.state_rows - 1);
  EXPECT_EQ(sf[last], 5 * static_cast<std::int64_t>(last));
  const BodyState st = make_state(sf[last], nb);
  EXPECT_EQ(pos[(last * nb + nb - 1) * 3 + 2], st.x[nb - 1].z);
}

TEST(Trace, PathInMissingDirectoryThrowsNamingIt) {
  const std::string path = (temp_dir() / "no-such-dir" / "t.h5").string();
  try {
    TraceWriter w(path, make_meta(), make_bodies(1), TraceOptions{});
    FAIL() << "expected RuntimeError";
  } catch (const RuntimeError& e) {
    EXPECT_NE(std::string(e.what()).find(path), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("no-such-dir"), std::string::npos) << e.what();
  }
}

TEST(Trace, ReadingNonTraceThrowsNamingThePath) {
  const fs::path dir = temp_dir();
  // A text file.
  const std::string text = (dir / "not-a-trace.txt").string();
  std::ofstream(text) << "hello\n";
  // An HDF5 file without the format attribute.
  const std::string plain = (dir / "plain.h5").string();
  {
    const hid_t f = H5Fcreate(plain.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT);
    ASSERT_GE(f, 0);
    H5Fclose(f);
  }
  const std::string missing = (dir / "missing.h5").string();
  for (const std::string& p : {text, plain, missing}) {
    try {
      read_trace_summary(p);
      ADD_FAILURE() << "expected RuntimeError for " << p;
    } catch (const RuntimeError& e) {
      EXPECT_NE(std::string(e.what()).find(p), std::string::npos) << e.what();
    }
  }
}

TEST(Trace, InvalidOptionsThrow) {
  const std::string path = (temp_dir() / "opts.h5").string();
  TraceOptions opt;
  opt.state_every = 0;
  EXPECT_THROW(TraceWriter(path, make_meta(), make_bodies(1), opt), RuntimeError);
  opt.state_every = 1;
  opt.flush_every = 0;
  EXPECT_THROW(TraceWriter(path, make_meta(), make_bodies(1), opt), RuntimeError);
  opt.flush_every = 1;
  for (double bad : {-1.0, std::nan(""), std::numeric_limits<double>::infinity()}) {
    opt.flush_interval_s = bad;
    try {
      TraceWriter w(path, make_meta(), make_bodies(1), opt);
      ADD_FAILURE() << "flush_interval_s " << bad << " accepted";
    } catch (const RuntimeError& e) {
      EXPECT_NE(std::string(e.what()).find("flush_interval_s"), std::string::npos) << e.what();
    }
  }
}

// TraceOptions::flush_interval_s: the flushes flush_every frames call for wait until that
// long after the previous one began (an hour: none within the test) while the buffered rows
// hold under kFlushIntervalBytes, while flush_bytes still flushes at once; an interval
// already passed (1 ns), or rows of kFlushIntervalBytes a frame, leave flush_every's flushes
// where they were (frames 5, 10, ..).
TEST(Trace, FlushIntervalDefersFrameFlushesButNotByteFlushes) {
  std::size_t nb = 4;
  const auto run = [&](double interval, std::size_t flush_bytes, int frames) {
    const std::string path = (temp_dir() / "interval.h5").string();
    TraceOptions opt;
    opt.state_every = 1;
    opt.flush_every = 5;
    opt.flush_interval_s = interval;
    opt.flush_bytes = flush_bytes;
    TraceWriter w(path, make_meta(), make_bodies(nb), opt);
    w.append_state(0, make_state(0, nb));
    std::vector<std::int64_t> flushed;
    for (std::int64_t f = 1; f <= frames; ++f) {
      w.append_frame(make_metrics(f), make_state(f, nb), {});
      w.wait_for_flush();
      flushed.push_back(w.flushed_frames());
    }
    w.close();
    EXPECT_EQ(read_trace_summary(path).frames, frames) << "close writes every frame";
    return flushed;
  };
  const std::size_t no_limit = std::size_t{1} << 30;
  const std::vector<std::int64_t> hour = run(3600.0, no_limit, 12);
  EXPECT_EQ(hour.back(), 0) << "a frame-count flush within the hour";
  const std::vector<std::int64_t> ns = run(1e-9, no_limit, 12);
  EXPECT_EQ(ns[3], 0);
  EXPECT_EQ(ns[4], 5);
  EXPECT_EQ(ns[9], 10);
  EXPECT_EQ(ns[11], 10);
  // A state row of 4 bodies is 96 bytes: a flush_bytes of 1 flushes every frame.
  const std::vector<std::int64_t> bytes = run(3600.0, 1, 12);
  for (std::size_t i = 0; i < bytes.size(); ++i) EXPECT_EQ(bytes[i], static_cast<std::int64_t>(i + 1)) << i;
  nb = kFlushIntervalBytes / 24 + 1;  // a state row (24 bytes a body) past kFlushIntervalBytes
  const std::vector<std::int64_t> big = run(3600.0, no_limit, 12);
  EXPECT_EQ(big[3], 0);
  EXPECT_EQ(big[4], 5);
  EXPECT_EQ(big[9], 10);
}

TEST(Trace, XdmfSidecarReferencesEveryStateRow) {
  const std::string path = (temp_dir() / "anim.h5").string();
  TraceOptions opt;
  opt.state_every = 4;
  write_trace(path, 3, 10, opt);  // states 0, 4, 8
  const std::string xmf = write_xdmf_sidecar(path);
  EXPECT_EQ(xmf, path + ".xmf");
  std::ifstream in(xmf);
  ASSERT_TRUE(in.good());
  const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  auto count = [&](const std::string& needle) {
    std::size_t c = 0;
    for (auto p = text.find(needle); p != std::string::npos; p = text.find(needle, p + 1)) ++c;
    return c;
  };
  EXPECT_EQ(count("<Grid Name=\"frame "), 3u);
  EXPECT_EQ(count("TopologyType=\"Polyvertex\" NumberOfElements=\"3\""), 3u);
  EXPECT_EQ(count("anim.h5:/states/position"), 3u);
  EXPECT_EQ(count("anim.h5:/states/velocity"), 3u);
  EXPECT_NE(text.find("<Time Value=\"0.008\"/>"), std::string::npos) << text;
  // Row 2 of the 3 x 3 x 3 position dataset, as an XDMF 3 HDF5 hyperslab.
  EXPECT_NE(text.find(">anim.h5:/states/position|2 0 0:1 1 1:1 3 3:3 3 3</DataItem>"), std::string::npos) << text;
  EXPECT_EQ(text.find("HyperSlab"), std::string::npos) << "ParaView's Xdmf3 readers leave a HyperSlab item untyped";
  EXPECT_EQ(count("</Xdmf>"), 1u);
  EXPECT_THROW(write_xdmf_sidecar((temp_dir() / "missing.h5").string()), RuntimeError);
}

}  // namespace octocd_test_trace
