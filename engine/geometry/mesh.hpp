// Triangle-mesh queries: a bounding-volume hierarchy for ray casting (the simulated laser
// scanner, the tactile simulator) and exact point-to-surface distance (coverage, oracles).
#pragma once

#include "engine/core.hpp"

#include <memory>
#include <optional>

namespace ts {

/// Mesh measurements used by import checks and reports.
double mesh_area(const Mesh& mesh);
double mesh_signed_volume(const Mesh& mesh);   ///< > 0 when faces are wound outward
Eigen::AlignedBox3d mesh_bounds(const Mesh& mesh);

/// Topology report: open edges (used by one face) and non-manifold edges (used by > 2 faces).
struct MeshTopology {
  std::size_t boundary_edges = 0;
  std::size_t nonmanifold_edges = 0;
  bool closed() const { return boundary_edges == 0 && nonmanifold_edges == 0; }
};
MeshTopology mesh_topology(const Mesh& mesh);

struct RayHit {
  double t = 0.0;        ///< distance along the (unit) ray direction
  Vec3 point;            ///< hit point
  Vec3 normal;           ///< unit geometric normal of the hit face (as wound)
  int face = -1;
};

struct ClosestPoint {
  double distance = 0.0; ///< unsigned Euclidean distance to the surface
  Vec3 point;            ///< closest surface point
  Vec3 normal;           ///< unit normal of the face holding `point`
  int face = -1;
};

/// Static BVH over a mesh's triangles. Immutable after construction; every query is
/// thread-safe. Keeps its own copy of the mesh.
class MeshIndex {
 public:
  explicit MeshIndex(Mesh mesh);
  ~MeshIndex();
  MeshIndex(MeshIndex&&) noexcept;
  MeshIndex& operator=(MeshIndex&&) noexcept;

  const Mesh& mesh() const;
  /// First hit along origin + t * dir, t in (t_min, t_max]; dir need not be unit.
  std::optional<RayHit> raycast(const Vec3& origin, const Vec3& dir, double t_max = 1e30,
                                double t_min = 0.0) const;
  /// Whether raycast(origin, dir, t_max, t_min) would hit anything; stops at the first hit found
  /// (no nearest hit to find), so occluded rays cost a fraction of a raycast.
  bool occluded(const Vec3& origin, const Vec3& dir, double t_max = 1e30, double t_min = 0.0) const;
  /// Exact closest point on the surface.
  ClosestPoint closest(const Vec3& p) const;
  /// Closest point, but only if closer than max_distance (faster for far-away points).
  std::optional<ClosestPoint> closest_within(const Vec3& p, double max_distance) const;
  /// Inside test for closed meshes: parity of crossings along a few fixed directions (majority).
  bool inside(const Vec3& p) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace ts
