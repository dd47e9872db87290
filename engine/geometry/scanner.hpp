// Simulated laser scanner (Section 4.2): builds an object's database clouds from its mesh.
#pragma once

#include "engine/core.hpp"
#include "engine/geometry/mesh.hpp"

namespace ts {
inline namespace geometry {

/// The simulated laser scanner. Each view is an orthographic raster of parallel rays (a laser
/// line scanner swept across the object) covering the object's projection; the first hits are
/// kept. Views are chosen greedily, toward the direction that sees the most still-uncovered
/// surface (the widest unexplored cone, Aggarwal & Kampmann 2012), with a random direction
/// every `random_every` views to escape local minima. Scanning stops at `target_coverage`, at
/// `max_views`, or when `stall_views` consecutive views each add less than `min_gain`
/// (concave pockets that parallel rays from outside cannot reach).
struct ScanSettings {
  double fine_spacing = 0.0015;   ///< m, voxel size of the fine cloud (one point per voxel)
  double coarse_voxel = 0.005;    ///< m, voxel filter of the coarse (feature) cloud
  double ray_pitch = 0.8;         ///< raster pitch of one view, as a fraction of fine_spacing
  int max_views = 200;            ///< upper bound on scanner viewpoints
  int candidate_views = 256;      ///< directions (Fibonacci sphere) the greedy choice scores
  double target_coverage = 0.995; ///< stop when this fraction of the area is scanned
  int random_every = 8;           ///< every k-th view is a random direction (escapes minima)
  int stall_views = 4;            ///< stop after this many consecutive views below min_gain
  double min_gain = 2e-4;         ///< fraction of the area a view must add to count as progress
  double coverage_radius = 0.002; ///< m, a surface point is covered within this distance
  double max_incidence_deg = 60;  ///< deg, first phase: a point counts as scanned only once hit
                                  ///< at an incidence below this (dense, non-grazing data)
  double grazing_incidence_deg = 85; ///< deg, second phase (when the first stalls): mop up
                                     ///< surface reachable only at grazing incidence
  int coverage_samples = 20000;   ///< area-weighted surface samples (tracking and final measure)
};

struct ScanResult {
  PointCloud fine;     ///< object frame, on the surface, outward unit normals
  PointCloud coarse;   ///< one fine point per coarse_voxel (voxel_representatives), with normal
  double coverage = 0.0;  ///< fraction of mesh area within coverage_radius of a fine point
  int views = 0;
  std::size_t rays = 0;   ///< rays cast by all views together
  std::vector<Vec3> directions;  ///< unit ray direction of each view, in scan order
};

/// Scan the mesh (see ScanSettings). The fine cloud keeps, per fine_spacing voxel, the hit
/// nearest to the voxel's centroid (so points lie exactly on the surface) with the hit face's
/// normal turned toward the scanner (outward for closed, outward-wound meshes). Uses TBB inside;
/// the result is identical for any thread count and deterministic for a given seed.
ScanResult scan_mesh(const MeshIndex& mesh, const ScanSettings& settings, std::uint64_t seed);

/// One view of the scanner: the first hits of an orthographic raster of parallel rays along
/// `direction` (pitch in m) covering the mesh, in raster order, with the hit faces' normals
/// turned toward the scanner. scan_mesh is made of such views.
PointCloud scan_view(const MeshIndex& mesh, const Vec3& direction, double pitch);

/// Fraction of mesh area within `radius` of some point (area-weighted surface samples drawn
/// from ts::Rng(seed); 0 for an empty mesh or an empty cloud).
double surface_coverage(const MeshIndex& mesh, const std::vector<Vec3>& points, double radius,
                        std::uint64_t seed, int samples = 20000);

}  // namespace geometry
}  // namespace ts
