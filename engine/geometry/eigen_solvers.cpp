#include "engine/geometry/eigen_solvers.hpp"

#include <Eigen/Eigenvalues>

namespace ts {
inline namespace geometry {

Eigen::Quaterniond quaternion_from_two_vectors(const Vec3& from, const Vec3& to) {
  return Eigen::Quaterniond::FromTwoVectors(from, to);
}

Eigen::Matrix<double, 6, 1> symmetric_eigenvalues(const Eigen::Matrix<double, 6, 6>& A) {
  return Eigen::SelfAdjointEigenSolver<Eigen::Matrix<double, 6, 6>>(A, Eigen::EigenvaluesOnly).eigenvalues();
}

}  // namespace geometry
}  // namespace ts
