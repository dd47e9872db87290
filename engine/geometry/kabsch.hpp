// Least-squares rigid registration of paired points (Arun, Huang & Blostein 1987, with Umeyama's
// reflection fix), used by triplet registration (Section 4.3.2) and every ICP iteration.
// Numerics: both point sets are centred in a local frame before anything is squared (dive logs
// sit far from the origin), and degenerate configurations are rejected by geometry (the ratio of
// singular values of the centred points), never by the residual.
#pragma once

#include "engine/core.hpp"

#include <span>
#include <vector>

namespace ts {
inline namespace geometry {

struct KabschSettings {
  double min_sv_ratio = 1e-3;   ///< sigma2/sigma1 of either centred set below this: degenerate
  double min_spread = 1e-12;    ///< m, sigma1 (RMS radius) below this: all points coincide
};

/// A rigid fit target_i ~= T_target_source * source_i, with diagnostics.
struct RigidFit {
  Pose T_target_source = Pose::Identity();
  bool valid = false;             ///< false: too few points, non-finite, coincident or collinear
  bool reflection_fixed = false;  ///< the unconstrained optimum was a reflection (det = -1)
  double rms = 0.0;               ///< m, weighted RMS residual after the fit
  double sv_ratio = 0.0;          ///< min over both sets of sigma2/sigma1 of the centred points
};

/// Weighted Kabsch/Arun. `weights` is empty (all 1) or one non-negative weight per pair.
/// Never returns NaN: invalid inputs give valid = false and the identity.
RigidFit kabsch(std::span<const Vec3> source, std::span<const Vec3> target,
                std::span<const double> weights = {}, const KabschSettings& settings = {});

/// A target point set met by many sources (a scene triplet registered against many model
/// triplets): its centroid and principal spreads computed once, not once a fit. kabsch(source,
/// target) gives the same fit as the unweighted kabsch(source, target.points()), bit for bit.
class KabschTarget {
 public:
  KabschTarget() = default;   ///< no points: every fit invalid
  explicit KabschTarget(std::span<const Vec3> target);
  std::span<const Vec3> points() const { return points_; }

 private:
  friend RigidFit kabsch(std::span<const Vec3> source, const KabschTarget& target, const KabschSettings& settings);
  std::vector<Vec3> points_;
  bool finite_ = false;       ///< every point finite (kabsch() checks nothing else of them)
  Vec3 centroid_ = Vec3::Zero(), spreads_ = Vec3::Zero();
};

/// Unweighted Kabsch/Arun against a prepared target (see KabschTarget).
RigidFit kabsch(std::span<const Vec3> source, const KabschTarget& target, const KabschSettings& settings = {});

/// The rotation R maximizing trace(R H) for a cross-covariance H = sum w s t^T of centred pairs,
/// i.e. minimizing sum w |R s - t|^2 (Arun et al. 1987 by SVD, with Umeyama's reflection fix:
/// R = V diag(1, 1, det(V U^T)) U^T). `reflected`: the unconstrained optimum was a reflection.
/// Given H = M^T it is the rotation nearest to M. The one SVD step of kabsch(), the symmetry
/// search's rotation-only ICP and recognize's ground-truth reader.
Mat3 rotation_from_covariance(const Mat3& H, bool* reflected = nullptr);

/// Singular values (descending) of the centred point set, divided by sqrt(n): the RMS spreads
/// along the principal axes. Computed in a frame centred on the points.
Vec3 principal_spreads(std::span<const Vec3> points);

/// Geometric test of a triangle (triplet sampling and registration, Section 4.3.2): true when the
/// three points are finite, pairwise distinct and far from collinear, i.e. the smaller in-plane
/// spread is at least `min_sv_ratio` times the larger. Independent of position and scale.
bool triangle_well_conditioned(const Vec3& a, const Vec3& b, const Vec3& c, double min_sv_ratio);

/// The rotation angle of R in radians, in [0, pi] (Eq. 10), computed stably near 0 and pi
/// (from the quaternion rather than arccos of the trace).
double rotation_angle(const Mat3& R);

}  // namespace geometry
}  // namespace ts
