// Issue 36, the second compression-bomb kind: a trace whose compressed chunks hold many
// rows, read row by row. Before: every small read inflated its whole chunk again (HDF5's
// default chunk cache is 1 MiB, and the reader reopened the dataset per read), while the
// read budget counted the bytes returned, not the bytes inflated. Now a chunked
// compressed dataset is opened once per reader with a cache of one band of rows, the
// budget counts the chunks inflated, and chunks above 256 MiB are refused. Also: a view
// page polls its stop callback (octocd.view's Ctrl-C). Every file is generated here, small.
#include <gtest/gtest.h>
#include <hdf5.h>
#include <unistd.h>

#include <atomic>
#include <cstring>
#include <filesystem>
#include <string>
#include <vector>

#include "octocd/error.hpp"
#include "octocd/trace_reader.hpp"
#include "octocd/validation.hpp"
#include "octocd/view.hpp"
#include "support/trace_edit.hpp"

// This file's own names (its tests compile in unity batches with the folder's other files).
namespace octocd_test_trace_chunks {

namespace fs = std::filesystem;

namespace {

// A pass-through filter that counts how often HDF5 runs it to read (inflate) a chunk:
// the count of chunk decodes is the property under test, not a time.
constexpr H5Z_filter_t kCountingFilter = 305;  // the range 256-511 is for testing
std::atomic<int> g_decodes{0};

size_t counting_filter(unsigned flags, size_t, const unsigned[], size_t nbytes, size_t*, void**) {
  if (flags & H5Z_FLAG_REVERSE) ++g_decodes;
  return nbytes;  // the data unchanged
}

void register_counting_filter() {
  static const H5Z_class2_t cls = {H5Z_CLASS_T_VERS, kCountingFilter, 1, 1, "octocd test counter", nullptr, nullptr,
                                   counting_filter};
  ASSERT_GE(H5Zregister(&cls), 0);
}

fs::path scratch(const std::string& name) {
  const fs::path d = fs::temp_directory_path() / ("octocd-chunks-" + std::to_string(::getpid()) + "-" + name);
  fs::remove_all(d);
  fs::create_directories(d);
  return d;
}

/// A version 1 trace header (format, version) and /states/position of `rows` x `n` x 3
/// float32 (row r: every value r), chunked `chunk` and filtered by `filter` (deflate or
/// the counting filter); `write` false leaves the chunks unallocated (no data).
void write_chunked_trace(const std::string& path, hsize_t rows, hsize_t n, std::vector<hsize_t> chunk,
                         H5Z_filter_t filter, bool write = true) {
  octocd::test::write_minimal_trace(path, {});
  const hid_t f = H5Fopen(path.c_str(), H5F_ACC_RDWR, H5P_DEFAULT);
  ASSERT_GE(f, 0);
  const hid_t lcpl = H5Pcreate(H5P_LINK_CREATE);
  H5Pset_create_intermediate_group(lcpl, 1);
  const hsize_t dims[3] = {rows, n, 3}, maxdims[3] = {H5S_UNLIMITED, H5S_UNLIMITED, 3};
  const hid_t space = H5Screate_simple(3, dims, maxdims);
  const hid_t dcpl = H5Pcreate(H5P_DATASET_CREATE);
  ASSERT_GE(H5Pset_chunk(dcpl, 3, chunk.data()), 0);
  if (filter == H5Z_FILTER_DEFLATE)
    ASSERT_GE(H5Pset_deflate(dcpl, 6), 0);
  else
    ASSERT_GE(H5Pset_filter(dcpl, filter, H5Z_FLAG_MANDATORY, 0, nullptr), 0);
  const hid_t d = H5Dcreate2(f, "/states/position", H5T_IEEE_F32LE, space, lcpl, dcpl, H5P_DEFAULT);
  ASSERT_GE(d, 0);
  if (write) {
    std::vector<float> x(rows * n * 3);
    for (hsize_t r = 0; r < rows; ++r) std::fill(x.begin() + r * n * 3, x.begin() + (r + 1) * n * 3, float(r));
    ASSERT_GE(H5Dwrite(d, H5T_NATIVE_FLOAT, H5S_ALL, H5S_ALL, H5P_DEFAULT, x.data()), 0);
  }
  H5Dclose(d);
  H5Pclose(dcpl);
  H5Sclose(space);
  H5Pclose(lcpl);
  H5Fclose(f);
}

// Before: 32 rows read one by one from one 1.9 MB chunk inflated it 32 times (and a
// chunk of 1,000 rows 1,000 times). Now once.
TEST(TraceChunks, RowsReadOneByOneInflateEachChunkOnce) {
  register_counting_filter();
  const fs::path dir = scratch("once");
  const std::string path = (dir / "t.h5").string();
  const hsize_t rows = 32, n = 5000;  // a chunk of 32 rows: 1.92 MB, above HDF5's 1 MiB default cache
  write_chunked_trace(path, rows, n, {rows, n, 3}, kCountingFilter);
  g_decodes = 0;
  {
    const octocd::TraceReader reader(path);
    for (hsize_t r = 0; r < rows; ++r) {
      const std::vector<float> row = reader.read_f32_rows("/states/position", static_cast<std::int64_t>(r), 1);
      ASSERT_EQ(row.size(), n * 3);
      ASSERT_EQ(row.front(), float(r));
      ASSERT_EQ(row.back(), float(r));
    }
  }
  EXPECT_EQ(g_decodes.load(), 1) << "decodes of the one chunk for " << rows << " row reads";
  // Two chunks of 16 rows, read in order: each inflated once.
  write_chunked_trace(path, rows, n, {16, n, 3}, kCountingFilter);
  g_decodes = 0;
  {
    const octocd::TraceReader reader(path);
    for (hsize_t r = 0; r < rows; ++r)
      ASSERT_EQ(reader.read_f32_rows("/states/position", static_cast<std::int64_t>(r), 1).front(), float(r));
  }
  EXPECT_EQ(g_decodes.load(), 2);
  fs::remove_all(dir);
}

// The budget counts chunks inflated: rows read alternately from two bands of 15 MB each
// (a file of a few dozen KB of deflated zeros) inflate a band per read; the reader refuses
// them past 64 x the file's size + 64 MiB, naming the file and dataset, within a few reads.
// Before: each read counted 240 KB (the row), and 200 reads inflated 3 GB.
TEST(TraceChunks, RereadChunksCountAgainstTheReadBudget) {
  const fs::path dir = scratch("budget");
  const std::string path = (dir / "bomb.h5").string();
  const hsize_t rows = 128, n = 20000;  // two chunks of 64 rows: 15.4 MB each inflated
  write_chunked_trace(path, rows, n, {64, n, 3}, H5Z_FILTER_DEFLATE);
  const auto file_bytes = fs::file_size(path);
  ASSERT_LT(file_bytes, 1u << 20) << "deflated zeros";
  const octocd::TraceReader reader(path);
  int reads = 0;
  try {
    for (; reads < 200; ++reads)
      reader.read_f32_rows("/states/position", reads % 2 == 0 ? 0 : 64, 1);  // band 0, band 1, band 0, ...
    FAIL() << "200 reads inflating 3 GB from a " << file_bytes << "-byte file were accepted";
  } catch (const octocd::InputError& e) {
    const std::string m = e.what();
    EXPECT_NE(m.find(path + ": /states/position: "), std::string::npos) << m;
    EXPECT_NE(m.find("allowed: a file whose values read in all are at most 64 x its size"), std::string::npos) << m;
  }
  std::printf("refused after %d reads of a %ju-byte file\n", reads, static_cast<std::uintmax_t>(file_bytes));
  EXPECT_LE(reads, 8) << "(64 MiB + 64 x the file) / 15.4 MB per read";
  fs::remove_all(dir);
}

// A compressed chunk above 256 MiB (here 768 MiB declared, never written) is refused
// naming the file, dataset and limit before anything is inflated.
TEST(TraceChunks, ChunksAboveTheLimitAreRefused) {
  const fs::path dir = scratch("huge");
  const std::string path = (dir / "huge.h5").string();
  write_chunked_trace(path, 2, 4, {1, hsize_t(1) << 26, 3}, H5Z_FILTER_DEFLATE, false);
  const octocd::TraceReader reader(path);
  try {
    reader.read_f32_rows("/states/position", 0, 1);
    FAIL() << "a chunk of 768 MiB was accepted";
  } catch (const octocd::InputError& e) {
    const std::string m = e.what();
    EXPECT_NE(m.find(path + ": /states/position: compressed in chunks of 1 x 67108864 x 3 x 4 bytes"),
              std::string::npos)
        << m;
    EXPECT_NE(m.find("allowed: compressed chunks of at most 256 MiB each"), std::string::npos) << m;
  }
  fs::remove_all(dir);
}

// write_view polls ViewSettings::stop before every frame of its window: a stop ends it
// with ValidationStopped and no page (octocd.view raises KeyboardInterrupt so).
TEST(ViewStop, AStopEndsTheWindowWithoutAPage) {
  const fs::path dir = scratch("view");
  const std::string path = (dir / "v.h5").string();
  const hsize_t frames = 200;
  const std::vector<float> lo{-0.5f, -0.5f, -0.5f}, hi{0.5f, 0.5f, 0.5f}, w{1.0f};
  const std::vector<float> x((frames + 1) * 3, 0.0f);
  octocd::test::write_minimal_trace(path, {{"/bodies/local_aabb_min", {1, 3}, &lo},
                                           {"/bodies/local_aabb_max", {1, 3}, &hi},
                                           {"/bodies/inverse_mass", {1}, &w},
                                           {"/states/position", {frames + 1, 1, 3}, &x},
                                           {"/states/velocity", {frames + 1, 1, 3}, &x}});
  octocd::ViewSettings vs;
  vs.frame = 100;
  vs.window = 50;
  int polls = 0;
  vs.stop = [&] { return ++polls > 3; };
  EXPECT_THROW(octocd::write_view(path, vs, (dir / "out").string()), octocd::ValidationStopped);
  EXPECT_EQ(polls, 4) << "polled once per frame until the stop";
  EXPECT_FALSE(fs::exists(dir / "out") && !fs::is_empty(dir / "out")) << "no page written";
  vs.stop = [] { return false; };
  EXPECT_NO_THROW(octocd::write_view(path, vs, (dir / "out").string()));
  fs::remove_all(dir);
}

}  // namespace

}  // namespace octocd_test_trace_chunks
