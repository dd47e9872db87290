// Poses in Touchstone's files, one convention for tactile logs, run stores and result files:
// the translation [tx, ty, tz] (m) and a unit quaternion [qw, qx, qy, qz] (w first) of the
// rotation. Logs and run stores keep the seven numbers in one row; result files split them into
// t and q and ask more of q (normalized, w >= 0: one quaternion per rotation).
#pragma once

#include "engine/core.hpp"

#include <array>
#include <string>

namespace ts::io {

/// [tx, ty, tz, qw, qx, qy, qz]: the quaternion as Eigen computes it from the rotation.
std::array<double, 7> pose_row(const Pose& T);

/// The row's quaternion normalized with w >= 0 (the same rotation): result files' convention.
std::array<double, 7> canonical_pose_row(const Pose& T);

/// A row read back: the quaternion normalized; an all-zero quaternion (a placeholder row) is
/// the identity. `t` and `q` may lie apart (result files).
Pose pose_from_row(const double* t, const double* q);
inline Pose pose_from_row(const double* row) { return pose_from_row(row, row + 3); }

/// A row read back from a file a user may have written (tactile logs): a non-finite value or a
/// quaternion whose norm is off 1 by more than 1e-3 throws ts::Error naming `file` and `field`;
/// a nearly-unit quaternion is normalized (user logs round their numbers).
Pose checked_pose_from_row(const double* row, const std::string& file, const std::string& field);

}  // namespace ts::io
