// Sequential object recognition and 6-DOF localization (Section 4.4): BRICPSF, Batch RANSAC
// with ICP and Free Space, and its ablations, as one code path.
//
//   batch-ransac   Section 4.3.2: every step on its own; hypotheses scored by Eq. 5.
//   ransac-icp     Section 5.4: every RANSAC hypothesis refined by ICP, scored by Eq. 5.
//   ransac-icp-fs  Section 5.4: as ransac-icp, scored by Eq. 6 (contact x free space).
//   bricpsf        Algorithm 1: the n_p hypotheses of the previous step are refined by ICP and
//                  re-evaluated (Eq. 6); Batch RANSAC proposes new ones (Eq. 6); the best
//                  Psi*n_p old and (1-Psi)*n_p new form the new state. A hypothesis keeps its
//                  object for life.
//
// A step takes the cumulative contact and free-space clouds in world coordinates; all work is
// done in a frame centred on the contacts, and poses are reported as T_world_object.
// Deterministic for a seed and any thread count (the caller's task arena decides the threads).
#pragma once

#include "engine/recognition/settings.hpp"
#include "engine/recognition/step_result.hpp"

#include <memory>
#include <optional>
#include <vector>

namespace ts {
inline namespace recognition {

namespace pipeline {
class Stage;
}

/// The names of every stage a step's pipeline may hold, in the order a step runs them
/// (StepResult::stages names the ones of its method).
const std::vector<std::string>& pipeline_stage_names();

class Recognizer {
 public:
  /// The W-nearest feature search: with settings.ransac.feature_table (default) the exact
  /// batched FeatureTable, shared by every recognizer over the same database and object mask
  /// (FeatureTable::shared); otherwise `index`, which may be shared between recognizers (build
  /// it with build_feature_index(db, settings.index, settings.objects)) or is built here.
  Recognizer(const Database& db, std::shared_ptr<const FeatureIndex> index,
             RecognizerSettings settings);
  Recognizer(const Database& db, RecognizerSettings settings);

  /// One exploration step with the cumulative clouds (world frame). Free space may be empty.
  /// `grasps`: the same contacts grouped by grasp (Exploration::grasp_groups()), for the
  /// per-grasp offsets of the evaluation (evaluate.grasp_offset_sigma); empty: not used.
  StepResult step(const PointCloud& contacts_world, const std::vector<Vec3>& free_world,
                  const GraspGroups& grasps = {});
  void reset();                     ///< forget the hypotheses; the next step is step 1
  /// Report each step's Funnel of this database object (nullopt: none). Changes no result.
  /// The shape prior a recognizer with these settings uses on `db` (null: none acts). Shared
  /// while held (ShapePrior::shared): a caller that runs many recognizers on one database holds
  /// it, so that it is built once (4 500 objects: about 4 s), not once per recognizer.
  static std::shared_ptr<const ShapePrior> shape_prior(const Database& db, const RecognizerSettings& settings);
  /// The sparse source's pair-table cache a recognizer with these settings uses on `db` (null:
  /// the source is off), shared alike (SparseTables::shared): held by a caller that runs many
  /// recognizers, each table is built once (when first wanted), not once per recognizer.
  static std::shared_ptr<SparseTables> sparse_tables(const Database& db, const RecognizerSettings& settings);
  /// With `T_world_object`, the object's true pose, each step also evaluates the object there
  /// (Funnel::truth_pose_*; an ICP and an evaluation more per step, not in the stage times).
  void watch(std::optional<std::uint32_t> object, std::optional<Pose> T_world_object = std::nullopt) {
    watch_ = object;
    watch_pose_ = object ? T_world_object : std::nullopt;
  }
  /// Each step also says why its answer won over its best rival (StepResult::explanation,
  /// decided_by). Changes no result; its time is not counted in the step's.
  void explain(bool on) { explain_ = on; }
  int steps_done() const { return step_; }
  const std::vector<Hypothesis>& hypotheses() const { return state_; }
  const RecognizerSettings& settings() const { return s_; }
  const Database& database() const { return db_; }

 private:
  const Database& db_;
  FeatureSearch search_;
  RecognizerSettings s_;
  int step_ = 0;
  std::vector<Hypothesis> state_;   ///< S_t, world poses, best first
  std::optional<std::uint32_t> watch_;
  std::optional<Pose> watch_pose_;
  bool explain_ = false;
  std::shared_ptr<const ShapePrior> prior_;  ///< when the shape prior acts (large databases)
  std::shared_ptr<SparseTables> sparse_;  ///< taken (SparseTables::shared) when the sparse source first runs
  /// The method's stages (engine/recognition/pipeline/compose.hpp); immutable, shared by copies.
  std::shared_ptr<const std::vector<std::unique_ptr<const pipeline::Stage>>> stages_;
};

}  // namespace recognition
}  // namespace ts
