// The real RunEngine: simulated grasp pools (datasets/simulator) explored by the recognizer
// (engine/recognition/recognizer), scored against the simulator's ground truth.
//
// A pool is an object at a random pose and `pool` random grasps on it (Section 5.1: the object
// stays fixed, the hand grasps it at random places). A run draws `steps` distinct grasps from a
// pool in random order (Section 5.2), fuses them step by step (engine/touch/fusion: cumulative
// contacts and free space) and runs the recognizer on each step. Protocol (config `protocol`):
//   independent (default): every run has its own pool, simulated lazily inside the run (only
//     the drawn grasps; nothing is kept), so runs are independent samples of pose and grasps;
//   shared_pool (the paper's): one pool per explored object and noise setting, simulated once
//     in prepare(); the runs of an object share its pose and grasps and differ only in order.
//
// Seeds: a shared pool comes from (seed, object name), an independent run's pool from (seed,
// object name, run) on another stream (pool_seed); a run's grasp order and its recognizer
// stream from (seed, object name, run). They do not depend on the variant, so sweep variants
// compare on the same grasps (common random numbers), nor on which other objects an
// experiment explores.
//
// Its parts, one concept a file: grasp_pools.hpp (simulator settings, pool seeds, a run's log),
// engine_database.hpp (the database file, fingerprints, the recognizer databases of the
// variants), truth_model.hpp (symmetries and MSSD), experiments/params/parameters.hpp (a
// variant's method settings); recognition_engine.cpp is the run loop.
#pragma once

#include "engine/database/database.hpp"
#include "experiments/params/config.hpp"
#include "experiments/runs/driver.hpp"
#include "experiments/runs/engine_database.hpp"
#include "experiments/runs/grasp_pools.hpp"

#include <nlohmann/json.hpp>

#include <filesystem>
#include <functional>
#include <memory>
#include <optional>
#include <string>

namespace ts::experiments {

/// Resolve the configuration's objects for every variant against `database` and build the run
/// store header. Throws ts::Error for an unknown object (naming the key). `threads` is recorded;
/// `note` receives status lines for a terminal (may be empty).
std::unique_ptr<RunEngine> make_recognition_engine(const ExperimentConfig& config,
                                                   EngineDatabase database, int threads,
                                                   std::function<void(const std::string&)> note = {});

/// Names of the per-step values the recognition engine records: "confidence_object" and
/// "confidence_pose" (NaN without a calibration), then "feature.<name>" for every confidence
/// feature (experiments/analysis/calibration.hpp), which `touchstone calibrate` fits on, then
/// "ran.<stage>" for every stage of the recognizer's pipeline (1 ran, 0 left out, NaN not in
/// the method; pipeline_stage_names()).
const std::vector<std::string>& recognition_step_values();

/// The per-step values that follow those when a variant sets diagnostics.truth_pose: the true
/// object at its true pose through the step's answer rule (Funnel::truth_pose_*):
/// "truth_pose.wins" (1: the step named it or the rule would with it added, 0: another object
/// beats it even there; Funnel::truth_pose_wins), "truth_pose.log_weight"
/// and "truth_pose.answer_log_weight" (ln wt of it and of the step's answer), "truth_pose.twin_score"
/// and "truth_pose.rival_twin_score" (V of it and the lowest of the other leaders', +inf when the
/// rule did not compare them); NaN in runs without it (the variant's off, or the object hidden).
const std::vector<std::string>& truth_pose_step_values();

/// Names of the per-stage timing columns the recognition engine records.
const std::vector<std::string>& recognition_stages();

}  // namespace ts::experiments
