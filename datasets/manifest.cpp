#include "datasets/manifest.hpp"

#include "engine/core.hpp"
#include "io/db_store.hpp"
#include "io/mesh_import.hpp"

#include <fstream>
#include <set>
#include <sstream>

namespace ts::datasets {

std::pair<std::string, std::string> split_archive_path(const std::string& path) {
  // ARCHIVE:MEMBER, where ARCHIVE ends in a tar suffix.
  for (const char* suffix : {".tar.gz:", ".tgz:", ".tar:"}) {
    const auto pos = path.find(suffix);
    if (pos != std::string::npos) {
      const auto split = pos + std::string(suffix).size() - 1;
      return {path.substr(0, split), path.substr(split + 1)};
    }
  }
  return {path, {}};
}

std::vector<ManifestEntry> read_manifest(const std::filesystem::path& manifest) {
  std::ifstream in(manifest);
  if (!in) throw Error("cannot read the manifest", manifest.string());
  const auto base = manifest.has_parent_path() ? manifest.parent_path() : std::filesystem::path(".");
  std::vector<ManifestEntry> out;
  std::set<std::string> names;
  std::string line;
  for (int number = 1; std::getline(in, line); ++number) {
    if (!line.empty() && line.back() == '\r') line.pop_back();
    if (line.find_first_not_of(" \t") == std::string::npos || line[0] == '#') continue;
    std::vector<std::string> fields;
    std::stringstream ss(line);
    for (std::string f; std::getline(ss, f, '\t');) fields.push_back(f);
    const std::string where = "line " + std::to_string(number);
    if (fields.size() < 3 || fields.size() > 4)
      throw Error("manifest line has " + std::to_string(fields.size()) +
                      " fields, expected source<TAB>path<TAB>name[<TAB>units]", manifest.string(), where);
    ManifestEntry e;
    e.source = fields[0];
    e.name = fields[2];
    e.line = number;
    if (e.name.empty() || fields[1].empty())
      throw Error("manifest line has an empty path or name", manifest.string(), where);
    io::check_object_name(e.name, manifest.string(), where);
    if (!names.insert(e.name).second)
      throw Error("duplicate object name '" + e.name + "'", manifest.string(), where);
    if (fields.size() == 4) {
      const auto units = io::metres_per_unit(fields[3]);
      if (!units)
        throw Error("units must be m, cm, mm or in, not '" + fields[3] + "'", manifest.string(), where + ", units");
      e.units = *units;
    }
    auto [path, member] = split_archive_path(fields[1]);
    e.member = member;
    if (!e.member.empty() && e.member.back() == '/')
      throw Error("archive member '" + e.member + "' is a folder", manifest.string(), where);
    std::filesystem::path p(path);
    e.path = p.is_absolute() ? p : base / p;
    out.push_back(std::move(e));
  }
  return out;
}

}  // namespace ts::datasets
