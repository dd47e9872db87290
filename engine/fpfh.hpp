// Fast Point Feature Histograms (Rusu, Blodow & Beetz 2009), 33 bins, as in PCL.
#pragma once

#include "engine/core.hpp"
#include "engine/search.hpp"

namespace ts {

struct FpfhSettings {
  double normal_radius = 0.007;   ///< m, PCA normal radius (paper: 7 mm)
  double feature_radius = 0.010;  ///< m, FPFH neighbourhood radius (paper: 10 mm)
};

/// FPFH at each `keypoints[i]` from the neighbourhood in `surface` (points with normals, indexed
/// by `surface_tree`, which must be built over surface.points). A keypoint whose neighbourhood
/// has fewer than 2 points other than itself gets a zero histogram and valid[i] = false.
struct FpfhResult {
  std::vector<Feature> features;
  std::vector<bool> valid;
};
FpfhResult compute_fpfh(const std::vector<Vec3>& keypoints, const std::vector<Vec3>& keypoint_normals,
                        const PointCloud& surface, const KdTree3& surface_tree,
                        const FpfhSettings& settings);

}  // namespace ts
