// The object database on disk: one HDF5 file, format in io/FORMAT_DB.md.
//
// - write_database(): a whole database, written under a temporary name and renamed when done.
//   The bytes depend only on the objects, settings and seeds (no timestamps), so a build is
//   byte-identical for any thread count.
// - append_to_database(): `db add`. Works on a copy that replaces the original only when
//   everything succeeded; on any failure (duplicate name, disk full, ...) the original file is
//   untouched.
// - DbReader: the engine's ObjectSource over a file. Opening reads only the summary (root,
//   parameter and per-object attributes): `db info` never touches point data. Every load checks
//   the dataset shapes against the summary, and all HDF5 access is serialised by the global HDF5
//   mutex, so a DbReader may be used from many threads.
#pragma once

#include "engine/database/database.hpp"
#include "engine/geometry/congruence.hpp"

#include <cstdint>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace ts::io {

/// Schema version written by this program; readers refuse other versions.
/// 2: distance fields stored as int16 bricks (CompactGrid); 1 (sparse float voxels) is still read.
constexpr std::int64_t kDbSchemaVersion = 2;
/// Value of the root attribute "format".
constexpr const char* kDbFormatName = "touchstone-object-database";

struct DbWriteSettings {
  int deflate = 1;   ///< zlib level 0..9 of the arrays (0: none; 1 makes the default database 3x smaller)
};

/// What a database records beside each object's data: the seed each object was built with.
struct StoredObject {
  const BuiltObject* object = nullptr;
  std::uint64_t seed = 0;
};

/// Congruent objects as a database records them (group /congruence, io/FORMAT_DB.md): every
/// object's shape signature (in /order order) and the congruent and mirror-image pairs found with
/// `settings`. Databases written before it have none: no classes known.
struct CongruenceRecord {
  CongruenceSettings settings;
  std::vector<ShapeSignature> signatures;   ///< one per object, database order
  std::vector<CongruentPair> pairs;         ///< sorted by (a, b); indices in database order
  /// Classes of congruent objects (ts::congruence_classes of the pairs).
  std::vector<std::vector<std::size_t>> classes() const;
  /// Mirror-image pairs.
  std::vector<CongruentPair> mirrors() const;
  /// The members of object i's class (ascending), or {i} when it is congruent to no other.
  std::vector<std::size_t> class_of(std::size_t i) const;
  /// Whether objects i and j are congruent (i == j included).
  bool same_class(std::size_t i, std::size_t j) const;
  /// The motion of a congruent pair that carries object `from`'s frame into object `to`'s
  /// (x_to = T * x_from), when the pair was checked directly; nullopt otherwise.
  std::optional<Eigen::Affine3d> motion(std::size_t from, std::size_t to) const;
};

/// Object names become HDF5 group names: non-empty, no '/', not "." or "..", no control
/// characters, no leading or trailing blanks. Throws ts::Error naming `file` and `field`.
void check_object_name(const std::string& name, const std::string& file = {},
                       const std::string& field = {});

/// Write a whole database (atomically). Names must be unique. `build_seed` is the --seed of
/// the build (each object's own seed is stored with it).
/// `congruence` (may be null: none recorded) covers the objects in the given order.
void write_database(const std::filesystem::path& path, const std::vector<StoredObject>& objects,
                    const DatabaseSettings& settings, std::uint64_t build_seed,
                    const DbWriteSettings& write = {}, const CongruenceRecord* congruence = nullptr);

/// One database from single-object databases (`db build`'s parts, written as objects finish),
/// in the given order: each part's object is copied as stored (no recompression). Every part
/// must hold exactly one object, of this program's schema; `settings` and `build_seed` are the
/// database's /params. Written atomically, like write_database.
void merge_databases(const std::vector<std::filesystem::path>& parts, const std::filesystem::path& path,
                     const DatabaseSettings& settings, std::uint64_t build_seed,
                     const CongruenceRecord* congruence = nullptr);

/// Append objects to an existing database (built with the database's settings). The original
/// file is replaced only when everything succeeded. `congruence` (when not null) replaces the
/// database's record and must cover the old objects and the new ones.
void append_to_database(const std::filesystem::path& path, const std::vector<StoredObject>& objects,
                        const DbWriteSettings& write = {}, const CongruenceRecord* congruence = nullptr);

/// Replace (or add) the congruence record of an existing database: written to a copy that
/// replaces the original only when complete, so a failure leaves the database as it was.
void write_congruence(const std::filesystem::path& path, const CongruenceRecord& congruence);

class DbReader final : public ObjectSource {
 public:
  /// Open and read the summary. Throws ts::Error for a missing, foreign, truncated or
  /// incompatible file (naming the file and the field).
  explicit DbReader(const std::filesystem::path& path);
  ~DbReader() override;

  std::size_t size() const override;
  const ObjectInfo& info(std::size_t i) const override;
  const DatabaseSettings& settings() const override;
  ObjectFeatures load_features(std::size_t i) const override;
  PointCloud load_coarse(std::size_t i) const override;
  PointCloud load_fine(std::size_t i) const override;
  DistanceField load_field(std::size_t i) const override;

  /// The object-frame mesh (the simulator touches it).
  Mesh load_mesh(std::size_t i) const;
  /// Index of `name`, or size() when absent.
  std::size_t find(const std::string& name) const;

  const std::string& path() const;
  std::int64_t schema_version() const;
  int feature_dim() const;
  std::uint64_t build_seed() const;
  std::uint64_t object_seed(std::size_t i) const;
  std::size_t mesh_vertices(std::size_t i) const;
  std::size_t mesh_faces(std::size_t i) const;
  /// The congruence record, or null for a database written without one (no classes known).
  const CongruenceRecord* congruence() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

/// Every build parameter as stored under /params: group ("" for max_extent, else "scan",
/// "fpfh" or "field"), name, value, and whether it is an integer. For reports (`db info`).
struct SettingValue {
  std::string group;
  std::string name;
  double value = 0.0;
  bool integer = false;
};
std::vector<SettingValue> settings_values(const DatabaseSettings& settings);
/// Sets the build parameter `key`, one of settings_values' names ("max_extent", or the group and
/// the name: "scan.fine_spacing", "field.fine_band_voxels", ...), to `value`. An unknown key, or a
/// value out of its range (the ranges `db build`'s flags take; lengths positive, counts at least
/// 1 and whole, fractions in [0, 1], angles in (0, 90] degrees), is an Error naming `origin` and
/// the key, before anything is built.
void set_setting_value(DatabaseSettings& settings, const std::string& key, double value, const std::string& origin);

/// Seed of one object: derived from the build seed and the object's name (not its position),
/// so an object's data do not depend on the order of the manifest, on threads, or on whether it
/// was built with `db build` or appended with `db add`.
std::uint64_t object_seed(std::uint64_t build_seed, const std::string& name);

}  // namespace ts::io
