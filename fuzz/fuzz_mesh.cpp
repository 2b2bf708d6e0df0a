// libFuzzer target: the mesh loader (issues 10, 57): OFF, OBJ, PLY (ASCII and binary, both
// byte orders) and STL (ASCII and binary) through assimp and octocd's checks (load_mesh),
// then what a scene does with a mesh (normalise, scale, per-mesh octree at depth auto,
// mean edge length). The format is picked from the content as a user's file name would:
// "ply" first -> .ply, "OFF" in the first bytes -> .off, "solid" first or the exact size of
// a binary STL (84 + 50 x the count at byte 80) -> .stl, else .obj. Bad input must end in
// InputError; anything else is a finding. The replay build prints what each input loaded.
#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <fstream>
#include <string>

#include "octocd/error.hpp"
#include "octocd/mesh.hpp"
#include "octocd/mesh_octree.hpp"

namespace {

/// A file per extension in /dev/shm (or /tmp), reused for every input of this process.
std::string scratch_path(const char* ext) {
  const char* dir = access("/dev/shm", W_OK) == 0 ? "/dev/shm" : "/tmp";
  return std::string(dir) + "/octocd-fuzz-mesh-" + std::to_string(getpid()) + ext;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  const auto binary_stl = [&] {
    if (text.size() < 84) return false;
    const auto* b = reinterpret_cast<const unsigned char*>(text.data()) + 80;
    const std::uint64_t count = b[0] | (b[1] << 8) | (b[2] << 16) | (std::uint64_t(b[3]) << 24);
    return 84 + 50 * count == text.size();
  };
  const char* ext = text.compare(0, 3, "ply") == 0                  ? ".ply"
                    : text.find("OFF") < 8                          ? ".off"
                    : text.compare(0, 5, "solid") == 0 || binary_stl() ? ".stl"
                                                                    : ".obj";
  const std::string path = scratch_path(ext);
  {
    std::ofstream out(path, std::ios::binary | std::ios::trunc);
    out.write(text.data(), static_cast<std::streamsize>(text.size()));
  }
  try {
    octocd::Mesh mesh = octocd::load_mesh(path);
    octocd::normalize_mesh(mesh);
    octocd::scale_mesh(mesh, 0.2f);
    const int depth = octocd::auto_mesh_octree_depth(mesh);
    const octocd::MeshOctree tree = octocd::build_mesh_octree(mesh, depth);
    (void)tree;
    (void)octocd::mean_edge_length(mesh);
    std::printf("  %s: %zu vertices, %zu triangles\n", ext, mesh.vertices.size(), mesh.triangles.size());
  } catch (const octocd::InputError&) {
  }
  std::remove(path.c_str());
  return 0;
}
