// The real RunEngine: simulated grasp pools (datasets/simulator) explored by the recognizer
// (engine/recognizer), scored against the simulator's ground truth.
//
// Per explored object and noise setting, one pool of `pool` random grasps is simulated once
// (Section 5.1: the object stays fixed, the hand grasps it at random places). A run draws
// `steps` distinct grasps from the pool in random order (Section 5.2), fuses them step by step
// (engine/fusion: cumulative contacts and free space) and runs the recognizer on each step.
//
// Seeds: the pool of an object comes from (seed, object name); a run's grasp order and its
// recognizer stream from (seed, object name, run). They do not depend on the variant, so sweep
// variants compare on the same grasps (common random numbers), nor on which other objects an
// experiment explores.
#pragma once

#include "experiments/config.hpp"
#include "experiments/driver.hpp"

#include <filesystem>
#include <functional>
#include <memory>
#include <string>

namespace ts::experiments {

/// Open the database, resolve the configuration's objects for every variant, and build the run
/// store header. Throws ts::Error for an unknown object (naming the key) or an unreadable
/// database. `threads` and `note` (status lines for a terminal; may be empty) are informative.
std::unique_ptr<RunEngine> make_recognition_engine(const ExperimentConfig& config,
                                                   const std::filesystem::path& database,
                                                   int threads,
                                                   std::function<void(const std::string&)> note = {});

/// Names of the per-stage timing columns the recognition engine records.
const std::vector<std::string>& recognition_stages();

}  // namespace ts::experiments
