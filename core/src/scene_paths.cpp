/// \file scene_paths.cpp
/// Where a scene's files are (docs/scenes.md, "Mesh resolution"): the data dir of the
/// dataset meshes and the resolution of a group's mesh name to a file.

#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <vector>

#include "octocd/error.hpp"
#include "octocd/scene.hpp"
#include "octocd/shared_files.hpp"
#include "scene_detail.hpp"

namespace octocd {

namespace fs = std::filesystem;

namespace scene_detail {

fs::path scene_folder(const std::string& origin) {
  if (origin.empty()) return {};
  std::error_code ec;
  fs::path p = fs::absolute(fs::path(origin), ec);
  if (ec) p = fs::path(origin);
  return p.lexically_normal().parent_path();
}

}  // namespace scene_detail

namespace {

using namespace scene_detail;

bool is_directory(const fs::path& p) {
  std::error_code ec;
  return fs::is_directory(p, ec);
}

const char* const kDatasetNames[] = {"bunny", "armadillo", "dragon", "asian-dragon"};

/// "a folder", "a FIFO", ... for a path's type in messages (the trace readers' words).
std::string file_type_text(fs::file_type t) {
  switch (t) {
    case fs::file_type::directory: return "a folder";
    case fs::file_type::fifo: return "a FIFO";
    case fs::file_type::character:
    case fs::file_type::block: return "a device";
    case fs::file_type::socket: return "a socket";
    default: return "not a plain file";
  }
}

/// Whether `p` (symbolic links resolved as far as it exists) lies inside folder `root`.
bool lies_inside(const fs::path& p, const fs::path& root) {
  if (root.empty()) return false;
  std::error_code ec;
  const fs::path a = fs::weakly_canonical(fs::absolute(p, ec), ec);
  if (ec) return false;
  const fs::path r = fs::weakly_canonical(fs::absolute(root, ec), ec);
  if (ec) return false;
  auto ai = a.begin();
  for (auto ri = r.begin(); ri != r.end(); ++ri, ++ai) {
    if (ri->empty()) continue;  // a trailing separator
    if (ai == a.end() || *ai != *ri) return false;
  }
  return true;
}

/// True when `mesh` is spelled as a file (has a folder or an extension), not a dataset name.
bool looks_like_file(const std::string& mesh) {
  const fs::path m(mesh);
  return m.has_parent_path() || m.has_extension();
}

}  // namespace

std::vector<std::string> default_data_dirs(const std::string& origin) {
  if (const char* env = std::getenv("OCTOCD_DATA_DIR"); env != nullptr && *env != '\0') return {env};
  std::vector<std::string> dirs;
  const fs::path folder = scene_folder(origin);
  if (!folder.empty()) dirs.push_back((folder / ".." / "cache").lexically_normal().string());
  const std::string built = (fs::path(shared_dir()) / "datasets" / "cache").lexically_normal().string();
  if (std::find(dirs.begin(), dirs.end(), built) == dirs.end()) dirs.push_back(built);
  return dirs;
}

namespace scene_detail {

std::string choose_data_dir(const std::string& origin, const std::string& data_dir) {
  if (!data_dir.empty()) return data_dir;
  const std::vector<std::string> dirs = default_data_dirs(origin);
  for (const std::string& d : dirs)
    if (is_directory(d)) return d;
  return dirs.front();
}

}  // namespace scene_detail

std::string resolve_mesh_path(const Scene& scene, const std::string& mesh, const std::string& key) {
  const Ctx c{scene.path.empty() ? std::string("<scene>") : scene.path};
  const bool file_like = looks_like_file(mesh);
  std::vector<fs::path> searched;
  const fs::path m(mesh);
  const fs::path base = scene.embedded ? fs::path(scene.mesh_dir) : scene_folder(scene.path);
  searched.push_back(m.is_absolute() ? m : base / m);
  // A dataset name is looked up in the data dir; a file path (with a folder or an
  // extension) is not: "meshes/bunny.obj" must not become ".../bunny.obj.obj".
  if (!scene.data_dir.empty() && !file_like)
    for (const char* ext : {".obj", ".off", ".ply"}) searched.push_back(fs::path(scene.data_dir) / (mesh + ext));
  if (scene.embedded) {
    // A scene found inside a trace names files for whoever wrote the trace: only those
    // inside --mesh-dir or the data dir are looked at (symbolic links resolved), so the
    // trace cannot make octocd read, stat or draw any other file.
    std::vector<fs::path> inside;
    for (const fs::path& p : searched)
      if (lies_inside(p, scene.mesh_dir) || lies_inside(p, scene.data_dir)) inside.push_back(p);
    if (inside.empty())
      c.fail(key, "mesh \"" + mesh + "\" named by the scene inside the trace lies outside --mesh-dir " +
                      scene.mesh_dir + " and the data dir " + scene.data_dir,
             "a dataset name (found in the data dir: --data-dir, $OCTOCD_DATA_DIR), or a mesh file inside the folder "
             "given by --mesh-dir DIR (default: the trace's folder), named relative to it");
    searched = std::move(inside);
  }
  // stat only, never open here: opening a FIFO blocks, a device never ends. The first
  // regular file wins; when there is none, a place that exists as something else (a
  // folder, FIFO, device, socket) is named with its type rather than "not found".
  for (const auto& p : searched) {
    std::error_code ec;
    if (!fs::is_regular_file(p, ec)) continue;
    const auto size = fs::file_size(p, ec);
    if (ec || size == 0)
      c.fail(key, "mesh file " + p.string() + " is empty (0 bytes)",
             "a non-empty mesh file (for datasets, run datasets/fetch.sh again)");
    return p.string();
  }
  for (const auto& p : searched) {
    std::error_code ec;
    const fs::file_status st = fs::status(p, ec);
    if (st.type() == fs::file_type::not_found) continue;
    if (st.type() == fs::file_type::none || ec)
      c.fail(key, "mesh path " + p.string() + " cannot be examined: " + ec.message(),
             "a readable regular mesh file");
    c.fail(key, "mesh path " + p.string() + ": not a regular file (" + file_type_text(st.type()) + ")",
           "a regular mesh file (.obj, .off, .ply, .stl), absolute or relative to the scene file's folder; or "
           "a dataset name (bunny, armadillo, dragon, asian-dragon)");
  }
  std::string list;
  for (const auto& p : searched) list += (list.empty() ? "" : ", ") + p.string();
  if (file_like)
    c.fail(key, "mesh file \"" + mesh + "\" not found (searched: " + list + ")",
           "an existing mesh file, absolute or relative to the scene file's folder; or a dataset "
           "name without extension (bunny, armadillo, dragon, asian-dragon)");
  const bool dataset = std::find(std::begin(kDatasetNames), std::end(kDatasetNames), mesh) != std::end(kDatasetNames);
  std::string advice;
  if (!is_directory(scene.data_dir))
    advice = "the data dir " + scene.data_dir + " does not exist: run datasets/fetch.sh, or give " +
             "--data-dir / $OCTOCD_DATA_DIR";
  else if (dataset)
    advice = "the data dir " + scene.data_dir + " lacks it: run datasets/fetch.sh, or give --data-dir / " +
             "$OCTOCD_DATA_DIR";
  else
    advice = "not a shipped dataset (bunny, armadillo, dragon, asian-dragon) and no such file";
  c.fail(key, "mesh \"" + mesh + "\" not found (searched: " + list + "); " + advice,
         "an existing mesh file (absolute or relative to the scene's folder), or a dataset name with "
         "NAME.obj|.off|.ply in the data dir (--data-dir, $OCTOCD_DATA_DIR, else <scene folder>/../cache, "
         "else the datasets/cache of octocd's shared files: PREFIX/share/octocd when installed, else the source "
         "tree)");
}

}  // namespace octocd
