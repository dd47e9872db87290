#include "experiments/runs/engine_database.hpp"

#include "io/db_store.hpp"
#include "io/sha256.hpp"

#include <sstream>

namespace ts::experiments {

std::string source_fingerprint(const ObjectSource& source) {
  io::Sha256 h;
  auto add = [&](const std::string& s) {
    h.update(s);
    h.update("\n");
  };
  std::ostringstream settings;
  settings.precision(17);
  const DatabaseSettings& d = source.settings();
  settings << d.max_extent << ' ' << d.fpfh.normal_radius << ' ' << d.fpfh.feature_radius;
  // The descriptor only when it is not FPFH: FPFH databases keep the fingerprints they had
  // before descriptors were a choice (and the calibrations and run stores that name them).
  if (d.descriptor != Descriptor::fpfh) settings << " descriptor " << descriptor_name(d.descriptor);
  add(settings.str());
  for (std::size_t i = 0; i < source.size(); ++i) {
    const ObjectInfo& o = source.info(i);
    std::ostringstream s;
    s.precision(17);
    s << o.name << ' ' << o.mesh_sha256 << ' ' << o.scale << ' ' << o.fine_points << ' '
      << o.coarse_points;
    add(s.str());
  }
  return h.hex_digest();
}

std::string file_fingerprint(const io::DbReader& reader) {
  // The content fingerprint plus the build seeds: a rebuilt database with other seeds is another
  // database even when its names and sizes agree.
  io::Sha256 h;
  h.update(source_fingerprint(reader));
  h.update(std::to_string(reader.schema_version()) + " " + std::to_string(reader.build_seed()));
  for (std::size_t i = 0; i < reader.size(); ++i) h.update(' ' + std::to_string(reader.object_seed(i)));
  return h.hex_digest();
}

EngineDatabase open_database(const std::filesystem::path& path) {
  auto reader = std::make_shared<io::DbReader>(path);
  EngineDatabase db;
  db.source = reader;
  db.load_mesh = [reader](std::size_t i) { return reader->load_mesh(i); };
  std::error_code ec;
  const auto absolute = std::filesystem::absolute(path, ec);
  db.description["path"] = ec ? path.string() : absolute.string();
  db.description["fingerprint"] = file_fingerprint(*reader);
  db.description["objects"] = reader->size();
  db.description["schema_version"] = reader->schema_version();
  db.description["build_seed"] = reader->build_seed();
  db.description["max_extent_m"] = reader->settings().max_extent;
  db.description["descriptor"] = descriptor_name(reader->settings().descriptor);
  // Classes of congruent objects (names), which reports count class-aware rates with; absent
  // when the database recorded none.
  if (const io::CongruenceRecord* c = reader->congruence()) {
    nlohmann::ordered_json classes = nlohmann::ordered_json::array();
    for (const auto& members : c->classes()) {
      nlohmann::ordered_json names = nlohmann::ordered_json::array();
      for (std::size_t i : members) names.push_back(reader->info(i).name);
      classes.push_back(names);
    }
    db.description["congruent_classes"] = classes;
  }
  return db;
}

EngineDatabase memory_database(std::vector<BuiltObject> objects, const DatabaseSettings& settings) {
  auto meshes = std::make_shared<std::vector<Mesh>>();
  for (const BuiltObject& o : objects) meshes->push_back(o.mesh);
  EngineDatabase db;
  db.source = std::make_shared<MemorySource>(std::move(objects), settings);
  db.load_mesh = [meshes](std::size_t i) { return meshes->at(i); };
  db.description["path"] = "(memory)";
  db.description["fingerprint"] = source_fingerprint(*db.source);
  db.description["objects"] = db.source->size();
  return db;
}

}  // namespace ts::experiments
