// Free space (Section 4.1.2): a sparse occupancy grid (OpenVDB) of states unknown / free /
// occupied, updated with contact points (occupied) and the swept volume of the gripper links
// while closing (free), and the free-space cloud sampled at res_free inside the box B of Eq. 3.
//
// The grid works in a local frame: voxel (i, j, k) has its centre at origin + (i, j, k) * voxel,
// with `origin` fixed at construction (in world coordinates). Dive logs sit far from the world
// origin (100 km), so every coordinate is taken relative to `origin` in double precision before
// it is divided by the voxel size.
//
// Updates commute: a voxel is occupied when any contact fell in it, else free when any swept
// link covered its centre, else unknown. So grids built grasp by grasp, in any order or in
// parallel and then merged, are identical.
//
// Not thread-safe for writes; const queries are thread-safe except free_cloud (it caches).
#pragma once

#include "engine/core.hpp"
#include "engine/touch/gripper.hpp"

#include <memory>

namespace ts {
inline namespace touch {

struct FreeSpaceSettings {
  double voxel = 0.004;      ///< m, occupancy voxel size
  double res_free = 0.04;    ///< m, free-space cloud sampling (paper: 4 cm)
  double s_obj_max = 0.20;   ///< m, largest object length in the database (Eq. 3)
  bool palm = true;          ///< the palm disc counts as swept volume too
};

enum class Occupancy : std::uint8_t { unknown = 0, free = 1, occupied = 2 };

class OccupancyGrid {
 public:
  OccupancyGrid(double voxel, const Vec3& origin);
  ~OccupancyGrid();
  OccupancyGrid(OccupancyGrid&&) noexcept;
  OccupancyGrid& operator=(OccupancyGrid&&) noexcept;
  OccupancyGrid(const OccupancyGrid&);
  OccupancyGrid& operator=(const OccupancyGrid&);

  double voxel() const;
  const Vec3& origin() const;

  /// Mark free every voxel whose centre lies inside the box [lo, hi] given in the frame
  /// T_world_box (occupied voxels stay occupied).
  void mark_free_box(const Pose& T_world_box, const Vec3& lo, const Vec3& hi);
  /// Mark free every voxel whose centre lies in the cylinder of `radius` about the z axis of
  /// T_world_cyl, z ∈ [z0, z1].
  void mark_free_cylinder(const Pose& T_world_cyl, double radius, double z0, double z1);
  /// Mark occupied the voxel holding p.
  void mark_occupied(const Vec3& p_world);
  /// Union with another grid of the same voxel size and origin (occupied wins).
  void merge(const OccupancyGrid& other);

  Occupancy state(const Vec3& p_world) const;
  std::size_t free_count() const;
  std::size_t occupied_count() const;
  /// Centres of all free voxels in world coordinates, ordered by (i, j, k).
  std::vector<Vec3> free_centres() const;
  /// Free-space cloud (Section 4.1.2): one point per cube of size `res` (cubes aligned to the
  /// grid origin) that holds a free voxel centre inside `box` (world): the free voxel centre
  /// nearest to the cube's centre (ties: the smaller (i, j, k)). Every point is a real free
  /// voxel centre, never an average that could fall inside the object. Ordered by cube key.
  /// Cost: proportional to the number of cubes; per-cube counts are cached on the first call
  /// with a given `res` and then kept current by every update, so this call is not
  /// thread-safe (the other const queries are).
  std::vector<Vec3> free_cloud(const Eigen::AlignedBox3d& box, double res) const;
  /// The recognizer's PC^free (Section 4.1.2, Eq. 8): the centre of every cube of size `res`
  /// (aligned to the grid origin) whose voxels are ALL free, when the centre lies in `box`;
  /// ordered by cube key. What sampling an octree's free leaves at res gives: such a centre is
  /// at least res / 2 per axis from anything not known free, so d_thresh = res / 2 never
  /// penalizes the true object. Same cost and caching (not thread-safe) as free_cloud; equal
  /// to the brute-force oracle of tests/engine/free_cloud_oracle.hpp. `res` should be a multiple
  /// of the voxel.
  std::vector<Vec3> full_free_cloud(const Eigen::AlignedBox3d& box, double res) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

/// Mark the swept volume of one grasp free: the rigid link boxes (not the foam) along the
/// closing path from the open hand to `joints` (Gripper::closing_waypoints), sampled so that no
/// link point moves more than half a voxel between samples, plus the palm when settings.palm.
void mark_swept_volume(OccupancyGrid& grid, const Gripper& gripper, const Pose& T_world_eef,
                       const std::vector<double>& joints, const FreeSpaceSettings& settings);

/// Points the hand held free at the end of one grasp: samples, at most `spacing` apart, of the
/// faces of its rigid link boxes that lead the closing (the inner face and the tip) at the final
/// joint angles, and of the palm's front disc when settings.palm (world frame). They are nearer the object than anything the free-space cloud
/// keeps (every link stopped at the object or at its limit) and share the grasp's arm pose error
/// with its contacts: the near-twin verification shifts both by the grasp's offset.
std::vector<Vec3> hand_surface_samples(const Gripper& gripper, const Pose& T_world_eef,
                                       const std::vector<double>& joints, double spacing,
                                       const FreeSpaceSettings& settings);

/// Box B of Eq. 3 around the cumulative contacts: centred on their centroid, sides = their
/// bounding-box size + 2 s_obj_max. Empty box when there are no contacts.
Eigen::AlignedBox3d free_space_box(const std::vector<Vec3>& contacts, double s_obj_max);

}  // namespace touch
}  // namespace ts
