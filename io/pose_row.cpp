#include "io/pose_row.hpp"

#include <cmath>

namespace ts::io {

std::array<double, 7> pose_row(const Pose& T) {
  const Eigen::Quaterniond q(T.linear());
  const Vec3 t = T.translation();
  return {t.x(), t.y(), t.z(), q.w(), q.x(), q.y(), q.z()};
}

std::array<double, 7> canonical_pose_row(const Pose& T) {
  Eigen::Quaterniond q(T.linear());
  q.normalize();
  if (q.w() < 0) q.coeffs() = -q.coeffs();
  const Vec3 t = T.translation();
  return {t.x(), t.y(), t.z(), q.w(), q.x(), q.y(), q.z()};
}

Pose pose_from_row(const double* t, const double* q) {
  Eigen::Quaterniond qq(q[0], q[1], q[2], q[3]);
  if (!(qq.norm() > 0.0)) qq = Eigen::Quaterniond::Identity();
  Pose T = Pose::Identity();
  T.linear() = qq.normalized().toRotationMatrix();
  T.translation() = Vec3(t[0], t[1], t[2]);
  return T;
}

Pose checked_pose_from_row(const double* r, const std::string& file, const std::string& field) {
  for (int i = 0; i < 7; ++i)
    if (!std::isfinite(r[i])) throw Error("pose holds a non-finite value", file, field);
  const double norm = Eigen::Quaterniond(r[3], r[4], r[5], r[6]).norm();
  if (std::abs(norm - 1.0) > 1e-3)
    throw Error("pose quaternion has norm " + std::to_string(norm) + ", expected 1", file, field);
  return pose_from_row(r);
}

}  // namespace ts::io
