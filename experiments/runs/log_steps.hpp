// How a tactile log becomes recognizer steps, as `touchstone recognize --log` runs it: the
// settings a log's sensing needs, the exploration (fusion) settings on a database, and each
// step's cumulative clouds. The command and the Python module's Recognizer.recognize_log share
// it, so that both give the same answers for the same log and seed.
#pragma once

#include "engine/database/database.hpp"
#include "engine/recognition/recognizer.hpp"
#include "engine/touch/fusion.hpp"

#include <cstddef>
#include <vector>

namespace ts::experiments {

/// `rs` for a log: a probe's path is free by the ball radius only, measured with the arm's error
/// (kProbeFreeThreshold unless d_thresh is set; kProbeInsideMargin unless the inside margin was
/// given explicitly, `inside_margin_given`). Pads: `rs` unchanged.
RecognizerSettings log_settings(RecognizerSettings rs, const TactileLog& log, bool inside_margin_given);

/// The fusion settings of a log recognized against `db`: the contact voxel filter, free space
/// at the evaluation's res_free inside the largest object's box (Eq. 3).
ExplorationSettings log_exploration(const Database& db, const RecognizerSettings& rs, double contact_voxel);

/// What one recognizer step takes.
struct StepInput {
  PointCloud contacts;        ///< cumulative, voxel-filtered (world)
  std::vector<Vec3> free;     ///< free-space points (world); empty for methods without free space
  GraspGroups grasps;         ///< the contacts by grasp (the per-grasp offsets)
};

/// Advance `ex` to its first k grasps and take the step's inputs (free space only when `method`
/// uses it: bricpsf and ransac-icp-fs).
StepInput step_input(Exploration& ex, std::size_t k, Method method);

}  // namespace ts::experiments
