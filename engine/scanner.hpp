// Simulated laser scanner (Section 4.2): builds an object's database clouds from its mesh.
#pragma once

#include "engine/core.hpp"
#include "engine/mesh.hpp"

namespace ts {

struct ScanSettings {
  double fine_spacing = 0.0015;   ///< m, target spacing of the fine cloud (voxel filter size)
  double coarse_voxel = 0.005;    ///< m, voxel filter of the coarse (feature) cloud
  int max_views = 400;            ///< upper bound on scanner viewpoints
  int rays_per_view = 4096;       ///< rays in one scan (a square raster over the view cone)
  double target_coverage = 0.995; ///< stop when this fraction of area is scanned
  int random_every = 8;           ///< every k-th view a random direction (escapes minima)
  double coverage_radius = 0.002; ///< m, a surface point is covered within this distance
};

struct ScanResult {
  PointCloud fine;     ///< object frame, outward unit normals
  PointCloud coarse;   ///< voxel-filtered fine cloud, outward unit normals
  double coverage = 0.0;  ///< fraction of mesh area within coverage_radius of a fine point
  int views = 0;
};

/// Scan the mesh from viewpoints chosen greedily toward the least-covered surface (the widest
/// unexplored cone), with a random view every `random_every`. Deterministic for a given seed.
ScanResult scan_mesh(const MeshIndex& mesh, const ScanSettings& settings, std::uint64_t seed);

/// Fraction of mesh area within `radius` of some point (area-weighted surface samples).
double surface_coverage(const MeshIndex& mesh, const std::vector<Vec3>& points, double radius,
                        std::uint64_t seed, int samples = 20000);

}  // namespace ts
