// The databases of an experiment: the file (or objects in memory) with what a run store records
// about it, and the recognizer databases its variants use (subsets of the file, one group per
// distinct subset, shared by the variants that use it).
#pragma once

#include "engine/database/database.hpp"
#include "engine/database/feature_table.hpp"
#include "engine/geometry/search.hpp"
#include "engine/recognition/shape_prior.hpp"
#include "engine/recognition/sparse_hypotheses.hpp"

#include <nlohmann/json.hpp>

#include <filesystem>
#include <functional>
#include <map>
#include <memory>
#include <string>
#include <vector>

namespace ts::io {
class DbReader;
}

namespace ts::experiments {

/// The database an experiment uses: objects for the recognizer, meshes for the simulator, and
/// what the run store records about it (its "fingerprint" decides whether --resume may go on).
struct EngineDatabase {
  std::shared_ptr<const ObjectSource> source;
  std::function<Mesh(std::size_t)> load_mesh;  ///< object-frame mesh of object i
  nlohmann::ordered_json description;          ///< {"path", "fingerprint", ...}
};

/// A database file (io/db_store). Throws ts::Error for a missing or foreign file.
EngineDatabase open_database(const std::filesystem::path& path);
/// Objects held in memory (tests; a database built a moment ago).
EngineDatabase memory_database(std::vector<BuiltObject> objects, const DatabaseSettings& settings);
/// SHA-256 over what determines an object source's content: settings, names, mesh checksums,
/// scales and point counts.
std::string source_fingerprint(const ObjectSource& source);
/// A database file's fingerprint (run stores and calibration files record it): the source's plus
/// the schema version and build seeds.
std::string file_fingerprint(const io::DbReader& reader);

/// A database restricted to some objects of another (study 4 and 7: smaller databases from the
/// same file). Index i here is objects[i] there.
class SubsetSource final : public ObjectSource {
 public:
  SubsetSource(std::shared_ptr<const ObjectSource> base, std::vector<std::size_t> objects)
      : base_(std::move(base)), objects_(std::move(objects)) {}
  std::size_t size() const override { return objects_.size(); }
  const ObjectInfo& info(std::size_t i) const override { return base_->info(objects_.at(i)); }
  const DatabaseSettings& settings() const override { return base_->settings(); }
  ObjectFeatures load_features(std::size_t i) const override { return base_->load_features(objects_.at(i)); }
  PointCloud load_coarse(std::size_t i) const override { return base_->load_coarse(objects_.at(i)); }
  PointCloud load_fine(std::size_t i) const override { return base_->load_fine(objects_.at(i)); }
  DistanceField load_field(std::size_t i) const override { return base_->load_field(objects_.at(i)); }

 private:
  std::shared_ptr<const ObjectSource> base_;
  std::vector<std::size_t> objects_;
};

/// One recognizer database (a subset of the file), shared by the variants that use it.
struct DatabaseGroup {
  std::vector<std::size_t> objects;            ///< file indices, in recognizer order
  std::vector<std::int32_t> to_file;           ///< recognizer index -> file index
  std::map<std::size_t, std::uint32_t> to_local;  ///< file index -> recognizer index
  std::unique_ptr<Database> database;
  /// Classes of congruent objects (recognizer index -> class, engine/recognition/answer_set.hpp):
  /// the database's recorded classes restricted to the group, each other object its own.
  std::vector<std::uint32_t> class_of;
  std::size_t classes = 0;
  /// FLANN indices, one per index setting its variants search with (built in prepare() where a
  /// variant needs one: the paper's preset); index_for() gives a variant's.
  std::vector<std::pair<FeatureIndexSettings, std::shared_ptr<const FeatureIndex>>> indices;
  std::shared_ptr<const FeatureIndex> index_for(const FeatureIndexSettings& s) const {
    for (const auto& [settings, index] : indices)
      if (settings.exact == s.exact && settings.trees == s.trees && settings.checks == s.checks &&
          settings.seed == s.seed)
        return index;
    return nullptr;
  }
  /// The FeatureTables of its variants (FeatureTable::shared keeps one only while it is held):
  /// built once in prepare(), not once per run.
  std::vector<std::shared_ptr<const FeatureTable>> tables;
  /// The shape priors of its variants (Recognizer::shape_prior), held alike: a run's recognizer
  /// finds its prior built (4 500 objects: about 4 s a run before).
  std::vector<std::shared_ptr<const ShapePrior>> priors;
  /// The sparse source's pair tables of its variants (Recognizer::sparse_tables), held alike: a
  /// run's recognizer finds those an earlier run built (45 objects: about 0.7 s a run before).
  std::vector<std::shared_ptr<SparseTables>> sparse_tables;
};

}  // namespace ts::experiments
