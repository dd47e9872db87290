// The engine tests' six analytic shapes (engine/recognition_fixture.hpp) written as a database
// file, for tests that run the touchstone program on it.
#pragma once

#include "engine/recognition_fixture.hpp"
#include "io/db_store.hpp"
#include "temp_dir.hpp"

#include <algorithm>
#include <filesystem>
#include <string>
#include <vector>

namespace ts::test {

inline std::filesystem::path make_db(const TempDir& dir, const std::string& name = "db.h5",
                                     std::vector<std::string> skip = {}) {
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
  const auto path = dir / name;
  io::write_database(path, stored, src->db_settings, 1);
  return path;
}

}  // namespace ts::test
