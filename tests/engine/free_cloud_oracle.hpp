// Test oracle of OccupancyGrid::full_free_cloud (engine/touch/free_space.hpp): the recognizer's
// free-space cloud PC^free (Section 4.1.2) by brute force over every free voxel: one point per
// cube of size res that is ENTIRELY free, at the cube's centre, inside the box B of Eq. 3.
#pragma once

#include "engine/touch/free_space.hpp"

#include <algorithm>
#include <array>
#include <cmath>

namespace ts::test {

/// Centres of the cubes [k * res, (k + 1) * res)^3 (k integer, relative to the grid's origin)
/// whose every voxel is free and whose centre lies in `box` (world frame); ordered by cube key.
/// res should be a multiple of the grid's voxel. Deterministic.
inline std::vector<Vec3> full_free_cloud(const OccupancyGrid& grid, const Eigen::AlignedBox3d& box,
                                  double res) {
  std::vector<Vec3> out;
  if (box.isEmpty() || !(res > 0.0)) return out;
  const double v = grid.voxel();
  const Vec3 o = grid.origin();
  const long per_axis = std::max(1L, std::lround(res / v));
  const long full = per_axis * per_axis * per_axis;
  // Cube key of every free voxel centre (voxel centres sit at origin + ijk * v).
  std::vector<std::array<long, 3>> keys;
  for (const Vec3& c : grid.free_centres()) {
    const Vec3 l = (c - o) / res;
    keys.push_back({static_cast<long>(std::floor(l.x() + 1e-9)), static_cast<long>(std::floor(l.y() + 1e-9)),
                    static_cast<long>(std::floor(l.z() + 1e-9))});
  }
  std::sort(keys.begin(), keys.end());
  for (std::size_t b = 0; b < keys.size();) {
    std::size_t e = b;
    while (e < keys.size() && keys[e] == keys[b]) ++e;
    if (static_cast<long>(e - b) >= full) {
      const Vec3 centre = o + res * Vec3(double(keys[b][0]) + 0.5, double(keys[b][1]) + 0.5,
                                         double(keys[b][2]) + 0.5);
      if (box.contains(centre)) out.push_back(centre);
    }
    b = e;
  }
  return out;
}

}  // namespace ts::test
