// Mesh manifests: one object a line, "source<TAB>path<TAB>name[<TAB>units]". `path` is a mesh file or
// "ARCHIVE:MEMBER" for a mesh inside a (gzip-compressed) tar archive; relative paths are
// resolved against the manifest's folder. `units` (m, cm, mm or in) is the length unit of the
// mesh file, used when the database keeps real sizes (db build --scale keep); without it the
// build's --units applies. Blank lines and lines starting with '#' are skipped.
#pragma once

#include <filesystem>
#include <string>
#include <utility>
#include <vector>

namespace ts::datasets {

struct ManifestEntry {
  std::string source;
  std::filesystem::path path;   ///< resolved file (the archive, when member is set)
  std::string member;           ///< member inside the archive, or empty
  std::string name;
  double units = 0.0;           ///< metres per mesh unit from the units column (0: not given)
  int line = 0;                 ///< 1-based line in the manifest
};

/// Split "ARCHIVE:MEMBER" (ARCHIVE ending in .tar.gz, .tgz or .tar) into the archive path and
/// the member; a plain path gives an empty member.
std::pair<std::string, std::string> split_archive_path(const std::string& path);

/// Parse a manifest. Throws ts::Error naming the file and line on a malformed line or a
/// duplicate object name.
std::vector<ManifestEntry> read_manifest(const std::filesystem::path& manifest);

}  // namespace ts::datasets
