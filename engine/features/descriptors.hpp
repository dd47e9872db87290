// Local shape descriptors behind one interface: FPFH (the engine's feature), and the three the
// paper compared it with in Section 4.3.1 (Figure 9): PFH, SHOT and Spin Images, each computed
// as the Point Cloud Library computes it with the defaults the paper names.
#pragma once

#include "engine/core.hpp"
#include "engine/geometry/search.hpp"

#include <span>
#include <string>
#include <string_view>

namespace ts {
inline namespace features {

enum class Descriptor {
  fpfh,   ///< Fast Point Feature Histograms (Rusu, Blodow & Beetz 2009), 3 x 11 = 33 bins
  pfh,    ///< Point Feature Histograms (Rusu, Marton, Blodow & Beetz 2008), 5^3 = 125 bins
  shot,   ///< Signature of Histograms of OrienTations (Tombari, Salti & Di Stefano 2010), 32 x 11 = 352
  spin,   ///< Spin Images (Johnson & Hebert 1998), image width 8: 9 x 17 = 153 bins
};

/// All four, in the order of the enum.
inline constexpr Descriptor kAllDescriptors[] = {Descriptor::fpfh, Descriptor::pfh, Descriptor::shot,
                                                 Descriptor::spin};

/// "fpfh", "pfh", "shot", "spin".
std::string descriptor_name(Descriptor d);
/// The inverse of descriptor_name; throws ts::Error naming the bad value (field "descriptor").
Descriptor parse_descriptor(std::string_view name);
/// Values per descriptor: 33, 125, 352, 153.
int descriptor_dim(Descriptor d);

struct DescriptorSettings {
  double feature_radius = 0.010;  ///< m, neighbourhood (support) radius of every descriptor
                                  ///< (recognition: 10 mm; the paper's comparison: 15 mm)
  double shot_lrf_radius = 0.0;   ///< m, SHOT's local reference frame radius; 0: feature_radius
                                  ///< (PCL's default, the paper's "0 lrf radius")
};

/// Descriptors of a set of keypoints: row i is values[i * dim .. (i + 1) * dim).
struct Descriptors {
  int dim = 0;
  std::vector<float> values;   ///< size() * dim, row-major; an invalid row is all zeros
  std::vector<bool> valid;     ///< one per keypoint

  std::size_t size() const { return valid.size(); }
  std::span<const float> row(std::size_t i) const {
    return {values.data() + i * static_cast<std::size_t>(dim), static_cast<std::size_t>(dim)};
  }
};

/// Descriptor `d` at each keypoint from its neighbourhood (within feature_radius, inclusive) in
/// `surface`, a cloud with unit normals indexed by `surface_tree` (built over surface.points).
/// Keypoints need not belong to the surface. Each is computed as PCL computes it:
///  - fpfh: compute_fpfh (engine/features/fpfh.hpp); valid with at least 2 neighbours other than itself.
///  - pfh: PFHEstimation, 5 bins per pair feature (f1 atan2 angle, f2, f3) from
///    pcl::computePairFeatures over every unordered pair of the neighbourhood (the keypoint's
///    own point included when it lies in the surface), bin f1 + 5 f2 + 25 f3, each pair adding
///    100 / (n (n - 1) / 2), so the histogram sums to 100. A degenerate pair (the same point
///    twice, or the line along the normal) is binned as PCL's PFHEstimation bins it, with
///    f = (0, 0, 0) (bin 62); a pair with a non-finite point or normal is left out (PCL's
///    binning of NaN is undefined). Valid with at least one pair counted.
///  - shot: SHOTEstimation with SHOTLocalReferenceFrameEstimation (weighted covariance,
///    eigenvectors' signs by the majority of neighbours): 32 volumes (8 azimuth x 2 elevation
///    x 2 radial) x 11 cosine bins (PCL's 10 shape bins + 1), PCL's interpolation on cosine,
///    radius, elevation and azimuth, unit Euclidean norm. Valid when the frame has at least 5
///    neighbours apart from the keypoint.
///  - spin: SpinImageEstimation(image_width = 8, support_angle_cos = 0, min_pts_neighb = 0),
///    rectangular (not radial, not angular), the keypoint's normal as the spin axis; bins
///    alpha x beta = 9 x 17, bilinear votes, divided by their sum. Needs keypoint_normals.
///    Valid when some neighbour falls inside the support cylinder.
/// keypoint_normals: empty, or one unit normal per keypoint (required for spin, unused by the
/// others). Deterministic for any thread count (TBB inside the caller's arena, each keypoint
/// writes its own row). Throws ts::Error on inconsistent inputs (sizes, missing normals, a
/// non-positive radius).
Descriptors compute_descriptors(Descriptor d, const std::vector<Vec3>& keypoints,
                                const std::vector<Vec3>& keypoint_normals, const PointCloud& surface,
                                const KdTree3& surface_tree, const DescriptorSettings& settings);

}  // namespace features
}  // namespace ts
