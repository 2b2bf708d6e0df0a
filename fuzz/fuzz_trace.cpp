// libFuzzer target: the trace readers (issues 10, 22 and 36). The input is written as a file
// and every reader below opens it: read_trace_summary and the XDMF sidecar, the trace
// reader of `octocd compare` and `octocd replay` (TraceReader, read the way they read it),
// and TraceReader as octocd.Trace (Python) and `octocd trace-summary` (the report) read it.
// The commands themselves have their own targets (fuzz_compare, fuzz_replay), and so has
// the external-trace reader of `validate --trace-in` (fuzz_external). A file that
// is not a readable trace must end in InputError (exit 2) or RuntimeError (exit 1);
// anything else (a crash, a hang, another exception) is a finding.
//
// Note: the HDF5 library itself is not instrumented (Debian's libhdf5), so the fuzzer sees
// coverage only in octocd's code; crashes inside libhdf5 on malformed files are upstream
// bugs, reported as such.
#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <fstream>
#include <functional>
#include <string>
#include <vector>

#include "octocd/error.hpp"
#include "octocd/trace.hpp"
#include "octocd/trace_reader.hpp"

namespace {

struct Reader {
  const char* name;
  std::function<void(const std::string&)> read;
};

const Reader kReaders[] = {
    {"read_trace_summary", [](const std::string& p) { (void)octocd::read_trace_summary(p); }},
    {"write_xdmf_sidecar",
     [](const std::string& p) { std::remove(octocd::write_xdmf_sidecar(p).c_str()); }},
    // What compare and replay read (cli/compare.cpp, cli/replay.cpp).
    {"TraceReader",
     [](const std::string& p) {
       const octocd::TraceReader t(p);
       for (const char* a : {"scene_name", "scene", "parameters", "engine", "build_id"})
         if (t.has_attribute(a)) (void)t.string_attribute(a);
       const auto boxes = t.local_boxes();
       const auto n = static_cast<std::int64_t>(boxes.size());
       (void)t.read_f32("/bodies/inverse_mass", n);
       (void)t.read_u32("/bodies/shape_id", n);
       if (t.has_dataset("/bodies/group")) (void)t.read_strings("/bodies/group");
       const std::int64_t rows = t.complete_rows("/frames");
       (void)t.read_i64("/frames/frame", rows);
       (void)t.read_u64("/frames/aabb_pairs", rows);
       const std::int64_t states = t.complete_rows("/states");
       (void)t.read_i64("/states/frame", states);
       if (states > 0) (void)t.read_f32_rows("/states/position", states - 1, 1);
       if (t.has_dataset("/contacts/offsets")) {
         const std::int64_t c = t.complete_rows("/contacts");
         (void)t.read_i64("/contacts/offsets", c + 1);
       }
     }},
    // What octocd.Trace (the Python module's TraceFile) and `octocd trace-summary` (the
    // report's input) read: every documented root attribute, every /frames column, the
    // states and the contacts of the first and last frame, row by row.
    {"TraceFile",
     [](const std::string& p) {
       const octocd::TraceReader t(p);
       for (const char* a : {"format", "version", "scene_name", "engine", "body_count", "dt", "state_every",
                             "committed_frames", "committed_states", "stage_names", "gravity", "mu",
                             "friction_combine", "contact_margin"})
         if (t.has_attribute(a)) (void)t.attribute(a);
       const std::int64_t rows = t.has_dataset("/frames/frame") ? t.complete_rows("/frames") : 0;
       for (const std::string& c : octocd::TraceReader::frame_columns()) {
         const std::string d = "/frames/" + c;
         if (!t.has_dataset(d)) continue;
         if (t.element_kind(d) == "integer") (void)t.read_i64_rows(d, 0, rows);
         else (void)t.read_f64_rows(d, 0, rows);
       }
       if (t.has_dataset("/states/position")) {
         const std::int64_t s = t.complete_rows("/states");
         if (t.has_dataset("/states/frame")) (void)t.read_i64_rows("/states/frame", 0, s);
         for (const char* d : {"/states/position", "/states/velocity", "/states/orientation"})
           if (s > 0 && t.has_dataset(d)) (void)t.read_f32_rows(d, s - 1, 1);
       }
       if (t.has_dataset("/contacts/offsets")) {
         const auto off = t.shape("/contacts/offsets");
         if (!off.empty() && off[0] >= 2) {
           const std::vector<std::int64_t> o = t.read_i64_rows("/contacts/offsets", 0, 2);
           if (o[0] >= 0 && o[1] >= o[0])
             for (const char* d : {"/contacts/pair", "/contacts/normal", "/contacts/depth", "/contacts/point"})
               if (t.has_dataset(d)) (void)t.read_f64_rows(d, o[0], o[1] - o[0]);
         }
       }
     }},
};

std::string scratch_path() {
  const char* dir = access("/dev/shm", W_OK) == 0 ? "/dev/shm" : "/tmp";
  return std::string(dir) + "/octocd-fuzz-trace-" + std::to_string(getpid()) + ".h5";
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string path = scratch_path();
  {
    std::ofstream out(path, std::ios::binary | std::ios::trunc);
    out.write(reinterpret_cast<const char*>(data), static_cast<std::streamsize>(size));
  }
  for (const Reader& r : kReaders) {
    try {
      r.read(path);
    } catch (const octocd::RuntimeError&) {
    } catch (const octocd::InputError&) {
    }
  }
  std::remove(path.c_str());
  std::remove((path + ".xmf").c_str());
  return 0;
}
