#pragma once
/// \file mesh.hpp
/// Triangle meshes: loading through assimp, welding, recentring and normalising
/// (design.md section 3), and procedural shapes for tests (boxes, icospheres).

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "octocd/math.hpp"

namespace octocd {

/// Limits checked when a mesh is loaded (docs/scenes.md, "Limits"): larger files or
/// counts are an InputError (exit code 2), raised before assimp parses the file where the
/// file says its counts (OFF and PLY headers), after it for OBJ and the rest.
namespace limits {
/// Largest mesh file (bytes): 1 GiB; assimp parses about 100 MB/s, so 10 s at most.
constexpr std::uintmax_t kMaxMeshFileBytes = 1ull << 30;
/// Most vertices of a mesh file (as stored, before welding): 10^7 (the datasets have at
/// most 1.6 x 10^5; the paper's largest mesh 3.6 x 10^5).
constexpr std::uint64_t kMaxMeshVertices = 10000000;
/// Most faces (polygons) of a mesh file: 2 x 10^7.
constexpr std::uint64_t kMaxMeshFaces = 20000000;
/// Most corners of one face (polygon): 1024. assimp triangulates a polygon in time
/// quadratic in its corners (3 x 10^4 corners took 2.2 s, 10^7 would take days), so a
/// larger face is refused before triangulation; with it, loading stays linear in the file.
constexpr std::uint64_t kMaxFaceCorners = 1024;
/// Most subdivisions of an icosphere (scenes' `icosphere.subdivisions`, make_icosphere):
/// 6, i.e. 81,920 triangles and 40,962 vertices, whose surface lies within 7.2 x 10^-5 r
/// of the sphere. One more quadruples the triangles (327,680; the largest dataset mesh's
/// size) for a surface 4x closer, and made the midphase of overlapping icospheres 17x
/// slower (64 overlapping bodies, 3 frames: 2.2 s at 6, 38 s at 7).
constexpr int kMaxIcosphereSubdivisions = 6;
}  // namespace limits

/// An indexed triangle mesh in its local frame (metres). Owns its arrays.
struct Mesh {
  std::string name;                                  ///< dataset or file name
  std::vector<Vec3> vertices;                        ///< welded, unique positions
  std::vector<std::array<std::uint32_t, 3>> triangles;  ///< indices into `vertices`
};

/// Loads a mesh file and welds it. Formats (by extension, case-insensitive): OBJ, OFF,
/// PLY, STL, read with assimp; any other extension (glTF, FBX, ...) is an InputError
/// before assimp is asked (docs/scenes.md, "Mesh formats").
/// All meshes of the file's scene are merged (node transforms are not applied); polygons
/// are triangulated, points and lines dropped. `name` is the file's stem ("bunny").
/// Does not recentre or scale (see `normalize_mesh`).
/// Messages read "mesh file '<path>': <problem>; allowed: <what>" (build_model prefixes
/// the scene file and key). Throws InputError naming `path` when the file is missing,
/// unreadable, of another format, empty (no
/// vertices or no triangles) or holds a non-finite vertex (naming its index in assimp's
/// load order, which for OFF/OBJ follows the face corners, and its value).
/// For OFF files the face count in the header is checked against what was loaded
/// (assimp's OFF reader drops faces after comment lines): a mismatch is an InputError;
/// every OFF face index must be below the header's vertex count (assimp clamps it).
/// Files over limits::kMaxMeshFileBytes, or with more than limits::kMaxMeshVertices
/// vertices or limits::kMaxMeshFaces faces, are an InputError naming the limit.
Mesh load_mesh(const std::string& path);

/// Merges coincident vertices (exactly equal positions; -0 equals +0) and drops triangles
/// that become degenerate (two equal indices). Keeps first-occurrence order, so it is
/// deterministic. Unreferenced vertices are kept.
void weld_mesh(Mesh& mesh);

/// design.md section 3: moves the mesh so the centre of its local AABB is the origin, then scales it
/// uniformly so the longest side of that AABB is 1 m. Throws InputError when the mesh
/// is empty or flat in all axes (longest side 0).
void normalize_mesh(Mesh& mesh);

/// Multiplies every vertex by s. Throws InputError unless s is finite and > 0.
void scale_mesh(Mesh& mesh, float s);

/// Local AABB of the vertices. Throws InputError for a mesh without vertices.
Aabb mesh_bounds(const Mesh& mesh);

/// Mean length of the mesh's unique edges (m): the paper's mesh resolution that sets
/// theta `auto` (design.md section 6). 0 for a mesh without triangles.
float mean_edge_length(const Mesh& mesh);

/// A closed box mesh centred on the origin with the given half extents (m): 8 vertices,
/// 12 triangles, each face split `subdivisions` times 1-to-4 (so faces carry vertices
/// inside, useful for vertex-proximity tests). Closed, wound counter-clockwise seen from
/// outside. Throws InputError unless subdivisions is in [0, 8] and every half extent is
/// finite and > 0.
Mesh make_box_mesh(Vec3 half_extents, int subdivisions = 0);

/// An icosphere of the given radius (m) centred on the origin: an icosahedron split
/// 1-to-4 `subdivisions` times (12, 42, 162, 642, ... vertices; new vertices projected
/// onto the sphere). Closed, wound counter-clockwise seen from outside. Throws InputError
/// unless subdivisions is in [0, limits::kMaxIcosphereSubdivisions] (6) and radius is
/// finite and > 0.
Mesh make_icosphere(float radius, int subdivisions);

}  // namespace octocd
