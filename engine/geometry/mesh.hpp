// Triangle-mesh queries: a bounding-volume hierarchy for ray casting (the simulated laser
// scanner, the tactile simulator) and exact point-to-surface distance (coverage, oracles).
#pragma once

#include "engine/core.hpp"

#include <array>
#include <cstdint>
#include <memory>
#include <optional>

namespace ts {
inline namespace geometry {

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

/// A lattice point near the surface (MeshIndex::shell).
struct ShellVoxel {
  std::array<std::int32_t, 3> ijk;   ///< the point ijk * voxel
  double sq_distance = 0.0;          ///< squared distance to the surface, m^2
  Vec3 point;                        ///< closest surface point
  int face = -1;                     ///< the face holding it
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

  /// Every lattice point ijk * voxel within `radius` of the surface, sorted by ijk, with what
  /// closest() returns there (the same arithmetic; ties to the smaller face index). Each face
  /// visits the lattice points of its own box grown by `radius`: no tree search, so a thin
  /// shell (radius about a voxel) of a whole mesh costs a few tests per lattice point.
  std::vector<ShellVoxel> shell(double voxel, double radius) const;

  /// Whether the faces bound a solid consistently: every edge is used by exactly two faces, once
  /// in each direction (no repeated vertex in a face), and every connected part encloses a
  /// positive volume (wound outward). Then side() tells inside from outside, except where closed
  /// parts overlap (a face inside another part's solid): such meshes get wrong signs near it.
  bool oriented() const;
  /// Which side of an oriented() surface p lies on, from its closest point `c` (as closest(),
  /// closest_within() or shell() give it): > 0 outside, < 0 inside, 0 on the surface. The dot
  /// product of p - c.point with the angle-weighted pseudonormal (Baerentzen and Aanaes 2005) of
  /// the face, edge or vertex holding c.point, whose sign is the side for a closed, consistently
  /// wound surface. Meaningless when !oriented().
  double side(const Vec3& p, const ClosestPoint& c) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace geometry
}  // namespace ts
