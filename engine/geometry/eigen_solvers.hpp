// Eigen's heavy solvers, compiled once: their templates take several seconds to instantiate in
// each file that uses them (scripts/ci_profile, -ftime-trace). The results are Eigen's own.
#pragma once

#include "engine/core.hpp"

namespace ts {
inline namespace geometry {

/// Eigen::Quaterniond::FromTwoVectors(from, to): a rotation taking direction `from` to
/// direction `to` (not normalized: Eigen's result as it is).
Eigen::Quaterniond quaternion_from_two_vectors(const Vec3& from, const Vec3& to);

/// The eigenvalues of the symmetric 6x6 matrix `A`, ascending (Eigen::SelfAdjointEigenSolver
/// with Eigen::EigenvaluesOnly; only the lower triangle is read).
Eigen::Matrix<double, 6, 1> symmetric_eigenvalues(const Eigen::Matrix<double, 6, 6>& A);

}  // namespace geometry
}  // namespace ts
