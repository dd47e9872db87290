// The engine tests' six analytic shapes (engine/recognition_fixture.hpp) written as a database
// file, for tests that run the touchstone program on it.
#pragma once

#include "engine/recognition_fixture.hpp"
#include "fixture_cache.hpp"
#include "io/db_store.hpp"
#include "temp_dir.hpp"

#include <algorithm>
#include <filesystem>
#include <string>
#include <system_error>
#include <unistd.h>
#include <vector>

namespace ts::test {

/// The engine tests' six shapes (less `skip`) as the database file `dir`/`name`: a copy of the
/// one this test binary built before (fixture_cache.hpp), else built and written, then kept.
inline std::filesystem::path make_db(const TempDir& dir, const std::string& name = "db.h5",
                                     std::vector<std::string> skip = {}) {
  const auto path = dir / name;
  std::string what = "db";
  for (const auto& s : skip) what += "-" + s;
  const auto cached = fixture_cache(what);
  std::error_code ec;
  if (!cached.empty() && std::filesystem::is_regular_file(cached, ec)) {
    std::filesystem::copy_file(cached, path, std::filesystem::copy_options::overwrite_existing);
    return path;
  }
  auto src = make_source();
  std::vector<BuiltObject> objects;
  for (std::size_t i = 0; i < src->size(); ++i) {
    if (std::find(skip.begin(), skip.end(), src->infos[i].name) != skip.end()) continue;
    BuiltObject o;
    o.info = src->infos[i];
    o.info.source = "test";
    o.info.mesh_sha256 = std::string(64, '0');
    o.mesh = src->meshes[i];
    o.features = src->feats[i];
    o.fine = src->fines[i];
    o.field = src->load_field(i);
    objects.push_back(std::move(o));
  }
  std::vector<io::StoredObject> stored;
  for (const auto& o : objects) stored.push_back({&o, 1});
  io::write_database(path, stored, src->db_settings, 1);
  if (!cached.empty()) {  // whole or not at all: another process may be reading it
    const auto part = cached.string() + ".tmp-" + std::to_string(::getpid());
    std::filesystem::copy_file(path, part, std::filesystem::copy_options::overwrite_existing, ec);
    if (!ec) std::filesystem::rename(part, cached, ec);
    if (ec) std::filesystem::remove(part, ec);
  }
  return path;
}

}  // namespace ts::test
