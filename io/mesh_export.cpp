#include "io/mesh_export.hpp"

#include "io/atomic_file.hpp"

#include <bit>
#include <cstdint>
#include <cstring>
#include <fstream>

namespace ts::io {

namespace {

static_assert(std::endian::native == std::endian::little, "binary PLY writer assumes a little-endian host");

template <typename T>
void put(std::string& out, T value) {
  char bytes[sizeof(T)];
  std::memcpy(bytes, &value, sizeof(T));
  out.append(bytes, sizeof(T));
}

}  // namespace

std::string ply_bytes(const Mesh& mesh, const std::string& comment) {
  std::string out = "ply\nformat binary_little_endian 1.0\n";
  if (!comment.empty()) {
    std::string line = comment;
    for (char& c : line)
      if (c == '\n' || c == '\r') c = ' ';
    out += "comment " + line + "\n";
  }
  out += "element vertex " + std::to_string(mesh.vertices.size()) + "\n";
  out += "property float x\nproperty float y\nproperty float z\n";
  out += "element face " + std::to_string(mesh.faces.size()) + "\n";
  out += "property list uchar int vertex_indices\nend_header\n";
  out.reserve(out.size() + mesh.vertices.size() * 12 + mesh.faces.size() * 13);
  // Assimp's PLY reader skips white space after end_header, binary data included: a first
  // byte of 0x09-0x0d or 0x20 would shift every value after it. The first vertex whose first
  // byte is not white space is written first (swapped with vertex 0, faces renumbered).
  auto first_byte = [](float x) {
    unsigned char b[sizeof x];
    std::memcpy(b, &x, sizeof x);
    return b[0];
  };
  auto blank = [](unsigned char c) { return c == ' ' || (c >= 0x09 && c <= 0x0d); };
  std::size_t lead = 0;
  while (lead < mesh.vertices.size() && blank(first_byte(static_cast<float>(mesh.vertices[lead].x())))) ++lead;
  if (lead == mesh.vertices.size()) lead = 0;   // (no such vertex: nothing to gain)
  auto renumber = [lead](int i) { return i == 0 ? static_cast<int>(lead) : i == static_cast<int>(lead) ? 0 : i; };
  for (std::size_t i = 0; i < mesh.vertices.size(); ++i) {
    const auto& v = mesh.vertices[static_cast<std::size_t>(renumber(static_cast<int>(i)))];
    for (int k = 0; k < 3; ++k) put(out, static_cast<float>(v[k]));
  }
  for (const auto& f : mesh.faces) {
    put(out, static_cast<std::uint8_t>(3));
    for (int k = 0; k < 3; ++k) put(out, static_cast<std::int32_t>(renumber(f[k])));
  }
  return out;
}

void write_ply(const Mesh& mesh, const std::filesystem::path& file, const std::string& comment) {
  const std::string bytes = ply_bytes(mesh, comment);
  AtomicOutput output(file);
  {
    std::ofstream out(output.temp_path(), std::ios::binary | std::ios::trunc);
    if (!out) throw Error("cannot write the mesh file", file.string());
    out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
    out.close();
    if (!out) throw Error("cannot write the mesh file (disk full?)", file.string());
  }
  output.commit();
}

}  // namespace ts::io
