// The files a mesh refers to: a mesh may read only files inside its own folder.
//
// Assimp follows references to other files: glTF buffers (its geometry) and images, an OBJ's
// material library (mtllib), the meshes of a LightWave or Irrlicht scene, and so on. A glTF
// whose buffer uri was "../../../../etc/shadow" made that file's bytes a mesh of the database
// (issue 57). Every file Assimp opens goes through a guard (io/mesh_import.cpp) that refuses a
// path outside the mesh's folder; glTF's references are also checked before Assimp reads, so
// that the error names the field.
#pragma once

#include <filesystem>
#include <string>

namespace ts::io {

/// True when `path` (relative to the working directory, or absolute) is `folder` or lies below
/// it, symbolic links resolved (the file need not exist; `folder` must).
bool inside_folder(const std::filesystem::path& path, const std::filesystem::path& folder);

/// Checks every external reference of a glTF 1 or 2 file (`bytes`: its JSON, or a binary .glb
/// holding its JSON chunk): buffers, images (and glTF 1's shaders), each `uri` either a data:
/// URI or a relative path, percent-decoded, that stays inside `folder`, the mesh's folder
/// (symbolic links resolved where the file exists). Empty `folder`: the mesh was read from
/// memory (an archive member), and only the relative path is checked. JSON that does not parse
/// is left to Assimp. Throws ts::Error naming `name` and the field ("buffers[0].uri",
/// "images[2].uri"; glTF 1: `buffers["id"].uri`): an absolute path, another URI scheme (file:,
/// http:), or a path leading out of the folder.
void check_gltf_references(const std::string& bytes, const std::string& name, const std::filesystem::path& folder);

}  // namespace ts::io
