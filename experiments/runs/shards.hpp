// One experiment over many processes or machines (issue 16): `experiment --shard I/N` runs a
// deterministic share of the runs into a store of its own, and `touchstone merge` folds the N
// shard stores into one store whose results equal a single-process run's. A run's record
// depends only on (seed, configuration, object, run) (driver.hpp), so a run computed in any
// shard is the run a single process computes.
#pragma once

#include "experiments/runs/driver.hpp"

#include <filesystem>
#include <functional>
#include <string>
#include <vector>

namespace ts::experiments {

struct Shard {
  int index = 1;   ///< 1-based
  int count = 1;
  /// "I/N" (the run store's `shard` attribute; a store without one holds a whole experiment).
  std::string label() const;
};

/// "I/N" with 1 <= I <= N <= 1e6; anything else is an error naming `field` (e.g. "--shard").
Shard parse_shard(const std::string& text, const std::string& field);

/// The shard's tasks: those at positions k with k mod N = I - 1 of `tasks` (all tasks in key
/// order), so each object's runs spread over the shards and the shards cost about the same.
std::vector<RunTask> shard_tasks(const std::vector<RunTask>& tasks, const Shard& shard);

/// Fold the complete shard stores of one experiment into a new store at `out` (complete,
/// `shard` unset). One clear error naming the store at fault when a shard is missing, given
/// twice, of another experiment (configuration, database, objects, variants or build layout),
/// not a shard, or incomplete; `out` must not exist. The shards are left as they are.
/// Returns the number of runs merged. `progress`, when given, is called with (stores done, of
/// total): after each shard is read and checked, and once the merged store is written (total:
/// shards + 1).
std::size_t merge_shards(const std::filesystem::path& out, const std::vector<std::filesystem::path>& shards,
                         const std::function<void(std::size_t, std::size_t)>& progress = {});

}  // namespace ts::experiments
