#include "engine/geometry/kabsch.hpp"

#include <Eigen/Eigenvalues>
#include <Eigen/SVD>

#include <algorithm>
#include <cmath>
#include <numbers>

namespace ts {
inline namespace geometry {

namespace {

// Weighted centroid computed relative to the first point, so that large absolute coordinates
// (100 km from the origin) lose no precision in the sums.
Vec3 centroid_of(std::span<const Vec3> p, std::span<const double> w, double wsum) {
  const Vec3 ref = p[0];
  Vec3 acc = Vec3::Zero();
  for (std::size_t i = 0; i < p.size(); ++i) acc += (w.empty() ? 1.0 : w[i]) * (p[i] - ref);
  return ref + acc / wsum;
}

// Sorted (descending) square roots of the eigenvalues of the weighted covariance.
Vec3 spreads_of(std::span<const Vec3> p, std::span<const double> w, const Vec3& c, double wsum) {
  Mat3 cov = Mat3::Zero();
  for (std::size_t i = 0; i < p.size(); ++i) {
    const Vec3 d = p[i] - c;
    cov.noalias() += (w.empty() ? 1.0 : w[i]) * d * d.transpose();
  }
  cov /= wsum;
  Eigen::SelfAdjointEigenSolver<Mat3> es(cov, Eigen::EigenvaluesOnly);
  const Vec3 ev = es.eigenvalues();  // ascending
  return {std::sqrt(std::max(0.0, ev[2])), std::sqrt(std::max(0.0, ev[1])),
          std::sqrt(std::max(0.0, ev[0]))};
}

}  // namespace

Vec3 principal_spreads(std::span<const Vec3> points) {
  if (points.empty()) return Vec3::Zero();
  for (const Vec3& p : points)
    if (!finite(p)) return Vec3::Zero();
  const double n = static_cast<double>(points.size());
  const Vec3 c = centroid_of(points, {}, n);
  return spreads_of(points, {}, c, n);
}

bool triangle_well_conditioned(const Vec3& a, const Vec3& b, const Vec3& c, double min_sv_ratio) {
  const std::array<Vec3, 3> pts{a, b, c};
  const Vec3 s = principal_spreads(pts);
  if (!(s[0] > 0.0)) return false;
  return s[1] >= min_sv_ratio * s[0];
}

Mat3 rotation_from_covariance(const Mat3& H, bool* reflected) {
  Eigen::JacobiSVD<Mat3> svd(H, Eigen::ComputeFullU | Eigen::ComputeFullV);
  const Mat3& U = svd.matrixU();
  const Mat3& V = svd.matrixV();
  // Reflection fix (Umeyama 1991): R = V diag(1, 1, det(V U^T)) U^T.
  Mat3 D = Mat3::Identity();
  const bool reflection = (V * U.transpose()).determinant() < 0.0;
  if (reflection) D(2, 2) = -1.0;
  if (reflected) *reflected = reflection;
  return V * D * U.transpose();
}

namespace {

/// A point set's centroid and spreads as kabsch() uses them.
struct Side {
  Vec3 centroid, spreads;
};
Side side_of(std::span<const Vec3> p, std::span<const double> w, double wsum) {
  const Vec3 c = centroid_of(p, w, wsum);
  return {c, spreads_of(p, w, c, wsum)};
}

/// kabsch() with the target's side given (`prepared`, unweighted) or computed (null).
RigidFit fit_pairs(std::span<const Vec3> source, std::span<const Vec3> target, std::span<const double> weights,
                   const KabschSettings& settings, const Side* prepared, bool target_finite) {
  RigidFit fit;
  const std::size_t n = source.size();
  if (n < 3 || target.size() != n || (!weights.empty() && weights.size() != n)) return fit;
  if (prepared && !target_finite) return fit;
  double wsum = 0.0;
  for (std::size_t i = 0; i < n; ++i) {
    if (!finite(source[i]) || (!prepared && !finite(target[i]))) return fit;
    const double w = weights.empty() ? 1.0 : weights[i];
    if (!(w >= 0.0) || !std::isfinite(w)) return fit;
    wsum += w;
  }
  if (!(wsum > 0.0)) return fit;

  const Side src = side_of(source, weights, wsum);
  const Side tgt = prepared ? *prepared : side_of(target, weights, wsum);
  const Vec3 &cs = src.centroid, &ct = tgt.centroid, &ss = src.spreads, &st = tgt.spreads;
  if (ss[0] < settings.min_spread || st[0] < settings.min_spread) return fit;
  fit.sv_ratio = std::min(ss[1] / ss[0], st[1] / st[0]);
  if (!(fit.sv_ratio >= settings.min_sv_ratio)) return fit;

  // Cross-covariance of the centred sets (Arun et al., Eq. 11): H = sum w (s - cs)(t - ct)^T.
  Mat3 H = Mat3::Zero();
  for (std::size_t i = 0; i < n; ++i) {
    const double w = weights.empty() ? 1.0 : weights[i];
    H.noalias() += w * (source[i] - cs) * (target[i] - ct).transpose();
  }
  const Mat3 R = rotation_from_covariance(H, &fit.reflection_fixed);
  if (!R.allFinite()) return fit;

  double sq = 0.0;
  for (std::size_t i = 0; i < n; ++i) {
    const double w = weights.empty() ? 1.0 : weights[i];
    sq += w * (R * (source[i] - cs) - (target[i] - ct)).squaredNorm();
  }
  fit.rms = std::sqrt(sq / wsum);
  fit.T_target_source.linear() = R;
  fit.T_target_source.translation() = ct - R * cs;
  fit.valid = fit.T_target_source.matrix().allFinite() && std::isfinite(fit.rms);
  if (!fit.valid) fit.T_target_source = Pose::Identity();
  return fit;
}

}  // namespace

RigidFit kabsch(std::span<const Vec3> source, std::span<const Vec3> target,
                std::span<const double> weights, const KabschSettings& settings) {
  return fit_pairs(source, target, weights, settings, nullptr, false);
}

KabschTarget::KabschTarget(std::span<const Vec3> target) : points_(target.begin(), target.end()) {
  finite_ = std::all_of(points_.begin(), points_.end(), [](const Vec3& p) { return finite(p); });
  // kabsch()'s sum of n unit weights, which is n exactly
  const auto wsum = static_cast<double>(points_.size());
  if (finite_ && wsum > 0.0) {
    const Side side = side_of(points_, {}, wsum);
    centroid_ = side.centroid;
    spreads_ = side.spreads;
  }
}

RigidFit kabsch(std::span<const Vec3> source, const KabschTarget& target, const KabschSettings& settings) {
  const Side side{target.centroid_, target.spreads_};
  return fit_pairs(source, target.points_, {}, settings, &side, target.finite_);
}

double rotation_angle(const Mat3& R) {
  if (!R.allFinite()) return std::numbers::pi;
  Eigen::Quaterniond q(R);
  q.normalize();
  const double v = q.vec().norm();
  return 2.0 * std::atan2(v, std::abs(q.w()));
}

}  // namespace geometry
}  // namespace ts
