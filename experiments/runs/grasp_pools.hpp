// Grasp pools of the experiments (Section 5.1-5.2): a pool is an object at a random pose and
// `pool` random grasps on it; a run draws `steps` of them. Protocol shared_pool: one pool per
// object (and noise setting), its drawn grasps copied into each run's log; independent: each
// run's own pool, of which only the drawn grasps are simulated.
#pragma once

#include "datasets/simulator.hpp"
#include "experiments/params/config.hpp"

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

namespace ts::experiments {

/// The simulator settings of a configuration (noise profile and overrides, sensors, sensing,
/// `pool` grasps; no seed).
datasets::SimulatorSettings simulation_settings(const ExperimentConfig& config);

/// What determines a pool apart from its object and seed (variants with equal keys share pools).
std::string pool_key(const datasets::SimulatorSettings& settings);

/// The simulator seed of a pool: the object's shared pool (run = nullopt, protocol shared_pool)
/// or run `run`'s own pool (protocol independent).
std::uint64_t pool_seed(std::uint64_t seed, const std::string& object, std::optional<int> run);

/// The drawn grasps of a shared pool, in the order drawn, as a log (a probe pool stays a probe
/// log).
TactileLog log_from_pool(const TactileLog& pool, const std::vector<std::int32_t>& grasps);

/// Protocol "independent": a run's own pool (object pose, gains, grasps) from `seed`; only the
/// drawn grasps are simulated (a grasp depends on the seed and its index alone, so this equals
/// picking them from the whole simulated pool).
TactileLog simulate_run_pool(const Mesh& mesh, const std::string& name, datasets::SimulatorSettings settings,
                             std::uint64_t seed, const std::vector<std::int32_t>& grasps);

}  // namespace ts::experiments
