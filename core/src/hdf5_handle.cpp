// Hdf5Reader (hdf5_handle.hpp): the one hardened way octocd opens and reads an HDF5 file
// (issue 22; docs/trace-format.md, "Security rules and limits").
#include "hdf5_handle.hpp"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <algorithm>
#include <cstring>
#include <limits>

#include <fmt/format.h>

#include "octocd/atomic_file.hpp"
#include "octocd/error.hpp"

namespace octocd {
namespace detail {

namespace {

const char* class_name(H5T_class_t c) {
  switch (c) {
    case H5T_INTEGER: return "integer";
    case H5T_FLOAT: return "float";
    case H5T_STRING: return "string";
    case H5T_COMPOUND: return "compound";
    case H5T_ARRAY: return "array type";
    case H5T_ENUM: return "enum";
    case H5T_VLEN: return "variable-length sequence";
    case H5T_REFERENCE: return "reference";
    case H5T_OPAQUE: return "opaque";
    case H5T_BITFIELD: return "bitfield";
    case H5T_TIME: return "time";
    default: return "unknown type";
  }
}

std::string shape_text(const std::vector<hsize_t>& dims) {
  if (dims.empty()) return "a scalar";
  std::string s;
  for (hsize_t d : dims) s += (s.empty() ? "" : " x ") + std::to_string(d);
  return s;
}

}  // namespace

GlobalHeaps check_global_heaps(const std::string& path) {
  GlobalHeaps heaps;
  // libhdf5 1.10 loops forever on a global heap collection ("GCOL": where variable-length
  // strings live, so every trace's root attributes) holding a free-space object of size 0
  // (H5HG__cache_heap_deserialize advances by the object's size; the heap has no
  // checksum), and reads past the collection (SIGSEGV) for an object larger than what is
  // left of it. Found by fuzzing the trace readers with flipped bytes. Every collection is
  // walked the way HDF5 walks it (HDF5 file format spec, "Global Heap"; 8-byte lengths).
  // Read with pread, never mmap: reading a mapped hole of a file on a full tmpfs raises
  // SIGBUS (found by the full-disk test of issue 22).
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC | O_NONBLOCK);
  if (fd < 0) return heaps;  // the caller's open reports it
  struct stat st {};
  if (::fstat(fd, &st) != 0 || !S_ISREG(st.st_mode) || st.st_size < 16) {
    ::close(fd);
    return heaps;
  }
  const auto size = static_cast<std::uint64_t>(st.st_size);
  // Bytes [at, at + n) of the file (n <= 16), zero past its end or on a read error.
  auto bytes_at = [&](std::uint64_t at, unsigned char* out, std::size_t n) {
    std::memset(out, 0, n);
    if (at < size) (void)!::pread(fd, out, n, static_cast<off_t>(at));
  };
  auto u64 = [](const unsigned char* p) {
    std::uint64_t v = 0;
    for (int k = 7; k >= 0; --k) v = (v << 8) | p[k];
    return v;
  };
  std::string corrupt;
  constexpr std::size_t kChunk = 1 << 20;
  std::vector<unsigned char> buf(kChunk + 8);
  for (std::uint64_t base = 0; corrupt.empty() && base < size; base += kChunk) {
    const std::size_t want = static_cast<std::size_t>(std::min<std::uint64_t>(kChunk + 4, size - base));
    const ssize_t got = ::pread(fd, buf.data(), want, static_cast<off_t>(base));
    if (got <= 0) break;
    for (std::size_t i = 0; corrupt.empty() && i + 5 <= static_cast<std::size_t>(got) && i < kChunk;) {
      const void* hit = ::memmem(buf.data() + i, static_cast<std::size_t>(got) - i, "GCOL\x01", 5);
      if (hit == nullptr) break;
      const std::size_t off = static_cast<std::size_t>(static_cast<const unsigned char*>(hit) - buf.data());
      if (off >= kChunk) break;  // found again in the next chunk
      i = off + 1;
      const std::uint64_t start = base + off;
      if (start + 16 > size) break;
      unsigned char head[16];
      bytes_at(start, head, 16);
      const std::uint64_t claimed = u64(head + 8);
      const std::uint64_t end = claimed > size - start ? size : start + claimed;
      for (std::uint64_t obj = start + 16; obj < end;) {
        if (obj + 16 > end) break;  // HDF5: the tail is free space
        unsigned char o[16];
        bytes_at(obj, o, 16);
        const unsigned idx = static_cast<unsigned>(o[0]) | (static_cast<unsigned>(o[1]) << 8);
        const std::uint64_t len = u64(o + 8);
        const std::uint64_t need = idx > 0 ? 16 + ((len / 8) + (len % 8 != 0)) * 8 : len;
        if (need == 0 || need > end - obj || (idx > 0 && len > end - obj)) {  // a loop, or past the heap
          corrupt = "global heap collection at byte " + std::to_string(start) + " holds an object of " +
                    std::to_string(len) + " bytes at byte " + std::to_string(obj) + " that does not fit it";
          break;
        }
        if (idx > 0) heaps[start][idx] = len;
        obj += need;
      }
    }
  }
  ::close(fd);
  if (!corrupt.empty())
    throw InputError(fmt::format("{}: corrupt file ({}); allowed: an HDF5 file that is not damaged", path, corrupt));
  return heaps;
}

namespace {

/// True when HDF5's error stack of the call that just failed holds an allocation failure
/// (major H5E_RESOURCE, or minor H5E_CANTALLOC / H5E_NOSPACE): the process ran out of
/// memory (a memory limit, ulimit -v), which says nothing about the file.
bool hdf5_out_of_memory() {
  bool oom = false;
  H5Ewalk2(
      H5E_DEFAULT, H5E_WALK_UPWARD,
      [](unsigned, const H5E_error2_t* e, void* data) -> herr_t {
        if (e->maj_num == H5E_RESOURCE || e->min_num == H5E_CANTALLOC || e->min_num == H5E_NOSPACE)
          *static_cast<bool*>(data) = true;
        return 0;
      },
      &oom);
  return oom;
}

}  // namespace

Hdf5Reader::Hdf5Reader(const std::string& path, const std::string& what) : path_(path), what_(what) {
  // A regular file only: HDF5 would block forever on a FIFO and read /dev/zero forever.
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0) {
    const int e = errno;
    throw InputError(fmt::format("{}: cannot open ({}: {}); allowed: {} (.h5)", path,
                                 e == ENOENT ? "ENOENT" : e == EACCES ? "EACCES" : "errno " + std::to_string(e),
                                 std::strerror(e), what));
  }
  if (!S_ISREG(st.st_mode))
    throw InputError(fmt::format("{}: not a regular file ({}); allowed: {} stored in a regular file", path,
                                 file_type_word(st.st_mode), what));
  file_bytes_ = static_cast<std::uint64_t>(st.st_size);
  if (H5Fis_hdf5(path.c_str()) <= 0)
    throw InputError(fmt::format("{}: not an HDF5 file{}; allowed: {} (docs/trace-format.md)", path,
                                 st.st_size < 512 ? fmt::format(" (only {} bytes: truncated?)", st.st_size) : "",
                                 what));
  heaps_ = check_global_heaps(path);
  // A SWMR reader retries a metadata read whose checksum fails (the writer may be half-way
  // through a write), sleeping 1 ns, 2 ns, 4 ns, ... between tries: HDF5's default of 100
  // tries never ends on a corrupt file (found by fuzz_trace). 24 tries wait about 17 ms.
  Hdf5Handle fapl(H5Pcreate(H5P_FILE_ACCESS));
  if (!fapl.ok() || H5Pset_metadata_read_attempts(fapl, 24) < 0)
    throw RuntimeError(fmt::format("{}: cannot set up HDF5 file access", path));
  file_ = Hdf5Handle(H5Fopen(path.c_str(), H5F_ACC_RDONLY | H5F_ACC_SWMR_READ, fapl));
  if (!file_.ok()) file_ = Hdf5Handle(H5Fopen(path.c_str(), H5F_ACC_RDONLY, fapl));
  if (!file_.ok() && hdf5_out_of_memory())
    throw RuntimeError(fmt::format("{}: out of memory while HDF5 opened it (this process may allocate less than "
                                   "the file needs: a memory limit such as ulimit -v; the file is not known to be "
                                   "damaged)",
                                   path));
  if (!file_.ok())
    throw InputError(fmt::format("{}: HDF5 cannot open it read-only (truncated or damaged: {} bytes); allowed: {}",
                                 path, st.st_size, what));
}


void Hdf5Reader::fail(const std::string& object, const std::string& problem, const std::string& allowed) const {
  if (hdf5_out_of_memory())
    throw RuntimeError(fmt::format("{}: {}: out of memory while reading it (this process may allocate less than "
                                   "the read needs: a memory limit such as ulimit -v; the file is not known to be "
                                   "damaged)",
                                   path_, object));
  throw InputError(fmt::format("{}: {}: {}; allowed: {}", path_, object, problem, allowed));
}

bool Hdf5Reader::exists(const std::string& name) const {
  if (name.empty() || name[0] != '/') fail(name, "not an absolute path", "internal: a path from /");
  if (name == "/") return true;
  std::size_t pos = 0;
  for (;;) {
    const std::size_t next = name.find('/', pos + 1);
    const std::string part = name.substr(0, next);
    if (H5Lexists(file_, part.c_str(), H5P_DEFAULT) <= 0) return false;
    H5L_info_t li{};
    if (H5Lget_info(file_, part.c_str(), &li, H5P_DEFAULT) < 0) fail(part, "unreadable link", "a readable file");
    if (li.type != H5L_TYPE_HARD)
      fail(part,
           li.type == H5L_TYPE_EXTERNAL ? "an external link (to another file), refused"
           : li.type == H5L_TYPE_SOFT   ? "a soft link, refused"
                                        : "a user-defined link, refused",
           "objects stored in this file under their own name (hard links)");
    if (next == std::string::npos) return true;
    pos = next;
  }
}

bool Hdf5Reader::is_dataset(const std::string& name) const {
  if (!exists(name)) return false;
  const Hdf5Handle obj(H5Oopen(file_, name.c_str(), H5P_DEFAULT));
  return obj.ok() && H5Iget_type(obj) == H5I_DATASET;
}

bool Hdf5Reader::has_attribute(const std::string& name) const { return H5Aexists(file_, name.c_str()) > 0; }

Hdf5Handle Hdf5Reader::attribute(const std::string& name, H5T_class_t cls, std::size_t count) const {
  const std::string obj = "/ (root attribute " + name + ")";
  if (!has_attribute(name)) fail(obj, "missing", count == 1 ? "one value" : std::to_string(count) + " values");
  Hdf5Handle a(H5Aopen(file_, name.c_str(), H5P_DEFAULT));
  if (!a.ok()) fail(obj, "cannot be opened", "a readable attribute");
  Hdf5Handle type(H5Aget_type(a));
  Hdf5Handle space(H5Aget_space(a));
  if (!type.ok() || !space.ok()) fail(obj, "unreadable type or dataspace", "a readable attribute");
  const H5T_class_t c = H5Tget_class(type);
  const bool numeric = cls == H5T_FLOAT;  // the caller's code for "a number"
  if (numeric ? (c != H5T_INTEGER && c != H5T_FLOAT) : c != cls)
    fail(obj, fmt::format("stored as {}", class_name(c)), numeric ? "a number (integer or float)" : "a string");
  const H5S_class_t sc = H5Sget_simple_extent_type(space);
  const hssize_t n = H5Sget_simple_extent_npoints(space);
  const bool ok = count == 1 ? (sc == H5S_SCALAR || (sc == H5S_SIMPLE && n == 1))
                             : (sc == H5S_SIMPLE && n == static_cast<hssize_t>(count));
  if (!ok)
    fail(obj,
         sc == H5S_NULL ? "holds no value (null dataspace)"
                        : fmt::format("stored as an array of {} values", n),
         count == 1 ? "one value (a scalar attribute)" : fmt::format("{} values", count));
  if (!numeric && H5Tis_variable_str(type) <= 0 && H5Tget_size(type) > trace_limits::kMaxStringBytes)
    fail(obj, fmt::format("a string of {} bytes", H5Tget_size(type)),
         fmt::format("at most {} bytes", trace_limits::kMaxStringBytes));
  if (numeric && H5Tget_size(type) > 16) fail(obj, "a number wider than 128 bits", "a number (integer or float)");
  return a;
}

std::string Hdf5Reader::string_attribute(const std::string& name) const {
  const Hdf5Handle a = attribute(name, H5T_STRING, 1);
  const std::string obj = "/ (root attribute " + name + ")";
  Hdf5Handle type(H5Aget_type(a));
  std::string out;
  if (H5Tis_variable_str(type) > 0) {
    Hdf5Handle mem(H5Tcopy(H5T_C_S1));
    H5Tset_size(mem, H5T_VARIABLE);
    H5Tset_cset(mem, H5Tget_cset(type));
    char* s = nullptr;
    if (H5Aread(a, mem, &s) < 0) fail(obj, "unreadable (damaged file?)", "a readable string");
    if (s != nullptr) {
      const std::size_t len = ::strnlen(s, trace_limits::kMaxStringBytes + 1);
      out.assign(s, len);
      H5free_memory(s);
      if (len > trace_limits::kMaxStringBytes)
        fail(obj, "a string longer than the limit", fmt::format("at most {} bytes", trace_limits::kMaxStringBytes));
    }
  } else {
    std::string buf(H5Tget_size(type), '\0');
    if (H5Aread(a, type, buf.data()) < 0) fail(obj, "unreadable (damaged file?)", "a readable string");
    out = buf.substr(0, buf.find('\0'));
    // NUL padding only: "product\0min" is neither "product" nor "min".
    if (buf.find_first_not_of('\0', out.size()) != std::string::npos)
      fail(obj, fmt::format("a string with an embedded NUL byte at byte {}", out.size()),
           "a string without NUL bytes (NUL padding only at its end)");
  }
  return out;
}

double Hdf5Reader::number_attribute(const std::string& name) const {
  const Hdf5Handle a = attribute(name, H5T_FLOAT, 1);
  double v = 0.0;
  if (H5Aread(a, H5T_NATIVE_DOUBLE, &v) < 0)
    fail("/ (root attribute " + name + ")", "unreadable as a number", "a number");
  return v;
}

std::int64_t Hdf5Reader::integer_attribute(const std::string& name) const {
  const Hdf5Handle a = attribute(name, H5T_FLOAT, 1);
  const std::string obj = "/ (root attribute " + name + ")";
  Hdf5Handle type(H5Aget_type(a));
  const std::size_t size = H5Tget_size(type);
  if (H5Tget_class(type) != H5T_INTEGER || (size != 4 && size != 8))
    fail(obj, fmt::format("stored as a {}-bit {}", 8 * size, H5Tget_class(type) == H5T_INTEGER ? "integer" : "float"),
         "a 32- or 64-bit integer");
  std::int64_t v = 0;
  if (H5Aread(a, H5T_NATIVE_INT64, &v) < 0) fail(obj, "unreadable as an integer", "a 32- or 64-bit integer");
  return v;
}

std::vector<double> Hdf5Reader::number_attributes(const std::string& name, std::size_t count) const {
  const Hdf5Handle a = attribute(name, H5T_FLOAT, count);
  std::vector<double> v(count, 0.0);
  if (H5Aread(a, H5T_NATIVE_DOUBLE, v.data()) < 0)
    fail("/ (root attribute " + name + ")", "unreadable as numbers", fmt::format("{} numbers", count));
  return v;
}

std::uint64_t Hdf5Reader::Dataset::per_row() const {
  std::uint64_t n = 1;
  for (std::size_t k = 1; k < dims.size(); ++k) n *= dims[k];
  return n;
}

Hdf5Reader::Dataset Hdf5Reader::open_dataset(const std::string& name) const {
  Dataset d;
  d.name = name;
  if (!exists(name)) fail(name, "missing", "a dataset of the layout in docs/trace-format.md");
  if (!is_dataset(name)) fail(name, "not a dataset", "a dataset");
  d.id = Hdf5Handle(H5Dopen2(file_, name.c_str(), H5P_DEFAULT));
  if (!d.id.ok()) fail(name, "cannot be opened as a dataset (damaged file?)", "a readable dataset");
  // Storage: inside this file only.
  Hdf5Handle dcpl(H5Dget_create_plist(d.id));
  if (!dcpl.ok()) fail(name, "unreadable storage properties", "a readable dataset");
  const H5D_layout_t layout = H5Pget_layout(dcpl);
  if (layout == H5D_VIRTUAL)
    fail(name, "a virtual dataset (a view of data in other files), refused", "data stored in this file");
  if (layout != H5D_CONTIGUOUS && layout != H5D_CHUNKED && layout != H5D_COMPACT)
    fail(name, "unknown storage layout", "contiguous, chunked or compact storage");
  if (H5Pget_external_count(dcpl) != 0)
    fail(name, "external storage (raw data kept in another file), refused", "data stored in this file");
  const int filters = H5Pget_nfilters(dcpl);
  for (int k = 0; k < filters; ++k) {
    unsigned flags = 0;
    std::size_t nelmts = 0;
    char fname[64] = {0};
    const H5Z_filter_t id = H5Pget_filter2(dcpl, static_cast<unsigned>(k), &flags, &nelmts, nullptr,
                                           sizeof fname, fname, nullptr);
    if (id < 0 || H5Zfilter_avail(id) <= 0)
      fail(name, fmt::format("compressed with filter {} ('{}'), which this HDF5 library lacks", static_cast<int>(id),
                             fname),
           "uncompressed data, or deflate (gzip), shuffle, fletcher32");
  }
  // Type and shape.
  Hdf5Handle type(H5Dget_type(d.id));
  Hdf5Handle space(H5Dget_space(d.id));
  if (!type.ok() || !space.ok()) fail(name, "unreadable type or dataspace", "a readable dataset");
  d.cls = H5Tget_class(type);
  d.type_size = H5Tget_size(type);
  const int rank = H5Sget_simple_extent_ndims(space);
  if (rank < 0 || rank > 8) fail(name, "unreadable dataspace", "a dataset of rank 1 to 3");
  d.dims.assign(static_cast<std::size_t>(rank), 0);
  if (rank > 0) H5Sget_simple_extent_dims(space, d.dims.data(), nullptr);
  // Declared size against the file's size, in double (no overflow; exact far enough).
  double bytes = static_cast<double>(d.type_size);
  for (hsize_t x : d.dims) bytes *= static_cast<double>(x);
  const double budget = static_cast<double>(file_bytes_) * static_cast<double>(trace_limits::kMaxExpansion) +
                        static_cast<double>(trace_limits::kSlackBytes);
  if (bytes > budget)
    fail(name,
         fmt::format("declares {} of {} bytes each, more than a file of {} bytes can hold", shape_text(d.dims),
                     d.type_size, file_bytes_),
         fmt::format("at most {} x the file's size + 1 MiB of data (deflate compresses at most 1032:1)",
                     trace_limits::kMaxExpansion));
  if (layout == H5D_CHUNKED && filters > 0) open_chunked(d, dcpl);
  return d;
}

void Hdf5Reader::open_chunked(Dataset& d, hid_t dcpl) const {
  const int rank = static_cast<int>(d.dims.size());
  std::vector<hsize_t> chunk(static_cast<std::size_t>(std::max(rank, 1)), 0);
  if (rank < 1 || H5Pget_chunk(dcpl, rank, chunk.data()) != rank)
    fail(d.name, "unreadable chunk dimensions", "a readable chunked dataset");
  // Inflated bytes of one chunk and of the chunks one band of rows spans, in double.
  double chunk_bytes = static_cast<double>(std::max<std::size_t>(d.type_size, 1)), band_chunks = 1;
  for (int k = 0; k < rank; ++k) {
    if (chunk[k] == 0) fail(d.name, "a chunk dimension of 0", "chunks of at least one element each way");
    chunk_bytes *= static_cast<double>(chunk[k]);
    if (k > 0) band_chunks *= static_cast<double>((d.dims[k] + chunk[k] - 1) / chunk[k]);
  }
  const double cap = static_cast<double>(trace_limits::kMaxChunkBytes);
  if (chunk_bytes > cap)
    fail(d.name,
         fmt::format("compressed in chunks of {} x {} bytes ({:.0f} bytes inflated each)",
                     shape_text(chunk), d.type_size, chunk_bytes),
         fmt::format("compressed chunks of at most {} MiB each (every read inflates a whole chunk)",
                     trace_limits::kMaxChunkBytes >> 20));
  if (chunk_bytes * band_chunks > cap)
    fail(d.name,
         fmt::format("a row spans {:.0f} compressed chunks of {:.0f} bytes ({:.0f} bytes inflated per band of rows)",
                     band_chunks, chunk_bytes, chunk_bytes * band_chunks),
         fmt::format("compressed chunks whose band of rows holds at most {} MiB", trace_limits::kMaxChunkBytes >> 20));
  d.chunk_rows = chunk[0];
  d.band_bytes = static_cast<std::uint64_t>(chunk_bytes * band_chunks);
  // A chunk a row (octocd's traces): a row read inflates its own chunks only.
  if (d.chunk_rows == 1) return;
  // Chunks of several rows: one open dataset per reader, its cache holding one band, so
  // rows read in order inflate each chunk once however small the reads (otherwise every
  // row read of a dataset whose chunks exceed HDF5's default 1 MiB cache, or reopened per
  // read, inflates them again). Its shape is then the one seen first (no SWMR refresh).
  auto found = chunked_.find(d.name);
  if (found == chunked_.end()) {
    Hdf5Handle dapl(H5Pcreate(H5P_DATASET_ACCESS));
    // Slots: a band's chunks have consecutive indices, so as many slots as chunks in the
    // band never collide (HDF5 hashes a chunk by its index modulo the slots).
    const auto slots = static_cast<std::size_t>(std::min(band_chunks * 2 + 1, double(1 << 20)));
    if (!dapl.ok() ||
        H5Pset_chunk_cache(dapl, std::max<std::size_t>(slots, 521), d.band_bytes + (1u << 20), 1.0) < 0)
      fail(d.name, "cannot set up its chunk cache", "a readable dataset");
    // HDF5 shares one cache among the opens of a dataset, set up by the first: close ours.
    d.id.reset();
    Hdf5Handle id(H5Dopen2(file_, d.name.c_str(), dapl));
    if (!id.ok()) fail(d.name, "cannot be opened as a dataset (damaged file?)", "a readable dataset");
    found = chunked_.emplace(d.name, Cached{std::move(id), -1}).first;
  }
  if (H5Iinc_ref(found->second.id) < 0) fail(d.name, "cannot be shared", "a readable dataset");
  d.id = Hdf5Handle(found->second.id.get());
}

Hdf5Reader::Dataset Hdf5Reader::open_numeric(const std::string& name, int rank) const {
  Dataset d = open_dataset(name);
  if (d.cls != H5T_INTEGER && d.cls != H5T_FLOAT)
    fail(name, fmt::format("stored as {}", class_name(d.cls)), "numbers (integer or float)");
  if (d.type_size > 16) fail(name, "numbers wider than 128 bits", "numbers (integer or float)");
  if (static_cast<int>(d.dims.size()) != rank)
    fail(name, fmt::format("rank {} ({})", d.dims.size(), shape_text(d.dims)), fmt::format("rank {}", rank));
  return d;
}

void Hdf5Reader::read_rows(const Dataset& d, hsize_t first, hsize_t count, hid_t mem_type, void* out) const {
  if (d.dims.empty()) fail(d.name, "a scalar", "a dataset of rank >= 1");
  if (first > d.dims[0] || count > d.dims[0] - first)
    fail(d.name, fmt::format("rows {}..{} asked, it has {}", first, first + count, d.dims[0]),
         "rows below its length");
  if (count == 0 || d.per_row() == 0) return;
  // The read budget: values stored (count x per_row x the stored element's size), or of
  // a compressed chunked dataset the bands of chunks inflated when more (all but the one
  // its cache holds: open_chunked).
  const std::uint64_t budget = trace_limits::kMaxReadExpansion * file_bytes_ + trace_limits::kReadSlackBytes;
  std::uint64_t bytes = count * d.per_row() * std::max<std::uint64_t>(d.type_size, 1);
  if (d.chunk_rows > 0) {
    const auto b0 = static_cast<std::int64_t>(first / d.chunk_rows);
    const auto b1 = static_cast<std::int64_t>((first + count - 1) / d.chunk_rows);
    std::uint64_t bands = static_cast<std::uint64_t>(b1 - b0 + 1);
    if (d.chunk_rows > 1) {
      Cached& c = chunked_.at(d.name);
      if (c.band >= b0 && c.band <= b1) --bands;  // its chunks come from the cache
      c.band = b1;
    }
    bytes = std::max(bytes, bands * d.band_bytes);
  }
  read_bytes_ += bytes;
  if (read_bytes_ > budget)
    fail(d.name,
         fmt::format("reading rows {}..{} takes the values read from this {}-byte file past {} bytes (a compression "
                     "bomb?)",
                     first, first + count - 1, file_bytes_, budget),
         fmt::format("a file whose values read in all are at most {} x its size + {} MiB", trace_limits::kMaxReadExpansion,
                     trace_limits::kReadSlackBytes >> 20));
  Hdf5Handle fspace(H5Dget_space(d.id));
  std::vector<hsize_t> start(d.dims.size(), 0), cnt = d.dims;
  start[0] = first;
  cnt[0] = count;
  Hdf5Handle mspace(H5Screate_simple(static_cast<int>(cnt.size()), cnt.data(), nullptr));
  if (!fspace.ok() || !mspace.ok() ||
      H5Sselect_hyperslab(fspace, H5S_SELECT_SET, start.data(), nullptr, cnt.data(), nullptr) < 0)
    fail(d.name, "cannot select rows", "a readable dataset");
  if (H5Dread(d.id, mem_type, mspace, fspace, H5P_DEFAULT, out) < 0)
    fail(d.name,
         fmt::format("reading rows {}..{} failed (a type HDF5 cannot convert, a missing filter, or a damaged file)",
                     first, first + count - 1),
         "a readable dataset of numbers");
}

void Hdf5Reader::check_vlen_lengths(const Dataset& d) const {
  // Each stored element of a variable-length string is (length: 4 bytes, global heap
  // address: 8, index: 4). libhdf5 1.10 allocates and zero-fills `length` bytes before it
  // reads the heap object: a damaged length of 4 GB costs seconds and gigabytes of memory
  // per element (found by mutation fuzzing of replay's /bodies/group). The lengths of a
  // contiguous dataset are read from the file and bounded first; other layouts are refused.
  Hdf5Handle dcpl(H5Dget_create_plist(d.id));
  const haddr_t at = H5Dget_offset(d.id);
  const std::uint64_t n = d.dims.empty() ? 1 : d.dims[0];
  if (n == 0) return;
  if (!dcpl.ok() || H5Pget_layout(dcpl) != H5D_CONTIGUOUS || at == HADDR_UNDEF)
    fail(d.name, "variable-length strings not stored contiguously", "a contiguous dataset of strings (as h5py and "
         "octocd write them)");
  Hdf5Handle fcpl(H5Fget_create_plist(file_));
  std::size_t addr = 0, len_size = 0;
  if (!fcpl.ok() || H5Pget_sizes(fcpl, &addr, &len_size) < 0 || addr == 0 || addr > 8)
    fail(d.name, "unreadable file layout", "a readable file");
  const std::uint64_t elem = 4 + addr + 4;
  if (n > file_bytes_ / elem || at > file_bytes_ - n * elem)
    fail(d.name, fmt::format("{} strings past the end of the file", n), "strings stored in the file");
  const int fd = ::open(path_.c_str(), O_RDONLY | O_CLOEXEC | O_NONBLOCK);
  if (fd < 0) fail(d.name, "cannot reread the file", "a readable file");
  std::vector<unsigned char> raw(static_cast<std::size_t>(n * elem));
  const ssize_t got = ::pread(fd, raw.data(), raw.size(), static_cast<off_t>(at));
  ::close(fd);
  if (got != static_cast<ssize_t>(raw.size())) fail(d.name, "cannot reread the strings", "a readable file");
  hsize_t userblock = 0;
  H5Pget_userblock(fcpl, &userblock);
  const auto le = [](const unsigned char* p, std::size_t bytes) {
    std::uint64_t v = 0;
    for (std::size_t k = bytes; k-- > 0;) v = (v << 8) | p[k];
    return v;
  };
  std::uint64_t total = 0;
  for (std::uint64_t i = 0; i < n; ++i) {
    const unsigned char* p = raw.data() + i * elem;
    const std::uint64_t len = le(p, 4);
    const std::uint64_t heap = le(p + 4, addr) + userblock;
    const auto idx = static_cast<unsigned>(le(p + 4 + addr, 4));
    total += len;
    if (len > file_bytes_ || len > trace_limits::kMaxStringBytes || total > file_bytes_)
      fail(d.name, fmt::format("element {} claims a string of {} bytes", i, len),
           fmt::format("strings held by the file (at most {} bytes each)", trace_limits::kMaxStringBytes));
    if (len == 0) continue;  // HDF5 reads no heap object for an empty string
    // The heap object must exist and hold the string: libhdf5 1.10 indexes its object
    // table with the stored index unchecked (SIGSEGV in H5HG_read; found by fuzzing).
    const auto h = heaps_.find(heap);
    const auto o = h == heaps_.end() ? decltype(h->second.end()){} : h->second.find(idx);
    if (h == heaps_.end() || o == h->second.end() || o->second < len)
      fail(d.name, fmt::format("element {} points to global heap object {} at byte {}, which {}", i, idx, heap,
                               h == heaps_.end() || o == h->second.end() ? "does not exist" : "is shorter"),
           "strings held by the file's global heap");
  }
}

std::vector<std::string> Hdf5Reader::read_strings(const std::string& name) const {
  const Dataset d = open_dataset(name);
  if (d.cls != H5T_STRING) fail(name, fmt::format("stored as {}", class_name(d.cls)), "strings");
  if (d.dims.size() != 1) fail(name, fmt::format("rank {}", d.dims.size()), "a 1-D dataset of strings");
  Hdf5Handle type(H5Dget_type(d.id));
  std::vector<std::string> out;
  const std::size_t n = static_cast<std::size_t>(d.dims[0]);
  if (n == 0) return out;
  out.reserve(n);
  if (H5Tis_variable_str(type) > 0) {
    check_vlen_lengths(d);
    Hdf5Handle mt(H5Tcopy(H5T_C_S1));
    H5Tset_size(mt, H5T_VARIABLE);
    H5Tset_cset(mt, H5Tget_cset(type));
    std::vector<char*> raw(n, nullptr);
    if (H5Dread(d.id, mt, H5S_ALL, H5S_ALL, H5P_DEFAULT, raw.data()) < 0)
      fail(name, "unreadable strings (damaged file?)", "a readable dataset of strings");
    bool too_long = false;
    for (char* p : raw) {
      const std::size_t len = p ? ::strnlen(p, trace_limits::kMaxStringBytes + 1) : 0;
      too_long = too_long || len > trace_limits::kMaxStringBytes;
      out.emplace_back(p ? std::string(p, len) : std::string());
      if (p) H5free_memory(p);
    }
    if (too_long) fail(name, "a string longer than the limit", fmt::format("at most {} bytes", trace_limits::kMaxStringBytes));
  } else {
    if (d.type_size > trace_limits::kMaxStringBytes)
      fail(name, fmt::format("strings of {} bytes", d.type_size), fmt::format("at most {} bytes", trace_limits::kMaxStringBytes));
    std::vector<char> buf(n * d.type_size);
    if (H5Dread(d.id, type, H5S_ALL, H5S_ALL, H5P_DEFAULT, buf.data()) < 0)
      fail(name, "unreadable strings (damaged file?)", "a readable dataset of strings");
    for (std::size_t i = 0; i < n; ++i) {
      const char* p = buf.data() + i * d.type_size;
      out.emplace_back(p, ::strnlen(p, d.type_size));
    }
  }
  return out;
}

}  // namespace detail
}  // namespace octocd
