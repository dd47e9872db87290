// What an experiment scores a pose against: the explored object's symmetries and a sample of its
// model (symmetry-aware errors, the BOP MSSD for a group that may be continuous).
#pragma once

#include "engine/core.hpp"
#include "engine/geometry/symmetry.hpp"

#include <vector>

namespace ts::experiments {

/// The object's symmetries and a model sample, for the symmetry-aware errors and MSSD.
struct ObjectTruthModel {
  SymmetryGroup symmetry;
  std::vector<Pose> mssd_symmetries;           ///< discrete elements as object-frame transforms
  std::vector<Vec3> model_points;              ///< <= 500 points of the fine cloud
};

/// The truth model of an object from its fine cloud (symmetries found on it; <= 500 model points).
ObjectTruthModel truth_model(const PointCloud& fine);

/// MSSD (BOP) for a symmetry group that may be continuous.
double group_mssd(const Pose& estimate, const Pose& truth, const ObjectTruthModel& m);

}  // namespace ts::experiments
