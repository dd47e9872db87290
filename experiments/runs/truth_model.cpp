#include "experiments/runs/truth_model.hpp"

#include "engine/geometry/pose_error.hpp"
#include "engine/geometry/search.hpp"
#include "experiments/analysis/metrics.hpp"

#include <Eigen/Geometry>

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>

namespace ts::experiments {

ObjectTruthModel truth_model(const PointCloud& fine) {
  ObjectTruthModel m;
  KdTree3 tree(fine.points);
  m.symmetry = find_symmetries(fine.points, tree);
  for (const Mat3& r : m.symmetry.rotations) m.mssd_symmetries.push_back(m.symmetry.transform(r));
  const std::size_t stride = std::max<std::size_t>(1, fine.points.size() / 500);
  for (std::size_t k = 0; k < fine.points.size(); k += stride) m.model_points.push_back(fine.points[k]);
  return m;
}

/// MSSD (BOP) for a symmetry group that may be continuous.
double group_mssd(const Pose& estimate, const Pose& truth, const ObjectTruthModel& m) {
  const SymmetryGroup& g = m.symmetry;
  if (g.kind == SymmetryGroup::Kind::spherical) {
    // Any rotation about the centre is a symmetry: the best one aligns the orientations, and
    // every point then moves by the displacement of the centre.
    return (estimate * g.centre - truth * g.centre).norm();
  }
  if (g.kind == SymmetryGroup::Kind::discrete) return mssd(estimate, truth, m.mssd_symmetries, m.model_points);
  // Axial: rotations about the axis (5-degree grid, then 0.25 degrees around the best) times
  // the discrete elements.
  auto at = [&](double angle) {
    const Mat3 spin = Eigen::AngleAxisd(angle, g.axis).toRotationMatrix();
    double best = std::numeric_limits<double>::infinity();
    for (const Mat3& r : g.rotations) {
      const Pose s = g.transform(spin * r);
      best = std::min(best, mssd(estimate, truth * s, {}, m.model_points));
    }
    return best;
  };
  const double coarse = 5.0 * std::numbers::pi / 180.0;
  double best = std::numeric_limits<double>::infinity(), best_angle = 0.0;
  for (int i = 0; i < 72; ++i) {
    const double v = at(i * coarse);
    if (v < best) best = v, best_angle = i * coarse;
  }
  for (int i = -20; i <= 20; ++i) best = std::min(best, at(best_angle + i * coarse / 20.0));
  return best;
}

}  // namespace ts::experiments
