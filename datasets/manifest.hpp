// Mesh manifests: one object a line, "source<TAB>path<TAB>name". `path` is a mesh file or
// "ARCHIVE:MEMBER" for a mesh inside a (gzip-compressed) tar archive; relative paths are
// resolved against the manifest's folder. Blank lines and lines starting with '#' are skipped.
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
  int line = 0;                 ///< 1-based line in the manifest
};

/// Split "ARCHIVE:MEMBER" (ARCHIVE ending in .tar.gz, .tgz or .tar) into the archive path and
/// the member; a plain path gives an empty member.
std::pair<std::string, std::string> split_archive_path(const std::string& path);

/// Parse a manifest. Throws ts::Error naming the file and line on a malformed line or a
/// duplicate object name.
std::vector<ManifestEntry> read_manifest(const std::filesystem::path& manifest);

}  // namespace ts::datasets
