#include "io/mesh_import.hpp"

#include "io/cloud_io.hpp"
#include "io/mesh_off.hpp"
#include "io/mesh_references.hpp"
#include "io/sha256.hpp"

#include <assimp/BaseImporter.h>
#include <assimp/DefaultIOSystem.h>
#include <assimp/Importer.hpp>
#include <assimp/MemoryIOWrapper.h>
#include <assimp/config.h>
#include <assimp/postprocess.h>
#include <assimp/scene.h>

#include <cctype>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <iterator>
#include <set>
#include <unordered_map>

namespace ts::io {

namespace {

// ValidateDataStructure first: a malformed scene (a truncated file) is then an import error
// instead of reaching an assertion in a later step (Debian's Assimp aborts on those).
constexpr unsigned kFlags = aiProcess_ValidateDataStructure | aiProcess_Triangulate |
                            aiProcess_JoinIdenticalVertices | aiProcess_SortByPType;

void configure(Assimp::Importer& importer) {
  // Drop point and line primitives: only triangles describe a surface.
  importer.SetPropertyInteger(AI_CONFIG_PP_SBP_REMOVE, aiPrimitiveType_POINT | aiPrimitiveType_LINE);
}

void append_node(const aiScene& scene, const aiNode& node, const aiMatrix4x4& parent, Mesh& out) {
  const aiMatrix4x4 T = parent * node.mTransformation;
  for (unsigned m = 0; m < node.mNumMeshes; ++m) {
    const aiMesh& mesh = *scene.mMeshes[node.mMeshes[m]];
    const int base = static_cast<int>(out.vertices.size());
    for (unsigned v = 0; v < mesh.mNumVertices; ++v) {
      const aiVector3D p = T * mesh.mVertices[v];
      out.vertices.emplace_back(p.x, p.y, p.z);
    }
    for (unsigned f = 0; f < mesh.mNumFaces; ++f) {
      const aiFace& face = mesh.mFaces[f];
      if (face.mNumIndices != 3) continue;
      out.faces.emplace_back(base + static_cast<int>(face.mIndices[0]), base + static_cast<int>(face.mIndices[1]),
                             base + static_cast<int>(face.mIndices[2]));
    }
  }
  for (unsigned c = 0; c < node.mNumChildren; ++c) append_node(scene, *node.mChildren[c], T, out);
}

[[noreturn]] void import_failed(const Assimp::Importer& importer, const std::string& name) {
  const char* e = importer.GetErrorString();
  throw Error(std::string("cannot read the mesh") + (e && *e ? std::string(": ") + e : ""), name);
}

/// Read the file without post-processing, check what the importer made, then post-process.
/// Assimp's importers can leave a scene that its own post-processing asserts on (a PLY face
/// list cut short: a mesh declared to hold polygons that holds none, and Debian's Assimp aborts
/// on assertions): every face must have vertices within its mesh, and each mesh's primitive
/// types are recomputed from its faces before kFlags run.
const aiScene* checked_scene(Assimp::Importer& importer, const aiScene* scene, const std::string& name) {
  if (!scene) import_failed(importer, name);
  for (unsigned m = 0; m < scene->mNumMeshes; ++m) {
    aiMesh* mesh = scene->mMeshes ? scene->mMeshes[m] : nullptr;
    if (!mesh || (mesh->mNumVertices > 0 && !mesh->mVertices) || (mesh->mNumFaces > 0 && !mesh->mFaces))
      throw Error("the mesh file declares data it does not hold (mesh " + std::to_string(m) + ")", name);
    unsigned types = 0;
    for (unsigned f = 0; f < mesh->mNumFaces; ++f) {
      const aiFace& face = mesh->mFaces[f];
      if (face.mNumIndices == 0 || !face.mIndices)
        throw Error("face " + std::to_string(f) + " has no vertices", name, "faces");
      for (unsigned i = 0; i < face.mNumIndices; ++i)
        if (face.mIndices[i] >= mesh->mNumVertices)
          throw Error("face " + std::to_string(f) + " names vertex " + std::to_string(face.mIndices[i]) + " of " +
                          std::to_string(mesh->mNumVertices),
                      name, "faces");
      types |= face.mNumIndices == 1   ? aiPrimitiveType_POINT
               : face.mNumIndices == 2 ? aiPrimitiveType_LINE
               : face.mNumIndices == 3 ? aiPrimitiveType_TRIANGLE
                                       : aiPrimitiveType_POLYGON;
    }
    mesh->mPrimitiveTypes = types;
  }
  scene = importer.ApplyPostProcessing(kFlags);
  if (!scene) import_failed(importer, name);
  return scene;
}

Mesh scene_mesh(const aiScene* scene, const Assimp::Importer& importer, const std::string& name) {
  if (!scene) import_failed(importer, name);
  Mesh mesh;
  if (scene->mRootNode) append_node(*scene, *scene->mRootNode, aiMatrix4x4(), mesh);
  return mesh;
}

std::string read_bytes(const std::filesystem::path& path) {
  std::error_code ec;
  if (!std::filesystem::exists(path, ec)) throw Error("mesh file does not exist", path.string());
  std::ifstream in(path, std::ios::binary);
  if (!in) throw Error("cannot read the mesh file", path.string());
  std::string data((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  if (in.bad()) throw Error("cannot read the mesh file", path.string());
  return data;
}

struct PositionHash {
  std::size_t operator()(const std::array<std::uint64_t, 3>& k) const {
    std::uint64_t h = 0x9e3779b97f4a7c15ULL;
    for (auto v : k) h = (h ^ v) * 0xbf58476d1ce4e5b9ULL + (h >> 29);
    return static_cast<std::size_t>(h);
  }
};

std::array<std::uint64_t, 3> position_key(const Vec3& v) {
  std::array<std::uint64_t, 3> k;
  for (int i = 0; i < 3; ++i) {
    const double x = v[i] + 0.0;  // -0.0 and +0.0 weld together
    std::memcpy(&k[static_cast<std::size_t>(i)], &x, sizeof x);
  }
  return k;
}

}  // namespace

std::optional<double> metres_per_unit(const std::string& unit) {
  if (unit == "m") return 1.0;
  if (unit == "cm") return 0.01;
  if (unit == "mm") return 0.001;
  if (unit == "in") return 0.0254;
  return std::nullopt;
}

ImportedMesh normalize_mesh(Mesh input, const std::string& name, const MeshImportSettings& settings) {
  if (settings.scale == ObjectScale::fit && (!(settings.max_extent > 0.0) || !std::isfinite(settings.max_extent)))
    throw Error("max extent must be a positive number of metres", name);
  if (settings.scale == ObjectScale::keep && (!(settings.units > 0.0) || !std::isfinite(settings.units)))
    throw Error("mesh units must be a positive number of metres", name);
  const int nv = static_cast<int>(input.vertices.size());
  for (std::size_t i = 0; i < input.vertices.size(); ++i)
    if (!finite(input.vertices[i]))
      throw Error("mesh has a non-finite vertex coordinate", name, "vertex " + std::to_string(i));

  if (input.faces.empty()) throw Error("mesh has no faces", name);
  {
    Eigen::AlignedBox3d referenced;
    for (std::size_t fi = 0; fi < input.faces.size(); ++fi)
      for (int k = 0; k < 3; ++k) {
        const int v = input.faces[fi][k];
        if (v < 0 || v >= nv) throw Error("face refers to a missing vertex", name, "face " + std::to_string(fi));
        referenced.extend(input.vertices[static_cast<std::size_t>(v)]);
      }
    const double largest = referenced.sizes().maxCoeff();
    if (!std::isfinite(largest)) throw Error("mesh extent is not a finite number", name);
    if (largest <= 0.0) throw Error("mesh has zero extent (every vertex at one point)", name);
  }

  // Weld on exact position (first-use order: deterministic, drops unreferenced vertices) and
  // drop degenerate faces.
  ImportedMesh out;
  std::unordered_map<std::array<std::uint64_t, 3>, int, PositionHash> index_of;
  std::vector<int> remap(input.vertices.size(), -1);
  Mesh& mesh = out.mesh;
  auto vertex = [&](int i) {
    if (remap[static_cast<std::size_t>(i)] >= 0) return remap[static_cast<std::size_t>(i)];
    const auto [it, added] = index_of.emplace(position_key(input.vertices[static_cast<std::size_t>(i)]),
                                              static_cast<int>(mesh.vertices.size()));
    if (added) mesh.vertices.push_back(input.vertices[static_cast<std::size_t>(i)]);
    return remap[static_cast<std::size_t>(i)] = it->second;
  };
  for (std::size_t fi = 0; fi < input.faces.size(); ++fi) {
    const auto& f = input.faces[fi];
    const Eigen::Vector3i g(vertex(f[0]), vertex(f[1]), vertex(f[2]));
    const bool repeated = g[0] == g[1] || g[1] == g[2] || g[0] == g[2];
    if (repeated || (mesh.vertices[static_cast<std::size_t>(g[1])] - mesh.vertices[static_cast<std::size_t>(g[0])])
                            .cross(mesh.vertices[static_cast<std::size_t>(g[2])] - mesh.vertices[static_cast<std::size_t>(g[0])])
                            .squaredNorm() == 0.0) {
      ++out.dropped_faces;
      continue;
    }
    mesh.faces.push_back(g);
  }
  if (mesh.faces.empty())
    throw Error(out.dropped_faces ? "mesh has no faces (all " + std::to_string(out.dropped_faces) + " are degenerate)"
                                  : std::string("mesh has no faces"),
                name);
  // Vertices only used by dropped faces: compact again so the bounding box is the surface's.
  {
    std::vector<int> used(mesh.vertices.size(), -1);
    std::vector<Vec3> kept;
    for (auto& f : mesh.faces)
      for (int k = 0; k < 3; ++k) {
        int& u = used[static_cast<std::size_t>(f[k])];
        if (u < 0) {
          u = static_cast<int>(kept.size());
          kept.push_back(mesh.vertices[static_cast<std::size_t>(f[k])]);
        }
        f[k] = u;
      }
    mesh.vertices = std::move(kept);
  }

  // Object frame: bounding-box centre at the origin; largest side = max_extent (fit) or the
  // mesh's own size in metres (keep).
  const Eigen::AlignedBox3d box = mesh_bounds(mesh);
  const Vec3 size = box.sizes();
  const double largest = size.maxCoeff();
  if (!(largest > 0.0) || !std::isfinite(largest)) throw Error("mesh has zero extent", name);  // guarded above
  out.centre = box.center();
  out.scale = settings.scale == ObjectScale::fit ? settings.max_extent / largest : settings.units;
  if (settings.scale == ObjectScale::keep) {
    // A real object touched by a hand: a size outside 5 mm .. 5 m is a units mistake (a mesh
    // in millimetres read as metres), and would make grids of millions of voxels a side.
    const double metres = largest * out.scale;
    if (!(metres >= kKeepMinSize && metres <= kKeepMaxSize)) {
      char text[160];
      std::snprintf(text, sizeof text, "at its own size the object is %.4g m long (%.4g file units x %.4g m): check the units", metres, largest, out.scale);
      throw Error(text, name, "units");
    }
  }
  for (auto& v : mesh.vertices) v = out.scale * (v - out.centre);
  out.extent = mesh_bounds(mesh).sizes();

  // Outward winding: flip when the faces enclose a negative volume.
  if (mesh_signed_volume(mesh) < 0.0) {
    for (auto& f : mesh.faces) std::swap(f[1], f[2]);
    out.flipped = true;
  }
  out.topology = mesh_topology(mesh);
  out.closed = out.topology.closed();
  if (out.topology.boundary_edges > 0)
    out.warnings.push_back("mesh is open (" + std::to_string(out.topology.boundary_edges) +
                           " boundary edges): it is used, but its distance field is unsigned");
  if (out.topology.nonmanifold_edges > 0)
    out.warnings.push_back("mesh is non-manifold (" + std::to_string(out.topology.nonmanifold_edges) +
                           " edges shared by more than two faces): it is used as it is");
  return out;
}

namespace {

/// Assimp (5.2) loops forever on a PLY header cut short and sizes arrays from element counts
/// and list lengths it has not checked against the file (26 GB from one ascii face line): PLY
/// is walked whole by Touchstone's own reader first.
/// Assimp takes a file for PLY by its extension or by a magic word in any case ("Ply"), so
/// both send it through the check (which wants the exact first line "ply").
void check_ply_header(const std::string& bytes, const std::string& name, const std::string& extension) {
  std::string head = bytes.substr(0, 3), ext = extension;
  for (char& c : head) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  for (char& c : ext) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  if (head == "ply" || ext == "ply" || ext == ".ply") check_ply_structure(bytes, name);
}

/// The importer Assimp's ReadFile (5.2.5, code/Common/Importer.cpp) picks for `file`: the one
/// importer whose extensions end the name (any case); when several do (.gltf, .glb, .xml) the
/// first of them whose CanRead with the signature check takes the file, and when none does (or
/// no extension matches) the first of all importers that takes it. Null when none would.
Assimp::BaseImporter* chosen_importer(const Assimp::Importer& importer, const std::string& file, Assimp::IOSystem* io) {
  std::string lower = file;
  for (char& c : lower) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  std::vector<Assimp::BaseImporter*> by_extension;
  for (std::size_t i = 0; i < importer.GetImporterCount(); ++i) {
    Assimp::BaseImporter* candidate = importer.GetImporter(i);
    std::set<std::string> extensions;
    candidate->GetExtensionList(extensions);
    for (const std::string& e : extensions)
      if (lower.ends_with("." + e)) {
        by_extension.push_back(candidate);
        break;
      }
  }
  if (by_extension.size() == 1) return by_extension.front();
  auto takes = [&](Assimp::BaseImporter* candidate) {
    try {
      return candidate->CanRead(file, io, true);
    } catch (const std::exception&) {   // ReadFile fails then: no importer reads the file
      return false;
    }
  };
  for (Assimp::BaseImporter* candidate : by_extension)
    if (takes(candidate)) return candidate;
  for (std::size_t i = 0; i < importer.GetImporterCount(); ++i)
    if (takes(importer.GetImporter(i))) return importer.GetImporter(i);
  return nullptr;
}

/// True when `chosen` is the importer of files named *.`extension` ("off", "gltf", "obj").
bool reads_extension(Assimp::BaseImporter* chosen, const std::string& extension) {
  if (!chosen) return false;
  std::set<std::string> extensions;
  chosen->GetExtensionList(extensions);
  return extensions.count(extension) > 0;
}

/// Assimp's file access for one import: the default file system, only regular files inside
/// `folder` (none at all when it is empty: a mesh read from memory). The paths refused are kept;
/// Assimp may go on without the file (an OBJ without its material library), so the import is
/// refused after it returns.
class FolderIO final : public Assimp::DefaultIOSystem {
 public:
  explicit FolderIO(std::filesystem::path folder) : folder_(std::move(folder)) {}
  bool Exists(const char* file) const override { return allowed(file) && DefaultIOSystem::Exists(file); }
  Assimp::IOStream* Open(const char* file, const char* mode) override {
    return allowed(file) ? DefaultIOSystem::Open(file, mode) : nullptr;
  }
  /// The first path refused, as Assimp asked for it ("" when none).
  const std::string& refused() const { return refused_; }

 private:
  bool allowed(const char* file) const {
    std::error_code ec;
    if (!folder_.empty() && inside_folder(file, folder_) &&
        (!std::filesystem::exists(file, ec) || std::filesystem::is_regular_file(file, ec)))
      return true;
    if (refused_.empty()) refused_ = file;
    return false;
  }
  std::filesystem::path folder_;
  mutable std::string refused_;
};

/// What both entry points share. `file`: the mesh's path (null: `bytes` come from memory, an
/// archive member, named by the extension `hint`).
ImportedMesh read_mesh(const std::string& bytes, const std::string& name, const std::filesystem::path* file,
                       const std::string& hint, const MeshImportSettings& settings) {
  check_ply_header(bytes, name, hint);
  Assimp::Importer importer;
  configure(importer);
  const std::filesystem::path folder = !file ? std::filesystem::path()
                                       : file->parent_path().empty() ? std::filesystem::path(".")
                                                                     : file->parent_path();
  auto* io = new FolderIO(folder);
  importer.SetIOHandler(io);   // the importer owns it
  // The importer Assimp will use, chosen as ReadFile and ReadFileFromMemory choose it.
  Assimp::BaseImporter* chosen = nullptr;
  if (file) {
    chosen = chosen_importer(importer, name, io);
  } else {
    Assimp::MemoryIOSystem memory(reinterpret_cast<const std::uint8_t*>(bytes.data()), bytes.size(), nullptr);
    chosen = chosen_importer(importer, std::string(AI_MEMORYIO_MAGIC_FILENAME) + "." + hint, &memory);
  }
  const aiScene* scene = nullptr;
  if (reads_extension(chosen, "off")) {
    // Assimp's OFF reader is given the mesh as plain OFF, read and checked whole here first.
    const std::string text = off_for_assimp(bytes, name);
    scene = importer.ReadFileFromMemory(text.data(), text.size(), 0, "off");
  } else {
    std::string ext = hint;
    for (char& c : ext) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
    if (reads_extension(chosen, "gltf") || ext == "gltf" || ext == ".gltf" || ext == "glb" || ext == ".glb")
      check_gltf_references(bytes, name, folder);
    // From the file (not memory) so formats with companion files (OBJ + MTL, glTF + BIN) work.
    scene = file ? importer.ReadFile(name, 0) : importer.ReadFileFromMemory(bytes.data(), bytes.size(), 0, hint.c_str());
  }
  // A file outside the mesh's folder was asked for. From memory, an OBJ's material library
  // cannot be read and is skipped (no material is used); any other reference is refused.
  if (!io->refused().empty() && (file || !reads_extension(chosen, "obj"))) {
    std::string reference = io->refused();   // as written in the mesh, where Assimp prefixed the folder
    const std::string prefix = folder.string() + "/";
    if (file && reference.rfind(prefix, 0) == 0) reference.erase(0, prefix.size());
    throw Error("refers to '" + reference.substr(0, 200) + "', " +
                    (file ? "outside the mesh's folder: a mesh may read only files inside its own folder"
                          : "and a mesh read from an archive reads no other file"),
                name, reads_extension(chosen, "obj") ? "mtllib" : "a file it refers to");
  }
  scene = checked_scene(importer, scene, name);
  ImportedMesh out = normalize_mesh(scene_mesh(scene, importer, name), name, settings);
  out.sha256 = sha256_hex(bytes);
  return out;
}

}  // namespace

bool is_mesh_extension(const std::string& extension) {
  if (extension.empty() || extension == ".") return false;
  std::string ext = extension[0] == '.' ? extension : "." + extension;
  Assimp::Importer importer;
  return importer.IsExtensionSupported(ext);
}

ImportedMesh import_mesh(const std::filesystem::path& file, const MeshImportSettings& settings) {
  const std::string bytes = read_bytes(file);
  return read_mesh(bytes, file.string(), &file, file.extension().string(), settings);
}

ImportedMesh import_mesh_from_memory(const std::string& bytes, const std::string& name,
                                     const MeshImportSettings& settings) {
  std::string hint = std::filesystem::path(name).extension().string();
  if (!hint.empty() && hint[0] == '.') hint.erase(0, 1);
  if (bytes.empty()) throw Error("mesh file is empty", name);
  return read_mesh(bytes, name, nullptr, hint, settings);
}

}  // namespace ts::io
