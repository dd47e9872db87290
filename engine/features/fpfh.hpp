// Fast Point Feature Histograms (Rusu, Blodow & Beetz 2009), 33 bins, as in PCL.
#pragma once

#include "engine/core.hpp"
#include "engine/geometry/search.hpp"

namespace ts {
inline namespace features {

struct FpfhSettings {
  double normal_radius = 0.007;   ///< m, PCA normal radius (paper: 7 mm); not used by compute_fpfh
  double feature_radius = 0.010;  ///< m, FPFH neighbourhood radius (paper: 10 mm)
};

/// FPFH at each `keypoints[i]` from the neighbourhood in `surface` (points with normals, indexed
/// by `surface_tree`, which must be built over surface.points). A keypoint whose neighbourhood
/// has fewer than 2 points other than itself gets a zero histogram and valid[i] = false.
///
/// Computed as PCL's FPFHEstimation does (see fpfh.cpp): FPFH(p) = sum over neighbours p_k
/// within feature_radius, p_k != p, of SPFH(p_k) / |p - p_k|^2, each 11-bin block (f1 = atan2
/// angle, f2, f3) then scaled to sum to 100. The SPFH of p_k uses p_k's own neighbourhood in
/// `surface`. As in PCL the keypoint's own SPFH is not added, so `keypoint_normals` (empty or
/// one per keypoint) does not change the result. Deterministic for any thread count; uses TBB
/// inside the caller's arena. Throws ts::Error on inconsistent inputs (sizes, missing normals).
struct FpfhResult {
  std::vector<Feature> features;
  std::vector<bool> valid;
};
FpfhResult compute_fpfh(const std::vector<Vec3>& keypoints, const std::vector<Vec3>& keypoint_normals,
                        const PointCloud& surface, const KdTree3& surface_tree,
                        const FpfhSettings& settings);

}  // namespace features
}  // namespace ts
