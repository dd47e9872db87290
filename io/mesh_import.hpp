// Mesh import (Assimp: OFF, OBJ, PLY, STL, 3DS, glTF, ...) into the OBJECT FRAME.
//
// The object frame (what every database object, simulated dive and ground-truth pose refers to):
//   p_object = scale * (p_file - centre)
// where `centre` is the centre of the mesh's axis-aligned bounding box in file units and, with
// the `fit` scale (the default), `scale` = max_extent / (largest bounding-box side), so the
// object's largest extent is max_extent metres (default 0.20 m); with the `keep` scale, `scale`
// is the metres of one file unit (1 for m, 0.01 for cm, 0.001 for mm, 0.0254 for in), so the
// object keeps its real size. Either way its bounding box is centred on the origin. Axes are
// the file's axes (no rotation). See io/FORMAT_DB.md.
//
// Steps: Assimp with aiProcess_Triangulate | aiProcess_JoinIdenticalVertices (points and lines
// dropped); every mesh of the scene merged, with its node transforms applied; vertices welded on
// exact position across meshes; unreferenced vertices and degenerate faces (a repeated vertex
// or zero area) dropped; faces flipped when the signed volume is negative (wound inward); the
// topology checked (open / non-manifold meshes are kept, with a warning).
// Rejected with ts::Error (naming the file): a mesh Assimp cannot read, no faces, a non-finite
// coordinate, zero extent.
//
// Before Assimp reads a file, the importer it will use is found as Assimp finds it (by the
// extension, else by its importers' own sniffing: a .off file is OFF whatever it holds, a file
// named otherwise may be OFF by its first bytes). OFF and PLY files are read whole by Touchstone
// first (io/mesh_off.hpp, check_ply_structure in io/cloud_io.hpp): Assimp 5.2 sizes arrays from
// their counts unchecked.
//
// A mesh may read only regular files inside its own folder (symbolic links resolved): every
// file Assimp opens goes through a guard, and a mesh that asked for another is refused, naming
// the reference (glTF's buffers[i].uri and images[i].uri are checked before Assimp reads:
// io/mesh_references.hpp; an OBJ's mtllib). A mesh read from memory (an archive member) reads
// no other file: data: URIs only; an OBJ member's material library is skipped (Touchstone uses
// no materials).
#pragma once

#include "engine/core.hpp"
#include "engine/database/database.hpp"
#include "engine/geometry/mesh.hpp"

#include <filesystem>
#include <optional>
#include <string>
#include <vector>

namespace ts::io {

struct MeshImportSettings {
  ObjectScale scale = ObjectScale::fit;
  double max_extent = 0.20;   ///< m, largest bounding-box side in the object frame (fit)
  double units = 1.0;         ///< m per file unit (keep)
};

/// Sizes a `keep` object may have (largest bounding-box side): outside, its units are wrong.
inline constexpr double kKeepMinSize = 0.005;   ///< m
inline constexpr double kKeepMaxSize = 5.0;     ///< m

/// Metres per unit of "m", "cm", "mm" or "in"; nullopt for another word.
std::optional<double> metres_per_unit(const std::string& unit);

struct ImportedMesh {
  Mesh mesh;                  ///< object frame, faces wound outward (when closed)
  double scale = 1.0;         ///< p_object = scale * (p_file - centre)
  Vec3 centre = Vec3::Zero(); ///< bounding-box centre, file units
  Vec3 extent = Vec3::Zero(); ///< bounding-box size in the object frame (m)
  std::string sha256;         ///< of the file bytes (hex)
  MeshTopology topology;
  bool closed = false;        ///< no boundary and no non-manifold edges
  bool flipped = false;       ///< faces were wound inward and have been flipped
  std::size_t dropped_faces = 0;        ///< degenerate faces removed
  std::vector<std::string> warnings;    ///< open / non-manifold (the mesh is still used)
};

/// Import a mesh file. `name` (default: the path) is used in errors.
ImportedMesh import_mesh(const std::filesystem::path& file, const MeshImportSettings& settings = {});

/// Import from bytes already in memory (an archive member). `name` names the source in errors
/// and its extension tells Assimp the format ("data.tar.gz:data/meshes/cube.off").
ImportedMesh import_mesh_from_memory(const std::string& bytes, const std::string& name,
                                     const MeshImportSettings& settings = {});

/// True when Assimp reads files with this extension (".off", "OBJ", ...).
bool is_mesh_extension(const std::string& extension);

/// Bring a mesh (vertices in any units) into the object frame as described above. Used by both
/// importers; exposed for callers that build meshes themselves. `name` names it in errors.
ImportedMesh normalize_mesh(Mesh mesh, const std::string& name, const MeshImportSettings& settings = {});

}  // namespace ts::io
