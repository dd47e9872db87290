// Mesh export: binary little-endian PLY (what io/mesh_import.cpp's Assimp importer reads back).
//
// Layout: "ply / format binary_little_endian 1.0", `element vertex N` with float x, y, z and
// `element face M` with `list uchar int vertex_indices` (triangles). Coordinates are written as
// float32, in the mesh's own units. The bytes depend only on the mesh (no timestamps), so equal
// meshes give equal files.
#pragma once

#include "engine/core.hpp"

#include <filesystem>
#include <string>

namespace ts::io {

/// The binary PLY file of `mesh`, as bytes. `comment` (one line, optional) goes in the header.
std::string ply_bytes(const Mesh& mesh, const std::string& comment = {});

/// Write `mesh` as binary PLY to `file` atomically (temporary file, then rename; see
/// atomic_file.hpp). Throws ts::Error naming the file when it cannot be written.
void write_ply(const Mesh& mesh, const std::filesystem::path& file, const std::string& comment = {});

}  // namespace ts::io
