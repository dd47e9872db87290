// Rotational symmetries of an object model, found from its geometry: the rotations about the
// model's centroid that map its surface onto itself within a tolerance. They make orientation
// errors meaningful for symmetric objects (sphere, cube, nut: Section 5.5 reports 0-180 degree
// errors for them because Eq. 10 ignores symmetry).
//
// How: principal axes of the surface sample decide the candidate rotations (distinct variances:
// half-turns about the axes; two equal: any rotation about the unique axis and half-turns about
// axes perpendicular to it; all equal: self-registration of an extreme point pair onto every
// pair with the same radii and angle). Each candidate is refined by rotation-only ICP and
// accepted when at least `inlier_fraction` of the sample lies within `tolerance` of the model.
// Continuous symmetries (bodies of revolution, spheres) are recognized as such.
#pragma once

#include "engine/core.hpp"
#include "engine/geometry/search.hpp"

#include <vector>

namespace ts {
inline namespace geometry {

struct SymmetrySettings {
  double tolerance = 0.0;          ///< m; 0: max(tolerance_rel * bbox diagonal, 2.5 * point spacing)
  double tolerance_rel = 0.01;     ///< of the bounding-box diagonal
  double inlier_fraction = 0.95;   ///< of sample points within tolerance for a symmetry
  std::size_t sample_points = 400; ///< points of the model used for the checks
  double eigen_equal_rel = 0.3;    ///< principal variances this close (relative) count as alike
  double continuous_fraction = 0.9;///< share of test rotations that must pass for a continuum
  int angle_steps = 360;           ///< test angles about an axis (1 degree)
  std::uint64_t seed = 1;          ///< random test rotations (sphere test)
};

struct SymmetryGroup {
  enum class Kind { discrete, axial, spherical };
  Kind kind = Kind::discrete;
  Vec3 centre = Vec3::Zero();   ///< object frame; every symmetry fixes it
  Vec3 axis = Vec3::UnitZ();    ///< axial: the axis of the continuous rotations (unit)
  /// Discrete elements, identity first. For `axial`, the elements modulo rotations about the
  /// axis: {I} (a cone) or {I, half-turn perpendicular to the axis} (a cylinder).
  std::vector<Mat3> rotations{Mat3::Identity()};
  double tolerance = 0.0;       ///< m, the tolerance the group was found with

  bool trivial() const { return kind == Kind::discrete && rotations.size() <= 1; }
  /// Object-frame transform of a symmetry rotation: x -> centre + R (x - centre).
  Pose transform(const Mat3& R) const {
    Pose T = Pose::Identity();
    T.linear() = R;
    T.translation() = centre - R * centre;
    return T;
  }
};

/// Rotations about the origin that carry the extreme pair of `source` onto every pair of `target`
/// with the same radii and angle (within `tol`): source's farthest point p1 and the point p2
/// farthest from the line through p1 (both beyond 2 tol from the origin), target's points at
/// those radii greedily thinned to one per tol (at most 240 each), index order (deterministic).
/// Points are relative to the centre of rotation. For shapes whose principal axes say nothing
/// (a cube, a regular octahedron): self-registration here, congruence (engine/geometry/congruence.hpp).
std::vector<Mat3> extreme_pair_rotations(const std::vector<Vec3>& source, const std::vector<Vec3>& target, double tol);

/// Find the symmetries of a model sampled by `points` (object frame), with `tree` built over
/// the same points. Deterministic.
SymmetryGroup find_symmetries(const std::vector<Vec3>& points, const KdTree3& tree,
                              const SymmetrySettings& settings = {});

}  // namespace geometry
}  // namespace ts
