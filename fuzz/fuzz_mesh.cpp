// libFuzzer target: the mesh loader (issue 10): OFF, OBJ and PLY through assimp and
// octocd's checks (load_mesh), then what a scene does with a mesh (normalise, scale,
// per-mesh octree at depth auto, mean edge length). The format is picked from the
// content as a user's file name would: "OFF" -> .off, "ply" -> .ply, else .obj. Bad
// input must end in InputError; anything else is a finding.
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
  const char* ext = text.compare(0, 3, "ply") == 0 ? ".ply"
                    : text.find("OFF") < 8        ? ".off"
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
  } catch (const octocd::InputError&) {
  }
  std::remove(path.c_str());
  return 0;
}
