// The object database as the engine sees it: per-object summary, features (loaded for every
// object, to build the feature index) and geometry (fine cloud, k-d tree, distance field),
// loaded lazily the first time a pruned feature or a hypothesis reaches the object.
// Storage lives in io/ (HDF5); the engine only sees the ObjectSource interface.
#pragma once

#include "engine/core.hpp"
#include "engine/features/descriptors.hpp"
#include "engine/features/fpfh.hpp"
#include "engine/geometry/distance_field.hpp"
#include "engine/geometry/scanner.hpp"
#include "engine/geometry/search.hpp"

#include <algorithm>
#include <atomic>
#include <memory>
#include <mutex>

namespace ts {
inline namespace database {

/// How a mesh's size becomes the object's: `fit` scales every mesh so that its largest
/// bounding-box side is max_extent (the paper's evaluation: shape alone tells objects apart);
/// `keep` keeps the mesh's own size, in metres after its units (a 5 cm bolt stays 5 cm).
enum class ObjectScale { fit, keep };

/// Everything needed to build a database object from its mesh.
struct DatabaseSettings {
  ObjectScale scale = ObjectScale::fit;
  double max_extent = 0.20;        ///< m, largest bounding-box extent after scaling (fit)
  ScanSettings scan;
  FpfhSettings fpfh;               ///< normal radius, and the feature radius of every descriptor
  Descriptor descriptor = Descriptor::fpfh;  ///< the local descriptor of keypoints and queries
  DistanceFieldSettings field;
};

struct ObjectInfo {
  std::string name;
  std::string source;              ///< where the mesh came from (manifest source / path)
  std::string mesh_sha256;         ///< checksum of the mesh file bytes
  double scale = 1.0;              ///< object frame = scale * (mesh - bbox centre)
  Vec3 centre = Vec3::Zero();      ///< that bbox centre, in the mesh file's units
  Vec3 extent = Vec3::Zero();      ///< bounding-box size in the object frame (m)
  std::size_t fine_points = 0;
  std::size_t coarse_points = 0;
  bool closed = false;             ///< watertight mesh: inside/outside is meaningful
  double coverage = 0.0;           ///< scanner coverage
};

struct ObjectFeatures {
  PointCloud coarse;               ///< object frame, with normals
  FeatureRows features;            ///< one row per coarse point, of the database's descriptor
};

/// What Batch RANSAC and the shortlist read of an object, kept for every object once loaded:
/// the coarse cloud (the feature keypoints, with normals) and a k-d tree over it. The features
/// themselves live only in the search structure built from Database::load_features.
struct ObjectKeypoints {
  PointCloud coarse;               ///< object frame, with normals
  /// A k-d tree over coarse.points, not a copy (KdTree3::over), built on the first call
  /// (thread-safe): only the shortlist's screening searches it, and on a database of thousands
  /// of objects, whose every keypoints the shape prior reads, most objects are never screened.
  /// coarse must not change once it is built.
  const KdTree3& tree() const;
  bool tree_built() const { return tree_built_.load(std::memory_order_acquire); }

 private:
  mutable std::once_flag tree_once_;
  mutable KdTree3 tree_;
  mutable std::atomic<bool> tree_built_{false};
};

struct ObjectGeometry {
  PointCloud fine;                 ///< object frame, with normals
  KdTree3 tree;                    ///< over fine.points, not a copy (KdTree3::over)
  DistanceField field;
  /// The surface points lowest along some of kExtremeDirections directions (extreme_points): how
  /// deep a pose puts the object below a plane, read from at most that many points instead of the
  /// cloud. For a geometry from a Database, of its keypoints (the coarse cloud, fine points one
  /// per coarse voxel, always loaded), so that the answer does not depend on whether the fine
  /// cloud is; otherwise of `fine` (none when it is empty). Built on the first call (thread-safe;
  /// copies share it), as only a step with a support plane asks; fine must not change once it is
  /// built, and a geometry from a Database must not outlive it.
  const std::vector<Vec3>& extremes() const;
  static constexpr int kExtremeDirections = 256;

 private:
  friend class Database;
  struct Extremes {
    std::once_flag once;
    std::vector<Vec3> points;
    const class Database* db = nullptr;   ///< the keypoints' database (fine not loaded)
    std::size_t object = 0;
  };
  std::shared_ptr<Extremes> extremes_ = std::make_shared<Extremes>();
};

/// Wall-clock seconds per stage of build_object (diagnostics printed by `db build`).
struct BuildTimings {
  double scan_s = 0.0;       ///< simulated laser scanner: fine and coarse clouds
  double features_s = 0.0;   ///< normals and descriptors of the coarse points
  double field_s = 0.0;      ///< distance field
};

/// A fully built object (what the builder produces and the store writes).
struct BuiltObject {
  ObjectInfo info;
  BuildTimings timings;            ///< filled by build_object
  Mesh mesh;                       ///< object frame (stored so the simulator touches the truth)
  ObjectFeatures features;         ///< coarse keypoints with PCA normals (as queries compute them)
  PointCloud fine;                 ///< scanner cloud, exact outward face normals
  DistanceField field;
};

/// Where objects come from. Implementations must be callable from several threads (the HDF5
/// store serializes its reads behind one mutex).
class ObjectSource {
 public:
  virtual ~ObjectSource() = default;
  virtual std::size_t size() const = 0;
  virtual const ObjectInfo& info(std::size_t i) const = 0;
  virtual const DatabaseSettings& settings() const = 0;
  virtual ObjectFeatures load_features(std::size_t i) const = 0;
  /// The coarse cloud alone (default: load_features(i).coarse; a store may read less).
  virtual PointCloud load_coarse(std::size_t i) const { return load_features(i).coarse; }
  virtual PointCloud load_fine(std::size_t i) const = 0;
  virtual DistanceField load_field(std::size_t i) const = 0;
};

/// The largest object length of a database (s_obj_max of Eq. 3, the half-margin of the free-space
/// box): max_extent under `fit`, the largest bounding-box side over the objects under `keep`.
double largest_object_extent(const ObjectSource& source);
class Database;
double largest_object_extent(const Database& db);

/// "fit" / "keep"; parse_object_scale throws ts::Error naming `where` naming file and field on another word.
const char* to_string(ObjectScale scale);
ObjectScale parse_object_scale(const std::string& word, const std::string& file, const std::string& field = {});

/// In-memory source over built objects (tests, `recognize` right after a build).
class MemorySource final : public ObjectSource {
 public:
  MemorySource(std::vector<BuiltObject> objects, DatabaseSettings settings);
  std::size_t size() const override;
  const ObjectInfo& info(std::size_t i) const override;
  const DatabaseSettings& settings() const override;
  ObjectFeatures load_features(std::size_t i) const override;
  PointCloud load_fine(std::size_t i) const override;
  DistanceField load_field(std::size_t i) const override;

 private:
  std::vector<BuiltObject> objects_;
  DatabaseSettings settings_;
};

/// An object's geometry, held while in use: the cache may evict its copy meanwhile, the holder's
/// stays valid.
using GeometryRef = std::shared_ptr<const ObjectGeometry>;

/// Thread-safe lazy cache over a source. Each object's keypoints (coarse cloud and its k-d tree)
/// are loaded at most once and kept; its geometry (fine cloud, k-d tree, distance field: the bulk of an object's memory) is
/// loaded on demand and, under a memory budget, evicted least-recently-used when the resident
/// geometry exceeds the budget. Objects in use (a GeometryRef held elsewhere) are never evicted,
/// so the budget may be exceeded while a step needs more objects at once than it holds.
/// Eviction changes no result, only what has to be loaded again. Counters let tests, reports and
/// benchmarks check what a scene actually needed.
class Database {
 public:
  explicit Database(std::shared_ptr<const ObjectSource> source);
  ~Database();

  std::size_t size() const;
  const ObjectInfo& info(std::size_t i) const;
  const DatabaseSettings& settings() const;
  std::size_t find(const std::string& name) const;   ///< size() when absent

  /// Coarse cloud and k-d tree, loaded once and kept (a few hundred kB an object).
  const ObjectKeypoints& keypoints(std::size_t i) const;
  /// Features and coarse cloud read from the source, not cached (for building search
  /// structures, which keep their own copy of the features).
  ObjectFeatures load_features(std::size_t i) const;
  GeometryRef geometry(std::size_t i) const;
  bool geometry_loaded(std::size_t i) const;         ///< resident now
  std::size_t geometry_loads() const;                ///< loads so far (reloads counted)
  std::size_t geometry_resident() const;             ///< objects whose geometry is resident
  std::size_t geometry_evictions() const;            ///< evictions so far
  std::size_t geometry_bytes() const;                ///< resident geometry (estimated bytes)
  std::size_t geometry_peak_bytes() const;           ///< largest geometry_bytes() so far

  /// Whether geometry() loads each object's fine cloud and its k-d tree (the default) or the
  /// distance field alone (about half the memory, less load time: bench_geometry; enough for
  /// field ICP and the field evaluation: see needs_surface in recognizer.hpp). A change drops the resident
  /// geometry; throws ts::Error while some of it is in use.
  void set_surface(bool on);
  bool surface() const;
  /// The fine cloud read from the source, not cached (symmetry detection, diagnostics).
  PointCloud load_fine(std::size_t i) const;

  /// Resident geometry allowed (bytes, estimated from the loaded arrays and grids); 0: no limit
  /// (the default). A smaller budget evicts at once what is not in use.
  void set_memory_budget(std::size_t bytes);
  std::size_t memory_budget() const;
  /// Evict least-recently-used geometry not in use until the budget holds (the recognizer
  /// calls it after each step; loads call it too).
  void trim() const;

 private:
  struct Slot;
  struct Cache;
  std::shared_ptr<const ObjectSource> source_;
  std::unique_ptr<Slot[]> slots_;
  std::unique_ptr<Cache> cache_;
};

/// The geometry of a set of objects, loaded once (those not resident in parallel: the file
/// reads take turns, building the trees and grids overlaps) and held for a stage: its parallel
/// loop reads it without touching the cache.
class GeometryPins {
 public:
  template <class Range, class ObjectOf>
  GeometryPins(const Database& db, const Range& items, ObjectOf object_of) : refs_(db.size()) {
    std::vector<std::uint32_t> objects;
    for (const auto& x : items) objects.push_back(static_cast<std::uint32_t>(object_of(x)));
    std::sort(objects.begin(), objects.end());
    objects.erase(std::unique(objects.begin(), objects.end()), objects.end());
    load(db, objects);
  }
  const ObjectGeometry& operator[](std::size_t object) const { return *refs_[object]; }

 private:
  void load(const Database& db, const std::vector<std::uint32_t>& objects);
  std::vector<GeometryRef> refs_;
};

/// Estimated bytes of one object's geometry (what the memory budget counts).
std::size_t memory_bytes(const ObjectGeometry& g);

/// Build one object from a mesh already in its object frame (see io/mesh_import for the
/// frame): scan_mesh (settings.scan) gives the fine cloud; PCA normals (fpfh.normal_radius)
/// on it, oriented by the scanner's outward normals, feed the descriptor (settings.descriptor,
/// over fpfh.feature_radius; FPFH by default) at one fine point per
/// scan.coarse_voxel (keypoints with an empty neighbourhood are dropped); the distance field
/// is signed when the mesh is closed. Fills info's extent, closed, counts and coverage (the
/// caller's name, source, checksum, scale and centre are kept). Deterministic for a seed and
/// any thread count. Uses TBB inside; call from within the caller's arena.
BuiltObject build_object(const Mesh& object_frame_mesh, ObjectInfo info,
                         const DatabaseSettings& settings, std::uint64_t seed);

}  // namespace database
}  // namespace ts
