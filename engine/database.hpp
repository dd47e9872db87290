// The object database as the engine sees it: per-object summary, features (loaded for every
// object, to build the feature index) and geometry (fine cloud, k-d tree, distance field),
// loaded lazily the first time a pruned feature or a hypothesis reaches the object.
// Storage lives in io/ (HDF5); the engine only sees the ObjectSource interface.
#pragma once

#include "engine/core.hpp"
#include "engine/distance_field.hpp"
#include "engine/fpfh.hpp"
#include "engine/scanner.hpp"
#include "engine/search.hpp"

#include <atomic>
#include <memory>
#include <mutex>

namespace ts {

/// Everything needed to build a database object from its mesh.
struct DatabaseSettings {
  double max_extent = 0.20;        ///< m, largest bounding-box extent after scaling
  ScanSettings scan;
  FpfhSettings fpfh;
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
  std::vector<Feature> features;   ///< one per coarse point
};

struct ObjectGeometry {
  PointCloud fine;                 ///< object frame, with normals
  KdTree3 tree;                    ///< over fine.points
  DistanceField field;
};

/// Wall-clock seconds per stage of build_object (diagnostics printed by `db build`).
struct BuildTimings {
  double scan_s = 0.0;       ///< simulated laser scanner: fine and coarse clouds
  double features_s = 0.0;   ///< normals and FPFH of the coarse points
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
  virtual PointCloud load_fine(std::size_t i) const = 0;
  virtual DistanceField load_field(std::size_t i) const = 0;
};

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

/// Thread-safe lazy cache over a source. Each object's features and geometry are loaded at
/// most once; counters let tests and reports check what a scene actually needed.
class Database {
 public:
  explicit Database(std::shared_ptr<const ObjectSource> source);
  ~Database();

  std::size_t size() const;
  const ObjectInfo& info(std::size_t i) const;
  const DatabaseSettings& settings() const;
  std::size_t find(const std::string& name) const;   ///< size() when absent

  const ObjectFeatures& features(std::size_t i) const;
  const ObjectGeometry& geometry(std::size_t i) const;
  bool geometry_loaded(std::size_t i) const;
  std::size_t geometry_loads() const;

 private:
  struct Slot;
  std::shared_ptr<const ObjectSource> source_;
  std::unique_ptr<Slot[]> slots_;
};

/// Build one object from a mesh already in its object frame (see io/mesh_import for the
/// frame): scan_mesh (settings.scan) gives the fine cloud; PCA normals (fpfh.normal_radius)
/// on it, oriented by the scanner's outward normals, feed FPFH at one fine point per
/// scan.coarse_voxel (keypoints with an empty neighbourhood are dropped); the distance field
/// is signed when the mesh is closed. Fills info's extent, closed, counts and coverage (the
/// caller's name, source, checksum, scale and centre are kept). Deterministic for a seed and
/// any thread count. Uses TBB inside; call from within the caller's arena.
BuiltObject build_object(const Mesh& object_frame_mesh, ObjectInfo info,
                         const DatabaseSettings& settings, std::uint64_t seed);

}  // namespace ts
