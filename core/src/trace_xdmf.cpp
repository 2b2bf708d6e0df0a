// The XDMF 3 sidecar of a trace (write_xdmf_sidecar; docs/trace-format.md, "ParaView"):
// the recorded states as a temporal collection of vertex grids whose arrays are HDF5
// hyperslabs of the trace itself. The writer is in trace_writer.cpp.
#include <hdf5.h>

#include <cstdint>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include <fmt/format.h>

#include "octocd/atomic_file.hpp"
#include "octocd/error.hpp"
#include "octocd/trace.hpp"
#include "octocd/xml.hpp"
#include "hdf5_handle.hpp"
#include "trace_detail.hpp"

namespace octocd {

namespace {

// Writes TRACE.xmf beside the trace `h5` whose summary is `sum`; returns its path.
std::string write_xdmf(const detail::Hdf5Reader& h5, const TraceSummary& sum) {
  const std::string& path = h5.path();
  const double dt = h5.number_attribute("dt");
  const auto rows = static_cast<std::size_t>(sum.state_rows);
  std::vector<std::int64_t> frames(rows);
  if (rows > 0) h5.read_rows(h5.open_numeric("/states/frame", 1), 0, rows, H5T_NATIVE_INT64, frames.data());
  const std::int64_t disk_rows = detail::dataset_rows(h5, "/states/position");
  const std::size_t nb = static_cast<std::size_t>(sum.bodies);
  // The trace's file name, XML-escaped.
  const std::string name = xml_escape(std::filesystem::path(path).filename().string());
  // /bodies/half_extents and /bodies/group_id appeared after the first traces: older
  // files get the sidecar without them.
  const bool has_half = h5.exists("/bodies/half_extents");
  const bool has_group = h5.exists("/bodies/group_id");
  const std::string xmf = path + ".xmf";

  std::ostringstream o;
  o.precision(15);
  const std::string all = std::to_string(disk_rows) + " " + std::to_string(nb) + " 3";
  // Row r of a (rows x bodies x 3) dataset as an (bodies x 3) item, in XDMF 3's HDF5
  // hyperslab notation "file:/dataset|start:stride:count:dataset dimensions" (one value per
  // dimension in each group). ParaView's Xdmf3 readers read it; they do not read the older
  // ItemType="HyperSlab" wrapper (its array stays untyped: "unrecognized array type [None]").
  auto slab = [&](std::size_t r, const char* dataset) {
    o << "          <DataItem Dimensions=\"" << nb << " 3\" NumberType=\"Float\" Precision=\"4\" Format=\"HDF\">"
      << name << ":" << dataset << "|" << r << " 0 0:1 1 1:1 " << nb << " 3:" << all << "</DataItem>\n";
  };
  o << "<?xml version=\"1.0\" ?>\n"
    << "<!DOCTYPE Xdmf SYSTEM \"Xdmf.dtd\" []>\n"
    << "<!-- octocd trace sidecar: open in ParaView with the XDMF Reader (Xdmf3) -->\n"
    << "<Xdmf Version=\"3.0\">\n  <Domain>\n"
    << "    <Grid Name=\"states\" GridType=\"Collection\" CollectionType=\"Temporal\">\n";
  for (std::size_t r = 0; r < rows; ++r) {
    o << "      <Grid Name=\"frame " << frames[r] << "\" GridType=\"Uniform\">\n"
      // Shortest text that reads back as the same float32 time (dt is float32 in octocd).
      << "        <Time Value=\"" << fmt::format("{}", static_cast<float>(static_cast<double>(frames[r]) * dt))
      << "\"/>\n"
      << "        <Topology TopologyType=\"Polyvertex\" NumberOfElements=\"" << nb
      << "\" NodesPerElement=\"1\"/>\n"
      << "        <Geometry GeometryType=\"XYZ\">\n";
    slab(r, "/states/position");
    o << "        </Geometry>\n"
      << "        <Attribute Name=\"velocity\" AttributeType=\"Vector\" Center=\"Node\">\n";
    slab(r, "/states/velocity");
    o << "        </Attribute>\n"
      << "        <Attribute Name=\"shape_id\" AttributeType=\"Scalar\" Center=\"Node\">\n"
      << "          <DataItem Dimensions=\"" << nb
      << "\" NumberType=\"UInt\" Precision=\"4\" Format=\"HDF\">" << name
      << ":/bodies/shape_id</DataItem>\n"
      << "        </Attribute>\n"
      << "        <Attribute Name=\"inverse_mass\" AttributeType=\"Scalar\" Center=\"Node\">\n"
      << "          <DataItem Dimensions=\"" << nb
      << "\" NumberType=\"Float\" Precision=\"4\" Format=\"HDF\">" << name
      << ":/bodies/inverse_mass</DataItem>\n"
      << "        </Attribute>\n";
    if (has_half)
      o << "        <Attribute Name=\"half_extents\" AttributeType=\"Vector\" Center=\"Node\">\n"
        << "          <DataItem Dimensions=\"" << nb
        << " 3\" NumberType=\"Float\" Precision=\"4\" Format=\"HDF\">" << name
        << ":/bodies/half_extents</DataItem>\n"
        << "        </Attribute>\n";
    if (has_group)
      o << "        <Attribute Name=\"group_id\" AttributeType=\"Scalar\" Center=\"Node\">\n"
        << "          <DataItem Dimensions=\"" << nb
        << "\" NumberType=\"Int\" Precision=\"4\" Format=\"HDF\">" << name
        << ":/bodies/group_id</DataItem>\n"
        << "        </Attribute>\n";
    o << "      </Grid>\n";
  }
  o << "    </Grid>\n  </Domain>\n</Xdmf>\n";

  try {  // beside it under an unpredictable name, then renamed (atomic_file.hpp)
    write_file_atomically(xmf, o.str(), "XDMF sidecar");
  } catch (const std::runtime_error& e) {
    throw RuntimeError("trace '" + path + "': " + e.what());
  }
  return xmf;
}

}  // namespace

std::string write_xdmf_sidecar(const std::string& trace_path) {
  const std::string& path = trace_path;
  try {
    const detail::Hdf5Reader h5(path, "an octocd trace");
    return write_xdmf(h5, detail::trace_summary_of(h5));  // checks that it is a trace
  } catch (const InputError& e) {
    throw RuntimeError(std::string("trace ") + e.what());
  }
}

}  // namespace octocd
