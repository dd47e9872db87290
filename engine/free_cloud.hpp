// The free-space cloud PC^free as the recognizer's Eq. 8 expects it (Section 4.1.2): one point per
// cube of size res_free that is ENTIRELY free, at the cube's centre, inside the box B of Eq. 3.
// This is what sampling an octree's free leaves at res_free gives (an inner octree node is free
// only when all its children are), and it is why the paper can use d_thresh = res_free / 2: a
// fully free cube's centre is at least res_free / 2 (per axis) from anything not known to be free,
// so the true object never costs free-space error. A cloud that also samples partly free cubes
// puts points right next to the surface and makes Eq. 8 penalize the true pose most of all.
#pragma once

#include "engine/free_space.hpp"

namespace ts {

/// Centres of the cubes [k * res, (k + 1) * res)^3 (k integer, relative to the grid's origin)
/// whose every voxel is free and whose centre lies in `box` (world frame); ordered by cube key.
/// res should be a multiple of the grid's voxel. Deterministic.
std::vector<Vec3> full_free_cloud(const OccupancyGrid& grid, const Eigen::AlignedBox3d& box,
                                  double res);

}  // namespace ts
