// Pictures of the scene (issue 17): what the engine concluded at a step, for a person to look at.
// scene_json() gathers, in the world frame, the step's contacts, its free-space points, the
// leading hypotheses' objects at their poses (points of each object's surface) and the true
// object at its true pose when known; scripts/plots/touchstone_plots.py draws each scene as a PNG
// (two views) and a self-contained interactive HTML page (no network at viewing time).
#pragma once

#include "engine/database/database.hpp"
#include "engine/recognition/recognizer.hpp"

#include <nlohmann/json.hpp>

#include <optional>
#include <string>
#include <vector>

namespace ts::experiments {

struct SceneLimits {
  std::size_t hypotheses = 3;         ///< leading hypotheses drawn, one per object, best first
  std::size_t object_points = 1500;   ///< surface points drawn of each object (evenly spread)
  std::size_t free_points = 4000;     ///< free-space points drawn (evenly spread)
};

/// One step's scene. `name` names the picture's files (scene_<name>_step<k>); `label` titles it.
/// Coordinates in metres, world frame, rounded to 0.1 mm. "hypotheses": one per object (the
/// answer's own hypothesis for the answer's object, each other object's best by ln w), ranked by
/// the object's posterior (normalized weights summed per object: a share of the state's weight,
/// not a calibrated probability), at most limits.hypotheses, the answer always among them
/// ("answer": true, with `answer_confidence`, the calibrated confidence, when there is one).
nlohmann::ordered_json scene_json(const Database& db, const StepResult& r, const PointCloud& contacts,
                                  const std::vector<Vec3>& free, const std::optional<std::size_t>& truth_object,
                                  const std::optional<Pose>& truth_pose, const std::string& name,
                                  const std::string& label, std::optional<double> answer_confidence = std::nullopt,
                                  const SceneLimits& limits = {});

/// The steps to draw from `--scene-steps` (1-based, ascending, unique; empty: the last step);
/// throws ts::Error naming `--scene-steps` for a step outside 1..steps.
std::vector<int> scene_steps(const std::vector<int>& asked, int steps, const std::string& input);

}  // namespace ts::experiments
