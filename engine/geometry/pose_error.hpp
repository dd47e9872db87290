// Pose errors as in Section 5.2 of the paper: position error (distance between the true and the
// estimated object origin), orientation error (Eq. 10: the angle of the relative rotation), and
// the symmetry-aware variants (the smallest error over the rotations that map the object onto
// itself, see engine/geometry/symmetry.hpp).
#pragma once

#include "engine/core.hpp"
#include "engine/geometry/symmetry.hpp"

namespace ts {
inline namespace geometry {

struct PoseError {
  double position_m = 0.0;                 ///< |t_est - t_true| (Section 5.2)
  double orientation_deg = 0.0;            ///< Eq. 10 on R_true^T R_est, in [0, 180]
  double symmetric_orientation_deg = 0.0;  ///< min of Eq. 10 over the object's symmetries
  double symmetric_position_m = 0.0;       ///< position error under the minimizing symmetry
};

/// Errors of an estimated pose T_world_object against the truth. With `symmetries` null (or
/// trivial) the symmetric errors equal the plain ones. Never NaN for finite inputs; non-finite
/// poses give the worst values (inf, 180, 180, inf).
PoseError pose_error(const Pose& estimate, const Pose& truth,
                     const SymmetryGroup* symmetries = nullptr);

/// Eq. 10 literally: arccos((tr(R) - 1) / 2), clamped to [0, pi] (for tests and reference).
double rotation_angle_eq10(const Mat3& R);

}  // namespace geometry
}  // namespace ts
