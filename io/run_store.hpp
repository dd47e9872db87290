// The run store of an experiment (HDF5; layout in FORMAT_RUN.md): the full configuration and
// versions, then per completed exploration run and step the best hypothesis, a posterior
// summary, the errors and per-stage timings. Runs are appended as they complete; a store can be
// re-opened to continue an interrupted experiment (`touchstone experiment --resume`).
//
// Crash behaviour: the store file is never written in place. append() writes its runs to a
// new file of the folder "<store>.runs/" (temporary name, fsync, rename, fsync of the folder),
// and read() merges the store with those files; compact() (every 64 files, and at the end of an
// experiment) writes a new store with them folded in, renames it over the old one, then
// removes them. A kill at any instant leaves the store and every finished append intact: it
// loses only the runs in flight (a kill between the rename and the removal leaves runs present
// twice, which read as once).
// All calls go through io/h5.hpp, i.e. behind the global HDF5 mutex.
#pragma once

#include "engine/core.hpp"

#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

namespace ts::io {

/// One exploration run observed at one step (one row of /steps).
struct RunStepRecord {
  std::int32_t best_object = -1;       ///< index into database_objects; -1: no hypothesis
  bool correct = false;                ///< best_object is the explored object
  double weight = 0.0;                 ///< weight of the best hypothesis (Eq. 6)
  double posterior_true = 0.0;         ///< posterior of the explored object (weights by object)
  double posterior_best = 0.0;         ///< posterior of best_object
  double posterior_entropy = 0.0;      ///< nats, over objects
  std::int32_t true_rank = 0;          ///< 1-based rank of the explored object; 0: absent
  std::int32_t hypotheses = 0;         ///< hypotheses alive after the step
  std::int32_t contacts = 0;           ///< points in the cumulative contact cloud
  std::int32_t free_points = 0;        ///< points in the cumulative free-space cloud
  Pose pose = Pose::Identity();        ///< best hypothesis, T_world_object
  double position_error_m = 0.0;       ///< vs the truth (meaningful when correct)
  double orientation_error_rad = 0.0;  ///< Eq. 10
  double symmetric_orientation_error_rad = 0.0;
  double mssd_m = 0.0;                 ///< BOP MSSD
  double time_s = 0.0;                 ///< wall time of the step
  std::vector<double> stage_times_s;   ///< one per RunStoreHeader::stages
  std::vector<double> values;          ///< one per RunStoreHeader::step_values (e.g. the
                                       ///< confidence and its features)
};

/// One completed exploration run (one row of /runs and its `steps` rows of /steps).
struct RunRecord {
  std::int32_t variant = 0;            ///< index into RunStoreHeader::variant_labels
  std::int32_t object = 0;             ///< index into RunStoreHeader::objects
  std::int32_t run = 0;                ///< 0-based run number of this object and variant
  std::vector<std::int32_t> grasps;    ///< pool indices, one per step, in order
  Pose truth = Pose::Identity();       ///< true object pose, T_world_object
  double wall_time_s = 0.0;            ///< whole run (simulation excluded)
  std::vector<RunStepRecord> steps;

  bool same_key(const RunRecord& o) const {
    return variant == o.variant && object == o.object && run == o.run;
  }
};

/// Everything a store holds besides its runs. Written once at creation.
struct RunStoreHeader {
  std::string config_json;                  ///< canonical configuration (what determines results)
  std::string database_json;                ///< database file, fingerprint, parameters
  std::string versions_json;                ///< touchstone, HDF5, compiler, ...
  std::string machine;                      ///< CPU model and cores of the creating machine
  std::int32_t steps = 0;                   ///< steps per run (rows per run in /steps)
  std::vector<std::string> variant_labels;  ///< "" when there is no sweep
  std::vector<std::string> variant_configs; ///< canonical JSON of each variant
  std::vector<std::string> objects;         ///< explored objects (RunRecord::object)
  std::vector<std::string> database_objects;///< names RunStepRecord::best_object indexes
  std::vector<std::string> stages;          ///< names of the per-stage timing columns
  std::vector<std::string> step_values;     ///< names of the per-step value columns (optional:
                                            ///< none in stores written before them)
  std::string shard;                        ///< "I/N" for shard I of N of an experiment's runs
                                            ///< (`experiment --shard`); "" for the whole
};

struct RunStoreContents {
  RunStoreHeader header;
  std::vector<RunRecord> runs;              ///< committed runs, sorted by (variant, object, run)
  bool complete = false;                    ///< every planned run is in (set by compact)
};

class RunStore {
 public:
  /// Create a new store at `path` (written atomically: a temporary file renamed when complete).
  /// Throws when `path` exists: an experiment never silently overwrites results.
  static void create(const std::filesystem::path& path, const RunStoreHeader& header);
  /// The header of an existing store; throws a clear error for a missing, foreign or damaged file.
  static RunStoreHeader read_header(const std::filesystem::path& path);
  /// Header and committed runs of the store and its pending files (sorted; a run present twice
  /// counts once). A pending file of another experiment is an error naming it.
  static RunStoreContents read(const std::filesystem::path& path);
  /// Append completed runs: a new file in "<store>.runs/" (see above); folds the folder into the
  /// store once it holds 64 files.
  static void append(const std::filesystem::path& path, const std::vector<RunRecord>& runs);
  /// Rewrite the store atomically with its committed runs and those of its pending files, sorted
  /// by key, mark it complete when `complete`, then remove the pending files. Equal results give
  /// equal bytes except the timing columns.
  static void compact(const std::filesystem::path& path, bool complete);
  /// Write a new store at `out` (which must not exist; written atomically) with `header` and
  /// every run of the stores `inputs` (their pending files included), sorted by key, each run's
  /// stored values copied as they are (equal runs give equal bytes, as compact()). The inputs
  /// must have `header`'s layout (steps, stages, step values, objects, variants); a run present
  /// in two inputs is an error naming both, or with `first_copy` the first input's copy is kept
  /// (a fold that was killed after its rename leaves runs in two places). The inputs are left as
  /// they are.
  static void merge(const std::filesystem::path& out, const RunStoreHeader& header,
                    const std::vector<std::filesystem::path>& inputs, bool complete, bool first_copy = false);
};

}  // namespace ts::io
