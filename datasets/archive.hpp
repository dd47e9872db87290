// Members of tar archives (.tar, .tar.gz, .tgz; ustar, GNU and pax headers), read into memory.
// Used for the default mesh data, which ships inside a Debian package's data.tar.gz.
#pragma once

#include <filesystem>
#include <map>
#include <set>
#include <string>
#include <vector>

namespace ts::datasets {

/// Read one regular-file member (its path inside the archive; a leading "./" is ignored).
/// Throws ts::Error naming the archive (and the member) when the archive is missing, corrupt or
/// truncated, or the member is absent. Nothing is sized by a header's size field unchecked: a
/// member declaring more than the rest of a plain tar is refused at its header, and one of a
/// compressed archive is read as it arrives.
std::string read_archive_member(const std::filesystem::path& archive, const std::string& member);

/// Read several members in one pass over the archive (one decompression). Every requested member
/// must be present.
std::map<std::string, std::string> read_archive_members(const std::filesystem::path& archive,
                                                        const std::set<std::string>& members);

/// Paths of the regular-file members, in archive order.
std::vector<std::string> list_archive(const std::filesystem::path& archive);

}  // namespace ts::datasets
