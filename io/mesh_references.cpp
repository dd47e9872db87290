#include "io/mesh_references.hpp"

#include "engine/core.hpp"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <cctype>
#include <cstdint>

namespace ts::io {

namespace {

namespace fs = std::filesystem;

std::uint32_t le32(const std::string& b, std::size_t at) {
  std::uint32_t v = 0;
  for (int i = 3; i >= 0; --i) v = (v << 8) | static_cast<unsigned char>(b[at + static_cast<std::size_t>(i)]);
  return v;
}

/// The JSON of a glTF file: the file itself, or the JSON of a binary glTF (.glb: "glTF", the
/// version, the length; glTF 2: chunks of a length and a type, the first the JSON; glTF 1: the
/// content's length and format 0, then the content), its length checked against the file.
std::string gltf_json(const std::string& b) {
  if (b.size() < 20 || b.compare(0, 4, "glTF") != 0) return b;
  const std::uint32_t length = le32(b, 12), type = le32(b, 16);
  if (length > b.size() - 20 || type != (le32(b, 4) == 1 ? 0u : 0x4E4F534Au)) return {};   // Assimp refuses it
  return b.substr(20, length);
}

std::string percent_decoded(const std::string& s) {
  std::string out;
  for (std::size_t i = 0; i < s.size(); ++i) {
    if (s[i] == '%' && i + 2 < s.size() && std::isxdigit(static_cast<unsigned char>(s[i + 1])) &&
        std::isxdigit(static_cast<unsigned char>(s[i + 2]))) {
      out += static_cast<char>(std::stoi(s.substr(i + 1, 2), nullptr, 16));
      i += 2;
    } else {
      out += s[i];
    }
  }
  return out;
}

/// Why a reference (as written, or percent-decoded) does not name a file inside the mesh's
/// folder; "" when it does as far as its text tells.
std::string lexical_refusal(const std::string& path) {
  const std::size_t colon = path.find(':');
  if (colon != std::string::npos && colon > 0 && std::isalpha(static_cast<unsigned char>(path[0])) &&
      std::all_of(path.begin(), path.begin() + static_cast<std::ptrdiff_t>(colon),
                  [](char c) { return std::isalnum(static_cast<unsigned char>(c)) || c == '+' || c == '-' || c == '.'; }))
    return "is a URI of the scheme '" + path.substr(0, colon + 1) + "' (only data: URIs and relative paths are read)";
  if (!path.empty() && (path[0] == '/' || path[0] == '\\')) return "is an absolute path";
  int depth = 0;
  std::size_t start = 0;
  while (start <= path.size()) {
    const std::size_t end = std::min(path.find_first_of("/\\", start), path.size());
    const std::string part = path.substr(start, end - start);
    if (part == "..") {
      if (--depth < 0) return "leads out of the mesh's folder";
    } else if (!part.empty() && part != ".") {
      ++depth;
    }
    start = end + 1;
  }
  return {};
}

}  // namespace

bool inside_folder(const fs::path& path, const fs::path& folder) {
  std::error_code ec;
  const fs::path base = fs::weakly_canonical(fs::absolute(folder, ec), ec);
  if (ec) return false;
  const fs::path p = fs::weakly_canonical(fs::absolute(path, ec), ec);
  if (ec) return false;
  return std::mismatch(base.begin(), base.end(), p.begin(), p.end()).first == base.end();
}

void check_gltf_references(const std::string& bytes, const std::string& name, const fs::path& folder) {
  const auto json = nlohmann::json::parse(gltf_json(bytes), nullptr, false);
  if (!json.is_object()) return;
  auto check = [&](const nlohmann::json& item, const std::string& field) {
    if (!item.is_object() || !item.contains("uri") || !item["uri"].is_string()) return;
    const std::string uri = item["uri"].get<std::string>();
    std::string head = uri.substr(0, 5);
    std::transform(head.begin(), head.end(), head.begin(), [](unsigned char c) { return std::tolower(c); });
    if (head == "data:") return;   // embedded in the file
    std::string why = lexical_refusal(uri);
    if (why.empty()) why = lexical_refusal(percent_decoded(uri));
    if (why.empty() && !folder.empty() && !inside_folder(folder / uri, folder))
      why = "leads out of the mesh's folder (through a symbolic link)";
    if (!why.empty())
      throw Error("'" + uri.substr(0, 200) + "' " + why + ": a mesh may read only files inside its own folder", name,
                  field);
  };
  for (const char* key : {"buffers", "images", "shaders"}) {
    if (!json.contains(key)) continue;
    const nlohmann::json& list = json[key];
    if (list.is_array())   // glTF 2
      for (std::size_t i = 0; i < list.size(); ++i) check(list[i], std::string(key) + "[" + std::to_string(i) + "].uri");
    else if (list.is_object())   // glTF 1: objects by id
      for (const auto& [id, item] : list.items()) check(item, std::string(key) + "[\"" + id + "\"].uri");
  }
}

}  // namespace ts::io
