// The HDF5 writing primitives of traces (trace_hdf5_out.hpp).
#include "trace_hdf5_out.hpp"

#include <algorithm>
#include <chrono>
#include <ctime>

#include <fmt/format.h>

namespace octocd::trace_out {

// The innermost (most specific) and outermost messages of HDF5's current error stack.
std::string hdf5_message() {
  std::vector<std::string> msgs;
  H5Ewalk2(
      H5E_DEFAULT, H5E_WALK_DOWNWARD,
      [](unsigned, const H5E_error2_t* e, void* data) -> herr_t {
        auto* out = static_cast<std::vector<std::string>*>(data);
        std::string s = e->desc ? e->desc : "";
        if (e->func_name) s += std::string(" (") + e->func_name + ")";
        out->push_back(s);
        return 0;
      },
      &msgs);
  H5Eclear2(H5E_DEFAULT);
  if (msgs.empty()) return "unknown HDF5 error";
  if (msgs.size() == 1) return msgs.front();
  return msgs.front() + ": " + msgs.back();
}

// The operating system's reason in an HDF5 I/O error ("... error message = 'No space left
// on device', ..."), or "" when the message holds none.
std::string os_reason(const std::string& message) {
  const std::string tag = "error message = '";
  const auto b = message.find(tag);
  if (b == std::string::npos) return "";
  const auto e = message.find('\'', b + tag.size());
  return message.substr(b + tag.size(), e == std::string::npos ? std::string::npos : e - b - tag.size());
}

[[noreturn]] void fail(const std::string& path, const std::string& op) {
  std::string message = hdf5_message();
  const std::string reason = os_reason(message);
  if (!reason.empty()) message = reason;
  std::replace(message.begin(), message.end(), '\n', ' ');
  throw Hdf5Failure(path, op, message);
}

Handle vlen_string_type(const std::string& path) {
  Handle t(check(H5Tcopy(H5T_C_S1), path, "H5Tcopy"));
  check(H5Tset_size(t, H5T_VARIABLE), path, "H5Tset_size");
  check(H5Tset_cset(t, H5T_CSET_UTF8), path, "H5Tset_cset");
  return t;
}

void attr_string(hid_t obj, const char* name, const std::string& value, const std::string& path) {
  Handle type = vlen_string_type(path);
  Handle space(check(H5Screate(H5S_SCALAR), path, "H5Screate"));
  Handle a(check(H5Acreate2(obj, name, type, space, H5P_DEFAULT, H5P_DEFAULT), path,
                 std::string("create attribute ") + name));
  const char* p = value.c_str();
  check(H5Awrite(a, type, &p), path, std::string("write attribute ") + name);
}

void attr_strings(hid_t obj, const char* name, const std::vector<std::string>& values,
                  const std::string& path) {
  Handle type = vlen_string_type(path);
  const hsize_t n = values.size();
  Handle space(check(H5Screate_simple(1, &n, nullptr), path, "H5Screate_simple"));
  Handle a(check(H5Acreate2(obj, name, type, space, H5P_DEFAULT, H5P_DEFAULT), path,
                 std::string("create attribute ") + name));
  std::vector<const char*> ptrs;
  for (const auto& v : values) ptrs.push_back(v.c_str());
  if (n > 0) check(H5Awrite(a, type, ptrs.data()), path, std::string("write attribute ") + name);
}

// A fixed-size dataset written once, before SWMR starts.
void fixed_dataset(hid_t group, const char* name, hid_t file_type, hid_t mem_type,
                   std::vector<hsize_t> dims, const void* data, const std::string& path) {
  Handle space(check(H5Screate_simple(static_cast<int>(dims.size()), dims.data(), nullptr), path,
                     "H5Screate_simple"));
  Handle d(check(H5Dcreate2(group, name, file_type, space, H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT),
                 path, std::string("create dataset ") + name));
  if (dims[0] > 0)
    check(H5Dwrite(d, mem_type, H5S_ALL, H5S_ALL, H5P_DEFAULT, data), path,
          std::string("write dataset ") + name);
}

void string_dataset(hid_t group, const char* name, const std::vector<std::string>& values,
                    const std::string& path) {
  Handle type = vlen_string_type(path);
  std::vector<const char*> ptrs;
  for (const auto& v : values) ptrs.push_back(v.c_str());
  fixed_dataset(group, name, type, type, {values.size()}, ptrs.data(), path);
}

Column make_column(hid_t group, const std::string& group_name, const char* name, hid_t file_type,
                   hid_t mem_type, std::vector<hsize_t> tail, hsize_t chunk_rows, int gzip,
                   const std::string& path) {
  Column c;
  c.name = group_name + "/" + name;
  c.mem_type = mem_type;
  c.elem = H5Tget_size(mem_type);
  c.tail = tail;
  std::vector<hsize_t> dims{0}, maxdims{H5S_UNLIMITED}, chunk{chunk_rows};
  for (hsize_t t : tail) {
    c.width *= static_cast<std::size_t>(t);
    dims.push_back(t);
    maxdims.push_back(t == 0 ? H5S_UNLIMITED : t);
    chunk.push_back(std::max<hsize_t>(t, 1));
  }
  const int rank = static_cast<int>(dims.size());
  Handle space(check(H5Screate_simple(rank, dims.data(), maxdims.data()), path,
                     "H5Screate_simple " + c.name));
  Handle dcpl(check(H5Pcreate(H5P_DATASET_CREATE), path, "H5Pcreate"));
  check(H5Pset_chunk(dcpl, rank, chunk.data()), path, "H5Pset_chunk " + c.name);
  if (gzip > 0 && H5Zfilter_avail(H5Z_FILTER_DEFLATE) > 0) {
    check(H5Pset_shuffle(dcpl), path, "H5Pset_shuffle " + c.name);
    check(H5Pset_deflate(dcpl, static_cast<unsigned>(gzip)), path, "H5Pset_deflate " + c.name);
    c.filtered = chunk_rows == 1;  // a chunk is a row: H5Dwrite_chunk can store one as it is
  }
  c.dset = Handle(check(H5Dcreate2(group, name, file_type, space, H5P_DEFAULT, dcpl, H5P_DEFAULT),
                        path, "create dataset " + c.name));
  return c;
}

std::string iso_utc_now() {
  const std::time_t t = std::chrono::system_clock::to_time_t(std::chrono::system_clock::now());
  std::tm tm{};
  gmtime_r(&t, &tm);
  char buf[32];
  std::strftime(buf, sizeof buf, "%Y-%m-%dT%H:%M:%SZ", &tm);
  return buf;
}

nlohmann::json vec_json(Vec3 v) { return nlohmann::json::array({v.x, v.y, v.z}); }

}  // namespace octocd::trace_out
