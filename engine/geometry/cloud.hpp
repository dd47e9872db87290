// Point-cloud operations: voxel-grid filter, normal estimation, bounds.
#pragma once

#include "engine/core.hpp"

namespace ts {
inline namespace geometry {

/// Voxel-grid filter (Section 4.1.2): one point per occupied voxel of size `voxel`, the
/// centroid of the points in it (normals averaged and renormalized when present). The output
/// order is deterministic (sorted by voxel key), independent of the input order's threads.
/// Voxels are aligned to the origin (voxel (i,j,k) = [i,i+1) x [j,j+1) x [k,k+1) times `voxel`),
/// so filtering a union of clouds uses one grid. Non-finite points are dropped. Throws ts::Error
/// when `voxel` is not positive.
PointCloud voxel_filter(const PointCloud& cloud, double voxel);

/// Voxel-grid filter that keeps input points: one point per occupied voxel, the member nearest
/// to the voxel's centroid (ties: the earlier input point), with its own normal. Points stay on
/// the sampled surface (the simulated scanner's fine cloud). Same grid and order as voxel_filter.
PointCloud voxel_representatives(const PointCloud& cloud, double voxel);

/// PCA normals from neighbours within `radius` (the point itself included; at least
/// `min_neighbours` needed, otherwise the normal is NaN-free but flagged by returning a zero
/// vector). Normals are oriented away from the cloud centroid; callers that know better (the
/// database builder, the contact pipeline) re-orient them against their own reference.
struct NormalSettings {
  double radius = 0.007;  ///< m, neighbourhood radius (paper: 7 mm)
  int min_neighbours = 3;
};
std::vector<Vec3> estimate_normals(const std::vector<Vec3>& points, const NormalSettings& s);

Eigen::AlignedBox3d bounds(const std::vector<Vec3>& points);
Vec3 centroid(const std::vector<Vec3>& points);

/// Apply a rigid transform to points (and normals).
PointCloud transformed(const PointCloud& cloud, const Pose& T);

/// Nearly uniform unit directions on the sphere (Fibonacci lattice), n of them (none for n <= 0).
std::vector<Vec3> fibonacci_directions(int n);

/// The points that are lowest along at least one of `directions` Fibonacci directions (each
/// point once, in input order). The lowest of them along any direction u approximates the lowest
/// of all points along u from above: never lower than the true lowest point. How far above
/// depends on the points' hull between sampled directions: on a sphere of radius r at most about
/// r (1 - cos a), a the angle from u to its nearest sampled direction; more near sharp edges
/// and corners that no sampled direction finds lowest. Empty input: empty.
std::vector<Vec3> extreme_points(const std::vector<Vec3>& points, int directions);

}  // namespace geometry
}  // namespace ts
