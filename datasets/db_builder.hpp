// Building an object database from meshes: read (files or archive members), import into the
// object frame, build every object (scanner, FPFH, distance field) in parallel over TBB, write.
//
// Determinism: object i is built with io::object_seed(seed, name) into its own slot and the
// file is written serially in input order, so the database is byte-identical for any thread
// count (and an object's data do not depend on the other objects).
//
// Objects are written as they finish, each to a single-object database in the parts folder
// (OUT.parts/ by default, written atomically), and merged into OUT at the end (compressed
// arrays copied as they are); memory holds only the objects being built. A build that stops
// (a kill, a failing mesh) keeps its finished parts: the same command resumes, building only
// what is missing. The parts folder records a fingerprint of the inputs (names, sources, mesh
// checksums), the parameters and the seed; a resume whose inputs or parameters changed is an
// error naming the manifest and the folder.
#pragma once

#include "engine/database/database.hpp"
#include "io/db_store.hpp"
#include "io/mesh_import.hpp"

#include <filesystem>
#include <functional>
#include <string>
#include <vector>

namespace ts::datasets {

/// One mesh to build: a file, or a member of a tar archive.
struct MeshInput {
  std::string name;             ///< object name
  std::string source;           ///< provenance stored in the database
  std::filesystem::path path;   ///< mesh file, or the archive when `member` is set
  std::string member;           ///< archive member, or empty
  std::string origin;           ///< where the input was declared (for errors), e.g. "m.tsv"
  std::string origin_field;     ///< e.g. "line 12"
  double units = 0.0;           ///< m per mesh unit under --scale keep (0: BuildSettings::units)

  /// "path" or "archive:member" (what errors name).
  std::string display() const;
};

/// Inputs from a manifest (datasets/manifest.hpp); errors name the manifest and the line.
std::vector<MeshInput> inputs_from_manifest(const std::filesystem::path& manifest);
/// Every mesh file (an extension Assimp reads) directly in `folder`, sorted by file name; the
/// object name is the file name without its extension.
std::vector<MeshInput> inputs_from_folder(const std::filesystem::path& folder);
/// One mesh given on the command line: a file or "ARCHIVE:MEMBER"; name defaults to the stem.
MeshInput input_from_path(const std::string& path, const std::string& name = {});

/// Seconds per stage. import/scan/features/field are summed over objects (each object's time
/// on its own thread, so with several threads they add up to more than the wall time);
/// read (archives), write and wall are wall-clock.
struct BuildTimes {
  double read_s = 0.0;
  double import_s = 0.0;
  double scan_s = 0.0;
  double features_s = 0.0;
  double field_s = 0.0;
  double write_s = 0.0;
  double wall_s = 0.0;
};

/// Where a build stands, after each object.
struct BuildProgress {
  std::size_t done = 0;       ///< objects finished, resumed ones included
  std::size_t total = 0;
  std::size_t resumed = 0;    ///< objects taken from an earlier, stopped build
  double elapsed_s = 0.0;     ///< since this build started building
  std::string name;           ///< the object just finished
  /// Seconds left at the rate of this build so far (0 before the first object).
  double remaining_s() const {
    const std::size_t built = done - resumed;
    return built == 0 ? 0.0 : elapsed_s / double(built) * double(total - done);
  }
};

struct BuildSettings {
  DatabaseSettings database;
  std::uint64_t seed = 1;                   ///< build seed (each object: io::object_seed)
  io::DbWriteSettings write;
  /// m per mesh unit of the inputs without their own units (database.scale = keep).
  double units = 1.0;
  /// Folder of finished objects (empty: OUT.parts beside OUT); removed after the merge.
  std::filesystem::path parts;
  /// Called after each object is built, under a lock, from the thread that built it; may be
  /// empty.
  std::function<void(const BuildProgress&)> progress;
  /// Congruent objects: found after the objects are built and stored with them.
  CongruenceSettings congruence;
};

/// What a congruence search over a database found, and what it cost.
struct CongruenceOutcome {
  io::CongruenceRecord record;
  CongruenceSearchStats stats;      ///< the pair search (prefilter and geometric checks)
  double signature_s = 0.0;         ///< wall time of the signatures (meshes read when needed)
  bool reused = false;              ///< the old objects' signatures and pairs were kept
};

/// An imported and built object, with what the import noticed.
struct BuildResult {
  BuiltObject object;
  std::uint64_t seed = 0;
  bool flipped = false;                 ///< faces were wound inward (flipped on import)
  std::vector<std::string> warnings;    ///< open / non-manifold mesh
  double import_s = 0.0;
};

struct BuildReport {
  std::vector<std::string> names;                    ///< input order
  std::vector<std::vector<std::string>> warnings;    ///< per object
  std::vector<bool> flipped;
  std::vector<double> coverage;
  std::size_t resumed = 0;                           ///< objects kept from a stopped build
  BuildTimes times;                                  ///< of the objects built by this run
  CongruenceOutcome congruence;                      ///< stored in the database
};

/// Import one mesh (bytes already read when `bytes` is given) and build it with `seed`.
BuildResult build_one(const MeshInput& input, const DatabaseSettings& settings, std::uint64_t seed,
                      const std::string* bytes = nullptr);

/// The congruence record of `db` with `added` objects appended (object-frame meshes, in order;
/// empty for the database as it is). With `reuse` and a record of the same settings in `db`, the
/// old objects' signatures and pairs are kept and only the pairs of the added objects are
/// searched; otherwise every object's signature is computed from its mesh and every pair
/// searched. Throws ts::Error for a tolerance that is not positive.
CongruenceOutcome database_congruence(const io::DbReader& db, const std::vector<const Mesh*>& added,
                                      const CongruenceSettings& settings, bool reuse);

/// Build every input and write the database to `out` (atomically). Throws the error of the
/// first failing input (in input order); `out` is not written then. A mesh that does not import
/// fails before anything is built; an object that fails to build leaves the finished ones in the
/// parts folder, for the same call to resume.
BuildReport build_database(const std::vector<MeshInput>& inputs, const std::filesystem::path& out,
                           const BuildSettings& settings);

}  // namespace ts::datasets
