/// \file mesh.cpp
/// Mesh loading (assimp), welding, normalisation (design.md section 3) and procedural shapes.

#include "octocd/mesh.hpp"

#include <assimp/DefaultIOSystem.h>
#include <assimp/Importer.hpp>
#include <assimp/postprocess.h>
#include <assimp/scene.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <sstream>
#include <unordered_map>
#include <utility>

#include "octocd/error.hpp"

namespace octocd {
namespace {

namespace fs = std::filesystem;

/// assimp's file access for one mesh file: the file itself opens, every other name (an
/// OBJ's `mtllib` material file, a texture, a file named by any importer) is absent. A
/// mesh file is read as geometry alone: the files it names could be anywhere (/etc/...,
/// a FIFO that blocks the open forever, /dev/zero), and octocd uses no material.
class OnlyThisFile : public Assimp::DefaultIOSystem {
 public:
  explicit OnlyThisFile(std::string path) : path_(std::move(path)) {}
  bool Exists(const char* file) const override { return file != nullptr && path_ == file && DefaultIOSystem::Exists(file); }
  Assimp::IOStream* Open(const char* file, const char* mode) override {
    if (file == nullptr || path_ != file || mode == nullptr || std::strchr(mode, 'w') != nullptr) return nullptr;
    return DefaultIOSystem::Open(file, mode);
  }

 private:
  std::string path_;
};

using Tri = std::array<std::uint32_t, 3>;

/// The mesh formats octocd loads and tests (assimp reads them); others are rejected up
/// front rather than failing inside assimp (glTF, for one, loads no usable mesh).
constexpr const char* kFormats = "a triangle mesh file in OBJ, OFF, PLY or STL format";

/// Throws "mesh file '<path>': <problem>; allowed: <allowed>" (the scene key is added by
/// build_model).
[[noreturn]] void fail(const std::string& path, const std::string& problem,
                       const std::string& allowed = kFormats) {
  throw InputError("mesh file '" + path + "': " + problem + "; allowed: " + allowed);
}

std::string lower(std::string s) {
  for (char& c : s) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

/// Fails when a mesh declares or holds more vertices or faces than the limits allow:
/// "<says> N vertices (expected at most M)" (e.g. says = "the OFF header declares").
void check_mesh_counts(const std::string& path, const std::string& says, std::uint64_t vertices,
                       std::uint64_t faces) {
  if (vertices > limits::kMaxMeshVertices)
    fail(path, says + " " + std::to_string(vertices) + " vertices (expected at most " +
                   std::to_string(limits::kMaxMeshVertices) + ")");
  if (faces > limits::kMaxMeshFaces)
    fail(path, says + " " + std::to_string(faces) + " faces (expected at most " +
                   std::to_string(limits::kMaxMeshFaces) + ")");
}

/// A non-negative integer token of an OFF file, or a failure naming `what`.
std::uint64_t off_count(const std::string& path, const std::string& token, const std::string& what) {
  try {
    std::size_t used = 0;
    if (token.empty() || token[0] == '-') throw std::invalid_argument("negative");
    const unsigned long long n = std::stoull(token, &used);
    if (used != token.size()) throw std::invalid_argument("trailing characters");
    return n;
  } catch (const std::exception&) {
    fail(path, "bad OFF " + what + " '" + token + "'", "a non-negative integer");
  }
}

/// Reads the next line holding data (blank lines and '#' comments skipped) into `tokens`;
/// false at the end of the file.
bool off_data_line(std::istream& in, std::string& line, std::vector<std::string>& tokens) {
  while (std::getline(in, line)) {
    const auto hash = line.find('#');
    if (hash != std::string::npos) line.erase(hash);
    tokens.clear();
    std::size_t i = 0;
    while (i < line.size()) {
      while (i < line.size() && std::isspace(static_cast<unsigned char>(line[i]))) ++i;
      std::size_t e = i;
      while (e < line.size() && !std::isspace(static_cast<unsigned char>(line[e]))) ++e;
      if (e > i) tokens.emplace_back(line, i, e - i);
      i = e;
    }
    if (!tokens.empty()) return true;
  }
  return false;
}

/// An OFF file's header counts, checked against the limits before assimp parses the
/// file, and (when `scan_faces`) every face's indices checked against the vertex count:
/// assimp's OFF reader clamps an index past the vertex count to the last vertex instead
/// of failing. Returns the header's face count.
std::uint64_t check_off(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) fail(path, "cannot open (expected a readable file)");
  std::vector<std::string> header, tokens;
  std::string line;
  while (header.size() < 3 && off_data_line(in, line, tokens))
    for (const std::string& t : tokens)
      if (header.size() < 3) header.push_back(t);
  const std::string kw = header.empty() ? std::string() : header[0];
  if (kw.size() < 3 || kw.compare(kw.size() - 3, 3, "OFF") != 0) {
    fail(path, "bad OFF header '" + kw.substr(0, 40) + "' (expected 'OFF' then vertex and face counts)");
  }
  if (header.size() < 3) fail(path, "truncated OFF header (expected vertex and face counts)");
  const std::uint64_t nv = off_count(path, header[1], "vertex count");
  const std::uint64_t nf = off_count(path, header[2], "face count");
  check_mesh_counts(path, "the OFF header declares", nv, nf);
  // The header line may hold the counts and the edge count; vertices start on the next line.
  // Vertex lines hold x y z (then optional colour or normal); assimp 5.2 reads past a
  // short line and crashes (found by fuzz_mesh), so each is checked here.
  for (std::uint64_t v = 0; v < nv; ++v) {
    if (!off_data_line(in, line, tokens))
      fail(path, "ends after " + std::to_string(v) + " of " + std::to_string(nv) + " vertices");
    bool numbers = tokens.size() >= 3;
    for (std::size_t c = 0; c < 3 && numbers; ++c) {
      char* end = nullptr;
      (void)std::strtod(tokens[c].c_str(), &end);
      numbers = end != tokens[c].c_str() && *end == '\0';
    }
    if (!numbers)
      fail(path, "vertex " + std::to_string(v) + " is not three numbers x y z (line '" + line.substr(0, 60) + "')");
  }
  for (std::uint64_t f = 0; f < nf; ++f) {
    if (!off_data_line(in, line, tokens)) break;  // too few faces: the count check reports it
    const std::uint64_t k = off_count(path, tokens[0], "corner count of face " + std::to_string(f));
    if (k < 3)
      fail(path, "face " + std::to_string(f) + " has " + std::to_string(k) + " corners (expected at least 3)");
    if (k >= tokens.size())
      fail(path, "face " + std::to_string(f) + " lists " + std::to_string(tokens.size() - 1) + " of its " +
                     std::to_string(k) + " corners (expected one line per face)");
    for (std::uint64_t c = 1; c <= k; ++c) {
      const std::uint64_t idx = off_count(path, tokens[c], "index of face " + std::to_string(f));
      if (idx >= nv)
        fail(path, "face " + std::to_string(f) + " uses vertex " + std::to_string(idx) + " but the file has " +
                       std::to_string(nv) + " vertices (expected indices in [0, " + std::to_string(nv) + "))");
    }
  }
  return nf;
}

/// Bytes of a PLY scalar type ("float", "uchar", "int32", ...); 0 for an unknown name.
std::size_t ply_type_size(const std::string& t) {
  if (t == "char" || t == "uchar" || t == "int8" || t == "uint8") return 1;
  if (t == "short" || t == "ushort" || t == "int16" || t == "uint16") return 2;
  if (t == "int" || t == "uint" || t == "int32" || t == "uint32" || t == "float" || t == "float32") return 4;
  if (t == "double" || t == "float64") return 8;
  return 0;
}

/// One property of a PLY element: a scalar, or a list (a count, then that many items).
struct PlyProperty {
  bool list = false;
  std::size_t count_size = 0, item_size = 0;  ///< bytes (binary files)
};
struct PlyElement {
  std::string name;
  std::uint64_t count = 0;
  std::vector<PlyProperty> properties;
};

/// The list lengths of a PLY body (every element with a list property, e.g. a face's
/// vertex_indices), each checked against limits::kMaxFaceCorners before assimp reads the
/// file: assimp 5.2 allocates a list's declared length before reading it (a 237-byte
/// file whose ASCII face declared 4 x 10^18 corners asked for 16 GB; found by fuzz_mesh).
/// The walk stops quietly where the body ends or does not parse (assimp reports that).
void check_ply_lists(const std::string& path, std::istream& in, const std::string& format,
                     const std::vector<PlyElement>& elements) {
  const auto too_many = [&](const std::string& element, std::uint64_t i, const std::string& what) {
    fail(path, "PLY " + element + " " + std::to_string(i) + " declares a list of " + what.substr(0, 40) +
                   " items (expected at most " + std::to_string(limits::kMaxFaceCorners) + " corners)");
  };
  if (format == "ascii") {
    // One element a line, exactly its properties' values, every value a number: a short or
    // long line, or a word, puts assimp's reader out of step with the header, and the
    // number it then takes for a list length is arbitrary (the fuzzer's file had "3 0 F").
    std::string line;
    for (const PlyElement& e : elements) {
      for (std::uint64_t i = 0; i < e.count; ++i) {
        if (!std::getline(in, line)) return;  // a short body: assimp's error
        std::istringstream ls(line);
        std::string tok;
        const auto value = [&](double& v) {
          if (!(ls >> tok))
            fail(path, "PLY " + e.name + " " + std::to_string(i) + ": its line ends before its last property " +
                           "(expected one " + e.name + " a line with every property's values)");
          std::size_t used = 0;
          try {
            v = std::stod(tok, &used);
          } catch (const std::exception&) {
            used = 0;
          }
          if (used != tok.size())
            fail(path, "PLY " + e.name + " " + std::to_string(i) + ": '" + tok.substr(0, 40) +
                           "' is not a number (expected numbers only in an ASCII PLY body)");
        };
        for (const PlyProperty& p : e.properties) {
          double c = 0;
          value(c);
          if (!p.list) continue;
          if (!(c >= 0 && c <= static_cast<double>(limits::kMaxFaceCorners))) too_many(e.name, i, tok);
          for (std::uint64_t k = 0; k < static_cast<std::uint64_t>(c); ++k) {
            double item = 0;
            value(item);
          }
        }
        if (ls >> tok)
          fail(path, "PLY " + e.name + " " + std::to_string(i) + ": its line has values past its last property " +
                         "(expected one " + e.name + " a line with every property's values)");
      }
    }
    return;
  }
  const bool little = format == "binary_little_endian";
  const auto read_uint = [&](std::size_t bytes, std::uint64_t& v) {
    unsigned char b[8] = {};
    if (!in.read(reinterpret_cast<char*>(b), static_cast<std::streamsize>(bytes))) return false;
    v = 0;
    for (std::size_t k = 0; k < bytes; ++k) v |= static_cast<std::uint64_t>(b[little ? k : bytes - 1 - k]) << (8 * k);
    return true;
  };
  for (const PlyElement& e : elements) {
    std::size_t fixed = 0;
    bool lists = false;
    for (const PlyProperty& p : e.properties) {
      if (p.list) lists = true;
      else fixed += p.item_size;
      if ((p.list ? p.count_size : p.item_size) == 0) return;  // an unknown type: assimp's error
    }
    if (!lists) {
      if (fixed == 0 || e.count > (std::uint64_t(1) << 40) / fixed) return;
      in.seekg(static_cast<std::streamoff>(e.count * fixed), std::ios::cur);
      continue;
    }
    for (std::uint64_t i = 0; i < e.count; ++i)
      for (const PlyProperty& p : e.properties) {
        if (!p.list) {
          in.seekg(static_cast<std::streamoff>(p.item_size), std::ios::cur);
          continue;
        }
        std::uint64_t c = 0;
        if (!read_uint(p.count_size, c)) return;
        // A signed count type reads as a huge unsigned value when negative: refused too.
        if (c > limits::kMaxFaceCorners) too_many(e.name, i, std::to_string(c));
        in.seekg(static_cast<std::streamoff>(c * p.item_size), std::ios::cur);
      }
    if (!in) return;
  }
}

/// A PLY file's vertex and face counts from its header ("element vertex N", "element
/// face N"), checked against the limits before assimp parses the file, then the lengths
/// of its lists (check_ply_lists). Other files
/// (OBJ has no header) are checked after parsing. A header without `end_header` in its
/// first 1000 lines is rejected: assimp 5.2's PLY reader never returns on one (found by
/// fuzz_mesh).
/// The body of a PLY file holds every element its header declares: each element takes at
/// least its fixed properties' bytes plus each list's count (binary) or two characters per
/// property, a digit and a separator (ASCII). A header declaring more than the bytes after
/// it can hold (a 166-byte file declaring 9,999,999 vertices) is refused before assimp
/// allocates the declared arrays.
void check_ply_body_size(const std::string& path, std::istream& in, const std::string& format,
                         const std::vector<PlyElement>& elements) {
  const std::streampos here = in.tellg();
  in.seekg(0, std::ios::end);
  const std::streampos end = in.tellg();
  in.seekg(here);
  if (here < 0 || end < here) return;
  const auto body = static_cast<std::uint64_t>(end - here);
  std::uint64_t need = 0;
  for (const PlyElement& e : elements) {
    std::uint64_t least = 0;  // bytes of one element at the least
    for (const PlyProperty& p : e.properties)
      least += format == "ascii" ? 2 : (p.list ? p.count_size : p.item_size);
    if (least == 0) continue;
    if (e.count > body / least || need > body - e.count * least)
      fail(path, "the PLY header declares " + std::to_string(e.count) + " " + e.name + " elements of at least " +
                     std::to_string(least) + " bytes each, but only " + std::to_string(body) +
                     " bytes follow the header (expected a body holding every declared element)");
    need += e.count * least;
  }
}

void check_ply_header(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) fail(path, "cannot open (expected a readable file)");
  std::string line, format;
  std::vector<PlyElement> elements;
  for (int n = 0; n < 1000 && std::getline(in, line); ++n) {
    while (!line.empty() && (line.back() == '\r' || line.back() == ' ' || line.back() == '\t')) line.pop_back();
    if (line == "end_header") {
      check_ply_body_size(path, in, format, elements);
      check_ply_lists(path, in, format, elements);
      return;
    }
    std::istringstream ls(line);
    std::string kw, element, count;
    ls >> kw >> element >> count;
    // The header grammar, strictly: assimp 5.2 loops forever on some malformed headers
    // (found by fuzz_mesh), so anything else is rejected here.
    const bool known = n == 0 ? line == "ply"
                              : kw == "format" || kw == "comment" || kw == "obj_info" ||
                                    kw == "element" || kw == "property";
    if (!known)
      fail(path, "PLY header line " + std::to_string(n + 1) + " is not ply, format, comment, obj_info, "
                     "element, property or end_header (expected a PLY header)");
    if (kw == "format" && element != "ascii" && element != "binary_little_endian" && element != "binary_big_endian")
      fail(path, "PLY format '" + element.substr(0, 40) + "' (expected ascii, binary_little_endian or binary_big_endian)");
    if (kw == "format") format = element;
    if (kw == "property" && !elements.empty()) {
      // "property TYPE NAME" or "property list COUNT_TYPE ITEM_TYPE NAME"
      PlyProperty p;
      p.list = element == "list";
      p.count_size = p.list ? ply_type_size(count) : 0;
      std::string item;
      if (p.list) ls >> item;
      p.item_size = ply_type_size(p.list ? item : element);
      elements.back().properties.push_back(p);
    }
    if (kw != "element") continue;
    elements.push_back({element, 0, {}});
    try {
      elements.back().count = std::stoull(count);
    } catch (const std::exception&) {
      elements.back().count = 0;
    }
    const bool vertex = element == "vertex", face = element == "face";
    if (!vertex && !face) continue;
    unsigned long long c = 0;
    try {
      c = std::stoull(count);
    } catch (const std::exception&) {
      continue;  // assimp reports a malformed header
    }
    const std::uint64_t limit = vertex ? limits::kMaxMeshVertices : limits::kMaxMeshFaces;
    if (c > limit)
      fail(path, "the PLY header declares " + count + " " + element + "s (expected at most " +
                     std::to_string(limit) + ")");
  }
  fail(path, "PLY header without an end_header line in its first 1000 lines (expected a PLY file)");
}

std::uint64_t edge_key(std::uint32_t a, std::uint32_t b) {
  if (a > b) std::swap(a, b);
  return (static_cast<std::uint64_t>(a) << 32) | b;
}

/// Splits every triangle 1-to-4 by its edge midpoints (shared midpoints are shared
/// vertices), keeping the winding; `place` maps the two endpoints to the new vertex.
template <class Place>
void subdivide(Mesh& m, Place place) {
  std::unordered_map<std::uint64_t, std::uint32_t> mid;
  mid.reserve(m.triangles.size() * 2);
  std::vector<Tri> out;
  out.reserve(m.triangles.size() * 4);
  auto midpoint = [&](std::uint32_t a, std::uint32_t b) {
    const auto [it, inserted] =
        mid.try_emplace(edge_key(a, b), static_cast<std::uint32_t>(m.vertices.size()));
    if (inserted) m.vertices.push_back(place(m.vertices[a], m.vertices[b]));
    return it->second;
  };
  for (const Tri& t : m.triangles) {
    const std::uint32_t ab = midpoint(t[0], t[1]);
    const std::uint32_t bc = midpoint(t[1], t[2]);
    const std::uint32_t ca = midpoint(t[2], t[0]);
    out.push_back({t[0], ab, ca});
    out.push_back({ab, t[1], bc});
    out.push_back({ca, bc, t[2]});
    out.push_back({ab, bc, ca});
  }
  m.triangles = std::move(out);
}

/// For a convex shape around the origin: flips any triangle whose normal points inwards.
void orient_outwards(Mesh& m) {
  for (Tri& t : m.triangles) {
    const Vec3 a = m.vertices[t[0]], b = m.vertices[t[1]], c = m.vertices[t[2]];
    const Vec3 u = b - a, v = c - a;
    const Vec3 n{u.y * v.z - u.z * v.y, u.z * v.x - u.x * v.z, u.x * v.y - u.y * v.x};
    if (dot(n, a + b + c) < 0.0f) std::swap(t[1], t[2]);
  }
}

Vec3 midpoint_of(Vec3 a, Vec3 b) { return 0.5f * (a + b); }

}  // namespace

Mesh load_mesh(const std::string& path) {
  std::error_code ec;
  if (!fs::exists(path, ec)) fail(path, "not found", "an existing mesh file");
  if (!fs::is_regular_file(path, ec)) fail(path, "not a regular file");
  const std::uintmax_t bytes = fs::file_size(path, ec);
  if (bytes == 0 || ec) fail(path, "empty file");
  if (bytes > limits::kMaxMeshFileBytes)
    fail(path, "file is " + std::to_string(bytes) + " bytes", "at most " + std::to_string(limits::kMaxMeshFileBytes) +
                                                                 " bytes (1 GiB)");
  {
    std::ifstream probe(path, std::ios::binary);
    if (!probe) fail(path, "cannot open", "a readable file");
  }
  const std::string ext = lower(fs::path(path).extension().string());
  if (ext != ".obj" && ext != ".off" && ext != ".ply" && ext != ".stl")
    fail(path, "format '" + (ext.empty() ? std::string("(no extension)") : ext) + "' is not supported");
  std::uint64_t off_faces = 0;
  if (ext == ".off") off_faces = check_off(path);
  if (ext == ".ply") check_ply_header(path);

  Assimp::Importer importer;
  importer.SetIOHandler(new OnlyThisFile(path));  // owned by the importer: no material file is opened
  // Read without post-processing first, so polygon counts can be compared with the OFF
  // header, then triangulate and join identical vertices.
  const aiScene* scene = importer.ReadFile(path, 0);
  if (scene == nullptr) {
    fail(path, std::string("assimp cannot read it: ") + importer.GetErrorString());  // kFormats
  }
  // Non-finite coordinates are checked before post-processing: joining identical
  // vertices may silently merge a NaN vertex into another one.
  std::uint64_t faces = 0, loaded = 0, vertices = 0;
  for (unsigned i = 0; i < scene->mNumMeshes; ++i) {
    faces += scene->mMeshes[i]->mNumFaces;
    vertices += scene->mMeshes[i]->mNumVertices;
  }
  check_mesh_counts(path, "holds", vertices, faces);
  // Faces are checked before assimp's post-processing, which asserts (abort()) on a face
  // without indices (found by fuzz_mesh: an OFF face line cut by garbage).
  for (unsigned i = 0, first = 0; i < scene->mNumMeshes; first += scene->mMeshes[i]->mNumFaces, ++i) {
    const aiMesh* am = scene->mMeshes[i];
    for (unsigned f = 0; f < am->mNumFaces; ++f) {
      const aiFace& face = am->mFaces[f];
      if (face.mNumIndices > limits::kMaxFaceCorners)
        fail(path, "face " + std::to_string(first + f) + " has " + std::to_string(face.mNumIndices) +
                       " corners (expected at most " + std::to_string(limits::kMaxFaceCorners) + ")");
      if (face.mNumIndices == 0 || face.mIndices == nullptr)
        fail(path, "face " + std::to_string(first + f) + " has no vertex indices (expected faces of 3 or "
                   "more vertices; a malformed face line?)");
      for (unsigned k = 0; k < face.mNumIndices; ++k)
        if (face.mIndices[k] >= am->mNumVertices)
          fail(path, "face " + std::to_string(first + f) + " uses vertex " + std::to_string(face.mIndices[k]) +
                         " but the file has " + std::to_string(am->mNumVertices) + " vertices");
    }
  }
  for (unsigned i = 0; i < scene->mNumMeshes; ++i) {
    const aiMesh* am = scene->mMeshes[i];
    for (unsigned v = 0; v < am->mNumVertices; ++v, ++loaded) {
      const aiVector3D& p = am->mVertices[v];
      if (!is_finite(Vec3{p.x, p.y, p.z})) {
        fail(path, "vertex " + std::to_string(loaded) + " (" + std::to_string(p.x) + ", " +
                       std::to_string(p.y) + ", " + std::to_string(p.z) +
                       ") is not finite (index in assimp's load order)",
             "finite coordinates");
      }
    }
  }

  if (ext == ".off") {
    const std::uint64_t expected = off_faces;
    if (faces != expected) {
      fail(path, "loaded " + std::to_string(faces) + " faces, expected " + std::to_string(expected) +
                     " from the OFF header",
           "an OFF file whose face list matches its header (comment lines inside the face "
           "list are not supported)");
    }
  }

  scene = importer.ApplyPostProcessing(aiProcess_Triangulate | aiProcess_JoinIdenticalVertices);
  if (scene == nullptr) {
    fail(path, std::string("assimp post-processing failed: ") + importer.GetErrorString());
  }

  Mesh mesh;
  mesh.name = fs::path(path).stem().string();
  for (unsigned mi = 0; mi < scene->mNumMeshes; ++mi) {
    const aiMesh* am = scene->mMeshes[mi];
    const std::size_t base = mesh.vertices.size();
    if (base + am->mNumVertices > std::numeric_limits<std::uint32_t>::max()) {
      fail(path, "too many vertices", "at most 2^32 - 1");
    }
    for (unsigned v = 0; v < am->mNumVertices; ++v) {
      const aiVector3D& p = am->mVertices[v];
      const Vec3 q{p.x, p.y, p.z};
      if (!is_finite(q)) {
        fail(path, "vertex " + std::to_string(mesh.vertices.size()) +
                       " is not finite", "finite coordinates");
      }
      mesh.vertices.push_back(q);
    }
    for (unsigned f = 0; f < am->mNumFaces; ++f) {
      const aiFace& face = am->mFaces[f];
      if (face.mNumIndices != 3) continue;  // points and lines carry no surface
      Tri t{};
      for (int k = 0; k < 3; ++k) {
        const unsigned idx = face.mIndices[k];
        if (idx >= am->mNumVertices) fail(path, "face index out of range");
        t[static_cast<std::size_t>(k)] = static_cast<std::uint32_t>(base + idx);
      }
      mesh.triangles.push_back(t);
    }
  }
  if (mesh.vertices.empty()) fail(path, "no vertices");
  if (mesh.triangles.empty()) fail(path, "no triangles");
  weld_mesh(mesh);
  if (mesh.triangles.empty()) {
    fail(path, "every triangle is degenerate after welding");
  }
  return mesh;
}

void weld_mesh(Mesh& mesh) {
  struct Key {
    std::uint32_t x, y, z;
    bool operator==(const Key& o) const { return x == o.x && y == o.y && z == o.z; }
  };
  struct KeyHash {
    std::size_t operator()(const Key& k) const {
      std::uint64_t h = 1469598103934665603ull;
      for (std::uint32_t w : {k.x, k.y, k.z}) h = (h ^ w) * 1099511628211ull;
      return static_cast<std::size_t>(h ^ (h >> 29));
    }
  };
  auto bits = [](float f) {
    if (f == 0.0f) f = 0.0f;  // -0 and +0 are equal positions
    std::uint32_t u;
    std::memcpy(&u, &f, sizeof u);
    return u;
  };

  std::unordered_map<Key, std::uint32_t, KeyHash> first;
  first.reserve(mesh.vertices.size());
  std::vector<std::uint32_t> remap(mesh.vertices.size());
  std::vector<Vec3> unique;
  unique.reserve(mesh.vertices.size());
  for (std::size_t i = 0; i < mesh.vertices.size(); ++i) {
    const Vec3 p = mesh.vertices[i];
    const auto [it, inserted] = first.try_emplace(Key{bits(p.x), bits(p.y), bits(p.z)},
                                                  static_cast<std::uint32_t>(unique.size()));
    if (inserted) unique.push_back(p);
    remap[i] = it->second;
  }
  std::vector<Tri> tris;
  tris.reserve(mesh.triangles.size());
  for (const Tri& t : mesh.triangles) {
    const Tri r{remap[t[0]], remap[t[1]], remap[t[2]]};
    if (r[0] == r[1] || r[1] == r[2] || r[2] == r[0]) continue;
    tris.push_back(r);
  }
  mesh.vertices = std::move(unique);
  mesh.triangles = std::move(tris);
}

void normalize_mesh(Mesh& mesh) {
  if (mesh.vertices.empty()) {
    throw InputError("mesh '" + mesh.name + "': no vertices; allowed: a non-empty mesh");
  }
  const Aabb b = mesh_bounds(mesh);
  double c[3], longest = 0.0;
  for (int a = 0; a < 3; ++a) {
    c[a] = 0.5 * (static_cast<double>(b.min[a]) + static_cast<double>(b.max[a]));
    longest = std::max(longest, static_cast<double>(b.max[a]) - static_cast<double>(b.min[a]));
  }
  if (!(longest > 0.0) || !std::isfinite(longest)) {
    throw InputError("mesh '" + mesh.name +
                     "': its bounding box has no extent; allowed: a longest side > 0");
  }
  const double inv = 1.0 / longest;
  for (Vec3& v : mesh.vertices) {
    for (int a = 0; a < 3; ++a) v[a] = static_cast<float>((static_cast<double>(v[a]) - c[a]) * inv);
  }
}

void scale_mesh(Mesh& mesh, float s) {
  if (!(s > 0.0f) || !std::isfinite(s)) {
    throw InputError("mesh '" + mesh.name + "': scale " + std::to_string(s) +
                     "; allowed: a finite scale > 0");
  }
  for (Vec3& v : mesh.vertices) v = s * v;
}

Aabb mesh_bounds(const Mesh& mesh) {
  if (mesh.vertices.empty()) {
    throw InputError("mesh '" + mesh.name + "': no vertices; allowed: a non-empty mesh");
  }
  Aabb b{mesh.vertices[0], mesh.vertices[0]};
  for (const Vec3& v : mesh.vertices) {
    for (int a = 0; a < 3; ++a) {
      b.min[a] = std::min(b.min[a], v[a]);
      b.max[a] = std::max(b.max[a], v[a]);
    }
  }
  return b;
}

float mean_edge_length(const Mesh& mesh) {
  if (mesh.triangles.empty()) return 0.0f;
  std::vector<std::uint64_t> edges;
  edges.reserve(mesh.triangles.size() * 3);
  for (const Tri& t : mesh.triangles) {
    edges.push_back(edge_key(t[0], t[1]));
    edges.push_back(edge_key(t[1], t[2]));
    edges.push_back(edge_key(t[2], t[0]));
  }
  std::sort(edges.begin(), edges.end());
  edges.erase(std::unique(edges.begin(), edges.end()), edges.end());
  double sum = 0.0;
  for (std::uint64_t e : edges) {
    const Vec3 a = mesh.vertices[static_cast<std::size_t>(e >> 32)];
    const Vec3 b = mesh.vertices[static_cast<std::size_t>(e & 0xffffffffu)];
    const double dx = static_cast<double>(a.x) - b.x, dy = static_cast<double>(a.y) - b.y,
                 dz = static_cast<double>(a.z) - b.z;
    sum += std::sqrt(dx * dx + dy * dy + dz * dz);
  }
  return static_cast<float>(sum / static_cast<double>(edges.size()));
}

Mesh make_box_mesh(Vec3 half_extents, int subdivisions) {
  if (subdivisions < 0 || subdivisions > 8) {
    throw InputError("make_box_mesh: subdivisions " + std::to_string(subdivisions) +
                     " (expected 0..8)");
  }
  for (int a = 0; a < 3; ++a) {
    if (!(half_extents[a] > 0.0f) || !std::isfinite(half_extents[a])) {
      throw InputError("make_box_mesh: half extents must be finite and > 0");
    }
  }
  Mesh m;
  m.name = "box";
  for (std::uint32_t i = 0; i < 8; ++i) {  // bit 0: x, bit 1: y, bit 2: z
    m.vertices.push_back({(i & 1u) ? half_extents.x : -half_extents.x,
                          (i & 2u) ? half_extents.y : -half_extents.y,
                          (i & 4u) ? half_extents.z : -half_extents.z});
  }
  // Two triangles per face (quad a b c d, counter-clockwise seen from outside).
  const std::uint32_t quads[6][4] = {{0, 4, 6, 2}, {1, 3, 7, 5},   // -x, +x
                                     {0, 1, 5, 4}, {2, 6, 7, 3},   // -y, +y
                                     {0, 2, 3, 1}, {4, 5, 7, 6}};  // -z, +z
  for (const auto& q : quads) {
    m.triangles.push_back({q[0], q[1], q[2]});
    m.triangles.push_back({q[0], q[2], q[3]});
  }
  orient_outwards(m);  // guards the table above
  for (int s = 0; s < subdivisions; ++s) subdivide(m, midpoint_of);
  return m;
}

Mesh make_icosphere(float radius, int subdivisions) {
  if (subdivisions < 0 || subdivisions > limits::kMaxIcosphereSubdivisions) {
    throw InputError("make_icosphere: subdivisions " + std::to_string(subdivisions) + " (expected 0.." +
                     std::to_string(limits::kMaxIcosphereSubdivisions) + ")");
  }
  if (!(radius > 0.0f) || !std::isfinite(radius)) {
    throw InputError("make_icosphere: radius must be finite and > 0");
  }
  const double t = (1.0 + std::sqrt(5.0)) / 2.0;
  const double base[12][3] = {{-1, t, 0}, {1, t, 0},   {-1, -t, 0}, {1, -t, 0},
                              {0, -1, t}, {0, 1, t},   {0, -1, -t}, {0, 1, -t},
                              {t, 0, -1}, {t, 0, 1},   {-t, 0, -1}, {-t, 0, 1}};
  auto on_sphere = [radius](double x, double y, double z) {
    const double s = static_cast<double>(radius) / std::sqrt(x * x + y * y + z * z);
    return Vec3{static_cast<float>(x * s), static_cast<float>(y * s), static_cast<float>(z * s)};
  };
  Mesh m;
  m.name = "icosphere";
  for (const auto& p : base) m.vertices.push_back(on_sphere(p[0], p[1], p[2]));
  m.triangles = {{0, 11, 5}, {0, 5, 1},  {0, 1, 7},   {0, 7, 10}, {0, 10, 11},
                 {1, 5, 9},  {5, 11, 4}, {11, 10, 2}, {10, 7, 6}, {7, 1, 8},
                 {3, 9, 4},  {3, 4, 2},  {3, 2, 6},   {3, 6, 8},  {3, 8, 9},
                 {4, 9, 5},  {2, 4, 11}, {6, 2, 10},  {8, 6, 7},  {9, 8, 1}};
  orient_outwards(m);
  for (int s = 0; s < subdivisions; ++s) {
    subdivide(m, [&](Vec3 a, Vec3 b) {
      return on_sphere(static_cast<double>(a.x) + b.x, static_cast<double>(a.y) + b.y,
                       static_cast<double>(a.z) + b.z);
    });
  }
  return m;
}

}  // namespace octocd
