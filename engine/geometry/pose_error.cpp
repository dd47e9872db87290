#include "engine/geometry/pose_error.hpp"
#include "engine/detail.hpp"

#include "engine/geometry/eigen_solvers.hpp"
#include "engine/geometry/kabsch.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>

namespace ts {
inline namespace geometry {

namespace {

using detail::kDegPerRad;

/// Minimal rotation taking unit vector `from` to unit vector `to` (the quaternion normalized:
/// see sweep_candidates in congruence.cpp).
Mat3 minimal_rotation(const Vec3& from, const Vec3& to) {
  return quaternion_from_two_vectors(from, to).normalized().toRotationMatrix();
}

}  // namespace

double rotation_angle_eq10(const Mat3& R) {
  return std::acos(std::clamp((R.trace() - 1.0) / 2.0, -1.0, 1.0));
}

PoseError pose_error(const Pose& estimate, const Pose& truth, const SymmetryGroup* sym) {
  PoseError e;
  if (!estimate.matrix().allFinite() || !truth.matrix().allFinite()) {
    const double inf = std::numeric_limits<double>::infinity();
    return {inf, 180.0, 180.0, inf};
  }
  const Mat3 Rt = truth.linear(), Re = estimate.linear();
  e.position_m = (estimate.translation() - truth.translation()).norm();
  const Mat3 Q = Rt.transpose() * Re;  // relative rotation in the object frame
  e.orientation_deg = rotation_angle(Q) * kDegPerRad;
  e.symmetric_orientation_deg = e.orientation_deg;
  e.symmetric_position_m = e.position_m;
  if (sym == nullptr || sym->trivial()) return e;

  // Equivalent truths: truth * G for every symmetry G (object frame, fixing sym->centre).
  // The error of the estimate against truth * G is angle(G^T Q).
  double best = std::numeric_limits<double>::infinity();
  Mat3 bestG = Mat3::Identity();
  auto consider = [&](const Mat3& G) {
    const double a = rotation_angle(G.transpose() * Q);
    if (a < best) { best = a; bestG = G; }
  };
  if (sym->kind == SymmetryGroup::Kind::spherical) {
    consider(Q);  // G = Q is a symmetry: zero orientation error
  } else if (sym->kind == SymmetryGroup::Kind::axial) {
    // G = Ra(phi) D. angle(G^T Q) = angle(Ra(-phi) M) with M = Q D^T, minimized (over phi) by
    // the minimal rotation X taking b = M^T a to a; then Ra(phi*) = (X M^T)^T = M X^T.
    const Vec3 a = sym->axis.normalized();
    for (const Mat3& D : sym->rotations) {
      const Mat3 M = Q * D.transpose();
      const Vec3 b = (M.transpose() * a).normalized();
      const Mat3 X = minimal_rotation(b, a);
      const Mat3 Ra = M * X.transpose();
      consider(Ra * D);
    }
  } else {
    for (const Mat3& G : sym->rotations) consider(G);
  }
  e.symmetric_orientation_deg = best * kDegPerRad;
  const Pose equivalent = truth * sym->transform(bestG);
  e.symmetric_position_m = (estimate.translation() - equivalent.translation()).norm();
  return e;
}

}  // namespace geometry
}  // namespace ts
